"""Radiance .hdr (RGBE) reading (engine.textures.image): against an independently written file
(Blender's writer through bpy) and against hand-encoded files in every scanline coding and
orientation, whose texels follow from the format's definition c·2^(e − 136) as Blender and
OpenImageIO (Cycles' image reader) decode it."""

import json
import re

import numpy as np
import pytest

from engine.errors import SceneError
from engine.textures import image as image_module
from engine.textures.image import read_image


def _texels(rgbe):
    """The format's definition of a texel, written out here independently of the reader."""
    rgbe = np.asarray(rgbe, np.int64)
    out = np.zeros(rgbe.shape[:-1] + (3,))
    for idx in np.ndindex(rgbe.shape[:-1]):
        r, g, b, e = rgbe[idx]
        if e:
            out[idx] = [c * 2.0 ** (e - 136) for c in (r, g, b)]
    return out


def _rle_channel(values):
    """New-style run-length coding of one channel: runs of ≥ 3 equal bytes, literals otherwise."""
    out, i, n = bytearray(), 0, len(values)
    while i < n:
        j = i
        while j < n and values[j] == values[i] and j - i < 127:
            j += 1
        if j - i >= 3:
            out += bytes([128 + j - i, values[i]])
            i = j
            continue
        k = i
        while k < n and k - i < 128 and not (k + 2 < n and values[k] == values[k + 1] == values[k + 2]):
            k += 1
        out += bytes([k - i]) + bytes(values[i:k])
        i = k
    return bytes(out)


def _encode(rgbe_scanlines, coding):
    """Pixel data of (n_scan, length, 4) RGBE bytes, scanline by scanline."""
    out = bytearray()
    for line in np.asarray(rgbe_scanlines, np.uint8):
        length = len(line)
        if coding == "rle":
            out += bytes([2, 2, length >> 8, length & 255])
            for ch in range(4):
                out += _rle_channel(list(line[:, ch]))
        elif coding == "flat":
            out += line.tobytes()
        else:                    # old-style runs: a pixel then (1, 1, 1, n) for its repeats
            i = 0
            while i < length:
                out += line[i].tobytes()
                j = i + 1
                while j < length and (line[j] == line[i]).all():
                    j += 1
                repeat = min(j - i - 1, 255)          # longer runs: test_old_style_runs_longer_than_255
                j = i + 1 + repeat
                if repeat:
                    out += bytes([1, 1, 1, repeat])
                i = j
    return bytes(out)


