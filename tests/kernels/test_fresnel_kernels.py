"""Fresnel values a chunk of paths at a time (engine.kernels.fresnel.abcs_row, abcs_fixups).

The measured-metal and constant-index mirror steps evaluate the Fresnel coefficients a wavelength at
a time over a chunk of paths in a branch-free form the compiler vectorises, with abcs_at's own
fallbacks for the lanes it cannot take; every lane must carry abcs_at's bits, at the edges (grazing,
NaN, real indices, extreme magnitudes) too.
"""

import itertools

import numpy as np
import pytest

from engine import kernels

needs_numba = pytest.mark.skipif(kernels._numba is None, reason="numba is not installed (NumPy kernels only)")


@needs_numba
def test_chunked_fresnel_gives_abcs_at_bits_in_every_lane():
    from engine.kernels import jit
    from engine.kernels.delta_bounce import _CHUNK, _chunk_fresnel, _fresnel_buffers
    from engine.kernels.fresnel import abcs_at

    @jit
    def chunked(cos, w, er, ei, complex_index, out):
        L, n = er.shape
        abcs, _ = np.empty((L, 4, _CHUNK)), 0
        c, ww, e, fast = _fresnel_buffers(L)
        for j0 in range(0, n, _CHUNK):
            m = min(_CHUNK, n - j0)
            for i in range(m):
                c[i] = cos[j0 + i]
                ww[i] = w[j0 + i]
                for q in range(L):
                    e[q, 0, i] = er[q, j0 + i]
                    e[q, 1, i] = ei[q, j0 + i]
            _chunk_fresnel(c, ww, e, m, abcs, fast, complex_index)
            for q in range(L):
                for k in range(4):
                    for i in range(m):
                        out[q, k, j0 + i] = abcs[q, k, i]

    @jit
    def lanes(cos, w, er, ei, out):
        for q in range(er.shape[0]):
            for i in range(er.shape[1]):
                a, b, c, s = abcs_at(cos[i], complex(er[q, i], ei[q, i]))
                out[q, 0, i] = a * w[i]
                out[q, 1, i] = b * w[i]
                out[q, 2, i] = c * w[i]
                out[q, 3, i] = s * w[i]

    cosines = [-0.1, -0.0, 0.0, 1e-300, 1e-201, 1e-199, 1e-8, 0.3, 0.7071, 1.0 - 1e-16, 1.0, 1.2, np.nan]
    parts = [0.0, 1e-200, 1e-160, 1e-80, 0.05, 0.47, 1.0, 1.5, 2.4, 7.0, 1e75, 1e160, np.inf, np.nan]
    grid = np.array(list(itertools.product(cosines, parts, parts))).T
    rng = np.random.default_rng(47)
    n_rand = 5000
    rand = np.stack((rng.uniform(-0.05, 1.05, n_rand), rng.uniform(0.01, 5, n_rand), rng.uniform(0, 6, n_rand)))
    rand[2, ::5] = 0.0                                          # real indices among them
    cos, er, ei = np.concatenate((grid, rand), axis=1)
    n = cos.size
    w = np.where(rng.random(n) < 0.9, 1.0, 0.0)
    L = 4
    er4 = np.stack([er, er * 1.01, er[::-1], er])
    ei4 = np.stack([ei, ei, ei[::-1], ei * 0.5])
    got, want = np.empty((L, 4, n)), np.empty((L, 4, n))
    chunked(cos, w, er4, ei4, True, got)
    lanes(cos, w, er4, ei4, want)
    assert got.tobytes() == want.tobytes()
    real = np.zeros_like(ei4)                                   # the real-index path of the black-glass mirror
    chunked(cos, w, er4, real, False, got)
    lanes(cos, w, er4, real, want)
    assert got.tobytes() == want.tobytes()
