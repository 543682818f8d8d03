"""Blender volumes (polar_addon.export.volumes) against Cycles' own renders, and what the exporter makes of each
volume node.

Parity scenes (Cycles CPU with the parity settings of tests/support/asset_parity.py, both renderers reading the
same Light Paths, Volume bounces included; RGB mode): the issue's new-user case — a cube whose material is only a
Volume Scatter (Henyey–Greenstein g = 0.3) on a grey floor under a sun, Cycles' default Volume bounces 0 — a
Principled Volume cube (g = 0.5, an absorption colour, Volume bounces 3) and a World volume lit by a point lamp.
The rule is the asset rule (``compare``): per 16 × 16 block |m_P − m_C| ≤ 4σ + 2 % m_C in ≥ 95 % of the blocks,
here over every block of the image.
"""

import math
import os
import tempfile

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import load_addon, read_multilayer  # noqa: E402
from tests.support import asset_parity as ap  # noqa: E402

SIZE = 64
SPP, SEEDS = 16, 4


def _material(name, kind, inputs=None, phase=None, surface=False):
    compat = load_addon().polar_addon.compat
    mat = bpy.data.materials.new(name)
    tree = compat.ensure_node_tree(mat)
    for node in list(tree.nodes):
        if node.type != "OUTPUT_MATERIAL":
            tree.nodes.remove(node)
    out = tree.nodes[0]
    node = tree.nodes.new(kind)
    if phase is not None:
        node.phase = phase
    for k, v in (inputs or {}).items():
        node.inputs[k].default_value = v
    tree.links.new(node.outputs[0], out.inputs["Volume"])
    return mat, node


def _scene(make_material=None, world_volume=None, lamp="sun"):
    """The floor, camera and lamp, and a cube of the material ``make_material()`` makes (after the reset)."""
    from mathutils import Vector
    scene = ap.reset(SIZE, SIZE)
    compat = load_addon().polar_addon.compat
    bpy.ops.mesh.primitive_plane_add(size=8.0)
    floor = bpy.context.object
    grey = bpy.data.materials.new("Floor")
    compat.ensure_node_tree(grey)
    grey.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.5, 0.5, 0.5, 1.0)
    grey.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 1.0
    floor.data.materials.append(grey)
    if make_material is not None:
        bpy.ops.mesh.primitive_cube_add(size=1.5, location=(0.0, 0.0, 0.8))   # not coplanar with the floor
        bpy.context.object.data.materials.append(make_material()[0])
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0.0, -5.0, 2.5)
    cam.rotation_euler = (Vector((0.0, 0.0, 0.6)) - cam.location).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(cam)
    scene.camera = cam
    world = bpy.data.worlds.new("World")
    scene.world = world
    compat.ensure_node_tree(world)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    if world_volume is not None:
        node = world.node_tree.nodes.new("ShaderNodeVolumeScatter")
        for k, v in world_volume.items():
            node.inputs[k].default_value = v
        world.node_tree.links.new(node.outputs[0], world.node_tree.nodes["World Output"].inputs["Volume"])
    if lamp == "sun":
        sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
        sun.data.energy = 3.0
        sun.rotation_euler = (math.radians(40.0), 0.0, math.radians(30.0))
    else:
        sun = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "POINT"))
        sun.data.energy, sun.data.shadow_soft_size = 300.0, 0.1
        sun.location = (1.0, -1.0, 2.0)
    scene.collection.objects.link(sun)
    return scene


def _parity(scene, volume_bounces, bounces=4, seeds=SEEDS):
    """The asset rule's report over every block, and Polar's warnings (``seeds`` renders a side)."""
    report = ap.CaseReport("volume", "sun", SPP, seeds, SIZE, SIZE)
    cyc = []
    ap.cycles_settings(scene, SPP, bounces)
    scene.cycles.volume_bounces = volume_bounces
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(seeds):
            scene.cycles.seed = seed
            scene.render.filepath = os.path.join(tmp, f"cycles_{seed}")
            bpy.ops.render.render(write_still=True)
            cyc.append(read_multilayer(scene.render.filepath + ".exr")["Combined"][..., :3])
    renderer, settings, report.warnings = ap.export_polar(scene, SPP, bounces)
    assert settings.max_volume_bounces == volume_bounces
    stokes = ap.render_polar(renderer, settings, seeds)
    ap.compare(np.array(cyc), stokes[:, 0], np.ones((SIZE, SIZE), bool), report)
    return report


