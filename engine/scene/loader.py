"""Scene files (JSON) → engine.scene.description.Scene, validated on load.

Two formats are read:

- the engine's own format (``"format": "polar-scene/1"``, documented in the
  docs/guide/scene-format.md), and
- the renderer-neutral peer format of ``shared/peers/scenes/*.json``
  (recognised by its top-level ``light`` and ``integrator``), converted by
  engine.scene.peer_format.

Every problem raises SceneError naming the field (``objects[1].radius``) and
the allowed range.
"""

from __future__ import annotations

import json
import math
import os
import re
import sys

import numpy as np

from ..files import refuse_special_file
from ..materials.catalogue import MODELS
from ..materials.mix import MAX_COMPONENTS, Mix, map_normals
from ..materials.normal_map import ShadingNormal
from ..polarisation.sources import DirectionalPolarisation, parse_polarisation
from ..textures import TexturedNumber, parse_texture_input, textured_emission
from ..textures.image import read_image
from .description import (EMISSION_SAMPLING, ENVMAP_GRIDS, HALVES_MODES, LIGHT_PATH_FIELDS, LIGHT_TREE_MODES,
                          PARALLEL_MODES, SAMPLERS, SPECTRAL_MODES, Camera, DirectionalLight, EnvironmentLight,
                          Interior, Mesh, PointLight, RenderSettings, Scene, SpotLight)
from ..errors import SceneError
from .meshio import read_mesh
from .shapes import icosphere, quad, transform_matrix, transform_mesh
from ..spectral import ConstantSpectrum, RGBIlluminantSpectrum, parse_spectrum

FORMAT = "polar-scene/1"
#: Largest coordinate accepted: Embree works in float32 (max ~3.4e38) and rays need headroom.
MAX_COORDINATE = 1e30
#: Largest light radiance / intensity / irradiance (also radiance × colour): images are float32
#: (max ~3.4e38), so a brighter light would develop to inf.
MAX_LIGHT = 1e30
#: Deepest nesting of JSON objects and lists (the top-level object is level 1).  Real scenes nest
#: about 30 levels (16 inline layered bases); the bound keeps parsing and validation off Python's
#: recursion limit.
MAX_NESTING = 64
#: Layered materials: bases nested inline or referenced by name, and coats over one stack in all.
#: Each coat is one recursion level when the stack is built and evaluated.
MAX_LAYER_NESTING = 16
MAX_COATS = 64
#: Integers beyond double range cannot be any scene value.
_LARGEST_INTEGER = int(sys.float_info.max)


# --------------------------------------------------------------------------- field readers

def _type_name(v) -> str:
    return type(v).__name__ if v is not None else "null"


def _require(d: dict, key: str, field: str):
    if not isinstance(d, dict):
        raise SceneError(field, f"must be an object, got {_type_name(d)}")
    if key not in d:
        raise SceneError(f"{field}.{key}" if field else key, "is required but missing")
    return d[key]


def number(value, field: str, lo=-math.inf, hi=math.inf, lo_open=False, hi_open=False) -> float:
    """A finite number within [lo, hi] (open ends where asked)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(field, f"must be a number, got {value!r}")
    rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if isinstance(value, int) and abs(value) > _LARGEST_INTEGER:
        raise SceneError(field, f"must be a finite number in {rng}, got {_integer_size(value)}")
    v = float(value)
    if not math.isfinite(v):
        raise SceneError(field, f"must be a finite number in {rng}, got {value!r}")
    if v < lo or v > hi or (lo_open and v == lo) or (hi_open and v == hi):
        raise SceneError(field, f"must be in {rng}, got {v:g}")
    return v


def integer(value, field: str, lo: int, hi: int) -> int:
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > _LARGEST_INTEGER:
        raise SceneError(field, f"must be a whole number in [{lo}, {hi}], got {_integer_size(value)}")
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            (isinstance(value, float) and not math.isfinite(value)) or float(value) != int(value):
        raise SceneError(field, f"must be a whole number in [{lo}, {hi}], got {value!r}")
    v = int(value)
    if v < lo or v > hi:
        raise SceneError(field, f"must be a whole number in [{lo}, {hi}], got {v}")
    return v


def vec3(value, field: str, unit=False) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise SceneError(field, f"must be a list of 3 numbers, got {value!r}")
    v = np.array([number(x, f"{field}[{i}]") for i, x in enumerate(value)])
    if unit:
        n = np.linalg.norm(v)
        if not n > 0:
            raise SceneError(field, "must be a non-zero vector")
        v = v / n
    return v


def choice(value, field: str, allowed) -> str:
    if value not in allowed:
        raise SceneError(field, f"must be one of {', '.join(map(repr, allowed))}, got {value!r}")
    return value


def _check_keys(d: dict, field: str, allowed: set):
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise SceneError(f"{field}.{unknown[0]}" if field else unknown[0],
                         f"unknown field (allowed: {', '.join(sorted(allowed))})")


# --------------------------------------------------------------------------- JSON text and tree

def _integer_size(value: int) -> str:
    """"an integer with N digits", without str() (Python refuses str() beyond 4300 digits)."""
    value = abs(value)
    digits = int(math.log10(value)) + 1 if value else 1
    if digits > 1 and 10 ** (digits - 1) > value:      # log10 rounds up just below a power of 10
        digits -= 1
    return f"an integer with {digits} digits"


class _OversizedInteger:
    """A JSON integer literal too long to be any scene value; parsed as this marker (not int(),
    which is slow and refuses more than 4300 digits) and reported by check_json_values with its field."""

    __slots__ = ("digits",)

    def __init__(self, digits: int):
        self.digits = digits

    def __repr__(self):
        return f"an integer with {self.digits} digits"


def _json_int(literal: str):
    # 400 characters hold every integer within double range (309 digits) with room to spare.
    return int(literal) if len(literal) <= 400 else _OversizedInteger(len(literal.lstrip("-")))


_BOMS = ((b"\x00\x00\xfe\xff", "UTF-32 big-endian"), (b"\xff\xfe\x00\x00", "UTF-32 little-endian"),
         (b"\xfe\xff", "UTF-16 big-endian"), (b"\xff\xfe", "UTF-16 little-endian"))


def _decode_scene_text(raw: bytes, path: str) -> str:
    """The text of a scene file, which must be UTF-8 (RFC 8259 §8.1).

    A UTF-8 byte-order mark is skipped (RFC 8259 lets parsers ignore it).  UTF-16/UTF-32 are
    rejected even with a byte-order mark: other tools reading scene files (peer renderers, the
    shared scripts) take UTF-8 only, so accepting them here would make files that work in one
    place only.  The message says how to fix the file.
    """
    fix = "scene files must be UTF-8 (RFC 8259); save the file as UTF-8"
    for bom, name in _BOMS:
        if raw.startswith(bom):
            raise SceneError("", f"{path}: the file is {name} (it starts with a byte-order mark); {fix}")
    # JSON text starts with two ASCII characters, so a NUL among the first bytes means UTF-16/32.
    if b"\x00" in raw[:4]:
        raise SceneError("", f"{path}: the file looks like UTF-16 or UTF-32 (NUL bytes at its start); {fix}")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = raw.count(b"\n", 0, e.start) + 1
        column = e.start - (raw.rfind(b"\n", 0, e.start) + 1) + 1
        raise SceneError("", f"{path}: byte 0x{raw[e.start]:02X} at line {line}, column {column} is not "
                             f"valid UTF-8 (Latin-1 or Windows-1252 text such as 'é' is a common cause); "
                             f"{fix}") from None


_JSON_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)


def _check_text_nesting(raw: bytes, path: str) -> None:
    """Reject JSON text nesting deeper than MAX_NESTING, saying on which line.

    Works on the UTF-8 bytes: strings are blanked first (their bytes never contain a bare '"'),
    then the running count of [{ minus ]} is the depth.  Strings hold no raw newlines in JSON,
    so line numbers survive the blanking."""
    if raw.count(b"[") + raw.count(b"{") <= MAX_NESTING:
        return
    code = np.frombuffer(_JSON_STRING.sub(b'""', raw), dtype=np.uint8)
    opens = (code == ord("[")) | (code == ord("{"))
    where = np.flatnonzero(opens | (code == ord("]")) | (code == ord("}")))
    depth = np.cumsum(np.where(opens[where], 1, -1))
    if depth.size and depth.max() > MAX_NESTING:
        at = int(where[np.argmax(depth > MAX_NESTING)])
        line = int(np.count_nonzero(code[:at] == ord("\n"))) + 1
        raise SceneError("", f"{path}: objects and lists nest more than {MAX_NESTING} levels deep "
                             f"(at line {line})")


def _field_path(field: str, keys) -> str:
    for k in keys:
        field = f"{field}[{k}]" if isinstance(k, int) else (f"{field}.{k}" if field else str(k))
    return field


def _is_numeric_block(node: list, max_ndim: int) -> bool:
    """Whether a list is a regular array of numbers within int64/double range, one or two levels
    deep (at most ``max_ndim``): vertex and face lists, checked at C speed instead of item by item.
    Deeper lists are walked (numpy would expand lists that Python callers share exponentially)."""
    if not node or min(max_ndim, 2) < (2 if isinstance(node[0], list) else 1) or \
            (isinstance(node[0], list) and node[0] and isinstance(node[0][0], list)):
        return False
    try:
        a = np.asarray(node)
    except (ValueError, TypeError, OverflowError, MemoryError):
        return False
    return a.dtype.kind in "fiub" and a.ndim <= min(max_ndim, 2)


def check_json_values(data, field: str = "") -> None:
    """Reject, before any field is read, what no field may hold, naming its path: nesting deeper
    than MAX_NESTING levels, integers beyond double range (±1.8e308; anywhere, notes included)
    and keys that are not strings.  Iterative, so no document can exhaust Python's stack."""
    stack = [(data, (), 1)]
    seen = set()                 # Python callers may share sub-lists (or build cycles)
    while stack:
        node, keys, level = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if level > MAX_NESTING:
            where = _field_path(field, keys[:8]) + ("…" if len(keys) > 8 else "")
            raise SceneError(where, f"objects and lists nest more than {MAX_NESTING} levels deep")
        if isinstance(node, list) and _is_numeric_block(node, MAX_NESTING - level + 1):
            continue
        if isinstance(node, dict):
            bad = next((k for k in node if not isinstance(k, str)), None)
            if bad is not None:
                raise SceneError(_field_path(field, keys), f"keys must be strings, got {bad!r}")
            items = node.items()
        else:
            items = enumerate(node)
        children = []
        for k, v in items:
            t = type(v)
            if t is float or t is str or t is bool or v is None:
                continue
            if isinstance(v, (dict, list)):
                children.append((v, keys + (k,), level + 1))
            elif isinstance(v, _OversizedInteger) or (isinstance(v, int) and abs(v) > _LARGEST_INTEGER):
                size = repr(v) if isinstance(v, _OversizedInteger) else _integer_size(v)
                raise SceneError(_field_path(field, keys + (k,)),
                                 "must be a number within ±1.8e308 (double precision), "
                                 f"got {size}")
        stack.extend(reversed(children))


