"""The light tree's traversal (engine.render.lights.tree): the choice of an emitter per shading point and the
probability of choosing a given one, as compiled per-point loops with their NumPy twins.

The arithmetic is Cycles' kernel/light/tree.h (light_tree_importance, light_tree_node_importance,
light_tree_emitter_importance with the per-kind parameters of kernel/light/{triangle, point, spot, area, distant,
background}.h, get_left_probability, light_tree_cluster_select_emitter, light_tree_pdf) in float64; the twins
perform the same operations in the same order (sums of three products left to right, leaf totals as running
sums), so they give the same bits.  The tree's arrays are a ``TreeArrays``; points p and side normals n (3, N)
(a zero n: a transmitting vertex, light from either side counts), world units, angles in radians.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from . import jit, jit_inner, twin

#: emitter kinds
TRIANGLE, POINT, SPOT, MESH, DISTANT, BACKGROUND = range(6)
#: the choice where no emitter can light the point (every importance on the way 0): no light sample
NO_LIGHT = -1


class TreeArrays(NamedTuple):
    """A built light tree.  Nodes (K): box ``node_lo``/``node_hi`` (K, 3), cone ``node_axis`` (K, 3),
    ``node_theta_o``, ``node_theta_e``, ``node_trig`` (K, 4) = (cos θ_o, sin θ_o, cos(θ_o + θ_e), cos(θ_e − θ_o)),
    ``node_energy``, the box's ``node_centre``, ``node_extent`` (hi − centre) (K, 3), ``node_r2`` = |extent|²,
    ``node_half_r`` = ½|extent| (``box_measures``), children ``node_left``/``node_right`` (−1: a leaf), a leaf's
    emitters ``node_first`` … + ``node_count``, ``node_distant`` (the distant lights' leaf).  Emitters (E, in
    leaf order): ``em_kind``, ``em_centre`` (E, 3), cone ``em_axis``, ``em_theta_o`` (a point light's 0: its cone
    faces the shading point), ``em_theta_e``, ``em_trig`` (E, 4) as ``node_trig``, ``em_energy``, lamp
    ``em_radius``/``em_sphere``, spot edge ``em_cos_outer``/``em_cos_inner``, ``em_corners`` (E, 8, 3) (a
    triangle's vertices repeated, a box's corners), ``em_light``, ``em_tri`` (−1: a whole light).  Per emitter the
    way from the root: ``path_node`` (D, E) (−1 padding) and ``path_right`` (D, E), its leaf ``leaf_of`` (E,);
    ``root`` (−1: no emitter)."""
    node_lo: np.ndarray
    node_hi: np.ndarray
    node_axis: np.ndarray
    node_theta_o: np.ndarray
    node_theta_e: np.ndarray
    node_trig: np.ndarray
    node_energy: np.ndarray
    node_centre: np.ndarray
    node_extent: np.ndarray
    node_r2: np.ndarray
    node_half_r: np.ndarray
    node_left: np.ndarray
    node_right: np.ndarray
    node_first: np.ndarray
    node_count: np.ndarray
    node_distant: np.ndarray
    em_kind: np.ndarray
    em_centre: np.ndarray
    em_axis: np.ndarray
    em_theta_o: np.ndarray
    em_theta_e: np.ndarray
    em_trig: np.ndarray
    em_energy: np.ndarray
    em_radius: np.ndarray
    em_sphere: np.ndarray
    em_cos_outer: np.ndarray
    em_cos_inner: np.ndarray
    em_corners: np.ndarray
    em_light: np.ndarray
    em_tri: np.ndarray
    path_node: np.ndarray
    path_right: np.ndarray
    leaf_of: np.ndarray
    root: int
    #: the same arrays row by row for the compiled loops (``pack``)
    packed: tuple = ()


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _sin(c):
    return np.sqrt(np.maximum(1.0 - c * c, 0.0))


def _unit(v):
    """v (3, M) / |v| and |v| (0 stays 0)."""
    length = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return v / np.where(length > 0, length, 1.0), length


# ----------------------------------------------------------------------------- NumPy reference

def importance_numpy(n, ptc, cos_u, axis, theta_o, theta_e, trig, d_max, d_min, energy):
    """Cycles' light_tree_importance (surface form): (I⁺, I⁻) (M,) of clusters or emitters seen from points with
    side normals n (3, M), unit directions ptc (3, M) towards their centres, half-angles acos(cos_u) they
    subtend, cones (axis (3, M), θ_o, θ_e, their cosines ``trig`` (4, M) as TreeArrays.node_trig), distances
    d_max ≥ d_min and energies (M,)."""
    sin_u = _sin(cos_u)
    transmits = (n[0] == 0) & (n[1] == 0) & (n[2] == 0)
    cos_i = _dot(ptc, n)
    sin_i = _sin(cos_i)
    cos_min_inc = np.where(transmits | (cos_i >= cos_u), 1.0, cos_i * cos_u + sin_i * sin_u)
    cos_max_inc = np.where(transmits, 1.0, np.maximum(cos_i * cos_u - sin_i * sin_u, 0.0))
    cos_t = np.clip(-_dot(axis, ptc), -1.0, 1.0)
    sin_t = _sin(cos_t)
    cos_tmu = cos_t * cos_u + sin_t * sin_u
    cos_o, sin_o = trig[0], trig[1]
    inside = (cos_t >= cos_u) | (cos_tmu >= cos_o)
    cos_min_out = np.where(inside, 1.0, cos_tmu * cos_o + _sin(cos_tmu) * sin_o)
    visible = (inside | (theta_o + theta_e > math.pi) | (cos_tmu > trig[2])) & (cos_min_inc >= 0)
    i_max = np.where(visible, np.abs(cos_min_inc * energy * cos_min_out / np.maximum(d_min * d_min, 1e-300)), 0.0)
    cos_tpu = cos_t * cos_u - sin_t * sin_u
    lower = ~((theta_e - theta_o < 0) | (cos_t < 0) | (cos_u < 0) | (cos_tpu < trig[3]))
    cos_max_out = cos_tpu * cos_o - _sin(cos_tpu) * sin_o
    i_min = np.where(visible & lower,
                     np.abs(cos_max_inc * energy * cos_max_out / np.maximum(d_max * d_max, 1e-300)), 0.0)
    return i_max, np.minimum(i_min, i_max)


def _spot_edge(cos_a, cos_outer, cos_inner):
    """A spot's falloff at cos of the angle to its axis: 1 inside cos_inner, 0 outside cos_outer, smoothstep."""
    hard = cos_inner <= cos_outer
    t = np.clip((cos_a - cos_outer) / np.where(hard, 1.0, cos_inner - cos_outer), 0.0, 1.0)
    return np.where(hard, np.where(cos_a >= cos_outer, 1.0, 0.0), t * t * (3.0 - 2.0 * t))


