"""Weidlich–Wilkie (2007) layered polarising BRDF ("weidlich_wilkie").

A stack of dielectric coats (real index, optional absorption, smooth or rough
top interface) over *any* other engine BSDF (Lambert, SmoothConductor,
TorranceSparrow, HTSG, another WeidlichWilkie).  Physics as fixed by
docs/physics.md §3 (Chapter 5 errata) and §5; symbols as there.

Geometry (docs/physics.md §0): ω_i = ``wi`` to the light, ω_o = ``sp.wo`` to the
viewer, n = shading normal, η = n_coat / n_exterior (real).  One-sided: zero
unless cosθ_i > 0 and cosθ_o > 0.

Published form (``form="published"``, WW 2007 / thesis Eq. 5.1–5.3 with the errata)
------------------------------------------------------------------------------------
    f = f_top(ω_i, ω_o) + T12 · f_base(ω'_i, ω'_o) · a · t

- f_top: the coat's Torrance–Sparrow reflection M_F(ω_i·h)·D(h)·G/(4cosθ_i cosθ_o)
  (Blinn D = (e+2)/(2π)cos^eθ_h or Beckmann D with m; V-cavity G by default), the
  Fresnel Mueller matrix in the facet (scattering-plane) frames.  A *smooth* coat has
  no f_top function: its mirror is the Dirac lobe of ``delta_reflection``.
- m, the transmission normal: the facet normal h = unit(ω_i + ω_o) for a rough coat
  (``transmission_normal="facet"``, WW's choice) or the macro normal n ("macro";
  always n for a smooth coat).  ω'_i, ω'_o are ω_i, ω_o refracted through m into the
  coat (Snell with η), both pointing away from the base; they are the base's in/out
  directions (the base is called through its own ``eval`` with a ShadingPoint whose
  ``wo`` is ω'_o).  Where a refracted direction falls below the macro horizon the
  layer term is 0.
- T12 = 1 − F(η; ω_i·m).
- a = exp(−αd(1/cosθ'_i + 1/cosθ'_o)), cosθ' against the macro normal (erratum 5.2),
  αd = Coat.absorption · Coat.thickness (dimensionless optical depth).
- t = 1 − F21(ω'_o·m)·G_int (``t_term="ww"``; = (1−G) + T21·G), G_int the shadowing
  term of the internal directions with h' = unit(ω'_i + ω'_o); ``t_term="t21"`` gives
  t = 1 − F21 = T21.  For a smooth coat G_int ≡ 1 (no cavities), so t = T21.
  F21(ω'_o·m) with 1/η equals F(η; ω_o·m) (no TIR: ω'_o is a refracted ray), which is
  how it is computed.

Polarisation of the layer term (erratum 5.7/5.8)
------------------------------------------------
    M_layer = a · [X21] · R2 · M_base(ω'_i→ω'_o) · R1 · [E12]

- E12 is the Fresnel transmission diattenuator of the entry (engine.polarisation.fresnel
  ``fresnel_transmission_abcs``: A = (T_s+T_p)/2, B = (T_s−T_p)/2, C = √(T_sT_p), S = 0)
  in the m-plane frames x = s1 = unit(m × k_i) (shared by the incident and refracted
  beams); X21 the exit diattenuator in x = s2 = unit(m × ω_o).  R1, R2 are the explicit
  frame rotations into/out of the base's own frames (``rotation_mueller``).  The product
  is in general not block-diagonal (M02, M12 ≠ 0 off-plane).  (Special case: refraction
  through h keeps ω'_i, ω'_o in the plane of ω_i, ω_o, so with a depolarising or
  scattering-plane base — Lambert, TS — it is block-diagonal in the scattering-plane
  frames, though not in the s-p frames of the macro normal.)  For a depolarising base it
  is rank 1: (ρ/π)·a·col₀(X21)·row₀(E12), p-polarised (B < 0, T_p > T_s).
- **Magnitudes.**  WW's t *replaces* T21 (docs/physics.md "missing"), so the exit is
  X21 = t · M̂_T21 with M̂_T21 = M_T21/T21 the unit-throughput diattenuator of the exit
  facet (same diattenuation and C/A as the Fresnel transmission, M00 = 1).  Taking
  docs/physics.md's M_layer = a·t·M_T21·R·M_base·R·M_T12 literally would give
  M00 = T12·T21·t·a·f_base, i.e. T21 twice, and would not reproduce the published
  scalar (the oracle).  The entry is E12 = M_T12 (M00 = T12) in the published form.
  Per form: published E12 = M_T12, X21 = t·M̂_T21; energy E12 = τ(θ_i)·M̂_T12,
  X21 = τ(θ_o)/η²·M̂_T21 (below); first_order E12 = M_T12, X21 = M_T21/η².
  M̂ is computed from the exact ratio q = T_p/T_s = η²(c+u)²/(η²c+u)², u = √(η²−1+c²)
  (c the external facet cosine), which stays finite at grazing (q → η²).

Energy-conserving form (``form="energy"``, the DEFAULT) — the fix and why
-------------------------------------------------------------------------
As published, WW is not energy conserving.  Two independent defects:

1. T12(ω_i·h): for fixed ω_i the facet angle depends on ω_o and is near normal incidence
   away from the specular peak, so T12 ≈ 0.96 over most of the hemisphere even at grazing
   incidence, where the coat's own lobe already reflects most of the flux (white Lambert
   base, η = 1.5, α = 0, Blinn e = 50: albedo 1.046 at θ_i = 70°, 1.266 at 85°, 1.43 at 89°).
2. No radiance compression: a refracted ray's radiance scales by n², and WW drops the
   1/η² of the exit.  Under a *smooth* coat (or any coat with transmission through n)
   a glossy base's lobe is widened by η² in solid angle at unchanged value: a
   TorranceSparrow silver base (m = 0.1) under a smooth η = 1.5 coat gives albedo 2.07.
   (With transmission through h the facet mapping happens to hide this.)

"T12 at the macro angle" or "T12 = 1 − E_top(θ_i)" cure only defect 1 (both measured:
the latter still gives 2.1 for the glossy base).  The fix used here is the physically
derived single-internal-bounce chain (docs/physics.md "missing") with the rough coat's own
transmittances, plus the closed-form sum of the internal reflections for a diffuse base:

    M_layer = a · X21 · R2 · M_base(ω'_i→ω'_o) · R1 · E12
              + (c_ms − 1) · a · (ρ_d/π) · col₀(X21)·row₀(E12)
    E12 = τ(θ_i) · M̂_T12(θ_i),   X21 = τ(θ_o)/η² · M̂_T21(θ'_o)

- ω'_i, ω'_o refracted through the *macro* normal (exact étendue: cosθ dω = η² cosθ' dω');
- τ(θ) = 1 − E_top(θ), E_top the coat's directional albedo ∫ f_top,00 cosθ_o dω_o
  (= F(θ) for a smooth coat): the flux the coat transmits, on entry and (by reciprocity
  of the coat) on exit; the M̂ keep the Fresnel diattenuation at the macro angles;
- c_ms = 1/(1 − ρ·R̄) for a depolarising base of albedo ρ = π·f_base, applied likewise to
  the depolarising share ρ_d/π of an ABCS base (MuellerValue.depol, e.g. TorranceSparrow's
  Lambert term; 1 otherwise): light reflected back down by the coat's underside returns
  to the diffuse base again;
  R̄ = 2∫ F_int(μ') e^{−2αd/μ'} μ' dμ' is the coat's diffuse internal reflectance incl. the
  absorption of the round trip, F_int = 1 beyond the critical angle, E_top(θ_ext) inside.

Why: it is provably bounded for *any* base and reciprocal.  For a non-depolarising base
∫ M00 cosθ_o dω_o = τ(θ_i) ∫_cone a τ f_base cosθ' dω' ≤ τ(θ_i)·albedo_base ≤ 1 − E_top(θ_i);
for a Lambert base the layer albedo is τ(θ_i)·ρx/(1 − ρ + ρx) ≤ τ(θ_i) with
x = (1 − Ē_top)/η² (α = 0), so the total is ≤ E_top + τ = 1, with equality for a white,
non-absorbing base (it is the exact answer for a smooth coat over a Lambertian base with
diffuse internal reflections).  For a mixed base (specular albedo a_s, diffuse ρ_d,
a_s + ρ_d ≤ 1) the two bounds add to ≤ τ(θ_i).  E_top ≤ 1 because V-cavity (and Smith) masking is a
valid masking function.  M00 is symmetric in ω_i ↔ ω_o (τ·τ, a, c_ms symmetric).
Costs: WW's t-term and facet transmission are not used by this form (``t_term`` is ignored,
``transmission_normal`` must be "macro"); the multiple-reflection sum is only applied to
depolarising bases or shares (a glossy base loses that — small — energy; HTSG's uniform
diffuse term is not separable from its "general" value and gets none); E_top is tabulated
on first use, shared by coats with equal parameters (Gauss–Legendre over the D·cosθ_h sampling warp, 128×96 nodes,
1° steps in θ, linear interpolation, |error| ~1e-6; an η grid for a dispersive coat).
A textured Beckmann m (per surface point: the coat's D, G, G_int, pdf and sampler take each
point's m) tabulates E_top over the texture's range [m_lo, m_hi] too: the constant-m tables at
nodes uniform in ln m (step ≤ 0.2, both ends nodes), Catmull–Rom in ln m between them — exact
at the nodes, ≤ 5.6e-4 from the exact table between them (measured, θ, η, m); R̄ is computed
per distinct (η, αd, m).  A Blinn exponent cannot vary over the surface.

First-order form (``form="first_order"``, an extra)
---------------------------------------------------
M_layer = a · M_T21 · R2 · M_base · R1 · M_T12 / η² with T12, T21 at the transmission
normal (default the facet normal, like WW): the docs/physics.md "missing" term literally.  It
equals the oracle column ``f_layer_first_order_with_inv_eta2_and_T21``.

Multiple coats
--------------
``coats`` is listed top (outermost) first.  A stack is built recursively: the layer
below coat k is ``WeidlichWilkie(coats[k+1:], base, exterior_n=coats[k].n)``, i.e. a
coat over "a layered BSDF", each with its own relative index n_{k+1}/n_k.  Only the
top coat's f_top is seen from outside; inner coats act through their own layer terms.

Base indices
------------
A base with an ``exterior_n`` attribute (SmoothConductor, TorranceSparrow, HTSG, an
inner WeidlichWilkie) must see the *coat* as its exterior medium, so that its Fresnel
term uses η_base/n_coat (erratum 5.1).  With ``match_base_exterior=True`` (default) the
constructor uses a shallow copy of the base with ``exterior_n`` set to the coat index
(the caller's object is not modified); a dispersive coat index then requires a base
that accepts a Spectrum there (only WeidlichWilkie does) — otherwise ValueError.
Bases that transmit (SmoothDielectric) are rejected.

Dirac lobes
-----------
- Smooth coat: the coat mirror is a Dirac lobe (M_F(θ_o) in the plane-of-incidence
  frames); if the base has a Dirac lobe too (SmoothConductor, HTSG's specular term),
  the chain entry → base mirror → exit is a Dirac lobe into the same mirror direction,
  weight a·M_T21·R·W_base(θ'_o)·R·M_T12 in every form (flux fractions: no 1/η², and
  t = T21, τ = T12 for a smooth coat).  ``delta_reflection`` returns the sum; a smooth coat over a delta-only base is
  ``delta_only``.
- Rough coat: no Dirac lobe.  A rough coat over a base whose reflection is all Dirac is rejected
  (ValueError: WW gives no function value there — use a rough base, e.g.
  TorranceSparrow with small m): a *delta-only* base, HTSG with σ₀ = 0 and no albedo (a smooth
  mirror), or a smooth coat over either.  The Dirac part of a mixed base (HTSG's specular
  term) is ignored under a rough coat (only its eval() lobes are layered).

Dispersion
----------
The coat index may be a Spectrum.  Evaluation is exact per wavelength (each wavelength
has its own internal directions; the base is evaluated on wavelength "lanes").
Sampling uses the path's mean η for its proposal, and ``pdf`` uses the same mean, so
MIS stays exact.

Sampling
--------
Per shading point (function of ω_o only) the coat lobe is chosen with probability
P_top = E/(E + (1 − E)·ρ̂·â), clipped to [0.05, 0.95] when both are > 0, E = E_top(θ_o)
(rough; by reciprocity of TS the albedo at θ_o) or F(θ_o) (smooth), ρ̂ = the base's mean
albedo for Lambert and 1 otherwise, â = mean_λ exp(−2αd/cosθ'_o).
- coat lobe: rough → the distribution's own sampler (Blinn D·cosθ_h, Beckmann visible
  normals) and ω_i = reflect(ω_o, h); smooth → the Dirac mirror (weight M_F/P_top).
- layer lobe: a mixture of (w_c) cosine-weighted hemisphere about n and (1 − w_c)
  "base through the coat": ω'_o = refraction of ω_o through n (mean η), the base's own
  ``sample`` at ω'_o gives ω'_i, refracted out through n (TIR → invalid sample).  Its
  density is p_base(ω'_i|ω'_o)·cosθ_i/(η² cosθ'_i) (Jacobian of refraction).  w_c = 1 for
  a Lambert base, 0 for a delta-only base, 0.25 otherwise (``layer_cosine_fraction``).
  Internal samples beyond the critical angle have no external direction and are lost
  (an invalid sample: 1 − 1/η² of a diffuse base's samples in this branch, which is why
  a Lambert base uses the cosine proposal only).
  A base Dirac sample (smooth coat only) becomes the layered Dirac lobe, weighted by the
  exact per-wavelength layered weight over its selection probability.
``pdf`` = P_top·pdf_top + (1 − P_top)·(w_c cosθ_i/π + (1 − w_c)·p_refr): exactly the
density of the non-delta directions; sample weights are eval·cosθ_i/pdf at the sampled
direction (the exact quotient).

Reciprocity
-----------
In the scattering-plane frames (s = unit(k_i × k_o), reversed path s' = −s) the full
Mueller matrix satisfies M(ω_o→ω_i) = P·M(ω_i→ω_o)ᵀ·P with P = diag(1, 1, −1, 1) in the
published form with transmission through h, the energy form and the first-order form
(for ABCS matrices this coincides with docs/physics.md's Q·Mᵀ·Q, Q = diag(1, 1, 1, −1); for
general matrices only P is right).  The published form through the macro normal breaks
M00 reciprocity by (1 − G_int)(T12(θ_i) − T12(θ_o))·f_base·a (docs/physics.md "energy" row).
"""

