"""Reading a shader node's inputs: validated constants, textures (images.texture_source) and baked graphs.

``Reader`` reads one node's inputs, recording warnings once per material.  Anything linked on a texturable
input that is not a texture the exporter reads itself (procedural textures, math nodes, …) goes through
:func:`_linked_input_fallback`: when the material is exported for an object (a :class:`BakeTarget`), Cycles
bakes it to a float image on the UV map the object's mesh exports (``texture_bake``), else (None or a
:class:`NoBake`) its own value is used, with one warning.
"""

import math
import weakref

import numpy as np

from ...engine.errors import SceneError
from ...engine.materials.roughness import ROUGHNESS_MIN
from ...engine.textures import ImageTexture, TextureInput
from .images import texture_source
from .node_links import follow
from .texture_bake import bake_input


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


#: Baked textures as material inputs (clamped to an input's range, squared for roughness) by bake,
#: living as long as the bake's cache entry.
_BAKED_INPUTS = weakref.WeakKeyDictionary()


def _own_value_warning(reader, socket, reason="which is not exported"):
    """One warning naming a linked input whose own (unlinked) value is used."""
    source = follow(socket)
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


class Reader:
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
