"""Blender's standard shaders → the closest polarising model (docs/guide/blender.md, "Using it": existing
scenes), and ``surface_bsdf``, the conversion of the shader graph plugged into a Surface:

- Diffuse → Lambert (Oren–Nayar above roughness 0); Glossy/Anisotropic → conductor from the colour
  (Gulbrandsen 2014); Metallic (Physical Conductor) → conductor with its n, k; Glass → smooth
  dielectric, or with roughness r the rough dielectric (α = r², the node's distribution, Multiscatter GGX
  compensated); Refraction → the ``refraction`` model (Cycles' closure: no Fresnel, no reflection); both with IOR
  and Roughness per point where linked; Principled → the engine's ``principled``
  model (Cycles' layer order); Sheen → sheen; Emission → emitter;
- Mix / Add Shader → an engine Mix, a Transparent BSDF mixed in → the object's pass-through alpha;
- a **Polarising BSDF** node → polarising_node (its model and inputs exactly);
- anything else: grey Lambert with a warning.
Roughness r maps to the slope m = r² (as Cycles' α = r²); the engine's rule decides where that is
smooth (engine.materials.roughness: below SMOOTH_LIMIT = 1e-4 the smooth model, as for a scene file).
Every converted shader becomes declaration values built through ``MODELS[name].build`` (the
declaration range-checks them once; a NaN or out-of-range input is an error naming the material
and the input); only wrappers without a declaration (tints, Cycles' F82 curve, the anisotropic GGX
part of a Principled-like metal) are made here directly.  Inputs are read by node_reader (constants,
textures, baked graphs); Normal inputs become normal or bump maps (normal_maps).
"""

import math

import numpy as np

from ...engine.errors import SceneError
from ...engine.materials.catalogue import MODELS
from ...engine.materials.lambert import Lambert
from ...engine.materials.principled import IOR_MIN, WEIGHT_CUTOFF
from ...engine.materials.roughness import ALPHA_MIN, effectively_smooth
from ...engine.spectral import ConstantSpectrum, RGBIlluminantSpectrum
from ...engine.textures import TextureInput
from ...engine.textures.inputs import TexturedNumber
from .lambert import DEFAULT_ALBEDO, lambert, rgb_spectrum
from .node_links import follow, linked_source
from .node_reader import Reader
from .normal_maps import with_shading_normal
from .polarising_node import polar_node_bsdf


def _textured_model(model, values, mat, node, sockets=None):
    """A model built through its declaration from ``values`` some of which are TextureInputs
    (validated: every value a texture can give must be in the parameter's range); ``sockets``: {parameter: the
    node's socket it comes from} for the errors' field names."""
    decl = MODELS[model]
    values = {k: _grey(v) for k, v in values.items()}
    return decl.build(decl.values(values, f"material {mat!r}.{node.name}", label=_socket_label(sockets)))


#: the Glass and Refraction BSDFs' sockets of the dielectric models' parameters (errors name the socket)
_GLASS_SOCKETS = {"n": "IOR", "alpha": "Roughness", "thin_film_ior": "Thin Film IOR",
                  "thin_film_thickness": "Thin Film Thickness"}


def _socket_label(sockets):
    return None if sockets is None else (lambda name: sockets.get(name, name))


def _grey(v):
    """A constant [r, g, b] with r = g = b as one number (the same spectrum as the constant path's
    ``rgb_spectrum``); anything else as is."""
    if isinstance(v, (list, tuple, np.ndarray)) and max(v) == min(v):
        return float(v[0])
    return v


def _textured(*values) -> bool:
    return any(isinstance(v, TextureInput) for v in values)


def _reflectance(value):
    """A reflectance spectrum of a constant [r, g, b] or a colour TextureInput (per point)."""
    if isinstance(value, TextureInput):
        from ...engine.textures.inputs import TexturedSpectrum
        return TexturedSpectrum(value, "reflectance").clamped_to(0.0, 1.0)
    return rgb_spectrum(value)


def conductor_index(colour, edge, mode):
    """(n, κ) spectra of a metal whose normal-incidence reflectance is ``colour`` (a constant [r, g, b]
    or a colour TextureInput), by Gulbrandsen's map per wavelength (and per point), so that the mirror
    shows the colour (engine.spectral.gulbrandsen); the second parameter by ``mode``: "schlick" (the
    reflectance at θ₈₂ of Schlick's curve through the colour: Cycles' Principled metal, ``edge`` unused),
    "f82" (``edge`` is that reflectance) or "tint" (``edge`` is Gulbrandsen's edge tint)."""
    from ...engine.spectral.gulbrandsen import GulbrandsenIndex
    from ...engine.textures.conductor_index import TexturedGulbrandsenIndex
    r = _reflectance(colour)
    g = r if edge is None or edge is colour else _reflectance(edge)
    kind = TexturedGulbrandsenIndex if _textured(colour, edge) else GulbrandsenIndex
    return kind(r, g, "n", mode), kind(r, g, "k", mode)


