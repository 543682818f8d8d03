"""Cycles' approximate Mie phase function for water droplets, as a depolariser.

Cycles' Volume Scatter "Mie" (kernel/svm/closure.h, CLOSURE_VOLUME_MIE_ID) is the blend
(1 − w)·HG(g_HG) + w·Draine(g_D, α) of Jendersie & d'Eon 2023 ("An Approximate Mie Scattering Function
for Fog and Cloud Rendering"), with g_HG, g_D, α, w fitted to the droplet diameter d in µm
(phase_mie_fitted_parameters in kernel/closure/volume_util.h, evaluated here in double precision with
exact log/sin/cos where Cycles uses its fast approximations).  The fit stands for water droplets in air,
0 < d < 50 µm, at no particular wavelength; engine.media.mie is the exact Lorenz–Mie matrix to compare
it with.  Sampling picks the HG lobe with probability 1 − w, else Draine, each exactly: the pdf is the
blend.  Draine's formula is evaluated as written also where Cycles substitutes Rayleigh
(|g_D| < 10⁻³, d ≲ 0.03 µm; engine.media.draine).
"""

from __future__ import annotations

import math

import numpy as np

from .draine import draine_density, draine_sample_mu
from .henyey_greenstein import clamp_g, hg_density, hg_sample_mu
from .phase import PhaseFunction, PhaseMatrix
from ..materials.parameters import ModelDeclaration, Parameter


def fitted_parameters(d: float) -> tuple[float, float, float, float]:
    """(g_HG, g_D, α, w) of Cycles' fit at diameter d µm (d < 0 counts as 0)."""
    d = max(float(d), 0.0)
    if d <= 0.1:
        return 13.8 * d * d, 1.1456 * d * math.sin(9.29044 * d), 250.0, 0.252977 - 312.983 * d ** 4.3
    ld = math.log(d)
    if d < 1.5:
        a = (ld - 0.238604) * (ld + 1.00667)
        b = 0.507522 - 0.15677 * ld
        c = 1.19692 * math.cos(a / b) + 1.37932 * ld + 0.0625835
        return (0.862 - 0.143 * ld * ld, 0.379685 * math.cos(c) + 0.344213, 250.0,
                0.146209 * math.cos(3.38707 * ld + 2.11193) + 0.316072 + 0.0778917 * ld)
    if d < 5.0:
        lld = math.log(ld)
        return (0.0604931 * lld + 0.940256, 0.500411 - 0.081287 / (-2.0 * ld + math.tan(ld) + 1.27551),
                7.30354 * ld + 6.31675, 0.026914 * (ld - math.cos(5.68947 * (lld - 0.0292149))) + 0.3764)
    return (math.exp(-0.0990567 / (d - 1.67154)), math.exp(-2.20679 / (d + 3.91029) - 0.428934),
            math.exp(3.62489 - 8.29288 / (d + 5.52825)), math.exp(-0.599085 / (d - 0.641583) - 0.665888))


class CyclesMie(PhaseFunction):
    name = "cycles_mie"

    def __init__(self, diameter: float = 20.0):
        self.diameter = float(diameter)
        g_hg, g_d, self.alpha, self.w = fitted_parameters(self.diameter)
        self.g_hg, self.g_d = clamp_g(g_hg), clamp_g(g_d)

    def elements(self, mu, lam) -> PhaseMatrix:
        return PhaseMatrix.depolarising(self.pdf_mu(mu, lam))

    def pdf_mu(self, mu, lam) -> np.ndarray:
        mu, _ = np.broadcast_arrays(np.asarray(mu, dtype=np.float64), np.asarray(lam, dtype=np.float64))
        return (1.0 - self.w) * hg_density(mu, self.g_hg) + self.w * draine_density(mu, self.g_d, self.alpha)

    def sample_mu(self, u, lam):
        """u < 1 − w: HG with u/(1 − w); else Draine with the rescaled rest (one number, both exact)."""
        u = np.asarray(u, dtype=np.float64)
        hg = u < 1.0 - self.w
        out = np.empty_like(u)
        out[hg] = hg_sample_mu(u[hg] / (1.0 - self.w), self.g_hg)
        rest = ~hg
        out[rest] = draine_sample_mu(np.minimum((u[rest] - (1.0 - self.w)) / self.w, np.nextafter(1.0, 0.0)),
                                     self.g_d, self.alpha)
        return out

    def describe(self) -> dict:
        return {"type": self.name, "diameter": self.diameter}


DECLARATION = ModelDeclaration(
    "cycles_mie", "Mie (Cycles' approximation)", "Cycles' Mie phase function for water droplets: a fitted "
    "Henyey–Greenstein + Draine blend (Jendersie & d'Eon 2023), depolarising",
    [Parameter("diameter", "droplet diameter (the fit holds for 0–50 µm)", unit="µm", lo=0.0, hi=1000.0,
               default=20.0)],
    catalogue="cycles_mie")


@DECLARATION.builder
def _cycles_mie(p):
    return CyclesMie(p["diameter"])
