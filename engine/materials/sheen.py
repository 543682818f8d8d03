"""Sheen as Cycles renders it (Principled BSDF's Sheen layer, the Sheen BSDF node's Microfiber): the
microfiber sheen of Zeltner, Burley & Chiang 2022, "Practical Multiple-Scattering Sheen Using Linearly
Transformed Cosines", in Cycles' form (kernel/closure/bsdf_sheen.h).  A depolariser.

With μ = cosθ_o (the viewer's side of the shading normal n) and r = clamp(roughness, 10⁻³, 1), three numbers
are read from a 32 × 32 table by bilinear interpolation as Cycles' lookup_table_read_2D does it (node i at
μ = i/31, node j at r = j/31): the transform a(μ, r), b(μ, r) and the directional albedo E(μ, r).  In the
frame B = normalize(n × wo), T = B × n (T: the viewer's side of the tangent plane; any frame about n at
μ = 1), with wi = (x, y, z),

    f·cosθ_i = E·D(wi),   D(wi) = (1/π)·max(z, 0)·(a / ((a x + b z)² + (a y)² + z²))²

D is a clamped cosine linearly transformed by M with M⁻¹ = [[a, 0, b], [0, a, 0], [0, 0, 1]] (a > 0), a
density over the upper hemisphere, so E is the albedo (the share of light the layer reflects, which
Cycles' Principled BSDF takes off the layers below: ``albedo``).  Mueller matrix f·tint·diag(1, 0, 0, 0)
with the ``tint`` spectrum (Cycles' Sheen Weight × Sheen Tint, or the node's Color).  Where the
interpolated |a| or E is below 10⁻⁵ Cycles drops the closure; so does this model (below r ≈ 0.13 that
leaves a sheen only towards grazing views, and at r → 0 almost none).

Sampling is exact, as Cycles': a cosine-distributed direction (x', y', z') becomes (x' − z'b, y', z'a),
normalised; pdf = D, weight = E·tint (valid where wi lies above the geometric normal, as Cycles rejects the
others).  As Polar's other diffuse models (Lambert, Oren–Nayar), the value is 0 where wo is behind the
shading normal (Cycles reads the table at μ = 0 there).

The table (engine/materials/data/sheen_ltc.npz: a, b, albedo indexed [μ node, roughness node]) is Polar's
own, fitted to Cycles' renders by tests/bench/fit_sheen.py (Cycles' table is in Blender's source, not in
its Python module, and is not copied).
"""

from __future__ import annotations

import functools
import math
import os

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, LobeColors, ShadingPoint, depolarising_value
from .parameters import ModelDeclaration, Parameter
from .sampling import cosine_hemisphere
from ..textures import TexturedNumber, textured
from ..vec3 import cross, dot, local_frame

TABLE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "sheen_ltc.npz")
NODES = 32
#: Cycles skips the closure where the interpolated |a| or E is below this (bsdf_sheen_setup).
CUTOFF = 1e-5
#: Cycles' smallest roughness (bsdf_sheen_setup clamps to [1e-3, 1]).
MIN_ROUGHNESS = 1e-3


@functools.lru_cache(maxsize=1)
def ltc_table() -> np.ndarray:
    """(3, 32, 32) float64: a, b and E at [μ node i, roughness node j] (μ = i/31, r = j/31)."""
    with np.load(TABLE) as data:
        table = np.stack([data["a"], data["b"], data["albedo"]]).astype(np.float64)
    if table.shape != (3, NODES, NODES):
        raise ValueError(f"{TABLE}: expected 32 × 32 tables, got {table.shape[1:]}")
    table.setflags(write=False)
    return table


def _axis(x: np.ndarray | float, n: int = NODES):
    """(i0, i1, t) of Cycles' lookup_table_read: x clamped to [0, 1], nodes at k/(n − 1)."""
    s = np.clip(x, 0.0, 1.0) * (n - 1)
    i0 = np.minimum(np.floor(s).astype(np.int64), n - 1)
    return i0, np.minimum(i0 + 1, n - 1), s - i0


def roughness_row(roughness: float) -> np.ndarray:
    """(3, 32): a, b, E along μ at one roughness (the table interpolated in r, as Cycles)."""
    r = min(max(float(roughness), MIN_ROUGHNESS), 1.0)
    j0, j1, t = _axis(r)
    table = ltc_table()
    return (1.0 - t) * table[:, :, j0] + t * table[:, :, j1]


