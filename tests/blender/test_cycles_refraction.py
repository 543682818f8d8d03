"""Blender's Glass and Refraction BSDF nodes against Cycles: the Refraction BSDF as Cycles' closure (refraction only,
no Fresnel: engine.materials.refraction), the IOR and Roughness of both nodes per point (image textures), and a Thin
Film on a rough Glass or Principled transmission.

The exporter's mapping is checked on the exported model; the renders use the Principled parity harness
(tests/blender/test_cycles_parity_principled.py: a UV sphere under the asset suite's lamps or sky, 64², 4 × 16 spp,
Polar's S0 luminance per 16 × 16 block within 4 σ + 2 % of Cycles' in ≥ 95 % of the blocks, no warning)."""

import pytest

bpy = pytest.importorskip("bpy")

from tests.blender.test_cycles_parity_principled import checker, compare_with_cycles, sphere_scene  # noqa: E402
from tests.blender.test_rough_glass import exported, shader_material, untinted  # noqa: E402
from tests.blender_support import empty_scene, load_addon  # noqa: E402


@pytest.fixture(scope="module")
def addon():
    return load_addon()


@pytest.mark.parametrize("distribution,roughness,want", [("GGX", 0.4, "ggx"), ("BECKMANN", 0.4, "beckmann"),
                                                         ("GGX", 0.0, None), ("BECKMANN", 0.005, None)])
def test_refraction_node_is_the_refraction_model_tinted_by_its_colour(addon, distribution, roughness, want):
    """Rough (α = r², either distribution) or sharp (the engine's smooth rule: r < 0.01), Color as the tint of what
    it transmits, no warning."""
    from polar_render.engine.materials.refraction import Refraction, SmoothRefraction
    empty_scene()
    bsdf, warnings = exported(shader_material("ShaderNodeBsdfRefraction", distribution, Roughness=roughness, IOR=1.6,
                                              Color=(0.9, 0.5, 0.2, 1.0)))
    model = untinted(bsdf)
    assert not warnings and model.name == "refraction" and model.n_int == pytest.approx(1.6)
    if want is None:
        assert type(model) is SmoothRefraction
    else:
        assert type(model) is Refraction and model.distribution == want and model.alpha == pytest.approx(0.16)
    assert bsdf.reflection is None and bsdf.transmission.linear_srgb() == pytest.approx([0.9, 0.5, 0.2])


def _linked(kind, distribution, sockets, others):
    """A material of node ``kind`` whose ``sockets`` ({name: (a, b)}) each come from a 4 × 4 checker image."""
    mat = shader_material(kind, distribution, **others)
    tree = mat.node_tree
    node = next(n for n in tree.nodes if n.bl_idname == kind)
    for name, (a, b) in sockets.items():
        tex = tree.nodes.new("ShaderNodeTexImage")
        tex.image, tex.interpolation = checker(name, a, b, False), "Closest"
        tree.links.new(tex.outputs["Color"], node.inputs[name])
    return mat


@pytest.mark.parametrize("kind", ["ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction"])
def test_linked_ior_and_roughness_vary_per_point(addon, kind):
    """IOR and Roughness from images: the index and α = r² per point (TexturedNumbers), no warning; an IOR texture
    across 1 is refused with the Principled's message."""
    from polar_render.engine.errors import SceneError
    from polar_render.engine.textures import TexturedNumber
    empty_scene()
    bsdf, warnings = exported(_linked(kind, "BECKMANN", {"IOR": (1.3, 1.8), "Roughness": (0.2, 0.6)}, {}))
    model = untinted(bsdf)
    assert not warnings and isinstance(model.alpha, TexturedNumber) and model.per_point_index
    assert (model.alpha.lo, model.alpha.hi) == pytest.approx((0.04, 0.36)) and model.distribution == "beckmann"
    assert (model.n_int.lo, model.n_int.hi) == pytest.approx((1.3, 1.8))
    bsdf, warnings = exported(_linked(kind, "GGX", {"IOR": (1.3, 1.8)}, {"Roughness": 0.0}))
    assert not warnings and untinted(bsdf).per_point and untinted(bsdf).delta_only     # smooth, index per point
    with pytest.raises(SceneError, match=r"IOR: a per-point index must lie on one side of 1, got values in "
                                         r"\[0\.8, 1\.5\]"):
        exported(_linked(kind, "GGX", {"IOR": (0.8, 1.5)}, {}))


