"""Beckmann visible-slope sampling (Heitz & d'Eon 2014): the NumPy reference and one compiled loop.

x̃ (the slope along the stretched viewing direction of the unit-roughness surface seen at θ) has
density ∝ (1 − x̃ tanθ) e^{−x̃²} on x̃ < cotθ and CDF F(x)/F(cotθ), F(x) = erfc(−x) + tanθ e^{−x²}/√π
(evaluated through erfcx, tail-accurate).  It solves F(x̃) = u·F(cotθ) by Halley steps safeguarded
by bisection on the bracket [−8, min(cotθ, 8)] (F(−8)/F(cotθ) < 1e-27), started from a table of the
converged x̃ over (tanθ/(1 + tanθ), Gaussian quantile of u), interpolated to ~1e-7 so that one step
ends the iteration (outside the table, u or 1 − u < 7.7e-9: Giles' erfc⁻¹, or for tanθ > 1 the
inverse of the left tail ≈ e^{−x²}·(tanθ/√π)/F(cotθ), which took 3.2 steps on average).  ỹ =
erfinv(2u₂ − 1) is Newton-polished from a double-precision fit of erfc⁻¹ (one step, Giles' start took
two).  Each path iterates until its own stopping rule; the compiled loops are the same algorithm per
path and agree to rounding (exp/log of the C library vs NumPy's).  engine.materials.microfacet.Beckmann
samples with them (tests/kernels/test_beckmann_sampling.py; tests/bench/beckmann_sampling.py).
"""

from __future__ import annotations

import math

import numpy as np

from . import jit, jit_inner, twin
from .error_function import (ERFCX_COEF, ERFCX_K, SQRT_PI, erfcinv_giles, erfcinv_giles_scalar, erfcx_nonneg,
                             erfcx_nonneg_scalar, erfinv_2u_minus_1)
from .nan_rules import minimum_at

_INV_SQRT_PI = 1.0 / SQRT_PI
_TWO_OVER_SQRT_PI = 2.0 / SQRT_PI
_HALF_SQRT_PI = 0.5 * SQRT_PI
_EXP_CUTOFF = 800.0           # engine.materials.microfacet._EXP_CUTOFF
_PI = math.pi
_GGX_FLAT_TAN2 = 1e150       # engine.materials.ggx._FLAT_TAN2


def _visible_slope_cdf(x: np.ndarray, t: np.ndarray, exp=np.exp, erfcx=erfcx_nonneg) -> np.ndarray:
    """F(x) = erfc(−x) + t e^{−x²}/√π (unnormalised CDF of the visible slope x̃), tail-accurate."""
    e = exp(-x * x)
    r = erfcx(np.abs(x))
    tp = t * _INV_SQRT_PI
    return np.where(x < 0, e * (r + tp), 2.0 + e * (tp - r))


def visible_slope_x_numpy(tan_t: np.ndarray, u1: np.ndarray) -> np.ndarray:
    """x̃ (N,) for tanθ (N,) ≥ 0 and u1 (N,) ∈ [0, 1) (see the module docstring)."""
    return _visible_slope_x_solve(tan_t, u1, True)


