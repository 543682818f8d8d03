"""The polarised sky as an environment (issue 35): the emitter's Stokes vectors equal the closed forms
(engine.spectral.daylight, itself checked against the papers' formulas in test_sky_model.py) to 1e-9
in any frame; a rendered panorama's DoLP and AoLP follow the Rayleigh closed form within noise; a camera
polariser at 90° from the sun darkens the sky by (1 − P)/(1 + P); the sky's S0 does not depend on its
polarisation; the scene format validates it.  Expected values are written here from the formulas."""

import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.postprocess.filters import malus
from engine.render.camera import CameraModel
from engine.render.lights.selection import LightSet
from engine.render.renderer import render
from engine.scene.loader import parse_scene

LUMA = np.array([0.2126, 0.7152, 0.0722])


def _sky_scene(elevation_deg=30.0, polarisation=None, width=48, height=24, spp=4, camera=None, turbidity=3.0):
    e = math.radians(elevation_deg)
    sky = {"type": "sky", "sun_direction": [math.cos(e), 0.0, math.sin(e)], "turbidity": turbidity}
    if polarisation is not None:
        sky["polarisation"] = polarisation
    cam = camera or {"projection": "equirectangular", "origin": [0, 0, 0], "target": [1, 0, 0], "up": [0, 0, 1]}
    return parse_scene({"format": "polar-scene/1", "camera": {"width": width, "height": height, **cam},
                        "render": {"spp": spp, "max_depth": 2, "seed": 1},
                        "materials": {"black": {"type": "lambert", "albedo": 0.0}},
                        "objects": [{"name": "speck", "shape": "sphere", "center": [0, 0, -1e3], "radius": 1e-3,
                                     "material": "black"}],
                        "lights": [sky]})


def _rayleigh(d, sun, delta):
    """(P, e) of single Rayleigh scattering for sky directions d (3, n): the closed form."""
    cos_g = np.clip(sun @ d, -1, 1)
    P = (1 - delta) * (1 - cos_g ** 2) / (1 + delta + (1 - delta) * cos_g ** 2)
    e = np.cross(sun, d.T).T
    return P, e / np.maximum(np.linalg.norm(e, axis=0), 1e-300)


@pytest.mark.parametrize("elevation", [5.0, 30.0, 60.0, 89.0])
def test_the_emitters_stokes_vectors_are_the_closed_form_in_any_frame(elevation):
    scene = _sky_scene(elevation, {"model": "rayleigh", "delta": 0.031})
    lights = LightSet(scene, _compiled(scene))
    env = lights.environment
    rng = np.random.default_rng(7)
    d = rng.normal(size=(3, 500))
    d /= np.linalg.norm(d, axis=0)
    d[2] = np.abs(d[2]) + 1e-3
    d /= np.linalg.norm(d, axis=0)
    k = -d
    s, x_e = env.emitted_polarisation(k)
    # an arbitrary frame per direction: x_ref ⟂ d
    a = rng.normal(size=(3, 500))
    x_ref = a - (a * d).sum(0) * d
    x_ref /= np.linalg.norm(x_ref, axis=0)
    y_ref = np.cross(k.T, x_ref.T).T
    c, sn = (x_e * x_ref).sum(0), (np.cross(k.T, x_e.T).T * x_ref).sum(0)
    s1 = (c * c - sn * sn) * s[1] + 2 * c * sn * s[2]
    s2 = -2 * c * sn * s[1] + (c * c - sn * sn) * s[2]
    sun = np.array([math.cos(math.radians(elevation)), 0.0, math.sin(math.radians(elevation))])
    P, e = _rayleigh(d, sun, 0.031)
    psi = np.arctan2((e * y_ref).sum(0), (e * x_ref).sum(0))
    np.testing.assert_allclose(s1, P * np.cos(2 * psi), atol=1e-9)
    np.testing.assert_allclose(s2, P * np.sin(2 * psi), atol=1e-9)
    np.testing.assert_array_equal(s[3], 0.0)


def _compiled(scene):
    from engine.render.accel import CompiledScene
    return CompiledScene(scene)