from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass, field

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, MuellerValue, ShadingPoint
from .conductor import mirror_reflection
from .htsg import HTSG
from .lambert import Lambert
from .microfacet import Beckmann, BlinnPhong, half_vector, reflect_local, shadowing_term
from .parameters import ModelDeclaration, Parameter, Socket
from .roughness import SMOOTH_LIMIT, checked_alpha, declared_slope
from .sampling import cosine_hemisphere, local_to_world
from .table_cache import cached_table
from ..errors import SceneError
from ..polarisation.frames import plane_of_incidence_axis, rotate_mueller_frames, rotation_mueller, \
    scattering_plane_axis
from ..polarisation.fresnel import fresnel_reflection_abcs, fresnel_transmission_abcs, refracted_cosine
from ..polarisation.mueller import abcs_matrix
from ..spectral import ConstantSpectrum, Spectrum, as_spectrum
from ..textures import TexturedNumber, TexturedSpectrum, textured
from ..vec3 import dot, local_frame, reflect, to_local

__all__ = ["Coat", "WeidlichWilkie", "FORMS", "T_TERMS", "TRANSMISSION_NORMALS", "DISTRIBUTIONS",
           "top_albedo"]

FORMS = ("energy", "published", "first_order")
T_TERMS = ("ww", "t21")
TRANSMISSION_NORMALS = ("facet", "macro")
DISTRIBUTIONS = ("smooth", "blinn", "beckmann")
#: Shadowing terms accepted for the coat (valid masking functions, so E_top ≤ 1).
COAT_SHADOWING = ("ts", "smith")
#: Lobe-selection probability bounds when both the coat and the layer contribute.
P_TOP_RANGE = (0.05, 0.95)

_TABLE_THETA_STEPS = 90     # E_top table: 1° steps in θ
_TABLE_NU, _TABLE_NPHI = 128, 96
_TABLE_N_ETA = 6            # η nodes for a dispersive coat
_MU_MIN = 1e-6
_ALBEDO_BLOCK = 16       # angles per vectorised block of the E_top quadrature (~25 MB)



def _spectrum_range(spec: Spectrum) -> tuple[float, float]:
    """(min, max) of a spectrum over the rendered range and its monochrome value (a textured
    spectrum: the bounds of every value it can take)."""
    if isinstance(spec, ConstantSpectrum):
        return spec.value, spec.value
    if isinstance(spec, TexturedSpectrum):
        return spec.lo, spec.hi
    lam = np.linspace(360.0, 830.0, 95)
    v = np.concatenate((np.asarray(spec.eval(lam), dtype=np.float64).ravel(), [spec.mono_value]))
    return float(v.min()), float(v.max())


