"""Light tree: next-event estimation's light choice over many lamps and emissive triangles, as Cycles makes it.

Part of engine.render.lights (its package docstring states the light interface).  The method is Conty &
Kulla 2018 ("Importance Sampling of Many Lights with Adaptive Tree Splitting") in Cycles' form
(intern/cycles/scene/light_tree.cpp builds it, kernel/light/tree.h traverses it; derivation and choices in
docs/architecture.md, "Light tree"):

- Emitters: every triangle of an emissive mesh that is sampled by area (``AreaEmitter``,
  ``TexturedAreaEmitter`` without a rectangle: a leaf per triangle, energy = its area × emitted luminance —
  a textured triangle's own mean), every other light whole (point, spot and sphere lamps, rectangle /
  disk / ellipse lamps, a textured rectangle).  Each has a bounding box, an orientation cone (axis, θ_o
  bounding the normals, θ_e the emission about them) and an energy (luminance units: radiance × area,
  intensity, irradiance).  Lights with no energy (black, hidden from indirect rays) are left out: never
  chosen, pick probability 0 (MIS then gives BSDF sampling their whole weight).
- Distant lights (the world, suns) sit outside the local tree: the root's right child is one leaf of
  them (Cycles' distant node), its left child the local tree.
- Build (once per scene, level by level over all nodes at once in NumPy): each node splits at the bucket
  boundary (12 buckets along each axis of its centroids' box) of least surface-area-orientation cost
  energy × area × M_Ω(θ_o, θ_e), kept as a leaf if no split is cheaper and it holds ≤ MAX_LEAF emitters.
  A node's cone: the normalised sum of its emitters' axes, θ_o the largest angle to a member's cone.
- Choice at a shading point p with side normal n (a zero n: a transmitting vertex, light from every
  side): from the root, the left child is taken with probability ½(I⁺_l/(I⁺_l + I⁺_r) + I⁻_l/(I⁻_l + I⁻_r))
  of Cycles' importance bounds I⁺ (least distance and angles) and I⁻ (largest), the number u reused
  (rescaled to its slot) at each level; in a leaf one emitter with probability ½(I⁺_i/ΣI⁺ + I⁻_i/ΣI⁻)
  (uniform among I⁺ > 0 where ΣI⁻ = 0).  The probability of the path taken is the pick probability.
- ``probability`` re-traverses the same nodes towards a given emitter with the same arithmetic (Cycles'
  light_tree_pdf), so MIS at emitter hits uses exactly the probability with which NEE picks it.

Arrays: points (3, N), emitters on the first axis, world units; angles in radians.
"""

from __future__ import annotations

import math

import numpy as np

from ...spectral import luminance
from ...vec3 import dot
from .area import AreaEmitter
from .environment import EnvironmentEmitter, EnvironmentMapEmitter
from .lamps import DirectionalEmitter, PointEmitter, SpotEmitter
from .textured import TexturedAreaEmitter

#: emitter kinds
TRIANGLE, POINT, SPOT, MESH, DISTANT, BACKGROUND = range(6)
#: a leaf holds at most this many emitters (Cycles' max_lights_in_leaf)
MAX_LEAF = 8
#: buckets per axis of the split search (Cycles' LightTreeBucket::num_buckets)
BUCKETS = 12
#: a choice's probability where no emitter can contribute (all importances 0): the vertex takes no light sample
NO_LIGHT = -1


def splits_into_triangles(light) -> bool:
    """Whether the tree takes ``light``'s triangles as separate emitters: a mesh light sampled by area over its
    triangles (not a rectangle, disk or ellipse lamp, which keep their own sampling as one emitter)."""
    return type(light) in (AreaEmitter, TexturedAreaEmitter) and light.rect is None


def _sin(c):
    return np.sqrt(np.maximum(1.0 - c * c, 0.0))


def _unit(v, axis=0):
    """v / |v| along ``axis`` and |v| (0 stays 0)."""
    length = np.sqrt((v * v).sum(axis=axis))
    return v / np.expand_dims(np.where(length > 0, length, 1.0), axis), length


def cone_measure(theta_o, theta_e):
    """Cycles' OrientationBounds::calculate_measure (the orientation part of the SAOH cost)."""
    theta_w = np.minimum(math.pi, theta_o + theta_e)
    c, s = np.cos(theta_o), np.sin(theta_o)
    return (2.0 * math.pi * (1.0 - c)
            + 0.5 * math.pi * (2.0 * theta_w * s - np.cos(theta_o - 2.0 * theta_w) - 2.0 * theta_o * s + c))


