"""Per-path Mueller bookkeeping of the path tracer.

Shapes (components first, paths last): throughput T (P, P, L, N) with P = 4, 3 or 1
(full, linear, scalar transport) and L wavelengths (1 where every wavelength shares
one product); per-wavelength values (L, N); rotations as (cos 2φ, sin 2φ) of shape
(N,).  A per-wavelength array with one row is broadcast over the others.
"""

from __future__ import annotations

import math

import numpy as np

from . import jit, jit_inner, twin
from .geometry import offset_origin_at, offset_origin_numpy
from .stokes_rotation import frame_rotation, frame_rotation_at, rotate_stokes


# ----------------------------------------------------------------------------- T = 1 at the camera

def identity_throughput_numpy(P, L, n):
    """The camera paths' Mueller product before any vertex: the identity (P, P, L, n) for n paths."""
    T = np.zeros((P, P, L, n))
    for i in range(P):
        T[i, i] = 1.0
    return T


@jit
def _identity_loop(T):
    P, L, n = T.shape[0], T.shape[2], T.shape[3]
    for i in range(P):
        for c in range(P):
            v = 1.0 if i == c else 0.0
            for k in range(L):
                for j in range(n):
                    T[i, c, k, j] = v


def identity_throughput_numba(P, L, n):
    # written in one nogil pass: np.zeros over reused batch memory (engine.render.allocator) is a
    # memset with the GIL held, then the diagonal is written in a second pass
    T = np.empty((P, P, L, n))
    _identity_loop(T)
    return T


identity_throughput = twin(_identity_loop and identity_throughput_numba, identity_throughput_numpy)


# ----------------------------------------------------------------------------- T ← T·R(φ)·M_abcs

def _rows_and_columns(rows, T_cols):
    """(rows, the columns of T holding their throughputs) as contiguous int64 for the compiled loops
    (``T_cols`` None: the rows themselves; engine.render.path_state.PathState.T_col)."""
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    return rows, rows if T_cols is None else np.ascontiguousarray(T_cols, dtype=np.int64)


def _rotated_rows_numpy(T, cols, x_out, x_T, wo):
    """T[..., cols] · R(φ), a new array: columns 1, 2 rotated from frame x_out to x_T about wo
    (nothing to rotate with fewer than 3 Stokes components)."""
    T = T[..., cols]
    if T.shape[0] >= 3:
        c2, s2 = frame_rotation(x_out, x_T, wo)
        # T·R(φ): each row of T is a co-vector, i.e. its components 1, 2 turn by −φ
        rotate_stokes(T.swapaxes(0, 1), c2, -s2, in_place=True)
    return T


def update_abcs_numpy(out, T, rows, x_out, x_T, wo, A, B, C, S, depol, T_cols=None):
    """out[..., rows] = T[..., T_cols] · R(φ) · M for M = [[A+depol,B,0,0],[B,A,0,0],[0,0,C,S],[0,0,−S,C]].

    ``rows`` (n,) are the paths (last-axis indices of out) the vertex values belong to, ``T_cols``
    (n,) the columns of T that hold their throughputs (None: ``rows``; see
    engine.render.path_state.PathState.T_col);
    x_out (the vertex value's outgoing frame), x_T (the path's frame), wo (both ⟂ it) are (3, n)
    and A..S, depol (L or 1, n), all given per such path.  R(φ) = rotation from x_out to x_T
    about wo (engine.kernels.stokes_rotation.frame_rotation), applied to columns 1, 2 of T.
    T is not modified.
    """
    P = T.shape[0]
    T = _rotated_rows_numpy(T, rows if T_cols is None else T_cols, x_out, x_T, wo)
    res = np.empty_like(T)
    a0 = A if depol is None else A + depol
    if P == 1:
        res[:, 0] = T[:, 0] * a0
    else:
        t0, t1 = T[:, 0], T[:, 1]
        res[:, 0] = a0 * t0 + B * t1
        res[:, 1] = B * t0 + A * t1
        if P == 4:
            t2, t3 = T[:, 2], T[:, 3]
            res[:, 2] = C * t2 - S * t3
            res[:, 3] = S * t2 + C * t3
        else:
            res[:, 2] = C * T[:, 2]
    out[..., rows] = res


@jit
def _frame_rotations(x_out, x_T, wo, n, P):
    """(cos 2φ, sin 2φ) arrays (n,) for every path; the identity when P < 3 (nothing rotates)."""
    c2 = np.ones(n)
    s2 = np.zeros(n)
    if P >= 3:
        for j in range(n):
            c2[j], s2[j] = frame_rotation_at(x_out, x_T, wo, j)
    return c2, s2


