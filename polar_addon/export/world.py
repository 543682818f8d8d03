"""World → environment light.

* A Background (or Emission) node with unlinked Color and Strength: a constant environment,
  colour × strength.
* Background(Color ← Environment Texture, Strength unlinked), the texture equirectangular, its
  Vector unlinked or fed by Texture Coordinate Generated/Object (no object) through at most one
  Mapping node whose Location is 0 and whose Scale is uniform and positive: mapped directly to an
  environment map of the image's own pixels (as Cycles reads them: 8-bit sRGB images decoded to
  linear, float images as stored) × strength, on Cycles' texel grid, turned by the Mapping
  rotation (Euler XYZ).  Images in the sRGB colour space that Cycles reads as stored (8-bit ones,
  float files) are interpolated on their sRGB-encoded values as Cycles does (interpolation_space
  "srgb": at a sharp bright feature such as a sub-texel sun this removes ~20 % of its light
  against linear interpolation).
  Closest/Cubic/Smart interpolation renders as Linear (warning).
* Anything else (Sky Texture, gradients, mixes, other mappings, a linked Strength): baked by
  Cycles into an equirectangular map (polar_addon.export.world_bake), resolution
  ``scene.polar.world_bake_resolution`` × half of it, ``world_bake_samples`` per texel, cached
  while the world is unchanged; a warning names what prevented the direct mapping.

A Sky Texture is polarised (World ▸ Sky Polarisation, on by default; its radiance stays Cycles' bake):
the clear-sky model of engine.spectral.daylight with the node's sun — Preetham and Hosek–Wilkie:
its Sun Direction, turned by a Mapping rotation on its Vector as the radiance is; Nishita (4.5), Single and
Multiple Scattering (5.x, no Vector input): Sun Elevation ε and Rotation ρ as Cycles' bake places the sun,
(cos ε sin ρ, cos ε cos ρ, sin ε) (measured against the bake: tests/blender/test_polarised_sources.py);
the haze: Preetham/Hosek–Wilkie turbidity T, else T = 2.2 × Aerosol (Dust) Density,
clamped to [1.7, 10] (Blender's default density 1 ↔ its default turbidity 2.2); the Berry model's maximum
degree follows T (daylight.max_degree_for_turbidity).  Altitude and Air and Ozone Density change the
radiance only.  The sun disc and the ground below the horizon are unpolarised.  A sun below the horizon, a
Vector that is not a rotation of the direction, or a texture mapping of the node's own: unpolarised, one
warning.
"""

import math

import numpy as np

from ...engine.scene.description import EnvironmentLight
from ...engine.spectral import RGBIlluminantSpectrum
from .. import compat
from . import world_bake

#: width of the baked map and Cycles samples per texel when no scene setting is found
DEFAULT_BAKE_WIDTH = 1024
DEFAULT_BAKE_SAMPLES = world_bake.BAKE_SAMPLES
#: 8-bit colour spaces whose pixel values Cycles uses as they are (others: decoded, or baked)
_LINEAR_SPACES = ("Non-Color", "Linear Rec.709", "Linear", "Raw", "Linear CIE-XYZ E", "Linear CIE-XYZ D65")
#: Cycles' colour for an image that cannot be loaded
MISSING_IMAGE = (1.0, 0.0, 1.0)


def export_world(world, warnings: list, bake_width=None, frame=None, bake_samples=None):
    """The scene's environment light (engine EnvironmentLight) or None for a black world.
    ``bake_width``, ``bake_samples``: width of a baked map and Cycles samples per texel (default:
    the settings of the scene using this world)."""
    if world is None:
        return None
    tree = compat.node_tree_in_use(world)
    output = tree.get_output_node("ALL") if tree is not None else None
    if tree is None or output is None:
        colour = [float(c) for c in world.color]
        return EnvironmentLight(RGBIlluminantSpectrum(colour, 1.0)) if max(colour) > 0 else None
    if not output.inputs["Surface"].is_linked:
        return None   # nothing plugged in: black world
    node = _source(output.inputs["Surface"])
    why = [node.bl_idname if node is not None else "the Surface link"]
    if node is not None and node.bl_idname in ("ShaderNodeBackground", "ShaderNodeEmission") and not node.mute:
        c, s = node.inputs["Color"], node.inputs["Strength"]
        if not c.is_linked and not s.is_linked:
            colour, strength = [float(x) for x in c.default_value[:3]], float(s.default_value)
            if strength <= 0 or max(colour) <= 0:
                return None
            return EnvironmentLight(RGBIlluminantSpectrum(colour, strength))
        source = _source(c) if c.is_linked else None
        why = [f"{source.bl_idname} feeding Color" if source is not None else "the Color link"] if c.is_linked else []
        if s.is_linked:
            strength_source = _source(s)
            why.append(f"{strength_source.bl_idname if strength_source else 'a link'} feeding Strength")
        else:
            direct = _environment_texture(world, source, c, float(s.default_value), warnings, why)
            if direct is not None:
                return direct
    return _with_sky_polarisation(world, tree, _baked(world, warnings, bake_width, bake_samples, frame, why),
                                  warnings)


