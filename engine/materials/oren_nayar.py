"""A rough diffuse surface as Cycles renders it (Principled Diffuse Roughness, Diffuse BSDF Roughness):
Fujii's improved Oren–Nayar with its multiple-scattering term (Cycles' kernel/closure/bsdf_oren_nayar.h,
the form of OpenPBR's "EON" model).  A depolariser.

With σ = roughness ∈ [0, 1], a = 1/(π + σ(π/2 − 2/3)), b = σa, s = ω_i·ω_o − cosθ_i cosθ_o, t = s/max(cosθ_i,
cosθ_o) where s > 0 (else t = s), E(μ) = aπ + b·G(μ) the single-scattering albedo (G as Cycles writes it),
E_avg = aπ + b(2π − 5.6)/3 and E_ms(ρ) = ρ²·E_avg/(1 − E_avg)/(π(1 − ρ(1 − E_avg))):

    f = ρ·[a + b·t + E_ms(ρ)·(1 − E(cosθ_o))·(1 − E(cosθ_i))]

per wavelength (ρ the albedo spectrum; Cycles' closure weight times its intensity — the multiple-scattering
term thus carries ρ³, as Cycles' does).  σ = 0 is Lambert exactly (a = 1/π, b = 0, E = 1).  Sampled
cosine-weighted; pdf cosθ_i/π.
"""

from __future__ import annotations

import math

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, LobeColors, depolarising_value
from .parameters import ModelDeclaration, Parameter
from .sampling import cosine_hemisphere, local_to_world
from ..vec3 import dot


def _g(cos_t):
    """Cycles' bsdf_oren_nayar_G(cosθ) (its Taylor form below cosθ = 1e-6)."""
    c = np.clip(cos_t, 0.0, 1.0)
    small = c < 1e-6
    cs = np.where(small, 1.0, c)
    s = np.sqrt(np.maximum(1.0 - cs * cs, 0.0))
    theta = np.arccos(cs)
    g = s * (theta - 2.0 / 3.0 - s * cs) + 2.0 / 3.0 * (s / cs) * (1.0 - s * s * s)
    return np.where(small, (math.pi / 2 - 2.0 / 3.0) - c, g)


