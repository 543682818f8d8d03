"""Adaptive sampling weighed by cost: per-path ray counts, the cost-weighted stopping rule, its state.

A sample of a tile costs c rays; the counts that minimise the image's MSE at equal cost are
n ∝ σ/√c (engine.render.adaptive).  Synthetic images with a known σ and cost per tile check the
rule; real renders check that the ray counts are deterministic.  No test times anything.
"""

import dataclasses
import math

import numpy as np
import pytest

from engine.render.adaptive import (AdaptiveSettings, HalfBuffers, TILE, allocation_level, cost_weight,
                                    cost_per_sample, state_channels, state_from_channels, tile_ids)
from engine.render.estimate import cost_map, mse_time_gain, predict, tile_cost_per_sample
from engine.render.film import Film
from engine.render.integrator import PathTracer
from engine.render.renderer import Renderer, RenderRequest
from tests.render.test_adaptive import GaussianTracer, small_scene
from tests.support.adaptive import adaptive_render


class CostlyGaussianTracer(GaussianTracer):
    """GaussianTracer whose samples of pixel p trace ``rays[p]`` rays each (the integrator's count)."""

    def __init__(self, sigma, rays):
        super().__init__(sigma)
        self.rays = np.asarray(rays, np.int64)

    def trace(self, pixel, sample, abort=None):
        values, stats = super().trace(pixel, sample, abort)
        stats["path_cost"] = self.rays[pixel]
        return values, stats


def costly_render(sigma_tiles, rays_tiles, threshold, side, min_spp=16, spp=4096, halves=None, film=None):
    W = H = side * TILE
    t = tile_ids(W, H)
    tracer = CostlyGaussianTracer(np.asarray(sigma_tiles, np.float64)[t], np.asarray(rays_tiles)[t])
    film = Film(W, H) if film is None else film
    halves = HalfBuffers(W * H) if halves is None else halves

    reason, stats = adaptive_render(tracer, film, halves, spp, 1 << 16, AdaptiveSettings(threshold, "s0", min_spp))
    return film, halves, reason, stats


def per_tile(a, side):
    """One pixel's value per tile (tiles share their count)."""
    return a[np.searchsorted(tile_ids(side * TILE, side * TILE), np.arange(side * side))]


# ------------------------------------------------------------------------------------ the rule

def test_a_dear_tile_gets_fewer_samples_than_a_cheap_one_of_equal_sigma():
    # 16 noisy tiles of equal σ, half of them 4× dearer, among 48 quiet ones: at equal cost the
    # optimum is n ∝ σ/√c, so the dear tiles stop at half the cheap ones' count (the noisy tiles'
    # shares are met above the threshold; the quiet tiles are below it at min_spp)
    side = 8
    sigma = np.where(np.arange(64) < 16, 1.0, 0.01)
    rays = np.where((np.arange(64) < 16) & (np.arange(64) % 2 == 1), 8, 2)
    T = 0.02
    film, halves, reason, stats = costly_render(sigma, rays, threshold=T, side=side)
    n = per_tile(film.count, side).astype(np.float64)
    cheap, dear = n[(sigma == 1) & (rays == 2)], n[rays == 8]
    assert reason == "threshold" and np.all(n[sigma < 1] == 16) and dear.min() > 16
    ratio = np.median(dear) / np.median(cheap)
    assert 0.38 < ratio < 0.65, (cheap, dear)                  # 1/√4 = 0.5 (± a checkpoint step and noise)
    # and as predicted: μ = T²/mean(σ·w), w = √(c/c̄), c̄ = 2.75 rays per sample
    assert stats["cost_per_sample"] == pytest.approx(2.75)
    w = np.sqrt(rays / 2.75)
    mu = T ** 2 / np.mean(sigma * w)
    assert stats["allocation_level"] == pytest.approx(mu, rel=0.3)
    np.testing.assert_allclose(np.median(cheap), 1.0 / (mu * w[0]), rtol=0.35)
    # the rays the half-buffers count are the tracer's, sample by sample
    np.testing.assert_array_equal(halves.cost, film.count * rays[tile_ids(32, 32)])


