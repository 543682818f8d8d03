"""Blender's Principled BSDF as Cycles composes it, from polarising parts (one declaration, the scene
format's ``"type": "principled"``; the Blender exporter fills it from the node's sockets).

Cycles' layer order (kernel/svm/closure.h as shipped in bpy): the metal weighted ``metallic``; of the rest,
the transmission weighted ``transmission``; the rest the opaque dielectric — its specular layer over the
diffuse base, the base weighted by one minus the specular layer's albedo at the view direction
(``closure_layering_weight``), or a coat over them.  Here:

- weights: an engine Mix (engine.materials.mix) of metal, transmission and dielectric with the per-point
  weights metallic, (1 − metallic)·transmission, (1 − metallic)(1 − transmission) (nested mixes);
- metal: a GGX Torrance–Sparrow conductor (α = roughness², Cycles' height-correlated G, ``multiscatter``
  for ``distribution`` "multi_ggx"; anisotropic GGX for ``anisotropic`` > 0) whose complex index per
  wavelength and point reflects the base colour at 0° and Cycles' F82-Tint value at θ₈₂
  (engine.spectral.gulbrandsen), its unpolarised reflectance rescaled to Cycles' F82-Tint curve at every facet
  angle (engine.materials.tinted.F82Reflectance); under a thin film (``thin_film_thickness`` > 0, rough or
  smooth) Cycles' own index estimate filmed by Airy's sum instead;
- transmission: the smooth dielectric at roughness 0 (with a film the thin-film dielectric), else the GGX
  rough dielectric (compensated for "multi_ggx"; a roughness texture gives its α = r² per point; a film on every
  facet), each refraction
  tinted by √(base colour) and the glass's Fresnel by Specular Tint (engine.materials.tinted);
- dielectric: a GGX Torrance–Sparrow dielectric (index from ``ior`` and ``specular_ior_level``: F0 =
  F0(ior)·2·level, per point through engine.textures.inputs.NumberSpectrum, beside a Specular Tint or an
  anisotropy too; a thin film on it as on the
  metal) with the albedo-scaled Lambertian (or Oren–Nayar) base, its smooth limit at roughness 0;
- coat: a GGX dielectric reflection of ``coat_ior`` and α = coat_roughness² (compensated, as Cycles
  always compensates its coat) over everything below — metal, transmission and dielectric — which is
  weighted by 1 − coat_weight·E_coat(ω_o) (engine.materials.mix.Layered: Cycles' layering) and seen
  through ``coat_tint``; sheen (engine.materials.sheen) over everything, layered the same way; the
  emission under both (engine.materials.mix.emission_weight).
Every parameter in ``DECLARATION.per_point`` may vary per point (textures, colour attributes, baked graphs);
the rest are constants, and inputs of Blender's node that are not parameters here (subsurface, newer
Blenders' inputs) are the exporter's to warn about.
"""

from __future__ import annotations

import math

import numpy as np

from . import conductor, torrance_sparrow
from .base import BSDF
from .mix import Mix
from .parameters import ModelDeclaration, Parameter
from .roughness import ALPHA_MIN, effectively_smooth
from ..errors import SceneError
from ..spectral import ConstantSpectrum, RGBUnboundedSpectrum
from ..spectral.gulbrandsen import GulbrandsenIndex
from ..textures import TexturedNumber, TexturedSpectrum, TextureInput

__all__ = ["DECLARATION", "IOR_MIN", "WEIGHT_CUTOFF", "specular_ior"]

#: Cycles' least index (svm closure: ior = max(IOR, 1e-5))
IOR_MIN = 1e-5
#: Cycles drops closures whose weight is below this (CLOSURE_WEIGHT_CUTOFF)
WEIGHT_CUTOFF = 1e-5
DISTRIBUTIONS = ("multi_ggx", "ggx")


