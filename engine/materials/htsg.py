"""He–Torrance–Sillion–Greenberg (1991) polarising BRDF ("htsg").

Physics as fixed by docs/physics.md (§2 numerics, §3 Chapter 4 errata,
§5 decisions); symbols follow He et al. 1991.  Lengths σ₀, τ, λ in µm inside
this module (the engine's wavelengths are nm: λ_µm = λ_nm / 1000, divided by
the exterior index, i.e. the wavelength *in the incident medium*).

Geometry (docs/physics.md §0): ω_i = ``wi`` points to the light, ω_o = ``sp.wo`` to
the viewer, k_i = −ω_i, k_r = ω_o, n = shading normal.  One-sided: zero unless
cosθ_i > 0 and cosθ_r > 0.  With v = k_r − k_i = ω_o + ω_i (unitless; the
physical vector is (2π/λ)·v):

    directional diffuse   M_dd = M_F(θ_h) · S·G·D / (π cosθ_i cosθ_r)
        M_F(θ_h)  Fresnel Mueller matrix (amplitudes r_s, r_p) at cosθ_h = |v|/2,
                  in the scattering-plane frames s = unit(k_i × k_r) (shared by
                  both beams; any ⟂ vector when k_i ∥ k_r), p = k × s
                  (docs/physics.md 4.40 with the 4.14 sign fix: diag(r_s, r_p)·|k_i×k_r|²);
        G = (|v|²/v_z)²                 (He's Eq. 76 with |k_i×k_r|⁴ cancelled analytically)
        D = π²τ²/(4λ²) · Σ_{m≥1} gᵐe^{−g}/(m!·m) · exp(−(2π/λ)²|v_xy|²τ²/(4m))
        g = [(2πσ/λ)(cosθ_i + cosθ_r)]²,  σ = σ₀/√(1+x²) the effective roughness
        S = S(θ_i)·S(θ_r),  S(θ) = (1 − ½erfc μ)/(Λ(μ) + 1),  μ = τ cotθ/(2σ₀),
            Λ = ½(e^{−μ²}/(√π μ) − erfc μ)   (the Eq. 25 erratum; S = 1 at θ = 0)
    uniform diffuse       M_ud = (albedo/π)·diag(1, 0, 0, 0)   (a depolariser)
    specular (Dirac)      weight M_F(θ_i)·e^{−g(θ_i,θ_i)}·S(θ_i)², plane-of-incidence frames

``eval`` returns M_dd (+ M_ud) per wavelength: kind "abcs" when the diffuse
albedo is zero, otherwise "general" (an ABCS matrix plus a depolariser is not of
ABCS form: M11 ≠ M00).

Effective roughness: x = z₀/σ₀ solves x·e^{x²/2} = f₀ with
f₀ = (K′_i + K′_r)/√(8π), K′ = tanθ·erfc(μ) (= 4K of Eq. 4.6); K′ = 0 for
tanθ < 1e-6 and tanθ is capped at 1e12 (docs/physics.md §2).  Equivalently
x² = W₀(f₀²) (Lambert W); it is solved by Newton's method on
h(t) = e^t + t − 2 ln f₀ with t = ln x², which is convex and increasing, so
Newton converges monotonically after at most one overshoot (no safeguard can
be violated; it is iterated to machine precision, ≤ 60 steps, typically < 8).

The series (``log_series``): terms T_m = exp(φ_m),
φ_m = m ln g − g − ln m! − ln m − c/m with c = (2π/λ)²|v_xy|²τ²/4.  Their ratio
R(m) = T_{m+1}/T_m = g·m/(m+1)²·exp(c/(m(m+1))) is strictly decreasing for
m ≥ 1, so the sequence is log-concave and unimodal, and *rigorous* geometric
tail bounds follow from a single term and ratio at each window end:

    Σ_{m>b} T_m ≤ T_b · r/(1−r),   r = R(b) < 1            (b past the mode)
    Σ_{m<a} T_m ≤ T_a · r′/(1−r′), r′ = 1/R(a−1) < 1       (a before the mode)

The mode m* (the root of ln R = 0, unique) is found by safeguarded Newton in ln m.
The window starts as [m̂ − ⌈K·s⌉ − 2, m̂ + ⌈(K+1)·s⌉ + 2] ∩ [1, ∞), m̂ = round(m*),
s = 1/√(−d ln R/dm) the peak width (≈ √g for the Poisson part), K = √(2 ln(1/tol))
(6.8 for tol = 1e-10).  Each end is then pushed outwards until φ has dropped by at
least ln(1/tol) + ln(2 + s) below the mode: φ is concave, so extrapolating the
chord from the mode through the end never stops short (skewed peaks: far
off-specular geometries where e^{−c/m} moves the peak above g).  Finally the two
rigorous tail bounds above are checked against ``tol``·sum and the window is
widened (K × 1.5) wherever they fail, so the omitted tail is provably below
tol·sum (this implies the Westin/He criterion "m > g and term < ε·sum").

Unit stride: the terms are generated from the mode outwards by the ratio
recurrence (one exp per term; they shrink monotonically, so nothing overflows).
Wide peaks lying clear of the series' start (m_lo ≥ 2 and s ≥ 2γ, γ = 1.5; in
practice g ≳ 60): the window is summed with an integer stride h = ⌊s/γ⌋ and weight h
(the trapezoid rule on the lattice m̂ + hℤ), every node from the closed form
φ_m = (z−g) − m·ln(z/g) − ½ln(2πz) − ε(z) − ln m − c/m, z = m+1, with
ε(z) = ln Γ(z) − Stirling's leading terms (a table for z < 64, the asymptotic series
beyond, error < 1e-19): no cancellation, ~1e-13 relative per term even at g = 5e5.
The summand continues to an analytic, near-Gaussian function of m of width s, so by
Poisson summation the unit-stride sum and the strided sum equal the same integral up
to aliasing terms (~exp(−2π²s²/h²) ≤ exp(−2π²γ²) ≈ 5e-20 for a Gaussian); both window
ends are in the provably negligible tails, which the trapezoid rule needs (a window
clipped at m = 1 is summed with unit stride: there the series' start is a hard edge,
and striding across it would cost ~1e-3).  This is not an asymptotic expansion: it
is checked against the brute-force full series for random g ∈ [1e-6, 5e5] and c in
tests/materials/test_htsg.py (agreement ≤ 1e-11 relative; stride=False sums every term of the
window and agrees with brute force too).  Cost per point and wavelength: ≤ ~110
terms (g ≈ 60, unit stride), ~25–30 strided nodes for any larger g (the full series
needs ~1.7e5 terms at the thesis's g ≈ 1.6e5).

Deviations from Westin's guards (docs/physics.md §2): none of the switches "S = 1 if
sinθ < 1e-5 or σ₀ < 1e-4 µm" and "σ = 0 if σ₀ < 1e-8 or cosθ < 1e-8" are applied; the
exact expressions are evaluated instead.  They are continuous and agree with the guarded
values except in corners (within 1e-8 of grazing, where S ≈ 0 makes the dd term vanish
anyway; σ₀ < 1e-4 µm near grazing; σ₀/τ ≳ 1e4 near the normal), where the exact
expressions are the consistent ones; the oracle cases are unaffected.  Results below
1e-280 (dd in 1/sr, specular weight) are flushed to 0: their products with the O(1)
Fresnel terms would be subnormal and too imprecise to stay realisable.

erfc: W. J. Cody's rational Chebyshev approximations (engine.kernels.error_function);
relative error ~1e-16 against libm (tested).  Only 2 erfc values per shading point are
needed (μ_i, μ_r do not depend on λ).

Sampling (λ-independent proposal, one direction for all wavelengths of a path):
the mirror (Dirac) lobe is chosen with probability
P_spec = min(ρ̄_s/(ρ̄_s + ρ̄_dd + ū), 0.9 if σ₀ > 0), bars = means over the path's wavelengths,
ρ_s = F(θ_o)·S(θ_o)²·e^{−g_s}, the dd albedo estimated as
ρ_dd ≈ F(θ_o)·S(θ_o)²·(1 − e^{−g_s}) (the incoherent share of the Kirchhoff
reflectance; g_s = g(θ_o, θ_o)), ū = mean diffuse albedo.  Otherwise a
direction comes from the mixture
    w_c · cosine hemisphere
  + w_b · Beckmann half-vector lobe, α_b = 2σ₀/τ      (geometric-optics limit of
          the dd lobe: for g ≫ 1 HTSG tends to Torrance–Sparrow with Beckmann m = 2σ/τ)
  + w_d · Beckmann half-vector lobe, α_d = λ_ref/(2πτ cosθ_o), λ_ref = 550 nm
          (the width of the m = 1 diffraction term near the mirror direction)
with w_c = 0.1 + 0.9·ū/(ū + ρ̄_dd), w_b = (1 − w_c)·g_ref/(1+g_ref),
w_d = (1 − w_c)/(1+g_ref), g_ref = (4πσ₀cosθ_o/λ_ref)² (g of the mirror geometry at
λ_ref; α_d = α_b/√g_ref), α's clamped to [1e-4, 4].  Half-vector samples reflected
below the horizon (or with ω_o·h ≤ 0) are returned invalid; ``pdf`` is the density
of the valid ones, so the estimator stays unbiased.
Sample weight f·cosθ_i/pdf with pdf = (1 − P_spec)·proposal (``pdf``), and
for the Dirac lobe its weight / P_spec.
"""

