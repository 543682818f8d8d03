"""Torrance–Sparrow polarising microfacet BRDF (docs/physics.md §1 and the Chapter 3 errata).

    f(ω_i, ω_o) = s · M_F(cosθ'_i) · D(h) · G(ω_i, ω_o) / (4 cosθ_i cosθ_o)  +  d · (ρ/π) · diag(1, 0, 0, 0)

- h = unit(ω_i + ω_o); the Fresnel Mueller matrix M_F (docs/physics.md §0) is evaluated at
  the *facet* angle cosθ'_i = ω_i·h = |ω_i + ω_o|/2 with the complex relative index
  η = (n + iκ)/exterior_n, in the facet frames, which for reflection are the
  scattering-plane frames: x_in = x_out = s = unit(k_i × k_o), k_i = −ω_i, k_o = ω_o
  (± the facet's s = unit(h × k_i); the sign is irrelevant).  At exact backscatter
  (k_o = −k_i, h = ω_i) the plane is undefined and any shared s ⟂ k_i is used: the facet
  is then at normal incidence, M_F = F·diag(1, 1, −1, −1), which is the same in every
  such frame.  The value is returned as ``MuellerValue("abcs", s, s, A, B, C, S)``.
- D: Beckmann (a Gaussian in the facet slope, normalised: docs/physics.md §3 Eq. 3.4 erratum) with
  the thesis's m (= SCATMECH s = Mitsuba α), GGX (Trowbridge–Reitz, α = m: Cycles' and Blender's
  microfacet distribution, engine.materials.ggx) or Blinn–Phong (engine.materials.microfacet).
  No cosθ_o is included (the integrator applies it).
- G: ``"ts"`` V-cavity (thesis Eq. 3.3, the default, as SCATMECH's
  Torrance_Sparrow_Shadow_Function), ``"smith"`` (exact separable Smith G1·G1 of the distribution),
  ``"smith_correlated"`` (height-correlated Smith 1/(1 + Λ_i + Λ_o), Heitz 2014: Cycles' G and the
  default for GGX), ``"smith_rational"`` (Mitsuba 3's rational Beckmann G1), ``"none"`` (G = 1,
  SCATMECH's Unit_Shadow_Function; not energy conserving at grazing angles).
- The Lambert term d·ρ/π is a depolariser (frame-independent), added to A only.
- One-sided: f = 0 where cosθ_i ≤ 0 or cosθ_o ≤ 0 w.r.t. the shading normal (as
  Mitsuba 3's rough conductor).  Every output is finite, also at θ = 0, 90°, exact
  specular and exact backscatter.

Diffuse layering (``diffuse_layering``):
- ``"add"`` (default): the Lambert term is added as written above (the two lobes do not share
  energy: s = d = ρ = 1 gives an albedo above 1);
- ``"albedo_scaling"`` (Cycles' Principled BSDF, ``closure_layering_weight``): the Lambert
  term is weighted by max(0, 1 − s·E(cosθ_o)), where E(cosθ_o) is the facet lobe's
  directional albedo (M00, unpolarised light) at the *outgoing* (view) direction:
      f = s·M_F·D·G/(4 cosθ_i cosθ_o) + d·max(0, 1 − s·E(cosθ_o))·(ρ/π)·diag(1, 0, 0, 0).
  The albedo at ω_o is then s·E + d·(1 − s·E)·ρ ≤ 1 for unpolarised light (= 1 for
  s = d = ρ = 1, up to the table error ≲ 5e-3, largest at grazing).  A GGX dielectric lobe (``cycles_layering``:
  Cycles' G, a real index, no film; also at m = 0) takes Cycles' *estimate* for E instead, as a Principled
  specular layer in Cycles (engine.materials.ggx_energy.cycles_layering_albedo; docs/physics.md, "Albedo scaling").
  Like Cycles' it is *not reciprocal*
  (the diffuse weight depends on ω_o only), and for fully polarised incident light the
  albedo can exceed 1 by the lobe's diattenuation share (the s-polarised reflectance
  is above the unpolarised one: for the smooth limit by (R_s − R_p)/2, at most 0.15 at
  n = 1.5, θ_o ≈ 79°).  E is tabulated once per
  model over √cosθ_o (33 nodes) and log m (nodes ALPHA_MIN·1.5^k shared by all models, cached
  per index and shadowing; only those spanning the model's m, or its texture's range) by a
  Gaussian slope-space quadrature (``specular_albedo``) for Beckmann facets, for GGX by the
  visible-normal quadrature of engine.materials.ggx_energy (``ggx_reflection_albedo``; α ≤ 1);
  interpolated bilinearly.  With ``multiscatter`` E is the compensated lobe's albedo (1 + k)·E, which is
  also what Cycles subtracts (its layering albedo: the closure weight's darkening times the Fresnel
  average over the lobe).  It needs a constant index n, κ (one table), so Blinn or a textured or
  wavelength-dependent n, κ is rejected with it.

Multiple scattering (``multiscatter``, GGX with Smith G — correlated or separable — only; default off):
the energy that a single-scattering facet lobe loses (light bouncing between facets) is put back as
Cycles' "Multiscatter GGX" does (albedo scaling, Kulla & Conty 2017; engine.materials.ggx_energy):
the lobe's S0 is multiplied by 1 + k with

    k = F_ms·(1 − E(cosθ_o))/E(cosθ_o),   F_ms = F_ss·E_avg/(1 − F_ss·(1 − E_avg)),

E the F = 1 lobe's directional albedo at the *view* direction and E_avg its cosine-weighted mean
(tables of this lobe and its shadowing form, bilinear in √cosθ_o and √α, α ≤ 1; with the default
height-correlated G they are Cycles' ggx_E and ggx_Eavg to 3·10⁻⁴), F_ss the conductor's mean Fresnel
reflectance as Cycles estimates it (an F82-tint fit to the exact Fresnel at 0° and ≈ 82°, per
wavelength).  The added k·M00 is a **depolarised** term (MuellerValue.depol, added to M00 only):
light scattered two or more times by randomly oriented facets is taken as unpolarised, the single-
scattering Mueller matrix — and so every polarisation the model predicts for first-order
scattering — is untouched, the sum stays realisable (a realisable matrix plus a non-negative
depolariser), and S0 for unpolarised light is Cycles' (scaling the whole matrix by 1 + k would
instead claim that multiply scattered light keeps the single bounce's diattenuation and
retardance).  Like Cycles' it is not reciprocal (k depends on ω_o only).  Sampling is unchanged
(the compensated lobe has the single-scattering lobe's shape); the sample weight is the compensated
f·cosθ_i/pdf.

Roughness range: m ≥ ALPHA_MIN = 1e-4 (engine.materials.roughness; ValueError below); with ``multiscatter``
m ≤ 1 (Cycles clamps GGX α to 1; the albedo tables span [0, 1]).  The lobe is evaluated as a
function for every allowed m; there is no switch to a Dirac mirror in the class: the declaration builds
the smooth limit (engine.materials.smooth_limit) for an effectively smooth m (below
roughness.SMOOTH_LIMIT).  At m = 1e-4 the peak D = 1/(π m²) ≈ 3.2e7 is still
resolved in double precision (tan²θ_h is computed from vector components).

Sampling (``sample``/``pdf``): a two-lobe mixture chosen per shading point with u_lobe:
- specular lobe with probability P_spec, diffuse (cosine-weighted) with 1 − P_spec;
  P_spec = w_s/(w_s + w_d) with w_s = s·mean_λ F(cosθ_o) (unpolarised Fresnel
  reflectance at the *macro* angle, an estimate of the lobe's albedo) and
  w_d = d·mean_λ ρ, clamped to [0.1, 0.9] when both lobes are present (so neither
  is starved); P_spec = 1 without a diffuse part and 0 without a specular part;
- specular directions: Beckmann → visible-normal sampling (Heitz & d'Eon 2014), GGX → visible
  normals in closed form (Heitz 2018, engine.materials.ggx), Blinn → D·cosθ_h sampling;
  ω_i = reflect(ω_o, h); samples below the horizon are invalid (their probability is simply lost);
- ``pdf`` is the full mixture density P_spec·pdf_spec + (1 − P_spec)·cosθ_i/π, so
  the integrator's MIS weights are right, and the weight is f·cosθ_i/pdf (the exact
  quotient of ``eval`` and ``pdf`` at the returned ω_i).
  With ``"albedo_scaling"`` the lobe weights are the lobes' albedos at ω_o instead:
  w_s = s·E(cosθ_o), w_d = d·ρ̄·max(0, 1 − s·E(cosθ_o)) (same clamping).

Implementation: with Beckmann or GGX facets (every shadowing form, no film) eval, pdf and sample are one
compiled pass each over the batch (engine.kernels.torrance_sparrow, declared with kernels.twin below); their
NumPy references are the batched functions ``_facet_eval``, ``_mixture_pdf`` and ``_mixture_sample`` of this
module, which Blinn facets, a filmed facet lobe and a TS without a facet lobe use directly (both return 0
where cosθ_i·cosθ_o underflows to 0).  The multiscatter term, the Lambert term and its layering weight are
added to the pass's value in NumPy, in ``eval``'s order (the same bits as before the GGX pass existed).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, LobeColors, MuellerValue, ShadingPoint, depolarising_value
from .conductor import K, METAL, N, THIN_FILM_IOR, THIN_FILM_THICKNESS, complex_index, mirror_reflection
from .ggx import GGX
from .ggx_energy import ALPHA_MAX, conductor_extra, cycles_layer_weight, ggx_reflection_albedo
from .microfacet import (SHADOWING, Beckmann, BlinnPhong, half_vector, reflect_local,
                                         shadowing_term)
from .parameters import ModelDeclaration, Parameter, Socket, exterior_n_parameter
from .roughness import ALPHA_MIN, SMOOTH_LIMIT, checked_alpha, declared_slope
from .sampling import cosine_hemisphere, local_to_world
from .smooth_limit import MirrorWithDiffuse
from ..errors import SceneError
from ..kernels import twin
from ..kernels.torrance_sparrow import (DISTRIBUTION_CODES, SHADOWING_CODES, _eta_rows, _p_inputs, _per_point,
                                        torrance_sparrow_eval_numba, torrance_sparrow_eval_pdf_numba,
                                        torrance_sparrow_pdf_numba, torrance_sparrow_sample_numba)
from ..polarisation.frames import scattering_plane_axis
from ..polarisation.fresnel import fresnel_reflection_abcs, fresnel_reflectance
from ..polarisation.thin_film import facet_film, film_at, film_label, film_reflection_abcs
from ..spectral.film_channels import film_layering_albedo, layering_wavelengths
from ..spectral import RGB_WAVELENGTHS_NM, ConstantSpectrum, as_spectrum
from ..textures import TexturedNumber
from ..textures.inputs import NumberSpectrum, textured
from ..vec3 import dot, local_frame, to_local

DISTRIBUTIONS = ("beckmann", "blinn", "ggx")
#: The shadowing forms whose albedo tables the multiple-scattering compensation has.
MULTISCATTER_SHADOWING = ("smith_correlated", "smith")
#: The distributions a scene file may name (Blinn needs an exponent: Python callers only).
SCENE_DISTRIBUTIONS = ("beckmann", "ggx")
#: Lobe-selection probability bounds when both a specular and a diffuse lobe exist.
P_SPEC_RANGE = (0.1, 0.9)
#: How the Lambert term combines with the specular lobe (module docstring).
DIFFUSE_LAYERINGS = ("add", "albedo_scaling")
#: Specular-albedo table (``"albedo_scaling"``): nodes in √cosθ_o, the ratio of neighbouring m nodes
#: (nodes at ALPHA_MIN·ratio^k, shared by every model: a textured m gives at each point exactly what the
#: constant m gives), quadrature points per slope axis, slope range in units of m (weight e^{−R²}).
ALBEDO_TABLE_MU_NODES = 33
ALBEDO_TABLE_M_RATIO = 1.5
ALBEDO_QUADRATURE_POINTS = 128
_SLOPE_RANGE = 5.5
#: cosθ_o of the table's first node (the grazing limit is evaluated just above 0).
_MU_FLOOR = 1e-4


def specular_albedo(cos_o, m, eta: complex, shadowing: str = "ts",
                    points: int = ALBEDO_QUADRATURE_POINTS) -> np.ndarray:
    """Directional albedo E(cosθ_o) = ∫ f_s·cosθ_i dω_i (M00, unpolarised, s = 1) of the Beckmann lobe.

    ``cos_o``, ``m``: arrays of one shape; ``eta``: the constant relative index (n + iκ)/exterior_n.
    With h = (−x, −y, 1)/‖·‖ and slopes (x, y) = m·(a, b), D dω_h = e^{−a²−b²}/(π cosθ_h) da db, so
        E = ∫∫ F(ω_o·h)·G·(ω_o·h)/(cosθ_o cosθ_h) · e^{−a²−b²}/π da db
    over facets whose mirror direction ω_i is above the horizon: a Gaussian-weighted integrand
    bounded by 2 (V-cavity G), even in b (ω_o in the xz plane), summed by the midpoint rule on
    ``points`` × ``points``/2 nodes of [−5.5, 5.5] × [0, 5.5].  Accuracy (against a fine
    (θ_i, φ_i) quadrature, tests/materials/test_principled_layering.py): ≲ 1e-3 for cosθ_o ≥ 0.3, ≲ 5e-3 at grazing.
    """
    cos_o, m = np.broadcast_arrays(np.asarray(cos_o, np.float64), np.asarray(m, np.float64))
    mu = np.maximum(cos_o.ravel(), _MU_FLOOR)
    mm = m.ravel()
    step = 2.0 * _SLOPE_RANGE / points
    ga = (np.arange(points) + 0.5) * step - _SLOPE_RANGE
    gb = (np.arange(points // 2) + 0.5) * step
    a, b = (v.ravel() for v in np.meshgrid(ga, gb, indexing="ij"))
    weight = 2.0 * np.exp(-(a * a + b * b)) / math.pi * step * step       # 2: the mirrored half b < 0
    eta_arr = np.full((1, a.size), eta, np.complex128)     # full shape: no broadcast views into the kernel
    out = np.empty(mu.size)
    for i in range(mu.size):          # one node at a time: bounded memory, results independent of batching
        x, y = mm[i] * a, mm[i] * b
        inv = 1.0 / np.sqrt(x * x + y * y + 1.0)
        h = np.stack((-x * inv, -y * inv, inv))
        wo = np.array([[math.sqrt(max(1.0 - mu[i] * mu[i], 0.0))], [0.0], [mu[i]]])
        d = wo[0] * h[0] + wo[2] * h[2]                       # ω_o·h
        wi = 2.0 * d * h - wo
        ok = (d > 0) & (wi[2] > 0)
        G = shadowing_term(shadowing, Beckmann(mm[i]), wi, np.repeat(wo, h.shape[1], axis=1), h)
        F = fresnel_reflectance(np.where(ok, d, 1.0)[None, :], eta_arr)[0]
        out[i] = np.sum(weight * np.where(ok, F * G * d / (mu[i] * h[2]), 0.0))
    return out.reshape(cos_o.shape)


@functools.lru_cache(maxsize=1024)
def _albedo_column(eta: complex, shadowing: str, k: int, distribution: str = "beckmann") -> np.ndarray:
    """E at the √cosθ_o nodes for m = ALPHA_MIN·ratio^k (cached: models sharing an index share it); GGX:
    the single-scattering reflection albedo by the visible-normal quadrature of engine.materials.ggx_energy
    (α capped at 1, the largest Cycles renders)."""
    t = np.linspace(0.0, 1.0, ALBEDO_TABLE_MU_NODES)
    m = ALPHA_MIN * ALBEDO_TABLE_M_RATIO ** k
    if distribution == "ggx":
        E = ggx_reflection_albedo(t * t, min(m, ALPHA_MAX), eta, correlated=shadowing == "smith_correlated")
    else:
        E = specular_albedo(t * t, np.full(t.size, m), eta, shadowing)
    E.setflags(write=False)
    return E


class SpecularAlbedoTable:
    """E(cosθ_o, m) of one Beckmann facet lobe (constant index) for m in [m_lo, m_hi]: bilinear in
    (√cosθ_o, log m) between fixed nodes (the same for every model, so the value at a point depends
    only on (cosθ_o, m), not on whether m is textured)."""

    def __init__(self, eta: complex, m_lo: float, m_hi: float, shadowing: str, distribution: str = "beckmann"):
        r = math.log(ALBEDO_TABLE_M_RATIO)
        self.k0 = max(int(math.floor(math.log(max(m_lo, ALPHA_MIN) / ALPHA_MIN) / r)), 0)
        k1 = max(int(math.floor(math.log(max(m_hi, ALPHA_MIN) / ALPHA_MIN) / r)), 0) + 1
        self.E = np.stack([_albedo_column(complex(eta), shadowing, k, distribution) for k in range(self.k0, k1 + 1)],
                          axis=1)

    def __call__(self, cos_o: np.ndarray, m) -> np.ndarray:
        """E at cosθ_o (N,) (clamped to [0, 1]) and m (a number or (N,) within [m_lo, m_hi])."""
        cos_o = np.asarray(cos_o, np.float64)
        m = np.broadcast_to(np.asarray(m, np.float64), cos_o.shape)
        x = np.sqrt(np.clip(cos_o, 0.0, 1.0)) * (ALBEDO_TABLE_MU_NODES - 1)
        i = np.minimum(x.astype(np.int64), ALBEDO_TABLE_MU_NODES - 2)
        fx = x - i
        y = np.log(np.maximum(m, ALPHA_MIN) / ALPHA_MIN) / math.log(ALBEDO_TABLE_M_RATIO) - self.k0
        j = np.clip(np.floor(y).astype(np.int64), 0, self.E.shape[1] - 2)
        fy = np.clip(y - j, 0.0, 1.0)
        E = self.E
        return ((E[i, j] * (1.0 - fx) + E[i + 1, j] * fx) * (1.0 - fy)
                + (E[i, j + 1] * (1.0 - fx) + E[i + 1, j + 1] * fx) * fy)


class IndexAlbedoTables:
    """E(cosθ_o, m, η) of a dielectric facet lobe whose real relative index η varies over the surface within
    [η_lo, η_hi] (all ≥ 1 or all ≤ 1): ``SpecularAlbedoTable``s at NODES indices evenly spaced in
    c = F0^¼ = √(|η − 1|/(η + 1)), linear in c between them (within 2e-3 of the exact table for η in
    [1.0001, 2.4], tests/materials/test_torrance_sparrow.py; even spacing in F0, √F0 or η errs by 2–7e-2 near
    η = 1, where the grazing Fresnel makes the albedo far from linear in F0).  Building costs NODES tables (a
    per-point roughness too: 17 × ~0.5 s once per process, cached)."""

    NODES = 17

    def __init__(self, eta_lo: float, eta_hi: float, m_lo: float, m_hi: float, shadowing: str,
                 distribution: str = "beckmann"):
        if not (eta_lo > 0 and eta_hi >= eta_lo and (eta_lo >= 1.0 or eta_hi <= 1.0)):
            raise ValueError(f"a per-point index range must lie on one side of 1, got [{eta_lo:g}, {eta_hi:g}]")
        self.above = eta_lo >= 1.0
        f_a, f_b = _root_f0(eta_lo), _root_f0(eta_hi)
        self.f_lo, self.f_hi = min(f_a, f_b), max(f_a, f_b)
        count = 1 if self.f_hi - self.f_lo < 1e-12 else self.NODES
        self.root_f0 = np.linspace(self.f_lo, self.f_hi, count)
        self.tables = [SpecularAlbedoTable(complex(self._eta_of(f)), m_lo, m_hi, shadowing, distribution)
                       for f in self.root_f0]

    def _eta_of(self, c: float) -> float:
        root = min(c * c, 0.999999)
        eta = (1.0 + root) / (1.0 - root)
        return eta if self.above else 1.0 / eta

    def __call__(self, cos_o: np.ndarray, m, eta: np.ndarray) -> np.ndarray:
        """E (N,) at cosθ_o (N,), m (a number or (N,)) and the points' real relative index eta (N,)."""
        if len(self.tables) == 1:
            return self.tables[0](cos_o, m)
        x = (np.clip(_root_f0(eta), self.f_lo, self.f_hi) - self.f_lo) / (self.f_hi - self.f_lo) \
            * (len(self.tables) - 1)
        i = np.minimum(x.astype(np.int64), len(self.tables) - 2)
        t = x - i
        m = np.broadcast_to(np.asarray(m, np.float64), np.shape(cos_o))
        E = np.empty(np.shape(cos_o))
        for k in np.unique(i):          # only the two tables each point lies between
            sel = np.nonzero(i == k)[0]
            c, mk = cos_o[sel], m[sel]
            E[sel] = (1.0 - t[sel]) * self.tables[k](c, mk) + t[sel] * self.tables[k + 1](c, mk)
        return E


