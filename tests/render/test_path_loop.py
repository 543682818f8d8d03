"""The compiled per-path bounce loop (engine.render.path_loop, engine.kernels.path_loop) and its twin.

Where the loop covers a scene (smooth mirrors and dielectrics under a constant environment) its images are the
wavefront's bit for bit: the same arithmetic in the same order, the same random numbers.  Each test renders both
transports (RenderSettings.tracer "auto" and the default "wavefront") and compares every Stokes component of every
pixel, the ray counts and the non-finite counts.  Scenes the loop does not cover take the wavefront, and say why.
"""

import copy
import dataclasses
import threading

import numpy as np
import pytest

from engine import kernels
from engine.errors import SceneError
from engine.render.path_loop import LOOP, WAVEFRONT
from engine.render.renderer import Renderer, stats_line
from engine.scene.loader import load_scene, parse_settings
from tests.conftest import shared_path

needs_numba = pytest.mark.skipif(not kernels.COMPILED, reason="the loop runs with the compiled kernels only")

DELTA_SCENES = ["fresnel_sphere", "fresnel_sphere_au", "glass_sphere", "plane_brewster", "conv_s3_check"]


def scene_at(name, width=24, height=20):
    scene = load_scene(shared_path("peers", "scenes", f"{name}.json"))
    if name != "conv_s3_check":
        scene = dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, width=width, height=height))
    return scene


def render_both(scene, spp=3, **overrides):
    """(loop result, wavefront result) of ``scene`` with ``overrides`` of its settings."""
    out = []
    for tracer in ("auto", "wavefront"):
        settings = dataclasses.replace(scene.settings, spp=spp, threads=1, tracer=tracer, **overrides)
        out.append(Renderer(scene).render(settings))
    return out


def assert_same(loop, wave):
    assert loop.stats["tracer"] == LOOP, loop.stats["tracer"]
    assert wave.stats["tracer"] == WAVEFRONT
    a, b = loop.stokes(), wave.stokes()
    assert np.array_equal(a, b), np.abs(a - b).max() / np.abs(b[0]).max()
    assert np.abs(a[0]).max() > 0
    for key in ("rays", "shadow_rays", "nonfinite", "samples"):
        assert loop.stats[key] == wave.stats[key], key


@needs_numba
@pytest.mark.parametrize("name", DELTA_SCENES)
def test_the_loop_renders_the_delta_peer_scenes_bit_for_bit_as_the_wavefront(name):
    assert_same(*render_both(scene_at(name)))


@needs_numba
@pytest.mark.parametrize("name,overrides", [
    ("glass_sphere", {"sampler": "independent"}),
    ("glass_sphere", {"sampler": "stratified"}),
    ("glass_sphere", {"rr_depth": 1, "max_depth": 24}),             # roulette from the first vertex on
    ("glass_sphere", {"max_depth": 3}),
    ("glass_sphere", {"polarisation": "off", "spectral": "mono"}),
    ("glass_sphere", {"polarisation": "linear", "spectral": "rgb"}),
    ("glass_sphere", {"reduce_spectral": "exact"}),                  # 4 wavelengths, one Mueller product
    ("glass_sphere", {"reduce_spectral": "off", "rr_depth": 2}),     # 4 wavelengths, one product each
    ("glass_sphere", {"denoise_data": True}),
    ("fresnel_sphere_au", {"sampler": "stratified", "rr_depth": 1}),
    ("fresnel_sphere_au", {"spectral": "rgb"}),
    ("fresnel_sphere", {"polarisation": "full", "seed": 7}),
    ("fresnel_sphere", {"max_depth": 2}),                            # one vertex, then the sky
])
def test_the_loop_equals_the_wavefront_across_samplers_transports_and_depths(name, overrides):
    assert_same(*render_both(scene_at(name), **overrides))


@needs_numba
def test_batches_and_threads_do_not_change_the_loops_image():
    scene = scene_at("glass_sphere", 40, 30)
    loop = Renderer(scene).render(dataclasses.replace(scene.settings, spp=4, threads=2, batch_rays=1024, tracer="auto"))
    wave = Renderer(scene).render(dataclasses.replace(scene.settings, spp=4, threads=1, tracer="wavefront"))
    assert_same(loop, wave)


@needs_numba
def test_a_dielectric_in_cycles_convention_keeps_the_refractions_radiance_scale():
    """BSDF.radiance_scaling False (Blender's materials): the loop takes the 1/η² back as the wavefront does."""
    scene = scene_at("glass_sphere")
    materials = {}
    for key, m in scene.materials.items():
        m = copy.copy(m)
        if type(m).__name__ == "SmoothDielectric":
            m.radiance_scaling = False
        materials[key] = m
    loop, wave = render_both(dataclasses.replace(scene, materials=materials), rr_depth=2)
    assert_same(loop, wave)
    plain = render_both(scene, rr_depth=2)[1].stokes()
    assert not np.array_equal(loop.stokes(), plain)            # the convention changes the image