def _write_hdr(path, rgbe_scanlines, resolution, coding="rle", header=b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n"):
    path.write_bytes(header + b"\n" + resolution.encode() + b"\n" + _encode(rgbe_scanlines, coding))


def _random_rgbe(rng, n_scan, length):
    """RGBE pixels with runs in every channel (so the run coder has work) and some zero texels."""
    px = rng.integers(0, 256, (n_scan, length, 4))
    px[..., 3] = rng.integers(100, 160, (n_scan, length))
    px[:, 5:17] = px[:, 5:6]                      # a run of equal pixels
    px[:, 20:30, 1] = 7                           # a run in one channel only
    px[rng.random((n_scan, length)) < 0.05] = 0   # e = 0: black
    return px.astype(np.uint8)


@pytest.mark.parametrize("coding", ["rle", "flat", "old"])
def test_scanline_codings_give_the_defined_texels(tmp_path, coding):
    rng = np.random.default_rng(3)
    px = _random_rgbe(rng, 6, 40)
    path = tmp_path / f"{coding}.hdr"
    _write_hdr(path, px, "-Y 6 +X 40", coding)
    got = read_image(str(path))                   # row 0 = bottom, as every texture
    np.testing.assert_array_equal(got, _texels(px)[::-1].astype(np.float32))


def test_old_style_runs_longer_than_255_shift_by_8_bits(tmp_path):
    px = np.zeros((1, 300, 4), np.uint8)
    px[0, :] = (10, 20, 30, 129)
    px[0, 0] = (1, 2, 3, 130)
    # pixel 0, pixel 1, then 298 repeats of pixel 1: (1,1,1,42) = 42, then (1,1,1,1) shifted by 8 = 256
    data = px[0, 0].tobytes() + px[0, 1].tobytes() + bytes([1, 1, 1, 42, 1, 1, 1, 1])
    (tmp_path / "o.hdr").write_bytes(b"#?RGBE\n\n-Y 1 +X 300\n" + data)
    np.testing.assert_array_equal(read_image(str(tmp_path / "o.hdr"))[0], _texels(px)[0].astype(np.float32))


ORIENTATIONS = {  # resolution line -> how the stored scanlines map onto the upright image (top row first)
    "-Y 5 +X 9": lambda img: img,
    "+Y 5 +X 9": lambda img: img[::-1],
    "-Y 5 -X 9": lambda img: img[:, ::-1],
    "+Y 5 -X 9": lambda img: img[::-1, ::-1],
    "+X 9 -Y 5": lambda img: img.transpose(1, 0, 2),
    "-X 9 -Y 5": lambda img: img.transpose(1, 0, 2)[:, ::-1],
    "+X 9 +Y 5": lambda img: img.transpose(1, 0, 2)[::-1],
    "-X 9 +Y 5": lambda img: img.transpose(1, 0, 2)[::-1, ::-1],
}


@pytest.mark.parametrize("resolution", sorted(ORIENTATIONS))
def test_orientations(tmp_path, resolution):
    """An upright 5×9 image stored in each orientation reads back upright."""
    rng = np.random.default_rng(4)
    upright = _random_rgbe(rng, 5, 9)
    # the stored scanlines: invert the mapping (each mapping is its own inverse up to the transpose)
    stored = {"-Y 5 +X 9": upright, "+Y 5 +X 9": upright[::-1], "-Y 5 -X 9": upright[:, ::-1],
              "+Y 5 -X 9": upright[::-1, ::-1], "+X 9 -Y 5": upright.transpose(1, 0, 2),
              "-X 9 -Y 5": upright[:, ::-1].transpose(1, 0, 2), "+X 9 +Y 5": upright[::-1].transpose(1, 0, 2),
              "-X 9 +Y 5": upright[::-1, ::-1].transpose(1, 0, 2)}[resolution]
    np.testing.assert_array_equal(ORIENTATIONS[resolution](stored), upright)
    path = tmp_path / "o.hdr"
    _write_hdr(path, stored, resolution, "flat")
    np.testing.assert_array_equal(read_image(str(path))[::-1], _texels(upright).astype(np.float32))


def test_compiled_decoder_equals_the_numpy_reference(tmp_path):
    rng = np.random.default_rng(6)
    for coding in ("rle", "flat", "old"):
        px = _random_rgbe(rng, 7, 33)
        data = np.frombuffer(_encode(px, coding), np.uint8)
        s0, a = image_module.decode_rgbe_runs_numpy(data, 7, 33)
        s1, b = image_module.decode_rgbe_runs(data, 7, 33)
        assert s0 == s1 == 0
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(a, px)
        for cut in (5, len(data) // 2, len(data) - 1):         # truncated: both report it
            assert image_module.decode_rgbe_runs_numpy(data[:cut], 7, 33)[0] == 1
            assert image_module.decode_rgbe_runs(data[:cut], 7, 33)[0] == 1


@pytest.mark.parametrize("content, message", [
    (b"P6\n", "does not start with '#?'"),
    (b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 1\n\x01\x02\x03\x80", "only 32-bit_rle_rgbe"),
    (b"#?RADIANCE\n\n-Y 2 -Y 3\n", "bad resolution line"),
    (b"#?RADIANCE\n\n-Y 2 +X 3\n\x01\x02\x03\x80", "ends early"),
    (b"#?RADIANCE\n\n-Y 1 +X 8\n\x02\x02\x00\x09", "other than the image width"),
    (b"#?RADIANCE\n\n-Y 1 +X 8\n\x02\x02\x00\x08\x89\x01", "longer than its scanline"),
    (b"#?RADIANCE\n-Y 1 +X 8\n", "no end"),
    (b"#?RADIANCE\n\n-Y 1 +X 8", "no pixel data"),
])
def test_bad_files_name_the_problem(tmp_path, content, message):
    path = tmp_path / "bad.hdr"
    path.write_bytes(content)
    with pytest.raises(SceneError, match=re.escape(message)):
        read_image(str(path), field="materials.m.albedo")


@pytest.mark.blender
def test_blender_written_hdr_reads_to_rgbe_precision(tmp_path):
    """An image written by Blender's own Radiance writer (bpy, view transform Standard so the
    floats are written as they are) reads back within RGBE's shared-exponent precision: each channel
    at most one mantissa step (≤ the pixel's largest channel / 128) below the original, as Blender
    truncates on writing and reads the step's lower end, as its own reader and OpenImageIO do."""
    bpy = pytest.importorskip("bpy")
    w, h = 37, 19
    rng = np.random.default_rng(5)
    px = np.ones((h, w, 4), np.float32)
    px[..., :3] = rng.uniform(0, 1, (h, w, 3)) * 10.0 ** rng.uniform(-3, 3, (h, w, 1))
    img = bpy.data.images.new("polar_hdr_test", w, h, float_buffer=True, alpha=False)
    scene = bpy.data.scenes.new("polar_hdr_test")     # its own settings: other tests' scenes are left alone
    try:
        img.pixels.foreach_set(px.ravel())            # Blender's rows: bottom first, as ours
        scene.view_settings.view_transform = "Standard"
        scene.view_settings.look = "None"
        scene.view_settings.exposure, scene.view_settings.gamma = 0.0, 1.0
        settings = scene.render.image_settings
        if hasattr(settings, "media_type"):            # Blender 5: single images, not multilayer
            settings.media_type = "IMAGE"
        settings.file_format = "HDR"
        img.save_render(str(tmp_path / "b.hdr"), scene=scene)
    finally:
        bpy.data.images.remove(img)
        bpy.data.scenes.remove(scene)
    got = read_image(str(tmp_path / "b.hdr")).astype(np.float64)
    ref = px[..., :3].astype(np.float64)
    peak = ref.max(axis=-1, keepdims=True)
    assert got.shape == ref.shape
    assert np.all(got <= ref * (1 + 1e-6)) and np.all(ref - got <= peak * 2.0 ** -7 * 1.0001)
    bright = ref >= 0.5 * peak                         # channels near the peak: ~2 % or better
    assert np.all(np.abs(got - ref)[bright] <= 0.02 * ref[bright])


@pytest.mark.blender
def test_texels_equal_blenders_and_openimageios_reading(tmp_path):
    """The decoding Cycles sees: random RGBE texels (every exponent, mantissas 0-255) read by Blender
    (bpy.data.images.load) and by OpenImageIO equal ours exactly (float32)."""
    bpy = pytest.importorskip("bpy")
    oiio = pytest.importorskip("OpenImageIO")
    rng = np.random.default_rng(8)
    w, h = 64, 9
    rgbe = rng.integers(0, 256, (h, w, 4), dtype=np.uint8)
    rgbe[..., 3] = rng.integers(100, 170, (h, w))
    rgbe[0, :4, 3] = 0                                                 # e = 0: black
    path = tmp_path / "t.hdr"
    path.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {h} +X {w}\n".encode() + rgbe.tobytes())
    ours = read_image(str(path), "Linear")                             # row 0 = bottom
    img = bpy.data.images.load(str(path))
    try:
        blender = np.array(img.pixels[:], np.float32).reshape(h, w, 4)[..., :3]   # bottom row first too
    finally:
        bpy.data.images.remove(img)
    np.testing.assert_array_equal(ours, blender)
    theirs = oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)[::-1]     # OIIO: top row first
    np.testing.assert_array_equal(ours, theirs[..., :3])


def test_environment_map_from_hdr_equals_the_same_texels_as_exr(tmp_path):
    """A .hdr environment is linear by default and lights the scene with its texels exactly as an
    EXR holding the same floats."""
    import OpenEXR

    from engine.scene.loader import parse_scene

    rng = np.random.default_rng(8)
    px = _random_rgbe(rng, 8, 16)
    _write_hdr(tmp_path / "sky.hdr", px, "-Y 8 +X 16")
    texels = _texels(px).astype(np.float32)
    OpenEXR.File({"compression": OpenEXR.NO_COMPRESSION},
                 {"RGB": np.ascontiguousarray(texels)}).write(str(tmp_path / "sky.exr"))
    base = {"format": "polar-scene/1", "camera": {"origin": [0, 0, 0], "target": [1, 0, 0], "up": [0, 0, 1],
                                                "width": 8, "height": 8, "fov_deg": 40},
            "materials": {}, "objects": []}
    lights = []
    for name in ("sky.hdr", "sky.exr"):
        scene = parse_scene(json.loads(json.dumps({**base, "lights": [{"type": "environment", "image": name}]})),
                            base_dir=str(tmp_path))
        lights.append(scene.lights[0])
    np.testing.assert_array_equal(lights[0].image, lights[1].image)
    np.testing.assert_array_equal(lights[0].image, texels)
