"""Minimal 8-bit PNG writer and reader (zlib + struct, no imaging library).

Images are uint8 arrays, (H, W, 3) RGB or (H, W) grey, row 0 at the top.
Pixel values are written as given (already sRGB-encoded by the caller); no
colour-space chunk is added, which viewers interpret as sRGB.
"""

from __future__ import annotations

import os
import struct
import zlib

import numpy as np

from . import atomic_output_path

_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_COLOUR_TYPES = {2: 3, 0: 1}  # PNG colour type -> samples per pixel (RGB, grey)


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def encode_png(image) -> bytes:
    """PNG bytes of a uint8 (H, W, 3) RGB or (H, W) grey image (filter 0, zlib level 6)."""
    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise ValueError(f"PNG image must be uint8; got {a.dtype}")
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 3)) or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"PNG image must have shape (H, W, 3) or (H, W) with H, W >= 1; got {a.shape}")
    height, width = a.shape[:2]
    colour_type = 2 if a.ndim == 3 else 0
    rows = a.reshape(height, -1)
    raw = np.concatenate([np.zeros((height, 1), np.uint8), rows], axis=1)  # filter byte 0 per row
    ihdr = struct.pack(">IIBBBBB", width, height, 8, colour_type, 0, 0, 0)
    return (_SIGNATURE + _chunk(b"IHDR", ihdr)
            + _chunk(b"IDAT", zlib.compress(raw.tobytes(), 6)) + _chunk(b"IEND", b""))


def write_png(path: str | os.PathLike, image) -> None:
    """Write a uint8 (H, W, 3) RGB or (H, W) grey image as PNG, atomically (temp file + rename)."""
    data = encode_png(image)
    with atomic_output_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)


def _unfilter(raw: np.ndarray, height: int, stride: int, bpp: int) -> np.ndarray:
    """Undo PNG per-row filters (0 None, 1 Sub, 2 Up, 3 Average, 4 Paeth)."""
    rows = raw.reshape(height, stride + 1)
    out = np.zeros((height, stride), np.uint8)
    prev = np.zeros(stride, np.int32)
    for y in range(height):
        ftype, line = rows[y, 0], rows[y, 1:].astype(np.int32)
        if ftype == 0:
            cur = line
        elif ftype == 1:  # Sub: cumulative sum per channel over pixels
            cur = np.cumsum(line.reshape(-1, bpp), axis=0).reshape(-1) % 256
        elif ftype == 2:
            cur = (line + prev) % 256
        elif ftype in (3, 4):
            cur = np.zeros(stride, np.int32)
            for i in range(stride):
                left = cur[i - bpp] if i >= bpp else 0
                up, upleft = prev[i], (prev[i - bpp] if i >= bpp else 0)
                if ftype == 3:
                    pred = (left + up) // 2
                else:
                    p = left + up - upleft
                    pa, pb, pc = abs(p - left), abs(p - up), abs(p - upleft)
                    pred = left if pa <= pb and pa <= pc else (up if pb <= pc else upleft)
                cur[i] = (line[i] + pred) % 256
        else:
            raise ValueError(f"PNG: unknown filter type {ftype} in row {y}")
        out[y] = cur
        prev = cur.astype(np.int32)
    return out


def read_png(path: str | os.PathLike) -> np.ndarray:
    """Decode an 8-bit, non-interlaced RGB or grey PNG to uint8 (H, W, 3) or (H, W).

    Meant for tests; other PNG variants raise ValueError.  Chunk CRCs are checked.
    """
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != _SIGNATURE:
        raise ValueError(f"{os.fspath(path)}: not a PNG file")
    pos, idat, ihdr = 8, [], None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack(">I", data[pos + 8 + length:pos + 12 + length])
        if zlib.crc32(kind + body) != crc:
            raise ValueError(f"PNG: CRC mismatch in {kind!r} chunk")
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            break
        pos += 12 + length
    if ihdr is None:
        raise ValueError("PNG: missing IHDR")
    width, height, depth, colour_type, _, _, interlace = ihdr
    if depth != 8 or colour_type not in _COLOUR_TYPES or interlace != 0:
        raise ValueError(f"PNG: unsupported depth {depth} / colour type {colour_type} / interlace {interlace}")
    bpp = _COLOUR_TYPES[colour_type]
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), np.uint8)
    pixels = _unfilter(raw, height, width * bpp, bpp)
    return pixels.reshape(height, width, 3) if bpp == 3 else pixels.reshape(height, width)
