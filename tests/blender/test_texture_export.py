"""Blender textures → Polar, against Cycles: image textures (8-bit sRGB and float EXR), Mapping nodes,
colour attributes, tangent-space normal maps, bump maps and missing image files.

Each scene is a 2 m diffuse plane seen from straight above by an orthographic camera that frames it
exactly (each texel of a 4×4 texture is one 8×8-pixel region), lit by a sun (angle 0) from the side
and a black world, so that each region's brightness is albedo × cos(sun, shading normal).  It is
rendered by Cycles (bpy ships it) and by Polar (the exporter + engine, as F12 does); per region the
luminance ratio Polar/Cycles must be 1 within 4 standard errors + 2 % (standard errors from
independent seeds), as tests/blender/test_cycles_parity_lights.py.  Engine-level checks: a roughness texture on
the converted Torrance–Sparrow gives at each texel the constant model of that roughness, bit for
bit; an untextured scene exports no UVs, colours or tangents (the engine's untextured path).
"""

import math
import os
import tempfile

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import cycles_seed_renders, load_addon, polar_material  # noqa: E402

W = H = 32
BLOCK = 8
SEEDS = 4
CYCLES_SPP = 32
POLAR_SPP = 16
BOUNCES = 2
REC709 = np.array([0.2126, 0.7152, 0.0722])
SUN = (0.45, 0.3, 1.0)                       # towards the sun: tilted normals differ in brightness


# --------------------------------------------------------------------------- images

def checker_png(path, dark=40, light=220):
    """A 4×4 8-bit sRGB checker, with a colour in one texel (sRGB decoding and channel order)."""
    from PIL import Image
    a = np.full((4, 4, 3), dark, np.uint8)
    a[(np.add.outer(np.arange(4), np.arange(4)) % 2) == 0] = light
    a[0, 3] = (230, 120, 30)
    Image.fromarray(a).save(path)
    return path


def normal_png(path):
    """A 2×2 Non-Color tangent-space normal map: normals tilted 35° towards +u, −u, +v, −v."""
    from PIL import Image
    t = math.radians(35)
    s, c = math.sin(t), math.cos(t)
    normals = np.array([[[0, s, c], [0, -s, c]],            # top row of the file = v near 1
                        [[s, 0, c], [-s, 0, c]]])
    Image.fromarray(np.round((normals + 1) / 2 * 255).astype(np.uint8)).save(path)
    return path


def height_exr(path):
    """A float height ramp along u: up over the left half, steeper down over the right half."""
    import OpenEXR
    u = (np.arange(256) + 0.5) / 256
    h = np.where(u < 0.5, u, 0.5 - 2 * (u - 0.5)).astype(np.float32)
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {"Y": np.tile(h, (4, 1))}).write(path)
    return path


# --------------------------------------------------------------------------- scenes