def _mm(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    return np.einsum("ij...,jk...->ik...", A, B)


def _dirac_only_reflection(base: BSDF) -> str | None:
    """What makes all of ``base``'s reflection Dirac lobes (nothing a rough coat can layer), or None.

    Besides delta-only bases (SmoothConductor, Torrance–Sparrow at m = 0 without a diffuse part):
    HTSG with σ₀ = 0 is a smooth Fresnel mirror (its directional-diffuse term vanishes), so
    without a diffuse albedo only its Dirac lobe is left; and a smooth coat over such a base."""
    if base.flags.is_delta_only:
        return f"a delta-only base ({base.name})"
    if isinstance(base, HTSG) and base.sigma0 == 0.0 and (
            base.albedo is None or not np.any(np.asarray(base.albedo.eval(np.linspace(360.0, 830.0, 95))))):
        return "an HTSG base with sigma0_um = 0 and no albedo (a smooth Fresnel mirror: its reflection is all Dirac)"
    if isinstance(base, WeidlichWilkie) and base.coat.smooth:
        inner = _dirac_only_reflection(base.base)
        return None if inner is None else f"a smooth coat over {inner}"
    return None


def _null_coat(coat, above: Spectrum) -> bool:
    """The coat has the constant index of the constant medium above it and absorbs nothing (α·d = 0)."""
    n, ext, absorption = coat.n_spectrum, above, coat.absorption_spectrum
    if not (isinstance(n, ConstantSpectrum) and isinstance(ext, ConstantSpectrum)) or n.value != ext.value:
        return False
    return coat.thickness == 0.0 or (isinstance(absorption, ConstantSpectrum) and absorption.value == 0.0)


@dataclass
class Coat:
    """One dielectric coat of a WeidlichWilkie stack.

    n            : float or Spectrum — real refractive index of the coat (> 0).
    thickness    : float ≥ 0 — d, in the same length unit as 1/absorption.
    absorption   : float or Spectrum ≥ 0 — α per unit length; only α·d matters.
    distribution : "smooth" | "blinn" | "beckmann" — roughness of the coat's top interface.
    exponent     : Blinn exponent e ≥ 0 (distribution "blinn").
    m            : Beckmann rms slope m ≥ 1e-4 (distribution "beckmann"); may be a TexturedNumber
                   (per surface point, see :meth:`facets`; its albedo table then spans m, see
                   :class:`_RoughnessAlbedoTable`).
    """

    n: object = 1.5
    thickness: float = 0.0
    absorption: object = 0.0
    distribution: str = "smooth"
    exponent: float | None = None
    m: float | None = None
    n_spectrum: Spectrum = field(init=False, repr=False)
    absorption_spectrum: Spectrum = field(init=False, repr=False)
    dist: object = field(init=False, repr=False)

    def __post_init__(self):
        self.n_spectrum = self.n.as_spectrum() if isinstance(self.n, TexturedNumber) else as_spectrum(self.n, "coat n")
        lo, _ = _spectrum_range(self.n_spectrum)
        if not lo > 0:
            raise ValueError(f"coat n must be > 0, got {self.n!r}")
        self.absorption_spectrum = as_spectrum(self.absorption, "coat absorption")
        if _spectrum_range(self.absorption_spectrum)[0] < 0:
            raise ValueError(f"coat absorption must be >= 0, got {self.absorption!r}")
        # thickness may be a TexturedNumber (per surface point, through ShadingPoint.number)
        d = self.thickness if isinstance(self.thickness, TexturedNumber) else float(self.thickness)
        lo = d.lo if isinstance(d, TexturedNumber) else d
        if not (math.isfinite(lo) and lo >= 0):
            raise ValueError(f"coat thickness must be a finite number >= 0, got {self.thickness!r}")
        self.thickness = d
        if self.distribution == "smooth":
            if self.exponent is not None or self.m is not None:
                raise ValueError("a smooth coat takes neither exponent nor m")
            self.dist = None
        elif self.distribution == "blinn":
            if self.exponent is None or self.m is not None:
                raise ValueError("distribution 'blinn' needs exponent (and no m)")
            if isinstance(self.exponent, TexturedNumber):
                raise ValueError("coat exponent: a Blinn exponent cannot vary over the surface (a coat's roughness "
                                 "can: use distribution 'beckmann' with a textured m)")
            self.dist = BlinnPhong(self.exponent)
        elif self.distribution == "beckmann":
            if self.m is None or self.exponent is not None:
                raise ValueError("distribution 'beckmann' needs m (and no exponent)")
            m = checked_alpha(self.m, "Beckmann m")         # (≥ roughness.ALPHA_MIN everywhere)
            lo = m.lo if isinstance(m, TexturedNumber) else m
            # a textured m: this is the distribution at its least value (for what is fixed per material)
            self.dist = Beckmann(lo)
        else:
            raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {self.distribution!r}")

    @property
    def smooth(self) -> bool:
        return self.dist is None

    @property
    def textured_m(self) -> bool:
        return isinstance(self.m, TexturedNumber)

    def roughness(self, sp: ShadingPoint) -> np.ndarray | None:
        """The Beckmann m at the batch's points (N,) for a textured m, else None (one distribution)."""
        return sp.number(self.m) if self.textured_m else None

    def facets(self, m: np.ndarray | None = None):
        """The facet distribution: the coat's own, or one Beckmann m per point where ``m`` (K,) is given."""
        return self.dist if m is None else Beckmann.per_point(m)

    def optical_depth(self, sp: ShadingPoint) -> np.ndarray:
        """α·d at the batch's wavelengths, (L, N)."""
        return sp.spectrum(self.absorption_spectrum) * sp.number(self.thickness)

    def describe(self) -> dict:
        out = {"n": repr(self.n_spectrum),
               "thickness": repr(self.thickness) if isinstance(self.thickness, TexturedNumber) else self.thickness,
               "absorption": repr(self.absorption_spectrum), "distribution": self.distribution}
        if self.exponent is not None:
            out["exponent"] = float(self.exponent)
        if self.m is not None:
            out["m"] = repr(self.m) if self.textured_m else float(self.m)
        return out


# ------------------------------------------------------------------------------------------------
# Geometry helpers
# ------------------------------------------------------------------------------------------------

def _refract_in(w, m, c, eta):
    """Refraction of the external direction w (w·m = c) into the coat through m.

    Returns (w', cosθ'_m, ok): w' points away from the base (same side as m), Snell with
    the relative index η; ok is False for c ≤ 0 or total internal reflection (η < 1).
    """
    cc = np.clip(c, 0.0, 1.0)
    cos_t, tir = refracted_cosine(cc, eta)
    wt = (w - cc * m) / eta + cos_t * m
    return wt, cos_t, (c > 0) & ~tir


def _refract_out(w, n, c, eta):
    """Refraction of the internal direction w (w·n = c, pointing up) out of the coat through n."""
    cc = np.clip(c, 0.0, 1.0)
    sin2 = eta * eta * (1.0 - cc * cc)
    ok = (c > 0) & (sin2 < 1.0)
    cos_o = np.sqrt(np.maximum(1.0 - sin2, 0.0))
    wo = eta * (w - cc * n) + cos_o * n
    return wo, cos_o, ok


def _transmission_shape(c, eta):
    """(B/A, C/A) of the Fresnel transmission diattenuator at external cosine c, relative index η.

    q = T_p/T_s = η²(c+u)²/(η²c+u)², u = √(η² − 1 + c²) (exact, finite at grazing where
    q → η²).  Under TIR (no transmission) the unpolarised shape (0, 1) is returned.
    """
    c = np.clip(c, 0.0, 1.0)
    eta = np.asarray(eta, dtype=np.float64)
    e2 = eta * eta
    u2 = e2 - 1.0 + c * c
    ok = u2 > 0
    u = np.sqrt(np.where(ok, u2, 1.0))
    q = np.where(ok, e2 * ((c + u) / (e2 * c + u)) ** 2, 1.0)
    return (1.0 - q) / (1.0 + q), 2.0 * np.sqrt(q) / (1.0 + q)


def _diattenuator(T, b_hat, c_hat):
    """T·[[1, b, 0, 0], [b, 1, 0, 0], [0, 0, c, 0], [0, 0, 0, c]] as (4, 4, ...)."""
    T, b_hat, c_hat = np.broadcast_arrays(T, b_hat, c_hat)
    return abcs_matrix(T, T * b_hat, T * c_hat, np.zeros_like(T))


# ------------------------------------------------------------------------------------------------
# The coat's directional albedo
# ------------------------------------------------------------------------------------------------

def _warp_nodes(dist, n_u: int, n_phi: int):
    """Quadrature nodes of ∫ g(h) D(h) cosθ_h dω_h = E_u[g]: h (3, n_u·n_phi) and weights (n_u·n_phi,).

    Gauss–Legendre in u ∈ (0, 1) through the D·cosθ_h sampling warp and in φ ∈ (0, π)
    (the integrands used here are symmetric about the plane of ω_i = (sinθ, 0, cosθ)).
    """
    x, w = np.polynomial.legendre.leggauss(n_u)
    u = 0.5 * (x + 1.0)
    wu = 0.5 * w
    xp, wp = np.polynomial.legendre.leggauss(n_phi)
    phi = 0.5 * math.pi * (xp + 1.0)
    wphi = 0.5 * wp  # ∫_0^π dφ/π
    if isinstance(dist, BlinnPhong):
        lnu = np.log(u) / (dist.e + 2.0)
        cos_h = np.exp(lnu)
        sin_h = np.sqrt(np.maximum(-np.expm1(2.0 * lnu), 0.0))
    elif isinstance(dist, Beckmann):
        t2 = -dist.m * dist.m * np.log1p(-u)
        cos_h = 1.0 / np.sqrt(1.0 + t2)
        sin_h = np.sqrt(t2) * cos_h
    else:
        raise TypeError(f"no quadrature warp for {dist!r}")
    cp, sph = np.cos(phi), np.sin(phi)
    h = np.stack((np.outer(sin_h, cp), np.outer(sin_h, sph), np.outer(cos_h, np.ones_like(phi))))
    return h.reshape(3, -1), np.outer(wu, wphi).ravel()


def top_albedo(cos_theta, eta, dist, shadowing: str = "ts", n_u: int = _TABLE_NU, n_phi: int = _TABLE_NPHI):
    """Directional albedo E_top(θ) = ∫ F(ω·h) D G/(4 cosθ cosθ_o) cosθ_o dω_o of a rough dielectric coat.

    cos_theta (K,) array, eta a real relative index; quadrature over the D·cosθ_h warp:
    E = E_h[F(ω·h) G (ω·h)/(cosθ h_z)], ω_o = reflect(ω, h).  Vectorised over blocks of
    _ALBEDO_BLOCK angles (elementwise the same operations, each row summed alone: the values
    are those of a loop over θ, bit for bit).
    """
    mu = np.maximum(np.atleast_1d(np.asarray(cos_theta, dtype=np.float64)), _MU_MIN)
    h, wq = _warp_nodes(dist, n_u, n_phi)
    hh = h[:, None, :]
    out = np.empty(mu.shape)
    for s in range(0, mu.size, _ALBEDO_BLOCK):
        c = mu[s:s + _ALBEDO_BLOCK][:, None]
        shape = (3, c.shape[0], h.shape[1])
        wi = np.broadcast_to(np.stack(np.broadcast_arrays(np.sqrt(np.maximum(1.0 - c * c, 0.0)), 0.0, c)),
                             shape).copy()
        d = np.maximum(dot(wi, hh), 0.0)
        wo = 2.0 * d * hh - wi
        G = shadowing_term(shadowing, dist, wi, wo, np.broadcast_to(hh, shape).copy())
        F = fresnel_reflection_abcs(d, np.full(d.shape, eta))[0]     # same shapes: no read-only broadcast view
        g = F * G * d / (c * np.maximum(hh[2], 1e-300))
        out[s:s + _ALBEDO_BLOCK] = np.sum(wq * g, axis=-1)
    return out


class _AlbedoTable:
    """E_top(θ, η) on a 1° θ grid (and an η grid for dispersive coats), bilinear lookup."""

    def __init__(self, dist, shadowing: str, eta_lo: float, eta_hi: float, key: tuple):
        """``key``: the parameters that define ``dist`` (the table is kept on disk between processes
        under them, engine.materials.table_cache)."""
        self.theta = np.linspace(0.0, 0.5 * math.pi, _TABLE_THETA_STEPS + 1)
        mu = np.cos(self.theta)
        if eta_hi - eta_lo <= 1e-12 * eta_hi:
            self.eta = np.array([eta_lo])
        else:
            self.eta = np.linspace(eta_lo, eta_hi, _TABLE_N_ETA)

        def build():
            return np.stack([np.clip(top_albedo(mu, e, dist, shadowing), 0.0, 1.0) for e in self.eta])
        self.E = cached_table("ww_top_albedo", (*key, shadowing, eta_lo, eta_hi, _TABLE_THETA_STEPS, _TABLE_N_ETA),
                              (self.eta.size, mu.size), build)

    def __call__(self, cos_theta, eta) -> np.ndarray:
        th = np.arccos(np.clip(cos_theta, 0.0, 1.0))
        x = th / self.theta[1]
        i = np.clip(np.floor(x).astype(np.int64), 0, _TABLE_THETA_STEPS - 1)
        fx = np.clip(x - i, 0.0, 1.0)
        if self.eta.size == 1:
            E = self.E[0]
            return E[i] * (1.0 - fx) + E[i + 1] * fx
        eta = np.clip(np.asarray(eta, dtype=np.float64), self.eta[0], self.eta[-1])
        y = (eta - self.eta[0]) / (self.eta[1] - self.eta[0])
        k = np.clip(np.floor(y).astype(np.int64), 0, self.eta.size - 2)
        fy = np.clip(y - k, 0.0, 1.0)
        e0 = self.E[k, i] * (1.0 - fx) + self.E[k, i + 1] * fx
        e1 = self.E[k + 1, i] * (1.0 - fx) + self.E[k + 1, i + 1] * fx
        return e0 * (1.0 - fy) + e1 * fy


@functools.lru_cache(maxsize=64)
def _albedo_table(dist_name: str, e: float, m: float, shadowing: str, eta_lo: float, eta_hi: float) -> _AlbedoTable:
    """Shared E_top tables (they depend only on the distribution, the shadowing term and η)."""
    dist = BlinnPhong(e) if dist_name == "blinn" else Beckmann(m)
    return _AlbedoTable(dist, shadowing, eta_lo, eta_hi, key=(dist_name, e, m))


#: Node spacing in ln m of the E_top table of a coat with a textured Beckmann m.  Measured against
#: the exact constant-m table (Catmull–Rom in ln m; θ on the 1° grid; η = 0.7, 1.1, 1.5, 2.5; V-cavity
#: and Smith shadowing; m from 1e-3 to 20): max |error| 5.6e-4 at a step of 0.206 (1.8e-3 at 0.31,
#: 4.6e-3 at 0.41); linear interpolation in ln m errs by 4.6e-3 at 0.206.
_LN_M_STEP = 0.2


class _RoughnessAlbedoTable:
    """E_top(θ, η, m) of a Beckmann coat whose m varies over the surface, for m in [m_lo, m_hi].

    Nodes uniform in ln m (step ≤ _LN_M_STEP, both ends exact), each node the constant-m table
    (shared with constant coats through ``_albedo_table``: equal at the nodes); between nodes
    a Catmull–Rom cubic in ln m of the nodes' own (θ, η) lookups (end intervals: the missing
    outer node reflected, p₋₁ = 2p₀ − p₁), clipped to [0, 1].  |error| ≤ 6e-4 (see _LN_M_STEP).
    """

    def __init__(self, shadowing: str, eta_lo: float, eta_hi: float, m_lo: float, m_hi: float):
        span = math.log(m_hi / m_lo)
        n = max(1, math.ceil(span / _LN_M_STEP - 1e-9)) if m_hi > m_lo * (1.0 + 1e-12) else 0
        self.ln_m = np.linspace(math.log(m_lo), math.log(m_hi), n + 1)
        self.m = np.exp(self.ln_m)
        self.m[0], self.m[-1] = m_lo, m_hi
        self.tables = [_albedo_table("beckmann", 0.0, float(mk), shadowing, eta_lo, eta_hi) for mk in self.m]

    def __call__(self, cos_theta, eta, m) -> np.ndarray:
        cos_theta, eta, m = np.broadcast_arrays(np.asarray(cos_theta, dtype=np.float64),
                                                np.asarray(eta, dtype=np.float64), np.asarray(m, dtype=np.float64))
        if len(self.tables) == 1:
            return self.tables[0](cos_theta, eta)
        n = len(self.tables) - 1
        V = np.stack([t(cos_theta, eta) for t in self.tables])
        x = (np.log(m) - self.ln_m[0]) / (self.ln_m[1] - self.ln_m[0])
        i = np.clip(np.floor(x).astype(np.int64), 0, n - 1)
        f = np.clip(x - i, 0.0, 1.0)

        def node(j):
            return np.take_along_axis(V, np.clip(j, 0, n)[None], 0)[0]
        p1, p2 = node(i), node(i + 1)
        p0 = np.where(i > 0, node(i - 1), 2.0 * p1 - p2)
        p3 = np.where(i + 2 <= n, node(i + 2), 2.0 * p2 - p1)
        c = p1 + 0.5 * f * (p2 - p0 + f * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + f * (3.0 * (p1 - p2) + p3 - p0)))
        return np.clip(np.where(f == 0.0, p1, np.where(f == 1.0, p2, c)), 0.0, 1.0)


