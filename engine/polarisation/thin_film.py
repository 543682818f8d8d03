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
from ..spectral import RGB_WAVELENGTHS_NM, cie

__all__ = ["FILM_CUTOFF_NM", "facet_film", "film_amplitudes", "film_band_reflectance", "film_layering_albedo",
           "film_reflection_abcs", "film_transmission_abcs", "layering_wavelengths"]

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


def film_amplitudes(cos_theta, n1, n_film, d_nm, n3, lam_nm):
    """(r_s, r_p) complex reflection amplitudes of the coated interface (arrays broadcast together:
    cosθ ∈ [0, 1] in the incident medium, indices, thickness and wavelength in nm)."""
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


def layering_wavelengths(sp):
    """The wavelengths at which ``film_layering_albedo`` reads a film at the shading points ``sp``: the RGB
    channels' (engine.spectral.RGB_WAVELENGTHS_NM) in "rgb" transport, where the film itself is evaluated there;
    else None (each channel's band, as the spectral transport develops the film's reflection)."""
    lookup = getattr(sp, "lookup", None)
    return RGB_WAVELENGTHS_NM if lookup is not None and lookup.channels else None


def film_layering_albedo(cos_o, n1, film, n3, lam_nm=None) -> np.ndarray:
    """(N,) Cycles' estimate of a filmed layer's albedo for layering what lies below (it has no table for
    iridescence): the film's reflectance at the view angle cos_o (N,), the largest over the colour channels, as
    Cycles layers by the largest channel — each channel's band average under the white (``film_band_reflectance``)
    where ``lam_nm`` is None, else the largest over the wavelengths ``lam_nm`` (K,) ("rgb" transport:
    ``layering_wavelengths``).  ``film`` = (index, thickness nm) (facet_film); n1 the medium above, n3 the
    substrate (complex for a metal; (3, 1) or (3, N): one per channel)."""
    if lam_nm is None:
        return film_band_reflectance(cos_o, n1, film[0], film[1], n3).max(axis=0)
    lam = np.asarray(lam_nm, np.float64)[:, None]
    c = np.clip(np.asarray(cos_o, np.float64), 0.0, 1.0)[None, :]
    return film_reflection_abcs(c, n1, film[0], film[1], n3, lam)[0].max(axis=0)


#: the Fourier series of ``film_band_reflectance`` stops where |B|·|q|^k is below this, or after BAND_TERMS terms
BAND_TOLERANCE = 1e-14
BAND_TERMS = 4000
#: its fallback quadrature (evanescent films, |q| → 1): wavelengths every BAND_STEP_NM nm
BAND_STEP_NM = 5.0


