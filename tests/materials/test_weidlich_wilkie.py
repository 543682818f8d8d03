"""Weidlich–Wilkie layered BRDF (engine.materials.weidlich_wilkie).

Oracle: shared/oracles/ww_reference.json (published form, Lambert base), plus the physics
checks of docs/physics.md §4 (index matching, absorption, rank 1, p-polarisation,
realisability, energy, reciprocity) and the sampling contract (chi-square against pdf()).
"""

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from engine.materials.base import ShadingPoint
from engine.materials.conductor import SmoothConductor
from engine.materials.evaluate import mueller_at, oracle_directions
from engine.materials.htsg import HTSG
from engine.materials.lambert import Lambert
from engine.materials.torrance_sparrow import TorranceSparrow
from engine.materials.catalogue import make_model
from engine.materials.weidlich_wilkie import Coat, WeidlichWilkie, top_albedo
from engine.polarisation.frames import rotate_mueller_frames, scattering_plane_axis
from engine.polarisation.fresnel import fresnel_reflection_abcs, refracted_cosine
from engine.polarisation.mueller import realisability_report
from engine.spectral import ConstantSpectrum
from engine.spectral.spectrum import TabulatedSpectrum
from tests.conftest import shared_path
from tests.support import chi2

with open(shared_path("oracles", "ww_reference.json")) as _fh:
    ORACLE = json.load(_fh)["cases"]

Z = np.array([0.0, 0.0, 1.0])


def _col(v):
    return np.asarray(v, dtype=np.float64).reshape(3, 1)


def _point(wo, lam=550.0, L=1):
    """ShadingPoint with normal +z for directions wo (3, N)."""
    wo = np.asarray(wo, dtype=np.float64)
    if wo.ndim == 1:
        wo = wo.reshape(3, 1)
    n = wo.shape[1]
    z = np.tile(Z.reshape(3, 1), (1, n))
    lam_arr = np.broadcast_to(np.asarray(lam, dtype=np.float64).reshape(-1, 1), (L, n)).copy()
    return ShadingPoint(np.zeros((3, n)), z, z, wo, lam_arr, False)


def _direction(theta_deg, phi_deg):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def _lambert(albedo=0.8):
    return Lambert(ConstantSpectrum(albedo))


def _blinn(eta=1.5, e=50.0, alpha_d=0.0):
    return Coat(n=eta, thickness=1.0, absorption=alpha_d, distribution="blinn", exponent=e)


def _scattering_matrix(model, wi, wo, lam=550.0):
    """eval() (4, 4, N) re-expressed in the scattering-plane frames s = unit(k_i × k_o)."""
    sp = _point(wo, lam)
    v = model.eval(sp, wi)
    x = scattering_plane_axis(-wi, wo)
    M = rotate_mueller_frames(v.matrix(), v.x_in[:, None], x[:, None], -wi[:, None],
                              v.x_out[:, None], x[:, None], wo[:, None])
    return M[:, :, 0]


def _albedo(model, theta_i_deg, n_mu=192, n_phi=192):
    """∫ M00 cosθ_o dω_o by Gauss–Legendre in (cosθ_o, φ_o) (φ ∈ [0, π], doubled by symmetry)."""
    x, w = np.polynomial.legendre.leggauss(n_mu)
    mu, wm = 0.5 * (x + 1.0), 0.5 * w
    xp, wp = np.polynomial.legendre.leggauss(n_phi)
    phi, wph = 0.5 * math.pi * (xp + 1.0), 0.5 * math.pi * wp
    MU, PH = np.meshgrid(mu, phi, indexing="ij")
    W = 2.0 * np.outer(wm, wph)
    s = np.sqrt(1.0 - MU * MU)
    wo = np.stack((s * np.cos(PH), s * np.sin(PH), MU)).reshape(3, -1)
    n = wo.shape[1]
    wi = np.tile(_col(oracle_directions(theta_i_deg, 0.0, 0.0)[0]), (1, n))
    f = model.eval(_point(wo), wi).matrix()[0, 0, 0]
    total = float(np.sum(f * MU.ravel() * W.ravel()))
    mirror = np.array([math.sin(math.radians(theta_i_deg)), 0.0, math.cos(math.radians(theta_i_deg))])
    d = model.delta_reflection(_point(mirror))
    if d is not None:
        total += float(d.matrix()[0, 0, 0, 0])
    return total


