"""Cycles parity of the Principled BSDF, one input at a time, each varying over the surface.

A UV sphere with a Principled BSDF whose one input under test is driven by a 4 × 4 checker image (two
values of that input), lit by the asset suite's HDRI sky and, separately, its lamps
(tests/support/asset_parity.py), rendered by Cycles and by Polar at equal samples; the asset rule per
16 × 16 block (Polar's S0 luminance within 4 σ + 2 % of Cycles' in ≥ 95 % of the sphere's blocks).
Inputs Polar does not simulate yet (docs/guide/blender.md, "Principled BSDF, input by input") are not
listed here: the table there says what they become.
"""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import load_addon  # noqa: E402
from tests.support import asset_parity as ap  # noqa: E402

SIZE = 64
SPP = 16
SEEDS = 4

#: input → (its two checker values, the other inputs' values)
CASES = {
    "Base Color": (((0.8, 0.1, 0.05), (0.1, 0.3, 0.8)), {"Roughness": 0.4}),
    "Base Color ": (((0.8, 0.1, 0.05), (0.9, 0.9, 0.9)), {"Roughness": 0.4, "Diffuse Roughness": 1.0}),  # Oren–Nayar
    "Metallic": ((0.0, 1.0), {"Base Color": (0.9, 0.6, 0.3), "Roughness": 0.35}),
    "Roughness": ((0.15, 0.9), {"Metallic": 1.0, "Base Color": (0.8, 0.8, 0.8)}),
    "Roughness ": ((0.05, 0.7), {"Base Color": (0.3, 0.5, 0.2)}),          # the dielectric's
    "Transmission Weight": ((0.0, 1.0), {"Roughness": 0.3, "Base Color": (0.9, 0.9, 0.9)}),
    "Emission Color": (((2.0, 0.5, 0.1), (0.0, 0.0, 0.0)), {"Emission Strength": 1.5}),
    "Emission Strength": ((0.5, 3.0), {"Emission Color": (1.0, 0.5, 0.2), "Base Color": (0.2, 0.2, 0.2)}),
    "Alpha": ((0.0, 1.0), {"Base Color": (0.8, 0.2, 0.1), "Roughness": 0.5}),        # a cut-out
    "Metallic ": ((0.0, 1.0), {"Base Color": (0.8, 0.2, 0.1), "Roughness": 0.4,     # under a clear coat
                               "Coat Weight": 1.0, "Coat Roughness": 0.1}),
    "Base Color  ": (((0.8, 0.1, 0.05), (0.1, 0.3, 0.8)), {"Roughness": 0.2,          # a Specular Tint
                                                            "Specular Tint": (1.0, 0.5, 0.2)}),
    "Base Color   ": (((0.95, 0.95, 0.95), (0.9, 0.7, 0.5)), {"Transmission Weight": 1.0, "Roughness": 0.15,
                                                              "Specular Tint": (1.0, 0.4, 0.1)}),  # a tinted glass
    "Base Color    ": (((0.95, 0.95, 0.95), (0.6, 0.8, 0.9)), {"Transmission Weight": 1.0, "Roughness": 0.0,
                                                               "IOR": 1.8, "Specular Tint": (0.2, 0.5, 1.0)}),
    "Base Color     ": (((0.6, 0.2, 0.1), (0.1, 0.2, 0.5)), {"Roughness": 0.5, "Sheen Weight": 1.0,  # a sheen
                                                             "Sheen Roughness": 0.4, "Sheen Tint": (1.0, 0.7, 0.5)}),
    "Base Color      ": (((0.9, 0.6, 0.3), (0.7, 0.7, 0.7)), {"Roughness": 0.3, "Metallic": 1.0,  # sheen, coat
                                                              "Sheen Weight": 0.7, "Sheen Roughness": 0.2,
                                                              "Coat Weight": 0.5}),
    "Coat Weight": ((0.0, 1.0), {"Base Color": (0.6, 0.2, 0.1), "Roughness": 0.5, "Coat Roughness": 0.05}),
    "Sheen Weight": ((0.0, 1.0), {"Base Color": (0.1, 0.2, 0.5), "Roughness": 0.5, "Sheen Roughness": 0.3}),
    "Sheen Tint": (((1.0, 0.5, 0.2), (0.2, 0.6, 1.0)), {"Base Color": (0.3, 0.3, 0.3), "Roughness": 0.5,
                                                      "Sheen Weight": 1.0, "Sheen Roughness": 0.5}),
    "Normal": (((0.5, 0.5, 1.0), (0.85, 0.6, 0.75)), {"Base Color": (0.6, 0.3, 0.2), "Roughness": 0.3}),
    "Normal ": (((0.5, 0.5, 1.0), (0.85, 0.6, 0.75)), {"Base Color": (0.9, 0.9, 0.9), "Roughness": 0.1,  # metal
                                                       "Metallic": 1.0}),
    "Coat Normal": (((0.5, 0.5, 1.0), (0.85, 0.6, 0.75)), {"Base Color": (0.2, 0.2, 0.2), "Roughness": 0.6,
                                                          "Coat Weight": 1.0, "Coat Roughness": 0.1}),
    "Specular Tint": (((1.0, 0.4, 0.1), (0.2, 0.5, 1.0)), {"Base Color": (0.1, 0.1, 0.1), "Roughness": 0.25}),
    "Specular Tint ": (((1.0, 0.5, 0.2), (0.9, 0.9, 0.9)), {"Base Color": (0.9, 0.8, 0.7), "Roughness": 0.3,  # metal
                                                           "Metallic": 1.0}),
    "Specular Tint  ": (((1.0, 0.4, 0.1), (0.3, 0.6, 1.0)), {"Base Color": (0.9, 0.9, 0.9), "Roughness": 0.15,
                                                            "Transmission Weight": 1.0}),         # a glass
    "Specular IOR Level": ((0.1, 1.0), {"Base Color": (0.05, 0.05, 0.05), "Roughness": 0.3}),
    "Specular IOR Level ": ((0.0, 0.8), {"Base Color": (0.3, 0.1, 0.05), "Roughness": 0.0}),        # smooth
    "Specular IOR Level  ": ((0.2, 0.9), {"Base Color": (0.3, 0.3, 0.6), "Roughness": 0.4,           # Oren–Nayar
                                          "Diffuse Roughness": 0.8}),
    "Diffuse Roughness": ((0.0, 1.0), {"Base Color": (0.8, 0.5, 0.3), "Roughness": 0.5}),
    "Coat IOR": ((1.1, 2.2), {"Base Color": (0.4, 0.1, 0.05), "Roughness": 0.5, "Coat Weight": 1.0,
                              "Coat Roughness": 0.1}),
    "Coat IOR ": ((1.2, 2.0), {"Base Color": (0.8, 0.8, 0.8), "Roughness": 0.3, "Metallic": 1.0,   # smooth, tinted
                               "Coat Weight": 0.8, "Coat Roughness": 0.0, "Coat Tint": (1.0, 0.5, 0.2)}),
    "IOR": ((1.2, 2.4), {"Base Color": (0.05, 0.05, 0.05), "Roughness": 0.3}),
    "IOR ": ((1.1, 1.9), {"Base Color": (0.4, 0.2, 0.1), "Roughness": 0.0}),                       # smooth
    "Coat Roughness": ((0.02, 0.6), {"Base Color": (0.5, 0.1, 0.1), "Roughness": 0.4, "Coat Weight": 1.0}),
    "Coat Roughness ": ((0.0, 0.35), {"Base Color": (0.9, 0.8, 0.6), "Roughness": 0.2, "Metallic": 1.0,  # metal
                                      "Coat Weight": 0.7, "Coat IOR": 1.6}),
    "Sheen Roughness": ((0.15, 0.8), {"Base Color": (0.1, 0.2, 0.5), "Roughness": 0.5, "Sheen Weight": 1.0,
                                      "Sheen Tint": (1.0, 0.8, 0.6)}),
    "Coat Tint": (((1.0, 0.4, 0.1), (0.2, 0.5, 1.0)), {"Base Color": (0.8, 0.8, 0.8), "Roughness": 0.4,
                                                       "Coat Weight": 0.8, "Coat Roughness": 0.05, "Metallic": 0.0}),
    "Coat Tint ": (((1.0, 0.4, 0.1), (0.6, 0.6, 0.6)), {"Base Color": (0.9, 0.7, 0.5), "Roughness": 0.3,  # metal
                                                        "Metallic": 1.0, "Coat Weight": 1.0, "Coat IOR": 1.8}),
}


