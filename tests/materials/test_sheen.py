"""Cycles' microfiber sheen (engine.materials.sheen): Cycles' formula and lookup, exact sampling (χ²),
albedo = ∫ f cosθ_i dω, pdf = f cosθ_i / E, finite at the ends of both table axes, a depolariser.

The fitted table's agreement with Cycles' renders is tests/bench/fit_sheen.py's (printed residuals) and
tests/blender/test_cycles_parity_sheen.py's business; here the model is checked against its own
definition."""

import math

import numpy as np
import pytest

from engine.materials.base import ShadingPoint
from engine.materials.flags import BSDFFlags
from engine.materials.sheen import CUTOFF, DECLARATION, NODES, Sheen, ltc_table
from engine.spectral import ConstantSpectrum
from tests.support import chi2


def points(mu, n, lam=None):
    """n shading points with n = +z and the viewer in the xz plane at cosθ_o = mu (x ≥ 0)."""
    z = np.tile([[0.0], [0.0], [1.0]], (1, n))
    wo = np.tile([[math.sqrt(max(1 - mu * mu, 0.0))], [0.0], [mu]], (1, n))
    lam = np.full((1, n), 550.0) if lam is None else lam
    return ShadingPoint(np.zeros((3, n)), z, z, wo, lam)


def table_at(mu, r):
    """(a, b, E) read as Cycles' lookup_table_read_2D does (written out here, scalar)."""
    def axis(v):
        s = min(max(v, 0.0), 1.0) * (NODES - 1)
        i = min(int(s), NODES - 1)
        return i, min(i + 1, NODES - 1), s - i
    i0, i1, t = axis(mu)
    j0, j1, u = axis(min(max(r, 1e-3), 1.0))
    tab = ltc_table()
    row0 = (1 - t) * tab[:, i0, j0] + t * tab[:, i1, j0]
    row1 = (1 - t) * tab[:, i0, j1] + t * tab[:, i1, j1]
    return (1 - u) * row0 + u * row1


def cycles_value(mu, r, wi):
    """E·D (BRDF × cosθ_i) as bsdf_sheen_eval computes it, wi (3, n) in the frame n = z, viewer at +x."""
    a, b, e = table_at(mu, r)
    if abs(a) < CUTOFF or e < CUTOFF:
        return np.zeros(wi.shape[1])
    x, y, z = wi
    len_sqr = (a * x + b * z) ** 2 + (a * y) ** 2 + z * z
    return e * np.maximum(z, 0.0) / math.pi * (a / len_sqr) ** 2


def upper_hemisphere(n_cos=300, n_phi=600, power=3):
    """(3, M) directions and solid-angle weights: Gauss–Legendre in u with cosθ = u^power (dense at the
    horizon, where low-roughness sheen peaks) × midpoint in φ."""
    x, w = np.polynomial.legendre.leggauss(n_cos)
    u, wu = 0.5 * (x + 1), 0.5 * w
    c, wc = u ** power, wu * power * u ** (power - 1)
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * math.pi
    C, P = np.meshgrid(c, phi, indexing="ij")
    W = np.broadcast_to(wc[:, None] * (2 * math.pi / n_phi), C.shape)
    s = np.sqrt(1 - C * C)
    return np.stack((s * np.cos(P), s * np.sin(P), C)).reshape(3, -1), W.ravel()


def random_upper(n, rng):
    w = rng.normal(size=(3, n))
    w[2] = np.abs(w[2])
    return w / np.linalg.norm(w, axis=0)


# --- the definition ------------------------------------------------------------------------------------------


def test_table_shape_and_nodes():
    tab = ltc_table()
    assert tab.shape == (3, NODES, NODES)
    assert np.all(np.isfinite(tab))
    assert np.all(tab[0] > 0)                       # a > 0: the sampler maps the hemisphere onto itself
    assert np.all((tab[2] >= 0) & (tab[2] < 1))     # E is an albedo
    m = Sheen(ConstantSpectrum(1.0), 10 / 31)
    for i in (0, 7, 31):                            # on a node the lookup is the node's value
        np.testing.assert_allclose(m.albedo(points(i / 31, 1)), tab[2, i, 10], rtol=1e-12)


