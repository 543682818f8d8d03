"""Rough dielectric interface: polarising microfacet reflection and refraction (Walter et al. 2007).

Two-sided like engine.materials.dielectric: the interior (index ``n``) lies behind the shading
normal, the exterior (``exterior_n``) in front.  Everything is computed in a local frame whose +z
is the normal on the viewer's side, with the real relative index η = n_far / n_viewer (the far
side is behind that normal), i.e. η = n/exterior_n for a viewer outside and its inverse inside.

Reflection (ω_i on the viewer's side), h = unit(ω_i + ω_o):

    f_r = M_F(ω_i·h; η) · D(h) G(ω_i, ω_o, h) / (4 |cosθ_i| cosθ_o)

M_F is the Fresnel reflection matrix (docs/physics.md §0) at the facet angle; inside the denser medium
beyond the facet's critical angle it is a pure retarder (total internal reflection: S ≠ 0,
circular polarisation appears).

Refraction (ω_i on the far side), generalised half vector h = ±unit(η ω_i + ω_o) with h_z > 0:

    f_t = M_T(ω_o·h; η) · |ω_i·h| (ω_o·h) D(h) G / (|cosθ_i| cosθ_o (η ω_i·h + ω_o·h)²)

M_T is the Fresnel diattenuator A = (T_s+T_p)/2, B = (T_s−T_p)/2, C = √(T_s T_p), S = 0 at the
facet (T_s, T_p are the same seen from either side).  This is Walter's radiance BTDF (his Eq. 21,
n_o²/(n_i ω_i·h + n_o ω_o·h)² = 1/(η ω_i·h + ω_o·h)²): the radiance scaling of refraction for a
camera-traced path, (n_o/n_i)² = 1/η² as in the smooth dielectric, is *inside the function value*
(so next-event estimation through the interface needs nothing else); for α → 0 the lobe integrates
to T/η², the smooth dielectric's weight.  Reciprocity (Veach's f/n_o² symmetry): with the viewer
in medium a and the light in b, η = n_b/n_a, η²·f(ω_o = a, ω_i = b) = f(ω_o = b, ω_i = a).

Frames: both lobes are ABCS matrices in the scattering-plane frames x_in = x_out = s = unit(k_i ×
k_o), k_i = −ω_i, k_o = ω_o; s is ⟂ the plane of ω_i, ω_o and h (the facet's plane of incidence),
so these are the facet's s-p frames (docs/physics.md §1).  Where k_i ∥ k_o the facet is at normal
incidence (an isotropic diattenuator or F·diag(1,1,−1,−1)), the same in every frame.

D: Beckmann (roughness α = the thesis's m) or GGX (α).  G: **separable** Smith
G = G1(ω_i, h)·G1(ω_o, h) with the exact G1 of the distribution (χ⁺ per direction: (ω·h)·cosθ_ω >
0), or Walter's rational Beckmann G1 (``smith_rational``, Mitsuba 3's ``roughdielectric``).

Sampling: a facet normal from the visible normals of ω_o (exact VNDF density for both
distributions), then reflection with probability F = (F_s+F_p)/2 at ω_o·h (1 under TIR), otherwise
refraction through h.  pdf: F·D_ωo(h)/(4 ω_o·h) for reflection, (1 − F)·D_ωo(h)·η²|ω_i·h|/(η ω_i·h
+ ω_o·h)² for refraction.  The sample weight is f·|cosθ_i|/pdf; ``eta_sq`` = η² on refraction (for
Russian roulette).  The index is one number (no dispersion): λ-independent.

Multiple scattering (``multiscatter``, GGX only; default off): Cycles' "Multiscatter GGX" glass
(albedo scaling, Kulla & Conty 2017; engine.materials.ggx_energy) divides the single-scattering lobes by
E(cosθ_o), their total directional albedo (reflection plus refraction with this interface's own
unpolarised Fresnel, as energy: without the 1/η² of radiance) seen from the viewer's side, so that a
clear interface returns all the light it receives.  Here the added (1/E − 1)·M00 is a **depolarised**
term (MuellerValue.depol): light scattered between facets more than once is taken as unpolarised, the
single-scattering Mueller matrices are untouched and the sum stays realisable; S0 for unpolarised light
is Cycles'.  E is tabulated once per (index, α) over √cosθ_o for both sides (exact in both, where Cycles
interpolates a 16³ table).  Not reciprocal (the scale depends on ω_o only), as in Cycles.  Beckmann
facets are refused with it: Cycles has no multiple-scattering Beckmann and its tables are GGX's.
Sampling is unchanged; the weight is the compensated f·|cosθ_i|/pdf.

Roughness per point (``alpha`` a TexturedNumber, e.g. the Principled BSDF's Roughness texture: α = r² at each
point): every formula above is elementwise in α, so each point gets exactly the constant-α lobe of its own
value (the compiled passes read α per path); the compensation's E is then bilinear in (√cosθ_o, √α) between
the per-α tables at the conductor table's roughness nodes (engine.materials.ggx_energy.DielectricAlbedoRange).

Index per point (``n`` a TexturedNumber or NumberSpectrum, e.g. the Principled IOR from a texture, all values on
one side of ``exterior_n``): every formula above is elementwise in η as well, so each point gets exactly the
constant-index lobe of its own value (the compiled passes read η per path); the compensation's E is then linear in
c = F0^¼ between per-index tables (engine.materials.ggx_energy.DielectricAlbedoIndex; a texture of one value: that
index's own table).  Where a point's index equals ``exterior_n`` exactly the interface is not there (the BTDF's
η → 1 limit is a delta): those points pass light straight through as the smooth dielectric does
(``index_matched``), a Dirac lobe of the sample (is_delta) and nothing in eval and pdf.

Thin film (``film_n``, ``film_thickness`` nm; Cycles' Thin Film on a rough Glass BSDF or Principled transmission): on
every facet Airy's sum over the film (engine.polarisation.thin_film, between the viewer's medium and the far one)
replaces M_F, and the refraction is the lossless film's transmission, 1 − R per polarisation (C = √(T_s T_p),
S = 0), as on the smooth thin-film dielectric; per wavelength, so the lobe is chosen by the reflectance averaged over
the path's wavelengths (as the smooth one's) and pdf uses that average.  These lobes run as the NumPy steps below
(the compiled passes take one λ-independent Fresnel); the multiple-scattering term keeps the unfilmed interface's E,
as Cycles' (its glass table has no film).

Implementation: eval, pdf and sample are one compiled pass each over the batch
(engine.kernels.rough_dielectric); the NumPy references are ``_eval``, ``_pdf_local`` and ``_sample``
of this module, declared with kernels.twin.
"""

