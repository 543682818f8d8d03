"""HTSG polarising BRDF (engine.materials.htsg) against shared/oracles/htsg_reference.json and docs/physics.md.

Every numerical claim of the module docstring is checked here: the oracle (ρ_dd, ρ_s, Mueller
matrices in both frames, intermediates), the series window and stride against a brute-force
sum, erfc against libm, energy and limits of docs/physics.md §4, realisability, reciprocity and the
sampler (χ² goodness of fit, weights, lobe probability).
"""

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from engine.materials.base import ShadingPoint
from engine.materials.evaluate import mueller_at, oracle_directions
from engine.materials.catalogue import make_model
from engine.materials.htsg import HTSG, erfc, ln_factorial, log_series, roughness_ratio, shadowing
from engine.polarisation.fresnel import fresnel_reflectance
from engine.polarisation.mueller import is_realisable
from engine.spectral import ConstantSpectrum
from engine.vec3 import cross, dot
from tests.conftest import shared_path
from tests.support import chi2

with open(shared_path("oracles", "htsg_reference.json")) as _fh:
    CASES = json.load(_fh)["cases"]

_LGAMMA = np.frompyfunc(math.lgamma, 1, 1)
Z = np.array([0.0, 0.0, 1.0])


def _model(case, **kw):
    if not kw:   # as `python -m engine mueller --model htsg --param ...` builds it
        return make_model("htsg", {"n": case["n"], "k": case["k"], "sigma0_um": case["sigma0_um"],
                                   "tau_um": case["tau_um"]})
    return HTSG(case["n"], case["k"], case["sigma0_um"], case["tau_um"], **kw)


def _point(wo, lam_nm, n=None):
    """ShadingPoint(s) with normal +z for wo (3,) or (3, N) and wavelengths (L, N) or a scalar."""
    wo = np.asarray(wo, dtype=np.float64)
    if wo.ndim == 1:
        wo = wo.reshape(3, 1)
    N = wo.shape[1]
    lam = np.asarray(lam_nm, dtype=np.float64)
    lam = np.full((1, N), float(lam)) if lam.ndim == 0 else lam
    z = np.repeat(Z.reshape(3, 1), N, axis=1)
    return ShadingPoint(np.zeros((3, N)), z, z, wo, lam, False)


def _direction(theta_deg, phi_deg):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def _rel(a, b):
    return abs(a - b) / abs(b)


def _degenerate(case):
    return "global_sp_frame" not in case["mueller_dd"]


# ------------------------------------------------------------------------------------------------
# oracle
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("case", CASES, ids=lambda c: c["id"])
def test_oracle_rho_dd_rho_s_and_mueller(case):
    model = _model(case)
    lam = case["lambda_um"] * 1000.0
    ti, tr, pr = case["theta_i_deg"], case["theta_r_deg"], case["phi_r_deg"]
    out = mueller_at(model, ti, tr, pr, lam, "scattering")
    M = np.array(out["brdf"])
    ref = case["rho_dd_reference"]
    assert _rel(M[0, 0], ref) < 1e-6
    rho_s = out["delta"][0][0]
    if case["rho_s_reference"] > 0:
        assert _rel(rho_s, case["rho_s_reference"]) < 1e-6
    else:
        assert 0.0 <= rho_s < 1e-300
    # scattering-plane frame: every element within 1e-6·M00 (degenerate: frame invariant, any shared s)
    Ms = np.array(case["mueller_dd"]["scattering_plane_frame"]["M"])
    assert np.max(np.abs(M - Ms)) <= 1e-6 * Ms[0, 0]
    # global frame through the engine's 'sp' basis (s = unit(z × k): a sign flip of s, same M)
    if not _degenerate(case):
        g = case["mueller_dd"]["global_sp_frame"]
        Mg = np.array(mueller_at(model, ti, tr, pr, lam, "sp")["brdf"])
        assert np.max(np.abs(Mg - np.array(g["M"]))) <= 1e-6 * Ms[0, 0]
        # the frame vectors the oracle lists are the ones the 'sp' basis uses (up to the sign of s)
        wi, wo = oracle_directions(ti, tr, pr)
        for s_ref, p_ref, k in ((g["s_in"], g["p_in"], -wi), (g["s_out"], g["p_out"], wo)):
            s = cross(Z, k)
            s = s / np.linalg.norm(s)
            assert abs(abs(dot(s, np.array(s_ref))) - 1.0) < 1e-12
            assert np.allclose(np.sign(dot(s, np.array(s_ref))) * cross(k, s), p_ref, atol=1e-12)


