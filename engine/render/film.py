"""Pixel accumulation with a box filter: per-pixel sums of whole path samples.

Sums are float64 and added in a fixed order, so a render is deterministic.
Besides the Stokes sums (4 components × linear sRGB) the film keeps the sum
of squares of the luminance Stokes vector per pixel, from which the standard
error of each pixel mean follows (used by tests and the peer comparisons), and
the sum of per-sample alpha (coverage of the camera rays: 0 where a sample saw
the transparent background or a holdout, as Cycles' alpha; 1 for samples added
without alpha).  With denoising data (``add_denoise_data``) it also sums the per-sample albedo
and shading normal of the first non-delta vertex (Cycles' Denoising Albedo / Normal).

With the low-discrepancy samplers a pixel's samples are not independent, and the i.i.d. standard error
(from the sums of squares) overestimates the error of its mean; the film then also keeps the
luminance Stokes sums of two classes of its samples (``half_y``, engine.render.halves): with ``halves``
"independent" the even and the odd samples (two independently scrambled sequences), whose difference is an
unbiased, if one-degree-of-freedom, estimate of the mean's variance (``stderr_luminance``); with "one_sequence"
(``Film.one_sequence``) the classes A and B of one sequence, correlated, whose difference is scaled by the
calibration factor (engine.render.halves.ERROR_FACTOR).  A film without half sums (a resumed file of a version
that kept none) has the i.i.d. formula, which ``stderr_method`` says is no estimate of one sequence's error.

The film's accumulators are written here alone: a render adds parts with ``Film.add`` (``SampleSums`` of a
work unit, or ``OrderedSamples`` added in ascending sample order: adaptive sampling, whose even/odd half
sums are ``HalfBuffers``), a resumed render's film is merged (``merge``) or rebuilt (``film_from_stokes``,
``Film.from_sums``).
"""

from __future__ import annotations

import numpy as np

from ..kernels.transport import pixel_sums
from ..spectral.cie import LUMINANCE_WEIGHTS
from .halves import add_in_order, class_counts, class_means, error_factor, fold_part


