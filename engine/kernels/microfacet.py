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

import math

import numpy as np

from . import jit, jit_inner, twin
from .error_function import (ERFCX_COEF, ERFCX_K, SQRT_PI, erfcinv_giles, erfcinv_giles_scalar, erfcx_nonneg,
                             erfcx_nonneg_scalar)
from .nan_rules import minimum_at

_INV_SQRT_PI = 1.0 / SQRT_PI
_TWO_OVER_SQRT_PI = 2.0 / SQRT_PI
_HALF_SQRT_PI = 0.5 * SQRT_PI
_EXP_CUTOFF = 800.0           # engine.materials.microfacet._EXP_CUTOFF
_PI = math.pi
_GGX_FLAT_TAN2 = 1e150       # engine.materials.ggx._FLAT_TAN2


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


@jit_inner
def _slope_cdf(x, t, coef, k):
    return _slope_cdf_e(x, np.exp(-x * x), t, coef, k)


@jit_inner
def _slope_cdf_e(x, e, t, coef, k):
    """F(x) given e = e^{−x²} (the Halley step needs the same exponential)."""
    r = erfcx_nonneg_scalar(abs(x), coef, k)
    tp = t * _INV_SQRT_PI
    return e * (r + tp) if x < 0 else 2.0 + e * (tp - r)


@jit_inner
def _slope_x_start(t, u1, coef, k):
    """x̃'s first guess and bracket for tanθ = ``t`` and u1: (x, lo, hi, target CDF value, tolerance)."""
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
    return x, lo, hi, target, tol


@jit_inner
def _slope_x_step(x, lo, hi, t, target, tol, coef, k):
    """One safeguarded Halley step of x̃ (CDF(x) = target within tol): (new x, lo, hi, converged)."""
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
    return xn, lo, hi, done


@jit_inner
def visible_slope_x_at(t, u1, coef, k):
    """x̃ for one tanθ = ``t`` ≥ 0 and u1 ∈ [0, 1) (``coef``, ``k``: ERFCX_COEF, ERFCX_K): the loop body
    of the compiled twin.  ``beckmann_vndf_at`` runs the same iteration interleaved with ỹ's."""
    x, lo, hi, target, tol = _slope_x_start(t, u1, coef, k)
    for _ in range(100):
        x, lo, hi, done = _slope_x_step(x, lo, hi, t, target, tol, coef, k)
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


# ----------------------------------------------------------------------------- per-path Beckmann pieces
# The formulas of engine.materials.microfacet for one direction at a time, in the same operation
# order (the compiled material passes, e.g. engine.kernels.torrance_sparrow, call them per path).

@jit_inner
def beckmann_d_at(h0, h1, h2, m):
    """Beckmann D(h) (engine.materials.microfacet.Beckmann.D)."""
    xy2 = h0 * h0 + h1 * h1
    z2 = h2 * h2
    if z2 > 0:
        t2 = xy2 / z2
    else:
        t2 = np.inf if xy2 > 0 else 0.0
    x = t2 / (m * m)
    if not (h2 > 0 and x <= _EXP_CUTOFF):
        return 0.0
    one_t = 1.0 + t2
    return np.exp(-x) * (one_t * one_t) / (_PI * m * m)


@jit_inner
def smith_a_at(w0, w1, w2, m):
    """a = cosθ/(m sinθ) (∞ at normal incidence)."""
    sin_t = np.sqrt(w0 * w0 + w1 * w1)
    return abs(w2) / (m * sin_t) if sin_t > 0 else np.inf


@jit_inner
def beckmann_lambda_at(a, coef, k):
    """Smith Λ(a) of engine.materials.microfacet.beckmann_lambda."""
    if a > 0 and a <= 6.0:
        lam = 0.5 * np.exp(-a * a) * (_INV_SQRT_PI / a - erfcx_nonneg_scalar(a, coef, k))
        return max(lam, 0.0)
    return 0.0 if a > 0 else np.inf


@jit_inner
def chi_plus_at(w0, w1, w2, h0, h1, h2):
    """1 where (w·h)·cosθ_w > 0, else 0."""
    return 1.0 if (w0 * h0 + w1 * h1 + w2 * h2) * w2 > 0 else 0.0


