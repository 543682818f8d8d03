"""The two sample classes A and B of a pixel, whose luminance sums give the half-split error estimate.

A render keeps, besides a pixel's sums, the luminance Stokes sums of two classes of its samples (the film's
``half_y``, adaptive sampling's engine.render.film.HalfBuffers); the difference of their means estimates the error
of the pixel value.  Which sample is in which class depends on how the samples draw the pattern's numbers
(``RenderSettings.halves``, resolved):

* "independent": class = the sample's parity (A even, B odd), fixed per sample.  The even and odd samples are two
  independently scrambled sequences, so A and B are independent estimates and ½|A − B| is an unbiased one-draw
  estimate of the standard error.
* "one_sequence" (the samples are ONE sequence, engine.render.sampler.sequence_index): the **octave split** of a
  pixel's c samples — A = samples 0 … q − 1, B = samples q … c − 1, q = the largest power of two below c.  At
  c = 2^(m+1) both classes are aligned blocks of 2^m indices of every pair's (0, 2)-sequence, i.e. each is a
  (0, m, 2)-net of every pair of dimensions (at c = 3·2^k, a net of 2^(k+1) and one of 2^k).  A split fixed per
  sample cannot do that: of the splits by a parity of index bits (Cycles' ``popcount(i & 0xaaaaaaaa)`` among
  them) only popcount(i >> 1) leaves each class covering the 2^m intervals of both pixel-jitter dimensions at
  every m, none a (0, m, 2)-net, and with it ½|A − B| overstated the image's true S0 error 1.4–26× (growing with
  the spp; the octave classes: 0.75–2.1×) — docs/guide/adaptive-sampling.md, "The two classes of one sequence".
  The classes move as
  the count grows: when sample 2^k is added, B is folded into A (A ← A + B, B ← 0), so the sums are streamed in
  ascending sample order (``fold_part`` for a part's sums, ``add_in_order`` sample by sample).  A and B are
  correlated (two halves of one net), so ½|A − B| is multiplied by ``ERROR_FACTOR`` (measured against
  high-spp references).

``class_counts`` gives the class sizes of a pixel's c samples, ``part_classes`` the classes of a part's samples
(the kernels' ``sample & 1``), ``class_means`` the calibrated class means.
"""

from __future__ import annotations

import numpy as np

#: The calibration of the one-sequence half-split error (docs/guide/adaptive-sampling.md, "Error estimate"): the
#: raw ½|A − B| (and every quantity derived from A and B) is multiplied by this factor, the inverse of the
#: median ratio raw ÷ true error of the image's RMS error, 1.20 (S0 and DoLP of glass_sphere, fresnel_sphere_au,
#: rough_sphere_a030 and the demo at 16–256 spp, 4 seeds each: 0.75–2.10; the median over 4×4 tiles 1.50–1.82;
#: tests/bench/halves_calibration.py).  "independent" halves: 1 (unbiased, no scaling).
ERROR_FACTOR = 1.0 / 1.2


def octave(count: np.ndarray) -> np.ndarray:
    """q (int64): the largest power of two below ``count`` (0 where count ≤ 1) — class A's size."""
    x = np.maximum(np.asarray(count, np.int64) - 1, 0)
    for shift in (1, 2, 4, 8, 16, 32):            # every bit below the highest set: x = 2^bit_length − 1
        x = x | (x >> shift)
    return (x + 1) >> 1


def class_counts(count: np.ndarray, halves: str) -> tuple[np.ndarray, np.ndarray]:
    """(n_A, n_B) int64: the sizes of classes A and B of a pixel's samples 0 … c − 1 (``count`` c (n,))."""
    c = np.asarray(count, np.int64)
    if halves == "independent":
        return (c + 1) // 2, c // 2
    _check(halves)
    q = octave(c)
    return q, c - q


def _check(halves: str) -> None:
    if halves != "one_sequence":
        raise ValueError(f"halves must be resolved ('independent' or 'one_sequence'), got {halves!r}")


