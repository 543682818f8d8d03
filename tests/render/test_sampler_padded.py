"""The "padded" sampler: every number of a path — the camera's jitter, lens and wavelengths, and at every vertex
the light choice and point, lobe, direction and roulette — is a coordinate of a padded pair
(engine.render.sampler.padded_pairs, layout PADDED_* then SOBOL_* per vertex): the "sobol" sampler's shuffled
Sobol' (0, 2)-sequence pairs, the pixel jitter Owen-scrambled, every other pair XOR-scrambled.

Tested: the numbers are functions of (seed, pixel, sample, pair) alone (any batch, order, pair list; compiled =
NumPy twin), every pair of a pixel's first 2^m even (odd) samples is a (0, m, 2)-net, the even and odd halves
are independent, every number is uniform over pixels (so the estimator is unbiased: known integrals come out
within their error), renders keep the independent sampler's mean and have less noise than "sobol" where the
pattern matters.  Determinism of whole renders (threads, batches, resumption, adaptive rounds) is tested with
the other samplers' in tests/render/test_stratified.py.
"""

import numpy as np
import pytest

from engine.render.sampler import PADDED_FIRST, PADDED_JITTER, SOBOL_DIRECTION, padded_pairs, vertex_pair
from tests.render.test_sampler_sobol import is_net, net_cells, seed_images

#: pairs tested: the jitter (Owen), the wavelengths, the first vertex's direction, a deep vertex's choices (XOR)
PAIRS = [PADDED_JITTER, 2, vertex_pair("padded", 0, SOBOL_DIRECTION), vertex_pair("padded", 40, 2)]


def test_pair_layout():
    """The camera's pairs first, then SOBOL_PER_BOUNCE per vertex from the first one on."""
    assert vertex_pair("padded", 0, 0) == PADDED_FIRST
    assert vertex_pair("padded", 2, 3) == PADDED_FIRST + 2 * 4 + 3
    assert vertex_pair("sobol", 1, 0) == 0


def test_numbers_depend_only_on_seed_pixel_sample_and_pair():
    rng = np.random.default_rng(4)
    n = 3000
    pixel = rng.integers(0, 1 << 21, n)
    sample = np.where(rng.random(n) < 0.7, rng.integers(0, 256, n), rng.integers(0, 1 << 34, n))
    pairs = [0, 1, 5, 41]
    full = padded_pairs(9, pixel, sample, pairs)
    assert full.shape == (8, n) and np.all((full >= 0) & (full < 1))
    order = rng.permutation(n)
    np.testing.assert_array_equal(padded_pairs(9, pixel[order], sample[order], pairs), full[:, order])
    for part in np.array_split(np.arange(n), 5):
        np.testing.assert_array_equal(padded_pairs(9, pixel[part], sample[part], pairs), full[:, part])
    np.testing.assert_array_equal(padded_pairs(9, pixel, sample, [41, 0]), np.concatenate((full[6:8], full[0:2])))
    assert not np.array_equal(padded_pairs(10, pixel, sample, pairs), full)


@pytest.mark.parametrize("n", [0, 1, 2000])
def test_the_compiled_numbers_are_the_numpy_twins_bit_for_bit(n):
    from engine import kernels
    from engine.kernels import sobol
    from engine.render.sampler import _seed_key
    if not kernels.COMPILED:
        pytest.skip("Numba kernels disabled")
    rng = np.random.default_rng(n + 11)
    pixel = rng.integers(0, 1 << 22, n)
    sample = np.where(rng.random(n) < 0.5, rng.integers(0, 64, n), rng.integers(0, 1 << 40, n))
    pairs = np.array([0, 1, 2, 3, 17, 1 << 20], np.int64)
    owen = np.array([True, False, False, True, False, False])
    for seed in (0, 5, 2 ** 63 - 1):
        a = sobol.owen_sobol_pairs_numpy(_seed_key(seed), pixel, sample, pairs, owen)
        b = sobol.owen_sobol_pairs_numba(_seed_key(seed), pixel, sample, pairs, owen)
        assert np.array_equal(a, b)


@pytest.mark.parametrize("pair", PAIRS)
def test_each_pixels_first_samples_of_every_pair_are_nets(pair):
    """A pixel's first 2^k even samples of a pair (and its first 2^k odd ones) are a (0, k, 2)-net, k ≤ 7, and
    so is a later aligned block; an XOR-scrambled pair's points (a digital shift) also keep the sequence's
    digits below the net's resolution: within a pixel they are one offset apart from the strata's corners."""
    m = 7
    for pixel in (0, 1, 12345, 1 << 20):
        for parity in (0, 1):
            sample = parity + 2 * np.arange(2 ** m + 2 ** 5)
            x, y = padded_pairs(3, np.full(sample.size, pixel), sample, [pair])
            for k in range(1, m + 1):
                assert is_net(x[:2 ** k], y[:2 ** k], k), (pixel, parity, k)
            assert is_net(x[2 ** m:], y[2 ** m:], 5)
            if pair != PADDED_JITTER:           # a digital shift: every point the same offset within its stratum
                frac = np.floor(x[:2 ** m] * 2 ** 32) % 2 ** (32 - m)
                assert np.unique(frac).size == 1


