"""The interface every material model implements (like Mitsuba 3's BSDF / pbrt-v4's BxDF).

Directions (docs/physics.md §0): ``wi`` points from the surface towards the light,
``wo`` towards the viewer (the previous path vertex).  A Mueller value always
describes the *physical* light flow: light travelling along k_i = −wi is
scattered into k_o = wo, and the matrix maps Stokes vectors given in the frame
``x_in`` (⟂ k_i) to Stokes vectors in the frame ``x_out`` (⟂ k_o), with
y = k × x as everywhere.

Batches: vectors are (3, N), per-wavelength values are (L, N) where L is the
number of wavelengths carried by each path (4, or 1 in monochrome mode).

Every model provides
- ``eval(sp, wi)``   – the non-delta Mueller BRDF/BTDF f (1/sr, *no* cosine),
- ``pdf(sp, wi)``    – the solid-angle density with which ``sample`` picks wi
                       for the non-delta lobes,
- ``sample(sp, u_lobe, u_dir)`` – a direction wi with weight f·|cosθ_i|/pdf
                       (for Dirac lobes: the lobe's Mueller weight), and
- ``delta_reflection(sp)`` – the Mueller weight of a mirror (Dirac) reflection
                       lobe into the mirror direction of wo, or None,
- ``scatter_delta(v)`` – optional, for delta-only models: ``sample`` and the path
                       tracer's throughput update T ← T·R(x_out → x_T)·M in one
                       compiled step over the vertices ``v`` (DeltaVertices), writing
                       the new T, direction, frame, validity and η² in place; returns
                       False (the default) where it does not apply, and the path
                       tracer then calls ``sample`` and updates T itself.  Adding a
                       family to the fast path is this one method, with the same
                       numbers as its ``sample`` (pdf 0, is_delta True),
- ``flags``          – its lobes and capabilities (engine.materials.flags.BSDFFlags).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .flags import UNKNOWN_MODEL_FLAGS, BSDFFlags
from ..polarisation.mueller import abcs_matrix, depolariser
from ..textures import TexturedNumber, TexturedSpectrum

if TYPE_CHECKING:
    from ..spectral import Spectrum, WavelengthLookup
    from ..textures import SurfacePoints

__all__ = ["BSDF", "BSDFFlags", "BSDFSample", "DeltaVertices", "LobeColors", "MuellerValue", "PER_POINT_MEMOS",
           "ScaledValue", "ShadingPoint", "assemble_values", "depolarising_value", "take_lanes", "take_value"]


#: ShadingPoint.memo keys whose values are per point (arrays with the points along their last axis), which a batch
#: made by ``take`` reads from the batch it was taken from instead of computing them again: a mix's sampled points
#: after next-event estimation at the same vertices (Torrance–Sparrow's complex index and multiscatter term: the
#: same per-point arithmetic, so the same values)
PER_POINT_MEMOS = frozenset({"relative_eta", "multiscatter_extra"})


@dataclass
class ShadingPoint:
    """A batch of surface hits as seen by a material (all world space)."""

    p: np.ndarray          # (3, N) position
    n_s: np.ndarray        # (3, N) unit shading normal, front side
    n_g: np.ndarray        # (3, N) unit geometric normal, same side as n_s
    wo: np.ndarray         # (3, N) unit direction towards the viewer
    lam: np.ndarray        # (L, N) wavelengths in nm
    mono: bool = False     # monochrome mode: spectra return their mono value
    lookup: WavelengthLookup | None = None  # table values at ``lam``, computed once
    material: np.ndarray | None = None  # (N,) slot of each point in a batched material set (see batching.py)
    #: the hits' triangles and barycentrics: per-vertex attributes (UV, colours) for textured
    #: parameters (engine.textures); None where no material of the scene varies over its surface
    surface: SurfacePoints | None = None

    @property
    def n(self) -> int:
        return self.wo.shape[1]

    @property
    def cos_o(self) -> np.ndarray:
        """n_s·ω_o (N,) (computed once per batch: ``memo``)."""
        return self.memo(None, "cos_o", lambda: self.n_s[0] * self.wo[0] + self.n_s[1] * self.wo[1]
                         + self.n_s[2] * self.wo[2])

    def memo(self, owner, key, compute):
        """``compute()`` once per batch for ``owner`` (a material, or None) and ``key`` (hashable: a string or a
        tuple): a value that is a function of these points alone (cosθ_o, a mixture's weights, a model's index …),
        kept on this object; ``take`` and ``flipped`` make new batches, without it.  The value is shared: callers
        must not write into it."""
        memo = self.__dict__.get("_memo")
        if memo is None:
            memo = self.__dict__["_memo"] = {}
        hit = memo.get((id(owner), key))
        if hit is not None and hit[0] is owner:
            return hit[1]
        value = self._inherited(owner, key) if key in PER_POINT_MEMOS else None
        if value is None:
            value = compute()
        memo[(id(owner), key)] = (owner, value)
        return value

    def _inherited(self, owner, key):
        """The memo of ``key`` (one of PER_POINT_MEMOS) at these points from the batch this one was taken from (or
        its parent …), or None."""
        link = self.__dict__.get("_parent_sel")
        if link is None:
            return None
        parent, sel = link
        hit = parent.__dict__.get("_memo", {}).get((id(owner), key))
        value = hit[1] if hit is not None and hit[0] is owner else parent._inherited(owner, key)
        if not isinstance(value, np.ndarray) or value.ndim == 0 or value.shape[-1] != parent.n:
            return None
        return take_lanes(value, sel)

    def _taken_from(self, parent: ShadingPoint, sel) -> ShadingPoint:
        """This batch, noted as ``parent``'s points ``sel`` (``take``: its per-point memos are read from there)."""
        self.__dict__["_parent_sel"] = (parent, sel)
        return self

    def spectrum(self, spec: Spectrum) -> np.ndarray:
        """A material parameter (engine.spectral Spectrum) at this batch's wavelengths, (L, N);
        a textured one (engine.textures.TexturedSpectrum) at this batch's surface points."""
        if isinstance(spec, TexturedSpectrum):
            return spec.at(self.surface_points(), self.lam, self.mono,
                           self.lookup.basis if self.lookup is not None and not self.mono else None)
        if self.lookup is not None and not self.mono:
            return spec.eval_cached(self.lookup)
        return spec.eval(self.lam, mono=self.mono)

    def number(self, value: float | TexturedNumber) -> float | np.ndarray:
        """A number parameter: itself if constant (the fast path), else its values (N,) at the points."""
        if isinstance(value, TexturedNumber):
            return value.at(self.surface_points())
        return value

    def surface_points(self) -> SurfacePoints:
        """The hits' per-vertex attributes (ValueError if the caller gave none)."""
        if self.surface is None:
            raise ValueError("a textured material parameter needs the surface points of the hits "
                             "(ShadingPoint.surface)")
        return self.surface

    def take(self, sel, shared: dict | None = None) -> ShadingPoint:
        """The points ``sel`` (integer indices) of this batch.  ``shared``: one dict passed to the takes of several
        batches at the same ``sel`` (a mixture's components' points), so that what they share — arrays, wavelength
        lookup, surface points — is gathered once and shared by the subsets (with the memos of the surface points)."""
        def sub(v):
            return v.take(sel)
        return ShadingPoint(take_lanes(self.p, sel, shared), take_lanes(self.n_s, sel, shared),
                            take_lanes(self.n_g, sel, shared), take_lanes(self.wo, sel, shared),
                            take_lanes(self.lam, sel, shared), self.mono,
                            None if self.lookup is None else _shared(self.lookup, sub, shared),
                            None if self.material is None else take_lanes(self.material, sel, shared),
                            None if self.surface is None else _shared(self.surface, sub, shared))._taken_from(self, sel)

    def flipped(self, where: np.ndarray) -> ShadingPoint:
        """This batch with n_s and n_g negated at the points ``where`` (N,) bool: the back faces of a
        two-sided material (BSDF.two_sided), shaded as if they were the front."""
        sign = np.where(where, -1.0, 1.0)[None, :]
        return ShadingPoint(self.p, self.n_s * sign, self.n_g * sign, self.wo, self.lam, self.mono, self.lookup,
                            self.material, self.surface)


