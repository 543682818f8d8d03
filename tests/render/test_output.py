"""Tests for engine.output: Stokes EXR files, PNG codec, colour maps, previews."""

from __future__ import annotations

import os
import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst
from hypothesis.extra import numpy as hnp

import engine.output
from engine.output import exr as exr_mod
from engine.output.colormaps import NAN_GREY, diverging, hue_saturation, sequential, srgb_encode, tonemap
from engine.output.exr import STOKES_EXR_CONVENTIONS, read_stokes_exr, write_stokes_exr
from engine.output.png import read_png, write_png
from engine.output.previews import LEGEND_HEIGHT, write_previews
from engine.polarisation import stokes as st

H, W = 5, 7


def physical_stokes(rng, h=H, w=W):
    """Random Stokes image with S0 >= |(S1, S2, S3)| per RGB channel, some S0 = 0 pixels."""
    s0 = rng.uniform(0.0, 3.0, (h, w, 3))
    direction = rng.normal(size=(3, h, w, 3))
    direction /= np.linalg.norm(direction, axis=0)
    s = np.concatenate([s0[None], direction * (s0 * rng.uniform(0, 1, (h, w, 3)))[None]])
    s[:, 0, 0, :] = 0.0
    return s


def hidden_files(directory):
    return [n for n in os.listdir(directory) if n.startswith(".")]


# --- EXR -------------------------------------------------------------------------------

def test_exr_round_trip_values_channels_and_metadata(tmp_path):
    rng = np.random.default_rng(1)
    s = physical_stokes(rng)
    spp = rng.integers(1, 1000, (H, W))
    stderr = rng.uniform(0, 0.1, (H, W))
    meta = {"polar.spp": 64, "polar.seed": 12345, "polar.exposure": 0.1,
            "polar.scene": "cornell", "polar.big": 2**40, "polar.flag": True}
    path = tmp_path / "img.exr"
    write_stokes_exr(path, s, metadata=meta, extra={"spp": spp, "S0.Y.stderr": stderr})

    stokes, channels, header = read_stokes_exr(path)
    assert stokes.dtype == np.float32 and stokes.shape == (4, H, W, 3)
    np.testing.assert_array_equal(stokes, s.astype(np.float32))
    expected = {f"S{k}.{c}" for k in range(4) for c in "RGB"} | {
        "R", "G", "B", "DoP", "DoLP", "AoLP", "DoCP", "spp", "S0.Y.stderr"}
    assert set(channels) == expected
    for c, name in enumerate("RGB"):
        np.testing.assert_array_equal(channels[name], s[0, :, :, c].astype(np.float32))
    assert channels["spp"].dtype == np.uint32
    np.testing.assert_array_equal(channels["spp"], spp)
    np.testing.assert_array_equal(channels["S0.Y.stderr"], stderr.astype(np.float32))

    assert header["polar.spp"] == 64 and header["polar.seed"] == 12345
    assert header["polar.exposure"] == 0.1  # stored as double: exact
    assert header["polar.scene"] == "cornell"
    assert header["polar.big"] == str(2**40)  # beyond int32: kept exactly as text
    assert header["polar.flag"] == 1
    assert header["polar.conventions"] == STOKES_EXR_CONVENTIONS
    assert "ZIP" in str(header["compression"]) and "ZIPS" not in str(header["compression"])


def test_exr_derived_channels_match_stokes_functions_on_luminance(tmp_path):
    rng = np.random.default_rng(2)
    s = physical_stokes(rng)
    # make RGB channels differ so luminance weighting matters
    s[..., 1] *= 0.3
    path = tmp_path / "d.exr"
    write_stokes_exr(path, s)
    _, channels, _ = read_stokes_exr(path)
    y = 0.2126 * s[..., 0] + 0.7152 * s[..., 1] + 0.0722 * s[..., 2]
    for name, fn in [("DoP", st.degree_of_polarisation), ("DoLP", st.degree_of_linear_polarisation),
                     ("AoLP", st.angle_of_linear_polarisation), ("DoCP", st.degree_of_circular_polarisation)]:
        np.testing.assert_allclose(channels[name], fn(y), rtol=1e-6, atol=1e-7, err_msg=name)
    assert channels["DoLP"][0, 0] == 0.0  # S0 = 0 pixel
    assert np.all(channels["DoP"] <= 1 + 1e-6)