def _node_sphere(kind, distribution, checkers, others, lighting):
    """The parity sphere with node ``kind`` at the output, its ``checkers`` ({socket: (a, b)}) from images."""
    scene = sphere_scene("Roughness", (0.5, 0.5), {}, lighting)
    tree = bpy.data.materials["P"].node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    tree.nodes.remove(tree.nodes["Image Texture"])
    node = tree.nodes.new(kind)
    node.distribution = distribution
    for k, v in others.items():
        node.inputs[k].default_value = (*v, 1.0) if isinstance(v, tuple) else v
    for name, (a, b) in checkers.items():
        tex = tree.nodes.new("ShaderNodeTexImage")
        tex.image, tex.interpolation = checker(name, a, b, False), "Closest"
        tree.links.new(tex.outputs["Color"], node.inputs[name])
    tree.links.new(node.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    return scene


#: name → (node, distribution, checkers, constant inputs, lighting).  Measured (64 spp × 4 seeds, Polar/Cycles mean Y):
#: 0.999, 1.006, 1.000, 1.000, 1.002.  Not listed: a rough glass with its IOR per point under the lamps, whose block
#: rule at these samples is at the mercy of rare bright paths (the sun through faces of different index: 16-sample
#: means scatter by ≈ 9 %; it was once taken for a 5–8 % gap).  At 256 spp × 16 seeds over the sphere it agrees:
#: IOR 1.3 | 1.8, roughness 0.3, GGX 1.005 ± 0.012, Multiscatter GGX 1.005 ± 0.012, the Principled's 1.2 | 2.0
#: 1.007 ± 0.009.  Under the area lamp alone the checker is 0.981 ± 0.007, one index alone 0.991 ± 0.006 (1.8) and
#: 0.934 ± 0.018 (1.3): low-index rough glass under a small source, not neighbouring faces of different index —
#: Cycles' light samples through refraction pairs no facet makes (+1.8 %, tests/materials/test_rough_glass_energy.py),
#: polarisation over the many crossings and total reflections (−2.1 % in Polar's S0), Cycles' height-correlated
#: shadowing (+0.1–0.7 %) (docs/physics.md).
PARITY = {
    "Refraction GGX, Roughness per point": ("ShaderNodeBsdfRefraction", "GGX", {"Roughness": (0.1, 0.5)},
                                            {"IOR": 1.45, "Color": (0.9, 0.8, 0.6)}, "lamps"),
    "Refraction Beckmann, IOR per point": ("ShaderNodeBsdfRefraction", "BECKMANN", {"IOR": (1.3, 1.8)},
                                           {"Roughness": 0.3}, "hdri"),
    "Refraction sharp, IOR per point": ("ShaderNodeBsdfRefraction", "GGX", {"IOR": (1.2, 1.6)}, {"Roughness": 0.0},
                                        "lamps"),
    "Glass Multiscatter GGX, Roughness per point": ("ShaderNodeBsdfGlass", "MULTI_GGX", {"Roughness": (0.15, 0.5)},
                                                    {"IOR": 1.6, "Color": (0.9, 0.9, 0.9)}, "lamps"),
    "Glass Beckmann, IOR and Roughness per point": ("ShaderNodeBsdfGlass", "BECKMANN",
                                                    {"IOR": (1.3, 2.0), "Roughness": (0.15, 0.5)}, {}, "hdri"),
}


@pytest.mark.parametrize("case", list(PARITY))
def test_glass_and_refraction_nodes_match_cycles(addon, case):
    kind, distribution, checkers, others, lighting = PARITY[case]
    compare_with_cycles(_node_sphere(kind, distribution, checkers, others, lighting), case, lighting)


#: a Thin Film on a rough transmission (Airy's sum on every facet), in the spectral mode as the house's other films
#: (Cycles integrates the film's spectrum per RGB channel).  Measured (4 seeds; Y at 16 spp, at 64 spp): 0.987 (the
#: same under the sky at 64 spp 0.996, 12/12; at 16 spp two blocks out by 0.002 of chromatic noise), 0.997 and 0.988,
#: 1.029 and 1.006.  A Thin Film Thickness per point under the lamps: one block of 12 at 1.15 (Glass and Principled
#: alike; constant 400 nm 12/12, Y 0.984), as the per-point IOR above.
FILMED = {
    "Glass GGX, thin film, Roughness per point": (
        lambda: _node_sphere("ShaderNodeBsdfGlass", "GGX", {"Roughness": (0.2, 0.4)},
                             {"IOR": 1.5, "Thin Film IOR": 2.0, "Thin Film Thickness": 400.0}, "lamps"), "lamps"),
    "Glass Multiscatter GGX, Thin Film Thickness per point": (
        lambda: _node_sphere("ShaderNodeBsdfGlass", "MULTI_GGX", {"Thin Film Thickness": (250.0, 600.0)},
                             {"Roughness": 0.3, "IOR": 1.5, "Thin Film IOR": 1.33}, "hdri"), "hdri"),
    "Principled rough transmission, thin film": (
        lambda: sphere_scene("Roughness", (0.15, 0.45), {"Transmission Weight": 1.0, "Thin Film Thickness": 400.0,
                                                         "Thin Film IOR": 2.0, "Base Color": (1.0, 1.0, 1.0)},
                             "lamps"), "lamps"),
}


@pytest.mark.parametrize("case", list(FILMED))
def test_thin_film_on_a_rough_transmission_matches_cycles(addon, case):
    build, lighting = FILMED[case]
    compare_with_cycles(build(), case, lighting, spectral="SPECTRAL")


def test_thin_film_on_a_rough_glass_is_filmed_without_warning(addon):
    """The film goes on every facet of the rough glass (Glass and Principled), no warning (before: one, no film)."""
    empty_scene()
    bsdf, warnings = exported(shader_material("ShaderNodeBsdfGlass", "MULTI_GGX", Roughness=0.3, IOR=1.5,
                                              **{"Thin Film Thickness": 400.0, "Thin Film IOR": 2.0}))
    model = untinted(bsdf)
    assert not warnings and model.name == "rough_dielectric" and model.film == (2.0, 400.0) and model.multiscatter
    bsdf, warnings = exported(shader_material("ShaderNodeBsdfPrincipled", **{
        "Transmission Weight": 1.0, "Roughness": 0.3, "Thin Film Thickness": 400.0, "Base Color": (1, 1, 1, 1)}))
    assert not warnings and untinted(bsdf).film is not None