def specular_ior(ior: float, level: float) -> float:
    """Cycles' Specular IOR Level: F0 = F0(IOR)·2·level, the index of that F0 (F0 ≤ 0.99; reciprocal
    below 1)."""
    if level == 0.5:
        return ior
    f0 = min(((ior - 1.0) / (ior + 1.0)) ** 2 * 2.0 * level, 0.99)
    root = math.sqrt(f0)
    eta = (1.0 + root) / (1.0 - root)
    return 1.0 / eta if ior < 1.0 else eta


def _specular_index(ior: float, level):
    """The dielectric's index for a Specular IOR Level that varies over the surface (a TexturedNumber): per point
    the index of F0 = F0(IOR)·2·level (``specular_ior``'s rule), a NumberSpectrum; bounds from the level's."""
    from ..textures.inputs import NumberSpectrum
    f0_ior = ((ior - 1.0) / (ior + 1.0)) ** 2

    def index(x):
        root = np.sqrt(np.minimum(f0_ior * 2.0 * np.clip(x, 0.0, 1.0), 0.99))
        eta = (1.0 + root) / (1.0 - root)
        return 1.0 / eta if ior < 1.0 else eta
    ends = sorted(float(index(np.array(v))) for v in (level.lo, level.hi))
    return NumberSpectrum(level, index, ends[0], ends[1])


def _ior_index(ior, level):
    """The dielectric's index for an IOR that varies over the surface (a TexturedNumber, every value on one side of
    1) and a Specular IOR Level, constant or per point too (a TexturedNumber): per point ``specular_ior``'s rule, a
    NumberSpectrum."""
    from ..textures.inputs import MappedNumbers, NumberSpectrum

    def index_of(x, lv):
        x = np.maximum(x, IOR_MIN)
        root = np.sqrt(np.minimum(((x - 1.0) / (x + 1.0)) ** 2 * 2.0 * np.clip(lv, 0.0, 1.0), 0.99))
        eta = (1.0 + root) / (1.0 - root)
        return np.where(x < 1.0, 1.0 / eta, eta)
    if not _textured(level):
        def index(x):
            return index_of(x, level)
        ends = sorted(float(index(np.array(v))) for v in (ior.lo, ior.hi))
        return NumberSpectrum(ior, index, ends[0], ends[1])
    # both per point: the index is monotone in each (away from 1 as |IOR − 1| and the level grow), so its bounds are
    # among the four corners
    corners = [float(index_of(np.array(x), np.array(lv))) for x in (ior.lo, ior.hi) for lv in (level.lo, level.hi)]
    both = MappedNumbers((ior, level), index_of, min(corners), max(corners))
    return NumberSpectrum(both, lambda v: v, min(corners), max(corners))


def _glass_index(ior):
    """The transmission's index for an IOR that varies over the surface (a TexturedNumber, every value on one side
    of 1): max(IOR, IOR_MIN) per point (Cycles' clamp), a NumberSpectrum (the Specular IOR Level changes only the
    specular layer's index, as in Cycles)."""
    from ..textures.inputs import NumberSpectrum

    def index(x):
        return np.maximum(x, IOR_MIN)
    return NumberSpectrum(ior, index, max(ior.lo, IOR_MIN), max(ior.hi, IOR_MIN))


def _textured(v) -> bool:
    return isinstance(v, (TexturedNumber, TexturedSpectrum))


def _never(x) -> bool:
    """A weight that is 0 everywhere (a texture whose largest value is below the cutoff included)."""
    return (x.hi if _textured(x) else x) < WEIGHT_CUTOFF


def _always(x) -> bool:
    """A weight that is 1 everywhere (a texture whose least value is above 1 − the cutoff included)."""
    return (x.lo if _textured(x) else x) > 1.0 - WEIGHT_CUTOFF


def _complement(x):
    """1 − x of a weight (a number or a TexturedNumber in [0, 1])."""
    if not _textured(x):
        return 1.0 - x
    src = x.source
    if src.power != 1.0:
        raise SceneError("principled", "a textured weight must map its texels linearly (power 1)")
    return TexturedNumber(TextureInput(src.texture, src.channel, -src.scale, 1.0 - src.offset), clip=(0.0, 1.0))


