"""Camera rays and their Stokes output frames.

Perspective (ideal pinhole) and orthographic projections with a box pixel
filter.  For film position (x, y) in pixels (x = col + ξ₁, y = row + ξ₂; row 0
at the top), with f = unit(target − origin), r = unit(f × up), u_cam = r × f
and t = tan(fov/2) along the fov axis:

    d = unit(f + (2x/W − 1 + 2·shift_x)·t_x·r + (1 − 2y/H + 2·shift_y)·t_y·u_cam)

(t_x = t, t_y = t·H/W for fov_axis "x"; the reverse for "y"), the formula of
shared/peers/README.md.  The Stokes frame of each ray is x = unit(d × u_cam)
(image right), y = (−d) × x (image up), light travelling along k = −d
(docs/physics.md §0).

Thin lens (Cycles' ``camera_sample_perspective``): the pinhole ray's point on the focus plane
(depth ``focus_distance``) stays fixed and the origin moves to a point of the aperture (radius R,
disk or regular polygon) in the plane ⟂ f through the origin, so points at the focus depth are
sharp and a point at depth z blurs into a circle of confusion of diameter 2R·|z − F|/z on the
focus plane.  Orthographic: the ray keeps f and its film point, and is aimed at the film point
moved to the focus depth.

Equirectangular (Cycles' ``equirectangular_range_to_direction``): longitude ψ (positive towards
r, 0 = f) runs left → right over ``longitude_deg``, latitude λ bottom → top over
``latitude_deg``; d = cos λ (sin ψ r + cos ψ f) + sin λ u_cam.  Its Stokes frame is
x = cos ψ r − sin ψ f = ∂d/∂ψ normalised (increasing longitude, image right), which equals
unit(d × u_cam) wherever that is defined and stays defined at the poles (λ = ±90°), where each
pixel keeps the frame of its own longitude; y = (−d) × x (image up, increasing latitude).
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels.geometry import film_offsets, pinhole_rays
from ..polarisation.frames import camera_ray_frame
from .. import vec3
from ..scene.description import Camera


class CameraModel:
    def __init__(self, cam: Camera):
        self.cam = cam
        o = np.asarray(cam.origin, np.float64)
        f = np.asarray(cam.target, np.float64) - o
        f /= np.linalg.norm(f)
        r = np.cross(f, cam.up)
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        self.origin, self.forward, self.right, self.up = o, f, r, u
        W, H = cam.width, cam.height
        if cam.projection == "perspective":
            t = math.tan(math.radians(cam.fov_deg) / 2)
            self.tx, self.ty = (t, t * H / W) if cam.fov_axis == "x" else (t * W / H, t)
        else:
            half_w = cam.ortho_width / 2
            self.tx, self.ty = half_w, half_w * H / W
        # Lens shift is measured in units of the larger image side (as Blender's).
        side = max(W, H)
        self.shift_x = cam.shift[0] * side / W
        self.shift_y = cam.shift[1] * side / H

    @property
    def lens_dimensions(self) -> int:
        """Random numbers the camera needs per ray besides the pixel jitter (2 for a thin lens)."""
        return 2 if self.cam.aperture_radius > 0 else 0

    def generate(self, pixel: np.ndarray, u: np.ndarray):
        """Rays for flat pixel indices (N,) and jitter u (2, N) in [0, 1) (plus, for a thin lens,
        the lens sample u[2:4]).

        Returns (origins (3, N), directions (3, N), stokes frame x (3, N),
        t_min (N,), t_max (N,)).
        """
        if self.cam.projection == "equirectangular" or self.cam.aperture_radius > 0:
            return self._panorama_or_thin_lens(pixel, u)

        W, H = self.cam.width, self.cam.height
        if self.cam.projection == "perspective":
            d, x, depth_per_length = pinhole_rays(pixel, u, W, H, self.shift_x, self.shift_y, self.tx, self.ty,
                                                  self.forward, self.right, self.up)
            o = np.broadcast_to(self.origin[:, None], d.shape).copy()
        else:
            sx, sy = film_offsets(pixel, u, W, H, self.shift_x, self.shift_y, self.tx, self.ty)
            d = np.broadcast_to(self.forward[:, None], (3, pixel.shape[0])).copy()
            o = self.origin[:, None] + sx * self.right[:, None] + sy * self.up[:, None]
            x = camera_ray_frame(d, self.up[:, None])
            depth_per_length = d[0] * self.forward[0] + d[1] * self.forward[1] + d[2] * self.forward[2]
        # Clip planes are depths along the viewing axis (as in Blender), not ray lengths.
        return o, d, x, self.cam.clip_start / depth_per_length, self.cam.clip_end / depth_per_length

    # ------------------------------------------------------------------ thin lens and panorama

    def _panorama_or_thin_lens(self, pixel: np.ndarray, u: np.ndarray):
        if self.cam.projection == "equirectangular":
            return self._equirectangular(pixel, u)
        return self._thin_lens(pixel, u)

    def _film_offsets(self, pixel: np.ndarray, u: np.ndarray):
        """(sx, sy): the film point in units of r and u_cam (tan for perspective, length for ortho)."""
        W, H = self.cam.width, self.cam.height
        col = pixel % W
        row = pixel // W
        sx = (2.0 * (col + u[0]) / W - 1.0 + 2.0 * self.shift_x) * self.tx
        sy = (1.0 - 2.0 * (row + u[1]) / H + 2.0 * self.shift_y) * self.ty
        return sx, sy

    def _thin_lens(self, pixel: np.ndarray, u: np.ndarray):
        cam = self.cam
        sx, sy = self._film_offsets(pixel, u)
        bx, by = aperture_sample(u[2], u[3], cam.aperture_blades, math.radians(cam.aperture_rotation_deg))
        bx = bx / cam.aperture_ratio
        r, up, f = self.right[:, None], self.up[:, None], self.forward[:, None]
        lens = cam.aperture_radius * (bx * r + by * up)
        F = cam.focus_distance
        if cam.projection == "perspective":
            # the pinhole ray through this film point meets the focus plane (depth F) at origin + F·(f + s)
            focus = F * (f + sx * r + sy * up)
            d = vec3.normalize(focus - lens)
            o = self.origin[:, None] + lens
        else:
            film = sx * r + sy * up
            d = vec3.normalize(F * f - lens)
            o = self.origin[:, None] + film + lens
        x = camera_ray_frame(d, up)
        # Clip planes are depths along the viewing axis; the lens lies in the depth-0 plane.
        depth_per_length = d[0] * self.forward[0] + d[1] * self.forward[1] + d[2] * self.forward[2]
        return o, d, x, cam.clip_start / depth_per_length, cam.clip_end / depth_per_length

    def _equirectangular(self, pixel: np.ndarray, u: np.ndarray):
        cam = self.cam
        W, H = cam.width, cam.height
        col = pixel % W
        row = pixel // W
        lon0, lon1 = (math.radians(a) for a in cam.longitude_deg)
        lat0, lat1 = (math.radians(a) for a in cam.latitude_deg)
        psi = lon0 + (col + u[0]) / W * (lon1 - lon0)
        lam = lat0 + (1.0 - (row + u[1]) / H) * (lat1 - lat0)       # row 0 = top = lat_max
        d, x = equirectangular_rays(psi, lam, self.forward, self.right, self.up)
        o = np.broadcast_to(self.origin[:, None], d.shape).copy()
        if cam.aperture_radius > 0:
            # Cycles' panorama lens: a disk ⟂ d aimed at the focus SPHERE of radius F.
            bx, by = aperture_sample(u[2], u[3], cam.aperture_blades, math.radians(cam.aperture_rotation_deg))
            lens = cam.aperture_radius * (bx / cam.aperture_ratio * x + by * vec3.cross(x, -d))
            d_new = vec3.normalize(cam.focus_distance * d - lens)
            o = o + lens
            d = d_new
            x = vec3.normalize(vec3.cross(d, vec3.cross(x, d)))      # re-orthogonalised ⟂ the new d, still ≈ ∂d/∂ψ
        n = pixel.shape[0]
        return o, d, x, np.full(n, cam.clip_start), np.full(n, cam.clip_end)


def equirectangular_rays(psi: np.ndarray, lam: np.ndarray, forward: np.ndarray, right: np.ndarray,
                         up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Directions d (3, N) for longitude ψ (towards ``right``) and latitude λ (towards ``up``), radians,
    and their Stokes frames x = cos ψ r − sin ψ f (continuous in ψ, defined at the poles)."""
    cl, sl = np.cos(lam), np.sin(lam)
    cp, sp = np.cos(psi), np.sin(psi)
    f, r, u = forward[:, None], right[:, None], up[:, None]
    d = cl * (sp * r + cp * f) + sl * u
    x = cp * r - sp * f
    return d, x


