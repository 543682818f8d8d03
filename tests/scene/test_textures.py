"""Textured material parameters (engine.textures): image reading, filtering, per-point models, renders.

Oracles: hand-computed filter weights and wrap rules, the PNG/EXR files' own stored values, the
sRGB transfer function, and the *constant* models evaluated with each texel's value.
"""

import struct
import zlib

import numpy as np
import OpenEXR
import pytest
from PIL import Image

from engine.errors import SceneError
from engine.materials.base import ShadingPoint
from engine.materials.htsg import HTSG
from engine.materials.lambert import Lambert
from engine.materials.mix import map_normals
from engine.materials.torrance_sparrow import TorranceSparrow
from engine.render.renderer import Renderer
from engine.scene.loader import parse_material, parse_scene
from engine.spectral import WavelengthLookup, as_spectrum
from engine.textures import ImageTexture, SurfacePoints, VertexAttributes, parse_texture_input
from engine.textures.image import read_image, srgb_to_linear


# --------------------------------------------------------------------------- helpers

def _points_at(uv: np.ndarray) -> SurfacePoints:
    """Surface points whose interpolated UV is exactly ``uv`` (2, N): one triangle per point, its
    three vertices all carrying that UV."""
    n = uv.shape[1]
    faces = np.arange(3 * n).reshape(n, 3)
    vuv = np.repeat(uv.T, 3, axis=0)
    return SurfacePoints(VertexAttributes(faces, vuv, {}), np.arange(n), np.full(n, 0.25), np.full(n, 0.25))


def _shading_points(n, rng, surface=None, lam=None):
    n_s = np.tile([[0.0], [0.0], [1.0]], (1, n))
    wo = rng.normal(size=(3, n))
    wo[2] = np.abs(wo[2]) + 0.05
    wo /= np.linalg.norm(wo, axis=0)
    lam = np.tile([[450.0], [520.0], [600.0], [680.0]], (1, n)) if lam is None else lam
    return ShadingPoint(np.zeros((3, n)), n_s, n_s, wo, lam, False, WavelengthLookup(lam), None, surface)


def _write_png16(path, data: np.ndarray):
    """A 16-bit PNG (uint16 (H, W, C), C = 1..4) with a different row filter on each row (0–4), so
    the reader's un-filtering is exercised (ISO/IEC 15948 §9, the encoder side)."""
    h, w, c = data.shape
    ctype = {1: 0, 2: 4, 3: 2, 4: 6}[c]
    raw = data.astype(">u2").tobytes()
    stride, bpp = w * c * 2, c * 2
    rows = [np.frombuffer(raw[r * stride:(r + 1) * stride], np.uint8).astype(np.int64) for r in range(h)]
    out = b""
    prev = np.zeros(stride, np.int64)
    for r, row in enumerate(rows):
        ft = r % 5
        left = np.concatenate((np.zeros(bpp, np.int64), row[:-bpp]))
        upleft = np.concatenate((np.zeros(bpp, np.int64), prev[:-bpp]))
        if ft == 0:
            f = row
        elif ft == 1:
            f = row - left
        elif ft == 2:
            f = row - prev
        elif ft == 3:
            f = row - (left + prev) // 2
        else:
            p = left + prev - upleft
            pa, pb, pc = np.abs(p - left), np.abs(p - prev), np.abs(p - upleft)
            f = row - np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, prev, upleft))
        out += bytes([ft]) + (f & 255).astype(np.uint8).tobytes()
        prev = row

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, ctype, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(out)) + chunk(b"IEND", b"")
    with open(path, "wb") as fh:
        fh.write(png)


# --------------------------------------------------------------------------- image reading

def test_png8_srgb_and_non_color_decoding(tmp_path):
    a = np.array([[[0, 10, 128], [255, 64, 200]], [[1, 2, 3], [250, 251, 252]]], np.uint8)   # top row first
    Image.fromarray(a).save(tmp_path / "a.png")
    data = read_image(str(tmp_path / "a.png"), "Non-Color")
    # row 0 of the texture is the image's bottom row (v = 0)
    np.testing.assert_array_equal(data, (a[::-1] / 255.0).astype(np.float32))
    srgb = read_image(str(tmp_path / "a.png"), "sRGB")
    c = a[::-1] / 255.0
    expect = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    np.testing.assert_array_equal(srgb, expect.astype(np.float32))
    assert read_image(str(tmp_path / "a.png")).tobytes() == srgb.tobytes()      # sRGB is the default for PNG
    assert srgb_to_linear(1.0) == 1.0 and srgb_to_linear(0.0) == 0.0


def test_png16_rgb_and_grey_full_precision(tmp_path):
    rng = np.random.default_rng(1)
    for c in (1, 3, 4):
        data = rng.integers(0, 65536, size=(7, 5, c), dtype=np.uint16)
        path = tmp_path / f"d{c}.png"
        _write_png16(path, data)
        got = read_image(str(path), "Non-Color")
        np.testing.assert_array_equal(got, (data[::-1] / 65535.0).astype(np.float32))
    # a 16-bit greyscale PNG written by Pillow
    grey = rng.integers(0, 65536, size=(4, 6)).astype(np.uint16)
    Image.fromarray(grey).save(tmp_path / "g.png")
    np.testing.assert_array_equal(read_image(str(tmp_path / "g.png"), "Non-Color")[:, :, 0],
                                  (grey[::-1] / 65535.0).astype(np.float32))


def test_exr_float_is_read_exactly_and_linear_by_default(tmp_path):
    rng = np.random.default_rng(2)
    rgb = rng.uniform(0, 5, size=(3, 4, 3)).astype(np.float32)
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {"R": rgb[..., 0].copy(), "G": rgb[..., 1].copy(), "B": rgb[..., 2].copy()}).write(
        str(tmp_path / "f.exr"))
    np.testing.assert_array_equal(read_image(str(tmp_path / "f.exr")), rgb[::-1])


def test_jpeg_is_read(tmp_path):
    Image.fromarray(np.full((8, 8, 3), 128, np.uint8)).save(tmp_path / "j.jpg", quality=100)
    got = read_image(str(tmp_path / "j.jpg"), "Non-Color")
    assert got.shape == (8, 8, 3) and np.allclose(got, 128 / 255, atol=2 / 255)


def test_missing_and_unsupported_images_name_the_field(tmp_path):
    with pytest.raises(SceneError, match=r"materials\.m\.albedo.*not found"):
        parse_material({"type": "lambert", "albedo": {"texture": "nope.png"}}, "materials.m", base_dir=str(tmp_path))
    (tmp_path / "x.gif").write_bytes(b"GIF89a")
    with pytest.raises(SceneError, match="unsupported image type"):
        parse_material({"type": "lambert", "albedo": {"texture": "x.gif"}}, "materials.m", base_dir=str(tmp_path))


# --------------------------------------------------------------------------- filtering and wrapping

PIX = np.array([[[1.0], [2.0], [4.0]],
                [[8.0], [16.0], [32.0]]], np.float32)        # H = 2 (row 0 at v = 0), W = 3


def _lookup(interp, ext, u, v):
    return ImageTexture(PIX, interp, ext).lookup(np.array([u, v], np.float64))[0]


