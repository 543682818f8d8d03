"""Fresnel reflection Mueller coefficients (A, B, C, S) as one compiled loop.

Same formulas, branch cuts and edge handling as engine.polarisation.fresnel (the NumPy
reference, docs/physics.md §0): u = √(η² − sin²θ) with Im u ≥ 0, r_s = (cosθ − u)/(cosθ + u),
r_p = (η² cosθ − u)/(η² cosθ + u), amplitudes 0 where a denominator vanishes (index-matched
grazing), cosines below 1e-200 flushed to 0; A = ½(|r_s|² + |r_p|²), B = ½(|r_s|² − |r_p|²),
C = Re(r_s r_p*), S = −Im(r_s r_p*).  Results agree with the reference to rounding: the compiled
step takes the square root and the quotients in real arithmetic (abcs_at), NumPy in complex.
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner
from .tables import relative_index_at

_TINY = 1e-200


@jit_inner
def _incidence_cosine(c):
    """cosθ clipped to [0, 1], below 1e-200 flushed to 0 (grazing), as fresnel_amplitudes does."""
    if c < 0.0:
        c = 0.0
    elif c > 1.0:
        c = 1.0
    if c < _TINY:
        c = 0.0
    return c


@jit_inner
def _abcs_complex(c, e):
    """abcs_at in complex arithmetic (Numba's csqrt and Smith division, which scale their operands):
    the fallback for magnitudes where squaring them would underflow or overflow."""
    c = _incidence_cosine(c)
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


@jit_inner
def _abcs_from_root(c, e2r, e2i, ur, ui):
    """(A, B, C, S, |c + u|², |η²c + u|²) from cosθ = c, η² = e2r + i·e2i and u = ur + i·ui: r_s =
    (c − u)/(c + u), r_p = (η²c − u)/(η²c + u) as N·conj(D)/|D|² (real arithmetic; the caller checks
    the two squared denominators)."""
    dsr, dsi, nsr, nsi = c + ur, ui, c - ur, -ui
    pr, pi = e2r * c, e2i * c
    dpr, dpi, npr, npi = pr + ur, pi + ui, pr - ur, pi - ui
    qs = dsr * dsr + dsi * dsi
    qp = dpr * dpr + dpi * dpi
    rsr = (nsr * dsr + nsi * dsi) / qs
    rsi = (nsi * dsr - nsr * dsi) / qs
    rpr = (npr * dpr + npi * dpi) / qp
    rpi = (npi * dpr - npr * dpi) / qp
    F_s = rsr * rsr + rsi * rsi
    F_p = rpr * rpr + rpi * rpi
    # r_s·conj(r_p)
    xr = rsr * rpr + rsi * rpi
    xi = rsi * rpr - rsr * rpi
    return 0.5 * (F_s + F_p), 0.5 * (F_s - F_p), xr, -xi, qs, qp


@jit_inner
def abcs_at(c, e):
    """(A, B, C, S) of the Fresnel reflection for one cosine ``c`` and complex relative index ``e``.

    Real arithmetic: u = √z from |z| = √(zr² + zi²) (the stable half-angle form, Im u ≥ 0) and
    r = N·conj(D)/|D|², about 2.6× cheaper than complex sqrt (libm hypot) and Smith's division.
    Where a square could underflow or overflow (|z| outside 1e±150, |D|² < 1e-250: near-grazing
    index-matched interfaces) the complex form _abcs_complex is used instead.  A real index (a
    dielectric) gives the complex form's numbers bit for bit (S = +0): near the critical angle the
    dielectric divides by 1 − F, which would magnify the extra roundings of N·conj(D)/|D|²."""
    c = _incidence_cosine(c)
    er, ei = e.real, e.imag
    e2r = er * er - ei * ei
    e2i = er * ei + ei * er
    zr = e2r - (1.0 - c * c)
    zi = e2i
    if zi == 0.0:
        if zr < 0.0:                    # total internal reflection: u = i·√(−zr), as before
            return _abcs_complex(c, e)
        # a real index below its critical angle: real u and real quotients, the complex form's bits
        # (NumPy's csqrt of a real zr ≥ 0 is √zr; Smith's division by a real is one division)
        u = np.sqrt(zr)
        if u < _TINY:
            u = 0.0
        den_s = c + u
        den_p = e2r * c + u
        r_s = (c - u) / den_s if den_s != 0 else 0.0
        r_p = (e2r * c - u) / den_p if den_p != 0 else 0.0
        F_s = r_s * r_s
        F_p = r_p * r_p
        return 0.5 * (F_s + F_p), 0.5 * (F_s - F_p), r_s * r_p, 0.0
    big = max(abs(zr), abs(zi))
    if not (big > 1e-150 and big < 1e150):
        return _abcs_complex(c, e)
    m = np.sqrt(zr * zr + zi * zi)
    if zr >= 0.0:
        t = np.sqrt(0.5 * (m + zr))
        ur, ui = t, zi / (2.0 * t)
        if ui < 0.0:
            ur, ui = -ur, -ui
    else:
        t = np.sqrt(0.5 * (m - zr))
        ur, ui = zi / (2.0 * t), t
    a, b, cc, s, qs, qp = _abcs_from_root(c, e2r, e2i, ur, ui)
    if qs < 1e-250 or qp < 1e-250:
        return _abcs_complex(c, e)
    return a, b, cc, s


@jit_inner
def abcs_row(cos, w, e, q, n, abcs, fast):
    """abcs_at for a chunk of paths at once: abcs[q, :, i] = abcs_at(cos[i], e[q, 0, i] + i·e[q, 1, i])·w[i]
    for i < n (cosines (n,), weights (n,), relative indices (L, 2, n) as real and imaginary parts).

    abcs_at's usual case (a complex index, moderate magnitudes) written without branches, so that the
    compiler runs it over several paths per instruction (AVX2: 4): ≈ 10 ns instead of ≈ 35 ns per
    evaluation.  ``fast[i]`` is False where abcs_at takes another path (a real index, |z| outside 1e±150,
    a tiny denominator, a NaN); abcs_fixups redoes those lanes with abcs_at itself, so every lane has
    abcs_at's numbers bit for bit (the same operations in the same order)."""
    for i in range(n):
        c = cos[i]
        c = 0.0 if c < 0.0 else c               # _incidence_cosine, as selects
        c = 1.0 if c > 1.0 else c
        c = 0.0 if c < _TINY else c
        er = e[q, 0, i]
        ei = e[q, 1, i]
        e2r = er * er - ei * ei
        e2i = er * ei + ei * er
        zr = e2r - (1.0 - c * c)
        zi = e2i
        big = max(abs(zr), abs(zi))
        m = np.sqrt(zr * zr + zi * zi)
        # abcs_at's two half-angle branches: m + |zr| is m + zr for zr ≥ 0 and m − zr otherwise, exactly
        t = np.sqrt(0.5 * (m + abs(zr)))
        h = zi / (2.0 * t)
        pos = zr >= 0.0
        ur = t if pos else h
        ui = h if pos else t
        flip = pos & (ui < 0.0)
        ur = -ur if flip else ur
        ui = -ui if flip else ui
        a, b, cc, s, qs, qp = _abcs_from_root(c, e2r, e2i, ur, ui)
        wi = w[i]
        abcs[q, 0, i] = a * wi
        abcs[q, 1, i] = b * wi
        abcs[q, 2, i] = cc * wi
        abcs[q, 3, i] = s * wi
        # every comparison False for a NaN: such lanes are redone too (harmless: abcs_at's own numbers)
        fast[i] = (zi != 0.0) & (big > 1e-150) & (big < 1e150) & (qs >= 1e-250) & (qp >= 1e-250)


@jit_inner
def abcs_fixups(cos, w, e, q, n, abcs, fast):
    """The lanes abcs_row left to abcs_at (``fast`` False), as abcs_at gives them."""
    for i in range(n):
        if not fast[i]:
            a, b, c, s = abcs_at(cos[i], complex(e[q, 0, i], e[q, 1, i]))
            wi = w[i]
            abcs[q, 0, i] = a * wi
            abcs[q, 1, i] = b * wi
            abcs[q, 2, i] = c * wi
            abcs[q, 3, i] = s * wi


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


# ----------------------------------------------------------------------------- mirror of a measured metal

@jit
def _tabulated_mirror_loop(cos_o, lam, wl_n, n, wl_k, k, scale, A, B, C, S):
    inside = True
    for i in range(lam.shape[0]):
        for j in range(lam.shape[1]):
            # the same relative index as engine.kernels.tables.complex_index_table, bit for bit
            e, ok = relative_index_at(wl_n, n, wl_k, k, lam[i, j], scale)
            inside = inside and ok
            c = cos_o[j]
            m = 1.0 if c >= 0 else 0.0          # behind the shading normal (or NaN): no reflection
            a_, b_, c_, s_ = abcs_at(c, e)
            A[i, j] = a_ * m
            B[i, j] = b_ * m
            C[i, j] = c_ * m
            S[i, j] = s_ * m
    return inside


def tabulated_mirror_abcs_numba(cos_o, lam, wl_n, n, wl_k, k, exterior_n):
    lam = np.ascontiguousarray(lam, dtype=np.float64)
    out = [np.empty(lam.shape) for _ in range(4)]
    wl_n, n, wl_k, k = (np.ascontiguousarray(a, dtype=np.float64) for a in (wl_n, n, wl_k, k))
    inside = _tabulated_mirror_loop(np.ascontiguousarray(cos_o, dtype=np.float64), lam, wl_n, n, wl_k, k,
                                    1.0 / float(exterior_n), *out)
    return tuple(out), bool(inside)


#: The compiled twin of engine.polarisation.fresnel.tabulated_mirror_abcs_numpy (None without Numba).
tabulated_mirror_abcs_numba = _tabulated_mirror_loop and tabulated_mirror_abcs_numba
