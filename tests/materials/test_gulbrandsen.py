"""Metals from colours: Gulbrandsen's map per wavelength gives the colour back (engine.spectral.gulbrandsen)."""

import numpy as np
import pytest

from engine.polarisation.fresnel import fresnel_reflectance
from engine.spectral import (GRID_NM, RGBReflectanceSpectrum, RGBUnboundedSpectrum, d65_normalised,
                             spectrum_to_linear_srgb)
from engine.spectral.gulbrandsen import GulbrandsenIndex, gulbrandsen_nk

COLOURS = [(0.8, 0.05, 0.05), (0.05, 0.8, 0.05), (0.05, 0.05, 0.8), (1.0, 0.766, 0.336), (0.955, 0.638, 0.538),
           (0.6, 0.45, 0.3)]


def developed_mirror_colour(n, k):
    """Linear sRGB of a mirror with index n(λ) + iκ(λ) at normal incidence under the unit white."""
    F = fresnel_reflectance(1.0, n.eval(GRID_NM) + 1j * k.eval(GRID_NM))
    return spectrum_to_linear_srgb(d65_normalised(GRID_NM) * F)


@pytest.mark.parametrize("colour", COLOURS)
def test_per_wavelength_map_develops_back_to_the_colour(colour):
    r = RGBReflectanceSpectrum(colour)
    got = developed_mirror_colour(GulbrandsenIndex(r, r, "n"), GulbrandsenIndex(r, r, "k"))
    np.testing.assert_allclose(got, np.minimum(colour, 0.999), atol=1.5e-3)


def test_per_channel_map_does_not():
    """What the exporter did before (n, κ per channel, then upsampled): a saturated red mirror is not red
    enough — the test above would fail with it."""
    colour = (0.8, 0.05, 0.05)
    n, k = gulbrandsen_nk(np.array(colour), np.array(colour))
    got = developed_mirror_colour(RGBUnboundedSpectrum(n), RGBUnboundedSpectrum(k))
    assert np.abs(got - colour).max() > 0.02


def test_rgb_view_is_the_per_channel_map():
    colour = (0.9, 0.5, 0.1)
    r = RGBReflectanceSpectrum(colour)
    n, k = gulbrandsen_nk(np.array(colour), np.array(colour))
    np.testing.assert_allclose(GulbrandsenIndex(r, r, "n").linear_srgb(), n)
    np.testing.assert_allclose(GulbrandsenIndex(r, r, "k").linear_srgb(), k)


@pytest.mark.parametrize("r,g", [(0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0), (0.999, 0.5), (1e-12, 1e-12)])
def test_limits_are_finite_and_reflect_r(r, g):
    n, k = gulbrandsen_nk(r, g)
    assert np.isfinite(n) and np.isfinite(k) and n > 0 and k >= 0
    assert fresnel_reflectance(1.0, n + 1j * k) == pytest.approx(min(r, 0.999), abs=1e-9)


def test_edge_tint_matches_cycles_f82_curve_at_both_angles():
    """Cycles' Principled metal follows Schlick's curve (F82 model, white tint): the conductor Polar builds
    reflects r at 0° exactly and Schlick's value at θ₈₂ (within the table's 4e-4) wherever a Gulbrandsen metal
    can (r ≥ 0.01); below, the nearest (g = 1)."""
    from engine.spectral.gulbrandsen import COS_82, edge_tint_for_f82, schlick_f82
    r = np.linspace(0.0, 0.999, 3001)
    g = edge_tint_for_f82(r, schlick_f82(r))
    n, k = gulbrandsen_nk(r, g)
    assert np.all((g >= 0) & (g <= 1)) and np.all(np.isfinite(n) & np.isfinite(k))
    np.testing.assert_allclose(fresnel_reflectance(1.0, n + 1j * k), r, atol=1e-12)
    f82 = fresnel_reflectance(COS_82, n + 1j * k)
    assert np.abs(f82 - schlick_f82(r))[r >= 0.01].max() < 4e-4
    ends = [np.abs(fresnel_reflectance(COS_82, complex(*gulbrandsen_nk(x, e))) - schlick_f82(x)) for x, e in
            ((x, e) for x in r[r < 0.01] for e in (0.0, 1.0))]
    nearest = np.minimum(ends[0::2], ends[1::2])
    assert np.all(np.abs(f82 - schlick_f82(r))[r < 0.01] <= nearest + 4e-4)   # unreachable: the closest end
    # an arbitrary target (Metallic BSDF's F82-Tint) between the reachable ends
    r2, target = np.full(5, 0.6), np.array([0.6, 0.65, 0.7, 0.8, 0.9])
    n2, k2 = gulbrandsen_nk(r2, edge_tint_for_f82(r2, target))
    np.testing.assert_allclose(fresnel_reflectance(COS_82, n2 + 1j * k2), target, atol=4e-4)


@pytest.mark.parametrize("mode", ["tint", "f82", "schlick", "schlick_tint", "cycles_film"])
def test_rgb_transport_maps_one_column_with_the_same_bits(mode):
    """"rgb" transport (a channels lookup): every path holds the same channel values, so the map runs once on one
    column and is shared (a stride-0 view) — bit for bit the map of every path's values, for subsets too."""
    from engine.spectral import RGB_WAVELENGTHS_NM, WavelengthLookup, rgb_channel_tables
    from engine.spectral.gulbrandsen import index_of
    n = 37
    lam = np.repeat(np.array(RGB_WAVELENGTHS_NM)[:, None], n, axis=1)
    root = WavelengthLookup(lam, *rgb_channel_tables(n), channels=True)
    r, edge = RGBReflectanceSpectrum((0.9, 0.55, 0.2)), RGBReflectanceSpectrum((0.7, 0.8, 0.95))
    for lk in (root, root.take(np.array([3, 5, 30, 31])).take(np.array([0, 2, 3]))):
        want = index_of(r.eval_cached(lk).copy(), edge.eval_cached(lk).copy(), mode)
        for part, w in zip("nk", want):
            got = GulbrandsenIndex(r, edge, part, mode).eval_cached(lk)
            assert got.shape == w.shape and got.strides[-1] == 0
            assert np.array_equal(got, w)