def test_fog_box_on_a_floor_matches_cycles():
    """The issue's new-user case (was 0.51× Cycles' luminance, silently): Volume Scatter g = 0.3 alone in a cube."""
    scene = _scene(lambda: _material("Fog", "ShaderNodeVolumeScatter", {"Density": 1.2, "Anisotropy": 0.3,
                                                                         "Color": (0.9, 0.8, 0.7, 1.0)}))
    report = _parity(scene, volume_bounces=0)
    assert report.warnings == []
    assert report.fraction >= ap.PASS_FRACTION, (report.luminance_ratio, report.failing)
    assert abs(report.luminance_ratio - 1.0) < 0.03, report.luminance_ratio


def test_principled_volume_matches_cycles():
    scene = _scene(lambda: _material("Smoke", "ShaderNodeVolumePrincipled",
                                     {"Density": 1.5, "Anisotropy": 0.5, "Color": (0.7, 0.75, 0.8, 1.0),
                                      "Absorption Color": (0.3, 0.2, 0.1, 1.0)}))
    # 8 seeds: with 4 (σ from 3 degrees of freedom) one block of 16 failed by chance after the first vertex's
    # numbers changed (2026-12-07, "sobol" drawing Cycles' light and BSDF sets): 16/16 at 8 and at 16 seeds, Y 1.001
    report = _parity(scene, volume_bounces=3, seeds=8)
    assert report.warnings == []
    assert report.fraction >= ap.PASS_FRACTION, (report.luminance_ratio, report.failing)


def test_emitting_principled_volume_matches_cycles():
    """A glowing smoke cube: Emission Strength 1.5 × an orange Emission Color over a scattering Principled
    Volume (density 0.8), the sun and floor as in the other cases."""
    scene = _scene(lambda: _material("Glow", "ShaderNodeVolumePrincipled",
                                     {"Density": 0.8, "Anisotropy": 0.3, "Color": (0.6, 0.6, 0.6, 1.0),
                                      "Emission Strength": 1.5, "Emission Color": (1.0, 0.45, 0.1, 1.0)}))
    report = _parity(scene, volume_bounces=2)
    assert report.warnings == []
    assert report.fraction >= ap.PASS_FRACTION, (report.luminance_ratio, report.failing)


def test_blackbody_principled_volume_matches_cycles():
    """Fire: Blackbody Intensity 1 at Temperature 2200 K (no temperature grid on a mesh: the socket's value, as
    Cycles), in a thin absorbing smoke."""
    scene = _scene(lambda: _material("Flame", "ShaderNodeVolumePrincipled",
                                     {"Density": 0.5, "Color": (0.3, 0.3, 0.3, 1.0), "Blackbody Intensity": 1.0,
                                      "Temperature": 2200.0}))
    report = _parity(scene, volume_bounces=1)
    assert report.warnings == []
    assert report.fraction >= ap.PASS_FRACTION, (report.luminance_ratio, report.failing)


def test_world_volume_matches_cycles():
    """World Output ▸ Volume is the world medium; a point lamp inside it (a sun does not reach through it, in
    either renderer)."""
    report = _parity(_scene(None, world_volume={"Density": 0.08, "Anisotropy": -0.2}, lamp="point"),
                     volume_bounces=1)
    assert report.warnings == []
    assert report.fraction >= ap.PASS_FRACTION, (report.luminance_ratio, report.failing)


# --------------------------------------------------------------------------- the exporter, node by node

def _interior(mat, warnings=None):
    addon = load_addon()
    bsdf, _ = addon.polar_addon.export.materials.export_material(mat, warnings if warnings is not None else [])
    return bsdf.interior


@pytest.mark.parametrize("phase, model", [("HENYEY_GREENSTEIN", "henyey_greenstein"), ("RAYLEIGH", "rayleigh"),
                                          ("FOURNIER_FORAND", "fournier_forand"), ("DRAINE", "draine"),
                                          ("MIE", "cycles_mie")])
