"""Polarised light sources in the transport (issue 35): Malus' law through an in-scene polariser, a circular
source through a quarter-wave retarder and a polariser as Jones calculus predicts, a polarised source seen in
a smooth dielectric as the Fresnel Mueller matrix predicts, next-event estimation of a polarised sun on a
rough dielectric as the model's Mueller matrix predicts — each expected value written here from the
conventions (docs/physics.md §0), not taken from the renderer.  And: unpolarised scenes keep their bits."""

import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.materials.evaluate import mueller_at
from engine.render.renderer import render
from engine.scene.loader import parse_scene

LUMA = np.array([0.2126, 0.7152, 0.0722])


def _scene(objects, materials, camera=None, lights=(), spp=4, polarisation="auto", size=8):
    cam = camera or {"projection": "orthographic", "origin": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0],
                     "ortho_width": 1.0}
    cam = {"width": size, "height": size, **cam}
    return parse_scene({"format": "polar-scene/1", "camera": cam,
                        "render": {"spp": spp, "max_depth": 8, "seed": 3, "polarisation": polarisation,
                                   "sampler": "independent"},
                        "materials": materials, "objects": list(objects), "lights": list(lights)})


def _screen(polarisation, z=0.0, radiance=1.0, half=3.0, axis_key=True):
    em = {"radiance": radiance, "polarisation": polarisation}
    return {"name": "screen", "shape": "quad", "material": "black", "emission": em,
            "vertices": [[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]]}


def _sheet(name, z, material, half=3.0):
    return {"name": name, "shape": "quad", "material": material,
            "vertices": [[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]]}


def _stokes(result):
    """Mean luminance Stokes (4,) over the image."""
    return np.einsum("shwc,c->s", result.stokes(), LUMA) / (result.film.width * result.film.height)


def _axis(deg):
    return [math.cos(math.radians(deg)), math.sin(math.radians(deg)), 0.0]


BLACK = {"black": {"type": "lambert", "albedo": 0.0}}


@pytest.mark.parametrize("psi", [0.0, 30.0, 45.0, 90.0, 135.0])
def test_a_screen_seen_directly_has_its_angle(psi):
    """Light travelling +z to a camera looking down −z with up +y: the camera frame x = d × up = +X, y = +Y, the
    emitter frame x_e = X, y_e = k × X = +Y — the same: S/S0 = (cos 2ψ, sin 2ψ, 0)."""
    r = render(_scene([_screen({"type": "linear", "angle": psi})], BLACK))
    S = _stokes(r)
    assert r.stats["transport"] == "linear"
    assert S[0] == pytest.approx(1.0, rel=1e-3)
    assert S[1] / S[0] == pytest.approx(math.cos(2 * math.radians(psi)), abs=1e-9)
    assert S[2] / S[0] == pytest.approx(math.sin(2 * math.radians(psi)), abs=1e-9)


@pytest.mark.parametrize("theta", [0.0, 20.0, 45.0, 60.0, 90.0])
@pytest.mark.parametrize("degree", [1.0, 0.5])
def test_malus_law_through_an_in_scene_polariser(theta, degree):
    """A linear source (angle 10°, degree P) through an ideal polariser at θ: S0 = L (1 + P cos 2(θ − 10°)) / 2."""
    mats = {**BLACK, "pol": {"type": "polariser", "axis": _axis(theta)}}
    r = render(_scene([_screen({"type": "linear", "angle": 10.0, "degree": degree}), _sheet("filter", 1.0, "pol")],
                      mats))
    expected = 0.5 * (1.0 + degree * math.cos(2 * math.radians(theta - 10.0)))
    assert _stokes(r)[0] == pytest.approx(expected, abs=2e-3)


def _jones_circular_through(handed, retarder_axis_deg, polariser_deg):
    """Transmitted intensity of unit right/left-circular light (S3 = ±1: E_y lags/leads E_x by 90°,
    S3 = 2 Im(E_x E_y*)) through a quarter-wave plate (fast axis at the given angle: Jones diag(1, i) in its
    frame) and an ideal polariser, in Jones calculus."""
    E = np.array([1.0, -1j if handed == "right" else 1j]) / math.sqrt(2)
    assert 2 * (E[0] * np.conj(E[1])).imag == pytest.approx(1.0 if handed == "right" else -1.0)

    def rot(deg):
        c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
        return np.array([[c, -s], [s, c]])

    qwp = rot(retarder_axis_deg) @ np.diag([1.0, 1j]) @ rot(-retarder_axis_deg)
    pol = rot(polariser_deg) @ np.diag([1.0, 0.0]) @ rot(-polariser_deg)
    out = pol @ qwp @ E
    return float(np.vdot(out, out).real)