# --------------------------------------------------------------------------- sections

def parse_camera(d: dict, field: str = "camera") -> Camera:
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object")
    _check_keys(d, field, {"projection", "origin", "target", "up", "fov_deg", "fov_axis", "width",
                           "height", "ortho_width", "shift", "clip_start", "clip_end", "note"} | CAMERA_LENS_KEYS)
    projection = choice(d.get("projection", "perspective"), f"{field}.projection",
                        ("perspective", "orthographic", "equirectangular"))
    origin = vec3(_require(d, "origin", field), f"{field}.origin")
    target = vec3(_require(d, "target", field), f"{field}.target")
    up = vec3(d.get("up", [0, 0, 1]), f"{field}.up", unit=True)
    forward = target - origin
    if not np.linalg.norm(forward) > 0:
        raise SceneError(f"{field}.target", "must differ from camera.origin")
    if np.linalg.norm(np.cross(forward / np.linalg.norm(forward), up)) < 1e-6:
        raise SceneError(f"{field}.up", "must not be parallel to the viewing direction (target − origin)")
    cam = Camera(
        origin=origin, target=target, up=up,
        width=integer(_require(d, "width", field), f"{field}.width", 1, 65536),
        height=integer(_require(d, "height", field), f"{field}.height", 1, 65536),
        fov_deg=number(d.get("fov_deg", 40.0), f"{field}.fov_deg", 0, 180, lo_open=True, hi_open=True),
        fov_axis=choice(d.get("fov_axis", "x"), f"{field}.fov_axis", ("x", "y")),
        projection=projection,
        ortho_width=number(d.get("ortho_width", 2.0), f"{field}.ortho_width", 0, math.inf, lo_open=True),
        clip_start=number(d.get("clip_start", 0.0), f"{field}.clip_start", 0),
        clip_end=number(d.get("clip_end", 1e30), f"{field}.clip_end", 0, lo_open=True),
    )
    shift = d.get("shift", [0.0, 0.0])
    if not isinstance(shift, (list, tuple)) or len(shift) != 2:
        raise SceneError(f"{field}.shift", "must be a list of 2 numbers")
    cam.shift = tuple(number(s, f"{field}.shift[{i}]", -10, 10) for i, s in enumerate(shift))
    if cam.clip_end <= cam.clip_start:
        raise SceneError(f"{field}.clip_end", f"must be greater than clip_start ({cam.clip_start:g})")
    _parse_lens_and_film(d, field, cam)
    return cam


#: Camera fields of the thin lens, the panorama and the film (all optional; defaults = pinhole, opaque).
CAMERA_LENS_KEYS = {"aperture_radius", "focus_distance", "aperture_blades", "aperture_rotation_deg",
                    "aperture_ratio", "longitude_deg", "latitude_deg", "film_transparent"}


def _angle_range(value, field, lo, hi, default):
    if value is None:
        return default
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise SceneError(field, f"must be a list [min, max] of 2 angles in [{lo:g}, {hi:g}] degrees")
    a, b = (number(v, f"{field}[{i}]", lo, hi) for i, v in enumerate(value))
    if not b > a:
        raise SceneError(field, f"max ({b:g}) must be greater than min ({a:g})")
    return (a, b)


def _parse_lens_and_film(d: dict, field: str, cam: Camera) -> None:
    """Thin lens (Cycles' aperture and focus), equirectangular range and film transparency."""
    cam.aperture_radius = number(d.get("aperture_radius", 0.0), f"{field}.aperture_radius", 0, 1e6)
    if "focus_distance" in d:
        cam.focus_distance = number(d["focus_distance"], f"{field}.focus_distance", 0, 1e30, lo_open=True)
    elif cam.aperture_radius > 0:
        raise SceneError(f"{field}.focus_distance", "is required with aperture_radius > 0 (a depth > 0 along "
                                                    "the view axis)")
    blades = integer(d.get("aperture_blades", 0), f"{field}.aperture_blades", 0, 1000)
    cam.aperture_blades = blades if blades >= 3 else 0
    cam.aperture_rotation_deg = number(d.get("aperture_rotation_deg", 0.0), f"{field}.aperture_rotation_deg",
                                       -1e6, 1e6)
    cam.aperture_ratio = number(d.get("aperture_ratio", 1.0), f"{field}.aperture_ratio", 0.01, 100)
    cam.longitude_deg = _angle_range(d.get("longitude_deg"), f"{field}.longitude_deg", -360, 360, (-180.0, 180.0))
    cam.latitude_deg = _angle_range(d.get("latitude_deg"), f"{field}.latitude_deg", -90, 90, (-90.0, 90.0))
    if cam.longitude_deg[1] - cam.longitude_deg[0] > 360:
        raise SceneError(f"{field}.longitude_deg", "must span at most 360 degrees")
    transparent = d.get("film_transparent", False)
    if not isinstance(transparent, bool):
        raise SceneError(f"{field}.film_transparent", "must be true or false")
    cam.film_transparent = transparent


def parse_settings(d: dict, field: str = "render") -> RenderSettings:
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object")
    _check_keys(d, field, {"spp", "max_depth", "rr_depth", "seed", "spectral", "wavelength_nm",
                           "polarisation", "batch_rays", "threads", "reduce_spectral", "simplify",
                           "sampler", "halves", "light_tree", "parallel", *(f.name for f in LIGHT_PATH_FIELDS)})
    s = RenderSettings()                 # the defaults
    return RenderSettings(
        **light_path_settings(d, field),
        spp=integer(d.get("spp", s.spp), f"{field}.spp", 1, 1 << 24),
        max_depth=integer(d.get("max_depth", s.max_depth), f"{field}.max_depth", 1, 1024),
        rr_depth=integer(d.get("rr_depth", s.rr_depth), f"{field}.rr_depth", 1, 1024),
        seed=integer(d.get("seed", s.seed), f"{field}.seed", 0, 2 ** 63 - 1),
        spectral=choice(d.get("spectral", s.spectral), f"{field}.spectral", SPECTRAL_MODES),
        wavelength_nm=number(d.get("wavelength_nm", s.wavelength_nm), f"{field}.wavelength_nm", 360, 830),
        polarisation=choice(d.get("polarisation", s.polarisation), f"{field}.polarisation",
                            ("auto", "full", "linear", "off")),
        batch_rays=integer(d.get("batch_rays", s.batch_rays), f"{field}.batch_rays", 1024, 1 << 24),
        threads=integer(d.get("threads", s.threads), f"{field}.threads", 0, 256),
        parallel=choice(d.get("parallel", s.parallel), f"{field}.parallel", PARALLEL_MODES),
        reduce_spectral=choice(d.get("reduce_spectral", s.reduce_spectral), f"{field}.reduce_spectral",
                               ("auto", "exact", "off")),
        simplify=choice(d.get("simplify", s.simplify), f"{field}.simplify", ("auto", "off")),
        sampler=choice(d.get("sampler", s.sampler), f"{field}.sampler", SAMPLERS),
        halves=choice(d.get("halves", s.halves), f"{field}.halves", HALVES_MODES),
        light_tree=choice(d.get("light_tree", s.light_tree), f"{field}.light_tree", LIGHT_TREE_MODES),
    )