def test_closest_filter_and_wrap_modes():
    # pixel i covers u ∈ [i/3, (i+1)/3), row j covers v ∈ [j/2, (j+1)/2)
    assert _lookup("Closest", "REPEAT", [0.1, 0.5, 0.9], [0.2, 0.2, 0.7]).tolist() == [1.0, 2.0, 32.0]
    assert _lookup("Closest", "REPEAT", [-0.1, 1.1], [0.2, -0.2]).tolist() == [4.0, 8.0]
    assert _lookup("Closest", "EXTEND", [-0.5, 1.5], [0.2, 9.0]).tolist() == [1.0, 32.0]
    assert _lookup("Closest", "CLIP", [-0.01, 0.5, 1.01, 0.5], [0.2, 0.2, 0.2, 1.2]).tolist() == [0.0, 2.0, 0.0, 0.0]
    # MIRROR: u ∈ [1, 4/3) is the mirror image of the last column, [4/3, 5/3) of the middle one
    assert _lookup("Closest", "MIRROR", [1.1, 1.5, -0.1], [0.2, 0.2, 0.2]).tolist() == [4.0, 2.0, 1.0]


def test_linear_filter_against_hand_computed_weights():
    # centre of pixel (0, 0) at (1/6, 1/4): exactly the texel
    assert _lookup("Linear", "EXTEND", [1 / 6], [1 / 4])[0] == pytest.approx(1.0, abs=1e-15)
    # halfway between centres (0,0), (1,0), (0,1), (1,1): the mean of 1, 2, 8, 16
    assert _lookup("Linear", "EXTEND", [1 / 3], [1 / 2])[0] == pytest.approx((1 + 2 + 8 + 16) / 4, rel=1e-15)
    # a quarter of the way in x from centre (1,0) to (2,0), on row 0
    x, y = (1.5 + 0.25) / 3, 0.25
    assert _lookup("Linear", "EXTEND", [x], [y])[0] == pytest.approx(0.75 * 2 + 0.25 * 4, rel=1e-15)
    # REPEAT: left of the first centre blends with the last column; CLIP blends with 0
    x = 0.0   # 0.5 pixel left of centre 0: halfway between column 2 (wrapped) and column 0
    assert _lookup("Linear", "REPEAT", [x], [0.25])[0] == pytest.approx(0.5 * 4 + 0.5 * 1, rel=1e-15)
    assert _lookup("Linear", "CLIP", [x], [0.25])[0] == pytest.approx(0.5 * 1, rel=1e-15)
    assert _lookup("Linear", "EXTEND", [x], [0.25])[0] == pytest.approx(1.0, rel=1e-15)


def test_cubic_filter_is_the_uniform_bspline():
    # at a pixel centre the B-spline weights are 1/6, 4/6, 1/6 of the neighbours (EXTEND at the edges)
    got = _lookup("Cubic", "EXTEND", [1.5 / 3], [0.25])[0]
    row0 = (1 + 4 * 2 + 4) / 6              # columns 0, 1, 2 at row 0
    row1 = (8 + 4 * 16 + 32) / 6
    expect = (1 * row0 + 4 * row0 + 1 * row1) / 6   # rows −1 (= row 0 extended), 0, 1
    assert got == pytest.approx(expect, rel=1e-14)
    # weights at any fraction sum to 1 and are ≥ 0: a constant image stays constant
    t = ImageTexture(np.full((3, 3, 1), 0.7, np.float32), "Cubic", "REPEAT")
    uv = np.random.default_rng(3).uniform(-2, 2, size=(2, 50))
    np.testing.assert_allclose(t.lookup(uv)[0], np.float32(0.7), rtol=1e-14)


# --------------------------------------------------------------------------- per-point models (oracles)

def _texture_file(tmp_path, values: np.ndarray, name="t.exr"):
    """A 1-channel float EXR with ``values`` (H, W) (row 0 = top of the file)."""
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {"Y": values.astype(np.float32)}).write(str(tmp_path / name))
    return name


def test_textured_torrance_sparrow_m_is_the_constant_model_per_texel(tmp_path):
    m_values = np.array([[0.05, 0.2, 0.45], [0.8, 0.12, 0.3]])
    name = _texture_file(tmp_path, m_values)
    mat = parse_material({"type": "torrance_sparrow", "metal": "Au", "diffuse_albedo": [0.3, 0.5, 0.2],
                          "diffuse_weight": 0.4, "m": {"texture": name, "interpolation": "Closest"}},
                         "materials.ts", base_dir=str(tmp_path))
    assert mat.varies_over_surface
    H, W = m_values.shape
    # one shading point per texel (at the pixel centre) and direction
    jj, ii = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    uv = np.stack((((ii + 0.5) / W).ravel(), ((jj + 0.5) / H).ravel()))
    texel = m_values[::-1].astype(np.float32).astype(np.float64)[jj, ii].ravel()   # row 0 = bottom
    reps = 40
    uv = np.repeat(uv, reps, axis=1)
    texel = np.repeat(texel, reps)
    n = uv.shape[1]
    rng = np.random.default_rng(5)
    sp = _shading_points(n, rng, _points_at(uv))
    wi = rng.normal(size=(3, n))
    wi[2] = np.abs(wi[2])
    wi /= np.linalg.norm(wi, axis=0)
    u_lobe, u_dir = rng.uniform(size=n), rng.uniform(size=(2, n))
    f = mat.eval(sp, wi).matrix()
    pdf = mat.pdf(sp, wi)
    s = mat.sample(sp, u_lobe, u_dir)
    for m in np.unique(texel):
        sel = np.nonzero(texel == m)[0]
        const = TorranceSparrow(mat.n, mat.k, m, diffuse_albedo=mat.albedo, diffuse_weight=0.4)
        sub = sp.take(sel)
        sub.surface = None                   # the constant model needs no surface
        np.testing.assert_array_equal(f[..., sel], const.eval(sub, wi[:, sel]).matrix())
        np.testing.assert_array_equal(pdf[sel], const.pdf(sub, wi[:, sel]))
        cs = const.sample(sub, u_lobe[sel], u_dir[:, sel])
        np.testing.assert_array_equal(s.wi[:, sel], cs.wi)
        np.testing.assert_array_equal(s.weight.matrix()[..., sel], cs.weight.matrix())
        np.testing.assert_array_equal(s.pdf[sel], cs.pdf)


