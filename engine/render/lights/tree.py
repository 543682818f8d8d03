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
  chosen, pick probability 0 (MIS then gives BSDF sampling their whole weight).  So is a world of one radiance
  (``constant_sky``): Cycles turns its MIS off and leaves it out of its tree (scene/light.cpp
  test_enabled_lights), as LightSet's "cycles" choice does without the tree.
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
  light_tree_pdf), so MIS at emitter hits uses exactly the probability with which NEE picks it.  The traversal's
  arithmetic is engine.kernels.light_tree's (compiled per-point loops and their NumPy twins); this module builds.

Arrays: points (3, N), emitters on the first axis, world units; angles in radians.
"""

from __future__ import annotations

import math

import numpy as np

from ...kernels import light_tree
from ...kernels.light_tree import BACKGROUND, DISTANT, MESH, POINT, SPOT, TRIANGLE, TreeArrays, cone_cosines
from ...spectral import luminance
from .area import AreaEmitter
from .environment import EnvironmentEmitter, EnvironmentMapEmitter
from .lamps import DirectionalEmitter, PointEmitter, SpotEmitter
from .textured import TexturedAreaEmitter

#: a leaf holds at most this many emitters (Cycles' max_lights_in_leaf)
MAX_LEAF = 8
#: buckets per axis of the split search (Cycles' LightTreeBucket::num_buckets)
BUCKETS = 12


def splits_into_triangles(light) -> bool:
    """Whether the tree takes ``light``'s triangles as separate emitters: a mesh light sampled by area over its
    triangles (not a rectangle, disk or ellipse lamp, which keep their own sampling as one emitter)."""
    return type(light) in (AreaEmitter, TexturedAreaEmitter) and light.rect is None


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
            if light.shades_nothing or light.constant_sky:      # (a constant sky: BSDF sampling alone, as Cycles)
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
                middle, perm = np.full(starts.size, -1), np.arange(idx.size)
                multi = count >= 2          # (single emitters are leaves: no split search over them)
                if multi.any():
                    sub = np.flatnonzero(multi[seg])
                    c_sub = count[multi]
                    r_sub = np.concatenate(([0], np.cumsum(c_sub)[:-1]))
                    m_sub, p_sub = _splits({key: v[sub] for key, v in level.items()},
                                           np.repeat(np.arange(c_sub.size), c_sub), r_sub, r_sub + c_sub, lo[multi],
                                           hi[multi], axis[multi], theta_o[multi], theta_e[multi], energy[multi])
                    middle[multi] = np.where(m_sub >= 0, rel[multi] + m_sub - r_sub, -1)
                    perm[sub] = sub[p_sub]
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
        self.nodes = {key: np.array(v, dtype=np.float64 if key not in ("left", "right", "first", "count", "distant")
                                    else bool if key == "distant" else np.int64).reshape(
                                        (len(v), 3) if key in ("lo", "hi", "axis") else (len(v),))
                      for key, v in nodes.items()}
        self._paths(-1 if root is None else root)

    def _paths(self, root: int) -> None:
        """Per emitter: the nodes from the root to its leaf and whether each step goes right (``probability``),
        the emitter of each triangle and whole light (MIS lookups) and the kernels' TreeArrays."""
        nd, em = self.nodes, self.em
        K = nd["left"].shape[0]
        parent, right_child = np.full(K, -1), np.zeros(K, bool)
        inner = nd["left"] >= 0
        parent[nd["left"][inner]] = np.flatnonzero(inner)
        parent[nd["right"][inner]] = np.flatnonzero(inner)
        right_child[nd["right"][inner]] = True
        leaves = np.flatnonzero(~inner)
        leaves = leaves[np.argsort(nd["first"][leaves], kind="stable")]
        leaf_of = np.repeat(leaves, nd["count"][leaves])          # the leaves' ranges tile [0, E) in order
        # walk up from every leaf at once: its ancestors, root first (−1 padding above shallow leaves)
        chain = [leaves]
        while (chain[-1] >= 0).any():
            chain.append(np.where(chain[-1] >= 0, parent[np.maximum(chain[-1], 0)], -1))
        chain = np.array(chain[:-1])[::-1]
        steps_node = [np.where((a >= 0) & (b >= 0), a, -1) for a, b in zip(chain[:-1], chain[1:])]
        steps_right = [(a >= 0) & (b >= 0) & right_child[np.maximum(b, 0)] for a, b in zip(chain[:-1], chain[1:])]
        by_leaf = np.full(K, -1)
        by_leaf[leaves] = np.arange(leaves.size)
        row = by_leaf[leaf_of]
        depth = len(steps_node)        # (0: the root is a leaf, or there is no emitter)
        path_node = np.array(steps_node, np.int64).reshape(depth, leaves.size)[:, row]
        path_right = np.array(steps_right, bool).reshape(depth, leaves.size)[:, row]
        # where a triangle or a whole light is an emitter
        tri = em["tri"]
        self.emitter_of_triangle = np.full(len(self.compiled.faces), -1, np.int64)
        self.emitter_of_triangle[tri[tri >= 0]] = np.flatnonzero(tri >= 0)
        self.emitter_of_light = np.full(self.split.shape[0], -1, np.int64)
        self.emitter_of_light[em["light"][tri < 0]] = np.flatnonzero(tri < 0)
        theta_o = np.where(em["kind"] == POINT, 0.0, em["theta_o"])       # a point light's cone faces the point
        self.arrays = TreeArrays(
            nd["lo"], nd["hi"], nd["axis"], nd["theta_o"], nd["theta_e"], cone_cosines(nd["theta_o"], nd["theta_e"]),
            nd["energy"], *light_tree.box_measures(nd["lo"], nd["hi"]), nd["left"], nd["right"], nd["first"],
            nd["count"], nd["distant"], em["kind"],
            np.ascontiguousarray(em["centre"]), np.ascontiguousarray(em["axis"]), theta_o, em["theta_e"],
            cone_cosines(theta_o, em["theta_e"]), em["energy"], em["radius"], em["sphere"], em["cos_outer"],
            em["cos_inner"], self._corners(), em["light"], em["tri"], np.ascontiguousarray(path_node),
            np.ascontiguousarray(path_right), leaf_of.astype(np.int64), int(root))
        self.arrays = self.arrays._replace(packed=light_tree.pack(self.arrays))

    def _corners(self) -> np.ndarray:
        """(E, 8, 3): a triangle's three vertices (repeated) or the eight corners of a box (the importance's
        subtended angle and farthest distance)."""
        em, c = self.em, self.compiled
        lo, hi = em["lo"], em["hi"]
        bits = np.array([[(k >> a) & 1 for a in range(3)] for k in range(8)], bool)      # (8, 3)
        corners = np.where(bits[None], hi[:, None, :], lo[:, None, :])
        tri = em["tri"]
        is_tri = tri >= 0
        if is_tri.any():
            v = c.vertices[c.faces[tri[is_tri]]].astype(np.float64)         # (m, 3, 3)
            corners[is_tri] = v[:, [0, 1, 2, 0, 1, 2, 0, 1]]
        return np.ascontiguousarray(corners)

    # ------------------------------------------------------------------ choice and its probability

    def choose(self, u, p, n):
        """See the class docstring.  u (N,) in [0, 1), p (3, N), n (3, N) side normals (zero: transmitting)."""
        return light_tree.choose(self.arrays, u, p, n)

    def probability(self, emitter, p, n):
        """The probability (M,) that ``choose`` at points p, n (3, M) picks the emitters ``emitter`` (M,) (−1: 0),
        re-traversing their nodes from the root with the arithmetic of ``choose`` (Cycles' light_tree_pdf)."""
        return light_tree.probability(self.arrays, emitter, p, n)

    def probability_of_light(self, li, p, n):
        """Pick probability (M,) of the whole light ``li`` at points p, n (3, M) (0 for a split light: its
        triangles are the emitters)."""
        e = self.emitter_of_light[li] if li < self.emitter_of_light.shape[0] else -1
        return self.probability(np.full(p.shape[1], e, np.int64), p, n)

    def probability_of_triangles(self, prims, p, n):
        """Pick probability (M,) of the triangles ``prims`` (M,) (emitters of split lights) at points p, n."""
        return self.probability(self.emitter_of_triangle[prims], p, n)


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
