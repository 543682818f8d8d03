"""Participating media in the transport (engine.render.participating): delta tracking, medium vertices with
next-event estimation and phase sampling, ratio tracking.  Oracles independent of the tracer: Rayleigh's
single-scattering degree of polarisation in closed form (Hansen & Travis 1974), Beer–Lambert for the
unscattered light, the white furnace (an albedo-1 medium under a uniform sky of radiance 1 stays at 1), and
bit-identity with the scene without the medium."""

import copy

import numpy as np
import pytest

from engine.errors import SceneError
from engine.render.participating import ParticipatingPathTracer
from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene

from .test_absorption import MATCHED, box, scene

HG = {"type": "henyey_greenstein", "g": 0.6}


def render(data):
    return Renderer(parse_scene(copy.deepcopy(data))).render()


def mean_and_error(image: np.ndarray) -> tuple[float, float]:
    """The pixel mean and its standard error (pixels are independent samples of one expectation)."""
    return float(image.mean()), float(image.std(ddof=1) / np.sqrt(image.size))


def cube(surface: str, half=1.0):
    """The cube [−half, half]³: an index-matched dielectric surface, or none (alpha 0: a volume alone)."""
    obj = box([-half] * 3, [half] * 3)
    if surface == "pass-through":
        obj["alpha"] = 0.0
        return obj, {"type": "lambert", "albedo": 0.5}
    return obj, dict(MATCHED)


def furnace(interior, surface="pass-through", spp=32, size=16, **render_settings):
    obj, material = cube(surface)
    cam = {"projection": "orthographic", "ortho_width": 1.6, "origin": [0, 0, 5], "target": [0, 0, 0],
           "up": [0, 1, 0]}
    return scene([{**obj, "material": "fog"}], {"fog": {**material, "interior": interior}}, camera=cam,
                 lights=[{"type": "environment", "radiance": 1.0}], spp=spp, size=size,
                 **{"max_depth": 256, **render_settings})


# ----------------------------------------------------------------------------- single scattering: Rayleigh


def rayleigh_dolp(theta_deg: float, delta: float) -> float:
    c2 = np.cos(np.radians(theta_deg)) ** 2
    return (1 - delta) * (1 - c2) / (1 + delta + (1 - delta) * c2)


@pytest.mark.parametrize("delta", [0.0, 0.0279])
@pytest.mark.parametrize("theta", [60.0, 90.0, 135.0])
def test_rayleigh_single_scattering_polarises_as_hansen_and_travis(theta, delta):
    """A sun along −z through a cube of Rayleigh fog (no surface), seen along v with v_z = cos θ (the
    scattering angle θ between the sun's light and the light reaching the camera), max_depth 2: only
    once-scattered sunlight.  Its DoLP is (1 − δ) sin²θ/(1 + δ + (1 − δ) cos²θ), polarised ⟂ the scattering
    plane: along world y, the image's vertical (S1 < 0, S2 = 0)."""
    th = np.radians(theta)
    v = np.array([np.sin(th), 0.0, np.cos(th)])
    cam = {"projection": "orthographic", "ortho_width": 0.8, "origin": (-5 * v).tolist(), "target": [0, 0, 0],
           "up": [0, 1, 0]}
    obj, material = cube("pass-through")
    fog = {"scattering": 0.7, "absorption": 0.2, "phase": {"type": "rayleigh", "depolarisation": delta}}
    data = scene([{**obj, "material": "fog"}], {"fog": {**material, "interior": fog}}, camera=cam,
                 lights=[{"type": "directional", "direction": [0, 0, -1], "irradiance": 2.0}], spp=4, size=8,
                 max_depth=2)
    result = render(data)
    assert result.stats["transport"] == "linear"
    S = result.stokes()[..., 1].reshape(4, -1).sum(axis=1)
    assert S[0] > 0
    expected = rayleigh_dolp(theta, delta)
    assert S[1] / S[0] == pytest.approx(-expected, abs=1e-9)
    assert abs(S[2] / S[0]) < 1e-9


