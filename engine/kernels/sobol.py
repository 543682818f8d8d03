"""Owen-scrambled, shuffled Sobol' pairs: the "sobol" sampler's numbers (engine.render.sampler.sobol_pairs).

``owen_sobol_sets`` draws the "cycles" sampler's numbers instead: Cycles' pattern (sample/sobol_burley.h),
each number a coordinate of one point of a 1- to 4-D Sobol' set (dimensions 0–3 of the shuffled index) per
dimension set (a role at a vertex), each coordinate Owen-scrambled with its own seed (below).

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
  sample // 2): with independent halves the error estimate's classes A (even) and B (odd) are independent
  estimates; one sequence (engine.render.sampler.sequence_index) draws sample s at 2·s, the even sequence;
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


#: Sobol' dimensions 2–12 as (degree s, coefficients a, initial m) of their primitive polynomials
#: (Joe & Kuo 2008, new-joe-kuo-6.21201); dimension 1 is the bit reversal
SOBOL_POLYNOMIALS = [(1, 0, [1]), (2, 1, [1, 3]), (3, 1, [1, 3, 1]), (3, 2, [1, 1, 1]), (4, 1, [1, 1, 3, 3]),
                     (4, 4, [1, 3, 5, 13]), (5, 2, [1, 1, 5, 5, 17]), (5, 4, [1, 1, 5, 5, 5]),
                     (5, 7, [1, 1, 7, 11, 19]), (5, 11, [1, 1, 5, 1, 1]), (5, 13, [1, 1, 1, 3, 11])]


def sobol_direction_numbers() -> np.ndarray:
    """Direction numbers (12, 32) (uint64 holding 32 bits) of Sobol' dimensions 1–12."""
    v = np.zeros((len(SOBOL_POLYNOMIALS) + 1, 32), dtype=np.uint64)
    v[0] = [1 << (31 - k) for k in range(32)]
    for d, (deg, a, m) in enumerate(SOBOL_POLYNOMIALS, start=1):
        w = [m[k] << (31 - k) for k in range(deg)]
        for k in range(deg, 32):
            x = w[k - deg] ^ (w[k - deg] >> deg)
            for j in range(1, deg):
                if (a >> (deg - 1 - j)) & 1:
                    x ^= w[k - j]
            w.append(x)
        v[d] = w
    return v


SOBOL_V = sobol_direction_numbers()


def _sobol_byte_tables(dims: int) -> np.ndarray:
    """(dims, 4, 256) uint64: byte b of the index → the bit-reversed XOR of Sobol' dimension d's direction numbers
    (SOBOL_V) of that byte's set bits: reverse(sobol_d(i)) is the XOR of the four bytes' entries."""
    table = np.zeros((dims, 4, 256), np.uint64)
    for d in range(dims):
        for b in range(4):
            for byte in range(256):
                acc = 0
                for t in range(8):
                    if (byte >> t) & 1:
                        acc ^= int(SOBOL_V[d, 8 * b + t])
                table[d, b, byte] = _reverse32_py(acc)
    return table


def _reverse32_py(x: int) -> int:
    return int(f"{x:032b}"[::-1], 2)


#: reverse(sobol_d(i)) for dimensions d 0–3 (the coordinates of a dimension set's point) by bytes of the index
SOBOL4_REVERSED = _sobol_byte_tables(4)


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


#: key constants of the dimension sets: their salt, the set index, the coordinate
_SET_SALT = np.uint64(0x8BB84B93962EACC9)
_SET = np.uint64(0x4BE98134A5976FD3)
_COORD = np.uint64(0x3BC0993A5AD19A13)


def _set_keys(seed_key, pixel, sample, sets):
    """(h, j) (S, N) uint64: each dimension set's key and shuffled index (the index sample // 2 under a nested
    uniform scramble of its bits seeded by the key's low word)."""
    smp = sample.astype(np.uint64)
    base = mix64((seed_key[0] ^ (pixel.astype(np.uint64) * _GOLDEN) ^ ((smp & _S1) * _PARITY)) + _SET_SALT)
    ri = reverse32((smp >> _S1) & _M32)
    h = np.empty((sets.shape[0], pixel.shape[0]), np.uint64)
    j = np.empty_like(h)
    for k in range(sets.shape[0]):
        h[k] = mix64(base + np.uint64(((int(sets[k]) + 1) * int(_SET)) & 0xFFFFFFFFFFFFFFFF))
        j[k] = reverse32(owen_permute(ri, h[k] & _M32))
    return h, j