def light_path_settings(d: dict, field: str = "render") -> dict:
    """The light-path settings (engine.scene.description.LIGHT_PATH_FIELDS) given in ``d``, checked: whole
    numbers and numbers in their range, true or false."""
    out = {}
    for f in LIGHT_PATH_FIELDS:
        if f.name not in d:
            continue
        value, name = d[f.name], f"{field}.{f.name}"
        if f.kind == "int":
            out[f.name] = integer(value, name, f.lo, f.hi)
        elif f.kind == "float":
            out[f.name] = number(value, name, f.lo, f.hi)
        elif isinstance(value, bool):
            out[f.name] = value
        else:
            raise SceneError(name, f"must be true or false, got {value!r}")
    return out


def _check_layer_stack(d, field: str, materials: dict | None = None) -> None:
    """Bound a layered material or a mix before it is built, since every coat and every nested mix
    is one recursion level when the material is built and rendered: at most MAX_LAYER_NESTING layered
    bases and mixes below it along any branch, given inline or by name (resolved in ``materials``
    when given), and at most MAX_COATS coats along any branch in all.  Malformed parts are left to
    parse_material, unknown or circular references to the lookup."""
    top = field
    walked: dict[str, list[tuple[int, int]]] = {}   # name → (level, coats) already walked from it

    def walk(d, field, level, coats, names):
        kind = d.get("type") if isinstance(d, dict) else None
        if kind == "weidlich_wilkie":
            if level > MAX_LAYER_NESTING:
                raise SceneError(f"{field}.base", f"layered materials nest more than {MAX_LAYER_NESTING} levels "
                                                  f"deep below {top} (counting bases given inline and by name)")
            if isinstance(d.get("coats"), list):
                coats += len(d["coats"])
                if coats > MAX_COATS:
                    raise SceneError(f"{field}.coats", f"a layered material has at most {MAX_COATS} coats in all "
                                                       f"(counting its layered bases' coats), got {coats}")
            children = [(d.get("base"), f"{field}.base")]
        elif kind == "mix":
            if level > MAX_LAYER_NESTING:
                raise SceneError(f"{field}.materials", f"mixes and layered materials nest more than "
                                                       f"{MAX_LAYER_NESTING} levels deep below {top} (counting "
                                                       "materials given inline and by name)")
            items = d.get("materials")
            children = [(m, f"{field}.materials[{i}]") for i, m in enumerate(items[:MAX_COMPONENTS + 1])] \
                if isinstance(items, list) else []
        else:
            return
        for child, where in children:
            if isinstance(child, dict):
                walk(child, where, level + 1, coats, names)
            elif isinstance(child, str) and materials is not None and child in materials and child not in names:
                # a name already walked at a level and coat count at least as deep cannot fail now
                if any(lv >= level + 1 and c >= coats for lv, c in walked.get(child, ())):
                    continue
                walked.setdefault(child, []).append((level + 1, coats))
                walk(materials[child], f"materials.{child}", level + 1, coats, names | {child})

    walk(d, field, 0, 0, frozenset())


def parse_material(d: dict, field: str, lookup=None, depth: int = 0, base_dir: str | None = None):
    """A BSDF from a material object, read through the model's declaration (engine.materials.parameters).
    ``lookup(name)`` resolves references to other materials (the base of a layered material may be
    given inline or by name); texture image paths are relative to ``base_dir`` (the scene file's folder)."""
    if depth == 0:
        _check_layer_stack(d, field)
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object with a 'type'")
    decl = MODELS[choice(_require(d, "type", field), f"{field}.type", tuple(MODELS))]
    _check_keys(d, field, {"type", "note", "name", "normal_map", "bump_map", "two_sided", "radiance_scaling",
                           "interior"}
                | set(decl.names()))
    if depth > 0 and "interior" in d:
        raise SceneError(f"{field}.interior", "belongs to a material of the scene's \"materials\" (the one the faces "
                                              "use), not to a base or a mixed material")
    interior = _parse_interior(d["interior"], f"{field}.interior") if d.get("interior") is not None else None
    parts = {}
    for p in decl.parameters:
        if p.kind == "coats":
            coats_in = _require(d, p.name, field)
            if not isinstance(coats_in, list) or not coats_in:
                raise SceneError(f"{field}.{p.name}", "must be a non-empty list of coats (top coat first)")
            parts[p.name] = [_parse_coat(c, f"{field}.{p.name}[{i}]", p.members, base_dir)
                             for i, c in enumerate(coats_in)]
        elif p.kind == "material":
            parts[p.name] = _parse_part(d.get(p.name, p.default), f"{field}.{p.name}", lookup, depth, base_dir)
        elif p.kind == "materials":
            items = _require(d, p.name, field)
            if not isinstance(items, list) or not items or len(items) > MAX_COMPONENTS:
                raise SceneError(f"{field}.{p.name}", f"must be a list of 1 to {MAX_COMPONENTS} materials (objects "
                                                      "inline or names of materials)")
            parts[p.name] = [_parse_part(v, f"{field}.{p.name}[{i}]", lookup, depth, base_dir, mixed=True)
                             for i, v in enumerate(items)]
    bsdf = decl.build(decl.values(d, field, base_dir=base_dir), **parts)
    if d.get("normal_map") is not None or d.get("bump_map") is not None:
        if isinstance(bsdf, Mix) and any(_own_maps(c) for c in bsdf.components):
            key = "normal_map" if d.get("normal_map") is not None else "bump_map"
            raise SceneError(f"{field}.{key}", "a mix whose materials have their own normal or bump maps cannot "
                                               "have one too: give the map to each of its materials")
        bsdf = _shading_normal(bsdf, d, field, base_dir)
    two_sided = d.get("two_sided", False)
    if not isinstance(two_sided, bool):
        raise SceneError(f"{field}.two_sided", f"must be true or false, got {two_sided!r}")
    if two_sided:
        bsdf.two_sided = True
    radiance_scaling = d.get("radiance_scaling", True)
    if not isinstance(radiance_scaling, bool):
        raise SceneError(f"{field}.radiance_scaling", f"must be true or false, got {radiance_scaling!r}")
    if not radiance_scaling:
        bsdf.radiance_scaling = False
    if interior is not None and interior.renders:
        bsdf.interior = interior            # (none when it absorbs and scatters nothing: renders as without)
    return bsdf


#: Blender's Volume Absorption defaults (Color 0.8 grey, Density 1)
_INTERIOR_DEFAULT_COLOR = [0.8, 0.8, 0.8]


def _parse_interior(d, field: str) -> Interior:
    """A material's interior or the world medium (engine.scene.description.Interior): ``absorption`` σ_a per
    scene unit (a number, [r, g, b] or a spectrum table, ≥ 0), or Blender's Volume Absorption ``color`` (in
    [0, 1]) and ``density`` (≥ 0): σ_a = density·(1 − color); a scattering medium adds ``scattering`` σ_s
    (as absorption), or gives ``albedo`` (in [0, 1]) and ``density``: σ_s = albedo·density, σ_a = (1 −
    albedo)·density; ``phase`` {"type": NAME, parameters} (engine.media.catalogue; default isotropic),
    ``grid`` {"values": [x][y][z], "bounds": [[x0, y0, z0], [x1, y1, z1]]} scales both coefficients,
    ``majorant`` bounds its density for free-flight sampling; an emitting medium gives ``emission`` ε, radiance
    per scene unit of length (an illuminant: a number, [r, g, b] or a table; not scaled by the density), or
    ``emission_grid`` {"values": [r, g, b][x][y][z] (linear sRGB), "bounds"} per point; a grid medium's colour
    per point, ``colour_grid`` (as ``emission_grid``), scales σ_s by it and σ_a by max(1 − it, 0)."""
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object like {\"absorption\": [0.1, 0.2, 0.3]} (per scene unit) or "
                                "{\"color\": [0.2, 0.8, 0.3], \"density\": 1.0} (Blender's Volume Absorption)")
    _check_keys(d, field, {"absorption", "color", "density", "note", "scattering", "albedo", "phase", "grid",
                           "majorant", "emission", "emission_grid", "colour_grid"})
    medium = {"phase": _parse_phase(d["phase"], f"{field}.phase") if d.get("phase") is not None else None,
              "grid": _parse_grid(d["grid"], f"{field}.grid") if d.get("grid") is not None else None}
    if d.get("emission") is not None:
        medium["emission"] = parse_spectrum(d["emission"], f"{field}.emission", kind="illuminant")
    if d.get("emission_grid") is not None:
        medium["emission_grid"] = _parse_grid(d["emission_grid"], f"{field}.emission_grid", colour=True)
    if d.get("colour_grid") is not None:
        medium["colour_grid"] = _parse_grid(d["colour_grid"], f"{field}.colour_grid", colour=True)
    if "majorant" in d:
        medium["majorant"] = number(d["majorant"], f"{field}.majorant", 0, lo_open=True)
    if "albedo" in d:
        for key in ("absorption", "color", "scattering"):
            if key in d:
                raise SceneError(f"{field}.{key}", "give either albedo and density or absorption and scattering")
        density = number(_require(d, "density", field), f"{field}.density", 0)
        albedo = np.array(_rgb_or_number(d["albedo"], f"{field}.albedo"))
        return _interior(field, list(density * (1.0 - albedo)), scattering=list(density * albedo), **medium)
    emits_only = ("emission" in d or "emission_grid" in d) and "density" not in d and "color" not in d
    if "absorption" in d or "scattering" in d or emits_only:
        if "color" in d or "density" in d:
            key = "absorption" if "absorption" in d else "scattering"
            raise SceneError(f"{field}.{key}", f"give either {key} or color and density, not both")
        absorption = parse_spectrum(d.get("absorption", 0.0), f"{field}.absorption", kind="unbounded")
        scattering = (parse_spectrum(d["scattering"], f"{field}.scattering", kind="unbounded")
                      if "scattering" in d else None)
        return _interior(field, absorption, scattering=scattering, **medium)
    density = number(_require(d, "density", field), f"{field}.density", 0)
    rgb = _rgb_or_number(d.get("color", _INTERIOR_DEFAULT_COLOR), f"{field}.color")
    interior = Interior.from_color_density(rgb, density)
    extra = any(medium.get(k) is not None for k in ("phase", "grid", "emission", "emission_grid", "colour_grid"))
    return _interior(field, interior.absorption, **medium) if extra else interior