def test_textured_htsg_sigma0_and_tau_are_the_constant_model_per_texel(tmp_path):
    s0_values = np.array([[0.0, 0.05, 0.18], [0.4, 1.0, 0.02]])
    tau_values = np.array([[3.0, 1.5, 0.8], [6.0, 2.0, 0.5]])
    _texture_file(tmp_path, s0_values, "s0.exr")
    _texture_file(tmp_path, tau_values, "tau.exr")
    mat = parse_material({"type": "htsg", "metal": "Al", "albedo": 0.1,
                          "sigma0_um": {"texture": "s0.exr", "interpolation": "Closest"},
                          "tau_um": {"texture": "tau.exr", "interpolation": "Closest"}},
                         "materials.h", base_dir=str(tmp_path))
    assert mat.varies_over_surface
    H, W = s0_values.shape
    jj, ii = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    uv = np.stack((((ii + 0.5) / W).ravel(), ((jj + 0.5) / H).ravel()))
    texel = np.arange(H * W)
    reps = 12
    uv, texel = np.repeat(uv, reps, axis=1), np.repeat(texel, reps)
    n = uv.shape[1]
    rng = np.random.default_rng(8)
    sp = _shading_points(n, rng, _points_at(uv))
    wi = rng.normal(size=(3, n))
    wi[2] = np.abs(wi[2])
    wi /= np.linalg.norm(wi, axis=0)
    u_lobe, u_dir = rng.uniform(size=n), rng.uniform(size=(2, n))
    f = mat.eval(sp, wi).matrix()
    pdf = mat.pdf(sp, wi)
    d = mat.delta_reflection(sp).matrix()
    smp = mat.sample(sp, u_lobe, u_dir)
    as32 = lambda a: a[::-1].astype(np.float32).astype(np.float64).ravel()   # noqa: E731 (row 0 = bottom)
    for t, (s0, tau) in enumerate(zip(as32(s0_values), as32(tau_values))):
        sel = np.nonzero(texel == t)[0]
        const = HTSG(mat.n, mat.k, s0, tau, albedo=mat.albedo)
        sub = sp.take(sel)
        sub.surface = None
        np.testing.assert_array_equal(f[..., sel], const.eval(sub, wi[:, sel]).matrix())
        np.testing.assert_array_equal(pdf[sel], const.pdf(sub, wi[:, sel]))
        np.testing.assert_array_equal(d[..., sel], const.delta_reflection(sub).matrix())
        cs = const.sample(sub, u_lobe[sel], u_dir[:, sel])
        np.testing.assert_array_equal(smp.wi[:, sel], cs.wi)
        np.testing.assert_array_equal(smp.weight.matrix()[..., sel], cs.weight.matrix())


def test_textured_weidlich_wilkie_coat_and_base_are_the_constant_model_per_texel(tmp_path):
    """Coat thickness and absorption (RGB) textured, over a base with a textured roughness."""
    thick = np.array([[0.0, 0.5], [1.0, 2.0]])
    _texture_file(tmp_path, thick, "d.exr")
    absorb = np.array([[[0.1, 0.5, 0.9], [0.2, 0.2, 0.2]], [[1.5, 0.0, 0.3], [0.7, 0.4, 0.1]]], np.float32)
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {c: absorb[..., i].copy() for i, c in enumerate("RGB")}).write(str(tmp_path / "a.exr"))
    m_tex = np.array([[0.1, 0.2], [0.3, 0.4]])
    _texture_file(tmp_path, m_tex, "m.exr")
    closest = {"interpolation": "Closest"}

    def material(d, a, m):
        return parse_material({"type": "weidlich_wilkie", "coats": [{"n": 1.5, "thickness": d, "absorption": a}],
                               "base": {"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": m}},
                              "materials.w", base_dir=str(tmp_path))
    mat = material({"texture": "d.exr", **closest}, {"texture": "a.exr", **closest},
                   {"texture": "m.exr", **closest})
    assert mat.varies_over_surface
    uv = np.array([[0.25, 0.75, 0.25, 0.75], [0.25, 0.25, 0.75, 0.75]])
    reps = 10
    uv = np.repeat(uv, reps, axis=1)
    n = uv.shape[1]
    rng = np.random.default_rng(9)
    sp = _shading_points(n, rng, _points_at(uv))
    wi = rng.normal(size=(3, n))
    wi[2] = np.abs(wi[2])
    wi /= np.linalg.norm(wi, axis=0)
    u_lobe, u_dir = rng.uniform(size=n), rng.uniform(size=(2, n))
    f = mat.eval(sp, wi).matrix()
    pdf = mat.pdf(sp, wi)
    smp = mat.sample(sp, u_lobe, u_dir)
    for t, (i, j) in enumerate(((0, 0), (1, 0), (0, 1), (1, 1))):      # texel (column i, row j from the bottom)
        sel = np.arange(t * reps, (t + 1) * reps)
        row = thick.shape[0] - 1 - j
        const = material(float(np.float32(thick[row, i])), absorb[row, i].astype(np.float64).tolist(),
                         float(np.float32(m_tex[row, i])))
        sub = sp.take(sel)
        sub.surface = None
        np.testing.assert_array_equal(f[..., sel], const.eval(sub, wi[:, sel]).matrix())
        np.testing.assert_array_equal(pdf[sel], const.pdf(sub, wi[:, sel]))
        cs = const.sample(sub, u_lobe[sel], u_dir[:, sel])
        np.testing.assert_array_equal(smp.wi[:, sel], cs.wi)
        np.testing.assert_array_equal(smp.weight.matrix()[..., sel], cs.weight.matrix())


def test_textured_coat_index_over_a_lambert_base_is_the_constant_model_per_texel(tmp_path):
    """A textured (smooth) coat index. The coat's internal reflectance sums its quadrature per
    distinct index, in another order than for a single index: equal to ~1e-15, not bit for bit.
    (A rough coat's albedo table then spans the texture's index range, as for a dispersive coat,
    and is interpolated in η: ~1e-3 from the single-index table.)"""
    n_values = np.array([[1.3, 1.5], [1.8, 2.2]])
    _texture_file(tmp_path, n_values, "n.exr")

    def material(n):
        return parse_material({"type": "weidlich_wilkie", "coats": [{"n": n, "thickness": 0.3, "absorption": 0.5}],
                               "base": {"type": "lambert", "albedo": [0.7, 0.4, 0.2]}}, "materials.w",
                              base_dir=str(tmp_path))
    mat = material({"texture": "n.exr", "interpolation": "Closest"})
    uv = np.repeat(np.array([[0.25, 0.75, 0.25, 0.75], [0.25, 0.25, 0.75, 0.75]]), 10, axis=1)
    n = uv.shape[1]
    rng = np.random.default_rng(17)
    sp = _shading_points(n, rng, _points_at(uv))
    wi = rng.normal(size=(3, n))
    wi[2] = np.abs(wi[2])
    wi /= np.linalg.norm(wi, axis=0)
    f = mat.eval(sp, wi).matrix()
    pdf = mat.pdf(sp, wi)
    for t, (i, j) in enumerate(((0, 0), (1, 0), (0, 1), (1, 1))):
        sel = np.arange(t * 10, (t + 1) * 10)
        const = material(float(np.float32(n_values[1 - j, i])))
        sub = sp.take(sel)
        sub.surface = None
        np.testing.assert_allclose(f[..., sel], const.eval(sub, wi[:, sel]).matrix(), rtol=1e-12, atol=1e-300)
        np.testing.assert_allclose(pdf[sel], const.pdf(sub, wi[:, sel]), rtol=1e-12)
    with pytest.raises(SceneError, match="a textured coat index needs a base without an exterior index"):
        parse_material({"type": "weidlich_wilkie", "coats": [{"n": {"texture": "n.exr"}}],
                        "base": {"type": "conductor", "metal": "Au"}}, "materials.w", base_dir=str(tmp_path))


