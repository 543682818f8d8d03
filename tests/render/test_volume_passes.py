"""Volume Direct / Volume Indirect light passes (Cycles' PATH_RAY_VOLUME_PASS): a path whose first vertex is a
medium vertex puts its light there, not under Glossy (engine.render.light_passes)."""

from __future__ import annotations

import numpy as np
import pytest

from engine.render.light_passes import render_light_passes
from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene
from tests.render.test_media_spectral import fog


@pytest.fixture(scope="module")
def foggy():
    data = fog(res=16, spp=8, interior={"absorption": 0.1, "scattering": 1.5, "phase": {"type": "rayleigh"}})
    renderer = Renderer(parse_scene(data))
    return renderer.render().stokes(), render_light_passes(renderer, threads=1)


def test_fog_light_goes_to_the_volume_passes_and_recombines(foggy):
    stokes, lp = foggy
    scale = np.abs(stokes).max()
    assert np.abs(lp.combined - stokes).max() <= 1e-12 * scale
    assert np.abs(lp.recombined() - stokes).max() <= 1e-12 * scale
    direct, indirect = lp.stokes["Volume Direct"], lp.stokes["Volume Indirect"]
    assert direct[0].mean() > 0.02 and indirect[0].mean() > 0.002
    # Rayleigh single scattering of the sun polarises the Volume Direct light (S1, S2 ≠ 0), never circularly
    assert np.abs(direct[1:3]).max() > 0.05 * direct[0].max()
    # the floor is Lambert: nothing is glossy, so the medium vertices' light is no longer counted there
    for name in ("Glossy Direct", "Glossy Indirect", "Transmission Direct", "Transmission Indirect"):
        assert not lp.stokes[name].any(), name
    assert lp.stokes["Diffuse Direct"][0].max() > 0                  # the floor seen through the fog
    assert not lp.warnings


def test_no_medium_no_volume_light():
    data = fog(res=8, spp=2)
    data["materials"]["fog"].pop("interior")
    lp = render_light_passes(Renderer(parse_scene(data)), threads=1)
    assert not lp.stokes["Volume Direct"].any() and not lp.stokes["Volume Indirect"].any()
    assert lp.stokes["Diffuse Direct"][0].max() > 0
