"""A clear sky's radiance and linear polarisation in closed form (the model of a ``sky`` environment).

Frame-free: every quantity is a function of world directions, so the transport can put the polarisation
into whatever Stokes frame it carries.  The world is Z-up (Blender's and Cycles' convention, which
``EnvironmentMapEmitter`` and the scene format follow); a direction ω points from the observer towards
the sky, and the light arriving from ω travels along k = −ω.

**Radiance (S0)**: Preetham, Shirley & Smits 1999, "A practical analytic model for daylight"
(SIGGRAPH '99, https://www.cs.utah.edu/~shirley/papers/sunsky/sunsky.pdf).  Each of Y, x, y is
Y_z·F(θ, γ)/F(0, θ_s) with the Perez distribution F(θ, γ) = (1 + A e^{B/cos θ})(1 + C e^{Dγ} + E cos²γ),
θ the view direction's zenith angle, γ its angle from the sun, θ_s the sun's zenith angle, the five
coefficients linear in the turbidity T (the paper's appendix), the zenith luminance
Y_z = (4.0453 T − 4.9710) tan χ − 0.2155 T + 2.4192 [kcd/m²], χ = (4/9 − T/120)(π − 2θ_s), and the zenith
chromaticities x_z, y_z = [T², T, 1] · M · [θ_s³, θ_s², θ_s, 1]ᵀ (the paper's two 3 × 4 matrices).  The
coefficients here are those of Cycles' Preetham sky (intern/cycles/scene/shader_nodes.cpp,
``sky_texture_precompute_preetham``) and appleseed's (``preethamenvironmentedf.cpp``), which agree digit
for digit.  CIE xyY → XYZ (X = xY/y, Z = (1 − x − y)Y/y) → linear Rec. 709 RGB with the engine's
``XYZ_TO_LINEAR_SRGB`` (Rec. 709 primaries, D65 white (0.3127, 0.3290); ≈ [[3.24097, −1.53738, −0.49861],
[−0.96924, 1.87597, 0.04156], [0.05563, −0.20398, 1.05697]]), negative channels clipped to 0; the result is
Y in kcd/m² × ``luminance_scale`` (default 0.06, the factor Cycles applies to its Preetham sky, so that the
two agree in brightness).  Below the horizon ``ground="horizon"`` evaluates the sky with θ clamped to
π/2 − 0.001 and the true γ (Cycles' ``sky_radiance_preetham`` rule), ``ground="black"`` returns 0.  The
sun disc itself is not part of the model.

**Polarisation** (degree P = DoLP in [0, 1] and the unit electric-field direction e ⟂ ω):

- ``model="rayleigh"``: single Rayleigh scattering by anisotropic molecules (depolarisation factor δ,
  Chandrasekhar 1950; Hansen & Travis 1974, Space Sci. Rev. 16:527, §2): P(γ) = (1−δ) sin²γ /
  (1 + δ + (1−δ) cos²γ), maximal (1−δ)/(1+δ) at γ = 90°, zero at the sun and the antisun; e ∝ s × ω,
  perpendicular to the scattering plane (the plane of the sun direction s and ω).
- ``model="berry"``: Berry, Dennis & Lee 2004, "Polarization singularities in the clear sky", New J. Phys.
  6:162 (https://doi.org/10.1088/1367-2630/6/1/162).  In the stereographic projection
  ζ = (ω_x + iω_y)/(1 + ω_z) = tan(θ/2) e^{iφ} (zenith at 0, horizon on |ζ| = 1) the sun's unstable
  index +1 singularity splits into the Babinet point (above the sun) and the Brewster point (below it),
  each ``neutral_separation_deg`` = d from the sun along the solar vertical (Berry's pair separation
  δ_B = 2d, A = tan(δ_B/4)): ζ_Ba = tan((θ_s − d)/2) e^{iφ_s}, ζ_Br = tan((θ_s + d)/2) e^{iφ_s}; the Arago
  point (above the antisun) and the fourth point (below it) are their antipodes −1/ζ*.  The complex
  polarisation field (the paper's Eq. 4.2, normalised so that max |w| = 1) is

      w(ζ) = −4 (ζ − ζ_Ba)(ζ − ζ_Br)(1 + ζ_Ba* ζ)(1 + ζ_Br* ζ) / [(1 + |ζ|²)² (1 + |ζ_Ba|²)(1 + |ζ_Br|²)],

  written with 1 + ζ_k* ζ = ζ_k* (ζ + 1/ζ_k*) so that it rotates with the sun (w → e^{2iβ} w when sun and
  sky turn by β about the zenith, as a spin-2 field must); the paper's form with the antipodal roots
  ζ + 1/ζ_k* differs from it by the constant phase Π_k ζ_k/|ζ_k| = e^{2iφ_s}, the factor OpenSky's
  ``Simu_Berry`` (Moutenet et al.) divides out.  The field's modulus is |w| = sin γ_Ba sin γ_Br (γ_k the
  angle from point k; Brewster's 1847 form), 1 on the horizon 90° in azimuth from the sun, 0 at the four
  neutral points; its phase gives the polarisation direction in the ζ-plane, χ = ½ arg w from the Re ζ
  axis towards Im ζ, carried to the sphere by the (conformal) inverse projection: e = cos χ u + sin χ v with
  u = unit(∂ω/∂Re ζ) ∝ (1 − X² + Y², −2XY, −2X) (ζ = X + iY) and v = ω × u.  With d = 0 the field is
  Rayleigh's exactly (|w| = sin²γ, e ∝ s × ω).  Berry's |w| is the *intensity* of polarisation (an
  unnormalised degree); the degree is ``berry_degree``:
  "ratio" (default): P = P_max |w| / (2 − |w|), the polarised part |w| over the Rayleigh total 2 − |w|
  (which gives exactly sin²γ/(1 + cos²γ) at d = 0; OpenSky's ``Simu_Berry``); "modulus": P = P_max |w|
  (the intensity read as the degree, as Pan et al. 2023 do).  P_max is ``max_degree``.  Berry et al.'s
  ad-hoc horizon depolarisation (§4) is not included.

Below the horizon (ω_z < 0: the ground-reflected lower hemisphere) the light is unpolarised: P = 0 (e
there is still a unit vector ⟂ ω).  Where P = 0 (neutral points, the sun, the antisun) e is a valid but
arbitrary unit vector ⟂ ω.

**Stokes**: ``stokes_linear(directions, x_axis)`` gives S1/S0, S2/S0 in the frame of the beam k = −ω with
x = ``x_axis`` (made ⟂ ω and unit) and y = k × x, the project's convention (docs/physics.md §0): with
ψ the angle of e from x towards y — counter-clockwise as seen by the observer looking at the sky, into
the beam — S1/S0 = P cos 2ψ, S2/S0 = P sin 2ψ (S2 > 0: e along (x + y)/√2), S3 = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import SceneError
from .cie import XYZ_TO_LINEAR_SRGB

#: The polarisation models of ClearSky.model.
SKY_POLARISATION_MODELS = ("rayleigh", "berry")
#: How the Berry model turns its polarisation intensity |w| into a degree (ClearSky.berry_degree).
BERRY_DEGREE_FORMS = ("ratio", "modulus")
#: What ClearSky.rgb returns below the horizon.
SKY_GROUND_MODES = ("horizon", "black")
#: Allowed turbidity: B_Y = −0.3554 T + 0.4275 < 0 needs T > 1.203 (else F grows without bound towards the
#: horizon) and Y_z > 0 at a horizon sun needs T < 11.2; [1.7, 10] is the range common implementations
#: clamp to (the paper's fits are for clear to hazy skies).
TURBIDITY_RANGE = (1.7, 10.0)
#: Allowed angular distance of each neutral point from the sun (antisun) in degrees.
NEUTRAL_SEPARATION_RANGE = (0.0, 45.0)
#: Cycles' Preetham sky scales Y_z [kcd/m²] by this factor (shader_nodes.cpp).
CYCLES_PREETHAM_SCALE = 0.06
#: θ is clamped to this below the horizon for ground="horizon" (Cycles' sky_radiance_preetham).
HORIZON_THETA = 0.5 * math.pi - 0.001

# Preetham et al. 1999, appendix: Perez coefficients (A, B, C, D, E) = slope·T + intercept, rows Y, x, y.
_PEREZ_SLOPE = np.array([[0.1787, -0.3554, -0.0227, 0.1206, -0.0670],
                         [-0.0193, -0.0665, -0.0004, -0.0641, -0.0033],
                         [-0.0167, -0.0950, -0.0079, -0.0441, -0.0109]])
_PEREZ_INTERCEPT = np.array([[-1.4630, 0.4275, 5.3251, -2.5771, 0.3703],
                             [-0.2592, 0.0008, 0.2125, -0.8989, 0.0452],
                             [-0.2608, 0.0092, 0.2102, -1.6537, 0.0529]])
# Zenith chromaticity: x_z = [T², T, 1] · M_x · [θ_s³, θ_s², θ_s, 1]ᵀ, likewise y_z.
_ZENITH_X = np.array([[0.00166, -0.00375, 0.00209, 0.0],
                      [-0.02903, 0.06377, -0.03202, 0.00394],
                      [0.11693, -0.21196, 0.06052, 0.25886]])
_ZENITH_Y = np.array([[0.00275, -0.00610, 0.00317, 0.0],
                      [-0.04214, 0.08970, -0.04153, 0.00516],
                      [0.15346, -0.26756, 0.06670, 0.26688]])


#: The maximum degree of polarisation of a clear sky against turbidity (``max_degree_for_turbidity``): measured
#: clear skies reach 0.6–0.8 at 90° from the sun, hazy ones less; a linear fit through (T 1.7, 0.80) falling
#: 0.05 per unit of T, kept within [0.3, 0.8] — an engineering choice, not a published law (docs/physics.md).
MAX_DEGREE_AT_CLEAREST, MAX_DEGREE_SLOPE, MAX_DEGREE_FLOOR = 0.80, 0.05, 0.30


def max_degree_for_turbidity(turbidity: float) -> float:
    """The Berry model's P_max for a sky of Preetham turbidity T (see MAX_DEGREE_AT_CLEAREST)."""
    p = MAX_DEGREE_AT_CLEAREST - MAX_DEGREE_SLOPE * (float(turbidity) - TURBIDITY_RANGE[0])
    return min(MAX_DEGREE_AT_CLEAREST, max(MAX_DEGREE_FLOOR, p))


