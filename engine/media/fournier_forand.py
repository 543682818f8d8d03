"""Fournier–Forand phase function (Fournier & Forand 1994; Fournier & Jonasz 1999) as a depolariser:
M = p_FF(μ)·diag(1, 0, 0, 0), Cycles' parameterisation (kernel/closure/volume_util.h).

From the particles' index n and backscatter fraction B = b_b/b: δ(Θ) = 4 sin²(Θ/2)/(3(n − 1)²),
δ90 = δ(90°), δ180 = δ(180°), v = −ln(2B(δ90 − 1) + 1)/ln δ90, and

    p_FF = [v(1 − δ) − (1 − δ^v) + (δ(1 − δ^v) − v(1 − δ))/sin²(Θ/2)] / (4π (1 − δ)² δ^v)
           + (1 − δ180^v)/(16π (δ180 − 1) δ180^v)·(3μ² − 1)

per steradian (Cycles' first-order expansion where |1 − δ| < 10⁻³), with the closed-form CDF
P(Θ' ≤ Θ) = [1 − δ^{v+1} − (1 − δ^v) sin²(Θ/2)]/((1 − δ) δ^v) + (1 − δ180^v)/(8 (δ180 − 1) δ180^v)·μ(1 − μ²).
As Cycles, B is clamped to ≤ 0.5 − 10⁻³ and n to ≥ 1 + 10⁻³.  Sampling inverts the CDF by safeguarded
Newton iteration to 10⁻¹³ (engine.media.phase.invert_cdf; Cycles takes ≤ 20 float Newton steps).

p_FF diverges as Θ → 0, integrably but so strongly that at small B a sizeable share of the light is
scattered by less than THETA_MIN = arccos(1 − 2⁻⁵³) ≈ 1.5·10⁻⁸ rad, where cos Θ rounds to 1
(``forward_mass``: 3.4 % at B = 0.0183, n = 1.33 — Petzold's ocean average; 10⁻⁶ at B = 0.1).  That share
is returned as straight-on scattering, a Dirac part (PhaseSample.is_delta, weight 1, pdf 0), which is
what it is to any renderer; p_FF at μ = 1 is reported as 0, as Cycles does (which loses that light).
"""

from __future__ import annotations

import math

import numpy as np

from .phase import FOUR_PI, PhaseFunction, PhaseMatrix, invert_cdf
from ..materials.parameters import ModelDeclaration, Parameter

#: The least angle whose cosine a double tells from 1 (rad): below it, scattering is straight on.
THETA_MIN = math.acos(np.nextafter(1.0, 0.0))


class FournierForand(PhaseFunction):
    name = "fournier_forand"
    forward_dirac = True

    def __init__(self, backscatter: float = 0.1, ior: float = 1.33):
        self.backscatter, self.ior = float(backscatter), float(ior)
        B = min(abs(self.backscatter), 0.5 - 1e-3)
        n = max(self.ior, 1.0 + 1e-3)
        d90, d180 = self._delta(n, 0.5), self._delta(n, 1.0)
        self.n = n
        self.v = -math.log(2.0 * B * (d90 - 1.0) + 1.0) / math.log(d90)
        self.c3 = (d180 ** -self.v - 1.0) / (d180 - 1.0)
        self.forward_mass = float(self._cdf_theta(np.array(math.sin(0.5 * THETA_MIN) ** 2)))

    @staticmethod
    def _delta(n, sin_half_sq):
        return 4.0 * sin_half_sq / (3.0 * (n - 1.0) ** 2)

    def _terms(self, mu):
        h = 0.5 * (1.0 - mu)                                    # sin²(Θ/2)
        d = self._delta(self.n, h)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdv = np.power(d, self.v)
        return h, d, pdv, 1.0 - d, 1.0 - pdv

    def pdf_mu(self, mu, lam) -> np.ndarray:
        mu, _ = np.broadcast_arrays(np.asarray(mu, dtype=np.float64), np.asarray(lam, dtype=np.float64))
        inside = np.abs(mu) < 1.0
        m = np.where(inside, mu, 0.0)
        h, d, pdv, md, mpdv = self._terms(m)
        v = self.v
        near = np.abs(md) < 1e-3
        safe = np.where(near, 1.0, md)
        exact = (v * md - mpdv + (d * mpdv - v * md) / h) / (FOUR_PI * safe * safe * pdv)
        taylor = (v * ((v - 1.0) - (v + 1.0) / h) / (8.0 * np.pi)
                  + v * (v + 1.0) * md * (2.0 * (v - 1.0) - (2.0 * v + 1.0) / h) / (24.0 * np.pi))
        pf = np.where(near, taylor, exact) + self.c3 / (16.0 * np.pi) * (3.0 * m * m - 1.0)
        return np.where(inside, pf, 0.0)

    def _cdf_theta(self, h) -> np.ndarray:
        """P(Θ' ≤ Θ) from h = sin²(Θ/2) (Cycles' CDF; exact also where cos Θ rounds to 1)."""
        d = self._delta(self.n, h)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdv = np.power(d, self.v)
            md, mpdv = 1.0 - d, 1.0 - pdv
            near = np.abs(md) < 1e-3
            exact = (1.0 - pdv * d - mpdv * h) / (np.where(near, 1.0, md) * pdv)
        v, mu = self.v, 1.0 - 2.0 * h
        taylor = 1.0 + v * (1.0 - h) * (1.0 - 0.5 * (v + 1.0) * md)
        F = np.where(near, taylor, exact) + self.c3 / 8.0 * mu * (1.0 - mu * mu)
        return np.where(h > 0, F, 0.0)

    def cdf_mu(self, mu) -> np.ndarray:
        """P(cos Θ ≤ μ) (the complement of Cycles' P(Θ' ≤ Θ)); 1 at μ = 1, the Dirac part included."""
        mu = np.asarray(mu, dtype=np.float64)
        return 1.0 - self._cdf_theta(0.5 * (1.0 - mu))

    def elements(self, mu, lam) -> PhaseMatrix:
        return PhaseMatrix.depolarising(self.pdf_mu(mu, lam))

    def sample_mu(self, u, lam):
        """The CDF inverted; u in the top ``forward_mass`` gives μ = 1 exactly (the Dirac part)."""
        u = np.asarray(u, dtype=np.float64)
        mu = invert_cdf(lambda x, i: self.cdf_mu(x), lambda x, i: 2.0 * np.pi * self.pdf_mu(x, 0.0), u,
                        2.0 * u - 1.0)
        return np.where(u >= 1.0 - self.forward_mass, 1.0, np.minimum(mu, np.nextafter(1.0, 0.0)))

    def describe(self) -> dict:
        return {"type": self.name, "backscatter": self.backscatter, "ior": self.ior}


DECLARATION = ModelDeclaration(
    "fournier_forand", "Fournier–Forand", "Fournier–Forand phase function of ocean particles, depolarising, as "
    "Cycles' Volume Scatter Fournier-Forand",
    [Parameter("backscatter", "backscatter fraction B = b_b/b (clamped to ≤ 0.499 as Cycles)", lo=0.0, hi=0.5,
               lo_open=True, default=0.1),
     Parameter("ior", "refractive index of the particles relative to the medium (clamped to ≥ 1.001 as Cycles)",
               lo=1.0, hi=3.0, default=1.33)],
    catalogue="fournier_forand")


@DECLARATION.builder
def _fournier_forand(p):
    return FournierForand(p["backscatter"], p["ior"])