def test_exr_half(tmp_path):
    s = physical_stokes(np.random.default_rng(3))
    write_stokes_exr(tmp_path / "h.exr", s, half=True)
    stokes, channels, _ = read_stokes_exr(tmp_path / "h.exr")
    assert channels["S1.G"].dtype == np.float16 and stokes.dtype == np.float32
    np.testing.assert_allclose(stokes, s, rtol=1e-3, atol=1e-3)
    s[0, 1, 1, 0] = 1e5
    with pytest.raises(ValueError, match="half"):
        write_stokes_exr(tmp_path / "h2.exr", s, half=True)


@pytest.mark.parametrize("bad, match", [
    (np.zeros((3, H, W, 3)), "shape"),
    (np.zeros((4, H, W)), "shape"),
    (np.zeros((4, 0, W, 3)), "shape"),
    (np.full((4, H, W, 3), np.nan), "non-finite"),
])
def test_exr_rejects_bad_images(tmp_path, bad, match):
    with pytest.raises(ValueError, match=match):
        write_stokes_exr(tmp_path / "x.exr", bad)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("kwargs, match", [
    ({"extra": {"spp": np.zeros((H + 1, W))}}, "shape"),
    ({"extra": {"DoLP": np.zeros((H, W))}}, "clashes"),
    ({"extra": {"e": np.full((H, W), np.inf)}}, "non-finite"),
    ({"extra": {"n": -np.ones((H, W), int)}}, "integer"),
    ({"metadata": {"compression": "none"}}, "reserved"),
    ({"metadata": {"polar.x": [1, 2]}}, "unsupported"),
])
def test_exr_rejects_bad_extras_and_metadata(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        write_stokes_exr(tmp_path / "x.exr", np.zeros((4, H, W, 3)), **kwargs)
    assert os.listdir(tmp_path) == []


def test_exr_atomic_write_leaves_no_temp(tmp_path):
    write_stokes_exr(tmp_path / "a.exr", np.ones((4, H, W, 3)))
    assert sorted(os.listdir(tmp_path)) == ["a.exr"]


def test_exr_failing_write_keeps_existing_target(tmp_path, monkeypatch):
    target = tmp_path / "a.exr"
    write_stokes_exr(target, np.ones((4, H, W, 3)))
    before = target.read_bytes()
    seen = []

    class CrashingFile:
        def __init__(self, header, channels):
            pass

        def write(self, path):
            seen.append(path)
            with open(path, "wb") as f:
                f.write(b"v/1\x01 truncated")
            raise RuntimeError("simulated crash mid-write")

    monkeypatch.setattr(exr_mod.OpenEXR, "File", CrashingFile)
    with pytest.raises(RuntimeError, match="simulated"):
        write_stokes_exr(target, np.zeros((4, H, W, 3)))
    monkeypatch.undo()

    name = os.path.basename(seen[0])
    assert os.path.dirname(seen[0]) == str(tmp_path)
    assert name.startswith(".") and name.endswith(".exr")
    assert target.read_bytes() == before
    assert hidden_files(tmp_path) == [] and sorted(os.listdir(tmp_path)) == ["a.exr"]
    np.testing.assert_array_equal(read_stokes_exr(target)[0], 1.0)


def test_exr_atomic_write_keeps_file_mode(tmp_path):
    target = tmp_path / "a.exr"
    write_stokes_exr(target, np.ones((4, H, W, 3)))
    assert os.stat(target).st_mode & 0o777 == 0o644  # not mkstemp's 0600
    os.chmod(target, 0o640)
    write_stokes_exr(target, np.ones((4, H, W, 3)))
    assert os.stat(target).st_mode & 0o777 == 0o640


def test_read_rejects_non_stokes_exr(tmp_path):
    import OpenEXR
    path = str(tmp_path / "plain.exr")
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {"R": np.ones((2, 2), np.float32)}).write(path)
    with pytest.raises(ValueError, match="missing channels"):
        read_stokes_exr(path)


# --- PNG -------------------------------------------------------------------------------

@settings(max_examples=30, deadline=None)
@given(hnp.arrays(np.uint8, hst.tuples(hst.integers(1, 9), hst.integers(1, 9), hst.just(3)))
       | hnp.arrays(np.uint8, hst.tuples(hst.integers(1, 9), hst.integers(1, 9))))