def emitter_importance_numpy(t: TreeArrays, e, p, n):
    """(I⁺, I⁻) (M,) of emitters e (M,) at points p (3, M) with side normals n (3, M)."""
    kind = t.em_kind[e]
    ptc, d = _unit(t.em_centre[e].T - p)
    d_min, d_max = d.copy(), d.copy()
    cos_u = np.ones(e.shape[0])
    axis = t.em_axis[e].T.copy()
    theta_o, theta_e, trig, energy = t.em_theta_o[e], t.em_theta_e[e], t.em_trig[e].T, t.em_energy[e].copy()
    visible = np.ones(e.shape[0], bool)
    transmits = (n[0] == 0) & (n[1] == 0) & (n[2] == 0)
    poly = (kind == TRIANGLE) | (kind == MESH)
    if poly.any():          # the corners: a triangle's three (repeated), a box's eight
        r = np.flatnonzero(poly)
        corners = t.em_corners[e[r]]                          # (m, 8, 3)
        pr, cr, nr = p[:, r], ptc[:, r], n[:, r]
        cos_min = np.full(r.size, np.inf)
        far = d[r].copy()
        above = transmits[r].copy()
        for k in range(8):
            to, dist_c = _unit(corners[:, k].T - pr)
            cos_min = np.minimum(cos_min, _dot(to, cr))
            far = np.maximum(far, dist_c)
            above |= _dot(to, nr) > 0
        cos_u[r], d_max[r] = cos_min, far
        front = (theta_o[r] != 0) | (_dot(axis[:, r], cr) < 0)
        visible[r] = above & front
    lamp = (kind == POINT) | (kind == SPOT)
    if lamp.any():
        r = np.flatnonzero(lamp)
        rad, dr = t.em_radius[e[r]], np.maximum(d[r], 1e-300)
        sphere = t.em_sphere[e[r]]
        outside = dr > rad
        cos_sph = np.where(outside, _sin(np.minimum(rad / dr, 1.0)), -1.0)
        hyp = np.sqrt(rad * rad + dr * dr)
        inner = rad / math.sqrt(2.0)
        cos_u[r] = np.where(sphere, cos_sph, dr / hyp)
        d_max[r] = np.where(sphere, np.where(outside, dr / np.where(outside, cos_sph, 1.0), inner), hyp)
        d_min[r] = np.where(sphere & ~outside, inner, d[r])
        point = kind[r] == POINT
        axis[:, r] = np.where(point[None], -ptc[:, r], axis[:, r])      # a point light's cone faces p
        s = r[~point]
        if s.size:          # the spot's falloff at the least angle to its axis (Cycles' spot energy)
            cos_a = np.clip(-_dot(axis[:, s], ptc[:, s]), -1.0, 1.0)
            cos_m = np.cos(np.maximum(0.0, np.arccos(cos_a) - np.arccos(np.clip(cos_u[s], -1.0, 1.0))))
            energy[s] = energy[s] * _spot_edge(cos_m, t.em_cos_outer[e[s]], t.em_cos_inner[e[s]])
    sun = kind == DISTANT
    if sun.any():           # a disc at distance 1 in the direction the light comes from
        r = np.flatnonzero(sun)
        ptc[:, r] = -axis[:, r]
        cos_u[r] = trig[2, r]           # cos θ_e (θ_o = 0)
        d_max[r], d_min[r] = 1.0 / cos_u[r], 1.0
    sky = kind == BACKGROUND
    if sky.any():           # the whole sphere
        r = np.flatnonzero(sky)
        ptc[:, r] = -axis[:, r]
        cos_u[r], d_max[r], d_min[r] = -1.0, 1.0, 1.0
    i_max, i_min = importance_numpy(n, ptc, cos_u, axis, theta_o, theta_e, trig, d_max, d_min, energy)
    return np.where(visible, i_max, 0.0), np.where(visible, i_min, 0.0)


