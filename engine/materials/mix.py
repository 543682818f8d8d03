"""An incoherent mixture of materials: f = Σ_k w_k·f_k (Blender's Mix Shader and Add Shader).

:class:`Mix` sums the Mueller BSDFs of its ``components`` with weights w_k ≥ 0, each a number or a
texture (per surface point, engine.textures).  Blender's Mix Shader with factor t is the weights
(1 − t, t), its Add Shader (1, 1); the weights are not normalised (a sum above 1 adds energy, as
Add Shader does).  Light scattered by different components adds incoherently, so the Mueller
matrices add.  Nested mixes are flattened (their weights multiplied), one material object listed
more than once with constant weights is listed once with their sum, and a component whose weight is
0 everywhere is dropped.

**Frames.**  Each component reports its value in its own frames (x_in ⟂ k_i = −ω_i, x_out ⟂
k_o = ω_o).  Depolarising values (A·diag(1, 0, 0, 0)) are frame-independent and add to M00 (an ABCS
value's ``depol`` share, a general value's M00).  With one polarising value the sum keeps that
value's kind and frames.  With several, the frames of the first polarising component are the common
pair (where a frame vector is degenerate, the plane-of-incidence axis unit(n_s × k) instead); ABCS
values whose frames already agree (|sin 2φ| ≤ 1e-12 on both beams) add as ABCS, otherwise every value
is rotated into the common pair (R_out·M·R_inᵀ, engine.kernels.stokes_rotation) and the sum is a
general matrix.

**Sampling.**  Component k is chosen with probability p_k = w_k·a_k / Σ_j w_j·a_j, a_k a cheap
albedo estimate: the wavelength-mean albedo of a Lambert component, a component's own
``albedo_estimate(sp)`` if it has one, else 1 (a Layered's top layer: its albedo E_top(ω_o), as Cycles weights
a closure by its albedo estimate; a Layered in a mix: Σ of its layers' w·a); a_k is clipped to
[ALBEDO_FLOOR, 1], so p_k > 0 wherever w_k > 0.  The component samples with the rest of u_lobe rescaled to
[0, 1) as its own lobe number.  A direction from a non-Dirac lobe gets the mixture's weight
Σ_j w_j·f_j·|cosθ_i| / Σ_j p_j·pdf_j (so MIS and next-event estimation see the mixture's true
density, ``pdf``); a Dirac one (w_k/p_k)·M_k with pdf 0.  η² (the radiance scale for Russian
roulette) is the chosen component's.  With one component the sample is that component's, its
weight times w.

**Shading normals.**  A component may carry its own normal or bump map (a ShadingNormal wrapper):
each component is evaluated at its own shading point.  ``shading_point`` computes those points from
the unflipped hit (a MixShadingPoint); when the integrator then flips the point for the back of a
two-sided mix, each component's point is flipped with it (its mapped normal negated), as a single
normal-mapped material is mapped first and flipped after (Cycles' order).  Called with a plain
ShadingPoint (a coat above, a test), the mix maps the components from the normal it is given.  The
integrator multiplies f by |n_s·ω_i| with the mix's own normal, so a component with its own normal
n_k enters ``eval`` as w_k·f_k·|n_k·ω_i| / |n_s·ω_i| (0 where n_s·ω_i = 0); ``delta_reflection``
(into the mirror direction about n_s) includes such a component only where n_k = ±n_s.

**Two-sided.**  The mix is two-sided if its own ``two_sided`` is set (scene files: the mix's
``"two_sided"`` key) or if all its components are; the components' own settings are not read.  The
integrator flips the back faces of an opaque two-sided mix as a whole (each component's point with
it, above).  It does not flip a material that transmits, so a two-sided mix with a transmitting
component (Principled's Transmission) flips its opaque components itself where the viewer sees the
back (n_g·ω_o < 0), and leaves the transmitting ones their inside and outside, as Cycles does per
closure.

**Under a coat.**  A mix as the base of a Weidlich–Wilkie coat passes the coat index on to those of
its components with an ``exterior_n`` (the ``exterior_n`` property).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from .base import (BSDF, BSDFFlags, BSDFSample, LobeColors, MuellerValue, ScaledValue, ShadingPoint,
                   assemble_values, depolarising_value, take_value)
from .lambert import Lambert
from .normal_map import ShadingNormal
from .parameters import ModelDeclaration, Parameter
from ..errors import SceneError
from ..kernels import twin
from ..kernels.mueller_sum import chain_sum_loop
from ..kernels.stokes_rotation import frame_rotation
from ..polarisation.frames import plane_of_incidence_axis
from ..textures import TexturedNumber
from ..vec3 import dot, reflect

__all__ = ["ALBEDO_FLOOR", "MAX_COMPONENTS", "Layered", "Mix", "MixShadingPoint", "WeightProduct", "add_values",
           "emission_weight", "rotate_mueller_batch"]

#: Most components of one mix after nested mixes are flattened (named mixes of mixes could otherwise
#: multiply to thousands of components).
MAX_COMPONENTS = 64
#: Smallest albedo estimate in the lobe-selection probabilities (keeps p_k > 0 where w_k > 0).
ALBEDO_FLOOR = 0.02
#: ABCS values whose frames differ by less than this in sin 2φ add without rotation.
_SAME_FRAME = 1e-12
_BELOW_ONE = math.nextafter(1.0, 0.0)


# --------------------------------------------------------------------------- weights

class WeightProduct:
    """A weight c·t₁·t₂·… (a constant times textured numbers): a nested mix's weight times its
    parent's.  Every factor is ≥ 0."""

    def __init__(self, constant: float, factors: tuple):
        self.constant, self.factors = float(constant), tuple(factors)
        self.lo = self.constant * math.prod(f.lo for f in self.factors)
        self.hi = self.constant * math.prod(f.hi for f in self.factors)

    def at(self, points) -> np.ndarray:
        value = self.constant
        for f in self.factors:
            value = value * f.at(points)
        return value

    def __repr__(self):
        return " × ".join([f"{self.constant:g}"] * (self.constant != 1.0) + [repr(f) for f in self.factors])


