"""Thin dielectric pane (engine.materials.thin_dielectric): the closed form against the explicit sum of the
two-interface bounces, Brewster's angle, realisability and the scene format."""

import math

import numpy as np
import pytest

from engine.materials.base import ShadingPoint
from engine.materials.catalogue import make_model
from engine.materials.thin_dielectric import ThinDielectric, thin_pane_abcs
from engine.polarisation.mueller import abcs_matrix, is_realisable, mueller_from_jones
from engine.scene.loader import parse_material


def explicit_pane(cos_theta, eta, bounces=400):
    """(M_R, M_T) as the incoherent sum of the Mueller matrices of every path through the pane, each
    the Jones matrix diag(a_s, a_p) of its amplitudes: outer interface (θ, η), inner (θ_t, 1/η), the
    textbook amplitude coefficients r = (n₁c₁ − n₂c₂)/(n₁c₁ + n₂c₂) (s), (n₂c₁ − n₁c₂)/(n₂c₁ + n₁c₂) (p)
    and t = 2n₁c₁/(n₁c₁ + n₂c₂) (s), 2n₁c₁/(n₂c₁ + n₁c₂) (p)."""
    c1 = cos_theta
    s2 = (1.0 - c1 * c1) / eta ** 2
    c2 = math.sqrt(1.0 - s2)
    n1, n2 = 1.0, eta

    def coeffs(na, nb, ca, cb):
        rs = (na * ca - nb * cb) / (na * ca + nb * cb)
        rp = (nb * ca - na * cb) / (nb * ca + na * cb)
        ts = 2 * na * ca / (na * ca + nb * cb)
        tp = 2 * na * ca / (nb * ca + na * cb)
        return np.array([rs, rp]), np.array([ts, tp])

    r12, t12 = coeffs(n1, n2, c1, c2)
    r21, t21 = coeffs(n2, n1, c2, c1)
    # these r_p equal docs/physics.md §0's (η²c − u)/(η²c + u) (r_p → −r_s at normal incidence), and the
    # products t₁₂t₂₁ are power fractions already (the n c factors cancel on the way in and out)
    M_R = mueller_from_jones(np.diag(r12).astype(complex))
    M_T = np.zeros((4, 4))
    for k in range(bounces):
        a_t = t12 * t21 * (r21 * r21) ** k
        a_r = t12 * t21 * r21 ** (2 * k + 1)
        M_T = M_T + mueller_from_jones(np.diag(a_t).astype(complex))
        M_R = M_R + mueller_from_jones(np.diag(a_r).astype(complex))
    return M_R, M_T


@pytest.mark.parametrize("theta", [0.0, 20.0, 45.0, math.degrees(math.atan(1.5)), 70.0, 89.0])
@pytest.mark.parametrize("eta", [1.5, 1.33, 2.4])
def test_closed_form_is_the_two_interface_sum(theta, eta):
    c = math.cos(math.radians(theta))
    refl, trans = thin_pane_abcs(np.array(c), eta)
    M_R, M_T = explicit_pane(c, eta)
    np.testing.assert_allclose(abcs_matrix(*[np.asarray(v) for v in refl]), M_R, atol=1e-12)
    np.testing.assert_allclose(abcs_matrix(*[np.asarray(v) for v in trans]), M_T, atol=1e-12)


def test_brewster_angle():
    eta = 1.5
    c = math.cos(math.atan(eta))
    (A, B, C, S), (At, Bt, Ct, St) = thin_pane_abcs(np.array(c), eta)
    R_s = ((c - math.sqrt(eta ** 2 - 1 + c * c)) / (c + math.sqrt(eta ** 2 - 1 + c * c))) ** 2
    assert B / A == pytest.approx(1.0, abs=1e-12)                 # reflection fully s-polarised
    assert 2 * A == pytest.approx(2 * R_s / (1 + R_s), rel=1e-12)
    assert -Bt / At == pytest.approx(R_s, rel=1e-10)              # transmitted DoP = R_s (p-polarised)
    assert At + Bt == pytest.approx((1 - R_s) / (1 + R_s), rel=1e-12) and At - Bt == pytest.approx(1.0, abs=1e-12)


