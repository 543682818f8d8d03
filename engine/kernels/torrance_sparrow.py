"""Torrance–Sparrow (Beckmann or GGX facets) eval, pdf and sample as one compiled pass each.

Per path, in the local shading frame (t, b, n) of engine.vec3.local_frame: the half vector, the
Beckmann or GGX D, the shadowing G ("ts" V-cavity, exact or rational Smith, height-correlated Smith,
none), the facet Fresnel
(A, B, C, S) per wavelength (engine.kernels.fresnel.abcs_at), the scattering-plane frame
x_in = x_out = unit(−ω_i × ω_o) (engine.kernels.geometry.unit_cross), the two-lobe choice and the
mixture pdf, visible-normal sampling (engine.kernels.microfacet.beckmann_vndf_at, ggx_vndf_at).
The NumPy references are the material's own batched formulas (engine.materials.torrance_sparrow,
where the twins are declared); each step here is the same arithmetic in the same operation order,
so the compiled pass gives the reference's bits (the reference's compiled pieces, Fresnel and the
visible slope, are the same arithmetic; exp, log, sin and cos are the C library's in both).  A
constant index is evaluated once per path, not once per wavelength (same inputs, same bits).

Shadowing codes (``SHADOWING_CODES``): 0 "ts", 1 "smith", 2 "smith_rational" (Beckmann only), 3 "none",
4 "smith_correlated".  Distribution codes (``DISTRIBUTION_CODES``): 0 Beckmann, 1 GGX (Cycles' and the
Principled BSDF's lobes: engine.materials.ggx, one direction at a time in its operation order).
"""

from __future__ import annotations

import math

import numpy as np

from . import jit, jit_inner
from .error_function import ERFCX_COEF, ERFCX_K
from .fresnel import abcs_at, abcs_fixups, abcs_row
from .geometry import local_frame_at, to_local_at, unit_cross_at
from .microfacet import (beckmann_d_at, beckmann_g1_pair_at, beckmann_lambda_at, beckmann_vndf_lambda_at,
                         chi_plus_at, ggx_d_at, ggx_lambda_at, ggx_vndf_at, smith_a_at)

#: The shadowing names of engine.materials.microfacet.SHADOWING, by kernel code.
SHADOWING_CODES = {"ts": 0, "smith": 1, "smith_rational": 2, "none": 3, "smith_correlated": 4}
#: The facet distributions of engine.materials.torrance_sparrow with a compiled pass, by kernel code.
DISTRIBUTION_CODES = {"beckmann": 0, "ggx": 1}
_DEGENERATE = 1e-12           # engine.polarisation.frames._DEGENERATE
_PI = math.pi
_ERFCX_COEF = np.ascontiguousarray(ERFCX_COEF, dtype=np.float64)
_ERFCX_K = float(ERFCX_K)


# ----------------------------------------------------------------------------- per-path pieces
# Per-point inputs may be given once for the batch: arrays of length 1 (a number), an index of
# shape (1, 1), (1, N), (L, 1) or (L, N) (a constant index is not spread over the batch).

@jit_inner
def at(v, i):
    """v[i], or v[0] for a number given as a one-element array."""
    return v[i if v.shape[0] > 1 else 0]


@jit_inner
def eta_at(eta, lam, i):
    """The relative index at row ``lam`` and path ``i`` of a broadcast (rows, columns) array."""
    return eta[lam if eta.shape[0] > 1 else 0, i if eta.shape[1] > 1 else 0]


@jit_inner
def facet_d_at(dist, h0, h1, h2, m):
    """D(h) of the distribution code ``dist`` (Beckmann.D / GGX.D)."""
    return beckmann_d_at(h0, h1, h2, m) if dist == 0 else ggx_d_at(h0, h1, h2, m)


@jit_inner
def smith_lambda_at(dist, w0, w1, w2, m, coef, k):
    """Smith Λ(ω) of the distribution code ``dist`` (the distributions' ``smith_lambda``)."""
    if dist == 0:
        return beckmann_lambda_at(smith_a_at(w0, w1, w2, m), coef, k)
    return ggx_lambda_at(w0, w1, w2, m)


