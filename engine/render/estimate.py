"""Predicting what an accuracy costs: samples per pixel and wall time, before rendering.

A short pilot render (every pixel ``pilot_spp`` samples, with the half-buffers of adaptive
sampling) gives each tile's error e at n = pilot_spp samples.  The standard error of a Monte Carlo
mean falls as 1/√spp, so the tile needs m = n·(e/T)² samples to reach the threshold T; adaptive
sampling stops it at the first checkpoint ≥ m (engine.render.adaptive.checkpoints), within
[min_spp, spp], or earlier at its share of the error at equal cost, n = σ/(μ·w)
(engine.render.adaptive: w = √(c/c̄) from the tile's cost per sample; for the polarisation
quantities e and σ are pooled with the tile's neighbourhood, as in the render).  A uniform render needs the
largest m of all tiles for every pixel.  Wall time = Σ over pixels of samples × that pixel's seconds
per sample on this machine, a per-tile cost map (:func:`cost_map`): the pilot is cut into units of
≥ 1024 pixels whose seconds per unit of cost are measured, and each 4×4 tile costs its own cost per
sample (:func:`tile_cost_per_sample`) × its unit's seconds per unit of cost — the pixels that need many samples,
glass and edges, are also the expensive ones.  The same prediction is made from the
first pass (``min_spp`` everywhere) of an adaptive render and printed beside what happened.

**Is adaptive worth it?** With per-sample variance v and cost c per pixel, n samples give the
quantity an MSE of mean(v/n) in Σ c·n seconds; a uniform render's MSE × time is mean(v)·Σc whatever
its spp.  :func:`mse_time_gain` is the ratio.  Rendering every tile *to the threshold* gives
n ∝ v, whose MSE × time is mean(c·v)·N — with equal costs exactly the uniform one (gain 1): the
gain comes only from the tiles held at ``min_spp`` or ``spp``.  The allocation with the least
MSE × time is n ∝ √(v/c) (Lagrange), gain Σv·Σc / (Σ√(v·c))² ≥ 1 (:func:`best_mse_time_gain`),
a bound no allocation exceeds.  v is estimated per tile as e²·n (e: tile error at n samples).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from .adaptive import (QUANTITIES, TILE, UNITS, AdaptiveSettings, allocation_from, checkpoints, film_noise,
                       ladder_of,
                       pooled_error, tile_cost, tile_ids)
from .plan import RenderRequest


@dataclass
class Prediction:
    quantity: str
    threshold: float
    counts: np.ndarray            # predicted samples per pixel of the adaptive render (window pixels)
    uniform_spp: int              # samples per pixel a uniform render needs (the worst tile)
    uniform_p95_spp: int          # … to bring 95 % of the pixels below the threshold
    seconds_per_sample: np.ndarray   # per pixel (or one number for all)
    capped: float                 # fraction of pixels that would stop at the maximum spp, not the threshold
    variance: np.ndarray | None = None   # per-sample variance of the quantity per pixel (tile e²·n), its units²
    rounds: int = 0               # adaptive rounds after the first pass (one per checkpoint up to the largest count)
    round_seconds: float = 0.0    # seconds of one round besides its samples (:func:`round_overhead`)

    @property
    def median(self) -> float:
        return float(np.median(self.counts))

    @property
    def p95(self) -> float:
        return float(np.percentile(self.counts, 95))

    @property
    def adaptive_seconds(self) -> float:
        return float(np.sum(self.counts * self.seconds_per_sample)) + self.rounds * self.round_seconds

    @property
    def uniform_seconds(self) -> float:
        return float(np.sum(np.broadcast_to(self.seconds_per_sample, self.counts.shape))) * self.uniform_spp

    @property
    def gain(self) -> float:
        """Predicted MSE × time of the quantity, uniform ÷ adaptive (> 1: adaptive is better)."""
        return mse_time_gain(self.variance, self.seconds_per_sample, self.counts)

    @property
    def best_gain(self) -> float:
        """The largest gain any allocation of samples could reach on this image."""
        return best_mse_time_gain(self.variance, self.seconds_per_sample)

    def describe(self) -> str:
        gain = self.gain if self.variance is not None else math.nan
        return (f"{self.quantity} ≤ {self.threshold:g} ({UNITS[self.quantity]}): adaptive median "
                f"{self.median:.0f} spp, 95th percentile {self.p95:.0f} spp, {self.adaptive_seconds:.1f} s; "
                f"uniform {self.uniform_spp} spp, {self.uniform_seconds:.1f} s "
                f"(for 95 % of the pixels: {self.uniform_p95_spp} spp)"
                + (f"; {100 * self.capped:.0f} % of pixels would stop at the maximum spp" if self.capped >= 0.005
                   else "")
                + (f"; MSE × time of {self.quantity} {gain:.2f}× better than uniform (best possible "
                   f"allocation {self.best_gain:.2f}×)" if math.isfinite(gain) else ""))


def _broadcast(variance, seconds_per_sample, counts=None):
    v = np.asarray(variance, np.float64)
    c = np.broadcast_to(np.asarray(seconds_per_sample, np.float64), v.shape)
    n = None if counts is None else np.broadcast_to(np.asarray(counts, np.float64), v.shape)
    return v, c, n


def mse_time_gain(variance, seconds_per_sample, counts) -> float:
    """MSE × time of a uniform render ÷ that of ``counts`` samples per pixel (arrays over pixels;
    ``variance``: per-sample variance, ``seconds_per_sample``: cost).  NaN where undefined (no noise)."""
    v, c, n = _broadcast(variance, seconds_per_sample, counts)
    den = float(np.mean(v / n) * np.sum(c * n))
    return float(np.mean(v) * np.sum(c)) / den if den > 0 else math.nan


def best_mse_time_gain(variance, seconds_per_sample) -> float:
    """The gain of the optimal allocation n ∝ √(v/c): Σv·Σc / (Σ√(v·c))² (Cauchy–Schwarz: ≥ 1)."""
    v, c, _ = _broadcast(variance, seconds_per_sample)
    den = float(np.sum(np.sqrt(v * c)) ** 2)
    return float(np.sum(v) * np.sum(c)) / den if den > 0 else math.nan


def tile_cost_per_sample(film, halves) -> np.ndarray:
    """Cost per sample of every pixel's tile (H·W,) (:attr:`~engine.render.film.HalfBuffers.cost`
    ÷ samples, summed over the tile; 0 where the tile has no sample or no cost was counted)."""
    return tile_cost(halves.cost, film.count, tile_ids(film.width, film.height), np.arange(film.count.size))


def cost_map(unit_times, n_pixels: int, seconds: float, cost_per_sample: np.ndarray | None = None) -> np.ndarray:
    """Seconds per sample of every pixel (n_pixels,) from the pilot's (pixels, paths, seconds[, cost])
    per unit, scaled so that the pilot's own samples add up to its wall time ``seconds`` (threads overlap).

    With ``cost_per_sample`` (per pixel: its tile's, :func:`tile_cost_per_sample`) and the units' cost,
    a pixel costs its tile's cost per sample × the seconds per unit of cost of the units it was traced
    in: the units (≥ :data:`~engine.render.adaptive.COST_CHUNK_PIXELS` pixels, so that per-unit
    overhead does not dominate) give the time, the deterministic cost counts how it spreads over the
    unit's tiles (the pixels seen through glass shade ~3× the vertices of those on a floor, at 16 spp a
    4×4 tile's count is within a few % of its mean).  Without them, every pixel of a unit costs the same.
    """
    spent, samples, work_cost = np.zeros(n_pixels), np.zeros(n_pixels), np.zeros(n_pixels)
    per_cost = cost_per_sample is not None and all(len(u) > 3 and u[3] for u in unit_times)
    for u in unit_times:
        pix, paths, sec = u[:3]
        spent[pix] += sec / len(pix)
        samples[pix] += paths / len(pix)
        if per_cost:
            work_cost[pix] += u[3] / len(pix)
    seen = samples > 0
    if not seen.any():
        return np.zeros(n_pixels)
    work = work_cost if per_cost else samples
    unit_cost = np.where(seen, spent / np.where(seen, work, 1.0), 0.0)     # seconds per cost (or per sample)
    unit_cost[~seen] = unit_cost[seen].mean()
    per_sample = unit_cost * (np.asarray(cost_per_sample, np.float64) if per_cost else 1.0)
    total = float(np.sum(per_sample[seen] * samples[seen]))
    return per_sample * (seconds / total if total > 0 else 0.0)


def predict(film, halves, quantity: str, threshold: float, min_spp: int, spp: int, seconds_per_sample,
            pixels: np.ndarray | None = None, round_seconds: float = 0.0, sampler: str = "independent") -> Prediction:
    """Predicted counts from a film whose pixels all have the same count n (the pilot or first pass).

    ``seconds_per_sample``: one number, or per pixel over the whole image (:func:`cost_map`);
    ``round_seconds``: the fixed time of an adaptive round (:func:`round_overhead`; 0: not counted);
    ``sampler``: the render's (its checkpoint ladder, engine.render.adaptive.ladder_of)."""
    if pixels is None:
        pixels = np.arange(film.count.size)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):   # extreme thresholds: need = ∞ or 0
        return _predict(film, halves, quantity, threshold, min_spp, spp, seconds_per_sample, pixels, round_seconds,
                        ladder_of(sampler))


