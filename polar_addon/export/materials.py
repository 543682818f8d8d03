"""Blender materials → engine BSDFs (and emission).

A material's Surface may be
- a **Polarising BSDF** node: its model and inputs are used exactly;
- a standard shader, converted to the closest polarising model (docs/guide/blender.md, "Using it": existing scenes):
  Diffuse → Lambert; Glossy/Anisotropic → conductor from the colour (Gulbrandsen 2014);
  Metallic (Physical Conductor) → conductor with its n, k; Glass/Refraction → smooth dielectric, or
  with roughness r the rough dielectric (single-scattering GGX, α = r²; Cycles' Multiscatter GGX
  adds energy compensation, which is not modelled: one warning); Principled → conductor
  (Metallic ≥ 0.5), dielectric or rough dielectric as Glass (Transmission ≥ 0.5), Weidlich–Wilkie
  coat (Coat Weight > 0) or Torrance–Sparrow dielectric + Lambert (otherwise); Emission → emitter;
- anything else: grey Lambert with a warning.
Roughness r maps to the slope m = r² (as Cycles' α = r²); the engine's rule decides where that is
smooth (engine.materials.roughness: below SMOOTH_LIMIT = 1e-4 the smooth model, as for a scene file).
Every converted shader becomes declaration values built through ``MODELS[name].build`` (the
declaration range-checks them once; a NaN or out-of-range input is an error naming the material
and the input); only wrappers without a declaration (tints, Cycles' F82 curve, the anisotropic GGX
part of a Principled-like metal) are made here directly.

Textures (docs/guide/blender.md, "Using it": existing scenes): an input that a texturable parameter
reads may be linked to an Image Texture (the image's own pixels; its interpolation, extension and
colour space, sRGB images filtered on their encoded values where Cycles does so (``image_pixels``);
the UV map through UV Map / Texture Coordinate ▸ UV nodes and Mapping nodes) or to a Color
Attribute / Attribute node (a vertex colour); a roughness texture becomes m = r² per point
(``TextureInput(power=2)``).  A Normal Map node (tangent space) or a Bump node with an image
height on a shader's Normal input becomes the engine's normal or bump map (ShadingNormal).  An
image whose file is missing renders Cycles' magenta (1, 0, 1).  Anything else linked on such an
input (procedural textures, math nodes, …) goes through :func:`_linked_input_fallback`: when the
material is exported for an object (a :class:`BakeTarget`), Cycles bakes it to a float image on the
UV map the object's mesh exports (``texture_bake``), else its own value is used, with one warning.
"""

import hashlib
import math
import os
import weakref

import numpy as np

from ...engine.materials.lambert import Lambert
from ...engine.materials.catalogue import MODELS
from ...engine.materials.normal_map import set_bump_correction
from ...engine.materials.principled import IOR_MIN, WEIGHT_CUTOFF, film_gaps
from ...engine.materials.roughness import ALPHA_MIN, ROUGHNESS_MIN, effectively_smooth
from ...engine.errors import SceneError
from ...engine.textures import ImageTexture, TextureInput, VertexColour
from ...engine.textures.image import linear_to_srgb, srgb_to_linear
from ...engine.textures.texture import srgb_decode
from ...engine.spectral import (ConstantSpectrum, RGBIlluminantSpectrum, RGBReflectanceSpectrum,
                                RGBUnboundedSpectrum)
from .. import compat
from ..nodes.models import DIELECTRIC_PRESETS, NODE_MODELS
from .texture_bake import bake_input
from .world import interpolated_encoded

DEFAULT_ALBEDO = 0.8


def _source(socket):
    """(node, output socket) feeding an input socket (through reroutes), or (None, None)."""
    if not socket.is_linked:
        return None, None
    link = socket.links[0]
    node, out = link.from_node, link.from_socket
    while node is not None and node.bl_idname == "NodeReroute":
        if not node.inputs[0].is_linked:
            return None, None
        link = node.inputs[0].links[0]
        node, out = link.from_node, link.from_socket
    return node, out


def _follow(socket):
    """The node feeding an input socket (through reroutes), or None."""
    return _source(socket)[0]


# --------------------------------------------------------------------------- textures

#: Cycles' value for an image it cannot load (kernel IMAGE_TEXTURE_MISSING_RGBA): magenta
MISSING_RGBA = (1.0, 0.0, 1.0, 1.0)
#: Blender's Image Texture interpolation → the engine's (Cycles renders Smart as Cubic)
INTERPOLATION = {"Closest": "Closest", "Linear": "Linear", "Cubic": "Cubic", "Smart": "Cubic"}
#: byte-image colour spaces whose stored values are already linear numbers
LINEAR_SPACES = ("Non-Color", "Linear Rec.709", "Raw", "Linear", "Generic Data")

#: (roughness textures: image texels are kept ≥ engine.materials.roughness.ROUGHNESS_MIN, the least r whose
#: square is the least slope ALPHA_MIN: a textured m must stay ≥ it, there is no per-point smooth limit)

#: image name → (signature, pixel hash, linear float32 (H, W, 4) pixels, {texture key: ImageTexture},
#: warnings about the image (repeated on every export that uses it), the sRGB-encoded float32
#: (H, W, 4) pixels Cycles filters, or None (see image_pixels))
_IMAGES: dict = {}
#: images kept converted between exports (their pixels stay in memory)
IMAGE_CACHE_SIZE = 32


def _image_signature(image):
    """What identifies an image's pixels without reading them (file images that are not edited)."""
    path = image.filepath_from_user() if image.source == "FILE" else ""
    try:
        mtime = os.path.getmtime(path) if path else 0.0
    except OSError:
        mtime = -1.0
    packed = image.packed_file.size if image.packed_file is not None else 0
    # session_uid: a datablock of the same name in another file (or made anew) is another image
    return (image.name_full, getattr(image, "session_uid", 0), image.source, path, mtime, packed,
            image.colorspace_settings.name,
            bool(image.is_float), getattr(image, "generated_type", ""), tuple(getattr(image, "generated_color", ())),
            tuple(image.size))


def image_pixels(image, mat, warnings):
    """(linear float32 (H, W, 4) pixels, row 0 = v 0 (Blender's order), cache entry) of a Blender
    image; a missing file gives one magenta pixel and one warning naming the file.

    ``image.pixels`` holds what an 8-bit file stores (so sRGB images are decoded here with the sRGB
    transfer function, as Cycles' OpenColorIO sRGB); Blender loads 16-bit and float images
    (``is_float``) into scene-linear floats, used as they are (verified in bpy 5.0.1).  The images
    that Cycles keeps sRGB-encoded and filters so (world.interpolated_encoded: sRGB 8-bit images,
    sRGB float images read from their file) also keep their encoded pixels, entry[5]: as stored
    (8-bit), or the float buffer encoded again (what the file holds).  Images are
    cached per name and signature (file, time, size, colour space); an
    image with unsaved edits (``is_dirty``) is re-read and its cache entry kept while its pixel
    hash is unchanged.
    """
    signature = _image_signature(image)
    entry = _IMAGES.get(image.name_full)
    if entry is not None and entry[0] == signature and not image.is_dirty:
        return _cached_image(entry, mat, warnings)
    notes = []
    raw, path = _read_image_pixels(image)
    if raw is None:
        notes.append(f"image {image.name!r} (file {path!r}) cannot be loaded; it renders magenta (1, 0, 1) as "
                     "in Cycles")
        pixels = np.array(MISSING_RGBA, np.float32).reshape(1, 1, 4)
        digest = "missing"
        encoded = None
    else:
        digest = hashlib.blake2b(raw.tobytes(), digest_size=16).hexdigest()
        if entry is not None and entry[1] == digest:
            _IMAGES[image.name_full] = (signature,) + entry[1:]
            return _cached_image(_IMAGES[image.name_full], mat, warnings)
        pixels, encoded = _colour_managed(image, _rgba(raw, image), notes)
    entry = (signature, digest, pixels, {}, notes, encoded)
    _cache_image(image.name_full, entry)
    warnings.extend(f"material {mat!r}: {note}" for note in notes)
    return pixels, entry


def _cached_image(entry, mat, warnings):
    """(pixels, entry) of a cache entry still valid, its notes repeated as warnings of material ``mat``."""
    warnings.extend(f"material {mat!r}: {note}" for note in entry[4])
    return entry[2], entry


def _read_image_pixels(image):
    """(flat float32 copy of ``image.pixels``, file path) of an image, or (None, its file path or,
    without one, its name) when Cycles cannot load it: a file image whose file is gone and that
    is not packed, an image without pixels or whose pixel count does not match its size."""
    path = image.filepath_from_user() if image.source == "FILE" else ""
    # a file image whose file is gone and that is not packed: Cycles reads the file, finds nothing and
    # renders magenta, whatever pixels the image may still hold in memory
    gone = image.source == "FILE" and image.packed_file is None and not os.path.isfile(path)
    w, h = image.size
    n = len(image.pixels) if w and h and not gone else 0
    if n == 0 or n != w * h * image.channels:
        return None, path or image.name
    raw = np.empty(n, np.float32)
    image.pixels.foreach_get(raw)
    return raw, path


def _rgba(raw, image):
    """The (H, W, 4) view or copy of an image's flat pixels ``raw``: grey, grey + alpha and RGB
    images widened to RGBA (grey repeated, alpha 1 where the image has none)."""
    w, h = image.size
    pixels = raw.reshape(h, w, image.channels)
    if image.channels != 4:           # grey, grey + alpha, RGB → RGBA
        c = image.channels
        rgb = pixels[..., :1].repeat(3, axis=2) if c <= 2 else pixels[..., :3]
        alpha = pixels[..., 1:2] if c == 2 else np.ones((h, w, 1), np.float32)
        pixels = np.concatenate((rgb, alpha), axis=2)
    return pixels


