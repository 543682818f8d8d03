"""Cycles' Light Paths read by Polar (polar_addon.render_engine.cycles_light_paths): small bpy scenes rendered by
Cycles and by Polar with one switch set in scene.cycles, which both renderers read, and the S0 luminance
compared by the asset suite's rule (tests/support/asset_parity.compare: per 16-pixel block, 4 standard errors
from independent seeds + 2 % of Cycles' mean, ≥ 95 % of the blocks).  Each case also shows that the switch
changes Polar's image (so the parity is not the parity of an ignored setting).  Everything else as the parity
suite runs Cycles (box filter, no denoising, no light tree, every other light-path limit off)."""

import tempfile

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import add_camera, add_plane, add_sphere, light_paths_off, load_addon, white_world  # noqa: E402
from tests.support import asset_parity as ap  # noqa: E402

W, H = 96, 64
SEEDS = 4
SPP = 32
BOUNCES = 8


def shader(name, idname, inputs):
    mat = bpy.data.materials.new(name)
    nodes = mat.node_tree.nodes
    for n in list(nodes):
        if n.bl_idname != "ShaderNodeOutputMaterial":
            nodes.remove(n)
    node = nodes.new(idname)
    for key, value in inputs.items():
        node.inputs[key].default_value = value
    mat.node_tree.links.new(node.outputs[0], nodes[0].inputs["Surface"])
    return mat


def diffuse(colour=0.8):
    return shader("Diffuse", "ShaderNodeBsdfDiffuse", {"Color": (colour, colour, colour, 1.0)})


def emitter(strength):
    return shader("Lamp", "ShaderNodeEmission", {"Color": (1, 1, 1, 1), "Strength": strength})


def base(world=0.0):
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = W, H, 100
    white_world(scene, world)
    return scene


def room():
    """Camera inside a closed grey room (6 × 6 × 3 m) lit by a ceiling panel: light bounces many times."""
    scene = base()
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, 1.5))
    box = bpy.context.object
    box.scale = (6, 6, 3)
    box.data.materials.append(diffuse(0.7))
    add_plane(1.0, emitter(20.0), location=(0, 0, 2.99)).rotation_euler = (np.pi, 0, 0)
    add_camera(scene, (0, -2.8, 1.2), (np.radians(85), 0, 0), lens=18)
    return scene


def metal_on_floor():
    """A mirror-like glossy sphere on a diffuse floor under a white sky: its reflection of the floor is a
    glossy → diffuse path, that of the sky glossy → background."""
    scene = base(world=1.0)
    add_plane(20.0, diffuse(0.6))
    add_sphere(1.0, (0, 0, 1.0), shader("Metal", "ShaderNodeBsdfGlossy", {"Color": (0.9, 0.9, 0.9, 1.0),
                                                                         "Roughness": 0.05}))
    add_camera(scene, (0, -5.5, 2.5), (np.radians(72), 0, 0), lens=40)
    return scene


def mirror_corridor():
    """The camera at the mouth of a 4 m corridor between two white mirrors (Glossy, roughness 0) 1 m apart, under a
    white sky of radiance 2: a pixel sees the sky after k ≤ 4 reflections, radiance 2 per sample whatever k (no
    light sampling, MIS weight 1 after a mirror, no Russian roulette: Cycles' throughput stays 1, Polar's roulette
    starts at the fifth vertex), so a clamp's result does not depend on the renderers' sampling strategies:
    k = 0 and 1 are Cycles' direct light, k ≥ 2 its indirect light."""
    scene = base(world=2.0)
    metal = shader("Mirror", "ShaderNodeBsdfGlossy", {"Color": (1.0, 1.0, 1.0, 1.0), "Roughness": 0.0})
    bottom = add_plane(12.0, metal)
    top = add_plane(12.0, metal, location=(0, 0, 1.0))
    top.rotation_euler = (np.pi, 0, 0)
    for plate in (bottom, top):
        plate.scale = (1.0, 4.0 / 12.0, 1.0)
    add_camera(scene, (0, -2.0, 0.5), (np.radians(90), 0, 0), lens=20)
    return scene


def glass_on_floor():
    """A smooth glass sphere on a diffuse floor under a small bright panel, black sky: the floor under the
    sphere is lit through the glass (a refractive caustic) and by it, its surroundings by the panel."""
    scene = base()
    add_plane(20.0, diffuse(0.8))
    add_sphere(0.8, (0, 0, 0.8), shader("Glass", "ShaderNodeBsdfGlass", {"Roughness": 0.0, "IOR": 1.5}))
    lamp = add_plane(1.0, emitter(40.0), location=(0, 0, 4.0))
    lamp.rotation_euler = (np.pi, 0, 0)
    add_camera(scene, (0, -5.0, 3.2), (np.radians(58), 0, 0), lens=35)
    return scene


