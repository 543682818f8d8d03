"""Shadow rays of next-event estimation in one compiled pass: where they start and how long they are.

From the surface points p (3, n) with geometric normals n_g towards the sampled light directions wi
at distances ``dist`` (inf for lights at infinity): the origins p moved off the surface along ±n_g
(engine.kernels.geometry.offset_origin, with ``epsilon``) and the lengths
dist·(1 − 1e-4) − 1e-4·(1 + max|p_i|), stopping just short of the light (inf where dist is not
finite).  In NumPy these are some ten passes over the batch with the GIL held.
"""

from __future__ import annotations

import numpy as np

from . import jit, twin
from .geometry import offset_origin_at, offset_origin_numpy


def shadow_rays_numpy(p, n_g, wi, dist, epsilon):
    """(o (3, n), t_max (n,)) of the shadow rays from p along wi; see the module docstring."""
    t_max = np.where(np.isfinite(dist), dist * (1.0 - 1e-4) - 1e-4 * (1.0 + np.abs(p).max(0)), np.inf)
    return offset_origin_numpy(p, n_g, wi, epsilon), t_max


@jit
def _shadow_rays_loop(p, n_g, wi, dist, epsilon, o, t_max):
    for i in range(p.shape[1]):
        m = offset_origin_at(p, n_g, wi, epsilon, i, o)
        d = dist[i]
        t_max[i] = d * (1.0 - 1e-4) - 1e-4 * (1.0 + m) if np.isfinite(d) else np.inf


def shadow_rays_numba(p, n_g, wi, dist, epsilon):
    c = np.ascontiguousarray
    p = c(p, dtype=np.float64)
    o = np.empty_like(p)
    t_max = np.empty(p.shape[1])
    _shadow_rays_loop(p, c(n_g, dtype=np.float64), c(wi, dtype=np.float64), c(dist, dtype=np.float64),
                      float(epsilon), o, t_max)
    return o, t_max


shadow_rays = twin(_shadow_rays_loop and shadow_rays_numba, shadow_rays_numpy)
