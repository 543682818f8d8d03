"""The Polarisation Mosaic pass: what a 2×2 micro-polariser camera records, from a Blender render."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import (add_plane, brewster_camera, empty_scene, load_addon, polar_material,  # noqa: E402
                                   read_multilayer, render_to_exr, white_world)


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def stokes_of(passes):
    return np.stack([passes[f"S{i}"] for i in range(4)]).astype(np.float64)


def test_mosaic_pass_is_malus_per_pixel_with_the_sensor_layout(addon, tmp_path):
    from polar_render.engine.postprocess.mosaic import mosaic
    scene = empty_scene(40, 30)
    add_plane(200, polar_material("Floor", "BLACK_GLASS"))
    brewster_camera(scene, lens=200.0)
    white_world(scene)
    bpy.context.view_layer.polar.use_pass_polarisation_mosaic = True
    scene.polar.mosaic_extinction = 0.01
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "mosaic")))
    raw = passes["Polarisation Mosaic"]
    st = stokes_of(passes)
    expected = mosaic(st, ((90.0, 45.0), (135.0, 0.0)), 0.01)
    np.testing.assert_allclose(raw, expected, rtol=1e-5, atol=1e-7)
    # s-polarised floor (S1 > 0): the 0° pixels (row 1, column 1 of each cell) are the brightest.
    assert raw[1::2, 1::2].mean() > 5 * raw[0::2, 0::2].mean()

    # A border render keeps the pattern of the full frame (odd window origin).
    scene.render.use_border, scene.render.use_crop_to_border = True, False
    scene.render.border_min_x, scene.render.border_max_x = 0.275, 0.75
    scene.render.border_min_y, scene.render.border_max_y = 0.5, 1.0
    scene.polar.mosaic_angles = (0.0, 45.0, 135.0, 90.0)
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "mosaic_border")))
    inside = (slice(0, 15), slice(11, 30))
    expected = mosaic(stokes_of(passes), ((0.0, 45.0), (135.0, 90.0)), 0.01)
    np.testing.assert_allclose(passes["Polarisation Mosaic"][inside], expected[inside], rtol=1e-5, atol=1e-7)
    assert passes["S0"][inside].min() > 0 and passes["S0"][:, :11].max() == 0