@jit_inner
def shadowing_at(kind, dist, i0, i1, i2, o0, o1, o2, h0, h1, h2, m, coef, k):
    """G of engine.materials.microfacet.shadowing_term for the kernel codes ``kind`` and ``dist``."""
    if kind == 0:
        di = i0 * h0 + i1 * h1 + i2 * h2
        do = o0 * h0 + o1 * h1 + o2 * h2
        if not (di > 0 and do > 0 and h2 > 0 and i2 > 0 and o2 > 0):
            return 0.0
        g_o = 2.0 * h2 * o2 / do
        g_i = 2.0 * h2 * i2 / di
        return min(1.0, min(g_o, g_i))
    if kind == 3:
        return chi_plus_at(i0, i1, i2, h0, h1, h2) * chi_plus_at(o0, o1, o2, h0, h1, h2)
    if kind == 4:           # g_smith_correlated
        return (chi_plus_at(i0, i1, i2, h0, h1, h2) * chi_plus_at(o0, o1, o2, h0, h1, h2)
                / (1.0 + smith_lambda_at(dist, i0, i1, i2, m, coef, k) + smith_lambda_at(dist, o0, o1, o2, m, coef, k)))
    if dist == 1:           # g_smith with GGX's G1 = χ⁺/(1 + Λ)
        return (chi_plus_at(i0, i1, i2, h0, h1, h2) / (1.0 + ggx_lambda_at(i0, i1, i2, m))
                * (chi_plus_at(o0, o1, o2, h0, h1, h2) / (1.0 + ggx_lambda_at(o0, o1, o2, m))))
    return beckmann_g1_pair_at(i0, i1, i2, o0, o1, o2, h0, h1, h2, m, kind == 2, coef, k)


@jit_inner
def specular_pdf_at(dist, i0, i1, i2, o0, o1, o2, m, coef, k, lam_o, have_lam):
    """Density of ω_i under visible-normal sampling and reflection (TorranceSparrow._specular_pdf_local):
    Beckmann.pdf_reflected, or for GGX the generic pdf(h)/(4 ω_o·h) in its order; Smith Λ(ω_o) is ``lam_o``
    where ``have_lam``, else computed here."""
    hv0, hv1, hv2 = i0 + o0, i1 + o1, i2 + o2
    length = np.sqrt(hv0 * hv0 + hv1 * hv1 + hv2 * hv2)
    if not length > 0:
        return 0.0
    h0, h1, h2 = hv0 / length, hv1 / length, hv2 / length
    return specular_pdf_h_at(dist, o0, o1, o2, h0, h1, h2, facet_d_at(dist, h0, h1, h2, m), m, coef, k, lam_o,
                             have_lam)


@jit_inner
def specular_pdf_h_at(dist, o0, o1, o2, h0, h1, h2, D, m, coef, k, lam_o, have_lam):
    """specular_pdf_at given the half vector h = unit(ω_i + ω_o) and D(h) (facet_at's: the same bits)."""
    d = o0 * h0 + o1 * h1 + o2 * h2
    if not (o2 > 0 and d > 0):
        return 0.0
    g1 = 1.0 / (1.0 + (lam_o if have_lam else smith_lambda_at(dist, o0, o1, o2, m, coef, k)))
    if dist == 0:
        return g1 * D / (4.0 * o2)
    return g1 * max(d, 0.0) * D / o2 / (4.0 * d)


@jit_inner
def p_spec_at(i, cos_o, p_given, use_given, eta, L, s, w_d):
    """Probability of the specular lobe (TorranceSparrow._p_spec): ``p_given[i]``, or from the mean
    unpolarised Fresnel reflectance at the macro angle against the diffuse weight ``w_d[i]``."""
    if use_given:
        return at(p_given, i)
    c = min(max(cos_o, 0.0), 1.0)
    e = eta_at(eta, 0, i)
    F0 = abcs_at(c, e)[0]
    F = F0
    for lam in range(1, L):      # the mean over the L wavelengths, summed in order as NumPy's mean(axis=0)
        if eta_at(eta, lam, i) != e:
            e = eta_at(eta, lam, i)
            F0 = abcs_at(c, e)[0]
        F += F0
    w_s = at(s, i) * (F / L)
    tot = w_s + at(w_d, i)
    p = w_s / tot if tot > 0 else 0.5
    return min(max(p, 0.1), 0.9)


