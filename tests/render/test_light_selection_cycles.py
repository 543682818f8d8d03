"""Scene.light_selection "cycles" (Blender scenes with Light Tree off): whole lights uniformly, a constant sky
beside other lights never chosen by next-event estimation (BSDF sampling alone finds it, MIS weight 1), as Cycles
disables background MIS for a world that does not vary (scene/light.cpp test_enabled_lights).

Oracle: the analytic radiance of a Lambert floor under a sun and a constant sky, ρ/π·E·cosθ + ρ·L (the floor
sees the upper hemisphere only); the variance against "power" selection from 8 seeds of the same scene."""

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
    alone = Renderer(_scene(_lights()[:1], "cycles")).lights         # the sky alone: chosen always
    np.testing.assert_array_equal(alone.prob, [1.0])
    uniform = Renderer(_scene(_lights(point=True), "uniform")).lights     # "uniform" as before
    np.testing.assert_allclose(uniform.prob, 1.0 / 3.0)


def test_floor_under_sun_and_sky_is_the_analytic_radiance():
    """Mean over the image within 0.2 % of ρ/π·E·cosθ + ρ·L, for "cycles" as for "power"."""
    expected = RHO / math.pi * E_SUN * abs(SUN_DIR[2]) + RHO * SKY
    for selection in ("cycles", "power"):
        y = _luminance(_scene(_lights(), selection, spp=32))
        assert y.mean() == pytest.approx(expected, rel=2e-3), selection


def test_cycles_selection_is_less_noisy_than_power_beside_a_dim_lamp():
    """A sun, a dim point lamp and the sky on a floor: σ² between 8 seeds with "cycles" below a tenth of that with
    "power" (the stratified light choice splits the pixel's samples evenly; power picks the dim lamp rarely)."""
    var = {}
    for selection in ("cycles", "power"):
        ys = np.array([_luminance(_scene(_lights(point=True), selection, seed=s)) for s in range(8)])
        var[selection] = ys.var(0, ddof=1).mean()
    assert var["cycles"] < 0.1 * var["power"], var          # measured: 7.8e-7 against 2.4e-4
