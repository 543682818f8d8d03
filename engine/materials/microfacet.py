"""Microfacet distributions, shadowing terms and half-vector sampling (batched, (3, N) layout).

Everything here works in a *local shading frame*: the macro normal is +z and
directions are unit vectors (3, N) pointing away from the surface (ω_i to the
light, ω_o to the viewer, h the microfacet normal).  Callers convert world →
local once (see engine.materials.torrance_sparrow).

Distributions (both normalised, ∫ D(h) cosθ_h dω_h = 1 over the upper hemisphere):

- :class:`Beckmann` with the thesis's roughness ``m`` (= Mitsuba's α = SCATMECH's
  2-D rms slope s, physics.md §5):
  D(h) = exp(−tan²θ_h/m²) / (π m² cos⁴θ_h), evaluated as exp(−x)·(1 + tan²θ_h)²/(π m²),
  x = tan²θ_h/m², with tan²θ_h = (h_x² + h_y²)/h_z² taken from the vector components
  (no 1 − cos² cancellation near the specular peak).  D is *exactly* 0 where x > 800
  (exp underflows there anyway; the cut-off avoids 0·∞ for near-horizontal h) and for
  h_z ≤ 0.  Very small m are numerically fine (the peak is 1/(π m²)); the material
  enforces m ≥ 1e-4 (engine.materials.torrance_sparrow.M_MIN).
  Sampling: **visible normals** (Heitz & d'Eon 2014), implemented from the paper's
  math: stretch ω_o by m, sample the visible slope x̃ from the marginal
  ∝ (1 − x̃ tanθ) e^{−x̃²} (x̃ < cotθ) by bisection-safeguarded Halley inversion of its CDF
  F(x) = erfc(−x) + tanθ e^{−x²}/√π (vectorised; converged to ~1e-14 in probability),
  ỹ = erfinv(2u − 1), rotate by φ_o, unstretch, h = normalize(−x, −y, 1).  The density
  of the sampled h is D_ωo(h) = G1(ω_o) max(0, ω_o·h) D(h)/cosθ_o with the *exact*
  Smith G1 (it is the normalisation of the visible-normal distribution, whatever
  shadowing term the BRDF uses); for the reflected ω_i = 2(ω_o·h)h − ω_o the
  solid-angle pdf is D_ωo(h)/(4 ω_o·h) = G1(ω_o) D(h)/(4 cosθ_o).
- :class:`BlinnPhong` with exponent e ≥ 0: D(h) = (e+2)/(2π) cos^e θ_h.  Sampling
  D(h) cosθ_h exactly (cosθ_h = u^{1/(e+2)}); pdf of ω_i = D cosθ_h/(4 ω_o·h).  Its
  Smith G1 uses the Beckmann G1 with the equivalent m = √(2/(e+2)) (Walter et al. 2007).

Shadowing/masking (symmetric in ω_i ↔ ω_o, all return (N,)):

- :func:`g_vcavity`: Torrance–Sparrow/Cook–Torrance V-cavity
  G = min(1, 2(n·h)(n·ω_o)/(ω_o·h), 2(n·h)(n·ω_i)/(ω_i·h)), and 0 when either direction
  is on the back side of the facet or of the macro surface (physics.md §1.4, §3 Eq. 3.3).
- :func:`g_smith` : separable Smith G1(ω_i)G1(ω_o) with the exact Beckmann
  G1 = χ⁺ / (1 + Λ(a)), Λ(a) = (erf(a) − 1)/2 + e^{−a²}/(2a√π), a = 1/(m tanθ);
  ``rational=True`` uses Walter's rational approximation as in Mitsuba 3:
  G1 = 1 if a ≥ 1.6 else (3.535a + 2.181a²)/(1 + 2.276a + 2.577a²); G1 = 0 where
  (ω·h)·cosθ ≤ 0.

D is the Beckmann distribution, i.e. a Gaussian in the facet *slope* tanθ_h (as SCATMECH's
Gaussian_Slope_Distribution_Function and Mitsuba 3), not Torrance & Sparrow's 1967 Gaussian in
the facet angle θ_h itself (physics.md §3, Eq. 3.4).

erf/erfc/erfcx/erfinv are implemented here (numpy only, no scipy): erfc from a Chebyshev
fit of the scaled function erfcx (see below; relative error of erfc ≲ 1e-14 for x ≥ 0, of
erf ≲ 2e-15), erfinv from Giles' approximation polished by Newton steps (~1e-15).
Visible-normal sampling costs ~1.5 µs per sample in numpy (3–4 Halley steps, each one erfcx).
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels import COMPILED
from ..kernels.microfacet import GILES_HIGH, GILES_LOW, compiled_visible_slope_x

SQRT_PI = math.sqrt(math.pi)
_INV_SQRT_PI = 1.0 / SQRT_PI
_TWO_OVER_SQRT_PI = 2.0 / SQRT_PI
#: exp(−x) for x beyond this is exactly 0 in double precision (and D is set to 0 there).
_EXP_CUTOFF = 800.0


# --- special functions ---------------------------------------------------------------------------------
#
# erfc is computed from the scaled function erfcx(x) = e^{x²} erfc(x) (x ≥ 0), which is smooth and
# decays like 1/(x√π): erfcx(x)·(x + K) is a smooth bounded function of t = (x − K)/(x + K) ∈ [−1, 1),
# approximated by a Chebyshev series of degree _ERFCX_DEGREE in t.  The coefficients are fitted
# at import time (least squares at 400 Chebyshev nodes, ~1 ms) to references independent of this
# approximation: the C library's erfc (math.erfc) times e^{x²} for x < 2, and for x ≥ 2 the
# continued fraction erfc(x) = e^{−x²}/√π · 1/(x + ½/(x + 1/(x + 3/2/(x + …)))) evaluated with
# 200 levels.  Relative error of erfc ≲ 1e-14 for x ≥ 0 (checked against math.erfc in the tests).

_ERFCX_K = 3.0
_ERFCX_DEGREE = 22


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
    x = _ERFCX_K * (1.0 + t) / (1.0 - t)
    coef = np.polynomial.chebyshev.chebfit(t, _erfcx_reference(x) * (x + _ERFCX_K), _ERFCX_DEGREE)
    coef.setflags(write=False)
    return coef


_ERFCX_COEF = _fit_erfcx()


def _erfcx_nonneg(x: np.ndarray) -> np.ndarray:
    """e^{x²} erfc(x) for x ≥ 0 (x = +∞ gives 0)."""
    xc = np.minimum(x, 1e150)
    t = (xc - _ERFCX_K) / (xc + _ERFCX_K)
    c = _ERFCX_COEF
    t2 = 2.0 * t
    b0 = np.empty_like(t)
    b1 = np.zeros_like(t)
    b2 = np.zeros_like(t)
    for k in range(len(c) - 1, 0, -1):  # Clenshaw recurrence b_k = c_k + 2t b_{k+1} − b_{k+2}, in place
        np.multiply(t2, b1, out=b0)
        b0 -= b2
        b0 += c[k]
        b0, b1, b2 = b2, b0, b1
    return (c[0] + t * b1 - b2) / (xc + _ERFCX_K)


def erfcx(x) -> np.ndarray:
    """Scaled complementary error function e^{x²} erfc(x), vectorised (overflows to ∞ for x ≲ −26.6)."""
    x = np.asarray(x, dtype=np.float64)
    pos = _erfcx_nonneg(np.abs(x))
    with np.errstate(over="ignore"):
        neg = 2.0 * np.exp(x * x) - pos
    return np.where(x >= 0, pos, neg)


def erfc(x) -> np.ndarray:
    """Complementary error function, vectorised (relative accuracy ~1e-14 for x ≥ 0)."""
    x = np.asarray(x, dtype=np.float64)
    ax = np.abs(x)
    c = np.exp(-ax * ax) * _erfcx_nonneg(ax)
    return np.where(x >= 0, c, 2.0 - c)


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
    return np.where(ax < 0.5, series, np.sign(x) * (1.0 - np.exp(-ax * ax) * _erfcx_nonneg(ax)))


def _erfcinv_giles(q: np.ndarray) -> np.ndarray:
    """Approximate x ≥ 0 with erfc(x) = q ∈ (0, 1]: M. Giles (2010), "Approximating the erfinv
    function" (single-precision fit, relative error ~1e-7 for q ≳ 1e-7, cruder beyond)."""
    y = 1.0 - q  # erf(x) = y ∈ [0, 1)
    w = -np.log(q * (2.0 - q))  # −log((1 − y)(1 + y)) without cancellation
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