def perez_coefficients(turbidity: float) -> np.ndarray:
    """The Perez coefficients (3, 5): rows Y, x, y; columns A, B, C, D, E (Preetham et al. 1999)."""
    return _PEREZ_SLOPE * float(turbidity) + _PEREZ_INTERCEPT


def perez(coeffs: np.ndarray, cos_theta, gamma) -> np.ndarray:
    """F(θ, γ) = (1 + A e^{B/cos θ})(1 + C e^{Dγ} + E cos²γ) for each row of coeffs (3, 5) -> (3, N)."""
    a, b, c, d, e = (coeffs[:, i:i + 1] for i in range(5))
    cos_theta = np.asarray(cos_theta, dtype=np.float64)[None, :]
    gamma = np.asarray(gamma, dtype=np.float64)[None, :]
    return (1.0 + a * np.exp(b / cos_theta)) * (1.0 + c * np.exp(d * gamma) + e * np.cos(gamma) ** 2)


def zenith_xyY(turbidity: float, theta_s: float) -> tuple[float, float, float]:
    """(x_z, y_z, Y_z [kcd/m²]) of the zenith for turbidity T and solar zenith angle θ_s [rad]."""
    t = float(turbidity)
    chi = (4.0 / 9.0 - t / 120.0) * (math.pi - 2.0 * theta_s)
    big_y = (4.0453 * t - 4.9710) * math.tan(chi) - 0.2155 * t + 2.4192
    tv = np.array([t * t, t, 1.0])
    th = np.array([theta_s ** 3, theta_s ** 2, theta_s, 1.0])
    return float(tv @ _ZENITH_X @ th), float(tv @ _ZENITH_Y @ th), float(big_y)