from __future__ import annotations

import math

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, MuellerValue, ShadingPoint
from .conductor import THIN_FILM_IOR, THIN_FILM_THICKNESS
from .dielectric import IOR_SOCKET, SmoothDielectric, checked_index, index_at, one_side_of, per_point_index
from .ggx import GGX
from .ggx_energy import ALPHA_MAX, DielectricAlbedo, DielectricAlbedoIndex, DielectricAlbedoRange
from .microfacet import Beckmann, reflect_local
from .parameters import ModelDeclaration, Parameter, Socket, exterior_n_parameter
from .roughness import SMOOTH_LIMIT, checked_alpha, declared_slope
from .sampling import local_to_world
from ..errors import SceneError
from ..kernels import twin
from ..kernels.rough_dielectric import (rough_dielectric_eval_numba, rough_dielectric_pdf_numba,
                                        rough_dielectric_sample_numba)
from ..polarisation.frames import scattering_plane_axis
from ..polarisation.fresnel import fresnel_reflection_abcs, fresnel_transmission_abcs
from ..polarisation.thin_film import facet_film, film_at, film_label, film_reflection_abcs, film_transmission_abcs
from ..textures import TexturedNumber
from ..vec3 import dot, local_frame, to_local

DISTRIBUTIONS = ("beckmann", "ggx")
SHADOWING = ("smith", "smith_rational")


# --------------------------------------------------------------------------- the batched steps
# eval, pdf and sample as functions of the batch (``dist``: the facet distribution, ``rational``:
# Walter's rational Beckmann G1, ``n_int``/``n_ext``: the indices behind/in front of the shading
# normal).  The twins below run them as one compiled pass each (engine.kernels.rough_dielectric).

