"""Microfacet distributions, shadowing terms and half-vector sampling (batched, (3, N) layout).

Everything here works in a *local shading frame*: the macro normal is +z and
directions are unit vectors (3, N) pointing away from the surface (ω_i to the
light, ω_o to the viewer, h the microfacet normal).  Callers convert world →
local once (see engine.materials.torrance_sparrow).

Distributions (both normalised, ∫ D(h) cosθ_h dω_h = 1 over the upper hemisphere):

- :class:`Beckmann` with the thesis's roughness ``m`` (= Mitsuba's α = SCATMECH's
  2-D rms slope s, docs/physics.md §5):
  D(h) = exp(−tan²θ_h/m²) / (π m² cos⁴θ_h), evaluated as exp(−x)·(1 + tan²θ_h)²/(π m²),
  x = tan²θ_h/m², with tan²θ_h = (h_x² + h_y²)/h_z² taken from the vector components
  (no 1 − cos² cancellation near the specular peak).  D is *exactly* 0 where x > 800
  (exp underflows there anyway; the cut-off avoids 0·∞ for near-horizontal h) and for
  h_z ≤ 0.  Very small m are numerically fine (the peak is 1/(π m²)); the material
  enforces m ≥ 1e-4 (engine.materials.roughness.ALPHA_MIN).
  Sampling: **visible normals** (Heitz & d'Eon 2014), implemented from the paper's
  math: stretch ω_o by m, sample the visible slope x̃ from the marginal
  ∝ (1 − x̃ tanθ) e^{−x̃²} (x̃ < cotθ) by bisection-safeguarded Halley inversion of its CDF
  F(x) = erfc(−x) + tanθ e^{−x²}/√π (vectorised; converged to ~1e-14 in probability),
  ỹ = erfinv(2u − 1), rotate by φ_o, unstretch, h = normalize(−x, −y, 1).  The density
  of the sampled h is D_ωo(h) = G1(ω_o) max(0, ω_o·h) D(h)/cosθ_o with the *exact*
  Smith G1 (it is the normalisation of the visible-normal distribution, whatever
  shadowing term the BRDF uses); for the reflected ω_i = 2(ω_o·h)h − ω_o the
  solid-angle pdf is D_ωo(h)/(4 ω_o·h) = G1(ω_o) D(h)/(4 cosθ_o).
- :class:`BlinnPhong` with exponent e ≥ 0: D(h) = (e+2)/(2π) cos^e θ_h.  Sampling
  D(h) cosθ_h exactly (cosθ_h = u^{1/(e+2)}); pdf of ω_i = D cosθ_h/(4 ω_o·h).  Its
  Smith G1 uses the Beckmann G1 with the equivalent m = √(2/(e+2)) (Walter et al. 2007).

Shadowing/masking (symmetric in ω_i ↔ ω_o, all return (N,)):

- :func:`g_vcavity`: Torrance–Sparrow/Cook–Torrance V-cavity
  G = min(1, 2(n·h)(n·ω_o)/(ω_o·h), 2(n·h)(n·ω_i)/(ω_i·h)), and 0 when either direction
  is on the back side of the facet or of the macro surface (docs/physics.md §1, §3 Eq. 3.3).
- :func:`g_smith_correlated`: height-correlated Smith 1/(1 + Λ(ω_i) + Λ(ω_o)) (Heitz 2014; Cycles' G),
  with the distribution's own Λ (``smith_lambda``).
- :func:`g_smith` : separable Smith G1(ω_i)G1(ω_o) with the exact Beckmann
  G1 = χ⁺ / (1 + Λ(a)), Λ(a) = (erf(a) − 1)/2 + e^{−a²}/(2a√π), a = 1/(m tanθ);
  ``rational=True`` uses Walter's rational approximation as in Mitsuba 3:
  G1 = 1 if a ≥ 1.6 else (3.535a + 2.181a²)/(1 + 2.276a + 2.577a²); G1 = 0 where
  (ω·h)·cosθ ≤ 0.

D is the Beckmann distribution, i.e. a Gaussian in the facet *slope* tanθ_h (as SCATMECH's
Gaussian_Slope_Distribution_Function and Mitsuba 3), not Torrance & Sparrow's 1967 Gaussian in
the facet angle θ_h itself (docs/physics.md §3, Eq. 3.4).

erf/erfc/erfcx/erfinv come from engine.kernels.error_function (NumPy only, no scipy), the
visible-slope inversion from engine.kernels.microfacet (compiled when Numba is available; one
Halley step from a tabulated start, one Newton step for ỹ, each one erfcx).
"""

