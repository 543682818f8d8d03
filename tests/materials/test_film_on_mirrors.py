"""Thin films on the smooth mirrors (Cycles' Thin Film on every Fresnel): the ``conductor`` model and the smooth
limit (m = 0) of Torrance–Sparrow, against an independent oracle — the characteristic (transfer) matrix of one
layer on a complex substrate, per polarisation (Born & Wolf §1.6, Macleod's tilted admittances)."""

import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.materials.base import BSDFFlags, ShadingPoint
from engine.materials.conductor import SmoothConductor
from engine.materials.smooth_limit import MirrorWithDiffuse
from engine.materials.thin_film import ThinFilmDielectric
from engine.materials.torrance_sparrow import FilmedMirrorWithDiffuse, TorranceSparrow
from engine.polarisation.mueller import is_realisable
from engine.spectral.film_channels import film_layering_albedo
from engine.scene.loader import parse_material
from engine.spectral import ConstantSpectrum

LAMBDAS = (420.0, 550.0, 680.0)
THETAS = (0.0, 25.0, 50.0, 70.0, 85.0)


def transfer_matrix_reflectances(cos1, n1, nf, d, n3, lam):
    """(R_s, R_p) of a film (real nf, thickness d) on a substrate n3 (complex: n + iκ, κ ≥ 0) seen from a medium n1,
    by the 2 × 2 characteristic matrix with the tilted admittances Y_s = n cosθ = u, Y_p = n / cosθ = n²/u,
    u = √(n² − n1² sin²θ) on the branch Im u ≥ 0 (the absorbing substrate's damped wave)."""
    s2 = (n1 * n1) * (1.0 - cos1 * cos1)
    uf = np.sqrt(nf * nf - s2 + 0j)
    u3 = np.sqrt(complex(n3) ** 2 - s2)
    if u3.imag < 0:
        u3 = -u3
    delta = 2.0 * math.pi * d * uf / lam
    out = []
    for y1, yf, y3 in ((n1 * cos1, uf, u3), (n1 / cos1, nf * nf / uf, complex(n3) ** 2 / u3)):
        m11, m12 = np.cos(delta), -1j * np.sin(delta) / yf
        m21, m22 = -1j * yf * np.sin(delta), np.cos(delta)
        r = (y1 * m11 + y1 * y3 * m12 - m21 - y3 * m22) / (y1 * m11 + y1 * y3 * m12 + m21 + y3 * m22)
        out.append(abs(r) ** 2)
    return tuple(out)


def points(thetas=THETAS, lambdas=LAMBDAS, phi=0.7):
    """A ShadingPoint with one view direction per θ (normal +z), every path carrying ``lambdas``."""
    t = np.radians(np.asarray(thetas, np.float64))
    n = t.size
    wo = np.stack((np.sin(t) * math.cos(phi), np.sin(t) * math.sin(phi), np.cos(t)))
    z = np.tile([[0.0], [0.0], [1.0]], (1, n))
    lam = np.tile(np.asarray(lambdas, np.float64)[:, None], (1, n))
    return ShadingPoint(np.zeros((3, n)), z, z, wo, lam)


def conductor(n, k, ext=1.0, **film):
    return SmoothConductor(ConstantSpectrum(n), ConstantSpectrum(k), ext, **film)


def oracle_ab(thetas, lambdas, n1, nf, d, n3_of_lambda):
    """(A, B) (L, N) = ((R_s + R_p)/2, (R_s − R_p)/2) from the oracle."""
    A, B = np.empty((len(lambdas), len(thetas))), np.empty((len(lambdas), len(thetas)))
    for i, lam in enumerate(lambdas):
        for j, th in enumerate(thetas):
            R_s, R_p = transfer_matrix_reflectances(math.cos(math.radians(th)), n1, nf, d, n3_of_lambda(lam), lam)
            A[i, j], B[i, j] = 0.5 * (R_s + R_p), 0.5 * (R_s - R_p)
    return A, B


# ----------------------------------------------------------------------------- (a) the oracle

