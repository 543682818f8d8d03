"""Owen-scrambled, shuffled Sobol' pairs: the "sobol" sampler's numbers (engine.render.sampler.sobol_pairs).

Every pair of dimensions d of a sample is a point of the 2-D Sobol' (0, 2)-sequence (dimensions 1–2: the
van der Corput radical inverse and the first primitive polynomial's dimension) as in pbrt-v4's
``PaddedSobolSampler`` and Burley 2020 ("Practical Hash-based Owen Scrambling", JCGT 9(4)):

- the index i = sample // 2 is *shuffled* by a nested uniform scramble of its bits (output bit k
  depends on input bits ≥ k only, so every aligned block of 2^m indices maps to an aligned block of
  2^m indices: the first 2^m samples of a pixel are still a whole block of the (0, 2)-sequence, a
  (0, m, 2)-net); the shuffle differs per (seed, pixel, parity, pair), which decorrelates the pairs
  ("padding": each pair of a sample sits at a different place of its own sequence);
- both coordinates are Owen-scrambled (nested uniform scrambling of the binary digits: digit k flipped
  by a random function of the digits above it; still a (0, m, 2)-net, and every point uniform on [0, 1)²)
  with seeds per (seed, pixel, parity, pair);
- the even and the odd samples (parity = sample & 1) are two independently scrambled sequences (index
  sample // 2): adaptive sampling's half-buffers A (even) and B (odd) are independent estimates;
- optionally (the "padded" sampler's pairs other than the jitter) a random XOR of both coordinates, a digital
  shift, instead of the Owen scramble (still a (0, m, 2)-net and uniform);
- the 16 bits below 2^-32 are a random offset per (seed, pixel, parity, pair) (a sub-resolution shift:
  the numbers are exactly uniform on the 2^-48 grid, not confined to the 2^-32 one); every number is < 1.

The scramble is pbrt-v4's ``FastOwenScrambler`` (Laine–Karras permutation with Vegdahl's constants)
on the bit-reversed value: a bijection of 32-bit integers in which bit k depends only on bits ≤ k, i.e.
after the reversal a nested scramble.  All arithmetic is on uint64 holding 32-bit values (the NumPy
twin and the compiled loop give the same bits).  Numbers are functions of (seed key, pixel, sample,
pair) only: order-, batch- and resumption-independent.
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner, twin
from .hashing import _mix64_one, mix64

_M32 = np.uint64(0xFFFFFFFF)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
#: key constants: this sampler's salt (its keys differ from the path keys of engine.kernels.hashing), the
#: parity, the pair index, the second seed word
_SALT = np.uint64(0x2545F4914F6CDD1D)
_PARITY = np.uint64(0xD6E8FEB86659FD93)
_PAIR = np.uint64(0xA0761D6478BD642F)
_SECOND = np.uint64(0xE7037ED1A0B428DB)
#: key constant of the XOR-scrambled pairs' digital shift
_XOR = np.uint64(0x7FB5D329728EA185)
#: the FastOwenScrambler's multipliers
_C1, _C2, _C3 = np.uint64(0x3D20ADEA), np.uint64(0x05526C56), np.uint64(0x53A22864)
_B1, _B2, _B4, _B8, _B16 = (np.uint64(v) for v in (0x55555555, 0x33333333, 0x0F0F0F0F, 0x00FF00FF, 0xFFFF))
_S1, _S2, _S4, _S8, _S16, _S24, _S32, _S48 = (np.uint64(v) for v in (1, 2, 4, 8, 16, 24, 32, 48))
_LOW16 = np.uint64(0xFFFF)
_TO_UNIT = 1.0 / float(1 << 48)


def _reverse32_py(x: int) -> int:
    return int(f"{x:032b}"[::-1], 2)


def _reversed_sobol2_tables() -> np.ndarray:
    """(4, 256) uint64: byte b of the index → the bit-reversed XOR of Sobol' dimension 2's direction
    numbers of that byte's set bits (v_0 = 2^31, v_k = v_(k−1) ^ (v_(k−1) >> 1)): reverse(sobol2(i)) is
    the XOR of the four bytes' entries."""
    v = [1 << 31]
    for _ in range(31):
        v.append(v[-1] ^ (v[-1] >> 1))
    rv = [_reverse32_py(x) for x in v]
    table = np.zeros((4, 256), np.uint64)
    for b in range(4):
        for byte in range(256):
            acc = 0
            for t in range(8):
                if (byte >> t) & 1:
                    acc ^= rv[8 * b + t]
            table[b, byte] = acc
    return table