def checker(name, a, b, colour, data=False):
    """A 4 × 4 checker image of values a and b (colours or numbers), Non-Color for numbers and ``data``."""
    img = bpy.data.images.new(name, 4, 4, alpha=False, float_buffer=True)
    if not colour or data:  # before the pixels: changing it regenerates a generated image's buffer
        img.colorspace_settings.name = "Non-Color"
    a, b = (tuple(v) if colour else (v, v, v) for v in (a, b))
    px = []
    for j in range(4):
        for i in range(4):
            px += list(a if (i + j) % 2 == 0 else b) + [1.0]
    img.pixels = px
    img.pack()              # Cycles reads the packed pixels
    return img


def sphere_scene(socket, values, others, lighting):
    from mathutils import Vector
    scene = ap.reset(SIZE, SIZE)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=48, ring_count=24)
    obj = bpy.context.object
    bpy.ops.object.shade_smooth()
    mat = bpy.data.materials.new("P")
    load_addon().polar_addon.compat.ensure_node_tree(mat)
    p = mat.node_tree.nodes["Principled BSDF"]
    for k, v in others.items():
        p.inputs[k].default_value = (*v, 1.0) if isinstance(v, tuple) else v
    name = socket.strip()
    colour = p.inputs[name].type == "RGBA"
    normal = p.inputs[name].type == "VECTOR"        # a normal: the checker through a tangent-space Normal Map
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = checker("checker", *values, colour or normal, data=normal)
    tex.interpolation = "Closest"
    if normal:
        nmap = mat.node_tree.nodes.new("ShaderNodeNormalMap")
        mat.node_tree.links.new(tex.outputs["Color"], nmap.inputs["Color"])
        mat.node_tree.links.new(nmap.outputs["Normal"], p.inputs[name])
    else:
        mat.node_tree.links.new(tex.outputs["Color"], p.inputs[name])
    obj.data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location = Vector((0.0, -5.0, 1.5))
    cam.rotation_euler = (Vector((0, 0, 0)) - cam.location).to_track_quat("-Z", "Y").to_euler()
    cam.data.lens = 65
    scene.camera = cam
    if lighting == "lamps":
        ap.light_lamps(scene, np.zeros(3), 1.0)
    else:
        ap.light_hdri(scene)
    return scene