def _local(n_s, wo, n_int, n_ext, wi=None):
    """(normal on the viewer's side, η, ω_o local[, ω_i local])."""
    outside = dot(n_s, wo) >= 0
    eta = np.where(outside, n_int / n_ext, n_ext / n_int)
    nn = np.where(outside[None, :], n_s, -n_s)
    t, b = local_frame(nn)
    wo_l = to_local(wo, t, b, nn)
    if wi is None:
        return nn, eta, wo_l
    return nn, eta, wo_l, to_local(wi, t, b, nn)


def _half_vector(wi_l, wo_l, eta):
    """Facet normal h (h_z ≥ 0) of the pair, whether it reflects, and validity (N,)."""
    refl = wi_l[2] > 0
    hv = np.where(refl[None, :], wi_l + wo_l, -(eta * wi_l + wo_l))
    length = np.sqrt(np.sum(hv * hv, axis=0))
    ok = (length > 1e-12) & (wo_l[2] > 0) & (wi_l[2] != 0)
    h = hv / np.where(ok, length, 1.0)
    h = np.where((h[2] < 0)[None, :], -h, h)
    d_o = np.sum(wo_l * h, axis=0)
    d_i = np.sum(wi_l * h, axis=0)
    # reflection: both on the facet's front; refraction: ω_o in front, ω_i behind
    ok &= (d_o > 0) & np.where(refl, d_i > 0, d_i < 0) & (h[2] > 0)
    return h, refl, ok, d_i, d_o


def _tir(c, eta):
    """(N,) bool: total internal reflection at facets of incidence cosines c (no refracted direction)."""
    c = np.clip(c, 0.0, 1.0)
    return (1.0 - c * c) / (eta * eta) > 1.0


def _eval(dist, rational, n_s, wo, wi, L, n_int, n_ext, no_fresnel=False, film=None):
    """(x, A, B, C, S): the facet reflection or refraction in the scattering-plane frame x (3, N), (L, N);
    ``no_fresnel``: no reflection, the refraction the identity (0 under total internal reflection); ``film``: a
    function of the facet cosines c (N,) giving the coated facet's reflection (A, B, C, S) (L, N) seen from the
    viewer's side (RoughDielectric._film_fresnel), its transmission 1 − R per polarisation."""
    _, eta, wo_l, wi_l = _local(n_s, wo, n_int, n_ext, wi)
    h, refl, ok, d_i, d_o = _half_vector(wi_l, wo_l, eta)
    D = dist.D(h)
    G = dist.G1(wi_l, h, rational) * dist.G1(wo_l, h, rational)
    ci = np.abs(wi_l[2])
    co = wo_l[2]
    ok = ok & (ci * co > 0)          # a product underflowing to 0 (both directions at grazing): f = 0, not 0/0
    den_cos = np.where(ok, ci * co, 1.0)
    jac = eta * d_i + d_o
    jac2 = np.where(ok & ~refl, jac * jac, 1.0)
    scalar_r = D * G / (4.0 * den_cos)
    scalar_t = np.abs(d_i) * d_o * D * G / (den_cos * jac2)
    scalar = np.where(ok, np.where(refl, scalar_r, scalar_t), 0.0)
    # facet Fresnel: reflection at ω_i·h (= ω_o·h), transmission seen from ω_o (T is symmetric)
    c_f = np.where(ok, np.where(refl, d_i, d_o), 1.0)
    Ar, Br, Cr, Sr = fresnel_reflection_abcs(c_f, eta)
    At, Bt, Ct, St = fresnel_transmission_abcs(c_f, eta)
    if no_fresnel:              # Cycles' Refraction BSDF (engine.materials.refraction)
        one = np.where(refl | _tir(c_f, eta), 0.0, 1.0)
        zero = np.zeros_like(one)
        Ar, Br, Cr, Sr = zero, zero, zero, zero
        At, Bt, Ct, St = one, zero, one, zero
    n = n_s.shape[1]
    x = scattering_plane_axis(-wi, wo)
    if film is not None:        # Airy's sum over the film on every facet, per wavelength
        R = film(c_f)
        T = film_transmission_abcs(R[0] + R[1], R[0] - R[1])
        return (x, *(np.where(refl, r, t) * scalar for r, t in zip(R, T)))
    tile = lambda r, t: np.broadcast_to(np.where(refl, r, t) * scalar, (L, n)).copy()  # noqa: E731
    return x, tile(Ar, At), tile(Br, Bt), tile(Cr, Ct), tile(Sr, St)


