"""Absorbing interiors: per-path medium stacks and Beer–Lambert attenuation along segments.

A mesh face whose material has an interior (engine.scene.description.Interior) bounds a closed
volume of absorption σ_a(λ) per scene unit.  Each path carries a stack of the volumes it is inside
(``PathState.media`` (MAX_MEDIA, n) int32, volume ids of engine.render.accel.CompiledScene.volumes,
bottom first, −1 = empty), as Cycles' volume stack (kernel/integrator/volume_stack.h):

- a path that crosses a volume's face from the front of its geometric normal to the back (a
  refraction, a thin transmission, a pass-through surface) enters that volume — pushed unless it is
  already on the stack (or the stack is full: ignored); crossing from back to front leaves it —
  removed wherever it is (if absent: nothing);
- reflections do not change the stack;
- along a segment the coefficients of every volume on the stack add up (Cycles evaluates every
  stack entry and sums their extinction: volume_shader_eval), so overlapping volumes are additive
  and a nested volume adds its σ to the one around it;
- a camera ray starts with the volumes whose inside holds its origin, found as Cycles'
  integrator_volume_stack_init does: a ray from the origin along +Z, adding each volume whose back
  face it meets before any front face of it;
- a segment that leaves the scene while inside an absorbing volume reaches nothing (exp(−σ·∞) = 0).

The attenuation is a scalar per wavelength (an isotropic absorber's Mueller matrix is
exp(−σ_a d)·identity): the integrator keeps it apart from the Mueller product T, as ``PathState.tau``
(L, n) per wavelength of the path (per RGB channel in RGB mode, where σ_a is the interior's linear
sRGB triple, as Cycles), and multiplies it into the light the path picks up.
"""

from __future__ import annotations

import numpy as np

from ..materials.flags import BSDFFlags
from ..spectral.spectrum import RGBReflectanceSpectrum, RGBUnboundedSpectrum
from .accel import offset_origin

#: Volumes a path can be inside at once (deeper nesting is ignored when entered, as Cycles' stack limit).
MAX_MEDIA = 8
#: Surfaces the camera's +Z stack-initialisation ray crosses at most.
MAX_INIT_CROSSINGS = 64


def enter(stack: np.ndarray, cols: np.ndarray, vol: np.ndarray) -> None:
    """Push the volumes ``vol`` (m,) onto the stacks ``cols`` (m,) distinct columns of ``stack``
    (K, n), in place, unless already there or full."""
    S = stack[:, cols]
    present = (S == vol[None, :]).any(axis=0)
    empty = S < 0
    slot = empty.argmax(axis=0)
    ok = ~present & empty.any(axis=0)
    if ok.any():
        at = np.flatnonzero(ok)
        S[slot[at], at] = vol[at]
        stack[:, cols] = S


def leave(stack: np.ndarray, cols: np.ndarray, vol: np.ndarray) -> None:
    """Remove the volumes ``vol`` (m,) from the stacks ``cols`` (m,) distinct columns, in place
    (the entries above move down one slot); absent ones change nothing."""
    S = stack[:, cols]
    match = S == vol[None, :]
    has = match.any(axis=0)
    if not has.any():
        return
    K = S.shape[0]
    j = match.argmax(axis=0)
    top = (S >= 0).sum(axis=0) - 1
    if np.all(~has | (j == top)):           # the usual case: the volume left is the last one entered
        at = np.flatnonzero(has)
        stack[j[at], cols[at]] = -1
        return
    src = np.arange(K)[:, None] + (np.arange(K)[:, None] >= j[None, :])
    shifted = np.where(src < K, np.take_along_axis(S, np.minimum(src, K - 1), axis=0), -1)
    stack[:, cols] = np.where(has[None, :], shifted, S)


def cross(stack: np.ndarray, cols: np.ndarray, vol: np.ndarray, entering: np.ndarray) -> None:
    """Enter (``entering``) or leave the volumes ``vol`` at the stacks ``cols`` (in place); vol < 0: no volume."""
    has = vol >= 0
    e, x = has & entering, has & ~entering
    if e.any():
        enter(stack, cols[e], vol[e])
    if x.any():
        leave(stack, cols[x], vol[x])


def _times(sigma: np.ndarray, length: np.ndarray) -> np.ndarray:
    """σ·length (L, m) with 0 where σ = 0, also for an infinite length (σ ≥ 0, length ≥ 0)."""
    if np.isfinite(length).all():
        return sigma * length[None, :]
    positive = sigma > 0
    return np.where(positive, sigma, 0.0) * np.where(positive, length[None, :], 0.0)