@jit_inner
def facet_at(n0, n1, n2, t0, t1, t2, b0, b1, b2, o0, o1, o2, w0, w1, w2, s, m, dist, kind, coef, k):
    """The facet lobe's scalars at ω_o = (o0, o1, o2), ω_i = (w0, w1, w2): (valid: cosθ_i > 0 and cosθ_o > 0, ok:
    the lobe is evaluated there, ω_o local (3), cosθ_i, h (3), D(h), f = s·D·G/(4 cosθ_i cosθ_o), the facet cosine
    c) (0 and 1 where not ok)."""
    lo0, lo1, lo2 = to_local_at(o0, o1, o2, t0, t1, t2, b0, b1, b2, n0, n1, n2)
    li0, li1, li2 = to_local_at(w0, w1, w2, t0, t1, t2, b0, b1, b2, n0, n1, n2)
    valid = li2 > 0 and lo2 > 0
    hv0, hv1, hv2 = li0 + lo0, li1 + lo1, li2 + lo2
    length = np.sqrt(hv0 * hv0 + hv1 * hv1 + hv2 * hv2)
    ok = length > 0 and valid and li2 * lo2 > 0     # a product underflowing to 0: f = 0 (as _facet_eval), not x/0
    fr = 0.0
    c = 1.0
    h0 = h1 = h2 = D = 0.0
    if ok:
        h0, h1, h2 = hv0 / length, hv1 / length, hv2 / length
        D = facet_d_at(dist, h0, h1, h2, m)
        G = shadowing_at(kind, dist, li0, li1, li2, lo0, lo1, lo2, h0, h1, h2, m, coef, k)
        fr = s * D * G / (4.0 * (li2 * lo2))
        c = min(0.5 * length, 1.0)
    return valid, ok, lo0, lo1, lo2, li2, h0, h1, h2, D, fr, c


@jit_inner
def facet_fresnel_at(i, o, eta, c, fr, factor, A, B, C, S):
    """A..S[:, o] = the facet Fresnel (A, B, C, S)(c) of path i's index per wavelength times f·``factor`` (eval_at's
    second half)."""
    e = eta_at(eta, 0, i)
    a_, b_, c_, s_ = abcs_at(c, e)
    for lam in range(A.shape[0]):
        if lam > 0 and eta_at(eta, lam, i) != e:    # a constant index: one Fresnel evaluation serves every λ
            e = eta_at(eta, lam, i)
            a_, b_, c_, s_ = abcs_at(c, e)
        A[lam, o] = a_ * fr * factor
        B[lam, o] = b_ * fr * factor
        C[lam, o] = c_ * fr * factor
        S[lam, o] = s_ * fr * factor


@jit_inner
def scattering_axis(w0, w1, w2, o0, o1, o2):
    """unit(k_i × k_o), k_i = −ω_i, k_o = ω_o (engine.kernels.geometry.unit_cross, same order)."""
    return unit_cross_at(-w0, -w1, -w2, o0, o1, o2, _DEGENERATE)


@jit_inner
def eval_at(i, n0, n1, n2, t0, t1, t2, b0, b1, b2, wo, wi, eta, s, m, dist, kind, coef, k, factor, A, B, C, S, x):
    """Facet lobe at path i into A..S[:, i] (times ``factor``) and x[:, i]; returns cosθ_i > 0 and cosθ_o > 0."""
    o0, o1, o2 = wo[0, i], wo[1, i], wo[2, i]
    w0, w1, w2 = wi[0, i], wi[1, i], wi[2, i]
    valid, _, _, _, _, _, _, _, _, _, fr, c = facet_at(n0, n1, n2, t0, t1, t2, b0, b1, b2, o0, o1, o2, w0, w1, w2, s,
                                                       m, dist, kind, coef, k)
    facet_fresnel_at(i, i, eta, c, fr, factor, A, B, C, S)
    x[0, i], x[1, i], x[2, i] = scattering_axis(w0, w1, w2, o0, o1, o2)
    return valid


