"""The engine's one rule for microfacet roughness: the least slope of a rough lobe and when a roughness is smooth.

Every microfacet model (Torrance–Sparrow, the Weidlich–Wilkie coat, the rough dielectric, the anisotropic GGX
of the Principled BSDF) takes its roughness α (the Beckmann rms slope m or the GGX α, the same number for
both) through these names, as pbrt-v4's ``TrowbridgeReitzDistribution::EffectivelySmooth``:

- a constant α below ``SMOOTH_LIMIT`` is **effectively smooth**: the declaration builds the model's smooth
  limit (a Fresnel mirror, the smooth dielectric, a smooth coat) — for a scene file and for Blender alike;
- a rough lobe has α ≥ ``ALPHA_MIN``; a roughness that varies over the surface (a texture) has no per-point
  smooth limit: its values must be ≥ ``ALPHA_MIN`` everywhere (a float32 texel one rounding below counts as
  the limit);
- Blender's roughness r gives α = r² (Cycles'); ``ROUGHNESS_MIN`` is the least r whose square, as float32,
  is ≥ ``ALPHA_MIN`` (the exporter keeps roughness texels ≥ it).

``SMOOTH_LIMIT`` equals ``ALPHA_MIN`` (pbrt puts its smooth limit at 1e-3, above its least α 1e-4; here the
GGX lobes are exact down to 1e-4, as Cycles', so every α a rough lobe can take is rendered rough).  The
declarations range-check a roughness once, where they build the model (engine.materials.parameters); the
constructors' :func:`checked_alpha` is a cheap guard for their direct (public API) use.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SceneError
from ..textures import TexturedNumber

#: Least microfacet roughness (Beckmann rms slope m or GGX α) of a rough lobe.
ALPHA_MIN = 1e-4
#: A constant roughness below this renders the model's smooth limit (the same number as ALPHA_MIN).
SMOOTH_LIMIT = ALPHA_MIN
#: Least Blender roughness r (α = r²) of a rough lobe: the float32 nearest √ALPHA_MIN whose square is ≥ ALPHA_MIN.
ROUGHNESS_MIN = float(np.nextafter(np.float32(math.sqrt(ALPHA_MIN)), np.float32(1)))


def effectively_smooth(*alphas) -> bool:
    """True where a constant roughness (or the largest of α_x, α_y) is below SMOOTH_LIMIT: the smooth model
    renders it.  A roughness that varies over the surface (a TexturedNumber) is never smooth."""
    if any(isinstance(a, TexturedNumber) for a in alphas):
        return False
    return max(float(a) for a in alphas) < SMOOTH_LIMIT


def declared_slope(values, name: str):
    """(α, smooth) of a declared roughness parameter ``name`` of engine.materials.parameters.Values — the one
    range check of a roughness on its way to a model: a constant (already within the declared range, ≥ 0) is
    smooth below SMOOTH_LIMIT; a texture is kept ≥ ALPHA_MIN where it is below only by float32 rounding and
    refused (SceneError) where it reaches further below (no per-point smooth limit)."""
    alpha = values[name]
    if not isinstance(alpha, TexturedNumber):
        return alpha, effectively_smooth(alpha)
    alpha = alpha.clamped_to(ALPHA_MIN)
    if not alpha.lo >= ALPHA_MIN:
        hi = values.model[name].hi
        raise SceneError(values.field(name), f"a roughness texture must stay in [{ALPHA_MIN:g}, {hi:g}] (the smooth "
                                             f"limit cannot vary per point), its values reach {alpha.lo:g}")
    return alpha, False


def checked_alpha(alpha, name: str = "roughness alpha"):
    """A rough lobe's roughness for a model constructor: a TexturedNumber as given, a number as float; finite and
    ≥ ALPHA_MIN everywhere, else ValueError (the constructors' guard for direct use: the declarations check first)."""
    textured = isinstance(alpha, TexturedNumber)
    lo, hi = (alpha.lo, alpha.hi) if textured else (float(alpha),) * 2
    if not (math.isfinite(lo) and math.isfinite(hi) and lo >= ALPHA_MIN):
        raise ValueError(f"{name} must be a finite number >= {ALPHA_MIN:g}, got {alpha!r}")
    return alpha if textured else lo