def _visible_slope_x_solve(tan_t: np.ndarray, u1: np.ndarray, use_table: bool, libm: bool = False) -> np.ndarray:
    """visible_slope_x_numpy, started from the table (``use_table``) or, as before it existed, from the
    Gaussian quantile / left-tail inverse everywhere; ``libm``: with exp, log and erfcx from the C library
    (math.exp, math.log, math.erfc: what builds the table, see _start_table; erfcx for arguments ≤ 26)."""
    if libm:
        exp, log = _libm(math.exp, -math.inf, 700.0), _libm(math.log, 5e-324, math.inf)
        erfcx = _libm(_erfcx_scalar, 0.0, 26.0)
    else:
        exp, log, erfcx = np.exp, np.log, erfcx_nonneg
    n = tan_t.shape[0]
    cot = np.where(tan_t > 0, 1.0 / np.where(tan_t > 0, tan_t, 1.0), np.inf)
    lo = np.full(n, -8.0)
    hi = np.minimum(cot, 8.0)
    # F(cotθ) = 2 exactly in double precision for cotθ ≥ 6 (e^{−36}·|t/√π − erfcx(cotθ)| < 2.3e-17)
    z = np.where(cot >= 6.0, 2.0, _visible_slope_cdf(np.minimum(cot, 30.0), tan_t, exp, erfcx))
    u = np.clip(u1, 0.0, 1.0)
    # Start: the tabulated x̃ at the Gaussian quantile g of u (_start_lookup_numpy); outside the table
    # the Gaussian quantile itself (exact for θ = 0) or, for large tanθ, the inverse of the left tail
    # ≈ e^{−x²}·(tanθ/√π)/F(cotθ).
    uc = np.clip(u, 1e-300, 1.0 - 1e-16)
    lower = uc < 0.5
    xg = erfcinv_giles(2.0 * np.where(lower, uc, 1.0 - uc), log)
    xg = np.where(lower, -xg, xg)
    arg = uc * z * SQRT_PI / np.maximum(tan_t, 1e-300)
    xr = -np.sqrt(np.maximum(-log(np.minimum(arg, 1.0)), 0.0))
    x = np.where(tan_t > 1.0, np.minimum(xr, hi), xg)
    if use_table:
        s = tan_t / (1.0 + tan_t)
        in_table = (np.minimum(uc, 1.0 - uc) > START_U_MIN) & (np.abs(xg) < START_G) & (s >= 0.0) & (s <= 1.0)
        x = np.where(in_table, _start_lookup_numpy(np.where(in_table, s, 0.0), np.where(in_table, xg, 0.0)), x)
    x = np.where((x > lo) & (x < hi), x, 0.5 * (lo + np.maximum(hi, lo)))
    target = u * z
    tol = 1e-14 * z
    active = np.arange(n)
    xa, la, ha, ta, tga, tola = x.copy(), lo, hi, tan_t, target, tol
    for _ in range(100):
        f = _visible_slope_cdf(xa, ta, exp, erfcx) - tga
        hit = np.abs(f) <= tola
        la = np.where(f < 0, xa, la)
        ha = np.where(f > 0, xa, ha)
        # Halley step (F' = (2/√π) e^{−x²}(1 − x t), F'' = −(2/√π) e^{−x²}(2x(1 − x t) + t)).
        g = _TWO_OVER_SQRT_PI * exp(-xa * xa)
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


# ----------------------------------------------------------------------------- the tabulated first guess
# x̃ as a function of s = tanθ/(1 + tanθ) ∈ [0, 1] and of the Gaussian quantile g of u (Giles' erfc⁻¹, which
# the start computes anyway) is smooth on the whole square: linear in g at θ = 0, ≈ −√(g² + …) in the
# left tail, e^{−g²/2}-flat towards cotθ in the right tail, and smooth in s at both ends (in t at t = 0, in
# cotθ at t = ∞).  Tensor-product 4-point Lagrange interpolation of the converged x̃ at 129 × 129 nodes (float32)
# (g ∈ [−4, 4]) is within 8·10⁻⁷·(1 + |x̃|) of the root for all but ~5 in 10⁶ draws, so the first Halley
# step is below the 1e-6 stopping rule and ends the iteration (3.2 steps on average before, at m = 0.3).
# Outside the table (|g| ≥ 4, u < 1.6·10⁻⁸ or 1 − u < 1.6·10⁻⁸) the start is the one before it.

START_NS = 129          # nodes in s
START_NG = 129          # nodes in g
START_G = 4.0           # g ∈ [−START_G, START_G]
#: the table is used for min(u, 1 − u) above this (erfc(4)/2; Giles' single-precision fit of erfc⁻¹ is not
#: monotonic far beyond its range: at u = 1e-300 it gives |g| < 4)
START_U_MIN = 7.7e-9


