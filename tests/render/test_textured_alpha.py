"""Alpha that varies over a surface (Principled Alpha from an image's alpha: glTF cut-outs and blends).

A black quad whose alpha texture is 0 on its left half and 1 on its right hides a white emitter behind
it: the left half shows the emitter exactly, the right half is black; a half-alpha texel lets half the
light through (in expectation: pass-through is stochastic); shadow rays are attenuated by 1 − alpha at
each point (a lamp seen through a 0.25-alpha sheet lights the floor by 0.75).
"""

import copy

import numpy as np
import OpenEXR
import pytest

from engine.errors import SceneError
from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene


def write_exr(path, grey):
    grey = np.asarray(grey, np.float32)
    OpenEXR.File({"type": OpenEXR.scanlineimage}, {"R": grey}).write(str(path))
    return str(path)


def sheet_scene(tmp_path, texels, spp=64):
    write_exr(tmp_path / "alpha.exr", texels)
    return {"format": "polar-scene/1",
            "camera": {"projection": "orthographic", "ortho_width": 2.0, "origin": [0, 0, 5], "target": [0, 0, 0],
                       "up": [0, 1, 0], "width": 8, "height": 8},
            "render": {"spp": spp, "max_depth": 4, "sampler": "independent"},
            "materials": {"black": {"type": "lambert", "albedo": 0.0}},
            "objects": [
                {"shape": "quad", "vertices": [[-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], "material": "black",
                 "uv": [[0, 0], [1, 0], [1, 1], [0, 1]],
                 "alpha": {"texture": "alpha.exr", "interpolation": "Closest", "color_space": "Non-Color"}},
                {"shape": "quad", "vertices": [[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], "material": "black",
                 "emission": {"radiance": 2.0}}]}


def render(data, tmp_path):
    return Renderer(parse_scene(copy.deepcopy(data), base_dir=str(tmp_path))).render().stokes()[0][..., 1]


def test_cut_out_shows_what_is_behind_where_alpha_is_zero(tmp_path):
    img = render(sheet_scene(tmp_path, [[0.0, 1.0]]), tmp_path)
    np.testing.assert_allclose(img[:, :4], 2.0, rtol=1e-3)            # alpha 0: the emitter
    np.testing.assert_array_equal(img[:, 4:], 0.0)                     # alpha 1: the black sheet


def test_half_alpha_lets_half_through_on_average(tmp_path):
    img = render(sheet_scene(tmp_path, [[0.5, 0.5]], spp=512), tmp_path)
    assert abs(img.mean() - 1.0) < 0.03                                # (1 − 0.5) × 2, stochastic crossings


def test_alpha_texture_values_must_be_in_the_unit_range(tmp_path):
    data = sheet_scene(tmp_path, [[0.0, 1.0]])
    data["objects"][0]["alpha"]["scale"] = 2.0
    with pytest.raises(SceneError, match=r"objects\[0\]\.alpha: texture values span \[0, 2\]: must be in \[0, 1\]"):
        parse_scene(data, base_dir=str(tmp_path))


# --------------------------------------------------------------------------- surfaces that scatter nothing

def test_a_black_sheet_is_crossed_without_a_random_choice(tmp_path):
    """A sheet that scatters nothing (black: an emitter's or a glTF unlit material) is crossed by camera rays
    always, weighted by 1 − alpha, as Cycles weighs a Transparent BSDF mixed with an emission: no noise."""
    img = render(sheet_scene(tmp_path, [[0.5, 0.25]], spp=4), tmp_path)
    clear = render(sheet_scene(tmp_path, [[0.0, 0.0]], spp=4), tmp_path)     # the emitter (2 up to its colour)
    np.testing.assert_allclose(img[:, :4], 0.5 * clear[:, :4], rtol=1e-12)
    np.testing.assert_allclose(img[:, 4:], 0.75 * clear[:, 4:], rtol=1e-12)


def test_an_emitting_half_alpha_sheet_adds_alpha_times_its_emission(tmp_path):
    """An unlit emitter of radiance 3 with alpha 0.3 in front of an emitter of 2: 0.3·3 + 0.7·2 = 2.3 in every
    pixel, deterministically — the mean of the stochastic crossing a nearly black sheet still takes (albedo
    1e-9: it scatters something, so it keeps the random choice) within its noise."""
    data = sheet_scene(tmp_path, [[0.3, 0.3]], spp=4)
    data["objects"][0]["emission"] = {"radiance": 3.0}
    img = render(data, tmp_path)
    np.testing.assert_allclose(img, 0.3 * 3.0 + 0.7 * 2.0, rtol=1e-4)    # (the colour conversion's rounding)
    assert img.std() < 1e-6
    data["materials"]["almost_black"] = {"type": "lambert", "albedo": 1e-9}
    data["objects"][0]["material"] = "almost_black"
    data["render"]["spp"] = 256
    stochastic = render(data, tmp_path)
    assert stochastic.std() > 0.01                                  # the random choice is noisy
    assert stochastic.mean() == pytest.approx(2.3, abs=0.03)


def test_a_transparent_film_counts_what_black_sheets_let_through(tmp_path):
    """Film transparency behind a black half-alpha sheet (nothing behind it) is exactly 1 − alpha."""
    data = sheet_scene(tmp_path, [[0.5, 0.2]], spp=4)
    data["objects"] = data["objects"][:1]
    data["camera"]["film_transparent"] = True
    alpha = Renderer(parse_scene(copy.deepcopy(data), base_dir=str(tmp_path))).render().film.alpha()
    np.testing.assert_allclose(alpha[:, :4], 0.5, rtol=1e-7)        # (float32 film)
    np.testing.assert_allclose(alpha[:, 4:], 0.2, rtol=1e-7)
