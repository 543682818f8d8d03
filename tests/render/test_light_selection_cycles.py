"""Scene.light_selection "cycles" (Blender scenes with Light Tree off): as Cycles without its tree, emissive meshes
by area and every other light uniformly (half each where both exist: scene/light.cpp device_update_distribution), a
constant sky beside other lights never chosen by next-event estimation (BSDF sampling alone finds it, MIS weight 1),
as Cycles disables background MIS for a world that does not vary (test_enabled_lights); which light is a constant
sky is the emitter's own ``constant_sky``.

Oracles: Cycles' distribution pdfs by hand; the analytic radiance of a Lambert floor under a sun and a constant
sky, ρ/π·E·cosθ + ρ·L (the floor sees the upper hemisphere only), and under two emissive squares and a point lamp
(Lambert's polygon formula); the variance against "power" selection from 8 seeds of the same scene."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene

RHO, SKY, E_SUN = 0.5, 0.2, 3.0
SUN_DIR = np.array([-0.3, 0.2, -1.0]) / np.linalg.norm([-0.3, 0.2, -1.0])      # the direction the light travels
POINT = {"type": "point", "position": [0.5, 0.3, 1.5], "intensity": 0.4}


def _scene(lights, selection, spp=16, seed=0):
    data = {"format": "polar-scene/1",
            "camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 20,
                       "width": 12, "height": 12},
            "materials": {"floor": {"type": "lambert", "albedo": RHO}},
            "objects": [{"shape": "quad", "material": "floor",
                         "vertices": [[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]]}],
            "lights": lights,
            "render": {"spp": spp, "max_depth": 2, "seed": seed}}
    return dataclasses.replace(parse_scene(data), light_selection=selection)


def _lights(point=False):
    out = [{"type": "environment", "radiance": SKY},
           {"type": "directional", "direction": SUN_DIR.tolist(), "irradiance": E_SUN, "angle_deg": 5.0}]
    return out + ([POINT] if point else [])


def _luminance(scene):
    return Renderer(scene).render(scene.settings).stokes()[0].mean(-1)


def test_probabilities_leave_a_constant_sky_to_bsdf_sampling():
    lights = Renderer(_scene(_lights(point=True), "cycles")).lights
    sky = [type(lt).__name__ == "EnvironmentEmitter" for lt in lights.lights]
    assert sky.count(True) == 1
    np.testing.assert_array_equal(lights.prob, np.where(sky, 0.0, 0.5))
    assert lights.prob_at(sky.index(True), np.zeros((3, 2)), np.tile([[0.0], [0.0], [1.0]], 2)) == 0.0
    u = np.linspace(0.0, 1.0, 1000, endpoint=False)
    choice = lights.choose(u, np.zeros((3, u.size)))[0]
    assert not np.any(choice == sky.index(True))
    assert abs(np.mean(choice == (sky.index(True) + 1) % 3) - 0.5) < 0.01
    alone = Renderer(_scene(_lights()[:1], "cycles")).lights         # the sky alone: never, no light is sampled
    np.testing.assert_array_equal(alone.prob, [0.0])
    assert not alone.sampled and Renderer(_scene(_lights()[:1], "power")).lights.sampled
    uniform = Renderer(_scene(_lights(point=True), "uniform")).lights     # "uniform" as before
    np.testing.assert_allclose(uniform.prob, 1.0 / 3.0)


def test_floor_under_sun_and_sky_is_the_analytic_radiance():
    """Mean over the image within 0.2 % of ρ/π·E·cosθ + ρ·L, for "cycles" as for "power"."""
    expected = RHO / math.pi * E_SUN * abs(SUN_DIR[2]) + RHO * SKY
    for selection in ("cycles", "power"):
        y = _luminance(_scene(_lights(), selection, spp=32))
        assert y.mean() == pytest.approx(expected, rel=2e-3), selection


def test_a_constant_sky_alone_is_left_to_bsdf_rays_as_cycles_does():
    """Cycles disables a world that does not vary as a light (test_enabled_lights, also when it is the only light):
    a Lambert floor under it is found by cosine-sampled BSDF rays alone, each sample ρ·L exactly — no noise at
    all, where light-sampling the sphere ("power") is noisy; the same mean."""
    ys = {sel: np.array([_luminance(_scene(_lights()[:1], sel, spp=4, seed=s)) for s in range(3)])
          for sel in ("cycles", "power")}
    assert ys["cycles"].var(0).max() < 1e-24                    # every pixel of every seed the same value
    np.testing.assert_allclose(ys["cycles"], RHO * SKY, rtol=1e-4)   # (D65 white → sRGB: within 3.4e-5)
    assert ys["power"].var(0, ddof=1).mean() > 1e-6
    assert ys["power"].mean() == pytest.approx(RHO * SKY, rel=2e-2)


def test_cycles_selection_is_less_noisy_than_power_beside_a_dim_lamp():
    """A sun, a dim point lamp and the sky on a floor: σ² between 8 seeds with "cycles" below a tenth of that with
    "power" (the stratified light choice splits the pixel's samples evenly; power picks the dim lamp rarely)."""
    var = {}
    for selection in ("cycles", "power"):
        ys = np.array([_luminance(_scene(_lights(point=True), selection, seed=s)) for s in range(8)])
        var[selection] = ys.var(0, ddof=1).mean()
    assert var["cycles"] < 0.1 * var["power"], var          # measured: 7.8e-7 against 2.4e-4


# --------------------------------------------------------------------------- emissive triangles by area (Cycles)

#: two coplanar emissive squares facing down at z = 1 (areas 1 and 0.25, radiances 2 and 6) and a point lamp below
#: them; a Lambert floor seen from z = 0.8 straight down
SQUARES = (((-0.8, 0.2), (-0.5, 0.5), 2.0), ((0.4, 0.9), (-0.25, 0.25), 6.0))
LAMP, LAMP_I, EYE, FOV = np.array([0.3, 0.6, 0.5]), 0.2, 0.8, 40.0


def _square_scene(selection, spp=64, seed=0, lamp=True):
    objects = [{"shape": "quad", "material": "floor", "vertices": [[-50, -50, 0], [50, -50, 0], [50, 50, 0],
                                                                   [-50, 50, 0]]}]
    for (x0, x1), (y0, y1), radiance in SQUARES:       # this winding's front faces down (−z)
        objects.append({"shape": "quad", "material": "floor", "emission": {"radiance": radiance},
                        "vertices": [[x0, y0, 1], [x0, y1, 1], [x1, y1, 1], [x1, y0, 1]]})
    data = {"format": "polar-scene/1",
            "camera": {"origin": [0, 0, EYE], "target": [0, 0, 0], "up": [0, 1, 0], "fov_deg": FOV,
                       "width": 12, "height": 12},
            "materials": {"floor": {"type": "lambert", "albedo": RHO}},
            "objects": objects,
            "lights": [{"type": "point", "position": LAMP.tolist(), "intensity": LAMP_I}] if lamp else [],
            "render": {"spp": spp, "max_depth": 2, "seed": seed}}
    return dataclasses.replace(parse_scene(data), light_selection=selection)


def _polygon_irradiance(p, corners):
    """Irradiance (m,) at floor points p (m, 3) (normal +z) from a Lambertian polygon of radiance 1 (Lambert's
    formula: ½ Σ over its edges of the angle they subtend × the z component of their unit normals)."""
    u = corners[None, :, :] - p[:, None, :]
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    v = np.roll(u, -1, axis=1)
    angle = np.arccos(np.clip((u * v).sum(-1), -1.0, 1.0))
    cross = np.cross(u, v)
    return np.abs(0.5 * (angle * cross[..., 2] / np.linalg.norm(cross, axis=-1)).sum(-1))


def test_cycles_probabilities_are_cycles_distribution():
    """Cycles' distribution_pdf_lights / _triangles by hand: lamps 1/num_lights, triangles ∝ area, half each where
    both exist; a constant sky and lights that light nothing 0; the sky alone 0 too; nothing usable: None."""
    from engine.render.lights.selection import cycles_probabilities
    area, sky, none = np.array([1.0, 0.25, 0.0, 0.0, 0.0]), np.array([0, 0, 0, 0, 1], bool), np.zeros(5, bool)
    np.testing.assert_allclose(cycles_probabilities(area, sky, none), [0.4, 0.1, 0.25, 0.25, 0.0])
    np.testing.assert_allclose(cycles_probabilities(area, np.zeros(5, bool), none), [0.4, 0.1, 1 / 6, 1 / 6, 1 / 6])
    np.testing.assert_allclose(cycles_probabilities(area[:2], sky[:2], none[:2]), [0.8, 0.2])     # triangles only
    np.testing.assert_allclose(cycles_probabilities(area[2:], sky[2:], none[2:]), [0.5, 0.5, 0.0])  # lamps only
    hidden = np.array([0, 1, 0, 1, 0], bool)            # a hidden mesh and a hidden lamp: 0, the rest renormalised
    np.testing.assert_allclose(cycles_probabilities(area, sky, hidden), [0.5, 0.0, 0.5, 0.0, 0.0])
    np.testing.assert_allclose(cycles_probabilities(area[4:], sky[4:], none[4:]), [0.0])    # the sky alone: none
    assert cycles_probabilities(area[:1], sky[:1], np.ones(1, bool)) is None


def test_emissive_squares_by_area_and_a_lamp_give_the_analytic_floor():
    """Two emissive squares (areas 1 and 0.25) and a point lamp: picked with 0.4, 0.1 and 0.5 (Cycles without its
    tree: half to the triangles by area); the floor's mean radiance within 0.5 % of ρ/π·E from Lambert's polygon
    formula and the lamp's I·cosθ/d²."""
    renderer = Renderer(_square_scene("cycles"))
    kinds = [type(lt).__name__ for lt in renderer.lights.lights]
    np.testing.assert_allclose(renderer.lights.prob, [0.4, 0.1, 0.5], err_msg=str(kinds))
    half = EYE * math.tan(math.radians(FOV / 2))
    g = (np.arange(200) + 0.5) / 200 * 2 * half - half
    p = np.stack(np.meshgrid(g, g) + [np.zeros((200, 200))], -1).reshape(-1, 3)
    E = sum(radiance * _polygon_irradiance(p, np.array([[x0, y0, 1], [x0, y1, 1], [x1, y1, 1], [x1, y0, 1]], float))
            for (x0, x1), (y0, y1), radiance in SQUARES)
    d = LAMP[None, :] - p
    E = E + LAMP_I * d[:, 2] / np.linalg.norm(d, axis=1) ** 3
    expected = RHO / math.pi * E.mean()
    y = renderer.render(renderer.scene.settings).stokes()[0].mean(-1)
    assert y.mean() == pytest.approx(expected, rel=5e-3)


# --------------------------------------------------------------------------- which light is a constant sky

def test_constant_sky_is_a_property_of_the_emitter(monkeypatch):
    """``constant_sky`` is the emitter's own: only the constant world says it (not a world map, a sky model, a
    sun, lamps or meshes); a sky class derived from the constant one is constant unless it says it varies with
    direction, and "cycles" gives such a varying sky its share beside the lamps."""
    from engine.render.lights import selection
    from engine.render.lights.environment import EnvironmentEmitter
    sky_model = {"type": "sky", "sun_direction": [0.3, 0.2, 0.9], "turbidity": 3.0, "polarisation": "none"}
    spot = {"type": "spot", "position": [0, 0, 2], "direction": [0, 0, -1], "intensity": 1.0}
    lights = Renderer(_scene(_lights(point=True) + [spot], "cycles")).lights.lights
    assert [lt.constant_sky for lt in lights] == [True, False, False, False]
    assert not any(lt.constant_sky for lt in Renderer(_square_scene("cycles")).lights.lights)
    mapped = Renderer(_scene([sky_model] + _lights()[1:], "cycles")).lights
    assert [lt.constant_sky for lt in mapped.lights] == [False, False]
    np.testing.assert_array_equal(mapped.prob, [0.5, 0.5])

    class PlainSky(EnvironmentEmitter):            # a new constant sky class: still left to BSDF sampling
        pass

    class VaryingSky(EnvironmentEmitter):          # a sky that varies: sampled as a light
        varies_with_direction = True

    for cls, prob in ((PlainSky, [0.0, 0.5, 0.5]), (VaryingSky, [1 / 3, 1 / 3, 1 / 3])):
        monkeypatch.setattr(selection, "EnvironmentEmitter", cls)
        light_set = Renderer(_scene(_lights(point=True), "cycles")).lights
        assert type(light_set.lights[0]) is cls
        np.testing.assert_allclose(light_set.prob, prob, err_msg=cls.__name__)
