"""The parameters of each polarising model as node sockets (pure data, no bpy).

Socket tuples: (name, socket type, default, min, max, description).  The names are what the
exporter reads; keep them stable (saved files refer to them).  Enum numbers are stable too.
"""

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

_N = ("n", "FLOAT", 0.47, 0.01, 20.0, "Real part of the complex index of refraction")
_K = ("k", "FLOAT", 2.4, 0.0, 50.0, "Extinction coefficient κ ≥ 0 (imaginary part of the index)")
_IOR = ("IOR", "FLOAT", 1.5, 1.0001, 5.0, "Index of refraction of the material (outside: 1)")

MODEL_SOCKETS = {
    "LAMBERT": [("Albedo", "COLOR", (0.8, 0.8, 0.8), 0.0, 1.0, "Diffuse reflectance (linear sRGB)")],
    "CONDUCTOR": [_N, _K],
    "DIELECTRIC": [_IOR],
    "BLACK_GLASS": [_IOR],
    "TORRANCE_SPARROW": [_N, _K,
                         ("Roughness", "FLOAT", 0.1, 0.0, 5.0, "Beckmann rms slope m (Mitsuba's α); 0 = smooth mirror"),
                         ("Diffuse", "COLOR", (0.0, 0.0, 0.0), 0.0, 1.0,
                          "Albedo of an added Lambertian (depolarising) part")],
    "HTSG": [("n", "FLOAT", 0.88, 0.01, 20.0, "Real part of the complex index"),
             ("k", "FLOAT", 6.15, 0.0, 50.0, "Extinction coefficient κ ≥ 0"),
             ("Sigma0", "FLOAT", 0.18, 0.0, 100.0, "Surface height rms deviation σ₀ in µm"),
             ("Tau", "FLOAT", 3.0, 1e-3, 1000.0, "Autocorrelation length τ in µm"),
             ("Diffuse", "COLOR", (0.0, 0.0, 0.0), 0.0, 1.0, "Albedo of the uniform diffuse term")],
    "WEIDLICH_WILKIE": [("Coat IOR", "FLOAT", 1.5, 1.0, 5.0, "Index of the coat"),
                        ("Coat Thickness", "FLOAT", 1.0, 0.0, 1e6, "Coat thickness (any unit; only "
                         "thickness × absorption matters)"),
                        ("Coat Absorption", "COLOR", (0.0, 0.0, 0.0), 0.0, 1e6,
                         "Absorption coefficient per unit thickness (linear sRGB)"),
                        ("Coat Roughness", "FLOAT", 0.0, 0.0, 5.0, "Beckmann rms slope of the coat surface "
                         "(0 = smooth)"),
                        ("Base", "SHADER", None, None, None, "The material under the coat: another "
                         "Polarising BSDF (default: white Lambert)")],
}
