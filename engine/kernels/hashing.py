"""Counter-based uniform random numbers: splitmix64's finaliser of (path key + dimension), and the
path keys themselves (engine.render.sampler) with a path's first dimensions in the same pass."""

from __future__ import annotations

import numpy as np

from . import jit, twin

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_S30, _S27, _S31, _S11 = (np.uint64(v) for v in (30, 27, 31, 11))
_TO_UNIT = 1.0 / float(1 << 53)


def mix64(x: np.ndarray) -> np.ndarray:
    """splitmix64 finaliser on uint64 arrays (wrapping arithmetic)."""
    x = (x ^ (x >> _S30)) * _M1
    x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


def uniforms_numpy(keys: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(k, N) floats in [0, 1): the top 53 bits of mix64(key + offset_j) for each dimension offset."""
    out = np.empty((offsets.shape[0], keys.shape[0]))
    for j in range(offsets.shape[0]):
        h = mix64(keys + offsets[j])
        out[j] = (h >> _S11).astype(np.float64) * _TO_UNIT
    return out


@jit
def _uniforms_loop(keys, offsets, out):
    for i in range(keys.shape[0]):
        for j in range(offsets.shape[0]):
            x = keys[i] + offsets[j]
            x = (x ^ (x >> _S30)) * _M1
            x = (x ^ (x >> _S27)) * _M2
            x = x ^ (x >> _S31)
            out[j, i] = np.float64(x >> _S11) * _TO_UNIT


def uniforms_numba(keys: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    out = np.empty((offsets.shape[0], keys.shape[0]))
    _uniforms_loop(np.ascontiguousarray(keys, dtype=np.uint64), offsets, out)
    return out


uniforms = twin(_uniforms_loop and uniforms_numba, uniforms_numpy)



def path_keys_and_uniforms_numpy(seed_key: np.ndarray, pixel: np.ndarray, sample: np.ndarray,
                                 offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-path keys (N,) = mix64(mix64(seed_key ^ pixel·φ) + sample·M2) for the render's mixed
    seed ``seed_key`` (uint64 (1,)), pixel and sample indices (N,), and the path's first
    dimensions (k, N) = uniforms(keys, offsets): the camera stage's random numbers in one pass."""
    k = mix64(seed_key ^ (pixel.astype(np.uint64) * _GOLDEN))
    keys = mix64(k + sample.astype(np.uint64) * _M2)
    return keys, uniforms_numpy(keys, offsets)


@jit
def _keys_and_uniforms_loop(seed_key, pixel, sample, offsets, keys, out):
    s = seed_key[0]
    for i in range(pixel.shape[0]):
        x = s ^ (np.uint64(pixel[i]) * _GOLDEN)
        x = (x ^ (x >> _S30)) * _M1
        x = (x ^ (x >> _S27)) * _M2
        x = x ^ (x >> _S31)
        x = x + np.uint64(sample[i]) * _M2
        x = (x ^ (x >> _S30)) * _M1
        x = (x ^ (x >> _S27)) * _M2
        key = x ^ (x >> _S31)
        keys[i] = key
        for j in range(offsets.shape[0]):
            x = key + offsets[j]
            x = (x ^ (x >> _S30)) * _M1
            x = (x ^ (x >> _S27)) * _M2
            x = x ^ (x >> _S31)
            out[j, i] = np.float64(x >> _S11) * _TO_UNIT


def path_keys_and_uniforms_numba(seed_key: np.ndarray, pixel: np.ndarray, sample: np.ndarray,
                                 offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = pixel.shape[0]
    keys = np.empty(n, np.uint64)
    out = np.empty((offsets.shape[0], n))
    _keys_and_uniforms_loop(np.asarray(seed_key, np.uint64), np.ascontiguousarray(pixel, np.int64),
                            np.ascontiguousarray(sample, np.int64), offsets, keys, out)
    return keys, out


path_keys_and_uniforms = twin(_keys_and_uniforms_loop and path_keys_and_uniforms_numba,
                              path_keys_and_uniforms_numpy)