def _pdf_local(dist, wi_l, wo_l, eta, no_fresnel=False, film=None):
    h, refl, ok, d_i, d_o = _half_vector(wi_l, wo_l, eta)
    vndf = dist.pdf(wo_l, h)
    if film is not None:        # the lobe chosen by the film's reflectance averaged over the path's wavelengths
        F = film(np.where(ok, d_o, 1.0))[0].mean(axis=0)
    elif no_fresnel:
        F = np.where(_tir(np.where(ok, d_o, 1.0), eta), 1.0, 0.0)
        ok = ok & ~refl
    else:
        F = fresnel_reflection_abcs(np.where(ok, d_o, 1.0), eta)[0]
    jac = eta * d_i + d_o
    jac2 = np.where(ok & ~refl, jac * jac, 1.0)
    p_r = F * vndf / (4.0 * np.where(ok, d_o, 1.0))
    p_t = (1.0 - F) * vndf * eta * eta * np.abs(d_i) / jac2
    return np.where(ok, np.where(refl, p_r, p_t), 0.0)


def _sample(dist, rational, n_s, wo, u_lobe, u_dir, L, n_int, n_ext, no_fresnel=False, film=None):
    """(wi, pdf, valid, eta_sq, x, A, B, C, S): the sampled direction, its pdf (0 where invalid), η² on
    refraction (1 on reflection) and the weight f·|cosθ_i|/pdf."""
    nn, eta, wo_l = _local(n_s, wo, n_int, n_ext)
    front = wo_l[2] > 0
    wo_s = np.where(front[None, :], wo_l, np.array([[0.0], [0.0], [1.0]]))
    h = dist.sample(wo_s, u_dir)
    c = np.clip(np.sum(wo_s * h, axis=0), 0.0, 1.0)
    if film is not None:
        F = film(c)[0].mean(axis=0)
    elif no_fresnel:                                # (a "reflection" then: no lobe, the sample is invalid)
        F = np.where(_tir(c, eta), 1.0, 0.0)
    else:
        F = fresnel_reflection_abcs(c, eta)[0]      # 1 under total internal reflection
    reflect = u_lobe < F
    wi_r = reflect_local(wo_s, h)
    inv_eta = 1.0 / eta
    cos_t = np.sqrt(np.maximum(1.0 - (1.0 - c * c) * inv_eta * inv_eta, 0.0))
    wi_t = -wo_s * inv_eta + (c * inv_eta - cos_t) * h
    wi_l = np.where(reflect[None, :], wi_r, wi_t)
    wi_l = wi_l / np.sqrt(np.sum(wi_l * wi_l, axis=0))
    wi = local_to_world(wi_l, nn)
    pdf = _pdf_local(dist, wi_l, wo_s, eta, no_fresnel, film)
    valid = front & (pdf > 0) & np.where(reflect, wi_l[2] > 0, wi_l[2] < 0) & np.all(np.isfinite(wi), axis=0)
    x, A, B, C, S = _eval(dist, rational, n_s, wo, wi, L, n_int, n_ext, no_fresnel, film)
    factor = np.where(valid, np.abs(wi_l[2]) / np.where(valid, pdf, 1.0), 0.0)[None, :]
    eta_sq = np.where(reflect, 1.0, eta * eta)
    return wi, np.where(valid, pdf, 0.0), valid, eta_sq, x, A * factor, B * factor, C * factor, S * factor


def _distribution(distribution: str, alpha):
    """The facet distribution of roughness α: a number, or (N,) one per path (a textured roughness)."""
    kind = Beckmann if distribution == "beckmann" else GGX
    return kind.per_point(alpha) if np.ndim(alpha) else kind(alpha)


def rough_dielectric_eval_numpy(n_s, wo, wi, L, n_int, n_ext, distribution, rational, alpha, no_fresnel=False):
    """(x, A, B, C, S) of ``_eval``."""
    return _eval(_distribution(distribution, alpha), rational, n_s, wo, wi, L, n_int, n_ext, no_fresnel)


def rough_dielectric_pdf_numpy(n_s, wo, wi, n_int, n_ext, distribution, alpha, no_fresnel=False):
    """The pdf (N,) of ω_i under ``_sample``."""
    _, eta, wo_l, wi_l = _local(n_s, wo, n_int, n_ext, wi)
    return _pdf_local(_distribution(distribution, alpha), wi_l, wo_l, eta, no_fresnel)


