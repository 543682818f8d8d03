"""Denoising guides (Cycles' Denoising Albedo / Normal): albedo and shading normal at the first non-delta hit."""

import dataclasses
import json

import numpy as np

from engine.cli import main
from engine.output.exr import read_stokes_exr
from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene

UP_QUAD = [[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]]


def _scene(materials, objects, spp=4, polarisation="auto", spectral="spectral"):
    return parse_scene({
        "format": "polar-scene/1",
        "camera": {"origin": [0.0, 0.0, 1.0], "target": [0.0, 0.0, 0.0], "up": [0, 1, 0], "fov_deg": 20,
                   "width": 6, "height": 4},
        "render": {"spp": spp, "max_depth": 6, "seed": 3, "polarisation": polarisation, "spectral": spectral},
        "materials": materials, "objects": objects,
        "lights": [{"type": "environment", "radiance": 1.0}]})


def _render(scene, **changes):
    st = dataclasses.replace(scene.settings, **changes)
    return Renderer(scene).render(st)


def test_lambert_plane_gives_its_albedo_and_normal():
    scene = _scene({"white": {"type": "lambert", "albedo": [0.37, 0.37, 0.37]}},
                   [{"name": "floor", "shape": "quad", "vertices": UP_QUAD, "material": "white"}])
    albedo, normal = _render(scene, denoise_data=True).film.denoise_data()
    np.testing.assert_allclose(albedo, 0.37, rtol=1e-12)
    np.testing.assert_allclose(normal, np.broadcast_to([0.0, 0.0, 1.0], normal.shape), atol=1e-12)


def test_through_a_mirror_the_next_diffuse_hit():
    # Camera looking down at a mirror (κ = 10⁴: reflectance 1 − 4·10⁻⁸); the reflected rays meet a
    # Lambert ceiling above the camera whose normal faces down.
    ceiling = [[-50, -50, 3], [-50, 50, 3], [50, 50, 3], [50, -50, 3]]
    scene = _scene({"mirror": {"type": "conductor", "n": 1.0, "k": 1e4},
                    "grey": {"type": "lambert", "albedo": [0.6, 0.6, 0.6]}},
                   [{"name": "mirror", "shape": "quad", "vertices": UP_QUAD, "material": "mirror"},
                    {"name": "ceiling", "shape": "quad", "vertices": ceiling, "material": "grey"}])
    albedo, normal = _render(scene, denoise_data=True).film.denoise_data()
    np.testing.assert_allclose(albedo, 0.6, rtol=1e-6)
    np.testing.assert_allclose(normal, np.broadcast_to([0.0, 0.0, -1.0], normal.shape), atol=1e-12)


def test_renders_without_the_guides_are_unchanged(tmp_path):
    scene_path = tmp_path / "s.json"
    scene_path.write_text(json.dumps({
        "format": "polar-scene/1",
        "camera": {"origin": [0.0, -6.0, 2.0], "target": [0.0, 0.0, 0.6], "up": [0, 0, 1], "fov_deg": 40,
                   "width": 12, "height": 8},
        "render": {"spp": 4, "max_depth": 6, "seed": 1},
        "materials": {"chalk": {"type": "lambert", "albedo": [0.8, 0.3, 0.2]}, "glass": {"type": "dielectric",
                                                                                       "n": 1.5},
                      "floor": {"type": "black_glass", "n": 1.5}},
        "objects": [{"name": "a", "shape": "sphere", "center": [-1, 0, 0.6], "radius": 0.6, "material": "chalk"},
                    {"name": "b", "shape": "sphere", "center": [1, 0, 0.6], "radius": 0.6, "material": "glass"},
                    {"name": "f", "shape": "quad", "vertices": [[-30, -30, 0], [30, -30, 0], [30, 30, 0],
                                                                 [-30, 30, 0]], "material": "floor"}],
        "lights": [{"type": "environment", "radiance": 1.0}]}))
    plain, guided = tmp_path / "plain.exr", tmp_path / "guided.exr"
    assert main(["render", str(scene_path), "-o", str(plain), "-q", "--no-previews"]) == 0
    assert main(["render", str(scene_path), "-o", str(guided), "-q", "--no-previews", "--denoise-data"]) == 0
    s_plain, c_plain, _ = read_stokes_exr(plain)
    s_guided, c_guided, _ = read_stokes_exr(guided)
    np.testing.assert_array_equal(s_plain, s_guided)            # the guides change no sample
    assert not any(n.startswith("denoise.") for n in c_plain)
    albedo = np.stack([c_guided[f"denoise.albedo.{c}"] for c in "RGB"], -1)
    normal = np.stack([c_guided[f"denoise.normal.{c}"] for c in "XYZ"], -1)
    # the chalk sphere (left of the image centre) is red-ish; its normals are unit vectors on average ≤ 1
    assert albedo.max() <= 1.0 + 1e-6 and albedo.min() >= 0.0
    assert np.all(np.linalg.norm(normal, axis=-1) <= 1.0 + 1e-6)
    chalk = albedo[..., 0] > 0.5
    assert chalk.any() and np.all(albedo[chalk][:, 1] < albedo[chalk][:, 0])
    assert main(["render", str(scene_path), "-o", str(tmp_path / "r.exr"), "-q", "--denoise-data",
                 "--resume", str(plain)]) == 2
