"""The glossy group's vertex in compiled steps: next-event estimation and the BSDF sample with its T update.

At the paths of one rough-conductor group (engine.materials.torrance_sparrow with its compiled facet lobe and no
Lambert or multiscatter term) the integrator's NumPy chain runs a dozen calls with some twenty (L, m) temporaries
per step.  Here, as engine.kernels.delta_bounce does for delta materials, per path:

- ``light_terms_loop``: given the light samples (engine.render.integrator._LightSamples: direction wi, distance,
  1/pdf scale, solid-angle pdf, ok, delta, emitted radiance (L, m), selection probability), the facet value
  (Fresnel Mueller at the half vector), the mixture pdf, the power-heuristic weight, the response (M00, M10, 0, 0)
  rotated into the path's frame, T·S and the light's weight (PathTracer._light_weight, throughput_times_stokes),
  and the shadow rays (shadow_rays); the caller casts them (CompiledScene.occluded) and ``add_light_terms_loop``
  adds T·S·weight·visibility into the radiance (add_to_paths);
- ``sample_update_loop``: the sample pass (torrance_sparrow.sample_at: visible normal, Fresnel Mueller, pdf) and,
  a chunk of paths at a time, T_new = T·R(x → x_T)·M (delta_bounce._update_chunk: update_abcs's arithmetic) and
  the next segment's columns (PathTracer._sample_bsdf, scatter_throughput, _store_sample).

Every step repeats the arithmetic of the NumPy chain in its order (the per-path pieces of
engine.kernels.torrance_sparrow, stokes_rotation.frame_rotation_at, geometry.offset_origin_at), so the numbers are
the chain's bit for bit.  One thing differs: a shadow ray is cast only where its answer can change the radiance.
Where a path's T·S is ±0 at every wavelength (the sampled direction below the shading horizon: the one-sided lobe
is 0 there, about half of a uniform sky's samples) and its weight finite, T·S·weight·v is ±0 for v = 0 and 1, and
adding ±0 leaves an accumulator unchanged (it starts at +0 and never becomes −0): the chain casts the ray, this
does not (the stats count fewer shadow rays).  The NumPy chain is the reference (the route is off without
compiled kernels); tests/render/test_glossy_bounce.py pairs them.

Shapes: per-path arrays (3, m) or (m,) of the group's m paths (gathered); T (P, P, LT, ·) read at the columns
``cols`` (engine.render.path_state.PathState.T_col); ``emitted`` (L, m) with LT and the lobe's wavelength rows
Lm each 1 or L; ``acc`` (m, P, L) = T·S per output wavelength, ``weight`` (m, L) the light's weight before
shadowing (path-major: one stream each).  Per-point inputs given once for the batch are one-element arrays
(torrance_sparrow.at); outputs of the sample are written at the batch rows ``rows``.
"""

from __future__ import annotations

import numpy as np

from . import jit
from .delta_bounce import _CHUNK, _chunk_buffers, _update_chunk
from .geometry import local_frame_at, offset_origin_at
from .stokes_rotation import frame_rotation_of
from .torrance_sparrow import (at, facet_at, facet_fresnel_at, p_spec_at, pdf_at, pdf_from_facet_at, sample_at,
                               scattering_axis)


