"""Display encodings: sRGB transfer, tone mapping and false-colour maps.

All functions are vectorised over arbitrary leading shapes and return uint8
sRGB-encoded colours with a trailing axis of 3 (except :func:`srgb_encode`,
which returns floats).  NaN inputs to the false-colour maps give neutral
grey :data:`NAN_GREY`, so "no data" is distinguishable from any map value.
"""

from __future__ import annotations

import numpy as np

NAN_GREY = np.array([128, 128, 128], dtype=np.uint8)

# ColorBrewer RdBu (11 classes), ordered blue (-1) -> red (+1), with the
# centre #f7f7f7 replaced by pure white so that 0 (unpolarised) is white.
_DIVERGING = np.array([
    (0x05, 0x30, 0x61), (0x21, 0x66, 0xAC), (0x43, 0x93, 0xC3), (0x92, 0xC5, 0xDE),
    (0xD1, 0xE5, 0xF0), (0xFF, 0xFF, 0xFF), (0xFD, 0xDB, 0xC7), (0xF4, 0xA5, 0x82),
    (0xD6, 0x60, 0x4D), (0xB2, 0x18, 0x2B), (0x67, 0x00, 0x1F),
], dtype=np.float64)

# viridis sampled at 9 evenly spaced points (0 -> dark purple, 1 -> yellow).
_VIRIDIS = np.array([
    (0x44, 0x01, 0x54), (0x47, 0x2D, 0x7B), (0x3B, 0x52, 0x8B), (0x2C, 0x72, 0x8E),
    (0x21, 0x90, 0x8C), (0x27, 0xAD, 0x81), (0x5D, 0xC8, 0x63), (0xAA, 0xDC, 0x32),
    (0xFD, 0xE7, 0x25),
], dtype=np.float64)


def srgb_encode(linear) -> np.ndarray:
    """sRGB OETF (IEC 61966-2-1) of linear values clipped to [0, 1]; float64 in [0, 1]."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def tonemap(rgb_linear, exposure: float = 0.0) -> np.ndarray:
    """Linear radiance → uint8 sRGB: scale by 2**exposure (stops), clip to [0, 1], encode.

    NaN becomes 0 (black).  Shape is preserved.
    """
    x = np.nan_to_num(np.asarray(rgb_linear, dtype=np.float64), nan=0.0) * 2.0 ** exposure
    return np.round(255.0 * srgb_encode(x)).astype(np.uint8)


def _ramp(t, table: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation of ``table`` rows at t ∈ [0, 1] (clipped); NaN → grey."""
    t = np.asarray(t, dtype=np.float64)
    nan = np.isnan(t)
    pos = np.clip(np.where(nan, 0.0, t), 0.0, 1.0) * (len(table) - 1)
    i = np.minimum(pos.astype(np.intp), len(table) - 2)
    f = (pos - i)[..., None]
    rgb = np.round(table[i] * (1.0 - f) + table[i + 1] * f).astype(np.uint8)
    rgb[nan] = NAN_GREY
    return rgb


def diverging(v) -> np.ndarray:
    """Signed quantity v ∈ [−1, 1] → uint8 RGB: dark blue (−1) → white (0) → dark red (+1).

    ColorBrewer RdBu control points; values outside [−1, 1] are clipped.
    """
    return _ramp((np.asarray(v, dtype=np.float64) + 1.0) / 2.0, _DIVERGING)


def sequential(v) -> np.ndarray:
    """Magnitude v ∈ [0, 1] → uint8 RGB along viridis (0 dark purple, 1 yellow); clipped."""
    return _ramp(v, _VIRIDIS)


def hue_saturation(aolp, dolp) -> np.ndarray:
    """AoLP (radians) as hue with period π, DoLP ∈ [0, 1] as HSV saturation, value 1.

    Hue = (AoLP mod π)/π of the colour circle: 0 (horizontal, along image
    right) red, π/6 yellow, π/3 green, ±π/2 (vertical) cyan, −π/3 blue,
    −π/6 magenta.  DoLP 0 gives white whatever the angle.  NaN in either → grey.
    """
    a = np.asarray(aolp, dtype=np.float64)
    s = np.asarray(dolp, dtype=np.float64)
    a, s = np.broadcast_arrays(a, s)
    nan = np.isnan(a) | np.isnan(s)
    h6 = np.mod(np.where(nan, 0.0, a), np.pi) / np.pi * 6.0
    s = np.clip(np.where(nan, 0.0, s), 0.0, 1.0)
    # HSV → RGB with V = 1: channel n has k = (n + 6h) mod 6, value 1 − s·clip(min(k, 4 − k), 0, 1).
    n = np.array([5.0, 3.0, 1.0])
    k = np.mod(n + h6[..., None], 6.0)
    rgb = 1.0 - s[..., None] * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)
    out = np.round(255.0 * rgb).astype(np.uint8)
    out[nan] = NAN_GREY
    return out
