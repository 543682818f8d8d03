"""Materials, lights and the viewport logic on the Blender side."""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import add_plane, empty_scene, load_addon, polar_material  # noqa: E402


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def exported(material):
    from polar_render.polar_addon.export.materials import export_material
    warnings = []
    bsdf, emission = export_material(material, warnings)
    return bsdf, emission, warnings


def principled(**inputs):
    mat = bpy.data.materials.new("P")
    node = mat.node_tree.nodes["Principled BSDF"]
    for k, v in inputs.items():
        node.inputs[k].default_value = v
    return mat


def test_node_parameters_survive_save_and_reload(addon, tmp_path):
    empty_scene()
    gold = polar_material("Gold", "CONDUCTOR", metal="Au")
    glass = polar_material("Glass", "DIELECTRIC", dielectric_preset="WATER")
    custom = polar_material("Custom", "CONDUCTOR", n=0.31, k=3.7)
    for m in (gold, glass, custom):
        add_plane(1.0, m)
    path = str(tmp_path / "materials.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=path)
    node = lambda name: bpy.data.materials[name].node_tree.nodes["Polarising BSDF"]  # noqa: E731
    assert node("Gold").model == "CONDUCTOR" and node("Gold").metal == "Au"
    assert node("Glass").model == "DIELECTRIC" and node("Glass").dielectric_preset == "WATER"
    assert node("Custom").inputs["n"].default_value == pytest.approx(0.31)
    assert node("Custom").inputs["k"].default_value == pytest.approx(3.7)
    # ... and they are what the exporter uses.
    bsdf, _, _ = exported(bpy.data.materials["Custom"])
    assert bsdf.name == "conductor"
    assert bsdf.n.eval(np.array([550.0]))[0] == pytest.approx(0.31, rel=1e-6)
    assert exported(bpy.data.materials["Glass"])[0].n_int == pytest.approx(1.333)


def test_node_shows_exactly_the_selected_models_inputs(addon):
    from polar_render.polar_addon.nodes.models import MODEL_ITEMS, MODEL_SOCKETS
    empty_scene()
    mat = polar_material("M", "LAMBERT")
    node = mat.node_tree.nodes["Polarising BSDF"]
    for model, *_ in MODEL_ITEMS:
        node.model = model
        assert [s.name for s in node.inputs] == [s[0] for s in MODEL_SOCKETS[model]]
        assert node.outputs[0].is_linked                         # switching keeps the Surface link


def test_enum_numbers_are_stable(addon):
    from polar_render.polar_addon.nodes.models import MODEL_ITEMS
    from polar_render.polar_addon.properties import POLARISATION_ITEMS, SPECTRAL_ITEMS
    assert [(i[0], i[3]) for i in MODEL_ITEMS] == [
        ("LAMBERT", 0), ("CONDUCTOR", 1), ("DIELECTRIC", 2), ("BLACK_GLASS", 3), ("TORRANCE_SPARROW", 4),
        ("HTSG", 5), ("WEIDLICH_WILKIE", 6), ("ROUGH_DIELECTRIC", 7), ("THIN_DIELECTRIC", 8)]
    assert [(i[0], i[3]) for i in POLARISATION_ITEMS] == [("AUTO", 0), ("FULL", 1), ("LINEAR", 2), ("OFF", 3)]
    assert [(i[0], i[3]) for i in SPECTRAL_ITEMS] == [("SPECTRAL", 0), ("MONO", 1), ("RGB", 2)]


def test_principled_conversion_per_input(addon):
    from polar_render.engine.materials.evaluate import mueller_at
    empty_scene()
    lam = np.array([[550.0]])
    # Metallic, smooth → Fresnel conductor whose normal-incidence reflectance is the base colour.
    bsdf, _, _ = exported(principled(**{"Metallic": 1.0, "Roughness": 0.0, "Base Color": (0.9, 0.9, 0.9, 1)}))
    assert bsdf.name == "conductor" and type(bsdf).__name__ == "F82Reflectance"   # S0 on Cycles' curve
    n, k = bsdf.base.n.eval(lam)[0, 0], bsdf.base.k.eval(lam)[0, 0]
    assert ((n - 1) ** 2 + k ** 2) / ((n + 1) ** 2 + k ** 2) == pytest.approx(0.9, rel=1e-6)
    # Transmission → smooth dielectric with the IOR.
    bsdf, _, _ = exported(principled(**{"Transmission Weight": 1.0, "IOR": 1.6, "Roughness": 0.0,
                                        "Base Color": (1, 1, 1, 1)}))
    assert bsdf.name == "dielectric" and bsdf.n_int == pytest.approx(1.6)
    # Rough transmission: GGX α = r², with Cycles' multiple-scattering compensation (Multiscatter GGX, the default).
    bsdf, _, warnings = exported(principled(**{"Transmission Weight": 1.0, "Roughness": 0.5,
                                               "Base Color": (1, 1, 1, 1)}))
    assert bsdf.name == "rough_dielectric" and bsdf.alpha == pytest.approx(0.25) and bsdf.multiscatter
    assert not warnings
    # Plain smooth dielectric base → Fresnel mirror over the base colour, shared as Cycles (albedo scaling).
    bsdf, _, _ = exported(principled(**{"Roughness": 0.0, "Base Color": (0.2, 0.4, 0.6, 1)}))
    assert bsdf.name == "torrance_sparrow" and bsdf.m == 0.0 and bsdf.diffuse_layering == "albedo_scaling"
    assert bsdf.albedo.linear_srgb() == pytest.approx([0.2, 0.4, 0.6], abs=1e-3)
    # Rough, non-metallic → Torrance–Sparrow dielectric (m = roughness²) with the base colour as Lambert part.
    bsdf, _, _ = exported(principled(**{"Roughness": 0.5, "IOR": 1.45, "Base Color": (0.5, 0.5, 0.5, 1)}))
    assert bsdf.name == "torrance_sparrow" and bsdf.m == pytest.approx(0.25)
    assert bsdf.n.eval(lam)[0, 0] == pytest.approx(1.45) and bsdf.has_diffuse
    # Rough metal → GGX Torrance–Sparrow conductor (α = r²), multiscatter as Cycles' default.
    bsdf, _, _ = exported(principled(**{"Metallic": 1.0, "Roughness": 0.4}))
    bsdf = bsdf.base
    assert bsdf.name == "torrance_sparrow" and bsdf.m == pytest.approx(0.16) and bsdf.k.eval(lam)[0, 0] > 0
    assert bsdf.distribution == "ggx" and bsdf.multiscatter
    # Metallic and Transmission are per-point mixture weights (Cycles' layer order), not switches.
    bsdf, _, _ = exported(principled(**{"Metallic": 0.25, "Roughness": 0.0, "Transmission Weight": 0.4}))
    assert bsdf.name == "mix" and [c.name for c in bsdf.components][-1] == "conductor"
    weights = dict(zip((c.name for c in bsdf.components), bsdf.weights))
    assert weights["conductor"] == pytest.approx(0.25)
    inner = [c for c in bsdf.components if c.name != "conductor"]
    if len(inner) == 1 and inner[0].name == "mix":         # nested: (dielectric, glass) under the metal
        inner = inner[0]
        assert inner.weights == pytest.approx([0.6, 0.4]) and weights["mix"] == pytest.approx(0.75)
    else:                                                  # flattened: weights multiplied out
        assert sorted(bsdf.weights) == pytest.approx(sorted([0.75 * 0.6, 0.75 * 0.4, 0.25]))
    # Blender's IOR range: 1000 (glTF specular-glossiness imports) and ≤ 0 (Cycles raises it to 1e-5) render.
    bsdf, _, _ = exported(principled(**{"Transmission Weight": 1.0, "IOR": 1000.0, "Roughness": 0.0,
                                        "Base Color": (1, 1, 1, 1)}))
    assert bsdf.n_int == pytest.approx(1000.0)
    bsdf, _, _ = exported(principled(**{"Transmission Weight": 1.0, "IOR": -2.0, "Roughness": 0.0,
                                        "Base Color": (1, 1, 1, 1)}))
    assert bsdf.n_int == pytest.approx(1e-5)
    from polar_render.engine.errors import SceneError
    with pytest.raises(SceneError, match="IOR"):
        exported(principled(**{"IOR": float("nan")}))
    # Specular IOR Level: F0 scaled by 2·level (level 0: no specular reflection at all).
    bsdf, _, _ = exported(principled(**{"Roughness": 0.0, "IOR": 1.5, "Specular IOR Level": 0.25}))
    n = bsdf.n.eval(lam)[0, 0]
    assert ((n - 1) / (n + 1)) ** 2 == pytest.approx(0.04 * 0.5, rel=1e-9)
    # Subsurface: rendered as the diffuse base it tends to (the same Mueller matrices as without it), one
    # warning; against Cycles' random walk at small radii this is 3–4 % brighter (docs/guide/blender.md).
    plain, _, _ = exported(principled(**{"Roughness": 0.5, "Base Color": (0.8, 0.3, 0.2, 1)}))
    sss, _, warnings = exported(principled(**{"Roughness": 0.5, "Base Color": (0.8, 0.3, 0.2, 1),
                                              "Subsurface Weight": 1.0, "Subsurface Scale": 0.01}))
    for theta in (0.0, 40.0, 80.0):
        np.testing.assert_array_equal(mueller_at(sss, theta, 30.0, 180.0)["brdf"],
                                      mueller_at(plain, theta, 30.0, 180.0)["brdf"])
    assert len(warnings) == 1 and "'Subsurface Weight'" in warnings[0]
    # Sheen: a layer over everything; Anisotropic: the anisotropic GGX, with one warning naming the tangent it
    # takes where Tangent is unlinked (Cycles: the radial tangent about the object's Z).
    bsdf, _, warnings = exported(principled(**{"Sheen Weight": 0.5, "Anisotropic": 0.3, "Roughness": 0.5}))
    assert bsdf.name == "layered" and bsdf.components[0].name == "sheen" and bsdf.top_weight == 0.5
    assert type(bsdf.components[1].components[0]).__name__ == "AnisotropicGGX"     # the specular layer below
    assert len(warnings) == 1 and "Tangent" in warnings[0] and "radial tangent" in warnings[0]
    # Coat → a GGX dielectric layer over everything below, Cycles' layering.
    bsdf, _, _ = exported(principled(**{"Coat Weight": 1.0, "Coat IOR": 1.6, "Coat Roughness": 0.0, "Roughness": 0.0}))
    assert bsdf.name == "layered" and bsdf.top_weight == 1.0     # Cycles' coat over everything below
    # Emission → emitter spectrum with colour × strength.
    _, emission, _ = exported(principled(**{"Emission Strength": 3.0, "Emission Color": (1, 0.5, 0.25, 1)}))
    assert emission is not None and emission.linear_srgb() == pytest.approx([3.0, 1.5, 0.75], rel=2e-3)


def _shader(tree, kind, **inputs):
    node = tree.nodes.new(kind)
    for k, v in inputs.items():
        node.inputs[k].default_value = v
    return node


@pytest.mark.parametrize("ior", [1.33, 1.5, 2.4])
def test_smooth_principled_is_the_polarising_fresnel_interface(addon, ior):
    """Metallic 0, Transmission 0, Roughness 0, a black base: the Mueller matrix (mirror lobe, every angle
    and basis) is black glass's to 1e-12; Transmission 1 (white base): the dielectric model's; so the DoLP of
    a smooth Principled dielectric is the Fresnel one (full s-polarisation at Brewster's angle)."""
    from polar_render.engine.materials.black_glass import BlackGlass
    from polar_render.engine.materials.dielectric import SmoothDielectric
    from polar_render.engine.materials.evaluate import mueller_at
    from polar_render.engine.spectral import ConstantSpectrum
    empty_scene()
    opaque, _, w1 = exported(principled(**{"Roughness": 0.0, "IOR": ior, "Base Color": (0, 0, 0, 1)}))
    clear, _, w2 = exported(principled(**{"Roughness": 0.0, "IOR": ior, "Transmission Weight": 1.0,
                                          "Base Color": (1, 1, 1, 1)}))
    assert not w1 and not w2
    ior = float(np.float32(ior))          # what the socket holds
    brewster = math.degrees(math.atan(ior))
    for theta in (0.0, 30.0, brewster, 75.0, 89.0):
        for basis in ("sp", "scattering"):
            for got, model in ((opaque, BlackGlass(ConstantSpectrum(ior))), (clear, SmoothDielectric(ior))):
                a = np.array(mueller_at(got, theta, theta, 0.0, basis=basis)["delta"])
                b = np.array(mueller_at(model, theta, theta, 0.0, basis=basis)["delta"])
                np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
    M = np.array(mueller_at(opaque, brewster, brewster, 0.0, basis="sp")["delta"])
    assert abs(M[1, 0] / M[0, 0]) == pytest.approx(1.0, abs=1e-9)       # DoLP 1 for unpolarised light


def test_mix_and_add_shaders_become_an_engine_mixture(addon):
    empty_scene()
    mat = bpy.data.materials.new("Mixed")
    tree = mat.node_tree
    out = tree.get_output_node("ALL")
    diffuse = _shader(tree, "ShaderNodeBsdfDiffuse", Color=(0.5, 0.5, 0.5, 1))
    glossy = _shader(tree, "ShaderNodeBsdfGlossy", Roughness=0.0)
    emit = _shader(tree, "ShaderNodeEmission", Strength=4.0, Color=(1, 0.5, 0.25, 1))
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = 0.3
    tree.links.new(diffuse.outputs[0], mix.inputs[1])
    tree.links.new(glossy.outputs[0], mix.inputs[2])
    add = tree.nodes.new("ShaderNodeAddShader")
    tree.links.new(mix.outputs[0], add.inputs[0])
    tree.links.new(emit.outputs[0], add.inputs[1])
    tree.links.new(add.outputs[0], out.inputs["Surface"])
    bsdf, emission, warnings = exported(mat)
    assert not warnings
    assert bsdf.name == "mix"
    # the emission adds with weight 1; the mixed BSDFs keep 0.7 and 0.3 (nested or flattened)
    assert emission.linear_srgb() == pytest.approx([4.0, 2.0, 1.0], rel=2e-3)

    def leaves(b, w=1.0):
        if b.name != "mix":
            return [(b.name, w)]
        return [x for c, cw in zip(b.components, b.weights) for x in leaves(c, w * float(cw))]
    found = dict(leaves(bsdf))
    assert found["lambert"] == pytest.approx(0.7) and found["conductor"] == pytest.approx(0.3)
    # Factor 1 keeps the second shader only; an unlinked shader input adds nothing.
    mix.inputs[0].default_value = 1.0
    assert exported(mat)[0].name in ("conductor", "mix")
    tree.links.remove(add.inputs[1].links[0])
    mix.inputs[0].default_value = 0.0
    assert exported(mat)[0].name == "lambert"


def test_transparent_mixes_become_pass_through_alpha(addon):
    """Mix Shader(Transparent, X, Factor f): X with alpha f (the object's pass-through); a Transparent BSDF
    alone: alpha 0; Mix(Transparent, X) by Light Path ▸ Is Camera Ray (glTF unlit): X seen by the camera
    only (the exporter hides the object from shadow and indirect rays)."""
    empty_scene()
    mat = bpy.data.materials.new("Veil")
    tree = mat.node_tree
    out = tree.get_output_node("ALL")
    clear = _shader(tree, "ShaderNodeBsdfTransparent")
    diffuse = _shader(tree, "ShaderNodeBsdfDiffuse", Color=(0.5, 0.5, 0.5, 1))
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = 0.3
    tree.links.new(clear.outputs[0], mix.inputs[1])
    tree.links.new(diffuse.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], out.inputs["Surface"])
    bsdf, _, warnings = exported(mat)
    assert bsdf.name == "lambert" and bsdf.alpha_factor == pytest.approx(0.3) and not warnings
    tree.links.new(clear.outputs[0], out.inputs["Surface"])
    bsdf, _, _ = exported(mat)
    assert bsdf.alpha_factor == 0.0
    path = tree.nodes.new("ShaderNodeLightPath")
    tree.links.new(path.outputs["Is Camera Ray"], mix.inputs[0])
    tree.links.new(mix.outputs[0], out.inputs["Surface"])
    bsdf, _, warnings = exported(mat)
    assert bsdf.name == "lambert" and bsdf.camera_only and not hasattr(bsdf, "alpha_factor") and not warnings


