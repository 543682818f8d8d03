"""Rough dielectric (Walter et al. 2007) eval, pdf and sample as one compiled pass each.

Per path: the viewer-side normal and relative index η, the local frame, the (generalised) half
vector, D and the separable Smith G of the Beckmann or GGX facets, the facet Fresnel reflection or
transmission (A, B, C, S) (engine.kernels.fresnel.abcs_at), the scattering-plane frame, the
visible-normal sample, the reflect/refract choice and the pdf.  The NumPy references are the
material's batched formulas (engine.materials.rough_dielectric, where the twins are declared),
written here in the same operation order, so the compiled pass gives their bits.

Distribution codes: 0 Beckmann, 1 GGX.  ``no_fresnel`` (Cycles' Refraction BSDF, engine.materials.refraction): no
reflection lobe, the transmission the identity Mueller matrix (1 at every facet, 0 under total internal
reflection).  The value is the same at every wavelength (one real index), written to each of the L rows.  The
roughness α and the relative indices η (seen from outside, from inside) are each one number (a one-element array) or
one per path (N,) (a textured roughness, a textured index), read with ``at``.
"""

from __future__ import annotations

import numpy as np

from . import jit, jit_inner
from .error_function import ERFCX_COEF, ERFCX_K
from .fresnel import abcs_at
from .microfacet import (beckmann_d_at, beckmann_g1_at, beckmann_lambda_at, beckmann_vndf_at, chi_plus_at,
                         ggx_d_at, ggx_lambda_at, ggx_vndf_at, smith_a_at)
from .geometry import local_frame_at, to_local_at, unit_cross_at
from .torrance_sparrow import at

DISTRIBUTION_CODES = {"beckmann": 0, "ggx": 1}
_ERFCX_COEF = np.ascontiguousarray(ERFCX_COEF, dtype=np.float64)
_ERFCX_K = float(ERFCX_K)


@jit_inner
def _d_at(dist, h0, h1, h2, alpha):
    return beckmann_d_at(h0, h1, h2, alpha) if dist == 0 else ggx_d_at(h0, h1, h2, alpha)


@jit_inner
def _g1_at(dist, rational, w0, w1, w2, h0, h1, h2, alpha, coef, k):
    if dist == 0:
        return beckmann_g1_at(w0, w1, w2, h0, h1, h2, alpha, rational, coef, k)
    return chi_plus_at(w0, w1, w2, h0, h1, h2) / (1.0 + ggx_lambda_at(w0, w1, w2, alpha))


@jit_inner
def _vndf_pdf_at(dist, o0, o1, o2, h0, h1, h2, alpha, coef, k):
    """G1(ω_o) max(0, ω_o·h) D(h)/cosθ_o (Beckmann.pdf / GGX.pdf)."""
    d = o0 * h0 + o1 * h1 + o2 * h2
    if not (o2 > 0 and d > 0):
        return 0.0
    if dist == 0:
        lam = beckmann_lambda_at(smith_a_at(o0, o1, o2, alpha), coef, k)
    else:
        lam = ggx_lambda_at(o0, o1, o2, alpha)
    g1 = 1.0 / (1.0 + lam)
    return g1 * max(d, 0.0) * _d_at(dist, h0, h1, h2, alpha) / o2


@jit
def _viewer_side(n_s, wo, i, eta_out, eta_in):
    """(nn, η, t, b) at path i: the normal on the viewer's side, η = n_far/n_viewer and its frame."""
    n0, n1, n2 = n_s[0, i], n_s[1, i], n_s[2, i]
    if n0 * wo[0, i] + n1 * wo[1, i] + n2 * wo[2, i] >= 0:
        eta = at(eta_out, i)
    else:
        eta = at(eta_in, i)
        n0, n1, n2 = -n0, -n1, -n2
    t0, t1, t2, b0, b1, b2 = local_frame_at(n0, n1, n2)
    return n0, n1, n2, eta, t0, t1, t2, b0, b1, b2


