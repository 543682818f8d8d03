"""The viewport's scene is F12's (issue 34: one way through the house): the same fixture exported by F12
(``export.scene.export_scene``) and by the viewport's incremental walk (``export.scene.SceneWalk``) gives the
same engine scene except the camera — every mesh with its emission, emitter sides, layers over the emission,
visibility and alpha, every material, every light, the light selection.  The fixture has no baked inputs (the
viewport does not bake: materials.VIEWPORT_NO_BAKE)."""

import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import add_plane, add_sphere, brewster_camera, empty_scene, load_addon, \
    white_world  # noqa: E402


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def _material(name, build):
    mat = bpy.data.materials.new(name)
    load_addon().polar_addon.compat.ensure_node_tree(mat)
    build(mat.node_tree)
    return mat


def _emitting_coated(tree):
    p = tree.nodes["Principled BSDF"]
    p.inputs["Coat Weight"].default_value = 1.0
    p.inputs["Emission Strength"].default_value = 2.0
    p.inputs["Emission Color"].default_value = (1.0, 0.5, 0.2, 1.0)


def _emission(tree):
    em = tree.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = 3.0
    tree.links.new(em.outputs[0], tree.nodes["Material Output"].inputs["Surface"])


def _half_transparent(tree):
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = 0.4
    tree.links.new(tree.nodes.new("ShaderNodeBsdfTransparent").outputs[0], mix.inputs[1])
    tree.links.new(tree.nodes["Principled BSDF"].outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], tree.nodes["Material Output"].inputs["Surface"])


def _unlit(tree):
    """glTF's KHR_materials_unlit as Blender's importer builds it: the camera sees the emission."""
    mix = tree.nodes.new("ShaderNodeMixShader")
    path = tree.nodes.new("ShaderNodeLightPath")
    tree.links.new(path.outputs["Is Camera Ray"], mix.inputs[0])
    tree.links.new(tree.nodes.new("ShaderNodeBsdfTransparent").outputs[0], mix.inputs[1])
    em = tree.nodes.new("ShaderNodeEmission")
    tree.links.new(em.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], tree.nodes["Material Output"].inputs["Surface"])


def _fixture():
    scene = empty_scene()
    white_world(scene, 0.5)
    brewster_camera(scene)
    add_plane(6.0, _material("Floor", lambda tree: None))
    add_sphere(0.5, (-1.5, 0, 0.5), _material("Coated emitter", _emitting_coated))
    add_sphere(0.4, (0, 0, 0.4), _material("Emission", _emission))
    add_sphere(0.4, (1.5, 0, 0.4), _material("Half transparent", _half_transparent))
    add_plane(0.8, _material("Unlit", _unlit), location=(0, 1.5, 0.5))
    light = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
    light.location = (2.0, -2.0, 3.0)
    scene.collection.objects.link(light)
    bpy.context.view_layer.update()
    return scene


def _mesh_record(m):
    return (m.name, m.vertices.round(9).tobytes(), m.faces.tobytes(), repr(m.emission), m.two_sided,
            m.emission_under_layers, m.visible_camera, m.visible_shadow, m.visible_indirect, m.holdout,
            repr(m.alpha), m.occluder, m.spread_deg, tuple(m.materials))


def _describe(bsdf):
    return repr(sorted((k, repr(v)) for k, v in bsdf.describe().items()))


def test_the_viewport_exports_the_scene_f12_renders(addon):
    from polar_render.polar_addon import viewport as vp
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    scene = _fixture()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    settings = engine_settings(scene)
    f12, f12_warnings = export_scene(depsgraph, scene.camera, 32, 24, settings)
    live = vp.SceneWalk().sync(depsgraph, None, settings)
    view = live.scene
    assert sorted(map(_mesh_record, view.meshes)) == sorted(map(_mesh_record, f12.meshes))
    used = {m.materials[0] for m in f12.meshes}
    assert {k: _describe(f12.materials[k]) for k in used} == {k: _describe(view.materials[k]) for k in used}
    assert [repr(vars(x)) for x in view.lights] == [repr(vars(x)) for x in f12.lights]
    assert view.light_selection == f12.light_selection == "power"
    assert sorted(live.warnings) == sorted(f12_warnings)
    # the rules that used to be F12's alone, present in both
    by_name = {m.name.split(":")[0]: m for m in view.meshes}
    coated = next(m for m in view.meshes if m.name.startswith("Sphere") and m.emission_under_layers)
    assert coated.two_sided
    unlit = [m for m in view.meshes if not m.visible_indirect]
    assert len(unlit) == 1 and not unlit[0].visible_shadow and unlit[0].visible_camera
    assert any(float(m.alpha) == pytest.approx(0.4) for m in view.meshes), by_name


def test_one_walk_over_the_depsgraph():
    """Only the scene walk (export/scene.py) iterates the depsgraph's instances: F12 and the viewport share it."""
    import pathlib
    root = pathlib.Path(__file__).resolve().parents[2] / "polar_addon"
    walkers = sorted(str(p.relative_to(root)) for p in root.rglob("*.py") if "object_instances" in p.read_text())
    assert walkers == ["export/scene.py"]


def test_f12_bakes_where_the_viewport_keeps_the_sockets_value(addon):
    """The one difference between the two walks: F12 bakes a linked input on the object's UV map (a material
    per object), the viewport takes the socket's own value with one warning."""
    from polar_render.polar_addon import viewport as vp
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    scene = empty_scene()
    white_world(scene, 0.5)
    brewster_camera(scene)

    def noisy(tree):
        noise = tree.nodes.new("ShaderNodeTexNoise")
        tree.links.new(noise.outputs["Fac"], tree.nodes["Principled BSDF"].inputs["Roughness"])

    add_sphere(0.5, (0, 0, 0.5), _material("Noisy", noisy))
    bpy.context.view_layer.update()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    settings = engine_settings(scene)
    f12, f12_warnings = export_scene(depsgraph, scene.camera, 16, 12, settings)
    live = vp.SceneWalk(source="blender-viewport").sync(depsgraph, None, settings)
    assert any(k.startswith("mat:Noisy@") for k in f12.materials)
    assert "mat:Noisy" in live.scene.materials and not any("@" in k for k in live.scene.materials)
    assert any("Roughness" in w and "own value" in w for w in live.warnings)
    assert not any("Roughness" in w and "own value" in w for w in f12_warnings)