class Film:
    def __init__(self, width: int, height: int):
        self.width, self.height = width, height
        n = width * height
        self.sums = np.zeros((4, 3, n))
        self.sumsq_y = np.zeros((4, n))
        self.count = np.zeros(n, np.int64)
        self.alpha_sums = None          # None: every sample so far had alpha 1 (no memory spent)
        self.denoise_sums = None        # None: no denoising data asked for; else (6, n): albedo RGB, normal XYZ
        self.half_y = None              # None: independent samples; else (2, 4, n): class A/B luminance Stokes sums
        #: a low-discrepancy render whose samples are one sequence (set by the renderer): its half sums are
        #: classes A/B (engine.render.halves), and without them ``stderr_method`` says the i.i.d. error is not an
        #: estimate of its error
        self.one_sequence = False
        self._added = False             # samples added yet (see ``add``)

    def add_samples(self, pixel: np.ndarray, stokes_rgb: np.ndarray, alpha: np.ndarray | None = None) -> None:
        """Add complete samples: ``stokes_rgb`` (4, 3, N) for flat pixel indices (N,), with their alpha
        (N,) or None (all 1)."""
        self.add(SampleSums.of(pixel, stokes_rgb, alpha))

    def add(self, part: SampleSums | OrderedSamples) -> None:
        """Add a part: the sums of a batch of samples (``SampleSums.of``, computed on any thread; the same
        additions as summing the batch over the whole film: pixels outside the part's range would only
        have had 0 added), or ``OrderedSamples``, added one by one in ascending sample index."""
        if isinstance(part, OrderedSamples):
            self._add_in_sample_order(part)
            return
        if not self._added:
            # Adding a whole-film bincount turned any −0.0 (a resumed film) into +0.0: do it once.
            self._added = True
            for a in (self.sums, self.sumsq_y, self.alpha_sums, self.denoise_sums):
                if a is not None:
                    a += 0.0
        lo, hi = part.lo, part.hi
        if part.alpha is not None or self.alpha_sums is not None:
            if self.alpha_sums is None:
                self.alpha_sums = self.count.astype(np.float64)
            self.alpha_sums[lo:hi] += part.count if part.alpha is None else part.alpha
        self.sums[:, :, lo:hi] += part.sums
        self.sumsq_y[:, lo:hi] += part.sumsq_y
        if part.half_y is not None:
            if self.half_y is None:
                self.half_y = np.zeros((2, 4, self.count.shape[0]))
            if self.one_sequence:       # the octave split moves with the count (engine.render.halves)
                fold_part(self.half_y[:, :, lo:hi], self.count[lo:hi], part.count, part.half_y)
            else:
                self.half_y[:, :, lo:hi] += part.half_y
        self.count[lo:hi] += part.count
        if part.denoise is not None:
            if self.denoise_sums is None:
                self.denoise_sums = np.zeros((6, self.count.shape[0]))
            self.denoise_sums[:, lo:hi] += part.denoise

    def _add_in_sample_order(self, part: OrderedSamples) -> None:
        """Every sample added to its pixel in ascending sample index (np.add.at adds element by element in
        index order: the same additions as one sample pass at a time, whatever the batching)."""
        if part.alpha is not None and self.alpha_sums is None:
            self.alpha_sums = self.count.astype(np.float64)   # every earlier sample had alpha 1
        pixel, _, values, y, alpha = part.ordered()
        n = self.count.size
        sums, vals = self.sums.reshape(12, n), values.reshape(12, -1)
        for r in range(12):
            np.add.at(sums[r], pixel, vals[r])
        for k in range(4):
            np.add.at(self.sumsq_y[k], pixel, y[k] * y[k])
        if self.alpha_sums is not None:
            np.add.at(self.alpha_sums, pixel, 1.0 if alpha is None else alpha)
        np.add.at(self.count, pixel, 1)
        if part.denoise is not None:
            self.add_denoise_data(part.pixel, *part.denoise)

    @property
    def halves(self) -> str:
        """How ``half_y`` splits the samples (engine.render.halves): "one_sequence" or "independent"."""
        return "one_sequence" if self.one_sequence else "independent"

    def keep_half_sums(self, half_y: np.ndarray) -> None:
        """Use ``half_y`` (2, 4, n) as the class A/B luminance Stokes sums (adaptive sampling's
        half-buffers, ``HalfBuffers.sums``: shared, not copied)."""
        self.half_y = half_y

    @classmethod
    def from_sums(cls, width: int, height: int, count: np.ndarray, sums: np.ndarray, sumsq_y: np.ndarray) -> Film:
        """A film holding finished samples exactly: ``count`` (n,), Stokes sums (4, 3, n), luminance sums
        of squares (4, n)."""
        film = cls(width, height)
        film.count[:] = count
        film.sums[:] = sums
        film.sumsq_y[:] = sumsq_y
        return film

    def add_denoise_data(self, pixel: np.ndarray, albedo: np.ndarray, normal: np.ndarray) -> None:
        """Add the denoising guides of samples already added with ``add_samples``: albedo (3, N) linear
        sRGB reflectance and world-space shading normal (3, N), for flat pixel indices (N,)."""
        n = self.count.shape[0]
        if self.denoise_sums is None:
            self.denoise_sums = np.zeros((6, n))
        for i, values in enumerate((*albedo, *normal)):
            self.denoise_sums[i] += np.bincount(pixel, weights=values, minlength=n)

    @property
    def has_denoise_data(self) -> bool:
        return self.denoise_sums is not None

    def denoise_data(self) -> tuple[np.ndarray, np.ndarray]:
        """(albedo, normal), each (H, W, 3): pixel means of the guides (0 where no sample yet).

        The normal is the mean of unit normals, not renormalised (as Cycles' Denoising Normal)."""
        if self.denoise_sums is None:
            raise ValueError("this film holds no denoising data (render with denoise_data=True)")
        m = self.denoise_sums / np.maximum(self.count, 1)
        m = m.reshape(2, 3, self.height, self.width).transpose(0, 2, 3, 1)
        return m[0], m[1]

    def merge(self, other: Film) -> None:
        if other.half_y is not None:
            self.half_y = other.half_y.copy() if self.half_y is None else self.half_y + other.half_y
        if other.denoise_sums is not None:
            self.denoise_sums = other.denoise_sums.copy() if self.denoise_sums is None \
                else self.denoise_sums + other.denoise_sums
        if other.alpha_sums is not None or self.alpha_sums is not None:
            mine = self.count.astype(np.float64) if self.alpha_sums is None else self.alpha_sums
            theirs = other.count.astype(np.float64) if other.alpha_sums is None else other.alpha_sums
            self.alpha_sums = mine + theirs
        self.sums += other.sums
        self.sumsq_y += other.sumsq_y
        self.count += other.count

    def mean(self) -> np.ndarray:
        """Stokes image (4, H, W, 3): pixel means (0 where a pixel has no sample yet)."""
        c = np.maximum(self.count, 1)
        m = self.sums / c
        return m.reshape(4, 3, self.height, self.width).transpose(0, 2, 3, 1)

    def alpha(self) -> np.ndarray:
        """Alpha image (H, W): the mean coverage of the pixel's camera rays (1 where no sample yet)."""
        if self.alpha_sums is None:
            return np.ones((self.height, self.width))
        a = np.where(self.count > 0, self.alpha_sums / np.maximum(self.count, 1), 1.0)
        return a.reshape(self.height, self.width)

    @property
    def has_alpha(self) -> bool:
        """True if some sample carried an alpha (the render tracked coverage)."""
        return self.alpha_sums is not None

    def stderr_luminance(self, iid: bool = False) -> np.ndarray:
        """Standard error of the luminance Stokes pixel means, (4, H, W) (0 where spp < 2).

        Independent samples (or ``iid``): the i.i.d. formula s/√n.  With even/odd half sums
        (``half_y``, the stratified sampler): the i.i.d. variance of the mean times the local ratio of
        the half-split estimate to it (``stratified_variance_ratio``)."""
        c = self.count.astype(np.float64)
        y_mean = np.einsum("c,scn->sn", LUMINANCE_WEIGHTS, self.sums) / np.maximum(c, 1)
        var = (self.sumsq_y / np.maximum(c, 1) - y_mean ** 2) * c / np.maximum(c - 1, 1)
        var_mean = np.maximum(var, 0.0) / np.maximum(c, 1)
        if self.half_y is not None and not iid:
            var_mean = var_mean * stratified_variance_ratio(self.half_y, self.count, var_mean, self.width,
                                                            self.height, self.halves)
        se = np.sqrt(var_mean)
        se[:, c < 2] = 0.0
        return se.reshape(4, self.height, self.width)

    @property
    def stderr_method(self) -> str:
        """What ``stderr_luminance`` is (the EXR header's ``polar.stderr``)."""
        if self.half_y is None:
            if self.one_sequence:
                return ("iid: sample standard deviation / sqrt(spp), not an estimate of this render's error: its "
                        "samples are one low-discrepancy sequence per pixel (halves one_sequence), whose error is "
                        "usually smaller")
            return "iid: sample standard deviation / sqrt(spp)"
        if self.one_sequence:
            return ("stratified one sequence: iid variance of the mean x the 5x5-pixel mean of (A - B)^2 nA nB / "
                    f"spp^2 / iid variance x {error_factor('one_sequence'):.4g}^2 (A, B: means of the samples below "
                    "and from the largest power of two under spp, the two halves of one low-discrepancy sequence, "
                    "correlated; the factor calibrated against reference renders, within 0.6-1.8x of the true error "
                    "on the peer scenes)")
        return ("stratified: iid variance of the mean x the 5x5-pixel mean of (A - B)^2 nA nB / spp^2 / iid variance "
                "(A, B: means of the even and the odd samples, independently scrambled)")

    def even_means_luminance(self) -> np.ndarray:
        """Means of class A's (the even samples' with independent halves) luminance Stokes components (4, H, W)
        (0 where none)."""
        n_a = class_counts(self.count, self.halves)[0]
        return (self.half_y[0] / np.maximum(n_a, 1)).reshape(4, self.height, self.width)

    def spp_image(self) -> np.ndarray:
        return self.count.reshape(self.height, self.width)