def _interior(field: str, absorption, **medium) -> Interior:
    """An Interior whose validation errors name the scene file's field."""
    try:
        return Interior(absorption, **medium)
    except SceneError as e:
        raise SceneError(field + e.field[len("interior"):], e.reason) from None


def _rgb_or_number(value, field: str) -> list:
    """[r, g, b] in [0, 1] from a number or a list of three."""
    if isinstance(value, (list, tuple)) and len(value) == 3:
        return [number(c, f"{field}[{i}]", 0, 1) for i, c in enumerate(value)]
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [number(value, field, 0, 1)] * 3
    raise SceneError(field, f"must be a number or an [r, g, b] list in [0, 1], got {value!r}")


def _parse_phase(d, field: str):
    """A phase function {"type": NAME, parameter: value, …} of engine.media.catalogue."""
    from ..media.catalogue import PHASE_MODELS, make_phase
    if not isinstance(d, dict) or "type" not in d:
        raise SceneError(field, f"must be an object like {{\"type\": \"rayleigh\"}} (types: {', '.join(PHASE_MODELS)})")
    name = choice(d["type"], f"{field}.type", tuple(PHASE_MODELS))
    return make_phase(name, {k: v for k, v in d.items() if k not in ("type", "note")}, field, text=False)


def _parse_grid(d, field: str, colour: bool = False):
    """A dense density grid (engine.media.grid.DensityGrid), or with ``colour`` an RGB one
    (engine.media.colour_grid.ColourGrid: values [r, g, b][x][y][z])."""
    from ..media.colour_grid import ColourGrid
    from ..media.grid import DensityGrid
    if not isinstance(d, dict):
        raise SceneError(field, f"must be an object {{\"values\": {'[r, g, b]' if colour else ''}[x][y][z] values, "
                                "\"bounds\": [[x0, y0, z0], [x1, y1, z1]]}")
    _check_keys(d, field, {"values", "bounds", "note"})
    bounds = _require(d, "bounds", field)
    if not isinstance(bounds, list) or len(bounds) != 2:
        raise SceneError(f"{field}.bounds", "must be [[x0, y0, z0], [x1, y1, z1]]")
    return (ColourGrid if colour else DensityGrid)(_require(d, "values", field), bounds[0], bounds[1], field)


def _shading_normal(bsdf, d: dict, field: str, base_dir):
    """The material with a normal map and/or bump map (engine.materials.normal_map)."""
    kw = {}
    for key, extra in (("normal_map", {"strength": 1.0}), ("bump_map", {"strength": 1.0, "distance": 1.0})):
        raw = d.get(key)
        if raw is None:
            continue
        where = f"{field}.{key}"
        if not isinstance(raw, dict) or "texture" not in raw:
            raise SceneError(where, "must be an image texture object like {\"texture\": \"normal.png\"}")
        raw = dict(raw)
        values = {name: number(raw.pop(name, default), f"{where}.{name}", 0.0) for name, default in extra.items()}
        convention = raw.pop("convention", "opengl") if key == "normal_map" else "opengl"
        if convention not in ShadingNormal.CONVENTIONS:
            raise SceneError(f"{where}.convention", f"must be one of {', '.join(map(repr, ShadingNormal.CONVENTIONS))} "
                             f"(the green channel's direction), got {convention!r}")
        raw.setdefault("color_space", "Non-Color")        # normal and height maps are data
        source = parse_texture_input(raw, where, base_dir)
        if key == "normal_map":
            kw.update(normal_map=source, normal_strength=values["strength"], normal_convention=convention)
        else:
            kw.update(bump_map=source, bump_distance=values["distance"], bump_strength=values["strength"])
    return map_normals(bsdf, **kw)


def _parse_part(value, field, lookup, depth, base_dir=None, mixed=False):
    """A nested material (the base under a coat; ``mixed``: one material of a mix): inline or a
    reference by name.  A mix's materials may have their own normal and bump maps, a base may not
    (nor may the materials of a mix under a coat)."""
    if depth > MAX_LAYER_NESTING:
        raise SceneError(field, f"{'mixes and ' if mixed else ''}layered materials nest more than "
                                f"{MAX_LAYER_NESTING} levels deep")
    if isinstance(value, str):
        if lookup is None:
            raise SceneError(field, "material references are not available here; give it inline")
        part = lookup(value, field)
    else:
        part = parse_material(value, field, lookup, depth + 1, base_dir)
    if not mixed and _own_maps(part):
        raise SceneError(field, "a material under a coat cannot have its own normal or bump map: give the map to "
                                "the layered material")
    return part


def _own_maps(bsdf) -> bool:
    """The material, or a material of it as a mix, has its own normal or bump map."""
    return isinstance(bsdf, ShadingNormal) or (isinstance(bsdf, Mix) and any(map(_own_maps, bsdf.components)))


def _parse_coat(c, field, coat, base_dir=None):
    if not isinstance(c, dict):
        raise SceneError(field, "must be an object like {\"n\": 1.5, \"distribution\": \"smooth\"}")
    _check_keys(c, field, {"note"} | set(coat.names()))
    return coat.build(coat.values(c, field, base_dir=base_dir))


def _parse_emission(d, field: str, base_dir: str = "."):
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object like {\"radiance\": 10, \"color\": [1, 1, 1]}")
    _check_keys(d, field, {"radiance", "color", "spectrum", "note"})
    if "spectrum" in d and not isinstance(d["spectrum"], str):
        # The peer format describes its emitters' spectra in words; an emitted spectrum itself is
        # always D65 × color here, so a table would be dropped silently: refuse it.
        raise SceneError(f"{field}.spectrum", "is a description only (text); the emitted spectrum is D65 × color "
                                              "× radiance — use 'color' and 'radiance'")
    if isinstance(d.get("color"), dict):
        # a texture object (or colour attribute): radiance × its RGB at each point, as a constant colour emits
        scale = number(d.get("radiance", 1.0), f"{field}.radiance", 0, MAX_LIGHT)
        emission = textured_emission(parse_texture_input(d["color"], f"{field}.color", base_dir), scale, field)
        if emission.hi > MAX_LIGHT:
            raise SceneError(f"{field}.color", f"times the radiance must be at most {MAX_LIGHT:g} (images are "
                                               f"float32), got {emission.hi:g}")
        return emission
    return _illuminant(d, field, "radiance")


def _illuminant(d: dict, field: str, key: str):
    """The spectrum of a light: ``d[key]`` (radiance, intensity or irradiance; default 1) × colour,
    each and their product at most MAX_LIGHT."""
    scale = number(d.get(key, 1.0), f"{field}.{key}", 0, MAX_LIGHT)
    color = d.get("color", [1.0, 1.0, 1.0])
    if not isinstance(color, (list, tuple)) or len(color) != 3:
        raise SceneError(f"{field}.color", "must be a list of 3 numbers ≥ 0")
    rgb = [number(c, f"{field}.color[{i}]", 0, MAX_LIGHT) for i, c in enumerate(color)]
    if scale * max(rgb) > MAX_LIGHT:
        raise SceneError(f"{field}.color", f"times the {key} must be at most {MAX_LIGHT:g} (images are float32), "
                                           f"got {scale * max(rgb):g}")
    return RGBIlluminantSpectrum(rgb, scale)


