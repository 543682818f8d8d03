"""Blender materials → engine BSDFs (and emission).

A material's Surface may be
- a **Polarising BSDF** node: its model and inputs are used exactly;
- a standard shader, converted to the closest polarising model (README, "Blender materials"):
  Diffuse → Lambert; Glossy/Anisotropic → conductor from the colour (Gulbrandsen 2014);
  Metallic (Physical Conductor) → conductor with its n, k; Glass/Refraction → smooth dielectric, or
  with roughness r the rough dielectric (single-scattering GGX, α = r²; Cycles' Multiscatter GGX
  adds energy compensation, which is not modelled: one warning); Principled → conductor
  (Metallic ≥ 0.5), dielectric or rough dielectric as Glass (Transmission ≥ 0.5), Weidlich–Wilkie
  coat (Coat Weight > 0) or Torrance–Sparrow dielectric + Lambert (otherwise); Emission → emitter;
- anything else: grey Lambert with a warning.
Roughness r maps to the Beckmann slope m = r² (as Cycles' α = r²); below m = 0.02 the smooth model
is used.  A linked Diffuse Color or Principled Base Color (dielectric) is baked by Cycles to an
image on the object's UV map (``texture_bake``) when the material is exported for an object; other
linked inputs use their unlinked value, with a warning.  Every value is validated; a NaN or
out-of-range input is an error naming the material and the input.
"""

import math
import weakref

import numpy as np

from ...engine.materials.conductor import SmoothConductor
from ...engine.materials.dielectric import SmoothDielectric
from ...engine.materials.lambert import Lambert
from ...engine.materials.torrance_sparrow import M_MIN
from ...engine.errors import SceneError
from ...engine.spectral import (ConstantSpectrum, RGBIlluminantSpectrum, RGBReflectanceSpectrum,
                                RGBUnboundedSpectrum)
from ...engine.textures import ImageTexture, TexturedNumber, TexturedSpectrum, TextureInput
from ..nodes.models import DIELECTRIC_PRESETS, NODE_MODELS
from .texture_bake import bake_input

SMOOTH_LIMIT = 0.02
DEFAULT_ALBEDO = 0.8


def _follow(socket):
    """The node feeding an input socket (through reroutes), or None."""
    if not socket.is_linked:
        return None
    node = socket.links[0].from_node
    while node is not None and node.bl_idname == "NodeReroute":
        node = node.inputs[0].links[0].from_node if node.inputs[0].is_linked else None
    return node


class BakeTarget:
    """What a material is exported for, so that linked inputs can be baked on its UV map
    (``texture_bake.bake_input``): the (evaluated) object, its 4×4 world matrix, the Blender material,
    the bake resolution.  ``requested`` becomes True once an input needed a bake (baked or not): the
    material is then exported per object."""

    def __init__(self, obj, matrix, material, resolution):
        self.obj, self.matrix, self.material, self.resolution = obj, matrix, material, resolution
        self.requested = False


#: Values of baked textures (clamped to an input's range) by bake, living as long as the bake's cache entry.
_BAKED_VALUES = weakref.WeakKeyDictionary()


def _linked_input_fallback(reader, socket, lo, hi):
    """The value of a linked input whose graph Polar does not evaluate itself, baked by Cycles on the
    object's UV map and clamped to [lo, hi] (the input's range): a TexturedSpectrum for a colour
    input, a TexturedNumber for a float input; or None — no object to bake on (one warning), or no
    UV map (``bake_input`` warns) — when the socket's own value is used."""
    target = reader.bake
    if target is None:
        reader.warnings.append(f"material {reader.mat!r}: input {socket.name!r} of {reader.node.name!r} is linked; "
                               "textures are not supported yet, its own value is used")
        return None
    target.requested = True
    baked = bake_input(target.obj, target.material, socket, target.resolution, reader.warnings,
                       matrix=target.matrix)
    if baked is None:
        return None
    value = _BAKED_VALUES.get(baked, {}).get((lo, hi))
    if value is None:           # computed once per cached bake: the bounds scan every texel
        tex = baked.texture
        if tex.pixels.min() < lo or tex.pixels.max() > hi:      # e.g. a Color Ramp beyond [0, 1]: as Cycles' clamp
            tex = ImageTexture(np.clip(tex.pixels, lo, hi), tex.interpolation, tex.extension, tex.name)
        source = TextureInput(tex, baked.channel, baked.scale, baked.offset)
        value = TexturedNumber(source) if tex.channels == 1 else TexturedSpectrum(source)
        _BAKED_VALUES.setdefault(baked, {})[(lo, hi)] = value
    return value