def _root_f0(eta):
    """F0^¼ of a real relative index, √(|η − 1|/(η + 1)) (any shape): IndexAlbedoTables' coordinate."""
    return np.sqrt(np.abs((eta - 1.0) / (eta + 1.0)))


# --------------------------------------------------------------------------- the facet lobe's batched steps
# eval, pdf and sample of the facet lobe (plus the diffuse lobe's share of pdf and sample) as functions
# of the batch: ``dist`` is a microfacet distribution (engine.materials.microfacet), ``s`` the specular
# weight (a number or (N,)), ``eta`` the relative index (L, N); ``p_given`` the specular-lobe
# probability (N,) or None for the Fresnel estimate against the diffuse weight ``w_d`` (N,)
# (TorranceSparrow._p_spec).  For Beckmann and GGX facets the twins below run them as one compiled pass
# each (engine.kernels.torrance_sparrow); Blinn facets and films use these functions directly.

def _facet_eval(dist, n_s, wo, wi, eta, s, shadowing, fresnel=None):
    """(x, A, B, C, S, valid): the facet lobe s·M_F·D·G/(4 cosθ_i cosθ_o) in the scattering-plane frame
    x (3, N), (A, B, C, S) (L, N), and valid = cosθ_i > 0 and cosθ_o > 0 (N,).  ``fresnel(cos_f, eta)`` →
    (A, B, C, S) of the facet's reflection (default: the bare interface; a coated facet: TorranceSparrow's film)."""
    t, b = local_frame(n_s)
    wo_l = to_local(wo, t, b, n_s)
    wi_l = to_local(wi, t, b, n_s)
    cos_i, cos_o = wi_l[2], wo_l[2]
    valid = (cos_i > 0) & (cos_o > 0)
    h, cos_f, ok = half_vector(wi_l, wo_l)
    ok &= valid & (cos_i * cos_o > 0)       # a product underflowing to 0 (cosines ~1e-160): f = 0, not 0/0
    D = dist.D(h)
    G = shadowing_term(shadowing, dist, wi_l, wo_l, h)
    denom = 4.0 * np.where(ok, cos_i * cos_o, 1.0)
    fr = np.where(ok, s * D * G / denom, 0.0)
    Af, Bf, Cf, Sf = (fresnel or fresnel_reflection_abcs)(np.where(ok, cos_f, 1.0)[None, :], eta)
    x = scattering_plane_axis(-wi, wo)
    return x, Af * fr, Bf * fr, Cf * fr, Sf * fr, valid