def _check_weight(w, where: str):
    """``w`` as a float, TexturedNumber or WeightProduct, ≥ 0 everywhere (ValueError otherwise)."""
    if isinstance(w, (TexturedNumber, WeightProduct)):
        if not (w.lo >= 0.0 and math.isfinite(w.hi)):
            raise ValueError(f"{where} must be ≥ 0 and finite everywhere, its texture spans [{w.lo:g}, {w.hi:g}]")
        return w
    if isinstance(w, (bool, np.bool_)) or not isinstance(w, (int, float, np.integer, np.floating)):
        raise ValueError(f"{where} must be a number or a TexturedNumber, got {w!r}")
    v = float(w)
    if not (math.isfinite(v) and v >= 0.0):
        raise ValueError(f"{where} must be a finite number ≥ 0, got {w!r}")
    return v


def _times(a, b):
    """The product of two weights (floats, TexturedNumbers, WeightProducts)."""
    if isinstance(a, float) and isinstance(b, float):
        return a * b

    def parts(w):
        if isinstance(w, float):
            return w, ()
        if isinstance(w, WeightProduct):
            return w.constant, w.factors
        return 1.0, (w,)
    (ca, fa), (cb, fb) = parts(a), parts(b)
    return WeightProduct(ca * cb, fa + fb)


def _merged(components: list, weights: list) -> tuple[list, list]:
    """The same material object listed more than once with constant weights (a material named twice,
    or reached through several nested mixes) once, with the sum of those weights."""
    out_c, out_w, at = [], [], {}
    for c, w in zip(components, weights):
        j = at.get(id(c)) if isinstance(w, float) else None
        if j is not None:
            out_w[j] += w
            continue
        if isinstance(w, float):
            at[id(c)] = len(out_c)
        out_c.append(c)
        out_w.append(w)
    return out_c, out_w


def _is_zero(w) -> bool:
    return w == 0.0 if isinstance(w, float) else w.hi == 0.0


def _weight_at(sp: ShadingPoint, w) -> np.ndarray:
    """The weight's values (N,) at the points."""
    if isinstance(w, float):
        return np.full(sp.n, w)
    if isinstance(w, WeightProduct):
        return np.broadcast_to(w.at(sp.surface_points()), (sp.n,))
    return np.broadcast_to(sp.number(w), (sp.n,))


# --------------------------------------------------------------------------- Mueller sums

def _component_scale(sp: ShadingPoint, q: ShadingPoint, w: np.ndarray, wi: np.ndarray, cos_s: np.ndarray,
                     cosine: bool) -> np.ndarray:
    """A component's factor in Mix._sum: w·|n_q·ω_i| (``cosine``), w at the mix's own point, else
    w·|n_q·ω_i|/|n_s·ω_i| (0 where ``cos_s`` = |n_s·ω_i| is 0)."""
    if cosine:
        return w * np.abs(dot(q.n_s, wi))
    if q is sp:
        return w
    return w * np.where(cos_s > 0, np.abs(dot(q.n_s, wi)) / np.where(cos_s > 0, cos_s, 1.0), 0.0)


def rotate_mueller_batch(M: np.ndarray, c_in, s_in, c_out, s_out) -> np.ndarray:
    """R_out·M·R_inᵀ for M (4, 4, L, N) with the frame rotations (cos 2φ, sin 2φ) of each beam (N,)
    (engine.kernels.stokes_rotation.frame_rotation): rows 1–2 by the output's, columns 1–2 by the
    input's, per lane, without 4×4 products (the same numbers as
    engine.polarisation.frames.rotate_mueller_frames)."""
    out = M.copy()
    co, so = c_out[None, None, :], s_out[None, None, :]
    r1, r2 = M[1], M[2]
    out[1] = co * r1 + so * r2
    out[2] = -so * r1 + co * r2
    ci, si = c_in[None, None, :], s_in[None, None, :]
    k1, k2 = out[:, 1].copy(), out[:, 2].copy()
    out[:, 1] = ci * k1 + si * k2
    out[:, 2] = -si * k1 + ci * k2
    return out


def _usable_frame(x: np.ndarray, n_s: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, bool]:
    """``x`` where it is a unit vector, the plane-of-incidence axis unit(n_s × k) elsewhere; and
    whether anything was replaced."""
    ok = dot(x, x) > 0.25
    if ok.all():
        return x, False
    return np.where(ok[None, :], x, plane_of_incidence_axis(n_s, k)), True


def _split_terms(terms) -> tuple[np.ndarray | float | None, list[MuellerValue]]:
    """The scaled terms [(scale (N,) or float, MuellerValue)] apart: the sum of the depolarising
    ones' A (L, N) (None: there are none) and the polarising ones, scaled, in order."""
    dep = None
    pol = []
    for scale, v in terms:
        s = scale[None, :] if isinstance(scale, np.ndarray) else scale
        if v.kind == "depolarising":
            a = v.A * s
            dep = a if dep is None else dep + a
        else:
            pol.append(v.scaled(s))
    return dep, pol


def _plus_depolariser(v: MuellerValue, dep) -> MuellerValue:
    """One polarising value plus a depolarising A (L, N) (None: nothing), of the value's kind and
    frames (ABCS: added to its depol share; general: to M00)."""
    if dep is None:
        return v
    if v.kind == "abcs":
        depol = dep if v.depol is None else v.depol + dep
        return MuellerValue("abcs", v.x_in, v.x_out, v.A, v.B, v.C, v.S, depol=depol)
    M = v.M.copy()
    M[0, 0] = M[0, 0] + dep
    return MuellerValue("general", v.x_in, v.x_out, M=M)


def _common_frames(pol: list[MuellerValue], k_in: np.ndarray, k_out: np.ndarray, n_s: np.ndarray):
    """The common frame pair (x_in, x_out) (3, N) of several polarising values (the first's, made
    usable) and each value's rotation into it: (cos 2φ_in, sin 2φ_in, cos 2φ_out, sin 2φ_out) (N,)
    each, None for the first value when its frames were kept."""
    ref = pol[0]
    x_in, moved_in = _usable_frame(ref.x_in, n_s, k_in)
    x_out, moved_out = _usable_frame(ref.x_out, n_s, k_out)
    rotations = [None if (i == 0 and not (moved_in or moved_out)) else
                 frame_rotation(v.x_in, x_in, k_in) + frame_rotation(v.x_out, x_out, k_out)
                 for i, v in enumerate(pol)]
    return x_in, x_out, rotations