def node_importance_numpy(t: TreeArrays, k, p, n):
    """(I⁺, I⁻) (M,) of nodes k (M,) (Cycles' light_tree_child_importance): a leaf of one emitter by that
    emitter's own importance, another node by its box and cone (the distant leaf by its cone alone)."""
    single = t.node_count[k] == 1
    i_max, i_min = np.zeros(k.shape[0]), np.zeros(k.shape[0])
    if single.any():
        r = np.flatnonzero(single)
        i_max[r], i_min[r] = emitter_importance_numpy(t, t.node_first[k[r]], p[:, r], n[:, r])
    r = np.flatnonzero(~single)
    if r.size:
        kk, pp, nn = k[r], p[:, r], n[:, r]
        centre, extent = t.node_centre[kk].T, t.node_extent[kk].T
        axis, theta_o, theta_e, trig = t.node_axis[kk].T, t.node_theta_o[kk], t.node_theta_e[kk], t.node_trig[kk].T
        transmits = (nn[0] == 0) & (nn[1] == 0) & (nn[2] == 0)
        ptc, d = _unit(centre - pp)
        r2 = t.node_r2[kk]
        cos_u = np.where(d * d <= r2, -1.0, np.sqrt(np.maximum(1.0 - r2 / np.maximum(d * d, 1e-300), 0.0)))
        d = np.maximum(t.node_half_r[kk], d)
        visible = transmits | (_dot(nn, centre - pp) + _dot(np.abs(nn), np.abs(extent)) > 0)
        distant = t.node_distant[kk]
        ptc = np.where(distant[None], -axis, ptc)
        cos_u = np.where(distant, np.where(theta_o + theta_e < math.pi, trig[2], -1.0), cos_u)
        d = np.where(distant, 1.0, d)
        visible |= distant
        a, b = importance_numpy(nn, ptc, cos_u, axis, theta_o, theta_e, trig, d, d, t.node_energy[kk])
        i_max[r], i_min[r] = np.where(visible, a, 0.0), np.where(visible, b, 0.0)
    return i_max, i_min


def left_probability_numpy(t: TreeArrays, k, p, n):
    """(probability (M,) of the left child of inner nodes k, valid (M,): some child can light the point)."""
    l_max, l_min = node_importance_numpy(t, t.node_left[k], p, n)
    r_max, r_min = node_importance_numpy(t, t.node_right[k], p, n)
    t_max, t_min = l_max + r_max, l_min + r_min
    ok = t_max > 0
    p_max = l_max / np.where(ok, t_max, 1.0)
    p_min = np.where(t_min > 0, l_min / np.where(t_min > 0, t_min, 1.0),
                     0.5 * (np.where(l_max > 0, 1.0, 0.0) + np.where(r_max == 0, 1.0, 0.0)))
    return 0.5 * (p_max + p_min), ok


def leaf_probabilities_numpy(t: TreeArrays, k, p, n):
    """(emitters (W, M) of leaves k (−1 padding), the shares (W, M) of each by the upper bounds I⁺/ΣI⁺ and by
    the lower ones I⁻/ΣI⁻ (uniform over I⁺ > 0 where ΣI⁻ = 0)); an emitter's probability is their mean."""
    first, count = t.node_first[k], t.node_count[k]
    width = int(count.max()) if k.size else 0
    slot = np.arange(width)[:, None]
    e = np.where(slot < count[None], first[None] + slot, -1)
    i_max, i_min = np.zeros(e.shape), np.zeros(e.shape)
    for w in range(width):
        r = np.flatnonzero(e[w] >= 0)
        i_max[w, r], i_min[w, r] = emitter_importance_numpy(t, e[w, r], p[:, r], n[:, r])
    s_max, s_min = np.cumsum(i_max, axis=0)[-1], np.cumsum(i_min, axis=0)[-1]
    has = i_max > 0
    n_has = has.sum(axis=0)
    q_max = i_max / np.where(s_max > 0, s_max, 1.0)
    q_min = np.where(s_min > 0, i_min / np.where(s_min > 0, s_min, 1.0),
                     np.where(has, 1.0 / np.maximum(n_has, 1), 0.0))
    return e, q_max, q_min


