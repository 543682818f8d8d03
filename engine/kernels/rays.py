"""Ray batches to and from Embree's float32 layout, in one pass each.

The renderer keeps rays as (3, N) float64 (structure of arrays); embreex takes (N, 3) float32
origins and directions and float32 maximum distances, and returns int32 triangle ids and float32
barycentrics and distances.  The conversions are plain casts (round to nearest), done here in one
compiled pass without the GIL instead of several NumPy passes.
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner, twin

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


@jit_inner
def _store_hit(i, p, u32, v32, t32, prims, mapped, prim, u, v, t):
    """Hit i as the renderer keeps it: triangle p (−1: miss) mapped through ``prims``, float64 u, v, t."""
    if mapped:
        p = prims[p] if p >= 0 else -1
    prim[i] = p
    u[i] = np.float64(u32)
    v[i] = np.float64(v32)
    t[i] = np.float64(t32)


@jit
def _hits_loop(prim_id, u, v, tfar, prims, mapped, prim, u64, v64, t64):
    for i in range(prim_id.shape[0]):
        _store_hit(i, np.int64(prim_id[i]), u[i], v[i], tfar[i], prims, mapped, prim, u64, v64, t64)


def embree_hits_numba(prim_id: np.ndarray, u: np.ndarray, v: np.ndarray, tfar: np.ndarray,
                      prims: np.ndarray | None):
    n = prim_id.shape[0]
    prim, u64, v64, t64 = np.empty(n, np.int64), np.empty(n), np.empty(n), np.empty(n)
    mapped = prims is not None
    _hits_loop(prim_id, u, v, tfar, prims if mapped else np.empty(0, np.int64), mapped, prim, u64, v64, t64)
    return prim, u64, v64, t64


embree_hits = twin(_hits_loop and embree_hits_numba, embree_hits_numpy)


# ----------------------------------------------------------------------------- Embree called per ray

#: Float32 word offsets in Embree 4's RTCRayHit (RTCRay: org, tnear, dir, time, tfar, mask, id, flags;
#: RTCHit: Ng, u, v, primID, geomID, instID[0]); RTCRay is its first 12 words.  A packet of W rays
#: (RTCRayHitW, structure of arrays) holds field f of lane k at word f·W + k.
_TFAR, _MASK, _U, _V, _PRIM_ID, _GEOM_ID, _INST_ID = 8, 9, 15, 16, 17, 18, 19
_INVALID = 0xFFFFFFFF


@jit_inner
def _ray_setup(rh, ri, width, k, o, d, t_max, has_t, i):
    """Ray i of the (3, N) float64 batch into lane k of the RTCRayHitW ``rh`` (``width`` W lanes; 1: an
    RTCRayHit) as embreex's ``run`` sets it up (the casts of _rays_loop; tnear 0, every mask bit, time 0,
    no flags, no hit).  u and v are left as the previous query wrote them, as embreex leaves them (a miss
    keeps them)."""
    rh[k], rh[width + k], rh[2 * width + k] = np.float32(o[0, i]), np.float32(o[1, i]), np.float32(o[2, i])
    rh[3 * width + k] = 0.0
    rh[4 * width + k], rh[5 * width + k] = np.float32(d[0, i]), np.float32(d[1, i])
    rh[6 * width + k], rh[7 * width + k] = np.float32(d[2, i]), 0.0
    if has_t:
        t = t_max[i]
        rh[_TFAR * width + k] = np.float32(MAX_DISTANCE if t > MAX_DISTANCE else t)
    else:
        rh[_TFAR * width + k] = np.float32(MAX_DISTANCE)
    ri[_MASK * width + k], ri[(_MASK + 1) * width + k], ri[(_MASK + 2) * width + k] = _INVALID, 0, 0
    ri[_PRIM_ID * width + k], ri[_GEOM_ID * width + k], ri[_INST_ID * width + k] = _INVALID, _INVALID, _INVALID


@jit_inner
def _read_hit(rh, ri, width, k, j, prims, mapped, prim, u, v, t):
    """Lane k of the RTCRayHitW ``rh`` (``width`` W lanes) as hit j (_store_hit)."""
    p = ri[_PRIM_ID * width + k]
    _store_hit(j, np.int64(-1) if p == _INVALID else np.int64(p), rh[_U * width + k], rh[_V * width + k],
               rh[_TFAR * width + k], prims, mapped, prim, u, v, t)


@jit
def closest_hits_loop(intersect1, scene, rh, o, d, t_max, has_t, prims, mapped, prim, u, v, t):
    """Closest hits of the rays o, d (3, N) float64 (lengths t_max, or unbounded) by Embree's
    ``rtcIntersect1(scene, rayhit, NULL)`` (``intersect1``: its ctypes function pointer, ``scene``: the
    RTCScene handle, ``rh``: a 16-byte aligned float32 RTCRayHit buffer): the numbers of
    embree_rays → embreex's ``run(output=1)`` → embree_hits, without their arrays."""
    ri = rh.view(np.uint32)
    addr = rh.ctypes.data
    for i in range(o.shape[1]):
        _ray_setup(rh, ri, 1, 0, o, d, t_max, has_t, i)
        intersect1(scene, addr, 0)
        _read_hit(rh, ri, 1, 0, i, prims, mapped, prim, u, v, t)


