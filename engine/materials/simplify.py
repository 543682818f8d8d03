"""Exact scene reductions of materials: skip Weidlich–Wilkie coats that are index-matched and clear.

``simplify_material(bsdf) -> (bsdf', reasons)``.  A WeidlichWilkie coat whose real index n equals
the index of the medium directly above it (``exterior_n`` for the top coat, the coat above
otherwise) at every wavelength — relative index η = n/n_above ≡ 1 (dimensionless) — and whose
optical depth α·d (absorption per unit length × thickness, dimensionless) is 0 at every
wavelength has no interface and no absorption; the stack without it is the same BSDF (Mueller
values in the docs/physics.md §0 frames and conventions; the sampled estimator f·cosθ_i/pdf has the
same expectation, though the proposal density ``pdf`` may differ: the reduced material uses its
own sampler).  If every coat goes, the result is the base as it was configured inside the stack,
i.e. seeing the same exterior index as before (``match_base_exterior``).

"Same" is exact in the physics; numerically the stack refracts through η = 1 with
cosθ' = √(1 − (1 − cos²θ)) and evaluates F(η = 1) ≈ 1e-23 instead of 0, so it agrees with the reduced
material to ~1e-14 relative to M00 away from the horizon and ~1e-16/cos²θ near it; within ~1e-8 rad of
the horizon the stack's η = 1 Fresnel rounds to a perfect mirror (the reduced material is then the
correct one).

Comparisons are exact (no tolerance): constant spectra by value, tables and RGB spectra by their
sample values, and the monochrome value too.  The input is never modified; a reduced material is
a new WeidlichWilkie with the same options, built on the same Coat objects.

Not every matched, clear coat can go: the WeidlichWilkie code treats a sub-stack differently
from a bare base in two places, and a coat is kept where removing it would change the BSDF:

- a *rough* coat has no Dirac lobe and drops the Dirac lobe of whatever lies below it (a smooth
  coat, HTSG's specular term, a mirror with diffuse); it is kept if the layer below may have one;
- in the energy form the internal-reflection factor c_ms is applied only when a coat sits
  directly on a base with a diffuse (depolarising) share, never to a sub-stack; a matched lowest
  coat between another coat and such a base is kept (and a WW base of an energy-form stack with
  such a base is not reduced to that bare base).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from ..spectral import LAMBDA_MAX, LAMBDA_MIN
from ..spectral.spectrum import (
    ConstantSpectrum,
    RGBIlluminantSpectrum,
    RGBReflectanceSpectrum,
    RGBUnboundedSpectrum,
    Spectrum,
    TabulatedSpectrum,
)
from .base import BSDF, BSDFFlags
from .weidlich_wilkie import Coat, WeidlichWilkie, _spectrum_range

__all__ = ["index_matched_and_clear", "same_spectrum", "simplify_material"]


# ------------------------------------------------------------------------------------------------
# Exact spectrum predicates
# ------------------------------------------------------------------------------------------------

def _constant_value(spec: Spectrum) -> float | None:
    """v if ``spec`` evaluates to exactly v at every rendered wavelength (eval and eval_cached), else None."""
    if isinstance(spec, ConstantSpectrum):
        return spec.value
    if isinstance(spec, (RGBReflectanceSpectrum, RGBUnboundedSpectrum)) and spec.is_constant:
        return float(spec.rgb[0])
    if isinstance(spec, TabulatedSpectrum) and spec.is_constant:
        lo, hi = spec.range_nm  # outside its range a table raises: only then is it a true constant
        return float(spec.values[0]) if lo <= LAMBDA_MIN and hi >= LAMBDA_MAX else None
    if isinstance(spec, RGBIlluminantSpectrum) and spec.is_constant:
        return 0.0
    return None


def same_spectrum(a: Spectrum, b: Spectrum) -> bool:
    """True if a and b give bit-identical values at every wavelength and in monochrome mode."""
    if a is b:
        return True
    ca, cb = _constant_value(a), _constant_value(b)
    if ca is not None or cb is not None:
        return ca is not None and cb is not None and ca == cb and a.mono_value == b.mono_value
    if isinstance(a, (RGBReflectanceSpectrum, RGBUnboundedSpectrum)) and \
            isinstance(b, (RGBReflectanceSpectrum, RGBUnboundedSpectrum)):
        return bool(np.array_equal(a.rgb, b.rgb))          # same basis code, same mono (luminance)
    if isinstance(a, RGBIlluminantSpectrum) and isinstance(b, RGBIlluminantSpectrum):
        return bool(np.array_equal(a.rgb, b.rgb)) and a.scale == b.scale
    if isinstance(a, TabulatedSpectrum) and isinstance(b, TabulatedSpectrum):
        return (bool(np.array_equal(a.wavelengths, b.wavelengths) and np.array_equal(a.values, b.values))
                and a.mono_value == b.mono_value)
    return False


def _is_zero(spec: Spectrum) -> bool:
    return _constant_value(spec) == 0.0 and spec.mono_value == 0.0


def _is_finite(spec: Spectrum) -> bool:
    c = _constant_value(spec)
    if c is not None:
        return math.isfinite(c) and math.isfinite(spec.mono_value)
    # RGB and table spectra reject non-finite input; other kinds: not known to be finite.
    return isinstance(spec, (RGBReflectanceSpectrum, RGBUnboundedSpectrum, RGBIlluminantSpectrum,
                             TabulatedSpectrum))


def _clear(coat: Coat) -> bool:
    """α·d ≡ 0: zero thickness (with a finite α) or zero absorption."""
    if coat.thickness == 0.0:
        return _is_finite(coat.absorption_spectrum)
    return _is_zero(coat.absorption_spectrum)


def index_matched_and_clear(coat: Coat, n_above: Spectrum) -> bool:
    """The coat's n equals n_above exactly (η ≡ 1) and its optical depth α·d is exactly 0."""
    return same_spectrum(coat.n_spectrum, n_above) and _clear(coat)


