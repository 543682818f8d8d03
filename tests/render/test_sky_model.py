"""The clear-sky model (engine.spectral.daylight): Preetham radiance, Rayleigh and Berry–Dennis–Lee
polarisation against closed forms written here independently, the Stokes frame convention of
docs/physics.md §0, and input validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.spectral.daylight import ClearSky, perez_coefficients, zenith_xyY

ELEVATIONS = (5.0, 30.0, 60.0, 90.0)


def sun_at(elevation_deg, azimuth_deg=20.0):
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return (math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e))


def random_directions(n, seed=0, upper=True):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    if upper:
        d[:, 2] = np.abs(d[:, 2])
    return d


def random_frames(d, seed=1):
    """Unit x axes ⟂ each direction, at random angles."""
    a = np.random.default_rng(seed).normal(size=d.shape)
    a -= np.sum(a * d, axis=1)[:, None] * d
    return a / np.linalg.norm(a, axis=1)[:, None]


def stokes_from_e(dolp, e, d, x):
    """S1/S0, S2/S0 of light with degree dolp, field e, from d, in the frame x, y = (−d) × x (via atan2)."""
    y = np.cross(-d, x)
    psi = np.arctan2(np.sum(e * y, axis=1), np.sum(e * x, axis=1))
    return dolp * np.cos(2 * psi), dolp * np.sin(2 * psi)


# --- Rayleigh -----------------------------------------------------------------------------------------

def rayleigh_reference(sun, d, delta):
    s = np.asarray(sun)
    gamma = np.arccos(np.clip(d @ s, -1, 1))
    dolp = (1 - delta) * np.sin(gamma) ** 2 / (1 + delta + (1 - delta) * np.cos(gamma) ** 2)
    s_perp = s[None, :] - (d @ s)[:, None] * d                   # the sun direction's part ⟂ ω
    e = np.cross(d, s_perp)                                       # ⟂ ω and ⟂ s: normal to the scattering plane
    return dolp, e / np.linalg.norm(e, axis=1)[:, None]


@pytest.mark.parametrize("elevation", ELEVATIONS)
@pytest.mark.parametrize("delta", [0.0, 0.031, 0.1])
def test_rayleigh_matches_closed_form(elevation, delta):
    sky = ClearSky(sun_direction=sun_at(elevation), model="rayleigh", delta=delta)
    d = random_directions(400, seed=int(elevation))
    dolp_ref, e_ref = rayleigh_reference(sky.sun, d, delta)
    dolp, e = sky.polarisation(d)
    np.testing.assert_allclose(dolp, dolp_ref, atol=1e-12)
    x = random_frames(d)
    s1, s2 = sky.stokes_linear(d, x)
    r1, r2 = stokes_from_e(dolp_ref, e_ref, d, x)
    np.testing.assert_allclose(s1, r1, atol=1e-9)
    np.testing.assert_allclose(s2, r2, atol=1e-9)
    # e is a unit vector ⟂ ω and ⟂ the sun direction: normal to the scattering plane (sun, ω)
    np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(e * d, axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(e @ sky.sun, 0.0, atol=1e-12)


@pytest.mark.parametrize("elevation", ELEVATIONS)
def test_rayleigh_zero_at_sun_and_maximum_at_ninety_degrees(elevation):
    delta = 0.031
    sky = ClearSky(sun_direction=sun_at(elevation), model="rayleigh", delta=delta)
    s = sky.sun
    assert sky.polarisation(s[None, :])[0][0] == pytest.approx(0.0, abs=1e-15)
    # the great circle 90° from the sun, upper half
    a = np.cross(s, [0.3, 0.1, 0.9]) if elevation == 90.0 else np.cross(s, [0, 0, 1])
    a /= np.linalg.norm(a)
    b = np.cross(s, a)
    t = np.linspace(0, 2 * math.pi, 73)
    ring = np.cos(t)[:, None] * a + np.sin(t)[:, None] * b
    ring = ring[ring[:, 2] >= 0]
    dolp_ring = sky.polarisation(ring)[0]
    np.testing.assert_allclose(dolp_ring, (1 - delta) / (1 + delta), atol=1e-12)
    assert sky.polarisation(random_directions(5000))[0].max() <= (1 - delta) / (1 + delta) + 1e-12


def test_rayleigh_zero_at_antisun_on_the_horizon():
    sky = ClearSky(sun_direction=sun_at(0.0), model="rayleigh")
    assert sky.polarisation(-sky.sun[None, :])[0][0] == pytest.approx(0.0, abs=1e-15)


# --- Berry, Dennis & Lee ------------------------------------------------------------------------------

def berry_reference(sun, d, separation_deg, max_degree, form="ratio"):
    """Berry et al. 2004 Eq. 4.2 as printed (antipodal roots −1/ζ*, moduli normalisation), in complex
    numbers from spherical angles, with the sun-azimuth phase removed (Π ζ_k*/|ζ_k|); e from the inverse
    stereographic projection by central differences along e^{iχ}."""
    theta = np.arccos(d[:, 2])
    phi = np.arctan2(d[:, 1], d[:, 0])
    zeta = np.tan(theta / 2) * np.exp(1j * phi)
    th_s, ph_s = math.acos(sun[2]), math.atan2(sun[1], sun[0])
    dd = math.radians(separation_deg)
    roots = [math.tan((th_s - dd) / 2) * np.exp(1j * ph_s), math.tan((th_s + dd) / 2) * np.exp(1j * ph_s)]
    num = -4 + 0j
    den = (1 + np.abs(zeta) ** 2) ** 2
    phase = 1 + 0j
    for r in roots:
        anti = -1 / np.conj(r)
        num = num * (zeta - r) * (zeta - anti)
        den = den * abs(r - anti)
        phase *= np.conj(r) / abs(r)
    w = num / den * phase
    m = np.abs(w)
    dolp = max_degree * (m / (2 - m) if form == "ratio" else m)
    chi = np.angle(w) / 2

    def inverse(z):
        x, y = z.real, z.imag
        return np.stack((2 * x, 2 * y, 1 - x * x - y * y), axis=1) / (1 + x * x + y * y)[:, None]

    eps = 1e-6
    step = eps * np.exp(1j * chi)
    e = inverse(zeta + step) - inverse(zeta - step)
    return dolp, e / np.linalg.norm(e, axis=1)[:, None], w


@pytest.mark.parametrize("elevation", ELEVATIONS)
@pytest.mark.parametrize("separation", [0.0, 10.0, 25.0])
def test_berry_matches_closed_form(elevation, separation):
    if elevation == 90.0 and separation == 0.0:
        pytest.skip("the printed form has a root at ζ = 0 and its antipode at ∞ (see the Rayleigh-limit test)")
    sky = ClearSky(sun_direction=sun_at(elevation, 37.0), model="berry", max_degree=0.7,
                   neutral_separation_deg=separation)
    d = random_directions(400, seed=7 + int(elevation))
    dolp_ref, e_ref, w_ref = berry_reference(sky.sun, d, separation, 0.7)
    dolp, e = sky.polarisation(d)
    np.testing.assert_allclose(dolp, dolp_ref, atol=1e-9)
    np.testing.assert_allclose(sky.berry_field(d), w_ref, atol=1e-9)
    x = random_frames(d)
    s1, s2 = sky.stokes_linear(d, x)
    r1, r2 = stokes_from_e(dolp_ref, e_ref, d, x)
    np.testing.assert_allclose(s1, r1, atol=1e-6)
    np.testing.assert_allclose(s2, r2, atol=1e-6)
    np.testing.assert_allclose(np.sum(e * d, axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0, atol=1e-12)


@pytest.mark.parametrize("elevation", (0.0,) + ELEVATIONS)
def test_berry_without_separation_is_rayleigh(elevation):
    """d = 0, P_max = 1: |w| = sin²γ and the ratio form is Rayleigh's δ = 0 degree and e-vector exactly."""
    berry = ClearSky(sun_direction=sun_at(elevation), neutral_separation_deg=0.0, max_degree=1.0)
    d = random_directions(500, seed=12)
    dolp_ref, e_ref = rayleigh_reference(berry.sun, d, 0.0)
    dolp, e = berry.polarisation(d)
    np.testing.assert_allclose(dolp, dolp_ref, atol=1e-12)
    np.testing.assert_allclose(np.abs(np.sum(e * e_ref, axis=1)), 1.0, atol=1e-9)


