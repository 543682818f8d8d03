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
Roughness r maps to the Beckmann slope m = r² (as Cycles' α = r²); below m = 0.02 the smooth model
is used.  Every value is validated; a NaN or out-of-range input is an error naming the material
and the input.

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

from ...engine.materials.conductor import SmoothConductor
from ...engine.materials.dielectric import SmoothDielectric
from ...engine.materials.lambert import Lambert
from ...engine.materials.catalogue import MODELS
from ...engine.materials.normal_map import ShadingNormal
from ...engine.materials.torrance_sparrow import M_MIN
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

SMOOTH_LIMIT = 0.02
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

#: least texel of a roughness texture: the float32 nearest 0.01 whose square is ≥ M_MIN (a textured
#: Beckmann m must stay ≥ M_MIN: there is no per-point smooth limit)
ROUGHNESS_MIN = float(np.nextafter(np.float32(0.01), np.float32(1)))

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
    return (image.name_full, image.source, path, mtime, packed, image.colorspace_settings.name,
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
        warnings.extend(f"material {mat!r}: {note}" for note in entry[4])
        return entry[2], entry
    notes = []
    path = image.filepath_from_user() if image.source == "FILE" else ""
    # a file image whose file is gone and that is not packed: Cycles reads the file, finds nothing and
    # renders magenta, whatever pixels the image may still hold in memory
    gone = image.source == "FILE" and image.packed_file is None and not os.path.isfile(path)
    w, h = image.size
    n = len(image.pixels) if w and h and not gone else 0
    if n == 0 or n != w * h * image.channels:
        path = path or image.name
        notes.append(f"image {image.name!r} (file {path!r}) cannot be loaded; it renders magenta (1, 0, 1) as "
                     "in Cycles")
        pixels = np.array(MISSING_RGBA, np.float32).reshape(1, 1, 4)
        digest = "missing"
        encoded = None
    else:
        raw = np.empty(n, np.float32)
        image.pixels.foreach_get(raw)
        digest = hashlib.blake2b(raw.tobytes(), digest_size=16).hexdigest()
        if entry is not None and entry[1] == digest:
            _IMAGES[image.name_full] = (signature,) + entry[1:]
            warnings.extend(f"material {mat!r}: {note}" for note in entry[4])
            return entry[2], _IMAGES[image.name_full]
        pixels = raw.reshape(h, w, image.channels)
        if image.channels != 4:           # grey, grey + alpha, RGB → RGBA
            c = image.channels
            rgb = pixels[..., :1].repeat(3, axis=2) if c <= 2 else pixels[..., :3]
            alpha = pixels[..., 1:2] if c == 2 else np.ones((h, w, 1), np.float32)
            pixels = np.concatenate((rgb, alpha), axis=2)
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
        pixels = np.ascontiguousarray(pixels, np.float32)
        if not np.all(np.isfinite(pixels)):
            pixels = np.nan_to_num(pixels, nan=0.0, posinf=0.0, neginf=0.0)
        if encoded is not None and not np.all(np.isfinite(encoded)):
            encoded = np.nan_to_num(encoded, nan=0.0, posinf=0.0, neginf=0.0)
    entry = (signature, digest, pixels, {}, notes, encoded)
    _IMAGES.pop(image.name_full, None)
    while len(_IMAGES) >= IMAGE_CACHE_SIZE:          # the least recently converted image goes first
        _IMAGES.pop(next(iter(_IMAGES)))
    _IMAGES[image.name_full] = entry
    warnings.extend(f"material {mat!r}: {note}" for note in notes)
    return pixels, entry


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


def _texture_node(node, out) -> bool:
    """True if output ``out`` of ``node`` is a texture the exporter reads itself (texture_source):
    an Image Texture, a Color Attribute, an Attribute (Geometry) node's Color or Alpha."""
    kind = node.bl_idname
    return kind in ("ShaderNodeTexImage", "ShaderNodeVertexColor") or (
        kind == "ShaderNodeAttribute" and node.attribute_type == "GEOMETRY" and out.name in ("Color", "Alpha"))


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
    if kind == "ShaderNodeTexImage":
        alpha = out.name == "Alpha"
        texture = image_texture(node, mat, warnings, alpha=alpha, min_value=ROUGHNESS_MIN if roughness else None)
        return TextureInput(texture, None, power=power)        # the Alpha output: a one-channel texture
    if kind in ("ShaderNodeVertexColor", "ShaderNodeAttribute"):
        name = node.layer_name if kind == "ShaderNodeVertexColor" else node.attribute_name
        alpha = out.name == "Alpha"
        # colours in [0, 1]: a roughness maps to m = M_MIN + (1 − M_MIN)·r² (≥ M_MIN without clamping)
        scale, offset = (1.0 - M_MIN, M_MIN) if roughness else (1.0, 0.0)
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


def gulbrandsen_nk(reflectivity, edge_tint):
    """Complex index (n, k) per channel from reflectivity r and edge tint g (Gulbrandsen 2014)."""
    r = np.clip(np.asarray(reflectivity, float), 0.0, 0.99)
    g = np.clip(np.asarray(edge_tint, float), 0.0, 1.0)
    sr = np.sqrt(r)
    n = g * (1 - r) / (1 + r) + (1 - g) * (1 + sr) / (1 - sr)
    k = np.sqrt(np.maximum((r * (n + 1) ** 2 - (n - 1) ** 2) / (1 - r), 0.0))
    return n, k


def _rgb_spectrum(rgb, kind="reflectance"):
    if max(rgb) == min(rgb):
        return ConstantSpectrum(rgb[0])
    return RGBReflectanceSpectrum(rgb) if kind == "reflectance" else RGBUnboundedSpectrum(rgb)


def _conductor(n_rgb, k_rgb, m, warnings, mat, diffuse=None):
    n, k = _rgb_spectrum(list(n_rgb), "unbounded"), _rgb_spectrum(list(k_rgb), "unbounded")
    if m < SMOOTH_LIMIT and diffuse is None:
        return SmoothConductor(n, k)
    return _torrance_sparrow(n, k, max(m, 1e-4), mat, diffuse=diffuse)


def _torrance_sparrow(n, k, m, mat, shadowing="ts", diffuse=None, layering="add"):
    """Torrance–Sparrow (or its smooth limit below M_MIN) with an optional Lambertian part
    combined by ``layering`` ("add" or Cycles' "albedo_scaling")."""
    from ...engine.materials.smooth_limit import MirrorWithDiffuse
    from ...engine.materials.torrance_sparrow import TorranceSparrow
    kwargs = {}
    if diffuse is not None and max(diffuse) > 0:
        kwargs = {"diffuse_albedo": _rgb_spectrum(diffuse), "diffuse_weight": 1.0, "diffuse_layering": layering}
    if m < M_MIN:   # roughness 0: the smooth limit (Fresnel mirror + Lambertian part)
        return MirrorWithDiffuse(n, k, **kwargs)
    return TorranceSparrow(n, k, m, shadowing=shadowing, **kwargs)


def _coat_roughness(m):
    """Coat keyword arguments: smooth below the smooth limit, Beckmann m otherwise."""
    return {"distribution": "smooth"} if m < SMOOTH_LIMIT else {"distribution": "beckmann", "m": m}


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


def _slope(values, name, decl, where):
    """A roughness input (Beckmann m) ≥ 0 within the declared maximum; small values map to the smooth model."""
    p = decl[name]
    return p.with_(lo=0.0).number(values.pop(name, p.socket.default), f"{where}.{p.socket.name}")


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
        if not isinstance(values.get("m"), TextureInput):
            m = _slope(values, "m", decl, where)
            values["m"] = m if m >= M_MIN else 0.0    # roughness 0: the smooth limit (Fresnel mirror + Lambertian part)
        values["shadowing"] = "smith" if node.shadowing == "SMITH" else "ts"
        if values.get("diffuse_albedo") == 0.0:   # black: no Lambertian part at all
            del values["diffuse_albedo"]
    if model == "WEIDLICH_WILKIE":
        coat_decl = decl["coats"].members
        coat_values = _socket_values(r, coat_decl)
        if isinstance(coat_values.get("m"), TextureInput):     # a textured Beckmann m (≥ M_MIN, checked at build)
            coat_values["distribution"] = "beckmann"
        else:
            m = _slope(coat_values, "m", coat_decl, where)
            if m >= SMOOTH_LIMIT:
                coat_values.update(distribution="beckmann", m=m)
        base_node = _follow(node.inputs["Base"])
        if depth > 16:
            raise SceneError(f"material {mat!r}", "layered materials nest more than 16 coats deep")
        parts["coats"] = [coat_decl.build(_declared(coat_decl, coat_values, where))]
        parts["base"] = Lambert(ConstantSpectrum(DEFAULT_ALBEDO)) if base_node is None else \
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


def _lambert(albedo, mat, node):
    """Lambert of a constant [r, g, b] or a colour texture."""
    if isinstance(albedo, TextureInput):
        return _textured_model("lambert", {"albedo": albedo}, mat, node)
    return Lambert(_rgb_spectrum(albedo))


def gulbrandsen_textures(colour: TextureInput, edge):
    """(n, κ) TextureInputs of a conductor whose reflectivity is an image texture: Gulbrandsen's
    map applied to every texel (float64 texels, so a texel gives exactly the constant conversion of
    its colour; between texels the index is interpolated, not the colour), with the edge tint the
    same texture or a constant [r, g, b]; None for other textures (colour attributes)."""
    tex = colour.texture
    if not isinstance(tex, ImageTexture) or colour.channel is not None:
        return None
    rgb = tex.linear_pixels.astype(np.float64)
    g = rgb if edge is colour else np.asarray(edge, np.float64)[None, None, :]
    if rgb.shape[2] == 1 and g.shape[2] == 3 and max(edge) != min(edge):
        rgb = np.repeat(rgb, 3, axis=2)
    elif g.shape[2] == 3 and rgb.shape[2] == 1:
        g = g[..., :1]
    n, k = gulbrandsen_nk(rgb, g)
    return tuple(TextureInput(ImageTexture(a, tex.interpolation, tex.extension, name=f"{tex.name} ({what})",
                                           uv_transform=tex.uv_transform))
                 for a, what in ((n, "n"), (k, "κ")))


def _conductor_from_colour(r, colour_name, edge_name, m, mat, node, warnings):
    """Gulbrandsen conductor from a colour (and edge tint) input: a colour image texture gives n, κ
    per texel; the edge tint and colour attributes stay constant (own value, warning); the
    roughness m may be a texture."""
    colour = r.rgb_or_texture(colour_name, 0.0, 1.0, bake=False)      # n, κ per texel of an image only
    edge = colour if edge_name is None else r.rgb(edge_name, 0.0, 1.0)
    if isinstance(colour, TextureInput):
        sources = gulbrandsen_textures(colour, edge)
        if sources is not None:
            n, k = sources
            if isinstance(m, TextureInput) or m >= SMOOTH_LIMIT:
                m = m if isinstance(m, TextureInput) else max(m, 1e-4)
                return _textured_model("torrance_sparrow", {"n": n, "k": k, "m": m}, mat, node)
            return _textured_model("conductor", {"n": n, "k": k}, mat, node)
        warnings.append(f"material {mat!r}: input {colour_name!r} of {node.name!r}: a colour attribute cannot set a "
                        "metal's index per point; its own value is used")
        colour = r._checked_rgb(colour_name, 0.0, 1.0)
        edge = colour if edge_name is None else edge
    n, k = gulbrandsen_nk(colour, edge)
    if isinstance(m, TextureInput):
        return _textured_model("torrance_sparrow", {"n": list(map(float, n)), "k": list(map(float, k)), "m": m},
                               mat, node)
    return _conductor(n, k, m, warnings, mat)


def _principled(node, mat, warnings, bake=None):
    r = _Reader(mat, node, warnings, bake)
    if r.float("Metallic", 0.0, 1.0) >= 0.5:
        m, _ = r.roughness_or_texture("Roughness")
        return _conductor_from_colour(r, "Base Color", None, m, mat, node, warnings)
    ior = r.float("IOR", 0.0, 100.0, lo_open=True)
    if r.float("Transmission Weight", 0.0, 1.0) >= 0.5:
        rough = r.float("Roughness", 0.0, 1.0)
        return _glass(ior, rough, getattr(node, "distribution", ""), mat, warnings, "rough transmission")
    base = r.rgb_or_texture("Base Color", 0.0, 1.0)
    m, _ = r.roughness_or_texture("Roughness")
    if r.float("Coat Weight", 0.0, 1.0) > 0:
        under = _principled_coated_base(base, m, ior, mat, node)
        from ...engine.materials.weidlich_wilkie import Coat, WeidlichWilkie
        coat = Coat(n=r.float("Coat IOR", 1.0, 10.0), thickness=0.0, absorption=ConstantSpectrum(0.0),
                    **_coat_roughness(r.float("Coat Roughness", 0.0, 1.0) ** 2))
        return WeidlichWilkie([coat], under)
    return _principled_dielectric(base, m, ior, mat, node)


def _principled_dielectric(base, m, ior, mat, node):
    """Cycles' Principled dielectric: the specular layer (Torrance–Sparrow n = IOR, m = r², or its
    smooth limit, a Fresnel mirror, below SMOOTH_LIMIT) over the Lambertian base colour weighted
    by one minus the specular layer's albedo at the view direction ("albedo_scaling", as Cycles'
    closure_layering_weight).  Base colour and roughness may be textures."""
    if _textured(base, m):
        values = {"n": ior, "k": 0.0, "diffuse_layering": "albedo_scaling"}
        if isinstance(m, TextureInput):
            values["m"] = m
        else:   # m = 0 builds the smooth limit (MirrorWithDiffuse)
            values["m"] = max(m, M_MIN) if m >= SMOOTH_LIMIT else 0.0
        if isinstance(base, TextureInput) or max(base) > 0:
            values["diffuse_albedo"] = base
        return _textured_model("torrance_sparrow", values, mat, node)
    return _torrance_sparrow(ConstantSpectrum(ior), ConstantSpectrum(0.0), m if m >= SMOOTH_LIMIT else 0.0, mat,
                             diffuse=base, layering="albedo_scaling")


def _principled_coated_base(base, m, ior, mat, node):
    """The base under a Principled coat: the earlier mapping (Torrance–Sparrow + Lambert added, or
    Lambert alone below SMOOTH_LIMIT), kept until the coat's layering is matched to Cycles too."""
    if _textured(base, m):
        if isinstance(m, TextureInput) or m >= SMOOTH_LIMIT:
            values = {"n": ior, "k": 0.0, "m": m if isinstance(m, TextureInput) else max(m, 1e-4)}
            if isinstance(base, TextureInput) or max(base) > 0:
                values["diffuse_albedo"] = base
            return _textured_model("torrance_sparrow", values, mat, node)
        return _lambert(base, mat, node)
    return _torrance_sparrow(ConstantSpectrum(ior), ConstantSpectrum(0.0), max(m, 1e-4), mat, diffuse=base) \
        if m >= SMOOTH_LIMIT else Lambert(_rgb_spectrum(base))


def _glass(ior, roughness, distribution, mat, warnings, what):
    """Smooth dielectric below the smooth limit, else the rough dielectric with GGX α = roughness².

    Cycles' GGX is single scattering and maps exactly; its Multiscatter GGX (Principled's default) adds
    the energy of multiple scattering between facets, which the polarising model does not have: it is
    rendered as single-scattering GGX with one warning.  Beckmann → Beckmann with the same α.
    """
    from ...engine.materials.rough_dielectric import ALPHA_MIN, RoughDielectric, index_matched
    alpha = roughness * roughness
    if alpha < SMOOTH_LIMIT or index_matched(ior, 1.0):
        return SmoothDielectric(ior)
    if distribution == "MULTI_GGX":
        warnings.append(f"material {mat!r}: {what} with Multiscatter GGX is rendered as single-scattering GGX "
                        "(rough_dielectric, no multiple-scattering energy compensation)")
    return RoughDielectric(ior, max(alpha, ALPHA_MIN), "beckmann" if distribution == "BECKMANN" else "ggx")


def _emission(node, mat, warnings, colour_name="Color", strength_name="Strength"):
    r = _Reader(mat, node, warnings)
    strength = r.float(strength_name, 0.0)
    colour = r.rgb(colour_name, 0.0)
    if strength <= 0 or max(colour) <= 0:
        return None
    return RGBIlluminantSpectrum(colour, strength)


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
        elif kind == "ShaderNodeVertexColor":
            needs["colors"].append(node.layer_name)
        elif kind == "ShaderNodeAttribute" and node.attribute_type == "GEOMETRY":
            needs["colors"].append(node.attribute_name)
        elif kind in _NORMAL_SHADERS + ("PolarShaderNodeBSDF",) and any(map(_baked_link, node.inputs)):
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
    """``bsdf`` wrapped in the engine's ShadingNormal when the shader's Normal input is a tangent-space
    Normal Map and/or a Bump node on image textures (Cycles: n = normalise(x·T + y·B + z·n), B = sign·(n × T)
    with MikkTSpace tangents; bump n' = normalise(n − distance·∇h), blended by Strength)."""
    sock = node.inputs.get("Normal")
    if sock is None or not sock.is_linked:
        return bsdf
    normal, bump, ok = _normal_nodes(sock)
    if not ok:
        return bsdf
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
    if "normal_map" not in kw and "bump_map" not in kw:
        return bsdf
    return ShadingNormal(bsdf, **kw)


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
                   "ShaderNodeBsdfPrincipled")


def _surface_bsdf(node, mat, warnings, depth, bake=None):
    kind = node.bl_idname
    if kind == "PolarShaderNodeBSDF":
        return polar_node_bsdf(node, mat, warnings, depth, bake), None
    r = _Reader(mat, node, warnings, bake)
    if kind == "ShaderNodeBsdfDiffuse":
        return _lambert(r.rgb_or_texture("Color", 0.0, 1.0), mat, node), None
    if kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
        m, _ = r.roughness_or_texture("Roughness")
        return _conductor_from_colour(r, "Color", None, m, mat, node, warnings), None
    if kind == "ShaderNodeBsdfMetallic":
        m, _ = r.roughness_or_texture("Roughness")
        if getattr(node, "fresnel_type", "") == "PHYSICAL_CONDUCTOR":
            n, k = r.rgb("IOR", 0.0), r.rgb("Extinction", 0.0)
            if isinstance(m, TextureInput):
                return _textured_model("torrance_sparrow", {"n": n, "k": k, "m": m}, mat, node), None
            return _conductor(n, k, m, warnings, mat), None
        return _conductor_from_colour(r, "Base Color", "Edge Tint", m, mat, node, warnings), None
    if kind in ("ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction"):
        rough = r.float("Roughness", 0.0, 1.0)
        return _glass(r.float("IOR", 0.0, 100.0, lo_open=True), rough, getattr(node, "distribution", ""), mat,
                      warnings, "rough glass"), None
    if kind == "ShaderNodeBsdfPrincipled":
        emission = _emission(node, mat, warnings, "Emission Color", "Emission Strength")
        return _principled(node, mat, warnings, bake), emission
    if kind == "ShaderNodeEmission":
        return Lambert(ConstantSpectrum(0.0)), _emission(node, mat, warnings)
    if kind in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
        first = next((_follow(s) for s in node.inputs if s.type == "SHADER" and s.is_linked), None)
        warnings.append(f"material {mat!r}: {node.bl_idname} is not supported; using its first shader input")
        if first is not None:
            return surface_bsdf(first, mat, warnings, depth + 1, bake)
    else:
        warnings.append(f"material {mat!r}: shader {kind} is not supported; rendered as grey Lambert")
    return Lambert(ConstantSpectrum(DEFAULT_ALBEDO)), None


def export_material(material, warnings, bake=None):
    """(BSDF, emission or None) for a Blender material (None → default grey).  ``bake``: a
    BakeTarget (the object the material is exported for) to bake linked inputs on, or None or a
    NoBake (their own values, one warning each).  Every Blender material is two-sided, as in Cycles
    (BSDF.two_sided: an opaque one seen from the back shades with flipped normals)."""
    bsdf, emission = _material_bsdf(material, warnings, bake)
    bsdf.two_sided = True
    return bsdf, emission


def _material_bsdf(material, warnings, bake):
    if material is None:
        return Lambert(ConstantSpectrum(DEFAULT_ALBEDO)), None
    tree = compat.node_tree_in_use(material)
    if tree is None:
        return Lambert(_rgb_spectrum([float(c) for c in material.diffuse_color[:3]])), None
    output = tree.get_output_node("ALL") or tree.get_output_node("CYCLES")
    node = _follow(output.inputs["Surface"]) if output is not None else None
    if node is None:
        warnings.append(f"material {material.name!r} has no surface shader; rendered black")
        return Lambert(ConstantSpectrum(0.0)), None
    return surface_bsdf(node, material.name, warnings, bake=bake)
