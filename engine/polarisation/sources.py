"""The polarisation of emitted light: a Stokes vector per source in the emitter's own frame.

A source's light leaving along the unit direction k is described in the frame whose x axis is the
emitter's reference axis a projected perpendicular to k, x_e = unit(a − (a·k) k), and y_e = k × x_e
(docs/physics.md §0: (x, y, k) right-handed).  The reference axis is the light's local X for area,
sun, point and spot lights and the surface tangent (the UV map's) for a mesh emitter, so a rotated
lamp or screen rotates its polarisation.  Where a is parallel to k (a point or spot light seen along
its own X axis) the projection of the local Y axis is taken instead; a point source's linear
polarisation cannot be continuous over the whole sphere (a hairy-ball theorem), and this keeps the
discontinuity at the two directions ±X, where the pattern of a real polarised lamp would have to be
singular too.  The sun is seen along one direction only, so its frame is always defined.

Normalised Stokes vectors in that frame (S0 = 1):

* linear, degree P, angle ψ (of the electric field from x_e towards y_e): (1, P cos 2ψ, P sin 2ψ, 0);
* circular, degree P: (1, 0, 0, ±P), + for right-handed (S3 > 0: optics convention, clockwise to a
  receiver looking into the beam), − for left-handed.

Unpolarised sources have ``SourcePolarisation.none()``; the transport keeps its scalar path for them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..vec3 import dot

KINDS = ("none", "linear", "circular")
HANDEDNESS = ("right", "left")
#: |a × k| below this counts as "the reference axis is along the ray" (the other axis is taken).
_PARALLEL = 1e-9

#: The preset of Blender's Light and emission panels for a liquid-crystal display: fully linearly
#: polarised at 45° from the panel's horizontal axis.  Twisted-nematic panels (most office and laptop
#: screens) have their front polariser at 45° so that viewers in polarised sunglasses (transmission axis
#: vertical) see them at half brightness in both orientations; turning the screen or the head by a
#: further 45° blacks it out.  (IPS and VA panels vary: 0° or 90° is common; set the angle by hand.)
LCD_ANGLE_DEG = 45.0


@dataclass(frozen=True)
class SourcePolarisation:
    """Polarisation of a source: ``kind`` "none" | "linear" | "circular", ``degree`` in [0, 1],
    ``angle_deg`` (linear: of E from the frame's x axis towards y, any real number, period 180°),
    ``handedness`` "right" | "left" (circular)."""

    kind: str = "none"
    degree: float = 1.0
    angle_deg: float = 0.0
    handedness: str = "right"

    @staticmethod
    def none() -> SourcePolarisation:
        return SourcePolarisation()

    @property
    def polarised(self) -> bool:
        return self.kind != "none" and self.degree > 0.0

    @property
    def circular(self) -> bool:
        return self.polarised and self.kind == "circular"

    @property
    def transport_need(self) -> str:
        """The smallest exact transport for this source: "off", "linear" or "full"."""
        return "off" if not self.polarised else ("full" if self.kind == "circular" else "linear")

    def stokes(self) -> np.ndarray:
        """The normalised Stokes vector (4,) in the emitter frame (x_e, y_e, k)."""
        if not self.polarised:
            return np.array([1.0, 0.0, 0.0, 0.0])
        if self.kind == "circular":
            return np.array([1.0, 0.0, 0.0, self.degree if self.handedness == "right" else -self.degree])
        psi = math.radians(self.angle_deg)
        return np.array([1.0, self.degree * math.cos(2 * psi), self.degree * math.sin(2 * psi), 0.0])

    def describe(self) -> dict:
        if not self.polarised:
            return {"type": "none"}
        if self.kind == "circular":
            return {"type": "circular", "degree": self.degree, "handedness": self.handedness}
        return {"type": "linear", "degree": self.degree, "angle": self.angle_deg}


@dataclass(frozen=True)
class DirectionalPolarisation:
    """The polarisation of an environment that varies with direction (a polarised sky, an environment map
    with Stokes channels): ``transport_need`` "linear" or "full", ``source`` what it comes from (reports)."""

    transport_need: str
    source: str

    @property
    def polarised(self) -> bool:
        return self.transport_need != "off"


def parse_polarisation(d, field: str) -> tuple[SourcePolarisation, np.ndarray | None]:
    """(SourcePolarisation, reference axis (3,) or None) from a scene file's "polarisation" object (None:
    unpolarised), e.g. {"type": "linear", "degree": 1, "angle": 45, "axis": [0, 0, 1]} or
    {"type": "circular", "handedness": "left"}; "axis" is the emitter's reference axis in world space."""
    if d is None:
        return SourcePolarisation.none(), None
    if not isinstance(d, dict):
        raise SceneError(field, 'must be an object such as {"type": "linear", "degree": 1, "angle": 45}')
    allowed = {"type", "degree", "angle", "handedness", "axis"}
    extra = sorted(set(d) - allowed)
    if extra:
        raise SceneError(f"{field}.{extra[0]}", f"unknown key; allowed: {', '.join(sorted(allowed))}")
    kind = d.get("type", "linear")
    if kind not in KINDS:
        raise SceneError(f"{field}.type", f"must be one of {', '.join(KINDS)}, got {kind!r}")
    degree = _number(d.get("degree", 1.0), f"{field}.degree")
    if not 0.0 <= degree <= 1.0:
        raise SceneError(f"{field}.degree", f"must be in [0, 1], got {degree!r}")
    angle = _number(d.get("angle", 0.0), f"{field}.angle")
    if abs(angle) > 1e6:
        raise SceneError(f"{field}.angle", f"must be a finite number of degrees in [-1e6, 1e6], got {angle!r}")
    handedness = d.get("handedness", "right")
    if handedness not in HANDEDNESS:
        raise SceneError(f"{field}.handedness", f"must be 'right' or 'left', got {handedness!r}")
    if kind != "linear" and "angle" in d:
        raise SceneError(f"{field}.angle", "applies to linear polarisation only")
    if kind != "circular" and "handedness" in d:
        raise SceneError(f"{field}.handedness", "applies to circular polarisation only")
    axis = None
    if "axis" in d:
        a = d["axis"]
        if not (isinstance(a, list) and len(a) == 3 and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                          and math.isfinite(v) for v in a)):
            raise SceneError(f"{field}.axis", f"must be a vector [x, y, z] of three finite numbers, got {a!r}")
        axis = np.array(a, np.float64)
        if not np.linalg.norm(axis) > 0:
            raise SceneError(f"{field}.axis", "must not be the zero vector")
        axis /= np.linalg.norm(axis)
    return SourcePolarisation(kind, degree, angle, handedness), axis


