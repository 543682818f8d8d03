"""Participating media in the transport: free-flight sampling, medium vertices, shadow-ray transmittance.

Media (engine.scene.description.Interior with ``scatters`` or a density grid: *tracked*) bound by closed
meshes, as absorbing interiors, on the paths' volume stacks (engine.render.media), and the world medium
(``Scene.medium``), which counts where a path's stack is empty (fog everywhere outside the closed media).
Scenes with one are traced by :class:`ParticipatingPathTracer`, the integrator with these stages changed
(every other scene keeps the plain PathTracer: its images are unchanged):

- ``_intersect``: after the closest hit, **delta tracking** along [0, t_hit) (t_hit = ∞ on a miss) with a
  majorant per path σ̄ = Σ_k ρ̄_k·max_λ σ_k(λ) over the tracked media k on its stack (ρ̄ the density bound,
  σ_k the tracked coefficient: σ_s, plus σ_a for a grid medium, whose absorption varies in space; a
  homogeneous medium's σ_a stays exact Beer–Lambert, engine.render.media).  At each tentative collision
  the event — scattering by medium k or a null collision — is chosen with probability ∝ the mean over the
  path's wavelengths of σ_{s,k}(λ, x) and of σ_n(λ, x) = σ̄ − Σ σ(λ, x), and the path's per-λ weight τ is
  multiplied by σ_event(λ, x)/(σ̄·P_event): unbiased at every wavelength (the spectral-tracking /
  null-scattering path-integral estimator of Kutz et al. 2017 and Miller, Georgiev & Jarosz 2019, with
  the mean over λ as the event probabilities).  A grey medium under a tight majorant has no null
  collisions and weight 1 (albedo via the analytic absorption).
- A scattering collision becomes a **medium vertex**: a pseudo-triangle (index F + k past the scene's
  triangles) whose pseudo-material (:class:`PhaseVertices`, index M + k) is medium k's phase function, so
  the integrator's own scatter stage runs next-event estimation (the lights' sampling, MIS by the power
  heuristic against phase sampling) and phase sampling, with the Mueller update T ← T·R(x_out → x_T)·M/pdf
  in the scattering-plane frames (engine.media.phase), exactly as at a surface; no cosine, no offset
  (zero normals), no stack change; Russian roulette as at surfaces.
- ``_attenuation`` / ``_emission``: light reached along a segment at distance s is weighted by the
  collisions before s (0 past a scattering one); afterwards every collision's weight folds into τ.
- ``_shadow_media``: shadow rays through homogeneous media exactly, exp(−(σ_a + σ_s)·d); through grid
  media by **ratio tracking** on the same majorant: Π (1 − σ(λ, x_i)/σ̄) per wavelength.

Distances count from the segment's ray origin (the offset origin of a surface vertex; medium vertices
start at the vertex).  The tracking's random numbers are their own hashed dimensions (``TRACK_DIMENSION``
and ``RATIO_DIMENSION`` on, per bounce), so the other numbers of a path are those it would draw without
media.  docs/physics.md "Participating media".
"""

from __future__ import annotations

import numpy as np

from ..kernels.hashing import uniforms
from ..materials.base import BSDF, BSDFFlags, BSDFSample
from ..kernels.transport import add_light
from ..media.henyey_greenstein import HenyeyGreenstein
from ..spectral.cie import LUMINANCE_WEIGHTS
from .accel import surface_points
from .integrator import PathTracer, _SurfaceHits
from .light_paths import LightPathRules
from .media import Media, cross, tracked_media
from .sampler import _offsets

#: First hashed dimension of the delta-tracking numbers (two per collision), and its stride per bounce.
TRACK_DIMENSION, BOUNCE_STRIDE = 1 << 40, 1 << 24
#: First hashed dimension of the shadow rays' ratio-tracking numbers (one per collision).
RATIO_DIMENSION = 1 << 41
#: Collisions per segment at most (a path still going then is dropped: its weight 0).
MAX_COLLISIONS = 1 << 16
#: Smallest majorant (per scene unit) of a path in an emitting medium bounded by a mesh or a grid, so that a
#: medium that emits without extinction still has collisions to count its emission at
EMISSION_RATE = 1.0


