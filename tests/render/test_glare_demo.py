"""The glare demo of examples/: polarised reflections vanish or dim at the right polariser angle."""

import dataclasses
import os

import numpy as np

from engine.postprocess.filters import best_angle, malus
from engine.render.renderer import Renderer
from engine.scene.loader import load_scene
from tests.conftest import REPO


def test_glare_demo_reflections_vanish_behind_a_vertical_polariser():
    scene = load_scene(os.path.join(REPO, "examples", "glare_demo.json"))
    scene.camera.width, scene.camera.height = 96, 48
    scene.settings = dataclasses.replace(scene.settings, spp=8, spectral="mono")
    Y = Renderer(scene).render().stokes_luminance()
    smooth = Y[:, 18:30, 10:38]          # left half, around the image centre row (Brewster's angle)
    glossy = Y[:, 18:30, 52:70]          # right half, clear of the reference sphere
    # Smooth dielectric at Brewster: the reflection is s-polarised (horizontal), a vertical polariser kills it.
    ratio = malus(smooth, 90.0) / malus(smooth, 0.0)
    assert ratio.mean() < 0.01 and ratio.min() < 1e-3
    # Glossy dielectric: the reflection is minimised at (about) the same angle, not removed.
    angles = np.arange(0.0, 180.0, 2.0)
    curve = np.array([malus(glossy, a).mean() for a in angles])
    assert abs(angles[curve.argmin()] - 90.0) <= 6.0
    residual = curve.min() / curve.max()
    assert malus(smooth, 90.0).mean() / malus(smooth, 0.0).mean() < residual < 0.5   # dimmed, not removed
    assert abs(np.median(best_angle(glossy)) - 90.0) < 6.0 or abs(np.median(best_angle(glossy)) + 90.0) < 6.0