# ---------------------------------------------------------------------------------------------
# Oracle
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("case", ORACLE, ids=lambda c: c["id"])
def test_oracle_published_form(case):
    # Built exactly as `python -m engine mueller --model weidlich_wilkie --param ...` builds it.
    model = make_model("weidlich_wilkie", {
        "coat_n": case["eta"], "coat_thickness": case["thickness_d"], "coat_absorption": case["alpha"],
        "coat_distribution": "blinn", "coat_exponent": case["blinn_exponent"], "base_albedo": case["base_albedo"],
        "t_term": "ww" if case["tir"] else "t21", "transmission_normal": "facet" if case["mf_normal"] else "macro",
        "form": "published"})
    wi, wo = oracle_directions(case["theta_i_deg"], case["theta_o_deg"], case["phi_o_deg"])
    sp = _point(wo)
    info = model.intermediates(sp, _col(wi))
    M00 = model.eval(sp, _col(wi)).matrix()[0, 0, 0, 0]
    rel = dict(rtol=1e-6, atol=1e-15)
    np.testing.assert_allclose(M00, case["f_total_reference"], **rel)
    np.testing.assert_allclose(info["f_top"][0, 0], case["f_top_reference"], **rel)
    np.testing.assert_allclose(info["f_layer"][0, 0], case["f_layer_reference"], **rel)
    ref = case["intermediates"]
    for key in ("T12", "F21", "G_int", "t", "a"):
        np.testing.assert_allclose(info[key][0, 0], ref[key], rtol=1e-6, atol=1e-12, err_msg=key)
    for key in ("theta_i_int_deg", "theta_o_int_deg"):
        np.testing.assert_allclose(info[key][0, 0], ref[key], rtol=0, atol=1e-5, err_msg=key)
    # The physically derived first-order term (for information in the oracle) is form="first_order".
    coat = Coat(n=case["eta"], thickness=case["thickness_d"], absorption=case["alpha"],
                distribution="blinn", exponent=case["blinn_exponent"])
    first = WeidlichWilkie([coat], _lambert(case["base_albedo"]), form="first_order",
                           transmission_normal="facet" if case["mf_normal"] else "macro")
    np.testing.assert_allclose(first.intermediates(sp, _col(wi))["f_layer"][0, 0],
                               case["f_layer_first_order_with_inv_eta2_and_T21"], **rel)


def test_oracle_covers_all_switches():
    assert len(ORACLE) >= 100
    assert {c["tir"] for c in ORACLE} == {0, 1} and {c["mf_normal"] for c in ORACLE} == {0, 1}


def test_top_albedo_quadrature_converged():
    dist = _blinn().dist
    mu = np.cos(np.radians([0.0, 60.0, 85.0, 89.0]))
    coarse = top_albedo(mu, 1.5, dist)
    fine = top_albedo(mu, 1.5, dist, n_u=512, n_phi=384)
    np.testing.assert_allclose(coarse, fine, rtol=0, atol=2e-5)
    np.testing.assert_allclose(coarse[0], 0.04005, atol=1e-4)  # ≈ F(0) = 0.04 for a narrow lobe


# ---------------------------------------------------------------------------------------------
# Limits: index matching and absorption (docs/physics.md §4)
# ---------------------------------------------------------------------------------------------

BASES = {
    "lambert": lambda: _lambert(0.7),
    "ts_conductor": lambda: TorranceSparrow(0.2, 3.0, 0.3),
    "ts_dielectric_diffuse": lambda: TorranceSparrow(1.6, 0.0, 0.25, diffuse_albedo=0.5, diffuse_weight=0.5),
    "htsg": lambda: HTSG(0.2, 3.0, 0.2, 2.0, albedo=0.1),
}
GEOMETRIES = [(40, 50, 60), (0, 30, 0), (70, 20, 180), (10, 80, 90), (35, 35, 0), (60, 60, 180)]


@pytest.mark.parametrize("form", ["energy", "published", "first_order"])
@pytest.mark.parametrize("dist", ["smooth", "blinn", "beckmann"])
@pytest.mark.parametrize("base_name", sorted(BASES))
def test_index_matched_coat_is_the_base(base_name, dist, form):
    base = BASES[base_name]()
    kw = {"blinn": dict(exponent=30.0), "beckmann": dict(m=0.3), "smooth": {}}[dist]
    clear = WeidlichWilkie(Coat(n=1.0, distribution=dist, **kw), base, form=form)
    absorbing = WeidlichWilkie(Coat(n=1.0, thickness=2.0, absorption=0.15, distribution=dist, **kw), base, form=form)
    for g in GEOMETRIES:
        B = np.array(mueller_at(base, *g)["brdf"])
        scale = max(abs(B[0, 0]), 1e-300)
        np.testing.assert_allclose(np.array(mueller_at(clear, *g)["brdf"]), B, rtol=0, atol=1e-12 * scale)
        a = math.exp(-0.3 * (1.0 / math.cos(math.radians(g[0])) + 1.0 / math.cos(math.radians(g[1]))))
        np.testing.assert_allclose(np.array(mueller_at(absorbing, *g)["brdf"]), a * B, rtol=0,
                                   atol=1e-12 * scale)


