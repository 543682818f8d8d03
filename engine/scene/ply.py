"""PLY meshes (ASCII, binary little/big endian): ``read_ply(path, field="") -> MeshData``.

The file is parsed by plyfile; this module adds what the engine needs on top:

* Vertex element: ``x, y, z`` required; ``nx, ny, nz`` optional (all three);
  texture coordinates optional, the first pair present of ``u, v``, ``s, t``,
  ``texture_u, texture_v``, ``texture_s, texture_t`` (``MeshData.uv``, v up as
  Blender's UV space); vertex colours optional, ``red, green, blue`` (and
  ``alpha``) as the colour attribute ``"Col"`` (the name Blender's PLY importer
  gives it): integer properties are divided by their type's full scale (uchar
  255, ushort 65535, ...), float ones taken as they are, must then lie in
  [0, 1], and red/green/blue are decoded from sRGB to linear (the default of
  Blender's importer), alpha stays linear.  Any other properties and any
  numeric types are accepted (others skipped).
  Face element: list property ``vertex_indices`` (or ``vertex_index``) with
  an integer type; polygons are fan-triangulated.  Other elements are read
  (they must be well formed) and ignored.
* Accepted beyond the PLY standard: ``int64`` / ``uint64`` properties and
  list counts (some exporters write them), blank or non-ASCII header lines,
  CR / CRLF line ends.
* ASCII data is text, so its values are read as float64 and its list
  lengths as int64 whatever width the header declares (a narrower type would
  wrap "300" in a uchar to 44 on numpy 1.x, and plyfile would truncate "2.5"
  in an integer list to 2); vertex indices must then be whole numbers.
  ASCII rows are one per line, as the PLY standard says; list lengths must
  be written as integers ("3", not "3.0"); booleans or words are rejected.
* Every problem is a ``SceneError`` naming the file, the element and row or
  header line, and the reason (``_explain`` maps plyfile's exceptions).
* Speed: binary files whose faces all have 3 (or all 4) corners are memory
  mapped (1M triangles in about 0.1 s); with mixed polygon sizes plyfile
  reads row by row in Python (about 6 us a face: 4 s for 1M triangles as
  2/3 M tris and quads, where the reader before plyfile took 0.5 s); ASCII is
  parsed in Python too (about 1 s per 100k faces).

plyfile is imported on first use: the Blender extension never reads mesh
files (its exporter hands meshes over as arrays) and so ships without it.
"""
from __future__ import annotations

import io
import re
import shutil
import tempfile

import numpy as np

from ..textures.image import srgb_to_linear
from .trimesh import (MeshData, check_corner_counts, check_finite, compute_vertex_normals,
                      fan_triangulate, mesh_file_error, open_mesh_file)

__all__ = ["read_ply"]

_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
_INT_TYPES = {"char": 1, "int8": 1, "uchar": 1, "uint8": 1, "short": 2, "int16": 2,
              "ushort": 2, "uint16": 2, "int": 4, "int32": 4, "uint": 4, "uint32": 4,
              "int64": 8, "uint64": 8}
_FLOAT_TYPES = {"float": 4, "float32": 4, "double": 8, "float64": 8}
_HEADER_END = re.compile(rb"(?:\r\n|\r|\n)end_header[ \t]*(\r\n|\r|\n)")
_INDEX_NAMES = ("vertex_indices", "vertex_index")
_UV_NAMES = (("u", "v"), ("s", "t"), ("texture_u", "texture_v"), ("texture_s", "texture_t"))
_COLOUR_NAMES = ("red", "green", "blue", "alpha")
#: the colour attribute's name (Blender's PLY importer calls it "Col")
COLOUR_ATTRIBUTE = "Col"