#: half-width of the pixel window over which ``stratified_variance_ratio`` averages (5 × 5 pixels)
RATIO_RADIUS = 2


def _box_mean(a: np.ndarray, ok: np.ndarray, width: int, height: int, r: int) -> np.ndarray:
    """Mean of a (4, n) over the pixels where ok (4, n) within (2r+1)² windows clipped to the image."""
    def box(v):            # window sums over the last two axes: shifted slices (no cancellation, ≥ 0 stays ≥ 0)
        p = np.pad(v, [(0, 0), (r, r), (0, 0)])
        rows = sum(p[:, i:i + height] for i in range(2 * r + 1))
        p = np.pad(rows, [(0, 0), (0, 0), (r, r)])
        return sum(p[:, :, j:j + width] for j in range(2 * r + 1))
    k = box(ok.reshape(-1, height, width).astype(np.float64))
    total = box(np.where(ok, a, 0.0).reshape(-1, height, width))
    return (total / np.maximum(k, 1.0)).reshape(a.shape)


def stratified_variance_ratio(half_y: np.ndarray, count: np.ndarray, var_iid: np.ndarray, width: int,
                              height: int, halves: str = "independent") -> np.ndarray:
    """Per pixel (4, n): how much smaller the variance of the pixel mean is with stratified samples
    than the i.i.d. estimate ``var_iid`` (4, n) says.

    The even and the odd samples (n_A = ⌈c/2⌉, n_B = ⌊c/2⌋ of a pixel's c) are independently
    scrambled sequences, so their means A, B are independent unbiased estimates, and
    (A − B)²·n_A·n_B/c² is an unbiased estimate of the variance of the pixel mean (exactly when
    n_A = n_B), but with one degree of freedom (its z-scores would be Cauchy-tailed).  So the
    per-pixel ratio of it to ``var_iid`` (in [0, c − 1]: the between-halves part of the sum of
    squares) is averaged over the 5 × 5 pixels around (pixels with c ≥ 2 and var_iid > 0): ~25
    degrees of freedom, at the price of a ratio that is local, not per pixel.  With ``halves`` "one_sequence" the
    classes A and B of one sequence (engine.render.halves: their sizes, and d scaled by the calibration factor)."""
    c = count.astype(np.float64)
    n_a, n_b = (k.astype(np.float64) for k in class_counts(count, halves))
    d = half_y[0] / np.maximum(n_a, 1) - half_y[1] / np.maximum(n_b, 1)
    f = error_factor(halves)
    if f != 1.0:
        d = f * d
    var_split = d * d * n_a * n_b / np.maximum(c * c, 1)
    ok = (c >= 2) & (var_iid > 0)
    ratio = np.where(ok, var_split / np.where(ok, var_iid, 1.0), 0.0)
    return _box_mean(ratio, ok, width, height, RATIO_RADIUS)