def _p_spec_estimate(cos_o, p_given, eta, s, w_d):
    """P_spec (N,): ``p_given``, or s·mean_λ F(cosθ_o) against w_d, clamped to P_SPEC_RANGE."""
    if p_given is not None:
        return p_given
    F = fresnel_reflectance(np.clip(cos_o, 0.0, 1.0)[None, :], eta)
    w_s = s * F.mean(axis=0)
    tot = w_s + w_d
    p = np.where(tot > 0, w_s / np.where(tot > 0, tot, 1.0), 0.5)
    return np.clip(p, *P_SPEC_RANGE)


def _specular_pdf_local(dist, wo_l, wi_l) -> np.ndarray:
    h, _, ok = half_vector(wi_l, wo_l)
    return np.where(ok, dist.pdf_reflected(wo_l, h), 0.0)


def _mixture_pdf(dist, n_s, wo, wi, p_given, eta, s, w_d, has_specular, has_diffuse):
    """P_spec·pdf_spec + (1 − P_spec)·cosθ_i/π (N,), 0 unless cosθ_i > 0 and cosθ_o > 0."""
    t, b = local_frame(n_s)
    wo_l = to_local(wo, t, b, n_s)
    wi_l = to_local(wi, t, b, n_s)
    valid = (wi_l[2] > 0) & (wo_l[2] > 0)
    p_spec = _p_spec_estimate(wo_l[2], p_given, eta, s, w_d)
    out = np.zeros(n_s.shape[1])
    if has_specular:
        out = out + p_spec * _specular_pdf_local(dist, wo_l, wi_l)
    if has_diffuse:
        out = out + (1.0 - p_spec) * np.maximum(wi_l[2], 0.0) / math.pi
    return np.where(valid, out, 0.0)


def _mixture_sample(dist, n_s, wo, u_lobe, u_dir, p_given, eta, s, w_d, has_specular, has_diffuse):
    """(wi, pdf, valid, factor): a direction from the two-lobe mixture, its full pdf (0 where invalid)
    and the weight factor cosθ_i/pdf (0 where invalid)."""
    t, b = local_frame(n_s)
    wo_l = to_local(wo, t, b, n_s)
    cos_o = wo_l[2]
    p_spec = _p_spec_estimate(cos_o, p_given, eta, s, w_d)
    pick_spec = u_lobe < p_spec
    wi_l = np.zeros((3, n_s.shape[1]))
    if has_specular:
        sel = np.nonzero(pick_spec & (cos_o > 0))[0]
        if sel.size:
            d = dist.take(sel)
            h = d.sample(wo_l[:, sel], u_dir[:, sel])
            wi_l[:, sel] = reflect_local(wo_l[:, sel], h)
    if has_diffuse:
        sel = np.nonzero(~pick_spec)[0]
        if sel.size:
            wi_l[:, sel] = cosine_hemisphere(u_dir[:, sel])
    wi = local_to_world(wi_l, n_s)
    pdf = _mixture_pdf(dist, n_s, wo, wi, p_given, eta, s, w_d, has_specular, has_diffuse)
    valid = (cos_o > 0) & (wi_l[2] > 0) & (pdf > 0) & np.all(np.isfinite(wi), axis=0)
    cos_i = np.maximum(dot(n_s, wi), 0.0)
    factor = np.where(valid, cos_i / np.where(valid, pdf, 1.0), 0.0)
    return wi, np.where(valid, pdf, 0.0), valid, factor


def _distribution(distribution: str, m):
    """The facet distribution of a compiled pass ("beckmann" or "ggx") with roughness m (a number or (N,))."""
    return (GGX if distribution == "ggx" else Beckmann).per_point(m)


