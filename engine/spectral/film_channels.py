"""A thin film's reflectance in the colour channels: what the spectral transport develops a film to under the
white, per linear-sRGB channel, and the layering albedo of a filmed layer (Cycles' rule, by the largest channel).

The film itself is engine.polarisation.thin_film (Airy's sum per wavelength); here each channel's band average of
its unpolarised reflectance, by a Fourier series of the sum over the channel's tabulated sensitivity
(engine.spectral.cie.channel_fourier_table; docs/physics.md, thin films).
"""

from __future__ import annotations

import numpy as np

from . import cie
from .spectrum import RGB_WAVELENGTHS_NM
from ..polarisation.thin_film import film_interfaces, film_reflection_abcs

__all__ = ["BAND_STEP_NM", "BAND_TERMS", "BAND_TOLERANCE", "film_band_reflectance", "film_layering_albedo",
           "layering_wavelengths"]


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
    r12_s, r12_p, r23_s, r23_p, cos_f = film_interfaces(c, n1, nf, n3)
    r12, r23 = (r12_s, r12_p), (r23_s, r23_p)
    opd = np.broadcast_to(2.0 * nf * d * cos_f.real, (3,) + shape).ravel()
    channel = np.repeat(np.arange(3), c.size)
    coherent = np.broadcast_to(cos_f.imag == 0.0, (3,) + shape).ravel()
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
    sens = cie.channel_sensitivity(lam)
    sens /= sens.sum(axis=1, keepdims=True)
    A = film_reflection_abcs(c[None, :], n1, nf[None, :], d[None, :], n3[None, :], lam[:, None])[0]   # (G, M)
    return np.einsum("gm,mg->m", A, sens[channel])