def render_both(scene, edit):
    """(Cycles (seeds, H, W, 3), Polar S0 (seeds, H, W, 3)) with the parity settings and then ``edit(cycles)``
    applied to scene.cycles, which Polar's exporter reads as F12 does (engine_settings)."""
    load_addon()
    from polar_render.engine.render.renderer import Renderer
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    ap.cycles_settings(scene, SPP, BOUNCES)
    edit(scene.cycles)
    cycles = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(SEEDS):
            scene.cycles.seed = seed
            scene.render.filepath = f"{tmp}/cycles_{seed}"
            bpy.ops.render.render(write_still=True)
            from tests.blender_support import read_multilayer
            cycles.append(read_multilayer(scene.render.filepath + ".exr")["Combined"][..., :3])
    scene.render.engine = "POLAR"
    p = scene.polar
    p.samples, p.max_bounces, p.seed, p.spectral, p.polarisation = SPP, BOUNCES, 0, "RGB", "AUTO"
    p.use_adaptive_sampling = False
    settings = engine_settings(scene)
    engine_scene, _ = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, W, H, settings)
    renderer = Renderer(engine_scene)
    import dataclasses
    polar = [renderer.render(dataclasses.replace(settings, seed=s)).stokes()[0] for s in range(SEEDS)]
    return np.array(cycles), np.array(polar), settings


def polar_only(scene, edit):
    """Polar's S0 (H, W, 3), seed 0, with the parity settings and ``edit`` (the switch's effect on Polar)."""
    from polar_render.engine.render.renderer import Renderer
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    light_paths_off(scene, BOUNCES)
    edit(scene.cycles)
    settings = engine_settings(scene)
    engine_scene, _ = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, W, H, settings)
    return Renderer(engine_scene).render(settings).stokes()[0]


def set_(**values):
    def edit(c):
        for k, v in values.items():
            setattr(c, k, v)
    return edit


CASES = {
    # name: (scene, the switch, the engine setting it becomes, Polar ÷ off at least this far from 1)
    "diffuse bounces 1 in a room": (room, set_(diffuse_bounces=1), ("max_diffuse_bounces", 1), 0.1),
    "glossy bounces 0, metal on a floor": (metal_on_floor, set_(glossy_bounces=0), ("max_glossy_bounces", 0), 0.02),
    "clamp direct 1.5, indirect 0.5 between mirrors": (mirror_corridor, set_(sample_clamp_direct=1.5,
                                                                              sample_clamp_indirect=0.5),
                                                        ("clamp_indirect", 0.5), 0.1),
    "no refractive caustics under glass": (glass_on_floor, set_(caustics_refractive=False),
                                           ("caustics_refractive", False), 0.01),
}


@pytest.mark.parametrize("name", list(CASES))
def test_light_path_switch_matches_cycles(name):
    build, edit, (field, value), change = CASES[name]
    scene = build()
    cycles, polar, settings = render_both(scene, edit)
    assert getattr(settings, field) == value
    report = ap.CaseReport(name, "light paths", SPP, SEEDS, W, H)
    ap.compare(cycles, polar, np.ones((H, W), bool), report)
    print(report.line())
    assert report.ok, (f"{report.line()}\nfailing blocks (row, column, Polar ÷ Cycles, tolerance): "
                       f"{[(i, j, round(r, 3), round(t, 3)) for i, j, r, t in report.failing]}")
    off = polar_only(scene, lambda c: None).mean()
    print(f"{name}: Polar with the switch ÷ without {polar.mean() / off:.3f}")
    assert abs(polar.mean() / off - 1) > change, (polar.mean(), off)


def test_filter_glossy_is_reported_not_dropped():
    """Polar does not blur glossy lobes: a scene with Filter Glossy on says so in the render's warnings."""
    load_addon()
    from polar_render.polar_addon.render_engine import light_path_warnings
    scene = metal_on_floor()
    light_paths_off(scene, BOUNCES)
    assert light_path_warnings(scene) == []
    scene.cycles.blur_glossy = 1.0
    (warning,) = light_path_warnings(scene)
    assert "Filter Glossy 1" in warning and "not applied" in warning
