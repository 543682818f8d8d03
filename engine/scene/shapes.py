"""Built-in shapes and mesh transforms.

Public API
----------
``icosphere(subdivisions, field="", uv=False)``  unit icosphere (pole aligned), optionally UV mapped
``quad(p0, p1, p2, p3, field="")``               flat quad, two triangles
``transform_matrix(translate, scale, rotate_deg, field="")``  4x4 affine matrix
``transform_mesh(mesh, matrix, field="")``       apply a 4x4 affine matrix

All functions are vectorised numpy; invalid input raises ``SceneError``.
"""
from __future__ import annotations

import math
import numbers

import numpy as np

from ..errors import SceneError
from .meshio import MeshData
from .trimesh import split_vertices

__all__ = ["icosphere", "sphere_uv_map", "quad", "transform_matrix", "transform_mesh"]

MAX_SUBDIVISIONS = 9


# ---------------------------------------------------------------------------
# icosphere


def _icosahedron():
    """Regular icosahedron, vertex 0 = (0,0,1), vertex 11 = (0,0,-1).

    Same vertex and face order as shared/peers/meshes/make_icosphere.py.
    """
    s5 = math.sqrt(5.0)
    k = np.arange(5)
    a_up = 2 * np.pi * k / 5
    a_dn = a_up + np.pi / 5
    v = np.empty((12, 3))
    v[0] = (0.0, 0.0, 1.0)
    v[1:6] = np.stack([2 / s5 * np.cos(a_up), 2 / s5 * np.sin(a_up),
                       np.full(5, 1 / s5)], axis=1)
    v[6:11] = np.stack([2 / s5 * np.cos(a_dn), 2 / s5 * np.sin(a_dn),
                        np.full(5, -1 / s5)], axis=1)
    v[11] = (0.0, 0.0, -1.0)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    k1 = (k + 1) % 5
    f = np.stack([
        np.stack([np.zeros(5, int), 1 + k, 1 + k1], 1),      # top cap
        np.stack([1 + k, 6 + k, 1 + k1], 1),                 # upper band
        np.stack([6 + k, 6 + k1, 1 + k1], 1),                # lower band
        np.stack([np.full(5, 11), 6 + k1, 6 + k], 1),        # bottom cap
    ], axis=1).reshape(-1, 3).astype(np.int64)
    # make every face counter-clockwise seen from outside
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    flip = np.einsum("ij,ij->i", n, v[f].mean(axis=1)) < 0
    f[flip] = f[flip][:, [0, 2, 1]]
    return v, f


def _subdivide(v: np.ndarray, f: np.ndarray):
    """Split each triangle (a,b,c) into (a,ab,ca),(ab,b,bc),(ca,bc,c),(ab,bc,ca).

    Edge midpoints are deduplicated; a new midpoint gets the next free index
    in the order its edge is first met (faces in order, edges ab, bc, ca).
    """
    nv = v.shape[0]
    a, b, c = f[:, 0], f[:, 1], f[:, 2]
    e0 = np.stack([a, b, b, c, c, a], axis=1).reshape(-1, 2)   # ab, bc, ca per face
    key = np.minimum(e0[:, 0], e0[:, 1]) * nv + np.maximum(e0[:, 0], e0[:, 1])
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")          # unique edges by first use
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    mid = (nv + rank[inv.reshape(-1)]).reshape(-1, 3)   # ab, bc, ca indices
    fe = e0[first[order]]
    m = v[fe[:, 0]] + v[fe[:, 1]]
    m /= np.sqrt(np.einsum("ij,ij->i", m, m))[:, None]
    ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
    nf = np.stack([a, ab, ca, ab, b, bc, ca, bc, c, ab, bc, ca], axis=1).reshape(-1, 3)
    return np.concatenate([v, m]), nf


