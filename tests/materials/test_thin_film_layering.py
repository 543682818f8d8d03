"""A thin film's colour-channel reflectances and the layering weight of what lies under a filmed layer.

``film_band_reflectance`` averages Airy's reflectance over each linear-sRGB channel's band under the D65 white by a
Fourier series (engine.spectral.film_channels); the oracle is a direct quadrature every 0.05 nm of the exact
per-wavelength reflectance.  The layering weight of a filmed Principled layer is one minus the largest channel's
reflectance (Cycles' rule), which in the spectral transport must be the channels the film itself develops to: a
white base under a film then reflects exactly all the light in its brightest channel and no more in any.
"""

import math

import numpy as np
import pytest

from engine.materials.base import ShadingPoint
from engine.polarisation.thin_film import film_reflection_abcs
from engine.spectral.film_channels import film_band_reflectance, film_layering_albedo, layering_wavelengths
from engine.scene.loader import parse_material
from engine.spectral import RGB_WAVELENGTHS_NM, WavelengthLookup, cie, rgb_channel_tables

FINE_NM = np.arange(360.0, 830.001, 0.05)


def sensitivities(lam):
    """(3, K) linear-sRGB channel sensitivities under the unit D65 white, each summing to 1 over ``lam``."""
    s = np.tensordot(cie.XYZ_TO_LINEAR_SRGB, cie.cmf_xyz(lam), axes=1) * cie.d65_normalised(lam)
    return s / s.sum(axis=1, keepdims=True)


def quadrature(cos, n1, nf, d, n3):
    R = film_reflection_abcs(np.full_like(FINE_NM, cos), n1, nf, d, n3, FINE_NM)[0]
    return sensitivities(FINE_NM) @ R


CASES = [  # cosθ, n₁, film index, thickness nm, substrate
    (1.0, 1.0, 2.0, 400.0, 1.5), (0.8, 1.0, 2.0, 400.0, 1.5), (0.05, 1.0, 2.0, 400.0, 1.5), (0.0, 1.0, 1.5, 300.0, 1.5),
    (0.3, 1.0, 1.5, 250.0, 1.45), (0.9, 1.0, 1.5, 400.0, 0.2 + 3.0j), (0.02, 1.0, 1.5, 300.0, 0.2 + 3.0j),
    (0.5, 1.0, 1.3, 1000.0, 0.05 + 4.0j), (1.0, 1.0, 2.0, 10000.0, 1.5), (0.7, 1.0, 1.2, 60000.0, 1.5),
    (0.7, 1.0, 2.0, 5.0, 1.5), (1.0, 1.0, 1.5, 0.5, 1.5),
    (0.3, 1.5, 1.2, 100.0, 1.6),    # from inside glass, beyond the film's critical angle: evanescent (quadrature)
    (0.5, 1.5, 1.2, 300.0, 1.0),    # … and totally reflected below it
]


@pytest.mark.parametrize("case", CASES)
def test_band_reflectance_equals_a_quadrature_over_the_wavelengths(case):
    got = film_band_reflectance(np.array([case[0]]), *case[1:])[:, 0]
    np.testing.assert_allclose(got, quadrature(*case), atol=3e-5)


def test_band_reflectance_per_point_and_per_channel_substrate():
    """Per-point cosθ, film index and thickness, and a metal's index per channel (the channels' own)."""
    cos = np.array([1.0, 0.6, 0.2])
    nf = np.array([1.3, 1.8, 2.2])
    d = np.array([150.0, 420.0, 800.0])
    n3 = np.array([[0.2 + 3.5j], [0.5 + 2.5j], [1.2 + 1.8j]])
    got = film_band_reflectance(cos, 1.0, nf, d, n3)
    for j in range(3):
        for c in range(3):
            want = quadrature(cos[j], 1.0, nf[j], d[j], n3[c, 0])[c]
            assert got[c, j] == pytest.approx(want, abs=3e-5)


def furnace(model, mu):
    """(3,) the linear-sRGB albedo at cosθ_o = mu under the D65 white: the mirror's and the Lambertian base's
    reflectance per wavelength (every 0.05 nm), developed to RGB."""
    k = FINE_NM.size
    n = np.tile([[0.0], [0.0], [1.0]], (1, k))
    wo = np.tile([[math.sqrt(1.0 - mu * mu)], [0.0], [mu]], (1, k))
    sp = ShadingPoint(np.zeros((3, k)), n, n, wo, FINE_NM[None, :])
    mirror = np.array([-wo[0], -wo[1], wo[2]])
    sp_mirror = ShadingPoint(np.zeros((3, k)), n, n, mirror, FINE_NM[None, :])
    delta = model.delta_reflection(sp_mirror).A[0]
    base = math.pi * model.eval(sp, n).A[0]          # a Lambertian base: ρ·w/π in every direction
    return sensitivities(FINE_NM) @ (delta + base)


@pytest.mark.parametrize("mu", [1.0, 0.8, 0.5, 0.2])
def test_a_white_base_under_a_film_reflects_all_the_light_in_its_brightest_channel_and_no_more(mu):
    """Before the layering weight read the film's band averages, it read single wavelengths per channel: the white
    base under an IOR-2 400 nm film reflected up to 1.047 (measured against Cycles' 1.000)."""
    model = parse_material({"type": "principled", "base_color": 1.0, "roughness": 0.0, "thin_film_ior": 2.0,
                            "thin_film_thickness": 400.0}, "materials.p")
    rgb = furnace(model, mu)
    assert rgb.max() == pytest.approx(1.0, abs=2e-4)
    assert np.all(rgb <= 1.0 + 2e-4)


def test_rgb_transport_layers_at_the_channel_wavelengths_where_it_evaluates_the_film():
    lam = np.repeat(np.array(RGB_WAVELENGTHS_NM)[:, None], 4, axis=1)
    z = np.tile([[0.0], [0.0], [1.0]], (1, 4))
    rgb = ShadingPoint(np.zeros((3, 4)), z, z, z, lam, lookup=WavelengthLookup(lam, *rgb_channel_tables(4),
                                                                               channels=True))
    spectral = ShadingPoint(np.zeros((3, 4)), z, z, z, lam, lookup=WavelengthLookup(lam))
    assert layering_wavelengths(rgb) == RGB_WAVELENGTHS_NM
    assert layering_wavelengths(rgb.take(np.array([0, 2]))) == RGB_WAVELENGTHS_NM
    assert layering_wavelengths(spectral) is None
    cos = np.array([0.9, 0.4])
    single = film_reflection_abcs(cos[None, :], 1.0, 2.0, 400.0, 1.5, np.array(RGB_WAVELENGTHS_NM)[:, None])[0]
    np.testing.assert_array_equal(film_layering_albedo(cos, 1.0, (2.0, 400.0), 1.5, RGB_WAVELENGTHS_NM),
                                  single.max(axis=0))
    np.testing.assert_array_equal(film_layering_albedo(cos, 1.0, (2.0, 400.0), 1.5),
                                  film_band_reflectance(cos, 1.0, 2.0, 400.0, 1.5).max(axis=0))
