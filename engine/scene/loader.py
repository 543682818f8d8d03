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

from ..materials.black_glass import BlackGlass
from ..materials.conductor import SmoothConductor
from ..materials.dielectric import SmoothDielectric
from ..materials.filter_sheet import FilterSheet
from ..materials.htsg import HTSG
from ..materials.lambert import Lambert
from ..materials.smooth_limit import MirrorWithDiffuse
from ..materials.torrance_sparrow import TorranceSparrow
from ..materials.weidlich_wilkie import Coat, WeidlichWilkie
from .description import (Camera, DirectionalLight, EnvironmentLight, Mesh, PointLight,
                                      RenderSettings, Scene, SpotLight)
from ..errors import SceneError
from .meshio import read_mesh
from .shapes import icosphere, quad, transform_matrix, transform_mesh
from ..spectral import ConstantSpectrum, RGBIlluminantSpectrum, named_ior, parse_spectrum

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
                           "height", "ortho_width", "shift", "clip_start", "clip_end", "note"})
    projection = choice(d.get("projection", "perspective"), f"{field}.projection",
                        ("perspective", "orthographic"))
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
    return cam


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
    """A BSDF from a material object.  ``lookup(name)`` resolves references to other materials
    (the base of a layered material may be given inline or by name)."""
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object with a 'type'")
    kind = choice(_require(d, "type", field), f"{field}.type",
                  ("lambert", "conductor", "dielectric", "black_glass", "torrance_sparrow", "htsg",
                   "weidlich_wilkie", "polariser", "retarder"))
    common = {"type", "note", "name"}
    if kind == "lambert":
        _check_keys(d, field, common | {"albedo"})
        return Lambert(parse_spectrum(d.get("albedo", 0.8), f"{field}.albedo", kind="reflectance"))
    if kind == "conductor":
        _check_keys(d, field, common | {"n", "k", "metal", "exterior_n"})
        ext = number(d.get("exterior_n", 1.0), f"{field}.exterior_n", 0, math.inf, lo_open=True)
        return SmoothConductor(*_complex_index(d, field), ext)
    if kind in ("polariser", "retarder"):
        _check_keys(d, field, common | {"axis", "extinction", "retardance_deg", "transmittance"})
        return FilterSheet(vec3(_require(d, "axis", field), f"{field}.axis", unit=True), kind,
                           extinction=number(d.get("extinction", 0.0), f"{field}.extinction", 0, 1),
                           retardance_deg=number(d.get("retardance_deg", 90.0), f"{field}.retardance_deg", -360, 360),
                           transmittance=number(d.get("transmittance", 1.0), f"{field}.transmittance", 0, 1))
    if kind == "weidlich_wilkie":
        _check_keys(d, field, common | {"coats", "base", "form", "t_term", "transmission_normal"})
        coats_in = _require(d, "coats", field)
        if not isinstance(coats_in, list) or not coats_in:
            raise SceneError(f"{field}.coats", "must be a non-empty list of coats (top coat first)")
        coats = [_parse_coat(c, f"{field}.coats[{i}]") for i, c in enumerate(coats_in)]
        base_in = d.get("base", {"type": "lambert", "albedo": 0.8})
        if depth > 16:
            raise SceneError(f"{field}.base", "layered materials nest more than 16 levels deep")
        if isinstance(base_in, str):
            if lookup is None:
                raise SceneError(f"{field}.base", "material references are not available here; give it inline")
            base = lookup(base_in, f"{field}.base")
        else:
            base = parse_material(base_in, f"{field}.base", lookup, depth + 1)
        form = choice(d.get("form", "energy"), f"{field}.form", ("energy", "published", "first_order"))
        normal = choice(d.get("transmission_normal"), f"{field}.transmission_normal", (None, "facet", "macro"))
        if form == "energy" and normal == "facet":
            raise SceneError(f"{field}.transmission_normal", "the energy-conserving form refracts through the macro "
                                                             "normal: use 'macro' (or form 'published')")
        try:
            return WeidlichWilkie(coats, base, form=form, t_term=choice(d.get("t_term", "ww"), f"{field}.t_term",
                                                                        ("ww", "t21")),
                                  transmission_normal=normal)
        except ValueError as e:
            raise SceneError(field, str(e)) from None
    if kind == "htsg":
        _check_keys(d, field, common | {"n", "k", "metal", "exterior_n", "sigma0_um", "tau_um", "albedo"})
        n, k = _complex_index(d, field)
        return HTSG(n, k, number(_require(d, "sigma0_um", field), f"{field}.sigma0_um", 0, 1e4),
                    number(_require(d, "tau_um", field), f"{field}.tau_um", 0, 1e6, lo_open=True),
                    albedo=parse_spectrum(d.get("albedo", 0.0), f"{field}.albedo", kind="reflectance"),
                    exterior_n=number(d.get("exterior_n", 1.0), f"{field}.exterior_n", 0, math.inf, lo_open=True))
    if kind == "torrance_sparrow":
        _check_keys(d, field, common | {"n", "k", "metal", "exterior_n", "m", "shadowing", "diffuse_albedo",
                                        "diffuse_weight", "specular_weight"})
        n, k = _complex_index(d, field)
        shadowing = choice(d.get("shadowing", "ts"), f"{field}.shadowing", ("ts", "smith", "smith_rational", "none"))
        m = number(_require(d, "m", field), f"{field}.m", 0, 100.0)
        if 0 < m < 1e-4:
            raise SceneError(f"{field}.m", f"must be 0 (the smooth limit) or in [0.0001, 100], got {m:g}")
        if m == 0:   # the smooth limit: a Fresnel mirror (plus the Lambertian part)
            return MirrorWithDiffuse(
                n, k, exterior_n=number(d.get("exterior_n", 1.0), f"{field}.exterior_n", 0, math.inf, lo_open=True),
                diffuse_albedo=parse_spectrum(d.get("diffuse_albedo", 0.0), f"{field}.diffuse_albedo",
                                              kind="reflectance"),
                diffuse_weight=number(d.get("diffuse_weight", 1.0 if "diffuse_albedo" in d else 0.0),
                                      f"{field}.diffuse_weight", 0),
                specular_weight=number(d.get("specular_weight", 1.0), f"{field}.specular_weight", 0))
        return TorranceSparrow(
            n, k, m, shadowing=shadowing,
            exterior_n=number(d.get("exterior_n", 1.0), f"{field}.exterior_n", 0, math.inf, lo_open=True),
            diffuse_albedo=parse_spectrum(d.get("diffuse_albedo", 0.0), f"{field}.diffuse_albedo", kind="reflectance"),
            diffuse_weight=number(d.get("diffuse_weight", 1.0 if "diffuse_albedo" in d else 0.0),
                                  f"{field}.diffuse_weight", 0),
            specular_weight=number(d.get("specular_weight", 1.0), f"{field}.specular_weight", 0))
    if kind == "dielectric":
        _check_keys(d, field, common | {"n", "exterior_n"})
        return SmoothDielectric(number(_require(d, "n", field), f"{field}.n", 0, math.inf, lo_open=True),
                                number(d.get("exterior_n", 1.0), f"{field}.exterior_n", 0, math.inf,
                                       lo_open=True))
    _check_keys(d, field, common | {"n", "k", "exterior_n"})
    if "k" in d:
        number(d["k"], f"{field}.k", 0, 0)  # black glass has a real index: only k = 0 is allowed
    n = parse_spectrum(d.get("n", 1.5), f"{field}.n", kind="unbounded")
    _check_positive_spectrum(n, f"{field}.n", strict=True)
    return BlackGlass(n, number(d.get("exterior_n", 1.0), f"{field}.exterior_n", 0, math.inf, lo_open=True))


