"""Adaptive sampling robust to rare paths, and the per-path cost of shaded vertices.

A tile whose first pass missed a rare bright path would stop at min_spp for good; for the
polarisation quantities its σ is pooled with its 3×3 tile neighbourhood's
(engine.render.adaptive.pooled_error).  Synthetic images with a known σ per tile check
the rule; a real render checks the integrator's cost count.  No test times anything.
"""


import numpy as np
import pytest

import engine.render.adaptive as adaptive
from engine.render.adaptive import (TILE, AdaptiveSettings, HalfBuffers, neighbourhood_sigma, pooled_error,
                                    state_channels, state_from_channels, tile_ids)
from engine.render.estimate import predict
from engine.render.film import Film
from engine.render.integrator import PATH_COST, VERTEX_COST
from engine.render.renderer import Renderer
from tests.render.test_adaptive import GaussianTracer, small_scene
from tests.render.test_adaptive_cost import costly_render, tracer_of
from tests.support.adaptive import adaptive_render

SIDE = 5                                     # tiles per side of the synthetic images
HIDDEN = 2 * SIDE + 2                        # the centre tile


class PolarisedGaussianTracer(GaussianTracer):
    """Pixels of S0 = 1 and S1 = 0.3 + σ·z (DoLP ≈ 0.3 ± σ), z from GaussianTracer's hash; a pixel's
    noise appears only from sample ``hidden[p]`` on (a rare path its first samples did not find)."""

    def __init__(self, sigma, hidden):
        super().__init__(sigma)
        self.hidden = np.asarray(hidden, np.int64)

    def trace(self, pixel, sample, abort=None):
        values, stats = super().trace(pixel, sample, abort)
        noise = np.where(sample >= self.hidden[pixel], values[0, 0] - 1.0, 0.0)
        out = np.zeros_like(values)
        out[0] = 1.0
        out[1] = (0.3 + noise)[None, :]
        return out, stats


def polarised_render(sigma_tiles, threshold, hidden_tiles=None, quantity="dolp", min_spp=16, spp=1024,
                     side=SIDE, film=None, halves=None):
    W = H = side * TILE
    t = tile_ids(W, H)
    hidden = np.zeros(side * side, np.int64) if hidden_tiles is None else np.asarray(hidden_tiles)
    tracer = PolarisedGaussianTracer(np.asarray(sigma_tiles, np.float64)[t], hidden[t])
    film = Film(W, H) if film is None else film
    halves = HalfBuffers(W * H) if halves is None else halves

    reason, stats = adaptive_render(tracer, film, halves, spp, 1 << 16, AdaptiveSettings(threshold, quantity, min_spp))
    return film, halves, reason, stats


def tile_count(film, tile, side=SIDE):
    return int(film.count[np.flatnonzero(tile_ids(side * TILE, side * TILE) == tile)[0]])


def rare_path_image():
    """Every tile noisy (σ = 0.5) from its first sample, but the centre tile (σ = 1) only from
    sample 64 on: its 16-spp first pass sees no noise at all."""
    sigma = np.full(SIDE * SIDE, 0.5)
    sigma[HIDDEN] = 1.0
    hidden = np.zeros(SIDE * SIDE, np.int64)
    hidden[HIDDEN] = 64
    return sigma, hidden


# ------------------------------------------------------------------------------------ the pooling