def torrance_sparrow_eval_numpy(n_s, wo, wi, eta, L, s, m, shadowing, distribution="beckmann"):
    """(x, A, B, C, S, valid) of the Beckmann or GGX facet lobe with roughness m (``_facet_eval``); eta
    broadcasts to (L, N)."""
    eta = np.broadcast_to(eta, (L, n_s.shape[1]))
    return _facet_eval(_distribution(distribution, m), n_s, wo, wi, eta, s, shadowing)


def torrance_sparrow_pdf_numpy(n_s, wo, wi, m, p_given, eta, L, s, w_d, has_specular, has_diffuse,
                               distribution="beckmann"):
    """The mixture pdf (N,) with Beckmann or GGX facets of roughness m (``_mixture_pdf``)."""
    eta = np.broadcast_to(eta, (L, n_s.shape[1]))
    return _mixture_pdf(_distribution(distribution, m), n_s, wo, wi, p_given, eta, s, w_d, has_specular,
                        has_diffuse)


def torrance_sparrow_sample_numpy(n_s, wo, u_lobe, u_dir, eta, L, s, m, shadowing, p_given, w_d, has_diffuse,
                                  distribution="beckmann", scale=True, value=True):
    """(wi, pdf, valid, factor, x, A, B, C, S, eval_valid) of a Beckmann or GGX facet lobe (roughness m)
    and an optional diffuse lobe: ``_mixture_sample``, then ``_facet_eval`` at wi with A..S times factor
    (``scale``; else the lobe's value itself); not ``value``: x and A..S None (the direction alone)."""
    eta = np.broadcast_to(eta, (L, n_s.shape[1]))
    dist = _distribution(distribution, m)
    wi, pdf, valid, factor = _mixture_sample(dist, n_s, wo, u_lobe, u_dir, p_given, eta, s, w_d, True, has_diffuse)
    x, A, B, C, S, eval_valid = _facet_eval(dist, n_s, wo, wi, eta, s, shadowing)
    if not value:
        return wi, pdf, valid, factor, None, None, None, None, None, eval_valid
    if not scale:
        return wi, pdf, valid, factor, x, A, B, C, S, eval_valid
    f = factor[None, :]
    return wi, pdf, valid, factor, x, A * f, B * f, C * f, S * f, eval_valid


def torrance_sparrow_eval_pdf_numpy(n_s, wo, wi, eta, L, s, m, shadowing, p_given, eta_p, s_p, w_d, has_diffuse,
                                    distribution="beckmann"):
    """(x, A, B, C, S, valid, pdf): ``torrance_sparrow_eval_numpy`` and ``torrance_sparrow_pdf_numpy`` (the facet
    lobe present) at the same directions (``eta``, ``s``: the lobe's; ``eta_p``, ``s_p``: the pdf's)."""
    return torrance_sparrow_eval_numpy(n_s, wo, wi, eta, L, s, m, shadowing, distribution) + (
        torrance_sparrow_pdf_numpy(n_s, wo, wi, m, p_given, eta_p, L, s_p, w_d, True, has_diffuse, distribution),)


torrance_sparrow_eval = twin(torrance_sparrow_eval_numba, torrance_sparrow_eval_numpy)
torrance_sparrow_eval_pdf = twin(torrance_sparrow_eval_pdf_numba, torrance_sparrow_eval_pdf_numpy)
torrance_sparrow_pdf = twin(torrance_sparrow_pdf_numba, torrance_sparrow_pdf_numpy)
torrance_sparrow_sample = twin(torrance_sparrow_sample_numba, torrance_sparrow_sample_numpy)


# --------------------------------------------------------------------------- TorranceSparrow's parameter checks

def _checked_roughness(m, distribution: str):
    """m as given if a TexturedNumber (Beckmann or GGX facets only), else float(m); finite and ≥ ALPHA_MIN
    everywhere (roughness.checked_alpha); ValueError otherwise."""
    if isinstance(m, TexturedNumber) and distribution not in ("beckmann", "ggx"):
        raise ValueError("a textured roughness m needs distribution='beckmann' or 'ggx'")
    return checked_alpha(m, "roughness m")


def _checked_shadowing(shadowing: str | None, distribution: str) -> str:
    """The shadowing form: None gives the distribution's default ("smith_correlated" for GGX, else "ts"); it must
    be one of SHADOWING, and "smith_rational" needs Beckmann facets; ValueError otherwise."""
    if shadowing is None:
        shadowing = "smith_correlated" if distribution == "ggx" else "ts"
    if shadowing not in SHADOWING:
        raise ValueError(f"shadowing must be one of {SHADOWING}, got {shadowing!r}")
    if shadowing == "smith_rational" and distribution == "ggx":
        raise ValueError("shadowing 'smith_rational' (Walter's rational Beckmann G1) needs distribution 'beckmann'")
    return shadowing


def _checked_exterior_n(exterior_n) -> float:
    """float(exterior_n), which must be finite and > 0 (ValueError otherwise)."""
    value = float(exterior_n)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"exterior_n must be a finite number > 0, got {exterior_n!r}")
    return value