def test_every_volume_scatter_phase(phase, model):
    ap.reset(8, 8)
    mat, node = _material("S", "ShaderNodeVolumeScatter", {"Density": 2.0, "Color": (0.5, 1.0, 0.25, 1.0)}, phase)
    warnings = []
    interior = _interior(mat, warnings)
    assert warnings == []
    assert interior.phase.name == model
    assert np.allclose(interior.scattering.linear_srgb(), [1.0, 2.0, 0.5], rtol=1e-3)
    assert np.allclose(interior.absorption.linear_srgb(), 0.0, atol=1e-9)
    if phase == "RAYLEIGH":           # the polarising Rayleigh, δ = 0 (Cycles' S0): DoLP 1 at 90°
        from polar_render.engine.materials.flags import BSDFFlags
        assert interior.phase.flags.has(BSDFFlags.POLARISING) and interior.phase.depolarisation == 0.0
        M = interior.phase.matrix(0.0)
        assert abs(M[1, 0] / M[0, 0]) == pytest.approx(1.0, abs=1e-12)


def test_mie_option_exports_lorenz_mie():
    from polar_render.polar_addon.export import volumes
    ap.reset(8, 8)
    mat, node = _material("M", "ShaderNodeVolumeScatter", {"Diameter": 2.0}, "MIE")
    token = volumes.MIE_MODEL.set("lorenz_mie")
    try:
        phase = _interior(mat).phase
    finally:
        volumes.MIE_MODEL.reset(token)
    assert phase.name == "mie" and phase.radius == pytest.approx(1.0)


def test_mixed_volumes_add_coefficients_and_mix_phases():
    """Add Shader of Volume Absorption and a Mix Shader (fac 0.25) of HG and Rayleigh scatter."""
    ap.reset(8, 8)
    mat, hg = _material("Mix", "ShaderNodeVolumeScatter", {"Density": 4.0, "Anisotropy": 0.5})
    tree = mat.node_tree
    ray = tree.nodes.new("ShaderNodeVolumeScatter")
    ray.phase = "RAYLEIGH"
    ray.inputs["Density"].default_value = 2.0
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = 0.25
    tree.links.new(hg.outputs[0], mix.inputs[1])
    tree.links.new(ray.outputs[0], mix.inputs[2])
    absorb = tree.nodes.new("ShaderNodeVolumeAbsorption")
    absorb.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1.0)
    add = tree.nodes.new("ShaderNodeAddShader")
    tree.links.new(mix.outputs[0], add.inputs[0])
    tree.links.new(absorb.outputs[0], add.inputs[1])
    tree.links.new(add.outputs[0], tree.nodes[0].inputs["Volume"])
    warnings = []
    interior = _interior(mat, warnings)
    assert warnings == []            # grey colours: the mixture by mean σ_s is Cycles' per-channel one
    s_hg, s_ray = 0.75 * 4.0 * 0.8, 0.25 * 2.0 * 0.8
    assert np.allclose(interior.scattering.linear_srgb(), s_hg + s_ray, rtol=1e-3)
    assert np.allclose(interior.absorption.linear_srgb(), 0.5, rtol=1e-3)
    phase = interior.phase
    assert phase.name == "mixture" and np.allclose(phase.weights, [s_hg / (s_hg + s_ray), s_ray / (s_hg + s_ray)])
    from polar_render.engine.media.henyey_greenstein import hg_density
    mu = np.linspace(-1, 1, 5)
    expect = phase.weights[0] * hg_density(mu, 0.5) + phase.weights[1] * 3 / (16 * np.pi) * (1 + mu ** 2)
    assert np.allclose(phase.matrix(mu)[:, 0, 0], expect, rtol=1e-12)
    assert np.all(phase.matrix(0.0)[1, 0] != 0)          # the Rayleigh part polarises


