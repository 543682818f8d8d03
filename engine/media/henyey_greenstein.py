"""Henyey–Greenstein phase function as a depolariser: M = p_HG(μ)·diag(1, 0, 0, 0).

p_HG(μ) = (1 − g²)/(4π (1 + g² − 2gμ)^{3/2}) per steradian, μ = cos Θ (engine.media.phase), mean
cosine g.  As Cycles (kernel/closure/volume_henyey_greenstein.h) g is clamped to ±(1 − 10⁻³); unlike
Cycles' shortcut for |g| < 10⁻³ (isotropic) the formula is evaluated for every g.  Sampling inverts
the CDF exactly in a form without cancellation at small g (docs/physics.md "Phase functions"):
with v = 2u − 1, μ = [v + g(v² + 3)/2 + g²v + g³(v² − 1)/2]/(1 + gv)².
"""

from __future__ import annotations

import numpy as np

from .phase import FOUR_PI, PhaseFunction, PhaseMatrix
from ..materials.parameters import ModelDeclaration, Parameter

#: Largest |g| (Cycles' clamp: volume_henyey_greenstein_setup, volume_draine_setup).
G_LIMIT = 1.0 - 1e-3


def clamp_g(g: float) -> float:
    """g clamped to ±G_LIMIT, as Cycles clamps its anisotropy."""
    return float(np.sign(g) * min(abs(float(g)), G_LIMIT))


def hg_density(mu, g):
    """p_HG (1/sr) at μ (any shape) for |g| < 1."""
    s = 1.0 + g * g - 2.0 * g * np.asarray(mu, dtype=np.float64)
    return (1.0 - g * g) / (FOUR_PI * s * np.sqrt(s))


def hg_sample_mu(u, g):
    """μ distributed as p_HG from u ∈ [0, 1) (exact inversion, stable at g → 0)."""
    v = 2.0 * np.asarray(u, dtype=np.float64) - 1.0
    t = 1.0 + g * v
    mu = (v + 0.5 * g * (v * v + 3.0) + g * g * v + 0.5 * g ** 3 * (v * v - 1.0)) / (t * t)
    return np.clip(mu, -1.0, 1.0)


class HenyeyGreenstein(PhaseFunction):
    name = "henyey_greenstein"

    def __init__(self, g: float = 0.0):
        self.anisotropy = float(g)
        self.g = clamp_g(g)

    def elements(self, mu, lam) -> PhaseMatrix:
        return PhaseMatrix.depolarising(self.pdf_mu(mu, lam))

    def pdf_mu(self, mu, lam) -> np.ndarray:
        mu, _ = np.broadcast_arrays(np.asarray(mu, dtype=np.float64), np.asarray(lam, dtype=np.float64))
        return hg_density(mu, self.g)

    def sample_mu(self, u, lam):
        return hg_sample_mu(u, self.g)

    def describe(self) -> dict:
        return {"type": self.name, "g": self.anisotropy}


G_PARAMETER = Parameter("g", "anisotropy: mean cosine of the scattering angle (clamped to ±0.999 as Cycles)",
                        lo=-1.0, hi=1.0, default=0.0)

DECLARATION = ModelDeclaration(
    "henyey_greenstein", "Henyey–Greenstein", "Henyey–Greenstein phase function, depolarising (Cycles' default "
    "volume phase)", [G_PARAMETER], catalogue="henyey_greenstein")


@DECLARATION.builder
def _henyey_greenstein(p):
    return HenyeyGreenstein(p["g"])