class _Reader:
    """Reads validated input values of one node, recording warnings once per material."""

    def __init__(self, material_name, node, warnings, bake=None):
        self.mat, self.node, self.warnings, self.bake = material_name, node, warnings, bake

    def _socket(self, name):
        sock = self.node.inputs.get(name)
        if sock is None:
            raise SceneError(f"material {self.mat!r}", f"node {self.node.name!r} has no input {name!r}")
        if sock.is_linked and sock.type != "SHADER":
            self.warnings.append(f"material {self.mat!r}: input {name!r} of {self.node.name!r} is linked; "
                                 "textures are not supported yet, its own value is used")
        return sock

    def float(self, name, lo=-math.inf, hi=math.inf, lo_open=False):
        v = float(self._socket(name).default_value)
        if not math.isfinite(v) or v < lo or v > hi or (lo_open and v == lo):
            rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
            raise SceneError(f"material {self.mat!r}.{self.node.name}.{name}", f"must be in {rng}, got {v!r}")
        return v

    def rgb(self, name, lo=0.0, hi=math.inf, textured=False):
        """[r, g, b]; with ``textured`` a linked input may give a baked TexturedSpectrum instead."""
        sock = self.node.inputs.get(name)
        if textured and sock is not None and sock.is_linked:
            value = _linked_input_fallback(self, sock, lo, hi)       # warns when it returns None
            if value is not None:
                return value
        else:
            sock = self._socket(name)
        v = [float(c) for c in sock.default_value[:3]]
        if not all(math.isfinite(c) and lo <= c <= hi for c in v):
            raise SceneError(f"material {self.mat!r}.{self.node.name}.{name}",
                             f"components must be in [{lo:g}, {hi:g}], got {v}")
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
    if isinstance(rgb, TexturedSpectrum):        # a baked input (_linked_input_fallback)
        return rgb
    if max(rgb) == min(rgb):
        return ConstantSpectrum(rgb[0])
    return RGBReflectanceSpectrum(rgb) if kind == "reflectance" else RGBUnboundedSpectrum(rgb)


def _conductor(n_rgb, k_rgb, m, warnings, mat, diffuse=None):
    n, k = _rgb_spectrum(list(n_rgb), "unbounded"), _rgb_spectrum(list(k_rgb), "unbounded")
    if m < SMOOTH_LIMIT and diffuse is None:
        return SmoothConductor(n, k)
    return _torrance_sparrow(n, k, max(m, 1e-4), mat, diffuse=diffuse)


def _torrance_sparrow(n, k, m, mat, shadowing="ts", diffuse=None):
    from ...engine.materials.smooth_limit import MirrorWithDiffuse
    from ...engine.materials.torrance_sparrow import TorranceSparrow
    kwargs = {}
    if diffuse is not None and (isinstance(diffuse, TexturedSpectrum) or max(diffuse) > 0):
        kwargs = {"diffuse_albedo": _rgb_spectrum(diffuse), "diffuse_weight": 1.0}
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


def polar_node_bsdf(node, mat, warnings, depth=0):
    """BSDF of a Polarising BSDF node (a model's own parameter checks become errors naming the material)."""
    try:
        return _polar_node_bsdf(node, mat, warnings, depth)
    except ValueError as e:
        if isinstance(e, SceneError):
            raise
        raise SceneError(f"material {mat!r}.{node.name}", str(e)) from None


def _polar_node_bsdf(node, mat, warnings, depth):
    """The node's inputs and menus → the model's declared parameters → the model's builder."""
    model = node.model
    decl = NODE_MODELS.get(model)
    if decl is None:
        raise SceneError(f"material {mat!r}", f"unknown Polarising BSDF model {model!r}")
    r = _Reader(mat, node, warnings)
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
        m = _slope(values, "m", decl, where)
        values["m"] = m if m >= M_MIN else 0.0    # roughness 0: the smooth limit (Fresnel mirror + Lambertian part)
        values["shadowing"] = "smith" if node.shadowing == "SMITH" else "ts"
        if values.get("diffuse_albedo") == 0.0:   # black: no Lambertian part at all
            del values["diffuse_albedo"]
    if model == "WEIDLICH_WILKIE":
        coat_decl = decl["coats"].members
        coat_values = _socket_values(r, coat_decl)
        m = _slope(coat_values, "m", coat_decl, where)
        if m >= SMOOTH_LIMIT:
            coat_values.update(distribution="beckmann", m=m)
        base_node = _follow(node.inputs["Base"])
        if depth > 16:
            raise SceneError(f"material {mat!r}", "layered materials nest more than 16 coats deep")
        parts["coats"] = [coat_decl.build(_declared(coat_decl, coat_values, where))]
        parts["base"] = Lambert(ConstantSpectrum(DEFAULT_ALBEDO)) if base_node is None else \
            surface_bsdf(base_node, mat, warnings, depth + 1)[0]
        values["form"] = "published" if node.ww_form == "PUBLISHED" else "energy"
    return decl.build(_declared(decl, values, where), **parts)