def choose_numpy(t: TreeArrays, u, p, n):
    """(light (N,) (NO_LIGHT: none), the rest of u rescaled to [0, 1), the pick probability (N,), the chosen
    triangle (N,) or −1 for a whole light) for numbers u (N,) at points p, n (3, N)."""
    N = u.shape[0]
    light, tri = np.full(N, NO_LIGHT, np.int64), np.full(N, -1, np.int64)
    prob, rest = np.zeros(N), np.zeros(N)
    if t.root < 0 or N == 0:
        return light, rest, prob, tri
    node = np.full(N, t.root, np.int64)
    pdf = np.ones(N)
    u = np.array(u, np.float64)
    alive = np.ones(N, bool)
    below = np.nextafter(1.0, 0.0)
    while True:
        at = np.flatnonzero(alive & (t.node_left[node] >= 0))
        if not at.size:
            break
        q, ok = left_probability_numpy(t, node[at], p[:, at], n[:, at])
        ua = u[at]
        go_left = ua < q
        uu = np.where(go_left, ua / np.where(q > 0, q, 1.0), (ua - q) / np.where(q < 1, 1.0 - q, 1.0))
        u[at] = np.minimum(np.maximum(uu, 0.0), below)
        pdf[at] = pdf[at] * np.where(go_left, q, 1.0 - q)
        node[at] = np.where(go_left, t.node_left[node[at]], t.node_right[node[at]])
        alive[at] = ok
    at = np.flatnonzero(alive)
    if not at.size:
        return light, rest, prob, tri
    e, q_max, q_min = leaf_probabilities_numpy(t, node[at], p[:, at], n[:, at])
    ua = u[at]
    several = t.node_count[node[at]] > 1
    by_max = ua > 0.5
    ua = np.where(several, np.minimum(np.maximum(2.0 * ua - np.where(by_max, 1.0, 0.0), 0.0), below), ua)
    by_max |= ~several
    q = np.where(by_max[None], q_max, q_min)
    cdf = np.cumsum(q, axis=0)
    total = cdf[-1]
    target = ua * total
    pick = np.minimum((cdf <= target[None]).sum(axis=0), t.node_count[node[at]] - 1)
    cols = np.arange(at.size)
    pick = np.where(q[pick, cols] > 0, pick, np.argmax(q > 0, axis=0))     # never a slot of probability 0
    chosen = q[pick, cols]
    lo = cdf[pick, cols] - chosen
    ok = (total > 0) & (chosen > 0)
    rest_a = np.minimum(np.maximum((target - lo) / np.where(chosen > 0, chosen, 1.0), 0.0), below)
    emitter = e[pick, cols]
    good = at[ok]
    light[good] = t.em_light[emitter[ok]]
    tri[good] = t.em_tri[emitter[ok]]
    prob[good] = pdf[good] * (0.5 * (q_max[pick, cols] + q_min[pick, cols]))[ok]
    rest[good] = rest_a[ok]
    return light, rest, prob, tri


def probability_numpy(t: TreeArrays, emitter, p, n):
    """The probability (M,) that ``choose`` at points p, n (3, M) picks the emitters ``emitter`` (M,) (−1: 0),
    re-traversing their nodes from the root (Cycles' light_tree_pdf)."""
    M = emitter.shape[0]
    out = np.zeros(M)
    if t.root < 0 or M == 0:
        return out
    ok = emitter >= 0
    pdf = np.where(ok, 1.0, 0.0)
    e = np.maximum(emitter, 0)
    for level in range(t.path_node.shape[0]):
        k = t.path_node[level, e]
        at = np.flatnonzero(ok & (k >= 0) & (pdf > 0))
        if not at.size:
            continue
        q, valid = left_probability_numpy(t, k[at], p[:, at], n[:, at])
        step = np.where(t.path_right[level, e[at]], 1.0 - q, q)
        pdf[at] = np.where(valid, pdf[at] * step, 0.0)
    at = np.flatnonzero(ok & (pdf > 0))
    if at.size:
        leaf = t.leaf_of[e[at]]
        _, q_max, q_min = leaf_probabilities_numpy(t, leaf, p[:, at], n[:, at])
        slot = e[at] - t.node_first[leaf]
        cols = np.arange(at.size)
        out[at] = pdf[at] * (0.5 * (q_max[slot, cols] + q_min[slot, cols]))
    return out