def _is_identity_rotation(r) -> bool:
    """Whether a rotation from ``_common_frames`` leaves both beams' frames as they are
    (|sin 2φ| ≤ _SAME_FRAME, cos 2φ > 0 on every lane)."""
    return r is None or (np.all(np.abs(r[1]) <= _SAME_FRAME) and np.all(np.abs(r[3]) <= _SAME_FRAME)
                         and np.all(r[0] > 0) and np.all(r[2] > 0))


def _shared_abcs_frames(pol: list[MuellerValue], k_in: np.ndarray, k_out: np.ndarray) -> bool:
    """Whether ABCS values are all in the first one's frames, equal to the bit, those usable (|x|² > 0.25) about
    finite beams: then ``_common_frames`` keeps them and finds every rotation the identity (cos 2φ ≈ 1, sin 2φ a
    rounding error of x·(k × x) = 0), so the sum is ``abcs_sum`` in them, without the rotations computed."""
    ref = pol[0]
    if any(v.kind != "abcs" for v in pol) or not all(
            (v.x_in is ref.x_in or np.array_equal(v.x_in, ref.x_in))
            and (v.x_out is ref.x_out or np.array_equal(v.x_out, ref.x_out)) for v in pol[1:]):
        return False
    return bool(np.all(dot(ref.x_in, ref.x_in) > 0.25) and np.all(dot(ref.x_out, ref.x_out) > 0.25)
                and np.isfinite(k_in).all() and np.isfinite(k_out).all())


def _sum_abcs(pol: list[MuellerValue], dep, x_in: np.ndarray, x_out: np.ndarray) -> MuellerValue:
    """Σ of ABCS values already in the frames (x_in, x_out), plus a depolarising A (L, N) (None:
    nothing), as an ABCS value."""
    A, B, C, S = (sum(getattr(v, f) for v in pol) for f in "ABCS")
    shares = [v.depol for v in pol if v.depol is not None] + ([dep] if dep is not None else [])
    return MuellerValue("abcs", x_in, x_out, A, B, C, S, depol=sum(shares) if shares else None)


def _sum_general(pol: list[MuellerValue], rotations, dep, x_in: np.ndarray, x_out: np.ndarray,
                 n: int, L: int) -> MuellerValue:
    """Σ of the values rotated into the frames (x_in, x_out) (``rotations`` from ``_common_frames``),
    plus a depolarising A (L, N) (None: nothing) on M00, as a general value (4, 4, L, n)."""
    M = np.zeros((4, 4, L, n))
    for v, r in zip(pol, rotations):
        M += v.matrix() if r is None else rotate_mueller_batch(v.matrix(), r[0], r[1], r[2], r[3])
    if dep is not None:
        M[0, 0] += dep
    return MuellerValue("general", x_in, x_out, M=M)


def abcs_sum_numpy(terms, x_in: np.ndarray, x_out: np.ndarray) -> MuellerValue:
    """Σ scale·value over ``terms`` [(scale (N,) or float, MuellerValue)] whose polarising values are ABCS values
    in the frames (x_in, x_out) (3, N), as an ABCS value."""
    dep, pol = _split_terms(terms)
    return _sum_abcs(pol, dep, x_in, x_out)


#: The most terms (values and depolarisers) the compiled sums take in one loop (the precompiled scenes' mixtures hold
#: 2–4; more go to the NumPy twins, the same bits).
_MAX_COMPILED_TERMS = 4
#: The most factors one term carries into the compiled sums (a lobe's normal-map factor, a tint, the mixture's
#: weight: a ScaledValue's factors and the term's scale), shorter chains padded with ones (x·1 = x, the same bits).
_MAX_FACTORS = 4
_NO_BLOCK = np.zeros((1, 1))
def _factor_block(f, L: int, n: int, scale: bool):
    """A factor as the compiled loop reads it: a (1 or L, n) float64 C array (a number spread over the row); None
    where it is not one (``scale``: a term's scale, a number or (n,), read as (1, n), as _split_terms reads it)."""
    a = np.asarray(f)
    if scale and a.ndim not in (0, 1):
        return None
    a = a.reshape(1, 1) if a.ndim == 0 else (a[None, :] if a.ndim == 1 else a)
    if a.ndim != 2 or a.shape[0] not in (1, L) or a.shape[1] not in (1, n) or a.dtype.kind not in "biuf":
        return None
    if a.shape[1] != n:
        return np.full((a.shape[0], n), a[:, 0], np.float64) if a.shape[0] == 1 else \
            np.ascontiguousarray(np.broadcast_to(a, (a.shape[0], n)), np.float64)
    # (writeable C arrays: a tuple mixing read-only and writeable arrays is heterogeneous, which Numba cannot index)
    return np.require(a, np.float64, ["C", "W"])


def _term_arrays(scale, v: MuellerValue, polarising: bool, shape: tuple):
    """One term's arrays for the compiled loop: (its blocks A, B, C, S, depol — dummies where it has none —, its
    factors padded to _MAX_FACTORS, their count), or None where the loop does not take it."""
    L, n = shape
    base, chain = (v.base, v.factors) if isinstance(v, ScaledValue) else (v, ())
    fs = [_factor_block(f, L, n, False) for f in chain] + [_factor_block(scale, L, n, True)]
    if len(fs) > _MAX_FACTORS or any(f is None for f in fs):
        return None
    blocks = (base.A, base.B, base.C, base.S, base.depol) if polarising else (base.A, None, None, None, None)
    if any(a is not None and (a.shape != shape or a.dtype != np.float64) for a in blocks):
        return None
    blocks = tuple(_NO_BLOCK if a is None else np.require(a, np.float64, ["C", "W"]) for a in blocks)
    return blocks, tuple(fs) + (fs[0],) * (_MAX_FACTORS - len(fs)), len(fs)