def test_equal_costs_give_the_rule_without_costs():
    sigma = np.geomspace(0.05, 1.0, 16)
    a = costly_render(sigma, np.full(16, 3), 0.01, side=4)[0]
    b = costly_render(sigma, np.full(16, 7), 0.01, side=4)[0]         # a constant cost cancels in n = σ/(μ·w)
    np.testing.assert_array_equal(a.count, b.count)


def test_every_tile_below_the_threshold_stops_whatever_its_cost():
    # the cheap tiles' share would give them more samples, but their error is below T at min_spp
    sigma = np.full(4, 0.01)
    sigma[0] = 1.0
    film, _, reason, _ = costly_render(sigma, [40, 1, 1, 1], 0.01, side=2)
    quiet = tile_ids(8, 8) != 0
    assert np.all(film.count[quiet] == 16) and film.count[~quiet].min() > 16 and reason == "threshold"


def test_cost_weighted_counts_gain_at_equal_cost_over_counts_that_ignore_it():
    # σ and cost vary independently over 64 tiles: the cost-weighted rule's MSE × cost beats the rule
    # without costs (n ∝ σ), measured with the true σ and cost
    rng = np.random.default_rng(3)
    sigma = np.geomspace(0.2, 2.0, 64)[rng.permutation(64)]
    rays = rng.choice([1, 2, 4, 8, 16], 64)
    weighted = costly_render(sigma, rays, 0.05, side=8)[0]
    plain = costly_render(sigma, np.ones(64, int), 0.05, side=8)[0]
    n_w, n_p = per_tile(weighted.count, 8), per_tile(plain.count, 8)
    g_w, g_p = mse_time_gain(sigma ** 2, rays, n_w), mse_time_gain(sigma ** 2, rays, n_p)
    assert g_w > 1.1 * g_p, (g_w, g_p)


def test_the_allocation_level_with_costs_gives_the_threshold_as_the_images_rms_error():
    sigma = np.array([0.01, 0.1, 0.1, 1.0, 3.0])
    w = np.sqrt(np.array([1.0, 4.0, 0.5, 2.0, 1.0]))
    mu = allocation_level(sigma, 0.02, w)
    n = sigma / (mu * w)                                       # the optimal counts n ∝ σ/√c
    assert math.sqrt(np.mean(sigma ** 2 / n)) == pytest.approx(0.02)
    assert allocation_level(sigma, 0.02, np.ones(5)) == allocation_level(sigma, 0.02)
    # tiles without an estimate yet (σ = ∞) do not count; nothing noisy: every tile stops at once
    assert allocation_level(np.r_[sigma, np.inf], 0.02, np.r_[w, 1.0]) == pytest.approx(mu)
    assert allocation_level(np.zeros(3), 0.02, np.ones(3)) == math.inf


def test_cost_weight_is_the_root_of_the_tiles_rays_per_sample_over_the_images():
    W = H = 2 * TILE
    tiles = tile_ids(W, H)
    counts = np.full(W * H, 4, np.int64)
    rays = (counts * np.array([2, 8, 4, 2])[tiles]).astype(np.int64)
    pixels = np.arange(W * H)
    c_bar = cost_per_sample(rays, counts, pixels)
    assert c_bar == pytest.approx(4.0)
    w = cost_weight(rays, counts, tiles, pixels, c_bar)
    np.testing.assert_allclose(w, np.sqrt(np.array([2, 8, 4, 2]) / 4.0)[tiles])
    # no rays counted (an EXR of an older version), or a tile without samples: weight 1
    assert cost_per_sample(np.zeros(W * H, np.int64), counts, pixels) == 0.0
    np.testing.assert_array_equal(cost_weight(rays, counts, tiles, pixels, 0.0), 1.0)
    none = counts.copy()
    none[tiles == 1] = 0
    assert np.all(cost_weight(np.where(tiles == 1, 0, rays), none, tiles, pixels, c_bar)[tiles == 1] == 1.0)


