"""Adaptive vs uniform sampling: error × time, and whether the estimate predicts the cost.

    python tests/bench/adaptive_sampling.py [--res 64] [--ref-spp 1024] [--out out/adaptive]

Part 1 (efficiency): for glass_sphere, fresnel_sphere_au and the demo scene, uniform renders at
16, 64, 256 spp and adaptive renders (threshold on s0 and on dolp, min 16, max 512 spp) are
compared with a high-spp render of ours (another seed; Mitsuba is used by accuracy_time.py but is
not needed here).  The reference's own noise, estimated from its even/odd half-buffers, is
subtracted from each MSE.  The DoLP MSE leaves out the pixels whose reference S0 is below 10⁻³ of
the median (< 1 % of the pixels: rare-path pixels whose DoLP is one or two samples' DoLP, 0 in a
render that missed them — they held > 95 % of the DoLP MSE and made it flat in spp).  Cost: wall
seconds (on a shared VM: noisy) and rays traced (camera + shadow rays: deterministic).  Figure of
merit: MSE × cost (lower is better; for unbiased Monte Carlo it is constant in spp), and the
equal-cost gain: the MSE of a uniform render of the same number of rays (log-log interpolation
between the uniform renders) ÷ the adaptive MSE (> 1: adaptive is better).

Part 0 (what allocation can gain): from the reference's half-buffers, the per-sample variance v of
S0 and DoLP per 4×4 tile and the pilot's cost c per pixel give the predicted gain in MSE × time
of the threshold rule's counts and the bound Σv·Σc/(Σ√(vc))² of any allocation
(engine.render.estimate.mse_time_gain / best_mse_time_gain), and the spread of σ = √v.

Part 2 (prediction): on three scenes, ``estimate`` (16-spp pilot) predicts the median and 95th
percentile of the samples per pixel and the wall time of an adaptive render to a target; the
render is then made and the ratios predicted/actual are printed (target: within 1.5×).

Writes out/adaptive/table.md and the PNGs of the demo scene's noise image and sample map into
examples/images/ (adaptive_noise.png, adaptive_spp.png).  Not run by the tests (it times things).
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, REPO)

from engine.output.colormaps import sequential  # noqa: E402
from engine.output.png import write_png  # noqa: E402
from engine.render.adaptive import AdaptiveSettings, film_noise, tile_ids  # noqa: E402
from engine.render.estimate import best_mse_time_gain, mse_time_gain, pilot_render, predict  # noqa: E402
from engine.render.renderer import Renderer  # noqa: E402
from engine.scene.loader import load_scene  # noqa: E402
from engine.spectral.cie import LUMINANCE_WEIGHTS  # noqa: E402

SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
PEERS = os.path.join(SHARED, "peers")


def load(name, res):
    if name == "demo":
        scene = load_scene(os.path.join(REPO, "examples", "demo.json"))
        scene.camera.width, scene.camera.height = 2 * res, res
    else:
        scene = load_scene(os.path.join(PEERS, "scenes", f"{name}.json"))
        scene.camera.width = scene.camera.height = res
    return scene


def lum(stokes_rgb):
    return np.einsum("shwc,c->shw", stokes_rgb, LUMINANCE_WEIGHTS)


def dolp(y):
    return np.where(y[0] > 0, np.hypot(y[1], y[2]) / np.where(y[0] > 0, y[0], 1.0), 0.0)


#: Pixels whose reference S0 is below this fraction of the median are left out of the DoLP MSE.
DARK = 1e-3


def reference(renderer, scene, spp):
    """(luminance Stokes (4, H, W), per-pixel noise variance of S0 and of DoLP, pixels kept for the
    DoLP MSE (H, W), the RenderResult) at ``spp``, seed 4242."""
    st = copy.copy(scene.settings)
    st.spp, st.seed = spp, 4242
    result = renderer.render(st, adaptive=AdaptiveSettings(threshold=0.0, quantity="s0", min_spp=spp))
    y = lum(result.stokes())
    a, b = result.halves.means(result.film.count)
    var_s0 = ((a[0] - b[0]) / 2) ** 2                       # (½|A − B|)² estimates the variance of the mean
    var_dolp = ((dolp(a) - dolp(b)) / 2) ** 2
    H, W = y.shape[1:]
    lit = y[0] > 0
    keep = y[0] >= DARK * (float(np.median(y[0][lit])) if lit.any() else 0.0)
    return y, var_s0.reshape(H, W), var_dolp.reshape(H, W), keep, result


def mse(y, ref):
    ry, var_s0, var_dolp, keep, _ = ref
    m_s0 = float(np.mean((y[0] - ry[0]) ** 2) - np.mean(var_s0))
    m_dolp = float(np.mean(((dolp(y) - dolp(ry)) ** 2)[keep]) - np.mean(var_dolp[keep]))
    return max(m_s0, 0.0), max(m_dolp, 0.0)


def timed(renderer, st, adaptive=None):
    t0 = time.perf_counter()
    result = renderer.render(st, adaptive=adaptive)
    return result, time.perf_counter() - t0


def rays(result):
    return int(result.stats["rays"] + result.stats["shadow_rays"])


def uniform_mse_at(cost, uniform, k):
    """MSE (column k) of a uniform render costing ``cost`` rays: log-log interpolation between the
    uniform (rays, mse…) rows, extrapolated with the slope of the nearest segment."""
    c = np.log([u[0] for u in uniform])
    m = np.log([max(u[k], 1e-300) for u in uniform])
    i = int(np.clip(np.searchsorted(c, np.log(cost)) - 1, 0, len(c) - 2))
    slope = (m[i + 1] - m[i]) / (c[i + 1] - c[i])
    return float(np.exp(m[i] + slope * (np.log(cost) - c[i])))


def allocation_gains(name, renderer, scene, ref, thresholds, rows):
    """Part 0: predicted gains of the threshold rule and the bound of any allocation, per quantity."""
    result = ref[4]
    film, n = result.film, result.film.count.astype(np.float64)
    a, b = result.halves.means(film.count)
    tiles = tile_ids(film.width, film.height)
    nt = int(tiles.max()) + 1

    def per_tile(v):
        return (np.bincount(tiles, v, nt) / np.bincount(tiles, None, nt))[tiles]
    keep = ref[3].ravel()
    v = {"S0": per_tile(n * ((a[0] - b[0]) / 2) ** 2),
         "DoLP": per_tile(np.where(keep, n * ((dolp(a) - dolp(b)) / 2) ** 2, 0.0))}
    st = copy.copy(scene.settings)
    st.spp, st.seed = 512, 9
    _, cost = pilot_render(renderer, st, 16)
    for quantity, threshold in thresholds:
        counts = predict(film, result.halves, quantity, threshold, 16, 512, cost).counts
        for label, var in v.items():
            sigma = np.sqrt(var)
            rows.append((name, quantity, threshold, label,
                         np.percentile(sigma, [5, 50, 95]), float(np.mean(counts >= 512)),
                         mse_time_gain(var, cost, counts), best_mse_time_gain(var, cost),
                         best_mse_time_gain(var, 1.0)))


def efficiency(names, res, ref_spp, thresholds, rows, gains):
    for name in names:
        scene = load(name, res)
        renderer = Renderer(scene)
        renderer.render(copy.copy(scene.settings))          # warm-up (kernels)
        ref = reference(renderer, scene, ref_spp)
        allocation_gains(name, renderer, scene, ref, thresholds[name], gains)
        uniform = []
        for spp in (16, 64, 256):
            st = copy.copy(scene.settings)
            st.spp, st.seed = spp, 7
            result, seconds = timed(renderer, st)
            m0, md = mse(lum(result.stokes()), ref)
            uniform.append((rays(result), m0, md))
            rows.append((name, f"uniform {spp} spp", spp, seconds, rays(result), m0, md, None, None))
        for quantity, threshold in thresholds[name]:
            st = copy.copy(scene.settings)
            st.spp, st.seed = 512, 7
            ad = AdaptiveSettings(threshold=threshold, quantity=quantity, min_spp=16)
            result, seconds = timed(renderer, st, ad)
            m0, md = mse(lum(result.stokes()), ref)
            mean_spp = float(result.film.count.mean())
            r = rays(result)
            rows.append((name, f"adaptive {quantity} ≤ {threshold:g} ({result.stats['stop_reason']})", mean_spp,
                         seconds, r, m0, md, uniform_mse_at(r, uniform, 1) / max(m0, 1e-300),
                         uniform_mse_at(r, uniform, 2) / max(md, 1e-300)))
            print(rows[-1], flush=True)
            if name == "demo" and quantity == "dolp":
                save_maps(result, quantity)


def save_maps(result, quantity):
    film = result.film
    err = film_noise(film, result.halves, quantity)[0].reshape(film.height, film.width)
    err = np.where(np.isfinite(err), err, 0.0)
    images = os.path.join(REPO, "examples", "images")
    scale = max(float(np.percentile(err, 99)), 1e-12)
    write_png(os.path.join(images, "adaptive_noise.png"), upscale(sequential(np.clip(err / scale, 0, 1))))
    counts = film.spp_image().astype(np.float64)
    t = np.log2(counts / counts.min()) / max(np.log2(counts.max() / counts.min()), 1e-12)
    write_png(os.path.join(images, "adaptive_spp.png"), upscale(sequential(t)))
    print(f"noise image: 0 … {scale:.3g} (99th percentile); sample map: log2, {counts.min():.0f} … "
          f"{counts.max():.0f} spp", flush=True)


def upscale(img, k=3):
    return np.repeat(np.repeat(img, k, axis=0), k, axis=1)


def prediction(cases, res, rows):
    for name, quantity, threshold in cases:
        scene = load(name, res)
        renderer = Renderer(scene)
        renderer.render(copy.copy(scene.settings))           # warm-up
        st = copy.copy(scene.settings)
        st.spp, st.seed = 1024, 11
        pilot, sps = pilot_render(renderer, st, 16)
        p = predict(pilot.film, pilot.halves, quantity, threshold, 16, st.spp, sps)
        ad = AdaptiveSettings(threshold=threshold, quantity=quantity, min_spp=16)
        result, seconds = timed(renderer, st, ad)
        counts = result.film.count
        actual = (float(np.median(counts)), float(np.percentile(counts, 95)), seconds, int(counts.sum()))
        rows.append((name, quantity, threshold, p.median, actual[0], p.p95, actual[1], p.adaptive_seconds, actual[2],
                     int(p.counts.sum()), actual[3], p.uniform_spp, p.uniform_seconds, result.stats["stop_reason"]))
        print(rows[-1], flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--out", default=os.path.join(REPO, "out", "adaptive"))
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    thresholds = {"glass_sphere": [("s0", 0.02), ("dolp", 0.01)],
                  "fresnel_sphere_au": [("s0", 0.01), ("dolp", 0.005)],
                  "demo": [("s0", 0.02), ("dolp", 0.01)]}
    eff, gains = [], []
    efficiency(list(thresholds), args.res, args.ref_spp, thresholds, eff, gains)
    pred = []
    prediction([("glass_sphere", "dolp", 0.01), ("fresnel_sphere_au", "s0", 0.01), ("demo", "dolp", 0.01)],
               args.res, pred)
    lines = ["| scene | threshold | σ per tile p5 / p50 / p95 | tiles at max spp | predicted gain of the "
             "threshold rule | bound, measured cost | bound, equal cost |", "|---|---|---|---|---|---|---|"]
    for name, q, t, label, pct, capped, g, best, best_eq in gains:
        lines.append(f"| {name} | {q} ≤ {t:g}, MSE of {label} | {pct[0]:.2g} / {pct[1]:.2g} / {pct[2]:.2g} | "
                     f"{100 * capped:.0f} % | {g:.2f}× | {best:.2f}× | {best_eq:.2f}× |")
    lines += ["", "| scene | sampling | mean spp | seconds | Mrays | MSE S0 | MSE × Mrays (S0) | MSE DoLP | "
              "MSE × Mrays (DoLP) | equal-cost gain S0 / DoLP |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, label, spp, s, r, m0, md, g0, gd in eff:
        gain = "" if g0 is None else f"{g0:.2f}× / {gd:.2f}×"
        lines.append(f"| {name} | {label} | {spp:.1f} | {s:.2f} | {r / 1e6:.2f} | {m0:.3e} | {m0 * r / 1e6:.3e} | "
                     f"{md:.3e} | {md * r / 1e6:.3e} | {gain} |")
    lines += ["", "| scene | target | median spp predicted / actual | p95 spp predicted / actual | "
              "seconds predicted / actual | samples predicted / actual | uniform (predicted) | stop |",
              "|---|---|---|---|---|---|---|---|"]
    for (name, q, t, pm, am, pp, ap95, ps, as_, pn, an, us, useconds, stop) in pred:
        lines.append(f"| {name} | {q} ≤ {t:g} | {pm:.0f} / {am:.0f} ({pm / am:.2f}×) | {pp:.0f} / {ap95:.0f} "
                     f"({pp / ap95:.2f}×) | {ps:.1f} / {as_:.1f} ({ps / as_:.2f}×) | {pn} / {an} ({pn / an:.2f}×) | "
                     f"{us} spp, {useconds:.1f} s | {stop} |")
    table = "\n".join(lines)
    with open(os.path.join(args.out, "table.md"), "w") as fh:
        fh.write(table + "\n")
    print(table)


if __name__ == "__main__":
    main()
