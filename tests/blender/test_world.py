"""Blender worlds: Environment Texture worlds mapped directly (with a Mapping node's rotation),
every other world baked by Cycles into an equirectangular map, and both against Cycles.

Oracles: Cycles itself.  A world baked with point samples at the texel centres (1 sample, a box
filter of 0.01 px) is Cycles' radiance in those directions, so the direct mapping's lookup must
reproduce it to float precision (except within one texel of the map's poles, where Cycles wraps
rows periodically and the engine holds the first/last row).  Renders of diffuse scenes must
agree with Cycles per region within 4 standard errors + 2 % (tests/blender/test_cycles_parity_lights.py's
method).  The engine's Euler rotation is checked against its own scalar form and against a
rotation matrix built here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.render.lights import EnvironmentMapEmitter
from engine.scene.loader import parse_light

REC709 = np.array([0.2126, 0.7152, 0.0722])


def _test_map(h=16, w=32, seed=3):
    rng = np.random.default_rng(seed)
    img = 0.2 + rng.random((h, w, 3))
    img[3, 7] = 40.0                                   # one bright texel
    return img


def _texel_directions(w, h):
    """Unit directions (3, h·w) of the texel centres of a w×h map on Cycles' grid (row 0 = zenith)."""
    j, i = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    phi = math.pi * (1.0 - 2.0 * (i + 0.5) / w)
    theta = math.pi * (j + 0.5) / h
    return np.stack((np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta))).reshape(3, -1)


def _euler(x, y, z):
    """Blender's Euler XYZ matrix (Rz·Ry·Rx), degrees, written out independently of the engine."""
    a, b, c = (math.radians(t) for t in (x, y, z))
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]])
    return rz @ ry @ rx


# --------------------------------------------------------------------------- engine: Euler rotation

def test_euler_about_z_only_is_the_scalar_rotation_bit_for_bit():
    img = _test_map()
    a = EnvironmentMapEmitter(img, rotation_deg=37.0)
    b = EnvironmentMapEmitter(img, rotation_deg=[0.0, 0.0, 37.0])
    d = np.random.default_rng(2).normal(size=(3, 500))
    assert np.array_equal(a.lookup_rgb(d), b.lookup_rgb(d))
    u = np.random.default_rng(4).random((3, 500))
    p = np.zeros((3, 500))
    for x, y in zip(a.sample(p, u), b.sample(p, u)):
        assert np.array_equal(x, y)


