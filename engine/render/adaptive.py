"""Adaptive sampling: sample passes go only where the estimated error is above a threshold.

**Error estimate.** The film keeps, besides its sums, the luminance Stokes sums of two classes of
each pixel's samples (half-buffers A and B, engine.render.halves): with independent halves the even and
the odd samples, two independent estimates of the pixel; with one sequence (the default) the samples
below and from the largest power of two under the count, two nets of one sequence, correlated, whose
difference is scaled by the calibration factor (engine.render.halves.ERROR_FACTOR, applied in the
means).  Their difference estimates the standard error of the pixel value.  Per pixel, from the
luminance Stokes means S_A, S_B:

* ``s0``     |Y_A − Y_B| / (Y_A + Y_B): relative standard error of the luminance S0 (0 where both are 0);
* ``dolp``   ½|DoLP_A − DoLP_B| (absolute);
* ``docp``   ½|DoCP_A − DoCP_B| (absolute, DoCP = S3/S0 signed);
* ``aolp``   ½|AoLP_A − AoLP_B| in degrees, the difference wrapped to ±90°; only where the pixel's
  DoLP > 0.05 (elsewhere the angle is undefined and the error is 0);
* ``stokes`` the largest of the s0 error and ½|S_k,A/S0,A − S_k,B/S0,B| for k = 1, 2, 3.

**Tiles.** One pixel's A/B difference is a single draw (one degree of freedom): it is 0.3× the
true error or less one time in four, so a per-pixel rule would stop many noisy pixels early.  The
rule therefore works on tiles of ``TILE``×``TILE`` pixels aligned to the image grid: a tile's error
is the root mean square of its pixels' errors (over the pixels where the quantity is defined), and
all pixels of a tile always have the same sample count.

**Allocation (which tiles go on).**  Rendering every tile *to* the threshold gives each tile
n ∝ σ² samples (σ: its per-sample standard deviation), and that gains exactly nothing over uniform
sampling at equal cost (engine.render.estimate).  A sample of tile t costs c_t (the integrator counts
1 per path and 4 per surface hit and per light sample, :data:`engine.render.integrator.PATH_COST`:
the shaded vertices are what 1-thread CPU time follows; a deterministic function of the seed,
summed per pixel in :attr:`HalfBuffers.cost`); a path through glass costs ~2.5× one that ends on a
diffuse floor.  The counts that minimise the image's mean squared error mean(σ²/n) at a
given cost Σ c·n are n ∝ σ/√c (Lagrange: σ²/n² = λ·c for every tile).  So a tile goes on only while
(1) its error e is above the threshold T (the issue's rule: samples go only where the error is
above T; every tile below T stops) **and** (2) σ̂/(n·w) > μ, with σ̂ = e·√n and the cost weight
w = √(c/c̄) (c: the tile's cost per sample so far, c̄: the first pass's over the image,
:func:`cost_weight`), i.e. e is above its share √(μ·w·σ̂) of the error.  A tile stops at
n = σ/(μ·w) ∝ σ/√c samples, or at the threshold (n = σ²/T²) if that comes first: a dear or noisy
tile stops above T because bringing it lower costs more than it buys elsewhere.  μ = T²/mean(σ·w)
(:func:`allocation_level`: the level at which the counts σ/(μ·w) give an image RMS error of T), set
once, from the first pass (``min_spp`` everywhere).  With equal costs (w = 1) this is n ∝ σ and
μ = T²/σ̄.  For ``s0`` condition (2) measures the tile in absolute luminance — the RMS of
½|Y_A − Y_B| over the tile ÷ the image's first-pass mean luminance (:func:`allocation_noise`) — so
that the image's luminance error is what is minimised (a relative error alone samples dark tiles as
much as bright ones); the other quantities use their tile error.  The mean of σ·w is over the
pixels where the quantity is defined (lit pixels; DoLP > 0.05 for ``aolp``).  Counts make the
rule deterministic (seconds would not be) while following the cost.

**Rare paths.** A rare bright path (glass seen in a mirror floor) can be missing from a tile's
first pass, which would stop it at ``min_spp`` for good, while the neighbouring tiles see such
paths.  For ``dolp``, ``aolp``, ``docp`` and ``stokes`` a tile's σ is therefore pooled with its
neighbourhood's: σ² = (n·σ̂² + n_nb·σ_nb²)/(n + n_nb), σ_nb the RMS first-pass σ̂ of its 3×3
tiles (:func:`neighbourhood_sigma`), worth n_nb = the first pass's samples
(:data:`NEIGHBOURHOOD_WEIGHT`), and its error is σ/√n (:func:`pooled_error`), in both conditions
and in μ.  Its own samples outweigh the neighbourhood as they come: a quiet tile beside noisy ones
stops after a few steps (its error falls as 1/n, not 1/√n), a tile that finds the rare paths goes
on by its own σ̂.  At ``min_spp`` the error is the quadratic mean of the tile's own and its
neighbourhood's RMS error, so an image whose every tile is below T there still stops there.

**Schedule.** Every pixel first gets ``min_spp`` samples; then tiles that go on get more,
checkpoint by checkpoint (:func:`checkpoints`, even steps so both halves stay equal: with the ``sobol``,
``padded`` and ``stratified`` samplers the counts 2^k and 3·2^(k−1), where a pixel's low-discrepancy points are whole
nets — their error is up to 2× lower there than at the counts between; with ``independent`` steps of
about +25 %), until no tile goes on, ``spp`` is reached or the time limit passes.

**Budget mode** (a time limit without a threshold, ``threshold`` 0).  There is no T to set μ, so each
round sets it: every tile's share n = σ/(μ·w) (σ = e·√n from its samples so far, pooled as above;
w = √(c/c̄)) is taken up to a checkpoint, at most :data:`BUDGET_JUMP` × its count, and μ is the largest
level whose counts cost :data:`BUDGET_GROWTH` × what the samples so far cost (:func:`budget_targets`).
Each round's counts are then the least-MSE counts for their cost, so the image is close to the best
allocation whenever the time runs out; a tile's σ is measured again every round (with a low-discrepancy
sampler it falls faster than 1/√n where the image is smooth).  The rounds are a deterministic function
of the seed (samples and counted costs only), so a budget render is a prefix of one deterministic
sequence: only where it stops depends on the time (at a round's start, or units of the last round
dropped whole at the limit).  Without a time limit it goes on until every noisy tile has ``spp``.

**Determinism.**  In threshold mode a tile's next step
depends only on its own samples and cost, and on μ, c̄ and its σ_nb, fixed after the first pass and kept
with the half-buffers (:class:`HalfBuffers` ``first`` and ``cost``, stored in the EXR), so without a time
limit the counts are a deterministic function of the seed — however the work is split, and also across an interrupted
render and its resumption, and a tighter threshold on resumption continues the looser one's path
(μ falls with T).  Samples are added to the film one sample pass at a time in ascending sample order
(:func:`add_in_sample_order`), so given the counts the sums are bit-identical whatever the threads,
batch size or resumption.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..spectral.cie import LUMINANCE_WEIGHTS
from .film import Film, HalfBuffers, OrderedSamples
from .halves import class_means

#: Quantities the threshold can apply to.
QUANTITIES = ("s0", "dolp", "aolp", "docp", "stokes")
#: Units of each quantity's error (for messages).
UNITS = {"s0": "relative", "dolp": "absolute", "aolp": "degrees", "docp": "absolute", "stokes": "relative"}
#: Side of the square tiles the stopping rule works on (pixels).
TILE = 4
#: DoLP below which the AoLP is undefined and its error does not hold a pixel back.
AOLP_MIN_DOLP = 0.05
#: Weight of a tile's neighbourhood in its σ estimate, in samples per first-pass sample
#: (:func:`pooled_error`).  Rare bright paths (glass seen in a mirror-like floor) can be missing from a
#: tile's 16-spp first pass while its neighbours see them: on glass_sphere 64² (dolp ≤ 0.01) two such
#: tiles had σ̂ = 0.01 against 0.7 in Mitsuba's 2 × 8192 spp, stopped at 16 spp and held 53 % of the
#: adaptive render's DoLP MSE.  DoLP MSE × rays gain over uniform, one render each (64², none / a
#: floor max(σ̂, ½ σ_nb) / this pooling at weight 1): glass_sphere dolp ≤ 0.01 0.95 / 1.58 / 1.96,
#: dolp ≤ 0.03 1.92 / 1.90 / 2.08, fresnel_sphere_au dolp ≤ 0.005 2.36 / 2.24 / 2.24, demo dolp ≤ 0.01
#: 6.44 / 4.84 / 4.82 (weight 0.7: 1.60, 1.96, 2.11, 5.58; 4: 1.84, 2.01, 2.12, 4.38).
NEIGHBOURHOOD_WEIGHT = 1.0
#: Quantities whose σ is pooled with the neighbourhood's (ratios of Stokes components, which a rare
#: bright path moves most; ``s0`` is measured in absolute luminance, where a rare path shows).
POOLED = ("dolp", "aolp", "docp", "stokes")
#: Fewest paths per work unit when a round is split for the workers (below, per-batch overhead dominates).
MIN_UNIT_PATHS = 16384
#: Work units a round is split into per worker.  Fewer, larger units trace faster per path (the
#: per-bounce overhead is paid per unit; on glass_sphere 64² the adaptive render took 30 % less wall
#: time with 1 unit per worker and ≥ 16384 paths than with 4 and ≥ 4096, at the same counts and image).
UNITS_PER_WORKER = 1
#: Fewest pixels per unit in a first pass that measures where samples cost more (engine.render.estimate).
#: Its units should cost per path what the adaptive rounds' units do: at 16 spp, 1024 pixels make
#: 16384 paths (:data:`MIN_UNIT_PATHS`); with 256-pixel units the pilot's per-unit overhead made the
#: time estimate 1.4–2.1× too high on glass_sphere and the demo (64²), with 1024 it was 0.57–1.27×.
COST_CHUNK_PIXELS = 1024
#: Stop reasons written to the EXR header ``polar.stop_reason``.
STOP_REASONS = ("threshold", "max_spp", "time_limit", "cancelled")


@dataclass
class AdaptiveSettings:
    """``threshold`` of the standard error of ``quantity`` (units: :data:`UNITS`), at least
    ``min_spp`` samples per pixel, at most ``time_limit`` seconds of sampling (0: no limit).

    ``threshold`` 0 is **budget mode** (a time limit without a threshold: CLI ``--time-limit`` alone,
    Blender's Time Limit without Noise Threshold): rounds of the share rule's counts for a growing cost
    (:func:`budget_targets`) until the time is up, or every noisy tile has ``spp``."""

    threshold: float = 0.01
    quantity: str = "s0"
    min_spp: int = 16
    time_limit: float = 0.0


def check_adaptive(threshold, quantity, min_spp, time_limit, spp, threshold_field: str = "--noise-threshold",
                   quantity_field: str = "--noise-quantity") -> AdaptiveSettings:
    """Validated settings, or a SceneError naming the CLI option and its allowed range.

    Any finite threshold > 0 is legal: a huge one stops every tile after ``min_spp`` samples, a
    tiny one (down to the smallest subnormal) samples every noisy tile to ``spp``.  ``threshold_field``,
    ``quantity_field``: the option names in messages (``estimate`` gives both as ``--target``)."""
    if threshold is None or not (math.isfinite(threshold) and threshold > 0):
        raise SceneError(threshold_field, f"must be a finite number > 0, got {threshold!r}")
    if quantity not in QUANTITIES:
        raise SceneError(quantity_field, f"must be one of {', '.join(QUANTITIES)}, got {quantity!r}")
    if quantity == "aolp" and threshold > 90:
        raise SceneError(threshold_field, f"an AoLP error is at most 90 degrees, got {threshold:g}")
    if min_spp is None or not (2 <= int(min_spp) <= spp):
        raise SceneError("--min-spp", f"must be an integer in [2, --spp = {spp}] (both half-buffers need "
                                      f"a sample), got {min_spp!r}")
    if time_limit is None or not (math.isfinite(time_limit) and time_limit >= 0):
        raise SceneError("--time-limit", f"must be a finite number of seconds ≥ 0 (0 = none), got {time_limit!r}")
    return AdaptiveSettings(float(threshold), quantity, int(min_spp), float(time_limit))


#: Checkpoint ladders (:func:`checkpoints`): "quarter" steps of ≈ +25 %; "nets" the counts 2^k and 3·2^(k−1).
LADDERS = ("quarter", "nets")


#: The ladder of each sampler (``RenderSettings.sampler``): whole nets for the low-discrepancy ones.
SAMPLER_LADDERS = {"sobol": "nets", "padded": "nets", "cycles": "nets", "stratified": "nets", "independent": "quarter"}


def ladder_of(sampler: str) -> str:
    """The checkpoint ladder (:data:`LADDERS`) of adaptive renders with ``sampler``."""
    return SAMPLER_LADDERS.get(sampler, "quarter")


def checkpoints(min_spp: int, spp: int, ladder: str = "quarter") -> np.ndarray:
    """Sample counts at which a tile's error is tested: min_spp, then the ladder's next counts, the last one
    clipped to spp.  ``quarter``: steps of 2·⌈c/8⌉ (≈ +25 %, even).  ``nets``: the even counts 2^k and
    3·2^(k−1) above min_spp (16, 24, 32, 48, 64, 96, …; steps of +50 % and +33 %), where the low-discrepancy
    samplers' points of a pixel are whole (0, m, 2)-nets or a net and a half: their error there is up to 2×
    below that of the counts in between (fresnel_sphere_au's S0 with ``sobol``: MSE × spp at 64, 70, 96,
    128, 138 spp 2.9, 6.6, 3.3, 2.0, 4.0·10⁻⁵).  A step depends only on c, so the sequence for a larger
    spp extends the one for a smaller spp (up to the clipped last checkpoint)."""
    out = [int(min_spp)]
    while out[-1] < spp:
        c = out[-1]
        if ladder == "nets":
            k = 1 << max(c.bit_length() - 1, 1)                       # the power of two ≤ c (at least 2)
            nxt = next(m for m in (k, 3 * k // 2, 2 * k, 3 * k) if m > c and m % 2 == 0)
        else:
            nxt = c + max(2, 2 * math.ceil(c / 8))
        out.append(min(int(spp), nxt))
    return np.asarray(out, np.int64)


# ------------------------------------------------------------------------------------ error formulas

def _ratio(num, den):
    out = np.zeros(np.broadcast(num, den).shape)
    np.divide(num, den, out=out, where=den > 0)
    return out


def _dolp(s):
    return _ratio(np.hypot(s[1], s[2]), s[0])


def pixel_noise(quantity: str, mean_a: np.ndarray, mean_b: np.ndarray, mean: np.ndarray | None = None):
    """Per-pixel standard error of ``quantity`` from the half-buffer means.

    ``mean_a``, ``mean_b``: luminance Stokes means (4, …) of the even and odd sample passes;
    ``mean``: the pixel's luminance Stokes mean (4, …) (default: the average of both), whose DoLP
    decides where the AoLP is defined.  Returns (error (…), defined (…) bool).
    """
    a, b = np.asarray(mean_a, np.float64), np.asarray(mean_b, np.float64)
    defined = np.ones(a.shape[1:], bool)
    if quantity in ("s0", "stokes"):
        err = _ratio(np.abs(a[0] - b[0]), a[0] + b[0])
        if quantity == "stokes":
            for k in (1, 2, 3):
                err = np.maximum(err, 0.5 * np.abs(_ratio(a[k], a[0]) - _ratio(b[k], b[0])))
    elif quantity == "dolp":
        err = 0.5 * np.abs(_dolp(a) - _dolp(b))
    elif quantity == "docp":
        err = 0.5 * np.abs(_ratio(a[3], a[0]) - _ratio(b[3], b[0]))
    elif quantity == "aolp":
        m = 0.5 * (a + b) if mean is None else np.asarray(mean, np.float64)
        diff = np.degrees(0.5 * (np.arctan2(a[2], a[1]) - np.arctan2(b[2], b[1])))
        diff = (diff + 90.0) % 180.0 - 90.0                      # the angle is defined modulo 180°
        defined = _dolp(m) > AOLP_MIN_DOLP
        err = np.where(defined, 0.5 * np.abs(diff), 0.0)
    else:
        raise ValueError(f"unknown noise quantity {quantity!r}")
    return err, defined


def tile_ids(width: int, height: int) -> np.ndarray:
    """Tile index of every flat pixel (tiles of TILE×TILE aligned to the image's top-left corner)."""
    ntx = -(-width // TILE)
    y, x = np.divmod(np.arange(width * height, dtype=np.int64), width)
    return (y // TILE) * ntx + x // TILE


def tile_noise(err: np.ndarray, defined: np.ndarray, tiles: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Per-pixel error of the pixel's tile: the RMS of ``err`` over the tile's ``pixels`` where
    ``defined`` (0 where none is); arrays are flat over the image, the result is over ``pixels``."""
    t = tiles[pixels]
    n_tiles = int(tiles.max()) + 1
    e2 = np.bincount(t, weights=np.where(defined[pixels], err[pixels] ** 2, 0.0), minlength=n_tiles)
    n = np.bincount(t, weights=defined[pixels].astype(np.float64), minlength=n_tiles)
    return np.sqrt(_ratio(e2, n))[t]


def next_targets(counts: np.ndarray, noise: np.ndarray, marks: np.ndarray, threshold: float) -> np.ndarray:
    """Sample count each pixel is to reach next (its own count where it is done).

    A count between two checkpoints is completed to the next one (its tile was in the middle of a
    step); a count on a checkpoint moves on to the next checkpoint if its tile ``noise`` is above
    ``threshold``, and is done otherwise or at the last checkpoint.  (The render loop passes −∞ as
    the noise of tiles that have reached their share of the error: :func:`allocation_level`.)
    """
    counts = np.asarray(counts, np.int64)
    i = np.minimum(np.searchsorted(marks, counts, side="left"), len(marks) - 1)
    on_mark = marks[i] == counts
    target = np.where(counts < marks[i], marks[i], counts)
    go_on = on_mark & (noise > threshold) & (i + 1 < len(marks))
    target[go_on] = marks[np.minimum(i + 1, len(marks) - 1)][go_on]
    return np.maximum(target, counts)


def allocation_noise(quantity: str, sums: np.ndarray, counts: np.ndarray, tiles: np.ndarray, pixels: np.ndarray,
                     mean_y: float, halves: str = "independent") -> tuple[np.ndarray, np.ndarray]:
    """(e, counted) over ``pixels``: the error of each pixel's tile in the units the allocation
    minimises, and whether the pixel counts in the image's RMS error.

    ``sums``: half-buffer sums (2, 4, n), ``counts`` (n,).  ``s0``: RMS over the tile of the absolute
    ½|Y_A − Y_B| ÷ ``mean_y`` (the image's mean luminance), so that tiles weigh by their share of the
    image's luminance error; every pixel counts.  The other quantities: the tile error
    (:func:`tile_noise`) of :func:`pixel_noise` (``stokes`` keeps its relative s0 part); the pixels
    that count are the lit ones (S0 > 0: DoLP, DoCP and S_k/S0 of a black pixel are not defined),
    for ``aolp`` those with DoLP > 0.05.  e = ∞ where a pixel has < 2 samples.  ``halves``: how ``sums`` split
    the samples (engine.render.halves: class sizes and the one-sequence calibration).
    """
    c = np.asarray(counts, np.int64)
    a, b = class_means(sums, c, halves)
    if quantity == "s0":
        err = 0.5 * np.abs(a[0] - b[0]) / mean_y if mean_y > 0 else np.zeros(c.size)
        defined = np.ones(c.size, bool)
        counted = defined
    else:
        err, defined = pixel_noise(quantity, a, b)
        counted = defined & (a[0] + b[0] > 0)
    err = np.where(c < 2, 1e30, err)
    out = tile_noise(err, defined, tiles, pixels)
    return np.where(out >= 1e29, np.inf, out), counted[pixels]


def allocation_level(sigma: np.ndarray, threshold: float, weight: np.ndarray | None = None) -> float:
    """μ = T² / mean(σ·w): the level at which counts n = σ/(μ·w) give an RMS error √mean(σ²/n) = T.

    ``sigma``: per-sample standard deviation of every counted pixel's tile (σ = e·√n); ``weight``:
    the tiles' cost weights w = √(c/c̄) (:func:`cost_weight`; None: all 1).  Tiles held at
    ``min_spp`` (σ/(μ·w) below it) only lower the image's error, tiles capped at ``spp`` raise it.
    ∞ (every tile stops at once) where no pixel is noisy.
    """
    sigma = np.asarray(sigma, np.float64)
    w = np.ones(sigma.shape) if weight is None else np.broadcast_to(np.asarray(weight, np.float64), sigma.shape)
    finite = np.isfinite(sigma)
    with np.errstate(over="ignore"):
        mean = float(np.mean(sigma[finite] * w[finite])) if finite.any() else 0.0
    try:
        t2 = float(threshold) ** 2
    except OverflowError:           # T beyond 1.3e154: μ = ∞, every tile stops at the first pass
        t2 = math.inf
    return t2 / mean if mean > 0 else math.inf


def cost_per_sample(cost: np.ndarray, counts: np.ndarray, pixels: np.ndarray) -> float:
    """c̄: the cost per sample of ``pixels`` (0 where nothing was counted: files of older versions)."""
    n = int(np.sum(counts[pixels]))
    return float(np.sum(cost[pixels])) / n if n > 0 else 0.0


def tile_cost(cost: np.ndarray, counts: np.ndarray, tiles: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """c of each pixel's tile over ``pixels``: the tile's cost per sample (Σ cost ÷ Σ samples over its
    pixels among ``pixels``; 0 where the tile has no sample or no cost was counted)."""
    t = tiles[pixels]
    n_tiles = int(tiles.max()) + 1
    r = np.bincount(t, weights=cost[pixels].astype(np.float64), minlength=n_tiles)
    n = np.bincount(t, weights=counts[pixels].astype(np.float64), minlength=n_tiles)
    return _ratio(r, n)[t]


def cost_weight(cost: np.ndarray, counts: np.ndarray, tiles: np.ndarray, pixels: np.ndarray,
                mean_cost: float) -> np.ndarray:
    """w = √(c/c̄) of each pixel's tile over ``pixels``: c its :func:`tile_cost`, c̄ = ``mean_cost``
    (:func:`cost_per_sample` of the first pass).  1 where c̄ = 0 (no cost counted) or the tile has
    no sample yet."""
    if not mean_cost > 0:
        return np.ones(pixels.size)
    c = tile_cost(cost, counts, tiles, pixels)
    return np.where(c > 0, np.sqrt(c / mean_cost), 1.0)


def neighbourhood_sigma(sigma: np.ndarray, tiles: np.ndarray, pixels: np.ndarray, width: int) -> np.ndarray:
    """σ_nb of each pixel's tile over ``pixels``: the RMS of the first-pass σ over the tile's 3×3
    neighbourhood of tiles (itself included; tiles outside the image or the window left out).
    ``sigma`` (over ``pixels``): the σ of each pixel's tile (∞ counts as 0)."""
    ntx = -(-width // TILE)
    t = tiles[pixels]
    n_tiles = int(tiles.max()) + 1
    nty = -(-n_tiles // ntx)
    s2 = np.zeros(n_tiles)
    s2[t] = np.where(np.isfinite(sigma), sigma, 0.0) ** 2
    present = np.zeros(n_tiles, bool)
    present[t] = True
    s2, present = s2.reshape(nty, ntx), present.reshape(nty, ntx)
    total, count = np.zeros((nty + 2, ntx + 2)), np.zeros((nty + 2, ntx + 2))
    for dy in range(3):
        for dx in range(3):
            total[dy:dy + nty, dx:dx + ntx] += s2
            count[dy:dy + nty, dx:dx + ntx] += present
    return np.sqrt(_ratio(total[1:-1, 1:-1], count[1:-1, 1:-1])).ravel()[t]


def pooled_error(e, n, sigma_nb, n_nb):
    """A tile's error at ``n`` samples from its own error ``e`` and its neighbourhood's σ_nb, worth
    ``n_nb`` samples: √((n·σ̂² + n_nb·σ_nb²) / (n + n_nb)) / √n with σ̂ = e·√n (``n_nb`` = 0: e)."""
    n = np.asarray(n, np.float64)
    return np.sqrt(_ratio(n * n * np.asarray(e, np.float64) ** 2 + n_nb * np.asarray(sigma_nb) ** 2, n * (n + n_nb)))


@dataclass
class Allocation:
    """The allocation of a first pass: level μ, the image's mean luminance ``mean_y`` (units of the
    ``s0`` error, :func:`allocation_noise`), its cost per sample ``mean_cost`` (c̄), and per pixel
    the tile's per-sample σ (pooled with its neighbourhood's), cost weight w = √(c/c̄), and its
    neighbourhood's σ_nb and weight in samples ``n_nb`` (:func:`pooled_error`; 0 for ``s0``)."""
    level: float
    mean_y: float
    mean_cost: float
    sigma: np.ndarray
    weight: np.ndarray
    sigma_nb: np.ndarray
    n_nb: np.ndarray


def allocation_from(sums: np.ndarray, counts: np.ndarray, quantity: str, threshold: float, tiles: np.ndarray,
                    pixels: np.ndarray, cost: np.ndarray | None = None, width: int | None = None,
                    halves: str = "independent") -> Allocation:
    """The :class:`Allocation` from half-buffer ``sums`` (2, 4, n), ``counts`` (n,) and ``cost`` (n,)
    (None: not counted, every weight 1) of a first pass, over ``pixels`` of an image ``width`` pixels
    wide (default: tiles in one row); ``threshold`` 0 gives μ = 0 (every noisy tile to ``spp``), ∞
    gives μ = ∞ (every tile stops at once); ``halves``: how ``sums`` split the samples (engine.render.halves)."""
    y = _ratio(sums[0, 0] + sums[1, 0], counts)
    mean_y = float(np.mean(y[pixels])) if pixels.size else 0.0
    e, counted = allocation_noise(quantity, sums, counts, tiles, pixels, mean_y, halves)
    n = counts[pixels]
    sigma_nb, n_nb = np.zeros(pixels.size), np.zeros(pixels.size)
    if quantity in POOLED and pixels.size and NEIGHBOURHOOD_WEIGHT > 0:
        sigma_nb = neighbourhood_sigma(e * np.sqrt(n), tiles, pixels,
                                       TILE * (int(tiles.max()) + 1) if width is None else width)
        n_nb = NEIGHBOURHOOD_WEIGHT * n
        e = pooled_error(e, n, sigma_nb, n_nb)
    sigma = e * np.sqrt(n)
    mean_cost = 0.0 if cost is None else cost_per_sample(cost, counts, pixels)
    weight = np.ones(pixels.size) if cost is None else cost_weight(cost, counts, tiles, pixels, mean_cost)
    if not threshold > 0:
        mu = 0.0
    elif math.isinf(threshold):
        mu = math.inf
    else:
        mu = allocation_level(sigma[counted], threshold, weight[counted])
    return Allocation(mu, mean_y, mean_cost, sigma, weight, sigma_nb, n_nb)


def first_pass_allocation(halves: HalfBuffers, quantity: str, threshold: float, tiles: np.ndarray,
                          pixels: np.ndarray, width: int | None = None) -> Allocation:
    """The :class:`Allocation` of the half-buffers' first pass (:attr:`HalfBuffers.first`)."""
    sums, counts, *cost = halves.first
    return allocation_from(sums, counts, quantity, threshold, tiles, pixels, cost[0] if cost else None, width,
                           halves.halves)


# ------------------------------------------------------------------------------------ budget mode

#: Budget mode (a time limit without a threshold): each round asks for this factor more cost than the
#: samples so far (every round's counts are the share rule's for their total cost, so whenever the time
#: runs out the image is close to the best allocation for the time spent).
BUDGET_GROWTH = 1.3
#: … and takes a tile at most this factor beyond its count in one round (its σ is then measured again).
BUDGET_JUMP = 4.0


def budget_targets(counts: np.ndarray, sigma: np.ndarray, weight: np.ndarray, cost: np.ndarray, marks: np.ndarray,
                   growth: float = BUDGET_GROWTH, jump: float = BUDGET_JUMP) -> tuple[np.ndarray, float]:
    """(the checkpoint every entry goes to next, the level μ) of a budget round.

    Entries are tiles (or pixels): ``counts`` on the checkpoints ``marks`` (a count between two is
    completed to the next), per-sample ``sigma`` (0: no noise, stays), cost weight ``weight``
    (w = √(c/c̄)) and ``cost`` (per sample, in any unit).  A tile's share at level μ is n = σ/(μ·w)
    (∝ σ/√c, the counts with the least mean squared error for their total cost), taken to the next
    checkpoint, at most ``jump`` × its count and at most the last checkpoint; μ is the largest level
    whose counts cost at least ``growth`` × the cost so far, Σ c·n (all that is left when less).  A
    deterministic function of its arguments."""
    counts = np.asarray(counts, np.int64)
    sigma, weight, cost = (np.asarray(a, np.float64) for a in (sigma, weight, cost))
    last = len(marks) - 1
    i = np.minimum(np.searchsorted(marks, counts, side="left"), last)
    floor = np.where(counts < marks[i], marks[i], counts)              # complete a step cut short
    cap = marks[np.minimum(np.searchsorted(marks, np.ceil(jump * counts) - 1e-9, side="left"), last)]
    cap = np.maximum(np.where(sigma > 0, cap, floor), floor)
    share = np.where(weight > 0, sigma / np.where(weight > 0, weight, 1.0), 0.0)     # σ/w: n = share/μ

    def at(mu):
        want = share / mu if mu > 0 else np.where(share > 0, np.inf, 0.0)
        n = marks[np.minimum(np.searchsorted(marks, np.minimum(np.ceil(want - 1e-9), marks[-1]), side="left"), last)]
        return np.clip(n, floor, cap)

    spent = float(np.sum(cost * counts))
    wanted = growth * spent
    most = at(0.0)
    if float(np.sum(cost * most)) <= wanted or not np.any(most > floor):
        return most, 0.0
    # μ between the level where no tile moves past its floor and one where all are at their caps
    go = (share > 0) & (cap > floor)
    hi = float(np.max(share[go] / floor[go]))
    lo = float(np.min(share[go] / cap[go])) * 0.5
    for _ in range(60):                              # bisection in log μ: the least cost ≥ wanted
        mid = math.sqrt(lo * hi)
        if float(np.sum(cost * at(mid))) >= wanted:
            lo = mid
        else:
            hi = mid
    return at(lo), lo


# ------------------------------------------------------------------------------------ accumulation

def add_in_sample_order(film, halves: HalfBuffers, pixel: np.ndarray, sample: np.ndarray,
                        values: np.ndarray, alpha: np.ndarray | None = None,
                        path_cost: np.ndarray | None = None) -> None:
    """Add samples (pixel, sample (N,), values (4, 3, N)) to ``film`` and ``halves`` in ascending sample
    index (each pixel at most once per sample index), so every pixel's sums are built in ascending
    sample order whatever the batching (engine.render.film.OrderedSamples).  ``alpha`` (N,) or None
    (all 1): camera-ray coverage; ``path_cost`` (N,) integers or None (not counted)."""
    part = OrderedSamples(pixel, sample, values, alpha, path_cost)
    film.add(part)
    halves.add(part)


def film_noise(film, halves: HalfBuffers, quantity: str, pixels: np.ndarray | None = None):
    """(per-pixel error (n,), defined (n,), tile error over ``pixels``) of the film's current state."""
    a, b = halves.means(film.count)
    mean = _ratio(np.einsum("c,scn->sn", LUMINANCE_WEIGHTS, film.sums), film.count)
    err, defined = pixel_noise(quantity, a, b, mean)
    err[film.count < 2] = np.inf                      # no estimate yet
    if pixels is None:
        pixels = np.arange(film.count.size)
    return err, defined, tile_noise(np.where(np.isfinite(err), err, 1e30), defined,
                                    tile_ids(film.width, film.height), pixels)


def image_error(film, halves: HalfBuffers, quantity: str, pixels: np.ndarray | None = None) -> float:
    """The image's RMS error of ``quantity`` in the allocation's units (:func:`allocation_noise`:
    for ``s0`` the luminance error ÷ the image's mean luminance), over the pixels where it is defined."""
    if pixels is None:
        pixels = np.arange(film.count.size)
    sums, counts = halves.first[:2] if halves.first is not None else (halves.sums, film.count)
    mean_y = float(np.mean(_ratio(sums[0, 0] + sums[1, 0], counts)[pixels])) if pixels.size else 0.0
    e, counted = allocation_noise(quantity, halves.sums, film.count, tile_ids(film.width, film.height), pixels,
                                  mean_y, halves.halves)
    e = e[counted & np.isfinite(e)]
    return float(np.sqrt(np.mean(e ** 2))) if e.size else math.nan


def adaptive_units(pixels: np.ndarray, start: np.ndarray, target: np.ndarray, tiles: np.ndarray,
                   batch_rays: int, chunk_pixels: int | None = None):
    """Work units (pixel chunk, pass0, pass1) bringing ``pixels`` from ``start`` to ``target``.

    A chunk holds at most ``chunk_pixels`` (default ``batch_rays``) pixels, a unit at most
    ``batch_rays`` paths.

    Chunks hold whole tiles (pixels sorted by tile), so an aborted unit never leaves two pixels
    of a tile at different counts; units are ordered by passes, then chunks.
    """
    order = np.lexsort((pixels, tiles[pixels]))
    pixels, start, target = pixels[order], start[order], target[order]
    t = tiles[pixels]
    tile_starts = np.flatnonzero(np.r_[True, t[1:] != t[:-1]])
    limit = min(batch_rays, chunk_pixels or batch_rays)
    bounds = [0]
    for s in tile_starts[1:]:
        if s - bounds[-1] + TILE * TILE > limit:             # the next tile might not fit
            bounds.append(int(s))
    bounds.append(pixels.size)
    chunks = [(bounds[i], bounds[i + 1]) for i in range(len(bounds) - 1) if bounds[i + 1] > bounds[i]]
    if not chunks:
        return []
    for a, b in chunks:            # within a chunk, ascending pixel order (memory locality when adding)
        o = np.argsort(pixels[a:b], kind="stable")
        pixels[a:b], start[a:b], target[a:b] = pixels[a:b][o], start[a:b][o], target[a:b][o]
    largest = max(b - a for a, b in chunks)
    per_unit = max(1, batch_rays // max(largest, 1))
    p_lo, p_hi = int(start.min()), int(target.max())
    units = []
    for p0 in range(p_lo, p_hi, per_unit):
        p1 = min(p_hi, p0 + per_unit)
        for a, b in chunks:
            sel = (start[a:b] < p1) & (target[a:b] > p0)
            if sel.any():
                units.append((pixels[a:b][sel], start[a:b][sel], target[a:b][sel], p0, p1))
    return units


def round_unit_paths(paths: int, n_pixels: int, passes: int, batch_rays: int, workers: int) -> int:
    """Paths per work unit of a round of ``paths`` paths over ``n_pixels`` pixels and at most ``passes``
    sample passes: ``paths`` ÷ the workers, at least :data:`MIN_UNIT_PATHS` and at most ``batch_rays``;
    a round that this cuts into at least ``workers`` units is then cut into a multiple of ``workers``
    units of equal, whole pass ranges (which may hold fewer than :data:`MIN_UNIT_PATHS` paths).

    Late rounds on few tiles take many passes: capped at ``batch_rays`` alone they were cut into
    full units and a small last one, which one worker traced while the other waited for the round's
    end (glass_sphere 128², 2 threads: 4 such rounds idled a core for ≈ 1 s of 9.4 s of CPU, ≈ 10 %
    of the wall time); equal pass ranges, a multiple of the workers, keep both busy.  How units are
    cut never changes the result.
    """
    workers = max(int(workers), 1)
    per_unit = min(batch_rays, max(MIN_UNIT_PATHS, -(-paths // (UNITS_PER_WORKER * workers))))
    n_units = -(-paths // per_unit)
    if n_units < workers or n_pixels <= 0 or passes <= 0:
        return per_unit
    n_units = workers * -(-n_units // workers)                        # a multiple of the workers
    equal = n_pixels * -(-passes // n_units)                          # whole pass ranges per unit
    return equal if equal <= batch_rays else per_unit


def unit_paths(unit):
    """(pixel, sample) of a unit's paths, sorted by sample then by the unit's pixel order."""
    pix, start, target, p0, p1 = unit
    pixel, sample = [], []
    for s in range(p0, p1):
        m = (start <= s) & (s < target)
        pixel.append(pix[m])
        sample.append(np.full(int(m.sum()), s, np.int64))
    return np.concatenate(pixel), np.concatenate(sample)


# ------------------------------------------------------------------------------------ the schedule

class PathJob:
    """Traces an adaptive unit (pixels, start, target, pass0, pass1) → (OrderedSamples, stats, the unit's
    pixels, seconds of tracing on this machine), or None if aborted (engine.render.driver's job)."""

    count_cost = True

    def __init__(self, settings):
        self.settings = settings

    def __call__(self, tracer, unit, abort=None):
        pixel, sample = unit_paths(unit)
        started = time.perf_counter()         # a measurement of this machine, not the time limit's clock
        traced = tracer.trace(pixel, sample, abort=abort)
        if traced is None:
            return None
        values, s = traced
        part = OrderedSamples(pixel, sample, values, s.pop("alpha", None), s.pop("path_cost", None),
                              s.pop("denoise", None))
        return part, s, unit[0], time.perf_counter() - started


class AdaptiveRounds:
    """The schedule of an adaptive render (engine.render.driver): rounds of units that bring the tiles
    that go on to their next checkpoint, until none does, ``spp`` is reached or the time limit passes.

    ``halves``: the half-buffers the parts are added to (a resumed render's, or new); ``workers``: the
    executor's (rounds are cut for them, :func:`round_unit_paths`); ``stats`` receives
    ``adaptive_rounds``, ``allocation_level``, ``cost_per_sample`` and at the end ``stop_reason``.
    ``on_first_pass(film, halves, seconds, samples)`` is called once every pixel has ``min_spp``
    samples; ``unit_times`` receives (pixels, paths, seconds, cost) of every unit of the first pass,
    cut into small pixel chunks for the purpose (engine.render.estimate).  How units are cut never
    changes the result."""

    def __init__(self, plan, film, halves: HalfBuffers, adaptive: AdaptiveSettings, workers: int, stats: dict,
                 on_first_pass=None, unit_times: list | None = None):
        W, H = film.width, film.height
        self.film, self.halves, self.adaptive, self.workers, self.stats = film, halves, adaptive, workers, stats
        self.spp, self.batch_rays, self.stratified = plan.settings.spp, plan.settings.batch_rays, plan.split_halves
        self.on_first_pass, self.unit_times = on_first_pass, unit_times
        self.job = PathJob(plan.settings)
        self.time_limit = adaptive.time_limit
        self.pixels = plan.pixels()
        self.tiles = tile_ids(W, H)
        self.ladder = ladder_of(plan.settings.sampler)
        self.marks = checkpoints(adaptive.min_spp, self.spp, self.ladder)
        marks = self.marks
        self.spp_is_a_step = len(marks) == 1 or \
            int(marks[-1]) == int(checkpoints(adaptive.min_spp, self.spp + 1, self.ladder)[len(marks) - 1])
        self.budget = max(self.pixels.size * self.spp - int(film.count[self.pixels].sum()), 1)
        self.level = None
        #: budget mode: a time limit without a threshold (the share rule's counts for a growing cost)
        self.budget_mode = not adaptive.threshold > 0
        self.first_pass_reported = False
        self.timing = False
        self.reason = None

    def errstate(self):
        # the error formulas treat ∞ and NaN explicitly (no estimate yet, a tile that stops): no warnings
        return np.errstate(over="ignore", invalid="ignore", divide="ignore")

    def _first_allocation(self) -> Allocation:
        film, halves, adaptive = self.film, self.halves, self.adaptive
        if halves.first is None:        # every pixel has exactly min_spp samples now (or a resumed state)
            halves.keep_first(film.count)
        if self.level is None:
            self.level = first_pass_allocation(halves, adaptive.quantity, adaptive.threshold, self.tiles,
                                               self.pixels, film.width)
            self.stats["allocation_level"] = self.level.level
            self.stats["cost_per_sample"] = self.level.mean_cost
        return self.level

    def _noise(self, counts):
        """Per pixel: the tile error where the tile goes on (above its share of the error), else −∞."""
        film, halves, adaptive, pixels, tiles = self.film, self.halves, self.adaptive, self.pixels, self.tiles
        level = self._first_allocation()
        e, _ = allocation_noise(adaptive.quantity, halves.sums, film.count, tiles, pixels, level.mean_y,
                                halves.halves)
        w = cost_weight(halves.cost, film.count, tiles, pixels, level.mean_cost)
        _, _, noise = film_noise(film, halves, adaptive.quantity, pixels)
        # the tile's error pooled with its neighbourhood's (rare paths its first pass missed); a tile goes
        # on while that error is above T and above its share of the error at equal cost, σ̂/(n·w) > μ
        # (σ̂ = e·√n, w = √(c/c̄))
        root_n = np.sqrt(counts)
        noise = pooled_error(noise, counts, level.sigma_nb, level.n_nb)
        e = pooled_error(e, counts, level.sigma_nb, level.n_nb)
        return np.where(e / (root_n * w) > level.level, noise, -np.inf)

    def _budget_targets(self, counts):
        """Budget mode: per pixel, the count its tile goes to in this round (:func:`budget_targets` over the
        tiles: σ = e·√n from the tile's samples so far, pooled with its neighbourhood's for the polarisation
        quantities, w = √(c/c̄) from its counted cost), and ∞ where the tile is noisy (σ > 0), else −∞."""
        film, halves, adaptive, pixels, tiles = self.film, self.halves, self.adaptive, self.pixels, self.tiles
        level = self._first_allocation()
        e, counted = allocation_noise(adaptive.quantity, halves.sums, film.count, tiles, pixels, level.mean_y,
                                      halves.halves)
        e = pooled_error(e, counts, level.sigma_nb, level.n_nb)
        sigma = np.where(counted | (adaptive.quantity == "s0"), e * np.sqrt(counts), 0.0)
        c = tile_cost(halves.cost, film.count, tiles, pixels)
        if not level.mean_cost > 0 or not np.all(c > 0):
            c = np.ones(pixels.size)                # no cost counted (a file of an older version)
        t = tiles[pixels]
        _, first, inverse = np.unique(t, return_index=True, return_inverse=True)
        # a tile's σ: the largest over its pixels (the pixels that count share it; the others are 0)
        sig_t = np.zeros(first.size)
        np.maximum.at(sig_t, inverse, np.where(np.isfinite(sigma), sigma, 0.0))
        n_pix = np.bincount(inverse, minlength=first.size)
        c_t, n_t = c[first], counts[first]
        mean_c = float(np.sum(c_t * n_pix) / np.sum(n_pix))
        target, mu = budget_targets(n_t, sig_t, np.sqrt(c_t / mean_c), c_t * n_pix, self.marks)
        self.stats["allocation_level"] = mu
        return target[inverse], np.where(sig_t > 0, np.inf, -np.inf)[inverse]

    def next_round(self, film, stop, tally):
        """The units of the next round, or None when sampling ends (``reason`` says why)."""
        adaptive, pixels = self.adaptive, self.pixels
        counts = film.count[pixels]
        first_done = counts.min() >= adaptive.min_spp
        # first pass: only bring every pixel to min_spp
        budget = first_done and self.budget_mode
        noise = self._noise(counts) if first_done and not budget else np.full(counts.shape, -np.inf)
        if first_done and not self.first_pass_reported:
            self.first_pass_reported = True
            self.timing = False
            if self.on_first_pass is not None:
                self.on_first_pass(film, self.halves, tally.seconds(), tally.samples)
        if budget:
            target, noise = self._budget_targets(counts)
        else:
            target = next_targets(counts, noise, self.marks, adaptive.threshold)
        todo = target > counts
        self.stats["adaptive_rounds"] = self.stats.get("adaptive_rounds", 0) + 1
        if not todo.any():
            # max_spp: the cap decided some tile's count — it wanted more, or it stopped at a clipped
            # last checkpoint that a larger --spp would have stepped over
            at_cap = counts >= self.spp
            self.reason = "max_spp" if at_cap.any() and (not self.spp_is_a_step
                                                         or (noise[at_cap] > adaptive.threshold).any()) \
                else "threshold"
            return None
        if stop():
            self.reason = stop.reason
            return None
        paths = int((target - counts)[todo].sum())
        per_unit = round_unit_paths(paths, int(todo.sum()), int((target - counts).max()), self.batch_rays,
                                    self.workers)
        self.timing = self.unit_times is not None and counts.min() < adaptive.min_spp
        return adaptive_units(pixels[todo], counts[todo], target[todo], self.tiles, per_unit,
                              chunk_pixels=max(COST_CHUNK_PIXELS, pixels.size // 128) if self.timing else None)

    def added(self, result) -> None:
        part, s, chunk, seconds = result
        self.halves.add(part)
        if self.timing:
            cost = part.path_cost
            self.unit_times.append((chunk, part.n_samples, seconds, None if cost is None else int(np.sum(cost))))

    def fraction(self, samples: int, seconds: float) -> float:
        frac = samples / self.budget
        if self.time_limit > 0:
            frac = max(frac, seconds / self.time_limit)
        return min(frac, 0.999)

    def finish(self, film, stats, stopped: str | None) -> bool:
        """Record the stop reason (one of :data:`STOP_REASONS`); True if the render was cancelled."""
        stats["stop_reason"] = reason = stopped or self.reason
        if self.stratified:
            film.keep_half_sums(self.halves.sums)       # the half-buffers are the even/odd luminance sums
        stats.setdefault("seconds", 0.0)
        return reason == "cancelled"


# ------------------------------------------------------------------------------------ storage in the EXR

#: Prefix of the EXR channels that hold an adaptive render's exact state (for --resume).
STATE_PREFIX = "adaptive"


def _float64_to_words(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    bits = np.ascontiguousarray(a, np.float64).view(np.uint64)
    return (bits >> np.uint64(32)).astype(np.uint32), (bits & np.uint64(0xFFFFFFFF)).astype(np.uint32)


def _words_to_float64(hi: np.ndarray, lo: np.ndarray) -> np.ndarray:
    bits = (hi.astype(np.uint64) << np.uint64(32)) | lo.astype(np.uint64)
    return bits.view(np.float64)


def _state_arrays(film, halves: HalfBuffers):
    """{name: float64 array (n,)} of everything a resumed adaptive render needs besides the counts."""
    out = {}
    for k in range(4):
        for c, cname in enumerate("RGB"):
            out[f"sum.S{k}.{cname}"] = film.sums[k, c]
        out[f"sumsq.S{k}.Y"] = film.sumsq_y[k]
        out[f"A.S{k}.Y"] = halves.sums[0, k]
        out[f"B.S{k}.Y"] = halves.sums[1, k]
    out["cost"] = halves.cost.astype(np.float64)             # integers < 2⁵³: exact
    return out


def state_channels(film, halves: HalfBuffers) -> dict[str, np.ndarray]:
    """Extra EXR channels (uint32, (H, W)) holding the film's float64 sums and the half-buffers bit
    for bit (high and low 32-bit words), and the first pass's half-buffers and counts (for μ), so
    that a resumed render continues the exact sums and the same allocation."""
    out = {}
    arrays = _state_arrays(film, halves)
    if halves.first is not None:
        arrays.update(_first_arrays(halves))
    for name, a in arrays.items():
        hi, lo = _float64_to_words(a)
        out[f"{STATE_PREFIX}.{name}.hi"] = hi.reshape(film.height, film.width)
        out[f"{STATE_PREFIX}.{name}.lo"] = lo.reshape(film.height, film.width)
    return out


def _first_arrays(halves: HalfBuffers):
    sums, counts, cost = halves.first
    out = {"first.count": counts.astype(np.float64), "first.cost": cost.astype(np.float64)}
    for k in range(4):
        out[f"first.A.S{k}.Y"] = sums[0, k]
        out[f"first.B.S{k}.Y"] = sums[1, k]
    return out


def has_state(channels: dict) -> bool:
    """Whether the channels hold (some of) an adaptive render's state (any ``adaptive.…`` channel)."""
    return any(name.startswith(STATE_PREFIX + ".") for name in channels)


#: Integers up to this are exact in the float64 words of the state (costs and counts).
_EXACT_INTEGER = float(2 ** 53)


def _state_names(channels: dict) -> tuple[list[str], list[str]]:
    """(names every state must have, names of its integer arrays), as :func:`state_channels` writes them.

    ``cost`` and the ``first.…`` pass are absent in files of older versions; a file holding any
    channel of one of these groups must hold all of it (``first.cost`` is optional too)."""
    def present(name):
        return any(f"{STATE_PREFIX}.{name}.{w}" in channels for w in ("hi", "lo"))
    names = [f"sum.S{k}.{c}" for k in range(4) for c in "RGB"] + [f"{q}.S{k}.Y" for q in ("sumsq", "A", "B")
                                                                  for k in range(4)]
    integers = []
    if present("cost"):
        names.append("cost")
        integers.append("cost")
    if any(name.startswith(f"{STATE_PREFIX}.first.") and not name.startswith(f"{STATE_PREFIX}.first.rays.")
           for name in channels):
        names += ["first.count"] + [f"first.{h}.S{k}.Y" for h in "AB" for k in range(4)]
        integers.append("first.count")
        if present("first.cost"):
            names.append("first.cost")
            integers.append("first.cost")
    return names, integers


def check_state(channels: dict, counts: np.ndarray, source: str = "the file",
                means: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The state's float64 arrays {name: (n,)} decoded from :func:`state_channels`, or a SceneError
    naming --resume, ``source`` and the damaged channel: one missing or not stored as uint32 words,
    a value that is not finite, a cost or count that is not a whole number ≥ 0 (a first-pass count
    above the pixel's count), a negative sum of squares, a sum that is not 0 where the pixel has
    no sample of its half (A: none, B: fewer than 2), sums that do not give the stored Stokes ``means``
    (4, H, W, 3) (float32-rounded; None: not checked), or half-buffers that do not add up to the sums
    (:func:`_check_consistency`)."""
    names, integers = _state_names(channels)
    missing = [f"{STATE_PREFIX}.{n}.{w}" for n in names for w in ("hi", "lo")
               if f"{STATE_PREFIX}.{n}.{w}" not in channels]
    if missing:
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise SceneError("--resume", f"{source} is damaged: its adaptive state lacks the channel"
                                     f"{'s' if len(missing) > 1 else ''} {', '.join(missing[:3])}{more}")
    c = np.asarray(counts).reshape(-1).astype(np.int64)
    out = {}
    for n in names:
        words = []
        for w in ("hi", "lo"):
            a = np.asarray(channels[f"{STATE_PREFIX}.{n}.{w}"])
            if a.dtype != np.uint32 or a.size != c.size:
                raise SceneError("--resume", f"{source} is damaged: channel {STATE_PREFIX}.{n}.{w} holds {a.dtype} "
                                             f"values of {a.size} pixels, not the uint32 words of {c.size} pixels")
            words.append(a.reshape(-1))
        v = _words_to_float64(*words)
        bad = int(np.count_nonzero(~np.isfinite(v)))
        if bad:
            raise SceneError("--resume", f"{source} is damaged: the stored value {STATE_PREFIX}.{n} is not finite "
                                         f"(NaN or ±inf) at {bad} pixel{'s' if bad > 1 else ''}")
        if n in integers:
            wrong = (v < 0) | (v > _EXACT_INTEGER) | (v != np.floor(v))
            if n == "first.count":
                wrong |= v > c
            if wrong.any():
                raise SceneError("--resume", f"{source} is damaged: {STATE_PREFIX}.{n} must hold whole numbers in "
                                             f"[0, {'the spp channel' if n == 'first.count' else '2^53'}], not at "
                                             f"{int(wrong.sum())} pixels")
        elif n.startswith("sumsq.") and (v < 0).any():
            raise SceneError("--resume", f"{source} is damaged: the sum of squares {STATE_PREFIX}.{n} is negative at "
                                         f"{int((v < 0).sum())} pixels")
        if not n.startswith("first."):
            empty = c < (2 if n.startswith("B.") else 1)
            if (v[empty] != 0).any():
                raise SceneError("--resume", f"{source} is damaged: {STATE_PREFIX}.{n} is not 0 at "
                                             f"{int((v[empty] != 0).sum())} pixels whose samples it cannot hold")
        out[n] = v
    if means is not None:           # the exact sums must give the means stored beside them (float32-rounded)
        stored = np.asarray(means, np.float64).transpose(0, 3, 1, 2).reshape(4, 3, -1)
        for k in range(4):
            for i, cname in enumerate("RGB"):
                m = out[f"sum.S{k}.{cname}"] / np.maximum(c, 1)
                off = ~(np.abs(m - stored[k, i]) <= 1e-6 * np.abs(stored[k, i]) + 1e-44)
                if off.any():
                    raise SceneError("--resume", f"{source} is damaged: {STATE_PREFIX}.sum.S{k}.{cname} does not give "
                                                 f"the stored means S{k}.{cname} at {int(off.sum())} pixels")
    _check_consistency(out, source)
    return out


#: Relative tolerance of :func:`_check_consistency`: float64 sums of ≤ 2²⁴ samples added in two ways differ
#: by at most ~2²⁴·2⁻⁵³ ≈ 2e-9 of the samples' magnitude; this allows 500× that.
STATE_TOLERANCE = 1e-6


def _check_consistency(state: dict[str, np.ndarray], source: str) -> None:
    """The half-buffers hold the same samples as the film: A + B = the luminance of the RGB sums for every
    Stokes component, within :data:`STATE_TOLERANCE` of the pixel's largest sum (rounding: the same samples
    added in two ways); and a sum of squares' root fits float32 (its standard error is written as float32).
    Finite damage to A, B or a sum of squares shows here (the sums themselves are checked against the stored
    means by :func:`check_state`).  The pixel's largest sum bounds |S1…S3| only for physical samples
    (|S_k| ≤ S0); a render whose samples were 500× beyond that could be refused."""
    lum = [np.einsum("c,cn->n", LUMINANCE_WEIGHTS, np.stack([state[f"sum.S{k}.{c}"] for c in "RGB"]))
           for k in range(4)]
    with np.errstate(over="ignore", invalid="ignore"):
        scale = np.max([np.abs(state[f"A.S{k}.Y"]) + np.abs(state[f"B.S{k}.Y"]) + np.abs(lum[k])
                        for k in range(4)], axis=0)
        for k in range(4):
            off = ~(np.abs(state[f"A.S{k}.Y"] + state[f"B.S{k}.Y"] - lum[k]) <= STATE_TOLERANCE * scale)
            if off.any():
                raise SceneError("--resume", f"{source} is damaged: {STATE_PREFIX}.A.S{k}.Y + {STATE_PREFIX}.B.S{k}.Y "
                                             f"is not the luminance of {STATE_PREFIX}.sum.S{k}.R/G/B (the same "
                                             f"samples) at {int(off.sum())} pixels")
            big = ~(np.sqrt(state[f"sumsq.S{k}.Y"]) <= float(np.finfo(np.float32).max))
            if big.any():
                raise SceneError("--resume", f"{source} is damaged: {STATE_PREFIX}.sumsq.S{k}.Y is beyond (3.4e38)² "
                                             f"at {int(big.sum())} pixels")


def state_from_channels(channels: dict, counts: np.ndarray, source: str = "the file", means: np.ndarray | None = None,
                        halves: str = "independent"):
    """(Film, HalfBuffers) rebuilt exactly from :func:`state_channels` and the ``spp`` counts (H, W), the half-buffers
    splitting the samples as ``halves`` (the file's ``polar.halves``, engine.render.halves);
    a damaged state is a SceneError naming --resume, ``source`` and the channel (:func:`check_state`,
    ``means``: the Stokes image stored beside the state)."""
    H, W = counts.shape
    state = check_state(channels, counts, source, means)
    sums = np.stack([np.stack([state[f"sum.S{k}.{c}"] for c in "RGB"]) for k in range(4)])
    sumsq_y = np.stack([state[f"sumsq.S{k}.Y"] for k in range(4)])
    film = Film.from_sums(W, H, counts.reshape(-1).astype(np.int64), sums, sumsq_y)
    halves_sums = np.stack([np.stack([state[f"{h}.S{k}.Y"] for k in range(4)]) for h in "AB"])
    # Files of older versions counted no cost, or rays (``rays``, ``first.rays``: segments and light
    # samples, another unit than PATH_COST's): they resume with equal costs (c̄ = 0, every weight 1).
    cost = state["cost"].astype(np.int64) if "cost" in state else None
    first = None
    if "first.count" in state:                              # … nor kept the first pass
        first_sums = np.stack([np.stack([state[f"first.{h}.S{k}.Y"] for k in range(4)]) for h in "AB"])
        first_cost = state["first.cost"].astype(np.int64) if "first.cost" in state else np.zeros(W * H, np.int64)
        first = (first_sums, state["first.count"].astype(np.int64), first_cost)
    film.one_sequence = halves == "one_sequence"
    return film, HalfBuffers.from_state(halves_sums, cost, first, halves)