@jit
def _update_abcs_loop(out, T, rows, cols, x_out, x_T, wo, A, B, C, S, D, has_depol):
    P, L, n = T.shape[0], T.shape[2], rows.shape[0]
    c2, s2 = _frame_rotations(x_out, x_T, wo, n, P)
    # paths innermost: every (row, wavelength) of T is one contiguous stream
    for k in range(L):
        la = k if A.shape[0] > 1 else 0
        for i in range(P):
            for j in range(n):
                m = rows[j]
                mc = cols[j]
                a = A[la, j]
                a0 = a + D[la, j] if has_depol else a
                t0 = T[i, 0, k, mc]
                if P == 1:
                    out[i, 0, k, m] = t0 * a0
                    continue
                b = B[la, j]
                t1 = T[i, 1, k, mc]
                if P >= 3:
                    t2 = T[i, 2, k, mc]
                    r1 = t1 * c2[j] - t2 * s2[j]
                    r2 = t1 * s2[j] + t2 * c2[j]
                else:
                    r1 = t1
                    r2 = 0.0
                out[i, 0, k, m] = a0 * t0 + b * r1
                out[i, 1, k, m] = b * t0 + a * r1
                if P == 4:
                    c, s = C[la, j], S[la, j]
                    t3 = T[i, 3, k, mc]
                    out[i, 2, k, m] = c * r2 - s * t3
                    out[i, 3, k, m] = s * r2 + c * t3
                elif P == 3:
                    out[i, 2, k, m] = C[la, j] * r2


def update_abcs_numba(out, T, rows, x_out, x_T, wo, A, B, C, S, depol, T_cols=None):
    has_depol = depol is not None
    # One compiled signature: contiguous float64 everywhere (per-wavelength rows of (1, n)
    # parameters are broadcast in the loop, not by copying).
    A, B, C, S, D, x_out, x_T, wo = (np.ascontiguousarray(x, dtype=np.float64)
                                     for x in (A, B, A if C is None else C, A if S is None else S,
                                               depol if has_depol else A, x_out, x_T, wo))
    rows, cols = _rows_and_columns(rows, T_cols)
    _update_abcs_loop(out, T, rows, cols, x_out, x_T, wo, A, B, C, S, D, has_depol)


update_abcs = twin(_update_abcs_loop and update_abcs_numba, update_abcs_numpy)


# ----------------------------------------------------------------------------- T ← T·M_depolarising, T ← T·R(φ)·M

def update_depolarising_numpy(out, T, rows, A, T_cols=None):
    """out[..., rows] = T[..., T_cols] · A·diag(1, 0, 0, 0): a depolariser needs no frame (A (L or 1, n));
    ``T_cols`` as in update_abcs_numpy (None: ``rows``)."""
    cols = rows if T_cols is None else T_cols
    res = np.zeros_like(T[..., cols])
    res[:, 0] = T[:, 0][..., cols] * A
    out[..., rows] = res


@jit
def _update_depolarising_loop(out, T, rows, cols, A):
    P, L = T.shape[0], T.shape[2]
    for k in range(L):
        la = k if A.shape[0] > 1 else 0
        for i in range(P):
            for j in range(rows.shape[0]):
                out[i, 0, k, rows[j]] = T[i, 0, k, cols[j]] * A[la, j]
            for c in range(1, P):
                for j in range(rows.shape[0]):
                    out[i, c, k, rows[j]] = 0.0


def update_depolarising_numba(out, T, rows, A, T_cols=None):
    rows, cols = _rows_and_columns(rows, T_cols)
    _update_depolarising_loop(out, T, rows, cols, np.ascontiguousarray(A, dtype=np.float64))


update_depolarising = twin(_update_depolarising_loop and update_depolarising_numba, update_depolarising_numpy)


def update_general_numpy(out, T, rows, x_out, x_T, wo, M, T_cols=None):
    """out[..., rows] = T[..., T_cols] · R(φ) · M for a general Mueller matrix M (4, 4, L or 1, n).

    Frames and ``T_cols`` as in ``update_abcs_numpy``; only the top-left P×P block of M is used.
    """
    P = T.shape[0]
    T = _rotated_rows_numpy(T, rows if T_cols is None else T_cols, x_out, x_T, wo)
    out[..., rows] = np.einsum("ijln,jkln->ikln", T, M[:P, :P])


