"""Lights and cameras against closed forms: a Lambertian plane seen by an orthographic camera
straight from above under point, spot, directional and small area lights."""

import dataclasses
import math

import numpy as np
import pytest

from engine.materials.lambert import Lambert
from engine.render.renderer import Renderer
from engine.scene.description import (Camera, DirectionalLight, Mesh, PointLight, RenderSettings, Scene,
                                      SpotLight)
from engine.scene.shapes import quad
from engine.spectral import ConstantSpectrum, RGBIlluminantSpectrum

RHO = 0.6
H = 2.0
WIDTH = 4.0     # the camera sees x, y ∈ [−2, 2]


def plane_scene(lights, extra_meshes=(), res=32, spp=16):
    floor = quad(*[np.array(p, float) for p in ([-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0])])
    meshes = [Mesh("floor", floor.vertices, floor.faces, ["grey"], np.zeros(2, np.int32))]
    meshes += list(extra_meshes)
    cam = Camera(origin=np.array([0.0, 0.0, 5.0]), target=np.zeros(3), up=np.array([0.0, 1.0, 0.0]),
                 width=res, height=res, projection="orthographic", ortho_width=WIDTH)
    return Scene(camera=cam, meshes=meshes,
                 materials={"grey": Lambert(ConstantSpectrum(RHO)), "black": Lambert(ConstantSpectrum(0.0))},
                 lights=list(lights), settings=RenderSettings(spp=spp, spectral="mono", max_depth=2,
                                                                                 sampler="independent"))


def pixel_centres(res):
    c = (np.arange(res) + 0.5) / res * WIDTH - WIDTH / 2
    x = c[None, :].repeat(res, 0)
    y = -c[:, None].repeat(res, 1)          # row 0 is the top of the image (+y: camera up)
    return x, y


def white(scale):
    return RGBIlluminantSpectrum([1.0, 1.0, 1.0], scale)


def test_point_light_inverse_square_and_cosine():
    I = 5.0
    res = 32
    result = Renderer(plane_scene([PointLight(np.array([0.0, 0.0, H]), white(I))], res=res, spp=64)).render()
    x, y = pixel_centres(res)
    r2 = x * x + y * y + H * H
    expected = RHO / math.pi * I * (H / np.sqrt(r2)) / r2
    S = result.stokes_luminance()
    np.testing.assert_allclose(S[0], expected, rtol=0.02)
    assert np.all(S[1:] == 0)


def test_directional_light_gives_cosine_weighted_irradiance():
    E = 3.0
    d = np.array([0.6, 0.0, -0.8])
    result = Renderer(plane_scene([DirectionalLight(d, white(E))], res=8, spp=4)).render()
    np.testing.assert_allclose(result.stokes_luminance()[0], RHO / math.pi * E * 0.8, rtol=1e-9)


def test_spot_light_cone_cuts_off_outside_the_angle():
    I = 5.0
    res = 32
    spot = SpotLight(np.array([0.0, 0.0, H]), np.array([0.0, 0.0, -1.0]), white(I), cone_angle_deg=40.0, blend=0.0)
    S = Renderer(plane_scene([spot], res=res, spp=16)).render().stokes_luminance()[0]
    x, y = pixel_centres(res)
    angle = np.degrees(np.arctan(np.hypot(x, y) / H))
    r2 = x * x + y * y + H * H
    inside = angle < 20 - 2
    outside = angle > 20 + 2
    np.testing.assert_allclose(S[inside], (RHO / math.pi * I * (H / np.sqrt(r2)) / r2)[inside], rtol=0.02)
    assert np.all(S[outside] == 0)