@pytest.mark.parametrize("case", [c for c in CASES if not _degenerate(c)], ids=lambda c: c["id"])
def test_oracle_frames_are_the_scattering_plane(case):
    """eval's own frames are s = ±unit(k_i × k_r) on both beams, with p = k × s as listed."""
    model = _model(case)
    wi, wo = oracle_directions(case["theta_i_deg"], case["theta_r_deg"], case["phi_r_deg"])
    v = model.eval(_point(wo, case["lambda_um"] * 1000.0), wi.reshape(3, 1))
    f = case["mueller_dd"]["scattering_plane_frame"]
    sign = np.sign(dot(v.x_in[:, 0], np.array(f["s"])))
    assert np.allclose(sign * v.x_in[:, 0], f["s"], atol=1e-12)
    assert np.allclose(v.x_in, v.x_out)
    assert np.allclose(sign * cross(-wi, v.x_in[:, 0]), f["p_in"], atol=1e-12)
    assert np.allclose(sign * cross(wo, v.x_out[:, 0]), f["p_out"], atol=1e-12)


_INTERMEDIATES = ("sigma_eff_um", "g", "S", "G_geom", "D", "F_unpol_half", "cos_theta_h",
                  "rho_s_S", "rho_s_g", "rho_s_sigma_eff_um")


@pytest.mark.parametrize("case", CASES, ids=lambda c: c["id"])
def test_oracle_intermediates(case):
    model = _model(case)
    wi, wo = oracle_directions(case["theta_i_deg"], case["theta_r_deg"], case["phi_r_deg"])
    it = model.intermediates(_point(wo, case["lambda_um"] * 1000.0), wi.reshape(3, 1))
    ref = case["intermediates"]
    for key in _INTERMEDIATES:
        got = float(np.ravel(it[key])[0])
        tol = 1e-6 if key == "D" else 1e-9
        assert abs(got - ref[key]) <= tol * abs(ref[key]) + 1e-300, key
    # series length sanity: the window brackets the peak and is never longer than the
    # reference's (which summed every term from m = 1 to beyond m > g + 10)
    win = {k: float(np.ravel(v)[0]) for k, v in it["series"].items()}
    assert win["m_lo"] <= win["mode"] <= win["m_hi"]
    assert win["m_hi"] <= ref["series_terms"] + 10
    assert win["tail"] <= model.series_tolerance
    assert win["nodes"] <= 200
    if ref["g"] > 1e5:
        assert win["step"] > 100 and win["m_hi"] - win["m_lo"] > 4000  # ~1.7e5 terms replaced by ~30


def test_oracle_thesis_params_needs_no_asymptotics():
    """g ≈ 1.6e5 (thesis Ch. 6.3): exact-window sum (every term) and strided sum agree with the oracle."""
    case = next(c for c in CASES if c["id"] == "hard-thesis-params")
    model = _model(case)
    wi, wo = oracle_directions(case["theta_i_deg"], case["theta_r_deg"], case["phi_r_deg"])
    it = model.intermediates(_point(wo, case["lambda_um"] * 1000.0), wi.reshape(3, 1))
    g, c = float(it["g"][0, 0]), float(it["c"][0, 0])
    full = log_series(np.array([math.log(g)]), np.array([c]), stride=False)[0]
    fast = log_series(np.array([math.log(g)]), np.array([c]))[0]
    assert abs(full - fast) < 1e-10
    D = math.pi ** 2 * case["tau_um"] ** 2 / (4 * case["lambda_um"] ** 2) * math.exp(full)
    assert _rel(D, case["intermediates"]["D"]) < 1e-6


# ------------------------------------------------------------------------------------------------
# special functions
# ------------------------------------------------------------------------------------------------