from __future__ import annotations

import math

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, MuellerValue, ShadingPoint
from .conductor import mirror_reflection, K, METAL, N, complex_index
from .parameters import ModelDeclaration, Parameter, Socket, exterior_n_parameter
from .sampling import cosine_hemisphere, local_to_world
from ..kernels.error_function import erfc
from ..polarisation.frames import scattering_plane_axis
from ..polarisation.fresnel import fresnel_reflection_abcs
from ..polarisation.mueller import abcs_matrix, depolariser
from ..spectral import ConstantSpectrum, Spectrum, as_spectrum
from ..textures import TexturedNumber, textured
from ..vec3 import cross, dot, normalize, reflect

__all__ = ["HTSG", "erfc", "shadowing", "roughness_ratio", "log_series", "ln_factorial"]

_SQRT_PI = math.sqrt(math.pi)
_LN_2PI = math.log(2.0 * math.pi)
_SQRT_8PI = math.sqrt(8.0 * math.pi)

# --------------------------------------------------------------------------------------------
# Shadowing and effective roughness
# --------------------------------------------------------------------------------------------

def _mu(cos_t, sin_t, sigma0, tau):
    """μ = τ cotθ/(2σ₀) (∞ at θ = 0 or σ₀ = 0)."""
    den = 2.0 * sigma0 * sin_t
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, tau * cos_t / np.where(den > 0, den, 1.0), np.inf)


def shadowing(mu, erfc_mu=None):
    """Smith shadowing S(μ) = (1 − ½erfc μ)/(Λ + 1), Λ = ½(e^{−μ²}/(√π μ) − erfc μ).

    μ = τ cotθ/(2σ₀) ≥ 0; S(∞) = 1 (normal incidence or a smooth surface), S(0) = 0 (grazing).
    """
    mu = np.asarray(mu, dtype=np.float64)
    ec = erfc(np.where(np.isfinite(mu), mu, 30.0)) if erfc_mu is None else erfc_mu
    ec = np.where(np.isfinite(mu), ec, 0.0)
    pos = mu > 0
    safe = np.where(pos & np.isfinite(mu), mu, 1.0)
    with np.errstate(over="ignore", under="ignore"):
        lam = 0.5 * (np.exp(-safe * safe) / (_SQRT_PI * safe) - ec)
    lam = np.where(np.isfinite(mu), lam, 0.0)
    return np.where(pos, (1.0 - 0.5 * ec) / (lam + 1.0), 0.0)


def roughness_ratio(f0, max_iter: int = 60):
    """x ≥ 0 with x·e^{x²/2} = f₀ (f₀ ≥ 0): the ratio z₀/σ₀ of He's Eq. 4.5.

    Solved for t = ln x² by Newton on h(t) = e^t + t − 2 ln f₀ (x² = W₀(f₀²)); h is convex
    and increasing, so the iteration converges monotonically after one step from any start.
    For f₀ < 1e-8, x = f₀ to double precision (x = f₀·(1 − f₀²/2 + …)).
    """
    f0 = np.asarray(f0, dtype=np.float64)
    x = f0.copy()
    big = f0 >= 1e-8
    if not big.any():
        return x
    L = 2.0 * np.log(f0[big])
    # start: W(y) ≈ ln y − ln ln y for large y, y for small y (t = ln W)
    t = np.where(L > 1.0, np.log(np.maximum(L - np.log(np.maximum(L, 1.0)), 0.5)), L)
    for _ in range(max_iter):
        et = np.exp(t)
        dt = (et + t - L) / (et + 1.0)
        t = t - dt
        if np.max(np.abs(dt)) < 1e-15:
            break
    x[big] = np.exp(0.5 * t)
    return x