@functools.lru_cache(maxsize=16)
def _roughness_albedo_table(shadowing: str, eta_lo: float, eta_hi: float, m_lo: float,
                            m_hi: float) -> _RoughnessAlbedoTable:
    """Shared E_top tables over a textured m's range (built once per range)."""
    return _RoughnessAlbedoTable(shadowing, eta_lo, eta_hi, m_lo, m_hi)


# ------------------------------------------------------------------------------------------------
# Wavelength lanes: exact per-wavelength internal geometry for a dispersive coat
# ------------------------------------------------------------------------------------------------

class _Lanes:
    """Maps a batch (L wavelengths × N points) to K evaluation lanes.

    If η is the same at every wavelength of each point (constant index, monochrome mode)
    the lanes are the N points (K = N, spectral arrays keep their (L, N) shape); otherwise
    every (wavelength, point) pair is a lane (K = L·N, lane l·N + j, spectral arrays (1, K)).
    """

    def __init__(self, sp: ShadingPoint, eta_LN: np.ndarray):
        self.L, self.N = sp.lam.shape
        self.spectral = bool(self.L > 1 and np.any(eta_LN != eta_LN[:1]))
        if self.spectral:
            self.K = self.L * self.N
            self.eta = eta_LN.reshape(self.K)
            self.lam = sp.lam.reshape(1, self.K)
        else:
            self.K = self.N
            self.eta = eta_LN[0]
            self.lam = sp.lam
        self.sp = sp

    def geo(self, x: np.ndarray) -> np.ndarray:
        if not self.spectral:
            return x
        return np.tile(x, (1,) * (x.ndim - 1) + (self.L,))

    def spec(self, v: np.ndarray) -> np.ndarray:
        return v.reshape(1, self.K) if self.spectral else v

    def out(self, v: np.ndarray) -> np.ndarray:
        if not self.spectral:
            return v
        return v.reshape(v.shape[:-2] + (self.L, self.N))

    def point(self, wo_int: np.ndarray) -> ShadingPoint:
        sp = self.sp
        # the base's textures see the same surface points (one per lane)
        surface = sp.surface if sp.surface is None or not self.spectral else \
            sp.surface.take(np.tile(np.arange(self.N), self.L))
        return ShadingPoint(self.geo(sp.p), self.geo(sp.n_s), self.geo(sp.n_g), wo_int, self.lam, sp.mono,
                            surface=surface)


# ------------------------------------------------------------------------------------------------
# The material
# ------------------------------------------------------------------------------------------------

