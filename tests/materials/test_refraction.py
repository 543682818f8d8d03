"""Cycles' Refraction BSDF (engine.materials.refraction): refraction only, no Fresnel, the identity Mueller matrix.

Checked against closed forms (the smooth limit: identity/η², 0 beyond the critical angle; the identity's own
realisability; no reflection), the sampler's chi-square, the hard cases (grazing, index-matched, n < 1 from either
side) and the scene format.  Its albedo against Cycles': tests/blender/test_cycles_refraction.py."""

import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.materials.catalogue import MODELS, make_model
from engine.materials.flags import BSDFFlags
from engine.materials.refraction import Refraction, SmoothRefraction
from engine.polarisation.fresnel import fresnel_transmission_mueller
from engine.polarisation.mueller import is_realisable
from engine.scene.loader import parse_material
from engine.textures import TexturedNumber, TextureInput
from engine.textures.texture import ImageTexture
from tests.materials.test_rough_dielectric import integrated_lobes, point, random_directions, sph, tile
from tests.support import chi2

ETA = 1.5           # (integrated_lobes' lobe axes take the glass of test_rough_dielectric: 1.5)


@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
@pytest.mark.parametrize("theta,inside", [(30.0, False), (80.0, False), (25.0, True), (60.0, True)])
def test_smooth_limit_is_identity_over_eta_squared_and_nothing_beyond_the_critical_angle(dist, theta, inside):
    """α → 0: the integrated lobe → identity/η² (Cycles' sharp refraction, radiance-scaled), 0 under total internal
    reflection (60° inside glass of 1.5), and no reflection at all; the smooth model's Dirac weight is that."""
    wo = sph(theta, 0.0, inside)
    eta = ETA if not inside else 1.0 / ETA
    tir = math.sin(math.radians(theta)) > eta
    want = np.zeros((4, 4)) if tir else np.eye(4) / eta ** 2
    R, T = integrated_lobes(Refraction(ETA, 1e-3, dist), wo)
    np.testing.assert_allclose(R, 0.0, atol=0.0)
    np.testing.assert_allclose(T, want, atol=4e-3)
    s = SmoothRefraction(ETA).sample(point(wo[:, None]), np.array([0.3]), np.zeros((2, 1)))
    assert s.valid[0] == (not tir) and s.is_delta[0] and s.pdf[0] == 0.0
    if not tir:
        np.testing.assert_allclose(s.weight.matrix()[:, :, 0, 0], np.eye(4) / eta ** 2, rtol=1e-14)
        assert s.eta_sq[0] == pytest.approx(eta ** 2) and s.wi[2, 0] * wo[2] < 0


def test_identity_and_not_the_normalised_fresnel_matrix():
    """Why the identity: the Fresnel transmission matrix normalised to Cycles' transmittance 1, M_T/M_T,00, sends
    p-polarised light out brighter than it came in (2T_p/(T_s + T_p) > 1: not realisable), the identity never."""
    M = fresnel_transmission_mueller(math.cos(math.radians(75.0)), ETA)
    p_in = np.array([1.0, -1.0, 0.0, 0.0])        # p in the s-p frame
    assert (M / M[0, 0] @ p_in)[0] > 1.05
    rng = np.random.default_rng(3)
    model = Refraction(ETA, 0.4, "ggx")
    for lower in (False, True):
        wo, wi = random_directions(rng, 4000, lower), rng.normal(size=(3, 4000))
        wi /= np.linalg.norm(wi, axis=0)
        v = model.eval(point(wo), wi)
        assert np.all(v.B == 0) and np.all(v.S == 0) and np.array_equal(v.A, v.C) and np.all(v.A >= 0)
        assert np.all(v.A[0][wi[2] * wo[2] > 0] == 0) and np.count_nonzero(v.A) > 200     # no reflection
        M = v.matrix()[:, :, 0, :]
        assert np.all(is_realisable(M / np.maximum(M[0, 0], 1e-300)))


@pytest.mark.parametrize("dist,alpha", [("ggx", 0.3), ("ggx", 1.0), ("beckmann", 0.5)])
@pytest.mark.parametrize("theta,inside", [(0.0, False), (70.0, False), (30.0, True), (60.0, True)])
def test_energy_is_at_most_one_without_compensation(dist, alpha, theta, inside):
    """η² ∫ f_t |cosθ_i| dω ≤ 1 (Cycles' transmittance 1 at every facet, no energy compensation): the light its
    shadowing and total internal reflection take is lost; from inside beyond the critical angle only the facets
    tilted towards the viewer pass any."""
    model = Refraction(ETA, alpha, dist)
    wo = sph(theta, 20.0, inside)
    _, T = integrated_lobes(model, wo, n_phi=128, panels=32)
    eta = ETA if not inside else 1.0 / ETA
    energy = eta ** 2 * T[0, 0]
    assert 0.01 < energy <= 1.0 + 1e-3
    if not inside and theta == 0.0:
        assert energy > 0.96


SAMPLING_CASES = [("ggx", 0.2, 0.0, False), ("beckmann", 0.6, 70.0, False), ("ggx", 0.3, 20.0, True),
                  ("ggx", 0.5, 55.0, True)]


