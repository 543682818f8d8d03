"""Blender materials → engine BSDFs (and emission): the entry point of the material export.

``export_material`` reads a material's Material Output: its Surface through ``shaders.surface_bsdf``, its
Volume as the medium of the object's interior (``volumes``), a Displacement only as a warning; a material without
nodes is a Lambert of its viewport colour.  ``attribute_needs`` tells the mesh export which UV maps,
tangents and colour attributes a material's graph reads, and whether an input may be baked.

The material export, each module importing only those listed after it:

- volumes: Volume graphs → media (interiors, the world medium, Volume objects);
- shaders: the standard shaders (Principled, Glossy, Metallic, Glass, …), mixes and ``surface_bsdf``;
- polarising_node: the Polarising BSDF node, its model and inputs exactly;
- normal_maps: Normal Map and Bump nodes → the engine's shading normals;
- lambert: the Lambert the conversions fall back to;
- node_reader: a node's validated inputs (constants, textures, baked graphs) and the bake targets;
- images: Blender images and texture nodes → engine textures;
- node_links: what feeds an input socket.
"""



from ...engine.materials.normal_map import has_mapped_normals, set_bump_correction
from ...engine.materials.rough_dielectric import compensate_dense_sides_as_cycles
from .. import compat
from .images import baked_link, uv_source
from .lambert import DEFAULT_ALBEDO, lambert
from .node_links import follow
from .node_reader import NoBake
from .shaders import NORMAL_SHADERS, anisotropic, surface_bsdf
from .volumes import material_medium

#: The viewport's target: baking there would run Cycles' bake operator inside view_update (its
#: temporary datablocks feed back as depsgraph updates) and re-bake on every drag of an object.
VIEWPORT_NO_BAKE = NoBake("which Polar bakes for final renders (F12) only, not in the viewport")


def export_material(material, warnings, bake=None):
    """(BSDF, emission or None) for a Blender material (None → default grey).  ``bake``: a
    BakeTarget (the object the material is exported for) to bake linked inputs on, or None or a
    NoBake (their own values, one warning each).  Every Blender material is two-sided, as in Cycles
    (BSDF.two_sided: an opaque one seen from the back shades with flipped normals), counts a direction only on
    the surface's side of its shading normal (BSDF.geometric_sides), refracts without
    scaling radiance by 1/η², as Cycles' closures do (BSDF.radiance_scaling), and compensates rough glass for
    multiple scattering as Cycles' tables do (rough_dielectric.compensate_dense_sides_as_cycles)."""
    bsdf, emission = _material_bsdf(material, warnings, bake)
    bsdf.two_sided = True
    # directions on the surface's side of the shading normal, as Cycles (mapped lobes keep their own rule)
    bsdf.geometric_sides = not has_mapped_normals(bsdf)
    if bsdf.flags.transmits:
        bsdf.radiance_scaling = False
        # rough glass seen from its denser side loses what Cycles' compensation loses there (docs/physics.md)
        compensate_dense_sides_as_cycles(bsdf)
    return bsdf, emission


def _material_bsdf(material, warnings, bake):
    if material is None:
        return lambert(DEFAULT_ALBEDO, "default"), None
    tree = compat.node_tree_in_use(material)
    if tree is None:
        return lambert([float(c) for c in material.diffuse_color[:3]], material.name), None
    output = tree.get_output_node("ALL") or tree.get_output_node("CYCLES")
    node = follow(output.inputs["Surface"]) if output is not None else None
    sock = output.inputs.get("Displacement") if output is not None else None
    if sock is not None and follow(sock) is not None:
        warnings.append(f"material {material.name!r}: Material Output ▸ Displacement is not simulated; the surface "
                        "is rendered without it")
    aovs = _aov_outputs(tree)
    if aovs:
        warnings.append(f"material {material.name!r}: AOV Output {', '.join(repr(a) for a in aovs)} not written "
                        "(Polar renders no shader AOVs)")
    volume = follow(output.inputs["Volume"]) if output is not None and "Volume" in output.inputs else None
    if node is None and volume is not None:
        # Cycles: a material with only a volume has a transparent surface (the object's alpha: scene.py)
        return _with_interior(lambert(0.0, material.name), volume, material.name, warnings), None
    if node is None:
        warnings.append(f"material {material.name!r} has no surface shader; rendered black")
        return lambert(0.0, material.name), None
    bsdf, emission = surface_bsdf(node, material.name, warnings, bake=bake)
    cycles = getattr(material, "cycles", None)      # Material ▸ Settings ▸ Bump Map Correction (Cycles' property)
    if not getattr(cycles, "use_bump_map_correction", True):
        set_bump_correction(bsdf, False)
    if volume is not None:
        bsdf = _with_interior(bsdf, volume, material.name, warnings)
    return bsdf, emission


