"""Shader AOVs and Light Groups are not written by Polar: one warning each names what is missing (a material's AOV
Output nodes, a View Layer's Shader AOVs, a View Layer's Light Groups), and the render goes on."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import (add_plane, add_sphere, brewster_camera, empty_scene, load_addon,  # noqa: E402
                                   read_multilayer, render_to_exr, white_world)


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def _export(scene):
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    return export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 24, 16, engine_settings(scene))[1]


def _aov_node(tree, name):
    node = tree.nodes.new("ShaderNodeOutputAOV")
    node.aov_name = name
    return node


def _scene():
    scene = empty_scene(24, 16, 1)
    add_plane(20)
    brewster_camera(scene, distance=8, lens=35)
    white_world(scene)
    return scene


def test_material_aov_outputs_warn_once_naming_them(addon, tmp_path):
    scene = _scene()
    mat = bpy.data.materials.new("Masked")
    tree = mat.node_tree
    _aov_node(tree, "mask")
    _aov_node(tree, "mask")                                        # twice: named once
    group = bpy.data.node_groups.new("Inner", "ShaderNodeTree")
    _aov_node(group, "from_group")
    tree.nodes.new("ShaderNodeGroup").node_tree = group
    add_sphere(1.0, (0, 0, 1), mat)
    warnings = [w for w in _export(scene) if "AOV" in w]
    assert warnings == ["material 'Masked': AOV Output 'from_group', 'mask' not written (Polar renders no shader "
                        "AOVs)"]
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "aov")))
    assert passes["S0"].max() > 0                                   # the render goes on


def test_view_layer_aovs_and_light_groups_warn_once_each(addon):
    scene = _scene()
    layer = bpy.context.view_layer
    for name, kind in (("mask", "VALUE"), ("tint", "COLOR")):
        aov = layer.aovs.add()
        aov.name, aov.type = name, kind
    layer.lightgroups.add(name="key")
    layer.lightgroups.add(name="fill")
    bpy.ops.object.light_add(type="POINT", location=(1, -1, 3))
    bpy.context.object.lightgroup = "key"
    warnings = _export(scene)
    assert [w for w in warnings if "Shader AOV" in w] == [
        "view layer 'ViewLayer': Shader AOV 'mask', 'tint' not written (Polar renders no shader AOVs)"]
    assert [w for w in warnings if "Light Group" in w] == [
        "view layer 'ViewLayer': Light Group 'key', 'fill' not written (no per-group passes; their lights light "
        "the Combined and Stokes passes as usual)"]


def test_no_aovs_no_light_groups_no_warning(addon):
    scene = _scene()
    assert not [w for w in _export(scene) if "AOV" in w or "Light Group" in w]


def test_f12_reports_the_warnings(addon, tmp_path, capfd):
    scene = _scene()
    bpy.context.view_layer.lightgroups.add(name="rim")
    capfd.readouterr()
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "lg")))
    out = capfd.readouterr()
    assert "Polar: view layer 'ViewLayer': Light Group 'rim' not written" in out.out + out.err
    assert np.all(np.isfinite(passes["S0"]))