def _colour_managed(image, pixels, notes):
    """(linear contiguous float32 pixels, sRGB-encoded pixels Cycles filters or None) of an image's
    RGBA ``pixels`` (see image_pixels); a colour space left unconverted adds a note, non-finite
    values become 0."""
    space = image.colorspace_settings.name
    encoded = None
    if interpolated_encoded(image):
        encoded = np.array(pixels, np.float32)      # a copy: pixels may be decoded below
        if image.is_float:          # Cycles reads the file's encoded values, Blender holds them decoded
            encoded[..., :3] = linear_to_srgb(pixels[..., :3])
    if not image.is_float and not image.colorspace_settings.is_data:
        if space == "sRGB":
            pixels = pixels.copy()
            pixels[..., :3] = srgb_to_linear(pixels[..., :3])
        elif space not in LINEAR_SPACES:
            notes.append(f"image {image.name!r} has colour space {space!r}, which is not converted; its "
                         "values are used as linear")
    pixels = _finite(np.ascontiguousarray(pixels, np.float32))
    if encoded is not None:
        encoded = _finite(encoded)
    return pixels, encoded


def _finite(array):
    """``array`` itself if all its values are finite, else a copy with NaN and ±inf replaced by 0."""
    if np.all(np.isfinite(array)):
        return array
    return np.nan_to_num(array, nan=0.0, posinf=0.0, neginf=0.0)


def _cache_image(name, entry):
    """Stores ``entry`` as the most recently converted image ``name``, the least recently converted
    ones dropped to keep at most IMAGE_CACHE_SIZE entries."""
    _IMAGES.pop(name, None)
    while len(_IMAGES) >= IMAGE_CACHE_SIZE:          # the least recently converted image goes first
        _IMAGES.pop(next(iter(_IMAGES)))
    _IMAGES[name] = entry


def _mapping_affine(node, mat, warnings):
    """(A (3, 3), b (3,)) of a Mapping node with unlinked inputs (v' = A v + b), or None (warning)."""
    import mathutils
    if any(node.inputs[k].is_linked for k in ("Location", "Rotation", "Scale")) or node.vector_type == "NORMAL":
        warnings.append(f"material {mat!r}: Mapping node {node.name!r} (linked inputs or type Normal) is not "
                        "exported; the texture uses the plain UV map")
        return None
    loc = np.array(node.inputs["Location"].default_value, np.float64)
    rot = np.array(mathutils.Euler(node.inputs["Rotation"].default_value, "XYZ").to_matrix(), np.float64)
    scale = np.array(node.inputs["Scale"].default_value, np.float64)
    if node.vector_type == "POINT":        # Cycles svm_mapping: R·(v·S) + L
        return rot * scale[None, :], loc
    if node.vector_type == "VECTOR":
        return rot * scale[None, :], np.zeros(3)
    with np.errstate(divide="ignore"):     # TEXTURE: R⁻¹(v − L) / S (safe divide: 0 where S = 0)
        inv = np.where(scale != 0, 1.0 / np.where(scale != 0, scale, 1.0), 0.0)
    A = inv[:, None] * rot.T
    return A, -A @ loc


def _uv_source(tex_node, mat, warnings):
    """(UV map name, '' = the active render map; affine map A (2, 2), b (2,)) of an Image Texture's
    Vector input, or None (with a warning) for coordinates other than a UV map."""
    A, b = np.eye(3), np.zeros(3)
    socket = tex_node.inputs["Vector"]
    for _ in range(32):
        node, out = _source(socket)
        if node is None:
            return "", A[:2, :2], b[:2]
        kind = node.bl_idname
        if kind == "ShaderNodeUVMap":
            return node.uv_map, A[:2, :2], b[:2]
        if kind == "ShaderNodeTexCoord" and out.name == "UV":
            return "", A[:2, :2], b[:2]
        if kind == "ShaderNodeMapping":
            affine = _mapping_affine(node, mat, warnings)
            if affine is not None:          # composed: outer(inner(v))
                A, b = A @ affine[0], A @ affine[1] + b
            socket = node.inputs["Vector"]
            continue
        break
    what = f"{node.bl_idname}" + (f" ▸ {out.name}" if out is not None else "")
    warnings.append(f"material {mat!r}: Image Texture {tex_node.name!r} reads coordinates from {what}; only UV "
                    "maps are exported, it uses the active UV map")
    return "", np.eye(2), np.zeros(2)


def image_texture(tex_node, mat, warnings, alpha=False, min_value=None):
    """The engine ImageTexture of a Blender Image Texture node (RGB, or its alpha channel; texels
    raised to at least ``min_value`` if given), cached with the image."""
    image = tex_node.image
    if image is None:       # Cycles: an Image Texture without image gives black
        pixels, entry = np.zeros((1, 1, 4), np.float32), (None, "none", None, {}, [], None)
        name = "<no image>"
    else:
        pixels, entry = image_pixels(image, mat, warnings)
        name = image.name
    if image is not None and image.source in ("TILED", "SEQUENCE", "MOVIE"):
        warnings.append(f"material {mat!r}: image {image.name!r} is a {image.source.lower()} image; only the pixels "
                        "Blender holds (one tile or frame) are used")
    if tex_node.projection != "FLAT":
        warnings.append(f"material {mat!r}: Image Texture {tex_node.name!r} uses {tex_node.projection} projection; "
                        "rendered with flat UV projection")
    _, A, b = _uv_source(tex_node, mat, warnings)
    interpolation = INTERPOLATION.get(tex_node.interpolation, "Linear")
    extension = tex_node.extension if tex_node.extension in ("REPEAT", "EXTEND", "CLIP", "MIRROR") else "REPEAT"
    mapped = not (np.array_equal(A, np.eye(2)) and not b.any())
    key = (alpha, min_value, interpolation, extension, A.tobytes() if mapped else None, b.tobytes() if mapped else None)
    textures = entry[3]
    space = "linear" if alpha or entry[5] is None else "srgb"     # alpha is never sRGB-encoded
    if key not in textures:
        data = pixels[..., 3:4] if alpha else (pixels if space == "linear" else entry[5])[..., :3]
        if not alpha and np.array_equal(data[..., 0], data[..., 1]) and np.array_equal(data[..., 1], data[..., 2]):
            data = data[..., :1]      # grey: one channel, read exactly (not through the luminance weights)
        if min_value is not None:
            data = np.maximum(data, _least_texel(min_value, space))
        textures[key] = ImageTexture(data, interpolation, extension, name=name, uv_transform=(A, b) if mapped else None,
                                     interpolation_space=space)
    return textures[key]


def _least_texel(value: float, space: str) -> np.float32:
    """The least float32 texel whose value (decoded, for "srgb") is ≥ ``value``: texels raised to it
    keep every lookup ≥ value (the filter weights are convex and the decoding monotone)."""
    if space == "linear":
        return np.float32(value)
    texel = np.float32(linear_to_srgb(value))
    while np.float32(srgb_decode(np.float64(texel))) < value:
        texel = np.nextafter(texel, np.float32(np.inf))
    return texel


#: Separate Color / Separate RGB outputs → the image channel they read
_SEPARATED_CHANNELS = {"Red": "R", "Green": "G", "Blue": "B", "R": "R", "G": "G", "B": "B"}


def _separated_image(node, out):
    """(Image Texture node, channel) where ``out`` of ``node`` is one channel of an Image Texture's
    Color through a Separate Color (RGB mode) or legacy Separate RGB node — how glTF imports its
    occlusion-roughness-metallic maps — else None."""
    if node.bl_idname not in ("ShaderNodeSeparateColor", "ShaderNodeSeparateRGB"):
        return None
    if getattr(node, "mode", "RGB") != "RGB" or out.name not in _SEPARATED_CHANNELS:
        return None
    source, source_out = _source(node.inputs[0])
    if source is None or source.bl_idname != "ShaderNodeTexImage" or source_out.name != "Color":
        return None
    return source, _SEPARATED_CHANNELS[out.name]


def _texture_node(node, out) -> bool:
    """True if output ``out`` of ``node`` is a texture the exporter reads itself (texture_source):
    an Image Texture, a Color Attribute, an Attribute (Geometry) node's Color or Alpha, one channel
    of an Image Texture through Separate Color."""
    kind = node.bl_idname
    return kind in ("ShaderNodeTexImage", "ShaderNodeVertexColor") or (
        kind == "ShaderNodeAttribute" and node.attribute_type == "GEOMETRY" and out.name in ("Color", "Alpha")) or (
        _separated_image(node, out) is not None)


def _baked_link(socket) -> bool:
    """True if a shader's input is linked to a graph that is not a texture the exporter reads itself
    (what ``_linked_input_fallback`` may bake; Normal inputs are normal/bump maps, never baked)."""
    if not socket.is_linked or socket.type == "SHADER" or socket.name == "Normal":
        return False
    node, out = _source(socket)
    return node is not None and not _texture_node(node, out)


def texture_source(socket, mat, warnings, roughness=False, node_name=""):
    """A TextureInput for a linked input socket (Image Texture, Color Attribute or Attribute node),
    or None (then :func:`_linked_input_fallback` decides).  ``roughness``: the parameter is m = r²
    (Beckmann slope from Blender roughness): the texture is squared after interpolation, image
    texels kept ≥ ROUGHNESS_MIN (m ≥ 1e-4, the engine's least textured slope)."""
    node, out = _source(socket)
    if node is None or not _texture_node(node, out):
        return None
    kind = node.bl_idname
    power = 2.0 if roughness else 1.0
    separated = _separated_image(node, out)
    if separated is not None:          # one channel of an image, read natively (not baked)
        texture = image_texture(separated[0], mat, warnings, min_value=ROUGHNESS_MIN if roughness else None)
        return TextureInput(texture, separated[1], power=power)
    if kind == "ShaderNodeTexImage":
        alpha = out.name == "Alpha"
        texture = image_texture(node, mat, warnings, alpha=alpha, min_value=ROUGHNESS_MIN if roughness else None)
        return TextureInput(texture, None, power=power)        # the Alpha output: a one-channel texture
    if kind in ("ShaderNodeVertexColor", "ShaderNodeAttribute"):
        name = node.layer_name if kind == "ShaderNodeVertexColor" else node.attribute_name
        alpha = out.name == "Alpha"
        # colours in [0, 1]: a roughness maps to m = ALPHA_MIN + (1 − ALPHA_MIN)·r² (≥ ALPHA_MIN without clamping)
        scale, offset = (1.0 - ALPHA_MIN, ALPHA_MIN) if roughness else (1.0, 0.0)
        return TextureInput(VertexColour(name, 4 if alpha else 3), "A" if alpha else None, scale, offset, power)