@jit
def _update_general_loop(out, T, rows, cols, x_out, x_T, wo, M):
    P, L, n = T.shape[0], T.shape[2], rows.shape[0]
    c2, s2 = _frame_rotations(x_out, x_T, wo, n, P)
    row = np.empty(4)
    for k in range(L):
        lm = k if M.shape[2] > 1 else 0
        for i in range(P):
            for j in range(n):
                m = rows[j]
                for c in range(P):
                    row[c] = T[i, c, k, cols[j]]
                if P >= 3:
                    t1, t2 = row[1], row[2]
                    row[1] = t1 * c2[j] - t2 * s2[j]
                    row[2] = t1 * s2[j] + t2 * c2[j]
                for c in range(P):
                    acc = 0.0
                    for q in range(P):
                        acc += row[q] * M[q, c, lm, j]
                    out[i, c, k, m] = acc


def update_general_numba(out, T, rows, x_out, x_T, wo, M, T_cols=None):
    x_out, x_T, wo = (np.ascontiguousarray(x, dtype=np.float64) for x in (x_out, x_T, wo))
    rows, cols = _rows_and_columns(rows, T_cols)
    _update_general_loop(out, T, rows, cols, x_out, x_T, wo, np.ascontiguousarray(M, dtype=np.float64))


update_general = twin(_update_general_loop and update_general_numba, update_general_numpy)


# ----------------------------------------------------------------------------- light into accumulators

def add_light_numpy(radiance, path, T, sel, Le, w, T_cols=None):
    """radiance[:, :, path[sel]] += T[:, 0, :, T_cols] · Le · w  (unpolarised light of radiance Le (L, n)).

    ``sel`` indexes the batch's paths (n of them), ``T_cols`` the columns of T holding their
    throughputs (None: ``sel``), ``w`` (n,) is the MIS weight.
    """
    radiance[:, :, path[sel]] += T[:, 0][:, :, sel if T_cols is None else T_cols] * (Le * w)


@jit
def _add_light_loop(radiance, path, T, sel, cols, Le, w):
    P, LT = T.shape[0], T.shape[2]
    L = Le.shape[0]
    if LT > 1:
        for i in range(P):
            for k in range(L):
                for j in range(sel.shape[0]):
                    radiance[i, k, path[sel[j]]] += T[i, 0, k, cols[j]] * (Le[k, j] * w[j])
        return
    # one throughput row for every wavelength (or RGB channel): each T[i, 0] read once and used for all L
    # (the same products and sums; 0.70-0.76× the time of one pass per channel, 1e5 paths)
    for i in range(P):
        for j in range(sel.shape[0]):
            p = path[sel[j]]
            t = T[i, 0, 0, cols[j]]
            wj = w[j]
            for k in range(L):
                radiance[i, k, p] += t * (Le[k, j] * wj)


def add_light_numba(radiance, path, T, sel, Le, w, T_cols=None):
    sel, cols = _rows_and_columns(sel, T_cols)
    _add_light_loop(radiance, np.ascontiguousarray(path, dtype=np.int64), T, sel, cols,
                    np.ascontiguousarray(Le, dtype=np.float64), np.ascontiguousarray(w, dtype=np.float64))


add_light = twin(_add_light_loop and add_light_numba, add_light_numpy)


# ----------------------------------------------------------------------------- T · S (next-event estimation)

def throughput_times_stokes_numpy(T, rows, S, weight):
    """(T[..., rows] · S) · weight: Stokes (P, L, n) reaching the camera from Stokes S (P, Lm, n).

    ``weight`` (L, n) scales each wavelength (light spectrum, cosine, MIS); T and S may carry one
    wavelength row (Lm = 1) that is shared by all L.  S may have fewer than P components (the rest
    are zero, e.g. 1 for light leaving a depolariser).
    """
    return np.einsum("ijln,jln->iln", T[:, :S.shape[0]][..., rows], S) * weight[None]


@jit
def _t_times_s_loop(T, rows, S, weight, out):
    P, LT = T.shape[0], T.shape[2]
    L = weight.shape[0]
    if LT == 1 and S.shape[1] == 1:
        # T and S of one row for every wavelength: each path's T·S once, scaled per wavelength (the same sums)
        for i in range(P):
            for j in range(rows.shape[0]):
                n = rows[j]
                acc = 0.0
                for m in range(S.shape[0]):
                    acc += T[i, m, 0, n] * S[m, 0, j]
                for k in range(L):
                    out[i, k, j] = acc * weight[k, j]
        return
    for i in range(P):
        for k in range(L):
            lt = k if LT > 1 else 0
            ls = k if S.shape[1] > 1 else 0
            for j in range(rows.shape[0]):
                n = rows[j]
                acc = 0.0
                for m in range(S.shape[0]):
                    acc += T[i, m, lt, n] * S[m, ls, j]
                out[i, k, j] = acc * weight[k, j]


