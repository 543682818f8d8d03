"""Per-vertex surface attributes (UV coordinates, colour attributes) and their values at ray hits.

:class:`VertexAttributes` holds the attributes of all meshes of a compiled scene (merged vertex
numbering); :class:`SurfacePoints` is a batch of hits (triangle, barycentrics) that interpolates
them on demand, once per batch (``memo``), so a material that reads a texture in ``eval``,
``pdf`` and ``sample`` of the same vertex pays for one lookup.
"""

from __future__ import annotations

import numpy as np

from ..kernels.geometry import interpolate_vertex_attribute


class VertexAttributes:
    """``faces`` (F, 3) into merged vertices; ``uv`` (V, 2) or None; ``layers``: name → (V, C) colours."""

    def __init__(self, faces: np.ndarray, uv: np.ndarray | None, layers: dict[str, np.ndarray]):
        self.faces, self.uv, self.layers = faces, uv, dict(layers)


class SurfacePoints:
    """N hits on triangles ``prim`` with Embree barycentrics (u, v) (vertex weights 1 − u − v, u, v)."""

    __slots__ = ("attributes", "prim", "b1", "b2", "_memo")

    def __init__(self, attributes: VertexAttributes, prim: np.ndarray, b1: np.ndarray, b2: np.ndarray):
        self.attributes, self.prim, self.b1, self.b2 = attributes, prim, b1, b2
        self._memo = {}

    @property
    def n(self) -> int:
        return self.prim.shape[0]

    def take(self, sel) -> SurfacePoints:
        """The points ``sel`` (indices; ``slice(None)`` gives this batch itself, memo included)."""
        if isinstance(sel, slice) and sel == slice(None):
            return self
        return SurfacePoints(self.attributes, self.prim[sel], self.b1[sel], self.b2[sel])

    def memo(self, key, compute):
        """compute() once per batch and key (keys: textures, parameters)."""
        value = self._memo.get(key)
        if value is None:
            value = self._memo[key] = compute()
        return value

    def _interpolate(self, values: np.ndarray) -> np.ndarray:
        return interpolate_vertex_attribute(self.attributes.faces, values, self.prim, self.b1, self.b2)

    def uv(self) -> np.ndarray:
        """Texture coordinates (2, N) (0 on meshes without UVs)."""
        if self.attributes.uv is None:
            return np.zeros((2, self.n))
        return self.memo("uv", lambda: self._interpolate(self.attributes.uv))

    def attribute(self, name: str, channels: int) -> np.ndarray:
        """Colour attribute ``name`` (channels, N), 0 where the scene has no such attribute."""
        layer = self.attributes.layers.get(name)
        if layer is None:
            return np.zeros((channels, self.n))
        value = self.memo(("attribute", name), lambda: self._interpolate(layer))
        if value.shape[0] >= channels:
            return value[:channels]
        return np.concatenate((value, np.zeros((channels - value.shape[0], self.n))))