def aperture_sample(u1: np.ndarray, u2: np.ndarray, blades: int, rotation: float) -> tuple[np.ndarray, np.ndarray]:
    """Uniform points (bx, by) on the unit disk (blades < 3) or on the regular ``blades``-gon inscribed
    in it with an edge midpoint at angle ``rotation`` (Cycles' bokeh shapes), from u1, u2 in [0, 1)."""
    if blades < 3:
        # concentric (Shirley–Chiu) map: uniform, continuous
        a = 2.0 * u1 - 1.0
        b = 2.0 * u2 - 1.0
        use_a = np.abs(a) > np.abs(b)
        radius = np.where(use_a, a, b)
        safe_a = np.where(a == 0, 1.0, a)
        safe_b = np.where(b == 0, 1.0, b)
        phi = np.where(use_a, (math.pi / 4) * (b / safe_a), math.pi / 2 - (math.pi / 4) * (a / safe_b))
        phi = np.where((a == 0) & (b == 0), 0.0, phi)
        return radius * np.cos(phi), radius * np.sin(phi)
    # Pick a wedge (equal areas), then a uniform point in the triangle (centre, v_k, v_k+1).
    k = np.minimum((u1 * blades).astype(np.int64), blades - 1)
    v = u1 * blades - k                        # reuse the fraction: uniform in [0, 1)
    half = math.pi / blades
    a0 = rotation - half + 2.0 * half * k      # wedge k spans rotation + 2πk/N ± π/N
    a1 = a0 + 2.0 * half
    s = np.sqrt(v)                             # uniform triangle: P = s·((1 − t)·v0 + t·v1)
    t = u2
    bx = s * ((1.0 - t) * np.cos(a0) + t * np.cos(a1))
    by = s * ((1.0 - t) * np.sin(a0) + t * np.sin(a1))
    return bx, by
