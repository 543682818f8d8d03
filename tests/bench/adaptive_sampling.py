"""Adaptive vs uniform sampling: error × cost, bias, and whether the estimate predicts the cost.

    python tests/bench/adaptive_sampling.py [--res 64] [--ref-spp 2048] [--mitsuba-python PY]
                                            [--mitsuba-spp 8192] [--seeds 8] [--out out/adaptive]
                                            [--modes threshold,budget] [--mse-seeds 1] [--no-bias]
                                            [--no-prediction]

References.  glass_sphere and fresnel_sphere_au: two Mitsuba 3 renders (llvm_ad_spectral_polarized,
``--mitsuba-spp`` each, seeds 100 and 101, ../shared/peers/render_peer.py; cached in --out) when
``--mitsuba-python`` imports mitsuba, and always two uniform renders of ours (``--ref-spp`` each,
seeds 4242 and 4243); the demo scene: ours only.  A reference is the mean of its pair; the
pair's difference gives its own per-pixel noise ((y₁ − y₂)/2)², subtracted from every MSE, and the
per-sample variance of every pixel (part 0).  The DoLP MSE leaves out the pixels whose reference
S0 is below 1 % of the median (0 % of glass_sphere, 2.3 % of fresnel_sphere_au): rare-path pixels
whose DoLP no render of ≤ 512 spp resolves.  With a 10⁻³ cut, 15 pixels of fresnel_sphere_au at
1–2.5·10⁻³ of the median, DoLP ≈ 1 in Mitsuba's 2 × 8192 spp and 0 in ours at 16…256 spp (no path
found), held > 90 % of the DoLP MSE and kept it flat from 16 to 256 spp (4.3·10⁻³ → 3.4·10⁻³);
with the 1 % cut it falls 15× for 16× the samples, as Monte Carlo noise should.

Part 0 (what allocation can gain): from the reference pair, the per-sample variance v of S0 and of
DoLP per 4×4 tile and the pilot's cost c per pixel give the predicted MSE × time gain of the counts
the rule would give from a 16-spp first pass (engine.render.estimate.predict), and the bound
Σv·Σc/(Σ√(vc))² of any allocation (engine.render.estimate.mse_time_gain / best_mse_time_gain).

Part 1 (efficiency, both modes side by side in one run): uniform renders at 16, 64, 256 spp, adaptive
renders in **threshold mode** (--noise-threshold on s0 and on dolp, min 16, max 512 spp) and in **budget
mode** (--time-limit alone, quantity s0 and dolp, max 512 spp) with the time of the uniform 64 and 256 spp
renders: the 1-thread render's limit is in CPU seconds of this process (RenderRequest.clock =
time.process_time, robust to other jobs), the every-core render's in wall seconds.  Cost: rays traced (camera + bounce +
shadow rays: deterministic), CPU seconds of a 1-thread render (robust when other processes share
the machine) and wall seconds of a render on every core (what a user waits; noisy on a shared VM).
The equal-cost gain is the MSE of a uniform render of the same cost (log-log interpolation between
the uniform renders) ÷ the adaptive MSE (> 1: adaptive is better), in each of the three costs.
``--mse-seeds`` K averages every MSE of part 1 over K seeds (the costs are the first seed's, except
in budget mode: the mean of its K renders' costs): one render's DoLP MSE depends on the rare paths it
finds, by ±30 % on glass_sphere.  References (Mitsuba's and ours) are cached in --out.  A last table
puts the two modes side by side (CPU-second gains against the first reference).  The table ends with
the load average.

Part 1b (bias): ``--seeds`` adaptive renders (s0 threshold) with different seeds; for S0…S3 the
mean over seeds of the image sum against our reference's (z = difference ÷ its standard error from
the seeds' spread and the reference pair), and the mean z² over 8×8-pixel blocks (≈ (K−1)/(K−3)
for K seeds without bias: a t-distribution).

Part 2 (prediction; ``--prediction-only`` runs only this part): on three scenes, ``estimate``
(16-spp pilot, and a one-tile probe for the time of a round: engine.render.estimate.round_overhead)
predicts the median and 95th percentile of the samples per pixel and the wall time of an adaptive
render to a target; the render is then made and the ratios predicted/actual are printed (target:
within 1.5×).

Writes out/adaptive/table.md and the PNGs of the demo scene's noise image and sample map into
examples/images/ (adaptive_noise.png, adaptive_spp.png).  Not run by the tests (it times things).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import subprocess
import sys
import time
from dataclasses import dataclass

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, REPO)

from engine.output.colormaps import sequential  # noqa: E402
from engine.output.png import write_png  # noqa: E402
from engine.render.adaptive import AdaptiveSettings, film_noise, tile_ids  # noqa: E402
from engine.render.estimate import (best_mse_time_gain, mse_time_gain, pilot_render, predict,  # noqa: E402
                                    round_overhead)
from engine.render.renderer import Renderer, RenderRequest  # noqa: E402
from engine.scene.loader import load_scene  # noqa: E402
from engine.spectral.cie import LUMINANCE_WEIGHTS  # noqa: E402

SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
PEERS = os.path.join(SHARED, "peers")
MITSUBA_VARIANT = "llvm_ad_spectral_polarized"
#: Pixels whose reference S0 is below this fraction of the median are left out of the DoLP MSE.
DARK = 1e-2
MAX_SPP, MIN_SPP = 512, 16


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


@dataclass
class Reference:
    label: str
    y: np.ndarray            # luminance Stokes (4, H, W): mean of the pair
    var: np.ndarray          # per-pixel variance of that mean, S0…S3 (4, H, W)
    var_dolp: np.ndarray     # … of its DoLP (H, W)
    keep: np.ndarray         # pixels in the DoLP MSE (H, W)
    spp: int                 # samples per pixel of one render of the pair


def make_reference(label, y1, y2, spp):
    y = 0.5 * (y1 + y2)
    lit = y[0] > 0
    keep = y[0] >= DARK * (float(np.median(y[0][lit])) if lit.any() else 0.0)
    return Reference(label, y, ((y1 - y2) / 2) ** 2, ((dolp(y1) - dolp(y2)) / 2) ** 2, keep, spp)


def our_reference(renderer, scene, spp, name, outdir):
    """Two uniform renders of ours (seeds 4242, 4243), cached in ``outdir`` as luminance Stokes .npy."""
    ys = []
    for seed in (4242, 4243):
        cam = scene.camera
        path = os.path.join(outdir, f"{name}__polar__{cam.width}x{cam.height}__{spp}spp__seed{seed}_lum.npy")
        if not os.path.exists(path):
            st = dataclasses.replace(scene.settings, spp=spp, seed=seed)
            np.save(path, lum(renderer.render(st).stokes()))
        ys.append(np.load(path))
    return make_reference(f"ours {spp} spp ×2", ys[0], ys[1], spp)


def mitsuba_reference(python, name, spp, res, outdir):
    ys = []
    for seed in (100, 101):
        stem = f"{name}__{MITSUBA_VARIANT}__{res}x{res}__{spp}spp__seed{seed}"
        path = os.path.join(outdir, stem + ".npy")
        if not os.path.exists(path):
            subprocess.run([python, os.path.join(PEERS, "render_peer.py"), name, "--variant", MITSUBA_VARIANT,
                            "--spp", str(spp), "--res", str(res), "--seed", str(seed), "--out", outdir],
                           check=True, capture_output=True)
        ys.append(lum(np.load(path).astype(np.float64)))
    return make_reference(f"Mitsuba {spp} spp ×2", ys[0], ys[1], spp)


def mse(y, ref: Reference):
    """(MSE of S0, MSE of DoLP) of luminance Stokes ``y`` against ``ref``, less the reference's noise."""
    m_s0 = float(np.mean((y[0] - ref.y[0]) ** 2) - np.mean(ref.var[0]))
    m_dolp = float(np.mean(((dolp(y) - dolp(ref.y)) ** 2)[ref.keep]) - np.mean(ref.var_dolp[ref.keep]))
    return max(m_s0, 1e-300), max(m_dolp, 1e-300)


