"""Area lights: emissive triangles, Blender's rectangle, disk and ellipse lamps, Cycles' spread.

Part of engine.render.lights (its package docstring states the light interface)."""

from __future__ import annotations

import math

import numpy as np

from ...kernels.geometry import area_light_sample, area_lights_sample, triangle_sample
from ...kernels.lamp_sampling import bilinear_warp_pdf, bilinear_warp_sample, ellipse_lamp_pdf, ellipse_lamp_sample
from ...kernels.light_sampling import (MIN_RECT_SOLID_ANGLE, SELECT_AREA, area_importance, rect_angles,
                                       rect_light_sample, rect_local, rect_sample)
from ...spectral import luminance
from ...vec3 import dot
from .base import _Light


def spread_profile(spread_rad: float):
    """Cycles' area-light spread f(cosθ) (kernel/light/area.h: area_light_spread_attenuation),
    normalised so that ∫ f cosθ dω = π; None for spread ≥ 180° (f = 1, Lambertian)."""
    half = 0.5 * spread_rad
    if half >= 0.5 * math.pi - 1e-9:
        return None
    tan_half = math.tan(half)
    norm = 1.0 / (tan_half - half) if half > 0.05 else 3.0 / half ** 3

    def f(cos_t):
        c = np.clip(cos_t, 1e-12, 1.0)
        tan_t = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
        return np.where(cos_t > 0, np.maximum(0.0, (tan_half - tan_t) * norm), 0.0)
    return f


class SphericalRectangle:
    """A planar rectangle (corner, unit edge axes x ⟂ y, edge lengths) sampled uniformly in the
    solid angle it subtends (Ureña, Conty & Kettunen 2013, "An Area-Preserving Parametrization
    for Spherical Rectangles"; Cycles' kernel/light/area.h samples rectangle lamps this way).
    Distances in scene units, solid angles in sr; the arithmetic is engine.kernels.light_sampling's."""

    def __init__(self, corner, ex, ey):
        self.corner = np.asarray(corner, np.float64)
        self.len_x = float(np.linalg.norm(ex))
        self.len_y = float(np.linalg.norm(ey))
        self.x = np.asarray(ex, np.float64) / self.len_x
        self.y = np.asarray(ey, np.float64) / self.len_y
        self.z = np.cross(self.x, self.y)

    @classmethod
    def from_triangles(cls, corners, tol=1e-9):
        """The rectangle covered by two triangles (2, 3, 3) (world coordinates), exactly or to float32 rounding, or
        None when they do not form one (e.g. a sheared parallelogram or a disk fan)."""
        pts = corners.reshape(-1, 3)
        unique = []
        for q in pts:
            if not any(np.allclose(q, v, rtol=0.0, atol=tol * (1.0 + np.abs(q).max())) for v in unique):
                unique.append(q)
        if len(corners) != 2 or len(unique) != 4:
            return None
        a = unique[0]
        # the corner opposite a is the farthest one; the other two span the edges from a
        rest = sorted(unique[1:], key=lambda q: float(np.dot(q - a, q - a)))
        ex, ey, diag = rest[0] - a, rest[1] - a, rest[2] - a
        lx, ly = np.linalg.norm(ex), np.linalg.norm(ey)
        if lx <= 0 or ly <= 0:
            return None
        scale = max(lx, ly)
        tri_area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
        # corners rounded to float32 (Blender's vertices and matrices) miss a rectangle by up to ≈ 2.4 units of
        # float32 rounding of the largest coordinate (measured over random rotations, sizes and places): allowed
        slack = 8.0 * 2.0 ** -24 * (1.0 + np.abs(pts).max())
        if (abs(np.dot(ex, ey)) > tol * lx * ly + slack * (lx + ly)
                or np.abs(diag - ex - ey).max() > tol * scale + slack
                or abs(tri_area.sum() - lx * ly) > 1e-7 * lx * ly + slack * (lx + ly)):
            return None
        return cls(a, ex, ey)

    def _local(self, p):
        """Rectangle coordinates relative to points p (3, N) (engine.kernels.light_sampling.rect_local)."""
        return rect_local(p, self.corner, self.x, self.y, self.z, self.len_x, self.len_y)

    def solid_angle(self, p):
        """Solid angle (N,) that the rectangle subtends at points p (3, N); 0 in its plane."""
        x0, x1, y0, y1, z0, _ = self._local(p)
        with np.errstate(invalid="ignore", divide="ignore"):
            S = rect_angles(x0, x1, y0, y1, z0)[3]
        return np.where(z0 < 0, np.nan_to_num(S), 0.0)

    def sample(self, p, u1, u2):
        """Points (3, N) on the rectangle, uniform in solid angle seen from p, and that solid angle (N,)."""
        return rect_sample(p, u1, u2, self.corner, self.x, self.y, self.z, self.len_x, self.len_y)


