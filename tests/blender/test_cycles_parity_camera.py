"""Camera, visibility, alpha and geometry of Blender scenes: Polar against Cycles (bpy ships it).

Small diffuse scenes rendered by both with a box pixel filter (Cycles' default is Blackman–Harris
1.5 px); Polar's side goes through the exporter (`export_scene`) and, for alpha, through the
render engine's Combined pass.
"""

import dataclasses
import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import (add_camera, add_plane, add_sphere, empty_scene, load_addon,  # noqa: E402
                                   read_multilayer, render_to_exr, white_world)

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def _engine_settings():
    # the render-engine module is polar_addon/engine.py on this branch, render_engine.py on main
    try:
        from polar_render.polar_addon.render_engine import engine_settings
    except ImportError:
        from polar_render.polar_addon.engine import engine_settings
    return engine_settings


def diffuse(name, albedo):
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    out = mat.node_tree.nodes["Material Output"]
    node = mat.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    node.inputs["Color"].default_value = (albedo, albedo, albedo, 1.0)
    mat.node_tree.nodes.remove(bsdf)
    mat.node_tree.links.new(node.outputs["BSDF"], out.inputs["Surface"])
    return mat


def cycles(scene, path, samples):
    """Combined pass (H, W, 4) of a Cycles render of ``scene`` (box filter, no denoising/clamping)."""
    engine = scene.render.engine
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device, c.samples, c.seed = "CPU", samples, 1
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.pixel_filter_type = "BOX"
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.max_bounces = c.diffuse_bounces = scene.polar.max_bounces
    try:
        return read_multilayer(render_to_exr(scene, path))["Combined"]
    finally:
        scene.render.engine = engine


def polar(scene, spp):
    """(luminance S0 (H, W), its standard error (H, W), export warnings) through the exporter."""
    from polar_render.engine.render.renderer import Renderer
    engine_settings = _engine_settings()
    from polar_render.polar_addon.export.scene import export_scene
    W, H = scene.render.resolution_x, scene.render.resolution_y
    settings = dataclasses.replace(engine_settings(scene), spp=spp)
    exported, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, W, H, settings)
    result = Renderer(exported).render(settings)
    return result.stokes_luminance()[0], result.film.stderr_luminance()[0], warnings