def take_lanes(a: np.ndarray, sel, shared: dict | None = None) -> np.ndarray:
    """``a``'s lanes (last axis) ``sel`` (integer indices, a mask or a slice); with ``shared`` (ShadingPoint.take) an
    array gathered before for the same ``sel`` is returned again."""
    def gather():           # np.take: ~4× faster than fancy indexing of (3, N) columns, the same values
        return np.take(a, sel, axis=-1) if isinstance(sel, np.ndarray) and sel.dtype != np.bool_ else a[..., sel]
    return gather() if shared is None else _shared(a, lambda _: gather(), shared)


def _shared(obj, take, shared: dict | None):
    """``take(obj)``, or what it gave before for the same object in ``shared`` (kept with it: ids stay unique)."""
    if shared is None:
        return take(obj)
    hit = shared.get(id(obj))
    if hit is not None and hit[0] is obj:
        return hit[1]
    value = take(obj)
    shared[id(obj)] = (obj, value)
    return value


@dataclass
class MuellerValue:
    """A batch of Mueller matrices with the frames they are expressed in.

    ``kind`` is one of
    - ``"depolarising"``: only ``A`` (= M00) is set; frame-independent.
    - ``"abcs"``: the block form [[A,B,0,0],[B,A,0,0],[0,0,C,S],[0,0,−S,C]]
      (Fresnel reflection, diattenuators, single-facet models), plus an optional
      depolarising part ``depol``·diag(1, 0, 0, 0) (a Lambertian term added to a
      polarising lobe: it adds to M00 only, not to M11).
    - ``"general"``: a full matrix ``M`` (4, 4, L, N).
    Arrays A, B, C, S are (L, N).  ``x_in``/``x_out`` are (3, N).
    """

    kind: str
    x_in: np.ndarray
    x_out: np.ndarray
    A: np.ndarray | None = None
    B: np.ndarray | None = None
    C: np.ndarray | None = None
    S: np.ndarray | None = None
    M: np.ndarray | None = None
    depol: np.ndarray | None = None

    def matrix(self) -> np.ndarray:
        """The full (4, 4, L, N) matrix."""
        if self.kind == "general":
            return self.M
        if self.kind == "depolarising":
            return depolariser(self.A)
        M = abcs_matrix(self.A, self.B, self.C, self.S)
        if self.depol is not None:
            M[0, 0] = M[0, 0] + self.depol
        return M

    def scaled(self, factor: np.ndarray | float) -> MuellerValue:
        """This value times a scalar factor broadcastable to (L, N)."""
        if self.kind == "general":
            return MuellerValue("general", self.x_in, self.x_out, M=self.M * factor)
        sc = lambda v: None if v is None else v * factor  # noqa: E731
        return MuellerValue(self.kind, self.x_in, self.x_out, sc(self.A), sc(self.B), sc(self.C), sc(self.S),
                            depol=sc(self.depol))

    def times(self, factor: np.ndarray | float) -> MuellerValue:
        """``scaled(factor)`` with the products put off (a ScaledValue) for an ABCS or depolarising value: they are
        multiplied out on first read, the same bits; a mixture's sum multiplies them in its own pass instead."""
        if self.kind == "general":
            return self.scaled(factor)
        return ScaledValue(self, factor)

    def m00(self) -> np.ndarray:
        """M00 (L, N): the value's response to unpolarised light (its S0)."""
        if self.kind == "general":
            return self.M[0, 0]
        return self.A if self.depol is None else self.A + self.depol

    def masked(self, keep: np.ndarray) -> MuellerValue:
        """Zero the entries where ``keep`` (N,) is False."""
        return self.scaled(keep.astype(np.float64)[None, :])