def _k_prime(cos_t, sin_t, erfc_mu):
    """K′ = tanθ·erfc(μ) with the guards of docs/physics.md §2 (0 for tanθ < 1e-6, tanθ ≤ 1e12)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        tan = np.where(cos_t > 0, sin_t / np.where(cos_t > 0, cos_t, 1.0), 1e12)
    tan = np.minimum(tan, 1e12)
    return np.where(tan < 1e-6, 0.0, tan * erfc_mu)


# --------------------------------------------------------------------------------------------
# The series
# --------------------------------------------------------------------------------------------
_EPS_TABLE_N = 64
# ε(z) = ln Γ(z) − [(z − ½) ln z − z + ½ ln 2π] for integer z < 64 (table), asymptotic beyond.
_EPS_TABLE = np.array([0.0] + [math.lgamma(z) - ((z - 0.5) * math.log(z) - z + 0.5 * _LN_2PI)
                               for z in range(1, _EPS_TABLE_N)])


def _stirling_eps(z):
    """ε(z) = ln Γ(z) − (z − ½) ln z + z − ½ ln 2π for integer-valued z ≥ 1 (float array)."""
    r = 1.0 / np.maximum(z, float(_EPS_TABLE_N))
    r2 = r * r
    out = r * (1.0 / 12.0 - r2 * (1.0 / 360.0 - r2 * (1.0 / 1260.0 - r2 * (1.0 / 1680.0))))
    small = z < _EPS_TABLE_N
    if small.any():
        out[small] = _EPS_TABLE[z[small].astype(np.int64)]
    return out


def ln_factorial(m):
    """ln m! for integer-valued float arrays m ≥ 0 (Stirling + table, ~1 ulp)."""
    z = np.asarray(m, dtype=np.float64) + 1.0
    return (z - 0.5) * np.log(z) - z + 0.5 * _LN_2PI + _stirling_eps(z)


def _log_term(m, g, ln_g, c):
    """φ_m = m ln g − g − ln m! − ln m − c/m without catastrophic cancellation (m ≥ 1 integer).

    φ_m = (z − g) − m·ln(z/g) − ½ ln(2πz) − ε(z) − ln m − c/m with z = m + 1; ln(z/g) is
    taken as log1p((z − g)/g) where z and g are within a factor 4 (the cancelling regime).
    """
    z = m + 1.0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        near = (g > 0.5) & (g < 4.0 * z) & (z < 4.0 * g)
        if near.all():
            lzg = np.log1p((z - g) / g)
        else:
            lzg = np.log(z) - ln_g
            if near.any():
                lzg[near] = np.log1p((z[near] - g[near]) / g[near])
        return (z - g) - m * lzg - 0.5 * (_LN_2PI + np.log(z)) - _stirling_eps(z) - np.log(m) - c / m


def _log_ratio(m, ln_g, c):
    """ln R(m) = ln(T_{m+1}/T_m) = ln g + ln m − 2 ln(m+1) + c/(m(m+1)); decreasing for m ≥ 1."""
    return ln_g + np.log(m) - 2.0 * np.log1p(m) + c / (m * (m + 1.0))


def _mode(ln_g, c):
    """Continuous root m* ≥ 1 of ln R(m) = 0 (1 where ln R(1) ≤ 0), by safeguarded Newton in t = ln m.

    ln R is strictly decreasing in m ≥ 1, so the root is unique and bracketed by
    [0, ln(max(2g, √(c/ln 1.5), 2) + 1)] (there g·m/(m+1)² < ½ and e^{c/(m(m+1))} < 1.5).
    The window only needs m* to ±0.1; the iteration stops at |Δt| < 1e-9.
    """
    f1 = _log_ratio(np.ones_like(ln_g), ln_g, c)
    m = np.ones_like(ln_g)
    idx = np.nonzero(f1 > 0)[0]
    if idx.size == 0:
        return m
    lg, cc = ln_g[idx], c[idx]
    gg = np.exp(np.minimum(lg, 700.0))
    hi = np.log(np.maximum(np.maximum(2.0 * gg, np.sqrt(cc / math.log(1.5))), 2.0) + 1.0)
    lo = np.zeros_like(hi)
    t = np.log(np.maximum(gg, 0.5 * np.sqrt(cc)) + 1e-300)
    t = np.where(np.isfinite(t) & (t > lo) & (t < hi), t, 0.5 * (lo + hi))
    res = np.empty_like(t)
    pos = np.arange(t.size)
    for _ in range(200):
        mm = np.exp(t)
        f = _log_ratio(mm, lg, cc)
        up = f > 0
        lo = np.where(up, t, lo)
        hi = np.where(up, hi, t)
        mp1 = mm + 1.0
        df = 1.0 - 2.0 * mm / mp1 - cc * (2.0 * mm + 1.0) / (mm * mp1 * mp1)
        step = f / np.where(df < 0, df, -1.0)
        tn = t - step
        bad = ~((tn > lo) & (tn < hi)) | ~(df < 0)
        conv = ((np.abs(step) < 1e-9) & (df < 0)) | (hi - lo < 1e-9)
        tn = np.where(bad & ~conv, 0.5 * (lo + hi), tn)
        if conv.any():
            res[pos[conv]] = tn[conv]
            keep = ~conv
            pos, t, lo, hi, lg, cc = pos[keep], tn[keep], lo[keep], hi[keep], lg[keep], cc[keep]
            if pos.size == 0:
                break
        else:
            t = tn
    if pos.size:
        res[pos] = t
    m[idx] = np.maximum(np.exp(res), 1.0)
    return m


def _prefix_counts(nodes_sorted_desc):
    """For counts sorted in descending order: n_active[j] = #{count > j}, j = 0..max−1."""
    jmax = int(nodes_sorted_desc[0]) if nodes_sorted_desc.size else 0
    return np.searchsorted(-nodes_sorted_desc, -np.arange(jmax), side="left")


def _sum_from_mode(mh, n_up, n_dn, lg, cc):
    """Σ_{m = mh − n_dn}^{mh + n_up} T_m / T_mh by the ratio recurrence in both directions.

    T_{m+1} = T_m·R(m), T_{m−1} = T_m/R(m−1), R(m) = g·m/(m+1)²·e^{c/(m(m+1))}: one exp
    per term; terms shrink monotonically away from the mode (log-concavity), so nothing
    overflows, and values below the float range underflow to 0 only deep in the provably
    negligible tails.  Points are sorted by count so the active set is always a prefix.
    """
    total = np.ones_like(lg)
    g = np.exp(np.minimum(lg, 700.0))
    for direction, count in ((1, n_up), (-1, n_dn)):
        order = np.argsort(-count, kind="stable")
        cnt = count[order]
        if cnt.size == 0 or cnt[0] <= 0:
            continue
        act = _prefix_counts(cnt)
        gs, cs = g[order], cc[order]
        m = mh[order].copy()
        term = np.ones_like(m)
        acc = np.zeros_like(m)
        with np.errstate(over="ignore", under="ignore", divide="ignore"):
            for j in range(act.size):
                a = act[j]
                mj = m[:a]
                if direction > 0:
                    nxt = mj + 1.0                  # R(m) with m = mj
                    r = mj * nxt
                    np.divide(cs[:a], r, out=r)
                    np.exp(r, out=r)
                    r *= mj
                    r /= nxt
                    r /= nxt
                    r *= gs[:a]
                    term[:a] *= r
                else:
                    nxt = mj - 1.0                  # R(m − 1)
                    r = nxt * mj
                    np.divide(cs[:a], r, out=r)
                    np.exp(r, out=r)
                    r *= nxt
                    r /= mj
                    r /= mj
                    r *= gs[:a]
                    term[:a] /= r
                m[:a] = nxt
                acc[:a] += term[:a]
        total[order] += acc
    return total