def test_even_and_odd_halves_are_independent():
    """Over pixels, sample 2i's numbers and sample 2i + 1's are uncorrelated; within pixels the odd half's points
    fall in the even half's cells no more often than an independent net's would (1/16 for 16-cell nets)."""
    n = 200_000
    for i in (0, 3, 10):
        even = padded_pairs(5, np.arange(n), np.full(n, 2 * i), PAIRS)
        odd = padded_pairs(5, np.arange(n), np.full(n, 2 * i + 1), PAIRS)
        assert all(abs(np.corrcoef(a, b)[0, 1]) < 0.01 for a in even for b in odd)
    n_pix = 4000
    pixel = np.repeat(np.arange(n_pix), 16)
    half = np.tile(np.arange(16), n_pix)
    for pair in PAIRS:
        e = padded_pairs(5, pixel, 2 * half, [pair])
        o = padded_pairs(5, pixel, 2 * half + 1, [pair])
        same = net_cells(e[0], e[1], 4, 2) == net_cells(o[0], o[1], 4, 2)
        assert abs(same.mean() - 1 / 16) < 4 * np.sqrt(1 / 16 * 15 / 16 / same.size), pair


def test_known_integrals_come_out_unbiased():
    """Per pixel, 32 samples estimate ∫∫ f over [0, 1)² for f smooth (x·y², exact 1/6) and discontinuous (the
    disc x² + y² < 1, exact π/4), on a pixel jitter (Owen) and a direction pair (XOR); over 4000 pixels the
    mean estimate is the exact value within 4 standard errors, and the per-pixel variance is below independent
    numbers' 1/32·Var f: > 10× for the smooth f, > 1.6× for the disc (measured 44× and 3.7× with the Owen
    scramble, 20× and 2.1× with the digital shift; each half of a pixel's samples is a 16-point net)."""
    n_pix, spp = 4000, 32
    pixel = np.repeat(np.arange(n_pix), spp)
    sample = np.tile(np.arange(spp), n_pix)
    for pair in (PADDED_JITTER, PAIRS[2]):
        x, y = padded_pairs(7, pixel, sample, [pair])
        for f, exact, gain in ((lambda a, b: a * b * b, 1 / 6, 10),
                               (lambda a, b: (a * a + b * b < 1.0) * 1.0, np.pi / 4, 1.6)):
            values = f(x, y)
            est = values.reshape(n_pix, spp).mean(1)
            se = est.std(ddof=1) / np.sqrt(n_pix)
            assert abs(est.mean() - exact) < 4 * se + 1e-12, (pair, exact)
            assert est.var(ddof=1) < values.var() / spp / gain, (pair, exact)


def test_renders_keep_the_independent_mean_with_less_noise_than_sobol():
    """fresnel_sphere (its noise the pixel jitter over the sphere's edge and highlights), 24², 32 spp, 8 seeds:
    the image mean = the independent sampler's within 4σ; the pixel variance below "sobol"'s / 1.25 (64²,
    64 spp: 0.60× "sobol"'s, tests/bench/sampler_race.py)."""
    from engine.scene.loader import load_scene
    from tests.conftest import shared_path
    scene = load_scene(shared_path("peers", "scenes", "fresnel_sphere.json"))
    scene.camera.width = scene.camera.height = 24
    seeds, spp = 8, 32
    pad, _ = seed_images(scene, "padded", seeds, spp)
    ind, _ = seed_images(scene, "independent", seeds, spp)
    sob, _ = seed_images(scene, "sobol", seeds, spp)
    v_pad, v_ind, v_sob = (a.var(0, ddof=1) for a in (pad, ind, sob))
    assert abs(pad.mean() - ind.mean()) < 4 * np.sqrt(((v_pad + v_ind) / seeds).sum()) / v_pad.size
    print(f"variance independent ÷ padded {v_ind.mean() / v_pad.mean():.2f}, sobol ÷ padded "
          f"{v_sob.mean() / v_pad.mean():.2f}")
    assert v_sob.mean() > 1.25 * v_pad.mean()


def test_a_rough_metal_keeps_its_mean_with_the_direction_pairs():
    """rough_sphere_a030 (its noise the first vertex's BSDF direction), 16², 16 spp, 8 seeds: the mean of
    "padded" renders = the independent sampler's within 4σ, with > 3× less variance (measured 64², 64 spp:
    6.7×)."""
    from engine.scene.loader import load_scene
    from tests.conftest import shared_path
    scene = load_scene(shared_path("peers", "scenes", "rough_sphere_a030.json"))
    scene.camera.width = scene.camera.height = 16
    seeds, spp = 8, 16
    pad, _ = seed_images(scene, "padded", seeds, spp)
    ind, _ = seed_images(scene, "independent", seeds, spp)
    v_pad, v_ind = pad.var(0, ddof=1), ind.var(0, ddof=1)
    assert abs(pad.mean() - ind.mean()) < 4 * np.sqrt(((v_pad + v_ind) / seeds).sum()) / v_pad.size
    print(f"variance independent ÷ padded {v_ind.mean() / v_pad.mean():.2f}")
    assert v_ind.mean() > 3 * v_pad.mean()


def test_camera_rays_of_the_data_passes_are_the_integrators():
    """The data passes (engine.render.data_passes) draw the camera's numbers through the same function: with
    "padded" their jitter is the padded jitter pair (rows of camera_numbers)."""
    from engine.render.sampler import camera_numbers
    pixel, sample = np.arange(50), np.arange(50) % 7
    _, u = camera_numbers(3, "padded", pixel, sample, 2, 1)
    np.testing.assert_array_equal(u[:4], padded_pairs(3, pixel, sample, [0, 1]))
    _, v = camera_numbers(3, "sobol", pixel, sample, 2, 1)
    assert not np.array_equal(u[:2], v[:2]) and np.array_equal(u[4], v[4])
