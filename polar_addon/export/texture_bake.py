"""Cycles bakes of material inputs that Polar cannot evaluate itself (procedural textures and any
other node graph feeding a colour or float input) into float images on the object's UV map.

:func:`bake_input` is the whole interface: it returns an engine :class:`TextureInput` over an
:class:`ImageTexture` (``resolution``² texels, row 0 at v = 0, looked up through the UV map the
object's mesh exports: the active render map unless a texture of its materials names another)
holding exactly the linear values the socket receives in Cycles (no view transform, no clamping:
``node_reader._linked_input_fallback`` clamps to the input's range), or None with one warning naming
the material and the input when the object has no UV map (or is not a mesh).

How: everything happens on temporary datablocks, all removed afterwards (the user's file is never
changed, not even for the duration of the bake): a scene ``__polar_bake`` (Cycles, 1 sample, CPU),
a copy of the object's evaluated mesh with only the faces of the material's slot (the texture
space of the original kept, so Generated coordinates are unchanged) placed at the object's world
matrix, a copy of the material whose active output is an Emission shader fed by the socket's source
(float inputs through a Math node, so the source goes through the same implicit colour → float
conversion as in the original graph), and a float Non-Color image as the active Image Texture
node.  ``bpy.ops.object.bake(type='EMIT')`` then writes Emission = the socket's value per texel.
One sample per texel: each texel holds the graph's value at its centre ((i + ½)/W, (j + ½)/H) in UV,
the engine's bilinear lookup interpolates between centres as for any image.

Where: the exporter calls this from the engine's ``render()`` (verified headless: ``blender -b`` and
the bpy module, where ``render()`` runs on the main thread).  In an interactive Blender, F12 runs
``render()`` on a job thread; the bake operator called from there is not verified.  Blender's
bake operator also resets ``G.is_rendering`` when it finishes.

Bakes are cached in memory per (object, object data, material, socket, node-graph values, UV map
and positions, world matrix, resolution): a re-export with nothing changed does not re-bake.
Bake times go to the ``polar.bake`` logger and to :data:`BAKE_CACHE`'s counters.
"""

from __future__ import annotations

import hashlib
import logging
import time

import numpy as np

from ...engine.textures import ImageTexture, TextureInput

log = logging.getLogger("polar.bake")

RESOLUTION_MIN, RESOLUTION_MAX = 8, 8192
#: Pixels of margin (dilation into unused texels) per 512 texels, so that bilinear lookups at the
#: edge of a UV island do not blend with empty texels.
MARGIN_PER_512 = 4
TEMP_NAME = "__polar_bake"
#: Blender socket types whose values are colours (3 channels) and numbers (1 channel).
COLOUR_SOCKETS = {"RGBA", "VECTOR"}
FLOAT_SOCKETS = {"VALUE", "INT", "BOOLEAN"}


class BakeCache:
    """Baked textures by key (see the module docstring), with counters of bakes, hits and seconds."""

    def __init__(self, max_entries: int = 64):
        self.entries: dict = {}
        self.max_entries = max_entries
        self.bakes = self.hits = 0
        self.seconds = 0.0

    def get(self, key):
        value = self.entries.get(key)
        if value is not None:
            self.hits += 1
        return value

    def put(self, key, value, seconds):
        if len(self.entries) >= self.max_entries:          # oldest first (dicts keep insertion order)
            self.entries.pop(next(iter(self.entries)))
        self.entries[key] = value
        self.bakes += 1
        self.seconds += seconds

    def clear(self):
        self.entries.clear()
        self.bakes = self.hits = 0
        self.seconds = 0.0

    def mark(self) -> tuple:
        """The counters now, for :meth:`summary` of what happened since."""
        return self.bakes, self.hits, self.seconds

    def summary(self, since: tuple = (0, 0, 0.0)) -> str:
        """One line for render stats (bakes and their time, reuses since ``mark()``), '' if none."""
        bakes, hits, seconds = self.bakes - since[0], self.hits - since[1], self.seconds - since[2]
        if not (bakes or hits):
            return ""
        return f"texture bakes: {bakes} in {seconds:.2f} s, {hits} reused"