def throughput_times_stokes_numba(T, rows, S, weight):
    out = np.empty((T.shape[0], max(weight.shape[0], T.shape[2]), S.shape[2]))
    w = weight if weight.shape[0] == out.shape[1] else np.broadcast_to(weight, out.shape[1:])
    _t_times_s_loop(T, np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(S, dtype=np.float64),
                    np.ascontiguousarray(w, dtype=np.float64), out)
    return out


throughput_times_stokes = twin(_t_times_s_loop and throughput_times_stokes_numba,
                                   throughput_times_stokes_numpy)


# ----------------------------------------------------------------------------- Russian roulette, path validity

def roulette_numpy(T, eta_sq, u_rr, valid, apply_rr):
    """Russian roulette on the new throughputs and the paths' validity; returns (T, nonfinite).

    T (P, P, L, n) is the throughput after this vertex, ``eta_sq`` (n,) the product of refraction
    scales η² so far, ``u_rr`` (n,) uniform numbers, ``valid`` (n,) bool where the vertex sampled
    a direction (updated in place).  With ``apply_rr`` a path survives with probability
    q = min(max_λ T00 · η², 0.95) and T is divided by q; a NaN q ends the path.  Then paths with a
    non-finite T end (``nonfinite`` counts those that were valid so far) and so do black ones
    (T00 = 0 at every wavelength).  T may be returned as a new array.
    """
    if apply_rr:
        q = np.minimum(np.max(T[0, 0], axis=0) * eta_sq, 0.95)
        survive = u_rr < q
        T = T / np.where(survive, q, 1.0)
        valid &= survive
    finite_T = np.isfinite(T).all(axis=(0, 1, 2))
    nonfinite = int((valid & ~finite_T).sum())
    valid &= finite_T & (np.abs(T[0, 0]).max(axis=0) > 0)
    return T, nonfinite


@jit
def _roulette_loop(T, eta_sq, u_rr, valid, apply_rr):
    P, L, n = T.shape[0], T.shape[2], T.shape[3]
    scale = np.ones(n)
    if apply_rr:
        for j in range(n):
            # max over λ as np.max: NaN if any entry is NaN
            m = T[0, 0, 0, j]
            for k in range(1, L):
                v = T[0, 0, k, j]
                if v > m or np.isnan(v):
                    m = v
                if np.isnan(m):
                    break
            q = m * eta_sq[j]
            if not np.isnan(q) and q > 0.95:      # np.minimum keeps a NaN
                q = 0.95
            if u_rr[j] < q:
                scale[j] = q
            else:
                valid[j] = False
    finite = np.ones(n, np.bool_)
    # component rows outermost: every (i, c, λ) row of T is one contiguous stream over paths
    for i in range(P):
        for c in range(P):
            for k in range(L):
                for j in range(n):
                    t = T[i, c, k, j]
                    if apply_rr:
                        t = t / scale[j]
                        T[i, c, k, j] = t
                    if not np.isfinite(t):
                        finite[j] = False
    nonfinite = 0
    for j in range(n):
        if valid[j] and not finite[j]:
            nonfinite += 1
        if not finite[j]:
            valid[j] = False
        elif valid[j]:
            black = True
            for k in range(L):
                if T[0, 0, k, j] != 0.0:
                    black = False
                    break
            if black:
                valid[j] = False
    return nonfinite


def roulette_numba(T, eta_sq, u_rr, valid, apply_rr):
    # T is divided in place (the caller's freshly scattered throughput)
    nonfinite = _roulette_loop(T, np.ascontiguousarray(eta_sq, dtype=np.float64),
                               np.ascontiguousarray(u_rr, dtype=np.float64), valid, bool(apply_rr))
    return T, int(nonfinite)


roulette = twin(_roulette_loop and roulette_numba, roulette_numpy)


# ----------------------------------------------------------------------------- per-path values into the batch

def add_to_paths_numpy(radiance, path, values):
    """radiance[:, :, path] += values for distinct batch indices ``path`` (n,), values (P, L, n)."""
    radiance[:, :, path] += values