def _erfcinv_small(q: np.ndarray) -> np.ndarray:
    """x ≥ 0 with erfc(x) = q for q ∈ [1e-300, 1] (Giles' start, Newton polish to ~1e-15)."""
    q = np.clip(q, 1e-300, 1.0)
    x = _erfcinv_giles(q)
    # Giles' fit is single precision (and poor for q < 1e-7): Newton on ln erfc(x) = ln q, i.e.
    # x ← x + (ln erfc(x) − ln q)·(√π/2)·erfcx(x), which converges fast in the tail as well.
    # Only the points that have not converged are iterated.
    log_q = np.log(q)
    active = np.arange(x.size)
    xa, lqa = x.copy(), log_q
    for _ in range(12):
        ex = _erfcx_nonneg(xa)
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
    x = np.sign(y) * _erfcinv_small(np.where(q > 0, q, 1.0))
    return np.where(q > 0, x, np.where(y > 0, np.inf, -np.inf))


def _gaussian_quantile_half(u: np.ndarray) -> np.ndarray:
    """erfinv(2u − 1) for u ∈ [0, 1], computed from min(u, 1 − u) (accurate in both tails)."""
    u = np.clip(u, 1e-16, 1.0 - 1e-16)
    lower = u < 0.5
    q = 2.0 * np.where(lower, u, 1.0 - u)  # erfc(|x|) = q
    x = _erfcinv_small(q)
    return np.where(lower, -x, x)


