"""Equirectangular environment maps: the peer convention (shared/peers/envmaps/make_envmap.py is the
oracle), importance sampling against its pdf (chi-square), rotation, the scene format and a render of
the peer scene envmap_spheres."""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.render.integrator import PathTracer
from engine.render.lights import EnvironmentMapEmitter
from engine.render.renderer import Renderer
from engine.render.sampler import PathSampler, path_keys
from engine.scene.description import EnvironmentLight
from engine.scene.loader import load_scene, parse_light
from engine.spectral import luminance
from tests.conftest import shared_path
from tests.support.chi2 import _with_elsewhere, assert_accepted, pearson


def _make_envmap():
    spec = importlib.util.spec_from_file_location("make_envmap", shared_path("peers", "envmaps", "make_envmap.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


ME = _make_envmap()
SKY = ME.read_exr(shared_path("peers", "envmaps", "sky_sun_patches.exr")).astype(np.float64)


def random_directions(n, seed=1):
    d = np.random.default_rng(seed).normal(size=(3, n))
    return d / np.linalg.norm(d, axis=0)


def rot_z(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# --------------------------------------------------------------------------- the convention

def test_lookup_matches_the_peer_reference():
    env = EnvironmentMapEmitter(SKY, grid="mitsuba")
    d = np.concatenate((random_directions(20000), ME.texel_directions(512, 256).reshape(-1, 3).T,
                        ME.sun_direction()[:, None], np.array([[0, 0, 1], [0, 0, -1], [-1, 0, 0]], float).T), axis=1)
    np.testing.assert_allclose(env.lookup_rgb(d), ME.lookup(SKY, d.T), rtol=1e-9, atol=1e-9)


def _escaped_scene(tmp_path, mono):
    """Camera looking at the sky; one small quad far behind it (the scene needs geometry)."""
    data = {"format": "polar-scene/1",
            "camera": {"origin": [0, 0, 0], "target": [1, 0.3, 0.4], "up": [0, 0, 1], "fov_deg": 120,
                       "width": 16, "height": 12},
            "materials": {"grey": {"type": "lambert", "albedo": 0.5}},
            "objects": [{"shape": "quad", "material": "grey",
                         "vertices": [[-50, -1, -1], [-50, 1, -1], [-50, 1, 1], [-50, -1, 1]]}],
            "lights": [{"type": "environment", "image": "sky.exr", "grid": "mitsuba"}],
            "render": {"spp": 1, "max_depth": 1, "spectral": "mono" if mono else "spectral", "sampler": "independent"}}
    ME.write_exr(str(tmp_path / "sky.exr"), SKY.astype(np.float32))
    (tmp_path / "scene.json").write_text(json.dumps(data))
    return load_scene(str(tmp_path / "scene.json"))


@pytest.mark.parametrize("mono", [False, True])
def test_escaped_rays_see_the_reference_lookup(tmp_path, mono):
    """Camera rays that escape get exactly lookup() (RGB mode) or its luminance (mono mode)."""
    scene = _escaped_scene(tmp_path, mono)
    r = Renderer(scene)
    st = dataclasses.replace(scene.settings, polarisation="full")   # what "auto" resolves to is irrelevant here
    tracer = PathTracer(r.compiled, r.lights, r.camera, st)
    pixel = np.arange(scene.camera.width * scene.camera.height)
    sample = np.zeros_like(pixel)
    out, _ = tracer.trace(pixel, sample)
    # the same camera rays, from the same per-path random numbers
    sampler = PathSampler(path_keys(st.seed, pixel, sample))
    _, d, *_ = r.camera.generate(pixel, sampler.next(2 + r.camera.lens_dimensions))
    ref = ME.lookup(SKY, d.T)
    if mono:
        np.testing.assert_allclose(out[0, 0], luminance(ref), rtol=1e-6)
    else:
        assert tracer.rgb_mode
        np.testing.assert_allclose(out[0].T, ref, rtol=1e-6)


def test_spectral_emission_develops_to_the_lookup():
    """In spectral mode each direction emits D65n · Σ rgb_c B_c, which develops back to lookup()."""
    from engine.spectral import GRID_NM, WavelengthLookup, spectrum_to_linear_srgb
    env = EnvironmentMapEmitter(SKY, grid="mitsuba")
    d = np.concatenate((random_directions(4, seed=9), ME.sun_direction()[:, None]), axis=1)
    lam = np.repeat(np.asarray(GRID_NM, float)[:, None], d.shape[1], axis=1)
    spectra = env.emitted(d, WavelengthLookup(lam), rgb_mode=False, mono=False)
    developed = np.array([spectrum_to_linear_srgb(spectra[:, k]) for k in range(d.shape[1])])
    np.testing.assert_allclose(developed, ME.lookup(SKY, d.T), rtol=1e-3, atol=1e-6)


@pytest.mark.parametrize("rotation", [0.0, 30.0, [10.0, -20.0, 45.0]])
def test_map_coordinates_computed_once_give_the_same_radiance_and_pdf(rotation):
    """The integrator computes a missed ray's map coordinates once (``map_coordinates``) and passes them to
    ``emitted`` and ``pdf``: the same bits as each computing them, in a turned map too; a constant sky has none."""
    from engine.render.lights import EnvironmentEmitter
    from engine.spectral import GRID_NM, ConstantSpectrum, WavelengthLookup
    env = EnvironmentMapEmitter(SKY, strength=1.7, rotation_deg=rotation, interpolation_space="srgb")
    d = random_directions(500, seed=4)
    uv = env.map_coordinates(d)
    lk = WavelengthLookup(np.repeat(np.asarray(GRID_NM[::7], float)[:, None], d.shape[1], axis=1))
    for mode in ((True, False), (False, True), (False, False)):
        assert np.array_equal(env.emitted(d, lk, *mode, uv=uv), env.emitted(d, lk, *mode))
    assert np.array_equal(env.pdf(d, uv=uv), env.pdf(d))
    swapped = (uv[0][::-1], uv[1][::-1])        # (the coordinates given are the ones read)
    assert not np.array_equal(env.pdf(d, uv=swapped), env.pdf(d))
    assert not np.array_equal(env.emitted(d, lk, True, False, uv=swapped), env.emitted(d, lk, True, False))
    assert EnvironmentEmitter(ConstantSpectrum(1.0)).map_coordinates(d) is None


def test_cycles_grid_puts_rows_at_texel_centres():
    img = np.random.default_rng(3).uniform(0.1, 2.0, size=(6, 10, 3))
    env = EnvironmentMapEmitter(img, grid="cycles")
    u = (np.arange(10) + 0.5) / 10
    v = (np.arange(6) + 0.5) / 6
    d = ME.uv_to_direction(u[None, :], v[:, None]).reshape(-1, 3).T
    np.testing.assert_allclose(env.lookup_rgb(d), img.reshape(-1, 3), rtol=1e-12)
    # within half a texel of the poles: the first / last row (clamped), interpolated in u only
    pole = ME.uv_to_direction(u, np.full(10, 0.25 / 6)).T
    np.testing.assert_allclose(env.lookup_rgb(pole), img[0], rtol=1e-12)


# --------------------------------------------------------------------------- sampling

def _cell_grid(env, split_v=3, split_u=2):
    """Edges (cos θ, φ in the map frame) that refine the emitter's bilinear pieces, on which its pdf
    is constant: cos edges descending from +1 to −1, φ edges ascending over [−π, π)."""
    W = env.texels.shape[1]
    cos_k = np.cos(math.pi * env.v_knots)
    cos_edges = np.concatenate([np.linspace(a, b, split_v + 1)[:-1] for a, b in zip(cos_k[:-1], cos_k[1:])]
                               + [[-1.0]])
    # u edges at (i + ½)/W, i.e. φ = π(1 − (2i + 1)/W); subdivide, then wrap into [−π, π)
    u_edges = (np.arange(W * split_u + 1) / split_u + 0.5) / W
    phi_edges = np.sort(np.mod(math.pi * (1.0 - 2.0 * u_edges) + math.pi, 2 * math.pi) - math.pi)
    phi_edges = np.unique(np.concatenate(([-math.pi], phi_edges, [math.pi])))
    return cos_edges, phi_edges


def _cell_masses(env, cos_edges, phi_edges, rotation_deg):
    """∫ pdf dω over every (cos θ, φ) cell of the map frame, by 2×2 Gauss points per cell."""
    g = np.array([0.5 - 0.5 / math.sqrt(3), 0.5 + 0.5 / math.sqrt(3)])
    c = cos_edges[:-1, None] + np.diff(cos_edges)[:, None] * g[None, :]          # (nc, 2)
    p = phi_edges[:-1, None] + np.diff(phi_edges)[:, None] * g[None, :]          # (np, 2)
    C = c[:, None, :, None]
    P = p[None, :, None, :]
    C, P = np.broadcast_arrays(C, P)
    s = np.sqrt(1 - C ** 2)
    d_map = np.stack((s * np.cos(P), s * np.sin(P), C)).reshape(3, -1)
    values = env.pdf(rot_z(rotation_deg) @ d_map).reshape(C.shape).mean(axis=(2, 3))
    area = np.abs(np.diff(cos_edges))[:, None] * np.diff(phi_edges)[None, :]
    return values * area


def _histogram(d_map, cos_edges, phi_edges):
    ic = np.clip(np.searchsorted(-cos_edges, -d_map[2], side="right") - 1, 0, cos_edges.size - 2)
    ip = np.clip(np.searchsorted(phi_edges, np.arctan2(d_map[1], d_map[0]), side="right") - 1, 0,
                 phi_edges.size - 2)
    return np.bincount(ic * (phi_edges.size - 1) + ip,
                       minlength=(cos_edges.size - 1) * (phi_edges.size - 1)).astype(float)


def _test_map():
    img = np.random.default_rng(7).uniform(0.0, 1.0, size=(7, 12, 3)) ** 3
    img[2, 4] = (40.0, 30.0, 20.0)          # a sun
    img[5:, 6:9] = 0.0                      # a black region (cells with pdf 0 must get no samples)
    return img


@pytest.mark.parametrize("grid,rotation", [("mitsuba", 0.0), ("cycles", 0.0), ("mitsuba", 37.0)])
def test_sampling_follows_the_pdf_chi_square(grid, rotation):
    env = EnvironmentMapEmitter(_test_map(), rotation_deg=rotation, grid=grid)
    n = 200_000
    u = np.random.default_rng(11).uniform(size=(3, n))
    wi, dist, factor, pdf, ok = env.sample(np.zeros((3, n)), u)
    assert ok.all() and np.isinf(dist).all()
    np.testing.assert_allclose(np.linalg.norm(wi, axis=0), 1.0, rtol=1e-12)
    # the returned pdf is the pdf of the returned direction (up to samples on cell boundaries)
    assert np.mean(np.isclose(env.pdf(wi), pdf, rtol=1e-9)) > 0.999
    np.testing.assert_allclose(factor * pdf, 1.0, rtol=1e-12)
    cos_edges, phi_edges = _cell_grid(env)
    mass = _cell_masses(env, cos_edges, phi_edges, rotation)
    counts = _histogram(rot_z(-rotation) @ wi, cos_edges, phi_edges)
    assert_accepted(pearson(*_with_elsewhere(counts, mass, n, 1e-9)), test_count=3, what="envmap samples")


def test_sampling_prefers_the_bright_texels():
    env = EnvironmentMapEmitter(SKY, grid="mitsuba")
    wi = env.sample(np.zeros((3, 100_000)), np.random.default_rng(2).uniform(size=(3, 100_000)))[0]
    in_sun = wi.T @ ME.sun_direction() > math.cos(math.radians(4.5))
    # the sun's cone is 0.15% of the sphere; it carries 29% of the luminance × solid angle
    assert in_sun.mean() > 100 * (1 - math.cos(math.radians(4.5))) / 2


@pytest.mark.parametrize("grid", ["mitsuba", "cycles"])
def test_pdf_integrates_to_one(grid):
    for img in (_test_map(), SKY):
        env = EnvironmentMapEmitter(img, rotation_deg=20.0, grid=grid)
        cos_edges, phi_edges = _cell_grid(env, 1, 1)
        assert _cell_masses(env, cos_edges, phi_edges, 20.0).sum() == pytest.approx(1.0, abs=1e-12)
    # an independent midpoint rule on a uniform (cos θ, φ) grid, blind to the cells
    nc, nphi = 1200, 2400
    c = -1 + (np.arange(nc) + 0.5) * 2 / nc
    p = (np.arange(nphi) + 0.5) * 2 * math.pi / nphi
    C, P = np.meshgrid(c, p, indexing="ij")
    s = np.sqrt(1 - C ** 2)
    d = np.stack((s * np.cos(P), s * np.sin(P), C)).reshape(3, -1)
    env = EnvironmentMapEmitter(SKY, grid=grid)
    assert env.pdf(d).sum() * (2 / nc) * (2 * math.pi / nphi) == pytest.approx(1.0, abs=2e-3)


@pytest.mark.parametrize("grid", ["mitsuba", "cycles"])
def test_constant_map_is_the_constant_environment(grid):
    """A constant map × strength: that radiance everywhere, the uniform-sphere pdf, and the same
    mean colour and power (light selection) as EnvironmentEmitter of that radiance."""
    from engine.render.lights import EnvironmentEmitter
    from engine.spectral import RGBIlluminantSpectrum
    env = EnvironmentMapEmitter(np.full((5, 9, 3), 2.0, np.float32), strength=1.5, grid=grid)
    d = random_directions(500)
    np.testing.assert_allclose(env.lookup_rgb(d), 3.0, rtol=1e-12)
    np.testing.assert_allclose(env.pdf(d), 1 / (4 * math.pi), rtol=1e-12)
    np.testing.assert_allclose(env.rgb(), 3.0, rtol=1e-12)
    const = EnvironmentEmitter(RGBIlluminantSpectrum([1, 1, 1], 3.0))
    assert env.power(2.0) == pytest.approx(const.power(2.0), rel=1e-3)    # D65 table vs sRGB white: 2.5e-4


def test_black_map_samples_uniformly():
    env = EnvironmentMapEmitter(np.zeros((4, 8, 3)))
    np.testing.assert_allclose(env.pdf(random_directions(1000)), 1 / (4 * math.pi), rtol=1e-12)


# --------------------------------------------------------------------------- rotation

@pytest.mark.parametrize("rotation", [90.0, -45.0, 200.0])
def test_rotation_turns_the_bright_texel_about_up(rotation):
    img = np.full((9, 16, 3), 0.01)
    img[3, 5] = 100.0
    d0 = ME.texel_directions(16, 9)[3, 5]
    env = EnvironmentMapEmitter(img, rotation_deg=rotation, grid="mitsuba")
    d_rot = rot_z(rotation) @ d0     # counter-clockwise seen from +Z: azimuth φ → φ + rotation
    np.testing.assert_allclose(env.lookup_rgb(d_rot[:, None])[0], 100.0, rtol=1e-9)
    assert env.lookup_rgb(d0[:, None])[0, 0] < 1.0
    wi = env.sample(np.zeros((3, 20000)), np.random.default_rng(5).uniform(size=(3, 20000)))[0]
    mean = wi.mean(axis=1)
    assert mean @ d_rot / np.linalg.norm(mean) > 0.99
    azimuth = math.degrees(math.atan2(mean[1], mean[0]) - math.atan2(d0[1], d0[0]))
    assert np.mod(azimuth - rotation + 180, 360) - 180 == pytest.approx(0.0, abs=1.0)


# --------------------------------------------------------------------------- scene format and renders

def test_scene_format_environment_map(tmp_path):
    ME.write_exr(str(tmp_path / "m.exr"), np.full((4, 8, 3), 2.0, np.float32))
    light = parse_light({"type": "environment", "image": "m.exr", "strength": 1.5, "rotation_deg": 30},
                        "lights[0]", str(tmp_path))
    assert isinstance(light, EnvironmentLight) and light.grid == "cycles"
    assert light.image.shape == (4, 8, 3) and light.strength == 1.5 and light.rotation_deg == 30
    bad = [({"strength": -1}, "strength"), ({"strength": 1e30}, "strength"), ({"grid": "blender"}, "grid"),
           ({"rotation_deg": "x"}, "rotation_deg"), ({"radiance": 2}, "radiance"),
           ({"image": "missing.exr"}, "image")]
    for extra, name in bad:
        with pytest.raises(SceneError, match=name):
            parse_light({"type": "environment", "image": "m.exr", **extra}, "lights[0]", str(tmp_path))


def _spheres(res, spp, **settings):
    scene = load_scene(shared_path("peers", "scenes", "envmap_spheres.json"))
    scene.camera.width = scene.camera.height = res
    scene.settings = dataclasses.replace(scene.settings, spp=spp, **settings)
    return scene


def test_constant_map_renders_as_the_constant_environment():
    """A map of 1.0 everywhere gives the image of the constant environment light of radiance 1
    (sampled differently: equal within noise)."""
    from engine.spectral import RGBIlluminantSpectrum
    a = _spheres(24, 32, max_depth=4)
    a.lights = [EnvironmentLight(RGBIlluminantSpectrum([1, 1, 1]), image=np.ones((8, 16, 3)), grid="mitsuba")]
    b = _spheres(24, 32, max_depth=4, seed=123)
    b.lights = [EnvironmentLight(RGBIlluminantSpectrum([1, 1, 1]))]
    ya = Renderer(a).render().stokes_luminance()[0]
    yb = Renderer(b).render().stokes_luminance()[0]
    assert np.isfinite(ya).all()
    # 4×4 blocks of 6×6 pixels: their means agree within noise
    ba = ya.reshape(4, 6, 4, 6).mean(axis=(1, 3))
    bb = yb.reshape(4, 6, 4, 6).mean(axis=(1, 3))
    assert np.abs(ba / bb - 1).max() < 0.05
    assert ya.mean() == pytest.approx(yb.mean(), rel=0.01)


@pytest.mark.parametrize("settings", [{}, {"reduce_spectral": False}, {"spectral": "mono"}],
                         ids=["rgb", "spectral", "mono"])
def test_envmap_spheres_loads_and_renders_finite(settings):
    scene = _spheres(24, 2, **settings)
    (light,) = scene.lights
    assert light.grid == "mitsuba" and light.image.shape == (256, 512, 3)
    result = Renderer(scene).render()
    y = result.stokes_luminance()
    assert np.isfinite(y).all() and result.stats["nonfinite"] == 0
    assert y[0].mean() > 0.1


def test_peer_envmap_light_mapping():
    from engine.scene.peer_format import peer_to_engine
    base = {"camera": {}, "materials": {}, "objects": [], "integrator": {}}
    out = peer_to_engine({**base, "light": {"type": "envmap", "file": "../envmaps/x.exr", "scale": 2.5}})
    assert out["lights"] == [{"type": "environment", "image": "../envmaps/x.exr", "strength": 2.5, "grid": "mitsuba"}]
    with pytest.raises(SceneError, match="light.file"):
        peer_to_engine({**base, "light": {"type": "envmap"}})
