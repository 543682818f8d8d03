"""Per-point cost of the microfacet materials' eval, pdf and sample, with either kernel backend.

    python tests/bench/bsdf_kernels.py [--n 20000] [--repeat 7]
    POLAR_KERNELS=numpy python tests/bench/bsdf_kernels.py      # the NumPy twins

One batch of shading points (random normals, viewers in front, 4 wavelengths) through each
model's eval, pdf and sample; prints the best of --repeat process-CPU times per point in ns.
The compiled passes (engine.kernels.torrance_sparrow, engine.kernels.rough_dielectric) are
latency-bound per path (the visible-slope solve, erfinv and the complex Fresnel dominate), so
the gain over the NumPy orchestration is largest where the NumPy steps were many and cheap
(eval, pdf, a diffuse lobe).  Not part of the test command.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))

from engine import kernels  # noqa: E402
from engine.materials.base import ShadingPoint  # noqa: E402
from engine.materials.rough_dielectric import RoughDielectric  # noqa: E402
from engine.materials.torrance_sparrow import TorranceSparrow  # noqa: E402


def unit(rng, n):
    v = rng.normal(size=(3, n))
    return v / np.linalg.norm(v, axis=0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    rng = np.random.default_rng(1)
    n = args.n
    n_s, wo, wi = unit(rng, n), unit(rng, n), unit(rng, n)
    wo *= np.where((n_s * wo).sum(0) < 0, -1.0, 1.0)[None, :]
    sp = ShadingPoint(np.zeros((3, n)), n_s, n_s, wo, rng.uniform(400, 700, (4, n)))
    u = rng.uniform(size=(3, n))
    models = {"ts gold (smith_rational)": TorranceSparrow(0.47, 2.4, 0.3, shadowing="smith_rational"),
              "ts plastic (ts + diffuse)": TorranceSparrow(1.5, 0.0, 0.2, diffuse_albedo=0.5, diffuse_weight=1.0),
              "rough glass (beckmann)": RoughDielectric(1.5, 0.2, "beckmann", "smith_rational"),
              "rough glass (ggx)": RoughDielectric(1.5, 0.2, "ggx")}
    print(f"backend {kernels.BACKEND}, {n} points, best of {args.repeat}")
    for name, model in models.items():
        for method, call in (("eval", lambda m: m.eval(sp, wi)), ("pdf", lambda m: m.pdf(sp, wi)),
                             ("sample", lambda m: m.sample(sp, u[0], u[1:]))):
            call(model)
            best = np.inf
            for _ in range(args.repeat):
                t = time.process_time()
                call(model)
                best = min(best, time.process_time() - t)
            print(f"{name:28s} {method:7s} {best / n * 1e9:7.0f} ns/point")
    return 0


if __name__ == "__main__":
    sys.exit(main())