def _mixture(under, over, fraction):
    """``under`` weighted 1 − fraction plus ``over`` weighted fraction (None where weightless)."""
    if over is None or _never(fraction):
        return under
    if under is None or _always(fraction):
        return over
    return Mix([under, over], [_complement(fraction), fraction])


def _alpha_of(roughness):
    """α = r² of a roughness (a number, or a TexturedNumber whose texture is squared after interpolation,
    kept ≥ the engine's least slope roughness.ALPHA_MIN)."""
    if not _textured(roughness):
        return roughness * roughness
    src = roughness.source
    if src.scale != 1.0 or src.offset != 0.0 or src.power != 1.0:       # (offset + scale·t)² per point
        from ..textures.inputs import SquaredNumber
        return SquaredNumber(roughness, clip=(ALPHA_MIN, 1.0))
    return TexturedNumber(TextureInput(src.texture, src.channel, power=2.0), clip=(ALPHA_MIN, 1.0))


def _root(colour):
    """√colour (the transmission tint), constant or per point."""
    if isinstance(colour, TexturedSpectrum):
        src = colour.source
        if src.scale != 1.0 or src.offset != 0.0:      # √(offset + scale·t): per point and wavelength
            from ..textures.inputs import RootSpectrum
            return RootSpectrum(colour)
        return TexturedSpectrum(TextureInput(src.texture, src.channel, src.scale, src.offset, 0.5 * src.power),
                                "unbounded")
    rgb = [math.sqrt(min(max(c, 0.0), 1.0)) for c in colour.linear_srgb()]
    if rgb == [1.0, 1.0, 1.0]:
        return None
    return ConstantSpectrum(rgb[0]) if min(rgb) == max(rgb) else RGBUnboundedSpectrum(rgb)


def _metal(p, alpha):
    """Cycles' Principled metal: a conductor of Gulbrandsen's index through the base colour at 0° and Cycles'
    F82-Tint value at θ₈₂ (its polarisation), its reflectance Cycles' F82-Tint curve at every angle
    (tinted.F82Reflectance); with a thin film the filmed index alone, as Cycles films its estimate of the index
    (the F82-Tint value taken as Gulbrandsen's edge tint: gulbrandsen mode "cycles_film")."""
    from ..textures.conductor_index import TexturedGulbrandsenIndex
    from .tinted import F82Reflectance
    base, tint = p["base_color"], p["specular_tint"]
    white = _white(tint)
    if _film_values(p):     # under a film Cycles takes (F0, F82-Tint value) as Gulbrandsen's (r, g) themselves
        kind = TexturedGulbrandsenIndex if _textured(base) or _textured(tint) else GulbrandsenIndex
        metal = _metal_of(*(kind(base, tint, part, "cycles_film") for part in ("n", "k")), p, alpha)
        thickness = p["thin_film_thickness"]
        if not _textured(thickness):
            return metal
        # a thickness per point: where it is below Cycles' cutoff the metal is unfilmed, on the F82-Tint curve
        return F82Reflectance(metal, base, None if white else tint, unless_film=thickness)
    if not _textured(base) and not _textured(tint) and not white:
        # Cycles' F82-Tint: the reflectance at θ₈₂ is Schlick's × the tint (≤ 1), per channel
        from ..spectral.gulbrandsen import schlick_f82
        f82 = [float(schlick_f82(c)) * min(t, 1.0) for c, t in zip(base.linear_srgb(), tint.linear_srgb())]
        edge = ConstantSpectrum(f82[0]) if min(f82) == max(f82) else RGBUnboundedSpectrum(f82)
        n, k = GulbrandsenIndex(base, edge, "n", "f82"), GulbrandsenIndex(base, edge, "k", "f82")
    # (a textured metallic: the index only where the metal has weight, engine.textures.conductor_index)
    live = p["metallic"] if isinstance(p["metallic"], TexturedNumber) else None
    if not white:           # a textured base or tint: the same curve per point and wavelength
        n, k = (TexturedGulbrandsenIndex(base, tint, part, "schlick_tint", live) for part in ("n", "k"))
    elif _textured(base):
        n, k = (TexturedGulbrandsenIndex(base, base, part, "schlick", live) for part in ("n", "k"))
    else:
        n, k = GulbrandsenIndex(base, base, "n", "schlick"), GulbrandsenIndex(base, base, "k", "schlick")
    return F82Reflectance(_metal_of(n, k, p, alpha), base, None if white else tint)


