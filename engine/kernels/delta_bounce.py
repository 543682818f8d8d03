"""One compiled step per delta-only material group: sampled direction, Fresnel, frames and T update.

At a vertex of a smooth (Dirac) material the path tracer needs, per path j of the group ``rows``:
the sampled direction d (mirror, refraction or straight through), the Mueller value M (ABCS form,
per wavelength) in the shared frames x_in = x_out = s, the update T_new[..., j] = T[..., j]·R(s → x_T)·M
(engine.kernels.transport.update_abcs_numpy) and the new frame x_T = s.  Done as a chain of NumPy
steps this allocates some twenty (L, n) temporaries and gathers every input per group; here one
loop computes, per path, the geometry once, the Fresnel coefficients per wavelength (once where the
index is the same at every wavelength) and the rotation once into a small chunk buffer, then
updates the chunk's T columns with paths innermost.  The mirrors take their Fresnel coefficients a
wavelength at a time over the chunk's paths, in a branch-free form the compiler vectorises
(engine.kernels.fresnel.abcs_row: ≈ 10 instead of ≈ 35 ns an evaluation, abcs_at's bits).

Arrays are the batch's full per-path arrays (paths on the last axis) indexed by ``rows``: n_s, wo,
x_T (3, n) (the shading normal, the direction to the previous vertex, the path's frame ⟂ wo),
lam (Lm, n); outputs T_out, d, x_out, valid, eta_sq are written at ``rows`` only.  The throughputs
are read from the columns ``T_cols`` of T (P, P, Lm, ·) (engine.render.path_state.PathState.T_col:
the batch does not copy T when it drops finished paths).
Every step repeats the arithmetic of the NumPy chain it replaces in the same order (the materials'
``sample`` and engine.kernels.transport.update_abcs), so the numbers are those of the compiled chain
bit for bit.  The NumPy references live with the materials (engine.materials.conductor, dielectric,
filter_sheet), where the physics of each step is written, and are paired with these loops there.
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner
from .fresnel import abcs_at, abcs_fixups, abcs_row
from .geometry import unit_cross_at
from .stokes_rotation import frame_rotation_at
from .tables import interp_from_knot, relative_index_at

#: |n × k| below which the plane of incidence is undefined (engine.polarisation.frames._DEGENERATE).
_DEGENERATE = 1e-12


#: Paths per chunk: each family loop computes the chunk's Mueller values and rotations path by path,
#: then updates T row by row with paths innermost (every (row, column, λ) of T is its own stream
#: n·8 bytes from the next: walking all P·P·L of them per path misses the TLB at every step).
_CHUNK = 256


@jit
def _chunk_buffers(L):
    """Scratch for one chunk: Mueller values (L, 4, _CHUNK) as (a, b, c, s) and rotations (2, _CHUNK)."""
    return np.empty((L, 4, _CHUNK)), np.empty((2, _CHUNK))


@jit
def _fresnel_buffers(L):
    """Scratch for a chunk's Fresnel values taken a wavelength at a time over its paths (fresnel.abcs_row):
    cosines and weights (_CHUNK,), relative indices (L, 2, _CHUNK) as real and imaginary parts, and
    the lanes done by the branch-free form (_CHUNK,)."""
    return np.empty(_CHUNK), np.empty(_CHUNK), np.empty((L, 2, _CHUNK)), np.empty(_CHUNK, np.bool_)


@jit_inner
def _chunk_fresnel(cos, w, e, n, abcs, fast, complex_index):
    """abcs[q, :, i] = abcs_at(cos[i], e[q, i])·w[i] for every wavelength q and path i < n of the chunk.
    ``complex_index`` False (a real index, e.g. black glass, which abcs_at never takes the branch-free
    way): abcs_at lane by lane only."""
    for q in range(e.shape[0]):
        if complex_index:
            abcs_row(cos, w, e, q, n, abcs, fast)
        else:
            for i in range(n):
                fast[i] = False
        abcs_fixups(cos, w, e, q, n, abcs, fast)


@jit_inner
def _update_chunk(T, cols, out, rows, j0, j1, abcs, rot):
    """out[..., m] = T[..., c]·R(φ)·M for the paths m = rows[j0:j1] whose throughputs are the columns
    c = cols[j0:j1] of T (engine.render.path_state.PathState.T_col), M = [[a,b,0,0],[b,a,0,0],[0,0,c,s],
    [0,0,−s,c]] from ``abcs`` (one row per wavelength or one for all), R(φ) = (cos 2φ, sin 2φ) from ``rot``:
    _update_abcs_loop's arithmetic and order (no depolarising part)."""
    P, L = T.shape[0], T.shape[2]
    for k in range(L):
        la = k if abcs.shape[0] > 1 else 0
        for i in range(P):
            for jj in range(j1 - j0):
                m = rows[j0 + jj]
                mc = cols[j0 + jj]
                a = abcs[la, 0, jj]
                t0 = T[i, 0, k, mc]
                if P == 1:
                    out[i, 0, k, m] = t0 * a
                    continue
                b = abcs[la, 1, jj]
                t1 = T[i, 1, k, mc]
                if P >= 3:
                    c2, s2 = rot[0, jj], rot[1, jj]
                    t2 = T[i, 2, k, mc]
                    r1 = t1 * c2 - t2 * s2
                    r2 = t1 * s2 + t2 * c2
                else:
                    r1 = t1
                    r2 = 0.0
                out[i, 0, k, m] = a * t0 + b * r1
                out[i, 1, k, m] = b * t0 + a * r1
                if P == 4:
                    c, s = abcs[la, 2, jj], abcs[la, 3, jj]
                    t3 = T[i, 3, k, mc]
                    out[i, 2, k, m] = c * r2 - s * t3
                    out[i, 3, k, m] = s * r2 + c * t3
                elif P == 3:
                    out[i, 2, k, m] = abcs[la, 2, jj] * r2