class Media:
    """The compiled scene's absorbing volumes as the integrator reads them (see the module docstring)."""

    def __init__(self, compiled, rgb_mode: bool, mono: bool):
        self.scene = compiled
        self.tri_volume = compiled.tri_volume
        self.tri_normal = compiled.tri_normal
        self.spectra = [interior.absorption for _, _, interior in compiled.volumes]
        self.rgb = np.array([np.asarray(s.linear_srgb(), np.float64) for s in self.spectra]).reshape(-1, 3)
        self.rgb_mode, self.mono = rgb_mode, mono

    # ------------------------------------------------------------------ coefficients

    def sigma(self, stack: np.ndarray, lk) -> np.ndarray | None:
        """σ_a (L, m) summed over each stack's volumes (L = 3 in RGB mode, else the paths' wavelengths
        of ``lk``), or None where every stack is empty."""
        occupied = stack >= 0
        if not occupied.any():
            return None
        m = stack.shape[1]
        L = 3 if self.rgb_mode else lk.lam.shape[0]
        out = np.zeros((L, m))
        for v in np.unique(stack[occupied]):
            cols = np.flatnonzero((stack == v).any(axis=0))
            out[:, cols] += self.coefficient(int(v), lk, cols)
        return out

    def coefficient(self, v: int, lk, cols: np.ndarray) -> np.ndarray:
        """σ_a of volume ``v`` (L, m) (RGB: (3, 1)) for the paths ``cols`` of the lookup ``lk``."""
        if self.rgb_mode:
            return self.rgb[v][:, None]
        return self.spectrum_values(self.spectra[v], lk, cols)

    def spectrum_values(self, spec, lk, cols: np.ndarray) -> np.ndarray:
        """A per-length coefficient's values (L, m) at the wavelengths of the paths ``cols`` of ``lk``."""
        sub = lk.take(cols) if cols.size < lk.lam.shape[1] else lk
        return spec.eval(sub.lam, mono=True) if self.mono else spec.eval_cached(sub)

    def crossing_sides(self, prim: np.ndarray, w_before: np.ndarray, w_after: np.ndarray,
                       n_g: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(volume (m,), entering (m,)) at a vertex on triangles ``prim`` for a path arriving from the side
        of ``w_before`` (the direction to the previous vertex) and leaving along ``w_after``: volume −1
        where the triangle bounds none or the path stays on one side of its geometric normal."""
        vol = self.tri_volume[prim]
        if n_g is None:
            n_g = self.tri_normal[prim].T
        before = (n_g * w_before).sum(axis=0) > 0
        after = (n_g * w_after).sum(axis=0) > 0
        vol = np.where(before != after, vol, -1)
        return vol, before & ~after

    # ------------------------------------------------------------------ camera rays

    def camera_stacks(self, o: np.ndarray) -> np.ndarray:
        """The stacks (MAX_MEDIA, n) of camera rays starting at ``o`` (3, n): Cycles' +Z ray test."""
        n = o.shape[1]
        if n and np.all(o == o[:, :1]):         # one origin (a pinhole camera): one ray for all
            return np.repeat(self._stacks_at(o[:, :1]), n, axis=1)
        return self._stacks_at(o)

    def _stacks_at(self, o: np.ndarray) -> np.ndarray:
        m = o.shape[1]
        stack = np.full((MAX_MEDIA, m), -1, np.int32)
        entered = np.full((MAX_INIT_CROSSINGS, m), -1, np.int32)     # volumes whose front face came first
        d_all = np.zeros((3, m))
        d_all[2] = 1.0
        active, origin = np.arange(m), o
        for _ in range(MAX_INIT_CROSSINGS):
            h = self.scene.intersect(origin, d_all[:, active], None)
            hit = h.prim >= 0
            if not hit.any():
                break
            active, prim, u, v = active[hit], h.prim[hit], h.u[hit], h.v[hit]
            vol = self.tri_volume[prim]
            back = self.tri_normal[prim, 2] > 0         # d = +Z leaves through a back face
            front_hit = (vol >= 0) & ~back
            if front_hit.any():
                enter(entered, active[front_hit], vol[front_hit])
            inside = (vol >= 0) & back
            if inside.any():
                cols, vols = active[inside], vol[inside]
                before = (entered[:, cols] == vols[None, :]).any(axis=0)
                if (~before).any():
                    enter(stack, cols[~before], vols[~before])
            p, n_g, _ = self.scene.surface(prim, u, v)
            origin = offset_origin(p, n_g, d_all[:, active])
        return stack

    # ------------------------------------------------------------------ along segments

    def march(self, stack: np.ndarray, d: np.ndarray, crossings: list, lk,
              gap: np.ndarray | None = None) -> SegmentMedia:
        """The coefficients along segments that start with the stacks ``stack`` (K, n) (updated in
        place to the stacks at the segments' ends) in directions ``d`` (3, n) and cross the pass-through
        surfaces ``crossings`` (layers of (rays, triangles, distances), as recorded by
        engine.render.visibility).  ``gap`` (n,) or None: how far along d each ray's origin lies from
        the vertex the segment starts at (the offset origin of engine.render.accel.offset_origin), added
        to the distances measured from the origins."""
        sigma0 = self.sigma(stack, lk)
        layers = []
        n = stack.shape[1]
        for rays, prims, t in crossings:
            vol = self.tri_volume[prims]
            has = vol >= 0
            if not has.any():
                continue
            rays, prims, t, vol = rays[has], prims[has], t[has], vol[has]
            entering = (self.tri_normal[prims] * d[:, rays].T).sum(axis=1) < 0
            cross(stack, rays, vol, entering)
            t_full = np.full(n, np.inf)
            t_full[rays] = t if gap is None else t + gap[rays]
            sig = self.sigma(stack[:, rays], lk.take(rays))
            L = 3 if self.rgb_mode else lk.lam.shape[0]
            sig_full = np.zeros((L, n))
            if sig is not None:
                sig_full[:, rays] = sig
            layers.append((t_full, sig_full))
        return SegmentMedia(sigma0, layers, gap)


class SegmentMedia:
    """σ_a along the live paths' current segments: ``sigma0`` (L, n) from their start vertices (None:
    0 everywhere) and ``layers`` of pass-through crossings, each (distance from the start vertex (n,),
    inf where a path has no crossing in that layer; σ after it (L, n)); ``gap`` (n,) or None: the
    distance from each start vertex to its ray's origin, added to distances measured from the origins."""

    def __init__(self, sigma0: np.ndarray | None, layers: list, gap: np.ndarray | None = None):
        self.sigma0, self.layers, self.gap = sigma0, layers, gap

    @property
    def absorbs(self) -> bool:
        """Some segment runs through an absorbing volume."""
        return self.sigma0 is not None or bool(self.layers)

    def optical_depth(self, rows: np.ndarray, s: np.ndarray) -> np.ndarray:
        """∫σ_a (L, m) of the segments ``rows`` (m,) int64 from their start vertices to distance s (m,)
        from their ray origins (may be inf)."""
        if self.gap is not None:
            s = s + self.gap[rows]
        L = self.sigma0.shape[0] if self.sigma0 is not None else self.layers[0][1].shape[0]
        cur = self.sigma0[:, rows] if self.sigma0 is not None else np.zeros((L, rows.size))
        if not self.layers:
            return _times(cur, s)
        depth = np.zeros((L, rows.size))
        t_prev = np.zeros(rows.size)
        for t_full, sig_full in self.layers:
            tk = t_full[rows]
            c = np.flatnonzero(tk < s)
            if c.size:
                depth[:, c] += _times(cur[:, c], tk[c] - t_prev[c])
                t_prev[c] = tk[c]
                cur[:, c] = sig_full[:, rows[c]]
        return depth + _times(cur, np.maximum(s - t_prev, 0.0))

    def transmittance(self, rows: np.ndarray, s: np.ndarray) -> np.ndarray:
        """exp(−∫σ_a) (L, m) of the segments ``rows`` up to distance s from their ray origins."""
        return np.exp(-self.optical_depth(rows, s))


def tracked_media(compiled, world) -> list:
    """[(volume id, or None for the world medium ``world``, Interior)] of the media a compiled scene renders by
    delta tracking (engine.render.participating): those that scatter or have a density grid."""
    out = [(v, interior) for v, (_, _, interior) in enumerate(compiled.volumes) if interior.tracked]
    if world is not None and world.tracked:
        out.append((None, world))
    return out


def media_flags(compiled, world) -> BSDFFlags:
    """The capabilities (POLARISING, RETARDING, WAVELENGTH_DEPENDENT) of the media: the tracked media's phase
    functions, and WAVELENGTH_DEPENDENT where a medium's coefficient needs wavelengths (``spectral_media``)."""
    flags = BSDFFlags.NONE
    for _, interior in tracked_media(compiled, world):
        if interior.phase is not None:
            flags |= interior.phase.flags
    if spectral_media(compiled, world):
        flags |= BSDFFlags.WAVELENGTH_DEPENDENT
    return flags


def defined_by_rgb(spectrum) -> bool:
    """A coefficient that RGB transport uses exactly as given: None, constant (grey) or an RGB triple (Cycles'
    colour arithmetic, per channel); a spectral table (TabulatedSpectrum) is not."""
    return (spectrum is None or getattr(spectrum, "is_constant", False)
            or isinstance(spectrum, (RGBReflectanceSpectrum, RGBUnboundedSpectrum)))


def spectral_media(compiled, world) -> list[str]:
    """The names of the media that need wavelengths (the compiled scene's volumes by material name, "world
    medium"): a coefficient σ_a or σ_s that is not ``defined_by_rgb``, or a tracked medium's phase function that
    depends on λ (Lorenz–Mie tables).  Grey and RGB media with Henyey–Greenstein or Rayleigh phases need none."""
    items = [(compiled.material_names[k], interior) for _, k, interior in compiled.volumes]
    items.append(("world medium", world))
    names = [name for name, it in items if it is not None
             and (not (defined_by_rgb(it.absorption) and defined_by_rgb(it.scattering))
                  or (it.tracked and it.phase is not None and it.phase.flags.wavelength_dependent))]
    return list(dict.fromkeys(names))