def facets(node, mat, warnings):
    """Torrance–Sparrow facet keywords of a Blender microfacet shader's Distribution, as Cycles renders
    it: GGX (height-correlated Smith G), Multiscatter GGX (GGX with Cycles' energy compensation, a
    depolarised term), Beckmann (the thesis' Beckmann with V-cavity shadowing, as before);
    Ashikhmin–Shirley is rendered as GGX (one warning)."""
    distribution = getattr(node, "distribution", "GGX")
    if distribution == "BECKMANN":
        return {"distribution": "beckmann"}
    if distribution == "ASHIKHMIN_SHIRLEY":
        warnings.append(f"material {mat!r}: {node.name!r} uses the Ashikhmin-Shirley distribution; rendered as GGX")
    return {"distribution": "ggx", "multiscatter": distribution == "MULTI_GGX"}


def _facet_conductor(n, k, m, mat, node, warnings, film=None, aniso=None):
    """A conductor of index n + iκ (spectra, [r, g, b] or textured) with facets as the node's Distribution
    and roughness m (α = r², constant or a TextureInput), or its smooth limit; ``film``: (IOR, thickness nm)
    of a Thin Film on its facets or its mirror (Cycles films the conductor's index);
    ``aniso``: (α_x, α_y, rotation in turns) of Cycles' anisotropic GGX (each α a number, or per point an
    engine.textures.inputs.MappedNumbers: ``_node_anisotropy``; None: isotropic).
    Smooth where the engine's rule calls every α smooth (engine.materials.roughness.effectively_smooth): the
    ``conductor`` model; else each α at least the least slope ALPHA_MIN (pbrt's rule)."""
    kw = facets(node, mat, warnings)
    smooth = not isinstance(m, TextureInput) and effectively_smooth(m, *(() if aniso is None else aniso[:2]))
    films = {} if film is None else {"thin_film_ior": film[0], "thin_film_thickness": film[1]}
    if smooth:
        return _textured_model("conductor", {"n": n, "k": k, **films}, mat, node)
    per_point = aniso is not None and any(isinstance(v, TexturedNumber) for v in aniso[:2])
    if aniso is not None and (per_point or aniso[0] != aniso[1]):
        if kw["distribution"] == "ggx":
            from ...engine.materials.anisotropic_ggx import AnisotropicGGX
            n_s, k_s = (rgb_spectrum(list(v), "unbounded") if isinstance(v, (list, tuple)) else v for v in (n, k))
            ax, ay = (v if isinstance(v, TexturedNumber) else max(v, ALPHA_MIN) for v in aniso[:2])
            # (no declaration: the anisotropic GGX is a part of Principled-like metals, engine.materials.principled)
            return AnisotropicGGX(n_s, k_s, ax, ay, rotation=aniso[2], multiscatter=kw["multiscatter"],
                                  film_n=None if film is None else _film_number(film[0], IOR_MIN),
                                  film_thickness=0.0 if film is None else _film_number(film[1]))
        warnings.append(f"material {mat!r}: the anisotropy of {node.name!r} is simulated with GGX only; rendered "
                        "isotropic (Beckmann)")
    if not isinstance(m, TextureInput):
        m = max(m, ALPHA_MIN)          # (an anisotropic pair rendered isotropic: its m may lie below)
    return _textured_model("torrance_sparrow", {"n": n, "k": k, "m": m, **kw, **films}, mat, node)


def _node_anisotropy(r, node, mat, warnings, m, kind):
    """(α_x, α_y, rotation) of a Glossy or Metallic BSDF's Anisotropy as Cycles sets it up, or None (isotropic):
    Metallic as the Principled BSDF (α = r²/aspect, r²·aspect, aspect = √(1 − 0.9·a), a ∈ [0, 1]); Glossy
    α = r²(1 − a), r²/(1 − a) for a ∈ (0, 0.99], r²/(1 + a), r²(1 + a) below 0 (|a| ≤ 10⁻⁴: isotropic); each
    α ≤ 1.  The Roughness (m = r²) and the Anisotropy may each vary per point: then α_x, α_y per point
    (engine.textures.inputs.MappedNumbers of α and a, each in [ALPHA_MIN, 1]).  The Rotation is a constant
    (linked: its own value, one warning)."""
    sock = node.inputs.get("Anisotropy")
    if sock is None or (not sock.is_linked and float(sock.default_value) == 0.0):
        return None
    a = r.number_or_texture("Anisotropy", -1.0, 1.0)
    _tangent_note(node, mat, warnings)
    metallic = kind == "ShaderNodeBsdfMetallic"
    if _textured(m, a):
        if metallic and not isinstance(a, TextureInput) and a <= 0.0:
            return None
        ax, ay = _per_point_alphas(m, a, metallic)
        if not isinstance(m, TextureInput) and max(ax.hi, ay.hi) <= ALPHA_MIN:
            return None                 # (a constant Roughness that keeps every α at the least slope: isotropic)
        return ax, ay, r.float("Rotation", -1e6, 1e6)
    rough = math.sqrt(m)
    if metallic:
        if a <= 0.0:
            return None
        from ...engine.materials.anisotropic_ggx import cycles_alphas
        ax, ay = cycles_alphas(rough, a)
    else:
        a = min(max(a, -0.99), 0.99)
        if abs(a) <= 1e-4:
            return None
        ax, ay = (min(float(v), 1.0) for v in _glossy_alphas(m, a))
    return ax, ay, r.float("Rotation", -1e6, 1e6)


def _glossy_alphas(alpha, a):
    """Cycles' Glossy BSDF (α_x, α_y) of α = r² and the Anisotropy a ∈ [−0.99, 0.99] (numbers or arrays)."""
    below = a < 0
    return np.where(below, alpha / (1.0 + a), alpha * (1.0 - a)), np.where(below, alpha * (1.0 + a), alpha / (1.0 - a))


