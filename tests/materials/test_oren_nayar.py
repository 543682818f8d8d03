"""Cycles' rough diffuse (engine.materials.oren_nayar): Lambert at σ = 0, energy-conserving for a white
albedo (the multiple-scattering term restores what single scattering loses), sampling consistent."""

import math

import numpy as np
import pytest

from engine.materials.base import ShadingPoint
from engine.materials.oren_nayar import OrenNayar
from engine.spectral import ConstantSpectrum


def points(mu, n):
    z = np.tile([[0.0], [0.0], [1.0]], (1, n))
    wo = np.tile([[math.sqrt(1 - mu * mu)], [0.0], [mu]], (1, n))
    return ShadingPoint(np.zeros((3, n)), z, z, wo, np.full((1, n), 550.0))


def hemisphere(n=400):
    """(3, n²) directions and solid-angle weights of a midpoint rule in (cosθ, φ) over the upper hemisphere."""
    c = (np.arange(n) + 0.5) / n
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * math.pi
    C, P = np.meshgrid(c, phi, indexing="ij")
    s = np.sqrt(1 - C * C)
    wi = np.stack((s * np.cos(P), s * np.sin(P), C)).reshape(3, -1)
    return wi, np.full(wi.shape[1], (1.0 / n) * (2 * math.pi / (2 * n)))


@pytest.mark.parametrize("sigma", [0.3, 0.7, 1.0])
@pytest.mark.parametrize("mu", [0.1, 0.5, 0.95])
def test_white_oren_nayar_conserves_energy(sigma, mu):
    """OpenPBR's EON construction, as Cycles': with ρ = 1 the multiple-scattering term fills in exactly what
    single scattering loses, so the directional albedo is 1 (single scattering alone is below)."""
    wi, dw = hemisphere()
    model = OrenNayar(ConstantSpectrum(1.0), sigma)
    f = model.eval(points(mu, wi.shape[1]), wi).A[0]
    assert float(np.sum(f * wi[2] * dw)) == pytest.approx(1.0, abs=4e-3)
    assert model._albedo(np.array([mu]))[0] < 0.999      # single scattering alone loses energy


def test_zero_roughness_is_lambert_and_sampling_is_consistent():
    rng = np.random.default_rng(2)
    n = 500
    sp = points(0.6, n)
    model = OrenNayar(ConstantSpectrum(0.5), 0.0)
    wi = rng.normal(size=(3, n))
    wi[2] = np.abs(wi[2])
    wi /= np.linalg.norm(wi, axis=0)
    np.testing.assert_allclose(model.eval(sp, wi).A[0], 0.5 / math.pi, rtol=1e-12)
    rough = OrenNayar(ConstantSpectrum(0.5), 0.8)
    bs = rough.sample(sp, rng.random(n), rng.random((2, n)))
    f = rough.eval(sp, bs.wi).A[0]
    np.testing.assert_allclose(bs.weight.A[0][bs.valid], (f * bs.wi[2] / bs.pdf)[bs.valid], rtol=1e-12)


def test_textured_roughness_is_the_constant_model_per_texel(tmp_path):
    """σ from a texture (Cycles' Diffuse Roughness linked): at each texel the constant-σ model bit for bit,
    Lambert (no multiple-scattering term) where σ = 0."""
    from tests.support.texel_rows import textured_and_constant
    sp, wi, _, _, mat, rows = textured_and_constant(tmp_path, {"type": "oren_nayar", "albedo": [0.8, 0.5, 0.3]},
                                                    "roughness", [0.0, 0.35, 1.0], reps=30, seed=5)
    assert mat.varies_over_surface
    f, est = mat.eval(sp, wi).matrix(), mat.albedo_estimate(sp)
    for sel, sigma, _, sub in rows:
        const = OrenNayar(mat.albedo, sigma)
        np.testing.assert_array_equal(f[..., sel], const.eval(sub, wi[:, sel]).matrix())
        np.testing.assert_array_equal(est[sel], const.albedo_estimate(sub))
