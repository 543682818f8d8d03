"""Next-event estimation's light sampling as compiled passes, each with its NumPy twin.

- rectangle lamps sampled uniformly in the solid angle they subtend (Ureña, Conty & Kettunen 2013;
  engine.render.lights.SphericalRectangle): the spherical rectangle's angles, the sampled point,
  and the emitter's side of it (direction, distance, cosθ at the light, pdf 1/Ω, radiance factor Ω)
  in one pass per shading point instead of some sixty NumPy passes over the batch.

The NumPy functions are the reference arithmetic (engine.render.lights calls them); the loops
repeat it per path in the same operation order, with NumPy's NaN rules for clip, maximum, sign and
nan_to_num, so both give the same bits (acos, sin and cos are the platform's libm in both).
Distances in scene units, solid angles in sr, all vectors (3, N) world space.
"""

from __future__ import annotations

import math

import numpy as np

from . import jit, twin
from ..vec3 import dot

#: below this solid angle (sr) a rectangle is sampled by area: the spherical-rectangle solid angle
#: g0 + g1 + g2 + g3 − 2π loses its relative precision (float64 cancellation ~1e-15·2π), and a
#: rectangle that small is sampled as well by area (dist²/cosθ is then nearly constant over it)
MIN_RECT_SOLID_ANGLE = 1e-6


# ----------------------------------------------------------------------------- NumPy reference

def rect_local(p, corner, ax, ay, az, len_x, len_y):
    """Rectangle coordinates relative to points p (3, N): x0, x1, y0, y1, z0 ≤ 0 and the sign
    s = ±1 with which the rectangle's z axis ``az`` points from its plane away from p (z_eff = s·z);
    ``corner`` (3,), unit edge axes ``ax`` ⟂ ``ay`` and their lengths."""
    d = corner[:, None] - p
    z0 = dot(d, az[:, None])
    s = np.where(z0 > 0, -1.0, 1.0)
    z0 = -np.abs(z0)
    x0 = dot(d, ax[:, None])
    y0 = dot(d, ay[:, None])
    return x0, x0 + len_x, y0, y0 + len_y, z0, s


def rect_angles(x0, x1, y0, y1, z0):
    """z components of the four inner normals of the spherical rectangle's edges (n0, n2), the
    constant k = 2π − γ2 − γ3 of the parametrisation and the solid angle S = γ0 + γ1 − k."""
    def unit_z(a, b):       # (cross product of two corner rays).z / its norm, as in the paper
        return a / np.sqrt(z0 * z0 * b * b + a * a)
    n0 = unit_z(y0 * (x0 - x1), x0 - x1)
    n1 = unit_z(x1 * (y1 - y0), y1 - y0)
    n2 = unit_z(y1 * (x1 - x0), x1 - x0)
    n3 = unit_z(x0 * (y0 - y1), y0 - y1)
    g0 = np.arccos(np.clip(-n0 * n1, -1.0, 1.0))
    g1 = np.arccos(np.clip(-n1 * n2, -1.0, 1.0))
    g2 = np.arccos(np.clip(-n2 * n3, -1.0, 1.0))
    g3 = np.arccos(np.clip(-n3 * n0, -1.0, 1.0))
    k = 2.0 * math.pi - g2 - g3
    return n0, n2, k, np.maximum(g0 + g1 - k, 0.0)