def icosphere(subdivisions: int, field: str = "", uv: bool = False) -> MeshData:
    """Unit icosphere centred at the origin, poles on the z axis.

    Level L has 10*4**L + 2 vertices and 20*4**L triangles (L=6: 40,962 and
    81,920), faces counter-clockwise seen from outside, vertex normals equal
    to the vertex positions.  Vertex/face order matches make_icosphere.py.
    ``uv``: add the longitude/latitude map of ``sphere_uv_map`` (extra
    vertices appended at the seam and the poles; faces and the first
    10*4**L + 2 vertices unchanged).
    """
    if (isinstance(subdivisions, bool) or not isinstance(subdivisions, numbers.Integral)
            or not 0 <= int(subdivisions) <= MAX_SUBDIVISIONS):
        raise SceneError(field, f"subdivisions must be an integer from 0 to "
                                f"{MAX_SUBDIVISIONS}, got {subdivisions!r}")
    v, f = _icosahedron()
    for _ in range(int(subdivisions)):
        v, f = _subdivide(v, f)
    v /= np.sqrt(np.einsum("ij,ij->i", v, v))[:, None]
    mesh = MeshData(v, f.astype(np.int32), v.copy())
    return sphere_uv_map(mesh) if uv else mesh


def sphere_uv_map(mesh: MeshData) -> MeshData:
    """The unit sphere ``mesh`` with Blender's UV-sphere map (longitude/latitude).

    u = ½ + atan2(y, x)/2π (u = ½ at +X, ¾ at +Y: increasing counter-clockwise
    seen from +Z, so an image reads left to right seen from outside; the seam
    u = 0 ≡ 1 at −X), v = 1 − acos(z)/π (0 at the south pole −Z, 1 at the
    north pole +Z): an equirectangular image wraps upright, as on Blender's UV
    sphere.  So that no triangle interpolates across the seam, the corners of
    a triangle spanning it (u range > ½) take u + 1 where u < ½, and a pole
    corner takes the mean u of its triangle's other two corners (Blender's
    pinched pole triangles).  Each (vertex, u) pair other than a vertex's
    first one (in face order) becomes a new vertex appended at the end (same
    position and normal); faces keep their order, and their corners their
    positions.
    """
    p = mesh.vertices
    u = 0.5 + np.arctan2(p[:, 1], p[:, 0]) / (2 * np.pi)
    u[(u <= 1e-12) | (u >= 1 - 1e-12)] = 0.0               # the seam meridian: one value, 0
    v = 1.0 - np.arccos(np.clip(p[:, 2], -1.0, 1.0)) / np.pi
    f = mesh.faces.astype(np.int64)
    cu = u[f]
    spans = (cu.max(axis=1) - cu.min(axis=1)) > 0.5
    cu[spans] = np.where(cu[spans] < 0.5, cu[spans] + 1.0, cu[spans])
    pole = np.abs(p[f, 2]) == 1.0
    if pole.any():        # at most one pole per triangle: the mean of the two other corners
        others = (cu.sum(axis=1) - np.where(pole, cu, 0.0).sum(axis=1)) / 2.0
        cu = np.where(pole, others[:, None], cu)
    values, key = np.unique(cu.reshape(-1), return_inverse=True)
    corners, source, first_corner = split_vertices(f.reshape(-1), key.reshape(-1), p.shape[0])
    uv = np.empty((source.size, 2))
    uv[:, 0] = np.where(first_corner >= 0, values[key.reshape(-1)[first_corner]], u[source])
    uv[:, 1] = v[source]
    normals = None if mesh.vertex_normals is None else mesh.vertex_normals[source]
    return MeshData(p[source], corners.reshape(-1, 3), normals, uv=uv)


# ---------------------------------------------------------------------------
# quad


def _point(p, field, name):
    try:
        a = np.asarray(p, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        a = None
    if a is None or a.shape != (3,) or not np.isfinite(a).all():
        raise SceneError(f"{field}.{name}" if field else name,
                         f"must be 3 finite numbers, got {p!r}")
    return a


def quad(p0, p1, p2, p3, field: str = "") -> MeshData:
    """Quad p0-p1-p2-p3 as triangles (p0,p1,p2), (p0,p2,p3); no vertex normals.

    The front side is the one from which p0, p1, p2, p3 appear
    counter-clockwise.  A quad of zero area is an error.
    """
    pts = np.stack([_point(p, field, f"p{i}") for i, p in enumerate((p0, p1, p2, p3))])
    faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
    n = np.cross(pts[1] - pts[0], pts[2] - pts[0]) + np.cross(pts[2] - pts[0],
                                                              pts[3] - pts[0])
    if not np.linalg.norm(n) > 0:
        raise SceneError(field, "quad corners are degenerate (zero area)")
    return MeshData(pts, faces, None)


# ---------------------------------------------------------------------------
# transforms


def _rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]], dtype=np.float64)


