"""Division-of-focal-plane polarisation camera: a 2×2 mosaic of micro-polarisers over the pixels.

Each pixel sees the scene through a linear polariser whose angle depends on (row mod 2, column
mod 2).  The default layout is that of common polarisation sensors (e.g. Sony IMX250MZR):

    row 0 (top of the image):  90°   45°
    row 1:                    135°    0°

Angles are measured like the AoLP: from image right towards image up (docs/physics.md, Conventions), so a
0° pixel passes horizontal light, I(θ) = ½[(t_max + t_min)S0 + (t_max − t_min)(S1 cos2θ + S2 sin2θ)]
with t_max = 1, t_min = the extinction ratio (engine.postprocess.filters).

Demosaicing (:func:`demosaic`) uses the standard formulas on bilinearly interpolated intensities:
S0 = (I0 + I45 + I90 + I135)/2, S1 = I0 − I90, S2 = I45 − I135 (per colour channel).
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from .filters import apply_filter, filter_row

#: Micro-polariser angles in degrees, [row][column] of each 2×2 cell, row 0 at the top of the image.
DEFAULT_LAYOUT = ((90.0, 45.0), (135.0, 0.0))
#: The four angles demosaicing needs, one per cell position.
DEMOSAIC_ANGLES = (0.0, 45.0, 90.0, 135.0)


def parse_layout(layout, field: str = "mosaic.layout") -> tuple:
    """A 2×2 layout from [[a, b], [c, d]] or four numbers (row 0 first); angles in degrees."""
    try:
        flat = [float(v) for v in np.asarray(layout, dtype=float).ravel()]
    except (TypeError, ValueError):
        raise SceneError(field, f"must be four angles in degrees (row 0 left, row 0 right, row 1 left, "
                                f"row 1 right), got {layout!r}") from None
    if len(flat) != 4 or not all(np.isfinite(flat)):
        raise SceneError(field, f"must be four finite angles in degrees, got {layout!r}")
    return ((flat[0], flat[1]), (flat[2], flat[3]))


def angle_map(height: int, width: int, layout=DEFAULT_LAYOUT, origin=(0, 0)) -> np.ndarray:
    """(H, W) polariser angle of every pixel in degrees (row 0 = top of the image).

    ``origin`` = (row, column) of this image's top-left pixel on the sensor (for crops and tiles)."""
    cell = np.asarray(parse_layout(layout), dtype=float)
    rows = (np.arange(height) + origin[0]) % 2
    cols = (np.arange(width) + origin[1]) % 2
    return cell[rows[:, None], cols[None, :]]


def mosaic(stokes: np.ndarray, layout=DEFAULT_LAYOUT, extinction: float = 0.0, origin=(0, 0)) -> np.ndarray:
    """Raw sensor image: each pixel's intensity behind its micro-polariser.

    ``stokes`` (4, H, W) or (4, H, W, C) in the image Stokes frame → (H, W) or (H, W, C).
    ``extinction`` = t_min/t_max of the micro-polarisers (0 = ideal).  ``origin`` = (row, column)
    of the image's top-left pixel on the sensor, so that a crop (border render) keeps the pattern.
    """
    if not (0.0 <= extinction <= 1.0):
        raise SceneError("mosaic.extinction", f"must be in [0, 1], got {extinction!r}")
    stokes = np.asarray(stokes, dtype=np.float64)
    cell = parse_layout(layout)
    out = np.empty(stokes.shape[1:], dtype=np.float64)
    for r in range(2):
        for c in range(2):
            row = filter_row("linear", cell[(r + origin[0]) % 2][(c + origin[1]) % 2], extinction)
            out[r::2, c::2] = apply_filter(stokes[:, r::2, c::2], row)
    return out


def _neighbour_sum(a: np.ndarray) -> np.ndarray:
    """3×3 sum with bilinear weights [[¼, ½, ¼], [½, 1, ½], [¼, ½, ¼]] over axes 0 and 1 (zero outside)."""
    p = np.pad(a, [(1, 1), (1, 1)] + [(0, 0)] * (a.ndim - 2))
    h, w = a.shape[:2]
    out = np.zeros_like(a)
    for dy, wy in ((0, 0.5), (1, 1.0), (2, 0.5)):
        for dx, wx in ((0, 0.5), (1, 1.0), (2, 0.5)):
            out += wy * wx * p[dy:dy + h, dx:dx + w]
    return out


def interpolate_angle(raw: np.ndarray, row: int, col: int) -> np.ndarray:
    """Full-resolution image of the pixels at cell position (row, col), bilinearly interpolated.

    Inside the image this is the standard bilinear demosaic (the same kernel as for Bayer red and
    blue); at the border the weights are renormalised over the samples that exist.
    """
    raw = np.asarray(raw, dtype=np.float64)
    mask = np.zeros(raw.shape[:2])
    mask[row::2, col::2] = 1.0
    mask_b = mask.reshape(mask.shape + (1,) * (raw.ndim - 2))
    return _neighbour_sum(raw * mask_b) / _neighbour_sum(mask_b * np.ones_like(raw))


def demosaic(raw: np.ndarray, layout=DEFAULT_LAYOUT) -> dict:
    """{angle: full-resolution intensity} for the four angles of the layout."""
    cell = parse_layout(layout)
    return {cell[r][c]: interpolate_angle(raw, r, c) for r in range(2) for c in range(2)}


def stokes_from_mosaic(raw: np.ndarray, layout=DEFAULT_LAYOUT, extinction: float = 0.0) -> np.ndarray:
    """(3, ...) linear Stokes S0, S1, S2 from a raw mosaic by the standard formulas.

    The layout must hold 0°, 45°, 90° and 135° (mod 180°).  With a known ``extinction`` ε the
    estimates are divided by (1 + ε) (S0) and (1 − ε) (S1, S2); with ε = 0 this is exactly
    S0 = (I0 + I45 + I90 + I135)/2, S1 = I0 − I90, S2 = I45 − I135.
    """
    cell = parse_layout(layout)
    by_angle = {round(a % 180.0, 9): a for row in cell for a in row}
    if sorted(by_angle) != list(DEMOSAIC_ANGLES):
        raise SceneError("mosaic.layout", f"demosaicing needs the angles 0, 45, 90 and 135 degrees once "
                                          f"each, got {[list(r) for r in cell]}")
    if not (0.0 <= extinction < 1.0):
        raise SceneError("mosaic.extinction", f"must be in [0, 1) to recover S1 and S2, got {extinction!r}")
    images = demosaic(raw, cell)
    i0, i45, i90, i135 = (images[by_angle[a]] for a in DEMOSAIC_ANGLES)
    s0 = (i0 + i45 + i90 + i135) / 2 / (1.0 + extinction)
    s1 = (i0 - i90) / (1.0 - extinction)
    s2 = (i45 - i135) / (1.0 - extinction)
    return np.stack([s0, s1, s2])
