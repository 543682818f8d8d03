"""A small bright sun in an equirectangular map: the radiance between its texels and the light it
sends to a diffuse plane.

Cycles interpolates images in the sRGB colour space on their encoded values and decodes the
result (scene/image.cpp ``compress_as_srgb``; 8-bit images and float files alike), so a sun of a
few texels in such an image carries ~20–50 % less ∫L dω than with linear interpolation.  Oracles:
the lookup written out here from Cycles' formulas, a Gauss–Legendre quadrature of the irradiance
of an upward plane (E = ∫ L cosθ dω), and Cycles itself (a bake of the world's radiance at many
directions, and a render of a plane)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.render.lights import EnvironmentMapEmitter
from engine.render.renderer import Renderer
from engine.scene.description import EnvironmentLight
from engine.scene.loader import load_scene
from engine.spectral import RGBIlluminantSpectrum, luminance

H, W = 16, 32


def _sun_map(sun=300.0):
    """Linear radiance (H, W, 3), row 0 = zenith: a dim sky and a sun of two texels side by side,
    37° above the horizon."""
    img = np.full((H, W, 3), 0.2)
    img[H // 2:] = (0.15, 0.1, 0.05)                  # ground
    img[5, 9:11] = sun
    return img


def _encode(x):
    """sRGB transfer function (IEC 61966-2-1), the power law continued above 1."""
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.maximum(x, 0.0031308) ** (1 / 2.4) - 0.055)


def _decode(c):
    """Its inverse, negative → 0 (Cycles' color_srgb_to_linear)."""
    return np.where(c < 0.04045, np.maximum(c, 0.0) / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4)


def cycles_lookup(img, u, v, space):
    """Radiance (N, 3) at map coordinates u (from +X, clockwise seen from above) and v (0 at the
    zenith) as Cycles' image lookup gives it: linear interpolation between texel centres, periodic
    in u, the first/last row held towards the poles; on encoded values for space "srgb"."""
    h, w = img.shape[:2]
    values = _encode(img) if space == "srgb" else img
    x = np.mod(u * w - 0.5, w)
    y = np.clip(v * h - 0.5, 0.0, h - 1.0)
    i0 = np.floor(x).astype(int) % w
    j0 = np.minimum(np.floor(y).astype(int), h - 2)
    fx, fy = (x - np.floor(x))[:, None], (y - j0)[:, None]
    i1 = (i0 + 1) % w
    out = ((values[j0, i0] * (1 - fx) + values[j0, i1] * fx) * (1 - fy)
           + (values[j0 + 1, i0] * (1 - fx) + values[j0 + 1, i1] * fx) * fy)
    return _decode(out) if space == "srgb" else out


def _uv(d):
    """Cycles' direction_to_equirectangular, v measured from the zenith (rows top down)."""
    return np.mod(0.5 - np.arctan2(d[1], d[0]) / (2 * math.pi), 1.0), np.arccos(np.clip(d[2], -1, 1)) / math.pi


def plane_irradiance(img, space, order=8):
    """E (3,) on an upward plane: ∫ L cosθ dω over the upper hemisphere, Gauss–Legendre on every
    piece between texel centres (where the lookup is smooth), in the map frame (a turn about +Z
    does not change it)."""
    h, w = img.shape[:2]
    g, gw = np.polynomial.legendre.leggauss(order)
    g, gw = 0.5 * (g + 1), 0.5 * gw
    v_edges = np.unique(np.concatenate(([0.0, 0.5], (np.arange(h) + 0.5) / h)))
    v_edges = v_edges[v_edges <= 0.5]
    u_edges = np.concatenate(([0.0], (np.arange(w) + 0.5) / w, [1.0]))
    v = (v_edges[:-1, None] + np.diff(v_edges)[:, None] * g).ravel()
    wv = (np.diff(v_edges)[:, None] * gw).ravel()
    u = (u_edges[:-1, None] + np.diff(u_edges)[:, None] * g).ravel()
    wu = (np.diff(u_edges)[:, None] * gw).ravel()
    V, U = np.meshgrid(v, u, indexing="ij")
    L = cycles_lookup(img, U.ravel(), V.ravel(), space).reshape(V.shape + (3,))
    theta = math.pi * V
    # dω = sinθ dθ dφ = π·2π sinθ du dv
    jac = (2 * math.pi ** 2) * np.sin(theta) * np.cos(theta)
    return np.einsum("ij,i,j,ijc->c", jac, wv, wu, L)


def _directions(n, seed):
    d = np.random.default_rng(seed).normal(size=(3, n))
    return d / np.linalg.norm(d, axis=0)


def _rot_z(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# --------------------------------------------------------------------------- the lookup

@pytest.mark.parametrize("space", ["linear", "srgb"])
@pytest.mark.parametrize("rotation", [0.0, 40.0])
def test_lookup_is_cycles_interpolation(space, rotation):
    img = _sun_map()
    env = EnvironmentMapEmitter(img, rotation_deg=rotation, grid="cycles", interpolation_space=space)
    d = _directions(20000, 4)
    d = d[:, np.abs(d[2]) < math.cos(math.pi / H)]                       # away from the held pole rows
    ref = cycles_lookup(img, *_uv(_rot_z(-rotation) @ d), space)
    np.testing.assert_allclose(env.lookup_rgb(d), ref, rtol=1e-9, atol=1e-12)


def test_srgb_space_keeps_texel_centres_and_narrows_the_sun():
    img = _sun_map()
    lin = EnvironmentMapEmitter(img, interpolation_space="linear")
    srgb = EnvironmentMapEmitter(img, interpolation_space="srgb")
    j, i = np.meshgrid(np.arange(1, H - 1), np.arange(W), indexing="ij")
    theta, phi = math.pi * (j + 0.5) / H, math.pi * (1 - 2 * (i + 0.5) / W)
    centres = np.stack((np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta))).reshape(3, -1)
    np.testing.assert_allclose(srgb.lookup_rgb(centres), img[1:-1].reshape(-1, 3), rtol=1e-12)
    # half-way between the sun (300) and the sky (0.2): the decoded mean of the encoded values
    # (~0.21·300), not the mean (~150)
    theta, phi = math.pi * 5.5 / H, math.pi * (1 - 2 * 11.0 / W)
    mid = np.array([[math.sin(theta) * math.cos(phi)], [math.sin(theta) * math.sin(phi)], [math.cos(theta)]])
    assert lin.lookup_rgb(mid)[0, 0] == pytest.approx(150.1, rel=1e-9)
    assert srgb.lookup_rgb(mid)[0, 0] == pytest.approx(_decode(0.5 * (_encode(300.0) + _encode(0.2))), rel=1e-9)
    assert srgb.lookup_rgb(mid)[0, 0] < 0.25 * 300


def test_srgb_space_is_linear_below_the_toe():
    """Below 0.0031308 the transfer function is linear: both spaces give the same radiance."""
    img = _sun_map() * (0.003 / 300.0)
    d = _directions(2000, 5)
    np.testing.assert_allclose(EnvironmentMapEmitter(img, interpolation_space="srgb").lookup_rgb(d),
                               EnvironmentMapEmitter(img).lookup_rgb(d), rtol=1e-9)


def test_interpolation_space_is_validated():
    with pytest.raises(SceneError, match="interpolation_space"):
        EnvironmentMapEmitter(_sun_map(), interpolation_space="gamma")


# --------------------------------------------------------------------------- the light on a plane

def _plane_scene(tmp_path, img, space, rotation, spp, seed=0):
    """A white Lambert plane facing +Z seen from above (direct light only), lit by the map."""
    data = {"format": "polar-scene/1",
            "camera": {"origin": [0, 0, 10], "target": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 10,
                       "width": 8, "height": 8},
            "materials": {"white": {"type": "lambert", "albedo": 1.0}},
            "objects": [{"shape": "quad", "material": "white",
                         "vertices": [[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]]}],
            "lights": [{"type": "environment", "radiance": 1.0}],
            "render": {"spp": spp, "max_depth": 2, "spectral": "mono", "seed": seed}}
    (tmp_path / "plane.json").write_text(json.dumps(data))
    scene = load_scene(str(tmp_path / "plane.json"))
    scene.lights = [EnvironmentLight(RGBIlluminantSpectrum([1, 1, 1]), image=img, rotation_deg=rotation,
                                     grid="cycles", interpolation_space=space)]
    return scene


def test_the_quadrature_sees_the_sun_edges():
    """The oracle is sensitive: the two interpolations differ by far more than the render noise."""
    img = _sun_map()
    lin, srgb = (float(luminance(plane_irradiance(img, s))) for s in ("linear", "srgb"))
    assert 0.4 < srgb / lin < 0.8          # most of a 2-texel sun lies on its interpolated edges
    # the sun alone: 2 texels × 300 × their solid angle × cosθ (the same for both interpolations
    # with the nearest texel, to within the rows' curvature)
    sun = plane_irradiance(img, "linear") - plane_irradiance(np.where(img > 1, 0.2, img), "linear")
    omega = (2 * math.pi / W) * (math.cos(math.pi * 5 / H) - math.cos(math.pi * 6 / H))
    assert sun[0] == pytest.approx(2 * 299.8 * omega * math.cos(math.pi * 5.5 / H), rel=0.02)


@pytest.mark.parametrize("space", ["linear", "srgb"])
def test_diffuse_plane_under_a_small_sun_matches_the_quadrature(tmp_path, space):
    """MIS of map sampling (piecewise-constant pdf) and BSDF sampling (the pdf evaluated at the
    escaped direction) is unbiased for either interpolation: radiance E/π within noise."""
    img = _sun_map()
    expected = float(luminance(plane_irradiance(img, space))) / math.pi
    y = Renderer(_plane_scene(tmp_path, img, space, 40.0, 2048)).render().stokes_luminance()[0]
    assert np.isfinite(y).all()
    se = y.std(ddof=1) / math.sqrt(y.size)
    assert abs(y.mean() - expected) < 4 * se + 2e-3 * expected, (y.mean(), expected, se)


# --------------------------------------------------------------------------- Blender / Cycles

@pytest.fixture(scope="module")
def blender():
    bpy = pytest.importorskip("bpy")
    from tests.blender_support import load_addon
    addon = load_addon()
    return bpy, addon.polar_addon.export


def _sun_world(bpy, path, float_file=True, colorspace=None, rotation_z=60.0):
    """World: Environment Texture of _sun_map() behind a Mapping rotation about Z.  float_file: an
    EXR written and loaded back (Blender tags it sRGB, stores it encoded); else a generated float
    image in ``colorspace``."""
    from tests.blender.test_world import _hdri_world, _image
    img = _sun_map()
    if float_file:
        image = _image(bpy, "sun_src", img)
        image.filepath_raw, image.file_format = path, "OPEN_EXR"
        image.save()
        bpy.data.images.remove(image)
        image = bpy.data.images.load(path)
    else:
        image = _image(bpy, "sun", img, colorspace=colorspace)
    return _hdri_world(bpy, image, (0.0, 0.0, rotation_z))


@pytest.mark.parametrize("source,space", [("file", "srgb"), ("generated sRGB", "linear"),
                                          ("generated Linear Rec.709", "linear")])
def test_exported_interpolation_space_is_the_one_cycles_uses(blender, tmp_path, source, space):
    """Cycles' radiance (a bake at 4× the map's resolution) is the direct lookup of the export."""
    bpy, export = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    colorspace = None if source == "file" else source.split(" ", 1)[1]
    world = _sun_world(bpy, str(tmp_path / "sun.exr"), source == "file", colorspace)
    light = export.world.export_world(world, [])
    assert light.interpolation_space == space
    if source == "file":
        assert world.node_tree.nodes["Environment Texture"].image.colorspace_settings.name == "sRGB"
    np.testing.assert_allclose(light.image, _sun_map(), rtol=1e-4)
    w, h = 4 * W, 4 * H
    baked = export.world_bake.bake_world(world, (w, h), samples=1, filter_width=0.01)
    from tests.blender.test_world import _texel_directions
    env = EnvironmentMapEmitter(light.image, light.strength, light.rotation_deg, light.grid,
                                interpolation_space=light.interpolation_space)
    direct = env.lookup_rgb(_texel_directions(w, h))
    keep = np.abs(_texel_directions(w, h)[2]) < math.cos(1.5 * math.pi / H)
    # the 0.01 px filter jitters Cycles' sample: at the sun's edges (~300 per map texel) that
    # moves a value by up to ~0.3
    near = np.abs(direct[keep] - baked.reshape(-1, 3)[keep])
    assert np.median(near) < 1e-4 and near.max() < 1.0, near.max()
    sun_edge = keep & (direct[:, 0] > 5) & (direct[:, 0] < 250)
    np.testing.assert_allclose(direct[sun_edge], baked.reshape(-1, 3)[sun_edge], rtol=0.02)


def test_plane_under_an_srgb_exr_sun_agrees_with_cycles(blender, tmp_path):
    """The reported bias (Polar ~9 % brighter on sunlit diffuse surfaces): an upward diffuse plane
    under the sun of an sRGB-tagged EXR, Cycles vs Polar, means within noise."""
    bpy, export = blender
    from tests.blender.test_cycles_parity_lights import diffuse
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.render.resolution_percentage = 100
    _sun_world(bpy, str(tmp_path / "sun.exr"))
    bpy.ops.mesh.primitive_plane_add(size=10)
    bpy.context.object.data.materials.append(diffuse("White", (1.0, 1.0, 1.0)))
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.type, cam.data.ortho_scale = "ORTHO", 2.0
    scene.collection.objects.link(cam)
    cam.location = (0.0, 0.0, 5.0)
    scene.camera = cam
    c = scene.cycles
    scene.render.engine = "CYCLES"
    c.device, c.samples, c.use_adaptive_sampling, c.use_denoising = "CPU", 512, False, False
    c.pixel_filter_type, c.filter_width = "BOX", 1.0
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    from tests.blender_support import read_multilayer
    scene.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = str(tmp_path / "cycles")
    bpy.ops.render.render(write_still=True)
    lum = np.array([0.2126, 0.7152, 0.0722])
    cy = read_multilayer(scene.render.filepath + ".exr")["Combined"][..., :3] @ lum
    from polar_render.engine.render.renderer import Renderer as AddonRenderer
    from polar_render.engine.scene.description import RenderSettings
    from polar_render.polar_addon.export.scene import export_scene
    settings = RenderSettings(spp=512, max_depth=2, seed=1, spectral="mono")
    engine_scene, _ = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 8, 8, settings)
    po = AddonRenderer(engine_scene).render(settings).stokes_luminance()[0]
    expected = float(luminance(plane_irradiance(_sun_map(), "srgb"))) / math.pi
    se = math.hypot(cy.std(ddof=1), po.std(ddof=1)) / math.sqrt(cy.size)
    assert abs(cy.mean() - expected) < 4 * se + 3e-3 * expected, (cy.mean(), expected)   # the oracle is Cycles'
    assert abs(po.mean() / cy.mean() - 1) < 4 * se / cy.mean() + 5e-3, (po.mean(), cy.mean(), se)