def compare_with_cycles(scene, name, lighting, spectral="RGB", seeds=SEEDS):
    """Render ``scene`` with Cycles and Polar at SPP × ``seeds`` and assert the asset rule with no warnings."""
    import tempfile
    report = ap.CaseReport(name, lighting, SPP, seeds, SIZE, SIZE)
    hit = ap.coverage(scene, SIZE, SIZE)
    with tempfile.TemporaryDirectory() as tmp:
        cyc = ap.render_cycles(scene, SPP, seeds, 8, tmp)
    renderer, settings, report.warnings = ap.export_polar(scene, SPP, 8, spectral=spectral)
    stokes = ap.render_polar(renderer, settings, seeds)
    ap.compare(cyc, stokes[:, 0], hit, report)
    print(report.line())
    assert not report.warnings, report.warnings
    assert report.blocks >= 8
    assert report.ok, (f"{report.line()}\nfailing blocks (row, column, Polar ÷ Cycles, tolerance): "
                       f"{[(i, j, round(r, 3), round(t, 3)) for i, j, r, t in report.failing]}")


@pytest.fixture(scope="module")
def addon():
    return load_addon()


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
@pytest.mark.parametrize("socket", list(CASES))
def test_principled_input_per_point_matches_cycles(addon, socket, lighting):
    values, others = CASES[socket]
    compare_with_cycles(sphere_scene(socket, values, others, lighting), f"Principled {socket.strip()}", lighting,
                        seeds=CASE_SEEDS.get((socket, lighting), SEEDS))


#: cases judged on more seeds: with 4 (σ from 3 degrees of freedom) one block of 12 failed by chance after the first
#: vertex's numbers changed (2026-12-07, "sobol" drawing Cycles' light and BSDF sets; block 1.071 against a
#: tolerance of 0.068); 12/12 at 8 and at 16 seeds
CASE_SEEDS = {("Coat Tint ", "lamps"): 8}


#: a constant Thin Film over a Base Color checker: rough metal and rough dielectric (Cycles' iridescence on
#: every Fresnel); compared in the spectral mode, since Cycles integrates the film's spectrum per RGB channel
#: where the RGB mode evaluates one wavelength per channel (measured there: green +5 % on the dielectric)
FILMS = {
    "metal": {"Roughness": 0.3, "Metallic": 1.0, "Thin Film IOR": 1.5, "Thin Film Thickness": 400.0},
    "dielectric": {"Roughness": 0.3, "Thin Film IOR": 2.0, "Thin Film Thickness": 400.0},
    "smooth metal": {"Roughness": 0.0, "Metallic": 1.0, "Thin Film IOR": 1.5, "Thin Film Thickness": 400.0},
    "smooth dielectric": {"Roughness": 0.0, "Thin Film IOR": 2.0, "Thin Film Thickness": 400.0},
}


#: (a smooth metal mirroring the HDRI in the spectral mode is 3.6 % dark against Cycles without any film — Y 0.964,
#: the spectral products of a mirror and the sky, within its large chromatic noise; with the film Y 0.956, 12/12)
#: (the film on the smooth dielectric under the lamps read R +4 % in two blocks, z ≈ 55, with either light choice:
#: the base under the film was weighted by single wavelengths' reflectance instead of the film's channel averages,
#: fixed in c46c48a — docs/physics.md, thin films; now R 1.012, 12/12)
FILM_CASES = [(part, lighting) for part in FILMS for lighting in ap.LIGHTINGS]


@pytest.mark.parametrize("part, lighting", FILM_CASES)
def test_thin_film_on_metal_and_specular_layers_matches_cycles(addon, part, lighting):
    colours = ((0.9, 0.6, 0.3), (0.8, 0.8, 0.8)) if "metal" in part else ((0.2, 0.2, 0.2), (0.05, 0.05, 0.05))
    compare_with_cycles(sphere_scene("Base Color", colours, FILMS[part], lighting), f"Thin film on {part}", lighting,
                        spectral="SPECTRAL")


#: Anisotropic GGX (constant Anisotropic, a Base Color checker) along a Tangent node's UV tangent
ANISOTROPIC = {
    "metal": {"Roughness": 0.4, "Metallic": 1.0, "Anisotropic": 0.8},
    "metal, rotated": {"Roughness": 0.4, "Metallic": 1.0, "Anisotropic": 0.8, "Anisotropic Rotation": 0.25},
    "dielectric": {"Roughness": 0.35, "Anisotropic": 1.0},
}


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
@pytest.mark.parametrize("part", list(ANISOTROPIC))
def test_anisotropic_ggx_matches_cycles(addon, part, lighting):
    colours = ((0.9, 0.6, 0.3), (0.8, 0.8, 0.8)) if "metal" in part else ((0.6, 0.2, 0.1), (0.1, 0.3, 0.6))
    scene = sphere_scene("Base Color", colours, ANISOTROPIC[part], lighting)
    mat = bpy.data.materials["P"]
    tangent = mat.node_tree.nodes.new("ShaderNodeTangent")
    tangent.direction_type = "UV_MAP"
    mat.node_tree.links.new(tangent.outputs["Tangent"], mat.node_tree.nodes["Principled BSDF"].inputs["Tangent"])
    compare_with_cycles(scene, f"Anisotropic {part}", lighting)


