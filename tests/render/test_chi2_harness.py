"""The shared chi-square harness (tests/support/chi2.py): its χ² survival function against closed
forms and tabulated quantiles, its cell merging, and that it accepts correct samplers and rejects
wrong ones (a test that cannot fail proves nothing)."""

import math

import numpy as np
import pytest

from engine.materials.base import ShadingPoint
from engine.materials.torrance_sparrow import TorranceSparrow
from tests.support import chi2

# --- χ² survival function ------------------------------------------------------------------------------


def test_chi2_survival_function():
    # dof = 2: Q = e^{−x/2};  dof = 1: Q = erfc(√(x/2)).
    for x in (0.1, 1.0, 5.0, 40.0):
        assert chi2.chi2_sf(x, 2) == pytest.approx(math.exp(-x / 2), rel=1e-12)
        assert chi2.chi2_sf(x, 1) == pytest.approx(math.erfc(math.sqrt(x / 2)), rel=1e-10)
        y = x / 2  # dof = 6: Q = e^{−y}(1 + y + y²/2)
        assert chi2.chi2_sf(x, 6) == pytest.approx(math.exp(-y) * (1 + y + y * y / 2), rel=1e-12)


@pytest.mark.parametrize("x,dof,p", [
    # upper percentage points of χ² (standard statistical tables, e.g. Abramowitz & Stegun ch. 26)
    (3.841458820694124, 1, 0.05), (6.634896601021214, 1, 0.01), (10.827566170662733, 1, 0.001),
    (18.307038053275146, 10, 0.05), (23.209251158954356, 10, 0.01),
    (124.34211340400407, 100, 0.05), (135.80672317102676, 100, 0.01),
    (2.7055434540954146, 1, 0.1),
])
def test_chi2_sf_at_tabulated_quantiles(x, dof, p):
    assert chi2.chi2_sf(x, dof) == pytest.approx(p, rel=1e-5)


@pytest.mark.parametrize("dof", [2, 10, 100, 1000])
def test_chi2_sf_even_dof_is_a_poisson_sum(dof):
    """For even dof, Q(k, y) = Σ_{j<k} e^{−y} y^j / j! (k = dof/2, y = x/2): an oracle independent of the
    series and continued fraction, on both sides of their switch at y = k + 1, up to large dof."""
    k = dof // 2
    for x in np.concatenate([dof * np.array([0.3, 0.8, 0.95, 1.0, 1.05, 1.3, 2.0]), [dof + 2.0]]):
        y = x / 2
        want = math.fsum(math.exp(j * math.log(y) - y - math.lgamma(j + 1)) for j in range(k))
        assert chi2.chi2_sf(x, dof) == pytest.approx(want, rel=1e-10, abs=1e-300)


def test_chi2_sf_limits_and_monotonicity():
    assert chi2.chi2_sf(0.0, 5) == 1.0
    assert chi2.chi2_sf(math.inf, 5) == 0.0
    assert 0.0 <= chi2.chi2_sf(5000.0, 10) < 1e-300
    x = np.linspace(0.0, 300.0, 301)
    for dof in (1, 7, 150):
        q = [chi2.chi2_sf(v, dof) for v in x]
        assert np.all(np.diff(q) <= 0) and q[0] == 1.0
        # the median of χ²_k is ≈ k (1 − 2/(9k))³ (Wilson–Hilferty), exact to < 1 % in p here
        assert chi2.chi2_sf(dof * (1 - 2 / (9 * dof)) ** 3, dof) == pytest.approx(0.5, abs=0.01)
    with pytest.raises(ValueError):
        chi2.chi2_sf(1.0, 0)


def test_sidak_level():
    assert chi2.sidak_level(0.01, 1) == pytest.approx(0.01)
    # k tests at the corrected level fail together with probability α
    assert 1 - (1 - chi2.sidak_level(0.01, 8)) ** 8 == pytest.approx(0.01, rel=1e-12)
    with pytest.raises(ValueError):
        chi2.sidak_level(1.5, 2)


# --- Pearson's test and cell merging ----------------------------------------------------------------------


def test_pearson_by_hand():
    r = chi2.pearson([12, 8, 30, 50], [10, 10, 30, 50])
    assert r.statistic == pytest.approx(0.8) and r.dof == 3
    assert r.p_value == pytest.approx(chi2.chi2_sf(0.8, 3))