@jit_inner
def beckmann_g1_at(w0, w1, w2, h0, h1, h2, m, rational, coef, k):
    """Smith G1 of engine.materials.microfacet's Beckmann (exact, or Walter's rational form)."""
    a = smith_a_at(w0, w1, w2, m)
    if rational:
        af = min(a, 1.6)
        g = 1.0 if a >= 1.6 else (3.535 * af + 2.181 * af * af) / (1.0 + 2.276 * af + 2.577 * af * af)
        return g * chi_plus_at(w0, w1, w2, h0, h1, h2)
    return chi_plus_at(w0, w1, w2, h0, h1, h2) / (1.0 + beckmann_lambda_at(a, coef, k))


@jit
def erfinv_2u_minus_1_at(u, coef, k):
    """engine.kernels.error_function.erfinv_2u_minus_1 for one u (Giles' start, the same Newton steps)."""
    u = min(max(u, 1e-16), 1.0 - 1e-16)
    lower = u < 0.5
    q = 2.0 * (u if lower else 1.0 - u)
    q = min(max(q, 1e-300), 1.0)
    x = erfcinv_giles_scalar(q)
    log_q = np.log(q)
    for _ in range(12):
        ex = erfcx_nonneg_scalar(x, coef, k)
        step = (np.log(ex) - x * x - log_q) * _HALF_SQRT_PI * ex
        xn = max(x + step, 0.0)
        x = xn
        if not abs(step) > 1e-9 * (1.0 + xn):
            break
    return -x if lower else x


@jit_inner
def beckmann_vndf_at(o0, o1, o2, u0, u1, m, coef, k):
    """A visible facet normal h of ω_o = (o0, o1, o2) (engine.materials.microfacet.Beckmann.sample).

    x̃ (visible_slope_x_at) and ỹ (erfinv_2u_minus_1_at) are independent: their iterations run in
    one loop, each with its own stopping rule and the same arithmetic, so the two latency-bound
    chains (erfcx, exp, log) overlap in the processor instead of running one after the other.
    """
    sxy = np.sqrt(o0 * o0 + o1 * o1)
    cz = max(o2, 0.0)
    t = min(m * sxy / cz if cz > 0 else 1e300, 1e300)
    if sxy > 0:
        cos_p, sin_p = o0 / sxy, o1 / sxy
    else:
        cos_p, sin_p = 1.0, 0.0
    # x̃: the start of visible_slope_x_at
    x, lo, hi, target, tol = _slope_x_start(t, u0, coef, k)
    # ỹ: the start of erfinv_2u_minus_1_at
    v = min(max(u1, 1e-16), 1.0 - 1e-16)
    lower = v < 0.5
    q = 2.0 * (v if lower else 1.0 - v)
    q = min(max(q, 1e-300), 1.0)
    y = erfcinv_giles_scalar(q)
    log_q = np.log(q)
    x_on = True
    y_on = True
    for it in range(100):
        if x_on:
            x, lo, hi, done = _slope_x_step(x, lo, hi, t, target, tol, coef, k)
            x_on = not done
        if y_on:
            ex = erfcx_nonneg_scalar(y, coef, k)
            step = (np.log(ex) - y * y - log_q) * _HALF_SQRT_PI * ex
            yn = max(y + step, 0.0)
            y = yn
            y_on = it < 11 and abs(step) > 1e-9 * (1.0 + yn)
        if not (x_on or y_on):
            break
    sx = x
    sy = -y if lower else y
    hx = m * (cos_p * sx - sin_p * sy)
    hy = m * (sin_p * sx + cos_p * sy)
    r = np.sqrt(hx * hx + hy * hy + 1.0)
    return -hx / r, -hy / r, 1.0 / r


# ----------------------------------------------------------------------------- per-path GGX pieces
# engine.materials.ggx.GGX, one direction at a time in the same operation order.

@jit_inner
def tan2_at(w0, w1, w2):
    """tan²θ of w about +z (engine.materials.microfacet._tan2)."""
    xy2 = w0 * w0 + w1 * w1
    z2 = w2 * w2
    if z2 > 0:
        return xy2 / z2
    return np.inf if xy2 > 0 else 0.0


@jit_inner
def ggx_d_at(h0, h1, h2, alpha):
    """GGX D(h)."""
    t2 = tan2_at(h0, h1, h2)
    if not (h2 > 0 and np.isfinite(t2)):
        return 0.0
    a2 = alpha * alpha
    if t2 > _GGX_FLAT_TAN2:         # cosθ_h < 1e-75: (1 + t)² would overflow; GGX.D's limit α²/π
        return a2 / _PI
    q = 1.0 + t2 / a2
    one_t = 1.0 + t2
    return one_t * one_t / (_PI * a2 * q * q)


