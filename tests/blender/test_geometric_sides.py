"""A direction counts only on the surface's side of the shading normal (BSDF.geometric_sides, set on every
Blender material, as Cycles' closures require): a smooth-shaded, rough, white metal sphere that emits, alone under
a black world, shows its emission and nothing more.  Sampled about the interpolated normal, a rough lobe also draws
directions below the faceted surface; those enter the sphere and see its (two-sided) emission from inside, which
made such a sphere 1–2 % too bright (SpecGlossEmission's emitters, docs/benchmarks/real-assets.md)."""

import dataclasses

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import PACKAGE, add_camera, load_addon  # noqa: E402
from tests.support import asset_parity as ap  # noqa: E402

EMISSION = 0.5


def emitting_metal_sphere():
    load_addon()
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "POLAR"
    scene.render.resolution_x = scene.render.resolution_y = 32
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0, 0, 0), segments=12, ring_count=6)
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("EmittingMetal")
    load_addon().polar_addon.compat.ensure_node_tree(mat)
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (1, 1, 1, 1)
    p.inputs["Metallic"].default_value = 1.0
    p.inputs["Roughness"].default_value = 1.0
    p.inputs["Emission Color"].default_value = (EMISSION, EMISSION, EMISSION, 1)
    p.inputs["Emission Strength"].default_value = 1.0
    bpy.context.object.data.materials.append(mat)
    add_camera(scene, (0, -6, 0), (np.pi / 2, 0, 0), lens=50.0)
    world = bpy.data.worlds.new("Black")
    load_addon().polar_addon.compat.ensure_node_tree(world)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    return scene


def sphere_s0(scene):
    renderer, settings, warnings = ap.export_polar(scene, 64, 8)
    assert not warnings, warnings
    settings = dataclasses.replace(settings, parallel="threads")      # (this process's integrator: patched below)
    s0 = ap.render_polar(renderer, settings, 1)[0, 0] @ ap.REC709
    inside = s0 > 0.9 * EMISSION                # the sphere's pixels (its silhouette's are partly black)
    assert inside.sum() > 20
    print(f"sphere S0 {s0[inside].mean():.5f} (emission {EMISSION})")
    return s0[inside].mean()


def test_a_smooth_emitting_metal_sphere_shows_its_emission_alone(monkeypatch):
    scene = emitting_metal_sphere()
    assert sphere_s0(scene) == pytest.approx(EMISSION, rel=2e-3)
    # the same render with every direction allowed (the shading normal alone): the sphere lights itself
    integrator = __import__(PACKAGE + ".engine.render.integrator", fromlist=["same_side"])
    monkeypatch.setattr(integrator, "same_side", lambda n_g, n_s, w: np.ones(w.shape[1], bool))
    assert sphere_s0(scene) > EMISSION * 1.01