def test_rayleigh_single_scattering_in_full_stokes_and_spectral_mode_agrees():
    """The same with the full 4×4 transport and sampled wavelengths: S3 = 0 and the same DoLP."""
    v = np.array([1.0, 0.0, 0.0])
    cam = {"projection": "orthographic", "ortho_width": 0.8, "origin": (-5 * v).tolist(), "target": [0, 0, 0],
           "up": [0, 1, 0]}
    obj, material = cube("pass-through")
    fog = {"scattering": 0.7, "phase": {"type": "rayleigh", "depolarisation": 0.0279}}
    data = scene([{**obj, "material": "fog"}], {"fog": {**material, "interior": fog}}, camera=cam,
                 lights=[{"type": "directional", "direction": [0, 0, -1], "irradiance": 2.0}], spp=4, size=8,
                 max_depth=2, polarisation="full", spectral="spectral", reduce_spectral="off")
    S = render(data).stokes()[..., 1].reshape(4, -1).sum(axis=1)
    assert S[1] / S[0] == pytest.approx(-rayleigh_dolp(90.0, 0.0279), abs=1e-6)
    assert abs(S[2] / S[0]) < 1e-9 and abs(S[3] / S[0]) < 1e-9


# ----------------------------------------------------------------------------- energy: the white furnace


@pytest.mark.parametrize("surface", ["pass-through", "index-matched"])
def test_albedo_one_medium_in_a_white_furnace_stays_at_the_furnace_radiance(surface):
    """HG fog (g = 0.6, optical thickness 4 across) of albedo 1 in a uniform sky of radiance 1: every pixel's
    expectation is 1, behind a surface-less volume and behind an index-matched dielectric (whose faces
    block next-event estimation, so the light comes through phase sampling alone)."""
    result = render(furnace({"albedo": 1.0, "density": 2.0, "phase": HG}, surface))
    m, e = mean_and_error(result.stokes()[0][..., 1])
    assert np.isfinite(result.stokes()).all() and result.stats["nonfinite"] == 0
    assert e < 0.01
    assert abs(m - 1.0) < 4 * e + 2e-3


def test_grid_medium_in_a_white_furnace_stays_at_the_furnace_radiance():
    """A random density grid (0–3 per unit) of albedo 1: delta tracking through the grid's null collisions
    and ratio tracking of the shadow rays keep the furnace at 1."""
    values = np.random.default_rng(7).uniform(0.0, 3.0, (5, 5, 5)).tolist()
    grid = {"values": values, "bounds": [[-1.1, -1.1, -1.1], [1.1, 1.1, 1.1]]}
    result = render(furnace({"albedo": 1.0, "density": 1.0, "phase": HG, "grid": grid}))
    m, e = mean_and_error(result.stokes()[0][..., 1])
    assert e < 0.01 and abs(m - 1.0) < 4 * e + 2e-3


# ----------------------------------------------------------------------------- Beer–Lambert, majorants


def thick_slab(interior, spp=64, size=24):
    """A camera looking down through the cube (2 units of fog) at an emitter of radiance 1 below it,
    max_depth 1: only the unscattered light."""
    obj, material = cube("pass-through")
    cam = {"projection": "orthographic", "ortho_width": 1.6, "origin": [0, 0, 5], "target": [0, 0, 0],
           "up": [0, 1, 0]}
    return scene([{**obj, "material": "fog"},
                  {"shape": "quad", "vertices": [[-4, -4, -2], [4, -4, -2], [4, 4, -2], [-4, 4, -2]],
                   "material": "black", "emission": {"radiance": 1.0}}],
                 {"fog": {**material, "interior": interior}}, camera=cam, spp=spp, size=size, max_depth=1)