def test_index_matched_smooth_coat_over_mirror_is_the_mirror():
    base = SmoothConductor(ConstantSpectrum(0.2), ConstantSpectrum(3.0))
    model = WeidlichWilkie(Coat(n=1.0), base)
    assert model.delta_only
    for th in (0.0, 30.0, 75.0):
        np.testing.assert_allclose(np.array(mueller_at(model, th, th, 0)["delta"]),
                                   np.array(mueller_at(base, th, th, 0)["delta"]), atol=1e-13)


# ---------------------------------------------------------------------------------------------
# Polarisation structure of the layer term
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("form", ["energy", "published", "first_order"])
def test_lambert_layer_is_rank_one(form):
    model = WeidlichWilkie(_blinn(alpha_d=0.2), _lambert(0.8), form=form)
    rng = np.random.default_rng(3)
    v = rng.normal(size=(3, 64))
    wi, wo = v / np.linalg.norm(v, axis=0), rng.normal(size=(3, 64))
    wi[2] = np.abs(wi[2]) + 0.05
    wo[2] = np.abs(wo[2]) + 0.05
    wi /= np.linalg.norm(wi, axis=0)
    wo /= np.linalg.norm(wo, axis=0)
    M = model.intermediates(_point(wo), wi)["M_layer"][:, :, 0, :]
    sv = np.linalg.svd(np.moveaxis(M, -1, 0), compute_uv=False)
    assert np.all(sv[:, 0] > 0)
    assert np.all(sv[:, 1] <= 1e-12 * sv[:, 0])


@pytest.mark.parametrize("coat", [Coat(n=1.5), Coat(n=2.5, thickness=1.0, absorption=0.3)])
def test_smooth_coat_over_lambert_is_p_polarised(coat):
    model = WeidlichWilkie(coat, _lambert(0.9))
    for g in [(30, 50, 40), (60, 20, 180), (75, 75, 90), (10, 45, 0)]:
        M = np.array(mueller_at(model, *g, basis="sp")["brdf"])
        # Unpolarised in: S_out = column 0, in the plane-of-incidence frame of ω_o.
        assert M[1, 0] < -1e-3 * M[0, 0]
        assert abs(M[2, 0]) < 1e-12 * M[0, 0] and M[3, 0] == 0.0
        # Rank-1 product col₀(exit) row₀(entry): M01 carries the entry diattenuation.
        assert M[0, 1] < 0
        np.testing.assert_allclose(M[1, 1] * M[0, 0], M[1, 0] * M[0, 1], rtol=1e-10)


@pytest.mark.parametrize("form,normal,base_name,basis", [
    ("energy", "macro", "lambert", "scattering"), ("energy", "macro", "lambert", "sp"),
    ("energy", "macro", "ts_conductor", "scattering"), ("published", "facet", "lambert", "sp"),
    ("published", "facet", "ts_conductor", "sp"), ("published", "macro", "ts_conductor", "scattering"),
    ("first_order", "macro", "ts_conductor", "scattering")])
def test_layer_not_block_diagonal_off_plane(form, normal, base_name, basis):
    model = WeidlichWilkie(_blinn(), BASES[base_name](), form=form, transmission_normal=normal)
    off = np.array(mueller_at(model, 40, 50, 60, basis=basis)["brdf"])
    assert abs(off[0, 2]) > 1e-3 * off[0, 0] and abs(off[2, 0]) > 1e-3 * off[0, 0]
    assert abs(off[1, 2]) > 1e-5 * off[0, 0]
    plane = np.array(mueller_at(model, 40, 50, 0, basis=basis)["brdf"])
    assert abs(plane[0, 2]) < 1e-12 * plane[0, 0] and abs(plane[2, 0]) < 1e-12 * plane[0, 0]


@pytest.mark.parametrize("base_name", ["lambert", "ts_conductor"])
def test_facet_transmission_is_block_diagonal_in_scattering_frames(base_name):
    """Refraction through h keeps ω'_i, ω'_o in the plane of ω_i, ω_o (h lies in it): every factor,
    and the base's own scattering plane, share the external scattering-plane frames."""
    model = WeidlichWilkie(_blinn(), BASES[base_name](), form="published")
    M = np.array(mueller_at(model, 40, 50, 60, basis="scattering")["brdf"])
    assert np.all(np.abs(M[:2, 2:]) < 1e-12 * M[0, 0]) and np.all(np.abs(M[2:, :2]) < 1e-12 * M[0, 0])
    if base_name == "lambert":
        assert abs(M[1, 1] - M[0, 0]) > 1e-3 * M[0, 0]  # but not of the ABCS form (a depolarised share)


