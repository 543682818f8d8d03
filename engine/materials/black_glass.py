"""Black glass: the smooth interface of an infinitely absorbing dielectric.

Only the Fresnel reflection of a real index n exists (the thesis's floor);
transmitted light is absorbed.  Its Mueller matrix is the conductor's with
κ = 0: a pure diattenuator (no retardance) that fully s-polarises at
Brewster's angle.  One-sided.
"""

from __future__ import annotations

from .conductor import SmoothConductor
from ..spectral import ConstantSpectrum


class BlackGlass(SmoothConductor):
    name = "black_glass"

    def __init__(self, n, exterior_n=1.0):
        # Retards only where n < exterior_n (total internal reflection): decided by SmoothConductor.
        super().__init__(n, ConstantSpectrum(0.0), exterior_n)

    def describe(self):
        return {"type": self.name, "n": repr(self.n), "exterior_n": self.exterior_n}
