"""Every material model's declaration, and models by name from flat ``NAME=VALUE`` parameters.

``MODELS`` lists the declarations (engine.materials.parameters) of all models, in the order
scene files and the Blender node show them.  ``make_model`` is how ``python -m engine mueller``
(and the oracle tests) instantiate a model in isolation, through the same builders and checks as
the scene loader; scene files nest coats and bases, the flat form names them ``coat_…`` (one
coat) and ``base_…`` (a Lambertian base).
"""

from __future__ import annotations

from . import (black_glass, conductor, dielectric, filter_sheet, htsg, lambert, mix, oren_nayar, principled, refraction,
               sheen, rough_dielectric, thin_dielectric, thin_film, torrance_sparrow, weidlich_wilkie)
from .parameters import ModelDeclaration, Parameter
from ..errors import SceneError

#: All declarations, keyed by the scene file's material type.
MODELS: dict[str, ModelDeclaration] = {d.name: d for d in (
    lambert.DECLARATION, oren_nayar.DECLARATION, conductor.DECLARATION, dielectric.DECLARATION, black_glass.DECLARATION,
    torrance_sparrow.DECLARATION, htsg.DECLARATION, weidlich_wilkie.DECLARATION,
    filter_sheet.POLARISER, filter_sheet.RETARDER, rough_dielectric.DECLARATION,
    thin_dielectric.DECLARATION, thin_film.DECLARATION, mix.DECLARATION, principled.DECLARATION, sheen.DECLARATION,
    refraction.DECLARATION)}

#: Flat names of nested parts: a layered model's coats (one coat) and its base (a Lambert).
_FLAT_PARTS = {"coats": ("coat_", weidlich_wilkie.COAT), "material": ("base_", lambert.DECLARATION)}


def _flat_parameters(decl: ModelDeclaration) -> dict[str, tuple[str, Parameter]]:
    """flat name → (prefix, Parameter) of one catalogue model."""
    out = {}
    for p in decl.parameters:
        if p.kind in _FLAT_PARTS:
            prefix, part = _FLAT_PARTS[p.kind]
            out.update({prefix + q.name: (prefix, q) for q in part.parameters})
        else:
            out[p.name] = ("", p)
    return out


#: Catalogue models: name → (declaration, {flat parameter name: (prefix, Parameter)}).
CATALOGUE = {d.catalogue: (d, _flat_parameters(d)) for d in MODELS.values() if d.catalogue}

#: model name → {parameter: (default, description)}
MODEL_PARAMETERS = {name: {key: (None if p.required else p.default, p.help_text(prefix))
                          for key, (prefix, p) in flat.items()}
                    for name, (_, flat) in CATALOGUE.items()}


def parameter_help() -> str:
    """The catalogue's models and their parameters, one per line (``mueller --help``)."""
    lines = ["models and parameters (--param NAME=VALUE):"]
    for name, (decl, flat) in CATALOGUE.items():
        lines.append(f"  {name}: {decl.title} ({decl.doc})")
        lines += [f"    {key}: {p.help_text(prefix)}" for key, (prefix, p) in flat.items()]
    return "\n".join(lines)


def make_model(name: str, params: dict, field: str = "param"):
    """A BSDF instance of catalogue model ``name`` with string or numeric parameters."""
    if name not in CATALOGUE:
        raise SceneError("model", f"unknown model {name!r} (available: {', '.join(CATALOGUE)})")
    decl, flat = CATALOGUE[name]
    unknown = sorted(set(params) - set(flat))
    if unknown:
        raise SceneError(f"{field}.{unknown[0]}", f"is not a parameter of {name} (parameters: {', '.join(flat)})")
    parts = {}
    for p in decl.parameters:
        if p.kind in _FLAT_PARTS:
            prefix, part = _FLAT_PARTS[p.kind]
            built = part.build(part.values(params, field, text=True, prefix=prefix))
            parts[p.name] = [built] if p.kind == "coats" else built
    return decl.build(decl.values(params, field, text=True), **parts)