def test_berry_modulus_form():
    sky = ClearSky(sun_direction=sun_at(30.0), berry_degree="modulus", max_degree=0.8)
    d = random_directions(200, seed=3)
    np.testing.assert_allclose(sky.polarisation(d)[0], berry_reference(sky.sun, d, 15.0, 0.8, "modulus")[0],
                               atol=1e-9)


@pytest.mark.parametrize("elevation", ELEVATIONS)
def test_berry_modulus_is_brewsters_product_and_vanishes_at_the_neutral_points(elevation):
    sky = ClearSky(sun_direction=sun_at(elevation, -70.0), neutral_separation_deg=18.0)
    pts = sky.neutral_points()
    # each point 18° from the sun (antisun) on the solar vertical; the pairs are antipodal
    for name, ref in (("babinet", sky.sun), ("brewster", sky.sun), ("arago", -sky.sun), ("fourth", -sky.sun)):
        assert math.degrees(math.acos(np.clip(pts[name] @ ref, -1, 1))) == pytest.approx(18.0, abs=1e-9)
        assert abs(np.linalg.det(np.stack((pts[name], sky.sun, [0, 0, 1])))) < 1e-12 or elevation == 90.0
    assert pts["babinet"][2] > pts["brewster"][2] or elevation == 90.0   # Babinet above the sun
    d = random_directions(300, seed=11)
    g_ba = np.arccos(np.clip(d @ pts["babinet"], -1, 1))
    g_br = np.arccos(np.clip(d @ pts["brewster"], -1, 1))
    np.testing.assert_allclose(np.abs(sky.berry_field(d)), np.sin(g_ba) * np.sin(g_br), atol=1e-12)
    visible = np.array([p for p in pts.values() if p[2] >= 0])
    assert len(visible) >= 2
    np.testing.assert_allclose(sky.polarisation(visible)[0], 0.0, atol=1e-15)