def test_erfc_matches_libm():
    rng = np.random.default_rng(1)
    x = np.concatenate((rng.uniform(-6, 6, 4000), rng.uniform(0, 27, 4000), np.exp(rng.uniform(-40, 0, 500)),
                        [0.0, 0.46875, 0.4687500001, 4.0, 4.0000001, 26.5, 26.6, 30.0, -30.0, 1e-300]))
    got = erfc(x)
    ref = np.array([math.erfc(v) for v in x])
    big = ref > 1e-300
    assert np.max(np.abs(got[big] - ref[big]) / ref[big]) < 4e-15
    assert np.all(np.abs(got[~big]) < 1e-300)
    assert erfc(np.array([np.inf]))[0] == 0.0 and erfc(np.array([-np.inf]))[0] == 2.0
    assert np.isnan(erfc(np.array([np.nan]))[0])


def test_ln_factorial_matches_lgamma():
    m = np.concatenate((np.arange(0, 300), np.unique(np.exp(np.linspace(5, 14, 200)).round())))
    ref = _LGAMMA(m + 1).astype(float)
    assert np.max(np.abs(ln_factorial(m) - ref) / np.maximum(ref, 1.0)) < 1e-14


def test_roughness_ratio_solves_the_equation():
    rng = np.random.default_rng(2)
    f0 = np.concatenate((np.exp(rng.uniform(math.log(1e-300), math.log(5e11), 3000)), [0.0, 1e-8, 1.0, 1e12]))
    x = roughness_ratio(f0)
    assert np.all(np.isfinite(x)) and np.all(x >= 0)
    pos = f0 > 0
    # ln x + x²/2 = ln f₀
    res = np.log(x[pos]) + 0.5 * x[pos] ** 2 - np.log(f0[pos])
    assert np.max(np.abs(res) / np.maximum(1.0, np.abs(np.log(f0[pos])))) < 1e-13
    assert x[~pos][0] == 0.0
    # monotone in f₀
    o = np.argsort(f0)
    assert np.all(np.diff(x[o]) >= 0)


def test_shadowing_function():
    mu = np.array([0.0, 1e-3, 0.1, 0.5, 1.0, 2.0, 5.0, 30.0, np.inf])
    S = shadowing(mu)
    assert S[0] == 0.0 and S[-1] == 1.0
    assert np.all(np.diff(S) >= 0) and np.all(np.diff(S[:7]) > 0)
    for m, s in zip(mu[1:-1], S[1:-1]):
        lam = 0.5 * (math.exp(-m * m) / (math.sqrt(math.pi) * m) - math.erfc(m))  # Eq. 25 erratum
        assert abs(s - (1 - 0.5 * math.erfc(m)) / (lam + 1)) < 1e-15
    # the thesis's uncorrected Λ = ½(1/(√π μ) − erfc μ) is measurably different (so the erratum matters)
    m = 0.5
    wrong = (1 - 0.5 * math.erfc(m)) / (0.5 * (1 / (math.sqrt(math.pi) * m) - math.erfc(m)) + 1)
    assert abs(shadowing(np.array([m]))[0] - wrong) > 0.05


# ------------------------------------------------------------------------------------------------
# the series
# ------------------------------------------------------------------------------------------------

def _brute_terms(g, c):
    """Every term of the series (log), m = 1 … far beyond the peak (float, math.lgamma)."""
    peak = max(g, math.sqrt(c) + 1.0, 1.0)
    M = int(peak + 60 * math.sqrt(peak) + 200 + 3 * math.sqrt(c))
    m = np.arange(1, M + 1, dtype=np.float64)
    lt = m * math.log(g) - g - _LGAMMA(m + 1).astype(float) - np.log(m) - c / m
    assert lt[-1] < lt.max() - 60  # the brute-force range itself is complete
    return m, lt


def _logsumexp(x):
    mx = x.max()
    return mx + math.log(np.sum(np.exp(x - mx)))


def _random_gc(n, seed):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        g = math.exp(rng.uniform(math.log(1e-6), math.log(5e5)))
        kind = rng.integers(3)
        c = 0.0 if kind == 0 else (math.exp(rng.uniform(-5, math.log(1e6))) if kind == 1
                                   else g * g * rng.uniform(0, 0.5))
        out.append((g, c))
    return out


