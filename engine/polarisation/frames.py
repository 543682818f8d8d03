"""Stokes reference frames and their rotation (docs/physics.md §0).

A frame for a beam propagating along unit k is a unit vector x ⟂ k with
y = k × x, so (x, y, k) is right-handed.  Re-expressing a Stokes vector from
frame x to a coaxial frame x′ uses cos φ = x·x′, sin φ = y·x′ and

    S1′ = cos2φ S1 + sin2φ S2,   S2′ = −sin2φ S1 + cos2φ S2,   S0′ = S0, S3′ = S3.

A Mueller matrix M given in frames (in, out) becomes R_out · M · R_inᵀ in
frames (in′, out′).  All vectors are (3, ...) arrays (see engine.vec3).  The rotation itself
(``frame_rotation``, ``rotate_stokes``) is engine.kernels.stokes_rotation, shared with the path
tracer's compiled loops.
"""

from __future__ import annotations

import numpy as np

from ..kernels.geometry import unit_cross
from ..kernels.stokes_rotation import frame_rotation, rotate_stokes
from ..vec3 import cross, dot, normalize

__all__ = ["camera_ray_frame", "frame_rotation", "frame_y", "plane_of_incidence_axis", "rotate_mueller_frames",
           "rotate_stokes", "rotate_stokes_frame", "rotation_mueller", "rotator", "scattering_plane_axis",
           "sp_basis_axis"]

# |n × k| below this is treated as "axis undefined" (normal incidence etc.).
_DEGENERATE = 1e-12


def frame_y(k: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The second frame axis y = k × x."""
    return cross(k, x)


def rotator(cos2phi, sin2phi) -> np.ndarray:
    """Mueller matrix (4, 4, ...) of the frame change with the given cos2φ, sin2φ."""
    c = np.asarray(cos2phi, dtype=np.float64)
    s = np.asarray(sin2phi, dtype=np.float64)
    R = np.zeros((4, 4) + np.broadcast(c, s).shape)
    R[0, 0] = 1.0
    R[3, 3] = 1.0
    R[1, 1] = c
    R[1, 2] = s
    R[2, 1] = -s
    R[2, 2] = c
    return R


def rotation_mueller(x_from, x_to, k) -> np.ndarray:
    """Mueller matrix that re-expresses Stokes vectors from frame x_from to x_to."""
    return rotator(*frame_rotation(x_from, x_to, k))


def rotate_stokes_frame(S: np.ndarray, x_from, x_to, k) -> np.ndarray:
    """Stokes vectors S (4, ...) in frame x_from, re-expressed in frame x_to."""
    return rotate_stokes(np.asarray(S, dtype=np.float64), *frame_rotation(x_from, x_to, k))


def rotate_mueller_frames(M: np.ndarray, x_in, x_in_new, k_in, x_out, x_out_new, k_out) -> np.ndarray:
    """M (4, 4, ...) in frames (x_in, x_out) → the same matrix in (x_in_new, x_out_new)."""
    R_out = rotation_mueller(x_out, x_out_new, k_out)
    R_in = rotation_mueller(x_in, x_in_new, k_in)
    tmp = np.einsum("ij...,jk...->ik...", R_out, M)
    return np.einsum("ij...,kj...->ik...", tmp, R_in)


def plane_of_incidence_axis(n: np.ndarray, k: np.ndarray) -> np.ndarray:
    """s = unit(n × k): the axis ⟂ the plane of incidence (shared by both beams).

    At normal incidence (n ∥ k) an arbitrary vector ⟂ n (engine.vec3.any_perpendicular) is used,
    the same for the incident, reflected and refracted beams (which are all ∥ n there).
    """
    return unit_cross(n, k, _DEGENERATE)


def scattering_plane_axis(k_in: np.ndarray, k_out: np.ndarray) -> np.ndarray:
    """s = unit(k_in × k_out), the normal of the scattering plane; any ⟂ k_in if k_out ∥ k_in."""
    return unit_cross(k_in, k_out, _DEGENERATE)


def camera_ray_frame(d: np.ndarray, up_cam: np.ndarray) -> np.ndarray:
    """Output frame x = unit(d × u_cam) (image right) for camera ray direction d.

    With k = −d (light travelling towards the camera), y = k × x is image up.
    """
    return normalize(cross(d, up_cam))


def sp_basis_axis(k: np.ndarray, normal=(0.0, 0.0, 1.0)) -> np.ndarray:
    """The oracles' `psps` basis: s = unit(z × k), falling back to (0, 1, 0) for k ∥ z."""
    z = np.broadcast_to(np.asarray(normal, dtype=np.float64).reshape((3,) + (1,) * (k.ndim - 1)), k.shape)
    s = cross(z, k)
    length = np.sqrt(dot(s, s))
    ok = length > _DEGENERATE
    fallback = np.broadcast_to(np.array([0.0, 1.0, 0.0]).reshape((3,) + (1,) * (k.ndim - 1)), k.shape)
    return np.where(ok, s / np.where(ok, length, 1.0), fallback)
