"""Spectral or RGB transport with participating media (issue 37 follow-up): media follow the surfaces' rule.

Grey and RGB coefficients with Henyey–Greenstein / Rayleigh phases need no wavelengths (RGB transport, as
Cycles); a spectral table of a coefficient keeps the paths spectral and is named in the report; the world
medium is named in the transport reason.
"""

from __future__ import annotations

import copy
import os

import numpy as np
import pytest

from engine.render.renderer import Renderer
from engine.scene.loader import load_scene, parse_scene
from tests.render.test_absorption import box

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def fog(res: int = 16, spp: int = 16, interior: dict | None = None, floor=0.5) -> dict:
    """A box of fog (alpha-0 boundary) on a floor under a sun and a sky."""
    fog_box = box([-1, -1, 0], [1, 1, 2])
    fog_box["alpha"] = 0.0
    interior = interior or {"albedo": 0.9, "density": 1.5, "phase": {"type": "henyey_greenstein", "g": 0.5}}
    return {"format": "polar-scene/1",
            "camera": {"width": res, "height": res, "projection": "perspective", "fov_deg": 40,
                       "origin": [0, -6, 2], "target": [0, 0, 1], "up": [0, 0, 1]},
            "render": {"spp": spp, "max_depth": 8, "seed": 3},
            "materials": {"floor": {"type": "lambert", "albedo": floor},
                          "fog": {"type": "lambert", "albedo": 0.5, "interior": interior}},
            "objects": [{**fog_box, "material": "fog"},
                        {"shape": "quad", "vertices": [[-6, -6, 0], [6, -6, 0], [6, 6, 0], [-6, 6, 0]],
                         "material": "floor"}],
            "lights": [{"type": "directional", "direction": [0.3, 0.5, -0.8], "irradiance": 3.0,
                        "color": [1.0, 0.8, 0.6]},
                       {"type": "environment", "radiance": 0.2}]}


@pytest.mark.parametrize("name", ["media_haze", "media_underwater"])
def test_examples_stay_spectral_for_their_coloured_surfaces_not_their_media(name):
    scene = load_scene(os.path.join(REPO, "examples", f"{name}.json"))
    plan = Renderer(scene).plan()
    medium = "haze" if name == "media_haze" else "water"
    assert plan.spectral.startswith("spectral (")
    assert "'rock'" in plan.spectral and repr(medium) not in plan.spectral      # RGB albedos need λ; RGB media none
    assert plan.settings.reduce_spectral == "auto"


def test_rgb_media_scene_renders_in_rgb_and_matches_the_spectral_mean():
    """Grey surfaces, RGB fog (σ_s per channel), a coloured sun: auto reduces to RGB; the spectral render
    (reduce_spectral "off") has the same mean within 4 standard errors (pixel-to-pixel noise of the difference).
    Grey coefficients make the expectations equal exactly (RGB ones differ by the upsampling: not asserted)."""
    data = fog(interior={"absorption": 0.15, "scattering": 1.2, "phase": {"type": "rayleigh"}})
    rgb = Renderer(parse_scene(data)).render()
    off = copy.deepcopy(data)
    off["render"]["reduce_spectral"] = "off"
    spectral = Renderer(parse_scene(off)).render()
    assert rgb.stats["spectral"].startswith("RGB") and spectral.stats["spectral"] == "spectral"
    a, b = rgb.stokes()[0], spectral.stokes()[0]                    # (H, W, 3)
    diff = (a - b).reshape(-1, 3)
    se = diff.std(axis=0, ddof=1) / np.sqrt(diff.shape[0])
    assert np.all(np.abs(diff.mean(axis=0)) < 4 * se), (diff.mean(axis=0), se)
    assert a.mean() > 0.05                                          # the fog and the floor are lit
    coloured = fog(interior={"albedo": [0.9, 0.8, 0.6], "density": 1.5, "phase": {"type": "rayleigh"}})
    assert Renderer(parse_scene(coloured)).plan().spectral.startswith("RGB")


def test_a_spectral_table_keeps_the_paths_spectral_and_is_named():
    table = [[360, 0.2], [550, 1.0], [830, 2.0]]
    data = fog(interior={"absorption": 0.1, "scattering": {"spectrum": table}})
    plan = Renderer(parse_scene(data)).plan()
    assert plan.spectral == "spectral ('fog' depends on λ)"
    assert plan.settings.reduce_spectral == "off"                   # the tracer then keeps the wavelengths
    tracer = Renderer(parse_scene(data)).tracer(plan)
    assert not tracer.rgb_mode and not tracer.uniform


def test_the_world_medium_is_named_in_the_transport_reason():
    data = fog(spp=1)
    data["medium"] = {"albedo": 0.5, "density": 0.01}
    reason = Renderer(parse_scene(data)).plan().transport_reason
    assert "participating media: 'fog', 'world medium'" in reason
    data["medium"] = {"absorption": 0.01}
    reason = Renderer(parse_scene(data)).plan().transport_reason
    assert "absorbing interiors: 'world medium'" in reason