@jit_inner
def pdf_at(i, n0, n1, n2, t0, t1, t2, b0, b1, b2, wo, wi, m, dist, p_spec, has_specular, has_diffuse, coef, k,
           lam_o, have_lam):
    """The two-lobe mixture density of ω_i = wi[:, i] (TorranceSparrow.pdf); ``lam_o``, ``have_lam`` as for
    specular_pdf_at."""
    return pdf_of(n0, n1, n2, t0, t1, t2, b0, b1, b2, wo[0, i], wo[1, i], wo[2, i], wi[0, i], wi[1, i], wi[2, i], m,
                  dist, p_spec, has_specular, has_diffuse, coef, k, lam_o, have_lam)


@jit_inner
def pdf_of(n0, n1, n2, t0, t1, t2, b0, b1, b2, o0, o1, o2, w0, w1, w2, m, dist, p_spec, has_specular, has_diffuse,
           coef, k, lam_o, have_lam):
    """pdf_at of ω_o = (o0, o1, o2) and ω_i = (w0, w1, w2) given as numbers."""
    lo0, lo1, lo2 = to_local_at(o0, o1, o2, t0, t1, t2, b0, b1, b2, n0, n1, n2)
    li0, li1, li2 = to_local_at(w0, w1, w2, t0, t1, t2, b0, b1, b2, n0, n1, n2)
    if not (li2 > 0 and lo2 > 0):
        return 0.0
    out = 0.0
    if has_specular:
        out = out + p_spec * specular_pdf_at(dist, li0, li1, li2, lo0, lo1, lo2, m, coef, k, lam_o, have_lam)
    if has_diffuse:
        out = out + (1.0 - p_spec) * max(li2, 0.0) / _PI
    return out


@jit_inner
def pdf_from_facet_at(lo0, lo1, lo2, li2, h0, h1, h2, D, m, dist, p_spec, has_specular, has_diffuse, coef, k, lam_o,
                      have_lam):
    """pdf_at where facet_at evaluated the lobe (its ``ok``: cosθ_i, cosθ_o > 0), from its ω_o, cosθ_i, h and D
    (the same bits: the same half vector and D)."""
    out = 0.0
    if has_specular:
        out = out + p_spec * specular_pdf_h_at(dist, lo0, lo1, lo2, h0, h1, h2, D, m, coef, k, lam_o, have_lam)
    if has_diffuse:
        out = out + (1.0 - p_spec) * max(li2, 0.0) / _PI
    return out


# ----------------------------------------------------------------------------- batch loops

@jit
def _eval_loop(n_s, wo, wi, eta, s, m, dist, kind, coef, k, A, B, C, S, x, valid):
    for i in range(n_s.shape[1]):
        n0, n1, n2 = n_s[0, i], n_s[1, i], n_s[2, i]
        t0, t1, t2, b0, b1, b2 = local_frame_at(n0, n1, n2)
        valid[i] = eval_at(i, n0, n1, n2, t0, t1, t2, b0, b1, b2, wo, wi, eta, at(s, i), at(m, i), dist, kind, coef, k,
                           1.0, A, B, C, S, x)


@jit
def _pdf_loop(n_s, wo, wi, m, dist, p_given, use_given, eta, L, s, w_d, has_specular, has_diffuse, coef, k, out):
    for i in range(n_s.shape[1]):
        n0, n1, n2 = n_s[0, i], n_s[1, i], n_s[2, i]
        t0, t1, t2, b0, b1, b2 = local_frame_at(n0, n1, n2)
        cos_o = (wo[0, i] * n0 + wo[1, i] * n1) + wo[2, i] * n2
        p = p_spec_at(i, cos_o, p_given, use_given, eta, L, s, w_d)
        out[i] = pdf_at(i, n0, n1, n2, t0, t1, t2, b0, b1, b2, wo, wi, at(m, i), dist, p, has_specular, has_diffuse,
                        coef, k, 0.0, False)


