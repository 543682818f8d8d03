"""A thin film on the rough dielectric's facets (engine.materials.rough_dielectric, ``film_n``/``film_thickness``:
Cycles' Thin Film on a rough Glass BSDF or Principled transmission): the smooth limit is the thin-film dielectric's
Dirac weights, energy ≤ 1 per wavelength, realisable matrices, the sampler's χ² and weights, and the unfilmed
lobes unchanged where the film is thinner than Cycles' cutoff.  Against Cycles:
tests/blender/test_cycles_refraction.py."""

import math

import numpy as np
import pytest

from engine.materials.base import ShadingPoint
from engine.materials.catalogue import MODELS
from engine.materials.rough_dielectric import RoughDielectric
from engine.polarisation.mueller import is_realisable
from engine.polarisation.thin_film import film_reflection_abcs, film_transmission_abcs
from tests.materials.test_rough_dielectric import integrated_lobes, sph, tile
from tests.support import chi2

ETA, FILM_N, FILM_NM = 1.5, 1.33, 350.0


def abcs(A, B, C, S):
    return np.array([[A, B, 0, 0], [B, A, 0, 0], [0, 0, C, S], [0, 0, -S, C]], dtype=np.float64)


@pytest.mark.parametrize("theta,inside", [(30.0, False), (70.0, False), (25.0, True), (60.0, True)])
def test_smooth_limit_is_the_thin_film_dielectric(theta, inside):
    """α = 10⁻³: the integrated lobes are Airy's reflection matrix at θ_o (S ≠ 0: the film's s–p phase; under total
    internal reflection a retarder) and the film's transmission 1 − R per polarisation / η², at 550 nm."""
    wo = sph(theta, 0.0, inside)
    R, T = integrated_lobes(RoughDielectric(ETA, 1e-3, "ggx", film_n=FILM_N, film_thickness=FILM_NM), wo)
    c = math.cos(math.radians(theta))
    n1, n3 = (1.0, ETA) if not inside else (ETA, 1.0)
    A, B, C, S = (float(np.ravel(v)[0]) for v in film_reflection_abcs(np.array([[c]]), n1, FILM_N, FILM_NM, n3,
                                                                        np.array([[550.0]])))
    eta = n3 / n1
    tir = (1.0 - c * c) / eta ** 2 > 1.0
    want_T = np.zeros((4, 4)) if tir else abcs(*film_transmission_abcs(A + B, A - B)) / eta ** 2
    np.testing.assert_allclose(R, abcs(A, B, C, S), atol=4e-3)
    np.testing.assert_allclose(T, want_T, atol=4e-3)
    assert abs(S) > 1e-4


def test_energy_realisability_and_per_wavelength_values():
    """Per wavelength (4 of them) the transported power R + η²T ≤ 1, matrices realisable, the film making the
    value depend on λ; a film thinner than Cycles' 0.1 nm is the bare interface (the compiled passes, same bits)."""
    rng = np.random.default_rng(8)
    model = RoughDielectric(ETA, 0.3, "ggx", film_n=FILM_N, film_thickness=FILM_NM)
    N = 3000
    wo = rng.normal(size=(3, N))
    wo /= np.linalg.norm(wo, axis=0)
    wi = rng.normal(size=(3, N))
    wi /= np.linalg.norm(wi, axis=0)
    lam = np.tile(np.array([[420.0], [500.0], [580.0], [660.0]]), (1, N))
    nrm = tile((0.0, 0.0, 1.0), N)
    sp = ShadingPoint(np.zeros((3, N)), nrm, nrm, wo, lam)
    M = model.eval(sp, wi).matrix()
    assert np.all(np.isfinite(M))
    for k in range(4):
        Mk = M[:, :, k, :]
        assert np.all(is_realisable(Mk / np.maximum(Mk[0, 0], 1e-300)))
    assert np.ptp(M[0, 0], axis=0).max() > 1e-3 * M[0, 0].max()
    thin = RoughDielectric(ETA, 0.3, "ggx", film_n=FILM_N, film_thickness=0.05)
    bare = RoughDielectric(ETA, 0.3, "ggx")
    assert thin.film is None
    np.testing.assert_array_equal(thin.eval(sp, wi).matrix(), bare.eval(sp, wi).matrix())
    for theta, inside in ((0.0, False), (60.0, False), (40.0, True)):
        R, T = integrated_lobes(model, sph(theta, 20.0, inside), n_phi=96, panels=32)
        eta = ETA if not inside else 1.0 / ETA
        assert 0.3 < R[0, 0] + eta ** 2 * T[0, 0] <= 1.0 + 1e-3


SAMPLING_CASES = [(0.5, 70.0, False), (0.3, 35.0, True)]


@pytest.mark.parametrize("alpha,theta,inside", SAMPLING_CASES)
def test_sampling_chi2_and_weights(alpha, theta, inside):
    """sample() follows pdf() (the lobe chosen by the film's reflectance averaged over the wavelengths), and its
    weight is f·|cosθ_i|/pdf at every wavelength."""
    model = RoughDielectric(ETA, alpha, "ggx", film_n=FILM_N, film_thickness=FILM_NM)
    N = 40_000
    rng = np.random.default_rng(23)
    wo = sph(theta, 10.0, inside)

    def at(n):
        nrm = tile((0.0, 0.0, 1.0), n)
        return ShadingPoint(np.zeros((3, n)), nrm, nrm, tile(wo, n), np.tile(np.array([[450.0], [600.0]]), (1, n)))
    s = model.sample(at(N), rng.random(N), rng.random((2, N)))
    v = s.valid
    f = model.eval(at(N), s.wi).A[:, v] * np.abs(s.wi[2, v]) / s.pdf[v]
    np.testing.assert_allclose(s.weight.A[:, v], f, rtol=1e-10)
    result = chi2.direction_sampler_test(s.wi, s.valid, lambda wi: model.pdf(at(wi.shape[1]), wi),
                                         n_cos=32, n_phi=32, order=6, sub=2, cos_range=(-1.0, 1.0))
    chi2.assert_accepted(result, test_count=len(SAMPLING_CASES), what="filmed rough dielectric samples")


def test_declaration_builds_the_film():
    decl = MODELS["rough_dielectric"]
    rough = decl.build(decl.values({"n": 1.5, "alpha": 0.2, "thin_film_thickness": 300.0, "thin_film_ior": 1.4}, "x"))
    assert rough.film == (1.4, 300.0) and rough.describe()["thin_film"] == "n 1.4, 300 nm"
    smooth = decl.build(decl.values({"n": 1.5, "alpha": 0.0, "thin_film_thickness": 300.0}, "x"))
    assert smooth.name == "thin_film"
    assert decl.build(decl.values({"n": 1.5, "alpha": 0.2}, "x")).film is None
