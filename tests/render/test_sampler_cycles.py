"""The "cycles" sampler: Cycles' pattern (sample/sobol_burley.h) — every role's numbers one point of a small
Owen-scrambled Sobol' set (engine.render.sampler.cycles_pairs, sets CYCLES_*; engine.kernels.sobol.owen_sobol_sets):
the light's 4-D set (point, choice, light number 3), the BSDF's 3-D one (direction, lobe), roulette's 1-D one, the
camera's 2-D ones, each index shuffled per (seed, pixel, parity, set), in the padded layout of pairs.

Tested here (compiled = NumPy twin bit for bit: test_sampler_sobol.py): the numbers are functions of (seed, pixel,
sample, pair) alone; a pixel's first 2^m even (odd) samples of each set's first two coordinates are a (0, m, 2)-net
and the light's and BSDF's 3-D points (1, m, 3)-nets (the choice stratified jointly with the point); every coordinate
uniform over pixels; the even and odd halves independent; renders keep the independent sampler's mean with less
noise.  The determinism of whole renders (threads, batches, resumption, adaptive rounds) is in test_stratified.py.
"""

import itertools

import numpy as np
import pytest

from engine.render.sampler import (PADDED_JITTER, PADDED_LENS, PADDED_WAVELENGTH, SOBOL_CHOICES, SOBOL_DIRECTION,
                                   SOBOL_LIGHT_POINT, SOBOL_ROULETTE, cycles_pairs, vertex_pair)
from tests.render.test_sampler_sobol import is_net, net_cells, peer_scene, unbiased_variances


def light_and_bsdf(seed, pixel, sample, bounce):
    """(light point x, y, light choice, light number 3), (direction x, y, lobe) of vertex ``bounce``."""
    u = cycles_pairs(seed, pixel, sample, [vertex_pair("cycles", bounce, r) for r in
                                           (SOBOL_LIGHT_POINT, SOBOL_DIRECTION, SOBOL_CHOICES, SOBOL_ROULETTE)])
    return (u[0], u[1], u[4], u[7]), (u[2], u[3], u[5])


def t_value(points, m):
    """The smallest t for which the 2^m points (d coordinates) are a (t, m, d)-net: every elementary interval of
    volume 2^(t − m) holds 2^t points."""
    for t in range(m + 1):
        if all(np.all(np.bincount(cells(points, ks), minlength=2 ** (m - t)) == 2 ** t)
               for ks in itertools.product(range(m - t + 1), repeat=len(points)) if sum(ks) == m - t):
            return t
    return m


def cells(points, ks):
    idx = np.zeros(points[0].size, np.int64)
    for p, k in zip(points, ks):
        idx = idx * 2 ** k + np.floor(p * 2 ** k).astype(np.int64)
    return idx


def test_numbers_depend_only_on_seed_pixel_sample_and_pair():
    """Any batch split, path order and pair list (pairs sharing a set or not) gives each (seed, pixel, sample,
    pair) the same numbers."""
    rng = np.random.default_rng(1)
    n = 3000
    pixel = rng.integers(0, 1 << 21, n)
    sample = np.where(rng.random(n) < 0.7, rng.integers(0, 256, n), rng.integers(0, 1 << 34, n))
    pairs = [0, 5, 3, 41, 4000]
    full = cycles_pairs(9, pixel, sample, pairs)
    assert full.shape == (10, n) and np.all((full >= 0) & (full < 1))
    order = rng.permutation(n)
    np.testing.assert_array_equal(cycles_pairs(9, pixel[order], sample[order], pairs), full[:, order])
    for part in np.array_split(np.arange(n), 7):
        np.testing.assert_array_equal(cycles_pairs(9, pixel[part], sample[part], pairs), full[:, part])
    for m, p in enumerate(pairs):                                   # each pair alone
        np.testing.assert_array_equal(cycles_pairs(9, pixel, sample, [p]), full[2 * m:2 * m + 2])
    assert not np.array_equal(cycles_pairs(10, pixel, sample, pairs), full)      # the seed matters