def _plyfile(field, path):
    try:
        import plyfile
    except ImportError:
        raise mesh_file_error(field, path, "reading PLY files needs the 'plyfile' package "
                                           "(pip install plyfile)") from None
    # plyfile knows the eight standard types only.  Some exporters write int64 /
    # uint64 (this engine read them before plyfile), so add them to plyfile's type
    # tables (private, unchanged since plyfile 0.4; entries are only added).  Should
    # the tables move, such files get "unsupported property" and the rest still reads.
    types, names = getattr(plyfile, "_data_types", {}), getattr(plyfile, "_data_type_reverse", {})
    for name, code in (("int64", "i8"), ("uint64", "u8")):
        types.setdefault(name, code)
        names.setdefault(code, name)
    return plyfile


# ---------------------------------------------------------------------------
# header: located and normalised here, parsed by plyfile


class _Header:
    """The header as written (``lines``) and as handed to plyfile (``text``).

    ``elements``: (name, count, smallest row size in bytes) for the size
    check before plyfile allocates anything; ``line_of`` maps a line of
    ``text`` (1-based) to the line of the file.
    """

    def __init__(self, raw: bytes, body: int):
        self.body = body
        self.lines = raw.decode("ascii", errors="replace").splitlines()
        self.fmt = next((t[1] for t in map(str.split, self.lines)
                         if len(t) > 1 and t[0] == "format"), None)
        self.elements = []
        self.declared = {}             # (element, property) -> value type as written
        kept, self.line_of = [], [1]
        for lineno, line in enumerate(self.lines[1:], start=2):
            tok = line.split()
            if not tok:
                continue           # blank header lines: tolerated, plyfile 1.0 rejects them
            if tok[0] == "element" and len(tok) == 3 and tok[2].isdigit():
                self.elements.append([tok[1], int(tok[2]), 0])
            elif tok[0] == "property" and self.elements:
                tok = self._property(tok)
            kept.append(" ".join(tok).encode("ascii", errors="replace").decode("ascii"))
            self.line_of.append(lineno)
        self.text = "\n".join(["ply"] + kept + ["end_header"]) + "\n"
        self.line_of.append(len(self.lines) + 1)

    def _property(self, tok):
        """Account the row size; for ASCII widen the types (see module docstring)."""
        is_list = tok[1:2] == ["list"]
        if len(tok) != (5 if is_list else 3):
            return tok                 # malformed: left for plyfile to report
        types = tok[2:4] if is_list else tok[1:2]
        ascii_ = self.fmt == "ascii"
        size = _INT_TYPES.get(types[0], _FLOAT_TYPES.get(types[0]))
        if size is None or self.elements[-1][2] is None:
            self.elements[-1][2] = None  # unknown type: plyfile names it, no size check
        else:
            self.elements[-1][2] += 2 if ascii_ else size  # ASCII: a digit and a separator
        self.declared[(self.elements[-1][0], tok[-1])] = types[-1]
        if ascii_ and all(t in _INT_TYPES or t in _FLOAT_TYPES for t in types):
            tok = tok[:-1 - len(types)] + (["int64"] if is_list else []) + ["double", tok[-1]]
        return tok

    def check(self, size, field, path):
        """Problems plyfile would not name (or would hit only after allocating)."""
        if self.fmt is None:
            raise mesh_file_error(field, path, "PLY header has no 'format' line")
        for lineno, line in enumerate(self.lines[1:], start=2):
            tok = line.split()
            if tok[:1] == ["element"] and (len(tok) != 3 or not tok[2].isdigit()):
                raise mesh_file_error(field, path, f"malformed element or bad element count on "
                                                   f"header line {lineno}: '{line.strip()}'")
            if tok[:1] == ["format"] and (len(tok) < 2 or tok[1] not in _FORMATS):
                raise mesh_file_error(field, path, f"unsupported PLY format on header line "
                                                   f"{lineno}: '{line.strip()}' (supported: "
                                                   f"{', '.join(_FORMATS)})")
            if tok[:2] == ["property", "list"] and len(tok) == 5 and tok[2] in _FLOAT_TYPES:
                raise mesh_file_error(field, path, f"list count type must be an integer type "
                                                   f"(header line {lineno})")
        left = size - self.body
        for name, count, row in self.elements:
            if row is None:
                break
            if count * row > left:
                raise mesh_file_error(field, path, f"truncated data in element '{name}' "
                                                   f"({count} rows): needs at least {count * row}"
                                                   f" bytes, only {max(left, 0)} left in the file")
            left -= count * row