def _sum_strided(m_lo, step, nodes, g, lg, cc, ref):
    """Σ_{j<nodes} exp(φ(m_lo + j·step) − ref), every term from the closed form."""
    order = np.argsort(-nodes, kind="stable")
    act = _prefix_counts(nodes[order])
    m_lo, step, g, lg, cc, ref = (v[order] for v in (m_lo, step, g, lg, cc, ref))
    acc = np.zeros_like(lg)
    for j in range(act.size):
        a = act[j]
        m = m_lo[:a] + j * step[:a]
        acc[:a] += np.exp(_log_term(m, g[:a], lg[:a], cc[:a]) - ref[:a])
    out = np.empty_like(acc)
    out[order] = acc
    return out


def log_series(ln_g, c, tol: float = 1e-10, stride: bool = True, gamma: float = 1.5, k0: float | None = None,
               return_info: bool = False):
    """ln Σ_{m≥1} gᵐe^{−g}/(m!·m)·e^{−c/m} for arrays ln g (may be −inf: sum 0) and c ≥ 0.

    See the module docstring for the window, its rigorous tail bound (omitted part ≤ tol·sum)
    and the integer-stride summation of wide peaks (``stride=False``: every term of the
    window).  The stride is used only where the window lies clear of the series' start
    (m_lo ≥ 2, so both window ends are in the provably negligible tails).  With
    ``return_info`` also returns a dict of per-point arrays: ``m_lo``, ``m_hi`` (window,
    inclusive), ``step`` (stride), ``nodes`` (terms evaluated), ``mode``, ``tail`` (bound on the
    omitted part relative to the sum).
    """
    ln_g = np.asarray(ln_g, dtype=np.float64)
    c = np.broadcast_to(np.asarray(c, dtype=np.float64), ln_g.shape)
    shape = ln_g.shape
    ln_g = ln_g.ravel()
    c = np.ascontiguousarray(c).ravel()
    out = np.full(ln_g.shape, -np.inf)
    info = {k: np.zeros(ln_g.shape) for k in ("m_lo", "m_hi", "step", "nodes", "mode", "tail")}
    idx = np.nonzero(np.isfinite(ln_g) & np.isfinite(c))[0]
    if k0 is None:
        k0 = math.sqrt(2.0 * math.log(1.0 / tol))
    lg, cc = ln_g[idx], c[idx]
    g = np.exp(np.minimum(lg, 700.0))
    mstar = _mode(lg, cc)
    kappa = (mstar - 1.0) / (mstar * (mstar + 1.0)) + cc * (2 * mstar + 1) / (mstar * (mstar + 1.0)) ** 2
    s = 1.0 / np.sqrt(np.maximum(kappa, 0.5 / (mstar + 1.0)))
    mh = np.floor(mstar + 0.5)
    ref = _log_term(mh, g, lg, cc)
    # Window ends: the Gaussian guess mh ± (K·s + 2), pushed outwards until the log-term has
    # dropped by at least `drop` below the mode.  φ is concave (m ≥ 2), so the chord from the
    # mode through the guess lies above φ beyond it: extending along the chord is safe.
    drop = math.log(1.0 / tol) + np.log(2.0 + s)
    k_lo = np.full(idx.shape, float(k0))
    k_up = k_lo + 1.0                     # the upper tail is the heavier one (Poisson skew, e^{−c/m})
    for _round in range(12):
        if idx.size == 0:
            break
        m_lo = np.maximum(1.0, mh - np.ceil(k_lo * s) - 2.0)
        m_hi = mh + np.ceil(k_up * s) + 2.0
        with np.errstate(divide="ignore", invalid="ignore"):
            d_hi = _log_term(m_hi, g, lg, cc) - ref
            ext = np.where(d_hi > -drop, np.ceil((d_hi + drop) * (m_hi - mh) / np.maximum(-d_hi, 1e-3)), 0.0)
            m_hi = m_hi + np.minimum(ext, 4.0 * (m_hi - mh))
            d_lo = _log_term(m_lo, g, lg, cc) - ref
            ext = np.where((m_lo > 1.0) & (d_lo > -drop),
                           np.ceil((d_lo + drop) * (mh - m_lo) / np.maximum(-d_lo, 1e-3)), 0.0)
            m_lo = np.maximum(1.0, m_lo - np.minimum(ext, 4.0 * (mh - m_lo)))
        if stride:
            step = np.where(m_lo >= 2.0, np.maximum(1.0, np.floor(s / gamma)), 1.0)
        else:
            step = np.ones_like(s)
        unit = step == 1.0
        total = np.zeros_like(lg)
        if unit.any():
            u = np.nonzero(unit)[0]
            total[u] = _sum_from_mode(mh[u], m_hi[u] - mh[u], mh[u] - m_lo[u], lg[u], cc[u])
        if (~unit).any():
            v = np.nonzero(~unit)[0]
            # the lattice passes through the mode: m_lo ≡ mh (mod step)
            m_lo[v] = mh[v] - np.floor((mh[v] - m_lo[v]) / step[v]) * step[v]
            nodes_v = np.floor((m_hi[v] - m_lo[v]) / step[v]) + 1.0
            total[v] = step[v] * _sum_strided(m_lo[v], step[v], nodes_v, g[v], lg[v], cc[v], ref[v])
        nodes = np.floor((m_hi - m_lo) / step) + 1.0
        m_last = m_lo + (nodes - 1.0) * step
        # rigorous tail bounds (log-concavity): upper beyond m_last, lower below m_lo
        with np.errstate(over="ignore", under="ignore", invalid="ignore", divide="ignore"):
            r_up = np.exp(np.minimum(_log_ratio(m_last, lg, cc), 0.0))
            t_up = np.exp(_log_term(m_last, g, lg, cc) - ref) * r_up / np.maximum(1.0 - r_up, 1e-300)
            t_up = np.where(r_up < 1.0, t_up, np.inf)
            mlm = np.maximum(m_lo - 1.0, 1.0)
            r_lo = np.exp(np.minimum(-_log_ratio(mlm, lg, cc), 0.0))
            t_lo = np.exp(_log_term(m_lo, g, lg, cc) - ref) * r_lo / np.maximum(1.0 - r_lo, 1e-300)
            t_lo = np.where(m_lo > 1.0, np.where(r_lo < 1.0, t_lo, np.inf), 0.0)
            tail_up = t_up / total
            tail_lo = t_lo / total
        ok = ((tail_up + tail_lo) <= tol) | (_round == 11)
        okk = idx[ok]
        out[okk] = ref[ok] + np.log(total[ok])
        for key, val in (("m_lo", m_lo), ("m_hi", m_last), ("step", step), ("nodes", nodes),
                         ("mode", mstar), ("tail", tail_up + tail_lo)):
            info[key][okk] = val[ok]
        bad = ~ok
        k_up = np.where(tail_up > 0.5 * tol, k_up * 1.5, k_up)[bad]
        k_lo = np.where(tail_lo > 0.5 * tol, k_lo * 1.5, k_lo)[bad]
        idx, lg, cc, g, mstar, s, mh, ref = (v[bad] for v in (idx, lg, cc, g, mstar, s, mh, ref))
    out = out.reshape(shape)
    if return_info:
        return out, {k: v.reshape(shape) for k, v in info.items()}
    return out