class BakeTarget:
    """What a material is exported for, so that linked inputs can be baked (``texture_bake.bake_input``):
    the (evaluated) object, its 4×4 world matrix, the Blender material, the bake resolution and the
    UV map the object's mesh exports (None: the active render map).  ``requested`` becomes True once
    an input needed a bake (baked or not), ``baked`` counts the inputs baked: a material that baked
    something is exported per object."""

    def __init__(self, obj, matrix, material, resolution, uv_map=None):
        self.obj, self.matrix, self.material, self.resolution = obj, matrix, material, resolution
        self.uv_map = uv_map
        self.requested = False
        self.baked = 0


class NoBake:
    """A bake target that bakes nothing: linked inputs keep their own value, with a warning giving
    ``reason`` (e.g. the viewport, which does not bake)."""

    def __init__(self, reason: str):
        self.reason = reason


#: The viewport's target: baking there would run Cycles' bake operator inside view_update (its
#: temporary datablocks feed back as depsgraph updates) and re-bake on every drag of an object.
VIEWPORT_NO_BAKE = NoBake("which Polar bakes for final renders (F12) only, not in the viewport")

#: Baked textures as material inputs (clamped to an input's range, squared for roughness) by bake,
#: living as long as the bake's cache entry.
_BAKED_INPUTS = weakref.WeakKeyDictionary()


def _own_value_warning(reader, socket, reason="which is not exported"):
    """One warning naming a linked input whose own (unlinked) value is used."""
    source = _follow(socket)
    what = source.bl_idname if source is not None else "a node"
    reader.warnings.append(f"material {reader.mat!r}: input {socket.name!r} of {reader.node.name!r} is linked to "
                           f"{what}, {reason}; its own value is used")


def _linked_input_fallback(reader, socket, lo=-math.inf, hi=math.inf, roughness=False):
    """What a linked texturable input that is not an Image Texture or colour attribute becomes: the
    graph baked by Cycles on the object's UV map (``reader.bake``, a BakeTarget), values clamped to
    [lo, hi] (as Cycles clamps the input's range), as a TextureInput (one channel for float sockets,
    RGB for colours; ``roughness``: Beckmann m = r², texels ≥ ROUGHNESS_MIN as image roughness); or
    None for the socket's own value — no object to bake for (one warning naming the input), or no
    UV map or a failed bake (``bake_input`` warns)."""
    target = reader.bake
    if not isinstance(target, BakeTarget):
        _own_value_warning(reader, socket, *((target.reason,) if isinstance(target, NoBake) else ()))
        return None
    target.requested = True
    baked = bake_input(target.obj, target.material, socket, target.resolution, reader.warnings,
                       matrix=target.matrix, uv_map=target.uv_map)
    if baked is None:
        return None
    target.baked += 1
    if roughness:
        lo = max(lo, ROUGHNESS_MIN)
    key = (lo, hi, roughness)
    value = _BAKED_INPUTS.get(baked, {}).get(key)
    if value is None:           # computed once per cached bake: the bounds scan every texel
        tex = baked.texture
        if tex.pixels.min() < lo or tex.pixels.max() > hi:      # e.g. a Color Ramp beyond [0, 1]: as Cycles' clamp
            tex = ImageTexture(np.clip(tex.pixels, lo, hi), tex.interpolation, tex.extension, tex.name)
        value = TextureInput(tex, baked.channel, baked.scale, baked.offset, power=2.0 if roughness else 1.0)
        _BAKED_INPUTS.setdefault(baked, {})[key] = value
    return value


def _declared_range(p):
    """(lo, hi) closed bounds of a declared parameter (an open end moved one float inward)."""
    lo = float(np.nextafter(p.lo, math.inf)) if p.lo_open else p.lo
    hi = float(np.nextafter(p.hi, -math.inf)) if p.hi_open else p.hi
    return lo, hi


class _Reader:
    """Reads validated input values of one node, recording warnings once per material; ``bake``: the
    BakeTarget linked texturable inputs are baked for (None: not baked)."""

    def __init__(self, material_name, node, warnings, bake=None):
        self.mat, self.node, self.warnings, self.bake = material_name, node, warnings, bake

    def _socket(self, name):
        sock = self.node.inputs.get(name)
        if sock is None:
            raise SceneError(f"material {self.mat!r}", f"node {self.node.name!r} has no input {name!r}")
        return sock

    def _constant(self, name):
        """The socket; a linked one (not a shader) warns that its own value is used (never baked:
        the parameter cannot vary over the surface)."""
        sock = self._socket(name)
        if sock.is_linked and sock.type != "SHADER":
            _own_value_warning(self, sock)
        return sock

    def texture(self, name, roughness=False, lo=-math.inf, hi=math.inf, bake=True):
        """A TextureInput if the input is linked to a texture, or to another graph that is baked
        (``bake``; values clamped to [lo, hi]), else None (one warning: its own value is used)."""
        sock = self._socket(name)
        if not sock.is_linked or sock.type == "SHADER":
            return None
        source = texture_source(sock, self.mat, self.warnings, roughness=roughness)
        if source is None:
            if bake:
                source = _linked_input_fallback(self, sock, lo, hi, roughness)
            else:
                _own_value_warning(self, sock, "which is not baked here (a metal's n, κ vary per point only "
                                   "with an Image Texture colour)")
        return source

    def float(self, name, lo=-math.inf, hi=math.inf, lo_open=False):
        v = float(self._constant(name).default_value)
        if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
            rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
            raise SceneError(f"material {self.mat!r}.{self.node.name}.{name}", f"must be in {rng}, got {v!r}")
        return v

    def rgb(self, name, lo=0.0, hi=math.inf):
        v = [float(c) for c in self._constant(name).default_value[:3]]
        if not all(math.isfinite(c) and lo <= c <= hi for c in v):
            raise SceneError(f"material {self.mat!r}.{self.node.name}.{name}",
                             f"components must be in [{lo:g}, {hi:g}], got {v}")
        return v

    def rgb_or_texture(self, name, lo=0.0, hi=math.inf, bake=True):
        """A TextureInput where the input is textured (or baked, ``bake``), else the validated
        constant [r, g, b]."""
        sock = self._socket(name)
        if sock.is_linked:
            source = self.texture(name, lo=lo, hi=hi, bake=bake)
            if source is not None:
                return source
            return self._checked_rgb(name, lo, hi)
        return self.rgb(name, lo, hi)

    def roughness_or_texture(self, name):
        """(Beckmann m = r² as a TextureInput or a number, the constant r or None where textured)."""
        sock = self._socket(name)
        if sock.is_linked:
            source = self.texture(name, roughness=True, lo=0.0, hi=1.0)
            if source is not None:
                return source, None
            r = self._checked_float(name, 0.0, 1.0)
            return r * r, r
        r = self.float(name, 0.0, 1.0)
        return r * r, r

    def number_or_texture(self, name, lo=0.0, hi=1.0):
        """A number input in [lo, hi] (default: a roughness or weight r itself, not squared): a TextureInput where
        textured or baked (values clamped to [lo, hi]), else the validated constant (linked but not mapped: its
        own value, one warning)."""
        sock = self._socket(name)
        if sock.is_linked:
            source = self.texture(name, lo=lo, hi=hi)
            if source is not None:
                return source
            return self._checked_float(name, lo, hi)
        return self.float(name, lo, hi)

    def _checked_rgb(self, name, lo, hi):
        v = [float(c) for c in self._socket(name).default_value[:3]]
        if not all(math.isfinite(c) and lo <= c <= hi for c in v):
            raise SceneError(f"material {self.mat!r}.{self.node.name}.{name}",
                             f"components must be in [{lo:g}, {hi:g}], got {v}")
        return v

    def _checked_float(self, name, lo, hi):
        v = float(self._socket(name).default_value)
        if not math.isfinite(v) or v < lo or v > hi:
            raise SceneError(f"material {self.mat!r}.{self.node.name}.{name}",
                             f"must be in [{lo:g}, {hi:g}], got {v!r}")
        return v


def _rgb_spectrum(rgb, kind="reflectance"):
    if max(rgb) == min(rgb):
        return ConstantSpectrum(rgb[0])
    return RGBReflectanceSpectrum(rgb) if kind == "reflectance" else RGBUnboundedSpectrum(rgb)


#: Polarising BSDF parameters that are microfacet slopes (engine.materials.roughness)
_SLOPES = ("m",)


def _socket_values(reader, decl) -> dict:
    """{parameter name: value} of a model's FLOAT and COLOR inputs (a grey colour as one number).

    An input that a node saved by an older version lacks is left out: the parameter keeps its
    declared default.  The declaration's builder validates every value.
    """
    values = {}
    for p in decl.parameters:
        s = p.socket
        if s is None or s.type not in ("FLOAT", "COLOR") or s.name not in reader.node.inputs:
            continue
        sock = reader._socket(s.name)
        if sock.is_linked:
            if p.texturable and p.name in decl.per_point:
                lo, hi = _declared_range(p)          # the node's inputs are the model's own parameters
                if p.name in _SLOPES:                # a baked roughness: kept ≥ the least slope (no per-point smooth)
                    lo = max(lo, ALPHA_MIN)
                source = reader.texture(s.name, lo=lo, hi=hi)
                if source is not None:
                    values[p.name] = source
                    continue
            else:
                reader.warnings.append(f"material {reader.mat!r}: input {s.name!r} of {reader.node.name!r} cannot vary "
                                       "over the surface in this model; its own value is used")
        if s.type == "FLOAT":
            values[p.name] = float(sock.default_value)
        else:
            rgb = [float(c) for c in sock.default_value[:3]]
            values[p.name] = rgb[0] if max(rgb) == min(rgb) else rgb
    return values


