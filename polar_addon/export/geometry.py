"""Blender objects → engine geometry: the evaluated meshes, hair and point clouds of an object as local
triangle arrays (``geometry_arrays``, read with ``foreach_get``), placed in the world as engine Meshes with
their materials, emission, alpha and ray visibility (``object_meshes``).  The walk over the scene that calls
these is ``export.scene``.

Geometry follows Cycles: meshes (including the evaluated meshes of text, metaballs, surfaces and
bevelled curves, which the depsgraph delivers as mesh instances), hair curves (``CURVES``, as
tubes of their ``radius``) and point clouds (spheres of their ``radius``).  Curves that geometry
nodes leave on a mesh or curve object (a ``CURVE`` instance without a mesh) are not rendered by
Cycles either: they are skipped with a warning.  Per object: ray visibility (camera, shadow,
diffuse/glossy/transmission), holdout and each material's Principled Alpha.  Meshes whose
materials read textures also carry per-corner UVs (one UV map), colour attributes and MikkTSpace
tangents (``corner_attributes``); meshes of untextured materials carry none (unchanged export).

Identity for the data passes and Cryptomatte (engine.render.data_passes): each Mesh carries its object's
name, Object Index (``pass_index``) and asset (the top-level parent's name, as Cycles), its material's name
(Cycles' "default_surface" for an empty slot) and Material Index; while :data:`PASS_UV` is set (a UV pass
was asked for: ``polar_addon.passes``), also the active render UV map per corner (``Mesh.pass_uv``).
"""

import contextvars

import numpy as np

from ...engine.errors import SceneError
from ...engine.scene.description import Mesh
from ...engine.scene.shapes import icosphere
from .. import compat
from .images import texture_source
from .materials import attribute_needs
from .node_links import follow
from .normal_maps import normal_input_unsupported


GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META", "CURVES", "POINTCLOUD"}
#: Object types whose evaluated mesh the depsgraph also lists as a mesh instance of the object.
CONVERTED_TYPES = {"CURVE", "SURFACE", "FONT", "META"}
#: Object types Cycles renders that Polar does not (warned once per object).
UNSUPPORTED_TYPES = {"GREASEPENCIL": "Grease Pencil strokes"}      # (Volume objects: export.volumes)
#: Sides of the tube around each hair segment; icosphere level of each point of a point cloud.
HAIR_SIDES = 6
POINT_SUBDIVISIONS = 1
#: Cycles' radius of hair points without a ``radius`` attribute (scene units).
DEFAULT_HAIR_RADIUS = 0.005
#: True while exporting for a render with a UV pass: meshes then carry their active render UV map
#: (``Mesh.pass_uv``); False (the default): nothing is read for it
PASS_UV = contextvars.ContextVar("polar_export_pass_uv", default=False)
#: Keys of :func:`object_rays`' dict that are the object's identity (Mesh attributes, not dataclass fields)
IDENTITY_KEYS = ("object_name", "pass_index", "asset_name")
#: The material name Cycles hashes (Cryptomatte) for an empty material slot
DEFAULT_MATERIAL_NAME = "default_surface"


def mesh_arrays(obj):
    """World-independent triangle data of an evaluated object: positions (T·3, 3) per corner,
    split (shading) normals per corner, and the material slot index per triangle; None if empty
    (also when the object has no mesh, e.g. curves without a surface)."""
    try:
        me = obj.to_mesh()
    except RuntimeError:              # "Object does not have geometry data"
        return None
    if me is None:
        obj.to_mesh_clear()
        return None
    try:
        me.calc_loop_triangles()
        nv, nt = len(me.vertices), len(me.loop_triangles)
        if nt == 0:
            return None
        P = np.empty(nv * 3, np.float32)
        me.attributes["position"].data.foreach_get("vector", P)
        F = np.empty(nt * 3, np.int32)
        me.loop_triangles.foreach_get("vertices", F)
        SN = np.empty(nt * 9, np.float32)
        me.loop_triangles.foreach_get("split_normals", SN)
        tri_poly = np.empty(nt, np.int32)
        me.loop_triangle_polygons.foreach_get("value", tri_poly)
        mi = me.attributes.get("material_index")
        if mi is not None and len(me.polygons):
            poly_mat = np.empty(len(me.polygons), np.int32)
            mi.data.foreach_get("value", poly_mat)
            tri_mat = poly_mat[tri_poly]
        else:
            tri_mat = np.zeros(nt, np.int32)
        arrays = (P.reshape(nv, 3).astype(np.float64), F.reshape(nt, 3), SN.reshape(nt * 3, 3).astype(np.float64),
                  tri_mat)
        needs = _attribute_needs(obj)
        pass_uv = _pass_uv(me) if PASS_UV.get() else None
        if needs is None:
            if pass_uv is None:
                return arrays
            return arrays + ({"warnings": [], "uv": None, "uv_map": None, "tangents": None, "colors": {},
                              "needs": None, "pass_uv": pass_uv},)
        attributes = corner_attributes(me, obj.name, needs)
        attributes["pass_uv"] = pass_uv
        return arrays + (attributes,)
    finally:
        obj.to_mesh_clear()