def test_separate_color_of_an_image_is_read_natively(addon, tmp_path):
    """glTF's occlusion-roughness-metallic map: Metallic from the image's blue channel, per point."""
    empty_scene()
    img = bpy.data.images.new("orm", 2, 1, alpha=False)
    img.colorspace_settings.name = "Non-Color"      # first: changing it regenerates a generated image's pixels
    img.pixels = [1.0, 0.5, 0.0, 1.0, 1.0, 0.5, 1.0, 1.0]        # metallic 0 left, 1 right
    mat = principled(**{"Roughness": 0.0})
    tree = mat.node_tree
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    sep = tree.nodes.new("ShaderNodeSeparateColor")
    tree.links.new(tex.outputs["Color"], sep.inputs[0])
    tree.links.new(sep.outputs["Blue"], tree.nodes["Principled BSDF"].inputs["Metallic"])
    bsdf, _, warnings = exported(mat)
    assert not warnings
    assert bsdf.name == "mix" and bsdf.varies_over_surface
    metallic = bsdf.weights[-1]                     # the metal's weight: the blue channel, 0 and 1
    assert (metallic.lo, metallic.hi) == (0.0, 1.0)


def test_emission_colour_from_an_image_varies_over_the_surface(addon):
    """glTF's emissive texture: Principled Emission Color from an Image Texture × Emission Strength."""
    from polar_render.engine.textures.inputs import TexturedSpectrum
    empty_scene()
    img = bpy.data.images.new("glow", 2, 1, alpha=False, float_buffer=True)
    img.pixels = [2.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    mat = principled(**{"Emission Strength": 3.0})
    tree = mat.node_tree
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Emission Color"])
    _, emission, warnings = exported(mat)
    assert not warnings
    assert isinstance(emission, TexturedSpectrum) and emission.kind == "illuminant"
    assert (emission.lo, emission.hi) == pytest.approx((0.0, 6.0))
    # through a Mix Shader with factor 0.25 on the emitting side: scaled by the weight
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = 0.25
    tree.links.new(tree.nodes["Principled BSDF"].outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], tree.get_output_node("ALL").inputs["Surface"])
    _, emission, _ = exported(mat)
    assert emission.hi == pytest.approx(1.5)


