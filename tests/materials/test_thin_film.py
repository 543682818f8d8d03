"""Thin films (engine.polarisation.thin_film, engine.materials.thin_film) against an independent oracle:
the characteristic-matrix method of a single layer (Born & Wolf §1.6), per polarisation."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.materials.base import ShadingPoint
from engine.materials.thin_film import ThinFilmDielectric
from engine.polarisation.fresnel import fresnel_reflection_abcs
from engine.polarisation.mueller import abcs_matrix, is_realisable
from engine.polarisation.thin_film import film_amplitudes, film_reflection_abcs, film_transmission_abcs


def characteristic_matrix_reflectance(cos1, n1, nf, d, n3, lam, pol):
    """|r|² of one layer by the 2 × 2 characteristic matrix, admittances Y = n cosθ (s) or n / cosθ (p)."""
    sin1 = math.sqrt(max(1.0 - cos1 * cos1, 0.0))
    cosf = np.sqrt(1.0 - (n1 * sin1 / nf) ** 2 + 0j)
    cos3 = np.sqrt(1.0 - (n1 * sin1 / n3) ** 2 + 0j)
    if pol == "s":
        y1, yf, y3 = n1 * cos1, nf * cosf, n3 * cos3
    else:
        y1, yf, y3 = n1 / cos1, nf / cosf, n3 / cos3
    delta = 2.0 * math.pi * nf * d * cosf / lam
    m11, m12 = np.cos(delta), -1j * np.sin(delta) / yf
    m21, m22 = -1j * yf * np.sin(delta), np.cos(delta)
    r = (y1 * m11 + y1 * y3 * m12 - m21 - y3 * m22) / (y1 * m11 + y1 * y3 * m12 + m21 + y3 * m22)
    return abs(r) ** 2


@pytest.mark.parametrize("n1,nf,n3", [(1.0, 1.33, 1.5), (1.0, 1.38, 1.52), (1.0, 2.0, 1.5), (1.5, 1.33, 1.0),
                                      (1.33, 1.5, 1.0)])
@pytest.mark.parametrize("theta", [0.0, 20.0, 45.0, 70.0, 85.0])
@pytest.mark.parametrize("d,lam", [(100.0, 450.0), (380.0, 550.0), (1200.0, 700.0)])
def test_both_polarisations_match_the_characteristic_matrix(n1, nf, n3, theta, d, lam):
    c = math.cos(math.radians(theta))
    r_s, r_p = film_amplitudes(c, n1, nf, d, n3, lam)
    for r, pol in ((r_s, "s"), (r_p, "p")):
        want = characteristic_matrix_reflectance(c, n1, nf, d, n3, lam, pol)
        assert abs(r) ** 2 == pytest.approx(want, abs=1e-12)


def test_quarter_wave_coating_cancels_reflection_at_normal_incidence():
    nf = math.sqrt(1.5)               # the ideal single-layer AR coating on n = 1.5
    A, B, C, S = film_reflection_abcs(1.0, 1.0, nf, 550.0 / (4 * nf), 1.5, 550.0)
    assert A == pytest.approx(0.0, abs=1e-15)
    nf = 1.38                          # MgF2: ((n1 n3 − nf²) / (n1 n3 + nf²))²
    A, *_ = film_reflection_abcs(1.0, 1.0, nf, 550.0 / (4 * nf), 1.5, 550.0)
    assert A == pytest.approx(((1.5 - nf ** 2) / (1.5 + nf ** 2)) ** 2, rel=1e-12)


def test_zero_thickness_is_the_bare_interface():
    c = np.linspace(0.0, 1.0, 41)
    for eta in (1.5, 1 / 1.5):
        got = film_reflection_abcs(c, 1.0, 1.33, 0.0, eta, 550.0)
        want = fresnel_reflection_abcs(c, eta + 0j)
        for g, w in zip(got, want):
            np.testing.assert_allclose(g, w, atol=1e-14)


@settings(deadline=None, max_examples=200)
@given(st.floats(0.0, 1.0), st.floats(1.0, 2.5), st.floats(1.0, 2.5), st.floats(0.0, 3000.0), st.floats(380.0, 780.0))
def test_reflection_and_transmission_are_realisable_and_conserve_energy(c, nf, n3, d, lam):
    A, B, C, S = film_reflection_abcs(c, 1.0, nf, d, n3, lam)
    At, Bt, Ct, St = film_transmission_abcs(A + B, A - B)
    assert 0.0 <= A + B <= 1.0 and 0.0 <= A - B <= 1.0
    assert A + At == pytest.approx(1.0, abs=1e-12)
    for M in (abcs_matrix(A, B, C, S), abcs_matrix(At, Bt, Ct, St)):
        assert is_realisable(np.asarray(M)[..., None]).all()


def test_a_soap_film_reflects_elliptically_polarised_light():
    """Off a free 250 nm soap film (n 1.33, air on both sides) at 75°, light linearly polarised at 45° comes
    back with circular polarisation (S ≠ 0, 17 % of A): the film's s–p phase difference; a bare interface
    below its critical angle has none."""
    c = math.cos(math.radians(75.0))
    A, B, C, S = film_reflection_abcs(c, 1.0, 1.33, 250.0, 1.0, 550.0)
    assert abs(S) > 0.1 * A
    assert fresnel_reflection_abcs(c, 1.33 + 0j)[3] == pytest.approx(0.0, abs=1e-15)


def test_model_samples_the_coated_interface():
    n = 2000
    rng = np.random.default_rng(5)
    z = np.tile([[0.0], [0.0], [1.0]], (1, n))
    wo = rng.normal(size=(3, n))
    wo[2] = np.abs(wo[2]) + 0.05
    wo /= np.linalg.norm(wo, axis=0)
    lam = np.tile([[450.0], [520.0], [600.0], [680.0]], (1, n))
    sp = ShadingPoint(np.zeros((3, n)), z, z, wo, lam)
    model = ThinFilmDielectric(1.5, 1.33, 400.0)
    d = model.delta_reflection(sp)
    A, *_ = film_reflection_abcs(wo[2][None, :], 1.0, 1.33, 400.0, 1.5, lam)
    np.testing.assert_allclose(d.A, A, rtol=1e-12)
    # the expected sample weight's M00 per wavelength: reflectance + transmittance × 1/η² (radiance)
    u = rng.random(n)
    bs = model.sample(sp, u, rng.random((2, n)))
    through = bs.wi[2] < 0
    assert through.any() and (~through).any()
    assert np.all(np.isfinite(bs.weight.matrix()))
    assert not model.scatter_delta(None)


@pytest.mark.parametrize("n3", [0.27 + 2.8j, 1.2 + 7.0j, 2.5 + 0.3j])
@pytest.mark.parametrize("theta", [0.0, 30.0, 60.0, 85.0])
@pytest.mark.parametrize("nf,d,lam", [(1.5, 400.0, 550.0), (2.0, 120.0, 450.0)])
def test_a_film_on_a_metal_matches_the_characteristic_matrix(n3, theta, nf, d, lam):
    """The absorbing substrate (Cycles' Thin Film on its metal): both reflectances as the oracle's."""
    c = math.cos(math.radians(theta))
    r_s, r_p = film_amplitudes(c, 1.0, nf, d, n3, lam)
    assert abs(r_s) ** 2 == pytest.approx(characteristic_matrix_reflectance(c, 1.0, nf, d, n3, lam, "s"), abs=1e-12)
    assert abs(r_p) ** 2 == pytest.approx(characteristic_matrix_reflectance(c, 1.0, nf, d, n3, lam, "p"), abs=1e-12)
    assert abs(r_s) <= 1 and abs(r_p) <= 1


def test_a_filmed_rough_facet_lobe_is_the_bare_lobe_times_the_films_fresnel_per_facet():
    """Torrance–Sparrow with a thin film: the facet's Fresnel matrix is the film's at the half-vector angle, so
    M_film = M_bare · A_film/A_bare per wavelength (A the matrices' M00), both realisable; thickness ≤ 0.1 nm is
    no film (Cycles' cutoff)."""
    from engine.materials.torrance_sparrow import TorranceSparrow
    from engine.spectral import WavelengthLookup
    rng = np.random.default_rng(4)
    N = 400
    n_s = np.tile([[0.0], [0.0], [1.0]], (1, N))
    wo, wi = rng.normal(size=(3, N)), rng.normal(size=(3, N))
    wo[2], wi[2] = np.abs(wo[2]) + 0.05, np.abs(wi[2]) + 0.05
    wo /= np.linalg.norm(wo, axis=0)
    wi /= np.linalg.norm(wi, axis=0)
    lam = np.tile([[420.0], [530.0], [640.0]], (1, N))
    sp = ShadingPoint(np.zeros((3, N)), n_s, n_s, wo, lam, False, WavelengthLookup(lam))
    for n, k in ((0.2, 3.4), (1.6, 0.0)):
        bare = TorranceSparrow(n, k, 0.3, distribution="ggx")
        filmed = TorranceSparrow(n, k, 0.3, distribution="ggx", film_n=1.4, film_thickness=350.0)
        same = TorranceSparrow(n, k, 0.3, distribution="ggx", film_n=1.4, film_thickness=0.1)
        h = wi + wo
        cos_h = np.linalg.norm(h, axis=0) / 2.0
        A_film = film_reflection_abcs(cos_h[None, :], 1.0, 1.4, 350.0, n + 1j * k, lam)[0]
        A_bare = fresnel_reflection_abcs(cos_h[None, :], np.full((1, 1), n + 1j * k))[0]
        Mb, Mf = bare.eval(sp, wi).matrix(), filmed.eval(sp, wi).matrix()
        np.testing.assert_allclose(Mf[0, 0], Mb[0, 0] * A_film / A_bare, rtol=1e-10, atol=1e-300)
        np.testing.assert_array_equal(same.eval(sp, wi).matrix(), Mb)
        assert all(is_realisable(Mf[:, :, j, :]).all() for j in range(3))
        assert filmed.flags.retarding and filmed.flags.wavelength_dependent
