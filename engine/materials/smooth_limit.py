"""The smooth limit (roughness m = 0) of Torrance–Sparrow: a Fresnel mirror plus a Lambertian part.

As m → 0 the facet lobe tends to the Dirac mirror s·M_F(θ_i) (docs/physics.md §3, Chapter 3 "limit"), so
roughness 0 is not an error but this model: a Dirac lobe with weight s·M_F(cosθ_o) in the
plane-of-incidence frames and the depolariser d·(ρ/π)·diag(1, 0, 0, 0).  Sampling picks the mirror
with probability P = s·F̄/(s·F̄ + d·ρ̄) (F̄, ρ̄: means over the path's wavelengths), otherwise a
cosine-weighted direction; the weights are divided by the chosen probability.  One-sided.

``diffuse_layering="albedo_scaling"`` (Cycles' Principled energy sharing, as in Torrance–Sparrow)
weights the Lambertian part by max(0, 1 − s·F(cosθ_o)), F the unpolarised Fresnel reflectance
at the view direction (exactly the mirror's albedo, per wavelength): albedo s·F + d·(1 − s·F)·ρ ≤ 1
for unpolarised light.  With ``cycles_estimate`` (a GGX Torrance–Sparrow at m = 0: the Principled specular layer)
F is Cycles' estimate instead, the reflectance's chord between the nodes of its table (docs/physics.md).
Not reciprocal (the weight depends on ω_o only).  The default ``"add"``
adds the Lambertian part as is.
"""

from __future__ import annotations

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, LobeColors, depolarising_value
from .conductor import mirror_reflection
from .sampling import cosine_hemisphere, local_to_world
from ..polarisation.fresnel import fresnel_reflectance
from ..spectral import as_spectrum
from ..textures import TexturedNumber, textured
from ..vec3 import dot


