"""Lambert's per-vertex work as compiled passes (twins in engine.materials.lambert).

- cosine-weighted sampling about the shading normal: the arithmetic of engine.materials.sampling
  (concentric disk map, local frame of engine.vec3.local_frame) and of Lambert's validity and pdf,
  per path and in the same operation order, so the compiled twin gives the NumPy reference's bits
  (sin and cos are the platform's libm in both here; the twin test allows rounding elsewhere);
- the albedo spectra of a LambertSet's RGB members, r·B_r + g·B_g + b·B_b, in the same order;
- next-event estimation through a Lambert surface: its Mueller value ρ/π·[front], its pdf, the power
  heuristic against the light's pdf and the light's weight, in the integrator's operation order.
"""

from __future__ import annotations

import numpy as np

from . import jit
from .geometry import to_world_at


@jit
def _cosine_sample_loop(u, n_s, wo, wi, valid, pdf):
    for j in range(n_s.shape[1]):
        # concentric disk map (engine.materials.sampling.cosine_hemisphere)
        a = 2.0 * u[0, j] - 1.0
        b = 2.0 * u[1, j] - 1.0
        use_a = abs(a) > abs(b)
        if use_a:
            r = a
            phi = (np.pi / 4) * (b / (a if a != 0 else 1.0))
        else:
            r = b
            phi = np.pi / 2 - (np.pi / 4) * (a / (b if b != 0 else 1.0))
        x = r * np.cos(phi)
        y = r * np.sin(phi)
        z = np.sqrt(max(1.0 - x * x - y * y, 0.0))
        n0, n1, n2 = n_s[0, j], n_s[1, j], n_s[2, j]
        wi[0, j], wi[1, j], wi[2, j] = to_world_at(n0, n1, n2, x, y, z)
        cos_o = n0 * wo[0, j] + n1 * wo[1, j] + n2 * wo[2, j]
        ok = cos_o > 0 and z > 0
        valid[j] = ok
        pdf[j] = z / np.pi if ok else 0.0


def cosine_sample_numba(u, n_s, wo):
    n = n_s.shape[1]
    wi, valid, pdf = np.empty((3, n)), np.empty(n, np.bool_), np.empty(n)
    _cosine_sample_loop(np.ascontiguousarray(u, dtype=np.float64), np.ascontiguousarray(n_s, dtype=np.float64),
                        np.ascontiguousarray(wo, dtype=np.float64), wi, valid, pdf)
    return wi, valid, pdf


#: The compiled twin of engine.materials.lambert.cosine_sample_numpy (None without Numba).
cosine_sample_numba = _cosine_sample_loop and cosine_sample_numba


@jit
def _rgb_albedo_loop(rgb, slot, basis, out):
    for k in range(basis.shape[1]):
        for j in range(slot.shape[0]):
            m = slot[j]
            out[k, j] = rgb[0, m] * basis[0, k, j] + rgb[1, m] * basis[1, k, j] + rgb[2, m] * basis[2, k, j]


def rgb_albedo_numba(rgb, slot, basis):
    out = np.empty(basis.shape[1:])
    _rgb_albedo_loop(np.ascontiguousarray(rgb, dtype=np.float64), np.ascontiguousarray(slot, dtype=np.int64),
                     np.ascontiguousarray(basis, dtype=np.float64), out)
    return out


#: The compiled twin of engine.materials.lambert.rgb_albedo_numpy (None without Numba).
rgb_albedo_numba = _rgb_albedo_loop and rgb_albedo_numba


@jit
def _direct_light_loop(n_s, wo, wi, albedo, emitted, scale, ok, pdf_light, select_prob, delta, A, weight, ok_out):
    n = n_s.shape[1]
    inv_pi = 1.0 / np.pi
    fa = np.empty(n)        # ρ's factor 1/π·[front]
    g = np.empty(n)         # |cosθ_i|·MIS/select_prob·[ok]
    for j in range(n):
        c = n_s[0, j] * wi[0, j] + n_s[1, j] * wi[1, j] + n_s[2, j] * wi[2, j]
        cos_i = abs(c)
        good = ok[j] and cos_i > 0
        cos_o = n_s[0, j] * wo[0, j] + n_s[1, j] * wo[1, j] + n_s[2, j] * wo[2, j]
        front = c > 0 and cos_o > 0
        fa[j] = inv_pi if front else 0.0
        if delta[j]:
            mis = 1.0
        else:
            pdf_b = c / np.pi if front else 0.0
            a = pdf_light[j] * select_prob[j]
            a2 = a * a
            den = a2 + pdf_b * pdf_b
            mis = a2 / den if den > 0 else 0.0
        g[j] = cos_i * mis / select_prob[j] * (1.0 if good else 0.0)
        ok_out[j] = good
    # per wavelength row, contiguous along the paths
    for k in range(albedo.shape[0]):
        for j in range(n):
            A[k, j] = albedo[k, j] * fa[j]
    for k in range(emitted.shape[0]):
        for j in range(n):
            weight[k, j] = emitted[k, j] * scale[j] * g[j]


def direct_light_numba(n_s, wo, wi, albedo, emitted, scale, ok, pdf_light, select_prob, delta):
    n = n_s.shape[1]
    f64 = np.float64
    A, weight, ok_out = np.empty((albedo.shape[0], n)), np.empty((emitted.shape[0], n)), np.empty(n, np.bool_)
    _direct_light_loop(np.ascontiguousarray(n_s, dtype=f64), np.ascontiguousarray(wo, dtype=f64),
                       np.ascontiguousarray(wi, dtype=f64), np.ascontiguousarray(albedo, dtype=f64),
                       np.ascontiguousarray(emitted, dtype=f64), np.ascontiguousarray(scale, dtype=f64),
                       np.ascontiguousarray(ok, dtype=np.bool_), np.ascontiguousarray(pdf_light, dtype=f64),
                       np.ascontiguousarray(np.broadcast_to(select_prob, (n,)), dtype=f64),
                       np.ascontiguousarray(np.broadcast_to(delta, (n,)), dtype=np.bool_),
                       A, weight, ok_out)
    return A[None], weight, ok_out


#: The compiled twin of engine.materials.lambert.direct_light_numpy (None without Numba).
direct_light_numba = _direct_light_loop and direct_light_numba


@jit
def _set_albedo_loop(rgb, value, constant, slot, basis, out):
    for k in range(basis.shape[1]):
        for j in range(slot.shape[0]):
            m = slot[j]
            if constant[m]:
                out[k, j] = value[m]
            else:
                out[k, j] = rgb[0, m] * basis[0, k, j] + rgb[1, m] * basis[1, k, j] + rgb[2, m] * basis[2, k, j]


def set_albedo_numba(rgb, value, constant, slot, basis):
    out = np.empty(basis.shape[1:])
    _set_albedo_loop(np.ascontiguousarray(rgb, dtype=np.float64), np.ascontiguousarray(value, dtype=np.float64),
                     np.ascontiguousarray(constant, dtype=np.bool_), np.ascontiguousarray(slot, dtype=np.int64),
                     np.ascontiguousarray(basis, dtype=np.float64), out)
    return out


#: The compiled twin of engine.materials.lambert.set_albedo_numpy (None without Numba).
set_albedo_numba = _set_albedo_loop and set_albedo_numba
