"""Counter-based uniform random numbers: splitmix64's finaliser of (path key + dimension), and the
path keys themselves (engine.render.sampler) with a path's first dimensions in the same pass."""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner, twin

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


@jit_inner
def _mix64_one(x):
    """mix64 of one uint64 (the compiled loops' copy of the finaliser)."""
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
            x = _mix64_one(keys[i] + offsets[j])
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
        key = _mix64_one(_mix64_one(s ^ (np.uint64(pixel[i]) * _GOLDEN)) + np.uint64(sample[i]) * _M2)
        keys[i] = key
        for j in range(offsets.shape[0]):
            x = _mix64_one(key + offsets[j])
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


def scrambled_sobol_pair_numpy(seed_key: np.ndarray, pixel: np.ndarray, sample: np.ndarray, pair_key: np.ndarray,
                               vx: np.ndarray, vy: np.ndarray, u0: np.ndarray, u1: np.ndarray):
    """Two numbers (2 × (N,)) in [0, 1) per path: the 32-bit Sobol' points of index sample // 2 with
    direction numbers vx, vy (32,) (uint64), XOR-scrambled by mix64(seed_key ^ pixel·pair_key ^
    (sample & 1)·φ) (low and high 32 bits), plus u0, u1 (N,) below 2^-32 (engine.render.sampler.stratified_pair)."""
    i = (sample.astype(np.uint64) >> np.uint64(1)) & np.uint64(0xFFFFFFFF)
    x, y = np.zeros_like(i), np.zeros_like(i)
    for j in range(int(i.max()).bit_length() if i.size else 0):
        on = ((i >> np.uint64(j)) & np.uint64(1)).astype(bool)
        x[on] ^= vx[j]
        y[on] ^= vy[j]
    half = (sample.astype(np.uint64) & np.uint64(1)) * _GOLDEN
    keys = mix64(seed_key[0] ^ (pixel.astype(np.uint64) * pair_key[0]) ^ half)
    mx = keys & np.uint64(0xFFFFFFFF)
    my = keys >> np.uint64(32)
    scale = 1.0 / 4294967296.0
    below_one = np.nextafter(1.0, 0.0)      # (2^32 − 1 + u) · 2^-32 can round up to 1
    return (np.minimum(((x ^ mx).astype(np.float64) + u0) * scale, below_one),
            np.minimum(((y ^ my).astype(np.float64) + u1) * scale, below_one))


@jit
def _sobol_pair_loop(seed_key, pixel, sample, pair_key, vx, vy, u0, u1, out):
    s, pk = seed_key[0], pair_key[0]
    low = np.uint64(0xFFFFFFFF)
    scale = 1.0 / 4294967296.0
    below_one = np.nextafter(1.0, 0.0)
    for n in range(pixel.shape[0]):
        smp = np.uint64(sample[n])
        i = (smp >> np.uint64(1)) & low
        x = np.uint64(0)
        y = np.uint64(0)
        j = 0
        while i != np.uint64(0):
            if i & np.uint64(1):
                x ^= vx[j]
                y ^= vy[j]
            i >>= np.uint64(1)
            j += 1
        h = _mix64_one(s ^ (np.uint64(pixel[n]) * pk) ^ ((smp & np.uint64(1)) * _GOLDEN))
        out[0, n] = min((np.float64(x ^ (h & low)) + u0[n]) * scale, below_one)
        out[1, n] = min((np.float64(y ^ (h >> np.uint64(32))) + u1[n]) * scale, below_one)


def scrambled_sobol_pair_numba(seed_key: np.ndarray, pixel: np.ndarray, sample: np.ndarray, pair_key: np.ndarray,
                               vx: np.ndarray, vy: np.ndarray, u0: np.ndarray, u1: np.ndarray):
    out = np.empty((2, pixel.shape[0]))
    _sobol_pair_loop(np.asarray(seed_key, np.uint64), np.ascontiguousarray(pixel, np.int64),
                     np.ascontiguousarray(sample, np.int64), np.asarray(pair_key, np.uint64), vx, vy,
                     np.ascontiguousarray(u0, np.float64), np.ascontiguousarray(u1, np.float64), out)
    return out[0], out[1]


scrambled_sobol_pair = twin(_sobol_pair_loop and scrambled_sobol_pair_numba, scrambled_sobol_pair_numpy)