_SERIES_CASES = _random_gc(120, 7) + [(g, c) for g in (55, 70, 100, 300) for c in (0, 100, 1e4)] + [
    (1e-6, 0.0), (1e-6, 1e6), (5e5, 0.0), (5e5, 1e10), (1.0, 0.0), (9.0, 0.0), (20.0, 400.0)]


def test_series_matches_brute_force_sum():
    """Window + stride (default) and window only (stride=False) vs the full float sum.

    The brute force is itself accurate to ~4e-15·g relative (m·ln g and lgamma(m+1) are ~g ln g)
    and ~2e-16·|ln Σ| (the log of very small sums).
    """
    G = np.array([x[0] for x in _SERIES_CASES])
    C = np.array([x[1] for x in _SERIES_CASES])
    fast, info = log_series(np.log(G), C, 1e-10, return_info=True)
    full = log_series(np.log(G), C, 1e-10, stride=False)
    assert np.all(info["tail"] <= 1e-10)
    assert np.any(info["step"] > 100)  # the strided path is exercised
    for k, (g, c) in enumerate(_SERIES_CASES):
        _, lt = _brute_terms(g, c)
        b = _logsumexp(lt)
        tol = 1e-12 + 4e-15 * g + 2e-16 * abs(b)
        assert abs(math.expm1(fast[k] - b)) <= tol, (g, c)
        assert abs(math.expm1(full[k] - b)) <= tol, (g, c)
    # stride vs every term of the same window: agreement far below the 1e-6 requirement
    assert np.max(np.abs(np.expm1(fast - full))) < 1e-10


@pytest.mark.parametrize("g,c", [(0.3, 0.0), (8.0, 0.0), (40.0, 50.0), (2000.0, 0.0), (1e-3, 3e3), (150.0, 3e4)])
def test_series_window_tail_bound_holds(g, c):
    """The terms left out of the window sum to at most tol × the total (brute force)."""
    tol = 1e-10
    _, info = log_series(np.array([math.log(g)]), np.array([c]), tol, stride=False, return_info=True)
    m, lt = _brute_terms(g, c)
    lo, hi = info["m_lo"][0], info["m_hi"][0]
    inside = (m >= lo) & (m <= hi)
    total = _logsumexp(lt)
    outside = _logsumexp(lt[~inside]) if (~inside).any() else -np.inf
    assert math.exp(outside - total) <= tol
    # ... and the window is not absurdly long: ~±(K·s) around the peak
    assert hi - lo + 1 <= 40 * math.sqrt(max(g, 1.0)) + 60


def test_series_zero_and_tiny_g():
    out = log_series(np.array([-np.inf, math.log(1e-300)]), np.array([0.0, 0.0]))
    assert out[0] == -np.inf
    assert abs(out[1] - (math.log(1e-300) - 1e-300)) < 1e-12  # Σ ≈ g e^{−g}


# ------------------------------------------------------------------------------------------------
# energy and limits (docs/physics.md §4, §4.6)
# ------------------------------------------------------------------------------------------------

def test_energy_reference_values():
    dd, rs = HTSG(0.88045, 6.1455, 0.18, 3.0).directional_albedo(30.0, 526.0, 192, 96)
    assert abs(dd + rs - 0.91393) < 1e-3
    assert dd + rs < float(fresnel_reflectance(math.cos(math.radians(30)), 0.88045 + 6.1455j))
    dd, rs = HTSG(0.88045, 6.1455, 0.5, 1.0).directional_albedo(60.0, 526.0, 192, 96)
    assert abs(dd + rs - 0.464) < 0.005


@pytest.mark.parametrize("seed", range(6))
def test_energy_at_most_one(seed):
    rng = np.random.default_rng(100 + seed)
    s0 = math.exp(rng.uniform(math.log(0.005), math.log(3.0)))
    tau = math.exp(rng.uniform(math.log(0.1), math.log(20.0)))
    n, k = rng.uniform(0.2, 3.0), (0.0 if seed % 2 else rng.uniform(0.0, 8.0))
    th, lam = rng.uniform(0.0, 89.0), rng.uniform(360.0, 830.0)
    dd, rs = HTSG(n, k, s0, tau).directional_albedo(th, lam, 160, 80)
    assert 0.0 <= dd and 0.0 <= rs
    assert dd + rs <= 1.0 + 1e-3


