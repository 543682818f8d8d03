"""Surface reconstruction at ray hits and ray-origin offsetting ((3, N) SoA, world space)."""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner, twin
from ..vec3 import any_perpendicular, cross, dot, normalize



# ----------------------------------------------------------------------------- one point's local frame

@jit_inner
def local_frame_at(n0, n1, n2):
    """(t, b) of engine.vec3.local_frame for one unit normal n, same operation order: the frame of
    every compiled sampler (local z = n)."""
    sign = 1.0 if n2 >= 0 else -1.0
    f = -1.0 / (sign + n2)
    g = n0 * n1 * f
    t0 = 1.0 + sign * n0 * n0 * f
    t1 = sign * g
    t2 = -sign * n0
    return t0, t1, t2, n1 * t2 - n2 * t1, n2 * t0 - n0 * t2, n0 * t1 - n1 * t0


@jit_inner
def to_local_at(v0, v1, v2, t0, t1, t2, b0, b1, b2, n0, n1, n2):
    """World vector v in the local frame (t, b, n): (v·t, v·b, v·n)."""
    return (v0 * t0 + v1 * t1 + v2 * t2, v0 * b0 + v1 * b1 + v2 * b2, v0 * n0 + v1 * n1 + v2 * n2)


@jit_inner
def to_world_at(n0, n1, n2, v0, v1, v2):
    """Local vector v (z along the unit normal n, frame local_frame_at) in world space
    (engine.materials.sampling.local_to_world)."""
    t0, t1, t2, b0, b1, b2 = local_frame_at(n0, n1, n2)
    return t0 * v0 + b0 * v1 + n0 * v2, t1 * v0 + b1 * v1 + n1 * v2, t2 * v0 + b2 * v1 + n2 * v2

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


surface_attributes = twin(_surface_loop and surface_attributes_numba, surface_attributes_numpy)


def offset_origin_numpy(p, n_g, w, epsilon):
    """p moved along ±n_g (to the side w leaves from) by (1 + max|p_i|)·epsilon."""
    side = np.where((n_g * w).sum(0) >= 0, 1.0, -1.0)
    mag = (1.0 + np.abs(p).max(axis=0)) * epsilon
    return p + (side * mag)[None, :] * n_g


@jit_inner
def offset_origin_at(p, n_g, w, epsilon, i, out):
    """out[:, i] = point p[:, i] moved off its surface along ±n_g[:, i], to the side of direction
    w[:, i] (offset_origin_numpy's rule and operation order, one path); returns max|p[:, i]|."""
    side = 1.0 if (n_g[0, i] * w[0, i] + n_g[1, i] * w[1, i]) + n_g[2, i] * w[2, i] >= 0 else -1.0
    m = max(max(abs(p[0, i]), abs(p[1, i])), abs(p[2, i]))
    s = side * ((1.0 + m) * epsilon)
    for k in range(3):
        out[k, i] = p[k, i] + s * n_g[k, i]
    return m


@jit
def _offset_loop(p, n_g, w, epsilon, out):
    for i in range(p.shape[1]):
        offset_origin_at(p, n_g, w, epsilon, i, out)


def offset_origin_numba(p, n_g, w, epsilon):
    out = np.empty(p.shape)             # C order whatever p's: the one precompiled signature
    _offset_loop(np.ascontiguousarray(p, dtype=np.float64), np.ascontiguousarray(n_g, dtype=np.float64),
                 np.ascontiguousarray(w, dtype=np.float64), float(epsilon), out)
    return out


offset_origin = twin(_offset_loop and offset_origin_numba, offset_origin_numpy)


def unit_cross_numpy(a, b, degenerate):
    """unit(a × b), or engine.vec3.any_perpendicular(a) where |a × b| ≤ ``degenerate``; (3, ...).

    The axis ⟂ a plane spanned by two directions (plane of incidence, scattering plane), with a
    deterministic fallback where they are parallel (engine.polarisation.frames).
    """
    s = cross(a, b)
    length = np.sqrt(dot(s, s))
    ok = length > degenerate
    fallback = any_perpendicular(a)
    return np.where(ok, s / np.where(ok, length, 1.0), fallback)