class AreaEmitter(_Light):
    """A Lambertian emitter made of mesh triangles: one-sided (emits along their front normal)
    or two-sided (both faces, same radiance), optionally with Cycles' spread profile.

    Points are sampled uniformly by area, solid-angle pdf dist² / (|cosθ_light| · A_total); an
    emitter that is one rectangle (two triangles: Blender's square/rectangle lamps) is sampled
    uniformly in the solid angle Ω it subtends, pdf 1/Ω (``SphericalRectangle``), except where
    Ω ≤ ``MIN_RECT_SOLID_ANGLE`` (then by area). ``pdf_hit`` evaluates the same choice from the
    ray's origin, so next-event estimation and MIS agree.
    """

    def __init__(self, spectrum, tris: np.ndarray, compiled, two_sided=False, spread_deg=180.0):
        super().__init__(spectrum)
        self.tris = tris
        areas = compiled.tri_area[tris]
        self.total_area = float(areas.sum())
        self.cdf = np.cumsum(areas) / self.total_area
        self.compiled = compiled
        self.two_sided = bool(two_sided)
        self.profile = spread_profile(math.radians(spread_deg))
        #: half the spread (rad, ≤ π/2): the emission cone about the normal (the light tree's θ_e)
        self.spread_half = min(0.5 * math.pi, 0.5 * math.radians(spread_deg))
        # Opaque emitters can stop their own grazing shadow rays (see CompiledScene.unblock_own_hits).
        # The correction is applied to two-sided (Blender) emitters only: for the scene format's
        # one-sided emitters it would change peer renders (cornell_lambert: 2 of 25,600 pixels at 2 spp).
        self.blocks_own_shadow_rays = self.two_sided and bool(compiled.tri_occluder[tris].all())
        # Solid-angle sampling needs a rectangle; the integrator's own-shadow correction recovers
        # cosθ from the area pdf, so emitters that block their own shadow rays keep area sampling.
        self.rect = None
        if len(tris) == 2 and not self.blocks_own_shadow_rays:
            self.rect = SphericalRectangle.from_triangles(compiled.vertices[compiled.faces[tris]])
            if self.rect is not None:
                self.normal = compiled.tri_normal[tris[0]].astype(np.float64)

    def sample(self, p, u):
        # u has 3 rows: triangle choice, then the point within it.
        if self.rect is None:
            return self._sample_area(p, u)
        r = self.rect
        wi, dist, scale, pdf, valid, use, cos_l = rect_light_sample(p, u[1], u[2], r.corner, r.x, r.y, r.z, r.len_x,
                                                                    r.len_y, self.normal, self.two_sided)
        if self.profile is not None:
            scale = scale * self.profile(cos_l)
            valid &= scale > 0
        return self._area_where_tiny(p, u, use, wi, dist, scale, pdf, valid)

    def _area_where_tiny(self, p, u, use, wi, dist, scale, pdf, valid):
        """The solid-angle sample (wi, dist, scale, pdf, valid), with area samples where ``use`` is
        False: the rectangle's solid angle is too small for its parametrisation (MIN_RECT_SOLID_ANGLE)."""
        if not use.all():
            far = (~use).nonzero()[0]
            a_wi, a_dist, a_scale, a_pdf, a_valid = self._sample_area(p[:, far], u[:, far])
            wi[:, far], dist[far], scale[far], pdf[far], valid[far] = a_wi, a_dist, a_scale, a_pdf, a_valid
        return wi, dist, scale, pdf, valid

    def _sample_area(self, p, u):
        """Uniform sampling by area (module docstring's ``sample`` contract)."""
        c = self.compiled
        if self.profile is None:
            return area_light_sample(p, u, self.cdf, self.tris, c.faces, c.vertices, c.tri_normal, self.total_area,
                                     self.two_sided)
        # the same sampling, with the spread profile (NumPy: only Blender lamps use it)
        idx = np.minimum(np.searchsorted(self.cdf, u[0], side="right"), len(self.tris) - 1)
        tri = self.tris[idx]
        f = c.faces[tri]
        su = np.sqrt(u[1])
        b1 = 1.0 - su
        b2 = u[2] * su
        V = c.vertices
        x = (V[f[:, 0]] * (1.0 - b1 - b2)[:, None] + V[f[:, 1]] * b1[:, None] + V[f[:, 2]] * b2[:, None]).T
        to = x - p
        dist2 = dot(to, to)
        dist = np.sqrt(dist2)
        wi = to / np.where(dist > 0, dist, 1.0)
        cos_l = -dot(wi, c.tri_normal[tri].T)
        if self.two_sided:
            cos_l = np.abs(cos_l)
        valid = (cos_l > 0) & (dist > 0)
        pdf = np.where(valid, dist2 / np.where(valid, cos_l, 1.0) / self.total_area, 0.0)
        scale = np.where(valid, 1.0 / np.where(valid, pdf, 1.0), 0.0)
        scale = scale * self.profile(cos_l)
        valid &= scale > 0
        return wi, dist, scale, pdf, valid

    def points_on(self, p, tri, u1, u2):
        """Points uniform by area on the triangles ``tri`` (n,) (u1, u2 (n,) in [0, 1)) seen from p (3, n):
        (wi, dist, cosθ at the emitting side (``facing``), (triangle, b1, b2)): ``sample_triangles``' points
        (engine.kernels.geometry.triangle_sample)."""
        c = self.compiled
        wi, dist, _, _, _, cos_l, b1, b2 = triangle_sample(p, tri, u1, u2, c.faces, c.vertices, c.tri_normal,
                                                           c.tri_area, self.two_sided)
        return wi, dist, cos_l, (tri, b1, b2)

    def sample_triangles(self, p, tri, u1, u2):
        """Next-event samples on given triangles (the light tree's choice): a point uniform by area on
        triangle ``tri`` (n,) seen from p (3, n), ``sample``'s (wi, dist, scale, pdf, valid) with the pdf of
        the point given its triangle (``triangle_pdf``), and the points (triangle, b1, b2)."""
        c = self.compiled
        wi, dist, scale, pdf, valid, cos_l, b1, b2 = triangle_sample(p, tri, u1, u2, c.faces, c.vertices, c.tri_normal,
                                                                     c.tri_area, self.two_sided)
        if self.profile is not None:
            scale = scale * self.profile(cos_l)
            valid &= scale > 0
        return wi, dist, scale, pdf, valid, (tri, b1, b2)

    def triangle_pdf(self, dist, cos_l, prim):
        """Solid-angle pdf dist²/(cosθ·A) (n,) of points at dist, cos_l (emitting side) sampled uniformly by
        area on their triangles ``prim`` (n,) (``sample_triangles``)."""
        ok = (cos_l > 0) & (dist > 0)
        area = self.compiled.tri_area[prim]
        return np.where(ok, dist * dist / np.where(ok, cos_l * area, 1.0), 0.0)

    def cos_at(self, where, wi: np.ndarray) -> np.ndarray:
        """cosθ at the emitter (its emitting side) of the directions wi (3, n) towards the points ``where``."""
        return self.facing(-dot(wi, self.compiled.tri_normal[where[0]].T))

    def facing(self, cos_l):
        """cosθ at the emitter of rays arriving with −dot(d, n) = cos_l, as seen by the emitting side
        (≤ 0: the ray sees a side that does not emit)."""
        return np.abs(cos_l) if self.two_sided else cos_l

    def emission_factor(self, cos_l):
        """Directional factor of the radiance (the spread profile), or None (Lambertian)."""
        return None if self.profile is None else self.profile(cos_l)

    @property
    def hit_pdf_needs_origin(self) -> bool:
        """Whether ``pdf_hit`` needs the segment's origin: a rectangle is sampled by solid angle, so a
        BSDF-sampled ray that reaches it is MIS-weighted with 1/Ω from where the ray started (the area
        pdf there would not be the pdf next-event estimation used, and the weights would not sum to 1)."""
        return self.rect is not None

    def pdf_hit(self, dist, cos_l, origin=None):
        """Solid-angle pdf with which ``sample`` from the points ``origin`` (3, N) picks the point at
        distance dist whose emitting side faces the ray at cos_l (from ``facing``).  Without
        ``origin`` (camera rays, never MIS-weighted) the area-sampling pdf."""
        ok = cos_l > 0
        area = np.where(ok, dist * dist / np.where(ok, cos_l, 1.0) / self.total_area, 0.0)
        if self.rect is None or origin is None:
            return area
        omega = self.rect.solid_angle(origin)
        use = omega > MIN_RECT_SOLID_ANGLE
        return np.where(use, np.where(ok, 1.0 / np.where(use, omega, 1.0), 0.0), area)

    def mean_luminance(self) -> float:
        """The emitted luminance averaged over the emitter's area (a constant emitter's own)."""
        return float(luminance(self.rgb()))

    def power(self):
        """Emitted power (luminance units; Lambertian: π·L·A per emitting side)."""
        return math.pi * self.mean_luminance() * self.total_area * (2 if self.two_sided else 1)

    def _bound(self):
        """Centroid (3,) and squared radius about it of the emitter's triangles (light selection)."""
        if not hasattr(self, "_centre"):
            c = self.compiled
            corners = c.vertices[c.faces[self.tris]].reshape(-1, 3)
            w = np.repeat(c.tri_area[self.tris], 3)
            self._centre = (corners * w[:, None]).sum(0) / w.sum()
            self._r2 = float(((corners - self._centre) ** 2).sum(1).max())
        return self._centre, self._r2

    def _plane_normal(self):
        """The unit normal (3,) shared by all the emitter's triangles if they lie in one plane, else None."""
        c = self.compiled
        normals = c.tri_normal[self.tris].astype(np.float64)
        normal = normals[0] / np.linalg.norm(normals[0])
        corners = c.vertices[c.faces[self.tris]].reshape(-1, 3)
        extent = max(float(np.ptp(corners, axis=0).max()), 1e-300)
        offsets = (corners - corners[0]) @ normal
        if np.abs(normals @ normal - 1.0).max() > 1e-9 or np.abs(offsets).max() > 1e-9 * extent:
            return None
        return normal

    def selection_record(self):
        centre, r2 = self._bound()
        power = self.mean_luminance() * self.total_area * (2 if self.two_sided else 1)
        row = [*centre, power, max(r2, 1e-12), math.sqrt(r2)]
        normal = None if self.two_sided else self._plane_normal()
        if normal is not None:      # a one-sided planar emitter (Blender's area lamps): dark behind its plane
            row += [1.0, *normal]
        return SELECT_AREA, row

    def importance(self, p, n=None):
        """Bound-like estimate of the irradiance at p (3, N) with side normals n: L·A/max(d², r²)
        about the centroid, times the orientation terms (receiver; emitter if one-sided and planar)."""
        _, row = self.selection_record()
        row = row + [0.0] * (10 - len(row))
        return area_importance(p, n, np.array(row[:3]), row[3], row[4], row[5], row[6], np.array(row[7:10]))


