"""Fresnel reflection Mueller coefficients (A, B, C, S) as one compiled loop.

Same formulas, branch cuts and edge handling as engine.polarisation.fresnel (the NumPy
reference, physics.md §0): u = √(η² − sin²θ) with Im u ≥ 0, r_s = (cosθ − u)/(cosθ + u),
r_p = (η² cosθ − u)/(η² cosθ + u), amplitudes 0 where a denominator vanishes (index-matched
grazing), cosines below 1e-200 flushed to 0; A = ½(|r_s|² + |r_p|²), B = ½(|r_s|² − |r_p|²),
C = Re(r_s r_p*), S = −Im(r_s r_p*).  Results agree with the reference to rounding (complex
square root and division are not bit-identical between NumPy and Numba).
"""

from __future__ import annotations

import numpy as np

from . import jit

_TINY = 1e-200


@jit
def abcs_at(c, e):
    """(A, B, C, S) at one cosine c (clamped to [0, 1]) and one complex relative index e."""
    if c < 0.0:
        c = 0.0
    elif c > 1.0:
        c = 1.0
    if c < _TINY:
        c = 0.0
    e2 = e * e
    z = complex((e2.real - (1.0 - c * c)) + 0.0, (e2.imag - 0.0) + 0.0)
    u = np.sqrt(z)
    if u.imag < 0:
        u = -u
    if abs(u) < _TINY:
        u = 0j
    den_s = c + u
    den_p = e2 * c + u
    r_s = (c - u) / den_s if den_s != 0 else 0j
    r_p = (e2 * c - u) / den_p if den_p != 0 else 0j
    F_s = r_s.real ** 2 + r_s.imag ** 2
    F_p = r_p.real ** 2 + r_p.imag ** 2
    x = r_s * r_p.conjugate()
    return 0.5 * (F_s + F_p), 0.5 * (F_s - F_p), x.real, -x.imag


@jit
def _abcs_loop(cos_theta, eta, A, B, C, S):
    for i in range(cos_theta.shape[0]):
        A[i], B[i], C[i], S[i] = abcs_at(cos_theta[i], eta[i])


def _abcs_numba(cos_theta, eta):
    c, e = np.broadcast_arrays(np.asarray(cos_theta, dtype=np.float64), np.asarray(eta, dtype=np.complex128))
    shape = c.shape
    c = np.ascontiguousarray(c).reshape(-1)
    e = np.ascontiguousarray(e).reshape(-1)
    out = [np.empty(c.shape[0]) for _ in range(4)]
    _abcs_loop(c, e, *out)
    return tuple(o.reshape(shape) for o in out)


#: The compiled twin of engine.polarisation.fresnel.fresnel_reflection_abcs_numpy (None without Numba).
fresnel_reflection_abcs_numba = _abcs_loop and _abcs_numba


# ----------------------------------------------------------------------------- smooth mirror, one pass

@jit
def _mirror_loop(wo, n_s, eta, degenerate, wi, s, A, B, C, S, valid):
    L = eta.shape[0]
    for j in range(wo.shape[1]):
        n0, n1, n2 = n_s[0, j], n_s[1, j], n_s[2, j]
        w0, w1, w2 = wo[0, j], wo[1, j], wo[2, j]
        cos_o = (n0 * w0 + n1 * w1) + n2 * w2            # ShadingPoint.cos_o
        ok = cos_o >= 0
        valid[j] = ok
        # wi = reflect(wo, n_s) = 2 (wo·n_s) n_s − wo (engine.vec3 order)
        f = 2.0 * ((w0 * n0 + w1 * n1) + w2 * n2)
        r0 = f * n0 - w0
        r1 = f * n1 - w1
        r2 = f * n2 - w2
        wi[0, j], wi[1, j], wi[2, j] = r0, r1, r2
        # s = unit(n_s × (−wi)), any_perpendicular(n_s) at normal incidence (geometry.unit_cross)
        b0, b1, b2 = -r0, -r1, -r2
        s0 = n1 * b2 - n2 * b1
        s1 = n2 * b0 - n0 * b2
        s2 = n0 * b1 - n1 * b0
        length = np.sqrt((s0 * s0 + s1 * s1) + s2 * s2)
        if length > degenerate:
            s[0, j], s[1, j], s[2, j] = s0 / length, s1 / length, s2 / length
        else:
            sign = 1.0 if n2 >= 0 else -1.0
            g = -1.0 / (sign + n2)
            h = n0 * n1 * g
            s[0, j] = 1.0 + sign * n0 * n0 * g
            s[1, j] = sign * h
            s[2, j] = -sign * n0
        c = cos_o if (cos_o >= 0.0 or np.isnan(cos_o)) else 0.0      # np.maximum(cos_o, 0)
        m = 1.0 if ok else 0.0
        for k in range(L):
            a, b, cc, ss = abcs_at(c, eta[k, j])
            A[k, j] = a * m
            B[k, j] = b * m
            C[k, j] = cc * m
            S[k, j] = ss * m


def _mirror_numba(wo, n_s, eta, degenerate):
    wo = np.ascontiguousarray(wo, dtype=np.float64)
    n_s = np.ascontiguousarray(n_s, dtype=np.float64)
    eta = np.ascontiguousarray(np.broadcast_to(eta, (np.shape(eta)[0], wo.shape[1])), dtype=np.complex128)
    n = wo.shape[1]
    wi, s = np.empty((3, n)), np.empty((3, n))
    A, B, C, S = (np.empty(eta.shape) for _ in range(4))
    valid = np.empty(n, np.bool_)
    _mirror_loop(wo, n_s, eta, float(degenerate), wi, s, A, B, C, S, valid)
    return wi, s, A, B, C, S, valid


#: The compiled twin of engine.materials.conductor.mirror_abcs_numpy (None without Numba).
mirror_abcs_numba = _mirror_loop and _mirror_numba
