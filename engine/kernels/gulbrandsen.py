"""A metal's complex index from its reflectivity and F82 value (Gulbrandsen's map) as one compiled loop.

``index_loop`` is engine.spectral.gulbrandsen.index_of per element for the modes that solve for the edge tint
(``edge_tint_for_f82``: "f82", "schlick", "schlick_tint"), the same arithmetic in the same order: the F82 value
(the edge itself, Schlick's at θ₈₂, or Schlick's × the clipped tint), the reflectances at θ₈₂ of the edge tints 0
and 1 (the compiled Fresnel ``abcs_at``'s bits, as the NumPy twin's Fresnel runs when kernels are compiled,
taken for blocks of lanes at once by fresnel.abcs_row), the edge-tint
table read bilinearly (nodes in √r and t), and Gulbrandsen's n, κ of (r, g).
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner
from .fresnel import abcs_fixups, abcs_row

#: modes of engine.spectral.gulbrandsen.index_of that this loop runs
F82, SCHLICK, SCHLICK_TINT = 0, 1, 2


@jit_inner
def _nk(r, g, r_max):
    """Gulbrandsen's (n, κ) of reflectivity r and edge tint g, clipped to [0, r_max] and [0, 1]."""
    r = min(max(r, 0.0), r_max)
    g = min(max(g, 0.0), 1.0)
    sr = np.sqrt(r)
    n = g * (1.0 - r) / (1.0 + r) + (1.0 - g) * (1.0 + sr) / (1.0 - sr)
    up, down = n + 1.0, n - 1.0
    return n, np.sqrt(max((r * (up * up) - down * down) / (1.0 - r), 0.0))


#: lanes per block: the two Fresnel values of a block's lanes are taken together (fresnel.abcs_row, SIMD)
_CHUNK = 256


@jit
def _index_loop(r_, edge_, mode, schlick_82, cos_82, r_max, table, n_out, k_out):
    R, T = table.shape
    N = r_.shape[0]
    cos, w = np.full(_CHUNK, cos_82), np.ones(_CHUNK)
    e, abcs, fast = np.empty((2, 2, _CHUNK)), np.empty((2, 4, _CHUNK)), np.empty(_CHUNK, np.bool_)
    for j0 in range(0, N, _CHUNK):
        m = min(_CHUNK, N - j0)
        for jj in range(m):         # the indices of edge tints 0 and 1 (rows 0 and 1)
            rc = min(max(r_[j0 + jj], 0.0), r_max)
            n0, k0 = _nk(rc, 0.0, r_max)
            n1, k1 = _nk(rc, 1.0, r_max)
            e[0, 0, jj], e[0, 1, jj], e[1, 0, jj], e[1, 1, jj] = n0, k0, n1, k1
        for q in range(2):          # their reflectances at θ₈₂: abcs_at(cos θ₈₂, n + iκ)[0] (·1: the same bits)
            abcs_row(cos, w, e, q, m, abcs, fast)
            abcs_fixups(cos, w, e, q, m, abcs, fast)
        for jj in range(m):
            k = j0 + jj
            r, edge = r_[k], edge_[k]
            if r != r or edge != edge:         # NaN in, NaN out (as the NumPy twin)
                n_out[k], k_out[k] = np.nan, np.nan
                continue
            if mode == F82:
                f82 = edge
            else:
                f82 = r + (1.0 - r) * schlick_82
                if mode == SCHLICK_TINT:
                    f82 = f82 * min(max(edge, 0.0), 1.0)
            rc = min(max(r, 0.0), r_max)
            lo_f = abcs[0, 0, jj]
            hi_f = abcs[1, 0, jj]
            t = min(max((f82 - lo_f) / max(hi_f - lo_f, 1e-300), 0.0), 1.0)
            x = np.sqrt(rc / r_max) * (R - 1)
            y = t * (T - 1)
            i = min(int(x), R - 2)
            j = min(int(y), T - 2)
            fx, fy = x - i, y - j
            g = ((table[i, j] * (1.0 - fx) + table[i + 1, j] * fx) * (1.0 - fy)
                 + (table[i, j + 1] * (1.0 - fx) + table[i + 1, j + 1] * fx) * fy)
            n_out[k], k_out[k] = _nk(r, g, r_max)


#: (r (N,), edge (N,), mode code, (1 − cos θ₈₂)⁵, cos θ₈₂, R_MAX, edge-tint table, out n (N,), out κ (N,));
#: None without Numba.
index_loop = _index_loop
