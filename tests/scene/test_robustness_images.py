"""Image files fail cleanly (issue 32): a broken, truncated, undecodable or oversized texture or
environment-map file is one SceneError naming the file (on the command line: one ``error:`` line,
exit status 2), never a traceback, a hang or a silent misreading; legal but unusual files (every TIFF
sample format) are read with OpenImageIO's values, as Blender and Cycles read them.

Oracles: files written here byte by byte (TIFF, 16-bit PNG, .hdr headers) or by independent writers
(Pillow, OpenEXR), the values stored in them, and OpenImageIO's documented normalisation (unsigned
integers by their full range, signed ones by their largest value, floats as they are).
"""

import contextlib
import io
import itertools
import json
import os
import struct
import subprocess
import sys
import tempfile
import time
import tracemalloc
import warnings
import zlib

import numpy as np
import OpenEXR
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from engine.errors import SceneError
from engine.textures import image as image_module
from engine.textures.image import read_image, read_texture, srgb_to_linear
from tests.conftest import REPO

# --------------------------------------------------------------------------- writers


def _chunk(kind, body):
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)


def _png(width, height, depth, ctype, idat, interlace=0):
    """PNG bytes: signature, IHDR, one IDAT chunk with ``idat`` as it is, IEND."""
    ihdr = struct.pack(">IIBBBBB", width, height, depth, ctype, 0, 0, interlace)
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", idat) + _chunk(b"IEND", b"")


def _png16(codes):
    """A 16-bit PNG of uint16 (H, W, C) codes, C = 1–4, every row with filter type 0 (None)."""
    h, w, c = codes.shape
    rows = b"".join(b"\0" + codes[r].astype(">u2").tobytes() for r in range(h))
    return _png(w, h, 16, {1: 0, 2: 4, 3: 2, 4: 6}[c], zlib.compress(rows))


def _tiff(a, planar=False, big_endian=False, size=None, extra_alpha=2):
    """Uncompressed baseline TIFF bytes of ``a`` (H, W) or (H, W, C) in its own dtype (SampleFormat
    1 uint, 2 int, 3 float; BitsPerSample its size), one strip per plane, the IFD after the pixels.
    ``size`` = (width, height) overrides the header's size; channels past 1 (grey) or 3 (RGB) are
    ExtraSamples of type ``extra_alpha`` (2 unassociated alpha, 0 unspecified)."""
    a = np.asarray(a)
    a = a[:, :, None] if a.ndim == 2 else a
    h, w, c = a.shape
    bo = ">" if big_endian else "<"
    a = a.astype(a.dtype.newbyteorder(bo))
    data = (np.ascontiguousarray(a.transpose(2, 0, 1)) if planar else a).tobytes()
    width, height = size or (w, h)
    plane = h * w * a.dtype.itemsize
    offsets, counts = ([8 + i * plane for i in range(c)], [plane] * c) if planar else ([8], [len(data)])
    entries = [(256, 4, [width]), (257, 4, [height]), (258, 3, [a.dtype.itemsize * 8] * c), (259, 3, [1]),
               (262, 3, [2 if c >= 3 else 1]), (273, 4, offsets), (277, 3, [c]), (278, 4, [height]),
               (279, 4, counts), (284, 3, [2 if planar else 1])]
    if c not in (1, 3):
        entries.append((338, 3, [extra_alpha] * (c - (3 if c > 3 else 1))))
    entries.append((339, 3, [{"u": 1, "i": 2, "f": 3}[a.dtype.kind]] * c))
    ifd_at = 8 + len(data) + (len(data) & 1)
    tail_at = ifd_at + 2 + 12 * len(entries) + 4
    ifd, tail = struct.pack(bo + "H", len(entries)), b""
    for tag, typ, values in entries:
        packed = struct.pack(bo + ("H" if typ == 3 else "I") * len(values), *values)
        if len(packed) <= 4:
            ifd += struct.pack(bo + "HHI", tag, typ, len(values)) + packed.ljust(4, b"\0")
        else:
            ifd += struct.pack(bo + "HHII", tag, typ, len(values), tail_at + len(tail))
            tail += packed
    head = (b"MM" if big_endian else b"II") + struct.pack(bo + "HI", 42, ifd_at)
    return head + data + b"\0" * (ifd_at - 8 - len(data)) + ifd + struct.pack(bo + "I", 0) + tail


