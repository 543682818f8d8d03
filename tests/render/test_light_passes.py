"""Cycles' light passes with their Stokes components (engine.render.light_passes), without Blender.

Recombination: on the glare demo (a smooth and a glossy black dielectric under a white sky, its reference ball
made a mixed Torrance–Sparrow with a diffuse part) the passes' own combined equals the render's Stokes image
(same samples, same paths), and (Direct + Indirect)·Color per lobe + Emission + Environment gives it back,
S0 … S3, within float rounding.  Polarisation: Glossy Direct of the smooth panel near Brewster's angle is
strongly polarised, the diffuse passes carry none.  An analytic case: a Lambert floor under a uniform sky of
radiance 1 (nothing else in the scene) has Diffuse Color ρ exactly (grey), Diffuse Direct 1 (irradiance/π), no
Indirect light, and Environment 1 where the camera sees the sky.  The CLI writes the channels and names a bad
value.
"""

import json
from pathlib import Path

import numpy as np
import pytest

from engine.cli import main
from engine.materials.batching import shading_groups
from engine.output.exr import read_stokes_exr
from engine.render.light_passes import render_light_passes, safe_divide_even_color
from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene

GLARE = Path(__file__).resolve().parents[2] / "examples" / "glare_demo.json"


def _glare(width=48, height=24, spp=8):
    d = json.loads(GLARE.read_text())
    d["camera"]["width"], d["camera"]["height"] = width, height
    d["render"]["spp"] = spp
    d["materials"]["mixed"] = {"type": "torrance_sparrow", "n": 1.5, "k": 0.0, "m": 0.2,
                               "diffuse_albedo": [0.6, 0.3, 0.2]}
    d["objects"][2]["material"] = "mixed"
    return d


def _recombined(lp):
    return lp.recombined()


@pytest.fixture(scope="module")
def glare():
    renderer = Renderer(parse_scene(_glare()))
    return renderer, renderer.render().stokes(), render_light_passes(renderer, threads=1)


def test_passes_recombine_to_the_render(glare):
    _, stokes, lp = glare
    assert np.abs(lp.combined - stokes).max() <= 1e-12 * np.abs(stokes).max()
    rec = _recombined(lp)
    # where a lobe's colour is 0 while it has light the division cannot be undone (Cycles' rule too): none here
    assert np.abs(rec - stokes).max() <= 1e-12 * np.abs(stokes).max()
    assert np.abs(stokes[1:]).max() > 0.05                 # the check sees the Stokes components
    assert not lp.warnings


def test_glossy_direct_carries_the_polarisation_diffuse_none(glare):
    _, stokes, lp = glare
    for name in ("Diffuse Direct", "Diffuse Indirect"):
        assert np.abs(lp.stokes[name][1:]).max() == 0.0, name
        assert lp.stokes[name][0].max() > 0.0, name
    gloss = lp.stokes["Glossy Direct"]
    y = (0.2126, 0.7152, 0.0722)
    s = [(gloss[k] * y).sum(-1) for k in range(3)]
    smooth = slice(None), slice(0, 20)             # the smooth panel: the image's left part
    dolp = np.hypot(s[1][smooth], s[2][smooth]) / np.maximum(s[0][smooth], 1e-12)
    assert np.median(dolp) > 0.8, np.median(dolp)
    # the mixed ball: its glossy light is polarised, its diffuse light not; both lobes present
    ball = lp.color["Diffuse Color"].sum(-1) > 0
    assert ball.sum() > 10
    assert (lp.color["Glossy Color"].sum(-1)[ball] > 0).all()