def blocks(img, n):
    """Means over an n × n grid of blocks, (n, n)."""
    H, W = img.shape
    return img[:H // n * n, :W // n * n].reshape(n, H // n, n, W // n).mean(axis=(1, 3))


def assert_regions_agree(ours, se, theirs, n):
    """Block means within 4 standard errors (ours, and the same again for Cycles) + 1 %."""
    bo, bt = blocks(ours, n), blocks(theirs, n)
    H, W = ours.shape
    per = (H // n) * (W // n)
    se_block = np.sqrt(blocks(se ** 2, n) * per) / per
    tol = 4 * np.sqrt(2) * se_block + 0.01 * np.abs(bt) + 1e-4
    assert (np.abs(bo - bt) <= tol).all(), (bo, bt, tol)


def edge_width(img):
    """10–90 % width (px) of the dark→bright step along x, from the row-averaged profile."""
    prof = img.mean(axis=0)
    lo, hi = prof.min(), prof.max()
    x = np.arange(prof.size) + 0.5

    def cross(level):
        v = lo + level * (hi - lo)
        i = int(np.nonzero(prof >= v)[0][0])
        return x[i - 1] + (v - prof[i - 1]) / (prof[i] - prof[i - 1])
    return cross(0.9) - cross(0.1)


def dof_scene(fstop):
    """A black card covering the left half of the view, 8 m away, against a white sky; focus 1 m."""
    scene = empty_scene(64, 24, 64)
    white_world(scene)
    cam = add_camera(scene, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), lens=100.0)
    cam.data.dof.use_dof = True
    cam.data.dof.aperture_fstop = fstop
    cam.data.dof.focus_distance = 1.0
    card = add_plane(20.0, diffuse("Black", 0.0), location=(-10.0, 0.0, -8.0))
    card.name = "Card"
    return scene


def test_depth_of_field_matches_cycles(addon, tmp_path):
    scene = dof_scene(1.0)
    theirs = np.einsum("hwc,c->hw", cycles(scene, str(tmp_path / "dof_cycles"), 128)[..., :3], LUMINANCE)
    ours, se, warnings = polar(scene, 128)
    assert warnings == []
    assert_regions_agree(ours, se, theirs, 4)
    # thin lens: CoC on the focus plane 2R·|z − F|/z, R = 50 mm / 2 = 25 mm·2 (100 mm lens at f/1)
    w_ours, w_theirs = edge_width(ours), edge_width(theirs)
    assert w_ours == pytest.approx(w_theirs, rel=0.15)
    coc_px = 2 * 0.05 * (8 - 1) / 8 / (2 * 1.0 * 18 / 100) * 64
    assert w_theirs > 0.4 * coc_px                    # really blurred (a sharp edge is < 1 px wide)


def test_film_transparent_alpha_matches_cycles(addon, tmp_path):
    scene = empty_scene(48, 32, 64)
    white_world(scene)
    add_camera(scene, (0.0, -6.0, 0.0), (math.pi / 2, 0.0, 0.0))
    add_sphere(1.0, (0.0, 0.0, 0.0), diffuse("Grey", 0.5))
    scene.render.film_transparent = True
    theirs = cycles(scene, str(tmp_path / "alpha_cycles"), 64)
    ours = read_multilayer(render_to_exr(scene, str(tmp_path / "alpha_polar")))["Combined"]
    a_ours, a_theirs = ours[..., 3], theirs[..., 3]
    assert np.allclose(blocks(a_ours, 8), blocks(a_theirs, 8), atol=0.02)
    sky = a_theirs == 0
    # (pixels on the silhouette may differ by a few samples: the renderers jitter differently)
    assert sky.sum() > 0.5 * sky.size and (a_ours[sky] == 0).mean() > 0.97 and a_ours[sky].max() < 0.25
    assert np.allclose(ours[a_ours == 0][:, :3], 0) and np.allclose(theirs[sky][:, :3], 0)   # background black


def visibility_scene():
    scene = empty_scene(48, 32, 64)
    add_camera(scene, (0.0, -7.0, 2.5), (math.radians(75), 0.0, 0.0))
    add_plane(20.0, diffuse("Floor", 0.8))
    ball = add_sphere(1.0, (0.0, 0.0, 1.0), diffuse("Ball", 0.8))
    ball.name = "Ball"
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    sun.data.angle = 0.0
    sun.rotation_euler = (math.radians(30), 0.0, math.radians(40))
    scene.collection.objects.link(sun)
    return scene, ball


@pytest.mark.parametrize("flag", ["visible_camera", "visible_shadow"])
def test_ray_visibility_matches_cycles(addon, tmp_path, flag):
    scene, ball = visibility_scene()
    setattr(ball, flag, False)
    theirs = np.einsum("hwc,c->hw", cycles(scene, str(tmp_path / f"{flag}_cycles"), 128)[..., :3], LUMINANCE)
    ours, se, warnings = polar(scene, 128)
    assert warnings == []
    assert_regions_agree(ours, se, theirs, 4)


def _gn(obj, build):
    mod = obj.modifiers.new("GN", "NODES")
    tree = bpy.data.node_groups.new("GN " + obj.name, "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    mod.node_group = tree
    out = tree.nodes.new("NodeGroupOutput")
    tree.links.new(build(tree).outputs[0], out.inputs[0])


def test_real_file_geometry_renders_with_exact_warnings(addon, tmp_path):
    scene = empty_scene(48, 36, 2)
    white_world(scene)
    add_camera(scene, (0.0, -12.0, 3.0), (math.radians(80), 0.0, 0.0))
    white = diffuse("White", 0.8)
    # geometry-nodes curve (not rendered by Cycles either) and point cloud
    line = bpy.data.objects.new("GN Curve", bpy.data.meshes.new("empty1"))
    scene.collection.objects.link(line)
    _gn(line, lambda t: t.nodes.new("GeometryNodeCurvePrimitiveLine"))
    cloud = bpy.data.objects.new("GN Points", bpy.data.meshes.new("empty2"))
    scene.collection.objects.link(cloud)

    def points(t):
        n = t.nodes.new("GeometryNodePoints")
        n.inputs["Count"].default_value = 20
        n.inputs["Radius"].default_value = 0.1
        return n
    _gn(cloud, points)
    # hair curves, a bevelled curve, text, a metaball, modifiers and collection instances
    hair = bpy.data.hair_curves.new("Hair")
    hair.add_curves([4, 4])
    hair.position_data.foreach_set("vector", np.array([[0, 0, 0], [0, 0, 0.5], [0.1, 0, 1], [0.2, 0, 1.5],
                                                       [1, 0, 0], [1, 0, 0.5], [1.1, 0, 1], [1.2, 0, 1.5]],
                                                      np.float32).ravel())
    scene.collection.objects.link(bpy.data.objects.new("Hair", hair))
    bpy.ops.curve.primitive_bezier_curve_add(location=(2.5, 0.0, 1.0))
    bpy.context.object.data.bevel_depth = 0.1
    bpy.ops.object.text_add(location=(-3.0, 0.0, 0.0), rotation=(math.pi / 2, 0, 0))
    bpy.ops.object.metaball_add(location=(0.0, 0.0, 3.0))
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(-1.5, 0.0, 2.0))
    cube = bpy.context.object
    cube.data.materials.append(white)
    cube.modifiers.new("Subdivision", "SUBSURF")
    cube.modifiers.new("Array", "ARRAY").count = 3
    coll = bpy.data.collections.new("Props")
    coll.objects.link(bpy.data.objects.new("Prop", cube.data))
    label = bpy.data.objects.new("Label", bpy.data.curves.new("Label", "FONT"))
    label.data.body = "P"
    coll.objects.link(label)
    for i in range(3):
        inst = bpy.data.objects.new(f"Instance {i}", None)
        inst.instance_type = "COLLECTION"
        inst.instance_collection = coll
        inst.location = (i - 1.0, 2.0, 0.0)
        scene.collection.objects.link(inst)
    add_plane(30.0, white)
    # every light type (with the options Polar renders as Cycles does), and one option it does not
    for kind, loc, opts in (("POINT", (-2, -2, 2), {"shadow_soft_size": 0.3}),
                            ("SPOT", (2, -2, 3), {"spot_size": math.radians(60), "spot_blend": 0.3}),
                            ("SUN", (0, 0, 5), {"angle": math.radians(5), "energy": 1.0}),
                            ("AREA", (0, -2, 3), {"shape": "DISK", "size": 0.5}),
                            ("POINT", (3, 1, 1), {"use_shadow": False})):
        bpy.ops.object.light_add(type=kind, location=loc)
        for k, v in opts.items():
            setattr(bpy.context.object.data, k, v)
    no_shadow = bpy.context.object.name
    bpy.ops.mesh.primitive_plane_add(size=0.5, location=(0.0, -1.0, 2.5))
    glow = bpy.data.materials.new("Glow")
    emit = glow.node_tree.nodes.new("ShaderNodeEmission")
    glow.node_tree.links.new(emit.outputs[0], glow.node_tree.nodes["Material Output"].inputs["Surface"])
    bpy.context.object.data.materials.append(glow)
    bpy.context.evaluated_depsgraph_get().update()

    engine_settings = _engine_settings()
    from polar_render.polar_addon.export.scene import export_scene
    exported, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 48, 36,
                                      engine_settings(scene))
    shadow_warnings = [w for w in warnings if no_shadow in w]
    assert len(shadow_warnings) == 1 and "shadow" in shadow_warnings[0].lower()
    warnings = [w for w in warnings if w not in shadow_warnings]
    assert warnings == ["object 'GN Curve': geometry-nodes curves without a mesh are not rendered (nor by Cycles): "
                        "convert them with Curve to Mesh",
                        "object 'Text': 4 zero-area faces ignored"]      # Blender's text triangulation
    assert len(exported.lights) >= 5
    names = sorted({m.name.split(":")[0] for m in exported.meshes})
    assert names == ["BézierCurve", "Cube", "GN Points", "Hair", "Label", "Mball", "Plane", "Plane.001", "Prop",
                     "Text", "light"]      # "light": the disk area light's emitter mesh
    assert sum(m.name.startswith("Prop") for m in exported.meshes) == 3            # one per instance
    assert sum(m.name.startswith("Label") for m in exported.meshes) == 3           # (text in an instance: once each)
    assert sum(m.name.startswith("Text") for m in exported.meshes) == 1            # not twice
    assert sum(len(m.faces) for m in exported.meshes if m.name.startswith("GN Points")) == 20 * 80
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "geometry")))
    assert np.isfinite(passes["S0"]).all() and passes["S0"].max() > 0


