"""Lorenz–Mie phase matrix of homogeneous spheres of one radius, tabulated per wavelength.

Amplitudes S1, S2 from the series (engine.media.mie_series) give, in the scattering-plane frames of
engine.media.phase (x = s ⟂ the scattering plane, so S1 is the s amplitude and S2 the p amplitude, as
r_s and r_p of the Fresnel matrix), the ABCS form of docs/physics.md §0:

    A = (|S1|² + |S2|²)/2,  B = (|S1|² − |S2|²)/2,  C = Re(S1 S2*),  S = −Im(S1 S2*)

i.e. Bohren & Huffman's (S11, −S12, S33, S34): their S12 changes sign because their Q is I_∥ − I_⊥.
Each table holds these on nodes uniform in Θ (max(721, 48x + 1) of them, x the size parameter: ≥ 48
per forward-lobe width π/x; at most 48 001) at one wavelength of ``WAVELENGTHS`` (360–830 nm, 5 nm),
normalised to ∫ A dΩ = 1 and interpolated linearly in μ (engine.media.tabulated); between two table
wavelengths the elements are interpolated linearly in λ, and sampling picks the lower or upper table
with the interpolation weight, then inverts its CDF: exact for the interpolated a1.  Tables are built
on first use, per wavelength.  Spheres with κ > 0 or size parameter ≳ 1 retard (S ≠ 0): full Stokes.
"""

from __future__ import annotations

import math

import numpy as np

from .mie_series import amplitudes, mie_coefficients
from .phase import PhaseFunction, PhaseMatrix
from .tabulated import TabulatedSphereMatrix
from ..errors import SceneError
from ..materials.flags import BSDFFlags
from ..materials.parameters import ModelDeclaration, Parameter

#: Wavelengths of the tables (nm).
WAVELENGTHS = np.arange(360.0, 830.0 + 1e-9, 5.0)
#: Nodes per forward-lobe width π/x, and the least and largest node counts over [0, π].
NODES_PER_LOBE, MIN_NODES, MAX_NODES = 48, 721, 48001


def sphere_table(m: complex, x: float) -> TabulatedSphereMatrix:
    """The normalised ABCS table of one sphere (relative index m, size parameter x)."""
    coef = mie_coefficients(m, x)
    count = int(min(MAX_NODES, max(MIN_NODES, math.ceil(NODES_PER_LOBE * x) + 1)))
    theta = np.linspace(np.pi, 0.0, count)
    mu = np.cos(theta)
    mu[0], mu[-1] = -1.0, 1.0
    s1, s2 = amplitudes(coef, mu)
    p1, p2 = np.abs(s1) ** 2, np.abs(s2) ** 2
    cross = s1 * np.conj(s2)
    return TabulatedSphereMatrix(mu, 0.5 * (p1 + p2), 0.5 * (p1 - p2), cross.real, -cross.imag)


class Mie(PhaseFunction):
    name = "mie"
    flags = BSDFFlags.POLARISING | BSDFFlags.RETARDING | BSDFFlags.WAVELENGTH_DEPENDENT

    def __init__(self, radius: float, n, k, medium_n: float = 1.0):
        """``radius`` µm; ``n``, ``k`` the particles' index (engine.spectral spectra, κ ≥ 0); ``medium_n``
        the surrounding medium's real index."""
        self.radius, self.n, self.k, self.medium_n = float(radius), n, k, float(medium_n)
        m = (np.asarray(n.eval(WAVELENGTHS), np.float64) + 1j * np.asarray(k.eval(WAVELENGTHS), np.float64)) / medium_n
        if np.any(m == 1.0):
            raise SceneError("mie.n", f"equals the medium's index {medium_n:g} with k = 0 at "
                                      f"{WAVELENGTHS[np.argmax(m == 1.0)]:g} nm: such particles do not scatter")
        self.m = m
        self.x = 2.0 * np.pi * self.radius * 1000.0 * self.medium_n / WAVELENGTHS
        self._tables: dict[int, TabulatedSphereMatrix] = {}

    def table(self, j: int) -> TabulatedSphereMatrix:
        """The table at WAVELENGTHS[j] (built on first use)."""
        t = self._tables.get(j)
        if t is None:
            t = self._tables[j] = sphere_table(complex(self.m[j]), float(self.x[j]))
        return t

    @staticmethod
    def _bracket(lam: np.ndarray):
        """(lower table index, weight of the upper one) for wavelengths ``lam`` (clamped to the tables)."""
        t = (np.clip(lam, WAVELENGTHS[0], WAVELENGTHS[-1]) - WAVELENGTHS[0]) / (WAVELENGTHS[1] - WAVELENGTHS[0])
        j = np.minimum(np.floor(t).astype(np.int64), WAVELENGTHS.size - 2)
        return j, t - j

    def elements(self, mu, lam) -> PhaseMatrix:
        mu, lam = np.broadcast_arrays(np.asarray(mu, dtype=np.float64), np.asarray(lam, dtype=np.float64))
        j, w = self._bracket(lam)
        out = [np.zeros(mu.shape) for _ in range(4)]
        for lo in np.unique(j):
            at = j == lo
            for node, weight in ((lo, 1.0 - w[at]), (lo + 1, w[at])):
                if np.any(weight > 0):
                    for acc, v in zip(out, self.table(int(node)).elements(mu[at])):
                        acc[at] += weight * v
        return PhaseMatrix.abcs(*out)

    def sample_mu(self, u, lam):
        """The lower table with probability 1 − w (u rescaled onto [0, 1)), else the upper one."""
        u = np.asarray(u, dtype=np.float64)
        j, w = self._bracket(np.broadcast_to(np.asarray(lam, dtype=np.float64), u.shape))
        upper = u >= 1.0 - w
        node = j + upper
        v = np.where(upper, (u - (1.0 - w)) / np.where(w > 0, w, 1.0), u / np.where(w < 1, 1.0 - w, 1.0))
        v = np.clip(v, 0.0, np.nextafter(1.0, 0.0))
        out = np.empty_like(u)
        for t in np.unique(node):
            at = node == t
            out[at] = self.table(int(t)).sample_mu(v[at])
        return out

    def describe(self) -> dict:
        return {"type": self.name, "radius": self.radius, "n": repr(self.n), "k": repr(self.k),
                "medium_n": self.medium_n}


DECLARATION = ModelDeclaration(
    "mie", "Lorenz–Mie", "Exact Lorenz–Mie scattering by homogeneous spheres of one radius (full Stokes: "
    "polarising and retarding), tabulated per wavelength",
    [Parameter("radius", "sphere radius", unit="µm", lo=0.0001, hi=50.0, default=1.0),
     Parameter("n", "refractive index of the spheres (real part)", kind="spectrum", lo=0.0, lo_open=True,
               default=1.33),
     Parameter("k", "extinction coefficient κ of the spheres (index n + iκ)", kind="spectrum", lo=0.0, default=0.0),
     Parameter("medium_n", "refractive index of the medium around the spheres", lo=0.0, lo_open=True, default=1.0)],
    catalogue="mie")


@DECLARATION.builder
def _mie(p):
    return Mie(p["radius"], p["n"], p["k"], p["medium_n"])