def importance(n, ptc, cos_u, axis, theta_o, theta_e, d_max, d_min, energy):
    """Cycles' light_tree_importance (surface form): (I⁺, I⁻) (M,) of clusters or emitters seen from points
    with side normals n (3, M) (zero: receives from every side), unit directions ptc (3, M) towards their
    centres, half-angles acos(cos_u) they subtend, cones (axis (3, M), θ_o, θ_e), distances d_max ≥ d_min
    and energies (M,)."""
    sin_u = _sin(cos_u)
    transmits = (n * n).sum(axis=0) == 0
    cos_i = dot(ptc, n)
    sin_i = _sin(cos_i)
    cos_min_inc = np.where(transmits | (cos_i >= cos_u), 1.0, cos_i * cos_u + sin_i * sin_u)
    cos_max_inc = np.where(transmits, 1.0, np.maximum(cos_i * cos_u - sin_i * sin_u, 0.0))
    cos_t = np.clip(-dot(axis, ptc), -1.0, 1.0)
    sin_t = _sin(cos_t)
    cos_tmu = cos_t * cos_u + sin_t * sin_u
    cos_o, sin_o = np.cos(theta_o), np.sin(theta_o)
    inside = (cos_t >= cos_u) | (cos_tmu >= cos_o)
    sin_tmu = _sin(cos_tmu)
    cos_min_out = np.where(inside, 1.0, cos_tmu * cos_o + sin_tmu * sin_o)
    visible = (inside | (theta_o + theta_e > math.pi) | (cos_tmu > np.cos(theta_o + theta_e))) & (cos_min_inc >= 0)
    i_max = np.where(visible, np.abs(cos_min_inc * energy * cos_min_out / np.maximum(d_min * d_min, 1e-300)), 0.0)
    cos_tpu = cos_t * cos_u - sin_t * sin_u
    lower = ~((theta_e - theta_o < 0) | (cos_t < 0) | (cos_u < 0) | (cos_tpu < np.cos(theta_e - theta_o)))
    cos_max_out = cos_tpu * cos_o - _sin(cos_tpu) * sin_o
    i_min = np.where(visible & lower,
                     np.abs(cos_max_inc * energy * cos_max_out / np.maximum(d_max * d_max, 1e-300)), 0.0)
    return i_max, np.minimum(i_min, i_max)


