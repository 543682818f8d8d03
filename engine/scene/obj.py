"""Wavefront OBJ meshes: ``read_obj(path, field="") -> MeshData``.

* Supported statements: ``v`` (extra components such as ``w`` or vertex
  colours are ignored), ``vn``, ``f`` with corners ``v``, ``v/vt``,
  ``v//vn``, ``v/vt/vn`` (negative = relative to the data defined so far),
  ``vt`` (u, v; a third component is ignored), ``usemtl``.  ``o``, ``g``,
  ``s``, ``mtllib``, ``l``, ``p`` and unknown statements are ignored.  Text
  after ``#`` is a comment.
* Texture coordinates (``MeshData.uv``, v up as Blender's UV space) are
  per corner in OBJ: a vertex whose corners refer to different (u, v)
  values is split, the value of its first such corner keeping the vertex
  and each further value appended as a new vertex after all others
  (``trimesh.split_vertices``), so a file whose vertices each have one UV
  keeps its vertex numbering.  Corners without ``vt`` do not split a vertex
  and vertices only they use get (0, 0).  ``uv`` is None when no corner
  refers to a ``vt``.
* Numbers must be numbers: ``v 0 0 true`` or ``f 1 2 x`` is an error naming
  the line; an index that does not fit a 64-bit integer is out of range.
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
  (``usemtl`` names in order of first appearance); ``group_names`` is empty
  and ``face_groups`` is ``None`` when the file has no ``usemtl`` at all.
* Faces before the first ``usemtl`` of a file that has ``usemtl``
  statements get group -1, and ``MeshData.ungrouped_line`` is the line of
  the first such face.  Decision (issue 13): they are not silently given a
  material.  A scene that maps ``usemtl`` names to materials cannot place
  them, so the loader should reject the file naming that OBJ line (add a
  ``usemtl`` before it, or give the object a single ``material``); reading
  the file itself succeeds, because a single material covers every face.
"""
from __future__ import annotations

import numpy as np

from .trimesh import (MeshData, check_corner_counts, check_finite, compute_vertex_normals,
                      fan_triangulate, mesh_file_error, open_mesh_file, split_vertices)

__all__ = ["read_obj"]

_WS = (" ", "\t")
_INT64_MAX = np.iinfo(np.int64).max
_PLURAL = {"vertex": "vertices", "normal": "normals", "texture coordinate": "texture coordinates"}


class _Statements:
    """The ``v``, ``vn``, ``f`` and ``usemtl`` statements of a file, as text."""

    def __init__(self):
        self.v, self.v_lines = [], []
        self.vn, self.vn_lines = [], []
        self.vt, self.vt_lines = [], []
        self.corners: list[str] = []
        # per face: corner count, file line, #v, #vn and #vt defined before it, group
        self.f_counts, self.f_lines, self.f_nv, self.f_nvn, self.f_group = [], [], [], [], []
        self.f_nvt = []
        self.group_names: list[str] = []
        self._group_of: dict[str, int] = {}
        self._current = -1            # group of the faces that follow; -1 before any usemtl

    def add_face(self, corners, lineno):
        self.corners.extend(corners)
        self.f_counts.append(len(corners))
        self.f_lines.append(lineno)
        self.f_nv.append(len(self.v))
        self.f_nvn.append(len(self.vn))
        self.f_nvt.append(len(self.vt))
        self.f_group.append(self._current)

    def use_material(self, name):
        if name not in self._group_of:
            self._group_of[name] = len(self.group_names)
            self.group_names.append(name)
        self._current = self._group_of[name]


def _scan(text: str) -> _Statements:
    """One pass over the lines; cheap prefix tests keep this fast for big files."""
    st = _Statements()
    for lineno, line in enumerate(text.splitlines(), start=1):
        if "#" in line:
            line = line.split("#", 1)[0]
        if line[:1] in _WS:
            line = line.lstrip()
        c0, c1 = line[:1], line[1:2]
        if c0 == "v" and c1 in _WS:
            st.v.append(line[2:])
            st.v_lines.append(lineno)
        elif c0 == "v" and c1 == "n" and line[2:3] in _WS:
            st.vn.append(line[3:])
            st.vn_lines.append(lineno)
        elif c0 == "v" and c1 == "t" and line[2:3] in _WS:
            st.vt.append(line[3:])
            st.vt_lines.append(lineno)
        elif c0 == "f" and c1 in _WS:
            st.add_face(line[2:].split(), lineno)
        elif c0 == "u" and line.startswith("usemtl") and line[6:7] in _WS:
            st.use_material(line[7:].strip())
        # everything else (o, g, s, mtllib, l, p, ...) is ignored
    return st