def _libm(fn, lo, hi):
    """``fn`` of the C library (math) over an array, its arguments clipped to [lo, hi] (NaN stays NaN)."""
    def apply(a):
        a = np.clip(np.asarray(a, dtype=np.float64), lo, hi)
        return np.fromiter(map(fn, a.ravel().tolist()), np.float64, a.size).reshape(a.shape)
    return apply


def _erfcx_scalar(x: float) -> float:
    """e^{x²} erfc(x) from the C library, 0 ≤ x ≤ 26 (relative error ≲ x²·1e-16: the table's needs)."""
    return math.exp(x * x) * math.erfc(x)


def _start_table() -> np.ndarray:
    """x̃ (START_NS, START_NG), float32, at s_i = i/(NS − 1), g_j = −G + 2Gj/(NG − 1), solved by the untabulated
    iteration.

    The compiled kernels hold the table as a constant of their cached machine code, so every process must build
    the same bits: the iteration's exp, log and erfcx are the C library's (NumPy's SIMD exp and log, and the
    erfcx series fitted through LAPACK at import, differ in the last bit between CPUs and settings, and the
    root moves with them by up to the stopping rule's tolerance); the rest is IEEE arithmetic, the same
    everywhere.
    """
    s = np.linspace(0.0, 1.0, START_NS)
    g = np.linspace(-START_G, START_G, START_NG)
    ss, gg = np.meshgrid(s, g, indexing="ij")
    t = np.where(ss < 1.0, ss / np.where(ss < 1.0, 1.0 - ss, 1.0), 1e300)
    u = 0.5 * _libm(math.erfc, -math.inf, math.inf)(-gg.ravel())
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        x = _visible_slope_x_solve(t.ravel(), u, False, libm=True).reshape(ss.shape)
    x = np.ascontiguousarray(x, dtype=np.float32)     # a start needs no more (≤ 3·10⁻⁸·|x̃| against ≤ 6·10⁻⁷ of the
    x.setflags(write=False)                           # interpolation), and each kernel holding it caches 66 kB less
    return x


START_TABLE = _start_table()
_G_SCALE = (START_NG - 1) / (2.0 * START_G)


def _start_lookup_numpy(s: np.ndarray, g: np.ndarray) -> np.ndarray:
    """The interpolated x̃ at s ∈ [0, 1], g ∈ (−START_G, START_G) (arrays of one shape)."""
    ps = s * (START_NS - 1)
    i = np.clip(np.floor(ps), 1, START_NS - 3).astype(np.int64)
    fs = ps - i
    pg = (g + START_G) * _G_SCALE
    j = np.clip(np.floor(pg), 1, START_NG - 3).astype(np.int64)
    fg = pg - j
    ws = _lagrange4(fs)
    wg = _lagrange4(fg)
    tab = START_TABLE
    out = None
    for a in range(4):
        r = i - 1 + a
        row = ((wg[0] * tab[r, j - 1] + wg[1] * tab[r, j]) + wg[2] * tab[r, j + 1]) + wg[3] * tab[r, j + 2]
        out = ws[a] * row if out is None else out + ws[a] * row
    return out


def _lagrange4(f):
    """Weights of the nodes −1, 0, 1, 2 for the cubic through them, at f."""
    fp1 = f + 1.0
    fm1 = f - 1.0
    fm2 = f - 2.0
    return (-(f * fm1 * fm2) / 6.0, (fp1 * fm1 * fm2) / 2.0, -(fp1 * f * fm2) / 2.0, (fp1 * f * fm1) / 6.0)


_lagrange4_at = jit_inner(_lagrange4)