@jit_inner
def unit_cross_at(a0, a1, a2, b0, b1, b2, degenerate):
    """unit_cross_numpy for one pair of vectors (a, b), as a tuple, same operation order."""
    s0 = a1 * b2 - a2 * b1
    s1 = a2 * b0 - a0 * b2
    s2 = a0 * b1 - a1 * b0
    length = np.sqrt((s0 * s0 + s1 * s1) + s2 * s2)
    if length > degenerate:
        return s0 / length, s1 / length, s2 / length
    # engine.vec3.any_perpendicular(a), same operation order
    sign = 1.0 if a2 >= 0 else -1.0
    f = -1.0 / (sign + a2)
    g = a0 * a1 * f
    return 1.0 + sign * a0 * a0 * f, sign * g, -sign * a0


@jit
def _unit_cross_loop(a, b, out, degenerate):
    for i in range(a.shape[1]):
        out[0, i], out[1, i], out[2, i] = unit_cross_at(a[0, i], a[1, i], a[2, i], b[0, i], b[1, i], b[2, i],
                                                        degenerate)


def unit_cross_numba(a, b, degenerate):
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    shape = a.shape
    a2 = np.ascontiguousarray(a).reshape(3, -1)
    b2 = np.ascontiguousarray(b).reshape(3, -1)
    out = np.empty_like(a2)
    _unit_cross_loop(a2, b2, out, float(degenerate))
    return out.reshape(shape)


unit_cross = twin(_unit_cross_loop and unit_cross_numba, unit_cross_numpy)


def film_offsets(pixel, u, W, H, shift_x, shift_y, tx, ty):
    """(s_x, s_y) (N,): image-plane offsets along right and up of flat pixel indices with jitter u (2, N)
    (engine.render.camera: (2x/W − 1 + 2·shift_x)·t_x, (1 − 2y/H + 2·shift_y)·t_y, row 0 at the top)."""
    col = pixel % W
    row = pixel // W
    sx = (2.0 * (col + u[0]) / W - 1.0 + 2.0 * shift_x) * tx
    sy = (1.0 - 2.0 * (row + u[1]) / H + 2.0 * shift_y) * ty
    return sx, sy


def pinhole_rays_numpy(pixel, u, W, H, shift_x, shift_y, tx, ty, forward, right, up):
    """Directions d, Stokes frames x = unit(d × up) (both (3, N)) and depth per unit length (N,)
    of pinhole camera rays through flat pixel indices with jitter u (2, N); see engine.render.camera."""
    sx, sy = film_offsets(pixel, u, W, H, shift_x, shift_y, tx, ty)
    up = up[:, None]
    d = normalize(forward[:, None] + sx * right[:, None] + sy * up)
    x = normalize(cross(d, up))
    return d, x, d[0] * forward[0] + d[1] * forward[1] + d[2] * forward[2]


@jit
def _pinhole_loop(pixel, u, W, H, shift_x, shift_y, tx, ty, f, r, up, d, x, depth):
    for i in range(pixel.shape[0]):
        col = pixel[i] % W
        row = pixel[i] // W
        sx = ((2.0 * (col + u[0, i]) / W - 1.0) + 2.0 * shift_x) * tx
        sy = ((1.0 - 2.0 * (row + u[1, i]) / H) + 2.0 * shift_y) * ty
        d0 = (f[0] + sx * r[0]) + sy * up[0]
        d1 = (f[1] + sx * r[1]) + sy * up[1]
        d2 = (f[2] + sx * r[2]) + sy * up[2]
        n = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
        if not n > 0:
            n = 1.0
        d0, d1, d2 = d0 / n, d1 / n, d2 / n
        x0 = d1 * up[2] - d2 * up[1]
        x1 = d2 * up[0] - d0 * up[2]
        x2 = d0 * up[1] - d1 * up[0]
        m = np.sqrt((x0 * x0 + x1 * x1) + x2 * x2)
        if not m > 0:
            m = 1.0
        d[0, i], d[1, i], d[2, i] = d0, d1, d2
        x[0, i], x[1, i], x[2, i] = x0 / m, x1 / m, x2 / m
        depth[i] = (d0 * f[0] + d1 * f[1]) + d2 * f[2]


def pinhole_rays_numba(pixel, u, W, H, shift_x, shift_y, tx, ty, forward, right, up):
    n = pixel.shape[0]
    d, x, depth = np.empty((3, n)), np.empty((3, n)), np.empty(n)
    _pinhole_loop(np.ascontiguousarray(pixel, dtype=np.int64), np.ascontiguousarray(u, dtype=np.float64),
                  int(W), int(H), float(shift_x), float(shift_y), float(tx), float(ty),
                  np.ascontiguousarray(forward, dtype=np.float64), np.ascontiguousarray(right, dtype=np.float64),
                  np.ascontiguousarray(up, dtype=np.float64), d, x, depth)
    return d, x, depth


