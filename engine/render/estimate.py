"""Predicting what an accuracy costs: samples per pixel and wall time, before rendering.

A short pilot render (every pixel ``pilot_spp`` samples, with the half-buffers of adaptive
sampling) gives each tile's error e at n = pilot_spp samples.  The standard error of a Monte Carlo
mean falls as 1/√spp, so the tile needs m = n·(e/T)² samples to reach the threshold T; adaptive
sampling stops it at the first checkpoint ≥ m (engine.render.adaptive.checkpoints), within
[min_spp, spp].  A uniform render needs the largest m of all tiles for every pixel.  Wall time =
Σ over pixels of samples × that pixel's seconds per sample, measured in the pilot on this machine
(:func:`cost_map`: the pilot is cut into small pixel chunks and each chunk's time is kept — the
pixels that need many samples, glass and edges, are also the expensive ones).  The same prediction is made from the
first pass (``min_spp`` everywhere) of an adaptive render and printed beside what happened.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from .adaptive import QUANTITIES, UNITS, AdaptiveSettings, checkpoints, film_noise


@dataclass
class Prediction:
    quantity: str
    threshold: float
    counts: np.ndarray            # predicted samples per pixel of the adaptive render (window pixels)
    uniform_spp: int              # samples per pixel a uniform render needs (the worst tile)
    uniform_p95_spp: int          # … to bring 95 % of the pixels below the threshold
    seconds_per_sample: np.ndarray   # per pixel (or one number for all)
    capped: float                 # fraction of pixels that would stop at the maximum spp, not the threshold

    @property
    def median(self) -> float:
        return float(np.median(self.counts))

    @property
    def p95(self) -> float:
        return float(np.percentile(self.counts, 95))

    @property
    def adaptive_seconds(self) -> float:
        return float(np.sum(self.counts * self.seconds_per_sample))

    @property
    def uniform_seconds(self) -> float:
        return float(np.sum(np.broadcast_to(self.seconds_per_sample, self.counts.shape))) * self.uniform_spp

    def describe(self) -> str:
        return (f"{self.quantity} ≤ {self.threshold:g} ({UNITS[self.quantity]}): adaptive median "
                f"{self.median:.0f} spp, 95th percentile {self.p95:.0f} spp, {self.adaptive_seconds:.1f} s; "
                f"uniform {self.uniform_spp} spp, {self.uniform_seconds:.1f} s "
                f"(for 95 % of the pixels: {self.uniform_p95_spp} spp)"
                + (f"; {100 * self.capped:.0f} % of pixels would stop at the maximum spp" if self.capped else ""))


def cost_map(unit_times, n_pixels: int, seconds: float) -> np.ndarray:
    """Seconds per sample of every pixel (n_pixels,) from the pilot's (pixels, paths, seconds) per unit,
    scaled so that the pilot's own samples add up to its wall time ``seconds`` (threads overlap)."""
    spent, samples = np.zeros(n_pixels), np.zeros(n_pixels)
    for pix, paths, sec in unit_times:
        spent[pix] += sec / len(pix)
        samples[pix] += paths / len(pix)
    seen = samples > 0
    if not seen.any():
        return np.zeros(n_pixels)
    per_sample = np.where(seen, spent / np.where(seen, samples, 1.0), 0.0)
    per_sample[~seen] = per_sample[seen].mean()
    total = float(np.sum(per_sample[seen] * samples[seen]))
    return per_sample * (seconds / total if total > 0 else 0.0)


def predict(film, halves, quantity: str, threshold: float, min_spp: int, spp: int, seconds_per_sample,
            pixels: np.ndarray | None = None) -> Prediction:
    """Predicted counts from a film whose pixels all have the same count n (the pilot or first pass).

    ``seconds_per_sample``: one number, or per pixel over the whole image (:func:`cost_map`)."""
    if pixels is None:
        pixels = np.arange(film.count.size)
    n = film.count[pixels].astype(np.float64)
    _, _, tile_err = film_noise(film, halves, quantity, pixels)
    need = n * (tile_err / threshold) ** 2
    marks = checkpoints(min_spp, spp)
    i = np.minimum(np.searchsorted(marks, np.ceil(need - 1e-9), side="left"), len(marks) - 1)
    counts = marks[i]
    uniform = int(min(spp, max(min_spp, math.ceil(float(need.max()) - 1e-9)))) if need.size else min_spp
    uniform_p95 = int(min(spp, max(min_spp, math.ceil(float(np.percentile(need, 95)) - 1e-9)))) if need.size \
        else min_spp
    capped = float(np.mean(need > spp)) if need.size else 0.0
    sps = np.asarray(seconds_per_sample, np.float64)
    return Prediction(quantity, threshold, counts, uniform, uniform_p95, sps[pixels] if sps.ndim else sps, capped)


def parse_target(text: str) -> tuple[str, float]:
    """'dolp:0.01' → ("dolp", 0.01), or a SceneError naming --target."""
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
    st = copy.copy(settings)
    st.spp = pilot_spp
    unit_times = []
    result = renderer.render(st, adaptive=AdaptiveSettings(threshold=math.inf, quantity=quantity,
                                                           min_spp=pilot_spp, time_limit=0.0),
                             unit_times=unit_times)
    return result, cost_map(unit_times, result.film.count.size, result.stats["seconds"])