def _parse_coat(c, field):
    if not isinstance(c, dict):
        raise SceneError(field, "must be an object like {\"n\": 1.5, \"distribution\": \"smooth\"}")
    _check_keys(c, field, {"n", "thickness", "absorption", "distribution", "exponent", "m", "note"})
    dist = choice(c.get("distribution", "smooth"), f"{field}.distribution", ("smooth", "blinn", "beckmann"))
    kw = {}
    if dist == "blinn":
        kw["exponent"] = number(_require(c, "exponent", field), f"{field}.exponent", 0, 1e7, lo_open=True)
    elif dist == "beckmann":
        kw["m"] = number(_require(c, "m", field), f"{field}.m", 1e-4, 100.0)
    return Coat(n=number(c.get("n", 1.5), f"{field}.n", 0, 100.0, lo_open=True),
                thickness=number(c.get("thickness", 0.0), f"{field}.thickness", 0),
                absorption=parse_spectrum(c.get("absorption", 0.0), f"{field}.absorption", kind="unbounded"),
                distribution=dist, **kw)


def _complex_index(d: dict, field: str):
    """(n, k) spectra of a conductor-like material: 'metal' or 'n' and 'k'."""
    if "metal" in d:
        if "n" in d or "k" in d:
            raise SceneError(f"{field}.metal", "give either 'metal' or 'n' and 'k', not both")
        return named_ior(d["metal"], field=f"{field}.metal")
    n = parse_spectrum(_require(d, "n", field), f"{field}.n", kind="unbounded")
    k = parse_spectrum(d.get("k", 0.0), f"{field}.k", kind="unbounded")
    _check_positive_spectrum(n, f"{field}.n", strict=True)
    _check_positive_spectrum(k, f"{field}.k", strict=False)
    return n, k


