"""Polarisation-camera output: the 2×2 micro-polariser mosaic against Malus's law, and demosaicing by
the standard formulas recovering S0, S1, S2 (with the sign of S2) of a smooth image."""

import numpy as np
import pytest

from engine.errors import SceneError
from engine.postprocess.mosaic import (DEFAULT_LAYOUT, angle_map, interpolate_angle, mosaic, parse_layout,
                                       stokes_from_mosaic)


def smooth_stokes(h=48, w=64, channels=3):
    """A smooth, physically valid linear Stokes image (4, H, W, C): S2 > 0 on the left, < 0 on the right."""
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    s0 = 1.0 + 0.3 * np.sin(2.0 * x + 1.0) * np.cos(1.5 * y)
    dolp = 0.4 + 0.2 * y
    aolp = np.radians(40.0) - np.radians(80.0) * x          # +40° (S2 > 0) … −40° (S2 < 0)
    st = np.stack([s0, s0 * dolp * np.cos(2 * aolp), s0 * dolp * np.sin(2 * aolp), np.zeros_like(s0)])
    return np.stack([st * (0.5 + 0.25 * c) for c in range(channels)], axis=-1)


def test_layout_of_common_sensors_and_malus_per_pixel():
    assert DEFAULT_LAYOUT == ((90.0, 45.0), (135.0, 0.0))
    np.testing.assert_array_equal(angle_map(3, 3), [[90, 45, 90], [135, 0, 135], [90, 45, 90]])
    s = np.zeros((4, 2, 2))
    s[0], s[1], s[2] = 1.0, 0.6, -0.2            # uniform light: horizontal-ish with some −45°
    raw = mosaic(s)
    assert raw[0, 0] == pytest.approx(0.5 * (1 - 0.6))            # top-left: 90°, vertical
    assert raw[0, 1] == pytest.approx(0.5 * (1 - 0.2))            # 45°: towards image up-right
    assert raw[1, 0] == pytest.approx(0.5 * (1 + 0.2))            # 135°
    assert raw[1, 1] == pytest.approx(0.5 * (1 + 0.6))            # 0°: horizontal


def test_extinction_ratio_leaks_the_crossed_component():
    s = np.zeros((4, 2, 2))
    s[0], s[1] = 1.0, 1.0                                         # fully horizontal
    raw = mosaic(s, extinction=0.01)
    assert raw[0, 0] == pytest.approx(0.01)                       # the 90° pixel sees t_min
    assert raw[1, 1] == pytest.approx(1.0)
    with pytest.raises(SceneError, match="mosaic.extinction"):
        mosaic(s, extinction=1.5)


def test_demosaic_recovers_smooth_stokes_including_the_sign_of_s2():
    st = smooth_stokes()
    raw = mosaic(st)
    assert raw.shape == st.shape[1:]
    rec = stokes_from_mosaic(raw)
    inner = (slice(None), slice(2, -2), slice(2, -2))
    for k in range(3):
        np.testing.assert_allclose(rec[k][inner[1:]], st[k][inner[1:]], atol=1e-3)
    s2 = st[2][inner[1:]]
    strong = np.abs(s2) > 0.02
    assert (np.sign(rec[2][inner[1:]][strong]) == np.sign(s2[strong])).all()
    assert (s2 > 0.02).any() and (s2 < -0.02).any()
    # The whole image, border included (renormalised weights), stays close.
    np.testing.assert_allclose(rec, st[:3], atol=2e-2)


def test_demosaic_with_a_known_extinction_and_another_layout():
    st = smooth_stokes(channels=1)[..., 0]
    layout = ((0.0, 45.0), (135.0, 90.0))
    rec = stokes_from_mosaic(mosaic(st, layout, extinction=0.05), layout, extinction=0.05)
    np.testing.assert_allclose(rec[:, 2:-2, 2:-2], st[:3, 2:-2, 2:-2], atol=3e-3)


def test_bilinear_interpolation_is_exact_for_linear_images():
    y, x = np.mgrid[0:9, 0:10].astype(float)
    ramp = 0.5 + 0.1 * x - 0.03 * y
    for r in range(2):
        for c in range(2):
            raw = np.where((np.arange(9)[:, None] % 2 == r) & (np.arange(10)[None, :] % 2 == c), ramp, -99.0)
            np.testing.assert_allclose(interpolate_angle(raw, r, c)[1:-1, 1:-1], ramp[1:-1, 1:-1], atol=1e-12)


def test_layout_errors_name_the_field():
    with pytest.raises(SceneError, match="mosaic.layout"):
        parse_layout([1, 2, 3])
    with pytest.raises(SceneError, match="--mosaic-layout"):
        parse_layout(["a", "b", "c", "d"], "--mosaic-layout")
    with pytest.raises(SceneError, match="0, 45, 90 and 135"):
        stokes_from_mosaic(np.zeros((4, 4)), ((0, 30), (60, 90)))


def test_cli_mosaic_output(tmp_path):
    from engine.cli import main
    from engine.output.exr import read_stokes_exr, write_stokes_exr
    st = smooth_stokes(16, 20)
    src = tmp_path / "in.exr"
    write_stokes_exr(str(src), st.astype(np.float32))
    out = tmp_path / "raw.exr"
    assert main(["polariser", str(src), "--mosaic", "--extinction", "0.02", "-o", str(out)]) == 0
    raw, _, header = read_stokes_exr(str(out))
    expected = mosaic(read_stokes_exr(str(src))[0], DEFAULT_LAYOUT, 0.02)
    np.testing.assert_allclose(raw[0], expected, rtol=1e-6, atol=1e-7)
    assert header["polar.filter"] == "mosaic" and header["polar.mosaic_layout_deg"] == "90,45,135,0"
    png = tmp_path / "raw.png"
    assert main(["polariser", str(src), "--mosaic", "--mosaic-layout", "0,45,135,90", "-o", str(png)]) == 0
    assert png.exists()
    assert main(["polariser", str(src), "--mosaic", "--mosaic-layout", "0,45", "-o", str(png)]) == 2


def test_a_crop_keeps_the_sensor_pattern():
    st = smooth_stokes(10, 12)
    full = mosaic(st)
    np.testing.assert_allclose(mosaic(st[:, 3:9, 1:8], origin=(3, 1)), full[3:9, 1:8])
    np.testing.assert_array_equal(angle_map(6, 7, origin=(3, 1)), angle_map(10, 12)[3:9, 1:8])