def test_anisotropy_without_a_tangent_node_says_which_tangent_it_takes(addon):
    """Tangent unlinked: Cycles' radial tangent about the object's Z becomes the UV map's (one warning naming
    both); a textured Roughness keeps the lobe anisotropic (that one warning only)."""
    scene = sphere_scene("Base Color", ((0.9, 0.6, 0.3), (0.8, 0.8, 0.8)),
                         {"Roughness": 0.4, "Metallic": 1.0, "Anisotropic": 0.8}, "lamps")
    _, _, warnings = ap.export_polar(scene, 1, 8)
    assert len(warnings) == 1 and "radial tangent about the object's Z" in warnings[0] and "UV map" in warnings[0]
    scene = sphere_scene("Roughness", (0.2, 0.6), {"Metallic": 1.0, "Anisotropic": 0.8}, "lamps")
    _, _, warnings = ap.export_polar(scene, 1, 8)
    assert len(warnings) == 1 and "radial tangent about the object's Z" in warnings[0]


def test_sheen_bsdf_node_exports_the_sheen_model_and_names_ashikhmin(addon):
    """The Sheen BSDF node becomes the engine's ``sheen`` (Microfiber, Cycles' default) with its Color and
    Roughness; the older Ashikhmin distribution is rendered as Microfiber with one warning."""
    from polar_render.polar_addon.export.materials import export_material
    mat = bpy.data.materials.new("Velvet")
    addon.polar_addon.compat.ensure_node_tree(mat)
    tree = mat.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    sheen = tree.nodes.new("ShaderNodeBsdfSheen")
    sheen.inputs["Color"].default_value = (0.9, 0.3, 0.2, 1.0)
    sheen.inputs["Roughness"].default_value = 0.3
    tree.links.new(sheen.outputs["BSDF"], tree.nodes["Material Output"].inputs["Surface"])
    warnings = []
    bsdf, _ = export_material(mat, warnings)
    assert warnings == [] and bsdf.name == "sheen" and bsdf.roughness == pytest.approx(0.3)
    assert list(bsdf.tint.linear_srgb()) == pytest.approx([0.9, 0.3, 0.2])
    sheen.distribution = "ASHIKHMIN"
    export_material(mat, warnings)
    assert len(warnings) == 1 and "Ashikhmin" in warnings[0] and "Microfiber" in warnings[0]


#: Cycles' metal nodes: the colour checker into ``socket`` of ``node`` (its other inputs ``others``; ``tangent``: a
#: Tangent node on the UV map), replacing the Principled BSDF at the output.  Their reflectance is Cycles' curve at
#: every angle (the Glossy colour at every angle; the Metallic F82-Tint), their polarisation Gulbrandsen's metal
METAL_NODES = {
    "Glossy, dark": ("ShaderNodeBsdfGlossy", "Color", ((0.05, 0.05, 0.05), (0.3, 0.1, 0.05)), {"Roughness": 0.3}),
    "Glossy, anisotropic": ("ShaderNodeBsdfGlossy", "Color", ((0.9, 0.6, 0.3), (0.8, 0.8, 0.8)),
                            {"Roughness": 0.45, "Anisotropy": 0.6, "tangent": True}),
    "Glossy, anisotropic < 0": ("ShaderNodeBsdfGlossy", "Color", ((0.9, 0.6, 0.3), (0.8, 0.8, 0.8)),
                                {"Roughness": 0.45, "Anisotropy": -0.5, "Rotation": 0.1, "tangent": True}),
    "Metallic F82": ("ShaderNodeBsdfMetallic", "Base Color", ((0.9, 0.6, 0.3), (0.6, 0.6, 0.6)),
                     {"Roughness": 0.3, "Edge Tint": (0.3, 0.5, 1.0)}),
    "Metallic F82, Edge Tint": ("ShaderNodeBsdfMetallic", "Edge Tint", ((1.0, 0.4, 0.1), (0.3, 0.6, 1.0)),
                                {"Roughness": 0.25, "Base Color": (0.8, 0.8, 0.8)}),
    "Metallic, anisotropic": ("ShaderNodeBsdfMetallic", "Base Color", ((0.9, 0.6, 0.3), (0.8, 0.8, 0.8)),
                              {"Roughness": 0.4, "Anisotropy": 0.8, "tangent": True}),
    "Metallic F82, thin film": ("ShaderNodeBsdfMetallic", "Base Color", ((0.9, 0.6, 0.3), (0.8, 0.8, 0.8)),
                                {"Roughness": 0.3, "Thin Film IOR": 1.5, "Thin Film Thickness": 400.0}),
}