def test_small_area_light_matches_the_equivalent_point_light():
    # A 0.1 × 0.1 square facing down with radiance L emits intensity L·A along its normal·cosθ.
    L, a = 500.0, 0.1
    q = quad(*[np.array(p, float) for p in ([-a / 2, a / 2, H], [a / 2, a / 2, H], [a / 2, -a / 2, H],
                                             [-a / 2, -a / 2, H])])
    lamp = Mesh("lamp", q.vertices, q.faces, ["black"], np.zeros(2, np.int32), emission=white(L))
    res = 16
    result = Renderer(plane_scene([], [lamp], res=res, spp=64)).render()
    x, y = pixel_centres(res)
    r2 = x * x + y * y + H * H
    cos = H / np.sqrt(r2)
    expected = RHO / math.pi * L * a * a * cos * cos / r2      # finite size: relative error ~ (a/H)² ≈ 0.3 %
    S0 = result.stokes_luminance()[0]
    se = result.film.stderr_luminance()[0]
    assert np.mean(np.abs(S0 - expected) < 4 * se + 0.005 * expected) > 0.99
    assert abs(S0.mean() / expected.mean() - 1) < 4 * np.sqrt((se ** 2).sum()) / se.size / expected.mean() + 0.005


def test_emitter_seen_directly_has_its_radiance_front_side_only():
    L = 2.5
    up = quad(*[np.array(p, float) for p in ([-5, -5, 1], [5, -5, 1], [5, 5, 1], [-5, 5, 1])])      # faces +z
    scene = plane_scene([], [Mesh("lamp", up.vertices, up.faces, ["black"], np.zeros(2, np.int32),
                                  emission=white(L))], res=8, spp=2)
    scene.settings = dataclasses.replace(scene.settings, max_depth=1)
    np.testing.assert_allclose(Renderer(scene).render().stokes_luminance()[0], L, rtol=1e-12)
    down = quad(*[np.array(p, float) for p in ([-5, 5, 1], [5, 5, 1], [5, -5, 1], [-5, -5, 1])])    # faces −z
    scene.meshes[1] = Mesh("lamp", down.vertices, down.faces, ["black"], np.zeros(2, np.int32), emission=white(L))
    assert np.all(Renderer(scene).render().stokes_luminance()[0] == 0)


@pytest.mark.parametrize("fov_axis", ["x", "y"])
def test_perspective_camera_ray_formula(fov_axis):
    from engine.render.camera import CameraModel
    cam = Camera(origin=np.zeros(3), target=np.array([0.0, 1.0, 0.0]), up=np.array([0.0, 0.0, 1.0]),
                 width=200, height=100, fov_deg=60.0, fov_axis=fov_axis)
    model = CameraModel(cam)
    # The right edge of the middle row (x = W) is at tan(fov/2) along x for fov_axis x.
    o, d, x, _, _ = model.generate(np.array([50 * 200 + 199]), np.array([[1.0], [0.0]]))
    t = math.tan(math.radians(30))
    slope_x = d[0, 0] / d[1, 0]
    assert abs(slope_x - (t if fov_axis == "x" else t * 2)) < 1e-12
    np.testing.assert_allclose(x[:, 0], np.cross(d[:, 0], [0, 0, 1]) / np.linalg.norm(np.cross(d[:, 0], [0, 0, 1])))


# ----------------------------------------------------------------------------- Cycles' light options
# Closed forms from Cycles' radiometry (intern/cycles/kernel/light/{point,spot,distant,area}.h).

def luminance_and_stderr(scene):
    result = Renderer(scene).render()
    return result.stokes_luminance()[0], result.film.stderr_luminance()[0]


def assert_matches(S0, se, expected, slack=0.005):
    """Pixels within 4 standard errors + slack·expected; the image mean within its own 4 σ + slack."""
    assert np.mean(np.abs(S0 - expected) < 4 * se + slack * expected) > 0.99
    assert abs(S0.mean() / expected.mean() - 1) < 4 * np.sqrt((se ** 2).sum()) / se.size / expected.mean() + slack


def test_disk_point_light_has_soft_falloff():
    # radius r, soft falloff: a disk of radiance I/(πr²) facing the receiver; irradiance at distance d
    # on a surface tilted by θ (horizon clear of the disk) = I/(d² + r²)·cosθ.
    I, r, res = 5.0, 0.8, 16
    light = PointLight(np.array([0.0, 0.0, H]), white(I), radius=r, soft_falloff=True, visible_camera=False)
    S0, se = luminance_and_stderr(plane_scene([light], res=res, spp=64))
    x, y = pixel_centres(res)
    d2 = x * x + y * y + H * H
    assert_matches(S0, se, RHO / math.pi * I / (d2 + r * r) * H / np.sqrt(d2))