def test_euler_rotation_turns_the_map_by_r():
    img = _test_map()
    angles = (25.0, -40.0, 110.0)
    plain = EnvironmentMapEmitter(img)
    turned = EnvironmentMapEmitter(img, rotation_deg=list(angles))
    R = _euler(*angles)
    d = np.random.default_rng(5).normal(size=(3, 2000))
    d /= np.linalg.norm(d, axis=0)
    # the feature seen along d without rotation is seen along R·d with it
    np.testing.assert_allclose(turned.lookup_rgb(R @ d), plain.lookup_rgb(d), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(turned.pdf(R @ d), plain.pdf(d), rtol=1e-10)
    # sampling: the same random numbers give the unrotated sample turned by R, with the pdf of
    # the direction produced
    u = np.random.default_rng(6).random((3, 4000))
    p = np.zeros((3, 4000))
    wi, _, _, pdf, valid = turned.sample(p, u)
    wi0, _, _, pdf0, _ = plain.sample(p, u)
    assert valid.all()
    np.testing.assert_allclose(R.T @ wi, wi0, atol=1e-12)
    np.testing.assert_allclose(pdf, pdf0, rtol=1e-12)
    np.testing.assert_allclose(turned.pdf(wi), pdf, rtol=1e-9)


def test_scene_format_accepts_euler_rotation(tmp_path):
    import OpenEXR
    header = {"compression": OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}
    rgb = np.full((4, 8, 3), 2.0, np.float32)
    with OpenEXR.File(header, {"RGB": rgb}) as f:
        f.write(str(tmp_path / "m.exr"))
    light = parse_light({"type": "environment", "image": "m.exr", "rotation_deg": [10, 20, 30]}, "lights[0]",
                        str(tmp_path))
    assert light.rotation_deg == [10, 20, 30]
    for bad in ([1, 2], [0, "x", 0], [0, 0, 400]):
        with pytest.raises(SceneError, match="rotation_deg"):
            parse_light({"type": "environment", "image": "m.exr", "rotation_deg": bad}, "lights[0]", str(tmp_path))


# --------------------------------------------------------------------------- Blender worlds

MAP_W, MAP_H = 64, 32


def _hdri_pixels():
    """A 64×32 map with distinct regions (linear RGB, row 0 = zenith): a warm bright patch, a blue
    band, a green quadrant; the first and last rows constant (equal), so that Cycles' periodic
    wrap at the poles and the engine's held rows agree."""
    img = np.full((MAP_H, MAP_W, 3), 0.3)
    img[6:12, 10:18] = (6.0, 3.0, 1.0)
    img[14:18, :] = (0.1, 0.2, 1.5)
    img[18:28, 36:60] = (0.2, 1.2, 0.3)
    img[0] = img[-1] = 0.3
    return img


@pytest.fixture(scope="module")
def blender():
    bpy = pytest.importorskip("bpy")
    from tests.blender_support import load_addon
    addon = load_addon()
    return bpy, addon.polar_addon.export


def _image(bpy, name, texels, float_buffer=True, colorspace=None):
    h, w = texels.shape[:2]
    img = bpy.data.images.new(name, w, h, float_buffer=float_buffer, alpha=True)
    if colorspace:
        img.colorspace_settings.name = colorspace
    px = np.ones((h, w, 4), np.float32)
    px[..., :3] = texels[::-1]                       # Blender's pixel rows start at the bottom
    img.pixels.foreach_set(px.ravel())
    return img


def _hdri_world(bpy, image, rotation_deg=(0.0, 0.0, 0.0), vector_type="POINT", location=(0.0, 0.0, 0.0),
                strength=1.0, coordinates="Generated"):
    world = bpy.data.worlds.new("HDRI")
    bpy.context.scene.world = world
    nt = world.node_tree
    bg = nt.nodes["Background"]
    bg.inputs["Strength"].default_value = strength
    env = nt.nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    coords = nt.nodes.new("ShaderNodeTexCoord")
    mapping = nt.nodes.new("ShaderNodeMapping")
    mapping.vector_type = vector_type
    mapping.inputs["Rotation"].default_value = [math.radians(a) for a in rotation_deg]
    if vector_type in ("POINT", "TEXTURE"):
        mapping.inputs["Location"].default_value = location
    nt.links.new(coords.outputs[coordinates], mapping.inputs["Vector"])
    nt.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    nt.links.new(env.outputs["Color"], bg.inputs["Color"])
    return world


def _sky_world(bpy, sky_type="HOSEK_WILKIE"):
    world = bpy.data.worlds.new("Sky")
    bpy.context.scene.world = world
    nt = world.node_tree
    sky = nt.nodes.new("ShaderNodeTexSky")
    sky.sky_type = sky_type
    nt.links.new(sky.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    return world, sky


def _emitter(light):
    return EnvironmentMapEmitter(light.image, light.strength, light.rotation_deg, light.grid)


def _away_from_map_poles(rotation_deg, vector_type, w, h):
    """Texels (of a w×h bake) whose direction is more than 1.5 map texels from the map's poles."""
    R = _euler(*rotation_deg)
    look = R if vector_type != "TEXTURE" else R.T     # the Mapping node looks the map up at look·d
    z = (look @ _texel_directions(w, h))[2]
    return np.abs(z) < math.cos(1.5 * math.pi / MAP_H)


@pytest.mark.parametrize("vector_type,coordinates", [("POINT", "Generated"), ("TEXTURE", "Object"),
                                                     ("NORMAL", "Generated")])
def test_rotated_environment_texture_maps_directly_as_cycles_sees_it(blender, vector_type, coordinates):
    bpy, export = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    rotation = (20.0, -35.0, 70.0)
    world = _hdri_world(bpy, _image(bpy, "hdri", _hdri_pixels()), rotation, vector_type, strength=1.5,
                        coordinates=coordinates)
    warnings = []
    light = export.world.export_world(world, warnings)
    assert warnings == [] and light.image is not None and light.grid == "cycles" and light.strength == 1.5
    assert np.array_equal(light.image, _hdri_pixels().astype(np.float32))
    w, h = 128, 64
    baked = export.world_bake.bake_world(world, (w, h), samples=1, filter_width=0.01).reshape(-1, 3)
    direct = _emitter(light).lookup_rgb(_texel_directions(w, h))
    keep = _away_from_map_poles(rotation, vector_type, w, h)
    # the 0.01 px filter still jitters Cycles' sample by ±0.005 px: at the patch edges (steps of
    # up to 5.7 per map texel) that moves a value by up to ~0.015
    np.testing.assert_allclose(direct[keep], baked[keep], rtol=2e-3, atol=0.02)
    assert np.median(np.abs(direct[keep] - baked[keep])) < 1e-5


def test_8bit_srgb_image_is_decoded_as_cycles_does(blender):
    bpy, export = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    levels = np.linspace(0.05, 0.95, MAP_W)[None, :, None] * np.ones((MAP_H, 1, 3))
    levels[0] = levels[-1] = 0.5
    image = _image(bpy, "ldr", levels, float_buffer=False, colorspace="sRGB")
    world = _hdri_world(bpy, image)
    light = export.world.export_world(world, [])
    w, h = 64, 32
    baked = export.world_bake.bake_world(world, (w, h), samples=1, filter_width=0.01).reshape(-1, 3)
    direct = _emitter(light).lookup_rgb(_texel_directions(w, h))
    keep = _away_from_map_poles((0.0, 0.0, 0.0), "POINT", w, h)
    np.testing.assert_allclose(direct[keep], baked[keep], rtol=2e-3, atol=1e-4)


def test_missing_image_warns_with_its_name_and_renders_magenta(blender, tmp_path):
    bpy, export = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    image = bpy.data.images.new("gone", 8, 4, float_buffer=True)
    image.source = "FILE"
    image.filepath = str(tmp_path / "no_such_sky.exr")
    world = _hdri_world(bpy, image, strength=2.0)
    warnings = []
    light = export.world.export_world(world, warnings)
    assert len(warnings) == 1 and "no_such_sky.exr" in warnings[0]
    assert light.image is None                          # Cycles' missing-texture magenta × strength
    assert np.allclose(light.radiance.rgb, (1.0, 0.0, 1.0)) and light.radiance.scale == 2.0


def test_unsupported_mapping_is_baked_not_flattened(blender):
    bpy, export = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    world = _hdri_world(bpy, _image(bpy, "hdri", _hdri_pixels()), location=(0.3, 0.0, 0.0))
    bpy.context.scene.polar.world_bake_resolution = 64
    before = export.world_bake.bake_count
    warnings = []
    light = export.world.export_world(world, warnings)
    assert export.world_bake.bake_count == before + 1
    assert len(warnings) == 1 and "Environment Texture" in warnings[0] and "Mapping" in warnings[0]
    assert light.image.shape == (32, 64, 3) and light.strength == 1.0
    assert np.ptp(light.image[..., 2]) > 1.0           # the blue band is there: not a flat colour


def test_bake_is_cached_while_the_world_is_unchanged(blender):
    bpy, export = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.context.scene.polar.world_bake_resolution = 64
    world, sky = _sky_world(bpy)
    bake = export.world_bake
    before = bake.bake_count
    first = export.world.export_world(world, [])
    second = export.world.export_world(world, [])
    assert bake.bake_count == before + 1                                # the second export did not bake
    assert second.image is first.image
    sky.turbidity = sky.turbidity + 1.0
    third = export.world.export_world(world, [])
    assert bake.bake_count == before + 2 and not np.array_equal(third.image, first.image)
    bpy.context.scene.polar.world_bake_resolution = 32                  # the resolution is part of the key
    assert export.world.export_world(world, []).image.shape == (16, 32, 3) and bake.bake_count == before + 3


def test_baking_leaves_nothing_behind(blender):
    bpy, export = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    world, sky = _sky_world(bpy)
    sky.sun_elevation = 0.7                                              # a value not baked before
    collections = ("scenes", "objects", "cameras", "images", "worlds", "node_groups", "meshes", "materials",
                   "libraries", "texts")

    def counts():
        return {c: len(getattr(bpy.data, c)) for c in collections}

    before = counts()
    scene_before = (bpy.context.scene.name, bpy.context.scene.camera, bpy.context.scene.render.engine)
    before_bakes = export.world_bake.bake_count
    export.world_bake.bake_world(world, (32, 16))
    assert export.world_bake.bake_count == before_bakes + 1
    assert counts() == before
    assert (bpy.context.scene.name, bpy.context.scene.camera, bpy.context.scene.render.engine) == scene_before
    assert world.users == 1 and not world.use_fake_user


# --------------------------------------------------------------------------- parity renders with Cycles

def _parity_scene(bpy):
    """A white diffuse floor and sphere, the camera looking slightly down so that the upper third of
    the frame is sky."""
    from tests.blender.test_cycles_parity_lights import diffuse
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 48, 36
    scene.render.resolution_percentage = 100
    grey = diffuse("Grey")
    bpy.ops.mesh.primitive_plane_add(size=8, location=(0, 0, 0))
    bpy.context.object.data.materials.append(grey)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.8, location=(0.0, 0.0, 0.8), segments=32, ring_count=16)
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(grey)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = 24
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (0.0, -5.0, 1.6), (math.radians(82), 0.0, 0.0)
    scene.camera = cam
    return scene


def _compare(bpy, scene, tmp_path):
    from tests.blender.test_cycles_parity_lights import cycles_renders, polar_renders, region_stats
    mp, sp = region_stats(polar_renders(scene))
    mc, sc = region_stats(cycles_renders(scene, str(tmp_path)))
    lit = mc > 0.02 * mc.max()
    ratio = mp[lit] / mc[lit]
    se = ratio * np.sqrt((sp[lit] / mp[lit]) ** 2 + (sc[lit] / mc[lit]) ** 2)
    return lit, ratio, se


def test_hdri_world_with_rotated_mapping_agrees_with_cycles(blender, tmp_path):
    bpy, export = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = _parity_scene(bpy)
    _hdri_world(bpy, _image(bpy, "hdri", _hdri_pixels()), (15.0, -20.0, 130.0), strength=1.2)
    lit, ratio, se = _compare(bpy, scene, tmp_path)
    assert lit.sum() >= 10
    bad = np.abs(ratio - 1.0) > 4.0 * se + 0.02
    assert not bad.any(), f"Polar/Cycles per region {np.round(ratio, 4).tolist()} ± {np.round(se, 4).tolist()}"


@pytest.mark.parametrize("sky_type", ["HOSEK_WILKIE", "MULTIPLE_SCATTERING"])
def test_sky_texture_world_agrees_with_cycles(blender, tmp_path, sky_type):
    bpy, export = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = _parity_scene(bpy)
    scene.polar.world_bake_resolution = 512
    world, sky = _sky_world(bpy, sky_type)
    if sky_type == "HOSEK_WILKIE":        # a smooth sky (no sun disc)
        sky.sun_direction = (0.4, -0.6, 0.7)
        strength = 3.0
    else:                                 # with its sun disc: enough samples for the disc's power
        scene.polar.world_bake_samples = 128
        sky.sun_elevation, sky.sun_rotation = math.radians(35), math.radians(60)
        strength = 0.05
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = strength
    lit, ratio, se = _compare(bpy, scene, tmp_path)
    assert lit.sum() >= 10
    bad = np.abs(ratio - 1.0) > 4.0 * se + 0.02
    assert not bad.any(), f"Polar/Cycles per region {np.round(ratio, 4).tolist()} ± {np.round(se, 4).tolist()}"
