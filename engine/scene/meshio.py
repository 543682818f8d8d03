"""Triangle-mesh input: PLY (ASCII, binary little/big endian) and Wavefront OBJ.

Public API
----------
``MeshData``                      vertices / faces / optional normals and groups
``read_mesh(path, field="")``     dispatch on the extension (.ply, .obj)
``read_ply(path, field="")``      PLY reader
``read_obj(path, field="")``      OBJ reader
``face_normals(vertices, faces)`` unnormalised geometric normals (p1-p0)x(p2-p0)
``triangle_areas(vertices, faces)``
``compute_vertex_normals(vertices, faces)`` area-weighted unit vertex normals

Conventions
-----------
* Faces are triangles, counter-clockwise seen from the front: the geometric
  normal ``(p1 - p0) x (p2 - p0)`` points to the front side.
* Polygons with more than three corners are triangulated as fans
  ``(c0, c1, c2), (c0, c2, c3), ...`` (exact for convex planar polygons).
* ``vertex_normals`` are unit length.  Normals that are present in the file
  are normalised; zero-length normals from the file (some exporters write
  zeros) are replaced by area-weighted normals computed from the faces.
* Every problem with the input raises ``SceneError(field, message)``; the
  message names the file and what is wrong.  No raw numpy / struct / OS
  exception escapes the readers.

OBJ specifics
-------------
* Supported statements: ``v`` (extra components such as ``w`` or vertex
  colours are ignored), ``vn``, ``f`` with corners ``v``, ``v/vt``,
  ``v//vn``, ``v/vt/vn`` (negative = relative to the data defined so far),
  ``usemtl``.  ``o``, ``g``, ``s``, ``vt``, ``mtllib``, ``l``, ``p`` and
  unknown statements are ignored.  Text after ``#`` is a comment.
* Without any ``vn`` in the file, ``vertex_normals`` is ``None`` and vertices
  are kept in file order (unreferenced ones included).
* With normals, OBJ allows a different normal per corner, so each distinct
  (position, normal) pair becomes one output vertex (sorted by position
  index, then normal index); unreferenced positions are dropped.
* Faces without normal indices in a file that does have normals are
  accepted: their corners become vertices of their own (pair (v, none)) and
  get area-weighted normals computed from the faces that use them, i.e. those
  faces are smooth shaded among themselves.
* ``face_groups`` holds, per output triangle, the index into ``group_names``
  (``usemtl`` names in order of first appearance).  Faces before the first
  ``usemtl`` get group -1 (``group_names`` is empty and ``face_groups`` is
  ``None`` when the file has no ``usemtl`` at all).
"""
from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field as dc_field

import numpy as np

from ..errors import SceneError

__all__ = [
    "MeshData",
    "read_mesh",
    "read_ply",
    "read_obj",
    "face_normals",
    "triangle_areas",
    "compute_vertex_normals",
]


# ---------------------------------------------------------------------------
# data


@dataclass
class MeshData:
    """A triangle mesh.

    vertices        float64 (V, 3)
    faces           int32 (F, 3), counter-clockwise = front
    vertex_normals  float64 (V, 3) unit vectors, or None (flat shading)
    face_groups     int32 (F,) material group per face (-1 = none), or None
    group_names     names of the groups (OBJ ``usemtl`` order)
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_normals: np.ndarray | None = None
    face_groups: np.ndarray | None = None
    group_names: list = dc_field(default_factory=list)

    def __post_init__(self):
        self.vertices = np.ascontiguousarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int32).reshape(-1, 3)
        if self.vertex_normals is not None:
            self.vertex_normals = np.ascontiguousarray(
                self.vertex_normals, dtype=np.float64).reshape(-1, 3)
            if self.vertex_normals.shape != self.vertices.shape:
                raise ValueError("vertex_normals must have the same shape as vertices")
        if self.face_groups is not None:
            self.face_groups = np.ascontiguousarray(self.face_groups, dtype=np.int32).reshape(-1)
            if self.face_groups.shape[0] != self.faces.shape[0]:
                raise ValueError("face_groups must have one entry per face")
        self.group_names = list(self.group_names)

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])


# ---------------------------------------------------------------------------
# geometry helpers


def face_normals(vertices, faces) -> np.ndarray:
    """Unnormalised geometric normals ``(p1 - p0) x (p2 - p0)``, shape (F, 3).

    Their length is twice the triangle area; they point to the front side.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces)
    p0 = v[f[:, 0]]
    return np.cross(v[f[:, 1]] - p0, v[f[:, 2]] - p0)


