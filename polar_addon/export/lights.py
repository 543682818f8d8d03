"""Blender lights → engine lights with Cycles-compatible units (so scenes look as bright as in Cycles).

From Cycles (intern/cycles/blender/light.cpp, kernel/light/area.h):
- power P = colour · energy · 2^exposure (W);
- point and spot: radiant intensity I = P / (4π) W/sr (the spot cone clips, it does not
  concentrate power); a radius > 0 (soft sphere light) is rendered as a point;
- sun: ``energy`` is the irradiance in W/m² perpendicular to the light; the angular diameter is
  ignored (a delta light);
- area: radiance L = P / (4·A) (Cycles' convention, not the physical P/(πA)); A = size_x·size_y
  (·π/4 for disk and ellipse), including the object's scale; one-sided, emitting along local −Z.
"""

import math

import numpy as np

from ...engine.scene.description import DirectionalLight, Mesh, PointLight, SpotLight
from ...engine.spectral import RGBIlluminantSpectrum

DISK_SEGMENTS = 64


def _power_colour(light):
    scale = float(light.energy) * 2.0 ** float(getattr(light, "exposure", 0.0))
    colour = [float(c) for c in light.color]
    if getattr(light, "use_temperature", False):
        colour = [c * t for c, t in zip(colour, getattr(light, "temperature_color", (1, 1, 1)))]
    return scale, colour


def export_light(obj, matrix_world, warnings: list):
    """One engine light (or emissive Mesh for area lights), or None for an empty light."""
    light = obj.data
    M = np.array(matrix_world, dtype=np.float64)
    position = M[:3, 3]
    direction = -M[:3, 2] / np.linalg.norm(M[:3, 2])
    scale, colour = _power_colour(light)
    if scale <= 0 or max(colour) <= 0:
        return None
    if light.type in ("POINT", "SPOT"):
        if getattr(light, "shadow_soft_size", 0.0) > 0:
            pass  # soft sphere lights render as points (documented)
        intensity = RGBIlluminantSpectrum(colour, scale / (4 * math.pi))
        if light.type == "POINT":
            return PointLight(position, intensity)
        return SpotLight(position, direction, intensity, cone_angle_deg=math.degrees(light.spot_size),
                         blend=float(light.spot_blend))
    if light.type == "SUN":
        return DirectionalLight(direction, RGBIlluminantSpectrum(colour, scale))
    if light.type == "AREA":
        return _area_light_mesh(obj, light, M, scale, colour, warnings)
    warnings.append(f"light {obj.name!r}: type {light.type} is not supported; ignored")
    return None


def _area_light_mesh(obj, light, M, scale, colour, warnings):
    sx = float(light.size)
    sy = float(light.size_y) if light.shape in ("RECTANGLE", "ELLIPSE") else sx
    if light.shape in ("DISK", "ELLIPSE"):
        t = np.linspace(0, 2 * np.pi, DISK_SEGMENTS, endpoint=False)
        ring = np.stack((0.5 * sx * np.cos(t), 0.5 * sy * np.sin(t), np.zeros_like(t)), axis=1)
        local = np.vstack(([0.0, 0.0, 0.0], ring))
        # Fan triangles wound so that the front (geometric normal) is local −Z.
        faces = np.array([[0, 1 + (i + 1) % DISK_SEGMENTS, 1 + i] for i in range(DISK_SEGMENTS)])
    else:
        local = np.array([[-sx / 2, -sy / 2, 0], [-sx / 2, sy / 2, 0], [sx / 2, sy / 2, 0], [sx / 2, -sy / 2, 0]])
        faces = np.array([[0, 1, 2], [0, 2, 3]])
    world = local @ M[:3, :3].T + M[:3, 3]
    v0, v1, v2 = (world[faces[:, i]] for i in range(3))
    area = 0.5 * np.linalg.norm(np.cross(v1 - v0, v2 - v0), axis=1).sum()
    if area <= 0:
        warnings.append(f"area light {obj.name!r} has zero area; ignored")
        return None
    # Cycles uses the analytic shape area (π/4·sx·sy for disks); our polygon is slightly smaller,
    # so use the exact area for the radiance and keep the emitted power.
    exact = sx * sy * (math.pi / 4 if light.shape in ("DISK", "ELLIPSE") else 1.0) * \
        np.linalg.norm(M[:3, 0]) * np.linalg.norm(M[:3, 1])
    normalise = getattr(light, "normalize", True)
    radiance = scale / (4 * exact) if normalise else scale / 4
    radiance *= exact / area if normalise else 1.0
    if getattr(light, "spread", math.pi) < math.pi - 1e-6:
        warnings.append(f"area light {obj.name!r}: spread < 180° is not supported; rendered as Lambertian")
    return Mesh(name=f"light:{obj.name}", vertices=world, faces=faces, materials=["__polar_black__"],
                material_ids=np.zeros(len(faces), np.int32), emission=RGBIlluminantSpectrum(colour, radiance))