# --------------------------------------------------------------------------------------------
# The material
# --------------------------------------------------------------------------------------------
_LAMBDA_REF_UM = 0.55
_FLUSH = 1e-280  # values below this are flushed to 0 (subnormal products lose precision)
_ALPHA_MIN, _ALPHA_MAX = 1e-4, 4.0
#: Largest probability of sampling the specular Dirac lobe when a directional-diffuse lobe exists.
P_SPEC_MAX = 0.9



def _beckmann_sample(u, alpha):
    """Half vectors (3, N) about +z with density D_B(h)·cosθ_h, Beckmann parameter α (N,)."""
    t2 = -alpha * alpha * np.log1p(-np.minimum(u[0], 1.0 - 1e-16))
    cos_h = 1.0 / np.sqrt(1.0 + t2)
    sin_h = np.sqrt(np.maximum(1.0 - cos_h * cos_h, 0.0))
    phi = 2.0 * np.pi * u[1]
    return np.stack((sin_h * np.cos(phi), sin_h * np.sin(phi), cos_h))


def _beckmann_pdf_h(cos_h, alpha):
    """D_B(h)·cosθ_h = exp(−tan²θ_h/α²)/(π α² cos³θ_h) (0 for cosθ_h ≤ 0)."""
    ok = cos_h > 1e-100
    c = np.where(ok, cos_h, 1.0)
    tan2 = np.maximum(1.0 - c * c, 0.0) / (c * c)
    with np.errstate(over="ignore", under="ignore"):
        val = np.exp(-tan2 / (alpha * alpha)) / (np.pi * alpha * alpha * c * c * c)
    return np.where(ok, val, 0.0)


