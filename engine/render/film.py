"""Pixel accumulation with a box filter: per-pixel sums of whole path samples.

Sums are float64 and added in a fixed order, so a render is deterministic.
Besides the Stokes sums (4 components × linear sRGB) the film keeps the sum
of squares of the luminance Stokes vector per pixel, from which the standard
error of each pixel mean follows (used by tests and the peer comparisons), and
the sum of per-sample alpha (coverage of the camera rays: 0 where a sample saw
the transparent background or a holdout, as Cycles' alpha; 1 for samples added
without alpha).  With denoising data (``add_denoise_data``) it also sums the per-sample albedo
and shading normal of the first non-delta vertex (Cycles' Denoising Albedo / Normal).
"""

from __future__ import annotations

import numpy as np

from ..spectral.cie import LUMINANCE_WEIGHTS


class Film:
    def __init__(self, width: int, height: int):
        self.width, self.height = width, height
        n = width * height
        self.sums = np.zeros((4, 3, n))
        self.sumsq_y = np.zeros((4, n))
        self.count = np.zeros(n, np.int64)
        self.alpha_sums = None          # None: every sample so far had alpha 1 (no memory spent)
        self.denoise_sums = None        # None: no denoising data asked for; else (6, n): albedo RGB, normal XYZ
        self._added = False             # samples added yet (see ``add``)

    def add_samples(self, pixel: np.ndarray, stokes_rgb: np.ndarray, alpha: np.ndarray | None = None) -> None:
        """Add complete samples: ``stokes_rgb`` (4, 3, N) for flat pixel indices (N,), with their alpha
        (N,) or None (all 1)."""
        self.add(SampleSums.of(pixel, stokes_rgb, alpha))

    def add(self, part: SampleSums) -> None:
        """Add the sums of a batch of samples (``SampleSums.of``, computed on any thread).

        The same additions as summing the batch over the whole film: pixels outside the part's
        range would only have had 0 added."""
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
        self.count[lo:hi] += part.count
        if part.denoise is not None:
            if self.denoise_sums is None:
                self.denoise_sums = np.zeros((6, self.count.shape[0]))
            self.denoise_sums[:, lo:hi] += part.denoise

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

    def stderr_luminance(self) -> np.ndarray:
        """Standard error of the luminance Stokes pixel means, (4, H, W) (0 where spp < 2)."""
        c = self.count.astype(np.float64)
        y_mean = np.einsum("c,scn->sn", LUMINANCE_WEIGHTS, self.sums) / np.maximum(c, 1)
        var = (self.sumsq_y / np.maximum(c, 1) - y_mean ** 2) * c / np.maximum(c - 1, 1)
        se = np.sqrt(np.maximum(var, 0.0) / np.maximum(c, 1))
        se[:, c < 2] = 0.0
        return se.reshape(4, self.height, self.width)

    def spp_image(self) -> np.ndarray:
        return self.count.reshape(self.height, self.width)


class SampleSums:
    """Per-pixel sums of one batch of samples over the flat pixel range [lo, hi) (a work unit's
    rows): what ``Film.add`` adds.  Computed where the batch was traced (a worker thread), so that
    the film's thread only adds ranges, in unit order (the image does not depend on threads).

    Each sum runs over the batch's samples in their order, as a bincount over the whole film would.
    """

    __slots__ = ("lo", "hi", "sums", "sumsq_y", "count", "alpha", "denoise", "n_samples")

    def __init__(self, lo, hi, sums, sumsq_y, count, alpha, denoise, n_samples):
        self.lo, self.hi, self.sums, self.sumsq_y, self.count = lo, hi, sums, sumsq_y, count
        self.alpha, self.denoise, self.n_samples = alpha, denoise, n_samples

    @classmethod
    def of(cls, pixel: np.ndarray, stokes_rgb: np.ndarray, alpha: np.ndarray | None = None,
           denoise: tuple[np.ndarray, np.ndarray] | None = None) -> SampleSums:
        """Sums of samples ``stokes_rgb`` (4, 3, N) at flat pixels (N,), their alpha (N,) or None (all
        1) and denoising guides (albedo (3, N), normal (3, N)) or None."""
        lo, hi = (int(pixel.min()), int(pixel.max()) + 1) if pixel.size else (0, 0)
        local, span = pixel - lo, hi - lo
        sums = np.empty((4, 3, span))
        for s in range(4):
            for c in range(3):
                sums[s, c] = np.bincount(local, weights=stokes_rgb[s, c], minlength=span)
        y = np.einsum("c,scn->sn", LUMINANCE_WEIGHTS, stokes_rgb)
        sumsq_y = np.empty((4, span))
        for s in range(4):
            sumsq_y[s] = np.bincount(local, weights=y[s] * y[s], minlength=span)
        count = np.bincount(local, minlength=span)
        alpha_sums = None if alpha is None else np.bincount(local, weights=alpha, minlength=span)
        guides = None
        if denoise is not None:
            guides = np.empty((6, span))
            for i, values in enumerate((*denoise[0], *denoise[1])):
                guides[i] = np.bincount(local, weights=values, minlength=span)
        return cls(lo, hi, sums, sumsq_y, count, alpha_sums, guides, pixel.shape[0])


def film_from_stokes(mean_rgb: np.ndarray, spp: np.ndarray, stderr_y: np.ndarray | None = None,
                     alpha: np.ndarray | None = None) -> Film:
    """A Film holding finished samples, rebuilt from pixel means (4, H, W, 3) and counts (H, W).

    Sums are mean × count (float32 means lose ~1e-7 relative).  With the per-pixel standard errors
    of the luminance components the sums of squares are restored too, otherwise they are set so
    that the resumed render's error estimate treats the old samples as noise-free.  ``alpha``
    (H, W): the stored alpha (mean coverage), restored as alpha × count.
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
    return film
