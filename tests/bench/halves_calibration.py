"""Calibration of the half-split error estimate: estimated ÷ true error of uniform renders, per quantity and spp.

    python tests/bench/halves_calibration.py [--res 64] [--spps 16,32,64,128,256] [--seeds 4]
                                             [--scenes glass_sphere,fresnel_sphere_au,rough_sphere_a030,demo]
                                             [--halves one_sequence,independent] [--ref-spp 2048] [--out out/adaptive]

For every scene, spp and ``halves`` mode, ``--seeds`` uniform renders (the default sampler) keep the luminance sums
of the two sample classes (engine.render.halves); the **raw** estimate of a pixel's error is the half-split one
the adaptive rule starts from — ``s0``: ½|Y_A − Y_B| (absolute luminance), ``dolp``: ½|DoLP_A − DoLP_B| — taken
without the calibration factor, and the **true** error is the render's difference from our reference (two
uniform renders of ``--ref-spp`` each, as tests/bench/adaptive_sampling.py makes and caches them, their own noise
subtracted).  Printed per scene, quantity and spp: the ratio √(mean est²) ÷ √(mean true² − reference noise) over
the image (the DoLP over pixels whose reference S0 is ≥ 1 % of the median, as the adaptive benchmark), and the
10th / 50th / 90th percentiles of the same ratio per 4×4 tile (the seeds pooled).  With independent halves the
ratio is 1 in expectation (the check of the method); with one sequence it is the factor the estimate misjudges
the error by (engine.render.halves.ERROR_FACTOR is its inverse).  Not run by the tests.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, REPO)

from engine.render.adaptive import tile_ids  # noqa: E402
from engine.render.halves import class_counts  # noqa: E402
from engine.render.renderer import Renderer  # noqa: E402
from tests.bench.adaptive_sampling import dolp, load, lum, our_reference  # noqa: E402


def raw_class_means(film, halves):
    """Class A and B luminance Stokes means (4, n) without the calibration factor."""
    n_a, n_b = class_counts(film.count, halves)
    return film.half_y[0] / np.maximum(n_a, 1), film.half_y[1] / np.maximum(n_b, 1)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spps", default="16,32,64,128,256")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--scenes", default="glass_sphere,fresnel_sphere_au,rough_sphere_a030,demo")
    ap.add_argument("--halves", default="one_sequence,independent")
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--out", default=os.path.join(REPO, "out", "adaptive"))
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    print(f"load average at the start: {os.getloadavg()}")
    rows = []
    for name in args.scenes.split(","):
        scene = load(name, args.res)
        renderer = Renderer(scene)
        ref = our_reference(renderer, scene, args.ref_spp, name, args.out)
        H, W = ref.y.shape[1:]
        tiles = tile_ids(W, H)
        nt = int(tiles.max()) + 1
        keep = ref.keep.reshape(-1)
        ref_y, ref_d = ref.y.reshape(4, -1), dolp(ref.y).reshape(-1)
        for halves in args.halves.split(","):
            for spp in (int(s) for s in args.spps.split(",")):
                est = {"s0": [], "dolp": []}
                true = {"s0": [], "dolp": []}
                for seed in range(args.seeds):
                    st = dataclasses.replace(scene.settings, spp=spp, seed=1000 + seed, halves=halves)
                    film = renderer.render(st).film
                    a, b = raw_class_means(film, halves)
                    y = lum(film.mean()).reshape(4, -1)
                    est["s0"].append((0.5 * (a[0] - b[0])) ** 2)
                    true["s0"].append((y[0] - ref_y[0]) ** 2 - ref.var[0].reshape(-1))
                    da = dolp(a[:, None, :])[0]
                    db = dolp(b[:, None, :])[0]
                    est["dolp"].append(np.where(keep, (0.5 * (da - db)) ** 2, 0.0))
                    true["dolp"].append(np.where(keep, (dolp(y[:, None, :])[0] - ref_d) ** 2
                                                 - ref.var_dolp.reshape(-1), 0.0))
                for q in ("s0", "dolp"):
                    e, t = np.mean(est[q], axis=0), np.mean(true[q], axis=0)
                    mask = np.ones(W * H, bool) if q == "s0" else keep
                    ratio = float(np.sqrt(e[mask].mean() / max(t[mask].mean(), 1e-300)))
                    te = np.bincount(tiles, np.where(mask, e, 0.0), nt)
                    tt = np.bincount(tiles, np.where(mask, t, 0.0), nt)
                    ok = tt > 0
                    tr = np.sqrt(te[ok] / tt[ok])
                    p10, p50, p90 = np.percentile(tr, [10, 50, 90]) if tr.size else (np.nan,) * 3
                    rows.append((name, halves, q, spp, ratio, p10, p50, p90))
                    print(f"{name:18s} {halves:13s} {q:5s} {spp:4d} spp: est/true {ratio:.3f}  tiles p10/50/90 "
                          f"{p10:.2f} / {p50:.2f} / {p90:.2f}", flush=True)
    print("\n| scene | halves | quantity | " + " | ".join(f"{s} spp" for s in args.spps.split(",")) + " |")
    print("|---|---|---|" + "---|" * len(args.spps.split(",")))
    keys = sorted({r[:3] for r in rows}, key=lambda k: [r[:3] for r in rows].index(k))
    for k in keys:
        cells = [f"{r[4]:.2f} ({r[6]:.2f})" for r in rows if r[:3] == k]
        print(f"| {k[0]} | {k[1]} | {k[2]} | " + " | ".join(cells) + " |")
    print("(image est/true; in brackets the median over 4×4 tiles)")
    print(f"load average at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
