"""Cycles' F82-Tint reflectance over a metal's own Fresnel reflectance (engine.materials.tinted.F82Reflectance's
ratio F_F82(θ)/F(θ)) per wavelength and point as one compiled loop.

``f82_ratio_loop`` is F82Reflectance._ratio's NumPy arithmetic per element in the same order (the clips as
np.clip's, NaN kept; F the compiled Fresnel ``abcs_at``, as the NumPy code's Fresnel runs when kernels are
compiled); the facet cosine's (N,) powers come computed by NumPy (the same ``**``).
"""

from __future__ import annotations

from . import jit, jit_inner
from .fresnel import abcs_at


@jit_inner
def _clip01(x):
    """np.clip(x, 0, 1) for one number: NaN stays NaN, −0 becomes 0."""
    v = x if (x > 0.0 or x != x) else 0.0
    return v if (v < 1.0 or v != v) else 1.0


@jit
def _f82_ratio_loop(c, s, s5, eta, f0, tint, has_tint, f82_curve, f5, k7, out):
    L, N = out.shape
    for q in range(L):
        for k in range(N):
            F = abcs_at(c[k], eta[q, k])[0]
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