def test_textured_albedo_and_weights_equal_the_constant_values(tmp_path):
    rgb = np.array([[[0.1, 0.5, 0.9], [0.3, 0.3, 0.3]]], np.float32)    # 1 × 2, one grey texel
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {c: rgb[..., i].copy() for i, c in enumerate("RGB")}).write(str(tmp_path / "c.exr"))
    tex = {"texture": "c.exr", "interpolation": "Closest"}
    lam_mat = parse_material({"type": "lambert", "albedo": tex}, "m", base_dir=str(tmp_path))
    ts = parse_material({"type": "torrance_sparrow", "n": 1.5, "m": 0.3, "diffuse_albedo": tex,
                         "specular_weight": {"texture": "c.exr", "channel": "G", "interpolation": "Closest"}},
                        "m", base_dir=str(tmp_path))
    rng = np.random.default_rng(6)
    uv = np.array([[0.25, 0.75] * 20, [0.5] * 40])
    sp = _shading_points(40, rng, _points_at(uv))
    wi = sp.wo * np.array([[-1], [-1], [1]])
    for k, texel in enumerate(rgb[0].astype(np.float64)):
        sel = np.arange(k, 40, 2)
        sub = sp.take(sel)
        sub.surface = None
        const_l = parse_material({"type": "lambert", "albedo": texel.tolist()}, "m")
        np.testing.assert_array_equal(lam_mat.eval(sp, wi).matrix()[..., sel], const_l.eval(sub, wi[:, sel]).matrix())
        const_ts = parse_material({"type": "torrance_sparrow", "n": 1.5, "m": 0.3, "diffuse_albedo": texel.tolist(),
                                   "specular_weight": float(texel[1])}, "m")
        np.testing.assert_array_equal(ts.eval(sp, wi).matrix()[..., sel], const_ts.eval(sub, wi[:, sel]).matrix())


def test_vertex_colours_interpolate_barycentrically():
    faces = np.array([[0, 1, 2]])
    col = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    pts = SurfacePoints(VertexAttributes(faces, None, {"Col": col}), np.zeros(3, np.int64),
                        np.array([0.0, 0.25, 0.5]), np.array([0.0, 0.5, 0.25]))
    mat = parse_material({"type": "lambert", "albedo": {"vertex_color": "Col"}}, "m")
    src = mat.albedo.source
    np.testing.assert_allclose(src.rgb(pts), [[1.0, 0.25, 0.25], [0.0, 0.25, 0.5], [0.0, 0.5, 0.25]], rtol=1e-15)
    assert np.all(src.texture.eval(SurfacePoints(VertexAttributes(faces, None, {}), np.zeros(1, np.int64),
                                                 np.zeros(1), np.zeros(1))) == 0)   # missing attribute: 0


def test_texture_errors_name_the_parameter(tmp_path):
    name = _texture_file(tmp_path, np.array([[0.5, 2.0]]))
    with pytest.raises(SceneError, match=r"materials\.a\.albedo: texture values .* span \[0\.5, 2\]: must be in "
                                         r"\[0, 1\]"):
        parse_material({"type": "lambert", "albedo": {"texture": name}}, "materials.a", base_dir=str(tmp_path))
    with pytest.raises(SceneError, match=r"materials\.a\.exterior_n: cannot vary over the surface"):
        parse_material({"type": "torrance_sparrow", "n": 1.5, "m": 0.3, "exterior_n": {"texture": name}}, "materials.a",
                       base_dir=str(tmp_path))
    with pytest.raises(SceneError, match=r"materials\.a\.m: a roughness texture must stay in \[0\.0001"):
        parse_material({"type": "torrance_sparrow", "n": 1.5, "m": {"texture": name, "offset": -0.5}},
                       "materials.a", base_dir=str(tmp_path))
    with pytest.raises(SceneError, match=r"materials\.a\.coats\[0\]\.exponent: a texture on this parameter of 'coat' "
                                         r"is not supported by the engine yet"):
        parse_material({"type": "weidlich_wilkie", "coats": [{"distribution": "blinn",
                                                              "exponent": {"texture": name}}]},
                       "materials.a", base_dir=str(tmp_path))
    with pytest.raises(SceneError, match=r"materials\.a\.albedo\.interpolation: must be one of Closest, Linear, Cubic"):
        parse_material({"type": "lambert", "albedo": {"texture": name, "interpolation": "Smart"}}, "materials.a",
                       base_dir=str(tmp_path))


# --------------------------------------------------------------------------- renders

def _checker_scene(albedo, tmp_path, spectral="spectral"):
    return parse_scene({
        "format": "polar-scene/1",
        "camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0], "projection": "orthographic",
                   "ortho_width": 2.0, "width": 8, "height": 8},
        "render": {"spp": 4, "max_depth": 2, "spectral": spectral, "reduce_spectral": "off"},
        "materials": {"plane": {"type": "lambert", "albedo": albedo}},
        "objects": [{"shape": "quad", "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                     "material": "plane"}],
        "lights": [{"type": "point", "position": [0.3, 0.2, 3], "intensity": 20}]}, str(tmp_path))


def test_checker_plane_renders_each_checker_with_its_albedo(tmp_path):
    """A 2×2 checker (Closest) on a plane filling an 8×8 orthographic view: every pixel of a cell
    equals the render of the plane with that cell's constant albedo (same paths, same numbers;
    both traced with 4 wavelengths: a grey constant would otherwise be traced in RGB)."""
    cells = np.array([[[200, 30, 30], [20, 180, 40]], [[30, 40, 220], [128, 128, 128]]], np.uint8)
    Image.fromarray(cells).save(tmp_path / "checker.png")
    textured = Renderer(_checker_scene({"texture": "checker.png", "interpolation": "Closest"}, tmp_path)).render()
    S = textured.stokes()
    texels = read_image(str(tmp_path / "checker.png"))                    # linear, row 0 = bottom
    assert S[0].max() > 0
    for j in range(2):
        for i in range(2):
            albedo = texels[j, i].astype(np.float64).tolist()
            const = Renderer(_checker_scene(albedo, tmp_path)).render().stokes()
            rows = slice((1 - j) * 4, (2 - j) * 4)          # image rows run top → bottom
            cols = slice(i * 4, (i + 1) * 4)
            np.testing.assert_array_equal(S[:, rows, cols], const[:, rows, cols])


# --------------------------------------------------------------------------- shading normals

def _rgb_exr(path, rgb: np.ndarray):
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {c: np.ascontiguousarray(rgb[..., i], np.float32) for i, c in enumerate("RGB")}).write(str(path))


def _plane_points(n, uv, tangents=None, flip_v=False):
    """Points on the quad [-1, 1]² (z = 0, n = +z) with its default UVs, at texture coordinates uv (2, N)."""
    verts = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    quad_uv = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    if flip_v:
        quad_uv[:, 1] = 1.0 - quad_uv[:, 1]
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    # barycentrics of uv on triangle 0 (0,0)-(1,0)-(1,1): p = (1-a-b)·t0 + a·t1 + b·t2
    v = uv[1] if not flip_v else 1.0 - uv[1]
    b2 = v
    b1 = uv[0] - v
    assert np.all(b1 >= 0)
    attrs = VertexAttributes(faces, quad_uv, {}, verts, tangents)
    return SurfacePoints(attrs, np.zeros(n, np.int64), b1, b2)


