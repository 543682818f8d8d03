"""Fuzzing scene files: any mutation either loads and renders finite pixels or raises SceneError."""

import copy
import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from engine.render.renderer import Renderer
from engine.errors import SceneError
from engine.scene.loader import parse_scene

BASE = {
    "format": "polar-scene/1",
    "camera": {"origin": [0, -5, 1.5], "target": [0, 0, 1], "up": [0, 0, 1], "fov_deg": 40, "width": 6, "height": 4},
    "render": {"spp": 1, "max_depth": 6},
    "materials": {
        "gold": {"type": "conductor", "metal": "Au"},
        "rough": {"type": "torrance_sparrow", "n": 1.5, "k": 0.0, "m": 0.2, "diffuse_albedo": [0.5, 0.2, 0.1]},
        "htsg": {"type": "htsg", "metal": "Al", "sigma0_um": 0.18, "tau_um": 3.0},
        "coat": {"type": "weidlich_wilkie", "coats": [{"n": 1.5, "distribution": "beckmann", "m": 0.1}],
                 "base": {"type": "lambert", "albedo": 0.6}},
        "glass": {"type": "dielectric", "n": 1.5},
        "floor": {"type": "black_glass", "n": 1.5},
    },
    "objects": [
        {"name": "a", "shape": "sphere", "center": [-1, 0, 1], "radius": 0.8, "subdivisions": 2, "material": "gold"},
        {"name": "b", "shape": "sphere", "center": [1, 0, 1], "radius": 0.8, "subdivisions": 2, "material": "coat"},
        {"name": "c", "shape": "sphere", "center": [0, 1, 1], "radius": 0.5, "subdivisions": 1, "material": "htsg"},
        {"name": "d", "shape": "triangles", "vertices": [[0, 0, 2], [1, 0, 2], [0, 1, 2]], "faces": [[0, 1, 2]],
         "material": "rough"},
        {"name": "floor", "shape": "quad", "vertices": [[-9, -9, 0], [9, -9, 0], [9, 9, 0], [-9, 9, 0]],
         "material": "floor", "emission": {"radiance": 0.5}},
    ],
    "lights": [{"type": "environment", "radiance": 1.0}, {"type": "point", "position": [0, -2, 3], "intensity": 5},
               {"type": "spot", "position": [0, 0, 4], "target": [0, 0, 0], "cone_angle_deg": 30},
               {"type": "directional", "direction": [0.2, 0.1, -1], "irradiance": 2}],
}

JUNK = st.one_of(st.none(), st.booleans(), st.integers(-10 ** 6, 10 ** 6),
                 st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=5),
                 st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4), st.just({}), st.just([]),
                 st.just(0), st.just(-1), st.just(1e-300), st.just(1e300))


def paths(node, prefix=()):
    """Every (path) to a value in a nested JSON structure."""
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from paths(v, prefix + (i,))


ALL_PATHS = [p for p in paths(BASE) if p]


def mutate(doc, path, value):
    doc = copy.deepcopy(doc)
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return doc


def check(doc):
    try:
        scene = parse_scene(doc)
    except SceneError as e:
        assert str(e) and ":" in str(e) or str(e)
        return
    try:
        result = Renderer(scene).render()
    except SceneError:
        return
    assert np.all(np.isfinite(result.stokes()))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(ALL_PATHS), JUNK)
def test_single_mutations_fail_cleanly_or_render_finite_pixels(path, value):
    check(mutate(BASE, path, value))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.sampled_from(ALL_PATHS), JUNK), min_size=2, max_size=4))
def test_multiple_mutations_fail_cleanly_or_render_finite_pixels(mutations):
    doc = BASE
    for path, value in mutations:
        try:
            doc = mutate(doc, path, value)
        except (KeyError, IndexError, TypeError):
            continue          # an earlier mutation removed the container
    check(doc)


def test_base_scene_renders():
    result = Renderer(parse_scene(BASE)).render()
    assert result.stokes()[0].max() > 0 and math.isfinite(result.stokes().sum())


def test_regressions_found_by_fuzzing():
    from engine.errors import SceneError
    import pytest
    for path, value in ((("objects", 3, "faces", 0, 2), 1e300), (("objects", 3, "faces", 0, 2), 2 ** 70),
                        (("objects", 3, "faces", 0, 2), 1.5), (("objects", 3, "vertices", 1, 0), float("nan"))):
        with pytest.raises(SceneError):
            parse_scene(mutate(BASE, path, value))