def owen_sobol_sets_numpy(seed_key: np.ndarray, pixel: np.ndarray, sample: np.ndarray, sets: np.ndarray,
                          row_set: np.ndarray, row_coord: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """(r, N) numbers in [0, 1): row k is coordinate ``row_coord[k]`` (0–3) of the point of dimension set
    ``sets[row_set[k]]`` (``sets`` int64 (S,), distinct) of sample ``sample`` (N,) of pixel ``pixel`` (N,) for the
    render's mixed seed ``seed_key`` (uint64 (1,)): Sobol' dimension ``row_coord[k]`` of the index sample // 2
    shuffled per (seed, pixel, parity, set), Owen-scrambled per (…, coordinate) (``shift`` (bool (S,)) True: that
    set's coordinates digitally shifted instead, a random XOR), the 16 bits below 2^-32 a random offset.  A pixel's
    first 2^m even (odd) samples of coordinates 0 and 1 of a set are a (0, m, 2)-net."""
    h, j = _set_keys(seed_key, pixel, sample, sets)
    out = np.empty((row_set.shape[0], pixel.shape[0]))
    byte = np.uint64(255)
    for k in range(row_set.shape[0]):
        t, jk = SOBOL4_REVERSED[row_coord[k]], j[row_set[k]]
        rx = t[0][jk & byte] ^ t[1][(jk >> _S8) & byte] ^ t[2][(jk >> _S16) & byte] ^ t[3][jk >> _S24]
        hc = mix64(h[row_set[k]] + np.uint64(((int(row_coord[k]) + 1) * int(_COORD)) & 0xFFFFFFFFFFFFFFFF))
        xs = (reverse32(rx) ^ (hc & _M32)) if shift[row_set[k]] else reverse32(owen_permute(rx, hc & _M32))
        out[k] = ((xs << _S16) | ((hc >> _S32) & _LOW16)).astype(np.float64) * _TO_UNIT
    return out


@jit
def _owen_sobol_sets_loop(seed_key, pixel, sample, sets, row_set, row_coord, shift, table, h, j, out):
    s = seed_key[0]
    byte = np.uint64(255)
    for n in range(pixel.shape[0]):            # per path: its key and reversed index (in the last rows)
        smp = np.uint64(sample[n])
        h[-1, n] = _mix64_one((s ^ (np.uint64(pixel[n]) * _GOLDEN) ^ ((smp & _S1) * _PARITY)) + _SET_SALT)
        j[-1, n] = _reverse32_one((smp >> _S1) & _M32)
    for k in range(sets.shape[0]):             # per set, over the paths: its key and shuffled index
        key = np.uint64(sets[k] + 1) * _SET
        for n in range(pixel.shape[0]):
            hk = _mix64_one(h[-1, n] + key)
            h[k, n] = hk
            j[k, n] = _reverse32_one(_owen_permute_one(j[-1, n], hk & _M32))
    for k in range(row_set.shape[0]):          # per number, over the paths
        c, q = row_coord[k], row_set[k]
        key, shifted = np.uint64(c + 1) * _COORD, shift[q]
        for n in range(pixel.shape[0]):
            jk = j[q, n]
            rx = (table[c, 0, jk & byte] ^ table[c, 1, (jk >> _S8) & byte] ^ table[c, 2, (jk >> _S16) & byte]
                  ^ table[c, 3, jk >> _S24])
            hc = _mix64_one(h[q, n] + key)
            if shifted:
                xs = _reverse32_one(rx) ^ (hc & _M32)
            else:
                xs = _reverse32_one(_owen_permute_one(rx, hc & _M32))
            out[k, n] = np.float64((xs << _S16) | ((hc >> _S32) & _LOW16)) * _TO_UNIT


def owen_sobol_sets_numba(seed_key: np.ndarray, pixel: np.ndarray, sample: np.ndarray, sets: np.ndarray,
                          row_set: np.ndarray, row_coord: np.ndarray, shift: np.ndarray) -> np.ndarray:
    n, n_sets = pixel.shape[0], sets.shape[0]
    out = np.empty((row_set.shape[0], n))
    _owen_sobol_sets_loop(np.asarray(seed_key, np.uint64), np.ascontiguousarray(pixel, np.int64),
                          np.ascontiguousarray(sample, np.int64), np.ascontiguousarray(sets, np.int64),
                          np.ascontiguousarray(row_set, np.int64), np.ascontiguousarray(row_coord, np.int64),
                          np.ascontiguousarray(shift, np.bool_), SOBOL4_REVERSED, np.empty((n_sets + 1, n), np.uint64),
                          np.empty((n_sets + 1, n), np.uint64), out)
    return out


owen_sobol_sets = twin(_owen_sobol_sets_loop and owen_sobol_sets_numba, owen_sobol_sets_numpy)