def lookup(mu: np.ndarray, row: np.ndarray):
    """(a, b, E) (each (N,)) at cosθ_o = mu (N,) from a roughness row (3, 32) (``roughness_row``)."""
    i0, i1, t = _axis(mu)
    v = (1.0 - t) * row[:, i0] + t * row[:, i1]
    return v[0], v[1], v[2]


def lookup_per_point(mu: np.ndarray, roughness: np.ndarray):
    """(a, b, E) (each (N,)) at cosθ_o = mu (N,) and a roughness per point (N,): the same bilinear
    interpolation as ``roughness_row`` then ``lookup`` (Cycles' lookup_table_read_2D)."""
    r = np.clip(roughness, MIN_ROUGHNESS, 1.0)
    i0, i1, t = _axis(mu)
    j0, j1, s = _axis(r)
    table = ltc_table()
    low = (1.0 - s) * table[:, i0, j0] + s * table[:, i0, j1]
    high = (1.0 - s) * table[:, i1, j0] + s * table[:, i1, j1]
    v = (1.0 - t) * low + t * high
    return v[0], v[1], v[2]


def ltc_density(x, y, z, a, b):
    """D (1/sr) of the direction (x, y, z) in the sheen frame (0 below the horizon)."""
    u = a * x + b * z
    q = u * u + (a * y) ** 2 + z * z
    return np.where(z > 0, np.maximum(z, 0.0) / math.pi * (a / np.where(q > 0, q, 1.0)) ** 2, 0.0)


def sheen_frame(n: np.ndarray, wo: np.ndarray):
    """(T, B) of Cycles' make_orthonormals_safe_tangent(n, wo): B = normalize(n × wo), T = B × n, or the
    engine's local frame about n where wo is along n."""
    c = cross(n, wo)
    length = np.sqrt(dot(c, c))
    ok = length > 1e-12
    t0, b0 = local_frame(n)
    b = np.where(ok[None, :], c / np.where(ok, length, 1.0)[None, :], b0)
    t = np.where(ok[None, :], cross(b, n), t0)
    return t, b