@pytest.mark.parametrize("dist,alpha,theta,inside", SAMPLING_CASES)
def test_sampling_chi2(dist, alpha, theta, inside):
    """sample() follows pdf() over the whole sphere (facets under total internal reflection: no sample, the
    pdf's missing mass)."""
    model = Refraction(ETA, alpha, dist)
    N = 60_000
    rng = np.random.default_rng(17)
    wo = sph(theta, 10.0, inside)
    s = model.sample(point(tile(wo, N)), rng.random(N), rng.random((2, N)))
    assert np.all(s.wi[2, s.valid] * wo[2] < 0)
    f = model.eval(point(tile(wo, N)), s.wi).A[0, s.valid] * np.abs(s.wi[2, s.valid]) / s.pdf[s.valid]
    np.testing.assert_allclose(s.weight.A[0, s.valid], f, rtol=1e-10)
    result = chi2.direction_sampler_test(s.wi, s.valid, lambda wi: model.pdf(point(tile(wo, wi.shape[1])), wi),
                                         n_cos=48, n_phi=48, order=8, sub=2, cos_range=(-1.0, 1.0))
    chi2.assert_accepted(result, test_count=len(SAMPLING_CASES), what="refraction samples")


@pytest.mark.parametrize("model", [Refraction(1.5, 0.3, "ggx"), SmoothRefraction(1.5), SmoothRefraction(0.8),
                                   Refraction(0.8, 0.5, "beckmann")],
                         ids=["rough", "smooth", "smooth_n<1", "rough_n<1"])
def test_hard_cases_are_finite(model):
    """Grazing (cosθ_o = 1e-9), normal incidence, from either side, n < 1 (total internal reflection seen from
    outside): finite weights in [0, 1/η²·…], valid samples refract."""
    wo = np.array([[math.sqrt(1 - 1e-18), 0.0, 1.0, 0.6, 0.6, math.sqrt(1 - 1e-18)],
                   [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                   [1e-9, 1.0, 0.0, 0.8, -0.8, -1e-9]])
    wo /= np.linalg.norm(wo, axis=0)
    rng = np.random.default_rng(1)
    for _ in range(50):
        s = model.sample(point(wo), rng.random(6), rng.random((2, 6)))
        M = s.weight.matrix()
        assert np.all(np.isfinite(M)) and np.all(np.isfinite(s.wi)) and np.all(np.isfinite(s.pdf))
        assert np.all(M[0, 0, 0] >= 0) and np.all(M[0, 0, 0] < 5.0)
        assert np.all((s.wi[2] * np.where(wo[2] >= 0, 1.0, -1.0) < 0)[s.valid])
    if isinstance(model, SmoothRefraction) and model.n_int < 1:     # from outside beyond asin(0.8): nothing passes
        s = model.sample(point(sph(60.0)[:, None]), np.zeros(1), np.zeros((2, 1)))
        assert not s.valid[0] and s.weight.A[0, 0] == 0.0


def test_index_matched_passes_straight_through():
    """n = exterior_n: no interface (any roughness), light straight through with weight 1, as Cycles' singular
    refraction at |η − 1| < 1e-4."""
    model = make_model("refraction", {"n": "1.33", "exterior_n": "1.33", "alpha": "0.5"})
    assert isinstance(model, SmoothRefraction)
    wo = random_directions(np.random.default_rng(2), 20)
    s = model.sample(point(wo), np.zeros(20), np.zeros((2, 20)))
    assert s.valid.all() and np.allclose(s.wi, -wo) and np.allclose(s.weight.matrix()[:, :, 0, :],
                                                                    np.eye(4)[:, :, None])


def test_scene_format_flags_and_bad_input():
    rough = parse_material({"type": "refraction", "n": 1.45, "alpha": 0.2, "distribution": "beckmann"}, "x")
    assert rough.describe() == make_model("refraction", {"n": "1.45", "alpha": "0.2",
                                                          "distribution": "beckmann"}).describe()
    assert rough.flags == BSDFFlags.GLOSSY_TRANSMISSION and not rough.polarising and not rough.multiscatter
    smooth = parse_material({"type": "refraction", "n": 1.45}, "x")
    assert isinstance(smooth, SmoothRefraction) and smooth.flags == BSDFFlags.DELTA_TRANSMISSION
    with pytest.raises(SceneError, match=r"x\.distribution: must be one of"):
        parse_material({"type": "refraction", "n": 1.45, "distribution": "phong"}, "x")
    with pytest.raises(SceneError, match=r"x\.n: must be a finite number in \(0"):
        parse_material({"type": "refraction", "n": -1}, "x")
    tex = TextureInput(ImageTexture(np.array([[[0.9]], [[1.2]]], dtype=np.float32)))
    for name in ("refraction", "rough_dielectric"):
        decl = MODELS[name]
        with pytest.raises(SceneError, match=r"x\.n: a per-point index must lie on one side of 1, got values in "
                                             r"\[0\.9, 1\.2\]"):
            decl.build(decl.values({"n": tex, "alpha": 0.1}, "x"))
    per_point = MODELS["refraction"].build(MODELS["refraction"].values({"n": 1.5, "alpha": tex}, "x"))
    assert isinstance(per_point.alpha, TexturedNumber) and per_point.varies_over_surface


@pytest.mark.parametrize("theta,inside", [(30.0, False), (85.0, False), (25.0, True), (60.0, True)])
def test_light_pass_colours_are_cycles_refraction_albedo(theta, inside):
    """Cycles' Refraction closure's colour (bsdf_albedo with no Fresnel): glossy 0, transmission 1, or 0 beyond the
    critical angle (60° inside glass of 1.5) — smooth and rough alike."""
    wo = sph(theta, 0.0, inside)
    tir = math.sin(math.radians(theta)) > (1.0 / ETA if inside else ETA)
    for model in (SmoothRefraction(ETA), Refraction(ETA, 0.3, "ggx")):
        c = model.lobe_colors(point(wo[:, None]))
        assert np.all(c.glossy == 0.0) and np.all(c.diffuse == 0.0)
        assert np.all(c.transmission == (0.0 if tir else 1.0)), (model, theta, inside)
