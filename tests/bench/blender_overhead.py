"""Blender render against the engine render of the same exported scene, with where the difference goes.

    python tests/bench/blender_overhead.py [--width 640] [--height 360] [--spp 8] [--repeats 3]
                                           [--threads 0] [--profile N] [--json]

Builds a small polarising scene in bpy (black-glass floor, gold and glass spheres, a sun and a grey
world: the scene of tests/blender/test_render.py's export-fidelity test), renders it once to load
the kernels, then alternately (``--repeats`` times, the fastest kept, because this VM's speed
varies):

- **Blender**: ``bpy.ops.render.render()`` as F12 does (export, BVH, trace with progress and live
  display updates, all passes written into the render result), no file written;
- **CLI equivalent**: ``export_scene`` once, then what ``python -m engine render`` does with that
  scene: ``Renderer(scene).render(settings)`` (BVH build + trace), no file written either.

The ratio Blender ÷ CLI of wall times is the target of issue 16 (≤ 1.10); the ratio of CPU times
(user + system, all threads, from getrusage) is also given: on a machine shared with other jobs it
varies much less than wall time.  One more Blender render runs under
cProfile (main thread: the render workers' time shows as waiting) and its time is split into
export, BVH, trace, progress callbacks (of which live display updates), final pass writing and the
rest.  Runs in the bpy module of the project's venv; prints a table (or one JSON line: ``--json``).
Not part of the test command.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import resource
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))


def build_scene(width, height, spp, threads):
    import bpy
    from tests.blender_support import (add_plane, add_sphere, brewster_camera, empty_scene, load_addon,
                                       polar_material, white_world)
    load_addon()
    scene = empty_scene(width=width, height=height, samples=spp)
    scene.polar.threads = threads
    add_plane(30, polar_material("Floor", "BLACK_GLASS"))
    add_sphere(1.0, (0.5, 0.5, 1.0), polar_material("Gold", "CONDUCTOR", metal="Au"))
    add_sphere(0.7, (-1.5, 0.0, 0.7), polar_material("Glass", "DIELECTRIC", IOR=1.5))
    bpy.ops.object.light_add(type="SUN", rotation=(0.5, 0.2, 0.0))
    bpy.context.object.data.energy = 2.0
    brewster_camera(scene, distance=9, lens=40)
    white_world(scene, 0.5)
    return scene


def cpu_seconds():
    """User + system CPU time of this process so far, all threads (also finished ones)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def blender_render():
    import bpy
    t0 = time.perf_counter()
    bpy.ops.render.render()
    return time.perf_counter() - t0


def cli_render(scene):
    """Seconds of Renderer(export).render(settings): what the CLI spends on the exported scene."""
    import bpy
    from polar_render.engine.render.renderer import Renderer
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    settings = engine_settings(scene)
    engine_scene, _ = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera,
                                   scene.render.resolution_x, scene.render.resolution_y, settings)
    t0 = time.perf_counter()
    Renderer(engine_scene).render(settings)
    return time.perf_counter() - t0


#: (label, file suffix or "" for built-ins, function name) summed from the profile's cumulative times
PARTS = [("export", "export/scene.py", "export_scene"),
         ("BVH + lights", "render/renderer.py", "__init__"),
         ("trace (engine render)", "render/renderer.py", "render"),
         ("progress callbacks", "polar_addon/render_engine.py", "progress"),
         ("  of which live display", "polar_addon/render_engine.py", "_live_display"),
         ("pass writing (all calls)", "polar_addon/render_engine.py", "_write_passes"),
         ("begin/end/update_result", "", "_result"),
         ("Blender operator total", "", "_bpy.ops.call")]


def profile_split(top=0):
    """Seconds per part of one profiled Blender render (main thread), and the profile's top lines."""
    prof = cProfile.Profile()
    prof.enable()
    blender_render()
    prof.disable()
    stats = pstats.Stats(prof)
    split = {}
    for label, suffix, name in PARTS:
        total = 0.0
        for (path, _, func), (_, _, _, cum, _) in stats.stats.items():
            if suffix and path.endswith(suffix) and func == name:
                total += cum
            elif not suffix and path == "~" and name in func:
                total += cum
        split[label] = total
    lines = []
    if top:
        import io
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats("cumulative").print_stats(top)
        lines = buf.getvalue().splitlines()
    return split, lines


def measure(width, height, spp, repeats, threads=0, top=0):
    scene = build_scene(width, height, spp, threads)
    blender_render()                       # kernels loaded / compiled, caches warm
    best = {"blender": [float("inf")] * 2, "cli": [float("inf")] * 2}     # [wall, CPU] seconds
    for _ in range(repeats):               # interleaved: slow phases of the machine hit both
        for name, run in (("blender", blender_render), ("cli", lambda: cli_render(scene))):
            c0 = cpu_seconds()
            wall = run()
            best[name] = [min(best[name][0], wall), min(best[name][1], cpu_seconds() - c0)]
    split, lines = profile_split(top)
    (best_b, cpu_b), (best_c, cpu_c) = best["blender"], best["cli"]
    return {"width": width, "height": height, "spp": spp, "blender_seconds": best_b, "cli_seconds": best_c,
            "ratio": best_b / best_c, "blender_cpu": cpu_b, "cli_cpu": cpu_c, "cpu_ratio": cpu_b / cpu_c,
            "split": split, "profile": lines}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=360)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--profile", type=int, default=0, metavar="N", help="also print the N top profile lines")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--repo", default=REPO, help="checkout whose extension and engine to measure (before/after "
                                                 "comparisons; default: this one)")
    args = ap.parse_args()
    sys.path.insert(0, os.path.abspath(args.repo))
    r = measure(args.width, args.height, args.spp, args.repeats, args.threads, args.profile)
    if args.json:
        print(json.dumps(r))
        return 0
    print(f"{r['width']}×{r['height']}, {r['spp']} spp: Blender {r['blender_seconds']:.2f} s, "
          f"CLI (render of the export) {r['cli_seconds']:.2f} s, Blender ÷ CLI {r['ratio']:.3f}; CPU time "
          f"{r['blender_cpu']:.2f} s ÷ {r['cli_cpu']:.2f} s = {r['cpu_ratio']:.3f}")
    print("profiled Blender render (main thread, cumulative s):")
    for label, seconds in r["split"].items():
        print(f"  {label:28s} {seconds:7.3f}")
    print("\n".join(r["profile"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