def _show(spec: Spectrum) -> str:
    c = _constant_value(spec)
    return repr(c) if c is not None else repr(spec)


# ------------------------------------------------------------------------------------------------
# What a coat's level shows to the level above (see the WeidlichWilkie code), read from its flags
# (a model without its own flags is assumed to have every lobe: conservative, the coat is kept).
# Stacks are recognised by their class (WeidlichWilkie) only to recurse into their structure.
# ------------------------------------------------------------------------------------------------

def _has_dirac(b: BSDF) -> bool:
    """The BSDF has a Dirac reflection lobe (``delta_reflection``); a stack has one iff its top coat is smooth."""
    return b.flags.has(BSDFFlags.DELTA_REFLECTION)


def _diffuse(b: BSDF) -> bool:
    """``eval`` returns a depolarising value or ABCS ``depol`` share for its diffuse lobes (c_ms applies)."""
    return b.flags.has(BSDFFlags.SEPARABLE_DIFFUSE)


def _levels(w: WeidlichWilkie) -> list[WeidlichWilkie]:
    """The WeidlichWilkie of every coat (levels[k] has coats[k:]); levels[-1].base is the base."""
    out = [w]
    while len(out[-1].coats) > 1:
        out.append(out[-1].base)
    return out


def _options(w: WeidlichWilkie) -> dict:
    levels = _levels(w)
    explicit = any(lv.w_c != WeidlichWilkie.default_layer_cosine_fraction(lv.base) for lv in levels)
    return {"form": w.form, "t_term": w.t_term, "transmission_normal": w.transmission_normal,
            "shadowing": w.shadowing, "match_base_exterior": w.match_base_exterior,
            "layer_cosine_fraction": w.w_c if explicit else None}


@dataclass(frozen=True)
class _Parent:
    """The stack whose base is being simplified: its form and how it configures its base."""

    form: str
    match: bool
    coat_n: Spectrum          # index of the parent's lowest coat (invariant under its own reductions)

    def accepts_bare(self, b: BSDF) -> bool:
        """Would the parent's lowest coat over ``b`` behave exactly as over the stack ``b`` replaces?"""
        if self.form == "energy" and _diffuse(b):
            return False
        if self.match and hasattr(b, "exterior_n"):
            if isinstance(b, WeidlichWilkie):
                return same_spectrum(b.exterior_n, self.coat_n)
            lo, hi = _spectrum_range(self.coat_n)
            return lo == hi and float(b.exterior_n) == float(lo)
        return True


