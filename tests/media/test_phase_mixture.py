"""engine.media.mixture.PhaseMixture (Blender's Mix / Add Shader of volume shaders): its matrix is the weighted
sum of its components' (against the components evaluated on their own), it is normalised, and its sampling
follows its pdf (Pearson's χ², tests/support/chi2.py), including a Fournier–Forand component's Dirac part."""

import numpy as np

from engine.media.catalogue import make_phase
from engine.media.mixture import PhaseMixture
from engine.polarisation.mueller import is_realisable
from tests.media.test_phase_functions import LAM, mu_density, mu_edges
from tests.support import chi2


def _mix():
    parts = [make_phase("henyey_greenstein", {"g": "0.6"}), make_phase("rayleigh", {"depolarisation": "0"}),
             make_phase("draine", {"g": "-0.3", "alpha": "2"})]
    return parts, PhaseMixture(parts, [2.0, 1.0, 1.0])


def test_matrix_is_the_weighted_sum_and_normalised():
    parts, mix = _mix()
    mu = np.linspace(-1.0, 1.0, 101)
    expect = 0.5 * parts[0].matrix(mu) + 0.25 * parts[1].matrix(mu) + 0.25 * parts[2].matrix(mu)
    np.testing.assert_allclose(mix.matrix(mu), expect, rtol=1e-14, atol=1e-300)
    edges = mu_edges()
    assert abs(chi2.interval_cell_mass(mu_density(mix), edges, order=16).sum() - 1.0) < 1e-9
    assert all(bool(is_realisable(M / M[0, 0])) for M in mix.matrix(mu))
    only_depolarising = PhaseMixture([parts[0], parts[2]], [1.0, 3.0])
    assert only_depolarising.elements(mu, LAM).kind == "depolarising"


def test_sampling_follows_the_pdf():
    _, mix = _mix()
    n = 100_000
    rng = np.random.default_rng(11)
    wo = np.tile(np.array([[0.0], [0.6], [0.8]]), (1, n))
    s = mix.sample(wo, rng.random((2, n)), np.full((2, n), LAM))
    assert np.all(s.valid)
    np.testing.assert_allclose(s.pdf, mix.pdf_mu(s.mu, LAM), rtol=1e-12)
    chi2.assert_accepted(chi2.interval_sampler_test(s.mu, mu_density(mix), mu_edges(), order=8, sub=2),
                         what="mixture samples")


def test_dirac_part_keeps_weight_one():
    ff = make_phase("fournier_forand", {"backscatter": "0.0183", "ior": "1.33"})
    mix = PhaseMixture([ff, make_phase("henyey_greenstein", {"g": "0"})], [1.0, 1.0])
    n = 200_000
    s = mix.sample(np.tile(np.array([[0.0], [0.0], [1.0]]), (1, n)), np.random.default_rng(3).random((2, n)),
                   np.full((1, n), LAM))
    k = int(s.is_delta.sum())
    p = 0.5 * ff.forward_mass
    assert abs(k - n * p) <= 5 * np.sqrt(n * p * (1 - p)) + 1
    np.testing.assert_allclose(s.weight.matrix()[0, 0, 0, s.is_delta], 1.0)
