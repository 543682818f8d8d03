"""Stateless, counter-based random numbers for paths.

Every random number is a hash of (seed, pixel, sample index, dimension), so a
render is bit-for-bit reproducible whatever the batching, tiling, number of
workers or resumption order: sample s of pixel p always sees the same
numbers.  The hash is splitmix64's finaliser (Steele et al. 2014), which
passes BigCrush as a counter-based generator; 53 bits are turned into a
float64 in [0, 1).  That is the "independent" sampler.  With ``RenderSettings.sampler`` "stratified" the
camera's numbers (pixel jitter, lens, wavelengths) and the first vertex's light and BSDF numbers are
replaced by ``stratified_pair`` (per-pixel XOR-scrambled Sobol' points, two independent sequences for
the even and the odd samples), still functions of (seed, pixel, sample index) only.

With "sobol" (the default) the camera's numbers are "stratified"'s, bit for bit, the first vertex's are Cycles'
(``vertex_pattern``: the "cycles" sampler's light and BSDF sets of vertex 0; until 2026-12-07 "stratified"'s jointly
stratified Sobol' dimensions 3–8, whose light and lobe choices repeat the jitter's y over a pixel's first 16
samples), and every number of the deeper vertices — light choice, light
point, lobe choice, BSDF direction, roulette, where "stratified" hashes them — is a coordinate of a
pair of dimensions (``sobol_pairs``, layout ``SOBOL_*`` below) drawn from its own shuffled,
Owen-scrambled 2-D Sobol' (0, 2)-sequence per (seed, pixel, pair, parity of the sample)
(engine.kernels.sobol): a pixel's first 2^m even (or odd) samples of every pair form a (0, m, 2)-net,
pairs are decorrelated by the per-pair index shuffle, each number is uniform and independent of the
other pairs (unbiased), and a function of (seed, pixel, sample, pair) only.

With "padded" every number — the camera's (PADDED_*) and every vertex's from the first on (SOBOL_* roles at
``vertex_pair``) — is a coordinate of such a pair (``padded_pairs``), the pixel jitter Owen-scrambled and every
other pair XOR-scrambled (a random digital shift: less variance than Owen's on the smooth direction and light
integrands, measured in docs/benchmarks.md, "Sampling patterns: padded").

With "cycles" the numbers are Cycles' (sample/sobol_burley.h, ``cycles_pairs``): the padded layout's pairs, but
every role's numbers are coordinates of ONE point of a small Owen-scrambled Sobol' set (CYCLES_*: the jitter, lens
and wavelengths 2-D; per vertex the light's 4-D set (point, choice, light number 3), the BSDF's 3-D one
(direction, lobe), roulette's 1-D one) whose index is shuffled per (seed, pixel, parity, set): the light choice
stratified jointly with the light point, the lobe with the direction (engine.kernels.sobol.owen_sobol_sets).
With independent halves (below), unlike Cycles, the even and odd samples are two independently scrambled sequences
(adaptive's half-buffers); with one sequence, as Cycles' own.

**Halves** (``RenderSettings.halves``, resolved per render by engine.scene.description.resolve_halves): with
"independent" every pattern above draws sample s at index s // 2 of the sequence of parity s & 1 (two independently
scrambled sequences); with "one_sequence" at index s of one sequence — ``sequence_index`` gives the patterns 2·s,
whose parity is 0 and index s: the even sequence's point s, so the same kernels draw it and a pixel's first 2^m
samples of every pair (set) are one (0, m, 2)-net, and every number is still a function of (seed, pixel, sample,
dimension) only.  The hashed dimensions (``PathSampler``) are keyed by the sample itself either way.
"""

from __future__ import annotations

import functools

import numpy as np

from ..kernels.hashing import mix64, path_keys_and_uniforms, scrambled_sobol_pair, uniforms
from ..kernels.sobol import SOBOL_V, owen_sobol_pairs, owen_sobol_sets

_MASK64 = (1 << 64) - 1


def sequence_index(sample: np.ndarray, halves: str) -> np.ndarray:
    """The index the patterns' kernels draw sample ``sample`` (N,) at (module docstring, "Halves"): ``sample``
    itself with "independent" halves (index sample // 2 of the sequence of parity sample & 1), 2·sample with
    "one_sequence" (index sample of the one sequence)."""
    if halves == "one_sequence":
        return 2 * np.asarray(sample, np.int64)
    if halves != "independent":
        raise ValueError(f"halves must be resolved ('independent' or 'one_sequence'), got {halves!r}")
    return sample


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