def _checked_lobe_weights(specular_weight, diffuse_weight) -> tuple:
    """(s, d): each weight as given if a TexturedNumber, else as a float; both converted first, then each checked
    (specular first) to be finite and ≥ 0 (its lowest value if textured), ValueError otherwise."""
    s = specular_weight if isinstance(specular_weight, TexturedNumber) else float(specular_weight)
    d = diffuse_weight if isinstance(diffuse_weight, TexturedNumber) else float(diffuse_weight)
    for name, v in (("specular_weight", s), ("diffuse_weight", d)):
        lo = v.lo if isinstance(v, TexturedNumber) else v
        if not (math.isfinite(lo) and lo >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
    return s, d


def _facet_distribution(distribution: str, m, blinn_exponent: float | None):
    """The facet distribution object: Beckmann(m) or GGX(m) (None for a textured m: built per point), BlinnPhong
    from blinn_exponent or else from m; ValueError for an unknown distribution or a blinn_exponent without Blinn."""
    if distribution == "beckmann":
        if blinn_exponent is not None:
            raise ValueError("blinn_exponent is only used with distribution='blinn'")
        return None if isinstance(m, TexturedNumber) else Beckmann(m)
    if distribution == "blinn":
        return BlinnPhong(blinn_exponent) if blinn_exponent is not None else BlinnPhong.from_beckmann_m(m)
    if distribution == "ggx":
        if blinn_exponent is not None:
            raise ValueError("blinn_exponent is only used with distribution='blinn'")
        return None if isinstance(m, TexturedNumber) else GGX(m)
    raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {distribution!r}")


def _check_multiscatter(distribution: str, shadowing: str, m) -> None:
    """ValueError unless ``multiscatter`` is possible: GGX facets, a shadowing of MULTISCATTER_SHADOWING and
    m ≤ ALPHA_MAX (its highest value if textured)."""
    if distribution != "ggx" or shadowing not in MULTISCATTER_SHADOWING:
        raise ValueError("multiscatter (Cycles' Multiscatter GGX) needs distribution='ggx' and a Smith "
                         f"shadowing {MULTISCATTER_SHADOWING} (its albedo tables are those lobes'), got "
                         f"{distribution!r}, {shadowing!r}")
    hi = m.hi if isinstance(m, TexturedNumber) else m
    if not hi <= ALPHA_MAX:
        raise ValueError(f"multiscatter needs roughness m <= {ALPHA_MAX:g} (Cycles clamps GGX alpha to 1), "
                         f"got {hi!r}")


class TorranceSparrow(BSDF):
    """Polarising Torrance–Sparrow microfacet reflector (see the module docstring).

    Parameters
    ----------
    n, k : Spectrum or float — complex index n + iκ of the material (n > 0, κ ≥ 0).
    m : float — roughness: Beckmann rms slope m ≥ 1e-4 (thesis m, SCATMECH s, Mitsuba α).
        For ``distribution="blinn"`` the exponent is e = 2/m² − 2 (needs m ≤ √2) unless
        ``blinn_exponent`` is given.
    shadowing : "ts" (default) | "smith" | "smith_rational" | "none".
    exterior_n : float > 0 — index of the incident medium (η = (n + iκ)/exterior_n).
    diffuse_albedo : Spectrum, float or None — ρ of the Lambert term (None = no diffuse term).
    specular_weight : float ≥ 0 — s.   diffuse_weight : float ≥ 0 — d.
    distribution : "beckmann" (default) | "blinn" | "ggx" (m is then the GGX α).
    diffuse_layering : "add" (default) | "albedo_scaling" (Cycles' Principled energy sharing, not
        reciprocal; module docstring).
    shadowing : None (the default) is "smith_correlated" for GGX (Cycles' G) and "ts" otherwise.
    multiscatter : bool — Cycles' multiple-scattering energy compensation, added as a depolarised
        term (module docstring); needs distribution "ggx", a Smith shadowing ("smith_correlated" or
        "smith") and m ≤ 1.
    """

    name = "torrance_sparrow"

    def __init__(self, n, k, m, shadowing: str | None = None, exterior_n: float = 1.0, diffuse_albedo=None,
                 specular_weight: float = 1.0, diffuse_weight: float = 0.0, distribution: str = "beckmann",
                 blinn_exponent: float | None = None, diffuse_layering: str = "add", multiscatter: bool = False,
                 film_n: float | None = None, film_thickness: float = 0.0):
        self.n = as_spectrum(n, "n")
        # a thin film on every facet (Cycles' Principled Thin Film on its metal and specular layers): Airy's sum
        # over the film on the substrate n + iκ replaces the facet's bare Fresnel matrix (engine.polarisation.
        # thin_film); thickness in nm, none below 0.1 nm (Cycles' cutoff)
        self.film = facet_film(film_n, film_thickness)
        self.k = as_spectrum(k, "k")
        # m, specular_weight and diffuse_weight may be TexturedNumbers (values per surface point,
        # read through ShadingPoint.number); constants keep their float fast path
        m = _checked_roughness(m, distribution)
        self.m = m
        shadowing = _checked_shadowing(shadowing, distribution)
        self.shadowing = shadowing
        self.exterior_n = _checked_exterior_n(exterior_n)
        self.s, self.d = _checked_lobe_weights(specular_weight, diffuse_weight)
        self.albedo = None if diffuse_albedo is None else as_spectrum(diffuse_albedo, "diffuse_albedo")
        self.dist = _facet_distribution(distribution, m, blinn_exponent)
        self.distribution = distribution
        if diffuse_layering not in DIFFUSE_LAYERINGS:
            raise ValueError(f"diffuse_layering must be one of {DIFFUSE_LAYERINGS}, got {diffuse_layering!r}")
        self.diffuse_layering = diffuse_layering
        self.multiscatter = bool(multiscatter)
        if self.multiscatter:
            _check_multiscatter(distribution, shadowing, m)
        self._init_lobes()
        self.flags = self._lobe_flags()

    def _init_lobes(self) -> None:
        """Set ``has_specular`` (s > 0 somewhere), ``has_diffuse`` (d > 0 somewhere and an albedo),
        ``varies_over_surface`` and ``_albedo`` (the facet lobe's albedo table with ``"albedo_scaling"`` and both
        lobes, else None); needs every parameter attribute set."""
        def positive(v):
            return v.hi > 0 if isinstance(v, TexturedNumber) else v > 0
        self.has_specular = positive(self.s)
        self.has_diffuse = positive(self.d) and self.albedo is not None
        self.varies_over_surface = textured(self.n, self.k, self.m, self.s, self.d, self.albedo,
                                            *(self.film if self.film is not None else ()))
        self._albedo = None
        if self.diffuse_layering == "albedo_scaling" and self.has_specular and self.has_diffuse:
            self._albedo = self._albedo_table()

    def _lobe_flags(self) -> BSDFFlags:
        """The model's BSDFFlags from its lobes (``_init_lobes``), index and film."""
        constant = all(getattr(v, "is_constant", False) for v in
                       (self.n, self.k) + ((self.albedo,) if self.has_diffuse else ()))
        # The facet lobe is reported unless a diffuse term replaces it (s = 0): a TS with neither
        # weight (black) still has its — zero — glossy lobe, so it is never taken for Dirac-only.
        flags = (BSDFFlags.when(self.has_specular or not self.has_diffuse, BSDFFlags.GLOSSY_REFLECTION)
                 | BSDFFlags.when(self.has_diffuse, BSDFFlags.DIFFUSE_REFLECTION | BSDFFlags.SEPARABLE_DIFFUSE)
                 | BSDFFlags.when(self.has_specular, BSDFFlags.POLARISING)
                 | BSDFFlags.when(self.has_specular and self._may_retard(), BSDFFlags.RETARDING)
                 | BSDFFlags.when(not constant or self.film is not None, BSDFFlags.WAVELENGTH_DEPENDENT))
        if self.film is not None and self.has_specular:
            flags |= BSDFFlags.RETARDING       # the film's s–p phase difference
        return flags

    def _may_retard(self) -> bool:
        """False only if κ ≡ 0 and n/exterior_n ≥ 1 (real η above 1: no TIR, no retardance)."""
        if isinstance(self.k, ConstantSpectrum) and isinstance(self.n, ConstantSpectrum):
            return not (self.k.value == 0.0 and self.n.value >= self.exterior_n)
        return True

    def _albedo_table(self) -> SpecularAlbedoTable | IndexAlbedoTables:
        """The facet lobe's albedo table (``"albedo_scaling"``): Beckmann or GGX, one constant index, or a real
        index per point (a grey textured n, κ = 0: IndexAlbedoTables over its range)."""
        if self.distribution not in ("beckmann", "ggx"):
            raise ValueError("diffuse_layering='albedo_scaling' needs distribution 'beckmann' or 'ggx' (the "
                             "specular-albedo tables)")
        lo, hi = (max(self.m.lo, ALPHA_MIN), max(self.m.hi, ALPHA_MIN)) if isinstance(self.m, TexturedNumber) else \
            (self.m, self.m)
        if isinstance(self.n, NumberSpectrum) and isinstance(self.k, ConstantSpectrum) and self.k.value == 0.0 \
                and self.film is None:
            return IndexAlbedoTables(self.n.lo / self.exterior_n, self.n.hi / self.exterior_n, lo, hi, self.shadowing,
                                     self.distribution)
        if not (isinstance(self.n, ConstantSpectrum) and isinstance(self.k, ConstantSpectrum)):
            raise ValueError("diffuse_layering='albedo_scaling' needs a constant n and k (one specular-albedo "
                             f"table), got n={self.n!r}, k={self.k!r}")
        eta = complex(self.n.value, self.k.value) / self.exterior_n
        return SpecularAlbedoTable(eta, lo, hi, self.shadowing, self.distribution)

    def lobe_albedo(self, sp: ShadingPoint, cos_o: np.ndarray) -> np.ndarray:
        """E(cosθ_o) (N,) of the facet lobe from its albedo table (``"albedo_scaling"``; an index per point read
        at the points)."""
        if isinstance(self._albedo, IndexAlbedoTables):
            return self._albedo(cos_o, sp.number(self.m), self.n.numbers(sp.surface_points()) / self.exterior_n)
        return self._albedo(cos_o, sp.number(self.m))

    def diffuse_scale(self, sp: ShadingPoint, cos_o: np.ndarray) -> np.ndarray | None:
        """max(0, 1 − s·E(cosθ_o)) (N,) of ``"albedo_scaling"``; None for ``"add"`` (weight 1)."""
        if self._albedo is None:
            return None
        return np.maximum(1.0 - sp.number(self.s) * self._layer_albedo(sp, cos_o, self._albedo), 0.0)

    def _layer_albedo(self, sp: ShadingPoint, cos_o: np.ndarray, table) -> np.ndarray:
        """E(cosθ_o) (N,) of the facet lobe (s = 1) from its albedo ``table`` (``_albedo_table``), × (1 + k) with
        ``multiscatter`` (the compensated lobe's: Cycles' layering estimate), a filmed lobe's ``film_albedo``."""
        if self.film is not None:
            return self.film_albedo(sp, cos_o)
        if self.cycles_layering:
            return self.cycles_layer_albedo(sp, cos_o)
        if isinstance(table, IndexAlbedoTables):
            E = table(cos_o, sp.number(self.m), self.n.numbers(sp.surface_points()) / self.exterior_n)
        else:
            E = table(cos_o, sp.number(self.m))
        if self.multiscatter:
            E = E * (1.0 + self.multiscatter_extra(sp)[0])
        return E

    @property
    def cycles_layering(self) -> bool:
        """A dielectric GGX lobe with Cycles' shadowing, a real index (constant or per point) and no film: its layering
        albedo is Cycles' estimate (``cycles_layer_albedo``), as a Principled specular layer's or coat's."""
        return (self.distribution == "ggx" and self.shadowing == "smith_correlated" and self.film is None
                and isinstance(self.k, ConstantSpectrum) and self.k.value == 0.0
                and isinstance(self.n, (ConstantSpectrum, NumberSpectrum)))

    def cycles_layer_albedo(self, sp: ShadingPoint, cos_o: np.ndarray) -> np.ndarray:
        """(N,) Cycles' layering albedo of this dielectric facet lobe (s = 1) at cosθ_o: its estimate F0 + (1 − F0)·s
        (engine.materials.ggx_energy.cycles_layering_albedo), × E + F_ms(1 − E) with ``multiscatter`` (the
        compensation's weight, which Cycles' ``bsdf_albedo`` carries: cycles_layering_darkening)."""
        eta = (self.n.numbers(sp.surface_points()) if isinstance(self.n, NumberSpectrum) else self.n.value) \
            / self.exterior_n
        return cycles_layer_weight(cos_o, sp.number(self.m), eta, self.multiscatter)

    def lobe_colors(self, sp: ShadingPoint) -> LobeColors | None:
        """Glossy: s·E(cosθ_o) (``_layer_albedo``; Cycles' estimate of a Principled specular layer); diffuse:
        d·ρ, × max(0, 1 − s·E) with ``"albedo_scaling"``.  None where the facet lobe has no albedo table (Blinn
        facets, an index that varies with the wavelength, a film outside ``"albedo_scaling"``)."""
        cos_o = np.clip(sp.cos_o, 0.0, 1.0)
        table = self._albedo
        if self.has_specular and table is None:
            table = self._colour_table()
            if table is None:
                return None
        glossy = sp.number(self.s) * self._layer_albedo(sp, cos_o, table) if self.has_specular else 0.0
        diffuse = 0.0
        if self.has_diffuse:
            diffuse = sp.spectrum(self.albedo) * sp.number(self.d)
            scale = self.diffuse_scale(sp, cos_o)
            if scale is not None:
                diffuse = diffuse * scale[None, :]
        return LobeColors.of(sp, diffuse=diffuse, glossy=glossy)

    def _colour_table(self):
        """The facet lobe's albedo table for ``lobe_colors`` outside ``"albedo_scaling"`` (built once), None where
        there is none (``_albedo_table``'s conditions, no film)."""
        if not hasattr(self, "_colour_albedo"):
            constant = isinstance(self.n, ConstantSpectrum) and isinstance(self.k, ConstantSpectrum)
            per_point = isinstance(self.n, NumberSpectrum) and isinstance(self.k, ConstantSpectrum) and \
                self.k.value == 0.0
            ok = self.distribution in ("beckmann", "ggx") and self.film is None and (constant or per_point)
            self._colour_albedo = self._albedo_table() if ok else None
        return self._colour_albedo

    def film_albedo(self, sp: ShadingPoint, cos_o: np.ndarray) -> np.ndarray:
        """(N,) Cycles' layering estimate of a filmed facet lobe (bsdf_microfacet_estimate_albedo: no table for
        iridescence, the film's reflectance at the view angle): the largest over the colour channels, each channel's
        band average as the spectral transport develops it, or in "rgb" transport its wavelength
        (engine.spectral.film_channels.film_layering_albedo, layering_wavelengths), as Cycles layers by the largest
        channel."""
        # (a constant index: "albedo_scaling" needs one, _albedo_table)
        return film_layering_albedo(cos_o, self.exterior_n, film_at(self.film, sp), self.n.value + 1j * self.k.value,
                                    layering_wavelengths(sp))

    def as_layers(self):
        """With ``"albedo_scaling"``, the same material as Cycles' two closures: this specular lobe alone over
        a Lambert base of weight d, the base scaled by max(0, 1 − s·E(ω_o)) (mix.Layered); else None.  Used to
        give the two lobes their own mapped normals (mix.map_normals)."""
        if self._albedo is None:
            return None
        from .lambert import Lambert
        from .mix import Layered, Mix
        film_n, film_d = self.film if self.film is not None else (None, 0.0)
        top = TorranceSparrow(self.n, self.k, self.m, self.shadowing, self.exterior_n, None, self.s, 0.0,
                              self.distribution, None, "add", self.multiscatter, film_n, film_d)
        layered = Layered(top, Mix([Lambert(self.albedo)], [self.d]), 1.0,
                          lambda sp: 1.0 - self.diffuse_scale(sp, np.clip(sp.cos_o, 0.0, 1.0)))
        layered.two_sided = self.two_sided
        return layered

    # --- helpers ---------------------------------------------------------------------------------

    def _dist(self, sp: ShadingPoint, sel: np.ndarray | None = None):
        """The facet distribution at the points (``sel``: a subset of them)."""
        if self.dist is not None:
            return self.dist
        m = sp.number(self.m)
        per_point = GGX.per_point if self.distribution == "ggx" else Beckmann.per_point
        return per_point(m if sel is None else m[sel])

    def relative_eta(self, sp: ShadingPoint) -> np.ndarray:
        """(n + iκ)/exterior_n (L, N) at the points (once per batch: ShadingPoint.memo)."""
        return sp.memo(self, "relative_eta",
                       lambda: (sp.spectrum(self.n) + 1j * sp.spectrum(self.k)) / self.exterior_n)

    def _p_spec(self, sp: ShadingPoint, cos_o: np.ndarray) -> np.ndarray:
        """Probability of sampling the specular lobe (N,), a function of ω_o only."""
        p_given, w_d = self._p_spec_inputs(sp, cos_o)
        if p_given is not None:
            return p_given
        return _p_spec_estimate(cos_o, None, self.relative_eta(sp), sp.number(self.s), w_d)

    def _p_spec_inputs(self, sp: ShadingPoint, cos_o: np.ndarray):
        """(p_given, w_d) of ``_p_spec_estimate``: P_spec itself where it is not the Fresnel estimate
        (one lobe only: 1 or 0; ``"albedo_scaling"``: the lobes' albedos at ω_o), else the diffuse weight."""
        if not self.has_diffuse:
            return (np.ones(sp.n) if self.has_specular else np.zeros(sp.n)), None
        if not self.has_specular:
            return np.zeros(sp.n), None
        if self._albedo is not None:   # the lobes' albedos at ω_o
            s = sp.number(self.s)
            E = self.lobe_albedo(sp, cos_o)
            w_s = s * E
            w_d = sp.number(self.d) * sp.spectrum(self.albedo).mean(axis=0) * np.maximum(1.0 - s * E, 0.0)
            tot = w_s + w_d
            p = np.where(tot > 0, w_s / np.where(tot > 0, tot, 1.0), 0.5)
            return np.clip(p, *P_SPEC_RANGE), None
        return None, sp.number(self.d) * sp.spectrum(self.albedo).mean(axis=0)

    @property
    def _compiled_lobe(self) -> bool:
        """The facet lobe runs as the twins (engine.kernels.torrance_sparrow): Beckmann or GGX facets without a
        film (Blinn facets and a filmed lobe run the NumPy functions)."""
        return self.has_specular and self.distribution in DISTRIBUTION_CODES and \
            self.shadowing in SHADOWING_CODES and self.film is None

    def _facet_fresnel(self, sp: ShadingPoint):
        """The facet's reflection (A, B, C, S) as a function of (cos_f, η) for _facet_eval: None (the bare
        interface), or the film's at the batch's wavelengths (η (L, N) relative to exterior_n)."""
        if self.film is None:
            return None
        film_n, d = film_at(self.film, sp)
        ext = self.exterior_n

        def coated(cos_f, eta):
            return film_reflection_abcs(cos_f, ext, film_n, d, eta * ext, sp.lam)
        return coated

    def multiscatter_extra(self, sp: ShadingPoint) -> np.ndarray:
        """k (L, N) or (1, N) of the multiple-scattering compensation (module docstring): the facet
        lobe's S0 is (1 + k) times its single-scattering value (once per batch: ShadingPoint.memo)."""
        correlated = self.shadowing == "smith_correlated"
        return sp.memo(self, "multiscatter_extra", lambda: conductor_extra(
            np.clip(sp.cos_o, 0.0, 1.0), sp.number(self.m), self._eta(sp), correlated=correlated))

    def _depol(self, sp: ShadingPoint, valid: np.ndarray, cos_o) -> np.ndarray | None:
        """The Lambert term d·ρ/π (L, N) (times the ``"albedo_scaling"`` weight), 0 where not valid."""
        if not self.has_diffuse:
            return None
        # A depolariser adds to M00 only (not to the ABCS block's M11).
        depol = sp.spectrum(self.albedo) * (sp.number(self.d) / math.pi) * valid[None, :]
        scale = self.diffuse_scale(sp, cos_o() if self._albedo is not None else None)
        if scale is not None:
            depol = depol * scale[None, :]
        return depol

    # --- BSDF interface --------------------------------------------------------------------------

    def diffuse_share(self, sp: ShadingPoint, wi: np.ndarray, f: MuellerValue) -> np.ndarray | None:
        """The Lambert term of ``f`` = eval(sp, wi): its depolarised part without the multiscatter term."""
        if not (self.has_diffuse and self.has_specular):
            return super().diffuse_share(sp, wi, f)
        if f.depol is None:
            return np.zeros_like(f.A)
        return f.depol - self.multiscatter_extra(sp) * f.A if self.multiscatter else f.depol

    def eval(self, sp: ShadingPoint, wi: np.ndarray) -> MuellerValue:
        if not self.has_specular:   # pure Lambert: a depolariser (frame-independent)
            n_s = sp.n_s
            t, b = local_frame(n_s)
            cos_o = to_local(sp.wo, t, b, n_s)[2]
            valid = (to_local(wi, t, b, n_s)[2] > 0) & (cos_o > 0)
            depol = self._depol(sp, valid, lambda: cos_o)
            return depolarising_value(depol if depol is not None else np.zeros((sp.lam.shape[0], sp.n)), sp.n)
        if self._compiled_lobe:
            x, A, B, C, S, valid = torrance_sparrow_eval(sp.n_s, sp.wo, wi, self._eta(sp), sp.lam.shape[0],
                                                         sp.number(self.s), self._m(sp), self.shadowing,
                                                         self.distribution)
        else:
            x, A, B, C, S, valid = _facet_eval(self._dist(sp), sp.n_s, sp.wo, wi, self.relative_eta(sp),
                                               sp.number(self.s), self.shadowing, self._facet_fresnel(sp))
        return self._facet_value(sp, x, A, B, C, S, valid)

    def _facet_value(self, sp: ShadingPoint, x, A, B, C, S, valid) -> MuellerValue:
        """``eval``'s value from the facet lobe's blocks: the Lambert and multiscatter terms added."""
        depol = self._depol(sp, valid, lambda: sp.cos_o)
        if self.multiscatter:   # the multiply scattered energy, depolarised: k·M00 of the facet lobe
            extra = self.multiscatter_extra(sp) * A
            depol = extra if depol is None else depol + extra
        return MuellerValue("abcs", x, x, A, B, C, S, depol=depol)

    def eval_and_pdf(self, sp: ShadingPoint, wi: np.ndarray) -> tuple[MuellerValue, np.ndarray]:
        """(``eval``, ``pdf``) at the same directions: with the compiled facet lobe one pass for both
        (torrance_sparrow_eval_pdf, the same bits), else the two calls."""
        cls = type(self)
        if not (self.has_specular and self._compiled_lobe and cls.eval is TorranceSparrow.eval
                and cls.pdf is TorranceSparrow.pdf and cls._facet_value is TorranceSparrow._facet_value):
            return super().eval_and_pdf(sp, wi)
        p_given, eta_p, s_p, w_d = self._mixture_inputs(sp, compact=True)
        x, A, B, C, S, valid, pdf = torrance_sparrow_eval_pdf(sp.n_s, sp.wo, wi, self._eta(sp), sp.lam.shape[0],
                                                              sp.number(self.s), self._m(sp), self.shadowing,
                                                              p_given, eta_p, s_p, w_d, self.has_diffuse,
                                                              self.distribution)
        return self._facet_value(sp, x, A, B, C, S, valid), pdf

    def _m(self, sp: ShadingPoint):
        """The roughness at the points: a number, or (N,) for a textured m."""
        return sp.number(self.m)

    def _eta(self, sp: ShadingPoint) -> np.ndarray:
        """The relative index for the twins: (1, 1) for constant n and κ (the value every entry of
        ``relative_eta`` has, computed the same way), else ``relative_eta`` (L, N); once per batch (a configured
        copy that changes exterior_n, engine.materials.weidlich_wilkie, is another owner)."""
        if isinstance(self.n, ConstantSpectrum) and isinstance(self.k, ConstantSpectrum):
            return sp.memo(self, "eta", lambda: (np.full((1, 1), self.n.value) + 1j * np.full((1, 1), self.k.value))
                           / self.exterior_n)
        return self.relative_eta(sp)

    def _mixture_inputs(self, sp: ShadingPoint, compact: bool = False):
        """(p_given, eta, s, w_d) for the mixture pdf and sampling (``compact``: eta as ``_eta``); the lobe choice's
        inputs once per batch."""
        p_given, w_d = sp.memo(self, "p_spec_inputs",
                               lambda: self._p_spec_inputs(sp, sp.cos_o if self._albedo is not None else None))
        return p_given, self._eta(sp) if compact else self.relative_eta(sp), sp.number(self.s), w_d

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        p_given, eta, s, w_d = self._mixture_inputs(sp, compact=self._compiled_lobe)
        if self._compiled_lobe:
            return torrance_sparrow_pdf(sp.n_s, sp.wo, wi, self._m(sp), p_given, eta, sp.lam.shape[0], s, w_d, True,
                                        self.has_diffuse, self.distribution)
        return _mixture_pdf(self._dist(sp) if self.has_specular else None, sp.n_s, sp.wo, wi, p_given, eta, s,
                            w_d, self.has_specular, self.has_diffuse)

    def sample(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        p_given, eta, s, w_d = self._mixture_inputs(sp, compact=self._compiled_lobe)
        if self._compiled_lobe:
            # with multiscatter the lobe's value itself (k·A joins depol before the factor, as in ``eval``)
            wi, pdf, valid, factor, x, A, B, C, S, eval_valid = self._compiled_sample(sp, u_lobe, u_dir, p_given,
                                                                                      eta, s, w_d)
            depol = self._depol(sp, eval_valid, lambda: sp.cos_o)
            if self.multiscatter:
                extra = self.multiscatter_extra(sp) * A
                weight = MuellerValue("abcs", x, x, A, B, C, S, depol=extra if depol is None else depol + extra)
                weight = weight.scaled(factor[None, :])
            else:
                weight = MuellerValue("abcs", x, x, A, B, C, S,
                                      depol=None if depol is None else depol * factor[None, :])
        else:
            wi, pdf, valid, factor = _mixture_sample(self._dist(sp) if self.has_specular else None, sp.n_s, sp.wo,
                                                     u_lobe, u_dir, p_given, eta, s, w_d, self.has_specular,
                                                     self.has_diffuse)
            weight = self.eval(sp, wi).scaled(factor[None, :])
        return BSDFSample(wi=wi, weight=weight, pdf=pdf, is_delta=np.zeros(sp.n, bool), valid=valid,
                          eta_sq=np.ones(sp.n))

    def _compiled_sample(self, sp: ShadingPoint, u_lobe, u_dir, p_given, eta, s, w_d, value: bool = True) -> tuple:
        """The compiled sample pass (torrance_sparrow_sample's tuple) with this lobe's settings; with multiscatter
        the lobe's value unscaled by the sample's factor (``sample`` adds k·A first); not ``value``: the direction
        alone (x and A..S None, no Fresnel values computed)."""
        return torrance_sparrow_sample(sp.n_s, sp.wo, u_lobe, u_dir, eta, sp.lam.shape[0], s, self._m(sp),
                                       self.shadowing, p_given, w_d, self.has_diffuse, self.distribution,
                                       not self.multiscatter, value)

    def sample_direction(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        """``sample`` without the weight (no Dirac lanes: None)."""
        p_given, eta, s, w_d = self._mixture_inputs(sp, compact=self._compiled_lobe)
        if self._compiled_lobe:
            wi, pdf, valid = self._compiled_sample(sp, u_lobe, u_dir, p_given, eta, s, w_d, value=False)[:3]
        else:
            wi, pdf, valid, _ = _mixture_sample(self._dist(sp) if self.has_specular else None, sp.n_s, sp.wo, u_lobe,
                                                u_dir, p_given, eta, s, w_d, self.has_specular, self.has_diffuse)
        return BSDFSample(wi=wi, weight=None, pdf=pdf, is_delta=np.zeros(sp.n, bool), valid=valid,
                          eta_sq=np.ones(sp.n))

    def delta_reflection(self, sp: ShadingPoint):
        return None

    def lobe_kernel_inputs(self, sp: ShadingPoint) -> tuple | None:
        """The facet lobe's inputs of engine.kernels.glossy_bounce (``eval``'s, ``pdf``'s and ``sample``'s, as their
        compiled twins take them: eta, s, m, distribution and shadowing codes, p_given, use_given, the pdf's eta and
        s, w_d and its wavelength count), or None where the value is not the compiled facet lobe alone (a Lambert
        or multiscatter term, a film, Blinn facets, a subclass's own eval, pdf or sample)."""
        cls = type(self)
        if (not self._compiled_lobe or self.has_diffuse or self.multiscatter or cls.eval is not TorranceSparrow.eval
                or cls.pdf is not TorranceSparrow.pdf or cls.sample is not TorranceSparrow.sample):
            return None
        n = sp.n
        p_given, eta_p, s, w_d = self._mixture_inputs(sp, compact=True)
        p, use_given, wd = _p_inputs(p_given, w_d, n)
        return (_eta_rows(self._eta(sp)), _per_point(s, n), _per_point(self._m(sp), n),
                DISTRIBUTION_CODES[self.distribution], SHADOWING_CODES[self.shadowing], p, use_given,
                np.zeros((1, 1), np.complex128) if use_given else _eta_rows(eta_p),
                np.zeros(1) if use_given else _per_point(s, n), wd, int(sp.lam.shape[0]))

    def describe(self) -> dict:
        out = {"type": self.name, "n": repr(self.n), "k": repr(self.k), "m": self.m,
               "shadowing": self.shadowing, "distribution": self.distribution, "exterior_n": self.exterior_n,
               "specular_weight": self.s, "diffuse_weight": self.d,
               "diffuse_albedo": None if self.albedo is None else repr(self.albedo)}
        for key in ("m", "specular_weight", "diffuse_weight"):
            if isinstance(out[key], TexturedNumber):
                out[key] = repr(out[key])
        if self.distribution == "blinn":
            out["blinn_exponent"] = self.dist.e
        if self.diffuse_layering != "add":
            out["diffuse_layering"] = self.diffuse_layering
        if self.multiscatter:
            out["multiscatter"] = True
        if self.film is not None:
            out["thin_film"] = film_label(self.film)
        return out


# --------------------------------------------------------------------------- the smooth limit under a film

class FilmedMirrorWithDiffuse(MirrorWithDiffuse):
    """The smooth limit (m = 0) of a Torrance–Sparrow under a thin film (Cycles' Principled Thin Film on a smooth
    specular layer): engine.materials.smooth_limit's mirror plus Lambertian part, the mirror's Mueller matrix
    Airy's sum over the film (index, thickness nm; none at ≤ 0.1 nm) on the substrate n + iκ instead of M_F, at
    the path's wavelengths.  With ``"albedo_scaling"`` the Lambertian part is weighted by max(0, 1 − s·E(cosθ_o)),
    E the rough filmed lobe's layering estimate (TorranceSparrow.film_albedo, Cycles' for iridescence: the film's
    reflectance at the view angle, the largest over the RGB channels' wavelengths)."""

    def __init__(self, n, k, exterior_n=1.0, diffuse_albedo=0.0, specular_weight=1.0, diffuse_weight=0.0,
                 diffuse_layering="add", film_n: float | None = None, film_thickness: float = 0.0):
        super().__init__(n, k, exterior_n, diffuse_albedo, specular_weight, diffuse_weight, diffuse_layering)
        self.film = facet_film(film_n, film_thickness)
        if self.film is not None:
            self.varies_over_surface = self.varies_over_surface or textured(*self.film)
            if diffuse_layering == "albedo_scaling" and textured(self.n, self.k):
                raise ValueError("diffuse_layering='albedo_scaling' under a thin film needs an n and k that do not "
                                 "vary over the surface (the film's layering albedo is estimated per model)")
            self.flags |= BSDFFlags.RETARDING | BSDFFlags.WAVELENGTH_DEPENDENT

    def _mirror(self, sp: ShadingPoint):
        """(wi, MuellerValue, valid) of the (filmed) mirror, weight 1 (engine.materials.conductor.mirror_reflection)."""
        return mirror_reflection(sp, self._eta(sp), film_at(self.film, sp), self.exterior_n)

    def film_albedo(self, sp: ShadingPoint, cos_o: np.ndarray) -> np.ndarray:
        """(N,) the film's layering albedo at cosθ_o (engine.spectral.film_channels.film_layering_albedo, as
        TorranceSparrow.film_albedo — the same signature; n, κ at each channel's wavelength
        engine.spectral.RGB_WAVELENGTHS_NM, one per channel as in Cycles)."""
        lam = np.asarray(RGB_WAVELENGTHS_NM, np.float64)
        n3 = (self.n.eval(lam) + 1j * self.k.eval(lam))[:, None]
        return film_layering_albedo(cos_o, self.exterior_n, film_at(self.film, sp), n3, layering_wavelengths(sp))

    def lobe_colors(self, sp: ShadingPoint) -> LobeColors | None:
        """The mirror's (MirrorWithDiffuse.lobe_colors) without a film; under one None (Cycles' colour is the
        film's reflectance per channel, its layering weight the largest channel's: not told apart here)."""
        return super().lobe_colors(sp) if self.film is None else None

    def diffuse_scale(self, sp):
        """max(0, 1 − s·E(cosθ_o)) (1, N) under the film (E: ``film_albedo``), else the bare mirror's (L, N)."""
        if self.film is None:
            return super().diffuse_scale(sp)
        E = self.film_albedo(sp, np.clip(sp.cos_o, 0.0, 1.0))
        return np.maximum(1.0 - sp.number(self.s) * E, 0.0)[None, :]

    def describe(self) -> dict:
        out = super().describe()
        if self.film is not None:
            out["thin_film"] = film_label(self.film)
        return out


# --------------------------------------------------------------------------- declaration

#: Largest weight of either lobe: far beyond any physical use, small enough for finite pixels.
MAX_WEIGHT = 1e6

DECLARATION = ModelDeclaration(
    "torrance_sparrow", "Torrance–Sparrow",
    "Rough microfacet reflection (Beckmann or GGX facets, complex index) with an optional Lambertian part",
    [N, K, METAL,
     Parameter("m", f"roughness: the Beckmann rms slope (= Mitsuba α, SCATMECH s) or the GGX α; below "
                    f"{SMOOTH_LIMIT:g} (e.g. 0) the smooth limit: a Fresnel mirror; a texture ≥ {ALPHA_MIN:g} "
                    "everywhere", lo=0.0, hi=100.0, texturable=True,
               socket=Socket("Roughness", "FLOAT", 0.1, 0.0, 5.0,
                             "Beckmann rms slope m (Mitsuba's α); 0 = smooth mirror")),
     Parameter("distribution", "microfacet distribution (GGX: Cycles' and Blender's)", kind="choice",
               choices=SCENE_DISTRIBUTIONS, default="beckmann"),
     Parameter("shadowing", "shadowing-masking (default: 'ts' for Beckmann, 'smith_correlated' — Cycles' — for "
                            "GGX)", kind="choice", choices=SHADOWING, default=None),
     Parameter("multiscatter", "add the energy of multiple scattering between facets as a depolarised term, as "
                               "Cycles' Multiscatter GGX (needs distribution 'ggx', a Smith shadowing, m ≤ 1)",
               kind="bool", default=False),
     Parameter("diffuse_albedo", "albedo of the added Lambertian part", kind="spectrum", spectrum="reflectance",
               lo=0.0, hi=1.0, default=0.0, texturable=True,
               socket=Socket("Diffuse", "COLOR", (0.0, 0.0, 0.0), 0.0, 1.0,
                             "Albedo of an added Lambertian (depolarising) part")),
     Parameter("diffuse_weight", "weight d of the Lambertian part (default 1 where diffuse_albedo is given)",
               lo=0.0, hi=MAX_WEIGHT, default=0.0, texturable=True),
     Parameter("specular_weight", "weight s of the facet part", lo=0.0, hi=MAX_WEIGHT, default=1.0,
               texturable=True),
     Parameter("diffuse_layering", "how the Lambertian part combines with the facet part: added, or weighted "
                                   "by one minus the facet part's albedo at the view direction (Cycles' "
                                   "Principled; not reciprocal)", kind="choice", choices=DIFFUSE_LAYERINGS,
               default="add"),
     THIN_FILM_THICKNESS.with_(doc="a thin film on every facet, or on the mirror at m = 0 (0: none; Airy's sum "
                                   "over the film on the substrate replaces the Fresnel matrix)"),
     THIN_FILM_IOR,
     exterior_n_parameter(socket=Socket("Exterior IOR", "FLOAT", 1.0, 1.0, 3.0,
                                        "Index of the medium above the surface (1 = air, 1.33 = water)"))],
    catalogue="torrance_sparrow", node="TORRANCE_SPARROW")


DECLARATION.per_point = frozenset({"n", "k", "m", "diffuse_albedo", "diffuse_weight", "specular_weight",
                                   "thin_film_thickness", "thin_film_ior"})


@DECLARATION.builder
def _torrance_sparrow(p):
    n, k = complex_index(p)
    shadowing, distribution, multiscatter = p["shadowing"], p["distribution"], p["multiscatter"]
    if shadowing == "smith_rational" and distribution == "ggx":
        raise SceneError(p.field("shadowing"), "'smith_rational' (Walter's rational Beckmann G1) exists for "
                                               "distribution 'beckmann' only")
    if multiscatter and distribution != "ggx":
        raise SceneError(p.field("multiscatter"), "needs distribution 'ggx' (Cycles' Multiscatter GGX; the albedo "
                                                  f"tables are GGX's), got {distribution!r}")
    if multiscatter and shadowing not in (None,) + MULTISCATTER_SHADOWING:
        raise SceneError(p.field("multiscatter"), f"needs shadowing {' or '.join(map(repr, MULTISCATTER_SHADOWING))} "
                                                  f"(the albedo tables are of the Smith lobes), got {shadowing!r}")
    m, smooth = declared_slope(p, "m")        # (the one range check of m; textured: ≥ ALPHA_MIN everywhere)
    m_hi = m.hi if isinstance(m, TexturedNumber) else m
    if multiscatter and not m_hi <= ALPHA_MAX:
        raise SceneError(p.field("m"), f"must be at most {ALPHA_MAX:g} with multiscatter (Cycles clamps GGX α to 1; "
                                       f"the albedo tables span [0, 1]), got {m_hi:g}")
    kw = dict(exterior_n=p["exterior_n"], diffuse_albedo=p["diffuse_albedo"],
              diffuse_weight=p.get("diffuse_weight", 1.0 if p.given("diffuse_albedo") else 0.0),
              specular_weight=p["specular_weight"], diffuse_layering=p["diffuse_layering"])
    film = facet_film(p["thin_film_ior"], p["thin_film_thickness"]) is not None     # (the ior validated always)
    film_n = p["thin_film_ior"]
    if film:
        kw.update(film_n=film_n, film_thickness=p["thin_film_thickness"])
    if smooth:   # effectively smooth (roughness.SMOOTH_LIMIT): a Fresnel mirror (plus the Lambertian part); E = 1
        if film:
            return FilmedMirrorWithDiffuse(n, k, **kw)
        # GGX: Cycles' layering estimate at roughness 0 (a Principled specular layer)
        return MirrorWithDiffuse(n, k, cycles_estimate=distribution == "ggx", **kw)
    return TorranceSparrow(n, k, m, shadowing=shadowing, distribution=distribution, multiscatter=multiscatter, **kw)