def _count(x: float, min_spp: int, spp: int) -> int:
    """⌈x⌉ within [min_spp, spp] (x = ∞ or NaN: spp), without converting ∞ to an integer."""
    x = float(x)
    return int(min(spp, max(min_spp, math.ceil(x - 1e-9)))) if x <= spp else int(spp)


def _predict(film, halves, quantity, threshold, min_spp, spp, seconds_per_sample, pixels, round_seconds, ladder):
    n = film.count[pixels].astype(np.float64)
    _, _, tile_err = film_noise(film, halves, quantity, pixels)
    alloc = allocation_from(halves.sums, film.count, quantity, threshold, tile_ids(film.width, film.height), pixels,
                            halves.cost, film.width, halves.halves)
    need = n * (tile_err / threshold) ** 2                # every tile below the threshold (uniform: its own error)
    sigma, mu = alloc.sigma, alloc.level
    marks = checkpoints(min_spp, spp, ladder)
    if np.any(alloc.n_nb > 0):
        # the error pooled with the neighbourhood (engine.render.adaptive.pooled_error) at every
        # checkpoint m, the tile's own σ̂ staying what it is: the first m where e(m) ≤ T or σ(m)/(μ·w) ≤ m
        m = marks[:, None].astype(np.float64)
        # (the pooled quantities' allocation error is their tile error)
        e_m = pooled_error(tile_err * np.sqrt(n) / np.sqrt(m), m, alloc.sigma_nb, alloc.n_nb)
        stop = (e_m <= threshold) | ((e_m * np.sqrt(m) / (mu * alloc.weight) <= m) if mu > 0 else False)
        wanted = np.where(stop.any(axis=0), 0.0, np.inf)        # capped: would go on past spp
        stop[-1] = True
        i = np.argmax(stop, axis=0)
    else:
        # where the tile's share of the error at equal cost is met: n = σ/(μ·w)
        share = sigma / (mu * alloc.weight) if mu > 0 else np.full(n.shape, np.inf)
        wanted = np.minimum(need, share)
        i = np.minimum(np.searchsorted(marks, np.ceil(wanted - 1e-9), side="left"), len(marks) - 1)
    counts = marks[i]
    uniform = _count(need.max(), min_spp, spp) if need.size else min_spp
    uniform_p95 = _count(np.percentile(need, 95), min_spp, spp) if need.size else min_spp
    capped = float(np.mean(wanted > spp)) if need.size else 0.0
    sps = np.asarray(seconds_per_sample, np.float64)
    rounds = int(np.searchsorted(marks, counts.max())) + 1 if counts.size else 0
    return Prediction(quantity, threshold, counts, uniform, uniform_p95, sps[pixels] if sps.ndim else sps, capped,
                      variance=sigma ** 2, rounds=rounds, round_seconds=float(round_seconds))