@jit
def occluded_loop(occluded1, scene, rh, o, d, t_max, blocked):
    """Shadow queries by Embree's ``rtcOccluded1(scene, ray, NULL)`` as embreex's ``run(query=
    "OCCLUDED")`` makes them: blocked where Embree set tfar to −inf."""
    ri = rh.view(np.uint32)
    addr = rh.ctypes.data
    for i in range(o.shape[1]):
        _ray_setup(rh, ri, 1, 0, o, d, t_max, True, i)
        occluded1(scene, addr, 0)
        blocked[i] = rh[_TFAR] < 0


@jit_inner
def _packet_setup(rh, ri, valid, i0, o, d, t_max, has_t):
    """Rays i0, i0 + 1, … of the batch into the lanes of the packet ``rh`` (width: valid's length); lanes
    past the batch's end invalid.  Returns the number of valid lanes."""
    width = valid.shape[0]
    m = min(width, o.shape[1] - i0)
    for k in range(width):
        valid[k] = -1 if k < m else 0
        if k < m:
            _ray_setup(rh, ri, width, k, o, d, t_max, has_t, i0 + k)
    return m


@jit
def packet_queries(query, scene, valid, rh, args, o, d, t_max, has_t, shadow, prims, mapped, prim, u, v, t, blocked):
    """closest_hits_loop's (``shadow`` False: prim, u, v, t written) or occluded_loop's (True: ``blocked``
    written) queries in packets of W rays (W = len(valid): 4, 8 or 16) by Embree's ``rtcIntersectW`` /
    ``rtcOccludedW(valid, scene, rayhit, args)`` (``query``: its ctypes function pointer; ``valid``: int32
    (W,), ``rh``: float32 RTCRayHitW, both 4W-byte aligned; ``args``: an RTCIntersectArguments /
    RTCOccludedArguments buffer).  The one-ray queries' hits and answers bit for bit (measured:
    tests/render/test_accel.py)."""
    ri = rh.view(np.uint32)
    width = valid.shape[0]
    addr, vaddr, aaddr = rh.ctypes.data, valid.ctypes.data, args.ctypes.data
    for i0 in range(0, o.shape[1], width):
        m = _packet_setup(rh, ri, valid, i0, o, d, t_max, has_t)
        query(vaddr, scene, addr, aaddr)
        for k in range(m):
            if shadow:
                blocked[i0 + k] = rh[_TFAR * width + k] < 0
            else:
                _read_hit(rh, ri, width, k, i0 + k, prims, mapped, prim, u, v, t)