class ScaledValue(MuellerValue):
    """An ABCS or depolarising ``base`` times factors f₁, f₂, … (each a number, (N,) made (1, N), or broadcastable
    to (L, N)), applied in order: every block is ((b·f₁)·f₂)·…, the bits of ``base.scaled(f₁).scaled(f₂)…``.  The
    blocks (A, B, C, S, depol) are multiplied out on first read and kept; engine.materials.mix's compiled sums read
    ``base`` and ``factors`` and multiply them in their own pass, without the scaled copies."""

    def __init__(self, base: MuellerValue, factor):
        if isinstance(base, ScaledValue):
            base, factors = base.base, base.factors + (factor,)
        else:
            factors = (factor,)
        if base.kind not in ("abcs", "depolarising"):
            raise ValueError(f"a ScaledValue scales an ABCS or depolarising value, got {base.kind!r}")
        self.kind, self.x_in, self.x_out, self.M = base.kind, base.x_in, base.x_out, None
        self.base, self.factors = base, factors
        self._blocks = None

    def _value(self) -> MuellerValue:
        if self._blocks is None:
            v = self.base
            for f in self.factors:
                v = MuellerValue.scaled(v, f)
            self._blocks = v
        return self._blocks

    A = property(lambda self: self._value().A)
    B = property(lambda self: self._value().B)
    C = property(lambda self: self._value().C)
    S = property(lambda self: self._value().S)
    depol = property(lambda self: self._value().depol)

    def scaled(self, factor) -> MuellerValue:
        return self._value().scaled(factor)

    def times(self, factor) -> MuellerValue:
        return ScaledValue(self, factor)


