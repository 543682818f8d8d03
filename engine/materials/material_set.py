"""Several whole materials shaded as one batch: each point is shaded by its own member.

A scene of many materials (a glTF sample with 18 Principled variants, a car with dozens of parts) would
otherwise run one material group per material at every bounce, and next-event estimation — light
choice, light sampling, shadow rays, MIS — once per group over a few hundred paths each: per-call
overhead of small arrays, which also convoys two worker threads on the GIL.  A ``MaterialSet`` is one
shader for the integrator (engine.materials.batching makes them): the light sampling, shadow rays and
throughput updates run once over all its points, and only the members' own ``eval`` / ``pdf`` /
``sample`` run per member, on its points (``ShadingPoint.material`` (N,): each point's member slot).

Contract: per point the same arithmetic as the member alone (the values are gathered from the member's
own calls: the renders do not change, except that a member's depolarising value placed beside a
polarising member's is carried as an ABCS value with B = C = S = 0, which adds exact zeros).
Members must agree on what the integrator reads from the shader as a whole: not delta-only, the same
``radiance_scaling`` and ``transmits`` (engine.materials.batching.set_key).  A member's own shading
point (a normal map) is kept per member (``SetShadingPoint``) and its mapped normal is the set's n_s
at its points, as the integrator would see it for the member alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import (BSDF, BSDFSample, LobeColors, MuellerValue, ShadingPoint, assemble_values, depolarising_value,
                   take_value)
from .flags import BSDFFlags
from ..polarisation.frames import plane_of_incidence_axis
from ..vec3 import reflect

__all__ = ["MaterialSet", "SetShadingPoint"]

#: The attribute under which a shading point keeps its split into the set's members (MaterialSet._split).
_SPLIT = "_material_set_split"


def _members(slot: np.ndarray, count: int) -> list[tuple[int, np.ndarray]]:
    """[(member j, its points (ascending indices))] for the members present in ``slot`` (N,)."""
    order = np.argsort(slot, kind="stable")
    counts = np.bincount(slot, minlength=count)
    ends = np.cumsum(counts)
    return [(j, order[ends[j] - counts[j]:ends[j]]) for j in np.flatnonzero(counts)]


@dataclass
class SetShadingPoint(ShadingPoint):
    """The set's shading point where a member has its own (a normal map): ``n_s`` (``n_g``) at each point is
    its member's, ``parts[j]`` the member's own point over its points (None: a plain take of this one),
    ``pos`` (N,) each point's index within its member's points.  Flipped and taken along with it."""

    owner: object = None
    parts: tuple = ()
    pos: np.ndarray | None = None

    def take(self, sel, shared: dict | None = None) -> SetShadingPoint:
        base = super().take(sel, shared)
        rows = np.arange(self.n)[sel]
        parts, pos = [None] * len(self.parts), np.empty(rows.size, np.int64)
        for j, idx in _members(base.material, len(self.parts)):
            if self.parts[j] is not None:
                parts[j] = self.parts[j].take(self.pos[rows[idx]])
            pos[idx] = np.arange(idx.size)
        return SetShadingPoint(base.p, base.n_s, base.n_g, base.wo, base.lam, base.mono, base.lookup, base.material,
                               base.surface, self.owner, tuple(parts), pos)._taken_from(self, sel)

    def flipped(self, where: np.ndarray) -> SetShadingPoint:
        base = super().flipped(where)
        parts = list(self.parts)
        for j, idx in _members(self.material, len(self.parts)):
            if parts[j] is not None:
                parts[j] = parts[j].flipped(where[idx])
        return SetShadingPoint(base.p, base.n_s, base.n_g, base.wo, base.lam, base.mono, base.lookup, base.material,
                               base.surface, self.owner, tuple(parts), self.pos)


def _member_value(m: BSDF, q: ShadingPoint, wi_m: np.ndarray, f: MuellerValue, idx: np.ndarray) -> MuellerValue:
    """Member m's own value at its points: the set's lanes ``idx``, unless the set's value became a general matrix
    (a member's is), which no longer holds a member's depolarised part (``depol``) apart: then m's own eval."""
    return m.eval(q, wi_m) if f.kind == "general" else take_value(f, idx)


class MaterialSet(BSDF):
    """Members (BSDFs) shaded as one batch; point i is shaded by ``members[sp.material[i]]``."""

    name = "material_set"

    def __init__(self, members: list):
        members = list(members)
        if len(members) < 2:
            raise ValueError(f"a MaterialSet needs at least 2 members, got {len(members)}")
        if any(m.flags.is_delta_only for m in members):
            raise ValueError("MaterialSet members must not be delta-only (they have their own one-step scatter)")
        if len({(m.radiance_scaling, m.flags.transmits, m.geometric_sides) for m in members}) != 1:
            raise ValueError("MaterialSet members must agree on radiance_scaling, transmits and geometric_sides")
        self.members = members
        F = BSDFFlags
        flags = F.BATCHED
        for m in members:
            flags |= m.flags & (F.LOBES | F.POLARISING | F.RETARDING | F.WAVELENGTH_DEPENDENT)
        self.flags = flags
        if not members[0].radiance_scaling:
            self.radiance_scaling = False
        if members[0].geometric_sides:
            self.geometric_sides = True
        self.varies_over_surface = any(m.varies_over_surface for m in members)

    @property
    def scatters_nothing(self) -> bool:
        return all(m.scatters_nothing for m in self.members)

    # --- points ----------------------------------------------------------------------------------

    def shading_point(self, sp: ShadingPoint) -> ShadingPoint:
        parts, pos = [None] * len(self.members), np.empty(sp.n, np.int64)
        n_s, n_g = sp.n_s, sp.n_g
        for j, idx in _members(sp.material, len(self.members)):
            m = self.members[j]
            pos[idx] = np.arange(idx.size)
            if type(m).shading_point is BSDF.shading_point:
                continue
            sub = sp.take(idx)
            q = m.shading_point(sub)
            if q is sub:
                continue
            if n_s is sp.n_s:
                n_s, n_g = sp.n_s.copy(), sp.n_g.copy()
            n_s[:, idx], n_g[:, idx] = q.n_s, q.n_g
            parts[j] = q
        if all(q is None for q in parts):
            return sp
        return SetShadingPoint(sp.p, n_s, n_g, sp.wo, sp.lam, sp.mono, sp.lookup, sp.material, sp.surface, self,
                               tuple(parts), pos)

    def _split(self, sp: ShadingPoint) -> list[tuple[BSDF, np.ndarray, ShadingPoint]]:
        """[(member, its points' indices, its shading point there)] for the members present; kept on ``sp``
        (the integrator passes the same point to next-event estimation and sampling: the members' own points,
        and with them their WavelengthLookup memos of parameter values, are made once)."""
        kept = sp.__dict__.get(_SPLIT)
        if kept is not None and kept[0] is self:
            return kept[1]
        own = isinstance(sp, SetShadingPoint) and sp.owner is self
        out = []
        for j, idx in _members(sp.material, len(self.members)):
            q = sp.parts[j] if own else None
            out.append((self.members[j], idx, sp.take(idx) if q is None else q))
        sp.__dict__[_SPLIT] = (self, out)
        return out

    def _frames(self, sp: ShadingPoint, wi: np.ndarray):
        """Frames for the lanes of depolarising member values (as engine.materials.mix: any frame holds them)."""
        return lambda: (plane_of_incidence_axis(sp.n_s, -wi), plane_of_incidence_axis(sp.n_s, sp.wo))

    # --- BSDF interface --------------------------------------------------------------------------

    def eval(self, sp: ShadingPoint, wi: np.ndarray) -> MuellerValue:
        parts = [(idx, m.eval(q, np.take(wi, idx, axis=1))) for m, idx, q in self._split(sp)]
        return assemble_values(parts, sp.n, sp.lam.shape[0], self._frames(sp, wi))

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        out = np.zeros(sp.n)
        for m, idx, q in self._split(sp):
            out[idx] = m.pdf(q, np.take(wi, idx, axis=1))
        return out

    def eval_and_pdf(self, sp: ShadingPoint, wi: np.ndarray) -> tuple[MuellerValue, np.ndarray]:
        """(``eval``, ``pdf``) with each member asked once for both (its eval_and_pdf: one compiled pass where it has
        one, the same numbers as its two calls)."""
        cls = type(self)
        if cls.eval is not MaterialSet.eval or cls.pdf is not MaterialSet.pdf:
            return super().eval_and_pdf(sp, wi)
        parts, pdf = [], np.zeros(sp.n)
        for m, idx, q in self._split(sp):
            value, pdf[idx] = m.eval_and_pdf(q, np.take(wi, idx, axis=1))
            parts.append((idx, value))
        return assemble_values(parts, sp.n, sp.lam.shape[0], self._frames(sp, wi)), pdf

    def sample(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        n = sp.n
        wi, pdf = np.empty((3, n)), np.empty(n)
        is_delta, valid, eta_sq = np.empty(n, bool), np.empty(n, bool), np.ones(n)
        parts = []
        for m, idx, q in self._split(sp):
            bs = m.sample(q, u_lobe[idx], np.take(u_dir, idx, axis=1))
            wi[:, idx], pdf[idx], is_delta[idx], valid[idx] = bs.wi, bs.pdf, bs.is_delta, bs.valid
            if bs.eta_sq is not None:
                eta_sq[idx] = bs.eta_sq
            parts.append((idx, bs.weight))
        weight = assemble_values(parts, n, sp.lam.shape[0], self._frames(sp, wi))
        return BSDFSample(wi=wi, weight=weight, pdf=pdf, is_delta=is_delta, valid=valid, eta_sq=eta_sq)

    def refraction_eta_sq(self, sp: ShadingPoint) -> np.ndarray | None:
        out = None
        for m, idx, q in self._split(sp):
            k = m.refraction_eta_sq(q)
            if k is not None:
                out = np.ones(sp.n) if out is None else out
                out[idx] = k
        return out

    def delta_reflection(self, sp: ShadingPoint) -> MuellerValue | None:
        L, parts = sp.lam.shape[0], []
        for m, idx, q in self._split(sp):
            v = m.delta_reflection(q)
            parts.append((idx, v if v is not None else depolarising_value(np.zeros((L, idx.size)), idx.size)))
        if all(v.kind == "depolarising" and not v.A.any() for _, v in parts):
            return None
        return assemble_values(parts, sp.n, L, self._frames(sp, -reflect(sp.wo, sp.n_s)))

    def diffuse_share(self, sp: ShadingPoint, wi: np.ndarray, f: MuellerValue) -> np.ndarray | None:
        out = np.zeros(f.m00().shape)
        for m, idx, q in self._split(sp):
            wi_m = np.take(wi, idx, axis=1)
            d = m.diffuse_share(q, wi_m, _member_value(m, q, wi_m, f, idx))
            if d is None:
                return None
            out[:, idx] = d
        return out

    def member_parts(self, sp: ShadingPoint, wi: np.ndarray | None = None, f: MuellerValue | None = None) -> list:
        """[(member, indices (k,) of its points in ``sp``, its shading point, its ``wi`` (3, k), its part of ``f``)]
        of the members present (``wi``/``f`` None where not given): for callers that treat members one by one
        (the light passes name the member whose lobes they cannot separate)."""
        out = []
        for m, idx, q in self._split(sp):
            wi_m = None if wi is None else np.take(wi, idx, axis=1)
            out.append((m, idx, q, wi_m, None if f is None else _member_value(m, q, wi_m, f, idx)))
        return out

    def lobe_colors(self, sp: ShadingPoint) -> LobeColors | None:
        out = LobeColors.of(sp)
        for m, idx, q in self._split(sp):
            c = m.lobe_colors(q)
            if c is None:
                return None
            out.diffuse[:, idx], out.glossy[:, idx], out.transmission[:, idx] = c.diffuse, c.glossy, c.transmission
        return out

    def describe(self) -> dict:
        return {"type": self.name, "members": [m.describe() for m in self.members]}
