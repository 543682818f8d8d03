"""An emitter hidden from indirect rays lights nothing (Cycles excludes a mesh light from the ray types its
object is invisible to), while the camera still sees it: Blender's glTF unlit materials, objects with
diffuse/glossy/transmission visibility off."""

import copy

import numpy as np

from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene


def scene(visible_indirect, selection_lights=()):
    return {"format": "polar-scene/1",
            "camera": {"origin": [0, -3, 3], "target": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 60,
                       "width": 16, "height": 16},
            "render": {"spp": 16, "max_depth": 4, "sampler": "independent"},
            "materials": {"grey": {"type": "lambert", "albedo": 0.5}},
            "objects": [
                {"shape": "quad", "vertices": [[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], "material": "grey"},
                {"shape": "quad", "vertices": [[-0.5, -0.5, 1], [-0.5, 0.5, 1], [0.5, 0.5, 1], [0.5, -0.5, 1]],
                 "material": "grey", "visible_indirect": visible_indirect,
                 "emission": {"radiance": 5.0, "two_sided": True}}],
            "lights": list(selection_lights)}


def render(data):
    return Renderer(parse_scene(copy.deepcopy(data))).render().stokes()[0][..., 1]


def test_hidden_emitter_is_seen_but_lights_nothing():
    lit, hidden = render(scene(True)), render(scene(False))
    assert hidden.max() > 4.9 and lit[lit < 4.0].max() > 0.05      # the lamp is seen; normally it lights the floor
    np.testing.assert_allclose(hidden[hidden > 4.9], 5.0, rtol=1e-4)
    unseen = scene(False)
    unseen["objects"][1]["visible_camera"] = False                  # nor seen: nothing at all
    np.testing.assert_array_equal(render(unseen), 0.0)


def test_other_lights_are_unaffected_by_a_hidden_emitter():
    """With a sun beside it, the floor gets the sun's light exactly as without the hidden emitter."""
    sun = [{"type": "directional", "direction": [0.2, 0.1, -1], "irradiance": 2.0}]
    with_hidden = scene(False, sun)
    without = copy.deepcopy(with_hidden)
    without["objects"][1]["emission"]["radiance"] = 0.0      # the same object, hidden alike, emitting nothing
    for d in (with_hidden, without):
        d["render"]["spp"] = 128
        d["objects"][1]["visible_camera"] = False      # the floor only (no partly covered lamp pixels)
    a, b = render(with_hidden), render(without)
    # (uniform selection picks the hidden emitter half the time: its samples add nothing, the sun's count twice)
    assert abs(a.mean() / b.mean() - 1.0) < 0.03
