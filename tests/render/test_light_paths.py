"""Cycles' Light Paths (engine.render.light_paths): per-kind bounce limits, sample clamping and the caustics
switches.  Oracles: a kind's limit k in a scene whose bounces are all of that kind ends every path exactly
where ``max_depth`` k + 2 does (same random numbers: bit-identical images); an open glass sheet pair in a
white furnace (no transmission: the Fresnel reflectance); a camera-visible emitter clamped to the limit; the
clamp's factor applied to all four Stokes components (DoP unchanged); caustics off removes exactly the light
that reached a diffuse floor through glass.  Defaults: the renders of before, bit for bit."""

import dataclasses
import types

import numpy as np
import pytest

from engine.errors import SceneError
from engine.render.light_paths import LightPathBatch, LightPathRules
from engine.render.renderer import Renderer
from engine.scene.description import LIGHT_PATH_FIELDS, RenderSettings
from engine.scene.loader import load_scene, parse_scene, parse_settings
from tests.conftest import shared_path


def render(scene, **kw):
    """Stokes image of ``scene`` with its own settings changed by ``kw`` (the scene keeps them)."""
    own = scene.settings
    scene.settings = dataclasses.replace(own, **kw)
    try:
        return Renderer(scene).render().stokes()
    finally:
        scene.settings = own


def peer(name, size=32, spp=4):
    scene = load_scene(shared_path("peers", "scenes", f"{name}.json"))
    scene.camera.width = scene.camera.height = size
    scene.settings = dataclasses.replace(scene.settings, spp=spp, max_depth=16)
    return scene


@pytest.mark.parametrize("name,field", [("cornell_lambert", "max_diffuse_bounces"),
                                        ("fresnel_sphere", "max_glossy_bounces"),
                                        ("rough_sphere_a030", "max_glossy_bounces")])
def test_a_kinds_limit_ends_paths_where_max_depth_does(name, field):
    """Every bounce of these scenes is of one kind (Lambert walls; conductor and black-glass mirrors, a rough
    conductor): limit k of that kind = max_depth k + 2, bit for bit (k = 0: direct light only)."""
    scene = peer(name)
    for k in (0, 1, 3):
        np.testing.assert_array_equal(render(scene, max_depth=k + 2), render(scene, max_depth=16, **{field: k}))


def test_defaults_and_unreached_limits_render_the_images_of_before():
    """Defaults, and limits at or above max_depth − 2 (they cannot end a path before max_depth does), run the
    plain loop; with a clamp no sample reaches the light-path loop runs and gives the same bits (its stages and
    numbers are the plain loop's)."""
    scene = peer("cornell_lambert")
    before = render(scene)
    st = scene.settings
    assert not st.light_paths_active
    limits = {f.name: st.max_depth - 2 for f in LIGHT_PATH_FIELDS if f.kind == "int"}
    assert not dataclasses.replace(st, **limits).light_paths_active
    assert dataclasses.replace(st, max_glossy_bounces=st.max_depth - 3).light_paths_active
    assert dataclasses.replace(st, caustics_reflective=False).light_paths_active
    np.testing.assert_array_equal(before, render(scene, **limits))
    np.testing.assert_array_equal(before, render(scene, clamp_direct=1e30, clamp_indirect=1e30,
                                                 max_diffuse_bounces=st.max_depth - 3))


def glass_pair(**render):
    """Two parallel smooth glass sheets (Cycles' convention: every sample 0 or 1) in a white furnace."""
    sheet = lambda z: [[-1, -1, z], [1, -1, z], [1, 1, z], [-1, 1, z]]          # noqa: E731
    return parse_scene({
        "format": "polar-scene/1",
        "camera": {"origin": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 10, "width": 8,
                   "height": 8},
        "render": {"spp": 256, "seed": 1, "max_depth": 32, "spectral": "rgb", **render},
        "materials": {"glass": {"type": "dielectric", "n": 1.5, "radiance_scaling": False}},
        "objects": [{"shape": "quad", "vertices": sheet(0.0), "material": "glass"},
                    {"shape": "quad", "vertices": sheet(-0.5), "material": "glass"}],
        "lights": [{"type": "environment", "radiance": 1.0}],
    })