@pytest.mark.parametrize("handed", ["right", "left"])
@pytest.mark.parametrize("polariser_deg", [45.0, -45.0, 0.0, 30.0])
def test_a_circular_source_through_a_quarter_wave_plate_and_a_polariser(handed, polariser_deg):
    mats = {**BLACK, "qwp": {"type": "retarder", "axis": _axis(0.0), "retardance_deg": 90.0},
            "pol": {"type": "polariser", "axis": _axis(polariser_deg)}}
    scene = _scene([_screen({"type": "circular", "handedness": handed}), _sheet("plate", 0.5, "qwp"),
                    _sheet("filter", 1.0, "pol")], mats)
    r = render(scene)
    assert r.stats["transport"] == "full"
    assert _stokes(r)[0] == pytest.approx(_jones_circular_through(handed, 0.0, polariser_deg), abs=2e-3)


def _fresnel_abcs(eta, cos_t):
    """(A, B, C, S) of the Fresnel reflection matrix (docs/physics.md §0), written here from r_s, r_p."""
    sin2 = 1.0 - cos_t * cos_t
    u = np.sqrt(complex(eta * eta - sin2))
    rs = (cos_t - u) / (cos_t + u)
    rp = (eta * eta * cos_t - u) / (eta * eta * cos_t + u)
    Fs, Fp = abs(rs) ** 2, abs(rp) ** 2
    return (Fs + Fp) / 2, (Fs - Fp) / 2, (rs * np.conj(rp)).real, -(rs * np.conj(rp)).imag


def _rotate(S, x_from, y_from, x_to):
    """S re-expressed from frame (x_from, y_from) to the coaxial frame with x axis x_to (§0)."""
    c, s = float(np.dot(x_from, x_to)), float(np.dot(y_from, x_to))
    c2, s2 = c * c - s * s, 2 * c * s
    return np.array([S[0], c2 * S[1] + s2 * S[2], -s2 * S[1] + c2 * S[2], S[3]])


@pytest.mark.parametrize("psi", [0.0, 45.0, 90.0, 120.0])
def test_a_polarised_source_seen_in_a_smooth_dielectric(psi):
    """A screen (reference axis world +Y, angle ψ) seen in a black-glass floor at 50°: the camera's Stokes vector
    is the Fresnel matrix times the source's, in the s/p frames, rotated into the camera frame."""
    theta = math.radians(50.0)
    d = np.array([math.sin(theta), 0.0, -math.cos(theta)])        # camera ray, looking down at the floor
    r_dir = np.array([math.sin(theta), 0.0, math.cos(theta)])     # mirrored: towards the screen
    centre = r_dir * 4.0
    # a screen facing the floor, ⟂ r_dir, its reference axis +Y
    u_ax = np.array([0.0, 1.0, 0.0])
    v_ax = np.cross(r_dir, u_ax)
    half = 6.0
    corners = [centre + half * (a * u_ax + b * v_ax) for a, b in ((-1, -1), (-1, 1), (1, 1), (1, -1))]
    normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
    if np.dot(normal, r_dir) > 0:            # face the floor (emission from the front face)
        corners = corners[::-1]
    screen = {"name": "screen", "shape": "quad", "material": "black", "vertices": [c.tolist() for c in corners],
              "emission": {"radiance": 1.0, "polarisation": {"type": "linear", "angle": psi, "axis": [0, 1, 0]}}}
    floor = _sheet("floor", 0.0, "glass", half=50.0)
    cam = {"projection": "orthographic", "origin": (-d * 3.0).tolist(), "target": [0, 0, 0], "up": [0, 0, 1],
           "ortho_width": 0.2}
    r = render(_scene([screen, floor], {**BLACK, "glass": {"type": "black_glass", "n": 1.5}}, camera=cam, spp=2))
    got = _stokes(r)
    # the source: light along k_i = −r_dir, frame x_e = +Y (⟂ k_i), y_e = k_i × x_e
    k_i = -r_dir
    x_e = u_ax
    y_e = np.cross(k_i, x_e)
    S_e = np.array([1.0, math.cos(2 * math.radians(psi)), math.sin(2 * math.radians(psi)), 0.0])
    # the s/p frames: x = s = unit(n × k_i) on both beams, y = k × s
    n = np.array([0.0, 0.0, 1.0])
    s_ax = np.cross(n, k_i) / np.linalg.norm(np.cross(n, k_i))
    S_in = _rotate(S_e, x_e, y_e, s_ax)
    A, B, C, Sg = _fresnel_abcs(1.5, math.cos(theta))
    M = np.array([[A, B, 0, 0], [B, A, 0, 0], [0, 0, C, Sg], [0, 0, -Sg, C]])
    S_out = M @ S_in
    k_o = -d
    x_cam = np.cross(d, [0, 0, 1.0])
    x_cam /= np.linalg.norm(x_cam)
    expected = _rotate(S_out, s_ax, np.cross(k_o, s_ax), x_cam)
    assert got[0] == pytest.approx(expected[0], rel=2e-3)
    np.testing.assert_allclose(got[1:3] / got[0], expected[1:3] / expected[0], atol=2e-3)


