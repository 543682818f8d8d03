"""Simulate only the effects a scene calls for: pick the cheapest exact transport.

Lights are unpolarised, so polarisation can only be created by materials:

- no material changes polarisation (only depolarisers such as Lambert)
  → scalar transport ("off"): S1 = S2 = S3 = 0 exactly;
- polarisation, but no material can create a phase difference between s and
  p (no complex index κ > 0, no reachable total internal reflection, no
  retarder) → linear Stokes transport ("linear", 3×3 Mueller): S3 = 0 exactly,
  and S0..S2 are unchanged because a 3×3 block of a matrix with M_i3 = M_3i = 0
  composes exactly;
- otherwise full 4×4 Mueller transport.

Before choosing, materials are simplified where that is exact (``simplify="auto"``): layered
(Weidlich–Wilkie) coats that are index-matched to the medium above and clear are skipped
(engine.materials.simplify), which can in turn make a scene non-polarising.

Each material reports what it can do through its ``flags`` (engine.materials.flags.BSDFFlags:
POLARISING, RETARDING).  The choice comes with a human-readable reason for logs and Blender's
render stats, and is overridden by asking for "full", "linear" or "off" explicitly.

Absorbing interiors (``material.interior``, engine.scene.description.Interior) scale the Stokes
vector by exp(−σ_a d) per wavelength and so never change the choice; the reason lists them.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping

from ..materials.base import BSDF, BSDFFlags
from ..materials.simplify import simplify_material
from ..scene.description import interior_of

TRANSPORT_SIZES = {"full": 4, "linear": 3, "off": 1}


def effective_materials(materials: Mapping[str, BSDF], used: set[str] | None = None,
                        simplify: str = "auto") -> tuple[dict[str, BSDF], list[str]]:
    """({name: BSDF} with exact simplifications applied, [reasons]) for the ``used`` names.

    ``simplify``: "auto" skips index-matched clear coats; "off" renders the materials as given.
    """
    if simplify not in ("auto", "off"):
        raise ValueError(f"simplify must be 'auto' or 'off', got {simplify!r}")
    out, reasons = dict(materials), []
    if simplify == "auto":
        for name in sorted(used if used is not None else materials):
            out[name], why = simplify_material(materials[name], name)
            reasons += why
            if out[name] is not materials[name] and interior_of(materials[name]) is not None:
                # the simplified surface keeps the material's interior (on a copy: it may be shared)
                out[name] = copy.copy(out[name])
                out[name].interior = materials[name].interior
    return out, reasons


def choose_transport(materials: Mapping[str, BSDF], used: set[str] | None = None) -> tuple[str, str]:
    """(mode, reason) for the materials ``used`` (names; default all of ``materials``)."""
    names = sorted(used if used is not None else materials)
    circular = [n for n in names if materials[n].flags.has(BSDFFlags.RETARDING)]
    polarising = [n for n in names if materials[n].flags.has(BSDFFlags.POLARISING)]
    if circular:
        return "full", f"full Stokes: {_list(circular)} can create circular polarisation"
    if polarising:
        return "linear", (f"linear Stokes (S3 = 0): {_list(polarising)} polarise but nothing retards "
                          "(real indices, no total internal reflection)")
    return "off", "scalar transport (S1..S3 = 0): every material depolarises and all lights are unpolarised"


def resolve_transport(requested: str, materials: Mapping[str, BSDF], used: set[str] | None = None) -> tuple[str, str]:
    """The transport to run for a requested mode ("auto" or explicit) and why (absorbing interiors
    listed after it: they never change the choice)."""
    if requested != "auto":
        return requested, f"{requested} (requested)" + absorption_note(materials, used)
    mode, reason = choose_transport(materials, used)
    return mode, f"auto → {reason}" + absorption_note(materials, used)


def absorption_note(materials: Mapping[str, BSDF], used: set[str] | None = None) -> str:
    """"; absorbing interiors: 'glass' (…)" for the ``used`` materials with an interior, else ""."""
    names = [n for n in sorted(used if used is not None else materials) if interior_of(materials[n]) is not None]
    if not names:
        return ""
    return (f"; absorbing interiors: {_list(names)} (Beer–Lambert exp(−σ_a·d) per wavelength inside closed meshes, "
            "polarisation unchanged)")


def _list(names: list[str]) -> str:
    shown = ", ".join(repr(n) for n in names[:3])
    return shown + (f" and {len(names) - 3} more" if len(names) > 3 else "")