# ------------------------------------------------------------------------------------ state

def test_rays_and_the_first_pass_rays_travel_with_the_state():
    film, halves, _, _ = costly_render(np.geomspace(0.05, 1.0, 4), [1, 2, 3, 4], 0.01, side=2)
    restored_film, restored = state_from_channels(state_channels(film, halves), film.spp_image().astype(np.uint32))
    np.testing.assert_array_equal(restored.cost, halves.cost)
    for a, b in zip(restored.first, halves.first):
        np.testing.assert_array_equal(a, b)
    assert np.all(halves.first[2] == 16 * np.array([1, 2, 3, 4])[tile_ids(8, 8)])


def test_a_state_without_ray_counts_resumes_with_equal_costs():
    sigma, rays = np.geomspace(0.05, 1.0, 4), [1, 2, 3, 4]
    film, halves, _, _ = costly_render(sigma, rays, 0.2, side=2)
    channels = {k: v for k, v in state_channels(film, halves).items() if ".cost." not in k}
    old_film, old = state_from_channels(channels, film.spp_image().astype(np.uint32))
    assert old.cost.sum() == 0 and old.first[2].sum() == 0
    resumed, resumed_halves, reason, stats = costly_render(sigma, rays, 0.01, side=2, halves=old, film=old_film)
    assert stats["cost_per_sample"] == 0.0 and reason == "threshold"
    equal = costly_render(sigma, [1, 1, 1, 1], 0.01, side=2)[0]           # the rule without costs
    np.testing.assert_array_equal(resumed.count, equal.count)


def test_resuming_continues_the_cost_weighted_counts_exactly():
    sigma, rays = np.geomspace(0.05, 1.0, 16), np.arange(1, 17)
    whole, whole_halves, _, _ = costly_render(sigma, rays, 0.01, side=4)
    part, part_halves, _, _ = costly_render(sigma, rays, 0.05, side=4)     # a looser threshold first
    film, halves = state_from_channels(state_channels(part, part_halves), part.spp_image().astype(np.uint32))
    resumed, resumed_halves, _, _ = costly_render(sigma, rays, 0.01, side=4, halves=halves, film=film)
    np.testing.assert_array_equal(resumed.count, whole.count)
    np.testing.assert_array_equal(resumed.sums, whole.sums)
    np.testing.assert_array_equal(resumed_halves.cost, whole_halves.cost)


# ------------------------------------------------------------------------------------ the integrator's counts

@pytest.fixture(scope="module")
def sphere():
    scene = small_scene("glass_sphere", res=16, spp=8)
    return scene, Renderer(scene)


def tracer_of(scene, renderer):
    st = dataclasses.replace(scene.settings, polarisation="full")   # what the renderer resolves "auto" to
    return PathTracer(renderer.compiled, renderer.lights, renderer.camera, st)


def test_per_path_ray_counts_do_not_depend_on_the_batch(sphere):
    scene, renderer = sphere
    tracer = tracer_of(scene, renderer)
    pixel = np.tile(np.arange(256), 4)
    sample = np.repeat(np.arange(4), 256)
    _, whole = tracer.trace(pixel, sample)
    rays = whole["path_cost"]
    order = np.random.default_rng(0).permutation(pixel.size)
    parts = np.empty_like(rays)
    for chunk in np.array_split(order, 5):                    # other batches, other orders
        parts[chunk] = tracer.trace(pixel[chunk], sample[chunk])[1]["path_cost"]
    np.testing.assert_array_equal(parts, rays)
    # every path traces its camera ray; the counts hold the segments and a light sample per NEE vertex
    assert rays.min() >= 1 and rays.sum() >= whole["rays"] and len(np.unique(rays)) > 2