@pytest.mark.parametrize("psi", [0.0, 60.0, 135.0])
def test_next_event_estimation_of_a_polarised_sun_on_a_rough_dielectric(psi):
    """A polarised sun (delta: next-event estimation only) on a rough Torrance–Sparrow dielectric seen at
    θ_o = 30°: S = M_sp(θ_i, θ_o) · S_e · E cos θ_i in the oracle basis (engine.materials.evaluate, checked
    against SCATMECH elsewhere), rotated into the camera frame."""
    theta_i, theta_o = 40.0, 30.0
    mat = {"type": "torrance_sparrow", "n": 1.5, "m": 0.3}
    w_i = np.array([-math.sin(math.radians(theta_i)), 0.0, math.cos(math.radians(theta_i))])
    w_o = np.array([math.sin(math.radians(theta_o)), 0.0, math.cos(math.radians(theta_o))])
    sun = {"type": "directional", "direction": (-w_i).tolist(), "irradiance": 1.0,
           "polarisation": {"type": "linear", "angle": psi, "axis": [0, 1, 0]}}
    cam = {"projection": "orthographic", "origin": (w_o * 3).tolist(), "target": [0, 0, 0], "up": [0, 0, 1],
           "ortho_width": 0.2}
    scene = _scene([_sheet("plane", 0.0, "rough", half=20.0)], {"rough": mat}, camera=cam, lights=[sun], spp=2)
    got = _stokes(render(scene))
    M = mueller_at(scene.materials["rough"], theta_i, theta_o, 0.0, basis="sp")["brdf"]
    k_i, k_o = -w_i, w_o
    z = np.array([0.0, 0.0, 1.0])
    s_i = np.cross(z, k_i) / np.linalg.norm(np.cross(z, k_i))
    s_o = np.cross(z, k_o) / np.linalg.norm(np.cross(z, k_o))
    x_e = np.array([0.0, 1.0, 0.0])
    S_e = np.array([1.0, math.cos(2 * math.radians(psi)), math.sin(2 * math.radians(psi)), 0.0])
    S_in = _rotate(S_e, x_e, np.cross(k_i, x_e), s_i)
    S_out = np.asarray(M) @ S_in * math.cos(math.radians(theta_i))
    d = -w_o
    x_cam = np.cross(d, z) / np.linalg.norm(np.cross(d, z))
    expected = _rotate(S_out, s_o, np.cross(k_o, s_o), x_cam)
    assert got[0] == pytest.approx(expected[0], rel=5e-3)
    np.testing.assert_allclose(got[1:3] / got[0], expected[1:3] / expected[0], atol=5e-3)


def test_an_unpolarised_light_with_polarisation_none_keeps_the_scene_unpolarised():
    a = _scene([_screen({"type": "none"})], BLACK)
    assert getattr(a.meshes[0], "emission_polarisation", None) is None
    r = render(a)
    assert r.stats["transport"] == "off"


def test_forcing_scalar_transport_names_the_polarised_source_it_drops():
    r = render(_scene([_screen({"type": "linear", "angle": 45})], BLACK, polarisation="off"))
    assert "polarisation of 'screen' is not simulated" in r.stats["transport_reason"]
    r = render(_scene([_screen({"type": "circular"})], BLACK, polarisation="linear"))
    assert "circular polarisation of 'screen' is not simulated" in r.stats["transport_reason"]