def _luma(result):
    return np.einsum("shwc,c->shw", result.stokes(), LUMA)


def _pixel_rays(scene):
    cam = CameraModel(scene.camera)
    W, H = scene.camera.width, scene.camera.height
    pixel = np.arange(W * H)
    _, d, x, _, _ = cam.generate(pixel, np.full((2, pixel.size), 0.5))
    return d, x


def test_a_rendered_panorama_of_the_rayleigh_sky_has_its_dolp_and_aolp():
    delta = 0.031
    scene = _sky_scene(30.0, {"model": "rayleigh", "delta": delta}, width=96, height=48, spp=16)
    r = render(scene)
    assert r.stats["transport"] == "linear"
    S = _luma(r).reshape(4, -1)
    d, x = _pixel_rays(scene)
    sun = np.array([math.cos(math.radians(30)), 0.0, math.sin(math.radians(30))])
    P, e = _rayleigh(d, sun, delta)
    k = -d
    y = np.cross(k.T, x.T).T
    psi = np.arctan2((e * y).sum(0), (e * x).sum(0))
    lat = np.degrees(np.arcsin(np.clip(d[2], -1, 1)))
    gamma = np.degrees(np.arccos(np.clip(sun @ d, -1, 1)))
    use = (lat > 5) & (lat < 75) & (gamma > 20) & (gamma < 160)
    assert use.sum() > 1000
    got1, got2 = S[1, use] / S[0, use], S[2, use] / S[0, use]
    np.testing.assert_allclose(got1, (P * np.cos(2 * psi))[use], atol=0.03)
    np.testing.assert_allclose(got2, (P * np.sin(2 * psi))[use], atol=0.03)
    # below the horizon: the ground-reflected hemisphere is unpolarised
    below = lat < -2
    assert np.abs(S[1:3, below]).max() <= 1e-12 * max(S[0, below].max(), 1.0)


@pytest.mark.parametrize("model", ["rayleigh", "berry"])
def test_a_camera_polariser_darkens_the_sky_at_90_degrees_from_the_sun(model):
    """Looking horizontally 90° in azimuth from a sun on the horizon (γ = 90°): the polariser across the sky's
    E-field transmits (1 − P)/2 of S0, along it (1 + P)/2 — the predicted darkening (1 − P)/(1 + P)."""
    pol = {"model": model, "delta": 0.031} if model == "rayleigh" else {"model": "berry", "max_degree": 0.7}
    cam = {"projection": "perspective", "origin": [0, 0, 0], "target": [0, 1, 0.2], "up": [0, 0, 1], "fov_deg": 2}
    scene = _sky_scene(0.0, pol, width=4, height=4, spp=16, camera=cam)
    S = _luma(render(scene))
    d = np.array([0.0, 1.0, 0.2]) / math.hypot(1.0, 0.2)
    sun = np.array([1.0, 0.0, 0.0])
    if model == "rayleigh":
        P = float(_rayleigh(d[:, None], sun, 0.031)[0][0])
    else:
        from engine.spectral.daylight import ClearSky
        P = float(ClearSky(sun_direction=(1.0, 0.0, 0.0), max_degree=0.7).polarisation(d[None, :])[0][0])
    best = [malus(S, a).mean() for a in np.arange(0.0, 180.0, 1.0)]
    s0 = S[0].mean()
    assert min(best) / s0 == pytest.approx((1 - P) / 2, abs=0.01)
    assert max(best) / s0 == pytest.approx((1 + P) / 2, abs=0.01)
    # the E-field of the sky there is vertical (⟂ the horizontal scattering plane): the dark angle is 0°
    # (image right), the bright one 90°
    assert int(np.argmin(best)) in (0, 1, 179) and abs(int(np.argmax(best)) - 90) <= 1