class EllipseEmitter(AreaEmitter):
    """A one-sided disk or ellipse lamp: the fan of ``sides`` triangles around its centre whose outer
    vertices lie at the parametric angles phase + 2πk/sides of the ellipse centre + cos·axis_a +
    sin·axis_b (Blender's disk and ellipse lamps, polar_addon.export.lights).  Sampled close to the
    solid angle it subtends (engine.kernels.lamp_sampling: the concentric map of a bilinear warp
    fitted to cosθ_l/d²) instead of by area; ``pdf_hit`` gives the same pdf from the ray's origin.
    Everything else (emission, spread profile, light selection) is ``AreaEmitter``'s."""

    MIN_SIDES = 8
    hit_pdf_needs_direction = True     # pdf_hit depends on where on the lamp the ray arrives

    def __init__(self, spectrum, tris, compiled, ellipse, spread_deg=180.0):
        super().__init__(spectrum, tris, compiled, False, spread_deg)
        self.centre, self.axis_a, self.axis_b, self.sides, self.phase = ellipse
        self.normal = compiled.tri_normal[tris[0]].astype(np.float64)

    @classmethod
    def fan_ellipse(cls, corners, normals, tol=1e-7):
        """(centre, axis_a, axis_b, sides, phase) of triangles (K, 3, 3) that are the fan of a regular
        polygon inscribed in an ellipse (up to an affine map), all with the unit normal normals (K, 3);
        None otherwise."""
        K = len(corners)
        if K < cls.MIN_SIDES or np.abs(normals - normals[0]).max() > 1e-6:
            return None
        pts = corners.reshape(-1, 3)
        scale = float(np.abs(pts - pts.mean(0)).max())
        if not scale > 0:
            return None
        # the centre is the vertex all triangles share
        centre = None
        for q in corners[0]:
            if all(np.abs(tri - q).max(axis=1).min() <= tol * scale for tri in corners):
                centre = q
                break
        if centre is None:
            return None
        ring = pts[np.abs(pts - centre).max(axis=1) > tol * scale]
        unique = []
        for q in ring:
            if not any(np.abs(q - r).max() <= tol * scale for r in unique):
                unique.append(q)
        ring = np.array(unique)
        if len(ring) != K:
            return None
        n = normals[0] / np.linalg.norm(normals[0])
        e1 = ring[0] - centre
        e1 = e1 / np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        q = np.stack(((ring - centre) @ e1, (ring - centre) @ e2), axis=1)
        if np.abs((ring - centre) @ n).max() > tol * scale:
            return None
        # conic through the ring: qᵀ M q = 1, M symmetric positive definite
        A = np.stack((q[:, 0] ** 2, 2 * q[:, 0] * q[:, 1], q[:, 1] ** 2), axis=1)
        m, *_ = np.linalg.lstsq(A, np.ones(K), rcond=None)
        if np.abs(A @ m - 1.0).max() > 1e-6:
            return None
        M = np.array([[m[0], m[1]], [m[1], m[2]]])
        w, V = np.linalg.eigh(M)
        if not (w > 0).all():
            return None
        axis_a = (V[0, 0] * e1 + V[1, 0] * e2) / math.sqrt(w[0])
        axis_b = (V[0, 1] * e1 + V[1, 1] * e2) / math.sqrt(w[1])
        if np.dot(np.cross(axis_a, axis_b), n) < 0:
            axis_b = -axis_b
        # parametric angles of the ring: regular?
        aa, bb = axis_a @ axis_a, axis_b @ axis_b
        ang = np.sort(np.mod(np.arctan2((ring - centre) @ axis_b / bb, (ring - centre) @ axis_a / aa), 2 * math.pi))
        steps = np.diff(np.concatenate((ang, [ang[0] + 2 * math.pi])))
        if np.abs(steps - 2 * math.pi / K).max() > 1e-6:
            return None
        # the fan covers the polygon exactly once
        tri_area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
        polygon = 0.5 * K * math.sin(2 * math.pi / K) * float(np.linalg.norm(np.cross(axis_a, axis_b)))
        if abs(tri_area.sum() - polygon) > 1e-6 * polygon:
            return None
        return centre, axis_a, axis_b, K, float(ang[0])

    def sample(self, p, u):
        # u has 3 rows: the first (triangle choice) is unused, then the warped point
        wi, dist, scale, pdf, cos_l, valid = ellipse_lamp_sample(p, u[1], u[2], self.centre, self.axis_a, self.axis_b,
                                                                 self.normal, self.sides, self.phase)
        if self.profile is not None:
            scale = scale * self.profile(cos_l)
            valid &= scale > 0
        return wi, dist, scale, pdf, valid

    def pdf_hit(self, dist, cos_l, origin=None, d=None):
        """Solid-angle pdf with which ``sample`` from ``origin`` (3, N) reaches the lamp along the
        directions d (3, N) at distance dist; without them (camera rays) the area-sampling pdf."""
        if origin is None or d is None:
            return super().pdf_hit(dist, cos_l)
        return ellipse_lamp_pdf(origin, origin + d * dist, self.centre, self.axis_a, self.axis_b, self.normal)