def node_scene(kind, socket, colours, others, lighting):
    """The checker sphere with the shader node ``kind`` at the output in place of the Principled BSDF: the checker
    (``colours``) into its ``socket``, its other inputs ``others`` (``"tangent"``: a Tangent node on the UV map)."""
    scene = sphere_scene("Base Color", colours, {}, lighting)
    tree = bpy.data.materials["P"].node_tree
    node = tree.nodes.new(kind)
    if hasattr(node, "distribution"):
        node.distribution = "MULTI_GGX"
    for k, v in others.items():
        if k == "tangent":
            tangent = tree.nodes.new("ShaderNodeTangent")
            tangent.direction_type = "UV_MAP"
            tree.links.new(tangent.outputs["Tangent"], node.inputs["Tangent"])
        else:
            node.inputs[k].default_value = (*v, 1.0) if isinstance(v, tuple) else v
    tree.links.new(tree.nodes["Image Texture"].outputs["Color"], node.inputs[socket])
    tree.links.new(node.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    return scene


def metal_node_scene(case, lighting):
    return node_scene(*METAL_NODES[case], lighting)


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
@pytest.mark.parametrize("case", list(METAL_NODES))
def test_glossy_and_metallic_nodes_match_cycles(addon, case, lighting):
    # a film in the spectral mode, as the Principled films above
    compare_with_cycles(metal_node_scene(case, lighting), case, lighting,
                        spectral="SPECTRAL" if "film" in case else "RGB")


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
def test_metallic_node_film_on_a_mirror_matches_cycles(addon, lighting):
    scene = metal_node_scene("Metallic F82, thin film", lighting)
    bpy.data.materials["P"].node_tree.nodes["Metallic BSDF"].inputs["Roughness"].default_value = 0.0
    compare_with_cycles(scene, "Metallic F82, smooth, thin film", lighting, spectral="SPECTRAL")


def test_beckmann_anisotropy_is_named(addon):
    """What the metal nodes do not simulate is named once: anisotropy with Beckmann facets."""
    scene = metal_node_scene("Glossy, anisotropic", "lamps")
    bpy.data.materials["P"].node_tree.nodes["Glossy BSDF"].distribution = "BECKMANN"
    _, _, warnings = ap.export_polar(scene, 1, 8)
    assert len(warnings) == 1 and "GGX only" in warnings[0]


#: an emitting Principled BSDF under its coat and sheen: Cycles attenuates the emission by both layers' albedo at the
#: view angle (engine.materials.mix.emission_weight); an Emission Color checker
EMISSIVE_LAYERS = {
    "coat": {"Base Color": (0.1, 0.1, 0.1), "Roughness": 0.5, "Coat Weight": 1.0, "Coat Roughness": 0.05,
             "Coat IOR": 1.9, "Emission Strength": 2.0},
    "sheen": {"Base Color": (0.1, 0.1, 0.1), "Roughness": 0.5, "Sheen Weight": 1.0, "Sheen Roughness": 0.3,
              "Emission Strength": 2.0},
    "sheen and coat": {"Base Color": (0.1, 0.1, 0.1), "Roughness": 0.5, "Sheen Weight": 0.8, "Sheen Roughness": 0.5,
                       "Coat Weight": 0.7, "Coat Roughness": 0.2, "Emission Strength": 2.0},
}


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
@pytest.mark.parametrize("layers", list(EMISSIVE_LAYERS))
def test_emission_under_coat_and_sheen_matches_cycles(addon, layers, lighting):
    scene = sphere_scene("Emission Color", ((1.0, 0.5, 0.2), (0.2, 0.6, 1.0)), EMISSIVE_LAYERS[layers], lighting)
    compare_with_cycles(scene, f"Emission under {layers}", lighting)


#: the film's inputs per point (glTF's iridescence thickness map): a checker of two values of one input on a rough
#: metal and a rough dielectric (the spectral mode, as the constant films above).  (Thin Film IOR 1.3 | 2.2 on the
#: dielectric under the HDRI: 11/12 blocks, Y 0.999, one block at 0.963 against a tolerance of 0.035; each constant
#: index alone 12/12 — the docs say so.)
FILM_INPUTS = {"Thin Film Thickness": (250.0, 600.0), "Thin Film IOR": (1.4, 2.0)}


#: a measured gap, not noise: Thin Film IOR 1.4 | 2.0 on the rough metal under the lamps reads Y 0.983–0.988 with one
#: block at 0.97 at 4 and at 16 seeds, with the first sobol and the current one alike (each constant index alone
#: passes); docs/physics.md, "Cycles' white is equal-energy".
FILM_GAPS = {("Thin Film IOR", "metal", "lamps")}


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
@pytest.mark.parametrize("part", ["metal", "dielectric"])
@pytest.mark.parametrize("socket", list(FILM_INPUTS))
def test_thin_film_inputs_per_point_match_cycles(addon, socket, part, lighting, request):
    if (socket, part, lighting) in FILM_GAPS:
        request.applymarker(pytest.mark.xfail(reason="measured gap: Y 0.983–0.988, one block 0.97 (FILM_GAPS)",
                                              strict=False))
    others = dict(FILMS[part])
    others.pop(socket)
    others["Base Color"] = (0.9, 0.6, 0.3) if part == "metal" else (0.1, 0.1, 0.1)
    scene = sphere_scene(socket, FILM_INPUTS[socket], others, lighting)
    compare_with_cycles(scene, f"{socket} on {part}", lighting, spectral="SPECTRAL")


#: the dielectric's index per point beside a Specular Tint or an anisotropy (a Tangent node's UV tangent)
INDEX_BESIDE = {
    "level, tint": ("Specular IOR Level", (0.1, 1.0), {"Specular Tint": (1.0, 0.5, 0.2), "Roughness": 0.3,
                                                       "Base Color": (0.1, 0.1, 0.1)}),
    "ior, tint": ("IOR", (1.2, 2.4), {"Specular Tint": (0.3, 0.6, 1.0), "Roughness": 0.25,
                                      "Base Color": (0.3, 0.1, 0.05)}),
    "ior, anisotropy": ("IOR", (1.2, 2.4), {"Anisotropic": 0.6, "Roughness": 0.35, "Base Color": (0.05, 0.05, 0.05)}),
    "level, anisotropy": ("Specular IOR Level", (0.1, 1.0), {"Anisotropic": 0.8, "Roughness": 0.3,
                                                             "Base Color": (0.3, 0.3, 0.6)}),
}


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
@pytest.mark.parametrize("case", list(INDEX_BESIDE))
def test_per_point_index_beside_a_tint_or_an_anisotropy_matches_cycles(addon, case, lighting):
    socket, values, others = INDEX_BESIDE[case]
    scene = sphere_scene(socket, values, others, lighting)
    if "Anisotropic" in others:
        tree = bpy.data.materials["P"].node_tree
        tangent = tree.nodes.new("ShaderNodeTangent")
        tangent.direction_type = "UV_MAP"
        tree.links.new(tangent.outputs["Tangent"], tree.nodes["Principled BSDF"].inputs["Tangent"])
    compare_with_cycles(scene, f"Principled {case} per point", lighting)


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
def test_diffuse_bsdf_roughness_per_point_matches_cycles(addon, lighting):
    """The Diffuse BSDF's Roughness from a texture: Cycles' Oren–Nayar per point, Lambert where it is 0."""
    scene = node_scene("ShaderNodeBsdfDiffuse", "Roughness", ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)),
                       {"Color": (0.8, 0.5, 0.3)}, lighting)
    compare_with_cycles(scene, "Diffuse BSDF Roughness", lighting)