def timed(renderer, st, adaptive=None):
    t0 = time.perf_counter()
    result = renderer.render(RenderRequest(st, adaptive=adaptive))
    return result, time.perf_counter() - t0


#: 1-thread renders per measurement; the least CPU time counts (other processes on the same cores
#: inflate a process's CPU time too, through shared caches and execution units).
CPU_REPEATS = 2


def costed(renderer, st, adaptive=None):
    """(result, CPU seconds of a 1-thread render, wall seconds of a render on every core): CPU time of
    one thread is robust when other processes share the machine, wall time is what a user waits."""
    one = dataclasses.replace(st, threads=1)
    cpu = []
    for _ in range(CPU_REPEATS):
        c0 = time.process_time()
        result = renderer.render(RenderRequest(one, adaptive=adaptive))
        cpu.append(time.process_time() - c0)
    _, wall = timed(renderer, st, adaptive)
    return result, min(cpu), wall


def rays(result):
    return int(result.stats["rays"] + result.stats["shadow_rays"])


def uniform_mse_at(cost, costs, mses):
    """MSE of a uniform render costing ``cost``: log-log interpolation between the uniform renders'
    (cost, MSE), extrapolated with the slope of the nearest segment."""
    c, m = np.log(costs), np.log(mses)
    i = int(np.clip(np.searchsorted(c, np.log(cost)) - 1, 0, len(c) - 2))
    slope = (m[i + 1] - m[i]) / (c[i + 1] - c[i])
    return float(np.exp(m[i] + slope * (np.log(cost) - c[i])))


