"""A thin non-absorbing film on an interface: Airy's coherent sum of the film's multiple reflections.

Incident medium (index n₁), a film of index n_f and thickness d (real, > 0), a substrate n₃ (real, or
complex n + iκ for a metal: the same formulas with the substrate's root u₃ taken with Im ≥ 0).  With
the interface amplitudes of engine.polarisation.fresnel (same time dependence e^{−iωt}, same r_p sign)
r₁₂ at the incidence cosine cosθ for η = n_f/n₁ and r₂₃ at the film's cosine cosθ_f = u/η for η = n₃/n_f,
the film's phase thickness δ = 2π n_f d cosθ_f / λ (complex beyond the film's critical angle: the
frustrated, evanescent case) gives, per polarisation,

    r = (r₁₂ + r₂₃ e^{2iδ}) / (1 + r₁₂ r₂₃ e^{2iδ}).

The reflection Mueller matrix is the ABCS form of (r_s, r_p) as for a bare interface (docs/physics.md
§0): A = (|r_s|² + |r_p|²)/2, B = (|r_s|² − |r_p|²)/2, C = Re(r_s r_p*), S = −Im(r_s r_p*) — the film's
s–p phase difference is what makes circular polarisation (S ≠ 0) off soap films and coated lenses.
Transmission through the lossless film: T = 1 − R per polarisation, as the diattenuator A, B of T and
C = √(T_s T_p), S = 0 (the film's small transmission retardance is neglected).  d = 0 is the bare
interface exactly.
"""

from __future__ import annotations

import numpy as np

from .fresnel import fresnel_amplitudes

__all__ = ["FILM_CUTOFF_NM", "facet_film", "film_amplitudes", "film_interfaces", "film_reflection_abcs",
           "film_transmission_abcs"]

#: Thinner films are none (Cycles' THINFILM_THICKNESS_CUTOFF, nm).
FILM_CUTOFF_NM = 0.1


def facet_film(film_n, thickness_nm) -> tuple | None:
    """(index, thickness nm) of a film on a model's facets, or None (no index, or thinner than FILM_CUTOFF_NM
    everywhere); the thickness and the index each a number or a per-point one (engine.textures.TexturedNumber:
    its bounds ``lo``, ``hi``; resolved at shading points by :func:`film_at` — where thinner than the cutoff,
    Airy's sum is the bare interface's to rounding).  ValueError for a non-finite or non-positive index or a
    non-finite or negative thickness."""
    per_point = hasattr(thickness_nm, "hi")
    hi = thickness_nm.hi if per_point else thickness_nm
    if film_n is None or not hi > FILM_CUTOFF_NM:
        return None
    lo = thickness_nm.lo if per_point else thickness_nm
    n_lo, n_hi = (film_n.lo, film_n.hi) if hasattr(film_n, "hi") else (film_n, film_n)
    if not (np.isfinite(n_lo) and np.isfinite(n_hi) and n_lo > 0 and np.isfinite(lo) and np.isfinite(hi) and lo >= 0):
        raise ValueError(f"a thin film needs a finite index > 0 and thickness >= 0, got {film_n!r}, {thickness_nm!r}")
    return (film_n if hasattr(film_n, "hi") else float(film_n)), (thickness_nm if per_point else float(thickness_nm))


def film_at(film, sp):
    """The film (index, thickness) at the shading points ``sp`` (each (N,) where per point, through
    ``sp.number``), or None."""
    if film is None or not (hasattr(film[0], "hi") or hasattr(film[1], "hi")):
        return film
    return (sp.number(film[0]) if hasattr(film[0], "hi") else film[0],
            sp.number(film[1]) if hasattr(film[1], "hi") else film[1])


def film_label(film) -> str:
    """The film for a model's describe()."""
    n, d = (repr(v) if hasattr(v, "hi") else f"{v:g}" for v in film)
    return f"n {n}, {d} nm"