def _rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]], dtype=np.float64)


def _rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]], dtype=np.float64)


def _vec3(value, field, name, allow_scalar=False):
    sub = f"{field}.{name}" if field else name
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise SceneError(sub, f"must be 3 numbers, got {value!r}") from None
    if allow_scalar and a.shape == ():
        a = np.full(3, float(a))
    if a.shape != (3,):
        raise SceneError(sub, f"must be {'a number or ' if allow_scalar else ''}"
                              f"3 numbers, got {value!r}")
    if not np.isfinite(a).all():
        raise SceneError(sub, f"must be finite, got {value!r}")
    return a


def transform_matrix(translate=(0.0, 0.0, 0.0), scale=1.0, rotate_deg=(0.0, 0.0, 0.0),
                     field: str = "") -> np.ndarray:
    """4x4 affine matrix  M = T @ Rz @ Ry @ Rx @ S  (column vectors, p' = M p).

    Applied to a point: first scale (uniform number or (sx, sy, sz); negative
    values mirror, zero is an error), then rotate about the fixed X axis by
    rx degrees, then about fixed Y by ry, then about fixed Z by rz (extrinsic
    X-Y-Z, right-handed, counter-clockwise looking down the axis towards the
    origin), then translate.
    """
    t = _vec3(translate, field, "translate")
    s = _vec3(scale, field, "scale", allow_scalar=True)
    r = _vec3(rotate_deg, field, "rotate_deg")
    if (s == 0).any():
        raise SceneError(f"{field}.scale" if field else "scale",
                         f"must be non-zero, got {scale!r}")
    rx, ry, rz = np.radians(r)
    m = np.eye(4)
    m[:3, :3] = _rot_z(rz) @ _rot_y(ry) @ _rot_x(rx) @ np.diag(s)
    m[:3, 3] = t
    return m


def transform_mesh(mesh: MeshData, matrix, field: str = "") -> MeshData:
    """Return a new mesh with ``matrix`` (4x4 affine, p' = M p) applied.

    Vertices: p' = A p + t.  Normals: n' = normalise(A^-T n).  If det(A) < 0
    (mirroring) the face winding is reversed so that front faces stay front
    (counter-clockwise seen from the side the transformed normals point to).
    Singular or non-affine matrices raise SceneError.
    """
    try:
        m = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        m = None
    if m is None or m.shape != (4, 4):
        raise SceneError(field, "transform must be a 4x4 matrix")
    if not np.isfinite(m).all():
        raise SceneError(field, "transform matrix contains non-finite values")
    if not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0), rtol=0, atol=1e-12):
        raise SceneError(field, "transform matrix must be affine "
                                f"(last row 0 0 0 1), got last row {m[3].tolist()}")
    a = m[:3, :3]
    scale = float(np.abs(a).max())
    if scale > 1e30:
        raise SceneError(field, f"transform scales by {scale:g}: at most 1e30 (ray casting is single precision)")
    det = float(np.linalg.det(a))
    if scale == 0 or abs(det) <= 1e-12 * scale ** 3 or np.linalg.cond(a) > 1e12:
        raise SceneError(field, f"transform matrix is singular (determinant {det:g})")
    verts = mesh.vertices @ a.T + m[:3, 3]
    normals = None
    if mesh.vertex_normals is not None:
        n = mesh.vertex_normals @ np.linalg.inv(a)   # (A^-T n) for row vectors
        length = np.sqrt(np.einsum("ij,ij->i", n, n))
        length[length == 0] = 1.0
        normals = n / length[:, None]
    faces = mesh.faces[:, [0, 2, 1]] if det < 0 else mesh.faces.copy()
    groups = None if mesh.face_groups is None else mesh.face_groups.copy()
    uv = None if mesh.uv is None else mesh.uv.copy()      # per vertex: unchanged by the transform
    return MeshData(verts, faces, normals, groups, list(mesh.group_names), mesh.ungrouped_line, uv,
                    {name: c.copy() for name, c in mesh.colors.items()})
