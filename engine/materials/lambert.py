"""Lambertian depolariser: f = (ρ/π)·diag(1, 0, 0, 0), one-sided.

ρ is the albedo spectrum (engine.spectral).  Zero when wi or wo lies behind
the shading normal (as Mitsuba 3's ``diffuse``).  Sampling: cosine-weighted
hemisphere about the shading normal, pdf = cosθ_i/π, weight = ρ.
"""

from __future__ import annotations

import numpy as np

from .base import BSDF, BSDFSample, ShadingPoint, depolarising_value
from .sampling import cosine_hemisphere, local_to_world
from ..vec3 import dot


class Lambert(BSDF):
    name = "lambert"
    polarising = False
    creates_circular = False

    def __init__(self, albedo):
        self.albedo = albedo
        self.wavelength_independent = bool(getattr(albedo, "is_constant", False))

    def eval(self, sp: ShadingPoint, wi: np.ndarray):
        ok = (dot(sp.n_s, wi) > 0) & (sp.cos_o > 0)
        a = sp.spectrum(self.albedo) * (ok / np.pi)[None, :]
        return depolarising_value(a, sp.n)

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        c = dot(sp.n_s, wi)
        return np.where((c > 0) & (sp.cos_o > 0), c / np.pi, 0.0)

    def sample(self, sp: ShadingPoint, u_lobe, u_dir) -> BSDFSample:
        local = cosine_hemisphere(u_dir)
        wi = local_to_world(local, sp.n_s)
        valid = (sp.cos_o > 0) & (local[2] > 0)
        a = sp.spectrum(self.albedo) * valid[None, :]
        return BSDFSample(wi=wi, weight=depolarising_value(a, sp.n), pdf=np.where(valid, local[2] / np.pi, 0.0),
                          is_delta=np.zeros(sp.n, bool), valid=valid, eta_sq=np.ones(sp.n))

    def describe(self) -> dict:
        return {"type": self.name, "albedo": repr(self.albedo)}