@jit_inner
def _start_lookup_at(s, g):
    """_start_lookup_numpy for one (s, g)."""
    tab = START_TABLE
    ps = s * (START_NS - 1)
    i = int(min(max(np.floor(ps), 1.0), START_NS - 3.0))
    fs = ps - i
    pg = (g + START_G) * _G_SCALE
    j = int(min(max(np.floor(pg), 1.0), START_NG - 3.0))
    fg = pg - j
    ws0, ws1, ws2, ws3 = _lagrange4_at(fs)
    wg0, wg1, wg2, wg3 = _lagrange4_at(fg)
    r0 = ((wg0 * tab[i - 1, j - 1] + wg1 * tab[i - 1, j]) + wg2 * tab[i - 1, j + 1]) + wg3 * tab[i - 1, j + 2]
    r1 = ((wg0 * tab[i, j - 1] + wg1 * tab[i, j]) + wg2 * tab[i, j + 1]) + wg3 * tab[i, j + 2]
    r2 = ((wg0 * tab[i + 1, j - 1] + wg1 * tab[i + 1, j]) + wg2 * tab[i + 1, j + 1]) + wg3 * tab[i + 1, j + 2]
    r3 = ((wg0 * tab[i + 2, j - 1] + wg1 * tab[i + 2, j]) + wg2 * tab[i + 2, j + 1]) + wg3 * tab[i + 2, j + 2]
    return ((ws0 * r0 + ws1 * r1) + ws2 * r2) + ws3 * r3



@jit_inner
def _slope_cdf(x, t, coef, k):
    return _slope_cdf_e(x, np.exp(-x * x), t, coef, k)


@jit_inner
def _slope_cdf_e(x, e, t, coef, k):
    """F(x) given e = e^{−x²} (the Halley step needs the same exponential)."""
    return _slope_cdf_er(x, e, erfcx_nonneg_scalar(abs(x), coef, k), t)


@jit_inner
def _slope_cdf_er(x, e, r, t):
    """F(x) given e = e^{−x²} and r = erfcx(|x|)."""
    tp = t * _INV_SQRT_PI
    return e * (r + tp) if x < 0 else 2.0 + e * (tp - r)


@jit_inner
def erfcx3_at(x1, x2, x3, coef, k):
    """erfcx_nonneg_scalar of three x ≥ 0 (erfcx4_at: the same bits)."""
    r1, r2, r3, _ = erfcx4_at(x1, x2, x3, 0.0, coef, k)
    return r1, r2, r3


@jit_inner
def erfcx4_at(x1, x2, x3, x4, coef, k):
    """erfcx_nonneg_scalar of four x ≥ 0, their series summed in one loop: the same operations per value (the
    same bits), four independent chains for the processor to overlap instead of four latency-bound ones."""
    c1, c2, c3, c4 = min(x1, 1e150), min(x2, 1e150), min(x3, 1e150), min(x4, 1e150)
    t1, t2, t3, t4 = (c1 - k) / (c1 + k), (c2 - k) / (c2 + k), (c3 - k) / (c3 + k), (c4 - k) / (c4 + k)
    d1, d2, d3, d4 = 2.0 * t1, 2.0 * t2, 2.0 * t3, 2.0 * t4
    p1 = q1 = p2 = q2 = p3 = q3 = p4 = q4 = 0.0
    for j in range(coef.shape[0] - 1, 0, -1):
        cj = coef[j]
        p1, q1 = (d1 * p1 - q1) + cj, p1
        p2, q2 = (d2 * p2 - q2) + cj, p2
        p3, q3 = (d3 * p3 - q3) + cj, p3
        p4, q4 = (d4 * p4 - q4) + cj, p4
    return ((coef[0] + t1 * p1 - q1) / (c1 + k), (coef[0] + t2 * p2 - q2) / (c2 + k),
            (coef[0] + t3 * p3 - q3) / (c3 + k), (coef[0] + t4 * p4 - q4) / (c4 + k))


@jit_inner
def _slope_x_start(t, u1, coef, k):
    """x̃'s first guess and bracket for tanθ = ``t`` and u1: (x, lo, hi, target CDF value, tolerance)."""
    return _slope_x_start_with(t, u1, coef, k, True)