def _material(name):
    """A fresh file (empty scene) with a Diffuse BSDF material ``name``: (material, Diffuse node)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    mat = bpy.data.materials.new(name)
    nodes = mat.node_tree.nodes
    for n in list(nodes):
        if n.bl_idname != "ShaderNodeOutputMaterial":
            nodes.remove(n)
    diffuse = nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1.0)
    mat.node_tree.links.new(diffuse.outputs[0], nodes["Material Output"].inputs["Surface"])
    return mat, diffuse


def _image_node(mat, path, colour_space="sRGB", interpolation="Closest", extension="REPEAT"):
    node = mat.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = bpy.data.images.load(path, check_existing=False)
    node.image.colorspace_settings.name = colour_space
    node.interpolation, node.extension = interpolation, extension
    return node


def base_scene(material):
    """The plane with ``material``, the camera framing it, the sun; returns the scene."""
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = W, H
    scene.render.resolution_percentage = 100
    bpy.ops.mesh.primitive_plane_add(size=2.0)
    bpy.context.object.data.materials.append(material)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.type, cam.data.ortho_scale = "ORTHO", 2.0
    cam.location = (0.0, 0.0, 5.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.data.angle = 3.0, 0.0
    import mathutils
    sun.rotation_euler = mathutils.Vector(SUN).to_track_quat("Z", "Y").to_euler()
    scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("World")
    scene.world = world
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    return scene


def checker(tmp):
    mat, diffuse = _material("Checker")
    tex = _image_node(mat, checker_png(os.path.join(tmp, "checker.png")))
    mat.node_tree.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    return base_scene(mat)


def checker_mapped(tmp):
    """The checker through UV Map → Mapping (Point: scale 0.5, rotation 90° about Z, location)."""
    mat, diffuse = _material("Mapped")
    tex = _image_node(mat, checker_png(os.path.join(tmp, "checker_m.png")))
    mapping = mat.node_tree.nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = (0.5, 0.5, 1.0)
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(90))
    mapping.inputs["Location"].default_value = (0.25, 0.5, 0.0)
    uvmap = mat.node_tree.nodes.new("ShaderNodeUVMap")
    links = mat.node_tree.links
    links.new(uvmap.outputs["UV"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    return base_scene(mat)


def vertex_colour(tmp):
    mat, diffuse = _material("Painted")
    attr = mat.node_tree.nodes.new("ShaderNodeVertexColor")
    attr.layer_name = "Paint"
    mat.node_tree.links.new(attr.outputs["Color"], diffuse.inputs["Color"])
    scene = base_scene(mat)
    me = bpy.data.objects["Plane"].data
    layer = me.color_attributes.new("Paint", "BYTE_COLOR", "CORNER")
    colours = [(0.9, 0.1, 0.1, 1), (0.1, 0.8, 0.2, 1), (0.2, 0.2, 0.9, 1), (0.9, 0.9, 0.2, 1)]
    for loop, colour in zip(me.loops, colours):
        layer.data[loop.index].color = colour
    return scene


def normal_map(tmp):
    mat, diffuse = _material("Normals")
    diffuse.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    tex = _image_node(mat, normal_png(os.path.join(tmp, "normal.png")), "Non-Color")
    node = mat.node_tree.nodes.new("ShaderNodeNormalMap")
    mat.node_tree.links.new(tex.outputs["Color"], node.inputs["Color"])
    mat.node_tree.links.new(node.outputs["Normal"], diffuse.inputs["Normal"])
    return base_scene(mat)


def bump(tmp):
    mat, diffuse = _material("Bumped")
    diffuse.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    tex = _image_node(mat, height_exr(os.path.join(tmp, "height.exr")), "Non-Color", "Linear", "EXTEND")
    node = mat.node_tree.nodes.new("ShaderNodeBump")
    node.inputs["Distance"].default_value = 0.6
    node.inputs["Strength"].default_value = 0.9
    mat.node_tree.links.new(tex.outputs["Color"], node.inputs["Height"])
    mat.node_tree.links.new(node.outputs["Normal"], diffuse.inputs["Normal"])
    return base_scene(mat)


def polarising_lambert(tmp):
    """The checker on a Polarising BSDF (Lambert) node's Albedo: the node's own texturable inputs."""
    bpy.ops.wm.read_homefile(use_empty=True)
    mat = polar_material("PolarChecker", "LAMBERT")
    node = next(n for n in mat.node_tree.nodes if n.bl_idname == "PolarShaderNodeBSDF")
    tex = _image_node(mat, checker_png(os.path.join(tmp, "checker_p.png")))
    mat.node_tree.links.new(tex.outputs["Color"], node.inputs["Albedo"])
    return base_scene(mat)


MISSING = "/nonexistent/polar_missing_texture.png"


def missing(tmp):
    mat, diffuse = _material("Missing")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    image = bpy.data.images.new("Gone", 4, 4)
    image.source, image.filepath = "FILE", MISSING
    tex.image = image
    mat.node_tree.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    return base_scene(mat)


SCENES = {"checker": checker, "checker_mapped": checker_mapped, "polarising_lambert": polarising_lambert,
          "vertex_colour": vertex_colour, "normal_map": normal_map, "bump": bump, "missing": missing}


# --------------------------------------------------------------------------- renders

def cycles_renders(scene, tmp):
    return cycles_seed_renders(scene, tmp, CYCLES_SPP, SEEDS, BOUNCES, light_threshold=0.0)


def polar_renders(scene):
    from polar_render.engine.render.renderer import Renderer
    from polar_render.engine.scene.description import RenderSettings
    from polar_render.polar_addon.export.scene import export_scene
    depsgraph = bpy.context.evaluated_depsgraph_get()
    out, warnings = [], []
    for seed in range(SEEDS):
        settings = RenderSettings(spp=POLAR_SPP, max_depth=BOUNCES + 2, seed=seed, spectral="spectral",
                                  polarisation="off")
        engine_scene, warnings = export_scene(depsgraph, scene.camera, W, H, settings)
        out.append(Renderer(engine_scene).render(settings).stokes()[0])
    return np.array(out), warnings


def region_stats(images):
    """Per-region means (regions, …) and their standard errors from the seed-to-seed spread."""
    k = images.shape[0]
    blocks = images.reshape(k, H // BLOCK, BLOCK, W // BLOCK, BLOCK, -1).mean(axis=(2, 4)).reshape(k, -1,
                                                                                              images.shape[-1])
    return blocks.mean(0), blocks.std(0, ddof=1) / math.sqrt(k)


@pytest.fixture(scope="module")
def renders():
    load_addon()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, build in SCENES.items():
            scene = build(tmp)
            polar, warnings = polar_renders(scene)
            results[name] = (region_stats(cycles_renders(scene, tmp)), region_stats(polar), warnings)
    return results


@pytest.mark.parametrize("name", list(SCENES))
def test_luminance_per_region_matches_cycles(renders, name):
    (mc, sc), (mp, sp), _ = renders[name]
    lc, lp = mc @ REC709, mp @ REC709
    se_c, se_p = np.sqrt((sc ** 2) @ REC709 ** 2), np.sqrt((sp ** 2) @ REC709 ** 2)
    # the texture shows: regions differ by far more than the tolerance (the test is not vacuous)
    if name != "missing":
        assert lc.max() > 1.15 * lc.min(), f"{name}: Cycles regions {np.round(lc, 3).tolist()}"
    ratio = lp / lc
    se = ratio * np.sqrt((se_p / lp) ** 2 + (se_c / lc) ** 2)
    bad = np.abs(ratio - 1.0) > 4.0 * se + 0.02
    assert not bad.any(), (f"{name}: Polar/Cycles per region {np.round(ratio, 4).tolist()} "
                           f"± {np.round(se, 4).tolist()}")


def test_textured_scenes_export_without_warnings(renders):
    for name in ("checker", "checker_mapped", "polarising_lambert", "vertex_colour", "normal_map", "bump"):
        assert renders[name][2] == [], name


def test_missing_image_renders_magenta_as_cycles_and_names_the_file(renders):
    (mc, _), (mp, _), warnings = renders["missing"]
    for image in (mc, mp):                          # (regions, RGB): red = blue, no green
        assert np.all(image[:, 1] < 0.03 * image[:, 0])
        np.testing.assert_allclose(image[:, 2], image[:, 0], rtol=0.1)
    assert warnings == [f"material 'Missing': image 'Gone' (file {MISSING!r}) cannot be loaded; it renders "
                        "magenta (1, 0, 1) as in Cycles"]


# --------------------------------------------------------------------------- exported scenes

def _export(scene):
    from polar_render.engine.scene.description import RenderSettings
    from polar_render.polar_addon.export.scene import export_scene
    return export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, W, H, RenderSettings(spp=1))


def test_roughness_texture_gives_the_constant_model_at_each_texel(tmp_path):
    """Principled (dielectric) Roughness from a grey texture → GGX Torrance–Sparrow (Multiscatter GGX, the
    Principled default) with α = r² per point: at each texel centre the exported material is, bit for bit,
    the constant Torrance–Sparrow of α = r² (r = 0 clamps to r ≈ 0.01: α ≥ 1e-4, the least textured
    roughness) and, where r > 0, the exporter's own conversion of a constant Roughness with that texel's
    value."""
    load_addon()
    from polar_render.engine.materials.base import ShadingPoint
    from polar_render.engine.materials.torrance_sparrow import TorranceSparrow
    from polar_render.engine.spectral import WavelengthLookup
    from polar_render.engine.textures import SurfacePoints, VertexAttributes
    from polar_render.engine.materials.roughness import ALPHA_MIN as M_MIN
    from PIL import Image
    r8 = np.array([[0, 60, 120], [180, 230, 255]], np.uint8)
    Image.fromarray(r8).save(tmp_path / "rough.png")
    bpy.ops.wm.read_homefile(use_empty=True)
    mat = bpy.data.materials.new("Rough")
    principled = mat.node_tree.nodes["Principled BSDF"]
    principled.inputs["Base Color"].default_value = (0.3, 0.3, 0.3, 1.0)
    tex = _image_node(mat, str(tmp_path / "rough.png"), "Non-Color")      # Closest: texel values exactly
    mat.node_tree.links.new(tex.outputs["Color"], principled.inputs["Roughness"])
    scene = base_scene(mat)
    exported, warnings = _export(scene)
    assert warnings == []
    plane = next(m for m in exported.meshes if m.name.startswith("Plane"))
    assert plane.uv is not None and plane.tangents is None and plane.colors == {}
    bsdf = exported.materials[plane.materials[0]]
    assert bsdf.varies_over_surface and bsdf.m.source.power == 2.0

    Hh, Ww = r8.shape
    jj, ii = np.meshgrid(np.arange(Hh), np.arange(Ww), indexing="ij")
    uv = np.stack((((ii + 0.5) / Ww).ravel(), ((jj + 0.5) / Hh).ravel()))
    pixels = np.empty(Hh * Ww * 4, np.float32)
    tex.image.pixels.foreach_get(pixels)                   # Blender's own 8-bit → float (row 0 = bottom)
    texel = pixels.reshape(Hh, Ww, 4)[..., 0][jj, ii].ravel()
    np.testing.assert_allclose(texel, (r8[::-1] / 255.0)[jj, ii].ravel(), rtol=1e-6)
    reps = 30
    uv, texel = np.repeat(uv, reps, axis=1), np.repeat(texel, reps)
    n = uv.shape[1]
    rng = np.random.default_rng(7)
    faces = np.arange(3 * n).reshape(n, 3)
    points = SurfacePoints(VertexAttributes(faces, np.repeat(uv.T, 3, axis=0), {}), np.arange(n),
                           np.full(n, 0.25), np.full(n, 0.25))
    n_s = np.tile([[0.0], [0.0], [1.0]], (1, n))
    wo, wi = rng.normal(size=(3, n)), rng.normal(size=(3, n))
    wo[2], wi[2] = np.abs(wo[2]) + 0.05, np.abs(wi[2])
    wo, wi = wo / np.linalg.norm(wo, axis=0), wi / np.linalg.norm(wi, axis=0)
    lam = np.tile([[450.0], [520.0], [600.0], [680.0]], (1, n))
    sp = ShadingPoint(np.zeros((3, n)), n_s, n_s, wo, lam, False, WavelengthLookup(lam), None, points)
    f = bsdf.eval(sp, wi).matrix()
    pdf = bsdf.pdf(sp, wi)
    mat.node_tree.links.remove(principled.inputs["Roughness"].links[0])
    for r in np.unique(texel):
        sel = np.nonzero(texel == r)[0]
        sub = sp.take(sel)
        sub.surface = None
        m = max(float(r) ** 2, M_MIN)        # α = r², clipped to the least textured slope after squaring
        oracles = [TorranceSparrow(bsdf.n, bsdf.k, m, diffuse_albedo=bsdf.albedo, diffuse_weight=1.0,
                                   diffuse_layering="albedo_scaling", distribution="ggx", multiscatter=True)]
        if r > 0:        # the exporter's own constant conversion (roughness 0: the smooth limit, no facets)
            principled.inputs["Roughness"].default_value = float(r)
            oracles.append(_export(scene)[0].materials[plane.materials[0]])
        for i, constant in enumerate(oracles):
            assert not constant.varies_over_surface
            np.testing.assert_array_equal(f[..., sel], constant.eval(sub, wi[:, sel]).matrix(),
                                          err_msg=f"texel {r}, oracle {i}")
            np.testing.assert_array_equal(pdf[sel], constant.pdf(sub, wi[:, sel]))
    assert len(oracles) == 2


def _texel_points(Hh, Ww, reps=20, seed=7):
    """Shading points at the texel centres of an Hh×Ww image (``reps`` directions each), their
    (row, column) texel (row 0 = bottom) and random incident directions."""
    from polar_render.engine.materials.base import ShadingPoint
    from polar_render.engine.spectral import WavelengthLookup
    from polar_render.engine.textures import SurfacePoints, VertexAttributes
    jj, ii = np.meshgrid(np.arange(Hh), np.arange(Ww), indexing="ij")
    uv = np.repeat(np.stack((((ii + 0.5) / Ww).ravel(), ((jj + 0.5) / Hh).ravel())), reps, axis=1)
    n = uv.shape[1]
    rng = np.random.default_rng(seed)
    faces = np.arange(3 * n).reshape(n, 3)
    points = SurfacePoints(VertexAttributes(faces, np.repeat(uv.T, 3, axis=0), {}), np.arange(n),
                           np.full(n, 0.25), np.full(n, 0.25))
    n_s = np.tile([[0.0], [0.0], [1.0]], (1, n))
    wo, wi = rng.normal(size=(3, n)), rng.normal(size=(3, n))
    wo[2], wi[2] = np.abs(wo[2]) + 0.05, np.abs(wi[2])
    wo, wi = wo / np.linalg.norm(wo, axis=0), wi / np.linalg.norm(wi, axis=0)
    lam = np.tile([[450.0], [520.0], [600.0], [680.0]], (1, n))
    sp = ShadingPoint(np.zeros((3, n)), n_s, n_s, wo, lam, False, WavelengthLookup(lam), None, points)
    return sp, np.repeat(jj.ravel(), reps), np.repeat(ii.ravel(), reps), wi


def test_metal_base_colour_texture_gives_the_constant_conversion_at_each_texel(tmp_path):
    """Principled Metallic with an sRGB Base Color image: n, κ per texel by Gulbrandsen; at each texel
    centre the material is, bit for bit, the exporter's conversion of that texel's (linear) colour."""
    load_addon()
    from PIL import Image
    from polar_render.polar_addon.export import images
    Image.fromarray(np.array([[[250, 200, 60], [200, 200, 200]], [[180, 90, 40], [240, 240, 250]]],
                             np.uint8)).save(tmp_path / "metal.png")
    bpy.ops.wm.read_homefile(use_empty=True)
    mat = bpy.data.materials.new("Metal")
    principled = mat.node_tree.nodes["Principled BSDF"]
    principled.inputs["Metallic"].default_value = 1.0
    principled.inputs["Roughness"].default_value = 0.5
    tex = _image_node(mat, str(tmp_path / "metal.png"))
    mat.node_tree.links.new(tex.outputs["Color"], principled.inputs["Base Color"])
    scene = base_scene(mat)
    exported, warnings = _export(scene)
    assert warnings == []
    key = next(m for m in exported.meshes if m.name.startswith("Plane")).materials[0]
    bsdf = exported.materials[key]
    assert bsdf.varies_over_surface and bsdf.name == "torrance_sparrow"
    linear = images._IMAGES[tex.image.name_full][2]            # the image's linear texels (row 0 bottom)
    from polar_render.engine.textures.image import srgb_to_linear  # image.pixels of 8-bit files are not linear
    np.testing.assert_allclose(linear[..., :3], srgb_to_linear(np.asarray(Image.open(tmp_path / "metal.png"))[::-1]
                                                               / 255.0), rtol=1e-6)
    sp, jj, ii, wi = _texel_points(2, 2)
    f = bsdf.eval(sp, wi).matrix()
    mat.node_tree.links.remove(principled.inputs["Base Color"].links[0])
    for j, i in {(j, i) for j, i in zip(jj, ii)}:
        principled.inputs["Base Color"].default_value = (*linear[j, i, :3], 1.0)
        constant = _export(scene)[0].materials[key]
        assert not constant.varies_over_surface
        sel = np.nonzero((jj == j) & (ii == i))[0]
        sub = sp.take(sel)
        sub.surface = None
        np.testing.assert_array_equal(f[..., sel], constant.eval(sub, wi[:, sel]).matrix(), err_msg=f"texel {j, i}")


def test_untextured_scene_exports_no_mesh_attributes():
    """Without textures the exporter adds nothing to the meshes (so the engine takes its untextured
    path and renders bit-identically), and the local arrays keep their four fields."""
    load_addon()
    from polar_render.polar_addon.export.geometry import geometry_arrays
    mat, _ = _material("Plain")
    scene = base_scene(mat)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=(0, 0, 0.5))
    bpy.context.object.data.color_attributes.new("Col", "FLOAT_COLOR", "POINT")
    exported, _ = _export(scene)
    for mesh in exported.meshes:
        assert mesh.uv is None and mesh.colors == {} and mesh.tangents is None, mesh.name
    assert len(geometry_arrays(bpy.data.objects["Plane"].evaluated_get(bpy.context.evaluated_depsgraph_get()))) == 4


def test_normal_map_exports_mikktspace_tangents_placed_and_mirrored():
    """The plane's tangent is +x with sign +1 (MikkTSpace); rotated objects carry rotated tangents and a
    mirroring scale flips the sign (the bitangent stays along +v)."""
    load_addon()
    with tempfile.TemporaryDirectory() as tmp:
        scene = normal_map(tmp)
        plane = bpy.data.objects["Plane"]
        plane.rotation_euler = (0.0, 0.0, math.radians(90))
        mesh = next(m for m in _export(scene)[0].meshes if m.name.startswith("Plane"))
        np.testing.assert_allclose(mesh.tangents, np.tile([0.0, 1.0, 0.0, 1.0], (len(mesh.vertices), 1)), atol=1e-6)
        plane.rotation_euler = (0.0, 0.0, 0.0)
        plane.scale = (-1.0, 1.0, 1.0)
        mesh = next(m for m in _export(scene)[0].meshes if m.name.startswith("Plane"))
        np.testing.assert_allclose(mesh.tangents, np.tile([-1.0, 0.0, 0.0, -1.0], (len(mesh.vertices), 1)),
                                   atol=1e-6)
        assert mesh.uv.shape == (len(mesh.vertices), 2)


def test_viewport_re_reads_a_mesh_when_a_material_gains_a_texture():
    """Incremental export: linking an Image Texture into a material re-reads the meshes using it (now
    with UVs); an untouched image is not read again (cached per image)."""
    load_addon()
    from polar_render.polar_addon import viewport as vp
    from polar_render.polar_addon.export import images
    from polar_render.polar_addon.render_engine import engine_settings
    with tempfile.TemporaryDirectory() as tmp:
        scene = checker(tmp)
        mat = bpy.data.materials["Checker"]
        link = mat.node_tree.nodes["Diffuse BSDF"].inputs["Color"].links[0]
        tex = link.from_node
        mat.node_tree.links.remove(link)
        bpy.context.view_layer.update()
        export = vp.SceneWalk()
        results = []

        def on_update(_scene, depsgraph):
            changes = vp.classify(vp.depsgraph_updates(depsgraph))
            results.append((export.sync(depsgraph, changes, engine_settings(depsgraph.scene, preview=True)),
                            dict(export.counts)))

        first = export.sync(bpy.context.evaluated_depsgraph_get(), None, engine_settings(scene, preview=True))
        assert next(m for m in first.scene.meshes if m.name.startswith("Plane")).uv is None
        bpy.app.handlers.depsgraph_update_post.append(on_update)
        try:
            mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Diffuse BSDF"].inputs["Color"])
            bpy.context.view_layer.update()
            synced, counts = results[-1]
            assert counts["arrays"] == 1 and counts["materials"] == 1 and synced.rebuild
            plane = next(m for m in synced.scene.meshes if m.name.startswith("Plane"))
            assert plane.uv is not None and synced.scene.materials[plane.materials[0]].varies_over_surface
            entry = images._IMAGES[tex.image.name_full]
            mat.node_tree.nodes["Diffuse BSDF"].inputs["Roughness"].default_value = 0.5   # another edit
            bpy.context.view_layer.update()
            synced, counts = results[-1]
            assert counts["arrays"] == 0 and counts["materials"] == 1
            assert images._IMAGES[tex.image.name_full] is entry        # pixels not read again
        finally:
            bpy.app.handlers.depsgraph_update_post.remove(on_update)


def test_other_links_keep_their_own_value_with_one_warning_each():
    """A procedural texture on an input, an object-space normal map and a bump without an image height
    are not exported: the input's own value (one warning naming it), the geometric normals."""
    load_addon()
    from polar_render.polar_addon.export.materials import export_material
    from polar_render.polar_addon.export.geometry import material_alpha
    mat, diffuse = _material("Procedural")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    noise = nodes.new("ShaderNodeTexNoise")
    links.new(noise.outputs["Color"], diffuse.inputs["Color"])
    normal = nodes.new("ShaderNodeNormalMap")
    normal.space = "OBJECT"
    links.new(_image_node(mat, normal_png(os.path.join(tempfile.gettempdir(), "polar_n.png")), "Non-Color")
              .outputs["Color"], normal.inputs["Color"])
    links.new(normal.outputs["Normal"], diffuse.inputs["Normal"])
    warnings = []
    bsdf, _ = export_material(mat, warnings)
    assert material_alpha(mat, warnings) == 1.0
    assert not bsdf.varies_over_surface and bsdf.albedo.value == pytest.approx(0.5)
    assert warnings == [
        "material 'Procedural': input 'Color' of 'Diffuse BSDF' is linked to ShaderNodeTexNoise, which is not "
        "exported; its own value is used",
        "material 'Procedural': Normal Map 'Normal Map' in object space is not supported (tangent space only); "
        "the geometric shading normals are used"]
    bump = nodes.new("ShaderNodeBump")
    links.new(noise.outputs["Fac"], bump.inputs["Height"])
    links.new(bump.outputs["Normal"], diffuse.inputs["Normal"])
    warnings = []
    export_material(mat, warnings)
    material_alpha(mat, warnings)
    assert warnings[-1] == ("material 'Procedural': bump and normal maps (linked Normal input) are not supported; "
                            "the geometric shading normals are used")


