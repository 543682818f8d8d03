"""Anisotropic GGX polarising microfacet reflection (Blender's Principled *Anisotropic* / *Anisotropic Rotation*).

The lobe is GGX Torrance–Sparrow (engine.materials.torrance_sparrow with ``distribution="ggx"``,
``shadowing="smith_correlated"``) with two roughnesses, α_x along a surface tangent T and α_y along the
bitangent B = n_s × T:

    f(ω_i, ω_o) = M_F(ω_i·h) · D(h) · G(ω_i, ω_o) / (4 cosθ_i cosθ_o),     h = unit(ω_i + ω_o),

- D(h) = 1 / (π α_x α_y (h_x²/α_x² + h_y²/α_y² + h_z²)²) for h_z > 0 (h in the frame (T, B, n_s); a sum of
  positive squares: no cancellation at the peak, finite up to the horizon), ∫ D cosθ_h dω_h = 1;
- G = χ⁺(ω_i·h) χ⁺(ω_o·h) / (1 + Λ(ω_i) + Λ(ω_o)), the height-correlated Smith term (Heitz 2014; Cycles'
  G) with the anisotropic GGX Λ(ω) = (√(1 + a) − 1)/2, a = ((α_x ω_x)² + (α_y ω_y)²)/ω_z² (∞ at grazing);
- M_F the Fresnel Mueller matrix of the complex relative index η = (n + iκ)/exterior_n at the facet angle,
  returned as ``MuellerValue("abcs", s, s, A, B, C, S)`` in the scattering-plane frames s = unit(k_i × k_o)
  (docs/physics.md §1), exactly as Torrance–Sparrow's GGX lobe.  One-sided: 0 unless cosθ_i, cosθ_o > 0.
With α_x = α_y it is Torrance–Sparrow's GGX lobe (the frame is then irrelevant and not computed).

Cycles (kernel/svm/closure.h, Principled BSDF; kernel/closure/bsdf_microfacet.h), read for the facts:
α_x = r²/aspect, α_y = r²·aspect, aspect = √(1 − 0.9·Anisotropic) (``cycles_alphas``; both saturated to
≤ 1 by ``bsdf_microfacet_ggx_setup``), along the Tangent input rotated about N by Anisotropic Rotation·2π
(right-handed: a quarter turn takes T to N × T), for the metal and the dielectric's specular layer only
(transmission and coat stay isotropic); the local frame is Y = unit(N × T), X = Y × N
(``make_orthonormals_tangent``), the same D, Λ and G as above, and visible-normal sampling with the view
stretched by (α_x, α_y) (Heitz 2018).

Tangent frame (``tangent_frame``): an explicit ``tangent(sp) -> (3, N)`` if given, else the mesh's
(``sp.surface.tangent_frame(sp.n_s)``: per-vertex tangents, or ∂p/∂u from the UVs; engine.textures.surface);
where the shading points carry no surface attributes (``sp.surface`` None) or the mesh has neither, **any
frame perpendicular to n_s** (engine.vec3.local_frame) — the lobe is then anisotropic in an arbitrary but
deterministic direction.  That tangent is rotated about n_s by ``rotation`` turns and projected onto the
tangent plane; where it is parallel to n_s (or zero, or not finite) the arbitrary frame is used instead.

Multiple scattering (``multiscatter``): as Torrance–Sparrow's, a depolarised term k·M00 added to the
single-scattering lobe, k = F_ms(1 − E)/E, F_ms = F_ss·E_avg/(1 − F_ss(1 − E_avg)), F_ss Cycles' F82 fit of
the mean Fresnel reflectance (engine.materials.ggx_energy.conductor_extra).  Which E:

- ``multiscatter_albedo="cycles"`` (default): Cycles' — ``microfacet_ggx_preserve_energy`` reads its
  *isotropic* tables ggx_E, ggx_Eavg at rough = √√(α_x α_y), i.e. at the isotropic **α = √(α_x α_y)**
  (the geometric mean; for the Principled BSDF that is r² itself unless α_x was clipped at 1, so the
  Anisotropic input does not change the compensation).  The anisotropic lobe's own F = 1 albedo differs
  from that isotropic one, so a white furnace is not 1: measured with this module's quadrature, within
  1 % only for mild anisotropy away from grazing (r = 0.5, Anisotropic 0.2); r = 0.4, Anisotropic 1
  (α = 0.51, 0.05): 0.85 at normal view; where α_x is clipped (r = 0.6, Anisotropic 1): 0.63.  This is
  what Blender renders.
- ``multiscatter_albedo="lobe"``: E(ω_o) and E_avg of *this* anisotropic lobe (F = 1), tabulated per
  model over √cosθ_o (33 nodes) and the view's azimuth in the tangent frame (17 nodes, uniform in the
  square root of the projected roughness α_o = √((α_x ω_x)² + (α_y ω_y)²)/sinθ_o, on which E mostly
  depends: uniform nodes in the azimuth itself miss the fast change near the narrow axis, 2·10⁻² there
  at α ratio 10) by the visible-normal quadrature of engine.materials.ggx_energy extended to two
  roughnesses (64 × 128 nodes over the whole disk: ≤ 3·10⁻⁴ from a 4× finer rule), bilinear: from the
  direct quadrature ≤ 2.2·10⁻³ for cosθ_o ≥ 0.05 and ≤ 4·10⁻³ for cosθ_o ≥ 0.01 at α ratios up to 10⁴
  (closer to the horizon up to 9·10⁻³, and 3·10⁻² at α ~ 10⁻⁴, where E climbs steeply to its grazing
  limit, as in the isotropic tables); 1.5–3.5 s per model (kept by engine.materials.table_cache).  A
  white furnace then returns 1 within 10⁻² at every view and aspect ratio (measured: ≤ 6·10⁻³ up to
  θ_o = 89°, ≤ 10⁻³ below 85°, α ratios 1.8 … 10 either way).  Not Cycles.
Both need α_x, α_y ≤ 1 (Cycles' clamp; the tables' range).  Sampling is unchanged by the compensation.

Sampling: visible normals of the anisotropic GGX (Heitz 2018, the view stretched by (α_x, α_y)),
ω_i = reflect(ω_o, h); pdf(ω_i) = D(h)/(4 cosθ_o (1 + Λ(ω_o))), samples below the horizon are invalid
(their probability is lost); the weight is the (compensated) f·cosθ_i/pdf.

Thin film (``film_n``, ``film_thickness`` in nm; none at ≤ 0.1 nm, Cycles' cutoff): as Torrance–Sparrow's, Airy's
sum over a film on the substrate n + iκ (engine.polarisation.thin_film.film_reflection_abcs) replaces every
facet's bare Fresnel matrix (Cycles' Principled Thin Film on its metal and specular layers); the compensation
keeps the bare substrate's F_ss, and the layering albedo is Cycles' untabulated estimate (the film's
reflectance at the view angle, the largest over the RGB channels' wavelengths).

Helpers: ``multiscatter_extra(sp)`` (k, as Torrance–Sparrow's), ``reflection_albedo(sp)`` (the lobe's
directional albedo with its own Fresnel at ω_o, times 1 + k with ``multiscatter``: the layering albedo a
Principled specular layer subtracts from the diffuse base; Cycles' estimate at α = √(α_x α_y), or the
anisotropic table with ``multiscatter_albedo="lobe"``; a constant index, or a real one per point — a
NumberSpectrum, engine.textures.inputs — from torrance_sparrow.IndexAlbedoTables), ``tangent_frame(sp)``.
Vectorised NumPy throughout (no compiled kernel).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, MuellerValue, ShadingPoint
from .ggx import visible_normals
from .ggx_energy import (ALPHA_MAX, E_FLOOR, MU_FLOOR, conductor_extra, f82_average_fresnel,
                         multiscatter_fresnel)
from .microfacet import _chi_plus, half_vector, reflect_local
from .table_cache import cached_table
from .roughness import ALPHA_MIN, checked_alpha
from .torrance_sparrow import SpecularAlbedoTable
from ..polarisation.frames import scattering_plane_axis
from ..polarisation.fresnel import fresnel_reflectance, fresnel_reflection_abcs
from ..polarisation.thin_film import facet_film, film_at, film_label, film_reflection_abcs
from ..spectral.film_channels import film_layering_albedo, layering_wavelengths
from ..spectral import ConstantSpectrum, as_spectrum
from ..textures import TexturedNumber, textured
from ..vec3 import cross, dot, local_frame, to_local

__all__ = ["AnisotropicGGX", "MULTISCATTER_ALBEDOS", "anisotropic_albedo", "cycles_alphas", "ggx_aniso_D",
           "ggx_aniso_lambda", "ggx_aniso_sample"]

#: Where the compensation's E comes from (module docstring).
MULTISCATTER_ALBEDOS = ("cycles", "lobe")
#: Cycles' Anisotropic → aspect: aspect = √(1 − ASPECT_SLOPE·a).
ASPECT_SLOPE = 0.9
#: The per-model albedo table (``multiscatter_albedo="lobe"``): nodes in t = √cosθ_o and in the view's
#: azimuth, through its projected roughness (``_azimuth_coordinate``); Gauss–Legendre nodes in μ and in
#: the azimuth ψ ∈ [0, π/2] for E_avg.
LOBE_MU_NODES = 33
LOBE_AZIMUTH_NODES = 17
LOBE_AVG_MU_NODES = 32
LOBE_AVG_AZIMUTH_NODES = 12
#: The visible-normal disk rule of the anisotropic albedo: Gauss–Legendre nodes in the radius, midpoint
#: nodes in the angle over the *whole* disk (the integrand is not even for a general view azimuth).
QUAD_RADIUS = 64
QUAD_ANGLE = 128
#: |n_s × T| below this (relative to |T|): the tangent is taken as parallel to the normal.
_PARALLEL = 1e-12
_TABLE_VERSION = 2


def cycles_alphas(roughness: float, anisotropic: float) -> tuple[float, float]:
    """(α_x, α_y) of Cycles' Principled BSDF for Blender roughness r and Anisotropic a: r² / aspect and
    r²·aspect with aspect = √(1 − 0.9·a), r and a clipped to [0, 1], each α saturated to ≤ 1 (as Cycles'
    ``bsdf_microfacet_ggx_setup``).  Cycles applies this only where a > 0 and a tangent exists; the caller
    still keeps α ≥ roughness.ALPHA_MIN (or, effectively smooth, uses the smooth model)."""
    r = min(max(float(roughness), 0.0), 1.0)
    a = min(max(float(anisotropic), 0.0), 1.0)
    alpha = r * r
    if a <= 0.0:
        return alpha, alpha
    aspect = math.sqrt(1.0 - ASPECT_SLOPE * a)
    return min(alpha / aspect, 1.0), min(alpha * aspect, 1.0)


# --------------------------------------------------------------------------- the distribution (local frame)
# Local frame (T, B, n): directions (3, N) with +z the normal; α_x, α_y numbers or (N,) arrays.

def ggx_aniso_D(h: np.ndarray, ax, ay) -> np.ndarray:
    """D(h) = 1/(π α_x α_y q²), q = (h_x²/α_x² + h_y²/α_y² + h_z²)/|h|² (any length of h), 0 for h_z ≤ 0."""
    hx, hy, hz = h[0] / ax, h[1] / ay, h[2]
    q = (hx * hx + hy * hy + hz * hz) / (h[0] * h[0] + h[1] * h[1] + hz * hz)
    ok = (hz > 0) & (q > 0)
    return np.where(ok, 1.0 / (math.pi * ax * ay * np.where(ok, q * q, 1.0)), 0.0)


def ggx_aniso_lambda(w: np.ndarray, ax, ay) -> np.ndarray:
    """Smith Λ(ω) = (√(1 + a) − 1)/2, a = ((α_x ω_x)² + (α_y ω_y)²)/ω_z² (either hemisphere; ∞ at grazing)."""
    xy = (ax * w[0]) ** 2 + (ay * w[1]) ** 2
    z2 = w[2] * w[2]
    with np.errstate(over="ignore"):
        a = np.where(z2 > 0, xy / np.where(z2 > 0, z2, 1.0), np.where(xy > 0, np.inf, 0.0))
    fin = np.isfinite(a)
    a = np.where(fin, a, 0.0)
    # (√(1+a) − 1)/2 without cancellation for small a
    return np.where(fin, 0.5 * a / (np.sqrt(1.0 + a) + 1.0), np.inf)


def ggx_aniso_sample(wo: np.ndarray, u: np.ndarray, ax, ay) -> np.ndarray:
    """Visible normals h (3, N) for views wo (3, N) from uniforms u (2, N) (Heitz 2018; engine.materials.ggx.
    visible_normals).  Density G1(ω_o) max(0, ω_o·h) D(h)/cosθ_o."""
    return visible_normals(wo, u, ax, ay)


def _pdf_reflected(wo_l: np.ndarray, wi_l: np.ndarray, ax, ay) -> np.ndarray:
    """Solid-angle density of ω_i under visible-normal sampling + reflection: G1(ω_o)(ω_o·h)D(h)/cosθ_o
    over 4 ω_o·h, 0 where h is undefined or ω_o·h ≤ 0 (ω_o, ω_i local)."""
    h, _, ok = half_vector(wi_l, wo_l)
    d = wo_l[0] * h[0] + wo_l[1] * h[1] + wo_l[2] * h[2]
    ok = ok & (wo_l[2] > 0) & (d > 0)
    g1 = 1.0 / (1.0 + ggx_aniso_lambda(wo_l, ax, ay))
    vis = np.where(ok, g1 * np.maximum(d, 0.0) * ggx_aniso_D(h, ax, ay) / np.where(ok, wo_l[2], 1.0), 0.0)
    return np.where(ok, vis / (4.0 * np.where(ok, d, 1.0)), 0.0)


# --------------------------------------------------------------------------- the anisotropic albedo

@functools.lru_cache(maxsize=1)
def _full_disk_rule():
    """(p1, p2, w) (K,): nodes on the unit disk, weights summing to 1 (uniform measure)."""
    x, wx = np.polynomial.legendre.leggauss(QUAD_RADIUS)
    rho = 0.5 * (x + 1.0)
    w_rho = wx * rho                     # ∫₀¹ 2ρ g dρ = Σ ½·2ρ·w g
    phi = 2.0 * math.pi * (np.arange(QUAD_ANGLE) + 0.5) / QUAD_ANGLE
    R, P = np.meshgrid(rho, phi, indexing="ij")
    w = np.repeat(w_rho, QUAD_ANGLE) / QUAD_ANGLE
    return (R * np.cos(P)).ravel(), (R * np.sin(P)).ravel(), w


def anisotropic_albedo(wo: np.ndarray, ax: float, ay: float, eta: complex | None = None) -> np.ndarray:
    """E(ω_o) (M,) of the single-scattering anisotropic GGX reflection lobe (height-correlated Smith) for
    views wo (3, M) in the tangent frame (cosθ_o clipped to ≥ ggx_energy.MU_FLOOR): with F = 1 (``eta``
    None) or the unpolarised Fresnel reflectance of the constant relative index ``eta``.  Over the visible
    normals of ω_o (the disk rule of engine.materials.ggx_energy over the whole disk), where the estimator
    f·cosθ_i/pdf is F·(1 + Λ_o)/(1 + Λ_o + Λ_i), 0 where ω_i is below the horizon."""
    p1, p2, w = _full_disk_rule()
    wo = np.asarray(wo, np.float64).reshape(3, -1)
    out = np.empty(wo.shape[1])
    step = 8
    for i in range(0, wo.shape[1], step):
        o = wo[:, i:i + step].copy()
        o[2] = np.maximum(o[2], MU_FLOOR)
        o = o / np.sqrt(np.sum(o * o, axis=0))
        M = o.shape[1]
        oo = np.repeat(o, p1.size, axis=1)
        h = ggx_aniso_sample(oo, _disk_as_uniform(p1, p2, M), ax, ay)
        d = np.maximum(np.sum(oo * h, axis=0), 0.0)
        wi = 2.0 * d * h - oo
        lam_o = ggx_aniso_lambda(oo, ax, ay)
        weight = np.where(wi[2] > 0, (1.0 + lam_o) / (1.0 + lam_o + ggx_aniso_lambda(wi, ax, ay)), 0.0)
        if eta is not None:
            weight = weight * fresnel_reflectance(d, complex(eta))
        out[i:i + step] = weight.reshape(M, p1.size) @ w
    return out


def _disk_as_uniform(p1, p2, M):
    """The uniforms (2, M·K) that ``ggx_aniso_sample`` maps to the disk points (p1, p2): u0 = ρ², u1 = φ/2π."""
    rho2 = p1 * p1 + p2 * p2
    phi = np.mod(np.arctan2(p2, p1), 2.0 * math.pi) / (2.0 * math.pi)
    return np.stack((np.tile(rho2, M), np.tile(phi, M)))


def _azimuth_coordinate(wo_l: np.ndarray, ax: float, ay: float) -> np.ndarray:
    """c ∈ [0, 1] (N,) of views wo_l (3, N): (√α_o − √α_lo)/(√α_hi − √α_lo), α_o the projected roughness
    √((α_x ω_x)² + (α_y ω_y)²)/√(ω_x² + ω_y²) between α_lo = min(α_x, α_y) and α_hi = max; 0 at normal view
    and for an isotropic lobe."""
    lo, hi = min(ax, ay), max(ax, ay)
    xy = wo_l[0] * wo_l[0] + wo_l[1] * wo_l[1]
    ok = xy > 0
    if hi == lo:
        return np.zeros(xy.shape)
    ao = np.sqrt(np.where(ok, ((ax * wo_l[0]) ** 2 + (ay * wo_l[1]) ** 2) / np.where(ok, xy, 1.0), lo * lo))
    return np.clip((np.sqrt(ao) - math.sqrt(lo)) / (math.sqrt(hi) - math.sqrt(lo)), 0.0, 1.0)


def _table_views(ax: float, ay: float):
    """The table's view directions (3, MU·AZ) (t = √μ major, the azimuth coordinate c minor) and the E_avg
    rule's views and weights: Gauss–Legendre in μ and in the azimuth ψ ∈ [0, π/2]."""
    t = np.linspace(0.0, 1.0, LOBE_MU_NODES)
    c = np.linspace(0.0, 1.0, LOBE_AZIMUTH_NODES)
    T, C = np.meshgrid(t, c, indexing="ij")
    mu = np.maximum(T * T, MU_FLOOR).ravel()
    sin_t = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    lo, hi = min(ax, ay), max(ax, ay)
    ao = (math.sqrt(lo) + C.ravel() * (math.sqrt(hi) - math.sqrt(lo))) ** 2
    # α_o² = α_x² cos²φ + α_y² sin²φ  ⇒  sin²φ = (α_x² − α_o²)/(α_x² − α_y²) (any φ when isotropic)
    sin2 = np.clip((ax * ax - ao * ao) / (ax * ax - ay * ay), 0.0, 1.0) if hi > lo else np.zeros(ao.shape)
    table = np.stack((sin_t * np.sqrt(1.0 - sin2), sin_t * np.sqrt(sin2), mu))
    xm, wm = np.polynomial.legendre.leggauss(LOBE_AVG_MU_NODES)
    xa, wa = np.polynomial.legendre.leggauss(LOBE_AVG_AZIMUTH_NODES)
    mu_a, w_mu = 0.5 * (xm + 1.0), 0.5 * wm
    psi, w_psi = 0.25 * math.pi * (xa + 1.0), 0.25 * math.pi * wa
    M, P = np.meshgrid(mu_a, psi, indexing="ij")
    s = np.sqrt(1.0 - M * M)
    avg = np.stack((s * np.cos(P), s * np.sin(P), M)).reshape(3, -1)
    # E_avg = (1/π) ∫ E cosθ dω = (4/π) ∫₀^{π/2} dψ ∫₀¹ E μ dμ
    avg_w = (4.0 / math.pi) * (w_mu[:, None] * mu_a[:, None] * w_psi[None, :]).ravel()
    return table, avg, avg_w