def depolarising_value(a: np.ndarray, n: int) -> MuellerValue:
    """A depolariser a·diag(1,0,0,0) (frames irrelevant, filled with zeros)."""
    zeros = np.zeros((3, n))
    return MuellerValue("depolarising", zeros, zeros, A=a)


@dataclass
class LobeColors:
    """A vertex's albedo by lobe, as Cycles' Color passes define it (``bsdf_albedo`` summed over the closures of
    each kind): ``diffuse``, ``glossy`` (reflection) and ``transmission``, each M00 (L, N) per wavelength — the
    share of unpolarised light from a uniform white sky that the lobe sends towards the viewer, deterministic
    for the vertex (engine.render.light_passes divides the light by it)."""

    diffuse: np.ndarray
    glossy: np.ndarray
    transmission: np.ndarray

    @staticmethod
    def of(sp: ShadingPoint, diffuse=0.0, glossy=0.0, transmission=0.0) -> LobeColors:
        """The lobes' albedos at the points ``sp``, each a number, (N,) or (L, N), as (L, N) arrays."""
        def full(v):
            v = np.asarray(v, np.float64)
            return np.broadcast_to(v[None, :] if v.ndim == 1 else v, sp.lam.shape).copy()
        return LobeColors(full(diffuse), full(glossy), full(transmission))

    def scaled(self, factor) -> LobeColors:
        """Every lobe times ``factor`` (a number, (N,) per point or (L, N))."""
        f = factor[None, :] if isinstance(factor, np.ndarray) and factor.ndim == 1 else factor
        return LobeColors(self.diffuse * f, self.glossy * f, self.transmission * f)

    def tinted(self, reflection, transmission) -> LobeColors:
        """Diffuse and glossy times ``reflection``, transmission times ``transmission`` (numbers or (L, N))."""
        return LobeColors(self.diffuse * reflection, self.glossy * reflection, self.transmission * transmission)

    def __add__(self, other: LobeColors) -> LobeColors:
        return LobeColors(self.diffuse + other.diffuse, self.glossy + other.glossy,
                          self.transmission + other.transmission)