def _as_directions(directions, name="directions") -> np.ndarray:
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim == 1:
        d = d[None, :]
    if d.ndim != 2 or d.shape[1] != 3:
        raise SceneError(name, f"must be an (N, 3) array of directions, got shape {np.shape(directions)}")
    norm = np.linalg.norm(d, axis=1)
    if not (np.isfinite(norm).all() and (norm > 0).all()):
        raise SceneError(name, "must be finite, non-zero vectors")
    return d / norm[:, None]


def _cross(a, b):
    return np.cross(a, b)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _any_perpendicular(w):
    """A unit vector ⟂ each row of w (N, 3): unit(a × w) with a the axis least aligned with w."""
    a = np.zeros_like(w)
    use_x = np.abs(w[:, 0]) < 0.9
    a[use_x, 0] = 1.0
    a[~use_x, 1] = 1.0
    return _unit(_cross(a, w))


@dataclass(frozen=True)
class ClearSky:
    """A clear sky: Preetham radiance and a Rayleigh or Berry linear polarisation (see the module docstring).

    ``sun_direction``: world vector towards the sun (Z-up; normalised here; elevation 0°–90°).
    ``turbidity``: Preetham's T in TURBIDITY_RANGE (default 2.2, Blender's Sky Texture default).
    ``model``: "berry" (default) or "rayleigh".  ``delta``: the Rayleigh depolarisation factor in [0, 0.5)
    (default 0.031, air: Hansen & Travis 1974).  ``max_degree``: P_max of the Berry model in [0, 1]
    (default 0.75).  ``neutral_separation_deg``: angular distance of each Berry neutral point from the sun
    or antisun in NEUTRAL_SEPARATION_RANGE (default 15°, Berry's pair separation 30°).  ``berry_degree``:
    "ratio" or "modulus".  ``ground``: "horizon" or "black" (radiance below the horizon).
    ``luminance_scale``: RGB = linear Rec. 709 with Y = luminance in kcd/m² × this (default 0.06, Cycles').
    """

    sun_direction: tuple = (0.0, 0.0, 1.0)
    turbidity: float = 2.2
    model: str = "berry"
    delta: float = 0.031
    max_degree: float = 0.75
    neutral_separation_deg: float = 15.0
    berry_degree: str = "ratio"
    ground: str = "horizon"
    luminance_scale: float = CYCLES_PREETHAM_SCALE
    _cache: dict = field(init=False, repr=False, compare=False, hash=False, default=None)

    def __post_init__(self):
        s = np.asarray(self.sun_direction, dtype=np.float64)
        if s.shape != (3,) or not np.isfinite(s).all() or not np.linalg.norm(s) > 0:
            raise SceneError("sun_direction", f"must be a finite, non-zero 3-vector (world, Z up), got "
                                              f"{self.sun_direction!r}")
        s = s / np.linalg.norm(s)
        if s[2] < 0.0:
            raise SceneError("sun_direction", f"must point above the horizon (elevation 0° to 90°, z ≥ 0), got "
                                              f"elevation {math.degrees(math.asin(s[2])):.3g}°")
        object.__setattr__(self, "sun_direction", tuple(float(c) for c in s))
        _check_range("turbidity", self.turbidity, *TURBIDITY_RANGE)
        if self.model not in SKY_POLARISATION_MODELS:
            raise SceneError("model", f"must be one of {', '.join(SKY_POLARISATION_MODELS)}, got {self.model!r}")
        _check_range("delta", self.delta, 0.0, 0.5, upper_open=True)
        _check_range("max_degree", self.max_degree, 0.0, 1.0)
        _check_range("neutral_separation_deg", self.neutral_separation_deg, *NEUTRAL_SEPARATION_RANGE)
        if self.berry_degree not in BERRY_DEGREE_FORMS:
            raise SceneError("berry_degree", f"must be one of {', '.join(BERRY_DEGREE_FORMS)}, "
                                             f"got {self.berry_degree!r}")
        if self.ground not in SKY_GROUND_MODES:
            raise SceneError("ground", f"must be one of {', '.join(SKY_GROUND_MODES)}, got {self.ground!r}")
        _check_range("luminance_scale", self.luminance_scale, 0.0, math.inf)
        object.__setattr__(self, "_cache", self._precompute(s))

    def _precompute(self, s):
        theta_s = math.acos(min(1.0, max(-1.0, s[2])))
        phi_s = math.atan2(s[1], s[0])            # 0 for a sun at the zenith: the Berry points split along +X
        coeffs = perez_coefficients(self.turbidity)
        xz, yz, big_yz = zenith_xyY(self.turbidity, theta_s)
        norm = perez(coeffs, np.array([1.0]), np.array([theta_s]))[:, 0]     # F(0, θ_s) per row
        d = math.radians(self.neutral_separation_deg)
        rot = complex(math.cos(phi_s), math.sin(phi_s))
        z_ba = math.tan(0.5 * (theta_s - d)) * rot
        z_br = math.tan(0.5 * (theta_s + d)) * rot
        return {"theta_s": theta_s, "phi_s": phi_s, "coeffs": coeffs, "zenith": np.array([big_yz, xz, yz]),
                "norm": norm, "roots": (z_ba, z_br)}

    # --- radiance ------------------------------------------------------------------------------
    @property
    def sun(self) -> np.ndarray:
        """The unit sun direction (3,)."""
        return np.array(self.sun_direction)

    def zenith_xyY(self) -> tuple[float, float, float]:
        """(x_z, y_z, Y_z [kcd/m², unscaled]) of this sky's zenith."""
        big_y, x, y = self._cache["zenith"]
        return float(x), float(y), float(big_y)

    def xyY(self, directions) -> np.ndarray:
        """CIE (x, y, Y [kcd/m², unscaled]) (N, 3) of the sky seen in each direction (N, 3); below the
        horizon per ``ground`` ("black": Y = 0, x, y of the horizon clamp)."""
        d = _as_directions(directions)
        cos_gamma = np.clip(d @ self.sun, -1.0, 1.0)
        gamma = np.arccos(cos_gamma)
        theta = np.minimum(np.arccos(np.clip(d[:, 2], -1.0, 1.0)), HORIZON_THETA)
        f = perez(self._cache["coeffs"], np.cos(theta), gamma)                       # (3, N): Y, x, y
        vals = self._cache["zenith"][:, None] * f / self._cache["norm"][:, None]
        big_y, x, y = vals
        if self.ground == "black":
            big_y = np.where(d[:, 2] < 0.0, 0.0, big_y)
        return np.stack((x, y, big_y), axis=1)

    def xyz(self, directions) -> np.ndarray:
        """CIE XYZ (N, 3) × luminance_scale (Y in kcd/m² × scale)."""
        x, y, big_y = self.xyY(directions).T
        big_y = big_y * self.luminance_scale
        safe_y = np.where(y > 0.0, y, 1.0)
        big_x = np.where(y > 0.0, x / safe_y * big_y, 0.0)
        big_z = np.where(y > 0.0, (1.0 - x - y) / safe_y * big_y, 0.0)
        return np.stack((big_x, big_y, big_z), axis=1)

    def rgb(self, directions) -> np.ndarray:
        """Linear Rec. 709 (sRGB primaries, D65) radiance (N, 3) towards the observer from each direction
        (N, 3): XYZ_TO_LINEAR_SRGB · XYZ, negative channels clipped to 0."""
        return np.maximum(self.xyz(directions) @ np.asarray(XYZ_TO_LINEAR_SRGB).T, 0.0)

    # --- polarisation ----------------------------------------------------------------------------
    def neutral_points(self) -> dict:
        """Unit world directions of the Berry model's four zeros of polarisation: "babinet" (above the sun),
        "brewster" (below it), "arago" (above the antisun, = −brewster) and "fourth" (below the antisun,
        = −babinet); each ``neutral_separation_deg`` from the sun or antisun on the solar vertical.  (The
        Rayleigh model's zeros are the sun and the antisun.)"""
        theta_s, phi_s = self._cache["theta_s"], self._cache["phi_s"]
        d = math.radians(self.neutral_separation_deg)

        def at(psi):
            return np.array([math.sin(psi) * math.cos(phi_s), math.sin(psi) * math.sin(phi_s), math.cos(psi)])

        babinet, brewster = at(theta_s - d), at(theta_s + d)
        return {"babinet": babinet, "brewster": brewster, "arago": -brewster, "fourth": -babinet}

    def berry_field(self, directions) -> np.ndarray:
        """Berry et al.'s normalised complex polarisation field w (N,) at directions (N, 3) of the upper
        hemisphere (ω_z ≥ 0; elsewhere 0)."""
        d = _as_directions(directions)
        return self._berry_w(d, d[:, 2] >= 0.0)[0]

    def _berry_w(self, d, upper):
        zz = np.where(upper, 1.0 + d[:, 2], 1.0)
        zeta = np.where(upper, (d[:, 0] + 1j * d[:, 1]) / zz, 0.0)
        z_ba, z_br = self._cache["roots"]
        num = -4.0 * (zeta - z_ba) * (zeta - z_br) * (1.0 + np.conj(z_ba) * zeta) * (1.0 + np.conj(z_br) * zeta)
        den = (1.0 + np.abs(zeta) ** 2) ** 2 * (1.0 + abs(z_ba) ** 2) * (1.0 + abs(z_br) ** 2)
        return np.where(upper, num / den, 0.0), zeta

    def polarisation(self, directions):
        """(dolp (N,), e (N, 3)): the degree of linear polarisation in [0, 1] and the unit electric-field
        direction e ⟂ ω of the light arriving from each direction ω (N, 3); P = 0 below the horizon."""
        d = _as_directions(directions)
        upper = d[:, 2] >= 0.0
        if self.model == "rayleigh":
            dolp, e = self._rayleigh(d)
        else:
            dolp, e = self._berry(d, upper)
        return np.where(upper, dolp, 0.0), e

    def _rayleigh(self, d):
        s = self.sun
        n = _cross(np.broadcast_to(s, d.shape), d)                    # s × ω: |.|² = sin²γ
        sin2 = np.einsum("ij,ij->i", n, n)
        cos_g = np.clip(d @ s, -1.0, 1.0)
        dl = self.delta
        dolp = (1.0 - dl) * sin2 / (1.0 + dl + (1.0 - dl) * cos_g ** 2)
        ok = sin2 > 1e-24
        e = np.where(ok[:, None], n / np.sqrt(np.where(ok, sin2, 1.0))[:, None], _any_perpendicular(d))
        return np.clip(dolp, 0.0, 1.0), e

    def _berry(self, d, upper):
        w, zeta = self._berry_w(d, upper)
        m = np.minimum(np.abs(w), 1.0)
        dolp = self.max_degree * (m / (2.0 - m) if self.berry_degree == "ratio" else m)
        chi = 0.5 * np.angle(w)
        X, Y = zeta.real, zeta.imag
        u = _unit(np.stack((1.0 - X * X + Y * Y, -2.0 * X * Y, -2.0 * X), axis=1))
        v = _cross(d, u)
        e = np.cos(chi)[:, None] * u + np.sin(chi)[:, None] * v
        e = np.where(upper[:, None], e, _any_perpendicular(d))
        return np.clip(dolp, 0.0, 1.0), e

    def stokes_linear(self, directions, x_axis):
        """(S1/S0, S2/S0) (N,) each of the light from ``directions`` ω (N, 3) in the Stokes frame of the beam
        k = −ω whose x axis is ``x_axis`` (N, 3) (its part ⟂ ω, normalised) and y = k × x (physics.md §0):
        S1/S0 = P cos 2ψ, S2/S0 = P sin 2ψ, ψ the angle of e from x towards y."""
        d = _as_directions(directions)
        x = np.broadcast_to(np.asarray(x_axis, dtype=np.float64), d.shape)
        x = x - np.einsum("ij,ij->i", x, d)[:, None] * d
        nx = np.linalg.norm(x, axis=1)
        if not (np.isfinite(nx).all() and (nx > 1e-12).all()):
            raise SceneError("x_axis", "must be finite and not parallel to the direction it belongs to")
        x = x / nx[:, None]
        y = _cross(-d, x)
        dolp, e = self.polarisation(d)
        ex, ey = np.einsum("ij,ij->i", e, x), np.einsum("ij,ij->i", e, y)
        return dolp * (ex * ex - ey * ey), dolp * (2.0 * ex * ey)


def _check_range(name, value, lo, hi, upper_open=False):
    """Raise SceneError(name, …) unless value is a finite number in [lo, hi] (or [lo, hi) if upper_open)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SceneError(name, f"must be a number, got {value!r}") from None
    if not (math.isfinite(v) and v >= lo and (v < hi if upper_open else v <= hi)):
        rng = f"[{lo:g}, {hi:g})" if upper_open or hi == math.inf else f"[{lo:g}, {hi:g}]"
        raise SceneError(name, f"must be a finite number in {rng}, got {value!r}")