def test_published_form_t_replaces_t21():
    """M00 of the published layer is T12·f_base·a·t (t replaces T21; no double counting)."""
    model = WeidlichWilkie(_blinn(alpha_d=0.3), _lambert(0.6), form="published")
    wi, wo = oracle_directions(50, 30, 120)
    info = model.intermediates(_point(wo), _col(wi))
    expected = info["T12"] * info["a"] * info["t"] * 0.6 / math.pi
    np.testing.assert_allclose(info["f_layer"], expected, rtol=1e-13)


# ---------------------------------------------------------------------------------------------
# Realisability and finiteness (hypothesis)
# ---------------------------------------------------------------------------------------------

SPECIAL_THETA = st.sampled_from([0.0, 89.99, 45.0]) | st.floats(0.0, 89.99)
SPECIAL_PHI = st.sampled_from([0.0, 180.0, 90.0]) | st.floats(0.0, 360.0)
COATS = st.sampled_from([("smooth", {}), ("blinn", {"exponent": 50.0}), ("blinn", {"exponent": 2000.0}),
                         ("beckmann", {"m": 0.05}), ("beckmann", {"m": 0.6})])
BASE_MAKERS = st.sampled_from(["lambert", "ts_conductor", "ts_dielectric_diffuse"])


def _check_realisable(M, label):
    M = np.asarray(M, dtype=np.float64)
    assert np.all(np.isfinite(M)), label
    rep = realisability_report(M, tol=1e-9)
    for key, ok in rep.items():
        assert np.all(ok), (label, key)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(theta_i=SPECIAL_THETA, theta_o=SPECIAL_THETA, phi_o=SPECIAL_PHI, eta=st.sampled_from([1.0, 1.5, 2.5, 0.8]),
       alpha_d=st.sampled_from([0.0, 0.4, 50.0]), coat=COATS, base_name=BASE_MAKERS,
       form=st.sampled_from(["energy", "published", "first_order"]), normal=st.sampled_from(["facet", "macro"]),
       exact=st.sampled_from(["none", "specular", "backscatter"]))
def test_realisable_and_finite(theta_i, theta_o, phi_o, eta, alpha_d, coat, base_name, form, normal, exact):
    dist, kw = coat
    if form == "energy":
        normal = "macro"
    model = WeidlichWilkie(Coat(n=eta, thickness=1.0, absorption=alpha_d, distribution=dist, **kw),
                           BASES[base_name](), form=form, transmission_normal=normal)
    if exact == "specular":
        theta_o, phi_o = theta_i, 0.0
    elif exact == "backscatter":
        theta_o, phi_o = theta_i, 180.0
    wi, wo = oracle_directions(theta_i, theta_o, phi_o)
    # A batch: the drawn geometry, its reverse, and ω_o along the normal.
    wis = np.stack((wi, wo, wi), axis=1)
    wos = np.stack((wo, wi, Z), axis=1)
    sp = _point(wos, lam=[450.0, 550.0], L=2)
    v = model.eval(sp, wis)
    M = v.matrix()
    _check_realisable(M, "eval")
    assert np.all(np.isfinite(v.x_in)) and np.all(np.isfinite(v.x_out))
    assert np.all(np.abs(np.linalg.norm(v.x_in, axis=0) - 1) < 1e-9)
    d = model.delta_reflection(sp)
    if d is not None:
        _check_realisable(d.matrix(), "delta")
    pdf = model.pdf(sp, wis)
    assert np.all(np.isfinite(pdf)) and np.all(pdf >= 0)
    rng = np.random.default_rng(0)
    bs = model.sample(sp, rng.random(3), rng.random((2, 3)))
    assert np.all(np.isfinite(bs.weight.matrix())) and np.all(np.isfinite(bs.pdf))
    _check_realisable(bs.weight.matrix(), "sample")


