"""Derived polarisation quantities of Stokes vectors.

Convention (docs/physics.md §0): S = (S0, S1, S2, S3) with S1 > 0 along the frame's
x axis, S2 > 0 along (x + y)/√2 and S3 = 2 Im(E_x E_y*) (> 0: right-circular,
optics convention).  Stokes vectors are arrays whose *first* axis has length 4
(``S[0]`` is S0), so images of shape (4, H, W) and batches of shape (4, N)
work alike.

Where S0 = 0 the ratios are defined as 0 (an unlit pixel is unpolarised).
"""

from __future__ import annotations

import numpy as np


def _ratio(num: np.ndarray, s0: np.ndarray) -> np.ndarray:
    num = np.asarray(num, dtype=np.float64)
    s0 = np.asarray(s0, dtype=np.float64)
    out = np.zeros(np.broadcast(num, s0).shape)
    np.divide(num, s0, out=out, where=s0 > 0)
    return out


def degree_of_polarisation(S: np.ndarray) -> np.ndarray:
    """DoP = √(S1² + S2² + S3²) / S0 (dimensionless, 0 where S0 = 0)."""
    return _ratio(np.sqrt(S[1] ** 2 + S[2] ** 2 + S[3] ** 2), S[0])


def degree_of_linear_polarisation(S: np.ndarray) -> np.ndarray:
    """DoLP = √(S1² + S2²) / S0."""
    return _ratio(np.hypot(S[1], S[2]), S[0])


def degree_of_circular_polarisation(S: np.ndarray) -> np.ndarray:
    """DoCP = S3 / S0, *signed* (> 0 right-circular, optics convention)."""
    return _ratio(S[3], S[0])


def angle_of_linear_polarisation(S: np.ndarray) -> np.ndarray:
    """AoLP = ½ atan2(S2, S1) in radians, in (−π/2, π/2].

    Measured from the frame's x axis towards its y axis; for camera images
    that is from image-right towards image-up.  0 where S1 = S2 = 0.
    """
    return 0.5 * np.arctan2(np.asarray(S[2], np.float64), np.asarray(S[1], np.float64))


def unpolarised(intensity) -> np.ndarray:
    """Stokes vector(s) (I, 0, 0, 0) of unpolarised light, shape (4, ...)."""
    intensity = np.asarray(intensity, dtype=np.float64)
    out = np.zeros((4,) + intensity.shape)
    out[0] = intensity
    return out


def linear_polariser_intensity(S: np.ndarray, angle_rad) -> np.ndarray:
    """Intensity through an ideal linear polariser (Malus): ½(S0 + S1 cos2θ + S2 sin2θ).

    θ is the transmission axis measured like the AoLP.
    """
    return 0.5 * (S[0] + S[1] * np.cos(2 * angle_rad) + S[2] * np.sin(2 * angle_rad))