def test_volume_absorption_becomes_the_absorbing_interior(addon):
    """Material Output ▸ Volume: Volume Absorption σ = ρ(1 − Color) (what glTF's KHR_materials_volume
    becomes), Principled Volume's absorption, a mix of them; Principled Volume's scattering is now rendered
    (tests/blender/test_volumes.py): σ_s = ρ·Color with its Henyey–Greenstein, no warning."""
    empty_scene()
    mat = principled(**{"Transmission Weight": 1.0, "Roughness": 0.0})
    tree = mat.node_tree
    vol = tree.nodes.new("ShaderNodeVolumeAbsorption")
    vol.inputs["Color"].default_value = (0.2, 0.5, 1.0, 1.0)
    vol.inputs["Density"].default_value = 2.0
    tree.links.new(vol.outputs[0], tree.get_output_node("ALL").inputs["Volume"])
    bsdf, _, warnings = exported(mat)
    assert not warnings
    assert bsdf.interior.absorption.linear_srgb() == pytest.approx([1.6, 1.0, 0.0])
    pv = tree.nodes.new("ShaderNodeVolumePrincipled")
    pv.inputs["Density"].default_value = 1.0
    pv.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1.0)
    pv.inputs["Absorption Color"].default_value = (0.25, 0.25, 0.25, 1.0)
    add = tree.nodes.new("ShaderNodeAddShader")
    tree.links.new(vol.outputs[0], add.inputs[0])
    tree.links.new(pv.outputs[0], add.inputs[1])
    tree.links.new(add.outputs[0], tree.get_output_node("ALL").inputs["Volume"])
    bsdf, _, warnings = exported(mat)
    assert bsdf.interior.absorption.linear_srgb() == pytest.approx([1.6 + 0.25, 1.0 + 0.25, 0.25])
    assert bsdf.interior.scattering.linear_srgb() == pytest.approx([0.5, 0.5, 0.5], rel=1e-3)
    assert bsdf.interior.phase.name == "henyey_greenstein" and not warnings


