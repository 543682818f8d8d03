"""Black glass: the smooth interface of an infinitely absorbing dielectric.

Only the Fresnel reflection of a real index n exists (the thesis's floor);
transmitted light is absorbed.  Its Mueller matrix is the conductor's with
κ = 0: a pure diattenuator (no retardance) that fully s-polarises at
Brewster's angle.  One-sided.
"""

from __future__ import annotations

from .conductor import SmoothConductor
from .dielectric import IOR_SOCKET
from .parameters import ModelDeclaration, Parameter, exterior_n_parameter
from ..spectral import ConstantSpectrum


class BlackGlass(SmoothConductor):
    name = "black_glass"

    def __init__(self, n, exterior_n=1.0):
        # Retards only where n < exterior_n (total internal reflection): decided by SmoothConductor.
        super().__init__(n, ConstantSpectrum(0.0), exterior_n)

    def describe(self):
        return {"type": self.name, "n": repr(self.n), "exterior_n": self.exterior_n}


# --------------------------------------------------------------------------- declaration

DECLARATION = ModelDeclaration(
    "black_glass", "Black Glass",
    "Smooth dielectric surface whose transmitted light is absorbed (polarises strongly near Brewster's angle)",
    [Parameter("n", "real index of the glass", kind="spectrum", lo=0.0, lo_open=True, default=1.5,
               socket=IOR_SOCKET),
     Parameter("k", "imaginary part of the index: black glass has a real index, so only 0", lo=0.0, hi=0.0,
               default=0.0),
     exterior_n_parameter()], node="BLACK_GLASS")


@DECLARATION.builder
def _black_glass(p):
    p.get("k")   # validated only: the model has no κ
    return BlackGlass(p["n"], p["exterior_n"])