#: Anisotropic and Anisotropic Rotation per point (glTF's KHR_materials_anisotropy map through the importer's
#: nodes), and the Roughness per point under a constant Anisotropic: a checker on the input, along a Tangent node's
#: UV tangent
ANISOTROPY_INPUTS = {
    "Anisotropic": ((0.1, 0.9), {"Roughness": 0.4, "Metallic": 1.0, "Base Color": (0.9, 0.7, 0.5)}),
    "Anisotropic Rotation": ((0.0, 0.25), {"Roughness": 0.4, "Metallic": 1.0, "Anisotropic": 0.8,
                                           "Base Color": (0.9, 0.7, 0.5)}),
    "Anisotropic ": ((0.0, 1.0), {"Roughness": 0.35, "Base Color": (0.6, 0.2, 0.1)}),          # the dielectric
    "Roughness": ((0.2, 0.6), {"Metallic": 1.0, "Anisotropic": 0.6, "Base Color": (0.9, 0.7, 0.5)}),  # α_x, α_y of r²
    "Roughness ": ((0.15, 0.5), {"Anisotropic": 0.6, "Base Color": (0.6, 0.2, 0.1)}),          # the dielectric's
}


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
@pytest.mark.parametrize("socket", list(ANISOTROPY_INPUTS))
def test_anisotropy_per_point_matches_cycles(addon, socket, lighting):
    values, others = ANISOTROPY_INPUTS[socket]
    scene = sphere_scene(socket, values, others, lighting)
    tree = bpy.data.materials["P"].node_tree
    tangent = tree.nodes.new("ShaderNodeTangent")
    tangent.direction_type = "UV_MAP"
    tree.links.new(tangent.outputs["Tangent"], tree.nodes["Principled BSDF"].inputs["Tangent"])
    compare_with_cycles(scene, f"Principled {socket.strip()} per point", lighting)


#: Cycles' metal nodes with a Roughness checker under a constant Anisotropy, or an Anisotropy checker (the Glossy's
#: across its negative range) under a constant Roughness, along a Tangent node's UV tangent: α_x, α_y per point
#: (Glossy: r²(1 − a), r²/(1 − a), below 0 r²/(1 + a), r²(1 + a); Metallic: as the Principled's)
NODE_ANISOTROPY = {
    "Glossy Roughness": ("ShaderNodeBsdfGlossy", "Roughness", ((0.2, 0.2, 0.2), (0.6, 0.6, 0.6)),
                         {"Color": (0.9, 0.6, 0.3), "Anisotropy": 0.6}),
    "Metallic Roughness": ("ShaderNodeBsdfMetallic", "Roughness", ((0.2, 0.2, 0.2), (0.6, 0.6, 0.6)),
                           {"Base Color": (0.9, 0.6, 0.3), "Anisotropy": 0.6}),
    "Glossy Anisotropy": ("ShaderNodeBsdfGlossy", "Anisotropy", ((-0.7, -0.7, -0.7), (0.2, 0.2, 0.2)),
                          {"Color": (0.9, 0.6, 0.3), "Roughness": 0.4}),
    "Metallic Anisotropy": ("ShaderNodeBsdfMetallic", "Anisotropy", ((0.1, 0.1, 0.1), (0.9, 0.9, 0.9)),
                            {"Base Color": (0.9, 0.6, 0.3), "Roughness": 0.4}),
}


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
@pytest.mark.parametrize("case", list(NODE_ANISOTROPY))
def test_anisotropic_node_inputs_per_point_match_cycles(addon, case, lighting):
    kind, socket, values, others = NODE_ANISOTROPY[case]
    scene = node_scene(kind, socket, values, {**others, "tangent": True}, lighting)
    compare_with_cycles(scene, f"{case} per point, anisotropic node", lighting)


