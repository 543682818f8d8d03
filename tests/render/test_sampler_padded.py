"""The "padded" sampler: every number of a path — the camera's jitter, lens and wavelengths, and at every vertex
the light choice and point, lobe, direction and roulette — is a coordinate of a padded pair
(engine.render.sampler.padded_pairs, layout PADDED_* then SOBOL_* per vertex): the "sobol" sampler's shuffled
Sobol' (0, 2)-sequence pairs, the pixel jitter Owen-scrambled, every other pair XOR-scrambled.

Tested here: the layout, the digital shift of the XOR-scrambled pairs, known integrals come out unbiased and
stratified, renders keep the independent sampler's mean and have less noise than "sobol" where the pattern
matters.  That the numbers are functions of (seed, pixel, sample, pair) alone (compiled = NumPy twin), every pair
of a pixel's first 2^m even (odd) samples a (0, m, 2)-net and the even and odd halves independent is tested with
"sobol"'s pairs (tests/render/test_sampler_sobol.py, parametrised by the pairs function); the determinism of
whole renders (threads, batches, resumption, adaptive rounds) with the other samplers' in test_stratified.py.
"""

import dataclasses

import numpy as np

from engine.render.sampler import PADDED_FIRST, PADDED_JITTER, SOBOL_DIRECTION, padded_pairs, vertex_pair
from tests.render.test_sampler_sobol import peer_scene, unbiased_variances

#: pairs tested: the jitter (Owen), the wavelengths, the first vertex's direction, a deep vertex's choices (XOR)
PAIRS = [PADDED_JITTER, 2, vertex_pair("padded", 0, SOBOL_DIRECTION), vertex_pair("padded", 40, 2)]


def test_pair_layout():
    """The camera's pairs first, then SOBOL_PER_BOUNCE per vertex from the first one on."""
    assert vertex_pair("padded", 0, 0) == PADDED_FIRST
    assert vertex_pair("padded", 2, 3) == PADDED_FIRST + 2 * 4 + 3
    assert vertex_pair("sobol", 1, 0) == 0


def test_xor_scrambled_pairs_keep_the_sequences_digits():
    """Every pair but the jitter is a digital shift of the shuffled sequence: within a pixel's first 2^m even
    samples every point sits at the same offset within its stratum of width 2^-m (the jitter, Owen-scrambled,
    does not); their (0, m, 2)-nets, decorrelation and independent halves are tested with "sobol"'s
    (tests/render/test_sampler_sobol.py, parametrised by the pairs function)."""
    m = 7
    for pair in PAIRS:
        for pixel in (0, 12345):
            sample = 2 * np.arange(2 ** m)
            x, _ = padded_pairs(3, np.full(sample.size, pixel), sample, [pair])
            offsets = np.unique(np.floor(x * 2 ** 32) % 2 ** (32 - m)).size
            assert (offsets == 1) == (pair != PADDED_JITTER), (pair, offsets)


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
    64 spp: 0.60× "sobol"'s, tests/bench/sampler_race.py), both with independent halves as measured there (with one
    sequence each gains, "sobol" more: docs/benchmarks/sampling-patterns.md)."""
    scene = peer_scene("fresnel_sphere", 24)
    scene.settings = dataclasses.replace(scene.settings, halves="independent")
    v = unbiased_variances(scene, ["padded", "independent", "sobol"], 8, 32)
    v_pad, v_ind, v_sob = v["padded"], v["independent"], v["sobol"]
    print(f"variance independent ÷ padded {v_ind.mean() / v_pad.mean():.2f}, sobol ÷ padded "
          f"{v_sob.mean() / v_pad.mean():.2f}")
    assert v_sob.mean() > 1.25 * v_pad.mean()


def test_a_rough_metal_keeps_its_mean_with_the_direction_pairs():
    """rough_sphere_a030 (its noise the first vertex's BSDF direction), 16², 16 spp, 8 seeds: the mean of
    "padded" renders = the independent sampler's within 4σ, with > 3× less variance (measured 64², 64 spp:
    6.7×)."""
    v = unbiased_variances(peer_scene("rough_sphere_a030", 16), ["padded", "independent"], 8, 16)
    v_pad, v_ind = v["padded"], v["independent"]
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