#: Keys every object may have, and the keys of each shape.
OBJECT_KEYS = {"name", "shape", "material", "materials", "emission", "transform", "note", "normal"}
OBJECT_SHAPE_KEYS = {"mesh": {"file", "smooth"}, "sphere": {"center", "radius", "subdivisions"},
                     "quad": {"vertices", "uv"},
                     "triangles": {"vertices", "faces", "normals", "material_ids", "uv", "colors", "tangents"}}


def _parse_object_base(d: dict, field: str, base_dir: str, material_names) -> Mesh:
    """An object's Mesh from its JSON object (without the emitter options of parse_object): shape,
    per-vertex attributes, transform, materials, emission and ray visibility, validated in that order."""
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object")
    shape = choice(_require(d, "shape", field), f"{field}.shape", ("mesh", "sphere", "quad", "triangles"))
    name = str(d.get("name", field))
    _check_keys(d, field, OBJECT_KEYS | OBJECT_RAY_KEYS | OBJECT_IDENTITY_KEYS | OBJECT_SHAPE_KEYS[shape])
    data, group_names, ungrouped_line = _object_geometry(d, field, shape, base_dir, material_names)
    uv, colors, tangents = _object_vertex_attributes(d, field, shape, data)
    if "transform" in d:
        matrix = parse_transform(d["transform"], f"{field}.transform")
        data = transform_mesh(data, matrix)
        if tangents is not None:
            tangents = _transform_tangents(tangents, matrix)
    faces = _object_faces(data, field, name)
    mat_list, ids = _object_materials(d, field, shape, data, len(faces), group_names, ungrouped_line)
    _check_material_names(d, field, mat_list, material_names)
    emission = _parse_emission(d["emission"], f"{field}.emission", base_dir) if d.get("emission") is not None \
        else None
    mesh = Mesh(name=name, vertices=np.asarray(data.vertices, dtype=np.float64), faces=faces,
                materials=list(mat_list), material_ids=ids.astype(np.int32), normals=data.vertex_normals,
                emission=emission, uv=uv, colors=colors or {}, tangents=tangents)
    _parse_ray_visibility(d, field, mesh, base_dir)
    _parse_identity(d, field, mesh)
    return mesh


#: An object's identity in the data passes and Cryptomatte (optional; engine.render.data_passes): its Object
#: Index ("pass_index", an integer ≥ 0) and asset name ("asset", default its own name).
OBJECT_IDENTITY_KEYS = {"pass_index", "asset"}


def _parse_identity(d: dict, field: str, mesh: Mesh) -> None:
    """Set the Mesh's identity attributes (engine.scene.description.Mesh.pass_index, asset_name) given in ``d``."""
    if "pass_index" in d:
        value = d["pass_index"]
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 2**31 - 1:
            raise SceneError(f"{field}.pass_index", f"must be an integer in [0, 2^31 − 1], got {value!r}")
        mesh.pass_index = value
    if "asset" in d:
        if not isinstance(d["asset"], str) or not d["asset"]:
            raise SceneError(f"{field}.asset", f"must be a non-empty string, got {d['asset']!r}")
        mesh.asset_name = d["asset"]


def _object_geometry(d: dict, field: str, shape: str, base_dir: str, material_names):
    """The untransformed mesh data of an object's ``shape``, with the mesh file's material group names
    and the line of its first face before any 'usemtl' (both None unless the shape is "mesh")."""
    if shape == "mesh":
        return _mesh_file_geometry(d, field, base_dir)
    if shape == "sphere":
        center = vec3(d.get("center", [0, 0, 0]), f"{field}.center")
        radius = number(d.get("radius", 1.0), f"{field}.radius", 0, math.inf, lo_open=True)
        # UVs (Blender's UV-sphere map, shapes.sphere_uv_map) need extra seam and pole vertices: only
        # for textured materials, so untextured spheres keep the peer meshes' exact vertex numbering
        data = icosphere(integer(d.get("subdivisions", 6), f"{field}.subdivisions", 0, 9),
                         uv=_any_textured(d, material_names))
        return transform_mesh(data, transform_matrix(translate=center, scale=radius)), None, None
    if shape == "quad":
        verts = _require(d, "vertices", field)
        if not isinstance(verts, list) or len(verts) != 4:
            raise SceneError(f"{field}.vertices", "must be a list of 4 points [x, y, z]")
        return quad(*[vec3(v, f"{field}.vertices[{i}]") for i, v in enumerate(verts)]), None, None
    return _parse_triangles(d, field), None, None


def _mesh_file_geometry(d: dict, field: str, base_dir: str):
    """A "mesh" object's data read from its ``file`` (relative to ``base_dir``; vertex normals dropped
    when ``smooth`` is false), with its material group names and first ungrouped face line."""
    path = _require(d, "file", field)
    if not isinstance(path, str):
        raise SceneError(f"{field}.file", "must be a file path (string)")
    data = read_mesh(os.path.join(base_dir, path), field=f"{field}.file")
    if d.get("smooth", True) is False:
        data.vertex_normals = None
    return data, data.group_names, getattr(data, "ungrouped_line", None)


def _object_vertex_attributes(d: dict, field: str, shape: str, data):
    """(uv, colors, tangents) per vertex, each None when absent: a quad's ``uv`` (default QUAD_UV), a
    mesh file's or sphere map's own, or a "triangles" object's ``uv``, ``colors`` and ``tangents``.
    Transforms keep the vertex order, so they stay valid."""
    if shape == "quad":
        return _vertex_uv(d.get("uv", QUAD_UV), f"{field}.uv", 4), None, None
    if shape in ("mesh", "sphere"):      # from the file (PLY u, v and colours; OBJ vt) or the sphere map
        return data.uv, dict(data.colors) or None, None
    n_vertices = len(data.vertices)
    uv = None if d.get("uv") is None else _vertex_uv(d["uv"], f"{field}.uv", n_vertices)
    colors = _vertex_colors(d.get("colors", {}), f"{field}.colors", n_vertices)
    tangents = None
    if d.get("tangents") is not None:
        tangents = _vertex_tangents(d["tangents"], f"{field}.tangents", n_vertices)
    return uv, colors, tangents


def _transform_tangents(tangents: np.ndarray, matrix) -> np.ndarray:
    """(V, 4) tangents under a 4×4 transform: directions by its linear part (renormalised); a mirror
    flips the handedness w."""
    a = np.asarray(matrix, np.float64)[:3, :3]
    xyz = tangents[:, :3] @ a.T
    w = tangents[:, 3] * (1.0 if np.linalg.det(a) > 0 else -1.0)
    return np.column_stack((xyz / np.linalg.norm(xyz, axis=1)[:, None], w))


def _object_faces(data, field: str, name: str) -> np.ndarray:
    """The (F, 3) int64 faces of object ``name``'s transformed data, refused when there are none or a
    vertex coordinate is non-finite or beyond ±MAX_COORDINATE."""
    faces = np.asarray(data.faces, dtype=np.int64)
    if len(faces) == 0:
        raise SceneError(field, f"object {name!r} has no triangles")
    if not np.all(np.isfinite(data.vertices)):
        raise SceneError(field, f"object {name!r} has non-finite vertex coordinates")
    if np.abs(data.vertices).max() > MAX_COORDINATE:
        raise SceneError(field, f"object {name!r} has coordinates beyond ±{MAX_COORDINATE:g} (ray casting is "
                                "single precision)")
    return faces


def _object_materials(d: dict, field: str, shape: str, data, n_faces: int, group_names, ungrouped_line):
    """(material names, int64 index per face): one ``material`` for the whole object, or a list of
    ``materials`` indexed per face (by ``material_ids`` or the mesh file's groups; default 0).
    The names are not checked here (_check_material_names)."""
    if "materials" not in d:
        return [_require(d, "material", field)], np.zeros(n_faces, dtype=np.int64)
    mat_list = _material_list(d["materials"], field, group_names, ungrouped_line)
    ids = d.get("material_ids") if shape == "triangles" else data.face_groups
    if ids is None:
        ids = np.zeros(n_faces, dtype=np.int64)
    ids = _index_array(ids, f"{field}.material_ids", "one material index per triangle")
    if ids.shape != (n_faces,) or (ids.size and (ids.min() < 0 or ids.max() >= len(mat_list))):
        raise SceneError(f"{field}.material_ids",
                         f"must hold one index in [0, {len(mat_list) - 1}] per triangle ({n_faces})")
    return mat_list, ids


def _material_list(mats, field: str, group_names, ungrouped_line) -> list:
    """An object's ``materials``: a non-empty list, or (mesh files with material groups) an object
    mapping each group name to a material, listed in group order."""
    if isinstance(mats, dict) and group_names is not None:
        if ungrouped_line is not None:   # OBJ faces before the first usemtl: no name to map them by
            raise SceneError(f"{field}.file", f"line {ungrouped_line}: this face comes before the first "
                                              "'usemtl', so no material name applies to it; add a 'usemtl' "
                                              "line before it, or give the object one 'material'")
        mat_list = []
        for g in group_names:
            if g not in mats:
                raise SceneError(f"{field}.materials", f"has no entry for the mesh's material group {g!r}")
            mat_list.append(mats[g])
        return mat_list
    if isinstance(mats, list) and mats:
        return mats
    raise SceneError(f"{field}.materials", "must be a non-empty list of material names (or, for OBJ "
                                           "files, an object mapping usemtl names to materials)")


