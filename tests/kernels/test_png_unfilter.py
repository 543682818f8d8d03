"""16-bit PNG un-filtering (engine.textures.image.png_unfilter): the compiled kernel gives the NumPy
reference's bytes on every filter type and pixel size; whole-file decoding against an independent
encoder is in test_textures.py (test_png16_rgb_and_grey_full_precision)."""

import numpy as np
import pytest

from engine.textures import image as image_module


@pytest.mark.parametrize("bpp", [2, 4, 6, 8])
def test_compiled_unfilter_equals_the_numpy_reference(bpp):
    rng = np.random.default_rng(bpp)
    height, width = 23, 17
    raw = rng.integers(0, 256, (height, 1 + width * bpp)).astype(np.uint8)
    raw[:, 0] = rng.permutation(np.arange(height) % 5)       # every filter type, in mixed order
    expect = image_module.png_unfilter_numpy(raw, bpp)
    np.testing.assert_array_equal(image_module.png_unfilter(raw, bpp), expect)
    assert expect.dtype == np.uint8 and expect.shape == (height, width * bpp)


def test_corrupt_data_is_a_scene_error(tmp_path):
    import struct
    import zlib

    from engine.errors import SceneError

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
    body = bytes([7]) + bytes(12)                              # filter type 7 does not exist
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 2, 1, 16, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(body)) + chunk(b"IEND", b"")
    (tmp_path / "bad.png").write_bytes(png)
    with pytest.raises(SceneError, match="corrupt 16-bit PNG"):
        image_module.read_image(str(tmp_path / "bad.png"), "Non-Color", field="t")