def _metal_of(n, k, p, alpha):
    values = {"n": n, "k": k}
    if effectively_smooth(alpha):
        values.update(_film_values(p))
        return conductor.DECLARATION.build(conductor.DECLARATION.values(values, p.where))
    aniso = _anisotropic_lobe(p, n, k, alpha)
    if aniso is not None:
        return aniso
    values.update(m=alpha, distribution="ggx",
                  multiscatter=p["distribution"] == "multi_ggx", **_film_values(p))
    return torrance_sparrow.DECLARATION.build(torrance_sparrow.DECLARATION.values(values, p.where))


def _anisotropic_lobe(p, n, k, alpha):
    """Cycles' anisotropic GGX reflection (engine.materials.anisotropic_ggx) of index n + iκ for Anisotropic > 0,
    else None: α_x = r²/aspect, α_y = r²·aspect, aspect = √(1 − 0.9·a), each in [ALPHA_MIN, 1], along the tangent
    rotated by Anisotropic Rotation.  The roughness, the Anisotropic and its Rotation may vary per point (α_x, α_y
    per point: engine.textures.inputs.MappedNumbers of α = r² and a)."""
    aniso = p["anisotropic"]
    if (aniso.hi if _textured(aniso) else aniso) <= 0.0:
        return None
    from .anisotropic_ggx import ASPECT_SLOPE, AnisotropicGGX, cycles_alphas
    if _textured(aniso) or _textured(alpha):
        from ..textures.inputs import MappedNumbers

        def aspect_of(a):
            return np.sqrt(1.0 - ASPECT_SLOPE * np.clip(a, 0.0, 1.0))

        def alpha_x(al, a):
            return np.maximum(np.minimum(al / aspect_of(a), 1.0), ALPHA_MIN)

        def alpha_y(al, a):
            return np.maximum(np.minimum(al * aspect_of(a), 1.0), ALPHA_MIN)
        al_range = (alpha.lo, alpha.hi) if _textured(alpha) else (alpha, alpha)
        a_range = (aniso.lo, aniso.hi) if _textured(aniso) else (aniso, aniso)
        # α_x grows with α and a, α_y grows with α and falls with a
        ax = MappedNumbers((alpha, aniso), alpha_x, float(alpha_x(al_range[0], a_range[0])),
                           float(alpha_x(al_range[1], a_range[1])))
        ay = MappedNumbers((alpha, aniso), alpha_y, float(alpha_y(al_range[0], a_range[1])),
                           float(alpha_y(al_range[1], a_range[0])))
    else:
        ax, ay = (max(v, ALPHA_MIN) for v in cycles_alphas(math.sqrt(alpha), aniso))
    film = _film_values(p)
    return AnisotropicGGX(n, k, ax, ay, rotation=p["anisotropic_rotation"],
                          multiscatter=p["distribution"] == "multi_ggx",
                          film_n=film.get("thin_film_ior"), film_thickness=film.get("thin_film_thickness", 0.0))


def _film_values(p) -> dict:
    """The thin film's keys for the metal and the dielectric specular layer, rough (on every facet) or smooth (on
    the mirror), as Cycles puts its Thin Film on every Fresnel of the Principled BSDF; empty without a film (a
    thickness — constant or per point — nowhere above Cycles' 0.1 nm cutoff)."""
    from ..polarisation.thin_film import FILM_CUTOFF_NM
    thickness = p["thin_film_thickness"]
    if (thickness.hi if _textured(thickness) else thickness) <= FILM_CUTOFF_NM:
        return {}
    return {"thin_film_thickness": p["thin_film_thickness"], "thin_film_ior": p["thin_film_ior"]}