def _declared(decl, values, where):
    """Values of ``decl`` whose errors name the node's inputs (socket names)."""
    def label(name):
        socket = decl[name].socket if name in decl else None
        return socket.name if socket is not None else name
    return decl.values(values, where, label=label)


def polar_node_bsdf(node, mat, warnings, depth=0, bake=None):
    """BSDF of a Polarising BSDF node (a model's own parameter checks become errors naming the material)."""
    try:
        return _polar_node_bsdf(node, mat, warnings, depth, bake)
    except ValueError as e:
        if isinstance(e, SceneError):
            raise
        raise SceneError(f"material {mat!r}.{node.name}", str(e)) from None


def _polar_node_bsdf(node, mat, warnings, depth, bake=None):
    """The node's inputs and menus → the model's declared parameters → the model's builder."""
    model = node.model
    decl = NODE_MODELS.get(model)
    if decl is None:
        raise SceneError(f"material {mat!r}", f"unknown Polarising BSDF model {model!r}")
    r = _Reader(mat, node, warnings, bake)
    where = f"material {mat!r}.{node.name}"
    values = _socket_values(r, decl)
    parts = {}
    if "metal" in decl and getattr(node, "metal", "CUSTOM") != "CUSTOM":   # measured n, κ instead of the inputs
        values.pop("n", None)
        values.pop("k", None)
        values["metal"] = node.metal
    if model in ("DIELECTRIC", "BLACK_GLASS", "ROUGH_DIELECTRIC", "THIN_DIELECTRIC"):
        preset = getattr(node, "dielectric_preset", "CUSTOM")
        for name, _, _, _, v in DIELECTRIC_PRESETS:
            if name == preset and v is not None:   # a named preset replaces the IOR input
                values["n"] = v
    if model == "TORRANCE_SPARROW":
        values.setdefault("m", decl["m"].socket.default)   # (a roughness the engine calls smooth: its smooth limit)
        values["shadowing"] = "smith" if node.shadowing == "SMITH" else "ts"
        if values.get("diffuse_albedo") == 0.0:   # black: no Lambertian part at all
            del values["diffuse_albedo"]
    if model == "WEIDLICH_WILKIE":
        coat_decl = decl["coats"].members
        coat_values = _socket_values(r, coat_decl)
        # a Beckmann coat: the engine builds a smooth one where its rule calls the roughness smooth (0 included)
        coat_values.setdefault("m", coat_decl["m"].socket.default)
        coat_values["distribution"] = "beckmann"
        base_node = _follow(node.inputs["Base"])
        if depth > 16:
            raise SceneError(f"material {mat!r}", "layered materials nest more than 16 coats deep")
        parts["coats"] = [coat_decl.build(_declared(coat_decl, coat_values, where))]
        parts["base"] = _lambert(DEFAULT_ALBEDO, mat, node) if base_node is None else \
            surface_bsdf(base_node, mat, warnings, depth + 1, bake)[0]
        values["form"] = "published" if node.ww_form == "PUBLISHED" else "energy"
    return decl.build(_declared(decl, values, where), **parts)


def _textured_model(model, values, mat, node):
    """A model built through its declaration from ``values`` some of which are TextureInputs
    (validated: every value a texture can give must be in the parameter's range)."""
    decl = MODELS[model]
    values = {k: _grey(v) for k, v in values.items()}
    return decl.build(decl.values(values, f"material {mat!r}.{node.name}"))


def _grey(v):
    """A constant [r, g, b] with r = g = b as one number (the same spectrum as the constant path's
    ``_rgb_spectrum``); anything else as is."""
    if isinstance(v, (list, tuple, np.ndarray)) and max(v) == min(v):
        return float(v[0])
    return v


def _textured(*values) -> bool:
    return any(isinstance(v, TextureInput) for v in values)


def _lambert(albedo, mat, node=None):
    """The ``lambert`` model of a constant (a number, [r, g, b] or a Spectrum) or a colour texture."""
    if isinstance(albedo, (int, float)):
        albedo = ConstantSpectrum(float(albedo))
    elif isinstance(albedo, (list, tuple)):
        albedo = _rgb_spectrum(list(albedo))
    decl = MODELS["lambert"]
    where = f"material {mat!r}" + (f".{node.name}" if node is not None else "")
    return decl.build(decl.values({"albedo": albedo}, where))


def _reflectance(value):
    """A reflectance spectrum of a constant [r, g, b] or a colour TextureInput (per point)."""
    if isinstance(value, TextureInput):
        from ...engine.textures.inputs import TexturedSpectrum
        return TexturedSpectrum(value, "reflectance").clamped_to(0.0, 1.0)
    return _rgb_spectrum(value)


def conductor_index(colour, edge, mode):
    """(n, κ) spectra of a metal whose normal-incidence reflectance is ``colour`` (a constant [r, g, b]
    or a colour TextureInput), by Gulbrandsen's map per wavelength (and per point), so that the mirror
    shows the colour (engine.spectral.gulbrandsen); the second parameter by ``mode``: "schlick" (the
    reflectance at θ₈₂ of Schlick's curve through the colour: Cycles' Principled metal, ``edge`` unused),
    "f82" (``edge`` is that reflectance) or "tint" (``edge`` is Gulbrandsen's edge tint)."""
    from ...engine.spectral.gulbrandsen import GulbrandsenIndex
    from ...engine.textures.conductor_index import TexturedGulbrandsenIndex
    r = _reflectance(colour)
    g = r if edge is None or edge is colour else _reflectance(edge)
    kind = TexturedGulbrandsenIndex if _textured(colour, edge) else GulbrandsenIndex
    return kind(r, g, "n", mode), kind(r, g, "k", mode)


def facets(node, mat, warnings):
    """Torrance–Sparrow facet keywords of a Blender microfacet shader's Distribution, as Cycles renders
    it: GGX (height-correlated Smith G), Multiscatter GGX (GGX with Cycles' energy compensation, a
    depolarised term), Beckmann (the thesis' Beckmann with V-cavity shadowing, as before);
    Ashikhmin–Shirley is rendered as GGX (one warning)."""
    distribution = getattr(node, "distribution", "GGX")
    if distribution == "BECKMANN":
        return {"distribution": "beckmann"}
    if distribution == "ASHIKHMIN_SHIRLEY":
        warnings.append(f"material {mat!r}: {node.name!r} uses the Ashikhmin-Shirley distribution; rendered as GGX")
    return {"distribution": "ggx", "multiscatter": distribution == "MULTI_GGX"}


def _facet_conductor(n, k, m, mat, node, warnings, film=None, aniso=None):
    """A conductor of index n + iκ (spectra, [r, g, b] or textured) with facets as the node's Distribution
    and roughness m (α = r², constant or a TextureInput), or its smooth limit; ``film``: (IOR, thickness nm)
    of a Thin Film on its facets or its mirror (Cycles films the conductor's index);
    ``aniso``: (α_x, α_y, rotation in turns) of Cycles' anisotropic GGX (a constant roughness; None: isotropic).
    Smooth where the engine's rule calls every α smooth (engine.materials.roughness.effectively_smooth): the
    ``conductor`` model; else each α at least the least slope ALPHA_MIN (pbrt's rule)."""
    kw = facets(node, mat, warnings)
    smooth = not isinstance(m, TextureInput) and effectively_smooth(m, *(() if aniso is None else aniso[:2]))
    films = {} if film is None else {"thin_film_ior": film[0], "thin_film_thickness": film[1]}
    if smooth:
        return _textured_model("conductor", {"n": n, "k": k, **films}, mat, node)
    if aniso is not None and aniso[0] != aniso[1]:
        if kw["distribution"] == "ggx":
            from ...engine.materials.anisotropic_ggx import AnisotropicGGX
            n_s, k_s = (_rgb_spectrum(list(v), "unbounded") if isinstance(v, (list, tuple)) else v for v in (n, k))
            # (no declaration: the anisotropic GGX is a part of Principled-like metals, engine.materials.principled)
            return AnisotropicGGX(n_s, k_s, max(aniso[0], ALPHA_MIN), max(aniso[1], ALPHA_MIN), rotation=aniso[2],
                                  multiscatter=kw["multiscatter"],
                                  film_n=None if film is None else _film_number(film[0], IOR_MIN),
                                  film_thickness=0.0 if film is None else _film_number(film[1]))
        warnings.append(f"material {mat!r}: the anisotropy of {node.name!r} is simulated with GGX only; rendered "
                        "isotropic (Beckmann)")
    if not isinstance(m, TextureInput):
        m = max(m, ALPHA_MIN)          # (an anisotropic pair rendered isotropic: its m may lie below)
    return _textured_model("torrance_sparrow", {"n": n, "k": k, "m": m, **kw, **films}, mat, node)


def _node_anisotropy(r, node, mat, warnings, m, kind):
    """(α_x, α_y, rotation) of a Glossy or Metallic BSDF's Anisotropy as Cycles sets it up, or None (isotropic):
    Metallic as the Principled BSDF (α = r²/aspect, r²·aspect, aspect = √(1 − 0.9·a), a ∈ [0, 1]); Glossy
    α = r²(1 − a), r²/(1 − a) for a ∈ (0, 0.99], r²/(1 + a), r²(1 + a) below 0; each α ≤ 1.  Needs a constant
    Roughness and Anisotropy (linked: its own value, one warning)."""
    sock = node.inputs.get("Anisotropy")
    if sock is None or (not sock.is_linked and float(sock.default_value) == 0.0):
        return None
    a = r.float("Anisotropy", -1.0, 1.0)
    textured = isinstance(m, TextureInput)
    _tangent_note(node, mat, warnings, textured)
    if textured:
        return None
    rough = math.sqrt(m)
    if kind == "ShaderNodeBsdfMetallic":
        if a <= 0.0:
            return None
        from ...engine.materials.anisotropic_ggx import cycles_alphas
        ax, ay = cycles_alphas(rough, a)
    else:
        a = min(max(a, -0.99), 0.99)
        if abs(a) <= 1e-4:
            return None
        r2 = rough * rough
        ax, ay = (r2 / (1.0 + a), r2 * (1.0 + a)) if a < 0 else (r2 * (1.0 - a), r2 / (1.0 - a))
        ax, ay = min(ax, 1.0), min(ay, 1.0)
    return ax, ay, r.float("Rotation", -1e6, 1e6)