def _read_header(fh, field, path) -> _Header:
    buf = fh.read(65536)
    if not (buf[:3] == b"ply" and buf[3:4] in (b"\n", b"\r")):
        raise mesh_file_error(field, path, "not a PLY file (it does not start with 'ply')")
    while True:
        m = _HEADER_END.search(buf)
        chunk = b"" if m else fh.read(1 << 20)
        if m or not chunk:
            break
        buf += chunk
    if m is None and buf.rstrip(b" \t").endswith(b"end_header"):   # no data after it
        return _Header(buf[:buf.rstrip(b" \t").rfind(b"end_header")], len(buf))
    if m is None:
        raise mesh_file_error(field, path, "PLY header has no 'end_header' line")
    return _Header(buf[:m.start()], m.end())


# ---------------------------------------------------------------------------
# data


def _parse(plyfile, fh, header: _Header):
    """plyfile.PlyData of the whole file.

    plyfile memory-maps binary elements only from a real file (from any other
    stream it reads row by row, property by property), so a binary file whose
    header had to be normalised is copied with the new header into a
    temporary file.  ASCII is read from memory.
    """
    fh.seek(0)
    head = fh.read(header.body)
    text = header.text.encode("ascii")
    if header.fmt == "ascii":         # odd bytes become '?', reported as non-numeric
        body = fh.read().decode("ascii", errors="replace").encode("ascii", errors="replace")
        return _read_guessing(plyfile, io.BytesIO(text + body), guesses=(None,))
    if head == text:
        return _read_guessing(plyfile, fh, guesses=(3, 4, None))
    with tempfile.TemporaryFile() as tmp:
        tmp.write(text)
        shutil.copyfileobj(fh, tmp)
        return _read_guessing(plyfile, tmp, guesses=(3, 4, None))


def _read_guessing(plyfile, stream, guesses):
    """plyfile memory-maps a list only when told its fixed length: try the usual ones."""
    for corners in guesses:
        stream.seek(0)
        known = {"face": {n: corners for n in _INDEX_NAMES}} if corners else {}
        try:
            return plyfile.PlyData.read(stream, known_list_len=known)
        except plyfile.PlyElementParseError as e:
            # a wrong guess shows as another length or as too few bytes
            if not (corners and e.message in ("unexpected list length", "early end-of-file")):
                raise


_ROW_REASONS = {
    "malformed input": "a value is not a number of the property's type (list lengths must be "
                       "integers >= 0)",
    "early end-of-line": "the row has fewer values than the header and its list lengths declare",
    "expected end-of-line": "the row has more values than the header declares",
}


def _explain(e, header: _Header, text_lines, field, path):
    """A plyfile exception -> SceneError naming the header line or element row."""
    if hasattr(e, "element"):
        what = _explain_row(e, header, text_lines)
    elif hasattr(e, "line"):
        what = _explain_header_line(e, header)
    else:
        what = f"cannot be read as PLY ({type(e).__name__}: {e})"
    return mesh_file_error(field, path, what)


def _explain_header_line(e, header: _Header) -> str:
    lineno = header.line_of[min(e.line or 1, len(header.line_of)) - 1]
    line = header.lines[lineno - 1].strip() if lineno <= len(header.lines) else "end_header"
    if "field type" in e.message:
        return f"malformed or unsupported property on header line {lineno}: '{line}'"
    return f"bad PLY header line {lineno} '{line}': {e.message}"


