"""Polarised multiple scattering in a Rayleigh slab against an independent reference (issue 37): the vector
adding–doubling solver of tests/support/adding_doubling.py, itself checked against the published Coulson, Dave &
Sekera (1960) Rayleigh tables, its own scalar limit against Chandrasekhar's H-function and energy conservation;
then Polar's renders of the same slab (I, Q, U at several view directions, reflected and transmitted) against it.

The larger-sample version is tests/bench/media_slab_reference.py."""

import copy

import numpy as np
import pytest

from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene
from tests.support.adding_doubling import Slab

from .test_absorption import box
from .test_participating import chandrasekhar_h

# Coulson, Dave & Sekera 1960 (the corrected values of Natraj, Li & Yung 2009), as tabulated in the public
# SASKTRAN-DISCO test suite ("Polarization Coulsen Albedo 0 STOKES=3"): τ = 0.5, ω = 1, δ = 0, black ground,
# μ0 = 0.2, incident flux πF = π; (μ, φ in degrees) → reflected (I, Q, U).  Their azimuth runs the other way
# round (clockwise seen from below), so their U is −U in the solver's frames; I and Q are the same.
COULSON_TAU_05_MU0_02 = {
    (0.02, 0): (0.44129802, -0.01753141, 0.0), (0.4, 0): (0.16889020, 0.01119511, 0.0),
    (1.0, 0): (0.05300496, 0.03755859, 0.0), (0.02, 60): (0.30091208, -0.15965601, 0.07365528),
    (0.4, 60): (0.12752450, -0.06066038, 0.05293867), (1.0, 60): (0.05300496, -0.01877930, 0.03252669)}
NADIR = 1.0 - 1e-13             # μ = 1 has no meridian plane: its limit


def test_solver_reproduces_the_coulson_dave_sekera_rayleigh_tables():
    slab = Slab(0.5, 1.0, 0.0, extra_mu=[0.2, 0.02, 0.4, NADIR], nodes=24)
    for (mu, phi), (i, q, u) in COULSON_TAU_05_MU0_02.items():
        got = slab.reflected(min(mu, NADIR), 0.2, np.radians(phi), irradiance=np.pi)
        np.testing.assert_allclose(got, [i, q, -u, 0.0], atol=2e-8, err_msg=f"mu={mu}, phi={phi}")


def test_solver_in_its_scalar_limit_is_chandrasekhars_semi_infinite_isotropic_medium():
    """δ = 1 makes Rayleigh an isotropic depolariser; τ = 60 is semi-infinite: E ω μ0 H(μ) H(μ0)/(4π(μ + μ0))."""
    omega, mu0, mu = 0.8, np.cos(np.radians(30.0)), np.cos(np.radians(50.0))
    got = Slab(60.0, omega, 1.0, extra_mu=[mu0, mu], nodes=16).reflected(mu, mu0, 0.7, irradiance=3.0)
    expected = 3.0 * omega * mu0 * chandrasekhar_h(omega, mu) * chandrasekhar_h(omega, mu0) / (4 * np.pi * (mu + mu0))
    assert got[0] == pytest.approx(expected, rel=1e-7)
    assert np.abs(got[1:]).max() < 1e-12 * expected


def test_solver_conserves_energy_without_absorption_and_is_reciprocal():
    """ω = 1: reflected + diffusely transmitted + direct flux = μ0 E; the reflection kernel's I element is
    symmetric in (μ, μ0)."""
    mu0 = 0.7
    slab = Slab(2.0, 1.0, 0.0279, extra_mu=[mu0, 0.3], nodes=16)
    up, down = slab.fluxes(mu0)
    assert up + down + mu0 * np.exp(-2.0 / mu0) == pytest.approx(mu0, rel=1e-6)
    assert slab._kernel(slab.R, 0.3, mu0, 0.4)[0, 0] == pytest.approx(slab._kernel(slab.R, mu0, 0.3, 0.4)[0, 0],
                                                                       rel=1e-10)


# ----------------------------------------------------------------------------- Polar against the solver


