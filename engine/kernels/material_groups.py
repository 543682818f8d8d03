"""The hit paths of a bounce sorted by material group, in one compiled pass.

The path tracer shades the paths of each material group together (engine.materials.batching:
``group_of[m]`` is the group of material m).  Per bounce it needs every path's material index and,
per group, the ascending indices of its paths (np.nonzero(grp == g)).  In NumPy that is a gather of
the triangles' materials, a gather of their groups, a bincount and one pass per group, each over
the whole batch with the GIL held; here one loop and a stable counting sort.
"""

from __future__ import annotations

import numpy as np

from . import jit, twin


def material_groups_numpy(prim, tri_material, group_of, n_groups):
    """(mat (n,): material of each hit triangle ``prim`` (n,); counts (n_groups,) int64: paths per group;
    order (n,) int64: the paths sorted by group, ascending within a group, so that group g's paths are
    order[start_g : start_g + counts[g]] with start_g = the counts of the groups before it)."""
    mat = tri_material[prim]
    grp = group_of[mat]
    counts = np.bincount(grp, minlength=n_groups).astype(np.int64)
    return mat, counts, np.argsort(grp, kind="stable").astype(np.int64)


@jit
def _material_groups_loop(prim, tri_material, group_of, mat, counts, order):
    n = prim.shape[0]
    grp = np.empty(n, np.int64)
    for j in range(n):
        m = tri_material[prim[j]]
        mat[j] = m
        g = group_of[m]
        grp[j] = g
        counts[g] += 1
    start = np.empty(counts.shape[0], np.int64)
    s = 0
    for g in range(counts.shape[0]):
        start[g] = s
        s += counts[g]
    for j in range(n):
        g = grp[j]
        order[start[g]] = j
        start[g] += 1


def material_groups_numba(prim, tri_material, group_of, n_groups):
    n = prim.shape[0]
    mat = np.empty(n, tri_material.dtype)
    counts = np.zeros(n_groups, np.int64)
    order = np.empty(n, np.int64)
    _material_groups_loop(np.ascontiguousarray(prim), np.ascontiguousarray(tri_material),
                          np.ascontiguousarray(group_of), mat, counts, order)
    return mat, counts, order


material_groups = twin(_material_groups_loop and material_groups_numba, material_groups_numpy)
