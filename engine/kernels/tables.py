"""Linear interpolation in the engine's 1 nm spectral tables (e.g. 360–830 nm, engine.spectral.cie).

x = clamp(λ, lo, hi) − lo, i = min(⌊x⌋, K − 2) for K table columns, t = x − i,
value = T[k, i]·(1 − t) + T[k, i + 1]·t; NaN wavelengths read the first entry; with
``zero_outside`` values outside [lo, hi] nm (and NaN) are 0.
"""

from __future__ import annotations

import numpy as np

from . import jit, twin


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