def test_sphere_point_light_is_exactly_inverse_square_outside():
    I, r, res = 5.0, 0.8, 16
    light = PointLight(np.array([0.0, 0.0, H]), white(I), radius=r, soft_falloff=False, visible_camera=False)
    S0, se = luminance_and_stderr(plane_scene([light], res=res, spp=64))
    x, y = pixel_centres(res)
    d2 = x * x + y * y + H * H
    assert_matches(S0, se, RHO / math.pi * I / d2 * H / np.sqrt(d2))


def test_camera_sees_sphere_and_disk_lights_with_their_radiance():
    # L = I/(πr²) (Cycles: S/(4π²r²)); the floor behind the light's silhouette is not occluded
    I, r = 5.0, 0.5
    for soft in (False, True):
        scene = plane_scene([PointLight(np.array([0.0, 0.0, H]), white(I), radius=r, soft_falloff=soft)], res=16,
                            spp=4)
        scene.settings = dataclasses.replace(scene.settings, max_depth=1)
        S0 = Renderer(scene).render().stokes_luminance()[0]
        x, y = pixel_centres(16)
        np.testing.assert_allclose(S0[np.hypot(x, y) < 0.3], I / (math.pi * r * r), rtol=1e-12)
        assert np.all(S0[np.hypot(x, y) > 0.75] == 0)


def test_sun_with_an_angle_keeps_its_irradiance():
    # a uniform disc of angular diameter 20° and radiance E/(π sin²10°): E·cosθ on any surface
    # whose horizon it clears
    E = 3.0
    d = np.array([0.6, 0.0, -0.8])
    S0, se = luminance_and_stderr(plane_scene([DirectionalLight(d, white(E), angle_deg=20.0)], res=8, spp=64))
    assert_matches(S0, se, np.full_like(S0, RHO / math.pi * E * 0.8), slack=0.002)


def test_sun_disc_is_seen_with_its_radiance():
    E, angle = 3.0, 2.0
    scene = plane_scene([DirectionalLight(np.array([0.0, 0.0, 1.0]), white(E), angle_deg=angle)], res=4, spp=2)
    scene.camera.origin, scene.camera.target = np.array([0.0, 0.0, -5.0]), np.array([0.0, 0.0, -10.0])
    scene.settings = dataclasses.replace(scene.settings, max_depth=1)
    S0 = Renderer(scene).render().stokes_luminance()[0]            # every ray looks into the sun
    np.testing.assert_allclose(S0, E / (math.pi * math.sin(math.radians(angle / 2)) ** 2), rtol=1e-12)
    scene.lights[0].visible_camera = False
    assert np.all(Renderer(scene).render().stokes_luminance()[0] == 0)


def test_spot_blend_follows_cycles_smoothstep_in_cosine():
    from engine.render.lights import SpotEmitter
    # Blender's defaults (45°, blend 0.15): full intensity inside 20.72°, not (1 − b)·22.5° = 19.13°
    spot = SpotEmitter(white(1.0), np.zeros(3), np.array([0.0, 0.0, -1.0]), 45.0, 0.15, "cycles")
    angles = np.radians([0.0, 19.5, 20.6, 20.8, 22.0, 22.49, 22.51, 40.0])
    wi = np.stack((np.sin(angles), np.zeros_like(angles), np.cos(angles)))     # receiver → light
    cos_half = math.cos(math.radians(22.5))
    t = np.clip((np.cos(angles) - cos_half) / (0.15 * (1 - cos_half)), 0, 1)
    np.testing.assert_allclose(spot._falloff(wi), t * t * (3 - 2 * t), rtol=1e-12, atol=1e-15)
    assert spot._falloff(wi)[2] == 1 and spot._falloff(wi)[3] < 1
    # … and a render under it
    I, res = 5.0, 32
    light = SpotLight(np.array([0.0, 0.0, H]), np.array([0.0, 0.0, -1.0]), white(I), cone_angle_deg=50.0,
                      blend=0.5, blend_profile="cycles")
    S0 = Renderer(plane_scene([light], res=res, spp=64)).render().stokes_luminance()[0]
    x, y = pixel_centres(res)
    r2 = x * x + y * y + H * H
    c = H / np.sqrt(r2)
    t = np.clip((c - math.cos(math.radians(25))) / (0.5 * (1 - math.cos(math.radians(25)))), 0, 1)
    expected = RHO / math.pi * I * c / r2 * t * t * (3 - 2 * t)
    assert abs(S0.sum() / expected.sum() - 1) < 0.01                # pixel footprints average the edge


