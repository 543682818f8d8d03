"""Would float32 Mueller transport pay?  Speed and error of the T·R·M update in float32 vs float64.

    python tests/bench/float32_transport.py [--paths 131072] [--depth 16]

Runs the compiled throughput update (engine.kernels.transport) on one batch in both
precisions, side by side in one run, and propagates a chain of ``depth`` Fresnel vertices
(alternating a dielectric at η = 1.5 and a conductor at η = 0.2 + 3.5i, random incidence and
frame rotations, renormalised each bounce as Russian roulette would) to compare the Stokes
vector reaching the camera.  Prints time per update and the worst relative error of S and DoP.
Not a test: benchmarks never run in the test command.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
from engine.kernels.transport import _update_abcs_loop  # noqa: E402
from engine.polarisation.fresnel import fresnel_reflection_abcs  # noqa: E402


def identity(dtype, L, n):
    T = np.zeros((4, 4, L, n), dtype)
    for i in range(4):
        T[i, i] = 1
    return T


def frames(rng, n, dtype):
    """Random (x_out, x_T, wo): two unit frame vectors ⟂ a unit direction, (3, n) each."""
    wo = rng.normal(size=(3, n))
    wo /= np.linalg.norm(wo, axis=0)
    xs = []
    for _ in range(2):
        x = np.cross(wo.T, rng.normal(size=(n, 3))).T
        xs.append((x / np.linalg.norm(x, axis=0)).astype(dtype))
    return xs[0], xs[1], wo.astype(dtype)


def time_update(dtype, n, L=4, repeats=20):
    rng = np.random.default_rng(0)
    T, rows = identity(dtype, L, n), np.arange(n)
    out = np.empty_like(T)
    A = rng.random((L, n)).astype(dtype)
    B, C, S = (A * f for f in (0.3, 0.5, 0.2))
    x_out, x_T, wo = frames(rng, n, dtype)
    _update_abcs_loop(out, T, rows, rows, x_out, x_T, wo, A, B, C, S, A, False)  # compile
    t0 = time.perf_counter()
    for _ in range(repeats):
        _update_abcs_loop(out, T, rows, rows, x_out, x_T, wo, A, B, C, S, A, False)
    return (time.perf_counter() - t0) / repeats


def chain(dtype, depth, n=20000):
    rng = np.random.default_rng(1)
    T, rows = identity(dtype, 1, n), np.arange(n)
    for b in range(depth):
        cos = rng.random((1, n))
        eta = np.full((1, n), 0.2 + 3.5j if b % 2 else 1.5 + 0j)
        A, B, C, S = (np.ascontiguousarray(x, dtype=dtype) for x in fresnel_reflection_abcs(cos, eta))
        x_out, x_T, wo = frames(rng, n, dtype)
        out = np.empty_like(T)
        _update_abcs_loop(out, T, rows, rows, x_out, x_T, wo, A, B, C, S, A, False)
        T = out / np.maximum(out[0, 0], 1e-30)
    return T[:, 0, 0].astype(np.float64)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=int, default=131072)
    ap.add_argument("--depth", type=int, default=16)
    a = ap.parse_args()
    t64, t32 = time_update(np.float64, a.paths), time_update(np.float32, a.paths)
    s64, s32 = chain(np.float64, a.depth), chain(np.float32, a.depth)
    rel = np.abs(s64 - s32).max(axis=0) / np.abs(s64[0])
    dop = lambda s: np.sqrt((s[1:] ** 2).sum(0)) / s[0]  # noqa: E731
    print(f"| precision | T·R·M update, {a.paths} paths × 4 λ | {a.depth}-vertex chain: max |ΔS|/S0 | max |ΔDoP| |")
    print("|---|---|---|---|")
    print(f"| float64 | {t64 * 1e3:.1f} ms | reference | reference |")
    print(f"| float32 | {t32 * 1e3:.1f} ms ({t64 / t32:.2f}× faster) | {rel.max():.1e} (median {np.median(rel):.1e}) "
          f"| {np.abs(dop(s64) - dop(s32)).max():.1e} |")


if __name__ == "__main__":
    main()
