"""Material models by name, built from flat ``NAME=VALUE`` parameters.

This is how ``python -m engine mueller`` (and the oracle tests) instantiate a
model in isolation.  Scene files use the richer JSON form of
engine.scene.loader, which builds the same classes.
"""

from __future__ import annotations

import math

from .conductor import SmoothConductor
from .lambert import Lambert
from .htsg import HTSG
from .smooth_limit import MirrorWithDiffuse
from .torrance_sparrow import TorranceSparrow
from .weidlich_wilkie import Coat, WeidlichWilkie
from ..errors import SceneError
from ..spectral import ConstantSpectrum, named_ior

#: model name → {parameter: (default, description)}
MODEL_PARAMETERS = {
    "lambert": {"albedo": (0.8, "albedo ρ in [0, 1]; BRDF ρ/π")},
    "fresnel": {"n": (None, "real part of the complex index, > 0 (or metal=Au|Ag|Al|Cu|Cr)"),
                "k": (0.0, "imaginary part κ ≥ 0"),
                "metal": (None, "named measured metal instead of n, k"),
                "exterior_n": (1.0, "index of the incident medium, > 0")},
    "torrance_sparrow": {"n": (None, "real part of the complex index, > 0 (or metal=NAME)"),
                         "k": (0.0, "imaginary part κ ≥ 0"),
                         "metal": (None, "named measured metal instead of n, k"),
                         "m": (None, "Beckmann rms slope: 0 (smooth limit: Fresnel mirror) or ≥ 1e-4 "
                                     "(= Mitsuba α, SCATMECH s)"),
                         "shadowing": ("ts", "ts (V-cavity) | smith | smith_rational (Mitsuba) | none"),
                         "diffuse_albedo": (0.0, "albedo of the added Lambertian part, [0, 1]"),
                         "diffuse_weight": (0.0, "weight d of the Lambertian part, ≥ 0"),
                         "specular_weight": (1.0, "weight s of the facet part, ≥ 0"),
                         "exterior_n": (1.0, "index of the incident medium, > 0")},
    "htsg": {"n": (None, "real part of the complex index, > 0 (or metal=NAME)"),
             "k": (0.0, "imaginary part κ ≥ 0"),
             "metal": (None, "named measured metal instead of n, k"),
             "sigma0_um": (None, "rms surface height σ₀ in µm, ≥ 0"),
             "tau_um": (None, "autocorrelation length τ in µm, > 0"),
             "albedo": (0.0, "albedo of the uniform diffuse (depolarising) term, [0, 1]"),
             "exterior_n": (1.0, "index of the incident medium, > 0")},
    "weidlich_wilkie": {"coat_n": (1.5, "index of the coat, > 0"),
                        "coat_thickness": (0.0, "coat thickness d (only absorption·d matters), ≥ 0"),
                        "coat_absorption": (0.0, "absorption coefficient per unit thickness, ≥ 0"),
                        "coat_distribution": ("smooth", "smooth | blinn | beckmann"),
                        "coat_exponent": (None, "Blinn–Phong exponent e > 0 (coat_distribution=blinn)"),
                        "coat_m": (None, "Beckmann rms slope ≥ 1e-4 (coat_distribution=beckmann)"),
                        "base_albedo": (0.8, "albedo of the Lambertian base, [0, 1]"),
                        "t_term": ("ww", "ww (1 − F21·G) | t21 (1 − F21); published form only"),
                        "transmission_normal": (None, "facet | macro (default: facet for published, "
                                                      "macro for energy)"),
                        "form": ("energy", "energy (default, energy conserving) | published | first_order")},
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
    if name == "weidlich_wilkie":
        return _weidlich_wilkie(params, field)
    n, k = _index(params, field)
    if name == "fresnel":
        return SmoothConductor(n, k, ext)
    if name == "htsg":
        for key in ("sigma0_um", "tau_um"):
            if key not in params:
                raise SceneError(f"{field}.{key}", "is required")
        return HTSG(n, k, _float(params, "sigma0_um", field, 0.0, hi=1e4),
                    _float(params, "tau_um", field, 0.0, lo_open=True, hi=1e6),
                    albedo=_float(params, "albedo", field, 0.0, hi=1.0) if "albedo" in params else 0.0,
                    exterior_n=ext)
    if "m" not in params:
        raise SceneError(f"{field}.m", "is required: the Beckmann rms slope, ≥ 1e-4")
    shadowing = params.get("shadowing", "ts")
    if shadowing not in ("ts", "smith", "smith_rational", "none"):
        raise SceneError(f"{field}.shadowing", f"must be one of ts, smith, smith_rational, none, got {shadowing!r}")
    opt = lambda key, lo, hi, default: _float(params, key, field, lo, hi=hi) if key in params else default  # noqa: E731
    albedo = opt("diffuse_albedo", 0.0, 1.0, 0.0)
    m = _float(params, "m", field, 0.0, hi=100.0)
    if 0 < m < 1e-4:
        raise SceneError(f"{field}.m", f"must be 0 (the smooth limit) or in [0.0001, 100], got {m:g}")
    if m == 0:
        return MirrorWithDiffuse(n, k, exterior_n=ext, diffuse_albedo=ConstantSpectrum(albedo),
                                 diffuse_weight=opt("diffuse_weight", 0.0, math.inf, 0.0),
                                 specular_weight=opt("specular_weight", 0.0, math.inf, 1.0))
    return TorranceSparrow(n, k, m, shadowing=shadowing, exterior_n=ext,
                           diffuse_albedo=ConstantSpectrum(albedo), diffuse_weight=opt("diffuse_weight", 0.0,
                                                                                         math.inf, 0.0),
                           specular_weight=opt("specular_weight", 0.0, math.inf, 1.0))


def _choice(params, key, field, allowed, default):
    value = params.get(key, default)
    if value not in allowed:
        raise SceneError(f"{field}.{key}", f"must be one of {', '.join(a for a in allowed if a)}, got {value!r}")
    return value


def _weidlich_wilkie(params, field):
    """One coat over a Lambertian base, with the oracle's options."""
    dist = _choice(params, "coat_distribution", field, ("smooth", "blinn", "beckmann"), "smooth")
    coat_kw = {}
    if dist == "blinn":
        if "coat_exponent" not in params:
            raise SceneError(f"{field}.coat_exponent", "is required for coat_distribution=blinn (> 0)")
        coat_kw["exponent"] = _float(params, "coat_exponent", field, 0.0, lo_open=True, hi=1e7)
    elif dist == "beckmann":
        if "coat_m" not in params:
            raise SceneError(f"{field}.coat_m", "is required for coat_distribution=beckmann (≥ 1e-4)")
        coat_kw["m"] = _float(params, "coat_m", field, 1e-4, hi=100.0)
    opt = lambda key, lo, hi, default: _float(params, key, field, lo, hi=hi) if key in params else default  # noqa: E731
    coat = Coat(n=opt("coat_n", 1e-6, 100.0, 1.5), thickness=opt("coat_thickness", 0.0, math.inf, 0.0),
                absorption=opt("coat_absorption", 0.0, math.inf, 0.0), distribution=dist, **coat_kw)
    form = _choice(params, "form", field, ("energy", "published", "first_order"), "energy")
    normal = _choice(params, "transmission_normal", field, (None, "facet", "macro"), None)
    if form == "energy" and normal == "facet":
        raise SceneError(f"{field}.transmission_normal", "the energy-conserving form refracts through the macro "
                                                         "normal: use macro (or form=published)")
    base = Lambert(ConstantSpectrum(opt("base_albedo", 0.0, 1.0, 0.8)))
    return WeidlichWilkie([coat], base, form=form, t_term=_choice(params, "t_term", field, ("ww", "t21"), "ww"),
                          transmission_normal=normal)


def _index(params, field):
    """(n, k) spectra from n= and k= or from metal=NAME."""
    if "metal" in params:
        if "n" in params or "k" in params:
            raise SceneError(f"{field}.metal", "give either metal or n and k, not both")
        return named_ior(params["metal"], field=f"{field}.metal")
    if "n" not in params:
        raise SceneError(f"{field}.n", "is required (or give metal=NAME)")
    n = _float(params, "n", field, 0.0, lo_open=True)
    k = _float(params, "k", field, 0.0) if "k" in params else 0.0
    return ConstantSpectrum(n), ConstantSpectrum(k)