def film_interfaces(cos_theta, n1, n_film, n3):
    """(r₁₂_s, r₁₂_p, r₂₃_s, r₂₃_p, cosθ_f) of the coated interface (arrays broadcast together: cosθ ∈ [0, 1] in the
    incident medium, the indices): the top interface's amplitudes at cosθ, the film's cosine (complex beyond its
    critical angle) and the bottom interface's amplitudes seen from inside the film at cosθ_f."""
    c = np.clip(np.asarray(cos_theta, np.float64), 0.0, 1.0)
    eta_f = np.asarray(n_film, np.float64) / np.asarray(n1, np.float64)
    r12_s, r12_p = fresnel_amplitudes(c, eta_f + 0j)
    u = np.sqrt(eta_f * eta_f - (1.0 - c * c) + 0j)
    u = np.where(u.imag < 0, -u, u)
    cos_f = u / eta_f                                 # complex beyond the film's critical angle
    # the second interface, seen from inside the film: its amplitudes at cosθ_f (complex cosines are
    # handled by the same formula with sin² = 1 − cos²)
    n3 = np.asarray(n3)
    eta_3 = (n3 if np.iscomplexobj(n3) else n3.astype(np.float64)) / np.asarray(n_film, np.float64)
    u3 = np.sqrt(eta_3 * eta_3 - (1.0 - cos_f * cos_f) + 0j)
    u3 = np.where(u3.imag < 0, -u3, u3)
    e2 = eta_3 * eta_3
    r23_s = _ratio(cos_f - u3, cos_f + u3)          # 0/0 (index-matched at grazing): 0, as a bare interface
    r23_p = _ratio(e2 * cos_f - u3, e2 * cos_f + u3)
    return r12_s, r12_p, r23_s, r23_p, cos_f


def film_amplitudes(cos_theta, n1, n_film, d_nm, n3, lam_nm):
    """(r_s, r_p) complex reflection amplitudes of the coated interface (arrays broadcast together:
    cosθ ∈ [0, 1] in the incident medium, indices, thickness and wavelength in nm)."""
    r12_s, r12_p, r23_s, r23_p, cos_f = film_interfaces(cos_theta, n1, n_film, n3)
    delta = 2.0 * np.pi * np.asarray(n_film, np.float64) * np.asarray(d_nm, np.float64) * cos_f / \
        np.asarray(lam_nm, np.float64)
    phase = np.exp(2j * delta)
    r_s = _airy(r12_s, r23_s, phase)
    r_p = _airy(r12_p, r23_p, phase)
    return r_s, r_p


def _ratio(num, den):
    ok = den != 0
    return np.where(ok, num / np.where(ok, den, 1.0), 0.0)


def _airy(r12, r23, phase):
    """(r₁₂ + r₂₃ e^{2iδ}) / (1 + r₁₂ r₂₃ e^{2iδ}); r₁₂ where the denominator vanishes (both interfaces
    totally reflecting at grazing)."""
    num, den = r12 + r23 * phase, 1.0 + r12 * r23 * phase
    ok = np.abs(den) > 1e-300
    return np.where(ok, num / np.where(ok, den, 1.0), r12)


def film_reflection_abcs(cos_theta, n1, n_film, d_nm, n3, lam_nm):
    """(A, B, C, S) of the coated interface's reflection Mueller matrix (module docstring)."""
    r_s, r_p = film_amplitudes(cos_theta, n1, n_film, d_nm, n3, lam_nm)
    R_s = np.minimum(r_s.real ** 2 + r_s.imag ** 2, 1.0)
    R_p = np.minimum(r_p.real ** 2 + r_p.imag ** 2, 1.0)
    x = r_s * np.conj(r_p)
    return 0.5 * (R_s + R_p), 0.5 * (R_s - R_p), x.real, -x.imag


def film_transmission_abcs(R_s, R_p):
    """(A, B, C, S) of the lossless film's transmission from its reflectances (module docstring)."""
    T_s, T_p = np.maximum(1.0 - R_s, 0.0), np.maximum(1.0 - R_p, 0.0)
    return 0.5 * (T_s + T_p), 0.5 * (T_s - T_p), np.sqrt(T_s * T_p), np.zeros_like(T_s)