class SpreadRectangleEmitter(AreaEmitter):
    """A one-sided rectangle lamp with a spread profile (Cycles' soft-box grid): the spherical
    rectangle's (u, v) (``SphericalRectangle``) are drawn from a bilinear warp fitted to the profile
    seen at its four corners (engine.kernels.lamp_sampling), so samples go where the grid lets light
    through (on the Cycles parity floor, unshadowed: 17× less variance per sample than uniform in
    solid angle at a 90° spread).  ``pdf_hit`` inverts the parametrisation at the arrival point."""

    hit_pdf_needs_direction = True     # pdf_hit depends on where on the lamp the ray arrives
    CORNER_FLOOR = 1e-2                # corner values ≥ this × the largest: the warp covers the lamp

    def _corner_profile(self, p):
        """Warp corner values (4, N) (order of WARP_CORNERS: u along the rectangle's x, v along y)."""
        r = self.rect
        ex, ey = r.x * r.len_x, r.y * r.len_y
        g = np.empty((4, p.shape[1]))
        for k, (a, b) in enumerate(((0, 0), (1, 0), (0, 1), (1, 1))):
            to = (r.corner + a * ex + b * ey)[:, None] - p
            cos_l = -dot(to, self.normal[:, None]) / np.sqrt(np.maximum(dot(to, to), 1e-300))
            g[k] = self.profile(cos_l)
        top = g.max(axis=0)
        return np.where(top > 0, np.maximum(g, self.CORNER_FLOOR * top), 1.0)

    def sample(self, p, u):
        if self.rect is None:
            return super().sample(p, u)
        r = self.rect
        uu, vv, pdf_uv = bilinear_warp_sample(self._corner_profile(p), u[1], u[2])
        wi, dist, scale, pdf, valid, use, cos_l = rect_light_sample(p, uu, vv, r.corner, r.x, r.y, r.z, r.len_x,
                                                                    r.len_y, self.normal, False)
        scale = scale / pdf_uv * self.profile(cos_l)
        pdf = pdf * pdf_uv
        valid &= scale > 0
        return self._area_where_tiny(p, u, use, wi, dist, scale, pdf, valid)

    def warp_coordinates(self, origin, x):
        """(u, v) ∈ [0, 1]² of the spherical-rectangle parametrisation seen from origin (3, N) at which
        ``rect_sample`` gives the rectangle points x (3, N), and the solid angle Ω (N,)."""
        r = self.rect
        x0, x1, y0, y1, z0, _ = r._local(origin)
        rel = x - origin
        xh = np.clip(dot(rel, r.x[:, None]), x0, x1)
        yh = np.clip(dot(rel, r.y[:, None]), y0, y1)
        with np.errstate(invalid="ignore", divide="ignore"):
            omega = np.nan_to_num(rect_angles(x0, x1, y0, y1, z0)[3])
            part = np.nan_to_num(rect_angles(x0, xh, y0, y1, z0)[3])
            d2 = xh * xh + z0 * z0
            h0 = y0 / np.sqrt(d2 + y0 * y0)
            h1 = y1 / np.sqrt(d2 + y1 * y1)
            hh = yh / np.sqrt(d2 + yh * yh)
            u = np.clip(part / np.where(omega > 0, omega, 1.0), 0.0, 1.0)
            v = np.clip(np.nan_to_num((hh - h0) / (h1 - h0)), 0.0, 1.0)
        return u, v, np.where(z0 < 0, omega, 0.0)

    def pdf_hit(self, dist, cos_l, origin=None, d=None):
        """Solid-angle pdf with which ``sample`` from ``origin`` (3, N) reaches the lamp along d (3, N)
        at distance dist; without them (camera rays) the area-sampling pdf."""
        if self.rect is None or origin is None or d is None:
            return super().pdf_hit(dist, cos_l, origin)
        ok = cos_l > 0
        area = np.where(ok, dist * dist / np.where(ok, cos_l, 1.0) / self.total_area, 0.0)
        u, v, omega = self.warp_coordinates(origin, origin + d * dist)
        use = omega > MIN_RECT_SOLID_ANGLE
        warp = bilinear_warp_pdf(self._corner_profile(origin), u, v)
        return np.where(use, np.where(ok, warp / np.where(use, omega, 1.0), 0.0), area)


