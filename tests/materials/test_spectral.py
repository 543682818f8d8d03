"""Tests for engine.spectral: CIE tables, wavelength sampling, RGB development, spectra, IOR."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hst

import engine.spectral as sp
from engine.errors import SceneError
from engine.spectral import cie
from tests.support import chi2

DATA = os.path.join(os.path.dirname(cie.__file__), "data")
SHARED_IOR = "/work/shared/data/ior"
GRID = np.arange(360.0, 831.0)  # 1 nm Riemann grid


def develop_1nm(radiance_on_grid):
    """Linear sRGB of a spectral radiance sampled on GRID (1 nm rectangle rule)."""
    xyz = (sp.cmf_xyz(GRID) * radiance_on_grid).sum(axis=-1)
    return sp.XYZ_TO_LINEAR_SRGB @ xyz


def develop_reflectance(refl_on_grid):
    """XYZ = Σ cmf · d65n · s, RGB = M · XYZ (1 nm)."""
    return develop_1nm(sp.d65_normalised(GRID) * refl_on_grid)


# --- tables ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "name, columns",
    [
        ("cie1931_2deg.csv", "wavelength_nm,xbar,ybar,zbar"),
        ("d65.csv", "wavelength_nm,value"),
        ("mallett_yuksel_2019_srgb.csv", "wavelength_nm,r,g,b"),
    ],
)
def test_tables_have_provenance_and_1nm_grid(name, columns):
    with open(os.path.join(DATA, name)) as f:
        lines = f.read().splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    assert any("colour" in ln for ln in comments)
    assert any("generate_tables.py" in ln for ln in comments)
    body = [ln for ln in lines if not ln.startswith("#")]
    assert body[0] == columns
    wl = np.array([float(ln.split(",")[0]) for ln in body[1:]])
    np.testing.assert_array_equal(wl, GRID)


def test_cmf_reference_values_and_range():
    # CIE 1931 2° at 555 nm: x̄ = 0.5121, ȳ = 1.0000, z̄ = 0.005749 (CIE 15 table)
    np.testing.assert_allclose(sp.cmf_xyz(555.0), [0.5121, 1.0, 0.005749], atol=2e-4)
    assert sp.cmf_xyz(np.array([[300.0, 359.9], [830.1, 900.0]])).shape == (3, 2, 2)
    assert np.all(sp.cmf_xyz(np.array([300.0, 359.9, 830.1, 900.0])) == 0.0)
    mid = sp.cmf_xyz(555.5)
    np.testing.assert_allclose(mid, 0.5 * (sp.cmf_xyz(555.0) + sp.cmf_xyz(556.0)), rtol=1e-12)


def test_d65_normalised():
    assert abs(np.sum(sp.d65_normalised(GRID) * sp.cmf_xyz(GRID)[1]) - 1.0) < 1e-12
    # CIE D65: 100.000 at 560 nm, 109.354 at 500 nm, 60.3125 at 830 nm (CIE 15 Table T.1)
    d = sp.d65_normalised(np.array([560.0, 500.0, 830.0]))
    np.testing.assert_allclose(d[1:] / d[0], [1.09354, 0.603125], rtol=1e-6)
    assert sp.d65_normalised(359.0) == 0.0 and sp.d65_normalised(831.0) == 0.0


def test_srgb_matrices():
    iec = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])
    np.testing.assert_allclose(sp.XYZ_TO_LINEAR_SRGB, iec, atol=5e-4)
    np.testing.assert_allclose(sp.XYZ_TO_LINEAR_SRGB @ sp.LINEAR_SRGB_TO_XYZ, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(sp.LINEAR_SRGB_TO_XYZ[1], sp.LUMINANCE_WEIGHTS, atol=1e-4)
    # white (1, 1, 1) maps to the D65 white point x, y = 0.3127, 0.3290 with Y = 1
    w = sp.LINEAR_SRGB_TO_XYZ @ np.ones(3)
    np.testing.assert_allclose([w[0] / w.sum(), w[1] / w.sum(), w[1]], [0.3127, 0.3290, 1.0], atol=1e-12)


# --- white -----------------------------------------------------------------------------------


def test_white_deterministic_integral():
    np.testing.assert_allclose(develop_1nm(sp.d65_normalised(GRID)), [1, 1, 1], atol=1e-3)


def _estimate_white(u):
    lam, pdf = sp.sample_wavelengths(u)
    per_path = (sp.rgb_weights(lam, pdf) * sp.d65_normalised(lam)[None]).sum(axis=1)  # (3, N)
    return per_path.mean(axis=1), per_path.std(axis=1) / math.sqrt(u.size)


def test_white_monte_carlo_converges():
    n = 2_000_000
    rng = np.random.default_rng(2024)
    # 2e6 jittered (stratified, randomly permuted) u, as a path sampler would provide
    u = rng.permutation((np.arange(n) + rng.random(n)) / n)
    means = np.mean([_estimate_white(c)[0] for c in np.split(u, 8)], axis=0)
    np.testing.assert_allclose(means, [1, 1, 1], atol=1e-3)


def test_white_monte_carlo_iid_is_unbiased():
    rng = np.random.default_rng(7)
    means, errs = zip(*(_estimate_white(rng.random(250_000)) for _ in range(8)))
    mean = np.mean(means, axis=0)
    err = np.sqrt(np.mean(np.square(errs), axis=0) / 8)
    exact = develop_1nm(sp.d65_normalised(GRID))
    assert np.all(np.abs(mean - exact) < 5 * err), (mean, exact, err)
    np.testing.assert_allclose(mean, [1, 1, 1], atol=2e-3)


# --- wavelength sampling ---------------------------------------------------------------------


def test_pdf_integrates_to_one_and_matches_mitsuba():
    lam = np.linspace(360.0, 830.0, 470_001)
    pdf = sp.wavelength_pdf(lam)
    integral = np.sum(0.5 * (pdf[1:] + pdf[:-1]) * np.diff(lam))
    assert abs(integral - 1.0) < 1e-9
    # Mitsuba 3 pdf_rgb_spectrum: 0.003939804229326285 * sech²(0.0072 (λ − 538))
    np.testing.assert_allclose(pdf, 0.003939804229326285 / np.cosh(0.0072 * (lam - 538.0)) ** 2, rtol=1e-9)
    assert np.all(sp.wavelength_pdf(np.array([359.99, 830.01, 200.0])) == 0.0)


def test_sample_histogram_follows_pdf_chi_square():
    n = 1_000_000
    lam, pdf = sp.sample_wavelengths(np.random.default_rng(11).random(n), count=1)
    assert lam.shape == pdf.shape == (1, n)
    assert lam.min() >= 360.0 and lam.max() <= 830.0
    np.testing.assert_allclose(pdf, sp.wavelength_pdf(lam), rtol=1e-12)
    edges = np.linspace(360.0, 830.0, 95)  # 94 bins of 5 nm
    result = chi2.interval_sampler_test(lam[0], sp.wavelength_pdf, edges)
    chi2.assert_accepted(result, what="sampled wavelengths")
    # and a deliberately wrong pdf (uniform) must be rejected by the same test
    wrong = chi2.interval_sampler_test(lam[0], lambda x: np.full(x.shape, 1 / 470.0), edges)
    assert wrong.rejected(), wrong


def test_sample_wavelengths_stratified_inverse_cdf():
    lam, pdf = sp.sample_wavelengths(np.array([0.1, 0.9]), count=4)
    assert lam.shape == pdf.shape == (4, 2)
    # CDF by numerical integration of the pdf; the j-th wavelength must have CDF frac(u + j/4)
    fine = np.linspace(360.0, 830.0, 470_001)
    pf = sp.wavelength_pdf(fine)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (pf[1:] + pf[:-1]) * np.diff(fine))])
    got = np.interp(lam, fine, cdf)
    want = np.mod(np.array([0.1, 0.9])[None, :] + np.arange(4)[:, None] / 4, 1.0)
    np.testing.assert_allclose(got, want, atol=1e-7)


def test_rgb_weights_shape_and_formula():
    lam, pdf = sp.sample_wavelengths(np.array([0.3, 0.7, 0.2]), count=4)
    w = sp.rgb_weights(lam, pdf)
    assert w.shape == (3, 4, 3)
    ref = np.einsum("ij,jkn->ikn", sp.XYZ_TO_LINEAR_SRGB, sp.cmf_xyz(lam)) / pdf / 4
    np.testing.assert_allclose(w, ref, rtol=1e-12)
    z = sp.rgb_weights(np.array([[500.0], [900.0]]), np.array([[0.003], [0.0]]))
    assert np.all(np.isfinite(z)) and np.all(z[:, 1] == 0.0)


# --- spectra ---------------------------------------------------------------------------------


def test_basis_sums_to_one_and_unit_white_reflectance_is_exactly_one():
    lam = np.linspace(340.0, 850.0, 1001)
    b = sp.basis_rgb(lam)
    np.testing.assert_allclose(b.sum(axis=0), 1.0, atol=1e-14)
    assert b.min() > 0.0 and b.max() < 1.0
    s = sp.RGBReflectanceSpectrum((1.0, 1.0, 1.0))
    assert s.is_constant and s.is_grey
    assert np.all(s.eval(lam) == 1.0)
    assert np.all(sp.RGBReflectanceSpectrum([0.25] * 3).eval(lam) == 0.25)


@pytest.mark.parametrize(
    "rgb",
    [(1, 0, 0), (0, 1, 0), (0, 0, 1), (0.2, 0.5, 0.8), (0.9, 0.1, 0.3), (0.18, 0.18, 0.18), (1, 1, 1), (0, 0, 0)],
)
def test_reflectance_round_trip_under_d65(rgb):
    s = sp.RGBReflectanceSpectrum(rgb)
    np.testing.assert_allclose(develop_reflectance(s.eval(GRID)), rgb, atol=1e-3)


@settings(max_examples=50, deadline=None)
@given(hst.tuples(*[hst.floats(0.0, 1.0)] * 3))
def test_reflectance_is_bounded_and_round_trips(rgb):
    v = sp.RGBReflectanceSpectrum(rgb).eval(GRID)
    assert v.min() >= -1e-12 and v.max() <= 1.0 + 1e-12
    np.testing.assert_allclose(develop_reflectance(v), rgb, atol=1e-3)


def test_reflectance_mono_and_shapes():
    s = sp.RGBReflectanceSpectrum((0.2, 0.5, 0.8))
    assert not s.is_constant and not s.is_grey
    lam = np.full((2, 5), 550.0)
    for mono in (False, True):
        out = s.eval(lam, mono=mono)
        assert out.shape == (2, 5) and out.dtype == np.float64
    assert np.all(s.eval(lam, mono=True) == pytest.approx(0.2126 * 0.2 + 0.7152 * 0.5 + 0.0722 * 0.8))
    assert s.eval(550.0).shape == ()


def test_illuminant_white_and_colour_develop():
    white = sp.RGBIlluminantSpectrum((1, 1, 1))
    assert white.is_white and white.is_grey and not white.is_constant
    np.testing.assert_allclose(white.eval(GRID), sp.d65_normalised(GRID), rtol=1e-15)
    np.testing.assert_allclose(develop_1nm(white.eval(GRID)), [1, 1, 1], atol=1e-3)
    coloured = sp.RGBIlluminantSpectrum((2.0, 0.5, 0.1), scale=3.0)
    assert not coloured.is_white
    np.testing.assert_allclose(develop_1nm(coloured.eval(GRID)), [6.0, 1.5, 0.3], rtol=1e-3, atol=1e-3)
    assert coloured.eval(np.zeros(4), mono=True) == pytest.approx(3.0 * (0.2126 * 2 + 0.7152 * 0.5 + 0.0722 * 0.1))
    assert sp.RGBIlluminantSpectrum((0, 0, 0)).is_constant


def test_constant_spectrum():
    c = sp.ConstantSpectrum(0.7)
    assert c.is_constant and c.is_grey
    lam = np.array([[400.0, 500.0, 600.0]])
    assert np.all(c.eval(lam) == 0.7) and c.eval(lam).shape == (1, 3)
    assert np.all(c.eval(lam, mono=True) == 0.7)


def test_tabulated_interpolates_and_rejects_out_of_range():
    t = sp.TabulatedSpectrum([400.0, 500.0, 700.0], [0.1, 0.3, 0.5], name="materials.x.eta")
    np.testing.assert_allclose(t.eval(np.array([400.0, 450.0, 600.0, 700.0])), [0.1, 0.2, 0.4, 0.5])
    with pytest.raises(SceneError) as e:
        t.eval(np.array([450.0, 380.0]))
    assert e.value.field == "materials.x.eta"
    assert "materials.x.eta" in str(e.value) and "400-700 nm" in str(e.value) and "380" in str(e.value)
    assert not t.is_constant
    assert sp.TabulatedSpectrum([300.0, 900.0], [2.0, 2.0]).is_constant
    # mono of a flat unbounded table is its value
    assert sp.TabulatedSpectrum([300.0, 900.0], [1.5, 1.5]).eval(np.ones(3), mono=True) == pytest.approx(1.5, rel=1e-3)


# --- named metals ----------------------------------------------------------------------------


def _read_shared(name):
    rows = []
    with open(os.path.join(SHARED_IOR, f"{name}.csv")) as f:
        for line in f:
            if line.startswith("#") or line.startswith("wavelength"):
                continue
            rows.append([float(x) for x in line.split(",")])
    return np.array(rows)


@pytest.mark.skipif(not os.path.isdir(SHARED_IOR), reason="shared data not available")
def test_au_at_550_matches_shared_csv_and_copies_are_verbatim():
    rows = _read_shared("Au")
    i = np.searchsorted(rows[:, 0], 550.0)
    (w0, n0, k0), (w1, n1, k1) = rows[i - 1], rows[i]
    t = (550.0 - w0) / (w1 - w0)
    n, k = sp.named_ior("Au")
    assert n.eval(550.0) == pytest.approx(n0 + t * (n1 - n0), rel=1e-12)
    assert k.eval(550.0) == pytest.approx(k0 + t * (k1 - k0), rel=1e-12)
    for name in sp.NAMED_METALS:
        with open(os.path.join(SHARED_IOR, f"{name}.csv"), "rb") as a, open(
            os.path.join(DATA, "ior", f"{name}.csv"), "rb"
        ) as b:
            assert a.read() == b.read(), name


@pytest.mark.parametrize("name", sp.NAMED_METALS)
def test_named_metals_cover_render_range(name):
    n, k = sp.named_ior(name)
    lam = np.array([sp.LAMBDA_MIN, 550.0, sp.LAMBDA_MAX])
    assert np.all(n.eval(lam) > 0) and np.all(k.eval(lam) > 0)
    assert sp.named_ior(name)[0] is n  # cached
    with pytest.raises(SceneError, match=rf"{name}\.n.*covers (29[89]|30[0-2])(\.\d+)?-88[56](\.\d+)? nm"):
        n.eval(np.array([250.0]))


def test_au_linear_srgb_matches_mitsuba_rgb_mode():
    # Mitsuba 3 ior_from_file("Au") pre-integrated to sRGB (peers/scenes/fresnel_sphere_au.json)
    n, k = sp.named_ior("Au")
    np.testing.assert_allclose(n.linear_srgb(), [0.143036, 0.375307, 1.442045], rtol=3e-3)
    np.testing.assert_allclose(k.linear_srgb(), [3.982997, 2.385556, 1.603359], rtol=3e-3)
    assert n.eval(550.0, mono=True) == pytest.approx(sp.luminance(n.linear_srgb()))


def test_unknown_metal_lists_allowed():
    with pytest.raises(SceneError) as e:
        sp.named_ior("Pt", field="materials.m.named")
    assert e.value.field == "materials.m.named"
    assert all(m in str(e.value) for m in sp.NAMED_METALS)


# --- user input ------------------------------------------------------------------------------


def test_parse_valid_inputs():
    assert isinstance(sp.parse_spectrum(0.5, "a"), sp.ConstantSpectrum)
    r = sp.parse_spectrum([0.1, 0.2, 0.3], "a")
    assert isinstance(r, sp.RGBReflectanceSpectrum) and r.rgb.tolist() == [0.1, 0.2, 0.3]
    assert isinstance(sp.parse_spectrum(5.0, "a", kind="unbounded"), sp.ConstantSpectrum)
    assert isinstance(sp.parse_spectrum([2, 3, 4], "a", kind="unbounded"), sp.RGBUnboundedSpectrum)
    light = sp.parse_spectrum(1, "light.radiance", kind="illuminant")
    assert isinstance(light, sp.RGBIlluminantSpectrum) and light.is_white
    np.testing.assert_allclose(develop_1nm(light.eval(GRID)), [1, 1, 1], atol=1e-3)
    assert isinstance(sp.parse_spectrum([4, 2, 1], "l", kind="illuminant"), sp.RGBIlluminantSpectrum)
    tab = sp.parse_spectrum({"spectrum": [[350, 0.2], [600, 0.4], [850, 0.6]]}, "m.albedo")
    assert isinstance(tab, sp.TabulatedSpectrum) and tab.eval(600.0) == pytest.approx(0.4)
    # an illuminant table of 1 everywhere has luminance 1 (Mitsuba's convention)
    flat = sp.parse_spectrum({"spectrum": [[360, 1.0], [830, 1.0]]}, "l", kind="illuminant")
    assert sp.LINEAR_SRGB_TO_XYZ[1] @ develop_1nm(flat.eval(GRID)) == pytest.approx(1.0, rel=1e-9)
    assert flat.eval(GRID, mono=True)[0] == pytest.approx(1.0, rel=2e-3)


@pytest.mark.parametrize(
    "value, kind, field_suffix, words",
    [
        ("abc", "reflectance", "", ["[0, 1]", "[r, g, b]", "'abc'"]),
        ("abc", "illuminant", "", ["≥ 0", "[r, g, b]", "'abc'"]),
        (float("nan"), "reflectance", "", ["nan"]),
        (float("inf"), "unbounded", "", ["≥ 0", "inf"]),
        (-0.1, "unbounded", "", ["≥ 0", "-0.1"]),
        (1.5, "reflectance", "", ["[0, 1]", "1.5"]),
        (True, "reflectance", "", ["True"]),
        (None, "illuminant", "", ["None"]),
        ([1, 2], "reflectance", "", ["[r, g, b]"]),
        ([0.5, "x", 0], "reflectance", "", ["'x'"]),
        ([0.5, 1.2, 0], "reflectance", "[1]", ["[0, 1]", "1.2"]),
        ([1, -2, 0], "illuminant", "[1]", ["≥ 0", "-2"]),
        ([1, float("nan"), 0], "unbounded", "[1]", ["≥ 0"]),
        ({"spectrum": [[400, 0.5], [700, 0.5]]}, "reflectance", ".spectrum", ["360-830 nm", "400-700"]),
        ({"spectrum": [[360, 0.5], [360, 0.6], [830, 0.5]]}, "reflectance", ".spectrum[1]", ["increasing"]),
        ({"spectrum": [[360, 0.5], [830, 1.5]]}, "reflectance", ".spectrum[1]", ["[0, 1]", "1.5"]),
        ({"spectrum": [[360, 0.5], [830]]}, "unbounded", ".spectrum[1]", ["[wavelength_nm, value]"]),
        ({"spectrum": [[360, 0.5]]}, "unbounded", ".spectrum", ["at least 2"]),
        ({"spectrum": [[360, 1]], "x": 1}, "unbounded", "", ['"spectrum"']),
    ],
)
def test_parse_errors_name_field_and_range(value, kind, field_suffix, words):
    field = "materials.paint.albedo"
    with pytest.raises(SceneError) as e:
        sp.parse_spectrum(value, field, kind=kind)
    assert e.value.field == field + field_suffix
    msg = str(e.value)
    assert msg.startswith(field)
    for w in words:
        assert w in msg, (w, msg)


def test_rgb_constructors_validate():
    with pytest.raises(SceneError):
        sp.RGBReflectanceSpectrum((0.5, 0.5, 1.01))
    with pytest.raises(SceneError):
        sp.RGBIlluminantSpectrum((1, 1, 1), scale=-1.0)
    assert sp.RGBIlluminantSpectrum((10.0, 20.0, 5.0)).mono_value == pytest.approx(
        0.2126 * 10 + 0.7152 * 20 + 0.0722 * 5
    )
