"""Directional albedos of single-scattering GGX lobes, for multiple-scattering energy compensation.

A microfacet lobe that scatters once loses the light that bounces between facets more than once:
at GGX α = 1 a white (F = 1) conductor reflects only 0.31 of normally incident light, a clear glass
interface (n = 1.5) 0.89.
Cycles' "Multiscatter GGX" (the Principled BSDF's default; also the Glossy, Glass and Metallic BSDFs)
puts it back by *albedo scaling* (Kulla & Conty 2017, "Revisiting Physically Based Shading at
Imageworks", as Cycles implements it in kernel/closure/bsdf_microfacet.h,
``microfacet_ggx_preserve_energy``): the single-scattering lobe f_ss is multiplied by

    1 + F_ms·(1 − E(μ_o))/E(μ_o),        F_ms = F_ss·E_avg / (1 − F_ss·(1 − E_avg)),

where μ_o is the cosine of the *viewing* direction, E(μ_o) the lobe's directional albedo with F = 1
(or, for glass, with the dielectric's own Fresnel over reflection and refraction, and then
F_ss = 1), E_avg = ∫ 2μ E(μ) dμ its hemispherical average, and F_ss the conductor's average
Fresnel reflectance (engine.materials.torrance_sparrow: Cycles' F82-tint fit).  The scale is a
function of ω_o only (not reciprocal, as in Cycles).

This module computes those E by deterministic quadrature of *this engine's* single-scattering lobes
(GGX D; Smith shadowing separable, G1(ω_i)·G1(ω_o), as the rough dielectric's, or height-correlated,
1/(1 + Λ(ω_i) + Λ(ω_o)), Cycles' form and Torrance–Sparrow's default for GGX), so that the
compensated lobes integrate to what they should here (a white conductor or a clear glass to 1).

The integral is taken over the visible normals of ω_o (Heitz 2018): with a facet h drawn from
D_ωo(h) = G1(ω_o) max(0, ω_o·h) D(h)/cosθ_o, the single-scattering estimator f·cosθ_i/pdf is
F·W(ω_i) for reflection and (1 − F)·W(ω_t) for refraction (the energy, i.e. without the 1/η² of
radiance), W = G/G1(ω_o) = G1(ω_i) (separable) or (1 + Λ_o)/(1 + Λ_o + Λ_i) (height-correlated), so

    E(μ_o) = ∫_disk [ F(ω_o·h)·W(ω_r) + (1 − F(ω_o·h))·W(ω_t) ] dA/π,

where the unit disk is Heitz's projected-hemisphere parametrisation of the visible normals (uniform
on the disk = distributed as D_ωo), ω_r and ω_t are ω_o reflected and refracted at h, and each term
is 0 where that direction lies on the wrong side of the surface (F = 1 under total internal
reflection; F = 1 and no refraction for the conductor's table).  The integrand is continuous (W → 0
at the horizon), so a product rule converges: Gauss–Legendre in the disk radius (weight 2ρ), the
midpoint rule in its angle (periodic; the half disk, the integrand being even).  No peak needs
resolving at any α: the visible-normal map absorbs it.  With 96 × 96 nodes E is within 2·10⁻³ of a
384 × 384 rule everywhere (1.5·10⁻⁴ rms; the worst case: the kink of W at the horizon for small α
and the square-root onset of total internal reflection), and the height-correlated tables reproduce
Cycles' own ggx_E, ggx_Eavg and ggx_glass_E (ior > 1) at their nodes to 3·10⁻⁴ (its ggx_glass_inv_E,
for light inside the glass, is not the albedo of its kernel's BSDF below the critical angle:
docs/physics.md).

Tables (built once, stored by engine.materials.table_cache):

- ``conductor_tables()``: E(μ, α) of the reflection lobe with F = 1, on ``MU_NODES`` nodes in
  t = √μ and ``ROUGH_NODES`` nodes in r = √α ∈ [0, 1] (Cycles' roughness axis; r = 0 is the smooth
  limit E = 1), plus E_avg(α) by Gauss–Legendre in μ; interpolated bilinearly in (t, r)
  (``conductor_albedo``, ``conductor_average``).
- ``DielectricAlbedo(n_ratio, alpha)``: E(μ) of one rough dielectric interface (reflection +
  refraction, the unpolarised Fresnel of the material's own real index) seen from either side, on
  ``DIELECTRIC_MU_NODES`` nodes in √μ, linear in between.  A rough dielectric has one index and one
  roughness, so its table is 1-D and exact in both (Cycles interpolates a 16³ table over roughness,
  μ and the index).  A roughness that varies over the surface (``DielectricAlbedoRange``): those tables at
  the conductor table's nodes in r = √α spanning its range, bilinear in (√μ, √α).  An index that varies over the
  surface too (``DielectricAlbedoIndex``, Cycles' ggx_glass_E is a table over the index as well): those tables at
  the nodes ``INDEX_NODES`` of c = F0^¼ = √(|η − 1|/(η + 1)) spanning the index range (every 1/32, refined towards
  η = 1; η and 1/η share c, so one axis serves both sides), linear in c between them; an index range of one value
  (a texture of one value) is that index's own table, exactly.

E is clamped to [``E_FLOOR``, 1] where it is used, so every compensation factor is finite and the
added energy never negative.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .table_cache import cached_table
from ..kernels import twin
from ..kernels.ggx_energy import conductor_extra_loop, layer_albedo_loop
from ..polarisation.fresnel import fresnel_reflectance

#: Nodes of the conductor table in t = √μ and in r = √α ∈ [0, 1].
MU_NODES = 33
ROUGH_NODES = 33
#: Gauss–Legendre nodes in μ for E_avg.
AVG_NODES = 32
#: Nodes of a dielectric's table in t = √μ (per side).
DIELECTRIC_MU_NODES = 65
#: Nodes of the index axis of a per-point index, in c = F0^¼ ∈ [0, 1] (c = 0: η = 1): every 1/32, and halving
#: steps towards c = 0 down to 1/1024, where the grazing albedo turns fast (the Fresnel reflectance at cosθ rises
#: from 0 at η = 1 to ~0.2 by η − 1 ≈ cos²θ/2: c ≈ cosθ/2)
INDEX_NODES = np.concatenate(([0.0], 2.0 ** -np.arange(10, 5, -1), np.arange(1, 33) / 32.0))
#: Largest F0^½ of an index node (c → 1 is η → ∞; IOR 1000 has c = 0.9990).
_ROOT_F0_MAX = 0.999999
#: Quadrature over the visible-normal disk: Gauss–Legendre nodes in the radius, midpoint nodes in the
#: angle over the half disk (the integrand is even).
QUAD_RADIUS = 96
QUAD_ANGLE = 96
#: cosθ_o of the μ = 0 node (the grazing limit, taken just above the horizon).
MU_FLOOR = 1e-6
#: Smallest albedo a compensation divides by.
E_FLOOR = 0.05
#: Largest roughness α the tables cover (Cycles clamps GGX α to 1).
ALPHA_MAX = 1.0

_TABLE_VERSION = 1


@functools.lru_cache(maxsize=1)
def _disk_rule():
    """(p1, p2, w) (K,): nodes on the unit disk and weights summing to 1 (uniform measure)."""
    x, wx = np.polynomial.legendre.leggauss(QUAD_RADIUS)
    rho = 0.5 * (x + 1.0)
    w_rho = wx * rho                     # ∫₀¹ 2ρ g dρ: ½·2ρ·w
    # the integrand is even in p1 (the viewer lies in the xz plane): the half disk p1 > 0, weights doubled
    phi = math.pi * ((np.arange(QUAD_ANGLE) + 0.5) / QUAD_ANGLE - 0.5)
    R, P = np.meshgrid(rho, phi, indexing="ij")
    w = np.repeat(w_rho, QUAD_ANGLE) / QUAD_ANGLE
    return (R * np.cos(P)).ravel(), (R * np.sin(P)).ravel(), w


def _ggx_lambda(w, alpha):
    """Smith Λ = (√(1 + α² tan²θ) − 1)/2 of GGX for directions w (3, ...) of either hemisphere (|tanθ|),
    ∞ at the horizon."""
    xy2 = w[0] * w[0] + w[1] * w[1]
    z2 = w[2] * w[2]
    ok = z2 > 0
    x = alpha * alpha * np.where(ok, xy2 / np.where(ok, z2, 1.0), 0.0)
    return np.where(ok, 0.5 * x / (np.sqrt(1.0 + x) + 1.0), np.inf)


def _weight(w, lam_o, alpha, correlated: bool):
    """The single-scattering estimator's shadowing factor G/G1(ω_o) for the scattered direction w:
    G1(w) = 1/(1 + Λ(w)) (separable Smith), or (1 + Λ(ω_o))/(1 + Λ(ω_o) + Λ(w)) (height-correlated)."""
    lam = _ggx_lambda(w, alpha)
    return (1.0 + lam_o) / (1.0 + lam_o + lam) if correlated else 1.0 / (1.0 + lam)


def _visible_normals(mu, alpha):
    """(ω_o (3, M, 1), h (3, M, K), w (K,)): the disk rule's facet normals for viewers at cosines mu (M,) in
    the xz plane, roughness ``alpha`` (a number or (M,)); Heitz 2018's map from the disk to D_ωo."""
    p1, p2, w = _disk_rule()
    mu = np.clip(np.asarray(mu, np.float64), MU_FLOOR, 1.0)[:, None]
    a = np.broadcast_to(np.asarray(alpha, np.float64), mu.shape[:1])[:, None]
    sin_o = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    vx, vz = a * sin_o, mu                                   # stretched ω_o, then normalised
    norm = np.sqrt(vx * vx + vz * vz)
    vx, vz = vx / norm, vz / norm
    s = 0.5 * (1.0 + vz)
    q2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - p1 * p1, 0.0)) + s * p2
    pz = np.sqrt(np.maximum(1.0 - p1 * p1 - q2 * q2, 0.0))
    # basis (T1, T2, v) = ((0, 1, 0), (−v_z, 0, v_x), v)
    nx = -q2 * vz + pz * vx
    ny = np.broadcast_to(p1, nx.shape)
    nz = q2 * vx + pz * vz
    hx, hy, hz = a * nx, a * ny, np.maximum(nz, 0.0)
    inv = 1.0 / np.sqrt(hx * hx + hy * hy + hz * hz)
    h = np.stack((hx * inv, hy * inv, hz * inv))
    wo = np.stack((sin_o, np.zeros_like(mu), mu))
    return wo, h, w