class PhaseVertices(BSDF):
    """A medium's phase function as the integrator's material at its scattering vertices (no cosine:
    ``eval`` is the phase matrix per steradian, ``sample`` its exact sampling at the hero wavelength)."""

    name = "phase"
    radiance_scaling = True
    shade_alone = True      # the scatter stage tells medium vertices apart by type (never in a MaterialSet)
    #: Cycles' light paths count its samples as volume bounces (engine.render.light_paths)
    medium_vertex = True

    def __init__(self, phase):
        self.phase = phase
        self.flags = (BSDFFlags.GLOSSY_REFLECTION | BSDFFlags.GLOSSY_TRANSMISSION
                      | (phase.flags & (BSDFFlags.POLARISING | BSDFFlags.RETARDING | BSDFFlags.WAVELENGTH_DEPENDENT)))

    def eval(self, sp, wi):
        return self.phase.eval(sp.wo, wi, sp.lam)

    def pdf(self, sp, wi):
        return self.phase.pdf(sp.wo, wi, sp.lam)

    def sample(self, sp, u_lobe, u_dir) -> BSDFSample:
        s = self.phase.sample(sp.wo, u_dir, sp.lam)
        return BSDFSample(s.wi, s.weight, s.pdf, s.is_delta, s.valid)

    def describe(self) -> dict:
        return self.phase.describe()


class _SceneWithMediumVertices:
    """The compiled scene seen by the integrator's stages, with one pseudo-triangle per tracked medium
    (index F + k: material M + k, no emitter, no volume, zero normal); everything else is the scene's."""

    def __init__(self, compiled, n_media: int, n_materials: int):
        self._compiled = compiled
        F = len(compiled.tri_material)
        self.tri_material = np.concatenate((compiled.tri_material,
                                            np.arange(n_materials, n_materials + n_media, dtype=np.int32)))
        self.tri_emitter = np.concatenate((compiled.tri_emitter, np.full(n_media, -1, np.int32)))
        volume = compiled.tri_volume if compiled.tri_volume is not None else np.full(F, -1, np.int32)
        self.tri_volume = np.concatenate((volume, np.full(n_media, -1, np.int32)))
        self.tri_normal = np.concatenate((compiled.tri_normal, np.zeros((n_media, 3))))

    def __getattr__(self, name):
        return getattr(self._compiled, name)


class ScatteringMedia(Media):
    """The volume stacks' analytic Beer–Lambert part with tracked media and a world medium.

    Volume ids are the compiled scene's, plus ``world`` = len(volumes) for the world medium, which a
    stack holds where it is otherwise empty.  ``shadow``: shadow rays' coefficients (σ_a + σ_s of a
    homogeneous tracked medium), else the paths' (its σ_a; its σ_s is tracked); a grid medium adds
    nothing here (tracked entirely)."""

    def __init__(self, scene, world_medium, rgb_mode: bool, mono: bool, shadow: bool):
        super().__init__(scene, rgb_mode, mono)
        interiors = [interior for _, _, interior in scene.volumes]
        self.world = None
        if world_medium is not None:
            self.world = len(interiors)
            interiors.append(world_medium)
        self.parts = []
        for it in interiors:
            # a grid medium is tracked entirely; an emitting one too along the paths (its shadow rays: exact)
            parts = [] if it.grid is not None or (it.emits and not shadow) else [it.absorption]
            if shadow and it.grid is None and it.scattering is not None:
                parts.append(it.scattering)
            self.parts.append(parts)
        self.rgb = np.array([sum((np.asarray(s.linear_srgb(), np.float64) for s in p), np.zeros(3))
                             for p in self.parts]).reshape(-1, 3)

    def with_world(self, stack: np.ndarray) -> np.ndarray:
        """The stacks with the world medium in the empty ones (the same array where there is none)."""
        if self.world is None:
            return stack
        empty = (stack < 0).all(axis=0)
        if not empty.any():
            return stack
        out = stack.copy()
        out[0, empty] = self.world
        return out

    def sigma(self, stack: np.ndarray, lk) -> np.ndarray | None:
        return super().sigma(self.with_world(stack), lk)

    def coefficient(self, v: int, lk, cols: np.ndarray) -> np.ndarray:
        if self.rgb_mode:
            return self.rgb[v][:, None]
        out = np.zeros((lk.lam.shape[0], cols.size))
        for spec in self.parts[v]:
            out += self.spectrum_values(spec, lk, cols)
        return out


