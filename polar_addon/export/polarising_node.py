"""The Polarising BSDF node → its engine model: the node's inputs and menus are the model's declared
parameters (nodes.models), used exactly and validated by the declaration's builder; a Weidlich–Wilkie
node's Base is any shader, converted by the caller's ``surface_bsdf``."""

import math

import numpy as np

from ...engine.errors import SceneError
from ...engine.materials.roughness import ALPHA_MIN
from ..nodes.models import DIELECTRIC_PRESETS, NODE_MODELS
from .lambert import DEFAULT_ALBEDO, lambert
from .node_links import follow
from .node_reader import Reader


def _declared_range(p):
    """(lo, hi) closed bounds of a declared parameter (an open end moved one float inward)."""
    lo = float(np.nextafter(p.lo, math.inf)) if p.lo_open else p.lo
    hi = float(np.nextafter(p.hi, -math.inf)) if p.hi_open else p.hi
    return lo, hi


#: Polarising BSDF parameters that are microfacet slopes (engine.materials.roughness)
_SLOPES = ("m", "alpha")


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


def polar_node_bsdf(node, mat, warnings, depth=0, bake=None, *, surface_bsdf):
    """BSDF of a Polarising BSDF node (a model's own parameter checks become errors naming the material).
    ``surface_bsdf``: the converter of a Weidlich–Wilkie Base shader (shaders.surface_bsdf, passed in by it:
    the Base may be any shader, this node among them)."""
    try:
        return _polar_node_bsdf(node, mat, warnings, depth, bake, surface_bsdf)
    except ValueError as e:
        if isinstance(e, SceneError):
            raise
        raise SceneError(f"material {mat!r}.{node.name}", str(e)) from None


def _polar_node_bsdf(node, mat, warnings, depth, bake, surface_bsdf):
    """The node's inputs and menus → the model's declared parameters → the model's builder."""
    model = node.model
    decl = NODE_MODELS.get(model)
    if decl is None:
        raise SceneError(f"material {mat!r}", f"unknown Polarising BSDF model {model!r}")
    r = Reader(mat, node, warnings, bake)
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
        base_node = follow(node.inputs["Base"])
        if depth > 16:
            raise SceneError(f"material {mat!r}", "layered materials nest more than 16 coats deep")
        parts["coats"] = [coat_decl.build(_declared(coat_decl, coat_values, where))]
        parts["base"] = lambert(DEFAULT_ALBEDO, mat, node) if base_node is None else \
            surface_bsdf(base_node, mat, warnings, depth + 1, bake)[0]
        values["form"] = "published" if node.ww_form == "PUBLISHED" else "energy"
    return decl.build(_declared(decl, values, where), **parts)