class Sheen(BSDF):
    """Cycles' microfiber sheen of roughness r ∈ [0, 1] (a number or a TexturedNumber: per point) with a ``tint``
    spectrum (constant or textured)."""

    name = "sheen"

    def __init__(self, tint, roughness):
        if isinstance(roughness, TexturedNumber):
            if not (0.0 <= roughness.lo and roughness.hi <= 1.0):
                raise ValueError(f"roughness must be in [0, 1], got values in [{roughness.lo:g}, {roughness.hi:g}]")
            self.roughness, self._row = roughness, None
        else:
            r = float(roughness)
            if not (math.isfinite(r) and 0.0 <= r <= 1.0):
                raise ValueError(f"roughness must be in [0, 1], got {roughness!r}")
            self.roughness, self._row = r, roughness_row(r)
        self.tint = tint
        self.varies_over_surface = textured(tint, roughness)
        self.flags = (BSDFFlags.DIFFUSE_REFLECTION | BSDFFlags.SEPARABLE_DIFFUSE
                      | BSDFFlags.when(not getattr(tint, "is_constant", False), BSDFFlags.WAVELENGTH_DEPENDENT))

    # ----------------------------------------------------------------- pieces

    def _tint(self, sp: ShadingPoint) -> np.ndarray:
        return np.maximum(sp.spectrum(self.tint), 0.0)

    def _table(self, sp: ShadingPoint):
        """(a, b, E) (each (N,)) at cosθ_o and the points' roughness."""
        if self._row is not None:
            return lookup(sp.cos_o, self._row)
        return lookup_per_point(sp.cos_o, sp.number(self.roughness))

    def _closure(self, sp: ShadingPoint):
        """(a, b, E, on): the table at cosθ_o and where the closure exists (wo in front, not dropped)."""
        cos_o = sp.cos_o
        a, b, e = self._table(sp)
        on = (cos_o > 0) & (np.abs(a) >= CUTOFF) & (e >= CUTOFF)
        return a, b, e, on

    def _local(self, sp: ShadingPoint, wi: np.ndarray):
        t, b = sheen_frame(sp.n_s, sp.wo)
        return dot(wi, t), dot(wi, b), dot(wi, sp.n_s)

    def _density(self, sp: ShadingPoint, wi: np.ndarray):
        """(D, E, on): the lobe's density at wi, the albedo, and where the closure exists."""
        a, b, e, on = self._closure(sp)
        x, y, z = self._local(sp, wi)
        d = np.where(on, ltc_density(x, y, z, np.where(on, a, 1.0), b), 0.0)
        return d, e, on

    # ----------------------------------------------------------------- the interface

    def albedo(self, sp: ShadingPoint) -> np.ndarray:
        """E(cosθ_o, r) (N,): the directional albedo Cycles' Principled BSDF takes off the layers below the
        sheen (weight·(1 − sheen weight·E·max(tint))); 0 where Cycles drops the closure.  Read at cosθ_o
        clamped to [0, 1] as Cycles reads it (so not 0 where wo is behind the shading normal)."""
        a, _, e = self._table(sp)
        return np.where((np.abs(a) >= CUTOFF) & (e >= CUTOFF), e, 0.0)

    def lobe_colors(self, sp: ShadingPoint) -> LobeColors:
        """Diffuse (Cycles counts its sheen closure as diffuse): tint × E(cosθ_o), its weight after
        ``bsdf_sheen_setup`` scaled it by the albedo."""
        return LobeColors.of(sp, diffuse=self._tint(sp) * self.albedo(sp)[None, :])

    def albedo_estimate(self, sp: ShadingPoint) -> np.ndarray:
        """The view direction's albedo (N,) for mixtures' lobe choice: the tint's wavelength mean × E."""
        return self._tint(sp).mean(axis=0) * np.where(sp.cos_o > 0, self.albedo(sp), 0.0)

    def eval(self, sp: ShadingPoint, wi: np.ndarray):
        d, e, _ = self._density(sp, wi)
        z = dot(wi, sp.n_s)
        f = np.where(z > 0, e * d / np.where(z > 0, z, 1.0), 0.0)        # E·D/cosθ_i
        return depolarising_value(self._tint(sp) * f[None, :], sp.n)

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        return self._density(sp, wi)[0]

    def sample(self, sp: ShadingPoint, u_lobe, u_dir) -> BSDFSample:
        a, b, e, on = self._closure(sp)
        c = cosine_hemisphere(u_dir)                                   # uniform disk, lifted
        aa = np.where(on, a, 1.0)
        v = np.stack((c[0] - c[2] * b, c[1], c[2] * aa))
        v = v / np.sqrt(dot(v, v))[None, :]
        t, bt = sheen_frame(sp.n_s, sp.wo)
        wi = t * v[0] + bt * v[1] + sp.n_s * v[2]
        valid = on & (v[2] > 0) & (dot(wi, sp.n_g) > 0)
        pdf = np.where(valid, ltc_density(v[0], v[1], v[2], aa, b), 0.0)
        weight = self._tint(sp) * np.where(valid, e, 0.0)[None, :]      # f·cosθ_i/pdf = E·D/D
        return BSDFSample(wi=wi, weight=depolarising_value(weight, sp.n), pdf=pdf,
                          is_delta=np.zeros(sp.n, bool), valid=valid, eta_sq=np.ones(sp.n))

    def describe(self) -> dict:
        rough = self.roughness if self._row is not None else repr(self.roughness)
        return {"type": self.name, "tint": repr(self.tint), "roughness": rough}


# --------------------------------------------------------------------------- declaration

DECLARATION = ModelDeclaration(
    "sheen", "Sheen (Cycles microfiber)",
    "Cycles' microfiber sheen (Principled Sheen, Sheen BSDF Microfiber): Zeltner et al.'s LTC lobe from a "
    "fitted table; depolarising",
    [Parameter("tint", "sheen colour (Cycles: Sheen Weight × Sheen Tint, or the Sheen BSDF's Color)",
               kind="spectrum", spectrum="unbounded", lo=0.0, hi=1e6, default=1.0, texturable=True),
     Parameter("roughness", "sheen roughness r", lo=0.0, hi=1.0, default=0.5, texturable=True)])
DECLARATION.per_point = frozenset({"tint", "roughness"})


@DECLARATION.builder
def _sheen(p):
    return Sheen(p["tint"], p["roughness"])
