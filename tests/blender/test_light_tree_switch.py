"""Cycles' Light Tree switch read by Polar (polar_addon.render_engine.engine_settings): on (Cycles' default) → "on"
(the tree, as Cycles, whatever the count of lights), off → "off" with Scene.light_selection "cycles"
(Cycles' own choice without its tree, polar_addon.export.scene.light_selection); an exported Blender scene (two-sided
emissive spheres, which block their own shadow rays, and a point lamp) renders the same mean with and without the
tree."""

import dataclasses

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import (add_camera, add_plane, add_sphere, drawn_properties, light_paths_off,  # noqa: E402
                                   load_addon)
from tests.blender.test_cycles_light_paths import diffuse, emitter  # noqa: E402

W, H = 32, 24


def scene_with_emitters():
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = W, H, 100
    scene.world = bpy.data.worlds.new("World")
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    add_plane(10.0, diffuse(0.8))
    for k, (x, strength) in enumerate(((-1.0, 5.0), (0.3, 40.0), (1.2, 1.0))):
        add_sphere(0.25, (x, 0.2 * k, 0.6 + 0.2 * k), emitter(strength), smooth=False)   # 48 × 24 faces each
    bpy.ops.object.light_add(type="POINT", location=(0.0, -1.0, 1.5))
    bpy.context.object.data.energy = 50.0
    add_camera(scene, (0.0, -4.0, 3.0), (np.radians(55), 0.0, 0.0), lens=30)
    light_paths_off(scene, 4)
    return scene


def test_the_light_tree_follows_cycles_switch_and_keeps_the_mean():
    load_addon()
    from polar_render.engine.render.renderer import Renderer
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    scene = scene_with_emitters()
    scene.render.engine = "POLAR"
    scene.polar.samples, scene.polar.max_bounces = 16, 3
    assert scene.cycles.use_light_tree and engine_settings(scene).light_tree == "on"
    depsgraph = bpy.context.evaluated_depsgraph_get()
    assert export_scene(depsgraph, scene.camera, W, H, engine_settings(scene))[0].light_selection == "power"
    scene.cycles.use_light_tree = False
    assert engine_settings(scene).light_tree == "off"
    settings = engine_settings(scene)
    engine_scene, _ = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, W, H, settings)
    assert engine_scene.light_selection == "cycles"
    renderer = Renderer(engine_scene)
    means = {mode: np.array([renderer.render(dataclasses.replace(settings, seed=s, light_tree=mode))
                             .stokes_luminance()[0].mean() for s in range(6)]) for mode in ("on", "off")}
    se = np.sqrt(means["on"].var(ddof=1) / 6 + means["off"].var(ddof=1) / 6)
    assert abs(means["on"].mean() - means["off"].mean()) < 4.0 * se
    assert renderer.lights.uses_tree("on") and renderer.lights.light_tree().split.sum() == 3


def test_sampling_panel_shows_cycles_light_tree_switch():
    load_addon()
    from polar_render.polar_addon.ui import POLAR_PT_sampling
    scene = scene_with_emitters()
    assert (scene.cycles, "use_light_tree") in drawn_properties(POLAR_PT_sampling, scene)
