"""Surface reconstruction at ray hits and ray-origin offsetting ((3, N) SoA, world space)."""

from __future__ import annotations

import numpy as np

from . import dispatch, jit


def surface_attributes_numpy(faces, vertices, vertex_normals, tri_has_normals, tri_normal, any_vertex_normals,
                             prim, u, v):
    """(p, n_g, n_s), each (3, N) float64, at hits on triangles ``prim`` with barycentrics (u, v).

    n_g is the face normal by winding; n_s the interpolated vertex normal (unit), or n_g for
    flat faces and degenerate interpolations.  Without vertex normals n_s *is* n_g.
    """
    tri = faces[prim]
    w0 = 1.0 - u - v
    V = vertices
    p = (V[tri[:, 0]] * w0[:, None] + V[tri[:, 1]] * u[:, None] + V[tri[:, 2]] * v[:, None]).T
    n_g = tri_normal[prim].T
    if not any_vertex_normals:
        return p, n_g, n_g
    N = vertex_normals
    n_s = (N[tri[:, 0]] * w0[:, None] + N[tri[:, 1]] * u[:, None] + N[tri[:, 2]] * v[:, None]).T
    length = np.sqrt((n_s * n_s).sum(0))
    smooth = tri_has_normals[prim] & (length > 0)
    n_s = np.where(smooth[None, :], n_s / np.where(length > 0, length, 1.0), n_g)
    return p, n_g, n_s


@jit
def _surface_loop(faces, V, N, has_vn, tri_normal, any_vn, prim, u, v, p, n_g, n_s):
    for i in range(prim.shape[0]):
        t = prim[i]
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        ui, vi = u[i], v[i]
        w0 = 1.0 - ui - vi
        for k in range(3):
            p[k, i] = V[a, k] * w0 + V[b, k] * ui + V[c, k] * vi
            n_g[k, i] = tri_normal[t, k]
        if any_vn:
            x = N[a, 0] * w0 + N[b, 0] * ui + N[c, 0] * vi
            y = N[a, 1] * w0 + N[b, 1] * ui + N[c, 1] * vi
            z = N[a, 2] * w0 + N[b, 2] * ui + N[c, 2] * vi
            length = np.sqrt(x * x + y * y + z * z)
            if has_vn[t] and length > 0:
                n_s[0, i] = x / length
                n_s[1, i] = y / length
                n_s[2, i] = z / length
            else:
                n_s[0, i] = n_g[0, i]
                n_s[1, i] = n_g[1, i]
                n_s[2, i] = n_g[2, i]


def surface_attributes_numba(faces, vertices, vertex_normals, tri_has_normals, tri_normal, any_vertex_normals,
                             prim, u, v):
    n = prim.shape[0]
    p = np.empty((3, n))
    n_g = np.empty((3, n))
    n_s = np.empty((3, n)) if any_vertex_normals else n_g
    _surface_loop(faces, vertices, vertex_normals, tri_has_normals, tri_normal, bool(any_vertex_normals),
                  np.ascontiguousarray(prim, dtype=np.int64), np.ascontiguousarray(u, dtype=np.float64),
                  np.ascontiguousarray(v, dtype=np.float64), p, n_g, n_s)
    return p, n_g, n_s


surface_attributes = dispatch(_surface_loop and surface_attributes_numba, surface_attributes_numpy)


def offset_origin_numpy(p, n_g, w, epsilon):
    """p moved along ±n_g (to the side w leaves from) by (1 + max|p_i|)·epsilon."""
    side = np.where((n_g * w).sum(0) >= 0, 1.0, -1.0)
    mag = (1.0 + np.abs(p).max(axis=0)) * epsilon
    return p + (side * mag)[None, :] * n_g


@jit
def _offset_loop(p, n_g, w, epsilon, out):
    for i in range(p.shape[1]):
        side = 1.0 if (n_g[0, i] * w[0, i] + n_g[1, i] * w[1, i]) + n_g[2, i] * w[2, i] >= 0 else -1.0
        m = max(max(abs(p[0, i]), abs(p[1, i])), abs(p[2, i]))
        s = side * ((1.0 + m) * epsilon)
        for k in range(3):
            out[k, i] = p[k, i] + s * n_g[k, i]


def offset_origin_numba(p, n_g, w, epsilon):
    out = np.empty_like(p, dtype=np.float64)
    _offset_loop(np.ascontiguousarray(p, dtype=np.float64), np.ascontiguousarray(n_g, dtype=np.float64),
                 np.ascontiguousarray(w, dtype=np.float64), float(epsilon), out)
    return out


offset_origin = dispatch(_offset_loop and offset_origin_numba, offset_origin_numpy)
