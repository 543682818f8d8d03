"""Simulate only the effects a scene calls for: pick the cheapest exact transport.

Without polarised sources, polarisation can only be created by materials:

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

Polarised sources (lights and emitters with a ``polarisation``, the polarised sky: ``source_needs``) count
like materials: a linearly polarised source needs at least linear Stokes, a circularly polarised one full
Stokes.  Asking for a smaller transport explicitly renders them unpolarised, with a warning in the reason.

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


def resolve_transport(requested: str, materials: Mapping[str, BSDF], used: set[str] | None = None,
                      sources: tuple[str, list[str]] = ("off", []),
                      media: tuple[str, list[str]] = ("off", []), world=None) -> tuple[str, str]:
    """The transport to run for a requested mode ("auto" or explicit) and why (absorbing interiors
    listed after it: they never change the choice).  ``sources``: (the transport the scene's polarised
    sources need, their names) — ``source_needs``; ``media``: the same for the participating media's phase
    functions — ``media_needs``; ``world``: the world medium (an Interior, or None), named with the media."""
    if requested == "auto" and TRANSPORT_SIZES[media[0]] > TRANSPORT_SIZES[choose_transport(materials, used)[0]] \
            and TRANSPORT_SIZES[media[0]] > TRANSPORT_SIZES[sources[0]]:
        what = "retard (full Stokes)" if media[0] == "full" else "polarise (linear Stokes)"
        return media[0], (f"auto → {media[0]} Stokes: the phase functions of {_list(media[1])} {what}"
                          + absorption_note(materials, used, world))
    need, names = sources
    if requested != "auto":
        note = ""
        if TRANSPORT_SIZES[requested] < TRANSPORT_SIZES[need]:
            lost = "polarisation" if requested == "off" else "circular polarisation"
            note = f"; the {lost} of {_list(names)} is not simulated in this transport"
        return requested, f"{requested} (requested)" + note + absorption_note(materials, used, world)
    mode, reason = choose_transport(materials, used)
    if TRANSPORT_SIZES[need] > TRANSPORT_SIZES[mode]:
        what = "circularly" if need == "full" else "linearly"
        mode, reason = need, (f"{'full' if need == 'full' else 'linear'} Stokes: {_list(names)} "
                              f"emit{'s' if len(names) == 1 else ''} {what} polarised light")
    elif names:
        reason += f"; polarised sources: {_list(names)}"
    return mode, f"auto → {reason}" + absorption_note(materials, used, world)


def source_needs(scene) -> tuple[str, list[str]]:
    """(the transport the scene's polarised sources need: "off", "linear" or "full", their names): lights and
    emissive meshes with a ``polarisation`` (engine.polarisation.sources), an environment with polarisation."""
    need, names = "off", []
    items = [(f"lights[{i}]", getattr(light, "polarisation", None)) for i, light in enumerate(scene.lights)]
    items += [(mesh.name, getattr(mesh, "emission_polarisation", None))
              for mesh in scene.meshes if mesh.emission is not None]
    for name, pol in items:
        kind = getattr(pol, "transport_need", None)
        if pol is None or kind in (None, "off"):
            continue
        names.append(name)
        if TRANSPORT_SIZES[kind] > TRANSPORT_SIZES[need]:
            need = kind
    return need, names


def media_needs(scene, used: set[str] | None = None) -> tuple[str, list[str]]:
    """(the transport the participating media's phase functions need: "off", "linear" (POLARISING: Rayleigh)
    or "full" (RETARDING: Lorenz–Mie), the media's names): the interiors of the ``used`` materials and the
    world medium ``scene.medium``."""
    items = [(name, interior_of(m)) for name, m in scene.materials.items() if used is None or name in used]
    items.append(("world medium", getattr(scene, "medium", None)))
    need, names = "off", []
    for name, interior in items:
        phase = getattr(interior, "phase", None)
        if phase is None or not interior.tracked:
            continue
        kind = ("full" if phase.flags.has(BSDFFlags.RETARDING) else "linear" if phase.flags.has(BSDFFlags.POLARISING)
                else "off")
        if kind != "off":
            names.append(name)
            need = kind if TRANSPORT_SIZES[kind] > TRANSPORT_SIZES[need] else need
    return need, names


def absorption_note(materials: Mapping[str, BSDF], used: set[str] | None = None, world=None) -> str:
    """"; absorbing interiors: 'glass' (…)" for the ``used`` materials with an interior and the world medium
    ``world`` (an Interior or None), else ""."""
    interiors = [(n, interior_of(materials[n])) for n in sorted(used if used is not None else materials)]
    interiors += [("world medium", world)] if world is not None else []
    names = [n for n, it in interiors if it is not None and not it.tracked]
    scattering = [n for n, it in interiors if it is not None and it.tracked]
    note = ""
    if names:
        note = (f"; absorbing interiors: {_list(names)} (Beer–Lambert exp(−σ_a·d) per wavelength inside closed "
                "meshes, polarisation unchanged)")
    if scattering:
        note += f"; participating media: {_list(scattering)} (delta tracking, phase functions at medium vertices)"
    return note


def _list(names: list[str]) -> str:
    shown = ", ".join(repr(n) for n in names[:3])
    return shown + (f" and {len(names) - 3} more" if len(names) > 3 else "")