def allocation_gains(name, renderer, scene, ref: Reference, thresholds, rows):
    """Part 0: predicted gain of the rule's counts (from a 16-spp first pass) and the bound of any
    allocation, per threshold and MSE, with the reference pair's per-sample variance per tile."""
    H, W = ref.y.shape[1:]
    tiles = tile_ids(W, H)
    nt = int(tiles.max()) + 1

    def per_tile(v):
        return (np.bincount(tiles, v, nt) / np.bincount(tiles, None, nt))[tiles]
    # the variance of one render's pixel is 2 × that of the pair's mean; × spp: per sample
    v = {"S0": per_tile(2 * ref.spp * ref.var[0].ravel()),
         "DoLP": per_tile(np.where(ref.keep, 2 * ref.spp * ref.var_dolp, 0.0).ravel())}
    st = dataclasses.replace(scene.settings, spp=MAX_SPP, seed=7)
    pilot, cost = pilot_render(renderer, st, MIN_SPP)
    for quantity, threshold in thresholds:
        counts = predict(pilot.film, pilot.halves, quantity, threshold, MIN_SPP, MAX_SPP, cost).counts
        for label, var in v.items():
            rows.append((name, quantity, threshold, label, np.percentile(np.sqrt(var), [5, 50, 95]),
                         float(np.mean(counts >= MAX_SPP)), mse_time_gain(var, cost, counts),
                         best_mse_time_gain(var, cost), mse_time_gain(var, 1.0, counts), best_mse_time_gain(var, 1.0)))