def triangle_areas(vertices, faces) -> np.ndarray:
    """Triangle areas, shape (F,)."""
    n = face_normals(vertices, faces)
    return 0.5 * np.sqrt(np.einsum("ij,ij->i", n, n))


def compute_vertex_normals(vertices, faces) -> np.ndarray:
    """Area-weighted unit vertex normals, shape (V, 3).

    Vertices used by no face (or only by degenerate faces) get (0, 0, 1).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    fn = face_normals(v, f)  # length = 2 * area -> area weighting
    nv = v.shape[0]
    idx = f.reshape(-1)
    out = np.empty((nv, 3))
    for k in range(3):
        out[:, k] = np.bincount(idx, weights=np.repeat(fn[:, k], 3), minlength=nv)
    return _normalise_or_default(out)


def _normalise_or_default(n: np.ndarray) -> np.ndarray:
    length = np.sqrt(np.einsum("ij,ij->i", n, n))
    ok = length > 0
    out = np.zeros_like(n)
    out[ok] = n[ok] / length[ok, None]
    out[~ok] = (0.0, 0.0, 1.0)
    return out


# ---------------------------------------------------------------------------
# shared helpers


def _err(field: str, path, what: str) -> SceneError:
    return SceneError(field, f"mesh file '{os.fspath(path)}': {what}")


def _read_bytes(path, field: str) -> bytes:
    p = os.fspath(path)
    if not os.path.exists(p):
        raise _err(field, p, "file not found")
    if os.path.isdir(p):
        raise _err(field, p, "is a directory, not a mesh file")
    try:
        with open(p, "rb") as fh:
            return fh.read()
    except OSError as e:
        raise _err(field, p, f"cannot be read ({e.strerror or e})") from None


def _fan(flat: np.ndarray, counts: np.ndarray):
    """Fan-triangulate polygons given as flat corner list + corner counts.

    Returns (triangles (T, 3), polygon index of each triangle (T,)).
    """
    nface = counts.shape[0]
    if nface and flat.shape[0] == 3 * nface and (counts == 3).all():
        return flat.reshape(-1, 3), np.arange(nface)
    ntri = counts - 2
    starts = np.cumsum(counts) - counts
    poly = np.repeat(np.arange(nface), ntri)
    first = np.cumsum(ntri) - ntri
    local = np.arange(int(ntri.sum())) - np.repeat(first, ntri)
    s = starts[poly]
    tris = np.stack([flat[s], flat[s + local + 1], flat[s + local + 2]], axis=1)
    return tris, poly


def _check_counts(counts: np.ndarray, field, path, what="face", lines=None):
    bad = np.flatnonzero(counts < 3)
    if bad.size:
        i = int(bad[0])
        where = f"{what} {i}" + (f" (line {lines[i]})" if lines is not None else "")
        raise _err(field, path, f"{where} has {int(counts[i])} corner(s); "
                                "a face needs at least 3")


def _check_finite(arr: np.ndarray, field, path, what: str, lines=None):
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        where = f"{what} {i}" + (f" (line {lines[i]})" if lines is not None else "")
        raise _err(field, path, f"{where} is not finite: {arr[i].tolist()}")


def _finish_normals(normals, vertices, faces, field, path):
    """Validate + normalise file normals; zero-length ones are recomputed."""
    _check_finite(normals, field, path, "vertex normal")
    length = np.sqrt(np.einsum("ij,ij->i", normals, normals))
    zero = length == 0
    out = np.empty_like(normals)
    ok = ~zero
    out[ok] = normals[ok] / length[ok, None]
    if zero.any():
        out[zero] = compute_vertex_normals(vertices, faces)[zero]
    return out


# ---------------------------------------------------------------------------
# PLY

_PLY_TYPES = {
    "char": "i1", "int8": "i1",
    "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4",
    "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4",
    "double": "f8", "float64": "f8",
    "int64": "i8", "uint64": "u8",  # non-standard, but harmless
}


class _Prop:
    __slots__ = ("name", "type", "count_type")

    def __init__(self, name, type_, count_type=None):
        self.name = name
        self.type = type_            # numpy code without byte order
        self.count_type = count_type  # None for scalar properties

    @property
    def is_list(self):
        return self.count_type is not None


class _Element:
    __slots__ = ("name", "count", "props")

    def __init__(self, name, count):
        self.name = name
        self.count = count
        self.props: list[_Prop] = []


def _parse_ply_header(data: bytes, field, path):
    if not (data.startswith(b"ply\n") or data.startswith(b"ply\r\n")):
        raise _err(field, path, "not a PLY file (it does not start with 'ply')")
    pos = data.find(b"end_header")
    while pos >= 0 and data[pos - 1:pos] not in (b"\n", b"\r"):
        pos = data.find(b"end_header", pos + 1)
    if pos < 0:
        raise _err(field, path, "PLY header has no 'end_header' line")
    end = pos + len(b"end_header")
    if data[end:end + 2] == b"\r\n":
        end += 2
    elif data[end:end + 1] in (b"\n", b"\r"):
        end += 1
    elif end != len(data):
        raise _err(field, path, "malformed 'end_header' line")
    lines = data[:pos].decode("ascii", errors="replace").splitlines()

    fmt = None
    elements: list[_Element] = []
    for lineno, line in enumerate(lines[1:], start=2):
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        kw = tok[0]
        if kw == "format":
            if len(tok) < 2 or tok[1] not in ("ascii", "binary_little_endian",
                                              "binary_big_endian"):
                raise _err(field, path, f"unsupported PLY format on header line "
                                        f"{lineno}: '{line.strip()}' (supported: ascii, "
                                        "binary_little_endian, binary_big_endian)")
            fmt = tok[1]
        elif kw == "element":
            if len(tok) != 3:
                raise _err(field, path, f"malformed element on header line {lineno}: "
                                        f"'{line.strip()}'")
            try:
                n = int(tok[2])
            except ValueError:
                n = -1
            if n < 0:
                raise _err(field, path, f"bad element count on header line {lineno}: "
                                        f"'{line.strip()}'")
            elements.append(_Element(tok[1], n))
        elif kw == "property":
            if not elements:
                raise _err(field, path, f"property before any element on header line "
                                        f"{lineno}")
            if len(tok) >= 2 and tok[1] == "list":
                if (len(tok) != 5 or tok[2] not in _PLY_TYPES
                        or tok[3] not in _PLY_TYPES):
                    raise _err(field, path, f"malformed list property on header line "
                                            f"{lineno}: '{line.strip()}'")
                if _PLY_TYPES[tok[2]][0] == "f":
                    raise _err(field, path, f"list count type must be an integer type "
                                            f"(header line {lineno})")
                elements[-1].props.append(
                    _Prop(tok[4], _PLY_TYPES[tok[3]], _PLY_TYPES[tok[2]]))
            else:
                if len(tok) != 3 or tok[1] not in _PLY_TYPES:
                    raise _err(field, path, f"malformed or unsupported property on header "
                                            f"line {lineno}: '{line.strip()}'")
                elements[-1].props.append(_Prop(tok[2], _PLY_TYPES[tok[1]]))
        else:
            raise _err(field, path, f"unknown PLY header keyword '{kw}' on line {lineno}")
    if fmt is None:
        raise _err(field, path, "PLY header has no 'format' line")
    return fmt, elements, end


def _truncated(field, path, elem, need, have):
    return _err(field, path, f"truncated binary data in element '{elem.name}' "
                             f"({elem.count} rows): needs at least {need} bytes, "
                             f"only {max(have, 0)} left in the file")


def _ply_binary_element(buf: bytes, off: int, elem: _Element, bo: str, field, path):
    """Parse one binary element. Returns ({prop index: data}, new offset).

    Scalar props -> array (n,); list props -> (flat values, counts).
    """
    n = elem.count
    props = elem.props
    remaining = len(buf) - off
    if not any(p.is_list for p in props):
        dt = np.dtype([(f"p{i}", bo + p.type) for i, p in enumerate(props)])
        need = n * dt.itemsize
        if need > remaining:
            raise _truncated(field, path, elem, need, remaining)
        arr = np.frombuffer(buf, dtype=dt, count=n, offset=off)
        return {i: arr[f"p{i}"] for i in range(len(props))}, off + need
    if n == 0:
        return {i: (np.zeros(0), np.zeros(0, np.int64)) if p.is_list else np.zeros(0)
                for i, p in enumerate(props)}, off
    # Every row needs at least its scalars and list counts (guards against
    # absurd row counts in a corrupt header before allocating anything).
    min_row = sum(np.dtype(p.count_type if p.is_list else p.type).itemsize
                  for p in props)
    if n * min_row > remaining:
        raise _truncated(field, path, elem, n * min_row, remaining)

    # Fast path: assume every row has the list lengths of the first row.
    guess = []
    o = off
    ok = True
    for p in props:
        if p.is_list:
            cs = np.dtype(p.count_type).itemsize
            if o + cs > len(buf):
                ok = False
                break
            c = int(np.frombuffer(buf, bo + p.count_type, 1, o)[0])
            if c <= 0:
                ok = False
                break
            guess.append(c)
            o += cs + c * np.dtype(p.type).itemsize
        else:
            o += np.dtype(p.type).itemsize
    if ok:
        fields = []
        gi = iter(guess)
        for i, p in enumerate(props):
            if p.is_list:
                fields.append((f"c{i}", bo + p.count_type))
                fields.append((f"p{i}", bo + p.type, (next(gi),)))
            else:
                fields.append((f"p{i}", bo + p.type))
        dt = np.dtype(fields)
        need = n * dt.itemsize
        if need <= remaining:
            arr = np.frombuffer(buf, dtype=dt, count=n, offset=off)
            gi = iter(guess)
            same = all((arr[f"c{i}"] == next(gi)).all()
                       for i, p in enumerate(props) if p.is_list)
            if same:
                out = {}
                for i, p in enumerate(props):
                    if p.is_list:
                        vals = arr[f"p{i}"]
                        out[i] = (vals.reshape(-1),
                                  np.full(n, vals.shape[1], dtype=np.int64))
                    else:
                        out[i] = arr[f"p{i}"]
                return out, off + need

    # Slow path: variable list lengths; walk the rows to find offsets, then
    # gather the values vectorised.
    layout = []
    for p in props:
        if p.is_list:
            layout.append((True, struct.Struct(("<" if bo == "<" else ">")
                                               + np.dtype(p.count_type).char).unpack_from,
                           np.dtype(p.count_type).itemsize, np.dtype(p.type).itemsize))
        else:
            layout.append((False, None, 0, np.dtype(p.type).itemsize))
    starts = [np.empty(n, dtype=np.int64) for _ in props]
    counts = [np.empty(n, dtype=np.int64) if p.is_list else None for p in props]
    size = len(buf)
    o = off
    try:
        for r in range(n):
            for i, (is_list, unpack, cs, isz) in enumerate(layout):
                if is_list:
                    c = unpack(buf, o)[0]
                    if c < 0:
                        raise _err(field, path, f"negative list length {c} in element "
                                                f"'{elem.name}' row {r}")
                    o += cs
                    starts[i][r] = o
                    counts[i][r] = c
                    o += c * isz
                else:
                    starts[i][r] = o
                    o += isz
            if o > size:
                raise struct.error("past end")
    except struct.error:
        raise _err(field, path, f"truncated binary data in element '{elem.name}' "
                                f"({n} rows): the data ends inside row {r}") from None
    u8 = np.frombuffer(buf, dtype=np.uint8)
    out = {}
    for i, p in enumerate(props):
        isz = np.dtype(p.type).itemsize
        if p.is_list:
            c = counts[i]
            first = np.cumsum(c) - c
            item = (np.repeat(starts[i], c)
                    + (np.arange(int(c.sum())) - np.repeat(first, c)) * isz)
        else:
            c = None
            item = starts[i]
        raw = u8[item[:, None] + np.arange(isz)].reshape(-1)
        vals = raw.view(bo + p.type) if raw.size else np.zeros(0, bo + p.type)
        out[i] = (vals, c) if p.is_list else vals
    return out, o


def _ply_ascii_element(tokens: list, pos: int, elem: _Element, field, path):
    """Parse one ASCII element. Returns ({prop index: data}, new token pos)."""
    n = elem.count
    props = elem.props

    def to_float(toks, what):
        try:
            return np.array(toks, dtype=np.float64)
        except ValueError:
            bad = next((t for t in toks if not _is_number(t)), "?")
            raise _err(field, path, f"non-numeric value '{bad}' in element "
                                    f"'{elem.name}' {what}") from None

    def short(got_rows):
        return _err(field, path, f"ASCII data ends early: element '{elem.name}' declares "
                                 f"{n} rows but only {got_rows} row(s) are present")

    if not any(p.is_list for p in props):
        k = len(props)
        if pos + n * k > len(tokens):
            raise short((len(tokens) - pos) // max(k, 1))
        arr = to_float(tokens[pos:pos + n * k], "data").reshape(n, k)
        return {i: arr[:, i] for i in range(k)}, pos + n * k
    if n == 0:
        return {i: (np.zeros(0), np.zeros(0, np.int64)) if p.is_list else np.zeros(0)
                for i, p in enumerate(props)}, pos

    def as_count(tok, r):
        try:
            c = int(tok)
        except ValueError:
            try:
                cf = float(tok)
                c = int(cf) if cf == int(cf) else -1
            except (ValueError, OverflowError):
                c = -1
        if c < 0:
            raise _err(field, path, f"bad list length '{tok}' in element '{elem.name}' "
                                    f"row {r}")
        return c

    # Fast path: every row has the list lengths of the first row.
    cols = []  # (prop index, is_count) per column of one row
    p_ = pos
    ok = True
    for i, p in enumerate(props):
        if p_ >= len(tokens):
            ok = False
            break
        if p.is_list:
            c = as_count(tokens[p_], 0)
            cols.append((i, "count"))
            cols.extend([(i, "item")] * c)
            p_ += 1 + c
        else:
            cols.append((i, "scalar"))
            p_ += 1
    L = len(cols)
    if ok and pos + n * L <= len(tokens):
        arr = to_float(tokens[pos:pos + n * L], "data").reshape(n, L)
        same = True
        col_of = {}
        for j, (i, kind) in enumerate(cols):
            col_of.setdefault((i, kind), []).append(j)
        for i, p in enumerate(props):
            if p.is_list:
                cj = col_of[(i, "count")][0]
                c = len(col_of.get((i, "item"), []))
                if not (arr[:, cj] == c).all():
                    same = False
                    break
        if same:
            out = {}
            for i, p in enumerate(props):
                if p.is_list:
                    js = col_of.get((i, "item"), [])
                    out[i] = (arr[:, js].reshape(-1), np.full(n, len(js), np.int64))
                else:
                    out[i] = arr[:, col_of[(i, "scalar")][0]]
            return out, pos + n * L

    # Slow path: variable list lengths.
    picks = [[] for _ in props]
    counts = [[] if p.is_list else None for p in props]
    p_ = pos
    nt = len(tokens)
    for r in range(n):
        for i, p in enumerate(props):
            if p_ >= nt:
                raise short(r)
            if p.is_list:
                c = as_count(tokens[p_], r)
                p_ += 1
                if p_ + c > nt:
                    raise short(r)
                picks[i].extend(range(p_, p_ + c))
                counts[i].append(c)
                p_ += c
            else:
                picks[i].append(p_)
                p_ += 1
    out = {}
    for i, p in enumerate(props):
        vals = to_float([tokens[j] for j in picks[i]], "data")
        out[i] = (vals, np.array(counts[i], np.int64)) if p.is_list else vals
    return out, p_


def _is_number(tok) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def _to_index(vals: np.ndarray, field, path, what) -> np.ndarray:
    """Convert parsed index values (any numeric dtype) to int64, checked."""
    if vals.dtype.kind == "f":
        if not np.isfinite(vals).all() or (vals != np.round(vals)).any():
            bad = vals[~np.isfinite(vals) | (vals != np.round(vals))][0]
            raise _err(field, path, f"{what}: non-integer vertex index {bad!r}")
    return vals.astype(np.int64)


def _check_index_range(flat, counts, nv, field, path, what="face", lines=None,
                       shown=None):
    bad = (flat < 0) | (flat >= nv)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        face = int(np.searchsorted(np.cumsum(counts), k, side="right"))
        where = f"{what} {face}" + (f" (line {lines[face]})" if lines is not None else "")
        val = int(flat[k]) if shown is None else shown[k]
        raise _err(field, path, f"{where} references vertex index {val}, out of range "
                                f"for {nv} vertices")


def read_ply(path, field: str = "") -> MeshData:
    """Read a PLY mesh (ascii / binary_little_endian / binary_big_endian).

    Vertex element: x, y, z required; nx, ny, nz optional (all three); any
    other properties and any numeric types are accepted (others skipped).
    Face element: list property ``vertex_indices`` (or ``vertex_index``);
    polygons are fan-triangulated.  Other elements are skipped.
    """
    data = _read_bytes(path, field)
    fmt, elements, body = _parse_ply_header(data, field, path)
    names = [e.name for e in elements]
    if "vertex" not in names:
        raise _err(field, path, "PLY file has no 'vertex' element")
    if "face" not in names:
        raise _err(field, path, "PLY file has no 'face' element (zero faces)")

    # Validate the interesting properties before reading any data.
    ve = elements[names.index("vertex")]
    fe = elements[names.index("face")]
    vprops = {p.name: i for i, p in enumerate(ve.props)}
    for c in ("x", "y", "z"):
        if c not in vprops:
            raise _err(field, path, f"vertex element has no '{c}' property")
        if ve.props[vprops[c]].is_list:
            raise _err(field, path, f"vertex property '{c}' must not be a list")
    has_n = all(c in vprops and not ve.props[vprops[c]].is_list
                for c in ("nx", "ny", "nz"))
    fi = next((i for i, p in enumerate(fe.props)
               if p.name in ("vertex_indices", "vertex_index")), None)
    if fi is None or not fe.props[fi].is_list:
        raise _err(field, path, "face element has no list property 'vertex_indices' "
                                "(or 'vertex_index')")
    if fe.props[fi].type[0] == "f":
        raise _err(field, path, "face vertex indices must have an integer type")
    if fe.count == 0:
        raise _err(field, path, "mesh has zero faces")
    if ve.count == 0:
        raise _err(field, path, "mesh has zero vertices")

    parsed = {}
    if fmt == "ascii":
        tokens = data[body:].decode("ascii", errors="replace").split()
        pos = 0
        for e in elements:
            parsed[e.name], pos = _ply_ascii_element(tokens, pos, e, field, path)
            if "vertex" in parsed and "face" in parsed:
                break
    else:
        bo = "<" if fmt == "binary_little_endian" else ">"
        off = body
        for e in elements:
            parsed[e.name], off = _ply_binary_element(data, off, e, bo, field, path)
            if "vertex" in parsed and "face" in parsed:
                break

    vd = parsed["vertex"]
    verts = np.stack([vd[vprops[c]] for c in ("x", "y", "z")], axis=1).astype(np.float64)
    _check_finite(verts, field, path, "vertex")
    flat, counts = parsed["face"][fi]
    flat = _to_index(flat, field, path, "face data")
    _check_counts(counts, field, path)
    _check_index_range(flat, counts, verts.shape[0], field, path)
    tris, _ = _fan(flat, counts)
    normals = None
    if has_n:
        normals = np.stack([vd[vprops[c]] for c in ("nx", "ny", "nz")],
                           axis=1).astype(np.float64)
        normals = _finish_normals(normals, verts, tris, field, path)
    return MeshData(verts, tris, normals)


# ---------------------------------------------------------------------------
# OBJ


def read_obj(path, field: str = "") -> MeshData:
    """Read a Wavefront OBJ mesh (see module docstring for the rules)."""
    raw = _read_bytes(path, field)
    text = raw.decode("utf-8", errors="replace")

    v_str, v_lines = [], []
    vn_str, vn_lines = [], []
    corners: list[str] = []
    f_counts, f_lines, f_nv, f_nvn, f_group = [], [], [], [], []
    group_names: list[str] = []
    group_of: dict[str, int] = {}
    cur_group = -1
    ws = (" ", "\t")

    for lineno, line in enumerate(text.splitlines(), start=1):
        if "#" in line:
            line = line.split("#", 1)[0]
        if line[:1] in ws:
            line = line.lstrip()
        c0 = line[:1]
        if c0 == "v":
            c1 = line[1:2]
            if c1 in ws:
                v_str.append(line[2:])
                v_lines.append(lineno)
                continue
            if c1 == "n" and line[2:3] in ws:
                vn_str.append(line[3:])
                vn_lines.append(lineno)
                continue
        elif c0 == "f" and line[1:2] in ws:
            tok = line[2:].split()
            corners.extend(tok)
            f_counts.append(len(tok))
            f_lines.append(lineno)
            f_nv.append(len(v_str))
            f_nvn.append(len(vn_str))
            f_group.append(cur_group)
            continue
        elif c0 == "u" and line.startswith("usemtl") and line[6:7] in ws:
            name = line[7:].strip()
            if name not in group_of:
                group_of[name] = len(group_names)
                group_names.append(name)
            cur_group = group_of[name]
        # everything else (vt, o, g, s, mtllib, l, p, ...) is ignored

    def floats(strs, lines, what):
        """First three numbers of each line -> (n, 3) float64."""
        toks = " ".join(strs).split()
        if len(toks) == 3 * len(strs):
            try:
                return np.array(toks, dtype=np.float64).reshape(-1, 3)
            except ValueError:
                pass
        rows = [s.split()[:3] for s in strs]   # extra components (w, colour) ignored
        short = next((i for i, r in enumerate(rows) if len(r) != 3), None)
        if short is not None:
            raise _err(field, path, f"line {lines[short]}: '{what}' needs 3 numbers")
        try:
            return np.array(rows, dtype=np.float64).reshape(-1, 3)
        except ValueError:
            i = next(i for i, r in enumerate(rows) if not all(map(_is_number, r)))
            raise _err(field, path, f"line {lines[i]}: non-numeric '{what}' "
                                    f"value {' '.join(rows[i])!r}") from None

    if not f_counts:
        raise _err(field, path, "mesh has zero faces (no 'f' statements)")
    verts = floats(v_str, v_lines, "v")
    _check_finite(verts, field, path, "vertex", v_lines)
    vnorm = floats(vn_str, vn_lines, "vn") if vn_str else np.zeros((0, 3))
    _check_finite(vnorm, field, path, "normal", vn_lines)

    counts = np.array(f_counts, dtype=np.int64)
    _check_counts(counts, field, path, lines=f_lines)
    face_of_corner = None

    def corner_line(k):
        nonlocal face_of_corner
        if face_of_corner is None:
            face_of_corner = np.cumsum(counts)
        return f_lines[int(np.searchsorted(face_of_corner, k, side="right"))]

    parsed = _obj_corners_fast(corners)
    if parsed is None:
        parsed = _obj_corners_slow(corners, corner_line, field, path)
    vi_raw, ni_raw, has_vn_mask = parsed

    base_v = np.repeat(np.array(f_nv, dtype=np.int64), counts)
    vi = _resolve_obj_index(vi_raw, base_v, len(v_str), field, path, "vertex",
                            corner_line)

    face_groups = None
    if group_names:
        poly_group = np.array(f_group, dtype=np.int64)

    if has_vn_mask is False or (has_vn_mask is not True and not has_vn_mask.any()):
        tris, poly = _fan(vi, counts)
        if group_names:
            face_groups = poly_group[poly]
        return MeshData(verts, tris, None, face_groups, group_names)

    base_n = np.repeat(np.array(f_nvn, dtype=np.int64), counts)
    if has_vn_mask is True:
        ni = _resolve_obj_index(ni_raw, base_n, len(vn_str), field, path, "normal",
                                corner_line)
    else:
        idx = np.flatnonzero(has_vn_mask)
        ni = np.full(len(corners), -1, dtype=np.int64)
        ni[idx] = _resolve_obj_index(ni_raw[idx], base_n[idx], len(vn_str), field, path,
                                     "normal", lambda k: corner_line(int(idx[k])))

    # Split vertices so that each (position, normal) pair is one vertex.
    stride = len(vn_str) + 1
    key = vi * stride + (ni + 1)
    ukey, inv = np.unique(key, return_inverse=True)
    inv = inv.reshape(-1)
    new_v = verts[ukey // stride]
    uni = ukey % stride - 1
    tris, poly = _fan(inv, counts)
    normals = np.empty_like(new_v)
    have = uni >= 0
    normals[have] = vnorm[uni[have]]
    length = np.sqrt(np.einsum("ij,ij->i", normals, normals))
    need = ~have
    need[have] = length[have] == 0
    ok = ~need
    normals[ok] /= length[ok, None]
    if need.any():
        normals[need] = compute_vertex_normals(new_v, tris)[need]
    if group_names:
        face_groups = poly_group[poly]
    return MeshData(new_v, tris, normals, face_groups, group_names)


def _obj_corners_fast(corners):
    """Bulk-parse face corners when all share one form (v, v//vn or v/vt/vn).

    Returns (vertex idx, normal idx or None, True/False = all/no normals) or
    None when the fast path does not apply (the slow path then also produces
    the detailed error messages).
    """
    n = len(corners)
    s = " ".join(corners)
    slashes = s.count("/")
    try:
        if slashes == 0:
            toks = s.split()
            if len(toks) == n:
                return np.array(toks, dtype=np.int64), None, False
        elif slashes == 2 * n:
            if s.count("//") == n:                       # v//vn
                toks = s.replace("//", " ").split()
                if len(toks) == 2 * n:
                    a = np.array(toks, dtype=np.int64).reshape(n, 2)
                    return a[:, 0], a[:, 1], True
            elif "//" not in s:                           # v/vt/vn
                toks = s.replace("/", " ").split()
                if len(toks) == 3 * n:
                    a = np.array(toks, dtype=np.int64).reshape(n, 3)
                    return a[:, 0], a[:, 2], True
    except (ValueError, OverflowError):
        return None
    return None


def _obj_corners_slow(corners, corner_line, field, path):
    """Per-corner parsing for mixed forms, with precise error messages."""
    parts = [c.split("/") for c in corners]
    bad = next((k for k, p in enumerate(parts) if len(p) > 3 or not p[0]), None)
    if bad is not None:
        raise _err(field, path, f"line {corner_line(bad)}: malformed face corner "
                                f"'{corners[bad]}'")
    has_vn = np.fromiter((len(p) == 3 and p[2] != "" for p in parts),
                         dtype=bool, count=len(parts))

    def ints(strs, what, pos):
        try:
            return np.array(strs, dtype=np.int64)
        except (ValueError, OverflowError):
            k = next(k for k, s in enumerate(strs) if not _is_int(s))
            raise _err(field, path, f"line {corner_line(pos(k))}: bad {what} index "
                                    f"'{strs[k]}' in face corner") from None

    vi = ints([p[0] for p in parts], "vertex", lambda k: k)
    ni = np.zeros(len(parts), dtype=np.int64)
    idx = np.flatnonzero(has_vn)
    if idx.size:
        ni[idx] = ints([parts[k][2] for k in idx], "normal", lambda k: int(idx[k]))
    return vi, ni, has_vn


def _is_int(s) -> bool:
    try:
        int(s)
        return True
    except ValueError:
        return False


def _resolve_obj_index(raw, base, total, field, path, what, corner_line):
    """1-based / negative OBJ indices -> 0-based, range checked."""
    out = np.where(raw > 0, raw - 1, base + raw)
    bad = (raw == 0) | (out < 0) | (out >= total)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise _err(field, path, f"line {corner_line(k)}: {what} index {int(raw[k])} is "
                                f"out of range ({total} {what}s defined"
                                + (f", {int(base[k])} before this line)" if raw[k] < 0
                                   else ")"))
    return out


# ---------------------------------------------------------------------------
# dispatch

_READERS = {".ply": read_ply, ".obj": read_obj}


def read_mesh(path, field: str = "") -> MeshData:
    """Read a mesh file, choosing the reader from the extension (.ply, .obj)."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    reader = _READERS.get(ext)
    if reader is None:
        raise _err(field, path, f"unsupported mesh format '{ext or '(no extension)'}' "
                                f"(supported: {', '.join(sorted(_READERS))})")
    return reader(path, field)
