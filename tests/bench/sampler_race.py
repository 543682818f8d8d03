"""Sampling patterns raced in one run: time to equal error of our samplers on the five peer scenes.

    python tests/bench/sampler_race.py [--scenes a,b] [--res 128] [--spp 32,128] [--seeds 4]
                                       [--samplers sobol,stratified,independent] [--threads 1]

A sampler spec "NAME/HALVES" renders with RenderSettings.halves HALVES (``--samplers
sobol/one_sequence,sobol/independent``: one sequence over a pixel's even and odd samples against two independent
ones); without it the scene's halves (default "auto": one sequence in these uniform renders).

For each peer scene (``shared/peers/scenes``, at --res × --res) and each sample count of ``--spp``,
every sampler renders the scene ``--seeds`` times (seeds 0, 1, …).  All our samplers are unbiased, so
a render's mean squared error is its variance: per pixel the variance over the seeds (ddof 1), averaged
over the pixels, of the luminance S0 and S1.  Monte Carlo error² ∝ 1/time, so the time to equal error
of sampler a ÷ sampler b is (t_b·MSE_b)/(t_a·MSE_a) (> 1: a gets there first); t is the CPU time of the
renders (``time.process_time``: not inflated by other processes' load on a shared machine; with
--threads 1 it is the render's work).  The first sampler of ``--samplers`` is compared with each other
one (± the standard error of the MSE ratio from the pixels' variance estimates, ``mse_rel_se``; the
CPU times' own spread, a few %, comes on top); ``bias z`` is the difference of the two image means ÷
its standard error (|z| < 4: the same expectation).  Kernels are loaded (``Renderer.warm_up``) and one
untimed render made before anything is timed; the samplers take turns seed by seed.

Mitsuba is not raced here (``tests/bench/bench_engine.py`` does, where Mitsuba 3 is installed).
Not part of the test command.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)

from engine.kernels.hashing import mix64  # noqa: E402
from engine.kernels.sobol import SOBOL2_REVERSED, owen_permute, reverse32  # noqa: E402
from engine.render.renderer import Renderer  # noqa: E402
from engine.scene.loader import load_scene  # noqa: E402

SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
SCENES = ["fresnel_sphere", "fresnel_sphere_au", "glass_sphere", "rough_sphere_a030", "cornell_lambert"]
#: scenes whose S1 is 0 (nothing polarises): no S1 column
NO_S1 = {"cornell_lambert"}

U = np.uint64
_M32, _S1, _S2, _S8, _S16, _S24, _S32, _S48, _LOW16 = (U(v) for v in (0xFFFFFFFF, 1, 2, 8, 16, 24, 32, 48, 0xFFFF))
_GOLDEN, _SALT, _PARITY, _PAIR, _SECOND = (U(v) for v in (0x9E3779B97F4A7C15, 0x2545F4914F6CDD1D, 0xD6E8FEB86659FD93,
                                                          0xA0761D6478BD642F, 0xE7037ED1A0B428DB))
_TO_UNIT = 1.0 / float(1 << 48)
# ------------------------------------------------- pattern variants raced against the "padded" sampler

_KENSLER = U(0x4F1BBCDCBFA53E0B)
_XOR = U(0x7FB5D329728EA185)


def kensler_permute(v: np.ndarray, bits: int, p: np.ndarray) -> np.ndarray:
    """A pseudo-random permutation of the 2^bits values v (uint64 < 2^bits) per 32-bit seed p (uint64, broadcast):
    Kensler 2013's hash ("Correlated Multi-Jittered Sampling", permute()), whose steps (XOR with constants,
    multiplication by odd numbers, XOR with right shifts of the masked value) each map the low ``bits`` bits
    bijectively, so no cycle walking is needed for a power-of-two length."""
    w = U((1 << bits) - 1)
    i = v ^ p
    i = (i * U(0xE170893D)) & _M32
    i ^= p >> _S16
    i ^= (i & w) >> U(4)
    i ^= p >> _S8
    i = (i * U(0x0929EB3F)) & _M32
    i ^= p >> U(23)
    i ^= (i & w) >> _S1
    i = (i * ((p >> U(27)) | _S1)) & _M32
    i = (i * U(0x6935FA69)) & _M32
    i ^= (i & w) >> U(11)
    i = (i * U(0x74DCB303)) & _M32
    i ^= (i & w) >> _S2
    i = (i * U(0x9E501CC3)) & _M32
    i ^= (i & w) >> _S2
    i = (i * U(0xC860A3DF)) & _M32
    i &= w
    i ^= i >> U(5)
    return (i + p) & w


_EXACT = U(0x3C6EF372FE94F82B)


def exact_nested_index(i: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Nested uniform scramble of index bits: bit m flipped by a hash of (seed, m, the bits above m)."""
    j = i.copy()
    for m in range(24):
        flip = mix64(seed ^ ((i >> U(m + 1)) * _GOLDEN) ^ (U(m + 1) * _EXACT)) >> U(63)
        j ^= flip << U(m)
    return j