def _explain_row(e, header: _Header, text_lines) -> str:
    name, row, count = e.element.name, e.row, e.element.count
    if e.message == "early end-of-file" and text_lines is not None:
        return (f"ASCII data ends early: element '{name}' declares {count} rows but only {row} "
                "row(s) are present")
    if e.message == "early end-of-file":
        return (f"truncated binary data in element '{name}' ({count} rows): the data ends inside "
                f"row {row}")
    where = f"element '{name}' row {row}"
    if text_lines is not None:      # ASCII: one row per line after the header
        names = [el[0] for el in header.elements]
        k = sum(el[1] for el in header.elements[:names.index(name)]) + row
        line = text_lines[k] if k < len(text_lines) else ""
        where += f" (line {len(header.lines) + 2 + k}: '{line.strip()[:60]}')"
        word = next((t for t in line.split() if not _is_number(t)), None)
        if e.message == "malformed input" and word is not None:
            return f"non-numeric value '{word}' in {where}"
    prop = f", property '{e.prop.name}'" if e.prop is not None else ""
    return f"{where}{prop}: {_ROW_REASONS.get(e.message, e.message)}"


def _is_number(tok) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def _list_column(col):
    """A plyfile list column -> (flat values, counts)."""
    if col.dtype != object:            # memory-mapped: (n, corners)
        return col.reshape(-1), np.full(len(col), col.shape[1], np.int64)
    counts = np.fromiter(map(len, col), dtype=np.int64, count=len(col))
    flat = np.concatenate(col) if len(col) else np.zeros(0, np.int64)
    return flat, counts


def _mesh_elements(ply, header, field, path):
    """Check the structure; returns (vertex data, face index property name, has normals)."""
    names = [e.name for e in ply.elements]
    for name, what in (("vertex", "'vertex' element"), ("face", "'face' element (zero faces)")):
        if name not in names:
            raise mesh_file_error(field, path, f"PLY file has no {what}")
    vprops = {p.name: p for p in ply["vertex"].properties}
    for c in ("x", "y", "z"):
        if c not in vprops:
            raise mesh_file_error(field, path, f"vertex element has no '{c}' property")
        if hasattr(vprops[c], "len_dtype"):      # a plyfile list property
            raise mesh_file_error(field, path, f"vertex property '{c}' must not be a list")
    index = _face_index_property(ply["face"], header, field, path)
    for name, what in (("face", "faces"), ("vertex", "vertices")):
        if ply[name].count == 0:
            raise mesh_file_error(field, path, f"mesh has zero {what}")
    has_normals = all(c in vprops and not hasattr(vprops[c], "len_dtype")
                      for c in ("nx", "ny", "nz"))
    return ply["vertex"].data, index, has_normals


def _face_index_property(fe, header, field, path) -> str:
    index = next((p for p in fe.properties if p.name in _INDEX_NAMES), None)
    if index is None or not hasattr(index, "len_dtype"):
        raise mesh_file_error(field, path, "face element has no list property 'vertex_indices' "
                                           "(or 'vertex_index')")
    if header.declared.get(("face", index.name)) in _FLOAT_TYPES:
        raise mesh_file_error(field, path, "face vertex indices must have an integer type")
    return index.name


def _vertex_indices(flat, counts, nv, field, path) -> np.ndarray:
    """Checked int64 indices from the parsed values (ASCII ones are float64)."""
    def fail(k, what):
        face = int(np.searchsorted(np.cumsum(counts), k, side="right"))
        raise mesh_file_error(field, path, f"face {face} {what}")

    if flat.dtype.kind == "f":
        bad = np.flatnonzero(~np.isfinite(flat) | (flat != np.round(flat)))
        if bad.size:
            fail(int(bad[0]), f"has a non-integer vertex index {float(flat[bad[0]])!r}")
    bad = np.flatnonzero((flat < 0) | (flat >= nv))
    if bad.size:
        fail(int(bad[0]), f"references vertex index {int(flat[bad[0]])}, out of range for "
                          f"{nv} vertices")
    return flat.astype(np.int64)