pinhole_rays = twin(_pinhole_loop and pinhole_rays_numba, pinhole_rays_numpy)


def area_light_sample_numpy(p, u, cdf, tris, faces, vertices, tri_normal, total_area, two_sided=False):
    """Uniform-by-area points on an emitter's triangles seen from p (3, N), u (3, N) ∈ [0, 1).

    Row 0 of u picks the triangle (inverting ``cdf`` over ``tris``), rows 1–2 the point
    (b1 = 1 − √u1, b2 = u2·√u1).  Returns (wi (3, N) unit towards the point, dist (N,),
    scale = 1/pdf (N,), pdf (N,) solid angle = dist²/(cosθ_light·A_total), valid (N,): the
    point's front face sees p; ``two_sided``: either face, cosθ_light taken as |cosθ|).
    """
    idx = np.minimum(np.searchsorted(cdf, u[0], side="right"), len(tris) - 1)
    tri = tris[idx]
    f = faces[tri]
    su = np.sqrt(u[1])
    b1 = 1.0 - su
    b2 = u[2] * su
    V = vertices
    x = (V[f[:, 0]] * (1.0 - b1 - b2)[:, None] + V[f[:, 1]] * b1[:, None] + V[f[:, 2]] * b2[:, None]).T
    to = x - p
    dist2 = (to[0] * to[0] + to[1] * to[1]) + to[2] * to[2]
    dist = np.sqrt(dist2)
    wi = to / np.where(dist > 0, dist, 1.0)
    n_l = tri_normal[tri].T
    cos_l = -((wi[0] * n_l[0] + wi[1] * n_l[1]) + wi[2] * n_l[2])
    if two_sided:
        cos_l = np.abs(cos_l)
    valid = (cos_l > 0) & (dist > 0)
    pdf = np.where(valid, dist2 / np.where(valid, cos_l, 1.0) / total_area, 0.0)
    return wi, dist, np.where(valid, 1.0 / np.where(valid, pdf, 1.0), 0.0), pdf, valid


@jit_inner
def triangle_point_at(V, faces, t, u1, u2, p0, p1, p2):
    """The point of triangle t at b1 = 1 − √u1, b2 = u2·√u1 (Embree's weights: 1 − b1 − b2, b1, b2 on its
    vertices V[faces[t]]) less (p0, p1, p2): (b1, b2, t0, t1, t2), in area_light_sample_numpy's order."""
    a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
    su = np.sqrt(u1)
    b1 = 1.0 - su
    b2 = u2 * su
    w0 = 1.0 - b1 - b2
    t0 = ((V[a, 0] * w0 + V[b, 0] * b1) + V[c, 0] * b2) - p0
    t1 = ((V[a, 1] * w0 + V[b, 1] * b1) + V[c, 1] * b2) - p1
    t2 = ((V[a, 2] * w0 + V[b, 2] * b1) + V[c, 2] * b2) - p2
    return b1, b2, t0, t1, t2


@jit_inner
def _area_point_at(V, faces, tri_normal, t, p, u, i, two_sided, total_area, wi, dist, scale, pdf, valid):
    """Point i of area_light_sample_numpy on triangle t (from u[1, i], u[2, i]) seen from p[:, i], written into
    the outputs' column i (its operation order)."""
    _, _, t0, t1, t2 = triangle_point_at(V, faces, t, u[1, i], u[2, i], p[0, i], p[1, i], p[2, i])
    d2 = (t0 * t0 + t1 * t1) + t2 * t2
    d = np.sqrt(d2)
    s = d if d > 0 else 1.0
    x0, x1, x2 = t0 / s, t1 / s, t2 / s
    cos_l = -((x0 * tri_normal[t, 0] + x1 * tri_normal[t, 1]) + x2 * tri_normal[t, 2])
    if two_sided:
        cos_l = abs(cos_l)
    ok = cos_l > 0 and d > 0
    wi[0, i], wi[1, i], wi[2, i] = x0, x1, x2
    dist[i] = d
    valid[i] = ok
    if ok:
        q = d2 / cos_l / total_area
        pdf[i] = q
        scale[i] = 1.0 / q
    else:
        pdf[i] = 0.0
        scale[i] = 0.0