def _per_point_alphas(m, a, metallic):
    """(α_x, α_y) per point (engine.textures.inputs.MappedNumbers of α = r² and the Anisotropy a, either textured
    or constant) of a Metallic (as the Principled: engine.materials.principled._anisotropic_lobe) or Glossy BSDF,
    each in [ALPHA_MIN, 1]; their bounds from the corners of the ranges of α and a (each α is monotone in both)."""
    from ...engine.materials.anisotropic_ggx import ASPECT_SLOPE
    from ...engine.textures.inputs import MappedNumbers
    alpha = TexturedNumber(m, clip=(0.0, 1.0)) if isinstance(m, TextureInput) else m
    aniso = TexturedNumber(a, clip=(-1.0, 1.0)) if isinstance(a, TextureInput) else a

    def pair(al, an):
        al = np.clip(al, 0.0, 1.0)
        if metallic:
            aspect = np.sqrt(1.0 - ASPECT_SLOPE * np.clip(an, 0.0, 1.0))
            ax, ay = al / aspect, al * aspect
        else:
            an = np.clip(an, -0.99, 0.99)
            ax, ay = _glossy_alphas(al, np.where(np.abs(an) <= 1e-4, 0.0, an))
        return np.clip(ax, ALPHA_MIN, 1.0), np.clip(ay, ALPHA_MIN, 1.0)

    def alpha_x(al, an):
        return pair(al, an)[0]

    def alpha_y(al, an):
        return pair(al, an)[1]
    al_lo, al_hi = (alpha.lo, alpha.hi) if isinstance(alpha, TexturedNumber) else (alpha, alpha)
    a_lo, a_hi = (aniso.lo, aniso.hi) if isinstance(aniso, TexturedNumber) else (aniso, aniso)
    # α_y grows with α; with a it falls (Metallic) or grows (Glossy); α_x grows with α and, opposite to α_y, with a
    y_lo, y_hi = (a_hi, a_lo) if metallic else (a_lo, a_hi)
    return (MappedNumbers((alpha, aniso), alpha_x, float(alpha_x(al_lo, y_hi)), float(alpha_x(al_hi, y_lo))),
            MappedNumbers((alpha, aniso), alpha_y, float(alpha_y(al_lo, y_lo)), float(alpha_y(al_hi, y_hi))))


def _conductor_from_colour(r, colour_name, edge_name, m, mat, node, warnings, mode="schlick"):
    """Conductor whose normal-incidence reflectance is a colour input, its unpolarised reflectance Cycles'
    Fresnel curve at every facet angle (engine.materials.tinted.F82Reflectance over Gulbrandsen's index through
    the curve at 0° and θ₈₂; ``mode``: "schlick", Cycles' F82 curve with a white tint — the Principled metal;
    "f82" with ``edge_name`` an F82-Tint input — the Metallic BSDF; "constant": the colour at every angle —
    Cycles' Glossy BSDF, its polarisation that of a conductor matched at 0° and θ₈₂).  Colours and the roughness
    m may vary per point (image, colour attribute, a baked graph).  The node's Anisotropy and Thin Film (Metallic)
    as Cycles (``_facet_conductor``)."""
    from ...engine.materials.tinted import F82Reflectance
    colour = r.rgb_or_texture(colour_name, 0.0, 1.0)
    tint = None
    if mode == "constant":
        n, k = conductor_index(colour, colour, "f82")
    elif mode == "f82":
        tint = r.rgb_or_texture(edge_name, 0.0, 1.0)
        if isinstance(colour, TextureInput) or isinstance(tint, TextureInput):
            n, k = conductor_index(colour, tint, "schlick_tint")
        else:
            from ...engine.spectral.gulbrandsen import schlick_f82
            f82 = [float(schlick_f82(c)) * t for c, t in zip(colour, tint)]     # Cycles' F82-Tint
            n, k = conductor_index(colour, f82, "f82")
        if not isinstance(tint, TextureInput) and min(tint) == 1.0:
            tint = None
    else:
        n, k = conductor_index(colour, None, "schlick")
    film = _film(r) if mode == "f82" else None
    if film is not None:            # Cycles films its own estimate: (F0, F82-Tint value) as Gulbrandsen's (r, g)
        n, k = conductor_index(colour, [1.0, 1.0, 1.0] if tint is None else tint, "cycles_film")
    metal = _facet_conductor(n, k, m, mat, node, warnings, film,
                             _node_anisotropy(r, node, mat, warnings, m, node.bl_idname))
    if film is not None:
        return metal                                     # (its reflectance is the filmed index's, as Cycles')
    return F82Reflectance(metal, _reflectance(colour), None if tint is None else _reflectance(tint),
                          "constant" if mode == "constant" else "f82_tint")


def _ior(r, name):
    """An IOR input as Cycles reads it: any finite value Blender holds, raised to IOR_MIN (an error
    only for NaN and ±inf)."""
    return max(r.float(name), IOR_MIN)


def _coat_ior(r):
    """Coat IOR as Cycles reads it (≥ 1; Polar's range ends at 100): a TextureInput (values clamped to [1, 100])
    where linked, else the constant."""
    if r._socket("Coat IOR").is_linked:
        source = r.texture("Coat IOR", lo=1.0, hi=100.0)
        if source is not None:
            return source
        return min(max(r._checked_float("Coat IOR", -math.inf, math.inf), 1.0), 100.0)
    return min(max(r.float("Coat IOR"), 1.0), 100.0)