@jit_inner
def _slope_x_quantile(u1):
    """(u1 clamped to [0, 1], to [1e-300, 1 − 1e-16], its Gaussian quantile g by Giles' erfc⁻¹)."""
    u = min(max(u1, 0.0), 1.0)
    uc = min(max(u, 1e-300), 1.0 - 1e-16)
    if uc < 0.5:
        xg = -erfcinv_giles_scalar(2.0 * uc)
    else:
        xg = erfcinv_giles_scalar(2.0 * (1.0 - uc))
    return u, uc, xg


@jit_inner
def _in_start_table(uc, xg, s):
    """Whether x̃'s start is read from the table at (s, g = xg) for the clamped u ``uc``."""
    return min(uc, 1.0 - uc) > START_U_MIN and abs(xg) < START_G and s >= 0.0 and s <= 1.0


@jit_inner
def _slope_x_start_with(t, u1, coef, k, use_table):
    """_slope_x_start, from the table where ``use_table`` and it applies, else as before the table."""
    cot = 1.0 / t if t > 0 else np.inf
    lo = -8.0
    hi = min(cot, 8.0)
    z = 2.0 if cot >= 6.0 else _slope_cdf(min(cot, 30.0), t, coef, k)
    u, uc, xg = _slope_x_quantile(u1)
    s = t / (1.0 + t)
    if use_table and _in_start_table(uc, xg, s):
        x = _start_lookup_at(s, xg)
    else:
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
    return _slope_x_step_er(x, e, erfcx_nonneg_scalar(abs(x), coef, k), lo, hi, t, target, tol)


@jit_inner
def _slope_x_step_er(x, e, r, lo, hi, t, target, tol):
    """_slope_x_step given e = e^{−x²} and r = erfcx(|x|)."""
    f = _slope_cdf_er(x, e, r, t) - target
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


# ----------------------------------------------------------------------------- ỹ's first guess
# ỹ = erfc⁻¹(q), q = 2 min(u, 1 − u), polished by Newton steps on ln erfc that stop after a step below
# 1e-9·(1 + ỹ) (engine.kernels.error_function.erfcinv).  Giles' single-precision start (~1e-7) takes two
# steps; this one, ỹ = (1 − q)·p(w) with w = −ln(q(2 − q)) as Giles' but p fitted to double precision
# (degree 14 in w on [0, 6.25], degree 14 in √w on [2.5, √18.5]; within 5·10⁻¹¹·(1 + ỹ), fitted to the
# Newton-polished erfcinv), takes one.  Beyond w = 18.5 (q < 9.2·10⁻⁹) it is Giles' start.

_YS_W_SPLIT = 6.25
_YS_W_MAX = 18.5
_YS_DEGREE = 14
#: p in the mapped variable τ ∈ [−1, 1] of each branch, highest power first (_fit_erfcinv_start(); literals, so
#: that the compiled code holds the same numbers in every process whatever NumPy's and LAPACK's last bits)
_YS_LOW = (6.485665386852146e-07, 3.488932720750327e-06, -1.3011284502003529e-05, -9.812452713544168e-06,
           9.468735105027324e-05, -0.00012076343388982066, -0.00026496810930874654, 0.0012340416918009698,
           -0.001271553330574061, -0.004137636926633445, 0.017808345085603243, -0.022604417876217437,
           -0.05892256632919925, 0.7504943192936285, 1.6536545626771852)
_YS_HIGH = (1.915660485331897e-07, -4.7195013564991414e-07, -4.929129408087878e-07, 4.126279383197585e-06,
            -9.00504326266143e-06, 5.150244274590919e-06, 3.279933031301438e-05, -0.000138091272050015,
            0.0003250300478840566, -0.0005852306198228581, 0.00098903579776517, -0.0018804422948674592,
            0.0032153358016027062, 0.9065714566349685, 3.235368966244533)