@jit
def _eval_pdf_loop(n_s, wo, wi, eta, s, m, dist, kind, p_given, use_given, eta_p, L, s_p, w_d, has_diffuse, coef, k,
                   A, B, C, S, x, valid, pdf):
    """_eval_loop and _pdf_loop (has_specular) at the same ω_o, ω_i in one pass: the pdf shares the lobe's frame, half
    vector and D (pdf_from_facet_at: pdf_at's bits) where facet_at evaluated the lobe, else pdf_of."""
    for i in range(n_s.shape[1]):
        n0, n1, n2 = n_s[0, i], n_s[1, i], n_s[2, i]
        t0, t1, t2, b0, b1, b2 = local_frame_at(n0, n1, n2)
        o0, o1, o2 = wo[0, i], wo[1, i], wo[2, i]
        w0, w1, w2 = wi[0, i], wi[1, i], wi[2, i]
        mi = at(m, i)
        e_valid, lobe, lo0, lo1, lo2, li2, h0, h1, h2, D, fr, c = facet_at(n0, n1, n2, t0, t1, t2, b0, b1, b2, o0, o1,
                                                                         o2, w0, w1, w2, at(s, i), mi, dist, kind,
                                                                         coef, k)
        facet_fresnel_at(i, i, eta, c, fr, 1.0, A, B, C, S)
        x[0, i], x[1, i], x[2, i] = scattering_axis(w0, w1, w2, o0, o1, o2)
        valid[i] = e_valid
        cos_o = (o0 * n0 + o1 * n1) + o2 * n2
        p = p_spec_at(i, cos_o, p_given, use_given, eta_p, L, s_p, w_d)
        if lobe:
            pdf[i] = pdf_from_facet_at(lo0, lo1, lo2, li2, h0, h1, h2, D, mi, dist, p, True, has_diffuse, coef, k,
                                       0.0, False)
        else:
            pdf[i] = pdf_of(n0, n1, n2, t0, t1, t2, b0, b1, b2, o0, o1, o2, w0, w1, w2, mi, dist, p, True,
                            has_diffuse, coef, k, 0.0, False)


#: lanes per block of _eval_pdf_rows_loop (its Fresnel values are taken a wavelength at a time over a block)
_CHUNK = 256


@jit
def _eval_pdf_rows_loop(n_s, wo, wi, eta, s, m, dist, kind, p_given, use_given, eta_p, L, s_p, w_d, has_diffuse, coef,
                        k, A, B, C, S, x, valid, pdf):
    """_eval_pdf_loop for an index per wavelength and path (eta (L, N), a textured metal's): the same per-path pass,
    the facet Fresnel values of each block of paths taken a wavelength at a time by fresnel.abcs_row (SIMD) and
    abcs_fixups — abcs_at's bits — then A..S = (value·f)·1 as facet_fresnel_at writes them."""
    N = n_s.shape[1]
    La = A.shape[0]
    cos, fr_, w = np.empty(_CHUNK), np.empty(_CHUNK), np.ones(_CHUNK)
    e, abcs, fast = np.empty((La, 2, _CHUNK)), np.empty((La, 4, _CHUNK)), np.empty(_CHUNK, np.bool_)
    for j0 in range(0, N, _CHUNK):
        mm = min(_CHUNK, N - j0)
        for jj in range(mm):
            i = j0 + jj
            n0, n1, n2 = n_s[0, i], n_s[1, i], n_s[2, i]
            t0, t1, t2, b0, b1, b2 = local_frame_at(n0, n1, n2)
            o0, o1, o2 = wo[0, i], wo[1, i], wo[2, i]
            w0, w1, w2 = wi[0, i], wi[1, i], wi[2, i]
            mi = at(m, i)
            e_valid, lobe, lo0, lo1, lo2, li2, h0, h1, h2, D, fr, c = facet_at(n0, n1, n2, t0, t1, t2, b0, b1, b2,
                                                                             o0, o1, o2, w0, w1, w2, at(s, i), mi,
                                                                             dist, kind, coef, k)
            cos[jj], fr_[jj] = c, fr
            for q in range(La):
                v = eta[q, i]
                e[q, 0, jj] = v.real
                e[q, 1, jj] = v.imag
            x[0, i], x[1, i], x[2, i] = scattering_axis(w0, w1, w2, o0, o1, o2)
            valid[i] = e_valid
            cos_o = (o0 * n0 + o1 * n1) + o2 * n2
            p = p_spec_at(i, cos_o, p_given, use_given, eta_p, L, s_p, w_d)
            if lobe:
                pdf[i] = pdf_from_facet_at(lo0, lo1, lo2, li2, h0, h1, h2, D, mi, dist, p, True, has_diffuse, coef,
                                           k, 0.0, False)
            else:
                pdf[i] = pdf_of(n0, n1, n2, t0, t1, t2, b0, b1, b2, o0, o1, o2, w0, w1, w2, mi, dist, p, True,
                                has_diffuse, coef, k, 0.0, False)
        for q in range(La):
            abcs_row(cos, w, e, q, mm, abcs, fast)
            abcs_fixups(cos, w, e, q, mm, abcs, fast)
            for jj in range(mm):
                i = j0 + jj
                f = fr_[jj]
                A[q, i] = abcs[q, 0, jj] * f * 1.0
                B[q, i] = abcs[q, 1, jj] * f * 1.0
                C[q, i] = abcs[q, 2, jj] * f * 1.0
                S[q, i] = abcs[q, 3, jj] * f * 1.0