def _ior_or_texture(r):
    """The IOR of a Principled, Glass or Refraction BSDF: a TextureInput where linked (the index per point of the
    Principled dielectric — with a Specular Tint, an anisotropy, a Thin Film or a linked Specular IOR Level too — and
    of every transmission, smooth, rough, tinted or filmed), else the constant as Cycles reads it (linked where it
    cannot be read per point: its own value, the reader's warning)."""
    if r._socket("IOR").is_linked:
        source = r.texture("IOR", lo=IOR_MIN, hi=1e6)
        if source is not None:
            return source
        return max(r._checked_float("IOR", -math.inf, math.inf), IOR_MIN)
    return _ior(r, "IOR")


def _specular_level(r):
    """Specular IOR Level: a TextureInput in [0, 1] where linked (glTF's KHR_materials_specular map; with a Specular
    Tint, an anisotropy, a Thin Film or a per-point IOR too), else the constant."""
    if r._socket("Specular IOR Level").is_linked:
        return r.number_or_texture("Specular IOR Level")
    return r.float("Specular IOR Level", 0.0, 1.0)


def _sheen_weight(r):
    """Sheen Weight as Cycles reads it (≥ 0, no upper clamp): a TextureInput in [0, 1] where linked, else the
    constant."""
    if r._socket("Sheen Weight").is_linked:
        return _fraction(r, "Sheen Weight")
    return max(r.float("Sheen Weight"), 0.0)


def _fraction(r, name):
    """A [0, 1] weight input (Metallic, Transmission Weight, a Mix Shader's Factor) as Cycles reads
    it: the constant clamped to [0, 1], or a TextureInput (image, colour attribute, Separate Color of
    an image, or a baked graph) whose values are clamped to [0, 1] where used (``_weight``)."""
    sock = r._socket(name)
    if sock.is_linked:
        source = r.texture(name, lo=0.0, hi=1.0)
        if source is not None:
            return source
    v = float(sock.default_value)
    if not math.isfinite(v):
        raise SceneError(f"material {r.mat!r}.{r.node.name}.{name}", f"must be a finite number, got {v!r}")
    return min(max(v, 0.0), 1.0)


def _weight(x, complement=False):
    """A mixture weight from a fraction: x or 1 − x, a float or a TexturedNumber clamped to [0, 1]."""
    from ...engine.textures.inputs import TexturedNumber
    if not isinstance(x, TextureInput):
        return 1.0 - x if complement else x
    if complement:
        if x.power != 1.0:
            raise ValueError("a weight texture has power 1")
        x = TextureInput(x.texture, x.channel, -x.scale, 1.0 - x.offset)
    return TexturedNumber(x, clip=(0.0, 1.0))


def _never(x) -> bool:
    """The fraction is 0 everywhere (a constant below Cycles' closure cutoff)."""
    return not isinstance(x, TextureInput) and x < WEIGHT_CUTOFF


def _always(x) -> bool:
    """The fraction is 1 everywhere."""
    return not isinstance(x, TextureInput) and x > 1.0 - WEIGHT_CUTOFF


def _principled(node, mat, warnings, bake=None):
    """The engine's ``principled`` model (engine/materials/principled.py: Cycles' layer order from
    polarising parts) filled from the node's sockets, each input constant or per point where the engine
    takes it per point (an image, a channel of one, a colour attribute, a baked graph)."""
    r = Reader(mat, node, warnings, bake)
    metallic = _fraction(r, "Metallic")
    transmission = _fraction(r, "Transmission Weight")
    roughness = r.number_or_texture("Roughness")
    values = {"base_color": _grey(r.rgb_or_texture("Base Color", 0.0, 1.0)), "metallic": metallic,
              "roughness": roughness, "transmission": transmission, "ior": _ior_or_texture(r),
              "specular_ior_level": _specular_level(r),
              "specular_tint": _grey(r.rgb_or_texture("Specular Tint", 0.0)),
              "coat_weight": _fraction(r, "Coat Weight"),
              "coat_roughness": r.number_or_texture("Coat Roughness"),
              "coat_ior": _coat_ior(r),
              "coat_tint": _grey(r.rgb_or_texture("Coat Tint", 0.0, 1.0)),
              "sheen_weight": _sheen_weight(r),
              "sheen_roughness": r.number_or_texture("Sheen Roughness"),
              "sheen_tint": _grey(r.rgb_or_texture("Sheen Tint", 0.0)),
              "anisotropic": _fraction(r, "Anisotropic") if anisotropic(node) else 0.0,
              "anisotropic_rotation": r.number_or_texture("Anisotropic Rotation", -1e6, 1e6),
              "diffuse_roughness": (r.number_or_texture("Diffuse Roughness")
                                    if node.inputs.get("Diffuse Roughness") is not None else 0.0),
              "distribution": "ggx" if getattr(node, "distribution", "MULTI_GGX") == "GGX" else "multi_ggx"}
    film = _film(r)
    if film is not None:
        values["thin_film_ior"], values["thin_film_thickness"] = film
    if isinstance(values["anisotropic"], TextureInput) or values["anisotropic"] > 0.0:
        _tangent_note(node, mat, warnings)          # (α_x, α_y per point with a Roughness texture)
    _unsimulated_principled_inputs(node, mat, warnings)
    decl = MODELS["principled"]
    return decl.build(decl.values(values, f"material {mat!r}.{node.name}"))