def _fit_erfcinv_start():
    """The fit behind _YS_LOW and _YS_HIGH: Chebyshev least squares of p = erfc⁻¹(q)/(1 − q) at 400 nodes of
    each branch (w, resp. √w, mapped to τ), converted to powers of τ (tests/kernels/test_beckmann_sampling.py)."""
    from .error_function import erfcinv
    cheb = np.polynomial.chebyshev
    n = 400
    tau = np.cos(np.pi * (np.arange(n) + 0.5) / n)
    out = []
    for a, b, root in ((0.0, _YS_W_SPLIT, False), (math.sqrt(_YS_W_SPLIT), math.sqrt(_YS_W_MAX), True)):
        v = 0.5 * (a + b) + 0.5 * (b - a) * tau
        w = v * v if root else v
        q = np.where(w > 0, -np.expm1(0.5 * np.log1p(-np.exp(-np.maximum(w, 1e-300)))), 1.0)   # q(2 − q) = e^{−w}
        y = 1.0 - q
        p = np.where(y > 0, erfcinv(q) / np.where(y > 0, y, 1.0), 0.5 * SQRT_PI)
        coef = cheb.cheb2poly(cheb.chebfit(tau, p, _YS_DEGREE))[::-1]
        out.append(tuple(float(c) for c in coef))
    return out


_YS_LOW_MID = 0.5 * _YS_W_SPLIT
_YS_HIGH_A = math.sqrt(_YS_W_SPLIT)
_YS_HIGH_MID = 0.5 * (math.sqrt(_YS_W_MAX) + _YS_HIGH_A)
_YS_HIGH_HALF = 0.5 * (math.sqrt(_YS_W_MAX) - _YS_HIGH_A)


def erfcinv_start_numpy(q: np.ndarray) -> np.ndarray:
    """x ≥ 0 with erfc(x) ≈ q ∈ (0, 1] (within 5·10⁻¹¹·(1 + x) for q ≥ 9.2·10⁻⁹, else Giles' ~1e-7):
    the start of erfinv_2u_minus_1 for ỹ."""
    y = 1.0 - q
    w = -np.log(q * (2.0 - q))
    tl = (w - _YS_LOW_MID) / _YS_LOW_MID
    p1 = _YS_LOW[0]
    for c in _YS_LOW[1:]:
        p1 = c + p1 * tl
    th = (np.sqrt(np.maximum(w, 0.0)) - _YS_HIGH_MID) / _YS_HIGH_HALF
    p2 = _YS_HIGH[0]
    for c in _YS_HIGH[1:]:
        p2 = c + p2 * th
    fitted = np.maximum(np.where(w < _YS_W_SPLIT, p1, p2) * y, 0.0)
    return np.where(w < _YS_W_MAX, fitted, erfcinv_giles(q))


@jit_inner
def erfcinv_start_at(q):
    """erfcinv_start_numpy for one q."""
    y = 1.0 - q
    w = -np.log(q * (2.0 - q))
    if w >= _YS_W_MAX:
        return erfcinv_giles_scalar(q)
    if w < _YS_W_SPLIT:
        tl = (w - _YS_LOW_MID) / _YS_LOW_MID
        p = _YS_LOW[0]
        for j in range(1, len(_YS_LOW)):
            p = _YS_LOW[j] + p * tl
    else:
        th = (np.sqrt(max(w, 0.0)) - _YS_HIGH_MID) / _YS_HIGH_HALF
        p = _YS_HIGH[0]
        for j in range(1, len(_YS_HIGH)):
            p = _YS_HIGH[j] + p * th
    return max(p * y, 0.0)


def visible_slope_y_numpy(u2: np.ndarray) -> np.ndarray:
    """ỹ = erfinv(2u₂ − 1) (N,) for u₂ (N,) ∈ [0, 1]: engine.kernels.error_function.erfinv_2u_minus_1 started
    from erfcinv_start_numpy (the ỹ of beckmann_vndf_at)."""
    return erfinv_2u_minus_1(u2, start=erfcinv_start_numpy)