def beckmann_lambda(a) -> np.ndarray:
    """Smith Λ(a) = (erf(a) − 1)/2 + e^{−a²}/(2a√π) for the Beckmann distribution, a = 1/(m tanθ) ≥ 0.

    Λ(∞) = 0 (normal incidence); Λ(0) = ∞ (grazing).  Computed as
    ½ e^{−a²}(1/(a√π) − erfcx(a)); for a > 6, Λ < 1e-17 and is set to 0.
    """
    a = np.asarray(a, dtype=np.float64)
    pos = a > 0
    small = pos & (a <= 6.0)
    safe = np.where(small, a, 1.0)
    lam = 0.5 * np.exp(-safe * safe) * (_INV_SQRT_PI / safe - _erfcx_nonneg(safe))
    lam = np.maximum(lam, 0.0)
    return np.where(small, lam, np.where(pos, 0.0, np.inf))


# --- vector helpers ------------------------------------------------------------------------------------


def half_vector(wi: np.ndarray, wo: np.ndarray):
    """(h, cos_facet, ok): h = unit(ω_i + ω_o), cos of the facet angle ω_i·h = ω_o·h = |ω_i + ω_o|/2.

    ``ok`` is False where ω_i = −ω_o (h undefined); h is then (0, 0, 1) and cos_facet 0.
    """
    hv = wi + wo
    length = np.sqrt(hv[0] * hv[0] + hv[1] * hv[1] + hv[2] * hv[2])
    ok = length > 0
    h = np.where(ok, hv / np.where(ok, length, 1.0), np.array([[0.0], [0.0], [1.0]]))
    return h, np.minimum(0.5 * length, 1.0), ok