class LightTree:
    """The light tree of a LightSet (see the module docstring); built once, read by any number of threads.

    ``choose(u, p, n)`` → (light index (N,) (NO_LIGHT: none), the rest of u rescaled to [0, 1), the pick
    probability (N,), the chosen triangle (N,) or −1 for a whole light); ``probability_of_light(li, p, n)``
    and ``probability_of_triangles(prims, p, n)`` the same probability for given lights / triangles.
    ``split[li]``: the light's triangles are separate emitters (NEE samples the chosen triangle by area,
    ``AreaEmitter.sample_triangles``; its pdf at hits is ``triangle_pdf``).
    """

    spatial = True

    def __init__(self, light_set, compiled):
        self.compiled = compiled
        self._emitters(light_set)
        self._build()

    # ------------------------------------------------------------------ emitters

    def _emitters(self, light_set) -> None:
        """Every emitter's kind, light, triangle, centre, box, cone and energy (local ones first)."""
        c = self.compiled
        rows = {k: [] for k in ("kind", "light", "tri", "centre", "lo", "hi", "axis", "theta_o", "theta_e", "energy",
                                "radius", "sphere", "cos_outer", "cos_inner")}
        n_lights = len(light_set.lights)
        self.split = np.zeros(n_lights, bool)
        tri_parts = []

        def add(kind, li, centre, lo, hi, axis, theta_o, theta_e, energy, radius=0.0, sphere=False,
                cos_outer=-1.0, cos_inner=-1.0):
            for key, value in zip(rows, (kind, li, -1, centre, lo, hi, axis, theta_o, theta_e, energy, radius,
                                         sphere, cos_outer, cos_inner)):
                rows[key].append(value)

        for li, light in enumerate(light_set.lights):
            if light.shades_nothing:
                continue
            if isinstance(light, (EnvironmentEmitter, EnvironmentMapEmitter)):
                energy = math.pi * float(luminance(light._rgb if isinstance(light, EnvironmentMapEmitter)
                                                   else light.rgb()))
                add(BACKGROUND, li, np.zeros(3), np.zeros(3), np.zeros(3), np.array([0.0, 0.0, -1.0]), math.pi, 0.0,
                    energy)
            elif isinstance(light, DirectionalEmitter):
                half = math.acos(max(-1.0, min(1.0, 1.0 - light.one_minus_cos)))
                add(DISTANT, li, np.zeros(3), np.zeros(3), np.zeros(3), light.direction.copy(), 0.0, half,
                    float(luminance(light.rgb())))
            elif isinstance(light, PointEmitter):
                pos, r = light.position, light.radius
                lum = float(luminance(light.rgb()))
                if isinstance(light, SpotEmitter):
                    add(SPOT, li, pos, pos - r, pos + r, light.axis.copy(), 0.0, math.acos(light.cos_outer), lum, r,
                        not light.soft_falloff, light.cos_outer, light.cos_inner)
                else:
                    add(POINT, li, pos, pos - r, pos + r, np.array([0.0, 0.0, 1.0]), math.pi, 0.5 * math.pi, lum, r,
                        not light.soft_falloff)
            elif splits_into_triangles(light):
                self.split[li] = True
                tri_parts.append((li, light))
            elif isinstance(light, AreaEmitter):          # a lamp sampled as a whole (rectangle, disk, ellipse)
                corners = c.vertices[c.faces[light.tris]].reshape(-1, 3).astype(np.float64)
                lo, hi = corners.min(0), corners.max(0)
                normal = None if light.two_sided else light._plane_normal()
                axis = normal if normal is not None else np.array([0.0, 0.0, 1.0])
                theta_o = 0.0 if normal is not None else math.pi
                energy = light.mean_luminance() * light.total_area
                add(MESH, li, 0.5 * (lo + hi), lo, hi, axis, theta_o, light.spread_half, energy)
            else:       # a light kind the tree does not know: never left out silently
                raise TypeError(f"the light tree has no rule for {type(light).__name__}")
        types = {"kind": np.int64, "light": np.int64, "tri": np.int64, "sphere": bool}
        arrays = {key: np.array(v, dtype=types.get(key, np.float64)).reshape(
                  (len(v), 3) if key in ("centre", "lo", "hi", "axis") else (len(v),)) for key, v in rows.items()}
        local = ~np.isin(arrays["kind"], (DISTANT, BACKGROUND))
        tri_arrays = [self._triangle_emitters(li, light) for li, light in tri_parts]
        parts = [{key: a[local] for key, a in arrays.items()}, *tri_arrays,
                 {key: a[~local] for key, a in arrays.items()}]
        em = {key: np.concatenate([p[key] for p in parts]) for key in arrays}
        keep = np.isfinite(em["energy"]) & (em["energy"] > 0)
        em = {key: a[keep] for key, a in em.items()}
        self.n_distant = int(np.isin(em["kind"], (DISTANT, BACKGROUND)).sum())
        self.em = em

    def _triangle_emitters(self, li, light) -> dict:
        """The emitters of a split mesh light: one per triangle (Cycles' LightTreeEmitter of a triangle)."""
        c = self.compiled
        tris = light.tris
        v = c.vertices[c.faces[tris]].astype(np.float64)          # (T, 3, 3)
        area = c.tri_area[tris].astype(np.float64)
        if hasattr(light, "tri_luminance"):          # textured: the triangle's own luminance (its sampling weight)
            lum = light.tree_luminance()
        else:
            lum = np.full(len(tris), light.mean_luminance())
        if light.two_sided:
            axis, _ = _unit(v[:, 0] - v[:, 1], axis=1)
            theta_o = np.full(len(tris), 0.5 * math.pi)
        else:
            axis = c.tri_normal[tris].astype(np.float64)
            theta_o = np.zeros(len(tris))
        T = len(tris)
        return {"kind": np.full(T, TRIANGLE, np.int64), "light": np.full(T, li, np.int64), "tri": tris.astype(np.int64),
                "centre": v.mean(axis=1), "lo": v.min(axis=1), "hi": v.max(axis=1), "axis": axis, "theta_o": theta_o,
                "theta_e": np.full(T, light.spread_half), "energy": area * lum, "radius": np.zeros(T),
                "sphere": np.zeros(T, bool), "cos_outer": np.full(T, -1.0), "cos_inner": np.full(T, -1.0)}

    # ------------------------------------------------------------------ build

    def _build(self) -> None:
        """Nodes (inner: left/right children; leaf: a range of emitters), level by level in NumPy."""
        em = self.em
        E = em["kind"].shape[0]
        n_local = E - self.n_distant
        nodes = {"lo": [], "hi": [], "axis": [], "theta_o": [], "theta_e": [], "energy": [], "left": [], "right": [],
                 "first": [], "count": [], "distant": []}
        order = np.arange(n_local)

        def new_nodes(k):
            start = len(nodes["left"])
            for key in nodes:
                nodes[key].extend([None] * k)
            return np.arange(start, start + k)

        def set_node(ids, **values):
            for key, vals in values.items():
                for i, v in zip(ids, vals):
                    nodes[key][i] = v

        root_local = None
        if n_local:
            # segments [start, end) of ``order`` at this level, their node ids
            starts, ends = np.array([0]), np.array([n_local])
            ids = new_nodes(1)
            root_local = int(ids[0])
            while starts.size:
                # this level's emitters: the segments' ranges of ``order``, one after the other
                count = ends - starts
                rel = np.concatenate(([0], np.cumsum(count)[:-1]))
                idx = np.repeat(starts - rel, count) + np.arange(int(count.sum()))
                level = {key: em[key][order[idx]] for key in ("centre", "lo", "hi", "axis", "theta_o", "theta_e",
                                                               "energy")}
                seg = np.repeat(np.arange(starts.size), count)
                lo, hi, axis, theta_o, theta_e, energy = _segment_measure(level, seg, rel)
                set_node(ids, lo=lo, hi=hi, axis=axis, theta_o=theta_o, theta_e=theta_e, energy=energy,
                         distant=[False] * ids.size)
                middle, perm = _splits(level, seg, rel, rel + count, lo, hi, axis, theta_o, theta_e, energy)
                order[idx] = order[idx][perm]
                split = middle >= 0
                leaves = ~split
                set_node(ids[leaves], first=starts[leaves], count=count[leaves],
                         left=[-1] * int(leaves.sum()), right=[-1] * int(leaves.sum()))
                k = int(split.sum())
                if not k:
                    break
                left_ids, right_ids = new_nodes(k), new_nodes(k)
                set_node(ids[split], left=left_ids, right=right_ids, first=[-1] * k, count=[0] * k)
                mid = (starts + middle - rel)[split]
                starts, ends = np.concatenate((starts[split], mid)), np.concatenate((mid, ends[split]))
                ids = np.concatenate((left_ids, right_ids))
        # emitters in leaf order, distant ones last
        perm = np.concatenate((order, np.arange(n_local, E)))
        self.em = {key: a[perm] for key, a in em.items()}
        em = self.em
        root = root_local
        if self.n_distant:
            d = slice(n_local, E)
            distant = new_nodes(1)
            axis, theta_o = _cone(em["axis"][d], em["theta_o"][d], np.zeros(self.n_distant, np.int64), 1)
            set_node(distant, lo=[np.zeros(3)], hi=[np.zeros(3)], axis=axis, theta_o=theta_o,
                     theta_e=[em["theta_e"][d].max()], energy=[em["energy"][d].sum()], left=[-1], right=[-1],
                     first=[n_local], count=[self.n_distant], distant=[True])
            root = int(distant[0])
            if root_local is not None:
                top = new_nodes(1)
                set_node(top, lo=[np.zeros(3)], hi=[np.zeros(3)], axis=[np.zeros(3)], theta_o=[0.0], theta_e=[0.0],
                         energy=[0.0], left=[root_local], right=[root], first=[-1], count=[0], distant=[False])
                root = int(top[0])
        self.root = root
        self.nodes = {key: np.array(v, dtype=np.float64 if key not in ("left", "right", "first", "count", "distant")
                                    else bool if key == "distant" else np.int64) for key, v in nodes.items()}
        if root is None:
            return
        self._paths()

    def _paths(self) -> None:
        """Per emitter: the nodes from the root to its leaf and whether each step goes right (probability)."""
        nd = self.nodes
        K = nd["left"].shape[0]
        parent, right_child = np.full(K, -1), np.zeros(K, bool)
        inner = nd["left"] >= 0
        parent[nd["left"][inner]] = np.flatnonzero(inner)
        parent[nd["right"][inner]] = np.flatnonzero(inner)
        right_child[nd["right"][inner]] = True
        E = self.em["kind"].shape[0]
        leaf_of = np.full(E, -1)
        leaves = np.flatnonzero(~inner)
        for k in leaves:
            leaf_of[nd["first"][k]:nd["first"][k] + nd["count"][k]] = k
        self.leaf_of = leaf_of
        # walk up from every leaf (vectorised over leaves): its ancestors, root first
        chain = [leaves]
        while (chain[-1] >= 0).any():
            chain.append(np.where(chain[-1] >= 0, parent[np.maximum(chain[-1], 0)], -1))
        chain = np.array(chain[:-1])[::-1]            # (depth + 1, leaves), −1 padding at the top
        steps_node, steps_right = [], []
        for a, b in zip(chain[:-1], chain[1:]):
            ok = (a >= 0) & (b >= 0)
            steps_node.append(np.where(ok, a, -1))
            steps_right.append(ok & right_child[np.maximum(b, 0)])
        depth = len(steps_node)
        by_leaf = np.full(K, -1)
        by_leaf[leaves] = np.arange(leaves.size)
        row = by_leaf[leaf_of]
        self.path_node = (np.array(steps_node).reshape(depth, -1)[:, row] if depth else np.zeros((0, E), np.int64))
        self.path_right = (np.array(steps_right).reshape(depth, -1)[:, row] if depth else np.zeros((0, E), bool))
        # where a triangle or a whole light is an emitter
        self.emitter_of_triangle = np.full(len(self.compiled.faces), -1, np.int64)
        tri = self.em["tri"]
        self.emitter_of_triangle[tri[tri >= 0]] = np.flatnonzero(tri >= 0)
        self.emitter_of_light = np.full(self.split.shape[0], -1, np.int64)
        whole = tri < 0
        self.emitter_of_light[self.em["light"][whole]] = np.flatnonzero(whole)

    # ------------------------------------------------------------------ importance

    def _emitter_importance(self, e, p, n):
        """(I⁺, I⁻) (M,) of emitters e (M,) at points p (3, M) with side normals n (3, M): Cycles'
        light_tree_emitter_importance with the per-kind parameters of kernel/light/{triangle, point, spot,
        area, distant, background}.h."""
        em = self.em
        kind = em["kind"][e]
        centre = em["centre"][e].T
        ptc, d = _unit(centre - p)
        d_min = d.copy()
        d_max = d.copy()
        cos_u = np.ones(e.shape[0])
        axis = em["axis"][e].T.copy()
        theta_o, theta_e, energy = em["theta_o"][e].copy(), em["theta_e"][e], em["energy"][e].copy()
        visible = np.ones(e.shape[0], bool)
        transmits = (n * n).sum(axis=0) == 0
        # triangles and whole meshes: the corners (a triangle's three, a box's eight)
        poly = (kind == TRIANGLE) | (kind == MESH)
        if poly.any():
            r = np.flatnonzero(poly)
            corners = self._corners(e[r])                      # (C, 3, m)
            to = corners - p[:, r][None]
            dist_c = np.sqrt((to * to).sum(axis=1))
            unit_c = to / np.where(dist_c > 0, dist_c, 1.0)[:, None]
            cos_u[r] = np.min((unit_c * ptc[:, r][None]).sum(axis=1), axis=0)
            d_max[r] = np.maximum(d[r], dist_c.max(axis=0))
            above = ((unit_c * n[:, r][None]).sum(axis=1) > 0).any(axis=0) | transmits[r]
            front = (theta_o[r] != 0) | (dot(axis[:, r], ptc[:, r]) < 0)
            visible[r] = above & front
        lamp = (kind == POINT) | (kind == SPOT)
        if lamp.any():
            r = np.flatnonzero(lamp)
            rad, dr = em["radius"][e[r]], np.maximum(d[r], 1e-300)
            sphere = em["sphere"][e[r]]
            outside = dr > rad
            cos_sph = np.where(outside, _sin(np.minimum(rad / dr, 1.0)), -1.0)
            hyp = np.sqrt(rad * rad + dr * dr)
            cos_u[r] = np.where(sphere, cos_sph, dr / hyp)
            inner = rad / math.sqrt(2.0)
            d_max[r] = np.where(sphere, np.where(outside, dr / np.where(outside, cos_sph, 1.0), inner), hyp)
            d_min[r] = np.where(sphere & ~outside, inner, d[r])
            point = kind[r] == POINT
            axis[:, r] = np.where(point[None], -ptc[:, r], axis[:, r])     # a point light's cone faces p
            theta_o[r] = np.where(point, 0.0, theta_o[r])
            spot = ~point
            if spot.any():          # the spot's falloff at the least angle to its axis (Cycles' spot energy)
                s = r[spot]
                cos_a = np.clip(-dot(axis[:, s], ptc[:, s]), -1.0, 1.0)
                cos_m = np.cos(np.maximum(0.0, np.arccos(cos_a) - np.arccos(np.clip(cos_u[s], -1.0, 1.0))))
                energy[s] = energy[s] * _spot_edge(cos_m, em["cos_outer"][e[s]], em["cos_inner"][e[s]])
        far = kind == DISTANT
        if far.any():
            r = np.flatnonzero(far)
            ptc[:, r] = -axis[:, r]
            cos_u[r] = np.cos(theta_e[r])
            d_max[r], d_min[r] = 1.0 / cos_u[r], 1.0
        sky = kind == BACKGROUND
        if sky.any():
            r = np.flatnonzero(sky)
            ptc[:, r] = -axis[:, r]
            cos_u[r], d_max[r], d_min[r] = -1.0, 1.0, 1.0
        i_max, i_min = importance(n, ptc, cos_u, axis, theta_o, theta_e, d_max, d_min, energy)
        return np.where(visible, i_max, 0.0), np.where(visible, i_min, 0.0)

    def _corners(self, e):
        """(C, 3, m) corners of emitters e: a triangle's three vertices (repeated to eight) or a box's eight."""
        em, c = self.em, self.compiled
        lo, hi = em["lo"][e], em["hi"][e]
        box = np.stack([np.where(np.array([(k >> a) & 1 for a in range(3)], bool)[None], hi, lo) for k in range(8)])
        tri = em["tri"][e]
        is_tri = tri >= 0
        if is_tri.any():
            v = c.vertices[c.faces[np.maximum(tri, 0)]].astype(np.float64)     # (m, 3, 3)
            v8 = v[:, [0, 1, 2, 0, 1, 2, 0, 1]].transpose(1, 0, 2)             # (8, m, 3)
            box = np.where(is_tri[None, :, None], v8, box)
        return box.transpose(0, 2, 1)

    def _node_importance(self, k, p, n):
        """(I⁺, I⁻) (M,) of nodes k (M,) seen from p, n (3, M): Cycles' light_tree_child_importance — a
        leaf of one emitter by that emitter's own importance, another node by its box and cone."""
        nd = self.nodes
        single = (nd["count"][k] == 1)
        i_max, i_min = np.zeros(k.shape[0]), np.zeros(k.shape[0])
        if single.any():
            r = np.flatnonzero(single)
            i_max[r], i_min[r] = self._emitter_importance(nd["first"][k[r]], p[:, r], n[:, r])
        rest = ~single
        if rest.any():
            r = np.flatnonzero(rest)
            kk = k[r]
            pp, nn = p[:, r], n[:, r]
            lo, hi = nd["lo"][kk].T, nd["hi"][kk].T
            centre = 0.5 * (lo + hi)
            extent = hi - centre
            axis = nd["axis"][kk].T
            theta_o, theta_e = nd["theta_o"][kk], nd["theta_e"][kk]
            transmits = (nn * nn).sum(axis=0) == 0
            ptc, d = _unit(centre - pp)
            r2 = dot(extent, extent)
            cos_u = np.where(d * d <= r2, -1.0, np.sqrt(np.maximum(1.0 - r2 / np.maximum(d * d, 1e-300), 0.0)))
            d = np.maximum(0.5 * np.sqrt(r2), d)
            visible = transmits | (dot(nn, centre - pp) + dot(np.abs(nn), np.abs(extent)) > 0)
            distant = nd["distant"][kk]
            if distant.any():           # the distant node: its cone seen from anywhere
                ptc = np.where(distant[None], -axis, ptc)
                cos_u = np.where(distant, np.cos(np.minimum(theta_o + theta_e, math.pi)), cos_u)
                d = np.where(distant, 1.0, d)
                visible |= distant
            a, b = importance(nn, ptc, cos_u, axis, theta_o, theta_e, d, d, nd["energy"][kk])
            i_max[r], i_min[r] = np.where(visible, a, 0.0), np.where(visible, b, 0.0)
        return i_max, i_min

    def _left_probability(self, k, p, n):
        """(probability (M,) of taking the left child of inner nodes k, valid (M,): some child can contribute)."""
        nd = self.nodes
        l_max, l_min = self._node_importance(nd["left"][k], p, n)
        r_max, r_min = self._node_importance(nd["right"][k], p, n)
        t_max, t_min = l_max + r_max, l_min + r_min
        ok = t_max > 0
        p_max = l_max / np.where(ok, t_max, 1.0)
        p_min = np.where(t_min > 0, l_min / np.where(t_min > 0, t_min, 1.0),
                         0.5 * ((l_max > 0).astype(np.float64) + (r_max == 0)))
        return 0.5 * (p_max + p_min), ok

    def _leaf_probabilities(self, k, p, n):
        """(emitters (MAX, M) of leaves k (−1 padding), their probabilities (MAX, M), the ones sampled by the
        upper bounds alone (MAX, M)): ½(I⁺/ΣI⁺ + I⁻/ΣI⁻), uniform over I⁺ > 0 where ΣI⁻ = 0."""
        nd = self.nodes
        first, count = nd["first"][k], nd["count"][k]
        width = int(count.max()) if k.size else 0
        slot = np.arange(width)[:, None]
        e = np.where(slot < count[None], first[None] + slot, -1)
        live = e >= 0
        cols = np.broadcast_to(np.arange(k.shape[0]), e.shape)[live]
        i_max, i_min = np.zeros(e.shape), np.zeros(e.shape)
        i_max[live], i_min[live] = self._emitter_importance(e[live], p[:, cols], n[:, cols])
        s_max, s_min = i_max.sum(axis=0), i_min.sum(axis=0)
        has = i_max > 0
        n_has = has.sum(axis=0)
        q_max = i_max / np.where(s_max > 0, s_max, 1.0)
        q_min = np.where(s_min > 0, i_min / np.where(s_min > 0, s_min, 1.0),
                         has / np.maximum(n_has, 1))
        return e, q_max, q_min

    # ------------------------------------------------------------------ choice and its probability

    def choose(self, u, p, n):
        """See the class docstring.  u (N,) in [0, 1), p (3, N), n (3, N) side normals (zero: transmitting)."""
        N = u.shape[0]
        light, tri = np.full(N, NO_LIGHT, np.int64), np.full(N, -1, np.int64)
        prob, rest = np.zeros(N), np.zeros(N)
        if self.root is None:
            return light, rest, prob, tri
        nd = self.nodes
        node = np.full(N, self.root, np.int64)
        pdf = np.ones(N)
        u = u.astype(np.float64, copy=True)
        alive = np.ones(N, bool)
        below = np.nextafter(1.0, 0.0)
        while True:
            at = np.flatnonzero(alive & (nd["left"][node] >= 0))
            if not at.size:
                break
            q, ok = self._left_probability(node[at], p[:, at], n[:, at])
            go_left = u[at] < q
            uu = np.where(go_left, u[at] / np.where(q > 0, q, 1.0), (u[at] - q) / np.where(q < 1, 1.0 - q, 1.0))
            u[at] = np.clip(uu, 0.0, below)
            pdf[at] *= np.where(go_left, q, 1.0 - q)
            node[at] = np.where(go_left, nd["left"][node[at]], nd["right"][node[at]])
            alive[at] &= ok
        at = np.flatnonzero(alive)
        if not at.size:
            return light, rest, prob, tri
        e, q_max, q_min = self._leaf_probabilities(node[at], p[:, at], n[:, at])
        ua = u[at]
        several = nd["count"][node[at]] > 1
        by_max = ua > 0.5
        ua = np.where(several, np.clip(2.0 * ua - by_max, 0.0, below), ua)
        by_max = np.where(several, by_max, True)
        q = np.where(by_max[None], q_max, q_min)
        cdf = np.cumsum(q, axis=0)
        total = cdf[-1]
        pick = np.minimum((cdf <= (ua * total)[None]).sum(axis=0), e.shape[0] - 1)
        cols = np.arange(at.size)
        # never a slot of probability 0 (rounding at the top of the cdf)
        pick = np.where(q[pick, cols] > 0, pick, np.argmax(q > 0, axis=0))
        chosen = q[pick, cols]
        lo = cdf[pick, cols] - chosen
        ok = (total > 0) & (chosen > 0)
        rest_a = np.clip((ua * total - lo) / np.where(chosen > 0, chosen, 1.0), 0.0, below)
        pe = 0.5 * (q_max[pick, cols] + q_min[pick, cols])
        emitter = e[pick, cols]
        good = at[ok]
        light[good] = self.em["light"][emitter[ok]]
        tri[good] = self.em["tri"][emitter[ok]]
        prob[good] = pdf[good] * pe[ok]
        rest[good] = rest_a[ok]
        return light, rest, prob, tri

    def probability(self, emitter, p, n):
        """The probability (M,) that ``choose`` at points p, n (3, M) picks the emitters ``emitter`` (M,)
        (−1: 0), re-traversing their nodes from the root with the arithmetic of ``choose``."""
        M = emitter.shape[0]
        out = np.zeros(M)
        if self.root is None:
            return out
        ok = emitter >= 0
        pdf = np.where(ok, 1.0, 0.0)
        e = np.maximum(emitter, 0)
        for level in range(self.path_node.shape[0]):
            k = self.path_node[level, e]
            at = np.flatnonzero(ok & (k >= 0))
            if not at.size:
                continue
            q, valid = self._left_probability(k[at], p[:, at], n[:, at])
            right = self.path_right[level, e[at]]
            pdf[at] *= np.where(valid, np.where(right, 1.0 - q, q), 0.0)
        at = np.flatnonzero(ok & (pdf > 0))
        if at.size:
            leaf = self.leaf_of[e[at]]
            es, q_max, q_min = self._leaf_probabilities(leaf, p[:, at], n[:, at])
            slot = e[at] - self.nodes["first"][leaf]
            cols = np.arange(at.size)
            out[at] = pdf[at] * 0.5 * (q_max[slot, cols] + q_min[slot, cols])
        return out

    def probability_of_light(self, li, p, n):
        """Pick probability (M,) of the whole light ``li`` at points p, n (3, M) (its triangles' sum is not
        asked: a split light is found by its triangles)."""
        e = self.emitter_of_light[li] if li < self.emitter_of_light.shape[0] else -1
        return self.probability(np.full(p.shape[1], e, np.int64), p, n)

    def probability_of_triangles(self, prims, p, n):
        """Pick probability (M,) of the triangles ``prims`` (M,) (emitters of split lights) at points p, n."""
        return self.probability(self.emitter_of_triangle[prims], p, n)