@jit
def _add_to_paths_loop(radiance, path, values):
    for i in range(values.shape[0]):
        for k in range(values.shape[1]):
            for j in range(path.shape[0]):
                radiance[i, k, path[j]] += values[i, k, j]


def add_to_paths_numba(radiance, path, values):
    _add_to_paths_loop(radiance, np.ascontiguousarray(path, dtype=np.int64),
                       np.ascontiguousarray(values, dtype=np.float64))


add_to_paths = twin(_add_to_paths_loop and add_to_paths_numba, add_to_paths_numpy)


# ----------------------------------------------------------------------------- dropping finished paths

def keep_columns_numpy(a, idx):
    """a[..., idx]: the paths ``idx`` (sorted int64 indices of the last axis) of a per-path array, as a new
    C-contiguous array of the same dtype."""
    return np.take(a, idx, axis=-1)


@jit_inner
def _check_columns(idx, n):
    """IndexError (as NumPy's) where a path index is outside [0, n): the loops below read and write unchecked."""
    for j in range(idx.shape[0]):
        if idx[j] < 0 or idx[j] >= n:
            raise IndexError("a path index is out of range")


@jit_inner
def _keep_columns_loop(a, idx, out):
    _check_columns(idx, a.shape[1])
    for r in range(a.shape[0]):
        for j in range(idx.shape[0]):
            out[r, j] = a[r, idx[j]]


def keep_columns_numba(a, idx):
    # every leading index is one row of a 2-D view: one loop serves vectors, Mueller products and keys
    rows = math.prod(a.shape[:-1])
    out = np.empty(a.shape[:-1] + (idx.shape[0],), a.dtype)
    _keep_columns_loop(a.reshape(rows, a.shape[-1]), idx, out.reshape(rows, idx.shape[0]))
    return out


keep_columns = twin(_keep_columns_loop and keep_columns_numba, keep_columns_numpy)


def put_columns_numpy(out, idx, a):
    """out[..., idx] = a: the columns ``idx`` (distinct valid int64 indices of the last axis) of a C-contiguous
    per-path array written from ``a`` (broadcast to out's shape with idx.shape[0] columns, cast to out's dtype)."""
    out[..., idx] = a


@jit_inner
def _put_columns_loop(out, idx, a):
    _check_columns(idx, out.shape[1])
    for r in range(out.shape[0]):
        for j in range(idx.shape[0]):
            out[r, idx[j]] = a[r, j]


def put_columns_numba(out, idx, a):
    if not out.flags.c_contiguous:          # a reshaped view would be a copy: the writes would be lost
        return put_columns_numpy(out, idx, a)
    rows = math.prod(out.shape[:-1])
    a = np.ascontiguousarray(np.broadcast_to(a, out.shape[:-1] + (idx.shape[0],)), dtype=out.dtype)
    _put_columns_loop(out.reshape(rows, out.shape[-1]), np.ascontiguousarray(idx, dtype=np.int64),
                      a.reshape(rows, idx.shape[0]))


put_columns = twin(_put_columns_loop and put_columns_numba, put_columns_numpy)


def scale_columns_numpy(out, idx, s):
    """out[..., idx] *= s: the columns ``idx`` (distinct valid int64 indices of the last axis) of a per-path array
    scaled in place by ``s`` (idx.shape[0],) (a refraction's 1/η² taken back: Cycles' radiance convention)."""
    out[..., idx] *= s


@jit_inner
def _scale_columns_loop(out, idx, s):
    _check_columns(idx, out.shape[1])
    for r in range(out.shape[0]):
        for j in range(idx.shape[0]):
            out[r, idx[j]] = out[r, idx[j]] * s[j]        # in s's precision, rounded to out's: as NumPy's *=


def scale_columns_numba(out, idx, s):
    if not out.flags.c_contiguous:          # a reshaped view would be a copy: the writes would be lost
        return scale_columns_numpy(out, idx, s)
    _scale_columns_loop(out.reshape(math.prod(out.shape[:-1]), out.shape[-1]),
                        np.ascontiguousarray(idx, dtype=np.int64), np.ascontiguousarray(s, dtype=np.float64))


scale_columns = twin(_scale_columns_loop and scale_columns_numba, scale_columns_numpy)


# ----------------------------------------------------------------------------- roulette, survivors, next origins

