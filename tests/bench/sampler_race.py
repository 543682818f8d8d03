"""Sampling patterns raced in one run: time to equal error of our samplers on the five peer scenes.

    python tests/bench/sampler_race.py [--scenes a,b] [--res 128] [--spp 32,128] [--seeds 4]
                                       [--samplers sobol,stratified,independent] [--threads 1]

For each peer scene (``shared/peers/scenes``, at --res × --res) and each sample count of ``--spp``,
every sampler renders the scene ``--seeds`` times (seeds 0, 1, …).  All our samplers are unbiased, so
a render's mean squared error is its variance: per pixel the variance over the seeds (ddof 1), averaged
over the pixels, of the luminance S0 and S1.  Monte Carlo error² ∝ 1/time, so the time to equal error
of sampler a ÷ sampler b is (t_b·MSE_b)/(t_a·MSE_a) (> 1: a gets there first); t is the CPU time of the
renders (``time.process_time``: not inflated by other processes' load on a shared machine; with
--threads 1 it is the render's work).  The first sampler of ``--samplers`` is compared with each other
one (± the standard error of the MSE ratio from the pixels' variance estimates, ``mse_rel_se``; the
CPU times' own spread, a few %, comes on top); ``bias z`` is the difference of the two image means ÷
its standard error (|z| < 4: the same expectation).  Kernels are loaded (``Renderer.warm_up``) and one
untimed render made before anything is timed; the samplers take turns seed by seed.

Mitsuba is not raced here (``tests/bench/bench_engine.py`` does, where Mitsuba 3 is installed).
Not part of the test command.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)

from engine.render.renderer import Renderer  # noqa: E402
from engine.scene.loader import load_scene  # noqa: E402

SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
SCENES = ["fresnel_sphere", "fresnel_sphere_au", "glass_sphere", "rough_sphere_a030", "cornell_lambert"]
#: scenes whose S1 is 0 (nothing polarises): no S1 column
NO_S1 = {"cornell_lambert"}


def render_one(renderer, scene, sampler, spp, seed, threads):
    """(S0 image, S1 image) (H, W) of one render and its CPU seconds."""
    st = dataclasses.replace(scene.settings, spp=spp, seed=seed, sampler=sampler, threads=threads)
    t = time.process_time()
    result = renderer.render(st)
    cpu = time.process_time() - t
    y = result.stokes_luminance()
    return y[0], y[1], cpu


def renders(renderer, scene, samplers, spp, seeds, threads):
    """{sampler: (S0 images, S1 images) (seeds, H, W), CPU seconds of its renders}; the samplers take
    turns seed by seed (a drift of the machine's speed is shared)."""
    got = {s: ([], [], 0.0) for s in samplers}
    for seed in range(seeds):
        for s in samplers:
            a, b, cpu = render_one(renderer, scene, s, spp, seed, threads)
            got[s][0].append(a)
            got[s][1].append(b)
            got[s] = (got[s][0], got[s][1], got[s][2] + cpu)
    return {s: (np.array(a), np.array(b), cpu) for s, (a, b, cpu) in got.items()}


def mse(images):
    """A render's mean squared error (unbiased estimators: its variance), from several seeds."""
    return float(images.var(axis=0, ddof=1).mean())


def mse_rel_se(images):
    """Relative standard error of ``mse(images)``: per pixel the variance estimate from k seeds has
    relative variance 2/(k − 1) (normal errors), and the pixels' sum weighs each by its variance, so the
    mean has relative SE sqrt(2/(k − 1)·Σv²)/Σv (Σv² from the estimates, E[v̂²] = v²(1 + 2/(k − 1))):
    a few bright pixels holding the error make it large."""
    k = images.shape[0]
    v = images.var(axis=0, ddof=1).ravel()
    total = v.sum()
    return float(np.sqrt(2 / (k - 1) * (v * v).sum() / (1 + 2 / (k - 1))) / total) if total > 0 else 0.0


def bias_z(a, b):
    """Difference of the image means of two sets of renders ÷ its standard error."""
    ma, mb = a.mean(axis=(1, 2)), b.mean(axis=(1, 2))
    se = np.sqrt(ma.var(ddof=1) / ma.size + mb.var(ddof=1) / mb.size)
    return float((ma.mean() - mb.mean()) / se) if se > 0 else 0.0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", default="32,128", help="comma list of samples per pixel")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--samplers", default="sobol,stratified,independent",
                    help="comma list; the first is compared with each other one")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    samplers = args.samplers.split(",")
    spps = [int(s) for s in args.spp.split(",")]
    first, others = samplers[0], samplers[1:]
    load = os.getloadavg()
    print(f"# sampler race, {datetime.date.today()}: {args.res}², {args.seeds} seeds per configuration, "
          f"{args.threads} thread(s), CPU time; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"# command: python tests/bench/sampler_race.py {' '.join(argv if argv is not None else sys.argv[1:])}")
    rows = []
    for name in args.scenes.split(","):
        scene = load_scene(os.path.join(SHARED, "peers", "scenes", f"{name}.json"))
        scene.camera.width = scene.camera.height = args.res
        renderer = Renderer(scene)
        for sampler in samplers:
            st = dataclasses.replace(scene.settings, sampler=sampler, threads=args.threads)
            renderer.warm_up(st)
        # one untimed full render: a scene's first one pays for growing the process's memory (measured
        # ~15 % more CPU time than the next), which would count against the sampler rendering first
        render_one(renderer, scene, samplers[0], spps[0], args.seeds, args.threads)
        for spp in spps:
            got = renders(renderer, scene, samplers, spp, args.seeds, args.threads)
            for s in samplers:
                s0, s1, cpu = got[s]
                print(f"{name:18s} {spp:4d} spp {s:11s} CPU {cpu:7.1f} s  MSE S0 {mse(s0):.3e}"
                      + ("" if name in NO_S1 else f"  S1 {mse(s1):.3e}"), flush=True)
            a0, a1, ta = got[first]
            for other in others:
                b0, b1, tb = got[other]
                r0 = tb * mse(b0) / (ta * mse(a0))
                r1 = None if name in NO_S1 else tb * mse(b1) / (ta * mse(a1))
                se0 = np.hypot(mse_rel_se(a0), mse_rel_se(b0))          # of the MSE ratio, relative
                rows.append((name, spp, other, mse(b0) / mse(a0), tb / ta, r0, se0 * r0, r1, bias_z(a0, b0)))
    print()
    print(f"| scene | spp | {first} vs | MSE S0 ÷ {first}'s | CPU {first} ÷ it | time to equal error S0 "
          f"(> 1: {first} faster) ± SE | same for S1 | bias z |")
    print("|---|---|---|---|---|---|---|---|")
    for name, spp, other, var_ratio, cpu_ratio, r0, se, r1, z in rows:
        print(f"| {name} | {spp} | {other} | {var_ratio:.2f} | {1 / cpu_ratio:.2f} | {r0:.2f} ± {se:.2f} | "
              f"{'—' if r1 is None else f'{r1:.2f}'} | {z:+.1f} |")


if __name__ == "__main__":
    main()