def _build_lobe_table(ax: float, ay: float, eta: complex | None) -> np.ndarray:
    """(LOBE_MU_NODES·LOBE_AZIMUTH_NODES + 1,): E at the table's nodes, then E_avg."""
    table, avg, avg_w = _table_views(ax, ay)
    E = anisotropic_albedo(table, ax, ay, eta)
    E_avg = float(np.sum(avg_w * anisotropic_albedo(avg, ax, ay, eta)))
    return np.clip(np.append(E, E_avg), 0.0, 1.0)


@functools.lru_cache(maxsize=64)
def _lobe_table(ax: float, ay: float, eta: complex | None) -> np.ndarray:
    key = (_TABLE_VERSION, ax, ay, "white" if eta is None else (eta.real, eta.imag), LOBE_MU_NODES,
           LOBE_AZIMUTH_NODES, LOBE_AVG_MU_NODES, LOBE_AVG_AZIMUTH_NODES, QUAD_RADIUS, QUAD_ANGLE, MU_FLOOR)
    table = cached_table("ggx_anisotropic_albedo", key, (LOBE_MU_NODES * LOBE_AZIMUTH_NODES + 1,),
                         lambda: _build_lobe_table(ax, ay, eta))
    table.setflags(write=False)
    return table


class LobeAlbedoTable:
    """E(ω_o) of one anisotropic lobe (α_x, α_y constant; F = 1 or a constant index), bilinear in
    (√cosθ_o, the azimuth coordinate of ``_azimuth_coordinate``), and its cosine-weighted mean ``average``."""

    def __init__(self, ax: float, ay: float, eta: complex | None = None):
        self.ax, self.ay = float(ax), float(ay)
        data = _lobe_table(self.ax, self.ay, None if eta is None else complex(eta))
        self.E = data[:-1].reshape(LOBE_MU_NODES, LOBE_AZIMUTH_NODES)
        self.average = float(data[-1])

    def __call__(self, wo_l: np.ndarray) -> np.ndarray:
        """E (N,) at local views wo_l (3, N) (cosθ_o clipped to [0, 1])."""
        x = np.sqrt(np.clip(wo_l[2], 0.0, 1.0)) * (LOBE_MU_NODES - 1)
        i = np.minimum(x.astype(np.int64), LOBE_MU_NODES - 2)
        fx = x - i
        y = _azimuth_coordinate(wo_l, self.ax, self.ay) * (LOBE_AZIMUTH_NODES - 1)
        j = np.minimum(y.astype(np.int64), LOBE_AZIMUTH_NODES - 2)
        fy = y - j
        E = self.E
        return ((E[i, j] * (1.0 - fx) + E[i + 1, j] * fx) * (1.0 - fy)
                + (E[i, j + 1] * (1.0 - fx) + E[i + 1, j + 1] * fx) * fy)