@jit_inner
def ggx_lambda_at(w0, w1, w2, alpha):
    """Smith Λ(ω) = (√(1 + α² tan²θ) − 1)/2 (∞ at grazing)."""
    t2 = tan2_at(w0, w1, w2)
    if not np.isfinite(t2):
        return np.inf
    x = alpha * alpha * t2
    return 0.5 * x / (np.sqrt(1.0 + x) + 1.0)


@jit_inner
def ggx_vndf_at(o0, o1, o2, u0, u1, alpha):
    """A visible facet normal of ω_o (Heitz 2018; engine.materials.ggx.GGX.sample)."""
    v0, v1, v2 = alpha * o0, alpha * o1, max(o2, 0.0)
    nv = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    v0, v1, v2 = v0 / nv, v1 / nv, v2 / nv
    lensq = v0 * v0 + v1 * v1
    if lensq > 0:
        inv = 1.0 / np.sqrt(lensq)
        a0, a1 = -v1 * inv, v0 * inv
    else:
        a0, a1 = 1.0, 0.0
    a2 = 0.0
    c0 = v1 * a2 - v2 * a1
    c1 = v2 * a0 - v0 * a2
    c2 = v0 * a1 - v1 * a0
    r = np.sqrt(u0)
    phi = 2.0 * math.pi * u1
    p1 = r * np.cos(phi)
    p2 = r * np.sin(phi)
    s = 0.5 * (1.0 + v2)
    p2 = (1.0 - s) * np.sqrt(max(1.0 - p1 * p1, 0.0)) + s * p2
    pz = np.sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0))
    n0 = p1 * a0 + p2 * c0 + pz * v0
    n1 = p1 * a1 + p2 * c1 + pz * v1
    n2 = p1 * a2 + p2 * c2 + pz * v2
    h0, h1, h2 = alpha * n0, alpha * n1, max(n2, 1e-300)
    nh = np.sqrt(h0 * h0 + h1 * h1 + h2 * h2)
    return h0 / nh, h1 / nh, h2 / nh


# ----------------------------------------------------------------------------- V-cavity shadowing

def g_vcavity_numpy(wi: np.ndarray, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Torrance–Sparrow V-cavity G = min(1, 2 h_z ω_o,z/(ω_o·h), 2 h_z ω_i,z/(ω_i·h)); 0 on back sides.
    Directions (3, ...) in the local frame (z = macro normal), broadcast against each other."""
    di = wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]
    do = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
    ok = (di > 0) & (do > 0) & (h[2] > 0) & (wi[2] > 0) & (wo[2] > 0)
    g_o = 2.0 * h[2] * wo[2] / np.where(ok, do, 1.0)
    g_i = 2.0 * h[2] * wi[2] / np.where(ok, di, 1.0)
    return np.where(ok, np.minimum(1.0, np.minimum(g_o, g_i)), 0.0)


@jit
def _g_vcavity_loop(wi, wo, h, out):
    for j in range(out.shape[0]):
        h0, h1, h2 = h[0, j], h[1, j], h[2, j]
        wi2, wo2 = wi[2, j], wo[2, j]
        di = wi[0, j] * h0 + wi[1, j] * h1 + wi2 * h2
        do = wo[0, j] * h0 + wo[1, j] * h1 + wo2 * h2
        if di > 0 and do > 0 and h2 > 0 and wi2 > 0 and wo2 > 0:
            g_o = 2.0 * h2 * wo2 / do
            g_i = 2.0 * h2 * wi2 / di
            out[j] = minimum_at(1.0, minimum_at(g_o, g_i))
        else:
            out[j] = 0.0


def g_vcavity_numba(wi: np.ndarray, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
    wi, wo, h = np.broadcast_arrays(wi, wo, h)
    shape = wi.shape[1:]
    flat = [np.ascontiguousarray(a, dtype=np.float64).reshape(3, -1) for a in (wi, wo, h)]
    out = np.empty(flat[0].shape[1])
    _g_vcavity_loop(*flat, out)
    return out.reshape(shape)


g_vcavity = twin(_g_vcavity_loop and g_vcavity_numba, g_vcavity_numpy)