def _unit_normals(normals, vertices, faces, field, path):
    """Normalise file normals; zero-length ones are recomputed from the faces."""
    check_finite(normals, field, path, "vertex normal")
    length = np.sqrt(np.einsum("ij,ij->i", normals, normals))
    zero = length == 0
    out = np.empty_like(normals)
    out[~zero] = normals[~zero] / length[~zero, None]
    if zero.any():
        out[zero] = compute_vertex_normals(vertices, faces)[zero]
    return out


def _scalar(vprops, name) -> bool:
    return name in vprops and not hasattr(vprops[name], "len_dtype")


def _vertex_uv(vd, vprops, field, path):
    """The first texture-coordinate pair present (see the module docstring), or None."""
    pair = next((p for p in _UV_NAMES if _scalar(vprops, p[0]) and _scalar(vprops, p[1])), None)
    if pair is None:
        return None
    uv = np.stack([vd[c] for c in pair], axis=1).astype(np.float64)
    bad = ~np.isfinite(uv).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise mesh_file_error(field, path, f"vertex {i} has non-finite texture coordinates "
                                           f"({pair[0]}, {pair[1]}) = {uv[i].tolist()}")
    return uv


def _full_scale(declared: str | None) -> float:
    """An integer colour type's full scale (uchar 255, ushort 65535, ...); 1 for floats."""
    size = _INT_TYPES.get(declared or "")
    if size is None:
        return 1.0
    signed = declared in ("char", "int8", "short", "int16", "int", "int32", "int64")
    return float(2 ** (8 * size - (1 if signed else 0)) - 1)


def _vertex_colours(vd, vprops, header, field, path) -> dict:
    """{"Col": linear (V, 3 or 4)} from red/green/blue(/alpha), or {} (see the module docstring)."""
    if not all(_scalar(vprops, c) for c in _COLOUR_NAMES[:3]):
        return {}
    names = _COLOUR_NAMES[:4] if _scalar(vprops, "alpha") else _COLOUR_NAMES[:3]
    cols = np.stack([vd[c].astype(np.float64) / _full_scale(header.declared.get(("vertex", c)))
                     for c in names], axis=1)
    bad = ~(np.isfinite(cols) & (cols >= 0) & (cols <= 1)).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise mesh_file_error(field, path, f"vertex {i} has a colour outside [0, 1] (after scaling integer "
                                           f"types by their full scale): {dict(zip(names, cols[i].tolist()))}")
    cols[:, :3] = srgb_to_linear(cols[:, :3])
    return {COLOUR_ATTRIBUTE: cols}


def read_ply(path, field: str = "") -> MeshData:
    """Read a PLY mesh (see the module docstring for what is accepted)."""
    with open_mesh_file(path, field) as fh:
        plyfile = _plyfile(field, path)
        header = _read_header(fh, field, path)
        fh.seek(0, io.SEEK_END)
        header.check(fh.tell(), field, path)
        try:
            ply = _parse(plyfile, fh, header)
        except (plyfile.PlyParseError, ValueError, OverflowError, MemoryError) as e:
            text_lines = None
            if header.fmt == "ascii" and hasattr(e, "element"):
                fh.seek(header.body)
                text_lines = fh.read().decode("ascii", errors="replace").splitlines()
            raise _explain(e, header, text_lines, field, path) from None
    vd, index_name, has_normals = _mesh_elements(ply, header, field, path)
    verts = np.stack([vd[c] for c in "xyz"], axis=1).astype(np.float64)
    check_finite(verts, field, path, "vertex")
    flat, counts = _list_column(ply["face"].data[index_name])
    check_corner_counts(counts, field, path)
    flat = _vertex_indices(flat, counts, verts.shape[0], field, path)
    tris, _ = fan_triangulate(flat, counts)
    normals = None
    if has_normals:
        normals = np.stack([vd[c] for c in ("nx", "ny", "nz")], axis=1).astype(np.float64)
        normals = _unit_normals(normals, verts, tris, field, path)
    vprops = {p.name: p for p in ply["vertex"].properties}
    return MeshData(verts, tris, normals, uv=_vertex_uv(vd, vprops, field, path),
                    colors=_vertex_colours(vd, vprops, header, field, path))