def test_layered_node_uses_the_linked_base(addon):
    empty_scene()
    mat = polar_material("Coated", "WEIDLICH_WILKIE", **{"Coat IOR": 1.5, "Coat Roughness": 0.1})
    base = mat.node_tree.nodes.new("PolarShaderNodeBSDF")
    base.model = "TORRANCE_SPARROW"
    base.metal = "Cu"
    mat.node_tree.links.new(base.outputs[0], mat.node_tree.nodes["Polarising BSDF"].inputs["Base"])
    bsdf, _, _ = exported(mat)
    assert bsdf.name == "weidlich_wilkie" and bsdf.base.name == "torrance_sparrow"
    # A rough coat over a perfect mirror has no BRDF value in WW: a clear error naming the material.
    base.model = "CONDUCTOR"
    from polar_render.engine.errors import SceneError
    with pytest.raises(SceneError, match="Coated"):
        exported(mat)


def test_standard_shaders_convert(addon):
    empty_scene()

    def with_shader(kind, **inputs):
        mat = bpy.data.materials.new(kind)
        tree = mat.node_tree
        node = tree.nodes.new(kind)
        for k, v in inputs.items():
            node.inputs[k].default_value = v
        tree.links.new(node.outputs[0], tree.get_output_node("ALL").inputs["Surface"])
        return mat

    assert exported(with_shader("ShaderNodeBsdfDiffuse", Color=(0.5, 0.5, 0.5, 1)))[0].name == "lambert"
    rough = exported(with_shader("ShaderNodeBsdfDiffuse", Color=(0.5, 0.5, 0.5, 1), Roughness=0.6))[0]
    assert rough.name == "oren_nayar" and rough.roughness == pytest.approx(0.6)        # Cycles' Oren–Nayar
    assert exported(with_shader("ShaderNodeBsdfGlass", IOR=1.45, Roughness=0.0))[0].n_int == pytest.approx(1.45)
    assert exported(with_shader("ShaderNodeBsdfGlossy", Roughness=0.0))[0].name == "conductor"
    bsdf, emission, _ = exported(with_shader("ShaderNodeEmission", Strength=2.0))
    assert emission is not None and bsdf.name == "lambert"


