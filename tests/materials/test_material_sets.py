"""Materials shaded together (LambertSet) give exactly the image of materials shaded one by one."""

import dataclasses

import numpy as np
import pytest

from engine.materials import batching
from engine.materials.lambert import Lambert, LambertSet
from engine.render import integrator
from engine.render.renderer import Renderer
from engine.scene.loader import load_scene, parse_scene
from engine.spectral import ConstantSpectrum
from engine.spectral.spectrum import RGBReflectanceSpectrum
from tests.conftest import shared_path


def one_by_one(materials):
    return list(materials), np.arange(len(materials)), np.zeros(len(materials), np.int64)


def cornell(spectral, res=24, spp=3):
    scene = load_scene(shared_path("peers", "scenes", "cornell_lambert.json"))
    scene.camera.width = scene.camera.height = res
    scene.settings = dataclasses.replace(scene.settings, spp=spp, spectral=spectral)
    return scene


@pytest.mark.parametrize("spectral", ["spectral", "mono"])
@pytest.mark.parametrize("grey", [False, True])
def test_lambert_set_render_is_bitwise_the_one_by_one_render(monkeypatch, spectral, grey):
    """Coloured (spectral), grey (RGB mode: λ-independent) and mono; several bounces, so a stale
    per-bounce value would show (the first version memoised albedos per wavelength lookup only)."""
    scene = cornell(spectral)
    if grey:
        for name, m in scene.materials.items():
            if isinstance(m, Lambert):
                scene.materials[name] = Lambert(ConstantSpectrum(float(np.mean(m.albedo.linear_srgb()))))
    renderer = Renderer(scene)
    settings = dataclasses.replace(scene.settings, polarisation="off")
    tracer = integrator.PathTracer(renderer.compiled, renderer.lights, renderer.camera, settings)
    assert any(isinstance(s, LambertSet) for s in tracer.shaders)
    batched = renderer.render().stokes()
    monkeypatch.setattr(integrator, "shading_groups", one_by_one)
    separate = renderer.render().stokes()
    assert np.abs(batched).max() > 0
    np.testing.assert_array_equal(batched, separate)


def test_mixed_constant_and_rgb_albedos_give_each_members_value():
    members = [Lambert(ConstantSpectrum(0.3)), Lambert(RGBReflectanceSpectrum([0.8, 0.1, 0.1])),
               Lambert(RGBReflectanceSpectrum([0.5, 0.5, 0.5]))]
    group = LambertSet(members)
    from engine.materials.base import ShadingPoint
    from engine.spectral import WavelengthLookup
    n = 600
    rng = np.random.default_rng(0)
    lam = rng.uniform(360, 830, (4, n))
    slot = rng.integers(0, 3, n)
    up = np.tile([[0.0], [0.0], [1.0]], n)
    wo = np.tile([[0.3], [0.0], [0.9539392014169456]], n)
    wi = np.tile([[-0.5], [0.0], [0.8660254037844386]], n)
    sp = ShadingPoint(np.zeros((3, n)), up, up, wo, lam, lookup=WavelengthLookup(lam), material=slot)
    got = group.eval(sp, wi).A
    for k, m in enumerate(members):
        mine = slot == k
        ref = m.eval(ShadingPoint(np.zeros((3, mine.sum())), up[:, mine], up[:, mine], wo[:, mine], lam[:, mine]),
                     wi[:, mine]).A
        np.testing.assert_array_equal(got[:, mine], ref)


def test_only_batchable_lambert_materials_are_grouped():
    from engine.materials.conductor import SmoothConductor
    from engine.spectral.spectrum import TabulatedSpectrum
    mats = [Lambert(ConstantSpectrum(0.5)), SmoothConductor(ConstantSpectrum(0.2), ConstantSpectrum(3.0)),
            Lambert(TabulatedSpectrum([400, 700], [0.2, 0.8], kind="reflectance")),
            Lambert(RGBReflectanceSpectrum([0.2, 0.4, 0.6]))]
    shaders, group_of, slot_of = batching.shading_groups(mats)
    assert isinstance(shaders[0], LambertSet) and shaders[0].members == [mats[0], mats[3]]
    assert group_of.tolist() == [0, 1, 2, 0] and slot_of[[0, 3]].tolist() == [0, 1]
    assert shaders[1] is mats[1] and shaders[2] is mats[2]
    single = batching.shading_groups(mats[:2])[0]
    assert single == mats[:2]                       # one Lambert: nothing to batch
    with pytest.raises(ValueError):
        LambertSet([mats[1]])