def rect_sample(p, u1, u2, corner, ax, ay, az, len_x, len_y):
    """Points q (3, N) on the rectangle, uniform in the solid angle seen from p (3, N) for u1, u2
    (N,) ∈ [0, 1), and that solid angle Ω (N,) (0 where p lies in the rectangle's plane)."""
    x0, x1, y0, y1, z0, s = rect_local(p, corner, ax, ay, az, len_x, len_y)
    with np.errstate(invalid="ignore", divide="ignore"):
        b0, b1, k, S = rect_angles(x0, x1, y0, y1, z0)
        au = u1 * S + k
        fu = (np.cos(au) * b0 - b1) / np.sin(au)
        cu = np.clip(np.sign(fu) / np.sqrt(fu * fu + b0 * b0), -1.0, 1.0)
        xu = np.clip(-(cu * z0) / np.maximum(np.sqrt(1.0 - cu * cu), 1e-300), x0, x1)
        d2 = xu * xu + z0 * z0
        h0 = y0 / np.sqrt(d2 + y0 * y0)
        h1 = y1 / np.sqrt(d2 + y1 * y1)
        hv = h0 + u2 * (h1 - h0)
        hv2 = hv * hv
        yv = np.where(hv2 < 1.0 - 1e-12, hv * np.sqrt(d2) / np.sqrt(np.maximum(1.0 - hv2, 1e-300)), y1)
    xu, yv = np.nan_to_num(xu), np.clip(np.nan_to_num(yv), y0, y1)
    q = p + ax[:, None] * xu + ay[:, None] * yv + az[:, None] * (s * z0)
    return q, np.where(z0 < 0, np.nan_to_num(S), 0.0)


def rect_light_sample_numpy(p, u1, u2, corner, ax, ay, az, len_x, len_y, normal, two_sided):
    """A rectangle lamp of emitting normal ``normal`` (3,) (both faces if ``two_sided``) sampled from
    p (3, N) uniformly in solid angle: (wi (3, N) unit towards the point, dist (N,), scale = Ω (N,),
    pdf = 1/Ω (N,), valid (N,), use (N,): Ω > MIN_RECT_SOLID_ANGLE (elsewhere the caller samples by
    area), cos_l (N,) cosθ at the light as seen by its emitting side).  scale and pdf are 0 where
    not valid."""
    q, omega = rect_sample(p, u1, u2, corner, ax, ay, az, len_x, len_y)
    use = omega > MIN_RECT_SOLID_ANGLE
    to = q - p
    dist = np.sqrt(dot(to, to))
    wi = to / np.where(dist > 0, dist, 1.0)
    cos_l = -dot(wi, normal[:, None])
    if two_sided:
        cos_l = np.abs(cos_l)
    valid = use & (cos_l > 0) & (dist > 0)
    pdf = np.where(valid, 1.0 / np.where(valid, omega, 1.0), 0.0)
    scale = np.where(valid, omega, 0.0)
    return wi, dist, scale, pdf, valid, use, cos_l


# ----------------------------------------------------------------------------- compiled loop

@jit
def _clip(x, lo, hi):
    # np.clip's NaN rule: a NaN x (or bound) comes out as NaN
    if x != x:
        return x
    t = x if x > lo else lo
    if t != t:
        return t
    return t if t < hi else hi


@jit
def _maximum(a, b):
    # np.maximum: NaN in either argument propagates
    if a != a:
        return a
    if b != b:
        return b
    return a if a >= b else b


@jit
def _nan_to_num(x):
    if x != x:
        return 0.0
    if x == np.inf:
        return 1.7976931348623157e308
    if x == -np.inf:
        return -1.7976931348623157e308
    return x


@jit
def _sign(x):
    if x != x:
        return x
    if x > 0:
        return 1.0
    if x < 0:
        return -1.0
    return 0.0


@jit
def _unit_z(a, b, z0):
    return a / np.sqrt(z0 * z0 * b * b + a * a)


