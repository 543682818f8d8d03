"""Contact sheets: several previews side by side with a small label under each (no font files:
digits and a few signs are drawn from a built-in 3×5 pixel font)."""

from __future__ import annotations

import math

import numpy as np

_GLYPHS = {
    "0": "111101101101111", "1": "010110010010111", "2": "111001111100111", "3": "111001111001111",
    "4": "101101111001001", "5": "111100111001111", "6": "111100111101111", "7": "111001001001001",
    "8": "111101111101111", "9": "111101111001111", "-": "000000111000000", ".": "000000000000010",
    "°": "111101111000000", " ": "000000000000000",
}


def draw_label(text: str, scale: int = 2) -> np.ndarray:
    """A white-on-black uint8 (5·scale, 4·scale·len, 3) image of ``text`` (digits, '-', '.', '°')."""
    glyphs = [np.array([int(b) for b in _GLYPHS.get(ch, _GLYPHS[" "])], np.uint8).reshape(5, 3) for ch in text]
    cells = [np.pad(g, ((0, 0), (0, 1))) for g in glyphs] or [np.zeros((5, 4), np.uint8)]
    bitmap = np.concatenate(cells, axis=1)
    bitmap = np.kron(bitmap, np.ones((scale, scale), np.uint8)) * 255
    return np.repeat(bitmap[:, :, None], 3, axis=2)


def contact_sheet(tiles, labels=None, columns: int | None = None, gap: int = 4) -> np.ndarray:
    """Arrange equally sized uint8 (H, W, 3) tiles in a grid, each with its label (degrees) below."""
    n = len(tiles)
    columns = columns or math.ceil(math.sqrt(n))
    rows = math.ceil(n / columns)
    h, w = tiles[0].shape[:2]
    label_h = 14
    sheet = np.zeros((rows * (h + label_h + gap) + gap, columns * (w + gap) + gap, 3), np.uint8)
    for i, tile in enumerate(tiles):
        r, c = divmod(i, columns)
        y, x = gap + r * (h + label_h + gap), gap + c * (w + gap)
        sheet[y:y + h, x:x + w] = tile
        if labels:
            lab = draw_label(labels[i] + "°")[:, :w]
            sheet[y + h + 2:y + h + 2 + lab.shape[0], x:x + lab.shape[1]] = lab
    return sheet
