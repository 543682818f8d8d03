"""Shade several materials in one call where a model supports it (fewer, larger batches).

``shading_groups(materials)`` returns (shaders, group_of, slot_of): ``shaders[g]`` is the BSDF
that shades group g, ``group_of[m]`` the group of material index m and ``slot_of[m]`` its slot
within that group (passed to the shader as ``ShadingPoint.material``).  Today Lambert materials
with constant or RGB albedos form one LambertSet; every other material is its own group.
"""

from __future__ import annotations

import numpy as np

from .lambert import LambertSet


def shading_groups(materials: list):
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
    for i, m in enumerate(materials):
        if i not in batched:
            group_of[i] = len(shaders)
            shaders.append(m)
    return shaders, group_of, slot_of