def _reflection_batches(mu, alpha, correlated: bool):
    """Per batch of viewing cosines (rows ``sl`` of ``mu``, bounded memory): the disk rule's ω_o, facets h,
    weights w, α (M, 1), Λ(ω_o), ω_o·h and the reflection lobe's shadowing factor (0 below the horizon)."""
    step = max(1, 4096 // QUAD_RADIUS // QUAD_ANGLE)
    alpha = np.broadcast_to(np.asarray(alpha, np.float64), mu.shape)
    for i in range(0, mu.size, step):
        sl = slice(i, i + step)
        wo, h, w = _visible_normals(mu[sl], alpha[sl])
        a = alpha[sl][:, None]
        lam_o = _ggx_lambda(wo, a)
        d = np.maximum(np.sum(wo * h, axis=0), 0.0)              # ω_o·h ≥ 0 for visible normals
        wr = 2.0 * d * h - wo
        yield sl, wo, h, w, a, lam_o, d, np.where(wr[2] > 0, _weight(wr, lam_o, a, correlated), 0.0)


def ggx_albedo(mu, alpha, eta: float | None = None, correlated: bool = False,
               viewer_side_refraction: bool = False) -> np.ndarray:
    """E(μ) (M,) of the single-scattering GGX lobe at viewing cosines ``mu`` (M,), roughness ``alpha`` > 0
    (a number or (M,)): the reflection lobe with F = 1 (``eta`` None), or a dielectric interface of real
    relative index ``eta`` = n_far/n_viewer, reflection plus refraction with the unpolarised Fresnel
    reflectance (energy: no 1/η²).  Shadowing: separable Smith G1(ω_i)·G1(ω_o), or with ``correlated``
    the height-correlated 1/(1 + Λ(ω_i) + Λ(ω_o)) (Heitz 2014; Cycles' form).  ``viewer_side_refraction``:
    refracted directions that end on the viewer's side count too (no BSDF produces them; Cycles' table
    generator counts them, so its ``ggx_glass_inv_E`` is this with ``correlated``, docs/physics.md)."""
    mu = np.atleast_1d(np.asarray(mu, np.float64))
    out = np.empty(mu.size)
    for sl, wo, h, w, a, lam_o, d, refl in _reflection_batches(mu, alpha, correlated):
        if eta is None:
            out[sl] = refl @ w
            continue
        F = fresnel_reflectance(d, complex(eta))
        inv = 1.0 / eta
        cos_t2 = 1.0 - (1.0 - d * d) * inv * inv
        tir = cos_t2 <= 0.0
        cos_t = np.sqrt(np.maximum(cos_t2, 0.0))
        wt = -wo * inv + (d * inv - cos_t) * h
        refr = np.where(~tir & ((wt[2] < 0) | viewer_side_refraction), _weight(wt, lam_o, a, correlated), 0.0)
        F = np.where(tir, 1.0, F)
        out[sl] = (F * refl + (1.0 - F) * refr) @ w
    return out


def ggx_reflection_albedo(mu, alpha, eta: complex, correlated: bool = True) -> np.ndarray:
    """E_F(μ) (M,) of the single-scattering GGX *reflection* lobe with the unpolarised Fresnel reflectance
    of the relative index ``eta`` (complex: a conductor; real: a dielectric's specular layer) at viewing
    cosines ``mu`` (M,), roughness ``alpha`` (a number or (M,)): the directional albedo that Cycles'
    Principled layering subtracts from the layers below (its ggx_gen_schlick_ior_s table is this over
    the F = 1 albedo E).  The same disk rule as :func:`ggx_albedo`."""
    mu = np.atleast_1d(np.asarray(mu, np.float64))
    out = np.empty(mu.size)
    for sl, _, _, w, _, _, d, refl in _reflection_batches(mu, alpha, correlated):
        out[sl] = (fresnel_reflectance(d, complex(eta)) * refl) @ w
    return out


# --------------------------------------------------------------------------- the conductor's table

def _t_nodes(n: int) -> np.ndarray:
    return np.linspace(0.0, 1.0, n)


def _build_conductor(correlated: bool) -> np.ndarray:
    """(MU_NODES + 1, ROUGH_NODES): E at (t_i², r_j²), and E_avg(r_j²) in the last row."""
    t = _t_nodes(MU_NODES)
    r = np.linspace(0.0, 1.0, ROUGH_NODES)
    x, wx = np.polynomial.legendre.leggauss(AVG_NODES)
    mu_avg, w_avg = 0.5 * (x + 1.0), 0.5 * wx
    out = np.ones((MU_NODES + 1, ROUGH_NODES))
    for j in range(1, ROUGH_NODES):              # r = 0: the smooth limit, E = 1
        alpha = r[j] * r[j]
        out[:MU_NODES, j] = ggx_albedo(t * t, alpha, correlated=correlated)
        out[MU_NODES, j] = np.sum(w_avg * 2.0 * mu_avg * ggx_albedo(mu_avg, alpha, correlated=correlated))
    return np.clip(out, 0.0, 1.0)


@functools.lru_cache(maxsize=2)
def conductor_tables(correlated: bool = False) -> np.ndarray:
    """The conductor's E(μ, α) and E_avg(α) table (``_build_conductor``) for separable or height-correlated
    Smith shadowing, from the disk cache."""
    correlated = bool(correlated)
    table = cached_table("ggx_conductor_albedo",
                         (_TABLE_VERSION, correlated, MU_NODES, ROUGH_NODES, AVG_NODES, QUAD_RADIUS, QUAD_ANGLE,
                          MU_FLOOR),
                         (MU_NODES + 1, ROUGH_NODES), lambda: _build_conductor(correlated))
    table.setflags(write=False)
    return table


def _rough_coordinate(alpha):
    """(j, f): the r = √α cell and the fraction within it, α clipped to [0, ALPHA_MAX]."""
    x = np.sqrt(np.clip(np.asarray(alpha, np.float64), 0.0, ALPHA_MAX)) * (ROUGH_NODES - 1)
    j = np.minimum(x.astype(np.int64), ROUGH_NODES - 2)
    return j, x - j


def conductor_albedo(mu, alpha, correlated: bool = False) -> np.ndarray:
    """E(μ, α) of the F = 1 GGX reflection lobe, bilinear in (√μ, √α); μ (N,), α a number or (N,)."""
    return _bilinear(conductor_tables(correlated), mu, alpha)


def _bilinear(E: np.ndarray, mu, alpha) -> np.ndarray:
    """A (√μ, √α) table's rows 0 … MU_NODES − 1 read bilinearly at μ (N,) and α (a number or (N,))."""
    mu = np.asarray(mu, np.float64)
    x = np.sqrt(np.clip(mu, 0.0, 1.0)) * (MU_NODES - 1)
    i = np.minimum(x.astype(np.int64), MU_NODES - 2)
    fx = x - i
    j, fy = _rough_coordinate(np.broadcast_to(np.asarray(alpha, np.float64), mu.shape))
    return ((E[i, j] * (1.0 - fx) + E[i + 1, j] * fx) * (1.0 - fy)
            + (E[i, j + 1] * (1.0 - fx) + E[i + 1, j + 1] * fx) * fy)


def _build_schlick_moments() -> np.ndarray:
    """(2·MU_NODES, ROUGH_NODES): the height-correlated reflection lobe's E_S = ∫(1 − ω_o·h)⁵ W and
    E_B = ∫(ω_o·h)(1 − ω_o·h)⁶ W over the disk rule (the F = 1 lobe weighted by Schlick's and the F82 term's
    factors), at (t_i², r_j²); r = 0: the mirror, (1 − μ)⁵ and μ(1 − μ)⁶."""
    t = _t_nodes(MU_NODES)
    r = np.linspace(0.0, 1.0, ROUGH_NODES)
    mu = t * t
    out = np.empty((2 * MU_NODES, ROUGH_NODES))
    out[:MU_NODES, 0], out[MU_NODES:, 0] = (1.0 - mu) ** 5, mu * (1.0 - mu) ** 6
    for j in range(1, ROUGH_NODES):
        for sl, _, _, w, _, _, d, refl in _reflection_batches(np.maximum(mu, MU_FLOOR), r[j] * r[j], True):
            s = 1.0 - d
            out[:MU_NODES][sl, j] = (s ** 5 * refl) @ w
            out[MU_NODES:][sl, j] = (d * s ** 6 * refl) @ w
    return out


@functools.lru_cache(maxsize=1)
def _schlick_moment_tables() -> np.ndarray:
    table = cached_table("ggx_schlick_moments", (_TABLE_VERSION, MU_NODES, ROUGH_NODES, QUAD_RADIUS, QUAD_ANGLE,
                                                 MU_FLOOR), (2 * MU_NODES, ROUGH_NODES), _build_schlick_moments)
    table.setflags(write=False)
    return table


def schlick_moments(mu, alpha) -> tuple[np.ndarray, np.ndarray]:
    """(E_S, E_B) (N,) of the height-correlated GGX reflection lobe at μ (N,), α (a number or (N,)): its albedo
    with the Fresnel factors (1 − cosθ_h)⁵ and cosθ_h(1 − cosθ_h)⁶, so that a Schlick / F82-Tint reflectance
    F = F0 + (1 − F0)(1 − c)⁵ − b·c(1 − c)⁶ gives the albedo F0·E + (1 − F0)·E_S − b·E_B (E: conductor_albedo)."""
    table = _schlick_moment_tables()
    return _bilinear(table[:MU_NODES], mu, alpha), _bilinear(table[MU_NODES:], mu, alpha)


def conductor_average(alpha, correlated: bool = False) -> np.ndarray:
    """E_avg(α) = ∫ 2μ E(μ, α) dμ, linear in √α."""
    row = conductor_tables(correlated)[MU_NODES]
    j, f = _rough_coordinate(alpha)
    return row[j] * (1.0 - f) + row[j + 1] * f


def f82_average_fresnel(eta: np.ndarray) -> np.ndarray:
    """F_ss: Cycles' estimate of a conductor's average Fresnel reflectance ∫ 2μ F(μ) dμ
    (``fresnel_conductor_Fss``): the F82-tint model fitted to the exact unpolarised reflectance at
    normal incidence (F0) and at cosθ = 1/7 (≈ 82°, F82), whose average is analytic:
        b = 7·(F0 + (1 − F0)(6/7)⁵ − F82) / (6/7)⁶,   F_ss = F0 + (1 − F0)/21 − b/126,
    clipped to [0, 1].  ``eta``: the complex relative index (any shape)."""
    eta = np.asarray(eta, np.complex128)
    F0 = fresnel_reflectance(np.ones(eta.shape), eta)
    F82 = fresnel_reflectance(np.full(eta.shape, 1.0 / 7.0), eta)
    f = 6.0 / 7.0
    f5 = f ** 5
    b = (7.0 / (f5 * f)) * (F0 + (1.0 - F0) * f5 - F82)
    return np.clip(F0 + (1.0 - F0) / 21.0 - b / 126.0, 0.0, 1.0)


def average_fresnel(eta) -> np.ndarray:
    """Cycles' F_ss of a reflection lobe of relative index ``eta`` (complex, any shape): the F82-tint fit
    (:func:`f82_average_fresnel`, ``fresnel_conductor_Fss``) where κ ≠ 0, the dielectric fit
    (:func:`dielectric_average_fresnel`, ``fresnel_dielectric_Fss``: a Principled specular layer or coat) at κ = 0."""
    eta = np.asarray(eta, np.complex128)
    return np.where(eta.imag == 0.0, dielectric_average_fresnel(eta.real), f82_average_fresnel(eta))


def multiscatter_fresnel(Fss, E_avg):
    """F_ms = F_ss·E_avg/(1 − F_ss·(1 − E_avg)): the Fresnel factor of the light that scatters more than once
    among the facets (Kulla–Conty; Cycles' ``microfacet_ggx_preserve_energy``), from the lobe's average Fresnel F_ss
    and its white albedo's average E_avg (arrays broadcast)."""
    return Fss * E_avg / (1.0 - Fss * (1.0 - E_avg))


def conductor_extra_numpy(mu, alpha, eta, correlated: bool = False) -> np.ndarray:
    """The compensation's share k (L, N) ≥ 0 for a conductor: f = f_ss·(1 + k), so the added
    (depolarised) term is k·M00(f_ss):  k = F_ms·(1 − E)/E, F_ms = F_ss·E_avg/(1 − F_ss·(1 − E_avg)), F_ss of
    :func:`average_fresnel` (a real index: a dielectric layer, Cycles' dielectric fit).
    ``mu`` (N,) viewing cosines, ``alpha`` a number or (N,), ``eta`` (L, N) or (L, 1) complex;
    ``correlated``: the lobe's Smith shadowing is height-correlated (else separable)."""
    E = np.clip(conductor_albedo(mu, alpha, correlated), E_FLOOR, 1.0)
    E_avg = np.clip(conductor_average(alpha, correlated), E_FLOOR, 1.0)
    Fms = multiscatter_fresnel(average_fresnel(eta), E_avg)
    return Fms * ((1.0 - E) / E)


def conductor_extra_numba(mu, alpha, eta, correlated: bool = False) -> np.ndarray:
    """conductor_extra_numpy in one compiled loop (engine.kernels.ggx_energy), the same bits where the NumPy twin
    calls the compiled Fresnel; other shapes than (N,) cosines and (L, 1 or N) indices go to the NumPy twin."""
    mu = np.asarray(mu, np.float64)
    eta = np.asarray(eta, np.complex128)
    n = mu.shape[0] if mu.ndim == 1 else -1
    if n < 0 or eta.ndim != 2 or eta.shape[1] not in (1, n) or np.ndim(alpha) > 1:
        return conductor_extra_numpy(mu, alpha, eta, correlated)
    out = np.empty((eta.shape[0], n))
    alpha = np.ascontiguousarray(np.broadcast_to(np.asarray(alpha, np.float64), (n,)))
    conductor_extra_loop(np.ascontiguousarray(mu), alpha, np.ascontiguousarray(eta), conductor_tables(correlated),
                         MU_NODES, ROUGH_NODES, ALPHA_MAX, E_FLOOR, out)
    return out


#: k of the multiple-scattering compensation of a conductor (conductor_extra_numpy), compiled where available.
conductor_extra = twin(conductor_extra_loop and conductor_extra_numba, conductor_extra_numpy)


# --------------------------------------------------------------------------- a dielectric's table

class DielectricAlbedo:
    """E(μ) of one rough GGX dielectric interface (index ratio ``n_ratio`` = n/exterior_n, roughness α):
    row 0 seen from outside (η = n_ratio), row 1 from inside (η = 1/n_ratio); the compensation
    factor is 1/E (Cycles' glass: F_ss = 1, so F_ms = 1)."""

    def __init__(self, n_ratio: float, alpha: float, cycles_dense_side: bool = False):
        self.n_ratio, self.alpha = float(n_ratio), float(alpha)
        self.E = _dielectric_table(self.n_ratio, self.alpha, cycles_dense_side)

    def __call__(self, mu: np.ndarray, outside: np.ndarray) -> np.ndarray:
        """E (N,) at viewing cosines |μ| (N,) from outside (True) or inside (False)."""
        x = np.sqrt(np.clip(np.abs(np.asarray(mu, np.float64)), 0.0, 1.0)) * (DIELECTRIC_MU_NODES - 1)
        i = np.minimum(x.astype(np.int64), DIELECTRIC_MU_NODES - 2)
        f = x - i
        row = np.where(outside, 0, 1)
        return self.E[row, i] * (1.0 - f) + self.E[row, i + 1] * f

    def extra(self, mu: np.ndarray, outside: np.ndarray) -> np.ndarray:
        """k = 1/E − 1 ≥ 0 (N,): f = f_ss·(1 + k)."""
        return 1.0 / np.clip(self(mu, outside), E_FLOOR, 1.0) - 1.0


class DielectricAlbedoRange:
    """E(μ, α) of one rough GGX dielectric interface (index ratio ``n_ratio``) whose roughness varies over the
    surface within [α_lo, α_hi] (a textured α): the 1-D tables of :class:`DielectricAlbedo` at the nodes
    r_j = j/(ROUGH_NODES − 1) of r = √α that span the range (the conductor table's roughness axis; r = 0 is the
    smooth limit E = 1), bilinear in (√μ, √α)."""

    def __init__(self, n_ratio: float, alpha_lo: float, alpha_hi: float, cycles_dense_side: bool = False):
        self.n_ratio = float(n_ratio)
        last = ROUGH_NODES - 1
        lo = math.sqrt(min(max(float(alpha_lo), 0.0), ALPHA_MAX)) * last
        hi = math.sqrt(min(max(float(alpha_hi), 0.0), ALPHA_MAX)) * last
        j0 = min(int(math.floor(lo)), last - 1)
        j1 = max(int(math.ceil(hi)), j0 + 1)
        r = _t_nodes(ROUGH_NODES)
        self.first = j0
        self.E = np.stack([np.ones((2, DIELECTRIC_MU_NODES)) if j == 0 else
                           _dielectric_table(self.n_ratio, float(r[j] * r[j]), cycles_dense_side)
                           for j in range(j0, j1 + 1)], axis=-1)

    def __call__(self, mu: np.ndarray, outside: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """E (N,) at viewing cosines |μ| (N,) from outside (True) or inside (False), roughness α (N,)."""
        x = np.sqrt(np.clip(np.abs(np.asarray(mu, np.float64)), 0.0, 1.0)) * (DIELECTRIC_MU_NODES - 1)
        i = np.minimum(x.astype(np.int64), DIELECTRIC_MU_NODES - 2)
        f = x - i
        y = np.sqrt(np.clip(np.asarray(alpha, np.float64), 0.0, ALPHA_MAX)) * (ROUGH_NODES - 1) - self.first
        j = np.clip(np.floor(y).astype(np.int64), 0, self.E.shape[2] - 2)
        g = np.clip(y - j, 0.0, 1.0)
        row = np.where(outside, 0, 1)
        E = self.E
        return ((E[row, i, j] * (1.0 - f) + E[row, i + 1, j] * f) * (1.0 - g)
                + (E[row, i, j + 1] * (1.0 - f) + E[row, i + 1, j + 1] * f) * g)

    def extra(self, mu: np.ndarray, outside: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        """k = 1/E − 1 ≥ 0 (N,): f = f_ss·(1 + k)."""
        return 1.0 / np.clip(self(mu, outside, alpha), E_FLOOR, 1.0) - 1.0


def root_f0(eta):
    """c = F0^¼ = √(|η − 1|/(η + 1)) of a real relative index (any shape; the same for η and 1/η)."""
    return np.sqrt(np.abs((np.asarray(eta, np.float64) - 1.0) / (np.asarray(eta, np.float64) + 1.0)))


def _index_of(c: float, above: bool) -> float:
    """The index ≥ 1 (``above``) or ≤ 1 whose F0^¼ is c."""
    root = min(c * c, _ROOT_F0_MAX)
    eta = (1.0 + root) / (1.0 - root)
    return eta if above else 1.0 / eta


class DielectricAlbedoIndex:
    """E(μ[, α], η) of one rough GGX dielectric interface whose index ratio varies over the surface within
    [η_lo, η_hi] (all ≥ 1 or all ≤ 1), its roughness constant (``alpha`` a number) or within [α_lo, α_hi]
    (``alpha`` a (lo, hi) pair): :class:`DielectricAlbedo` (or :class:`DielectricAlbedoRange`) at the index nodes
    ``INDEX_NODES`` of c = F0^¼ spanning the range, linear in c between them; for η_lo = η_hi that index's own
    table (the constant lobe's compensation, bit for bit)."""

    def __init__(self, eta_lo: float, eta_hi: float, alpha, cycles_dense_side: bool = False):
        if not (eta_lo > 0 and eta_hi >= eta_lo and (eta_lo >= 1.0 or eta_hi <= 1.0)):
            raise ValueError(f"a per-point index range must lie on one side of 1, got [{eta_lo:g}, {eta_hi:g}]")
        above = eta_lo >= 1.0
        self.per_point_alpha = isinstance(alpha, tuple)

        def table(eta):
            if self.per_point_alpha:
                return DielectricAlbedoRange(eta, *alpha, cycles_dense_side)
            return DielectricAlbedo(eta, alpha, cycles_dense_side)
        if eta_lo == eta_hi:
            self.nodes, self.tables = None, [table(float(eta_lo))]
            return
        last = INDEX_NODES.size - 1
        c_lo, c_hi = sorted(float(root_f0(e)) for e in (eta_lo, eta_hi))
        j0 = min(int(np.searchsorted(INDEX_NODES, c_lo, "right")) - 1, last - 1)
        j1 = min(max(int(np.searchsorted(INDEX_NODES, c_hi, "left")), j0 + 1), last)
        self.nodes = INDEX_NODES[j0:j1 + 1]
        self.tables = [table(_index_of(float(c), above)) for c in self.nodes]

    def __call__(self, mu, outside, eta, alpha=None) -> np.ndarray:
        """E (N,) at viewing cosines |μ| (N,) from outside (True) or inside (False), the points' index ratio η (N,)
        (and roughness α (N,) for a per-point roughness)."""
        args = (alpha,) if self.per_point_alpha else ()
        if len(self.tables) == 1:
            return self.tables[0](mu, outside, *args)
        mu, outside = np.asarray(mu, np.float64), np.broadcast_to(outside, np.shape(mu))
        c = root_f0(eta)
        j = np.clip(np.searchsorted(self.nodes, c, "right") - 1, 0, len(self.tables) - 2)
        g = np.clip((c - self.nodes[j]) / (self.nodes[j + 1] - self.nodes[j]), 0.0, 1.0)
        E = np.empty(np.shape(mu))
        for k in np.unique(j):              # only the two tables each point lies between
            sel = np.nonzero(j == k)[0]
            sub = (alpha[sel],) if self.per_point_alpha else ()
            E[sel] = ((1.0 - g[sel]) * self.tables[k](mu[sel], outside[sel], *sub)
                      + g[sel] * self.tables[k + 1](mu[sel], outside[sel], *sub))
        return E

    def extra(self, mu, outside, eta, alpha=None) -> np.ndarray:
        """k = 1/E − 1 ≥ 0 (N,): f = f_ss·(1 + k)."""
        return 1.0 / np.clip(self(mu, outside, eta, alpha), E_FLOOR, 1.0) - 1.0


@functools.lru_cache(maxsize=64)
def _dielectric_table(n_ratio: float, alpha: float, cycles_dense_side: bool = False) -> np.ndarray:
    """E (2, DIELECTRIC_MU_NODES) at the nodes in √μ, seen from outside (η = ``n_ratio``) and inside (1/``n_ratio``).
    ``cycles_dense_side``: on the denser side (η < 1) E_own·E_counted/E_true, E_counted and E_true the
    height-correlated albedos with and without refracted directions that end on the viewer's side: compensated by
    1/E there, the interface returns E_true/E_counted, what Cycles' compensation from its ggx_glass_inv_E table
    returns (docs/physics.md, "Multiple-scattering compensation")."""
    def build():
        t = _t_nodes(DIELECTRIC_MU_NODES)
        rows = []
        for eta in (n_ratio, 1.0 / n_ratio):
            E = ggx_albedo(t * t, alpha, eta)
            if cycles_dense_side and eta < 1.0:
                true = ggx_albedo(t * t, alpha, eta, correlated=True)
                E = E * ggx_albedo(t * t, alpha, eta, correlated=True, viewer_side_refraction=True) / true
            rows.append(E)
        return np.clip(np.stack(rows), 0.0, 1.0)
    key = (_TABLE_VERSION, n_ratio, alpha, DIELECTRIC_MU_NODES, QUAD_RADIUS, QUAD_ANGLE, MU_FLOOR)
    table = cached_table("ggx_dielectric_albedo", key + (("cycles_dense_side",) if cycles_dense_side else ()),
                         (2, DIELECTRIC_MU_NODES), build)
    table.setflags(write=False)
    return table


# --------------------------------------------------------------------------- Cycles' layering estimate

#: Nodes per axis of Cycles' ``ggx_gen_schlick_ior_s`` table: r = √α, μ and z = F0^¼, each i/15 (clamped as Cycles).
SCHLICK_NODES = 16


def _schlick_s(mu, alpha, eta: float) -> np.ndarray:
    """s (M,) of Cycles' table at viewing cosines ``mu`` (M,), roughness ``alpha``, index ``eta`` ≥ 1: the mean over
    the visible normals of ω_o of (F(ω_o·h) − F0)/(1 − F0), 0 where the mirrored direction lies below the surface
    (Cycles' sampler rejects it; the table generator averages eval.x/eval.y of the accepted samples, 0 otherwise)."""
    mu = np.atleast_1d(np.asarray(mu, np.float64))
    F0 = ((eta - 1.0) / (eta + 1.0)) ** 2
    out = np.empty(mu.size)
    for sl, _, _, w, _, _, d, refl in _reflection_batches(mu, alpha, True):
        s = np.clip((fresnel_reflectance(d, complex(eta)) - F0) / (1.0 - F0), 0.0, 1.0)
        out[sl] = np.where(refl > 0, s, 0.0) @ w
    return out


def _build_schlick_table() -> np.ndarray:
    n = SCHLICK_NODES
    x = np.arange(n) / (n - 1.0)
    rough, mu = np.clip(x, 1e-4, 1.0), np.clip(x, 1e-4, 1.0)
    R, M = np.meshgrid(rough, mu, indexing="ij")
    table = np.empty((n, n, n))                                   # [z, r, μ]
    for k, z in enumerate(np.clip(x, 1e-4, 0.99)):
        root = math.sqrt(min(z ** 4, 0.99))                       # Cycles' ior_from_F0(z⁴)
        eta = (1.0 + root) / (1.0 - root)
        table[k] = _schlick_s(M.ravel(), (R * R).ravel(), eta).reshape(n, n)
    return table


@functools.lru_cache(maxsize=1)
def schlick_table() -> np.ndarray:
    """Cycles' ``ggx_gen_schlick_ior_s`` (16, 16, 16) over [z, r, μ] by this module's quadrature (not Monte Carlo)."""
    table = cached_table("ggx_gen_schlick_ior_s", (_TABLE_VERSION, SCHLICK_NODES, QUAD_RADIUS, QUAD_ANGLE),
                         (SCHLICK_NODES,) * 3, _build_schlick_table)
    table.setflags(write=False)
    return table


def _lerp_coordinate(x):
    """(index, next index, fraction) of Cycles' ``lookup_table_read`` on 16 nodes over [0, 1]."""
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0) * (SCHLICK_NODES - 1)
    i = np.minimum(x.astype(np.int64), SCHLICK_NODES - 1)
    return i, np.minimum(i + 1, SCHLICK_NODES - 1), x - i


def cycles_layering_albedo(mu, alpha, eta) -> np.ndarray:
    """Cycles' estimate (N,) of a dielectric GGX reflection layer's albedo (``bsdf_microfacet_estimate_albedo``,
    what ``closure_layering_weight`` subtracts from the layers below): F0 + (1 − F0)·s, s read from
    :func:`schlick_table` trilinearly at (√α, μ, √(|η − 1|/(η + 1))) as Cycles reads it — on its 16 nodes, so
    its interpolation error (up to a few 10⁻² at grazing) is Cycles' too.  ``mu`` (N,) viewing cosines (clipped
    to [0, 1]), ``alpha`` and ``eta`` (> 0, real) numbers or (N,).  Independent of multiple-scattering
    compensation, as Cycles' estimate is; for α = 0 the smooth Fresnel reflectance interpolated between nodes."""
    mu = np.asarray(mu, np.float64)
    eta = np.broadcast_to(np.asarray(eta, np.float64), mu.shape)
    t = schlick_table()
    iz, jz, fz = _lerp_coordinate(root_f0(eta))
    ir, jr, fr = _lerp_coordinate(np.sqrt(np.broadcast_to(np.asarray(alpha, np.float64), mu.shape)))
    im, jm, fm = _lerp_coordinate(mu)

    def plane(z):
        return ((1.0 - fm) * ((1.0 - fr) * t[z, ir, im] + fr * t[z, jr, im])
                + fm * ((1.0 - fr) * t[z, ir, jm] + fr * t[z, jr, jm]))
    s = (1.0 - fz) * plane(iz) + fz * plane(jz)
    F0 = ((eta - 1.0) / (eta + 1.0)) ** 2
    return F0 + (1.0 - F0) * s


def cycles_layer_weight_numpy(mu, alpha, eta, darken: bool) -> np.ndarray:
    """(N,) what a dielectric GGX layer takes from the layers below in Cycles: its estimate
    :func:`cycles_layering_albedo`, with ``darken`` (a compensated lobe) × :func:`cycles_layering_darkening`.
    ``mu`` (N,) viewing cosines, ``alpha`` and ``eta`` (> 0, real) numbers or (N,); NaN where any of them is NaN."""
    mu, alpha, eta = np.broadcast_arrays(np.asarray(mu, np.float64), alpha, eta)
    bad = np.isnan(mu) | np.isnan(alpha) | np.isnan(eta)
    if bad.any():                       # (a NaN would index the tables at INT_MIN)
        E = cycles_layer_weight_numpy(np.where(bad, 1.0, mu), np.where(bad, 0.5, alpha), np.where(bad, 1.5, eta),
                                      darken)
        return np.where(bad, np.nan, E)
    E = cycles_layering_albedo(mu, alpha, eta)
    return E * cycles_layering_darkening(mu, alpha, eta) if darken else E


def cycles_layer_weight_numba(mu, alpha, eta, darken: bool) -> np.ndarray:
    """cycles_layer_weight_numpy in one compiled loop (engine.kernels.ggx_energy), the same bits; other shapes than
    (N,) cosines and numbers or (N,) for α and η go to the NumPy twin."""
    mu = np.asarray(mu, np.float64)
    n = mu.shape[0] if mu.ndim == 1 else -1
    if n < 0 or any(np.ndim(v) > 1 or (np.ndim(v) == 1 and len(v) != n) for v in (alpha, eta)) \
            or np.iscomplexobj(eta):
        return cycles_layer_weight_numpy(mu, alpha, eta, darken)

    def full(v):
        return np.ascontiguousarray(v, np.float64) if np.ndim(v) == 1 else np.full(n, v, np.float64)
    out = np.empty(n)
    layer_albedo_loop(np.ascontiguousarray(mu), full(alpha), full(eta), schlick_table(), conductor_tables(True),
                      MU_NODES, ROUGH_NODES, ALPHA_MAX, E_FLOOR, bool(darken), out)
    return out


#: Cycles' layering weight of a dielectric GGX layer (cycles_layer_weight_numpy), compiled where available.
cycles_layer_weight = twin(layer_albedo_loop and cycles_layer_weight_numba, cycles_layer_weight_numpy)


def dielectric_average_fresnel(eta) -> np.ndarray:
    """Cycles' fit of a dielectric's average Fresnel reflectance ∫ 2μ F(μ) dμ (``fresnel_dielectric_Fss``) for a
    real relative index ``eta`` (any shape): (η − 1)/(4.08567 + 1.00071 η) above 1, a cubic below."""
    eta = np.asarray(eta, np.float64)
    below = 0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607))
    return np.where(eta < 1.0, below, (eta - 1.0) / (4.08567 + 1.00071 * eta))


def cycles_layering_darkening(mu, alpha, eta) -> np.ndarray:
    """E + F_ms·(1 − E) (N,): the factor by which Cycles' multiple-scattering compensation scales a dielectric GGX
    reflection closure's weight (``microfacet_ggx_preserve_energy``: ``darkening``·``energy_scale``⁻¹), which its
    layering albedo (``bsdf_albedo``: closure weight × estimate) carries; E the F = 1 albedo at ``mu`` (N,),
    F_ms from Cycles' dielectric F_ss (:func:`dielectric_average_fresnel`) of ``eta``; ``alpha`` a number or (N,)."""
    E = np.clip(conductor_albedo(mu, alpha, correlated=True), E_FLOOR, 1.0)
    E_avg = np.clip(conductor_average(alpha, correlated=True), E_FLOOR, 1.0)
    Fms = multiscatter_fresnel(dielectric_average_fresnel(eta), E_avg)
    return E + Fms * (1.0 - E)