class SampleSums:
    """Per-pixel sums of one batch of samples over the flat pixel range [lo, hi) (a work unit's
    rows): what ``Film.add`` adds.  Computed where the batch was traced (a worker thread), so that
    the film's thread only adds ranges, in unit order (the image does not depend on threads).

    Each sum runs over the batch's samples in their order, as a bincount over the whole film would.
    """

    __slots__ = ("lo", "hi", "sums", "sumsq_y", "count", "alpha", "denoise", "n_samples", "half_y")

    def __init__(self, lo, hi, sums, sumsq_y, count, alpha, denoise, n_samples, half_y=None):
        self.lo, self.hi, self.sums, self.sumsq_y, self.count = lo, hi, sums, sumsq_y, count
        self.alpha, self.denoise, self.n_samples, self.half_y = alpha, denoise, n_samples, half_y

    @classmethod
    def of(cls, pixel: np.ndarray, stokes_rgb: np.ndarray, alpha: np.ndarray | None = None,
           denoise: tuple[np.ndarray, np.ndarray] | None = None, sample: np.ndarray | None = None) -> SampleSums:
        """Sums of samples ``stokes_rgb`` (4, 3, N) at flat pixels (N,), their alpha (N,) or None (all
        1) and denoising guides (albedo (3, N), normal (3, N)) or None; with the samples' indices
        ``sample`` (N,) (the stratified sampler; or any int64 array whose bit 0 is the sample's class,
        engine.render.halves.part_classes) also the luminance sums of classes A (bit 0 clear) and B."""
        lo, hi = (int(pixel.min()), int(pixel.max()) + 1) if pixel.size else (0, 0)
        local, span = pixel - lo, hi - lo
        # the Stokes sums, the luminance squares, the counts and the even/odd luminance sums in one compiled
        # pass (the bincounts' bits)
        sums, sumsq_y, count, half_y = pixel_sums(local, span, stokes_rgb, LUMINANCE_WEIGHTS, sample)
        alpha_sums = None if alpha is None else np.bincount(local, weights=alpha, minlength=span)
        guides = None
        if denoise is not None:
            guides = np.empty((6, span))
            for i, values in enumerate((*denoise[0], *denoise[1])):
                guides[i] = np.bincount(local, weights=values, minlength=span)
        return cls(lo, hi, sums, sumsq_y, count, alpha_sums, guides, pixel.shape[0], half_y)