@pytest.mark.parametrize("r", [0.0, 0.05, 0.23, 0.5, 0.81, 1.0])
@pytest.mark.parametrize("mu", [0.02, 0.3, 0.77, 1.0])
def test_eval_is_cycles_formula(mu, r):
    """f·cosθ_i = E·D in the frame whose x axis is the viewer's side of the tangent plane, with (a, b, E)
    interpolated bilinearly at (μ, clamp(r, 10⁻³, 1)); tint scales it per wavelength."""
    rng = np.random.default_rng(1)
    n = 400
    wi = random_upper(n, rng)
    lam = np.tile([[450.0], [550.0], [650.0]], (1, n))
    tint = ConstantSpectrum(0.7)
    value = Sheen(tint, r).eval(points(mu, n, lam), wi)
    assert value.kind == "depolarising"
    expected = 0.7 * cycles_value(mu, r, wi)
    for row in value.A:
        np.testing.assert_allclose(row * wi[2], expected, rtol=1e-10, atol=1e-300)


def test_frame_is_the_viewers_side():
    """b ≠ 0 makes the lobe asymmetric between the viewer's side (x > 0) and the far side; the model puts it
    where Cycles does (mirror images across the plane of n and wo agree, x ↔ −x do not)."""
    mu, r = 0.4, 0.3
    assert abs(table_at(mu, r)[1]) > 1e-3
    wi = np.array([[0.6], [0.0], [0.8]])
    mirror_y = wi * np.array([[1.0], [-1.0], [1.0]])
    far = wi * np.array([[-1.0], [1.0], [1.0]])
    m = Sheen(ConstantSpectrum(1.0), r)
    sp = points(mu, 1)
    f = m.eval(sp, wi).A[0, 0]
    assert f * 0.8 == pytest.approx(cycles_value(mu, r, wi)[0], rel=1e-12)
    assert m.eval(sp, mirror_y).A[0, 0] == pytest.approx(f, rel=1e-12)
    assert m.eval(sp, far).A[0, 0] == pytest.approx(cycles_value(mu, r, far)[0] / 0.8, rel=1e-12)
    assert m.eval(sp, far).A[0, 0] != pytest.approx(f, rel=1e-3)
    # the frame turns with the viewer: rotating wo and wi together about n leaves f unchanged
    c, s = math.cos(1.1), math.sin(1.1)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    turned = points(mu, 1)
    turned.wo = R @ turned.wo
    assert m.eval(turned, R @ wi).A[0, 0] == pytest.approx(f, rel=1e-12)


# --- energy, pdf, sampling ---------------------------------------------------------------------------------


@pytest.mark.parametrize("r", [0.06, 0.3, 0.6, 1.0])
@pytest.mark.parametrize("mu", [0.1, 0.5, 0.9, 1.0])
def test_eval_cos_integrates_to_albedo(mu, r):
    """∫ f cosθ_i dω over the hemisphere = E(μ, r) = ``albedo``, and the pdf integrates to 1 (where the
    closure exists)."""
    wi, dw = upper_hemisphere()
    m = Sheen(ConstantSpectrum(1.0), r)
    sp = points(mu, wi.shape[1])
    e = m.albedo(points(mu, 1))[0]
    assert e == pytest.approx(table_at(mu, r)[2], rel=1e-12)
    if e == 0.0:
        assert not np.any(m.eval(sp, wi).A) and not np.any(m.pdf(sp, wi))
        return
    assert float(np.sum(m.eval(sp, wi).A[0] * wi[2] * dw)) == pytest.approx(e, rel=2e-4)
    assert float(np.sum(m.pdf(sp, wi) * dw)) == pytest.approx(1.0, rel=2e-4)