@jit_inner
def _half_vector_at(i0, i1, i2, o0, o1, o2, eta):
    """(h, reflects, ok, ω_i·h, ω_o·h) of RoughDielectric._half_vector."""
    refl = i2 > 0
    if refl:
        hv0, hv1, hv2 = i0 + o0, i1 + o1, i2 + o2
    else:
        hv0, hv1, hv2 = -(eta * i0 + o0), -(eta * i1 + o1), -(eta * i2 + o2)
    length = np.sqrt(hv0 * hv0 + hv1 * hv1 + hv2 * hv2)
    ok = length > 1e-12 and o2 > 0 and i2 != 0
    ln = length if ok else 1.0
    h0, h1, h2 = hv0 / ln, hv1 / ln, hv2 / ln
    if h2 < 0:
        h0, h1, h2 = -h0, -h1, -h2
    d_o = o0 * h0 + o1 * h1 + o2 * h2
    d_i = i0 * h0 + i1 * h1 + i2 * h2
    ok = ok and d_o > 0 and ((d_i > 0) if refl else (d_i < 0)) and h2 > 0
    return h0, h1, h2, refl, ok, d_i, d_o


@jit_inner
def _tir_at(c, eta):
    """Total internal reflection at a facet of incidence cosine c (no refracted direction)."""
    c = min(max(c, 0.0), 1.0)
    return (1.0 - c * c) / (eta * eta) > 1.0


@jit
def _pdf_local_at(dist, i0, i1, i2, o0, o1, o2, eta, alpha, coef, k, no_fresnel):
    """RoughDielectric._pdf_local for one pair of local directions."""
    h0, h1, h2, refl, ok, d_i, d_o = _half_vector_at(i0, i1, i2, o0, o1, o2, eta)
    if not ok or (no_fresnel and refl):
        return 0.0
    vndf = _vndf_pdf_at(dist, o0, o1, o2, h0, h1, h2, alpha, coef, k)
    if no_fresnel:
        F = 1.0 if _tir_at(d_o, eta) else 0.0
    else:
        F = abcs_at(d_o, complex(eta, 0.0))[0]
    if refl:
        return F * vndf / (4.0 * d_o)
    jac = eta * d_i + d_o
    return (1.0 - F) * vndf * eta * eta * abs(d_i) / (jac * jac)


@jit
def _eval_at(i, n0, n1, n2, eta, t0, t1, t2, b0, b1, b2, wo, wi, dist, rational, alpha, coef, k, factor,
             A, B, C, S, x, no_fresnel):
    """RoughDielectric.eval at path i (times ``factor``) into A..S[:, i] and x[:, i]."""
    o0, o1, o2 = wo[0, i], wo[1, i], wo[2, i]
    w0, w1, w2 = wi[0, i], wi[1, i], wi[2, i]
    lo0, lo1, lo2 = to_local_at(o0, o1, o2, t0, t1, t2, b0, b1, b2, n0, n1, n2)
    li0, li1, li2 = to_local_at(w0, w1, w2, t0, t1, t2, b0, b1, b2, n0, n1, n2)
    h0, h1, h2, refl, ok, d_i, d_o = _half_vector_at(li0, li1, li2, lo0, lo1, lo2, eta)
    scalar = 0.0
    c_f = 1.0
    den_cos = abs(li2) * lo2
    if ok and den_cos > 0.0:         # a product underflowing to 0 (both directions at grazing): f = 0, not 0/0
        D = _d_at(dist, h0, h1, h2, alpha)
        G = (_g1_at(dist, rational, li0, li1, li2, h0, h1, h2, alpha, coef, k)
             * _g1_at(dist, rational, lo0, lo1, lo2, h0, h1, h2, alpha, coef, k))
        if refl:
            scalar = D * G / (4.0 * den_cos)
            c_f = d_i
        else:
            jac = eta * d_i + d_o
            scalar = abs(d_i) * d_o * D * G / (den_cos * (jac * jac))
            c_f = d_o
    a_, b_, c_, s_ = abcs_at(c_f, complex(eta, 0.0))
    if no_fresnel:
        # Cycles' Refraction: no reflection; transmission the identity, 0 under total internal reflection
        one = 0.0 if refl or _tir_at(c_f, eta) else 1.0
        a_, b_, c_, s_ = one, 0.0, one, 0.0
    elif not refl:
        # the transmission diattenuator (engine.polarisation.fresnel.fresnel_transmission_abcs)
        F_s = a_ + b_
        F_p = a_ - b_
        c = min(max(c_f, 0.0), 1.0)
        if (1.0 - c * c) / (eta * eta) > 1.0:
            T_s = T_p = 0.0
        else:
            T_s = min(max(1.0 - F_s, 0.0), 1.0)
            T_p = min(max(1.0 - F_p, 0.0), 1.0)
        a_, b_, c_, s_ = 0.5 * (T_s + T_p), 0.5 * (T_s - T_p), np.sqrt(T_s * T_p), 0.0
    a_, b_, c_, s_ = a_ * scalar * factor, b_ * scalar * factor, c_ * scalar * factor, s_ * scalar * factor
    for lam in range(A.shape[0]):
        A[lam, i], B[lam, i], C[lam, i], S[lam, i] = a_, b_, c_, s_
    # x = unit(k_i × k_o), k_i = −ω_i (engine.kernels.geometry.unit_cross, same order)
    x[0, i], x[1, i], x[2, i] = unit_cross_at(-w0, -w1, -w2, o0, o1, o2, 1e-12)