def parse_target(text: str) -> tuple[str, float]:
    """'dolp:0.01' → ("dolp", 0.01), or a SceneError naming --target (any finite threshold > 0; the
    CLI then applies render's rules, engine.render.adaptive.check_adaptive, e.g. an AoLP error ≤ 90°)."""
    q, sep, v = text.partition(":")
    try:
        value = float(v)
    except ValueError:
        value = math.nan
    if not sep or q not in QUANTITIES or not (math.isfinite(value) and value > 0):
        raise SceneError("--target", f"must look like QUANTITY:THRESHOLD with QUANTITY one of "
                                     f"{', '.join(QUANTITIES)} and THRESHOLD > 0, got {text!r}")
    return q, value


def pilot_render(renderer, settings, pilot_spp: int, quantity: str = "s0"):
    """Render every pixel with ``pilot_spp`` samples keeping the half-buffers;
    (RenderResult, seconds per sample of every pixel (H·W,))."""
    unit_times = []
    result = renderer.render(RenderRequest(dataclasses.replace(settings, spp=pilot_spp),
                                           adaptive=AdaptiveSettings(threshold=math.inf, quantity=quantity,
                                                                     min_spp=pilot_spp, time_limit=0.0),
                                           unit_times=unit_times))
    return result, cost_map(unit_times, result.film.count.size, result.stats["seconds"],
                            tile_cost_per_sample(result.film, result.halves))