def test_a_tracer_that_does_not_count_costs_traces_the_same_paths(sphere):
    """Uniform renders skip the per-path cost counting (only adaptive sampling reads it): same values,
    same ray counts, no path_cost; the renderer counts only for adaptive renders."""
    scene, renderer = sphere
    st = dataclasses.replace(scene.settings, polarisation="full")
    counting = PathTracer(renderer.compiled, renderer.lights, renderer.camera, st, count_cost=True)
    silent = PathTracer(renderer.compiled, renderer.lights, renderer.camera, st, count_cost=False)
    pixel = np.tile(np.arange(256), 4)
    sample = np.repeat(np.arange(4), 256)
    values, stats = counting.trace(pixel, sample)
    values_silent, stats_silent = silent.trace(pixel, sample)
    np.testing.assert_array_equal(values_silent, values)
    assert "path_cost" in stats and "path_cost" not in stats_silent
    assert {k: stats[k] for k in ("rays", "shadow_rays", "nonfinite")} == \
        {k: stats_silent[k] for k in ("rays", "shadow_rays", "nonfinite")}
    assert not renderer.tracer(renderer.plan(st)).count_cost
    assert renderer.tracer(renderer.plan(st), count_cost=True).count_cost


def test_rays_of_an_adaptive_render_do_not_depend_on_threads_or_batches_and_weigh_the_counts(sphere):
    scene, renderer = sphere
    ad = AdaptiveSettings(threshold=0.02, quantity="s0", min_spp=8)
    st = dataclasses.replace(scene.settings, spp=64)
    ref = renderer.render(RenderRequest(st, adaptive=ad))
    st2 = dataclasses.replace(st, threads=2, batch_rays=300)
    other = renderer.render(RenderRequest(st2, adaptive=ad))
    np.testing.assert_array_equal(other.halves.cost, ref.halves.cost)
    np.testing.assert_array_equal(other.film.count, ref.film.count)
    np.testing.assert_array_equal(other.film.sums, ref.film.sums)
    c = tile_cost_per_sample(ref.film, ref.halves)
    assert ref.stats["cost_per_sample"] > 1 and c.max() > 1.5 * c.min()       # glass is dearer than the floor


# ------------------------------------------------------------------------------------ the estimate

def test_cost_map_spreads_a_units_time_over_its_tiles_by_their_rays():
    units = [(np.array([0, 1]), 4, 2.0, 12), (np.array([2, 3]), 4, 6.0, 12)]   # 1/6 and 1/2 s per ray
    rays_per_sample = np.array([1.0, 5.0, 3.0, 3.0, 2.0])
    sps = cost_map(units, 5, seconds=1.0, cost_per_sample=rays_per_sample)  # wall 1 s (two threads)
    raw = np.array([1 / 6, 5 / 6, 1.5, 1.5])
    np.testing.assert_allclose(sps[:4], raw / 8.0)                         # the units took 8 s in all
    assert float(np.sum(sps[:4] * 2)) == pytest.approx(1.0)               # the pilot's samples: its wall time
    # units without rays: every pixel of a unit costs the same (the earlier map)
    np.testing.assert_allclose(cost_map([u[:3] for u in units], 5, 1.0, rays_per_sample)[:4],
                               [0.0625, 0.0625, 0.1875, 0.1875])


def test_prediction_gives_dear_tiles_fewer_samples():
    side = 8
    sigma = np.where(np.arange(64) < 16, 1.0, 0.01)
    rays = np.where((np.arange(64) < 16) & (np.arange(64) % 2 == 1), 8, 2)
    film, halves, _, _ = costly_render(sigma, rays, threshold=math.inf, side=side, min_spp=64)
    p = predict(film, halves, "s0", 0.02, 16, 4096, seconds_per_sample=1e-6)
    n = per_tile(p.counts, side)
    assert 0.38 < np.median(n[rays == 8]) / np.median(n[(sigma == 1) & (rays == 2)]) < 0.65