def _transmission(p, alpha, ior):
    from .dielectric import SmoothDielectric
    from .rough_dielectric import RoughDielectric, index_matched
    from .tinted import Tinted
    from .thin_film import ThinFilmDielectric
    rough = p["transmission_roughness"] if p.given("transmission_roughness") else p["roughness"]
    if _textured(rough):        # α = r² per point, the reflection lobes' (≥ ALPHA_MIN = the rough glass's least α)
        a = alpha
    else:
        a = float(rough) ** 2
    film = bool(_film_values(p))
    if _textured(ior):          # an index per point
        ior = _glass_index(ior)
    matched = not _textured(ior) and index_matched(ior, 1.0)
    films = {"film_n": p["thin_film_ior"], "film_thickness": p["thin_film_thickness"]} if film else {}
    if effectively_smooth(a) and film:
        glass = ThinFilmDielectric(ior, p["thin_film_ior"], p["thin_film_thickness"])
    elif matched or effectively_smooth(a):
        glass = SmoothDielectric(ior)
    else:               # (a roughness per point too: α = r² per point, ≥ the rough glass's least α)
        glass = RoughDielectric(ior, a, "ggx", multiscatter=p["distribution"] == "multi_ggx", **films)
    spec_tint = p["specular_tint"]
    if not _white(spec_tint):
        from .tinted import FresnelTinted           # Cycles: the glass's F0 × Specular Tint, transmittance 1 − F
        glass = FresnelTinted(glass, ior, spec_tint)
    tint = _root(p["base_color"])
    return glass if tint is None else Tinted(glass, None, tint)


def _dielectric(p, alpha, ior):
    base = p["base_color"]
    level = p["specular_ior_level"]
    if _textured(ior):
        eta = _ior_index(ior, level)
    else:
        eta = _specular_index(ior, level) if _textured(level) else specular_ior(ior, level)
    smooth = effectively_smooth(alpha)
    values = {"n": eta, "k": 0.0, "diffuse_layering": "albedo_scaling", "m": 0.0 if smooth else alpha,
              "distribution": "ggx", **_film_values(p)}
    if not smooth:
        values.update(multiscatter=p["distribution"] == "multi_ggx")
    decl = torrance_sparrow.DECLARATION
    tint = p["specular_tint"]
    tinted = not _white(tint)
    aniso = None if smooth else _anisotropic_lobe(p, eta, 0.0, alpha)
    rough_base = not _never(p["diffuse_roughness"])          # an Oren–Nayar base somewhere (a σ per point too)
    if rough_base or tinted or aniso is not None:
        # the specular layer over Cycles' diffuse base as two parts (mix.Layered): an Oren–Nayar base, a tint,
        # an anisotropic specular layer
        from .lambert import DECLARATION as LAMBERT
        from .mix import Layered
        from .oren_nayar import OrenNayar
        if aniso is not None:
            top, albedo = aniso, aniso.reflection_albedo
        else:
            top = decl.build(decl.values({k: v for k, v in values.items() if k != "diffuse_layering"}, p.where))
            albedo = _reflection_albedo(top, eta, alpha, smooth)
        if tinted:
            from .tinted import FresnelTinted
            albedo = _tinted_albedo(albedo, top, eta, alpha, smooth, _peak(tint))
            top = FresnelTinted(top, eta, tint)
        under = OrenNayar(base, p["diffuse_roughness"]) if rough_base else \
            LAMBERT.build(LAMBERT.values({"albedo": base}, p.where))
        return Layered(top, under, 1.0, albedo)
    if _textured(base) or max(base.linear_srgb()) > 0:
        values["diffuse_albedo"] = base
    return decl.build(decl.values(values, p.where))


def _white(tint) -> bool:
    """A tint that changes nothing (a constant white)."""
    return not _textured(tint) and tint.is_constant and tint.linear_srgb()[0] == 1.0


def _peak(tint):
    """The largest RGB channel of a tint: a number, or a function of the shading point for a textured tint (N,)."""
    if not _textured(tint):
        return float(max(tint.linear_srgb()))
    return lambda sp: np.max(tint.rgb_at(sp.surface_points()), axis=0)


