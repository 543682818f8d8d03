"""The "sobol" sampler's first vertex (engine.render.sampler.vertex_pattern): its light choice and lobe must not
repeat the pixel jitter.  Until 2026-12-07 they were "stratified"'s Sobol' dimensions 7, 8, which over a pixel's
first 16 samples (one sequence) are fixed functions of the jitter's y (dimension 2) in their first two digits: with
two lights each one lit only one half of the pixel, an error that did not shrink with the samples (TextureTransform
under the sun and the area light: σ² 2.1× Cycles', docs/benchmarks/real-assets.md, helper F).

Oracle: a Lambert floor of black and white stripes, half a pixel wide along the image's y, under two suns of different
irradiance (delta: the light choice is the only light number), 16 spp, 12 seeds; every estimator is unbiased, so the
pixel variance between seeds is the error.  Independent numbers bound it from above."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene

N_PIX, FOV, DIST = 8, 20.0, 3.0


def _stripes():
    """Quads of albedo 1 and 0 alternating every half pixel along y (the camera looks down −z, up +y)."""
    half = DIST * math.tan(math.radians(FOV / 2))           # half the image's width on the floor
    step = half / N_PIX                                     # half a pixel
    objects = []
    for k in range(-2 * N_PIX - 2, 2 * N_PIX + 2):
        y0, y1 = k * step, (k + 1) * step
        objects.append({"shape": "quad", "material": "white" if k % 2 else "black",
                        "vertices": [[-1, y0, 0], [1, y0, 0], [1, y1, 0], [-1, y1, 0]]})
    return objects


def _scene(sampler, seed):
    data = {"format": "polar-scene/1",
            "camera": {"origin": [0, 0, DIST], "target": [0, 0, 0], "up": [0, 1, 0], "fov_deg": FOV,
                       "width": N_PIX, "height": N_PIX},
            "materials": {"white": {"type": "lambert", "albedo": 1.0}, "black": {"type": "lambert", "albedo": 0.0}},
            "objects": _stripes(),
            "lights": [{"type": "directional", "direction": [0.2, 0.1, -1.0], "irradiance": 4.0},
                       {"type": "directional", "direction": [-0.1, 0.3, -1.0], "irradiance": 1.0}],
            "render": {"spp": 16, "max_depth": 2, "seed": seed, "sampler": sampler}}
    scene = parse_scene(data)
    return dataclasses.replace(scene, settings=dataclasses.replace(scene.settings, halves="one_sequence"))


def _variance(sampler, seeds=12):
    ys = np.array([Renderer(s).render(s.settings).stokes()[0].mean(-1) for s in (_scene(sampler, k)
                                                                                   for k in range(seeds))])
    return ys.var(0, ddof=1).mean(), ys.mean()


def test_two_lights_on_sub_pixel_stripes_converge_with_sobol():
    """"sobol"'s pixel variance well below independent numbers' (measured 0.45×; 3.7× before the fix: each sun
    lit one half of the pixel) and near "cycles"' (measured 1.1×; 9.0× before), with the same mean."""
    v_sob, m_sob = _variance("sobol")
    v_ind, m_ind = _variance("independent")
    v_cyc, _ = _variance("cycles")
    print(f"variance sobol ÷ independent {v_sob / v_ind:.2f}, sobol ÷ cycles {v_sob / v_cyc:.2f}")
    assert abs(m_sob - m_ind) < 4 * math.sqrt((v_sob + v_ind) / 12 / N_PIX ** 2)
    assert v_sob < 0.5 * v_ind
    assert v_sob < 1.5 * v_cyc



@pytest.mark.parametrize("material, one", [({"type": "lambert", "albedo": 0.5}, True),
                                           ({"type": "torrance_sparrow", "n": 0.47, "k": 2.4, "m": 0.3}, True),
                                           ({"type": "torrance_sparrow", "n": 1.5, "m": 0.3, "diffuse_albedo": 0.5},
                                            False),
                                           ({"type": "rough_dielectric", "n": 1.5, "alpha": 0.3}, False)])
def test_one_lobe_materials_keep_the_direction_stratified_with_the_jitter(material, one):
    """PathTracer.one_lobe (by material index, so that batching does not change the image): the materials without
    a lobe choice (Lambert, a rough conductor), whose first-vertex direction "sobol" draws as "stratified" does (one
    net with the jitter), and not those with one (a glossy lobe over a diffuse one, a rough dielectric's reflection
    and refraction: Cycles' (lobe, direction) set)."""
    data = {"format": "polar-scene/1",
            "camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 20, "width": 4,
                       "height": 4},
            "materials": {"m": material},
            "objects": [{"shape": "quad", "material": "m",
                         "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]}],
            "lights": [{"type": "environment", "radiance": 1.0}]}
    renderer = Renderer(parse_scene(data))
    assert renderer.tracer(renderer.plan()).one_lobe.tolist() == [one]
