"""An emitter whose Emission Color and Emission Strength both vary over the surface (issue 33): the radiance at
each point is exactly the constant ``RGBIlluminantSpectrum`` of the colour texel × the strength texel, and the
luminance the emitter is sampled by (next-event estimation) is that product's."""

from __future__ import annotations

import numpy as np

from engine.spectral import RGBIlluminantSpectrum
from engine.spectral.cie import luminance
from engine.textures.inputs import ProductEmission, TextureInput
from engine.textures.texture import ImageTexture
from tests.scene.test_textures import _points_at

COLOURS = np.array([[[2.0, 0.5, 0.1], [0.2, 0.6, 1.5], [1.0, 1.0, 1.0], [-0.3, 0.4, 0.2]]], np.float32)
STRENGTHS = np.array([[[0.5], [3.0], [-1.0], [2.0]]], np.float32)


def _inputs():
    colour = TextureInput(ImageTexture(COLOURS, "Closest", name="colour"))
    strength = TextureInput(ImageTexture(STRENGTHS, "Closest", name="strength"))
    return colour, strength


def _points(reps=3):
    centres = (np.arange(4) + 0.5) / 4
    uv = np.repeat(np.stack((centres, np.full(4, 0.5))), reps, axis=1)
    return _points_at(uv)


def test_radiance_is_the_constant_illuminant_of_colour_times_strength():
    colour, strength = _inputs()
    emission = ProductEmission(colour, strength)
    assert emission.kind == "illuminant" and emission.lo == 0.0 and emission.hi == 2.0 * 3.0
    reps = 3
    points = _points(reps)
    lam = np.tile(np.array([[420.0], [510.0], [580.0], [650.0]]), (1, 4 * reps))
    values = emission.at(points, lam, False)
    mono = emission.at(points, lam, True)
    rgb = emission.linear_srgb_at(points)          # what the emitter's luminance estimates read
    lum = emission.luminance_at(points)
    for t in range(4):
        c = np.maximum(COLOURS[0, t].astype(np.float64), 0.0) * max(float(STRENGTHS[0, t, 0]), 0.0)
        const = RGBIlluminantSpectrum(c.tolist(), 1.0)
        sel = slice(t * reps, (t + 1) * reps)
        np.testing.assert_allclose(values[:, sel], const.eval(lam[:, sel]), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(mono[:, sel], const.mono_value, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(emission.rgb_at(points)[:, sel], np.tile(c[:, None], (1, reps)), rtol=1e-12)
        np.testing.assert_allclose(lum[sel], luminance(rgb[:, sel].T), rtol=1e-12)
    assert np.all(lum[2 * reps:3 * reps] == 0.0)            # a negative strength emits nothing


def test_scaled_and_where_it_may_emit():
    colour, strength = _inputs()
    emission = ProductEmission(colour, strength)
    points = _points()
    np.testing.assert_allclose(emission.scaled(0.25).rgb_at(points), 0.25 * emission.rgb_at(points), rtol=1e-12)
    source = emission.source
    assert source.texture.channels == 3 and "colour" in source.texture.name and "strength" in source.texture.name
    attributes = points.attributes
    prim = np.arange(points.n)
    np.testing.assert_array_equal(source.texture.texels_per_triangle(attributes, prim),
                                  np.maximum(colour.texture.texels_per_triangle(attributes, prim),
                                             strength.texture.texels_per_triangle(attributes, prim)))
    may = source.may_be_positive(attributes, prim)
    assert may.dtype == bool and may.shape == prim.shape
    assert may[:6].all()                    # conservative (pooled texels): True wherever both factors may be > 0