def test_png_round_trip(tmp_path_factory, image):
    path = tmp_path_factory.mktemp("png") / "x.png"
    write_png(path, image)
    out = read_png(path)
    assert out.dtype == np.uint8
    np.testing.assert_array_equal(out, image)


def _paeth(a, b, c):
    p = a + b - c
    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
    return a if pa <= pb and pa <= pc else (b if pb <= pc else c)


@pytest.mark.parametrize("ftype", [1, 2, 3, 4])
def test_png_decoder_filters(tmp_path, ftype):
    """Hand-filter an image with each PNG filter type; the decoder must undo it."""
    img = np.random.default_rng(ftype).integers(0, 256, (4, 5, 3)).astype(np.int64)
    rows, bpp = img.reshape(4, -1), 3
    raw = bytearray()
    for y in range(4):
        prev = rows[y - 1] if y else np.zeros_like(rows[0])
        raw.append(ftype)
        for i, x in enumerate(rows[y]):
            a = rows[y, i - bpp] if i >= bpp else 0
            b, c = prev[i], (prev[i - bpp] if i >= bpp else 0)
            pred = {1: a, 2: b, 3: (a + b) // 2, 4: _paeth(a, b, c)}[ftype]
            raw.append(int(x - pred) % 256)

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    path = tmp_path / "f.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 5, 4, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(bytes(raw))) + chunk(b"IEND", b""))
    np.testing.assert_array_equal(read_png(path), img)


def test_png_rejects_bad_input_and_is_atomic(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match="uint8"):
        write_png(tmp_path / "a.png", np.zeros((2, 2, 3), np.float32))
    with pytest.raises(ValueError, match="shape"):
        write_png(tmp_path / "a.png", np.zeros((2, 2, 4), np.uint8))
    target = tmp_path / "a.png"
    write_png(target, np.full((2, 2), 7, np.uint8))
    monkeypatch.setattr(engine.output.os, "replace", lambda *a: (_ for _ in ()).throw(OSError("disk gone")))
    with pytest.raises(OSError, match="disk gone"):
        write_png(target, np.zeros((3, 3), np.uint8))
    monkeypatch.undo()
    np.testing.assert_array_equal(read_png(target), 7)
    assert os.listdir(tmp_path) == ["a.png"]


def test_png_bad_crc_detected(tmp_path):
    path = tmp_path / "a.png"
    write_png(path, np.zeros((2, 2, 3), np.uint8))
    data = bytearray(path.read_bytes())
    data[20] ^= 0xFF  # inside IHDR
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="CRC"):
        read_png(path)


# --- colour maps -----------------------------------------------------------------------

def test_diverging_endpoints_and_nan():
    blue, white, red, nan = diverging(np.array([-1.0, 0.0, 1.0, np.nan]))
    assert blue[2] > blue[0] + 50 and blue[2] > blue[1]
    assert red[0] > red[2] + 50 and red[0] > red[1]
    np.testing.assert_array_equal(white, [255, 255, 255])
    np.testing.assert_array_equal(nan, NAN_GREY)
    np.testing.assert_array_equal(diverging(5.0), diverging(1.0))  # clipped
    assert diverging(np.zeros((2, 3))).shape == (2, 3, 3)


def test_diverging_lightness_is_symmetric_and_peaks_at_zero():
    v = np.linspace(-1, 1, 41)
    lum = diverging(v).astype(float) @ [0.2126, 0.7152, 0.0722]
    assert np.argmax(lum) == 20
    assert np.all(np.diff(lum[:21]) >= 0) and np.all(np.diff(lum[20:]) <= 0)
    assert abs(lum[0] - lum[-1]) < 25  # ends about equally dark


def test_sequential_endpoints_monotone_lightness_and_nan():
    lo, hi, nan = sequential(np.array([0.0, 1.0, np.nan]))
    np.testing.assert_array_equal(lo, [0x44, 0x01, 0x54])  # viridis dark purple
    np.testing.assert_array_equal(hi, [0xFD, 0xE7, 0x25])  # viridis yellow
    np.testing.assert_array_equal(nan, NAN_GREY)
    lum = sequential(np.linspace(0, 1, 50)).astype(float) @ [0.2126, 0.7152, 0.0722]
    assert np.all(np.diff(lum) >= 0)