def test_energy_with_diffuse_albedo_adds_albedo():
    base = HTSG(1.5, 0.0, 0.2, 2.0)
    diff = HTSG(1.5, 0.0, 0.2, 2.0, albedo=0.3)
    a = sum(base.directional_albedo(40.0, 550.0, 160, 80))
    b = sum(diff.directional_albedo(40.0, 550.0, 160, 80))
    assert abs(b - a - 0.3) < 2e-3  # the half-vector quadrature integrates the constant a/π too


@pytest.mark.parametrize("sigma0", [0.0, 1e-9, 1e-6])
def test_smooth_limit(sigma0):
    """σ₀ → 0: ρ_dd → 0 and ρ_s → F(θ_i) (docs/physics.md 4.10)."""
    model = HTSG(0.88045, 6.1455, sigma0, 3.0)
    for ti in (0.0, 30.0, 60.0, 85.0):
        F = float(fresnel_reflectance(math.cos(math.radians(ti)), 0.88045 + 6.1455j))
        for tr, pr in ((ti, 0.0), (20.0, 90.0), (70.0, 180.0)):
            out = mueller_at(model, ti, tr, pr, 550.0, "scattering")
            assert 0.0 <= out["brdf"][0][0] <= 1e-6 * (sigma0 / 1e-6) ** 2 + 1e-300
            assert _rel(out["delta"][0][0], F) < 1e-6


def test_long_wavelength_limit():
    """λ → ∞: g → 0, so ρ_dd → 0 and ρ_s → F(θ_i)·S(θ_i)²."""
    model = HTSG(1.5, 0.0, 0.5, 1.0)
    ti = 60.0
    wi, wo = oracle_directions(ti, ti, 0.0)
    for lam in (1e6, 1e8):
        it = model.intermediates(_point(wo, lam), wi.reshape(3, 1))
        F = float(fresnel_reflectance(math.cos(math.radians(ti)), 1.5))
        assert _rel(float(it["rho_s"][0, 0]), F * float(it["rho_s_S"][0])) < 1e-4 * (1e6 / lam) ** 2
        assert float(it["rho_dd"][0, 0]) < 1e-3 * (1e6 / lam) ** 2
    # and ρ_dd does fall with λ
    vals = [float(model.intermediates(_point(wo, lam), wi.reshape(3, 1))["rho_dd"][0, 0]) for lam in (1e4, 1e5, 1e6)]
    assert vals[0] > vals[1] > vals[2] > 0


# ------------------------------------------------------------------------------------------------
# realisability, finiteness, reciprocity (hypothesis)
# ------------------------------------------------------------------------------------------------

_THETAS = st.one_of(st.sampled_from([0.0, 1e-7, 89.99, 89.9999, 45.0]), st.floats(0.0, 89.999))
_PHIS = st.one_of(st.sampled_from([0.0, 180.0, 90.0]), st.floats(-180.0, 180.0))
_SIGMAS = st.one_of(st.sampled_from([0.0, 1e-9, 20.0, 0.18]), st.floats(1e-4, 5.0))
_TAUS = st.one_of(st.sampled_from([0.2, 3.0, 50.0]), st.floats(0.05, 30.0))
_KAPPAS = st.one_of(st.sampled_from([0.0, 50.0]), st.floats(0.0, 50.0))


def _check_matrix(M, tol=1e-9):
    M = np.asarray(M)
    assert np.all(np.isfinite(M))
    assert M[0, 0] >= 0.0
    if M[0, 0] > 0:
        assert bool(is_realisable((M / M[0, 0])[:, :, None], tol))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ti=_THETAS, to=_THETAS, po=_PHIS, s0=_SIGMAS, tau=_TAUS, n=st.floats(0.1, 4.0), kap=_KAPPAS,
       lam=st.floats(360.0, 830.0), albedo=st.sampled_from([0.0, 0.5]))
