"""The compiled scene: all meshes merged into one Embree BVH plus per-triangle data.

The BVH is queried from compiled loops through Embree's C API (engine.render.embree_direct), or through
embreex without Numba (``ray_scene``: the same hits).  Embree works in float32 and has no t_near, so secondary
rays start at a point offset along the geometric normal (see
``offset_origin``).  Positions on surfaces are reconstructed in float64 from
the barycentric coordinates rather than from o + t·d.
"""

from __future__ import annotations

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

from ..kernels import twin
from ..kernels.geometry import offset_origin as offset_origin_kernel, surface_attributes
from ..kernels.rays import MAX_DISTANCE, closest_hits_loop, embree_hits, embree_rays, segments_near_box
from ..scene.description import Scene, interior_of
from ..textures import SurfacePoints, VertexAttributes

# Mitsuba 3's float32 ray epsilon: offsets scale with (1 + max|p_i|).
RAY_EPSILON = 8.9e-5


class EmbreexScene:
    """One triangle mesh (vertices (V, 3), triangles (F, 3)) as an embreex scene: the reference queries.

    Robust (watertight) traversal, as embreex's default: without it queries are ≈ 20 % faster (Mitsuba 3's
    setting) but rays aimed at a closed mesh's shared edges slip through it (tests/render/test_accel.py)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.embree = rtcs.EmbreeScene(robust=True)
        TriangleMesh(self.embree, np.asarray(vertices, np.float32), np.asarray(faces, np.int32))

    def closest(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray | None, prims: np.ndarray | None):
        """(prim (N,) int64, −1 = miss, mapped through ``prims`` unless None; u, v, t (N,) float64)."""
        of, df, dists = embree_rays(o, d, t_max)
        res = self.embree.run(of, df, output=1) if dists is None else self.embree.run(of, df, dists=dists, output=1)
        return embree_hits(res["primID"], res["u"], res["v"], res["tfar"], prims)

    def occluded(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray) -> np.ndarray:
        """True where the segment o → o + t_max·d is blocked."""
        of, df, dists = embree_rays(o, d, t_max)
        return self.embree.run(of, df, dists=dists, query="OCCLUDED") == 0


def ray_scene_numpy(vertices: np.ndarray, faces: np.ndarray) -> EmbreexScene:
    """The scene the queries run on: embreex's."""
    return EmbreexScene(vertices, faces)


def ray_scene_numba(vertices: np.ndarray, faces: np.ndarray):
    """The same scene built through Embree's C API and queried from compiled loops (the same hits,
    without embreex's per-call arrays: engine.render.embree_direct), embreex's where its library is not found."""
    from .embree_direct import DirectScene, library
    lib = library()
    return EmbreexScene(vertices, faces) if lib is None else DirectScene(lib, vertices, faces)


#: The Embree scene of a mesh, with ``closest`` and ``occluded`` queries.
ray_scene = twin(closest_hits_loop and ray_scene_numba, ray_scene_numpy)


class NoTriangles:
    """The queries of a scene without triangles (a world-only scene, or one of lamps alone): every ray
    misses, as Embree's misses (prim −1, u = v = 0, t the ray's float32 length, unbounded: 1e37), no
    shadow ray is blocked."""

    def closest(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray | None, prims: np.ndarray | None):
        n = o.shape[1]
        t = (np.full(n, MAX_DISTANCE, np.float32) if t_max is None
             else np.minimum(np.asarray(t_max, np.float64), MAX_DISTANCE).astype(np.float32))
        return np.full(n, -1, np.int64), np.zeros(n), np.zeros(n), t.astype(np.float64)

    def occluded(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray) -> np.ndarray:
        return np.zeros(o.shape[1], bool)


class Hits:
    """Closest hits of a ray batch: ``prim`` (N,) global triangle index (−1 = miss), barycentrics u, v, distance t."""

    __slots__ = ("prim", "u", "v", "t")

    def __init__(self, prim, u, v, t):
        self.prim, self.u, self.v, self.t = prim, u, v, t


