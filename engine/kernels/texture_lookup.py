"""Bilinear image-texture lookups (Blender's Image Texture, Linear) as one compiled loop.

``bilinear_loop`` is engine.textures.texture.ImageTexture.lookup_numpy for ``interpolation`` "Linear" per
point, the same arithmetic in the same order: x = u·W − ½, y = v·H − ½, the four texels wrapped by the
extension (REPEAT, EXTEND, CLIP: 0 outside, MIRROR), weighted row by row ((t₀₀·(1 − fx) + t₁₀·fx)·(1 − fy) +
(t₀₁·(1 − fx) + t₁₁·fx)·fy, each sum from 0), integer codes divided by their full scale (alpha rounded to
float32), and for sRGB-encoded texels the colour channels clipped to the texels' range and decoded
(IEC 61966-2-1, negative → 0, rounded to float32).  The coordinates come reduced (no |u| ≥ 2⁵², finite).
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner

#: extension codes (the order of engine.textures.texture.EXTENSIONS)
REPEAT, EXTEND, CLIP, MIRROR = 0, 1, 2, 3


@jit_inner
def _wrap(i, n, extension):
    """(index in [0, n), inside) of pixel index i under the extension (inside: CLIP's test, else True)."""
    if extension == REPEAT:
        m = i % n
        return m, True
    if extension == EXTEND:
        return min(max(i, 0), n - 1), True
    if extension == MIRROR:
        m = i % (2 * n)
        return (m if m < n else 2 * n - 1 - m), True
    return min(max(i, 0), n - 1), (i >= 0) and (i < n)


@jit_inner
def _srgb_decode(c):
    v = c / 12.92 if c <= 0.04045 else ((max(c, 0.04045) + 0.055) / 1.055) ** 2.4
    return max(v, 0.0)


@jit
def _bilinear_loop(uv, pixels, width, height, extension, code_scale, colour, srgb, lo, hi, out):
    n = uv.shape[1]
    C = pixels.shape[2]
    for k in range(n):
        x = uv[0, k] * width - 0.5
        y = uv[1, k] * height - 0.5
        x0 = np.floor(x)
        y0 = np.floor(y)
        fx = x - x0
        fy = y - y0
        i0 = np.int64(x0)
        j0 = np.int64(y0)
        # the four texels' indices (and CLIP's inside tests) depend on the point alone: wrapped once, not per channel
        jj_0, in_y0 = _wrap(j0, height, extension)
        jj_1, in_y1 = _wrap(j0 + 1, height, extension)
        ii_0, in_x0 = _wrap(i0, width, extension)
        ii_1, in_x1 = _wrap(i0 + 1, width, extension)
        for c in range(C):
            acc = 0.0
            for b in range(2):
                jj, in_y = (jj_0, in_y0) if b == 0 else (jj_1, in_y1)
                wy = 1.0 - fy if b == 0 else fy
                row = 0.0
                for a in range(2):
                    ii, in_x = (ii_0, in_x0) if a == 0 else (ii_1, in_x1)
                    wx = 1.0 - fx if a == 0 else fx
                    t = np.float64(pixels[jj, ii, c])
                    if code_scale > 0.0:
                        t = t / code_scale
                        if c >= colour:
                            t = np.float64(np.float32(t))
                    if extension == CLIP:
                        t = t * (1.0 if (in_x and in_y) else 0.0)
                    row += t * wx
                acc += row * wy
            if srgb and c < colour:
                acc = np.float64(np.float32(_srgb_decode(min(max(acc, lo[c]), hi[c]))))
            out[c, k] = acc


#: (uv (2, N), pixels (H, W, C), W, H, extension code, code scale (0: floats), colour channels, srgb, lo (C,),
#: hi (C,), out (C, N)); None without Numba.
bilinear_loop = _bilinear_loop
