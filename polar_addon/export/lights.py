"""Blender lights → engine lights with Cycles' meaning, so scenes render as in Cycles (F12).

Sources (Blender 4.x/5.0 Cycles): intern/cycles/blender/light.cpp (BlenderSync::sync_light: the
parameter mapping), intern/cycles/scene/light.cpp (Light::area, device_update_lights: eval_fac),
intern/cycles/kernel/light/point.h, spot.h, distant.h, area.h (radiometry and sampling),
kernel/light/light.h (lamps are not in the BVH: rays pass through them, they never cast shadows).

- strength S = colour · energy · 2^exposure (· temperature colour) in W (sun: W/m²);
- point and spot: radiant intensity I = S/(4π) W/sr (the spot cone only clips power); a radius
  r > 0 makes a light of radiance S/(4π²r²): a disk facing the receiver with soft falloff
  (Cycles' default), a sphere without it; soft shadows, sampled by next-event estimation;
  ``normalize`` off: I = S/π (r = 0) or radiance S/π;
- spot size is the full cone angle, spot blend is Cycles' smoothstep in cos θ from cos(size/2) to
  cos(size/2) + blend·(1 − cos(size/2));
- sun: irradiance S ⟂ the light; an angle > 0 spreads it over a disc of that angular diameter
  (radiance S/(π sin²(angle/2)), soft shadows); ``normalize`` off: radiance S;
- area (square, rectangle, disk, ellipse): radiance L = S/(π·A) (Blender ≥ 4.0; before 4.0 it was
  S/(4A)), A = size_x·size_y (·π/4 for disk and ellipse) including the object's scale; ``normalize``
  off: L = S/π; one-sided along local −Z, with Cycles' spread profile; a lamp, not an occluder
  (rays and shadows pass through it, also through its back); hidden from the camera when the
  object's camera visibility is off; portals are not lights.

Polarisation (Light ▸ Polarisation, ``light.polar``; Polar's own, Cycles has none): linear or circular,
in the light's own frame — its local X axis projected ⟂ each ray (engine.polarisation.sources).
"""

import math

import numpy as np

from ...engine.scene.description import DirectionalLight, Mesh, PointLight, SpotLight
from ...engine.polarisation.sources import parse_polarisation
from ...engine.spectral import RGBIlluminantSpectrum

DISK_SEGMENTS = 64


def _power_colour(light):
    scale = float(light.energy) * 2.0 ** float(getattr(light, "exposure", 0.0))
    colour = [float(c) for c in light.color]
    if getattr(light, "use_temperature", False):
        colour = [c * t for c, t in zip(colour, getattr(light, "temperature_color", (1, 1, 1)))]
    return scale, colour


def export_light(obj, matrix_world, warnings: list):
    """One engine light (or emissive lamp Mesh for area lights), or None for an empty light; polarised as the
    light's Polarisation panel says (reference axis: the light's local X)."""
    out = _export_light(obj, matrix_world, warnings)
    settings = getattr(obj.data, "polar", None)
    described = settings.engine_dict() if settings is not None else None
    if out is not None and described is not None:
        pol, _ = parse_polarisation(described, f"light {obj.name!r} polarisation")
        axis = np.array(matrix_world, dtype=np.float64)[:3, 0]
        axis = axis / np.linalg.norm(axis)
        if isinstance(out, Mesh):
            out.emission_polarisation, out.emission_axis = pol, axis
        else:
            out.polarisation, out.polarisation_axis = pol, axis
    return out


def _export_light(obj, matrix_world, warnings: list):
    light = obj.data
    M = np.array(matrix_world, dtype=np.float64)
    position = M[:3, 3]
    direction = -M[:3, 2] / np.linalg.norm(M[:3, 2])
    scale, colour = _power_colour(light)
    if scale <= 0 or max(colour) <= 0:
        return None
    normalise = bool(getattr(light, "normalize", True))
    camera = bool(getattr(obj, "visible_camera", True))
    if not getattr(light, "use_shadow", True):
        warnings.append(f"light {obj.name!r}: shadows cannot be switched off; rendered with shadows")
    if light.type in ("POINT", "SPOT"):
        radius = max(float(getattr(light, "shadow_soft_size", 0.0)), 0.0)
        soft = bool(getattr(light, "use_soft_falloff", True))
        if normalise:
            i_scale = scale / (4 * math.pi)
        else:   # eval_fac 1/π: intensity S/π for a point, radiance S/π (intensity S·r²) with a radius
            i_scale = scale * radius * radius if radius > 0 else scale / math.pi
        intensity = RGBIlluminantSpectrum(colour, i_scale)
        if light.type == "POINT":
            return PointLight(position, intensity, radius=radius, soft_falloff=soft, visible_camera=camera)
        return SpotLight(position, direction, intensity, cone_angle_deg=math.degrees(light.spot_size),
                         blend=float(light.spot_blend), blend_profile="cycles", radius=radius, soft_falloff=soft,
                         visible_camera=camera)
    if light.type == "SUN":
        angle = max(float(getattr(light, "angle", 0.0)), 0.0)
        irradiance = scale if normalise or angle <= 0 else scale * math.pi * math.sin(angle / 2) ** 2
        return DirectionalLight(direction, RGBIlluminantSpectrum(colour, irradiance),
                                angle_deg=math.degrees(angle), visible_camera=camera)
    if light.type == "AREA":
        cycles = getattr(light, "cycles", None)
        if cycles is not None and getattr(cycles, "is_portal", False):
            return None          # portals only guide Cycles' world sampling; they emit nothing
        return _area_light_mesh(obj, light, M, scale, colour, normalise, warnings)
    warnings.append(f"light {obj.name!r}: type {light.type} is not supported; ignored")
    return None


def _area_light_mesh(obj, light, M, scale, colour, normalise, warnings):
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
    # so scale the radiance by exact/polygon area: the emitted power stays S.
    exact = sx * sy * (math.pi / 4 if light.shape in ("DISK", "ELLIPSE") else 1.0) * \
        np.linalg.norm(M[:3, 0]) * np.linalg.norm(M[:3, 1])
    radiance = scale / (math.pi * exact) if normalise else scale / math.pi
    radiance *= exact / area
    spread = float(getattr(light, "spread", math.pi))
    if spread <= 0:
        warnings.append(f"area light {obj.name!r}: spread 0 (a collimated beam) is not supported; ignored")
        return None
    return Mesh(name=f"light:{obj.name}", vertices=world, faces=faces, materials=["__polar_black__"],
                material_ids=np.zeros(len(faces), np.int32), emission=RGBIlluminantSpectrum(colour, radiance),
                two_sided=False, occluder=False, visible_camera=bool(getattr(obj, "visible_camera", True)),
                spread_deg=min(math.degrees(spread), 180.0))