def _exr(rgb, compression=OpenEXR.ZIP_COMPRESSION):
    with tempfile.TemporaryDirectory() as directory:
        path = os.path.join(directory, "x.exr")
        OpenEXR.File({"compression": compression, "type": OpenEXR.scanlineimage},
                     {"R": rgb[..., 0].copy(), "G": rgb[..., 1].copy(), "B": rgb[..., 2].copy()}).write(path)
        with open(path, "rb") as fh:
            return fh.read()


def _exr_header_end(data):
    """Offset of an EXR file's chunk offset table: after the attributes (name, type, size, value)
    and the empty name that ends them."""
    pos = 8
    while data[pos] != 0:
        type_end = data.index(b"\0", data.index(b"\0", pos) + 1)
        pos = type_end + 5 + struct.unpack("<i", data[type_end + 1:type_end + 5])[0]
    return pos + 1


def _hdr(rgbe, resolution=None):
    """A Radiance .hdr file of (H, W, 4) RGBE bytes, flat scanlines."""
    h, w = rgbe.shape[:2]
    res = resolution or f"-Y {h} +X {w}"
    return b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + res.encode() + b"\n" + np.asarray(rgbe, np.uint8).tobytes()


def _pil(a, fmt, **options):
    buf = io.BytesIO()
    Image.fromarray(a).save(buf, fmt, **options)
    return buf.getvalue()


def _write(directory, name, data):
    path = os.path.join(str(directory), name)
    with open(path, "wb") as fh:
        fh.write(data)
    return path


RNG = np.random.default_rng(32)
RGB8 = RNG.integers(0, 256, (9, 13, 3)).astype(np.uint8)
RGB16 = RNG.integers(0, 65536, (9, 13, 3)).astype(np.uint16)
RGBF = RNG.uniform(0, 4, (9, 13, 3)).astype(np.float32)
RGBE = np.concatenate([RNG.integers(0, 256, (9, 13, 3)), RNG.integers(120, 140, (9, 13, 1))], axis=2).astype(np.uint8)

#: small valid files of every format the engine reads: name → (suffix, bytes)
SEEDS = {
    "png8": (".png", _pil(RGB8, "PNG")),
    "png8_rgba": (".png", _pil(np.dstack([RGB8, RGB8[..., :1]]), "PNG")),
    "png16": (".png", _png16(RGB16)),
    "png16_grey_alpha": (".png", _png16(RGB16[..., :2])),
    "jpeg": (".jpg", _pil(RGB8, "JPEG", quality=90)),
    "tiff_u8_lzw": (".tif", _pil(RGB8, "TIFF", compression="tiff_lzw")),
    "tiff_u16": (".tif", _tiff(RGB16)),
    "tiff_f32": (".tif", _tiff(RGBF)),
    "tiff_i16_planar": (".tif", _tiff(RGB16.astype(np.int16), planar=True)),
    "exr": (".exr", _exr(RGBF)),
    "exr_piz": (".exr", _exr(RGBF, OpenEXR.PIZ_COMPRESSION)),
    "hdr": (".hdr", _hdr(RGBE)),
    "bmp": (".bmp", _pil(RGB8, "BMP")),
}


def _assert_one_scene_error(path, call, match=None):
    """``call()`` raises one SceneError whose message names ``path`` (and matches ``match``), in
    one line; returns the message."""
    with pytest.raises(SceneError) as info:
        call()
    message = str(info.value)
    assert os.path.basename(path) in message, message
    assert "\n" not in message, message
    if match:
        assert match in message, message
    return message


