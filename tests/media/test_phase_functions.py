"""Phase functions (engine/media): normalised, sampled exactly, realisable, and Rayleigh's analytic DoLP.

- ∫ a1 dΩ = 1 by Gauss–Legendre quadrature over panels in Θ that refine geometrically towards Θ = 0
  (the forward peaks of HG g = 0.99, Fournier–Forand and Cycles' Mie fit);
- ``sample`` follows ``pdf``: Pearson's χ² (tests/support/chi2.py) of the sampled Θ = arccos(−wi·wo)
  over cells refining towards 0, and of the directions over (cos, φ) cells for the smooth ones;
- every matrix realisable (Cloude coherency ≥ 0, engine.polarisation.mueller.is_realisable) and the
  output of random fully polarised inputs of DoP ≤ 1;
- Rayleigh: DoLP of scattered unpolarised light = (1−δ) sin²Θ/(1 + δ + (1−δ) cos²Θ) exactly, polarised
  ⟂ the scattering plane (S1 > 0 in the scattering-plane frames), δ = 1 a depolariser;
- hard cases: Θ = 0 and π, wi = ±wo (degenerate frames), g = ±1 (clamped as Cycles), δ = 0 and 1.
"""

import math

import numpy as np
import pytest

from engine.media.catalogue import PHASE_MODELS, make_phase, phase_matrices_at
from engine.media.draine import draine_cdf, draine_density
from engine.media.phase import sample_one_plus_beta_mu2
from engine.polarisation.mueller import is_realisable
from tests.support import chi2

CASES = [
    ("rayleigh", {"depolarisation": "0"}), ("rayleigh", {"depolarisation": "0.0279"}),
    ("rayleigh", {"depolarisation": "1"}),
    ("henyey_greenstein", {"g": "0"}), ("henyey_greenstein", {"g": "0.7"}), ("henyey_greenstein", {"g": "-0.5"}),
    ("henyey_greenstein", {"g": "1"}), ("henyey_greenstein", {"g": "-1"}), ("henyey_greenstein", {"g": "1e-7"}),
    ("draine", {"g": "0.5", "alpha": "3"}), ("draine", {"g": "-0.3", "alpha": "250"}),
    ("draine", {"g": "0", "alpha": "1"}), ("draine", {"g": "2e-6", "alpha": "250"}),
    ("draine", {"g": "0.8", "alpha": "0"}),
    ("fournier_forand", {"backscatter": "0.1", "ior": "1.33"}),
    ("fournier_forand", {"backscatter": "0.01", "ior": "1.1"}),
    ("fournier_forand", {"backscatter": "0.5", "ior": "1.05"}),
    ("cycles_mie", {"diameter": "0"}), ("cycles_mie", {"diameter": "0.05"}), ("cycles_mie", {"diameter": "1"}),
    ("cycles_mie", {"diameter": "3"}), ("cycles_mie", {"diameter": "20"}),
    ("mie", {"radius": "0.5"}), ("mie", {"radius": "0.3", "n": "1.5", "k": "0.2"}),
]
IDS = [f"{name}-{'-'.join(p.values())}" for name, p in CASES]
#: a wavelength between two Mie tables (the blend of two tables is what is sampled)
LAM = 552.5


def mu_edges(n_fine: int = 40, n_coarse: int = 60, first: float = 1e-6) -> np.ndarray:
    """Cell edges in μ = cos Θ over [−1, 1], from cells in Θ geometric from ``first`` to 0.3 rad at both ends
    (the forward and backward peaks) and uniform between.  Cells and quadrature are in μ, the variable the
    phase functions take: cos Θ of a tiny Θ carries an absolute rounding error of 10⁻¹⁶, 2 % of 1 − μ at
    Θ = 10⁻⁷, where Fournier–Forand's density is steep."""
    fine = np.geomspace(first, 0.3, n_fine)
    theta = np.concatenate(([0.0], fine, np.linspace(0.3, np.pi - 0.3, n_coarse + 1)[1:-1], np.pi - fine[::-1],
                            [np.pi]))
    return np.unique(np.cos(theta))


