"""Cycles bakes of procedural material inputs (polar_addon/export/texture_bake.py).

Oracles: the analytic checker pattern at texel centres (Blender's Checker Texture formula), Cycles'
own render of the same textured plane (luminance per region within 4 standard errors + 2 %), and
bpy.data's contents before and after (nothing may be left behind).
"""

import math
import tempfile

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import cycles_seed_renders, load_addon  # noqa: E402

W, H = 48, 36
BLOCK = 12
SEEDS = 4
CYCLES_SPP = 32
POLAR_SPP = 16
REC709 = np.array([0.2126, 0.7152, 0.0722])
COLOUR1, COLOUR2 = (0.9, 0.25, 0.1), (0.05, 0.2, 0.6)


def _bake_module():
    load_addon()
    import importlib
    return importlib.import_module("polar_render.polar_addon.export.texture_bake")


def _export(scene, width=W, height=H):
    from polar_render.engine.scene.description import RenderSettings
    from polar_render.polar_addon.export.scene import export_scene
    settings = RenderSettings(spp=POLAR_SPP, max_depth=4, seed=0, spectral="spectral", polarisation="off")
    return export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, width, height, settings)


def checker_scene(shader="ShaderNodeBsdfDiffuse", scale=2.5, uv_vector=False, name="Checker"):
    """A 2 m plane whose Diffuse Color (or Principled Base Color) is a Checker Texture, a white
    world, and an orthographic camera looking straight down at the plane."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = W, H
    scene.render.resolution_percentage = 100
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    plane = bpy.context.object
    mat = bpy.data.materials.new(name)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    for n in list(nodes):
        if n.bl_idname != "ShaderNodeOutputMaterial":
            nodes.remove(n)
    shader_node = nodes.new(shader)
    checker = nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = scale
    checker.inputs["Color1"].default_value = (*COLOUR1, 1.0)
    checker.inputs["Color2"].default_value = (*COLOUR2, 1.0)
    if uv_vector:
        links.new(nodes.new("ShaderNodeTexCoord").outputs["UV"], checker.inputs["Vector"])
    colour = "Color" if shader == "ShaderNodeBsdfDiffuse" else "Base Color"
    links.new(checker.outputs["Color"], shader_node.inputs[colour])
    links.new(shader_node.outputs[0], nodes["Material Output"].inputs["Surface"])
    plane.data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 1.8
    scene.collection.objects.link(cam)
    cam.location = (0.0, 0.0, 3.0)
    scene.camera = cam
    world = bpy.data.worlds.new("World")
    scene.world = world
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    return scene, plane, mat, shader_node.inputs[colour]


def checker_oracle(u, v, scale):
    """Blender's Checker Texture (node_tex_checker / svm_checker) at vector (u, v, 0): Color1 where
    the parities of ⌊x⌋ and ⌊y⌋ differ (z = 0), else Color2; p = (vector·scale + 1e-6)·0.999999."""
    x = np.floor((u * scale + 1e-6) * 0.999999).astype(int)
    y = np.floor((v * scale + 1e-6) * 0.999999).astype(int)
    first = (np.abs(x) % 2 == np.abs(y) % 2) == 0
    return np.where(first[..., None], COLOUR1, COLOUR2)


def data_snapshot():
    """Names of every datablock in bpy.data, per collection."""
    out = {}
    for attr in dir(bpy.data):
        coll = getattr(bpy.data, attr, None)
        if isinstance(coll, bpy.types.bpy_prop_collection) and attr not in ("window_managers", "screens",
                                                                           "workspaces"):
            out[attr] = sorted(x.name_full for x in coll)
    return out


def test_checker_bake_equals_the_analytic_checker():
    tb = _bake_module()
    scale, res = 4.0, 64
    scene, plane, mat, socket = checker_scene("ShaderNodeBsdfPrincipled", scale=scale, uv_vector=True)
    warnings = []
    baked = tb.bake_input(plane, mat, socket, res, warnings, cache=None)
    assert warnings == []
    px = baked.texture.pixels
    assert px.shape == (res, res, 3) and px.dtype == np.float32
    centres = (np.arange(res) + 0.5) / res
    u, v = np.meshgrid(centres, centres)          # row j ↔ v = (j + ½)/res: row 0 at v = 0
    expected = checker_oracle(u, v, scale)
    # away from cell edges (the value at a texel centre; edges of cells fall between texels here)
    def off_edges(x):
        return np.abs(x * scale - np.round(x * scale)) > 1.0 / res
    inner = off_edges(u) & off_edges(v)
    np.testing.assert_allclose(px[inner], expected[inner], atol=1e-5)
    # ... and the texture lookup at those centres gives the same values
    looked_up = baked.texture.lookup(np.stack((u[inner], v[inner])))
    np.testing.assert_allclose(looked_up.T, expected[inner], atol=1e-5)


def test_noise_roughness_bake_is_one_channel_in_unit_range():
    tb = _bake_module()
    scene, plane, mat, _ = checker_scene("ShaderNodeBsdfPrincipled")
    nodes = mat.node_tree.nodes
    noise = nodes.new("ShaderNodeTexNoise")
    principled = nodes["Principled BSDF"]
    mat.node_tree.links.new(noise.outputs["Fac"], principled.inputs["Roughness"])
    warnings = []
    baked = tb.bake_input(plane, mat, principled.inputs["Roughness"], 32, warnings, cache=None)
    px = baked.texture.pixels
    assert warnings == [] and px.shape == (32, 32, 1)
    assert px.min() >= 0.0 and px.max() <= 1.0 and px.std() > 0.01   # noise, not a constant


def test_no_uv_map_gives_one_warning_naming_the_input():
    _bake_module()
    scene, plane, mat, _ = checker_scene()
    plane.data.uv_layers.remove(plane.data.uv_layers[0])
    engine_scene, warnings = _export(scene)
    about = [w for w in warnings if "'Checker'" in w and "'Color'" in w]
    assert len(about) == 1 and "no UV map" in about[0], warnings
    bsdf = engine_scene.materials[engine_scene.meshes[0].materials[0]]
    assert bsdf.varies_over_surface is False         # the socket's own value


def test_reexport_reuses_the_bake_and_leaves_bpy_data_unchanged():
    tb = _bake_module()
    tb.BAKE_CACHE.clear()
    scene, plane, mat, _ = checker_scene()
    scene.polar.texture_bake_resolution = 64
    before = data_snapshot()
    first, warnings = _export(scene)
    assert tb.BAKE_CACHE.bakes == 1 and tb.BAKE_CACHE.hits == 0 and warnings == []
    assert data_snapshot() == before                 # no temporary scene, mesh, material, image left
    mesh = first.meshes[0]
    assert mesh.uv is not None and mesh.uv.shape == (mesh.vertices.shape[0], 2)
    assert first.materials[mesh.materials[0]].varies_over_surface
    _export(scene)                                   # nothing changed: the cached image
    assert tb.BAKE_CACHE.bakes == 1 and tb.BAKE_CACHE.hits == 1
    mat.node_tree.nodes["Checker Texture"].inputs["Scale"].default_value = 3.0
    _export(scene)                                   # the graph changed: baked again
    assert tb.BAKE_CACHE.bakes == 2
    scene.polar.texture_bake_resolution = 32
    _export(scene)
    assert tb.BAKE_CACHE.bakes == 3
    assert data_snapshot() == before


def test_material_shared_by_two_objects_is_baked_per_object():
    tb = _bake_module()
    tb.BAKE_CACHE.clear()
    scene, plane, mat, _ = checker_scene()
    scene.polar.texture_bake_resolution = 16
    other = plane.copy()
    other.data = plane.data.copy()
    other.location.x = 3.0
    scene.collection.objects.link(other)
    engine_scene, _ = _export(scene)
    keys = sorted({m.materials[0] for m in engine_scene.meshes})
    assert keys == sorted(["mat:Checker@Plane", f"mat:Checker@{other.name}"]) and tb.BAKE_CACHE.bakes == 2


def test_bake_resolution_setting_is_range_checked():
    tb = _bake_module()
    scene, *_ = checker_scene()
    assert scene.polar.texture_bake_resolution == 512
    scene.polar.texture_bake_resolution = 1            # Blender clamps to the property's range
    assert scene.polar.texture_bake_resolution == tb.RESOLUTION_MIN
    with pytest.raises(ValueError, match=r"texture_bake_resolution must be an integer in \[8, 8192\]"):
        tb.check_resolution(9000)


def _cycles_renders(scene, tmp):
    return cycles_seed_renders(scene, tmp, CYCLES_SPP, SEEDS, 3) @ REC709


def _polar_renders(scene):
    from polar_render.engine.render.renderer import Renderer
    from polar_render.engine.scene.description import RenderSettings
    out = []
    for seed in range(SEEDS):
        engine_scene, _ = _export(scene)
        settings = RenderSettings(spp=POLAR_SPP, max_depth=5, seed=seed, spectral="spectral", polarisation="off")
        out.append(Renderer(engine_scene).render(settings).stokes()[0] @ REC709)
    return np.array(out)


def _region_stats(images):
    k = images.shape[0]
    blocks = images.reshape(k, H // BLOCK, BLOCK, W // BLOCK, BLOCK).mean(axis=(2, 4)).reshape(k, -1)
    return blocks.mean(0), blocks.std(0, ddof=1) / math.sqrt(k)


def test_baked_checker_renders_as_in_cycles():
    """Checker on Generated coordinates (Cycles' default), 2.5 cells per side (not symmetric under
    a flip of u or v), white world: S0 luminance per 12×12 region agrees with Cycles."""
    _bake_module()
    scene, *_ = checker_scene(scale=2.5)
    scene.polar.texture_bake_resolution = 256
    polar = _polar_renders(scene)
    with tempfile.TemporaryDirectory() as tmp:
        cycles = _cycles_renders(scene, tmp)
    (mc, sc), (mp, sp) = _region_stats(cycles), _region_stats(polar)
    ratio = mp / mc
    se = ratio * np.sqrt((sp / mp) ** 2 + (sc / mc) ** 2)
    assert mc.max() / mc.min() > 1.5, "the regions should differ (a checker, not a flat colour)"
    bad = np.abs(ratio - 1.0) > 4.0 * se + 0.02
    assert not bad.any(), f"Polar/Cycles per region {np.round(ratio, 4).tolist()} ± {np.round(se, 4).tolist()}"


def test_f12_render_bakes_and_reports_the_bake_time(tmp_path, capfd):
    """Baking from inside the engine's render() (bpy.ops.render.render) works, and the render stats
    name the bakes and their time."""
    tb = _bake_module()
    tb.BAKE_CACHE.clear()
    scene, *_ = checker_scene()
    scene.render.engine = "POLAR"
    scene.render.resolution_x = scene.render.resolution_y = 8
    scene.polar.samples = 1
    scene.polar.texture_bake_resolution = 16
    scene.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    scene.render.filepath = str(tmp_path / "f12")
    before = data_snapshot()
    bpy.ops.render.render(write_still=True)
    out = capfd.readouterr().out
    assert "texture bakes: 1 in " in out and tb.BAKE_CACHE.bakes == 1
    after = data_snapshot()
    after["images"] = [n for n in after["images"] if n != "Render Result"]
    assert after == before


def test_principled_base_color_is_baked_for_dielectrics_and_metals():
    _bake_module()
    scene, plane, mat, socket = checker_scene("ShaderNodeBsdfPrincipled")
    scene.polar.texture_bake_resolution = 16
    engine_scene, warnings = _export(scene)
    bsdf = engine_scene.materials[engine_scene.meshes[0].materials[0]]
    assert type(bsdf).__name__ == "TorranceSparrow" and bsdf.varies_over_surface and warnings == []
    socket.node.inputs["Metallic"].default_value = 1.0     # a metal's n, κ from the baked colour, per point
    engine_scene, warnings = _export(scene)
    bsdf = engine_scene.materials[engine_scene.meshes[0].materials[0]]
    assert type(bsdf).__name__ == "F82Reflectance" and bsdf.varies_over_surface and warnings == []   # Cycles' curve
    assert type(bsdf.base).__name__ == "TorranceSparrow" and bsdf.base.varies_over_surface


def test_float_input_fallback_gives_a_textured_number():
    """The hook returns a TexturedNumber for float sockets (for inputs that accept textures)."""
    _bake_module()
    from polar_render.engine.textures import TexturedNumber
    from polar_render.polar_addon.export import node_reader
    scene, plane, mat, _ = checker_scene("ShaderNodeBsdfPrincipled")
    nodes = mat.node_tree.nodes
    principled = nodes["Principled BSDF"]
    mat.node_tree.links.new(nodes.new("ShaderNodeTexNoise").outputs["Fac"], principled.inputs["Roughness"])
    warnings = []
    reader = node_reader.Reader(mat.name, nodes["Principled BSDF"], warnings,
                                node_reader.BakeTarget(plane, None, mat, 16))
    value = TexturedNumber(node_reader._linked_input_fallback(reader, nodes["Principled BSDF"].inputs["Roughness"],
                                                             0.0, 1.0))      # the hook gives a TextureInput
    assert isinstance(value, TexturedNumber) and 0.0 <= value.lo < value.hi <= 1.0 and warnings == []


def test_multi_material_object_bakes_only_its_faces_with_unchanged_generated_coordinates(monkeypatch):
    """A cube (off-centre, stretched: Generated coordinates depend on its whole bounding box) with
    two material slots: the bake of slot 0 writes texels of slot-0 faces only, equal to those of a
    bake with every face in slot 0 (the removed faces do not move the texture space)."""
    tb = _bake_module()
    monkeypatch.setattr(tb, "MARGIN_PER_512", 0)
    scene, plane, mat, socket = checker_scene()
    bpy.ops.mesh.primitive_cube_add(size=2, location=(0.3, 0.0, 0.0))
    cube = bpy.context.object
    cube.scale = (2.0, 1.0, 1.0)
    cube.data.materials.append(mat)
    cube.data.materials.append(bpy.data.materials.new("Other"))
    full = tb.bake_input(cube, mat, socket, 64, [], cache=None).texture.pixels.copy()
    slots = np.ones(6, np.int32)
    slots[0] = 0                                 # one face left: its own bounding box is flat
    cube.data.polygons.foreach_set("material_index", slots)
    cube.data.update()
    part = tb.bake_input(cube, mat, socket, 64, [], cache=None).texture.pixels
    written = np.any(part != 0, axis=-1)
    assert 0 < written.sum() < np.any(full != 0, axis=-1).sum()
    core = written & np.roll(written, 1, 0) & np.roll(written, -1, 0) & np.roll(written, 1, 1) & np.roll(written, -1, 1)
    assert core.sum() > 50
    np.testing.assert_allclose(part[core], full[core], atol=1e-6)


def test_a_failed_bake_is_a_warning_naming_the_input(monkeypatch):
    tb = _bake_module()

    def fail(*args):
        raise RuntimeError("Error: Current render engine does not support baking\n")
    monkeypatch.setattr(tb, "_bake_pixels", fail)
    scene, plane, mat, socket = checker_scene()
    warnings = []
    assert tb.bake_input(plane, mat, socket, 16, warnings, cache=None) is None
    assert len(warnings) == 1 and "'Checker'" in warnings[0] and "'Color'" in warnings[0]
    assert "does not support baking" in warnings[0]


# ------------------------------------------------------------------ merged with the texture export

def _off_edges(x, scale, margin):
    """True where x·scale is more than ``margin`` (in x units) from a checker cell edge."""
    return np.abs(x * scale - np.round(x * scale)) > margin * scale


def test_baked_roughness_is_m_squared_with_the_least_textured_slope():
    """A Checker Fac on a Principled dielectric's Roughness is baked as a one-channel float image and
    becomes m = r² per point (TextureInput power 2), r clamped at ROUGHNESS_MIN as an image roughness:
    at texel centres m is (max(Fac, ROUGHNESS_MIN))² of the analytic checker."""
    tb = _bake_module()
    from polar_render.engine.materials.roughness import ROUGHNESS_MIN
    scale, res = 4.0, 64
    scene, plane, mat, _ = checker_scene("ShaderNodeBsdfPrincipled", scale=scale, uv_vector=True)
    nodes = mat.node_tree.nodes
    principled = nodes["Principled BSDF"]
    mat.node_tree.links.remove(principled.inputs["Base Color"].links[0])
    mat.node_tree.links.new(nodes["Checker Texture"].outputs["Fac"], principled.inputs["Roughness"])
    scene.polar.texture_bake_resolution = res
    tb.BAKE_CACHE.clear()
    exported, warnings = _export(scene)
    assert warnings == [] and tb.BAKE_CACHE.bakes == 1
    mesh = exported.meshes[0]
    assert mesh.materials[0] == "mat:Checker@Plane" and mesh.uv is not None
    bsdf = exported.materials[mesh.materials[0]]
    assert type(bsdf).__name__ == "TorranceSparrow" and bsdf.varies_over_surface
    m = bsdf.m.source
    assert m.power == 2.0 and m.texture.channels == 1
    # α = r² per point, kept ≥ the least textured slope 1e-4 (= ROUGHNESS_MIN², the clip of the squared value)
    assert (bsdf.m.lo, bsdf.m.hi) == pytest.approx((ROUGHNESS_MIN ** 2, 1.0), rel=1e-6)
    centres = (np.arange(res) + 0.5) / res
    u, v = (a.ravel() for a in np.meshgrid(centres, centres))
    inner = _off_edges(u, scale, 1.0 / res) & _off_edges(v, scale, 1.0 / res)
    fac = (checker_oracle(u[inner], v[inner], scale)[:, 0] == COLOUR1[0]).astype(float)
    expected = np.maximum(fac, ROUGHNESS_MIN) ** 2
    got = np.clip(m.number_at_uv(np.stack((u[inner], v[inner]))), *bsdf.m.clip)
    np.testing.assert_allclose(got, expected, rtol=1e-6)


def test_bake_uses_the_uv_map_the_mesh_exports_for_its_image_textures(tmp_path):
    """A material whose Roughness is an image on UV map 'Second' and whose Base Color is a Checker on
    the active map: the mesh exports 'Second' (one UV map per mesh) and the checker is baked on it, so
    that looking the bake up at a point's 'Second' coordinates gives the checker of its active-map
    coordinates."""
    tb = _bake_module()
    from PIL import Image
    Image.fromarray(np.full((2, 2), 128, np.uint8)).save(tmp_path / "grey.png")
    scale, res = 2.5, 128
    scene, plane, mat, _ = checker_scene("ShaderNodeBsdfPrincipled", scale=scale, uv_vector=True)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    image = nodes.new("ShaderNodeTexImage")
    image.image = bpy.data.images.load(str(tmp_path / "grey.png"))
    image.image.colorspace_settings.name = "Non-Color"
    uvmap = nodes.new("ShaderNodeUVMap")
    uvmap.uv_map = "Second"
    links.new(uvmap.outputs["UV"], image.inputs["Vector"])
    links.new(image.outputs["Color"], nodes["Principled BSDF"].inputs["Roughness"])
    me = plane.data
    second = me.uv_layers.new(name="Second")
    for loop in me.loops:
        a, b = me.uv_layers["UVMap"].uv[loop.index].vector
        second.uv[loop.index].vector = (0.5 * a + 0.25, b)
    assert me.uv_layers["UVMap"].active_render
    scene.polar.texture_bake_resolution = res
    tb.BAKE_CACHE.clear()
    exported, warnings = _export(scene)
    assert warnings == [] and tb.BAKE_CACHE.bakes == 1
    mesh = exported.meshes[0]
    corners = [t.loops[c] for t in me.loop_triangles for c in range(3)]
    np.testing.assert_allclose(mesh.uv, [tuple(second.uv[i].vector) for i in corners], atol=1e-7)
    bsdf = exported.materials[mesh.materials[0]]
    base = bsdf.albedo.source
    assert bsdf.m.source.power == 2.0 and base.texture.channels == 3
    g = np.linspace(0.02, 0.98, 40)
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    inner = _off_edges(u, scale, 4.0 / res) & _off_edges(v, scale, 2.0 / res)
    looked_up = base.texture.lookup(np.stack((0.5 * u[inner] + 0.25, v[inner])))
    np.testing.assert_allclose(looked_up.T, checker_oracle(u[inner], v[inner], scale), atol=1e-5)


def test_only_objects_that_baked_get_their_own_material_key():
    """The same baked material on an object with a UV map (baked: its own key) and on two without
    (their own value, one warning each: one shared key)."""
    tb = _bake_module()
    scene, plane, mat, _ = checker_scene()
    scene.polar.texture_bake_resolution = 16
    bare = []
    for x in (3.0, 6.0):
        other = plane.copy()
        other.data = plane.data.copy()
        other.data.uv_layers.remove(other.data.uv_layers[0])
        other.location.x = x
        scene.collection.objects.link(other)
        bare.append(other.name)
    tb.BAKE_CACHE.clear()
    exported, warnings = _export(scene)
    keys = {m.name.split(":")[0]: m.materials[0] for m in exported.meshes}
    assert keys == {"Plane": "mat:Checker@Plane", bare[0]: "mat:Checker", bare[1]: "mat:Checker"}
    assert exported.materials["mat:Checker@Plane"].varies_over_surface
    assert not exported.materials["mat:Checker"].varies_over_surface
    assert tb.BAKE_CACHE.bakes == 1 and len([w for w in warnings if "no UV map" in w]) == 2
    assert all(m.uv is None for m in exported.meshes if m.name.split(":")[0] in bare)


def test_baked_colours_are_clamped_to_the_input_range():
    """A Checker whose colour exceeds 1 on a Diffuse Color: the baked values are clamped to [0, 1], as
    Cycles clamps a BSDF's colour (the bake itself keeps them)."""
    tb = _bake_module()
    scene, plane, mat, socket = checker_scene()
    mat.node_tree.nodes["Checker Texture"].inputs["Color1"].default_value = (3.0, 0.5, 2.0, 1.0)
    scene.polar.texture_bake_resolution = 16
    tb.BAKE_CACHE.clear()
    raw = tb.bake_input(plane, mat, socket, 16, [], cache=None).texture.pixels
    assert raw.max() == pytest.approx(3.0)
    exported, warnings = _export(scene)
    bsdf = exported.materials[exported.meshes[0].materials[0]]
    assert warnings == [] and bsdf.varies_over_surface
    assert bsdf.albedo.source.bounds(rgb=True) == pytest.approx((min(COLOUR2), 1.0), abs=1e-6)


def test_viewport_does_not_bake_and_says_so():
    """The viewport's incremental export keeps a baked input's own value, with one warning that names
    the input and says that final renders bake it; nothing is baked."""
    tb = _bake_module()
    from polar_render.polar_addon import viewport as vp
    from polar_render.polar_addon.render_engine import engine_settings
    scene, plane, mat, _ = checker_scene()
    tb.BAKE_CACHE.clear()
    result = vp.SceneWalk().sync(bpy.context.evaluated_depsgraph_get(), None,
                                         engine_settings(scene, preview=True))
    about = [w for w in result.warnings if "'Color'" in w and "'Checker'" in w]
    assert len(about) == 1 and "final renders (F12) only, not in the viewport" in about[0], result.warnings
    assert tb.BAKE_CACHE.bakes == 0
    assert not result.scene.materials[result.scene.meshes[0].materials[0]].varies_over_surface