#: an IOR checker on a glass: rough (Multiscatter GGX: the per-index compensation tables) and tinted by its Base
#: Color; smooth, with a Specular Tint
GLASS_IOR = {"rough tinted": {"Transmission Weight": 1.0, "Roughness": 0.2, "Base Color": (0.9, 0.7, 0.5)},
             "smooth, specular tint": {"Transmission Weight": 1.0, "Roughness": 0.0, "Specular Tint": (1.0, 0.6, 0.3)}}


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
@pytest.mark.parametrize("case", list(GLASS_IOR))
def test_ior_per_point_on_a_glass_matches_cycles(addon, case, lighting):
    """An IOR checker (1.2 | 2.0, an image texture) on a transmitting Principled BSDF: the glass's index per point
    (no warning: the comparison refuses any)."""
    if case.startswith("smooth") and lighting != "lamps":
        pytest.skip("one lighting for the smooth glass (the budget)")
    scene = sphere_scene("IOR", (1.2, 2.0), dict(GLASS_IOR[case]), lighting)
    compare_with_cycles(scene, f"Principled IOR per point on a {case} glass", lighting)


@pytest.mark.parametrize("socket, values", [("IOR", (1.2, 2.0)), ("Specular IOR Level", (0.1, 0.9))])
def test_per_point_index_on_a_filmed_anisotropy_matches_cycles(addon, socket, values):
    """An IOR or a Specular IOR Level checker on an anisotropic specular layer under a Thin Film (a Tangent node's
    UV tangent): the index per point under the film, no warning (the spectral mode, as the films above; lamps)."""
    scene = sphere_scene(socket, values, {"Anisotropic": 0.5, "Roughness": 0.3, "Thin Film Thickness": 300.0,
                                          "Thin Film IOR": 1.5, "Base Color": (0.1, 0.1, 0.1)}, "lamps")
    tree = bpy.data.materials["P"].node_tree
    tangent = tree.nodes.new("ShaderNodeTangent")
    tangent.direction_type = "UV_MAP"
    tree.links.new(tangent.outputs["Tangent"], tree.nodes["Principled BSDF"].inputs["Tangent"])
    compare_with_cycles(scene, f"Principled {socket} per point, filmed anisotropy", "lamps", spectral="SPECTRAL")


def test_ior_and_specular_ior_level_both_per_point_match_cycles(addon):
    """An IOR checker and a Specular IOR Level checker (a second image) on a rough dielectric that half transmits:
    the specular layer's index per point from both, the glass's from the IOR (no warning)."""
    scene = sphere_scene("IOR", (1.3, 2.2), {"Roughness": 0.3, "Transmission Weight": 0.5,
                                             "Base Color": (0.6, 0.4, 0.2)}, "lamps")
    tree = bpy.data.materials["P"].node_tree
    tex = tree.nodes.new("ShaderNodeTexImage")
    # the same checker, values crossed: IOR 1.3 with level 0.9 (F0 above the IOR's), 2.2 with 0.1 (below)
    tex.image, tex.interpolation = checker("level", 0.9, 0.1, False), "Closest"
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Specular IOR Level"])
    compare_with_cycles(scene, "Principled IOR and Specular IOR Level per point", "lamps")


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
def test_emission_shader_strength_per_point_matches_cycles(addon, lighting):
    """An Emission shader whose Strength comes from a texture (a constant Color): Color × Strength per point."""
    scene = node_scene("ShaderNodeEmission", "Strength", ((0.5, 0.5, 0.5), (3.0, 3.0, 3.0)),
                       {"Color": (0.2, 0.6, 1.0)}, lighting)
    compare_with_cycles(scene, "Emission shader Strength", lighting)


#: Under the HDRI Cycles' default estimate of a rough glass is not one image: its next-event estimation evaluates
#: refraction pairs no facet can refract (bsdf_microfacet_eval: "TODO: check if the refraction configuration is
#: valid"), which its BSDF sampling never produces, so turning the world's light samples off (World ▸ Settings ▸
#: Sampling: None) darkens its roughness-0.4 glass sphere by 4.5 % (0.3491 → 0.3339, 256 spp × 8 seeds).  Polar's
#: glass is 0 on those pairs (Walter's χ⁺): 0.3367, its BSDF-only estimate's image (1.008 ± 0.006), 0.964 of Cycles'
#: default; the roughness-0.1 glass (fewer pairs beyond the critical angle) 0.999 ± 0.005 of Cycles' default; under
#: a uniform world 1.000 and 1.011 (docs/physics.md, "Rough glass against Cycles under a small bright source").  So
#: the HDRI case is judged against Cycles' BSDF-sampled world ("hdri"); its default (the world's light samples on)
#: is a measured gap of Cycles' own (its centre block 0.962–0.971 in 2 of 6 sets of 4 seeds, the rest pass), pinned by
#: test_rough_glass_under_the_hdri_is_cycles_bsdf_sampled_image rather than by a case here that could not fail.
GLASS_LIGHTINGS = {"lamps": ("lamps", True), "hdri": ("hdri", False)}


@pytest.mark.parametrize("case", list(GLASS_LIGHTINGS))
def test_roughness_per_point_on_a_glass_matches_cycles(addon, case):
    """A Roughness checker on a transmitting Principled BSDF: the rough glass's α = r² per point, as the reflection
    lobes' (no warning); under the HDRI against Cycles with and without the world's light samples."""
    lighting, world_light_samples = GLASS_LIGHTINGS[case]
    scene = sphere_scene("Roughness", (0.1, 0.4), {"Transmission Weight": 1.0, "Base Color": (0.9, 0.9, 0.9)},
                         lighting)
    if not world_light_samples:
        scene.world.cycles.sampling_method = "NONE"       # Cycles: BSDF sampling only (Polar ignores the setting)
    # 8 seeds: with 4, σ from 3 degrees of freedom let one block of 12 fail by chance (seen with one sequence over
    # the even and odd samples: block 1.074 against 0.062 at seeds 0-3, all 12 pass at 8 and 16 seeds, Y 0.991-0.998)
    compare_with_cycles(scene, "Principled Roughness on a glass", lighting, seeds=8)


