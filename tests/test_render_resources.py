"""The renderer's process resources: the kernel warm-up and the allocator settings for batches."""

import copy
import resource
import sys

import numpy as np
import pytest

from engine.render import allocator, integrator
from engine.render.renderer import Renderer
from engine.scene.loader import load_scene
from tests.conftest import shared_path


def small_scene(name="cornell_lambert", res=24, spp=2):
    scene = load_scene(shared_path("peers", "scenes", f"{name}.json"))
    scene.camera.width, scene.camera.height = res, res * 3 // 4
    scene.settings.spp = spp
    return scene


def test_warm_up_traces_a_grid_spread_over_the_whole_image(monkeypatch):
    traced = []
    original = integrator.PathTracer.trace

    def trace(self, pixel, sample, abort=None):
        traced.append((pixel.copy(), sample.copy()))
        return original(self, pixel, sample, abort)

    monkeypatch.setattr(integrator.PathTracer, "trace", trace)
    scene = small_scene(res=64)
    seconds = Renderer(scene).warm_up(paths=256)
    assert seconds > 0 and len(traced) == 1
    pixel, sample = traced[0]
    W, H = scene.camera.width, scene.camera.height
    rows, cols = pixel // W, pixel % W
    assert 200 <= pixel.size <= 256 and np.unique(pixel).size == pixel.size
    assert rows.min() == 0 and rows.max() == H - 1 and cols.min() == 0 and cols.max() == W - 1
    assert np.unique(cols).size > W // 8 and np.unique(rows).size > H // 8     # a grid, not a line
    assert (sample == 0).all()


def test_a_render_after_the_warm_up_is_the_same_image():
    scene = small_scene()
    st = copy.copy(scene.settings)
    st.threads = 2
    cold = Renderer(scene).render(st).stokes()
    warm = Renderer(scene)
    warm.warm_up(st)
    assert np.array_equal(warm.render(st).stokes(), cold)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc malloc settings")
def test_freed_batch_sized_arrays_are_not_faulted_in_again():
    if not allocator.keep_freed_memory():
        pytest.skip("not glibc")
    hugepages = np.core.multiarray._get_madvise_hugepage()
    np.core.multiarray._set_madvise_hugepage(False)      # count 4 KiB pages (as without transparent huge pages)
    try:
        a = np.ones(200 << 17)                           # 200 MiB, above glibc's largest default mmap threshold
        del a
        before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        b = np.ones(200 << 17)
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
        del b
    finally:
        np.core.multiarray._set_madvise_hugepage(hugepages)
    assert faults < 1000            # default glibc: a fresh mmap, 51 200 page faults