def test_tangent_frame_from_uvs_and_from_vertex_tangents():
    n = 3
    uv = np.array([[0.9, 0.8, 0.95], [0.45, 0.5, 0.3]])
    n_s = np.tile([[0.0], [0.0], [1.0]], (1, n))
    t, b = _plane_points(n, uv).tangent_frame(n_s)
    np.testing.assert_allclose(t, np.tile([[1.0], [0], [0]], (1, n)), atol=1e-15)
    np.testing.assert_allclose(b, np.tile([[0.0], [1], [0]], (1, n)), atol=1e-15)
    # mirrored v: the bitangent follows +v, i.e. −y
    t, b = _plane_points(n, uv, flip_v=True).tangent_frame(n_s)
    np.testing.assert_allclose(b, np.tile([[0.0], [-1], [0]], (1, n)), atol=1e-15)
    # given tangents (here along +y, handedness −1) win over the UVs
    tan = np.tile([0.0, 1.0, 0.0, -1.0], (4, 1))
    t, b = _plane_points(n, uv, tangents=tan).tangent_frame(n_s)
    np.testing.assert_allclose(t, np.tile([[0.0], [1], [0]], (1, n)), atol=1e-15)
    np.testing.assert_allclose(b, np.tile([[1.0], [0], [0]], (1, n)), atol=1e-15)    # −(z × y) = +x
    # a mesh without tangents in a scene where others have them: derived from its UVs
    t, b = _plane_points(n, uv, tangents=np.zeros((4, 4))).tangent_frame(n_s)
    np.testing.assert_allclose(t, np.tile([[1.0], [0], [0]], (1, n)), atol=1e-15)


def test_normal_mapped_plane_has_the_mapped_normal_and_its_frames(tmp_path):
    """A constant tangent-space normal n_t on the z = 0 plane (T = +x, B = +y): the shading normal
    is n_t in world space, and a mirror's Mueller matrix and frames are those of a plane tilted to it."""
    n_t = np.array([0.3, -0.2, 0.9])
    n_t /= np.linalg.norm(n_t)
    texel = ((n_t + 1.0) / 2.0).astype(np.float32)
    _rgb_exr(tmp_path / "n.exr", np.tile(texel, (2, 2, 1)))
    mat = parse_material({"type": "conductor", "metal": "Au", "normal_map": {"texture": "n.exr"}}, "materials.g",
                         base_dir=str(tmp_path))
    n = 50
    rng = np.random.default_rng(11)
    uv = np.stack((rng.uniform(0.55, 0.95, n), rng.uniform(0.05, 0.5, n)))
    sp = _shading_points(n, rng, _plane_points(n, uv))
    mapped = mat.shading_point(sp)
    expect = 2.0 * texel.astype(np.float64) - 1.0
    expect /= np.linalg.norm(expect)
    # the map's normal, except where the view's mirror direction would go below the surface: there
    # Cycles' correction turns it towards n_g (ensure_valid_specular_reflection, a mirror has no diffuse lobe)
    e = np.tile(expect[:, None], (1, n))
    mirror_z = 2.0 * (e * sp.wo).sum(0) * e[2] - sp.wo[2]
    kept = mirror_z >= np.minimum(0.9 * sp.wo[2], 0.01)
    assert kept.any() and not kept.all()
    np.testing.assert_allclose(mapped.n_s[:, kept], e[:, kept], rtol=1e-14, atol=1e-15)
    corrected = 2.0 * (mapped.n_s * sp.wo).sum(0) * mapped.n_s[2] - sp.wo[2]
    np.testing.assert_allclose(corrected[~kept], np.minimum(0.9 * sp.wo[2], 0.01)[~kept], atol=1e-9)
    np.testing.assert_array_equal(mapped.n_g, sp.n_g)            # the geometric normal is untouched
    lambert = parse_material({"type": "lambert", "albedo": 0.5, "normal_map": {"texture": "n.exr"}}, "materials.l",
                             base_dir=str(tmp_path))
    np.testing.assert_allclose(lambert.shading_point(sp).n_s, e, rtol=1e-14, atol=1e-15)   # diffuse: uncorrected
    # the mirror of the mapped plane is the constant conductor at a plane with that normal
    ok = ShadingNormalTest.front(mapped)
    tilted = ShadingPoint(sp.p, mapped.n_s, mapped.n_s, sp.wo, sp.lam, False, sp.lookup)
    got = mat.delta_reflection(mapped)
    ref = mat.base.delta_reflection(tilted)
    np.testing.assert_array_equal(got.matrix()[..., ok], ref.matrix()[..., ok])
    np.testing.assert_array_equal(got.x_in[:, ok], ref.x_in[:, ok])
    np.testing.assert_array_equal(got.x_out[:, ok], ref.x_out[:, ok])
    # strength 0 leaves the interpolated normal
    flat = parse_material({"type": "conductor", "metal": "Au", "normal_map": {"texture": "n.exr", "strength": 0}},
                          "materials.g", base_dir=str(tmp_path))
    np.testing.assert_allclose(flat.shading_point(sp).n_s, sp.n_s, atol=1e-15)
    # the DirectX convention (Blender 5.3) reads green pointing down: the same normal, y mirrored
    directx = parse_material({"type": "lambert", "albedo": 0.5,
                              "normal_map": {"texture": "n.exr", "convention": "directx"}},
                             "materials.g", base_dir=str(tmp_path))
    expect[1] = -expect[1]
    np.testing.assert_allclose(directx.shading_point(sp).n_s, np.tile(expect[:, None], (1, n)), rtol=1e-14,
                               atol=1e-15)
    with pytest.raises(SceneError, match=r"materials\.g\.normal_map\.convention: must be one of 'opengl', "
                                         r"'directx'.*got 'vulkan'"):
        parse_material({"type": "conductor", "metal": "Au", "normal_map": {"texture": "n.exr", "convention": "vulkan"}},
                       "materials.g", base_dir=str(tmp_path))


class ShadingNormalTest:
    @staticmethod
    def front(sp):
        """Points whose mirror direction about n_s stays above the geometric surface."""
        r = 2.0 * (sp.wo * sp.n_s).sum(0) * sp.n_s - sp.wo
        return ((r * sp.n_g).sum(0) > 0) & ((sp.wo * sp.n_s).sum(0) > 0)


def test_bump_map_ramp_tilts_the_normal_by_its_slope(tmp_path):
    """Height h = a·u (scene units × distance d) on the 2 × 2 plane: z rises by d·a/2 per unit x,
    so n ∝ (−d·a/2, 0, 1)."""
    W, a, d = 16, 0.8, 0.5
    u_centres = (np.arange(W) + 0.5) / W
    _texture_file(tmp_path, np.tile(a * u_centres, (4, 1)), "h.exr")
    mat = parse_material({"type": "lambert", "bump_map": {"texture": "h.exr", "distance": d,
                                                          "extension": "EXTEND"}},
                         "materials.b", base_dir=str(tmp_path))
    n = 20
    rng = np.random.default_rng(12)
    uv = np.stack((rng.uniform(0.6, 0.85, n), rng.uniform(0.1, 0.5, n)))
    sp = _shading_points(n, rng, _plane_points(n, uv))
    expect = np.array([-d * a / 2.0, 0.0, 1.0])
    expect /= np.linalg.norm(expect)
    np.testing.assert_allclose(mat.shading_point(sp).n_s, np.tile(expect[:, None], (1, n)), rtol=1e-6, atol=1e-7)