@jit
def _rect_light_loop(p, u1, u2, corner, ax, ay, az, len_x, len_y, normal, two_sided, min_omega,
                     wi, dist, scale, pdf, valid, use, cos_l):
    two_pi = 2.0 * math.pi
    for j in range(p.shape[1]):
        p0, p1, p2 = p[0, j], p[1, j], p[2, j]
        # rect_local
        d0, d1, d2 = corner[0] - p0, corner[1] - p1, corner[2] - p2
        z0 = d0 * az[0] + d1 * az[1] + d2 * az[2]
        s = -1.0 if z0 > 0 else 1.0
        z0 = -abs(z0)
        x0 = d0 * ax[0] + d1 * ax[1] + d2 * ax[2]
        y0 = d0 * ay[0] + d1 * ay[1] + d2 * ay[2]
        x1 = x0 + len_x
        y1 = y0 + len_y
        # rect_angles
        n0 = _unit_z(y0 * (x0 - x1), x0 - x1, z0)
        n1 = _unit_z(x1 * (y1 - y0), y1 - y0, z0)
        n2 = _unit_z(y1 * (x1 - x0), x1 - x0, z0)
        n3 = _unit_z(x0 * (y0 - y1), y0 - y1, z0)
        g0 = np.arccos(_clip(-n0 * n1, -1.0, 1.0))
        g1 = np.arccos(_clip(-n1 * n2, -1.0, 1.0))
        g2 = np.arccos(_clip(-n2 * n3, -1.0, 1.0))
        g3 = np.arccos(_clip(-n3 * n0, -1.0, 1.0))
        k = two_pi - g2 - g3
        S = _maximum(g0 + g1 - k, 0.0)
        b0, b1 = n0, n2
        # rect_sample
        au = u1[j] * S + k
        fu = (np.cos(au) * b0 - b1) / np.sin(au)
        cu = _clip(_sign(fu) / np.sqrt(fu * fu + b0 * b0), -1.0, 1.0)
        xu = _clip(-(cu * z0) / _maximum(np.sqrt(1.0 - cu * cu), 1e-300), x0, x1)
        e2 = xu * xu + z0 * z0
        h0 = y0 / np.sqrt(e2 + y0 * y0)
        h1 = y1 / np.sqrt(e2 + y1 * y1)
        hv = h0 + u2[j] * (h1 - h0)
        hv2 = hv * hv
        yv = hv * np.sqrt(e2) / np.sqrt(_maximum(1.0 - hv2, 1e-300)) if hv2 < 1.0 - 1e-12 else y1
        xu = _nan_to_num(xu)
        yv = _clip(_nan_to_num(yv), y0, y1)
        sz = s * z0
        q0 = p0 + ax[0] * xu + ay[0] * yv + az[0] * sz
        q1 = p1 + ax[1] * xu + ay[1] * yv + az[1] * sz
        q2 = p2 + ax[2] * xu + ay[2] * yv + az[2] * sz
        omega = _nan_to_num(S) if z0 < 0 else 0.0
        # the emitter's side (rect_light_sample_numpy)
        used = omega > min_omega
        t0, t1, t2 = q0 - p0, q1 - p1, q2 - p2
        r = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        div = r if r > 0 else 1.0
        w0, w1, w2 = t0 / div, t1 / div, t2 / div
        c = -(w0 * normal[0] + w1 * normal[1] + w2 * normal[2])
        if two_sided:
            c = abs(c)
        ok = used and c > 0 and r > 0
        wi[0, j], wi[1, j], wi[2, j] = w0, w1, w2
        dist[j] = r
        cos_l[j] = c
        use[j] = used
        valid[j] = ok
        pdf[j] = 1.0 / omega if ok else 0.0
        scale[j] = omega if ok else 0.0


def rect_light_sample_numba(p, u1, u2, corner, ax, ay, az, len_x, len_y, normal, two_sided):
    n = p.shape[1]
    wi, dist, scale, pdf = np.empty((3, n)), np.empty(n), np.empty(n), np.empty(n)
    valid, use, cos_l = np.empty(n, np.bool_), np.empty(n, np.bool_), np.empty(n)
    f64 = np.float64
    _rect_light_loop(np.ascontiguousarray(p, dtype=f64), np.ascontiguousarray(u1, dtype=f64),
                     np.ascontiguousarray(u2, dtype=f64), np.asarray(corner, f64), np.asarray(ax, f64),
                     np.asarray(ay, f64), np.asarray(az, f64), float(len_x), float(len_y), np.asarray(normal, f64),
                     bool(two_sided), MIN_RECT_SOLID_ANGLE, wi, dist, scale, pdf, valid, use, cos_l)
    return wi, dist, scale, pdf, valid, use, cos_l


#: The compiled twin of rect_light_sample_numpy (None without Numba).
rect_light_sample_numba = _rect_light_loop and rect_light_sample_numba
rect_light_sample = twin(rect_light_sample_numba, rect_light_sample_numpy)
