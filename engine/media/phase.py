"""The interface every phase function implements, and the sampling helpers they share.

Directions as for surfaces (docs/physics.md §0, engine.materials.base): at a medium vertex ``wo``
points towards the viewer (the previous vertex), ``wi`` towards the light; the light travels along
k_i = −wi into the vertex and leaves along k_o = wo.  The scattering angle Θ has
μ = cos Θ = k_i·k_o = −wi·wo (μ = 1: straight on).  A phase matrix maps Stokes vectors in the frame
x_in = s on k_i to the frame x_out = s on k_o, with the **scattering-plane axis**
s = unit(k_i × k_o) on both beams and y = k × s on each (physics.md "Phase functions"; any s ⟂ k_i
where k_o ∥ k_i: every phase matrix is invariant there).  It is given per steradian and normalised,
∫ a1 dΩ = 1 (a1 = M00), so a medium vertex's value is σ_s·M.

Batches: ``mu`` (n,) or any shape broadcastable against the wavelengths ``lam`` (L, n) nm; directions
(3, n).  Sampling is exact for a1 at the path's **first (hero) wavelength** ``lam[0]``: ``sample``
returns wi with pdf = a1(μ; lam[0]) and the Mueller weight M(λ)/pdf for every wavelength (1 in M00
at the hero wavelength; equal to M/M00 at every λ for phase functions that do not depend on λ).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..materials.base import MuellerValue
from ..materials.flags import BSDFFlags
from ..materials.sampling import local_to_world
from ..polarisation.frames import scattering_plane_axis
from ..vec3 import dot

__all__ = ["PhaseFunction", "PhaseMatrix", "PhaseSample", "direction_about", "invert_cdf", "sample_one_plus_beta_mu2"]

FOUR_PI = 4.0 * np.pi


@dataclass
class PhaseMatrix:
    """The six elements of a phase matrix of a macroscopically isotropic, mirror-symmetric medium
    (van de Hulst; Hansen & Travis 1974 eq. 2.13) in the scattering-plane frames:

        [[a1, b1, 0, 0], [b1, a2, 0, 0], [0, 0, a3, b2], [0, 0, −b2, a4]]    (1/sr)

    ``kind`` "depolarising" (only a1), "abcs" (a2 = a1, a4 = a3: spheres; engine.materials.base's
    ABCS form with A, B, C, S = a1, b1, a3, b2) or "general".  Arrays of one shape (or scalars)."""

    kind: str
    a1: np.ndarray
    b1: np.ndarray | float = 0.0
    a2: np.ndarray | float = 0.0
    a3: np.ndarray | float = 0.0
    b2: np.ndarray | float = 0.0
    a4: np.ndarray | float = 0.0

    @classmethod
    def depolarising(cls, p) -> PhaseMatrix:
        return cls("depolarising", p)

    @classmethod
    def abcs(cls, A, B, C, S) -> PhaseMatrix:
        return cls("abcs", A, B, A, C, S, C)

    def matrix(self) -> np.ndarray:
        """The full matrices (..., 4, 4)."""
        a1 = np.asarray(self.a1, dtype=np.float64)
        shape = np.broadcast_shapes(*(np.shape(v) for v in (a1, self.b1, self.a2, self.a3, self.b2, self.a4)))
        M = np.zeros(shape + (4, 4))
        M[..., 0, 0] = a1
        if self.kind != "depolarising":
            M[..., 0, 1] = M[..., 1, 0] = self.b1
            M[..., 1, 1] = self.a2
            M[..., 2, 2] = self.a3
            M[..., 3, 3] = self.a4
            M[..., 2, 3] = self.b2
            M[..., 3, 2] = 0.0 - np.asarray(self.b2)
        return M

    def value(self, x: np.ndarray) -> MuellerValue:
        """As the integrator's MuellerValue (arrays (L, n)) with x_in = x_out = ``x`` (3, n)."""
        if self.kind == "depolarising":
            return MuellerValue("depolarising", x, x, A=np.asarray(self.a1, dtype=np.float64))
        shape = np.shape(self.a1)
        full = [np.broadcast_to(np.asarray(v, dtype=np.float64), shape) for v in (self.a1, self.b1, self.a3, self.b2)]
        if self.kind == "abcs":
            return MuellerValue("abcs", x, x, *full)
        return MuellerValue("general", x, x, M=np.moveaxis(self.matrix(), (-2, -1), (0, 1)))

    def scaled(self, f) -> PhaseMatrix:
        """Every element times ``f`` (broadcastable)."""
        return PhaseMatrix(self.kind, *(np.multiply(v, f) for v in (self.a1, self.b1, self.a2, self.a3, self.b2,
                                                                    self.a4)))


