"""A shader's Normal input (and a Principled's Coat Normal) → the engine's normal and bump maps
(ShadingNormal): a tangent-space Normal Map node and/or a Bump node on image textures, as Cycles."""

from .. import compat
from .node_links import follow
from .node_reader import Reader


def _normal_nodes(socket):
    """(Normal Map node or None, Bump node or None, supported) for a shader's Normal input.
    Supported: a Normal Map node whose Color is an Image Texture, a Bump node whose Height is an
    Image Texture (its own Normal input unlinked or such a Normal Map), both as Cycles."""
    node = follow(socket)
    if node is None:
        return None, None, True
    bump = None
    if node.bl_idname == "ShaderNodeBump":
        bump = node
        height = follow(node.inputs["Height"])
        if height is None or height.bl_idname != "ShaderNodeTexImage":
            return None, None, False
        node = follow(node.inputs["Normal"])
        if node is None:
            return None, bump, True
    if node.bl_idname != "ShaderNodeNormalMap":
        return None, None, False
    colour = follow(node.inputs["Color"])
    if colour is None or colour.bl_idname != "ShaderNodeTexImage":
        return None, None, False
    return node, bump, True


def normal_input_unsupported(node) -> bool:
    """True if a shader node's Normal input is linked to something that is not exported (the scene
    exporter then warns that the geometric shading normals are used)."""
    sock = node.inputs.get("Normal")
    return sock is not None and sock.is_linked and not _normal_nodes(sock)[2]


def with_shading_normal(bsdf, node, mat, warnings):
    """``bsdf`` with the engine's normal and bump maps where the shader's Normal input (and a Principled's Coat
    Normal) is a tangent-space Normal Map and/or a Bump node on image textures (Cycles: n = normalise(x·T + y·B +
    z·n), B = sign·(n × T) with MikkTSpace tangents, Strength as Cycles' tangent space; bump n' = normalise(n −
    distance·∇h), blended by Strength); the engine maps it closure by closure (principled.with_normal_maps)."""
    normal = _normal_keywords(node.inputs.get("Normal"), mat, warnings)
    coat = None
    sock = node.inputs.get("Coat Normal") if node.bl_idname == "ShaderNodeBsdfPrincipled" else None
    if sock is not None and sock.is_linked:
        if not _normal_nodes(sock)[2]:
            warnings.append(f"material {mat!r}: the Coat Normal of {node.name!r} is linked to something other than a "
                            "Normal Map or Bump node on an image texture; the coat uses the Normal input's normal")
        else:
            coat = _normal_keywords(sock, mat, warnings)
    if normal is None and coat is None:
        return bsdf
    from ...engine.materials.principled import with_normal_maps
    return with_normal_maps(bsdf, normal, coat)


def _normal_keywords(sock, mat, warnings):
    """The engine's normal/bump-map keywords (ShadingNormal) of a Normal input, or None where it is unlinked or
    not exported (the scene exporter warns for the Normal input: normal_input_unsupported)."""
    if sock is None or not sock.is_linked:
        return None
    normal, bump, ok = _normal_nodes(sock)
    if not ok:
        return None
    kw = {}
    if normal is not None:
        if normal.space != "TANGENT":
            warnings.append(f"material {mat!r}: Normal Map {normal.name!r} in {normal.space.lower()} space is not "
                            "supported (tangent space only); the geometric shading normals are used")
        else:
            r = Reader(mat, normal, warnings)
            kw.update(normal_map=r.texture("Color"), normal_strength=max(r.float("Strength"), 0.0),
                      normal_convention=compat.normal_map_convention(normal))
    if bump is not None:
        r = Reader(mat, bump, warnings)
        distance = r.float("Distance")
        kw.update(bump_map=r.texture("Height"), bump_distance=-distance if bump.invert else distance,
                  bump_strength=min(max(r.float("Strength"), 0.0), 1.0))
    kw = {k: v for k, v in kw.items() if v is not None}
    return kw if "normal_map" in kw or "bump_map" in kw else None
