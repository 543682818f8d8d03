"""Stateless, counter-based random numbers for paths.

Every random number is a hash of (seed, pixel, sample index, dimension), so a
render is bit-for-bit reproducible whatever the batching, tiling, number of
workers or resumption order: sample s of pixel p always sees the same
numbers.  The hash is splitmix64's finaliser (Steele et al. 2014), which
passes BigCrush as a counter-based generator; 53 bits are turned into a
float64 in [0, 1).
"""

from __future__ import annotations

import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = (np.uint64(v) for v in (30, 27, 31, 11))
_TO_UNIT = 1.0 / float(1 << 53)
_MASK64 = (1 << 64) - 1


def mix64(x: np.ndarray) -> np.ndarray:
    """splitmix64 finaliser on uint64 arrays (wrapping arithmetic)."""
    x = (x ^ (x >> _S30)) * _M1
    x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


def path_keys(seed: int, pixel: np.ndarray, sample: np.ndarray) -> np.ndarray:
    """Per-path 64-bit keys from the render seed, pixel index and sample index."""
    s = mix64(np.asarray([(seed * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) & _MASK64], dtype=np.uint64))
    k = mix64(s ^ (pixel.astype(np.uint64) * _GOLDEN))
    return mix64(k + sample.astype(np.uint64) * _M2)


class PathSampler:
    """Random numbers for a batch of paths that all sit at the same bounce.

    ``next(k)`` returns k fresh dimensions, shape (k, N), for the current keys;
    ``compact(mask)`` keeps the surviving paths' keys.
    """

    def __init__(self, keys: np.ndarray):
        self.keys = keys
        self.dimension = 0

    def next(self, k: int = 1) -> np.ndarray:
        out = np.empty((k, self.keys.shape[0]))
        for j in range(k):
            self.dimension += 1
            h = mix64(self.keys + np.uint64((self.dimension * 0x9E3779B97F4A7C15) & _MASK64))
            out[j] = (h >> _S11).astype(np.float64) * _TO_UNIT
        return out

    def compact(self, keep: np.ndarray):
        self.keys = self.keys[keep]