@jit_inner
def _set_abcs(abcs, k, jj, a, b, c, s):
    abcs[k, 0, jj] = a
    abcs[k, 1, jj] = b
    abcs[k, 2, jj] = c
    abcs[k, 3, jj] = s


@jit_inner
def _new_frame(x_out, x_T, wo, m, s0, s1, s2, P, rot, jj):
    """Store s as the path's new frame x_out[:, m] and R(s → x_T) as (cos 2φ, sin 2φ) in rot[:, jj] (the
    identity when P < 3: nothing rotates)."""
    x_out[0, m] = s0
    x_out[1, m] = s1
    x_out[2, m] = s2
    if P >= 3:
        rot[0, jj], rot[1, jj] = frame_rotation_at(x_out, x_T, wo, m)
    else:
        rot[0, jj], rot[1, jj] = 1.0, 0.0


@jit_inner
def _mirror_geometry(n_s, wo, d, m):
    """cosθ_o = n_s·wo and the mirror direction d[:, m] = reflect(wo, n_s) (engine.vec3 order); returns
    (cosθ_o, s) with s = unit(n_s × −d) the plane-of-incidence axis."""
    n0, n1, n2 = n_s[0, m], n_s[1, m], n_s[2, m]
    w0, w1, w2 = wo[0, m], wo[1, m], wo[2, m]
    cos_o = (n0 * w0 + n1 * w1) + n2 * w2
    t = 2.0 * ((w0 * n0 + w1 * n1) + w2 * n2)
    d0 = t * n0 - w0
    d1 = t * n1 - w1
    d2 = t * n2 - w2
    d[0, m] = d0
    d[1, m] = d1
    d[2, m] = d2
    return cos_o, unit_cross_at(n0, n1, n2, -d0, -d1, -d2, _DEGENERATE)


@jit
def constant_mirror_loop(rows, n_s, wo, x_T, T, eta, T_out, d, x_out, valid, eta_sq, T_cols):
    """Fresnel mirror of one complex relative index ``eta`` (every wavelength and path): the smooth
    conductor's (and black glass's) ``sample``; valid where cosθ_o ≥ 0, the value zero elsewhere."""
    P = T.shape[0]
    abcs, rot = _chunk_buffers(1)
    cos, w, e, fast = _fresnel_buffers(1)
    e[0, 0, :] = eta.real
    e[0, 1, :] = eta.imag
    for j0 in range(0, rows.shape[0], _CHUNK):
        j1 = min(j0 + _CHUNK, rows.shape[0])
        for jj in range(j1 - j0):
            m = rows[j0 + jj]
            cos_o, s = _mirror_geometry(n_s, wo, d, m)
            ok = cos_o >= 0
            w[jj] = 1.0 if ok else 0.0
            cos[jj] = cos_o if (cos_o >= 0.0 or np.isnan(cos_o)) else 0.0        # np.maximum(cos_o, 0.0)
            _new_frame(x_out, x_T, wo, m, s[0], s[1], s[2], P, rot, jj)
            valid[m] = ok
            eta_sq[m] = 1.0
        _chunk_fresnel(cos, w, e, j1 - j0, abcs, fast, eta.imag != 0.0)
        _update_chunk(T, T_cols, T_out, rows, j0, j1, abcs, rot)


