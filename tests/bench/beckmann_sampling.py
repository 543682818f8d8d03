"""ns per Beckmann visible-normal sample (engine.kernels.microfacet.beckmann_vndf_at), with and without
the tabulated first guess of x̃, interleaved in one process; and how far the two samples differ.

    python tests/bench/beckmann_sampling.py [--n 200000] [--rounds 7] [--m 0.3]

Viewers are those of a sphere seen by a camera (cosθ_o = √ξ, the projected-disc density) and stretched by
the roughness m; uniforms from NumPy's PCG64.  Each round times both versions once (order alternating) on
the thread's CPU clock; the best round of each and their ratio are printed, with the load average.  The
difference of the sampled normals is measured over the same draws and over hard cases (θ_o near 0 and 90°,
u near 0 and 1, m from 1e-4 to 10).  Not a test.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))

from engine import kernels  # noqa: E402
from engine.kernels import jit  # noqa: E402
from engine.kernels.error_function import ERFCX_COEF, ERFCX_K  # noqa: E402
from engine.kernels.microfacet import _beckmann_vndf_with  # noqa: E402


@jit
def _sample_loop(wo, u, m, coef, k, use_table, out):
    for i in range(wo.shape[1]):
        h0, h1, h2, _ = _beckmann_vndf_with(wo[0, i], wo[1, i], wo[2, i], u[0, i], u[1, i], m[i], coef, k, use_table,
                                            0.0)
        out[0, i] = h0
        out[1, i] = h1
        out[2, i] = h2


def sample(wo, u, m, use_table):
    out = np.empty_like(wo)
    _sample_loop(wo, u, m, np.ascontiguousarray(ERFCX_COEF), float(ERFCX_K), use_table, out)
    return out


def sphere_viewers(rng, n):
    c = np.sqrt(rng.random(n))
    s = np.sqrt(1.0 - c * c)
    phi = 2 * np.pi * rng.random(n)
    return np.ascontiguousarray(np.stack((s * np.cos(phi), s * np.sin(phi), c)))


def hard_cases(rng):
    """(wo, u, m) over grazing and normal viewers, u at both ends and extreme roughness."""
    theta = np.concatenate([[0.0, 1e-300, 1e-12, 1e-6], np.pi / 2 - np.array([0.0, 1e-300, 1e-15, 1e-9, 1e-6, 1e-3]),
                            np.linspace(0.0, np.pi / 2, 31)])
    us = np.array([0.0, 1e-300, 1e-16, 1e-12, 1e-9, 7.7e-9, 1e-8, 1e-6, 1e-3, 0.5, 1 - 1e-3, 1 - 1e-6, 1 - 1e-8,
                   1 - 1e-12, 1 - 2 ** -53])
    ms = np.array([1e-4, 1e-3, 0.01, 0.3, 1.0, 3.0, 10.0])
    tt, u0, u1, mm = np.meshgrid(theta, us, us[::3], ms, indexing="ij")
    tt, u0, u1, mm = tt.ravel(), u0.ravel(), u1.ravel(), mm.ravel()
    phi = 2 * np.pi * rng.random(tt.size)
    wo = np.stack((np.sin(tt) * np.cos(phi), np.sin(tt) * np.sin(phi), np.cos(tt)))
    return np.ascontiguousarray(wo), np.ascontiguousarray(np.stack((u0, u1))), np.ascontiguousarray(mm)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=200000)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--m", type=float, default=0.3)
    args = ap.parse_args(argv)
    if not kernels.COMPILED:
        sys.exit("needs the compiled kernels (numba)")
    rng = np.random.default_rng(1)
    wo = sphere_viewers(rng, args.n)
    u = np.ascontiguousarray(rng.random((2, args.n)))
    m = np.full(args.n, args.m)
    sample(wo[:, :8], u[:, :8], m[:8], True)             # compile both
    sample(wo[:, :8], u[:, :8], m[:8], False)
    best = {True: np.inf, False: np.inf}
    for r in range(args.rounds):
        for use in ((True, False) if r % 2 else (False, True)):
            t0 = time.thread_time_ns()
            sample(wo, u, m, use)
            best[use] = min(best[use], (time.thread_time_ns() - t0) / args.n)
    print(f"load average {os.getloadavg()[0]:.2f}; m = {args.m}, {args.n} sphere viewers, best of {args.rounds}")
    print(f"  before (Giles starts):         {best[False]:7.1f} ns per sample")
    print(f"  after (table / fitted starts): {best[True]:7.1f} ns per sample   ratio {best[False] / best[True]:.2f}x")
    for label, (w, uu, mm) in (("sphere viewers", (wo, u, m)), ("hard cases", hard_cases(rng))):
        with np.errstate(all="ignore"):
            a, b = sample(w, uu, mm, False), sample(w, uu, mm, True)
        d = np.max(np.abs(a - b), axis=0)
        finite = np.all(np.isfinite(a), axis=0) & np.all(np.isfinite(b), axis=0)
        bulk = np.all((uu > 1e-3) & (uu < 1 - 1e-3), axis=0)
        # where the old start stopped short of the root (stretched tanθ > 1e5 and 1 − u₀ < 1e-6: its first
        # Halley step is tiny because of the curvature, test_beckmann_sampling.py)
        tan = mm * np.sqrt(w[0] ** 2 + w[1] ** 2) / np.maximum(w[2], 1e-300)
        miss = (tan > 1e5) & (uu[0] > 1 - 1e-6)
        print(f"  {label} ({w.shape[1]}): max |Δh| {d[~miss].max():.2e}, u in [1e-3, 1 - 1e-3]: {d[bulk].max():.2e}; "
              f"bit-identical {np.mean(d == 0):.1%}; all finite: {finite.all()}"
              + (f"; where the old start stopped short ({miss.sum()}): {d[miss].max():.2e}" if miss.any() else ""))


if __name__ == "__main__":
    main()
