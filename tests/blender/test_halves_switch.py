"""Render Properties ▸ Sampling ▸ Even/Odd Samples (``scene.polar.halves``) read by Polar
(polar_addon.render_engine.engine_settings → RenderSettings.halves) and drawn in the Sampling panel."""

import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import drawn_properties, load_addon  # noqa: E402


def test_the_halves_switch_reaches_the_engine_and_the_panel():
    load_addon()
    from polar_render.polar_addon.render_engine import engine_settings
    from polar_render.polar_addon.ui import POLAR_PT_sampling
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    p = scene.polar
    assert p.halves == "AUTO" and engine_settings(scene).halves == "auto"
    for item, mode in (("ONE_SEQUENCE", "one_sequence"), ("INDEPENDENT", "independent")):
        p.halves = item
        assert engine_settings(scene).halves == mode
    assert (p, "halves") in drawn_properties(POLAR_PT_sampling, scene)
