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

from . import jit, jit_inner, twin
from .geometry import to_world_at
from .nan_rules import maximum_at, minimum_at
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

@jit_inner
def _clip(x, lo, hi):
    # np.clip's NaN rule: a NaN x (or bound) comes out as NaN
    if x != x:
        return x
    t = x if x > lo else lo
    if t != t:
        return t
    return t if t < hi else hi


@jit_inner
def _nan_to_num(x):
    if x != x:
        return 0.0
    if x == np.inf:
        return 1.7976931348623157e308
    if x == -np.inf:
        return -1.7976931348623157e308
    return x


@jit_inner
def _sign(x):
    if x != x:
        return x
    if x > 0:
        return 1.0
    if x < 0:
        return -1.0
    return 0.0


@jit_inner
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
        S = maximum_at(g0 + g1 - k, 0.0)
        b0, b1 = n0, n2
        # rect_sample
        au = u1[j] * S + k
        fu = (np.cos(au) * b0 - b1) / np.sin(au)
        cu = _clip(_sign(fu) / np.sqrt(fu * fu + b0 * b0), -1.0, 1.0)
        xu = _clip(-(cu * z0) / maximum_at(np.sqrt(1.0 - cu * cu), 1e-300), x0, x1)
        e2 = xu * xu + z0 * z0
        h0 = y0 / np.sqrt(e2 + y0 * y0)
        h1 = y1 / np.sqrt(e2 + y1 * y1)
        hv = h0 + u2[j] * (h1 - h0)
        hv2 = hv * hv
        yv = hv * np.sqrt(e2) / np.sqrt(maximum_at(1.0 - hv2, 1e-300)) if hv2 < 1.0 - 1e-12 else y1
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


# ----------------------------------------------------------------------------- light selection by importance
#
# Each light's selection importance at shading points p (3, N) with side normals n (3, N) or None is
# one of four formulas (engine.render.lights: LightSet, the lights' ``importance``), recorded per light
# as a kind and a row of SELECTION_PARAMS numbers so that one compiled pass evaluates them all:
#   SELECT_CONSTANT  [value]                                          (environments: π·luminance)
#   SELECT_POINT     [x, y, z, lum, max(r², 1e-12), r, spot, ax, ay, az, cos_outer, cos_inner]
#                    (spot 0: none, 1: hard edge, 2: smoothstep edge; a the spot's unit axis)
#   SELECT_AREA      [cx, cy, cz, lum·A·sides, max(r², 1e-12), r, one_sided, nx, ny, nz]
#                    (about the centroid, radius r; one_sided 1: a planar emitter emitting along its unit
#                    normal n only, so points behind its plane get importance 0: ``emitter_side``)
#   SELECT_DISTANT   [tx, ty, tz, lum, sin half-angle]                (t: towards the sun)

SELECT_CONSTANT, SELECT_POINT, SELECT_AREA, SELECT_DISTANT = 0, 1, 2, 3
SELECTION_PARAMS = 12
#: share of a light's selection importance kept when it lies below the shading point's horizon
#: (transmitting materials can still use it; a floor keeps every light's probability > 0)
BELOW_HORIZON = 0.1
#: share of the power distribution mixed into the per-point selection probabilities (defensive: every
#: light keeps a probability > 0). 0.01 halved a lamp-lit floor's variance under a grey world (whose
#: power rivals a lamp's), but then a constant sky under strong lamps was picked so rarely that its
#: weights made outliers (tests/render/test_lights.py, power selection with area lights and sky)
GLOBAL_SHARE = 0.1


def facing_factor(to, dist, sin_alpha, n):
    """Orientation term of the selection importance at points with side normals n (3, N) for
    light centres in directions to/dist subtending half-angles asin(sin_alpha):
    BELOW_HORIZON + (1 − BELOW_HORIZON)·cos⁺(max(θ − α, 0)), θ the angle between n and the centre."""
    if n is None:
        return 1.0
    cos_t = np.clip(dot(n, to) / np.maximum(dist, 1e-300), -1.0, 1.0)
    theta = np.maximum(np.arccos(cos_t) - np.arcsin(np.clip(sin_alpha, 0.0, 1.0)), 0.0)
    return BELOW_HORIZON + (1.0 - BELOW_HORIZON) * np.maximum(np.cos(theta), 0.0)