def mu_density(phase, lam=LAM):
    """The density of μ = cos Θ: 2π a1(μ)."""
    return lambda m: 2.0 * np.pi * phase.pdf_mu(m, lam)


def test_every_declared_phase_function_is_tested():
    assert {name for name, _ in CASES} == set(PHASE_MODELS)


@pytest.mark.parametrize("name, params", CASES, ids=IDS)
def test_normalised(name, params):
    """∫ a1 dΩ = 1 (composite Gauss–Legendre in μ, 16 nodes per cell, cells refining towards Θ = 0 and π),
    Fournier–Forand's Dirac part (engine.media.fournier_forand.THETA_MIN) included."""
    phase = make_phase(name, params)
    edges = mu_edges(200, 400, 1e-9)
    if name == "fournier_forand":        # its integrable divergence at μ = 1: the top cell from its CDF
        edges = edges[edges <= math.cos(1e-6)]
        mu = np.linspace(-1.0, edges[-1], 9)
        quadrature = [chi2.interval_cell_mass(mu_density(phase), np.append(edges[edges < m], m), order=16).sum()
                      for m in mu[1:]]
        np.testing.assert_allclose(phase.cdf_mu(mu[1:]), quadrature, rtol=1e-9, atol=1e-12)
    total = chi2.interval_cell_mass(mu_density(phase), edges, order=16).sum()
    rest = 1.0 - phase.cdf_mu(edges[-1]) if name == "fournier_forand" else 0.0
    assert abs(total + rest - 1.0) < 2e-6, (total, rest)


@pytest.mark.parametrize("name, params", CASES, ids=IDS)
def test_sampling_chi2_in_theta(name, params):
    """``sample`` follows ``pdf``: μ = cos Θ of 100 000 samples over cells refining towards Θ = 0 and π (the
    Dirac part of Fournier–Forand apart, its count binomial), and the pdf that ``sample`` reports equals
    ``pdf`` of its direction."""
    phase = make_phase(name, params)
    n = 100_000
    rng = np.random.default_rng(hash(name + str(params)) % 2**32)
    wo = np.tile(np.array([[0.3], [-0.4], [math.sqrt(0.75)]]), (1, n))
    lam = np.full((3, n), LAM)
    lam[1:] = 700.0
    s = phase.sample(wo, rng.random((2, n)), lam)
    assert np.all(s.valid)
    np.testing.assert_allclose(s.pdf, phase.pdf_mu(s.mu, LAM), rtol=1e-12, atol=1e-300)
    wide = s.mu < 1 - 1e-6           # pdf(wo, wi) recomputes μ from the directions: 1e-16 off
    np.testing.assert_allclose(s.pdf[wide], phase.pdf(wo, s.wi, lam)[wide], rtol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(s.wi, axis=0), 1.0, atol=1e-12)
    np.testing.assert_allclose(-np.sum(s.wi * wo, axis=0), s.mu, atol=1e-12)
    dirac = phase.forward_mass if phase.forward_dirac else 0.0
    k = int(s.is_delta.sum())
    assert abs(k - n * dirac) <= 5 * math.sqrt(n * dirac * (1 - dirac)) + 1, (k, n * dirac)
    assert np.all(s.mu[s.is_delta] == 1.0) and np.all(s.mu[~s.is_delta] < 1.0)
    np.testing.assert_allclose(s.weight.matrix()[0, 0, 0, s.is_delta], 1.0)
    edges = mu_edges()
    if name == "fournier_forand":        # cell masses from its CDF (checked against quadrature in test_normalised)
        counts = np.bincount(np.clip(np.searchsorted(edges, s.mu, side="right") - 1, 0, edges.size - 2),
                             minlength=edges.size - 1)
        result = chi2.pearson(counts, n * np.diff(phase.cdf_mu(edges)))
    else:
        result = chi2.interval_sampler_test(s.mu, mu_density(phase), edges, order=8, sub=2)
    chi2.assert_accepted(result, test_count=len(CASES), what=f"{name} samples")