class OrenNayar(BSDF):
    """Fujii/EON Oren–Nayar of albedo ρ (a Spectrum, constant or textured) and roughness σ ∈ [0, 1]."""

    name = "oren_nayar"
    flags = BSDFFlags.DIFFUSE_REFLECTION | BSDFFlags.SEPARABLE_DIFFUSE

    def __init__(self, albedo, roughness):
        from ..textures import TexturedNumber, TexturedSpectrum
        self.albedo = albedo
        if isinstance(roughness, TexturedNumber):        # σ per point (Cycles' Diffuse Roughness from a texture)
            if not (0.0 <= roughness.lo and roughness.hi <= 1.0):
                raise ValueError(f"roughness must be in [0, 1], got values in [{roughness.lo:g}, {roughness.hi:g}]")
            self.roughness = roughness
        else:
            sigma = float(roughness)
            if not (math.isfinite(sigma) and 0.0 <= sigma <= 1.0):
                raise ValueError(f"roughness must be in [0, 1], got {roughness!r}")
            self.roughness = sigma
            self.a, self.b, self.e_avg = _coefficients(sigma)
        self.varies_over_surface = isinstance(albedo, TexturedSpectrum) or isinstance(roughness, TexturedNumber)
        if not getattr(albedo, "is_grey", False):
            self.flags = type(self).flags | BSDFFlags.WAVELENGTH_DEPENDENT

    def _coefficients(self, sp):
        """(a, b, E_avg): numbers, or (N,) at the points for a σ per point."""
        if isinstance(self.roughness, float):
            return self.a, self.b, self.e_avg
        return _coefficients(sp.number(self.roughness))

    @staticmethod
    def _albedo_of(mu, a, b):
        return a * math.pi + b * _g(mu)

    def _albedo(self, mu):
        """E(μ) of the single-scattering lobe (a constant σ)."""
        return self._albedo_of(mu, self.a, self.b)

    def _value(self, sp, wi):
        rho = np.clip(sp.spectrum(self.albedo), 0.0, 1.0)
        cos_i, cos_o = dot(sp.n_s, wi), sp.cos_o
        ok = (cos_i > 0) & (cos_o > 0)
        s = dot(wi, sp.wo) - cos_i * cos_o
        t = np.where(s > 0, s / np.maximum(np.maximum(cos_i, cos_o), 1e-300), s)
        a, b, e_avg = self._coefficients(sp)
        single = a + b * t
        if np.ndim(b) == 0 and b <= 0.0:    # σ = 0: Lambert (Cycles returns before the multiple-scattering term)
            return np.where(ok[None, :], rho * single[None, :], 0.0)
        lambert = np.asarray(b) <= 0.0          # (a σ per point: Lambert where it is 0)
        e = np.where(lambert, 0.5, e_avg)
        e_ms = rho * rho * (e / (1.0 - e)) / (math.pi * (1.0 - rho * (1.0 - e)))
        multi = e_ms * ((1.0 - self._albedo_of(cos_o, a, b)) * (1.0 - self._albedo_of(cos_i, a, b)))[None, :]
        multi = np.where(lambert, 0.0, multi)
        return np.where(ok[None, :], rho * (single[None, :] + multi), 0.0)

    def eval(self, sp, wi):
        return depolarising_value(self._value(sp, wi), sp.n)

    def pdf(self, sp, wi):
        c = dot(sp.n_s, wi)
        return np.where((c > 0) & (sp.cos_o > 0), c / math.pi, 0.0)

    def sample(self, sp, u_lobe, u_dir) -> BSDFSample:
        wi = local_to_world(cosine_hemisphere(u_dir), sp.n_s)
        valid = (sp.cos_o > 0) & (dot(wi, sp.n_g) > 0)
        weight = math.pi * self._value(sp, wi) * valid[None, :]      # f·cosθ/pdf with pdf = cosθ/π
        return BSDFSample(wi=wi, weight=depolarising_value(weight, sp.n), pdf=self.pdf(sp, wi),
                          is_delta=np.zeros(sp.n, bool), valid=valid)

    def lobe_colors(self, sp) -> LobeColors:
        """Diffuse: ρ (Cycles' energy-preserving Oren–Nayar closure: its weight, whatever the roughness)."""
        return LobeColors.of(sp, diffuse=np.clip(sp.spectrum(self.albedo), 0.0, 1.0))

    def albedo_estimate(self, sp):
        """The view direction's albedo (N,) for mixtures' lobe choice: ρ's wavelength mean × E(cosθ_o)."""
        a, b, _ = self._coefficients(sp)
        return np.clip(sp.spectrum(self.albedo), 0.0, 1.0).mean(axis=0) * self._albedo_of(np.clip(sp.cos_o, 0, 1), a, b)

    def describe(self):
        rough = self.roughness if isinstance(self.roughness, float) else repr(self.roughness)
        return {"type": self.name, "albedo": repr(self.albedo), "roughness": rough}


def _coefficients(sigma):
    """(a, b, E_avg) of Fujii's Oren–Nayar for σ (a number or an array)."""
    a = 1.0 / (math.pi + sigma * (math.pi / 2 - 2.0 / 3.0))
    b = sigma * a
    return a, b, a * math.pi + (2.0 * math.pi - 5.6) / 3.0 * b


DECLARATION = ModelDeclaration(
    "oren_nayar", "Oren–Nayar (Cycles)",
    "Rough diffuse reflection as Cycles' Diffuse Roughness (Fujii's improved Oren–Nayar with its "
    "multiple-scattering term); depolarising",
    [Parameter("albedo", "diffuse colour", kind="spectrum", spectrum="reflectance", lo=0.0, hi=1.0, default=0.8,
               texturable=True),
     Parameter("roughness", "σ (0: Lambert)", lo=0.0, hi=1.0, default=0.5, texturable=True)])
DECLARATION.per_point = frozenset({"albedo", "roughness"})


@DECLARATION.builder
def _oren_nayar(p):
    return OrenNayar(p["albedo"], p["roughness"])