def exact_owen(v: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """Owen's nested uniform scramble of 32-bit values: digit d (from the top) flipped by a hash of (seed, d, the
    digits above), exact for the top 20 digits, the 12 below random per 20-digit prefix."""
    out = v.copy()
    for d in range(20):
        bit = 31 - d
        flip = mix64(seed ^ ((v >> U(bit + 1)) * _GOLDEN) ^ (U(d + 1) * _EXACT)) >> U(63)
        out ^= flip << U(bit)
    low = mix64(seed ^ ((v >> U(12)) * _GOLDEN) ^ _XOR) & U(0xFFF)
    return (out & U(0xFFFFF000)) | low


def variant_pairs(seed_key: np.ndarray, pixel: np.ndarray, sample: np.ndarray, pairs: np.ndarray,
                       block_bits: int = 0, xor: bool = False, split: bool = True, exact: bool = False,
                       owen_pairs: tuple = ()) -> np.ndarray:
    """engine.kernels.sobol.owen_sobol_pairs_numpy's numbers with the pattern's variants: ``block_bits`` > 0
    permutes the shuffled index within each aligned block of 2^block_bits by a Kensler permutation per (pair,
    block) (a uniform permutation where the nested shuffle allows only the block-preserving ones); ``xor``: a
    random XOR (digital shift) per pair instead of the Owen scramble; ``split`` False: one sequence over all
    samples (index ``sample``), not two (even, odd); ``exact``: Owen's scramble by a hash per digit and prefix
    (and the index shuffle alike) instead of the Laine–Karras-style hash; ``owen_pairs`` (with ``xor``): these
    pairs Owen-scrambled.  With the defaults the bits equal owen_sobol_pairs_numpy's."""
    n = pixel.shape[0]
    out = np.empty((2 * pairs.shape[0], n))
    smp = sample.astype(U)
    i = ((smp >> _S1) if split else smp) & _M32
    par = (smp & _S1) if split else np.zeros_like(smp)
    base = mix64((seed_key[0] ^ (pixel.astype(U) * _GOLDEN) ^ (par * _PARITY)) + _SALT)
    ri = reverse32(i)
    for m in range(pairs.shape[0]):
        h = mix64(base + U(((int(pairs[m]) + 1) * int(_PAIR)) & 0xFFFFFFFFFFFFFFFF))
        h2 = mix64(h ^ _SECOND)
        j = exact_nested_index(i, h & _M32) if exact else reverse32(owen_permute(ri, h & _M32))
        if block_bits:
            low = U((1 << block_bits) - 1)
            seed = mix64(h2 ^ ((j >> U(block_bits)) * _GOLDEN) ^ _KENSLER) & _M32
            j = (j & ~low) | kensler_permute(j & low, block_bits, seed)
        ry = (SOBOL2_REVERSED[0][j & U(255)] ^ SOBOL2_REVERSED[1][(j >> _S8) & U(255)]
              ^ SOBOL2_REVERSED[2][(j >> _S16) & U(255)] ^ SOBOL2_REVERSED[3][j >> _S24])
        if xor and int(pairs[m]) in owen_pairs:
            x = reverse32(owen_permute(j, h >> _S32))
            y = reverse32(owen_permute(ry, h2 & _M32))
        elif exact and not xor:
            x = exact_owen(reverse32(j), h >> _S32)
            y = exact_owen(reverse32(ry), h2 & _M32)
        elif xor:
            s = mix64(h ^ _XOR)
            x = reverse32(j) ^ (s & _M32)
            y = reverse32(ry) ^ (s >> _S32)
        else:
            x = reverse32(owen_permute(j, h >> _S32))
            y = reverse32(owen_permute(ry, h2 & _M32))
        out[2 * m] = ((x << _S16) | ((h2 >> _S32) & _LOW16)).astype(np.float64) * _TO_UNIT
        out[2 * m + 1] = ((y << _S16) | (h2 >> _S48)).astype(np.float64) * _TO_UNIT
    return out


def owen_joint(module, seed_key, pixel, sample, first_dim):
    """(2, N): Sobol' dimensions first_dim + 1, first_dim + 2 of the unshuffled index sample // 2 (one point set
    for all dimensions: they stratify jointly), each coordinate Owen-scrambled per (seed, pixel, parity, dimension)."""
    smp = sample.astype(U)
    i = (smp >> _S1) & _M32
    base = mix64((seed_key[0] ^ (pixel.astype(U) * _GOLDEN) ^ ((smp & _S1) * _PARITY)) + U(0x9FB21C651E98DF25))
    out = np.empty((2, pixel.size))
    for c in range(2):
        v = module._SOBOL_V[first_dim + c]
        x = np.zeros_like(i)
        for b in range(int(i.max()).bit_length() if i.size else 0):
            x[((i >> U(b)) & _S1).astype(bool)] ^= v[b]
        h = mix64(base + U(((first_dim + c + 1) * int(_PAIR)) & 0xFFFFFFFFFFFFFFFF))
        xs = reverse32(owen_permute(reverse32(x), h & _M32))
        out[c] = ((xs << _S16) | ((h >> _S32) & _LOW16)).astype(np.float64) * _TO_UNIT
    return out


def _sobol_byte_tables(module, dims: int) -> np.ndarray:
    """(dims, 4, 256) uint64: byte b of the index → the XOR of Sobol' dimension d's direction numbers of that
    byte's set bits (dimension 0 the van der Corput radical inverse)."""
    table = np.zeros((dims, 4, 256), np.uint64)
    for d in range(dims):
        v = module._SOBOL_V[d]
        for b in range(4):
            for byte in range(256):
                acc = 0
                for t in range(8):
                    if (byte >> t) & 1:
                        acc ^= int(v[8 * b + t])
                table[d, b, byte] = acc
    return table


#: Cycles' dimension sets (the camera's, then per vertex b: CYCLES_FIRST + CYCLES_PER_BOUNCE·b + role) and their
#: sizes: the light's (point x, point y, choice, light number 3), the BSDF's (direction x, y, lobe), roulette's
CYCLES_FILTER, CYCLES_LENS, CYCLES_WAVELENGTH, CYCLES_FIRST = 0, 1, 2, 3
CYCLES_LIGHT, CYCLES_BSDF, CYCLES_TERMINATE, CYCLES_PER_BOUNCE = 0, 1, 2, 3
_CYCLES_SALT, _CYCLES_SET, _CYCLES_COORD = U(0x8BB84B93962EACC9), U(0x4BE98134A5976FD3), U(0x3BC0993A5AD19A13)
_SOBOL_BYTES = {}


def cycles_set(module, seed_key, pixel, sample, dim_set: int, dims: int, xor: bool = False,
               split: bool = True) -> np.ndarray:
    """(dims, N): one point of a ``dims``-D Owen-scrambled Sobol' set per path, as Cycles' sobol_burley_sample_nD:
    the index sample // 2 shuffled (nested uniform scramble) per (seed, pixel, parity, dimension set), Sobol'
    dimensions 0 … dims − 1 of it, each coordinate Owen-scrambled (``xor``: digitally shifted) with its own seed;
    ``split`` False: one sequence over all samples (index ``sample``; not allowed in the engine: adaptive's halves)."""
    tables = _SOBOL_BYTES.setdefault(id(module), _sobol_byte_tables(module, 4))
    smp = sample.astype(U)
    i = ((smp >> _S1) if split else smp) & _M32
    par = (smp & _S1) if split else np.zeros_like(smp)
    base = mix64((seed_key[0] ^ (pixel.astype(U) * _GOLDEN) ^ (par * _PARITY)) + _CYCLES_SALT)
    h = mix64(base + U(((dim_set + 1) * int(_CYCLES_SET)) & 0xFFFFFFFFFFFFFFFF))
    j = reverse32(owen_permute(reverse32(i), h & _M32))
    out = np.empty((dims, pixel.size))
    for c in range(dims):
        t = tables[c]
        x = t[0][j & U(255)] ^ t[1][(j >> _S8) & U(255)] ^ t[2][(j >> _S16) & U(255)] ^ t[3][j >> _S24]
        hc = mix64(h + U(((c + 1) * int(_CYCLES_COORD)) & 0xFFFFFFFFFFFFFFFF))
        if (xor and dim_set != CYCLES_FILTER) or dim_set == CYCLES_WAVELENGTH:      # the engine's: wavelengths shifted
            xs = x ^ (hc & _M32)
        else:
            xs = reverse32(owen_permute(reverse32(x), hc & _M32))
        out[c] = ((xs << _S16) | ((hc >> _S32) & _LOW16)).astype(np.float64) * _TO_UNIT
    return out


def cycles_pairs(module, seed_key, pixel, sample, pairs, xor=False, split=True) -> np.ndarray:
    """(2k, N): the "padded" sampler's pairs (its layout: PADDED_*, then SOBOL_* roles per vertex) drawn from Cycles'
    dimension sets: the jitter, lens and wavelengths each a 2-D set; per vertex the light's 4-D set (point, choice,
    light number 3), the BSDF's 3-D set (direction, lobe) and roulette's 1-D one, so (light choice, lobe) and
    (roulette, light number 3) take one coordinate from each of two sets."""
    cache = {}

    def point(dim_set, dims):
        if dim_set not in cache:
            cache[dim_set] = cycles_set(module, seed_key, pixel, sample, dim_set, dims, xor, split)
        return cache[dim_set]

    out = np.empty((2 * len(pairs), pixel.size))
    for m, p in enumerate(int(q) for q in pairs):
        if p < module.PADDED_FIRST:
            out[2 * m:2 * m + 2] = point({module.PADDED_JITTER: CYCLES_FILTER, module.PADDED_LENS: CYCLES_LENS,
                                          module.PADDED_WAVELENGTH: CYCLES_WAVELENGTH}[p], 2)
            continue
        b, role = divmod(p - module.PADDED_FIRST, module.SOBOL_PER_BOUNCE)
        first = CYCLES_FIRST + CYCLES_PER_BOUNCE * b
        light, bsdf = point(first + CYCLES_LIGHT, 4), point(first + CYCLES_BSDF, 3)
        if role == module.SOBOL_LIGHT_POINT:
            out[2 * m:2 * m + 2] = light[:2]
        elif role == module.SOBOL_DIRECTION:
            out[2 * m:2 * m + 2] = bsdf[:2]
        elif role == module.SOBOL_CHOICES:
            out[2 * m], out[2 * m + 1] = light[2], bsdf[2]
        else:
            out[2 * m], out[2 * m + 1] = point(first + CYCLES_TERMINATE, 1)[0], light[3]
    return out


#: "cycles:jointK" variants: the first vertex's roles drawn from the jitter's set (coordinates 2, 3: the light point;
#: with K = 6 coordinates 4, 5: the BSDF direction), stratified jointly with the pixel position as "sobol"'s
_JOINT_ROWS = {1: {1: ((0, 0), (0, 1))}, 0: {}, 4: {0: ((0, 2), (0, 3))}, 6: {0: ((0, 2), (0, 3)), 1: ((0, 4), (0, 5))}}
_JOINT_TABLES = {}


def cycles_joint_pairs(joint: int, shift: bool = False):
    """The engine's ``cycles_pairs`` with the first vertex's light point (``joint`` 6: and BSDF direction) taken
    from further coordinates of the jitter's set (CYCLES_FILTER, Owen-scrambled; ``shift``: digitally shifted),
    compiled kernel; ``joint`` 1: the roles swapped, the direction coordinates 0, 1 of that set, the jitter 2, 3."""
    def draw(seed, pixel, sample, pairs):
        module = sys.modules[SAMPLER_MODULE]
        kernels = sys.modules[SAMPLER_MODULE.replace("render.sampler", "kernels.sobol")]
        table = _JOINT_TABLES.setdefault((SAMPLER_MODULE, joint), kernels._sobol_byte_tables(max(joint, 4)))
        rows = []
        for p in (int(q) for q in np.atleast_1d(pairs)):
            if p < module.PADDED_FIRST:
                rows += [(p, 2), (p, 3)] if joint == 1 and p == module.PADDED_JITTER else [(p, 0), (p, 1)]
                continue
            bounce, role = divmod(p - module.PADDED_FIRST, module.SOBOL_PER_BOUNCE)
            if bounce == 0 and role in _JOINT_ROWS[joint]:
                rows += list(_JOINT_ROWS[joint][role])
                continue
            first = module.CYCLES_FIRST + module.CYCLES_PER_BOUNCE * bounce
            rows += [(first + r, c) for r, c in module._CYCLES_ROLES[role]]
        pixel, sample = np.asarray(pixel), np.asarray(sample)
        if not rows:
            return np.empty((0, pixel.shape[0]))
        sets, row_set = np.unique(np.array([r for r, _ in rows], np.int64), return_inverse=True)
        n = pixel.shape[0]
        out = np.empty((len(rows), n))
        kernels._owen_sobol_sets_loop(module._seed_key(seed), np.ascontiguousarray(pixel, np.int64),
                                      np.ascontiguousarray(sample, np.int64), sets, row_set.astype(np.int64),
                                      np.array([c for _, c in rows], np.int64),
                                      (sets == module.CYCLES_WAVELENGTH) | (shift & (sets == module.CYCLES_FILTER)),
                                      table, np.empty((sets.size + 1, n), np.uint64),
                                      np.empty((sets.size + 1, n), np.uint64), out)
        return out
    return draw


def halves_of(spec: str) -> tuple[str, str | None]:
    """("sobol", "one_sequence") of "sobol/one_sequence": a sampler spec and its RenderSettings.halves (None: the
    settings' own, "auto" by default)."""
    name, _, halves = spec.partition("/")
    return name, halves or None


def pattern(spec: str, spp: int):
    """A sampler spec → (RenderSettings.sampler, the "padded" sampler's pairs function or None: the engine's).
    "padded:KNOB:…" races the pattern variants of ``variant_pairs`` (numbers of every pair): ``xor``, ``exact``,
    ``owen=0+1`` (those pairs Owen, the others XOR), ``whole`` (one sequence over even and odd samples), ``bK``
    Kensler permutations within blocks of 2^K shuffled indices, ``bN`` within the whole render's count per
    sequence (as Mitsuba's ldsampler permutes its whole sample count — not progressive); ``cycles``: Cycles' dimension
    sets (``cycles_pairs``, the engine's "cycles" numbers bit for bit), with ``xor`` digitally shifted but the jitter,
    with ``whole`` one sequence over even and odd samples (Cycles' own; not allowed in the engine).  "cycles:jointK"
    (``cycles_joint_pairs``) races the engine's "cycles" with the first vertex's light point (K 4) and direction
    (K 6) in the jitter's set (K 1: direction and jitter swapped), ``:shift``: the jitter's set shifted."""
    name, *knobs = halves_of(spec)[0].split(":")
    if not knobs:
        return name, None
    if name == "cycles":                # the engine's "cycles" with its first vertex jointly stratified (cycles:joint4)
        return name, cycles_joint_pairs(int(knobs[0][5:]), "shift" in knobs)
    kw = {}
    for k in knobs:
        if k == "xor":
            kw["xor"] = True
        elif k == "exact":
            kw["exact"] = True
        elif k.startswith("owen="):            # these pairs Owen-scrambled, the others XOR
            kw["xor"] = True
            kw["owen_pairs"] = tuple(int(v) for v in k[5:].split("+"))
        elif k == "whole":
            kw["split"] = False
    cycles = "cycles" in knobs          # Cycles' dimension sets (cycles_pairs)
    joint = "joint" in knobs            # the jitter and the first light point from stratified's joint 12-D set
    joint_owen = "jointowen" in knobs   # … from Sobol' dimensions 1–4 of one point set, each Owen-scrambled
    for k in knobs:
        if k == "bN":
            kw["block_bits"] = (spp if kw.get("split") is False else spp // 2).bit_length() - 1
        elif k.startswith("b"):
            kw["block_bits"] = int(k[1:])

    def pairs_function(seed, pixel, sample, pairs):
        module = sys.modules[SAMPLER_MODULE]
        pixel, sample, pairs = np.asarray(pixel), np.asarray(sample), np.asarray(pairs, np.int64)
        if cycles:
            return cycles_pairs(module, module._seed_key(seed), pixel, sample, pairs, xor=bool(kw.get("xor")),
                                split=kw.get("split", True))
        out = (variant_pairs(module._seed_key(seed), pixel, sample, pairs, **kw) if kw
               else module.owen_sobol_pairs(module._seed_key(seed), pixel, sample, pairs,
                                            np.isin(pairs, list(module.PADDED_OWEN))))
        if joint_owen:
            light = module.vertex_pair("padded", 0, module.SOBOL_LIGHT_POINT)
            for p, first_dim in ((module.PADDED_JITTER, 0), (light, 2)):
                for r in np.nonzero(pairs == p)[0]:
                    out[2 * r:2 * r + 2] = owen_joint(module, module._seed_key(seed), pixel, sample, first_dim)
        if joint:
            light = module.vertex_pair("padded", 0, module.SOBOL_LIGHT_POINT)
            for p, named in ((module.PADDED_JITTER, module.PAIR_JITTER), (light, module.PAIR_LIGHT_POINT)):
                for r in np.nonzero(pairs == p)[0]:
                    u = np.random.default_rng().random((2, pixel.size))
                    out[2 * r], out[2 * r + 1] = module.stratified_pair(seed, pixel, sample, u[0], u[1], pair=named)
        return out
    return name, pairs_function


#: the engine's sampler module the renders read (in an asset race: the extension's copy, polar_render.engine)
SAMPLER_MODULE = "engine.render.sampler"
_ENGINE_PAIRS = {}


def render_one(renderer, scene, spec, spp, seed, threads, settings=None):
    """(S0 image, S1 image) (H, W) of one render of sampler ``spec`` (``pattern``; "…/one_sequence" or
    "…/independent": with those halves) and its CPU seconds (``settings``: instead of the scene's)."""
    module = sys.modules[SAMPLER_MODULE]
    engine_pairs = _ENGINE_PAIRS.setdefault(SAMPLER_MODULE, (module.padded_pairs, module.cycles_pairs))
    sampler, variant = pattern(spec, spp)
    module.padded_pairs = variant if variant and sampler == "padded" else engine_pairs[0]
    module.cycles_pairs = variant if variant and sampler == "cycles" else engine_pairs[1]
    st = dataclasses.replace(settings or scene.settings, spp=spp, seed=seed, sampler=sampler, threads=threads)
    halves = halves_of(spec)[1]
    if halves:
        st = dataclasses.replace(st, halves=halves)
    t = time.process_time()
    result = renderer.render(st)
    cpu = time.process_time() - t
    y = result.stokes_luminance()
    return y[0], y[1], cpu


def renders(renderer, scene, samplers, spp, seeds, threads, settings=None):
    """{sampler: (S0 images, S1 images) (seeds, H, W), CPU seconds of its renders}; the samplers take
    turns seed by seed (a drift of the machine's speed is shared)."""
    got = {s: ([], [], 0.0) for s in samplers}
    for seed in range(seeds):
        for s in samplers:
            a, b, cpu = render_one(renderer, scene, s, spp, seed, threads, settings)
            got[s][0].append(a)
            got[s][1].append(b)
            got[s] = (got[s][0], got[s][1], got[s][2] + cpu)
    return {s: (np.array(a), np.array(b), cpu) for s, (a, b, cpu) in got.items()}


def mse(images):
    """A render's mean squared error (unbiased estimators: its variance), from several seeds."""
    return float(images.var(axis=0, ddof=1).mean())


def mse_rel_se(images):
    """Relative standard error of ``mse(images)``: per pixel the variance estimate from k seeds has
    relative variance 2/(k − 1) (normal errors), and the pixels' sum weighs each by its variance, so the
    mean has relative SE sqrt(2/(k − 1)·Σv²)/Σv (Σv² from the estimates, E[v̂²] = v²(1 + 2/(k − 1))):
    a few bright pixels holding the error make it large."""
    k = images.shape[0]
    v = images.var(axis=0, ddof=1).ravel()
    total = v.sum()
    return float(np.sqrt(2 / (k - 1) * (v * v).sum() / (1 + 2 / (k - 1))) / total) if total > 0 else 0.0


def trimmed(images):
    """``mse`` over the pixels without the 1 % of largest variance (a few fireflies' pixels hold most of a
    glossy asset's error, and their variance estimates from a few seeds are themselves noisy)."""
    v = np.sort(images.reshape(images.shape[0], -1).var(axis=0, ddof=1))
    return float(v[:int(0.99 * v.size)].mean())


def bias_z(a, b):
    """Difference of the image means of two sets of renders ÷ its standard error."""
    ma, mb = a.mean(axis=(1, 2)), b.mean(axis=(1, 2))
    se = np.sqrt(ma.var(ddof=1) / ma.size + mb.var(ddof=1) / mb.size)
    return float((ma.mean() - mb.mean()) / se) if se > 0 else 0.0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", default="32,128", help="comma list of samples per pixel")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--samplers", default="sobol,stratified,independent",
                    help="comma list; the first is compared with each other one")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--assets", default="", help="race on these real assets (tests/support/asset_parity: "
                    "Blender imports, lights and exports them as F12 does) instead of the peer scenes")
    ap.add_argument("--lighting", default="hdri", help="the assets' lighting (lamps or hdri)")
    ap.add_argument("--edit", default="", help="assets: 'diffuse' replaces every material by a grey 0.5 Diffuse BSDF")
    ap.add_argument("--bounces", type=int, default=8, help="assets: max bounces (0: direct light only)")
    args = ap.parse_args(argv)
    if args.assets:
        return asset_race(args)
    samplers = args.samplers.split(",")
    spps = [int(s) for s in args.spp.split(",")]
    first, others = samplers[0], samplers[1:]
    load = os.getloadavg()
    print(f"# sampler race, {datetime.date.today()}: {args.res}², {args.seeds} seeds per configuration, "
          f"{args.threads} thread(s), CPU time; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"# command: python tests/bench/sampler_race.py {' '.join(argv if argv is not None else sys.argv[1:])}")
    rows = []
    for name in args.scenes.split(","):
        scene = load_scene(os.path.join(SHARED, "peers", "scenes", f"{name}.json"))
        scene.camera.width = scene.camera.height = args.res
        renderer = Renderer(scene)
        for sampler in samplers:
            st = dataclasses.replace(scene.settings, sampler=pattern(sampler, 1)[0], threads=args.threads)
            renderer.warm_up(st)
        # one untimed full render: a scene's first one pays for growing the process's memory (measured
        # ~15 % more CPU time than the next), which would count against the sampler rendering first
        render_one(renderer, scene, samplers[0], spps[0], args.seeds, args.threads)
        for spp in spps:
            got = renders(renderer, scene, samplers, spp, args.seeds, args.threads)
            for s in samplers:
                s0, s1, cpu = got[s]
                print(f"{name:18s} {spp:4d} spp {s:11s} CPU {cpu:7.1f} s  MSE S0 {mse(s0):.3e}"
                      + ("" if name in NO_S1 else f"  S1 {mse(s1):.3e}"), flush=True)
            a0, a1, ta = got[first]
            for other in others:
                b0, b1, tb = got[other]
                r0 = tb * mse(b0) / (ta * mse(a0))
                r1 = None if name in NO_S1 else tb * mse(b1) / (ta * mse(a1))
                se0 = np.hypot(mse_rel_se(a0), mse_rel_se(b0))          # of the MSE ratio, relative
                rows.append((name, spp, other, mse(b0) / mse(a0), tb / ta, r0, se0 * r0, r1, bias_z(a0, b0)))
    print()
    print(f"| scene | spp | {first} vs | MSE S0 ÷ {first}'s | CPU {first} ÷ it | time to equal error S0 "
          f"(> 1: {first} faster) ± SE | same for S1 | bias z |")
    print("|---|---|---|---|---|---|---|---|")
    for name, spp, other, var_ratio, cpu_ratio, r0, se, r1, z in rows:
        print(f"| {name} | {spp} | {other} | {var_ratio:.2f} | {1 / cpu_ratio:.2f} | {r0:.2f} ± {se:.2f} | "
              f"{'—' if r1 is None else f'{r1:.2f}'} | {z:+.1f} |")


def diffuse_materials():
    """Every material's output replaced by a grey 0.5 Diffuse BSDF (docs/benchmarks.md, "Why BoomBox under the
    HDRI is noisier than Cycles outside its fireflies": the diffuse box)."""
    import bpy
    for mat in bpy.data.materials:
        if not mat.use_nodes:
            continue
        tree = mat.node_tree
        out = next(n for n in tree.nodes if n.type == "OUTPUT_MATERIAL")
        diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1.0)
        tree.links.new(diffuse.outputs["BSDF"], out.inputs["Surface"])


def asset_race(args):
    """The race on real assets: σ² = mean over the pixels where the camera sees the asset of the per-pixel
    variance over the seeds of the S0 luminance (the asset suite's noise, tests/bench/asset_speed.py), per
    sampler, and each sampler's σ² ÷ the first one's (± its standard error); equal samples, MSE only."""
    from tests.support import asset_parity as ap
    global SAMPLER_MODULE
    SAMPLER_MODULE = "polar_render.engine.render.sampler"
    samplers = args.samplers.split(",")
    load = os.getloadavg()
    print(f"# asset sampler race, {datetime.date.today()}: {args.lighting} {args.edit} {args.bounces} bounces, "
          f"{args.seeds} seeds, spp {args.spp}; "
          f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    for name in args.assets.split(","):
        asset = ap.CATALOGUE[name]
        w, h = asset.size if not args.res else (args.res, args.res)
        scene = ap.build(asset, args.lighting, w, h)
        hit = ap.coverage(scene, w, h)
        if args.edit == "diffuse":
            diffuse_materials()
        for spp in [int(s) for s in args.spp.split(",")]:
            renderer, settings, _ = ap.export_polar(scene, spp, args.bounces)
            got = renders(renderer, None, samplers, spp, args.seeds, args.threads, settings)
            first = got[samplers[0]][0][:, hit]
            for s in samplers:
                img = got[s][0][:, hit]
                se = np.hypot(mse_rel_se(img[:, :, None]), mse_rel_se(first[:, :, None]))
                print(f"{name:20s} {spp:4d} spp {s:22s} σ² {mse(img):.4e}  ÷ {samplers[0]}'s "
                      f"{mse(img) / mse(first):.2f} ± {se * mse(img) / mse(first):.2f}  without the 1 % noisiest "
                      f"pixels {trimmed(img) / trimmed(first):.2f}  CPU {got[s][2]:6.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    main()
