"""Where a sample's CPU time goes: per-stage CPU µs per sample of the peer scenes (issue 36 item 2).

    python tests/bench/stage_profile.py [--scenes a,b] [--res 256] [--spp 32] [--threads 1,2] [--repeats 2]
                                        [--cprofile N]

Each scene is rendered at its defaults (the scene's settings, ``--threads`` workers) after a warm-up render;
the integrator's stages, the Embree queries, the Mueller update and the film's sums are wrapped by timers that
read the calling thread's CPU clock (``time.thread_time_ns``) and charge each call's *own* time (nested timed
calls subtracted) to its stage, so the stages add up to the traced CPU time.  "other" is the process CPU time
of the render minus the stages (Python between the batches, the film's adding thread, thread start-up).  The
fastest of ``--repeats`` renders per thread count is reported.  A timed call costs two thread-clock reads
(≈ 1 µs); a render makes a few thousand (≈ 0.2 % of its time).  ``--cprofile N``: also print the N functions
of most own time while one thread traces the render's units under cProfile (which sees one thread only).  The
load average is printed; not a test.
"""

from __future__ import annotations

import argparse
import cProfile
import dataclasses
import functools
import os
import pstats
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)

from engine.render import accel, film, integrator  # noqa: E402
from engine.render.driver import BandJob  # noqa: E402
from engine.render.renderer import Renderer  # noqa: E402
from engine.scene.loader import load_scene  # noqa: E402

SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
SCENES = ["fresnel_sphere", "glass_sphere", "rough_sphere_a030"]

#: (label, owner object, attribute): what is timed, in the table's order
STAGES = [
    ("camera", integrator.PathTracer, "_camera_paths"),
    ("Embree closest hits", accel.CompiledScene, "intersect"),
    ("intersect stage (rest)", integrator.PathTracer, "_intersect"),
    ("emission", integrator.PathTracer, "_emission"),
    ("surface reconstruction", integrator.PathTracer, "_surface"),
    ("material grouping", integrator, "material_groups"),
    ("random numbers", integrator.PathTracer, "_vertex_numbers"),
    ("random numbers (sobol)", integrator.PathTracer, "_sobol_vertex_numbers"),
    ("delta scatter (one step)", integrator.PathTracer, "_scatter_delta"),
    ("shading point", integrator.PathTracer, "_shading_point"),
    ("Embree shadow rays", accel.CompiledScene, "occluded"),
    ("NEE (rest)", integrator.PathTracer, "_group_next_event"),
    ("BSDF sample", integrator.PathTracer, "_sample_bsdf"),
    ("Mueller update", integrator, "scatter_throughput"),
    ("scatter (rest)", integrator.PathTracer, "_scatter"),
    ("roulette + next segments", integrator.PathTracer, "_next_segments"),
    ("accumulation (Stokes → RGB)", integrator.PathTracer, "_finish"),
    ("film sums (worker)", film.SampleSums, "of"),
    ("film add", film.Film, "add"),
]


class StageClock:
    """Per-thread stack of running timers; ``own[label]`` accumulates each call's own CPU ns."""

    def __init__(self):
        self.local = threading.local()
        self.lock = threading.Lock()
        self.own: dict[str, int] = {}

    def wrap(self, label, fn):
        clock = self

        @functools.wraps(fn)
        def timed(*args, **kwargs):
            stack = getattr(clock.local, "stack", None)
            if stack is None:
                stack = clock.local.stack = []
            stack.append(0)                      # nested timed time of this call
            t0 = time.thread_time_ns()
            try:
                return fn(*args, **kwargs)
            finally:
                total = time.thread_time_ns() - t0
                nested = stack.pop()
                if stack:
                    stack[-1] += total
                with clock.lock:
                    clock.own[label] = clock.own.get(label, 0) + total - nested
        return timed