class OrderedSamples:
    """A batch of samples that ``Film.add`` adds one by one in ascending sample index (adaptive
    sampling: each pixel's sums are then built in ascending sample order whatever the batching).

    ``pixel``, ``sample`` (N,) with each pixel at most once per sample index, ``values`` (4, 3, N),
    ``alpha`` (N,) or None (all 1), ``path_cost`` (N,) integers or None (not counted), ``denoise``
    (albedo (3, N), normal (3, N)) or None."""

    __slots__ = ("pixel", "sample", "values", "alpha", "path_cost", "denoise", "_ordered")

    def __init__(self, pixel, sample, values, alpha=None, path_cost=None, denoise=None):
        self.pixel, self.sample, self.values, self.alpha = pixel, sample, values, alpha
        self.path_cost, self.denoise, self._ordered = path_cost, denoise, None

    @property
    def n_samples(self) -> int:
        return int(self.pixel.shape[0])

    def ordered(self):
        """(pixel, sample, values (12, N), luminance Stokes y (4, N), alpha) sorted by sample index (stable)."""
        if self._ordered is None:
            pixel, sample, alpha = self.pixel, self.sample, self.alpha
            y = np.einsum("c,scn->sn", LUMINANCE_WEIGHTS, self.values)
            vals = self.values.reshape(12, -1)
            order = np.argsort(sample, kind="stable")
            if np.any(order != np.arange(order.size)):
                pixel, sample, vals, y = pixel[order], sample[order], vals[:, order], y[:, order]
                alpha = None if alpha is None else np.asarray(alpha)[order]
            self._ordered = (pixel, sample, vals, y, alpha)
        return self._ordered


