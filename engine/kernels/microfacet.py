"""Beckmann visible-slope sampling (Heitz & d'Eon 2014) as one compiled loop per path.

The same algorithm and constants as engine.materials.microfacet.Beckmann (the NumPy reference):
x̃ solves F(x̃) = u·F(cotθ), F(x) = erfc(−x) + tanθ e^{−x²}/√π, by Halley steps safeguarded by
bisection on [−8, min(cotθ, 8)], started from Giles' erfc⁻¹ (or the left-tail inverse for
tanθ > 1); erfcx(x) = e^{x²} erfc(x) is the same Chebyshev series (coefficients passed in).
Each path iterates until its own stopping rule, exactly as the vectorised version does per
element; results agree to rounding (exp/log of the C library vs NumPy's).
"""

from __future__ import annotations

import math

import numpy as np

from . import jit

_SQRT_PI = math.sqrt(math.pi)
_INV_SQRT_PI = 1.0 / _SQRT_PI
_TWO_OVER_SQRT_PI = 2.0 / _SQRT_PI
#: M. Giles (2010), erfinv(y) ≈ y·p(w), w = −log(1 − y²): Horner coefficients of p, highest first,
#: for w < 5 (in w − 2.5) and w ≥ 5 (in √w − 3).  Shared with the NumPy reference
#: (engine.materials.microfacet._erfcinv_giles).
GILES_LOW = (2.81022636e-08, 3.43273939e-07, -3.5233877e-06, -4.39150654e-06, 0.00021858087, -0.00125372503,
             -0.00417768164, 0.246640727, 1.50140941)
GILES_HIGH = (-0.000200214257, 0.000100950558, 0.00134934322, -0.00367342844, 0.00573950773, -0.0076224613,
              0.00943887047, 1.00167406, 2.83297682)


@jit
def _erfcx_nonneg(x, coef, k):
    xc = min(x, 1e150)
    t = (xc - k) / (xc + k)
    t2 = 2.0 * t
    b1 = 0.0
    b2 = 0.0
    for j in range(coef.shape[0] - 1, 0, -1):
        b0 = (t2 * b1 - b2) + coef[j]
        b2 = b1
        b1 = b0
    return (coef[0] + t * b1 - b2) / (xc + k)


@jit
def _slope_cdf(x, t, coef, k):
    e = np.exp(-x * x)
    r = _erfcx_nonneg(abs(x), coef, k)
    tp = t * _INV_SQRT_PI
    return e * (r + tp) if x < 0 else 2.0 + e * (tp - r)


@jit
def _erfcinv_giles(q):
    y = 1.0 - q
    w = -np.log(q * (2.0 - q))
    if w < 5.0:
        wl = w - 2.5
        p = GILES_LOW[0]
        for j in range(1, len(GILES_LOW)):
            p = GILES_LOW[j] + p * wl
    else:
        wh = np.sqrt(w) - 3.0
        p = GILES_HIGH[0]
        for j in range(1, len(GILES_HIGH)):
            p = GILES_HIGH[j] + p * wh
    return max(p * y, 0.0)


@jit
def _visible_slope_x_loop(tan_t, u1, coef, k, out):
    for i in range(tan_t.shape[0]):
        t = tan_t[i]
        cot = 1.0 / t if t > 0 else np.inf
        lo = -8.0
        hi = min(cot, 8.0)
        z = _slope_cdf(min(cot, 30.0), t, coef, k)
        u = min(max(u1[i], 0.0), 1.0)
        uc = min(max(u, 1e-300), 1.0 - 1e-16)
        if uc < 0.5:
            xg = -_erfcinv_giles(2.0 * uc)
        else:
            xg = _erfcinv_giles(2.0 * (1.0 - uc))
        arg = uc * z * _SQRT_PI / max(t, 1e-300)
        xr = -np.sqrt(max(-np.log(min(arg, 1.0)), 0.0))
        x = min(xr, hi) if t > 1.0 else xg
        if not (x > lo and x < hi):
            x = 0.5 * (lo + max(hi, lo))
        target = u * z
        tol = 1e-14 * z
        for _ in range(100):
            f = _slope_cdf(x, t, coef, k) - target
            hit = abs(f) <= tol
            if f < 0:
                lo = x
            if f > 0:
                hi = x
            g = _TWO_OVER_SQRT_PI * np.exp(-x * x)
            d1 = g * (1.0 - x * t)
            d2 = -g * (2.0 * x * (1.0 - x * t) + t)
            den = 2.0 * d1 * d1 - f * d2
            ok = d1 > 0 and den > 0
            newton = x - 2.0 * f * d1 / (den if ok else 1.0)
            inside = ok and newton > lo and newton < hi
            xn = x if hit else (newton if inside else 0.5 * (lo + hi))
            done = hit or (inside and abs(newton - x) <= 1e-6 * (1.0 + abs(x))) or \
                (hi - lo <= 1e-15 * (1.0 + abs(x)))
            x = xn
            if done:
                break
        out[i] = x


def visible_slope_x_numba(tan_t, u1, coef, k):
    """x̃ (N,) for tanθ (N,) ≥ 0 and u1 (N,) ∈ [0, 1); ``coef``, ``k``: the erfcx series."""
    out = np.empty(np.shape(tan_t))
    _visible_slope_x_loop(np.ascontiguousarray(tan_t, dtype=np.float64), np.ascontiguousarray(u1, dtype=np.float64),
                          np.ascontiguousarray(coef, dtype=np.float64), float(k), out)
    return out


compiled_visible_slope_x = _visible_slope_x_loop and visible_slope_x_numba