def next_segments_numpy(T, eta_sq, eta_step, u_rr, valid, apply_rr, x_T, d, path, keys, is_delta, pdf, p, n_g,
                        epsilon, compact_T=True):
    """The end of a bounce in one step: η² ← η²·eta_step, Russian roulette and validity
    (roulette_numpy, ``valid`` updated in place), then the surviving paths' columns of every per-path
    array and the origins of their next segments, p moved off the surface along ±n_g
    (engine.kernels.geometry.offset_origin_numpy with ``epsilon``).

    T (P, P, L, n) is the bounce's new throughput (may be divided in place); x_T, d, p, n_g (3, n);
    eta_sq, eta_step, u_rr (n,) float (u_rr read only with ``apply_rr``); path (n,) int64, keys (n,)
    uint64, is_delta (n,) bool, pdf (n,) float.  Returns (idx: the kept paths (m,) int64, nonfinite,
    T, x_T, d, eta_sq, path, keys, is_delta, pdf, p, o), each restricted to idx (the arrays themselves,
    not copies, where every path goes on).  With ``compact_T`` False, T is returned whole (its columns
    idx are the survivors': engine.render.path_state.PathState.T_col).
    """
    eta_sq = eta_sq * eta_step
    T, nonfinite = roulette_numpy(T, eta_sq, u_rr, valid, apply_rr)
    idx = np.flatnonzero(valid)
    kept = [x_T, d, eta_sq, path, keys, is_delta, pdf, p, n_g]
    if idx.shape[0] < valid.shape[0]:
        kept = [np.take(a, idx, axis=-1) for a in kept]
        if compact_T:
            T = np.take(T, idx, axis=-1)
    x_T, d, eta_sq, path, keys, is_delta, pdf, p, n_g = kept
    return idx, nonfinite, T, x_T, d, eta_sq, path, keys, is_delta, pdf, p, offset_origin_numpy(p, n_g, d, epsilon)


@jit
def _next_segments_loop(T, eta_sq, eta_step, u_rr, valid, apply_rr, x_T, d, path, keys, is_delta, pdf, p, n_g,
                        epsilon, compact_T):
    n = valid.shape[0]
    eta_new = np.empty(n)
    for j in range(n):
        eta_new[j] = eta_sq[j] * eta_step[j]
    # roulette and validity: _roulette_loop's arithmetic (T divided in place)
    nonfinite = _roulette_loop(T, eta_new, u_rr, valid, apply_rr)
    m = 0
    for j in range(n):
        if valid[j]:
            m += 1
    idx = np.empty(m, np.int64)
    m = 0
    for j in range(n):
        if valid[j]:
            idx[m] = j
            m += 1
    if m < n:
        # the survivors' columns, each array as rows of a 2-D view (keep_columns' loop)
        P, L = T.shape[0], T.shape[2]
        if compact_T:
            T_k = np.empty((P, P, L, m))
            _keep_columns_loop(T.reshape(P * P * L, n), idx, T_k.reshape(P * P * L, m))
        else:
            T_k = T
        x_k, d_k, p_k, n_k = np.empty((3, m)), np.empty((3, m)), np.empty((3, m)), np.empty((3, m))
        for a, out in ((x_T, x_k), (d, d_k), (p, p_k), (n_g, n_k)):
            _keep_columns_loop(a, idx, out)
        eta_k, pdf_k = np.empty(m), np.empty(m)
        path_k, keys_k, delta_k = np.empty(m, np.int64), np.empty(m, np.uint64), np.empty(m, np.bool_)
        _keep_columns_loop(eta_new.reshape(1, n), idx, eta_k.reshape(1, m))
        _keep_columns_loop(pdf.reshape(1, n), idx, pdf_k.reshape(1, m))
        _keep_columns_loop(path.reshape(1, n), idx, path_k.reshape(1, m))
        _keep_columns_loop(keys.reshape(1, n), idx, keys_k.reshape(1, m))
        _keep_columns_loop(is_delta.reshape(1, n), idx, delta_k.reshape(1, m))
    else:
        T_k, x_k, d_k, p_k, n_k = T, x_T, d, p, n_g
        eta_k, pdf_k, path_k, keys_k, delta_k = eta_new, pdf, path, keys, is_delta
    # next origins, off the surface to the side of the new direction
    o = np.empty((3, m))
    for jj in range(m):
        offset_origin_at(p_k, n_k, d_k, epsilon, jj, o)
    return idx, nonfinite, T_k, x_k, d_k, eta_k, path_k, keys_k, delta_k, pdf_k, p_k, o