@pytest.mark.parametrize("n,k", [(0.2, 3.0), (1.2, 7.0), (2.5, 0.3), (1.5, 0.0)])
@pytest.mark.parametrize("nf,d", [(1.4, 300.0), (2.0, 120.0), (1.33, 1500.0)])
@pytest.mark.parametrize("ext", [1.0, 1.33])
def test_filmed_smooth_conductor_is_the_characteristic_matrix_reflectance(n, k, nf, d, ext):
    sp = points()
    model = conductor(n, k, ext, film_n=nf, film_thickness=d)
    got = model.delta_reflection(sp)
    A, B = oracle_ab(THETAS, LAMBDAS, ext, nf, d, lambda lam: complex(n, k))
    np.testing.assert_allclose(got.A, A, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(got.B, B, rtol=1e-10, atol=1e-13)
    # the sample is the same Dirac lobe, weight 1 (no fused step: the film's reflectance depends on λ)
    bs = model.sample(sp, np.full(sp.n, 0.5), np.full((2, sp.n), 0.5))
    assert bs.is_delta.all() and bs.valid.all()
    np.testing.assert_array_equal(bs.weight.A, got.A)
    assert model.scatter_delta(None) is False


def test_filmed_measured_metal_is_the_characteristic_matrix_reflectance_of_its_tables():
    model = parse_material({"type": "conductor", "metal": "Au", "thin_film_thickness": 250.0,
                            "thin_film_ior": 1.5}, "m")
    assert model.film == (1.5, 250.0)
    lambdas = (430.0, 512.0, 633.0, 700.0)
    sp = points(lambdas=lambdas)
    A, B = oracle_ab(THETAS, lambdas, 1.0, 1.5, 250.0,
                     lambda lam: complex(model.n.eval(np.array([lam]))[0], model.k.eval(np.array([lam]))[0]))
    value = model.delta_reflection(sp)
    np.testing.assert_allclose(value.A, A, rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(value.B, B, rtol=1e-9, atol=1e-13)


# ----------------------------------------------------------------------------- (b) no film

@pytest.mark.parametrize("thickness", [0.0, 0.05, 0.1])
@pytest.mark.parametrize("n,k", [(0.2, 3.0), (1.5, 0.0)])
def test_a_film_at_most_the_cutoff_is_the_bare_conductor_bit_for_bit(thickness, n, k):
    sp = points(thetas=np.linspace(0.0, 90.0, 13))
    bare, thin = conductor(n, k), conductor(n, k, film_n=1.4, film_thickness=thickness)
    assert thin.film is None and thin.flags == bare.flags and thin.describe() == bare.describe()
    a, b = bare.delta_reflection(sp), thin.delta_reflection(sp)
    for name in ("A", "B", "C", "S", "x_in", "x_out"):
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
    # and by the scene format
    d = {"type": "conductor", "n": n, "k": k, "thin_film_ior": 1.4, "thin_film_thickness": thickness}
    parsed = parse_material(d, "m")
    assert parsed.film is None
    np.testing.assert_array_equal(parsed.delta_reflection(sp).A, a.A)


@pytest.mark.parametrize("thickness", [0.0, 0.1])
def test_a_film_at_most_the_cutoff_is_the_bare_smooth_limit_bit_for_bit(thickness):
    sp = points(thetas=np.linspace(0.0, 89.0, 9))
    kw = dict(diffuse_albedo=0.6, diffuse_weight=1.0, specular_weight=0.8, diffuse_layering="albedo_scaling")
    bare = MirrorWithDiffuse(1.5, 0.0, **kw)
    thin = FilmedMirrorWithDiffuse(1.5, 0.0, film_n=1.33, film_thickness=thickness, **kw)
    assert thin.film is None and thin.flags == bare.flags
    u_lobe, u_dir = np.linspace(0.01, 0.99, sp.n), np.full((2, sp.n), 0.3)
    wi = np.tile([[0.3], [0.1], [0.9]], (1, sp.n))
    wi /= np.linalg.norm(wi, axis=0)
    for a, b in ((bare.delta_reflection(sp), thin.delta_reflection(sp)), (bare.eval(sp, wi), thin.eval(sp, wi)),
                 (bare.sample(sp, u_lobe, u_dir).weight, thin.sample(sp, u_lobe, u_dir).weight)):
        np.testing.assert_array_equal(a.matrix(), b.matrix())
    np.testing.assert_array_equal(bare.pdf(sp, wi), thin.pdf(sp, wi))
    built = parse_material({"type": "torrance_sparrow", "n": 1.5, "m": 0, "thin_film_thickness": thickness}, "m")
    assert type(built) is MirrorWithDiffuse


# ----------------------------------------------------------------------------- (c) polarisation

def test_filmed_mirrors_are_realisable_and_make_circular_polarisation_from_linear():
    """Light linearly polarised at 45° off a filmed mirror at 60° comes back elliptical (S3 ≠ 0): on a real
    substrate (κ = 0, n > exterior: a bare one retards nothing) only the film's s–p phase difference does it."""
    sp = points(thetas=np.linspace(0.0, 90.0, 31), lambdas=(400.0, 470.0, 550.0, 620.0, 700.0))
    for n, k in ((1.5, 0.0), (0.2, 3.0), (1.2, 7.0)):
        model = conductor(n, k, film_n=1.38, film_thickness=420.0)
        assert BSDFFlags.RETARDING in model.flags and BSDFFlags.WAVELENGTH_DEPENDENT in model.flags
        M = model.delta_reflection(sp).matrix()
        assert is_realisable(M.reshape(4, 4, -1)).all()
    bare = conductor(1.5, 0.0)
    assert BSDFFlags.RETARDING not in bare.flags and BSDFFlags.WAVELENGTH_DEPENDENT not in bare.flags
    oblique = points(thetas=(60.0,), lambdas=(450.0, 550.0, 650.0))
    linear45 = np.array([1.0, 0.0, 1.0, 0.0])
    s3_bare = np.einsum("ij...,j->i...", bare.delta_reflection(oblique).matrix(), linear45)[3]
    np.testing.assert_array_equal(s3_bare, 0.0)
    out = np.einsum("ij...,j->i...", conductor(1.5, 0.0, film_n=2.3, film_thickness=420.0)
                    .delta_reflection(oblique).matrix(), linear45)      # a TiO₂-like film on glass
    assert np.max(np.abs(out[3]) / out[0]) > 0.25
    # on a metal the film changes the metal's own retardance
    metal = [np.einsum("ij...,j->i...", m.delta_reflection(oblique).matrix(), linear45)[3]
             for m in (conductor(0.2, 3.0), conductor(0.2, 3.0, film_n=1.38, film_thickness=420.0))]
    assert np.max(np.abs(metal[0] - metal[1])) > 0.05


# ----------------------------------------------------------------------------- (d) the smooth TS layer

def test_smooth_filmed_dielectric_layer_mirror_and_diffuse_base():
    """The m = 0 Torrance–Sparrow under a film: the mirror is the film's reflectance on the real substrate (the
    oracle; its full matrix is the thin_film model's reflection), the Lambertian base is weighted by
    max(0, 1 − s·E) with E the film's layering albedo (film_layering_albedo, as the rough filmed lobe)."""
    n, nf, d, s, rho = 1.5, 1.33, 400.0, 0.7, 0.8
    model = parse_material({"type": "torrance_sparrow", "n": n, "m": 0, "specular_weight": s, "diffuse_albedo": rho,
                            "diffuse_layering": "albedo_scaling", "thin_film_thickness": d, "thin_film_ior": nf}, "m")
    assert isinstance(model, FilmedMirrorWithDiffuse) and model.film == (nf, d)
    assert BSDFFlags.RETARDING in model.flags and BSDFFlags.DELTA_REFLECTION in model.flags
    sp = points()
    mirror = model.delta_reflection(sp)
    A, B = oracle_ab(THETAS, LAMBDAS, 1.0, nf, d, lambda lam: n)
    np.testing.assert_allclose(mirror.A, s * A, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(mirror.B, s * B, rtol=1e-10, atol=1e-13)
    coated = ThinFilmDielectric(n, nf, d).delta_reflection(sp)
    for name in "ABCS":
        np.testing.assert_allclose(getattr(mirror, name), s * getattr(coated, name), rtol=1e-12, atol=1e-15)
    # the diffuse base
    wi = np.tile([[-0.2], [0.4], [0.8]], (1, sp.n))
    wi /= np.linalg.norm(wi, axis=0)
    E = film_layering_albedo(sp.cos_o, 1.0, (nf, d), n)        # the channels' band averages (spectral transport)
    want = rho * np.maximum(1.0 - s * E, 0.0) / math.pi
    got = model.eval(sp, wi).matrix()[0, 0]
    np.testing.assert_allclose(got, np.broadcast_to(want, got.shape), rtol=1e-12)
    bare = MirrorWithDiffuse(n, 0.0, diffuse_albedo=rho, specular_weight=s, diffuse_weight=1.0,
                             diffuse_layering="albedo_scaling")
    assert np.max(np.abs(bare.eval(sp, wi).matrix()[0, 0] - got)) > 1e-3   # the film's weight is not the bare one
    # sampling: mirror picks carry the filmed matrix / P, diffuse picks eval·cosθ_i / pdf
    rng = np.random.default_rng(3)
    u_lobe = rng.random(sp.n * 40)
    big = points(thetas=np.repeat(THETAS, 40))
    bs = model.sample(big, u_lobe, rng.random((2, big.n)))
    assert bs.is_delta.any() and (~bs.is_delta).any()
    mir = model.delta_reflection(big)
    diff = ~bs.is_delta & bs.valid
    f = model.eval(big, bs.wi).matrix()[0, 0]
    np.testing.assert_allclose(bs.weight.matrix()[0, 0][:, diff],
                               (f * bs.wi[2] / model.pdf(big, bs.wi))[:, diff], rtol=1e-12)
    p = model._p_mirror(big, mir.scaled(1.0 / s))
    pick = bs.is_delta
    np.testing.assert_allclose(bs.weight.A[:, pick], (mir.A / p)[:, pick], rtol=1e-12)
    np.testing.assert_allclose(bs.weight.S[:, pick], (mir.S / p)[:, pick], rtol=1e-12)


# ----------------------------------------------------------------------------- (e) the scene format

def test_the_declarations_build_filmed_mirrors_from_scene_dicts():
    cond = parse_material({"type": "conductor", "n": 0.2, "k": 3.0, "thin_film_thickness": 300,
                           "thin_film_ior": 1.4}, "materials.m")
    assert isinstance(cond, SmoothConductor) and cond.film == (1.4, 300.0)
    assert cond.describe()["thin_film"] == "n 1.4, 300 nm"
    sp = points()
    np.testing.assert_array_equal(cond.delta_reflection(sp).A,
                                  conductor(0.2, 3.0, film_n=1.4, film_thickness=300.0).delta_reflection(sp).A)
    assert parse_material({"type": "conductor", "n": 0.2, "k": 3.0, "thin_film_thickness": 300}, "m").film == \
        (1.33, 300.0)
    smooth = parse_material({"type": "torrance_sparrow", "n": 1.5, "m": 0, "diffuse_albedo": 0.5,
                             "thin_film_thickness": 300, "thin_film_ior": 1.4}, "m")
    assert isinstance(smooth, FilmedMirrorWithDiffuse) and smooth.film == (1.4, 300.0)
    assert smooth.describe()["thin_film"] == "n 1.4, 300 nm"
    rough = parse_material({"type": "torrance_sparrow", "n": 1.5, "m": 0.2, "thin_film_thickness": 300,
                            "thin_film_ior": 1.4}, "m")
    assert isinstance(rough, TorranceSparrow) and rough.film == (1.4, 300.0)


@pytest.mark.parametrize("model", [{"type": "conductor", "n": 0.2, "k": 3.0},
                                   {"type": "torrance_sparrow", "n": 1.5, "m": 0},
                                   {"type": "torrance_sparrow", "n": 1.5, "m": 0.3}])
@pytest.mark.parametrize("key,value", [("thin_film_thickness", -1.0), ("thin_film_thickness", 2e6),
                                       ("thin_film_thickness", "thick"), ("thin_film_thickness", float("nan")),
                                       ("thin_film_ior", 0.0), ("thin_film_ior", -1.3), ("thin_film_ior", float("inf")),
                                       ("thin_film_ior", True)])
def test_bad_film_values_fail_with_one_line_naming_the_field(model, key, value):
    d = {**model, "thin_film_thickness": 300.0, key: value}
    with pytest.raises(SceneError) as err:
        parse_material(d, "materials.m")
    assert err.value.field == f"materials.m.{key}"
    assert "\n" not in str(err.value) and str(err.value).startswith(f"materials.m.{key}: ")


# --------------------------------------------------------------------------- a thickness that varies over the surface

@pytest.mark.parametrize("material", [
    {"type": "conductor", "n": 0.3, "k": 2.5, "thin_film_ior": 1.5},
    {"type": "torrance_sparrow", "n": 0.3, "k": 2.5, "m": 0.2, "distribution": "ggx", "thin_film_ior": 1.5},
    {"type": "torrance_sparrow", "n": 1.5, "k": 0.0, "m": 0.0, "diffuse_albedo": 0.3, "diffuse_weight": 1.0,
     "diffuse_layering": "albedo_scaling", "thin_film_ior": 2.0},
    {"type": "principled", "metallic": 1.0, "roughness": 0.4, "base_color": [0.9, 0.6, 0.3], "thin_film_ior": 1.5},
    {"type": "principled", "transmission": 1.0, "roughness": 0.0, "thin_film_ior": 1.4}])
def test_textured_film_thickness_is_the_constant_film_per_texel(tmp_path, material):
    """thin_film_thickness from a texture (glTF's iridescence thickness map): at each texel the model with that
    constant thickness, to rounding (texels 0 — no film —, 180 and 420 nm).  The Principled metal's index under a
    film is Cycles' film estimate; where the texture gives no film its S0 is rescaled to the F82-Tint curve as the
    unfilmed metal's, so there S0 agrees (to the energy compensation's F_ss of the two indices, 0.3 %) and the
    polarisation is the film estimate's."""
    from tests.support.texel_rows import textured_and_constant
    sp, wi, u_lobe, u_dir, textured, rows = textured_and_constant(tmp_path, material, "thin_film_thickness",
                                                                  [0.0, 180.0, 420.0], reps=40, seed=21)
    assert textured.varies_over_surface
    got_eval, got_delta = textured.eval(sp, wi).matrix(), textured.delta_reflection(sp)
    got_sample = textured.sample(sp, u_lobe, u_dir)
    for sel, d, const, sub in rows:
        if d == 0 and material.get("metallic") == 1.0:
            np.testing.assert_allclose(got_eval[0, 0][..., sel], const.eval(sub, wi[:, sel]).matrix()[0, 0],
                                       rtol=1e-2, atol=1e-12)
            continue
        np.testing.assert_allclose(got_eval[..., sel], const.eval(sub, wi[:, sel]).matrix(), rtol=1e-10, atol=1e-14)
        if got_delta is not None:
            np.testing.assert_allclose(got_delta.matrix()[..., sel], const.delta_reflection(sub).matrix(),
                                       rtol=1e-10, atol=1e-14)
        cs = const.sample(sub, u_lobe[sel], u_dir[:, sel])
        np.testing.assert_allclose(got_sample.weight.matrix()[..., sel], cs.weight.matrix(), rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("material", [
    {"type": "conductor", "n": 0.3, "k": 2.5, "thin_film_thickness": 300.0},
    {"type": "torrance_sparrow", "n": 1.5, "k": 0.0, "m": 0.2, "distribution": "ggx", "thin_film_thickness": 300.0},
    {"type": "principled", "transmission": 1.0, "roughness": 0.0, "thin_film_thickness": 300.0}])
def test_textured_film_index_is_the_constant_film_per_texel(tmp_path, material):
    """thin_film_ior from a texture: at each texel the model with that constant film index (1.2, 1.6, 2.3)."""
    from tests.support.texel_rows import textured_and_constant
    sp, wi, u_lobe, u_dir, textured, rows = textured_and_constant(tmp_path, material, "thin_film_ior",
                                                                  [1.2, 1.6, 2.3], reps=30, seed=23)
    assert textured.varies_over_surface
    got_eval, got_sample = textured.eval(sp, wi).matrix(), textured.sample(sp, u_lobe, u_dir)
    for sel, _, const, sub in rows:
        np.testing.assert_allclose(got_eval[..., sel], const.eval(sub, wi[:, sel]).matrix(), rtol=1e-10, atol=1e-14)
        cs = const.sample(sub, u_lobe[sel], u_dir[:, sel])
        np.testing.assert_allclose(got_sample.weight.matrix()[..., sel], cs.weight.matrix(), rtol=1e-10, atol=1e-14)