@jit_inner
def sample_at(i, o, n_s, wo, u_lobe, u_dir, eta, s, m, dist, kind, p_given, use_given, w_d, has_diffuse, scale, coef,
              k, wi, pdf, valid, factor, A, B, C, S, x, eval_valid, value=True):
    """The sample pass at path i into column o: direction wi[:, o], pdf, valid, the weight's factor cosθ_i/pdf, the
    lobe's value (times the factor where ``scale``) A..S[:, o] in the frame x[:, o] (not written unless ``value``:
    the direction alone) and eval's valid (TorranceSparrow.sample).  Returns Smith Λ(ω_o) where the Beckmann
    sampler computed it (specular_pdf_at's bits), else NaN."""
    n0, n1, n2 = n_s[0, i], n_s[1, i], n_s[2, i]
    t0, t1, t2, b0, b1, b2 = local_frame_at(n0, n1, n2)
    o0, o1, o2 = wo[0, i], wo[1, i], wo[2, i]
    lo0 = o0 * t0 + o1 * t1 + o2 * t2
    lo1 = o0 * b0 + o1 * b1 + o2 * b2
    cos_o = o0 * n0 + o1 * n1 + o2 * n2
    p = p_spec_at(i, cos_o, p_given, use_given, eta, A.shape[0], s, w_d)
    pick_spec = u_lobe[i] < p
    l0 = l1 = l2 = 0.0
    mi = at(m, i)
    lam_o = 0.0
    have_lam = False
    if pick_spec and cos_o > 0:
        # visible-normal sampling (engine.materials.microfacet.Beckmann.sample, engine.materials.ggx.GGX.sample)
        if dist == 0:       # with the pdf's Λ(ω_o), its erfcx beside the sampler's
            h0, h1, h2, lam_o = beckmann_vndf_lambda_at(lo0, lo1, cos_o, u_dir[0, i], u_dir[1, i], mi, coef, k)
            have_lam = True
        else:
            h0, h1, h2 = ggx_vndf_at(lo0, lo1, cos_o, u_dir[0, i], u_dir[1, i], mi)
        d = lo0 * h0 + lo1 * h1 + cos_o * h2
        l0 = 2.0 * d * h0 - lo0
        l1 = 2.0 * d * h1 - lo1
        l2 = 2.0 * d * h2 - cos_o
    elif has_diffuse and not pick_spec:
        # cosine-weighted (engine.materials.sampling.cosine_hemisphere)
        a = 2.0 * u_dir[0, i] - 1.0
        bb = 2.0 * u_dir[1, i] - 1.0
        if abs(a) > abs(bb):
            r = a
            phi = (np.pi / 4) * (bb / (a if a != 0 else 1.0))
        else:
            r = bb
            phi = np.pi / 2 - (np.pi / 4) * (a / (bb if bb != 0 else 1.0))
        l0 = r * np.cos(phi)
        l1 = r * np.sin(phi)
        l2 = np.sqrt(max(1.0 - l0 * l0 - l1 * l1, 0.0))
    w0 = t0 * l0 + b0 * l1 + n0 * l2
    w1 = t1 * l0 + b1 * l1 + n1 * l2
    w2 = t2 * l0 + b2 * l1 + n2 * l2
    wi[0, o], wi[1, o], wi[2, o] = w0, w1, w2
    # the lobe at wi (eval_at's first half), whose half vector and D the pdf shares (pdf_at's bits)
    e_valid, lobe, fo0, fo1, fo2, fi2, h0, h1, h2, D, fr, c = facet_at(n0, n1, n2, t0, t1, t2, b0, b1, b2, o0, o1,
                                                                     o2, w0, w1, w2, at(s, i), mi, dist, kind, coef, k)
    if lobe:
        q = pdf_from_facet_at(fo0, fo1, fo2, fi2, h0, h1, h2, D, mi, dist, p, True, has_diffuse, coef, k, lam_o,
                              have_lam)
    else:
        q = pdf_of(n0, n1, n2, t0, t1, t2, b0, b1, b2, o0, o1, o2, w0, w1, w2, mi, dist, p, True, has_diffuse, coef,
                   k, lam_o, have_lam)
    ok = cos_o > 0 and l2 > 0 and q > 0 and np.isfinite(w0) and np.isfinite(w1) and np.isfinite(w2)
    cos_i = max(n0 * w0 + n1 * w1 + n2 * w2, 0.0)
    f = cos_i / q if ok else 0.0
    valid[o] = ok
    pdf[o] = q if ok else 0.0
    factor[o] = f
    if value:
        facet_fresnel_at(i, o, eta, c, fr, f if scale else 1.0, A, B, C, S)       # eval_at's second half
        x[0, o], x[1, o], x[2, o] = scattering_axis(w0, w1, w2, o0, o1, o2)
    eval_valid[o] = e_valid
    return lam_o if have_lam else np.nan