class HalfBuffers:
    """Luminance Stokes sums of the sample classes A and B per pixel (``halves``: how the samples are split,
    engine.render.halves — "independent": even and odd sample passes; "one_sequence": the classes of one
    sequence): ``sums`` (2, 4, n),
    and the cost of the pixel's samples: ``cost`` (n,) int64 (engine.render.integrator's per-path
    count, :data:`~engine.render.integrator.PATH_COST`: the deterministic cost adaptive sampling weighs by).

    ``first``: (sums (2, 4, n), counts (n,), cost (n,)) as they were when every pixel of the window
    had its ``min_spp`` samples (None before): the allocation level μ is computed from it, so that it
    is the same after an interruption and for any threshold given on resumption."""

    def __init__(self, n: int, halves: str = "independent"):
        self.sums = np.zeros((2, 4, n))
        self.cost = np.zeros(n, np.int64)
        self.first = None
        self.halves = halves

    @classmethod
    def from_state(cls, sums: np.ndarray, cost: np.ndarray | None = None, first=None,
                   halves: str = "independent") -> HalfBuffers:
        """Half-buffers holding ``sums`` (2, 4, n) exactly, ``cost`` (n,) (None: 0) and ``first``."""
        halves = cls(sums.shape[-1], halves)
        halves.sums[:] = sums
        if cost is not None:
            halves.cost = np.asarray(cost, np.int64)
        halves.first = first
        return halves

    def add(self, part: OrderedSamples) -> None:
        """Add the part's costs, and its luminance to A or B by sample class (engine.render.halves), in ascending
        sample order."""
        if part.path_cost is not None:       # integer sums: exact in any order
            np.add.at(self.cost, part.pixel, np.asarray(part.path_cost, np.int64))
        pixel, sample, _, y, _ = part.ordered()
        if self.halves == "one_sequence":
            add_in_order(self.sums, pixel, sample, y)
            return
        for h in (0, 1):
            m = sample % 2 == h
            pix_h = pixel[m]
            for k in range(4):
                np.add.at(self.sums[h, k], pix_h, y[k, m])

    def keep_first(self, counts: np.ndarray) -> None:
        self.first = (self.sums.copy(), np.asarray(counts, np.int64).copy(), self.cost.copy())

    def means(self, counts: np.ndarray):
        """(mean_A, mean_B), each (4, n), calibrated (engine.render.halves.class_means; samples 0…c−1 give A
        ⌈c/2⌉ and B ⌊c/2⌋ of them with independent halves; 0 where none)."""
        return class_means(self.sums, counts, self.halves)


def film_from_stokes(mean_rgb: np.ndarray, spp: np.ndarray, stderr_y: np.ndarray | None = None,
                     alpha: np.ndarray | None = None, even_y: np.ndarray | None = None,
                     halves: str = "independent") -> Film:
    """A Film holding finished samples, rebuilt from pixel means (4, H, W, 3) and counts (H, W).

    Sums are mean × count (float32 means lose ~1e-7 relative).  With the per-pixel standard errors
    of the luminance components the sums of squares are restored too, otherwise they are set so
    that the resumed render's error estimate treats the old samples as noise-free.  ``alpha``
    (H, W): the stored alpha (mean coverage), restored as alpha × count.  ``even_y`` (4, H, W): the
    even samples' luminance means of a stratified render (``Film.even_means_luminance``), restored
    as the even/odd half sums (float32-rounded: they only serve the error estimate); with ``halves``
    "one_sequence" the class A means and class sums (engine.render.halves).
    """
    H, W = spp.shape
    film = Film(W, H)
    count = spp.reshape(-1).astype(np.int64)
    film.count[:] = count
    film.sums[:] = np.asarray(mean_rgb, np.float64).transpose(0, 3, 1, 2).reshape(4, 3, -1) * count
    y = np.einsum("c,scn->sn", LUMINANCE_WEIGHTS, film.sums) / np.maximum(count, 1)
    if stderr_y is not None:
        var = np.asarray(stderr_y, np.float64).reshape(4, -1) ** 2 * count
        film.sumsq_y[:] = (var * np.maximum(count - 1, 0) / np.maximum(count, 1) + y * y) * count
    else:
        film.sumsq_y[:] = y * y * count
    if alpha is not None:
        film.alpha_sums = np.asarray(alpha, np.float64).reshape(-1) * count
    if even_y is not None:
        film.half_y = np.empty((2, 4, count.shape[0]))
        film.one_sequence = halves == "one_sequence"
        film.half_y[0] = np.asarray(even_y, np.float64).reshape(4, -1) * class_counts(count, halves)[0]
        film.half_y[1] = np.einsum("c,scn->sn", LUMINANCE_WEIGHTS, film.sums) - film.half_y[0]
    return film