@jit
def _knot_hints(wl):
    """(first whole nm, hints): hints[i] = the last knot ≤ first + i nm, for the whole nm across the
    grid wl; an empty table where that would be long (a bisection serves then)."""
    first = np.floor(wl[0])
    size = int(np.ceil(wl[wl.shape[0] - 1]) - first) + 1
    if size > 4096:
        return first, np.empty(0, np.int64)
    hints = np.empty(size, np.int64)
    j = 0
    for i in range(size):
        while j + 1 < wl.shape[0] and wl[j + 1] <= first + i:
            j += 1
        hints[i] = j
    return first, hints


@jit_inner
def _last_knot(wl, x, first, hints):
    """The last knot ≤ x for wl[0] ≤ x ≤ wl[-1] (np.searchsorted(wl, x, "right") − 1 for increasing
    knots): from the hint at ⌊x⌋ (a step or two for knots about a nm apart or more), else by bisection."""
    m = wl.shape[0]
    if hints.shape[0] > 0:
        j = hints[int(np.floor(x) - first)]
        while j + 1 < m and wl[j + 1] <= x:
            j += 1
        return j
    lo = 0
    hi = m - 1
    while hi - lo > 1:                 # wl[lo] ≤ x < wl[hi] (or x at the last knot: held there)
        mid = (lo + hi) // 2
        if wl[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@jit_inner
def _index_on_grid(wl, n, k, x, j, scale):
    """relative_index_at(wl, n, wl, k, x, scale) for tables on one wavelength grid, wl[0] ≤ x ≤ wl[-1]
    and j = the last knot ≤ x: one search serves n and κ."""
    a = interp_from_knot(wl, n, x, j)
    b = interp_from_knot(wl, k, x, j)
    return complex((a + b * 0.0) * scale, (b - a * 0.0) * scale)


@jit
def tabulated_mirror_loop(rows, n_s, wo, x_T, T, lam, wl_n, n, wl_k, k, scale, T_out, d, x_out, valid, eta_sq, T_cols):
    """Fresnel mirror of a measured metal: the relative index (n + iκ)(λ)·scale from piecewise-linear
    tables at each path's wavelengths (engine.kernels.fresnel._tabulated_mirror_loop's arithmetic).
    Returns False, writing nothing, if some wavelength lies outside a table (the caller falls back)."""
    P, L = T.shape[0], T.shape[2]
    lo = max(wl_n[0], wl_k[0])
    hi = min(wl_n[wl_n.shape[0] - 1], wl_k[wl_k.shape[0] - 1])
    for j in range(rows.shape[0]):
        for q in range(L):
            x = lam[q, rows[j]]
            if not (x >= lo and x <= hi):
                return False
    shared_grid = wl_n.shape[0] == wl_k.shape[0] and np.all(wl_n == wl_k)
    first, hints = _knot_hints(wl_n)
    abcs, rot = _chunk_buffers(L)
    cos, w, e, fast = _fresnel_buffers(L)
    for j0 in range(0, rows.shape[0], _CHUNK):
        j1 = min(j0 + _CHUNK, rows.shape[0])
        for jj in range(j1 - j0):
            m = rows[j0 + jj]
            cos_o, s = _mirror_geometry(n_s, wo, d, m)
            cos[jj] = cos_o
            w[jj] = 1.0 if cos_o >= 0 else 0.0
            for q in range(L):
                if shared_grid:
                    x = lam[q, m]
                    eq = _index_on_grid(wl_n, n, k, x, _last_knot(wl_n, x, first, hints), scale)
                else:
                    eq, _ = relative_index_at(wl_n, n, wl_k, k, lam[q, m], scale)
                e[q, 0, jj] = eq.real
                e[q, 1, jj] = eq.imag
            _new_frame(x_out, x_T, wo, m, s[0], s[1], s[2], P, rot, jj)
            valid[m] = cos_o >= 0
            eta_sq[m] = 1.0
        # the Fresnel values a wavelength at a time over the chunk's paths (SIMD: fresnel.abcs_row)
        _chunk_fresnel(cos, w, e, j1 - j0, abcs, fast, True)
        _update_chunk(T, T_cols, T_out, rows, j0, j1, abcs, rot)
    return True


@jit_inner
def _clip01(x):
    """np.clip(x, 0, 1) (a NaN stays NaN)."""
    if x < 0.0:
        return 0.0
    if x > 1.0:
        return 1.0
    return x


@jit
def dielectric_loop(rows, n_s, wo, x_T, T, u_lobe, eta_front, eta_back, T_out, d, x_out, valid, eta_sq, T_cols):
    """Smooth dielectric (engine.materials.dielectric.SmoothDielectric.sample): reflection with
    probability A (the unpolarised reflectance), else refraction (invalid under total internal
    reflection); weights divided by the lobe's probability, refraction scaled by 1/η²."""
    P = T.shape[0]
    abcs, rot = _chunk_buffers(1)
    for j in range(rows.shape[0]):
        jj = j % _CHUNK
        m = rows[j]
        n0, n1, n2 = n_s[0, m], n_s[1, m], n_s[2, m]
        w0, w1, w2 = wo[0, m], wo[1, m], wo[2, m]
        cos_o = (n0 * w0 + n1 * w1) + n2 * w2
        front = cos_o >= 0
        eta = eta_front if front else eta_back
        if not front:
            n0, n1, n2 = -n0, -n1, -n2
        c = abs(cos_o)
        a, b, cc, ss = abcs_at(c, complex(eta, 0.0))
        reflect_lobe = u_lobe[m] < a
        # sampled direction: mirror, or the refracted d/η + (c/η − cosθ_t)·n of the camera ray d = −wo
        cl = _clip01(c)
        sin2_t = (1.0 - cl * cl) / (eta * eta)
        tir = sin2_t > 1.0
        r = 1.0 - sin2_t
        cos_t = np.sqrt(r if (r >= 0.0 or np.isnan(r)) else 0.0)
        inv_eta = 1.0 / eta
        if reflect_lobe:
            t = 2.0 * ((w0 * n0 + w1 * n1) + w2 * n2)
            d0, d1, d2 = t * n0 - w0, t * n1 - w1, t * n2 - w2
        else:
            f = c * inv_eta - cos_t
            d0, d1, d2 = -w0 * inv_eta + f * n0, -w1 * inv_eta + f * n1, -w2 * inv_eta + f * n2
        d[0, m] = d0
        d[1, m] = d1
        d[2, m] = d2
        s = unit_cross_at(n0, n1, n2, -d0, -d1, -d2, _DEGENERATE)
        # the chosen lobe's weight (fresnel_transmission_abcs for refraction)
        if reflect_lobe:
            p_r = a if a > 0 else 1.0
            va, vb, vc, vs = a / p_r, b / p_r, cc / p_r, ss / p_r
        else:
            F_s = a + b
            F_p = a - b
            T_s = 0.0 if tir else _clip01(1.0 - F_s)
            T_p = 0.0 if tir else _clip01(1.0 - F_p)
            p_t = 1.0 - a if a < 1 else 1.0
            scale_t = (inv_eta * inv_eta) / p_t
            va = (0.5 * (T_s + T_p)) * scale_t
            vb = (0.5 * (T_s - T_p)) * scale_t
            vc = np.sqrt(T_s * T_p) * scale_t
            vs = 0.0 * scale_t
        _set_abcs(abcs, 0, jj, va, vb, vc, vs)
        _new_frame(x_out, x_T, wo, m, s[0], s[1], s[2], P, rot, jj)
        valid[m] = reflect_lobe or not tir
        eta_sq[m] = 1.0 if reflect_lobe else eta * eta
        if jj == _CHUNK - 1 or j == rows.shape[0] - 1:
            _update_chunk(T, T_cols, T_out, rows, j - jj, j + 1, abcs, rot)


@jit
def filter_sheet_loop(rows, wo, x_T, T, axis, a, b, c, s, T_out, d, x_out, valid, eta_sq, T_cols):
    """Thin filter sheet (engine.materials.filter_sheet.FilterSheet.sample): straight through, d = −wo,
    in the frame of the filter axis projected ⟂ wo (any_perpendicular(wo) where the axis ∥ wo)."""
    P = T.shape[0]
    abcs, rot = _chunk_buffers(1)
    for jj in range(_CHUNK):
        _set_abcs(abcs, 0, jj, a, b, c, s)
    a0, a1, a2 = axis[0], axis[1], axis[2]
    for j in range(rows.shape[0]):
        jj = j % _CHUNK
        m = rows[j]
        k0, k1, k2 = wo[0, m], wo[1, m], wo[2, m]
        t = (a0 * k0 + a1 * k1) + a2 * k2
        x0, x1, x2 = a0 - t * k0, a1 - t * k1, a2 - t * k2
        length = np.sqrt((x0 * x0 + x1 * x1) + x2 * x2)
        if length > 1e-9:
            x0, x1, x2 = x0 / length, x1 / length, x2 / length
        else:  # engine.vec3.any_perpendicular(wo), same operation order
            sign = 1.0 if k2 >= 0 else -1.0
            f = -1.0 / (sign + k2)
            x0, x1, x2 = 1.0 + sign * k0 * k0 * f, sign * (k0 * k1 * f), -sign * k0
        d[0, m] = -k0
        d[1, m] = -k1
        d[2, m] = -k2
        _new_frame(x_out, x_T, wo, m, x0, x1, x2, P, rot, jj)
        valid[m] = True
        eta_sq[m] = 1.0
        if jj == _CHUNK - 1 or j == rows.shape[0] - 1:
            _update_chunk(T, T_cols, T_out, rows, j - jj, j + 1, abcs, rot)