#: Principled inputs not simulated yet, and the value at which they change nothing (a colour: white)
_PRINCIPLED_NOT_SIMULATED = (("Subsurface Weight", 0.0, "rendered as the diffuse base"),)


def anisotropic(node, name="Anisotropic") -> bool:
    """A Principled BSDF whose Anisotropic (a Glossy or Metallic BSDF whose Anisotropy) is set (a constant ≠ 0,
    or linked: its own value is then used, with the reader's warning)."""
    sock = node.inputs.get(name)
    return sock is not None and (sock.is_linked or float(sock.default_value) != 0.0)


def _tangent_note(node, mat, warnings):
    """The warnings of an anisotropic Principled, Glossy or Metallic BSDF: Cycles stretches its GGX along the
    Tangent input — a Tangent node on a UV map is that map's MikkTSpace tangent, as Polar's; unlinked, Cycles'
    default is the radial tangent about the object's Z (generated coordinates), for which Polar takes the active UV
    map's tangent (the same on a UV sphere or cylinder, not in general)."""
    sock = node.inputs.get("Tangent")
    source = follow(sock) if sock is not None and sock.is_linked else None
    if source is None or source.bl_idname != "ShaderNodeTangent" or source.direction_type != "UV_MAP":
        what = "unlinked (Cycles: the radial tangent about the object's Z)" if source is None else \
            f"from {source.bl_idname} {source.name!r}"
        warnings.append(f"material {mat!r}: the Tangent of {node.name!r} is {what}; its anisotropy is rendered along "
                        "the active UV map's tangent")


def _unsimulated_principled_inputs(node, mat, warnings):
    """One warning per Principled input that is set (or linked) to something Polar does not simulate yet
    (docs/guide/blender.md, "Principled BSDF, input by input"); inputs newer Blenders add are named too."""
    for name, neutral, instead in _PRINCIPLED_NOT_SIMULATED:
        sock = node.inputs.get(name)
        if sock is None:
            continue
        value = sock.default_value
        values = [float(v) for v in value[:3]] if hasattr(value, "__len__") else [float(value)]
        if sock.is_linked or any(v != neutral for v in values):
            warnings.append(f"material {mat!r}: Principled input {name!r} of {node.name!r} is not simulated yet "
                            f"({instead})")
    known = {"Base Color", "Metallic", "Roughness", "IOR", "Alpha", "Normal", "Weight", "Diffuse Roughness",
             "Subsurface Weight", "Subsurface Radius", "Subsurface Scale", "Subsurface IOR", "Subsurface Anisotropy",
             "Specular IOR Level", "Specular Tint", "Anisotropic", "Anisotropic Rotation", "Tangent",
             "Transmission Weight", "Coat Weight", "Coat Roughness", "Coat IOR", "Coat Tint", "Coat Normal",
             "Sheen Weight", "Sheen Roughness", "Sheen Tint", "Emission Color", "Emission Strength",
             "Thin Film Thickness", "Thin Film IOR"}
    for sock in node.inputs:
        if sock.name not in known and sock.enabled and (sock.is_linked or _non_default(sock)):
            warnings.append(f"material {mat!r}: Principled input {sock.name!r} of {node.name!r} (a newer Blender's) "
                            "is not simulated")


def _non_default(sock) -> bool:
    """A newer input set away from its default (booleans and numbers; other kinds count as set)."""
    rna = sock.bl_rna.properties.get("default_value")
    if rna is None:
        return False
    default = getattr(rna, "default_array", None) if getattr(rna, "is_array", False) else getattr(rna, "default", None)
    value = sock.default_value
    try:
        return tuple(value) != tuple(default) if hasattr(value, "__len__") else value != default
    except TypeError:
        return True


def _tint_spectrum(colour):
    """A tint spectrum (≥ 0, any magnitude) of a constant [r, g, b] or a colour TextureInput; None for white."""
    from ...engine.textures.inputs import TexturedSpectrum
    if isinstance(colour, TextureInput):
        return TexturedSpectrum(colour, "unbounded")
    return None if min(colour) == max(colour) == 1.0 else rgb_spectrum(list(colour), "unbounded")


def _tinted(bsdf, reflection, transmission):
    """``bsdf`` with its reflected and transmitted light tinted (engine.materials.tinted: Cycles' glass
    colour, the Principled transmission tint); colours as constant [r, g, b] or TextureInputs, None or
    white for none."""
    from ...engine.materials.tinted import Tinted
    r = None if reflection is None else _tint_spectrum(reflection)
    t = None if transmission is None else _tint_spectrum(transmission)
    return bsdf if r is None and t is None else Tinted(bsdf, r, t)