def area_light_sample_numba(p, u, cdf, tris, faces, vertices, tri_normal, total_area, two_sided=False):
    """area_light_sample_numpy compiled: the group loop (_area_lights_loop) with one emitter, the same bits."""
    n = p.shape[1]
    return area_lights_sample_numba(p, u, np.zeros(n, np.int64), np.ascontiguousarray(cdf, dtype=np.float64),
                                    np.array([0, len(tris)], np.int64), np.ascontiguousarray(tris, dtype=np.int64),
                                    faces, vertices, tri_normal, np.array([float(total_area)]),
                                    np.array([bool(two_sided)]))


def area_lights_sample_numpy(p, u, light, cdf, start, tris, faces, vertices, tri_normal, total_area, two_sided):
    """area_light_sample for several emitters at once: point i on emitter ``light[i]`` (k) of a group whose
    triangles and cdfs are concatenated — emitter k's are ``tris[start[k]:start[k + 1]]``, ``cdf[…]`` the same
    slice; ``total_area`` (K,), ``two_sided`` (K,) bool.  Per point exactly area_light_sample's result (the same
    arithmetic); (wi (3, N), dist, scale, pdf, valid (N,))."""
    n = p.shape[1]
    wi, dist, scale, pdf, valid = np.empty((3, n)), np.empty(n), np.empty(n), np.empty(n), np.empty(n, bool)
    for k in np.unique(light):
        rows = np.flatnonzero(light == k)
        a, b = start[k], start[k + 1]
        wi[:, rows], dist[rows], scale[rows], pdf[rows], valid[rows] = area_light_sample_numpy(
            p[:, rows], u[:, rows], cdf[a:b], tris[a:b], faces, vertices, tri_normal, total_area[k], two_sided[k])
    return wi, dist, scale, pdf, valid


@jit
def _area_lights_loop(p, u, light, cdf, start, tris, faces, V, tri_normal, total_area, two_sided, wi, dist, scale,
                      pdf, valid):
    for i in range(p.shape[1]):
        e = light[i]
        a, b = start[e], start[e + 1]
        k = min(np.searchsorted(cdf[a:b], u[0, i], side="right"), b - a - 1)
        t = tris[a + k]
        _area_point_at(V, faces, tri_normal, t, p, u, i, two_sided[e], total_area[e], wi, dist, scale, pdf, valid)


def area_lights_sample_numba(p, u, light, cdf, start, tris, faces, vertices, tri_normal, total_area, two_sided):
    n = p.shape[1]
    wi, dist, scale, pdf, valid = np.empty((3, n)), np.empty(n), np.empty(n), np.empty(n), np.empty(n, np.bool_)
    f64, i64 = np.float64, np.int64
    _area_lights_loop(np.ascontiguousarray(p, dtype=f64), np.ascontiguousarray(u, dtype=f64),
                      np.ascontiguousarray(light, dtype=i64), cdf, start, tris, faces, vertices, tri_normal,
                      total_area, two_sided, wi, dist, scale, pdf, valid)
    return wi, dist, scale, pdf, valid


area_lights_sample = twin(_area_lights_loop and area_lights_sample_numba, area_lights_sample_numpy)
area_light_sample = twin(_area_lights_loop and area_light_sample_numba, area_light_sample_numpy)


def triangle_sample_numpy(p, tri, u1, u2, faces, vertices, tri_normal, tri_area, two_sided):
    """A point uniform by area on each given triangle ``tri`` (N,) seen from p (3, N) (the light tree's triangle
    choice; engine.render.lights.area.AreaEmitter.sample_triangles): b1 = 1 − √u1, b2 = u2·√u1 (u1, u2 (N,)).
    Returns (wi (3, N) unit towards the point, dist (N,), 1/pdf (N,) (0 where the pdf is 0), pdf (N,) solid angle
    = dist²/(cosθ_light·A_triangle), pdf > 0 (N,), cosθ at the emitter (N,) (|cosθ| for ``two_sided``), b1, b2)."""
    f = faces[tri]
    su = np.sqrt(u1)
    b1 = 1.0 - su
    b2 = u2 * su
    V = vertices
    x = (V[f[:, 0]] * (1.0 - b1 - b2)[:, None] + V[f[:, 1]] * b1[:, None] + V[f[:, 2]] * b2[:, None]).T
    to = x - p
    dist = np.sqrt(to[0] * to[0] + to[1] * to[1] + to[2] * to[2])
    wi = to / np.where(dist > 0, dist, 1.0)
    n_l = tri_normal[tri].T
    cos_l = -(wi[0] * n_l[0] + wi[1] * n_l[1] + wi[2] * n_l[2])
    if two_sided:
        cos_l = np.abs(cos_l)
    ok = (cos_l > 0) & (dist > 0)
    pdf = np.where(ok, dist * dist / np.where(ok, cos_l * tri_area[tri], 1.0), 0.0)
    valid = pdf > 0
    return wi, dist, np.where(valid, 1.0 / np.where(valid, pdf, 1.0), 0.0), pdf, valid, cos_l, b1, b2


