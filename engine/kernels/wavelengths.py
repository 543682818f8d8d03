"""Hero-wavelength sampling and the per-wavelength sRGB weights of a path, as compiled passes.

The NumPy references are engine.spectral.cie.sample_wavelengths_numpy and rgb_weights_numpy
(Mitsuba 3's tanh-shaped sampling density, physics constants there).  The transcendental steps
(atanh, cosh) and the 3×3 XYZ → sRGB product (BLAS) stay NumPy calls on the same contiguous
arrays as in the reference, so their rounding is NumPy's own; the loops here replace only the
elementwise arithmetic around them (same operations, same order: bit-identical results).
"""

from __future__ import annotations

import numpy as np

from . import jit

@jit
def _cdf_argument_loop(u, count, t0, dt, z):
    # z[j] = T0 + frac(u + j/count)·(T1 − T0); frac as np.mod (fmod, then into [0, 1), +0.0 for 0)
    for j in range(count):
        off = float(j) / count
        for i in range(u.shape[0]):
            m = np.fmod(u[i] + off, 1.0)
            if m != 0:
                if m < 0:
                    m += 1.0
            else:
                m = 0.0
            z[j, i] = t0 + m * dt

@jit
def _wavelength_loop(atanh_z, c, a, lo, hi, lam, y):
    # λ = clip(C + atanh(z)/A, lo, hi) and the cosh argument A·(λ − C) of its pdf
    for j in range(atanh_z.shape[0]):
        for i in range(atanh_z.shape[1]):
            v = c + atanh_z[j, i] / a
            if v < lo:
                v = lo
            elif v > hi:
                v = hi
            lam[j, i] = v
            y[j, i] = a * (v - c)

@jit
def _pdf_loop(lam, cosh_y, norm, lo, hi, pdf):
    for j in range(lam.shape[0]):
        for i in range(lam.shape[1]):
            v = lam[j, i]
            ch = cosh_y[j, i]
            pdf[j, i] = norm / (ch * ch) if (v >= lo and v <= hi) else 0.0

def sample_tanh(u, count, t0, dt, c, a, lo, hi, norm):
    """(λ, pdf), each (count, *u.shape): λ = clip(c + atanh(t0 + frac(u + j/count)·dt)/a, lo, hi) nm,
    pdf = norm / cosh²(a (λ − c)) inside [lo, hi] nm, else 0 (see engine.spectral.cie)."""
    u = np.asarray(u, dtype=np.float64)
    flat = np.ascontiguousarray(u).reshape(-1)
    z = np.empty((count, flat.shape[0]))
    _cdf_argument_loop(flat, count, float(t0), float(dt), z)
    lam = np.empty_like(z)
    y = np.empty_like(z)
    _wavelength_loop(np.arctanh(z), float(c), float(a), float(lo), float(hi), lam, y)
    pdf = np.empty_like(z)
    _pdf_loop(lam, np.cosh(y), float(norm), float(lo), float(hi), pdf)
    shape = (count,) + u.shape
    return lam.reshape(shape), pdf.reshape(shape)

sample_tanh = _cdf_argument_loop and sample_tanh

@jit
def _divide_by_pdf_loop(rgb, pdf, count):
    # rgb[:, j, i] /= pdf·count (as the product with its reciprocal), 0 where pdf ≤ 0
    for r in range(rgb.shape[0]):            # contiguous streams (the reciprocal is recomputed, cheap)
        for j in range(pdf.shape[0]):
            for i in range(pdf.shape[1]):
                p = pdf[j, i]
                inv = 1.0 / (p * count) if p > 0 else 0.0
                rgb[r, j, i] = rgb[r, j, i] * inv

def weights_over_pdf(rgb, pdf):
    """rgb (3, count, N) × 1/(pdf·count) (0 where pdf ≤ 0), in place; returns rgb."""
    pdf = np.ascontiguousarray(pdf, dtype=np.float64)
    rgb = np.ascontiguousarray(rgb)
    count = pdf.shape[0]
    _divide_by_pdf_loop(rgb.reshape(rgb.shape[0], count, -1), pdf.reshape(count, -1), count)
    return rgb

weights_over_pdf = _divide_by_pdf_loop and weights_over_pdf
