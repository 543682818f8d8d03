"""The light tree (engine.render.lights.tree): its pick probabilities against the frequencies of its own picks
(chi-square over every emitter and the "no light" outcome), their sum, the probability MIS reads at emitter hits
against the one the choice returned, and whole renders with and without the tree (same mean within noise)."""

import dataclasses
import math

import numpy as np
import pytest

from engine import kernels
from engine.errors import SceneError
from engine.materials.lambert import Lambert
from engine.render.accel import CompiledScene
from engine.render.lights import LightSet
from engine.kernels.light_tree import NO_LIGHT
from engine.render.renderer import Renderer
from engine.scene.description import (Camera, DirectionalLight, EnvironmentLight, Mesh, PointLight, RenderSettings,
                                      Scene, SpotLight)
from engine.scene.loader import parse_settings
from engine.scene.shapes import quad
from engine.spectral import ConstantSpectrum, RGBIlluminantSpectrum
from engine.textures import TextureInput, textured_emission
from tests.render.test_textured_emission import grid_mesh, image
from tests.support.chi2 import assert_accepted, pearson


def white(scale):
    return RGBIlluminantSpectrum([1.0, 1.0, 1.0], scale)


def many_lights_scene(count=150, seed=1, facing_down=False, sky=False, res=16, spp=16):
    """A grey floor (z = 0) under ``count`` small emissive triangles of mixed power (three meshes: one-sided,
    two-sided, one-sided at 30× the radiance), a textured emissive grid, a point, a sphere and a spot light;
    ``facing_down``: every one-sided triangle faces the floor; ``sky``: a grey world and a sun too."""
    rng = np.random.default_rng(seed)
    floor = quad(*[np.array(p, float) for p in ([-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0])])
    meshes = [Mesh("floor", floor.vertices, floor.faces, ["grey"], np.zeros(2, np.int32))]
    centre = np.column_stack((rng.uniform(-2, 2, count), rng.uniform(-2, 2, count), rng.uniform(0.6, 2.0, count)))
    v = centre[:, None, :] + rng.normal(0.0, 0.08, (count, 3, 3))
    if facing_down:
        v[:, :, 2] = v[:, :, 2].mean(axis=1, keepdims=True)
        up = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])[:, 2] > 0
        v[up] = v[up][:, [0, 2, 1]]
    for k, (radiance, two_sided) in enumerate(((4.0, False), (2.0, True), (120.0, False))):
        part = v[k::3].reshape(-1, 3)
        m = Mesh(f"emitters{k}", part, np.arange(len(part)).reshape(-1, 3), ["black"],
                 np.zeros(len(part) // 3, np.int32), emission=white(radiance))
        m.two_sided = two_sided and not facing_down
        meshes.append(m)
    texels = rng.uniform(0.0, 1.0, (4, 4, 3)) ** 3
    meshes.append(grid_mesh("panel", [-1.5, 1.0, 2.2], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], 3, 2,
                            textured_emission(TextureInput(image(texels)), 30.0)))
    lights = [PointLight(np.array([1.5, -1.0, 1.5]), white(3.0)),
              PointLight(np.array([-1.2, -1.4, 1.0]), white(2.0), radius=0.2, soft_falloff=False),
              SpotLight(np.array([0.0, 1.5, 2.5]), np.array([0.2, -0.3, -1.0]), white(40.0), 50.0, 0.3)]
    if sky:
        lights += [EnvironmentLight(ConstantSpectrum(0.05)), DirectionalLight(np.array([0.3, 0.2, -1.0]), white(0.5),
                                                                             2.0)]
    cam = Camera(origin=np.array([0.0, 0.0, 6.0]), target=np.zeros(3), up=np.array([0.0, 1.0, 0.0]),
                 width=res, height=res, projection="orthographic", ortho_width=4.0)
    return Scene(camera=cam, meshes=meshes,
                 materials={"grey": Lambert(ConstantSpectrum(0.5)), "black": Lambert(ConstantSpectrum(0.0))},
                 lights=lights, settings=RenderSettings(spp=spp, spectral="mono", max_depth=3, sampler="independent"))


def tree_of(scene):
    lights = LightSet(scene, CompiledScene(scene))
    return lights, lights.light_tree()


def picked_emitters(tree, light, tri):
    """The emitter index of each pick (NO_LIGHT: none)."""
    by_tri = tree.emitter_of_triangle[np.maximum(tri, 0)]
    by_light = tree.emitter_of_light[np.maximum(light, 0)]
    return np.where(light < 0, NO_LIGHT, np.where(tri >= 0, by_tri, by_light))


@pytest.mark.parametrize("sky", [False, True])
def test_pick_probabilities_are_the_frequencies_of_the_picks(sky):
    lights, tree = tree_of(many_lights_scene(sky=sky))
    E = tree.em["kind"].shape[0]
    assert E == 150 + 12 + 3 + sky            # every triangle, the lamps and the sun (a constant world is none)
    rng = np.random.default_rng(7)
    cases = [((0.3, -0.4, 0.0), (0, 0, 1.0)), ((-1.0, 0.8, 0.0), (0, 0, 1.0)), ((0.5, 0.5, 1.2), (0, 0, 0.0)),
             ((1.0, -1.0, 1.5), (0.6, 0.0, 0.8))]
    for p, n in cases:
        p, n = np.array(p)[:, None], np.array(n)[:, None]
        prob = tree.probability(np.arange(E), np.repeat(p, E, 1), np.repeat(n, E, 1))
        assert np.all(prob >= 0) and prob.sum() <= 1.0 + 1e-12
        M = 200_000
        light, rest, chosen, tri = tree.choose(rng.random(M), np.repeat(p, M, 1), np.repeat(n, M, 1))
        e = picked_emitters(tree, light, tri)
        got = e >= 0
        # the probability the choice returns is the one MIS recomputes for that emitter
        np.testing.assert_allclose(chosen[got], prob[e[got]], rtol=1e-13, atol=0)
        assert np.all((rest >= 0) & (rest < 1))
        observed = np.append(np.bincount(e[got], minlength=E), (~got).sum())
        expected = M * np.append(prob, max(1.0 - prob.sum(), 0.0))
        assert_accepted(pearson(observed, expected), test_count=len(cases) * 2, what="light tree picks")


def test_pick_probabilities_sum_to_one_where_every_emitter_can_light_the_point():
    lights, tree = tree_of(many_lights_scene(facing_down=True, sky=True))
    E = tree.em["kind"].shape[0]
    rng = np.random.default_rng(3)
    for _ in range(8):
        p = np.array([rng.uniform(-1, 1), rng.uniform(-1, 1), 0.0])[:, None]
        prob = tree.probability(np.arange(E), np.repeat(p, E, 1), np.repeat(np.array([[0.0], [0.0], [1.0]]), E, 1))
        # no traversal ends without a light: every emitter but the spot faces the point (its sibling then does)
        assert prob.sum() == pytest.approx(1.0, abs=1e-12)


def test_a_constant_sky_is_left_to_bsdf_sampling():
    """Cycles leaves a world of one radiance out of its tree (scene/light.cpp test_enabled_lights: its MIS off):
    beside other lights it is never picked and its pick probability (MIS at world misses) is 0; alone, no light
    is picked at all.  (Before 2026-12-07 session 6 it took a share of every point's samples.)"""
    scene = many_lights_scene(count=6, sky=True)
    lights, tree = tree_of(scene)
    sky = next(i for i, lt in enumerate(lights.lights) if lt.constant_sky)
    p = np.array([[0.2], [0.1], [0.0]]).repeat(4096, 1)
    n = np.array([[0.0], [0.0], [1.0]]).repeat(4096, 1)
    light, _, prob, _ = tree.choose((np.arange(4096) + 0.5) / 4096, p, n)
    assert not (light == sky).any() and (light >= 0).all() and (prob > 0).all()
    assert np.all(tree.probability_of_light(sky, p[:, :1], n[:, :1]) == 0.0)
    scene.meshes, scene.lights = scene.meshes[:1], [lt for lt in scene.lights if isinstance(lt, EnvironmentLight)]
    lights, tree = tree_of(scene)
    light, _, prob, _ = tree.choose(np.array([0.3]), p[:, :1], n[:, :1])
    assert tree.arrays.root == -1 and light[0] == NO_LIGHT and prob[0] == 0.0


def test_whole_lights_and_triangles_are_found_by_mis_lookups():
    lights, tree = tree_of(many_lights_scene())
    p, n = np.array([[0.2], [0.1], [0.0]]), np.array([[0.0], [0.0], [1.0]])
    for li, light in enumerate(lights.lights):
        if tree.split[li]:
            prims = light.tris
            prob = tree.probability_of_triangles(prims, np.repeat(p, prims.size, 1), np.repeat(n, prims.size, 1))
            assert prob.shape == prims.shape and np.all(prob >= 0)
        else:
            assert tree.emitter_of_light[li] >= 0
            assert tree.probability_of_light(li, p, n).shape == (1,)


def test_renders_with_and_without_the_tree_have_the_same_mean():
    """Unbiasedness: over seeds, the pixel means with the tree equal those without it within their noise, and
    the tree's noise is not larger on this many-light floor."""
    scene = many_lights_scene(count=120, res=12, spp=8, sky=True)
    seeds = 8
    images = {"on": [], "off": []}
    for seed in range(seeds):
        for mode in images:
            st = dataclasses.replace(scene.settings, seed=seed, light_tree=mode)
            images[mode].append(Renderer(scene).render(st).stokes_luminance()[0])
    a, b = np.array(images["on"]), np.array(images["off"])
    # 2×2-pixel blocks: the mean of each block over seeds, and its standard error from the seeds' spread
    ba, bb = (x.reshape(seeds, 6, 2, 6, 2).mean(axis=(2, 4)) for x in (a, b))
    diff = ba.mean(axis=0) - bb.mean(axis=0)
    se = np.sqrt(ba.var(axis=0, ddof=1) / seeds + bb.var(axis=0, ddof=1) / seeds)
    lit = se > 0                        # (the blocks under the panel's dark back are 0 in every render)
    assert np.all(diff[~lit] == 0) and lit.sum() > 20
    z = diff[lit] / se[lit]
    assert np.abs(z).max() < 5.0 and abs(z.mean()) * math.sqrt(z.size) < 4.0, z
    # the whole image: its mean over seeds
    ma, mb = a.mean(axis=(1, 2)), b.mean(axis=(1, 2))
    assert abs(ma.mean() - mb.mean()) < 4.0 * math.sqrt(ma.var(ddof=1) / seeds + mb.var(ddof=1) / seeds)
    # and less noise per pixel with the tree than with the power selection over whole lights
    assert a.var(axis=0, ddof=1).mean() < b.var(axis=0, ddof=1).mean()


def test_light_tree_setting_is_checked_and_off_keeps_the_light_set_choice():
    with pytest.raises(SceneError, match="render.light_tree"):
        parse_settings({"light_tree": "yes"})
    assert parse_settings({"light_tree": "on"}).light_tree == "on"
    small = LightSet(*(lambda s: (s, CompiledScene(s)))(many_lights_scene(count=9)))
    big = LightSet(*(lambda s: (s, CompiledScene(s)))(many_lights_scene(count=90)))
    assert not small.uses_tree("auto") and big.uses_tree("auto")      # 9 + 12 + 3 vs 90 + 12 + 3 emitters
    assert small.uses_tree("on") and not big.uses_tree("off")


@pytest.mark.skipif(not kernels.COMPILED, reason="needs Numba")
def test_compiled_traversal_gives_the_numpy_twins_bits():
    """The per-point loops (engine.kernels.light_tree) against their NumPy twins on random points and normals,
    transmitting (zero) normals and a world and a sun included."""
    from engine.kernels import light_tree as K
    _, tree = tree_of(many_lights_scene(count=300, sky=True))
    t = tree.arrays
    rng = np.random.default_rng(11)
    M = 5000
    p = np.vstack((rng.uniform(-2.5, 2.5, M), rng.uniform(-2.5, 2.5, M), rng.uniform(0.0, 2.5, M)))
    n = rng.normal(size=(3, M))
    n /= np.linalg.norm(n, axis=0)
    n[:, ::5] = 0.0
    u = rng.random(M)
    for got, want in zip(K.choose_numba(t, u, p, n), K.choose_numpy(t, u, p, n)):
        assert np.array_equal(got, want)
    e = rng.integers(-1, t.em_kind.size, M)
    assert np.array_equal(K.probability_numba(t, e, p, n), K.probability_numpy(t, e, p, n))


@pytest.mark.parametrize("lamps", [1, 2, 0])
def test_trees_of_one_emitter_or_none_choose_it_or_nothing(lamps):
    """A tree whose root is a leaf (one lamp), a root over two, and none at all (a black emitter only)."""
    scene = many_lights_scene(count=3)
    scene.meshes = scene.meshes[:1] + [scene.meshes[-1]] * (lamps == 0)
    scene.meshes[-1].emission = textured_emission(TextureInput(image(np.zeros((2, 2, 3)))), 1.0) if not lamps \
        else scene.meshes[-1].emission
    scene.lights = scene.lights[:lamps]
    lights, tree = tree_of(scene)
    p, n = np.array([[0.1], [0.0], [0.0]]), np.array([[0.0], [0.0], [1.0]])
    light, rest, prob, tri = tree.choose(np.array([0.3]), p, n)
    if lamps == 0:
        assert light[0] == NO_LIGHT and prob[0] == 0.0
    else:
        assert light[0] >= 0 and 0 < prob[0] <= 1 and prob[0] == tree.probability_of_light(int(light[0]), p, n)[0]
    st = dataclasses.replace(scene.settings, light_tree="on", spp=2)
    assert np.isfinite(Renderer(scene).render(st).stokes_luminance()).all()


@pytest.mark.parametrize("tree", ["off", "on"])
def test_emitters_sampled_together_give_the_same_image_as_one_by_one(tree, monkeypatch):
    """Next-event estimation samples the emitters sampled by area (one- and two-sided meshes) together, in one
    compiled pass (lights.area.AreaGroup): the image is the one of sampling each light by itself, bit for bit."""
    from engine.render.lights.area import AreaGroup
    scene = many_lights_scene(count=30, res=12, spp=4, sky=True)
    settings = dataclasses.replace(scene.settings, light_tree=tree, spectral="rgb", polarisation="linear")
    renderer = Renderer(scene)
    together = renderer.render(settings).stokes()
    assert (AreaGroup(renderer.lights.lights).index >= 0).sum() == 3
    monkeypatch.setattr(AreaGroup, "by_area", staticmethod(lambda light: False))
    alone = Renderer(scene).render(settings).stokes()
    assert np.array_equal(together, alone) and together[0].max() > 0