def _conductor_from_colour(r, colour_name, edge_name, m, mat, node, warnings, mode="schlick"):
    """Conductor whose normal-incidence reflectance is a colour input, its unpolarised reflectance Cycles'
    Fresnel curve at every facet angle (engine.materials.tinted.F82Reflectance over Gulbrandsen's index through
    the curve at 0° and θ₈₂; ``mode``: "schlick", Cycles' F82 curve with a white tint — the Principled metal;
    "f82" with ``edge_name`` an F82-Tint input — the Metallic BSDF; "constant": the colour at every angle —
    Cycles' Glossy BSDF, its polarisation that of a conductor matched at 0° and θ₈₂).  Colours and the roughness
    m may vary per point (image, colour attribute, a baked graph).  The node's Anisotropy and Thin Film (Metallic)
    as Cycles (``_facet_conductor``)."""
    from ...engine.materials.tinted import F82Reflectance
    colour = r.rgb_or_texture(colour_name, 0.0, 1.0)
    tint = None
    if mode == "constant":
        n, k = conductor_index(colour, colour, "f82")
    elif mode == "f82":
        tint = r.rgb_or_texture(edge_name, 0.0, 1.0)
        if isinstance(colour, TextureInput) or isinstance(tint, TextureInput):
            n, k = conductor_index(colour, tint, "schlick_tint")
        else:
            from ...engine.spectral.gulbrandsen import schlick_f82
            f82 = [float(schlick_f82(c)) * t for c, t in zip(colour, tint)]     # Cycles' F82-Tint
            n, k = conductor_index(colour, f82, "f82")
        if not isinstance(tint, TextureInput) and min(tint) == 1.0:
            tint = None
    else:
        n, k = conductor_index(colour, None, "schlick")
    film = _film(r) if mode == "f82" else None
    if film is not None:            # Cycles films its own estimate: (F0, F82-Tint value) as Gulbrandsen's (r, g)
        n, k = conductor_index(colour, [1.0, 1.0, 1.0] if tint is None else tint, "cycles_film")
    metal = _facet_conductor(n, k, m, mat, node, warnings, film,
                             _node_anisotropy(r, node, mat, warnings, m, node.bl_idname))
    if film is not None:
        return metal                                     # (its reflectance is the filmed index's, as Cycles')
    return F82Reflectance(metal, _reflectance(colour), None if tint is None else _reflectance(tint),
                          "constant" if mode == "constant" else "f82_tint")


def _ior(r, name):
    """An IOR input as Cycles reads it: any finite value Blender holds, raised to IOR_MIN (an error
    only for NaN and ±inf)."""
    return max(r.float(name), IOR_MIN)


def _coat_ior(r):
    """Coat IOR as Cycles reads it (≥ 1; Polar's range ends at 100): a TextureInput (values clamped to [1, 100])
    where linked, else the constant."""
    if r._socket("Coat IOR").is_linked:
        source = r.texture("Coat IOR", lo=1.0, hi=100.0)
        if source is not None:
            return source
        return min(max(r._checked_float("Coat IOR", -math.inf, math.inf), 1.0), 100.0)
    return min(max(r.float("Coat IOR"), 1.0), 100.0)


def _filmed_anisotropy(node) -> bool:
    """A Principled BSDF that is anisotropic under a Thin Film: its dielectric's index cannot vary per point
    (engine.materials.principled)."""
    film = node.inputs.get("Thin Film Thickness")
    return _anisotropic(node) and film is not None and (film.is_linked or float(film.default_value) > 0.0)


def _principled_ior(r, node, transmission):
    """The Principled IOR: a TextureInput where linked on an opaque material without a linked Specular IOR Level
    (the dielectric's index per point, with or without a Specular Tint or an anisotropy), else as Cycles reads the
    constant (linked: its own value, one warning)."""
    if r._socket("IOR").is_linked:
        plain = not (node.inputs["Specular IOR Level"].is_linked or _filmed_anisotropy(node))
        if plain and not isinstance(transmission, TextureInput) and transmission == 0.0:
            source = r.texture("IOR", lo=IOR_MIN, hi=1e6)
            if source is not None:
                return source
        else:
            r.warnings.append(f"material {r.mat!r}: IOR of {node.name!r} cannot vary over the surface with a "
                              "transmission, a linked Specular IOR Level or a filmed anisotropy yet; its own value is "
                              "used")
        return max(r._checked_float("IOR", -math.inf, math.inf), IOR_MIN)
    return _ior(r, "IOR")


def _specular_level(r, node):
    """Specular IOR Level: a TextureInput in [0, 1] where linked (glTF's KHR_materials_specular map; with a Specular
    Tint or an anisotropy too; not yet on an anisotropic layer under a Thin Film: its own value, one warning), else
    the constant."""
    if r._socket("Specular IOR Level").is_linked:
        if _filmed_anisotropy(node):
            r.warnings.append(f"material {r.mat!r}: Specular IOR Level of {node.name!r} cannot vary over the surface "
                              "on an anisotropic layer under a Thin Film yet; its own value is used")
            return r._checked_float("Specular IOR Level", 0.0, 1.0)
        return r.number_or_texture("Specular IOR Level")
    return r.float("Specular IOR Level", 0.0, 1.0)


def _sheen_weight(r):
    """Sheen Weight as Cycles reads it (≥ 0, no upper clamp): a TextureInput in [0, 1] where linked, else the
    constant."""
    if r._socket("Sheen Weight").is_linked:
        return _fraction(r, "Sheen Weight")
    return max(r.float("Sheen Weight"), 0.0)


def _fraction(r, name):
    """A [0, 1] weight input (Metallic, Transmission Weight, a Mix Shader's Factor) as Cycles reads
    it: the constant clamped to [0, 1], or a TextureInput (image, colour attribute, Separate Color of
    an image, or a baked graph) whose values are clamped to [0, 1] where used (``_weight``)."""
    sock = r._socket(name)
    if sock.is_linked:
        source = r.texture(name, lo=0.0, hi=1.0)
        if source is not None:
            return source
    v = float(sock.default_value)
    if not math.isfinite(v):
        raise SceneError(f"material {r.mat!r}.{r.node.name}.{name}", f"must be a finite number, got {v!r}")
    return min(max(v, 0.0), 1.0)


def _weight(x, complement=False):
    """A mixture weight from a fraction: x or 1 − x, a float or a TexturedNumber clamped to [0, 1]."""
    from ...engine.textures.inputs import TexturedNumber
    if not isinstance(x, TextureInput):
        return 1.0 - x if complement else x
    if complement:
        if x.power != 1.0:
            raise ValueError("a weight texture has power 1")
        x = TextureInput(x.texture, x.channel, -x.scale, 1.0 - x.offset)
    return TexturedNumber(x, clip=(0.0, 1.0))


def _never(x) -> bool:
    """The fraction is 0 everywhere (a constant below Cycles' closure cutoff)."""
    return not isinstance(x, TextureInput) and x < WEIGHT_CUTOFF


def _always(x) -> bool:
    """The fraction is 1 everywhere."""
    return not isinstance(x, TextureInput) and x > 1.0 - WEIGHT_CUTOFF


def _principled(node, mat, warnings, bake=None):
    """The engine's ``principled`` model (engine/materials/principled.py: Cycles' layer order from
    polarising parts) filled from the node's sockets, each input constant or per point where the engine
    takes it per point (an image, a channel of one, a colour attribute, a baked graph)."""
    r = _Reader(mat, node, warnings, bake)
    metallic = _fraction(r, "Metallic")
    transmission = _fraction(r, "Transmission Weight")
    roughness = r.number_or_texture("Roughness")
    values = {"base_color": _grey(r.rgb_or_texture("Base Color", 0.0, 1.0)), "metallic": metallic,
              "roughness": roughness, "transmission": transmission, "ior": _principled_ior(r, node, transmission),
              "specular_ior_level": _specular_level(r, node),
              "specular_tint": _grey(r.rgb_or_texture("Specular Tint", 0.0)),
              "coat_weight": _fraction(r, "Coat Weight"),
              "coat_roughness": r.number_or_texture("Coat Roughness"),
              "coat_ior": _coat_ior(r),
              "coat_tint": _grey(r.rgb_or_texture("Coat Tint", 0.0, 1.0)),
              "sheen_weight": _sheen_weight(r),
              "sheen_roughness": r.number_or_texture("Sheen Roughness"),
              "sheen_tint": _grey(r.rgb_or_texture("Sheen Tint", 0.0)),
              "anisotropic": _fraction(r, "Anisotropic") if _anisotropic(node) else 0.0,
              "anisotropic_rotation": r.number_or_texture("Anisotropic Rotation", -1e6, 1e6),
              "diffuse_roughness": (r.number_or_texture("Diffuse Roughness")
                                    if node.inputs.get("Diffuse Roughness") is not None else 0.0),
              "distribution": "ggx" if getattr(node, "distribution", "MULTI_GGX") == "GGX" else "multi_ggx"}
    film = _film(r)
    if film is not None:
        values["thin_film_ior"], values["thin_film_thickness"] = film
    if isinstance(values["anisotropic"], TextureInput) or values["anisotropic"] > 0.0:
        _tangent_note(node, mat, warnings, False)          # α_x, α_y per point with a Roughness texture
    _unsimulated_principled_inputs(node, mat, warnings)
    gaps = film_gaps(metallic, transmission, roughness) if film else []
    if gaps:
        warnings.append(f"material {mat!r}: the Thin Film of {node.name!r} is not simulated on its "
                        f"{' and '.join(gaps)} (there: no film)")
    decl = MODELS["principled"]
    return decl.build(decl.values(values, f"material {mat!r}.{node.name}"))