#: reverse(sobol2(i)) by bytes (see _reversed_sobol2_tables)
SOBOL2_REVERSED = _reversed_sobol2_tables()


def reverse32(x: np.ndarray) -> np.ndarray:
    """Bit reversal of 32-bit values held in uint64 arrays."""
    x = ((x >> _S1) & _B1) | ((x & _B1) << _S1)
    x = ((x >> _S2) & _B2) | ((x & _B2) << _S2)
    x = ((x >> _S4) & _B4) | ((x & _B4) << _S4)
    x = ((x >> _S8) & _B8) | ((x & _B8) << _S8)
    return (x >> _S16) | ((x & _B16) << _S16)


def owen_permute(r: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """pbrt-v4's FastOwenScrambler body on bit-reversed 32-bit values r (uint64 arrays): output bit k
    depends on bits ≤ k of r (a nested scramble of reverse(r)'s digits)."""
    r = r ^ ((r * _C1) & _M32)
    r = (r + seed) & _M32
    r = (r * ((seed >> _S16) | _S1)) & _M32
    r = r ^ ((r * _C2) & _M32)
    return r ^ ((r * _C3) & _M32)


def owen_sobol_pairs_numpy(seed_key: np.ndarray, pixel: np.ndarray, sample: np.ndarray,
                           pairs: np.ndarray, owen: np.ndarray | None = None) -> np.ndarray:
    """(2k, N) numbers in [0, 1): rows 2m, 2m + 1 are pair ``pairs[m]`` (int64 (k,)) of sample ``sample``
    (N,) of pixel ``pixel`` (N,) for the render's mixed seed ``seed_key`` (uint64 (1,)) (module docstring);
    ``owen`` (bool (k,), default all True): pair m Owen-scrambled, else XOR-scrambled (a random digital shift
    of both coordinates per (seed, pixel, parity, pair): the points keep the sequence's exact digit structure,
    lower variance than Owen's on smooth integrands)."""
    n = pixel.shape[0]
    out = np.empty((2 * pairs.shape[0], n))
    smp = sample.astype(np.uint64)
    i = (smp >> _S1) & _M32
    base = mix64((seed_key[0] ^ (pixel.astype(np.uint64) * _GOLDEN) ^ ((smp & _S1) * _PARITY)) + _SALT)
    ri = reverse32(i)
    for m in range(pairs.shape[0]):
        h = mix64(base + np.uint64(((int(pairs[m]) + 1) * int(_PAIR)) & 0xFFFFFFFFFFFFFFFF))
        h2 = mix64(h ^ _SECOND)
        j = reverse32(owen_permute(ri, h & _M32))                  # the shuffled index
        ry = (SOBOL2_REVERSED[0][j & np.uint64(255)] ^ SOBOL2_REVERSED[1][(j >> _S8) & np.uint64(255)]
              ^ SOBOL2_REVERSED[2][(j >> _S16) & np.uint64(255)] ^ SOBOL2_REVERSED[3][j >> _S24])
        if owen is None or owen[m]:                                 # Owen's scramble of each coordinate
            x, y = (reverse32(owen_permute(r, seed)) for r, seed in ((j, h >> _S32), (ry, h2 & _M32)))
        else:                                                       # a digital shift of each coordinate
            shift = mix64(h ^ _XOR)
            x, y = (reverse32(r) ^ s for r, s in ((j, shift & _M32), (ry, shift >> _S32)))
        out[2 * m] = ((x << _S16) | ((h2 >> _S32) & _LOW16)).astype(np.float64) * _TO_UNIT
        out[2 * m + 1] = ((y << _S16) | (h2 >> _S48)).astype(np.float64) * _TO_UNIT
    return out


@jit_inner
def _reverse32_one(x):
    x = ((x >> _S1) & _B1) | ((x & _B1) << _S1)
    x = ((x >> _S2) & _B2) | ((x & _B2) << _S2)
    x = ((x >> _S4) & _B4) | ((x & _B4) << _S4)
    x = ((x >> _S8) & _B8) | ((x & _B8) << _S8)
    return (x >> _S16) | ((x & _B16) << _S16)


@jit_inner
def _owen_permute_one(r, seed):
    r = r ^ ((r * _C1) & _M32)
    r = (r + seed) & _M32
    r = (r * ((seed >> _S16) | _S1)) & _M32
    r = r ^ ((r * _C2) & _M32)
    return r ^ ((r * _C3) & _M32)


@jit
def _owen_sobol_loop(seed_key, pixel, sample, pairs, owen, table, base, ri, out):
    s = seed_key[0]
    byte = np.uint64(255)
    for n in range(pixel.shape[0]):            # per path: its key and reversed index
        smp = np.uint64(sample[n])
        base[n] = _mix64_one((s ^ (np.uint64(pixel[n]) * _GOLDEN) ^ ((smp & _S1) * _PARITY)) + _SALT)
        ri[n] = _reverse32_one((smp >> _S1) & _M32)
    for m in range(pairs.shape[0]):            # per pair, over the paths (the faster order)
        key = np.uint64(pairs[m] + 1) * _PAIR
        for n in range(pixel.shape[0]):
            h = _mix64_one(base[n] + key)
            h2 = _mix64_one(h ^ _SECOND)
            j = _reverse32_one(_owen_permute_one(ri[n], h & _M32))
            ry = table[0, j & byte] ^ table[1, (j >> _S8) & byte] ^ table[2, (j >> _S16) & byte] ^ table[3, j >> _S24]
            if owen[m]:
                x = _reverse32_one(_owen_permute_one(j, h >> _S32))
                y = _reverse32_one(_owen_permute_one(ry, h2 & _M32))
            else:
                shift = _mix64_one(h ^ _XOR)
                x = _reverse32_one(j) ^ (shift & _M32)
                y = _reverse32_one(ry) ^ (shift >> _S32)
            out[2 * m, n] = np.float64((x << _S16) | ((h2 >> _S32) & _LOW16)) * _TO_UNIT
            out[2 * m + 1, n] = np.float64((y << _S16) | (h2 >> _S48)) * _TO_UNIT


def owen_sobol_pairs_numba(seed_key: np.ndarray, pixel: np.ndarray, sample: np.ndarray,
                           pairs: np.ndarray, owen: np.ndarray | None = None) -> np.ndarray:
    n = pixel.shape[0]
    out = np.empty((2 * pairs.shape[0], n))
    owen = np.ones(pairs.shape[0], np.bool_) if owen is None else np.ascontiguousarray(owen, np.bool_)
    _owen_sobol_loop(np.asarray(seed_key, np.uint64), np.ascontiguousarray(pixel, np.int64),
                     np.ascontiguousarray(sample, np.int64), np.ascontiguousarray(pairs, np.int64), owen,
                     SOBOL2_REVERSED, np.empty(n, np.uint64), np.empty(n, np.uint64), out)
    return out


owen_sobol_pairs = twin(_owen_sobol_loop and owen_sobol_pairs_numba, owen_sobol_pairs_numpy)