# --------------------------------------------------------------------------- the model

class AnisotropicGGX(BSDF):
    """Polarising anisotropic GGX microfacet reflection (see the module docstring).

    Parameters
    ----------
    n, k : Spectrum or float — complex index n + iκ (as Torrance–Sparrow's: constant, tabulated, a
        per-point TexturedSpectrum, or the Gulbrandsen index of engine.spectral.gulbrandsen /
        engine.textures.conductor_index, all read through ``sp.spectrum``).
    alpha_x, alpha_y : float ≥ ALPHA_MIN (1e-4, engine.materials.roughness) — GGX roughness along the tangent T
        and the bitangent n × T.
    rotation : float — turns about n_s applied to the tangent (Blender's Anisotropic Rotation).
    tangent : callable(sp) -> (3, N) (or one (3,) vector) or None — the tangent per point (None: the mesh's, see
        ``tangent_frame``; any frame ⟂ n_s where the scene has no surface attributes).
    exterior_n : float > 0 — index of the incident medium (η = (n + iκ)/exterior_n).
    multiscatter : bool — Cycles' multiple-scattering compensation as a depolarised term (needs α ≤ 1).
    multiscatter_albedo : "cycles" (Cycles' isotropic tables at α = √(α_x α_y)) | "lobe" (this lobe's own
        albedo: energy-conserving for a white conductor at every aspect ratio).
    film_n, film_thickness : float or None, float — a thin film on every facet (index, thickness in nm), as
        Torrance–Sparrow's; none for film_n None or a thickness ≤ 0.1 nm.
    """

    name = "anisotropic_ggx"

    def __init__(self, n, k, alpha_x: float, alpha_y: float, rotation: float = 0.0,
                 tangent: Callable[[ShadingPoint], np.ndarray] | None = None, exterior_n: float = 1.0,
                 multiscatter: bool = False, multiscatter_albedo: str = "cycles", film_n: float | None = None,
                 film_thickness: float = 0.0):
        self.n = as_spectrum(n, "n")
        self.k = as_spectrum(k, "k")
        # α_x, α_y and the rotation: numbers, or per point (TexturedNumbers: a per-point Anisotropic, Rotation)
        self.per_point = any(isinstance(v, TexturedNumber) for v in (alpha_x, alpha_y))
        ax, ay = ((v if isinstance(v, TexturedNumber) else float(v)) for v in (alpha_x, alpha_y))
        for label, a in (("alpha_x", ax), ("alpha_y", ay)):
            checked_alpha(a, label)                  # (≥ roughness.ALPHA_MIN everywhere)
        self.alpha_x, self.alpha_y = ax, ay
        self.rotation = rotation if isinstance(rotation, TexturedNumber) else float(rotation)
        if not isinstance(self.rotation, TexturedNumber) and not math.isfinite(self.rotation):
            raise ValueError(f"rotation must be a finite number of turns, got {rotation!r}")
        if tangent is not None and not callable(tangent):
            raise ValueError(f"tangent must be a callable sp -> (3, N) or None, got {tangent!r}")
        self.tangent = tangent
        self.exterior_n = float(exterior_n)
        if not (math.isfinite(self.exterior_n) and self.exterior_n > 0):
            raise ValueError(f"exterior_n must be a finite number > 0, got {exterior_n!r}")
        self.multiscatter = bool(multiscatter)
        if multiscatter_albedo not in MULTISCATTER_ALBEDOS:
            raise ValueError(f"multiscatter_albedo must be one of {MULTISCATTER_ALBEDOS}, got {multiscatter_albedo!r}")
        self.multiscatter_albedo = multiscatter_albedo
        highest = max(getattr(ax, "hi", ax), getattr(ay, "hi", ay))
        if self.multiscatter and not highest <= ALPHA_MAX:
            raise ValueError(f"multiscatter needs alpha_x, alpha_y <= {ALPHA_MAX:g} (Cycles clamps GGX alpha to 1), "
                             f"got {ax!r}, {ay!r}")
        if self.per_point and multiscatter_albedo != "cycles":
            raise ValueError("per-point roughnesses need multiscatter_albedo='cycles' (one lobe table per α pair)")
        self.film = facet_film(film_n, film_thickness)
        self.isotropic = not self.per_point and ax == ay
        #: the single α of Cycles' energy tables for this lobe (rough = √√(α_x α_y) in its kernel); per point: None
        #: (``_alphas``)
        self.alpha_cycles = None if self.per_point else (ax if self.isotropic else math.sqrt(ax * ay))
        self._lobe_table = None
        self._reflection_table = None
        # the tangent frame needs the surface's attributes (an explicit callable may read them too)
        self.varies_over_surface = (not self.isotropic) or textured(self.n, self.k, self.rotation,
                                                                    *(self.film if self.film is not None else ()))
        constant = all(getattr(v, "is_constant", False) for v in (self.n, self.k))
        filmed = self.film is not None          # the film's s–p phase difference and its colours
        self.flags = (BSDFFlags.GLOSSY_REFLECTION | BSDFFlags.POLARISING
                      | BSDFFlags.when(self._may_retard() or filmed, BSDFFlags.RETARDING)
                      | BSDFFlags.when(not constant or filmed, BSDFFlags.WAVELENGTH_DEPENDENT))

    def _may_retard(self) -> bool:
        """False only if κ ≡ 0 and n/exterior_n ≥ 1 (real η above 1: no TIR, no retardance)."""
        if isinstance(self.k, ConstantSpectrum) and isinstance(self.n, ConstantSpectrum):
            return not (self.k.value == 0.0 and self.n.value >= self.exterior_n)
        return True

    # --- frames and indices ----------------------------------------------------------------------

    def tangent_frame(self, sp: ShadingPoint) -> tuple[np.ndarray, np.ndarray]:
        """(X, Y) (3, N): the unit tangent along which α_x applies and Y = n_s × X (right-handed with n_s).

        The tangent is ``tangent(sp)``, else the mesh's (``sp.surface.tangent_frame``), else (no surface
        attributes) engine.vec3.local_frame's; rotated about n_s by ``rotation`` turns; then, as Cycles'
        make_orthonormals_tangent, Y = unit(n_s × T), X = Y × n_s.  Where T ∥ n_s (or T is zero or not
        finite), and for an isotropic lobe, local_frame(n_s)."""
        n = sp.n_s
        t0, b0 = local_frame(n)
        if self.isotropic:
            return t0, b0
        if self.tangent is not None:
            T = np.asarray(self.tangent(sp), np.float64)
            T = np.broadcast_to(T.reshape(3, -1) if T.ndim == 1 else T, n.shape)
        elif sp.surface is not None:
            T = sp.surface.tangent_frame(n)[0]
        else:
            T = t0
        rotation = sp.number(self.rotation)
        if np.any(rotation != 0.0):      # Rodrigues about n: a quarter turn takes T to n × T
            ang = 2.0 * math.pi * rotation
            c, s = np.cos(ang), np.sin(ang)
            T = c * T + s * cross(n, T) + (1.0 - c) * dot(n, T)[None, :] * n
        Y = cross(n, T)
        with np.errstate(invalid="ignore", over="ignore"):
            length = np.sqrt(dot(Y, Y))
            size = np.sqrt(dot(T, T))
        ok = np.isfinite(length) & np.isfinite(size) & (length > _PARALLEL * size) & (length > 0)
        Y = np.where(ok[None, :], Y / np.where(ok, length, 1.0)[None, :], b0)
        X = np.where(ok[None, :], cross(Y, n), t0)
        return X, Y

    def relative_eta(self, sp: ShadingPoint) -> np.ndarray:
        """η = (n + iκ)/exterior_n (L, N)."""
        return (sp.spectrum(self.n) + 1j * sp.spectrum(self.k)) / self.exterior_n

    def _eta(self, sp: ShadingPoint) -> np.ndarray:
        """The relative index for the compensation: (1, 1) for constant n and κ, else ``relative_eta``."""
        if isinstance(self.n, ConstantSpectrum) and isinstance(self.k, ConstantSpectrum):
            return (np.full((1, 1), self.n.value) + 1j * np.full((1, 1), self.k.value)) / self.exterior_n
        return self.relative_eta(sp)

    def _constant_eta(self) -> complex:
        if not (isinstance(self.n, ConstantSpectrum) and isinstance(self.k, ConstantSpectrum)):
            raise ValueError("the reflection albedo table needs a constant n and k (one table), got "
                             f"n={self.n!r}, k={self.k!r}")
        return complex(self.n.value, self.k.value) / self.exterior_n

    def _alphas(self, sp: ShadingPoint):
        """(α_x, α_y, α for Cycles' energy tables): numbers, or (N,) at the points where per point."""
        if not self.per_point:
            return self.alpha_x, self.alpha_y, self.alpha_cycles
        ax, ay = sp.number(self.alpha_x), sp.number(self.alpha_y)
        return ax, ay, np.sqrt(ax * ay)

    def _local(self, sp: ShadingPoint, *ws):
        X, Y = self.tangent_frame(sp)
        return [to_local(w, X, Y, sp.n_s) for w in ws]

    # --- the compensation and the albedo ---------------------------------------------------------

    def _white_table(self) -> LobeAlbedoTable:
        if self._lobe_table is None:
            self._lobe_table = LobeAlbedoTable(self.alpha_x, self.alpha_y)
        return self._lobe_table

    def _extra(self, sp: ShadingPoint, wo_l: np.ndarray) -> np.ndarray:
        mu = np.clip(wo_l[2], 0.0, 1.0)
        if self.multiscatter_albedo == "cycles":
            return conductor_extra(mu, self._alphas(sp)[2], self._eta(sp), correlated=True)
        table = self._white_table()
        E = np.clip(table(wo_l), E_FLOOR, 1.0)
        E_avg = min(max(table.average, E_FLOOR), 1.0)
        Fms = multiscatter_fresnel(f82_average_fresnel(self._eta(sp)), E_avg)
        return Fms * ((1.0 - E) / E)[None, :]

    def multiscatter_extra(self, sp: ShadingPoint) -> np.ndarray:
        """k (L, N) or (1, N) of the compensation: the lobe's S0 is (1 + k) times its single-scattering value."""
        (wo_l,) = self._local(sp, sp.wo)
        return self._extra(sp, wo_l)

    def lobe_colors(self, sp: ShadingPoint):
        """Glossy: ``reflection_albedo`` (Cycles' estimate) for a real constant index (a Principled specular
        layer); None for a metal (engine.materials.tinted.F82Reflectance gives the Principled metal's)."""
        from .base import LobeColors
        if not (isinstance(self.k, ConstantSpectrum) and self.k.value == 0.0):
            return None
        return LobeColors.of(sp, glossy=self.reflection_albedo(sp))

    def reflection_albedo(self, sp: ShadingPoint) -> np.ndarray:
        """E(ω_o) (N,): the lobe's directional albedo for unpolarised light with its own (constant) Fresnel,
        times 1 + k with ``multiscatter`` (the layering albedo of a specular layer, as Torrance–Sparrow's):
        Cycles' estimate (the isotropic GGX table at α = √(α_x α_y)) or, with ``multiscatter_albedo="lobe"``,
        this lobe's own (anisotropic quadrature table).  With a thin film: the film's reflectance at the view
        angle, the largest over the RGB channels' wavelengths (Torrance–Sparrow's ``film_albedo``: Cycles has no
        table for iridescence)."""
        from ..textures.inputs import NumberSpectrum
        (wo_l,) = self._local(sp, sp.wo)
        cos_o = np.clip(wo_l[2], 0.0, 1.0)
        if isinstance(self.n, NumberSpectrum) and self.film is None and self.multiscatter_albedo == "cycles" and \
                isinstance(self.k, ConstantSpectrum) and self.k.value == 0.0:
            # a real index per point (the Principled dielectric's per-point IOR or Specular IOR Level): Cycles'
            # estimate from the index tables (engine.materials.torrance_sparrow.IndexAlbedoTables)
            if self._reflection_table is None:
                from .torrance_sparrow import IndexAlbedoTables
                lo = max(min(getattr(self.alpha_x, "lo", self.alpha_x), getattr(self.alpha_y, "lo", self.alpha_y)),
                         ALPHA_MIN)
                hi = max(getattr(self.alpha_x, "hi", self.alpha_x), getattr(self.alpha_y, "hi", self.alpha_y))
                self._reflection_table = IndexAlbedoTables(self.n.lo / self.exterior_n, self.n.hi / self.exterior_n,
                                                           lo, hi, "smith_correlated", "ggx")
            E = self._reflection_table(cos_o, self._alphas(sp)[2], self.n.numbers(sp.surface_points()) /
                                       self.exterior_n)
            return E * (1.0 + self._extra(sp, wo_l)[0]) if self.multiscatter else E
        if self.film is not None:
            if isinstance(self.n, NumberSpectrum) and isinstance(self.k, ConstantSpectrum):
                # a real index per point (the Principled's per-point IOR or Specular IOR Level): the substrate's
                # index at each point
                substrate = self.n.numbers(sp.surface_points()) + 1j * self.k.value
            else:
                substrate = self._constant_eta() * self.exterior_n
            return film_layering_albedo(cos_o, self.exterior_n, film_at(self.film, sp), substrate,
                                        layering_wavelengths(sp))
        eta = self._constant_eta()
        if self.multiscatter_albedo == "cycles":
            if self._reflection_table is None:
                if self.per_point:          # √(α_x α_y) lies between the least and the largest α
                    lo = max(min(self.alpha_x.lo, self.alpha_y.lo), ALPHA_MIN)
                    hi = max(self.alpha_x.hi, self.alpha_y.hi)
                else:
                    lo = hi = self.alpha_cycles
                self._reflection_table = SpecularAlbedoTable(eta, lo, hi, "smith_correlated", "ggx")
            E = self._reflection_table(cos_o, self._alphas(sp)[2])
        else:
            if self._reflection_table is None:
                self._reflection_table = LobeAlbedoTable(self.alpha_x, self.alpha_y, eta)
            E = self._reflection_table(wo_l)
        if self.multiscatter:
            E = E * (1.0 + self._extra(sp, wo_l)[0])
        return E

    # --- BSDF interface --------------------------------------------------------------------------

    def _facet_eval(self, sp: ShadingPoint, wi: np.ndarray):
        """(x, A, B, C, S, valid, wo_l) of the single-scattering lobe (Torrance–Sparrow's _facet_eval with
        the anisotropic D and Λ in the tangent frame)."""
        wo_l, wi_l = self._local(sp, sp.wo, wi)
        cos_i, cos_o = wi_l[2], wo_l[2]
        valid = (cos_i > 0) & (cos_o > 0)
        h, cos_f, ok = half_vector(wi_l, wo_l)
        ok &= valid & (cos_i * cos_o > 0)       # a product underflowing to 0: f = 0, not 0/0
        ax, ay, _ = self._alphas(sp)
        D = ggx_aniso_D(h, ax, ay)
        G = _chi_plus(wi_l, h) * _chi_plus(wo_l, h) / (1.0 + ggx_aniso_lambda(wi_l, ax, ay)
                                                       + ggx_aniso_lambda(wo_l, ax, ay))
        denom = 4.0 * np.where(ok, cos_i * cos_o, 1.0)
        fr = np.where(ok, D * G / denom, 0.0)
        c, eta = np.where(ok, cos_f, 1.0)[None, :], self.relative_eta(sp)
        if self.film is None:
            Af, Bf, Cf, Sf = fresnel_reflection_abcs(c, eta)
        else:                                   # the coated facet (Torrance–Sparrow's _facet_fresnel)
            film_n, d = film_at(self.film, sp)
            Af, Bf, Cf, Sf = film_reflection_abcs(c, self.exterior_n, film_n, d, eta * self.exterior_n, sp.lam)
        x = scattering_plane_axis(-wi, sp.wo)
        return x, Af * fr, Bf * fr, Cf * fr, Sf * fr, valid, wo_l

    def eval(self, sp: ShadingPoint, wi: np.ndarray) -> MuellerValue:
        x, A, B, C, S, _, wo_l = self._facet_eval(sp, wi)
        depol = self._extra(sp, wo_l) * A if self.multiscatter else None
        return MuellerValue("abcs", x, x, A, B, C, S, depol=depol)

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        wo_l, wi_l = self._local(sp, sp.wo, wi)
        valid = (wi_l[2] > 0) & (wo_l[2] > 0)
        ax, ay, _ = self._alphas(sp)
        return np.where(valid, _pdf_reflected(wo_l, wi_l, ax, ay), 0.0)

    def sample(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        X, Y = self.tangent_frame(sp)
        n_s = sp.n_s
        wo_l = to_local(sp.wo, X, Y, n_s)
        cos_o = wo_l[2]
        wi_l = np.zeros((3, sp.n))
        sel = np.nonzero(cos_o > 0)[0]
        ax, ay, _ = self._alphas(sp)
        if sel.size:
            h = ggx_aniso_sample(wo_l[:, sel], u_dir[:, sel], ax[sel] if np.ndim(ax) else ax,
                                 ay[sel] if np.ndim(ay) else ay)
            wi_l[:, sel] = reflect_local(wo_l[:, sel], h)
        wi = X * wi_l[0] + Y * wi_l[1] + n_s * wi_l[2]
        # the density at the returned (world) ω_i, as ``pdf`` computes it: the exact quotient of eval and pdf
        # there (at α ~ 1e-4 and grazing views the local → world rounding moves the pdf by ~1e-9)
        wi_l = to_local(wi, X, Y, n_s)
        pdf = np.where((wi_l[2] > 0) & (cos_o > 0), _pdf_reflected(wo_l, wi_l, ax, ay), 0.0)
        valid = (cos_o > 0) & (wi_l[2] > 0) & (pdf > 0) & np.all(np.isfinite(wi), axis=0)
        cos_i = np.maximum(dot(n_s, wi), 0.0)
        factor = np.where(valid, cos_i / np.where(valid, pdf, 1.0), 0.0)
        weight = self.eval(sp, wi).scaled(factor[None, :])
        return BSDFSample(wi=wi, weight=weight, pdf=np.where(valid, pdf, 0.0), is_delta=np.zeros(sp.n, bool),
                          valid=valid, eta_sq=np.ones(sp.n))

    def delta_reflection(self, sp: ShadingPoint):
        return None

    def describe(self) -> dict:
        shown = (repr(v) if isinstance(v, TexturedNumber) else v for v in (self.alpha_x, self.alpha_y, self.rotation))
        ax, ay, rotation = shown
        out = {"type": self.name, "n": repr(self.n), "k": repr(self.k), "alpha_x": ax,
               "alpha_y": ay, "rotation": rotation,
               "tangent": "callable" if self.tangent is not None else "surface", "shadowing": "smith_correlated",
               "exterior_n": self.exterior_n}
        if self.multiscatter:
            out["multiscatter"] = True
            out["multiscatter_albedo"] = self.multiscatter_albedo
        if self.film is not None:
            out["thin_film"] = film_label(self.film)
        return out