@pytest.mark.parametrize("bad, field, words", [
    ({"type": "linear", "degree": 1.5}, "degree", "[0, 1]"),
    ({"type": "elliptic"}, "type", "none, linear, circular"),
    ({"type": "circular", "handedness": "up"}, "handedness", "'right' or 'left'"),
    ({"type": "circular", "angle": 3}, "angle", "linear polarisation only"),
    ({"type": "linear", "axis": [0, 0, 0]}, "axis", "zero vector"),
    ({"type": "linear", "angle": float("nan")}, "angle", "finite"),
    ({"type": "linear", "colour": 1}, "colour", "unknown key"),
])
def test_bad_polarisation_names_the_field(bad, field, words):
    with pytest.raises(SceneError) as e:
        _scene([_screen(bad)], BLACK)
    assert f"objects[0].emission.polarisation.{field}" in str(e.value) and words in str(e.value)


def _unpolarised_scene():
    return parse_scene({"format": "polar-scene/1",
                        "camera": {"origin": [0, -6, 3], "target": [0, 0, 0.5], "up": [0, 0, 1], "fov_deg": 40,
                                   "width": 16, "height": 12},
                        "render": {"spp": 2, "max_depth": 6, "seed": 5, "sampler": "independent", "threads": 1},
                        "materials": {"gold": {"type": "conductor", "metal": "Au"},
                                      "rough": {"type": "torrance_sparrow", "n": 1.5, "m": 0.2},
                                      "glass": {"type": "dielectric", "n": 1.5},
                                      "black": {"type": "lambert", "albedo": 0.0}},
                        "objects": [{"shape": "sphere", "center": [-1.2, 0, 0.6], "radius": 0.6, "material": "gold"},
                                    {"shape": "sphere", "center": [1.2, 0, 0.6], "radius": 0.6, "material": "glass"},
                                    {"shape": "quad", "material": "rough",
                                     "vertices": [[-9, -9, 0], [9, -9, 0], [9, 9, 0], [-9, 9, 0]]},
                                    {"name": "lamp", "shape": "quad", "material": "black", "emission": {"radiance": 4},
                                     "vertices": [[-1, -1, 4], [-1, 1, 4], [1, 1, 4], [1, -1, 4]]}],
                        "lights": [{"type": "environment", "radiance": 0.2},
                                   {"type": "directional", "direction": [0.3, 0.2, -1], "irradiance": 1.0}]})


def test_unpolarised_scenes_take_the_unpolarised_path_bit_for_bit(monkeypatch):
    """With no polarised source the transport runs exactly the code it ran before sources could be polarised:
    the same render with the polarised branches cut out (the light added as T[:, 0]·L_e, the BSDF's response
    to unpolarised light) has the same bits."""
    from engine.kernels.transport import add_light
    from engine.render.integrator import PathTracer
    before = render(_unpolarised_scene())
    assert before.stats["transport"] == "full"
    plain = PathTracer._bsdf_response

    def add_plain(self, radiance, path, T, rows, Le, w, T_cols, light, d, x_T):
        add_light(radiance, path, T, rows, Le, w, T_cols)

    monkeypatch.setattr(PathTracer, "_add_light", add_plain)
    monkeypatch.setattr(PathTracer, "_bsdf_response",
                        lambda self, sp, bsdf, x_T, wi, polarised=None: plain(self, sp, bsdf, x_T, wi, None))
    after = render(_unpolarised_scene())
    assert np.array_equal(before.stokes(), after.stokes())
    assert before.stokes()[0].max() > 0


def test_a_zero_degree_source_through_the_polarised_path_equals_the_unpolarised_one():
    """The polarised branches with s = (1, 0, 0, 0) (a source of degree 0 forced through them) give the
    unpolarised image to rounding: the frames and Mueller products of the polarised path agree with T[:, 0]."""
    from engine.polarisation.sources import SourcePolarisation

    class ForcedZero(SourcePolarisation):
        polarised = True            # (the parser counts degree 0 as unpolarised)

    plain = render(_unpolarised_scene())
    scene = _unpolarised_scene()
    lamp = next(m for m in scene.meshes if m.emission is not None)
    lamp.emission_polarisation = ForcedZero("linear", 0.0)
    scene.lights[1].polarisation = ForcedZero("linear", 0.0)
    forced = render(scene)
    assert forced.stats["transport"] == "full"
    np.testing.assert_allclose(forced.stokes(), plain.stokes(), rtol=1e-9, atol=1e-12)
