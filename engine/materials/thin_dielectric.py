"""Thin dielectric pane: two parallel smooth interfaces, incoherent multiple reflections inside.

For windows and cover glasses modelled as one surface: the pane (index ``n``) sits in a medium of
index ``exterior_n`` on both sides, its thickness is negligible (no refraction offset: transmitted
light continues along −ω_o) and the internal bounces add incoherently (thickness ≫ coherence length).

Per interface the Fresnel amplitudes r_s, r_p at the incidence cosine (η = n/exterior_n, docs/physics.md §0)
give R = |r|², T = 1 − R per channel; inside the pane the reflection amplitude is −r (Stokes relations)
and t·t′ = 1 − r² = T.  Every path through the pane is a Jones matrix diag(a_s, a_p); summing their
Mueller matrices (the ABCS block form: the s and p channels separate) gives geometric series:

- reflection, a = r (first surface) and −T r^{2k+1} (k ≥ 0 internal round trips):
  R_tot = R + T² R/(1 − R²) = 2R/(1 + R) per channel,
  C_R = Re(r_s r_p*) + T_s T_p r_s r_p/(1 − R_s R_p),  S_R = −Im(r_s r_p*);
- transmission, a = T r^{2k}:  T_tot = T²/(1 − R²) = (1 − R)/(1 + R),  C_T = T_s T_p/(1 − R_s R_p),  S_T = 0;
- A = (X_s + X_p)/2, B = (X_s − X_p)/2 with X = R_tot or T_tot.

At Brewster's angle r_p = 0: the reflection is fully s-polarised and the transmitted light has degree
of polarisation R_s.  With n < exterior_n (a gap of low index) total internal reflection at the first
interface reflects everything (a retarder: S ≠ 0).  Frames: x = s = unit(n × k), shared by the
incident, reflected and transmitted beams (the transmitted beam is the incident one).  No radiance
scaling (the same medium on both sides).  Sampling: reflection with probability (R_tot,s + R_tot,p)/2,
weights divided by the chosen probability.  Two-sided.
"""

from __future__ import annotations

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, MuellerValue, ShadingPoint, depolarising_value
from .dielectric import IOR_SOCKET
from .parameters import ModelDeclaration, Parameter, exterior_n_parameter
from ..polarisation.frames import plane_of_incidence_axis
from ..polarisation.fresnel import fresnel_amplitudes
from ..vec3 import reflect


def thin_pane_abcs(cos_theta, eta):
    """((A, B, C, S) of reflection, (A, B, C, S) of transmission) of a thin pane of relative index η."""
    r_s, r_p = fresnel_amplitudes(cos_theta, eta)
    R_s = r_s.real ** 2 + r_s.imag ** 2
    R_p = r_p.real ** 2 + r_p.imag ** 2
    T_s = np.clip(1.0 - R_s, 0.0, 1.0)
    T_p = np.clip(1.0 - R_p, 0.0, 1.0)
    Rt_s, Rt_p = 2.0 * R_s / (1.0 + R_s), 2.0 * R_p / (1.0 + R_p)
    Tt_s, Tt_p = T_s / (1.0 + R_s), T_p / (1.0 + R_p)          # T²/(1 − R²) = T/(1 + R)
    den = 1.0 - R_s * R_p
    ok = den > 0                                                 # 0 only under total reflection (T = 0)
    series = np.where(ok, T_s * T_p / np.where(ok, den, 1.0), 0.0)
    x = r_s * np.conj(r_p)
    # r_s r_p is real below the critical angle; under TIR the series term vanishes (T = 0)
    C_R = x.real + series * np.where(ok, (r_s * r_p).real, 0.0)
    refl = (0.5 * (Rt_s + Rt_p), 0.5 * (Rt_s - Rt_p), C_R, -x.imag)
    trans = (0.5 * (Tt_s + Tt_p), 0.5 * (Tt_s - Tt_p), series, np.zeros_like(series))
    return refl, trans


class ThinDielectric(BSDF):
    """Thin two-interface pane (see the module docstring)."""

    name = "thin_dielectric"

    def __init__(self, n: float, exterior_n: float = 1.0):
        self.n_int = float(n)
        self.n_ext = float(exterior_n)
        for name, v in (("n", self.n_int), ("exterior_n", self.n_ext)):
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        self.flags = (BSDFFlags.DELTA_REFLECTION | BSDFFlags.DELTA_TRANSMISSION | BSDFFlags.POLARISING
                      | BSDFFlags.when(self.n_int < self.n_ext, BSDFFlags.RETARDING))

    def _geometry(self, sp: ShadingPoint):
        cos_o = sp.cos_o
        nn = np.where((cos_o >= 0)[None, :], sp.n_s, -sp.n_s)
        return np.abs(cos_o), nn

    def eval(self, sp, wi):
        return depolarising_value(np.zeros_like(sp.lam), sp.n)

    def pdf(self, sp, wi):
        return np.zeros(sp.n)

    def _tile(self, sp, values):
        L = sp.lam.shape[0]
        return [np.broadcast_to(v, (L, sp.n)).copy() for v in values]

    def delta_reflection(self, sp):
        c, nn = self._geometry(sp)
        s = plane_of_incidence_axis(nn, sp.wo)
        refl, _ = thin_pane_abcs(c, self.n_int / self.n_ext)
        return MuellerValue("abcs", s, s, *self._tile(sp, refl))

    def sample(self, sp, u_lobe, u_dir) -> BSDFSample:
        c, nn = self._geometry(sp)
        refl, trans = thin_pane_abcs(c, self.n_int / self.n_ext)
        p_r = refl[0]
        reflect_lobe = u_lobe < p_r
        wi = np.where(reflect_lobe[None, :], reflect(sp.wo, nn), -sp.wo)
        # k_i and k_o lie in the plane of incidence (or along n): one s for every beam
        s = plane_of_incidence_axis(nn, sp.wo)
        pr = np.where(p_r > 0, p_r, 1.0)
        pt = np.where(p_r < 1, 1.0 - p_r, 1.0)
        value = [np.where(reflect_lobe, r / pr, t / pt) for r, t in zip(refl, trans)]
        return BSDFSample(wi=wi, weight=MuellerValue("abcs", s, s, *self._tile(sp, value)), pdf=np.zeros(sp.n),
                          is_delta=np.ones(sp.n, bool), valid=np.ones(sp.n, bool), eta_sq=np.ones(sp.n))

    def describe(self):
        return {"type": self.name, "n": self.n_int, "exterior_n": self.n_ext}


# --------------------------------------------------------------------------- declaration

DECLARATION = ModelDeclaration(
    "thin_dielectric", "Thin Dielectric",
    "Thin pane (window, cover glass): two interfaces, incoherent internal reflections, no refraction offset",
    [Parameter("n", "real index of the pane", lo=0.0, lo_open=True, socket=IOR_SOCKET),
     exterior_n_parameter()],
    catalogue="thin_dielectric", node="THIN_DIELECTRIC")


@DECLARATION.builder
def _thin_dielectric(p):
    return ThinDielectric(p["n"], p["exterior_n"])