@jit
def _eval_loop(n_s, wo, wi, eta_out, eta_in, dist, rational, alpha, coef, k, A, B, C, S, x, no_fresnel):
    for i in range(n_s.shape[1]):
        n0, n1, n2, eta, t0, t1, t2, b0, b1, b2 = _viewer_side(n_s, wo, i, eta_out, eta_in)
        _eval_at(i, n0, n1, n2, eta, t0, t1, t2, b0, b1, b2, wo, wi, dist, rational, at(alpha, i), coef, k, 1.0,
                 A, B, C, S, x, no_fresnel)


@jit
def _pdf_loop(n_s, wo, wi, eta_out, eta_in, dist, alpha, coef, k, out, no_fresnel):
    for i in range(n_s.shape[1]):
        n0, n1, n2, eta, t0, t1, t2, b0, b1, b2 = _viewer_side(n_s, wo, i, eta_out, eta_in)
        o0, o1, o2 = wo[0, i], wo[1, i], wo[2, i]
        w0, w1, w2 = wi[0, i], wi[1, i], wi[2, i]
        out[i] = _pdf_local_at(dist, w0 * t0 + w1 * t1 + w2 * t2, w0 * b0 + w1 * b1 + w2 * b2,
                               w0 * n0 + w1 * n1 + w2 * n2, o0 * t0 + o1 * t1 + o2 * t2,
                               o0 * b0 + o1 * b1 + o2 * b2, o0 * n0 + o1 * n1 + o2 * n2, eta, at(alpha, i), coef,
                               k, no_fresnel)


@jit
def _sample_loop(n_s, wo, u_lobe, u_dir, eta_out, eta_in, dist, rational, alpha, coef, k,
                 wi, pdf, valid, eta_sq, A, B, C, S, x, no_fresnel):
    for i in range(n_s.shape[1]):
        n0, n1, n2, eta, t0, t1, t2, b0, b1, b2 = _viewer_side(n_s, wo, i, eta_out, eta_in)
        a = at(alpha, i)
        o0, o1, o2 = wo[0, i], wo[1, i], wo[2, i]
        lo0 = o0 * t0 + o1 * t1 + o2 * t2
        lo1 = o0 * b0 + o1 * b1 + o2 * b2
        lo2 = o0 * n0 + o1 * n1 + o2 * n2
        front = lo2 > 0
        if not front:
            lo0, lo1, lo2 = 0.0, 0.0, 1.0
        if dist == 0:
            h0, h1, h2 = beckmann_vndf_at(lo0, lo1, lo2, u_dir[0, i], u_dir[1, i], a, coef, k)
        else:
            h0, h1, h2 = ggx_vndf_at(lo0, lo1, lo2, u_dir[0, i], u_dir[1, i], a)
        c = min(max(lo0 * h0 + lo1 * h1 + lo2 * h2, 0.0), 1.0)
        if no_fresnel:                                # (a "reflection" then: no lobe, the sample is invalid)
            F = 1.0 if _tir_at(c, eta) else 0.0
        else:
            F = abcs_at(c, complex(eta, 0.0))[0]      # 1 under total internal reflection
        reflect = u_lobe[i] < F
        if reflect:
            d = lo0 * h0 + lo1 * h1 + lo2 * h2
            l0 = 2.0 * d * h0 - lo0
            l1 = 2.0 * d * h1 - lo1
            l2 = 2.0 * d * h2 - lo2
        else:
            inv_eta = 1.0 / eta
            cos_t = np.sqrt(max(1.0 - (1.0 - c * c) * inv_eta * inv_eta, 0.0))
            g = c * inv_eta - cos_t
            l0 = -lo0 * inv_eta + g * h0
            l1 = -lo1 * inv_eta + g * h1
            l2 = -lo2 * inv_eta + g * h2
        ln = np.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
        l0, l1, l2 = l0 / ln, l1 / ln, l2 / ln
        w0 = t0 * l0 + b0 * l1 + n0 * l2
        w1 = t1 * l0 + b1 * l1 + n1 * l2
        w2 = t2 * l0 + b2 * l1 + n2 * l2
        wi[0, i], wi[1, i], wi[2, i] = w0, w1, w2
        q = _pdf_local_at(dist, l0, l1, l2, lo0, lo1, lo2, eta, a, coef, k, no_fresnel)
        ok = (front and q > 0 and ((l2 > 0) if reflect else (l2 < 0)) and np.isfinite(w0) and np.isfinite(w1)
              and np.isfinite(w2))
        valid[i] = ok
        pdf[i] = q if ok else 0.0
        eta_sq[i] = 1.0 if reflect else eta * eta
        _eval_at(i, n0, n1, n2, eta, t0, t1, t2, b0, b1, b2, wo, wi, dist, rational, a, coef, k,
                 abs(l2) / q if ok else 0.0, A, B, C, S, x, no_fresnel)