@dataclass
class BSDFSample:
    """Result of ``BSDF.sample`` for a batch of N shading points."""

    wi: np.ndarray             # (3, N) unit direction towards the light
    weight: MuellerValue       # f·|cosθ_i|/pdf (Dirac lobes: their Mueller weight), incl. radiance scale
    pdf: np.ndarray            # (N,) solid-angle pdf of wi (0 for Dirac lobes)
    is_delta: np.ndarray       # (N,) bool: wi was chosen from a Dirac lobe
    valid: np.ndarray          # (N,) bool: False where no direction could be sampled
    eta_sq: np.ndarray | None = field(default=None)  # (N,) radiance scale undone for Russian roulette (1 = none)


@dataclass(eq=False)
class DeltaVertices:
    """The vertices of one delta-only material in a path tracer's batch, for ``BSDF.scatter_delta``.

    Every array is the batch's own (paths on the last axis, n of them), read and written only at the
    columns ``rows`` (m,) int64 — no gathered copies.  Inputs: shading normal ``n_s`` and direction to
    the previous vertex ``wo`` (3, n), the materials' wavelengths ``lam`` (Lm, n) nm (``mono``: one
    wavelength), the lobe-choice numbers ``u_lobe`` (n,), the throughput ``T`` (P, P, Lm, n) in frame
    ``x_T`` (3, n) ⟂ wo, read at the columns ``T_cols`` (m,) (None: ``rows``; the batch does not copy T
    when it drops finished paths: engine.render.path_state.PathState.T_col).  Outputs: ``T_out`` =
    T·R(x_out → x_T)·M, the sampled direction ``d`` (= wi) and its frame ``x_out`` (3, n), ``valid`` (n,)
    bool and the radiance scale ``eta_sq`` (n,).
    """
    rows: np.ndarray
    n_s: np.ndarray
    wo: np.ndarray
    lam: np.ndarray
    mono: bool
    u_lobe: np.ndarray
    T: np.ndarray
    x_T: np.ndarray
    T_out: np.ndarray
    d: np.ndarray
    x_out: np.ndarray
    valid: np.ndarray
    eta_sq: np.ndarray
    T_cols: np.ndarray | None = None


