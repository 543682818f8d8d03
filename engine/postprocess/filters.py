"""Virtual polarisation filters applied to a rendered Stokes image.

A filter is a Mueller matrix F in the image's Stokes frame (x = image right, y = image up, light
travelling towards the camera, docs/physics.md §0); the camera behind it measures intensity only, so
the filtered image is row 0 of F applied to S:  I = F₀₀S0 + F₀₁S1 + F₀₂S2 + F₀₃S3.
Angles are measured like the AoLP: from image right towards image up, in degrees.

- ideal linear polariser at θ (Malus): I = ½(S0 + S1 cos2θ + S2 sin2θ);
- finite extinction: principal transmittances t_max (along the axis) and t_min (across):
  I = ½[(t_max + t_min) S0 + (t_max − t_min)(S1 cos2θ + S2 sin2θ)];
- circular analyser: right ½(S0 + S3), left ½(S0 − S3) (S3 > 0 is right-circular);
- linear retarder (fast axis φ, retardance δ) followed by a linear polariser at θ: row 0 of
  P(θ)·R(φ, δ), e.g. a quarter-wave plate at 45° before a polariser at 0° analyses circular light.
"""

from __future__ import annotations

import math

import numpy as np

FILTER_TYPES = ("linear", "circular-right", "circular-left", "retarder")


def linear_polariser_mueller(angle_deg: float, t_max: float = 1.0, t_min: float = 0.0) -> np.ndarray:
    """4×4 Mueller matrix of a linear polariser with transmission axis at ``angle_deg``."""
    c, s = math.cos(2 * math.radians(angle_deg)), math.sin(2 * math.radians(angle_deg))
    a, b = 0.5 * (t_max + t_min), 0.5 * (t_max - t_min)
    r = math.sqrt(max(t_max * t_min, 0.0))
    return np.array([[a, b * c, b * s, 0.0],
                     [b * c, a * c * c + r * s * s, (a - r) * c * s, 0.0],
                     [b * s, (a - r) * c * s, a * s * s + r * c * c, 0.0],
                     [0.0, 0.0, 0.0, r]])


def linear_retarder_mueller(fast_axis_deg: float, retardance_deg: float) -> np.ndarray:
    """4×4 Mueller matrix of a linear retarder (fast axis angle, retardance δ), optics convention.

    Jones form in the fast-axis frame: diag(1, e^{iδ}) (the slow component is delayed, e^{−iωt}
    fields).  A quarter-wave plate with its fast axis at +45° turns horizontal light (S1 = 1) into
    right-circular light (S3 = +1, S3 = 2 Im(E_x E_y*)) and vertical light into S3 = −1.
    """
    c, s = math.cos(2 * math.radians(fast_axis_deg)), math.sin(2 * math.radians(fast_axis_deg))
    cd, sd = math.cos(math.radians(retardance_deg)), math.sin(math.radians(retardance_deg))
    return np.array([[1.0, 0.0, 0.0, 0.0],
                     [0.0, c * c + s * s * cd, c * s * (1 - cd), -s * sd],
                     [0.0, c * s * (1 - cd), s * s + c * c * cd, c * sd],
                     [0.0, s * sd, -c * sd, cd]])


def filter_row(kind: str = "linear", angle_deg: float = 0.0, extinction: float = 0.0,
               retarder_angle_deg: float = 45.0, retardance_deg: float = 90.0) -> np.ndarray:
    """Row 0 of the filter's Mueller matrix (what an intensity camera behind it sees).

    ``extinction`` = t_min/t_max of the linear polariser (0 = ideal).
    """
    if kind not in FILTER_TYPES:
        raise ValueError(f"filter type must be one of {', '.join(FILTER_TYPES)}, got {kind!r}")
    if not (0.0 <= extinction <= 1.0):
        raise ValueError(f"extinction must be in [0, 1], got {extinction!r}")
    if kind == "circular-right":
        return np.array([0.5, 0.0, 0.0, 0.5])
    if kind == "circular-left":
        return np.array([0.5, 0.0, 0.0, -0.5])
    P = linear_polariser_mueller(angle_deg, 1.0, extinction)
    if kind == "linear":
        return P[0]
    return (P @ linear_retarder_mueller(retarder_angle_deg, retardance_deg))[0]


def apply_filter(stokes: np.ndarray, row: np.ndarray) -> np.ndarray:
    """Filtered intensity image: Σ_i row_i S_i for a Stokes image (4, ...) → (...)."""
    return np.tensordot(np.asarray(row, dtype=np.float64), np.asarray(stokes, dtype=np.float64), axes=(0, 0))


def malus(stokes: np.ndarray, angle_deg: float) -> np.ndarray:
    """Intensity through an ideal linear polariser at ``angle_deg`` (Malus's law)."""
    return apply_filter(stokes, filter_row("linear", angle_deg))


def best_angle(stokes: np.ndarray, minimise: bool = True) -> np.ndarray:
    """Polariser angle (degrees) that minimises (or maximises) the transmitted intensity per pixel."""
    aolp = 0.5 * np.degrees(np.arctan2(stokes[2], stokes[1]))
    return np.mod(aolp + (90.0 if minimise else 0.0) + 90.0, 180.0) - 90.0
