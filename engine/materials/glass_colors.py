"""Cycles' Glossy and Transmission Color of a glass (``bsdf_albedo`` of its microfacet glass closure,
kernel/closure/bsdf_microfacet.h ``bsdf_microfacet_estimate_albedo``), for the light passes
(engine.render.light_passes; BSDF.lobe_colors).

- transmission: 1 − F(cosθ_o), the smooth interface's unpolarised transmittance at the view angle (Cycles'
  ``microfacet_fresnel`` at cos NI, at any roughness);
- glossy: at roughness 0 the reflectance F(cosθ_o); rough, Cycles' table estimate mix(F0, 1, s), s its
  ggx_gen_schlick_ior_s table: the GGX reflection lobe's albedo with the real Fresnel over its albedo with F = 1,
  E_F(μ, α)/E(μ, α) (engine.materials.ggx_energy: E_F from the lobe's albedo table of this index, E the
  height-correlated conductor table), read with the outside index from either side (as Cycles' Principled glass
  reads its table by |η − 1|/(η + 1)).
"""

from __future__ import annotations

import numpy as np

from .base import LobeColors, ShadingPoint


def smooth_glass_colors(sp: ShadingPoint, reflectance: np.ndarray) -> LobeColors:
    """Glossy R, transmission 1 − R (each (L, N)) from the mirror's reflectance ``reflectance`` (L, N)."""
    R = np.broadcast_to(reflectance, sp.lam.shape)
    return LobeColors.of(sp, glossy=R, transmission=1.0 - R)


def rough_glass_colors(sp: ShadingPoint, eta: float, alpha: float) -> LobeColors:
    """Cycles' colours of a rough glass of relative index ``eta`` (inside over outside) and GGX α at the points."""
    from .ggx_energy import conductor_albedo
    from .torrance_sparrow import SpecularAlbedoTable
    from ..polarisation.fresnel import fresnel_reflectance
    cos_o = sp.cos_o
    mu = np.clip(np.abs(cos_o), 0.0, 1.0)
    side = np.where(cos_o >= 0, eta, 1.0 / eta)
    F = fresnel_reflectance(mu[None, :], side[None, :] + 0j)[0]
    outside = max(eta, 1.0 / eta)
    E_F = SpecularAlbedoTable(complex(outside), alpha, alpha, "smith_correlated", "ggx")(mu, alpha)
    E = conductor_albedo(mu, alpha, correlated=True)
    glossy = np.where(E > 0, E_F / np.where(E > 0, E, 1.0), 0.0)
    return LobeColors.of(sp, glossy=np.clip(glossy, 0.0, 1.0), transmission=1.0 - F)


def refraction_colors(sp: ShadingPoint, n, n_ext: float) -> LobeColors:
    """Cycles' colours of its Refraction BSDF (no Fresnel: ``microfacet_fresnel`` gives transmittance 1 except
    total internal reflection at cos NI, and no reflection) of index ``n`` (a number or (N,) per point) in
    ``n_ext``: glossy 0, transmission 1 where the view direction refracts, 0 beyond the critical angle."""
    cos_o = sp.cos_o
    eta = np.where(cos_o >= 0, n / n_ext, n_ext / n)             # transmitted over incident index
    tir = 1.0 - cos_o * cos_o > eta * eta
    return LobeColors.of(sp, transmission=np.where(tir, 0.0, 1.0))

