"""The work split: a small image gives every worker a unit, and the image does not depend on it.

engine.render.plan.work_units groups the passes by ``batch_rays`` alone (the grouping fixes the
bits of each pixel's sums) and cuts the rows into at least ``workers`` bands (which changes no
pixel's additions)."""

import dataclasses

import numpy as np
import pytest

from engine.render import driver as driver_module
from engine.render.plan import work_units
from engine.render.renderer import Renderer
from tests.render.test_render_acceptance import peer_scene


def _coverage(units, width, window, spp, first_pass=0):
    """How often each (row, pass) of the window is covered by ``units`` (rows, passes) int array."""
    x0, y0, x1, y1 = window or (0, 0, width, None)
    seen = np.zeros((y1 - y0, spp), np.int64)
    for r0, r1, p0, p1 in units:
        assert y0 <= r0 < r1 <= y1 and first_pass <= p0 < p1 <= spp
        seen[r0 - y0:r1 - y0, p0:p1] += 1
    return seen


@pytest.mark.parametrize("W,H,spp,batch,window,first_pass", [
    (96, 96, 16, 1 << 17, None, 0),           # the asset suite's render: two half-height bands of 16 passes
    (96, 96, 16, 73728, None, 0),
    (32, 32, 2, 1024, None, 0),
    (33, 7, 5, 1 << 17, None, 0),             # rows not divisible by the workers
    (40, 1, 3, 1 << 17, None, 0),             # one row: nothing to cut
    (640, 480, 4, 1 << 17, None, 0),          # a large image: already many bands
    (64, 64, 16, 64 * 64, None, 0),           # one pass per unit: enough units, whole passes kept
    (96, 96, 16, 1 << 17, (10, 20, 50, 61), 0),
    (96, 96, 16, 1 << 17, None, 5),           # a resumed render
])
@pytest.mark.parametrize("workers", [1, 2, 3, 8])
def test_units_cover_every_row_and_pass_once_and_keep_the_pass_grouping(W, H, spp, batch, window, first_pass,
                                                                        workers):
    units = list(work_units(W, H, spp, batch, first_pass=first_pass, window=window, workers=workers))
    y0, y1 = (window[1], window[3]) if window else (0, H)
    cols = (window[2] - window[0]) if window else W
    seen = _coverage(units, W, (0, y0, W, y1), spp, first_pass)
    assert np.all(seen[:, first_pass:] == 1) and np.all(seen[:, :first_pass] == 0)
    assert all((r1 - r0) * cols * (p1 - p0) <= max(batch, cols) for r0, r1, p0, p1 in units)
    # the pass groups (what fixes each pixel's sums) are those of a single worker's split
    single = list(work_units(W, H, spp, batch, first_pass=first_pass, window=window))
    assert sorted({(p0, p1) for *_, p0, p1 in units}) == sorted({(p0, p1) for *_, p0, p1 in single})
    groups = len({(p0, p1) for *_, p0, p1 in single})
    if len(single) < 4 * workers:       # too few units for the workers: every worker gets a band of each group
        assert len(units) >= min(workers, y1 - y0) * groups
    else:                               # enough: the single worker's split
        assert units == single


def test_a_small_image_gives_each_of_two_workers_one_batch_of_every_pass():
    # 96 × 96 at 16 spp needs two batches of 2**17 paths: grouped for half-height bands, all 16 passes in one group,
    # one unit per worker (before: 14 + 2 passes, two batches per worker, the second of 9,216 paths paying a whole
    # batch's per-bounce calls)
    for workers in (1, 2):
        assert list(work_units(96, 96, 16, 1 << 17, workers=workers)) == [(0, 48, 0, 16), (48, 96, 0, 16)]
    # an image that fits one batch stays one unit for one worker
    assert list(work_units(24, 24, 6, 1 << 17)) == [(0, 24, 0, 6)]


@pytest.mark.parametrize("W,H,spp,batch", [(96, 96, 128, 1 << 17), (64, 64, 16, 4096), (640, 480, 7, 1 << 17),
                                           (1920, 1080, 16, 1 << 17), (33, 7, 50, 256)])
def test_pass_groups_and_bands_are_balanced(W, H, spp, batch):
    units = list(work_units(W, H, spp, batch))
    sizes = {p1 - p0 for *_, p0, p1 in units}
    heights = {r1 - r0 for r0, r1, *_ in units}
    assert max(sizes) - min(sizes) <= 1 and max(heights) - min(heights) <= 1, (sizes, heights)
    assert all((r1 - r0) * W * (p1 - p0) <= batch for r0, r1, p0, p1 in units)


def test_two_threads_trace_at_least_two_units_and_give_the_same_bits(monkeypatch):
    scene = peer_scene("fresnel_sphere", 6, res=24)
    # every pass fits one batch: one unit per worker count before
    scene.settings = dataclasses.replace(scene.settings, batch_rays=1 << 17)
    renderer = Renderer(scene)
    traced = []
    real = driver_module.trace_in_order

    def spy(units, trace_unit, add_result, workers, stop_requested, abort):
        traced.append((workers, list(units)))
        return real(units, trace_unit, add_result, workers, stop_requested, abort)

    monkeypatch.setattr(driver_module, "trace_in_order", spy)
    results = {}
    for threads in (1, 2):
        results[threads] = renderer.render(dataclasses.replace(scene.settings, threads=threads))
    (w1, u1), (w2, u2) = traced
    assert (w1, len(u1)) == (1, 1) and w2 == 2 and len(u2) >= 2
    a, b = results[1].film, results[2].film
    assert np.all(a.count == 6) and np.array_equal(a.count, b.count)
    for name in ("sums", "sumsq_y", "half_y"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None)
        if x is not None:
            assert np.array_equal(x, y), name