#: The process-wide cache used by the exporter.
BAKE_CACHE = BakeCache()


def check_resolution(resolution) -> int:
    """The bake resolution as an int, or ValueError naming the setting and its range."""
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) \
            or not RESOLUTION_MIN <= resolution <= RESOLUTION_MAX:
        raise ValueError(f"texture_bake_resolution must be an integer in [{RESOLUTION_MIN}, {RESOLUTION_MAX}], "
                         f"got {resolution!r}")
    return int(resolution)


def source_socket(socket):
    """The output socket feeding an input socket, through reroutes; None if unlinked."""
    while socket is not None and socket.is_linked:
        link = socket.links[0]
        if link.is_muted:
            return None
        out = link.from_socket
        if out.node.bl_idname != "NodeReroute":
            return out
        socket = out.node.inputs[0]
    return None


def _value_repr(v):
    if hasattr(v, "__len__") and not isinstance(v, str):
        try:
            return tuple(_value_repr(x) for x in v)
        except TypeError:
            pass
    if hasattr(v, "name_full"):                 # an ID (image, node group, object): by name
        return ("ID", v.name_full)
    return v if isinstance(v, (int, float, str, bool, type(None))) else repr(v)


def tree_signature(tree, _seen=None) -> str:
    """Hash of everything in a node tree (and the groups it uses) that can change a baked value:
    nodes with their properties and input values, links, mutes."""
    seen = set() if _seen is None else _seen
    h = hashlib.sha1()
    if tree is None or tree.name_full in seen:
        return ""
    seen.add(tree.name_full)
    for node in sorted(tree.nodes, key=lambda n: n.name):
        h.update(repr((node.bl_idname, node.name, node.mute)).encode())
        for prop in node.bl_rna.properties:
            pid = prop.identifier
            if pid in ("rna_type", "location", "location_absolute", "width", "height", "dimensions", "select",
                       "show_options", "show_preview", "hide", "show_texture", "label", "color", "use_custom_color",
                       "parent", "inputs", "outputs", "internal_links", "bl_idname", "bl_label",
                       "bl_description", "bl_icon", "bl_static_type", "bl_width_default", "bl_width_min",
                       "bl_width_max", "bl_height_default", "bl_height_min", "bl_height_max", "warning_propagation"):
                continue
            try:
                value = getattr(node, pid)
            except (AttributeError, RuntimeError):
                continue
            kind = value.bl_rna.identifier if prop.type == "POINTER" and value is not None else ""
            if kind.endswith("NodeTree"):
                h.update(tree_signature(value, seen).encode())
            elif kind == "Image":              # by name, file and edit state (never its pixels: slow)
                h.update(repr((value.name_full, value.filepath, value.is_dirty)).encode())
            elif prop.type != "COLLECTION":
                h.update(repr((pid, _value_repr(value))).encode())
        for s in node.inputs:
            if hasattr(s, "default_value"):
                h.update(repr((s.identifier, _value_repr(s.default_value))).encode())
    for link in tree.links:
        h.update(repr((link.from_node.name, link.from_socket.identifier, link.to_node.name,
                       link.to_socket.identifier, link.is_muted)).encode())
    return h.hexdigest()


def _active_render_uv(mesh):
    return next((layer for layer in mesh.uv_layers if layer.active_render), None)


def _geometry_signature(mesh, uv) -> str:
    """Hash of the positions and UVs the bake depends on."""
    h = hashlib.sha1()
    p = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.attributes["position"].data.foreach_get("vector", p)
    t = np.empty(len(uv.uv) * 2, np.float32)
    uv.uv.foreach_get("vector", t)
    mi = mesh.attributes.get("material_index")
    m = np.empty(len(mesh.polygons), np.int32) if mi is not None else np.zeros(0, np.int32)
    if mi is not None:
        mi.data.foreach_get("value", m)
    for a in (p, t, m, np.asarray(mesh.texspace_location), np.asarray(mesh.texspace_size)):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _evaluated(obj):
    import bpy
    return obj if obj.is_evaluated else obj.evaluated_get(bpy.context.evaluated_depsgraph_get())