def test_hair_and_point_cloud_coverage_matches_cycles(addon, tmp_path):
    """Hair tubes and point spheres cover as much of the image as Cycles' curves and points (the
    alpha of a transparent film is the coverage)."""
    scene = empty_scene(64, 48, 32)
    white_world(scene)
    add_camera(scene, (0.0, -4.0, 0.5), (math.radians(90), 0.0, 0.0))
    hair = bpy.data.hair_curves.new("Hair")
    hair.add_curves([4, 4])
    hair.position_data.foreach_set("vector", np.array([[0, 0, 0], [0, 0, 0.5], [0.1, 0, 1], [0.2, 0, 1.5],
                                                       [1, 0, 0], [1, 0, 0.5], [1.1, 0, 1], [1.2, 0, 1.5]],
                                                      np.float32).ravel())
    scene.collection.objects.link(bpy.data.objects.new("Hair", hair))
    cloud = bpy.data.objects.new("GN Points", bpy.data.meshes.new("empty"))
    scene.collection.objects.link(cloud)

    def points(t):
        n = t.nodes.new("GeometryNodePoints")
        n.inputs["Count"].default_value = 1
        n.inputs["Radius"].default_value = 0.2
        n.inputs["Position"].default_value = (-0.8, 0.0, 0.5)
        return n
    _gn(cloud, points)
    # curves that geometry nodes leave on a mesh object: Cycles does not render them (nor does Polar)
    line = bpy.data.objects.new("GN Curve", bpy.data.meshes.new("empty line"))
    scene.collection.objects.link(line)

    def thick_line(t):
        n = t.nodes.new("GeometryNodeCurvePrimitiveLine")
        n.inputs["Start"].default_value, n.inputs["End"].default_value = (-1.5, 0.0, -0.3), (1.5, 0.0, -0.3)
        r = t.nodes.new("GeometryNodeSetCurveRadius")
        r.inputs["Radius"].default_value = 0.05
        t.links.new(n.outputs[0], r.inputs[0])
        return r
    _gn(line, thick_line)
    scene.render.film_transparent = True
    for radius in (None, 0.02):                 # Cycles' default hair radius, then a radius attribute
        if radius is not None:
            hair.attributes.new("radius", "FLOAT", "POINT").data.foreach_set("value", np.full(8, radius, np.float32))
        theirs = cycles(scene, str(tmp_path / "cover_cycles"), 32)[..., 3]
        ours = read_multilayer(render_to_exr(scene, str(tmp_path / "cover_polar")))["Combined"][..., 3]
        assert ours[:, :24].sum() == pytest.approx(theirs[:, :24].sum(), rel=0.03)      # the sphere
        assert ours[:, 24:].sum() == pytest.approx(theirs[:, 24:].sum(), rel=0.06)      # the two hairs
        assert theirs[38:46].sum() == 0 and ours[38:46].sum() == 0                     # no line