def _tinted_albedo(albedo, top, n, alpha, smooth, t):
    """The layering albedo of a specular layer with Specular Tint t (its largest channel, as Cycles' layering
    takes the largest; a number or a function of the shading point): E_t = E_F + F0(t − 1)(E_1 − E_F)/(1 − F0),
    E_F the untinted albedo, E_1 the F = 1 albedo (1 where compensated or smooth)."""
    from .ggx_energy import conductor_albedo, cycles_layering_darkening
    from ..textures.inputs import NumberSpectrum
    per_point = isinstance(n, NumberSpectrum)           # an index per point (a per-point IOR or Specular IOR Level)
    f0 = None if per_point else ((n - 1.0) / (n + 1.0)) ** 2
    if not per_point and f0 >= 1.0:
        return albedo

    def tinted(sp):
        E = albedo(sp)
        cycles = getattr(top, "cycles_layering", False)       # (an anisotropic layer keeps its own estimate)
        if smooth or (cycles and not top.multiscatter):
            E1 = 1.0
        elif cycles:        # Cycles' estimate mix(F0·t, 1, s) × its compensation's weight
            mu = np.clip(sp.cos_o, 0.0, 1.0)
            E1 = cycles_layering_darkening(mu, sp.number(alpha), n.numbers(sp.surface_points()) if per_point else n)
        elif top.multiscatter:
            E1 = 1.0
        else:
            E1 = conductor_albedo(np.clip(sp.cos_o, 0.0, 1.0), sp.number(alpha), correlated=True)
        peak = t(sp) if callable(t) else t
        if per_point:
            x = n.numbers(sp.surface_points())
            f = ((x - 1.0) / (x + 1.0)) ** 2
            return np.maximum(E + f * (peak - 1.0) * (E1 - E) / (1.0 - f), 0.0)
        return np.maximum(E + f0 * (peak - 1.0) * (E1 - E) / (1.0 - f0), 0.0)
    return tinted


def _reflection_albedo(top, n, alpha, smooth):
    """E(ω_o) (N,) of a dielectric reflection layer of index n (a number or per point), Cycles' layering albedo: its
    film's reflectance under a film, else Cycles' estimate (engine.materials.ggx_energy.cycles_layering_albedo), when
    rough × the weight of its compensation (TorranceSparrow.cycles_layer_albedo)."""
    from .ggx_energy import cycles_layer_weight
    from ..textures.inputs import NumberSpectrum
    if getattr(top, "film", None) is not None:       # a filmed layer: Cycles' estimate, its film's reflectance
        return lambda sp: top.film_albedo(sp, sp.cos_o)
    if not smooth:
        return lambda sp: top.cycles_layer_albedo(sp, np.clip(sp.cos_o, 0.0, 1.0))
    # smooth: the Fresnel reflectance interpolated between the nodes of Cycles' table (its estimate at α = 0)
    if isinstance(n, NumberSpectrum):                 # an index per point (a per-point Specular IOR Level)
        return lambda sp: cycles_layer_weight(np.clip(sp.cos_o, 0.0, 1.0), 0.0, n.numbers(sp.surface_points()), False)
    return lambda sp: cycles_layer_weight(np.clip(sp.cos_o, 0.0, 1.0), 0.0, float(n), False)