@jit
def light_terms_loop(n_s, wo, x_T, p, n_g, wi, dist, scale, pdf_l, ok, delta, emitted, select_prob,
                     eta, s, m, dist_code, kind, p_given, use_given, eta_p, s_p, w_d, L_p, coef, k, lam_o,
                     T, cols, epsilon, A, B, C, S, o, acc, weight, skip, o_t, wi_t, t_t, test):
    """Per path j: ok[j] &= |n_s·wi| > 0 (as _light_weight narrows it), the facet value at wi (eval_at's, into the
    one-column scratch A..S, its frame x),
    the MIS weight against the lobe's pdf (1 where delta), weight[j, :] = emitted·scale·(|cosθ_i|·mis/select·ok),
    acc[j, i, q] = Σ_c T[i, c, q, col]·S[c, q, j] with S = (M00, M10, 0, 0) rotated from x into x_T (P ≥ 3; P = 1:
    M00), skip[j] where T·S·weight·v is ±0 whatever the visibility v.  The shadow rays of the ok paths not
    skipped go to o_t, wi_t, t_t (3, ·), (·) and their paths to ``test``; returns how many.

    Where the facet value f is 0 (ω_i or ω_o below the horizon, D or G = 0) S is ±0 (a finite Fresnel value and
    rotation times 0) and T is finite (next_segments ends the others), so T·S is ±0: the path is skipped
    without its Fresnel value, frame or T·S where its weight is finite (acc is then not written).
    The pdf shares the lobe's half vector and D (pdf_from_facet_at: pdf_at's arithmetic) and takes Smith Λ(ω_o)
    from ``lam_o`` (m,) where it is not NaN (sample_update_loop's, the same bits; an empty array: none)."""
    P, LT = T.shape[0], T.shape[2]
    L = emitted.shape[0]
    Lm = A.shape[0]
    n_test = 0
    for j in range(n_s.shape[1]):
        n0, n1, n2 = n_s[0, j], n_s[1, j], n_s[2, j]
        w0, w1, w2 = wi[0, j], wi[1, j], wi[2, j]
        v0, v1, v2 = wo[0, j], wo[1, j], wo[2, j]
        cos_i = abs((n0 * w0 + n1 * w1) + n2 * w2)
        okj = ok[j] and cos_i > 0
        ok[j] = okj
        t0, t1, t2, b0, b1, b2 = local_frame_at(n0, n1, n2)
        mj = at(m, j)
        _, lobe, lo0, lo1, lo2, li2, h0, h1, h2, D, fr, c = facet_at(n0, n1, n2, t0, t1, t2, b0, b1, b2, v0, v1, v2,
                                                                     w0, w1, w2, at(s, j), mj, dist_code, kind, coef,
                                                                     k)
        if at(delta, j):
            mis = 1.0
        else:
            cos_o = (v0 * n0 + v1 * n1) + v2 * n2
            pp = p_spec_at(j, cos_o, p_given, use_given, eta_p, L_p, s_p, w_d)
            if lobe:            # pdf_at with the lobe's h and D
                lam = lam_o[j] if lam_o.shape[0] > 0 else np.nan
                q = pdf_from_facet_at(lo0, lo1, lo2, li2, h0, h1, h2, D, mj, dist_code, pp, True, False, coef, k,
                                      lam, not np.isnan(lam))
            else:
                q = pdf_at(j, n0, n1, n2, t0, t1, t2, b0, b1, b2, wo, wi, mj, dist_code, pp, True, False, coef, k,
                           0.0, False)
            a = pdf_l[j] * at(select_prob, j)
            a2 = a * a
            b2q = q * q
            den = a2 + b2q
            mis = a2 / den if den > 0 else 0.0
        f = cos_i * mis / at(select_prob, j) * (1.0 if okj else 0.0)
        finite = True
        for q in range(L):
            w = (emitted[q, j] * scale[j]) * f
            weight[j, q] = w
            finite = finite and np.isfinite(w)
        if fr == 0.0 and finite:
            skip[j] = True
            continue
        facet_fresnel_at(j, 0, eta, c, fr, 1.0, A, B, C, S)
        if P >= 3:
            x0, x1, x2 = scattering_axis(w0, w1, w2, v0, v1, v2)
            c2, s2 = frame_rotation_of(x0, x1, x2, x_T[0, j], x_T[1, j], x_T[2, j], v0, v1, v2)
        else:
            c2, s2 = 1.0, 0.0
        col = cols[j]
        zero = True
        for q in range(L):
            w = weight[j, q]
            lt = q if LT > 1 else 0
            ls = q if Lm > 1 else 0
            m00 = A[ls, 0]
            b = B[ls, 0]
            r1 = c2 * b + s2 * 0.0
            r2 = -s2 * b + c2 * 0.0
            for i in range(P):
                v = 0.0
                v += T[i, 0, lt, col] * m00
                if P >= 3:
                    v += T[i, 1, lt, col] * r1
                    v += T[i, 2, lt, col] * r2
                    if P == 4:
                        v += T[i, 3, lt, col] * 0.0
                acc[j, i, q] = v
                if not (np.isfinite(v) and np.isfinite(w) and (v == 0.0 or w == 0.0)):
                    zero = False
        skip[j] = zero
        if okj and not zero:
            mx = offset_origin_at(p, n_g, wi, epsilon, j, o)
            d = dist[j]
            for c3 in range(3):
                o_t[c3, n_test] = o[c3, j]
                wi_t[c3, n_test] = wi[c3, j]
            t_t[n_test] = d * (1.0 - 1e-4) - 1e-4 * (1.0 + mx) if np.isfinite(d) else np.inf
            test[n_test] = j
            n_test += 1
    return n_test