def _check_material_names(d: dict, field: str, mat_list: list, material_names) -> None:
    """Each material of the object must be the name of a defined material."""
    for i, m in enumerate(mat_list):
        if not isinstance(m, str) or m not in material_names:
            f = f"{field}.material" if "materials" not in d else f"{field}.materials[{i}]"
            raise SceneError(f, f"unknown material {m!r} (defined: {', '.join(sorted(material_names)) or 'none'})")


def _any_textured(d: dict, materials) -> bool:
    """Whether a material named by the object (``material`` or ``materials``), or its emission, varies over
    the surface."""
    emission = d.get("emission")
    if isinstance(emission, dict) and isinstance(emission.get("color"), dict):
        return True
    if isinstance(d.get("alpha"), dict):
        return True
    names = d.get("materials", [d.get("material")])
    names = list(names.values()) if isinstance(names, dict) else names
    if not isinstance(names, list) or not isinstance(materials, dict):
        return False
    return any(getattr(materials.get(n), "varies_over_surface", False) for n in names if isinstance(n, str))


#: Per-object ray visibility, holdout and alpha (optional; defaults: visible to every ray, opaque).
OBJECT_RAY_KEYS = {"visible_camera", "visible_shadow", "visible_indirect", "holdout", "alpha"}


def _parse_ray_visibility(d: dict, field: str, mesh: Mesh, base_dir: str = ".") -> None:
    for key in ("visible_camera", "visible_shadow", "visible_indirect", "holdout"):
        if key in d:
            if not isinstance(d[key], bool):
                raise SceneError(f"{field}.{key}", "must be true or false")
            setattr(mesh, key, d[key])
    raw = d.get("alpha", 1.0)
    if isinstance(raw, dict):       # a texture object: alpha per point (an image's alpha channel, a cut-out)
        source = parse_texture_input(raw, f"{field}.alpha", base_dir)
        value = TexturedNumber(source).clamped_to(0.0, 1.0)
        if not (0.0 <= value.lo and value.hi <= 1.0):
            raise SceneError(f"{field}.alpha", f"texture values span [{value.lo:g}, {value.hi:g}]: must be in [0, 1]")
        mesh.alpha = value
    else:
        mesh.alpha = number(raw, f"{field}.alpha", 0, 1)


#: Texture coordinates of a quad's corners p0..p3 (the unit square, as a Blender plane's UV map).
QUAD_UV = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]


def _float_array(value, field, what, widths=(2, 3, 4)):
    """A (rows, width) float64 array, numbers only (strings and booleans refused, ragged rows named);
    the width is the first row's when it is one of ``widths``."""
    first = value[0] if isinstance(value, (list, tuple)) and value else None
    if isinstance(value, np.ndarray):
        columns = value.shape[1] if value.ndim == 2 and value.shape[1] in widths else widths[0]
    else:
        columns = len(first) if isinstance(first, (list, tuple)) and len(first) in widths else widths[0]
    return _number_array(value, field, what, columns=columns)


def _vertex_uv(value, field, n_vertices):
    uv = _float_array(value, field, "one [u, v] per vertex", widths=(2,))
    if uv.shape != (n_vertices, 2) or not np.all(np.isfinite(uv)):
        raise SceneError(field, f"must hold one finite [u, v] per vertex ({n_vertices})")
    return uv


def _vertex_tangents(value, field, n_vertices):
    """(V, 4): [tx, ty, tz] (handedness +1) or [tx, ty, tz, ±1] per vertex, xyz normalised."""
    t = _float_array(value, field, "one [tx, ty, tz] or [tx, ty, tz, w] per vertex")
    if t.ndim != 2 or t.shape[0] != n_vertices or t.shape[1] not in (3, 4) or not np.all(np.isfinite(t)):
        raise SceneError(field, f"must hold one finite [tx, ty, tz] or [tx, ty, tz, w] per vertex ({n_vertices})")
    if t.shape[1] == 3:
        t = np.column_stack((t, np.ones(n_vertices)))
    length = np.linalg.norm(t[:, :3], axis=1)
    if not np.all(length > 0):
        raise SceneError(field, "tangents must be non-zero vectors")
    if not np.all(np.abs(t[:, 3]) == 1):
        raise SceneError(field, "the handedness w must be +1 or -1")
    t[:, :3] /= length[:, None]
    return t


def _vertex_colors(value, field, n_vertices):
    if not isinstance(value, dict):
        raise SceneError(field, "must be an object mapping attribute names to one [r, g, b] (or [r, g, b, a]) "
                                "per vertex")
    out = {}
    for name, col in value.items():
        c = _float_array(col, f"{field}.{name}", "one [r, g, b] or [r, g, b, a] per vertex")
        if c.ndim != 2 or c.shape[0] != n_vertices or c.shape[1] not in (3, 4):
            raise SceneError(f"{field}.{name}", f"must hold one [r, g, b] or [r, g, b, a] per vertex ({n_vertices})")
        if not np.all(np.isfinite(c)) or c.min() < 0 or c.max() > 1:
            raise SceneError(f"{field}.{name}", "values must be linear colours in [0, 1]")
        out[name] = c
    return out


def _is_json_number(x) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def _number_array(value, field: str, what: str, columns: int | None = None) -> np.ndarray:
    """float64 array from a list of numbers, or (``columns``) from a list of rows of that many.

    Strict where numpy is lenient: strings ("1") and booleans are rejected, not converted, and a
    ragged row is named (``objects[3].vertices[1]``)."""
    if isinstance(value, np.ndarray) and value.dtype.kind in "fiu":      # Python callers
        a = value.astype(np.float64)
        if (a.ndim != 2 or a.shape[1] != columns) if columns else a.ndim != 1:
            raise SceneError(field, f"must be {what}")
        return a
    if not isinstance(value, (list, tuple)):
        raise SceneError(field, f"must be {what}, got {_type_name(value)}")
    if columns:
        for i, row in enumerate(value):
            if not isinstance(row, (list, tuple)) or len(row) != columns:
                raise SceneError(f"{field}[{i}]", f"must be a list of {columns} numbers, got {_show(row)}")
        flat = [x for row in value for x in row]
    else:
        flat = value
    if not all(t in (int, float) for t in set(map(type, flat))):
        k = next((k for k, x in enumerate(flat) if not _is_json_number(x)), None)
        if k is not None:
            where = f"{field}[{k // columns}][{k % columns}]" if columns else f"{field}[{k}]"
            raise SceneError(where, f"must be a number, got {_show(flat[k])}")
    try:
        a = np.array(flat, dtype=np.float64)
    except OverflowError:
        raise SceneError(field, f"must be {what} (numbers within ±1.8e308)") from None
    return a.reshape(-1, columns) if columns else a


def _index_array(value, field, what, columns: int | None = None):
    """Whole numbers only (no silent truncation of 2.5 to 2)."""
    a = _number_array(value, field, what, columns)
    if a.size and (not np.all(np.isfinite(a)) or np.any(a != np.round(a)) or np.abs(a).max() > 2 ** 31):
        raise SceneError(field, f"must be {what} (whole numbers)")
    return a.astype(np.int64)


def _show(value, limit: int = 40) -> str:
    """repr of a value for a message, shortened (a bad row may be a huge list)."""
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 1] + "…"


def _parse_triangles(d, field):
    from .meshio import MeshData
    v = _number_array(_require(d, "vertices", field), f"{field}.vertices", "a list of [x, y, z] points", 3)
    f = _index_array(_require(d, "faces", field), f"{field}.faces", "a list of [i, j, k] vertex index triples", 3)
    if not np.all(np.isfinite(v)):
        raise SceneError(f"{field}.vertices", "must be finite numbers")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise SceneError(f"{field}.faces", f"vertex indices must be in [0, {len(v) - 1}]")
    normals = None
    if d.get("normals") is not None:
        normals = _number_array(d["normals"], f"{field}.normals", "one [nx, ny, nz] per vertex", 3)
        if normals.shape != v.shape:
            raise SceneError(f"{field}.normals", "must hold one [nx, ny, nz] per vertex")
        lengths = np.linalg.norm(normals, axis=1)
        if not np.all(lengths > 0) or not np.all(np.isfinite(lengths)):
            raise SceneError(f"{field}.normals", "must be finite, non-zero vectors")
        normals = normals / lengths[:, None]
    return MeshData(vertices=v, faces=f.astype(np.int32), vertex_normals=normals)


