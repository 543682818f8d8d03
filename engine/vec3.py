"""3-vector algebra on structure-of-arrays batches.

Vectors are arrays of shape (3, ...) — the component on the *first* axis — so
that a batch of N directions is (3, N) and every component is a contiguous
row.  The whole engine uses this layout (Stokes (4, ...), Mueller (4, 4, ...)).
"""

from __future__ import annotations

import numpy as np


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched dot product a·b, shape (...)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched cross product a × b, shape (3, ...)."""
    return np.stack((a[1] * b[2] - a[2] * b[1],
                     a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]))


def norm(a: np.ndarray) -> np.ndarray:
    return np.sqrt(dot(a, a))


def normalize(a: np.ndarray) -> np.ndarray:
    """a/|a|; zero vectors stay zero (no NaN)."""
    n = norm(a)
    return a / np.where(n > 0, n, 1.0)


def as_soa(v, dtype=np.float64) -> np.ndarray:
    """A (3,) vector or an (N, 3) list of vectors as a (3, N) / (3,) array."""
    v = np.asarray(v, dtype=dtype)
    return v.T if v.ndim == 2 else v


def any_perpendicular(n: np.ndarray) -> np.ndarray:
    """A unit vector ⟂ the unit vector n (Duff et al. 2017, branchless).

    Deterministic and continuous except across n_z = 0; used wherever a frame
    axis is undefined (normal incidence, forward/backward scattering) and the
    physics is invariant to the choice.
    """
    sign = np.where(n[2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    return np.stack((1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]))


def local_frame(n: np.ndarray):
    """Tangents (t, b) with (t, b, n) a right-handed orthonormal basis for unit n (3, ...):
    t = any_perpendicular(n), b = n × t.  Every local shading frame of the engine is this one."""
    t = any_perpendicular(n)
    return t, cross(n, t)


def to_local(w: np.ndarray, t: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Components (w·t, w·b, w·n) (3, ...) of w in the basis (t, b, n) of ``local_frame``."""
    return np.stack((dot(w, t), dot(w, b), dot(w, n)))


def reflect(w: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror direction of w about n (both pointing away from the surface)."""
    return 2.0 * dot(w, n) * n - w
