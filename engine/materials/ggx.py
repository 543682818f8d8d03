"""The GGX (Trowbridge–Reitz) microfacet distribution with visible-normal sampling (local frame, +z normal).

    D(h) = 1 / (π α² cos⁴θ_h (1 + tan²θ_h/α²)²),   ∫ D(h) cosθ_h dω_h = 1,

evaluated as (1 + t)² / (π α² (1 + t/α²)²) with t = tan²θ_h from the vector components (no
1 − cos² cancellation at the peak).  Smith masking (exact for GGX): G1(ω, h) = χ⁺((ω·h) cosθ_ω) /
(1 + Λ), Λ = (√(1 + α² tan²θ_ω) − 1)/2.

Visible normals (Heitz 2018, "Sampling the GGX distribution of visible normals"), in closed form:
stretch ω_o to (α ω_x, α ω_y, ω_z), sample a point on the projected hemisphere (a disk whose half
is squeezed by (1 + cosθ)/2), lift it to the hemisphere and unstretch.  The density of the sampled
h is D_ωo(h) = G1(ω_o) max(0, ω_o·h) D(h)/cosθ_o, as for engine.materials.microfacet.Beckmann.
No iteration, so no compiled kernel is needed.  ``GGX.per_point`` holds one α per point (a textured
roughness of engine.materials.torrance_sparrow); the directional albedos that multiple-scattering
compensation needs are in engine.materials.ggx_energy.
"""

from __future__ import annotations

import math

import numpy as np

from .microfacet import MicrofacetDistribution, _chi_plus, _tan2


#: tan²θ_h above which D takes its horizontal-facet limit α²/π (the formula's (1 + t)² would overflow).
_FLAT_TAN2 = 1e150


class GGX(MicrofacetDistribution):
    """GGX / Trowbridge–Reitz distribution with roughness α (> 0); visible-normal sampling."""

    name = "ggx"

    def __init__(self, alpha: float):
        alpha = float(alpha)
        if not (math.isfinite(alpha) and alpha > 0):
            raise ValueError(f"GGX roughness alpha must be a finite number > 0, got {alpha!r}")
        self.alpha = alpha
        self.smith_m = alpha

    @classmethod
    def per_point(cls, alpha: np.ndarray) -> GGX:
        """GGX distributions with one roughness per point, α (N,) > 0 (a textured roughness): every
        method is elementwise in α, so point i gets exactly the values of ``GGX(alpha[i])``."""
        alpha = np.asarray(alpha, dtype=np.float64)
        if not np.all(np.isfinite(alpha) & (alpha > 0)):
            raise ValueError("GGX roughness alpha must be finite numbers > 0")
        dist = cls.__new__(cls)
        dist.alpha = dist.smith_m = alpha
        return dist

    def take(self, sel: np.ndarray) -> GGX:
        return self if np.ndim(self.alpha) == 0 else GGX.per_point(self.alpha[sel])

    def D(self, h: np.ndarray) -> np.ndarray:
        t2 = _tan2(h)
        ok = (h[2] > 0) & np.isfinite(t2)
        # beyond tan²θ_h = 1e150 (cosθ_h < 1e-75) (1 + t)² overflows: D is its limit α²/π there
        flat = ok & (t2 > _FLAT_TAN2)
        t = np.where(ok & ~flat, t2, 0.0)
        a2 = self.alpha * self.alpha
        q = 1.0 + t / a2
        return np.where(ok, np.where(flat, a2 / math.pi, (1.0 + t) ** 2 / (math.pi * a2 * q * q)), 0.0)

    def smith_lambda(self, w: np.ndarray) -> np.ndarray:
        """Λ(ω) = (√(1 + α² tan²θ) − 1)/2 (∞ at grazing)."""
        t2 = _tan2(w)
        fin = np.isfinite(t2)
        x = self.alpha * self.alpha * np.where(fin, t2, 0.0)
        # (√(1+x) − 1)/2 written without cancellation for small x
        lam = 0.5 * x / (np.sqrt(1.0 + x) + 1.0)
        return np.where(fin, lam, np.inf)

    def G1(self, w: np.ndarray, h: np.ndarray, rational: bool = False) -> np.ndarray:
        if rational:
            raise ValueError("the rational Smith approximation exists for Beckmann only")
        return _chi_plus(w, h) / (1.0 + self.smith_lambda(w))

    def sample(self, wo: np.ndarray, u: np.ndarray) -> np.ndarray:
        return visible_normals(wo, u, self.alpha, self.alpha)

    def pdf(self, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
        """G1(ω_o) max(0, ω_o·h) D(h)/cosθ_o: the visible-normal density."""
        d = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        ok = (wo[2] > 0) & (d > 0)
        g1 = 1.0 / (1.0 + self.smith_lambda(wo))
        return np.where(ok, g1 * np.maximum(d, 0.0) * self.D(h) / np.where(ok, wo[2], 1.0), 0.0)

    def __repr__(self):
        return f"GGX(alpha={self.alpha!r})"


def visible_normals(wo: np.ndarray, u: np.ndarray, ax, ay) -> np.ndarray:
    """GGX visible normals h (3, N), local frame (+z the normal), for views wo (3, N) from uniforms u (2, N)
    (Heitz 2018): stretch ω_o by (α_x, α_y, 1), sample the projected hemisphere, unstretch.  Density
    G1(ω_o) max(0, ω_o·h) D(h)/cosθ_o; α_x = α_y is the isotropic GGX (GGX.sample)."""
    v = np.stack((ax * wo[0], ay * wo[1], np.maximum(wo[2], 0.0)))
    v = v / np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    lensq = v[0] * v[0] + v[1] * v[1]
    has = lensq > 0
    inv = np.where(has, 1.0 / np.sqrt(np.where(has, lensq, 1.0)), 0.0)
    t1 = np.stack((np.where(has, -v[1] * inv, 1.0), np.where(has, v[0] * inv, 0.0), np.zeros_like(lensq)))
    t2 = np.stack((v[1] * t1[2] - v[2] * t1[1], v[2] * t1[0] - v[0] * t1[2], v[0] * t1[1] - v[1] * t1[0]))
    r = np.sqrt(u[0])
    phi = 2.0 * math.pi * u[1]
    p1 = r * np.cos(phi)
    p2 = r * np.sin(phi)
    s = 0.5 * (1.0 + v[2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - p1 * p1, 0.0)) + s * p2
    pz = np.sqrt(np.maximum(1.0 - p1 * p1 - p2 * p2, 0.0))
    nh = p1 * t1 + p2 * t2 + pz * v
    h = np.stack((ax * nh[0], ay * nh[1], np.maximum(nh[2], 1e-300)))
    return h / np.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2])