def test_hue_saturation():
    rgb = hue_saturation(np.array([0.0, np.pi / 2, -np.pi / 2, np.pi / 3, 0.3, np.nan]),
                         np.array([1.0, 1.0, 1.0, 1.0, 0.0, 1.0]))
    np.testing.assert_array_equal(rgb[0], [255, 0, 0])      # horizontal: red
    np.testing.assert_array_equal(rgb[1], [0, 255, 255])    # vertical: cyan
    np.testing.assert_array_equal(rgb[2], rgb[1])           # period π
    np.testing.assert_array_equal(rgb[3], [0, 255, 0])      # +60°: green
    np.testing.assert_array_equal(rgb[4], [255, 255, 255])  # unpolarised: white
    np.testing.assert_array_equal(rgb[5], NAN_GREY)
    np.testing.assert_array_equal(hue_saturation(0.0, np.nan), NAN_GREY)
    half = hue_saturation(0.0, 0.5)
    assert half[0] == 255 and 120 < half[1] == half[2] < 135


def test_srgb_encode_known_values():
    np.testing.assert_allclose(srgb_encode([0.0, 0.0031308, 0.18, 1.0, 2.0, -1.0]),
                               [0.0, 0.04045, 0.46135, 1.0, 1.0, 0.0], atol=2e-5)


def test_tonemap_monotonic_and_exposure():
    x = np.linspace(0, 1.5, 3000)
    t = tonemap(x)
    assert t.dtype == np.uint8 and t[0] == 0 and t[-1] == 255
    assert np.all(np.diff(t.astype(int)) >= 0) and len(np.unique(t)) > 230
    assert tonemap(0.25, exposure=1.0) == tonemap(0.5)
    assert tonemap(np.nan) == 0


# --- previews --------------------------------------------------------------------------