class MirrorWithDiffuse(BSDF):
    name = "torrance_sparrow"      # the m = 0 member of the Torrance–Sparrow family

    def __init__(self, n, k, exterior_n=1.0, diffuse_albedo=0.0, specular_weight=1.0, diffuse_weight=0.0,
                 diffuse_layering="add", cycles_estimate=False):
        if diffuse_layering not in ("add", "albedo_scaling"):
            raise ValueError(f"diffuse_layering must be one of ('add', 'albedo_scaling'), got {diffuse_layering!r}")
        self.diffuse_layering = diffuse_layering
        #: "albedo_scaling" by Cycles' estimate of the mirror's albedo (a GGX layer at roughness 0, a real index)
        self.cycles_estimate = bool(cycles_estimate)
        self.n, self.k = as_spectrum(n, "n"), as_spectrum(k, "k")
        self.exterior_n = float(exterior_n)
        self.albedo = as_spectrum(diffuse_albedo, "diffuse_albedo")
        # weights may be TexturedNumbers (per surface point, read through ShadingPoint.number)
        self.s, self.d = (w if isinstance(w, TexturedNumber) else float(w) for w in (specular_weight, diffuse_weight))
        self.m = 0.0
        self.has_diffuse = self.d.hi > 0 if isinstance(self.d, TexturedNumber) else self.d > 0
        self.varies_over_surface = textured(self.n, self.k, self.albedo, self.s, self.d)
        # real η ≥ 1 at every wavelength: no retardance (no κ, no total internal reflection)
        real_above_one = (self.k.is_constant and float(self.k.eval([550.0])[0]) == 0.0
                          and self.n.is_constant and float(self.n.eval([550.0])[0]) >= self.exterior_n)
        constant = self.n.is_constant and self.k.is_constant and self.albedo.is_constant
        self.flags = (BSDFFlags.DELTA_REFLECTION | BSDFFlags.POLARISING
                      | BSDFFlags.when(self.has_diffuse, BSDFFlags.DIFFUSE_REFLECTION | BSDFFlags.SEPARABLE_DIFFUSE)
                      | BSDFFlags.when(not real_above_one, BSDFFlags.RETARDING)
                      | BSDFFlags.when(not constant, BSDFFlags.WAVELENGTH_DEPENDENT))

    def _eta(self, sp):
        """The relative index (L, N), once per batch (ShadingPoint.memo)."""
        return sp.memo(self, "eta", lambda: (sp.spectrum(self.n) + 1j * sp.spectrum(self.k)) / self.exterior_n)

    def _diffuse(self, sp):
        """d·ρ (L, N), times max(0, 1 − s·F(cosθ_o)) with ``"albedo_scaling"``; once per batch (next-event
        estimation's eval, MIS's pdf and the sample read it at the same points)."""
        return sp.memo(self, "diffuse", lambda: self._diffuse_now(sp))

    def _diffuse_now(self, sp):
        if self.diffuse_layering == "add":
            return sp.spectrum(self.albedo) * sp.number(self.d)
        return sp.spectrum(self.albedo) * sp.number(self.d) * self.diffuse_scale(sp)

    def diffuse_scale(self, sp):
        """max(0, 1 − s·F(cosθ_o)) (L, N): one minus the mirror's albedo at the view direction; with
        ``cycles_estimate`` (and a real index) F is Cycles' estimate, the Fresnel reflectance interpolated between
        the nodes of its table (engine.materials.ggx_energy.cycles_layering_albedo at α = 0)."""
        eta = self._eta(sp)
        if self.cycles_estimate and not np.any(eta.imag):
            from .ggx_energy import cycles_layering_albedo
            F = cycles_layering_albedo(np.clip(sp.cos_o, 0.0, 1.0), 0.0, eta.real[0])[None, :]
            return np.maximum(1.0 - sp.number(self.s) * F, 0.0)
        F = fresnel_reflectance(np.clip(sp.cos_o, 0.0, 1.0)[None, :], eta)
        return np.maximum(1.0 - sp.number(self.s) * F, 0.0)

    def lobe_colors(self, sp) -> LobeColors | None:
        """Glossy: s × the mirror's M00 (its reflectance at the view angle, per wavelength); diffuse: d·ρ (× the
        ``"albedo_scaling"`` weight)."""
        glossy = self.delta_reflection(sp).m00()
        return LobeColors.of(sp, diffuse=self._diffuse(sp) if self.has_diffuse else 0.0, glossy=glossy)

    def _p_mirror(self, sp, mirror):
        """The mirror's probability P (N,) with ``mirror`` = self._mirror(sp)[1]; once per batch (MIS's pdf and the
        sample read it at the same points)."""
        return sp.memo(self, "p_mirror", lambda: self._p_mirror_now(sp, mirror))

    def _p_mirror_now(self, sp, mirror):
        spec = sp.number(self.s) * mirror.A.mean(axis=0)
        diff = self._diffuse(sp).mean(axis=0) if self.has_diffuse else np.zeros(sp.n)
        total = spec + diff
        return np.where(total > 0, spec / np.where(total > 0, total, 1.0), 1.0)

    def _mirror(self, sp):
        """(wi, MuellerValue, valid) of the mirror, weight 1 (engine.materials.conductor.mirror_reflection); once per
        batch."""
        return sp.memo(self, "mirror", lambda: mirror_reflection(sp, self._eta(sp)))

    def delta_reflection(self, sp):
        return self._mirror(sp)[1].scaled(sp.number(self.s))

    def eval(self, sp, wi):
        ok = (dot(sp.n_s, wi) > 0) & (sp.cos_o > 0)
        return depolarising_value(self._diffuse(sp) * (ok / np.pi)[None, :], sp.n)

    def pdf(self, sp, wi):
        if not self.has_diffuse:
            return np.zeros(sp.n)
        p = self._p_mirror(sp, self._mirror(sp)[1])
        c = dot(sp.n_s, wi)
        return np.where((c > 0) & (sp.cos_o > 0), (1.0 - p) * c / np.pi, 0.0)

    def sample(self, sp, u_lobe, u_dir) -> BSDFSample:
        wi_m, mirror, valid_m = self._mirror(sp)
        p = self._p_mirror(sp, mirror)
        pick = u_lobe < p
        local = cosine_hemisphere(u_dir)
        wi_d = local_to_world(local, sp.n_s)
        wi = np.where(pick[None, :], wi_m, wi_d)
        w_m = mirror.scaled((sp.number(self.s) / np.where(p > 0, p, 1.0))[None, :])
        diff_ok = (~pick) & (sp.cos_o > 0) & (local[2] > 0)
        w_d = self._diffuse(sp) * (diff_ok / np.where(p < 1, 1.0 - p, 1.0))[None, :]
        sel = pick[None, :]
        value = type(mirror)("abcs", w_m.x_in, w_m.x_out, np.where(sel, w_m.A, 0.0), np.where(sel, w_m.B, 0.0),
                             np.where(sel, w_m.C, 0.0), np.where(sel, w_m.S, 0.0),
                             depol=np.where(sel, 0.0, w_d))
        pdf = np.where(pick, 0.0, (1.0 - p) * np.maximum(local[2], 0.0) / np.pi)
        return BSDFSample(wi=wi, weight=value, pdf=pdf, is_delta=pick, valid=np.where(pick, valid_m, diff_ok),
                          eta_sq=np.ones(sp.n))
