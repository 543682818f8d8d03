"""What polarised sources cost (issue 35), measured side by side in one process.

    python tests/bench/polarised_sources.py [--repeats 5] [--res 128] [--spp 16]

1. **Unpolarised scenes are unchanged.**  Peer-style scenes without a polarised source rendered alternately
   by the current code and by the same code with the polarised branches cut out (the light added as
   T[:, 0]·L_e and the BSDF's response to unpolarised light, exactly the code before sources could be
   polarised; tests/render/test_polarised_sources.py checks the two give the same bits): the time ratio with
   its spread over the alternated repeats.
2. **What a polarised sky costs.**  examples/daylight_water.json with a meadow for the lake (so that nothing
   but the sky polarises: a sky, a sun, hills, rocks) with the sky polarised (Auto → linear Stokes) and
   unpolarised (Auto → scalar), alternated: the ratio is what an outdoor scene of depolarising materials pays
   for its polarised daylight at equal samples.

Prints Markdown tables; docs/benchmarks.md ("Polarised sources") holds a run.  Not part of the test command.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)


def _unpolarised_scenes(res, spp):
    base = {"format": "polar-scene/1", "render": {"spp": spp, "max_depth": 8, "seed": 0, "sampler": "independent"},
            "camera": {"origin": [0, -6, 3], "target": [0, 0, 0.6], "up": [0, 0, 1], "fov_deg": 40,
                       "width": res, "height": res}}
    floor = {"shape": "quad", "material": "floor", "vertices": [[-9, -9, 0], [9, -9, 0], [9, 9, 0], [-9, 9, 0]]}
    lamp = {"shape": "quad", "material": "black", "emission": {"radiance": 6},
            "vertices": [[-1, -1, 4], [-1, 1, 4], [1, 1, 4], [1, -1, 4]]}
    return {
        "fresnel+lamp": {**base, "materials": {"glass": {"type": "dielectric", "n": 1.5},
                                               "floor": {"type": "black_glass", "n": 1.5},
                                               "black": {"type": "lambert", "albedo": 0.0}},
                         "objects": [{"shape": "sphere", "center": [0, 0, 0.8], "radius": 0.8, "material": "glass"},
                                     floor, lamp],
                         "lights": [{"type": "environment", "radiance": 0.3}]},
        "gold+sun": {**base, "materials": {"gold": {"type": "conductor", "metal": "Au"},
                                           "floor": {"type": "torrance_sparrow", "n": 1.5, "m": 0.2},
                                           "black": {"type": "lambert", "albedo": 0.0}},
                     "objects": [{"shape": "sphere", "center": [0, 0, 0.8], "radius": 0.8, "material": "gold"}, floor],
                     "lights": [{"type": "environment", "radiance": 0.3},
                                {"type": "directional", "direction": [0.3, 0.2, -1], "irradiance": 2.0}]},
        "lambert+lamp": {**base, "materials": {"white": {"type": "lambert", "albedo": 0.8},
                                               "floor": {"type": "lambert", "albedo": 0.5},
                                               "black": {"type": "lambert", "albedo": 0.0}},
                         "objects": [{"shape": "sphere", "center": [0, 0, 0.8], "radius": 0.8, "material": "white"},
                                     floor, lamp],
                         "lights": []},
    }


def _cut_polarised_branches():
    """Patch the integrator back to the unpolarised-only code; returns the function that undoes it."""
    from engine.kernels.transport import add_light
    from engine.render.integrator import PathTracer
    saved = PathTracer._add_light, PathTracer._bsdf_response
    plain = saved[1]

    def add_plain(self, radiance, path, T, rows, Le, w, T_cols, light, d, x_T):
        add_light(radiance, path, T, rows, Le, w, T_cols)

    PathTracer._add_light = add_plain
    PathTracer._bsdf_response = lambda self, sp, bsdf, x_T, wi, polarised=None: plain(self, sp, bsdf, x_T, wi, None)

    def undo():
        PathTracer._add_light, PathTracer._bsdf_response = saved
    return undo


def _seconds(renderer, settings):
    t0 = time.perf_counter()
    renderer.render(settings)
    return time.perf_counter() - t0


def main(argv=None):
    from engine.render.renderer import Renderer
    from engine.scene.loader import parse_scene
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--spp", type=int, default=16)
    a = p.parse_args(argv)

    print(f"Run {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {os.cpu_count()} cores, "
          f"{a.res}², {a.spp} spp, {a.repeats} alternated repeats (fastest and spread of each side)\n")
    print("| scene (unpolarised) | now s | before s | now ÷ before | spread of the ratios |")
    print("|---|---|---|---|---|")
    for name, data in _unpolarised_scenes(a.res, a.spp).items():
        scene = parse_scene(json.loads(json.dumps(data)))
        renderer = Renderer(scene)
        renderer.render(scene.settings)                 # warm: kernels compiled or loaded
        now, before = [], []
        for _ in range(a.repeats):
            now.append(_seconds(renderer, scene.settings))
            undo = _cut_polarised_branches()
            try:
                before.append(_seconds(renderer, scene.settings))
            finally:
                undo()
        ratios = [x / y for x, y in zip(now, before)]
        print(f"| {name} | {min(now):.3f} | {min(before):.3f} | {min(now) / min(before):.3f} | "
              f"{min(ratios):.3f}–{max(ratios):.3f} (median {statistics.median(ratios):.3f}) |")

    print("\n| outdoor scene | sky polarised s (transport) | sky unpolarised s (transport) | ratio |")
    print("|---|---|---|---|")
    path = os.path.join(REPO, "examples", "daylight_water.json")
    with open(path) as f:
        data = json.load(f)
    data["camera"].update(width=a.res * 8 // 5, height=a.res)
    data["materials"]["water"] = {"type": "lambert", "albedo": [0.2, 0.18, 0.12]}     # a meadow: nothing polarises
    off = json.loads(json.dumps(data))
    off["lights"][0]["polarisation"] = "none"
    scenes = [parse_scene(data, os.path.dirname(path)), parse_scene(off, os.path.dirname(path))]
    renderers = [Renderer(s) for s in scenes]
    times = [[], []]
    transports = []
    settings = [dataclasses.replace(s.settings, spp=a.spp) for s in scenes]
    for r, st in zip(renderers, settings):
        transports.append(r.render(st).stats["transport"])
    for _ in range(a.repeats):
        for i, (r, st) in enumerate(zip(renderers, settings)):
            times[i].append(_seconds(r, st))
    print(f"| daylight_water | {min(times[0]):.3f} ({transports[0]}) | {min(times[1]):.3f} ({transports[1]}) | "
          f"{min(times[0]) / min(times[1]):.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
