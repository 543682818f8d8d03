"""Rayleigh scattering with a depolarisation factor δ (Hansen & Travis 1974 eq. 2.15; Chandrasekhar 1950).

In the scattering-plane frames of engine.media.phase (x = s ⟂ the scattering plane, so S1 > 0 is light
polarised perpendicular to it — the opposite sign of Hansen & Travis's Q = I_l − I_r), with
μ = cos Θ, Δ = (1 − δ)/(1 + δ/2) and Δ' = (1 − 2δ)/(1 − δ):

    M = Δ·(3/16π)·[[1+μ², 1−μ², 0, 0], [1−μ², 1+μ², 0, 0], [0, 0, 2μ, 0], [0, 0, 0, 2Δ'μ]]
        + (1 − Δ)/(4π)·diag(1, 0, 0, 0)          (1/sr, ∫ M00 dΩ = 1)

so unpolarised light scattered at Θ has DoLP = (1−δ)(1−μ²)/(1+δ+(1−δ)μ²), polarised ⟂ the
scattering plane.  δ = 0: Chandrasekhar's Rayleigh matrix (Cycles' Rayleigh phase for S0); δ = 1: an
isotropic depolariser; air ≈ 0.0279 (Young 1980), 0.031 in Hansen & Travis.  No retardance (S3 is
not created), the same at every wavelength (the λ⁻⁴ law belongs to the scattering coefficient).
Sampling: a1 ∝ 1 + βμ² with β = 3Δ/(4 − Δ), inverted exactly (engine.media.phase).
"""

from __future__ import annotations

import numpy as np

from .phase import FOUR_PI, PhaseFunction, PhaseMatrix, sample_one_plus_beta_mu2
from ..materials.flags import BSDFFlags
from ..materials.parameters import ModelDeclaration, Parameter


class Rayleigh(PhaseFunction):
    name = "rayleigh"

    def __init__(self, depolarisation: float = 0.0):
        d = float(depolarisation)
        self.depolarisation = d
        self.share = (1.0 - d) / (1.0 + 0.5 * d)                 # Δ: the polarised share
        self.share_circular = (1.0 - 2.0 * d) / (1.0 + 0.5 * d)  # Δ·Δ' (finite at δ = 1)
        self.beta = 3.0 * self.share / (4.0 - self.share)
        self.flags = BSDFFlags.when(self.share > 0, BSDFFlags.POLARISING)

    def elements(self, mu, lam) -> PhaseMatrix:
        mu, _ = np.broadcast_arrays(np.asarray(mu, dtype=np.float64), np.asarray(lam, dtype=np.float64))
        k = 3.0 / (16.0 * np.pi)
        mu2 = mu * mu
        a1 = k * self.share * (1.0 + mu2) + (1.0 - self.share) / FOUR_PI
        if self.share == 0.0:
            return PhaseMatrix.depolarising(a1)
        return PhaseMatrix("general", a1, k * self.share * (1.0 - mu2), k * self.share * (1.0 + mu2),
                           2.0 * k * self.share * mu, 0.0 * mu, 2.0 * k * self.share_circular * mu)

    def pdf_mu(self, mu, lam) -> np.ndarray:
        mu = np.asarray(mu, dtype=np.float64)
        return (1.0 + self.beta * mu * mu) / (FOUR_PI * (1.0 + self.beta / 3.0)) + 0.0 * np.asarray(lam)

    def sample_mu(self, u, lam):
        return sample_one_plus_beta_mu2(np.asarray(u, dtype=np.float64), self.beta)

    def describe(self) -> dict:
        return {"type": self.name, "depolarisation": self.depolarisation}


DECLARATION = ModelDeclaration(
    "rayleigh", "Rayleigh", "Rayleigh scattering by particles much smaller than the wavelength, polarising "
    "(Hansen & Travis 1974), with a depolarisation factor",
    [Parameter("depolarisation", "depolarisation factor δ (anisotropy of the molecules; air ≈ 0.0279)",
               lo=0.0, hi=1.0, default=0.0)],
    catalogue="rayleigh")


@DECLARATION.builder
def _rayleigh(p):
    return Rayleigh(p["depolarisation"])
