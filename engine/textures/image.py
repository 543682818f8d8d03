"""Reading image files for textures and environment maps: PNG (8-bit through Pillow, 16-bit decoded
here), JPEG, BMP and TGA (Pillow), TIFF (OpenImageIO), OpenEXR (OpenEXR) and Radiance .hdr (decoded here).

Pixels are returned as float32 (H, W, C), C = 1–4 channels, with row 0 at the *bottom* of the
image (v = 0, as Blender's UV space: v grows upwards), colour channels decoded to linear values
according to the colour space:

- ``"sRGB"``: the sRGB transfer function is undone on R, G, B (alpha stays linear), as Blender's
  default for 8/16-bit images (IEC 61966-2-1: c ≤ 0.04045 → c/12.92, else ((c+0.055)/1.055)^2.4);
  textures read them encoded instead (:func:`read_texture`) and decode after filtering, as Cycles;
- ``"Non-Color"``: values are used as stored (data: roughness, normal and height maps);
- ``"Linear"``: as Non-Color for the numbers (Blender's "Linear Rec.709": scene-linear colour),
  the default for EXR files.

Values follow OpenImageIO, the library Blender and Cycles read images with: unsigned integer samples
are normalised by their type's full range (255, 65535, 4294967295), signed ones by their largest
value (127, 32767, 2147483647: the most negative code maps slightly below −1), float samples (half,
float, double) are taken as they are; as Cycles (scene/image.cpp), a pixel with a non-finite
channel (NaN, ±inf, or a double beyond float32's range) becomes 0 in every channel.

Every file goes through one guarded path (:func:`_read_raw`): the reader of its type parses the
header, the size is checked against MAX_IMAGE_SIDE and MAX_IMAGE_PIXELS *before* any pixel is
decoded, and whatever a decoder raises on a broken, truncated or unsupported file becomes one
SceneError naming the file and what is wrong.

TIFF goes through OpenImageIO, because the format's legal sample types (uint8/16/32, int8/16/32,
float16/32/64; 1–4 channels, chunky or planar, strips or tiles, LZW/Deflate/PackBits, predictors)
are beyond Pillow, which decodes few of them and misreads some (16-bit RGB reduced to 8 bits, planar
16-bit RGB as zeros, uint32 wrapped negative, int8 as uint8); OpenImageIO reads them all as Blender
does.  It is imported only for TIFF files (and interlaced 16-bit PNGs).

Radiance .hdr (RGBE): decoded here, because no library at hand fits: Pillow cannot read it, imageio
reads it only through FreeImage (a binary it downloads at run time) or OpenCV, and OpenCV (a ~50 MB
dependency for one format) accepts only the standard ``-Y H +X W`` orientation.  The format is small
(Greg Ward, "Real Pixels", Graphics Gems II; Radiance's color.c): a text header (``#?RADIANCE`` or
``#?RGBE``, ``FORMAT=32-bit_rle_rgbe``; ``32-bit_rle_xyze`` is refused; EXPOSURE and COLORCORR are
ignored, as Blender and most readers do), a resolution line in any of the eight orientations
(``-Y H +X W`` rows top to bottom, ``+Y`` bottom to top, ``-X`` right to left, ``+X W -Y H`` column
by column), then per scanline flat pixels, old-style runs (1, 1, 1, n) or new-style RLE (each
channel run-length coded).  Run decoding is a Numba kernel (a NumPy/Python twin as reference); a
texel (r, g, b, e) is c·2^(e − 136) per channel and 0 for e = 0, as Blender and OpenImageIO (the
reader Cycles' image loader uses) decode it, so an HDRI lights a Polar render as it lights Cycles';
Radiance's own colr_color takes the middle of the mantissa step, (c + ½)·2^(e − 136).  .hdr files
are "Linear" by default, as EXR.
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
import re
import struct
import zlib

import numpy as np

from ..errors import SceneError
from ..files import refuse_special_file
from ..kernels import jit, twin

COLOR_SPACES = ("sRGB", "Non-Color", "Linear")

#: Largest width or height of an image file, checked from the header before decoding.  32768 is
#: twice the largest sizes in common use (16k × 8k HDRIs, 16k textures), so that any real texture or
#: environment map passes; a header beyond it is a mistake or a decompression bomb.
MAX_IMAGE_SIDE = 32768
#: Largest number of pixels of an image file (checked likewise): 2^28 = 16384 × 16384 or 32768 × 8192,
#: twice a 16k × 8k HDRI.  At 4 float32 channels that is 4 GiB per copy of the pixels, plus the float64
#: values decoding passes through: more would exhaust the memory of the machines this runs on.
MAX_IMAGE_PIXELS = 1 << 28


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
    """Blender's default: "Linear" for float (EXR, .hdr) images, "sRGB" for 8/16-bit ones and for
    every TIFF (Blender's TIFF reader puts all TIFFs, float ones too, in the default byte space)."""
    return "Linear" if path.lower().endswith(_FLOAT_SUFFIXES) else "sRGB"


def _fail(path: str, field: str, what: str) -> SceneError:
    return SceneError(field, f"cannot read image {path!r}: {what}")


def _check_size(path: str, field: str, width: int, height: int) -> None:
    """Refuse a header's size before any pixel is decoded (see MAX_IMAGE_SIDE, MAX_IMAGE_PIXELS)."""
    if width < 1 or height < 1:
        raise _fail(path, field, f"its header gives an empty size, {width}×{height} pixels")
    if width > MAX_IMAGE_SIDE or height > MAX_IMAGE_SIDE:
        raise _fail(path, field, f"its header gives {width}×{height} pixels, over the limit of "
                                 f"{MAX_IMAGE_SIDE} pixels per side (engine.textures.image.MAX_IMAGE_SIDE)")
    if width * height > MAX_IMAGE_PIXELS:
        raise _fail(path, field, f"its header gives {width}×{height} pixels, over the limit of "
                                 f"{MAX_IMAGE_PIXELS} pixels in all (engine.textures.image.MAX_IMAGE_PIXELS)")


def _zero_non_finite(a: np.ndarray) -> np.ndarray:
    """Pixels (H, W, C) with every channel of a pixel that has a non-finite one set to 0, as Cycles
    does for float images ("so that a changed hue does not show"); ``a`` itself if all are finite."""
    bad = ~np.isfinite(a)
    if not bad.any():
        return a
    a = a.copy()
    a[bad.any(axis=2)] = 0
    return a


def _read_pil(path: str, field: str) -> np.ndarray:
    """8-bit PNG, JPEG, BMP, TGA through Pillow: (H, W, C) codes / 255 (float64), top row first."""
    try:
        from PIL import Image  # Pillow: the reader for 8-bit PNG, JPEG, BMP, TGA
    except ImportError:
        raise SceneError(field, f"reading {os.path.basename(path)!r} needs the Pillow package (pip install pillow); "
                                "EXR textures need only OpenEXR") from None

    # Image.open parses only the header; our own size limit, checked next, replaces Pillow's bomb
    # guard (which warns from 89 M pixels and refuses from 179 M, below MAX_IMAGE_PIXELS); the guard
    # is off only while the header is parsed
    saved, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
    try:
        im = Image.open(path)
    finally:
        Image.MAX_IMAGE_PIXELS = saved
    with im:
        _check_size(path, field, *im.size)
        im.load()
        mode = im.mode
        if mode in ("I;16", "I;16B", "I;16L"):
            return np.asarray(im, dtype=np.float64)[:, :, None] / 65535.0
        if mode in ("I", "F") or mode.startswith("I;"):
            # 32-bit integer or float pixels: a conversion to 8 bits would clip them
            raise _fail(path, field, f"unsupported pixel format {mode!r} (save it as EXR or 16-bit PNG)")
        if mode not in ("L", "LA", "RGB", "RGBA"):
            im = im.convert("RGBA" if "A" in mode or "transparency" in im.info else "RGB")
        a = np.asarray(im, dtype=np.float64)
    if a.ndim == 2:
        a = a[:, :, None]
    return a / 255.0


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_bit_depth(path: str) -> int:
    """Bit depth from the PNG IHDR chunk (byte 24), 0 if not a PNG."""
    with open(path, "rb") as f:
        head = f.read(29)
    if head[:8] != _PNG_SIGNATURE or len(head) < 29:
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
    """A 16-bit PNG at full precision (Pillow would reduce RGB to 8 bits): chunks checked (order, CRC
    of the critical ones, length), decompressed with the standard library's zlib up to the size the
    header gives, row filters undone (ISO/IEC 15948 §9); (H, W, C) codes / 65535, top row first.
    Interlaced (Adam7) files go to OpenImageIO (libpng, as Blender)."""
    with open(path, "rb") as f:
        data = f.read()
    if not data.startswith(_PNG_SIGNATURE):
        raise _fail(path, field, "not a PNG file")
    pos, idat, header, ended = 8, [], None, False
    while pos < len(data):
        if pos + 8 > len(data):
            if idat:     # cut after the image data (IEND): the pixels are complete, as Pillow reads them
                break
            raise _fail(path, field, "the file ends early (truncated)")
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        crc = data[pos + 8 + length:pos + 12 + length]
        if len(body) < length or len(crc) < 4:
            if idat and kind != b"IDAT":
                break
            raise _fail(path, field, "the file ends early (truncated)")
        if header is None and kind != b"IHDR":
            raise _fail(path, field, "corrupt 16-bit PNG: the first chunk is not IHDR")
        # critical chunks (upper-case first letter) must be intact, as libpng requires
        if kind[:1].isupper() and struct.unpack(">I", crc)[0] != zlib.crc32(kind + body) & 0xFFFFFFFF:
            raise _fail(path, field, f"corrupt 16-bit PNG: CRC error in its {kind.decode('latin-1')!r} chunk")
        if kind == b"IHDR":
            if length != 13:
                raise _fail(path, field, "corrupt 16-bit PNG: bad IHDR chunk")
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            ended = True
            break
        pos += 12 + length
    if header is None:
        raise _fail(path, field, "corrupt 16-bit PNG: no IHDR chunk" if ended else "the file ends early (truncated)")
    width, height, depth, ctype, compression, filtering, interlace = header
    channels = {0: 1, 2: 3, 4: 2, 6: 4}.get(ctype)
    if depth != 16 or channels is None or compression != 0 or filtering != 0 or interlace > 1:
        raise _fail(path, field, f"unsupported PNG colour type {ctype} at bit depth {depth} "
                                 f"(compression {compression}, filter {filtering}, interlace {interlace})")
    _check_size(path, field, width, height)
    if interlace:
        return _read_oiio(path, field, "interlaced 16-bit PNG")
    if not idat:
        raise _fail(path, field, "corrupt 16-bit PNG: no image data (IDAT)" if ended
                    else "the file ends early (truncated)")
    bpp = 2 * channels
    stride = width * bpp
    expected = height * (stride + 1)
    try:
        # at most the bytes the header calls for: a zlib bomb stops there
        raw = zlib.decompressobj().decompress(b"".join(idat), expected)
    except zlib.error as e:
        raise _fail(path, field, f"corrupt 16-bit PNG data ({e})") from None
    if len(raw) != expected:
        raise _fail(path, field, "the 16-bit PNG pixel data ends early (truncated or corrupt)")
    raw = np.frombuffer(raw, dtype=np.uint8).reshape(height, stride + 1)
    if (raw[:, 0] > 4).any():
        raise _fail(path, field, "corrupt 16-bit PNG data (a row filter type other than 0–4)")
    out = png_unfilter(raw, bpp).astype(np.int64)
    words = (out[:, 0::2] << 8) | out[:, 1::2]
    return words.reshape(height, width, channels).astype(np.float64) / 65535.0


def _read_exr(path: str, field: str) -> np.ndarray:
    """An OpenEXR file (part 0) as float64 (H, W, C): R, G, B, A, or Y, or its single channel."""
    import OpenEXR

    # the binding prints its reading problems on stdout: captured, they become the error's reason
    said = io.StringIO()
    try:
        with contextlib.redirect_stdout(said):
            head = OpenEXR.File(path, header_only=True).header()
    except Exception as e:  # OpenEXR raises plain Exceptions for unreadable headers
        raise _fail(path, field, f"not a readable EXR file ({_reason(e, said)})") from None
    (x0, y0), (x1, y1) = head["dataWindow"]
    width, height = int(x1) - int(x0) + 1, int(y1) - int(y0) + 1
    _check_size(path, field, width, height)
    try:
        with contextlib.redirect_stdout(said):
            channels = {name: ch.pixels for name, ch in OpenEXR.File(path, separate_channels=True).channels().items()}
    except Exception as e:  # a broken or truncated pixel table or chunk: the file has no readable part
        raise _fail(path, field, f"its EXR pixel data cannot be decoded, truncated or corrupt ({_reason(e, said)})") \
            from None
    order = [c for c in ("R", "G", "B", "A") if c in channels]
    if not order:
        if "Y" in channels:
            order = ["Y"]
        elif len(channels) == 1:
            order = list(channels)
        else:
            raise SceneError(field, f"{path!r}: no R, G, B, A or Y channels "
                                    f"(has {', '.join(sorted(channels)) or 'no channels'})")
    for name in order:
        if getattr(channels[name], "shape", None) != (height, width):
            raise _fail(path, field, f"EXR channel {name!r} is subsampled or not a pixel plane (not supported)")
    return np.stack([np.asarray(channels[c], dtype=np.float64) for c in order], axis=-1)


def _reason(e: Exception, said: io.StringIO) -> str:
    """The most telling line of a library's failure: its printed warning, else its exception."""
    printed = [line.strip() for line in said.getvalue().splitlines() if line.strip()]
    if printed:     # "Warning: Exception raised reading pixel data for part 0 - <reason>"
        return printed[-1].rsplit(" - ", 1)[-1]
    return str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__


def _read_oiio(path: str, field: str, kind: str) -> np.ndarray:
    """A file through OpenImageIO (subimage 0): (H, W, min(C, 4)) float64, top row first; uint8 and
    uint16 samples as codes / full scale (exactly, as the other readers), every other sample type as
    OpenImageIO converts it to float (see the module docstring).  Alpha as stored (straight where
    the file says so: "oiio:UnassociatedAlpha", as Cycles and Blender open files)."""
    try:
        import OpenImageIO as oiio
    except ImportError:
        raise SceneError(field, f"reading the {kind} image {os.path.basename(path)!r} needs the OpenImageIO "
                                "package (pip install openimageio)") from None
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(path, config)
    if inp is None:
        problem = oiio.geterror()
        if "limits:imagesize_MB" in problem:    # OpenImageIO's own guard, from the header: the machine's memory
            raise _fail(path, field, f"its header claims an image larger than this machine's memory, over the limit "
                                     f"of {oiio.get_int_attribute('limits:imagesize_MB')} MB that OpenImageIO reads")
        raise _fail(path, field, f"not a readable {kind} file ({_oiio_reason(problem)})")
    try:
        spec = inp.spec()
        _check_size(path, field, spec.width, spec.height)
        if spec.deep or spec.depth != 1 or spec.nchannels < 1:
            raise _fail(path, field, f"a deep, volume or channel-less {kind} image (not supported)")
        n = min(spec.nchannels, 4)      # as Cycles: channels after the fourth are left out
        types = {str(spec.channelformat(c)) for c in range(n)}
        native = types.pop() if len(types) == 1 else "float"
        scale = {"uint8": 255.0, "uint16": 65535.0}.get(native)
        pixels = inp.read_image(0, 0, 0, n, native if scale else "float")
        problem = inp.geterror()
        if pixels is None or problem:
            raise _fail(path, field, f"its {kind} pixel data cannot be decoded, truncated or corrupt "
                                     f"({_oiio_reason(problem)})")
    finally:
        inp.close()
    a = np.asarray(pixels).reshape(spec.height, spec.width, n).astype(np.float64)
    return a / scale if scale else a


def _oiio_reason(message: str) -> str:
    lines = [line.strip() for line in (message or "").splitlines() if line.strip()]
    return lines[-1] if lines else "no reason given"


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
    """RGBE bytes (..., 4) → float64 (..., 3): c·2^(e − 136), 0 where e = 0 (as Blender and OpenImageIO)."""
    e = rgbe[..., 3].astype(np.int64)
    scale = np.where(e > 0, np.ldexp(1.0, e - 136), 0.0)
    return rgbe[..., :3].astype(np.float64) * scale[..., None]


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
    if a1 == b"Y":
        _check_size(path, field, length, n_scan)
    else:
        _check_size(path, field, n_scan, length)
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


def _read_png(path: str, field: str) -> np.ndarray:
    return _read_png16(path, field) if _png_bit_depth(path) == 16 else _read_pil(path, field)


def _read_tiff(path: str, field: str) -> np.ndarray:
    return _read_oiio(path, field, "TIFF")


#: suffix → (what the file is called in messages, its reader)
_READERS = {".exr": ("EXR", _read_exr), ".hdr": ("Radiance .hdr", _read_hdr), ".png": ("PNG", _read_png),
            ".jpg": ("JPEG", _read_pil), ".jpeg": ("JPEG", _read_pil), ".tif": ("TIFF", _read_tiff),
            ".tiff": ("TIFF", _read_tiff), ".bmp": ("BMP", _read_pil), ".tga": ("TGA", _read_pil)}


def _read_raw(path: str, field: str) -> np.ndarray:
    """The stored values (H, W, C) of an image file, top row first, as float64 (integer samples
    normalised, non-finite pixels 0): the one guarded path every file is read through.  Each reader
    checks the header's size (_check_size) before decoding; anything else a decoder raises on a
    broken file becomes one SceneError naming the file."""
    kind, reader = _READERS.get(os.path.splitext(path)[1].lower(), (None, None))
    if reader is None:
        raise SceneError(field, f"{path!r}: unsupported image type (use PNG, JPEG, TIFF, EXR or Radiance .hdr)")
    try:
        with np.errstate(all="ignore"):     # junk values (signalling NaNs, > float32) are dealt with below
            a = reader(path, field)
    except SceneError:
        raise
    except MemoryError:
        raise _fail(path, field, "not enough memory to decode it") from None
    except Exception as e:
        # third-party decoders raise many types for malformed input (Pillow alone: OSError,
        # SyntaxError, EOFError, ValueError, struct.error, IndexError, ...): all are the file's fault
        detail = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise _fail(path, field, f"broken, truncated or unsupported {kind} file ({detail})") from None
    a = np.asarray(a)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[0] < 1 or a.shape[1] < 1 or not 1 <= a.shape[2] <= 4:
        raise _fail(path, field, f"unsupported pixel layout {a.shape} (expected height × width × 1–4 channels)")
    with np.errstate(all="ignore"):
        return _zero_non_finite(a.astype(np.float64, copy=False))


def _stamp(path: str) -> tuple[int, int]:
    """What the caches key a file's contents by: modification time (ns) and size."""
    st = os.stat(path)
    return st.st_mtime_ns, st.st_size


@functools.lru_cache(maxsize=16)
def _read_cached(path: str, stamp: tuple, color_space: str, field: str) -> np.ndarray:
    a = _read_raw(path, field)
    with np.errstate(over="ignore"):     # a decoded value beyond float32's range becomes inf: 0, as Cycles
        if color_space == "sRGB":
            colour = min(a.shape[2], 3) if a.shape[2] != 2 else 1     # grey+alpha: only grey is colour
            a = a.copy()
            a[:, :, :colour] = srgb_to_linear(a[:, :, :colour])
        out = _zero_non_finite(np.ascontiguousarray(a[::-1], dtype=np.float32))    # row 0 = bottom (v = 0)
    out.setflags(write=False)
    return out


def _check_exists(path: str, field: str) -> None:
    """A SceneError naming ``field`` unless ``path`` is a regular file (a FIFO or device is refused
    before it is opened: reading it could wait forever)."""
    refuse_special_file(path, field, "image ")
    if not os.path.isfile(path):
        raise SceneError(field, f"image file {path!r} not found")


def read_image(path: str, color_space: str | None = None, field: str = "") -> np.ndarray:
    """Linear float32 pixels (H, W, C), C = 1–4, all finite, row 0 at the bottom (see the module
    docstring).  Any problem with the file (missing, unsupported, oversized, broken) is a
    SceneError naming ``field`` and the file."""
    if color_space is None:
        color_space = default_color_space(path)
    if color_space not in COLOR_SPACES:
        raise SceneError(field, f"colour space must be one of {', '.join(COLOR_SPACES)}, got {color_space!r}")
    _check_exists(path, field)
    return _read_cached(os.path.abspath(path), _stamp(path), color_space, field)


def read_texture(path: str, color_space: str | None = None, field: str = "") -> tuple[np.ndarray, str]:
    """(float32 pixels (H, W, C), row 0 at the bottom; interpolation space) of an image file for an
    ImageTexture.  Files in the "sRGB" colour space come encoded, with interpolation space "srgb"
    (filtered encoded, decoded after, as Cycles does for every image file it reads as sRGB, 8-bit
    or float: scene/image.cpp ``compress_as_srgb``); others linear, as :func:`read_image`.  Errors
    as :func:`read_image`."""
    if color_space is None:
        color_space = default_color_space(path)
    if color_space == "sRGB":
        _check_exists(path, field)
        return _read_encoded(os.path.abspath(path), _stamp(path), field), "srgb"
    return read_image(path, color_space, field), "linear"


@functools.lru_cache(maxsize=16)
def _read_encoded(path: str, stamp: tuple, field: str) -> np.ndarray:
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
        with np.errstate(over="ignore"):
            out = _zero_non_finite(np.ascontiguousarray(a[::-1], dtype=np.float32))
    out.setflags(write=False)
    return out