def test_equirectangular_panorama_matches_cycles(addon, tmp_path):
    scene, ball = visibility_scene()
    scene.render.resolution_x, scene.render.resolution_y = 64, 32
    cam = scene.camera
    cam.location, cam.rotation_euler = (0.5, -3.0, 1.2), (math.radians(90), 0.0, math.radians(20))
    cam.data.type = "PANO"
    cam.data.panorama_type = "EQUIRECTANGULAR"
    cam.data.longitude_min, cam.data.longitude_max = math.radians(-150), math.radians(150)
    cam.data.latitude_min, cam.data.latitude_max = math.radians(-80), math.radians(60)
    theirs = np.einsum("hwc,c->hw", cycles(scene, str(tmp_path / "pano_cycles"), 64)[..., :3], LUMINANCE)
    ours, se, warnings = polar(scene, 64)
    assert warnings == []
    assert_regions_agree(ours, se, theirs, 4)
    assert_regions_agree(ours, se, theirs, 8)


def test_principled_alpha_and_holdout_coverage_match_cycles(addon, tmp_path):
    scene = empty_scene(48, 32, 64)
    white_world(scene)
    add_camera(scene, (0.0, -6.0, 0.0), (math.pi / 2, 0.0, 0.0))
    veil = bpy.data.materials.new("Veil")
    veil.node_tree.nodes["Principled BSDF"].inputs["Alpha"].default_value = 0.3
    add_sphere(1.0, (-1.2, 0.0, 0.0), veil)
    held = add_sphere(0.8, (1.2, 0.0, 0.0), diffuse("Held", 0.5))
    held.is_holdout = True
    add_plane(30.0, diffuse("Back", 0.5), location=(0.0, 5.0, 0.0)).rotation_euler = (math.pi / 2, 0.0, 0.0)
    theirs = cycles(scene, str(tmp_path / "veil_cycles"), 64)[..., 3]
    ours = read_multilayer(render_to_exr(scene, str(tmp_path / "veil_polar")))["Combined"][..., 3]
    # the veil is alpha 1 (the wall behind it is opaque); the holdout is a hole
    assert np.allclose(blocks(ours, 8), blocks(theirs, 8), atol=0.03)
    scene.render.film_transparent = True
    bpy.data.objects["Plane"].hide_render = True
    theirs = cycles(scene, str(tmp_path / "veil2_cycles"), 64)[..., 3]
    ours = read_multilayer(render_to_exr(scene, str(tmp_path / "veil2_polar")))["Combined"][..., 3]
    # against the transparent sky a ray through the veil crosses two surfaces of alpha 0.3: 1 − 0.7²
    assert np.allclose(blocks(ours, 8), blocks(theirs, 8), atol=0.03)
    assert ours[13:19, 8:14].mean() == pytest.approx(1 - 0.7 ** 2, abs=0.05)


