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