def _spot_edge(cos_a, cos_outer, cos_inner):
    """A spot's falloff at cos of the angle to its axis: 1 inside cos_inner, 0 outside cos_outer, smoothstep."""
    hard = cos_inner <= cos_outer
    t = np.clip((cos_a - cos_outer) / np.where(hard, 1.0, cos_inner - cos_outer), 0.0, 1.0)
    return np.where(hard, (cos_a >= cos_outer).astype(np.float64), t * t * (3.0 - 2.0 * t))


def _cone(axis, theta_o, group, groups, sums=None):
    """Bounding cones (axis (G, 3), θ_o (G,)) of emitters' cones grouped by ``group`` (M,) ∈ [0, groups): the
    normalised sum of the axes (``sums`` (G, 3) if known), θ_o the largest angle from it to a member's axis plus
    the member's θ_o (π where the axes cancel)."""
    if sums is None:
        sums = np.zeros((groups, 3))
        np.add.at(sums, group, axis)
    a, length = _unit(sums, axis=1)
    cos = np.clip((a[group] * axis).sum(axis=1), -1.0, 1.0)
    spread = np.arccos(cos) + theta_o
    t = np.zeros(groups)
    np.maximum.at(t, group, spread)
    count = np.bincount(group, minlength=groups)
    t = np.where(length > 1e-9 * np.maximum(count, 1), np.minimum(t, math.pi), math.pi)
    a = np.where((length > 0)[:, None], a, np.array([0.0, 0.0, 1.0]))
    return a, t


