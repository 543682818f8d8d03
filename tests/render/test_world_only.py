"""A scene without geometry renders as Cycles renders it: the world (an HDRI or sky preview) along every
camera ray, lamps the camera sees, black where neither is; lights have nothing to light.

Oracles: the peer environment map's reference lookup (shared/peers/envmaps/make_envmap.py) along the render's own
camera rays (the same per-path random numbers), and the same scene with geometry that no camera ray meets
(bit-for-bit: without geometry every ray is a miss, as Embree's misses are).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from engine.cli import main
from engine.output.exr import read_stokes_exr
from engine.render.renderer import Renderer
from engine.render.sampler import PathSampler, path_keys
from engine.scene.loader import load_scene, parse_scene
from tests.render.test_envmap import ME, SKY

CAMERA = {"origin": [0, 0, 0], "target": [1, 0.3, 0.4], "up": [0, 0, 1], "fov_deg": 120, "width": 16, "height": 12}
#: a grey quad far behind the camera: geometry no camera ray meets
BEHIND = {"shape": "quad", "material": "grey", "vertices": [[-50, -1, -1], [-50, 1, -1], [-50, 1, 1], [-50, -1, 1]]}


def _scene(tmp_path, lights, objects=(), spp=4, **render):
    data = {"format": "polar-scene/1", "camera": CAMERA,
            "materials": {"grey": {"type": "lambert", "albedo": 0.5}}, "objects": list(objects), "lights": lights,
            "render": {"spp": spp, "max_depth": 8, "sampler": "independent", **render}}
    ME.write_exr(str(tmp_path / "sky.exr"), SKY.astype(np.float32))
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(data))
    return path


SKY_LIGHT = {"type": "environment", "image": "sky.exr", "grid": "mitsuba"}


@pytest.mark.parametrize("spectral", ["spectral", "mono"])
def test_world_only_scene_sees_the_map_along_its_camera_rays(tmp_path, spectral):
    scene = load_scene(str(_scene(tmp_path, [SKY_LIGHT], spectral=spectral)))
    assert scene.meshes == []
    out = Renderer(scene).render(scene.settings)
    W, H, spp = CAMERA["width"], CAMERA["height"], scene.settings.spp
    camera = Renderer(scene).camera
    # the reference lookup along each sample's camera ray (the same random numbers), averaged per pixel
    pixel = np.repeat(np.arange(W * H), spp)
    sample = np.tile(np.arange(spp), W * H)
    _, d, *_ = camera.generate(pixel, PathSampler(path_keys(scene.settings.seed, pixel, sample)).next(2))
    ref = ME.lookup(SKY, d.T).reshape(H, W, spp, 3).mean(2)
    stokes = out.stokes()
    if spectral == "mono":
        from engine.spectral import luminance
        np.testing.assert_allclose(stokes[0, ..., 0], luminance(ref), rtol=1e-6)
    else:
        np.testing.assert_allclose(stokes[0], ref, rtol=1e-6)      # RGB with exact light spectra: the texels
    assert np.all(stokes[1:] == 0)
    assert out.stats["shadow_rays"] == 0 and out.stats["rays"] == W * H * spp      # one ray a path: all miss


@pytest.mark.parametrize("sampler", ["independent", "sobol"])
def test_no_geometry_equals_geometry_no_camera_ray_meets(tmp_path, sampler):
    bare = load_scene(str(_scene(tmp_path, [SKY_LIGHT], sampler=sampler)))
    behind = load_scene(str(_scene(tmp_path, [SKY_LIGHT], [BEHIND], sampler=sampler)))
    a, b = (Renderer(s).render(dataclasses.replace(s.settings, denoise_data=True)) for s in (bare, behind))
    np.testing.assert_array_equal(a.stokes(), b.stokes())
    for x, y in zip(a.film.denoise_data(), b.film.denoise_data()):
        np.testing.assert_array_equal(x, y)                      # guides 0: the sky only


def test_constant_world_gives_its_radiance_in_every_pixel(tmp_path):
    scene = load_scene(str(_scene(tmp_path, [{"type": "environment", "radiance": 2.0, "color": [0.1, 0.25, 0.45]}],
                                  polarisation="full")))
    stokes = Renderer(scene).render(scene.settings).stokes()
    np.testing.assert_array_equal(stokes[0], np.broadcast_to(stokes[0, 0, 0], stokes[0].shape))
    np.testing.assert_allclose(stokes[0, 0, 0], [0.2, 0.5, 0.9], rtol=3e-4)   # the colour round trip
    assert np.all(stokes[1:] == 0)


def test_nothing_at_all_renders_black_and_opaque(tmp_path):
    """As Cycles: a scene without objects and with a black world is a black image (alpha 1: Film ▸
    Transparent off), not an error; through the command line too."""
    path = _scene(tmp_path, [])
    assert main(["render", str(path), "-o", str(tmp_path / "black.exr"), "-q", "--no-previews"]) == 0
    stokes, channels, _ = read_stokes_exr(tmp_path / "black.exr")
    assert np.all(stokes == 0)
    if "A" in channels:
        assert np.all(channels["A"] == 1)


def test_lights_without_geometry_light_nothing_and_lamps_are_seen(tmp_path):
    # a point light and a sun (delta lights) with nothing to light: black
    point = [{"type": "point", "position": [2, 0, 1], "intensity": 50},
             {"type": "directional", "direction": [0, 0, -1], "irradiance": 3}]
    scene = load_scene(str(_scene(tmp_path, point)))
    assert np.all(Renderer(scene).render(scene.settings).stokes() == 0)
    # a non-occluding lamp (Cycles' area light) in front of the camera, over a dim world: the lamp is seen
    lamp = {"shape": "quad", "material": "grey", "vertices": [[3, -0.6, -0.4], [3, -0.6, 0.8], [3, 0.6, 0.8],
                                                                [3, 0.6, -0.4]],
            "emission": {"radiance": 4.0, "occluder": False, "two_sided": True}}
    scene = load_scene(str(_scene(tmp_path, [{"type": "environment", "radiance": 0.1}], [lamp])))
    s0 = Renderer(scene).render(scene.settings).stokes()[0].mean(-1)
    # covered pixels: the lamp and the world behind it (rays pass through lamps); elsewhere the world
    assert s0.max() == pytest.approx(4.1, rel=1e-3) and s0.min() == pytest.approx(0.1, rel=1e-3)
    assert (s0 > 4.0).sum() >= 2 and (s0 > 1.0).sum() > 4


def test_polarised_sky_is_seen_with_its_polarisation(tmp_path):
    """The clear sky 90° from the sun, seen directly, is polarised (no surface in the scene)."""
    scene = parse_scene({"format": "polar-scene/1",
                         "camera": {"origin": [0, 0, 0], "target": [0, 1, 1], "up": [0, 0, 1], "fov_deg": 30,
                                    "width": 8, "height": 6},
                         "render": {"spp": 2, "sampler": "independent"}, "materials": {}, "objects": [],
                         "lights": [{"type": "sky", "sun_direction": [1, 0, 0.1], "polarisation": {"model": "berry"}}]},
                        str(tmp_path))
    stokes = Renderer(scene).render(scene.settings).stokes()
    y = stokes.mean(-1)
    dolp = np.hypot(y[1], y[2]) / y[0]
    assert np.all(y[0] > 0) and dolp.min() > 0.3
