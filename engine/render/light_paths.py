"""Cycles' Light Paths in the wavefront tracer: per-kind bounce limits, sample clamping and the caustics
switches (RenderSettings ``max_*_bounces``, ``clamp_direct`` / ``clamp_indirect``, ``caustics_*``;
engine.scene.description.LIGHT_PATH_FIELDS).

With none of them set the tracer never comes here (PathTracer.trace runs its own loop, the arithmetic of
every render before them); with any set it runs :func:`trace_light_paths`, the same stages plus the
bookkeeping below, kept per path of the batch (indexed by the batch's path index, so the PathState's
compaction never has to carry it).

Bounce kinds (Cycles' path_state_next).  Each sampled continuation is classified by the lobe it took:
transmission when the new direction crosses the surface (n_g·ω_i and n_g·ω_o of opposite signs), a NULL
lobe's straight pass-through (ω_i = −ω_o at a material with a NULL lobe) "transparent", else reflection;
a reflection is "diffuse" at a material whose reflection lobes are diffuse only (Lambert), "glossy"
otherwise (microfacet and mirror lobes: Cycles counts singular reflections as glossy).  A material with
both diffuse and non-mirror glossy lobes in the sampled hemisphere (a Principled-like mixture, a coat over
a diffuse base) does not report which lobe its sample took: its non-mirror bounces count as diffuse.  A
scattering event in a participating medium (a medium vertex, engine.render.participating) is a "volume" bounce
(Cycles' Volume bounces: ``max_volume_bounces``; a path past it crosses media without scattering, as Cycles'
absorption-only volumes — killing it at its next collision has that expectation).
Cycles keeps a counter per kind; when a bounce makes its kind's counter exceed the kind's limit the path
ends at its next surface, whose emission (MIS-weighted) still counts — as ``max_depth`` ends a path.  So
``max_diffuse_bounces`` 0 renders a diffuse surface's direct light only.  Transparent crossings of alpha
(pass-through) surfaces are traced inside the intersection (engine.render.visibility, at most
MAX_PASS_THROUGH per segment) and are not counted against ``max_transparent_bounces``; only NULL-lobe
materials (filter sheets) are.

Clamping (Cycles' film_clamp_light).  Every light contribution of a sample — the emission a segment
reaches (with the alpha crossings' emission before it) and the light sample of a vertex — is converted to
linear sRGB as the film converts it (per path: Σ_λ S0(λ)·w_rgb(λ)), and where the largest of |R|, |G|, |B|
of its S0 exceeds the limit, all its Stokes components at every wavelength are scaled by limit ÷ that
component: the polarisation (DoP, AoLP) of the contribution is unchanged.  (The kernel source shipped with
bpy 5.0 reads ``reduce_add(fabs(L))``, but Cycles' renders clamp the largest component, measured: a white sky
of radiance 1 stays 1 under Clamp Direct 1, a mirror's 0.81 becomes 0.5 under Clamp Indirect 0.5 —
tests/blender/test_cycles_light_paths.py.)  Cycles' "direct" limit applies to the
segments from the camera and from the first vertex and to the first vertex's light sample; every other
contribution uses the "indirect" limit.  0 = no clamp (Cycles).

Caustics (Cycles' svm closure setup: ``!caustics_reflective && (path_flag & PATH_RAY_DIFFUSE)``).  At a
vertex reached by a diffuse bounce, with ``caustics_reflective`` off the glossy and mirror reflection lobes
are dropped, with ``caustics_refractive`` off the glossy and smooth transmission lobes: a BSDF sample that
took a dropped lobe ends the path there, and at a material all of whose lobes are dropped the light sample
adds nothing either.  A material that keeps some lobe keeps its whole light sample (its evaluation does not
separate the lobes).

The compiled per-path loop (engine.render.path_loop) does not do this bookkeeping: it must refuse any
settings whose ``light_paths_active`` is True (``tracer.settings.light_paths_active``, equivalently
``tracer.light_paths is not None``), which leaves them to this wavefront loop.  Limits at or above
``max_depth`` − 2 cannot end a path earlier than ``max_depth`` and do not count as active (the Cycles parity
tests set every kind's limit to the total bounces: those renders keep the plain loop).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..materials.flags import BSDFFlags
from ..vec3 import dot

if TYPE_CHECKING:
    import threading

#: The bounce kinds, in the order of the per-path counters
KINDS = ("diffuse", "glossy", "transmission", "transparent", "volume")
DIFFUSE, GLOSSY, TRANSMISSION, TRANSPARENT, VOLUME = range(5)


def describe(settings) -> str:
    """The light-path limits that can change the image, for the stats line ("" when none: the plain loop), e.g.
    "diffuse ≤ 1, clamp indirect 0.5, no refractive caustics"."""
    if not getattr(settings, "light_paths_active", False):
        return ""
    parts = [f"{kind} ≤ {getattr(settings, f'max_{kind}_bounces')}" for kind in KINDS
             if getattr(settings, f"max_{kind}_bounces") < settings.max_depth - 2]
    parts += [f"clamp {which} {getattr(settings, f'clamp_{which}'):g}" for which in ("direct", "indirect")
              if getattr(settings, f"clamp_{which}") > 0]
    parts += [f"no {which} caustics" for which in ("reflective", "refractive")
              if not getattr(settings, f"caustics_{which}")]
    return ", ".join(parts)


class LightPathRules:
    """The light-path settings of a render, resolved once per tracer: the limits (5,), the clamps and, by
    material index, what each material's lobes are (see the module docstring); a material with a true
    ``medium_vertex`` attribute (a medium's phase function: engine.render.participating) scatters volume bounces."""

    def __init__(self, settings, materials: list):
        self.limits = np.array([getattr(settings, f"max_{kind}_bounces") for kind in KINDS], np.int64)
        # (a limit at or above max_depth − 2 ends no path before max_depth does: RenderSettings.light_paths_active)
        self.counting = bool((self.limits < settings.max_depth - 2).any())
        self.clamp_direct = float(settings.clamp_direct) or np.inf
        self.clamp_indirect = float(settings.clamp_indirect) or np.inf
        self.clamping = np.isfinite(self.clamp_direct) or np.isfinite(self.clamp_indirect)
        dropped = BSDFFlags.NONE
        if not settings.caustics_reflective:
            dropped |= BSDFFlags.GLOSSY_REFLECTION | BSDFFlags.DELTA_REFLECTION
        if not settings.caustics_refractive:
            dropped |= BSDFFlags.GLOSSY_TRANSMISSION | BSDFFlags.DELTA_TRANSMISSION
        self.dropped = int(dropped)
        lobes = [m.flags.lobes for m in materials]
        self.lobes = np.array([int(f) for f in lobes], np.int64)
        # reflections at these materials are diffuse bounces: diffuse reflection lobes and no glossy one
        # (mirror lobes are told apart by the sample's is_delta)
        self.diffuse_reflection = np.array([f.has(BSDFFlags.DIFFUSE_REFLECTION)
                                            and not f.has(BSDFFlags.GLOSSY_REFLECTION) for f in lobes], bool)
        self.diffuse_transmission = np.array([f.has(BSDFFlags.DIFFUSE_TRANSMISSION)
                                              and not f.has(BSDFFlags.GLOSSY_TRANSMISSION) for f in lobes], bool)
        self.null = np.array([f.has(BSDFFlags.NULL) for f in lobes], bool)
        self.volume = np.array([bool(getattr(m, "medium_vertex", False)) for m in materials], bool)
        # every lobe dropped after a diffuse bounce (the light sample adds nothing there)
        self.all_dropped = np.array([bool(dropped) and (int(f) & ~self.dropped) == 0 for f in lobes], bool)
        self.dropping = bool(dropped)

    def batch(self, n_total: int) -> LightPathBatch:
        return LightPathBatch(self, n_total)


class LightPathBatch:
    """The bookkeeping of one batch: bounce counters (5, N), the paths that end at their next surface and
    those whose last bounce was diffuse, by batch path index."""

    def __init__(self, rules: LightPathRules, n_total: int):
        self.rules = rules
        self.counts = np.zeros((len(KINDS), n_total), np.int32) if rules.counting else None
        self.stop = np.zeros(n_total, bool)
        self.after_diffuse = np.zeros(n_total, bool)

    # ------------------------------------------------------------------ clamping and dropped light samples

    def mark(self, acc, path: np.ndarray) -> tuple | None:
        """The radiance of the paths ``path`` before a stage adds light (None: nothing to clamp or drop)."""
        if not (self.rules.clamping or self.rules.dropping):
            return None
        ids = path.copy()
        return ids, acc.radiance[:, :, ids].copy()

    def settle(self, acc, mark: tuple | None, direct: bool, drop: np.ndarray | None = None) -> np.ndarray | None:
        """Clamp the light added since ``mark`` (per path: one contribution) with the direct or indirect
        limit; ``drop`` (n,) bool: paths whose contribution is dropped entirely (caustics).  Returns the factor
        (n,) each path's contribution was scaled by (None: 1)."""
        if mark is None:
            return None
        ids, before = mark
        limit = self.rules.clamp_direct if direct else self.rules.clamp_indirect
        if not np.isfinite(limit) and (drop is None or not drop.any()):
            return None
        added = acc.radiance[:, :, ids] - before
        factor = np.ones(ids.size)
        if np.isfinite(limit):
            total = np.abs(contribution_rgb(added[0], acc.w_rgb, ids)).max(axis=0)
            over = total > limit
            factor[over] = limit / total[over]
        if drop is not None:
            factor[drop] = 0.0
        changed = factor != 1.0
        if changed.any():
            rows = ids[changed]
            acc.radiance[:, :, rows] = before[:, :, changed] + added[:, :, changed] * factor[changed]
        return factor

    # ------------------------------------------------------------------ bounces

    def continuing(self, path: np.ndarray, hit: np.ndarray) -> np.ndarray:
        """``hit`` without the paths that end at this surface (a kind's limit was passed by their last bounce)."""
        stop = self.stop[path]
        return hit & ~stop if stop.any() else hit

    def materials(self, tracer, prim: np.ndarray) -> np.ndarray:
        """(n,) material index of the hits (the scene's, as the scatter reads it)."""
        return tracer.scene.tri_material[prim]

    def dropped_light(self, path: np.ndarray, mat: np.ndarray) -> np.ndarray | None:
        """(n,) True where a vertex's light sample adds nothing: every lobe of its material is dropped
        after the diffuse bounce that reached it (None: none)."""
        if not self.rules.dropping:
            return None
        drop = self.after_diffuse[path] & self.rules.all_dropped[mat]
        return drop if drop.any() else None

    def scattered(self, path: np.ndarray, mat: np.ndarray, n_g: np.ndarray, wo: np.ndarray, nxt) -> None:
        """Classify the sampled continuations ``nxt`` (engine.render.integrator._Scattered) of the paths
        ``path`` at materials ``mat``: end the ones that took a dropped lobe after a diffuse bounce (their
        ``valid`` cleared), count the bounces and mark the paths that end at their next surface."""
        rules = self.rules
        kind, lobe = classify(rules, mat, n_g, wo, nxt.d, nxt.is_delta)
        if rules.dropping:
            gone = self.after_diffuse[path] & ((lobe & rules.dropped) != 0)
            if gone.any():
                nxt.valid &= ~gone
        if self.counts is not None:
            counts = self.counts[kind, path] + 1
            self.counts[kind, path] = counts
            self.stop[path] = counts > rules.limits[kind]
        if rules.dropping:
            transparent = kind == TRANSPARENT        # Cycles: a transparent crossing keeps the ray's flags
            self.after_diffuse[path] = np.where(transparent, self.after_diffuse[path],
                                                (lobe & int(BSDFFlags.DIFFUSE)) != 0)


def classify(rules: LightPathRules, mat: np.ndarray, n_g: np.ndarray, wo: np.ndarray, wi: np.ndarray,
             is_delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(kind (n,) int: DIFFUSE, GLOSSY, TRANSMISSION, TRANSPARENT or VOLUME (a medium vertex); lobe (n,) int: the
    BSDFFlags lobe bit the sample is counted as) of sampled directions ``wi`` leaving ``wo`` (3, n) at materials
    ``mat``."""
    transmit = dot(wi, n_g) * dot(wo, n_g) < 0
    straight = transmit & is_delta & rules.null[mat] & (dot(wi, wo) <= -1.0 + 1e-12)
    diffuse_r = ~transmit & ~is_delta & rules.diffuse_reflection[mat]
    diffuse_t = transmit & ~is_delta & rules.diffuse_transmission[mat]
    kind = np.where(transmit, TRANSMISSION, np.where(diffuse_r, DIFFUSE, GLOSSY))
    kind = np.where(straight, TRANSPARENT, np.where(rules.volume[mat], VOLUME, kind))
    lobe = np.where(transmit, np.where(is_delta, int(BSDFFlags.DELTA_TRANSMISSION),
                                       np.where(diffuse_t, int(BSDFFlags.DIFFUSE_TRANSMISSION),
                                                int(BSDFFlags.GLOSSY_TRANSMISSION))),
                    np.where(is_delta, int(BSDFFlags.DELTA_REFLECTION),
                             np.where(diffuse_r, int(BSDFFlags.DIFFUSE_REFLECTION), int(BSDFFlags.GLOSSY_REFLECTION))))
    # (a diffuse transmission is a transmission bounce that counts as diffuse for the caustics switches)
    return kind, np.where(straight, int(BSDFFlags.NULL), lobe)


def contribution_rgb(s0: np.ndarray, w_rgb: np.ndarray | None, ids: np.ndarray) -> np.ndarray:
    """Linear sRGB (3, m) of S0 contributions (L, m) of the batch paths ``ids``, as the film converts them
    (engine.kernels.transport.spectral_stokes_rgb_samples: Σ_λ S0(λ)·w_rgb(λ); RGB transport: as they are)."""
    if w_rgb is None:
        return s0
    return np.einsum("lm,clm->cm", s0, w_rgb[:, :, ids])


def trace_light_paths(tracer, pixel: np.ndarray, sample: np.ndarray,
                      abort: threading.Event | None = None, passes=None):
    """PathTracer.trace with Cycles' light-path rules (the same stages, in the same order, and the same
    random numbers: a path that no rule touches gets the same light as without them).  ``passes``: a
    function (state, acc) → the light passes' batch recorder (engine.render.light_passes.LightPassBatch),
    told what each stage added (then the tracer need not have any rule active)."""
    st = tracer.settings
    rules = tracer.light_paths if tracer.light_paths is not None else LightPathRules(st, tracer.materials)
    n_total = pixel.shape[0]
    state, acc = tracer._camera_paths(pixel, sample)
    lp = rules.batch(n_total)
    lpb = None if passes is None else passes(state, acc)
    for bounce in range(st.max_depth):
        if abort is not None and abort.is_set():
            return None
        if state.n == 0:
            break
        mark = lp.mark(acc, state.path)
        seen = None if lpb is None else lpb.mark(state)
        hits, hit, background = tracer._intersect(state, acc, bounce)
        tracer._emission(state, acc, hits, hit, background, bounce)
        lp.settle(acc, mark, direct=bounce <= 1)
        if lpb is not None:
            lpb.emitted(seen, hit, background)
        if bounce + 1 >= st.max_depth:
            break
        surf = tracer._surface(state, hits, lp.continuing(state.path, hit))
        if surf is None:
            break
        mat = lp.materials(tracer, surf.prim)
        mark = lp.mark(acc, state.path)
        seen = None if lpb is None else lpb.mark(state)
        nxt = tracer._scatter(state, acc, surf, bounce)
        factor = lp.settle(acc, mark, direct=bounce == 0, drop=lp.dropped_light(state.path, mat))
        lp.scattered(state.path, mat, surf.n_g, surf.wo, nxt)
        if lpb is not None:
            lpb.scattered(seen, factor, state, surf, mat, nxt)
        tracer._next_segments(state, acc, surf, nxt, bounce)
    out = tracer._finish(acc, n_total)
    if lpb is not None:
        out[1]["light_passes"] = lpb.finish()
    return out
