"""Point, spot and sun lights (with Cycles' radius, blend and angle options).

Part of engine.render.lights (its package docstring states the light interface)."""

from __future__ import annotations

import math

import numpy as np

from ...kernels import twin
from ...kernels.light_sampling import (SELECT_DISTANT, SELECT_POINT, distant_importance, lamp_hits, point_importance,
                                       point_light_sample_numba, spot_falloff)
from ...materials.sampling import local_to_world
from ...spectral import luminance
from ...vec3 import dot, normalize
from .base import _Light, uniform_cone


def point_light_sample_numpy(p, u, position, radius, soft_falloff, spot):
    """Next-event samples of a point or spot light (``PointEmitter``, ``SpotEmitter``) at p (3, N)
    for u (3, N) (rows 1–2 used): the module docstring's ``sample`` contract.  ``spot`` = [edge kind
    (0: no spot, 1: hard edge, 2: smoothstep), axis (3), cos_outer, cos_inner].  Radius 0: a delta
    light; else a disk facing p (``soft_falloff``) or a sphere."""
    to = position[:, None] - p
    dist2 = dot(to, to)
    dist = np.sqrt(dist2)
    valid = dist > 0
    wi = to / np.where(valid, dist, 1.0)
    # the spot attenuation by the direction of each sampled ray (to the centre for a delta light), as Cycles'
    # spot_light_sample / spot_light_sample_from_intersection (kernel/light/spot.h: spot_light_attenuation of −ls→D)
    def falloff(w):
        return 1.0 if spot[0] == 0 else spot_falloff(w, spot[1:4], spot[4], spot[5])
    if radius <= 0:
        scale = np.where(valid, falloff(wi) / np.where(valid, dist2, 1.0), 0.0)
        return wi, dist, scale, np.zeros(p.shape[1]), valid
    r = radius
    if soft_falloff:
        # disk ⟂ (p − centre), radius r, uniform by area: pdf = t²/(cos·πr²), radiance I/(πr²)
        rho = r * np.sqrt(u[1])
        phi = 2.0 * math.pi * u[2]
        offset = local_to_world(np.stack((rho * np.cos(phi), rho * np.sin(phi), np.zeros_like(rho))), -wi)
        to_s = to + offset
        t2 = dot(to_s, to_s)
        t = np.sqrt(t2)
        w = to_s / np.where(t > 0, t, 1.0)
        cos_l = dot(w, wi)                # the disk's normal is −wi (it faces p)
        valid &= (cos_l > 0) & (t > 0)
        pdf = np.where(valid, t2 / np.where(valid, cos_l * math.pi * r * r, 1.0), 0.0)
        scale = np.where(valid, falloff(w) * cos_l / np.where(valid, t2, 1.0), 0.0)
        return w, t, scale, pdf, valid
    # sphere: uniform cone of half-angle asin(r/d), hit distance by the law of cosines
    valid &= dist > r
    sin2 = np.minimum(r * r / np.where(valid, dist2, 1.0), 1.0)
    one_minus_cos_max = sin2 / (1.0 + np.sqrt(1.0 - sin2))
    w, cos_t = uniform_cone(u[1], u[2], one_minus_cos_max, wi)
    t = dist * cos_t - np.sqrt(np.maximum(r * r - dist2 * (1.0 - cos_t * cos_t), 0.0))
    pdf = np.where(valid, 1.0 / (2.0 * math.pi * np.where(valid, one_minus_cos_max, 1.0)), 0.0)
    scale = np.where(valid, falloff(w) * 2.0 * one_minus_cos_max / (r * r), 0.0)
    return w, np.maximum(t, 0.0), scale, pdf, valid


#: One compiled pass per light where Numba is available (engine.kernels.light_sampling).
point_light_sample = twin(point_light_sample_numba, point_light_sample_numpy)


class PointEmitter(_Light):
    """Isotropic light of radiant intensity I: irradiance I/d² at normal incidence.

    With a radius r > 0 (Cycles, kernel/light/point.h) it is a uniform emitter of radiance
    I/(πr²): a disk of radius r facing the receiver (``soft_falloff``; sampled uniformly by area,
    on-axis irradiance I/(d² + r²)) or a sphere (sampled uniformly in its cone, exactly I/d²
    outside; receivers inside it get no direct light from it).
    """

    def __init__(self, spectrum, position, radius=0.0, soft_falloff=True):
        super().__init__(spectrum)
        self.position = np.asarray(position, np.float64)
        self.radius = float(radius)
        self.soft_falloff = bool(soft_falloff)
        self.is_delta = self.radius <= 0
        self.hittable = not self.is_delta

    def _falloff(self, wi):
        return 1.0

    def intersect(self, o, d, seg, hit, p_ref):
        """Rays o + t·d, 0 < t < seg, that reach the sphere or disk: (rows, radiance factor relative
        to the intensity spectrum (n,), solid-angle pdf of next-event estimation from p_ref (n,)).

        The disk faces the ray origin (Cycles' point_light_intersect); the spot attenuation is that of the
        ray's direction, as next-event estimation's of its sampled rays (Cycles' spot.h)."""
        r = self.radius
        c = self.position[:, None]
        ok, t, cos_l = lamp_hits(o, d, seg, self.position, r, self.soft_falloff)
        rows = ok.nonzero()[0]
        if rows.size == 0:
            return rows, np.zeros(0), np.zeros(0)
        factor = self._falloff(d[:, rows]) / (math.pi * r * r) * np.ones(rows.size)
        q = p_ref[:, rows] if p_ref is not None else o[:, rows]
        if self.soft_falloff:
            pdf = t[rows] ** 2 / (cos_l[rows] * math.pi * r * r)
        else:
            to = c - q
            sin2 = np.minimum(r * r / np.maximum(dot(to, to), r * r), 1.0)
            pdf = 1.0 / (2.0 * math.pi * (sin2 / (1.0 + np.sqrt(1.0 - sin2))))
        return rows, factor, pdf

    def sample(self, p, u):
        # u has 3 rows: the first (light choice) is unused, then the point on the disk or in the cone
        spot = getattr(self, "spot_record", None)
        return point_light_sample(p, u, self.position, self.radius, self.soft_falloff,
                                  np.zeros(6) if spot is None else np.array(spot))

    def power(self):
        return 4.0 * math.pi * float(luminance(self.rgb()))

    def selection_record(self):
        spot = getattr(self, "spot_record", [0.0] * 6)
        return SELECT_POINT, [*self.position, float(luminance(self.rgb())), max(self.radius ** 2, 1e-12), self.radius,
                              *spot]

    def importance(self, p, n=None):
        """Irradiance at p (3, N) facing the light, I·falloff/max(d², r²), times the orientation term."""
        _, row = self.selection_record()
        spot = None if row[6] == 0 else (np.array(row[7:10]), row[10], row[11])
        return point_importance(p, n, self.position, row[3], row[4], row[5], spot)