def _same_exterior(a: BSDF, b: BSDF) -> bool:
    ea, eb = getattr(a, "exterior_n", None), getattr(b, "exterior_n", None)
    if ea is None or eb is None:
        return ea is None and eb is None
    if isinstance(ea, Spectrum) or isinstance(eb, Spectrum):
        return isinstance(ea, Spectrum) and isinstance(eb, Spectrum) and same_spectrum(ea, eb)
    return float(ea) == float(eb)


# ------------------------------------------------------------------------------------------------
# The reduction
# ------------------------------------------------------------------------------------------------

def _removable(j: int, coats: list[Coat], base: BSDF, form: str, parent: _Parent | None) -> str | None:
    """None if removing coats[j] (matched and clear) leaves the BSDF unchanged, else why not."""
    K = len(coats)
    below_dirac = coats[j + 1].smooth if j + 1 < K else _has_dirac(base)
    if not coats[j].smooth and below_dirac:
        return "rough coat hides the Dirac lobe below it"
    if j == K - 1 and K >= 2 and form == "energy" and _diffuse(base):   # never for a stack base
        return "energy form: the coat above would gain the internal-reflection factor"
    if K == 1 and parent is not None and not parent.accepts_bare(base):
        return "the enclosing stack would treat the bare base differently"
    return None


def _simplify_ww(w: WeidlichWilkie, label: str, parent: _Parent | None) -> tuple[BSDF, list[str]]:
    coats = list(w.coats)
    levels = _levels(w)
    base = levels[-1].base
    ext = w.exterior_n
    reasons: list[str] = []
    changed = False

    if isinstance(base, WeidlichWilkie):
        new_base, sub = _simplify_ww(base, f"the base of {label}",
                                     _Parent(w.form, w.match_base_exterior, coats[-1].n_spectrum))
        if new_base is not base:
            base, changed = new_base, True
            reasons += sub

    numbers = list(range(1, len(coats) + 1))   # 1-based positions in the input stack, top first
    progress = True
    while progress and coats:
        progress = False
        for j in range(len(coats)):
            above = ext if j == 0 else coats[j - 1].n_spectrum
            if not index_matched_and_clear(coats[j], above):
                continue
            if _removable(j, coats, base, w.form, parent) is not None:
                continue
            where = "medium above" if j == 0 else f"coat {numbers[j - 1]} above"
            reasons.append(f"coat {numbers[j]} of {label} is index-matched (n = {_show(coats[j].n_spectrum)} = "
                           f"{where}) and clear (absorption·thickness = 0): skipped")
            del coats[j], numbers[j]
            changed = progress = True
            break

    if not changed:
        return w, []
    if not coats:
        out = copy.copy(base)
        reasons.append(f"{label} has no coat left: it is its base "
                       f"({getattr(base, 'name', type(base).__name__)}, as configured inside the stack)")
        return out, reasons
    try:
        new = WeidlichWilkie(coats, base, exterior_n=ext, **_options(w))
    except ValueError:
        return w, []
    if not _same_exterior(_levels(new)[-1].base, base):   # safety net: the base must see what it saw
        return w, []
    return new, reasons


def simplify_material(bsdf: BSDF, name: str | None = None) -> tuple[BSDF, list[str]]:
    """Skip index-matched, clear WeidlichWilkie coats (recursively into WW bases); exact, no tolerance.

    Returns (material, reasons): the input object itself and [] if nothing can be skipped (always
    for a non-WeidlichWilkie material), otherwise a new equivalent material (a WeidlichWilkie
    with the remaining coats and the same options, or the configured base) and one human-readable
    line per reduction.  ``name`` (e.g. the scene's material name) only labels the reasons.
    The input is never modified.
    """
    if not isinstance(bsdf, WeidlichWilkie):
        return bsdf, []
    label = f"'{name}'" if name else f"'{bsdf.name}'"
    return _simplify_ww(bsdf, label, None)