def film_band_reflectance(cos_theta, n1, n_film, d_nm, n3) -> np.ndarray:
    """(3, N) the film's unpolarised reflectance (R_s + R_p)/2 at cosθ (N,) averaged over each linear-sRGB
    channel's band under the unit D65 white (engine.spectral.cie.channel_fourier_table): what the spectral
    transport's film reflects of a white light, developed to RGB.  Indices do not vary within a band: ``n_film``
    and ``d_nm`` numbers or (N,), ``n3`` a number, (N,), or one per channel ((3, 1) or (3, N), complex for a metal).

    Airy's r = Σ_m a_m z^m (z = e^{2πi·OPD/λ}, OPD = 2 n_f d cosθ_f; a₀ = r₁₂, a_m = (1 − r₁₂²) r₂₃ q^{m−1},
    q = −r₁₂ r₂₃) makes |r|² = c₀ + 2 Re Σ_{k≥1} c_k z^k with c₀ = |r₁₂|² + |1 − r₁₂²|²|r₂₃|²/(1 − |q|²) and
    c_k = B q^{k−1}, B = (1 − r₁₂²) r₂₃ r₁₂* + |1 − r₁₂²|²|r₂₃|² q/(1 − |q|²); a band's average of z^k is
    S_c(k·OPD) — exact where the film's cosine is real (docs/physics.md, thin films).  Evanescent films and
    |q| → 1 are averaged by quadrature every BAND_STEP_NM nm instead."""
    c = np.clip(np.asarray(cos_theta, np.float64), 0.0, 1.0)
    shape = c.shape
    nf = np.broadcast_to(np.asarray(n_film, np.float64), shape)
    d = np.broadcast_to(np.asarray(d_nm, np.float64), shape)
    n3 = np.asarray(n3)
    n3 = np.broadcast_to(n3 if np.iscomplexobj(n3) else n3.astype(np.float64), (3,) + shape)
    eta_f = nf / np.asarray(n1, np.float64)
    r12 = fresnel_amplitudes(c, eta_f + 0j)
    u = np.sqrt(eta_f * eta_f - (1.0 - c * c) + 0j)
    u = np.where(u.imag < 0, -u, u)
    cos_f = u / eta_f
    eta_3 = n3 / nf
    u3 = np.sqrt(eta_3 * eta_3 - (1.0 - cos_f * cos_f) + 0j)
    u3 = np.where(u3.imag < 0, -u3, u3)
    e2 = eta_3 * eta_3
    r23 = (_ratio(cos_f - u3, cos_f + u3), _ratio(e2 * cos_f - u3, e2 * cos_f + u3))
    opd = np.broadcast_to(2.0 * nf * d * cos_f.real, (3,) + shape).ravel()
    channel = np.repeat(np.arange(3), c.size)
    coherent = np.broadcast_to(u.imag == 0.0, (3,) + shape).ravel()
    h, table = cie.channel_fourier_table()
    last = table.shape[1] - 1
    R = np.zeros(3 * c.size)
    exact = np.zeros(3 * c.size, bool)
    for a, b in zip(r12, r23):
        a = np.broadcast_to(a, (3,) + shape).ravel()
        b = b.ravel()
        q = -a * b
        t2 = np.abs(1.0 - a * a) ** 2 * np.abs(b) ** 2
        den = 1.0 - np.abs(q) ** 2
        ok = coherent & (den > 1e-9)
        safe = np.where(ok, den, 1.0)
        c0 = np.abs(a) ** 2 + t2 / safe
        B = (1.0 - a * a) * b * np.conj(a) + t2 * q / safe
        series = np.zeros(q.shape, np.complex128)
        power = np.ones(q.shape, np.complex128)
        act = np.flatnonzero(ok & (np.abs(B) > 0.0))
        for k in range(1, BAND_TERMS + 1):
            if act.size == 0:
                break
            t = k * opd[act] / h
            i0 = np.minimum(t.astype(np.int64), last - 1)
            f = t - i0
            ch = channel[act]
            S = np.where(t < last, table[ch, i0] * (1.0 - f) + table[ch, i0 + 1] * f, 0.0)
            series[act] += power[act] * S
            power[act] *= q[act]
            act = act[np.abs(B[act]) * np.abs(power[act]) > BAND_TOLERANCE]
        done = ok.copy()
        done[act] = False
        R += np.where(done, 0.5 * (c0 + 2.0 * (B * series).real), 0.0)
        exact |= ~done
    rest = np.flatnonzero(exact)
    if rest.size:
        R[rest] = _band_quadrature(np.tile(c.ravel(), 3)[rest], n1, np.tile(nf.ravel(), 3)[rest],
                                   np.tile(d.ravel(), 3)[rest], n3.ravel()[rest], channel[rest])
    return R.reshape((3,) + shape)


def _band_quadrature(c, n1, nf, d, n3, channel) -> np.ndarray:
    """(M,) ``film_band_reflectance``'s channel averages by quadrature (every BAND_STEP_NM nm, the channel's
    sensitivity as in engine.spectral.cie.channel_fourier_table) of films whose phase factor is not a pure
    phase (evanescent) or whose series converges slowly."""
    lam = np.arange(cie.LAMBDA_MIN, cie.LAMBDA_MAX + 0.5 * BAND_STEP_NM, BAND_STEP_NM)
    sens = np.tensordot(cie.XYZ_TO_LINEAR_SRGB, cie.cmf_xyz(lam), axes=1) * cie.d65_normalised(lam)
    sens /= sens.sum(axis=1, keepdims=True)
    A = film_reflection_abcs(c[None, :], n1, nf[None, :], d[None, :], n3[None, :], lam[:, None])[0]   # (G, M)
    return np.einsum("gm,mg->m", A, sens[channel])