def _number(v, field) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SceneError(field, f"must be a finite number, got {v!r}")
    return float(v)


def emitter_frame(axis: np.ndarray, other: np.ndarray, k: np.ndarray) -> np.ndarray:
    """x_e (3, n): the reference ``axis`` (3,) or (3, n) projected ⟂ the directions of travel k (3, n),
    normalised; where the axis is along k, ``other`` (the emitter's second axis) projected instead."""
    axis = np.broadcast_to(np.asarray(axis, np.float64).reshape(3, -1), k.shape)
    other = np.broadcast_to(np.asarray(other, np.float64).reshape(3, -1), k.shape)
    x = axis - dot(axis, k)[None, :] * k
    norm = np.sqrt(dot(x, x))
    bad = norm < _PARALLEL
    if bad.any():
        o = other[:, bad] - dot(other[:, bad], k[:, bad])[None, :] * k[:, bad]
        x[:, bad] = o
        norm[bad] = np.sqrt(dot(o, o))
    return x / np.maximum(norm, 1e-300)[None, :]


def reference_axes(axis) -> tuple[np.ndarray, np.ndarray]:
    """(axis, other) (3,) each: the emitter's reference axis (None: world +X) and the second axis that
    ``emitter_frame`` takes where the first is along the ray — unit(axis × Z), or unit(axis × X) for an
    axis along Z (any axis ⟂ the first serves: along the first axis every frame is one rotation about it)."""
    a = np.array([1.0, 0.0, 0.0]) if axis is None else np.asarray(axis, np.float64).reshape(3)
    a = a / np.linalg.norm(a)
    other = np.cross(a, [0.0, 0.0, 1.0])
    if np.linalg.norm(other) < 1e-6:
        other = np.cross(a, [1.0, 0.0, 0.0])
    return a, other / np.linalg.norm(other)


def uv_tangent(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None) -> np.ndarray | None:
    """The mean direction of increasing U over a mesh (3,) (area-weighted ∂P/∂u of its triangles), or None
    without UVs or where it vanishes: a mesh emitter's reference axis, so that a rotated screen rotates its
    polarisation.  ``vertices`` (V, 3) world, ``faces`` (F, 3), ``uv`` (V, 2)."""
    if uv is None or len(faces) == 0:
        return None
    v, f, t = np.asarray(vertices, np.float64), np.asarray(faces), np.asarray(uv, np.float64)
    e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    d1, d2 = t[f[:, 1]] - t[f[:, 0]], t[f[:, 2]] - t[f[:, 0]]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    # ∂P/∂u = (e1·dv2 − e2·dv1)/det; weighting each triangle by |det| (its UV area) sums sign(det)·(…)
    tangent = (np.sign(det)[:, None] * (e1 * d2[:, 1:2] - e2 * d1[:, 1:2])).sum(axis=0)
    norm = np.linalg.norm(tangent)
    return tangent / norm if norm > 1e-12 * max(float(np.abs(v).max(initial=0.0)), 1.0) ** 2 else None

