"""Polarised lights and emission in Blender (issue 35): the Light and Material settings are saved in .blend
files, exported in the source's own frame (the light's local X; a mesh's UV U direction or its local X), and
F12 renders them — a rotated screen rotates its polarisation."""

import math
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import add_camera, empty_scene, load_addon, read_multilayer, render_to_exr  # noqa: E402


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def _screen_scene(rotation_z=0.0, angle_deg=0.0, polarisation="LINEAR", uv=False):
    """A camera looking down −Z at an emissive plane (black Lambert + Emission), rotated about Z."""
    scene = empty_scene(16, 16, samples=2)
    add_camera(scene, (0, 0, 5), (0, 0, 0), lens=50)
    bpy.ops.mesh.primitive_plane_add(size=8, location=(0, 0, 0), rotation=(0, 0, rotation_z))
    plane = bpy.context.object
    if not uv:
        while plane.data.uv_layers:
            plane.data.uv_layers.remove(plane.data.uv_layers[0])
    mat = bpy.data.materials.new("Screen")
    load_addon().polar_addon.compat.ensure_node_tree(mat)
    tree = mat.node_tree
    em = tree.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = 1.0
    tree.links.new(em.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    mat.polar.polarisation, mat.polar.degree, mat.polar.angle = polarisation, 1.0, math.radians(angle_deg)
    plane.data.materials.append(mat)
    bpy.context.view_layer.update()
    return scene, plane, mat


def _export(scene):
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    return export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 16, 16, engine_settings(scene))


def test_emission_polarisation_is_exported_in_the_objects_frame(addon):
    scene, plane, _ = _screen_scene(rotation_z=math.radians(30), angle_deg=20)
    engine_scene, _ = _export(scene)
    mesh = next(m for m in engine_scene.meshes if m.emission is not None)
    assert mesh.emission_polarisation.kind == "linear" and mesh.emission_polarisation.angle_deg == pytest.approx(20)
    np.testing.assert_allclose(mesh.emission_axis, [math.cos(math.radians(30)), math.sin(math.radians(30)), 0],
                               atol=1e-6)


@pytest.mark.parametrize("rotation, angle", [(0.0, 0.0), (30.0, 0.0), (30.0, 15.0), (0.0, 90.0)])
def test_a_rotated_screen_rotates_its_polarisation_in_the_render(addon, tmp_path, rotation, angle):
    """Seen straight on (camera x = +X, y = +Y), the AoLP is the object's rotation plus the angle."""
    scene, _, _ = _screen_scene(rotation_z=math.radians(rotation), angle_deg=angle)
    passes = read_multilayer(render_to_exr(scene, os.path.join(tmp_path, "screen")))
    s0, s1, s2 = (passes[k][4:12, 4:12, 1].mean() for k in ("S0", "S1", "S2"))
    psi = math.radians(rotation + angle)
    assert s0 == pytest.approx(1.0, rel=0.02)
    assert s1 / s0 == pytest.approx(math.cos(2 * psi), abs=0.01)
    assert s2 / s0 == pytest.approx(math.sin(2 * psi), abs=0.01)


def test_a_uv_mapped_screen_takes_its_uv_direction(addon):
    scene, plane, _ = _screen_scene(rotation_z=math.radians(45), uv=True)
    engine_scene, _ = _export(scene)
    mesh = next(m for m in engine_scene.meshes if m.emission is not None)
    if mesh.uv is None:
        assert mesh.emission_axis is not None       # no UVs exported for this material: the object's X
    else:
        from polar_render.engine.polarisation.sources import uv_tangent
        u = uv_tangent(mesh.vertices, mesh.faces, mesh.uv)
        np.testing.assert_allclose(u, [math.sqrt(0.5), math.sqrt(0.5), 0], atol=1e-6)