def _film(r):
    """(IOR, thickness nm) of a node's Thin Film inputs, or None (no film: thickness ≤ Cycles' 0.1 nm
    cutoff everywhere, or the inputs absent: Blender before 4.2).  The thickness a number or a TextureInput
    (linked: an image, a colour attribute, a baked graph — glTF's iridescence thickness map; values ≥ 0)."""
    from ...engine.textures.inputs import TexturedNumber
    if r.node.inputs.get("Thin Film Thickness") is None:
        return None
    if r._socket("Thin Film Thickness").is_linked:
        thickness = r.texture("Thin Film Thickness", lo=0.0, hi=1e6)       # (not mapped: its own value, warned)
        if thickness is None:
            thickness = r._checked_float("Thin Film Thickness", -math.inf, math.inf)
    else:
        thickness = r.float("Thin Film Thickness")
    if (TexturedNumber(thickness).hi if isinstance(thickness, TextureInput) else thickness) <= 0.1:
        return None
    ior = None
    if r._socket("Thin Film IOR").is_linked:
        ior = r.texture("Thin Film IOR", lo=IOR_MIN, hi=1e6)          # (not mapped: its own value, warned)
    if ior is None:
        ior = max(r._checked_float("Thin Film IOR", -math.inf, math.inf), IOR_MIN)
    return ior, thickness


def _film_number(value, lo=0.0):
    """A film thickness (or, ``lo`` IOR_MIN, index) for a model built here directly: a number, or a TexturedNumber
    of a TextureInput."""
    from ...engine.textures.inputs import TexturedNumber
    return TexturedNumber(value, clip=(lo, 1e6)) if isinstance(value, TextureInput) else value


def _glass(ior, alpha, distribution, film=None, where="material"):
    """The ``rough_dielectric`` model of α (Blender's roughness²; the engine builds the smooth dielectric where its
    rule calls α smooth, or the interface is index-matched): GGX as Cycles' GGX, Multiscatter GGX (Principled's and
    Glass' default) with Cycles' energy compensation (``multiscatter``), Beckmann as Beckmann; with a ``film``
    (IOR, thickness) Airy's sum on every facet, or on the smooth interface (the ``thin_film`` model there).  The
    index, α and the film may each be a TextureInput (linked IOR, Roughness, Thin Film inputs: per point, as the
    Principled transmission's)."""
    beckmann = distribution == "BECKMANN"
    decl = MODELS["rough_dielectric"]
    films = {} if film is None else {"thin_film_ior": _film_number(film[0], IOR_MIN),
                                     "thin_film_thickness": _film_number(film[1])}
    return decl.build(decl.values({"n": ior, "alpha": alpha, "distribution": "beckmann" if beckmann else "ggx",
                                   "multiscatter": distribution == "MULTI_GGX", **films}, where,
                                  label=_socket_label(_GLASS_SOCKETS)))


def _emission(node, mat, warnings, colour_name="Color", strength_name="Strength", bake=None):
    """The emitted spectrum of an Emission shader or a Principled BSDF: Color × Strength, each constant or
    varying over the surface (an image, a colour attribute, a baked graph: Cycles' Emission Color from a
    texture; both per point: their product per point); None where nothing is emitted.  Cycles clamps neither; a negative
    strength or colour emits nothing, as a zero one."""
    from ...engine.textures.inputs import ColouredEmission, ProductEmission, textured_emission
    r = Reader(mat, node, warnings, bake)
    colour = r.rgb_or_texture(colour_name, -math.inf)
    if r._socket(strength_name).is_linked:
        source = r.texture(strength_name)          # a strength per point (not mapped: its own value, warned)
        if source is not None:                     # × the colour, constant or per point
            emission = ProductEmission(colour, source) if isinstance(colour, TextureInput) else \
                ColouredEmission(source, colour)
            return emission if emission.hi > 0 else None
        strength = r._checked_float(strength_name, -math.inf, math.inf)
    else:
        strength = r.float(strength_name)
    if strength <= 0:
        return None
    if isinstance(colour, TextureInput):
        emission = textured_emission(colour, strength, f"material {mat!r}.{node.name}.{colour_name}")
        return emission if emission.hi > 0 else None
    colour = [max(c, 0.0) for c in colour]
    if max(colour) <= 0:
        return None
    return RGBIlluminantSpectrum(colour, strength)


def _weighted_emission(parts, mat, node, warnings):
    """One emission from (weight, emission) pairs of a shader mix: constant ones add up; a textured one
    is kept, scaled by its weight (with others beside it, only it: one warning)."""
    from ...engine.textures.inputs import TexturedSpectrum
    parts = [(w, e) for w, e in parts if e is not None and w > 0]
    textured = [(w, e) for w, e in parts if isinstance(e, TexturedSpectrum)]
    if textured:
        if len(parts) > 1:
            warnings.append(f"material {mat!r}: {node.name!r} mixes a textured emission with other emission; only "
                            "the textured one is rendered")
        w, e = textured[0]
        if hasattr(e, "scaled"):            # a strength per point (inputs.ColouredEmission, ProductEmission)
            return e.scaled(w)
        src = e.source
        scaled = TextureInput(src.texture, src.channel, src.scale * w, src.offset * w, src.power)
        return TexturedSpectrum(scaled, "illuminant", e.clip)
    rgb = sum((w * e.linear_srgb() for w, e in parts), np.zeros(3))
    return RGBIlluminantSpectrum(list(rgb), 1.0) if rgb.max() > 0 else None


def surface_bsdf(node, mat, warnings, depth=0, bake=None):
    """(BSDF, emission spectrum or None) for the shader node plugged into a Surface (with its
    normal or bump map, if any)."""
    bsdf, emission = _surface_bsdf(node, mat, warnings, depth, bake)
    if node.bl_idname in NORMAL_SHADERS:
        bsdf = with_shading_normal(bsdf, node, mat, warnings)
    return bsdf, emission