@jit
def _triangle_sample_loop(p, tri, u1, u2, faces, V, tri_normal, tri_area, two_sided, wi, dist, scale, pdf, valid,
                          cos_out, b1_out, b2_out):
    for i in range(p.shape[1]):
        t = tri[i]
        b1, b2, t0, t1, t2 = triangle_point_at(V, faces, t, u1[i], u2[i], p[0, i], p[1, i], p[2, i])
        d = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        s = d if d > 0 else 1.0
        x0, x1, x2 = t0 / s, t1 / s, t2 / s
        cos_l = -(x0 * tri_normal[t, 0] + x1 * tri_normal[t, 1] + x2 * tri_normal[t, 2])
        if two_sided:
            cos_l = abs(cos_l)
        q = d * d / (cos_l * tri_area[t]) if (cos_l > 0 and d > 0) else 0.0
        wi[0, i], wi[1, i], wi[2, i] = x0, x1, x2
        dist[i], pdf[i], valid[i], cos_out[i], b1_out[i], b2_out[i] = d, q, q > 0, cos_l, b1, b2
        scale[i] = 1.0 / q if q > 0 else 0.0


def triangle_sample_numba(p, tri, u1, u2, faces, vertices, tri_normal, tri_area, two_sided):
    n = p.shape[1]
    out = (np.empty((3, n)), np.empty(n), np.empty(n), np.empty(n), np.empty(n, np.bool_), np.empty(n), np.empty(n),
           np.empty(n))
    f64 = np.float64
    _triangle_sample_loop(np.ascontiguousarray(p, dtype=f64), np.ascontiguousarray(tri, dtype=np.int64),
                          np.ascontiguousarray(u1, dtype=f64), np.ascontiguousarray(u2, dtype=f64), faces, vertices,
                          tri_normal, tri_area, bool(two_sided), *out)
    return out


triangle_sample = twin(_triangle_sample_loop and triangle_sample_numba, triangle_sample_numpy)


def interpolate_vertex_attribute_numpy(faces, values, prim, u, v):
    """Per-vertex ``values`` (V, C) interpolated at hits on triangles ``prim`` with barycentrics
    (u, v) (weights 1 − u − v, u, v of the triangle's vertices 0, 1, 2, as Embree's): (C, N) float64."""
    tri = faces[prim]
    w0 = 1.0 - u - v
    A = values
    return (A[tri[:, 0]] * w0[:, None] + A[tri[:, 1]] * u[:, None] + A[tri[:, 2]] * v[:, None]).T


@jit
def _interpolate_loop(faces, values, prim, u, v, out):
    for i in range(prim.shape[0]):
        t = prim[i]
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        ui, vi = u[i], v[i]
        w0 = 1.0 - ui - vi
        for k in range(values.shape[1]):
            out[k, i] = (values[a, k] * w0 + values[b, k] * ui) + values[c, k] * vi


def interpolate_vertex_attribute_numba(faces, values, prim, u, v):
    """interpolate_vertex_attribute_numpy in one compiled pass (the same products and sums, no gathered copies),
    C-contiguous (C, N)."""
    out = np.empty((values.shape[1], np.shape(prim)[0]))
    f64 = np.float64
    # (the scene's tables as they are, as surface_attributes: converted, they would be copied at every call)
    _interpolate_loop(faces, values, np.ascontiguousarray(prim, dtype=np.int64), np.ascontiguousarray(u, dtype=f64),
                      np.ascontiguousarray(v, dtype=f64), out)
    return out


interpolate_vertex_attribute = twin(_interpolate_loop and interpolate_vertex_attribute_numba,
                                    interpolate_vertex_attribute_numpy)


# ----------------------------------------------------------------------------- tangent frames of normal maps

