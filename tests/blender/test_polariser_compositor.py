"""Virtual polariser in Blender: the compositor group and the Polariser pass equal the numpy formula."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import (add_plane, add_sphere, brewster_camera, empty_scene, load_addon,  # noqa: E402
                                   polar_material, read_multilayer, white_world)


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def read_all(path):
    import OpenEXR
    with OpenEXR.File(path, separate_channels=True) as f:
        return {n: np.array(c.pixels, dtype=np.float64) for p in f.parts for n, c in p.channels.items()}


def scene_with_gold():
    scene = empty_scene(width=40, height=30, samples=2)
    add_plane(100, polar_material("Floor", "BLACK_GLASS"))
    add_sphere(1.0, (0.3, 0.5, 1.0), polar_material("Gold", "CONDUCTOR", metal="Au"))
    brewster_camera(scene, distance=9, lens=40)
    white_world(scene)
    return scene


@pytest.mark.parametrize("kind,angle", [("LINEAR", 30.0), ("CIRCULAR_RIGHT", 0.0), ("RETARDER", 100.0)])
def test_compositor_group_and_polariser_pass_equal_the_numpy_formula(addon, tmp_path, kind, angle):
    from polar_render.engine.postprocess.filters import apply_filter, filter_row
    scene = scene_with_gold()
    bpy.ops.polar.add_virtual_polariser()
    scene.polar.polariser_type = kind
    scene.polar.polariser_angle = angle
    scene.polar.polariser_extinction = 0.01
    scene.render.filepath = str(tmp_path / kind)
    bpy.ops.render.render(write_still=True)
    chans = read_all(str(tmp_path / kind) + ".exr")
    S = np.stack([np.stack([chans[f"ViewLayer.S{i}.{c}"] for c in "RGB"], -1) for i in range(4)])
    presets = {"LINEAR": (angle, 0.0, 0.0), "CIRCULAR_RIGHT": (90.0, 45.0, 90.0), "RETARDER": (angle, 45.0, 90.0)}
    a, r_angle, retardance = presets[kind]
    expected = apply_filter(S, filter_row("retarder", a, 0.01, r_angle, retardance))
    polariser = np.stack([chans[f"ViewLayer.Polariser.{c}"] for c in "RGB"], -1)
    np.testing.assert_allclose(polariser, expected, rtol=1e-5, atol=1e-7)
    composite = np.stack([chans[f"Composite.Combined.{c}"] for c in "RGB"], -1)
    np.testing.assert_allclose(composite, expected, rtol=1e-5, atol=1e-6)
    assert np.abs(S[3]).max() > 0 if kind != "LINEAR" else True


def test_changing_the_scene_angle_updates_the_compositor_live(addon):
    scene = scene_with_gold()
    bpy.ops.polar.add_virtual_polariser()
    node = scene.compositing_node_group.nodes["Virtual Polariser"]
    scene.polar.polariser_angle = 72.0
    assert node.inputs["Angle"].default_value == pytest.approx(72.0)
    scene.polar.polariser_type = "CIRCULAR_LEFT"
    assert node.inputs["Angle"].default_value == 0.0 and node.inputs["Retardance"].default_value == 90.0


def test_false_colour_passes(addon, tmp_path):
    scene = scene_with_gold()
    vl = scene.view_layers[0].polar
    vl.use_pass_visdop = vl.use_pass_viss1 = vl.use_pass_visaolp = True
    scene.render.filepath = str(tmp_path / "vis")
    bpy.ops.render.render(write_still=True)
    passes = read_multilayer(str(tmp_path / "vis") + ".exr")
    for name in ("VisDoP", "VisS1", "VisAoLP"):
        assert passes[name].shape[-1] == 3 and np.all(np.isfinite(passes[name]))
    # Brewster floor: S1/S0 ≈ +1 → the red end of the diverging map.
    h, w = passes["VisS1"].shape[:2]
    corner = passes["VisS1"][h - 3, 2]
    assert corner[0] > 0.5 and corner[2] < 0.2