@pytest.mark.parametrize("bounce", [0, 1, 40])
def test_each_pixels_first_samples_of_each_role_are_nets(bounce):
    """For a pixel, the first 2^k even samples (and the first 2^k odd ones), k ≤ 7: the light point and the BSDF
    direction (each set's coordinates 0, 1) are (0, k, 2)-nets, and with the light choice (lobe) (1, k, 3)-nets
    (Sobol' dimensions 0–2 of one point): the choice is stratified jointly with the point it chooses for."""
    m = 7
    for pixel in (0, 12345):
        for parity in (0, 1):
            sample = parity + 2 * np.arange(2 ** m)
            light, bsdf = light_and_bsdf(3, np.full(sample.size, pixel), sample, bounce)
            for k in range(1, m + 1):
                assert is_net(light[0][:2 ** k], light[1][:2 ** k], k), (pixel, parity, k)
                assert is_net(bsdf[0][:2 ** k], bsdf[1][:2 ** k], k), (pixel, parity, k)
            assert t_value(light[:3], m) <= 1 and t_value(bsdf, m) <= 1
            assert t_value(light, m) <= 2                           # with light number 3
            assert t_value((light[2], bsdf[2]), m) > 1              # two sets: not one point (the shuffle differs)


def test_the_cameras_sets_are_nets():
    """The jitter, lens and wavelengths' pairs of a pixel's first 2^k even samples are (0, k, 2)-nets."""
    m = 6
    sample = 2 * np.arange(2 ** m)
    for pair in (PADDED_JITTER, PADDED_LENS, PADDED_WAVELENGTH):
        x, y = cycles_pairs(4, np.full(sample.size, 77), sample, [pair])
        assert all(is_net(x[:2 ** k], y[:2 ** k], k) for k in range(1, m + 1)), pair


def test_every_coordinate_is_uniform_over_pixels():
    """Over pixels, each sample index's numbers (every coordinate of the light's 4-D set, the BSDF's and
    roulette's) are uniform on [0, 1) (mean 1/2, second moment 1/3, 16 equal bins) and uncorrelated."""
    n = 200_000
    for s in (0, 1, 6, 63):
        light, bsdf = light_and_bsdf(2, np.arange(n), np.full(n, s), 1)
        rr = cycles_pairs(2, np.arange(n), np.full(n, s), [vertex_pair("cycles", 1, SOBOL_ROULETTE)])[0]
        numbers = (*light, *bsdf, rr)
        for v in numbers:
            assert abs(v.mean() - 0.5) < 0.004 and abs((v * v).mean() - 1 / 3) < 0.004
            counts = np.bincount(np.floor(v * 16).astype(int), minlength=16)
            assert counts.min() > n / 16 * 0.95 and counts.max() < n / 16 * 1.05
        c = np.corrcoef(np.array(numbers))
        assert np.all(np.abs(c[np.triu_indices(len(numbers), 1)]) < 0.01)


def test_even_and_odd_samples_are_independent_sequences():
    """Sample 2i and 2i + 1 of a pixel come from independently scrambled sequences: over pixels their numbers are
    uncorrelated, and within a pixel the odd half's light points fall in the even half's net cells no more often
    than independent nets' would (1/16)."""
    n = 200_000
    pairs = [PADDED_JITTER, vertex_pair("cycles", 0, SOBOL_LIGHT_POINT), vertex_pair("cycles", 0, SOBOL_CHOICES)]
    for i in (0, 3, 10):
        even = cycles_pairs(5, np.arange(n), np.full(n, 2 * i), pairs)
        odd = cycles_pairs(5, np.arange(n), np.full(n, 2 * i + 1), pairs)
        assert all(abs(np.corrcoef(a, b)[0, 1]) < 0.01 for a in even for b in odd)
    n_pix = 4000
    pixel = np.repeat(np.arange(n_pix), 16)
    half = np.tile(np.arange(16), n_pix)
    e = cycles_pairs(5, pixel, 2 * half, pairs[1:2])
    o = cycles_pairs(5, pixel, 2 * half + 1, pairs[1:2])
    same = net_cells(e[0], e[1], 4, 2) == net_cells(o[0], o[1], 4, 2)
    assert abs(same.mean() - 1 / 16) < 4 * np.sqrt(1 / 16 * 15 / 16 / same.size)


def test_renders_keep_the_independent_mean_with_less_noise():
    """rough_sphere_a030 (its noise the first vertex's BSDF direction), 16², 16 spp, 8 seeds: the mean of "cycles"
    renders = the independent sampler's within 4σ (unbiased_variances), with > 2× less variance (measured 2.50
    here, "sobol" 2.55, "padded" 3.25; at 64², 64 spp "cycles" has 0.73× "sobol"'s MSE, tests/bench/sampler_race.py)."""
    v = unbiased_variances(peer_scene("rough_sphere_a030", 16), ["cycles", "independent"], 8, 16)
    print(f"variance independent ÷ cycles {v['independent'].mean() / v['cycles'].mean():.2f}")
    assert v["independent"].mean() > 2 * v["cycles"].mean()
