"""Per-object ray visibility, holdout and pass-through (alpha) surfaces, as Cycles' Object ▸
Visibility and Principled Alpha.

Rays that meet a surface they must not see, or a pass-through surface (alpha < 1, crossed with
probability 1 − alpha), continue along the same direction from just behind it: a null
interaction that changes neither the Stokes vector nor its frame and does not count as a bounce
(Cycles' transparent bounces; at most ``MAX_PASS_THROUGH`` per segment).  Shadow rays cross
shadow-invisible surfaces and are attenuated by 1 − alpha at pass-through ones (transparent
shadows).  Alpha may vary over a surface (a TexturedNumber: Principled Alpha from an image's alpha, a
glTF cut-out or blend): it is read at each crossing's triangle and barycentrics.  Scenes without any of
these features never reach this module's loops, so their images are unchanged.

Pass-through crossings are where a path enters or leaves an absorbing interior without a bounce
(a Blender material with only a Volume output, a hidden glass's alpha): both loops can ``record``
them — (rays, triangles, distances from the segment's origin), one layer per crossing — for the
integrator's medium stacks (engine.render.media).  Hidden surfaces are not recorded: as in Cycles,
rays that do not see an object do not enter its volume.
"""

from __future__ import annotations

import numpy as np

from ..kernels.hashing import uniforms
from ..textures import TexturedNumber
from .accel import Hits, offset_origin, surface_points

#: Surfaces a ray may cross before it is treated as blocked (Cycles' default transparent bounces: 8;
#: more here because invisible objects count too).
MAX_PASS_THROUGH = 32
#: Random-number dimensions of the pass-through decisions live far above the path's own dimensions.
_PASS_DIMENSION = 1 << 40
_GOLDEN = 0x9E3779B97F4A7C15
_MASK64 = (1 << 64) - 1


