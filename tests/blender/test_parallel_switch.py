"""Render Properties ▸ Performance ▸ Parallel (``scene.polar.parallel``) read by Polar, and the add-on's
register telling the engine that a Blender session renders again (processes.keep_pool_warm: "auto" may start the
worker processes in the background after a small render)."""

import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import load_addon  # noqa: E402


def test_the_parallel_switch_reaches_the_engine_and_blender_keeps_the_pool_warm():
    load_addon()
    from polar_render.engine.render import processes
    from polar_render.polar_addon.render_engine import engine_settings
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    assert engine_settings(scene).parallel == "auto"
    for item in scene.polar.bl_rna.properties["parallel"].enum_items:
        scene.polar.parallel = item.identifier
        assert engine_settings(scene).parallel == item.identifier.lower()
    assert processes._WARM          # set by the add-on's register (a command-line render leaves it off)
