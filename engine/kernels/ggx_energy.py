"""The multiple-scattering compensation share of a rough GGX conductor as one compiled loop.

``conductor_extra_loop`` is engine.materials.ggx_energy.conductor_extra_numpy per element, the same arithmetic
in the same order: E(μ, α) and E_avg(α) read bilinearly from the conductor table (rows 0 … mu_nodes − 1: E at
nodes in √μ and √α; row mu_nodes: E_avg), each clipped to [e_floor, 1]; Cycles' average Fresnel F_ss of the
F82-tint fit through F(0°) and F(θ₈₂) (the compiled Fresnel ``abcs_at``, as the NumPy twin calls it when kernels
are compiled; once per run of equal indices along the points: a metal of one colour), for a real index (κ = 0: a
dielectric layer) Cycles' dielectric fit instead; k = F_ms·(1 − E)/E.
One call per batch instead of some forty NumPy passes over small arrays.

``layer_albedo_loop`` is engine.materials.ggx_energy.cycles_layer_weight_numpy per point, the same arithmetic in
the same order: Cycles' layering estimate F0 + (1 − F0)·s of a dielectric GGX layer (s read trilinearly from the
16³ table at (F0^¼, √α, μ), Cycles' ``lookup_table_read``), with ``darken`` × E + F_ms·(1 − E) (E, E_avg from
the height-correlated conductor table as above, F_ms of Cycles' dielectric F_ss).
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner
from .fresnel import abcs_at

#: F82-tint constants of engine.materials.ggx_energy.f82_average_fresnel (the same Python floats)
_F = 6.0 / 7.0
_F5 = _F ** 5
_B_SCALE = 7.0 / (_F5 * _F)
_COS_82 = 1.0 / 7.0


@jit_inner
def _cell(v, hi, nodes):
    """(cell index, fraction) of v clipped to [0, hi] on nodes in √v (NumPy: sqrt(clip)·(nodes − 1), astype)."""
    x = np.sqrt(min(max(v, 0.0), hi)) * (nodes - 1)
    i = min(int(x), nodes - 2)
    return i, x - i


@jit_inner
def _average_fresnel(e):
    if e.imag == 0.0:                      # a dielectric: Cycles' fresnel_dielectric_Fss (dielectric_average_fresnel)
        x = e.real
        if x < 1.0:
            return 0.997118 + x * (0.1014 - x * (0.965241 + x * 0.130607))
        return (x - 1.0) / (4.08567 + 1.00071 * x)
    F0 = abcs_at(1.0, e)[0]
    F82 = abcs_at(_COS_82, e)[0]
    b = _B_SCALE * (F0 + (1.0 - F0) * _F5 - F82)
    return min(max(F0 + (1.0 - F0) / 21.0 - b / 126.0, 0.0), 1.0)


@jit_inner
def _white_albedo(m, a, table, mu_nodes, rough_nodes, alpha_max, e_floor):
    """(E(μ, α), E_avg(α)) of the F = 1 lobe read bilinearly from the conductor table, each clipped to [e_floor, 1]."""
    i, fx = _cell(m, 1.0, mu_nodes)
    j, fy = _cell(a, alpha_max, rough_nodes)
    E = ((table[i, j] * (1.0 - fx) + table[i + 1, j] * fx) * (1.0 - fy)
         + (table[i, j + 1] * (1.0 - fx) + table[i + 1, j + 1] * fx) * fy)
    E_avg = table[mu_nodes, j] * (1.0 - fy) + table[mu_nodes, j + 1] * fy
    return min(max(E, e_floor), 1.0), min(max(E_avg, e_floor), 1.0)


@jit
def _conductor_extra_loop(mu, alpha, eta, table, mu_nodes, rough_nodes, alpha_max, e_floor, out):
    L, M = eta.shape
    n = mu.shape[0]
    fss_col = np.empty(L)
    last = np.empty(L, np.complex128)      # (M = N) the last index seen per row and its F_ss: one metal's
    for q in range(L if M > 0 else 0):     # index repeated over the points is evaluated once
        fss_col[q] = _average_fresnel(eta[q, 0])
        last[q] = eta[q, 0]
    for k in range(n):
        m, a = mu[k], alpha[k]
        if m != m or a != a:
            for q in range(L):
                out[q, k] = np.nan
            continue
        E, E_avg = _white_albedo(m, a, table, mu_nodes, rough_nodes, alpha_max, e_floor)
        share = (1.0 - E) / E
        for q in range(L):
            if M > 1:
                e = eta[q, k]
                if e.real != last[q].real or e.imag != last[q].imag:
                    fss_col[q] = _average_fresnel(e)
                    last[q] = e
            Fss = fss_col[q]
            Fms = Fss * E_avg / (1.0 - Fss * (1.0 - E_avg))
            out[q, k] = Fms * share


@jit_inner
def _lerp(v, nodes):
    """(index, next index, fraction) of v clipped to [0, 1] on ``nodes`` nodes (ggx_energy._lerp_coordinate)."""
    x = min(max(v, 0.0), 1.0) * (nodes - 1)
    i = min(int(x), nodes - 1)
    return i, min(i + 1, nodes - 1), x - i


@jit
def _layer_albedo_loop(mu, alpha, eta, schlick, table, mu_nodes, rough_nodes, alpha_max, e_floor, darken, out):
    nodes = schlick.shape[0]
    for k in range(mu.shape[0]):
        m, a, e = mu[k], alpha[k], eta[k]
        if m != m or a != a or e != e:     # NaN in, NaN out (as the NumPy twin)
            out[k] = np.nan
            continue
        q = (e - 1.0) / (e + 1.0)
        iz, jz, fz = _lerp(np.sqrt(abs(q)), nodes)
        ir, jr, fr = _lerp(np.sqrt(a), nodes)
        im, jm, fm = _lerp(m, nodes)
        lo = ((1.0 - fm) * ((1.0 - fr) * schlick[iz, ir, im] + fr * schlick[iz, jr, im])
              + fm * ((1.0 - fr) * schlick[iz, ir, jm] + fr * schlick[iz, jr, jm]))
        hi = ((1.0 - fm) * ((1.0 - fr) * schlick[jz, ir, im] + fr * schlick[jz, jr, im])
              + fm * ((1.0 - fr) * schlick[jz, ir, jm] + fr * schlick[jz, jr, jm]))
        s = (1.0 - fz) * lo + fz * hi
        F0 = q * q
        value = F0 + (1.0 - F0) * s
        if darken:
            E, E_avg = _white_albedo(m, a, table, mu_nodes, rough_nodes, alpha_max, e_floor)
            Fss = _average_fresnel(complex(e, 0.0))
            Fms = Fss * E_avg / (1.0 - Fss * (1.0 - E_avg))
            value = value * (E + Fms * (1.0 - E))
        out[k] = value


#: (mu (N,), alpha (N,), eta (N,) real, schlick (S, S, S), table, mu_nodes, rough_nodes, alpha_max, e_floor, darken,
#: out (N,)); None without Numba.
layer_albedo_loop = _layer_albedo_loop

#: (mu (N,), alpha (N,), eta (L, 1 or N) complex, table, mu_nodes, rough_nodes, alpha_max, e_floor, out (L, N));
#: None without Numba.
conductor_extra_loop = _conductor_extra_loop