def test_no_transmission_bounce_leaves_the_fresnel_reflection():
    """Unlimited: the furnace is white.  max_transmission_bounces 0: a path that crossed the first sheet ends at
    the second, so a pixel is the first sheet's reflectance F ≈ 0.04 (n = 1.5, ≤ 5° from normal incidence)."""
    white = render(glass_pair())[0]
    np.testing.assert_allclose(white, 1.0, rtol=5e-4)      # (white light in RGB: 1 ± 2.1e-4)
    s0 = render(glass_pair(max_transmission_bounces=0))[0].mean()
    f, n = 0.04, 8 * 8 * 256
    assert abs(s0 - f) < 4 * np.sqrt(f * (1 - f) / n) + 2e-4 * f, s0


def test_clamp_direct_caps_a_visible_emitter():
    """A camera-visible emitter of radiance 1 (sRGB (1, 1, 1)) with clamp_direct 0.6: each sample is scaled to
    (0.6, 0.6, 0.6); clamp_indirect does not touch it."""
    doc = {"format": "polar-scene/1",
           "camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 10, "width": 6,
                      "height": 6},
           "render": {"spp": 4, "seed": 1, "spectral": "rgb"},
           "materials": {"black": {"type": "lambert", "albedo": 0.0}},
           "objects": [{"shape": "quad", "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                        "material": "black", "emission": {"radiance": 1.0}}],
           "lights": []}
    plain_result = Renderer(parse_scene(doc)).render()
    plain = plain_result.stokes()
    scene = parse_scene({**doc, "render": {**doc["render"], "clamp_direct": 0.6, "clamp_indirect": 0.01}})
    result = Renderer(scene).render()
    clamped = result.stokes()
    assert "light paths: clamp direct 0.6, clamp indirect 0.01" in result.stats_line()       # said, not silent
    assert "light paths" not in plain_result.stats_line()
    np.testing.assert_allclose(plain[0], 1.0, rtol=1e-6)
    np.testing.assert_allclose(clamped[0], 0.6, rtol=1e-12)


def test_clamp_scales_every_stokes_component_by_s0s_factor():
    """LightPathBatch.settle on polarised spectral contributions: the largest sRGB component of each clamped S0 is
    the limit,
    S1–S3 scaled by the same factor (DoP and AoLP unchanged), contributions below the limit and the light
    added before the mark untouched."""
    rng = np.random.default_rng(3)
    P, L, N = 4, 4, 64
    settings = RenderSettings(clamp_indirect=0.5)
    rules = LightPathRules(settings, [])
    batch = LightPathBatch(rules, N)
    w_rgb = rng.uniform(0.1, 1.0, (3, L, N))
    earlier = rng.uniform(0, 1, (P, L, N))
    acc = types.SimpleNamespace(radiance=earlier.copy(), w_rgb=w_rgb)
    path = np.arange(0, N, 2)
    mark = batch.mark(acc, path)
    s0 = rng.uniform(0, 0.25, (L, path.size))
    stokes = np.concatenate([s0[None], (s0 * rng.uniform(-0.5, 0.5, (3, L, path.size)))])
    acc.radiance[:, :, path] += stokes
    batch.settle(acc, mark, direct=False)
    added = acc.radiance - earlier
    np.testing.assert_array_equal(added[:, :, 1::2], 0.0)
    rgb_max = np.einsum("ln,cln->cn", stokes[0], w_rgb[:, :, path]).max(axis=0)
    over = rgb_max > 0.5
    assert over.any() and (~over).any()
    after = np.einsum("ln,cln->cn", added[0][:, path], w_rgb[:, :, path]).max(axis=0)
    np.testing.assert_allclose(after[over], 0.5, rtol=1e-12)
    factor = np.where(over, 0.5 / rgb_max, 1.0)
    np.testing.assert_allclose(added[:, :, path], stokes * factor, rtol=1e-12, atol=1e-15)


def glass_over_floor(**render):
    """A glass sphere above a white Lambert floor under a small area light, black sky: the floor's light through
    the sphere is a refractive caustic."""
    return parse_scene({
        "format": "polar-scene/1",
        "camera": {"origin": [0, -4, 4], "target": [0, 0, 0.3], "up": [0, 0, 1], "fov_deg": 35, "width": 24,
                   "height": 24},
        "render": {"spp": 16, "seed": 2, "max_depth": 8, **render},
        "materials": {"glass": {"type": "dielectric", "n": 1.5}, "white": {"type": "lambert", "albedo": 0.8},
                      "black": {"type": "lambert", "albedo": 0.0}},
        "objects": [{"shape": "sphere", "center": [0, 0, 1], "radius": 0.6, "subdivisions": 4, "material": "glass"},
                    {"shape": "quad", "vertices": [[-4, -4, 0], [4, -4, 0], [4, 4, 0], [-4, 4, 0]],
                     "material": "white"},
                    {"shape": "quad", "vertices": [[-0.3, -0.3, 4], [-0.3, 0.3, 4], [0.3, 0.3, 4], [0.3, -0.3, 4]],
                     "material": "black", "emission": {"radiance": 60.0}}],
        "lights": [],
    })


def test_no_refractive_caustics_darkens_the_floor_under_glass_only():
    """Caustics off drops the glass lobes after the floor's diffuse bounce: the same random numbers, so no pixel
    gains light and the light lost is the caustic in the sphere's shadow; the reflective switch alone keeps the
    refraction (it drops the sphere's mirror reflections after the floor, a small part)."""
    on = render(glass_over_floor())[0].sum(-1)
    off = render(glass_over_floor(caustics_refractive=False))[0].sum(-1)
    assert np.all(off <= on + 1e-12)
    lost = on - off
    assert lost.sum() > 5.0, lost.sum()
    reflective_off = render(glass_over_floor(caustics_reflective=False))[0].sum(-1)
    assert np.all(reflective_off <= on + 1e-12)
    assert (on - reflective_off).sum() < 0.5 * lost.sum()


def test_bad_values_name_the_field_and_its_range():
    for f in LIGHT_PATH_FIELDS:
        bad = {"int": -1, "float": -0.5, "bool": 1}[f.kind]
        with pytest.raises(SceneError) as e:
            parse_settings({f.name: bad})
        assert e.value.field == f"render.{f.name}"
        assert ("[0, 1024]" in str(e.value)) if f.kind == "int" else \
            ("[0, 1e+30]" in str(e.value)) if f.kind == "float" else ("true or false" in str(e.value))
    assert parse_settings({"max_glossy_bounces": 2, "clamp_indirect": 10, "caustics_reflective": False}) == \
        RenderSettings(max_glossy_bounces=2, clamp_indirect=10.0, caustics_reflective=False)


def test_command_line_options_and_resume_identity():
    from engine.cli import _settings_from_options, build_parser
    from engine.render.resume import differences, estimator_identity
    args = build_parser().parse_args(["render", "s.json", "-o", "o.exr", "--max-diffuse-bounces", "2",
                                      "--clamp-indirect", "4", "--caustics-refractive", "off"])
    scene = types.SimpleNamespace(settings=RenderSettings())
    st = _settings_from_options(scene, args)
    assert (st.max_diffuse_bounces, st.clamp_indirect, st.caustics_refractive) == (2, 4.0, False)
    args = build_parser().parse_args(["render", "s.json", "-o", "o.exr", "--max-glossy-bounces", "-1"])
    with pytest.raises(SceneError) as e:
        _settings_from_options(scene, args)
    assert e.value.field == "--max-glossy-bounces" and "[0, 1024]" in str(e.value)
    ident = estimator_identity("h", st, "full", size=(4, 4))
    assert ident["polar.max_diffuse_bounces"] == 2 and ident["polar.caustics_refractive"] == "off"
    plain = estimator_identity("h", RenderSettings(), "full", size=(4, 4))
    assert not any(k.removeprefix("polar.") in {f.name for f in LIGHT_PATH_FIELDS} for k in plain)
    assert differences(ident, plain) and not differences(ident, dict(ident))