def small_lamp(L, a=0.1, facing_down=True, **options):
    corners = ([-a / 2, a / 2, H], [a / 2, a / 2, H], [a / 2, -a / 2, H], [-a / 2, -a / 2, H])
    q = quad(*[np.array(p, float) for p in (corners if facing_down else corners[::-1])])
    return Mesh("lamp", q.vertices, q.faces, ["black"], np.zeros(2, np.int32), emission=white(L), **options)


def test_two_sided_emitter_lights_with_its_back():
    L, a, res = 500.0, 0.1, 16
    S0, se = luminance_and_stderr(plane_scene([], [small_lamp(L, a, facing_down=False, two_sided=True)],
                                              res=res, spp=64))
    x, y = pixel_centres(res)
    r2 = x * x + y * y + H * H
    assert_matches(S0, se, RHO / math.pi * L * a * a * H * H / (r2 * r2))


def test_spread_concentrates_the_light_and_keeps_the_power():
    # Cycles' spread s: radiance L·f(θ), f = N·(tan(s/2) − tan θ)⁺, N = 1/(tan(s/2) − s/2)
    L, a, res, s = 500.0, 0.1, 16, math.radians(100.0)
    S0, se = luminance_and_stderr(plane_scene([], [small_lamp(L, a, spread_deg=100.0)], res=res, spp=64))
    x, y = pixel_centres(res)
    r2 = x * x + y * y + H * H
    cos = H / np.sqrt(r2)
    f = np.maximum(0.0, math.tan(s / 2) - np.sqrt(1 - cos * cos) / cos) / (math.tan(s / 2) - s / 2)
    away = np.abs(np.sqrt(1 - cos * cos) / cos / math.tan(s / 2) - 1) > 0.15     # not across the cut-off
    expected = RHO / math.pi * L * f * a * a * cos * cos / r2
    assert_matches(S0[away], se[away], expected[away])
    assert abs(S0.sum() / expected.sum() - 1) < 0.02
    from engine.render.lights import spread_profile
    th = np.linspace(0, math.pi / 2, 200001)
    mid = 0.5 * (th[1:] + th[:-1])
    integral = (spread_profile(s)(np.cos(mid)) * np.cos(mid) * np.sin(mid)).sum() * (th[1] - th[0]) * 2 * math.pi
    assert integral == pytest.approx(math.pi, rel=1e-6)      # the emitted power is that of f = 1


def test_lamps_do_not_occlude_and_add_light_where_rays_cross_them():
    # A lamp between the camera and the floor, facing up (towards the camera), not an occluder:
    # the point light's shadows and the floor behind it are unchanged, the camera sees L on top.
    I, L = 5.0, 2.0
    point = PointLight(np.array([0.3, 0.0, H + 1.0]), white(I))
    big = quad(*[np.array(p, float) for p in ([-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1])])   # faces +z
    lamp = Mesh("lamp", big.vertices, big.faces, ["black"], np.zeros(2, np.int32), emission=white(L),
                occluder=False)
    res = 16
    x, y = pixel_centres(res)
    d2 = (x - 0.3) ** 2 + y * y + (H + 1.0) ** 2
    lit = RHO / math.pi * I * (H + 1.0) / np.sqrt(d2) / d2           # unshadowed, as if the lamp were absent
    under = (np.abs(x) < 0.95) & (np.abs(y) < 0.95)
    outside = (np.abs(x) > 1.05) | (np.abs(y) > 1.05)
    S0, se = luminance_and_stderr(plane_scene([point], [lamp], res=res, spp=16))
    assert_matches(S0[outside], se[outside], lit[outside])
    assert_matches(S0[under], se[under], lit[under] + L)
    lamp.visible_camera = False
    S0, se = luminance_and_stderr(plane_scene([point], [lamp], res=res, spp=16))
    assert_matches(S0, se, lit)