def test_unscattered_light_through_an_optically_thick_slab_follows_beer_lambert_per_channel():
    """σ_s = (1, 1.5, 2), σ_a = 0.25 per unit over 2 units (optical depths 2.5–4.5): the unscattered light is
    exp(−(σ_s + σ_a)·2) per channel; the majorant is the largest channel's, so the red and green
    channels see null collisions with spectral-tracking weights."""
    sigma_s, sigma_a = np.array([1.0, 1.5, 2.0]), 0.25
    result = render(thick_slab({"scattering": sigma_s.tolist(), "absorption": sigma_a, "phase": HG}, spp=256))
    img = result.stokes()[0]
    for c in range(3):
        m, e = mean_and_error(img[..., c])
        expected = np.exp(-(sigma_s[c] + sigma_a) * 2.0)
        assert abs(m - expected) < 4 * e + 1e-3 * expected, (c, m, expected, e)


def test_a_loose_majorant_gives_the_same_mean_as_a_tight_one():
    """The furnace-free slab with multiple scattering lit from below: majorant 1 (tight) and 5 (four null
    collisions per real one) agree within their noise."""
    def slab(majorant):
        data = thick_slab({"albedo": 0.8, "density": 1.0, "phase": HG, "majorant": majorant}, spp=32, size=16)
        data["render"]["max_depth"] = 6
        return data
    (m1, e1), (m5, e5) = (mean_and_error(render(slab(k)).stokes()[0][..., 1]) for k in (1.0, 5.0))
    assert m1 > 0.05
    assert abs(m1 - m5) < 4 * np.hypot(e1, e5)


def test_an_index_matched_boundary_and_a_volume_without_surface_give_the_same_multiple_scattering():
    """The slab lit from below (albedo 0.8, up to 5 scattering events) bounded by an index-matched dielectric
    (stack changed at the path's own vertices; next-event estimation blocked by the faces) and by no surface
    (stack changed at pass-through crossings, mid-segment; shadow rays through): the same expectation.  A
    path that scatters between two crossings keeps the stack where it scattered (a furnace cannot tell)."""
    def slab(surface):
        obj, material = cube(surface)
        data = thick_slab({"albedo": 0.8, "density": 1.0, "phase": HG}, spp=32, size=16)
        data["objects"][0] = {**obj, "material": "fog"}
        data["materials"]["fog"] = {**material, "interior": data["materials"]["fog"]["interior"]}
        data["render"]["max_depth"] = 6
        return data
    (m1, e1), (m2, e2) = (mean_and_error(render(slab(s)).stokes()[0][..., 1]) for s in ("pass-through",
                                                                                      "index-matched"))
    assert np.isfinite([m1, m2]).all() and m1 > 0.05
    assert abs(m1 - m2) < 4 * np.hypot(e1, e2)


# ----------------------------------------------------------------------------- multiple scattering: Chandrasekhar


