"""Two-sided materials (BSDF.two_sided, the real-asset issue's double-sided materials): seen from the
back, an opaque material shades as its front does (Cycles' rule for every Blender material), a
transmissive one keeps its inside and outside, and a one-sided material (the scene format's default)
renders as before.  Oracle: the same quad with its winding reversed, seen from the front."""

import numpy as np
import pytest

from engine.errors import SceneError
from engine.render.renderer import Renderer
from engine.scene.loader import parse_material, parse_scene

FRONT = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]     # normal +z, towards the camera
BACK = FRONT[::-1]                                           # normal −z: the camera sees its back

MATERIALS = {
    "lambert": {"type": "lambert", "albedo": 0.5},
    "conductor": {"type": "conductor", "metal": "Au"},
    "black_glass": {"type": "black_glass", "n": 1.5},
    "torrance_sparrow": {"type": "torrance_sparrow", "n": 1.5, "k": 0.0, "m": 0.3, "diffuse_albedo": 0.4,
                         "diffuse_weight": 1.0},
    "htsg": {"type": "htsg", "metal": "Al", "sigma0_um": 0.18, "tau_um": 3.0},
    "weidlich_wilkie": {"type": "weidlich_wilkie", "coats": [{"n": 1.5, "distribution": "beckmann", "m": 0.2}],
                        "base": {"type": "lambert", "albedo": 0.6}},
}


def scene(material, vertices, spp=8):
    return {
        "format": "polar-scene/1",
        "camera": {"origin": [0, -3, 3], "target": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 30, "width": 12,
                   "height": 10},
        "render": {"spp": spp, "seed": 5, "max_depth": 5},
        "materials": {"m": material},
        "objects": [{"shape": "quad", "vertices": vertices, "material": "m"}],
        "lights": [{"type": "environment", "radiance": 0.5},
                   {"type": "directional", "direction": [0.3, 0.4, -1.0], "irradiance": 3.0},
                   {"type": "point", "position": [-0.5, -1.0, 1.5], "intensity": 2.0}],
    }


def stokes(doc):
    return Renderer(parse_scene(doc)).render().stokes()


@pytest.mark.parametrize("name", list(MATERIALS))
def test_back_of_a_two_sided_opaque_material_is_its_front(name):
    """The back face with flipped normals is the same shading point as the front face of the reversed
    quad (light from above reaches the back face's flipped front): equal up to the float32 hit points
    of the two triangulations."""
    material = dict(MATERIALS[name], two_sided=True)
    front = stokes(scene(MATERIALS[name], FRONT))
    back = stokes(scene(material, BACK))
    assert front[0].max() > 0
    np.testing.assert_allclose(back, front, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("name", list(MATERIALS))
def test_one_sided_default_is_unchanged(name):
    """Without the flag the back of an opaque model is as before (black or the environment behind)."""
    one = stokes(scene(MATERIALS[name], BACK))
    explicit = stokes(scene(dict(MATERIALS[name], two_sided=False), BACK))
    np.testing.assert_array_equal(one, explicit)
    assert not np.array_equal(one, stokes(scene(MATERIALS[name], FRONT)))


@pytest.mark.parametrize("material", [{"type": "dielectric", "n": 1.5}, {"type": "thin_dielectric", "n": 1.5},
                                      {"type": "rough_dielectric", "n": 1.5, "alpha": 0.2},
                                      {"type": "polariser", "axis": [1.0, 0.5, 0.0]}])
def test_transmissive_two_sided_material_keeps_inside_and_outside(material):
    """A material that lets light through keeps its sides: the flag changes nothing."""
    plain = stokes(scene(material, BACK))
    np.testing.assert_array_equal(stokes(scene(dict(material, two_sided=True), BACK)), plain)


def test_normal_mapped_back_face_is_the_mapped_front_negated(tmp_path):
    """Cycles maps the normal with the unflipped frame, then flips it: a back face of a normal-mapped
    two-sided material shades with −(mapped normal) — finite, and for a flat map the front's image."""
    import OpenEXR
    flat = np.tile(np.array([0.5, 0.5, 1.0], np.float32), (2, 2, 1))
    OpenEXR.File({"type": OpenEXR.scanlineimage},
                 {c: np.ascontiguousarray(flat[..., i]) for i, c in enumerate("RGB")}).write(str(tmp_path / "n.exr"))
    material = {"type": "lambert", "albedo": 0.5, "normal_map": {"texture": str(tmp_path / "n.exr")}}
    doc = scene(dict(material, two_sided=True), BACK)
    doc["objects"][0]["uv"] = [[0, 0], [1, 0], [1, 1], [0, 1]]
    back = stokes(doc)
    front_doc = scene(material, FRONT)
    front_doc["objects"][0]["uv"] = [[0, 0], [1, 0], [1, 1], [0, 1]]
    np.testing.assert_allclose(back, stokes(front_doc), rtol=1e-6, atol=1e-7)


def test_two_sided_must_be_a_boolean():
    with pytest.raises(SceneError, match=r"materials\.m\.two_sided: must be true or false, got 'yes'"):
        parse_material(dict(MATERIALS["lambert"], two_sided="yes"), "materials.m")
    assert parse_material(dict(MATERIALS["lambert"], two_sided=True), "materials.m").two_sided
    assert "two_sided" not in vars(parse_material(MATERIALS["lambert"], "materials.m"))   # fingerprints unchanged