def _coat(p, below):
    """Cycles' coat: a GGX dielectric reflection (index coat_ior ≥ 1, α = coat_roughness², energy-compensated
    as Cycles always compensates it; smooth: a Fresnel mirror) over everything below, which is weighted by
    1 − coat_weight·E_coat(ω_o) (engine.materials.mix.Layered) and seen through the coat's tint
    (engine.materials.tinted.CoatTinted; an index-matched coat still tints)."""
    from .mix import Layered
    ior = p["coat_ior"]
    if _textured(ior):          # an index per point (≥ 1, as Cycles clamps it)
        from ..textures.inputs import NumberSpectrum
        n = NumberSpectrum(ior, lambda x: np.clip(x, 1.0, 100.0), max(ior.lo, 1.0), min(max(ior.hi, 1.0), 100.0))
    else:
        n = max(ior, 1.0)
    tint = p["coat_tint"]
    if not (getattr(tint, "is_constant", False) and tint.linear_srgb()[0] == 1.0):
        from .mix import Mix
        from .tinted import CoatTinted
        w = p["coat_weight"]
        # each part of a mixture tinted on its own, so the mixture stays flat under the coat (mix.Layered)
        below = below.with_components([CoatTinted(c, tint, n, w) for c in below.components]) \
            if type(below) is Mix else CoatTinted(below, tint, n, w)
    if (n.hi if _textured(n) else n) == 1.0:                # an index-matched coat reflects nothing
        return below
    alpha = _alpha_of(p["coat_roughness"])
    decl = torrance_sparrow.DECLARATION
    smooth = effectively_smooth(alpha)
    values = {"n": n, "k": 0.0, "m": 0.0} if smooth else \
        {"n": n, "k": 0.0, "m": alpha, "distribution": "ggx", "multiscatter": True}
    top = decl.build(decl.values(values, p.where))
    layered = Layered(top, below, p["coat_weight"], _reflection_albedo(top, n, alpha, smooth))
    layered.role = "coat"           # its top is the coat (with_normal_maps: Coat Normal)
    return layered


def with_normal_maps(bsdf: BSDF, normal: dict | None, coat: dict | None = None) -> BSDF:
    """A principled material (or any material) with Blender's Normal and Coat Normal maps (ShadingNormal keywords,
    None for none), mapped closure by closure (mix.map_normals): the coat layer by ``coat`` where given, else by
    ``normal`` (Cycles' coat follows the Normal input where Coat Normal is unlinked), everything else by
    ``normal``."""
    from .mix import map_normals
    if coat is not None and getattr(bsdf, "role", None) == "coat":
        rest = [map_normals(c, **normal) if normal else c for c in bsdf.components[1:]]
        return bsdf.with_components([map_normals(bsdf.components[0], **coat)] + rest)
    return map_normals(bsdf, **normal) if normal else bsdf


DECLARATION = ModelDeclaration(
    "principled", "Principled BSDF",
    "Blender's Principled BSDF as Cycles composes it: metal, transmission and a dielectric over a diffuse "
    "base, from polarising parts",
    [Parameter("base_color", "base colour: diffuse albedo, metal reflectance at 0°, transmission tint²",
               kind="spectrum", spectrum="reflectance", lo=0.0, hi=1.0, default=0.8, texturable=True),
     Parameter("metallic", "metal's weight", lo=0.0, hi=1.0, default=0.0, texturable=True),
     Parameter("roughness", "Blender roughness r (α = r² for every lobe)", lo=0.0, hi=1.0, default=0.5,
               texturable=True),
     Parameter("ior", "index of the dielectric and the transmission", lo=0.0,
               lo_open=True, default=1.5, texturable=True),
     Parameter("transmission", "transmission's weight (of what the metal leaves)", lo=0.0, hi=1.0, default=0.0,
               texturable=True),
     Parameter("transmission_roughness", "the transmission's roughness where it differs (default: roughness, "
                                         "per point where that is; constant)", lo=0.0, hi=1.0, default=0.5),
     Parameter("specular_ior_level", "Cycles' Specular IOR Level: F0 × 2·level", lo=0.0, hi=1.0, default=0.5,
               texturable=True),
     Parameter("diffuse_roughness", "the base's Oren–Nayar roughness σ (0: Lambert)", lo=0.0, hi=1.0, default=0.0,
               texturable=True),
     Parameter("specular_tint", "Cycles' Specular Tint: the dielectric's F0 × tint (its F82 tint for the metal)",
               kind="spectrum", spectrum="unbounded", lo=0.0, hi=1e6, default=1.0, texturable=True),
     Parameter("anisotropic", "Cycles' Anisotropic: the metal's and the specular layer's GGX stretched along the "
                              "surface tangent, α = r²/aspect and r²·aspect, aspect = √(1 − 0.9·a)", lo=0.0, hi=1.0,
               default=0.0, texturable=True),
     Parameter("anisotropic_rotation", "the tangent's rotation about the normal, in turns", lo=-1e6, hi=1e6,
               default=0.0, texturable=True),
     Parameter("coat_weight", "coat (> 0: a coat over the dielectric)", lo=0.0, hi=1.0, default=0.0, texturable=True),
     Parameter("coat_roughness", "coat roughness r", lo=0.0, hi=1.0, default=0.03, texturable=True),
     Parameter("coat_ior", "coat index", lo=1.0, hi=100.0, default=1.5, texturable=True),
     Parameter("coat_tint", "coat colour: its transmittance at normal incidence (Cycles' Coat Tint: everything "
                            "below × tint^(1/cosθ_t), blended by coat_weight)", kind="spectrum", spectrum="reflectance",
               lo=0.0, hi=1.0, default=1.0, texturable=True),
     Parameter("sheen_weight", "Cycles' sheen layer over everything (microfiber, engine.materials.sheen)", lo=0.0,
               hi=1e6, default=0.0, texturable=True),
     Parameter("sheen_roughness", "the sheen's roughness", lo=0.0, hi=1.0, default=0.5, texturable=True),
     Parameter("sheen_tint", "the sheen's colour", kind="spectrum", spectrum="unbounded", lo=0.0, hi=1e6,
               default=1.0, texturable=True),
     Parameter("thin_film_thickness", "thin film on the transmission, the metal and the dielectric specular "
                                      "layer (Airy's sum, per facet where rough)", unit="nm", lo=0.0, hi=1e6,
               default=0.0, texturable=True),
     Parameter("thin_film_ior", "thin film's index", lo=0.0, lo_open=True, default=1.33, texturable=True),
     Parameter("distribution", "microfacet distribution: Multiscatter GGX (Cycles' default) or GGX",
               kind="choice", choices=DISTRIBUTIONS, default="multi_ggx")])