#: What each pair of Sobol' dimensions (2·pair + 1, 2·pair + 2) stratifies (``stratified_pair``'s pair)
PAIR_JITTER = 0             # the pixel jitter (x, y)
PAIR_LIGHT_POINT = 1        # first vertex: the point on the chosen light (next-event estimation)
PAIR_BSDF_DIRECTION = 2     # first vertex: the BSDF's direction numbers
PAIR_CHOICES = 3            # first vertex: (light choice, BSDF lobe)
PAIR_LENS = 4               # the thin lens's point (depth of field)
PAIR_WAVELENGTH = 5         # the wavelengths' number: its place within a period 1/count, and which period


_SOBOL_V = SOBOL_V
#: per-pair constants of the scramble hash
_PAIR_KEYS = tuple(np.array([k], np.uint64) for k in (0xD1B54A32D192ED03, 0x8CB92BA72F3D8DD7, 0xABC98388FB8FAC03,
                                                       0xE7037ED1A0B428DB, 0x94D049BB133111EB, 0xBF58476D1CE4E5B9))


def stratified_pair(seed: int, pixel: np.ndarray, sample: np.ndarray, u0: np.ndarray, u1: np.ndarray, pair: int = 0):
    """Two numbers (2 × (N,)) in [0, 1) for sample ``sample`` of pixel ``pixel``: Sobol' dimensions
    2·pair + 1, 2·pair + 2 of the index sample // 2, digit-scrambled by a random XOR per pixel, pair
    and parity of ``sample`` (so each point is uniform and independent of every other dimension,
    hence unbiased), the hashed uniforms u0, u1 filling the bits below 2^-32.  Pair 0 (the pixel
    jitter) is a (0, 2)-sequence: a pixel's first 2^m even (or odd) samples fill the 2^m elementary
    intervals of each shape; the pairs with it make a 12-D Sobol' point set (each dimension
    stratified too; what each pair stratifies: PAIR_JITTER … PAIR_WAVELENGTH)."""
    # the even and the odd samples are two independently scrambled sequences (index sample // 2; "independent"
    # halves: the error estimate's classes A (even) and B (odd) are then independent); one sequence ("one_sequence"
    # halves, the default) is its even sequence at 2·sample (sequence_index)
    return scrambled_sobol_pair(_seed_key(seed), pixel, sample, _PAIR_KEYS[pair], _SOBOL_V[2 * pair],
                                _SOBOL_V[2 * pair + 1], u0, u1)