def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def tangent_frame_numpy(n_s, t, dpdv, ok, t4, has_t4):
    """(T, B) (3, N) of engine.textures.SurfacePoints.tangent_frame: unit T ⟂ n_s from the per-vertex tangents t4
    (4, N) (xyz, w = handedness; used where has_t4 and xyz ≠ 0) else from ∂p/∂u ``t`` (Gram–Schmidt against n_s),
    any perpendicular (the least aligned axis, projected) where neither exists (``ok``: ∂p/∂u exists); B =
    ±(n_s × T), the sign from ∂p/∂v ``dpdv`` or w.  All (3, N) but ``ok`` (N,)."""
    sign = np.where(_dot3(np.cross(n_s.T, t.T).T, dpdv) < 0, -1.0, 1.0)
    if has_t4:      # given tangents win where the mesh has them
        given = np.any(t4[:3] != 0, axis=0)
        t = np.where(given[None, :], t4[:3], t)
        sign = np.where(given, np.where(t4[3] < 0, -1.0, 1.0), sign)
        ok = ok | given
    t = t - n_s * _dot3(n_s, t)[None, :]
    length = np.sqrt(_dot3(t, t))
    ok = ok & (length > 1e-12)
    axis = np.zeros_like(n_s)
    axis[np.argmin(np.abs(n_s), axis=0), np.arange(n_s.shape[1])] = 1.0
    fb = axis - n_s * _dot3(n_s, axis)[None, :]
    fb = fb / np.sqrt(_dot3(fb, fb))[None, :]
    t = np.where(ok[None, :], t / np.where(ok, length, 1.0)[None, :], fb)
    b = sign[None, :] * np.cross(n_s.T, t.T).T
    return t, b


@jit
def _tangent_frame_loop(n_s, t_in, dpdv, ok_in, t4, has_t4, t_out, b_out):
    for j in range(n_s.shape[1]):
        n0, n1, n2 = n_s[0, j], n_s[1, j], n_s[2, j]
        t0, t1, t2 = t_in[0, j], t_in[1, j], t_in[2, j]
        c0, c1, c2 = n1 * t2 - n2 * t1, n2 * t0 - n0 * t2, n0 * t1 - n1 * t0
        sign = -1.0 if c0 * dpdv[0, j] + c1 * dpdv[1, j] + c2 * dpdv[2, j] < 0 else 1.0
        ok = ok_in[j]
        if has_t4 and (t4[0, j] != 0 or t4[1, j] != 0 or t4[2, j] != 0):
            t0, t1, t2 = t4[0, j], t4[1, j], t4[2, j]
            sign = -1.0 if t4[3, j] < 0 else 1.0
            ok = True
        d = n0 * t0 + n1 * t1 + n2 * t2
        t0, t1, t2 = t0 - n0 * d, t1 - n1 * d, t2 - n2 * d
        length = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        ok = ok and length > 1e-12
        if ok:
            t0, t1, t2 = t0 / length, t1 / length, t2 / length
        else:       # np.argmin of |n|: the first least component (the first NaN if any)
            a0, a1, a2 = abs(n0), abs(n1), abs(n2)
            k = 0
            if a0 != a0:
                k = 0
            elif a1 != a1:
                k = 1
            elif a2 != a2:
                k = 2
            else:
                if a1 < a0:
                    k = 1
                if a2 < (a1 if k == 1 else a0):
                    k = 2
            e0, e1, e2 = (1.0 if k == 0 else 0.0), (1.0 if k == 1 else 0.0), (1.0 if k == 2 else 0.0)
            d = n0 * e0 + n1 * e1 + n2 * e2
            t0, t1, t2 = e0 - n0 * d, e1 - n1 * d, e2 - n2 * d
            length = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
            t0, t1, t2 = t0 / length, t1 / length, t2 / length
        t_out[0, j], t_out[1, j], t_out[2, j] = t0, t1, t2
        b_out[0, j] = sign * (n1 * t2 - n2 * t1)
        b_out[1, j] = sign * (n2 * t0 - n0 * t2)
        b_out[2, j] = sign * (n0 * t1 - n1 * t0)


def tangent_frame_numba(n_s, t, dpdv, ok, t4, has_t4):
    f64 = np.float64
    n = n_s.shape[1]
    t_out, b_out = np.empty((3, n)), np.empty((3, n))
    _tangent_frame_loop(np.ascontiguousarray(n_s, dtype=f64), np.ascontiguousarray(t, dtype=f64),
                        np.ascontiguousarray(dpdv, dtype=f64), np.ascontiguousarray(ok, dtype=np.bool_),
                        np.ascontiguousarray(t4 if has_t4 else np.zeros((4, 0)), dtype=f64), bool(has_t4),
                        t_out, b_out)
    return t_out, b_out


tangent_frame = twin(_tangent_frame_loop and tangent_frame_numba, tangent_frame_numpy)
