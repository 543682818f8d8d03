"""Per-vertex surface attributes (UV coordinates, colour attributes) and their values at ray hits.

:class:`VertexAttributes` holds the attributes of all meshes of a compiled scene (merged vertex
numbering); :class:`SurfacePoints` is a batch of hits (triangle, barycentrics) that interpolates
them on demand, once per batch (``memo``), so a material that reads a texture in ``eval``,
``pdf`` and ``sample`` of the same vertex pays for one lookup.
"""

from __future__ import annotations

import numpy as np

from ..kernels.geometry import interpolate_vertex_attribute, tangent_frame


class VertexAttributes:
    """``faces`` (F, 3) into merged vertices; ``uv`` (V, 2) or None; ``layers``: name → (V, C) colours;
    ``vertices`` (V, 3) positions (for dp/du, dp/dv); ``tangents`` (V, 4) (xyz, handedness ±1) or None."""

    def __init__(self, faces: np.ndarray, uv: np.ndarray | None, layers: dict[str, np.ndarray],
                 vertices: np.ndarray | None = None, tangents: np.ndarray | None = None):
        self.faces, self.uv, self.layers = faces, uv, dict(layers)
        self.vertices, self.tangents = vertices, tangents


class SurfacePoints:
    """N hits on triangles ``prim`` with Embree barycentrics (u, v) (vertex weights 1 − u − v, u, v).

    A subset made by :meth:`take` remembers its parent batch and its points there: a value it has not
    memoised yet but the parent (or the parent's parent …) has is the parent's value at those points
    (every memoised value is per point, the points along its last axis), not a second lookup.
    """

    __slots__ = ("attributes", "prim", "b1", "b2", "_memo", "_parent", "_sel")

    def __init__(self, attributes: VertexAttributes, prim: np.ndarray, b1: np.ndarray, b2: np.ndarray):
        self.attributes, self.prim, self.b1, self.b2 = attributes, prim, b1, b2
        self._memo = {}
        self._parent = self._sel = None

    @property
    def n(self) -> int:
        return self.prim.shape[0]

    def take(self, sel) -> SurfacePoints:
        """The points ``sel`` (indices; ``slice(None)`` gives this batch itself, memo included).

        A subset of this batch's points (a boolean mask, a slice, or increasing indices) shares this
        batch's memoised values (``memo``); other selections (repeated or reordered points, e.g. one
        point per wavelength lane, whose lookups may see other wavelengths) start with an empty memo."""
        if isinstance(sel, slice) and sel == slice(None):
            return self
        sub = SurfacePoints(self.attributes, self.prim[sel], self.b1[sel], self.b2[sel])
        if _is_subset(sel):
            sub._parent, sub._sel = self, sel
        return sub

    def memo(self, key, compute):
        """compute() once per batch and key (keys: textures, parameters); a subset (``take``) first
        looks for the key among its parents' values."""
        value = self._memo.get(key)
        if value is None:
            value = self._inherited(key)
            if value is None:
                value = compute()
            self._memo[key] = value
        return value

    def _inherited(self, key):
        """The value of ``key`` at these points from the nearest parent that memoised it, or None."""
        parent = self._parent
        if parent is None:
            return None
        value = parent._memo.get(key)
        if value is None:
            value = parent._inherited(key)
            if value is None:
                return None
        return _points_of(value, self._sel, parent.n)

    def _interpolate(self, values: np.ndarray) -> np.ndarray:
        return interpolate_vertex_attribute(self.attributes.faces, values, self.prim, self.b1, self.b2)

    def uv(self) -> np.ndarray:
        """Texture coordinates (2, N) (0 on meshes without UVs)."""
        if self.attributes.uv is None:
            return np.zeros((2, self.n))
        return self.memo("uv", lambda: self._interpolate(self.attributes.uv))

    def position_derivatives(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(∂p/∂u, ∂p/∂v) (3, N) of each hit's triangle from its positions and UVs, and where they
        exist (N,) (False on triangles with degenerate UVs or without UVs)."""
        def compute():
            a = self.attributes
            if a.uv is None or a.vertices is None:
                z = np.zeros((3, self.n))
                return z, z, np.zeros(self.n, bool)
            tri = a.faces[self.prim]
            p0, p1, p2 = (a.vertices[tri[:, i]] for i in range(3))
            t0, t1, t2 = (a.uv[tri[:, i]] for i in range(3))
            dp1, dp2 = p1 - p0, p2 - p0
            du1, dv1 = t1[:, 0] - t0[:, 0], t1[:, 1] - t0[:, 1]
            du2, dv2 = t2[:, 0] - t0[:, 0], t2[:, 1] - t0[:, 1]
            det = du1 * dv2 - du2 * dv1
            scale = np.abs(det) > 1e-300
            inv = np.where(scale, 1.0 / np.where(scale, det, 1.0), 0.0)
            dpdu = ((dv2 * inv)[:, None] * dp1 - (dv1 * inv)[:, None] * dp2).T
            dpdv = ((du1 * inv)[:, None] * dp2 - (du2 * inv)[:, None] * dp1).T
            ok = scale & np.all(np.isfinite(dpdu), axis=0) & np.all(np.isfinite(dpdv), axis=0)
            return dpdu, dpdv, ok
        return self.memo("dpduv", compute)

    def tangent_frame(self, n_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit tangent T ⟂ n_s along +u and bitangent B = ±(n_s × T) along +v, (3, N) each: from
        per-vertex tangents (xyz, w = handedness) if the meshes have them, else from ∂p/∂u, ∂p/∂v
        (Gram–Schmidt against n_s); any perpendicular pair where neither exists."""
        a = self.attributes
        t, dpdv, ok = self.position_derivatives()
        t4 = self._interpolate(a.tangents) if a.tangents is not None else None
        return tangent_frame(n_s, t, dpdv, ok, t4, t4 is not None)      # (engine.kernels.geometry)

    def attribute(self, name: str, channels: int) -> np.ndarray:
        """Colour attribute ``name`` (channels, N), 0 where the scene has no such attribute."""
        layer = self.attributes.layers.get(name)
        if layer is None:
            return np.zeros((channels, self.n))
        value = self.memo(("attribute", name), lambda: self._interpolate(layer))
        if value.shape[0] >= channels:
            return value[:channels]
        return np.concatenate((value, np.zeros((channels - value.shape[0], self.n))))


def _is_subset(sel) -> bool:
    """``sel`` picks distinct points in their order (a mask, a slice with a positive step, increasing indices)."""
    if isinstance(sel, slice):
        return sel.step is None or sel.step > 0
    sel = np.asarray(sel)
    if sel.dtype == np.bool_:
        return sel.ndim == 1
    return sel.ndim == 1 and sel.dtype.kind in "iu" and bool(np.all(sel[1:] > sel[:-1]))


def _points_of(value, sel, n: int):
    """A memoised value (an array with the points along its last axis, or a tuple of such) at the points
    ``sel`` of its n; None if it is not per point (then it is looked up again)."""
    if isinstance(value, tuple):
        parts = tuple(_points_of(v, sel, n) for v in value)
        return None if any(p is None for p in parts) else parts
    if not isinstance(value, np.ndarray) or value.ndim == 0 or value.shape[-1] != n:
        return None
    if isinstance(sel, slice) or np.asarray(sel).dtype == np.bool_:
        return value[..., sel].copy()
    return np.take(value, sel, axis=-1)
