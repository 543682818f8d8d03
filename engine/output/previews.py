"""False-colour PNG previews of a Stokes image, each with a legend strip.

Every preview is the H×W image with an 8-pixel legend bar appended below it
(so the PNG is (H + 8)×W).  The bar runs left → right through the preview's
colour map from its minimum to its maximum value; dark tick marks in the
bar's lower half mark the minimum (left column), the centre and the maximum
(right column).  Pixels where the luminance S0 is 0 (no light, so no
polarisation information) are neutral grey in the polarisation previews.
"""

from __future__ import annotations

import os

import numpy as np

from . import check_stokes_image, luminance_stokes
from .colormaps import diverging, hue_saturation, sequential, tonemap
from .png import write_png
from ..polarisation import stokes as st

LEGEND_HEIGHT = 8
_TICK_COLOUR = np.array([0, 0, 0], dtype=np.uint8)


def legend_bar(colours: np.ndarray) -> np.ndarray:
    """Legend strip (LEGEND_HEIGHT, W, 3) from one row of W colours (min at left, max at right).

    Ticks (3 px tall, dark) are drawn in the bottom rows at columns 0, (W−1)//2 and W−1.
    """
    bar = np.repeat(np.asarray(colours, np.uint8)[None], LEGEND_HEIGHT, axis=0)
    w = bar.shape[1]
    bar[LEGEND_HEIGHT - 3:, [0, (w - 1) // 2, w - 1]] = _TICK_COLOUR
    return bar


def _with_legend(image: np.ndarray, colour_map) -> np.ndarray:
    """Append a legend bar for ``colour_map``, a function of t ∈ [0, 1] → (W, 3) uint8."""
    t = np.linspace(0.0, 1.0, image.shape[1])
    return np.concatenate([image, legend_bar(colour_map(t))], axis=0)


def write_previews(stem: str | os.PathLike, stokes_rgb, exposure: float = 0.0) -> list[str]:
    """Write PNG previews of a (4, H, W, 3) Stokes image; return the paths written.

    Files (all with a legend bar, see module docstring):

    ``{stem}_S0.png``
        S0 RGB tone-mapped: ×2**exposure, clipped to [0, 1], sRGB-encoded.
        Legend: grey ramp of linear luminance 0 → 2**−exposure (white point).
    ``{stem}_S1.png``, ``_S2.png``, ``_S3.png``
        normalised luminance Stokes S_k/S0 ∈ [−1, 1] through :func:`diverging`:
        blue −1, white 0, red +1.  S1: red = linear along image-right
        (horizontal), blue = vertical; S2: red = +45° (right-up diagonal),
        blue = −45°; S3: red = right-circular, blue = left-circular (optics
        convention).  Legend: −1 → +1.
    ``{stem}_DoLP.png``, ``{stem}_DoP.png``
        degree of linear polarisation / of polarisation ∈ [0, 1] through
        :func:`sequential` (viridis: dark purple 0, yellow 1).  Legend: 0 → 1.
    ``{stem}_AoLP.png``
        angle of linear polarisation (from image-right towards image-up) as
        hue with period π: red 0° (horizontal), yellow +30°, green +60°,
        cyan ±90° (vertical), blue −60°, magenta −30°; DoLP is the
        saturation, so weakly polarised pixels fade to white.  Legend: AoLP −π/2 → +π/2 at full saturation.
    """
    s = check_stokes_image(stokes_rgb)
    stem = os.fspath(stem)
    y = luminance_stokes(s)
    dark = ~(y[0] > 0)

    def ratio(values: np.ndarray) -> np.ndarray:
        return np.where(dark, np.nan, values / np.where(dark, 1.0, y[0]))

    def grey(t: np.ndarray) -> np.ndarray:  # displayed linear value t, i.e. scene 2**-exposure·t
        return tonemap(np.repeat(t[:, None], 3, axis=1))

    dolp = ratio(np.hypot(y[1], y[2]))
    aolp = np.where(dark, np.nan, st.angle_of_linear_polarisation(y))
    images = {
        "S0": _with_legend(tonemap(s[0], exposure), grey),
        **{f"S{k}": _with_legend(diverging(ratio(y[k])), lambda t: diverging(2.0 * t - 1.0))
           for k in (1, 2, 3)},
        "DoLP": _with_legend(sequential(dolp), sequential),
        "DoP": _with_legend(sequential(ratio(np.sqrt(y[1] ** 2 + y[2] ** 2 + y[3] ** 2))), sequential),
        "AoLP": _with_legend(hue_saturation(aolp, dolp),
                             lambda t: hue_saturation(np.pi * (t - 0.5), np.ones_like(t))),
    }
    paths = []
    for name, image in images.items():
        path = f"{stem}_{name}.png"
        write_png(path, image)
        paths.append(path)
    return paths
