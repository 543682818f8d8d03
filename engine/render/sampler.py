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

from ..kernels.hashing import mix64, uniforms

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M2 = np.uint64(0x94D049BB133111EB)
_MASK64 = (1 << 64) - 1


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
        dims = range(self.dimension + 1, self.dimension + k + 1)
        self.dimension += k
        offsets = np.array([(d * 0x9E3779B97F4A7C15) & _MASK64 for d in dims], dtype=np.uint64)
        return uniforms(self.keys, offsets)

    def compact(self, keep: np.ndarray):
        self.keys = self.keys[keep]