def test_realisable_and_finite(ti, to, po, s0, tau, n, kap, lam, albedo):
    model = HTSG(n, kap, s0, tau, albedo=albedo)
    for basis in ("scattering", "sp"):
        out = mueller_at(model, ti, to, po, lam, basis)
        _check_matrix(out["brdf"])
        _check_matrix(out["delta"])
        assert out["delta"][0][0] <= 1.0 + 1e-12


@settings(max_examples=40, deadline=None)
@given(ti=_THETAS, s0=_SIGMAS, tau=_TAUS, kap=_KAPPAS)
def test_exact_specular_and_backscatter_are_finite(ti, s0, tau, kap):
    model = HTSG(0.9, kap, s0, tau)
    for po in (0.0, 180.0):  # exact mirror direction (v_xy = 0) and exact retro-reflection (k_i ∥ k_r)
        out = mueller_at(model, ti, ti, po, 526.0, "scattering")
        _check_matrix(out["brdf"])


@pytest.mark.parametrize("s0,tau,n,kap", [(0.1, 100.0, 0.81, 50.0), (1e-9, 100.0, 0.39, 0.5), (20.0, 0.2, 1.1, 6.8)])
def test_realisable_in_batches_down_to_underflow(s0, tau, n, kap):
    """Batches with values down to the float limit: no subnormal results (they would lose the
    precision that keeps A² ≥ B² + C² + S²), every matrix realisable, delta weights ≤ 1."""
    rng = np.random.default_rng(21)
    N = 3000
    wi = np.stack([_direction(rng.uniform(0, 90), rng.uniform(-180, 180)) for _ in range(N)], axis=1)
    wo = np.stack([_direction(rng.uniform(0, 90), rng.uniform(-180, 180)) for _ in range(N)], axis=1)
    sp = _point(wo, rng.uniform(360, 830, (4, N)))
    model = HTSG(n, kap, s0, tau)
    for M in (model.eval(sp, wi).matrix(), model.delta_reflection(sp).matrix()):
        assert np.all(np.isfinite(M))
        m00 = M[0, 0]
        assert np.all((m00 == 0) | (m00 >= 1e-280))
        Mn = np.where(m00 > 0, M / np.where(m00 > 0, m00, 1.0), 0.0)
        assert np.all(is_realisable(Mn, 1e-9))


def _eval_pair(model, wi, wo, lam):
    v = model.eval(_point(wo, lam), wi.reshape(3, 1))
    return v, v.matrix()[:, :, 0, 0]


@settings(max_examples=100, deadline=None)
@given(ti=st.floats(0.0, 89.5), pi=st.floats(-180, 180), to=st.floats(0.0, 89.5), po=st.floats(-180, 180),
       s0=st.floats(0.01, 3.0), tau=st.floats(0.1, 20.0), kap=_KAPPAS, lam=st.floats(360.0, 830.0))
def test_reciprocity(ti, pi, to, po, s0, tau, kap, lam):
    model = HTSG(1.3, kap, s0, tau)
    wi, wo = _direction(ti, pi), _direction(to, po)
    v1, M1 = _eval_pair(model, wi, wo, lam)
    v2, M2 = _eval_pair(model, wo, wi, lam)
    assert abs(M1[0, 0] - M2[0, 0]) <= 1e-9 * max(M1[0, 0], 1e-300)
    # scattering-plane frames of the reversed path: s' = ±s, and M_rev = Q·Mᵀ·Q, Q = diag(1,1,1,−1)
    assert abs(abs(dot(v1.x_in[:, 0], v2.x_in[:, 0])) - 1.0) < 1e-9 or np.linalg.norm(cross(wi, wo)) < 1e-6
    Q = np.diag([1.0, 1.0, 1.0, -1.0])
    assert np.max(np.abs(M2 - Q @ M1.T @ Q)) <= 1e-9 * max(M1[0, 0], 1e-300)


