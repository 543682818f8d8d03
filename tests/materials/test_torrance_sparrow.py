"""Torrance–Sparrow polarising microfacet BRDF (engine.materials.torrance_sparrow, .microfacet).

- NIST SCATMECH oracle: every record of shared/oracles/scatmech_facet_torrance_sparrow.json in
  both of its bases, through engine.materials.evaluate.mueller_at.
- docs/physics.md §4: realisability and purity, reciprocity, energy, the m → 0 Fresnel-mirror limit,
  finite values at the degenerate geometries.
- Microfacet building blocks: erf family, D normalisation, Smith G1 against its defining
  integral, Walter's rational G1.
- Sampling: chi-square goodness of fit of sample() against pdf() (as Mitsuba 3's BSDF chi²
  tests), weight = eval·cosθ_i/pdf, and the Monte Carlo albedo against quadrature.
"""

import functools
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.materials.base import ShadingPoint
from engine.materials.catalogue import make_model
from engine.materials.evaluate import mueller_at, oracle_directions
from engine.materials.microfacet import (Beckmann, BlinnPhong, erf, erfc, erfcx, erfinv, g1_beckmann_exact,
                                         g1_beckmann_rational, g_vcavity, half_vector)
from engine.materials.roughness import ALPHA_MIN as M_MIN
from engine.materials.torrance_sparrow import TorranceSparrow
from engine.polarisation.frames import rotate_mueller_frames
from engine.polarisation.fresnel import fresnel_reflection_mueller
from engine.polarisation.mueller import depolarisation_index_sq_excess, is_realisable
from engine.spectral import ConstantSpectrum, named_ior
from engine.vec3 import cross, dot
from tests.conftest import shared_path
from tests.support import chi2

# --- helpers ---------------------------------------------------------------------------------------------


def _records():
    with open(shared_path("oracles", "scatmech_facet_torrance_sparrow.json")) as fh:
        return json.load(fh)["records"]


RECORDS = _records()
SHADOW = {"Torrance_Sparrow_Shadow_Function": "ts", "Unit_Shadow_Function": "none"}


def sph(theta_deg, phi_deg):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def point(wo, normal=(0.0, 0.0, 1.0), lam=550.0):
    """ShadingPoint for viewer directions wo (3, N) (or (3,)), one wavelength unless lam is (L, N)."""
    wo = np.asarray(wo, dtype=np.float64).reshape(3, -1)
    n = wo.shape[1]
    nrm = np.asarray(normal, dtype=np.float64)
    nrm = np.tile(nrm.reshape(3, 1), (1, n)) if nrm.ndim == 1 else nrm
    lam = np.full((1, n), float(lam)) if np.isscalar(lam) else np.asarray(lam, dtype=np.float64)
    return ShadingPoint(np.zeros((3, n)), nrm, nrm, wo, lam)


def tile(v, n):
    return np.tile(np.asarray(v, dtype=np.float64).reshape(3, 1), (1, n))


def matrix_in_frames(value, x_in, k_in, x_out, k_out):
    """The (4, 4, L, N) Mueller matrix of ``value`` re-expressed in frames x_in, x_out (3, N)."""
    M = value.matrix()
    if value.kind == "depolarising":
        return M
    return rotate_mueller_frames(M, value.x_in, x_in, k_in, value.x_out, x_out, k_out)


@functools.cache
def _gl16():
    return np.polynomial.legendre.leggauss(16)


def gauss_legendre(a, b, panels):
    """Composite 16-point Gauss–Legendre nodes and weights on [a, b] (avoids large eigenproblems)."""
    x, w = _gl16()
    edges = np.linspace(a, b, panels + 1)
    half = 0.5 * np.diff(edges)[:, None]
    nodes = (half * (x + 1.0) + edges[:-1, None]).ravel()
    return nodes, (half * w).ravel()


