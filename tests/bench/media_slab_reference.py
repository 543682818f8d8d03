"""Polar's Rayleigh slabs against the vector adding–doubling reference, with many samples.

    python tests/bench/media_slab_reference.py [--size 64] [--spp 256] [--seeds 2]

The slabs and views of tests/render/test_media_slab_reference.py (SLABS), rendered with ``seeds`` independent
seeds of size² pixels × spp; prints per view the solver's (I, Q, U), Polar's, their difference in standard
errors (from the pixels of all seeds) and the relative difference of I.  Not part of the test command.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(os.path.dirname(HERE)))

from tests.render.test_media_slab_reference import SLABS, polar_stokes, reference, slab_scene  # noqa: E402
from tests.support.adding_doubling import Slab  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--seeds", type=int, default=2)
    args = ap.parse_args()
    print(f"{'slab':14s} {'view':>14s}  {'reference I, Q, U':>30s}  {'Polar I, Q, U':>30s}  "
          f"{'z (I, Q, U)':>20s}  ΔI/I")
    for name, (tau, omega, delta, sun, views) in SLABS.items():
        mu0 = np.cos(np.radians(sun))
        slab = Slab(tau, omega, delta, extra_mu=[mu0] + [np.cos(np.radians(v[0])) for v in views], nodes=24)
        for view in views:
            runs = [polar_stokes(slab_scene(tau, omega, delta, sun, view, args.size, args.spp, seed=s))
                    for s in range(args.seeds)]
            m = np.mean([r[0] for r in runs], axis=0)
            e = np.sqrt(np.sum([r[1] ** 2 for r in runs], axis=0)) / len(runs)
            ref = reference(slab, view, mu0)
            z = (m[:3] - ref[:3]) / e[:3]
            fmt = " ".join(f"{v:9.5f}" for v in ref[:3]), " ".join(f"{v:9.5f}" for v in m[:3])
            print(f"{name:14s} {str(view):>14s}  {fmt[0]:>30s}  {fmt[1]:>30s}  "
                  f"{' '.join(f'{v:6.2f}' for v in z):>20s}  {(m[0] - ref[0]) / ref[0]:+.4f}")


if __name__ == "__main__":
    main()