def sphere_luminance(images, hit):
    """(mean, standard error) over seeds of the mean luminance of (seeds, H, W, 3) images over the (H, W) mask."""
    y = (images @ ap.REC709)[:, hit].mean(axis=1)
    return float(y.mean()), float(y.std(ddof=1) / np.sqrt(len(y)))


def test_rough_glass_under_the_hdri_is_cycles_bsdf_sampled_image(addon):
    """A roughness-0.4 Principled glass sphere under the HDRI (64², 8 seeds): Polar's S0 equals Cycles'
    BSDF-sampled estimate (the world's light samples off) within 3σ + 1.5 % (Cycles under-compensates inside rough
    glass by ≈ 1 %: ggx_glass_inv_E, docs/physics.md); Cycles' default is ≥ 1.5 % + 3σ brighter than that (measured
    4.5 %): its next-event estimation through back-facing facets, absent from Polar's glass (GLASS_LIGHTINGS).
    Samples where the noise is: the BSDF-sampled Cycles 256 spp (σ of the mean 0.0019), its default 128 (0.0008),
    Polar 64 (0.0012); at 256 spp each, σ was 0.0019 / 0.0006 / 0.0006 in 51 s instead of 24 s."""
    import tempfile
    seeds = 8
    scene = sphere_scene("Roughness", (0.4, 0.4), {"Transmission Weight": 1.0, "Base Color": (0.9, 0.9, 0.9)}, "hdri")
    hit = ap.coverage(scene, SIZE, SIZE)
    with tempfile.TemporaryDirectory() as tmp:
        mc, sc = sphere_luminance(ap.render_cycles(scene, 128, seeds, 8, tmp), hit)
        scene.world.cycles.sampling_method = "NONE"
        mb, sb = sphere_luminance(ap.render_cycles(scene, 256, seeds, 8, tmp), hit)
    renderer, settings, warnings = ap.export_polar(scene, 64, 8)
    mp, sp = sphere_luminance(ap.render_polar(renderer, settings, seeds)[:, 0], hit)
    assert not warnings, warnings
    ratio, se = mp / mb, mp / mb * np.hypot(sp / mp, sb / mb)
    print(f"rough glass, HDRI: Polar {mp:.4f} ± {sp:.4f}, Cycles BSDF-sampled {mb:.4f} ± {sb:.4f}, default {mc:.4f} ± "
          f"{sc:.4f}: Polar/Cycles(BSDF sampling) {ratio:.4f} ± {se:.4f}")
    assert abs(ratio - 1.0) <= 3.0 * se + 0.015, (f"Polar/Cycles(BSDF sampling) {ratio:.4f} ± {se:.4f} "
                                                  f"(Polar {mp:.4f}, Cycles {mb:.4f}, default {mc:.4f} ± {sc:.4f})")
    assert mc > mb * 1.015 + 3.0 * np.hypot(sc, sb), (mc, sc, mb, sb)


def _colour_texture(tree, name, socket):
    """A 2 × 2 colour image (four colours, Closest) into ``socket``: a colour that varies beside the checker."""
    img = bpy.data.images.new(name, 2, 2, alpha=False, float_buffer=True)
    img.pixels = [2.0, 0.5, 0.1, 1.0, 0.2, 0.6, 1.5, 1.0, 1.0, 1.0, 1.0, 1.0, 0.1, 1.2, 0.3, 1.0]
    img.pack()
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Closest"
    tree.links.new(tex.outputs["Color"], socket)


def _lit_floor():
    """A white diffuse floor under the sphere, lit by it (the emitter's next-event estimation is exercised)."""
    bpy.ops.mesh.primitive_plane_add(size=8.0, location=(0.0, 0.0, -1.0))
    mat = bpy.data.materials.new("Floor")
    load_addon().polar_addon.compat.ensure_node_tree(mat)
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    p.inputs["Roughness"].default_value = 1.0
    bpy.context.object.data.materials.append(mat)


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
def test_emission_strength_per_point_beside_a_textured_colour_matches_cycles(addon, lighting):
    """A Strength checker beside a textured Emission Color: colour × strength per point, what the emitter is seen
    as and what its next-event estimation samples by (the floor it lights); no warning."""
    scene = sphere_scene("Emission Strength", (0.5, 3.0), {"Base Color": (0.2, 0.2, 0.2)}, lighting)
    tree = bpy.data.materials["P"].node_tree
    _colour_texture(tree, "colours", tree.nodes["Principled BSDF"].inputs["Emission Color"])
    _lit_floor()
    compare_with_cycles(scene, "Principled Emission Strength × Color", lighting)


@pytest.mark.parametrize("lighting", ap.LIGHTINGS)
def test_emission_shader_strength_beside_a_textured_colour_matches_cycles(addon, lighting):
    """The Emission shader's Strength checker beside a textured Color, over a floor it lights."""
    scene = node_scene("ShaderNodeEmission", "Strength", ((0.5, 0.5, 0.5), (3.0, 3.0, 3.0)), {}, lighting)
    tree = bpy.data.materials["P"].node_tree
    _colour_texture(tree, "colours", tree.nodes["Emission"].inputs["Color"])
    _lit_floor()
    compare_with_cycles(scene, "Emission shader Strength × Color", lighting)