def test_textured_export_pickles_for_distributed_workers():
    """The exported textures are engine objects only (a Mapping node is the image's uv_transform), so
    the scene reaches Dask workers that have no bpy."""
    import pickle
    load_addon()
    with tempfile.TemporaryDirectory() as tmp:
        scene = checker_mapped(tmp)
        exported, _ = _export(scene)
    plane = next(m for m in exported.meshes if m.name.startswith("Plane"))
    texture = exported.materials[plane.materials[0]].albedo.source.texture
    assert type(texture).__module__.endswith("engine.textures.texture") and texture.uv_transform is not None
    A, b = texture.uv_transform          # Point mapping: R(90°)·diag(0.5, 0.5)·uv + (0.25, 0.5)
    np.testing.assert_allclose(A, [[0.0, -0.5], [0.5, 0.0]], atol=1e-7)
    np.testing.assert_allclose(b, [0.25, 0.5], atol=1e-7)
    copy = pickle.loads(pickle.dumps(exported))
    uv = np.random.default_rng(3).uniform(size=(2, 50))
    copy_texture = copy.materials[plane.materials[0]].albedo.source.texture
    np.testing.assert_array_equal(copy_texture.lookup(uv), texture.lookup(uv))


def test_alpha_output_is_a_one_channel_texture(tmp_path):
    """An Image Texture's Alpha output on a number input reads the alpha channel (linear, as stored)."""
    load_addon()
    from PIL import Image
    from polar_render.polar_addon.export.images import texture_source
    rgba = np.array([[[255, 0, 0, 51], [0, 255, 0, 204]]], np.uint8)
    Image.fromarray(rgba, "RGBA").save(tmp_path / "alpha.png")
    bpy.ops.wm.read_homefile(use_empty=True)
    mat, diffuse = _material("Alpha")
    tex = _image_node(mat, str(tmp_path / "alpha.png"))
    mat.node_tree.links.new(tex.outputs["Alpha"], diffuse.inputs["Roughness"])
    warnings = []
    source = texture_source(diffuse.inputs["Roughness"], "Alpha", warnings)
    assert warnings == [] and source.texture.channels == 1
    values = source.number_at_uv(np.array([[0.25, 0.75], [0.5, 0.5]]))
    np.testing.assert_allclose(values, [0.2, 0.8], rtol=1e-6)