def spot_falloff(wi, axis, cos_outer, cos_inner):
    """A spot light's attenuation (N,) towards the receivers in directions −wi (3, N) from it:
    1 inside cos_inner, 0 outside cos_outer, smoothstep in cosθ between."""
    c = -(axis[:, None] * wi).sum(0)
    if cos_inner <= cos_outer:
        return (c >= cos_outer).astype(np.float64)
    t = np.clip((c - cos_outer) / (cos_inner - cos_outer), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def point_importance(p, n, position, lum, r2, radius, spot=None):
    """Irradiance estimate lum·falloff/max(d², r2) times the orientation term for a point or spot
    light (``spot``: (axis, cos_outer, cos_inner) or None) of radius ``radius``."""
    to = position[:, None] - p
    d2 = dot(to, to)
    dist = np.sqrt(np.maximum(d2, 1e-300))
    wi = to / dist
    falloff = 1.0 if spot is None else spot_falloff(wi, *spot)
    return lum * falloff / np.maximum(d2, r2) * facing_factor(to, dist, radius / dist, n)


def emitter_side(to, dist, sin_alpha, normal):
    """Emitter-side orientation term of a planar one-sided emitter with unit normal ``normal`` (3,)
    whose centre lies at to/dist (3, N) from the receivers, half-angle asin(sin_alpha):
    cos⁺(max(θ_e − α, 0)), θ_e the angle between the normal and the direction centre → receiver.
    It is 0 only where θ_e ≥ π/2 + α, i.e. behind the emitter's plane, where the emitter sends no light
    (a lamp seen from its back would otherwise take most samples and give nothing)."""
    cos_e = np.clip(-dot(normal[:, None], to) / np.maximum(dist, 1e-300), -1.0, 1.0)
    theta = np.maximum(np.arccos(cos_e) - np.arcsin(np.clip(sin_alpha, 0.0, 1.0)), 0.0)
    return np.maximum(np.cos(theta), 0.0)


def area_importance(p, n, centre, power, r2, radius, one_sided=0.0, normal=None):
    """power/max(d², r2) about the emitter's centroid times the orientation term (half-angle
    asin(radius/d)), and for a planar one-sided emitter (``one_sided`` ≠ 0, unit ``normal`` (3,))
    times ``emitter_side``."""
    to = centre[:, None] - p
    d2 = dot(to, to)
    dist = np.sqrt(d2)
    sin_alpha = radius / np.maximum(dist, 1e-300)
    imp = power / np.maximum(d2, r2) * facing_factor(to, dist, sin_alpha, n)
    if one_sided != 0:
        imp = imp * emitter_side(to, dist, sin_alpha, normal)
    return imp


def distant_importance(p, n, towards, lum, sin_half):
    """lum times the orientation term of a sun in the direction ``towards`` (3,)."""
    to = np.broadcast_to(towards[:, None], p.shape)
    return lum * facing_factor(to, 1.0, sin_half, n) * np.ones(p.shape[1])


def light_importance_numpy(kind, row, p, n):
    """The importance (N,) of one light recorded as (kind, params row) (see SELECT_*)."""
    if kind == SELECT_CONSTANT:
        return np.full(p.shape[1], row[0])
    if kind == SELECT_POINT:
        spot = None if row[6] == 0 else (row[7:10], row[10], row[11])
        return point_importance(p, n, row[0:3], row[3], row[4], row[5], spot)
    if kind == SELECT_AREA:
        return area_importance(p, n, row[0:3], row[3], row[4], row[5], row[6], row[7:10])
    return distant_importance(p, n, row[0:3], row[3], row[4])


def selection_probabilities_numpy(p, n, kinds, params, prob):
    """Per-point light selection probabilities (count, N) at points p (3, N) with side normals n
    (3, N) or None: (1 − GLOBAL_SHARE)·importance/Σ importance + GLOBAL_SHARE·prob (prob (count,):
    the power distribution, also used alone where every importance is 0)."""
    imp = np.stack([light_importance_numpy(k, row, p, n) for k, row in zip(kinds, params)])
    imp = np.where(np.isfinite(imp) & (imp > 0), imp, 0.0)
    total = imp.sum(0)
    local = np.where(total > 0, imp / np.where(total > 0, total, 1.0), prob[:, None])
    return (1.0 - GLOBAL_SHARE) * local + GLOBAL_SHARE * prob[:, None]


def choose_light_numpy(u, probs):
    """(light index (N,), the remainder of u rescaled to [0, 1), the chosen light's probability
    (N,)) for uniform numbers u (N,) and per-point probabilities probs (count, N)."""
    count = probs.shape[0]
    cdf = np.cumsum(probs, axis=0)
    choice = np.minimum((cdf <= u[None, :] * cdf[-1][None, :]).sum(0), count - 1)
    cols = np.arange(u.shape[0])
    chosen = probs[choice, cols]
    lo = cdf[choice, cols] - chosen
    rest = (u * cdf[-1] - lo) / np.where(chosen > 0, chosen, 1.0)
    return choice, np.clip(rest, 0.0, np.nextafter(1.0, 0.0)), chosen


@jit_inner
def _facing(has_n, n, j, t0, t1, t2, dist, sin_alpha):
    if not has_n:
        return 1.0
    cos_t = _clip((n[0, j] * t0 + n[1, j] * t1 + n[2, j] * t2) / maximum_at(dist, 1e-300), -1.0, 1.0)
    theta = maximum_at(np.arccos(cos_t) - np.arcsin(_clip(sin_alpha, 0.0, 1.0)), 0.0)
    return BELOW_HORIZON + (1.0 - BELOW_HORIZON) * maximum_at(np.cos(theta), 0.0)


@jit_inner
def _emitter_side(t0, t1, t2, dist, sin_alpha, n0, n1, n2):
    """``emitter_side`` for one receiver (t: centre − receiver)."""
    cos_e = _clip(-(n0 * t0 + n1 * t1 + n2 * t2) / maximum_at(dist, 1e-300), -1.0, 1.0)
    theta = maximum_at(np.arccos(cos_e) - np.arcsin(_clip(sin_alpha, 0.0, 1.0)), 0.0)
    return maximum_at(np.cos(theta), 0.0)


@jit
def _column_sum(a, j):
    """Σ_i a[i, j] in NumPy's order for a.sum(0) of a one-column array (its pairwise summation:
    eight running sums from 8 rows on; ≤ 128 rows)."""
    n = a.shape[0]
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[i, j]
        return res
    r = np.empty(8)
    for k in range(8):
        r[k] = a[k, j]
    i = 8
    while i < n - (n % 8):
        for k in range(8):
            r[k] += a[i + k, j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += a[i, j]
        i += 1
    return res


@jit
def _probabilities_loop(p, n, has_n, kinds, params, prob, probs):
    count = kinds.shape[0]
    # NumPy sums a (count, N) array over axis 0 row after row, but a single column pairwise
    pairwise = p.shape[1] == 1
    for j in range(p.shape[1]):
        total = 0.0
        for i in range(count):
            kind = kinds[i]
            row = params[i]
            if kind == SELECT_CONSTANT:
                imp = row[0]
            elif kind == SELECT_POINT:
                t0, t1, t2 = row[0] - p[0, j], row[1] - p[1, j], row[2] - p[2, j]
                d2 = t0 * t0 + t1 * t1 + t2 * t2
                dist = np.sqrt(maximum_at(d2, 1e-300))
                falloff = 1.0
                if row[6] != 0:
                    w0, w1, w2 = t0 / dist, t1 / dist, t2 / dist
                    c = -(row[7] * w0 + row[8] * w1 + row[9] * w2)
                    if row[6] == 1:
                        falloff = 1.0 if c >= row[10] else 0.0
                    else:
                        t = _clip((c - row[10]) / (row[11] - row[10]), 0.0, 1.0)
                        falloff = t * t * (3.0 - 2.0 * t)
                imp = row[3] * falloff / maximum_at(d2, row[4]) * _facing(has_n, n, j, t0, t1, t2, dist, row[5] / dist)
            elif kind == SELECT_AREA:
                t0, t1, t2 = row[0] - p[0, j], row[1] - p[1, j], row[2] - p[2, j]
                d2 = t0 * t0 + t1 * t1 + t2 * t2
                dist = np.sqrt(d2)
                sin_alpha = row[5] / maximum_at(dist, 1e-300)
                imp = row[3] / maximum_at(d2, row[4]) * _facing(has_n, n, j, t0, t1, t2, dist, sin_alpha)
                if row[6] != 0:
                    imp = imp * _emitter_side(t0, t1, t2, dist, sin_alpha, row[7], row[8], row[9])
            else:
                imp = row[3] * _facing(has_n, n, j, row[0], row[1], row[2], 1.0, row[4]) * 1.0
            if not (np.isfinite(imp) and imp > 0):
                imp = 0.0
            probs[i, j] = imp
            total += imp
        if pairwise:
            total = _column_sum(probs, j)
        for i in range(count):
            local = probs[i, j] / total if total > 0 else prob[i]
            probs[i, j] = (1.0 - GLOBAL_SHARE) * local + GLOBAL_SHARE * prob[i]


def selection_probabilities_numba(p, n, kinds, params, prob):
    if p.shape[1] == 1 and kinds.shape[0] > 128:       # NumPy's pairwise sum recurses there
        return selection_probabilities_numpy(p, n, kinds, params, prob)
    probs = np.empty((kinds.shape[0], p.shape[1]))
    f64 = np.float64
    has_n = n is not None
    _probabilities_loop(np.ascontiguousarray(p, dtype=f64), np.ascontiguousarray(n if has_n else p, dtype=f64),
                        has_n, np.ascontiguousarray(kinds, dtype=np.int64), np.ascontiguousarray(params, dtype=f64),
                        np.ascontiguousarray(prob, dtype=f64), probs)
    return probs


@jit
def _choose_loop(u, probs, choice, rest, chosen):
    count = probs.shape[0]
    below_one = np.nextafter(1.0, 0.0)
    for j in range(u.shape[0]):
        total = 0.0
        for i in range(count):
            total += probs[i, j]
        x = u[j] * total
        k = 0
        cdf = 0.0
        for i in range(count):
            cdf += probs[i, j]
            if cdf <= x:
                k += 1
        k = min(k, count - 1)
        cdf = 0.0
        for i in range(k + 1):
            cdf += probs[i, j]
        c = probs[k, j]
        lo = cdf - c
        r = (x - lo) / (c if c > 0 else 1.0)
        choice[j] = k
        rest[j] = _clip(r, 0.0, below_one)
        chosen[j] = c


def choose_light_numba(u, probs):
    n = u.shape[0]
    choice, rest, chosen = np.empty(n, np.int64), np.empty(n), np.empty(n)
    _choose_loop(np.ascontiguousarray(u, dtype=np.float64), np.ascontiguousarray(probs, dtype=np.float64),
                 choice, rest, chosen)
    return choice, rest, chosen


#: The compiled twins of selection_probabilities_numpy and choose_light_numpy (None without Numba).
selection_probabilities_numba = _probabilities_loop and selection_probabilities_numba
choose_light_numba = _choose_loop and choose_light_numba
selection_probabilities = twin(selection_probabilities_numba, selection_probabilities_numpy)
choose_light = twin(choose_light_numba, choose_light_numpy)


# ----------------------------------------------------------------------------- point and spot lights

@jit_inner
def _spot(spot, w0, w1, w2):
    """The spot attenuation of engine.kernels.light_sampling.spot_falloff towards −w (spot: [kind,
    ax, ay, az, cos_outer, cos_inner], kind 0 none, 1 hard edge, 2 smoothstep)."""
    if spot[0] == 0:
        return 1.0
    c = -(spot[1] * w0 + spot[2] * w1 + spot[3] * w2)
    if spot[0] == 1:
        return 1.0 if c >= spot[4] else 0.0
    t = _clip((c - spot[4]) / (spot[5] - spot[4]), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


@jit
def _point_light_loop(p, u1, u2, position, radius, soft, delta, spot, wi, dist, scale, pdf, valid):
    r = radius
    two_pi = 2.0 * math.pi
    for j in range(p.shape[1]):
        t0, t1, t2 = position[0] - p[0, j], position[1] - p[1, j], position[2] - p[2, j]
        d2 = t0 * t0 + t1 * t1 + t2 * t2
        d = np.sqrt(d2)
        ok = d > 0
        s = d if ok else 1.0
        w0, w1, w2 = t0 / s, t1 / s, t2 / s
        if delta:
            wi[0, j], wi[1, j], wi[2, j] = w0, w1, w2
            dist[j] = d
            scale[j] = _spot(spot, w0, w1, w2) / d2 if ok else 0.0
            pdf[j] = 0.0
            valid[j] = ok
            continue
        if soft:
            # a disk ⟂ wi facing p, uniform by area
            rho = r * np.sqrt(u1[j])
            phi = two_pi * u2[j]
            o0, o1, o2 = to_world_at(-w0, -w1, -w2, rho * np.cos(phi), rho * np.sin(phi), 0.0)
            s0, s1, s2 = t0 + o0, t1 + o1, t2 + o2
            e2 = s0 * s0 + s1 * s1 + s2 * s2
            e = np.sqrt(e2)
            q = e if e > 0 else 1.0
            v0, v1, v2 = s0 / q, s1 / q, s2 / q
            cos_l = v0 * w0 + v1 * w1 + v2 * w2
            ok = ok and cos_l > 0 and e > 0
            wi[0, j], wi[1, j], wi[2, j] = v0, v1, v2
            dist[j] = e
            pdf[j] = e2 / (cos_l * math.pi * r * r) if ok else 0.0
            scale[j] = _spot(spot, v0, v1, v2) * cos_l / e2 if ok else 0.0     # by the sampled ray, as Cycles
            valid[j] = ok
            continue
        # a sphere: uniform in its cone, the hit distance by the law of cosines
        ok = ok and d > r
        sin2 = minimum_at(r * r / (d2 if ok else 1.0), 1.0)
        omc_max = sin2 / (1.0 + np.sqrt(1.0 - sin2))
        omc = u1[j] * omc_max
        cos_t = 1.0 - omc
        sin_t = np.sqrt(maximum_at(omc * (2.0 - omc), 0.0))
        phi = two_pi * u2[j]
        v0, v1, v2 = to_world_at(w0, w1, w2, sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t)
        t = d * cos_t - np.sqrt(maximum_at(r * r - d2 * (1.0 - cos_t * cos_t), 0.0))
        wi[0, j], wi[1, j], wi[2, j] = v0, v1, v2
        dist[j] = maximum_at(t, 0.0)
        pdf[j] = 1.0 / (two_pi * omc_max) if ok else 0.0
        scale[j] = _spot(spot, v0, v1, v2) * 2.0 * omc_max / (r * r) if ok else 0.0
        valid[j] = ok


def point_light_sample_numba(p, u, position, radius, soft_falloff, spot):
    n = p.shape[1]
    wi, dist, scale, pdf, valid = np.empty((3, n)), np.empty(n), np.empty(n), np.empty(n), np.empty(n, np.bool_)
    f64 = np.float64
    _point_light_loop(np.ascontiguousarray(p, dtype=f64), np.ascontiguousarray(u[1], dtype=f64),
                      np.ascontiguousarray(u[2], dtype=f64), np.asarray(position, f64), float(radius),
                      bool(soft_falloff), radius <= 0, np.asarray(spot, f64), wi, dist, scale, pdf, valid)
    return wi, dist, scale, pdf, valid


#: The compiled twin of engine.render.lights.point_light_sample_numpy (None without Numba).
point_light_sample_numba = _point_light_loop and point_light_sample_numba


def lamp_hits_numpy(o, d, seg, position, radius, soft_falloff):
    """Rays o + t·d (3, N), 0 < t < seg (N,), that reach a point light's disk (``soft_falloff``: radius
    ``radius`` about ``position``, facing the ray origin, as Cycles' point_light_intersect) or sphere:
    (hit mask (N,), t (N,), cosθ at the disk (N,), 1 for the sphere)."""
    r = radius
    c = position[:, None]
    to_c = c - o
    dist2 = dot(to_c, to_c)
    dist = np.sqrt(dist2)
    if soft_falloff:
        n = -to_c / np.where(dist > 0, dist, 1.0)           # disk normal, towards the origin
        cos_l = -dot(d, n)
        t = dist / np.where(cos_l > 0, cos_l, 1.0)
        x = o + d * t[None, :] - c
        ok = (cos_l > 0) & (dist > 0) & (dot(x, x) <= r * r)
    else:
        along = dot(to_c, d)
        disc = along * along - (dist2 - r * r)
        t = along - np.sqrt(np.maximum(disc, 0.0))
        ok = (dist > r) & (disc >= 0) & (along > 0)
        cos_l = np.ones_like(t)
    ok &= (t > 0) & (t < seg)
    return ok, t, cos_l


@jit
def _lamp_hits_loop(o, d, seg, position, r, soft, ok, t_out, cos_out):
    for j in range(o.shape[1]):
        c0, c1, c2 = position[0] - o[0, j], position[1] - o[1, j], position[2] - o[2, j]
        d0, d1, d2 = d[0, j], d[1, j], d[2, j]
        dist2 = c0 * c0 + c1 * c1 + c2 * c2
        dist = np.sqrt(dist2)
        if soft:
            s = dist if dist > 0 else 1.0
            n0, n1, n2 = -c0 / s, -c1 / s, -c2 / s
            cos_l = -(d0 * n0 + d1 * n1 + d2 * n2)
            t = dist / (cos_l if cos_l > 0 else 1.0)
            x0 = o[0, j] + d0 * t - position[0]
            x1 = o[1, j] + d1 * t - position[1]
            x2 = o[2, j] + d2 * t - position[2]
            hit = cos_l > 0 and dist > 0 and x0 * x0 + x1 * x1 + x2 * x2 <= r * r
        else:
            along = c0 * d0 + c1 * d1 + c2 * d2
            disc = along * along - (dist2 - r * r)
            t = along - np.sqrt(maximum_at(disc, 0.0))
            hit = dist > r and disc >= 0 and along > 0
            cos_l = 1.0
        ok[j] = hit and t > 0 and t < seg[j]
        t_out[j] = t
        cos_out[j] = cos_l


def lamp_hits_numba(o, d, seg, position, radius, soft_falloff):
    n = o.shape[1]
    ok, t, cos_l = np.empty(n, np.bool_), np.empty(n), np.empty(n)
    f64 = np.float64
    _lamp_hits_loop(np.ascontiguousarray(o, dtype=f64), np.ascontiguousarray(d, dtype=f64),
                    np.ascontiguousarray(np.broadcast_to(seg, (n,)), dtype=f64), np.asarray(position, f64),
                    float(radius), bool(soft_falloff), ok, t, cos_l)
    return ok, t, cos_l


#: The compiled twin of lamp_hits_numpy (None without Numba).
lamp_hits_numba = _lamp_hits_loop and lamp_hits_numba
lamp_hits = twin(lamp_hits_numba, lamp_hits_numpy)
