"""`python -m engine polariser` reads Blender's multilayer EXRs (passes named <Layer>.<Pass>.<Channel>)."""

import numpy as np
import OpenEXR
import pytest

from engine.cli import main
from engine.output.exr import read_stokes_exr, stokes_layers
from engine.postprocess.filters import apply_filter, filter_row


def _stokes(seed, h=3, w=4):
    rng = np.random.default_rng(seed)
    s = rng.uniform(-0.3, 0.3, (4, h, w, 3)).astype(np.float32)
    s[0] = rng.uniform(1.0, 2.0, (h, w, 3))
    return s


def _write_multilayer(path, layers):
    """A multipart EXR as Blender writes it: one part per pass, channels <Layer>.<Pass>.<R|G|B>."""
    parts = []
    for layer, stokes in layers.items():
        for k in range(4):
            name = f"{layer}.S{k}"
            chans = {f"{name}.{c}": np.ascontiguousarray(stokes[k, :, :, i]) for i, c in enumerate("RGB")}
            parts.append(OpenEXR.Part({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                                      chans, name=name))
    OpenEXR.File(parts).write(str(path))


def test_reads_the_only_layer_and_chooses_among_several(tmp_path, capsys):
    a, b = _stokes(1), _stokes(2)
    one = tmp_path / "one.exr"
    _write_multilayer(one, {"View.Layer": a})            # a layer name with a dot
    stokes, channels, _ = read_stokes_exr(one)
    np.testing.assert_array_equal(stokes, a)
    assert "S0.R" in channels and "S3.B" in channels

    two = tmp_path / "two.exr"
    _write_multilayer(two, {"Front": a, "Back": b})
    assert stokes_layers(OpenEXR.File(str(two), separate_channels=True).parts[0].channels.keys()
                         | OpenEXR.File(str(two), separate_channels=True).parts[4].channels.keys()) == []
    channels = read_stokes_exr(two, "Back")[1]
    assert "S0.R" in channels and "Back.S0.R" not in channels     # the layer's channels, prefix removed
    np.testing.assert_array_equal(read_stokes_exr(two, "Back")[0], b)
    np.testing.assert_array_equal(read_stokes_exr(two, "Front")[0], a)

    out = tmp_path / "f.exr"
    assert main(["polariser", str(two), "-o", str(out), "--angle", "30"]) == 2
    err = capsys.readouterr().err
    assert "--layer" in err and "'Back'" in err and "'Front'" in err
    assert main(["polariser", str(two), "-o", str(out), "--layer", "Side"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --layer") and "'Side'" in err and "'Back', 'Front'" in err
    assert main(["polariser", str(two), "-o", str(out), "--angle", "30", "--layer", "Back"]) == 0
    expected = apply_filter(b, filter_row("linear", 30.0, 0.0, 45.0, 90.0))
    np.testing.assert_allclose(read_stokes_exr(out)[0][0], expected, rtol=1e-6)
    # a plain Polar EXR still reads without --layer
    assert main(["polariser", str(out), "-o", str(tmp_path / "g.png")]) == 0


def test_polariser_reads_a_blender_multilayer_render(tmp_path):
    bpy = pytest.importorskip("bpy")
    from tests.blender_support import (add_plane, brewster_camera, empty_scene, load_addon, polar_material,
                                       read_multilayer, render_to_exr, white_world)
    load_addon()
    scene = empty_scene(12, 8, samples=2)
    add_plane(200, polar_material("Floor", "BLACK_GLASS"))
    brewster_camera(scene)
    white_world(scene)
    assert scene.render.image_settings.media_type == "MULTI_LAYER_IMAGE"
    path = render_to_exr(scene, str(tmp_path / "blender"))
    passes = read_multilayer(path)
    st = np.stack([passes[f"S{k}"] for k in range(4)])
    assert np.abs(st[1]).max() > 0.1 * st[0].max()          # the Brewster floor is polarised

    out = tmp_path / "filtered.exr"
    assert main(["polariser", path, "-o", str(out), "--angle", "90"]) == 0
    expected = apply_filter(st, filter_row("linear", 90.0, 0.0, 45.0, 90.0))
    np.testing.assert_allclose(read_stokes_exr(out)[0][0], expected, rtol=1e-6, atol=1e-9)
    assert main(["polariser", path, "-o", str(tmp_path / "m.png"), "--mosaic", "--layer", "ViewLayer"]) == 0
    del bpy
