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
