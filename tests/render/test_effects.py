"""Automatic effect selection: the reduced transports are exact where Auto picks them."""

import dataclasses

import numpy as np
import pytest

from engine.render.renderer import Renderer
from engine.scene.loader import load_scene
from tests.conftest import shared_path


def peer(name, res, spp=2):
    scene = load_scene(shared_path("peers", "scenes", f"{name}.json"))
    scene.camera.width = scene.camera.height = res
    # the statistics below assume independent samples
    scene.settings = dataclasses.replace(scene.settings, spp=spp, sampler="independent")
    return scene


@pytest.mark.parametrize("name,mode", [("cornell_lambert", "off"), ("plane_brewster", "linear"),
                                       ("fresnel_sphere", "full"), ("glass_sphere", "full"),
                                       ("conv_s3_check", "full")])
def test_auto_picks_the_cheapest_exact_transport(name, mode):
    result = Renderer(peer(name, 8, 1)).render()
    assert result.stats["transport"] == mode
    assert result.stats["transport_reason"].startswith("auto")


@pytest.mark.parametrize("name,reduced", [("plane_brewster", "linear"), ("cornell_lambert", "off")])
def test_reduced_transport_equals_full_transport(name, reduced):
    scene = peer(name, 24)
    renderer = Renderer(scene)
    settings = dataclasses.replace(scene.settings, polarisation="full")
    full = renderer.render(settings).stokes()
    settings = dataclasses.replace(settings, polarisation=reduced)
    fast = renderer.render(settings).stokes()
    np.testing.assert_allclose(fast, full, rtol=1e-12, atol=1e-15)
    assert np.all(full[3] == 0)


def test_linear_transport_would_be_wrong_where_auto_keeps_full():
    # Counter-example: the conductor creates circular polarisation; dropping S3 changes the image.
    scene = peer("conv_s3_check", 8, 16)
    renderer = Renderer(scene)
    settings = dataclasses.replace(scene.settings, polarisation="full")
    full = renderer.render(settings).stokes()
    assert np.abs(full[3]).max() > 0.01
    settings = dataclasses.replace(settings, polarisation="linear")
    assert np.all(renderer.render(settings).stokes()[3] == 0)