def _compiled_sum(terms, summed: bool):
    """The blocks (A, B, C, S, depol or None) of Σ scale·value over ``terms`` in one compiled loop
    (engine.kernels.mueller_sum.chain_sum_loop): ``summed`` as abcs_sum_numpy adds them, else as _plus_depolariser
    adds one ABCS value and the depolarisers; a ScaledValue's factors are multiplied there, in its order.  None
    where the loop does not take the terms (too many, blocks not (L, N) float64, long chains)."""
    ordered = [t for t in terms if t[1].kind == "abcs"] + [t for t in terms if t[1].kind == "depolarising"]
    n_pol = len(ordered) - sum(v.kind == "depolarising" for _, v in terms)
    if len(ordered) != len(terms) or len(ordered) > _MAX_COMPILED_TERMS or n_pol == 0:
        return None
    first = ordered[0][1]
    shape = (first.base if isinstance(first, ScaledValue) else first).A.shape
    if len(shape) != 2:
        return None
    arrays = [_term_arrays(scale, v, i < n_pol, shape) for i, (scale, v) in enumerate(ordered)]
    if any(t is None for t in arrays):
        return None
    has_depol = np.array([t[0][4] is not _NO_BLOCK for t in arrays])
    A, B, C, S, D = (np.zeros(shape) if summed else np.empty(shape) for _ in range(5))
    dep = np.empty(shape) if n_pol < len(ordered) else _NO_BLOCK
    chain_sum_loop(*(tuple(t[0][j] for t in arrays) for j in range(5)), has_depol, tuple(t[1] for t in arrays),
                   np.array([t[2] for t in arrays]), n_pol, summed, A, B, C, S, D, dep)
    if n_pol < len(ordered):        # the depolarisers' own sum, added last
        D = D + dep if summed or has_depol[0] else dep
    elif not has_depol.any():
        D = None
    return A, B, C, S, D


def abcs_sum_numba(terms, x_in: np.ndarray, x_out: np.ndarray) -> MuellerValue:
    """abcs_sum_numpy in one compiled loop (``_compiled_sum``: the blocks, the depolarised shares and the
    depolarisers, each term's factors multiplied there), the same bits; terms the loop does not take go to the
    NumPy twin."""
    out = _compiled_sum(terms, True)
    if out is None:
        return abcs_sum_numpy(terms, x_in, x_out)
    A, B, C, S, D = out
    return MuellerValue("abcs", x_in, x_out, A, B, C, S, depol=D)


#: Σ scale·value of ABCS values in shared frames (abcs_sum_numpy), compiled where available.
abcs_sum = twin(chain_sum_loop and abcs_sum_numba, abcs_sum_numpy)


def one_abcs_numpy(terms) -> MuellerValue:
    """Σ scale·value over ``terms`` holding one polarising value, an ABCS one, and depolarisers: that value scaled,
    in its frames, the depolarisers added to its depolarised share (``_plus_depolariser``)."""
    dep, pol = _split_terms(terms)
    return _plus_depolariser(pol[0], dep)


def one_abcs_numba(terms) -> MuellerValue:
    """one_abcs_numpy in one compiled loop (``_compiled_sum``), the same bits."""
    out = _compiled_sum(terms, False)
    if out is None:
        return one_abcs_numpy(terms)
    v = next(v for _, v in terms if v.kind == "abcs")
    A, B, C, S, D = out
    return MuellerValue("abcs", v.x_in, v.x_out, A, B, C, S, depol=D)


#: One ABCS value plus depolarisers (one_abcs_numpy), compiled where available.
one_abcs = twin(chain_sum_loop and one_abcs_numba, one_abcs_numpy)


def add_values(terms, n: int, L: int, k_in: np.ndarray, k_out: np.ndarray, n_s: np.ndarray) -> MuellerValue:
    """Σ scale·value over ``terms`` [(scale (N,) or float, MuellerValue)], all for the same beams
    k_in = −ω_i, k_out = ω_o (3, N) (see the module docstring, "Frames"); the cheapest kind that holds
    the sum."""
    polarising = [v for _, v in terms if v.kind != "depolarising"]
    if len(polarising) > 1 and _shared_abcs_frames(polarising, k_in, k_out):
        return abcs_sum(terms, polarising[0].x_in, polarising[0].x_out)
    if len(polarising) > 1:
        x_in, x_out, rotations = _common_frames(polarising, k_in, k_out, n_s)
        if all(v.kind == "abcs" for v in polarising) and all(_is_identity_rotation(r) for r in rotations):
            return abcs_sum(terms, x_in, x_out)
    if len(polarising) == 1 and polarising[0].kind == "abcs":
        return one_abcs(terms)
    dep, pol = _split_terms(terms)
    if not pol:
        return depolarising_value(np.zeros((L, n)) if dep is None else np.broadcast_to(dep, (L, n)).copy(), n)
    if len(pol) == 1:
        return _plus_depolariser(pol[0], dep)
    return _sum_general(pol, rotations, dep, x_in, x_out, n, L)


# --------------------------------------------------------------------------- shading points

@dataclass
class MixShadingPoint(ShadingPoint):
    """A mix's shading point with each component's own (``parts[k]``; None: the point itself), made
    by ``Mix.shading_point`` before the integrator flips two-sided back faces, and flipped and taken
    along with it."""

    owner: object = None
    parts: tuple = ()

    def _with(self, base: ShadingPoint, parts) -> MixShadingPoint:
        return MixShadingPoint(base.p, base.n_s, base.n_g, base.wo, base.lam, base.mono, base.lookup, base.material,
                               base.surface, self.owner, tuple(parts))

    def take(self, sel, shared: dict | None = None) -> MixShadingPoint:
        shared = {} if shared is None else shared       # the components' points share the hit's arrays
        return self._with(super().take(sel, shared),
                          (None if q is None else q.take(sel, shared) for q in self.parts))._taken_from(self, sel)

    def flipped(self, where: np.ndarray) -> MixShadingPoint:
        return self._with(super().flipped(where), (None if q is None else q.flipped(where) for q in self.parts))


