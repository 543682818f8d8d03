"""Stateless, counter-based random numbers for paths.

Every random number is a hash of (seed, pixel, sample index, dimension), so a
render is bit-for-bit reproducible whatever the batching, tiling, number of
workers or resumption order: sample s of pixel p always sees the same
numbers.  The hash is splitmix64's finaliser (Steele et al. 2014), which
passes BigCrush as a counter-based generator; 53 bits are turned into a
float64 in [0, 1).
"""

from __future__ import annotations

import functools

import numpy as np

from ..kernels.hashing import mix64, path_keys_and_uniforms, uniforms

_MASK64 = (1 << 64) - 1


def _seed_key(seed: int) -> np.ndarray:
    """The render seed mixed into a 64-bit key (uint64 (1,))."""
    return mix64(np.asarray([(seed * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) & _MASK64], dtype=np.uint64))


@functools.lru_cache(maxsize=256)
def _offsets(first: int, k: int) -> np.ndarray:
    """Hash offsets of dimensions first+1 … first+k (shared: callers only read them).  Cached: every
    batch asks for the same few at each bounce, and building them from Python integers cost about
    as much as hashing them (a read-only flag would make Numba compile the kernels again for it)."""
    return np.array([(d * 0x9E3779B97F4A7C15) & _MASK64 for d in range(first + 1, first + k + 1)], dtype=np.uint64)


def path_keys(seed: int, pixel: np.ndarray, sample: np.ndarray) -> np.ndarray:
    """Per-path 64-bit keys from the render seed, pixel index and sample index."""
    return path_keys_and_uniforms(_seed_key(seed), pixel, sample, _offsets(0, 0))[0]


class PathSampler:
    """Random numbers for a batch of paths that all sit at the same bounce.

    ``next(k)`` returns k fresh dimensions, shape (k, N), for the current keys; ``skip(k)`` passes
    over k dimensions nobody reads (the numbers are stateless in the dimension, so the following
    ones are those ``next(k)`` would have left); ``compact(mask)`` keeps the surviving paths' keys.
    """

    def __init__(self, keys: np.ndarray):
        self.keys = keys
        self.dimension = 0

    @classmethod
    def start(cls, seed: int, pixel: np.ndarray, sample: np.ndarray, k: int) -> tuple[PathSampler, np.ndarray]:
        """The sampler of paths (pixel, sample) (N,) and their first k dimensions (k, N), the same
        numbers as ``PathSampler(path_keys(seed, pixel, sample)).next(k)``, in one pass."""
        keys, u = path_keys_and_uniforms(_seed_key(seed), pixel, sample, _offsets(0, k))
        sampler = cls(keys)
        sampler.dimension = k
        return sampler, u

    def next(self, k: int = 1) -> np.ndarray:
        offsets = _offsets(self.dimension, k)
        self.dimension += k
        return uniforms(self.keys, offsets)

    def skip(self, k: int) -> None:
        """Advance past k dimensions without computing them."""
        self.dimension += k

    def compact(self, keep: np.ndarray):
        self.keys = self.keys[keep]