DECLARATION.per_point = frozenset({"base_color", "metallic", "roughness", "transmission", "coat_tint", "coat_weight",
                                   "coat_roughness", "coat_ior", "specular_tint", "specular_ior_level",
                                   "thin_film_thickness", "thin_film_ior", "diffuse_roughness", "sheen_weight",
                                   "sheen_roughness", "sheen_tint", "anisotropic", "anisotropic_rotation", "ior"})


@DECLARATION.builder
def _principled(p):
    p["thin_film_ior"]          # validated even where no film uses it (a NaN is refused, not ignored)
    metallic, transmission = p["metallic"], p["transmission"]
    alpha = _alpha_of(p["roughness"])
    from .dielectric import one_side_of
    ior = one_side_of(p, "ior", 1.0)
    if not _textured(ior):
        ior = max(ior, IOR_MIN)
    metal = glass = dielectric = None
    if not _never(metallic):
        metal = _metal(p, alpha)
    if not _always(metallic) and not _never(transmission):
        glass = _transmission(p, alpha, ior)
    if not _always(metallic) and not _always(transmission):
        dielectric = _dielectric(p, alpha, ior)
    below = _mixture(_mixture(dielectric, glass, transmission), metal, metallic)
    if not _never(p["coat_weight"]):
        below = _coat(p, below)
    return below if _never(p["sheen_weight"]) else _sheen(p, below)


def _sheen(p, below):
    """Cycles' first layer: the microfiber sheen (engine.materials.sheen) weighted sheen_weight, tinted, over
    everything else, which is weighted by 1 − sheen_weight·max(tint)·E_sheen(ω_o) (closure_layering_weight
    takes the largest channel)."""
    from .mix import Layered
    from .sheen import Sheen
    tint = p["sheen_tint"]
    top = Sheen(tint, p["sheen_roughness"])
    if not _textured(tint):
        peak = float(max(tint.linear_srgb()))

        def albedo(sp):
            return peak * top.albedo(sp)
    else:
        def albedo(sp):
            return np.max(np.maximum(sp.spectrum(tint), 0.0), axis=0) * top.albedo(sp)
    layered = Layered(top, below, p["sheen_weight"], albedo)
    layered.role = "sheen"          # a layer over the emission (mix.emission_weight)
    return layered
