"""Robustness of texture-valued and extreme material inputs (issue 32): each class either renders
what the input means, with no dropped (non-finite) samples, or is refused with one SceneError
naming the field — never a TypeError, a black image or NaN.

Classes: a textured conductor index with κ = 0 or omitted; zero-length shading normals (a
(0.5, 0.5, 0.5) normal-map texel, strength ½ on a texel opposite the normal: Cycles keeps the
unperturbed normal there); huge finite UVs; the index-matched rough dielectric; texels stored in
float32 one rounding beyond a range limit; and a fuzzer over every texturable parameter of every
model at and beyond its declared range.
"""

import math

import numpy as np
import OpenEXR
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from engine.errors import SceneError
from engine.materials.base import BSDFFlags
from engine.materials.catalogue import MODELS
from engine.materials.dielectric import SmoothDielectric
from engine.materials.normal_map import ShadingNormal
from engine.materials.rough_dielectric import RoughDielectric
from engine.render.renderer import Renderer
from engine.scene.loader import parse_material, parse_scene
from engine.textures.texture import EXTENSIONS, INTERPOLATIONS, ImageTexture


def write_exr(path, pixels):
    """A float32 EXR: (H, W) grey as R, or (H, W, 3) as R, G, B; row 0 at the top of the file."""
    pixels = np.asarray(pixels, np.float32)
    if pixels.ndim == 2:
        channels = {"R": pixels}
    else:
        channels = {c: np.ascontiguousarray(pixels[..., i]) for i, c in enumerate("RGB")}
    OpenEXR.File({"type": OpenEXR.scanlineimage}, channels).write(str(path))
    return str(path)