class Tracks:
    """The collisions of one bounce's delta tracking: rounds of (paths (m,), distances (m,), weights (L, m),
    scattering (m,) bool); ``scattered`` (n,), ``t`` (n,), ``medium`` (n,) and ``stack`` of the scattering ones."""

    def __init__(self, n: int, L: int, K: int):
        self.n, self.L = n, L
        self.rounds: list = []
        #: the emission met at the collisions: rounds of (paths (m,), distances (m,), ε/σ̄ (L, m))
        self.emitted: list = []
        self.scattered = np.zeros(n, bool)
        self.t = np.full(n, np.inf)
        self.medium = np.full(n, -1, np.int64)
        #: the volume stacks (K, n) where the scattering paths scattered (their stacks from then on)
        self.stack = np.full((K, n), -1, np.int32)

    def weight(self, rows: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The weight (L, m) of light reached at distance s (m,) along the paths ``rows`` (m,): the product
        of the collisions' weights before s, 0 where the path scattered before s."""
        out = np.ones((self.L, rows.size))
        pos = np.full(self.n, -1, np.int64)
        for paths, t, w, scat in self.rounds:
            pos[paths] = np.arange(paths.size)
            j = pos[rows]
            at = np.flatnonzero(j >= 0)
            before = at[t[j[at]] < s[at]]
            jb = j[before]
            out[:, before] *= np.where(scat[jb][None, :], 0.0, w[:, jb])
            pos[paths] = -1
        return out

    def total(self) -> np.ndarray:
        """Every collision's weight multiplied per path (L, n), the scattering one included."""
        out = np.ones((self.L, self.n))
        for paths, _, w, _ in self.rounds:
            out[:, paths] *= w
        return out


class Tracking:
    """Free-flight sampling and ratio tracking over the tracked media (see the module docstring)."""

    def __init__(self, media: ScatteringMedia, tracked: list, rgb_mode: bool, mono: bool):
        self.media = media
        n_volumes = len(media.parts)
        #: tracked index k of each volume id (the world's last), −1: not tracked
        self.index = np.full(n_volumes, -1, np.int64)
        self.interiors = []
        for k, (v, interior) in enumerate(tracked):
            self.index[media.world if v is None else v] = k
            self.interiors.append(interior)
        self.rgb_mode, self.mono = rgb_mode, mono
        self.bound = np.array([it.density_bound for it in self.interiors])
        self.grids = [it.grid for it in self.interiors]
        self.emits = [it.emits for it in self.interiors]
        #: an emitting medium bounded by a mesh or a grid: its collisions' rate at least EMISSION_RATE
        self.bounded_emitter = np.array([it.emits and (v is not None or it.grid is not None)
                                         for v, it in tracked], bool)

    def _values(self, spec, lk, cols: np.ndarray) -> np.ndarray:
        if spec is None:
            return np.zeros((3 if self.rgb_mode else lk.lam.shape[0], cols.size))
        if self.rgb_mode:
            return np.repeat(np.asarray(spec.linear_srgb(), np.float64)[:, None], cols.size, axis=1)
        return self.media.spectrum_values(spec, lk, cols)

    def _coefficients(self, k: int, lk, cols: np.ndarray):
        """(σ_s, the tracked σ — with a colour grid its bound —, None or (colour basis (3, L, m), σ_a)) (L, m) of
        medium k at unit density for the paths ``cols``.  A colour grid's σ_s·C + σ_a·max(1 − C, 0) ≤
        σ_s·Σ_c C̄_c·B_c + σ_a (C̄ the channels' largest node values, B_c ≥ 0), the majorant's per-λ bound."""
        it = self.interiors[k]
        s = self._values(it.scattering, lk, cols)
        if it.colour_grid is not None:
            a = self._values(it.absorption, lk, cols)
            basis = self._rgb_basis(lk, cols)
            return s, s * np.einsum("clm,c->lm", basis, it.colour_grid.max) + a, (basis, a)
        return s, (s + self._values(it.absorption, lk, cols) if it.grid is not None or it.emits else s), None

    def _rgb_basis(self, lk, cols: np.ndarray, illuminant: bool = False) -> np.ndarray:
        """The spectra (3, L, m) of unit linear sRGB channels for the paths ``cols``: reflectances (Σ_c B_c = 1), or
        with ``illuminant`` D65n-weighted (the channels of an RGBIlluminantSpectrum)."""
        if self.rgb_mode:
            return np.repeat(np.eye(3)[:, :, None], cols.size, axis=2)
        if self.mono:
            return np.repeat(np.asarray(LUMINANCE_WEIGHTS, np.float64)[:, None, None], cols.size, axis=2)
        sub = lk.take(cols) if cols.size < lk.lam.shape[1] else lk
        return sub.d65[None] * sub.basis if illuminant else sub.basis

    def _emission_basis(self, k: int, lk, cols: np.ndarray) -> np.ndarray | None:
        """Medium k's emission for the paths ``cols``: ε (1, L, m) of a homogeneous one, or the spectra (3, L, m)
        of unit linear sRGB channels that its emission grid's values weigh (None: it does not emit)."""
        it = self.interiors[k]
        if not self.emits[k]:
            return None
        if it.emission_grid is None:
            return self._values(it.emission, lk, cols)[None]
        return self._rgb_basis(lk, cols, illuminant=True)

    def _members(self, stack: np.ndarray, rows: np.ndarray, grids_only: bool = False) -> list:
        """[(k, paths (m,))] of the tracked media on the stacks (K, n) (the world's where empty) of the
        paths ``rows``."""
        eff = self.media.with_world(stack[:, rows])
        tk = np.where(eff >= 0, self.index[np.maximum(eff, 0)], -1)
        out = [(int(k), rows[(tk == k).any(axis=0)]) for k in np.unique(tk[tk >= 0])]
        return [(k, cols) for k, cols in out if not grids_only or self.grids[k] is not None]

    def _majorants(self, members: list, lk, n: int, o, d, t_end) -> tuple[np.ndarray, np.ndarray, list]:
        """(σ̄ (n,), the distance the tracking ends at (n,), [(k, paths, σ_s, σ_tracked, emission basis, colour)])
        of the paths (engine.render.participating.Tracking._coefficients)."""
        sbar = np.zeros(n)
        homogeneous = np.zeros(n, bool)
        emitter = np.zeros(n, bool)
        grid_end = np.full(n, -np.inf)
        coeffs = []
        for k, cols in members:
            s, tr, colour = self._coefficients(k, lk, cols)
            sbar[cols] += self.bound[k] * tr.max(axis=0)
            coeffs.append((k, cols, s, tr, self._emission_basis(k, lk, cols), colour))
            emitter[cols] |= self.bounded_emitter[k]
            if self.grids[k] is None:
                homogeneous[cols] = True
            else:
                _, t1 = self.grids[k].box_range(o[:, cols], d[:, cols])
                grid_end[cols] = np.maximum(grid_end[cols], t1)
        end = np.where(homogeneous, t_end, np.minimum(t_end, grid_end))
        # an emitter without extinction still needs collisions to count its emission (σ_n = σ̄ there)
        sbar = np.where(emitter & (sbar < EMISSION_RATE), np.maximum(sbar, EMISSION_RATE), sbar)
        return sbar, end, coeffs

    def _densities(self, k: int, p: np.ndarray) -> np.ndarray | float:
        return 1.0 if self.grids[k] is None else self.grids[k].density(p)

    def _at(self, coeffs: list, n: int, act: np.ndarray, x: np.ndarray, L: int) -> tuple[np.ndarray, np.ndarray]:
        """(σ_s per medium (K, L, m), the tracked σ (L, m)) at the points x (3, m) of the paths ``act``."""
        sig_s = np.zeros((len(self.interiors), L, act.size))
        sig_t = np.zeros((L, act.size))
        for k, s, tr, _, colour, on, c in self._on_paths(coeffs, n, act):
            rho = self._densities(k, x[:, on])
            if colour is None:
                sig_s[k][:, on] = s[:, c] * rho
                sig_t[:, on] += tr[:, c] * rho
                continue
            basis, a = colour                # C(λ, x) = Σ_c C_c(x)·B_c(λ): σ_s·C and σ_a·max(1 − C, 0)
            C = np.einsum("clm,cm->lm", basis[:, :, c], self.interiors[k].colour_grid.rgb(x[:, on]))
            sig_s[k][:, on] = s[:, c] * C * rho
            sig_t[:, on] += (s[:, c] * C + a[:, c] * np.maximum(1.0 - C, 0.0)) * rho
        return sig_s, sig_t

    @staticmethod
    def _on_paths(coeffs: list, n: int, act: np.ndarray):
        """Per medium of ``coeffs`` on some of the paths ``act``: (k, σ_s, tracked σ, emission basis, (colour basis,
        σ_a) of a colour grid, the places ``on`` of its paths in ``act``, their columns in its arrays)."""
        pos = np.full(n, -1, np.int64)
        for k, cols, s, tr, basis, colour in coeffs:
            pos[cols] = np.arange(cols.size)
            c = pos[act]
            on = np.flatnonzero(c >= 0)
            pos[cols] = -1
            if on.size:
                yield k, s, tr, basis, colour, on, c[on]

    def _emitted_at(self, coeffs: list, n: int, act: np.ndarray, x: np.ndarray, L: int) -> np.ndarray | None:
        """ε (L, m) summed over the emitting media at the points x (3, m) of the paths ``act`` (None: none emits)."""
        out = None
        for k, _, _, basis, _, on, c in self._on_paths(coeffs, n, act):
            if basis is None:
                continue
            out = np.zeros((L, act.size)) if out is None else out
            grid = self.interiors[k].emission_grid
            if grid is None:
                out[:, on] += basis[0][:, c]
            else:
                g = grid.rgb(x[:, on])                                      # (3, m_on) linear sRGB
                out[:, on] += np.einsum("clm,cm->lm", basis[:, :, c], g)
        return out

    def pieces(self, start: np.ndarray, d: np.ndarray, crossings: list, t_end: np.ndarray):
        """The segments cut at their pass-through crossings (``crossings``: layers of (rays, triangles,
        distances), engine.render.visibility): yields (stacks (K, n), paths (m,), from (n,), to (n,)) per
        piece, the stacks updated at each crossing as engine.render.media.Media.march updates them."""
        n = d.shape[1]
        count = np.zeros(n, np.int64)
        numbered: list = []                 # crossing c of every ray: (rays, triangles, distances)
        for rays, prims, t in crossings:
            c = count[rays]
            for cv in np.unique(c):
                at = c == cv
                while len(numbered) <= cv:
                    numbered.append([])
                numbered[cv].append((rays[at], prims[at], t[at]))
            count[rays] += 1
        stack, t_lo = start.copy(), np.zeros(n)
        for c in range(len(numbered) + 1):
            rows = np.arange(n) if c == 0 else np.flatnonzero(count >= c)
            t_hi = t_end.copy()
            if c < len(numbered):
                rays, prims, t = (np.concatenate(a) for a in zip(*numbered[c]))
                t_hi[rays] = np.minimum(t, t_end[rays])
            yield stack, rows, t_lo, t_hi
            if c < len(numbered):
                vol = self.media.tri_volume[prims]
                entering = (self.media.tri_normal[prims] * d[:, rays].T).sum(axis=1) < 0
                cross(stack, rays, vol, entering)
                t_lo = t_lo.copy()
                t_lo[rays] = t

    def free_flight(self, start, o, d, crossings, t_end, lk, keys, bounce: int) -> Tracks | None:
        """Delta tracking of the segments o + t·d, t < t_end (n,), that start with the stacks (K, n) and
        cross the pass-through surfaces ``crossings``; None where no path runs through a tracked medium."""
        n = d.shape[1]
        L = 3 if self.rgb_mode else lk.lam.shape[0]
        tracks, j = None, 0
        first = TRACK_DIMENSION + bounce * BOUNCE_STRIDE
        for stack, rows, t_lo, t_hi in self.pieces(start, d, crossings, t_end):
            if tracks is not None:
                rows = rows[~tracks.scattered[rows]]
            members = self._members(stack, rows)
            if not members:
                continue
            tracks = tracks or Tracks(n, L, start.shape[0])
            sbar, end, coeffs = self._majorants(members, lk, n, o, d, t_hi)
            act = np.flatnonzero((sbar > 0) & (end > t_lo))
            t = t_lo.copy()
            K = len(self.interiors)
            while act.size and j < MAX_COLLISIONS:
                u = uniforms(keys[act], _offsets(first + 2 * j, 2))
                j += 1
                t[act] -= np.log1p(-u[0]) / sbar[act]
                go = t[act] < end[act]
                act, u = act[go], u[:, go]
                if act.size == 0:
                    break
                x = o[:, act] + t[act] * d[:, act]
                sig_s, sig_t = self._at(coeffs, n, act, x, L)
                eps = self._emitted_at(coeffs, n, act, x, L)
                if eps is not None:         # every tentative collision counts ε/σ̄ (the null-scattering estimator)
                    tracks.emitted.append((act, t[act].copy(), eps / sbar[act]))
                sig_n = np.maximum(sbar[act] - sig_t, 0.0)
                c = np.concatenate((sig_s.mean(axis=1), sig_n.mean(axis=0)[None]))        # (K + 1, m)
                total = c.sum(axis=0)
                event = np.minimum((u[1] * total >= np.cumsum(c, axis=0)).sum(axis=0), K)
                chosen = np.take_along_axis(c, event[None], axis=0)[0]
                sig = np.where(event[None] < K, sig_s[np.minimum(event, K - 1), :, np.arange(act.size)].T, sig_n)
                ok = chosen > 0
                w = np.where(ok[None], sig * (total / np.where(ok, chosen * sbar[act], 1.0))[None], 0.0)
                scat = (event < K) & ok
                tracks.rounds.append((act, t[act].copy(), w, scat))
                tracks.scattered[act[scat]] = True
                tracks.t[act[scat]] = t[act[scat]]
                tracks.medium[act[scat]] = event[scat]
                tracks.stack[:, act[scat]] = stack[:, act[scat]]
                act = act[~scat & ok]
            if act.size:            # still going after MAX_COLLISIONS: dropped
                tracks.rounds.append((act, t[act].copy(), np.zeros((L, act.size)), np.zeros(act.size, bool)))
        return tracks

    def ratio_tracking(self, start, p, wi, crossings, dist, lk, keys, bounce: int) -> np.ndarray | None:
        """Transmittance (L, n) of the grid media along the shadow rays p + t·wi, t < dist (n,), that start
        with the stacks (K, n) and cross ``crossings``: Π (1 − σ(λ, x_i)/σ̄) over the collisions x_i on the
        majorant σ̄ (None: no grid medium on the way)."""
        n = wi.shape[1]
        L = 3 if self.rgb_mode else lk.lam.shape[0]
        out, j = None, 0
        first = RATIO_DIMENSION + bounce * BOUNCE_STRIDE
        for stack, rows, t_lo, t_hi in self.pieces(start, wi, crossings, dist):
            members = self._members(stack, rows, grids_only=True)
            if not members:
                continue
            out = np.ones((L, n)) if out is None else out
            sbar, end, coeffs = self._majorants(members, lk, n, p, wi, t_hi)
            act = np.flatnonzero((sbar > 0) & (end > t_lo))
            t = t_lo.copy()
            while act.size and j < MAX_COLLISIONS:
                t[act] -= np.log1p(-uniforms(keys[act], _offsets(first + j, 1))[0]) / sbar[act]
                j += 1
                act = act[t[act] < end[act]]
                if act.size == 0:
                    break
                _, sig_t = self._at(coeffs, n, act, p[:, act] + t[act] * wi[:, act], L)
                out[:, act] *= np.maximum(1.0 - sig_t / sbar[act], 0.0)
                act = act[out[:, act].max(axis=0) > 0]
            out[:, act] = 0.0
        return out


class ParticipatingPathTracer(PathTracer):
    """The path tracer of scenes with tracked media (see the module docstring)."""

    def __init__(self, compiled, lights, camera, settings, materials=None, count_cost: bool = True, world=None):
        super().__init__(compiled, lights, camera, settings, materials, count_cost)
        tracked = tracked_media(compiled, world)
        M, F = len(self.materials), len(compiled.tri_material)
        self.first_medium_prim = F
        phases = [PhaseVertices(it.phase if it.phase is not None else HenyeyGreenstein(0.0)) for _, it in tracked]
        self.materials += phases
        self.scene = _SceneWithMediumVertices(compiled, len(tracked), M)
        self.two_sided = np.concatenate((self.two_sided, np.zeros(len(tracked), bool)))
        self._material_tables(np.concatenate((compiled.used_materials, np.arange(M, M + len(tracked)))))
        self.media = ScatteringMedia(self.scene, world, self.rgb_mode, self.mono, shadow=False)
        self.extinction = ScatteringMedia(self.scene, world, self.rgb_mode, self.mono, shadow=True)
        self.tracking = Tracking(self.extinction, tracked, self.rgb_mode, self.mono)
        # Cycles' light paths: a medium vertex is a volume bounce; its limit (which RenderSettings.light_paths_active
        # leaves out: it changes only scenes with scattering media) turns the bookkeeping on here
        if self.light_paths is not None or settings.max_volume_bounces < settings.max_depth - 2:
            self.light_paths = LightPathRules(settings, self.materials)

    # ------------------------------------------------------------------ segments

    def _intersect(self, state, acc, bounce):
        state.bounce = bounce
        hits, hit, background = super()._intersect(state, acc, bounce)
        # camera rays that reached a transparent film's background (each added 1 to the transparency)
        state.see_through = (np.flatnonzero(hits.prim < 0) if bounce == 0 and self.film_transparent
                             and acc.transparency is not None else None)
        t_end = np.where(hit, hits.t, np.inf if state.t_max is None else state.t_max)
        tracks = self.tracking.free_flight(state.media, state.o, state.d, state.crossings or [], t_end, state.lk,
                                           state.sampler.keys, bounce)
        state.tracks = tracks
        if tracks is None:
            return hits, hit, background
        med = tracks.scattered
        if med.any():
            hits.prim = np.where(med, self.first_medium_prim + tracks.medium, hits.prim)
            hits.t = np.where(med, tracks.t, hits.t)
            hit = hit | med
            background = background & ~med
        if state.tau is None:
            state.tau = np.ones((tracks.L, state.n))
        return hits, hit, background

    def _attenuation(self, state, segment):
        att = PathTracer._attenuation(state, segment)
        tracks = getattr(state, "tracks", None)
        if tracks is None:
            return att

        def tracked(rows, s):
            f = att(rows, s)
            w = tracks.weight(rows, s)
            return w if f is None else f * w
        state.tracked_att = tracked
        return tracked

    def _emission(self, state, acc, hits, hit, background, bounce):
        super()._emission(state, acc, hits, hit, background, bounce)
        tracks = getattr(state, "tracks", None)
        if tracks is not None:
            att = getattr(state, "tracked_att", None)
            state.tracked_att = None
            self._volume_emission(state, acc, tracks, att)
            if getattr(state, "see_through", None) is not None:
                self._film_transparency(state, acc, tracks, att)
            state.tau = state.tau * tracks.total()
            if tracks.scattered.any():      # the stacks where they scattered, not at their segments' ends
                state.media[:, tracks.scattered] = tracks.stack[:, tracks.scattered]
            state.tracks = None

    def _volume_emission(self, state, acc, tracks, att) -> None:
        """The media's emission met along the segments: ε(x)/σ̄ at each collision x, weighted by the collisions
        before it and the analytic absorption up to it (``att``; unpolarised: the throughput's first column)."""
        for rows, t, e in tracks.emitted:
            f = att(rows, t) if att is not None else tracks.weight(rows, t)
            Le = e if f is None else e * f
            add_light(acc.radiance, state.path, state.T_store, rows, Le, np.ones(rows.size), state.T_columns(rows))

    @staticmethod
    def _film_transparency(state, acc, tracks, att) -> None:
        """A transparent film's camera rays that missed every surface: their transparency is the mean over the
        wavelengths of their throughput at the background (Cycles' film_write_transparent: average(throughput)),
        0 where they scattered in a medium (their light is the medium's), not the 1 the surface pass gave."""
        rows = state.see_through
        state.see_through = None
        if rows.size == 0:
            return
        inf = np.full(rows.size, np.inf)
        f = att(rows, inf) if att is not None else tracks.weight(rows, inf)
        left = 1.0 if f is None else f.mean(axis=0)
        acc.transparency[state.path[rows]] += left - 1.0

    def _surface(self, state, hits, hit):
        F = self.first_medium_prim
        med = hits.prim >= F
        p_med = np.zeros((3, state.n))
        if med.any():
            p_med[:, med] = state.o[:, med] + hits.t[med] * state.d[:, med]
        state.o = state.t_max = state.prev_delta = state.prev_pdf = state.p_prev = state.n_prev = None
        prim, u, v, p_med = state.compress(hit, hits.prim, hits.u, hits.v, p_med)
        if state.n == 0:
            return None
        real = prim < F
        p, n_g, n_s = p_med, np.zeros((3, state.n)), np.zeros((3, state.n))
        if real.any():
            at = np.flatnonzero(real)
            p[:, at], n_g[:, at], n_s[:, at] = self.scene.surface(prim[at], u[at], v[at])
        attrs = surface_points(self.scene._compiled, np.where(real, prim, 0), u, v) if self.textured else None
        return _SurfaceHits(prim=prim, p=p, n_g=n_g, n_s=n_s, wo=-state.d, at=attrs)

    # ------------------------------------------------------------------ next-event estimation

    def _light_weight(self, sp, bsdf, x_T, ls):
        if not isinstance(bsdf, PhaseVertices):
            return super()._light_weight(sp, bsdf, x_T, ls)
        if not ls.ok.any():
            return None
        S = self._bsdf_response(sp, bsdf, x_T, ls.wi, ls.polarised)
        mis = self._light_mis(sp, bsdf, ls)
        return S, ls.emitted * ls.scale[None, :] * (mis / ls.select_prob * ls.ok)[None, :]

    def _shadow_media(self, medium, wi, dist, lookup, crossings):
        stack = self._shadow_stack(medium, wi)
        start = stack.copy()
        tau, p, keys, bounce = medium[1], medium[5], medium[6], medium[7]
        n = stack.shape[1]
        segment = self.extinction.march(stack, wi, crossings, lookup)
        f = segment.transmittance(np.arange(n), dist) if segment.absorbs else None
        g = self.tracking.ratio_tracking(start, p, wi, crossings, dist, lookup, keys, bounce)
        if g is not None:
            f = g if f is None else f * g
        if tau is not None:
            f = tau if f is None else f * tau
        return f