def test_emission_and_blackbody_are_exported_as_cycles_defines_them():
    """Principled Volume: ε = Emission Strength·Emission Color + Tint·σ/π·10⁻⁶·mix(1, T⁴, Blackbody Intensity)·
    colour(T), not scaled by Density, no warning; Volume Coefficients: ε its Emission Coefficients; the Color
    Attribute on a mesh (where the attribute does not exist: Cycles uses Color alone) no warning."""
    ap.reset(8, 8)
    load_addon()
    from polar_render.polar_addon.export import blackbody
    mat, node = _material("Fire", "ShaderNodeVolumePrincipled",
                          {"Density": 3.0, "Emission Strength": 2.0, "Emission Color": (1.0, 0.5, 0.25, 1.0),
                           "Blackbody Intensity": 0.5, "Temperature": 1800.0,
                           "Blackbody Tint": (1.0, 0.8, 0.6, 1.0)})
    warnings = []
    interior = _interior(mat, warnings)
    assert warnings == [] and interior.scatters and interior.emits
    T4 = 1800.0 ** 4
    bb = np.array([1.0, 0.8, 0.6]) * 5.670373e-8 * 1e-6 / np.pi * (0.5 + 0.5 * T4) * blackbody.colour(1800.0)
    assert np.allclose(interior.emission.linear_srgb(), 2.0 * np.array([1.0, 0.5, 0.25]) + bb, rtol=1e-6)
    assert bb[:2].min() > 0 and bb[0] > bb[1] > bb[2] >= 0     # red-hot (Cycles: blue −0.02·… at 1800 K, 0 here)
    mat, node = _material("Glow", "ShaderNodeVolumeCoefficients", {"Emission Coefficients": (1.0, 0.0, 0.5)})
    warnings = []
    assert np.allclose(_interior(mat, warnings).emission.linear_srgb(), [1.0, 0.0, 0.5]) and warnings == []
    mat, node = _material("Tinted", "ShaderNodeVolumePrincipled", {"Color Attribute": "color"})
    warnings = []
    assert np.allclose(_interior(mat, warnings).scattering.linear_srgb(), node.inputs["Color"].default_value[:3],
                       rtol=1e-3) and warnings == []


def test_linked_density_keeps_its_value_with_one_warning():
    ap.reset(8, 8)
    mat, node = _material("Cloud", "ShaderNodeVolumeScatter", {"Density": 0.5})
    noise = mat.node_tree.nodes.new("ShaderNodeTexNoise")
    mat.node_tree.links.new(noise.outputs[0], node.inputs["Density"])
    warnings = []
    interior = _interior(mat, warnings)
    assert len(warnings) == 1 and "Density" in warnings[0]
    assert np.allclose(interior.scattering.linear_srgb(), 0.4, rtol=1e-3)


def _export(scene):
    load_addon()
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    return export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 8, 8, engine_settings(scene))


def _volume_object(scene, name, path, mat, location=(0.0, 0.0, 0.0)):
    """(box mesh, Interior) of a Volume object ``name`` reading the file ``path`` with ``mat``, exported without a
    warning about it."""
    vol = bpy.data.volumes.new(name)
    vol.filepath = path
    obj = bpy.data.objects.new(name, vol)
    obj.location = location
    obj.data.materials.append(mat)
    scene.collection.objects.link(obj)
    engine_scene, warnings = _export(scene)
    assert not any(name in w for w in warnings), warnings
    box = next(m for m in engine_scene.meshes if m.name.startswith(name))
    return box, engine_scene.materials[box.materials[0]].interior


def test_volume_object_reads_its_openvdb_grid(tmp_path):
    """A file-backed Volume object: its density grid, placed by the object's matrix, × Principled's Density."""
    load_addon()
    from polar_render.polar_addon import compat
    openvdb = compat.openvdb_module()
    assert openvdb is not None              # it ships inside bpy 4.5–5.3
    grid = openvdb.FloatGrid()
    grid.name = "density"
    values = np.arange(4 * 3 * 2, dtype=np.float32).reshape(4, 3, 2) / 10.0
    grid.copyFromArray(values, ijk=(2, 0, 1))
    grid.transform = openvdb.createLinearTransform(voxelSize=0.25)
    path = str(tmp_path / "smoke.vdb")
    openvdb.write(path, grids=[grid])
    scene = _scene(None)
    mat, node = _material("Smoke", "ShaderNodeVolumePrincipled", {"Density": 2.0, "Color": (1.0, 1.0, 1.0, 1.0)})
    box, interior = _volume_object(scene, "Smoke", path, mat, location=(1.0, 0.0, 0.0))
    assert box.alpha == 0.0
    g = interior.grid
    assert g.values.shape == (4, 3, 2)
    # voxel (i, j, k) at index (2 + i, j, 1 + k) · 0.25, + the object's location
    assert np.allclose(g.lo, [1.5, 0.0, 0.25]) and np.allclose(g.hi, [1.5 + 0.75, 0.5, 0.5])
    assert np.allclose(g.values, values, atol=1e-7)
    assert np.allclose(interior.scattering.linear_srgb(), 2.0, rtol=1e-3)


