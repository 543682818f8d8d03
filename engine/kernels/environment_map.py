"""An equirectangular environment map's radiance lookup, pdf and importance sampling as compiled loops.

The NumPy references are engine.render.lights.environment's ``lookup_numpy``, ``pdf_numpy`` and
``sample_numpy`` (EnvironmentMapEmitter's arithmetic, paired there with these loops by ``twin``); each loop
runs the same arithmetic in the same order per direction, without the batch-sized temporaries:

- ``lookup``: at the map coordinates (u, v) (N,) each (the directions' u = (½ − atan2(y, x)/2π) mod 1,
  v = acos(z/|d|)/π, computed by NumPy: on AVX-512 CPUs NumPy's atan2, acos and pow differ from Numba's in the
  last bit) the bilinear value of the texels (H, W, C) on the grid (``mitsuba``: knots at the texel rows,
  v·(H − 1); else Cycles' texel centres, v·H − ½ clamped to the first and last rows), periodic in u,
  × ``strength`` → out (C, N) (an sRGB-interpolated map is decoded after, in NumPy);
- ``pdf``: the solid-angle pdf cell_pdf[j, i] (per sr) of the bilinear piece holding each (u, v);
- ``sample``: as Cycles' background map (light/background.h), the pair u₁, u₂ alone: the row by u₁ on the rows'
  marginal ``row_cdf``, the piece within it by u₂ on the row's part of the flat ``cdf`` (numpy.searchsorted's
  "right" side both), each number's remainder within its step placing the direction uniformly in solid angle
  inside the piece (cos θ between its knot rows, longitude) → the map-frame direction (3, N), its pdf and 1/pdf
  (0 where the pdf is 0); one continuous map of the pair, so a stratified pair stays stratified on the sphere;
- ``uniform_sample``: a constant sky's sample (EnvironmentEmitter.sample): directions uniform on the sphere
  (z = 1 − 2u₀, φ = 2πu₁, as engine.materials.sampling.uniform_sphere), distance ∞, 1/pdf = 4π, pdf = 1/4π.
"""

from __future__ import annotations

import math

import numpy as np

from . import jit, jit_inner


@jit
def _lookup_loop(u_, v_, img, mitsuba, strength, out):
    H, W, C = img.shape
    for k in range(u_.shape[0]):
        u, v = u_[k], v_[k]
        x = (u * W - 0.5) % W
        i0 = min(np.floor(x), W - 1.0)
        fx = x - i0
        if mitsuba:
            y = v * (H - 1)
            j0 = min(np.floor(y), H - 2.0)
            fy = y - j0
        else:
            y = v * H - 0.5
            j0 = min(max(np.floor(y), 0.0), H - 2.0)
            fy = min(max(y - j0, 0.0), 1.0)
        a, b = np.int64(i0), np.int64(j0)
        a1 = (a + 1) % W
        for c in range(C):
            top = img[b, a, c] * (1 - fx) + img[b, a1, c] * fx
            bot = img[b + 1, a, c] * (1 - fx) + img[b + 1, a1, c] * fx
            value = top * (1 - fy) + bot * fy
            out[c, k] = value * strength


@jit
def _pdf_loop(u_, v_, cell_pdf, H, mitsuba, out):
    W = cell_pdf.shape[1]
    for k in range(u_.shape[0]):
        u, v = u_[k], v_[k]
        i = np.int64(np.floor(u * W - 0.5)) % W
        if mitsuba:
            j = np.int64(min(np.floor(v * (H - 1)), H - 2.0))
        else:
            j = np.int64(min(max(np.floor(v * H + 0.5), 0.0), float(H)))
        out[k] = cell_pdf[j, i]


@jit_inner
def _search_right(cdf, target, lo, hi):
    """The first index in [lo, hi) whose ``cdf`` exceeds ``target`` (numpy.searchsorted's "right" side), hi if none."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if cdf[mid] <= target:
            lo = mid + 1
        else:
            hi = mid
    return lo


@jit
def _sample_loop(cdf, row_cdf, row_prob, row_start, cos_knots, cell_pdf, u, dm, scale, pdf):
    W = cell_pdf.shape[1]
    K = row_prob.shape[0]
    for k in range(u.shape[1]):
        j = min(_search_right(row_cdf, u[1, k], 0, K), K - 1)
        pj = row_prob[j]
        dv = min(max((u[1, k] - (row_cdf[j] - pj)) / (pj if pj > 0 else 1.0), 0.0), 1.0)
        target = row_start[j] + u[2, k] * pj
        c = min(max(_search_right(cdf, target, j * W, j * W + W), j * W), j * W + W - 1)
        i = c - j * W
        cell = cdf[c] - (cdf[c - 1] if c > 0 else 0.0)
        du = min(max((target - (cdf[c] - cell)) / (cell if cell > 0 else 1.0), 0.0), 1.0)
        cos_t = cos_knots[j] + dv * (cos_knots[j + 1] - cos_knots[j])
        sin_t = np.sqrt(max(1.0 - cos_t * cos_t, 0.0))
        phi = math.pi * (1.0 - 2.0 * ((i + 0.5 + du) / W))
        dm[0, k] = sin_t * np.cos(phi)
        dm[1, k] = sin_t * np.sin(phi)
        dm[2, k] = cos_t
        p = cell_pdf[j, i]
        pdf[k] = p
        scale[k] = 1.0 / p if p > 0 else 0.0


@jit
def _uniform_loop(u, wi, dist, scale, pdf, valid):
    for k in range(u.shape[1]):
        z = 1.0 - 2.0 * u[0, k]
        r = np.sqrt(max(1.0 - z * z, 0.0))
        phi = 2.0 * np.pi * u[1, k]
        wi[0, k], wi[1, k], wi[2, k] = r * np.cos(phi), r * np.sin(phi), z
        dist[k], scale[k], pdf[k], valid[k] = np.inf, 4.0 * math.pi, 1.0 / (4.0 * math.pi), True


def lookup_numba(u, v, img, mitsuba, strength):
    out = np.empty((img.shape[2], u.shape[0]))
    _lookup_loop(u, v, img, bool(mitsuba), float(strength), out)
    return out


def pdf_numba(u, v, cell_pdf, H, mitsuba):
    out = np.empty(u.shape[0])
    _pdf_loop(u, v, cell_pdf, int(H), bool(mitsuba), out)
    return out


def sample_numba(cdf, row_cdf, row_prob, row_start, cos_knots, cell_pdf, u):
    u = np.asarray(u, np.float64)
    n = u.shape[1]
    dm, scale, pdf = np.empty((3, n)), np.empty(n), np.empty(n)
    _sample_loop(cdf, row_cdf, row_prob, row_start, cos_knots, cell_pdf, u, dm, scale, pdf)
    return dm, scale, pdf


def uniform_sample_numba(u):
    n = u.shape[1]
    out = np.empty((3, n)), np.empty(n), np.empty(n), np.empty(n), np.empty(n, np.bool_)
    _uniform_loop(u, *out)
    return out


#: The compiled halves (None without Numba); the pairs are declared in engine.render.lights.environment.
lookup_numba = _lookup_loop and lookup_numba
pdf_numba = _pdf_loop and pdf_numba
sample_numba = _sample_loop and sample_numba
uniform_sample_numba = _uniform_loop and uniform_sample_numba
