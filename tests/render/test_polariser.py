"""Virtual polarisers (post-process) against Malus's law and against physical filter sheets in the scene."""

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from engine.materials.filter_sheet import FilterSheet
from engine.polarisation.mueller import is_realisable, mueller_from_jones
from engine.postprocess.filters import (apply_filter, best_angle, filter_row, linear_polariser_mueller,
                                        linear_retarder_mueller, malus)
from engine.render.renderer import Renderer
from engine.scene.description import Mesh
from engine.scene.loader import load_scene
from engine.scene.shapes import quad
from tests.conftest import shared_path

def _physical_stokes(t):
    """(S0, S0·p) with |p| ≤ 1: a realisable Stokes vector."""
    p = np.array(t[1:]) / max(1.0, math.sqrt(t[1] ** 2 + t[2] ** 2 + t[3] ** 2))
    return np.concatenate(([t[0]], t[0] * p))


stokes_vectors = st.tuples(st.floats(0, 10), st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).map(
    _physical_stokes)


@settings(max_examples=200, deadline=None)
@given(stokes_vectors, st.floats(-180, 180))
def test_linear_filter_is_malus(S, angle):
    th = math.radians(angle)
    expected = 0.5 * (S[0] + S[1] * math.cos(2 * th) + S[2] * math.sin(2 * th))
    assert malus(S, angle) == pytest.approx(expected, abs=1e-12)
    assert -1e-12 <= malus(S, angle) <= S[0] + 1e-12      # rounding either side (found: -3.8e-164)
    # crossed polarisers sum to the total intensity
    assert malus(S, angle) + malus(S, angle + 90) == pytest.approx(S[0], abs=1e-12)


def test_filter_matrices_are_physical_and_match_jones():
    for angle in (0, 17, 45, 90, 133):
        for ext in (0.0, 1e-3, 0.3):
            assert is_realisable(linear_polariser_mueller(angle, 1.0, ext))
        for delta in (30, 90, 180):
            assert is_realisable(linear_retarder_mueller(angle, delta))
    J = np.array([[1, 0], [0, np.exp(1j * math.pi / 2)]])
    np.testing.assert_allclose(linear_retarder_mueller(0, 90), mueller_from_jones(J), atol=1e-15)
    # Finite extinction: unpolarised light passes (t_max + t_min)/2.
    assert filter_row("linear", 30, 0.01) @ np.array([2.0, 0, 0, 0]) == pytest.approx(1.01)


def test_circular_analysers_and_quarter_wave_plate():
    right = np.array([1.0, 0, 0, 1.0])
    assert apply_filter(right, filter_row("circular-right")) == pytest.approx(1.0)
    assert apply_filter(right, filter_row("circular-left")) == pytest.approx(0.0)
    # A quarter-wave plate at 45° turns right-circular light into linear at ±45°/0°: the plate + polariser
    # combination passes all of it at one polariser angle and none at the crossed one.
    through = [apply_filter(right, filter_row("retarder", a, retarder_angle_deg=45, retardance_deg=90))
               for a in range(0, 180, 5)]
    assert max(through) == pytest.approx(1.0) and min(through) == pytest.approx(0.0, abs=1e-12)


def test_best_angle_minimises():
    S = np.array([1.0, 0.3, 0.5, 0.0])
    a = best_angle(S)
    grid = [malus(S, t) for t in np.linspace(-90, 90, 3601)]
    assert malus(S, a) == pytest.approx(min(grid), abs=1e-6)


def scene_with_sheets(sheets, spp=64):
    """conv_s3_check (narrow field, full Stokes incl. S3) with filter sheets in front of the camera."""
    scene = load_scene(shared_path("peers", "scenes", "conv_s3_check.json"))
    scene.settings = dataclasses.replace(scene.settings, spp=spp)
    for i, (y, sheet) in enumerate(sheets):
        q = quad(*[np.array(p, float) for p in ([-1, y, 0], [-1, y, 2], [1, y, 2], [1, y, 0])])
        name = f"sheet{i}"
        scene.materials[name] = sheet
        scene.meshes.append(Mesh(name, q.vertices, q.faces, [name], np.zeros(2, np.int32)))
    return scene


def in_plane_axis(angle_deg):
    """Camera looks along +y with up +z: image right is +x, image up is +z."""
    t = math.radians(angle_deg)
    return [math.cos(t), 0.0, math.sin(t)]


@pytest.mark.parametrize("angle", [0.0, 30.0, 90.0, 135.0])
def test_polariser_sheet_in_front_of_the_camera_equals_the_post_process(angle):
    bare = Renderer(scene_with_sheets([])).render()
    filtered = Renderer(scene_with_sheets([(-4.5, FilterSheet(in_plane_axis(angle)))])).render()
    post = malus(bare.stokes_luminance(), angle)
    got = filtered.stokes_luminance()
    se = np.hypot(filtered.film.stderr_luminance()[0], bare.film.stderr_luminance()[0])
    assert np.all(np.abs(got[0] - post) < 4 * se + 2e-4 * bare.stokes_luminance()[0])
    # behind an ideal polariser the light is fully polarised along the axis
    aolp = 0.5 * np.degrees(np.arctan2(got[2], got[1]))
    assert np.allclose(np.mod(aolp - angle + 90, 180) - 90, 0, atol=0.5)


def test_retarder_then_polariser_sheets_equal_the_post_process():
    angle, fast, delta = 20.0, 45.0, 90.0
    bare = Renderer(scene_with_sheets([])).render()
    sheets = [(-4.0, FilterSheet(in_plane_axis(fast), "retarder", retardance_deg=delta)),
              (-4.5, FilterSheet(in_plane_axis(angle)))]
    got = Renderer(scene_with_sheets(sheets)).render().stokes_luminance()[0]
    post = apply_filter(bare.stokes_luminance(), filter_row("retarder", angle, 0.0, fast, delta))
    np.testing.assert_allclose(got, post, rtol=2e-3)
    assert abs(got.mean() - malus(bare.stokes_luminance(), angle).mean()) > 0.05 * got.mean()  # S3 matters here