def test_power_selection_is_unbiased_and_prefers_strong_lights():
    from engine.render.lights import LightSet
    from engine.render.accel import CompiledScene
    rng = np.random.default_rng(3)
    pos = np.column_stack((rng.uniform(-2, 2, 8), rng.uniform(-2, 2, 8), rng.uniform(1, 3, 8)))
    power = np.logspace(0, 3, 8)
    lights = [PointLight(p, white(i)) for p, i in zip(pos, power / 100)]
    res = 16
    scene = plane_scene(lights, res=res, spp=64)
    scene.light_selection = "power"
    S0, se = luminance_and_stderr(scene)
    x, y = pixel_centres(res)
    expected = np.zeros_like(x)
    for p, i in zip(pos, power / 100):
        d2 = (x - p[0]) ** 2 + (y - p[1]) ** 2 + p[2] ** 2
        expected += RHO / math.pi * i * p[2] / np.sqrt(d2) / d2
    assert_matches(S0, se, expected)
    ls = LightSet(scene, CompiledScene(scene))
    probs = ls.probabilities(np.array([[0.0], [0.0], [0.0]]))
    assert probs.sum() == pytest.approx(1.0) and np.all(probs > 0)
    assert ls.prob[-1] > 0.5                                      # ∝ power globally


def test_power_selection_keeps_mis_unbiased_for_area_lights_and_sky():
    # emitter hits by BSDF rays weigh themselves with the selection probability at the vertex the
    # ray left: a wrong probability would bias the sum of both strategies
    from engine.scene.description import EnvironmentLight
    L_env, res = 0.2, 16
    lamps, expected = [], np.full((res, res), RHO * L_env)
    x, y = pixel_centres(res)
    for k, (cx, L) in enumerate(((-1.0, 200.0), (0.0, 2000.0), (1.0, 20000.0))):
        a = 0.1
        corners = ([cx - a / 2, a / 2, H], [cx + a / 2, a / 2, H], [cx + a / 2, -a / 2, H], [cx - a / 2, -a / 2, H])
        q = quad(*[np.array(p, float) for p in corners])
        lamps.append(Mesh(f"lamp{k}", q.vertices, q.faces, ["black"], np.zeros(2, np.int32), emission=white(L),
                          occluder=False))
        d2 = (x - cx) ** 2 + y * y + H * H
        expected = expected + RHO / math.pi * L * a * a * H * H / (d2 * d2)
    scene = plane_scene([EnvironmentLight(white(L_env))], lamps, res=res, spp=128)
    scene.light_selection = "power"
    S0, se = luminance_and_stderr(scene)
    assert_matches(S0, se, expected)                               # finite lamp size: ≲ (a/H)² ≈ 0.3 %


