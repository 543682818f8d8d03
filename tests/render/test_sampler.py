"""The stateless path sampler: the camera stage's one-pass start gives the same random numbers."""

import numpy as np
import pytest

from engine.render.sampler import PathSampler, path_keys


@pytest.mark.parametrize("seed", [0, 7, 2**40 + 3])
@pytest.mark.parametrize("k", [0, 2, 5])
def test_start_is_keys_then_next_and_continues_the_same_dimensions(seed, k):
    rng = np.random.default_rng(seed % 1000 + k)
    pixel = rng.integers(0, 1 << 22, 2000)
    sample = rng.integers(0, 4096, 2000)
    reference = PathSampler(path_keys(seed, pixel, sample))
    first = reference.next(k)
    sampler, u = PathSampler.start(seed, pixel, sample, k)
    np.testing.assert_array_equal(u, first)
    np.testing.assert_array_equal(sampler.keys, reference.keys)
    assert sampler.dimension == reference.dimension == k
    np.testing.assert_array_equal(sampler.next(3), reference.next(3))


def test_keys_differ_between_seeds_pixels_and_samples():
    pixel = np.arange(1000)
    keys = path_keys(0, pixel, np.zeros(1000, np.int64))
    assert np.unique(keys).size == 1000
    assert not np.array_equal(keys, path_keys(1, pixel, np.zeros(1000, np.int64)))
    assert not np.array_equal(keys, path_keys(0, pixel, np.ones(1000, np.int64)))


@pytest.mark.parametrize("skipped", [1, 4, 7])
def test_skip_leaves_the_same_following_dimensions_as_next(skipped):
    """The integrator skips the dimensions a bounce does not read (light and direction numbers at
    delta vertices): what follows must be the numbers ``next`` would have left, bit for bit."""
    pixel, sample = np.arange(500), np.full(500, 3)
    drawn = PathSampler(path_keys(5, pixel, sample))
    drawn.next(2)
    every = drawn.next(skipped + 3)
    skipping = PathSampler(path_keys(5, pixel, sample))
    skipping.next(2)
    skipping.skip(skipped)
    np.testing.assert_array_equal(skipping.next(3), every[skipped:])
    assert skipping.dimension == drawn.dimension
    # the cached dimension offsets are shared, never changed by a draw
    np.testing.assert_array_equal(skipping.next(3), drawn.next(3))


def test_stratified_pair_is_a_net_and_uniform():
    """Each pixel's first 2^m even (and odd) jitters (m = 4 here) are a (0, m, 2)-net: one point in every
    elementary interval of area 2^-m (16 × 1, 8 × 2, 4 × 4, 2 × 8, 1 × 16); over pixels, every sample
    index's jitter is uniform on [0, 1)² (the scramble differs per pixel, seed and parity), so the pixel
    estimate is unbiased, and the even and odd halves are independent (adaptive sampling's half-buffers)."""
    from engine.render.sampler import stratified_pair
    rng = np.random.default_rng(5)
    pixels = np.repeat(np.arange(50), 32)
    samples = np.tile(np.arange(32), 50)
    x, y = stratified_pair(7, pixels, samples, rng.random(pixels.size), rng.random(pixels.size))
    assert ((x >= 0) & (x < 1) & (y >= 0) & (y < 1)).all()
    for p in range(50):
        for parity in (0, 1):
            sel = (pixels == p) & (samples % 2 == parity)
            for kx in range(5):
                cells = (np.floor(x[sel] * 2 ** kx) * 2 ** (4 - kx) + np.floor(y[sel] * 2 ** (4 - kx))).astype(int)
                assert np.array_equal(np.sort(cells), np.arange(16))
    n = 200_000
    even, odd = (stratified_pair(5, np.arange(n), np.full(n, s), rng.random(n), rng.random(n)) for s in (6, 7))
    assert all(abs(np.corrcoef(a, b)[0, 1]) < 0.01 for a in even for b in odd)
    n = 200_000
    for s in (0, 1, 5, 12):
        x, y = stratified_pair(3, np.arange(n), np.full(n, s), rng.random(n), rng.random(n))
        # mean and second moment of U(0, 1): 1/2 and 1/3 (σ of the mean ≈ 0.29/√n ≈ 6.5e-4)
        for v in (x, y):
            assert abs(v.mean() - 0.5) < 0.004 and abs((v * v).mean() - 1 / 3) < 0.004
        assert abs(np.corrcoef(x, y)[0, 1]) < 0.01


@pytest.mark.parametrize("pair", [1, 2, 3, 4, 5])
def test_stratified_pairs_are_stratified_and_uniform(pair):
    """Sobol' dimensions 3–12 (the first vertex's light and BSDF numbers, the lens, the wavelengths):
    each coordinate of a pixel's first 16 even samples falls once in each sixteenth of [0, 1); over
    pixels each sample's pair is uniform and uncorrelated with the pixel jitter (pair 0) of the same
    sample."""
    from engine.render.sampler import stratified_pair
    rng = np.random.default_rng(pair)
    pixels = np.repeat(np.arange(40), 16)
    samples = np.tile(np.arange(0, 32, 2), 40)
    x, y = stratified_pair(11, pixels, samples, rng.random(pixels.size), rng.random(pixels.size), pair=pair)
    for p in range(40):
        for v in (x[pixels == p], y[pixels == p]):
            assert np.array_equal(np.sort(np.floor(v * 16).astype(int)), np.arange(16))
    n = 200_000
    for s in (0, 3, 9):
        pix, smp = np.arange(n), np.full(n, s)
        x, y = stratified_pair(2, pix, smp, rng.random(n), rng.random(n), pair=pair)
        jx, jy = stratified_pair(2, pix, smp, rng.random(n), rng.random(n), pair=0)
        for v in (x, y):
            assert abs(v.mean() - 0.5) < 0.004 and abs((v * v).mean() - 1 / 3) < 0.004
            for j in (jx, jy):
                assert abs(np.corrcoef(v, j)[0, 1]) < 0.01


@pytest.mark.parametrize("n", [0, 1, 1000])
def test_scrambled_sobol_pair_twins_bitwise(n):
    """The compiled stratified numbers are the NumPy twin's, bit for bit (sample indices up to 2^33:
    index sample // 2 keeps its low 32 bits)."""
    from engine import kernels
    from engine.kernels import hashing
    from engine.render.sampler import _PAIR_KEYS, _SOBOL_V, _seed_key
    if not kernels.COMPILED:
        pytest.skip("Numba kernels disabled")
    rng = np.random.default_rng(n)
    pixel = rng.integers(0, 1 << 20, n)
    sample = np.where(rng.random(n) < 0.5, rng.integers(0, 64, n), rng.integers(0, 1 << 33, n))
    u0, u1 = rng.random(n), rng.random(n)
    u0[:3] = np.nextafter(1.0, 0.0)             # the clamp below 1
    for pair in range(len(_PAIR_KEYS)):
        args = (_seed_key(5), pixel, sample, _PAIR_KEYS[pair], _SOBOL_V[2 * pair], _SOBOL_V[2 * pair + 1], u0, u1)
        a, b = hashing.scrambled_sobol_pair_numpy(*args), hashing.scrambled_sobol_pair_numba(*args)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