def test_generated_volume_object_warns_once():
    scene = _scene(None)
    vol = bpy.data.volumes.new("Generated")
    obj = bpy.data.objects.new("Generated", vol)
    mat, _ = _material("Smoke", "ShaderNodeVolumePrincipled")
    obj.data.materials.append(mat)
    scene.collection.objects.link(obj)
    _, warnings = _export(scene)
    mine = [w for w in warnings if "Generated" in w]
    assert len(mine) == 1 and "not read from a file" in mine[0]


def test_volume_object_blackbody_reads_its_temperature_grid(tmp_path):
    """Fire from a file: Principled Volume's Temperature Attribute reads the object's "temperature" grid; the
    emission grid holds Cycles' blackbody emission of Temperature × that grid at the density grid's nodes (plus
    the constant Emission), no warning."""
    load_addon()
    from polar_render.polar_addon import compat
    from polar_render.polar_addon.export import blackbody
    openvdb = compat.openvdb_module()
    density = np.full((3, 3, 3), 0.5, np.float32)
    temperature = np.linspace(0.5, 1.5, 27, dtype=np.float32).reshape(3, 3, 3)   # × 1500 K: 750–2250 K
    path = _write_vdb(openvdb, str(tmp_path / "fire.vdb"), [("density", density, openvdb.FloatGrid),
                                                            ("temperature", temperature, openvdb.FloatGrid)], (0, 0, 0))
    scene = _scene(None)
    mat, node = _material("Fire", "ShaderNodeVolumePrincipled",
                          {"Blackbody Intensity": 1.0, "Temperature": 1500.0, "Emission Strength": 0.1})
    _, interior = _volume_object(scene, "Fire", path, mat)
    assert interior.emission is None and interior.emits
    values = np.stack([c.values for c in interior.emission_grid.channels], axis=-1)
    expected = 0.1 * np.ones(3) + blackbody.emission(1500.0 * temperature.astype(np.float64), 1.0, np.ones(3))
    assert np.allclose(values, expected, rtol=1e-5)


def test_volume_object_colour_attribute_reads_its_vector_grid(tmp_path):
    """Smoke from a file with a colour: Principled Volume's Color Attribute reads the object's Vec3 "color" grid
    (written with Blender's openvdb), and the medium's colour grid holds Color × that grid at the density grid's
    nodes, σ_s = Density, σ_a = Density·(1 − √Absorption Color) (Cycles' svm_node_principled_volume), no warning."""
    load_addon()
    from polar_render.polar_addon import compat
    openvdb = compat.openvdb_module()
    density = np.full((3, 4, 2), 0.5, np.float32)
    rgb = np.random.default_rng(7).uniform(0.0, 1.0, (3, 4, 2, 3)).astype(np.float32)
    path = _write_vdb(openvdb, str(tmp_path / "coloured.vdb"), [("density", density, openvdb.FloatGrid),
                                                                ("color", rgb, openvdb.Vec3SGrid)], (1, 0, 0))
    scene = _scene(None)
    colour, absorption_colour = np.array([0.8, 0.5, 1.0]), np.array([0.25, 0.0, 1.0])
    mat, node = _material("Tinted", "ShaderNodeVolumePrincipled",
                          {"Density": 2.0, "Color": (*colour, 1.0), "Absorption Color": (*absorption_colour, 1.0),
                           "Color Attribute": "color"})
    _, interior = _volume_object(scene, "Tinted", path, mat)
    assert np.allclose(interior.grid.values, density)
    values = np.stack([c.values for c in interior.colour_grid.channels], axis=-1)
    assert values.shape == (3, 4, 2, 3)
    assert np.allclose(values, colour * rgb.astype(np.float64), atol=1e-6)
    assert np.allclose(interior.scattering.linear_srgb(), 2.0, rtol=1e-3)
    assert np.allclose(interior.absorption.linear_srgb(), 2.0 * (1.0 - np.sqrt(absorption_colour)), atol=2e-3)


def _write_vdb(openvdb, path, grids, ijk, voxel=0.5) -> str:
    """An OpenVDB file at ``path`` of the grids [(name, values, grid class)], each from index ``ijk``."""
    out = []
    for name, values, kind in grids:
        g = kind()
        g.name = name
        g.copyFromArray(values, ijk=ijk)
        g.transform = openvdb.createLinearTransform(voxelSize=voxel)
        out.append(g)
    openvdb.write(path, grids=out)
    return path