def test_internal_directions_beyond_critical_angle():
    """Transmission through h can put the internal directions beyond the critical angle (41.8°)."""
    model = WeidlichWilkie(_blinn(alpha_d=0.5), _lambert(0.8), form="published")
    wi, wo = oracle_directions(80, 60, 180)
    info = model.intermediates(_point(wo), _col(wi))
    assert info["theta_i_int_deg"][0, 0] > 70.0
    assert info["f_layer"][0, 0] > 0 and np.isfinite(info["f_layer"][0, 0])
    # A coat less dense than the exterior: no transmission beyond its critical angle (TIR from outside).
    inv = WeidlichWilkie(Coat(n=0.8, distribution="blinn", exponent=50.0), _lambert(0.8), form="published")
    wi, wo = oracle_directions(70, 70, 0)  # specular: h = n, 70° > asin(0.8) = 53.1°
    info = inv.intermediates(_point(wo), _col(wi))
    assert info["f_layer"][0, 0] == 0.0 and not info["valid_layer"][0, 0]


# ---------------------------------------------------------------------------------------------
# Energy
# ---------------------------------------------------------------------------------------------

ENERGY_ANGLES = [0.0, 30.0, 60.0, 70.0, 80.0, 85.0, 89.0, 89.99]


def test_energy_form_conserves_energy_white_lambert():
    model = WeidlichWilkie(_blinn(), _lambert(1.0))  # form="energy" is the default
    assert model.form == "energy"
    albedo = np.array([_albedo(model, t) for t in ENERGY_ANGLES])
    assert np.all(albedo <= 1.0 + 1e-3), albedo
    # White, non-absorbing base: the internal reflections are summed, so nothing is lost.
    assert np.all(albedo >= 0.995), albedo


def test_published_form_exceeds_one_at_grazing():
    model = WeidlichWilkie(_blinn(), _lambert(1.0), form="published")
    a70, a85 = _albedo(model, 70.0), _albedo(model, 85.0)
    assert abs(a70 - 1.046) < 2e-3 and abs(a85 - 1.266) < 3e-3
    macro = WeidlichWilkie(_blinn(), _lambert(1.0), form="published", transmission_normal="macro")
    assert abs(_albedo(macro, 70.0) - 0.893) < 2e-3


@pytest.mark.parametrize("coat", [Coat(n=1.5), Coat(n=1.5, distribution="beckmann", m=0.2)],
                         ids=["smooth", "beckmann"])
def test_energy_form_glossy_base(coat):
    """A glossy base under the coat: WW's missing 1/η² gives ~η²× the energy; the energy form is bounded."""
    base = TorranceSparrow(0.05, 10.0, 0.1)
    model = WeidlichWilkie(coat, base)
    for t in (0.0, 75.0):
        assert _albedo(model, t, 160, 160) <= 1.0 + 1e-3
    if coat.smooth:
        assert _albedo(WeidlichWilkie(coat, base, form="published"), 0.0, 160, 160) > 1.8


def test_energy_form_partial_albedo_and_absorption_bounded():
    for base, coat in [(_lambert(0.5), _blinn(eta=2.5, alpha_d=0.3)),
                       (_lambert(1.0), Coat(n=1.3, thickness=1.0, absorption=2.0, distribution="beckmann", m=0.4))]:
        model = WeidlichWilkie(coat, base)
        for t in (0.0, 60.0, 88.0):
            assert 0.0 < _albedo(model, t, 128, 128) <= 1.0 + 1e-3


# ---------------------------------------------------------------------------------------------
# Reciprocity
# ---------------------------------------------------------------------------------------------

def _random_pairs(n, seed):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(2):
        v = rng.normal(size=(3, n))
        v[2] = np.abs(v[2])
        out.append(v / np.linalg.norm(v, axis=0))
    return out


@pytest.mark.parametrize("form,normal", [("published", "facet"), ("energy", "macro"), ("first_order", "facet"),
                                         ("first_order", "macro")])