def test_scene_format_light_options_are_optional_and_validated():
    from engine.errors import SceneError
    from engine.scene.loader import parse_light, parse_object
    quad_obj = {"shape": "quad", "vertices": [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], "material": "a"}
    plain = parse_object({**quad_obj, "emission": {"radiance": 2}}, "o", ".", {"a": None})
    assert (plain.two_sided, plain.occluder, plain.visible_camera, plain.spread_deg) == (False, True, True, 180.0)
    lamp = parse_object({**quad_obj, "emission": {"radiance": 2, "two_sided": True, "occluder": False,
                                                  "spread_deg": 90}}, "o", ".", {"a": None})
    assert (lamp.two_sided, lamp.occluder, lamp.spread_deg) == (True, False, 90.0)
    point = parse_light({"type": "point", "position": [0, 0, 1], "radius": 0.2, "soft_falloff": False}, "l")
    assert (point.radius, point.soft_falloff) == (0.2, False)
    assert parse_light({"type": "point", "position": [0, 0, 1]}, "l").radius == 0.0
    assert parse_light({"type": "directional", "direction": [0, 0, -1], "angle_deg": 5}, "l").angle_deg == 5.0
    spot = parse_light({"type": "spot", "position": [0, 0, 1], "direction": [0, 0, -1], "blend": 0.2,
                        "blend_profile": "cycles"}, "l")
    assert spot.blend_profile == "cycles"
    for bad, where in (({"type": "point", "position": [0, 0, 1], "radius": -1}, "lights[0].radius"),
                       ({"type": "point", "position": [0, 0, 1], "soft_falloff": 1}, "lights[0].soft_falloff"),
                       ({"type": "spot", "position": [0, 0, 1], "direction": [0, 0, -1], "blend_profile": "x"},
                        "lights[0].blend_profile")):
        with pytest.raises(SceneError, match=where.replace("[", r"\[").replace("]", r"\]")):
            parse_light(bad, "lights[0]")
    with pytest.raises(SceneError, match=r"objects\[0\]\.emission\.spread_deg"):
        parse_object({**quad_obj, "emission": {"spread_deg": 0}}, "objects[0]", ".", {"a": None})


def test_a_constant_sky_beside_a_lamp_takes_few_light_samples():
    # Every NEE sample the sky takes beside a lamp is a sample without the lamp; cosine-sampled BSDF
    # rays find a constant sky anyway (MIS weight → 1).  With the sky in the global power share
    # (≈ 5 % of a lamp-lit floor's samples here) the floor under the lamp had 2.6× the variance it has
    # without the sky; now the sky changes it by the little light it adds.
    from engine.render.accel import CompiledScene
    from engine.render.lights import LightSet
    from engine.scene.description import EnvironmentLight
    a = 1.0
    corners = ([-a, a, H], [a, a, H], [a, -a, H], [-a, -a, H])
    q = quad(*[np.array(p, float) for p in corners])                # facing down
    lamp = Mesh("lamp", q.vertices, q.faces, ["black"], np.zeros(2, np.int32), emission=white(20.0), occluder=False)
    sky = EnvironmentLight(white(0.2))

    def floor_variance(lights, meshes):
        scene = plane_scene(lights, meshes, res=16, spp=64)
        scene.light_selection = "power"
        S0, se = luminance_and_stderr(scene)
        x, y = pixel_centres(16)
        under = (np.abs(x) < 0.8) & (np.abs(y) < 0.8)
        return float(np.mean(se[under] ** 2)), scene

    with_sky, scene = floor_variance([sky], [lamp])
    without_sky, _ = floor_variance([], [lamp])
    assert with_sky < 1.5 * without_sky
    lights = LightSet(scene, CompiledScene(scene))
    probs = lights.probabilities(np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]]),
                                 np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 1.0]]))
    sky_row = lights.environment_index
    assert np.all(probs[sky_row] > 0) and np.all(probs[sky_row] < 0.01)
    assert np.allclose(probs.sum(0), 1.0)
    alone = plane_scene([sky])
    alone.light_selection = "power"
    assert LightSet(alone, CompiledScene(alone)).probabilities(np.zeros((3, 1)))[0, 0] == 1.0


def test_a_light_of_an_unknown_type_is_an_error_not_left_out():
    # (a scene built with another copy of the package, e.g. the Blender extension's, fails isinstance)
    from engine.errors import SceneError
    from engine.render.accel import CompiledScene
    from engine.render.lights import LightSet

    class StrangeLight:
        intensity = 1.0

    scene = plane_scene([PointLight(np.array([0.0, 0.0, 1.0]), white(1.0)), StrangeLight()])
    with pytest.raises(SceneError, match=r"lights\[1\].*StrangeLight"):
        LightSet(scene, CompiledScene(scene))
