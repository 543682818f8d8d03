"""Fresnel amplitudes and Mueller matrices of a smooth interface (docs/physics.md §0).

Time dependence e^{−iωt}; complex relative index η = η_t / n_i = n + iκ with
κ ≥ 0 (so internal reflection has |η| < 1).  Amplitudes:

    u   = √(η² − sin²θ)  on the branch Im u ≥ 0
    r_s = (cosθ − u) / (cosθ + u),   r_p = (η² cosθ − u) / (η² cosθ + u)

(r_p → −r_s at normal incidence).  The reflection Mueller matrix in frames
with x = s = ±unit(n × k) on both beams and y = k × s is the ABCS form
[[A,B,0,0],[B,A,0,0],[0,0,C,S],[0,0,−S,C]] with A = (F_s+F_p)/2,
B = (F_s−F_p)/2, C = Re(r_s r_p*), S = −Im(r_s r_p*).
Transmission (real η, below the critical angle) is the diattenuator
A = (T_s+T_p)/2, B = (T_s−T_p)/2, C = √(T_s T_p), S = 0 with T = 1 − F; the
radiance factor of refraction is *not* included (see the dielectric material).
"""

from __future__ import annotations

import numpy as np

from .mueller import abcs_matrix
from ..kernels import twin
from ..kernels.fresnel import fresnel_reflection_abcs_numba, tabulated_mirror_abcs_numba
from ..kernels.tables import complex_index_table_numpy


_TINY = 1e-200


def fresnel_amplitudes(cos_theta, eta):
    """Complex reflection amplitudes (r_s, r_p) for incidence cosine cosθ ∈ [0, 1].

    ``eta`` is the complex relative index n + iκ (κ ≥ 0), broadcast with cosθ.
    Where the interface is index-matched at grazing incidence (u = 0 and
    cosθ = 0) the amplitudes are defined as 0.
    """
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    # Complex division overflows for subnormal denominators; angles within 1e-200 rad
    # of grazing are grazing.
    c = np.where(c < _TINY, 0.0, c)
    eta = np.asarray(eta, dtype=np.complex128)
    eta2 = eta * eta
    u = np.sqrt(eta2 - (1.0 - c * c) + 0j)
    # Principal sqrt has Re u ≥ 0; a negative-zero imaginary part would put u on
    # the wrong branch for TIR, so enforce Im u ≥ 0 explicitly.
    u = np.where(u.imag < 0, -u, u)
    u = np.where(np.abs(u) < _TINY, 0.0, u)
    den_s = c + u
    den_p = eta2 * c + u
    ok_s = den_s != 0
    ok_p = den_p != 0
    r_s = np.where(ok_s, (c - u) / np.where(ok_s, den_s, 1.0), 0.0)
    r_p = np.where(ok_p, (eta2 * c - u) / np.where(ok_p, den_p, 1.0), 0.0)
    return r_s, r_p


def fresnel_reflection_abcs_numpy(cos_theta, eta):
    """(A, B, C, S) of the Fresnel reflection Mueller matrix (see module docstring)."""
    r_s, r_p = fresnel_amplitudes(cos_theta, eta)
    F_s = r_s.real ** 2 + r_s.imag ** 2
    F_p = r_p.real ** 2 + r_p.imag ** 2
    x = r_s * np.conj(r_p)
    return 0.5 * (F_s + F_p), 0.5 * (F_s - F_p), x.real, -x.imag


#: (A, B, C, S) of the Fresnel reflection Mueller matrix for cosθ and η broadcast together; the
#: compiled loop of engine.kernels.fresnel when available (same numbers up to rounding).
fresnel_reflection_abcs = twin(fresnel_reflection_abcs_numba, fresnel_reflection_abcs_numpy)


def tabulated_mirror_abcs_numpy(cos_o, lam, wl_n, n, wl_k, k, exterior_n):
    """((A, B, C, S), inside): the Fresnel mirror of a measured conductor in one step.

    The relative index (n + iκ)(λ)/exterior_n from piecewise-linear tables (wl_n, n), (wl_k, k) [nm]
    at lam (L, N) nm, then the reflection coefficients at cos_o (N,), zero where cos_o < 0 (behind
    the shading normal) or NaN; each (L, N).  ``inside`` is False if some λ lies outside a table
    (the values are then meaningless: the caller falls back to the spectra's own evaluation).
    """
    eta, inside = complex_index_table_numpy(lam, wl_n, n, wl_k, k, exterior_n)
    cos_o = np.asarray(cos_o, dtype=np.float64)
    m = (cos_o >= 0).astype(np.float64)[None, :]
    A, B, C, S = fresnel_reflection_abcs_numpy(np.maximum(cos_o, 0.0)[None, :], eta)
    return (A * m, B * m, C * m, S * m), inside


#: The measured-metal mirror (complex index from tables + Fresnel) as one compiled loop when available.
tabulated_mirror_abcs = twin(tabulated_mirror_abcs_numba, tabulated_mirror_abcs_numpy)


def fresnel_reflection_mueller(cos_theta, eta) -> np.ndarray:
    """Reflection Mueller matrix (4, 4, ...) in the plane-of-incidence frames."""
    return abcs_matrix(*fresnel_reflection_abcs(cos_theta, eta))


def fresnel_reflectance(cos_theta, eta):
    """Unpolarised reflectance (F_s + F_p)/2."""
    return fresnel_reflection_abcs(cos_theta, eta)[0]


def refracted_cosine(cos_theta, eta):
    """cosθ_t of the refracted beam for *real* relative index η, and a TIR mask.

    Snell: sinθ_t = sinθ/η.  Where sin²θ_t > 1 (total internal reflection)
    cosθ_t is returned as 0 and ``tir`` is True.
    """
    c = np.clip(np.asarray(cos_theta, dtype=np.float64), 0.0, 1.0)
    eta = np.asarray(eta, dtype=np.float64)
    sin2_t = (1.0 - c * c) / (eta * eta)
    tir = sin2_t > 1.0  # sin²θ_t = 1 exactly is grazing refraction (or an index-matched grazing ray)
    cos_t = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    return cos_t, tir


def fresnel_transmission_abcs(cos_theta, eta):
    """(A, B, C, S) of the transmission diattenuator for real η; zero under TIR.

    Power transmittances T_s = 1 − F_s, T_p = 1 − F_p (energy conservation at the
    interface); no retardance below the critical angle.
    """
    A_r, B_r, _, _ = fresnel_reflection_abcs(cos_theta, eta)
    F_s = A_r + B_r
    F_p = A_r - B_r
    _, tir = refracted_cosine(cos_theta, np.real(eta))
    T_s = np.where(tir, 0.0, np.clip(1.0 - F_s, 0.0, 1.0))
    T_p = np.where(tir, 0.0, np.clip(1.0 - F_p, 0.0, 1.0))
    zero = np.zeros_like(T_s)
    return 0.5 * (T_s + T_p), 0.5 * (T_s - T_p), np.sqrt(T_s * T_p), zero


def fresnel_transmission_mueller(cos_theta, eta) -> np.ndarray:
    """Transmission Mueller matrix (4, 4, ...) (diattenuator) in plane-of-incidence frames."""
    return abcs_matrix(*fresnel_transmission_abcs(cos_theta, eta))