def _principled(node, mat, warnings, bake=None):
    r = _Reader(mat, node, warnings, bake)
    metal = r.float("Metallic", 0.0, 1.0) >= 0.5
    glass = not metal and r.float("Transmission Weight", 0.0, 1.0) >= 0.5
    base = r.rgb("Base Color", 0.0, 1.0, textured=not (metal or glass))   # a dielectric's albedo may be baked
    rough = r.float("Roughness", 0.0, 1.0)
    m = rough * rough
    if metal:
        n, k = gulbrandsen_nk(base, base)
        return _conductor(n, k, m, warnings, mat)
    ior = r.float("IOR", 0.0, 100.0, lo_open=True)
    if glass:
        return _glass(ior, rough, getattr(node, "distribution", ""), mat, warnings, "rough transmission")
    under = _torrance_sparrow(ConstantSpectrum(ior), ConstantSpectrum(0.0), max(m, 1e-4), mat, diffuse=base) \
        if m >= SMOOTH_LIMIT else Lambert(_rgb_spectrum(base))
    if r.float("Coat Weight", 0.0, 1.0) > 0:
        from ...engine.materials.weidlich_wilkie import Coat, WeidlichWilkie
        coat = Coat(n=r.float("Coat IOR", 1.0, 10.0), thickness=0.0, absorption=ConstantSpectrum(0.0),
                    **_coat_roughness(r.float("Coat Roughness", 0.0, 1.0) ** 2))
        return WeidlichWilkie([coat], under)
    return under


def _glass(ior, roughness, distribution, mat, warnings, what):
    """Smooth dielectric below the smooth limit, else the rough dielectric with GGX α = roughness².

    Cycles' GGX is single scattering and maps exactly; its Multiscatter GGX (Principled's default) adds
    the energy of multiple scattering between facets, which the polarising model does not have: it is
    rendered as single-scattering GGX with one warning.  Beckmann → Beckmann with the same α.
    """
    from ...engine.materials.rough_dielectric import ALPHA_MIN, RoughDielectric
    alpha = roughness * roughness
    if alpha < SMOOTH_LIMIT:
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


def surface_bsdf(node, mat, warnings, depth=0, bake=None):
    """(BSDF, emission spectrum or None) for the shader node plugged into a Surface (``bake``: a
    BakeTarget, or None when linked inputs are not to be baked)."""
    kind = node.bl_idname
    if kind == "PolarShaderNodeBSDF":
        return polar_node_bsdf(node, mat, warnings, depth), None
    r = _Reader(mat, node, warnings, bake)
    if kind == "ShaderNodeBsdfDiffuse":
        return Lambert(_rgb_spectrum(r.rgb("Color", 0.0, 1.0, textured=True))), None
    if kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
        colour = r.rgb("Color", 0.0, 1.0)
        n, k = gulbrandsen_nk(colour, colour)
        return _conductor(n, k, r.float("Roughness", 0.0, 1.0) ** 2, warnings, mat), None
    if kind == "ShaderNodeBsdfMetallic":
        rough = r.float("Roughness", 0.0, 1.0) ** 2
        if getattr(node, "fresnel_type", "") == "PHYSICAL_CONDUCTOR":
            return _conductor(r.rgb("IOR", 0.0), r.rgb("Extinction", 0.0), rough, warnings, mat), None
        colour = r.rgb("Base Color", 0.0, 1.0)
        n, k = gulbrandsen_nk(colour, r.rgb("Edge Tint", 0.0, 1.0))
        return _conductor(n, k, rough, warnings, mat), None
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
    BakeTarget (the object the material is exported for) to bake linked inputs on, or None."""
    if material is None:
        return Lambert(ConstantSpectrum(DEFAULT_ALBEDO)), None
    tree = material.node_tree
    if tree is None:
        return Lambert(_rgb_spectrum([float(c) for c in material.diffuse_color[:3]])), None
    output = tree.get_output_node("ALL") or tree.get_output_node("CYCLES")
    node = _follow(output.inputs["Surface"]) if output is not None else None
    if node is None:
        warnings.append(f"material {material.name!r} has no surface shader; rendered black")
        return Lambert(ConstantSpectrum(0.0)), None
    return surface_bsdf(node, material.name, warnings, bake=bake)