def slab_scene(tau, omega, delta, sun_zenith, view, size, spp, seed=0):
    """A slab −1 ≤ z ≤ 0 (80 units wide, no surface, nothing below: a black ground) of Rayleigh medium with
    σ_t = τ, under a sun of irradiance 1 whose light travels at azimuth 0 and zenith angle ``sun_zenith``, seen
    by an orthographic camera (up = +z, so its Stokes frame is the solver's e_φ) at view = (θ in degrees from
    the outward normal, φ in degrees, "up" | "down")."""
    th, phi, side = np.radians(view[0]), np.radians(view[1]), view[2]
    k = np.array([np.sin(th) * np.cos(phi), np.sin(th) * np.sin(phi), np.cos(th) if side == "up" else -np.cos(th)])
    centre = np.array([0.0, 0.0, 0.0 if side == "up" else -1.0])
    obj = box([-40, -40, -1], [40, 40, 0])
    obj["alpha"] = 0.0
    s0 = np.radians(sun_zenith)
    return {"format": "polar-scene/1",
            "camera": {"width": size, "height": size, "projection": "orthographic", "ortho_width": 0.5,
                       "origin": (centre + 20 * k).tolist(), "target": centre.tolist(), "up": [0, 0, 1]},
            "render": {"spp": spp, "max_depth": 1000, "sampler": "independent", "seed": seed},
            "materials": {"fog": {"type": "lambert", "albedo": 0.5, "interior": {
                "scattering": tau * omega, "absorption": tau * (1 - omega),
                "phase": {"type": "rayleigh", "depolarisation": delta}}}},
            "objects": [{**obj, "material": "fog"}],
            "lights": [{"type": "directional", "direction": [np.sin(s0), 0.0, -np.cos(s0)], "irradiance": 1.0}]}


def polar_stokes(data) -> tuple[np.ndarray, np.ndarray, dict]:
    """Mean (I, Q, U, V) over the pixels (independent samples of one expectation) and its standard error."""
    result = Renderer(parse_scene(copy.deepcopy(data))).render()
    S = result.stokes()[..., 1].reshape(4, -1)
    return S.mean(axis=1), S.std(axis=1, ddof=1) / np.sqrt(S.shape[1]), result.stats


def reference(slab, view, mu0):
    mu, phi = np.cos(np.radians(view[0])), np.radians(view[1])
    return (slab.reflected if view[2] == "up" else slab.transmitted)(mu, mu0, phi)


SLABS = {
    # τ, ω, δ, sun zenith, views (θ, φ, side)
    "thin-absorbing": (1.0, 0.95, 0.0279, 40.0, [(60, 90, "up"), (30, 180, "up"), (70, 20, "up"),
                                               (50, 45, "down"), (30, 120, "down")]),
    "thick-bright": (2.0, 0.98, 0.0, 60.0, [(50, 90, "up"), (10, 0, "up"), (40, 120, "down")]),
}


@pytest.mark.parametrize("name", list(SLABS))
def test_polar_renders_a_rayleigh_slab_as_the_adding_doubling_reference(name):
    """I, Q and U of every view within 4σ (+ 0.3 % of I for the solver's quadrature) of the solver's, V = 0;
    the views see several orders of scattering (the solver's single-scattering-only answer is ≥ 10σ away in
    I) and, taken together, real polarisation (|Q| or |U| ≥ 8σ)."""
    tau, omega, delta, sun, views = SLABS[name]
    mu0 = np.cos(np.radians(sun))
    extra = [mu0] + [np.cos(np.radians(v[0])) for v in views]
    slab = Slab(tau, omega, delta, extra_mu=extra, nodes=16)
    single = Slab(tau, omega, delta, extra_mu=extra, nodes=16, start=tau)       # no doubling: one scattering
    polarised = 0.0
    for view in views:
        m, e, stats = polar_stokes(slab_scene(tau, omega, delta, sun, view, size=32, spp=64))
        ref = reference(slab, view, mu0)
        assert stats["transport"] == "linear" and stats["nonfinite"] == 0
        assert e[0] < 0.02 * ref[0], (view, e)
        assert np.all(np.abs(m[:3] - ref[:3]) < 4 * e[:3] + 3e-3 * ref[0]), (view, m, ref, e)
        assert m[3] == 0.0
        assert abs(reference(single, view, mu0)[0] - ref[0]) > 10 * e[0], view
        polarised = max(polarised, max(abs(ref[1]), abs(ref[2])) / max(e[1], e[2]))
    assert polarised > 8


def test_full_stokes_spectral_transport_renders_the_slab_as_the_reference_too():
    """The thin slab's most polarised view with the full 4×4 transport and sampled wavelengths (the Mueller
    products carry Rayleigh's circular element): the same I, Q, U within 4σ, and V exactly 0 (no element of
    Rayleigh's matrix couples V to I, Q, U)."""
    tau, omega, delta, sun, views = SLABS["thin-absorbing"]
    view, mu0 = views[0], np.cos(np.radians(sun))
    data = slab_scene(tau, omega, delta, sun, view, size=32, spp=64)
    data["render"].update(polarisation="full", spectral="spectral", reduce_spectral="off")
    m, e, stats = polar_stokes(data)
    ref = reference(Slab(tau, omega, delta, extra_mu=[mu0, np.cos(np.radians(view[0]))], nodes=16), view, mu0)
    assert stats["transport"] == "full"
    assert np.all(np.abs(m[:3] - ref[:3]) < 4 * e[:3] + 3e-3 * ref[0]), (m, ref, e)
    assert m[3] == 0.0