def part_classes(pixel: np.ndarray, sample: np.ndarray, halves: str, end: int | None = None) -> np.ndarray:
    """An int64 array (N,) whose bit 0 is the class (0: A, 1: B) of the samples (``pixel``, ``sample``) (N,) of a
    part added to a film whose pixels hold the samples before the part's (engine.render.film.SampleSums,
    ``fold_part``): "independent": ``sample`` itself (its parity); "one_sequence": B where the sample is at or
    beyond the octave q(e) of the pixel's count e after the part (its largest sample in the part + 1; ``end``:
    that count where every pixel of the part ends there, a uniform render's unit)."""
    if halves == "independent":
        return sample
    _check(halves)
    pixel, sample = np.asarray(pixel, np.int64), np.asarray(sample, np.int64)
    if end is not None:
        return (sample >= int(octave(np.array([end]))[0])).astype(np.int64)
    if not pixel.size:
        return np.zeros(0, np.int64)
    lo = int(pixel.min())
    end = np.zeros(int(pixel.max()) - lo + 1, np.int64)
    np.maximum.at(end, pixel - lo, sample + 1)
    return (sample >= octave(end)[pixel - lo]).astype(np.int64)


def fold_part(half_y: np.ndarray, before: np.ndarray, added: np.ndarray, part: np.ndarray) -> None:
    """Add a part's class sums ``part`` (2, 4, m) (``part_classes``' split) to one-sequence class sums ``half_y``
    (2, 4, m) in place, for pixels holding ``before`` (m,) samples that get ``added`` (m,) more: where the octave
    of the new count is at or beyond ``before`` (A grows past the old samples), A ← (A + B) + A_part,
    B ← B_part; elsewhere A, B += the part's (A_part is 0 there)."""
    fold = (added > 0) & (octave(before + added) >= before)
    if fold.any():
        half_y[0][:, fold] = (half_y[0][:, fold] + half_y[1][:, fold]) + part[0][:, fold]
        half_y[1][:, fold] = part[1][:, fold]
    keep = ~fold
    half_y[:, :, keep] += part[:, :, keep]


def add_in_order(sums: np.ndarray, pixel: np.ndarray, sample: np.ndarray, y: np.ndarray) -> None:
    """Add samples (``pixel``, ``sample`` (N,) sorted by sample, luminance Stokes ``y`` (4, N)) to one-sequence
    class sums ``sums`` (2, 4, n) one by one in ascending sample order: before sample 2^k (k ≥ 0) of a pixel B is
    folded into A; every sample goes to B.  The same operations per pixel whatever the batching."""
    bounds = [0]
    s_max = int(sample[-1]) if sample.size else 0
    k = 1
    while k <= s_max:
        bounds.append(int(np.searchsorted(sample, k, side="left")))
        k *= 2
    bounds.append(sample.size)
    for i in range(len(bounds) - 1):
        a, b = bounds[i], bounds[i + 1]
        if a == b:
            continue
        if i > 0:                           # pixels whose sample 2^(i−1) is here: fold before adding it
            p = pixel[a:b][sample[a:b] == (1 << (i - 1))]
            sums[0][:, p] += sums[1][:, p]
            sums[1][:, p] = 0.0
        for c in range(4):
            np.add.at(sums[1, c], pixel[a:b], y[c, a:b])


def error_factor(halves: str) -> float:
    """The factor the half-split error of ``halves`` is multiplied by (``ERROR_FACTOR``; 1 for "independent")."""
    return 1.0 if halves == "independent" else ERROR_FACTOR


def _ratio(num, den):
    out = np.zeros(np.broadcast(num, den).shape)
    np.divide(num, den, out=out, where=den > 0)
    return out


def class_means(sums: np.ndarray, count: np.ndarray, halves: str) -> tuple[np.ndarray, np.ndarray]:
    """(mean_A, mean_B), each (4, n), of class sums ``sums`` (2, 4, n) of pixels with ``count`` (n,) samples (0 where
    a class has none), calibrated: with a factor f ≠ 1 (``error_factor``) both are moved toward their midpoint
    m = (A + B)/2 (A' = m + f·(A − m)), so that every error taken from their difference (½|A − B| and the ratios
    of engine.render.adaptive.pixel_noise) is f × the raw one, to first order, and A' + B' = A + B."""
    n_a, n_b = class_counts(count, halves)
    a, b = _ratio(sums[0], n_a), _ratio(sums[1], n_b)
    f = error_factor(halves)
    if f != 1.0:
        m = 0.5 * (a + b)
        a, b = m + f * (a - m), m + f * (b - m)
    return a, b