class HTSG(BSDF):
    """HTSG polarising BRDF: directional-diffuse + specular Dirac + uniform diffuse (one-sided).

    Parameters
    ----------
    n, k : Spectrum or float
        Complex index η = n + iκ of the material (κ ≥ 0); relative index η / exterior_n.
    sigma0_um : float
        RMS surface height σ₀ in µm, ≥ 0 (σ₀ = 0: a smooth Fresnel mirror).
    tau_um : float
        Autocorrelation length τ in µm, > 0.
    albedo : Spectrum or float
        Uniform diffuse albedo a (BRDF a/π, a depolariser), in [0, 1]; default 0.
    exterior_n : float
        Index of the incident medium (> 0); λ in the medium is λ_vacuum/exterior_n.
    series_tolerance : float
        Relative bound on the omitted tail of the series, in (0, 1e-2].
    """

    name = "htsg"

    def __init__(self, n, k, sigma0_um, tau_um, albedo=0.0, exterior_n=1.0, series_tolerance=1e-10):
        self.n = as_spectrum(n, "n")
        self.k = as_spectrum(k, "k")
        # σ₀ and τ may be TexturedNumbers (values per surface point, through ShadingPoint.number)
        s0, tau = (v if isinstance(v, TexturedNumber) else float(v) for v in (sigma0_um, tau_um))
        ext, tol = float(exterior_n), float(series_tolerance)
        s0_lo, tau_lo = (v.lo if isinstance(v, TexturedNumber) else v for v in (s0, tau))
        if not (math.isfinite(s0_lo) and s0_lo >= 0.0):
            raise ValueError(f"sigma0_um must be a finite number ≥ 0, got {sigma0_um!r}")
        if not (math.isfinite(tau_lo) and tau_lo > 0.0):
            raise ValueError(f"tau_um must be a finite number > 0, got {tau_um!r}")
        if not (math.isfinite(ext) and ext > 0.0):
            raise ValueError(f"exterior_n must be a finite number > 0, got {exterior_n!r}")
        if not (0.0 < tol <= 1e-2):
            raise ValueError(f"series_tolerance must be in (0, 0.01], got {series_tolerance!r}")
        self.sigma0 = s0
        self.tau = tau
        self.exterior_n = ext
        self.series_tolerance = tol
        if isinstance(albedo, Spectrum):
            self.albedo = albedo
        else:
            a = float(albedo)
            if not (math.isfinite(a) and 0.0 <= a <= 1.0):
                raise ValueError(f"albedo must be in [0, 1], got {albedo!r}")
            self.albedo = None if a == 0.0 else ConstantSpectrum(a)
        if isinstance(self.n, ConstantSpectrum) and not self.n.value > 0:
            raise ValueError(f"n must be > 0, got {self.n.value!r}")
        if isinstance(self.k, ConstantSpectrum) and not self.k.value >= 0:
            raise ValueError(f"k must be ≥ 0, got {self.k.value!r}")
        self.varies_over_surface = textured(self.n, self.k, self.sigma0, self.tau, self.albedo)
        # Directional-diffuse (glossy) and specular (Dirac) lobes at any σ₀ (σ₀ = 0 zeroes the first,
        # a rough surface the second); the uniform diffuse term, if any, is folded into the "general"
        # value (not separable).  RETARDING is conservative (not derived from n, κ); the roughness in
        # wavelengths, σ₀/λ, makes the model λ-dependent.
        self.flags = (BSDFFlags.GLOSSY_REFLECTION | BSDFFlags.DELTA_REFLECTION
                      | BSDFFlags.when(self.albedo is not None, BSDFFlags.DIFFUSE_REFLECTION)
                      | BSDFFlags.POLARISING | BSDFFlags.RETARDING | BSDFFlags.WAVELENGTH_DEPENDENT)

    # ---------------------------------------------------------------- helpers
    def relative_eta(self, sp: ShadingPoint) -> np.ndarray:
        return (sp.spectrum(self.n) + 1j * sp.spectrum(self.k)) / self.exterior_n

    def _lambda_um(self, sp: ShadingPoint) -> np.ndarray:
        return sp.lam * (1e-3 / self.exterior_n)

    def _roughness(self, sp: ShadingPoint):
        """(σ₀, τ) in µm at the points: floats, or arrays (N,) where textured."""
        return sp.number(self.sigma0), sp.number(self.tau)

    def _angles(self, n_s, w, s0, tau):
        """(cosθ, sinθ, μ, erfc μ, S(θ), K′) of direction w about n_s for roughness (σ₀, τ); arrays (N,)."""
        cos_t = dot(n_s, w)
        cr = cross(n_s, w)
        sin_t = np.sqrt(dot(cr, cr))
        mu = _mu(np.maximum(cos_t, 0.0), sin_t, s0, tau)
        ec = np.where(np.isfinite(mu), erfc(np.where(np.isfinite(mu), mu, 30.0)), 0.0)
        S = shadowing(mu, ec)
        kp = _k_prime(np.maximum(cos_t, 0.0), sin_t, ec)
        return cos_t, sin_t, mu, ec, S, kp

    @staticmethod
    def _sigma_eff(kp_i, kp_r, s0):
        """Effective roughness σ = σ₀/√(1 + x²), x·e^{x²/2} = (K′_i + K′_r)/√(8π) (Eqs. 4.4–4.6)."""
        if np.isscalar(s0) and s0 == 0.0:
            return np.zeros_like(kp_i)
        x = roughness_ratio((kp_i + kp_r) / _SQRT_8PI)
        return s0 / np.sqrt(1.0 + x * x)

    def _dd_parts(self, sp: ShadingPoint, wi: np.ndarray, info: bool = False):
        """Scalar factor Q = S·G·D/(π cos_i cos_r) (L, N), cosθ_h (N,), frame s, validity, extras."""
        wo = sp.wo
        n_s = sp.n_s
        s0, tau = self._roughness(sp)
        cos_i, _, _, _, S_i, kp_i = self._angles(n_s, wi, s0, tau)
        cos_r, _, _, _, S_r, kp_r = self._angles(n_s, wo, s0, tau)
        valid = (cos_i > 0) & (cos_r > 0)
        v = wi + wo
        v_z = cos_i + cos_r
        v2 = dot(v, v)
        vt = v - v_z[None, :] * n_s
        vxy2 = np.maximum(dot(vt, vt), 0.0)
        cos_h = np.clip(0.5 * np.sqrt(v2), 0.0, 1.0)
        sigma = self._sigma_eff(kp_i, kp_r, s0)
        lam = self._lambda_um(sp)                       # (L, N)
        k = 2.0 * np.pi / lam                           # wavenumber in the medium, 1/µm
        vz_safe = np.where(valid, v_z, 1.0)
        with np.errstate(divide="ignore"):
            ln_g = 2.0 * (np.log(k * sigma[None, :]) + np.log(vz_safe)[None, :])
        ln_g = np.where(valid[None, :], ln_g, -np.inf)
        c = k * k * (vxy2 * (0.25 * tau * tau))[None, :]
        res = log_series(ln_g, c, self.series_tolerance, return_info=info)
        ln_sum, sinfo = res if info else (res, None)
        # D/π = π τ²/(4λ²)·Σ ; G = (|v|²/v_z)² ; Q = S_i/cos_i · S_r/cos_r · G · D/π
        ln_q = ln_sum + np.log(np.pi * tau * tau / 4.0) - 2.0 * np.log(lam) \
            + 2.0 * (np.log(np.where(valid, v2, 1.0)) - np.log(vz_safe))[None, :]
        with np.errstate(over="ignore", under="ignore"):
            q = np.exp(ln_q)
        ci = np.where(valid, cos_i, 1.0)
        cr = np.where(valid, cos_r, 1.0)
        q = q * np.where(valid, (S_i / ci) * (S_r / cr), 0.0)[None, :]
        # flush results below 1e-280 /sr to 0: products with the O(1) Fresnel terms would be
        # subnormal, whose lost precision breaks A² ≥ B² + C² + S² (realisability)
        q = np.where(np.isfinite(q) & (q >= _FLUSH), q, 0.0)
        s_axis = scattering_plane_axis(-wi, wo)
        extra = None
        if info:
            g = np.exp(ln_g)
            extra = dict(sigma_eff_um=sigma, g=g, c=c, S=S_i * S_r, S_i=S_i, S_r=S_r,
                         G_geom=np.where(valid, (v2 / vz_safe) ** 2, 0.0),
                         D=np.exp(ln_sum + np.log(np.pi ** 2 * tau ** 2 / 4.0) - 2.0 * np.log(lam)),
                         ln_series=ln_sum, cos_theta_h=cos_h, series=sinfo, valid=valid,
                         v_xy2=vxy2)
        return q, cos_h, s_axis, valid, extra

    def _specular_scale(self, sp: ShadingPoint, cos_t, S_t, kp_t):
        """e^{−g(θ,θ)}·S(θ)² (L, N) and g(θ,θ) for the mirror geometry of a direction at θ."""
        valid = cos_t > 0
        sigma = self._sigma_eff(kp_t, kp_t, self._roughness(sp)[0])
        lam = self._lambda_um(sp)
        g = (2.0 * np.pi / lam * sigma[None, :] * (2.0 * np.maximum(cos_t, 0.0))[None, :]) ** 2
        scale = np.exp(-g) * np.where(valid, S_t * S_t, 0.0)[None, :]
        scale = np.where(scale >= _FLUSH, scale, 0.0)  # see _dd_parts
        return scale, g, sigma

    # ---------------------------------------------------------------- public interface
    def eval(self, sp: ShadingPoint, wi: np.ndarray) -> MuellerValue:
        q, cos_h, s_axis, valid, _ = self._dd_parts(sp, wi)
        A, B, C, S = fresnel_reflection_abcs(cos_h[None, :], self.relative_eta(sp))
        A, B, C, S = A * q, B * q, C * q, S * q
        if self.albedo is None:
            return MuellerValue("abcs", s_axis, s_axis, A, B, C, S)
        ud = sp.spectrum(self.albedo) * (valid / np.pi)[None, :]
        M = abcs_matrix(A, B, C, S) + depolariser(ud)
        return MuellerValue("general", s_axis, s_axis, M=M)

    def delta_reflection(self, sp: ShadingPoint) -> MuellerValue:
        _, value, _ = mirror_reflection(sp, self.relative_eta(sp))
        cos_o, _, _, _, S_o, kp_o = self._angles(sp.n_s, sp.wo, *self._roughness(sp))
        scale, _, _ = self._specular_scale(sp, cos_o, S_o, kp_o)
        return value.scaled(scale)

    def intermediates(self, sp: ShadingPoint, wi: np.ndarray) -> dict:
        """Per-point quantities of the dd term (and of the specular term at θ_i), for tests/logs.

        sigma_eff_um (N,), g (L,N), S = S_i·S_r (N,), G_geom (N,), D (L,N), F_unpol_half (L,N),
        cos_theta_h (N,), rho_dd (L,N), series (dict of window arrays, see ``log_series``),
        rho_s (L,N), rho_s_S = S(θ_i)² (N,), rho_s_g (L,N), rho_s_sigma_eff_um (N,).
        """
        q, cos_h, _, valid, ex = self._dd_parts(sp, wi, info=True)
        eta = self.relative_eta(sp)
        A = fresnel_reflection_abcs(cos_h[None, :], eta)[0]
        cos_i, _, _, _, S_i, kp_i = self._angles(sp.n_s, wi, *self._roughness(sp))
        scale, g_s, sig_s = self._specular_scale(sp, cos_i, S_i, kp_i)
        F_i = fresnel_reflection_abcs(np.maximum(cos_i, 0.0)[None, :], eta)[0]
        ex.update(F_unpol_half=A, rho_dd=A * q, rho_s=F_i * scale, rho_s_S=np.where(cos_i > 0, S_i * S_i, 0.0),
                  rho_s_g=g_s, rho_s_sigma_eff_um=sig_s)
        return ex

    # ---------------------------------------------------------------- sampling
    def _lobe_plan(self, sp: ShadingPoint):
        """λ-independent sampling plan per point: P_spec, mixture weights, Beckmann widths."""
        s0, tau = self._roughness(sp)
        cos_o, _, _, _, S_o, kp_o = self._angles(sp.n_s, sp.wo, s0, tau)
        valid = cos_o > 0
        scale, g_s, _ = self._specular_scale(sp, cos_o, S_o, kp_o)
        F = fresnel_reflection_abcs(np.maximum(cos_o, 0.0)[None, :], self.relative_eta(sp))[0]
        ss = np.where(valid, S_o * S_o, 0.0)[None, :]
        rho_s = np.mean(F * scale, axis=0)
        rho_dd = np.mean(F * ss * -np.expm1(-g_s), axis=0)
        ud = np.mean(sp.spectrum(self.albedo), axis=0) * valid if self.albedo is not None else np.zeros(sp.n)
        den = rho_s + rho_dd + ud
        p_spec = np.where(den > 0, rho_s / np.where(den > 0, den, 1.0), 0.0)
        if not np.isscalar(s0):       # textured σ₀: the cap below where σ₀ > 0
            p_spec = np.where(s0 > 0, np.minimum(p_spec, P_SPEC_MAX), p_spec)
        elif s0 > 0:
            # The dd estimate F·S²·(1 − e^{−g(θ_o)}) vanishes at grazing views although the lobe does
            # not (other directions have larger g): keep ≥ 10 % of the samples for it, or the rare dd
            # samples carry weights of several hundred (fireflies).
            p_spec = np.minimum(p_spec, P_SPEC_MAX)
        rest = rho_dd + ud
        w_c = 0.1 + 0.9 * np.where(rest > 0, ud / np.where(rest > 0, rest, 1.0), 0.0)
        co = np.maximum(cos_o, 1e-6)
        g_ref = (4.0 * np.pi * s0 * co / _LAMBDA_REF_UM) ** 2
        w_b = (1.0 - w_c) * g_ref / (1.0 + g_ref)
        w_d = (1.0 - w_c) - w_b
        a_b = np.broadcast_to(np.clip(2.0 * s0 / tau, _ALPHA_MIN, _ALPHA_MAX), (sp.n,)).copy()
        a_d = np.clip(_LAMBDA_REF_UM / (2.0 * np.pi * tau * co), _ALPHA_MIN, _ALPHA_MAX)
        return dict(p_spec=p_spec, rho_s=rho_s, den=den, w_c=w_c, w_b=w_b, w_d=w_d, a_b=a_b, a_d=a_d,
                    valid=valid)

    def _proposal_pdf(self, sp, wi, plan):
        cos_i = dot(sp.n_s, wi)
        cos_o = dot(sp.n_s, sp.wo)
        ok = (cos_i > 0) & (cos_o > 0)
        h = normalize(wi + sp.wo)
        cos_h = dot(sp.n_s, h)
        wo_h = dot(sp.wo, h)
        jac = np.where(wo_h > 0, 1.0 / (4.0 * np.where(wo_h > 0, wo_h, 1.0)), 0.0)
        p = plan["w_c"] * np.maximum(cos_i, 0.0) / np.pi
        p = p + (plan["w_b"] * _beckmann_pdf_h(cos_h, plan["a_b"])
                 + plan["w_d"] * _beckmann_pdf_h(cos_h, plan["a_d"])) * jac
        return np.where(ok, p, 0.0)

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        plan = self._lobe_plan(sp)
        return (1.0 - plan["p_spec"]) * self._proposal_pdf(sp, wi, plan)

    def sample(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        plan = self._lobe_plan(sp)
        p_spec = plan["p_spec"]
        n = sp.n
        is_delta = u_lobe < p_spec
        # remap u_lobe for the mixture choice
        u2 = np.where(is_delta, 0.0, (u_lobe - p_spec) / np.where(p_spec < 1.0, 1.0 - p_spec, 1.0))
        use_c = u2 < plan["w_c"]
        use_b = ~use_c & (u2 < plan["w_c"] + plan["w_b"])
        alpha = np.where(use_b, plan["a_b"], plan["a_d"])
        h_loc = _beckmann_sample(u_dir, alpha)
        h = local_to_world(h_loc, sp.n_s)
        wi_b = reflect(sp.wo, h)
        wi_c = local_to_world(cosine_hemisphere(u_dir), sp.n_s)
        wi = np.where(use_c[None, :], wi_c, wi_b)
        wi_mirror = reflect(sp.wo, sp.n_s)
        wi = np.where(is_delta[None, :], wi_mirror, wi)
        wi = normalize(wi)

        cos_i = dot(sp.n_s, wi)
        pdf = (1.0 - p_spec) * self._proposal_pdf(sp, wi, plan)
        nd_valid = plan["valid"] & ~is_delta & (cos_i > 0) & (pdf > 1e-300) & (use_c | (dot(sp.wo, h) > 0))
        pdf = np.where(nd_valid, pdf, 0.0)

        # evaluate the BRDF only where it is needed (a below-horizon wi costs nothing in eval)
        f = self.eval(sp, np.where(nd_valid[None, :], wi, -sp.n_s)) if not nd_valid.all() else self.eval(sp, wi)
        w_nd = np.where(nd_valid, cos_i / np.where(nd_valid, pdf, 1.0), 0.0)
        weight_nd = f.scaled(w_nd[None, :])
        if not is_delta.any():
            weight = weight_nd
        else:
            # weight / P_spec = (weight / ρ̄_s)·(ρ̄_s + ρ̄_dd + ū): finite even for subnormal P_spec
            d = self.delta_reflection(sp)
            rs = plan["rho_s"]
            rs_safe = np.where(is_delta & (rs > 0), rs, np.inf)[None, :]
            d = MuellerValue("abcs", d.x_in, d.x_out, d.A / rs_safe, d.B / rs_safe, d.C / rs_safe, d.S / rs_safe)
            inv_p = np.where(is_delta, plan["den"], 0.0)[None, :]
            d_axis = d.x_in
            x_axis = np.where(is_delta[None, :], d_axis, f.x_in)
            sel = is_delta[None, :]
            if f.kind == "abcs":
                pick = lambda a, b: np.where(sel, a * inv_p, b)  # noqa: E731
                weight = MuellerValue("abcs", x_axis, x_axis, pick(d.A, weight_nd.A), pick(d.B, weight_nd.B),
                                      pick(d.C, weight_nd.C), pick(d.S, weight_nd.S))
            else:
                Md = d.matrix() * inv_p
                weight = MuellerValue("general", x_axis, x_axis, M=np.where(sel, Md, weight_nd.M))
        valid = nd_valid | (is_delta & plan["valid"])
        return BSDFSample(wi=wi, weight=weight, pdf=pdf, is_delta=is_delta, valid=valid, eta_sq=np.ones(n))

    # ---------------------------------------------------------------- diagnostics
    def directional_albedo(self, theta_i_deg: float, wavelength_nm: float, n_theta: int = 384, n_phi: int = 256):
        """(∫ M00 cosθ_o dω_o over the non-delta part, ρ_s) for one incidence angle and wavelength.

        Quadrature over the half vector h: dω_o = 4(ω_i·h) dω_h, tanθ_h = α·t/(1−t) with
        Gauss–Legendre nodes t ∈ (0, 1) and the trapezoid rule in φ_h (periodic).
        """
        ti = math.radians(theta_i_deg)
        wi = np.array([-math.sin(ti), 0.0, math.cos(ti)])
        lam_um = float(wavelength_nm) * 1e-3 / self.exterior_n
        alpha_diff = lam_um / (2.0 * np.pi * self.tau * max(math.cos(ti), 1e-3))
        alpha = max(min(max(2.0 * self.sigma0 / self.tau, alpha_diff), 1.0), 0.02)
        t, wt = np.polynomial.legendre.leggauss(n_theta)
        t = 0.5 * (t + 1.0)
        wt = 0.5 * wt
        tan_h = alpha * t / (1.0 - t)
        dtan = alpha / (1.0 - t) ** 2
        th = np.arctan(tan_h)
        dth = dtan / (1.0 + tan_h ** 2)
        ph = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
        TH, PH = np.meshgrid(th, ph, indexing="ij")
        W = (wt * dth)[:, None] * (2.0 * np.pi / n_phi) * np.sin(TH)
        h = np.stack((np.sin(TH) * np.cos(PH), np.sin(TH) * np.sin(PH), np.cos(TH))).reshape(3, -1)
        wih = dot(h, wi[:, None])
        wo = 2.0 * wih * h - wi[:, None]
        N = wo.shape[1]
        z = np.zeros((3, N))
        z[2] = 1.0
        sp = ShadingPoint(np.zeros((3, N)), z, z, wo, np.full((1, N), float(wavelength_nm)), False)
        m00 = self.eval(sp, np.repeat(wi[:, None], N, axis=1)).matrix()[0, 0, 0]
        integrand = m00 * np.maximum(wo[2], 0.0) * 4.0 * np.maximum(wih, 0.0)
        dd = float(np.sum(integrand * W.ravel()))
        sp1 = ShadingPoint(np.zeros((3, 1)), z[:, :1], z[:, :1], np.array([[-wi[0]], [-wi[1]], [wi[2]]]),
                           np.full((1, 1), float(wavelength_nm)), False)
        rho_s = float(self.delta_reflection(sp1).A[0, 0])
        return dd, rho_s

    def describe(self) -> dict:
        def shown(v):
            return repr(v) if isinstance(v, TexturedNumber) else v
        return {"type": self.name, "n": repr(self.n), "k": repr(self.k), "sigma0_um": shown(self.sigma0),
                "tau_um": shown(self.tau), "albedo": repr(self.albedo) if self.albedo is not None else 0.0,
                "exterior_n": self.exterior_n, "series_tolerance": self.series_tolerance}


# --------------------------------------------------------------------------- declaration

DECLARATION = ModelDeclaration(
    "htsg", "He–Torrance–Sillion–Greenberg",
    "Physically based rough surface (σ₀, τ in µm), wavelength dependent",
    [N.with_(socket=Socket("n", "FLOAT", 0.88, 0.01, 20.0, "Real part of the complex index")),
     K.with_(socket=Socket("k", "FLOAT", 6.15, 0.0, 50.0, "Extinction coefficient κ ≥ 0")),
     METAL,
     Parameter("sigma0_um", "rms surface height σ₀", unit="µm", lo=0.0, hi=1e4, texturable=True,
               socket=Socket("Sigma0", "FLOAT", 0.18, 0.0, 100.0, "Surface height rms deviation σ₀ in µm")),
     Parameter("tau_um", "autocorrelation length τ", unit="µm", lo=0.0, lo_open=True, hi=1e6, texturable=True,
               socket=Socket("Tau", "FLOAT", 3.0, 1e-3, 1000.0, "Autocorrelation length τ in µm")),
     Parameter("albedo", "albedo of the uniform diffuse (depolarising) term", kind="spectrum",
               spectrum="reflectance", lo=0.0, hi=1.0, default=0.0, texturable=True,
               socket=Socket("Diffuse", "COLOR", (0.0, 0.0, 0.0), 0.0, 1.0, "Albedo of the uniform diffuse term")),
     exterior_n_parameter()],
    catalogue="htsg", node="HTSG")


DECLARATION.per_point = frozenset({"n", "k", "sigma0_um", "tau_um", "albedo"})


@DECLARATION.builder
def _htsg(p):
    n, k = complex_index(p)
    return HTSG(n, k, p["sigma0_um"], p["tau_um"], albedo=p["albedo"], exterior_n=p["exterior_n"])