# ----------------------------------------------------------------------------- wrappers (the compiled twins)

def _f64(a):
    return np.ascontiguousarray(a, dtype=np.float64)


def _alphas(alpha):
    """α as the loops read it (``at``): a number as a one-element array, else (N,) contiguous float64."""
    if np.ndim(alpha) == 0:
        return np.array([float(alpha)])
    return np.array(alpha, dtype=np.float64)


def _etas(n_int, n_ext):
    """(η seen from outside, from inside) as the loops read them (``at``): n_int/n_ext and n_ext/n_int, one-element
    arrays for a number, else (N,) for an index per path (the same IEEE quotients as the NumPy references')."""
    if np.ndim(n_int) == 0:
        return np.array([n_int / n_ext]), np.array([n_ext / n_int])
    n = np.asarray(n_int, dtype=np.float64)
    return np.ascontiguousarray(n / n_ext), np.ascontiguousarray(n_ext / n)


def rough_dielectric_eval_numba(n_s, wo, wi, L, n_int, n_ext, distribution, rational, alpha, no_fresnel=False):
    n = n_s.shape[1]
    A, B, C, S = (np.empty((L, n)) for _ in range(4))
    x = np.empty((3, n))
    _eval_loop(_f64(n_s), _f64(wo), _f64(wi), *_etas(n_int, n_ext), DISTRIBUTION_CODES[distribution],
               bool(rational), _alphas(alpha), _ERFCX_COEF, _ERFCX_K, A, B, C, S, x, bool(no_fresnel))
    return x, A, B, C, S


def rough_dielectric_pdf_numba(n_s, wo, wi, n_int, n_ext, distribution, alpha, no_fresnel=False):
    out = np.empty(n_s.shape[1])
    _pdf_loop(_f64(n_s), _f64(wo), _f64(wi), *_etas(n_int, n_ext), DISTRIBUTION_CODES[distribution],
              _alphas(alpha), _ERFCX_COEF, _ERFCX_K, out, bool(no_fresnel))
    return out


def rough_dielectric_sample_numba(n_s, wo, u_lobe, u_dir, L, n_int, n_ext, distribution, rational, alpha,
                                  no_fresnel=False):
    n = n_s.shape[1]
    A, B, C, S = (np.empty((L, n)) for _ in range(4))
    wi, x = np.empty((3, n)), np.empty((3, n))
    pdf, eta_sq, valid = np.empty(n), np.empty(n), np.empty(n, np.bool_)
    _sample_loop(_f64(n_s), _f64(wo), _f64(u_lobe), _f64(u_dir), *_etas(n_int, n_ext),
                 DISTRIBUTION_CODES[distribution], bool(rational), _alphas(alpha), _ERFCX_COEF, _ERFCX_K,
                 wi, pdf, valid, eta_sq, A, B, C, S, x, bool(no_fresnel))
    return wi, pdf, valid, eta_sq, x, A, B, C, S


#: None without Numba (engine.kernels.twin then keeps the NumPy references).
rough_dielectric_eval_numba = _eval_loop and rough_dielectric_eval_numba
rough_dielectric_pdf_numba = _pdf_loop and rough_dielectric_pdf_numba
rough_dielectric_sample_numba = _sample_loop and rough_dielectric_sample_numba