def budgeted(renderer, st, quantity, cpu_budget, wall_budget):
    """Budget mode (a time limit without a threshold): (result of a 1-thread render whose time limit is
    ``cpu_budget`` CPU seconds of this process — RenderRequest.clock = process_time, so other jobs on the
    machine do not shorten it —, its CPU seconds, result of a render on every core limited to
    ``wall_budget`` wall seconds, its wall seconds).  Each is one render: a budget render's counts
    depend on the time, so there is no least of two."""
    one = dataclasses.replace(st, threads=1)
    ad = AdaptiveSettings(threshold=0.0, quantity=quantity, min_spp=MIN_SPP, time_limit=cpu_budget)
    c0 = time.process_time()
    result = renderer.render(RenderRequest(one, adaptive=ad, clock=time.process_time))
    cpu = time.process_time() - c0
    if wall_budget is None:
        return result, cpu, None, None
    t0 = time.perf_counter()
    wall_result = renderer.render(RenderRequest(st, adaptive=dataclasses.replace(ad, time_limit=wall_budget)))
    return result, cpu, wall_result, time.perf_counter() - t0


def equal_cost_gains(uniform, errs, costs):
    """[per reference: S0 (rays, CPU s, wall s), DoLP (rays, CPU s, wall s)] gains at equal cost: the
    uniform renders' MSE interpolated at each cost ÷ the MSE (``errs``: per cost column, per reference)."""
    gains = []
    for j in range(len(uniform[0][3])):
        g = []
        for k in (0, 1):
            for col, cost in enumerate(costs):
                g.append(uniform_mse_at(cost, [u[col] for u in uniform], [u[3][j][k] for u in uniform])
                         / errs[col][j][k])
        gains.append(g)
    return gains


def seed_mse(renderer, st, refs, result, seeds, adaptive=None):
    """[per reference: (MSE of S0, MSE of DoLP)] of ``result`` (seed 7) and of renders with the next
    ``seeds`` − 1 seeds, averaged: one render's DoLP MSE is dominated by the rare paths it happens to find."""
    errs = [[mse(lum(result.stokes()), r) for r in refs]]
    for k in range(1, seeds):
        other = renderer.render(RenderRequest(dataclasses.replace(st, seed=7 + k), adaptive=adaptive))
        errs.append([mse(lum(other.stokes()), r) for r in refs])
    return [tuple(float(np.mean([e[j][i] for e in errs])) for i in (0, 1)) for j in range(len(refs))]


def efficiency(name, renderer, scene, refs, thresholds, rows, modes=("threshold", "budget"), budget_spp=(64, 256),
               seeds=1):
    """Part 1: uniform renders, then threshold mode (one row per threshold) and budget mode (a time limit
    alone: per quantity, the time of the uniform renders of ``budget_spp``), side by side; MSEs averaged over
    ``seeds`` seeds (the costs are the first seed's)."""
    uniform = []
    for spp in (16, 64, 256):
        st = dataclasses.replace(scene.settings, spp=spp, seed=7)
        result, cpu, seconds = costed(renderer, st)
        uniform.append((rays(result), cpu, seconds, seed_mse(renderer, st, refs, result, seeds)))
        rows.append((name, "uniform", f"uniform {spp} spp", spp, cpu, seconds, rays(result), uniform[-1][3], None))
    st = dataclasses.replace(scene.settings, spp=MAX_SPP, seed=7)
    for quantity, threshold in thresholds if "threshold" in modes else ():
        ad = AdaptiveSettings(threshold=threshold, quantity=quantity, min_spp=MIN_SPP)
        result, cpu, seconds = costed(renderer, st, ad)
        errs = seed_mse(renderer, st, refs, result, seeds, ad)
        r_ = rays(result)
        gains = equal_cost_gains(uniform, [errs] * 3, (r_, cpu, seconds))
        rows.append((name, "threshold", f"{quantity} ≤ {threshold:g} ({result.stats['stop_reason']})",
                     float(result.film.count.mean()), cpu, seconds, r_, errs, gains))
        print(rows[-1], flush=True)
        if name == "demo" and quantity == "dolp":
            save_maps(result, quantity)
    for quantity in sorted({q for q, _ in thresholds}, reverse=True) if "budget" in modes else ():
        for spp in budget_spp:
            u = uniform[[16, 64, 256].index(spp)]
            result, cpu, wall_result, seconds = budgeted(renderer, st, quantity, u[1], u[2])
            errs = [[mse(lum(result.stokes()), r) for r in refs]]
            r_, cpus = [rays(result)], [cpu]
            for k in range(1, seeds):                # the same budget with other seeds: mean MSE and cost
                other, c_k, _, _ = budgeted(renderer, dataclasses.replace(st, seed=7 + k), quantity, u[1], None)
                errs.append([mse(lum(other.stokes()), r) for r in refs])
                r_.append(rays(other))
                cpus.append(c_k)
            errs = [tuple(float(np.mean([e[j][i] for e in errs])) for i in (0, 1)) for j in range(len(refs))]
            r_, cpu = float(np.mean(r_)), float(np.mean(cpus))
            wall_errs = [mse(lum(wall_result.stokes()), r) for r in refs]
            gains = equal_cost_gains(uniform, [errs, errs, wall_errs], (r_, cpu, seconds))
            rows.append((name, "budget", f"{quantity}, time of uniform {spp} spp ({result.stats['stop_reason']}, "
                                         f"{result.stats.get('adaptive_rounds', 0)} rounds)",
                         float(result.film.count.mean()), cpu, seconds, r_, errs, gains))
            print(rows[-1], flush=True)