def test_light_units_match_cycles(addon):
    from polar_render.polar_addon.export.lights import export_light
    empty_scene()
    lam = np.array([[550.0]])
    for kind, energy in (("POINT", 100.0), ("SPOT", 100.0), ("SUN", 3.0), ("AREA", 50.0)):
        bpy.ops.object.light_add(type=kind, location=(0, 0, 2))
        obj = bpy.context.object
        obj.data.energy = energy
        if kind == "AREA":
            obj.data.size = 0.5
        warnings = []
        light = export_light(obj, obj.matrix_world, warnings)
        if kind in ("POINT", "SPOT"):
            assert light.intensity.eval(lam, mono=True)[0, 0] == pytest.approx(energy / (4 * math.pi))
        elif kind == "SUN":
            assert light.irradiance.eval(lam, mono=True)[0, 0] == pytest.approx(energy)
            np.testing.assert_allclose(light.direction, [0, 0, -1], atol=1e-12)
        else:
            # Blender ≥ 4.0: L = P/(π·A) (kernel/light/area.h, eval_fac = invarea/π)
            assert light.emission.eval(lam, mono=True)[0, 0] == pytest.approx(energy / (math.pi * 0.25))
            assert not light.occluder and not light.two_sided
            v = light.vertices
            normal = np.cross(v[light.faces[0, 1]] - v[light.faces[0, 0]], v[light.faces[0, 2]] - v[light.faces[0, 0]])
            assert normal[2] < 0                                   # emits downwards (local −Z)