def mesh_emitter(spectrum, tris, compiled, two_sided=False, spread_deg=180.0):
    """The emitter of an emissive mesh's triangles: an ``EllipseEmitter`` for a one-sided disk or
    ellipse fan, a ``SpreadRectangleEmitter`` for a one-sided rectangle with a spread, else an
    ``AreaEmitter``."""
    if not two_sided and len(tris) >= EllipseEmitter.MIN_SIDES:
        corners = compiled.vertices[compiled.faces[tris]].astype(np.float64)
        ellipse = EllipseEmitter.fan_ellipse(corners, compiled.tri_normal[tris].astype(np.float64))
        if ellipse is not None:
            return EllipseEmitter(spectrum, tris, compiled, ellipse, spread_deg)
    if not two_sided and len(tris) == 2 and spread_profile(math.radians(spread_deg)) is not None:
        return SpreadRectangleEmitter(spectrum, tris, compiled, False, spread_deg)
    return AreaEmitter(spectrum, tris, compiled, two_sided, spread_deg)


class AreaGroup:
    """The emitters of a light set that ``AreaEmitter.sample`` samples uniformly by area (no rectangle, no spread
    profile, radiance constant over the surface and in direction), their triangles and cdfs concatenated, so that
    next-event estimation samples all of them in one compiled pass (engine.kernels.geometry.area_lights_sample):
    per point exactly its emitter's ``sample``.  ``index`` (lights,): each light's place in the group, −1 outside."""

    def __init__(self, lights):
        members = [i for i, light in enumerate(lights) if self.by_area(light)]
        self.index = np.full(len(lights), -1, np.int64)
        self.index[members] = np.arange(len(members))
        group = [lights[i] for i in members]
        self.compiled = group[0].compiled if group else None
        sizes = [len(light.tris) for light in group]
        self.start = np.concatenate(([0], np.cumsum(sizes))).astype(np.int64)
        self.cdf = np.concatenate([light.cdf for light in group] or [np.zeros(0)]).astype(np.float64)
        self.tris = np.concatenate([light.tris for light in group] or [np.zeros(0, np.int64)]).astype(np.int64)
        self.total_area = np.array([light.total_area for light in group], np.float64)
        self.two_sided = np.array([light.two_sided for light in group], np.bool_)

    @staticmethod
    def by_area(light) -> bool:
        return (isinstance(light, AreaEmitter) and type(light).sample is AreaEmitter.sample and light.rect is None
                and light.profile is None and not light.varies_over_surface
                and not getattr(light, "varies_with_direction", False))

    def sample(self, p: np.ndarray, u: np.ndarray, member: np.ndarray):
        """``sample``'s (wi, dist, scale, pdf, valid) of the points p (3, n) with u (3, n), point i on the group's
        emitter ``member[i]`` (its place in the group, ``index``)."""
        c = self.compiled
        return area_lights_sample(p, u, member, self.cdf, self.start, self.tris, c.faces, c.vertices, c.tri_normal,
                                  self.total_area, self.two_sided)