# ----------------------------------------------------------------------------- compiled loops

@jit_inner
def _sin_at(c):
    return np.sqrt(max(1.0 - c * c, 0.0))


@jit_inner
def _importance_at(n0, n1, n2, c0, c1, c2, cos_u, a0, a1, a2, theta_o, theta_e, cos_o, sin_o, cos_sum, cos_diff,
                   d_max, d_min, energy):
    """importance_numpy for one point and cluster (``cos_o`` … ``cos_diff``: the cone's TreeArrays.node_trig)."""
    sin_u = _sin_at(cos_u)
    transmits = n0 == 0 and n1 == 0 and n2 == 0
    cos_i = c0 * n0 + c1 * n1 + c2 * n2
    sin_i = _sin_at(cos_i)
    cos_min_inc = 1.0 if (transmits or cos_i >= cos_u) else cos_i * cos_u + sin_i * sin_u
    cos_max_inc = 1.0 if transmits else max(cos_i * cos_u - sin_i * sin_u, 0.0)
    cos_t = -(a0 * c0 + a1 * c1 + a2 * c2)
    cos_t = min(max(cos_t, -1.0), 1.0)
    sin_t = _sin_at(cos_t)
    cos_tmu = cos_t * cos_u + sin_t * sin_u
    inside = cos_t >= cos_u or cos_tmu >= cos_o
    cos_min_out = 1.0 if inside else cos_tmu * cos_o + _sin_at(cos_tmu) * sin_o
    visible = (inside or theta_o + theta_e > math.pi or cos_tmu > cos_sum) and cos_min_inc >= 0
    if not visible:
        return 0.0, 0.0
    i_max = abs(cos_min_inc * energy * cos_min_out / max(d_min * d_min, 1e-300))
    cos_tpu = cos_t * cos_u - sin_t * sin_u
    if theta_e - theta_o < 0 or cos_t < 0 or cos_u < 0 or cos_tpu < cos_diff:
        return i_max, 0.0
    cos_max_out = cos_tpu * cos_o - _sin_at(cos_tpu) * sin_o
    i_min = abs(cos_max_inc * energy * cos_max_out / max(d_max * d_max, 1e-300))
    return i_max, min(i_min, i_max)


# The compiled loops read the tree from four packed arrays (``pack``: one row per node or emitter), so that a
# helper call passes four array structs instead of two dozen.
_MID, _EXT, _AXIS, _THETA_O, _THETA_E, _TRIG, _ENERGY, _R2, _HALF_R = 0, 3, 6, 9, 10, 11, 15, 16, 17  # node_f
_LEFT, _RIGHT, _FIRST, _COUNT, _DISTANT = range(5)                                             # node_i columns
_CENTRE, _EAXIS, _ETHETA_O, _ETHETA_E, _ETRIG, _EENERGY, _RADIUS, _COS_OUTER, _COS_INNER, _CORNERS = (
    0, 3, 6, 7, 8, 12, 13, 14, 15, 16)                                                         # em_f columns
_KIND, _SPHERE, _LIGHT, _TRI = range(4)                                                        # em_i columns


def pack(t: TreeArrays):
    """(node_f (K, 18), node_i (K, 5), em_f (E, 40), em_i (E, 4)): the tree's arrays row by row for the loops."""
    node_f = np.concatenate((t.node_centre, t.node_extent, t.node_axis, t.node_theta_o[:, None],
                             t.node_theta_e[:, None], t.node_trig, t.node_energy[:, None], t.node_r2[:, None],
                             t.node_half_r[:, None]), axis=1)
    node_i = np.stack((t.node_left, t.node_right, t.node_first, t.node_count, t.node_distant.astype(np.int64)), axis=1)
    em_f = np.concatenate((t.em_centre, t.em_axis, t.em_theta_o[:, None], t.em_theta_e[:, None], t.em_trig,
                           t.em_energy[:, None], t.em_radius[:, None], t.em_cos_outer[:, None],
                           t.em_cos_inner[:, None], t.em_corners.reshape(-1, 24)), axis=1)
    em_i = np.stack((t.em_kind, t.em_sphere.astype(np.int64), t.em_light, t.em_tri), axis=1)
    return tuple(np.ascontiguousarray(a) for a in (node_f, node_i.astype(np.int64), em_f, em_i.astype(np.int64)))