def _aov_outputs(tree, seen=None) -> list:
    """Names of the AOV Output nodes (not muted) of a material's node tree and the node groups in it, sorted."""
    seen = set() if seen is None else seen
    if tree is None or tree.name_full in seen:
        return []
    seen.add(tree.name_full)
    names = set()
    for node in tree.nodes:
        if node.mute:
            continue
        if node.bl_idname == "ShaderNodeOutputAOV":
            names.add(getattr(node, "aov_name", "") or node.name)
        elif getattr(node, "node_tree", None) is not None:
            names.update(_aov_outputs(node.node_tree, seen))
    return sorted(names)


# --------------------------------------------------------------------------- mesh attributes

def attribute_needs(material) -> dict:
    """Mesh attributes that a material's node graph (what its Surface reads) uses:
    {"uv": [UV map names], "tangents": [UV map names], "colors": [colour attribute names],
    "bake": [''] where a shader input may be baked (on the UV map the mesh exports: the active
    render map unless a texture names one)}, '' for the active render one; empty lists where none
    (an untextured material needs nothing)."""
    needs = {"uv": [], "tangents": [], "colors": [], "bake": []}
    tree = compat.node_tree_in_use(material) if material is not None else None
    if tree is None:
        return needs
    output = tree.get_output_node("ALL") or tree.get_output_node("CYCLES")
    if output is None:
        return needs
    seen, stack = set(), [output]
    while stack:
        node = stack.pop()
        if node.name in seen:
            continue
        seen.add(node.name)
        kind = node.bl_idname
        if kind == "ShaderNodeTexImage":
            needs["uv"].append(uv_source(node, "", [])[0])
        elif kind == "ShaderNodeNormalMap" and node.space == "TANGENT":
            needs["uv"].append(node.uv_map)
            needs["tangents"].append(node.uv_map)
        elif kind == "ShaderNodeTangent" and node.direction_type == "UV_MAP":
            needs["uv"].append(node.uv_map)
            needs["tangents"].append(node.uv_map)
        elif (kind == "ShaderNodeBsdfPrincipled" and anisotropic(node)) or \
                (kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic", "ShaderNodeBsdfMetallic")
                 and anisotropic(node, "Anisotropy")):
            needs["uv"].append("")              # the surface tangent of the anisotropy (see _tangent_note)
            needs["tangents"].append("")
        elif kind == "ShaderNodeVertexColor":
            needs["colors"].append(node.layer_name)
        elif kind == "ShaderNodeAttribute" and node.attribute_type == "GEOMETRY":
            needs["colors"].append(node.attribute_name)
        elif kind in NORMAL_SHADERS + ("PolarShaderNodeBSDF", "ShaderNodeEmission") and any(map(baked_link,
                                                                                                  node.inputs)):
            needs["bake"].append("")
        for sock in node.inputs:
            for link in sock.links:
                stack.append(link.from_node)
    return {k: list(dict.fromkeys(v)) for k, v in needs.items()}


# --------------------------------------------------------------------------- volumes

def _with_interior(bsdf, volume, mat, warnings):
    """``bsdf`` carrying the medium of the material's Volume graph (engine Interior: export.volumes), if it
    absorbs or scatters anything."""
    interior = material_medium(volume, mat, warnings)
    if interior is not None:
        bsdf.interior = interior
    return bsdf
