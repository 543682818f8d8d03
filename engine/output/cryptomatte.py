"""Cryptomatte identifiers, rank/coverage layers and manifests, as Cycles and Blender write them.

A name (object, material or asset) becomes its 32-bit MurmurHash3 (x86_32, seed 0) of the UTF-8 bytes
(``murmurhash3_32``), and that hash the float32 whose bits it is, with the exponent clamped to [1, 254] so
that it is never zero, denormal, infinite or NaN (``hash_to_float``: Cycles' ``util_hash_to_float``, the
Cryptomatte specification's "uint32_to_float32").  A layer of L levels is ⌈L/2⌉ RGBA passes
``<Layer>00``, ``<Layer>01``, …; pass k holds the ids and coverages of ranks 2k, 2k + 1 as
(r, g, b, a) = (id₂ₖ, coverage₂ₖ, id₂ₖ₊₁, coverage₂ₖ₊₁), ranks by decreasing coverage, empty ranks 0.
The metadata of a layer named N (Blender: ``<ViewLayer>.CryptoObject``; a standalone file: ``CryptoObject``)
are the four header strings ``cryptomatte/<first 7 hex digits of the hash of N>/name|hash|conversion|manifest``,
the manifest a JSON object {name: "8-digit hex hash"} (``layer_metadata``).
"""

from __future__ import annotations

import json
import struct

import numpy as np

#: Cycles' Cryptomatte kinds: (layer suffix, what is hashed)
KINDS = {"object": "CryptoObject", "material": "CryptoMaterial", "asset": "CryptoAsset"}
#: Blender's Cryptomatte levels (View Layer ▸ Cryptomatte ▸ Levels) range
LEVELS_RANGE = (2, 16)
#: the name Cycles hashes for a surface without a material
DEFAULT_MATERIAL = "default_surface"

_C1, _C2 = 0xCC9E2D51, 0x1B873593
_M32 = 0xFFFFFFFF


def _rotl(x: int, r: int) -> int:
    return ((x << r) | (x >> (32 - r))) & _M32


def murmurhash3_32(data: bytes | str, seed: int = 0) -> int:
    """MurmurHash3_x86_32 of ``data`` (a str is hashed as its UTF-8 bytes) with ``seed``: an int in [0, 2³²)."""
    if isinstance(data, str):
        data = data.encode("utf-8")
    h = seed & _M32
    n = len(data)
    blocks = n // 4
    for (k,) in struct.iter_unpack("<I", data[:blocks * 4]):
        k = (_rotl((k * _C1) & _M32, 15) * _C2) & _M32
        h = (_rotl(h ^ k, 13) * 5 + 0xE6546B64) & _M32
    tail = data[blocks * 4:]
    k = 0
    if len(tail) >= 3:
        k ^= tail[2] << 16
    if len(tail) >= 2:
        k ^= tail[1] << 8
    if len(tail) >= 1:
        k ^= tail[0]
        k = (_rotl((k * _C1) & _M32, 15) * _C2) & _M32
        h ^= k
    h ^= n
    h ^= h >> 16
    h = (h * 0x85EBCA6B) & _M32
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & _M32
    h ^= h >> 16
    return h


def hash_to_float(h: int) -> np.float32:
    """The float32 of a 32-bit hash (Cycles' util_hash_to_float): sign and mantissa bits kept, the exponent
    clamped to [1, 254]."""
    h = int(h) & _M32
    exponent = min(max((h >> 23) & 0xFF, 1), 254)
    bits = (h & 0x807FFFFF) | (exponent << 23)
    return np.frombuffer(struct.pack("<I", bits), np.float32)[0]


def name_id(name: str) -> np.float32:
    """The Cryptomatte id (float32) of ``name``."""
    return hash_to_float(murmurhash3_32(name))


def manifest(names) -> str:
    """The manifest of ``names`` (each once, in order): JSON {"name": "hex hash", …} as Cycles writes it."""
    items = [f"{json.dumps(n, ensure_ascii=False)}:\"{murmurhash3_32(n):08x}\"" for n in dict.fromkeys(names)]
    return "{" + ",".join(items) + "}"


def layer_metadata(layer: str, names) -> dict:
    """The header strings of the Cryptomatte layer ``layer`` (e.g. "ViewLayer.CryptoObject") holding ``names``."""
    prefix = f"cryptomatte/{murmurhash3_32(layer):08x}"[:len("cryptomatte/") + 7] + "/"
    return {prefix + "name": layer, prefix + "hash": "MurmurHash3_32", prefix + "conversion": "uint32_to_float32",
            prefix + "manifest": manifest(names)}


def check_levels(levels) -> int:
    """``levels`` as an int in LEVELS_RANGE, or a ValueError naming the field."""
    lo, hi = LEVELS_RANGE
    if isinstance(levels, bool) or not isinstance(levels, (int, np.integer)) or not lo <= levels <= hi:
        raise ValueError(f"cryptomatte_levels must be an integer in [{lo}, {hi}], got {levels!r}")
    return int(levels)


def pass_count(levels: int) -> int:
    """RGBA passes of a layer of ``levels`` ranks (Cycles: ⌈levels / 2⌉)."""
    return (check_levels(levels) + 1) // 2


def ranked(pixel: np.ndarray, ident: np.ndarray, weight: np.ndarray, n_pixels: int, slots: int) -> tuple:
    """(ids (n_pixels, slots) float32, coverage (n_pixels, slots) float64) from matte samples: the summed
    ``weight`` of each (pixel, id index ``ident``) pair, ranked by decreasing coverage per pixel (ties by id
    index); ``ident`` indexes the caller's id table, returned as an index array (−1: empty rank)."""
    ids = np.full((n_pixels, slots), -1, np.int64)
    cover = np.zeros((n_pixels, slots))
    if pixel.size == 0:
        return ids, cover
    n_ids = int(ident.max()) + 1
    key = pixel.astype(np.int64) * n_ids + ident
    unique, inverse = np.unique(key, return_inverse=True)
    total = np.bincount(inverse, weights=weight, minlength=unique.size)
    upix, uid = unique // n_ids, unique % n_ids
    order = np.lexsort((uid, -total, upix))
    upix, uid, total = upix[order], uid[order], total[order]
    first = np.searchsorted(upix, upix, side="left")
    rank = np.arange(upix.size) - first
    keep = (rank < slots) & (total > 0)
    ids[upix[keep], rank[keep]] = uid[keep]
    cover[upix[keep], rank[keep]] = total[keep]
    return ids, cover


def layer_passes(ids: np.ndarray, cover: np.ndarray, id_values: np.ndarray, levels: int) -> list[np.ndarray]:
    """The RGBA passes (H, W, 4) float32 of a layer: ``ids`` (H, W, slots) id indices (−1 empty) into
    ``id_values`` (the float32 ids), ``cover`` their coverage; 2·⌈levels/2⌉ ranks kept (as Cycles, whose
    passes hold two ranks each: odd levels keep one more)."""
    H, W = ids.shape[:2]
    out = []
    values = np.append(np.asarray(id_values, np.float32), np.float32(0.0))     # index −1 → 0
    for k in range(pass_count(levels)):
        p = np.zeros((H, W, 4), np.float32)
        for j in (0, 1):
            rank = 2 * k + j
            if rank < ids.shape[2]:
                p[..., 2 * j] = values[ids[..., rank]]
                p[..., 2 * j + 1] = cover[..., rank]
        out.append(p)
    return out
