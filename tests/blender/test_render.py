"""The Blender extension rendering through the bpy module: passes, polarisation, export fidelity,
settings, border, animation, cancellation and errors."""

import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import (add_plane, add_sphere, brewster_camera, empty_scene, load_addon,  # noqa: E402
                                   polar_material, read_multilayer, render_to_exr, white_world)


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def brewster_scene(samples=4):
    scene = empty_scene(samples=samples)
    add_plane(200, polar_material("Floor", "BLACK_GLASS"))
    brewster_camera(scene, lens=200.0)
    white_world(scene)
    return scene


def test_passes_and_brewster_floor(addon, tmp_path):
    scene = brewster_scene()
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "brewster")))
    for name in ("Combined", "S0", "S1", "S2", "S3", "DoP", "DoLP", "AoLP", "DoCP"):
        assert name in passes, name
    H, W = passes["S0"].shape[:2]
    centre = (slice(H // 2 - 2, H // 2 + 2), slice(W // 2 - 2, W // 2 + 2))
    assert passes["DoLP"][centre].min() > 0.9
    assert passes["S1"][centre].mean() > 0                      # s-polarised: horizontal in the image
    assert np.all(passes["S0"] > 0)
    np.testing.assert_array_equal(passes["Combined"][..., :3], passes["S0"])
    assert np.all(passes["S3"] == 0)                               # auto → linear: nothing retards


def test_lambert_only_scene_is_unpolarised(addon, tmp_path):
    scene = empty_scene()
    add_plane(20, polar_material("Chalk", "LAMBERT"))
    add_sphere(1.0, (0, 0, 1))                                     # no material: default grey Lambert
    bpy.ops.object.light_add(type="POINT", location=(2, -2, 4))
    bpy.context.object.data.energy = 500
    brewster_camera(scene, distance=8, lens=35)
    white_world(scene, 0.2)
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "lambert")))
    assert passes["S0"].max() > 0
    for name in ("S1", "S2", "S3", "DoLP", "DoCP"):
        assert np.all(passes[name] == 0), name


def test_blender_render_equals_engine_render_of_the_export(addon, tmp_path):
    from polar_render.engine.render.renderer import Renderer
    from polar_render.polar_addon.render_engine import engine_settings
    from polar_render.polar_addon.export.scene import export_scene
    scene = empty_scene(width=40, height=30, samples=3)
    add_plane(30, polar_material("Floor", "BLACK_GLASS"))
    add_sphere(1.0, (0.5, 0.5, 1.0), polar_material("Gold", "CONDUCTOR", metal="Au"))
    add_sphere(0.7, (-1.5, 0.0, 0.7), polar_material("Glass", "DIELECTRIC", IOR=1.5))
    bpy.ops.object.light_add(type="SUN", rotation=(0.5, 0.2, 0.0))
    bpy.context.object.data.energy = 2.0
    brewster_camera(scene, distance=9, lens=40)
    white_world(scene, 0.5)
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "fidelity")))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    settings = engine_settings(scene)
    engine_scene, _ = export_scene(depsgraph, scene.camera, 40, 30, settings)
    stokes = Renderer(engine_scene).render(settings).stokes().astype(np.float32)
    for i in range(4):
        np.testing.assert_allclose(passes[f"S{i}"], stokes[i], rtol=1e-6, atol=1e-7)
    assert np.abs(passes["S3"]).max() > 0                           # gold seen via the floor: circular


def test_resolution_percentage_and_border(addon, tmp_path):
    scene = brewster_scene()
    scene.render.resolution_x, scene.render.resolution_y = 80, 60
    scene.render.resolution_percentage = 50
    scene.render.use_border = True
    scene.render.use_crop_to_border = False
    scene.render.border_min_x, scene.render.border_max_x = 0.25, 0.75
    scene.render.border_min_y, scene.render.border_max_y = 0.5, 1.0
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "border")))
    S0 = passes["S0"][..., 0]
    assert S0.shape == (30, 40)
    inside = S0[0:15, 10:30]
    assert np.all(inside > 0)
    outside = np.ones_like(S0, bool)
    outside[0:15, 10:30] = False
    assert np.all(S0[outside] == 0)