@pytest.mark.parametrize("base_name", ["lambert", "ts_conductor"])
def test_reciprocity(form, normal, base_name):
    """M_rev = P·Mᵀ·P, P = diag(1, 1, −1, 1), in the scattering-plane frames (M00 symmetric).

    (For ABCD matrices this equals docs/physics.md's Q·Mᵀ·Q with Q = diag(1, 1, 1, −1).)
    """
    model = WeidlichWilkie(Coat(n=1.5, thickness=1.0, absorption=0.2, distribution="beckmann", m=0.3),
                           BASES[base_name](), form=form, transmission_normal=normal)
    wi, wo = _random_pairs(500, 7)
    A = _scattering_matrix(model, wi, wo)
    B = _scattering_matrix(model, wo, wi)
    P = np.diag([1.0, 1.0, -1.0, 1.0])
    Brev = np.einsum("ij,jkn,kl->iln", P, np.transpose(B, (1, 0, 2)), P)
    scale = np.abs(A[0, 0]).max()
    np.testing.assert_allclose(A[0, 0], B[0, 0], rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(A, Brev, rtol=0, atol=1e-13 * scale)


def test_published_macro_reciprocity_defect():
    """Through the macro normal WW's t breaks reciprocity by (1 − G_int)(T12(θ_i) − T12(θ_o))·f_base·a."""
    model = WeidlichWilkie(Coat(n=1.05, distribution="blinn", exponent=20.0), _lambert(0.8), form="published",
                           transmission_normal="macro")
    wi, wo = oracle_directions(85, 20, 170)
    fwd = model.intermediates(_point(wo), _col(wi))
    rev = model.intermediates(_point(wi), _col(wo))
    assert fwd["G_int"][0, 0] < 0.99
    diff = fwd["f_layer"][0, 0] - rev["f_layer"][0, 0]
    expected = (1 - fwd["G_int"][0, 0]) * (fwd["T12"][0, 0] - rev["T12"][0, 0]) * 0.8 / math.pi * fwd["a"][0, 0]
    assert abs(diff) > 1e-4
    np.testing.assert_allclose(diff, expected, rtol=1e-10)


# ---------------------------------------------------------------------------------------------
# Dirac lobes
# ---------------------------------------------------------------------------------------------

def test_smooth_coat_mirror_is_fresnel():
    model = WeidlichWilkie(Coat(n=1.5), _lambert(0.8))
    glass = SmoothConductor(ConstantSpectrum(1.5), ConstantSpectrum(0.0))
    for th in (0.0, 56.31, 80.0):
        np.testing.assert_allclose(np.array(mueller_at(model, th, th, 0)["delta"]),
                                   np.array(mueller_at(glass, th, th, 0)["delta"]), atol=1e-14)


def test_smooth_coat_over_mirror_delta_weight():
    eta_c = 1.5
    n_b, k_b = 0.2, 3.0
    model = WeidlichWilkie(Coat(n=eta_c, thickness=1.0, absorption=0.1),
                           SmoothConductor(ConstantSpectrum(n_b), ConstantSpectrum(k_b)))
    assert model.delta_only and model.base.exterior_n == eta_c
    for th in (0.0, 35.0, 70.0):
        D = np.array(mueller_at(model, th, th, 0)["delta"])
        c = math.cos(math.radians(th))
        c_t = float(refracted_cosine(c, eta_c)[0])
        # Per polarisation (the diattenuators and the mirror share the plane of incidence):
        # F + ½(T_s² R_s + T_p² R_p)·a — not F + T²R·a.
        A, B = fresnel_reflection_abcs(c, eta_c)[:2]
        Ab, Bb = fresnel_reflection_abcs(c_t, complex(n_b, k_b) / eta_c)[:2]
        Ts, Tp = 1 - (A + B), 1 - (A - B)
        expected = A + 0.5 * (Ts ** 2 * (Ab + Bb) + Tp ** 2 * (Ab - Bb)) * math.exp(-0.2 / c_t)
        np.testing.assert_allclose(D[0, 0], expected, rtol=1e-12)
        _check_realisable(D[:, :, None], "delta")


def test_rough_coat_over_delta_base_rejected():
    with pytest.raises(ValueError):
        WeidlichWilkie(_blinn(), SmoothConductor(ConstantSpectrum(0.2), ConstantSpectrum(3.0)))


# ---------------------------------------------------------------------------------------------
# Stacks, dispersion, base indices, parameters
# ---------------------------------------------------------------------------------------------

def test_multiple_coats_recursive():
    base = TorranceSparrow(0.2, 3.0, 0.3)
    single = WeidlichWilkie(_blinn(), base)
    stack = WeidlichWilkie([Coat(n=1.0), _blinn()], base)
    assert isinstance(stack.base, WeidlichWilkie) and stack.base.exterior_n.value == 1.0
    for g in GEOMETRIES:
        np.testing.assert_allclose(np.array(mueller_at(stack, *g)["brdf"]), np.array(mueller_at(single, *g)["brdf"]),
                                   rtol=0, atol=1e-13)
    two = WeidlichWilkie([Coat(n=1.4, distribution="beckmann", m=0.2),
                          Coat(n=2.0, thickness=1.0, absorption=0.1, distribution="blinn", exponent=80.0)],
                         _lambert(0.9))
    assert two.base.exterior_n.value == 1.4 and two.base.coat.n == 2.0
    for t in (0.0, 60.0, 85.0):
        assert _albedo(two, t, 128, 128) <= 1.0 + 1e-3


def test_dispersive_coat_is_exact_per_wavelength():
    lam_tab = np.array([360.0, 830.0])
    n_spec = TabulatedSpectrum(lam_tab, np.array([1.62, 1.46]), name="test-glass")
    base = _lambert(0.8)
    model = WeidlichWilkie(Coat(n=n_spec, distribution="beckmann", m=0.3), base, form="published")
    lams = np.array([400.0, 500.0, 600.0, 700.0])
    wi, wo = _random_pairs(5, 11)
    sp = _point(wo, lam=lams, L=4)
    M = model.eval(sp, wi).matrix()
    for j, lam in enumerate(lams):
        n_l = float(n_spec.eval(np.array([lam]))[0])
        ref = WeidlichWilkie(Coat(n=n_l, distribution="beckmann", m=0.3), base, form="published")
        Mr = ref.eval(_point(wo, lam=lam), wi).matrix()[:, :, 0]
        np.testing.assert_allclose(M[:, :, j], Mr, rtol=1e-12, atol=1e-15)
    assert not np.allclose(M[0, 0, 0], M[0, 0, 3])
    # Energy form with a dispersive coat: table over η, still bounded.
    energy = WeidlichWilkie(Coat(n=n_spec, distribution="beckmann", m=0.3), _lambert(1.0))
    assert energy.albedo_table().eta.size > 1
    bs = energy.sample(sp, np.full(5, 0.5), np.full((2, 5), 0.3))
    assert np.all(np.isfinite(bs.weight.matrix()))


def test_base_exterior_index_matched_to_coat():
    base = TorranceSparrow(0.2, 3.0, 0.3)
    model = WeidlichWilkie(Coat(n=1.5, distribution="beckmann", m=0.3), base)
    assert base.exterior_n == 1.0  # the caller's object is untouched
    assert model.base.exterior_n == 1.5 and model.base is not base
    raw = WeidlichWilkie(Coat(n=1.5, distribution="beckmann", m=0.3), base, match_base_exterior=False)
    assert raw.base is base
    wi, wo = oracle_directions(30, 40, 20)
    assert not np.allclose(model.eval(_point(wo), _col(wi)).matrix(), raw.eval(_point(wo), _col(wi)).matrix())


def test_parameter_validation():
    with pytest.raises(ValueError):
        Coat(n=1.5, distribution="blinn")
    with pytest.raises(ValueError):
        Coat(n=1.5, distribution="beckmann", m=0.0)
    with pytest.raises(ValueError):
        Coat(n=-1.0)
    with pytest.raises(ValueError):
        WeidlichWilkie(_blinn(), _lambert(), form="bogus")
    with pytest.raises(ValueError):
        WeidlichWilkie(_blinn(), _lambert(), form="energy", transmission_normal="facet")
    with pytest.raises(ValueError):
        WeidlichWilkie([], _lambert())
    m = WeidlichWilkie(_blinn(), _lambert())
    assert m.name == "weidlich_wilkie" and m.describe()["form"] == "energy"


# ---------------------------------------------------------------------------------------------
# Sampling
# ---------------------------------------------------------------------------------------------

def _chi_square(model, theta_o, phi_o, n=200_000, seed=1, n_cos=20, n_phi=40, q=6):
    wo = _direction(theta_o, phi_o)
    sp = _point(np.tile(_col(wo), (1, n)))
    rng = np.random.default_rng(seed)
    bs = model.sample(sp, rng.random(n), rng.random((2, n)))
    nd = bs.valid & ~bs.is_delta
    wi = bs.wi[:, nd]
    # weight == eval·cosθ_i/pdf and pdf == pdf(ω_i) at the sampled non-delta directions
    k = min(2000, wi.shape[1])
    sub = _point(np.tile(_col(wo), (1, k)))
    pdf = model.pdf(sub, wi[:, :k])
    np.testing.assert_allclose(bs.pdf[nd][:k], pdf, rtol=1e-12)
    expect = model.eval(sub, wi[:, :k])
    Mw = bs.weight.matrix()[:, :, :, nd][..., :k]
    Me = expect.matrix() * (wi[2, :k] / pdf)[None, None, None, :]
    Me = rotate_mueller_frames(Me, expect.x_in[:, None], bs.weight.x_in[:, nd][:, None, :k], -wi[:, None, :k],
                               expect.x_out[:, None], bs.weight.x_out[:, nd][:, None, :k],
                               np.tile(_col(wo), (1, k))[:, None])
    np.testing.assert_allclose(Mw, Me, rtol=1e-10, atol=1e-12 * np.abs(Me[0, 0]).max())
    # Non-delta directions against pdf() over (cosθ_i, φ_i) cells, Gauss–Legendre q×q per cell; Dirac and
    # invalid samples fill the harness's "elsewhere" cell.
    def pdf_at(d):
        return model.pdf(_point(np.tile(_col(wo), (1, d.shape[1]))), d)

    mass = chi2.hemisphere_cell_mass(pdf_at, n_cos, n_phi, order=q)
    # Total non-delta mass: the sampler's valid non-delta fraction.
    frac = nd.sum() / n
    assert abs(frac - mass.sum()) < 5 * math.sqrt(max(mass.sum() * (1 - mass.sum()), 1e-12) / n) + 1e-3
    result = chi2.direction_sampler_test(bs.wi, nd, pdf_at, n_cos=n_cos, n_phi=n_phi, order=q)
    chi2.assert_accepted(result, test_count=5, what="Weidlich–Wilkie samples")
    return bs, frac


@pytest.mark.parametrize("theta_o,phi_o", [(30.0, 0.0), (75.0, 40.0)])
def test_sampling_chi_square_rough_coat_over_lambert(theta_o, phi_o):
    model = WeidlichWilkie(Coat(n=1.5, thickness=1.0, absorption=0.2, distribution="beckmann", m=0.25),
                           _lambert(0.8))
    _chi_square(model, theta_o, phi_o)


@pytest.mark.parametrize("theta_o,phi_o", [(20.0, 0.0), (60.0, 120.0)])
def test_sampling_chi_square_smoothish_coat_over_ts(theta_o, phi_o):
    model = WeidlichWilkie(Coat(n=1.5, distribution="beckmann", m=0.1), TorranceSparrow(0.2, 3.0, 0.3),
                           form="published")
    _chi_square(model, theta_o, phi_o)


def test_sampling_chi_square_smooth_coat_with_delta_lobe():
    model = WeidlichWilkie(Coat(n=1.5), TorranceSparrow(1.6, 0.0, 0.3, diffuse_albedo=0.6, diffuse_weight=0.5))
    bs, frac = _chi_square(model, 50.0, 0.0)
    # The coat mirror is chosen with P_top; those samples are Dirac, with weight M_F/P_top.
    wo = _col(_direction(50.0, 0.0))
    p_top = model._plan(_point(wo))[0][0]
    delta = bs.is_delta & bs.valid
    assert 0 < p_top < 1 and abs(delta.mean() - p_top) < 5 * math.sqrt(p_top * (1 - p_top) / delta.size)
    assert np.all(bs.pdf[bs.is_delta] == 0)
    mirror = model.delta_reflection(_point(wo)).matrix()[:, :, 0, 0]
    np.testing.assert_allclose(bs.weight.matrix()[:, :, 0, np.nonzero(delta)[0][0]], mirror / p_top, rtol=1e-12)


def test_sampling_estimates_albedo():
    """E[weight00] = ∫ M00 cosθ_i dω_i + Dirac weights (unbiasedness incl. Dirac lobes)."""
    cases = [
        (WeidlichWilkie(Coat(n=1.5, distribution="beckmann", m=0.3), _lambert(0.8)), 45.0),
        (WeidlichWilkie(Coat(n=1.5, thickness=1.0, absorption=0.2),
                        SmoothConductor(ConstantSpectrum(0.2), ConstantSpectrum(3.0))), 30.0),
        (WeidlichWilkie(Coat(n=1.5), HTSG(0.2, 3.0, 0.02, 2.0, albedo=0.2)), 40.0),
    ]
    for model, th in cases:
        n = 100_000
        wo = np.tile(_col(_direction(th, 0.0)), (1, n))
        rng = np.random.default_rng(5)
        bs = model.sample(_point(wo), rng.random(n), rng.random((2, n)))
        w = bs.weight.matrix()[0, 0, 0]
        est, err = w.mean(), w.std() / math.sqrt(n)
        ref = _albedo(model, th, 192, 192)  # reciprocal geometry: albedo at θ_o (energy form is reciprocal)
        assert abs(est - ref) < 5 * err + 2e-3, (model.base.name, est, ref, err)


def test_energy_form_mixed_base_diffuse_share():
    """The internal-reflection sum applies to a TS base's Lambert share (MuellerValue.depol); still ≤ 1."""
    base = TorranceSparrow(0.05, 10.0, 0.2, diffuse_albedo=1.0, diffuse_weight=0.3, specular_weight=0.7)
    model = WeidlichWilkie(Coat(n=1.5, distribution="beckmann", m=0.2), base)
    wi, wo = oracle_directions(30, 40, 70)
    info = model.intermediates(_point(wo), _col(wi))
    assert info["c_ms"][0, 0] > 1.2
    for t in (0.0, 60.0, 85.0):
        assert _albedo(model, t, 160, 160) <= 1.0 + 1e-3