@jit
def add_light_terms_loop(radiance, path, acc, weight, skip, blocked):
    """radiance[i, q, path[j]] += acc[j, i, q]·(weight[j, q]·v), v = 0 where ``blocked`` else 1 (the chain's
    weight·visibility, T·S·weight and add_to_paths), for the paths not skipped (light_terms_loop)."""
    P, L = acc.shape[1], acc.shape[2]
    for j in range(acc.shape[0]):
        if skip[j]:
            continue
        v = 0.0 if blocked[j] else 1.0
        pj = path[j]
        for i in range(P):
            for q in range(L):
                radiance[i, q, pj] += acc[j, i, q] * (weight[j, q] * v)


@jit
def sample_update_loop(rows, cols, n_s, wo, x_T, u_lobe, u_dir, eta, s, m, dist_code, kind, p_given, use_given, w_d,
                       coef, k, T, Lm, lam_o, T_out, d_out, x_out, valid_out, pdf_out, is_delta_out, eta_step_out):
    """TorranceSparrow.sample at the group's paths j (sample_at, into a chunk's columns; Smith Λ(ω_o) into
    lam_o[j], NaN where not computed), then at their batch rows m = rows[j]: T_out[..., m] = T[..., cols[j]]·R(x →
    x_T)·M, M the sample's weight (ABCS with ``Lm`` wavelength rows, frame x), and the next segment d, x_T, valid,
    pdf, is_delta (False), eta_step (1)."""
    P = T.shape[0]
    abcs, rot = _chunk_buffers(Lm)
    A, B, C, S = np.empty((Lm, _CHUNK)), np.empty((Lm, _CHUNK)), np.empty((Lm, _CHUNK)), np.empty((Lm, _CHUNK))
    wi, x, pdf, factor = np.empty((3, _CHUNK)), np.empty((3, _CHUNK)), np.empty(_CHUNK), np.empty(_CHUNK)
    valid, eval_valid = np.empty(_CHUNK, np.bool_), np.empty(_CHUNK, np.bool_)
    n = rows.shape[0]
    for j0 in range(0, n, _CHUNK):
        j1 = min(j0 + _CHUNK, n)
        for j in range(j0, j1):
            jj = j - j0
            lam_o[j] = sample_at(j, jj, n_s, wo, u_lobe, u_dir, eta, s, m, dist_code, kind, p_given, use_given, w_d,
                                 False, True, coef, k, wi, pdf, valid, factor, A, B, C, S, x, eval_valid)
            mm = rows[j]
            for c in range(3):
                d_out[c, mm] = wi[c, jj]
                x_out[c, mm] = x[c, jj]
            valid_out[mm] = valid[jj]
            pdf_out[mm] = pdf[jj]
            is_delta_out[mm] = False
            eta_step_out[mm] = 1.0
            for q in range(Lm):
                abcs[q, 0, jj] = A[q, jj]
                abcs[q, 1, jj] = B[q, jj]
                abcs[q, 2, jj] = C[q, jj]
                abcs[q, 3, jj] = S[q, jj]
            if P >= 3:
                rot[0, jj], rot[1, jj] = frame_rotation_of(x[0, jj], x[1, jj], x[2, jj], x_T[0, j], x_T[1, j],
                                                           x_T[2, j], wo[0, j], wo[1, j], wo[2, j])
            else:
                rot[0, jj], rot[1, jj] = 1.0, 0.0
        _update_chunk(T, cols, T_out, rows, j0, j1, abcs, rot)