def parse_transform(d, field: str) -> np.ndarray:
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object with translate/scale/rotate_deg or matrix")
    _check_keys(d, field, {"translate", "scale", "rotate_deg", "matrix"})
    if "matrix" in d:
        if len(d) > 1:
            raise SceneError(f"{field}.matrix", "cannot be combined with translate/scale/rotate_deg")
        what = "a 4×4 list of finite numbers (row-major)"
        m = _number_array(d["matrix"], f"{field}.matrix", what, 4) if isinstance(d["matrix"], list) else None
        if m is None or m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise SceneError(f"{field}.matrix", "must be a 4×4 list of finite numbers (row-major)")
        if abs(np.linalg.det(m[:3, :3])) < 1e-300:
            raise SceneError(f"{field}.matrix", "is singular (its 3×3 part has determinant 0)")
        return m
    scale = d.get("scale", 1.0)
    if isinstance(scale, list):
        scale = vec3(scale, f"{field}.scale")
        if np.any(scale == 0):
            raise SceneError(f"{field}.scale", "components must be non-zero")
    else:
        scale = number(scale, f"{field}.scale", 0, math.inf, lo_open=True)
    return transform_matrix(translate=vec3(d.get("translate", [0, 0, 0]), f"{field}.translate"),
                            scale=scale, rotate_deg=vec3(d.get("rotate_deg", [0, 0, 0]), f"{field}.rotate_deg"))


def _parse_light_base(d: dict, field: str, base_dir: str = "."):
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object with a 'type'")
    kind = choice(_require(d, "type", field), f"{field}.type", ("environment", "sky", "point", "spot", "directional"))
    if kind == "sky":
        return _sky(d, field)
    if kind == "environment":
        if "image" in d:
            return _environment_map(d, field, base_dir)
        _check_keys(d, field, {"type", "radiance", "color", "note"})
        return EnvironmentLight(_illuminant(d, field, "radiance"))
    if kind == "point":
        _check_keys(d, field, {"type", "position", "intensity", "color", "note", *LIGHT_OPTIONS["point"]})
        return PointLight(vec3(_require(d, "position", field), f"{field}.position"),
                          _illuminant(d, field, "intensity"))
    if kind == "spot":
        _check_keys(d, field, {"type", "position", "direction", "target", "intensity", "color",
                               "cone_angle_deg", "blend", "note", *LIGHT_OPTIONS["spot"]})
        pos = vec3(_require(d, "position", field), f"{field}.position")
        if "target" in d:
            direction = vec3(d["target"], f"{field}.target") - pos
            if not np.linalg.norm(direction) > 0:
                raise SceneError(f"{field}.target", "must differ from the position")
            direction /= np.linalg.norm(direction)
        else:
            direction = vec3(_require(d, "direction", field), f"{field}.direction", unit=True)
        return SpotLight(pos, direction,
                         _illuminant(d, field, "intensity"),
                         number(d.get("cone_angle_deg", 45.0), f"{field}.cone_angle_deg", 0, 180, lo_open=True),
                         number(d.get("blend", 0.0), f"{field}.blend", 0, 1))
    _check_keys(d, field, {"type", "direction", "irradiance", "color", "note", *LIGHT_OPTIONS["directional"]})
    return DirectionalLight(vec3(_require(d, "direction", field), f"{field}.direction", unit=True),
                            _illuminant(d, field, "irradiance"))


# ----------------------------------------------------------------------------- Cycles' light options
# Optional, with Cycles' meaning (docs/guide/blender.md: the light table); the defaults are the format's
# original meaning, so existing and peer scenes render exactly as before.

#: optional keys of each light type
LIGHT_OPTIONS = {"point": ("radius", "soft_falloff", "visible_camera", "polarisation"),
                 "spot": ("radius", "soft_falloff", "visible_camera", "blend_profile", "polarisation"),
                 "directional": ("angle_deg", "visible_camera", "polarisation")}
#: optional emitter options inside "emission" (Mesh fields; defaults: one-sided, opaque, Lambertian, unpolarised)
EMITTER_OPTIONS = ("two_sided", "occluder", "spread_deg", "sampling", "under_layers", "polarisation")


def _flag(d, key: str, field: str, default: bool) -> bool:
    value = d.get(key, default)
    if not isinstance(value, bool):
        raise SceneError(f"{field}.{key}", "must be true or false")
    return value


def _environment_map(d: dict, field: str, base_dir: str) -> EnvironmentLight:
    """An equirectangular environment map: ``image`` (path relative to the scene file; EXR read
    with OpenEXR, PNG/JPEG/TIFF through engine.textures.image), ``strength``, ``rotation_deg``
    (about +Z, counter-clockwise seen from above; or Euler angles [x, y, z], order XYZ as Blender's)
    and the texel ``grid`` (default "cycles")."""
    _check_keys(d, field, {"type", "image", "strength", "rotation_deg", "grid", "note", "polarisation"})
    path = d["image"]
    if not isinstance(path, str) or not path:
        raise SceneError(f"{field}.image", "must be the path of an image file")
    img = read_image(os.path.join(base_dir, path), field=f"{field}.image")[::-1]     # row 0 = zenith
    channels = img.shape[2]
    rgb = np.repeat(img[:, :, :1], 3, axis=2) if channels < 3 else img[:, :, :3]
    if img.shape[0] < 2:
        raise SceneError(f"{field}.image", f"needs at least 2 rows, got {img.shape[0]}")
    if not np.isfinite(rgb).all():
        raise SceneError(f"{field}.image", "texels must be finite")
    # some HDR tools write tiny negative texels; radiance cannot be negative
    rgb = np.maximum(rgb, np.float32(0.0))
    strength = number(d.get("strength", 1.0), f"{field}.strength", 0, MAX_LIGHT)
    if strength * float(rgb.max(initial=0.0)) > MAX_LIGHT:
        raise SceneError(f"{field}.strength", f"times the brightest texel must be at most {MAX_LIGHT:g}, "
                                              f"got {strength * float(rgb.max()):g}")
    rotation = d.get("rotation_deg", 0.0)
    if isinstance(rotation, list):
        if len(rotation) != 3:
            raise SceneError(f"{field}.rotation_deg", f"must be a number or Euler angles [x, y, z] in degrees, "
                                                      f"got {len(rotation)} values")
        rotation = [number(a, f"{field}.rotation_deg[{i}]", -360.0, 360.0) for i, a in enumerate(rotation)]
    else:
        rotation = number(rotation, f"{field}.rotation_deg", -360.0, 360.0)
    grid = choice(d.get("grid", "cycles"), f"{field}.grid", ENVMAP_GRIDS)
    light = EnvironmentLight(RGBIlluminantSpectrum([1.0, 1.0, 1.0], strength), image=rgb, strength=strength,
                             rotation_deg=rotation, grid=grid)
    if _flag(d, "polarisation", field, True):
        stokes = stokes_channels(os.path.join(base_dir, path), rgb.shape[:2], f"{field}.image")
        if stokes is not None:         # set only then: unpolarised maps keep their fingerprints
            light.stokes = stokes
            light.polarisation = DirectionalPolarisation(
                "full" if np.abs(stokes[..., 2]).max(initial=0.0) > 0 else "linear", f"{field}.image")
    return light


#: texels (width, height) of the equirectangular map a ``sky`` environment's radiance is tabulated in
SKY_MAP_SIZE = (512, 256)
SKY_POLARISATION_KEYS = {"model", "delta", "max_degree", "neutral_separation_deg", "berry_degree"}


def _sky(d: dict, field: str) -> EnvironmentLight:
    """A clear sky (engine.spectral.daylight.ClearSky): Preetham's radiance × ``strength`` tabulated in an
    equirectangular map (SKY_MAP_SIZE, importance-sampled), polarised by the model named in "polarisation"
    ({"model": "berry" | "rayleigh", …}; "none": unpolarised)."""
    from ..spectral.daylight import ClearSky, max_degree_for_turbidity
    _check_keys(d, field, {"type", "sun_direction", "turbidity", "strength", "polarisation", "ground", "note"})
    sun = vec3(_require(d, "sun_direction", field), f"{field}.sun_direction", unit=True)
    strength = number(d.get("strength", 1.0), f"{field}.strength", 0, MAX_LIGHT)
    pol = d.get("polarisation", {"model": "berry"})
    if pol == "none":
        pol = None
    elif not isinstance(pol, dict):
        raise SceneError(f"{field}.polarisation", 'must be an object such as {"model": "berry"} or "none"')
    else:
        _check_keys(pol, f"{field}.polarisation", SKY_POLARISATION_KEYS)
    kwargs = {k: v for k, v in (pol or {}).items()}
    kwargs.setdefault("model", "berry")
    turbidity = d.get("turbidity", 2.2)
    if "max_degree" not in kwargs and isinstance(turbidity, (int, float)) and not isinstance(turbidity, bool):
        kwargs["max_degree"] = max_degree_for_turbidity(turbidity)      # hazier skies polarise less
    try:
        sky = ClearSky(sun_direction=tuple(sun), turbidity=turbidity, ground=d.get("ground", "horizon"), **kwargs)
    except SceneError as e:
        where = f"{field}.polarisation.{e.field}" if e.field in SKY_POLARISATION_KEYS else f"{field}.{e.field}"
        raise SceneError(where, e.reason) from None
    W, H = SKY_MAP_SIZE
    v = (np.arange(H) + 0.5) / H                         # the "cycles" grid: row j at v = (j + ½)/H
    u = (np.arange(W) + 0.5) / W
    theta, phi = np.pi * v[:, None], np.pi * (1.0 - 2.0 * u[None, :])    # u = ½ − φ/2π (EnvironmentMapEmitter)
    dirs = np.stack(np.broadcast_arrays(np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)),
                    axis=-1).reshape(-1, 3)
    image = (sky.rgb(dirs) * strength).reshape(H, W, 3)
    light = EnvironmentLight(RGBIlluminantSpectrum([1.0, 1.0, 1.0], 1.0), image=image, strength=1.0,
                             grid="cycles")
    light.sky = sky
    if pol is not None:
        light.polarisation = DirectionalPolarisation("linear", f"{field} ({sky.model} clear sky)")
    return light