#: Principled inputs not simulated yet, and the value at which they change nothing (a colour: white)
_PRINCIPLED_NOT_SIMULATED = (("Subsurface Weight", 0.0, "rendered as the diffuse base"),)


def _anisotropic(node, name="Anisotropic") -> bool:
    """A Principled BSDF whose Anisotropic (a Glossy or Metallic BSDF whose Anisotropy) is set (a constant ≠ 0,
    or linked: its own value is then used, with the reader's warning)."""
    sock = node.inputs.get(name)
    return sock is not None and (sock.is_linked or float(sock.default_value) != 0.0)


def _tangent_note(node, mat, warnings, textured_roughness):
    """The warnings of an anisotropic Principled, Glossy or Metallic BSDF: Cycles stretches its GGX along the
    Tangent input — a Tangent node on a UV map is that map's MikkTSpace tangent, as Polar's; unlinked, Cycles'
    default is the radial tangent about the object's Z (generated coordinates), for which Polar takes the active UV
    map's tangent (the same on a UV sphere or cylinder, not in general)."""
    sock = node.inputs.get("Tangent")
    source = _follow(sock) if sock is not None and sock.is_linked else None
    if source is None or source.bl_idname != "ShaderNodeTangent" or source.direction_type != "UV_MAP":
        what = "unlinked (Cycles: the radial tangent about the object's Z)" if source is None else \
            f"from {source.bl_idname} {source.name!r}"
        warnings.append(f"material {mat!r}: the Tangent of {node.name!r} is {what}; its anisotropy is rendered along "
                        "the active UV map's tangent")
    if textured_roughness:
        warnings.append(f"material {mat!r}: the anisotropy of {node.name!r} needs a constant Roughness; rendered "
                        "isotropic")


def _unsimulated_principled_inputs(node, mat, warnings):
    """One warning per Principled input that is set (or linked) to something Polar does not simulate yet
    (docs/guide/blender.md, "Principled BSDF, input by input"); inputs newer Blenders add are named too."""
    for name, neutral, instead in _PRINCIPLED_NOT_SIMULATED:
        sock = node.inputs.get(name)
        if sock is None:
            continue
        value = sock.default_value
        values = [float(v) for v in value[:3]] if hasattr(value, "__len__") else [float(value)]
        if sock.is_linked or any(v != neutral for v in values):
            warnings.append(f"material {mat!r}: Principled input {name!r} of {node.name!r} is not simulated yet "
                            f"({instead})")
    known = {"Base Color", "Metallic", "Roughness", "IOR", "Alpha", "Normal", "Weight", "Diffuse Roughness",
             "Subsurface Weight", "Subsurface Radius", "Subsurface Scale", "Subsurface IOR", "Subsurface Anisotropy",
             "Specular IOR Level", "Specular Tint", "Anisotropic", "Anisotropic Rotation", "Tangent",
             "Transmission Weight", "Coat Weight", "Coat Roughness", "Coat IOR", "Coat Tint", "Coat Normal",
             "Sheen Weight", "Sheen Roughness", "Sheen Tint", "Emission Color", "Emission Strength",
             "Thin Film Thickness", "Thin Film IOR"}
    for sock in node.inputs:
        if sock.name not in known and sock.enabled and (sock.is_linked or _non_default(sock)):
            warnings.append(f"material {mat!r}: Principled input {sock.name!r} of {node.name!r} (a newer Blender's) "
                            "is not simulated")


def _non_default(sock) -> bool:
    """A newer input set away from its default (booleans and numbers; other kinds count as set)."""
    rna = sock.bl_rna.properties.get("default_value")
    if rna is None:
        return False
    default = getattr(rna, "default_array", None) if getattr(rna, "is_array", False) else getattr(rna, "default", None)
    value = sock.default_value
    try:
        return tuple(value) != tuple(default) if hasattr(value, "__len__") else value != default
    except TypeError:
        return True


def _tint_spectrum(colour):
    """A tint spectrum (≥ 0, any magnitude) of a constant [r, g, b] or a colour TextureInput; None for white."""
    from ...engine.textures.inputs import TexturedSpectrum
    if isinstance(colour, TextureInput):
        return TexturedSpectrum(colour, "unbounded")
    return None if min(colour) == max(colour) == 1.0 else _rgb_spectrum(list(colour), "unbounded")


def _tinted(bsdf, reflection, transmission):
    """``bsdf`` with its reflected and transmitted light tinted (engine.materials.tinted: Cycles' glass
    colour, the Principled transmission tint); colours as constant [r, g, b] or TextureInputs, None or
    white for none."""
    from ...engine.materials.tinted import Tinted
    r = None if reflection is None else _tint_spectrum(reflection)
    t = None if transmission is None else _tint_spectrum(transmission)
    return bsdf if r is None and t is None else Tinted(bsdf, r, t)


def _film(r):
    """(IOR, thickness nm) of a node's Thin Film inputs, or None (no film: thickness ≤ Cycles' 0.1 nm
    cutoff everywhere, or the inputs absent: Blender before 4.2).  The thickness a number or a TextureInput
    (linked: an image, a colour attribute, a baked graph — glTF's iridescence thickness map; values ≥ 0)."""
    from ...engine.textures.inputs import TexturedNumber
    if r.node.inputs.get("Thin Film Thickness") is None:
        return None
    if r._socket("Thin Film Thickness").is_linked:
        thickness = r.texture("Thin Film Thickness", lo=0.0, hi=1e6)       # (not mapped: its own value, warned)
        if thickness is None:
            thickness = r._checked_float("Thin Film Thickness", -math.inf, math.inf)
    else:
        thickness = r.float("Thin Film Thickness")
    if (TexturedNumber(thickness).hi if isinstance(thickness, TextureInput) else thickness) <= 0.1:
        return None
    ior = None
    if r._socket("Thin Film IOR").is_linked:
        ior = r.texture("Thin Film IOR", lo=IOR_MIN, hi=1e6)          # (not mapped: its own value, warned)
    if ior is None:
        ior = max(r._checked_float("Thin Film IOR", -math.inf, math.inf), IOR_MIN)
    return ior, thickness


def _film_number(value, lo=0.0):
    """A film thickness (or, ``lo`` IOR_MIN, index) for a model built here directly: a number, or a TexturedNumber
    of a TextureInput."""
    from ...engine.textures.inputs import TexturedNumber
    return TexturedNumber(value, clip=(lo, 1e6)) if isinstance(value, TextureInput) else value


def _glass(ior, roughness, distribution, film=None, warn=None, where="material"):
    """The ``rough_dielectric`` model of α = roughness² (the engine builds the smooth dielectric where its rule
    calls α smooth, or the interface is index-matched): GGX as Cycles' GGX, Multiscatter GGX (Principled's and
    Glass' default) with Cycles' energy compensation (``multiscatter``), Beckmann as Beckmann; with a ``film``
    (IOR, thickness) on a smooth surface the ``thin_film`` model (a film on a rough one is not simulated:
    ``warn``)."""
    alpha = roughness * roughness
    if film is not None:
        if effectively_smooth(alpha):    # a smooth coated interface: interference and its elliptical polarisation
            decl = MODELS["thin_film"]
            return decl.build(decl.values({"n": ior, "film_n": _film_number(film[0], IOR_MIN),
                                           "thickness": _film_number(film[1])}, where))
        if warn is not None:
            warn("its Thin Film on a rough surface is not simulated (smooth surfaces only)")
    beckmann = distribution == "BECKMANN"
    decl = MODELS["rough_dielectric"]
    return decl.build(decl.values({"n": ior, "alpha": alpha, "distribution": "beckmann" if beckmann else "ggx",
                                   "multiscatter": distribution == "MULTI_GGX"}, where))


def _emission(node, mat, warnings, colour_name="Color", strength_name="Strength", bake=None):
    """The emitted spectrum of an Emission shader or a Principled BSDF: Color × Strength, each constant or
    varying over the surface (an image, a colour attribute, a baked graph: Cycles' Emission Color from a
    texture; both per point: their product per point); None where nothing is emitted.  Cycles clamps neither; a negative
    strength or colour emits nothing, as a zero one."""
    from ...engine.textures.inputs import ColouredEmission, ProductEmission, textured_emission
    r = _Reader(mat, node, warnings, bake)
    colour = r.rgb_or_texture(colour_name, -math.inf)
    if r._socket(strength_name).is_linked:
        source = r.texture(strength_name)          # a strength per point (not mapped: its own value, warned)
        if source is not None:                     # × the colour, constant or per point
            emission = ProductEmission(colour, source) if isinstance(colour, TextureInput) else \
                ColouredEmission(source, colour)
            return emission if emission.hi > 0 else None
        strength = r._checked_float(strength_name, -math.inf, math.inf)
    else:
        strength = r.float(strength_name)
    if strength <= 0:
        return None
    if isinstance(colour, TextureInput):
        emission = textured_emission(colour, strength, f"material {mat!r}.{node.name}.{colour_name}")
        return emission if emission.hi > 0 else None
    colour = [max(c, 0.0) for c in colour]
    if max(colour) <= 0:
        return None
    return RGBIlluminantSpectrum(colour, strength)


