"""Multiple-scattering energy compensation of the GGX lobes (engine.materials.ggx_energy; Cycles'
"Multiscatter GGX"): Torrance–Sparrow with GGX facets and the rough dielectric with ``multiscatter``.

Oracles: white furnaces by an independent quadrature of eval() over the sphere (a white conductor and a
clear interface must return all the light: 1 within the table error, the single-scattering lobes less);
Cycles' own albedo tables at a few nodes (the height-correlated tables are the same integrals); the
single-scattering Mueller matrix plus a non-negative depolariser (realisable, polarisation untouched);
weight = f·|cosθ_i|/pdf and the chi-square of the new GGX Torrance–Sparrow sampler; finite values at
every edge (normal and grazing incidence, α = 1e-4 and 1, indices near 1 and huge)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from engine.errors import SceneError
from engine.materials import ggx_energy
from engine.materials.base import ShadingPoint
from engine.materials.catalogue import make_model
from engine.materials.rough_dielectric import RoughDielectric
from engine.materials.torrance_sparrow import TorranceSparrow
from engine.polarisation.fresnel import fresnel_reflectance
from engine.polarisation.mueller import is_realisable
from engine.scene.loader import parse_material
from tests.materials.test_rough_dielectric import sphere_quadrature
from tests.support import chi2

ALPHAS = (0.1, 0.25, 0.5, 0.75, 1.0)


def point(wo, lam=550.0):
    n = wo.shape[1]
    nrm = np.tile(np.array([[0.0], [0.0], [1.0]]), (1, n))
    return ShadingPoint(np.zeros((3, n)), nrm, nrm, wo, np.full((1, n), lam))


def sph(theta_deg, phi_deg=0.0, inside=False):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), (-1.0 if inside else 1.0) * math.cos(t)])


def tile(v, n):
    return np.tile(np.asarray(v, dtype=np.float64).reshape(3, 1), (1, n))


def conductor_white(alpha, multiscatter=True, shadowing="smith_correlated"):
    """F ≡ 1 up to 1e-16: κ = 1e8."""
    return TorranceSparrow(1.0, 1e8, alpha, distribution="ggx", shadowing=shadowing, multiscatter=multiscatter)


def energy(model, wo, axes, eta=1.0):
    """∫ M00 |cosθ_i| dω over the sphere (η²× on the far side: energy, not radiance), by polar quadratures
    about each lobe axis, every node assigned to its nearest axis (independent of the sampler)."""
    total = 0.0
    for k, axis in enumerate(axes):
        v, W = sphere_quadrature(axis, n_phi=192, panels=40)
        nearest = np.argmax(np.array([np.asarray(a) @ v for a in axes]), axis=0) == k
        v, W = v[:, nearest], W[nearest]
        val = model.eval(point(tile(wo, v.shape[1])), v)
        m00 = val.A[0] + (0.0 if val.depol is None else val.depol[0])
        scale = np.where(v[2] * wo[2] < 0, eta * eta, 1.0)
        total += np.sum(m00 * np.abs(v[2]) * W * scale)
    return total


def refraction_axis(wo, eta):
    """The macro refraction direction of wo (local frame, either side), or −wo under TIR."""
    c = abs(wo[2])
    s2 = (1.0 - c * c) / eta ** 2
    if s2 >= 1.0:
        return -wo
    nz = np.array([0.0, 0.0, math.copysign(1.0, wo[2])])
    return -wo / eta + (c / eta - math.sqrt(1.0 - s2)) * nz


# --- white furnaces -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("shadowing", ["smith_correlated", "smith"])
@pytest.mark.parametrize("alpha", ALPHAS)
def test_white_conductor_furnace_returns_all_the_light(alpha, shadowing):
    """F = 1: the compensated lobe's albedo is 1 within 1e-2 at every view angle; the single-scattering lobe's
    is below (by 0.03 at α = 0.1 … 0.7 at α = 1)."""
    for theta in (0.0, 30.0, 60.0, 75.0, 85.0):
        wo = sph(theta, 15.0)
        mirror = wo * np.array([-1.0, -1.0, 1.0])
        e_ms = energy(conductor_white(alpha, True, shadowing), wo, [mirror])
        e_ss = energy(conductor_white(alpha, False, shadowing), wo, [mirror])
        assert e_ms == pytest.approx(1.0, abs=1e-2), (theta, e_ms)
        assert e_ss < e_ms - 1e-3, (theta, e_ss, e_ms)


CLEAR_CASES = [(n, a, th, inside) for n in (1.5, 1.0 / 1.5) for a in (0.1, 0.5, 1.0) for th in (0.0, 40.0, 75.0)
               for inside in (False, True)]


@pytest.mark.parametrize("n,alpha,theta,inside", CLEAR_CASES)
def test_clear_rough_dielectric_furnace_returns_all_the_light(n, alpha, theta, inside):
    """Reflection + η²·transmission (the energy; η² undoes the radiance scaling in f_t) is 1 within 1e-2 from
    either side, total internal reflection included; the single-scattering lobes lose energy."""
    wo = sph(theta, 20.0, inside)
    eta = n if not inside else 1.0 / n
    axes = [wo * np.array([-1.0, -1.0, 1.0]), refraction_axis(wo, eta)]
    if np.allclose(axes[0], axes[1]):
        axes = axes[:1]
    e_ms = energy(RoughDielectric(n, alpha, "ggx", multiscatter=True), wo, axes, eta)
    e_ss = energy(RoughDielectric(n, alpha, "ggx"), wo, axes, eta)
    assert e_ms == pytest.approx(1.0, abs=1e-2), e_ms
    assert e_ss <= e_ms + 1e-9


def test_tables_reproduce_cycles_albedo_tables_at_their_nodes():
    """The height-correlated F = 1 table is the integral Cycles tabulates by Monte Carlo (2²³ samples per node,
    intern/cycles/scene/shader.tables, table_ggx_E / table_ggx_Eavg, roughness r = √α on 32 nodes, μ on 32):
    a few of its values, to 5e-4; and one node of its glass table (ior = 1.5569 from outside, r = 8/15)."""
    cycles_E = {(1.0, 1.0): 0.306853, (10 / 31, 15 / 31): 0.846089, (10 / 31, 5 / 31): 0.995917,
                (1 / 31, 31 / 31): 0.888202, (1e-4, 1.0): 0.999079}
    for (mu, r), value in cycles_E.items():
        assert ggx_energy.ggx_albedo([mu], r * r, correlated=True)[0] == pytest.approx(value, abs=5e-4)
    cycles_Eavg = {31 / 31: 0.409137, 15 / 31: 0.893209, 5 / 31: 0.997199}
    for r, value in cycles_Eavg.items():
        assert ggx_energy.conductor_average(r * r, correlated=True) == pytest.approx(value, abs=2e-3)
    glass = {1.0: 0.988597, 2 / 15: 0.906730, 8 / 15: 0.956000}
    for mu, value in glass.items():
        assert ggx_energy.ggx_albedo([mu], (8 / 15) ** 2, 1.5569, correlated=True)[0] == pytest.approx(value, abs=5e-4)


def test_blender_glass_compensates_its_dense_side_as_cycles_inv_table():
    """Cycles' ggx_glass_inv_E (light inside the glass; α = 1, η = 1/1.557: 0.732, 0.623, 0.519 at μ = 1/15, 2/15,
    5/15, docs/physics.md) counts refracted directions that end on the viewer's side, which its BSDF never
    produces (its albedo there: 0.548, 0.519, 0.502).  ggx_albedo with ``viewer_side_refraction`` is that table;
    compensate_dense_side_as_cycles makes a rough interface seen from inside return E_true/E_counted, what Cycles'
    returns, and leaves the outside and the energy-conserving default (scene files) alone."""
    mu = np.array([1 / 15, 2 / 15, 5 / 15])
    counted = ggx_energy.ggx_albedo(mu, 1.0, 1 / 1.557, correlated=True, viewer_side_refraction=True)
    true = ggx_energy.ggx_albedo(mu, 1.0, 1 / 1.557, correlated=True)
    np.testing.assert_allclose(counted, [0.732, 0.623, 0.519], atol=1.5e-3)
    np.testing.assert_allclose(true, [0.548, 0.519, 0.502], atol=1.5e-3)
    own = RoughDielectric(1.557, 1.0, "ggx", multiscatter=True)
    cycles = RoughDielectric(1.557, 1.0, "ggx", multiscatter=True)
    cycles.compensate_dense_side_as_cycles()
    inside = np.zeros(3, bool)
    E_own = ggx_energy.ggx_albedo(mu, 1.0, 1 / 1.557)           # the lobe's own albedo (separable G)
    # the interface's albedo seen from inside, E_lobe/E_table: 1 by default, Cycles' E_true/E_counted
    np.testing.assert_allclose(E_own / own._energy(mu, inside), 1.0, atol=2e-3)
    np.testing.assert_allclose(E_own / cycles._energy(mu, inside), true / counted, rtol=2e-3)
    assert np.all(true / counted < 0.99)
    outside = np.ones(3, bool)
    np.testing.assert_array_equal(cycles._energy(mu, outside), own._energy(mu, outside))


def test_conductor_table_interpolation_and_quadrature_accuracy():
    """The 33 × 33 (√μ, √α) table against the direct quadrature at random points (μ ≥ 0.05) and the 96 × 96
    disk rule against a 4× finer one."""
    rng = np.random.default_rng(3)
    mu, alpha = rng.uniform(0.05, 1.0, 200), rng.uniform(0.01, 1.0, 200) ** 2
    for correlated in (False, True):
        err = ggx_energy.conductor_albedo(mu, alpha, correlated) - ggx_energy.ggx_albedo(mu, alpha,
                                                                                           correlated=correlated)
        assert np.abs(err).max() < 5e-3 and np.sqrt(np.mean(err ** 2)) < 1.5e-3


def test_f82_average_fresnel_is_cycles_fit():
    """F_ss of Cycles' fresnel_conductor_Fss: F0 + (1 − F0)/21 − b/126 with b from F0 and F(1/7); F = 1 → 1;
    within 0.02 of the exact ∫2μF dμ for a dielectric and metals (the fit's own error)."""
    assert ggx_energy.f82_average_fresnel(np.array([1.0 + 1e8j]))[0] == pytest.approx(1.0, abs=1e-12)
    x, w = np.polynomial.legendre.leggauss(400)
    mu, w = 0.5 * (x + 1.0), 0.5 * w
    for eta in (1.5 + 0j, 0.2 + 3.0j, 1.5 + 1.0j, 0.47 + 2.4j, 2.9 + 3.0j):
        exact = np.sum(w * 2.0 * mu * fresnel_reflectance(mu, eta))
        assert ggx_energy.f82_average_fresnel(np.array([eta]))[0] == pytest.approx(exact, abs=2e-2)
    # by hand from Cycles' formula: F0, F82 → b → F_ss
    eta = 1.5 + 1.0j
    F0, F82 = fresnel_reflectance(1.0, eta), fresnel_reflectance(1.0 / 7.0, eta)
    f = 6.0 / 7.0
    b = 7.0 / f ** 6 * (F0 + (1.0 - F0) * f ** 5 - F82)
    assert ggx_energy.f82_average_fresnel(np.array([eta]))[0] == pytest.approx(F0 + (1 - F0) / 21 - b / 126,
                                                                               rel=1e-12)


def test_conductor_compensation_is_cycles_formula():
    """S0 of the compensated conductor is (1 + F_ms(1 − E)/E)·S0 of the single-scattering lobe, F_ms =
    F_ss·E_avg/(1 − F_ss(1 − E_avg)) (Cycles' microfacet_ggx_preserve_energy), point by point."""
    rng = np.random.default_rng(2)
    N = 500
    wo = rng.normal(size=(3, N))
    wo[2] = np.abs(wo[2])
    wo /= np.linalg.norm(wo, axis=0)
    wi = rng.normal(size=(3, N))
    wi[2] = np.abs(wi[2])
    wi /= np.linalg.norm(wi, axis=0)
    for alpha in (0.3, 1.0):
        ms = TorranceSparrow(1.5, 1.0, alpha, distribution="ggx", multiscatter=True).eval(point(wo), wi)
        ss = TorranceSparrow(1.5, 1.0, alpha, distribution="ggx").eval(point(wo), wi)
        for name in "ABCS":          # the single-scattering matrix is untouched
            np.testing.assert_array_equal(getattr(ms, name), getattr(ss, name))
        E = ggx_energy.conductor_albedo(wo[2], alpha, True)
        E_avg = ggx_energy.conductor_average(alpha, True)
        Fss = ggx_energy.f82_average_fresnel(np.array([1.5 + 1.0j]))[0]
        Fms = Fss * E_avg / (1.0 - Fss * (1.0 - E_avg))
        np.testing.assert_allclose(ms.A[0] + ms.depol[0], ss.A[0] * (1.0 + Fms * (1.0 - E) / E), rtol=1e-12)


# --- polarisation: realisable, single scattering untouched -------------------------------------------------


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


DIRECTION = st.tuples(*(st.floats(-1.0, 1.0) for _ in range(3))).filter(lambda v: 1e-3 < np.linalg.norm(v))


@settings(deadline=None, max_examples=60, suppress_health_check=[HealthCheck.too_slow])
@given(wo=DIRECTION, wi=DIRECTION, alpha=st.floats(1e-4, 1.0), n=st.floats(0.05, 20.0), k=st.floats(0.0, 20.0),
       correlated=st.booleans())
def test_conductor_matrices_are_realisable(wo, wi, alpha, n, k, correlated):
    wo, wi = _unit(wo), _unit(wi)
    wo[2], wi[2] = abs(wo[2]), abs(wi[2])
    model = TorranceSparrow(n, k, alpha, distribution="ggx", multiscatter=True,
                            shadowing="smith_correlated" if correlated else "smith")
    v = model.eval(point(wo[:, None]), wi[:, None])
    M = v.matrix()[:, :, 0, 0]
    assert np.all(np.isfinite(M)) and np.all(v.depol >= 0)
    if M[0, 0] > 0:
        assert is_realisable((M / M[0, 0])[:, :, None])[0]


@settings(deadline=None, max_examples=60, suppress_health_check=[HealthCheck.too_slow])
@given(wo=DIRECTION, wi=DIRECTION, alpha=st.floats(1e-4, 1.0), n=st.floats(0.3, 4.0))
# found by hypothesis: both directions at grazing, cosθ_i·cosθ_o underflowing to 0 gave 0/0 (NaN); now f = 0
@example(wo=(0.0, 1.0, 6.645049782996298e-290), wi=(0.0, 1.0, 6.645049782996298e-290), alpha=1.0, n=1.0)
def test_dielectric_matrices_are_realisable(wo, wi, alpha, n):
    wo, wi = _unit(wo), _unit(wi)
    model = RoughDielectric(n, alpha, "ggx", multiscatter=True)
    v = model.eval(point(wo[:, None]), wi[:, None])
    M = v.matrix()[:, :, 0, 0]
    assert np.all(np.isfinite(M)) and np.all(v.depol >= 0)
    if M[0, 0] > 0:
        assert is_realisable((M / M[0, 0])[:, :, None])[0]
        # the compensation is depolarised: the degree of polarisation of unpolarised light scattered once,
        # |M10|/M00, only shrinks
        ss = RoughDielectric(n, alpha, "ggx").eval(point(wo[:, None]), wi[:, None]).matrix()[:, :, 0, 0]
        assert abs(M[1, 0]) / M[0, 0] <= abs(ss[1, 0]) / ss[0, 0] + 1e-12


# --- sampling ----------------------------------------------------------------------------------------------


def _models():
    return [TorranceSparrow(0.2, 3.0, 0.3, distribution="ggx", multiscatter=True),
            TorranceSparrow(1.5, 1.0, 1.0, distribution="ggx", shadowing="smith", multiscatter=True),
            TorranceSparrow(0.2, 3.0, 0.6, distribution="ggx", multiscatter=True, diffuse_albedo=0.5,
                            diffuse_weight=1.0),
            RoughDielectric(1.5, 0.4, "ggx", multiscatter=True), RoughDielectric(1.0 / 1.33, 1.0, "ggx",
                                                                                multiscatter=True)]


@pytest.mark.parametrize("k", range(5))
def test_sample_weight_is_eval_cos_over_pdf(k):
    model = _models()[k]
    N = 3000
    rng = np.random.default_rng(11 + k)
    wo = rng.normal(size=(3, N))
    wo[2] = np.abs(wo[2])
    wo /= np.linalg.norm(wo, axis=0)
    for side in (1.0, -1.0) if isinstance(model, RoughDielectric) else (1.0,):
        w = wo * np.array([[1.0], [1.0], [side]])
        sp = point(w)
        s = model.sample(sp, rng.random(N), rng.random((2, N)))
        v = s.valid
        assert v.sum() > N // 3
        f = model.eval(sp, s.wi).matrix()[:, :, 0, v] * (np.abs(s.wi[2, v]) / s.pdf[v])
        np.testing.assert_allclose(s.weight.matrix()[:, :, 0, v], f, rtol=1e-10, atol=1e-13)
        np.testing.assert_allclose(model.pdf(sp, s.wi)[v], s.pdf[v], rtol=1e-10)
        assert np.all(s.weight.depol[0, v] >= 0)


TS_SAMPLING = [(0.05, 20.0), (0.4, 60.0), (1.0, 0.0), (0.7, 80.0)]


@pytest.mark.parametrize("alpha,theta", TS_SAMPLING)
def test_ggx_torrance_sparrow_sampling_chi2(alpha, theta):
    """Visible-normal GGX samples reflected about the facet follow pdf() (compensation leaves it unchanged)."""
    model = TorranceSparrow(0.2, 3.0, alpha, distribution="ggx", multiscatter=True)
    N = 100_000
    rng = np.random.default_rng(7)
    wo = sph(theta, 10.0)
    s = model.sample(point(tile(wo, N)), rng.random(N), rng.random((2, N)))
    result = chi2.direction_sampler_test(s.wi, s.valid, lambda wi: model.pdf(point(tile(wo, wi.shape[1])), wi),
                                         n_cos=48, n_phi=48, order=8, sub=2)
    chi2.assert_accepted(result, test_count=len(TS_SAMPLING), what="GGX Torrance–Sparrow samples")


# --- edges --------------------------------------------------------------------------------------------------


EDGE_DIRECTIONS = np.stack([_unit(d) for d in ([0, 0, 1.0], [1, 0, 0.0], [1, 0, 1e-9], [0.6, 0, 0.8],
                                               [0.6, 0, -0.8], [1, 0, -1e-12], [0, 0, -1.0])], axis=1)


@pytest.mark.parametrize("alpha", [1e-4, 1e-2, 1.0])
def test_every_output_is_finite_at_the_edges(alpha):
    models = [TorranceSparrow(n, k, alpha, distribution="ggx", shadowing=sh, multiscatter=True)
              for n, k in ((1.0, 1e8), (0.2, 3.0), (1.5, 0.0), (1e6, 0.0), (1.0001, 0.0))
              for sh in ("smith_correlated", "smith")]
    models += [RoughDielectric(n, alpha, "ggx", multiscatter=True) for n in (1.5, 1 / 1.5, 1.0001, 0.9999, 1e6, 1e-3)]
    rng = np.random.default_rng(0)
    K = EDGE_DIRECTIONS.shape[1]
    with np.errstate(all="raise"):
        for model in models:
            for i in range(K):
                sp = point(np.repeat(EDGE_DIRECTIONS[:, i:i + 1], K, axis=1))
                v = model.eval(sp, EDGE_DIRECTIONS)
                s = model.sample(sp, rng.random(K), rng.random((2, K)))
                assert np.all(np.isfinite(v.matrix())) and np.all(np.isfinite(model.pdf(sp, EDGE_DIRECTIONS)))
                assert np.all(np.isfinite(s.weight.matrix())) and np.all(np.isfinite(s.pdf))
                assert np.all(v.depol >= 0)


def test_textured_roughness_is_the_constant_model_per_texel(tmp_path):
    from tests.scene.test_textures import _points_at, _shading_points, _texture_file
    m_values = np.array([[0.05, 0.2, 0.45], [0.8, 0.12, 1.0]])
    name = _texture_file(tmp_path, m_values)
    mat = parse_material({"type": "torrance_sparrow", "metal": "Au", "distribution": "ggx", "multiscatter": True,
                          "m": {"texture": name, "interpolation": "Closest"}}, "materials.ts", base_dir=str(tmp_path))
    assert mat.varies_over_surface and mat.multiscatter
    H, W = m_values.shape
    jj, ii = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    uv = np.stack((((ii + 0.5) / W).ravel(), ((jj + 0.5) / H).ravel()))
    texel = m_values[::-1].astype(np.float32).astype(np.float64)[jj, ii].ravel()
    reps = 30
    uv, texel = np.repeat(uv, reps, axis=1), np.repeat(texel, reps)
    n = uv.shape[1]
    rng = np.random.default_rng(5)
    sp = _shading_points(n, rng, _points_at(uv))
    wi = rng.normal(size=(3, n))
    wi[2] = np.abs(wi[2])
    wi /= np.linalg.norm(wi, axis=0)
    u_lobe, u_dir = rng.uniform(size=n), rng.uniform(size=(2, n))
    f = mat.eval(sp, wi).matrix()
    s = mat.sample(sp, u_lobe, u_dir)
    for m in np.unique(texel):
        sel = np.nonzero(texel == m)[0]
        const = TorranceSparrow(mat.n, mat.k, m, distribution="ggx", multiscatter=True)
        sub = sp.take(sel)
        sub.surface = None
        np.testing.assert_allclose(f[..., sel], const.eval(sub, wi[:, sel]).matrix(), rtol=1e-13, atol=0)
        cs = const.sample(sub, u_lobe[sel], u_dir[:, sel])
        np.testing.assert_allclose(s.wi[:, sel], cs.wi, rtol=0, atol=1e-14)
        np.testing.assert_allclose(s.weight.matrix()[..., sel], cs.weight.matrix(), rtol=1e-12, atol=0)


# --- scene format and defaults -------------------------------------------------------------------------------


def test_scene_format_and_validation():
    ts = parse_material({"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": 0.5, "distribution": "ggx",
                         "multiscatter": True}, "x")
    assert ts.multiscatter and ts.shadowing == "smith_correlated" and ts.describe()["multiscatter"] is True
    flat = make_model("torrance_sparrow", {"n": "0.2", "k": "3", "m": "0.5", "distribution": "ggx",
                                           "multiscatter": "true"})
    assert flat.describe() == ts.describe()
    glass = parse_material({"type": "rough_dielectric", "n": 1.5, "alpha": 0.3, "distribution": "ggx",
                            "multiscatter": True}, "x")
    assert glass.multiscatter and glass.describe()["multiscatter"] is True
    # off by default: nothing in describe() (scene fingerprints unchanged), no depolarised term
    for plain in (parse_material({"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": 0.5}, "x"),
                  parse_material({"type": "rough_dielectric", "n": 1.5, "alpha": 0.3}, "x")):
        assert "multiscatter" not in plain.describe() and not plain.multiscatter
        assert plain.eval(point(sph(30.0)[:, None]), sph(40.0, 180.0)[:, None]).depol is None
    bad = [({"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": 0.5, "multiscatter": True}, "x.multiscatter"),
           ({"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": 0.5, "distribution": "ggx", "shadowing": "ts",
             "multiscatter": True}, "x.multiscatter"),
           ({"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": 1.5, "distribution": "ggx", "multiscatter": True},
            "x.m"),
           ({"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": 0.5, "distribution": "ggx",
             "shadowing": "smith_rational"}, "x.shadowing"),
           ({"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": 0.5, "multiscatter": 1}, "x.multiscatter"),
           ({"type": "rough_dielectric", "n": 1.5, "alpha": 0.3, "multiscatter": True}, "x.multiscatter"),
           ({"type": "rough_dielectric", "n": 1.5, "alpha": 2.0, "distribution": "ggx", "multiscatter": True},
            "x.alpha")]
    for data, field in bad:
        with pytest.raises(SceneError) as err:
            parse_material(data, "x")
        assert err.value.field == field, data
    # the smooth limits ignore the option (nothing to compensate)
    assert not isinstance(parse_material({"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": 0,
                                          "distribution": "ggx", "multiscatter": True}, "x"), TorranceSparrow)
    assert parse_material({"type": "rough_dielectric", "n": 1.5, "alpha": 0, "distribution": "ggx",
                           "multiscatter": True}, "x").name == "dielectric"


def test_tables_are_cached_on_disk(tmp_path, monkeypatch):
    """Built once per engine source (engine.materials.table_cache); a second process reads the bits."""
    from engine.materials import table_cache
    monkeypatch.setenv("POLAR_KERNEL_CACHE", str(tmp_path))
    monkeypatch.setattr(table_cache, "cache_base", lambda: str(tmp_path))
    ggx_energy.conductor_tables.cache_clear()
    ggx_energy._dielectric_table.cache_clear()
    try:
        built = ggx_energy.conductor_tables(True).copy()
        ggx_energy._dielectric_table(1.5, 0.3)
        files = sorted(p.name for p in (tmp_path / "tables").rglob("*.npy"))
        assert any(f.startswith("ggx_conductor_albedo") for f in files)
        assert any(f.startswith("ggx_dielectric_albedo") for f in files)
        ggx_energy.conductor_tables.cache_clear()
        np.testing.assert_array_equal(ggx_energy.conductor_tables(True), built)
    finally:
        ggx_energy.conductor_tables.cache_clear()
        ggx_energy._dielectric_table.cache_clear()


def test_layering_estimate_reproduces_cycles_gen_schlick_table():
    """Cycles' estimate of a dielectric layer's albedo, F0 + (1 − F0)·s with s its ggx_gen_schlick_ior_s table read
    trilinearly on 16 nodes (kernel/closure/bsdf_microfacet.h, bsdf_microfacet_estimate_albedo): s for IOR 1.5 at
    r = √α ∈ {0, 0.25, 0.5, 1} and μ ∈ {1, 0.7, 0.4, 0.1} read from Cycles' table (4 decimals, a port's test
    vectors), to 2e-4; at α = 0 the Fresnel reflectance at the nodes μ = i/15 and its chord between them."""
    cycles_s = {0.0: [0.0000, 0.0117, 0.0955, 0.5628], 0.25: [0.0001, 0.0126, 0.0927, 0.4092],
                0.5: [0.0006, 0.0138, 0.0639, 0.1705], 1.0: [0.0014, 0.0058, 0.0161, 0.0403]}
    mu = np.array([1.0, 0.7, 0.4, 0.1])
    F0 = 0.04
    for r, s in cycles_s.items():
        est = ggx_energy.cycles_layering_albedo(mu, r * r, 1.5)
        np.testing.assert_allclose((est - F0) / (1.0 - F0), s, atol=2e-4)
    nodes = np.arange(1, 16) / 15.0
    est = ggx_energy.cycles_layering_albedo(nodes, 0.0, 1.5)
    np.testing.assert_allclose(est, fresnel_reflectance(nodes, 1.5 + 0j), atol=2e-3)   # (z between its nodes)
    mid = 0.5 * (nodes[:-1] + nodes[1:])
    assert np.all(ggx_energy.cycles_layering_albedo(mid, 0.0, 1.5) >= fresnel_reflectance(mid, 1.5 + 0j) - 1e-3)
    # the compensation's weight E + F_ms(1 − E) ≤ 1, = 1 at α → 0; Cycles' F_ss of a dielectric
    d = ggx_energy.cycles_layering_darkening(np.linspace(0.01, 1, 20), 1.0, 1.5)
    assert np.all((d > 0.3) & (d <= 1.0))
    assert ggx_energy.dielectric_average_fresnel(1.5) == pytest.approx(0.5 / (4.08567 + 1.00071 * 1.5))