def _segment_measure(em, seg, starts):
    """Each segment's box (lo, hi (S, 3)), cone (axis, θ_o, θ_e) and energy (S,)."""
    S = starts.size
    lo = np.minimum.reduceat(em["lo"], starts, axis=0)
    hi = np.maximum.reduceat(em["hi"], starts, axis=0)
    axis, theta_o = _cone(em["axis"], em["theta_o"], seg, S)
    theta_e = np.maximum.reduceat(em["theta_e"], starts)
    energy = np.add.reduceat(em["energy"], starts)
    return lo, hi, axis, theta_o, theta_e, energy


def _buckets(em, key, S, B):
    """Per (segment, bucket) key ∈ [0, S·B) of the emitters: counts, energies, boxes (lo, hi), cones (axis, θ_o),
    θ_e and the sums of the axes, each (S, B[, 3]); empty buckets have empty boxes."""
    K = S * B
    n_b = np.bincount(key, minlength=K)
    e_b = np.bincount(key, weights=em["energy"], minlength=K)
    order = np.argsort(key, kind="stable")
    k_sorted = key[order]
    first = np.flatnonzero(np.concatenate(([True], k_sorted[1:] != k_sorted[:-1])))
    used = k_sorted[first]
    lo_b, hi_b = np.full((K, 3), np.inf), np.full((K, 3), -np.inf)
    lo_b[used] = np.minimum.reduceat(em["lo"][order], first, axis=0)
    hi_b[used] = np.maximum.reduceat(em["hi"][order], first, axis=0)
    te_b = np.zeros(K)
    te_b[used] = np.maximum.reduceat(em["theta_e"][order], first)
    sum_b = np.zeros((K, 3))
    sum_b[used] = np.add.reduceat(em["axis"][order], first, axis=0)
    ax_b, to_b = _cone(em["axis"], em["theta_o"], key, K, sum_b)
    return (n_b.reshape(S, B), e_b.reshape(S, B), lo_b.reshape(S, B, 3), hi_b.reshape(S, B, 3),
            ax_b.reshape(S, B, 3), to_b.reshape(S, B), te_b.reshape(S, B), sum_b.reshape(S, B, 3))