def test_viewport_sync_logic(addon):
    from polar_render.polar_addon.viewport import ViewportSync, camera_from_view, viewport_resolution
    assert viewport_resolution(1920, 1080) == (320, 180)        # one pass stays ≤ 65536 samples
    assert viewport_resolution(200, 100) == (200, 100)
    sync = ViewportSync(target_samples=3)
    assert sync.needs_export
    sync.needs_export = False
    view = np.eye(4)
    proj = np.diag([2.0, 2.0, -1.0, 0.0])
    assert sync.on_view(view, proj, (100, 80)) is True
    sync.add_samples(3)
    assert sync.done()
    assert sync.on_view(view, proj, (100, 80)) is False and sync.done()
    assert sync.on_updates([("OBJECT", False, False, False)]) is False     # selection only
    assert sync.done() and not sync.needs_export
    assert sync.on_updates([("OBJECT", False, True, False)]) is True       # moved an object
    assert sync.needs_export and sync.samples == 0
    sync.needs_export = False
    assert sync.on_updates([("MATERIAL", False, False, True)]) is True
    assert sync.on_view(view, proj, (120, 80)) is True                      # resize restarts
    cam = camera_from_view(view, proj, 100, 80, True)
    assert cam.fov_deg == pytest.approx(2 * math.degrees(math.atan(0.5)))
    np.testing.assert_allclose(cam.target - cam.origin, [0, 0, -1])


def test_use_polarising_bsdf_operator_replaces_the_surface_shader(addon):
    empty_scene()
    mat = bpy.data.materials.new("Plain")                     # a default Principled material
    with bpy.context.temp_override(material=mat):
        assert bpy.ops.polar.add_polarising_bsdf(model="CONDUCTOR") == {"FINISHED"}
    surface = mat.node_tree.get_output_node("ALL").inputs["Surface"].links[0].from_node
    assert surface.bl_idname == "PolarShaderNodeBSDF" and surface.model == "CONDUCTOR"
    bsdf, _, _ = exported(mat)
    assert bsdf.name == "conductor"