def test_named_uv_map_point_colours_and_bump_with_normal_map_export(tmp_path):
    """A UV Map node naming the second UV map exports that map; a point-domain colour attribute is
    spread to the corners; a Bump node over a Normal Map gives one ShadingNormal with both."""
    load_addon()
    from polar_render.engine.materials.normal_map import ShadingNormal
    mat, diffuse = _material("Both")
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    tex = _image_node(mat, normal_png(str(tmp_path / "n.png")), "Non-Color")
    uvmap = nodes.new("ShaderNodeUVMap")
    uvmap.uv_map = "Second"
    links.new(uvmap.outputs["UV"], tex.inputs["Vector"])
    normal = nodes.new("ShaderNodeNormalMap")
    normal.uv_map = "Second"
    links.new(tex.outputs["Color"], normal.inputs["Color"])
    height = _image_node(mat, height_exr(str(tmp_path / "h.exr")), "Non-Color", "Linear", "EXTEND")
    links.new(uvmap.outputs["UV"], height.inputs["Vector"])
    bump = nodes.new("ShaderNodeBump")
    links.new(height.outputs["Color"], bump.inputs["Height"])
    links.new(normal.outputs["Normal"], bump.inputs["Normal"])
    links.new(bump.outputs["Normal"], diffuse.inputs["Normal"])
    colour = nodes.new("ShaderNodeVertexColor")
    colour.layer_name = "Dots"
    links.new(colour.outputs["Color"], diffuse.inputs["Color"])
    scene = base_scene(mat)
    me = bpy.data.objects["Plane"].data
    second = me.uv_layers.new(name="Second")
    for loop in me.loops:
        u, v = me.uv_layers["UVMap"].uv[loop.index].vector
        second.uv[loop.index].vector = (0.5 * u + 0.25, v)
    dots = me.color_attributes.new("Dots", "FLOAT_COLOR", "POINT")
    for vertex in me.vertices:
        dots.data[vertex.index].color = (0.1 * vertex.index, 0.2, 0.3, 1.0)
    exported, warnings = _export(scene)
    assert warnings == []
    plane = next(m for m in exported.meshes if m.name.startswith("Plane"))
    corners = np.array([(me.loops[t.loops[c]].vertex_index, t.loops[c]) for t in me.loop_triangles for c in range(3)])
    expected_uv = np.array([tuple(second.uv[loop].vector) for loop in corners[:, 1]])
    np.testing.assert_allclose(plane.uv, expected_uv, atol=1e-7)
    np.testing.assert_allclose(plane.colors["Dots"][:, 0], 0.1 * corners[:, 0], atol=1e-6)
    assert plane.tangents is not None and np.all(plane.tangents[:, 3] == 1.0)
    bsdf = exported.materials[plane.materials[0]]
    assert isinstance(bsdf, ShadingNormal) and bsdf.normal_map is not None and bsdf.bump_map is not None
    assert bsdf.base.varies_over_surface
    assert bsdf.bump_correction                     # Cycles' Material ▸ Settings ▸ Bump Map Correction, default on
    mat.cycles.use_bump_map_correction = False
    mat.update_tag()                                # (the UI tags the material; a script must)
    exported, _ = _export(scene)
    assert not exported.materials[plane.materials[0]].bump_correction