def test_low_expectation_cells_are_merged_smallest_first():
    expected = np.array([0.5, 1.0, 2.0, 2.5, 4.0, 6.0, 100.0, 0.0])
    observed = np.array([1, 0, 3, 2, 5, 6, 99, 0])
    r = chi2.pearson(observed, expected)
    # 0.5 + 1 + 2 + 2.5 = 6 → one cell; 4 + 6 = 10 → one cell; 100 alone; the empty cell dropped
    assert (r.cells, r.merged_into, r.dof) == (7, 3, 2)
    want = (6 - 6) ** 2 / 6 + (11 - 10) ** 2 / 10 + (99 - 100) ** 2 / 100
    assert r.statistic == pytest.approx(want)
    # a remainder below 5 at the end joins the last group, so no merged cell expects fewer than 5:
    # 3 + 3 = 6 → one cell; 3 + 3 → 6, then the remaining 3 joins it → 9
    r = chi2.pearson([1, 4, 3, 3, 4], [3.0] * 5)
    assert (r.merged_into, r.dof) == (2, 1)
    assert r.statistic == pytest.approx(1 / 6 + 1 / 9)
    with pytest.raises(AssertionError, match="fewer than two cells"):
        chi2.pearson([3, 4], [3.0, 4.0])


def test_pearson_refuses_bad_input():
    with pytest.raises(AssertionError, match="zero probability"):
        chi2.pearson([10, 10, 1], [10.5, 10.5, 0.0])
    with pytest.raises(ValueError, match="totals differ"):
        chi2.pearson([10, 10], [10, 20])
    with pytest.raises(AssertionError, match="finite"):
        chi2.pearson([10, 10], [25, -5])


# --- whole tests: accept right, reject wrong --------------------------------------------------------------

N = 100_000


def _cosine_directions(n, seed=1):
    """Cosine-weighted hemisphere samples (Malley's method): pdf cosθ/π."""
    u = np.random.default_rng(seed).random((2, n))
    r, phi = np.sqrt(u[0]), 2 * math.pi * u[1]
    return np.stack((r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u[0])))


def _cosine_pdf(wi):
    return np.maximum(wi[2], 0.0) / math.pi


def _cosine_power_pdf(e):
    return lambda wi: (e + 1) / (2 * math.pi) * np.maximum(wi[2], 0.0) ** e


def test_accepts_cosine_sampler():
    r = chi2.direction_sampler_test(_cosine_directions(N), True, _cosine_pdf, n_cos=24, n_phi=48)
    chi2.assert_accepted(r, what="cosine samples")
    assert r.dof > 1000


def test_rejects_cosine_sampler_against_uniform_pdf():
    r = chi2.direction_sampler_test(_cosine_directions(N), True, lambda wi: np.full(wi.shape[1], 0.5 / math.pi),
                                    n_cos=24, n_phi=48)
    assert r.p_value < 1e-100, r
    with pytest.raises(AssertionError, match="do not follow the pdf"):
        chi2.assert_accepted(r)


def test_rejects_slightly_wrong_lobe():
    """Power: cosθ samples against a cos^1.1 θ pdf (a 10 % error in a lobe exponent) are rejected."""
    r = chi2.direction_sampler_test(_cosine_directions(N), True, _cosine_power_pdf(1.1), n_cos=24, n_phi=48)
    assert r.rejected(), r


def test_rejects_phi_dependence_missing_from_the_pdf():
    """Samples whose φ is squeezed towards +x (a wrong azimuth), against the isotropic pdf."""
    wi = _cosine_directions(N)
    phi = np.arctan2(wi[1], wi[0])
    phi = phi - 0.05 * np.sin(phi)   # a derivative 1 − 0.05 cos φ: 5 % more density near φ = 0
    r_xy = np.hypot(wi[0], wi[1])
    wrong = np.stack((r_xy * np.cos(phi), r_xy * np.sin(phi), wi[2]))
    assert chi2.direction_sampler_test(wrong, True, _cosine_pdf, n_cos=24, n_phi=48).rejected()


def test_elsewhere_cell_catches_lost_mass():
    """A sampler that loses 1 % of its samples (marked invalid) while its pdf claims 0.5 % (or none)."""
    wi = _cosine_directions(N)
    on_grid = np.random.default_rng(3).random(N) > 0.01
    r = chi2.direction_sampler_test(wi, on_grid, lambda w: 0.995 * _cosine_pdf(w), n_cos=24, n_phi=48)
    assert r.rejected(), r
    with pytest.raises(AssertionError, match="zero probability"):
        chi2.direction_sampler_test(wi, on_grid, _cosine_pdf, n_cos=24, n_phi=48)
    # and the same samples against the pdf scaled to the kept mass are accepted
    r = chi2.direction_sampler_test(wi, on_grid, lambda w: 0.99 * _cosine_pdf(w), n_cos=24, n_phi=48)
    chi2.assert_accepted(r)


