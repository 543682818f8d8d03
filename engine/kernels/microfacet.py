"""Beckmann visible-slope sampling (Heitz & d'Eon 2014): the NumPy reference and one compiled loop.

x̃ (the slope along the stretched viewing direction of the unit-roughness surface seen at θ) has
density ∝ (1 − x̃ tanθ) e^{−x̃²} on x̃ < cotθ and CDF F(x)/F(cotθ), F(x) = erfc(−x) + tanθ e^{−x²}/√π
(evaluated through erfcx, tail-accurate).  It solves F(x̃) = u·F(cotθ) by Halley steps safeguarded
by bisection on the bracket [−8, min(cotθ, 8)] (F(−8)/F(cotθ) < 1e-27), started from Giles'
erfc⁻¹ (or, for tanθ > 1, the inverse of the left tail ≈ e^{−x²}·(tanθ/√π)/F(cotθ)).  Each path
iterates until its own stopping rule; the compiled loop is the same algorithm per path and agrees
to rounding (exp/log of the C library vs NumPy's).  engine.materials.microfacet.Beckmann samples
with it.
"""

from __future__ import annotations

import numpy as np

from . import jit, twin
from .error_function import (ERFCX_COEF, ERFCX_K, SQRT_PI, erfcinv_giles, erfcinv_giles_scalar, erfcx_nonneg,
                             erfcx_nonneg_scalar)

_INV_SQRT_PI = 1.0 / SQRT_PI
_TWO_OVER_SQRT_PI = 2.0 / SQRT_PI