def test_realisable_energy_and_sampling():
    rng = np.random.default_rng(3)
    N = 2000
    for n, ext in ((1.5, 1.0), (1.0, 1.33)):                      # the second: a low-index gap, TIR
        model = ThinDielectric(n, ext)
        c = rng.random(N)
        refl, trans = thin_pane_abcs(c, n / ext)
        assert np.all(refl[0] + trans[0] <= 1.0 + 1e-12) and np.all(refl[0] + trans[0] >= 1.0 - 1e-12)
        for v in (refl, trans):
            assert np.all(is_realisable(abcs_matrix(*v)))
        wo = rng.normal(size=(3, N))
        wo /= np.linalg.norm(wo, axis=0)
        nrm = np.tile([[0.0], [0.0], [1.0]], (1, N))
        sp = ShadingPoint(np.zeros((3, N)), nrm, nrm, wo, np.full((1, N), 550.0))
        s = model.sample(sp, rng.random(N), rng.random((2, N)))
        through = np.all(s.wi == -wo, axis=0)
        mirror = np.isclose(s.wi[2], wo[2]) & np.isclose(s.wi[0], -wo[0])
        assert np.all(through | mirror) and np.all(s.valid) and np.all(s.is_delta)
    assert ThinDielectric(1.0, 1.33).creates_circular and not ThinDielectric(1.5).creates_circular


def test_scene_loader_and_catalogue():
    a = parse_material({"type": "thin_dielectric", "n": 1.52}, "x")
    b = make_model("thin_dielectric", {"n": "1.52"})
    assert a.describe() == b.describe() == {"type": "thin_dielectric", "n": 1.52, "exterior_n": 1.0}
    assert a.transmits and a.delta_only and a.polarising


def test_white_furnace_closed_thin_pane_sphere_is_exactly_one():
    """Every path through a closed sphere of thin panes escapes (R_tot + T_tot = 1 per channel): with
    polarisation off every sample is exactly 1; with full polarisation the pane is lossless for every
    polarisation state, so the equilibrium field stays unpolarised: S0 = 1 and S1..S3 = 0 within noise
    (single paths carry polarised weights)."""
    from engine.render.renderer import Renderer
    from engine.scene.description import Camera, EnvironmentLight, Mesh, RenderSettings, Scene
    from engine.scene.shapes import icosphere
    from engine.spectral import RGBIlluminantSpectrum

    sphere = icosphere(3)
    cam = Camera(origin=np.array([0.0, -4.0, 0.0]), target=np.zeros(3), up=np.array([0.0, 0.0, 1.0]),
                 width=12, height=12, fov_deg=35.0)
    mesh = Mesh("ball", sphere.vertices, sphere.faces, ["pane"], np.zeros(len(sphere.faces), np.int32),
                normals=sphere.vertex_normals)
    for pol, spp in (("off", 8), ("full", 256)):
        scene = Scene(camera=cam, meshes=[mesh], materials={"pane": ThinDielectric(1.5)},
                      lights=[EnvironmentLight(RGBIlluminantSpectrum([1.0, 1.0, 1.0], 1.0))],
                      settings=RenderSettings(spp=spp, spectral="mono", max_depth=256, rr_depth=256,
                                              polarisation=pol))
        result = Renderer(scene).render()
        S = result.stokes_luminance()
        if pol == "off":
            np.testing.assert_allclose(S[0], 1.0, atol=1e-9)
            continue
        se = result.film.stderr_luminance()
        for i, want in enumerate((1.0, 0.0, 0.0, 0.0)):
            sigma_mean = np.sqrt((se[i] ** 2).sum()) / se[i].size
            assert abs(S[i].mean() - want) < 4 * sigma_mean + 1e-9, (i, S[i].mean(), sigma_mean)
        assert np.abs(S[1]).max() > 1e-3          # single paths are polarised