class SpotEmitter(PointEmitter):
    """Point light restricted to a cone; ``blend`` smooths the edge (smoothstep in cos angle).

    Profile "angle": the edge runs from cos(half) to cos(half·(1 − blend)); profile "cycles"
    (kernel/light/spot.h: spot_light_attenuation): from cos(half) to cos(half) + blend·(1 − cos(half)).
    """

    def __init__(self, spectrum, position, direction, cone_angle_deg, blend, blend_profile="angle",
                 radius=0.0, soft_falloff=True):
        super().__init__(spectrum, position, radius, soft_falloff)
        self.axis = normalize(np.asarray(direction, np.float64))
        half = math.radians(cone_angle_deg) / 2
        self.cos_outer = math.cos(half)
        if blend_profile == "cycles":
            self.cos_inner = min(1.0, self.cos_outer + blend * (1.0 - self.cos_outer))
        else:
            self.cos_inner = math.cos(half * (1.0 - blend))

    def power(self):
        return 2.0 * math.pi * (1.0 - self.cos_outer) * float(luminance(self.rgb()))

    def _falloff(self, wi):
        return spot_falloff(wi, self.axis, self.cos_outer, self.cos_inner)

    @property
    def spot_record(self):
        """[edge kind (1 hard, 2 smooth), axis, cos_outer, cos_inner] (SELECT_POINT's spot columns)."""
        return [1.0 if self.cos_inner <= self.cos_outer else 2.0, *self.axis, self.cos_outer, self.cos_inner]


class DirectionalEmitter(_Light):
    """Parallel light (sun) travelling along ``direction`` with irradiance E ⟂ to it.

    With an angular diameter > 0 (Cycles' sun angle, kernel/light/distant.h) it is a disc of
    uniform radiance E/(π sin²θh), θh = angle/2, sampled uniformly in its cone (soft shadows,
    the same irradiance E on a surface facing it).
    """

    at_infinity = True

    def __init__(self, spectrum, direction, angle_deg=0.0):
        super().__init__(spectrum)
        self.direction = normalize(np.asarray(direction, np.float64))
        half = 0.5 * math.radians(angle_deg)
        self.is_delta = half <= 0
        self.hittable = not self.is_delta
        self.one_minus_cos = 2.0 * math.sin(0.5 * half) ** 2
        # radiance / E divided by the cone pdf: 2π(1 − cosθh) / (π sin²θh)
        self.factor = 2.0 * self.one_minus_cos / math.sin(half) ** 2 if half > 0 else 1.0
        self.radiance_factor = 1.0 / (math.pi * math.sin(half) ** 2) if half > 0 else 0.0

    def intersect(self, o, d, seg, hit, p_ref):
        """Rays that escape (not ``hit``) within the sun's disc: (rows, radiance/E, cone pdf);
        Cycles' integrate_distant_lights."""
        rows = (~hit & (1.0 - dot(d, -self.direction[:, None]) <= self.one_minus_cos)).nonzero()[0]
        return (rows, np.full(rows.size, self.radiance_factor),
                np.full(rows.size, 1.0 / (2.0 * math.pi * self.one_minus_cos)))

    def sample(self, p, u):
        n = p.shape[1]
        if self.is_delta:
            wi = np.broadcast_to(-self.direction[:, None], (3, n)).copy()
            return wi, np.full(n, np.inf), np.ones(n), np.zeros(n), np.ones(n, bool)
        wi, _ = uniform_cone(u[1], u[2], self.one_minus_cos, -self.direction)
        return (wi, np.full(n, np.inf), np.full(n, self.factor),
                np.full(n, 1.0 / (2.0 * math.pi * self.one_minus_cos)), np.ones(n, bool))

    def power(self, scene_radius=1.0):
        return float(luminance(self.rgb())) * math.pi * scene_radius ** 2

    def selection_record(self):
        sin_half = math.sqrt(self.one_minus_cos * (2.0 - self.one_minus_cos))
        return SELECT_DISTANT, [*(-self.direction), float(luminance(self.rgb())), sin_half]

    def importance(self, p, n=None):
        _, row = self.selection_record()
        return distant_importance(p, n, -self.direction, row[3], row[4])