@pytest.mark.parametrize("name, params", [c for c in CASES if c[0] in ("rayleigh", "draine", "mie")][:6])
def test_sampling_chi2_directions(name, params):
    """Directions over (cos Θ, φ) cells about −wo = +z: the azimuth is uniform and independent of Θ."""
    phase = make_phase(name, params)
    n = 100_000
    rng = np.random.default_rng(7)
    wo = np.tile(np.array([[0.0], [0.0], [-1.0]]), (1, n))
    lam = np.full((1, n), LAM)
    s = phase.sample(wo, rng.random((2, n)), lam)
    z = np.zeros((3, 1))
    z[2] = -1.0

    def pdf(wi):
        return phase.pdf(np.tile(z, (1, wi.shape[1])), wi, np.full((1, wi.shape[1]), LAM))
    result = chi2.direction_sampler_test(s.wi, s.valid & ~s.is_delta, pdf, n_cos=20, n_phi=12, cos_range=(-1.0, 1.0))
    chi2.assert_accepted(result, test_count=6, what=f"{name} directions")


@pytest.mark.parametrize("name, params", CASES, ids=IDS)
def test_realisable_and_finite(name, params):
    """Cloude's criterion at 2001 angles including Θ = 0 and π; outputs of random pure states have DoP ≤ 1;
    M00 = pdf at the sampling wavelength; eval with degenerate frames (wi = ±wo) finite."""
    phase = make_phase(name, params)
    mu = np.concatenate(([-1.0, 1.0], np.cos(np.linspace(0.0, np.pi, 1999))))
    M = phase.matrix(mu, LAM)                                          # (n, 4, 4)
    assert np.all(np.isfinite(M)) and np.all(M[:, 0, 0] >= 0)
    np.testing.assert_allclose(M[:, 0, 0], phase.pdf_mu(mu, LAM), rtol=1e-12)
    assert np.all(is_realisable(np.moveaxis(M, (1, 2), (0, 1)), tol=1e-9))
    rng = np.random.default_rng(3)
    v = rng.normal(size=(3, mu.size))
    s_in = np.vstack((np.ones(mu.size), v / np.linalg.norm(v, axis=0)))
    out = np.einsum("nij,jn->in", M, s_in)
    assert np.all(np.linalg.norm(out[1:], axis=0) <= out[0] * (1 + 1e-9) + 1e-300)
    for sign in (1.0, -1.0):                                           # forward (wi = −wo) and backward
        wo = np.array([[0.0], [0.6], [0.8]])
        value = phase.eval(wo, -sign * wo, np.full((2, 1), LAM))
        assert np.isfinite(value.matrix()).all() and np.isfinite(value.x_in).all()
        np.testing.assert_allclose(np.linalg.norm(value.x_in), 1.0)


@pytest.mark.parametrize("delta", [0.0, 0.0279, 0.3, 1.0])
def test_rayleigh_dolp_analytic(delta):
    """Single scattering of unpolarised light: DoLP = (1−δ) sin²Θ/(1+δ+(1−δ)cos²Θ), along s (S1 > 0), S2 = S3 = 0."""
    phase = make_phase("rayleigh", {"depolarisation": str(delta)})
    angles = np.linspace(0.0, 180.0, 37)
    got = phase_matrices_at(phase, angles)
    c = np.cos(np.radians(angles))
    expected = (1 - delta) * (1 - c * c) / (1 + delta + (1 - delta) * c * c)
    np.testing.assert_allclose(got["dolp_unpolarised"], expected, rtol=1e-12, atol=1e-15)
    M = np.array(got["mueller"])
    assert np.all(M[:, 1, 0] >= 0) and np.all(M[:, 2:, 0] == 0)
    if delta == 1.0:
        np.testing.assert_allclose(M[:, 0, 0], 1 / (4 * np.pi), rtol=1e-14)
        assert np.all(M[:, 1:, :] == 0)


