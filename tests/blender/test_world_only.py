"""A Blender scene with nothing but a world (an HDRI or sky preview) renders with Polar as with Cycles; a scene
with nothing at all renders black, with one warning (Cycles renders it black too).

Oracle: Cycles, with the world parity rules of tests/blender/test_world.py (per 12 × 12-pixel region, Polar/Cycles
within 4 standard errors + 2 %, the standard errors from four seeds each).
"""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender.test_world import _compare, _hdri_pixels, _hdri_world, _image, _sky_world  # noqa: E402
from tests.blender_support import load_addon, read_multilayer, render_to_exr  # noqa: E402


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def _world_only_scene():
    """No object but a camera looking slightly up at the sky, 48 × 36 (the parity tests' size)."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 48, 36
    scene.render.resolution_percentage = 100
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = 24
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (0.0, -5.0, 1.6), (math.radians(95), 0.0, math.radians(20))
    scene.camera = cam
    return scene


def _assert_parity(scene, tmp_path, what):
    lit, ratio, se = _compare(bpy, scene, tmp_path)
    assert lit.sum() >= 10
    bad = np.abs(ratio - 1.0) > 4.0 * se + 0.02
    print(f"\n{what}: Polar/Cycles per region {ratio.min():.4f}–{ratio.max():.4f} (mean {ratio.mean():.4f}), "
          f"max |ratio − 1|/σ {np.max(np.abs(ratio - 1) / se):.2f}")
    assert not bad.any(), f"Polar/Cycles per region {np.round(ratio, 4).tolist()} ± {np.round(se, 4).tolist()}"


def test_hdri_world_alone_agrees_with_cycles(addon, tmp_path, capsys):
    scene = _world_only_scene()
    _hdri_world(bpy, _image(bpy, "hdri", _hdri_pixels()), (15.0, -20.0, 130.0), strength=1.2)
    with capsys.disabled():
        _assert_parity(scene, tmp_path, "HDRI world alone")


def test_sky_texture_world_alone_agrees_with_cycles(addon, tmp_path, capsys):
    scene = _world_only_scene()
    scene.polar.world_bake_resolution = 512
    world, sky = _sky_world(bpy, "HOSEK_WILKIE")
    sky.sun_direction = (0.4, -0.6, 0.7)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 3.0
    with capsys.disabled():
        _assert_parity(scene, tmp_path, "Hosek-Wilkie sky alone")


def test_f12_renders_a_world_only_scene(addon, tmp_path):
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    scene = _world_only_scene()
    scene.render.engine = "POLAR"
    scene.polar.samples = 2
    addon.polar_addon.compat.set_multilayer_exr(scene.render.image_settings)
    _hdri_world(bpy, _image(bpy, "hdri", _hdri_pixels()), strength=1.0)
    engine_scene, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 48, 36,
                                          engine_settings(scene))
    assert engine_scene.meshes == [] and warnings == []
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "world")))
    assert passes["S0"].min() > 0.05 and np.all(passes["Combined"][..., 3] == 1)
    np.testing.assert_array_equal(passes["Combined"][..., :3], passes["S0"])


def test_empty_scene_renders_black_with_a_warning(addon, tmp_path):
    """No object and no world: as Cycles, a black (opaque) image, not an error; one warning says why."""
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    scene = _world_only_scene()
    scene.render.engine = "POLAR"
    scene.polar.samples = 1
    addon.polar_addon.compat.set_multilayer_exr(scene.render.image_settings)
    assert scene.world is None
    _, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 48, 36, engine_settings(scene))
    assert warnings == ["the scene has no visible geometry and a black world: the image is black"]
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "empty")))
    assert np.all(passes["S0"] == 0) and np.all(passes["Combined"][..., 3] == 1)
    # a point light adds nothing to see: still black, the warning says the lamps are all there is
    bpy.ops.object.light_add(type="POINT", location=(0, 0, 2))
    _, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, 48, 36, engine_settings(scene))
    assert warnings == ["the scene has no visible geometry and a black world: the image is black but for the "
                        "lamps the camera sees"]
    assert np.all(read_multilayer(render_to_exr(scene, str(tmp_path / "point")))["S0"] == 0)