def _weighted_emission(parts, mat, node, warnings):
    """One emission from (weight, emission) pairs of a shader mix: constant ones add up; a textured one
    is kept, scaled by its weight (with others beside it, only it: one warning)."""
    from ...engine.textures.inputs import TexturedSpectrum
    parts = [(w, e) for w, e in parts if e is not None and w > 0]
    textured = [(w, e) for w, e in parts if isinstance(e, TexturedSpectrum)]
    if textured:
        if len(parts) > 1:
            warnings.append(f"material {mat!r}: {node.name!r} mixes a textured emission with other emission; only "
                            "the textured one is rendered")
        w, e = textured[0]
        if hasattr(e, "scaled"):            # a strength per point (inputs.ColouredEmission, ProductEmission)
            return e.scaled(w)
        src = e.source
        scaled = TextureInput(src.texture, src.channel, src.scale * w, src.offset * w, src.power)
        return TexturedSpectrum(scaled, "illuminant", e.clip)
    rgb = sum((w * e.linear_srgb() for w, e in parts), np.zeros(3))
    return RGBIlluminantSpectrum(list(rgb), 1.0) if rgb.max() > 0 else None


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
            needs["uv"].append(_uv_source(node, "", [])[0])
        elif kind == "ShaderNodeNormalMap" and node.space == "TANGENT":
            needs["uv"].append(node.uv_map)
            needs["tangents"].append(node.uv_map)
        elif kind == "ShaderNodeTangent" and node.direction_type == "UV_MAP":
            needs["uv"].append(node.uv_map)
            needs["tangents"].append(node.uv_map)
        elif (kind == "ShaderNodeBsdfPrincipled" and _anisotropic(node)) or \
                (kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic", "ShaderNodeBsdfMetallic")
                 and _anisotropic(node, "Anisotropy")):
            needs["uv"].append("")              # the surface tangent of the anisotropy (see _tangent_note)
            needs["tangents"].append("")
        elif kind == "ShaderNodeVertexColor":
            needs["colors"].append(node.layer_name)
        elif kind == "ShaderNodeAttribute" and node.attribute_type == "GEOMETRY":
            needs["colors"].append(node.attribute_name)
        elif kind in _NORMAL_SHADERS + ("PolarShaderNodeBSDF", "ShaderNodeEmission") and any(map(_baked_link,
                                                                                                  node.inputs)):
            needs["bake"].append("")
        for sock in node.inputs:
            for link in sock.links:
                stack.append(link.from_node)
    return {k: list(dict.fromkeys(v)) for k, v in needs.items()}


# --------------------------------------------------------------------------- shading normals

def _normal_nodes(socket):
    """(Normal Map node or None, Bump node or None, supported) for a shader's Normal input.
    Supported: a Normal Map node whose Color is an Image Texture, a Bump node whose Height is an
    Image Texture (its own Normal input unlinked or such a Normal Map), both as Cycles."""
    node = _follow(socket)
    if node is None:
        return None, None, True
    bump = None
    if node.bl_idname == "ShaderNodeBump":
        bump = node
        height = _follow(node.inputs["Height"])
        if height is None or height.bl_idname != "ShaderNodeTexImage":
            return None, None, False
        node = _follow(node.inputs["Normal"])
        if node is None:
            return None, bump, True
    if node.bl_idname != "ShaderNodeNormalMap":
        return None, None, False
    colour = _follow(node.inputs["Color"])
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
            r = _Reader(mat, normal, warnings)
            kw.update(normal_map=r.texture("Color"), normal_strength=max(r.float("Strength"), 0.0),
                      normal_convention=compat.normal_map_convention(normal))
    if bump is not None:
        r = _Reader(mat, bump, warnings)
        distance = r.float("Distance")
        kw.update(bump_map=r.texture("Height"), bump_distance=-distance if bump.invert else distance,
                  bump_strength=min(max(r.float("Strength"), 0.0), 1.0))
    kw = {k: v for k, v in kw.items() if v is not None}
    return kw if "normal_map" in kw or "bump_map" in kw else None


def surface_bsdf(node, mat, warnings, depth=0, bake=None):
    """(BSDF, emission spectrum or None) for the shader node plugged into a Surface (with its
    normal or bump map, if any)."""
    bsdf, emission = _surface_bsdf(node, mat, warnings, depth, bake)
    if node.bl_idname in _NORMAL_SHADERS:
        bsdf = with_shading_normal(bsdf, node, mat, warnings)
    return bsdf, emission


#: converted shaders whose Normal input is exported
_NORMAL_SHADERS = ("ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic",
                   "ShaderNodeBsdfMetallic", "ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction",
                   "ShaderNodeBsdfPrincipled", "ShaderNodeBsdfSheen")


def _surface_bsdf(node, mat, warnings, depth, bake=None):
    kind = node.bl_idname
    if kind == "PolarShaderNodeBSDF":
        return polar_node_bsdf(node, mat, warnings, depth, bake), None
    r = _Reader(mat, node, warnings, bake)
    if kind == "ShaderNodeBsdfDiffuse":
        colour = r.rgb_or_texture("Color", 0.0, 1.0)
        sigma = r.number_or_texture("Roughness")          # (a σ per point: Oren–Nayar, Lambert where 0)
        if isinstance(sigma, TextureInput) or sigma > 0:       # Cycles' Oren–Nayar (Fujii/EON) above roughness 0
            return _textured_model("oren_nayar", {"albedo": colour, "roughness": sigma}, mat, node), None
        return _lambert(colour, mat, node), None
    if kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
        m, _ = r.roughness_or_texture("Roughness")
        return _conductor_from_colour(r, "Color", None, m, mat, node, warnings, mode="constant"), None
    if kind == "ShaderNodeBsdfMetallic":
        m, _ = r.roughness_or_texture("Roughness")
        if getattr(node, "fresnel_type", "") == "PHYSICAL_CONDUCTOR":
            n, k = r.rgb("IOR", 0.0), r.rgb("Extinction", 0.0)
            n = [max(c, IOR_MIN) for c in n]                 # Cycles' least index
            return _facet_conductor(n, k, m, mat, node, warnings, _film(r),
                                    _node_anisotropy(r, node, mat, warnings, m, kind)), None
        return _conductor_from_colour(r, "Base Color", "Edge Tint", m, mat, node, warnings, mode="f82"), None
    if kind in ("ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction"):
        rough = r.float("Roughness", 0.0, 1.0)
        colour = r.rgb_or_texture("Color", 0.0)          # Cycles tints reflection and refraction by Color
        glass = _glass(_ior(r, "IOR"), rough, getattr(node, "distribution", ""), _film(r),
                       lambda text: warnings.append(f"material {mat!r}: {node.name!r}: {text}"),
                       f"material {mat!r}.{node.name}")
        return _tinted(glass, colour, colour), None
    if kind == "ShaderNodeBsdfSheen":
        if getattr(node, "distribution", "MICROFIBER") != "MICROFIBER":
            warnings.append(f"material {mat!r}: Sheen BSDF {node.name!r} with the {node.distribution.title()} "
                            "distribution is rendered as Microfiber (Cycles' default)")
        tint = r.rgb_or_texture("Color", 0.0)
        return _textured_model("sheen", {"tint": _grey(tint), "roughness": r.number_or_texture("Roughness")},
                               mat, node), None
    if kind == "ShaderNodeBsdfPrincipled":
        emission = _emission(node, mat, warnings, "Emission Color", "Emission Strength", bake)
        bsdf = _principled(node, mat, warnings, bake)
        if emission is not None and getattr(bsdf, "role", None) in ("sheen", "coat"):
            # Cycles attenuates the Principled emission by its sheen and coat (engine.materials.mix.emission_weight)
            from ...engine.materials.mix import emission_weight
            if emission_weight(bsdf) is None:
                warnings.append(f"material {mat!r}: the emission of {node.name!r} under a coat or sheen that varies "
                                "over the surface is not attenuated by them")
            else:
                bsdf.emission_under_layers = True
        return bsdf, emission
    if kind == "ShaderNodeEmission":
        return _lambert(0.0, mat, node), _emission(node, mat, warnings, bake=bake)
    if kind in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
        return _shader_mix(node, mat, warnings, depth, bake)
    if kind == "ShaderNodeBsdfTransparent":
        black = _lambert(0.0, mat, node)
        if depth == 0:          # the whole surface transparent: the object passes every ray
            _white_transparent(node, mat, warnings)
            black.alpha_factor = 0.0
        else:
            warnings.append(f"material {mat!r}: Transparent BSDF {node.name!r} inside a mix other than Mix "
                            "Shader(Transparent, X) at the surface output scatters nothing here")
        return black, None
    else:
        warnings.append(f"material {mat!r}: shader {kind} is not supported; rendered as grey Lambert")
    return _lambert(DEFAULT_ALBEDO, mat, node), None


def _black(bsdf) -> bool:
    """A material that scatters nothing (the black Lambert standing for an Emission shader's BSDF)."""
    albedo = getattr(bsdf, "albedo", None)
    return isinstance(bsdf, Lambert) and isinstance(albedo, ConstantSpectrum) and albedo.value == 0.0


def _transparent(node) -> bool:
    return node is not None and node.bl_idname == "ShaderNodeBsdfTransparent"


