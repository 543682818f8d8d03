"""Adaptive sampling with a time budget (a time limit without a threshold) and the nets ladder.

Budget mode spends rounds on the share rule's counts n ∝ σ/√c for a cost that grows by
BUDGET_GROWTH per round, until the time runs out.  Synthetic tracers with a known σ and cost per
tile check the counts; the time runs on injected clocks (no test times anything).
"""

import dataclasses

import numpy as np
import pytest

from engine.render.adaptive import (BUDGET_GROWTH, AdaptiveRounds, AdaptiveSettings, HalfBuffers, TILE, budget_targets,
                                    checkpoints, ladder_of, tile_ids)
from engine.render.driver import drive
from engine.render.film import Film
from engine.render.plan import RenderPlan, RenderRequest
from engine.render.renderer import Renderer
from engine.scene.description import RenderSettings
from tests.render.test_adaptive import small_scene
from tests.render.test_adaptive_cost import CostlyGaussianTracer, per_tile
from tests.support.adaptive import InOrder

MARKS = checkpoints(16, 4096, "nets")


# ------------------------------------------------------------------------------------ the ladder

def test_the_nets_ladder_holds_the_powers_of_two_and_their_halves_between():
    assert checkpoints(16, 600, "nets").tolist() == [16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512, 600]
    assert checkpoints(2, 16, "nets").tolist() == [2, 4, 6, 8, 12, 16]
    assert checkpoints(10, 40, "nets").tolist() == [10, 12, 16, 24, 32, 40]
    long, short = checkpoints(16, 5000, "nets"), checkpoints(16, 300, "nets")
    np.testing.assert_array_equal(long[:len(short) - 1], short[:-1])      # a larger spp extends the sequence
    assert np.all(long % 2 == 0)                                          # both half-buffers stay equal


def test_low_discrepancy_samplers_use_the_nets_ladder():
    assert ladder_of("sobol") == ladder_of("stratified") == "nets" and ladder_of("independent") == "quarter"


# ------------------------------------------------------------------------------------ one round

def test_a_round_gives_counts_proportional_to_sigma_over_root_cost_for_the_grown_cost():
    sigma = np.array([1.0, 2.0, 4.0, 8.0, 0.0])
    counts = np.full(5, 16)
    cost = np.ones(5)
    target, mu = budget_targets(counts, sigma, np.ones(5), cost, MARKS, growth=3.0, jump=1e9)
    assert target[-1] == 16                                         # no noise: no sample
    assert np.all(np.diff(target[:4]) >= 0) and target[3] > target[0]
    wanted = 3.0 * float(np.sum(cost * counts))
    assert float(np.sum(cost * target)) >= wanted                   # at least the grown cost …
    assert mu > 0
    # … and the least: the share at a level a little above μ costs less than that
    lower = np.maximum(16, MARKS[np.searchsorted(MARKS, np.ceil(sigma / (mu * 1.01) - 1e-9))])
    assert float(np.sum(cost * np.where(sigma > 0, lower, 16))) < wanted or np.array_equal(lower, target)
    # n ∝ σ: every count is its share σ/μ taken to the next checkpoint
    share = MARKS[np.searchsorted(MARKS, np.ceil(sigma[:4] / mu - 1e-9))]
    np.testing.assert_array_equal(target[:4], np.maximum(16, share))


def test_a_dear_tile_gets_fewer_samples_by_the_square_root_of_its_cost():
    counts = np.full(2, 16)
    target, mu = budget_targets(counts, np.array([4.0, 4.0]), np.sqrt(np.array([1.0, 4.0]) / 2.5),
                                np.array([1.0, 4.0]), MARKS, growth=8.0, jump=1e9)
    assert target[1] < target[0]
    assert 0.33 <= target[1] / target[0] <= 0.75                    # 1/√4 = 0.5, ± a checkpoint step


def test_a_round_completes_cut_steps_respects_the_jump_and_takes_what_is_left():
    marks = checkpoints(16, 64, "nets")                             # 16, 24, 32, 48, 64
    counts = np.array([20, 16, 16])                                 # the first was cut short in its step
    target, mu = budget_targets(counts, np.array([0.0, 1.0, 100.0]), np.ones(3), np.ones(3), marks, growth=1.01,
                                jump=2.0)
    assert target[0] == 24                                          # completed, though it has no noise
    assert target[2] <= 32                                          # at most 2 × its count
    # everything left costs less than the grown cost: every noisy tile to its cap, μ = 0
    target, mu = budget_targets(np.array([48, 64]), np.array([1.0, 1.0]), np.ones(2), np.ones(2), marks, growth=10.0)
    assert mu == 0.0 and target.tolist() == [64, 64]


# ------------------------------------------------------------------------------------ whole renders