# --------------------------------------------------------------------------- broken 16-bit PNG streams

def _png16_cases():
    good = _png16(RGB16[:2, :3])
    idat_at = good.index(b"IDAT")
    flipped = bytearray(good)
    flipped[idat_at + 6] ^= 0xFF                                       # IDAT data no longer matches its CRC
    short_rows = _png(3, 2, 16, 2, zlib.compress(b"\0" + bytes(18)))  # one row of two
    return {
        "IDAT of 5 junk bytes": (_png(2, 1, 16, 2, b"\x01\x02\x03\x04\x05"), "corrupt 16-bit PNG data"),
        "cut inside IDAT": (good[:-20], "ends early"),
        "cut to half": (good[:len(good) // 2], "ends early"),
        "cut after IHDR": (good[:33], "ends early"),
        "CRC error in IDAT": (bytes(flipped), "CRC error"),
        "fewer rows than the header": (short_rows, "ends early"),
        "zlib stream cut short": (_png(3, 2, 16, 2, zlib.compress(b"\0" + bytes(18) * 2)[:-9]), "16-bit PNG"),
        "filter type 9": (_png(2, 1, 16, 2, zlib.compress(b"\x09" + bytes(12))), "row filter"),
        # (byte 24, where IHDR has the bit depth, says 16 in both: they reach the 16-bit decoder)
        "no IHDR first": (b"\x89PNG\r\n\x1a\n" + _chunk(b"tEXt", b"Comment\0\x10") + good[8:], "not IHDR"),
        "IHDR of 12 bytes": (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBB", 3, 2, 16, 2, 0, 0))
                             + good[33:], "bad IHDR"),
        "no IDAT": (good[:33] + _chunk(b"IEND", b""), "no image data"),
        "palette at 16 bits": (_png(2, 1, 16, 3, zlib.compress(bytes(5))), "unsupported PNG colour type 3"),
    }


@pytest.mark.parametrize("case", sorted(_png16_cases()))
def test_broken_png16_streams_are_one_scene_error(tmp_path, case):
    data, match = _png16_cases()[case]
    path = _write(tmp_path, "broken16.png", data)
    _assert_one_scene_error(path, lambda: read_image(path, "Non-Color", field="materials.m.albedo.texture"), match)
    _assert_one_scene_error(path, lambda: read_texture(path, "sRGB", field="materials.m.albedo.texture"), match)


def test_png16_cut_after_its_image_data_reads_exactly(tmp_path):
    """Only the IEND chunk cut (the issue's "last 8 bytes"): the pixels are complete, and read
    exactly, as Pillow reads an 8-bit PNG cut the same way."""
    codes = RGB16[:4, :5]
    path = _write(tmp_path, "cut.png", _png16(codes)[:-8])
    np.testing.assert_array_equal(read_image(path, "Non-Color"), (codes[::-1] / 65535.0).astype(np.float32))
    path8 = _write(tmp_path, "cut8.png", _pil(RGB8, "PNG")[:-8])
    np.testing.assert_array_equal(read_image(path8, "Non-Color"), (RGB8[::-1] / 255.0).astype(np.float32))


def _png16_adam7(codes):
    """An Adam7-interlaced 16-bit PNG (ISO/IEC 15948 §8.2): the seven passes' sub-images one after
    the other, each row with filter type 0."""
    h, w, c = codes.shape
    rows = b""
    for x0, y0, dx, dy in ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2),
                           (0, 1, 1, 2)):
        sub = codes[y0::dy, x0::dx]
        if sub.size:
            rows += b"".join(b"\0" + row.astype(">u2").tobytes() for row in sub)
    return _png(w, h, 16, {1: 0, 2: 4, 3: 2, 4: 6}[c], zlib.compress(rows), interlace=1)


