"""What the Stokes transports cost in a participating medium, side by side in one run.

    python tests/bench/media_transport.py [--res 64] [--spp 16] [--repeat 3]

A box of Henyey–Greenstein fog (g = 0.6, albedo 0.9, optical thickness 4 across, no surface) on a
Lambert floor under a sun and a sky, rendered with the scalar ("off"), linear and full Stokes transports
(the phase function depolarises, so all three estimate the same S0), and the same box with Rayleigh fog
(linear, full).  Prints the best-of-``repeat`` wall time of each and its ratio to scalar (issue 37 asks
full Stokes ≤ 1.5× scalar in media), and the rays per path.  Then the Rayleigh box in linear Stokes with the
spectral reduction "auto" (grey media and surfaces: RGB transport) against "off" (four sampled wavelengths
per path): the speed of RGB transport in media.  Not part of the test command.
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)

from engine.render.renderer import Renderer  # noqa: E402
from engine.scene.loader import parse_scene  # noqa: E402
from tests.render.test_absorption import box  # noqa: E402


def fog_scene(phase: dict, res: int, spp: int) -> dict:
    fog = box([-1, -1, 0], [1, 1, 2])
    fog["alpha"] = 0.0
    floor = {"shape": "quad", "vertices": [[-6, -6, 0], [6, -6, 0], [6, 6, 0], [-6, 6, 0]], "material": "floor"}
    return {"format": "polar-scene/1",
            "camera": {"width": res, "height": res, "projection": "perspective", "fov_deg": 45,
                       "origin": [0, -6, 3], "target": [0, 0, 1], "up": [0, 0, 1]},
            "render": {"spp": spp, "max_depth": 16},
            "materials": {"floor": {"type": "lambert", "albedo": 0.5},
                          "fog": {"type": "lambert", "albedo": 0.5,
                                  "interior": {"albedo": 0.9, "density": 2.0, "phase": phase}}},
            "objects": [{**fog, "material": "fog"}, floor],
            "lights": [{"type": "directional", "direction": [0.3, 0.5, -0.8], "irradiance": 3.0},
                       {"type": "environment", "radiance": 0.2}]}


def timed(data: dict, transport: str, repeat: int, reduce: str = "auto") -> tuple[float, dict]:
    d = copy.deepcopy(data)
    d["render"]["polarisation"] = transport
    d["render"]["reduce_spectral"] = reduce
    renderer = Renderer(parse_scene(d))
    renderer.render()                        # kernels compiled, caches filled
    best, stats = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = renderer.render()
        best = min(best, time.perf_counter() - t0)
        stats = result.stats
    return best, stats


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    cases = [("henyey_greenstein g=0.6", {"type": "henyey_greenstein", "g": 0.6}, ("off", "linear", "full")),
             ("rayleigh", {"type": "rayleigh", "depolarisation": 0.0279}, ("linear", "full"))]
    paths = args.res * args.res * args.spp
    for name, phase, transports in cases:
        data = fog_scene(phase, args.res, args.spp)
        times = {t: timed(data, t, args.repeat) for t in transports}
        base = times[transports[0]][0]
        for t, (sec, stats) in times.items():
            print(f"{name:26s} {t:7s} {sec:7.3f} s  ×{sec / base:5.2f} of {transports[0]}  "
                  f"{stats['rays'] / paths:5.2f} rays/path, {stats['shadow_rays'] / paths:5.2f} shadow rays/path")
    data = fog_scene(cases[1][1], args.res, args.spp)
    times = {r: timed(data, "linear", args.repeat, r) for r in ("off", "auto")}
    for r, (sec, stats) in times.items():
        print(f"rayleigh linear reduce={r:4s} {sec:7.3f} s  ×{sec / times['off'][0]:5.2f} of spectral  "
              f"({stats['spectral']})")


if __name__ == "__main__":
    main()