def reflect_local(w: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Mirror direction of w about the unit facet normal h (both (3, N))."""
    d = w[0] * h[0] + w[1] * h[1] + w[2] * h[2]
    return 2.0 * d * h - w


def _tan2(w: np.ndarray) -> np.ndarray:
    """tan²θ of w about +z (∞ for w_z = 0 with w_xy ≠ 0; 0 for w = ±z)."""
    xy2 = w[0] * w[0] + w[1] * w[1]
    z2 = w[2] * w[2]
    return np.where(z2 > 0, xy2 / np.where(z2 > 0, z2, 1.0), np.where(xy2 > 0, np.inf, 0.0))


def _smith_a(w: np.ndarray, m: float) -> np.ndarray:
    """a = 1/(m tanθ) = cosθ/(m sinθ) ≥ 0 (∞ at normal incidence, 0 at grazing)."""
    sin_t = np.sqrt(w[0] * w[0] + w[1] * w[1])
    cos_t = np.abs(w[2])
    return np.where(sin_t > 0, cos_t / (m * np.where(sin_t > 0, sin_t, 1.0)), np.inf)


def _chi_plus(w: np.ndarray, h: np.ndarray) -> np.ndarray:
    """1 where (w·h)·cosθ_w > 0 (w sees the front of facet h from the front of the surface)."""
    d = w[0] * h[0] + w[1] * h[1] + w[2] * h[2]
    return (d * w[2] > 0).astype(np.float64)


def g1_beckmann_exact(w: np.ndarray, h: np.ndarray, m: float) -> np.ndarray:
    """Exact Smith masking G1(w, h) = χ⁺((w·h) cosθ_w) / (1 + Λ(1/(m tanθ_w))) for Beckmann."""
    return _chi_plus(w, h) / (1.0 + beckmann_lambda(_smith_a(w, m)))


def g1_beckmann_rational(w: np.ndarray, h: np.ndarray, m: float) -> np.ndarray:
    """Walter et al. 2007 rational approximation of the Beckmann G1 (as Mitsuba 3's ``smith_g1``)."""
    a = _smith_a(w, m)
    af = np.minimum(a, 1.6)
    g = np.where(a >= 1.6, 1.0, (3.535 * af + 2.181 * af * af) / (1.0 + 2.276 * af + 2.577 * af * af))
    return g * _chi_plus(w, h)


# --- distributions -------------------------------------------------------------------------------------


class MicrofacetDistribution:
    """Interface: isotropic distribution of microfacet normals about +z (local frame)."""

    name = "distribution"
    #: Beckmann-equivalent roughness used by the Smith masking functions.
    smith_m: float = 1.0

    def D(self, h: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def G1(self, w: np.ndarray, h: np.ndarray, rational: bool = False) -> np.ndarray:
        """Smith masking of facet h seen from w (Beckmann form with ``smith_m``)."""
        if rational:
            return g1_beckmann_rational(w, h, self.smith_m)
        return g1_beckmann_exact(w, h, self.smith_m)

    def sample(self, wo: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Facet normals h (3, N) for viewer directions wo (3, N) from uniforms u (2, N)."""
        raise NotImplementedError

    def pdf(self, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Solid-angle density of h under :meth:`sample` (N,)."""
        raise NotImplementedError

    def pdf_reflected(self, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Solid-angle density of ω_i = reflect(ω_o, h) under :meth:`sample`: pdf(h)/(4 ω_o·h)."""
        d = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        ok = d > 0
        return np.where(ok, self.pdf(wo, h) / (4.0 * np.where(ok, d, 1.0)), 0.0)


class Beckmann(MicrofacetDistribution):
    """Beckmann distribution with roughness m (rms 2-D slope); visible-normal sampling."""

    name = "beckmann"

    def __init__(self, m: float):
        m = float(m)
        if not (math.isfinite(m) and m > 0):
            raise ValueError(f"Beckmann roughness m must be a finite number > 0, got {m!r}")
        self.m = m
        self.smith_m = m

    @classmethod
    def per_point(cls, m: np.ndarray) -> Beckmann:
        """Beckmann distributions with one roughness per point, m (N,) > 0 (a textured m): every
        method is elementwise in m, so point i gets exactly the values of ``Beckmann(m[i])``."""
        m = np.asarray(m, dtype=np.float64)
        if not np.all(np.isfinite(m) & (m > 0)):
            raise ValueError("Beckmann roughness m must be finite numbers > 0")
        dist = cls.__new__(cls)
        dist.m = dist.smith_m = m
        return dist

    def D(self, h: np.ndarray) -> np.ndarray:
        t2 = _tan2(h)
        x = t2 / (self.m * self.m)
        ok = (h[2] > 0) & (x <= _EXP_CUTOFF)
        xs = np.where(ok, x, 0.0)
        ts = np.where(ok, t2, 0.0)
        one_t = 1.0 + ts
        return np.where(ok, np.exp(-xs) * (one_t * one_t) / (math.pi * self.m * self.m), 0.0)

    # -- visible normal sampling (Heitz & d'Eon 2014) --
    @staticmethod
    def _visible_slope_cdf(x: np.ndarray, t: np.ndarray) -> np.ndarray:
        """F(x) = erfc(−x) + t e^{−x²}/√π (unnormalised CDF of the visible slope x̃), tail-accurate."""
        e = np.exp(-x * x)
        r = _erfcx_nonneg(np.abs(x))
        tp = t * _INV_SQRT_PI
        return np.where(x < 0, e * (r + tp), 2.0 + e * (tp - r))

    @classmethod
    def _sample_slopes11(cls, tan_t: np.ndarray, u1: np.ndarray, u2: np.ndarray, use_kernel: bool = True):
        """Visible slopes (x̃, ỹ) of the unit-roughness Beckmann surface seen from θ with tanθ = tan_t ≥ 0.

        x̃ has density ∝ (1 − x̃ tanθ) e^{−x̃²} on x̃ < cotθ, with CDF F(x)/F(cotθ),
        F(x) = erfc(−x) + tanθ e^{−x²}/√π; it is found by Halley's method safeguarded by
        bisection on the bracket [−8, min(cotθ, 8)] (F(−8)/F(cotθ) < 1e-27).  ỹ is independent
        with density e^{−ỹ²}/√π: ỹ = erfinv(2u₂ − 1).  x̃ comes from the compiled loop of
        engine.kernels.microfacet when available (the same algorithm per path; this NumPy body is
        its reference, ``use_kernel=False``).
        """
        if COMPILED and use_kernel:
            return compiled_visible_slope_x(tan_t, u1, _ERFCX_COEF, _ERFCX_K), _gaussian_quantile_half(u2)
        n = tan_t.shape[0]
        cot = np.where(tan_t > 0, 1.0 / np.where(tan_t > 0, tan_t, 1.0), np.inf)
        lo = np.full(n, -8.0)
        hi = np.minimum(cot, 8.0)
        z = cls._visible_slope_cdf(np.minimum(cot, 30.0), tan_t)
        u = np.clip(u1, 0.0, 1.0)
        # Start: the Gaussian quantile (exact for θ = 0); for large tanθ the left tail is
        # ≈ e^{−x²}·(tanθ/√π)/F(cotθ), whose inverse is the better start.
        uc = np.clip(u, 1e-300, 1.0 - 1e-16)
        lower = uc < 0.5
        xg = _erfcinv_giles(2.0 * np.where(lower, uc, 1.0 - uc))
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
            f = cls._visible_slope_cdf(xa, ta) - tga
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
        y = _gaussian_quantile_half(u2)
        return x, y

    def sample(self, wo: np.ndarray, u: np.ndarray) -> np.ndarray:
        m = self.m
        sxy = np.sqrt(wo[0] * wo[0] + wo[1] * wo[1])
        cz = np.maximum(wo[2], 0.0)
        # Stretched direction (m wo_x, m wo_y, wo_z): tanθ' = m tanθ, same azimuth.
        tan_t = np.where(cz > 0, m * sxy / np.where(cz > 0, cz, 1.0), 1e300)
        tan_t = np.minimum(tan_t, 1e300)
        has_phi = sxy > 0
        cos_p = np.where(has_phi, wo[0] / np.where(has_phi, sxy, 1.0), 1.0)
        sin_p = np.where(has_phi, wo[1] / np.where(has_phi, sxy, 1.0), 0.0)
        sx, sy = self._sample_slopes11(tan_t, u[0], u[1])
        x = m * (cos_p * sx - sin_p * sy)
        y = m * (sin_p * sx + cos_p * sy)
        h = np.stack((-x, -y, np.ones_like(x)))
        return h / np.sqrt(h[0] * h[0] + h[1] * h[1] + 1.0)

    def pdf(self, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
        """G1(ω_o) max(0, ω_o·h) D(h)/cosθ_o (exact Smith G1): the visible-normal density."""
        d = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        ok = (wo[2] > 0) & (d > 0)
        g1 = 1.0 / (1.0 + beckmann_lambda(_smith_a(wo, self.m)))
        return np.where(ok, g1 * np.maximum(d, 0.0) * self.D(h) / np.where(ok, wo[2], 1.0), 0.0)

    def pdf_reflected(self, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
        """G1(ω_o) D(h)/(4 cosθ_o) where ω_o·h > 0 (the ω_o·h of the Jacobian cancels)."""
        d = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        ok = (wo[2] > 0) & (d > 0)
        g1 = 1.0 / (1.0 + beckmann_lambda(_smith_a(wo, self.m)))
        return np.where(ok, g1 * self.D(h) / (4.0 * np.where(ok, wo[2], 1.0)), 0.0)

    def __repr__(self):
        return f"Beckmann(m={self.m!r})"


class BlinnPhong(MicrofacetDistribution):
    """Blinn–Phong distribution D = (e+2)/(2π) cos^e θ_h; samples D cosθ_h."""

    name = "blinn"

    def __init__(self, exponent: float):
        e = float(exponent)
        if not (math.isfinite(e) and e >= 0):
            raise ValueError(f"Blinn-Phong exponent must be a finite number >= 0, got {exponent!r}")
        self.e = e
        self.smith_m = math.sqrt(2.0 / (e + 2.0))

    @classmethod
    def from_beckmann_m(cls, m: float) -> BlinnPhong:
        """The Blinn lobe matching Beckmann roughness m near the peak: e = 2/m² − 2 (needs m ≤ √2)."""
        m = float(m)
        if not (math.isfinite(m) and 0 < m <= math.sqrt(2.0)):
            raise ValueError(f"Blinn from Beckmann m needs 0 < m <= sqrt(2), got {m!r}")
        return cls(max(2.0 / (m * m) - 2.0, 0.0))

    def D(self, h: np.ndarray) -> np.ndarray:
        c = h[2]
        ok = c > 0
        cs = np.where(ok, np.minimum(c, 1.0), 1.0)
        return np.where(ok, (self.e + 2.0) / (2.0 * math.pi) * cs ** self.e, 0.0)

    def sample(self, wo: np.ndarray, u: np.ndarray) -> np.ndarray:
        # cosθ_h = u^{1/(e+2)};  sin²θ_h = 1 − u^{2/(e+2)} = −expm1(2 ln u/(e+2)).
        u1 = np.clip(u[0], 1e-300, 1.0)
        lnu = np.log(u1) / (self.e + 2.0)
        cos_t = np.exp(lnu)
        sin_t = np.sqrt(np.maximum(-np.expm1(2.0 * lnu), 0.0))
        phi = 2.0 * math.pi * u[1]
        return np.stack((sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t))

    def pdf(self, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
        return self.D(h) * np.maximum(h[2], 0.0)

    def __repr__(self):
        return f"BlinnPhong(e={self.e!r})"


# --- shadowing -----------------------------------------------------------------------------------------


def g_vcavity(wi: np.ndarray, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Torrance–Sparrow V-cavity G = min(1, 2 h_z ω_o,z/(ω_o·h), 2 h_z ω_i,z/(ω_i·h)); 0 on back sides."""
    di = wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]
    do = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
    ok = (di > 0) & (do > 0) & (h[2] > 0) & (wi[2] > 0) & (wo[2] > 0)
    g_o = 2.0 * h[2] * wo[2] / np.where(ok, do, 1.0)
    g_i = 2.0 * h[2] * wi[2] / np.where(ok, di, 1.0)
    return np.where(ok, np.minimum(1.0, np.minimum(g_o, g_i)), 0.0)


def g_smith(dist: MicrofacetDistribution, wi: np.ndarray, wo: np.ndarray, h: np.ndarray,
            rational: bool = False) -> np.ndarray:
    """Separable Smith shadowing-masking G1(ω_i, h)·G1(ω_o, h) of ``dist``."""
    return dist.G1(wi, h, rational) * dist.G1(wo, h, rational)


SHADOWING = ("ts", "smith", "smith_rational", "none")


def shadowing_term(kind: str, dist: MicrofacetDistribution, wi, wo, h) -> np.ndarray:
    """G of the named kind: "ts" (V-cavity), "smith", "smith_rational" or "none" (G = 1 on the front side)."""
    if kind == "ts":
        return g_vcavity(wi, wo, h)
    if kind == "smith":
        return g_smith(dist, wi, wo, h)
    if kind == "smith_rational":
        return g_smith(dist, wi, wo, h, rational=True)
    if kind == "none":
        return _chi_plus(wi, h) * _chi_plus(wo, h)
    raise ValueError(f"shadowing must be one of {SHADOWING}, got {kind!r}")