def test_the_skys_radiance_does_not_depend_on_its_polarisation():
    a = render(_sky_scene(20.0, {"model": "berry"}))
    b = render(_sky_scene(20.0, "none"))
    assert b.stats["transport"] == "off" and a.stats["transport"] == "linear"
    np.testing.assert_allclose(_luma(a)[0], _luma(b)[0], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("sky, field, words", [
    ({"sun_direction": [1, 0, -0.5]}, "lights[0].sun_direction", "above the horizon"),
    ({"sun_direction": [0, 0, 1], "turbidity": 30}, "lights[0].turbidity", "[1.7, 10]"),
    ({"sun_direction": [0, 0, 1], "polarisation": {"model": "mie"}}, "lights[0].polarisation.model", "berry"),
    ({"sun_direction": [0, 0, 1], "polarisation": {"delta": 0.9}}, "lights[0].polarisation.delta", "0.5"),
    ({"sun_direction": [0, 0, 1], "polarisation": {"colour": 1}}, "lights[0].polarisation.colour", ""),
    ({"sun_direction": [0, 0, 1], "polarisation": 3}, "lights[0].polarisation", "none"),
])
def test_bad_sky_settings_name_the_field(sky, field, words):
    with pytest.raises(SceneError) as e:
        parse_scene({"format": "polar-scene/1", "camera": {"origin": [0, 0, 0], "target": [1, 0, 0], "up": [0, 0, 1],
                                                            "width": 4, "height": 4},
                     "materials": {"m": {"type": "lambert", "albedo": 0.5}},
                     "objects": [{"shape": "sphere", "center": [5, 0, 0], "radius": 1, "material": "m"}],
                     "lights": [{"type": "sky", **sky}]})
    assert str(e.value).startswith(field) and words in str(e.value)


def test_a_polar_panorama_of_the_sky_lights_a_scene_as_the_sky_does(tmp_path):
    """An environment map with Stokes channels (S0.R … S3.B, Polar's own EXR) is polarised: a level Polar
    panorama of the Rayleigh sky, written as EXR and used as the environment, renders the same Stokes image
    as the sky itself (the map's frame — the tangent of longitude — is the panorama's)."""
    from engine.output.exr import write_stokes_exr
    sky = render(_sky_scene(35.0, {"model": "rayleigh", "delta": 0.0}, width=128, height=64, spp=16))
    path = tmp_path / "sky.exr"
    write_stokes_exr(str(path), sky.stokes())
    cam = {"projection": "equirectangular", "origin": [0, 0, 0], "target": [1, 0, 0], "up": [0, 0, 1]}
    scene = parse_scene({"format": "polar-scene/1", "camera": {"width": 64, "height": 32, **cam},
                         "render": {"spp": 16, "max_depth": 2, "seed": 2},
                         "materials": {"black": {"type": "lambert", "albedo": 0.0}},
                         "objects": [{"shape": "sphere", "center": [0, 0, -1e3], "radius": 1e-3, "material": "black"}],
                         "lights": [{"type": "environment", "image": "sky.exr"}]}, base_dir=str(tmp_path))
    relit = render(scene)
    assert relit.stats["transport"] == "linear"
    direct = render(_sky_scene(35.0, {"model": "rayleigh", "delta": 0.0}, width=64, height=32, spp=16))
    a, b = _luma(relit).reshape(4, -1), _luma(direct).reshape(4, -1)
    d, _ = _pixel_rays(_sky_scene(35.0, width=64, height=32))
    sun = np.array([math.cos(math.radians(35)), 0.0, math.sin(math.radians(35))])
    gamma = np.degrees(np.arccos(np.clip(sun @ d, -1, 1)))
    lat = np.degrees(np.arcsin(np.clip(d[2], -1, 1)))
    use = (gamma > 15) & (lat > 3) & (lat < 75)
    np.testing.assert_allclose(a[1:3, use] / a[0, use], b[1:3, use] / b[0, use], atol=0.04)
    # the same file without polarisation: unpolarised
    off = parse_scene({"format": "polar-scene/1", "camera": {"width": 8, "height": 4, **cam},
                       "materials": {"black": {"type": "lambert", "albedo": 0.0}},
                       "objects": [{"shape": "sphere", "center": [0, 0, -1e3], "radius": 1e-3, "material": "black"}],
                       "lights": [{"type": "environment", "image": "sky.exr", "polarisation": False}]},
                      base_dir=str(tmp_path))
    assert off.lights[0].polarisation is None
