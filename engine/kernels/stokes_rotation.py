"""The Stokes-frame rotation (docs/physics.md §0): the one implementation, NumPy and per path for loops.

A frame for a beam along unit k is a unit x ⟂ k with y = k × x.  Re-expressing a Stokes vector
from frame x to a coaxial frame x′ uses cos φ = x·x′, sin φ = y·x′ and

    S1′ = cos2φ S1 + sin2φ S2,   S2′ = −sin2φ S1 + cos2φ S2,   S0′ = S0, S3′ = S3.

engine.polarisation.frames builds its Mueller rotators on these; the path tracer's throughput
updates (engine.kernels.transport) and next-event estimation use them directly.
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner, twin
from ..vec3 import cross, dot


def frame_rotation(x_from: np.ndarray, x_to: np.ndarray, k: np.ndarray):
    """(cos 2φ, sin 2φ) of the passive rotation from frame x_from to x_to about k ((3, ...) each).

    Computed without trigonometric functions; robust when the frames are not exactly coaxial
    (the in-plane components are renormalised); the identity where both are degenerate.
    """
    c = dot(x_from, x_to)
    s = dot(cross(k, x_from), x_to)
    r2 = c * c + s * s
    zero = r2 == 0
    c = np.where(zero, 1.0, c)                              # degenerate: the identity (cos 2φ, sin 2φ) = (1, 0)
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
    return frame_rotation_of(x[0, j], x[1, j], x[2, j], xt[0, j], xt[1, j], xt[2, j], k[0, j], k[1, j], k[2, j])


@jit_inner
def frame_rotation_of(x0, x1, x2, xt0, xt1, xt2, k0, k1, k2):
    """frame_rotation_at of one frame x, target frame xt and direction k given as numbers."""
    c = (x0 * xt0 + x1 * xt1) + x2 * xt2
    y0 = k1 * x2 - k2 * x1
    y1 = k2 * x0 - k0 * x2
    y2 = k0 * x1 - k1 * x0
    s = (y0 * xt0 + y1 * xt1) + y2 * xt2
    r2 = c * c + s * s
    if r2 == 0:
        return 1.0, 0.0                                     # degenerate: the identity
    if not r2 > 0:
        r2 = 1.0
    return (c * c - s * s) / r2, 2.0 * c * s / r2


# ----------------------------------------------------------------------------- a BSDF's response to unpolarised light

def unpolarised_response_in_frame_numpy(m00, b, x_out, x_T, wo, P):
    """The Stokes vector (P, L, N) that an ABCS Mueller value (M00 = ``m00``, M10 = ``b``, (L, N) each, in frame
    ``x_out``) scatters towards ``wo`` from unpolarised light, re-expressed in the frames ``x_T`` ((3, N) each;
    P ≥ 3): (m00, b, 0, 0) rotated by frame_rotation(x_out, x_T, wo) (rotate_stokes's arithmetic)."""
    S = np.zeros((P,) + np.shape(m00))
    S[0] = m00
    S[1] = b
    return rotate_stokes(S, *frame_rotation(x_out, x_T, wo))


@jit
def _response_in_frame_loop(m00, b, x_out, x_T, wo, out):
    P, L, n = out.shape
    for j in range(n):
        c2, s2 = frame_rotation_at(x_out, x_T, wo, j)
        for q in range(L):
            s1 = b[q, j]
            out[0, q, j] = m00[q, j]
            out[1, q, j] = c2 * s1 + s2 * 0.0         # rotate_stokes of (m00, b, 0, 0): S2 = 0
            out[2, q, j] = -s2 * s1 + c2 * 0.0
            for p in range(3, P):
                out[p, q, j] = 0.0


def unpolarised_response_in_frame_numba(m00, b, x_out, x_T, wo, P):
    L, n = np.shape(m00)
    c = np.ascontiguousarray
    out = np.empty((P, L, n))
    _response_in_frame_loop(c(m00, dtype=np.float64), c(np.broadcast_to(b, (L, n)), dtype=np.float64),
                            *(c(np.broadcast_to(x, (3, n)), dtype=np.float64) for x in (x_out, x_T, wo)), out)
    return out


unpolarised_response_in_frame = twin(_response_in_frame_loop and unpolarised_response_in_frame_numba,
                                     unpolarised_response_in_frame_numpy)
