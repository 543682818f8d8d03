"""The error-function family in NumPy, and the scalar forms the compiled Beckmann sampler uses.

- :func:`erfc`: W. J. Cody's rational Chebyshev approximations (Math. Comp. 23, 631–637, 1969;
  Netlib SPECFUN CALERF), vectorised; relative error ~1e-16 against libm, and subnormal results
  (26.543 ≤ x < 27.3) to a unit of the subnormal grid; NaN propagates, ±∞ gives 0 / 2.
  :func:`erf` is built on it.
- :func:`erfcx` = e^{x²} erfc(x), the form that stays accurate far in the tail (Smith Λ, the
  visible-slope CDF of engine.kernels.microfacet): a Chebyshev series in t = (x − K)/(x + K) of
  erfcx(x)·(x + K), fitted at import time (below); relative error ≲ 1e-14 (x ≥ 0).
- :func:`erfinv`: Giles' single-precision start polished by Newton steps on ln erfc (~1e-15).

The scalar ``*_scalar`` functions are the same arithmetic for Numba loops (None without Numba).
"""

from __future__ import annotations

import math

import numpy as np

from . import jit_inner

SQRT_PI = math.sqrt(math.pi)
_INV_SQRT_PI = 1.0 / SQRT_PI
_TWO_OVER_SQRT_PI = 2.0 / SQRT_PI

# ------------------------------------------------------------------------------------------------
# erfc (Cody 1969, Netlib SPECFUN CALERF coefficients)
# ------------------------------------------------------------------------------------------------
_A = (3.16112374387056560e00, 1.13864154151050156e02, 3.77485237685302021e02,
      3.20937758913846947e03, 1.85777706184603153e-1)
_B = (2.36012909523441209e01, 2.44024637934444173e02, 1.28261652607737228e03,
      2.84423683343917062e03)
_C = (5.64188496988670089e-1, 8.88314979438837594e00, 6.61191906371416295e01,
      2.98635138197400131e02, 8.81952221241769090e02, 1.71204761263407058e03,
      2.05107837782607147e03, 1.23033935479799725e03, 2.15311535474403846e-8)
_D = (1.57449261107098347e01, 1.17693950891312499e02, 5.37181101862009858e02,
      1.62138957456669019e03, 3.29079923573345963e03, 4.36261909014324716e03,
      3.43936767414372164e03, 1.23033935480374942e03)
_P = (3.05326634961232344e-1, 3.60344899949804439e-1, 1.25781726111229246e-1,
      1.60837851487422766e-2, 6.58749161529837803e-4, 1.63153871373020978e-2)
_Q = (2.56852019228982242e00, 1.87295284992346047e00, 5.27905102951428412e-1,
      6.05183413124413191e-2, 2.33520497626869185e-3)
_XBIG = 26.543  # erfc(x) is subnormal (< 2.2e-308) beyond this
_XMAX = 27.3  # erfc(x) < 4.9e-324 (the smallest subnormal) beyond this: 0


def _exp_neg_sq(y):
    """exp(−y²) with Cody's split y² = ysq² + (y−ysq)(y+ysq), ysq = ⌊16y⌋/16 (no error growth)."""
    ysq = np.floor(16.0 * y) / 16.0
    return np.exp(-ysq * ysq) * np.exp(-(y - ysq) * (y + ysq))


def _exp_neg_sq_subnormal(y, r):
    """exp(−y²)·r for subnormal results: Cody's split with exp(−ysq²) = exp(−ysq²/2)², so that only the
    final product is rounded to the subnormal grid (Cody's own code returns 0 beyond _XBIG)."""
    ysq = np.floor(16.0 * y) / 16.0
    half = np.exp(-0.5 * ysq * ysq)
    return half * (half * (np.exp(-(y - ysq) * (y + ysq)) * r))


