"""Light sources for next-event estimation and for rays that hit emitters.

A light contributes the Stokes vector L·(1, 0, 0, 0) in any frame, unless it is polarised: then
``polarisation`` is set and ``emitted_polarisation(k)`` gives its normalised Stokes vectors and their
frame for light leaving along k (engine.polarisation.sources; the integrator's engine.render.polarised_light).

``sample(p, u)`` returns, for receiving points p (3, N), a direction wi
towards the light, the distance to it (inf for lights at infinity), a factor
(N,) such that incident radiance / solid-angle pdf = emitted spectrum × factor,
that pdf (0 for delta lights: point, spot, directional) and a validity mask.
The emitted spectrum itself comes from ``radiance(lam, mono)`` (or, where the
integrator works in RGB, from ``rgb()``: the light's spectrum integrated
against the CIE observer on the 1 nm grid).
Lights that are not triangles but can be hit (``hittable``: spheres/disks of point and spot
lights with a radius, suns with an angle) are found by ``intersect`` on every path segment and
weighted by MIS against next-event estimation like emissive triangles; they never occlude.
Light selection (uniform, or by estimated importance) is handled by ``LightSet``.
Radiometry of the Cycles options (sphere/disk lights, sun angle, spread, spot blend) follows
Cycles' intern/cycles/kernel/light/{point,spot,distant,area}.h.

Emitters whose radiance varies over the surface (a texture × strength: ``textured``) have
``varies_over_surface``: ``sample_points`` returns the sampled points (triangle, barycentrics) with
``sample``'s tuple, ``emitted_at`` the radiance there, and ``pdf_hit`` takes the hit's triangle.

Split by kind: ``base`` (the interface), ``environment``, ``area`` (emissive meshes and lamps),
``textured`` (emissive meshes with textured radiance), ``lamps`` (point, spot, sun) and
``selection`` (LightSet).
"""

from .area import (MIN_RECT_SOLID_ANGLE, AreaEmitter, EllipseEmitter, SphericalRectangle, SpreadRectangleEmitter,
                   mesh_emitter, spread_profile)
from .base import _Light, uniform_cone
from .environment import EnvironmentEmitter, EnvironmentMapEmitter, euler_xyz_matrix
from .lamps import DirectionalEmitter, PointEmitter, SpotEmitter, point_light_sample_numpy
from .selection import LightSet
from .textured import EMISSION_SAMPLING, TexturedAreaEmitter

__all__ = ["AreaEmitter", "DirectionalEmitter", "EMISSION_SAMPLING", "EllipseEmitter", "EnvironmentEmitter",
           "EnvironmentMapEmitter", "LightSet", "MIN_RECT_SOLID_ANGLE", "PointEmitter", "SphericalRectangle",
           "SpotEmitter", "SpreadRectangleEmitter", "TexturedAreaEmitter", "euler_xyz_matrix", "mesh_emitter",
           "point_light_sample_numpy", "spread_profile", "uniform_cone", "_Light"]