def rough_dielectric_sample_numpy(n_s, wo, u_lobe, u_dir, L, n_int, n_ext, distribution, rational, alpha,
                                  no_fresnel=False):
    """(wi, pdf, valid, eta_sq, x, A, B, C, S) of ``_sample``."""
    return _sample(_distribution(distribution, alpha), rational, n_s, wo, u_lobe, u_dir, L, n_int, n_ext, no_fresnel)


rough_dielectric_eval = twin(rough_dielectric_eval_numba, rough_dielectric_eval_numpy)
rough_dielectric_pdf = twin(rough_dielectric_pdf_numba, rough_dielectric_pdf_numpy)
rough_dielectric_sample = twin(rough_dielectric_sample_numba, rough_dielectric_sample_numpy)


def index_matched(n, exterior_n: float) -> bool:
    """True for an interface between equal indices: it scatters nothing at any roughness (light passes
    straight through: the BTDF's η → 1 limit is a delta), which the smooth dielectric renders exactly;
    the microfacet formulas degenerate there (the half vector η ω_i + ω_o of the one direction is 0).
    An index per point is matched only where it is exterior_n everywhere (elsewhere: RoughDielectric's
    pass-through at its matched points)."""
    if per_point_index(n):
        return n.lo == n.hi == float(exterior_n)
    return float(n) == float(exterior_n)