@dataclass
class PhaseSample:
    """Result of ``PhaseFunction.sample`` for n vertices."""

    wi: np.ndarray              # (3, n) unit direction towards the light
    weight: MuellerValue        # M(λ)/pdf in the frames x_in = x_out = s, arrays (L, n)
    pdf: np.ndarray             # (n,) solid-angle pdf of wi (1/sr), a1 at the hero wavelength
    mu: np.ndarray              # (n,) cos Θ of the sample
    valid: np.ndarray           # (n,) bool (False only where pdf = 0 and not is_delta)
    is_delta: np.ndarray        # (n,) bool: straight on from a Dirac part (weight a depolariser 1, pdf 0)


class PhaseFunction:
    """A phase function with its Mueller matrix (see the module docstring).

    Subclasses implement ``elements(mu, lam) -> PhaseMatrix`` (1/sr, arrays of the broadcast shape of
    mu and lam) and ``sample_mu(u, lam) -> mu`` (u (n,) uniform, lam (n,) the sampling wavelength),
    exact for ``pdf_mu``; they set ``flags`` (engine.materials.flags.BSDFFlags: only the capabilities
    POLARISING, RETARDING, WAVELENGTH_DEPENDENT are meaningful here) and ``name``.
    """

    name = "phase"
    flags = BSDFFlags.NONE
    #: a depolarising phase function whose share at cos Θ = 1 (in double precision) is a Dirac part
    forward_dirac = False

    def elements(self, mu, lam) -> PhaseMatrix:
        raise NotImplementedError

    def sample_mu(self, u: np.ndarray, lam: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def pdf_mu(self, mu, lam) -> np.ndarray:
        """a1 (1/sr) at cos Θ = ``mu`` and the wavelengths ``lam`` (broadcast shape): the density of
        ``sample`` per steradian where lam is the sampling wavelength."""
        return np.asarray(self.elements(mu, lam).a1, dtype=np.float64)

    # ------------------------------------------------------------------ shared by every phase function

    def matrix(self, mu, lam=550.0) -> np.ndarray:
        """The phase matrices (..., 4, 4) (1/sr) at cos Θ = ``mu`` and wavelengths ``lam`` nm (broadcast
        shape ...), in the scattering-plane frames."""
        mu, lam = np.broadcast_arrays(np.asarray(mu, dtype=np.float64), np.asarray(lam, dtype=np.float64))
        return self.elements(mu, lam).matrix()

    def eval(self, wo: np.ndarray, wi: np.ndarray, lam: np.ndarray) -> MuellerValue:
        """M(Θ) for light arriving along −wi and leaving along wo (3, n), per wavelength of lam (L, n)."""
        mu = np.clip(-dot(wi, wo), -1.0, 1.0)
        return self.elements(np.broadcast_to(mu, lam.shape), lam).value(scattering_plane_axis(-wi, wo))

    def pdf(self, wo: np.ndarray, wi: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """Solid-angle pdf (n,) with which ``sample`` picks wi (at the hero wavelength lam[0])."""
        return self.pdf_mu(np.clip(-dot(wi, wo), -1.0, 1.0), lam[0])

    def sample(self, wo: np.ndarray, u: np.ndarray, lam: np.ndarray) -> PhaseSample:
        """wi ∝ a1 at the hero wavelength lam[0] from u (2, n): u[0] picks cos Θ, u[1] the azimuth."""
        mu = np.clip(self.sample_mu(u[0], lam[0]), -1.0, 1.0)
        wi = direction_about(-wo, mu, u[1])
        pdf = self.pdf_mu(mu, lam[0])
        valid = pdf > 0
        value = self.elements(np.broadcast_to(mu, lam.shape), lam).scaled(
            np.where(valid, 1.0 / np.where(valid, pdf, 1.0), 0.0))
        delta = (mu == 1.0) & self.forward_dirac
        if delta.any():
            value = PhaseMatrix.depolarising(np.where(delta, 1.0, value.a1))
            valid = valid | delta
        return PhaseSample(wi, value.value(scattering_plane_axis(-wi, wo)), pdf, mu, valid, delta)


# --------------------------------------------------------------------------- sampling helpers


def direction_about(d: np.ndarray, mu: np.ndarray, u_phi: np.ndarray) -> np.ndarray:
    """Unit directions (3, n) at cos = ``mu`` from the unit directions ``d`` (3, n), azimuth 2π·u_phi
    in engine.vec3.local_frame(d) (Cycles' phase_sample_direction)."""
    s = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    phi = 2.0 * np.pi * u_phi
    return local_to_world(np.stack((s * np.cos(phi), s * np.sin(phi), mu)), d)


def sample_one_plus_beta_mu2(u: np.ndarray, beta) -> np.ndarray:
    """μ ∈ [−1, 1] with density ∝ 1 + β μ² (β ≥ 0) from u ∈ [0, 1): the real root of the CDF's cubic
    β μ³/3 + μ + c = 0, c = (1 + β/3)(1 − 2u), in the hyperbolic form (no cancellation for any β,
    the linear limit μ = 2u − 1 at β = 0)."""
    beta = np.asarray(beta, dtype=np.float64)
    c = (1.0 + beta / 3.0) * (1.0 - 2.0 * u)
    safe = np.where(beta > 0, beta, 1.0)
    p = 3.0 / safe                                   # μ³ + p μ + p c = 0
    arg = 1.5 * c * np.sqrt(3.0 / p)                 # (3 q / 2p) √(3/p) with q = p c
    mu = -2.0 * np.sqrt(p / 3.0) * np.sinh(np.arcsinh(arg) / 3.0)
    return np.clip(np.where(beta > 0, mu, -c), -1.0, 1.0)


def invert_cdf(cdf, density, u: np.ndarray, x0: np.ndarray, lo: float = -1.0, hi: float = 1.0,
               tol: float = 1e-13, max_iter: int = 200) -> np.ndarray:
    """x ∈ [lo, hi] with cdf(x) = u for a continuous increasing ``cdf`` with derivative ``density``
    (both vectorised over arrays shaped like u): Newton's method from ``x0`` kept inside a bisection
    bracket (a step leaving the bracket is a bisection), until the bracket or step is below ``tol`` times
    the distance to the nearer end of [lo, hi] (or one ulp)."""
    a = np.full(u.shape, lo, dtype=np.float64)
    b = np.full(u.shape, hi, dtype=np.float64)
    x = np.clip(np.asarray(x0, dtype=np.float64), lo, hi)
    active = np.ones(u.shape, bool)
    for _ in range(max_iter):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        xi, ui = x[idx], u[idx]
        f = cdf(xi, idx) - ui
        below = f < 0
        a[idx] = np.where(below, xi, a[idx])
        b[idx] = np.where(below, b[idx], xi)
        d = density(xi, idx)
        step = np.where(d > 0, f / np.where(d > 0, d, 1.0), np.inf)
        new = xi - step
        inside = (new > a[idx]) & (new < b[idx])
        new = np.where(inside, new, 0.5 * (a[idx] + b[idx]))
        # the tolerance is relative to the distance from the nearer end: peaks at ±1 are resolved too
        scale = tol * np.maximum(np.minimum(hi - xi, xi - lo), np.spacing(1.0))
        done = (np.abs(new - xi) <= scale) | (b[idx] - a[idx] <= scale) | (f == 0) | (new == xi)
        x[idx] = np.where(f == 0, xi, new)
        active[idx[done]] = False
    return x