class RayVisibility:
    """Per-mesh flags indexed by the compiled scene's ``tri_mesh``; build with ``ray_visibility``."""

    def __init__(self, mesh_rays, tri_mesh: np.ndarray, compiled=None):
        flags = np.array([r[:4] for r in mesh_rays], bool).reshape(-1, 4)
        self.tri_mesh = tri_mesh
        self.camera_hidden, self.indirect_hidden, self.shadow_hidden = ~flags[:, 0], ~flags[:, 1], ~flags[:, 2]
        self.holdout = flags[:, 3]
        #: meshes whose alpha varies over the surface (a TexturedNumber: Principled Alpha from a texture),
        #: read at the hit's triangle and barycentrics; their entry in ``alpha`` is its least value
        self.textured_alpha = {i: r[4] for i, r in enumerate(mesh_rays) if isinstance(r[4], TexturedNumber)}
        self.compiled = compiled
        self.alpha = np.array([float(r[4].lo) if i in self.textured_alpha else float(r[4])
                               for i, r in enumerate(mesh_rays)], np.float64)
        self.any_alpha = bool((self.alpha < 1).any())
        #: triangles whose material scatters nothing (BSDF.scatters_nothing: an emitter's or unlit material):
        #: camera rays cross their alpha deterministically (``pass_through``'s ``null_crossings``)
        self.tri_null = None
        if compiled is not None and self.any_alpha:
            null = np.array([getattr(m, "scatters_nothing", False) for m in compiled.materials], bool)
            tri_null = null[compiled.tri_material] & (self.alpha[tri_mesh] < 1)
            self.tri_null = null[compiled.tri_material] if tri_null.any() else None
        self.any_holdout = bool(self.holdout.any())
        self.affects_shadows = bool(self.shadow_hidden.any() or self.any_alpha)
        #: (camera rays, indirect rays): whether ``pass_through`` can skip any surface for them
        self._skips = (self.any_alpha or bool(self.camera_hidden.any()),
                       self.any_alpha or bool(self.indirect_hidden.any()))

    def alpha_at(self, mesh: np.ndarray, prim: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Alpha (N,) at hits on triangles ``prim`` (of meshes ``mesh``) at barycentrics u, v: the mesh's
        constant, or its texture's value there (clipped to [0, 1])."""
        a = self.alpha[mesh]
        if not self.textured_alpha:
            return a
        a = a.copy()
        for i, value in self.textured_alpha.items():
            sel = np.nonzero(mesh == i)[0]
            if sel.size:
                points = surface_points(self.compiled, prim[sel], u[sel], v[sel])
                a[sel] = np.clip(value.at(points), 0.0, 1.0)
        return a

    # ------------------------------------------------------------------ camera and indirect rays

    def pass_through(self, scene, o: np.ndarray, d: np.ndarray, t_max: np.ndarray | None, hits: Hits,
                     camera: bool, keys: np.ndarray, bounce: int, record: list | None = None,
                     null_crossings: list | None = None) -> tuple[Hits, int]:
        """The first hit each ray really sees (hidden and chosen pass-through surfaces skipped), and
        the number of extra rays cast.  ``camera``: the segment starts at the camera.  ``record``: a
        list to which the crossed pass-through (alpha) surfaces are appended, one layer per crossing:
        (rays (m,) int64, triangles (m,), distances from o (m,)) (hidden surfaces are not crossings).
        With ``record`` the distances, and the returned hits' t, also count the offsets by which each
        continued ray starts past the surface it crossed (the distances along d from o, as the medium
        attenuation needs them); without it they are the sum of the rays' own t (as before).
        ``null_crossings``: a list, for camera rays (``tri_null`` set): a surface that scatters nothing is crossed
        always instead of with probability 1 − alpha, and the crossing appended as (rays, triangles, u, v,
        distances, alpha) — the caller adds alpha × its emission and weights the ray by 1 − alpha, as Cycles
        handles a Transparent BSDF mixed with an emission (no random choice: far less noise, same mean)."""
        if not self._skips[0 if camera else 1]:
            return hits, 0          # nothing these rays could cross: their hits as they are
        hidden = self.camera_hidden if camera else self.indirect_hidden
        prim, u, v, t = hits.prim.copy(), hits.u.copy(), hits.v.copy(), hits.t.copy()
        active = np.arange(prim.shape[0])
        extra = 0
        for it in range(MAX_PASS_THROUGH):
            p_act = prim[active]
            hit = p_act >= 0
            mesh = self.tri_mesh[np.where(hit, p_act, 0)]
            skip = hit & hidden[mesh]
            if self.any_alpha:
                a = self.alpha_at(mesh, np.where(hit, p_act, 0), u[active], v[active])
                partial = hit & ~skip & (a < 1)
                if partial.any():
                    dim = (_PASS_DIMENSION + bounce * 4096 + it) * _GOLDEN & _MASK64
                    xi = uniforms(keys[active], np.array([dim], np.uint64))[0]
                    crossed = partial & (xi >= a)      # crossed with probability 1 − alpha
                    if null_crossings is not None and self.tri_null is not None:
                        null = partial & self.tri_null[np.where(hit, p_act, 0)]
                        if null.any():
                            rays = active[null]
                            null_crossings.append((rays, prim[rays].copy(), u[rays].copy(), v[rays].copy(),
                                                   t[rays].copy(), a[null]))
                            crossed |= null
                    skip |= crossed
                    if record is not None and crossed.any():
                        rays = active[crossed]
                        record.append((rays, prim[rays].copy(), t[rays].copy()))
            active = active[skip]
            if active.size == 0:
                break
            p, n_g, _ = scene.surface(prim[active], u[active], v[active])
            da = d[:, active]
            o2 = offset_origin(p, n_g, da)
            tm = None if t_max is None else np.maximum(t_max[active] - t[active], 0.0)
            h = scene.intersect(o2, da, tm)
            extra += active.size
            prim[active], u[active], v[active] = h.prim, h.u, h.v
            if record is not None:
                t[active] += ((o2 - p) * da).sum(axis=0)       # the continued ray starts past the surface
            t[active] = np.where(h.prim >= 0, t[active] + h.t, h.t)
        # (rays still crossing after MAX_PASS_THROUGH layers keep their last hit)
        return Hits(prim, u, v, t), extra

    # ------------------------------------------------------------------ shadow rays

    def transmittance(self, scene, o: np.ndarray, d: np.ndarray, t_max: np.ndarray,
                      record: list | None = None) -> tuple[np.ndarray, int]:
        """Fraction (N,) of light that reaches o from o + t_max·d through shadow-invisible and
        pass-through surfaces (0 where something opaque blocks), and the number of rays cast.
        ``record``: a list to which the pass-through (alpha) surfaces crossed are appended as in
        ``pass_through`` (rays, triangles, distances from o)."""
        n = o.shape[1]
        trans = np.ones(n)
        active = np.arange(n)
        o_act, tm = o, t_max.copy()
        start = np.zeros(n) if record is not None else None     # distance of each ray's origin from o
        rays = 0
        for _ in range(MAX_PASS_THROUGH + 1):
            h = scene.intersect(o_act, d[:, active], tm)
            rays += active.size
            hit = h.prim >= 0
            mesh = self.tri_mesh[np.where(hit, h.prim, 0)]
            alpha = self.alpha_at(mesh, np.where(hit, h.prim, 0), h.u, h.v) if self.any_alpha else self.alpha[mesh]
            crossable = hit & (self.shadow_hidden[mesh] | (alpha < 1))
            opaque = hit & ~crossable
            trans[active[opaque]] = 0.0
            factor = np.where(self.shadow_hidden[mesh], 1.0, 1.0 - alpha)
            trans[active[crossable]] *= factor[crossable]
            keep = crossable & (trans[active] > 0)
            if record is not None:
                at = start[active] + h.t
                alpha_crossed = keep & ~self.shadow_hidden[mesh]
                if alpha_crossed.any():
                    record.append((active[alpha_crossed], h.prim[alpha_crossed].copy(), at[alpha_crossed]))
                start[active[keep]] = at[keep]
            if not keep.any():
                return trans, rays
            active = active[keep]
            p, n_g, _ = scene.surface(h.prim[keep], h.u[keep], h.v[keep])
            o_act = offset_origin(p, n_g, d[:, active])
            if record is not None:
                start[active] += ((o_act - p) * d[:, active]).sum(axis=0)
            tm = np.maximum(tm[keep] - h.t[keep], 0.0)
        trans[active] = 0.0                       # more layers than allowed: blocked
        return trans, rays


def ray_visibility(scene) -> RayVisibility | None:
    """The compiled scene's RayVisibility, or None when every mesh has the defaults (fast path)."""
    if all(cam and ind and sh and not hold and not isinstance(alpha, TexturedNumber) and alpha >= 1
           for cam, ind, sh, hold, alpha in scene.mesh_rays):
        return None
    return RayVisibility(scene.mesh_rays, scene.tri_mesh, scene)