#: converted shaders whose Normal input is exported
NORMAL_SHADERS = ("ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic",
                   "ShaderNodeBsdfMetallic", "ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction",
                   "ShaderNodeBsdfPrincipled", "ShaderNodeBsdfSheen")


def _surface_bsdf(node, mat, warnings, depth, bake=None):
    kind = node.bl_idname
    if kind == "PolarShaderNodeBSDF":
        return polar_node_bsdf(node, mat, warnings, depth, bake, surface_bsdf=surface_bsdf), None
    r = Reader(mat, node, warnings, bake)
    if kind == "ShaderNodeBsdfDiffuse":
        colour = r.rgb_or_texture("Color", 0.0, 1.0)
        sigma = r.number_or_texture("Roughness")          # (a σ per point: Oren–Nayar, Lambert where 0)
        if isinstance(sigma, TextureInput) or sigma > 0:       # Cycles' Oren–Nayar (Fujii/EON) above roughness 0
            return _textured_model("oren_nayar", {"albedo": colour, "roughness": sigma}, mat, node), None
        return lambert(colour, mat, node), None
    if kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
        m, _ = r.roughness_or_texture("Roughness")
        return _conductor_from_colour(r, "Color", None, m, mat, node, warnings, mode="constant"), None
    if kind == "ShaderNodeBsdfMetallic":
        m, _ = r.roughness_or_texture("Roughness")
        if getattr(node, "fresnel_type", "") == "PHYSICAL_CONDUCTOR":
            n, k = r.rgb("IOR", 0.0), r.rgb("Extinction", 0.0)
            n = [max(c, IOR_MIN) for c in n]                 # Cycles' least index
            return _facet_conductor(n, k, m, mat, node, warnings, _film(r),
                                    _node_anisotropy(r, node, mat, warnings, m, kind)), None
        return _conductor_from_colour(r, "Base Color", "Edge Tint", m, mat, node, warnings, mode="f82"), None
    if kind in ("ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction"):
        alpha, _ = r.roughness_or_texture("Roughness")   # α = r², IOR and α per point where linked
        colour = r.rgb_or_texture("Color", 0.0)
        distribution = getattr(node, "distribution", "")
        if kind == "ShaderNodeBsdfRefraction":           # refraction only, no Fresnel; Color is the closure's weight
            model = _textured_model("refraction", {"n": _ior_or_texture(r), "alpha": alpha, "distribution":
                                                   "beckmann" if distribution == "BECKMANN" else "ggx"}, mat, node,
                                    _GLASS_SOCKETS)
            return _tinted(model, None, colour), None
        glass = _glass(_ior_or_texture(r), alpha, distribution, _film(r), f"material {mat!r}.{node.name}")
        return _tinted(glass, colour, colour), None      # Cycles tints reflection and refraction by Color
    if kind == "ShaderNodeBsdfSheen":
        if getattr(node, "distribution", "MICROFIBER") != "MICROFIBER":
            warnings.append(f"material {mat!r}: Sheen BSDF {node.name!r} with the {node.distribution.title()} "
                            "distribution is rendered as Microfiber (Cycles' default)")
        tint = r.rgb_or_texture("Color", 0.0)
        return _textured_model("sheen", {"tint": _grey(tint), "roughness": r.number_or_texture("Roughness")},
                               mat, node), None
    if kind == "ShaderNodeBsdfPrincipled":
        emission = _emission(node, mat, warnings, "Emission Color", "Emission Strength", bake)
        bsdf = _principled(node, mat, warnings, bake)
        if emission is not None and getattr(bsdf, "role", None) in ("sheen", "coat"):
            # Cycles attenuates the Principled emission by its sheen and coat (engine.materials.mix.emission_weight)
            from ...engine.materials.mix import emission_weight
            if emission_weight(bsdf) is None:
                warnings.append(f"material {mat!r}: the emission of {node.name!r} under a coat or sheen that varies "
                                "over the surface is not attenuated by them")
            else:
                bsdf.emission_under_layers = True
        return bsdf, emission
    if kind == "ShaderNodeEmission":
        return lambert(0.0, mat, node), _emission(node, mat, warnings, bake=bake)
    if kind in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
        return _shader_mix(node, mat, warnings, depth, bake)
    if kind == "ShaderNodeBsdfTransparent":
        black = lambert(0.0, mat, node)
        if depth == 0:          # the whole surface transparent: the object passes every ray
            _white_transparent(node, mat, warnings)
            black.alpha_factor = 0.0
        else:
            warnings.append(f"material {mat!r}: Transparent BSDF {node.name!r} inside a mix other than Mix "
                            "Shader(Transparent, X) at the surface output scatters nothing here")
        return black, None
    else:
        warnings.append(f"material {mat!r}: shader {kind} is not supported; rendered as grey Lambert")
    return lambert(DEFAULT_ALBEDO, mat, node), None


def _black(bsdf) -> bool:
    """A material that scatters nothing (the black Lambert standing for an Emission shader's BSDF)."""
    albedo = getattr(bsdf, "albedo", None)
    return isinstance(bsdf, Lambert) and isinstance(albedo, ConstantSpectrum) and albedo.value == 0.0


def _transparent(node) -> bool:
    return node is not None and node.bl_idname == "ShaderNodeBsdfTransparent"


