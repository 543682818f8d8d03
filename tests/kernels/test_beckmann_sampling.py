"""Beckmann visible-normal sampling (engine.kernels.microfacet): the tabulated first guess of x̃ and the fitted
one of ỹ against the iteration they shorten, against the C library's erfc, and the sampled slopes against
their analytic densities (docs/physics.md §5; the solve: engine/kernels/microfacet.py's module docstring)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from engine import kernels
from engine.kernels import microfacet as mf
from engine.kernels.error_function import erfinv_2u_minus_1
from tests.support import chi2

needs_numba = pytest.mark.skipif(kernels._numba is None, reason="numba is not installed (NumPy kernels only)")

_T_HARD = [0.0, 1e-300, 1e-12, 1e-3, 0.1, 0.3, 1.0, 3.0, 30.0, 1e3, 1e6, 1e12, 1e300]
_U_HARD = [0.0, 1e-300, 1e-16, 1e-12, 1e-9, 7.7e-9, 7.8e-9, 1e-8, 1e-6, 1e-3, 0.3, 0.5, 0.9, 1 - 1e-3, 1 - 1e-6,
           1 - 1e-8, 1 - 7.8e-9, 1 - 1e-12, 1 - 2 ** -53]


def _cases():
    """(tanθ, u): the hard grid and 40000 draws (tanθ = m tanθ_o of a sphere's viewers, m from 1e-3 to 3)."""
    rng = np.random.default_rng(36)
    tt, uu = (a.ravel() for a in np.meshgrid(_T_HARD, _U_HARD, indexing="ij"))
    c = np.sqrt(rng.random(40000))
    t = 10 ** rng.uniform(-3, 0.5, c.size) * np.sqrt(1 - c * c) / c
    return np.concatenate([tt, t]), np.concatenate([uu, rng.random(c.size)])


def _cdf_libm(x, t):
    """F(x)/F(cotθ) of the visible slope with the C library's erfc and exp (independent of erfcx's fit)."""
    def f(v):
        return math.erfc(-v) + (t * math.exp(-v * v) / math.sqrt(math.pi) if t > 0 else 0.0)
    return f(x) / (f(min(1.0 / t, 30.0)) if t > 0 else 2.0)


def test_x_equals_the_untabulated_iteration():
    """The tabulated start ends at the root the iteration from the old start reaches: the same bits where
    the table does not apply, the same x̃ to its convergence rule elsewhere (|ΔF|/F(cotθ) ≤ 2e-14), and
    x̃ itself within 2e-12 for u ∈ [1e-3, 1 − 1e-3]."""
    t, u = _cases()
    with np.errstate(all="ignore"):
        new = mf.visible_slope_x_numpy(t, u)
        old = mf._visible_slope_x_solve(t, u, False)
    assert np.all(np.isfinite(new)) and np.all(new <= np.where(t > 0, 1 / np.maximum(t, 1e-300), 8.0))
    in_table = (np.minimum(u, 1 - u) > mf.START_U_MIN)
    assert np.array_equal(new[~in_table], old[~in_table])
    cot = np.where(t > 0, 1 / np.maximum(t, 1e-300), np.inf)
    z = np.where(cot >= 6, 2.0, mf._visible_slope_cdf(np.minimum(cot, 30.0), t))
    d_prob = np.abs(mf._visible_slope_cdf(new, t) - mf._visible_slope_cdf(old, t)) / z
    # the old start's one known miss: at tanθ > 1e5 and 1 − u < 1e-6 its first Halley step is tiny because
    # of the curvature, not because it is near the root, and it stops short (new: the root, see below)
    missed = (t > 1e5) & (u > 1 - 1e-6)
    assert np.max(d_prob[~missed]) <= 2e-14
    bulk = (u >= 1e-3) & (u <= 1 - 1e-3)
    assert np.max(np.abs(new - old)[bulk]) <= 2e-12
    # against the C library: the new x̃ solves F(x̃)/F(cotθ) = u where the table applies (≤ 3e-14 absolute)
    sel = np.nonzero(in_table)[0]
    res = np.array([abs(_cdf_libm(new[i], t[i]) - u[i]) for i in sel])
    assert res.max() <= 3e-14, (t[sel[res.argmax()]], u[sel[res.argmax()]], res.max())


def test_table_start_is_within_one_halley_step():
    """The interpolated start is within 8e-7·(1 + |x̃|) of the root for 99.99 % of draws (below the 1e-6
    step that ends the iteration), never worse than 1e-4."""
    t, u = _cases()
    t, u = t[len(_T_HARD) * len(_U_HARD):], u[len(_T_HARD) * len(_U_HARD):]
    sel = np.minimum(u, 1 - u) > mf.START_U_MIN
    t, u = t[sel], u[sel]
    lower = u < 0.5
    g = mf.erfcinv_giles(2 * np.where(lower, u, 1 - u))
    g = np.where(lower, -g, g)
    start = mf._start_lookup_numpy(t / (1 + t), g)
    root = mf._visible_slope_x_solve(t, u, False)
    err = np.abs(start - root) / (1 + np.abs(root))
    assert np.mean(err <= 8e-7) >= 0.9999 and err.max() <= 1e-4


def test_y_start_and_root():
    """ỹ from the fitted start: within 5e-11 of the root before its one Newton step, the same ỹ as from Giles'
    start to 4 ulps of 1 + |ỹ| (both Newton-polished), and erfc(ỹ) = 2 min(u, 1 − u) with the C library's erfc
    (relative 2e-14)."""
    rng = np.random.default_rng(7)
    u = np.concatenate([rng.random(20000), 10 ** rng.uniform(-16, 0, 2000), 1 - 10 ** rng.uniform(-16, 0, 2000),
                        [0.0, 1e-300, 1e-16, 5e-9, 1e-8, 0.5, 1 - 1e-8, 1 - 1e-16, 1.0]])
    y = mf.visible_slope_y_numpy(u)
    ref = erfinv_2u_minus_1(u)
    assert np.all(np.isfinite(y)) and np.all(np.abs(y - ref) <= 4 * np.spacing(1 + np.abs(ref)))
    uc = np.clip(u, 1e-16, 1 - 1e-16)
    q = 2 * np.minimum(uc, 1 - uc)
    fitted = q >= 9.3e-9
    assert np.max(np.abs(mf.erfcinv_start_numpy(q) - np.abs(ref))[fitted] / (1 + np.abs(ref[fitted]))) <= 5e-11
    rel = np.array([abs(math.erfc(abs(a)) - b) / b for a, b in zip(y, q)])
    assert rel.max() <= 2e-14


@needs_numba
def test_compiled_twins():
    """The compiled x̃ and ỹ against their NumPy references (exp and log of the C library against NumPy's)."""
    t, u = _cases()
    with np.errstate(all="ignore"):
        np.testing.assert_allclose(mf.visible_slope_x_numba(t, u), mf.visible_slope_x_numpy(t, u), rtol=0, atol=1e-12)
    np.testing.assert_allclose(mf.visible_slope_y_numba(u), mf.visible_slope_y_numpy(u), rtol=0, atol=1e-14)


@needs_numba
def test_vndf_kernel_equals_the_slopes():
    """beckmann_vndf_at (the x̃ and ỹ iterations interleaved, their first steps' erfcx fused) gives the normal of
    the separate twins' slopes, bit for bit, also at the ends of u and of the start table."""
    from engine.kernels.error_function import ERFCX_COEF, ERFCX_K
    rng = np.random.default_rng(3)
    n = 3000 + len(_U_HARD) ** 2
    c = rng.random(n)
    c[:4] = [1.0, 1e-12, 0.0, 1e-300]
    s = np.sqrt(1 - c * c)
    phi = 2 * np.pi * rng.random(n)
    wo = np.stack((s * np.cos(phi), s * np.sin(phi), c))
    u = rng.random((2, n))
    u[:, 3000:] = [a.ravel() for a in np.meshgrid(_U_HARD, _U_HARD, indexing="ij")]
    m = 10 ** rng.uniform(-4, 1, n)
    coef = np.ascontiguousarray(ERFCX_COEF)
    got = np.array([mf.beckmann_vndf_at(*wo[:, i], u[0, i], u[1, i], m[i], coef, float(ERFCX_K)) for i in range(n)]).T
    s = np.sqrt(wo[0] * wo[0] + wo[1] * wo[1])
    t = np.minimum(np.where(c > 0, m * s / np.where(c > 0, c, 1), 1e300), 1e300)
    sx, sy = mf.visible_slope_x_numba(t, u[0]), mf.visible_slope_y_numba(u[1])
    cp, sp = np.where(s > 0, wo[0] / np.where(s > 0, s, 1), 1.0), np.where(s > 0, wo[1] / np.where(s > 0, s, 1), 0.0)
    hx, hy = m * (cp * sx - sp * sy), m * (sp * sx + cp * sy)
    r = np.sqrt(hx * hx + hy * hy + 1)
    assert np.array_equal(got, np.stack((-hx / r, -hy / r, 1 / r)))
    # with the pdf's Λ(ω_o) (its erfcx beside the sampler's): the same normal, and Λ's bits (a = ∞, 0, > 6 included)
    with_lam = np.array([mf.beckmann_vndf_lambda_at(*wo[:, i], u[0, i], u[1, i], m[i], coef, float(ERFCX_K))
                         for i in range(n)]).T
    lam = np.array([mf.beckmann_lambda_at(mf.smith_a_at(*wo[:, i], m[i]), coef, float(ERFCX_K)) for i in range(n)])
    assert np.array_equal(with_lam[:3], got)
    assert np.array_equal(with_lam[3], lam)
    assert np.isinf(lam).any() and (lam == 0).any() and ((lam > 0) & np.isfinite(lam)).any()


@needs_numba
def test_erfcx3_equals_erfcx():
    """erfcx3_at and erfcx4_at (three, four series summed in one loop) give erfcx_nonneg_scalar's bits for each of
    their arguments."""
    from engine.kernels.error_function import ERFCX_COEF, ERFCX_K, erfcx_nonneg_scalar
    coef, k = np.ascontiguousarray(ERFCX_COEF), float(ERFCX_K)
    x = np.concatenate([[0.0, 1e-300, 1e-8, 2.9999999999999996, 3.0, 26.0, 30.0, 1e150, 1e300, np.inf, np.nan],
                        10 ** np.random.default_rng(5).uniform(-6, 3, 3000)])
    one = np.array([erfcx_nonneg_scalar(v, coef, k) for v in x])
    three = np.array([mf.erfcx3_at(a, b, c, coef, k) for a, b, c in zip(x, np.roll(x, 1), np.roll(x, 2))])
    for j in range(3):
        assert np.array_equal(three[:, j], np.roll(one, j), equal_nan=True)
    four = np.array([mf.erfcx4_at(a, b, c, d, coef, k) for a, b, c, d in zip(*(np.roll(x, j) for j in range(4)))])
    for j in range(4):
        assert np.array_equal(four[:, j], np.roll(one, j), equal_nan=True)


@needs_numba
@pytest.mark.parametrize("rational", [False, True])
def test_g1_pair_equals_the_product(rational):
    """beckmann_g1_pair_at (the two Λ's erfcx fused) gives beckmann_g1_at(ω_i)·beckmann_g1_at(ω_o)'s bits: normal
    incidence (a = ∞), a > 6, grazing and back-facing directions, χ⁺ = 0, m from 1e-4 to 10."""
    from engine.kernels.error_function import ERFCX_COEF, ERFCX_K
    coef, k = np.ascontiguousarray(ERFCX_COEF), float(ERFCX_K)
    rng = np.random.default_rng(7)
    n = 4000
    w = rng.normal(size=(3, 3, n))
    hard = np.array([[0, 0, 1], [1e-9, 0, 1], [1, 0, 1e-12], [1, 0, 0], [0, 1, -1], [0.3, 0.1, 1]], float).T
    w[0, :, :6] = hard          # ω_i
    w[1, :, 6:12] = hard        # ω_o
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    wi, wo, h = w
    m = 10 ** rng.uniform(-4, 1, n)
    for j in range(n):
        a, b, c = wi[:, j], wo[:, j], h[:, j]
        want = mf.beckmann_g1_at(*a, *c, m[j], rational, coef, k) * mf.beckmann_g1_at(*b, *c, m[j], rational, coef, k)
        got = mf.beckmann_g1_pair_at(*a, *b, *c, m[j], rational, coef, k)
        assert got == want or (np.isnan(got) and np.isnan(want)), (j, got, want)


@pytest.mark.parametrize("t", [0.0, 0.2, 1.0, 4.0, 1e3])
def test_sampled_slopes_follow_their_density(t):
    """x̃ against (2/√π)(1 − x t) e^{−x²}/F(cotθ) on x < cotθ, ỹ against e^{−y²}/√π (chi-square, 40000 draws)."""
    rng = np.random.default_rng(int(t * 10) + 1)
    n = 40000
    u = rng.random((2, n))
    x = mf.visible_slope_x(np.full(n, t), u[0])
    y = mf.visible_slope_y(u[1])
    cot = 1 / t if t > 0 else np.inf
    z = 2.0 if cot >= 6 else float(mf._visible_slope_cdf(np.array([cot]), np.array([t]))[0])
    hi = min(cot, 8.0)

    def px(v):
        return np.where(v < cot, 2 / math.sqrt(math.pi) * (1 - v * t) * np.exp(-v * v) / z, 0.0)

    lo = min(-4.5, float(x.min()))
    edges = np.concatenate([[-8.0], np.linspace(max(lo, -8.0) + 1e-9, hi, 41)]) if lo > -8 else np.linspace(-8, hi, 41)
    tests = 2 * 5
    chi2.assert_accepted(chi2.interval_sampler_test(x, px, edges, order=8, sub=2), test_count=tests, what="x̃")
    chi2.assert_accepted(chi2.interval_sampler_test(y, lambda v: np.exp(-v * v) / math.sqrt(math.pi),
                                                    np.linspace(-6, 6, 41), order=8), test_count=tests, what="ỹ")


def test_start_constants_are_reproducible():
    """The compiled kernels hold the x̃ table and ỹ's coefficients as constants of their cached machine code:
    the table is the same bits whatever NumPy's SIMD loops (a process with NumPy's AVX-512 loops allowed builds
    it too), and the coefficients' polynomials are what their fit gives (to 1e-12; the least squares' last bits
    differ between LAPACK kernels)."""
    import hashlib
    import os
    import subprocess
    import sys
    from tests.conftest import REPO
    env = {k: v for k, v in os.environ.items() if k not in ("NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE")}
    code = ("import hashlib, engine.kernels.microfacet as mf; "
            "print(hashlib.sha256(mf.START_TABLE.tobytes()).hexdigest())")
    other = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, check=True)
    assert other.stdout.strip() == hashlib.sha256(mf.START_TABLE.tobytes()).hexdigest()
    assert np.array_equal(mf._start_table(), mf.START_TABLE)
    tau = np.linspace(-1, 1, 1001)
    for fitted, literal in zip(mf._fit_erfcinv_start(), (mf._YS_LOW, mf._YS_HIGH)):
        assert np.max(np.abs(np.polyval(fitted, tau) - np.polyval(literal, tau))) <= 1e-12
