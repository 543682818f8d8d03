"""The renderer's process resources: the kernel warm-up and the allocator settings for batches."""

import dataclasses
import os
import subprocess
import sys

import numpy as np
import pytest

from engine.render import allocator, integrator
from engine.render.renderer import Renderer
from engine.scene.loader import load_scene
from tests.conftest import REPO, shared_path


def small_scene(name="cornell_lambert", res=24, spp=2):
    scene = load_scene(shared_path("peers", "scenes", f"{name}.json"))
    scene.camera.width, scene.camera.height = res, res * 3 // 4
    scene.settings = dataclasses.replace(scene.settings, spp=spp)
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
    st = dataclasses.replace(scene.settings, threads=2)
    cold = Renderer(scene).render(st).stokes()
    warm = Renderer(scene)
    warm.warm_up(st)
    assert np.array_equal(warm.render(st).stokes(), cold)


#: Child process: warm-up then render each scene; prints the compiled kernels that gained a signature
#: in a render (each loaded or compiled there, holding the GIL, instead of before it)
_WARM_CHILD = """
import dataclasses, sys, numba
from engine.render.renderer import Renderer
from engine.scene.loader import load_scene
from tests.conftest import shared_path
import engine.kernels, pkgutil, importlib
mods = [importlib.import_module('engine.kernels.' + m.name) for m in pkgutil.iter_modules(engine.kernels.__path__)]
import engine.materials.conductor
mods.append(engine.materials.conductor)
kernels = {f'{m.__name__}.{k}': v for m in mods for k, v in vars(m).items()
           if isinstance(v, numba.core.registry.CPUDispatcher)}
for name, sampler in (('fresnel_sphere_au', 'stratified'), ('cornell_lambert', 'independent')):
    scene = load_scene(shared_path('peers', 'scenes', name + '.json'))
    scene.camera.width = scene.camera.height = 32
    st = dataclasses.replace(scene.settings, spp=2, sampler=sampler, threads=1)
    r = Renderer(scene)
    r.warm_up(st)
    before = {k: len(v.signatures) for k, v in kernels.items()}
    r.render(st)
    print(name, sorted(k for k, v in kernels.items() if len(v.signatures) > before[k]))
"""


@pytest.mark.subprocess
def test_the_warm_up_loads_every_kernel_a_render_calls():
    """After ``warm_up`` a render of the same scene and settings loads or compiles no kernel (one
    would hold the GIL inside the render and stall the other workers): a spectral stratified scene and
    a Lambertian one with next-event estimation, in a fresh interpreter."""
    from engine import kernels
    if not kernels.COMPILED:
        pytest.skip("Numba kernels disabled")
    out = subprocess.run([sys.executable, "-c", _WARM_CHILD], capture_output=True, text=True, check=True,
                         cwd=REPO).stdout
    assert out.splitlines() == ["fresnel_sphere_au []", "cornell_lambert []"], out


#: Child process: the settings applied in a fresh interpreter (pytest's may have loaded bpy, and then
#: the allocator is left alone); prints the page faults of re-allocating a freed 200 MiB array.
_FAULTS_CHILD = """
import resource, numpy as np
from engine.render import allocator
if not allocator.keep_freed_memory():
    print("skip"); raise SystemExit
np.core.multiarray._set_madvise_hugepage(False)      # count 4 KiB pages (as without transparent huge pages)
a = np.ones(200 << 17)                               # 200 MiB, above glibc's largest default mmap threshold
del a
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
b = np.ones(200 << 17)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def fault_counts(child: str) -> list[int]:
    """The numbers a child interpreter running ``child`` prints (pytest.skip where it prints "skip")."""
    root = REPO
    out = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, check=True,
                         cwd=root, env={**os.environ, "PYTHONPATH": root}).stdout.split()
    if out[-1] == "skip":
        pytest.skip("not glibc")
    return [int(v) for v in out]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc malloc settings")
def test_freed_batch_sized_arrays_are_not_faulted_in_again():
    assert fault_counts(_FAULTS_CHILD)[-1] < 1000            # default glibc: a fresh mmap, 51 200 page faults


def test_the_allocator_is_left_alone_inside_blender(monkeypatch):
    monkeypatch.setitem(sys.modules, "bpy", object())
    assert allocator._glibc() is None


#: Child process posing as Blender (a ``bpy`` module loaded): the settings hold during render_heap only;
#: prints the page faults of re-allocating a freed 200 MiB array inside it, and after it.
_HOST_FAULTS_CHILD = """
import resource, sys, types
import numpy as np
sys.modules["bpy"] = types.ModuleType("bpy")
from engine.render import allocator
assert not allocator.keep_freed_memory()                # nothing kept for the process inside Blender
if allocator._glibc_library() is None:
    print("skip"); raise SystemExit
np.core.multiarray._set_madvise_hugepage(False)

def refault():
    a = np.ones(200 << 17)
    del a
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    b = np.ones(200 << 17)
    del b
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before

with allocator.render_heap():
    with allocator.render_heap():                       # nested (viewport session + its renders)
        pass
    inside = refault()                                  # still held after the inner one ended
print(inside, refault())
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc malloc settings")
def test_inside_blender_the_heap_settings_hold_for_a_render_only():
    inside, after = fault_counts(_HOST_FAULTS_CHILD)[-2:]
    assert inside < 1000                  # the render's freed arrays are reused
    assert after > 25000                  # given back: 200 MiB is above the restored 32 MiB threshold


def test_renders_hold_the_heap_settings(monkeypatch):
    from engine.render import renderer as renderer_module
    held = []

    class Probe:
        def __enter__(self):
            held.append(True)

        def __exit__(self, *exc):
            held.append(False)

    monkeypatch.setattr(renderer_module, "render_heap", Probe)
    scene = small_scene("plane_brewster", res=4, spp=1)
    Renderer(scene).render(scene.settings)
    assert held == [True, False]
