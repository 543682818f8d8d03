"""Blender: Principled (Transmission, Roughness) and Glass/Refraction with roughness → rough_dielectric
(single-scattering GGX, α = roughness²); the Rough/Thin Dielectric node models."""

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


def test_principled_rough_transmission_is_single_scatter_ggx_with_one_warning(addon):
    empty_scene()
    mat = shader_material("ShaderNodeBsdfPrincipled", **{"Transmission Weight": 1.0, "Roughness": 0.5, "IOR": 1.45})
    bsdf, warnings = exported(mat)
    assert bsdf.name == "rough_dielectric" and bsdf.distribution == "ggx"
    assert bsdf.alpha == pytest.approx(0.25) and bsdf.n_int == pytest.approx(1.45)
    assert len([w for w in warnings if "Multiscatter" in w]) == 1
    bsdf, warnings = exported(shader_material("ShaderNodeBsdfPrincipled", "GGX",
                                              **{"Transmission Weight": 1.0, "Roughness": 0.5}))
    assert bsdf.name == "rough_dielectric" and not warnings
    bsdf, _ = exported(shader_material("ShaderNodeBsdfPrincipled", **{"Transmission Weight": 1.0, "Roughness": 0.1}))
    assert bsdf.name == "dielectric"       # α = 0.01 < the smooth limit


@pytest.mark.parametrize("kind,distribution,want", [("ShaderNodeBsdfGlass", "GGX", "ggx"),
                                                    ("ShaderNodeBsdfGlass", "BECKMANN", "beckmann"),
                                                    ("ShaderNodeBsdfGlass", "MULTI_GGX", "ggx"),
                                                    ("ShaderNodeBsdfRefraction", "GGX", "ggx")])
def test_glass_and_refraction_with_roughness(addon, kind, distribution, want):
    empty_scene()
    bsdf, warnings = exported(shader_material(kind, distribution, Roughness=0.4, IOR=1.6))
    assert bsdf.name == "rough_dielectric" and bsdf.distribution == want
    assert bsdf.alpha == pytest.approx(0.16) and bsdf.n_int == pytest.approx(1.6)
    assert bool(warnings) == (distribution == "MULTI_GGX")


def test_rough_and_thin_dielectric_node_models(addon):
    empty_scene()
    bsdf, _ = exported(polar_material("R", "ROUGH_DIELECTRIC", IOR=1.33, Roughness=0.3))
    assert bsdf.name == "rough_dielectric" and bsdf.alpha == pytest.approx(0.3) and bsdf.n_int == pytest.approx(1.33)
    bsdf, _ = exported(polar_material("R0", "ROUGH_DIELECTRIC", Roughness=0.0))
    assert bsdf.name == "dielectric"
    bsdf, _ = exported(polar_material("T", "THIN_DIELECTRIC", dielectric_preset="WATER"))
    assert bsdf.name == "thin_dielectric" and bsdf.n_int == pytest.approx(1.333)