def test_previews(tmp_path):
    s = np.zeros((4, H, W, 3))
    s[0] = 1.0
    s[1, :, :3] = 1.0     # left: fully horizontal linear
    s[2, :, 3:6] = -0.5   # -45°, DoLP 0.5
    s[3, 0, 6] = 1.0      # right-circular pixel
    s[:, 4, 6] = 0.0      # no light
    paths = write_previews(str(tmp_path / "p"), s)
    names = ["S0", "S1", "S2", "S3", "DoLP", "DoP", "AoLP"]
    assert paths == [str(tmp_path / f"p_{n}.png") for n in names]
    assert hidden_files(tmp_path) == []
    img = {n: read_png(p) for n, p in zip(names, paths)}
    for n in names:
        assert img[n].shape == (H + LEGEND_HEIGHT, W, 3), n

    np.testing.assert_array_equal(img["S0"][0, 0], [255, 255, 255])
    np.testing.assert_array_equal(img["S1"][0, 0], diverging(1.0))
    np.testing.assert_array_equal(img["S1"][0, 4], diverging(0.0))
    np.testing.assert_array_equal(img["S2"][0, 4], diverging(-0.5))
    np.testing.assert_array_equal(img["S3"][0, 6], diverging(1.0))
    np.testing.assert_array_equal(img["DoLP"][0, 0], sequential(1.0))
    np.testing.assert_array_equal(img["DoLP"][0, 4], sequential(0.5))
    np.testing.assert_array_equal(img["AoLP"][0, 0], [255, 0, 0])
    np.testing.assert_array_equal(img["AoLP"][0, 4], hue_saturation(-np.pi / 4, 0.5))
    for n in ["S1", "S2", "S3", "DoLP", "AoLP"]:
        np.testing.assert_array_equal(img[n][4, 6], NAN_GREY, err_msg=n)  # S0 = 0
    np.testing.assert_array_equal(img["S0"][4, 6], [0, 0, 0])

    # legend: map min at left, max at right (top row), dark ticks at ends and centre
    legend = img["S1"][H:]
    np.testing.assert_array_equal(legend[0, 0], diverging(-1.0))
    np.testing.assert_array_equal(legend[0, -1], diverging(1.0))
    np.testing.assert_array_equal(legend[0, (W - 1) // 2], diverging(0.0))
    for col in (0, (W - 1) // 2, W - 1):
        np.testing.assert_array_equal(legend[-1, col], [0, 0, 0])
    assert legend[-1, 1].sum() > 0
    np.testing.assert_array_equal(img["DoLP"][H, -1], sequential(1.0))
    np.testing.assert_array_equal(img["S0"][H, -1], [255, 255, 255])


def test_previews_exposure_and_validation(tmp_path):
    s = np.zeros((4, H, W, 3))
    s[0] = 0.25
    p = write_previews(tmp_path / "e", s, exposure=2.0)[0]
    np.testing.assert_array_equal(read_png(p)[0, 0], [255, 255, 255])
    with pytest.raises(ValueError, match="shape"):
        write_previews(tmp_path / "bad", np.zeros((4, H, W)))


# --- finite-or-refused, temporary names, destinations, rescue ------------------------------------

def _image_with(value, component=0, channel=0):
    s = np.zeros((4, H, W, 3))
    s[0] = 1.0
    s[component, 1, 2, channel] = value
    return s


@pytest.mark.parametrize("stokes, extra, channel", [
    (_image_with(1e39), None, "S0.R"),                    # finite float64, inf as float32
    (_image_with(-3.5e38, 1, 2), None, "S1.B"),
    (_image_with(1e308, 0, 1), None, "S0.G"),             # luminance overflows too: DoP would be NaN
    (np.ones((4, H, W, 3)), {"S0.Y.stderr": np.full((H, W), 4e38)}, "S0.Y.stderr"),
])
def test_exr_refuses_values_that_are_not_finite_as_stored(tmp_path, stokes, extra, channel):
    with pytest.raises(ValueError, match=f"channel '{channel}'.*not finite as float32"):
        write_stokes_exr(tmp_path / "x.exr", stokes, extra=extra)
    assert os.listdir(tmp_path) == []


def test_exr_largest_float32_is_written(tmp_path):
    big = float(np.finfo(np.float32).max)
    write_stokes_exr(tmp_path / "x.exr", _image_with(big))
    stokes, channels, _ = read_stokes_exr(tmp_path / "x.exr")
    assert stokes[0, 1, 2, 0] == np.float32(big)
    assert all(np.all(np.isfinite(c)) for c in channels.values())


def test_temporary_name_is_short_whatever_the_target_name(tmp_path, monkeypatch):
    from engine.output import destination
    seen = []
    real = destination.make_temporary
    monkeypatch.setattr(destination, "make_temporary", lambda d, ext: seen.append(real(d, ext)) or seen[-1])
    target = tmp_path / ("n" * 251 + ".exr")                 # 255 bytes: the longest name allowed
    write_stokes_exr(target, np.ones((4, H, W, 3)))
    name = os.path.basename(seen[0])
    assert name.startswith(f".polar-tmp-{os.getpid()}-") and name.endswith(".exr") and len(name) < 40
    assert sorted(os.listdir(tmp_path)) == [target.name]


def test_check_destination(tmp_path):
    from engine.output.destination import check_destination
    deep = tmp_path / "a" / "b" / "out.exr"
    assert check_destination(deep) == str(deep)
    assert (tmp_path / "a" / "b").is_dir() and os.listdir(tmp_path / "a" / "b") == []
    existing = tmp_path / "keep.exr"
    existing.write_bytes(b"old")
    check_destination(existing)
    assert existing.read_bytes() == b"old"
    with pytest.raises(IsADirectoryError, match="is a folder"):
        check_destination(tmp_path / "a")
    with pytest.raises(OSError, match="256 bytes"):
        check_destination(tmp_path / ("n" * 252 + ".exr"))
    (tmp_path / "file").write_text("x")
    with pytest.raises(OSError, match="cannot create the folder"):
        check_destination(tmp_path / "file" / "out.exr")


def test_rescue_goes_to_the_next_folder_that_works(tmp_path, monkeypatch):
    from engine.output import rescue
    target = tmp_path / "gone" / "out.exr"                   # its folder does not exist any more
    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))
    os.makedirs(tmp_path / "tmp")
    import tempfile
    monkeypatch.setattr(tempfile, "tempdir", None)           # re-read TMPDIR
    s = physical_stokes(np.random.default_rng(1))
    path = rescue.save_rescue(target, s, {"polar.spp": 3}, {"spp": np.full((H, W), 3, np.uint32)})
    assert os.path.dirname(path) == str(tmp_path / "tmp") and os.path.basename(path).startswith("polar-rescue-")
    stokes, channels, header = read_stokes_exr(path)
    np.testing.assert_allclose(stokes, s, rtol=1e-7, atol=1e-7)
    assert header["polar.spp"] == 3 and header["polar.rescued_from"] == str(target)
    assert np.all(channels["spp"] == 3)