def test_no_light_leaks_through_at_grazing_angles_with_a_tilted_shading_normal(tmp_path):
    """Shading normal tilted 70° from the plane's normal, viewer at grazing incidence from above:
    directions that the shading normal calls 'reflected' but that go below the surface carry
    nothing (eval, samples), and a light below the plane leaves the image black."""
    n_t = np.array([math_sin(70), 0.0, math_cos(70)])
    _rgb_exr(tmp_path / "tilt.exr", np.tile(((n_t + 1) / 2).astype(np.float32), (2, 2, 1)))
    mat = parse_material({"type": "lambert", "albedo": 0.9, "normal_map": {"texture": "tilt.exr"}},
                         "materials.l", base_dir=str(tmp_path))
    n = 4000
    rng = np.random.default_rng(13)
    uv = np.stack((rng.uniform(0.55, 0.95, n), rng.uniform(0.05, 0.5, n)))
    sp = _shading_points(n, rng, _plane_points(n, uv))
    wo = np.array([[0.99], [0.0], [0.14]])               # grazing, above the plane, towards +x
    sp.wo = np.tile(wo / np.linalg.norm(wo), (1, n))
    mapped = mat.shading_point(sp)
    s = mat.sample(mapped, rng.uniform(size=n), rng.uniform(size=(2, n)))
    below = s.wi[2] < 0
    assert below.sum() > n // 10                          # the tilted hemisphere reaches below the plane
    assert not s.valid[below].any() and np.all(s.weight.matrix()[..., below] == 0)
    assert np.all(mat.eval(mapped, s.wi).matrix()[..., below] == 0)
    assert np.all(mat.base.eval(mapped, s.wi).matrix()[0, 0][:, below] > 0)   # without the guard: a leak
    # render: only a light below the plane, camera above at a grazing angle
    scene = parse_scene({
        "format": "polar-scene/1",
        "camera": {"origin": [4, 0, 0.6], "target": [0, 0, 0], "up": [0, 0, 1], "width": 16, "height": 8,
                   "fov_deg": 30},
        "render": {"spp": 8, "max_depth": 4},
        "materials": {"m": {"type": "lambert", "albedo": 0.9, "normal_map": {"texture": "tilt.exr"}}},
        "objects": [{"shape": "quad", "vertices": [[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], "material": "m"}],
        "lights": [{"type": "point", "position": [0.5, 0, -1], "intensity": 50}]}, str(tmp_path))
    S = Renderer(scene).render().stokes()
    assert np.all(S == 0)
    # the same light above the plane does light it (the scene is not simply dark)
    scene.lights[0].position = np.array([0.5, 0.0, 1.0])
    assert Renderer(scene).render().stokes()[0].max() > 0


def _cycles_g1(cos_d, cos_i):
    """Cycles' bump shadowing (kernel/closure/bsdf.h) in its Λ form: 1 / (1 + Λ), Λ = (√(1 + α² tan²θ_i) − 1) / 2,
    α² = min(1, tan²θ_d / 8)."""
    alpha2 = min(1.0, (1.0 / cos_d ** 2 - 1.0) / 8.0)
    return 1.0 / (1.0 + 0.5 * (np.sqrt(1.0 + alpha2 * (1.0 / cos_i ** 2 - 1.0)) - 1.0))


@pytest.mark.parametrize("correction", [True, False])
def test_mapped_diffuse_lobe_follows_cycles_bump_rules(tmp_path, correction):
    """A Lambert whose mapped normal N is tilted 45° towards +x on the z = 0 plane (N_s = +z), as Cycles shades
    it: lit by N·ω_i even where the viewer is behind N (but in front of the plane), nothing from a light below
    the plane or behind N, and softened by the GGX bump shadowing term when Bump Map Correction is on."""
    n_t = np.array([math_sin(45), 0.0, math_cos(45)])
    _rgb_exr(tmp_path / "tilt.exr", np.tile(((n_t + 1) / 2).astype(np.float32), (2, 2, 1)))
    tilt = parse_texture_input({"texture": "tilt.exr", "color_space": "Non-Color"}, "m", str(tmp_path))
    mat = map_normals(Lambert(as_spectrum(0.6, "albedo")), normal_map=tilt, bump_correction=correction)
    n = 4
    rng = np.random.default_rng(3)
    uv = np.stack((rng.uniform(0.6, 0.9, n), rng.uniform(0.1, 0.5, n)))
    sp = _shading_points(n, rng, _plane_points(n, uv))
    wo = np.array([-1.0, 0.0, 0.3]) / np.hypot(1.0, 0.3)      # behind N (N·ω_o < 0), in front of the plane
    sp.wo = np.tile(wo[:, None], (1, n))
    at = mat.shading_point(sp)
    big_n = at.n_s[:, 0]
    assert big_n @ wo < 0 < wo[2] and abs(big_n @ n_t - 1.0) < 1e-6
    lights = np.array([[0.5, 0.0, 1.0], [-1.0, 0.0, 0.5], [1.0, 0.0, -0.3], [0.0, 1.0, 0.05]]).T
    lights /= np.linalg.norm(lights, axis=0)
    f = mat.eval(at, lights).A[0]                    # (one wavelength row is enough: a grey Lambert)
    cos_n = big_n @ lights
    cos_s = lights[2]
    for k in range(4):
        if cos_n[k] > 0 and cos_s[k] > 0:
            want = 0.6 / np.pi * (_cycles_g1(big_n[2], cos_s[k]) if correction else 1.0)
        else:
            want = 0.0                               # behind N (k = 1), or below the plane although N sees it (k = 2)
        assert f[k] == pytest.approx(want, rel=1e-6, abs=1e-15), k
    assert f[0] > 0 and f[1] == 0 and f[2] == 0 and f[3] > 0
    if correction:                                   # near the plane's horizon the softening bites
        assert f[3] < 0.5 * 0.6 / np.pi


def test_normal_mapped_principled_is_split_into_cycles_closures_and_equals_it_where_flat(tmp_path):
    """map_normals splits a Principled dielectric (Torrance–Sparrow with "albedo_scaling") into its specular layer
    over a Lambert base, each mapped on its own; with a flat map (n_t = +z) the split material's Mueller matrices
    equal the unmapped single model's."""
    _rgb_exr(tmp_path / "flat.exr", np.tile(np.array([0.5, 0.5, 1.0], np.float32), (2, 2, 1)))
    plain = parse_material({"type": "principled", "base_color": [0.6, 0.4, 0.2], "roughness": 0.5}, "m")
    mapped = parse_material({"type": "principled", "base_color": [0.6, 0.4, 0.2], "roughness": 0.5,
                             "normal_map": {"texture": "flat.exr"}}, "m", base_dir=str(tmp_path))
    assert isinstance(plain, TorranceSparrow) and plain.has_diffuse
    assert mapped.name == "layered" and [type(c.base).__name__ for c in mapped.components] == \
        ["TorranceSparrow", "Lambert"]
    n = 300
    rng = np.random.default_rng(5)
    uv = np.stack((rng.uniform(0.6, 0.9, n), rng.uniform(0.05, 0.5, n)))
    sp = _shading_points(n, rng, _plane_points(n, uv))
    wi = rng.normal(size=(3, n))
    wi[2] = np.abs(wi[2]) + 0.05
    wi /= np.linalg.norm(wi, axis=0)
    got = mapped.eval(mapped.shading_point(sp), wi).matrix()
    want = plain.eval(sp, wi).matrix()
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-14)


def math_sin(deg):
    return np.sin(np.radians(deg))


def math_cos(deg):
    return np.cos(np.radians(deg))


