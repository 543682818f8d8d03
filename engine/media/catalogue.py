"""Every phase function's declaration, phase functions by name from ``NAME=VALUE`` parameters, and the
table of phase matrices that ``python -m engine mueller`` prints for them.

As engine.materials.catalogue for the material models: the declarations (engine.materials.parameters)
validate the parameters and build the phase functions; ``make_phase`` is what the command line (and
tests) use.
"""

from __future__ import annotations

import numpy as np

from . import cycles_mie, draine, fournier_forand, henyey_greenstein, mie, rayleigh
from ..errors import SceneError
from ..materials.evaluate import cos_sin_deg
from ..materials.parameters import ModelDeclaration

#: All phase-function declarations, keyed by name.
PHASE_MODELS: dict[str, ModelDeclaration] = {d.name: d for d in (
    rayleigh.DECLARATION, mie.DECLARATION, henyey_greenstein.DECLARATION, fournier_forand.DECLARATION,
    draine.DECLARATION, cycles_mie.DECLARATION)}


def phase_parameter_help() -> str:
    """The phase functions and their parameters, one per line (``mueller --help``)."""
    lines = ["phase functions (--model NAME --scattering-angle DEG, --param NAME=VALUE):"]
    for name, decl in PHASE_MODELS.items():
        lines.append(f"  {name}: {decl.title} ({decl.doc})")
        lines += [f"    {p.name}: {p.help_text()}" for p in decl.parameters]
    return "\n".join(lines)


def make_phase(name: str, params: dict, field: str = "param", text: bool = True):
    """A phase function (engine.media.phase.PhaseFunction) of model ``name`` with string (``text``: the
    command line's NAME=VALUE) or scene-file values."""
    if name not in PHASE_MODELS:
        raise SceneError("model", f"unknown phase function {name!r} (available: {', '.join(PHASE_MODELS)})")
    decl = PHASE_MODELS[name]
    unknown = sorted(set(params) - set(decl.names()))
    if unknown:
        raise SceneError(f"{field}.{unknown[0]}", f"is not a parameter of {name} (parameters: "
                                                 f"{', '.join(decl.names())})")
    return decl.build(decl.values(params, field, text=text))


def phase_matrices_at(phase, angles_deg, wavelength_nm: float = 550.0) -> dict:
    """{"mueller": [4×4 per angle] (1/sr), "pdf": [sampling pdf per angle] (1/sr), "dolp_unpolarised":
    [DoLP of scattered unpolarised light]} at scattering angles Θ (degrees), in the scattering-plane
    frames (x ⟂ the scattering plane on both beams)."""
    mu = np.array([cos_sin_deg(a)[0] for a in angles_deg], dtype=np.float64)
    lam = np.full(mu.shape, float(wavelength_nm))
    M = phase.matrix(mu, lam)
    pdf = phase.pdf_mu(mu, lam)
    dolp = np.hypot(M[..., 1, 0], M[..., 2, 0]) / np.where(M[..., 0, 0] > 0, M[..., 0, 0], 1.0)
    return {"mueller": M.tolist(), "pdf": pdf.tolist(), "dolp_unpolarised": dolp.tolist()}
