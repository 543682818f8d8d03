"""Shade several materials in one call where possible (fewer, larger batches).

``shading_groups(materials)`` returns (shaders, group_of, slot_of): ``shaders[g]`` is the BSDF
that shades group g, ``group_of[m]`` the group of material index m and ``slot_of[m]`` its slot
within that group (passed to the shader as ``ShadingPoint.material``).  Lambert materials with
constant or RGB albedos form one LambertSet (one vectorised shader); the other materials that are
not delta-only form one MaterialSet per ``set_key`` (each point shaded by its own member, but light
sampling, shadow rays and throughput updates once for the whole set); delta-only materials (one-step
scatter) stay groups of their own.  ``batch=False`` gives every material but the LambertSet's its own
group (the per-material groups, for comparison).
"""

from __future__ import annotations

import numpy as np

from .lambert import LambertSet
from .material_set import MaterialSet


def set_key(m):
    """What the members of one MaterialSet share (what the integrator reads from a group's shader as a whole),
    or None: the material is shaded alone (delta-only materials have their own one-step scatter; Lambert
    materials have their own fused next-event estimation, ``direct_light``; pseudo-materials that the integrator
    tells apart by type, ``shade_alone``)."""
    if m.flags.is_delta_only or getattr(m, "direct_light", None) is not None or getattr(m, "shade_alone", False):
        return None
    return (bool(m.radiance_scaling), bool(m.flags.transmits))


def shading_groups(materials: list, batch: bool = True):
    """(shaders list, group_of (M,) int64, slot_of (M,) int64) for the material list."""
    group_of = np.zeros(len(materials), np.int64)
    slot_of = np.zeros(len(materials), np.int64)
    shaders = []
    diffuse = [i for i, m in enumerate(materials) if LambertSet.batchable(m)]
    batched = set(diffuse) if len(diffuse) >= 2 else set()
    if batched:
        group_of[diffuse] = 0
        slot_of[diffuse] = np.arange(len(diffuse))
        shaders.append(LambertSet([materials[i] for i in diffuse]))
    sets: dict = {}
    if batch:
        for i, m in enumerate(materials):
            key = set_key(m) if i not in batched else None
            if key is not None:
                sets.setdefault(key, []).append(i)
    members = {i for idx in sets.values() if len(idx) >= 2 for i in idx}
    for i, m in enumerate(materials):
        if i in batched or i in members:
            continue
        group_of[i] = len(shaders)
        shaders.append(m)
    for idx in sets.values():
        if len(idx) >= 2:
            group_of[idx] = len(shaders)
            slot_of[idx] = np.arange(len(idx))
            shaders.append(MaterialSet([materials[i] for i in idx]))
    return shaders, group_of, slot_of
