"""Scene files (JSON) → engine.scene.description.Scene, validated on load.

Two formats are read:

- the engine's own format (``"format": "polar-scene/1"``, documented in the
  README, section "Scene files"), and
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

import numpy as np

from ..materials.catalogue import MODELS
from .description import (Camera, DirectionalLight, EnvironmentLight, Mesh, PointLight,
                                      RenderSettings, Scene, SpotLight)
from ..errors import SceneError
from .meshio import read_mesh
from .shapes import icosphere, quad, transform_matrix, transform_mesh
from ..spectral import ConstantSpectrum, RGBIlluminantSpectrum

FORMAT = "polar-scene/1"
#: Largest coordinate accepted: Embree works in float32 (max ~3.4e38) and rays need headroom.
MAX_COORDINATE = 1e30


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
    v = float(value)
    rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if not math.isfinite(v):
        raise SceneError(field, f"must be a finite number in {rng}, got {value!r}")
    if v < lo or v > hi or (lo_open and v == lo) or (hi_open and v == hi):
        raise SceneError(field, f"must be in {rng}, got {v:g}")
    return v


def integer(value, field: str, lo: int, hi: int) -> int:
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
                           "polarisation", "batch_rays", "threads", "reduce_spectral", "simplify"})
    s = RenderSettings()
    s.spp = integer(d.get("spp", s.spp), f"{field}.spp", 1, 1 << 24)
    s.max_depth = integer(d.get("max_depth", s.max_depth), f"{field}.max_depth", 1, 1024)
    s.rr_depth = integer(d.get("rr_depth", s.rr_depth), f"{field}.rr_depth", 1, 1024)
    s.seed = integer(d.get("seed", s.seed), f"{field}.seed", 0, 2 ** 63 - 1)
    s.spectral = choice(d.get("spectral", s.spectral), f"{field}.spectral", ("spectral", "mono"))
    s.wavelength_nm = number(d.get("wavelength_nm", s.wavelength_nm), f"{field}.wavelength_nm", 360, 830)
    s.polarisation = choice(d.get("polarisation", s.polarisation), f"{field}.polarisation",
                            ("auto", "full", "linear", "off"))
    s.batch_rays = integer(d.get("batch_rays", s.batch_rays), f"{field}.batch_rays", 1024, 1 << 24)
    s.threads = integer(d.get("threads", s.threads), f"{field}.threads", 0, 256)
    s.reduce_spectral = choice(d.get("reduce_spectral", s.reduce_spectral), f"{field}.reduce_spectral",
                               ("auto", "exact", "off"))
    s.simplify = choice(d.get("simplify", s.simplify), f"{field}.simplify", ("auto", "off"))
    return s


def parse_material(d: dict, field: str, lookup=None, depth: int = 0):
    """A BSDF from a material object, read through the model's declaration (engine.materials.parameters).
    ``lookup(name)`` resolves references to other materials (the base of a layered material may be
    given inline or by name)."""
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object with a 'type'")
    decl = MODELS[choice(_require(d, "type", field), f"{field}.type", tuple(MODELS))]
    _check_keys(d, field, {"type", "note", "name"} | set(decl.names()))
    parts = {}
    for p in decl.parameters:
        if p.kind == "coats":
            coats_in = _require(d, p.name, field)
            if not isinstance(coats_in, list) or not coats_in:
                raise SceneError(f"{field}.{p.name}", "must be a non-empty list of coats (top coat first)")
            parts[p.name] = [_parse_coat(c, f"{field}.{p.name}[{i}]", p.members) for i, c in enumerate(coats_in)]
        elif p.kind == "material":
            parts[p.name] = _parse_part(d.get(p.name, p.default), f"{field}.{p.name}", lookup, depth)
    return decl.build(decl.values(d, field), **parts)


def _parse_part(value, field, lookup, depth):
    """A nested material (e.g. the base under a coat): inline or a reference by name."""
    if depth > 16:
        raise SceneError(field, "layered materials nest more than 16 levels deep")
    if isinstance(value, str):
        if lookup is None:
            raise SceneError(field, "material references are not available here; give it inline")
        return lookup(value, field)
    return parse_material(value, field, lookup, depth + 1)


def _parse_coat(c, field, coat):
    if not isinstance(c, dict):
        raise SceneError(field, "must be an object like {\"n\": 1.5, \"distribution\": \"smooth\"}")
    _check_keys(c, field, {"note"} | set(coat.names()))
    return coat.build(coat.values(c, field))


def _parse_emission(d, field: str):
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object like {\"radiance\": 10, \"color\": [1, 1, 1]}")
    _check_keys(d, field, {"radiance", "color", "spectrum", "note"})
    scale = number(d.get("radiance", 1.0), f"{field}.radiance", 0)
    return _illuminant(d, field, scale)


def _illuminant(d: dict, field: str, scale: float):
    color = d.get("color", [1.0, 1.0, 1.0])
    if not isinstance(color, (list, tuple)) or len(color) != 3:
        raise SceneError(f"{field}.color", "must be a list of 3 numbers ≥ 0")
    rgb = [number(c, f"{field}.color[{i}]", 0) for i, c in enumerate(color)]
    return RGBIlluminantSpectrum(rgb, scale)


def parse_object(d: dict, field: str, base_dir: str, material_names) -> Mesh:
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object")
    shape = choice(_require(d, "shape", field), f"{field}.shape", ("mesh", "sphere", "quad", "triangles"))
    name = str(d.get("name", field))
    allowed = {"name", "shape", "material", "materials", "emission", "transform", "note", "normal"} | OBJECT_RAY_KEYS
    per_shape = {"mesh": {"file", "smooth"}, "sphere": {"center", "radius", "subdivisions"},
                 "quad": {"vertices"}, "triangles": {"vertices", "faces", "normals", "material_ids"}}
    _check_keys(d, field, allowed | per_shape[shape])

    group_names = None
    if shape == "mesh":
        path = _require(d, "file", field)
        if not isinstance(path, str):
            raise SceneError(f"{field}.file", "must be a file path (string)")
        data = read_mesh(os.path.join(base_dir, path), field=f"{field}.file")
        group_names = data.group_names
        if d.get("smooth", True) is False:
            data.vertex_normals = None
    elif shape == "sphere":
        center = vec3(d.get("center", [0, 0, 0]), f"{field}.center")
        radius = number(d.get("radius", 1.0), f"{field}.radius", 0, math.inf, lo_open=True)
        data = icosphere(integer(d.get("subdivisions", 6), f"{field}.subdivisions", 0, 9))
        data = transform_mesh(data, transform_matrix(translate=center, scale=radius))
    elif shape == "quad":
        verts = _require(d, "vertices", field)
        if not isinstance(verts, list) or len(verts) != 4:
            raise SceneError(f"{field}.vertices", "must be a list of 4 points [x, y, z]")
        data = quad(*[vec3(v, f"{field}.vertices[{i}]") for i, v in enumerate(verts)])
    else:
        data = _parse_triangles(d, field)

    if "transform" in d:
        data = transform_mesh(data, parse_transform(d["transform"], f"{field}.transform"))

    faces = np.asarray(data.faces, dtype=np.int64)
    n_faces = len(faces)
    if n_faces == 0:
        raise SceneError(field, f"object {name!r} has no triangles")
    if not np.all(np.isfinite(data.vertices)):
        raise SceneError(field, f"object {name!r} has non-finite vertex coordinates")
    if np.abs(data.vertices).max() > MAX_COORDINATE:
        raise SceneError(field, f"object {name!r} has coordinates beyond ±{MAX_COORDINATE:g} (ray casting is "
                                "single precision)")

    # Materials: one for the whole object, or a list indexed per face.
    if "materials" in d:
        mats = d["materials"]
        if isinstance(mats, dict) and group_names is not None:
            mat_list = []
            for g in group_names:
                if g not in mats:
                    raise SceneError(f"{field}.materials", f"has no entry for the mesh's material group {g!r}")
                mat_list.append(mats[g])
        elif isinstance(mats, list) and mats:
            mat_list = mats
        else:
            raise SceneError(f"{field}.materials", "must be a non-empty list of material names (or, for OBJ "
                                                   "files, an object mapping usemtl names to materials)")
        ids = d.get("material_ids") if shape == "triangles" else data.face_groups
        if ids is None:
            ids = np.zeros(n_faces, dtype=np.int64)
        ids = _index_array(ids, f"{field}.material_ids", "one material index per triangle")
        if ids.shape != (n_faces,) or (ids.size and (ids.min() < 0 or ids.max() >= len(mat_list))):
            raise SceneError(f"{field}.material_ids",
                             f"must hold one index in [0, {len(mat_list) - 1}] per triangle ({n_faces})")
    else:
        mat_list = [_require(d, "material", field)]
        ids = np.zeros(n_faces, dtype=np.int64)
    for i, m in enumerate(mat_list):
        if not isinstance(m, str) or m not in material_names:
            f = f"{field}.material" if "materials" not in d else f"{field}.materials[{i}]"
            raise SceneError(f, f"unknown material {m!r} (defined: {', '.join(sorted(material_names)) or 'none'})")

    emission = _parse_emission(d["emission"], f"{field}.emission") if d.get("emission") is not None else None
    mesh = Mesh(name=name, vertices=np.asarray(data.vertices, dtype=np.float64), faces=faces,
                materials=list(mat_list), material_ids=ids.astype(np.int32), normals=data.vertex_normals,
                emission=emission)
    _parse_ray_visibility(d, field, mesh)
    return mesh


#: Per-object ray visibility, holdout and alpha (optional; defaults: visible to every ray, opaque).
OBJECT_RAY_KEYS = {"visible_camera", "visible_shadow", "visible_indirect", "holdout", "alpha"}


def _parse_ray_visibility(d: dict, field: str, mesh: Mesh) -> None:
    for key in ("visible_camera", "visible_shadow", "visible_indirect", "holdout"):
        if key in d:
            if not isinstance(d[key], bool):
                raise SceneError(f"{field}.{key}", "must be true or false")
            setattr(mesh, key, d[key])
    mesh.alpha = number(d.get("alpha", 1.0), f"{field}.alpha", 0, 1)


def _float_array(value, field, what):
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise SceneError(field, f"must be {what}") from None


def _index_array(value, field, what):
    """Whole numbers only (no silent truncation of 2.5 to 2)."""
    a = _float_array(value, field, what)
    if a.size and (not np.all(np.isfinite(a)) or np.any(a != np.round(a)) or np.abs(a).max() > 2 ** 31):
        raise SceneError(field, f"must be {what} (whole numbers)")
    return a.astype(np.int64)


def _parse_triangles(d, field):
    from .meshio import MeshData
    v = _float_array(_require(d, "vertices", field), f"{field}.vertices", "a list of [x, y, z] points")
    f = _index_array(_require(d, "faces", field), f"{field}.faces", "a list of [i, j, k] vertex index triples")
    if not np.all(np.isfinite(v)):
        raise SceneError(f"{field}.vertices", "must be finite numbers")
    if v.ndim != 2 or v.shape[1] != 3:
        raise SceneError(f"{field}.vertices", "must be a list of [x, y, z] points")
    if f.ndim != 2 or f.shape[1] != 3:
        raise SceneError(f"{field}.faces", "must be a list of [i, j, k] vertex index triples")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise SceneError(f"{field}.faces", f"vertex indices must be in [0, {len(v) - 1}]")
    normals = None
    if d.get("normals") is not None:
        normals = _float_array(d["normals"], f"{field}.normals", "one [nx, ny, nz] per vertex")
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
        m = np.asarray(d["matrix"], dtype=np.float64) if isinstance(d["matrix"], list) else None
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


def parse_light(d: dict, field: str):
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object with a 'type'")
    kind = choice(_require(d, "type", field), f"{field}.type", ("environment", "point", "spot", "directional"))
    if kind == "environment":
        _check_keys(d, field, {"type", "radiance", "color", "note"})
        return EnvironmentLight(_illuminant(d, field, number(d.get("radiance", 1.0), f"{field}.radiance", 0)))
    if kind == "point":
        _check_keys(d, field, {"type", "position", "intensity", "color", "note"})
        return PointLight(vec3(_require(d, "position", field), f"{field}.position"),
                          _illuminant(d, field, number(d.get("intensity", 1.0), f"{field}.intensity", 0)))
    if kind == "spot":
        _check_keys(d, field, {"type", "position", "direction", "target", "intensity", "color",
                               "cone_angle_deg", "blend", "note"})
        pos = vec3(_require(d, "position", field), f"{field}.position")
        if "target" in d:
            direction = vec3(d["target"], f"{field}.target") - pos
            if not np.linalg.norm(direction) > 0:
                raise SceneError(f"{field}.target", "must differ from the position")
            direction /= np.linalg.norm(direction)
        else:
            direction = vec3(_require(d, "direction", field), f"{field}.direction", unit=True)
        return SpotLight(pos, direction,
                         _illuminant(d, field, number(d.get("intensity", 1.0), f"{field}.intensity", 0)),
                         number(d.get("cone_angle_deg", 45.0), f"{field}.cone_angle_deg", 0, 180, lo_open=True),
                         number(d.get("blend", 0.0), f"{field}.blend", 0, 1))
    _check_keys(d, field, {"type", "direction", "irradiance", "color", "note"})
    return DirectionalLight(vec3(_require(d, "direction", field), f"{field}.direction", unit=True),
                            _illuminant(d, field, number(d.get("irradiance", 1.0), f"{field}.irradiance", 0)))


def parse_scene(data: dict, base_dir: str = ".", source: str = "") -> Scene:
    """A validated Scene from a parsed engine-format (or peer-format) JSON object."""
    if not isinstance(data, dict):
        raise SceneError("", "a scene file must hold a JSON object")
    from .peer_format import is_peer_scene, peer_to_engine
    if is_peer_scene(data):
        data = peer_to_engine(data)
    fmt = data.get("format")
    if fmt != FORMAT:
        raise SceneError("format", f"must be {FORMAT!r} (or a peer scene with 'light' and 'integrator'), "
                                   f"got {fmt!r}")
    _check_keys(data, "", {"format", "camera", "render", "materials", "objects", "lights", "description",
                           "note", "name"})
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
            materials[name] = parse_material(mats_in[name], f"materials.{name}", lookup)
            resolving.pop()
        return materials[name]

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
    lights = [parse_light(light, f"lights[{i}]") for i, light in enumerate(lights_in)]
    if sum(isinstance(light, EnvironmentLight) for light in lights) > 1:
        raise SceneError("lights", "at most one environment light is allowed")
    scene = Scene(camera=camera, meshes=meshes, materials=materials, lights=lights, settings=settings,
                  source=source)
    return scene


def load_scene(path: str) -> Scene:
    """Read and validate a scene file (engine or peer format)."""
    try:
        with open(path, encoding="utf-8") as fh:
            data = json.load(fh)
    except FileNotFoundError:
        raise SceneError("", f"scene file {path!r} does not exist") from None
    except json.JSONDecodeError as e:
        raise SceneError("", f"{path}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    except OSError as e:
        raise SceneError("", f"cannot read scene file {path!r}: {e.strerror}") from None
    return parse_scene(data, os.path.dirname(os.path.abspath(path)), source=path)


__all__ = ["FORMAT", "load_scene", "parse_scene", "parse_camera", "parse_material", "parse_light",
           "parse_settings", "parse_object", "ConstantSpectrum"]
