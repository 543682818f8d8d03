"""RGB transport ("spectral": "rgb"): Cycles' colour arithmetic, channel by channel.

Oracles are closed forms of RGB products: a Lambert plane under a uniform coloured sky returns
albedo × sky per channel; a closed diffuse box lit from inside multiplies the albedo per bounce per
channel (the geometric series of a furnace).  Spectral transport does not (spectral products of
saturated colours are not RGB products): asserted too, so the tests can fail.
"""

import copy

import numpy as np
import pytest

from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene
from engine.errors import SceneError

ALBEDO = [0.8, 0.05, 0.05]
SKY = [0.3, 0.5, 1.0]


def plane_scene(spectral, spp=64):
    return {"format": "polar-scene/1",
            "camera": {"projection": "orthographic", "ortho_width": 1.0, "origin": [0, 0, 5], "target": [0, 0, 0],
                       "up": [0, 1, 0], "width": 4, "height": 4},
            "render": {"spp": spp, "max_depth": 8, "spectral": spectral, "sampler": "independent"},
            "materials": {"red": {"type": "lambert", "albedo": ALBEDO}},
            "objects": [{"shape": "quad", "vertices": [[-9, -9, 0], [9, -9, 0], [9, 9, 0], [-9, 9, 0]],
                         "material": "red"}],
            "lights": [{"type": "environment", "radiance": 1.0, "color": SKY}]}


def render(data):
    return Renderer(parse_scene(copy.deepcopy(data))).render()


def test_one_bounce_is_albedo_times_sky_per_channel():
    s0 = render(plane_scene("rgb", spp=256)).stokes()[0].reshape(-1, 3)
    se = s0.std(0, ddof=1) / np.sqrt(len(s0))
    want = np.array(ALBEDO) * SKY
    assert np.all(np.abs(s0.mean(0) - want) <= 4 * se + 1e-6 * want), (s0.mean(0), want, se)
    # the channel ratios are exact: every path carries the three channels through the same bounces
    np.testing.assert_allclose(s0.mean(0) / want, s0.mean(0)[0] / want[0], rtol=1e-12)


def test_products_of_saturated_colours_are_rgb_products_only_in_rgb_transport():
    """A red floor lit by a red lamp: every path carries the channels through the same geometry, so in RGB
    transport the image's channel ratios are exactly those of lamp colour × albedo (Cycles' arithmetic);
    spectral transport (the engine's default) multiplies spectra, and the minor channels differ."""
    lamp = [1.0, 0.02, 0.02]

    def lit(spectral):
        data = plane_scene(spectral, spp=64)
        data["lights"] = []
        data["objects"].append({"shape": "quad", "vertices": [[-1, -1, 2], [1, -1, 2], [1, 1, 2], [-1, 1, 2]],
                                "material": "red", "visible_camera": False,
                                "emission": {"radiance": 5.0, "color": lamp, "two_sided": True}})
        return render(data).stokes()[0].reshape(-1, 3).mean(0)
    rgb, spectral = lit("rgb"), lit("spectral")
    want = np.array(lamp) * ALBEDO
    np.testing.assert_allclose(rgb / rgb[0], want / want[0], rtol=1e-9)
    assert abs((spectral[1] / spectral[0]) / (want[1] / want[0]) - 1.0) > 0.2


def test_rgb_transport_reports_and_refuses_unknown_modes():
    result = render(plane_scene("rgb", spp=2))
    assert "Cycles" in result.stats["spectral"]
    bad = plane_scene("rgb")
    bad["render"]["spectral"] = "cmyk"
    with pytest.raises(SceneError, match=r"render\.spectral: must be one of 'spectral', 'rgb', 'mono'"):
        parse_scene(bad)