def stokes_channels(path: str, shape, field: str):
    """The normalised linear and circular Stokes components (H, W, 3) of an EXR with Polar's channel names
    (S0.R … S3.B: engine.output.exr), s_k = Y(S_k)/Y(S0) per texel (Y: Rec.709 luminance; 0 where Y(S0) ≤ 0),
    scaled down where the degree would exceed 1; None for any other file.  Row 0 = the top of the image."""
    if not path.lower().endswith(".exr"):
        return None
    import OpenEXR
    try:
        with OpenEXR.File(path, separate_channels=True) as f:
            chans = {n: np.asarray(c.pixels, np.float64) for part in f.parts for n, c in part.channels.items()}
    except Exception as e:          # the image itself was read; an unreadable header here is the same file
        raise SceneError(field, f"cannot read its channels: {e}") from None
    names = [f"S{k}.{c}" for k in range(4) for c in "RGB"]
    if not all(n in chans for n in names[3:9]):         # S1 and S2 at least
        return None
    weights = (0.2126, 0.7152, 0.0722)
    Y = [sum(w * chans.get(f"S{k}.{c}", 0.0) for w, c in zip(weights, "RGB")) for k in range(4)]
    if any(np.shape(y) != tuple(shape) for y in Y[:3]):
        raise SceneError(field, f"its Stokes channels are {np.shape(Y[1])}, its image {tuple(shape)}")
    y0 = np.where(Y[0] > 0, Y[0], 1.0)
    st = np.stack([np.where(Y[0] > 0, np.broadcast_to(Y[k], Y[0].shape) / y0, 0.0) for k in (1, 2, 3)], axis=-1)
    if not np.isfinite(st).all():
        raise SceneError(field, "its Stokes channels must be finite")
    dop = np.sqrt((st ** 2).sum(axis=-1))
    return st / np.maximum(dop, 1.0)[..., None]


def parse_light(d: dict, field: str, base_dir: str = "."):
    """A light from its JSON object, with the optional Cycles options of LIGHT_OPTIONS; image paths
    are relative to ``base_dir`` (the scene file's folder)."""
    light = _parse_light_base(d, field, base_dir)
    if isinstance(light, (PointLight, SpotLight)):
        light.radius = number(d.get("radius", 0.0), f"{field}.radius", 0)
        light.soft_falloff = _flag(d, "soft_falloff", field, True)
    if isinstance(light, SpotLight):
        light.blend_profile = choice(d.get("blend_profile", "angle"), f"{field}.blend_profile", ("angle", "cycles"))
    if isinstance(light, DirectionalLight):
        light.angle_deg = number(d.get("angle_deg", 0.0), f"{field}.angle_deg", 0, 180, hi_open=True)
    if not isinstance(light, EnvironmentLight):
        light.visible_camera = _flag(d, "visible_camera", field, True)
        pol, axis = parse_polarisation(d.get("polarisation"), f"{field}.polarisation")
        if pol.polarised:          # (set only then: unpolarised lights keep their fingerprints)
            light.polarisation, light.polarisation_axis = pol, axis
    return light


def parse_object(d: dict, field: str, base_dir: str, material_names) -> Mesh:
    """An object from its JSON object, with the optional emitter options (EMITTER_OPTIONS) in its
    "emission"."""
    emission = d.get("emission") if isinstance(d, dict) else None
    if not isinstance(emission, dict) or not any(key in emission for key in EMITTER_OPTIONS):
        return _parse_object_base(d, field, base_dir, material_names)
    plain = {key: value for key, value in emission.items() if key not in EMITTER_OPTIONS}
    mesh = _parse_object_base({**d, "emission": plain}, field, base_dir, material_names)
    for key, value in _emitter_options(emission, f"{field}.emission").items():
        setattr(mesh, key, value)
    return mesh


def _emitter_options(d, field: str) -> dict:
    """The Mesh emitter fields given in an "emission" object (validated)."""
    out = {key: _flag(d, key, field, True) for key in ("two_sided", "occluder") if key in d}
    if "spread_deg" in d:
        out["spread_deg"] = number(d["spread_deg"], f"{field}.spread_deg", 0, 180, lo_open=True)
    if "sampling" in d:
        out["emission_sampling"] = choice(d["sampling"], f"{field}.sampling", EMISSION_SAMPLING)
    if _flag(d, "under_layers", field, False):
        out["emission_under_layers"] = True
    pol, axis = parse_polarisation(d.get("polarisation"), f"{field}.polarisation")
    if pol.polarised:
        out["emission_polarisation"], out["emission_axis"] = pol, axis
    return out


def parse_scene(data: dict, base_dir: str = ".", source: str = "") -> Scene:
    """A validated Scene from a parsed engine-format (or peer-format) JSON object."""
    if not isinstance(data, dict):
        raise SceneError("", "a scene file must hold a JSON object")
    check_json_values(data)
    from .peer_format import is_peer_scene, peer_to_engine
    if is_peer_scene(data):
        data = peer_to_engine(data)
    fmt = data.get("format")
    if fmt != FORMAT:
        raise SceneError("format", f"must be {FORMAT!r} (or a peer scene with 'light' and 'integrator'), "
                                   f"got {fmt!r}")
    _check_keys(data, "", {"format", "camera", "render", "materials", "objects", "lights", "description",
                           "note", "name", "medium"})
    camera = parse_camera(_require(data, "camera", ""), "camera")
    settings = parse_settings(data.get("render", {}), "render")
    mats_in = data.get("materials", {})
    if not isinstance(mats_in, dict):
        raise SceneError("materials", "must be an object mapping names to materials")
    materials = {}
    resolving = []

    def lookup(name, field):
        if name not in mats_in:
            raise SceneError(field, f"unknown material {name!r} (defined: {', '.join(sorted(mats_in))})")
        if name in resolving:
            raise SceneError(field, f"material {name!r} refers to itself through its bases")
        if name not in materials:
            resolving.append(name)
            materials[name] = parse_material(mats_in[name], f"materials.{name}", lookup, base_dir=base_dir)
            resolving.pop()
        return materials[name]

    for name, m in mats_in.items():    # bases by name: bound the whole chain before lookup recurses along it
        _check_layer_stack(m, f"materials.{name}", mats_in)
    for name in mats_in:
        lookup(name, f"materials.{name}")
    materials = {name: materials[name] for name in mats_in}
    objects = data.get("objects", [])
    if not isinstance(objects, list):
        raise SceneError("objects", "must be a list")
    meshes = [parse_object(o, f"objects[{i}]", base_dir, materials) for i, o in enumerate(objects)]
    lights_in = data.get("lights", [])
    if not isinstance(lights_in, list):
        raise SceneError("lights", "must be a list")
    lights = [parse_light(light, f"lights[{i}]", base_dir) for i, light in enumerate(lights_in)]
    if sum(isinstance(light, EnvironmentLight) for light in lights) > 1:
        raise SceneError("lights", "at most one environment light is allowed")
    scene = Scene(camera=camera, meshes=meshes, materials=materials, lights=lights, settings=settings,
                  source=source)
    if data.get("medium") is not None:
        medium = _parse_interior(data["medium"], "medium")
        scene.medium = medium if medium.renders else None
    return scene


def load_scene(path: str) -> Scene:
    """Read and validate a scene file (engine or peer format; UTF-8 JSON)."""
    refuse_special_file(path, "", "scene file ")
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except FileNotFoundError:
        raise SceneError("", f"scene file {path!r} does not exist") from None
    except OSError as e:
        raise SceneError("", f"cannot read scene file {path!r}: {e.strerror}") from None
    text = _decode_scene_text(raw, path)
    try:
        data = json.loads(text, parse_int=_json_int)
    except json.JSONDecodeError as e:
        raise SceneError("", f"{path}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    except RecursionError:
        # json recurses once per level: text nested ~1000 deep stops here, shallower excess
        # nesting is reported with its field by check_json_values.
        _check_text_nesting(raw, path)
        raise SceneError("", f"{path}: objects and lists nest more than {MAX_NESTING} levels deep") from None
    return parse_scene(data, os.path.dirname(os.path.abspath(path)), source=path)


__all__ = ["FORMAT", "load_scene", "parse_scene", "parse_camera", "parse_material", "parse_light",
           "parse_settings", "parse_object", "ConstantSpectrum"]