# --------------------------------------------------------------------------- MaterialSet

def _glossy_box(tmp_path, spectral, twins=False):
    """A box (floor, back, left, right, ceiling) and two panes as Blender's materials (Principled: rough metals, a
    plastic, a clear coat with a normal map, a sheen, two rough glasses, and a Mix), every one two-sided in Cycles'
    convention as the exporter writes them, lit by a point lamp; 16 × 16 at 4 spp, 5 segments.  ``twins``: the
    white, red and frosted materials again under other names on the box's halves, and two smooth glass panes of
    twin materials."""
    import OpenEXR
    tilt = np.array([0.5, 0.0, np.sqrt(0.75)])
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {c: np.full((2, 2), (tilt[i] + 1) / 2, np.float32) for i, c in enumerate("RGB")}
                 ).write(str(tmp_path / "tilt.exr"))
    blender = {"two_sided": True, "radiance_scaling": False}
    materials = {
        "white": {"type": "principled", "base_color": [0.8, 0.8, 0.8], "metallic": 1.0, "roughness": 0.4, **blender},
        "red": {"type": "principled", "base_color": [0.63, 0.1, 0.05], "roughness": 0.5, **blender},
        "green": {"type": "principled", "base_color": [0.14, 0.45, 0.09], "roughness": 0.3, "coat_weight": 1.0,
                  "normal_map": {"texture": "tilt.exr", "color_space": "Non-Color"}, **blender},
        "gold": {"type": "principled", "base_color": [1.0, 0.77, 0.34], "metallic": 1.0, "roughness": 0.2,
                 "sheen_weight": 0.5, **blender},
        "glass": {"type": "principled", "base_color": [0.9, 0.9, 1.0], "transmission": 1.0, "roughness": 0.3,
                  **blender},
        "frosted": {"type": "principled", "transmission": 1.0, "roughness": 0.6, "ior": 1.33, **blender},
        "mixed": {"type": "mix", "materials": ["red", "gold"], "weights": [0.3, 0.7], **blender}}

    def quad(material, *v):
        return {"shape": "quad", "material": material, "vertices": [list(map(float, x)) for x in v]}
    objects = [quad("white", [-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]),
               quad("gold", [-1, 1, 2], [1, 1, 2], [1, -1, 2], [-1, -1, 2]),
               quad("mixed", [-1, 1, 0], [1, 1, 0], [1, 1, 2], [-1, 1, 2]),
               quad("red", [-1, -1, 0], [-1, 1, 0], [-1, 1, 2], [-1, -1, 2]),
               quad("green", [1, 1, 0], [1, -1, 0], [1, -1, 2], [1, 1, 2]),
               quad("glass", [-0.6, -0.2, 0.1], [0.1, -0.2, 0.1], [0.1, -0.2, 1.2], [-0.6, -0.2, 1.2]),
               quad("frosted", [0.2, 0.3, 0.1], [0.8, 0.1, 0.1], [0.8, 0.1, 1.0], [0.2, 0.3, 1.0])]
    if twins:
        smooth = {"type": "dielectric", "n": 1.5, **blender}
        materials.update({"white_2": materials["white"], "red_2": materials["red"], "frosted_2": materials["frosted"],
                          "pane": smooth, "pane_2": dict(smooth)})
        objects = objects[1:] + [quad("white_2", [-1, -1, 0], [0, -1, 0], [0, 1, 0], [-1, 1, 0]),
                                 quad("white", [0, -1, 0], [1, -1, 0], [1, 1, 0], [0, 1, 0]),
                                 quad("red_2", [-1, -1, 1], [-1, 1, 1], [-1, 1, 2], [-1, -1, 2]),
                                 quad("frosted_2", [0.2, 0.6, 0.1], [0.8, 0.4, 0.1], [0.8, 0.4, 1.0], [0.2, 0.6, 1.0]),
                                 quad("pane", [-0.9, -0.6, 0.2], [-0.5, -0.6, 0.2], [-0.5, -0.6, 0.9],
                                      [-0.9, -0.6, 0.9]),
                                 quad("pane_2", [0.4, -0.6, 0.2], [0.8, -0.6, 0.2], [0.8, -0.6, 0.9],
                                      [0.4, -0.6, 0.9])]
    return parse_scene({
        "format": "polar-scene/1",
        "camera": {"origin": [0, -3.8, 1], "target": [0, 0, 1], "up": [0, 0, 1], "width": 16, "height": 16,
                   "fov_deg": 40},
        "render": {"spp": 4, "max_depth": 5, "spectral": spectral},
        "materials": materials, "objects": objects,
        "lights": [{"type": "point", "position": [0.2, -0.5, 1.8], "intensity": 20}]}, str(tmp_path))