def test_light_polarisation_is_saved_and_exported(addon, tmp_path):
    scene = empty_scene(8, 8, samples=1)
    add_camera(scene, (0, 0, 5), (0, 0, 0))
    bpy.ops.mesh.primitive_plane_add(size=4)
    for kind, rot in (("SUN", (0.3, 0.0, 0.5)), ("AREA", (0.0, 0.0, 1.0)), ("SPOT", (0.0, 0.0, 0.0))):
        light = bpy.data.lights.new(kind, kind)
        obj = bpy.data.objects.new(kind, light)
        obj.rotation_euler = rot
        obj.location = (0, 0, 3)
        scene.collection.objects.link(obj)
        light.polar.polarisation = "CIRCULAR" if kind == "SPOT" else "LINEAR"
        light.polar.handedness = "LEFT"
        light.polar.angle = math.radians(45)
    screen = bpy.data.materials.new("Screen")
    screen.polar.polarisation, screen.polar.degree, screen.polar.handedness = "CIRCULAR", 0.5, "LEFT"
    screen.use_fake_user = True
    path = os.path.join(tmp_path, "lights.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    saved = bpy.data.materials["Screen"].polar
    assert (saved.polarisation, saved.degree, saved.handedness) == ("CIRCULAR", 0.5, "LEFT")
    assert bpy.data.lights["SUN"].polar.polarisation == "LINEAR"
    assert bpy.data.lights["SPOT"].polar.handedness == "LEFT"
    bpy.context.view_layer.update()
    engine_scene, _ = _export(scene)
    by_type = {type(x).__name__: x for x in engine_scene.lights}
    sun = by_type["DirectionalLight"]
    assert sun.polarisation.kind == "linear" and sun.polarisation.angle_deg == pytest.approx(45)
    M = np.array(bpy.data.objects["SUN"].matrix_world)
    np.testing.assert_allclose(sun.polarisation_axis, M[:3, 0] / np.linalg.norm(M[:3, 0]), atol=1e-6)
    assert by_type["SpotLight"].polarisation.kind == "circular"
    assert by_type["SpotLight"].polarisation.handedness == "left"
    area = next(m for m in engine_scene.meshes if m.name.startswith("light:"))
    assert area.emission_polarisation.kind == "linear"
    # the render's transport follows: a circular source needs full Stokes
    from polar_render.engine.render.effects import source_needs
    assert source_needs(engine_scene)[0] == "full"


def test_the_lcd_preset_sets_45_degrees_linear(addon):
    scene, plane, mat = _screen_scene(polarisation="NONE")
    with bpy.context.temp_override(material=mat):
        assert bpy.ops.polar.lcd_screen_preset(target="MATERIAL") == {"FINISHED"}
    assert mat.polar.polarisation == "LINEAR" and mat.polar.degree == 1.0
    assert math.degrees(mat.polar.angle) == pytest.approx(45.0)


# ------------------------------------------------------------------ the polarised Sky Texture

def _sky_world(scene, sky_type, rotation_z_deg=0.0, **props):
    world = bpy.data.worlds.new("Sky")
    scene.world = world
    load_addon().polar_addon.compat.ensure_node_tree(world)
    tree = world.node_tree
    sky = tree.nodes.new("ShaderNodeTexSky")
    sky.sky_type = sky_type
    for k, v in props.items():
        setattr(sky, k, v)
    tree.links.new(sky.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    if rotation_z_deg:
        mapping = tree.nodes.new("ShaderNodeMapping")
        mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(rotation_z_deg))
        coords = tree.nodes.new("ShaderNodeTexCoord")
        tree.links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
        tree.links.new(mapping.outputs["Vector"], sky.inputs["Vector"])
    scene.polar.world_bake_resolution = 128
    return world


def _brightest_direction(light):
    """The world direction of the baked map's brightest texel (row 0 = zenith, u = ½ − φ/2π)."""
    img = np.asarray(light.image)
    H, W = img.shape[:2]
    j, i = np.unravel_index(np.argmax(img.sum(axis=2)), (H, W))
    theta, phi = math.pi * (j + 0.5) / H, math.pi * (1 - 2 * (i + 0.5) / W)
    return np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)])


