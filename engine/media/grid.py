"""A dense density grid: values on the nodes of a regular lattice spanning an axis-aligned box, trilinear
between them and 0 outside the box.

``values`` (nx, ny, nz) ≥ 0, node (i, j, k) at lo + (i, j, k)·(hi − lo)/(n − 1) in world units (every
axis ≥ 2 nodes; the box's corners are nodes).  A medium's coefficients are σ(λ)·ρ(x) with ρ this grid's
trilinear value (engine.scene.description.Interior); free-flight sampling bounds ρ by ``majorant``
(default the largest node value: trilinear interpolation never exceeds it).  File-backed grids (OpenVDB)
are read by the Blender extension (polar_addon.export.volumes) into this dense form.
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError


def node_values(values, field: str, layout: str) -> np.ndarray:
    """``values`` as a float64 array; else a SceneError naming ``field``.values (nested lists in ``layout``)."""
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(f"{field}.values", f"must be a nested list {layout} of numbers ≥ 0") from None


class DensityGrid:
    """Trilinear density ρ(x) on a dense lattice over the box [lo, hi] (see the module docstring)."""

    def __init__(self, values, lo, hi, field: str = "grid"):
        v = node_values(values, field, "[x][y][z]")
        if v.ndim != 3 or min(v.shape) < 2:
            raise SceneError(f"{field}.values", f"must be a 3-D array [x][y][z] with ≥ 2 nodes per axis, got shape "
                                                f"{list(v.shape)}")
        if not np.all(np.isfinite(v)) or np.any(v < 0):
            raise SceneError(f"{field}.values", "must be finite numbers ≥ 0 (densities)")
        lo, hi = np.asarray(lo, np.float64).reshape(-1), np.asarray(hi, np.float64).reshape(-1)
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)) \
                or np.any(hi <= lo):
            raise SceneError(f"{field}.bounds", f"must be [[x0, y0, z0], [x1, y1, z1]] finite with x0 < x1, y0 < y1, "
                                                f"z0 < z1, got {lo.tolist()}, {hi.tolist()}")
        self.values, self.lo, self.hi = v, lo, hi
        self.max = float(v.max())
        self._scale = (np.array(v.shape, np.float64) - 1.0) / (hi - lo)

    def density(self, p: np.ndarray) -> np.ndarray:
        """ρ (n,) at the points p (3, n): trilinear between the nodes, 0 outside the box."""
        g = (p - self.lo[:, None]) * self._scale[:, None]
        shape = np.array(self.values.shape)[:, None]
        inside = np.all((g >= 0) & (g <= shape - 1), axis=0)
        g = np.clip(g, 0.0, shape - 1)
        i0 = np.minimum(np.floor(g).astype(np.int64), shape - 2)
        f = g - i0
        out = np.zeros(p.shape[1])
        V = self.values
        for dx in (0, 1):
            wx = f[0] if dx else 1.0 - f[0]
            for dy in (0, 1):
                wy = f[1] if dy else 1.0 - f[1]
                for dz in (0, 1):
                    wz = f[2] if dz else 1.0 - f[2]
                    out += wx * wy * wz * V[i0[0] + dx, i0[1] + dy, i0[2] + dz]
        return np.where(inside, out, 0.0)

    def box_range(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(t0, t1) (n,): where the rays o + t·d (3, n) are inside the box (t0 > t1: never)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d
            a = (self.lo[:, None] - o) * inv
            b = (self.hi[:, None] - o) * inv
        lo_t = np.where(np.isnan(a), -np.inf, np.minimum(a, b))
        hi_t = np.where(np.isnan(b), np.inf, np.maximum(a, b))
        return lo_t.max(axis=0), hi_t.min(axis=0)

    def describe(self) -> dict:
        return {"shape": list(self.values.shape), "bounds": [self.lo.tolist(), self.hi.tolist()], "max": self.max}