def next_segments_numba(T, eta_sq, eta_step, u_rr, valid, apply_rr, x_T, d, path, keys, is_delta, pdf, p, n_g,
                        epsilon, compact_T=True):
    c = np.ascontiguousarray
    res = _next_segments_loop(T, c(eta_sq, dtype=np.float64), c(eta_step, dtype=np.float64),
                              c(u_rr, dtype=np.float64), valid, bool(apply_rr), c(x_T, dtype=np.float64),
                              c(d, dtype=np.float64), c(path, dtype=np.int64), c(keys, dtype=np.uint64),
                              c(is_delta, dtype=np.bool_), c(pdf, dtype=np.float64), c(p, dtype=np.float64),
                              c(n_g, dtype=np.float64), float(epsilon), bool(compact_T))
    return (res[0], int(res[1])) + tuple(res[2:])


next_segments = twin(_next_segments_loop and next_segments_numba, next_segments_numpy)


# ----------------------------------------------------------------------------- the batch's film values

def stokes_rgb_samples_numpy(rgb, in_place=False):
    """(out, nonfinite): the batch's Stokes × RGB samples (4, 3, n) from rgb (P, 3, n) (components
    beyond P zero), samples with a non-finite component zeroed and counted.  ``in_place``: with P = 4
    ``rgb`` itself is zeroed there and returned (no copy; the caller is done with it)."""
    if in_place and rgb.shape[0] == 4:
        out = rgb
    else:
        out = np.zeros((4, 3, rgb.shape[2]))
        out[:rgb.shape[0]] = rgb
    finite = np.isfinite(out).all(axis=(0, 1))
    out[:, :, ~finite] = 0.0
    return out, int((~finite).sum())


@jit_inner
def _zero_nonfinite_samples(out, P, j0, j1):
    """Zero the P Stokes rows (× RGB) of every sample j in [j0, j1) of ``out`` (4, 3, n) that has a NaN
    or ±inf among them; returns how many samples that was."""
    nonfinite = 0
    for j in range(j0, j1):
        finite = True
        for p in range(P):
            for c in range(3):
                if not np.isfinite(out[p, c, j]):
                    finite = False
        if not finite:
            nonfinite += 1
            for p in range(P):
                for c in range(3):
                    out[p, c, j] = 0.0
    return nonfinite


@jit
def _stokes_rgb_loop(rgb, out, in_place):
    P, n = rgb.shape[0], rgb.shape[2]
    if not in_place:
        # component rows outermost: each (p, c) row is one contiguous stream over the samples
        for p in range(4):
            for c in range(3):
                for j in range(n):
                    out[p, c, j] = rgb[p, c, j] if p < P else 0.0
    return _zero_nonfinite_samples(out, P, 0, n)


def stokes_rgb_samples_numba(rgb, in_place=False):
    rgb = np.ascontiguousarray(rgb, dtype=np.float64)
    in_place = in_place and rgb.shape[0] == 4
    out = rgb if in_place else np.empty((4, 3, rgb.shape[2]))
    nonfinite = _stokes_rgb_loop(rgb, out, in_place)
    return out, int(nonfinite)


stokes_rgb_samples = twin(_stokes_rgb_loop and stokes_rgb_samples_numba, stokes_rgb_samples_numpy)


def spectral_stokes_rgb_samples_numpy(radiance, w_rgb):
    """stokes_rgb_samples of the spectral radiance (P, L, n) weighted by the paths' colour-matching
    weights w_rgb (3, L, n): rgb[p, c] = Σ_λ radiance[p, λ]·w_rgb[c, λ], summed in λ order."""
    return stokes_rgb_samples_numpy(np.einsum("pln,cln->pcn", radiance, w_rgb))


#: Samples per block of _spectral_stokes_rgb_loop: a block's sums stay in the L1 cache while every
#: wavelength's products are added to them (one pass over the batch; the machine is bandwidth-bound).
_RGB_BLOCK = 1024


@jit
def _spectral_stokes_rgb_loop(radiance, w_rgb, out):
    P, L, n = radiance.shape
    nonfinite = 0
    for j0 in range(0, n, _RGB_BLOCK):
        j1 = min(n, j0 + _RGB_BLOCK)
        for p in range(4):
            for c in range(3):
                o = out[p, c, j0:j1]
                o[:] = 0.0
                if p >= P:
                    continue
                # einsum's sum: from 0, one wavelength's products at a time
                for q in range(L):
                    r = radiance[p, q, j0:j1]
                    w = w_rgb[c, q, j0:j1]
                    for j in range(j1 - j0):
                        o[j] += r[j] * w[j]
        nonfinite += _zero_nonfinite_samples(out, P, j0, j1)
    return nonfinite