def _check_positive_spectrum(spec, field: str, strict: bool):
    """Constant or tabulated index parts: n > 0, κ ≥ 0 over 360–830 nm."""
    lam = np.linspace(360.0, 830.0, 95)
    try:
        v = spec.eval(lam)
    except SceneError:
        raise
    bad = (v <= 0) if strict else (v < 0)
    if np.any(bad) or not np.all(np.isfinite(v)):
        raise SceneError(field, f"must be {'> 0' if strict else '≥ 0'} at every wavelength in 360–830 nm")


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


def _parse_object_base(d: dict, field: str, base_dir: str, material_names) -> Mesh:
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object")
    shape = choice(_require(d, "shape", field), f"{field}.shape", ("mesh", "sphere", "quad", "triangles"))
    name = str(d.get("name", field))
    allowed = {"name", "shape", "material", "materials", "emission", "transform", "note", "normal"}
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
    return Mesh(name=name, vertices=np.asarray(data.vertices, dtype=np.float64), faces=faces,
                materials=list(mat_list), material_ids=ids.astype(np.int32), normals=data.vertex_normals,
                emission=emission)


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


def _parse_light_base(d: dict, field: str):
    if not isinstance(d, dict):
        raise SceneError(field, "must be an object with a 'type'")
    kind = choice(_require(d, "type", field), f"{field}.type", ("environment", "point", "spot", "directional"))
    if kind == "environment":
        _check_keys(d, field, {"type", "radiance", "color", "note"})
        return EnvironmentLight(_illuminant(d, field, number(d.get("radiance", 1.0), f"{field}.radiance", 0)))
    if kind == "point":
        _check_keys(d, field, {"type", "position", "intensity", "color", "note", *LIGHT_OPTIONS["point"]})
        return PointLight(vec3(_require(d, "position", field), f"{field}.position"),
                          _illuminant(d, field, number(d.get("intensity", 1.0), f"{field}.intensity", 0)))
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
                         _illuminant(d, field, number(d.get("intensity", 1.0), f"{field}.intensity", 0)),
                         number(d.get("cone_angle_deg", 45.0), f"{field}.cone_angle_deg", 0, 180, lo_open=True),
                         number(d.get("blend", 0.0), f"{field}.blend", 0, 1))
    _check_keys(d, field, {"type", "direction", "irradiance", "color", "note", *LIGHT_OPTIONS["directional"]})
    return DirectionalLight(vec3(_require(d, "direction", field), f"{field}.direction", unit=True),
                            _illuminant(d, field, number(d.get("irradiance", 1.0), f"{field}.irradiance", 0)))


# ----------------------------------------------------------------------------- Cycles' light options
# Optional, with Cycles' meaning (README: the Blender light table); the defaults are the format's
# original meaning, so existing and peer scenes render exactly as before.

#: optional keys of each light type
LIGHT_OPTIONS = {"point": ("radius", "soft_falloff", "visible_camera"),
                 "spot": ("radius", "soft_falloff", "visible_camera", "blend_profile"),
                 "directional": ("angle_deg", "visible_camera")}
#: optional emitter options inside "emission" (Mesh fields; defaults: one-sided, opaque, Lambertian)
EMITTER_OPTIONS = ("two_sided", "occluder", "spread_deg")


def _flag(d, key: str, field: str, default: bool) -> bool:
    value = d.get(key, default)
    if not isinstance(value, bool):
        raise SceneError(f"{field}.{key}", "must be true or false")
    return value


def parse_light(d: dict, field: str):
    """A light from its JSON object, with the optional Cycles options of LIGHT_OPTIONS."""
    light = _parse_light_base(d, field)
    if isinstance(light, (PointLight, SpotLight)):
        light.radius = number(d.get("radius", 0.0), f"{field}.radius", 0)
        light.soft_falloff = _flag(d, "soft_falloff", field, True)
    if isinstance(light, SpotLight):
        light.blend_profile = choice(d.get("blend_profile", "angle"), f"{field}.blend_profile", ("angle", "cycles"))
    if isinstance(light, DirectionalLight):
        light.angle_deg = number(d.get("angle_deg", 0.0), f"{field}.angle_deg", 0, 180, hi_open=True)
    if not isinstance(light, EnvironmentLight):
        light.visible_camera = _flag(d, "visible_camera", field, True)
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
    return out


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
