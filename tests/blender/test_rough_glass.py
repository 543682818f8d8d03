"""Blender: Principled (Transmission, Roughness) and Glass with roughness → rough_dielectric
(GGX, α = roughness², Cycles' multiple-scattering compensation for Multiscatter GGX), tinted as Cycles
tints glass; the Rough/Thin Dielectric node models."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import empty_scene, load_addon, polar_material  # noqa: E402


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def exported(material):
    from polar_render.polar_addon.export.materials import export_material
    warnings = []
    bsdf, _ = export_material(material, warnings)
    return bsdf, warnings


def untinted(bsdf):
    """The glass model under a colour tint (engine.materials.tinted)."""
    from polar_render.engine.materials.tinted import Tinted
    return bsdf.base if isinstance(bsdf, Tinted) else bsdf


def shader_material(kind, distribution=None, **inputs):
    mat = bpy.data.materials.new("G")
    tree = mat.node_tree
    if kind == "ShaderNodeBsdfPrincipled":
        node = tree.nodes["Principled BSDF"]
    else:
        for n in list(tree.nodes):
            if n.bl_idname != "ShaderNodeOutputMaterial":
                tree.nodes.remove(n)
        node = tree.nodes.new(kind)
        tree.links.new(node.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    if distribution is not None:
        node.distribution = distribution
    for k, v in inputs.items():
        node.inputs[k].default_value = v
    return mat


def test_principled_rough_transmission_is_ggx_tinted_by_the_root_of_the_base_colour(addon):
    empty_scene()
    mat = shader_material("ShaderNodeBsdfPrincipled", **{"Transmission Weight": 1.0, "Roughness": 0.5, "IOR": 1.45,
                                                         "Base Color": (0.64, 0.25, 0.04, 1.0)})
    bsdf, warnings = exported(mat)
    glass = untinted(bsdf)
    assert glass.name == "rough_dielectric" and glass.distribution == "ggx" and glass.multiscatter
    assert glass.alpha == pytest.approx(0.25) and glass.n_int == pytest.approx(1.45)
    assert not warnings
    # Cycles' transmission tint: √(Base Color) at each refraction, reflections untinted
    assert bsdf.reflection is None and bsdf.transmission.linear_srgb() == pytest.approx([0.8, 0.5, 0.2])
    bsdf, warnings = exported(shader_material("ShaderNodeBsdfPrincipled", "GGX",
                                              **{"Transmission Weight": 1.0, "Roughness": 0.5}))
    assert untinted(bsdf).name == "rough_dielectric" and not untinted(bsdf).multiscatter and not warnings
    bsdf, _ = exported(shader_material("ShaderNodeBsdfPrincipled", **{"Transmission Weight": 1.0, "Roughness": 0.0,
                                                                      "Base Color": (1, 1, 1, 1)}))
    assert bsdf.name == "dielectric"       # roughness 0: the smooth dielectric; a white base: no tint


@pytest.mark.parametrize("kind,distribution,want", [("ShaderNodeBsdfGlass", "GGX", "ggx"),
                                                    ("ShaderNodeBsdfGlass", "BECKMANN", "beckmann"),
                                                    ("ShaderNodeBsdfGlass", "MULTI_GGX", "ggx")])
def test_glass_and_refraction_with_roughness(addon, kind, distribution, want):
    empty_scene()
    bsdf, warnings = exported(shader_material(kind, distribution, Roughness=0.4, IOR=1.6))
    bsdf = untinted(bsdf)
    assert bsdf.name == "rough_dielectric" and bsdf.distribution == want
    assert bsdf.alpha == pytest.approx(0.16) and bsdf.n_int == pytest.approx(1.6)
    assert bsdf.multiscatter == (distribution == "MULTI_GGX") and not warnings


def test_rough_and_thin_dielectric_node_models(addon):
    empty_scene()
    bsdf, _ = exported(polar_material("R", "ROUGH_DIELECTRIC", IOR=1.33, Roughness=0.3))
    assert bsdf.name == "rough_dielectric" and bsdf.alpha == pytest.approx(0.3) and bsdf.n_int == pytest.approx(1.33)
    bsdf, _ = exported(polar_material("R0", "ROUGH_DIELECTRIC", Roughness=0.0))
    assert bsdf.name == "dielectric"
    bsdf, _ = exported(polar_material("T", "THIN_DIELECTRIC", dielectric_preset="WATER"))
    assert bsdf.name == "thin_dielectric" and bsdf.n_int == pytest.approx(1.333)


@pytest.mark.parametrize("kind,distribution", [("ShaderNodeBsdfGlass", "BECKMANN"), ("ShaderNodeBsdfGlass", "GGX"),
                                               ("ShaderNodeBsdfGlossy", "BECKMANN"), ("ShaderNodeBsdfGlossy", "GGX")])
def test_the_smooth_limit_is_the_engines_for_blender_and_scene_files(addon, kind, distribution):
    """One rule (engine.materials.roughness): roughness r with α = r² below SMOOTH_LIMIT = 1e-4 (r < 0.01) is the
    smooth model, from it on the rough lobe — Beckmann facets as GGX (they turned smooth below α = 0.02 before),
    and the rough glass is the model a scene file's ``rough_dielectric`` of the same α builds."""
    from polar_render.engine.materials.catalogue import MODELS
    empty_scene()
    glass = kind == "ShaderNodeBsdfGlass"
    for r, rough in ((0.0, False), (0.0099, False), (0.0101, True), (0.1, True)):
        bsdf, _ = exported(shader_material(kind, distribution, Roughness=r, **({"IOR": 1.5} if glass else {})))
        model = untinted(bsdf) if glass else bsdf.base
        if glass:
            assert model.name == ("rough_dielectric" if rough else "dielectric"), (r, model.name)
            decl = MODELS["rough_dielectric"]
            r32 = float(np.float32(r))          # (as Blender stores the socket)
            from_file = decl.build(decl.values({"n": 1.5, "alpha": r32 * r32, "distribution": distribution.lower()},
                                               "x"))
            assert model.describe() == from_file.describe()
        else:
            assert model.name == ("torrance_sparrow" if rough else "conductor"), (r, model.name)
