"""Ray batches to and from Embree's float32 layout, in one pass each.

The renderer keeps rays as (3, N) float64 (structure of arrays); embreex takes (N, 3) float32
origins and directions and float32 maximum distances, and returns int32 triangle ids and float32
barycentrics and distances.  The conversions are plain casts (round to nearest), done here in one
compiled pass without the GIL instead of several NumPy passes.
"""

from __future__ import annotations

import numpy as np

from . import jit, twin

#: Largest ray length handed to Embree (float32; "unbounded" rays get this).
MAX_DISTANCE = 1e37


def embree_rays_numpy(o: np.ndarray, d: np.ndarray, t_max: np.ndarray | None):
    """(origins (N, 3), directions (N, 3), distances (N,) or None) in float32 for origins o and
    directions d (3, N) and ray lengths t_max (N,) (None: unbounded), lengths capped at 1e37."""
    of = np.ascontiguousarray(o.T, dtype=np.float32)
    df = np.ascontiguousarray(d.T, dtype=np.float32)
    dists = None if t_max is None else np.minimum(t_max, MAX_DISTANCE).astype(np.float32)
    return of, df, dists


@jit
def _rays_loop(o, d, t_max, has_t, of, df, dists):
    for i in range(o.shape[1]):
        for k in range(3):
            of[i, k] = np.float32(o[k, i])
            df[i, k] = np.float32(d[k, i])
        if has_t:
            t = t_max[i]
            dists[i] = np.float32(MAX_DISTANCE if t > MAX_DISTANCE else t)    # NaN stays NaN (np.minimum)


def embree_rays_numba(o: np.ndarray, d: np.ndarray, t_max: np.ndarray | None):
    n = o.shape[1]
    of, df = np.empty((n, 3), np.float32), np.empty((n, 3), np.float32)
    has_t = t_max is not None
    dists = np.empty(n if has_t else 0, np.float32)
    t = np.asarray(t_max, np.float64) if has_t else np.empty(0)
    _rays_loop(np.asarray(o, np.float64), np.asarray(d, np.float64), t, has_t, of, df, dists)
    return of, df, dists if has_t else None


embree_rays = twin(_rays_loop and embree_rays_numba, embree_rays_numpy)


def embree_hits_numpy(prim_id: np.ndarray, u: np.ndarray, v: np.ndarray, tfar: np.ndarray,
                      prims: np.ndarray | None):
    """(prim (N,) int64, u, v, t (N,) float64) from Embree's closest hits; ``prims`` maps the
    BVH's triangle ids to the scene's (None: the same), misses stay −1."""
    prim = prim_id.astype(np.int64)
    if prims is not None:
        prim = np.where(prim >= 0, prims[np.maximum(prim, 0)], -1)
    return prim, u.astype(np.float64), v.astype(np.float64), tfar.astype(np.float64)


@jit
def _hits_loop(prim_id, u, v, tfar, prims, mapped, prim, u64, v64, t64):
    for i in range(prim_id.shape[0]):
        p = np.int64(prim_id[i])
        if mapped:
            p = prims[p] if p >= 0 else -1
        prim[i] = p
        u64[i] = np.float64(u[i])
        v64[i] = np.float64(v[i])
        t64[i] = np.float64(tfar[i])


def embree_hits_numba(prim_id: np.ndarray, u: np.ndarray, v: np.ndarray, tfar: np.ndarray,
                      prims: np.ndarray | None):
    n = prim_id.shape[0]
    prim, u64, v64, t64 = np.empty(n, np.int64), np.empty(n), np.empty(n), np.empty(n)
    mapped = prims is not None
    _hits_loop(prim_id, u, v, tfar, prims if mapped else np.empty(0, np.int64), mapped, prim, u64, v64, t64)
    return prim, u64, v64, t64


embree_hits = twin(_hits_loop and embree_hits_numba, embree_hits_numpy)