def test_camera_and_visibility_export(addon):
    engine_settings = _engine_settings()
    from polar_render.polar_addon.export.scene import export_scene
    scene = dof_scene(2.8)
    target = bpy.data.objects.new("Focus", None)
    scene.collection.objects.link(target)
    target.location = (0.3, 0.2, -4.5)
    cam = scene.camera.data
    cam.dof.focus_object = target
    cam.dof.aperture_blades = 6
    cam.dof.aperture_rotation = math.radians(10)
    scene.render.use_motion_blur = True
    card = bpy.data.objects["Card"]
    card.visible_glossy = False
    mat = card.material_slots[0].material
    bump = mat.node_tree.nodes.new("ShaderNodeBump")
    diffuse_node = mat.node_tree.nodes["Diffuse BSDF"]
    mat.node_tree.links.new(bump.outputs["Normal"], diffuse_node.inputs["Normal"])
    exported, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 64, 24,
                                      engine_settings(scene))
    c = exported.camera
    assert c.aperture_radius == pytest.approx(0.1 / (2 * 2.8), rel=1e-6)       # Cycles: lens·1e-3 / (2 N)
    assert c.focus_distance == pytest.approx(4.5, rel=1e-6)                   # depth along the view axis
    assert (c.aperture_blades, round(c.aperture_rotation_deg, 4)) == (6, 10.0)
    assert warnings == [
        "motion blur is not simulated: the image shows the scene at the current frame",
        "object 'Card': visibility to only some of diffuse, glossy and transmission rays is not supported; "
        "it is visible to all of them",
        "material 'Black': bump and normal maps (linked Normal input) are not supported; the geometric "
        "shading normals are used"]
    card.visible_camera = card.visible_shadow = False
    card.visible_diffuse = card.visible_transmission = False
    card.is_holdout = True
    exported, _ = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 64, 24, engine_settings(scene))
    mesh = next(m for m in exported.meshes if m.name.startswith("Card"))
    flags = (mesh.visible_camera, mesh.visible_shadow, mesh.visible_indirect, mesh.holdout)
    assert flags == (False, False, False, True)


def test_polar_panels_show_the_cycles_settings_it_reads(addon):
    """Film ▸ Transparent, the panorama ranges and Object ▸ Visibility have Polar panels (Blender shows
    its own only for Cycles/EEVEE); drawn here into a recording layout."""
    from types import SimpleNamespace

    class Layout:
        def __init__(self):
            self.props = []

        def prop(self, data, name, **kw):
            assert hasattr(data, name), name
            self.props.append(name)

        def column(self, **kw):
            return self

        def separator(self):
            pass

        def label(self, **kw):
            pass

    scene, ball = visibility_scene()
    scene.camera.data.type = "PANO"
    scene.camera.data.panorama_type = "EQUIRECTANGULAR"
    ctx = SimpleNamespace(engine="POLAR", scene=scene, camera=scene.camera.data, object=ball)
    drawn = {}
    for name in ("POLAR_PT_film", "POLAR_PT_camera_panorama", "POLAR_PT_object_visibility"):
        panel = getattr(bpy.types, name)
        assert panel.poll(ctx) and not panel.poll(SimpleNamespace(**{**vars(ctx), "engine": "CYCLES"}))
        fake = SimpleNamespace(layout=Layout())
        panel.draw(fake, ctx)
        drawn[name] = fake.layout.props
    assert drawn["POLAR_PT_film"] == ["film_transparent"]
    assert drawn["POLAR_PT_camera_panorama"] == ["panorama_type", "latitude_min", "latitude_max", "longitude_min",
                                                 "longitude_max"]
    visibility = drawn["POLAR_PT_object_visibility"]
    assert "visible_camera" in visibility and "visible_shadow" in visibility and "is_holdout" in visibility
