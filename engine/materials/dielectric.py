"""Smooth dielectric interface with reflection, refraction and total internal reflection.

Two-sided: the interior (index ``n``) lies behind the shading normal, the
exterior (``exterior_n``) in front of it.  From the viewer's side (wo) the
relative index is η = n_far / n_near.

- Reflection: the Fresnel Mueller matrix M_F(cosθ_o, η) in the plane-of-
  incidence frames; beyond the critical angle (TIR) r_s, r_p are complex
  with |r| = 1, so M_F becomes a pure retarder (S ≠ 0: circular polarisation).
- Refraction: the diattenuator with T_s = 1 − F_s, T_p = 1 − F_p (no
  retardance for real η below the critical angle), in the shared s-p frames
  x = s = unit(n × k).
- Lobe choice: reflection with probability P_r = mean over the path's
  wavelengths of the unpolarised reflectance (F_s + F_p)/2; the weights are
  divided by the chosen probability, so the estimator is exact per wavelength.

**Radiance scaling.**  Radiance is not conserved across a refracting interface:
L/n² is.  Paths are traced from the camera, so a refracted camera ray that
moves from a medium of index n_o (the wo side) into n_i (the wi side) carries
radiance L_o = (n_o/n_i)² T L_i.  The factor (n_o/n_i)² = 1/η² is part of the
sample weight, *not* of the Mueller matrix; it cancels for a path that enters
and leaves a closed object (as in Mitsuba 3's ``dielectric``).

The index must be the same at every wavelength (no dispersion): a refracted
direction is shared by all wavelengths of a path.
"""

from __future__ import annotations

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, MuellerValue, ShadingPoint, depolarising_value
from .parameters import ModelDeclaration, Parameter, Socket, exterior_n_parameter
from ..polarisation.frames import plane_of_incidence_axis
from ..polarisation.fresnel import fresnel_reflection_abcs, fresnel_transmission_abcs, refracted_cosine
from ..vec3 import reflect


class SmoothDielectric(BSDF):
    name = "dielectric"
    # total internal reflection retards; the index is one number (no dispersion): λ-independent
    flags = BSDFFlags.DELTA_REFLECTION | BSDFFlags.DELTA_TRANSMISSION | BSDFFlags.POLARISING | BSDFFlags.RETARDING

    def __init__(self, n: float, exterior_n: float = 1.0):
        self.n_int = float(n)
        self.n_ext = float(exterior_n)

    def _sides(self, sp: ShadingPoint):
        cos_o = sp.cos_o
        outside = cos_o >= 0
        eta = np.where(outside, self.n_int / self.n_ext, self.n_ext / self.n_int)
        nn = np.where(outside[None, :], sp.n_s, -sp.n_s)
        return np.abs(cos_o), eta, nn

    def eval(self, sp, wi):
        return depolarising_value(np.zeros_like(sp.lam), sp.n)

    def pdf(self, sp, wi):
        return np.zeros(sp.n)

    def delta_reflection(self, sp):
        c, eta, nn = self._sides(sp)
        wi = reflect(sp.wo, nn)
        s = plane_of_incidence_axis(nn, -wi)
        A, B, C, S = fresnel_reflection_abcs(c, eta)
        L = sp.lam.shape[0]
        tile = lambda v: np.broadcast_to(v, (L, sp.n)).copy()  # noqa: E731
        return MuellerValue("abcs", s, s, tile(A), tile(B), tile(C), tile(S))

    def sample(self, sp, u_lobe, u_dir) -> BSDFSample:
        c, eta, nn = self._sides(sp)
        L = sp.lam.shape[0]
        A, B, C, S = fresnel_reflection_abcs(c, eta)
        p_reflect = A  # the index is wavelength-independent, so A is the same for every λ
        reflect_lobe = u_lobe < p_reflect

        wi_r = reflect(sp.wo, nn)
        cos_t, tir = refracted_cosine(c, eta)
        inv_eta = 1.0 / eta
        # Refraction of the camera ray d = −wo: t = d/η + (c/η − cosθ_t) n.
        wi_t = -sp.wo * inv_eta + (c * inv_eta - cos_t) * nn
        wi = np.where(reflect_lobe[None, :], wi_r, wi_t)
        s = plane_of_incidence_axis(nn, -wi)

        At, Bt, Ct, St = fresnel_transmission_abcs(c, eta)
        p_r = np.where(p_reflect > 0, p_reflect, 1.0)
        p_t = np.where(p_reflect < 1, 1.0 - p_reflect, 1.0)
        radiance_scale = inv_eta * inv_eta
        scale_t = radiance_scale / p_t
        pick = lambda r, t: np.where(reflect_lobe, r / p_r, t * scale_t)  # noqa: E731
        tile = lambda v: np.broadcast_to(v, (L, sp.n)).copy()  # noqa: E731
        value = MuellerValue("abcs", s, s, tile(pick(A, At)), tile(pick(B, Bt)), tile(pick(C, Ct)),
                             tile(pick(S, St)))
        valid = reflect_lobe | ~tir
        eta_sq = np.where(reflect_lobe, 1.0, eta * eta)
        return BSDFSample(wi=wi, weight=value, pdf=np.zeros(sp.n), is_delta=np.ones(sp.n, bool),
                          valid=valid, eta_sq=eta_sq)

    def describe(self):
        return {"type": self.name, "n": self.n_int, "exterior_n": self.n_ext}


# --------------------------------------------------------------------------- declaration

#: The Polarising BSDF node's index input of the smooth dielectric models (glass and black glass).
IOR_SOCKET = Socket("IOR", "FLOAT", 1.5, 1.0001, 5.0, "Index of refraction of the material (outside: 1)")

DECLARATION = ModelDeclaration(
    "dielectric", "Fresnel Dielectric",
    "Smooth glass-like interface: reflection, refraction, total internal reflection",
    [Parameter("n", "real index of the material", lo=0.0, lo_open=True, socket=IOR_SOCKET),
     exterior_n_parameter()], node="DIELECTRIC")


@DECLARATION.builder
def _dielectric(p):
    return SmoothDielectric(p["n"], p["exterior_n"])