def test_whole_sphere_domain():
    """Uniform directions on the sphere against 1/(4π) over cos θ ∈ [−1, 1]; a sampler that never goes
    below the horizon is rejected on the same domain."""
    u = np.random.default_rng(5).random((2, N))
    c, phi = 1 - 2 * u[0], 2 * math.pi * u[1]
    s = np.sqrt(1 - c * c)
    wi = np.stack((s * np.cos(phi), s * np.sin(phi), c))
    kw = dict(n_cos=24, n_phi=48, cos_range=(-1.0, 1.0))
    chi2.assert_accepted(chi2.direction_sampler_test(wi, True, lambda w: np.full(w.shape[1], 0.25 / math.pi), **kw))
    upper = wi.copy()
    upper[2] = np.abs(wi[2])   # mirrored into the upper hemisphere
    assert chi2.direction_sampler_test(upper, True, lambda w: np.full(w.shape[1], 0.25 / math.pi), **kw).rejected()


def test_samples_outside_the_domain_fail():
    wi = _cosine_directions(1000)
    wi[2, 7] = -0.3
    with pytest.raises(AssertionError, match="outside"):
        chi2.direction_sampler_test(wi, True, _cosine_pdf, n_cos=4, n_phi=8)
    wi[:, 7] = np.nan
    with pytest.raises(AssertionError, match="outside"):
        chi2.direction_sampler_test(wi, True, _cosine_pdf, n_cos=4, n_phi=8)


def test_unnormalised_pdf_fails():
    with pytest.raises(AssertionError, match="integrates to"):
        chi2.direction_sampler_test(_cosine_directions(1000), True, lambda w: 1.01 * _cosine_pdf(w),
                                    n_cos=4, n_phi=8)


def test_too_coarse_quadrature_fails():
    """A narrow lobe integrated with one node per cell is caught by the sub vs 2·sub comparison."""
    def narrow(wi):   # normalised cos^400 lobe around the normal
        return _cosine_power_pdf(400.0)(wi)
    with pytest.raises(AssertionError, match="quadrature too coarse"):
        chi2.direction_sampler_test(_cosine_directions(N), True, narrow, n_cos=24, n_phi=8, order=1)


def test_hemisphere_cell_mass_of_cosine_lobe():
    """∫ cosθ/π over a cell = (c₁² − c₀²)/2 · Δφ/π, exact for Gauss–Legendre of order ≥ 1 in cosθ."""
    m = chi2.hemisphere_cell_mass(_cosine_pdf, 5, 7, order=2)
    c = np.linspace(0, 1, 6)
    want = np.outer((c[1:] ** 2 - c[:-1] ** 2) / 2, np.full(7, 2 / 7))
    np.testing.assert_allclose(m, want, rtol=1e-12)


def test_interval_sampler_accepts_and_rejects():
    x = np.sqrt(np.random.default_rng(4).random(N))          # pdf 2x on [0, 1]
    edges = np.linspace(0.0, 1.0, 41)
    chi2.assert_accepted(chi2.interval_sampler_test(x, lambda t: 2 * t, edges))
    assert chi2.interval_sampler_test(x, lambda t: np.ones_like(t), edges).p_value < 1e-100
    assert chi2.interval_sampler_test(x, lambda t: 2.1 * t ** 1.1, edges).rejected()
    with pytest.raises(AssertionError, match="outside"):
        chi2.interval_sampler_test(np.append(x, 1.5), lambda t: 2 * t, edges)


def test_rejects_a_real_brdf_sampler_against_a_neighbouring_roughness():
    """Torrance–Sparrow samples for m = 0.3 against the pdf of m = 0.33: the harness sees a 10 %
    roughness error with the sample count the BRDF tests use."""
    wo = np.array([math.sin(math.radians(40.0)), 0.0, math.cos(math.radians(40.0))])

    def point(n):   # n shading points at the origin, normal +z, viewer wo, λ = 550 nm
        z = np.tile([[0.0], [0.0], [1.0]], (1, n))
        return ShadingPoint(np.zeros((3, n)), z, z, np.tile(wo.reshape(3, 1), (1, n)), np.full((1, n), 550.0))

    right, wrong = TorranceSparrow(0.47, 2.4, 0.3), TorranceSparrow(0.47, 2.4, 0.33)
    rng = np.random.default_rng(8)
    s = right.sample(point(N), rng.random(N), rng.random((2, N)))

    def pdf_of(model):
        return lambda wi: model.pdf(point(wi.shape[1]), wi)

    kw = dict(n_cos=24, n_phi=48, order=8)
    chi2.assert_accepted(chi2.direction_sampler_test(s.wi, s.valid, pdf_of(right), **kw))
    assert chi2.direction_sampler_test(s.wi, s.valid, pdf_of(wrong), **kw).p_value < 1e-6
