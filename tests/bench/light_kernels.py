"""The lights' compiled loops against their NumPy twins (the code they replaced), timed side by side in one process.

    python tests/bench/light_kernels.py [--n 20000] [--repeats 15]

Each pair (engine.kernels.TWINS) runs on the same inputs, alternating NumPy and compiled calls ``--repeats`` times,
32 MB written before each call (a render's other work evicts the tables between its calls); printed: the median
thread-CPU µs per call of each and their ratio, and whether the outputs are bit-identical.
Inputs: an equirectangular sky the size of the asset suite's (512 × 256, float32, a sun, tests/data/assets/
environment/make_sky.py's shape) turned by Euler angles, ``--n`` random directions and numbers; a mesh light of
15 k triangles for the light tree's triangle samples.  The load average
is printed; not a test.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(os.path.dirname(HERE)))

import numpy as np  # noqa: E402

from engine import kernels  # noqa: E402
from engine.render.lights import environment as env_module  # noqa: E402


def race(name, args, repeats):
    pair = kernels.TWINS[name]
    a, b = pair.reference(*args), pair.compiled(*args)           # warm-up (and compilation)
    a, b = (x if isinstance(x, tuple) else (x,) for x in (a, b))
    same = all(np.array_equal(x, y) for x, y in zip(a, b))
    t_ref, t_comp = [], []
    flush = np.empty(4 << 20)
    for _ in range(repeats):
        for fn, out in ((pair.reference, t_ref), (pair.compiled, t_comp)):
            flush[:] = 1.0
            c0 = time.thread_time_ns()
            fn(*args)
            out.append((time.thread_time_ns() - c0) / 1e3)
    r, c = float(np.median(t_ref)), float(np.median(t_comp))
    print(f"{name:42s} {r:10.1f} {c:10.1f} {r / c:7.2f}  {'bit-identical' if same else 'DIFFER'}")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=20000)
    p.add_argument("--repeats", type=int, default=15)
    args = p.parse_args(argv)
    if not kernels.COMPILED:
        sys.exit("needs the compiled kernels (Numba)")
    print(f"load average before: {os.getloadavg()}")
    rng = np.random.default_rng(1)
    sky = rng.uniform(0.0, 1.0, (256, 512, 3)).astype(np.float32)
    sky[60:64, 100:104] = 5e4                                        # a sun
    env = env_module.EnvironmentMapEmitter(sky, strength=1.0, rotation_deg=[5.0, 10.0, 30.0])
    d = rng.normal(size=(3, args.n))
    d /= np.linalg.norm(d, axis=0)
    u, v = env_module._uv_numpy(env._to_map(d))
    numbers = rng.uniform(size=(3, args.n))
    print(f"{'pair (' + str(args.n) + ' points)':42s} {'NumPy µs':>10s} {'Numba µs':>10s} {'ratio':>7s}")
    race("render.lights.environment.lookup", (u, v, env._interpolated, False, env.strength), args.repeats)
    race("render.lights.environment.pdf", (u, v, env.cell_pdf, env.texels.shape[0], False), args.repeats)
    race("render.lights.environment.sample", (env.cdf, env.cdf_guide, env.cos_knots, env.cell_pdf, numbers),
         args.repeats)
    race("render.lights.environment.uniform_sample", (numbers,), args.repeats)
    # the light tree's per-triangle samples on a 15 k-triangle emitter (SpecGlossEmission's size), as many points
    # as the asset's calls take (≈ 100) and a batch's worth
    V = rng.normal(size=(8000, 3)).astype(np.float32)
    faces = rng.integers(0, 8000, size=(15000, 3)).astype(np.int32)
    cross = np.cross(V[faces[:, 1]] - V[faces[:, 0]], V[faces[:, 2]] - V[faces[:, 0]])
    length = np.linalg.norm(cross, axis=1)
    normal, area = cross / np.where(length > 0, length, 1.0)[:, None], 0.5 * length
    for n in (100, args.n):
        p = rng.normal(size=(3, n)) * 3.0
        print(f"  {n} points:")
        race("kernels.geometry.triangle_sample", (p, rng.integers(0, 15000, n), numbers[0, :n], numbers[1, :n], faces,
                                                  V, normal, area, False), args.repeats)
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
