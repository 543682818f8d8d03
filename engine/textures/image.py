"""Reading image files for textures: PNG, JPEG (8/16-bit, through Pillow), OpenEXR (float) and
Radiance .hdr (RGBE, decoded here).

Pixels are returned as float32 (H, W, C), C = 1–4 channels, with row 0 at the *bottom* of the
image (v = 0, as Blender's UV space: v grows upwards), colour channels decoded to linear values
according to the colour space:

- ``"sRGB"``: the sRGB transfer function is undone on R, G, B (alpha stays linear), as Blender's
  default for 8/16-bit images (IEC 61966-2-1: c ≤ 0.04045 → c/12.92, else ((c+0.055)/1.055)^2.4);
  textures read them encoded instead (:func:`read_texture`) and decode after filtering, as Cycles;
- ``"Non-Color"``: values are used as stored (data: roughness, normal and height maps);
- ``"Linear"``: as Non-Color for the numbers (Blender's "Linear Rec.709": scene-linear colour),
  the default for EXR files.

Integer images are normalised by their full scale (255, 65535); EXR channels are read as float.

Radiance .hdr (RGBE): decoded here, because no library at hand fits: Pillow cannot read it, imageio
reads it only through FreeImage (a binary it downloads at run time) or OpenCV, and OpenCV (a ~50 MB
dependency for one format) accepts only the standard ``-Y H +X W`` orientation.  The format is small
(Greg Ward, "Real Pixels", Graphics Gems II; Radiance's color.c): a text header (``#?RADIANCE`` or
``#?RGBE``, ``FORMAT=32-bit_rle_rgbe``; ``32-bit_rle_xyze`` is refused; EXPOSURE and COLORCORR are
ignored, as Blender and most readers do), a resolution line in any of the eight orientations
(``-Y H +X W`` rows top to bottom, ``+Y`` bottom to top, ``-X`` right to left, ``+X W -Y H`` column
by column), then per scanline flat pixels, old-style runs (1, 1, 1, n) or new-style RLE (each
channel run-length coded).  Run decoding is a Numba kernel (a NumPy/Python twin as reference); a
texel (r, g, b, e) is (c + ½)·2^(e − 136) per channel and 0 for e = 0 (Radiance's and Blender's
rounding to the middle of the mantissa step).  .hdr files are "Linear" by default, as EXR.
"""

from __future__ import annotations

import functools
import os
import re

import numpy as np

from ..errors import SceneError
from ..kernels import jit, twin

COLOR_SPACES = ("sRGB", "Non-Color", "Linear")
_PIL_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".tga")


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """Inverse sRGB transfer function (IEC 61966-2-1), float64, elementwise."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    """sRGB transfer function (IEC 61966-2-1), its power law continued above 1, negative values → 0
    (as Cycles' color_linear_to_srgb); float64, elementwise; inverse of srgb_to_linear on c ≥ 0."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c < 0.0031308, 12.92 * np.maximum(c, 0.0),
                    1.055 * np.maximum(c, 0.0031308) ** (1 / 2.4) - 0.055)


_FLOAT_SUFFIXES = (".exr", ".hdr")


def default_color_space(path: str) -> str:
    """Blender's default: "Linear" for float (EXR, .hdr) images, "sRGB" for 8/16-bit ones."""
    return "Linear" if path.lower().endswith(_FLOAT_SUFFIXES) else "sRGB"


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


def png_unfilter_numpy(raw: np.ndarray, bpp: int) -> np.ndarray:
    """PNG rows with their filters undone (ISO/IEC 15948 §9): ``raw`` uint8 (H, 1 + stride), byte 0 of
    each row its filter type (0 None, 1 Sub, 2 Up, 3 Average, 4 Paeth); ``bpp`` bytes per pixel.
    Returns uint8 (H, stride).  NumPy reference: None/Up/Sub vectorised per row, Average and Paeth
    (sequential along a row) pixel by pixel over the pixel's bytes."""
    height, stride = raw.shape[0], raw.shape[1] - 1
    width = stride // bpp
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
    return out.astype(np.uint8)