def _transparent_mix(node, shaders, mat, warnings, depth, bake):
    """(BSDF, emission) of the Mix Shader patterns that make a surface see-through, or None:

    - Mix(Transparent, X) by Light Path ▸ Is Camera Ray (glTF's KHR_materials_unlit): the camera sees X,
      every other ray passes through — X with ``camera_only`` (the exporter hides the object from shadow and
      indirect rays, so that its emission lights nothing, as in Cycles);
    - Mix(Transparent, X) or Mix(X, Transparent) by a constant or per-point Factor (an alpha mix): X with
      ``alpha_factor`` the weight of X (the object's pass-through alpha, engine.render.visibility; the
      Transparent BSDF's colour must be white, else one warning and its luminance).
    A Transparent BSDF anywhere else scatters nothing (one warning).  X is read at the same depth: its
    own see-through pattern (an alpha mix of an unlit mix) still applies to the material."""
    if node.bl_idname != "ShaderNodeMixShader" or len(shaders) != 2:
        return None
    first, second = (follow(s) for s in shaders)
    if not (_transparent(first) or _transparent(second)) or (_transparent(first) and _transparent(second)):
        return None
    other = second if _transparent(first) else first
    clear = first if _transparent(first) else second
    if depth > 0:           # nested: the Transparent BSDF scatters nothing (it warns as a shader)
        return None
    fac_node, fac_out = linked_source(node.inputs[0])
    if fac_node is not None and fac_node.bl_idname == "ShaderNodeLightPath":
        if fac_out.name != "Is Camera Ray" or not _transparent(first):
            warnings.append(f"material {mat!r}: Light Path ▸ {fac_out.name} drives {node.name!r}; rendered as "
                            "the camera sees it")
        bsdf, emission = (surface_bsdf(other, mat, warnings, depth, bake) if other is not None
                          else (lambert(0.0, mat, node), None))
        bsdf.camera_only = True         # (hidden from indirect rays, its emission lights nothing: as Cycles)
        return bsdf, emission
    _white_transparent(clear, mat, warnings)
    r = Reader(mat, node, warnings, bake)
    fac = _fraction(r, node.inputs[0].name)
    weight = _weight(fac, complement=not _transparent(first))       # the weight of X
    bsdf, emission = (surface_bsdf(other, mat, warnings, depth, bake) if other is not None
                      else (lambert(0.0, mat, node), None))
    bsdf.alpha_factor = weight
    return bsdf, emission


def _white_transparent(node, mat, warnings):
    """One warning where a Transparent BSDF's colour is not white (its tint is not simulated)."""
    colour = [float(c) for c in node.inputs["Color"].default_value[:3]]
    if node.inputs["Color"].is_linked or colour != [1.0, 1.0, 1.0]:
        warnings.append(f"material {mat!r}: the colour of Transparent BSDF {node.name!r} is not simulated; light "
                        "passes untinted")


def _shader_mix(node, mat, warnings, depth, bake):
    """(BSDF, emission) of a Mix Shader (weights 1 − Factor and Factor, Factor clamped to [0, 1] as
    Cycles, constant or per point) or an Add Shader (weights 1 and 1): an engine Mix of the two
    shaders' BSDFs, nested mixes nesting.  An unlinked shader input adds nothing (as in Cycles).
    Emission adds up with the same weights; under a per-point Factor the emission is weighed by the
    Factor's own value (one warning: an emitter's strength does not follow a texture Factor)."""
    if depth > 32:
        raise SceneError(f"material {mat!r}", "shader mixes nest more than 32 deep")
    shaders = [s for s in node.inputs if s.type == "SHADER"]
    special = _transparent_mix(node, shaders, mat, warnings, depth, bake)
    if special is not None:
        return special
    if node.bl_idname == "ShaderNodeMixShader":
        r = Reader(mat, node, warnings, bake)
        fac = _fraction(r, node.inputs[0].name)
        weights = [_weight(fac, complement=True), _weight(fac)]
        own = [1.0 - fac, fac] if not isinstance(fac, TextureInput) else None
    else:
        weights = own = [1.0, 1.0]
    parts, part_weights, emitted = [], [], []
    for i, (sock, w) in enumerate(zip(shaders, weights)):
        child = follow(sock)
        if child is None or (isinstance(w, float) and w < WEIGHT_CUTOFF):
            continue
        bsdf, emission = surface_bsdf(child, mat, warnings, depth + 1, bake)
        if not _black(bsdf):            # an Emission shader scatters nothing
            parts.append(bsdf)
            part_weights.append(w)
        if emission is not None:
            if own is None:
                r._constant(node.inputs[0].name)       # warns: emission weighed by the Factor's own value
                value = float(node.inputs[0].default_value)
                wk = min(max(value, 0.0), 1.0)
                wk = 1.0 - wk if i == 0 else wk
            else:
                wk = own[i]
            emitted.append((wk, emission))
    emission = _weighted_emission(emitted, mat, node, warnings)
    if not parts:
        return lambert(0.0, mat, node), emission
    if len(parts) == 1 and isinstance(part_weights[0], float) and part_weights[0] == 1.0:
        return parts[0], emission
    decl = MODELS["mix"]
    return decl.build(decl.values({"weights": part_weights}, f"material {mat!r}.{node.name}"), materials=parts), \
        emission