@jit_inner
def _emitter_importance_at(e, p0, p1, p2, n0, n1, n2, em_f, em_i):
    """emitter_importance_numpy for emitter e at one point."""
    kind = em_i[e, _KIND]
    v0, v1, v2 = em_f[e, _CENTRE] - p0, em_f[e, _CENTRE + 1] - p1, em_f[e, _CENTRE + 2] - p2
    d = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    div = d if d > 0 else 1.0
    c0, c1, c2 = v0 / div, v1 / div, v2 / div
    d_min, d_max, cos_u = d, d, 1.0
    a0, a1, a2 = em_f[e, _EAXIS], em_f[e, _EAXIS + 1], em_f[e, _EAXIS + 2]
    theta_o, theta_e, energy = em_f[e, _ETHETA_O], em_f[e, _ETHETA_E], em_f[e, _EENERGY]
    transmits = n0 == 0 and n1 == 0 and n2 == 0
    if kind == TRIANGLE or kind == MESH:
        cos_min, far, above = np.inf, d, transmits
        for k in range(3 if kind == TRIANGLE else 8):       # (a triangle's other five are repeats: same min, max)
            col = _CORNERS + 3 * k
            w0, w1, w2 = em_f[e, col] - p0, em_f[e, col + 1] - p1, em_f[e, col + 2] - p2
            dc = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
            dv = dc if dc > 0 else 1.0
            w0, w1, w2 = w0 / dv, w1 / dv, w2 / dv
            cos_min = min(cos_min, w0 * c0 + w1 * c1 + w2 * c2)
            far = max(far, dc)
            above = above or (w0 * n0 + w1 * n1 + w2 * n2) > 0
        cos_u, d_max = cos_min, far
        front = theta_o != 0 or (a0 * c0 + a1 * c1 + a2 * c2) < 0
        if not (above and front):
            return 0.0, 0.0
    elif kind == POINT or kind == SPOT:
        rad, dr = em_f[e, _RADIUS], max(d, 1e-300)
        outside = dr > rad
        cos_sph = _sin_at(min(rad / dr, 1.0)) if outside else -1.0
        hyp = np.sqrt(rad * rad + dr * dr)
        inner = rad / math.sqrt(2.0)
        if em_i[e, _SPHERE] != 0:
            cos_u = cos_sph
            d_max = dr / cos_sph if outside else inner
            d_min = d if outside else inner
        else:
            cos_u = dr / hyp
            d_max = hyp
        if kind == POINT:
            a0, a1, a2 = -c0, -c1, -c2
        else:
            cos_a = min(max(-(a0 * c0 + a1 * c1 + a2 * c2), -1.0), 1.0)
            cos_m = np.cos(max(0.0, np.arccos(cos_a) - np.arccos(min(max(cos_u, -1.0), 1.0))))
            lo, hi = em_f[e, _COS_OUTER], em_f[e, _COS_INNER]
            if hi <= lo:
                edge = 1.0 if cos_m >= lo else 0.0
            else:
                x = min(max((cos_m - lo) / (hi - lo), 0.0), 1.0)
                edge = x * x * (3.0 - 2.0 * x)
            energy = energy * edge
    elif kind == DISTANT:
        c0, c1, c2 = -a0, -a1, -a2
        cos_u = em_f[e, _ETRIG + 2]
        d_max, d_min = 1.0 / cos_u, 1.0
    else:
        c0, c1, c2 = -a0, -a1, -a2
        cos_u, d_max, d_min = -1.0, 1.0, 1.0
    return _importance_at(n0, n1, n2, c0, c1, c2, cos_u, a0, a1, a2, theta_o, theta_e, em_f[e, _ETRIG],
                          em_f[e, _ETRIG + 1], em_f[e, _ETRIG + 2], em_f[e, _ETRIG + 3], d_max, d_min, energy)


@jit_inner
def _node_importance_at(k, p0, p1, p2, n0, n1, n2, node_f, node_i, em_f, em_i):
    """node_importance_numpy for node k at one point."""
    if node_i[k, _COUNT] == 1:
        return _emitter_importance_at(node_i[k, _FIRST], p0, p1, p2, n0, n1, n2, em_f, em_i)
    m0, m1, m2 = node_f[k, _MID], node_f[k, _MID + 1], node_f[k, _MID + 2]
    x0, x1, x2 = node_f[k, _EXT], node_f[k, _EXT + 1], node_f[k, _EXT + 2]
    a0, a1, a2 = node_f[k, _AXIS], node_f[k, _AXIS + 1], node_f[k, _AXIS + 2]
    theta_o, theta_e = node_f[k, _THETA_O], node_f[k, _THETA_E]
    transmits = n0 == 0 and n1 == 0 and n2 == 0
    v0, v1, v2 = m0 - p0, m1 - p1, m2 - p2
    d = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    div = d if d > 0 else 1.0
    c0, c1, c2 = v0 / div, v1 / div, v2 / div
    r2 = node_f[k, _R2]
    cos_u = -1.0 if d * d <= r2 else np.sqrt(max(1.0 - r2 / max(d * d, 1e-300), 0.0))
    d = max(node_f[k, _HALF_R], d)
    visible = transmits or ((n0 * v0 + n1 * v1 + n2 * v2)
                            + (abs(n0) * abs(x0) + abs(n1) * abs(x1) + abs(n2) * abs(x2))) > 0
    if node_i[k, _DISTANT] != 0:
        c0, c1, c2 = -a0, -a1, -a2
        cos_u = node_f[k, _TRIG + 2] if theta_o + theta_e < math.pi else -1.0
        d = 1.0
        visible = True
    if not visible:
        return 0.0, 0.0
    return _importance_at(n0, n1, n2, c0, c1, c2, cos_u, a0, a1, a2, theta_o, theta_e, node_f[k, _TRIG],
                          node_f[k, _TRIG + 1], node_f[k, _TRIG + 2], node_f[k, _TRIG + 3], d, d, node_f[k, _ENERGY])