def _vectors(strs, lines, what, field, path, width=3) -> np.ndarray:
    """First ``width`` numbers of each statement -> (n, width) float64."""
    toks = " ".join(strs).split()
    if len(toks) == width * len(strs):
        try:
            return np.array(toks, dtype=np.float64).reshape(-1, width)
        except ValueError:
            pass
    rows = [s.split()[:width] for s in strs]   # extra components (w, colour) ignored
    for row, line in zip(rows, lines):
        if len(row) != width:
            raise mesh_file_error(field, path, f"line {line}: '{what}' needs {width} numbers")
        bad = next((t for t in row if not _is_float(t)), None)
        if bad is not None:
            raise mesh_file_error(field, path, f"line {line}: non-numeric '{what}' value "
                                               f"{' '.join(row)!r}")
    return np.array(rows, dtype=np.float64).reshape(-1, width)


def _is_float(tok) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def _corners_uniform(corners):
    """Bulk-parse face corners when all share one form (v, v//vn or v/vt/vn).

    Returns (vertex idx, normal idx or None, has-normal mask or bool) or None
    when the corners are mixed or not all plain integers (``_corners_mixed``
    then parses them one by one and names any bad corner).
    """
    n = len(corners)
    s = " ".join(corners)
    slashes = s.count("/")
    try:
        if slashes == 0:
            toks = s.split()
            if len(toks) == n:
                return np.array(toks, dtype=np.int64), None, False
        elif slashes == 2 * n and s.count("//") == n:          # v//vn
            toks = s.replace("//", " ").split()
            if len(toks) == 2 * n:
                a = np.array(toks, dtype=np.int64).reshape(n, 2)
                return a[:, 0], a[:, 1], True
        elif slashes == 2 * n and "//" not in s:                # v/vt/vn
            toks = s.replace("/", " ").split()
            if len(toks) == 3 * n:
                a = np.array(toks, dtype=np.int64).reshape(n, 3)
                return a[:, 0], a[:, 2], True
    except (ValueError, OverflowError):
        return None
    return None


def _corners_mixed(corners, corner_line, field, path):
    """Per-corner parsing for mixed forms, with precise error messages."""
    parts = [c.split("/") for c in corners]
    bad = next((k for k, p in enumerate(parts) if len(p) > 3 or not p[0]), None)
    if bad is not None:
        raise mesh_file_error(field, path, f"line {corner_line(bad)}: malformed face corner "
                                           f"'{corners[bad]}'")
    has_vn = np.fromiter((len(p) == 3 and p[2] != "" for p in parts), dtype=bool, count=len(parts))
    vi = _indices([p[0] for p in parts], "vertex", corner_line, field, path)
    ni = np.zeros(len(parts), dtype=np.int64)
    idx = np.flatnonzero(has_vn)
    if idx.size:
        ni[idx] = _indices([parts[k][2] for k in idx], "normal",
                           lambda k: corner_line(int(idx[k])), field, path)
    return vi, ni, has_vn


def _indices(strs, what, line_of, field, path) -> np.ndarray:
    """Index strings -> int64; a non-integer or one beyond int64 names its line."""
    try:
        return np.array(strs, dtype=np.int64)
    except (ValueError, OverflowError):
        pass
    for k, s in enumerate(strs):
        try:
            value = int(s)
        except ValueError:
            raise mesh_file_error(field, path, f"line {line_of(k)}: bad {what} index '{s}' in "
                                               "face corner (not an integer)") from None
        if abs(value) > _INT64_MAX:
            raise mesh_file_error(field, path, f"line {line_of(k)}: {what} index {s} is out of "
                                               "range (it does not even fit a 64-bit integer)")
    raise AssertionError("unreachable: numpy rejected indices that Python accepts")


def _resolve(raw, base, total, what, corner_line, field, path):
    """1-based / negative OBJ indices -> 0-based, range checked."""
    out = np.where(raw > 0, raw - 1, base + raw)
    bad = (raw == 0) | (out < 0) | (out >= total)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        relative = f", {int(base[k])} before this line" if raw[k] < 0 else ""
        raise mesh_file_error(field, path, f"line {corner_line(k)}: {what} index {int(raw[k])} "
                                           f"is out of range ({total} {_PLURAL[what]} defined"
                                           f"{relative})")
    return out


def _texcoord_corners(corners, corner_line, field, path):
    """(raw vt index per corner, has-vt mask): the second field of ``v/vt`` and ``v/vt/vn``."""
    n = len(corners)
    s = " ".join(corners)
    if "//" not in s and s.count("/") in (n, 2 * n):     # uniform v/vt or v/vt/vn: in bulk
        width = s.count("/") // n + 1
        toks = s.replace("/", " ").split()
        if len(toks) == width * n:
            try:
                return np.array(toks, dtype=np.int64).reshape(n, width)[:, 1], np.ones(n, bool)
            except (ValueError, OverflowError):
                pass
    parts = [c.split("/") for c in corners]
    has = np.fromiter((len(p) >= 2 and p[1] != "" for p in parts), dtype=bool, count=n)
    raw = np.zeros(n, dtype=np.int64)
    idx = np.flatnonzero(has)
    if idx.size:
        raw[idx] = _indices([parts[k][1] for k in idx], "texture coordinate",
                            lambda k: corner_line(int(idx[k])), field, path)
    return raw, has