def _cost(lo, hi, theta_o, theta_e, energy):
    """Cycles' SAOH measure energy × area × M_Ω (the box's diagonal where its area is 0)."""
    size = np.maximum(hi - lo, 0.0)
    area = 2.0 * (size[..., 0] * size[..., 1] + size[..., 1] * size[..., 2] + size[..., 2] * size[..., 0])
    area = np.where(area > 0, area, np.sqrt((size * size).sum(axis=-1)))
    return energy * area * cone_measure(theta_o, theta_e)


def _splits(em, seg, starts, ends, lo, hi, axis, theta_o, theta_e, energy):
    """(middle (S,): where each segment splits, −1 for a leaf; the permutation of the level's emitters that
    partitions every split segment at its middle).  Cycles' LightTree::should_split: the bucket boundary of
    least regularised cost along any axis; a split if cheaper than the segment, or if it holds more than
    MAX_LEAF emitters (at the middle of its order if no boundary is cheaper)."""
    S = starts.size
    count = ends - starts
    E = seg.shape[0]
    c = em["centre"]
    c_lo = np.minimum.reduceat(c, starts, axis=0)
    c_hi = np.maximum.reduceat(c, starts, axis=0)
    extent = c_hi - c_lo
    max_extent = extent.max(axis=1)
    total = _cost(lo, hi, theta_o, theta_e, energy)
    best = np.full(S, np.inf)
    best_dim = np.full(S, -1)
    best_split = np.zeros(S, np.int64)
    best_left = np.zeros(S, np.int64)
    B = BUCKETS
    below = np.arange(B - 1)[:, None] >= np.arange(B)[None, :]          # (split, bucket): bucket on the left
    for dim in range(3):
        ext = extent[:, dim]
        usable = ext > 0
        inv = np.where(usable, 1.0 / np.where(usable, ext, 1.0), 0.0)
        b = np.clip((B * (c[:, dim] - c_lo[seg, dim]) * inv[seg]).astype(np.int64), 0, B - 1)
        n_b, e_b, lo_b, hi_b, ax_b, to_b, te_b, sum_b = _buckets(em, seg * B + b, S, B)
        filled = n_b > 0
        # the left side of split j holds buckets ≤ j (prefixes), the right side the rest (suffixes)
        sides = []
        for rev in (False, True):
            f = (lambda a: a[:, ::-1]) if rev else (lambda a: a)
            n_s = f(np.cumsum(f(n_b), axis=1))
            e_s = f(np.cumsum(f(e_b), axis=1))
            lo_s = f(np.minimum.accumulate(f(lo_b), axis=1))
            hi_s = f(np.maximum.accumulate(f(hi_b), axis=1))
            te_s = f(np.maximum.accumulate(f(te_b), axis=1))
            a_s, length = _unit(f(np.cumsum(f(sum_b), axis=1)), axis=2)
            take = (slice(None), slice(0, B - 1)) if not rev else (slice(None), slice(1, B))
            n_s, e_s, lo_s, hi_s, te_s, a_s, length = (x[take] for x in (n_s, e_s, lo_s, hi_s, te_s, a_s, length))
            member = (~below if rev else below)[None] & filled[:, None, :]              # (S, split, bucket)
            cos = np.clip(np.einsum("sjk,sbk->sjb", a_s, ax_b), -1.0, 1.0)
            t_o = np.where(member, np.arccos(cos) + to_b[:, None, :], 0.0).max(axis=2)
            t_o = np.where(length > 1e-9, np.minimum(t_o, math.pi), math.pi)
            sides.append((_cost(lo_s, hi_s, t_o, te_s, e_s), n_s))
        (cost_l, n_l), (cost_r, n_r) = sides
        reg = np.where(usable, max_extent * inv, 0.0)
        cost = reg[:, None] * (np.where(n_l > 0, cost_l, 0.0) + np.where(n_r > 0, cost_r, 0.0))
        cost = np.where(usable[:, None] & (n_l > 0) & (n_r > 0), cost, np.inf)
        j = np.argmin(cost, axis=1)
        c_best = cost[np.arange(S), j]
        better = (c_best < total) & (c_best < best)
        best = np.where(better, c_best, best)
        best_dim = np.where(better, dim, best_dim)
        best_split = np.where(better, j, best_split)
        best_left = np.where(better, n_l[np.arange(S), j], best_left)
    split = (count >= 2) & ((best_dim >= 0) | (count > MAX_LEAF))
    middle = np.where(split, np.where(best_dim >= 0, starts + best_left, (starts + ends) // 2), -1)
    # partition: within a segment split along a dimension, the emitters of buckets ≤ best_split first (stable)
    goes_right = np.zeros(E, bool)
    along = split & (best_dim >= 0)
    if along.any():
        d = np.maximum(best_dim[seg], 0)
        ext = extent[seg, d]
        inv = np.where(ext > 0, 1.0 / np.where(ext > 0, ext, 1.0), 0.0)
        b = np.clip((B * (c[np.arange(E), d] - c_lo[seg, d]) * inv).astype(np.int64), 0, B - 1)
        goes_right = along[seg] & (b > best_split[seg])
    perm = np.lexsort((np.arange(E), goes_right, seg))
    return middle, perm