def install(clock: StageClock):
    """Wrap every stage; returns a function that restores the originals."""
    saved = []
    for label, owner, name in STAGES:
        if owner is None:
            continue
        raw = owner.__dict__[name] if isinstance(owner, type) else getattr(owner, name)
        if isinstance(raw, classmethod):
            wrapped = classmethod(clock.wrap(label, raw.__func__))
        elif isinstance(raw, staticmethod):
            wrapped = staticmethod(clock.wrap(label, raw.__func__))
        else:
            wrapped = clock.wrap(label, raw)
        saved.append((owner, name, raw))
        setattr(owner, name, wrapped)

    def restore():
        for owner, name, raw in saved:
            setattr(owner, name, raw)
    return restore


def render_once(renderer, settings):
    c0 = time.process_time()
    w0 = time.perf_counter()
    renderer.render(settings)
    return time.process_time() - c0, time.perf_counter() - w0


def profile_scene(name, res, spp, threads, repeats):
    """{threads: (own ns per label, process CPU s, wall s)} of the fastest of ``repeats`` renders."""
    scene = load_scene(os.path.join(SHARED, "peers", "scenes", f"{name}.json"))
    scene.camera.width = scene.camera.height = res
    renderer = Renderer(scene)
    out = {}
    for t in threads:
        settings = dataclasses.replace(scene.settings, spp=spp, threads=t, seed=0)
        renderer.render(dataclasses.replace(settings, seed=99))         # warm-up
        best = None
        for _ in range(repeats):
            clock = StageClock()
            restore = install(clock)
            try:
                cpu, wall = render_once(renderer, settings)
            finally:
                restore()
            if best is None or cpu < best[1]:
                best = (dict(clock.own), cpu, wall)
        out[t] = best
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--cprofile", type=int, default=0)
    args = ap.parse_args(argv)
    scenes = args.scenes.split(",")
    threads = [int(t) for t in args.threads.split(",")]
    samples = args.res * args.res * args.spp
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} {os.getloadavg()[2]:.2f}; "
          f"{args.res}², {args.spp} spp; CPU µs per sample (own time of each stage)")
    results = {name: profile_scene(name, args.res, args.spp, threads, args.repeats) for name in scenes}
    cols = [(name, t) for name in scenes for t in threads]
    print("| stage | " + " | ".join(f"{n} {t} thr" for n, t in cols) + " |")
    print("|---|" + "---|" * len(cols))
    for label, owner, _ in STAGES:
        if owner is None:
            continue
        cells = [results[n][t][0].get(label, 0) / 1e3 / samples for n, t in cols]
        if any(c > 0 for c in cells):
            print(f"| {label} | " + " | ".join(f"{c:.3f}" for c in cells) + " |")
    other = [results[n][t][1] * 1e6 / samples - sum(results[n][t][0].values()) / 1e3 / samples for n, t in cols]
    print("| other (Python between batches, threads) | " + " | ".join(f"{c:.3f}" for c in other) + " |")
    print("| **process CPU** | " + " | ".join(f"**{results[n][t][1] * 1e6 / samples:.3f}**" for n, t in cols) + " |")
    print("| wall µs per sample | " + " | ".join(f"{results[n][t][2] * 1e6 / samples:.3f}" for n, t in cols) + " |")
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    if args.cprofile:
        for name in scenes:
            scene = load_scene(os.path.join(SHARED, "peers", "scenes", f"{name}.json"))
            scene.camera.width = scene.camera.height = args.res
            renderer = Renderer(scene)
            settings = dataclasses.replace(scene.settings, spp=args.spp, threads=1, seed=0)
            renderer.render(dataclasses.replace(settings, seed=99))
            plan = renderer.plan(settings)
            tracer = renderer.tracer(plan)
            job = BandJob(plan.settings, plan.width, plan.window, plan.stratified)
            prof = cProfile.Profile()       # the units traced on this thread (cProfile sees one thread)
            prof.enable()
            for unit in plan.units():
                job(tracer, unit)
            prof.disable()
            print(f"\n## cProfile {name} (1 thread)")
            pstats.Stats(prof).sort_stats("tottime").print_stats(args.cprofile)


if __name__ == "__main__":
    main()