@jit
def _unfilter_loop(raw, bpp, out):
    height, stride = out.shape
    for r in range(height):
        ftype = raw[r, 0]
        for i in range(stride):
            x = np.int64(raw[r, 1 + i])
            a = np.int64(out[r, i - bpp]) if i >= bpp else np.int64(0)
            b = np.int64(out[r - 1, i]) if r > 0 else np.int64(0)
            c = np.int64(out[r - 1, i - bpp]) if (r > 0 and i >= bpp) else np.int64(0)
            if ftype == 1:
                x += a
            elif ftype == 2:
                x += b
            elif ftype == 3:
                x += (a + b) // 2
            elif ftype == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                x += a if (pa <= pb and pa <= pc) else (b if pb <= pc else c)
            out[r, i] = x & 255


def _png_unfilter_compiled(raw: np.ndarray, bpp: int) -> np.ndarray:
    out = np.empty((raw.shape[0], raw.shape[1] - 1), np.uint8)
    _unfilter_loop(np.ascontiguousarray(raw), int(bpp), out)
    return out


png_unfilter = twin(_unfilter_loop and _png_unfilter_compiled, png_unfilter_numpy)


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
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), dtype=np.uint8)
    if raw.size != height * (stride + 1) or (raw.reshape(height, stride + 1)[:, 0] > 4).any():
        raise SceneError(field, f"cannot read image {path!r}: corrupt 16-bit PNG data")
    out = png_unfilter(raw.reshape(height, stride + 1), bpp).astype(np.int64)
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


# --------------------------------------------------------------------------- Radiance .hdr (RGBE)

#: Errors of the run decoder, by its return code.
_RGBE_ERRORS = {1: "the pixel data ends early", 2: "a run is longer than its scanline (corrupt run-length data)",
                3: "a new-style run-length scanline declares a length other than the image width"}


def decode_rgbe_runs_numpy(data: np.ndarray, n_scan: int, length: int):
    """(status, (n_scan, length, 4) uint8 RGBE pixels) from the pixel bytes after the resolution line.

    status 0 = ok, else a key of _RGBE_ERRORS.  Per scanline: new-style RLE (starts 2, 2, length
    high byte < 128, low byte, for 8 ≤ length < 32768; then each of the four channels as runs:
    count > 128 → the next byte (count − 128) times, else count literal bytes) or flat pixels with
    old-style runs ((1, 1, 1, n): the previous pixel n << shift times, shift += 8 for consecutive
    runs).  NumPy reference of the compiled kernel (a Python loop over runs, slices within a run).
    """
    out = np.zeros((n_scan, length, 4), np.uint8)
    n, pos = data.shape[0], 0
    for s in range(n_scan):
        if (8 <= length <= 0x7FFF and pos + 4 <= n and data[pos] == 2 and data[pos + 1] == 2
                and data[pos + 2] < 128):
            if (int(data[pos + 2]) << 8 | int(data[pos + 3])) != length:
                return 3, out
            pos += 4
            for ch in range(4):
                i = 0
                while i < length:
                    if pos >= n:
                        return 1, out
                    count = int(data[pos])
                    pos += 1
                    if count > 128:
                        count -= 128
                        if count > length - i:
                            return 2, out
                        if pos >= n:
                            return 1, out
                        out[s, i:i + count, ch] = data[pos]
                        pos += 1
                    else:
                        if count == 0 or count > length - i:
                            return 2, out
                        if pos + count > n:
                            return 1, out
                        out[s, i:i + count, ch] = data[pos:pos + count]
                        pos += count
                    i += count
        else:
            i, shift = 0, 0
            while i < length:
                if pos + 4 > n:
                    return 1, out
                px = data[pos:pos + 4]
                pos += 4
                if px[0] == 1 and px[1] == 1 and px[2] == 1:       # old-style run of the previous pixel
                    count = int(px[3]) << shift
                    if i == 0 or count > length - i:
                        return 2, out
                    out[s, i:i + count] = out[s, i - 1]
                    i += count
                    shift += 8
                else:
                    out[s, i] = px
                    i += 1
                    shift = 0
    return 0, out


