"""Linear interpolation in the engine's 1 nm spectral tables (e.g. 360–830 nm, engine.spectral.cie).

x = clamp(λ, lo, hi) − lo, i = min(⌊x⌋, K − 2) for K table columns, t = x − i,
value = T[k, i]·(1 − t) + T[k, i + 1]·t; NaN wavelengths read the first entry; with
``zero_outside`` values outside [lo, hi] nm (and NaN) are 0.
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner, twin


def interp_grid_numpy(table, lam_nm, lo, hi, zero_outside):
    """Rows of the (K, M) table (1 nm steps from ``lo`` to ``hi`` nm) at lam_nm → (K, *lam.shape)."""
    lam = np.asarray(lam_nm, dtype=np.float64)
    x = np.clip(np.nan_to_num(lam, nan=lo), lo, hi) - lo
    i = np.minimum(np.floor(x).astype(np.intp), table.shape[1] - 2)
    t = x - i
    out = table[:, i] * (1.0 - t) + table[:, i + 1] * t
    if zero_outside:
        out = np.where((lam >= lo) & (lam <= hi), out, 0.0)
    return out


@jit
def _interp_loop(table, lam, lo, hi, zero_outside, out):
    last = table.shape[1] - 2
    for j in range(lam.shape[0]):
        v = lam[j]
        x = lo if np.isnan(v) else v
        x = min(max(x, lo), hi) - lo
        i = min(int(np.floor(x)), last)
        t = x - i
        inside = v >= lo and v <= hi
        for k in range(table.shape[0]):
            if zero_outside and not inside:
                out[k, j] = 0.0
            else:
                out[k, j] = table[k, i] * (1.0 - t) + table[k, i + 1] * t


def interp_grid_numba(table, lam_nm, lo, hi, zero_outside):
    lam = np.asarray(lam_nm, dtype=np.float64)
    flat = np.ascontiguousarray(lam).reshape(-1)
    out = np.empty((table.shape[0], flat.shape[0]))
    _interp_loop(np.ascontiguousarray(table, dtype=np.float64), flat, float(lo), float(hi), bool(zero_outside), out)
    return out.reshape((table.shape[0],) + lam.shape)


interp_grid = twin(_interp_loop and interp_grid_numba, interp_grid_numpy)


# ----------------------------------------------------------------------------- measured (n, κ) tables

@jit_inner
def interp_at(xp, fp, x):
    """np.interp(x, xp, fp) for one x (strictly increasing xp): the same cases and arithmetic as
    NumPy's compiled_interp (ends held, exact knots returned, NaN fallback from the right knot)."""
    if np.isnan(x):
        return x
    if x < xp[0]:
        return fp[0]
    return interp_from_knot(xp, fp, x, np.searchsorted(xp, x, side="right") - 1)


@jit_inner
def interp_from_knot(xp, fp, x, j):
    """interp_at(xp, fp, x) for xp[0] ≤ x (not NaN) with j the last knot ≤ x, found by the caller
    (several tables on one grid share the search): the same cases and arithmetic."""
    if x >= xp[xp.shape[0] - 1]:
        return fp[xp.shape[0] - 1]
    if xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    r = slope * (x - xp[j]) + fp[j]
    if np.isnan(r):
        r = slope * (x - xp[j + 1]) + fp[j + 1]
        if np.isnan(r) and fp[j] == fp[j + 1]:
            r = fp[j]
    return r


def complex_index_table_numpy(lam, wl_n, n, wl_k, k, exterior_n):
    """((n + iκ)(λ) / exterior_n, inside): the relative complex index (L, N) of tabulated n and κ
    (engine.spectral TabulatedSpectrum, piecewise linear) at lam (L, N) nm; ``inside`` is False if
    some λ lies outside either table (the values there are then meaningless: the caller reports it)."""
    inside = bool(np.all((lam >= wl_n[0]) & (lam <= wl_n[-1]) & (lam >= wl_k[0]) & (lam <= wl_k[-1])))
    return (np.interp(lam, wl_n, n) + 1j * np.interp(lam, wl_k, k)) / exterior_n, inside


@jit_inner
def relative_index_at(wl_n, n, wl_k, k, x, scale):
    """(relative complex index at λ = x, whether x lies inside both tables), as NumPy's
    (interp(n) + i·interp(κ)) / e: Smith's division by e + 0i, i.e. times scale = 1/e."""
    inside = x >= wl_n[0] and x <= wl_n[-1] and x >= wl_k[0] and x <= wl_k[-1]
    a = interp_at(wl_n, n, x)
    b = interp_at(wl_k, k, x)
    return complex((a + b * 0.0) * scale, (b - a * 0.0) * scale), inside


@jit
def _complex_index_loop(lam, wl_n, n, wl_k, k, scale, out):
    inside = True
    for i in range(lam.shape[0]):
        for j in range(lam.shape[1]):
            out[i, j], ok = relative_index_at(wl_n, n, wl_k, k, lam[i, j], scale)
            inside = inside and ok
    return inside


def complex_index_table_numba(lam, wl_n, n, wl_k, k, exterior_n):
    lam = np.ascontiguousarray(lam, dtype=np.float64)
    out = np.empty(lam.shape, np.complex128)
    inside = _complex_index_loop(lam, *(np.ascontiguousarray(a, dtype=np.float64) for a in (wl_n, n, wl_k, k)),
                                 1.0 / float(exterior_n), out)
    return out, bool(inside)


complex_index_table = twin(_complex_index_loop and complex_index_table_numba, complex_index_table_numpy)