@needs_numba
def test_path_costs_and_batch_values_are_the_wavefronts():
    """What adaptive sampling reads (each path's cost) and the batch's values, straight from PathTracer.trace."""
    scene = scene_at("glass_sphere", 16, 16)
    renderer = Renderer(scene)
    pixel = np.repeat(np.arange(256, dtype=np.int64), 3)
    sample = np.tile(np.arange(3, dtype=np.int64), 256)
    out = []
    for tracer in ("auto", "wavefront"):
        plan = renderer.plan(dataclasses.replace(scene.settings, tracer=tracer))
        t = renderer.tracer(plan, count_cost=True)
        assert (t.path_loop is not None) == (tracer == "auto")
        out.append(t.trace(pixel, sample))
    (a, sa), (b, sb) = out
    assert np.array_equal(a, b)
    assert np.array_equal(sa["path_cost"], sb["path_cost"]) and sa["path_cost"].max() > 1
    assert sa["rays"] == sb["rays"] and sa["nonfinite"] == sb["nonfinite"]


@needs_numba
def test_a_batch_whose_wavelengths_leave_a_measured_metals_tables_takes_the_wavefront(monkeypatch):
    """The wavefront's mirror step falls back to the material's ``sample`` outside the tables: such a batch is
    traced by the wavefront whole, the others by the loop (here: every batch, the range made narrow)."""
    from engine.render import path_loop
    calls = []
    original = path_loop.DeltaScene.covers_wavelengths

    def narrow(self, lam):
        self.table_range = (500.0, 600.0)
        calls.append(original(self, lam))
        return calls[-1]
    monkeypatch.setattr(path_loop.DeltaScene, "covers_wavelengths", narrow)
    loop, wave = render_both(scene_at("fresnel_sphere_au"))
    assert calls and not any(calls)
    assert np.array_equal(loop.stokes(), wave.stokes())


@needs_numba
def test_abort_is_honoured_between_batches():
    scene = scene_at("fresnel_sphere", 8, 8)
    renderer = Renderer(scene)
    tracer = renderer.tracer(renderer.plan(dataclasses.replace(scene.settings, tracer="auto")))
    assert tracer.path_loop is not None
    abort = threading.Event()
    abort.set()
    pixel = np.arange(64, dtype=np.int64)
    assert tracer.trace(pixel, np.zeros_like(pixel), abort) is None
    assert tracer.trace(pixel, np.zeros_like(pixel), threading.Event()) is not None


@pytest.mark.parametrize("name,overrides,reason", [
    ("rough_sphere_a030", {}, "materials other than smooth conductors and dielectrics"),
    ("cornell_lambert", {}, "lights other than a constant environment"),
    ("glass_sphere", {"sampler": "padded"}, "sampler 'padded'"),
    ("glass_sphere", {"clamp_direct": 1.0}, "light-path rules"),
])
def test_scenes_the_loop_does_not_cover_take_the_wavefront_and_say_why(name, overrides, reason):
    scene = scene_at(name, 8, 8)
    result = Renderer(scene).render(dataclasses.replace(scene.settings, spp=1, threads=1, tracer="auto", **overrides))
    if not kernels.COMPILED:
        reason = "no compiled kernels"
    assert result.stats["tracer"] == f"{WAVEFRONT} ({reason})"
    assert f"tracer: {WAVEFRONT} ({reason})" in stats_line(result.stats)


def test_the_wavefront_is_the_default_and_is_named_without_a_reason():
    scene = scene_at("glass_sphere", 8, 8)
    result = Renderer(scene).render(dataclasses.replace(scene.settings, spp=1, threads=1))
    assert result.settings.tracer == "wavefront" and result.stats["tracer"] == WAVEFRONT


def test_participating_media_take_the_wavefront():
    from engine.render.participating import ParticipatingPathTracer
    scene = scene_at("glass_sphere", 8, 8)
    renderer = Renderer(scene)
    plan = renderer.plan(dataclasses.replace(scene.settings, tracer="auto"))
    tracer = ParticipatingPathTracer(renderer.compiled, renderer.lights, renderer.camera, plan.settings,
                                     materials=list(plan.materials))
    assert tracer.path_loop is None
    assert tracer.tracer_reason in ("participating media", "no compiled kernels")


def test_the_tracer_setting_is_validated():
    assert parse_settings({"tracer": "auto"}).tracer == "auto"
    assert parse_settings({}).tracer == "wavefront"
    with pytest.raises(SceneError, match="render.tracer"):
        parse_settings({"tracer": "loop"})
