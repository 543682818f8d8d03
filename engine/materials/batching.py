"""Shade several materials in one call where possible (fewer, larger batches).

``shading_groups(materials)`` returns (shaders, group_of, slot_of): ``shaders[g]`` is the BSDF
that shades group g, ``group_of[m]`` the group of material index m and ``slot_of[m]`` its slot
within that group (passed to the shader as ``ShadingPoint.material``).  Lambert materials with
constant or RGB albedos form one LambertSet (one vectorised shader); the other materials that are
not delta-only form one MaterialSet per ``set_key`` (each point shaded by its own member, but light
sampling, shadow rays and throughput updates once for the whole set); delta-only materials (one-step
scatter) stay groups of their own.  ``batch=False`` gives every material but the LambertSet's its own
group (the per-material groups, for comparison).

Materials of one set that are the same model with the same parameters (``same_material``: an exported glTF
sample's 18 emissive variants share 2 BSDFs, their emission being lights) share one member slot, so each
distinct BSDF runs once per bounce over all its points: per point the same arithmetic (bit-identical images),
without the per-member calls (SpecGlossEmission: 17 members → 2); so do such twins among the materials shaded
alone (AttenuationTest: 18 delta-only glasses → 10 groups).
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
    return (bool(m.radiance_scaling), bool(m.flags.transmits), bool(m.geometric_sides))


#: the engine's package ("engine", or "polar_render.engine" in the extension): its objects are compared field by field
_ENGINE = __name__.rsplit(".materials", 1)[0] + "."
#: arrays with more elements are compared by identity only (a texture's pixels: shared objects, or different)
_COMPARED_ELEMENTS = 4096


def same_material(a, b) -> bool:
    """Whether materials ``a`` and ``b`` are the same model with the same parameters: the same type and, field by
    field (recursively, through the engine's objects: spectra, textures' inputs, wrapped models), equal numbers,
    strings and small arrays; large arrays, functions and objects of other packages only when the same object.  Caches a
    class fills on first use (``_cached_fields``) are not compared.  False where unsure: materials then stay apart."""
    return _same(a, b, set())


def object_fields(obj) -> dict:
    """An object's fields by name (``vars`` and every class's ``__slots__``), the caches its class fills on first
    use (``_cached_fields``) as None, as if not filled yet: what a material is, not what it has computed (also
    engine.render.resume.scene_fingerprint's)."""
    fields = dict(vars(obj)) if hasattr(obj, "__dict__") else {}
    for cls in type(obj).__mro__:
        for name in getattr(cls, "__slots__", ()):
            if hasattr(obj, name):
                fields[name] = getattr(obj, name)
    for name in getattr(type(obj), "_cached_fields", ()):
        if name in fields:
            fields[name] = None
    return fields


def bsdfs_within(bsdf) -> list:
    """Every BSDF reachable from ``bsdf`` (itself first) through its fields (``object_fields``) and the lists,
    tuples and dicts among them — a mixture's components, a layer, a wrapper's base —, each once."""
    from .base import BSDF
    found, seen = [], set()

    def walk(x) -> None:
        if id(x) in seen:
            return
        seen.add(id(x))
        if isinstance(x, (list, tuple)):
            for v in x:
                walk(v)
        elif isinstance(x, dict):
            for v in x.values():
                walk(v)
        elif isinstance(x, BSDF):
            found.append(x)
            for v in object_fields(x).values():
                walk(v)
    walk(bsdf)
    return found


def _same(a, b, seen: set) -> bool:
    if a is b:
        return True
    if type(a) is not type(b):
        return False
    if a is None or isinstance(a, (bool, int, float, complex, str, bytes, np.number, np.bool_)):
        return bool(a == b)
    if isinstance(a, np.ndarray):
        return (a.shape == b.shape and a.dtype == b.dtype and a.dtype != object and a.size <= _COMPARED_ELEMENTS
                and bool(np.array_equal(a, b)))
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y, seen) for x, y in zip(a, b))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k], seen) for k in a)
    if isinstance(a, (set, frozenset)):
        return a == b
    if not type(a).__module__.startswith(_ENGINE):
        return False                                # functions, classes, others' objects: only the same object
    if (id(a), id(b)) in seen:                      # a cycle: equal unless a field on the way differs
        return True
    seen.add((id(a), id(b)))
    fa, fb = object_fields(a), object_fields(b)
    return fa.keys() == fb.keys() and all(_same(fa[k], fb[k], seen) for k in fa)


def _distinct(materials: list, idx: list) -> tuple[list, list]:
    """(indices of the distinct materials among ``idx`` in order, each index's slot among them)."""
    first, slots = [], []
    for i in idx:
        slot = next((k for k, j in enumerate(first) if same_material(materials[i], materials[j])), None)
        if slot is None:
            slot = len(first)
            first.append(i)
        slots.append(slot)
    return first, slots


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
    alone = []                  # the first of each distinct material shaded alone (batch: its twins join its group)
    for i, m in enumerate(materials):
        if i in batched or i in members:
            continue
        twin = None
        if batch and not getattr(m, "shade_alone", False):
            twin = next((j for j in alone if same_material(m, materials[j])), None)
            if twin is None:
                alone.append(i)
        if twin is not None:
            group_of[i] = group_of[twin]
            continue
        group_of[i] = len(shaders)
        shaders.append(m)
    for idx in sets.values():
        if len(idx) >= 2:
            first, slots = _distinct(materials, idx)
            group_of[idx] = len(shaders)
            slot_of[idx] = slots
            shaders.append(MaterialSet([materials[i] for i in first]) if len(first) >= 2 else materials[first[0]])
    return shaders, group_of, slot_of