def _pass_uv(me):
    """The active render UV map per loop-triangle corner (nt·3, 2) float32 (the UV pass's), or None."""
    layer = next((layer for layer in me.uv_layers if layer.active_render), None)
    if layer is None:
        return None
    nt = len(me.loop_triangles)
    loops = np.empty(nt * 3, np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    uv = np.empty(len(me.loops) * 2, np.float32)
    layer.uv.foreach_get("vector", uv)
    return uv.reshape(-1, 2)[loops]


def attributes_outdated(obj, arrays) -> bool:
    """True if ``arrays`` (from :func:`geometry_arrays`) lack mesh attributes that the object's
    materials now read, or carry ones they no longer read (the viewport re-reads the mesh after a
    material edit that adds or removes a texture)."""
    if arrays is None or obj.type in ("POINTCLOUD", "CURVES"):
        return False
    stored = arrays[4]["needs"] if len(arrays) > 4 else None
    return _attribute_needs(obj) != stored


def geometry_unchanged(obj, arrays) -> bool:
    """True if the evaluated mesh object ``obj`` still has the vertex positions and triangles of
    ``arrays`` (from :func:`geometry_arrays`), compared exactly; False for other object types
    (which the caller then re-reads).  Reads positions and triangle indices only: a fraction of
    :func:`mesh_arrays`' cost (no normals, attributes or to_mesh copy)."""
    if arrays is None or obj.type != "MESH":
        return False
    me = obj.data
    P, F = arrays[0], arrays[1]
    if len(me.vertices) != len(P) or len(me.loop_triangles) != len(F):
        return False
    positions = np.empty(P.size, np.float32)
    me.attributes["position"].data.foreach_get("vector", positions)
    if not np.array_equal(positions.reshape(P.shape), P):
        return False
    triangles = np.empty(F.size, np.int32)
    me.loop_triangles.foreach_get("vertices", triangles)
    return np.array_equal(triangles.reshape(F.shape), F)


def _attribute_needs(obj):
    """What the materials of ``obj`` read from its mesh (materials.attribute_needs, merged), or None."""
    merged = {"uv": [], "tangents": [], "colors": [], "bake": []}
    for slot in obj.material_slots:
        if slot.material is None or compat.node_tree_in_use(slot.material) is None:
            continue
        for k, v in attribute_needs(slot.material).items():
            merged[k].extend(v)
    merged = {k: list(dict.fromkeys(v)) for k, v in merged.items()}
    return merged if any(merged.values()) else None


def corner_attributes(me, name, needs) -> dict:
    """Per loop-triangle corner (nt·3 rows, the order of ``mesh_arrays``' corners) UVs (nt·3, 2),
    colour attributes {name: (nt·3, 4) linear} and MikkTSpace tangents (nt·3, 4: object-space xyz,
    bitangent sign), as ``needs`` asks; "warnings" lists what could not be read.  The engine has
    one UV map per mesh: the first map a texture asks for (the active render map for ''), else —
    when only baked inputs need one — the active render map; "uv_map" names it (baked inputs are
    baked on it), None if none is exported (a missing map the bake warns about itself)."""
    nt = len(me.loop_triangles)
    loops = np.empty(nt * 3, np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    out = {"warnings": [], "uv": None, "uv_map": None, "tangents": None, "colors": {}, "needs": needs}
    active = next((layer.name for layer in me.uv_layers if layer.active_render), None)
    maps = [m or active for m in needs["uv"] + needs["tangents"]]
    maps = list(dict.fromkeys(m for m in maps if m is not None))
    found = [m for m in maps if m in me.uv_layers]
    if len(found) < len(maps) or (needs["uv"] and not maps):
        out["warnings"].append(f"object {name!r}: UV map {next((m for m in maps if m not in found), '')!r} asked for "
                               "by its materials is missing; textures read (0, 0) there")
    if len(found) > 1:
        out["warnings"].append(f"object {name!r}: its materials use UV maps {', '.join(map(repr, found))}; only "
                               f"{found[0]!r} is exported (one UV map per mesh)")
    if not found and needs.get("bake") and active is not None:     # baked inputs only: the active render map
        found = [active]
    if found:
        out["uv_map"] = found[0]
        uv = np.empty(len(me.loops) * 2, np.float32)
        me.uv_layers[found[0]].uv.foreach_get("vector", uv)
        out["uv"] = uv.reshape(-1, 2)[loops].astype(np.float64)
        if needs["tangents"]:
            try:
                me.calc_tangents(uvmap=found[0])
            except RuntimeError as e:       # n-gons: MikkTSpace in Blender needs tris/quads
                out["warnings"].append(f"object {name!r}: no UV tangents ({e}); normal maps use tangents from the "
                                       "UV gradients")
            else:
                t = np.empty(len(me.loops) * 3, np.float32)
                me.loops.foreach_get("tangent", t)
                sign = np.empty(len(me.loops), np.float32)
                me.loops.foreach_get("bitangent_sign", sign)
                out["tangents"] = np.column_stack((t.reshape(-1, 3)[loops], sign[loops])).astype(np.float64)
    vertex_of_loop = None
    for key in needs["colors"]:
        layer_name = key or me.color_attributes.default_color_name or \
            (me.color_attributes.active_color.name if me.color_attributes.active_color is not None else "")
        attr = me.color_attributes.get(layer_name)
        if attr is None:
            out["warnings"].append(f"object {name!r}: colour attribute {layer_name!r} asked for by its materials is "
                                   "missing; it reads 0")
            continue
        values = np.empty(len(attr.data) * 4, np.float32)
        attr.data.foreach_get("color", values)          # linear for byte and float colours alike
        values = values.reshape(-1, 4)
        if attr.domain == "POINT":
            if vertex_of_loop is None:
                vertex_of_loop = np.empty(len(me.loops), np.int32)
                me.loops.foreach_get("vertex_index", vertex_of_loop)
            values = values[vertex_of_loop]
        out["colors"][key] = values[loops].astype(np.float64)
    return out


def _attribute(data, name, n, width=1):
    """Float attribute ``name`` of a point domain as an (n,) or (n, width) array, or None."""
    attr = data.attributes.get(name)
    if attr is None or len(attr.data) != n:
        return None
    out = np.empty(n * width, np.float32)
    attr.data.foreach_get("vector" if width == 3 else "value", out)
    return out.reshape(n, width) if width > 1 else out


def _icosphere_template():
    """Unit icosphere scaled so its surface area is the sphere's 4π: by Cauchy's formula its mean
    projected area (the coverage seen from a random direction) is then that of the true sphere."""
    ico = icosphere(POINT_SUBDIVISIONS)
    v, f = np.asarray(ico.vertices, np.float64), np.asarray(ico.faces, np.int32)
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum()
    return v * np.sqrt(4 * np.pi / area), f


def pointcloud_arrays(obj):
    """Spheres (icospheres with smooth normals) of each point's ``radius`` (default 0.01), in the
    ``mesh_arrays`` layout; None for an empty cloud."""
    data = obj.data
    n = len(data.points)
    if n == 0:
        return None
    centres = _attribute(data, "position", n, 3).astype(np.float64)
    radius = _attribute(data, "radius", n)
    radius = np.full(n, 0.01) if radius is None else np.abs(radius.astype(np.float64))
    unit, faces = _icosphere_template()
    nv = unit.shape[0]
    P = (centres[:, None, :] + radius[:, None, None] * unit[None]).reshape(-1, 3)
    F = (faces[None] + (np.arange(n) * nv)[:, None, None]).reshape(-1, 3)
    SN = np.tile((unit / np.linalg.norm(unit, axis=1, keepdims=True))[faces].reshape(-1, 3), (n, 1))
    keep = np.repeat(radius > 0, faces.shape[0])
    if not keep.any():
        return None
    corner_keep = np.repeat(keep, 3)
    return P, F[keep], SN[corner_keep], np.zeros(int(keep.sum()), np.int32)


def hair_arrays(obj):
    """Tubes of HAIR_SIDES sides around every segment of a hair-curves object (radius per point,
    Cycles' default 0.005), in the ``mesh_arrays`` layout; None if there is no segment."""
    data = obj.data
    n_curves, n_points = len(data.curves), len(data.points)
    if n_curves == 0 or n_points < 2:
        return None
    pos = _attribute(data, "position", n_points, 3).astype(np.float64)
    radius = _attribute(data, "radius", n_points)
    radius = np.full(n_points, DEFAULT_HAIR_RADIUS) if radius is None else np.abs(radius.astype(np.float64))
    offsets = np.empty(n_curves + 1, np.int32)
    data.curve_offset_data.foreach_get("value", offsets)
    last = np.zeros(n_points, bool)
    last[offsets[1:] - 1] = True                   # a segment starts at every point but a curve's last
    start = np.nonzero(~last)[0]
    a, b = pos[start], pos[start + 1]
    axis = b - a
    length = np.linalg.norm(axis, axis=1)
    ok = length > 0
    start, a, b, axis, length = start[ok], a[ok], b[ok], axis[ok], length[ok]
    if start.size == 0:
        return None
    t = axis / length[:, None]
    helper = np.where(np.abs(t[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(t, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(t, e1)
    ang = 2 * np.pi * np.arange(HAIR_SIDES) / HAIR_SIDES
    # polygon of the tube scaled to the circle's mean width (perimeter / π = 2r): same average coverage
    widen = np.pi / (HAIR_SIDES * np.sin(np.pi / HAIR_SIDES))
    radius = radius * widen
    ring = np.cos(ang)[None, :, None] * e1[:, None, :] + np.sin(ang)[None, :, None] * e2[:, None, :]  # (S, K, 3)
    ra, rb = radius[start][:, None, None], radius[start + 1][:, None, None]
    verts = np.concatenate((a[:, None] + ra * ring, b[:, None] + rb * ring), axis=1)          # (S, 2K, 3)
    normals = np.concatenate((ring, ring), axis=1)
    k = np.arange(HAIR_SIDES)
    k1 = (k + 1) % HAIR_SIDES
    # quad (a_k, a_k1, b_k1, b_k) as two counter-clockwise triangles seen from outside
    quad = np.stack((np.stack((k, k1, HAIR_SIDES + k1), 1), np.stack((k, HAIR_SIDES + k1, HAIR_SIDES + k), 1)), 1)
    quad = quad.reshape(-1, 3)
    nseg = start.size
    F = (quad[None] + (np.arange(nseg) * 2 * HAIR_SIDES)[:, None, None]).reshape(-1, 3).astype(np.int32)
    P = verts.reshape(-1, 3)
    SN = normals.reshape(-1, 3)[F.ravel()]
    return P, F, SN, np.zeros(F.shape[0], np.int32)


def geometry_arrays(obj):
    """``mesh_arrays`` for any renderable object type (mesh, hair curves, point cloud)."""
    if obj.type == "POINTCLOUD":
        return pointcloud_arrays(obj)
    if obj.type == "CURVES":
        return hair_arrays(obj)
    return mesh_arrays(obj)


def times_alpha(a, b, material, warnings):
    """The product of two alphas (numbers or TexturedNumbers): a Principled Alpha and a Mix Shader's
    transparency; two textured ones: the first, one warning."""
    from ...engine.textures import TextureInput, TexturedNumber
    if not isinstance(a, TexturedNumber) and not isinstance(b, TexturedNumber):
        return float(a) * float(b)
    if isinstance(a, TexturedNumber) and isinstance(b, TexturedNumber):
        warnings.append(f"material {material.name!r}: two textured transparencies (Alpha and a Transparent mix); "
                        "only the Alpha is rendered")
        return a
    tex, c = (a, float(b)) if isinstance(a, TexturedNumber) else (b, float(a))
    if c == 1.0:
        return tex
    src = tex.source
    scaled = TextureInput(src.texture, src.channel, src.scale * c, src.offset * c, src.power)
    return TexturedNumber(scaled).clamped_to(0.0, 1.0)


def material_alpha(material, warnings):
    """Principled Alpha of a material's surface shader (1 if none): a number, or a TexturedNumber where
    Alpha comes from an image (its alpha or a channel), a Separate Color of one or a colour attribute —
    anything else linked keeps its own value with one warning; also warns about a linked Normal input
    that is not an exported normal or bump map (normal_maps.normal_input_unsupported)."""
    tree = compat.node_tree_in_use(material) if material is not None else None
    if tree is None:
        return 1.0
    output = tree.get_output_node("ALL") or tree.get_output_node("CYCLES")
    node = follow(output.inputs["Surface"]) if output is not None else None
    if node is None:
        # a volume alone: Cycles' surface is transparent (the interior is the material's: materials.py)
        volume = output.inputs.get("Volume") if output is not None else None
        return 0.0 if volume is not None and follow(volume) is not None else 1.0
    if normal_input_unsupported(node):
        warnings.append(f"material {material.name!r}: bump and normal maps (linked Normal input) are not "
                        "supported; the geometric shading normals are used")
    alpha = node.inputs.get("Alpha") if node.bl_idname == "ShaderNodeBsdfPrincipled" else None
    if alpha is None:
        return 1.0
    if alpha.is_linked:
        # an image's alpha (glTF cut-outs and blends), a channel of one, a colour attribute: per point
        source = texture_source(alpha, material.name, warnings)
        if source is not None:
            from ...engine.textures import TexturedNumber
            return TexturedNumber(source).clamped_to(0.0, 1.0)
        warnings.append(f"material {material.name!r}: Alpha is linked to a graph that is not an image or colour "
                        "attribute (not baked for alpha); its own value is used")
    value = float(alpha.default_value)
    if not np.isfinite(value):
        raise SceneError(f"material {material.name!r}", "input 'Alpha' must be a number in [0, 1]")
    return min(max(value, 0.0), 1.0)


def object_rays(obj, view_layer, warnings) -> dict:
    """Cycles' Object ▸ Visibility of an (evaluated) object as engine Mesh fields."""
    diffuse, glossy, transmission = (bool(getattr(obj, f"visible_{k}", True))
                                     for k in ("diffuse", "glossy", "transmission"))
    if len({diffuse, glossy, transmission}) > 1:
        warnings.append(f"object {obj.name!r}: visibility to only some of diffuse, glossy and transmission rays "
                        "is not supported; it is " + ("visible to all of them" if diffuse or glossy or transmission
                                                      else "hidden from all of them"))
    if not getattr(obj, "visible_volume_scatter", True):
        pass                              # no volumes in Polar: nothing to hide from
    holdout = bool(getattr(obj, "is_holdout", False))
    try:
        holdout = holdout or bool(obj.original.holdout_get(view_layer=view_layer))
    except (AttributeError, TypeError, RuntimeError):
        pass
    return {"visible_camera": bool(getattr(obj, "visible_camera", True)),
            "visible_shadow": bool(getattr(obj, "visible_shadow", True)),
            "visible_indirect": diffuse or glossy or transmission, "holdout": holdout, **object_identity(obj)}


def object_identity(obj) -> dict:
    """The object's identity for the data passes and Cryptomatte (IDENTITY_KEYS): its name, Object Index and
    asset — the name of its top-level parent (itself without one), as Cycles hashes it."""
    top = getattr(obj, "original", obj)
    seen = set()
    while getattr(top, "parent", None) is not None and id(top) not in seen:
        seen.add(id(top))
        top = top.parent
    return {"object_name": str(obj.name), "pass_index": int(getattr(obj, "pass_index", 0)),
            "asset_name": str(top.name)}


def object_meshes(name, arrays, M, slots, material_key, emissions, alphas, rays, warnings):
    """Engine Meshes of one object instance: ``arrays`` from :func:`geometry_arrays` placed by the
    4×4 world matrix ``M``, one Mesh per material slot used.  ``slots``: the slots' materials;
    ``material_key(material)``: its name in the scene's materials (exported on first use), whose
    ``emissions[key]`` and ``alphas[key]`` the Meshes take; ``rays()``: the object's ray visibility
    (:func:`object_rays`).  [] (with a warning) if nothing is left.  Used per instance by
    :func:`export_scene` and by the viewport's incremental export."""
    P, F, SN, tri_mat = arrays[:4]
    attributes = arrays[4] if len(arrays) > 4 else None     # per-corner UVs, colours, tangents (textures)
    if attributes is not None:
        warnings.extend(attributes["warnings"])
    if not np.all(np.isfinite(P)):
        raise SceneError(f"object {name!r}", "has non-finite vertex coordinates")
    Pw = P @ M[:3, :3].T + M[:3, 3]
    normal_matrix = np.linalg.inv(M[:3, :3]).T if abs(np.linalg.det(M[:3, :3])) > 1e-300 else None
    if normal_matrix is None:
        warnings.append(f"object {name!r} has a singular transform (zero scale); skipped")
        return []
    tri = Pw[F]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    degenerate = ~(area2 > 0)
    if degenerate.all():
        warnings.append(f"object {name!r} has only zero-area faces; skipped")
        return []
    if degenerate.any():
        warnings.append(f"object {name!r}: {int(degenerate.sum())} zero-area faces ignored")
    N = SN @ normal_matrix.T
    length = np.linalg.norm(N, axis=1, keepdims=True)
    N = np.where(length > 0, N / np.where(length > 0, length, 1.0), 0.0)
    mirrored = np.linalg.det(M[:3, :3]) < 0   # keep front faces in front under negative scale
    ray_fields = dict(rays())
    identity = {k: ray_fields.pop(k) for k in IDENTITY_KEYS if k in ray_fields}
    pass_uv = attributes.get("pass_uv") if attributes is not None else None
    keys = [material_key(slots[i] if i < len(slots) else None) for i in range(len(slots))]
    tri_mat = np.clip(tri_mat, 0, len(keys) - 1)
    meshes = []
    # One engine Mesh per (object, emissive material) so that emitters are separate lights.
    for slot in np.unique(tri_mat):
        sel = np.nonzero(tri_mat == slot)[0]
        key = keys[slot]
        corner = (sel[:, None] * 3 + np.arange(3)[None, :]).ravel()
        local_faces = np.arange(corner.size, dtype=np.int64).reshape(-1, 3)
        if mirrored:
            local_faces = local_faces[:, [0, 2, 1]]
        extra = {} if attributes is None else _corner_fields(attributes, corner, M, mirrored)
        mesh = Mesh(name=f"{name}:{slot}", vertices=Pw[F[sel]].reshape(-1, 3),
                    faces=local_faces, materials=[key], material_ids=np.zeros(len(sel), np.int32),
                    normals=N[corner], emission=emissions.get(key), alpha=alphas.get(key, 1.0),
                    **ray_fields, **extra)
        _set_identity(mesh, identity, slots[slot] if slot < len(slots) else None,
                      None if pass_uv is None else pass_uv[corner])
        meshes.append(mesh)
    return meshes


def _set_identity(mesh, identity, material, pass_uv) -> None:
    """Give ``mesh`` its object's ``identity`` (object_identity), its Blender ``material``'s name and Material
    Index (None: Cycles' default surface, index 0) and the UV pass's ``pass_uv`` — instance attributes of the
    engine Mesh (engine.scene.description.Mesh), set only when they differ from its defaults."""
    for key, value in identity.items():
        setattr(mesh, key, value)
    mesh.material_names = [material.name if material is not None else DEFAULT_MATERIAL_NAME]
    index = int(getattr(material, "pass_index", 0)) if material is not None else 0
    if index:
        mesh.material_pass_indices = [index]
    if pass_uv is not None:
        mesh.pass_uv = pass_uv


def _corner_fields(attributes, corner, M, mirrored) -> dict:
    """Mesh fields uv, colors, tangents of the corners ``corner`` (vertices are split per corner, so
    per-corner data is per-vertex data).  Tangents are directions: placed by the linear part of M;
    a mirroring transform flips the handedness (bitangent = w·(n × t) must stay the +v direction)."""
    out = {}
    if attributes.get("uv") is not None:
        out["uv"] = attributes["uv"][corner]
    if attributes.get("colors"):
        out["colors"] = {k: v[corner] for k, v in attributes["colors"].items()}
    if attributes.get("tangents") is not None:
        t = attributes["tangents"][corner]
        xyz = t[:, :3] @ M[:3, :3].T
        length = np.linalg.norm(xyz, axis=1, keepdims=True)
        xyz = np.where(length > 0, xyz / np.where(length > 0, length, 1.0), 0.0)   # 0: derived from the UVs
        w = np.where(t[:, 3] < 0, -1.0, 1.0) * (-1.0 if mirrored else 1.0)
        out["tangents"] = np.column_stack((xyz, w))
    return out