@pytest.mark.parametrize("spectral", ["rgb", "spectral"])
def test_material_sets_render_the_one_by_one_image(tmp_path, monkeypatch, spectral):
    """Every non-Lambert, non-delta material of a box shaded in MaterialSets (one per radiance convention and
    transmission) gives the image of one group per material, to float rounding: the members' values are their
    own calls' (a member's normal map included); light sampling and shadow rays are per path."""
    from engine.materials.material_set import MaterialSet
    scene = _glossy_box(tmp_path, spectral)
    renderer = Renderer(scene)
    tracer = renderer.tracer(renderer.plan())
    sets = [s for s in tracer.shaders if isinstance(s, MaterialSet)]
    assert sorted(len(s.members) for s in sets) == [2, 5]          # opaque: 5, transmitting: 2
    batched = renderer.render().stokes()
    monkeypatch.setattr(integrator, "shading_groups", lambda m: batching.shading_groups(m, batch=False))
    separate = renderer.render().stokes()
    assert np.abs(separate[0]).max() > 0 and np.abs(separate[1:]).max() > 0     # lit, and polarised
    np.testing.assert_allclose(batched, separate, rtol=1e-12, atol=1e-13 * np.abs(separate).max())


def test_material_sets_group_what_the_integrator_reads_alike():
    """Sets form by (radiance_scaling, transmits); delta-only, Lambert and one-of-a-kind materials stay alone."""
    from engine.materials.conductor import SmoothConductor
    from engine.materials.material_set import MaterialSet
    from engine.materials.torrance_sparrow import TorranceSparrow
    rough = [TorranceSparrow(ConstantSpectrum(0.2), ConstantSpectrum(3.0), m) for m in (0.1, 0.2, 0.3)]
    rough[2].radiance_scaling = False
    mats = [rough[0], Lambert(ConstantSpectrum(0.5)), SmoothConductor(ConstantSpectrum(0.2), ConstantSpectrum(3.0)),
            rough[1], rough[2]]
    shaders, group_of, slot_of = batching.shading_groups(mats)
    assert shaders[:3] == [mats[1], mats[2], mats[4]]
    assert isinstance(shaders[3], MaterialSet) and shaders[3].members == [rough[0], rough[1]]
    assert group_of.tolist() == [3, 0, 1, 3, 2] and slot_of[[0, 3]].tolist() == [0, 1]
    with pytest.raises(ValueError, match="radiance_scaling"):
        MaterialSet([rough[0], rough[2]])
    with pytest.raises(ValueError, match="delta-only"):
        MaterialSet([rough[0], mats[2]])


# --------------------------------------------------------------------------- twins: one member, one group

def test_twin_materials_are_one_member_and_one_group():
    """Materials of one model with the same parameters (an exported glTF sample's emissive variants) share a set
    slot, and twins shaded alone share a group; different parameters, or large arrays that are not the same
    object, keep them apart; batch=False (the per-material groups) leaves every material its own group."""
    from engine.materials.conductor import SmoothConductor
    from engine.materials.material_set import MaterialSet
    from engine.materials.torrance_sparrow import TorranceSparrow

    def rough(m=0.3):
        return TorranceSparrow(ConstantSpectrum(0.2), RGBReflectanceSpectrum([0.5, 0.4, 0.3]), m)

    def mirror():
        return SmoothConductor(ConstantSpectrum(0.2), ConstantSpectrum(3.0))
    mats = [rough(), rough(0.5), rough(), mirror(), rough(), mirror(), Lambert(ConstantSpectrum(0.5))]
    assert batching.same_material(mats[0], mats[2]) and not batching.same_material(mats[0], mats[1])
    shaders, group_of, slot_of = batching.shading_groups(mats)
    sets = [s for s in shaders if isinstance(s, MaterialSet)]
    assert len(shaders) == 3 and len(sets) == 1 and sets[0].members == [mats[0], mats[1]]
    assert group_of[[0, 1, 2, 4]].tolist() == [group_of[0]] * 4 and slot_of[[0, 1, 2, 4]].tolist() == [0, 1, 0, 0]
    assert group_of[3] == group_of[5] and shaders[group_of[3]] is mats[3]
    alone, _, _ = batching.shading_groups([rough(), rough()])
    assert len(alone) == 1 and isinstance(alone[0], TorranceSparrow)       # all twins: the one material
    assert len(batching.shading_groups(mats, batch=False)[0]) == 7