@pytest.mark.parametrize("r", [0.0, 0.1, 0.5, 1.0])
@pytest.mark.parametrize("mu", [0.05, 0.6, 1.0])
def test_pdf_is_eval_cos_over_albedo_and_weight_is_albedo(mu, r):
    rng = np.random.default_rng(3)
    n = 2000
    sp = points(mu, n)
    m = Sheen(ConstantSpectrum(0.5), r)
    e = m.albedo(points(mu, 1))[0]
    wi = random_upper(n, rng)
    f = m.eval(sp, wi).A[0]
    if e > 0:
        np.testing.assert_allclose(m.pdf(sp, wi) * e * 0.5, f * wi[2], rtol=1e-12, atol=1e-300)
    s = m.sample(sp, rng.random(n), rng.random((2, n)))
    assert np.all(s.valid) == (e > 0) and not np.any(s.is_delta)
    if e > 0:
        np.testing.assert_allclose(s.weight.A[0], 0.5 * e, rtol=1e-12)             # f cosθ/pdf = E·tint
        np.testing.assert_allclose(s.pdf, m.pdf(sp, s.wi), rtol=1e-9)
        fs = m.eval(sp, s.wi).A[0]
        np.testing.assert_allclose(s.weight.A[0], fs * s.wi[2] / s.pdf, rtol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(s.wi, axis=0), 1.0, rtol=1e-12)


SAMPLING_CASES = [(0.1, 75.0), (0.3, 45.0), (0.5, 0.0), (0.7, 85.0), (1.0, 30.0)]


@pytest.mark.parametrize("r,theta", SAMPLING_CASES)
def test_sampling_chi2(r, theta):
    """sample() directions follow pdf() (Pearson's test over (cosθ, φ) cells of the hemisphere)."""
    m = Sheen(ConstantSpectrum(1.0), r)
    N = 100_000
    rng = np.random.default_rng(7)
    mu = math.cos(math.radians(theta))
    s = m.sample(points(mu, N), rng.random(N), rng.random((2, N)))
    assert np.all(s.valid)
    result = chi2.direction_sampler_test(s.wi, s.valid, lambda wi: m.pdf(points(mu, wi.shape[1]), wi),
                                         n_cos=40, n_phi=40, order=8, sub=2)
    chi2.assert_accepted(result, test_count=len(SAMPLING_CASES), what="sheen samples")


def test_samples_below_the_geometric_normal_are_rejected():
    """As Cycles: a direction below the geometric normal is not valid (zero weight and pdf)."""
    n = 4000
    rng = np.random.default_rng(4)
    sp = points(0.3, n)
    tilt = math.radians(20.0)
    sp.n_g = np.tile([[-math.sin(tilt)], [0.0], [math.cos(tilt)]], (1, n))
    s = Sheen(ConstantSpectrum(1.0), 0.4).sample(sp, rng.random(n), rng.random((2, n)))
    below = (s.wi * sp.n_g).sum(axis=0) <= 0
    assert below.any() and not np.any(s.valid[below])
    assert not np.any(s.weight.A[0][below]) and not np.any(s.pdf[below])
    assert np.all(s.valid[~below])


# --- limits, depolarisation, declaration -------------------------------------------------------------------


