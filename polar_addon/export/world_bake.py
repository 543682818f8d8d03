"""Bake a Blender world into an equirectangular radiance map with Cycles.

Worlds that have no direct engine equivalent (Sky Texture, gradients, mixes, an Environment
Texture behind an unsupported mapping) are rendered by Cycles through a panoramic
equirectangular camera, in a separate Blender process: the world (with the images and node
groups it uses) is written to a temporary .blend with ``bpy.data.libraries.write``, the child
appends it into an empty file, renders it and writes an EXR that is read back here.  A child
process is used because a render cannot be started from inside a render (F12 runs Polar's
``render()`` on Blender's render thread, where calling ``bpy.ops.render.render`` is not
allowed); as a side effect nothing is ever added to the user's file.

Texel grid and directions are Cycles' Environment Texture's (engine ``grid="cycles"``): pixel
(i, j) of a W×H bake (row 0 = zenith) is the world seen along u = (i + ½)/W, v = (j + ½)/H
with u = (½ − atan2(d_y, d_x)/2π) mod 1, v = acos(d_z)/π.  The camera rotation (90°, 0, −90°)
gives exactly this mapping (verified: a 64×32 Environment Texture bakes to its own pixels).
With the default box filter of one pixel each texel is the mean over its pixel footprint
(``samples`` jittered samples, the World Bake Samples setting), so a small bright sun disc keeps
its power: at 1024 × 512 within ~2 % with 16 samples, within noise with 128.

Results are cached in memory for the session, keyed on a hash of every value of the world's
node tree (nodes, sockets, links, node groups, images) and the resolution: viewport updates and
re-renders of an unchanged world do not bake again.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from collections import OrderedDict

import numpy as np

#: default jittered samples per texel (a smooth world needs few; features smaller than a texel,
#: like a sun disc, need more for their power to be right)
BAKE_SAMPLES = 16
#: how many baked maps stay in memory (a 2048×1024 map is 25 MB)
CACHE_SIZE = 4

_cache: OrderedDict = OrderedDict()
#: number of Cycles bakes run in this session (tests check that the cache avoids re-baking)
bake_count = 0

# Node properties that only concern the editor, never the shading result.
_UI_PROPS = {"rna_type", "location", "location_absolute", "width", "height", "dimensions", "name", "label",
             "select", "show_options", "show_preview", "show_texture", "hide", "use_custom_color", "color",
             "color_tag", "parent", "internal_links", "warning_propagation", "is_active_output"}

_BAKE_JOB = r'''
import hashlib, math, os, sys
import numpy as np
import bpy
blend, world_name, out, width, height, samples, filter_width, frame = sys.argv[-8:]
bpy.ops.wm.read_homefile(use_empty=True)
with bpy.data.libraries.load(blend, link=False) as (src, dst):
    dst.worlds = [world_name]
world = dst.worlds[0]
for img in bpy.data.images:          # unsaved pixel edits, passed along as .npy files
    path = blend + "." + str(int.from_bytes(hashlib.sha1(img.name.encode()).digest()[:8], "little")) + ".npy"
    if os.path.exists(path):
        px = np.load(path)
        if tuple(img.size) != (px.shape[1], px.shape[0]):
            img.scale(px.shape[1], px.shape[0])
        img.pixels.foreach_set(px.ravel())
scene = bpy.context.scene
scene.world = world
world.cycles_visibility.camera = True
scene.frame_set(int(frame))
cam = bpy.data.objects.new("polar_bake_camera", bpy.data.cameras.new("polar_bake_camera"))
cam.data.type = "PANO"
cam.data.panorama_type = "EQUIRECTANGULAR"
cam.rotation_euler = (math.pi / 2, 0.0, -math.pi / 2)
scene.collection.objects.link(cam)
scene.camera = cam
r = scene.render
r.engine = "CYCLES"
r.resolution_x, r.resolution_y, r.resolution_percentage = int(width), int(height), 100
r.film_transparent = False
r.use_compositing = False
r.use_sequencer = False
c = scene.cycles
c.device = "CPU"
c.samples = int(samples)
c.use_adaptive_sampling = False
c.use_denoising = False
c.pixel_filter_type = "BOX"
c.filter_width = float(filter_width)
c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
ims = r.image_settings
ims.file_format = "OPEN_EXR"
ims.color_depth = "32"
r.filepath = out
bpy.ops.render.render(write_still=True)
'''


def _value(v):
    """A hashable, repr-stable form of an RNA property value."""
    try:
        return tuple(_value(x) for x in v) if hasattr(v, "__len__") and not isinstance(v, str) else v
    except TypeError:
        return repr(v)


def _image_key(image):
    if image is None:
        return None
    key = (image.name_full, image.source, _image_path(image), tuple(image.size), image.colorspace_settings.name,
           image.alpha_mode, image.packed_file is not None, image.is_dirty, image.is_float)
    if image.is_dirty or image.source == "GENERATED":
        # unsaved edits: the pixels themselves are the state
        key += (hashlib.sha1(_pixels(image).tobytes()).hexdigest(),)
    return key


def _image_path(image):
    import bpy
    return bpy.path.abspath(image.filepath, library=image.library) if image.filepath else ""


def _pixels(image) -> np.ndarray:
    """The image's pixels (H, W, channels) float32 as Blender holds them, row 0 at the bottom."""
    w, h = image.size
    px = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(h, w, image.channels)


