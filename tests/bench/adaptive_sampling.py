"""Adaptive vs uniform sampling: error × time, and whether the estimate predicts the cost.

    python tests/bench/adaptive_sampling.py [--res 64] [--ref-spp 1024] [--out out/adaptive]

Part 1 (efficiency): for glass_sphere, fresnel_sphere_au and the demo scene, uniform renders at
16, 64, 256 spp and adaptive renders (threshold on s0 and on dolp, min 16, max 512 spp) are
compared with a high-spp render of ours (another seed; Mitsuba is used by accuracy_time.py but is
not needed here).  The reference's own noise, estimated from its even/odd half-buffers, is
subtracted from each MSE.  Figure of merit: MSE × seconds (lower is better; for unbiased Monte
Carlo it is constant in spp, so it compares efficiencies independently of the sample count).

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
from engine.render.adaptive import AdaptiveSettings, film_noise  # noqa: E402
from engine.render.estimate import pilot_render, predict  # noqa: E402
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


def reference(renderer, scene, spp):
    """(luminance Stokes (4, H, W), per-pixel noise variance of S0 and of DoLP) at ``spp``, seed 4242."""
    st = copy.copy(scene.settings)
    st.spp, st.seed = spp, 4242
    result = renderer.render(st, adaptive=AdaptiveSettings(threshold=0.0, quantity="s0", min_spp=spp))
    y = lum(result.stokes())
    a, b = result.halves.means(result.film.count)
    var_s0 = ((a[0] - b[0]) / 2) ** 2                       # (½|A − B|)² estimates the variance of the mean
    var_dolp = ((dolp(a) - dolp(b)) / 2) ** 2
    H, W = y.shape[1:]
    return y, var_s0.reshape(H, W), var_dolp.reshape(H, W)


def mse(y, ref):
    ry, var_s0, var_dolp = ref
    m_s0 = float(np.mean((y[0] - ry[0]) ** 2) - np.mean(var_s0))
    m_dolp = float(np.mean((dolp(y) - dolp(ry)) ** 2) - np.mean(var_dolp))
    return max(m_s0, 0.0), max(m_dolp, 0.0)


def timed(renderer, st, adaptive=None):
    t0 = time.perf_counter()
    result = renderer.render(st, adaptive=adaptive)
    return result, time.perf_counter() - t0


def efficiency(names, res, ref_spp, thresholds, rows):
    for name in names:
        scene = load(name, res)
        renderer = Renderer(scene)
        renderer.render(copy.copy(scene.settings))          # warm-up (kernels)
        ref = reference(renderer, scene, ref_spp)
        for spp in (16, 64, 256):
            st = copy.copy(scene.settings)
            st.spp, st.seed = spp, 7
            result, seconds = timed(renderer, st)
            m0, md = mse(lum(result.stokes()), ref)
            rows.append((name, f"uniform {spp} spp", spp, seconds, m0, md))
        for quantity, threshold in thresholds[name]:
            st = copy.copy(scene.settings)
            st.spp, st.seed = 512, 7
            ad = AdaptiveSettings(threshold=threshold, quantity=quantity, min_spp=16)
            result, seconds = timed(renderer, st, ad)
            m0, md = mse(lum(result.stokes()), ref)
            mean_spp = float(result.film.count.mean())
            rows.append((name, f"adaptive {quantity} ≤ {threshold:g} ({result.stats['stop_reason']})", mean_spp,
                         seconds, m0, md))
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
    eff = []
    efficiency(list(thresholds), args.res, args.ref_spp, thresholds, eff)
    pred = []
    prediction([("glass_sphere", "dolp", 0.01), ("fresnel_sphere_au", "s0", 0.01), ("demo", "dolp", 0.01)],
               args.res, pred)
    lines = ["| scene | sampling | mean spp | seconds | MSE S0 | MSE × s (S0) | MSE DoLP | MSE × s (DoLP) |",
             "|---|---|---|---|---|---|---|---|"]
    for name, label, spp, s, m0, md in eff:
        lines.append(f"| {name} | {label} | {spp:.1f} | {s:.2f} | {m0:.3e} | {m0 * s:.3e} | {md:.3e} | {md * s:.3e} |")
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