def test_the_neighbourhood_sigma_is_the_rms_over_the_3x3_tiles_present():
    W = H = 3 * TILE
    tiles = tile_ids(W, H)
    pixels = np.arange(W * H)
    sigma = np.where(tiles == 4, 1.0, 0.0)                   # only the centre tile is noisy
    expected = np.sqrt(1.0 / np.array([4, 6, 4, 6, 9, 6, 4, 6, 4]))   # corners see 4 tiles, edges 6
    np.testing.assert_allclose(neighbourhood_sigma(sigma, tiles, pixels, W), expected[tiles])
    # a window: tiles outside it do not count (the centre tile now has 4 neighbours present)
    window = pixels[(pixels % W < 2 * TILE) & (pixels // W < 2 * TILE)]
    np.testing.assert_allclose(neighbourhood_sigma(sigma[window], tiles, window, W), 0.5)
    # an infinite σ (no estimate) counts as 0, not as ∞
    assert np.all(np.isfinite(neighbourhood_sigma(np.where(tiles == 0, np.inf, sigma), tiles, pixels, W)))


def test_the_pooled_error_weighs_the_neighbourhood_as_n_nb_samples():
    # σ² = (n·σ̂² + n_nb·σ_nb²)/(n + n_nb), e = σ/√n
    e, n, s_nb, n_nb = 0.05, 16.0, 0.8, 16.0
    assert pooled_error(e, n, s_nb, n_nb) == pytest.approx(np.sqrt((16 * 0.2 ** 2 + 16 * 0.64) / 32 / 16))
    assert pooled_error(e, n, s_nb, 0.0) == pytest.approx(e)                  # no weight: the own error
    # at n = n_nb: the quadratic mean of the own error and the neighbourhood's (σ_nb/√n)
    assert pooled_error(e, n, s_nb, n) == pytest.approx(np.sqrt((e ** 2 + s_nb ** 2 / n) / 2))
    # a quiet tile: the neighbourhood's share falls as 1/n, the own error as 1/√n
    m = np.array([16.0, 64.0, 256.0])
    quiet = pooled_error(0.0, m, s_nb, n_nb)
    np.testing.assert_allclose(quiet, s_nb * np.sqrt(n_nb / (m * (m + n_nb))))


def test_a_tile_whose_first_pass_missed_its_noise_goes_on_when_its_neighbours_are_noisy(monkeypatch):
    sigma, hidden = rare_path_image()
    film, _, reason, _ = polarised_render(sigma, 0.01, hidden)
    n = tile_count(film, HIDDEN)
    assert n >= 256, n                 # past the samples that found its noise, then on by its own error
    monkeypatch.setattr(adaptive, "NEIGHBOURHOOD_WEIGHT", 0.0)
    without = polarised_render(sigma, 0.01, hidden)[0]
    assert tile_count(without, HIDDEN) == 16                 # without the pooling it stops at min_spp for good


def test_a_quiet_tile_beside_noisy_ones_stops_after_a_few_steps():
    # the centre tile is truly quiet: its own samples soon outweigh the neighbourhood
    sigma = np.full(SIDE * SIDE, 0.5)
    sigma[HIDDEN] = 0.0
    film, _, _, _ = polarised_render(sigma, 0.01)
    n = tile_count(film, HIDDEN)
    # e(n) = σ_nb·√(16/(n(n + 16))) with σ_nb = √(8/9)·0.5 reaches T = 0.01 at n ≈ 180 (a checkpoint above)
    assert 16 < n <= 256 and n < 0.5 * tile_count(film, 0), (n, tile_count(film, 0))


def test_s0_is_not_floored():
    sigma, hidden = rare_path_image()
    film, _, _, _ = polarised_render(sigma, 0.01, hidden, quantity="s0")
    assert np.all(film.count == 16)                          # S0 = 1 everywhere: no noise, no floor


@pytest.mark.parametrize("quantity", ["dolp", "stokes", "docp", "aolp"])
def test_an_image_below_the_threshold_at_min_spp_still_stops_there(quantity):
    # tiles of σ up to 2T: every tile's error at 16 spp (≈ σ/4) is below T, and so is its pooled
    # error (the quadratic mean of its own and its neighbourhood's): nothing goes on
    T = 0.01
    sigma = np.geomspace(1e-4, 2 * T, SIDE * SIDE)[np.random.default_rng(1).permutation(SIDE * SIDE)]
    film, _, reason, _ = polarised_render(sigma, T, quantity=quantity)
    assert reason == "threshold" and np.all(film.count == 16)


def test_resuming_continues_the_pooled_counts_exactly():
    sigma, hidden = rare_path_image()
    whole, whole_halves, _, _ = polarised_render(sigma, 0.01, hidden)
    part, part_halves, _, _ = polarised_render(sigma, 0.05, hidden)          # a looser threshold first
    film, halves = state_from_channels(state_channels(part, part_halves), part.spp_image().astype(np.uint32))
    resumed, _, _, _ = polarised_render(sigma, 0.01, hidden, film=film, halves=halves)
    np.testing.assert_array_equal(resumed.count, whole.count)
    np.testing.assert_array_equal(resumed.sums, whole.sums)


def test_the_prediction_pools_as_the_render_does(monkeypatch):
    sigma, hidden = rare_path_image()
    film, halves, _, _ = polarised_render(sigma, np.inf, hidden)              # the first pass alone
    assert np.all(film.count == 16)
    centre = tile_ids(SIDE * TILE, SIDE * TILE) == HIDDEN
    p = predict(film, halves, "dolp", 0.01, 16, 1024, seconds_per_sample=1e-6)
    assert p.counts[centre].min() > 16
    # a quiet tile beside noisy ones: predicted where the render stops it
    sigma[HIDDEN], hidden[HIDDEN] = 0.0, 0
    quiet = polarised_render(sigma, 0.01)[0]
    first = polarised_render(sigma, np.inf)
    q = predict(first[0], first[1], "dolp", 0.01, 16, 1024, seconds_per_sample=1e-6)
    assert q.counts[centre].max() == quiet.count[centre].max()
    monkeypatch.setattr(adaptive, "NEIGHBOURHOOD_WEIGHT", 0.0)
    assert np.all(predict(film, halves, "dolp", 0.01, 16, 1024, seconds_per_sample=1e-6).counts[centre] == 16)


# ------------------------------------------------------------------------------------ cost

def test_a_state_with_the_old_ray_counts_resumes_with_equal_costs():
    # files of the earlier version stored rays (``adaptive.rays``, ``adaptive.first.rays``), another
    # unit: they are ignored, as for files that counted nothing
    sigma, cost = np.geomspace(0.05, 1.0, 4), [1, 2, 3, 4]
    film, halves, _, _ = costly_render(sigma, cost, 0.2, side=2)
    channels = {k.replace(".cost.", ".rays."): v for k, v in state_channels(film, halves).items()}
    assert any(".rays." in k for k in channels)
    old_film, old = state_from_channels(channels, film.spp_image().astype(np.uint32))
    assert old.cost.sum() == 0 and old.first[2].sum() == 0
    resumed, _, reason, stats = costly_render(sigma, cost, 0.01, side=2, halves=old, film=old_film)
    assert stats["cost_per_sample"] == 0.0 and reason == "threshold"
    np.testing.assert_array_equal(resumed.count, costly_render(sigma, [1, 1, 1, 1], 0.01, side=2)[0].count)


def test_a_paths_cost_is_one_plus_four_per_surface_hit_and_light_sample():
    scene = small_scene("cornell_lambert", res=8, spp=4)
    renderer = Renderer(scene)
    tracer = tracer_of(scene, renderer)
    pixel = np.tile(np.arange(64), 4)
    sample = np.repeat(np.arange(4), 64)
    hits, lights, current = np.zeros(pixel.size, np.int64), np.zeros(pixel.size, np.int64), {}
    intersect, scatter, next_event = tracer._intersect, tracer._scatter, tracer._next_event

    def counted_intersect(state, acc, bounce):
        out = intersect(state, acc, bounce)
        np.add.at(hits, state.path[out[1]], 1)
        return out

    def counted_scatter(state, acc, surf, bounce):
        current["path"] = state.path
        return scatter(state, acc, surf, bounce)

    def counted_next_event(sp, lookup, bsdf, T, rows, *args, **kwargs):
        np.add.at(lights, current["path"][rows], 1)
        return next_event(sp, lookup, bsdf, T, rows, *args, **kwargs)
    tracer._intersect, tracer._scatter, tracer._next_event = counted_intersect, counted_scatter, counted_next_event
    cost = tracer.trace(pixel, sample)[1]["path_cost"]
    assert (PATH_COST, VERTEX_COST) == (1, 4)
    assert lights.sum() > 0 and hits.max() > 1
    np.testing.assert_array_equal(cost, PATH_COST + VERTEX_COST * (hits + lights))


def test_non_adaptive_renders_do_not_carry_the_cost():
    scene = small_scene("glass_sphere", res=8, spp=2)
    result = Renderer(scene).render(scene.settings)
    assert "path_cost" not in result.stats and "path_rays" not in result.stats


# ------------------------------------------------------------------------------------ accumulation

def test_adding_a_unit_at_once_gives_the_sums_of_one_sample_pass_at_a_time():
    # many passes of few pixels (a late round): every pixel's sums in ascending sample order,
    # bit for bit what adding pass by pass gives (the reference loop below)
    from engine.render.adaptive import add_in_sample_order
    rng = np.random.default_rng(5)
    W = H = 8
    pix = rng.choice(W * H, 20, replace=False)
    pixel, sample = np.tile(pix, 37), np.repeat(np.arange(3, 40), 20)
    values = rng.lognormal(0.0, 2.0, (4, 3, pixel.size)) * rng.choice([-1.0, 1.0], (4, 3, pixel.size))
    alpha = rng.random(pixel.size)
    film, halves = Film(W, H), HalfBuffers(W * H)
    add_in_sample_order(film, halves, pixel, sample, values, alpha)
    ref, ref_halves = Film(W, H), HalfBuffers(W * H)
    ref.alpha_sums = np.zeros(W * H)
    y = np.einsum("c,scn->sn", adaptive.LUMINANCE_WEIGHTS, values)
    for s in np.unique(sample):
        m = sample == s
        p = pixel[m]
        for k in range(4):
            for c in range(3):
                ref.sums[k, c, p] = ref.sums[k, c, p] + values[k, c, m]
            ref.sumsq_y[k, p] = ref.sumsq_y[k, p] + y[k, m] * y[k, m]
            ref_halves.sums[s % 2, k, p] = ref_halves.sums[s % 2, k, p] + y[k, m]
        ref.alpha_sums[p] = ref.alpha_sums[p] + alpha[m]
        ref.count[p] += 1
    np.testing.assert_array_equal(film.sums, ref.sums)
    np.testing.assert_array_equal(film.sumsq_y, ref.sumsq_y)
    np.testing.assert_array_equal(halves.sums, ref_halves.sums)
    np.testing.assert_array_equal(film.alpha_sums, ref.alpha_sums)
    np.testing.assert_array_equal(film.count, ref.count)
    # the same samples in another order (a pixel's samples shuffled): the same film sums (the
    # luminance, an einsum, may round differently at another column position, so not compared here)
    shuffled = rng.permutation(pixel.size)
    film2, halves2 = Film(W, H), HalfBuffers(W * H)
    add_in_sample_order(film2, halves2, pixel[shuffled], sample[shuffled], values[:, :, shuffled], alpha[shuffled])
    np.testing.assert_array_equal(film2.sums, ref.sums)
    np.testing.assert_array_equal(film2.count, ref.count)
