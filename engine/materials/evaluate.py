"""Evaluate a material model at one oracle geometry, in a chosen Stokes basis.

Geometry as in shared/oracles/README.md: normal +z, direction to the source
ω_i = (−sinθ_i, 0, cosθ_i), viewer ω_o = (sinθ_o cosφ_o, sinθ_o sinφ_o,
cosθ_o); φ_o = 0 is the forward (specular) side.  Bases:

- ``sp`` (the oracles' ``psps``): per beam s = unit(z × k), p = k × s
  (s = (0, 1, 0) when k ∥ z);
- ``scattering`` (``plane``): s = unit(k_i × k_o) on both beams; when
  k_i ∥ k_o, s = unit(k_i × x̂) as SCATMECH does, and when k_i ∥ x̂ too
  (θ_i = θ_o = 90° in the plane of incidence), s = unit(k_i × ẑ) = −ŷ, the
  limit of both rules.

``brdf`` is the non-delta Mueller BRDF per steradian (no cosines); ``delta``
the Mueller weight of the mirror (Dirac) lobe for the mirror direction of
θ_i, or None.
"""

from __future__ import annotations

import math

import numpy as np

from .base import ShadingPoint
from ..polarisation.frames import rotate_mueller_frames, sp_basis_axis
from ..vec3 import cross, dot

BASES = ("sp", "scattering")


def cos_sin_deg(a: float):
    """cos and sin of an angle in degrees, exact at multiples of 90° (so θ = 90° is grazing, not 6e-17)."""
    if float(a) % 90.0 == 0.0:
        q = int(round(float(a) / 90.0)) % 4
        return ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))[q]
    r = math.radians(a)
    return math.cos(r), math.sin(r)


def oracle_directions(theta_i_deg: float, theta_o_deg: float, phi_o_deg: float):
    """(ω_i, ω_o) as (3,) arrays for the oracle geometry (normal +z, source in the −x half-plane)."""
    ci, si = cos_sin_deg(theta_i_deg)
    co, so = cos_sin_deg(theta_o_deg)
    cp, sp = cos_sin_deg(phi_o_deg)
    return np.array([-si, 0.0, ci]), np.array([so * cp, so * sp, co])


def _basis_axes(basis: str, k_i: np.ndarray, k_o: np.ndarray):
    if basis == "sp":
        return sp_basis_axis(k_i), sp_basis_axis(k_o)
    # Exact forward/back scatter (k_o ∥ k_i) leaves the plane undefined: SCATMECH's unit(k_i × x̂).
    # When k_i ∥ x̂ as well (θ_i = θ_o = 90°, φ_o = 0° or 180°), unit(k_i × ẑ): the normal of the
    # plane of incidence, which is what both rules give in the limit (s = −ŷ for every k_i in the
    # x–z plane), so the result is continuous there.
    for other in (k_o, np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])):
        s = cross(k_i, other)
        length = math.sqrt(float(dot(s, s)))
        if length >= 1e-12:
            return s / length, s / length
    raise ValueError(f"no scattering plane for k_i = {k_i}")    # k_i = 0: not a direction


def _in_basis(value, basis, k_i, k_o) -> np.ndarray:
    M = value.matrix()[:, :, 0, 0]
    if value.kind == "depolarising":
        return M
    x_in, x_out = _basis_axes(basis, k_i, k_o)
    return rotate_mueller_frames(M, value.x_in[:, 0], x_in, k_i, value.x_out[:, 0], x_out, k_o)


def mueller_at(model, theta_i_deg, theta_o_deg, phi_o_deg, wavelength_nm=550.0, basis="sp") -> dict:
    """{"brdf": 4×4 list, "delta": 4×4 list or None, "basis": basis} for one geometry."""
    if basis not in BASES:
        raise ValueError(f"basis must be one of {BASES}, got {basis!r}")
    wi, wo = oracle_directions(theta_i_deg, theta_o_deg, phi_o_deg)
    z = np.array([0.0, 0.0, 1.0])
    lam = np.array([[float(wavelength_nm)]])

    def point(w_out):
        col = lambda v: v.reshape(3, 1)  # noqa: E731
        return ShadingPoint(np.zeros((3, 1)), col(z), col(z), col(w_out), lam, False)

    brdf = _in_basis(model.eval(point(wo), wi.reshape(3, 1)), basis, -wi, wo)
    mirror = np.array([-wi[0], -wi[1], wi[2]])
    d = model.delta_reflection(point(mirror))
    delta = None if d is None else _in_basis(d, basis, -wi, mirror).tolist()
    return {"brdf": brdf.tolist(), "delta": delta, "basis": basis}