@pytest.mark.parametrize("name", ["fresnel_sphere", "glass_sphere", "plane_brewster"])
def test_one_mueller_product_per_path_is_exact_where_nothing_depends_on_wavelength(name):
    scene = peer(name, 16)
    renderer = Renderer(scene)
    settings = dataclasses.replace(scene.settings, polarisation="full", reduce_spectral="exact")
    reduced = renderer.render(settings)
    settings = dataclasses.replace(settings, reduce_spectral="off")
    per_wavelength = renderer.render(settings)
    assert "one Mueller product" in reduced.stats["spectral"]
    np.testing.assert_allclose(reduced.stokes(), per_wavelength.stokes(), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", ["fresnel_sphere", "plane_brewster"])
def test_rgb_light_integration_has_the_same_expectation_and_less_noise(name):
    # "auto" replaces the sampled wavelengths by each light's exactly integrated colour: a different
    # estimator with the same expectation (block z-test) and no chromatic noise (smaller errors).
    scene = peer(name, 32, spp=16)
    renderer = Renderer(scene)
    settings = scene.settings
    auto = renderer.render(settings)
    settings = dataclasses.replace(settings, reduce_spectral="off")
    spectral = renderer.render(settings)
    assert auto.stats["spectral"].startswith("RGB")
    a, b = auto.stokes_luminance(), spectral.stokes_luminance()
    sa, sb = auto.film.stderr_luminance(), spectral.film.stderr_luminance()
    for comp in range(3):
        d = (a[comp] - b[comp]).reshape(8, 4, 8, 4).mean(axis=(1, 3))
        var = (sa[comp] ** 2 + sb[comp] ** 2).reshape(8, 4, 8, 4).sum(axis=(1, 3)) / 16 ** 2
        z = d / np.sqrt(np.maximum(var, 1e-30))
        assert np.mean(np.abs(z) < 4) >= 0.95, comp
    assert sa[0].mean() < sb[0].mean()


@pytest.mark.parametrize("name", ["fresnel_sphere_au", "cornell_lambert"])
def test_measured_metals_and_coloured_albedos_keep_per_wavelength_transport(name):
    result = Renderer(peer(name, 8, 1)).render()
    assert result.stats["spectral"].startswith("spectral (") and "on λ)" in result.stats["spectral"]


# ----------------------------------------------------------------------------- skipped clear layers

def coated_ball_scene(coat, base=None, spp=64, res=32):
    """The thesis WW set-up (sphere on black glass under a white sky) with the given coat."""
    import json
    with open("examples/thesis_ww_coat_red.json") as fh:
        d = json.load(fh)
    d["materials"]["ball"]["coats"] = [coat]
    if base is not None:
        d["materials"]["ball"]["base"] = base
    d["camera"]["width"] = d["camera"]["height"] = res
    d["render"]["spp"] = spp
    from engine.scene.loader import parse_scene
    return parse_scene(d, "examples")


def test_index_matched_clear_coat_is_skipped_reported_and_unbiased():
    """A coat with n = exterior index and no absorption is skipped (a rough one too); the scene then
    needs no polarisation at the ball (the floor still polarises).  The render equals the render with
    every layer kept (simplify="off") within Monte Carlo noise: the samplers differ, the BSDF does not."""
    from tests.render.test_render_acceptance import block_z
    scene = coated_ball_scene({"n": 1.0, "distribution": "beckmann", "m": 0.3})
    renderer = Renderer(scene)
    settings = dataclasses.replace(scene.settings, threads=1)
    auto = renderer.render(settings)
    assert any("index-matched" in why and "'ball'" in why for why in auto.stats["simplified"])
    settings = dataclasses.replace(settings, simplify="off")
    kept = renderer.render(settings)
    assert kept.stats["simplified"] == []
    assert not np.array_equal(auto.stokes(), kept.stokes())      # really different samplers
    Ya, Yk = auto.stokes_luminance(), kept.stokes_luminance()
    sa, sk = auto.film.stderr_luminance(), kept.film.stderr_luminance()
    for comp in range(3):
        with np.errstate(invalid="ignore", divide="ignore"):   # the sky is exact: 0/0 blocks
            z = block_z(Ya[comp] - Yk[comp], np.sqrt(sa[comp] ** 2 + sk[comp] ** 2), 0.0, block=4)
        z = z[np.isfinite(z)]
        assert np.mean(np.abs(z) < 4) >= 0.98, f"S{comp}: {np.mean(np.abs(z) < 4):.3f} of blocks within 4σ"


def test_index_matched_clear_coat_over_lambert_makes_the_scene_scalar():
    """Only the ball, lit by the sky: with its clear matched coat skipped it is Lambertian, so Auto
    picks scalar transport — and the full-transport render of the unsimplified scene has S1..S3 = 0
    up to rounding and the same S0 within noise."""
    scene = coated_ball_scene({"n": 1.0}, spp=32)
    scene.meshes = [m for m in scene.meshes if m.name == "sphere"]
    renderer = Renderer(scene)
    auto = renderer.render()
    assert auto.stats["transport"] == "off"
    assert "simplified" in auto.stats and auto.stats["simplified"]
    settings = dataclasses.replace(scene.settings, simplify="off")
    kept = renderer.render(settings)
    assert kept.stats["transport"] != "off"
    Y = kept.stokes_luminance()
    assert np.abs(Y[1:]).max() <= 1e-9 * Y[0].max()


@pytest.mark.parametrize("coat", [{"n": 1.0 + 1e-6}, {"n": 1.0, "thickness": 1.0, "absorption": 0.1},
                                  {"n": 1.5}])
def test_coats_that_do_something_are_kept(coat):
    scene = coated_ball_scene(coat, spp=1, res=8)
    result = Renderer(scene).render()
    assert result.stats["simplified"] == []