@pytest.mark.parametrize("r", [0.0, 1e-4, 0.5, 1.0])
@pytest.mark.parametrize("mu", [0.0, 1e-9, 1e-4, 0.5, 1.0 - 1e-12, 1.0])
def test_finite_at_the_ends(mu, r):
    rng = np.random.default_rng(5)
    n = 500
    sp = points(mu, n)
    m = Sheen(ConstantSpectrum(1.0), r)
    wi = random_upper(n, rng)
    wi[:, :3] = [[0.0, 1.0, -1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]     # the normal and the horizon
    for arr in (m.eval(sp, wi).A, m.pdf(sp, wi), m.albedo(sp)):
        assert np.all(np.isfinite(arr)) and np.all(arr >= 0)
    s = m.sample(sp, rng.random(n), rng.random((2, n)))
    for arr in (s.wi, s.weight.A, s.pdf):
        assert np.all(np.isfinite(arr))
    assert np.all(s.weight.A >= 0) and np.all(s.pdf >= 0)
    assert np.all(s.pdf[s.valid] > 0)
    if mu == 0.0:       # viewer on the horizon: nothing (as Polar's diffuse models), albedo as Cycles reads it
        assert not np.any(m.eval(sp, wi).A) and not np.any(s.valid)
        a, _, e = table_at(0.0, r)
        assert m.albedo(sp)[0] == pytest.approx(e if e >= CUTOFF and a >= CUTOFF else 0.0, rel=1e-12)


def test_viewer_behind_the_shading_normal_gives_nothing():
    rng = np.random.default_rng(6)
    n = 100
    sp = points(0.5, n)
    sp.wo = sp.wo * np.array([[1.0], [1.0], [-1.0]])
    m = Sheen(ConstantSpectrum(1.0), 0.5)
    wi = random_upper(n, rng)
    assert not np.any(m.eval(sp, wi).A) and not np.any(m.pdf(sp, wi))
    assert not np.any(m.sample(sp, rng.random(n), rng.random((2, n))).valid)


def test_depolarising():
    rng = np.random.default_rng(8)
    n = 50
    m = Sheen(ConstantSpectrum(0.9), 0.4)
    sp = points(0.6, n)
    v = m.eval(sp, random_upper(n, rng))
    M = v.matrix()
    assert M.shape == (4, 4, 1, n)
    np.testing.assert_array_equal(M[0, 0], v.A)
    M[0, 0] = 0.0
    assert not np.any(M)                            # f·diag(1, 0, 0, 0)
    assert not m.polarising and not m.creates_circular and not m.transmits
    assert m.flags.has(BSDFFlags.DIFFUSE_REFLECTION) and not m.flags.has(BSDFFlags.GLOSSY)
    assert not m.flags.wavelength_dependent          # a grey tint
    s = m.sample(sp, rng.random(n), rng.random((2, n)))
    assert s.weight.kind == "depolarising"


def test_declaration_builds_the_model_and_checks_roughness():
    decl = DECLARATION
    m = decl.build(decl.values({"tint": "0.5", "roughness": "0.25"}, "param", text=True))
    assert isinstance(m, Sheen) and m.roughness == 0.25
    assert m.describe()["type"] == "sheen"
    default = decl.build(decl.values({}, "param", text=True))
    assert default.roughness == 0.5
    with pytest.raises(Exception, match="roughness"):
        decl.build(decl.values({"roughness": "1.5"}, "param", text=True))
    with pytest.raises(ValueError):
        Sheen(ConstantSpectrum(1.0), -0.1)


def test_textured_roughness_is_the_constant_model_per_texel(tmp_path):
    """Sheen Roughness per point (a texture): at each texel the constant-roughness model, to rounding (the bilinear
    table read is the same two interpolations in another order)."""
    from engine.scene.loader import parse_material
    from tests.scene.test_textures import _points_at, _shading_points, _texture_file
    r_values = np.array([[0.05, 0.3], [0.62, 1.0]])
    name = _texture_file(tmp_path, r_values)
    mat = parse_material({"type": "sheen", "tint": [0.9, 0.6, 0.3],
                          "roughness": {"texture": name, "interpolation": "Closest"}}, "materials.s",
                         base_dir=str(tmp_path))
    assert mat.varies_over_surface
    jj, ii = np.meshgrid(np.arange(2), np.arange(2), indexing="ij")
    uv = np.repeat(np.stack((((ii + 0.5) / 2).ravel(), ((jj + 0.5) / 2).ravel())), 50, axis=1)
    texel = np.repeat(r_values[::-1].astype(np.float32).astype(np.float64)[jj, ii].ravel(), 50)
    rng = np.random.default_rng(11)
    sp = _shading_points(uv.shape[1], rng, _points_at(uv))
    wi = random_upper(uv.shape[1], rng)
    u_lobe, u_dir = rng.uniform(size=uv.shape[1]), rng.uniform(size=(2, uv.shape[1]))
    f, pdf, s = mat.eval(sp, wi).matrix(), mat.pdf(sp, wi), mat.sample(sp, u_lobe, u_dir)
    albedo = mat.albedo(sp)
    for r in np.unique(texel):
        sel = np.nonzero(texel == r)[0]
        const = Sheen(mat.tint, float(r))
        sub = sp.take(sel)
        sub.surface = None
        np.testing.assert_allclose(f[..., sel], const.eval(sub, wi[:, sel]).matrix(), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(pdf[sel], const.pdf(sub, wi[:, sel]), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(albedo[sel], const.albedo(sub), rtol=1e-12, atol=1e-15)
        cs = const.sample(sub, u_lobe[sel], u_dir[:, sel])
        np.testing.assert_allclose(s.wi[:, sel], cs.wi, rtol=1e-12, atol=1e-14)
    with pytest.raises(Exception, match="roughness"):
        parse_material({"type": "sheen", "roughness": {"texture": name, "scale": 2.0}}, "materials.s",
                       base_dir=str(tmp_path))
