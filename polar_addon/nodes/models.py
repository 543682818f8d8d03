"""The parameters of each polarising model as node sockets (pure data, no bpy).

Socket tuples: (name, socket type, default, min, max, description), generated from the
parameter declarations of engine.materials (a parameter's ``socket``).  The names are what the
exporter reads; keep them stable (saved files refer to them).  Enum numbers are stable too.
"""

from ...engine.materials.catalogue import MODELS

MODEL_ITEMS = [
    ("LAMBERT", "Lambert", "Ideal depolariser: diffuse, unpolarised reflection (albedo/π)", 0),
    ("CONDUCTOR", "Fresnel Conductor", "Smooth metal mirror with a complex index n + ik", 1),
    ("DIELECTRIC", "Fresnel Dielectric", "Smooth glass-like interface: reflection, refraction, total "
                                         "internal reflection", 2),
    ("BLACK_GLASS", "Black Glass", "Smooth dielectric surface whose transmitted light is absorbed "
                                   "(polarises strongly near Brewster's angle)", 3),
    ("TORRANCE_SPARROW", "Torrance–Sparrow", "Rough microfacet reflection (Beckmann facets, complex index) "
                                            "with an optional Lambertian part", 4),
    ("HTSG", "He–Torrance–Sillion–Greenberg", "Physically based rough surface (σ₀, τ in µm), "
                                              "wavelength dependent", 5),
    ("WEIDLICH_WILKIE", "Weidlich–Wilkie Layered", "A clear or absorbing coat over a base material "
                                                   "(plug another Polarising BSDF into Base)", 6),
    ("ROUGH_DIELECTRIC", "Rough Dielectric", "Frosted glass: microfacet reflection and refraction, "
                                             "polarising per facet", 7),
    ("THIN_DIELECTRIC", "Thin Dielectric", "Thin pane (window, cover glass): two interfaces, no refraction "
                                           "offset", 8),
]

METAL_ITEMS = [
    ("CUSTOM", "Custom", "Use the n and k inputs", 0),
    ("Au", "Gold", "Measured gold (Palik)", 1),
    ("Ag", "Silver", "Measured silver (Palik)", 2),
    ("Al", "Aluminium", "Measured aluminium (Palik)", 3),
    ("Cu", "Copper", "Measured copper (Palik)", 4),
    ("Cr", "Chromium", "Measured chromium (Palik)", 5),
]

DIELECTRIC_PRESETS = [
    ("CUSTOM", "Custom", "Use the IOR input", 0, None),
    ("GLASS", "Glass (1.5)", "Crown glass", 1, 1.5),
    ("WATER", "Water (1.33)", "Water", 2, 1.333),
    ("DIAMOND", "Diamond (2.42)", "Diamond", 3, 2.418),
    ("ACRYLIC", "Acrylic (1.49)", "PMMA", 4, 1.49),
    ("SAPPHIRE", "Sapphire (1.77)", "Sapphire (ordinary ray)", 5, 1.77),
]

SHADOWING_ITEMS = [
    ("TS", "Torrance–Sparrow", "V-cavity shadowing of the thesis (default)", 0),
    ("SMITH", "Smith", "Smith shadowing for Beckmann facets (as Mitsuba 3)", 1),
]

WW_FORM_ITEMS = [
    ("ENERGY", "Energy Conserving", "Weidlich–Wilkie with the project's energy-conserving fix", 0),
    ("PUBLISHED", "Published", "Weidlich–Wilkie as published (gains energy at grazing angles)", 1),
]


def declared_sockets(decl) -> list:
    """Socket tuples of one model in declaration order (a coats parameter contributes its coat's sockets)."""
    out = []
    for p in decl.parameters:
        if p.kind == "coats":
            out += declared_sockets(p.members)
        elif p.socket is not None:
            out.append(p.socket.as_tuple())
    return out


#: Polarising BSDF model enum → the declarations of engine.materials (one group of sockets each).
NODE_MODELS = {decl.node: decl for decl in MODELS.values() if decl.node}
MODEL_SOCKETS = {model: declared_sockets(decl) for model, decl in NODE_MODELS.items()}
