"""Direction sampling warps shared by the material models (batched, (3, N) layout)."""

from __future__ import annotations

import numpy as np

from ..vec3 import local_frame


def cosine_hemisphere(u: np.ndarray) -> np.ndarray:
    """Cosine-weighted directions about +z from u (2, N) (concentric disk map); pdf = z/π."""
    a = 2.0 * u[0] - 1.0
    b = 2.0 * u[1] - 1.0
    use_a = np.abs(a) > np.abs(b)
    safe_a = np.where(a == 0, 1.0, a)
    safe_b = np.where(b == 0, 1.0, b)
    r = np.where(use_a, a, b)
    phi = np.where(use_a, (np.pi / 4) * (b / safe_a), np.pi / 2 - (np.pi / 4) * (a / safe_b))
    x = r * np.cos(phi)
    y = r * np.sin(phi)
    z = np.sqrt(np.maximum(1.0 - x * x - y * y, 0.0))
    return np.stack((x, y, z))


def uniform_sphere(u: np.ndarray) -> np.ndarray:
    """Uniform directions on the unit sphere from u (2, N); pdf = 1/(4π)."""
    z = 1.0 - 2.0 * u[0]
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = 2.0 * np.pi * u[1]
    return np.stack((r * np.cos(phi), r * np.sin(phi), z))


def local_to_world(v: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Map v (3, N) given in a frame with +z = n (3, N) to world space."""
    t, b = local_frame(n)
    return t * v[0] + b * v[1] + n * v[2]