def budget_render(sigma_tiles, cost_tiles, limit, side=8, spp=4096, min_spp=16, quantity="s0"):
    """A budget render of a synthetic image (per-tile σ and cost); the clock is the cost traced so far, so
    ``limit`` is a deterministic budget in units of cost."""
    W = H = side * TILE
    t = tile_ids(W, H)
    tracer = CostlyGaussianTracer(np.asarray(sigma_tiles, np.float64)[t], np.asarray(cost_tiles)[t])
    film, halves = Film(W, H), HalfBuffers(W * H)
    settings = RenderSettings(spp=spp, batch_rays=1 << 16, sampler="sobol")
    plan = RenderPlan(settings, "", (), (), "", W, H, None, 1)
    stats = plan.stats()
    adaptive = AdaptiveSettings(0.0, quantity, min_spp, limit)
    drive(AdaptiveRounds(plan, film, halves, adaptive, 1, stats), film, tracer, InOrder(), stats,
          RenderRequest(clock=lambda: float(halves.cost.sum())))
    return film, halves, stats


def test_a_budget_render_follows_sigma_and_stops_at_the_time_limit():
    side = 8
    sigma = np.where(np.arange(64) % 4 == 0, 4.0, 1.0)
    sigma[:4] = 0.0                                                 # tiles without noise
    film, halves, stats = budget_render(sigma, np.ones(64), limit=64 * 16 * 16 * 6.0)
    n = per_tile(film.count, side)
    assert stats["stop_reason"] == "time_limit"
    assert np.all(n[:4] == 16)                                      # no noise, no more samples
    loud, quiet = n[4:][sigma[4:] == 4.0], n[4:][sigma[4:] == 1.0]
    assert quiet.min() > 16 and 2.5 <= np.median(loud) / np.median(quiet) <= 6.0     # n ∝ σ: 4
    # the time is spent: the last round starts before the limit and adds at most BUDGET_GROWTH − 1 of the cost so far
    spent = float(halves.cost.sum())
    assert 64 * 16 * 16 * 6.0 <= spent <= BUDGET_GROWTH * 64 * 16 * 16 * 6.0 * 1.5


def test_a_dear_tile_of_equal_sigma_gets_half_the_samples_of_a_cheap_one():
    film, _, stats = budget_render(np.ones(64), np.where(np.arange(64) % 2 == 0, 2, 8), limit=1024 * 16 * 5 * 8.0)
    n = per_tile(film.count, 8)
    ratio = np.median(n[1::2]) / np.median(n[::2])
    assert 0.35 <= ratio <= 0.7, (n[::2], n[1::2])                 # 1/√4 = 0.5


def test_budget_renders_are_prefixes_of_one_deterministic_sequence():
    sigma = np.geomspace(0.05, 2.0, 64)
    a, ha, _ = budget_render(sigma, np.ones(64), limit=64 * 16 * 16 * 3.0)
    b, hb, _ = budget_render(sigma, np.ones(64), limit=64 * 16 * 16 * 3.0)
    np.testing.assert_array_equal(a.count, b.count)
    np.testing.assert_array_equal(a.sums, b.sums)
    np.testing.assert_array_equal(ha.sums, hb.sums)
    longer, _, _ = budget_render(sigma, np.ones(64), limit=64 * 16 * 16 * 9.0)
    assert np.all(longer.count >= a.count) and longer.count.sum() > a.count.sum()


def test_without_a_time_limit_every_noisy_tile_reaches_the_maximum():
    sigma = np.where(np.arange(64) < 8, 0.0, 1.0)
    film, _, stats = budget_render(sigma, np.ones(64), limit=0.0, spp=64)
    n = per_tile(film.count, 8)
    assert stats["stop_reason"] == "max_spp" and np.all(n[:8] == 16) and np.all(n[8:] == 64)


def test_dolp_budget_renders_run_on_unpolarised_images_without_noise():
    # DoLP of the grey synthetic image is 0 everywhere: no tile is noisy, the render stops after the first pass
    film, _, stats = budget_render(np.ones(16), np.ones(16), limit=1e12, side=4, quantity="dolp")
    assert stats["stop_reason"] == "threshold" and np.all(film.count == 16)


# ------------------------------------------------------------------------------------ a real scene

@pytest.mark.parametrize("threads", [1, 2])
def test_budget_rounds_of_a_real_scene_do_not_depend_on_the_threads(threads):
    # without a time limit the rounds are a deterministic function of the seed: same counts and bits
    scene = small_scene(res=16, spp=32)
    scene.settings = dataclasses.replace(scene.settings, sampler="sobol")
    renderer = Renderer(scene)
    ad = AdaptiveSettings(0.0, "s0", 8)
    one = renderer.render(RenderRequest(dataclasses.replace(scene.settings, threads=1), adaptive=ad))
    other = renderer.render(RenderRequest(dataclasses.replace(scene.settings, threads=threads, batch_rays=1000),
                                          adaptive=ad))
    assert one.stats["stop_reason"] == "max_spp" and one.stats["adaptive_rounds"] > 2
    np.testing.assert_array_equal(one.film.count, other.film.count)
    np.testing.assert_array_equal(one.film.sums, other.film.sums)