# --------------------------------------------------------------------------- sRGB images between texels

def _transition_scene(tmp, kind):
    """A 2×1 sRGB image (dark | light), Linear, EXTEND, magnified over the plane: the transition
    between the two texel centres (u = ¼ … ¾) spans 16 pixel columns.  ``kind``: "png" (8-bit file),
    "exr" (float file of the same encoded values, tagged sRGB) or "packed" (that EXR packed)."""
    codes = np.array([[[20, 20, 20], [235, 235, 235]]], np.uint8)
    if kind == "png":
        from PIL import Image
        path = os.path.join(tmp, "edge.png")
        Image.fromarray(codes).save(path)
    else:
        import OpenEXR
        path = os.path.join(tmp, f"edge_{kind}.exr")
        OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                     {c: (codes[..., k] / 255.0).astype(np.float32) for k, c in enumerate("RGB")}).write(path)
    mat, diffuse = _material(f"Edge_{kind}")
    tex = _image_node(mat, path, "sRGB", "Linear", "EXTEND")
    if kind == "packed":
        tex.image.pack()
    mat.node_tree.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    return base_scene(mat)


@pytest.fixture(scope="module")
def transition_renders():
    """kind → (Cycles, Polar) per-column-strip luminance (mean, standard error), exported texture."""
    load_addon()
    from polar_render.polar_addon.export.images import _IMAGES
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for kind in ("png", "exr", "packed"):
            scene = _transition_scene(tmp, kind)
            polar, warnings = polar_renders(scene)
            assert warnings == [], warnings
            image = bpy.data.materials[f"Edge_{kind}"].node_tree.nodes["Image Texture"].image
            texture = next(iter(_IMAGES[image.name_full][3].values()))
            stats = []
            for images in (cycles_renders(scene, tmp), polar):          # 8 strips of 4 columns
                lum = images @ REC709
                strips = lum.reshape(SEEDS, H, 8, W // 8).mean(axis=(1, 3))
                stats.append((strips.mean(0), strips.std(0, ddof=1) / math.sqrt(SEEDS)))
            results[kind] = (stats, texture)
    return results


@pytest.mark.parametrize("kind", ["png", "exr", "packed"])
def test_srgb_image_between_texels_matches_cycles(transition_renders, kind):
    """Cycles filters 8-bit sRGB images and sRGB float files on their encoded values and decodes
    after (scene/image.cpp compress_as_srgb); a packed float image reaches it as Blender's decoded
    float buffer and is filtered linearly.  Per strip of 4 columns Polar/Cycles = 1 within 4 standard
    errors + 2 %; the two rules differ by far more in the transition (the test is not vacuous)."""
    ((lc, se_c), (lp, se_p)), texture = transition_renders[kind]
    assert texture.interpolation_space == ("linear" if kind == "packed" else "srgb")
    ratio = lp / lc
    se = ratio * np.sqrt((se_p / lp) ** 2 + (se_c / lc) ** 2)
    bad = np.abs(ratio - 1.0) > 4.0 * se + 0.02
    assert not bad.any(), f"{kind}: Polar/Cycles per strip {np.round(ratio, 4).tolist()} ± {np.round(se, 4).tolist()}"
    from polar_render.engine.textures import ImageTexture
    from polar_render.engine.textures.image import srgb_to_linear
    u = (np.arange(W) + 0.5) / W                   # the strip in the middle of the transition: u ∈ [½, ⅝)
    uv = np.stack((u[16:20], np.full(4, 0.5)))
    encoded = ImageTexture(np.array([[[20], [235]]], np.uint8), "Linear", "EXTEND", interpolation_space="srgb")
    linear = ImageTexture(srgb_to_linear(np.array([[[20], [235]]]) / 255.0), "Linear", "EXTEND")
    other = encoded if kind == "packed" else linear
    assert abs(other.lookup(uv).mean() / texture.lookup(uv).mean() - 1.0) > 0.2