def test_rayleigh_is_chandrasekhar_at_delta_0():
    """δ = 0: (3/16π)[[1+μ², 1−μ², 0, 0], [1−μ², 1+μ², 0, 0], [0, 0, 2μ, 0], [0, 0, 0, 2μ]] (no retardance)."""
    mu = np.linspace(-1, 1, 9)
    M = make_phase("rayleigh", {}).matrix(mu)
    k = 3 / (16 * np.pi)
    expected = np.zeros((9, 4, 4))
    expected[:, 0, 0] = expected[:, 1, 1] = k * (1 + mu * mu)
    expected[:, 0, 1] = expected[:, 1, 0] = k * (1 - mu * mu)
    expected[:, 2, 2] = expected[:, 3, 3] = 2 * k * mu
    np.testing.assert_allclose(M, expected, atol=1e-16)


def test_frames_rotate_with_the_scattering_plane():
    """eval's frames are s = unit(k_i × k_o) on both beams, ⟂ both directions; the matrix's S1 row follows
    the scattering plane (light scattered by 90° is polarised ⟂ the plane holding k_i and k_o)."""
    phase = make_phase("rayleigh", {})
    wo = np.array([[0.0], [0.0], [1.0]])
    wi = np.array([[-1.0], [0.0], [0.0]])                 # k_i = +x, k_o = +z: plane x–z, s = ±y
    v = phase.eval(wo, wi, np.full((1, 1), 550.0))
    np.testing.assert_allclose(np.abs(v.x_in[:, 0]), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(v.x_in, v.x_out)
    M = v.matrix()[:, :, 0, 0]
    assert M[1, 0] == pytest.approx(M[0, 0])              # fully polarised along s = y


def test_hg_clamped_as_cycles():
    a, b = make_phase("henyey_greenstein", {"g": "1"}), make_phase("henyey_greenstein", {"g": "0.999"})
    assert a.g == b.g == 0.999 and make_phase("henyey_greenstein", {"g": "-1"}).g == -0.999


def test_draine_cdf_matches_quadrature_and_is_stable_at_small_g():
    """The closed-form CDF against quadrature of the density (g from 1e-8 to 0.99, α 0 … 250), and its g → 0
    limit (μ + 1 + α(μ³ + 1)/3)/(2 + 2α/3) without cancellation."""
    mu = np.linspace(-1.0, 1.0, 11)
    for g in (1e-8, 1e-3, 0.3, -0.6, 0.99):
        for alpha in (0.0, 1.0, 250.0):
            expected = []
            for m in mu:
                edges = mu_edges(100, 200, 1e-8)
                edges = np.append(edges[edges < m], m)
                def density(x, g=g, a=alpha):
                    return 2 * np.pi * draine_density(x, g, a)
                expected.append(chi2.interval_cell_mass(density, edges, order=16).sum())
            np.testing.assert_allclose(draine_cdf(mu, g, alpha), expected, atol=1e-10, err_msg=f"g={g}, α={alpha}")
            assert np.all(np.diff(draine_cdf(np.linspace(-1.0, 1.0, 4001), g, alpha)) >= 0)
    alpha = 250.0
    np.testing.assert_allclose(draine_cdf(mu, 1e-12, alpha), (mu + 1 + alpha * (mu ** 3 + 1) / 3) / (2 + 2 * alpha / 3),
                               rtol=1e-10, atol=1e-15)


def test_one_plus_beta_mu2_inversion():
    """The cubic's root makes the CDF equal u, for β from 0 to 10⁶."""
    u = np.linspace(0.0, 1.0, 101)
    for beta in (0.0, 1e-9, 0.75, 1.0, 250.0, 1e6):
        mu = sample_one_plus_beta_mu2(u, beta)
        cdf = (mu + 1 + beta * (mu ** 3 + 1) / 3) / (2 + 2 * beta / 3)
        np.testing.assert_allclose(cdf, u, atol=2e-12)
