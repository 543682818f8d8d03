"""Cycles' Refraction BSDF: refraction only, without Fresnel (not a physical interface).

Cycles' closure (kernel/closure/bsdf_microfacet.h, ``bsdf_microfacet_*_refraction_setup``: MicrofacetFresnel::NONE)
transmits everything that can refract — transmittance 1 at every facet, 0 under total internal reflection — and
reflects nothing; its sharp form (roughness 0) is the delta refraction of the same rule.  No energy compensation
(Cycles calls none for this closure): a rough lobe loses what its shadowing-masking and total internal reflection
take.  Two-sided as engine.materials.dielectric (interior ``n`` behind the shading normal).

Polarisation: with no Fresnel there are no s and p transmittances to differ, and the normalised Fresnel
transmission matrix M_T/M_T,00 would amplify light polarised along the stronger axis above its intensity
(docs/physics.md, "Cycles' Refraction BSDF").  The model's Mueller matrix is the **identity** in the refraction's
frames — the scattering-plane frames x_in = x_out = unit(k_i × k_o) (the plane of incidence of the smooth one) —
times the scalar BTDF: non-polarising, energy-conserving, realisable; polarised light passes unchanged.

- Rough (α ≥ roughness.ALPHA_MIN; GGX or Beckmann facets, α = Blender roughness² ≤ 1): the rough dielectric's
  transmission lobe (engine.materials.rough_dielectric, Walter 2007, with its facet pair, separable Smith G and
  radiance convention) with M_T replaced by the identity (the compiled passes' ``no_fresnel``); sampled by the
  visible normals of ω_o, every sample refracting: pdf D_ωo(h)·η²|ω_i·h|/(η ω_i·h + ω_o·h)², none under total
  internal reflection at the sampled facet (the path ends, as Cycles').
- Smooth: the delta refraction t = −ω_o/η + (cosθ_o/η − cosθ_t) n, weight identity/η² (the radiance scaling of
  engine.materials.dielectric; BSDF.radiance_scaling), invalid under total internal reflection.
- The index and the roughness may vary per point (TexturedNumber), as the rough dielectric's: every formula is
  elementwise; an index per point stays on one side of exterior_n; where it equals exterior_n the light passes
  straight through (weight 1).
"""

from __future__ import annotations

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, MuellerValue, depolarising_value
from .dielectric import SmoothDielectric, one_side_of
from .parameters import ModelDeclaration, Parameter
from .rough_dielectric import DECLARATION as ROUGH_DIELECTRIC
from .rough_dielectric import DISTRIBUTIONS, RoughDielectric, index_matched
from .roughness import SMOOTH_LIMIT, declared_slope


class Refraction(RoughDielectric):
    """Rough refraction without Fresnel (see the module docstring); the rough dielectric's parameters, no
    ``multiscatter``."""

    name = "refraction"
    flags = BSDFFlags.GLOSSY_TRANSMISSION
    no_fresnel = True

    def __init__(self, n, alpha, distribution: str = "ggx", exterior_n: float = 1.0):
        super().__init__(n, alpha, distribution, "smith", exterior_n, multiscatter=False)

    def describe(self) -> dict:
        out = super().describe()
        del out["shadowing"]
        return out

    def lobe_colors(self, sp):
        """Cycles' Refraction colours (engine.materials.glass_colors.refraction_colors): no glossy."""
        from .glass_colors import refraction_colors
        return refraction_colors(sp, self._n(sp), self.n_ext)


class SmoothRefraction(SmoothDielectric):
    """Delta refraction without Fresnel (see the module docstring)."""

    name = "refraction"
    flags = BSDFFlags.DELTA_TRANSMISSION

    def delta_reflection(self, sp):
        return None

    def sample(self, sp, u_lobe, u_dir) -> BSDFSample:
        c, eta, nn = self._sides(sp)
        wi, s, tir, inv_eta = self._directions(sp, c, eta, nn, np.zeros(sp.n, bool))
        scale = np.broadcast_to(np.where(tir, 0.0, inv_eta * inv_eta), (sp.lam.shape[0], sp.n)).copy()
        zero = np.zeros_like(scale)
        return BSDFSample(wi=wi, weight=MuellerValue("abcs", s, s, scale, zero, scale.copy(), zero.copy()),
                          pdf=np.zeros(sp.n), is_delta=np.ones(sp.n, bool), valid=~tir,
                          eta_sq=np.broadcast_to(eta * eta, (sp.n,)).copy())

    def scatter_delta(self, v) -> bool:
        return False

    def eval(self, sp, wi):
        return depolarising_value(np.zeros_like(sp.lam), sp.n)

    def lobe_colors(self, sp):
        """Cycles' Refraction colours (engine.materials.glass_colors.refraction_colors): no glossy."""
        from .glass_colors import refraction_colors
        return refraction_colors(sp, self._n(sp), self.n_ext)


# --------------------------------------------------------------------------- declaration

DECLARATION = ModelDeclaration(
    "refraction", "Refraction (Cycles)",
    "Cycles' Refraction BSDF: refraction only, no Fresnel (every facet transmits all but total internal "
    "reflection); non-polarising",
    [ROUGH_DIELECTRIC["n"],
     ROUGH_DIELECTRIC["alpha"].with_(default=0.0, socket=None,
                                     doc=f"microfacet roughness α (GGX α or Beckmann rms slope; Blender's roughness²); "
                                         f"below {SMOOTH_LIMIT:g} (e.g. 0) the sharp refraction"),
     Parameter("distribution", "microfacet distribution", kind="choice", choices=DISTRIBUTIONS, default="ggx"),
     ROUGH_DIELECTRIC["exterior_n"]],
    catalogue="refraction")

#: the index and the roughness may vary per point (Blender's Refraction BSDF with linked IOR, Roughness)
DECLARATION.per_point = frozenset({"n", "alpha"})


@DECLARATION.builder
def _refraction(p) -> BSDF:
    n, exterior, distribution = one_side_of(p, "n", p["exterior_n"]), p["exterior_n"], p["distribution"]
    alpha, smooth = declared_slope(p, "alpha")
    if smooth or index_matched(n, exterior):      # the smooth limit, or no interface at all (straight through)
        return SmoothRefraction(n, exterior)
    return Refraction(n, alpha, distribution, exterior)