@jit_inner
def visible_slope_y_at(u2, coef, k):
    """ỹ for one u₂ (the loop body of the compiled twin; beckmann_vndf_at runs the same steps)."""
    v = min(max(u2, 1e-16), 1.0 - 1e-16)
    lower = v < 0.5
    q = 2.0 * (v if lower else 1.0 - v)
    q = min(max(q, 1e-300), 1.0)
    y = erfcinv_start_at(q)
    log_q = np.log(q)
    for _ in range(12):
        ex = erfcx_nonneg_scalar(y, coef, k)
        step = (np.log(ex) - y * y - log_q) * _HALF_SQRT_PI * ex
        y = max(y + step, 0.0)
        if not abs(step) > 1e-9 * (1.0 + y):
            break
    return -y if lower else y


@jit
def _visible_slope_y_loop(u2, coef, k, out):
    for i in range(u2.shape[0]):
        out[i] = visible_slope_y_at(u2[i], coef, k)


def visible_slope_y_numba(u2):
    out = np.empty(np.shape(u2))
    coef = np.ascontiguousarray(ERFCX_COEF, dtype=np.float64)
    _visible_slope_y_loop(np.ascontiguousarray(u2, dtype=np.float64), coef, float(ERFCX_K), out)
    return out


# The NumPy logarithm is not the C library's in every last bit: with one Newton step (not two, as from Giles'
# start) such a bit can survive into ỹ, so the NumPy steps of the materials call the compiled ỹ when it is on.
visible_slope_y = twin(_visible_slope_y_loop and visible_slope_y_numba, visible_slope_y_numpy)


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
    return _beckmann_lambda_given(a, erfcx_nonneg_scalar(a, coef, k) if a > 0 and a <= 6.0 else 0.0)


@jit_inner
def _beckmann_lambda_given(a, r):
    """beckmann_lambda_at given r = erfcx(a) (read where 0 < a ≤ 6 only)."""
    if a > 0 and a <= 6.0:
        lam = 0.5 * np.exp(-a * a) * (_INV_SQRT_PI / a - r)
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


@jit_inner
def beckmann_g1_pair_at(i0, i1, i2, o0, o1, o2, h0, h1, h2, m, rational, coef, k):
    """beckmann_g1_at(ω_i)·beckmann_g1_at(ω_o) (the separable Smith G), the two Λ's erfcx summed in one loop
    (erfcx3_at: the same bits)."""
    if rational:
        return (beckmann_g1_at(i0, i1, i2, h0, h1, h2, m, True, coef, k)
                * beckmann_g1_at(o0, o1, o2, h0, h1, h2, m, True, coef, k))
    a_i = smith_a_at(i0, i1, i2, m)
    a_o = smith_a_at(o0, o1, o2, m)
    r_i, r_o, _ = erfcx3_at(a_i, a_o, 0.0, coef, k)
    return (chi_plus_at(i0, i1, i2, h0, h1, h2) / (1.0 + _beckmann_lambda_given(a_i, r_i))
            * (chi_plus_at(o0, o1, o2, h0, h1, h2) / (1.0 + _beckmann_lambda_given(a_o, r_o))))


@jit_inner
def beckmann_vndf_at(o0, o1, o2, u0, u1, m, coef, k):
    """A visible facet normal h of ω_o = (o0, o1, o2) (engine.materials.microfacet.Beckmann.sample).

    x̃ (visible_slope_x_at) and ỹ (visible_slope_y_at) are independent: their iterations run in
    one loop, each with its own stopping rule and the same arithmetic, so the two latency-bound
    chains (erfcx, exp, log) overlap in the processor instead of running one after the other.
    """
    return _beckmann_vndf_with(o0, o1, o2, u0, u1, m, coef, k, True, 0.0)[:3]