def test_interlaced_png16_is_read_at_full_precision(tmp_path):
    """Adam7-interlaced 16-bit PNGs (legal; the hand decoder does not un-interlace) are read through
    OpenImageIO, at full precision; broken ones are one SceneError too."""
    for channels in (1, 3, 4):
        codes = RGB16[..., :channels] if channels <= 3 else np.dstack([RGB16, RGB16[..., :1]])
        path = _write(tmp_path, f"adam7_{channels}.png", _png16_adam7(codes))
        np.testing.assert_array_equal(read_image(path, "Non-Color"), (codes[::-1] / 65535.0).astype(np.float32))
    broken = _write(tmp_path, "adam7_cut.png", _png16_adam7(RGB16)[:120])
    _assert_one_scene_error(broken, lambda: read_image(broken, "Non-Color"))


# --------------------------------------------------------------------------- decompression-bomb headers

def _jpeg_claiming(width, height):
    data = bytearray(_pil(RGB8, "JPEG"))
    sof = data.index(b"\xff\xc0")                         # baseline frame header: length, precision, height, width
    data[sof + 5:sof + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def _bmp_claiming(width, height):
    data = bytearray(_pil(RGB8, "BMP"))
    data[18:26] = struct.pack("<ii", width, height)
    return bytes(data)


def _exr_claiming(width, height):
    data = bytearray(_exr(RGBF[:2, :2]))
    at = data.index(b"dataWindow\0box2i\0") + len(b"dataWindow\0box2i\0") + 4
    data[at:at + 16] = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    return bytes(data)


BOMBS = {
    "png8 100000²": (".png", lambda: _png(100000, 100000, 8, 2, zlib.compress(bytes(64))), "per side"),
    "png16 100000²": (".png", lambda: _png(100000, 100000, 16, 2, zlib.compress(bytes(64))), "per side"),
    "png8 20000² (under the side limit)": (".png", lambda: _png(20000, 20000, 8, 0, zlib.compress(bytes(64))),
                                           "in all"),
    "png16 32768 × 8193": (".png", lambda: _png(32768, 8193, 16, 0, zlib.compress(bytes(64))), "in all"),
    # (OpenImageIO refuses first a header beyond the machine's memory: 10 GB here, on a smaller machine)
    "tiff 100000²": (".tif", lambda: _tiff(RGB8[:1, :1, 0], size=(100000, 100000)), ("per side", "memory")),
    "tiff float 30000²": (".tif", lambda: _tiff(RGBF[:1, :1], size=(30000, 30000)), "in all"),
    "jpeg 65535²": (".jpg", lambda: _jpeg_claiming(65535, 65535), "per side"),
    "jpeg 20000 × 20000": (".jpg", lambda: _jpeg_claiming(20000, 20000), "in all"),
    "exr data window 100000²": (".exr", lambda: _exr_claiming(100000, 100000), "per side"),
    "hdr 100000²": (".hdr", lambda: _hdr(RGBE[:1, :1], "-Y 100000 +X 100000"), "per side"),
    "hdr columns 40000 × 9000": (".hdr", lambda: _hdr(RGBE[:1, :1], "+X 40000 -Y 9000"), "per side"),
    "bmp 100000²": (".bmp", lambda: _bmp_claiming(100000, 100000), "per side"),
}


@pytest.mark.parametrize("case", sorted(BOMBS))
def test_oversized_headers_are_refused_before_decoding(tmp_path, case):
    """A file of a few hundred bytes whose header claims more pixels than the limits is refused
    from its header: fast, with next to no memory (the pixels would take gigabytes), naming the
    limit that is exceeded."""
    suffix, make, which = BOMBS[case]
    data = make()
    assert len(data) < 2000
    path = _write(tmp_path, "bomb" + suffix, data)
    tracemalloc.start()
    start = time.perf_counter()
    try:
        message = _assert_one_scene_error(path, lambda: read_image(path, field="lights[0].image"), "over the limit")
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    assert time.perf_counter() - start < 2.0
    assert peak < 16 << 20, f"{peak / 2**20:.0f} MiB traced while refusing"
    which = [w for w in ((which,) if isinstance(which, str) else which) if w in message]
    assert which, message
    limit = {"per side": image_module.MAX_IMAGE_SIDE, "in all": image_module.MAX_IMAGE_PIXELS}.get(which[0], "MB")
    assert str(limit) in message


def test_the_limits_admit_real_textures_and_hdris():
    """16k × 8k HDRIs, 16k² textures and 32k × 8k panoramas pass; one more pixel per side or in
    all does not; an empty size is refused too."""
    for width, height in ((16384, 8192), (16384, 16384), (32768, 8192), (8192, 32768), (1, 1)):
        image_module._check_size("x.png", "f", width, height)
    for width, height, what in ((32769, 1, "per side"), (1, 32769, "per side"), (16385, 16384, "in all"),
                                (0, 5, "empty"), (5, 0, "empty")):
        with pytest.raises(SceneError, match=what):
            image_module._check_size("x.png", "f", width, height)


# --------------------------------------------------------------------------- undecodable EXR pixels

def _exr_cases():
    good = _exr(RGBF)
    header_end = _exr_header_end(good)
    # a smooth image, so that its ZIP chunk is stored compressed (noise would be stored raw)
    smooth = _exr(np.tile(np.linspace(0, 1, 13, dtype=np.float32)[None, :, None], (9, 1, 3)))
    first = struct.unpack("<Q", smooth[header_end:header_end + 8])[0]       # chunk: y, size, data
    size = struct.unpack("<i", smooth[first + 4:first + 8])[0]
    junk_chunk = bytearray(smooth)
    junk_chunk[first + 8:first + 8 + size] = RNG.integers(0, 256, size, dtype=np.uint8).tobytes()
    return {
        "last 8 bytes cut": good[:-8],
        "cut to half": good[:len(good) // 2],
        "cut after the header": good[:header_end],
        "data window grown to 64 × 64": _exr_claiming(64, 64),
        "compressed chunk overwritten with junk": bytes(junk_chunk),
        "magic number wrong": b"\x77\x2f\x31\x00" + good[4:],
        "junk": bytes(RNG.integers(0, 256, 300, dtype=np.uint8)),
    }


@pytest.mark.parametrize("case", sorted(_exr_cases()))
def test_undecodable_exr_is_one_scene_error(tmp_path, capsys, case):
    path = _write(tmp_path, "broken.exr", _exr_cases()[case])
    _assert_one_scene_error(path, lambda: read_image(path, field="lights[0].image"), "EXR")
    # the binding's printed warning became the message's reason instead of a stray line on stdout
    assert capsys.readouterr().out == ""


# --------------------------------------------------------------------------- TIFF sample formats

SAMPLE_TYPES = ("u1", "u2", "u4", "i1", "i2", "i4", "f2", "f4", "f8")


def _samples(dtype, shape, seed):
    """Values of ``dtype`` (H, W, C) including the type's extremes (the float ones within float16)."""
    dt, rng = np.dtype(dtype), np.random.default_rng(seed)
    if dt.kind == "f":
        a = rng.uniform(-3, 3, shape).astype(dt)
        a.flat[:3] = [0.5, -0.0, 60000.0]
    else:
        info = np.iinfo(dt)
        a = rng.integers(info.min, info.max, shape, dtype=dt, endpoint=True)
        a.flat[:3] = [info.min, info.max, (info.max >> 1) + 1]
    return a


def _oiio_value(a):
    """OpenImageIO's float value of samples: integers over their type's largest value (uint: the
    full range 2^bits − 1; int: 2^(bits−1) − 1, so the most negative code is a little below −1),
    floats as they are."""
    return a.astype(np.float64) / (np.iinfo(a.dtype).max if a.dtype.kind in "ui" else 1.0)


@pytest.mark.parametrize("dtype, channels, planar",
                         list(itertools.product(SAMPLE_TYPES, (1, 2, 3, 4), (False, True))))
def test_every_tiff_sample_format_reads_its_values(tmp_path, dtype, channels, planar):
    a = _samples(dtype, (5, 7, channels), seed=channels)
    path = _write(tmp_path, f"s_{dtype}_{channels}.tif", _tiff(a, planar=planar))
    got = read_image(path, "Non-Color")
    expect = _oiio_value(a)[::-1].astype(np.float32)
    assert got.shape == (5, 7, channels) and got.dtype == np.float32
    if a.dtype in (np.uint8, np.uint16) or a.dtype.kind == "f":
        np.testing.assert_array_equal(got, expect)               # exact: codes / full scale, floats as stored
    else:
        np.testing.assert_allclose(got, expect, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("dtype, channels, planar", [("u2", 3, False), ("f4", 1, False), ("i4", 4, True),
                                                     ("f8", 3, True), ("i1", 2, False)])
def test_big_endian_tiffs_read_the_same_values(tmp_path, dtype, channels, planar):
    a = _samples(dtype, (4, 6, channels), seed=7)
    little = read_image(_write(tmp_path, "le.tif", _tiff(a, planar=planar)), "Non-Color")
    big = read_image(_write(tmp_path, "be.tif", _tiff(a, planar=planar, big_endian=True)), "Non-Color")
    np.testing.assert_array_equal(big, little)


def test_the_issue_examples_read_their_values(tmp_path):
    """float32 grey 0.5 (read as 0 before), uint32 at 2³¹ (wrapped negative), int32 at 2³⁰ (1.1e10
    after sRGB decoding): 0.5 each as data; as colour (a TIFF's default is sRGB, as in Blender)
    sRGB-decoded 0.5."""
    cases = {"f32.tif": np.full((2, 3), 0.5, np.float32), "u32.tif": np.full((2, 3), 2 ** 31, np.uint32),
             "i32.tif": np.full((2, 3), 2 ** 30, np.int32)}
    for name, a in cases.items():
        path = _write(tmp_path, name, _tiff(a))
        np.testing.assert_allclose(read_image(path, "Non-Color"), 0.5, rtol=1e-6)
        np.testing.assert_allclose(read_image(path), srgb_to_linear(0.5), rtol=1e-6)
        encoded, space = read_texture(path)
        assert space == "srgb"
        np.testing.assert_allclose(encoded, 0.5, rtol=1e-6)


@pytest.mark.parametrize("compression", ["tiff_lzw", "tiff_adobe_deflate", "packbits", "raw"])
def test_compressed_tiffs_written_by_pillow(tmp_path, compression):
    path = _write(tmp_path, "c.tif", _pil(RGB8, "TIFF", compression=compression))
    np.testing.assert_array_equal(read_image(path, "Non-Color"), (RGB8[::-1] / 255.0).astype(np.float32))
    grey16 = RGB16[..., 0]
    path = _write(tmp_path, "g16.tif", _pil(grey16, "TIFF", compression=compression))
    np.testing.assert_array_equal(read_image(path, "Non-Color")[..., 0], (grey16[::-1] / 65535.0).astype(np.float32))
    # 8/16-bit TIFFs keep their integer codes for sRGB textures (filtered encoded, as PNG)
    encoded, _ = read_texture(path)
    assert encoded.dtype == np.uint16
    np.testing.assert_array_equal(encoded[..., 0], grey16[::-1])


def test_tiff_alpha_stays_straight_and_channels_past_four_are_left_out(tmp_path):
    rgba = np.dstack([RGB8, np.full(RGB8.shape[:2], 64, np.uint8)])
    got = read_image(_write(tmp_path, "a.tif", _tiff(rgba)), "Non-Color")
    np.testing.assert_array_equal(got, (rgba[::-1] / 255.0).astype(np.float32))      # not premultiplied
    five = np.dstack([RGBF, RGBF[..., :2]])
    got = read_image(_write(tmp_path, "five.tif", _tiff(five, extra_alpha=0)), "Non-Color")
    np.testing.assert_array_equal(got, five[::-1, :, :4])


def test_non_finite_pixels_become_zero_as_in_cycles(tmp_path):
    """A pixel with a NaN or infinite channel (or a double beyond float32) is 0 in every channel,
    as Cycles sets it; the others are untouched."""
    for dtype in (np.float32, np.float64):
        a = RGBF.astype(dtype)
        a[0, 0, 1], a[2, 3, 0], a[4, 4, 2] = np.nan, np.inf, -np.inf
        if dtype == np.float64:
            a[5, 5, 0] = 1e300
        got = read_image(_write(tmp_path, f"nan{np.dtype(dtype).itemsize}.tif", _tiff(a)), "Non-Color")[::-1]
        with np.errstate(over="ignore"):
            stored = a.astype(np.float32)
        bad = (~np.isfinite(stored)).any(axis=2)
        assert bad.sum() == (4 if dtype == np.float64 else 3)
        assert np.all(got[bad] == 0) and np.isfinite(got).all()
        np.testing.assert_array_equal(got[~bad], stored[~bad])
    rgb = RGBF.copy()
    rgb[1, 2, 2] = np.nan
    got = read_image(_write(tmp_path, "nan.exr", _exr(rgb)))[::-1]
    assert np.all(got[1, 2] == 0) and np.isfinite(got).all()


def test_tiff_without_openimageio_is_a_clear_error(tmp_path, monkeypatch):
    path = _write(tmp_path, "needs_oiio.tif", _tiff(RGB8))
    monkeypatch.setitem(sys.modules, "OpenImageIO", None)          # as if not installed
    _assert_one_scene_error(path, lambda: read_image(path, field="t"), "pip install openimageio")


# --------------------------------------------------------------------------- truncated and junk files

DAMAGE = {
    "empty": lambda data: b"",
    "signature only": lambda data: data[:8],
    "cut to a third": lambda data: data[:len(data) // 3],
    "cut to 70 %": lambda data: data[:len(data) * 7 // 10],
    "random bytes": lambda data: bytes(np.random.default_rng(len(data)).integers(0, 256, len(data), dtype=np.uint8)),
    "text": lambda data: b"this is not an image\n" * 5,
}


@pytest.mark.parametrize("damage", sorted(DAMAGE))
@pytest.mark.parametrize("seed", sorted(SEEDS))
def test_truncated_and_junk_files_of_every_format_are_one_scene_error(tmp_path, seed, damage):
    suffix, data = SEEDS[seed]
    path = _write(tmp_path, f"{seed}_damaged{suffix}", DAMAGE[damage](data))
    _assert_one_scene_error(path, lambda: read_image(path, field="materials.m.albedo.texture"))
    _assert_one_scene_error(path, lambda: read_texture(path, field="materials.m.albedo.texture"))


@pytest.mark.parametrize("seed", sorted(SEEDS))
def test_the_seed_files_are_valid(tmp_path, seed):
    """The fuzzer's starting points read as the images they were made from."""
    suffix, data = SEEDS[seed]
    got = read_image(_write(tmp_path, seed + suffix, data), "Non-Color")
    assert got.shape[:2] == (9, 13) and got.dtype == np.float32 and np.isfinite(got).all()


# --------------------------------------------------------------------------- fuzzing

_FUZZ_COUNTER = itertools.count()


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


@pytest.mark.fuzz
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.sampled_from(sorted(SEEDS)),
       cut=st.one_of(st.none(), st.integers(0, 1 << 16)),
       edits=st.lists(st.tuples(st.integers(0, 1 << 16), st.integers(0, 255)), max_size=8),
       color_space=st.sampled_from(["Non-Color", "sRGB"]))
def test_fuzzed_image_files_read_or_fail_cleanly(fuzz_dir, seed, cut, edits, color_space):
    """Random byte edits and truncations of small valid files of every format: read_image returns
    finite float32 pixels (H, W, 1–4) or raises SceneError naming the file, nothing else (no other
    exception, no NumPy warning).  The limits are lowered here so that an edited size field cannot
    make a decoder allocate gigabytes legitimately."""
    suffix, data = SEEDS[seed]
    data = bytearray(data)
    for pos, value in edits:
        data[pos % len(data)] = value
    if cut is not None:
        data = data[:cut % (len(data) + 1)]
    path = _write(fuzz_dir, f"f{next(_FUZZ_COUNTER)}{suffix}", bytes(data))
    with pytest.MonkeyPatch.context() as mp, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mp.setattr(image_module, "MAX_IMAGE_SIDE", 4096)
        mp.setattr(image_module, "MAX_IMAGE_PIXELS", 1 << 20)
        try:
            got = read_image(path, color_space, field="fuzz")
        except SceneError as e:
            assert os.path.basename(path) in str(e) or "fuzz" in str(e)
            got = None
        finally:
            os.remove(path)
    # junk values (signalling NaNs, overflows) do not leak NumPy's RuntimeWarnings to the terminal
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)]
    if got is None:
        return
    assert got.dtype == np.float32 and got.ndim == 3 and 1 <= got.shape[2] <= 4
    assert got.shape[0] >= 1 and got.shape[1] >= 1 and got.shape[0] * got.shape[1] <= 1 << 20
    assert np.isfinite(got).all()


# --------------------------------------------------------------------------- through the command line

def _demo_scene(directory, **changes):
    with open(os.path.join(REPO, "examples", "demo.json")) as fh:
        scene = json.load(fh)
    scene["camera"]["width"], scene["camera"]["height"] = 16, 8
    scene["render"]["spp"] = 1
    for key, value in changes.items():
        node = scene
        *parents, last = key.split(".")
        for part in parents:
            node = node[int(part)] if isinstance(node, list) else node[part]
        node[int(last) if isinstance(node, list) else last] = value
    path = os.path.join(str(directory), "scene.json")
    with open(path, "w") as fh:
        json.dump(scene, fh)
    return path


@pytest.mark.subprocess
def test_cli_render_with_a_broken_png_texture_is_one_error_line(tmp_path):
    """``python -m engine render scene.json -o out.exr`` with a texture whose PNG is cut short:
    exit status 2, one ``error:`` line naming the field and the file, no traceback, no output file."""
    _write(tmp_path, "broken.png", SEEDS["png8"][1][:200])
    scene = _demo_scene(tmp_path, **{"materials.chalk.albedo": {"texture": "broken.png"}})
    out = tmp_path / "out.exr"
    run = subprocess.run([sys.executable, "-m", "engine", "render", scene, "-o", str(out)], cwd=REPO,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr + run.stdout
    errors = [line for line in run.stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, run.stderr
    assert errors[0].startswith("error: materials.chalk.albedo.texture: ") and "broken.png" in errors[0]
    assert not out.exists()


@pytest.mark.parametrize("name, data", [("sky.exr", _exr(RGBF)[:-8]), ("sky.hdr", _hdr(RGBE)[:-50]),
                                        ("sky.tif", _tiff(RGBF)[:150])])
def test_cli_environment_map_that_cannot_be_read_is_one_error_line(tmp_path, capsys, name, data):
    from engine import cli

    _write(tmp_path, name, data)
    scene = _demo_scene(tmp_path, **{"lights.0": {"type": "environment", "image": name}})
    with contextlib.redirect_stdout(io.StringIO()):
        status = cli.main(["render", scene, "-o", str(tmp_path / "out.exr")])
    err = capsys.readouterr().err
    assert status == 2 and "Traceback" not in err
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and errors[0].startswith("error: lights[0].image: ") and name in errors[0], err
