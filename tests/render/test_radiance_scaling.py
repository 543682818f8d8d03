"""Refraction's radiance scaling (BSDF.radiance_scaling): physically a refraction scales radiance by
(n_o/n_i)² = 1/η², and a path through a closed object gets both factors, which cancel; Cycles' closures
leave the factor out, so a surface crossed once (an open glass sheet, inverted normals: the real-asset
suite's sunglasses) renders differently.  Blender materials follow Cycles (``"radiance_scaling": false``).
Oracles: the white furnace (F + T = 1 without the factor) and the factor itself (every path through one
rough sheet carries exactly η² more, with the same random numbers)."""

import numpy as np
import pytest

from engine.errors import SceneError
from engine.render.renderer import Renderer
from engine.scene.loader import parse_material, parse_scene

SHEET = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]     # normal +z, towards the camera


def scene(material, lights, spp=8, max_depth=6, objects=()):
    return {
        "format": "polar-scene/1",
        "camera": {"origin": [0, -0.5, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 20, "width": 10,
                   "height": 8},
        "render": {"spp": spp, "seed": 3, "max_depth": max_depth},
        "materials": {"m": material, "black": {"type": "lambert", "albedo": 0.0}},
        "objects": [{"shape": "quad", "vertices": SHEET, "material": "m"}, *objects],
        "lights": lights,
    }


def stokes(doc):
    return Renderer(parse_scene(doc)).render().stokes()


@pytest.mark.parametrize("vertices", [SHEET, SHEET[::-1]], ids=["front", "back"])
def test_open_glass_sheet_in_a_white_furnace_is_white_without_the_factor(vertices):
    """A smooth glass sheet crossed once in a uniform white sky: Cycles' convention reflects F and passes
    1 − F, so every pixel is 1 (each sample exactly 1, whichever lobe it picks), seen from either face; the
    physical convention gives F + (1 − F)/η² < 1 seen from the front and F + (1 − F)·η² > 1 from the back."""
    doc = scene({"type": "dielectric", "n": 1.5, "radiance_scaling": False}, [{"type": "environment", "radiance": 1.0}])
    doc["objects"][0]["vertices"] = vertices
    S = stokes(doc)
    np.testing.assert_allclose(S[0], np.broadcast_to(S[0, :1, :1], S[0].shape), rtol=1e-12)   # every pixel the sky
    np.testing.assert_allclose(S[0], 1.0, rtol=3e-4)         # (white's RGB → spectrum round trip: 2.4e-4)
    doc["materials"]["m"]["radiance_scaling"] = True
    physical = stokes(doc)[0].mean()
    assert (physical < 0.6) if vertices is SHEET else (physical > 1.8)


def test_every_path_through_one_rough_sheet_carries_eta_squared_more():
    """A rough glass sheet, an area light behind it, nothing else: every path that reaches the light crosses
    the sheet once, by BSDF sampling or by next-event estimation through the rough interface, so Cycles'
    convention is the physical image × η² = 2.25 — per pixel, with the same random numbers."""
    lamp = {"shape": "quad", "vertices": [[-2, -2, -1], [2, -2, -1], [2, 2, -1], [-2, 2, -1]], "material": "black",
            "emission": {"radiance": 3.0}}                  # facing +z, up at the sheet
    rough = {"type": "rough_dielectric", "n": 1.5, "alpha": 0.3, "distribution": "ggx"}
    physical = stokes(scene(rough, [], spp=16, objects=[lamp]))
    cycles = stokes(scene(dict(rough, radiance_scaling=False), [], spp=16, objects=[lamp]))
    assert physical[0].min() > 0
    np.testing.assert_allclose(cycles, 2.25 * physical, rtol=1e-9, atol=1e-12)


def test_scene_key_is_checked_and_default_keeps_the_physics():
    assert parse_material({"type": "dielectric", "n": 1.5}, "m").radiance_scaling is True
    assert "radiance_scaling" not in vars(parse_material({"type": "dielectric", "n": 1.5}, "m"))   # fingerprint
    with pytest.raises(SceneError, match=r"materials\.m\.radiance_scaling: must be true or false, got 'no'"):
        parse_material({"type": "dielectric", "n": 1.5, "radiance_scaling": "no"}, "materials.m")