@jit_inner
def _left_probability_at(k, p0, p1, p2, n0, n1, n2, node_f, node_i, em_f, em_i):
    """left_probability_numpy for inner node k at one point."""
    l_max, l_min = _node_importance_at(node_i[k, _LEFT], p0, p1, p2, n0, n1, n2, node_f, node_i, em_f, em_i)
    r_max, r_min = _node_importance_at(node_i[k, _RIGHT], p0, p1, p2, n0, n1, n2, node_f, node_i, em_f, em_i)
    t_max, t_min = l_max + r_max, l_min + r_min
    ok = t_max > 0
    p_max = l_max / (t_max if ok else 1.0)
    if t_min > 0:
        p_min = l_min / t_min
    else:
        p_min = 0.5 * ((1.0 if l_max > 0 else 0.0) + (1.0 if r_max == 0 else 0.0))
    return 0.5 * (p_max + p_min), ok


@jit_inner
def _leaf_at(k, p0, p1, p2, n0, n1, n2, node_i, em_f, em_i, i_max, i_min):
    """Fills i_max, i_min (≥ count) with leaf k's emitters' importances; returns (ΣI⁺, ΣI⁻, count with I⁺ > 0)."""
    first, count = node_i[k, _FIRST], node_i[k, _COUNT]
    s_max, s_min, n_has = 0.0, 0.0, 0
    for w in range(count):
        a, b = _emitter_importance_at(first + w, p0, p1, p2, n0, n1, n2, em_f, em_i)
        i_max[w], i_min[w] = a, b
        s_max += a
        s_min += b
        if a > 0:
            n_has += 1
    return s_max, s_min, n_has


@jit_inner
def _share(w, by_max, i_max, i_min, s_max, s_min, n_has):
    """The leaf share of slot w by the upper (by_max) or lower bounds (leaf_probabilities_numpy)."""
    if by_max:
        return i_max[w] / (s_max if s_max > 0 else 1.0)
    if s_min > 0:
        return i_min[w] / s_min
    return 1.0 / max(n_has, 1) if i_max[w] > 0 else 0.0


@jit
def _choose_loop(u, p, n, root, node_f, node_i, em_f, em_i, light, rest, prob, tri):
    below = np.nextafter(1.0, 0.0)
    width = max(1, node_i[:, _COUNT].max()) if node_i.shape[0] else 1
    i_max, i_min = np.empty(width), np.empty(width)
    for j in range(u.shape[0]):
        light[j], tri[j], prob[j], rest[j] = -1, -1, 0.0, 0.0
        if root < 0:
            continue
        p0, p1, p2, n0, n1, n2 = p[0, j], p[1, j], p[2, j], n[0, j], n[1, j], n[2, j]
        node, pdf, uj, alive = root, 1.0, u[j], True
        while node_i[node, _LEFT] >= 0:
            q, ok = _left_probability_at(node, p0, p1, p2, n0, n1, n2, node_f, node_i, em_f, em_i)
            go_left = uj < q
            if go_left:
                uu = uj / (q if q > 0 else 1.0)
            else:
                uu = (uj - q) / (1.0 - q if q < 1 else 1.0)
            uj = min(max(uu, 0.0), below)
            pdf = pdf * (q if go_left else 1.0 - q)
            node = node_i[node, _LEFT] if go_left else node_i[node, _RIGHT]
            if not ok:
                alive = False
                break
        if not alive:
            continue
        s_max, s_min, n_has = _leaf_at(node, p0, p1, p2, n0, n1, n2, node_i, em_f, em_i, i_max, i_min)
        count = node_i[node, _COUNT]
        by_max = uj > 0.5
        if count > 1:
            uj = min(max(2.0 * uj - (1.0 if by_max else 0.0), 0.0), below)
        else:
            by_max = True
        total = 0.0
        for w in range(count):
            total += _share(w, by_max, i_max, i_min, s_max, s_min, n_has)
        target = uj * total
        pick, cdf, first_pos, found = count - 1, 0.0, -1, False
        for w in range(count):
            q = _share(w, by_max, i_max, i_min, s_max, s_min, n_has)
            if first_pos < 0 and q > 0:
                first_pos = w
            cdf += q
            if not found and cdf > target:
                pick, found = w, True
        if _share(pick, by_max, i_max, i_min, s_max, s_min, n_has) <= 0:
            pick = max(first_pos, 0)
        chosen = _share(pick, by_max, i_max, i_min, s_max, s_min, n_has)
        lo = 0.0
        for w in range(pick + 1):
            lo += _share(w, by_max, i_max, i_min, s_max, s_min, n_has)
        lo = lo - chosen
        if not (total > 0 and chosen > 0):
            continue
        e = node_i[node, _FIRST] + pick
        light[j], tri[j] = em_i[e, _LIGHT], em_i[e, _TRI]
        q_max = _share(pick, True, i_max, i_min, s_max, s_min, n_has)
        q_min = _share(pick, False, i_max, i_min, s_max, s_min, n_has)
        prob[j] = pdf * (0.5 * (q_max + q_min))
        rest[j] = min(max((target - lo) / chosen, 0.0), below)