def bake_input(obj, material, socket, resolution: int, warnings: list, *, matrix=None, uv_map=None,
               cache: BakeCache | None = BAKE_CACHE) -> TextureInput | None:
    """Bake the graph feeding ``socket`` (an input of a shader node of ``material``) on ``obj``.

    ``obj``: the object (evaluated from a depsgraph, or original: then the context's depsgraph
    evaluates it); ``matrix``: its 4×4 world matrix (default ``obj.matrix_world``; an instance's
    matrix for instances); ``resolution``: texels per side.  Returns a TextureInput over a
    (resolution, resolution, C) float32 ImageTexture (C = 1 for float sockets, 3 for colours and
    vectors; linear "Linear"/"REPEAT" lookup) on the UV map ``uv_map`` (None or '': the active
    render map) — which the mesh exported for this object must carry — or None after appending one
    warning naming the material and the input (no UV map, not a mesh, or an unlinked socket).
    """
    resolution = check_resolution(resolution)
    where = f"material {material.name!r}: input {socket.name!r} of {socket.node.name!r}"
    source = source_socket(socket)
    if source is None:
        warnings.append(f"{where} is not linked to a texture graph; its own value is used")
        return None
    channels = 1 if socket.type in FLOAT_SOCKETS else 3
    obj_eval = _evaluated(obj)
    mesh = obj_eval.data if obj_eval.type == "MESH" else None
    uv = None if mesh is None else mesh.uv_layers.get(uv_map) if uv_map else _active_render_uv(mesh)
    if uv is None:
        which = f"UV map {uv_map!r}" if uv_map and mesh is not None and len(mesh.uv_layers) else "UV map"
        warnings.append(f"{where} is driven by a texture graph Polar cannot evaluate, and object "
                        f"{obj.name!r} has no {which} to bake it on; its own value is used")
        return None
    original = material.original if material.is_evaluated else material
    slot = next((i for i, s in enumerate(obj_eval.material_slots) if s.material is not None
                 and s.material.original == original), 0)
    M = np.asarray(obj_eval.matrix_world if matrix is None else matrix, np.float64).reshape(4, 4)
    key = (obj.original.name_full if obj.is_evaluated else obj.name_full, mesh.original.name_full,
           original.name_full, socket.node.name, socket.identifier, tree_signature(original.node_tree),
           uv.name, slot, _geometry_signature(mesh, uv), M.round(9).tobytes(), resolution)
    hit = cache.get(key) if cache is not None else None
    if hit is not None:
        log.info("%s: reused the %d² bake", where, resolution)
        return hit
    t0 = time.perf_counter()
    try:
        pixels = _bake_pixels(obj_eval, original, socket, source, slot, uv.name, M, resolution, channels)
    except RuntimeError as e:              # the operator's own report, e.g. Cycles disabled
        warnings.append(f"{where}: the Cycles bake failed ({str(e).strip()}); its own value is used")
        return None
    seconds = time.perf_counter() - t0
    texture = ImageTexture(pixels, "Linear", "REPEAT", name=f"bake:{original.name}/{socket.node.name}/{socket.name}",
                           field=where)
    result = TextureInput(texture)
    if cache is not None:
        cache.put(key, result, seconds)
    log.info("%s: baked %d² texels on UV map %r of %r in %.3f s", where, resolution, uv.name, obj.name, seconds)
    return result