@jit
def _sample_loop(n_s, wo, u_lobe, u_dir, eta, s, m, dist, kind, p_given, use_given, w_d, has_diffuse, scale, coef, k,
                 wi, pdf, valid, factor, A, B, C, S, x, eval_valid, value):
    for i in range(n_s.shape[1]):
        sample_at(i, i, n_s, wo, u_lobe, u_dir, eta, s, m, dist, kind, p_given, use_given, w_d, has_diffuse, scale,
                  coef, k, wi, pdf, valid, factor, A, B, C, S, x, eval_valid, value)


# ----------------------------------------------------------------------------- wrappers (the compiled twins)

def _per_point(v, n):
    """A number as a one-element array, else (n,) contiguous float64 (read with ``at``)."""
    if np.ndim(v) == 0:
        return np.array([float(v)])
    return np.ascontiguousarray(np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)))


def _eta_rows(eta):
    """The relative index as a 2-D complex128 array, not spread over the batch (read with ``eta_at``)."""
    e = np.asarray(eta, dtype=np.complex128)
    return np.ascontiguousarray(e.reshape((1,) * (2 - e.ndim) + e.shape))


def _p_inputs(p_given, w_d, n):
    use_given = p_given is not None
    return (_per_point(p_given, n) if use_given else np.zeros(1), use_given,
            np.zeros(1) if use_given else _per_point(w_d, n))


def _f64(a):
    return np.ascontiguousarray(a, dtype=np.float64)


def torrance_sparrow_eval_numba(n_s, wo, wi, eta, L, s, m, shadowing, distribution="beckmann"):
    n = n_s.shape[1]
    A, B, C, S = (np.empty((L, n)) for _ in range(4))
    x, valid = np.empty((3, n)), np.empty(n, np.bool_)
    _eval_loop(_f64(n_s), _f64(wo), _f64(wi), _eta_rows(eta), _per_point(s, n), _per_point(m, n),
               DISTRIBUTION_CODES[distribution], SHADOWING_CODES[shadowing], _ERFCX_COEF, _ERFCX_K, A, B, C, S, x,
               valid)
    return x, A, B, C, S, valid