@jit
def _rgbe_loop(data, n_scan, length, out):
    n = data.shape[0]
    pos = 0
    for s in range(n_scan):
        if (8 <= length <= 0x7FFF and pos + 4 <= n and data[pos] == 2 and data[pos + 1] == 2
                and data[pos + 2] < 128):
            if ((np.int64(data[pos + 2]) << 8) | np.int64(data[pos + 3])) != length:
                return 3
            pos += 4
            for ch in range(4):
                i = 0
                while i < length:
                    if pos >= n:
                        return 1
                    count = np.int64(data[pos])
                    pos += 1
                    if count > 128:
                        count -= 128
                        if count > length - i:
                            return 2
                        if pos >= n:
                            return 1
                        value = data[pos]
                        pos += 1
                        for k in range(count):
                            out[s, i + k, ch] = value
                    else:
                        if count == 0 or count > length - i:
                            return 2
                        if pos + count > n:
                            return 1
                        for k in range(count):
                            out[s, i + k, ch] = data[pos + k]
                        pos += count
                    i += count
        else:
            i = 0
            shift = 0
            while i < length:
                if pos + 4 > n:
                    return 1
                if data[pos] == 1 and data[pos + 1] == 1 and data[pos + 2] == 1:
                    count = np.int64(data[pos + 3]) << shift
                    pos += 4
                    if i == 0 or count > length - i:
                        return 2
                    for k in range(count):
                        for ch in range(4):
                            out[s, i + k, ch] = out[s, i - 1, ch]
                    i += count
                    shift += 8
                else:
                    for ch in range(4):
                        out[s, i, ch] = data[pos + ch]
                    pos += 4
                    i += 1
                    shift = 0
    return 0


def _decode_rgbe_runs_compiled(data: np.ndarray, n_scan: int, length: int):
    out = np.zeros((n_scan, length, 4), np.uint8)
    status = _rgbe_loop(np.ascontiguousarray(data, dtype=np.uint8), np.int64(n_scan), np.int64(length), out)
    return int(status), out


decode_rgbe_runs = twin(_rgbe_loop and _decode_rgbe_runs_compiled, decode_rgbe_runs_numpy)


def rgbe_to_float(rgbe: np.ndarray) -> np.ndarray:
    """RGBE bytes (..., 4) → float64 (..., 3): (c + ½)·2^(e − 136), 0 where e = 0 (Radiance's colr_color)."""
    e = rgbe[..., 3].astype(np.int64)
    scale = np.where(e > 0, np.ldexp(1.0, e - 136), 0.0)
    return (rgbe[..., :3].astype(np.float64) + 0.5) * scale[..., None]


_RESOLUTION = re.compile(rb"^([-+])([XY]) +(\d+) +([-+])([XY]) +(\d+)[ \t]*\r?$")


