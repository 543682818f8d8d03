"""Camera rays and their Stokes output frames.

Perspective (ideal pinhole) and orthographic projections with a box pixel
filter.  For film position (x, y) in pixels (x = col + ξ₁, y = row + ξ₂; row 0
at the top), with f = unit(target − origin), r = unit(f × up), u_cam = r × f
and t = tan(fov/2) along the fov axis:

    d = unit(f + (2x/W − 1 + 2·shift_x)·t_x·r + (1 − 2y/H + 2·shift_y)·t_y·u_cam)

(t_x = t, t_y = t·H/W for fov_axis "x"; the reverse for "y"), the formula of
shared/peers/README.md.  The Stokes frame of each ray is x = unit(d × u_cam)
(image right), y = (−d) × x (image up), light travelling along k = −d
(physics.md §0).
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels.geometry import film_offsets, pinhole_rays
from ..polarisation.frames import camera_ray_frame
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

    def generate(self, pixel: np.ndarray, u: np.ndarray):
        """Rays for flat pixel indices (N,) and jitter u (2, N) in [0, 1).

        Returns (origins (3, N), directions (3, N), stokes frame x (3, N),
        t_min (N,), t_max (N,)).
        """
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
