"""A mapped shading normal's factor on a lobe's value as one compiled pass (twin in engine.materials.normal_map).

Per path, the leak rule (n_g·ω_i)(n_g·N)(N·ω_i) ≥ 0 as 1 or 0 and, for a diffuse lobe with Cycles' bump map
correction, times the terminator softening G1(α², |N_s·ω_i|) with α² = min(1, tan²θ_d / 8), cosθ_d = |N_s·N|
(engine.materials.normal_map: geometric_agreement, terminator_softening), each dot product summed x, y, z in
order and every step in the NumPy reference's order, so the numbers are its bits (NaN where it gives NaN).
Inputs (3, N) unit vectors n_g, N (the mapped normal), ω_i, N_s (the interpolated normal, read with ``soften``);
out (N,).
"""

from __future__ import annotations

import numpy as np

from . import jit


@jit
def _normal_factor_loop(n_g, n, wi, n_smooth, soften, out):
    for j in range(n.shape[1]):
        g0, g1, g2 = n_g[0, j], n_g[1, j], n_g[2, j]
        s0, s1, s2 = n[0, j], n[1, j], n[2, j]
        w0, w1, w2 = wi[0, j], wi[1, j], wi[2, j]
        side = ((g0 * w0 + g1 * w1) + g2 * w2) * ((g0 * s0 + g1 * s1) + g2 * s2) * ((s0 * w0 + s1 * w1) + s2 * w2)
        keep = 1.0 if side >= 0 else 0.0
        if soften:
            m0, m1, m2 = n_smooth[0, j], n_smooth[1, j], n_smooth[2, j]
            cos_i = abs((m0 * w0 + m1 * w1) + m2 * w2)
            cos_d = abs((m0 * s0 + m1 * s1) + m2 * s2)
            tan2_d = 1.0 / (cos_d * cos_d) - 1.0
            alpha2 = 0.125 * tan2_d
            if alpha2 < 0.0:            # np.clip(·, 0, 1): NaN stays NaN
                alpha2 = 0.0
            elif alpha2 > 1.0:
                alpha2 = 1.0
            tan2_i = (1.0 - cos_i * cos_i) / (cos_i * cos_i)
            g = 2.0 / (1.0 + np.sqrt(1.0 + alpha2 * tan2_i))
            if cos_i < 1e-6:
                g = 0.0
            if cos_d >= 1.0 or cos_i >= 1.0:
                g = 1.0
            keep = keep * g
        out[j] = keep


def normal_factor_numba(n_g, n, wi, n_smooth, soften):
    """(N,) the factor (module docstring); ``n_smooth`` read only with ``soften``."""
    out = np.empty(n.shape[1])
    c = np.ascontiguousarray
    _normal_factor_loop(c(n_g, dtype=np.float64), c(n, dtype=np.float64), c(wi, dtype=np.float64),
                        c(n_smooth, dtype=np.float64), bool(soften), out)
    return out


#: None without Numba (engine.kernels.twin then keeps the NumPy reference).
normal_factor_numba = _normal_factor_loop and normal_factor_numba
