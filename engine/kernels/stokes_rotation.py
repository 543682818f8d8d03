"""The Stokes-frame rotation (docs/physics.md §0): the one implementation, NumPy and per path for loops.

A frame for a beam along unit k is a unit x ⟂ k with y = k × x.  Re-expressing a Stokes vector
from frame x to a coaxial frame x′ uses cos φ = x·x′, sin φ = y·x′ and

    S1′ = cos2φ S1 + sin2φ S2,   S2′ = −sin2φ S1 + cos2φ S2,   S0′ = S0, S3′ = S3.

engine.polarisation.frames builds its Mueller rotators on these; the path tracer's throughput
updates (engine.kernels.transport) and next-event estimation use them directly.
"""

from __future__ import annotations

import numpy as np

from . import jit_inner
from ..vec3 import cross, dot


def frame_rotation(x_from: np.ndarray, x_to: np.ndarray, k: np.ndarray):
    """(cos 2φ, sin 2φ) of the passive rotation from frame x_from to x_to about k ((3, ...) each).

    Computed without trigonometric functions; robust when the frames are not exactly coaxial
    (the in-plane components are renormalised); the identity where both are degenerate.
    """
    c = dot(x_from, x_to)
    s = dot(cross(k, x_from), x_to)
    r2 = c * c + s * s
    r2 = np.where(r2 > 0, r2, 1.0)
    return (c * c - s * s) / r2, 2.0 * c * s / r2


def rotate_stokes(S: np.ndarray, c2, s2, in_place: bool = False) -> np.ndarray:
    """Stokes vectors S (P, ...) (components first) re-expressed in the frame rotated by φ, given as
    (cos 2φ, sin 2φ); S itself when P < 3 (nothing to rotate).  A new array unless ``in_place``
    (then S, which may be a view, is overwritten)."""
    if S.shape[0] < 3:
        return S
    s1, s2_old = S[1], S[2]
    if in_place:
        s1, s2_old = s1.copy(), s2_old.copy()
        out = S
    else:
        out = S.copy()
    out[1] = c2 * s1 + s2 * s2_old
    out[2] = -s2 * s1 + c2 * s2_old
    return out


@jit_inner
def frame_rotation_at(x, xt, k, j):
    """(cos 2φ, sin 2φ) of frame_rotation(x, xt, k) for column j of (3, N) arrays, same operation order."""
    c = (x[0, j] * xt[0, j] + x[1, j] * xt[1, j]) + x[2, j] * xt[2, j]
    y0 = k[1, j] * x[2, j] - k[2, j] * x[1, j]
    y1 = k[2, j] * x[0, j] - k[0, j] * x[2, j]
    y2 = k[0, j] * x[1, j] - k[1, j] * x[0, j]
    s = (y0 * xt[0, j] + y1 * xt[1, j]) + y2 * xt[2, j]
    r2 = c * c + s * s
    if not r2 > 0:
        r2 = 1.0
    return (c * c - s * s) / r2, 2.0 * c * s / r2