class CompiledScene:
    """Geometry ready for ray casting: merged triangles, normals, material and emitter ids."""

    def __init__(self, scene: Scene):
        # A scene without meshes (a world alone, as Cycles renders it) has empty triangle arrays: every
        # camera ray misses and sees the environment.
        self.material_names = list(scene.materials)
        self.materials = [scene.materials[n] for n in self.material_names]
        mat_index = {n: i for i, n in enumerate(self.material_names)}

        verts, faces, tri_mat, tri_mesh, vnormals, has_vn = [], [], [], [], [], []
        offset = 0
        for mi, mesh in enumerate(scene.meshes):
            v = np.asarray(mesh.vertices, np.float64)
            f = np.asarray(mesh.faces, np.int64) + offset
            verts.append(v)
            faces.append(f)
            lut = np.array([mat_index[m] for m in mesh.materials], dtype=np.int32)
            tri_mat.append(lut[mesh.material_ids])
            tri_mesh.append(np.full(len(f), mi, np.int32))
            if mesh.normals is not None:
                vnormals.append(np.asarray(mesh.normals, np.float64))
                has_vn.append(np.ones(len(f), bool))
            else:
                vnormals.append(np.zeros_like(v))
                has_vn.append(np.zeros(len(f), bool))
            offset += len(v)
        if not scene.meshes:
            verts, faces, vnormals = [np.zeros((0, 3))], [np.zeros((0, 3), np.int64)], [np.zeros((0, 3))]
            tri_mat, tri_mesh, has_vn = [np.zeros(0, np.int32)], [np.zeros(0, np.int32)], [np.zeros(0, bool)]
        self.vertices = np.concatenate(verts)
        self.faces = np.concatenate(faces)
        self.tri_material = np.concatenate(tri_mat)
        #: indices of the materials some triangle uses (sorted; every render asks, so found once here)
        self.used_materials = np.unique(self.tri_material)
        self.tri_mesh = np.concatenate(tri_mesh)
        self._volumes()
        self.vertex_normals = np.concatenate(vnormals)
        self.tri_has_normals = np.concatenate(has_vn)
        self.any_vertex_normals = bool(self.tri_has_normals.any())

        v0, v1, v2 = (self.vertices[self.faces[:, i]] for i in range(3))
        cross = np.cross(v1 - v0, v2 - v0)
        length = np.linalg.norm(cross, axis=1)
        self.tri_area = 0.5 * length
        self.tri_normal = cross / np.where(length > 0, length, 1.0)[:, None]
        self.scene_extent = float(np.abs(self.vertices).max()) if len(self.vertices) else 1.0

        self.attributes = _vertex_attributes(scene.meshes, self.faces, len(self.vertices))

        # per-object ray visibility, holdout and alpha (engine.render.visibility reads them via tri_mesh)
        self.mesh_rays = [(m.visible_camera, m.visible_indirect, m.visible_shadow, m.holdout, m.alpha)
                          for m in scene.meshes]
        # tri_emitter is filled in by the light set (area lights).
        self.tri_emitter = np.full(len(self.faces), -1, np.int32)
        self._separate_passthrough_emitters(scene)

    def _volumes(self) -> None:
        """Absorbing interiors (engine.scene.description.Interior, on the materials): every (mesh,
        material) pair whose material absorbs is one volume; ``tri_volume`` (F,) int32 its index per
        triangle (−1: none; None when the scene has no volume) and ``volumes`` [(mesh, material, Interior)]."""
        interiors = [interior_of(m) for m in self.materials]
        self.volumes = []
        self.tri_volume = None
        absorbing = np.array([i is not None for i in interiors], bool)
        if not absorbing.any():
            return
        inside = absorbing[self.tri_material]
        count = len(self.materials)
        keys = self.tri_mesh[inside].astype(np.int64) * count + self.tri_material[inside]
        unique, index = np.unique(keys, return_inverse=True)
        self.tri_volume = np.full(len(self.tri_material), -1, np.int32)
        self.tri_volume[inside] = index.astype(np.int32)
        self.volumes = [(int(k // count), int(k % count), interiors[int(k % count)]) for k in unique]

    @property
    def has_volumes(self) -> bool:
        """Some mesh bounds an absorbing interior."""
        return self.tri_volume is not None

    def _separate_passthrough_emitters(self, scene: Scene) -> None:
        """Keep non-occluding emitters (Cycles' lamps) out of the main BVH: shadow rays and paths
        pass through them; ``passthrough_hits`` finds where a segment crosses them (their own BVH)."""
        occluding = np.array([getattr(m, "occluder", True) or m.emission is None for m in scene.meshes], bool)
        self.tri_occluder = occluding[self.tri_mesh]
        self.passthrough_prims = np.nonzero(~self.tri_occluder)[0]
        self.has_passthrough = self.passthrough_prims.size > 0
        self._main_prims = None
        if not self.has_passthrough:
            self.rays = ray_scene(self.vertices, self.faces) if len(self.faces) else NoTriangles()
            return
        self._main_prims = np.nonzero(self.tri_occluder)[0]
        # lamps alone (no occluding geometry): the lamps are seen and light nothing
        self.rays = (ray_scene(self.vertices, self.faces[self._main_prims]) if self._main_prims.size
                     else NoTriangles())
        self.rays_passthrough = ray_scene(self.vertices, self.faces[self.passthrough_prims])
        corners = self.vertices[self.faces[self.passthrough_prims].ravel()]
        self.passthrough_box = (corners.min(axis=0), corners.max(axis=0))

    @property
    def used_material_names(self) -> set[str]:
        """Names of the materials some triangle uses."""
        return {self.material_names[i] for i in self.used_materials}

    @property
    def has_area_lights(self) -> bool:
        """True if some triangle emits (set by the light set)."""
        return bool((self.tri_emitter >= 0).any())

    # ------------------------------------------------------------------ ray casting

    def intersect(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray | None = None) -> Hits:
        """Closest hits for origins o and unit directions d, both (3, N)."""
        return Hits(*self.rays.closest(o, d, t_max, self._main_prims))

    def passthrough_hits(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray,
                         max_layers: int = 8) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Every crossing of the segments o → o + t_max·d (t_max may be inf) with non-occluding
        emitters, as a list of layers (ray index, global triangle, distance from o): layer k holds
        each ray's k-th crossing (so a ray appears at most once per layer), up to ``max_layers``.

        Each layer restarts just past the previous crossing (Embree has no t_near).  Only the segments that pass
        near the emitters' bounding box (``passthrough_box``; engine.kernels.rays.segments_near_box, a conservative
        test) are handed to Embree: the others cannot cross them, and Embree answers each ray alike whatever rays
        share its query.
        """
        layers = []
        if not self.has_passthrough or o.shape[1] == 0:
            return layers
        t_left = np.asarray(t_max, np.float64)
        near = segments_near_box(o, d, t_left, *self.passthrough_box)
        if near.all():
            idx, o_cur, whole = np.arange(o.shape[1]), o, True
        else:
            idx = np.flatnonzero(near)
            if idx.size == 0:
                return layers
            o_cur, t_left, whole = np.take(o, idx, axis=1), t_left[idx], False
        start = np.zeros(idx.size)
        for layer in range(max_layers):
            # (the first layer with every ray: d as it is, not a gathered copy)
            d_cur = d if layer == 0 and whole and d.flags.c_contiguous else d[:, idx]
            local, _, _, t = self.rays_passthrough.closest(o_cur, d_cur, t_left, None)
            got = local >= 0
            if not got.any():
                break
            t = t[got]
            layers.append((idx[got], self.passthrough_prims[local[got]], start[got] + t))
            # continue just past the crossing
            step = t + RAY_EPSILON * (1.0 + np.abs(o_cur[:, got]).max(0))
            idx, start, t_left = idx[got], start[got] + step, t_left[got] - step
            o_cur = o_cur[:, got] + d[:, idx] * step[None, :]
            keep = t_left > 0
            idx, start, t_left, o_cur = idx[keep], start[keep], t_left[keep], o_cur[:, keep]
            if idx.size == 0:
                break
        return layers

    def occluded(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray) -> np.ndarray:
        """True where the segment o → o + t_max·d is blocked."""
        return self.rays.occluded(o, d, t_max)

    def unblock_own_hits(self, emitter: int | np.ndarray, p: np.ndarray, n_g: np.ndarray, wi: np.ndarray,
                         dist: np.ndarray, cos_l: np.ndarray, blocked: np.ndarray) -> np.ndarray:
        """``blocked`` with the shadow rays p → p + dist·wi towards emitter ``emitter`` (an index, or one per ray
        (N,)) cleared where they were stopped by that emitter itself.

        A shadow ray starts at p offset along n_g, parallel to p → x, so it meets the emitter's
        plane earlier than ``dist`` by about offset/cosθ_light (``cos_l``); at grazing angles that
        exceeds the t_max margin and an opaque emitter shadows itself.  A blocked ray whose first
        hit is the emitter within that distance of x is visible after all.
        """
        idx = blocked.nonzero()[0]
        o = offset_origin(p[:, idx], n_g[:, idx], wi[:, idx])
        d = dist[idx]
        hits = self.intersect(o, wi[:, idx], d * 1.001 + 1e-3)
        slack = (4.0 * RAY_EPSILON * (1.0 + np.abs(p[:, idx]).max(0)) / np.maximum(cos_l[idx], 1e-3)
                 + 1e-4 * (1.0 + d))
        mine = emitter if np.ndim(emitter) == 0 else np.asarray(emitter)[idx]
        own = (hits.prim >= 0) & (self.tri_emitter[np.maximum(hits.prim, 0)] == mine) & (hits.t >= d - slack)
        out = blocked.copy()
        out[idx[own]] = False
        return out

    # ------------------------------------------------------------------ surface data

    def surface(self, prim: np.ndarray, u: np.ndarray, v: np.ndarray):
        """(p, n_g, n_s) as (3, N) float64 at the hits ``prim`` with barycentrics (u, v).

        n_g is the face normal by winding; n_s the interpolated vertex normal
        (or n_g for flat faces and degenerate interpolations).
        """
        return surface_attributes(self.faces, self.vertices, self.vertex_normals, self.tri_has_normals,
                                  self.tri_normal, self.any_vertex_normals, prim, u, v)


def _vertex_attributes(meshes, faces: np.ndarray, n_vertices: int) -> VertexAttributes | None:
    """UVs, colour attributes and tangents of all meshes in the merged vertex numbering (None if no
    mesh has any): a mesh without UVs gets (0, 0), one without a colour attribute 0 (as Blender),
    one without tangents 0 (then derived from its UVs)."""
    names = sorted({name for mesh in meshes for name in mesh.colors})
    has_tangents = any(mesh.tangents is not None for mesh in meshes)
    if not names and not has_tangents and all(mesh.uv is None for mesh in meshes):
        return None
    uv = np.zeros((n_vertices, 2))
    tangents = np.zeros((n_vertices, 4)) if has_tangents else None
    layers = {name: np.zeros((n_vertices, max(np.shape(m.colors[name])[1] for m in meshes if name in m.colors)))
              for name in names}
    offset = 0
    for mesh in meshes:
        nv = len(mesh.vertices)
        if mesh.uv is not None:
            uv[offset:offset + nv] = mesh.uv
        if mesh.tangents is not None:
            tangents[offset:offset + nv] = mesh.tangents
        for name, values in mesh.colors.items():
            values = np.asarray(values, np.float64)
            layers[name][offset:offset + nv, :values.shape[1]] = values
        offset += nv
    return VertexAttributes(faces, uv, layers, np.concatenate([np.asarray(m.vertices, np.float64) for m in meshes]),
                            tangents)


def surface_points(compiled: CompiledScene, prim: np.ndarray, u: np.ndarray, v: np.ndarray) -> SurfacePoints:
    """The hits' handle on per-vertex attributes (UV, colours) for textured materials."""
    attributes = compiled.attributes
    if attributes is None:     # no mesh has attributes: UV (0, 0), colours 0 everywhere
        attributes = compiled.attributes = VertexAttributes(compiled.faces, None, {}, compiled.vertices)
    return SurfacePoints(attributes, prim, u, v)


def offset_origin(p: np.ndarray, n_g: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Start point of a ray leaving surface point p in direction w (all (3, N)).

    Moved along the geometric normal to the side w leaves from, by
    (1 + max|p_i|)·8.9e-5 (Mitsuba 3's rule), which keeps float32 Embree from
    re-hitting the same triangle at grazing angles.
    """
    return offset_origin_kernel(p, n_g, w, RAY_EPSILON)