class RoughDielectric(BSDF):
    """Polarising rough dielectric (see the module docstring)."""

    name = "rough_dielectric"
    flags = (BSDFFlags.GLOSSY_REFLECTION | BSDFFlags.GLOSSY_TRANSMISSION | BSDFFlags.POLARISING
             | BSDFFlags.RETARDING)
    #: Cycles' Refraction BSDF (engine.materials.refraction): no Fresnel, no reflection lobe
    no_fresnel = False

    def __init__(self, n, alpha: float, distribution: str = "beckmann", shadowing: str = "smith",
                 exterior_n: float = 1.0, multiscatter: bool = False, film_n=None, film_thickness=0.0):
        # the index: a number, or per point (a TexturedNumber / NumberSpectrum: a Principled IOR texture)
        self.n_int = checked_index(n)
        self.n_ext = float(exterior_n)
        self.per_point_index = per_point_index(self.n_int)
        n_lo, n_hi = (self.n_int.lo, self.n_int.hi) if self.per_point_index else (self.n_int, self.n_int)
        for name, v in (("n", n_lo), ("exterior_n", self.n_ext)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        if n_lo < self.n_ext < n_hi:
            raise ValueError(f"an index per point must lie on one side of exterior_n = {self.n_ext:g}, got values "
                             f"in [{n_lo:g}, {n_hi:g}]")
        #: some point's index equals exterior_n (no interface there: the smooth dielectric's pass-through)
        self._matched_somewhere = self.per_point_index and n_lo <= self.n_ext <= n_hi
        # α: a number, or per point (a TexturedNumber: a Principled roughness texture, α = r² per point)
        self.per_point = isinstance(alpha, TexturedNumber)
        self.alpha = checked_alpha(alpha, "roughness alpha")      # (≥ roughness.ALPHA_MIN everywhere)
        self.varies_over_surface = self.per_point or self.per_point_index
        if self._matched_somewhere:
            self.flags = self.flags | BSDFFlags.DELTA_TRANSMISSION
        if distribution not in DISTRIBUTIONS:
            raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {distribution!r}")
        if shadowing not in SHADOWING:
            raise ValueError(f"shadowing must be one of {SHADOWING}, got {shadowing!r}")
        if shadowing == "smith_rational" and distribution != "beckmann":
            raise ValueError("shadowing 'smith_rational' exists for the beckmann distribution only")
        self.distribution, self.shadowing = distribution, shadowing
        self.dist = None if self.per_point else _distribution(distribution, self.alpha)
        self.multiscatter = bool(multiscatter)
        # a thin film on every facet (Cycles' Thin Film on a rough Glass or Principled transmission): Airy's sum
        # replaces the facets' Fresnel matrices (engine.polarisation.thin_film); None below Cycles' 0.1 nm
        self.film = facet_film(film_n, film_thickness)
        if self.film is not None:
            self.flags = self.flags | BSDFFlags.WAVELENGTH_DEPENDENT
            self.varies_over_surface = self.varies_over_surface or any(isinstance(v, TexturedNumber)
                                                                       for v in self.film)
        self._energy = None
        #: the denser side's compensation as Cycles' (compensate_dense_side_as_cycles); False: energy conserved
        self.cycles_dense_side = False
        if self.multiscatter:
            if distribution != "ggx":
                raise ValueError("multiscatter (Cycles' Multiscatter GGX) needs distribution='ggx'")
            hi = alpha.hi if self.per_point else self.alpha
            if not hi <= ALPHA_MAX:
                raise ValueError(f"multiscatter needs alpha <= {ALPHA_MAX:g} (Cycles clamps GGX alpha to 1), "
                                 f"got {alpha!r}")
            self._index_range = (n_lo, n_hi) if self.per_point_index else None
            self._energy = self._energy_table()

    def _energy_table(self):
        """The compensation's albedo table (engine.materials.ggx_energy) of this interface's index and roughness."""
        lo, hi = (self.alpha.lo, self.alpha.hi) if self.per_point else (self.alpha, self.alpha)
        if self._index_range is not None:
            n_lo, n_hi = self._index_range
            return DielectricAlbedoIndex(n_lo / self.n_ext, n_hi / self.n_ext, (lo, hi) if self.per_point else lo,
                                         self.cycles_dense_side)
        ratio = self.n_int / self.n_ext
        if self.per_point:
            return DielectricAlbedoRange(ratio, lo, hi, self.cycles_dense_side)
        return DielectricAlbedo(ratio, lo, self.cycles_dense_side)

    def compensate_dense_side_as_cycles(self) -> None:
        """Seen from the denser side, compensate as Cycles does (its ggx_glass_inv_E table counts refracted
        directions that no BSDF produces, so a rough interface returns less than all the light there: 0.5–2 % of a
        rough glass sphere's brightness; docs/physics.md).  For Blender's glass, whose reference is Cycles; scene
        files keep the energy-conserving compensation.  No effect without ``multiscatter``."""
        if self.multiscatter and not self.cycles_dense_side:
            self.cycles_dense_side = True
            self._energy = self._energy_table()

    def _alpha(self, sp: ShadingPoint):
        """α at the points: the number, or (N,) for a textured roughness."""
        return sp.number(self.alpha)

    def _n(self, sp: ShadingPoint):
        """The interior index at the points: the number, or (N,) for a textured index."""
        return index_at(self.n_int, sp)

    def _matched(self, sp: ShadingPoint, n) -> np.ndarray | None:
        """(N,) bool: the points whose index equals exterior_n (None where no point's can)."""
        if not self._matched_somewhere:
            return None
        return np.asarray(n) == self.n_ext

    def _multiscatter_depol(self, sp: ShadingPoint, A: np.ndarray, n) -> np.ndarray | None:
        """(1/E(cosθ_o) − 1)·A (L, N), the depolarised multiple-scattering term; None without it."""
        if self._energy is None:
            return None
        cos_o = dot(sp.n_s, sp.wo)
        if self.per_point_index:
            args = (self._alpha(sp),) if self.per_point else ()
            return A * self._energy.extra(np.abs(cos_o), cos_o >= 0, n / self.n_ext, *args)[None, :]
        if self.per_point:
            return A * self._energy.extra(np.abs(cos_o), cos_o >= 0, self._alpha(sp))[None, :]
        return A * self._energy.extra(np.abs(cos_o), cos_o >= 0)[None, :]

    # --- BSDF interface ---------------------------------------------------------------------------

    def _film_fresnel(self, sp: ShadingPoint, n):
        """The coated facets' reflection (A, B, C, S) (L, N) as a function of the facet cosines c (N,), seen from
        the viewer's side of each point (the film between the viewer's medium and the far one); None without a
        film."""
        if self.film is None:
            return None
        outside = sp.cos_o >= 0
        n1 = np.where(outside, self.n_ext, n)[None, :]
        n3 = np.where(outside, n, self.n_ext)[None, :]
        film_n, thickness = film_at(self.film, sp)
        return lambda c: film_reflection_abcs(c[None, :], n1, film_n, thickness, n3, sp.lam)

    def eval(self, sp: ShadingPoint, wi: np.ndarray) -> MuellerValue:
        n = self._n(sp)
        if self.film is not None:        # (NumPy: the compiled passes take a λ-independent Fresnel)
            x, A, B, C, S = _eval(_distribution(self.distribution, self._alpha(sp)), self.shadowing == "smith_rational",
                                  sp.n_s, sp.wo, wi, sp.lam.shape[0], n, self.n_ext, film=self._film_fresnel(sp, n))
        else:
            x, A, B, C, S = rough_dielectric_eval(sp.n_s, sp.wo, wi, sp.lam.shape[0], n, self.n_ext,
                                                  self.distribution, self.shadowing == "smith_rational",
                                                  self._alpha(sp), self.no_fresnel)
        return MuellerValue("abcs", x, x, A, B, C, S, depol=self._multiscatter_depol(sp, A, n))

    def refraction_eta_sq(self, sp: ShadingPoint) -> np.ndarray:
        eta = self._n(sp) / self.n_ext
        return np.where(sp.cos_o >= 0, eta * eta, 1.0 / (eta * eta))

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        if self.film is not None:
            n = self._n(sp)
            _, eta, wo_l, wi_l = _local(sp.n_s, sp.wo, n, self.n_ext, wi)
            return _pdf_local(_distribution(self.distribution, self._alpha(sp)), wi_l, wo_l, eta,
                              film=self._film_fresnel(sp, n))
        return rough_dielectric_pdf(sp.n_s, sp.wo, wi, self._n(sp), self.n_ext, self.distribution, self._alpha(sp),
                                    self.no_fresnel)

    def sample(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        n = self._n(sp)
        if self.film is not None:
            wi, pdf, valid, eta_sq, x, A, B, C, S = _sample(
                _distribution(self.distribution, self._alpha(sp)), self.shadowing == "smith_rational", sp.n_s, sp.wo,
                u_lobe, u_dir, sp.lam.shape[0], n, self.n_ext, film=self._film_fresnel(sp, n))
        else:
            wi, pdf, valid, eta_sq, x, A, B, C, S = rough_dielectric_sample(
                sp.n_s, sp.wo, u_lobe, u_dir, sp.lam.shape[0], n, self.n_ext, self.distribution,
                self.shadowing == "smith_rational", self._alpha(sp), self.no_fresnel)
        weight = MuellerValue("abcs", x, x, A, B, C, S, depol=self._multiscatter_depol(sp, A, n))
        sample = BSDFSample(wi=wi, weight=weight, pdf=pdf, is_delta=np.zeros(sp.n, bool), valid=valid, eta_sq=eta_sq)
        matched = self._matched(sp, n)
        if matched is not None and matched.any():
            self._pass_through(sp, u_lobe, u_dir, np.flatnonzero(matched), sample)
        return sample

    def _pass_through(self, sp: ShadingPoint, u_lobe, u_dir, at: np.ndarray, sample: BSDFSample) -> None:
        """At the index-matched points ``at``: the smooth dielectric's sample (light straight through, a Dirac
        lobe), written into ``sample`` in place."""
        smooth = SmoothDielectric(self.n_ext, self.n_ext).sample(sp.take(at), u_lobe[at], u_dir[:, at])
        w, v = sample.weight, smooth.weight
        sample.wi[:, at] = smooth.wi
        w.x_in[:, at], w.x_out[:, at] = v.x_in, v.x_out
        for name in "ABCS":
            getattr(w, name)[:, at] = getattr(v, name)
        if w.depol is not None:
            w.depol[:, at] = 0.0
        sample.pdf[at], sample.is_delta[at], sample.valid[at] = 0.0, True, smooth.valid
        sample.eta_sq[at] = smooth.eta_sq

    def describe(self) -> dict:
        out = {"type": self.name, "n": repr(self.n_int) if self.per_point_index else self.n_int,
               "alpha": repr(self.alpha) if self.per_point else self.alpha,
               "distribution": self.distribution,
               "shadowing": self.shadowing, "exterior_n": self.n_ext}
        if self.multiscatter:
            out["multiscatter"] = "cycles_dense_side" if self.cycles_dense_side else True
        if self.film is not None:
            out["thin_film"] = film_label(self.film)
        return out

    def lobe_colors(self, sp: ShadingPoint):
        """Cycles' glass colours (engine.materials.glass_colors.rough_glass_colors) for a constant index and
        roughness; None where either varies over the surface."""
        if self.per_point or self.per_point_index:
            return None
        from .glass_colors import rough_glass_colors
        return rough_glass_colors(sp, self.n_int / self.n_ext, self.alpha)


# --------------------------------------------------------------------------- declaration

DECLARATION = ModelDeclaration(
    "rough_dielectric", "Rough Dielectric",
    "Frosted glass: microfacet reflection and refraction (Walter 2007), polarising per facet",
    [Parameter("n", "real index of the material", lo=0.0, lo_open=True, socket=IOR_SOCKET, texturable=True),
     Parameter("alpha", f"microfacet roughness α (Beckmann rms slope or GGX α); below {SMOOTH_LIMIT:g} (e.g. 0) "
                        "the smooth dielectric", lo=0.0, hi=10.0, default=0.1, texturable=True,
               socket=Socket("Roughness", "FLOAT", 0.1, 0.0, 2.0,
                             "Microfacet roughness α (Beckmann rms slope / GGX α); 0 = smooth glass")),
     Parameter("distribution", "microfacet distribution", kind="choice", choices=DISTRIBUTIONS,
               default="beckmann"),
     Parameter("shadowing", "Smith shadowing-masking (separable; rational = Walter's Beckmann approximation)",
               kind="choice", choices=SHADOWING, default="smith"),
     Parameter("multiscatter", "add the energy of multiple scattering between facets as a depolarised term, as "
                               "Cycles' Multiscatter GGX glass (needs distribution 'ggx' and alpha ≤ 1)",
               kind="bool", default=False),
     THIN_FILM_THICKNESS.with_(doc="a thin film on every facet, or on the smooth interface (0: none; Airy's sum over "
                                   "the film replaces the Fresnel matrices, transmission 1 − R per polarisation)"),
     THIN_FILM_IOR,
     exterior_n_parameter()],
    catalogue="rough_dielectric", node="ROUGH_DIELECTRIC")

#: the index and the roughness may vary per point (Blender's Glass BSDF with linked IOR, Roughness; every formula is
#: elementwise, the Principled transmission's machinery)
DECLARATION.per_point = frozenset({"n", "alpha", "thin_film_thickness", "thin_film_ior"})


@DECLARATION.builder
def _rough_dielectric(p):
    alpha, smooth = declared_slope(p, "alpha")        # (the one range check of α)
    distribution, shadowing = p["distribution"], p["shadowing"]
    if shadowing == "smith_rational" and distribution != "beckmann":
        raise SceneError(p.field("shadowing"), "'smith_rational' exists for distribution 'beckmann' only")
    multiscatter = p["multiscatter"]
    n = one_side_of(p, "n", p["exterior_n"])
    if multiscatter and distribution != "ggx":
        raise SceneError(p.field("multiscatter"), "needs distribution 'ggx' (Cycles' Multiscatter GGX; Cycles has "
                                                  f"no multiple-scattering Beckmann), got {distribution!r}")
    top = alpha.hi if isinstance(alpha, TexturedNumber) else alpha
    if multiscatter and top > ALPHA_MAX:
        raise SceneError(p.field("alpha"), f"must be at most {ALPHA_MAX:g} with multiscatter (Cycles clamps GGX α "
                                           f"to 1; the albedo tables span [0, 1]), got {top:g}")
    film_n, thickness = p["thin_film_ior"], p["thin_film_thickness"]       # (the index validated always)
    film = facet_film(film_n, thickness) is not None
    if smooth and film:                             # a smooth coated interface: the thin-film dielectric
        from .thin_film import ThinFilmDielectric
        return ThinFilmDielectric(n, film_n, thickness, p["exterior_n"])
    if smooth or index_matched(n, p["exterior_n"]):   # the smooth limit, or no interface at all
        return SmoothDielectric(n, p["exterior_n"])
    return RoughDielectric(n, alpha, distribution, shadowing, p["exterior_n"], multiscatter=multiscatter,
                           **({"film_n": film_n, "film_thickness": thickness} if film else {}))


def compensate_dense_sides_as_cycles(bsdf) -> None:
    """In place: every rough dielectric in ``bsdf`` (mixes, layers, wrappers) compensates its denser side as
    Cycles (RoughDielectric.compensate_dense_side_as_cycles): what Blender's materials render with."""
    from .batching import bsdfs_within
    for m in bsdfs_within(bsdf):
        if isinstance(m, RoughDielectric):
            m.compensate_dense_side_as_cycles()