def camera_numbers(seed: int, sampler: str, pixel: np.ndarray, sample: np.ndarray, lens_dimensions: int,
                   extra: int = 0, halves: str = "independent"):
    """(PathSampler, u (2 + lens_dimensions + extra, N)): the camera's numbers of sample ``sample`` of pixel
    ``pixel`` with ``sampler`` (RenderSettings.sampler) — the pixel jitter, the thin lens's point
    (``lens_dimensions`` 0 or 2), then ``extra`` hashed dimensions (the wavelengths' number) — with the jitter and
    lens pairs stratified (``stratified_pair``; "padded": its pairs PADDED_JITTER, PADDED_LENS; "cycles": its sets
    CYCLES_FILTER, CYCLES_LENS) for the stratifying samplers, at ``sequence_index(sample, halves)`` (``halves``
    resolved).  The one source of camera rays' numbers: the integrator's paths and the data passes
    (engine.render.data_passes) see the same rays."""
    ps, u = PathSampler.start(seed, pixel, sample, 2 + lens_dimensions + extra)
    sample = sequence_index(sample, halves)
    if sampler in PADDED_LAYOUT:
        pairs = pattern_pairs(sampler, seed, pixel, sample, [PADDED_JITTER, PADDED_LENS][:1 + lens_dimensions // 2])
        u[:2 + lens_dimensions] = pairs
    elif sampler != "independent":
        u[0], u[1] = stratified_pair(seed, pixel, sample, u[0], u[1], pair=PAIR_JITTER)
        if lens_dimensions == 2:
            u[2], u[3] = stratified_pair(seed, pixel, sample, u[2], u[3], pair=PAIR_LENS)
    return ps, u


#: The "sobol" sampler's pairs of dimensions (``sobol_pairs``) at the vertices after the first (the camera
#: and the first vertex draw "stratified"'s numbers): SOBOL_PER_BOUNCE per vertex, vertex b ≥ 1 at
#: SOBOL_PER_BOUNCE·(b − 1) + role
SOBOL_PER_BOUNCE = 4
SOBOL_LIGHT_POINT = 0       # the point on the chosen light (next-event estimation: light numbers 1, 2)
SOBOL_DIRECTION = 1         # the BSDF's direction numbers (BSDF numbers 1, 2)
SOBOL_CHOICES = 2           # (the light choice, the BSDF lobe) (light number 0, BSDF number 0)
SOBOL_ROULETTE = 3          # (Russian roulette, light number 3)


def sobol_pair_index(bounce: int, role: int) -> int:
    """The pair of dimensions of ``role`` (SOBOL_LIGHT_POINT … SOBOL_ROULETTE) at vertex ``bounce`` ≥ 1."""
    if bounce < 1:
        raise ValueError("the first vertex draws the stratified sampler's numbers")
    return SOBOL_PER_BOUNCE * (bounce - 1) + role


#: The "padded" sampler's pairs: the camera's (jitter, lens, wavelengths), then SOBOL_PER_BOUNCE per vertex b ≥ 0
#: at PADDED_FIRST + SOBOL_PER_BOUNCE·b + role (roles SOBOL_LIGHT_POINT … SOBOL_ROULETTE)
PADDED_JITTER, PADDED_LENS, PADDED_WAVELENGTH = 0, 1, 2
PADDED_FIRST = 3
#: the samplers drawing every number, the camera's too, in the padded layout of pairs
PADDED_LAYOUT = ("padded", "cycles")


def vertex_pattern(sampler: str, bounce: int) -> str:
    """The pattern whose pairs (sets) draw vertex ``bounce``'s numbers with ``sampler``: "cycles" at "sobol"'s first
    vertex (its light numbers one Owen-scrambled 4-D set, its lobe and direction one 3-D set, each shuffled per pixel:
    ``cycles_pairs``), else ``sampler``.  Not "stratified"'s Sobol' dimensions 3–8: for a pixel's first 16 samples
    (one sequence) the first two binary digits of dimensions 7, 8 (light choice, lobe) are fixed functions of
    dimension 2's (the jitter's y), so each light's or lobe's samples covered half of the pixel
    (docs/benchmarks/real-assets.md, helper F).  The integrator gives one-lobe materials (no lobe choice: Lambert, a
    rough conductor) "stratified"'s direction back, one net with the jitter (PathTracer._sobol_vertex_numbers)."""
    return "cycles" if sampler == "sobol" and bounce == 0 else sampler


def vertex_pair(sampler: str, bounce: int, role: int) -> int:
    """The pair of dimensions of ``role`` at vertex ``bounce`` for the pair-drawing ``sampler`` ("sobol": bounce
    ≥ 1, ``sobol_pair_index``; "padded" and "cycles": every bounce ≥ 0)."""
    if sampler in PADDED_LAYOUT:
        return PADDED_FIRST + SOBOL_PER_BOUNCE * bounce + role
    return sobol_pair_index(bounce, role)


#: The "padded" sampler's Owen-scrambled pairs (the others XOR-scrambled)
PADDED_OWEN = frozenset({PADDED_JITTER})


def padded_pairs(seed: int, pixel: np.ndarray, sample: np.ndarray, pairs) -> np.ndarray:
    """(2k, N) numbers of the "padded" sampler's ``pairs`` (as ``sobol_pairs``): the same shuffled Sobol' pairs,
    PADDED_OWEN Owen-scrambled, every other pair XOR-scrambled (engine.kernels.sobol.owen_sobol_pairs)."""
    pairs = np.asarray(pairs, dtype=np.int64)
    return owen_sobol_pairs(_seed_key(seed), pixel, sample, pairs, np.isin(pairs, list(PADDED_OWEN)))


def pattern_pairs(sampler: str, seed: int, pixel: np.ndarray, sample: np.ndarray, pairs) -> np.ndarray:
    """``sobol_pairs``, ``padded_pairs`` or ``cycles_pairs`` for ``sampler``."""
    draw = padded_pairs if sampler == "padded" else cycles_pairs if sampler == "cycles" else sobol_pairs
    return draw(seed, pixel, sample, pairs)


#: The "cycles" sampler's dimension sets (Cycles' PRNG_FILTER, PRNG_LENS_TIME, then per vertex b at CYCLES_FIRST +
#: CYCLES_PER_BOUNCE·b + role: PRNG_LIGHT, PRNG_SURFACE_BSDF, PRNG_TERMINATE); the camera's sets are the padded
#: pairs' indices
CYCLES_FILTER, CYCLES_LENS, CYCLES_WAVELENGTH = PADDED_JITTER, PADDED_LENS, PADDED_WAVELENGTH
CYCLES_FIRST = 3
CYCLES_LIGHT, CYCLES_BSDF, CYCLES_TERMINATE = 0, 1, 2
CYCLES_PER_BOUNCE = 3
#: per padded vertex role (SOBOL_LIGHT_POINT … SOBOL_ROULETTE): the (set role, coordinate) of its two numbers —
#: the light point = the light set's 0, 1 (Cycles' rand.x, y), the direction the BSDF set's 0, 1, (light choice,
#: lobe) = the light set's 2 (rand.z) and the BSDF set's 2, (roulette, light number 3) = roulette's 0 and the
#: light set's 3
_CYCLES_ROLES = {SOBOL_LIGHT_POINT: ((CYCLES_LIGHT, 0), (CYCLES_LIGHT, 1)),
                 SOBOL_DIRECTION: ((CYCLES_BSDF, 0), (CYCLES_BSDF, 1)),
                 SOBOL_CHOICES: ((CYCLES_LIGHT, 2), (CYCLES_BSDF, 2)),
                 SOBOL_ROULETTE: ((CYCLES_TERMINATE, 0), (CYCLES_LIGHT, 3))}


def cycles_pairs(seed: int, pixel: np.ndarray, sample: np.ndarray, pairs) -> np.ndarray:
    """(2k, N) numbers of the "cycles" sampler for the padded layout's ``pairs`` (as ``padded_pairs``): each
    number a coordinate of its dimension set's point (CYCLES_*, _CYCLES_ROLES; engine.kernels.sobol.owen_sobol_sets),
    so a role's numbers are stratified jointly; a function of (seed, pixel, sample, pair) only.  The wavelengths' set
    (Cycles has none) is digitally shifted as "padded"'s and "stratified"'s: its integrand is smooth and periodic,
    where the shift's lattice gains 30× over Owen's scramble (tests/render/test_stratified.py)."""
    rows = []
    for p in (int(q) for q in np.atleast_1d(pairs)):
        if p < PADDED_FIRST:
            rows += [(p, 0), (p, 1)]
        else:
            bounce, role = divmod(p - PADDED_FIRST, SOBOL_PER_BOUNCE)
            first = CYCLES_FIRST + CYCLES_PER_BOUNCE * bounce
            rows += [(first + r, c) for r, c in _CYCLES_ROLES[role]]
    if not rows:
        return np.empty((0, np.shape(pixel)[0]))
    sets, row_set = np.unique(np.array([r for r, _ in rows], np.int64), return_inverse=True)
    return owen_sobol_sets(_seed_key(seed), np.asarray(pixel), np.asarray(sample), sets, row_set.astype(np.int64),
                           np.array([c for _, c in rows], np.int64), sets == CYCLES_WAVELENGTH)


def sobol_pairs(seed: int, pixel: np.ndarray, sample: np.ndarray, pairs) -> np.ndarray:
    """(2k, N) numbers in [0, 1) of the "sobol" sampler: rows 2m, 2m + 1 the pair ``pairs[m]`` of sample
    ``sample`` (N,) of pixel ``pixel`` (N,) (engine.kernels.sobol: shuffled, Owen-scrambled Sobol'
    (0, 2)-sequences per (seed, pixel, pair, parity of the sample))."""
    return owen_sobol_pairs(_seed_key(seed), pixel, sample, np.asarray(pairs, dtype=np.int64))