@jit
def _probability_loop(emitter, p, n, root, node_f, node_i, em_f, em_i, path_node, path_right, leaf_of, out):
    width = max(1, node_i[:, _COUNT].max()) if node_i.shape[0] else 1
    i_max, i_min = np.empty(width), np.empty(width)
    for j in range(emitter.shape[0]):
        out[j] = 0.0
        e = emitter[j]
        if root < 0 or e < 0:
            continue
        p0, p1, p2, n0, n1, n2 = p[0, j], p[1, j], p[2, j], n[0, j], n[1, j], n[2, j]
        pdf = 1.0
        for level in range(path_node.shape[0]):
            k = path_node[level, e]
            if k < 0:
                continue
            q, ok = _left_probability_at(k, p0, p1, p2, n0, n1, n2, node_f, node_i, em_f, em_i)
            pdf = pdf * (1.0 - q if path_right[level, e] else q) if ok else 0.0
            if not pdf > 0:
                break
        if not pdf > 0:
            continue
        leaf = leaf_of[e]
        s_max, s_min, n_has = _leaf_at(leaf, p0, p1, p2, n0, n1, n2, node_i, em_f, em_i, i_max, i_min)
        w = e - node_i[leaf, _FIRST]
        q_max = _share(w, True, i_max, i_min, s_max, s_min, n_has)
        q_min = _share(w, False, i_max, i_min, s_max, s_min, n_has)
        out[j] = pdf * (0.5 * (q_max + q_min))


def choose_numba(t: TreeArrays, u, p, n):
    N = u.shape[0]
    light, tri = np.empty(N, np.int64), np.empty(N, np.int64)
    prob, rest = np.empty(N), np.empty(N)
    _choose_loop(np.ascontiguousarray(u, np.float64), np.ascontiguousarray(p, np.float64),
                 np.ascontiguousarray(n, np.float64), t.root, *t.packed, light, rest, prob, tri)
    return light, rest, prob, tri


def probability_numba(t: TreeArrays, emitter, p, n):
    out = np.empty(emitter.shape[0])
    _probability_loop(np.ascontiguousarray(emitter, np.int64), np.ascontiguousarray(p, np.float64),
                      np.ascontiguousarray(n, np.float64), t.root, *t.packed, t.path_node, t.path_right, t.leaf_of,
                      out)
    return out


#: The compiled twins (None without Numba).
choose_numba = _choose_loop and choose_numba
probability_numba = _probability_loop and probability_numba
choose = twin(choose_numba, choose_numpy)
probability = twin(probability_numba, probability_numpy)


def cone_cosines(theta_o, theta_e):
    """(cos θ_o, sin θ_o, cos(θ_o + θ_e), cos(θ_e − θ_o)) (M, 4) of cones: TreeArrays.node_trig / em_trig."""
    return np.ascontiguousarray(np.stack((np.cos(theta_o), np.sin(theta_o), np.cos(theta_o + theta_e),
                                          np.cos(theta_e - theta_o)), axis=1))


def box_measures(lo, hi):
    """(centre, extent = hi − centre (K, 3), |extent|², ½|extent| (K,)) of boxes lo, hi (K, 3): what a node's
    importance reads of its box (TreeArrays.node_centre …)."""
    centre = 0.5 * (lo + hi)
    extent = hi - centre
    r2 = extent[:, 0] * extent[:, 0] + extent[:, 1] * extent[:, 1] + extent[:, 2] * extent[:, 2]
    return np.ascontiguousarray(centre), np.ascontiguousarray(extent), r2, 0.5 * np.sqrt(r2)
