"""engine.materials.tinted: Cycles' glass colour and Principled transmission tint as a factor per lobe side."""

import numpy as np
import pytest

from engine.materials.base import ShadingPoint
from engine.materials.dielectric import SmoothDielectric
from engine.materials.rough_dielectric import RoughDielectric
from engine.materials.tinted import Tinted
from engine.polarisation.mueller import is_realisable
from engine.spectral import ConstantSpectrum, RGBUnboundedSpectrum


def points(n, rng, lam=550.0):
    z = np.tile([[0.0], [0.0], [1.0]], (1, n))
    wo = rng.normal(size=(3, n))
    wo[2] = np.abs(wo[2]) + 0.1
    wo /= np.linalg.norm(wo, axis=0)
    return ShadingPoint(np.zeros((3, n)), z, z, wo, np.full((1, n), lam))


@pytest.mark.parametrize("base", [RoughDielectric(1.5, 0.3, "ggx"),
                                  RoughDielectric(1.5, 0.6, "ggx", multiscatter=True)])
def test_rough_glass_values_are_the_base_times_the_side_tint(base):
    rng = np.random.default_rng(3)
    sp = points(4000, rng)
    tinted = Tinted(base, ConstantSpectrum(0.3), ConstantSpectrum(0.6))
    wi = rng.normal(size=(3, 4000))
    wi /= np.linalg.norm(wi, axis=0)
    got, want = tinted.eval(sp, wi).matrix(), base.eval(sp, wi).matrix()
    factor = np.where(wi[2] < 0, 0.6, 0.3)
    np.testing.assert_allclose(got, want * factor, rtol=1e-14, atol=0)
    np.testing.assert_array_equal(tinted.pdf(sp, wi), base.pdf(sp, wi))
    assert is_realisable(got).all()
    # sampling: the base's directions, the weight × the tint of the side the direction went to
    u = rng.random((3, 4000))
    a, b = tinted.sample(sp, u[0], u[1:]), base.sample(sp, u[0], u[1:])
    np.testing.assert_array_equal(a.wi, b.wi)
    side = np.where(b.wi[2] < 0, 0.6, 0.3)
    np.testing.assert_allclose(a.weight.matrix(), b.weight.matrix() * side, rtol=1e-14, atol=0)


def test_smooth_glass_tints_each_lobe_and_its_mirror():
    rng = np.random.default_rng(4)
    sp = points(2000, rng)
    tint = RGBUnboundedSpectrum([0.9, 0.5, 0.1])
    glass = SmoothDielectric(1.5)
    tinted = Tinted(glass, None, tint)
    assert tinted.flags.has(tinted.flags.WAVELENGTH_DEPENDENT)
    u = rng.random((3, 2000))
    a, b = tinted.sample(sp, u[0], u[1:]), glass.sample(sp, u[0], u[1:])
    through = b.wi[2] < 0
    assert through.any() and (~through).any()
    t = tint.eval(sp.lam)
    np.testing.assert_allclose(a.weight.matrix(), b.weight.matrix() * np.where(through, t, 1.0), rtol=1e-14)
    np.testing.assert_array_equal(tinted.delta_reflection(sp).matrix(), glass.delta_reflection(sp).matrix())
    both = Tinted(glass, ConstantSpectrum(0.25), None)
    np.testing.assert_allclose(both.delta_reflection(sp).matrix(), 0.25 * glass.delta_reflection(sp).matrix())


def test_specular_tint_is_cycles_generalized_schlick():
    """FresnelTinted: the mirror's reflectance is F0·tint at normal incidence and the real Fresnel curve's
    remap F_real + F0(t − 1)(1 − F_real)/(1 − F0) elsewhere (→ 1 at grazing); polarisation shape kept."""
    from engine.materials.conductor import SmoothConductor
    from engine.materials.tinted import FresnelTinted
    from engine.polarisation.fresnel import fresnel_reflectance
    mirror = SmoothConductor(ConstantSpectrum(1.5), ConstantSpectrum(0.0))
    tinted = FresnelTinted(mirror, 1.5, ConstantSpectrum(0.25))
    for mu in (1.0, 0.5, 0.05):
        sp = points(1, np.random.default_rng(0))
        sp.wo[:] = [[np.sqrt(1 - mu * mu)], [0.0], [mu]]
        got = tinted.delta_reflection(sp)
        want = mirror.delta_reflection(sp)
        F = fresnel_reflectance(mu, 1.5 + 0j)
        expect = F + 0.04 * (0.25 - 1.0) * (1.0 - F) / 0.96
        np.testing.assert_allclose(got.A, expect, rtol=1e-12)
        np.testing.assert_allclose(got.matrix() / got.A, want.matrix() / want.A, rtol=1e-12)   # same shape
    assert tinted.delta_reflection(sp).A[0, 0] < 1.0


# --------------------------------------------------------------------------- Cycles' F82-Tint metal curve

def test_f82_curve_meets_its_defining_points():
    """F(0°) = F0, F(θ₈₂) = Schlick's value there × tint, F(90°) = 1, and no tint is Schlick's curve."""
    from engine.materials.tinted import f82_curve
    f0 = np.array([0.04, 0.3, 0.9])[:, None]
    tint = np.array([0.2, 0.7, 1.0])[:, None]
    c82 = 1.0 / 7.0
    schlick82 = f0 + (1.0 - f0) * (1.0 - c82) ** 5
    np.testing.assert_allclose(f82_curve(np.ones((1, 1)), f0, tint), f0, rtol=1e-15)
    np.testing.assert_allclose(f82_curve(np.full((1, 1), c82), f0, tint), schlick82 * tint, rtol=1e-12)
    np.testing.assert_allclose(f82_curve(np.zeros((1, 1)), f0, tint), 1.0, rtol=1e-15)
    mu = np.linspace(0.0, 1.0, 11)[None, :]
    np.testing.assert_allclose(f82_curve(mu, f0, None), f0 + (1 - f0) * (1 - mu) ** 5, rtol=1e-15)
    np.testing.assert_allclose(f82_curve(mu, f0, np.ones_like(f0)), f82_curve(mu, f0, None), rtol=1e-14)
    # a strong tint dips below Schlick's curve, never below 0
    assert np.all(f82_curve(mu, f0, np.zeros_like(f0)) >= 0.0)