def spectral_stokes_rgb_samples_numba(radiance, w_rgb):
    out = np.empty((4, 3, radiance.shape[2]))
    nonfinite = _spectral_stokes_rgb_loop(np.ascontiguousarray(radiance, dtype=np.float64),
                                          np.ascontiguousarray(w_rgb, dtype=np.float64), out)
    return out, int(nonfinite)


spectral_stokes_rgb_samples = twin(_spectral_stokes_rgb_loop and spectral_stokes_rgb_samples_numba,
                                   spectral_stokes_rgb_samples_numpy)


# ----------------------------------------------------------------------------- per-pixel sums of a batch

def pixel_sums_numpy(local, span, stokes_rgb, weights, sample=None):
    """(sums (4, 3, span), sums of y² (4, span), counts (span,) int64, half sums (2, 4, span) or None) of a
    batch's samples at pixels ``local`` (n,) int64 in [0, span): stokes_rgb (4, 3, n) and its luminance
    Stokes y = Σ_c weights[c]·stokes_rgb[:, c] (4, n) (einsum's order) summed per pixel in the samples'
    order (np.bincount, as engine.render.film.SampleSums.of); with the samples' indices ``sample`` (n,)
    int64 also y's sums over the even (row 0) and the odd (row 1) samples."""
    y = np.einsum("c,scn->sn", weights, stokes_rgb)
    sums = np.empty((4, 3, span))
    for s in range(4):
        for c in range(3):
            sums[s, c] = np.bincount(local, weights=stokes_rgb[s, c], minlength=span)
    sumsq_y = np.empty((4, span))
    for s in range(4):
        sumsq_y[s] = np.bincount(local, weights=y[s] * y[s], minlength=span)
    half_y = None
    if sample is not None:
        half_y = np.empty((2, 4, span))
        slot = local + span * (sample & 1)            # even samples' pixels, then odd samples'
        for s in range(4):
            half_y[:, s] = np.bincount(slot, weights=y[s], minlength=2 * span).reshape(2, span)
    return sums, sumsq_y, np.bincount(local, minlength=span), half_y


@jit
def _pixel_sums_loop(local, stokes_rgb, weights, sample, has_half, sums, sumsq_y, count, half_y):
    # the bincounts as compiled loops without the GIL or temporaries (y, y², the half slots): every sum
    # still adds its samples in order, starting from +0.0, so each pixel's sums have the bincounts' bits.
    # One Stokes row at a time, as bincount: a pass over the samples that updated all 17 sums at once
    # touched 17 rows a pixel apart (4× slower where every sample has a pixel of its own); y is made
    # where it is added (its square and its half sum in one pass), as einsum makes it: (w0·x0 + w1·x1) + w2·x2.
    n = local.shape[0]
    w0, w1, w2 = weights[0], weights[1], weights[2]
    for s in range(4):
        for c in range(3):
            for j in range(n):
                sums[s, c, local[j]] += stokes_rgb[s, c, j]
        for j in range(n):
            v = (w0 * stokes_rgb[s, 0, j] + w1 * stokes_rgb[s, 1, j]) + w2 * stokes_rgb[s, 2, j]
            sumsq_y[s, local[j]] += v * v
            if has_half:
                half_y[sample[j] & 1, s, local[j]] += v
    for j in range(n):
        count[local[j]] += 1


def pixel_sums_numba(local, span, stokes_rgb, weights, sample=None):
    sums, sumsq_y, count = np.zeros((4, 3, span)), np.zeros((4, span)), np.zeros(span, np.int64)
    has_half = sample is not None
    half_y = np.zeros((2, 4, span) if has_half else (2, 4, 0))
    _pixel_sums_loop(np.ascontiguousarray(local, dtype=np.int64), np.ascontiguousarray(stokes_rgb, dtype=np.float64),
                     np.ascontiguousarray(weights, dtype=np.float64),
                     np.ascontiguousarray(sample, dtype=np.int64) if has_half else np.zeros(0, np.int64), has_half,
                     sums, sumsq_y, count, half_y)
    return sums, sumsq_y, count, half_y if has_half else None


pixel_sums = twin(_pixel_sums_loop and pixel_sums_numba, pixel_sums_numpy)