def quad_scene(material, uv=((0, 0), (1, 0), (1, 1), (0, 1)), spp=4, size=8, environment=1.0, lights=()):
    """A square quad (material "m") filling most of a small view from above-front, under a uniform sky."""
    return {
        "format": "polar-scene/1",
        "camera": {"origin": [0, -2.5, 2.5], "target": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 30,
                   "width": size, "height": size},
        "render": {"spp": spp, "max_depth": 6, "seed": 3},
        "materials": {"m": material},
        "objects": [{"shape": "quad", "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                     "uv": [list(map(float, p)) for p in uv], "material": "m"}],
        "lights": [{"type": "environment", "radiance": environment}, *lights],
    }


def render(doc, base_dir):
    """(Stokes (4, H, W, 3), non-finite samples dropped) of a scene document."""
    result = Renderer(parse_scene(doc, base_dir=str(base_dir))).render()
    stokes = result.stokes()
    assert np.isfinite(stokes).all()
    return stokes, result.stats["nonfinite"]


SUN = {"type": "directional", "direction": [0.3, 0.5, -1.0], "irradiance": 3.0}


# ----------------------------------------------------------------------------- textured conductor, κ = 0

@pytest.mark.parametrize("k", [None, 0.0, {"texture": "zero.exr"}])
@pytest.mark.parametrize("n", [1.5, 0.6, (1.4, 1.6, 1.8)])
def test_textured_real_conductor_index_renders_as_the_constant_one(tmp_path, n, k):
    """n from a uniform texture with κ omitted, 0, or a texture of 0: the image of the constant n
    (n < 1 totally reflects beyond the critical angle: it retards, and the auto transport sees it).
    One wavelength, so that the constant's λ-independent transport and the texture's spectral one
    trace the same numbers."""
    texel = np.full((2, 2, 3), n, np.float32) if isinstance(n, tuple) else np.full((2, 2), n, np.float32)
    write_exr(tmp_path / "n.exr", texel)
    write_exr(tmp_path / "zero.exr", np.zeros((2, 2), np.float32))
    textured = {"type": "conductor", "n": {"texture": "n.exr"}}
    constant = {"type": "conductor", "n": list(n) if isinstance(n, tuple) else n}
    if k is not None:
        textured["k"] = k
        constant["k"] = 0.0
    docs = [quad_scene(m, lights=[SUN]) for m in (textured, constant)]
    for doc in docs:
        doc["render"]["spectral"] = "mono"
    got, dropped = render(docs[0], tmp_path)
    want, _ = render(docs[1], tmp_path)
    assert dropped == 0 and got[0].max() > 0
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-5)          # other kernels: rounding apart
    material = parse_material(textured, "materials.m", base_dir=str(tmp_path))
    assert material.flags & BSDFFlags.RETARDING          # a textured n may totally reflect: auto sees it


# ----------------------------------------------------------------------------- zero-length shading normals

@pytest.mark.parametrize("material", [{"type": "lambert", "albedo": 0.7}, {"type": "dielectric", "n": 1.5},
                                      {"type": "conductor", "metal": "Au"},
                                      {"type": "rough_dielectric", "n": 1.5, "alpha": 0.2}])
@pytest.mark.parametrize("texel,strength", [((0.5, 0.5, 0.5), 1.0), ((0.5, 0.5, 0.5), 0.3),
                                            ((0.5, 0.5, 0.0), 0.5), ((0.5, 0.5, 0.0), 1.0)])
def test_zero_length_mapped_normal_keeps_the_unperturbed_normal(tmp_path, material, texel, strength):
    """A texel whose normal is the zero vector, or a strength that blends a normal with its opposite
    into zero, shades with the interpolated normal (Cycles' rule): the image of the unmapped material,
    no dropped samples.  ((0.5, 0.5, 0) at strength 1 is a normal pointing into the surface: a valid,
    if strange, map: it must only stay finite.)"""
    write_exr(tmp_path / "n.exr", np.tile(np.asarray(texel, np.float32), (2, 2, 1)))
    mapped_material = dict(material, normal_map={"texture": "n.exr", "strength": strength})
    got, dropped = render(quad_scene(mapped_material, lights=[SUN]), tmp_path)
    assert dropped == 0
    if texel == (0.5, 0.5, 0.0) and strength == 1.0:
        return
    want, _ = render(quad_scene(material, lights=[SUN]), tmp_path)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_zero_mapped_normal_is_the_shading_normal_per_point(tmp_path):
    """Per point: zero texels keep n_s, the others are mapped (a checker of flat and zero texels)."""
    texels = np.array([[[0.5, 0.5, 0.5], [0.5, 0.5, 1.0]], [[0.5, 0.5, 1.0], [0.5, 0.5, 0.5]]], np.float32)
    write_exr(tmp_path / "n.exr", texels)
    material = parse_material({"type": "lambert", "albedo": 0.5, "normal_map": {"texture": "n.exr",
                                                                                "interpolation": "Closest"}},
                              "materials.m", base_dir=str(tmp_path))
    assert isinstance(material, ShadingNormal)
    from tests.scene.test_textures import _plane_points, _shading_points
    rng = np.random.default_rng(5)
    u = rng.uniform(0.01, 0.99, 64)
    uv = np.stack((u, u * rng.uniform(0.0, 1.0, 64)))          # on the quad's first triangle (u ≥ v)
    sp = _shading_points(64, rng, _plane_points(64, uv))
    n = material.shading_normal(sp)
    assert np.isfinite(n).all()
    np.testing.assert_allclose(np.einsum("ij,ij->j", n, n), 1.0, rtol=1e-12)
    np.testing.assert_allclose(n, sp.n_s, atol=1e-12)        # flat texels map to n_s too: all equal n_s


# ----------------------------------------------------------------------------- huge UVs

@pytest.mark.parametrize("extension", EXTENSIONS)
@pytest.mark.parametrize("interpolation", INTERPOLATIONS)
def test_huge_coordinates_read_what_the_extension_makes_of_them(interpolation, extension):
    pixels = np.random.default_rng(2).random((5, 7, 3)).astype(np.float32)
    texture = ImageTexture(pixels, interpolation, extension)
    period_end = {"REPEAT": 0.0, "MIRROR": 0.0}
    huge = np.array([[1.7e308, -1.7e308, 2.0 ** 60, -(2.0 ** 53), 3e20, np.inf, np.nan],
                     [1.7e308, 2.0 ** 62, -1e300, 1e300, 0.25, 0.5, 0.5]])
    got = texture.lookup(huge)
    assert np.isfinite(got).all()

    def equivalent(u):
        if not np.isfinite(u):
            return 0.0
        if extension in period_end:
            return float(np.mod(u, 1.0 if extension == "REPEAT" else 2.0))
        return min(max(u, -1.0), 2.0)
    small = np.vectorize(equivalent)(huge)
    np.testing.assert_array_equal(got, texture.lookup(small))
    ordinary = np.array([[0.3, -0.7, 1.9, 5.25], [0.1, 0.45, -3.2, 0.9]])      # below 2^52: unchanged bits
    np.testing.assert_array_equal(texture.lookup(ordinary), ImageTexture(pixels, interpolation, extension)
                                  .lookup(ordinary.copy()))


@pytest.mark.parametrize("interpolation", ["Linear", "Cubic", "Closest"])
@pytest.mark.parametrize("scale", [1.7e308, 1e300, 3.4e38, 1e20])
def test_render_with_huge_vertex_uvs_drops_no_sample(tmp_path, interpolation, scale):
    write_exr(tmp_path / "c.exr", np.random.default_rng(4).random((4, 4, 3)).astype(np.float32))
    uv = ((-scale, -scale), (scale, -scale), (scale, scale), (-scale, scale))
    stokes, dropped = render(quad_scene({"type": "lambert", "albedo": {"texture": "c.exr",
                                                                       "interpolation": interpolation}}, uv=uv),
                             tmp_path)
    assert dropped == 0 and stokes[0].max() > 0


# ----------------------------------------------------------------------------- index-matched rough dielectric

@pytest.mark.parametrize("distribution", ["beckmann", "ggx"])
@pytest.mark.parametrize("n,exterior", [(1.0, 1.0), (1.33, 1.33), (2.4, 2.4)])
def test_index_matched_rough_dielectric_is_invisible(tmp_path, distribution, n, exterior):
    """No interface: light passes straight through at any roughness (the smooth dielectric's answer,
    1.0 of a uniform sky), where the microfacet BTDF degenerated to black."""
    material = {"type": "rough_dielectric", "n": n, "alpha": 0.3, "distribution": distribution,
                "exterior_n": exterior}
    built = parse_material(material, "materials.m")
    assert isinstance(built, SmoothDielectric) and not isinstance(built, RoughDielectric)
    doc = quad_scene(material, spp=4)
    doc["objects"] = [{"shape": "sphere", "center": [0, 0, 0], "radius": 0.8, "material": "m"}]
    stokes, dropped = render(doc, tmp_path)
    assert dropped == 0
    h, w = stokes.shape[1:3]
    centre = stokes[0, h // 2 - 1:h // 2 + 1, w // 2 - 1:w // 2 + 1]
    np.testing.assert_allclose(centre, 1.0, rtol=2e-3)
    assert np.abs(stokes[1:]).max() < 1e-9


@pytest.mark.parametrize("n", [1.0 + 1e-9, 1.0 + 1e-6, 1.0 - 1e-6, 1.001])
def test_nearly_index_matched_rough_dielectric_stays_finite_and_nearly_clear(tmp_path, n):
    doc = quad_scene({"type": "rough_dielectric", "n": n, "alpha": 0.3}, spp=16)
    doc["objects"] = [{"shape": "sphere", "center": [0, 0, 0], "radius": 0.8, "material": "m"}]
    stokes, dropped = render(doc, tmp_path)
    assert dropped == 0
    h, w = stokes.shape[1:3]
    np.testing.assert_allclose(stokes[0, h // 2, w // 2], 1.0, rtol=0.02)


# ----------------------------------------------------------------------------- float32 limits

@pytest.mark.parametrize("material,has_m", [
    ({"type": "torrance_sparrow", "metal": "Au", "m": {"texture": "t.exr"}}, True),
    ({"type": "weidlich_wilkie", "coats": [{"n": 1.5, "distribution": "beckmann", "m": {"texture": "t.exr"}}],
      "base": {"type": "lambert", "albedo": 0.5}}, False),
])
def test_roughness_texel_stored_as_float32_limit_counts_as_the_limit(tmp_path, material, has_m):
    """A texel meant as the least roughness 1e-4 is stored as float32 9.99999975e-05: accepted and
    clipped to the limit; a texel really below it (0.99e-4) is still refused with the range."""
    limit = 1e-4
    write_exr(tmp_path / "t.exr", np.array([[limit, 0.2], [0.3, 0.5]], np.float32))
    assert float(np.float32(limit)) < limit
    built = parse_material(material, "materials.m", base_dir=str(tmp_path))
    if has_m:
        assert built.m.lo == limit and built.m.clip[0] == limit
    stokes, dropped = render(quad_scene(material, lights=[SUN]), tmp_path)
    assert dropped == 0
    write_exr(tmp_path / "t.exr", np.array([[0.99e-4, 0.2], [0.3, 0.5]], np.float32))
    with pytest.raises(SceneError, match=r"materials\.m.*(1e-04|0\.0001)"):
        parse_material(material, "materials.m", base_dir=str(tmp_path))


@pytest.mark.parametrize("scale,ok", [(1.0, True), (1.0 + 1e-9, True), (1.0 + 2 ** -25, True), (1.001, False)])
def test_albedo_texel_a_float32_rounding_above_one_is_one(tmp_path, scale, ok):
    write_exr(tmp_path / "a.exr", np.array([[1.0, 0.5], [0.25, 1.0]], np.float32))
    material = {"type": "lambert", "albedo": {"texture": "a.exr", "scale": scale}}
    if not ok:
        with pytest.raises(SceneError, match=r"materials\.m\.albedo: texture values .*must be in \[0, 1\]"):
            parse_material(material, "materials.m", base_dir=str(tmp_path))
        return
    built = parse_material(material, "materials.m", base_dir=str(tmp_path))
    assert built.albedo.hi == 1.0


# ----------------------------------------------------------------------------- fuzzing the declared ranges

def _texturable():
    """(model, parameter name, Parameter) of every texturable number or spectrum, coats' included."""
    out = []
    for decl in MODELS.values():
        for p in decl.parameters:
            if p.kind in ("number", "spectrum") and p.texturable:
                out.append((decl.name, p.name, p))
    return out


TEXTURABLE = _texturable()
MINIMAL = {   # the least scene-file material each model builds from (the fuzzed parameter is added)
    "lambert": {}, "conductor": {"n": 0.5, "k": 2.0}, "dielectric": {"n": 1.5}, "black_glass": {"n": 1.5},
    "torrance_sparrow": {"n": 1.5, "k": 0.0, "m": 0.2}, "htsg": {"metal": "Al", "sigma0_um": 0.18, "tau_um": 3.0},
    "weidlich_wilkie": {"coats": [{"n": 1.5}], "base": {"type": "lambert", "albedo": 0.5}},
    "polariser": {}, "retarder": {}, "rough_dielectric": {"n": 1.5, "alpha": 0.2}, "thin_dielectric": {"n": 1.5},
    "oren_nayar": {"roughness": 0.5}, "principled": {}, "sheen": {}, "thin_film": {"n": 1.5}, "refraction": {"n": 1.5},
}


def _edge_values(p):
    """Values at and beyond the declared range: the limits, one float32 and one float64 step beyond,
    far beyond, and the non-finite ones."""
    values = [0.0, 0.5, 1.0, 2.0, 1e-4, 1e-30, 1e30, -1.0, -1e-30, math.inf, -math.inf, math.nan]
    for limit in (p.lo, p.hi):
        if math.isfinite(limit):
            values += [limit, float(np.nextafter(np.float32(limit), np.float32(-np.inf))),
                       float(np.nextafter(np.float32(limit), np.float32(np.inf))),
                       math.nextafter(limit, -math.inf), math.nextafter(limit, math.inf), limit * 2 + 1]
    return values


@pytest.mark.fuzz
@settings(max_examples=120, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.sampled_from(TEXTURABLE), st.data())
def test_texture_values_at_and_beyond_every_declared_range(tmp_path, target, data):
    """A uniform texture (float32 texels, possibly scaled/offset) holding a value at or beyond the
    parameter's range: refused with one SceneError naming the parameter, or built and rendered with no
    dropped sample."""
    model, name, p = target
    value = data.draw(st.sampled_from(_edge_values(p)), label="value")
    scale = data.draw(st.sampled_from([1.0, 1.0, -1.0, 1e-3, 1e3]), label="scale")
    with np.errstate(over="ignore", invalid="ignore"):
        texel = np.float32(value / scale) if math.isfinite(value) else np.float32(value)
    material = dict(MINIMAL[model], type=model)
    material[name] = {"texture": "v.exr", "scale": scale}
    try:
        write_exr(tmp_path / "v.exr", np.full((2, 2), texel, np.float32))
    except Exception:          # noqa: BLE001 — the image writer's refusal is not under test here
        return
    try:
        parse_material(material, "materials.m", base_dir=str(tmp_path))
    except SceneError as e:
        assert str(e).startswith("materials.m") and "\n" not in str(e), str(e)
        return
    stokes, dropped = render(quad_scene(material, spp=1, size=4, lights=[SUN]), tmp_path)
    assert dropped == 0


# ----------------------------------------------------------------------------- Cycles' specular-normal correction

def test_valid_specular_normal_lifts_the_mirror_direction_just_to_the_threshold():
    """engine.materials.normal_map.valid_specular_normal, against its defining property (not its formula):
    where the view's mirror direction about n lies below t = min(0.9·ω_o·n_g, 0.01), the corrected normal is
    a unit vector in the plane of n and n_g, turned towards n_g, whose mirror direction is exactly at t;
    elsewhere n is kept."""
    from engine.materials.normal_map import valid_specular_normal
    rng = np.random.default_rng(1)
    N = 20000
    n = rng.normal(size=(3, N))
    n /= np.linalg.norm(n, axis=0)
    n[2] = np.abs(n[2])
    wo = rng.normal(size=(3, N))
    wo /= np.linalg.norm(wo, axis=0)
    wo[2] = np.abs(wo[2])
    ng = np.zeros((3, N))
    ng[2] = 1.0
    m = valid_specular_normal(n, ng, wo)
    t = np.minimum(0.9 * wo[2], 0.01)
    before = 2.0 * (n * wo).sum(0) * n[2] - wo[2]
    after = 2.0 * (m * wo).sum(0) * m[2] - wo[2]
    fix = before < t
    assert 0.3 < fix.mean() < 0.9
    np.testing.assert_array_equal(m[:, ~fix], n[:, ~fix])
    np.testing.assert_allclose(after[fix], t[fix], atol=1e-10)
    np.testing.assert_allclose(np.linalg.norm(m, axis=0), 1.0, atol=1e-14)
    np.testing.assert_allclose(np.einsum("in,in->n", np.cross(n.T, ng.T).T, m)[fix], 0.0, atol=1e-12)
    assert np.all(m[2][fix] >= n[2][fix] - 1e-12)
    assert np.all(np.isfinite(valid_specular_normal(ng, ng, ng)))          # normal incidence, n = n_g
