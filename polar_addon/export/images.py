"""Blender images and texture nodes → engine textures (docs/guide/blender.md, "Using it": existing scenes).

An input that a texturable parameter reads may be linked to an Image Texture (the image's own pixels; its
interpolation, extension and colour space, sRGB images filtered on their encoded values where Cycles does so
(``image_pixels``); the UV map through UV Map / Texture Coordinate ▸ UV nodes and Mapping nodes), to one channel
of one through Separate Color, or to a Color Attribute / Attribute node (a vertex colour): ``texture_source``
makes it a TextureInput; a roughness texture becomes m = r² per point (``TextureInput(power=2)``).  An image
whose file is missing renders Cycles' magenta (1, 0, 1).  Converted images are cached between exports
(``image_pixels``).  Anything else linked on such an input is the node reader's (node_reader: baked or its own
value).
"""

import hashlib
import os

import numpy as np

from ...engine.materials.roughness import ALPHA_MIN, ROUGHNESS_MIN
from ...engine.textures import ImageTexture, TextureInput, VertexColour
from ...engine.textures.image import linear_to_srgb, srgb_to_linear
from ...engine.textures.texture import srgb_decode
from .node_links import linked_source
from .world import interpolated_encoded


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


def uv_source(tex_node, mat, warnings):
    """(UV map name, '' = the active render map; affine map A (2, 2), b (2,)) of an Image Texture's
    Vector input, or None (with a warning) for coordinates other than a UV map."""
    A, b = np.eye(3), np.zeros(3)
    socket = tex_node.inputs["Vector"]
    for _ in range(32):
        node, out = linked_source(socket)
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
    _, A, b = uv_source(tex_node, mat, warnings)
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
    source, source_out = linked_source(node.inputs[0])
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


def baked_link(socket) -> bool:
    """True if a shader's input is linked to a graph that is not a texture the exporter reads itself
    (what ``_linked_input_fallback`` may bake; Normal inputs are normal/bump maps, never baked)."""
    if not socket.is_linked or socket.type == "SHADER" or socket.name == "Normal":
        return False
    node, out = linked_source(socket)
    return node is not None and not _texture_node(node, out)


def texture_source(socket, mat, warnings, roughness=False, node_name=""):
    """A TextureInput for a linked input socket (Image Texture, Color Attribute or Attribute node),
    or None (then :func:`_linked_input_fallback` decides).  ``roughness``: the parameter is m = r²
    (Beckmann slope from Blender roughness): the texture is squared after interpolation, image
    texels kept ≥ ROUGHNESS_MIN (m ≥ 1e-4, the engine's least textured slope)."""
    node, out = linked_source(socket)
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