def _visible_slope_cdf(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """F(x) = erfc(−x) + t e^{−x²}/√π (unnormalised CDF of the visible slope x̃), tail-accurate."""
    e = np.exp(-x * x)
    r = erfcx_nonneg(np.abs(x))
    tp = t * _INV_SQRT_PI
    return np.where(x < 0, e * (r + tp), 2.0 + e * (tp - r))


def visible_slope_x_numpy(tan_t: np.ndarray, u1: np.ndarray) -> np.ndarray:
    """x̃ (N,) for tanθ (N,) ≥ 0 and u1 (N,) ∈ [0, 1) (see the module docstring)."""
    n = tan_t.shape[0]
    cot = np.where(tan_t > 0, 1.0 / np.where(tan_t > 0, tan_t, 1.0), np.inf)
    lo = np.full(n, -8.0)
    hi = np.minimum(cot, 8.0)
    z = _visible_slope_cdf(np.minimum(cot, 30.0), tan_t)
    u = np.clip(u1, 0.0, 1.0)
    # Start: the Gaussian quantile (exact for θ = 0); for large tanθ the left tail is
    # ≈ e^{−x²}·(tanθ/√π)/F(cotθ), whose inverse is the better start.
    uc = np.clip(u, 1e-300, 1.0 - 1e-16)
    lower = uc < 0.5
    xg = erfcinv_giles(2.0 * np.where(lower, uc, 1.0 - uc))
    xg = np.where(lower, -xg, xg)
    arg = uc * z * SQRT_PI / np.maximum(tan_t, 1e-300)
    xr = -np.sqrt(np.maximum(-np.log(np.minimum(arg, 1.0)), 0.0))
    x = np.where(tan_t > 1.0, np.minimum(xr, hi), xg)
    x = np.where((x > lo) & (x < hi), x, 0.5 * (lo + np.maximum(hi, lo)))
    target = u * z
    tol = 1e-14 * z
    active = np.arange(n)
    xa, la, ha, ta, tga, tola = x.copy(), lo, hi, tan_t, target, tol
    for _ in range(100):
        f = _visible_slope_cdf(xa, ta) - tga
        hit = np.abs(f) <= tola
        la = np.where(f < 0, xa, la)
        ha = np.where(f > 0, xa, ha)
        # Halley step (F' = (2/√π) e^{−x²}(1 − x t), F'' = −(2/√π) e^{−x²}(2x(1 − x t) + t)).
        g = _TWO_OVER_SQRT_PI * np.exp(-xa * xa)
        d1 = g * (1.0 - xa * ta)
        d2 = -g * (2.0 * xa * (1.0 - xa * ta) + ta)
        den = 2.0 * d1 * d1 - f * d2
        ok = (d1 > 0) & (den > 0)
        newton = xa - 2.0 * f * d1 / np.where(ok, den, 1.0)
        inside = ok & (newton > la) & (newton < ha)
        xn = np.where(hit, xa, np.where(inside, newton, 0.5 * (la + ha)))
        x[active] = xn
        # Halley converges cubically: after a step below 1e-6 the error is ~1e-18.
        done = hit | (inside & (np.abs(newton - xa) <= 1e-6 * (1.0 + np.abs(xa)))) | \
            (ha - la <= 1e-15 * (1.0 + np.abs(xa)))
        keep = ~done
        if not keep.any():
            break
        active = active[keep]
        xa, la, ha, ta, tga, tola = xn[keep], la[keep], ha[keep], ta[keep], tga[keep], tola[keep]
    return x


@jit
def _slope_cdf(x, t, coef, k):
    return _slope_cdf_e(x, np.exp(-x * x), t, coef, k)


@jit
def _slope_cdf_e(x, e, t, coef, k):
    """F(x) given e = e^{−x²} (the Halley step needs the same exponential)."""
    r = erfcx_nonneg_scalar(abs(x), coef, k)
    tp = t * _INV_SQRT_PI
    return e * (r + tp) if x < 0 else 2.0 + e * (tp - r)


@jit
def visible_slope_x_at(t, u1, coef, k):
    """x̃ for one tanθ = ``t`` ≥ 0 and u1 ∈ [0, 1) (``coef``, ``k``: ERFCX_COEF, ERFCX_K); the loop body
    of the compiled twin, also called per path by the Torrance–Sparrow kernels."""
    cot = 1.0 / t if t > 0 else np.inf
    lo = -8.0
    hi = min(cot, 8.0)
    z = _slope_cdf(min(cot, 30.0), t, coef, k)
    u = min(max(u1, 0.0), 1.0)
    uc = min(max(u, 1e-300), 1.0 - 1e-16)
    if uc < 0.5:
        xg = -erfcinv_giles_scalar(2.0 * uc)
    else:
        xg = erfcinv_giles_scalar(2.0 * (1.0 - uc))
    arg = uc * z * SQRT_PI / max(t, 1e-300)
    xr = -np.sqrt(max(-np.log(min(arg, 1.0)), 0.0))
    x = min(xr, hi) if t > 1.0 else xg
    if not (x > lo and x < hi):
        x = 0.5 * (lo + max(hi, lo))
    target = u * z
    tol = 1e-14 * z
    for _ in range(100):
        e = np.exp(-x * x)
        f = _slope_cdf_e(x, e, t, coef, k) - target
        hit = abs(f) <= tol
        if f < 0:
            lo = x
        if f > 0:
            hi = x
        g = _TWO_OVER_SQRT_PI * e
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
    return x


@jit
def _visible_slope_x_loop(tan_t, u1, coef, k, out):
    for i in range(tan_t.shape[0]):
        out[i] = visible_slope_x_at(tan_t[i], u1[i], coef, k)


def visible_slope_x_numba(tan_t, u1):
    out = np.empty(np.shape(tan_t))
    _visible_slope_x_loop(np.ascontiguousarray(tan_t, dtype=np.float64), np.ascontiguousarray(u1, dtype=np.float64),
                          np.ascontiguousarray(ERFCX_COEF, dtype=np.float64), float(ERFCX_K), out)
    return out


visible_slope_x = twin(_visible_slope_x_loop and visible_slope_x_numba, visible_slope_x_numpy)