@pytest.mark.parametrize("r, tint", [(0.9, 1.0), (0.05, 1.0), (0.8, 0.2), (0.3, 0.5)])
def test_f82_metal_mirror_reflects_cycles_curve_with_the_metals_polarisation(r, tint):
    """A smooth metal under F82Reflectance: its S0 reflectance is Cycles' F82-Tint curve at every angle (where the
    Gulbrandsen index alone is off by up to 38 % for a dark metal, more with a tint), its Mueller matrix the
    metal's own up to that scalar (same DoLP, same retardance), realisable."""
    from engine.materials.conductor import SmoothConductor
    from engine.materials.tinted import F82Reflectance, f82_curve
    from engine.spectral.gulbrandsen import index_of, schlick_f82
    n, k = index_of(np.array(r), np.array(schlick_f82(r) * tint), "f82")
    metal = SmoothConductor(ConstantSpectrum(float(n)), ConstantSpectrum(float(k)))
    wrapped = F82Reflectance(metal, ConstantSpectrum(r), None if tint == 1.0 else ConstantSpectrum(tint))
    rng = np.random.default_rng(7)
    sp = points(500, rng)
    got, base = wrapped.delta_reflection(sp).matrix(), metal.delta_reflection(sp).matrix()
    want_s0 = f82_curve(sp.cos_o[None, :], r, None if tint == 1.0 else tint)[0]
    np.testing.assert_allclose(got[0, 0, 0], want_s0, rtol=1e-12, atol=1e-15)
    ratio = got[0, 0, 0] / base[0, 0, 0]
    np.testing.assert_allclose(got, base * ratio, rtol=1e-12, atol=1e-15)
    assert is_realisable(got).all()


def test_f82_metal_rough_lobe_is_rescaled_at_the_half_vector():
    """A rough GGX metal under F82Reflectance: eval = the lobe × F82(θ_h)/F(θ_h), the pdf and the sampled
    directions the lobe's own, the sample weight rescaled alike."""
    from engine.materials.torrance_sparrow import TorranceSparrow
    from engine.materials.tinted import F82Reflectance, f82_curve
    from engine.polarisation.fresnel import fresnel_reflectance
    base = TorranceSparrow(ConstantSpectrum(0.4), ConstantSpectrum(2.5), 0.2, distribution="ggx", multiscatter=True)
    tint = 0.6
    wrapped = F82Reflectance(base, ConstantSpectrum(0.5), ConstantSpectrum(tint))
    rng = np.random.default_rng(9)
    sp = points(3000, rng)
    wi = rng.normal(size=(3, 3000))
    wi[2] = np.abs(wi[2])
    wi /= np.linalg.norm(wi, axis=0)
    h = wi + sp.wo
    cos_h = 0.5 * np.linalg.norm(h, axis=0)
    expected = f82_curve(cos_h, 0.5, tint) / fresnel_reflectance(cos_h, complex(0.4, 2.5))
    np.testing.assert_allclose(wrapped.eval(sp, wi).matrix(), base.eval(sp, wi).matrix() * expected,
                               rtol=1e-10, atol=1e-14)
    np.testing.assert_array_equal(wrapped.pdf(sp, wi), base.pdf(sp, wi))
    u = rng.random((3, 3000))
    a, b = wrapped.sample(sp, u[0], u[1:]), base.sample(sp, u[0], u[1:])
    np.testing.assert_array_equal(a.wi, b.wi)
    assert np.all(np.isfinite(a.weight.matrix()))


@pytest.mark.skipif(not __import__("engine.kernels", fromlist=["COMPILED"]).COMPILED, reason="needs Numba")
@pytest.mark.parametrize("curve, tinted", [("f82_tint", True), ("f82_tint", False), ("constant", False)])
def test_compiled_f82_ratio_is_the_numpy_ratio_bit_for_bit(curve, tinted):
    """F82Reflectance's ratio in one compiled loop (tinted.f82_ratio) against its NumPy twin with the compiled
    Fresnel (the twin's own when kernels are compiled): bit for bit, with cosines and reflectances outside [0, 1],
    negative zeros, NaN, and lanes where F = 0."""
    from engine.kernels import TWINS
    from engine.materials import tinted as T
    assert TWINS["materials.tinted.f82_ratio"].compiled is T.f82_ratio_numba
    rng = np.random.default_rng(82)
    L, n = 4, 900
    cos = rng.uniform(-0.2, 1.2, n)
    cos[:4] = (-0.0, 0.0, 1.0, np.nan)
    eta = rng.uniform(0.2, 3.0, (L, n)) + 1j * rng.uniform(0.0, 5.0, (L, n))
    eta[:, 10:14] = 1.0         # F = 0 at matched indices
    f0, tint = rng.uniform(-0.1, 1.1, (L, n)), rng.uniform(-0.1, 1.1, (L, n))
    f0[0, :3], tint[1, :3], f0[2, 20], tint[3, 21] = -0.0, -0.0, np.nan, np.nan
    args = (cos, eta, f0, tint if tinted else None, curve, (L, n))
    got, want = T.f82_ratio_numba(*args), T.f82_ratio_numpy(*args)
    assert got.shape == want.shape == (L, n) and got.tobytes() == want.tobytes()