class WeidlichWilkie(BSDF):
    """Weidlich–Wilkie layered polarising BRDF (see the module docstring).

    Parameters
    ----------
    coats : Coat or list of Coat — top (outermost) first.
    base : BSDF — the substrate (any reflective engine BSDF).
    form : "energy" (default) | "published" | "first_order".
    t_term : "ww" (t = 1 − F21·G_int, default) | "t21" (t = 1 − F21); published form only.
    transmission_normal : None (default: "facet" for published/first_order, "macro" for energy)
        | "facet" (h; WW) | "macro" (n).  Smooth coats always use n; the energy form needs "macro".
    exterior_n : float or Spectrum > 0 — index above the top coat.
    shadowing : "ts" (V-cavity, default) | "smith" — the coat's G (f_top and G_int).
    match_base_exterior : bool — give the base the coat as exterior medium (default True).
    layer_cosine_fraction : float in [0, 1] or None — w_c of the layer-lobe proposal.
    """

    name = "weidlich_wilkie"
    #: Built on first use from the parameters (not part of the material: engine.render.resume.scene_fingerprint).
    _cached_fields = ("_table", "_rbar_nodes")

    def __init__(self, coats, base: BSDF, form: str = "energy", t_term: str = "ww",
                 transmission_normal: str | None = None, exterior_n=1.0, shadowing: str = "ts",
                 match_base_exterior: bool = True, layer_cosine_fraction: float | None = None):
        coats = [coats] if isinstance(coats, Coat) else list(coats)
        if not coats or not all(isinstance(c, Coat) for c in coats):
            raise ValueError("coats must be a Coat or a non-empty list of Coat")
        if not isinstance(base, BSDF):
            raise ValueError(f"base must be a BSDF, got {base!r}")
        if base.flags.transmits:
            raise ValueError(f"the base must be reflective; {getattr(base, 'name', base)!r} transmits")
        if form not in FORMS:
            raise ValueError(f"form must be one of {FORMS}, got {form!r}")
        if t_term not in T_TERMS:
            raise ValueError(f"t_term must be one of {T_TERMS}, got {t_term!r}")
        if transmission_normal is None:
            transmission_normal = "macro" if form == "energy" else "facet"
        if transmission_normal not in TRANSMISSION_NORMALS:
            raise ValueError(f"transmission_normal must be one of {TRANSMISSION_NORMALS}, got {transmission_normal!r}")
        if form == "energy" and transmission_normal != "macro":
            raise ValueError("the energy form refracts through the macro normal (transmission_normal='macro'); "
                             "use form='published' for WW's transmission through the facet normal")
        if shadowing not in COAT_SHADOWING:
            raise ValueError(f"shadowing must be one of {COAT_SHADOWING}, got {shadowing!r}")
        self.coats = coats
        self.coat = coats[0]
        self.form = form
        self.t_term = t_term
        self.transmission_normal = transmission_normal
        self.shadowing = shadowing
        self.match_base_exterior = bool(match_base_exterior)
        self._exterior = as_spectrum(exterior_n, "exterior_n")
        if not _spectrum_range(self._exterior)[0] > 0:
            raise ValueError(f"exterior_n must be > 0, got {exterior_n!r}")
        self._table = None
        self._rbar_nodes = None

        if len(coats) > 1:
            base = WeidlichWilkie(coats[1:], base, form=form, t_term=t_term,
                                  transmission_normal=transmission_normal, exterior_n=self.coat.n_spectrum,
                                  shadowing=shadowing, match_base_exterior=match_base_exterior,
                                  layer_cosine_fraction=layer_cosine_fraction)
        elif self.match_base_exterior and hasattr(base, "exterior_n"):
            base = copy.copy(base)
            if isinstance(base, WeidlichWilkie):
                base.exterior_n = self.coat.n_spectrum
            else:
                lo, hi = _spectrum_range(self.coat.n_spectrum)
                if isinstance(self.coat.n_spectrum, TexturedSpectrum):
                    raise ValueError("a textured coat index needs a base without an exterior index (e.g. lambert), "
                                     "or match_base_exterior=False")
                if hi - lo > 1e-12 * hi:
                    raise ValueError("a dispersive coat index needs a base without a scalar exterior_n "
                                     "(or match_base_exterior=False)")
                base.exterior_n = float(lo)
        self.base = base
        dirac_base = None if self.coat.smooth else _dirac_only_reflection(base)
        if dirac_base:
            raise ValueError(f"a rough coat over {dirac_base} is not supported (WW has no function value "
                             "there); use a rough base, e.g. TorranceSparrow with a small m or HTSG with sigma0_um > 0")

        if layer_cosine_fraction is None:
            w_c = self.default_layer_cosine_fraction(base)
        else:
            w_c = float(layer_cosine_fraction)
            if not (0.0 <= w_c <= 1.0):
                raise ValueError(f"layer_cosine_fraction must be in [0, 1], got {layer_cosine_fraction!r}")
        self.w_c = w_c
        self.flags = self._layered_flags(base.flags)
        self.varies_over_surface = base.varies_over_surface or any(
            textured(c.n_spectrum, c.thickness, c.absorption_spectrum, c.m) for c in coats)

    @staticmethod
    def default_layer_cosine_fraction(base: BSDF) -> float:
        """w_c of the layer-lobe proposal when not given: 0 for a Dirac-only base, 1 for a Lambert base
        (the cosine proposal is its exact density), 0.25 otherwise."""
        if base.flags.is_delta_only:
            return 0.0
        return 1.0 if isinstance(base, Lambert) else 0.25

    def _layered_flags(self, base: BSDFFlags) -> BSDFFlags:
        """Lobes and capabilities of this coat over a base with flags ``base`` (fixed at construction).

        Lobes: the top coat's own lobe (Dirac mirror if smooth, glossy if rough) plus the base's lobes
        seen through the coat — a Dirac base lobe stays a Dirac lobe through a smooth coat and is
        dropped by a rough one (see "Dirac lobes" above), glossy and diffuse lobes stay what they are.
        The coat's Fresnel interface always polarises; it retards if the base does or the coat may
        totally reflect (η < 1 somewhere); λ-dependent unless the base, the exterior index and every
        coat's n and absorption are.  The layered value is a "general" matrix: no separable diffuse share.
        """
        F = BSDFFlags
        smooth = self.coat.smooth
        flags = (F.DELTA_REFLECTION if smooth else F.GLOSSY_REFLECTION) | F.POLARISING
        flags |= base & (F.GLOSSY_REFLECTION | F.DIFFUSE_REFLECTION)
        flags |= F.when(smooth, base & F.DELTA_REFLECTION)
        flags |= F.when(base.retarding or self._coat_may_tir(), F.RETARDING)
        constant = (not base.wavelength_dependent and self._exterior.is_constant and
                    all(c.n_spectrum.is_constant and c.absorption_spectrum.is_constant for c in self.coats))
        return flags | F.when(not constant, F.WAVELENGTH_DEPENDENT)

    # --- parameters ----------------------------------------------------------------------------

    @property
    def exterior_n(self) -> Spectrum:
        return self._exterior

    @exterior_n.setter
    def exterior_n(self, value):
        self._exterior = as_spectrum(value, "exterior_n")
        self._table = None
        self._rbar_nodes = None

    def _coat_may_tir(self) -> bool:
        """True unless η ≥ 1 at every wavelength (then the coat's reflection never retards)."""
        lo_n, _ = _spectrum_range(self.coat.n_spectrum)
        _, hi_e = _spectrum_range(self._exterior)
        return lo_n < hi_e

    def _eta(self, sp: ShadingPoint) -> np.ndarray:
        """Relative coat index η = n_coat/n_exterior, (L, N) real."""
        return sp.spectrum(self.coat.n_spectrum) / sp.spectrum(self._exterior)

    def _layer_base(self) -> BSDF:
        """The base as the layer term sees it: ``self.base`` without the null interfaces on top of it.

        A coat that is index-matched to the medium above it (η ≡ 1: constant, equal indices) and clear
        (α·d = 0) is no interface at all, so a sub-stack whose top coats are such null coats *is* the
        base below them (exactly, in the physics; to ~1e-14 numerically).  Evaluating that base
        directly makes the energy form's internal-reflection factor c_ms — applied to a base's
        diffuse share — independent of where a null coat is inserted (a sub-stack's "general" value
        hides the diffuse share).  A rough null coat over a Dirac lobe is kept (a rough coat drops
        the Dirac lobe below it, see "Dirac lobes").  Found per call: ``exterior_n`` of a stack used
        as a base is set after construction.
        """
        b = self.base
        while isinstance(b, WeidlichWilkie) and _null_coat(b.coat, b.exterior_n) and \
                (b.coat.smooth or not b.base.flags.has(BSDFFlags.DELTA_REFLECTION)):
            b = b.base
        return b

    def albedo_table(self) -> _AlbedoTable | _RoughnessAlbedoTable:
        """The coat's E_top(θ, η) table (rough coats only; E_top(θ, η, m) over a textured m's
        range), built on first use."""
        if self._table is None:
            n_lo, n_hi = _spectrum_range(self.coat.n_spectrum)
            e_lo, e_hi = _spectrum_range(self._exterior)
            if n_hi - n_lo <= 1e-12 * n_hi and e_hi - e_lo <= 1e-12 * e_hi:
                lo = hi = n_lo / e_lo
            else:
                lo, hi = n_lo / e_hi, n_hi / e_lo
            if self.coat.textured_m:
                self._table = _roughness_albedo_table(self.shadowing, lo, hi, self.coat.m.lo, self.coat.m.hi)
                return self._table
            self._table = _albedo_table(self.coat.dist.name, float(getattr(self.coat.dist, "e", 0.0)),
                                        float(getattr(self.coat.dist, "m", 0.0)), self.shadowing, lo, hi)
        return self._table

    def coat_reflectance(self, cos_theta, eta, m=None) -> np.ndarray:
        """E_top(θ): the coat's directional albedo seen from outside (F(θ) for a smooth coat);
        ``m``: the Beckmann m per value (a textured coat roughness), broadcast with the others."""
        c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
        if self.coat.smooth:
            return fresnel_reflection_abcs(c, eta)[0]
        if m is not None:
            return self.albedo_table()(c, eta, m)
        return self.albedo_table()(c, eta)

    def internal_reflectance(self, eta, tau, m=None) -> np.ndarray:
        """R̄ = 2∫₀¹ F_int(μ') e^{−2αd/μ'} μ' dμ': the coat underside's diffuse reflectance, round trip included.

        F_int = 1 beyond the critical angle, E_top(θ_ext) inside it (θ_ext the external angle
        of the ray refracted out).  ``eta``, ``tau`` (= αd) and ``m`` (a textured coat's Beckmann m,
        or None) broadcast; evaluated once per distinct (η, αd[, m]), Gauss–Legendre on [0, μ'_c]
        and [μ'_c, 1].
        """
        if m is not None:
            eta_b, tau_b, m_b = np.broadcast_arrays(np.asarray(eta, dtype=np.float64),
                                                    np.asarray(tau, dtype=np.float64), np.asarray(m, dtype=np.float64))
            keys, inv = np.unique(np.stack((eta_b.ravel(), tau_b.ravel(), m_b.ravel()), axis=1), axis=0,
                                  return_inverse=True)
            R = self._internal_reflectance(keys[:, 0].copy(), keys[:, 1].copy(), keys[:, 2].copy())
            return R[np.ravel(inv)].reshape(eta_b.shape)
        eta_b, tau_b = np.broadcast_arrays(np.asarray(eta, dtype=np.float64), np.asarray(tau, dtype=np.float64))
        flat_e, flat_x = eta_b.ravel(), tau_b.ravel()
        if flat_e.size and np.all(flat_e == flat_e[0]) and np.all(flat_x == flat_x[0]):
            e, x, inv = flat_e[:1], flat_x[:1], np.zeros(flat_e.size, dtype=np.int64)
        else:  # complex keys sort lexicographically: one sort instead of a row-wise unique
            uniq, inv = np.unique(flat_e + 1j * flat_x, return_inverse=True)
            e, x = uniq.real.copy(), uniq.imag.copy()
        return self._internal_reflectance(e, x)[np.ravel(inv)].reshape(eta_b.shape)

    def _internal_reflectance(self, e: np.ndarray, x: np.ndarray, m: np.ndarray | None = None) -> np.ndarray:
        """R̄ at distinct (η, αd[, m]) triples, (U,) each."""
        if self._rbar_nodes is None:
            xg, wg = np.polynomial.legendre.leggauss(48)
            self._rbar_nodes = (0.5 * (xg + 1.0), 0.5 * wg)
        z, wz = self._rbar_nodes
        mu_c = np.sqrt(np.clip(1.0 - 1.0 / (e * e), 0.0, 1.0))
        mu1 = mu_c[None, :] * z[:, None]
        w1 = mu_c[None, :] * wz[:, None]
        mu2 = mu_c[None, :] + (1.0 - mu_c[None, :]) * z[:, None]
        w2 = (1.0 - mu_c[None, :]) * wz[:, None]
        cos_ext = np.sqrt(np.clip(1.0 - (e * e)[None, :] * (1.0 - mu2 * mu2), 0.0, 1.0))
        F2 = self.coat_reflectance(cos_ext.ravel(), np.broadcast_to(e, mu2.shape).ravel(),
                                   None if m is None else np.broadcast_to(m, mu2.shape).ravel()).reshape(mu2.shape)

        def radial(mu):
            safe = np.maximum(mu, 1e-300)
            return np.where(mu > 0, np.exp(-2.0 * x[None, :] / safe) * 2.0 * mu, 0.0)

        R = np.sum(w1 * radial(mu1), axis=0) + np.sum(w2 * F2 * radial(mu2), axis=0)
        return np.clip(R, 0.0, 1.0)

    # --- the layered value ---------------------------------------------------------------------

    def _evaluate(self, sp: ShadingPoint, wi: np.ndarray, info: bool = False):
        coat = self.coat
        rough = not coat.smooth
        eta_LN = self._eta(sp)
        lanes = _Lanes(sp, eta_LN)
        K = lanes.K
        eta = lanes.eta
        m_pts = coat.roughness(sp) if rough else None
        mK = None if m_pts is None else lanes.geo(m_pts)          # a textured m: one per lane
        m_r = None if mK is None else mK[None, :]
        dist = coat.facets(mK) if rough else None
        n = lanes.geo(sp.n_s)
        wiK = lanes.geo(wi)
        woK = lanes.geo(sp.wo)
        cos_i = dot(n, wiK)
        cos_o = dot(n, woK)
        front = (cos_i > 0) & (cos_o > 0)
        k_in = -wiK

        if rough:
            h, cos_f, ok_h = half_vector(wiK, woK)
            ok_h &= front
        m = h if (rough and self.transmission_normal == "facet") else n
        ci_m = dot(wiK, m)
        co_m = dot(woK, m)
        wi_t, _, ok_i = _refract_in(wiK, m, ci_m, eta)
        wo_t, _, ok_o = _refract_in(woK, m, co_m, eta)
        ci_t = dot(n, wi_t)
        co_t = dot(n, wo_t)
        valid = front & ok_i & ok_o & (ci_t > 0) & (co_t > 0)

        # Fresnel factors (lane-wise, (1, K)).
        eta_r = eta[None, :]
        T12 = fresnel_transmission_abcs(np.clip(ci_m, 0.0, 1.0)[None, :], eta_r)[0]
        F21 = fresnel_reflection_abcs(np.clip(co_m, 0.0, 1.0)[None, :], eta_r)[0]
        b12, c12 = _transmission_shape(ci_m[None, :], eta_r)
        b21, c21 = _transmission_shape(co_m[None, :], eta_r)

        t_frame, b_frame = local_frame(n)
        if rough:
            wi_tl = to_local(wi_t, t_frame, b_frame, n)
            wo_tl = to_local(wo_t, t_frame, b_frame, n)
            hp, _, ok_hp = half_vector(wi_tl, wo_tl)
            G_int = np.where(ok_hp, shadowing_term(self.shadowing, dist, wi_tl, wo_tl, hp), 0.0)[None, :]
        else:
            G_int = np.ones((1, K))
        t = 1.0 - F21 * (G_int if self.t_term == "ww" else 1.0)

        tau = lanes.spec(coat.optical_depth(sp))
        inv = np.where(valid, 1.0 / np.where(valid, ci_t, 1.0) + 1.0 / np.where(valid, co_t, 1.0), 0.0)
        a = np.where(valid[None, :], np.exp(-tau * inv[None, :]), 0.0)

        if self.form == "published":
            t_in, t_out = T12, t
        elif self.form == "energy":  # m = n here
            t_in = 1.0 - self.coat_reflectance(cos_i[None, :], eta_r, m_r)
            t_out = (1.0 - self.coat_reflectance(cos_o[None, :], eta_r, m_r)) / (eta_r * eta_r)
        else:  # first_order
            t_in, t_out = T12, (1.0 - F21) / (eta_r * eta_r)
        E12 = _diattenuator(t_in, b12, c12)
        X21 = _diattenuator(t_out, b21, c21)

        s1 = plane_of_incidence_axis(m, k_in)
        s2 = plane_of_incidence_axis(m, woK)
        Lk = lanes.lam.shape[0]
        M_layer = np.zeros((4, 4, Lk, K))
        ms_factor = np.ones((1, K))
        if np.any(valid):
            base_val = self._layer_base().eval(lanes.point(wo_t), wi_t)
            Mb = base_val.matrix()
            rank1 = X21[:, 0][:, None] * E12[0][None, :]  # col₀(X21)·row₀(E12)
            if base_val.kind == "depolarising":
                M_layer = (a * Mb[0, 0])[None, None] * rank1
                diffuse = Mb[0, 0]
            else:
                R1 = rotation_mueller(s1, base_val.x_in, -wi_t)[:, :, None, :]
                R2 = rotation_mueller(base_val.x_out, s2, wo_t)[:, :, None, :]
                M_layer = a[None, None] * _mm(X21, _mm(R2, _mm(Mb, _mm(R1, E12))))
                diffuse = getattr(base_val, "depol", None)  # a Lambert share of an ABCS base (TS)
            if self.form == "energy" and diffuse is not None:
                # Internal reflections back onto the base's diffuse share ρ_d/π: c_ms = 1/(1 − ρ_d R̄),
                # added as (c_ms − 1)·a·(ρ_d/π)·col₀(X21)·row₀(E12).
                rho = np.clip(math.pi * diffuse, 0.0, 1.0)
                c_ms = 1.0 / np.maximum(1.0 - rho * self.internal_reflectance(eta_r, tau, m_r), 1e-12)
                M_layer = M_layer + ((c_ms - 1.0) * a * diffuse)[None, None] * rank1
                ms_factor = c_ms
            M_layer = np.where(valid[None, None, None, :], M_layer, 0.0)

        if rough:
            x = scattering_plane_axis(k_in, woK)
            M = rotate_mueller_frames(M_layer, s1[:, None, :], x[:, None, :], k_in[:, None, :],
                                      s2[:, None, :], x[:, None, :], woK[:, None, :])
            h_l = to_local(h, t_frame, b_frame, n)
            wi_l = to_local(wiK, t_frame, b_frame, n)
            wo_l = to_local(woK, t_frame, b_frame, n)
            D = dist.D(h_l)
            G = shadowing_term(self.shadowing, dist, wi_l, wo_l, h_l)
            fr = np.where(ok_h, D * G / (4.0 * np.where(ok_h, cos_i * cos_o, 1.0)), 0.0)
            A, B, C, S = fresnel_reflection_abcs(np.where(ok_h, cos_f, 1.0)[None, :], eta_r)
            M_top = abcs_matrix(A * fr, B * fr, C * fr, S * fr)
            M = M + M_top
            x_in = x_out = x
        else:
            M = M_layer
            M_top = None
            x_in, x_out = s1, s2

        N = sp.n
        value = MuellerValue("general", x_in[:, :N], x_out[:, :N],
                             M=np.ascontiguousarray(np.broadcast_to(lanes.out(M), (4, 4) + sp.lam.shape)))
        if not info:
            return value
        full = lambda v: np.broadcast_to(lanes.out(np.broadcast_to(v, (Lk, K))), sp.lam.shape)  # noqa: E731
        deg = lambda c: np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))  # noqa: E731
        out = {"T12": full(T12), "F21": full(F21), "G_int": full(G_int), "t": full(t), "a": full(a),
               "T_in": full(t_in), "T_out": full(t_out), "c_ms": full(ms_factor),
               "theta_i_int_deg": full(deg(ci_t)[None, :]), "theta_o_int_deg": full(deg(co_t)[None, :]),
               "valid_layer": full(valid[None, :].astype(float)) > 0,
               "f_layer": full(M_layer[0, 0]),
               "f_top": full(M_top[0, 0]) if M_top is not None else np.zeros(sp.lam.shape),
               "M_layer": lanes.out(M_layer), "layer_frames": (s1[:, :N], s2[:, :N])}
        return value, out

    def eval(self, sp: ShadingPoint, wi: np.ndarray) -> MuellerValue:
        return self._evaluate(sp, wi)

    def intermediates(self, sp: ShadingPoint, wi: np.ndarray) -> dict:
        """WW intermediates per (λ, point): T12, F21, G_int, t, a, internal angles, f_top, f_layer (M00)."""
        return self._evaluate(sp, wi, info=True)[1]

    # --- Dirac lobes ----------------------------------------------------------------------------

    def _layered_delta(self, sp: ShadingPoint):
        """(M (4,4,L,N), x_in, x_out) of the base's Dirac lobe seen through a smooth coat, or None."""
        eta_LN = self._eta(sp)
        lanes = _Lanes(sp, eta_LN)
        eta = lanes.eta
        n = lanes.geo(sp.n_s)
        woK = lanes.geo(sp.wo)
        cos_o = dot(n, woK)
        wo_t, cos_t, ok = _refract_in(woK, n, cos_o, eta)
        W = self.base.delta_reflection(lanes.point(wo_t))
        if W is None:
            return None
        wi_t = reflect(wo_t, n)
        wiK = reflect(woK, n)
        ok &= cos_t > 0
        eta_r = eta[None, :]
        c = np.clip(cos_o, 0.0, 1.0)[None, :]
        T = fresnel_transmission_abcs(c, eta_r)[0]     # T12(θ_o) = T21(θ'_o) at the mirror geometry
        b, cc = _transmission_shape(c, eta_r)
        E12 = _diattenuator(T, b, cc)
        X21 = E12                                        # t = T21 for a smooth coat (G_int ≡ 1)
        tau = lanes.spec(self.coat.optical_depth(sp))
        inv = np.where(ok, 2.0 / np.where(ok, cos_t, 1.0), 0.0)
        a = np.where(ok[None, :], np.exp(-tau * inv[None, :]), 0.0)
        s1 = plane_of_incidence_axis(n, -wiK)
        s2 = plane_of_incidence_axis(n, woK)
        Mb = W.matrix()
        if W.kind == "depolarising":
            M = (a * Mb[0, 0])[None, None] * (X21[:, 0][:, None] * E12[0][None, :])
        else:
            R1 = rotation_mueller(s1, W.x_in, -wi_t)[:, :, None, :]
            R2 = rotation_mueller(W.x_out, s2, wo_t)[:, :, None, :]
            M = a[None, None] * _mm(X21, _mm(R2, _mm(Mb, _mm(R1, E12))))
        M = np.where(ok[None, None, None, :], M, 0.0)
        N = sp.n
        M = np.ascontiguousarray(np.broadcast_to(lanes.out(M), (4, 4) + sp.lam.shape))
        return M, s1[:, :N], s2[:, :N]

    def _coat_mirror(self, sp: ShadingPoint):
        wi, value, valid = mirror_reflection(sp, self._eta(sp).astype(np.complex128))
        return wi, value, valid

    def delta_reflection(self, sp: ShadingPoint):
        if not self.coat.smooth:
            return None
        wi, mirror, valid = self._coat_mirror(sp)
        layered = self._layered_delta(sp)
        if layered is None:
            return mirror
        M, x_in, x_out = layered
        s = mirror.x_in
        M = rotate_mueller_frames(M, x_in[:, None, :], s[:, None, :], -wi[:, None, :],
                                  x_out[:, None, :], s[:, None, :], sp.wo[:, None, :])
        return MuellerValue("general", s, s, M=mirror.matrix() + M)

    # --- sampling --------------------------------------------------------------------------------

    def _albedo_hint(self, sp: ShadingPoint) -> np.ndarray:
        if isinstance(self.base, Lambert):
            return np.clip(sp.spectrum(self.base.albedo).mean(axis=0), 0.0, 1.0)
        return np.ones(sp.n)

    def _plan(self, sp: ShadingPoint):
        """(P_top, η_ref, ω'_o, ok'_o, local frame) for the batch (functions of ω_o only)."""
        n = sp.n_s
        cos_o = sp.cos_o
        eta_ref = self._eta(sp).mean(axis=0)
        if self.coat.smooth:
            e_top = fresnel_reflection_abcs(np.clip(cos_o, 0.0, 1.0), eta_ref)[0]
        else:
            e_top = self.coat_reflectance(cos_o, eta_ref, self.coat.roughness(sp))
        wo_t, cos_t, ok_t = _refract_in(sp.wo, n, cos_o, eta_ref)
        ok_t &= cos_t > 0
        tau = self.coat.optical_depth(sp)
        a_est = np.where(ok_t, np.exp(-2.0 * tau / np.where(ok_t, cos_t, 1.0)[None, :]).mean(axis=0), 0.0)
        e_layer = (1.0 - e_top) * self._albedo_hint(sp) * a_est
        tot = e_top + e_layer
        p = np.where(tot > 0, e_top / np.where(tot > 0, tot, 1.0), 0.5)
        both = (e_top > 0) & (e_layer > 0)
        p = np.where(both, np.clip(p, *P_TOP_RANGE), p)
        return p, eta_ref, wo_t, ok_t

    def _refracted_pdf(self, sp, wi, cos_i, eta_ref, wo_t, ok_t):
        """Density of ω_i under "sample the base at ω'_o and refract out" (Jacobian included)."""
        wi_t, cos_ti, ok_i = _refract_in(wi, sp.n_s, cos_i, eta_ref)
        ok = ok_i & ok_t & (cos_ti > 0)
        if not np.any(ok):
            return np.zeros(sp.n)
        sp_b = ShadingPoint(sp.p, sp.n_s, sp.n_g, wo_t, sp.lam, sp.mono, surface=sp.surface)
        pb = self.base.pdf(sp_b, wi_t)
        jac = cos_i / (eta_ref * eta_ref * np.where(ok, cos_ti, 1.0))
        return np.where(ok, pb * jac, 0.0)

    def _top_pdf(self, sp, wi):
        t, b = local_frame(sp.n_s)
        wo_l = to_local(sp.wo, t, b, sp.n_s)
        wi_l = to_local(wi, t, b, sp.n_s)
        h, _, ok = half_vector(wi_l, wo_l)
        return np.where(ok, self.coat.facets(self.coat.roughness(sp)).pdf_reflected(wo_l, h), 0.0)

    def _pdf(self, sp, wi, plan):
        p_top, eta_ref, wo_t, ok_t = plan
        cos_i = dot(sp.n_s, wi)
        valid = (sp.cos_o > 0) & (cos_i > 0)
        out = np.zeros(sp.n)
        if not self.coat.smooth:
            out = out + p_top * self._top_pdf(sp, wi)
        layer = np.zeros(sp.n)
        if self.w_c > 0:
            layer = layer + self.w_c * np.maximum(cos_i, 0.0) / math.pi
        if self.w_c < 1:
            layer = layer + (1.0 - self.w_c) * self._refracted_pdf(sp, wi, cos_i, eta_ref, wo_t, ok_t)
        out = out + (1.0 - p_top) * layer
        return np.where(valid, out, 0.0)

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        return self._pdf(sp, wi, self._plan(sp))

    def sample(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        N = sp.n
        n = sp.n_s
        cos_o = sp.cos_o
        plan = self._plan(sp)
        p_top, eta_ref, wo_t, ok_t = plan
        front = cos_o > 0
        u_lobe = np.asarray(u_lobe, dtype=np.float64)
        pick_top = u_lobe < p_top
        u2 = np.clip((u_lobe - p_top) / np.where(p_top < 1, 1.0 - p_top, 1.0), 0.0, 1.0 - 1e-16)
        pick_cos = ~pick_top & (u2 < self.w_c)
        pick_base = ~pick_top & ~pick_cos
        u3 = np.clip((u2 - self.w_c) / (1.0 - self.w_c if self.w_c < 1 else 1.0), 0.0, 1.0 - 1e-16)

        wi = n.copy()
        ok_dir = np.zeros(N, bool)
        top_delta = np.zeros(N, bool)
        base_delta = np.zeros(N, bool)
        p_bd = np.ones(N)

        if np.any(pick_top & front):
            sel = np.nonzero(pick_top & front)[0]
            if self.coat.smooth:
                wi[:, sel] = reflect(sp.wo[:, sel], n[:, sel])
                top_delta[sel] = True
                ok_dir[sel] = True
            else:
                t, b = local_frame(n[:, sel])
                wo_l = to_local(sp.wo[:, sel], t, b, n[:, sel])
                m_pts = self.coat.roughness(sp)
                h = self.coat.facets(None if m_pts is None else m_pts[sel]).sample(wo_l, u_dir[:, sel])
                wi_l = reflect_local(wo_l, h)
                wi[:, sel] = t * wi_l[0] + b * wi_l[1] + n[:, sel] * wi_l[2]
                ok_dir[sel] = wi_l[2] > 0
        if np.any(pick_cos & front):
            sel = np.nonzero(pick_cos & front)[0]
            local = cosine_hemisphere(u_dir[:, sel])
            wi[:, sel] = local_to_world(local, n[:, sel])
            ok_dir[sel] = local[2] > 0
        if np.any(pick_base & front & ok_t):
            sel = np.nonzero(pick_base & front & ok_t)[0]
            sp_b = ShadingPoint(sp.p[:, sel], n[:, sel], sp.n_g[:, sel], wo_t[:, sel], sp.lam[:, sel], sp.mono,
                                surface=None if sp.surface is None else sp.surface.take(sel))
            bs = self.base.sample(sp_b, u3[sel], u_dir[:, sel])
            c_t = dot(n[:, sel], bs.wi)
            w_out, _, ok_out = _refract_out(bs.wi, n[:, sel], c_t, eta_ref[sel])
            is_d = np.asarray(bs.is_delta, bool)
            ok_b = np.asarray(bs.valid, bool) & ok_out
            if self.coat.smooth and np.any(is_d & ok_b):
                # The layered Dirac lobe: mirror direction; selection probability of the base's
                # Dirac lobe P_bd = W00/weight00 (both at the reference geometry).
                dsel = np.nonzero(is_d & ok_b)[0]
                Wd = self.base.delta_reflection(ShadingPoint(sp_b.p[:, dsel], sp_b.n_s[:, dsel],
                                                             sp_b.n_g[:, dsel], sp_b.wo[:, dsel],
                                                             sp_b.lam[:, dsel], sp.mono,
                                                             surface=None if sp_b.surface is None else
                                                             sp_b.surface.take(dsel)))
                if self.base.flags.is_delta_only or Wd is None:
                    pb = np.ones(dsel.size)
                else:
                    num = Wd.matrix()[0, 0]
                    den = bs.weight.matrix()[0, 0][:, dsel]
                    j = np.argmax(np.abs(den), axis=0)
                    cols = np.arange(dsel.size)
                    nn, dd = num[j, cols], den[j, cols]
                    pb = np.where(dd > 0, nn / np.where(dd > 0, dd, 1.0), 0.0)
                gsel = sel[dsel]
                wi[:, gsel] = reflect(sp.wo[:, gsel], n[:, gsel])
                base_delta[gsel] = pb > 0
                p_bd[gsel] = np.where(pb > 0, pb, 1.0)
                ok_dir[gsel] = pb > 0
            nd = ~is_d & ok_b
            if np.any(nd):
                gsel = sel[nd]
                wi[:, gsel] = w_out[:, nd]
                ok_dir[gsel] = True

        is_delta = top_delta | base_delta
        cos_i = dot(n, wi)
        nondelta = ok_dir & ~is_delta & front & (cos_i > 0)
        pdf = np.where(nondelta, self._pdf(sp, wi, plan), 0.0)
        nondelta &= pdf > 0
        value = self.eval(sp, wi)
        factor = np.where(nondelta, np.maximum(cos_i, 0.0) / np.where(nondelta, pdf, 1.0), 0.0)
        M = value.matrix() * factor[None, None, None, :]
        x_in, x_out = value.x_in.copy(), value.x_out.copy()

        if np.any(top_delta):
            _, mirror, mvalid = self._coat_mirror(sp)
            scale = np.where(top_delta & mvalid, 1.0 / np.where(p_top > 0, p_top, 1.0), 0.0)
            M = np.where(top_delta[None, None, None, :], mirror.matrix() * scale[None, None, None, :], M)
            x_in = np.where(top_delta[None, :], mirror.x_in, x_in)
            x_out = np.where(top_delta[None, :], mirror.x_out, x_out)
        if np.any(base_delta):
            Ml, xl_in, xl_out = self._layered_delta(sp)
            prob = (1.0 - p_top) * (1.0 - self.w_c) * p_bd
            scale = np.where(base_delta & (prob > 0), 1.0 / np.where(prob > 0, prob, 1.0), 0.0)
            M = np.where(base_delta[None, None, None, :], Ml * scale[None, None, None, :], M)
            x_in = np.where(base_delta[None, :], xl_in, x_in)
            x_out = np.where(base_delta[None, :], xl_out, x_out)

        valid = (nondelta | (is_delta & ok_dir)) & front & np.all(np.isfinite(M), axis=(0, 1, 2))
        M = np.where(valid[None, None, None, :], M, 0.0)
        return BSDFSample(wi=wi, weight=MuellerValue("general", x_in, x_out, M=M),
                          pdf=np.where(valid & ~is_delta, pdf, 0.0), is_delta=is_delta, valid=valid,
                          eta_sq=np.ones(N))

    def describe(self) -> dict:
        base = self.base
        return {"type": self.name, "form": self.form, "t_term": self.t_term,
                "transmission_normal": self.transmission_normal, "shadowing": self.shadowing,
                "exterior_n": repr(self._exterior), "coat": self.coat.describe(),
                "base": base.describe() if hasattr(base, "describe") else repr(base)}


# --------------------------------------------------------------------------- declarations

COAT = ModelDeclaration(
    "coat", "Coat", "One dielectric coat of a Weidlich–Wilkie stack",
    [Parameter("n", "real index of the coat", lo=0.0, lo_open=True, hi=100.0, default=1.5, texturable=True,
               socket=Socket("Coat IOR", "FLOAT", 1.5, 1.0, 5.0, "Index of the coat")),
     Parameter("thickness", "coat thickness d (any length unit; only absorption·d matters)", lo=0.0, default=0.0,
               texturable=True,
               socket=Socket("Coat Thickness", "FLOAT", 1.0, 0.0, 1e6,
                             "Coat thickness (any unit; only thickness × absorption matters)")),
     Parameter("absorption", "absorption coefficient α per unit thickness", kind="spectrum", lo=0.0, default=0.0,
               texturable=True,
               socket=Socket("Coat Absorption", "COLOR", (0.0, 0.0, 0.0), 0.0, 1e6,
                             "Absorption coefficient per unit thickness (linear sRGB)")),
     Parameter("distribution", "roughness of the coat's top interface", kind="choice", choices=DISTRIBUTIONS,
               default="smooth"),
     Parameter("exponent", "Blinn–Phong exponent e", lo=0.0, lo_open=True, hi=1e7, texturable=True,
               only_with=("distribution", ("blinn",))),
     Parameter("m", f"Beckmann rms slope; below {SMOOTH_LIMIT:g} (e.g. 0) a smooth coat (the distribution then "
                    "counts as 'smooth'); a texture ≥ the least slope everywhere", lo=0.0, hi=100.0, texturable=True,
               only_with=("distribution", ("beckmann",)),
               socket=Socket("Coat Roughness", "FLOAT", 0.0, 0.0, 5.0,
                             "Beckmann rms slope of the coat surface (0 = smooth)"))])


COAT.per_point = frozenset({"n", "thickness", "absorption", "m"})


@COAT.builder
def _coat(p):
    dist = p["distribution"]
    kw = {"exponent": p["exponent"]} if dist == "blinn" else {}
    if dist == "beckmann":
        m, smooth = declared_slope(p, "m")         # effectively smooth (roughness.SMOOTH_LIMIT): the smooth coat
        dist, kw = ("smooth", {}) if smooth else (dist, {"m": m})
    return Coat(n=p["n"], thickness=p["thickness"], absorption=p["absorption"], distribution=dist, **kw)


DECLARATION = ModelDeclaration(
    "weidlich_wilkie", "Weidlich–Wilkie Layered",
    "A clear or absorbing coat over a base material (plug another Polarising BSDF into Base)",
    [Parameter("coats", "the coats, top first", kind="coats", members=COAT),
     Parameter("base", "the material under the coats (a reflective one)", kind="material",
               default={"type": "lambert", "albedo": 0.8},
               socket=Socket("Base", "SHADER", None, None, None,
                             "The material under the coat: another Polarising BSDF (default: white Lambert)")),
     Parameter("form", "energy (energy conserving), published (as published) or first_order", kind="choice",
               choices=FORMS, default="energy"),
     Parameter("t_term", "transmission term: ww (1 − F21·G) or t21 (1 − F21)", kind="choice", choices=T_TERMS,
               default="ww", only_with=("form", ("published", "first_order"))),
     Parameter("transmission_normal", "refraction through the facet or the macro normal (default: facet for "
                                      "the published form, macro for the energy form)", kind="choice",
               choices=TRANSMISSION_NORMALS, default=None)],
    catalogue="weidlich_wilkie", node="WEIDLICH_WILKIE")


@DECLARATION.builder
def _weidlich_wilkie(p, coats, base):
    form, normal = p["form"], p["transmission_normal"]
    if form == "energy" and normal == "facet":
        raise SceneError(p.field("transmission_normal"), "the energy-conserving form refracts through the macro "
                                                         "normal: use 'macro' (or form 'published')")
    t_term = p["t_term"]
    try:
        return WeidlichWilkie(coats, base, form=form, t_term=t_term, transmission_normal=normal)
    except SceneError:
        raise
    except ValueError as e:
        raise SceneError(p.where, str(e)) from None