def test_animation_renders_every_frame_with_animated_seed(addon, tmp_path):
    scene = brewster_scene(samples=1)
    scene.frame_start, scene.frame_end = 1, 2
    scene.polar.use_animated_seed = True
    scene.render.filepath = str(tmp_path / "frame_")
    bpy.ops.render.render(animation=True)
    files = sorted(f for f in os.listdir(tmp_path) if f.endswith(".exr"))
    assert files == ["frame_0001.exr", "frame_0002.exr"]
    a = read_multilayer(str(tmp_path / files[0]))["S0"]
    b = read_multilayer(str(tmp_path / files[1]))["S0"]
    assert not np.array_equal(a, b)                                 # different noise per frame


def test_cancel_keeps_a_partial_image(addon, tmp_path):
    from polar_render.polar_addon import render_engine as polar_engine
    scene = brewster_scene(samples=64)
    scene.polar.batch_rays = 1024
    scene.polar.threads = 1
    polar_engine.CONTROL.cancel = True
    try:
        passes = read_multilayer(render_to_exr(scene, str(tmp_path / "cancelled")))
    finally:
        polar_engine.CONTROL.cancel = False
    assert np.all(passes["S0"] == 0)           # cancelled before the first batch: nothing traced, no crash


@pytest.mark.parametrize("case", ["no_camera", "nan_parameter"])
def test_bad_input_is_a_clear_blender_error(addon, tmp_path, case):
    scene = brewster_scene()
    if case == "no_camera":
        scene.camera = None
        expected = "camera"
    else:
        mat = bpy.data.materials["Floor"]
        node = mat.node_tree.nodes["Polarising BSDF"]
        node.model = "CONDUCTOR"
        node.inputs["k"].default_value = float("nan")
        expected = "material 'Floor'"
    scene.render.filepath = str(tmp_path / case)
    with pytest.raises(RuntimeError) as err:
        bpy.ops.render.render(write_still=True)
    assert expected in str(err.value)
    assert not os.path.exists(str(tmp_path / case) + ".exr")       # no black image saved


def test_degenerate_and_open_meshes_render_with_a_warning(addon, tmp_path):
    from polar_render.polar_addon.render_engine import engine_settings
    from polar_render.polar_addon.export.scene import export_scene
    scene = brewster_scene()
    me = bpy.data.meshes.new("Degenerate")
    me.from_pydata([(0, 0, 1), (0, 0, 1), (1, 0, 1), (2, 0, 1)], [], [(0, 1, 2), (0, 2, 3)])  # zero-area faces
    scene.collection.objects.link(bpy.data.objects.new("Degenerate", me))
    squashed = add_sphere(1.0, (0, 0, 1))
    squashed.scale = (1.0, 1.0, 0.0)                  # a singular transform
    bpy.ops.mesh.primitive_grid_add(size=2, location=(0, 0, 0.5))   # an open (non-manifold) sheet
    _, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 48, 36, engine_settings(scene))
    assert any("zero-area" in w and "Degenerate" in w for w in warnings)
    assert any("zero scale" in w for w in warnings)
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "degenerate")))
    assert np.all(np.isfinite(passes["S0"])) and passes["S0"].max() > 0


def test_unsupported_world_and_shader_warn_but_render(addon, tmp_path):
    scene = brewster_scene()
    world = scene.world
    sky = world.node_tree.nodes.new("ShaderNodeTexSky")
    world.node_tree.links.new(sky.outputs[0], world.node_tree.nodes["Background"].inputs["Color"])
    obj = add_sphere(1.0, (0, 0, 1))
    mat = bpy.data.materials.new("Toon")
    toon = mat.node_tree.nodes.new("ShaderNodeBsdfToon")
    mat.node_tree.links.new(toon.outputs[0], mat.node_tree.get_output_node("ALL").inputs["Surface"])
    obj.data.materials.append(mat)
    from polar_render.polar_addon.render_engine import engine_settings
    from polar_render.polar_addon.export.scene import export_scene
    _, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 48, 36, engine_settings(scene))
    assert any("ShaderNodeTexSky" in w for w in warnings)
    assert any("ShaderNodeBsdfToon" in w for w in warnings)
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "warn")))
    assert passes["S0"].max() > 0


def test_skip_clear_layers_setting_reaches_the_engine(addon):
    from polar_render.polar_addon.render_engine import engine_settings
    scene = empty_scene()
    assert scene.polar.skip_clear_layers is True
    assert engine_settings(scene).simplify == "auto"
    scene.polar.skip_clear_layers = False
    assert engine_settings(scene).simplify == "off"