def test_one_sided_and_back_facing_zero():
    model = HTSG(1.5, 0.0, 0.2, 2.0, albedo=0.4)
    wo = _direction(30, 0)
    for wi in (np.array([0.3, 0.0, -0.9]), np.array([1.0, 0.0, 0.0])):
        wi = wi / np.linalg.norm(wi)
        assert np.all(model.eval(_point(wo, 550.0), wi.reshape(3, 1)).matrix() == 0.0)
        assert model.pdf(_point(wo, 550.0), wi.reshape(3, 1))[0] == 0.0
    wo_back = np.array([0.0, 0.6, -0.8])
    assert np.all(model.eval(_point(wo_back, 550.0), _direction(20, 180).reshape(3, 1)).matrix() == 0.0)
    assert np.all(model.delta_reflection(_point(wo_back, 550.0)).matrix() == 0.0)


def test_uniform_diffuse_is_a_depolariser_added_to_m00():
    a = HTSG(1.5, 0.0, 0.2, 2.0)
    b = HTSG(1.5, 0.0, 0.2, 2.0, albedo=ConstantSpectrum(0.25))
    wi, wo = _direction(40, 180), _direction(25, 30)
    Ma = a.eval(_point(wo, 550.0), wi.reshape(3, 1)).matrix()[:, :, 0, 0]
    vb = b.eval(_point(wo, 550.0), wi.reshape(3, 1))
    assert vb.kind == "general"
    Mb = vb.matrix()[:, :, 0, 0]
    D = Mb - Ma
    assert abs(D[0, 0] - 0.25 / math.pi) < 1e-15
    D[0, 0] = 0.0
    assert np.max(np.abs(D)) < 1e-15


def test_spectral_batch_matches_single_wavelength_evaluations():
    rng = np.random.default_rng(9)
    N = 64
    model = HTSG(0.5, 3.0, 0.25, 2.0, albedo=0.1)
    wi = np.stack([_direction(rng.uniform(0, 89), rng.uniform(-180, 180)) for _ in range(N)], axis=1)
    wo = np.stack([_direction(rng.uniform(0, 89), rng.uniform(-180, 180)) for _ in range(N)], axis=1)
    lam = rng.uniform(360, 830, (4, N))
    M = model.eval(_point(wo, lam), wi).matrix()
    for j in range(4):
        Mj = model.eval(_point(wo, lam[j:j + 1]), wi).matrix()
        assert np.allclose(M[:, :, j], Mj[:, :, 0], rtol=1e-12, atol=0)


def test_parameter_validation():
    with pytest.raises(ValueError):
        HTSG(1.5, 0.0, -0.1, 1.0)
    with pytest.raises(ValueError):
        HTSG(1.5, 0.0, 0.1, 0.0)
    with pytest.raises(ValueError):
        HTSG(1.5, 0.0, 0.1, float("nan"))
    with pytest.raises(ValueError):
        HTSG(1.5, 0.0, 0.1, 1.0, albedo=1.5)
    with pytest.raises(ValueError):
        HTSG(1.5, 0.0, 0.1, 1.0, series_tolerance=0.0)
    with pytest.raises(ValueError):
        HTSG(1.5, -1.0, 0.1, 1.0)
    m = HTSG(ConstantSpectrum(1.5), ConstantSpectrum(0.0), 0.0, 1.0)
    assert m.name == "htsg" and not m.delta_only and m.creates_circular
    assert m.describe()["type"] == "htsg"


# ------------------------------------------------------------------------------------------------
# sampling
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("params,theta_o", [
    (dict(n=0.88045, k=6.1455, sigma0_um=0.3, tau_um=1.5, albedo=0.2), 40.0),   # geometric lobe + diffuse
    (dict(n=1.5, k=0.0, sigma0_um=0.03, tau_um=0.6), 60.0),                      # diffraction lobe, strong Dirac
])
def test_sampling_chi_square(params, theta_o):
    model = HTSG(**params)
    lam = 550.0
    wo = _direction(theta_o, 0.0)
    N = 200_000
    rng = np.random.default_rng(11)
    sp = _point(np.repeat(wo.reshape(3, 1), N, axis=1), np.full((1, N), lam))
    bs = model.sample(sp, rng.random(N), rng.random((2, N)))
    # Dirac and invalid samples fill the harness's "elsewhere" cell (expected: 1 − ∫ pdf over the hemisphere).
    result = chi2.direction_sampler_test(
        bs.wi, bs.valid & ~bs.is_delta,
        lambda wi: model.pdf(_point(np.repeat(wo.reshape(3, 1), wi.shape[1], axis=1), lam), wi),
        n_cos=10, n_phi=20, order=2, sub=12)
    assert result.dof >= 30
    chi2.assert_accepted(result, test_count=2, what="HTSG samples")