from __future__ import annotations

import math

import numpy as np

# erf, erfc, erfcx, erfinv: re-exported, the special functions of this model's formulas
from ..kernels.error_function import SQRT_PI, erf, erfc, erfcx, erfcx_nonneg, erfinv, erfinv_2u_minus_1  # noqa: F401
from ..kernels.microfacet import g_vcavity, visible_slope_x, visible_slope_y

_INV_SQRT_PI = 1.0 / SQRT_PI
#: exp(−x) for x beyond this is exactly 0 in double precision (and D is set to 0 there).
_EXP_CUTOFF = 800.0


def beckmann_lambda(a) -> np.ndarray:
    """Smith Λ(a) = (erf(a) − 1)/2 + e^{−a²}/(2a√π) for the Beckmann distribution, a = 1/(m tanθ) ≥ 0.

    Λ(∞) = 0 (normal incidence); Λ(0) = ∞ (grazing).  Computed as
    ½ e^{−a²}(1/(a√π) − erfcx(a)); for a > 6, Λ < 1e-17 and is set to 0.
    """
    a = np.asarray(a, dtype=np.float64)
    pos = a > 0
    small = pos & (a <= 6.0)
    safe = np.where(small, a, 1.0)
    lam = 0.5 * np.exp(-safe * safe) * (_INV_SQRT_PI / safe - erfcx_nonneg(safe))
    lam = np.maximum(lam, 0.0)
    return np.where(small, lam, np.where(pos, 0.0, np.inf))


# --- vector helpers ------------------------------------------------------------------------------------


def half_vector(wi: np.ndarray, wo: np.ndarray):
    """(h, cos_facet, ok): h = unit(ω_i + ω_o), cos of the facet angle ω_i·h = ω_o·h = |ω_i + ω_o|/2.

    ``ok`` is False where ω_i = −ω_o (h undefined); h is then (0, 0, 1) and cos_facet 0.
    """
    hv = wi + wo
    length = np.sqrt(hv[0] * hv[0] + hv[1] * hv[1] + hv[2] * hv[2])
    ok = length > 0
    h = np.where(ok, hv / np.where(ok, length, 1.0), np.array([[0.0], [0.0], [1.0]]))
    return h, np.minimum(0.5 * length, 1.0), ok