@jit_inner
def beckmann_vndf_lambda_at(o0, o1, o2, u0, u1, m, coef, k):
    """(h0, h1, h2, Λ(ω_o)): beckmann_vndf_at and beckmann_lambda_at(smith_a_at(ω_o)) (the same bits), Λ's erfcx
    summed with the sampler's first three (erfcx4_at), off the serial chain of the pdf that follows."""
    a = smith_a_at(o0, o1, o2, m)
    h0, h1, h2, r = _beckmann_vndf_with(o0, o1, o2, u0, u1, m, coef, k, True, a if a > 0 and a <= 6.0 else 0.0)
    return h0, h1, h2, _beckmann_lambda_given(a, r)


@jit_inner
def _beckmann_vndf_with(o0, o1, o2, u0, u1, m, coef, k, use_table, a_extra):
    """(h0, h1, h2, erfcx(a_extra)): beckmann_vndf_at with x̃ started from the table (``use_table``) or as before it
    (tests/bench), and erfcx of a further ``a_extra`` ≥ 0 for the caller."""
    sxy = np.sqrt(o0 * o0 + o1 * o1)
    cz = max(o2, 0.0)
    t = min(m * sxy / cz if cz > 0 else 1e300, 1e300)
    if sxy > 0:
        cos_p, sin_p = o0 / sxy, o1 / sxy
    else:
        cos_p, sin_p = 1.0, 0.0
    # ỹ: the start of visible_slope_y_at (Giles' before the fitted start, for tests/bench)
    v = min(max(u1, 1e-16), 1.0 - 1e-16)
    lower = v < 0.5
    q = 2.0 * (v if lower else 1.0 - v)
    q = min(max(q, 1e-300), 1.0)
    y = erfcinv_start_at(q) if use_table else erfcinv_giles_scalar(q)
    log_q = np.log(q)
    x_on = True
    y_on = True
    first = 0
    # x̃: the start of visible_slope_x_at.  From the table (nearly every draw), F(cotθ), the first x̃ step and the
    # first ỹ step need erfcx at three independent points: computed together (erfcx3_at), then the steps as below
    cot = 1.0 / t if t > 0 else np.inf
    u, uc, xg = _slope_x_quantile(u0)
    s = t / (1.0 + t)
    if use_table and _in_start_table(uc, xg, s):
        lo = -8.0
        hi = min(cot, 8.0)
        x = _start_lookup_at(s, xg)
        if not (x > lo and x < hi):
            x = 0.5 * (lo + max(hi, lo))
        zc = min(cot, 30.0)
        r_z, r_x, r_y, r_extra = erfcx4_at(zc, abs(x), y, a_extra, coef, k)
        z = 2.0 if cot >= 6.0 else _slope_cdf_er(zc, np.exp(-zc * zc), r_z, t)
        target = u * z
        tol = 1e-14 * z
        x, lo, hi, done = _slope_x_step_er(x, np.exp(-x * x), r_x, lo, hi, t, target, tol)
        x_on = not done
        step = (np.log(r_y) - y * y - log_q) * _HALF_SQRT_PI * r_y
        yn = max(y + step, 0.0)
        y = yn
        y_on = abs(step) > 1e-9 * (1.0 + yn)
        first = 1
    else:
        x, lo, hi, target, tol = _slope_x_start_with(t, u0, coef, k, use_table)
        r_extra = erfcx_nonneg_scalar(a_extra, coef, k)
    for it in range(first, 100):
        if not (x_on or y_on):
            break
        if x_on:
            x, lo, hi, done = _slope_x_step(x, lo, hi, t, target, tol, coef, k)
            x_on = not done
        if y_on:
            ex = erfcx_nonneg_scalar(y, coef, k)
            step = (np.log(ex) - y * y - log_q) * _HALF_SQRT_PI * ex
            yn = max(y + step, 0.0)
            y = yn
            y_on = it < 11 and abs(step) > 1e-9 * (1.0 + yn)
    sx = x
    sy = -y if lower else y
    hx = m * (cos_p * sx - sin_p * sy)
    hy = m * (sin_p * sx + cos_p * sy)
    r = np.sqrt(hx * hx + hy * hy + 1.0)
    return -hx / r, -hy / r, 1.0 / r, r_extra


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