def test_sample_weights_pdf_and_lobe_probability():
    model = HTSG(0.88045, 6.1455, 0.06, 1.0, albedo=0.1)
    rng = np.random.default_rng(4)
    N = 4000
    wo = np.stack([_direction(rng.uniform(0, 85), rng.uniform(-180, 180)) for _ in range(N)], axis=1)
    lam = rng.uniform(360, 830, (4, N))
    sp = _point(wo, lam)
    u_lobe = rng.random(N)
    bs = model.sample(sp, u_lobe, rng.random((2, N)))
    plan = model._lobe_plan(sp)
    p_spec = plan["p_spec"]
    # the Dirac lobe is chosen exactly when u_lobe < P_spec
    assert np.array_equal(bs.is_delta, u_lobe < p_spec)
    assert 0.05 < p_spec.mean() < 0.95
    # Dirac samples: mirror direction, weight = delta weight / P_spec, pdf 0
    d = bs.is_delta
    mirror = 2 * dot(wo, sp.n_s) * sp.n_s - wo
    assert np.allclose(bs.wi[:, d], mirror[:, d], atol=1e-12)
    assert np.all(bs.pdf[d] == 0)
    dr = model.delta_reflection(sp).matrix()
    assert np.allclose(bs.weight.matrix()[..., d], dr[..., d] / p_spec[d], rtol=1e-10, atol=0)
    # non-delta samples: weight = eval·cosθ_i/pdf and pdf = pdf() (the integrator's MIS density)
    nd = bs.valid & ~d
    assert nd.sum() > N // 4
    sub = ShadingPoint(sp.p[:, nd], sp.n_s[:, nd], sp.n_g[:, nd], wo[:, nd], lam[:, nd])
    f = model.eval(sub, bs.wi[:, nd]).matrix()
    cos_i = dot(sub.n_s, bs.wi[:, nd])
    pdf = model.pdf(sub, bs.wi[:, nd])
    assert np.allclose(bs.pdf[nd], pdf, rtol=1e-12)
    assert np.allclose(bs.weight.matrix()[..., nd], f * (cos_i / pdf), rtol=1e-10, atol=1e-300)
    # one direction per path: the plan uses only wavelength means, so it is symmetric in the path's λs
    sp2 = _point(wo, lam[::-1])
    assert np.allclose(model.pdf(sp2, bs.wi), model.pdf(sp, bs.wi), rtol=1e-12, atol=0)
    assert np.all(np.isfinite(bs.weight.matrix()))


def test_delta_fraction_matches_lobe_probability():
    model = HTSG(1.5, 0.0, 0.03, 0.6)
    wo = _direction(50.0, 0.0)
    N = 100_000
    sp = _point(np.repeat(wo.reshape(3, 1), N, axis=1), np.full((1, N), 550.0))
    rng = np.random.default_rng(3)
    bs = model.sample(sp, rng.random(N), rng.random((2, N)))
    p = model._lobe_plan(sp)["p_spec"][0]
    assert 0.05 < p < 0.95
    # the documented choice: P_spec = ρ_s / (ρ_s + F·S²·(1 − e^{−g_s})) = ρ_s / (F(θ_o)·S(θ_o)²)
    it = model.intermediates(_point(wo, 550.0), np.array([[-wo[0]], [-wo[1]], [wo[2]]]))
    F = float(fresnel_reflectance(wo[2], 1.5))
    assert abs(p - float(it["rho_s"][0, 0]) / (F * float(it["rho_s_S"][0]))) < 1e-12
    assert abs(bs.is_delta.mean() - p) < 5 * math.sqrt(p * (1 - p) / N)
    # the estimator is unbiased: E[weight·M00] over all samples = directional albedo
    est = float(np.mean(np.where(bs.valid, bs.weight.matrix()[0, 0, 0], 0.0)))
    dd, rs = model.directional_albedo(50.0, 550.0, 256, 128)
    assert abs(est - (dd + rs)) < 5e-3
