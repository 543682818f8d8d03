"""A phase matrix of spheres tabulated over cos Θ, with exact sampling of its tabulated a1.

The elements a1 (= a2), b1, a3 (= a4), b2 (engine.media.phase.PhaseMatrix "abcs" form) are given at
nodes μ_0 = −1 < … < μ_K = 1 and interpolated linearly in μ; the table is normalised so that the
interpolant's 2π ∫ a1 dμ = 1 exactly (the trapezoid sum).  Linear interpolation keeps the matrix
realisable: A ≥ √(B² + C² + S²) holds at the nodes and the right-hand side is a norm, hence convex.
Sampling inverts the piecewise-quadratic CDF exactly: the cell by binary search in the cumulative
masses, then x = 2r/(p_k + √(p_k² + 2 s r)) within it (p_k the density at the cell's left node, s its
slope, r the remaining mass; no cancellation for either sign of s).
"""

from __future__ import annotations

import numpy as np


class TabulatedSphereMatrix:
    """Elements (K+1,) each at the ascending nodes ``mu`` (K+1,) from −1 to 1 (normalised here)."""

    def __init__(self, mu: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray, S: np.ndarray):
        mu = np.asarray(mu, dtype=np.float64)
        if mu[0] != -1.0 or mu[-1] != 1.0 or np.any(np.diff(mu) <= 0):
            raise ValueError("nodes must rise strictly from −1 to 1")
        h = np.diff(mu)
        mass = 0.5 * (A[:-1] + A[1:]) * h
        total = 2.0 * np.pi * mass.sum()
        if not total > 0:
            raise ValueError("the tabulated a1 integrates to 0")
        self.mu = mu
        self.A, self.B, self.C, self.S = (np.asarray(v, dtype=np.float64) / total for v in (A, B, C, S))
        self.norm = total                       # 2π ∫ A dμ of the raw table
        self.h = h
        cells = 0.5 * (self.A[:-1] + self.A[1:]) * h
        self.mass = float(cells.sum())         # ∫ A dμ = 1/2π up to rounding
        self.cdf = np.concatenate(([0.0], np.cumsum(cells))) / self.mass

    def elements(self, mu) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C, S) (1/sr) at ``mu`` (any shape), linear in μ between nodes."""
        mu = np.asarray(mu, dtype=np.float64)
        return tuple(np.interp(mu, self.mu, v) for v in (self.A, self.B, self.C, self.S))

    def density(self, mu) -> np.ndarray:
        return np.interp(np.asarray(mu, dtype=np.float64), self.mu, self.A)

    def sample_mu(self, u: np.ndarray) -> np.ndarray:
        """μ with density 2π·A(μ) from u ∈ [0, 1) (exact for the interpolant)."""
        u = np.asarray(u, dtype=np.float64)
        k = np.clip(np.searchsorted(self.cdf, u, side="right") - 1, 0, self.mu.size - 2)
        r = (u - self.cdf[k]) * self.mass
        p0 = self.A[k]
        slope = (self.A[k + 1] - self.A[k]) / self.h[k]
        x = 2.0 * r / (p0 + np.sqrt(np.maximum(p0 * p0 + 2.0 * slope * r, 0.0)))
        return np.clip(self.mu[k] + np.where(np.isfinite(x), np.minimum(x, self.h[k]), 0.0), -1.0, 1.0)