def _sky_nodes(tree):
    """The Sky Texture nodes that feed the world's output (through any nodes), in walk order."""
    out = tree.get_output_node("ALL")
    found, seen, todo = [], set(), [out]
    while todo:
        node = todo.pop()
        if node is None or node.name in seen or node.mute:
            continue
        seen.add(node.name)
        if node.bl_idname == "ShaderNodeTexSky":
            found.append(node)
        for sock in node.inputs:
            for link in sock.links:
                if link.is_valid and not link.is_muted:
                    todo.append(link.from_node)
    return found


def sky_sun_and_turbidity(node):
    """(the unit direction towards the sun (3,) in the texture's frame, the turbidity T) of a Sky Texture node,
    where Cycles' bake of it puts the sun, and the mapping in this module's docstring."""
    from ...engine.spectral.daylight import TURBIDITY_RANGE
    if node.sky_type in ("PREETHAM", "HOSEK_WILKIE"):
        sun = np.array(node.sun_direction, np.float64)
        turbidity = float(node.turbidity)
    else:
        e, r = float(node.sun_elevation), float(node.sun_rotation)
        sun = np.array([math.cos(e) * math.sin(r), math.cos(e) * math.cos(r), math.sin(e)])
        density = float(getattr(node, "aerosol_density", getattr(node, "dust_density", 1.0)))
        turbidity = 2.2 * density
    norm = np.linalg.norm(sun)
    sun = sun / norm if norm > 0 else np.array([0.0, 0.0, 1.0])
    return sun, min(max(turbidity, TURBIDITY_RANGE[0]), TURBIDITY_RANGE[1])


def _with_sky_polarisation(world, tree, light, warnings):
    """``light`` (a baked EnvironmentLight or None) polarised as the world's Sky Texture's daylight."""
    from ...engine.polarisation.sources import DirectionalPolarisation
    from ...engine.render.lights.environment import euler_xyz_matrix
    from ...engine.spectral.daylight import ClearSky, max_degree_for_turbidity
    settings = getattr(getattr(world, "original", world), "polar", None)
    model = settings.engine_model() if settings is not None else "berry"      # (World ▸ Sky Polarisation)
    if light is None or light.image is None or model is None:
        return light
    skies = _sky_nodes(tree)
    if not skies:
        return light
    node = skies[0]
    what = f"world {world.name!r}: Sky Texture {node.name!r}"
    if len(skies) > 1:
        warnings.append(f"{what} is one of {len(skies)} Sky Textures; only its polarisation is simulated")
    # Nishita (4.5), Single and Multiple Scattering (5.x) have no Vector input (unavailable: they always look up
    # the ray direction, turned by Sun Rotation alone)
    vector = next(sock for sock in node.inputs if sock.identifier == "Vector")
    rotation = _vector_rotation(vector) if vector.enabled else 0.0
    if rotation is None or not _identity_texture_mapping(node.texture_mapping):
        warnings.append(f"{what}: its Vector is not the direction turned by a Mapping rotation; its light is "
                        "rendered unpolarised")
        return light
    sun, turbidity = sky_sun_and_turbidity(node)
    if isinstance(rotation, list):
        sun = euler_xyz_matrix(np.radians(rotation)) @ sun
    elif rotation:
        c, s = math.cos(math.radians(rotation)), math.sin(math.radians(rotation))
        sun = np.array([c * sun[0] - s * sun[1], s * sun[0] + c * sun[1], sun[2]])
    if sun[2] < 0.0:
        warnings.append(f"{what}: the sun is below the horizon; the twilight sky is rendered unpolarised")
        return light
    light.sky = ClearSky(sun_direction=tuple(sun), turbidity=turbidity, model=model,
                         max_degree=max_degree_for_turbidity(turbidity))
    light.polarisation = DirectionalPolarisation("linear", f"{what} ({model} daylight)")
    return light