def test_same_material_compares_large_arrays_by_identity():
    from engine.materials.torrance_sparrow import TorranceSparrow
    from engine.spectral.spectrum import TabulatedSpectrum
    wl = np.linspace(360.0, 830.0, 5000)
    one, other = TabulatedSpectrum(wl, np.full(wl.size, 0.5)), TabulatedSpectrum(wl, np.full(wl.size, 0.5))
    small = [TabulatedSpectrum([360.0, 830.0], [0.5, 0.6]) for _ in range(2)]
    assert not batching.same_material(TorranceSparrow(ConstantSpectrum(0.2), one, 0.3),
                                      TorranceSparrow(ConstantSpectrum(0.2), other, 0.3))
    assert batching.same_material(TorranceSparrow(ConstantSpectrum(0.2), one, 0.3),
                                  TorranceSparrow(ConstantSpectrum(0.2), one, 0.3))
    assert batching.same_material(TorranceSparrow(ConstantSpectrum(0.2), small[0], 0.3),
                                  TorranceSparrow(ConstantSpectrum(0.2), small[1], 0.3))


@pytest.mark.parametrize("spectral", ["rgb", "spectral"])
def test_twins_shaded_together_render_the_same_bits(tmp_path, monkeypatch, spectral):
    """The box with twins of its materials (glossy twins in the sets, smooth-glass twins shaded alone): one member
    or group per distinct material gives bit for bit the image of one per material."""
    renderer = Renderer(_glossy_box(tmp_path, spectral, twins=True))
    tracer = renderer.tracer(renderer.plan())
    together = renderer.render().stokes()
    monkeypatch.setattr(batching, "same_material", lambda a, b: False)
    apart_tracer = renderer.tracer(renderer.plan())
    def slots(t):
        return sum(len(getattr(s, "members", [s])) for s in t.shaders)
    assert slots(tracer) + 4 == slots(apart_tracer)         # the white, red, frosted and glass twins
    apart = renderer.render().stokes()
    assert np.abs(apart[0]).max() > 0
    np.testing.assert_array_equal(together, apart)


def test_assembled_values_ask_for_frames_only_where_a_lane_has_none():
    """assemble_values (a MaterialSet's members' values into one): where the members' own values (with their frames)
    cover every lane, the frames for depolarising lanes are not computed (they would all be overwritten); where a
    depolarising value leaves lanes without frames they are, and hold there.  The same numbers either way."""
    from engine.materials.base import MuellerValue, assemble_values, depolarising_value
    rng = np.random.default_rng(5)
    n, L = 12, 3
    lanes = rng.permutation(n)
    a, b = np.sort(lanes[:7]), np.sort(lanes[7:])

    def abcs(m):
        x = rng.normal(size=(3, m))
        return MuellerValue("abcs", x, x.copy(), *(rng.normal(size=(L, m)) for _ in range(4)),
                            depol=rng.random((L, m)))
    asked = []

    def frames():
        asked.append(1)
        return np.full((3, n), 7.0), np.full((3, n), -7.0)
    va, vb = abcs(a.size), abcs(b.size)
    whole = assemble_values([(a, va), (b, vb)], n, L, frames)
    assert not asked
    for idx, v in ((a, va), (b, vb)):
        assert np.array_equal(whole.x_in[:, idx], v.x_in) and np.array_equal(whole.x_out[:, idx], v.x_out)
        assert np.array_equal(whole.A[:, idx], v.A) and np.array_equal(whole.depol[:, idx], v.depol)
    grey = depolarising_value(rng.random((L, b.size)), b.size)
    mixed = assemble_values([(a, va), (b, grey)], n, L, frames)
    assert asked == [1]
    assert np.array_equal(mixed.x_in[:, b], np.full((3, b.size), 7.0)) and np.array_equal(mixed.x_in[:, a], va.x_in)
    assert np.array_equal(mixed.depol[:, b], grey.A) and not mixed.A[:, b].any()