@pytest.mark.parametrize("elevation", [0.0, 20.0, 60.0])
def test_berry_maximum_ninety_degrees_from_the_sun(elevation):
    sky = ClearSky(sun_direction=sun_at(elevation, 10.0), max_degree=0.75)
    s = sky.sun
    side = np.cross([0, 0, 1], s) if elevation < 90 else np.array([0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    # the horizon points 90° in azimuth from the sun are 90° from every point of the solar vertical
    np.testing.assert_allclose(sky.polarisation(np.stack((side, -side)))[0], 0.75, atol=1e-12)
    d = random_directions(20000, seed=5)
    dolp = sky.polarisation(d)[0]
    assert dolp.max() <= 0.75 + 1e-12
    near = np.arccos(np.clip(d @ s, -1, 1)) < math.radians(10)
    assert dolp[near].max() < 0.1                                     # weak near the sun


def winding(sky, centre, radius_deg=2.0, n=721):
    """Total turn of 2ψ (ψ: the e-vector's angle in a fixed tangent frame at centre) once around a small
    circle about centre, in units of 2π: twice the singularity's index."""
    a = np.cross(centre, [0.3, -0.5, 0.8])
    a /= np.linalg.norm(a)
    b = np.cross(centre, a)
    t = np.linspace(0, 2 * math.pi, n)
    r = math.radians(radius_deg)
    pts = math.cos(r) * centre + math.sin(r) * (np.cos(t)[:, None] * a + np.sin(t)[:, None] * b)
    _, e = sky.polarisation(pts)
    two_psi = np.unwrap(2 * np.arctan2(e @ b, e @ a))
    return (two_psi[-1] - two_psi[0]) / (2 * math.pi)


def test_singularity_indices():
    """Rayleigh's sun is an index +1 point; Berry's splits it into two +1/2 points (the paper's §2)."""
    rayleigh = ClearSky(sun_direction=sun_at(40.0), model="rayleigh")
    assert abs(winding(rayleigh, rayleigh.sun)) == pytest.approx(2.0, abs=1e-6)
    berry = ClearSky(sun_direction=sun_at(40.0), neutral_separation_deg=15.0)
    pts = berry.neutral_points()
    for name in ("babinet", "brewster"):
        assert abs(winding(berry, pts[name])) == pytest.approx(1.0, abs=1e-6)
    assert abs(winding(berry, berry.sun, radius_deg=2.0)) == pytest.approx(0.0, abs=1e-6)   # no longer singular
    assert abs(winding(berry, berry.sun, radius_deg=30.0)) == pytest.approx(2.0, abs=1e-6)  # both points inside
    low = ClearSky(sun_direction=sun_at(5.0), neutral_separation_deg=15.0)                # Arago 10° up
    assert abs(winding(low, low.neutral_points()["arago"])) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("model", ["rayleigh", "berry"])
def test_pattern_turns_with_the_sun(model):
    sky = ClearSky(sun_direction=sun_at(35.0, 0.0), model=model)
    beta = math.radians(123.0)
    rz = np.array([[math.cos(beta), -math.sin(beta), 0], [math.sin(beta), math.cos(beta), 0], [0, 0, 1]])
    turned = ClearSky(sun_direction=tuple(rz @ sky.sun), model=model)
    d = random_directions(300, seed=9)
    p0, e0 = sky.polarisation(d)
    p1, e1 = turned.polarisation(d @ rz.T)
    np.testing.assert_allclose(p1, p0, atol=1e-12)
    np.testing.assert_allclose(np.abs(np.sum(e1 * (e0 @ rz.T), axis=1)), 1.0, atol=1e-9)


# --- Stokes frames ----------------------------------------------------------------------------------------

def test_s2_sign_convention():
    """Sun at the zenith, sky on the horizon along +X: e = ±Y.  In the frame x = (0, 1, 1)/√2 of the beam
    k = −X, y = k × x = (0, 1, −1)/√2, so e = (x + y)/√2: S2/S0 = +P, S1 = 0 (physics.md §0)."""
    sky = ClearSky(sun_direction=(0, 0, 1), model="rayleigh", delta=0.031)
    d = np.array([[1.0, 0.0, 0.0]])
    x = np.array([[0.0, 1.0, 1.0]]) / math.sqrt(2)
    s1, s2 = sky.stokes_linear(d, x)
    assert s1[0] == pytest.approx(0.0, abs=1e-15)
    assert s2[0] == pytest.approx((1 - 0.031) / (1 + 0.031), abs=1e-15)


def test_stokes_rotate_with_the_frame():
    """Re-expressing in x′ = cos φ x + sin φ y: S1′ = cos2φ S1 + sin2φ S2, S2′ = −sin2φ S1 + cos2φ S2."""
    sky = ClearSky(sun_direction=sun_at(25.0))
    d = random_directions(100, seed=4)
    x = random_frames(d)
    y = np.cross(-d, x)
    phi = np.random.default_rng(2).uniform(0, math.pi, len(d))
    x2 = np.cos(phi)[:, None] * x + np.sin(phi)[:, None] * y
    s1, s2 = sky.stokes_linear(d, x)
    t1, t2 = sky.stokes_linear(d, x2)
    np.testing.assert_allclose(t1, np.cos(2 * phi) * s1 + np.sin(2 * phi) * s2, atol=1e-12)
    np.testing.assert_allclose(t2, -np.sin(2 * phi) * s1 + np.cos(2 * phi) * s2, atol=1e-12)


# --- properties -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("model", ["rayleigh", "berry"])
@pytest.mark.parametrize("elevation", [0.0, 5.0, 45.0, 90.0])
def test_finite_and_bounded_everywhere(model, elevation):
    sky = ClearSky(sun_direction=sun_at(elevation), model=model, turbidity=6.0)
    special = [sky.sun, -sky.sun, [0, 0, 1], [0, 0, -1], [1, 0, 0], [0, -1, 0], [0.6, 0.8, 0.0]]
    special += list(sky.neutral_points().values())
    d = np.concatenate((np.array(special, dtype=float), random_directions(2000, seed=2, upper=False)))
    dolp, e = sky.polarisation(d)
    assert np.isfinite(dolp).all() and np.isfinite(e).all()
    assert (dolp >= 0).all() and (dolp <= 1).all()
    np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(e * d, axis=1), 0.0, atol=1e-12)
    assert (dolp[d[:, 2] < 0] == 0).all()                              # the ground is unpolarised
    rgb = sky.rgb(d)
    assert np.isfinite(rgb).all() and (rgb >= 0).all()
    s1, s2 = sky.stokes_linear(d, random_frames(d))
    np.testing.assert_allclose(np.hypot(s1, s2), dolp, atol=1e-12)


# --- Preetham radiance --------------------------------------------------------------------------------------

@pytest.mark.parametrize("elevation", ELEVATIONS)
@pytest.mark.parametrize("turbidity", [2.0, 2.2, 5.0, 9.0])
def test_zenith_equals_Yz(elevation, turbidity):
    sky = ClearSky(sun_direction=sun_at(elevation), turbidity=turbidity)
    th = math.radians(90 - elevation)
    chi = (4 / 9 - turbidity / 120) * (math.pi - 2 * th)
    yz = (4.0453 * turbidity - 4.9710) * math.tan(chi) - 0.2155 * turbidity + 2.4192
    x, y, big_y = sky.xyY([[0, 0, 1]])[0]
    assert big_y == pytest.approx(yz, rel=1e-12)
    assert (x, y) == pytest.approx(sky.zenith_xyY()[:2], rel=1e-12)
    assert yz > 0
    # the luminance of the RGB is Y × luminance_scale (no clipping at the zenith)
    xyz = sky.xyz([[0, 0, 1]])[0]
    assert xyz[1] == pytest.approx(0.06 * yz, rel=1e-12)


def test_zenith_chromaticity_polynomials():
    """x_z, y_z = [T², T, 1]·M·[θ³, θ², θ, 1]ᵀ written out term by term (Preetham et al. 1999, appendix)."""
    t, th = 3.0, math.radians(50.0)
    xz = ((0.00166 * th ** 3 - 0.00375 * th ** 2 + 0.00209 * th) * t * t
          + (-0.02903 * th ** 3 + 0.06377 * th ** 2 - 0.03202 * th + 0.00394) * t
          + (0.11693 * th ** 3 - 0.21196 * th ** 2 + 0.06052 * th + 0.25886))
    yz = ((0.00275 * th ** 3 - 0.00610 * th ** 2 + 0.00317 * th) * t * t
          + (-0.04214 * th ** 3 + 0.08970 * th ** 2 - 0.04153 * th + 0.00516) * t
          + (0.15346 * th ** 3 - 0.26756 * th ** 2 + 0.06670 * th + 0.26688))
    got = zenith_xyY(t, th)
    assert got[0] == pytest.approx(xz, rel=1e-14) and got[1] == pytest.approx(yz, rel=1e-14)
    np.testing.assert_allclose(perez_coefficients(3.0)[0], [0.1787 * 3 - 1.4630, -0.3554 * 3 + 0.4275,
                                                             -0.0227 * 3 + 5.3251, 0.1206 * 3 - 2.5771,
                                                             -0.0670 * 3 + 0.3703], rtol=1e-14)


@pytest.mark.parametrize("elevation", [5.0, 30.0, 60.0])
def test_symmetric_about_the_solar_meridian(elevation):
    sky = ClearSky(sun_direction=sun_at(elevation, 50.0), turbidity=3.0)
    n = np.cross(sky.sun, [0, 0, 1])
    n /= np.linalg.norm(n)                                            # normal of the solar meridian plane
    d = random_directions(300, seed=6)
    mirrored = d - 2 * (d @ n)[:, None] * n
    np.testing.assert_allclose(sky.rgb(mirrored), sky.rgb(d), rtol=1e-12, atol=1e-14)
    for model in ("rayleigh", "berry"):
        pol = ClearSky(sun_direction=sky.sun, model=model)
        np.testing.assert_allclose(pol.polarisation(mirrored)[0], pol.polarisation(d)[0], atol=1e-12)


@pytest.mark.parametrize("elevation", [20.0, 45.0, 70.0])
def test_brightest_near_the_sun(elevation):
    sky = ClearSky(sun_direction=sun_at(elevation, -30.0), turbidity=2.5)
    d = random_directions(40000, seed=8)
    y = sky.xyY(d)[:, 2]
    brightest = d[np.argmax(y)]
    assert math.degrees(math.acos(np.clip(brightest @ sky.sun, -1, 1))) < 3.0
    gamma = np.degrees(np.arccos(np.clip(d @ sky.sun, -1, 1)))
    assert np.median(y[gamma < 10]) > 1.5 * np.median(y[gamma > 60])


def test_rgb_matrix_maps_d65_to_white_and_ground_modes():
    sky = ClearSky(sun_direction=sun_at(40.0), luminance_scale=1.0)
    from engine.spectral import XYZ_TO_LINEAR_SRGB
    white = np.asarray(XYZ_TO_LINEAR_SRGB) @ np.array([0.3127 / 0.3290, 1.0, (1 - 0.3127 - 0.3290) / 0.3290])
    np.testing.assert_allclose(white, 1.0, atol=1e-12)
    below = np.array([[0.3, 0.2, -0.5], [0, 0, -1]])
    assert (sky.rgb(below) > 0).all()
    np.testing.assert_allclose(ClearSky(sun_direction=sky.sun, ground="black").rgb(below), 0.0)
    # "horizon": θ clamped to the horizon, γ from the true direction (Cycles' rule)
    flat = np.array([[0.3, 0.2, 0.0]]) / math.hypot(0.3, 0.2)
    assert sky.rgb([[0.3, 0.2, -1e-9]]) == pytest.approx(sky.rgb(flat), rel=1e-6)


def test_Yz_positive_over_the_allowed_range():
    for t in np.linspace(1.7, 10.0, 25):
        for el in np.linspace(0.0, 90.0, 31):
            assert zenith_xyY(t, math.radians(90 - el))[2] > 0


# --- validation ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("kwargs, name", [
    ({"sun_direction": (0, 0, 0)}, "sun_direction"),
    ({"sun_direction": (1, 0)}, "sun_direction"),
    ({"sun_direction": (0, float("nan"), 1)}, "sun_direction"),
    ({"sun_direction": (1, 0, -0.2)}, "sun_direction"),
    ({"turbidity": 1.0}, "turbidity"),
    ({"turbidity": 12.0}, "turbidity"),
    ({"turbidity": "haze"}, "turbidity"),
    ({"model": "hosek"}, "model"),
    ({"delta": -0.01}, "delta"),
    ({"delta": 0.5}, "delta"),
    ({"max_degree": 1.2}, "max_degree"),
    ({"neutral_separation_deg": 50.0}, "neutral_separation_deg"),
    ({"neutral_separation_deg": -1.0}, "neutral_separation_deg"),
    ({"berry_degree": "linear"}, "berry_degree"),
    ({"ground": "grass"}, "ground"),
    ({"luminance_scale": -1.0}, "luminance_scale"),
    ({"luminance_scale": float("inf")}, "luminance_scale"),
])
def test_invalid_parameters_name_their_field(kwargs, name):
    with pytest.raises(SceneError) as err:
        ClearSky(**kwargs)
    assert err.value.field == name
    assert name in str(err.value)


def test_invalid_directions_and_frames():
    sky = ClearSky()
    with pytest.raises(SceneError, match="directions"):
        sky.polarisation(np.zeros((2, 3)))
    with pytest.raises(SceneError, match="directions"):
        sky.rgb(np.ones((2, 2)))
    with pytest.raises(SceneError, match="x_axis"):
        sky.stokes_linear([[0, 0, 1]], [[0, 0, 2]])


def test_sun_is_normalised_and_the_sky_is_hashable():
    sky = ClearSky(sun_direction=(0, 3, 4))
    assert sky.sun_direction == pytest.approx((0, 0.6, 0.8))
    assert hash(sky) == hash(ClearSky(sun_direction=(0, 0.6, 0.8)))
    assert sky == ClearSky(sun_direction=(0, 0.6, 0.8))