def chandrasekhar_h(omega: float, mu: float, nodes: int = 64) -> float:
    """Chandrasekhar's H-function of isotropic scattering with albedo ω < 1 (Radiative Transfer, 1950, ch. V):
    H(μ) = 1/(1 − (ω/2) μ ∫₀¹ H(μ')/(μ + μ') dμ'), iterated to convergence on Gauss–Legendre nodes."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    x, w = 0.5 * (x + 1.0), 0.5 * w
    H = np.ones_like(x)
    for _ in range(20000):
        new = 1.0 / (1.0 - 0.5 * omega * x * (w * H / (x[:, None] + x[None, :])).sum(axis=1))
        done = np.max(np.abs(new - H)) < 1e-15
        H = new
        if done:
            break
    return float(1.0 / (1.0 - 0.5 * omega * mu * (w * H / (mu + x)).sum()))


@pytest.mark.parametrize("omega", [0.5, 0.8, 0.95])
def test_chandrasekhar_h_function_has_its_exact_zeroth_moment(omega):
    """∫₀¹ H(μ) dμ = (2/ω)(1 − √(1 − ω)) (Chandrasekhar 1950, eq. V.(34)), by independent quadrature."""
    x, w = np.polynomial.legendre.leggauss(200)
    moment = sum(0.5 * wi * chandrasekhar_h(omega, 0.5 * (xi + 1.0)) for xi, wi in zip(x, w))
    assert moment == pytest.approx(2.0 / omega * (1.0 - np.sqrt(1.0 - omega)), rel=1e-6)


def test_multiple_scattering_from_a_semi_infinite_isotropic_medium_matches_chandrasekhar():
    """A sun of irradiance E at zenith angle θ0 on a semi-infinite isotropic medium of albedo ω (a box 30 mean
    free paths deep, 120 wide, no surface) seen at zenith angle θ: the reflected radiance, all orders of
    scattering, is E ω μ0 H(μ) H(μ0)/(4π (μ + μ0)) (Chandrasekhar 1950, eq. V.(2)–(3) with πF = E)."""
    omega, E, th0, th = 0.8, 3.0, 30.0, 50.0
    mu0, mu = np.cos(np.radians(th0)), np.cos(np.radians(th))
    expected = E * omega * mu0 * chandrasekhar_h(omega, mu) * chandrasekhar_h(omega, mu0) / (4 * np.pi * (mu + mu0))
    obj = box([-60, -60, -30], [60, 60, 0])
    obj["alpha"] = 0.0
    v = np.array([-np.sin(np.radians(th)), 0.0, -np.cos(np.radians(th))])
    cam = {"projection": "orthographic", "ortho_width": 1.0, "origin": (-10 * v).tolist(), "target": [0, 0, 0],
           "up": [0, 1, 0]}
    sun = [np.sin(np.radians(th0)), 0.0, -mu0]
    data = scene([{**obj, "material": "fog"}],
                 {"fog": {"type": "lambert", "albedo": 0.5, "interior": {"albedo": omega, "density": 1.0}}},
                 camera=cam, lights=[{"type": "directional", "direction": sun, "irradiance": E}], spp=64, size=16,
                 max_depth=400)
    m, e = mean_and_error(render(data).stokes()[0][..., 1])
    assert e < 0.01 * expected
    assert abs(m - expected) < 4 * e + 2e-3 * expected


# ----------------------------------------------------------------------------- scenes without scattering


def lit_floor(interior=None, medium=None):
    obj, material = cube("pass-through", 0.5)
    floor = {"shape": "quad", "vertices": [[-3, -3, -1], [3, -3, -1], [3, 3, -1], [-3, 3, -1]], "material": "floor"}
    cam = {"projection": "perspective", "fov_deg": 40, "origin": [0, -4, 3], "target": [0, 0, -0.5], "up": [0, 0, 1]}
    mats = {"floor": {"type": "lambert", "albedo": 0.6},
            "fog": {**material, **({"interior": interior} if interior is not None else {})}}
    data = scene([{**obj, "material": "fog"}, floor], mats, camera=cam,
                 lights=[{"type": "point", "position": [1, -1, 2], "intensity": 10.0}], spp=4, size=12)
    if medium is not None:
        data["medium"] = medium
    return data


@pytest.mark.parametrize("zero", [
    {"scattering": 0.0, "phase": {"type": "rayleigh"}},
    {"albedo": 0.5, "density": 0.0, "phase": HG},
    {"scattering": 1.0, "absorption": 1.0, "grid": {"values": np.zeros((2, 2, 2)).tolist(),
                                                    "bounds": [[-1, -1, -1], [1, 1, 1]]}}])
def test_density_zero_renders_bit_identically_to_no_medium(zero):
    plain = render(lit_floor()).stokes()
    np.testing.assert_array_equal(render(lit_floor(zero)).stokes(), plain)
    np.testing.assert_array_equal(render(lit_floor(medium=zero)).stokes(), plain)


def test_a_scattering_medium_chooses_the_media_tracer_and_the_transport_its_phase_function_needs():
    cases = [({"type": "henyey_greenstein", "g": 0.3}, "off"), ({"type": "rayleigh"}, "linear"),
             ({"type": "mie", "radius": 0.2}, "full")]
    for phase, transport in cases:
        for where in ("interior", "medium"):
            fog = {"scattering": 0.5, "phase": phase}
            r = Renderer(parse_scene(lit_floor(fog) if where == "interior" else lit_floor(medium=fog)))
            plan = r.plan()
            assert plan.settings.polarisation == transport, (phase, where, plan.transport_reason)
            assert isinstance(r.tracer(plan), ParticipatingPathTracer)


def test_world_fog_dims_and_scatters_the_light_finitely():
    """Homogeneous world fog around the lit floor: finite, darker where the floor is far, brighter than
    nothing in the sky (in-scattered light)."""
    plain = render(lit_floor()).stokes()[0]
    foggy = render(lit_floor(medium={"albedo": 0.9, "density": 0.3, "phase": HG})).stokes()[0]
    assert np.isfinite(foggy).all()
    sky = plain[0, :, 1] == 0                                       # the top row sees no floor without fog
    assert sky.any() and (foggy[0, sky, 1] > 0).all()


@pytest.mark.parametrize("bad, field", [
    ({"albedo": 1.5, "density": 1.0}, "materials.fog.interior.albedo"),
    ({"scattering": -1.0}, "materials.fog.interior.scattering"),
    ({"scattering": 1.0, "phase": {"type": "fog"}}, "materials.fog.interior.phase.type"),
    ({"scattering": 1.0, "phase": {"type": "henyey_greenstein", "g": 2.0}}, "materials.fog.interior.phase.g"),
    ({"scattering": 1.0, "majorant": 0.5}, "materials.fog.interior.majorant"),
    ({"scattering": 1.0, "grid": {"values": [[1.0, 2.0]], "bounds": [[0, 0, 0], [1, 1, 1]]}},
     "materials.fog.interior.grid.values"),
    ({"scattering": 1.0, "grid": {"values": np.ones((2, 2, 2)).tolist(), "bounds": [[0, 0, 0], [1, 0, 1]]}},
     "materials.fog.interior.grid.bounds"),
    ({"scattering": 1.0, "albedo": 0.5, "density": 1.0}, "materials.fog.interior.scattering")])
def test_bad_media_are_refused_in_one_line_naming_the_field(bad, field):
    with pytest.raises(SceneError) as e:
        parse_scene(lit_floor(bad))
    assert e.value.field == field and "\n" not in str(e.value)


# ----------------------------------------------------------------------------- volume emission


def glowing_box(interior, spp=64, size=12, **render_settings):
    """The camera looking down through the cube (2 units of medium, no surface) at nothing: only the medium's
    emission, max_depth 1 (no scattered light)."""
    obj, material = cube("pass-through")
    cam = {"projection": "orthographic", "ortho_width": 1.6, "origin": [0, 0, 5], "target": [0, 0, 0],
           "up": [0, 1, 0]}
    return scene([{**obj, "material": "fire"}], {"fire": {**material, "interior": interior}}, camera=cam, spp=spp,
                 size=size, **{"max_depth": 1, **render_settings})


def emitted(eps, sigma_t, d=2.0):
    """∫₀ᵈ ε e^{−σ_t s} ds = ε/σ_t (1 − e^{−σ_t d}) (ε·d without extinction)."""
    eps, sigma_t = np.broadcast_arrays(np.asarray(eps, float), np.asarray(sigma_t, float))
    safe = np.where(sigma_t > 0, sigma_t, 1.0)
    return np.where(sigma_t > 0, eps / safe * -np.expm1(-sigma_t * d), eps * d)


@pytest.mark.parametrize("medium, sigma_t", [
    ({"absorption": [0.3, 0.8, 2.0], "emission": [1.0, 2.0, 3.0]}, [0.3, 0.8, 2.0]),
    ({"absorption": [0.2, 0.2, 0.2], "scattering": [0.1, 0.4, 1.0], "phase": HG, "emission": [1.0, 2.0, 3.0]},
     [0.3, 0.6, 1.2]),
    ({"absorption": [0.3, 0.8, 2.0], "majorant": 3.0, "grid": {"values": np.ones((2, 2, 2)).tolist(),
                                                               "bounds": [[-1, -1, -1], [1, 1, 1]]},
      "emission_grid": {"values": np.ones((3, 2, 2, 2)).tolist(), "bounds": [[-1, -1, -1], [1, 1, 1]]}},
     [0.3, 0.8, 2.0]),
    ({"emission": 0.5}, [0.0, 0.0, 0.0])])
def test_an_emitting_box_glows_as_the_integral_of_its_attenuated_emission_per_channel(medium, sigma_t):
    """Emission ε in an absorbing (and scattering: max_depth 1 keeps only the unscattered part) box 2 units
    deep: ε/σ_t (1 − e^{−2σ_t}) per channel — homogeneous, on a density grid with a loose majorant and a
    per-point emission grid of ε = 1, and without extinction (ε·2, collisions at the emitters' least rate)."""
    eps = np.asarray(medium.get("emission", 1.0), float)
    img = render(glowing_box(medium)).stokes()[0]
    expected = emitted(eps * np.ones(3), sigma_t)
    for c in range(3):
        m, e = mean_and_error(img[..., c])
        assert abs(m - expected[c]) < 4 * e + 2e-3 * expected[c], (c, m, expected[c], e)


def test_an_emitting_box_with_a_coloured_emission_in_spectral_transport_develops_to_the_analytic_colour():
    """Grey σ_t = 0.7 and ε = (1, 2, 3) carried per wavelength (no RGB reduction): the image develops to
    ε_rgb/σ_t (1 − e^{−2σ_t}) (linear in ε, so exact per channel) within the colour noise."""
    img = render(glowing_box({"absorption": 0.7, "emission": [1.0, 2.0, 3.0]}, spp=64,
                             reduce_spectral="off")).stokes()[0]
    expected = emitted(np.array([1.0, 2.0, 3.0]), 0.7)
    for c in range(3):
        m, e = mean_and_error(img[..., c])
        assert abs(m - expected[c]) < 4 * e + 1e-2 * expected[c], (c, m, expected[c], e)


# ----------------------------------------------------------------------------- transparent film


def test_a_transparent_film_counts_camera_rays_that_scatter_in_fog_as_opaque():
    """Nothing but fog under a transparent film: in world fog every camera ray scatters (alpha 1 everywhere,
    Cycles' too); through a 2-unit box of grey fog σ_t = 0.6 the alpha is the chance to scatter or be absorbed,
    1 − e^{−1.2}, within 4σ (it was 0: every ray that missed the surfaces counted as transparent)."""
    world = glowing_box({"albedo": 1.0, "density": 0.6, "phase": HG}, spp=16, size=8)
    world["objects"] = []
    world["medium"] = {"albedo": 1.0, "density": 0.6, "phase": HG}
    world["camera"]["film_transparent"] = True
    a = Renderer(parse_scene(world)).render().film.alpha()
    np.testing.assert_array_equal(a, 1.0)
    box_fog = glowing_box({"albedo": 0.5, "density": 0.6, "phase": HG}, spp=64, size=8, max_depth=4)
    box_fog["camera"]["film_transparent"] = True
    m, e = mean_and_error(Renderer(parse_scene(box_fog)).render().film.alpha())
    expected = -np.expm1(-1.2)
    assert abs(m - expected) < 4 * e + 1e-3, (m, expected, e)


# ----------------------------------------------------------------------------- colour grids

RED, BLUE = np.array([0.9, 0.2, 0.1]), np.array([0.1, 0.3, 0.8])
SCATTER, ABSORB = 1.5, 0.6             # σ_s, σ_a at unit density and colour: σ_s·C, σ_a·max(1 − C, 0)


def colour_box(interior, **render_settings):
    """The cube lit by a sun along −z and seen from +z (backscatter, θ = 180°), max_depth 2: once-scattered
    sunlight along lines of constant x, so each half of the image sees only its half of the medium."""
    obj, material = cube("pass-through")
    cam = {"projection": "orthographic", "ortho_width": 1.6, "origin": [0, 0, 5], "target": [0, 0, 0],
           "up": [0, 1, 0]}
    return scene([{**obj, "material": "fog"}], {"fog": {**material, "interior": interior}}, camera=cam,
                 lights=[{"type": "directional", "direction": [0, 0, -1], "irradiance": 2.0}], spp=64, size=12,
                 **{"max_depth": 2, **render_settings})


def backscattered(colour) -> np.ndarray:
    """Single-scattered sunlight (E = 2, isotropic phase) from 2 units of σ_s = 1.5·C, σ_a = 0.6·(1 − C):
    ∫₀² σ_s E/(4π) e^{−2σ_t s} ds = σ_s E/(4π)·(1 − e^{−4σ_t})/(2σ_t) per channel."""
    s = SCATTER * colour
    t = s + ABSORB * (1.0 - colour)
    return s * 2.0 / (4 * np.pi) * -np.expm1(-4 * t) / (2 * t)


def red_blue_grid() -> dict:
    """A colour grid red for x < 0 and blue for x > 0 (41 nodes along x: the blend is |x| < 0.05)."""
    v = np.zeros((3, 41, 2, 2))
    v[:, :20] = RED[:, None, None, None]
    v[:, 21:] = BLUE[:, None, None, None]
    v[:, 20] = ((RED + BLUE) / 2)[:, None, None]
    return {"values": v.tolist(), "bounds": [[-1, -1, -1], [1, 1, 1]]}


UNIT_GRID = {"values": np.ones((2, 2, 2)).tolist(), "bounds": [[-1, -1, -1], [1, 1, 1]]}


@pytest.mark.parametrize("settings", [{}, {"spectral": "spectral", "reduce_spectral": "off"}])
def test_a_red_and_blue_colour_grid_scatters_each_half_as_a_homogeneous_medium_of_its_colour(settings):
    """σ_s = 1.5·C(x), σ_a = 0.6·max(1 − C(x), 0) (Cycles' Principled Volume) on a density grid of 1 and a colour
    grid red on the left, blue on the right: each half (pixels |x| > 0.25) develops to the analytic single
    scattering of its colour within 4σ per channel, as does the homogeneous medium of that colour (σ_s = 1.5·C,
    σ_a = 0.6·(1 − C), no grid) — in RGB and in spectral transport (C upsampled as a reflectance)."""
    coloured = render(colour_box({"scattering": SCATTER, "absorption": ABSORB, "grid": UNIT_GRID,
                                  "colour_grid": red_blue_grid()}, **settings)).stokes()[0]
    for colour, cols in ((RED, slice(0, 4)), (BLUE, slice(8, 12))):
        homogeneous = render(colour_box({"scattering": (SCATTER * colour).tolist(),
                                         "absorption": (ABSORB * (1 - colour)).tolist()}, **settings)).stokes()[0]
        expected = backscattered(colour)
        for img in (coloured, homogeneous):
            for c in range(3):
                m, e = mean_and_error(img[:, cols, c])
                assert abs(m - expected[c]) < 4 * e + 2e-3 * expected[c], (colour, c, m, expected[c], e)


def test_a_colour_grid_needs_a_density_grid():
    with pytest.raises(SceneError, match="colour_grid"):
        parse_scene(colour_box({"scattering": 1.0, "absorption": 0.5, "colour_grid": red_blue_grid()}))