class BSDF:
    """Base class of the material models.

    ``flags`` (BSDFFlags) says which lobes the model has and what it can do to polarisation;
    models set it as a class attribute or, where parameters matter, per instance in
    ``__init__``.  A model that sets nothing is assumed to do everything (UNKNOWN_MODEL_FLAGS).
    The boolean properties below are read-only views of ``flags``.
    """

    flags: BSDFFlags = UNKNOWN_MODEL_FLAGS
    name: str = "bsdf"
    #: some parameter is a texture (engine.textures): the integrator then gives the shading points
    #: their surface attributes (ShadingPoint.surface)
    varies_over_surface: bool = False
    #: Seen from the back (the geometric normal facing away from the viewer), an opaque two-sided
    #: material shades with both normals flipped, as Blender's materials do in Cycles; a material with
    #: a transmission lobe keeps its inside and outside.  The models are one-sided by default (scene
    #: files: ``"two_sided": true``); the Blender exporter sets it on every material it converts.
    #: Set on an instance only when true, so a one-sided material's scene fingerprint is unchanged.
    two_sided: bool = False
    #: A direction (sampled, or towards a light) counts only where it lies on the same side of the surface
    #: (geometric normal n_g) as of the shading normal: reflected light must leave above the faceted surface,
    #: refracted light below it, as Cycles' closures require (kernel/closure/bsdf_microfacet.h, "the same
    #: hemisphere w.r.t. both normals").  Without it, an interpolated normal lets a rough lobe sample
    #: directions into the object (a smooth-shaded emitter then lit itself: +2 % on SpecGlossEmission).  The
    #: Blender exporter sets it on every material; scene files keep the shading normal alone (False).
    geometric_sides: bool = False
    #: Refraction scales radiance by (n_o/n_i)² = 1/η² (the physics, as Mitsuba 3 and pbrt; a path that
    #: enters and leaves a closed object gets both factors, which cancel).  False: Cycles' convention, no
    #: such factor (the integrator multiplies it back: each sampled refraction's weight by its η²,
    #: BSDFSample.eta_sq, and next-event estimation through a rough interface by ``refraction_eta_sq``), so
    #: a surface crossed only once — an open glass sheet, inverted normals — renders as in Cycles.  The
    #: Blender exporter sets it on every material it converts; scene files: ``"radiance_scaling": false``.
    #: Set on an instance only when false, so existing scenes' fingerprints are unchanged.
    radiance_scaling: bool = True

    @property
    def scatters_nothing(self) -> bool:
        """The model reflects and transmits nothing anywhere (a black surface: an emitter's material in Blender,
        a glTF unlit surface); models that can prove it say so (engine.render.visibility crosses such a surface's
        alpha without a random choice)."""
        return False

    @property
    def delta_only(self) -> bool:
        """Every lobe is a Dirac delta (no next-event estimation at such vertices)."""
        return self.flags.is_delta_only

    @property
    def transmits(self) -> bool:
        """Light can pass through the surface (refraction, a filter sheet)."""
        return self.flags.transmits

    @property
    def polarising(self) -> bool:
        """The model can change the polarisation state (False for a depolariser such as Lambert)."""
        return self.flags.polarising

    @property
    def creates_circular(self) -> bool:
        """The model can create circular polarisation (BSDFFlags.RETARDING)."""
        return self.flags.retarding

    def eval(self, sp: ShadingPoint, wi: np.ndarray) -> MuellerValue:
        raise NotImplementedError

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def eval_and_pdf(self, sp: ShadingPoint, wi: np.ndarray) -> tuple[MuellerValue, np.ndarray]:
        """(``eval(sp, wi)``, ``pdf(sp, wi)``): a model that computes both in one pass overrides it (the same
        numbers as the two calls)."""
        return self.eval(sp, wi), self.pdf(sp, wi)

    def sample(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        raise NotImplementedError

    def sample_direction(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        """``sample`` for a caller that evaluates the non-Dirac directions itself (a mixture,
        engine.materials.mix): the same wi, pdf, is_delta, valid and eta_sq; the weight is ``sample``'s on the
        Dirac lanes (is_delta & valid) and unspecified elsewhere, None where there is none.  By default ``sample``;
        models whose weight costs more than their direction skip it."""
        return self.sample(sp, u_lobe, u_dir)

    def diffuse_share(self, sp: ShadingPoint, wi: np.ndarray, f: MuellerValue) -> np.ndarray | None:
        """M00 (L, N) of the diffuse lobes (Cycles' diffuse closures: Lambert, Oren–Nayar, sheen, translucent)
        within ``f`` = ``eval(sp, wi)``, which the light passes count as Diffuse (engine.render.light_passes); a
        diffuse lobe depolarises, so that part of f is M00·diag(1, 0, 0, 0).  By the lobes: none without a
        diffuse lobe, all of f without a glossy one (Dirac lobes are not in ``eval``); models with both override
        it, else None: not separated (the light passes then count the whole value as Glossy, with a warning)."""
        if not self.flags.has(BSDFFlags.DIFFUSE):
            return np.zeros_like(f.m00())
        if not self.flags.has(BSDFFlags.GLOSSY):
            return f.m00()
        return None

    def lobe_colors(self, sp: ShadingPoint) -> LobeColors | None:
        """The albedo of each lobe at the points (LobeColors, M00 (L, N) each) by Cycles' definition: what its
        Diffuse / Glossy / Transmission Color passes hold (kernel/closure/bsdf.h ``bsdf_albedo``; derivations in
        docs/guide/polariser-and-passes.md).  By default: a mirror without other lobes, the M00 of its
        ``delta_reflection``; models with other lobes override it, else None: not available (the light passes
        then estimate the colour from the sampled direction, with a warning)."""
        if self.flags.lobes == BSDFFlags.DELTA_REFLECTION:
            value = self.delta_reflection(sp)
            if value is not None:
                return LobeColors.of(sp, glossy=value.m00())
        return None

    def delta_reflection(self, sp: ShadingPoint) -> MuellerValue | None:
        """Mueller weight of the mirror (Dirac) lobe for reflection of wo, or None."""
        return None

    def scatter_delta(self, v: DeltaVertices) -> bool:
        """Sample the vertices ``v`` and update their throughputs in one step (see the module
        docstring); False: not available here (the caller uses ``sample``)."""
        return False

    def refraction_eta_sq(self, sp: ShadingPoint) -> np.ndarray | None:
        """η² (N,) of a refraction from the viewer's side (η = n beyond / n on the viewer's side): the
        factor by which ``eval`` of a transmitted direction is below Cycles' (see ``radiance_scaling``);
        None for a material without non-Dirac transmission."""
        return None

    def shading_point(self, sp: ShadingPoint) -> ShadingPoint:
        """The point at which this material is evaluated: ``sp`` itself, or with the shading normal
        from a normal or bump map (engine.materials.normal_map).  Callers (the integrator) pass the
        result to eval/pdf/sample/delta_reflection."""
        return sp

    def describe(self) -> dict[str, object]:
        """Parameters for logs and file headers."""
        return {"type": self.name}


def take_value(v: MuellerValue, idx: np.ndarray) -> MuellerValue:
    """The lanes ``idx`` (integer indices) of a value: every array along its last axis."""
    def t(a):
        return None if a is None else np.take(a, idx, axis=-1)
    if v.kind == "general":
        return MuellerValue("general", t(v.x_in), t(v.x_out), M=t(v.M))
    return MuellerValue(v.kind, t(v.x_in), t(v.x_out), t(v.A), t(v.B), t(v.C), t(v.S), depol=t(v.depol))


def assemble_values(parts, n: int, L: int, frames) -> MuellerValue:
    """One value over n lanes from [(lanes idx, value over those lanes)] (zero elsewhere), of the
    cheapest kind that holds them all; ``frames()`` gives (x_in, x_out) for the lanes whose value
    is depolarising (any frame holds a depolariser), asked only where some lane has no other value's frames."""
    kinds = {v.kind for _, v in parts}
    if kinds <= {"depolarising"}:
        A = np.zeros((L, n))
        for idx, v in parts:
            A[:, idx] = v.A
        return depolarising_value(A, n)
    framed = np.zeros(n, bool)
    for idx, v in parts:
        if v.kind != "depolarising":
            framed[idx] = True
    # every lane's frames are some value's (written below): frames() would be overwritten everywhere
    x_in, x_out = (np.empty((3, n)), np.empty((3, n))) if framed.all() else frames()
    for idx, v in parts:
        if v.kind != "depolarising":
            x_in[:, idx], x_out[:, idx] = v.x_in, v.x_out
    if kinds <= {"depolarising", "abcs"}:
        A, B, C, S, D = (np.zeros((L, n)) for _ in range(5))
        shared = False
        for idx, v in parts:
            if v.kind == "depolarising":
                D[:, idx], shared = v.A, True
                continue
            A[:, idx], B[:, idx], C[:, idx], S[:, idx] = v.A, v.B, v.C, v.S
            if v.depol is not None:
                D[:, idx], shared = v.depol, True
        return MuellerValue("abcs", x_in, x_out, A, B, C, S, depol=D if shared else None)
    M = np.zeros((4, 4, L, n))
    for idx, v in parts:
        M[..., idx] = v.matrix()
    return MuellerValue("general", x_in, x_out, M=M)