def bias(name, renderer, scene, ref: Reference, threshold, seeds, rows):
    """Part 1b: S0…S3 of ``seeds`` adaptive renders (s0 ≤ threshold) against our reference."""
    ys = []
    for seed in range(seeds):
        st = dataclasses.replace(scene.settings, spp=MAX_SPP, seed=1000 + seed)
        ys.append(lum(renderer.render(RenderRequest(st, adaptive=AdaptiveSettings(threshold, "s0", MIN_SPP)))
                      .stokes()))
    ys = np.stack(ys)                                              # (K, 4, H, W)
    K = seeds
    H, W = ys.shape[2:]
    out = []
    for k in range(4):
        sums = ys[:, k].sum(axis=(1, 2))
        se2 = sums.var(ddof=1) / K + float(ref.var[k].sum())       # pixels' noise is independent
        diff = sums.mean() - float(ref.y[k].sum())
        z_image = diff / np.sqrt(se2) if se2 > 0 else 0.0
        b = 8
        blocks = ys[:, k, :H // b * b, :W // b * b].reshape(K, H // b, b, W // b, b).sum(axis=(2, 4))
        rblock = ref.y[k, :H // b * b, :W // b * b].reshape(H // b, b, W // b, b).sum(axis=(1, 3))
        rvar = ref.var[k, :H // b * b, :W // b * b].reshape(H // b, b, W // b, b).sum(axis=(1, 3))
        bse2 = blocks.var(axis=0, ddof=1) / K + rvar
        ok = bse2 > 0
        z2 = float(np.mean((blocks.mean(axis=0) - rblock)[ok] ** 2 / bse2[ok])) if ok.any() else 0.0
        rel = diff / abs(float(ref.y[0].sum()))
        out.append((z_image, z2, rel))
    rows.append((name, threshold, K, out))
    print(rows[-1], flush=True)


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
        renderer.render(scene.settings)           # warm-up
        st = dataclasses.replace(scene.settings, spp=1024, seed=11)
        pilot, sps = pilot_render(renderer, st, MIN_SPP)
        p = predict(pilot.film, pilot.halves, quantity, threshold, MIN_SPP, st.spp, sps,
                    round_seconds=round_overhead(renderer, st, pilot, sps, MIN_SPP))
        ad = AdaptiveSettings(threshold=threshold, quantity=quantity, min_spp=MIN_SPP)
        result, seconds = timed(renderer, st, ad)
        counts = result.film.count
        actual = (float(np.median(counts)), float(np.percentile(counts, 95)), seconds, int(counts.sum()))
        rows.append((name, quantity, threshold, p.median, actual[0], p.p95, actual[1], p.adaptive_seconds, actual[2],
                     int(p.counts.sum()), actual[3], p.uniform_spp, p.uniform_seconds, result.stats["stop_reason"]))
        print(rows[-1], flush=True)


def has_mitsuba(python):
    return bool(python) and os.path.exists(python) and subprocess.run(
        [python, "-c", "import mitsuba"], capture_output=True).returncode == 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--ref-spp", type=int, default=2048, help="samples of each of our two reference renders")
    ap.add_argument("--mitsuba-python", default=os.environ.get("MITSUBA_PYTHON", "/work/peerenv/bin/python"))
    ap.add_argument("--mitsuba-spp", type=int, default=8192, help="samples of each of the two Mitsuba references")
    ap.add_argument("--seeds", type=int, default=8, help="adaptive renders per scene for the bias check")
    ap.add_argument("--out", default=os.path.join(REPO, "out", "adaptive"))
    ap.add_argument("--prediction-only", action="store_true", help="part 2 only")
    ap.add_argument("--scenes", default="glass_sphere,fresnel_sphere_au,demo", help="scenes of parts 0–1b")
    ap.add_argument("--modes", default="threshold,budget",
                    help="adaptive modes of part 1: threshold (--noise-threshold) and/or budget (--time-limit alone)")
    ap.add_argument("--mse-seeds", type=int, default=1, help="seeds each MSE of part 1 is averaged over")
    ap.add_argument("--no-bias", action="store_true", help="skip part 1b")
    ap.add_argument("--no-prediction", action="store_true", help="skip part 2")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    modes = tuple(args.modes.split(","))
    thresholds = {"glass_sphere": [("s0", 0.02), ("s0", 0.05), ("dolp", 0.01), ("dolp", 0.03)],
                  "fresnel_sphere_au": [("s0", 0.01), ("s0", 0.005), ("dolp", 0.005), ("dolp", 0.002)],
                  "demo": [("s0", 0.02), ("dolp", 0.01)]}
    mitsuba = has_mitsuba(args.mitsuba_python)
    load_before = os.getloadavg()
    eff, gains, biases, labels = [], [], [], {}
    for name in [] if args.prediction_only else [n for n in thresholds if n in args.scenes.split(",")]:
        scene = load(name, args.res)
        renderer = Renderer(scene)
        renderer.render(scene.settings)          # warm-up (kernels)
        refs = [our_reference(renderer, scene, args.ref_spp, name, args.out)]
        if mitsuba and name != "demo":
            refs.insert(0, mitsuba_reference(args.mitsuba_python, name, args.mitsuba_spp, args.res, args.out))
        labels[name] = [r.label for r in refs]
        allocation_gains(name, renderer, scene, refs[-1], thresholds[name], gains)
        efficiency(name, renderer, scene, refs, thresholds[name], eff, modes, seeds=args.mse_seeds)
        if not args.no_bias:
            bias(name, renderer, scene, refs[-1], thresholds[name][0][1], args.seeds, biases)
    pred = []
    if not args.no_prediction:
        prediction([("glass_sphere", "dolp", 0.01), ("fresnel_sphere_au", "s0", 0.01), ("demo", "dolp", 0.01)],
                   args.res, pred)
    lines = ["| scene | threshold | MSE of | σ per tile p5 / p50 / p95 | tiles at max spp | predicted gain of the "
             "rule, measured cost / equal cost | bound, measured cost / equal cost |",
             "|---|---|---|---|---|---|---|"]
    for name, q, t, label, pct, capped, g, best, g_eq, best_eq in gains:
        lines.append(f"| {name} | {q} ≤ {t:g} | {label} | {pct[0]:.2g} / {pct[1]:.2g} / {pct[2]:.2g} | "
                     f"{100 * capped:.0f} % | {g:.2f}× / {g_eq:.2f}× | {best:.2f}× / {best_eq:.2f}× |")
    lines += ["", "| scene | reference | mode | sampling | mean spp | CPU s (1 thread) | wall s | Mrays | MSE S0 | "
              "MSE DoLP | equal-cost gain S0 (rays / CPU s / wall s) | equal-cost gain DoLP (rays / CPU s / wall s) |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, mode, label, spp, cpu, s, r, errs, g in eff:
        for j, ref_label in enumerate(labels[name]):
            m0, md = errs[j]
            gain = ("", "") if g is None else tuple(f"{g[j][3 * k]:.2f}× / **{g[j][3 * k + 1]:.2f}×** / "
                                                    f"{g[j][3 * k + 2]:.2f}×" for k in (0, 1))
            lines.append(f"| {name} | {ref_label} | {mode} | {label} | {spp:.1f} | {cpu:.2f} | {s:.2f} | "
                         f"{r / 1e6:.2f} | {m0:.3e} | {md:.3e} | {gain[0]} | {gain[1]} |")
    # both modes side by side: the CPU-second gain of S0 and of DoLP (first reference), per row
    lines += ["", "| scene | threshold mode: T (stop) — mean spp — gain S0 / DoLP (CPU s) | budget mode: the time of "
              "— mean spp — gain S0 / DoLP (CPU s) |", "|---|---|---|"]
    for name in labels:
        th = [row for row in eff if row[0] == name and row[1] == "threshold"]
        bu = [row for row in eff if row[0] == name and row[1] == "budget"]
        for i in range(max(len(th), len(bu))):
            cells = []
            for part in (th, bu):
                if i < len(part):
                    _, _, label, spp, _, _, _, _, g = part[i]
                    cells.append(f"{label} — {spp:.1f} — **{g[0][1]:.2f}× / {g[0][4]:.2f}×**")
                else:
                    cells.append("")
            lines.append(f"| {name} | {cells[0]} | {cells[1]} |")
    lines += ["", "| scene | adaptive s0 ≤ | seeds | z of the image sum S0 / S1 / S2 / S3 | mean z² over 8×8 "
              "blocks S0 / S1 / S2 / S3 | image-sum difference ÷ ΣS0, S0 / S1 / S2 / S3 |", "|---|---|---|---|---|---|"]
    for name, t, K, out in biases:
        lines.append(f"| {name} | {t:g} | {K} | " + " / ".join(f"{z:+.2f}" for z, _, _ in out) + " | "
                     + " / ".join(f"{z2:.2f}" for _, z2, _ in out) + " | "
                     + " / ".join(f"{rel:+.1e}" for _, _, rel in out) + " |")
    lines += ["", "| scene | target | median spp predicted / actual | p95 spp predicted / actual | "
              "seconds predicted / actual | samples predicted / actual | uniform (predicted) | stop |",
              "|---|---|---|---|---|---|---|---|"]
    for (name, q, t, pm, am, pp, ap95, ps, as_, pn, an, us, useconds, stop) in pred:
        lines.append(f"| {name} | {q} ≤ {t:g} | {pm:.0f} / {am:.0f} ({pm / am:.2f}×) | {pp:.0f} / {ap95:.0f} "
                     f"({pp / ap95:.2f}×) | {ps:.1f} / {as_:.1f} ({ps / as_:.2f}×) | {pn} / {an} ({pn / an:.2f}×) | "
                     f"{us} spp, {useconds:.1f} s | {stop} |")
    lines += ["", f"Load average (1 / 5 / 15 min) at the start: {' / '.join(f'{v:.2f}' for v in load_before)}, "
                  f"at the end: {' / '.join(f'{v:.2f}' for v in os.getloadavg())} ({os.cpu_count()} cores)."]
    table = "\n".join(lines)
    with open(os.path.join(args.out, "table.md"), "w") as fh:
        fh.write(table + "\n")
    print(table)


if __name__ == "__main__":
    main()