# ----------------------------------------------------------------------------- a box test before Embree

#: The box test's margin relative to the coordinates' size: Embree computes in float32 (rounding 2^-24 ≈ 6e-8 of the
#: coordinates), so a segment that stays farther than this from a box cannot be reported to cross a triangle in it.
BOX_MARGIN = 1e-5


def segments_near_box_numpy(o: np.ndarray, d: np.ndarray, t_max: np.ndarray, lo: np.ndarray,
                            hi: np.ndarray) -> np.ndarray:
    """(N,) bool: False only where the segment o + t·d, 0 ≤ t ≤ t_max (o, d (3, N), t_max (N,), inf: a ray) stays
    outside the box [lo, hi] (3,) widened by pad = BOX_MARGIN·(1 + max|o| + max|lo, hi|), its length widened to
    t_max·(1 + BOX_MARGIN) + pad: a slab test in float64 that Embree's float32 hits of triangles inside the box
    cannot contradict.  Segments with a NaN or an infinite origin or direction, or a NaN length, are True."""
    size = 1.0 + np.abs(o).max(axis=0) + max(float(np.abs(lo).max()), float(np.abs(hi).max()))
    pad = BOX_MARGIN * size
    t_lo = np.zeros(o.shape[1])
    t_hi = t_max * (1.0 + BOX_MARGIN) + pad
    with np.errstate(divide="ignore", invalid="ignore"):
        for k in range(3):
            a = (lo[k] - pad - o[k]) / d[k]
            b = (hi[k] + pad - o[k]) / d[k]
            flat = d[k] == 0.0
            inside = (o[k] >= lo[k] - pad) & (o[k] <= hi[k] + pad)
            t_lo = np.where(flat, np.where(inside, t_lo, np.inf), np.maximum(t_lo, np.minimum(a, b)))
            t_hi = np.where(flat, t_hi, np.minimum(t_hi, np.maximum(a, b)))
    finite = np.isfinite(o).all(axis=0) & np.isfinite(d).all(axis=0) & ~np.isnan(t_max)
    return ~finite | (t_lo <= t_hi)


@jit
def _near_box_loop(o, d, t_max, lo, hi, out):
    box = 0.0
    for k in range(3):
        box = max(box, abs(lo[k]), abs(hi[k]))
    for i in range(o.shape[1]):
        finite = not np.isnan(t_max[i])
        size = 0.0
        for k in range(3):
            finite = finite and np.isfinite(o[k, i]) and np.isfinite(d[k, i])
            size = max(size, abs(o[k, i]))
        if not finite:
            out[i] = True
            continue
        pad = BOX_MARGIN * (1.0 + size + box)
        t_lo = 0.0
        t_hi = t_max[i] * (1.0 + BOX_MARGIN) + pad
        for k in range(3):
            if d[k, i] == 0.0:
                if not (o[k, i] >= lo[k] - pad and o[k, i] <= hi[k] + pad):
                    t_lo = np.inf
            else:
                a = (lo[k] - pad - o[k, i]) / d[k, i]
                b = (hi[k] + pad - o[k, i]) / d[k, i]
                t_lo = max(t_lo, min(a, b))
                t_hi = min(t_hi, max(a, b))
        out[i] = t_lo <= t_hi


def segments_near_box_numba(o: np.ndarray, d: np.ndarray, t_max: np.ndarray, lo: np.ndarray,
                            hi: np.ndarray) -> np.ndarray:
    out = np.empty(o.shape[1], np.bool_)
    # (contiguous: one compiled signature, the precompiled one, whatever views the callers pass)
    c = np.ascontiguousarray
    _near_box_loop(c(o, np.float64), c(d, np.float64), c(t_max, np.float64), c(lo, np.float64), c(hi, np.float64), out)
    return out


segments_near_box = twin(_near_box_loop and segments_near_box_numba, segments_near_box_numpy)