def _struct_key(struct, depth=0, seen=None):
    """Every shading-relevant property of an RNA struct, recursing into sub-structs, images,
    objects (their world matrix) and node groups."""
    import bpy
    seen = set() if seen is None else seen
    if struct is None or depth > 6:
        return None
    out = []
    for prop in struct.bl_rna.properties:
        ident = prop.identifier
        if ident in _UI_PROPS or ident.startswith("bl_"):
            continue
        value = getattr(struct, ident, None)
        if prop.type == "POINTER":
            if isinstance(value, bpy.types.Image):
                out.append((ident, _image_key(value)))
            elif isinstance(value, bpy.types.NodeTree):
                out.append((ident, _tree_key(value, depth + 1, seen)))
            elif isinstance(value, bpy.types.Object):
                out.append((ident, value.name_full, _value(value.matrix_world)))
            elif isinstance(value, bpy.types.ID):
                out.append((ident, value.name_full))
            elif value is not None:
                out.append((ident, _struct_key(value, depth + 1, seen)))
        elif prop.type == "COLLECTION":
            if ident not in ("inputs", "outputs"):
                out.append((ident, tuple(_struct_key(item, depth + 1, seen) for item in value)))
        else:
            out.append((ident, _value(value)))
    return tuple(out)


def _tree_key(tree, depth=0, seen=None):
    seen = set() if seen is None else seen
    if tree is None:
        return None
    if tree.name_full in seen:
        return ("tree", tree.name_full)
    seen.add(tree.name_full)
    nodes = []
    for node in sorted(tree.nodes, key=lambda n: n.name):
        sockets = tuple((s.identifier, _value(getattr(s, "default_value", None)), s.is_linked)
                        for s in node.inputs)
        nodes.append((node.name, node.bl_idname, node.mute, _struct_key(node, depth, seen), sockets))
    links = sorted((lk.from_node.name, lk.from_socket.identifier, lk.to_node.name, lk.to_socket.identifier,
                    lk.is_muted) for lk in tree.links)
    return tree.name_full, tuple(nodes), tuple(links)


def world_key(world, settings) -> str:
    """Hash of everything in ``world`` that Cycles' rendering of it depends on, and the bake ``settings``."""
    parts = (world.name_full, _value(world.color), _tree_key(world.node_tree), tuple(settings))
    return hashlib.sha1(repr(parts).encode()).hexdigest()


def _images_in(tree, found=None):
    found = {} if found is None else found
    if tree is None:
        return found
    for node in tree.nodes:
        image = getattr(node, "image", None)
        if image is not None:
            found[image.name] = image
        if getattr(node, "node_tree", None) is not None:
            _images_in(node.node_tree, found)
    return found


def _child_command(script: str, args) -> list:
    import bpy
    if bpy.app.binary_path:        # a Blender executable: run it in background mode
        return [bpy.app.binary_path, "-b", "--factory-startup", "--python-expr", script, "--", *args]
    return [sys.executable, "-c", script, *args]     # the bpy module: its own Python imports bpy


def _read_exr(path) -> np.ndarray:
    import OpenEXR
    with OpenEXR.File(path, separate_channels=True) as f:
        channels = {name: np.asarray(c.pixels) for part in f.parts for name, c in part.channels.items()}
    return np.stack([channels[k] for k in ("R", "G", "B")], axis=-1).astype(np.float32)   # row 0 = top


def bake_world(world, resolution=(1024, 512), frame=1, samples=BAKE_SAMPLES, filter_width=1.0):
    """Linear-sRGB radiance (H, W, 3) float32 (finite, ≥ 0; shared by the cache: do not modify)
    of ``world`` rendered by Cycles, row 0 = zenith, on
    Cycles' texel grid (see the module docstring); cached by :func:`world_key`.  ``samples`` and
    ``filter_width`` (pixels, box filter) set the texel footprint: 1 sample with a tiny filter
    point-samples the texel centres."""
    global bake_count
    import bpy
    world = getattr(world, "original", world)
    width, height = int(resolution[0]), int(resolution[1])
    # an animated world (keyframes or drivers on it or its node tree) differs per frame
    animated = any(getattr(x, "animation_data", None) is not None for x in (world, world.node_tree))
    key = world_key(world, (width, height, samples, filter_width, frame if animated else None))
    if key in _cache:
        _cache.move_to_end(key)
        return _cache[key]
    tmp = tempfile.mkdtemp(prefix="polar_world_bake_")
    try:
        blend = os.path.join(tmp, "world.blend")
        bpy.data.libraries.write(blend, {world}, path_remap="ABSOLUTE", fake_user=True)
        for image in _images_in(world.node_tree).values():
            if image.is_dirty or (image.source == "GENERATED" and image.packed_file is None):
                np.save(blend + "." + str(_name_hash(image.name)) + ".npy", _pixels(image))
        out = os.path.join(tmp, "bake.exr")
        args = [blend, world.name, out, str(width), str(height), str(samples), repr(float(filter_width)),
                str(int(frame))]
        proc = subprocess.run(_child_command(_BAKE_JOB, args), capture_output=True, text=True)
        if proc.returncode != 0 or not os.path.exists(out):
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-5:]
            raise RuntimeError(f"baking world {world.name!r} with Cycles failed: {' | '.join(tail)}")
        # radiance is finite and ≥ 0 (the engine rejects anything else)
        texels = np.ascontiguousarray(np.maximum(np.nan_to_num(_read_exr(out), nan=0.0, posinf=0.0,
                                                               neginf=0.0), np.float32(0.0)))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    texels.flags.writeable = False
    bake_count += 1
    _cache[key] = texels
    while len(_cache) > CACHE_SIZE:
        _cache.popitem(last=False)
    return texels


def _name_hash(name: str) -> int:
    """A process-independent hash of an image name (Python's str hash is salted per process)."""
    return int.from_bytes(hashlib.sha1(name.encode()).digest()[:8], "little")


def clear_cache():
    _cache.clear()