def _source(socket):
    """The node feeding ``socket`` (through reroutes), or None for a muted or invalid link."""
    if not socket.is_linked:
        return None
    link = socket.links[0]
    if not link.is_valid or link.is_muted:
        return None
    node = link.from_node
    while node.bl_idname == "NodeReroute" and node.inputs[0].is_linked:
        node = node.inputs[0].links[0].from_node
    return node


def _from_socket(socket):
    """The output socket feeding the linked ``socket`` (through reroutes)."""
    link = socket.links[0]
    node, out = link.from_node, link.from_socket
    while node.bl_idname == "NodeReroute" and node.inputs[0].is_linked:
        out = node.inputs[0].links[0].from_socket
        node = out.node
    return out


def _environment_texture(world, env, colour_socket, strength, warnings, why):
    """The direct mapping of an Environment Texture world, or None where it needs baking (then
    ``why`` says what prevents the direct mapping)."""
    if env is None or env.bl_idname != "ShaderNodeTexEnvironment" or env.mute:
        return None
    what = f"Environment Texture {env.name!r}"
    if _from_socket(colour_socket).identifier != "Color" or env.projection != "EQUIRECTANGULAR":
        why[:] = [f"{what}: {env.projection.lower()} projection or its Alpha output"]
        return None
    if not _identity_texture_mapping(env.texture_mapping):
        why[:] = [f"{what}: its own texture mapping"]
        return None
    rotation = _vector_rotation(env.inputs["Vector"])
    if rotation is None:
        why[:] = [f"{what}: its Vector input is not the direction turned by a Mapping rotation (Location 0, "
                  "uniform Scale)"]
        return None
    image = env.image
    if image is None or image.source not in ("FILE", "GENERATED"):
        why[:] = [f"{what}: " + (f"a {image.source.lower()} image" if image is not None else "no image")]
        return None
    if not image.has_data:
        try:
            image.reload() if image.source == "FILE" else None
        except RuntimeError:
            pass
    if image.size[0] < 1 or image.size[1] < 2 or not image.has_data:
        name = image.filepath or image.name
        warnings.append(f"world {world.name!r}: image {name!r} cannot be loaded; rendering Cycles' magenta")
        return EnvironmentLight(RGBIlluminantSpectrum(list(MISSING_IMAGE), strength)) if strength > 0 else None
    texels = _linear_texels(image)
    if texels is None:
        why[:] = [f"{what}: image {image.name!r} has alpha or the colour space {image.colorspace_settings.name!r}"]
        return None
    if env.interpolation != "Linear":
        warnings.append(f"world {world.name!r}: Environment Texture interpolation {env.interpolation!r} "
                        "renders as 'Linear'")
    if strength <= 0:
        return None
    space = "srgb" if interpolated_encoded(image) else "linear"
    return EnvironmentLight(RGBIlluminantSpectrum([1.0, 1.0, 1.0], strength), image=texels, strength=strength,
                            rotation_deg=rotation, grid="cycles", interpolation_space=space)


def interpolated_encoded(image) -> bool:
    """Cycles interpolates ``image`` on its sRGB-encoded values (and decodes the result): images in
    the sRGB colour space that it reads as stored (scene/image.cpp ``compress_as_srgb``), i.e.
    8-bit ones, and float ones read from their file; a packed or generated float image reaches
    Cycles as Blender's linear float buffer and is interpolated linearly (measured, Blender 5.0)."""
    if image.colorspace_settings.name != "sRGB":
        return False
    return not image.is_float or (image.source == "FILE" and image.packed_file is None)


def _identity_texture_mapping(tm) -> bool:
    """The texture node's own (Properties-panel) mapping does nothing."""
    return (tuple(tm.translation) == (0.0, 0.0, 0.0) and tuple(tm.rotation) == (0.0, 0.0, 0.0)
            and tuple(tm.scale) == (1.0, 1.0, 1.0) and not tm.use_min and not tm.use_max
            and (tm.mapping_x, tm.mapping_y, tm.mapping_z) == ("X", "Y", "Z"))