def test_textured_conductor_index_and_mono_mode_equal_the_constant_values(tmp_path):
    rgb = np.array([[[0.2, 0.9, 1.4], [2.5, 2.5, 2.5]]], np.float32)
    _rgb_exr(tmp_path / "k.exr", rgb)
    mat = parse_material({"type": "conductor", "n": 0.3, "k": {"texture": "k.exr", "interpolation": "Closest"}},
                         "materials.c", base_dir=str(tmp_path))
    uv = np.array([[0.25, 0.75] * 10, [0.5] * 20])
    for mono in (False, True):
        rng = np.random.default_rng(14)
        lam = np.full((1, 20), 550.0) if mono else None
        sp = _shading_points(20, rng, _points_at(uv), lam)
        sp.mono = mono
        got = mat.delta_reflection(sp).matrix()
        for t in range(2):
            sel = np.arange(t, 20, 2)
            sub = sp.take(sel)
            sub.surface = None
            const = parse_material({"type": "conductor", "n": 0.3, "k": rgb[0, t].astype(np.float64).tolist()}, "c")
            np.testing.assert_allclose(got[..., sel], const.delta_reflection(sub).matrix(), rtol=1e-15, atol=0)


def test_scene_format_guide_texture_table_is_generated_from_the_declarations():
    from engine.materials.catalogue import MODELS
    from engine.materials.parameters import texture_support_table
    from tests.conftest import REPO
    guide = open(f"{REPO}/docs/guide/scene-format.md", encoding="utf-8").read()
    assert texture_support_table(MODELS.values()) in guide


def test_textured_materials_survive_pickling_for_distributed_workers(tmp_path):
    import pickle
    name = _texture_file(tmp_path, np.array([[0.1, 0.3], [0.2, 0.4]]))
    mat = parse_material({"type": "torrance_sparrow", "n": 1.5, "m": {"texture": name}}, "m", base_dir=str(tmp_path))
    copy = pickle.loads(pickle.dumps(mat))
    uv = np.random.default_rng(15).uniform(size=(2, 30))
    rng = np.random.default_rng(16)
    sp = _shading_points(30, rng, _points_at(uv))
    wi = sp.wo * np.array([[-1], [-1], [1]])
    np.testing.assert_array_equal(mat.eval(sp, wi).matrix(), copy.eval(sp, wi).matrix())


def test_scene_file_textures_are_relative_to_the_scene_file(tmp_path, monkeypatch):
    import json
    from engine.scene.loader import load_scene
    folder = tmp_path / "scene"
    (folder / "maps").mkdir(parents=True)
    Image.fromarray(np.full((2, 2, 3), 200, np.uint8)).save(folder / "maps" / "c.png")
    doc = {"format": "polar-scene/1",
           "camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "width": 4, "height": 4},
           "materials": {"m": {"type": "lambert", "albedo": {"texture": "maps/c.png"}}},
           "objects": [{"shape": "triangles", "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [[0, 1, 2]],
                        "uv": [[0, 0], [1, 0], [0, 1]], "colors": {"Col": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]},
                        "material": "m"}],
           "lights": [{"type": "point", "position": [0, 0, 3], "intensity": 1}]}
    (folder / "s.json").write_text(json.dumps(doc))
    monkeypatch.chdir(tmp_path)
    scene = load_scene(str(folder / "s.json"))
    assert scene.materials["m"].varies_over_surface
    np.testing.assert_array_equal(scene.meshes[0].uv, [[0, 0], [1, 0], [0, 1]])
    assert set(scene.meshes[0].colors) == {"Col"}
    doc["objects"][0]["uv"] = [[0, 0], [1, 0]]
    with pytest.raises(SceneError, match=r"objects\[0\]\.uv: must hold one finite \[u, v\] per vertex \(3\)"):
        parse_scene(doc, str(folder))


def test_textured_scene_built_in_python_renders_each_texel(tmp_path):
    """The Python API (docs/guide/command-line.md): an in-memory image on a Lambert albedo, a mesh with UVs."""
    from engine.materials.lambert import Lambert
    from engine.scene.description import Camera, Mesh, PointLight, RenderSettings, Scene
    from engine.spectral import ConstantSpectrum
    from engine.textures import TexturedSpectrum, TextureInput

    def scene(albedo):
        mesh = Mesh("plane", np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]),
                    np.array([[0, 1, 2], [0, 2, 3]]), ["m"], np.zeros(2, np.int32),
                    uv=np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]]))
        cam = Camera(np.array([0.0, 0, 5]), np.zeros(3), np.array([0.0, 1, 0]), 8, 8, projection="orthographic",
                     ortho_width=2.0)
        return Scene(cam, [mesh], {"m": Lambert(albedo)}, [PointLight(np.array([0.2, 0.1, 3]), ConstantSpectrum(20))],
                     RenderSettings(spp=2, max_depth=2, reduce_spectral="off"))
    pixels = np.array([[[0.2], [0.6]], [[0.9], [0.4]]], np.float32)      # grey, row 0 = bottom
    tex = TexturedSpectrum(TextureInput(ImageTexture(pixels, "Closest")))
    S = Renderer(scene(tex)).render().stokes()
    for j in range(2):
        for i in range(2):
            const = Renderer(scene(ConstantSpectrum(float(pixels[j, i, 0])))).render().stokes()
            rows, cols = slice((1 - j) * 4, (2 - j) * 4), slice(i * 4, (i + 1) * 4)
            np.testing.assert_array_equal(S[:, rows, cols], const[:, rows, cols])


def test_a_texture_input_built_in_code_is_a_parameter_value():
    """What an exporter with images in memory (Blender) passes: no file, the same checks."""
    from engine.textures import TextureInput
    tex = TextureInput(ImageTexture(np.array([[[0.1], [0.3]]], np.float32), "Closest"), scale=0.5)
    mat = parse_material({"type": "torrance_sparrow", "n": 1.5, "m": tex}, "materials.x")
    assert mat.varies_over_surface and (mat.m.lo, mat.m.hi) == (np.float32(0.1) * 0.5, np.float32(0.3) * 0.5)
    with pytest.raises(SceneError, match=r"materials\.x\.albedo: texture values .* must be in \[0, 1\]"):
        parse_material({"type": "lambert", "albedo": TextureInput(tex.texture, scale=5.0)}, "materials.x")


# --------------------------------------------------------------------------- sRGB images filtered encoded (Cycles)

def _cycles_srgb_to_linear(c):
    """Cycles' util/color.h color_srgb_to_linear, written out per value."""
    if c < 0.04045:
        return 0.0 if c < 0.0 else c * (1.0 / 12.92)
    return ((c + 0.055) * (1.0 / 1.055)) ** 2.4


def _cycles_srgb_lookup(codes, u, v, cubic=False):
    """Cycles' lookup of an 8-bit sRGB image (scene/image.cpp compress_as_srgb), one point at a time:
    bilinear (or cubic B-spline) filter of the stored bytes / 255 with REPEAT, then colour channels
    decoded (svm_image_texture), alpha as filtered."""
    H, W, C = codes.shape
    x, y = u * W - 0.5, v * H - 0.5
    i0, j0 = int(np.floor(x)), int(np.floor(y))
    fx, fy = x - i0, y - j0
    if cubic:
        def w(t):
            return [(1 - t) ** 3 / 6, (3 * t ** 3 - 6 * t ** 2 + 4) / 6, (-3 * t ** 3 + 3 * t ** 2 + 3 * t + 1) / 6,
                    t ** 3 / 6]
        offsets, wx, wy = (-1, 0, 1, 2), w(fx), w(fy)
    else:
        offsets, wx, wy = (0, 1), [1 - fx, fx], [1 - fy, fy]
    acc = np.zeros(C)
    for b, dj in enumerate(offsets):
        for a, di in enumerate(offsets):
            acc += wx[a] * wy[b] * codes[(j0 + dj) % H, (i0 + di) % W] / 255.0
    colour = 1 if C <= 2 else 3
    return np.array([_cycles_srgb_to_linear(c) if k < colour else c for k, c in enumerate(acc)])