def test_lambert_floor_under_a_uniform_sky():
    d = {"format": "polar-scene/1",
         "camera": {"origin": [0.0, -4.0, 2.0], "target": [0.0, 10.0, 1.0], "up": [0, 0, 1], "fov_deg": 60,
                    "width": 16, "height": 12},
         "render": {"spp": 64, "seed": 5},
         "materials": {"grey": {"type": "lambert", "albedo": 0.5}},
         "objects": [{"name": "floor", "shape": "quad", "material": "grey",
                      "vertices": [[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]]}],
         "lights": [{"type": "environment", "radiance": 1.0}]}
    renderer = Renderer(parse_scene(d))
    lp = render_light_passes(renderer, threads=1)
    sky = lp.stokes["Environment"][0].sum(-1) > 0
    floor = (lp.color["Diffuse Color"].sum(-1) > 0) & ~sky              # pixels entirely on the floor
    assert floor.sum() > 50 and sky.sum() > 20
    assert np.allclose(lp.color["Diffuse Color"][floor], 0.5, rtol=1e-9)   # cosine sampling: ρ exactly
    direct = lp.stokes["Diffuse Direct"][0][floor]
    assert abs(direct.mean() - 1.0) < 0.01, direct.mean()
    assert np.abs(lp.stokes["Diffuse Indirect"]).max() == 0.0 and np.abs(lp.stokes["Glossy Direct"]).max() == 0.0
    only_sky = sky & (lp.color["Diffuse Color"].sum(-1) == 0)
    assert only_sky.sum() > 20
    assert np.allclose(lp.stokes["Environment"][0][only_sky], 1.0, atol=2e-3)


def test_safe_divide_even_color():
    a = np.array([[2.0, 4.0, 6.0], [2.0, 4.0, 6.0], [2.0, 4.0, 6.0]])
    b = np.array([[1.0, 2.0, 3.0], [0.0, 2.0, 3.0], [0.0, 0.0, 3.0]])
    assert np.allclose(safe_divide_even_color(a, b), [[2, 2, 2], [2, 2, 2], [2, 2, 2]])


def test_cli_writes_the_light_passes(tmp_path):
    scene = tmp_path / "glare.json"
    scene.write_text(json.dumps(_glare(24, 12, 4)))
    out = tmp_path / "glare.exr"
    assert main(["render", str(scene), "-o", str(out), "--light-passes", "glossy_direct,diffuse_color",
                 "--no-previews", "--quiet"]) == 0
    _, channels, header = read_stokes_exr(out)
    names = set(channels)
    assert int(header["polar.light_samples"]) == 4
    assert {"Glossy Direct.R", "Glossy Direct S1.R", "Glossy Direct S3.B", "Diffuse Color.G"} <= names
    assert not any(n.startswith("Diffuse Direct") for n in names)
    assert main(["render", str(scene), "-o", str(tmp_path / "bad.exr"), "--light-passes", "shiny",
                 "--no-previews", "--quiet"]) != 0
    assert not (tmp_path / "bad.exr").exists()


def test_a_material_set_keeps_its_members_passes_apart():
    """Materials shaded as one MaterialSet (the glossy panel made a Weidlich–Wilkie coat, whose lobes the passes
    cannot separate, beside the mixed Torrance–Sparrow ball): the warning names the member's model, not the set,
    and the ball's Diffuse Direct is the one it has without that neighbour (it was counted Glossy: the set's value,
    a general matrix because of the coat, no longer held the ball's depolarised part apart)."""
    d = _glare(spp=4)
    ref = render_light_passes(Renderer(parse_scene(d)), threads=1)
    d["materials"]["glossy"] = {"type": "weidlich_wilkie", "coats": [{"n": 1.5, "distribution": "beckmann", "m": 0.2}],
                                "base": {"type": "lambert", "albedo": 0.5}}
    scene = parse_scene(d)
    shaders = shading_groups(list(scene.materials.values()))[0]
    assert any(type(s).__name__ == "MaterialSet" for s in shaders)         # the case under test
    lp = render_light_passes(Renderer(scene), threads=1)
    assert any("weidlich_wilkie" in w for w in lp.warnings) and not any("material_set" in w for w in lp.warnings)
    ball = ref.stokes["Diffuse Direct"][0].sum(-1) > 0
    assert ball.sum() > 20
    np.testing.assert_allclose(lp.stokes["Diffuse Direct"][0][ball], ref.stokes["Diffuse Direct"][0][ball], rtol=1e-9)