def _transparent_mix(node, shaders, mat, warnings, depth, bake):
    """(BSDF, emission) of the Mix Shader patterns that make a surface see-through, or None:

    - Mix(Transparent, X) by Light Path ▸ Is Camera Ray (glTF's KHR_materials_unlit): the camera sees X,
      every other ray passes through — X with ``camera_only`` (the exporter hides the object from shadow and
      indirect rays, so that its emission lights nothing, as in Cycles);
    - Mix(Transparent, X) or Mix(X, Transparent) by a constant or per-point Factor (an alpha mix): X with
      ``alpha_factor`` the weight of X (the object's pass-through alpha, engine.render.visibility; the
      Transparent BSDF's colour must be white, else one warning and its luminance).
    A Transparent BSDF anywhere else scatters nothing (one warning).  X is read at the same depth: its
    own see-through pattern (an alpha mix of an unlit mix) still applies to the material."""
    if node.bl_idname != "ShaderNodeMixShader" or len(shaders) != 2:
        return None
    first, second = (_follow(s) for s in shaders)
    if not (_transparent(first) or _transparent(second)) or (_transparent(first) and _transparent(second)):
        return None
    other = second if _transparent(first) else first
    clear = first if _transparent(first) else second
    if depth > 0:           # nested: the Transparent BSDF scatters nothing (it warns as a shader)
        return None
    fac_node, fac_out = _source(node.inputs[0])
    if fac_node is not None and fac_node.bl_idname == "ShaderNodeLightPath":
        if fac_out.name != "Is Camera Ray" or not _transparent(first):
            warnings.append(f"material {mat!r}: Light Path ▸ {fac_out.name} drives {node.name!r}; rendered as "
                            "the camera sees it")
        bsdf, emission = (surface_bsdf(other, mat, warnings, depth, bake) if other is not None
                          else (_lambert(0.0, mat, node), None))
        bsdf.camera_only = True         # (hidden from indirect rays, its emission lights nothing: as Cycles)
        return bsdf, emission
    _white_transparent(clear, mat, warnings)
    r = _Reader(mat, node, warnings, bake)
    fac = _fraction(r, node.inputs[0].name)
    weight = _weight(fac, complement=not _transparent(first))       # the weight of X
    bsdf, emission = (surface_bsdf(other, mat, warnings, depth, bake) if other is not None
                      else (_lambert(0.0, mat, node), None))
    bsdf.alpha_factor = weight
    return bsdf, emission


def _white_transparent(node, mat, warnings):
    """One warning where a Transparent BSDF's colour is not white (its tint is not simulated)."""
    colour = [float(c) for c in node.inputs["Color"].default_value[:3]]
    if node.inputs["Color"].is_linked or colour != [1.0, 1.0, 1.0]:
        warnings.append(f"material {mat!r}: the colour of Transparent BSDF {node.name!r} is not simulated; light "
                        "passes untinted")


def _shader_mix(node, mat, warnings, depth, bake):
    """(BSDF, emission) of a Mix Shader (weights 1 − Factor and Factor, Factor clamped to [0, 1] as
    Cycles, constant or per point) or an Add Shader (weights 1 and 1): an engine Mix of the two
    shaders' BSDFs, nested mixes nesting.  An unlinked shader input adds nothing (as in Cycles).
    Emission adds up with the same weights; under a per-point Factor the emission is weighed by the
    Factor's own value (one warning: an emitter's strength does not follow a texture Factor)."""
    if depth > 32:
        raise SceneError(f"material {mat!r}", "shader mixes nest more than 32 deep")
    shaders = [s for s in node.inputs if s.type == "SHADER"]
    special = _transparent_mix(node, shaders, mat, warnings, depth, bake)
    if special is not None:
        return special
    if node.bl_idname == "ShaderNodeMixShader":
        r = _Reader(mat, node, warnings, bake)
        fac = _fraction(r, node.inputs[0].name)
        weights = [_weight(fac, complement=True), _weight(fac)]
        own = [1.0 - fac, fac] if not isinstance(fac, TextureInput) else None
    else:
        weights = own = [1.0, 1.0]
    parts, part_weights, emitted = [], [], []
    for i, (sock, w) in enumerate(zip(shaders, weights)):
        child = _follow(sock)
        if child is None or (isinstance(w, float) and w < WEIGHT_CUTOFF):
            continue
        bsdf, emission = surface_bsdf(child, mat, warnings, depth + 1, bake)
        if not _black(bsdf):            # an Emission shader scatters nothing
            parts.append(bsdf)
            part_weights.append(w)
        if emission is not None:
            if own is None:
                r._constant(node.inputs[0].name)       # warns: emission weighed by the Factor's own value
                value = float(node.inputs[0].default_value)
                wk = min(max(value, 0.0), 1.0)
                wk = 1.0 - wk if i == 0 else wk
            else:
                wk = own[i]
            emitted.append((wk, emission))
    emission = _weighted_emission(emitted, mat, node, warnings)
    if not parts:
        return _lambert(0.0, mat, node), emission
    if len(parts) == 1 and isinstance(part_weights[0], float) and part_weights[0] == 1.0:
        return parts[0], emission
    decl = MODELS["mix"]
    return decl.build(decl.values({"weights": part_weights}, f"material {mat!r}.{node.name}"), materials=parts), \
        emission


def export_material(material, warnings, bake=None):
    """(BSDF, emission or None) for a Blender material (None → default grey).  ``bake``: a
    BakeTarget (the object the material is exported for) to bake linked inputs on, or None or a
    NoBake (their own values, one warning each).  Every Blender material is two-sided, as in Cycles
    (BSDF.two_sided: an opaque one seen from the back shades with flipped normals), and refracts without
    scaling radiance by 1/η², as Cycles' closures do (BSDF.radiance_scaling)."""
    bsdf, emission = _material_bsdf(material, warnings, bake)
    bsdf.two_sided = True
    if bsdf.flags.transmits:
        bsdf.radiance_scaling = False
    return bsdf, emission


def _material_bsdf(material, warnings, bake):
    if material is None:
        return _lambert(DEFAULT_ALBEDO, "default"), None
    tree = compat.node_tree_in_use(material)
    if tree is None:
        return _lambert([float(c) for c in material.diffuse_color[:3]], material.name), None
    output = tree.get_output_node("ALL") or tree.get_output_node("CYCLES")
    node = _follow(output.inputs["Surface"]) if output is not None else None
    sock = output.inputs.get("Displacement") if output is not None else None
    if sock is not None and _follow(sock) is not None:
        warnings.append(f"material {material.name!r}: Material Output ▸ Displacement is not simulated; the surface "
                        "is rendered without it")
    volume = _follow(output.inputs["Volume"]) if output is not None and "Volume" in output.inputs else None
    if node is None and volume is not None:
        # Cycles: a material with only a volume has a transparent surface (the object's alpha: scene.py)
        return _with_interior(_lambert(0.0, material.name), volume, material.name, warnings), None
    if node is None:
        warnings.append(f"material {material.name!r} has no surface shader; rendered black")
        return _lambert(0.0, material.name), None
    bsdf, emission = surface_bsdf(node, material.name, warnings, bake=bake)
    cycles = getattr(material, "cycles", None)      # Material ▸ Settings ▸ Bump Map Correction (Cycles' property)
    if not getattr(cycles, "use_bump_map_correction", True):
        set_bump_correction(bsdf, False)
    if volume is not None:
        bsdf = _with_interior(bsdf, volume, material.name, warnings)
    return bsdf, emission


# --------------------------------------------------------------------------- volumes

def _absorption(node, mat, warnings, weight=1.0, depth=0) -> np.ndarray:
    """σ_a (3,) per unit length of the volume shader graph at ``node`` (Cycles' svm volume closures):
    Volume Absorption ρ·(1 − Color); Principled Volume ρ·max(1 − Color, 0)·max(1 − √Absorption Color, 0)
    (its scattering, emission and blackbody are not simulated: one warning); Volume Coefficients'
    Absorption; Mix / Add Shader weighted; anything else (Volume Scatter, …) one warning, no absorption."""
    kind = node.bl_idname
    r = _Reader(mat, node, warnings)
    if kind in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
        if depth > 32:
            raise SceneError(f"material {mat!r}", "volume shader mixes nest more than 32 deep")
        shaders = [sk for sk in node.inputs if sk.type == "SHADER"]
        if kind == "ShaderNodeMixShader":
            fac = min(max(float(r._constant(node.inputs[0].name).default_value), 0.0), 1.0)
            weights = (1.0 - fac, fac)
        else:
            weights = (1.0, 1.0)
        total = np.zeros(3)
        for sk, w in zip(shaders, weights):
            child = _follow(sk)
            if child is not None and w > 0:
                total += _absorption(child, mat, warnings, weight * w, depth + 1)
        return total
    if kind == "ShaderNodeVolumeAbsorption":
        density = max(r.float("Density"), 0.0)
        colour = np.array(r.rgb("Color", -math.inf))
        return weight * density * (1.0 - colour)
    if kind == "ShaderNodeVolumePrincipled":
        density = max(r.float("Density"), 0.0)
        colour = np.array(r.rgb("Color", -math.inf))
        absorption_colour = np.array(r.rgb("Absorption Color", 0.0))
        scattered = density * np.maximum(colour, 0.0)
        emitted = max(r.float("Emission Strength"), 0.0) * max(r.rgb("Emission Color", 0.0)) + \
            max(r.float("Blackbody Intensity"), 0.0)
        if scattered.max() > 0 or emitted > 0:
            warnings.append(f"material {mat!r}: the scattering and emission of Principled Volume {node.name!r} are not "
                            "simulated; only its absorption is rendered")
        return weight * density * np.maximum(1.0 - colour, 0.0) * np.maximum(1.0 - np.sqrt(absorption_colour), 0.0)
    if kind == "ShaderNodeVolumeCoefficients":
        sock = node.inputs.get("Absorption Coefficients")
        if sock is None:
            warnings.append(f"material {mat!r}: volume node {node.name!r} is not simulated")
            return np.zeros(3)
        value = np.array(sock.default_value[:3] if hasattr(sock.default_value, "__len__") else [sock.default_value] * 3)
        warnings.append(f"material {mat!r}: only the absorption of Volume Coefficients {node.name!r} is simulated")
        return weight * np.maximum(value, 0.0)
    warnings.append(f"material {mat!r}: volume shader {kind} is not simulated (scattering volumes are not yet "
                    "rendered); its object's interior is left clear")
    return np.zeros(3)


def _with_interior(bsdf, volume, mat, warnings):
    """``bsdf`` carrying the absorbing interior of the material's Volume graph (engine Interior), if it
    absorbs anything."""
    from ...engine.scene.description import Interior
    sigma = _absorption(volume, mat, warnings)
    if not np.all(np.isfinite(sigma)):
        raise SceneError(f"material {mat!r}", f"the volume's absorption must be finite, got {sigma.tolist()}")
    sigma = np.maximum(sigma, 0.0)        # a Color above 1 would absorb negatively: Cycles' too, none here
    if sigma.max() > 0:
        bsdf.interior = Interior([float(x) for x in sigma])
    return bsdf
