"""Per-path Mueller bookkeeping of the path tracer.

Shapes (components first, paths last): throughput T (P, P, L, N) with P = 4, 3 or 1
(full, linear, scalar transport) and L wavelengths (1 where every wavelength shares
one product); per-wavelength values (L, N); rotations as (cos 2φ, sin 2φ) of shape
(N,).  A per-wavelength array with one row is broadcast over the others.
"""

from __future__ import annotations

import numpy as np

from . import dispatch, jit


# ----------------------------------------------------------------------------- T ← T·R(φ)·M_abcs

def update_abcs_numpy(T, c2, s2, A, B, C, S, depol):
    """T · R(φ) · M for M = [[A+depol,B,0,0],[B,A,0,0],[0,0,C,S],[0,0,−S,C]]; returns a new array.

    R(φ) re-expresses the vertex's outgoing frame in the path's frame (rotating columns 1, 2).
    """
    P = T.shape[0]
    T = T.copy()
    if P >= 3:
        t1 = T[:, 1].copy()
        t2 = T[:, 2]
        T[:, 1] = t1 * c2 - t2 * s2
        T[:, 2] = t1 * s2 + t2 * c2
    out = np.empty_like(T)
    a0 = A if depol is None else A + depol
    if P == 1:
        out[:, 0] = T[:, 0] * a0
        return out
    t0, t1 = T[:, 0], T[:, 1]
    out[:, 0] = a0 * t0 + B * t1
    out[:, 1] = B * t0 + A * t1
    if P == 4:
        t2, t3 = T[:, 2], T[:, 3]
        out[:, 2] = C * t2 - S * t3
        out[:, 3] = S * t2 + C * t3
    else:
        out[:, 2] = C * T[:, 2]
    return out


@jit
def _update_abcs_loop(T, c2, s2, A, B, C, S, D, has_depol, out):
    P, L, N = T.shape[0], T.shape[2], T.shape[3]
    for n in range(N):
        for k in range(L):
            la = k if A.shape[0] > 1 else 0
            a, b = A[la, n], B[la, n]
            a0 = a + D[la, n] if has_depol else a
            for i in range(P):
                t0 = T[i, 0, k, n]
                if P == 1:
                    out[i, 0, k, n] = t0 * a0
                    continue
                t1 = T[i, 1, k, n]
                if P >= 3:
                    t2 = T[i, 2, k, n]
                    r1 = t1 * c2[n] - t2 * s2[n]
                    r2 = t1 * s2[n] + t2 * c2[n]
                else:
                    r1 = t1
                    r2 = 0.0
                out[i, 0, k, n] = a0 * t0 + b * r1
                out[i, 1, k, n] = b * t0 + a * r1
                if P == 4:
                    c, s = C[la, n], S[la, n]
                    t3 = T[i, 3, k, n]
                    out[i, 2, k, n] = c * r2 - s * t3
                    out[i, 3, k, n] = s * r2 + c * t3
                elif P == 3:
                    out[i, 2, k, n] = C[la, n] * r2


def update_abcs_numba(T, c2, s2, A, B, C, S, depol):
    out = np.empty_like(T)
    has_depol = depol is not None
    D = depol if has_depol else A
    # Broadcast per-wavelength rows of (1, N) parameters in the loop, not by copying.
    _update_abcs_loop(T, c2, s2, A, B, C if C is not None else A, S if S is not None else A, D, has_depol, out)
    return out


update_abcs = dispatch(_update_abcs_loop and update_abcs_numba, update_abcs_numpy)


# ----------------------------------------------------------------------------- light into accumulators

def add_light_numpy(radiance, path, T, sel, Le, w):
    """radiance[:, :, path[sel]] += T[:, 0, :, sel] · Le · w  (unpolarised light of radiance Le (L, n)).

    ``sel`` indexes the batch's paths (n of them), ``w`` (n,) is the MIS weight.
    """
    radiance[:, :, path[sel]] += T[:, 0][:, :, sel] * (Le * w)


@jit
def _add_light_loop(radiance, path, T, sel, Le, w):
    P, LT = T.shape[0], T.shape[2]
    L = Le.shape[0]
    for j in range(sel.shape[0]):
        q = path[sel[j]]
        s = sel[j]
        for k in range(L):
            e = Le[k, j] * w[j]
            lt = k if LT > 1 else 0
            for i in range(P):
                radiance[i, k, q] += T[i, 0, lt, s] * e


def add_light_numba(radiance, path, T, sel, Le, w):
    _add_light_loop(radiance, path, T, np.asarray(sel, dtype=np.int64), Le, np.asarray(w, dtype=np.float64))


add_light = dispatch(_add_light_loop and add_light_numba, add_light_numpy)


# ----------------------------------------------------------------------------- T · S (next-event estimation)

def throughput_times_stokes_numpy(T, S, weight):
    """(T · S) · weight: Stokes (P, L, n) reaching the camera from Stokes S (P, Lm, n) at the vertex.

    ``weight`` (L, n) scales each wavelength (light spectrum, cosine, MIS); T and S may carry one
    wavelength row (Lm = 1) that is shared by all L.
    """
    return np.einsum("ijln,jln->iln", T, S) * weight[None]


@jit
def _t_times_s_loop(T, S, weight, out):
    P, LT, N = T.shape[0], T.shape[2], T.shape[3]
    L = weight.shape[0]
    for n in range(N):
        for k in range(L):
            lt = k if LT > 1 else 0
            ls = k if S.shape[1] > 1 else 0
            for i in range(P):
                acc = 0.0
                for j in range(P):
                    acc += T[i, j, lt, n] * S[j, ls, n]
                out[i, k, n] = acc * weight[k, n]


def throughput_times_stokes_numba(T, S, weight):
    out = np.empty((T.shape[0], max(weight.shape[0], T.shape[2]), T.shape[3]))
    w = weight if weight.shape[0] == out.shape[1] else np.broadcast_to(weight, out.shape[1:])
    _t_times_s_loop(T, S, w, out)
    return out


throughput_times_stokes = dispatch(_t_times_s_loop and throughput_times_stokes_numba,
                                   throughput_times_stokes_numpy)
