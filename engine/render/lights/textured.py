"""Emissive meshes whose radiance varies over the surface (a texture × strength).

Part of engine.render.lights (its package docstring states the light interface).  The emitted
radiance at a point x is L_e(x, λ) = D65n(λ)·Σ c_i(x) B_i(λ), c(x) = strength × the texture's RGB at
x (``engine.textures.textured_emission``): per point exactly a constant ``RGBIlluminantSpectrum`` of
that colour; in RGB that spectrum's exact integral against the observer (as a constant light's
``rgb()``), in mono its luminance.  The integrator asks for it where a ray hits the emitter (the
hit's triangle and barycentrics) and at the points that next-event estimation samples
(``sample_points``, which also returns them).
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import SceneError
from ...scene.description import EMISSION_SAMPLING
from ...textures import TexturedSpectrum
from ...vec3 import dot
from ..accel import surface_points
from .area import AreaEmitter



def triangle_grid(levels: int) -> tuple[np.ndarray, np.ndarray]:
    """Barycentrics (b1, b2) (levels²,) of the centroids of the levels² congruent sub-triangles a
    triangle splits into (levels per edge): equal-area points for its mean."""
    i, j = np.meshgrid(np.arange(levels), np.arange(levels), indexing="ij")
    up = (i + j) < levels
    down = (i + j) < levels - 1
    b1 = np.concatenate(((i[up] + 1.0 / 3.0), (i[down] + 2.0 / 3.0))) / levels
    b2 = np.concatenate(((j[up] + 1.0 / 3.0), (j[down] + 2.0 / 3.0))) / levels
    return b1, b2


class TexturedAreaEmitter(AreaEmitter):
    """A Lambertian emitter of mesh triangles (one- or two-sided, optionally with a spread profile)
    whose radiance is a ``TexturedSpectrum`` of kind "illuminant".

    Per-triangle emitted luminance L̄_t: the mean of the texture's luminance (that of the exact RGB,
    ``TexturedSpectrum.luminance_at``) over ``levels``² equal-area points of the triangle (the
    centroids of its regular subdivision), ``levels`` = ⌈2·√(texels it covers)⌉ clipped to
    [2, MAX_LEVELS]: about two points per texel side, texel resolution for small meshes; all levels
    shrink (to ≥ 1) where the mesh would need more than ESTIMATE_POINTS lookups.  Σ A_t·L̄_t is the
    emitter's power (light selection).

    ``sampling`` "luminance": triangle t with probability ∝ A_t·w_t, the point uniform within it,
    so its area pdf is w_t / Σ A_s·w_s (``density``).  w_t = L̄_t, raised to FLOOR × the emitter's mean
    where the texture may be positive on the triangle at all (``TextureInput.may_be_positive``: its
    texel footprint, conservative) — an estimate can miss a thin bright sliver, and although MIS
    stays unbiased there (BSDF sampling alone covers points of NEE pdf 0: weight 1), its light would
    come from BSDF hits only — and w_t = 0 where it cannot be: black triangles get no samples.  A
    rectangle (two triangles, today sampled by solid angle) draws one sample of the mixture
    RECT_SHARE·(solid angle) + (1 − RECT_SHARE)·(luminance) and weighs it by the mixture's pdf, so it
    keeps most of the solid-angle sampling's gain near the lamp.  Where every w_t is equal (a uniform
    texture) the emitter is sampled as a constant one.  "area": as a constant emitter (by area; a
    rectangle by solid angle), the texture read at the sampled point.  Either way ``sample_points``
    returns (triangle, b1, b2) of its points, ``pdf_hit`` takes the hit's triangle (``prim``): MIS
    sees the pdf that sampled the point.  A black emitter (no triangle may be positive) returns no
    valid sample and has power 0.
    """

    varies_over_surface = True
    MAX_LEVELS = 64
    ESTIMATE_POINTS = 1 << 19
    FLOOR = 1e-3
    RECT_SHARE = 0.5

    def __init__(self, spectrum, tris, compiled, two_sided=False, spread_deg=180.0, sampling="luminance",
                 field="emission"):
        if not isinstance(spectrum, TexturedSpectrum) or spectrum.kind != "illuminant":
            raise SceneError(field, "a textured emission must be a TexturedSpectrum of kind 'illuminant' "
                                    "(engine.textures.textured_emission)")
        if sampling not in EMISSION_SAMPLING:
            raise SceneError(f"{field}_sampling", f"must be one of {', '.join(map(repr, EMISSION_SAMPLING))}, "
                                                  f"got {sampling!r}")
        super().__init__(spectrum, np.sort(tris), compiled, two_sided, spread_deg)
        self.sampling = sampling
        areas = compiled.tri_area[self.tris]
        self.tri_luminance, self.tri_may_emit = self._triangle_luminance()
        self._power_area = float((areas * self.tri_luminance).sum())
        weight = self._luminance_weight()
        self.black = not bool(self.tri_may_emit.any())
        self.density = None             # area pdf per triangle (luminance sampling), else None
        # equal weights (a uniform texture, up to the estimate's rounding): sampled as a constant emitter
        if not self.black and sampling == "luminance" and weight.max() - weight.min() > 1e-9 * weight.max():
            mass = areas * weight
            total = float(mass.sum())
            cdf = np.cumsum(mass) / total
            cdf[np.flatnonzero(mass > 0)[-1]:] = 1.0        # trailing zero-mass triangles are never picked
            self.lum_cdf = cdf
            self.density = weight / total

    # ------------------------------------------------------------------ the texture per triangle

    def _triangle_luminance(self) -> tuple[np.ndarray, np.ndarray]:
        """(estimated mean emitted luminance (T,), may the radiance be positive (T,)) per triangle."""
        c, source = self.compiled, self.spectrum.source
        attributes = surface_points(c, self.tris[:0], np.zeros(0), np.zeros(0)).attributes
        texels = source.texture.texels_per_triangle(attributes, self.tris)
        levels = np.clip(np.ceil(2.0 * np.sqrt(texels)), 2, self.MAX_LEVELS).astype(np.int64)
        need = float((levels.astype(np.float64) ** 2).sum())
        if need > self.ESTIMATE_POINTS:
            shrink = math.sqrt(self.ESTIMATE_POINTS / need)
            levels = np.maximum(np.floor(levels * shrink), 1).astype(np.int64)
        mean = np.zeros(len(self.tris))
        for k in np.unique(levels):
            rows = np.flatnonzero(levels == k)
            b1, b2 = triangle_grid(int(k))
            per = b1.size
            step = max(1, (1 << 18) // per)
            for start in range(0, rows.size, step):
                part = rows[start:start + step]
                prim = np.repeat(self.tris[part], per)
                points = surface_points(c, prim, np.tile(b1, part.size), np.tile(b2, part.size))
                lum = self.spectrum.luminance_at(points)
                mean[part] = np.maximum(lum, 0.0).reshape(part.size, per).mean(axis=1)
        may = (mean > 0) | source.may_be_positive(attributes, self.tris)
        return mean, may

    def mean_luminance(self) -> float:
        return self._power_area / self.total_area

    # ------------------------------------------------------------------ radiance at points

    def emitted_at(self, where, lookup, rgb_mode: bool, mono: bool) -> np.ndarray:
        """Radiance (L, n) (RGB (3, n) in RGB mode) at the points ``where`` = (triangle (n,),
        barycentrics b1, b2 (n,), Embree's: vertex weights 1 − b1 − b2, b1, b2) for paths with the
        wavelengths of ``lookup``."""
        prim, b1, b2 = where
        points = surface_points(self.compiled, prim, b1, b2)
        if rgb_mode:
            return self.spectrum.linear_srgb_at(points)
        if not mono and lookup.channels and type(self.spectrum).at is TexturedSpectrum.at:
            # "rgb" transport (rgb_channel_tables: basis the identity, D65 1): ``spectrum.at`` is the texels'
            # RGB itself (up to the sign of zeros) where they are finite; without the tables' gathers and products
            rgb = self.spectrum.rgb_at(points)
            if np.isfinite(rgb).all():
                return rgb
        if mono:
            return self.spectrum.at(points, lookup.lam, True)
        return self.spectrum.at(points, lookup.lam, False, lookup.basis, lookup.d65)

    def _weights(self, prim: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Barycentrics (b1, b2) (n,) of the points x (3, n) projected onto the planes of triangles
        ``prim`` (unclipped: outside the triangle some weight is < 0)."""
        c = self.compiled
        f = c.faces[prim]
        v0 = c.vertices[f[:, 0]].T
        e1 = c.vertices[f[:, 1]].T - v0
        e2 = c.vertices[f[:, 2]].T - v0
        r = x - v0
        a11, a12, a22 = dot(e1, e1), dot(e1, e2), dot(e2, e2)
        r1, r2 = dot(r, e1), dot(r, e2)
        det = a11 * a22 - a12 * a12
        ok = det > 0
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        return (a22 * r1 - a12 * r2) * inv, (a11 * r2 - a12 * r1) * inv

    def barycentrics(self, prim: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Barycentrics (b1, b2) (n,) of the points x (3, n) on triangles ``prim``, kept within the
        triangle (for crossings that the ray caster reports without them)."""
        b1, b2 = self._weights(prim, x)
        b1, b2 = np.clip(b1, 0.0, 1.0), np.clip(b2, 0.0, 1.0)
        over = b1 + b2
        big = over > 1.0
        return np.where(big, b1 / np.where(big, over, 1.0), b1), np.where(big, b2 / np.where(big, over, 1.0), b2)

    def _locate(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(triangle, b1, b2) of points x (3, n) on the rectangle (two triangles): the triangle that
        holds each point (the one whose smallest barycentric weight is larger)."""
        inside = []
        for t in self.tris:
            b1, b2 = self._weights(np.full(x.shape[1], t), x)
            inside.append(np.minimum(np.minimum(b1, b2), 1.0 - b1 - b2))
        prim = np.where(inside[1] > inside[0], self.tris[1], self.tris[0])
        b1, b2 = self.barycentrics(prim, x)
        return prim, b1, b2

    # ------------------------------------------------------------------ sampling

    def sample(self, p, u):
        return self.sample_points(p, u)[:5]

    def sample_points(self, p, u):
        """``sample``'s (wi, dist, scale, pdf, valid) and the sampled points (triangle, b1, b2)."""
        n = p.shape[1]
        if self.black:
            z = np.zeros(n)
            return (np.zeros((3, n)), np.ones(n), z, z.copy(), np.zeros(n, bool),
                    (np.full(n, self.tris[0]), z.copy(), z.copy()))
        if self.density is None:
            if self.rect is not None:           # as a constant rectangle: by solid angle
                wi, dist, scale, pdf, valid = AreaEmitter.sample(self, p, u)
                return wi, dist, scale, pdf, valid, self._locate(p + wi * dist[None, :])
            wi, dist, cos_l, where = self._triangle_points(p, u[0], u[1], u[2], self.cdf)
            return (*self._weighted(wi, dist, cos_l, self._area_pdf(dist, cos_l, None)), where)
        if self.rect is None:                   # triangles by luminance
            wi, dist, cos_l, where = self._triangle_points(p, u[0], u[1], u[2], self.lum_cdf)
            return (*self._weighted(wi, dist, cos_l, self._area_pdf(dist, cos_l, where[0])), where)
        # a rectangle: one sample of the mixture RECT_SHARE·(solid angle) + (1 − RECT_SHARE)·(luminance)
        share = self.RECT_SHARE
        by_rect = u[0] < share
        wi, dist, cos_l = np.empty((3, n)), np.empty(n), np.empty(n)
        prim, b1, b2 = np.empty(n, np.int64), np.empty(n), np.empty(n)
        rows = np.flatnonzero(by_rect)
        if rows.size:
            ur = u[:, rows].copy()
            ur[0] = np.minimum(ur[0] / share, np.nextafter(1.0, 0.0))     # the area fallback's triangle choice
            w, d, _, _, _ = AreaEmitter.sample(self, p[:, rows], ur)
            wi[:, rows], dist[rows] = w, d
            prim[rows], b1[rows], b2[rows] = self._locate(p[:, rows] + w * d[None, :])
            cos_l[rows] = self.facing(-dot(w, self.compiled.tri_normal[prim[rows]].T))
        rows = np.flatnonzero(~by_rect)
        if rows.size:
            u0 = np.minimum((u[0, rows] - share) / (1.0 - share), np.nextafter(1.0, 0.0))
            w, d, c, (t, x1, x2) = self._triangle_points(p[:, rows], u0, u[1, rows], u[2, rows], self.lum_cdf)
            wi[:, rows], dist[rows], cos_l[rows], prim[rows], b1[rows], b2[rows] = w, d, c, t, x1, x2
        pdf = self._mixture_pdf(dist, cos_l, p, prim)
        return (*self._weighted(wi, dist, cos_l, pdf), (prim, b1, b2))

    def _triangle_points(self, p, u0, u1, u2, cdf):
        """Points on the triangle that ``cdf`` picks with u0, uniform within it (u1, u2), seen from p:
        (wi, dist, cosθ at the emitting side, (triangle, b1, b2))."""
        idx = np.minimum(np.searchsorted(cdf, u0, side="right"), len(self.tris) - 1)
        return self.points_on(p, self.tris[idx], u1, u2)

    def tree_luminance(self) -> np.ndarray:
        """Per triangle (T,): the luminance the light tree weighs its area with — the luminance-sampling weight
        (the estimate, floored where the texture may be positive, 0 where it cannot), the mean with "area"."""
        if self.black:
            return np.zeros(len(self.tris))
        if self.sampling != "luminance":
            return np.full(len(self.tris), self.mean_luminance())
        return self._luminance_weight()

    def _luminance_weight(self) -> np.ndarray:
        """w_t (T,): the estimated luminance, raised to FLOOR × the mean where the texture may be positive, else 0."""
        mean = self._power_area / self.total_area
        floor = self.FLOOR * mean if mean > 0 else 1.0
        return np.where(self.tri_may_emit, np.maximum(self.tri_luminance, floor), 0.0)

    def _area_pdf(self, dist, cos_l, prim):
        """Solid-angle pdf of points at dist, cos_l on triangles ``prim`` sampled with the area density
        (uniform: None) or by luminance."""
        ok = (cos_l > 0) & (dist > 0)
        area_pdf = 1.0 / self.total_area if prim is None else self.density[np.searchsorted(self.tris, prim)]
        return np.where(ok, dist * dist / np.where(ok, cos_l, 1.0) * area_pdf, 0.0)

    def _mixture_pdf(self, dist, cos_l, origin, prim):
        """The rectangle's mixture pdf (``sample_points``) of points on triangles ``prim`` seen from origin."""
        share = self.RECT_SHARE
        return share * AreaEmitter.pdf_hit(self, dist, cos_l, origin) + (1.0 - share) * self._area_pdf(dist, cos_l,
                                                                                                         prim)

    def _weighted(self, wi, dist, cos_l, pdf):
        """(wi, dist, scale = profile/pdf, pdf, valid) of sampled points."""
        valid = (cos_l > 0) & (dist > 0) & (pdf > 0)
        pdf = np.where(valid, pdf, 0.0)
        scale = np.where(valid, 1.0 / np.where(valid, pdf, 1.0), 0.0)
        if self.profile is not None:
            scale = scale * self.profile(cos_l)
            valid &= scale > 0
        return wi, dist, scale, pdf, valid

    @property
    def hit_pdf_needs_origin(self) -> bool:
        return self.rect is not None and not self.black

    def pdf_hit(self, dist, cos_l, origin=None, prim=None):
        """``AreaEmitter.pdf_hit`` for the points on triangles ``prim`` (n,) (needed with luminance
        sampling: the area pdf is that triangle's)."""
        if self.black:
            return np.zeros(np.shape(dist))
        if self.density is None:
            return super().pdf_hit(dist, cos_l, origin)
        if self.rect is None or origin is None:
            return self._area_pdf(dist, cos_l, prim)
        return self._mixture_pdf(dist, cos_l, origin, prim)
