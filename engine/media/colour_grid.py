"""A dense RGB grid: three channels on the nodes of one regular lattice over an axis-aligned box, trilinear
between them and 0 outside the box (engine.media.grid.DensityGrid per channel).

``values`` (3, nx, ny, nz) ≥ 0 (linear sRGB), node (i, j, k) at lo + (i, j, k)·(hi − lo)/(n − 1) in world
units.  A medium's per-point emission (Interior.emission_grid: linear sRGB radiance per unit length, upsampled
as an illuminant, D65n(λ)·Σ_c g_c(x)·B_c(λ): engine.spectral) and its per-point colour (Interior.colour_grid:
upsampled as a reflectance, Σ_c g_c(x)·B_c(λ), scaling σ_s and σ_a) read it; ``max`` (3,) is each channel's largest
node value, which trilinear interpolation never exceeds.  File-backed grids (OpenVDB colour or temperature
grids) are read by the Blender extension (polar_addon.export.volumes) into this dense form.
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from .grid import DensityGrid, node_values


class ColourGrid:
    """Trilinear linear-sRGB values g(x) (3,) on a dense lattice over the box [lo, hi] (see the module docstring)."""

    def __init__(self, values, lo, hi, field: str = "grid"):
        v = node_values(values, field, "[r, g, b][x][y][z]")
        if v.ndim != 4 or v.shape[0] != 3:
            raise SceneError(f"{field}.values", f"must be a 4-D array [channel r, g, b][x][y][z], got shape "
                                                f"{list(v.shape)}")
        self.channels = [DensityGrid(v[c], lo, hi, field=field) for c in range(3)]
        self.lo, self.hi = self.channels[0].lo, self.channels[0].hi
        self.max = np.array([g.max for g in self.channels])

    def rgb(self, p: np.ndarray) -> np.ndarray:
        """g (3, n) at the points p (3, n): trilinear between the nodes, 0 outside the box."""
        return np.stack([g.density(p) for g in self.channels])

    def box_range(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(t0, t1) (n,): where the rays o + t·d (3, n) are inside the box (t0 > t1: never)."""
        return self.channels[0].box_range(o, d)

    def describe(self) -> dict:
        return {"shape": list(self.channels[0].values.shape), "bounds": [self.lo.tolist(), self.hi.tolist()],
                "max": self.max.tolist()}