def _bake_pixels(obj_eval, material, socket, source, slot, uv_name, M, resolution, channels) -> np.ndarray:
    """(resolution, resolution, channels) float32 of the socket's values, row 0 at v = 0."""
    import bmesh
    import bpy
    from mathutils import Matrix

    data = bpy.data
    scene = mesh = ob = mat = image = None
    try:
        scene = data.scenes.new(TEMP_NAME)
        scene.render.engine = "CYCLES"
        scene.cycles.device = "CPU"
        scene.cycles.samples = 1                 # the value at each texel's centre (see the docstring)
        scene.cycles.use_denoising = False
        scene.render.bake.use_clear = True

        mesh = data.meshes.new_from_object(obj_eval)
        mesh.name = TEMP_NAME
        src_mesh = obj_eval.data
        mesh.use_auto_texspace = False           # Generated coordinates as on the whole original mesh
        mesh.texspace_location, mesh.texspace_size = src_mesh.texspace_location, src_mesh.texspace_size
        if len(obj_eval.material_slots) > 1:     # only this material's faces write texels
            bm = bmesh.new()
            bm.from_mesh(mesh)
            bmesh.ops.delete(bm, geom=[f for f in bm.faces if f.material_index != slot], context="FACES")
            bm.to_mesh(mesh)
            bm.free()
        mat = material.copy()
        mat.name = TEMP_NAME
        mesh.materials.clear()
        mesh.materials.append(mat)
        mesh.polygons.foreach_set("material_index", np.zeros(len(mesh.polygons), np.int32))
        ob = data.objects.new(TEMP_NAME, mesh)
        ob.matrix_world = Matrix(M.tolist())
        scene.collection.objects.link(ob)

        image = data.images.new(TEMP_NAME, resolution, resolution, alpha=False, float_buffer=True, is_data=True)
        image.colorspace_settings.name = "Non-Color"   # values as baked: no colour-space conversion
        tree = mat.node_tree
        nodes, links = tree.nodes, tree.links
        src = next(o for o in nodes[source.node.name].outputs if o.identifier == source.identifier)
        emission = nodes.new("ShaderNodeEmission")
        emission.inputs["Strength"].default_value = 1.0
        if channels == 1:                          # same colour → float conversion as the original input
            to_float = nodes.new("ShaderNodeMath")
            to_float.operation, to_float.use_clamp = "ADD", False
            to_float.inputs[1].default_value = 0.0
            links.new(src, to_float.inputs[0])
            links.new(to_float.outputs[0], emission.inputs["Color"])
        else:
            links.new(src, emission.inputs["Color"])
        output = nodes.new("ShaderNodeOutputMaterial")
        output.target = "ALL"
        links.new(emission.outputs[0], output.inputs["Surface"])
        for node in nodes:
            if node.bl_idname == "ShaderNodeOutputMaterial":
                node.is_active_output = node == output
        target = nodes.new("ShaderNodeTexImage")
        target.image = image
        for node in nodes:
            node.select = False
        target.select = True
        nodes.active = target

        view_layer = scene.view_layers[0]
        ob.select_set(True, view_layer=view_layer)
        view_layer.objects.active = ob
        margin = max(1, MARGIN_PER_512 * resolution // 512)
        with bpy.context.temp_override(scene=scene, view_layer=view_layer, active_object=ob, object=ob,
                                       selected_objects=[ob], selected_editable_objects=[ob]):
            bpy.ops.object.bake(type="EMIT", uv_layer=uv_name, margin=margin, use_clear=True,
                                target="IMAGE_TEXTURES", save_mode="INTERNAL", use_selected_to_active=False)
        px = np.empty(resolution * resolution * 4, np.float32)
        image.pixels.foreach_get(px)           # row 0 = bottom = v 0, as the engine's ImageTexture
        px = px.reshape(resolution, resolution, 4)
        return np.ascontiguousarray(px[:, :, :1] if channels == 1 else px[:, :, :3])
    finally:
        for collection, item in ((data.objects, ob), (data.meshes, mesh), (data.materials, mat),
                                 (data.images, image), (data.scenes, scene)):
            if item is not None:
                collection.remove(item)