#: Most samples per pixel the round-overhead probe (:func:`round_overhead`) takes: its cost must not
#: grow with ``--spp`` (16 pixels × 2²⁴ spp would take days); at most one tile × 1024 samples.
ROUND_PROBE_MAX_SPP = 1024


def round_overhead(renderer, settings, pilot, seconds_per_sample, min_spp: int) -> float:
    """Seconds an adaptive round costs besides its samples, on this machine: one tile (the pilot's
    noisiest) is rendered adaptively to min(``settings.spp``, :data:`ROUND_PROBE_MAX_SPP`) with a
    threshold of 0, through every checkpoint up to there (from min(``min_spp``, that)); its time less
    its samples' (``seconds_per_sample`` of :func:`cost_map`) is shared among its rounds.  Small renders
    and late rounds (few tiles, many sample passes each) are dominated by this: per-unit tracing set-up,
    the error images, adding sample pass by pass.  Bounded work whatever ``settings.spp``."""
    film = pilot.film
    _, _, tile_err = film_noise(film, pilot.halves, "s0")
    p = int(np.argmax(np.where(np.isfinite(tile_err), tile_err, 0.0)))
    y, x = divmod(p, film.width)
    x0, y0 = x - x % TILE, y - y % TILE
    window = (x0, y0, min(x0 + TILE, film.width), min(y0 + TILE, film.height))
    st = dataclasses.replace(settings, spp=min(int(settings.spp), ROUND_PROBE_MAX_SPP))
    started = time.perf_counter()
    probe = renderer.render(RenderRequest(st, window, AdaptiveSettings(threshold=0.0, quantity="s0",
                                                                       min_spp=min(int(min_spp), st.spp))))
    seconds = time.perf_counter() - started
    sps = np.broadcast_to(np.asarray(seconds_per_sample, np.float64), probe.film.count.shape)
    samples = float(np.sum(probe.film.count * sps))
    return max(seconds - samples, 0.0) / max(int(probe.stats.get("adaptive_rounds", 1)), 1)
