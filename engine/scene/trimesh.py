"""Triangle meshes in memory, and the checks every mesh-file reader shares.

``MeshData``                      vertices / faces / optional normals and groups
``face_normals(vertices, faces)`` unnormalised geometric normals (p1-p0)x(p2-p0)
``triangle_areas(vertices, faces)``
``compute_vertex_normals(vertices, faces)`` area-weighted unit vertex normals
``split_vertices(corner_vertex, corner_key, n_vertices, keyed=None)`` one vertex per (vertex, key)

Conventions
-----------
* Faces are triangles, counter-clockwise seen from the front: the geometric
  normal ``(p1 - p0) x (p2 - p0)`` points to the front side.
* Polygons with more than three corners are triangulated as fans
  ``(c0, c1, c2), (c0, c2, c3), ...`` (exact for convex planar polygons).
* ``vertex_normals`` are unit length.  Normals that are present in a file
  are normalised; zero-length normals from a file (some exporters write
  zeros) are replaced by area-weighted normals computed from the faces.
* Every problem with a mesh file raises ``SceneError(field, message)`` whose
  message names the file and what is wrong (``mesh_file_error``).

The file readers live in ``ply.py`` and ``obj.py``; ``meshio.read_mesh``
chooses one from the extension.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field as dc_field

import numpy as np

from ..errors import SceneError

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
    ungrouped_line  OBJ only: file line of the first face that comes before
                    every ``usemtl`` when the file has ``usemtl`` statements
                    (such faces have group -1), else None
    uv              float64 (V, 2) texture coordinates per vertex, or None
    colors          {attribute name: float64 (V, 3 or 4)} linear colours in [0, 1]
    """

    vertices: np.ndarray
    faces: np.ndarray
    vertex_normals: np.ndarray | None = None
    face_groups: np.ndarray | None = None
    group_names: list = dc_field(default_factory=list)
    ungrouped_line: int | None = None
    uv: np.ndarray | None = None
    colors: dict = dc_field(default_factory=dict)

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
        if self.uv is not None:
            self.uv = np.ascontiguousarray(self.uv, dtype=np.float64).reshape(-1, 2)
            if self.uv.shape[0] != self.vertices.shape[0]:
                raise ValueError("uv must have one row per vertex")
        self.colors = {name: np.ascontiguousarray(c, dtype=np.float64) for name, c in self.colors.items()}
        if any(c.ndim != 2 or c.shape[0] != self.vertices.shape[0] or c.shape[1] not in (3, 4)
               for c in self.colors.values()):
            raise ValueError("colors must hold one [r, g, b] or [r, g, b, a] row per vertex")

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


def split_vertices(corner_vertex, corner_key, n_vertices: int, keyed=None):
    """Split vertices whose corners carry different keys (per-corner UVs: OBJ ``vt``, a sphere's seam).

    ``corner_vertex`` (C,) vertex of each face corner, ``corner_key`` (C,) integer key of its
    attribute, ``keyed`` (C,) bool: corners with a key (default all; the others keep their vertex).
    A vertex keeps its index for the key of its first keyed corner (in corner order); each further
    key becomes a new vertex appended after the ``n_vertices`` (in order of first use), so faces
    and the existing vertex numbering stay as they are.  Returns (new corner vertices (C,),
    source vertex of every output vertex (V',), first keyed corner of every output vertex (V',),
    -1 where none).
    """
    cv = np.asarray(corner_vertex, dtype=np.int64)
    key = np.asarray(corner_key, dtype=np.int64)
    idx = np.arange(cv.size) if keyed is None else np.flatnonzero(keyed)
    out = cv.copy()
    if idx.size == 0:
        return out, np.arange(n_vertices), np.full(n_vertices, -1, np.int64)
    pair = cv[idx] * (int(key[idx].max()) + 1) + key[idx]
    _, first, inv = np.unique(pair, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")                     # (vertex, key) pairs by first use
    pair_corner = idx[first[order]]
    pair_vertex = cv[pair_corner]
    primary = np.zeros(order.size, bool)
    primary[np.unique(pair_vertex, return_index=True)[1]] = True
    index = np.where(primary, pair_vertex, 0)
    index[~primary] = n_vertices + np.arange(int((~primary).sum()))
    pair_out = np.empty_like(index)
    pair_out[order] = index
    out[idx] = pair_out[inv.reshape(-1)]
    source = np.concatenate([np.arange(n_vertices), pair_vertex[~primary]])
    first_corner = np.full(source.size, -1, np.int64)
    first_corner[index] = pair_corner
    return out, source, first_corner


def _normalise_or_default(n: np.ndarray) -> np.ndarray:
    length = np.sqrt(np.einsum("ij,ij->i", n, n))
    ok = length > 0
    out = np.zeros_like(n)
    out[ok] = n[ok] / length[ok, None]
    out[~ok] = (0.0, 0.0, 1.0)
    return out


# ---------------------------------------------------------------------------
# checks shared by the file readers (one copy for PLY and OBJ)


def mesh_file_error(field: str, path, what: str) -> SceneError:
    """The one error shape of the readers: ``field: mesh file 'path': what``."""
    return SceneError(field, f"mesh file '{os.fspath(path)}': {what}")


def open_mesh_file(path, field: str):
    """Open ``path`` for binary reading; missing files and folders are SceneErrors."""
    p = os.fspath(path)
    if not os.path.exists(p):
        raise mesh_file_error(field, p, "file not found")
    if os.path.isdir(p):
        raise mesh_file_error(field, p, "is a directory, not a mesh file")
    try:
        return open(p, "rb")
    except OSError as e:
        raise mesh_file_error(field, p, f"cannot be read ({e.strerror or e})") from None


def fan_triangulate(flat: np.ndarray, counts: np.ndarray):
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


def _where(what, i, lines):
    return f"{what} {i}" + (f" (line {lines[i]})" if lines is not None else "")


def check_corner_counts(counts: np.ndarray, field, path, lines=None):
    """Every polygon needs >= 3 corners; ``lines`` (optional) maps face -> file line."""
    bad = np.flatnonzero(counts < 3)
    if bad.size:
        i = int(bad[0])
        raise mesh_file_error(field, path, f"{_where('face', i, lines)} has {int(counts[i])} "
                                           "corner(s); a face needs at least 3")


def check_finite(arr: np.ndarray, field, path, what: str, lines=None):
    """Every row of ``arr`` (n, 3) must be finite."""
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise mesh_file_error(field, path, f"{_where(what, i, lines)} is not finite: "
                                           f"{arr[i].tolist()}")