SKY_CASES = [("MULTIPLE_SCATTERING", 0.0, {"sun_elevation": math.radians(25), "sun_rotation": math.radians(40)}),
             ("SINGLE_SCATTERING", 0.0, {"sun_elevation": math.radians(35), "sun_rotation": math.radians(-60)}),
             ("PREETHAM", 60.0, {"sun_direction": (0.5, -0.6, 0.4), "turbidity": 3.0}),
             ("PREETHAM", 0.0, {"sun_direction": (0.5, -0.6, 0.4), "turbidity": 3.0}),
             ("HOSEK_WILKIE", 45.0, {"sun_direction": (-0.3, 0.7, 0.5), "turbidity": 4.0})]


@pytest.mark.parametrize("sky_type, rotation, props", SKY_CASES)
def test_every_sky_type_is_polarised_about_the_sun_cycles_bakes(addon, sky_type, rotation, props):
    """The model's sun lies in the vertical plane where Cycles' own bake of the Sky Texture is brightest (the
    glow about the sun and on the horizon below it is symmetric about the solar vertical), a Mapping rotation
    on the Vector turning both; its elevation is the node's."""
    from polar_render.polar_addon.export.world import export_world
    scene = empty_scene(8, 8, samples=1)
    world = _sky_world(scene, sky_type, rotation, **props)
    warnings = []
    light = export_world(world, warnings, bake_width=256, bake_samples=4)
    assert light.sky is not None and light.polarisation.transport_need == "linear", warnings
    sun = np.array(light.sky.sun_direction)
    bright = _brightest_direction(light)
    azimuth = math.degrees(math.atan2(sun[1], sun[0]) - math.atan2(bright[1], bright[0]))
    assert abs((azimuth + 180.0) % 360.0 - 180.0) < 3.0
    if "sun_elevation" in props:
        assert math.asin(sun[2]) == pytest.approx(props["sun_elevation"], abs=1e-6)
    else:
        given = np.array(props["sun_direction"]) / np.linalg.norm(props["sun_direction"])
        assert sun[2] == pytest.approx(given[2], abs=1e-6)          # a rotation about Z keeps the elevation
    assert light.sky.model == "berry"


def test_sky_polarisation_is_a_saved_world_setting(addon, tmp_path):
    from polar_render.polar_addon.export.world import export_world
    scene = empty_scene(8, 8, samples=1)
    world = _sky_world(scene, "MULTIPLE_SCATTERING")
    world.polar.sky_polarisation = "OFF"
    path = os.path.join(tmp_path, "sky.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)
    world = bpy.data.worlds["Sky"]
    assert world.polar.sky_polarisation == "OFF"
    light = export_world(world, [], bake_width=64, bake_samples=1)
    assert light.polarisation is None and light.sky is None
    world.polar.sky_polarisation = "RAYLEIGH"
    assert export_world(world, [], bake_width=64, bake_samples=1).sky.model == "rayleigh"


def test_a_sun_below_the_horizon_leaves_the_sky_unpolarised_with_a_warning(addon):
    from polar_render.polar_addon.export.world import export_world
    scene = empty_scene(8, 8, samples=1)
    world = _sky_world(scene, "PREETHAM", sun_direction=(0.0, 0.8, -0.2))
    warnings = []
    light = export_world(world, warnings, bake_width=64, bake_samples=1)
    assert light.polarisation is None
    assert any("below the horizon" in w for w in warnings)


def test_an_outdoor_scene_renders_with_linear_stokes_and_a_polarised_sky(addon, tmp_path):
    """F12 of a Sky Texture world seen by a camera looking 90° from the sun: the sky is polarised."""
    scene = empty_scene(8, 8, samples=4)
    _sky_world(scene, "MULTIPLE_SCATTERING", sun_elevation=math.radians(10), sun_rotation=0.0)
    # the sun towards +Y; look along +X, a little up
    add_camera(scene, (0, 0, 1), (math.radians(100), 0, math.radians(-90)), lens=200)
    bpy.ops.mesh.primitive_plane_add(size=2, location=(0, 0, -50))
    passes = read_multilayer(render_to_exr(scene, os.path.join(tmp_path, "sky")))
    s0 = passes["S0"][..., 1].mean()
    dolp = math.hypot(passes["S1"][..., 1].mean(), passes["S2"][..., 1].mean()) / s0
    assert 0.4 < dolp < 0.85