def lobe_quadrature(theta_i_deg, m, n_u=128, n_phi=192, full=False):
    """Nodes ω_o (3, K) and weights (K,) with ∫ g(ω_o) dω_o ≈ Σ w g(ω_o) for g concentrated near the
    mirror direction of ω_i = sph(θ_i, 180°) (light in the −x half-plane, viewer towards +x).

    ω_o = reflect(ω_i, h) with h = unit(−x, −y, 1) over Beckmann slopes of scale m in polar form,
    x = mρcosφ, y = mρsinφ, u = e^{−ρ²} (Gauss–Legendre in u, midpoint rule in φ).  dω_h =
    cos³θ_h m² ρ dρ dφ, ρdρ = du/(2u), dω_o = 4 (ω_i·h) dω_h; facets with ω_i·h ≤ 0 get weight 0.
    Unless ``full``, φ covers [0, π] only with doubled weights, which is exact for integrands that
    are even under the mirror y → −y (M00 of an isotropic BRDF); ``full`` uses 2·n_phi nodes on [0, 2π).
    """
    wi = sph(theta_i_deg, 180.0)
    u, wu = gauss_legendre(0.0, 1.0, n_u // 16)
    if full:
        n_phi *= 2
    phi = (2.0 if full else 1.0) * math.pi * (np.arange(n_phi) + 0.5) / n_phi
    U, P = np.meshgrid(u, phi, indexing="ij")
    WU = np.broadcast_to(wu[:, None], U.shape).ravel()
    U, P = U.ravel(), P.ravel()
    rho = np.sqrt(-np.log(U))
    sx, sy = m * rho * np.cos(P), m * rho * np.sin(P)
    h = np.stack((-sx, -sy, np.ones_like(sx)))
    h = h / np.sqrt(h[0] ** 2 + h[1] ** 2 + 1.0)
    d = wi @ h
    wo = 2.0 * d * h - wi[:, None]
    dphi = (2.0 if full else 1.0) * math.pi / n_phi * (1.0 if full else 2.0)
    weights = np.where(d > 0, h[2] ** 3 * m * m / (2.0 * U) * dphi * WU * 4.0 * d, 0.0)
    return wi, wo, weights


def directional_albedo(model, theta_i_deg, m):
    """∫ M00(ω_i, ω_o) cosθ_o dω_o by lobe quadrature."""
    wi, wo, wts = lobe_quadrature(theta_i_deg, m)
    v = model.eval(point(wo), tile(wi, wo.shape[1]))
    return float(np.sum(v.A[0] * np.maximum(wo[2], 0.0) * wts))


# --- the SCATMECH oracle ---------------------------------------------------------------------------------


def test_oracle_file_is_the_expected_one():
    assert len(RECORDS) == 610
    assert {r["sdf_s_rms_slope"] for r in RECORDS} == {0.001, 0.01, 0.05, 0.2, 0.5}
    assert any(r["M"]["psps"][0][0] == 0.0 for r in RECORDS)  # underflow records are present


@pytest.mark.parametrize("rec", RECORDS, ids=lambda r: f"{r['case']}-m{r['sdf_s_rms_slope']}-{r['material']}-"
                         f"{r['theta_i_deg']}-{r['theta_r_deg']}-{r['phi_r_deg']}")
def test_matches_scatmech_facet_model(rec):
    """Every element within 1e-7·M00 in both bases; exactly 0 where SCATMECH's M00 underflows to 0."""
    # Built exactly as `python -m engine mueller --model torrance_sparrow --param ...` builds it.
    model = make_model("torrance_sparrow", {"n": rec["n"], "k": rec["k"], "m": rec["sdf_s_rms_slope"],
                                            "shadowing": SHADOW[rec["shadow"]]})
    for key, basis in (("psps", "sp"), ("plane", "scattering")):
        out = mueller_at(model, rec["theta_i_deg"], rec["theta_r_deg"], rec["phi_r_deg"], 550.0, basis)
        assert out["delta"] is None
        ours = np.array(out["brdf"])
        ref = np.array(rec["M"][key])
        assert np.all(np.isfinite(ours))
        m00 = ref[0, 0]
        if m00 == 0.0:
            assert np.all(ours == 0.0), (key, ours)
        else:
            err = np.max(np.abs(ours - ref))
            assert err <= 1e-7 * m00, (key, err / m00)


def test_vcavity_shadowing_matches_scatmech_g_ts():
    """G_TS (given in every record, also where SCATMECH does not apply it), vectorised over all records."""
    dirs = [oracle_directions(r["theta_i_deg"], r["theta_r_deg"], r["phi_r_deg"]) for r in RECORDS]
    wi = np.array([d[0] for d in dirs]).T
    wo = np.array([d[1] for d in dirs]).T
    h, cos_f, ok = half_vector(wi, wo)
    assert ok.all()
    G = g_vcavity(wi, wo, h)
    ref = np.array([r["G_TS"] for r in RECORDS])
    np.testing.assert_allclose(G, ref, rtol=1e-10, atol=1e-15)
    alpha = np.degrees(np.arctan2(np.hypot(h[0], h[1]), h[2]))
    np.testing.assert_allclose(alpha, [r["alpha_deg"] for r in RECORDS], atol=1e-9)


# --- special functions and distributions -----------------------------------------------------------------


def test_erf_family_against_the_c_library():
    x = np.concatenate([np.linspace(-7.0, 7.0, 14001), np.logspace(-300, 1.3, 600), [0.0, 27.0, 1e5]])
    ref_c = np.array([math.erfc(v) for v in x])
    ref_e = np.array([math.erf(v) for v in x])
    got_c = erfc(x)
    pos = ref_c > 0
    assert np.max(np.abs(got_c[pos] - ref_c[pos]) / ref_c[pos]) < 1e-13
    assert np.all(got_c[~pos] == 0.0)
    nz = ref_e != 0
    assert np.max(np.abs(erf(x)[nz] - ref_e[nz]) / np.abs(ref_e[nz])) < 1e-14
    xs = np.linspace(0.0, 20.0, 2001)
    ref_x = np.array([math.erfc(v) * math.exp(v * v) for v in xs])
    assert np.max(np.abs(erfcx(xs) - ref_x) / ref_x) < 5e-13
    assert erfc(np.array([np.inf, -np.inf])).tolist() == [0.0, 2.0]
    y = np.concatenate([np.linspace(-0.999999, 0.999999, 4001), [0.0, 1e-300, -1e-10]])
    assert np.max(np.abs(erf(erfinv(y)) - y)) < 5e-15
    assert erfinv(np.array([1.0, -1.0])).tolist() == [np.inf, -np.inf]


def _slope_grid(m, lo, hi, n=160):
    """Gauss–Legendre nodes/weights over the slope square [lo, hi]×[−10m, 10m] → (h (3, K), weights·dω/dxdy)."""
    xs, wx = gauss_legendre(lo, hi, n // 16)
    ys, wy = gauss_legendre(-10.0 * m, 10.0 * m, n // 16)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    W = np.outer(wx, wy)
    h = np.stack((-X.ravel(), -Y.ravel(), np.ones(X.size)))
    h = h / np.sqrt(h[0] ** 2 + h[1] ** 2 + 1.0)
    return h, W.ravel() * h[2] ** 3  # dω_h = cos³θ_h dx dy


@pytest.mark.parametrize("m", [1e-3, 0.05, 0.3, 1.0, 5.0])
def test_beckmann_is_normalised_and_smith_g1_matches_its_definition(m):
    dist = Beckmann(m)
    h, w = _slope_grid(m, -10.0 * m, 10.0 * m)
    assert abs(np.sum(dist.D(h) * h[2] * w) - 1.0) < 1e-10
    assert dist.D(np.array([[0.0], [0.0], [1.0]]))[0] == pytest.approx(1.0 / (math.pi * m * m), rel=1e-15)
    for theta in (0.0, 10.0, 45.0, 75.0, 88.0, 89.9):
        wo = sph(theta, 0.0).reshape(3, 1)
        # ∫ max(0, ω_o·h) D(h) dω_h = cosθ_o / G1(ω_o): the integrand vanishes for slopes x > cotθ.
        cot = math.inf if theta == 0 else 1.0 / math.tan(math.radians(theta))
        h, w = _slope_grid(m, -10.0 * m, min(cot, 10.0 * m))
        proj = np.maximum(wo[:, 0] @ h, 0.0)
        integral = np.sum(proj * dist.D(h) * w)
        g1 = g1_beckmann_exact(wo, np.array([[0.0], [0.0], [1.0]]), m)[0]
        assert g1 == pytest.approx(wo[2, 0] / integral, rel=1e-8), theta
        # The visible-normal density is normalised.
        pdf = dist.pdf(np.tile(wo, (1, h.shape[1])), h)
        assert np.sum(pdf * w) == pytest.approx(1.0, abs=1e-8)


def test_rational_smith_g1_is_walters_approximation():
    th = np.radians(np.linspace(0.0, 89.999, 4000))
    w = np.stack((np.sin(th), np.zeros_like(th), np.cos(th)))
    up = np.tile([[0.0], [0.0], [1.0]], (1, th.size))
    for m in (0.05, 0.3, 1.0):
        exact = g1_beckmann_exact(w, up, m)
        approx = g1_beckmann_rational(w, up, m)
        assert np.max(np.abs(approx - exact) / exact) < 3.5e-3
        a = 1.0 / (m * np.tan(th[1:]))
        expect = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1 + 2.276 * a + 2.577 * a * a))
        np.testing.assert_allclose(approx[1:], expect, rtol=1e-14)
    # back side of the facet: zero
    assert g1_beckmann_rational(w[:, 10:11], -up[:, :1], 0.3)[0] == 0.0


@pytest.mark.parametrize("e", [0.0, 1.0, 20.0, 1000.0])
def test_blinn_is_normalised(e):
    dist = BlinnPhong(e)
    th, wt = gauss_legendre(0.0, 0.5 * math.pi, 64)
    h = np.stack((np.sin(th), np.zeros_like(th), np.cos(th)))
    total = np.sum(dist.D(h) * np.cos(th) * np.sin(th) * 2.0 * math.pi * wt)
    assert total == pytest.approx(1.0, abs=1e-9)
    assert BlinnPhong.from_beckmann_m(0.1).e == pytest.approx(198.0)


def test_distribution_underflow_is_exact_zero():
    h = np.array([[1.0, 1.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0], [1e-200, 0.0, -0.5, 1.0]])
    h = h / np.sqrt((h ** 2).sum(0))
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        D = Beckmann(1e-4).D(h)
        assert D[:3].tolist() == [0.0, 0.0, 0.0] and D[3] == pytest.approx(1 / (math.pi * 1e-8))
        assert np.all(np.isfinite(BlinnPhong(1e6).D(h)))


# --- physics checks (docs/physics.md §4) ---------------------------------------------------------------------

HARD_ANGLES = [0.0, 1e-7, 30.0, 89.99, 90.0]


@pytest.mark.parametrize("nk", [(1.5, 0.0), (0.47, 2.4), (0.3, 50.0), (1.0, 0.0)])
@pytest.mark.parametrize("m", [M_MIN, 0.05, 5.0])
@pytest.mark.parametrize("shadowing", ["ts", "smith", "smith_rational", "none"])
def test_degenerate_geometries_are_finite(nk, m, shadowing):
    """θ = 0, 89.99°, 90°, exact specular/backscatter, κ = 0 and 50, m = 1e-4 and 5: no NaN, no FP traps."""
    geoms = [oracle_directions(ti, to, ph) for ti in HARD_ANGLES for to in HARD_ANGLES for ph in (0.0, 90.0, 180.0)]
    wi = np.array([g[0] for g in geoms]).T
    wo = np.array([g[1] for g in geoms]).T
    n = wi.shape[1]
    sp = point(wo, lam=np.full((2, n), 550.0))
    rng = np.random.default_rng(7)
    for model in (TorranceSparrow(*nk, m, shadowing=shadowing),
                  TorranceSparrow(*nk, m, shadowing=shadowing, exterior_n=1.7, diffuse_albedo=0.5,
                                  diffuse_weight=0.5)):
        with np.errstate(divide="raise", invalid="raise", over="raise"):
            M = model.eval(sp, wi).matrix()
            p = model.pdf(sp, wi)
            samples = [model.sample(sp, np.full(n, ul), np.full((2, n), ud))
                       for ul, ud in ((0.05, 0.0), (0.5, 0.5), (0.95, 1.0 - 2 ** -53))]
            samples.append(model.sample(sp, rng.random(n), rng.random((2, n))))
        assert np.all(np.isfinite(M)) and np.all(np.isfinite(p)) and np.all(p >= 0)
        for s in samples:
            assert np.all(np.isfinite(s.weight.matrix())) and np.all(np.isfinite(s.pdf))
            assert np.all(np.isfinite(s.wi[:, s.valid]))
            assert not s.is_delta.any()
    # One-sided: nothing at θ = 90° or from behind.
    at90 = np.isclose(wi[2], 0.0) | np.isclose(wo[2], 0.0)
    assert np.all(M[..., at90] == 0.0)


angles = st.one_of(st.sampled_from([0.0, 1e-7, 45.0, 89.99, 90.0]), st.floats(0.0, 90.0))
phis = st.one_of(st.sampled_from([0.0, 90.0, 180.0]), st.floats(-180.0, 180.0))
roughness = st.one_of(st.sampled_from([M_MIN, 1e-3, 5.0]), st.floats(-4.0, math.log10(5.0)).map(lambda e: 10 ** e))
indices = st.one_of(st.sampled_from([(1.5, 0.0), (0.47, 2.4), (0.2, 50.0), (1.0, 0.0), (0.96, 6.69)]),
                    st.tuples(st.floats(0.05, 5.0), st.floats(0.0, 50.0)))
shadowings = st.sampled_from(["ts", "smith", "smith_rational", "none"])
kinds = st.sampled_from(["free", "specular", "backscatter"])


def _geometry(ti, to, po, kind):
    if kind == "specular":
        to, po = ti, 0.0
    elif kind == "backscatter":
        to, po = ti, 180.0
    return oracle_directions(ti, to, po)


@settings(max_examples=200, deadline=None)
@given(indices, roughness, angles, angles, phis, kinds, shadowings, st.sampled_from([1.0, 1.33, 2.0]),
       st.sampled_from([0.0, 0.4]))
def test_realisable_and_pure(nk, m, ti, to, po, kind, shadowing, exterior_n, d):
    wi, wo = _geometry(ti, to, po, kind)
    model = TorranceSparrow(nk[0], nk[1], m, shadowing=shadowing, exterior_n=exterior_n,
                            diffuse_albedo=0.7 if d else None, diffuse_weight=d)
    M = model.eval(point(wo), wi.reshape(3, 1)).matrix()
    assert np.all(np.isfinite(M))
    assert is_realisable(M).all()
    m00 = M[0, 0, 0, 0]
    assert m00 >= 0
    if d == 0.0:  # a single facet is a non-depolarising (Jones) element: tr(MᵀM) = 4 M00²
        assert abs(depolarisation_index_sq_excess(M)[0, 0]) <= 1e-9 * m00 * m00 + 1e-300


@settings(max_examples=200, deadline=None)
@given(indices, roughness, angles, angles, phis, shadowings, st.sampled_from([0.0, 0.4]))
def test_reciprocity(nk, m, ti, to, po, shadowing, d):
    """M00(ω_i, ω_o) = M00(ω_o, ω_i); in scattering-plane frames M_rev = Q Mᵀ Q (docs/physics.md §4)."""
    wi, wo = oracle_directions(ti, to, po)
    model = TorranceSparrow(nk[0], nk[1], m, shadowing=shadowing, diffuse_albedo=0.7, diffuse_weight=d)
    fwd = model.eval(point(wo), wi.reshape(3, 1))
    rev = model.eval(point(wi), wo.reshape(3, 1))
    a, b = fwd.A[0, 0], rev.A[0, 0]
    assert a == pytest.approx(b, rel=1e-12, abs=1e-300)
    k_i, k_o = -wi.reshape(3, 1), wo.reshape(3, 1)
    s = cross(k_i, k_o)
    length = math.sqrt(float(dot(s, s)[0]))
    if length < 1e-6:
        return  # scattering plane undefined (exact backscatter/grazing): M00 only
    s = s / length
    M = matrix_in_frames(fwd, s, k_i, s, k_o)[:, :, 0, 0]
    # Reversed path: k_i' = −ω_o, k_o' = ω_i, s' = unit(k_i' × k_o') = −s, p_in' = p_out.
    M_rev = matrix_in_frames(rev, -s, -k_o, -s, -k_i)[:, :, 0, 0]
    Q = np.diag([1.0, 1.0, 1.0, -1.0])
    np.testing.assert_allclose(M_rev, Q @ M.T @ Q, rtol=0, atol=1e-10 * max(a, 1e-300))


@settings(max_examples=100, deadline=None)
@given(st.floats(0.0, 89.9), st.floats(0.0, 89.9), phis, st.floats(-1.0, 1.0), st.floats(0.0, 2 * math.pi),
       roughness, shadowings)
def test_rotation_invariance(ti, to, po, cz, az, m, shadowing):
    """The same local geometry about an arbitrary shading normal gives the same matrix (in matching frames).

    (Exactly grazing directions are excluded: rotating them leaves cosθ = ±1e-17, on either side.)"""
    wi, wo = oracle_directions(ti, to, po)
    # A rotation R taking +z to n = (sinβ cos az, sinβ sin az, cz).
    sb = math.sqrt(max(0.0, 1.0 - cz * cz))
    nrm = np.array([sb * math.cos(az), sb * math.sin(az), cz])
    e1 = np.array([1.0, 0.0, 0.0]) if abs(nrm[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t = np.cross(nrm, e1)
    t /= np.linalg.norm(t)
    R = np.stack((t, np.cross(nrm, t), nrm), axis=1)  # columns: images of x, y, z
    model = TorranceSparrow(0.47, 2.4, m, shadowing=shadowing)
    ref = model.eval(point(wo), wi.reshape(3, 1))
    rot = model.eval(point(R @ wo, normal=nrm), (R @ wi).reshape(3, 1))
    M0 = ref.matrix()[:, :, 0, 0]
    M1 = matrix_in_frames(rot, R @ ref.x_in, -(R @ wi).reshape(3, 1), R @ ref.x_out, (R @ wo).reshape(3, 1))
    scale = max(M0[0, 0], 1e-300)
    np.testing.assert_allclose(M1[:, :, 0, 0], M0, rtol=0, atol=1e-7 * scale)


@pytest.mark.parametrize("nk", [(0.2, 50.0), (0.96, 6.69), (1.5, 0.0)], ids=["k50", "aluminium", "glass"])
@pytest.mark.parametrize("shadowing", ["ts", "smith"])
def test_energy_conservation(nk, shadowing):
    """Directional albedo ∫ M00 cosθ_o dω_o ≤ 1 (+1e-3) and above a trivial lower bound."""
    for m in (0.05, 0.3, 1.0):
        model = TorranceSparrow(*nk, m, shadowing=shadowing)
        for theta in (0.0, 30.0, 60.0, 80.0, 89.0):
            a = directional_albedo(model, theta, m)
            assert a <= 1.0 + 1e-3, (m, theta, a)
            if m == 0.05 and theta <= 60.0:  # narrow lobe, no shadowing: albedo ≈ F(θ_i)
                F = fresnel_reflection_mueller(math.cos(math.radians(theta)), complex(*nk))[0, 0]
                assert a == pytest.approx(F, rel=1e-2), (theta, a, F)


@pytest.mark.parametrize("nk", [(0.47, 2.4), (1.5, 0.0)])
@pytest.mark.parametrize("shadowing", ["ts", "smith"])
def test_small_roughness_limit_is_the_fresnel_mirror(nk, shadowing):
    """m = 1e-3: ∫ M cosθ_o dω_o over the lobe → M_F(θ_i) in the plane-of-incidence frames (within 1e-3)."""
    m = 1e-3
    model = TorranceSparrow(*nk, m, shadowing=shadowing)
    for theta in (0.0, 30.0, 60.0, 80.0):
        wi, wo, wts = lobe_quadrature(theta, m, full=True)
        n = wo.shape[1]
        v = model.eval(point(wo), tile(wi, n))
        # Frames that converge to the shared plane-of-incidence axis s0 = +y at the mirror direction.
        s0 = np.array([0.0, 1.0, 0.0])
        x_out = tile(s0, n) - (s0 @ wo) * wo
        x_out = x_out / np.sqrt((x_out ** 2).sum(0))
        M = matrix_in_frames(v, tile(s0, n), tile(-wi, n), x_out, wo)[:, :, 0, :]
        integral = np.sum(M * (np.maximum(wo[2], 0.0) * wts), axis=-1)
        MF = fresnel_reflection_mueller(math.cos(math.radians(theta)), complex(*nk))
        np.testing.assert_allclose(integral, MF, atol=1e-3, err_msg=f"theta={theta}")


# --- sampling ----------------------------------------------------------------------------------------------


SAMPLING_CASES = [
    # (θ_o, m, shadowing, diffuse weight, distribution, blinn exponent)
    (30.0, 0.05, "ts", 0.0, "beckmann", None),
    (75.0, 0.05, "smith", 0.0, "beckmann", None),
    (0.0, 0.8, "ts", 0.0, "beckmann", None),
    (60.0, 0.8, "smith", 0.0, "beckmann", None),
    (88.0, 0.3, "ts", 0.0, "beckmann", None),
    (45.0, 0.3, "ts", 0.6, "beckmann", None),
    (40.0, 0.8, "smith", 0.3, "beckmann", None),
    (50.0, 0.0, "ts", 0.0, "blinn", 30.0),
]


def _model_for(case, nk=(0.47, 2.4)):
    _, m, shadowing, d, dist, e = case
    return TorranceSparrow(*nk, max(m, M_MIN), shadowing=shadowing, diffuse_albedo=0.8 if d else None,
                           diffuse_weight=d, distribution=dist, blinn_exponent=e)


@pytest.mark.parametrize("case", SAMPLING_CASES, ids=lambda c: f"th{c[0]}-m{c[1]}-{c[2]}-d{c[3]}-{c[4]}")
def test_sampling_chi2(case):
    """sample() directions follow pdf(): chi-square over (cosθ, φ) cells (+ one cell for invalid samples)."""
    theta_o = case[0]
    model = _model_for(case)
    N = 100_000
    rng = np.random.default_rng(12345)
    wo = sph(theta_o, 0.0)
    sp = point(tile(wo, N))
    s = model.sample(sp, rng.random(N), rng.random((2, N)))
    assert np.all(s.wi[2, s.valid] > 0)
    result = chi2.direction_sampler_test(s.wi, s.valid, lambda wi: model.pdf(point(tile(wo, wi.shape[1])), wi),
                                         n_cos=24, n_phi=48, order=8)
    chi2.assert_accepted(result, test_count=len(SAMPLING_CASES), what="Torrance–Sparrow samples")


@pytest.mark.parametrize("case", SAMPLING_CASES[:: 2] + [SAMPLING_CASES[5]],
                         ids=lambda c: f"th{c[0]}-m{c[1]}-{c[2]}-d{c[3]}-{c[4]}")
def test_sample_weight_is_eval_cos_over_pdf(case):
    model = _model_for(case)
    N = 2000
    rng = np.random.default_rng(5)
    wo = sph(case[0], 30.0)
    lam = np.tile(np.array([[450.0], [550.0], [650.0]]), (1, N))
    sp = point(tile(wo, N), lam=lam)
    s = model.sample(sp, rng.random(N), rng.random((2, N)))
    v = s.valid
    assert v.mean() > 0.5
    f = model.eval(sp, s.wi)
    pdf = model.pdf(sp, s.wi)
    np.testing.assert_allclose(s.pdf[v], pdf[v], rtol=1e-12)
    assert np.all(pdf[v] > 0) and np.all(s.pdf[~v] == 0)
    W = matrix_in_frames(s.weight, f.x_in, -s.wi, f.x_out, tile(wo, N))[..., v]
    expect = f.matrix()[..., v] * (s.wi[2, v] / pdf[v])
    np.testing.assert_allclose(W, expect, rtol=1e-9, atol=1e-12 * np.abs(expect).max())
    assert np.all(s.weight.matrix()[..., ~v] == 0.0)


@pytest.mark.parametrize("case", [(30.0, 0.3, "smith", 0.0, "beckmann", None), (70.0, 0.8, "ts", 0.0, "beckmann", None),
                                  (45.0, 0.1, "ts", 0.5, "beckmann", None)],
                         ids=["smith-0.3", "ts-0.8", "ts-0.1-diffuse"])
def test_monte_carlo_albedo_matches_quadrature(case):
    """Mean of the sample weights' M00 (estimates ∫ f cosθ_i dω_i for fixed ω_o) equals the quadrature albedo
    (∫ f cosθ_o dω_o for fixed ω_i, by reciprocity) within 5σ."""
    theta, m = case[0], case[1]
    model = _model_for(case, nk=(0.96, 6.69))
    N = 100_000
    rng = np.random.default_rng(99)
    s = model.sample(point(tile(sph(theta, 0.0), N)), rng.random(N), rng.random((2, N)))
    w = s.weight.matrix()[0, 0, 0]   # M00 (the depolarising part included)
    mc, err = w.mean(), w.std() / math.sqrt(N)
    spec = TorranceSparrow(0.96, 6.69, m, shadowing=case[2])
    quad = directional_albedo(spec, theta, m)
    if case[3]:
        quad += case[3] * 0.8  # the Lambert term integrates to d·ρ
    assert abs(mc - quad) < 5 * err + 2e-4, (mc, quad, err)


# --- spectral plumbing, flags, validation ----------------------------------------------------------------


def test_per_wavelength_values_use_the_spectra():
    n_au, k_au = named_ior("Au")
    lams = np.array([420.0, 550.0, 700.0])
    model = TorranceSparrow(n_au, k_au, 0.2, diffuse_albedo=ConstantSpectrum(0.3), diffuse_weight=0.2)
    wi, wo = oracle_directions(35.0, 50.0, 20.0)
    v = model.eval(point(wo, lam=lams.reshape(3, 1)), wi.reshape(3, 1))
    for j, lam in enumerate(lams):
        ref = TorranceSparrow(float(n_au.eval(lam)), float(k_au.eval(lam)), 0.2, diffuse_albedo=0.3,
                              diffuse_weight=0.2).eval(point(wo, lam=lam), wi.reshape(3, 1))
        for name in "ABCS":
            assert getattr(v, name)[j, 0] == pytest.approx(getattr(ref, name)[0, 0], rel=1e-14)
    assert len({round(float(v.A[j, 0]), 9) for j in range(3)}) == 3  # gold is coloured


def test_flags_and_validation():
    assert TorranceSparrow(1.5, 0.0, 0.1).creates_circular is False
    assert TorranceSparrow(0.47, 2.4, 0.1).creates_circular is True
    assert TorranceSparrow(1.5, 0.0, 0.1, exterior_n=2.0).creates_circular is True  # internal: TIR retards
    model = TorranceSparrow(1.5, 0.0, 0.1)
    assert model.name == "torrance_sparrow" and not model.delta_only and model.polarising
    assert model.delta_reflection(point(sph(10.0, 0.0))) is None
    assert model.describe()["m"] == 0.1
    for bad in (dict(m=0.0), dict(m=M_MIN / 2), dict(m=float("nan")), dict(shadowing="cook"),
                dict(distribution="phong"), dict(exterior_n=0.0), dict(specular_weight=-1.0),
                dict(distribution="blinn", m=2.0), dict(distribution="ggx", shadowing="smith_rational"),
                dict(multiscatter=True), dict(distribution="ggx", shadowing="ts", multiscatter=True),
                dict(distribution="ggx", m=1.5, multiscatter=True)):
        kw = dict(n=1.5, k=0.0, m=0.1)
        kw.update(bad)
        with pytest.raises(ValueError):
            TorranceSparrow(**kw)


def test_diffuse_part_is_a_pure_depolariser():
    # A Lambertian part adds ρ/π to M00 only; with the facet part off the matrix is (ρ/π)·diag(1,0,0,0),
    # and with it on, M − M_facet is that depolariser (not ρ/π on M11 too).
    diffuse_only = TorranceSparrow(0.47, 2.4, 0.3, diffuse_albedo=0.6, diffuse_weight=1.0, specular_weight=0.0)
    both = TorranceSparrow(0.47, 2.4, 0.3, diffuse_albedo=0.6, diffuse_weight=1.0)
    facet = TorranceSparrow(0.47, 2.4, 0.3)
    for geometry in ((30, 40, 20), (60, 10, 170)):
        M = np.array(mueller_at(diffuse_only, *geometry, 550.0, "sp")["brdf"])
        np.testing.assert_allclose(M, np.diag([0.6 / np.pi, 0, 0, 0]), atol=1e-15)
        diff = np.array(mueller_at(both, *geometry, 550.0, "sp")["brdf"]) - \
            np.array(mueller_at(facet, *geometry, 550.0, "sp")["brdf"])
        np.testing.assert_allclose(diff, np.diag([0.6 / np.pi, 0, 0, 0]), atol=1e-12)


def test_roughness_zero_is_the_smooth_limit():
    """m = 0 is the Fresnel mirror (plus the Lambertian part), not an error (robustness issue)."""
    for params in ({"n": 0.47, "k": 2.4}, {"metal": "Au"}):
        model = make_model("torrance_sparrow", {**params, "m": 0})
        mirror = make_model("fresnel", params)
        for ti in (0.0, 30.0, 89.99):
            a = mueller_at(model, ti, ti, 0.0, 550.0, "sp")
            b = mueller_at(mirror, ti, ti, 0.0, 550.0, "sp")
            np.testing.assert_allclose(a["delta"], b["delta"], atol=1e-15)
            assert np.all(np.array(a["brdf"]) == 0)
    with_diffuse = make_model("torrance_sparrow", {"n": 1.5, "m": 0, "diffuse_albedo": 0.5, "diffuse_weight": 1})
    out = mueller_at(with_diffuse, 30, 50, 100, 550.0, "sp")
    np.testing.assert_allclose(out["brdf"], np.diag([0.5 / np.pi, 0, 0, 0]), atol=1e-15)
    # Sampling the mixture: weights average to the directional albedo F(θ_o) + ρ (energy bookkeeping).
    N = 200_000
    rng = np.random.default_rng(3)
    s = with_diffuse.sample(point(tile(sph(40.0, 0.0), N)), rng.random(N), rng.random((2, N)))
    total = s.weight.matrix()[0, 0, 0].mean()
    from engine.polarisation.fresnel import fresnel_reflectance
    expected = fresnel_reflectance(np.cos(np.radians(40.0)), 1.5) + 0.5
    assert abs(total - expected) <= 1e-9 + 5 * s.weight.matrix()[0, 0, 0].std() / np.sqrt(N)
    # below the smooth limit (engine.materials.roughness.SMOOTH_LIMIT = 1e-4) is the same smooth limit; the class
    # itself refuses a slope below the least one (its guard for direct use)
    assert make_model("torrance_sparrow", {"n": 1.5, "m": 5e-5}).describe() == make_model("torrance_sparrow",
                                                                                          {"n": 1.5, "m": 0}).describe()
    with pytest.raises(ValueError):
        TorranceSparrow(1.5, 0.0, 5e-5)


@pytest.mark.parametrize("distribution, shadowing", [("ggx", "smith_correlated"), ("beckmann", "ts")])
def test_index_albedo_tables_interpolate_the_exact_table_within_2e_3(distribution, shadowing):
    """A real index per point (the Principled dielectric under a per-point Specular IOR Level): the lobe's
    albedo from tables at 17 indices evenly spaced in F0^¼, linear in it, against the table at each exact index
    (near η = 1 too: a Specular IOR Level near 0)."""
    from engine.materials.torrance_sparrow import IndexAlbedoTables, SpecularAlbedoTable
    family = IndexAlbedoTables(1.0001, 2.4, 0.05, 0.6, shadowing, distribution)
    rng = np.random.default_rng(17)
    for eta in np.concatenate([rng.uniform(1.0001, 1.1, 5), rng.uniform(1.0001, 2.4, 7)]):
        cos_o = rng.uniform(0.02, 1.0, 64)
        m = rng.uniform(0.05, 0.6, 64)
        exact = SpecularAlbedoTable(complex(eta), 0.05, 0.6, shadowing, distribution)(cos_o, m)
        got = family(cos_o, m, np.full(64, eta))
        assert np.max(np.abs(got - exact)) < 2e-3, eta
    # at a node it is that node's table exactly; below 1 the reciprocal side
    node = family.tables[3]
    eta3 = family._eta_of(family.root_f0[3])
    np.testing.assert_allclose(family(np.linspace(0, 1, 9), 0.2, np.full(9, eta3)), node(np.linspace(0, 1, 9), 0.2),
                               rtol=1e-9, atol=1e-12)
    inside = IndexAlbedoTables(0.5, 0.9, 0.1, 0.1, shadowing, distribution)
    assert all(inside._eta_of(f) < 1 for f in inside.root_f0)
    with pytest.raises(ValueError, match="one side of 1"):
        IndexAlbedoTables(0.8, 1.2, 0.1, 0.1, shadowing, distribution)