def _read_hdr(path: str, field: str) -> np.ndarray:
    """A Radiance .hdr file as float64 (H, W, 3), row 0 at the top (see the module docstring)."""
    with open(path, "rb") as f:
        data = f.read()

    def fail(what):
        return SceneError(field, f"cannot read image {path!r}: {what}")

    if not data.startswith(b"#?"):
        raise fail("not a Radiance .hdr file (it does not start with '#?')")
    end = data.find(b"\n\n")
    end_crlf = data.find(b"\r\n\r\n")
    if end < 0 and end_crlf < 0:
        raise fail("the header has no end (a blank line)")
    header_end = (end + 2) if end >= 0 and (end_crlf < 0 or end < end_crlf) else end_crlf + 4
    for line in data[:header_end].splitlines():
        if line.startswith(b"FORMAT=") and line.strip() != b"FORMAT=32-bit_rle_rgbe":
            raise fail(f"unsupported pixel format {line[7:].strip().decode('ascii', 'replace')!r} "
                       "(only 32-bit_rle_rgbe)")
    eol = data.find(b"\n", header_end)
    if eol < 0:
        raise fail("no pixel data after the resolution line")
    m = _RESOLUTION.match(data[header_end:eol])
    if m is None or m.group(2) == m.group(5):
        raise fail("bad resolution line (expected e.g. '-Y 512 +X 1024')")
    (s1, a1, n1, s2, a2, n2) = m.groups()
    n_scan, length = int(n1), int(n2)
    if n_scan < 1 or length < 1 or n_scan * length > 1 << 28:
        raise fail(f"image size {n_scan}×{length} is empty or too large")
    status, rgbe = decode_rgbe_runs(np.frombuffer(data, np.uint8, offset=eol + 1), n_scan, length)
    if status:
        raise fail(_RGBE_ERRORS[status])
    rgb = rgbe_to_float(rgbe)
    # scanline axis first: rows top → bottom and columns left → right
    if (a1 == b"Y") == (s1 == b"+"):     # +Y: first scanline at the bottom; -X: at the right
        rgb = rgb[::-1]
    if (a2 == b"Y") == (s2 == b"+"):
        rgb = rgb[:, ::-1]
    if a1 == b"X":                       # scanlines are columns
        rgb = rgb.transpose(1, 0, 2)
    return np.ascontiguousarray(rgb)


def _read_raw(path: str, field: str) -> np.ndarray:
    """The stored values (H, W, C), top row first: integer images as code / full scale (float64)."""
    if path.lower().endswith(".exr"):
        a = _read_exr(path, field)
    elif path.lower().endswith(".hdr"):
        a = _read_hdr(path, field)
    elif path.lower().endswith(_PIL_SUFFIXES):
        a = _read_png16(path, field) if path.lower().endswith(".png") and _png_bit_depth(path) == 16 else None
        if a is None or a.shape[2] == 1:
            a = _read_pil(path, field) if a is None else a
    else:
        raise SceneError(field, f"{path!r}: unsupported image type (use PNG, JPEG, TIFF, EXR or Radiance .hdr)")
    return a


@functools.lru_cache(maxsize=16)
def _read_cached(path: str, mtime: float, color_space: str, field: str) -> np.ndarray:
    a = _read_raw(path, field)
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


def read_texture(path: str, color_space: str | None = None, field: str = "") -> tuple[np.ndarray, str]:
    """(float32 pixels (H, W, C), row 0 at the bottom; interpolation space) of an image file for an
    ImageTexture.  Files in the "sRGB" colour space come encoded, with interpolation space "srgb"
    (filtered encoded, decoded after, as Cycles does for every image file it reads as sRGB, 8-bit
    or float: scene/image.cpp ``compress_as_srgb``); others linear, as :func:`read_image`."""
    if color_space is None:
        color_space = default_color_space(path)
    if color_space == "sRGB":
        if not os.path.isfile(path):
            raise SceneError(field, f"image file {path!r} not found")
        return _read_encoded(os.path.abspath(path), os.path.getmtime(path), field), "srgb"
    return read_image(path, color_space, field), "linear"


@functools.lru_cache(maxsize=16)
def _read_encoded(path: str, mtime: float, field: str) -> np.ndarray:
    """Stored values of an image file, row 0 at the bottom: 8/16-bit images as their integer codes
    (uint8/uint16, value = code / full scale exactly as read_image computes it, so the decoded
    texels are bit for bit read_image's "sRGB" ones), float images as float32."""
    a = _read_raw(path, field)
    for dtype in (np.uint8, np.uint16):
        scale = np.iinfo(dtype).max
        codes = np.rint(a * scale)
        if codes.min() >= 0 and codes.max() <= scale and np.array_equal(codes / scale, a):
            out = np.ascontiguousarray(codes[::-1], dtype=dtype)
            break
    else:
        out = np.ascontiguousarray(a[::-1], dtype=np.float32)
    out.setflags(write=False)
    return out
