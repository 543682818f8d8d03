"""Lights and cameras against closed forms: a Lambertian plane seen by an orthographic camera
straight from above under point, spot, directional and small area lights."""

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
                 lights=list(lights), settings=RenderSettings(spp=spp, spectral="mono", max_depth=2))


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
    scene.settings.max_depth = 1
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
