"""Counter-based uniform random numbers: splitmix64's finaliser of (path key + dimension)."""

from __future__ import annotations

import numpy as np

from . import jit, twin

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
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
