"""Reading image files for textures: PNG, JPEG (8/16-bit, through Pillow) and OpenEXR (float).

Pixels are returned as float32 (H, W, C), C = 1–4 channels, with row 0 at the *bottom* of the
image (v = 0, as Blender's UV space: v grows upwards), colour channels decoded to linear values
according to the colour space:

- ``"sRGB"``: the sRGB transfer function is undone on R, G, B (alpha stays linear), as Blender's
  default for 8/16-bit images (IEC 61966-2-1: c ≤ 0.04045 → c/12.92, else ((c+0.055)/1.055)^2.4);
- ``"Non-Color"``: values are used as stored (data: roughness, normal and height maps);
- ``"Linear"``: as Non-Color for the numbers (Blender's "Linear Rec.709": scene-linear colour),
  the default for EXR files.

Integer images are normalised by their full scale (255, 65535); EXR channels are read as float.
"""

from __future__ import annotations

import functools
import os

import numpy as np

from ..errors import SceneError

COLOR_SPACES = ("sRGB", "Non-Color", "Linear")
_PIL_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".tga")


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """Inverse sRGB transfer function (IEC 61966-2-1), float64, elementwise."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4)


def default_color_space(path: str) -> str:
    """Blender's default: "Linear" for float (EXR) images, "sRGB" for 8/16-bit ones."""
    return "Linear" if path.lower().endswith(".exr") else "sRGB"


def _read_pil(path: str, field: str) -> np.ndarray:
    try:
        from PIL import Image  # Pillow: the reader for PNG/JPEG (8 and 16 bit)
    except ImportError:
        raise SceneError(field, f"reading {os.path.basename(path)!r} needs the Pillow package (pip install pillow); "
                                "EXR textures need only OpenEXR") from None

    try:
        with Image.open(path) as im:
            mode = im.mode
            if mode in ("I;16", "I;16B", "I;16L", "I"):
                # 16-bit greyscale (Pillow has no 16-bit RGB mode: such PNGs come as 8-bit RGB(A),
                # see _read_png16 below)
                a = np.asarray(im, dtype=np.float64)[:, :, None] / 65535.0
            else:
                if mode not in ("L", "LA", "RGB", "RGBA"):
                    im = im.convert("RGBA" if "A" in mode or "transparency" in im.info else "RGB")
                a = np.asarray(im, dtype=np.float64)
                if a.ndim == 2:
                    a = a[:, :, None]
                a = a / 255.0
    except (OSError, ValueError) as e:
        raise SceneError(field, f"cannot read image {path!r}: {e}") from None
    return a


def _png_bit_depth(path: str) -> int:
    """Bit depth from the PNG IHDR chunk (byte 24), 0 if not a PNG."""
    with open(path, "rb") as f:
        head = f.read(29)
    if head[:8] != b"\x89PNG\r\n\x1a\n" or len(head) < 29:
        return 0
    return head[24]


def _read_png16(path: str, field: str) -> np.ndarray:
    """A 16-bit RGB(A) PNG at full precision (Pillow would reduce it to 8 bits): decoded with the
    standard library's zlib, with the PNG row filters undone (ISO/IEC 15948 §9)."""
    import struct
    import zlib

    with open(path, "rb") as f:
        data = f.read()
    pos, idat, width = 8, [], None
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        chunk = data[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            width, height, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", chunk)
            if interlace:
                raise SceneError(field, f"{path!r}: interlaced 16-bit PNGs are not supported")
        elif kind == b"IDAT":
            idat.append(chunk)
        pos += 12 + length
    channels = {0: 1, 2: 3, 4: 2, 6: 4}.get(ctype)
    if width is None or channels is None:
        raise SceneError(field, f"cannot read image {path!r}: unsupported PNG colour type")
    bpp = 2 * channels
    stride = width * bpp
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), dtype=np.uint8).reshape(height, stride + 1)
    out = np.zeros((height, stride), np.int64)
    prev = np.zeros(stride, np.int64)
    for r in range(height):          # PNG filters are sequential along a row and down the rows
        ftype, line = raw[r, 0], raw[r, 1:].astype(np.int64)
        if ftype == 0:
            cur = line
        elif ftype == 2:             # Up
            cur = (line + prev) & 255
        elif ftype == 1:             # Sub: a running sum along each byte lane of a pixel
            cur = np.cumsum(line.reshape(width, bpp), axis=0).reshape(-1) & 255
        else:                        # Average, Paeth: pixel by pixel, vectorised over its bytes
            cur = np.zeros(stride, np.int64)
            a = np.zeros(bpp, np.int64)
            c = np.zeros(bpp, np.int64)
            for i in range(0, stride, bpp):
                b = prev[i:i + bpp]
                if ftype == 3:
                    pred = (a + b) // 2
                else:
                    p = a + b - c
                    pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - c)
                    pred = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
                a = (line[i:i + bpp] + pred) & 255
                cur[i:i + bpp] = a
                c = b
        out[r] = cur
        prev = cur
    words = (out[:, 0::2] << 8) | out[:, 1::2]
    return words.reshape(height, width, channels).astype(np.float64) / 65535.0


def _read_exr(path: str, field: str) -> np.ndarray:
    import OpenEXR

    try:
        f = OpenEXR.File(path, separate_channels=True)
    except Exception as e:  # OpenEXR raises plain Exceptions for unreadable files
        raise SceneError(field, f"cannot read image {path!r}: {e}") from None
    channels = {name: np.asarray(ch.pixels, dtype=np.float64) for name, ch in f.channels().items()}
    order = [c for c in ("R", "G", "B", "A") if c in channels]
    if not order:
        if "Y" in channels:
            order = ["Y"]
        elif len(channels) == 1:
            order = list(channels)
        else:
            raise SceneError(field, f"{path!r}: no R, G, B, A or Y channels (has {', '.join(sorted(channels))})")
    return np.stack([channels[c] for c in order], axis=-1)


@functools.lru_cache(maxsize=16)
def _read_cached(path: str, mtime: float, color_space: str, field: str) -> np.ndarray:
    if path.lower().endswith(".exr"):
        a = _read_exr(path, field)
    elif path.lower().endswith(_PIL_SUFFIXES):
        a = _read_png16(path, field) if path.lower().endswith(".png") and _png_bit_depth(path) == 16 else None
        if a is None or a.shape[2] == 1:
            a = _read_pil(path, field) if a is None else a
    else:
        raise SceneError(field, f"{path!r}: unsupported image type (use PNG, JPEG, TIFF or EXR)")
    if color_space == "sRGB":
        colour = min(a.shape[2], 3) if a.shape[2] != 2 else 1     # grey+alpha: only grey is colour
        a = a.copy()
        a[:, :, :colour] = srgb_to_linear(a[:, :, :colour])
    out = np.ascontiguousarray(a[::-1], dtype=np.float32)   # row 0 = bottom (v = 0)
    out.setflags(write=False)
    return out


def read_image(path: str, color_space: str | None = None, field: str = "") -> np.ndarray:
    """Linear float32 pixels (H, W, C) of an image file, row 0 at the bottom (see module docstring)."""
    if color_space is None:
        color_space = default_color_space(path)
    if color_space not in COLOR_SPACES:
        raise SceneError(field, f"colour space must be one of {', '.join(COLOR_SPACES)}, got {color_space!r}")
    if not os.path.isfile(path):
        raise SceneError(field, f"image file {path!r} not found")
    return _read_cached(os.path.abspath(path), os.path.getmtime(path), color_space, field)