def reflect_local(w: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Mirror direction of w about the unit facet normal h (both (3, N))."""
    d = w[0] * h[0] + w[1] * h[1] + w[2] * h[2]
    return 2.0 * d * h - w


def _tan2(w: np.ndarray) -> np.ndarray:
    """tan²θ of w about +z (∞ for w_z = 0 with w_xy ≠ 0; 0 for w = ±z)."""
    xy2 = w[0] * w[0] + w[1] * w[1]
    z2 = w[2] * w[2]
    return np.where(z2 > 0, xy2 / np.where(z2 > 0, z2, 1.0), np.where(xy2 > 0, np.inf, 0.0))


def _smith_a(w: np.ndarray, m: float) -> np.ndarray:
    """a = 1/(m tanθ) = cosθ/(m sinθ) ≥ 0 (∞ at normal incidence, 0 at grazing)."""
    sin_t = np.sqrt(w[0] * w[0] + w[1] * w[1])
    cos_t = np.abs(w[2])
    return np.where(sin_t > 0, cos_t / (m * np.where(sin_t > 0, sin_t, 1.0)), np.inf)


def _chi_plus(w: np.ndarray, h: np.ndarray) -> np.ndarray:
    """1 where (w·h)·cosθ_w > 0 (w sees the front of facet h from the front of the surface)."""
    d = w[0] * h[0] + w[1] * h[1] + w[2] * h[2]
    return (d * w[2] > 0).astype(np.float64)


def g1_beckmann_exact(w: np.ndarray, h: np.ndarray, m: float) -> np.ndarray:
    """Exact Smith masking G1(w, h) = χ⁺((w·h) cosθ_w) / (1 + Λ(1/(m tanθ_w))) for Beckmann."""
    return _chi_plus(w, h) / (1.0 + beckmann_lambda(_smith_a(w, m)))


def g1_beckmann_rational(w: np.ndarray, h: np.ndarray, m: float) -> np.ndarray:
    """Walter et al. 2007 rational approximation of the Beckmann G1 (as Mitsuba 3's ``smith_g1``)."""
    a = _smith_a(w, m)
    af = np.minimum(a, 1.6)
    g = np.where(a >= 1.6, 1.0, (3.535 * af + 2.181 * af * af) / (1.0 + 2.276 * af + 2.577 * af * af))
    return g * _chi_plus(w, h)


# --- distributions -------------------------------------------------------------------------------------


class MicrofacetDistribution:
    """Interface: isotropic distribution of microfacet normals about +z (local frame)."""

    name = "distribution"
    #: Beckmann-equivalent roughness used by the Smith masking functions.
    smith_m: float = 1.0

    def D(self, h: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def G1(self, w: np.ndarray, h: np.ndarray, rational: bool = False) -> np.ndarray:
        """Smith masking of facet h seen from w (Beckmann form with ``smith_m``)."""
        if rational:
            return g1_beckmann_rational(w, h, self.smith_m)
        return g1_beckmann_exact(w, h, self.smith_m)

    def smith_lambda(self, w: np.ndarray) -> np.ndarray:
        """Smith Λ(ω) (N,) of the exact G1 = 1/(1 + Λ) (Beckmann form with ``smith_m``; ∞ at grazing)."""
        return beckmann_lambda(_smith_a(w, self.smith_m))

    def sample(self, wo: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Facet normals h (3, N) for viewer directions wo (3, N) from uniforms u (2, N)."""
        raise NotImplementedError

    def pdf(self, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Solid-angle density of h under :meth:`sample` (N,)."""
        raise NotImplementedError

    def pdf_reflected(self, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Solid-angle density of ω_i = reflect(ω_o, h) under :meth:`sample`: pdf(h)/(4 ω_o·h)."""
        d = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        ok = d > 0
        return np.where(ok, self.pdf(wo, h) / (4.0 * np.where(ok, d, 1.0)), 0.0)

    def take(self, sel: np.ndarray) -> MicrofacetDistribution:
        """The distribution at the points ``sel`` of a batch: itself for one roughness, the selected
        points' roughnesses for a per-point distribution (``per_point``)."""
        return self


class Beckmann(MicrofacetDistribution):
    """Beckmann distribution with roughness m (rms 2-D slope); visible-normal sampling."""

    name = "beckmann"

    def __init__(self, m: float):
        m = float(m)
        if not (math.isfinite(m) and m > 0):
            raise ValueError(f"Beckmann roughness m must be a finite number > 0, got {m!r}")
        self.m = m
        self.smith_m = m

    @classmethod
    def per_point(cls, m: np.ndarray) -> Beckmann:
        """Beckmann distributions with one roughness per point, m (N,) > 0 (a textured m): every
        method is elementwise in m, so point i gets exactly the values of ``Beckmann(m[i])``."""
        m = np.asarray(m, dtype=np.float64)
        if not np.all(np.isfinite(m) & (m > 0)):
            raise ValueError("Beckmann roughness m must be finite numbers > 0")
        dist = cls.__new__(cls)
        dist.m = dist.smith_m = m
        return dist

    def take(self, sel: np.ndarray) -> Beckmann:
        return self if np.ndim(self.m) == 0 else Beckmann.per_point(self.m[sel])

    def D(self, h: np.ndarray) -> np.ndarray:
        t2 = _tan2(h)
        x = t2 / (self.m * self.m)
        ok = (h[2] > 0) & (x <= _EXP_CUTOFF)
        xs = np.where(ok, x, 0.0)
        ts = np.where(ok, t2, 0.0)
        one_t = 1.0 + ts
        return np.where(ok, np.exp(-xs) * (one_t * one_t) / (math.pi * self.m * self.m), 0.0)

    # -- visible normal sampling (Heitz & d'Eon 2014) --
    @staticmethod
    def _sample_slopes11(tan_t: np.ndarray, u1: np.ndarray, u2: np.ndarray):
        """Visible slopes (x̃, ỹ) of the unit-roughness Beckmann surface seen from θ with tanθ = tan_t ≥ 0.

        x̃ has density ∝ (1 − x̃ tanθ) e^{−x̃²} on x̃ < cotθ (engine.kernels.microfacet); ỹ is
        independent with density e^{−ỹ²}/√π: ỹ = erfinv(2u₂ − 1) (engine.kernels.microfacet.visible_slope_y).
        """
        return visible_slope_x(tan_t, u1), visible_slope_y(u2)

    def sample(self, wo: np.ndarray, u: np.ndarray) -> np.ndarray:
        m = self.m
        sxy = np.sqrt(wo[0] * wo[0] + wo[1] * wo[1])
        cz = np.maximum(wo[2], 0.0)
        # Stretched direction (m wo_x, m wo_y, wo_z): tanθ' = m tanθ, same azimuth.
        tan_t = np.where(cz > 0, m * sxy / np.where(cz > 0, cz, 1.0), 1e300)
        tan_t = np.minimum(tan_t, 1e300)
        has_phi = sxy > 0
        cos_p = np.where(has_phi, wo[0] / np.where(has_phi, sxy, 1.0), 1.0)
        sin_p = np.where(has_phi, wo[1] / np.where(has_phi, sxy, 1.0), 0.0)
        sx, sy = self._sample_slopes11(tan_t, u[0], u[1])
        x = m * (cos_p * sx - sin_p * sy)
        y = m * (sin_p * sx + cos_p * sy)
        h = np.stack((-x, -y, np.ones_like(x)))
        return h / np.sqrt(h[0] * h[0] + h[1] * h[1] + 1.0)

    def pdf(self, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
        """G1(ω_o) max(0, ω_o·h) D(h)/cosθ_o (exact Smith G1): the visible-normal density."""
        d = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        ok = (wo[2] > 0) & (d > 0)
        g1 = 1.0 / (1.0 + beckmann_lambda(_smith_a(wo, self.m)))
        return np.where(ok, g1 * np.maximum(d, 0.0) * self.D(h) / np.where(ok, wo[2], 1.0), 0.0)

    def pdf_reflected(self, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
        """G1(ω_o) D(h)/(4 cosθ_o) where ω_o·h > 0 (the ω_o·h of the Jacobian cancels)."""
        d = wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2]
        ok = (wo[2] > 0) & (d > 0)
        g1 = 1.0 / (1.0 + beckmann_lambda(_smith_a(wo, self.m)))
        return np.where(ok, g1 * self.D(h) / (4.0 * np.where(ok, wo[2], 1.0)), 0.0)

    def __repr__(self):
        return f"Beckmann(m={self.m!r})"


class BlinnPhong(MicrofacetDistribution):
    """Blinn–Phong distribution D = (e+2)/(2π) cos^e θ_h; samples D cosθ_h."""

    name = "blinn"

    def __init__(self, exponent: float):
        e = float(exponent)
        if not (math.isfinite(e) and e >= 0):
            raise ValueError(f"Blinn-Phong exponent must be a finite number >= 0, got {exponent!r}")
        self.e = e
        self.smith_m = math.sqrt(2.0 / (e + 2.0))

    @classmethod
    def from_beckmann_m(cls, m: float) -> BlinnPhong:
        """The Blinn lobe matching Beckmann roughness m near the peak: e = 2/m² − 2 (needs m ≤ √2)."""
        m = float(m)
        if not (math.isfinite(m) and 0 < m <= math.sqrt(2.0)):
            raise ValueError(f"Blinn from Beckmann m needs 0 < m <= sqrt(2), got {m!r}")
        return cls(max(2.0 / (m * m) - 2.0, 0.0))

    def D(self, h: np.ndarray) -> np.ndarray:
        c = h[2]
        ok = c > 0
        cs = np.where(ok, np.minimum(c, 1.0), 1.0)
        return np.where(ok, (self.e + 2.0) / (2.0 * math.pi) * cs ** self.e, 0.0)

    def sample(self, wo: np.ndarray, u: np.ndarray) -> np.ndarray:
        # cosθ_h = u^{1/(e+2)};  sin²θ_h = 1 − u^{2/(e+2)} = −expm1(2 ln u/(e+2)).
        u1 = np.clip(u[0], 1e-300, 1.0)
        lnu = np.log(u1) / (self.e + 2.0)
        cos_t = np.exp(lnu)
        sin_t = np.sqrt(np.maximum(-np.expm1(2.0 * lnu), 0.0))
        phi = 2.0 * math.pi * u[1]
        return np.stack((sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t))

    def pdf(self, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
        return self.D(h) * np.maximum(h[2], 0.0)

    def __repr__(self):
        return f"BlinnPhong(e={self.e!r})"


# --- shadowing -----------------------------------------------------------------------------------------


def g_smith(dist: MicrofacetDistribution, wi: np.ndarray, wo: np.ndarray, h: np.ndarray,
            rational: bool = False) -> np.ndarray:
    """Separable Smith shadowing-masking G1(ω_i, h)·G1(ω_o, h) of ``dist``."""
    return dist.G1(wi, h, rational) * dist.G1(wo, h, rational)


def g_smith_correlated(dist: MicrofacetDistribution, wi: np.ndarray, wo: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Height-correlated Smith shadowing-masking χ⁺(ω_i, h)·χ⁺(ω_o, h)/(1 + Λ(ω_i) + Λ(ω_o)) of ``dist``
    (Heitz 2014, Eq. 99; Cycles' G): a facet masked from one direction is likelier shadowed from the other,
    so G ≥ G1·G1, with equality where either direction is normal."""
    return _chi_plus(wi, h) * _chi_plus(wo, h) / (1.0 + dist.smith_lambda(wi) + dist.smith_lambda(wo))


SHADOWING = ("ts", "smith", "smith_rational", "none", "smith_correlated")


def shadowing_term(kind: str, dist: MicrofacetDistribution, wi, wo, h) -> np.ndarray:
    """G of the named kind: "ts" (V-cavity), "smith" (separable), "smith_rational", "none" (G = 1 on the
    front side) or "smith_correlated" (height-correlated Smith)."""
    if kind == "ts":
        return g_vcavity(wi, wo, h)
    if kind == "smith":
        return g_smith(dist, wi, wo, h)
    if kind == "smith_correlated":
        return g_smith_correlated(dist, wi, wo, h)
    if kind == "smith_rational":
        return g_smith(dist, wi, wo, h, rational=True)
    if kind == "none":
        return _chi_plus(wi, h) * _chi_plus(wo, h)
    raise ValueError(f"shadowing must be one of {SHADOWING}, got {kind!r}")