@pytest.mark.parametrize("interpolation", ["Linear", "Cubic"])
@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_srgb_texture_lookup_is_cycles_filter_then_decode(interpolation, channels):
    rng = np.random.default_rng(3)
    codes = rng.integers(0, 256, size=(3, 5, channels)).astype(np.uint8)
    uv = rng.uniform(-0.3, 1.3, size=(2, 200))
    expected = np.array([_cycles_srgb_lookup(codes, u, v, interpolation == "Cubic") for u, v in uv.T]).T
    for pixels in (codes, (codes / 255.0).astype(np.float32)):      # integer codes or float encoded values
        tex = ImageTexture(pixels, interpolation, "REPEAT", interpolation_space="srgb")
        got = tex.lookup(uv)
        np.testing.assert_allclose(got, expected, rtol=2e-6, atol=1e-9)     # float32 texels / results
        lo, hi = tex.value_range()
        assert np.all(got >= lo[:, None]) and np.all(got <= hi[:, None])


def test_srgb_texture_differs_from_linear_interpolation_between_texels_as_cycles():
    """Half-way between a black and a white texel: dec(½) = 0.214 (Cycles), not ½ (decoded texels lerped)."""
    codes = np.array([[[0], [255]]], np.uint8)
    tex = ImageTexture(codes, "Linear", "EXTEND", interpolation_space="srgb")
    got = tex.lookup(np.array([[0.5, 0.375], [0.5, 0.5]]))[0]
    np.testing.assert_allclose(got, [_cycles_srgb_to_linear(0.5), _cycles_srgb_to_linear(0.25)], rtol=1e-6)
    assert got[0] < 0.22


def test_srgb_texture_keeps_decoded_texels_at_centres_and_with_closest(tmp_path):
    """Texel centres, Closest lookups and the bounds are bit for bit those of the texels decoded at
    load time (read_image's "sRGB" pixels), so such renders do not change."""
    from engine.textures.image import read_texture
    rng = np.random.default_rng(5)
    Image.fromarray(rng.integers(0, 256, size=(4, 6, 4)).astype(np.uint8)).save(tmp_path / "t.png")
    decoded = read_image(str(tmp_path / "t.png"), "sRGB")
    encoded, space = read_texture(str(tmp_path / "t.png"), "sRGB")
    assert space == "srgb" and encoded.dtype == np.uint8
    jj, ii = np.meshgrid(np.arange(4), np.arange(6), indexing="ij")
    centres = np.stack((((ii + 0.5) / 6).ravel(), ((jj + 0.5) / 4).ravel()))
    anywhere = rng.uniform(-1, 2, size=(2, 300))
    for interpolation, uv in (("Closest", anywhere), ("Linear", centres)):
        for extension in ("REPEAT", "CLIP"):
            new = ImageTexture(encoded, interpolation, extension, interpolation_space="srgb")
            old = ImageTexture(decoded, interpolation, extension)
            np.testing.assert_array_equal(new.lookup(uv), old.lookup(uv))
            for a, b in zip(new.value_range(), old.value_range()):
                np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ImageTexture(encoded, interpolation_space="srgb").linear_pixels, decoded)


def test_srgb_texture_clip_reaches_black_and_negative_encoded_values_decode_to_zero():
    tex = ImageTexture(np.array([[[200], [200]]], np.uint8), "Linear", "CLIP", interpolation_space="srgb")
    got = tex.lookup(np.array([[0.5, 1.0, 1.25 - 1e-9], [0.5, 0.5, 0.5]]))[0]
    np.testing.assert_allclose(got, [_cycles_srgb_to_linear(200 / 255), _cycles_srgb_to_linear(100 / 255),
                                     _cycles_srgb_to_linear(0.0)], rtol=1e-6, atol=1e-9)
    assert tex.value_range()[0][0] == 0.0
    neg = ImageTexture(np.array([[[-0.5], [0.5]]], np.float32), "Linear", "EXTEND", interpolation_space="srgb")
    assert neg.lookup(np.array([[0.0, 0.5], [0.5, 0.5]]))[0, 0] == 0.0
    assert neg.value_range()[0][0] == 0.0
    with pytest.raises(SceneError, match="interpolation_space"):
        ImageTexture(np.zeros((1, 1, 3), np.float32), interpolation_space="gamma")
    with pytest.raises(SceneError, match="integer texels"):
        ImageTexture(np.zeros((1, 1, 3), np.uint8))


def test_scene_file_srgb_images_are_filtered_encoded_and_white_stays_in_range(tmp_path):
    """Scene files follow Cycles: sRGB images (8-bit default, or a float file tagged so) are
    filtered on their encoded values; Non-Color/Linear ones linearly.  A white 8-bit texel
    decodes to exactly 1, so an albedo texture reaching it passes the loader's [0, 1] check."""
    from engine.textures.inputs import parse_texture_input
    Image.fromarray(np.array([[[0, 0, 0], [255, 255, 255]]], np.uint8)).save(tmp_path / "bw.png")
    _rgb_exr(tmp_path / "bw.exr", np.array([[[0.0, 0, 0], [1, 1, 1]]], np.float32))
    half = np.array([[0.5], [0.5]])
    for raw, expected in (({"texture": "bw.png"}, _cycles_srgb_to_linear(0.5)),
                          ({"texture": "bw.exr", "color_space": "sRGB"}, _cycles_srgb_to_linear(0.5)),
                          ({"texture": "bw.png", "color_space": "Non-Color"}, 0.5),
                          ({"texture": "bw.exr"}, 0.5)):
        source = parse_texture_input({**raw, "extension": "EXTEND"}, "materials.m.albedo", str(tmp_path))
        np.testing.assert_allclose(source.texture.lookup(half)[:, 0], expected, rtol=1e-6)
        assert source.bounds(rgb=True) == (0.0, 1.0)
    mat = parse_material({"type": "lambert", "albedo": {"texture": "bw.png"}}, "materials.m", base_dir=str(tmp_path))
    assert (mat.albedo.lo, mat.albedo.hi) == (0.0, 1.0)


def test_texels_are_stored_read_only_and_contiguous_without_touching_the_callers_array():
    """Blender hands writeable (and possibly strided) pixels, image files read-only ones: stored alike, the compiled
    lookups have one signature (the one the precompile compiles), and the caller's array keeps its flags."""
    base = np.random.default_rng(3).random((6, 10, 3)).astype(np.float32)
    strided = base[:, ::2]
    t = ImageTexture(strided, "Linear", "REPEAT")
    assert t.pixels.flags.c_contiguous and not t.pixels.flags.writeable
    assert base.flags.writeable and np.array_equal(t.pixels, strided)
    c = ImageTexture(base, "Linear", "REPEAT")
    assert not c.pixels.flags.writeable and base.flags.writeable
    uv = np.array([[0.13, 0.57, 0.91], [0.2, 0.44, 0.8]])
    copy = ImageTexture(np.ascontiguousarray(strided), "Linear", "REPEAT")
    np.testing.assert_array_equal(t.lookup(uv), copy.lookup(uv))
