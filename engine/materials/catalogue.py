"""Material models by name, built from flat ``NAME=VALUE`` parameters.

This is how ``python -m engine mueller`` (and the oracle tests) instantiate a
model in isolation.  Scene files use the richer JSON form of
engine.scene.loader, which builds the same classes.
"""

from __future__ import annotations

import math

from .conductor import SmoothConductor
from .lambert import Lambert
from ..scene.errors import SceneError
from ..spectral import ConstantSpectrum, named_ior

#: model name → {parameter: (default, description)}
MODEL_PARAMETERS = {
    "lambert": {"albedo": (0.8, "albedo ρ in [0, 1]; BRDF ρ/π")},
    "fresnel": {"n": (None, "real part of the complex index, > 0 (or metal=Au|Ag|Al|Cu|Cr)"),
                "k": (0.0, "imaginary part κ ≥ 0"),
                "metal": (None, "named measured metal instead of n, k"),
                "exterior_n": (1.0, "index of the incident medium, > 0")},
}


def _float(params, key, field, lo, lo_open=False, hi=math.inf):
    raw = params[key]
    try:
        v = float(raw)
    except (TypeError, ValueError):
        raise SceneError(f"{field}.{key}", f"must be a number, got {raw!r}") from None
    if not math.isfinite(v) or v < lo or (lo_open and v == lo) or v > hi:
        rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
        raise SceneError(f"{field}.{key}", f"must be a finite number in {rng}, got {raw!r}")
    return v


def make_model(name: str, params: dict, field: str = "param"):
    """A BSDF instance of model ``name`` with string or numeric parameters."""
    if name not in MODEL_PARAMETERS:
        raise SceneError("model", f"unknown model {name!r} (available: {', '.join(MODEL_PARAMETERS)})")
    unknown = sorted(set(params) - set(MODEL_PARAMETERS[name]))
    if unknown:
        raise SceneError(f"{field}.{unknown[0]}",
                         f"is not a parameter of {name} (parameters: {', '.join(MODEL_PARAMETERS[name])})")
    if name == "lambert":
        albedo = _float(params, "albedo", field, 0.0, hi=1.0) if "albedo" in params else 0.8
        return Lambert(ConstantSpectrum(albedo))
    ext = _float(params, "exterior_n", field, 0.0, lo_open=True) if "exterior_n" in params else 1.0
    if "metal" in params:
        if "n" in params or "k" in params:
            raise SceneError(f"{field}.metal", "give either metal or n and k, not both")
        n, k = named_ior(params["metal"], field=f"{field}.metal")
        return SmoothConductor(n, k, ext)
    if "n" not in params:
        raise SceneError(f"{field}.n", "is required (or give metal=NAME)")
    n = _float(params, "n", field, 0.0, lo_open=True)
    k = _float(params, "k", field, 0.0) if "k" in params else 0.0
    return SmoothConductor(ConstantSpectrum(n), ConstantSpectrum(k), ext)
