"""Draine's phase function (Draine 2003, ApJ 598:1017) as a depolariser: M = p_D(μ)·diag(1, 0, 0, 0).

p_D(μ) = (1 − g²)(1 + αμ²) / ((1 + α(1 + 2g²)/3)·4π·(1 + g² − 2gμ)^{3/2}) per steradian: Henyey–Greenstein
(α = 0), Cornette–Shanks (α = 1), Rayleigh's S0 (g = 0, α = 1).  As Cycles (kernel/closure/volume_util.h,
volume_draine.h) g is clamped to ±(1 − 10⁻³); unlike Cycles, which substitutes HG for |α| < 10⁻³ and
Rayleigh for |g| < 10⁻³ with α > 0.999 (for its Mie fit's α = 250 a different function), the formula is
evaluated as written for every g and α.

Sampling: the CDF in μ is F = (F_HG + α·M2)/(1 + α(1 + 2g²)/3), with r = √(1 + g² − 2gμ), R = 1 + g, a = 1 + g²,
F_HG = (1 − g)(1 + μ)/(r(R + r)) and the partial second moment of HG
M2 = (1 − g²)(1 + μ)/(R + r)·[(a(μ − 1) + 2gμ)²/((a + rR)² rR) + (1 + μ)²/(3(R + r)²)]
(every term without cancellation as g → 0; docs/physics.md "Phase functions" derives it), inverted by
safeguarded Newton iteration to 10⁻¹³ (engine.media.phase.invert_cdf) from the HG sample of the same u.
"""

from __future__ import annotations

import numpy as np

from .henyey_greenstein import G_PARAMETER, clamp_g, hg_sample_mu
from .phase import FOUR_PI, PhaseFunction, PhaseMatrix, invert_cdf, sample_one_plus_beta_mu2
from ..materials.parameters import ModelDeclaration, Parameter


def draine_density(mu, g, alpha):
    """p_D (1/sr) at μ for |g| < 1, α ≥ 0."""
    mu = np.asarray(mu, dtype=np.float64)
    s = 1.0 + g * g - 2.0 * g * mu
    norm = (1.0 + alpha * (1.0 + 2.0 * g * g) / 3.0) * FOUR_PI
    return (1.0 - g * g) * (1.0 + alpha * mu * mu) / (norm * s * np.sqrt(s))


def draine_cdf(mu, g, alpha):
    """P(cos Θ ≤ μ) of Draine's phase function (see the module docstring)."""
    mu = np.asarray(mu, dtype=np.float64)
    a, R = 1.0 + g * g, 1.0 + g
    r = np.sqrt(a - 2.0 * g * mu)
    f_hg = (1.0 - g) * (1.0 + mu) / (r * (R + r))
    m2 = (1.0 - g * g) * (1.0 + mu) / (R + r) * ((a * (mu - 1.0) + 2.0 * g * mu) ** 2 / ((a + r * R) ** 2 * r * R)
                                                 + (1.0 + mu) ** 2 / (3.0 * (R + r) ** 2))
    return (f_hg + alpha * m2) / (1.0 + alpha * (1.0 + 2.0 * g * g) / 3.0)


def draine_sample_mu(u, g, alpha):
    """μ distributed as p_D from u ∈ [0, 1) (scalar g, α)."""
    u = np.asarray(u, dtype=np.float64)
    if g == 0.0:
        return sample_one_plus_beta_mu2(u, alpha)
    return invert_cdf(lambda x, i: draine_cdf(x, g, alpha), lambda x, i: 2.0 * np.pi * draine_density(x, g, alpha),
                      u, hg_sample_mu(u, g))


class Draine(PhaseFunction):
    name = "draine"

    def __init__(self, g: float = 0.0, alpha: float = 1.0):
        self.anisotropy, self.alpha = float(g), float(alpha)
        self.g = clamp_g(g)

    def elements(self, mu, lam) -> PhaseMatrix:
        return PhaseMatrix.depolarising(self.pdf_mu(mu, lam))

    def pdf_mu(self, mu, lam) -> np.ndarray:
        mu, _ = np.broadcast_arrays(np.asarray(mu, dtype=np.float64), np.asarray(lam, dtype=np.float64))
        return draine_density(mu, self.g, self.alpha)

    def sample_mu(self, u, lam):
        return draine_sample_mu(u, self.g, self.alpha)

    def describe(self) -> dict:
        return {"type": self.name, "g": self.anisotropy, "alpha": self.alpha}


DECLARATION = ModelDeclaration(
    "draine", "Draine", "Draine's phase function (HG generalised by α), depolarising, as Cycles' Volume Scatter Draine",
    [G_PARAMETER, Parameter("alpha", "α: weight of the (1 + αμ²) factor (0 = Henyey–Greenstein, 1 = Cornette–Shanks)",
                            lo=0.0, hi=1000.0, default=1.0)],
    catalogue="draine")


@DECLARATION.builder
def _draine(p):
    return Draine(p["g"], p["alpha"])
