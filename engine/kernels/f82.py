"""Cycles' F82-Tint reflectance over a metal's own Fresnel reflectance (engine.materials.tinted.F82Reflectance's
ratio F_F82(θ)/F(θ)) per wavelength and point as one compiled loop.

``f82_ratio_loop`` is F82Reflectance._ratio's NumPy arithmetic per element in the same order (the clips as
np.clip's, NaN kept; F the compiled Fresnel ``abcs_at``'s bits, as the NumPy code's Fresnel runs when kernels are
compiled, taken a wavelength at a time over blocks of lanes by fresnel.abcs_row); the facet cosine's (N,) powers
come computed by NumPy (the same ``**``).
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner
from .fresnel import abcs_fixups, abcs_row


@jit_inner
def _clip01(x):
    """np.clip(x, 0, 1) for one number: NaN stays NaN, −0 becomes 0."""
    v = x if (x > 0.0 or x != x) else 0.0
    return v if (v < 1.0 or v != v) else 1.0


#: lanes per block: the Fresnel values of a block are taken a wavelength at a time (fresnel.abcs_row, SIMD)
_CHUNK = 256


@jit
def _f82_ratio_loop(c, s, s5, eta, f0, tint, has_tint, f82_curve, f5, k7, out):
    L, N = out.shape
    w = np.ones(_CHUNK)
    e, abcs, fast = np.empty((L, 2, _CHUNK)), np.empty((L, 4, _CHUNK)), np.empty(_CHUNK, np.bool_)
    for j0 in range(0, N, _CHUNK):
        m = min(_CHUNK, N - j0)
        cos = c[j0:j0 + m]
        for q in range(L):
            for jj in range(m):
                v = eta[q, j0 + jj]
                e[q, 0, jj] = v.real
                e[q, 1, jj] = v.imag
            # F = abcs_at(c, η)[0] (·1: the same bits), the usual lanes without branches
            abcs_row(cos, w, e, q, m, abcs, fast)
            abcs_fixups(cos, w, e, q, m, abcs, fast)
            for jj in range(m):
                k = j0 + jj
                F = abcs[q, 0, jj]
                f = _clip01(f0[q, k])
                if f82_curve:
                    schlick = f + (1.0 - f) * s5[k]
                    if has_tint:
                        b = (f + (1.0 - f) * f5) * k7 * (1.0 - _clip01(tint[q, k]))
                        target = _clip01(schlick - b * c[k] * s5[k] * s[k])
                    else:
                        target = _clip01(schlick)
                else:
                    target = f
                out[q, k] = target / F if F > 0 else 1.0


#: (cosθ_f clipped (N,), 1 − cosθ_f (N,), its 5th power (N,), η (L, N) complex, F0 (L, N), tint (L, N), has_tint,
#: the F82-Tint curve (else F0 at every angle), (6/7)⁵, 7/((6/7)⁵·6/7), out ratio (L, N)); None without Numba.
f82_ratio_loop = _f82_ratio_loop