def _uv_split(verts, normals, corner_vertex, vt, ti):
    """Split vertices by their corners' (u, v) values (see the module docstring)."""
    _, canon = np.unique(vt, axis=0, return_inverse=True)       # equal values: one key
    canon = canon.reshape(-1)
    has = ti >= 0
    key = np.where(has, canon[np.where(has, ti, 0)], 0)
    corners, source, first_corner = split_vertices(corner_vertex, key, len(verts), keyed=has)
    uv = np.zeros((source.size, 2))
    used = first_corner >= 0
    uv[used] = vt[ti[first_corner[used]]]
    return verts[source], None if normals is None else normals[source], corners, uv


def _split_by_normal(verts, vnorm, vi, ni, counts):
    """One output vertex per distinct (position, normal) pair; ni = -1: no normal."""
    stride = len(vnorm) + 1
    ukey, inv = np.unique(vi * stride + (ni + 1), return_inverse=True)
    new_v = verts[ukey // stride]
    uni = ukey % stride - 1
    tris, poly = fan_triangulate(inv.reshape(-1), counts)
    normals = np.zeros_like(new_v)
    have = uni >= 0
    normals[have] = vnorm[uni[have]]
    length = np.sqrt(np.einsum("ij,ij->i", normals, normals))
    need = length == 0            # no normal, or a zero-length one from the file
    normals[~need] /= length[~need, None]
    if need.any():
        normals[need] = compute_vertex_normals(new_v, tris)[need]
    return new_v, tris, poly, normals, inv.reshape(-1)


def read_obj(path, field: str = "") -> MeshData:
    """Read a Wavefront OBJ mesh (see the module docstring for the rules)."""
    with open_mesh_file(path, field) as fh:
        text = fh.read().decode("utf-8", errors="replace")
    st = _scan(text)
    if not st.f_counts:
        raise mesh_file_error(field, path, "mesh has zero faces (no 'f' statements)")
    verts = _vectors(st.v, st.v_lines, "v", field, path)
    check_finite(verts, field, path, "vertex", st.v_lines)
    vnorm = _vectors(st.vn, st.vn_lines, "vn", field, path) if st.vn else np.zeros((0, 3))
    check_finite(vnorm, field, path, "normal", st.vn_lines)
    counts = np.array(st.f_counts, dtype=np.int64)
    check_corner_counts(counts, field, path, lines=st.f_lines)
    face_end = np.cumsum(counts)

    def corner_line(k):
        return st.f_lines[int(np.searchsorted(face_end, k, side="right"))]

    parsed = _corners_uniform(st.corners) or _corners_mixed(st.corners, corner_line, field, path)
    vi_raw, ni_raw, has_vn = parsed
    vi = _resolve(vi_raw, np.repeat(np.array(st.f_nv, dtype=np.int64), counts), len(st.v),
                  "vertex", corner_line, field, path)
    if has_vn is False or (has_vn is not True and not has_vn.any()):
        tris, poly = fan_triangulate(vi, counts)
        verts_out, normals, corner_vertex = verts, None, vi
    else:
        mask = np.ones(len(vi), bool) if has_vn is True else has_vn
        idx = np.flatnonzero(mask)
        ni = np.full(len(vi), -1, dtype=np.int64)
        base_n = np.repeat(np.array(st.f_nvn, dtype=np.int64), counts)
        ni[idx] = _resolve(ni_raw[idx], base_n[idx], len(st.vn), "normal",
                           lambda k: corner_line(int(idx[k])), field, path)
        verts_out, tris, poly, normals, corner_vertex = _split_by_normal(verts, vnorm, vi, ni, counts)
    uv = None
    if st.vt:
        ti_raw, has_vt = _texcoord_corners(st.corners, corner_line, field, path)
        if has_vt.any():
            vt = _vectors([t if len(t.split()) != 1 else t + " 0" for t in st.vt],   # "vt u": v = 0
                          st.vt_lines, "vt", field, path, width=2)
            bad = ~np.isfinite(vt).all(axis=1)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise mesh_file_error(field, path, f"texture coordinate {i} (line {st.vt_lines[i]}) is not "
                                                   f"finite: {vt[i].tolist()}")
            idx = np.flatnonzero(has_vt)
            ti = np.full(len(vi), -1, dtype=np.int64)
            base_t = np.repeat(np.array(st.f_nvt, dtype=np.int64), counts)
            ti[idx] = _resolve(ti_raw[idx], base_t[idx], len(st.vt), "texture coordinate",
                               lambda k: corner_line(int(idx[k])), field, path)
            verts_out, normals, corner_vertex, uv = _uv_split(verts_out, normals, corner_vertex, vt, ti)
            tris, _ = fan_triangulate(corner_vertex, counts)
    if not st.group_names:
        return MeshData(verts_out, tris, normals, uv=uv)
    face_group = np.array(st.f_group, dtype=np.int64)
    ungrouped = np.flatnonzero(face_group < 0)
    return MeshData(verts_out, tris, normals, face_group[poly], st.group_names,
                    st.f_lines[int(ungrouped[0])] if ungrouped.size else None, uv)