def _albedo_estimate(component: BSDF, sp: ShadingPoint):
    """A cheap estimate in [ALBEDO_FLOOR, 1] of how much light the component reflects at the points
    ((N,) or 1.0): its own ``albedo_estimate(sp)`` if it has one, a Lambert's wavelength-mean albedo,
    else 1."""
    own = getattr(component, "albedo_estimate", None)
    if callable(own):
        return np.clip(own(sp), ALBEDO_FLOOR, 1.0)
    base = component.base if isinstance(component, ShadingNormal) else component
    if isinstance(base, Lambert) and base.albedo is not None:
        return np.clip(sp.spectrum(base.albedo).mean(axis=0), ALBEDO_FLOOR, 1.0)
    return 1.0


# --------------------------------------------------------------------------- the model

class Mix(BSDF):
    """f = Σ_k w_k·f_k (see the module docstring).

    ``components``: BSDFs (nested Mix components are flattened); ``weights``: one per component, a
    number ≥ 0 or a TexturedNumber (engine.textures) whose values are ≥ 0.
    """

    name = "mix"

    def __init__(self, components, weights):
        components, weights = list(components), list(weights)
        if not components:
            raise ValueError("a mix needs at least one material")
        if len(weights) != len(components):
            raise ValueError(f"a mix needs one weight per material: {len(components)} materials, "
                             f"{len(weights)} weights")
        flat_c, flat_w = [], []
        for i, (c, w) in enumerate(zip(components, weights)):
            if not isinstance(c, BSDF):
                raise ValueError(f"material {i} of a mix must be a BSDF, got {c!r}")
            w = _check_weight(w, f"weight {i} of a mix")
            if type(c) is Mix:            # a plain mix flattens (a Layered keeps its view-dependent weights)
                flat_c += c.components
                flat_w += [_times(w, inner) for inner in c.weights]
            else:
                flat_c.append(c)
                flat_w.append(w)
        flat_c, flat_w = _merged(flat_c, flat_w)
        if len(flat_c) > MAX_COMPONENTS:
            raise ValueError(f"a mix has at most {MAX_COMPONENTS} materials in all (counting nested mixes' "
                             f"materials), got {len(flat_c)}")
        keep = [i for i, w in enumerate(flat_w) if not _is_zero(w)]
        self.components = [flat_c[i] for i in keep]
        self.weights = [flat_w[i] for i in keep]
        if self.components and all(c.two_sided for c in self.components):
            self.two_sided = True
        self.varies_over_surface = any(c.varies_over_surface for c in self.components) or \
            any(not isinstance(w, float) for w in self.weights)
        self.flags = self._mixed_flags()

    # --- flags -----------------------------------------------------------------------------------

    def _mixed_flags(self) -> BSDFFlags:
        """The union of the components' lobes and capabilities (never BATCHED); SEPARABLE_DIFFUSE when
        the sum keeps the diffuse lobes apart: no component with a non-Dirac polarising lobe, or one
        that keeps its own diffuse lobes apart (``add_values`` then adds the rest to its depol)."""
        F = BSDFFlags
        flags = F.NONE
        for c in self.components:
            flags |= c.flags & (F.LOBES | F.POLARISING | F.RETARDING | F.WAVELENGTH_DEPENDENT)
        smooth = [c for c in self.components if c.flags.has(F.SMOOTH)]
        polarising = [c for c in smooth if c.flags.polarising]
        if smooth and (not polarising or (len(polarising) == 1 and polarising[0].flags.has(F.SEPARABLE_DIFFUSE))):
            flags |= F.SEPARABLE_DIFFUSE
        return flags

    # --- under a coat ----------------------------------------------------------------------------

    @property
    def exterior_n(self):
        """The exterior index of the first component that has one (AttributeError if none has)."""
        for c in self.components:
            if hasattr(c, "exterior_n"):
                return c.exterior_n
        raise AttributeError("no material of this mix has an exterior index")

    @exterior_n.setter
    def exterior_n(self, value):
        """Set the exterior index of every component that has one (on copies: a coat configures its
        own copy of the base, engine.materials.weidlich_wilkie)."""
        parts = []
        for c in self.components:
            if hasattr(c, "exterior_n"):
                c = copy.copy(c)
                c.exterior_n = value
            parts.append(c)
        self.components = parts

    def with_components(self, components) -> Mix:
        """This mix (its kind, weights, layering and two-sidedness) over ``components``, one per component,
        in order, e.g. each with its own normal map (engine.materials.normal_map.map_normals)."""
        components = list(components)
        if len(components) != len(self.components):
            raise ValueError(f"with_components needs {len(self.components)} materials, got {len(components)}")
        out = copy.copy(self)
        out.components = components
        out.varies_over_surface = self.varies_over_surface or any(c.varies_over_surface for c in components)
        out.flags = out._mixed_flags()
        return out

    # --- points, weights, probabilities ----------------------------------------------------------

    def _component_points(self, sp: ShadingPoint) -> list[ShadingPoint]:
        """Each component's shading point: ``sp`` itself, or the component's own (a normal or bump map);
        for an opaque component of a two-sided mix that transmits (which the integrator does not flip),
        flipped where the viewer sees the back (n_g·ω_o < 0), as the integrator flips an opaque material."""
        flip = None
        if self.two_sided and self.flags.transmits:
            back = dot(sp.n_g, sp.wo) < 0
            flip = back if back.any() else None
        out = []
        for c in self.components:
            q = c.shading_point(sp) if type(c).shading_point is not BSDF.shading_point else sp
            if flip is not None and not c.flags.transmits:
                q = q.flipped(flip)
            out.append(q)
        return out

    def shading_point(self, sp: ShadingPoint) -> ShadingPoint:
        parts = self._component_points(sp)
        if all(q is sp for q in parts):
            return sp
        return MixShadingPoint(sp.p, sp.n_s, sp.n_g, sp.wo, sp.lam, sp.mono, sp.lookup, sp.material, sp.surface,
                               self, tuple(None if q is sp else q for q in parts))

    def _points(self, sp: ShadingPoint) -> list[ShadingPoint]:
        """Each component's shading point (``sp`` itself where the component has none of its own)."""
        if isinstance(sp, MixShadingPoint) and sp.owner is self:
            return [sp if q is None else q for q in sp.parts]
        return self._component_points(sp)

    def _weights(self, sp: ShadingPoint) -> list[np.ndarray]:
        return [_weight_at(sp, w) for w in self.weights]

    def _weights_at(self, sp: ShadingPoint) -> list[np.ndarray]:
        """``_weights(sp)``, computed once per batch (ShadingPoint.memo: next-event estimation evaluates and
        asks the pdf at the same points; a Layered's weights read its top layer's albedo)."""
        return sp.memo(self, "weights", lambda: self._weights(sp))

    def _probabilities_at(self, sp: ShadingPoint, points) -> np.ndarray:
        """``_probabilities`` at the batch ``sp`` (its ``_points``), computed once per batch."""
        return sp.memo(self, "probabilities", lambda: self._probabilities(points, self._weights_at(sp)))

    def _estimates(self, points, weights) -> list:
        """w_k·a_k per component (the module docstring, "Sampling")."""
        return [w * _albedo_estimate(c, q) for c, q, w in zip(self.components, points, weights)]

    def _probabilities(self, points, weights) -> np.ndarray:
        """(K, N) lobe-selection probabilities p_k ∝ w_k·a_k (``_estimates``; 0 where every weight is 0)."""
        if not self.components:
            return np.zeros((0, 0))
        raw = np.array(self._estimates(points, weights))
        total = raw.sum(axis=0)
        return raw / np.where(total > 0, total, 1.0)[None, :]

    # --- BSDF interface --------------------------------------------------------------------------

    def _sum(self, sp, points, weights, wi, cosine: bool) -> MuellerValue:
        """Σ w_k·f_k (``cosine``: Σ w_k·f_k·|n_k·ω_i|), each f_k at its own point; with own normals and
        not ``cosine``, w_k·f_k·|n_k·ω_i|/|n_s·ω_i| (see the module docstring)."""
        cos_s = np.abs(dot(sp.n_s, wi))
        terms = []
        for c, q, w in zip(self.components, points, weights):
            if not w.any():
                continue
            terms.append((_component_scale(sp, q, w, wi, cos_s, cosine), c.eval(q, wi)))
        return add_values(terms, sp.n, sp.lam.shape[0], -wi, sp.wo, sp.n_s)

    def _sum_and_pdf(self, sp, points, weights, p, wi, cosine: bool) -> tuple[MuellerValue, np.ndarray]:
        """(``_sum(sp, points, weights, wi, cosine)``, ``_pdf(points, p, wi)``), a component asked for both once
        (BSDF.eval_and_pdf: one pass where it has one; the same numbers)."""
        cos_s = np.abs(dot(sp.n_s, wi))
        terms = []
        out = np.zeros(wi.shape[1])
        for c, q, w, pk in zip(self.components, points, weights, p):
            value, density = w.any(), pk.any() and not c.flags.is_delta_only
            if value and density:
                f, d = c.eval_and_pdf(q, wi)
            elif value:
                f = c.eval(q, wi)
            elif density:
                d = c.pdf(q, wi)
            if density:
                out += pk * d
            if value:
                terms.append((_component_scale(sp, q, w, wi, cos_s, cosine), f))
        return add_values(terms, sp.n, sp.lam.shape[0], -wi, sp.wo, sp.n_s), out

    def refraction_eta_sq(self, sp: ShadingPoint) -> np.ndarray | None:
        """The first transmitting component's (a mix's transmitting materials are taken to share one index,
        as Principled's one glass does)."""
        for c, q in zip(self.components, self._points(sp)):
            k = c.refraction_eta_sq(q)
            if k is not None:
                return k
        return None

    def eval(self, sp: ShadingPoint, wi: np.ndarray) -> MuellerValue:
        return self._sum(sp, self._points(sp), self._weights_at(sp), wi, cosine=False)

    def diffuse_share(self, sp: ShadingPoint, wi: np.ndarray, f: MuellerValue) -> np.ndarray | None:
        """Σ w_k·d_k (L, N): each component's diffuse part at its own point, weighted as ``eval`` weights its
        value (a Layered's base under the layer's attenuation); None if a component with both diffuse and
        glossy lobes does not tell them apart."""
        if not (self.flags.has(BSDFFlags.DIFFUSE) and self.flags.has(BSDFFlags.GLOSSY)):
            return super().diffuse_share(sp, wi, f)
        cos_s = np.abs(dot(sp.n_s, wi))
        out = np.zeros(f.m00().shape)
        for c, q, w in zip(self.components, self._points(sp), self._weights_at(sp)):
            if not w.any() or not c.flags.has(BSDFFlags.DIFFUSE):
                continue
            d = c.diffuse_share(q, wi, c.eval(q, wi))
            if d is None:
                return None
            if q is not sp:
                w = w * np.where(cos_s > 0, np.abs(dot(q.n_s, wi)) / np.where(cos_s > 0, cos_s, 1.0), 0.0)
            out = out + w[None, :] * d
        return out

    def lobe_colors(self, sp: ShadingPoint) -> LobeColors | None:
        """Σ w_k·colours_k, each component's at its own point (a Layered's base under the layer's attenuation:
        Cycles' closure weights after ``closure_layering_weight``); None if a component has none."""
        out = LobeColors.of(sp)
        for c, q, w in zip(self.components, self._points(sp), self._weights_at(sp)):
            if not w.any():
                continue
            colors = c.lobe_colors(q)
            if colors is None:
                return None
            out = out + colors.scaled(w)
        return out

    def _pdf(self, points, p, wi) -> np.ndarray:
        out = np.zeros(wi.shape[1])
        for c, q, pk in zip(self.components, points, p):
            if pk.any() and not c.flags.is_delta_only:
                out += pk * c.pdf(q, wi)
        return out

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        points = self._points(sp)
        return self._pdf(points, self._probabilities_at(sp, points), wi)

    def eval_and_pdf(self, sp: ShadingPoint, wi: np.ndarray) -> tuple[MuellerValue, np.ndarray]:
        """(``eval``, ``pdf``) with each component asked once for both (``_sum_and_pdf``)."""
        cls = type(self)
        if cls.eval is not Mix.eval or cls.pdf is not Mix.pdf or not self.components:
            return super().eval_and_pdf(sp, wi)
        points = self._points(sp)
        return self._sum_and_pdf(sp, points, self._weights_at(sp), self._probabilities_at(sp, points), wi, False)

    def sample(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        return self._sample(sp, u_lobe, u_dir, weighted=True)

    def sample_direction(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        """``sample`` without the mixture's value at the non-Dirac directions (a mix inside a mix: the outer
        one evaluates them)."""
        return self._sample(sp, u_lobe, u_dir, weighted=False)

    def _sample(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray, weighted: bool) -> BSDFSample:
        """``sample``; not ``weighted``: the weight only on the Dirac lanes (BSDF.sample_direction).  The
        components sample their directions only (their values are the mixture's to sum)."""
        n, L = sp.n, sp.lam.shape[0]
        if not self.components:     # every weight was 0: black
            return BSDFSample(wi=sp.n_s.copy(), weight=depolarising_value(np.zeros((L, n)), n), pdf=np.zeros(n),
                              is_delta=np.zeros(n, bool), valid=np.zeros(n, bool), eta_sq=np.ones(n))
        points, weights = self._points(sp), self._weights_at(sp)
        if len(self.components) == 1:
            c = self.components[0]
            bs = c.sample(points[0], u_lobe, u_dir) if weighted else c.sample_direction(points[0], u_lobe, u_dir)
            w = weights[0]
            return BSDFSample(wi=bs.wi, weight=None if bs.weight is None else bs.weight.scaled(w[None, :]),
                              pdf=bs.pdf, is_delta=bs.is_delta, valid=bs.valid & (w > 0), eta_sq=bs.eta_sq)
        p = self._probabilities_at(sp, points)
        cols = np.arange(n)
        some = p.sum(axis=0) > 0
        cdf = np.cumsum(p, axis=0)
        k = (u_lobe[None, :] >= cdf[:-1]).sum(axis=0)
        # rounding at the top of the cdf must not pick a component of probability 0
        zero = some & (p[k, cols] == 0)
        if zero.any():
            last = len(p) - 1 - np.argmax((p > 0)[::-1], axis=0)
            k = np.where(zero, last, k)
        lower = np.where(k > 0, cdf[np.maximum(k - 1, 0), cols], 0.0)
        p_k = p[k, cols]
        u_rest = np.clip((u_lobe - lower) / np.where(p_k > 0, p_k, 1.0), 0.0, _BELOW_ONE)

        wi = sp.n_s.copy()
        is_delta, valid = np.zeros(n, bool), np.zeros(n, bool)
        eta_sq, pdf = np.ones(n), np.zeros(n)
        parts = []
        for j, c in enumerate(self.components):
            sel = np.flatnonzero(some & (k == j))
            if not sel.size:
                continue
            bs = c.sample_direction(points[j].take(sel), u_rest[sel], np.take(u_dir, sel, axis=1))
            wi[:, sel] = bs.wi
            is_delta[sel], valid[sel] = bs.is_delta, bs.valid
            if bs.eta_sq is not None:
                eta_sq[sel] = bs.eta_sq
            d = np.flatnonzero(bs.is_delta & bs.valid)
            if d.size:
                ratio = weights[j][sel[d]] / p[j, sel[d]]
                parts.append((sel[d], take_value(bs.weight, d).scaled(ratio[None, :])))
        smooth = np.flatnonzero(valid & ~is_delta)
        if smooth.size:
            shared = {}         # (the components' points share the hit's arrays: gathered once)
            sub = sp.take(smooth, shared)
            sub_points = [sub if q is sp else q.take(smooth, shared) for q in points]
            d_sub = np.take(wi, smooth, axis=1)
            if weighted:        # the components' values and densities at once (the same numbers)
                value, density = self._sum_and_pdf(sub, sub_points, [w[smooth] for w in weights], p[:, smooth],
                                                   d_sub, cosine=True)
            else:
                density = self._pdf(sub_points, p[:, smooth], d_sub)
            good = density > 0
            valid[smooth] = good
            pdf[smooth] = density
            if weighted:
                value = value.scaled(np.where(good, 1.0 / np.where(good, density, 1.0), 0.0)[None, :])
                parts.append((smooth, value))

        def frames():
            return plane_of_incidence_axis(sp.n_s, -wi), plane_of_incidence_axis(sp.n_s, sp.wo)
        weight = assemble_values(parts, n, L, frames) if parts or weighted else None
        return BSDFSample(wi=wi, weight=weight, pdf=pdf, is_delta=is_delta & valid, valid=valid, eta_sq=eta_sq)

    def delta_reflection(self, sp: ShadingPoint) -> MuellerValue | None:
        points, weights = self._points(sp), self._weights_at(sp)
        terms = []
        for c, q, w in zip(self.components, points, weights):
            if not c.flags.has(BSDFFlags.DELTA_REFLECTION) or not w.any():
                continue
            value = c.delta_reflection(q)
            if value is None:
                continue
            if q is not sp:         # its own normal: its mirror direction is another one, except where n_k = ±n_s
                same = np.minimum(np.max(np.abs(q.n_s - sp.n_s), axis=0), np.max(np.abs(q.n_s + sp.n_s), axis=0))
                w = w * (same <= 1e-12)
            terms.append((w, value))
        if not terms:
            return None
        wi = reflect(sp.wo, sp.n_s)
        return add_values(terms, sp.n, sp.lam.shape[0], -wi, sp.wo, sp.n_s)

    def describe(self) -> dict:
        return {"type": self.name, "materials": [c.describe() for c in self.components],
                "weights": [w if isinstance(w, float) else repr(w) for w in self.weights]}


# --------------------------------------------------------------------------- declaration

#: One weight of a mix (the declaration of each element of ``weights``).
WEIGHT = Parameter("weight", "one material's weight w_k", lo=0.0, texturable=True)

DECLARATION = ModelDeclaration(
    "mix", "Mix",
    "An incoherent mixture f = Σ w_k·f_k of materials (Blender's Mix Shader: weights 1 − fac, fac; "
    "Add Shader: 1, 1)",
    [Parameter("materials", "the mixed materials, inline or by name (nested mixes are flattened)",
               kind="materials"),
     Parameter("weights", "one weight w_k ≥ 0 per material, in the same order; not normalised (a sum above 1 "
                          "adds light, as Add Shader)", kind="numbers", element=WEIGHT)],
    catalogue=None, node=None)      # not a Polarising BSDF model: Blender's own Mix/Add Shader nodes make it


DECLARATION.per_point = frozenset({"weights"})


def map_normals(bsdf: BSDF, **kw) -> BSDF:
    """``bsdf`` with a normal and/or bump map (ShadingNormal's keywords), mapped lobe by lobe as Cycles maps
    each closure of a shader: a mix (a layered one included) maps each of its components and keeps its
    weights and layering; a model with a diffuse base under a specular layer that it can split into those
    two (``as_layers()``, Torrance–Sparrow's "albedo_scaling") is split first, so that the specular layer gets
    the corrected normal and the diffuse base its own rules (engine.materials.normal_map)."""
    if isinstance(bsdf, Mix):
        return bsdf.with_components([map_normals(c, **kw) for c in bsdf.components])
    if hasattr(bsdf, "with_base"):     # a wrapper over a composite (a coat's tint): map what it wraps
        return bsdf.with_base(map_normals(bsdf.base, **kw))
    split = getattr(bsdf, "as_layers", None)
    layered = split() if split is not None else None
    if layered is not None:
        return map_normals(layered, **kw)
    return ShadingNormal(bsdf, **kw)


@DECLARATION.builder
def _mix(p, materials):
    weights = p["weights"]
    if len(weights) != len(materials):
        raise SceneError(p.field("weights"), f"must hold one weight per material: {len(materials)} "
                                             f"material{'s' * (len(materials) != 1)}, got {len(weights)} "
                                             f"weight{'s' * (len(weights) != 1)}")
    try:
        return Mix(materials, weights)
    except ValueError as e:
        raise SceneError(p.field("materials"), str(e)) from None


class Layered(Mix):
    """A top layer over a base, as Cycles layers its closures (``closure_layering_weight``): the top
    weighted ``weight``, everything below weighted max(0, 1 − weight·E_top(ω_o)) on top of its own weights,
    E_top the top layer's directional albedo at the view direction (``albedo(sp)`` → (N,)).  Not
    reciprocal, as Cycles' is; the top's polarisation is its own, the base's light is scaled by a scalar."""

    def __init__(self, top: BSDF, base: BSDF, weight: float, albedo):
        if type(base) is Mix:
            parts, weights = list(base.components), list(base.weights)
        else:
            parts, weights = [base], [1.0]
        weight = weight if isinstance(weight, TexturedNumber) else float(weight)
        super().__init__([top] + parts, [weight] + weights)
        if self.components[0] is not top:
            raise ValueError("a layered material's top layer must have a weight > 0")
        self.top_weight, self.albedo = weight, albedo      # a number or a TexturedNumber (per point)
        self.name = "layered"

    def _weights(self, sp: ShadingPoint) -> list[np.ndarray]:
        weights = super()._weights(sp)
        top = self._points(sp)[0]       # the top's albedo at its own normal (a corrected mapped one: Cycles')
        scale = np.maximum(1.0 - weights[0] * self._top_albedo(top), 0.0)     # the top's weight at each point
        return weights[:1] + [w * scale for w in weights[1:]]

    def _top_albedo(self, top: ShadingPoint):
        """E_top(ω_o) at the top layer's point ``top``, once per batch."""
        return top.memo(self, "top albedo", lambda: self.albedo(top))

    def _estimates(self, points, weights) -> list:
        """w_k·a_k per component: the top layer's a is its albedo E_top(ω_o) (what it takes from the base; Cycles'
        sample weight of that closure, bsdf_microfacet_estimate_albedo: a specular layer of albedo 0.05 over a
        diffuse base is sampled in proportion to that), the others' as in a Mix."""
        raw = super()._estimates(points, weights)
        raw[0] = weights[0] * np.clip(self._top_albedo(points[0]), ALBEDO_FLOOR, 1.0)
        return raw

    def albedo_estimate(self, sp: ShadingPoint) -> np.ndarray:
        """Σ_k w_k·a_k (``_estimates``): how much the layered material reflects at the points, so that a mix over
        it picks it as it would pick its layers flattened (Cycles' closures side by side)."""
        return sum(self._estimates(self._points(sp), self._weights_at(sp)))



def emission_weight(bsdf: BSDF):
    """Cycles' attenuation of a Principled BSDF's own emission by the layers over it (kernel/svm/closure.h:
    "Emission (attenuated by sheen and coat)"): f(cosθ) (N,) = Π over the sheen and coat layers (``Layered`` with
    ``role`` "sheen" or "coat", outermost first) of max(0, 1 − weight·E_layer(θ)), θ the viewing angle from the
    surface normal, E the layer's albedo as it weights what lies below; None where no layer covers the emission.
    Needs layers whose weight and albedo are the same everywhere (else None, and the caller warns); the coat's tint
    is not applied
    to the emission (its layering is).  The layers' normal maps are not seen (the geometric frame)."""
    layers = []
    b = bsdf
    while isinstance(b, Layered) and getattr(b, "role", None) in ("sheen", "coat"):
        if isinstance(b.top_weight, TexturedNumber) or b.components[0].varies_over_surface:
            return None         # (a layer whose weight or albedo varies over the surface: not without its points)
        layers.append(b)
        nxt = b.components[1] if len(b.components) == 2 else None
        b = nxt if getattr(nxt, "role", None) in ("sheen", "coat") else None
    if not layers:
        return None

    def weight(cos_theta: np.ndarray) -> np.ndarray:
        c = np.clip(np.asarray(cos_theta, np.float64), 0.0, 1.0)
        n = c.shape[0]
        wo = np.stack((np.sqrt(np.maximum(1.0 - c * c, 0.0)), np.zeros(n), c))
        up = np.tile(np.array([[0.0], [0.0], [1.0]]), (1, n))
        sp = ShadingPoint(np.zeros((3, n)), up, up, wo, np.full((1, n), 550.0))
        f = np.ones(n)
        for layer in layers:
            f = f * np.maximum(1.0 - layer.top_weight * layer.albedo(sp), 0.0)
        return f
    return weight
