"""Light sources for next-event estimation and for rays that hit emitters.

All lights are unpolarised, so only their spectral radiance matters: a light
contributes the Stokes vector L·(1, 0, 0, 0) in any frame.

``sample(p, u)`` returns, for receiving points p (3, N), a direction wi
towards the light, the distance to it (inf for lights at infinity), a factor
(N,) such that incident radiance / solid-angle pdf = emitted spectrum × factor,
that pdf (0 for delta lights: point, spot, directional) and a validity mask.
The emitted spectrum itself comes from ``radiance(lam, mono)`` (or, where the
integrator works in RGB, from ``rgb()``: the light's spectrum integrated
against the CIE observer on the 1 nm grid).
Light selection (uniform over the lights) is handled by ``LightSet``.
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels.geometry import area_light_sample
from ..materials.sampling import uniform_sphere
from ..spectral import GRID_NM, spectrum_to_linear_srgb
from ..scene.description import DirectionalLight, EnvironmentLight, PointLight, SpotLight
from ..vec3 import dot, normalize


class _Light:
    is_delta = False
    at_infinity = False

    def __init__(self, spectrum):
        self.spectrum = spectrum

    def radiance(self, lam, mono) -> np.ndarray:
        return self.spectrum.eval(lam, mono=mono)

    def rgb(self) -> np.ndarray:
        """Linear sRGB (3,) of the emitted spectrum: the exact expectation of the spectral estimator."""
        if not hasattr(self, "_rgb"):
            self._rgb = spectrum_to_linear_srgb(self.spectrum.eval(GRID_NM))
        return self._rgb


class EnvironmentEmitter(_Light):
    """Constant radiance from every direction; sampled uniformly on the sphere."""

    at_infinity = True

    def sample(self, p, u):
        wi = uniform_sphere(u)
        n = p.shape[1]
        return wi, np.full(n, np.inf), np.full(n, 4.0 * math.pi), np.full(n, 1.0 / (4.0 * math.pi)), np.ones(n, bool)

    def pdf(self, d):
        return np.full(d.shape[1], 1.0 / (4.0 * math.pi))


class AreaEmitter(_Light):
    """A one-sided Lambertian emitter made of mesh triangles (emits along their front normal).

    Points are sampled uniformly by area; the solid-angle pdf is
    dist² / (cosθ_light · A_total).
    """

    def __init__(self, spectrum, tris: np.ndarray, compiled):
        super().__init__(spectrum)
        self.tris = tris
        areas = compiled.tri_area[tris]
        self.total_area = float(areas.sum())
        self.cdf = np.cumsum(areas) / self.total_area
        self.compiled = compiled

    def sample(self, p, u):
        # u has 3 rows: triangle choice, then the point within it.
        c = self.compiled
        return area_light_sample(p, u, self.cdf, self.tris, c.faces, c.vertices, c.tri_normal, self.total_area)

    def pdf_hit(self, dist, cos_l):
        """Solid-angle pdf of having sampled a point at distance dist whose front faces the ray at cos_l."""
        ok = cos_l > 0
        return np.where(ok, dist * dist / np.where(ok, cos_l, 1.0) / self.total_area, 0.0)


class PointEmitter(_Light):
    """Isotropic point light of radiant intensity I: irradiance I/r² at normal incidence."""

    is_delta = True

    def __init__(self, spectrum, position):
        super().__init__(spectrum)
        self.position = np.asarray(position, np.float64)

    def _falloff(self, wi):
        return 1.0

    def sample(self, p, u):
        to = self.position[:, None] - p
        dist2 = dot(to, to)
        dist = np.sqrt(dist2)
        valid = dist > 0
        wi = to / np.where(valid, dist, 1.0)
        scale = np.where(valid, self._falloff(wi) / np.where(valid, dist2, 1.0), 0.0)
        return wi, dist, scale, np.zeros(p.shape[1]), valid


class SpotEmitter(PointEmitter):
    """Point light restricted to a cone; ``blend`` smooths the edge (smoothstep in cos angle)."""

    def __init__(self, spectrum, position, direction, cone_angle_deg, blend):
        super().__init__(spectrum, position)
        self.axis = normalize(np.asarray(direction, np.float64))
        half = math.radians(cone_angle_deg) / 2
        self.cos_outer = math.cos(half)
        self.cos_inner = math.cos(half * (1.0 - blend))

    def _falloff(self, wi):
        c = -(self.axis[:, None] * wi).sum(0)
        if self.cos_inner <= self.cos_outer:
            return (c >= self.cos_outer).astype(np.float64)
        t = np.clip((c - self.cos_outer) / (self.cos_inner - self.cos_outer), 0.0, 1.0)
        return t * t * (3.0 - 2.0 * t)


class DirectionalEmitter(_Light):
    """Parallel light (sun) travelling along ``direction`` with irradiance E ⟂ to it."""

    is_delta = True
    at_infinity = True

    def __init__(self, spectrum, direction):
        super().__init__(spectrum)
        self.direction = normalize(np.asarray(direction, np.float64))

    def sample(self, p, u):
        n = p.shape[1]
        wi = np.broadcast_to(-self.direction[:, None], (3, n)).copy()
        return wi, np.full(n, np.inf), np.ones(n), np.zeros(n), np.ones(n, bool)


class LightSet:
    """All lights of a compiled scene; NEE picks one uniformly (probability 1/count)."""

    def __init__(self, scene, compiled):
        self.lights = []
        self.environment = None
        for mesh_index, mesh in enumerate(scene.meshes):
            if mesh.emission is None:
                continue
            tris = np.nonzero((compiled.tri_mesh == mesh_index) & (compiled.tri_area > 0))[0]
            if len(tris) == 0:
                continue
            compiled.tri_emitter[tris] = len(self.lights)
            self.lights.append(AreaEmitter(mesh.emission, tris, compiled))
        for light in scene.lights:
            if isinstance(light, EnvironmentLight):
                self.environment = EnvironmentEmitter(light.radiance)
                self.lights.append(self.environment)
            elif isinstance(light, SpotLight):
                self.lights.append(SpotEmitter(light.intensity, light.position, light.direction,
                                               light.cone_angle_deg, light.blend))
            elif isinstance(light, PointLight):
                self.lights.append(PointEmitter(light.intensity, light.position))
            elif isinstance(light, DirectionalLight):
                self.lights.append(DirectionalEmitter(light.irradiance, light.direction))
        self.select_prob = 1.0 / len(self.lights) if self.lights else 0.0

    def __len__(self):
        return len(self.lights)