def erfc(x):
    """Complementary error function, vectorised (Cody 1969); float64 array of x's shape.

    Relative error ~1e-16 (checked against math.erfc); NaN propagates, ±inf gives 0 / 2.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.abs(x)
    out = np.empty_like(y)
    # |x| ≤ 0.46875: erfc = 1 − x·P(x²)/Q(x²)
    r1 = y <= 0.46875
    if r1.any():
        xx = x[r1]
        t = np.where(np.abs(xx) > 1.11e-16, xx * xx, 0.0)
        num = _A[4] * t
        den = t.copy()
        for i in range(3):
            num = (num + _A[i]) * t
            den = (den + _B[i]) * t
        out[r1] = 1.0 - xx * (num + _A[3]) / (den + _B[3])
    # 0.46875 < |x| ≤ 4
    r2 = (y > 0.46875) & (y <= 4.0)
    if r2.any():
        yy = y[r2]
        num = _C[8] * yy
        den = yy.copy()
        for i in range(7):
            num = (num + _C[i]) * yy
            den = (den + _D[i]) * yy
        res = _exp_neg_sq(yy) * (num + _C[7]) / (den + _D[7])
        out[r2] = np.where(x[r2] < 0, 2.0 - res, res)
    # |x| > 4
    r3 = y > 4.0
    if r3.any():
        yy = y[r3]
        big = yy >= _XMAX
        tail = (yy >= _XBIG) & ~big
        ys = np.where(big, 5.0, yy)
        t = 1.0 / (ys * ys)
        num = _P[5] * t
        den = t.copy()
        for i in range(4):
            num = (num + _P[i]) * t
            den = (den + _Q[i]) * t
        res = t * (num + _P[4]) / (den + _Q[4])
        res = (_INV_SQRT_PI - res) / ys
        res = np.where(big, 0.0, np.where(tail, _exp_neg_sq_subnormal(ys, res), _exp_neg_sq(ys) * res))
        out[r3] = np.where(x[r3] < 0, 2.0 - res, res)
    nan = np.isnan(x)
    if nan.any():
        out[nan] = np.nan
    return out


def erf(x) -> np.ndarray:
    """Error function, vectorised (relative accuracy ~1e-15).

    |x| < 0.5: the positive-term series erf(x) = (2/√π) e^{−x²} Σ 2ⁿ x^{2n+1}/(2n+1)!!;
    otherwise sign(x)(1 − erfc(|x|)).
    """
    x = np.asarray(x, dtype=np.float64)
    ax = np.abs(x)
    xs = np.where(ax < 0.5, x, 0.0)
    x2 = xs * xs
    term = xs.copy()
    total = xs.copy()
    for k in range(1, 20):
        term = term * (2.0 * x2 / (2 * k + 1))
        total = total + term
    series = _TWO_OVER_SQRT_PI * np.exp(-x2) * total
    return np.where(ax < 0.5, series, np.sign(x) * (1.0 - erfc(ax)))


# ------------------------------------------------------------------------------------------------
# erfcx = e^{x²} erfc(x)
# ------------------------------------------------------------------------------------------------
#
# erfcx(x)·(x + K) is a smooth bounded function of t = (x − K)/(x + K) ∈ [−1, 1), approximated by a
# Chebyshev series of degree ERFCX_DEGREE in t.  The coefficients are fitted at import time (least
# squares at 400 Chebyshev nodes, ~1 ms) to references independent of this approximation: the C
# library's erfc (math.erfc) times e^{x²} for x < 2, and for x ≥ 2 the continued fraction
# erfc(x) = e^{−x²}/√π · 1/(x + ½/(x + 1/(x + 3/2/(x + …)))) evaluated with 200 levels.

ERFCX_K = 3.0
ERFCX_DEGREE = 22


def _erfcx_reference(x: np.ndarray) -> np.ndarray:
    out = np.empty_like(x)
    small = x < 2.0
    out[small] = [math.erfc(v) * math.exp(v * v) for v in x[small]]
    xb = x[~small]
    f = xb.copy()
    for k in range(200, 0, -1):
        f = xb + (0.5 * k) / f
    out[~small] = 1.0 / (SQRT_PI * f)
    return out


def _fit_erfcx() -> np.ndarray:
    n = 400
    t = np.cos(np.pi * (np.arange(n) + 0.5) / n)
    x = ERFCX_K * (1.0 + t) / (1.0 - t)
    coef = np.polynomial.chebyshev.chebfit(t, _erfcx_reference(x) * (x + ERFCX_K), ERFCX_DEGREE)
    coef.setflags(write=False)
    return coef


ERFCX_COEF = _fit_erfcx()


def erfcx_nonneg(x: np.ndarray) -> np.ndarray:
    """e^{x²} erfc(x) for x ≥ 0 (x = +∞ gives 0)."""
    xc = np.minimum(x, 1e150)
    t = (xc - ERFCX_K) / (xc + ERFCX_K)
    c = ERFCX_COEF
    t2 = 2.0 * t
    b0 = np.empty_like(t)
    b1 = np.zeros_like(t)
    b2 = np.zeros_like(t)
    for k in range(len(c) - 1, 0, -1):  # Clenshaw recurrence b_k = c_k + 2t b_{k+1} − b_{k+2}, in place
        np.multiply(t2, b1, out=b0)
        b0 -= b2
        b0 += c[k]
        b0, b1, b2 = b2, b0, b1
    return (c[0] + t * b1 - b2) / (xc + ERFCX_K)


def erfcx(x) -> np.ndarray:
    """Scaled complementary error function e^{x²} erfc(x), vectorised (overflows to ∞ for x ≲ −26.6)."""
    x = np.asarray(x, dtype=np.float64)
    pos = erfcx_nonneg(np.abs(x))
    with np.errstate(over="ignore"):
        neg = 2.0 * np.exp(x * x) - pos
    return np.where(x >= 0, pos, neg)


# ------------------------------------------------------------------------------------------------
# erfinv
# ------------------------------------------------------------------------------------------------
#: M. Giles (2010), erfinv(y) ≈ y·p(w), w = −log(1 − y²): Horner coefficients of p, highest first,
#: for w < 5 (in w − 2.5) and w ≥ 5 (in √w − 3).
GILES_LOW = (2.81022636e-08, 3.43273939e-07, -3.5233877e-06, -4.39150654e-06, 0.00021858087, -0.00125372503,
             -0.00417768164, 0.246640727, 1.50140941)
GILES_HIGH = (-0.000200214257, 0.000100950558, 0.00134934322, -0.00367342844, 0.00573950773, -0.0076224613,
              0.00943887047, 1.00167406, 2.83297682)


def erfcinv_giles(q: np.ndarray, log=np.log) -> np.ndarray:
    """Approximate x ≥ 0 with erfc(x) = q ∈ (0, 1]: M. Giles (2010), "Approximating the erfinv
    function" (single-precision fit, relative error ~1e-7 for q ≳ 1e-7, cruder beyond); ``log``: NumPy's or
    another elementwise logarithm."""
    y = 1.0 - q  # erf(x) = y ∈ [0, 1)
    w = -log(q * (2.0 - q))  # −log((1 − y)(1 + y)) without cancellation
    lo = w < 5.0
    wl = w - 2.5
    p1 = GILES_LOW[0]
    for c in GILES_LOW[1:]:
        p1 = c + p1 * wl
    wh = np.sqrt(w) - 3.0
    p2 = GILES_HIGH[0]
    for c in GILES_HIGH[1:]:
        p2 = c + p2 * wh
    return np.maximum(np.where(lo, p1, p2) * y, 0.0)


def erfcinv(q: np.ndarray, start=erfcinv_giles) -> np.ndarray:
    """x ≥ 0 with erfc(x) = q for q ∈ [1e-300, 1] (Newton polish to ~1e-15 from ``start(q)``, Giles')."""
    q = np.clip(q, 1e-300, 1.0)
    x = start(q)
    # Giles' fit is single precision (and poor for q < 1e-7): Newton on ln erfc(x) = ln q, i.e.
    # x ← x + (ln erfc(x) − ln q)·(√π/2)·erfcx(x), which converges fast in the tail as well.
    # Only the points that have not converged are iterated.
    log_q = np.log(q)
    active = np.arange(x.size)
    xa, lqa = x.copy(), log_q
    for _ in range(12):
        ex = erfcx_nonneg(xa)
        step = (np.log(ex) - xa * xa - lqa) * (0.5 * SQRT_PI) * ex
        xn = np.maximum(xa + step, 0.0)
        x[active] = xn
        # Newton converges quadratically (ln erfc has curvature ≲ 2): after a step below 1e-9
        # the remaining error is ≲ 1e-17.
        keep = np.abs(step) > 1e-9 * (1.0 + xn)
        if not keep.any():
            break
        active, xa, lqa = active[keep], xn[keep], lqa[keep]
    return x


def erfinv(y) -> np.ndarray:
    """Inverse error function on (−1, 1) (±∞ at ±1), vectorised; accurate to ~1e-14."""
    y = np.asarray(y, dtype=np.float64)
    q = 1.0 - np.abs(y)
    x = np.sign(y) * erfcinv(np.where(q > 0, q, 1.0))
    return np.where(q > 0, x, np.where(y > 0, np.inf, -np.inf))


def erfinv_2u_minus_1(u: np.ndarray, start=erfcinv_giles) -> np.ndarray:
    """erfinv(2u − 1) for u ∈ [0, 1], computed from min(u, 1 − u) (accurate in both tails); ``start``: as erfcinv's."""
    u = np.clip(u, 1e-16, 1.0 - 1e-16)
    lower = u < 0.5
    q = 2.0 * np.where(lower, u, 1.0 - u)  # erfc(|x|) = q
    x = erfcinv(q, start)
    return np.where(lower, -x, x)



# ------------------------------------------------------------------------------------------------
# scalar forms for compiled loops (same operation order)
# ------------------------------------------------------------------------------------------------

@jit_inner
def erfcx_nonneg_scalar(x, coef, k):
    """erfcx_nonneg for one x ≥ 0 with the series ``coef`` (ERFCX_COEF) and ``k`` (ERFCX_K)."""
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


@jit_inner
def erfcinv_giles_scalar(q):
    """erfcinv_giles for one q ∈ (0, 1]."""
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