def _is_direction(socket) -> bool:
    """``socket`` carries the world ray direction: unlinked, or Texture Coordinate Generated or
    Object without an object (both are the direction for world shaders)."""
    if not socket.is_linked:
        return True
    node, out = _source(socket), _from_socket(socket)
    return (node is not None and node.bl_idname == "ShaderNodeTexCoord" and not node.mute
            and (out.identifier == "Generated" or (out.identifier == "Object" and node.object is None)))


def _vector_rotation(socket):
    """Euler XYZ angles (degrees, engine convention: the map turned by R) of the Vector input of an
    Environment Texture; None where the lookup is not the ray direction turned by a rotation."""
    if _is_direction(socket):
        return 0.0
    node = _source(socket)
    if node is None or node.bl_idname != "ShaderNodeMapping" or node.mute:
        return None
    if not _is_direction(node.inputs["Vector"]):
        return None
    kind = node.vector_type
    inputs = {s.identifier: s for s in node.inputs}
    if any(s.is_linked for k, s in inputs.items() if k != "Vector" and s.enabled):
        return None
    if kind in ("POINT", "TEXTURE") and any(x != 0.0 for x in inputs["Location"].default_value):
        return None
    # the environment texture normalises the vector, so a uniform positive scale changes nothing
    scale = tuple(inputs["Scale"].default_value) if inputs["Scale"].enabled else (1.0, 1.0, 1.0)
    if not (scale[0] > 0 and scale[0] == scale[1] == scale[2]):
        return None
    from mathutils import Euler
    rot = Euler(tuple(inputs["Rotation"].default_value), "XYZ")
    # POINT/VECTOR/NORMAL look up R·d: the map is turned by Rᵀ; TEXTURE looks up Rᵀ·d: turned by R
    turn = rot if kind == "TEXTURE" else rot.to_matrix().transposed().to_euler("XYZ")
    angles = [math.degrees(a) for a in turn]
    if angles[0] == 0.0 and angles[1] == 0.0:
        return angles[2]
    return angles


def _linear_texels(image):
    """Linear radiance texels (H, W, 3) float32, row 0 = zenith, as Cycles reads ``image``;
    None where the image needs baking (alpha < 1, an 8-bit colour space other than sRGB/linear)."""
    px = world_bake._pixels(image)[::-1]
    channels = px.shape[2]
    if channels == 4 and float(px[..., 3].min()) < 1.0:
        return None         # Cycles un-premultiplies float images: leave alpha to Cycles
    rgb = np.repeat(px[..., :1], 3, axis=2) if channels < 3 else px[..., :3]
    if not image.is_float:
        space = image.colorspace_settings.name
        if space == "sRGB":
            rgb = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
        elif space not in _LINEAR_SPACES:
            return None
    rgb = np.nan_to_num(rgb, nan=0.0, posinf=0.0, neginf=0.0)
    return np.ascontiguousarray(np.maximum(rgb, 0.0), dtype=np.float32)


def _bake_settings(world):
    """(width, samples) of the Polar settings of the scene using ``world`` (the context scene first)."""
    import bpy
    original = getattr(world, "original", world)
    scenes = [bpy.context.scene] if getattr(bpy.context, "scene", None) is not None else []
    for scene in scenes + list(bpy.data.scenes):
        if scene.world is not None and scene.world.original == original and hasattr(scene, "polar"):
            return int(scene.polar.world_bake_resolution), int(scene.polar.world_bake_samples)
    return DEFAULT_BAKE_WIDTH, DEFAULT_BAKE_SAMPLES


def _baked(world, warnings, bake_width, bake_samples, frame, why):
    import bpy
    width, samples = _bake_settings(world)
    width = width if bake_width is None else int(bake_width)
    samples = samples if bake_samples is None else int(bake_samples)
    height = max(2, width // 2)
    if frame is None:
        scene = getattr(bpy.context, "scene", None)
        frame = scene.frame_current if scene is not None else 1
    texels = world_bake.bake_world(world, (width, height), frame=frame, samples=samples)
    # an approximation (finite resolution: a sun disc is spread over its texels), so say so
    warnings.append(f"world {world.name!r} ({'; '.join(why)}) is baked by Cycles into a {width}×{height} "
                    "environment map")
    if not float(texels.max(initial=0.0)) > 0.0:
        return None
    return EnvironmentLight(RGBIlluminantSpectrum([1.0, 1.0, 1.0], 1.0), image=texels, strength=1.0,
                            rotation_deg=0.0, grid="cycles")