def torrance_sparrow_pdf_numba(n_s, wo, wi, m, p_given, eta, L, s, w_d, has_specular, has_diffuse,
                               distribution="beckmann"):
    n = n_s.shape[1]
    p, use_given, wd = _p_inputs(p_given, w_d, n)
    out = np.empty(n)
    _pdf_loop(_f64(n_s), _f64(wo), _f64(wi), _per_point(m, n), DISTRIBUTION_CODES[distribution], p, use_given,
              np.zeros((1, 1), np.complex128) if use_given else _eta_rows(eta), int(L),
              np.zeros(1) if use_given else _per_point(s, n), wd, bool(has_specular), bool(has_diffuse),
              _ERFCX_COEF, _ERFCX_K, out)
    return out


def torrance_sparrow_eval_pdf_numba(n_s, wo, wi, eta, L, s, m, shadowing, p_given, eta_p, s_p, w_d, has_diffuse,
                                    distribution="beckmann"):
    """torrance_sparrow_eval_numba's (x, A, B, C, S, valid) and torrance_sparrow_pdf_numba's pdf (has_specular) at
    the same directions in one pass (the same bits); ``eta``, ``s``: the lobe's, ``eta_p``, ``s_p``: the pdf's."""
    n = n_s.shape[1]
    p, use_given, wd = _p_inputs(p_given, w_d, n)
    A, B, C, S = (np.empty((L, n)) for _ in range(4))
    x, valid, pdf = np.empty((3, n)), np.empty(n, np.bool_), np.empty(n)
    eta = _eta_rows(eta)
    # an index per wavelength and path (a textured metal's): the Fresnel values a block of paths at a time (SIMD)
    loop = _eval_pdf_rows_loop if eta.shape == (L, n) and L > 1 and np.iscomplexobj(eta) else _eval_pdf_loop
    loop(_f64(n_s), _f64(wo), _f64(wi), eta, _per_point(s, n), _per_point(m, n),
                   DISTRIBUTION_CODES[distribution], SHADOWING_CODES[shadowing], p, use_given,
                   np.zeros((1, 1), np.complex128) if use_given else _eta_rows(eta_p), int(L),
                   np.zeros(1) if use_given else _per_point(s_p, n), wd, bool(has_diffuse), _ERFCX_COEF, _ERFCX_K,
                   A, B, C, S, x, valid, pdf)
    return x, A, B, C, S, valid, pdf


def torrance_sparrow_sample_numba(n_s, wo, u_lobe, u_dir, eta, L, s, m, shadowing, p_given, w_d, has_diffuse,
                                  distribution="beckmann", scale=True, value=True):
    """The sample pass's (wi, pdf, valid, factor, x, A, B, C, S, eval_valid); not ``value``: x and A..S None (the
    direction alone: the lobe's Fresnel values are not computed)."""
    n = n_s.shape[1]
    p, use_given, wd = _p_inputs(p_given, w_d, n)
    A, B, C, S = (np.empty((L, n)) for _ in range(4))
    wi, x = np.empty((3, n)), np.empty((3, n))
    pdf, factor = np.empty(n), np.empty(n)
    valid, eval_valid = np.empty(n, np.bool_), np.empty(n, np.bool_)
    _sample_loop(_f64(n_s), _f64(wo), _per_point(u_lobe, n), _f64(u_dir), _eta_rows(eta), _per_point(s, n),
                 _per_point(m, n), DISTRIBUTION_CODES[distribution], SHADOWING_CODES[shadowing], p, use_given, wd,
                 bool(has_diffuse), bool(scale), _ERFCX_COEF, _ERFCX_K, wi, pdf, valid, factor, A, B, C, S, x,
                 eval_valid, bool(value))
    if not value:
        return wi, pdf, valid, factor, None, None, None, None, None, eval_valid
    return wi, pdf, valid, factor, x, A, B, C, S, eval_valid


#: None without Numba (engine.kernels.twin then keeps the NumPy references).
torrance_sparrow_eval_numba = _eval_loop and torrance_sparrow_eval_numba
torrance_sparrow_pdf_numba = _pdf_loop and torrance_sparrow_pdf_numba
torrance_sparrow_sample_numba = _sample_loop and torrance_sparrow_sample_numba
torrance_sparrow_eval_pdf_numba = _eval_pdf_loop and torrance_sparrow_eval_pdf_numba
