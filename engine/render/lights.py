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
Lights that are not triangles but can be hit (``hittable``: spheres/disks of point and spot
lights with a radius, suns with an angle) are found by ``intersect`` on every path segment and
weighted by MIS against next-event estimation like emissive triangles; they never occlude.
Light selection (uniform, or by estimated importance) is handled by ``LightSet``.
Radiometry of the Cycles options (sphere/disk lights, sun angle, spread, spot blend) follows
Cycles' intern/cycles/kernel/light/{point,spot,distant,area}.h.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SceneError
from ..kernels import twin
from ..kernels.geometry import area_light_sample
from ..kernels.lamp_sampling import bilinear_warp_pdf, bilinear_warp_sample, ellipse_lamp_pdf, ellipse_lamp_sample
from ..kernels.light_sampling import (GLOBAL_SHARE, MIN_RECT_SOLID_ANGLE, SELECT_AREA, SELECT_CONSTANT, SELECT_DISTANT,
                                      SELECT_POINT, SELECTION_PARAMS, area_importance, choose_light,
                                      distant_importance, lamp_hits, point_importance, point_light_sample_numba,
                                      rect_angles, rect_light_sample, rect_local, rect_sample, selection_probabilities,
                                      spot_falloff)
from ..materials.sampling import local_to_world, uniform_sphere
from ..spectral import GRID_NM, luminance, spectrum_to_linear_srgb
from ..textures.image import srgb_to_linear
from ..scene.description import (ENVMAP_GRIDS, ENVMAP_INTERPOLATION_SPACES, DirectionalLight, EnvironmentLight,
                                 PointLight, SpotLight)
from ..vec3 import dot, normalize


def uniform_cone(u1, u2, one_minus_cos_max, axis):
    """Directions uniform in the cone of 1 − cosθ ≤ ``one_minus_cos_max`` around the unit
    ``axis`` (3,) or (3, N); pdf = 1/(2π·one_minus_cos_max)."""
    one_minus_cos = u1 * one_minus_cos_max
    cos_t = 1.0 - one_minus_cos
    sin_t = np.sqrt(np.maximum(one_minus_cos * (2.0 - one_minus_cos), 0.0))
    phi = 2.0 * math.pi * u2
    local = np.stack((sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t))
    axis = np.broadcast_to(axis.reshape(3, -1), local.shape)
    return local_to_world(local, axis), cos_t


class _Light:
    is_delta = False
    at_infinity = False
    hittable = False      # an analytic emitter that rays find through ``intersect`` (not in the BVH)
    blocks_own_shadow_rays = False    # an opaque emitter whose geometry can stop its own shadow rays
    hit_pdf_needs_origin = False      # ``pdf_hit`` needs the segment's origin (solid-angle sampled lamps)
    hit_pdf_needs_direction = False   # ... and where on the lamp the ray arrives (warp-sampled lamps)

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

    def power(self, scene_radius=1.0):
        # a sphere of radius R under uniform radiance L receives π·L·4πR²
        return float(luminance(self.rgb())) * 4.0 * math.pi ** 2 * scene_radius ** 2

    #: Share of its irradiance π·L taken as the selection importance (and LightSet.mix_prob leaves a
    #: constant sky out of the global power share).  Of all lights a constant sky needs next-event
    #: estimation least: cosine-sampled BSDF rays find it, with MIS weights → 1.  But every light
    #: sample it takes beside a lamp is a sample without the lamp: area_rectangle_back's lamp-lit
    #: floor under a 0.05 grey world had 9.5× Cycles' variance at 64 stratified spp (≈ 5 % of its
    #: samples went to the sky), 1.4× without the world, 2.1× now.  Alone, the sky is still picked
    #: with probability 1.
    SELECTION_SHARE = 0.1

    def importance(self, p, n=None):
        return np.full(p.shape[1], self.selection_record()[1][0])

    def selection_record(self):
        """(kind, parameters) of ``importance`` for the compiled light selection (engine.kernels.light_sampling)."""
        return SELECT_CONSTANT, [math.pi * float(luminance(self.rgb())) * self.SELECTION_SHARE]


def euler_xyz_matrix(angles_rad) -> np.ndarray:
    """Rotation matrix (3, 3) of Euler angles (x, y, z) in radians, order XYZ as Blender's Euler
    and Mapping node: R = Rz(z)·Ry(y)·Rx(x) (x applied first)."""
    cx, cy, cz = (math.cos(a) for a in angles_rad)
    sx, sy, sz = (math.sin(a) for a in angles_rad)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return rz @ ry @ rx


def _map_rotation(rotation_deg):
    """(angle about +Z in radians, None) for a turn about +Z only — a scalar or [0, 0, z], kept on
    the scalar path so such maps render bit-identically — else (0, R (3, 3)) from Euler XYZ degrees."""
    angles = np.atleast_1d(np.asarray(rotation_deg, dtype=np.float64))
    if angles.shape == (1,):
        return math.radians(float(angles[0])), None
    if angles.shape != (3,) or not np.isfinite(angles).all():
        raise SceneError("rotation_deg", f"must be a number or Euler angles [x, y, z] in degrees, got {rotation_deg!r}")
    if angles[0] == 0.0 and angles[1] == 0.0:
        return math.radians(float(angles[2])), None
    return 0.0, euler_xyz_matrix(np.radians(angles))


class EnvironmentMapEmitter(_Light):
    """Radiance from an equirectangular image (linear sRGB texels, row 0 = zenith), × strength.

    Direction convention (the peer format's, = Cycles' equirectangular mapping): world +Z up; a
    ray escaping along d sees u = (½ − atan2(d_y, d_x)/2π) mod 1, v = acos(d_z)/π, after turning
    d by −``rotation_deg`` about +Z (so the map turns by +rotation_deg, counter-clockwise seen
    from above). ``rotation_deg`` may also be Euler angles [x, y, z] in degrees, order XYZ as
    Blender's (R = Rz·Ry·Rx): the map is turned by R, so d is looked up at Rᵀd; [0, 0, z] is the
    scalar z. Radiance is the bilinear interpolation on the texel grid ``grid`` (ENVMAP_GRIDS),
    periodic in u; a texel (1, 1, 1) is the unit white (as ``EnvironmentEmitter`` of radiance 1).

    ``interpolation_space`` "srgb": the interpolation runs on the sRGB-encoded texels and its result
    is decoded, L = dec(Σ wᵢ·enc(texelᵢ)) (IEC 61966-2-1 transfer function, its power law continued
    above 1; negative → 0), as Cycles does for every image in the sRGB colour space, float EXRs
    included (scene/image.cpp ``compress_as_srgb``: the kernel decodes after the lookup).  Texel
    centres keep their values; between a bright texel and dark ones the radiance falls off
    ~t^2.4 instead of t, so a sub-texel sun carries ~20 % less ∫L dω than with "linear".

    Sampling: the bilinear pieces (cells between neighbouring texel columns and rows) are chosen
    in proportion to their mean texel luminance × solid angle (luminance × sinθ integrated), and
    directions are uniform in solid angle inside the cell, so the pdf is constant per cell (for
    "srgb" the corner mean bounds the piece's mean from above: still a pdf that covers the map).
    ``importance=False`` samples cells by solid angle alone (uniform on the sphere).
    """

    at_infinity = True
    varies_with_direction = True

    def __init__(self, image, strength=1.0, rotation_deg=0.0, grid="cycles", importance=True,
                 interpolation_space="linear"):
        super().__init__(None)
        if grid not in ENVMAP_GRIDS:
            raise SceneError("grid", f"must be one of {', '.join(ENVMAP_GRIDS)}, got {grid!r}")
        if interpolation_space not in ENVMAP_INTERPOLATION_SPACES:
            raise SceneError("interpolation_space", f"must be one of {', '.join(ENVMAP_INTERPOLATION_SPACES)}, "
                                                    f"got {interpolation_space!r}")
        img = np.asarray(image)
        # float32 maps stay float32 (half the memory of large HDRIs; the arithmetic is float64)
        img = img if img.dtype == np.float32 else img.astype(np.float64)
        if img.ndim != 3 or img.shape[2] != 3 or img.shape[0] < 2 or img.shape[1] < 1:
            raise SceneError("image", f"must be an RGB image of at least 2 rows, got shape {img.shape}")
        self.texels = img
        # the values the bilinear interpolation runs on
        self._interpolated = img if interpolation_space == "linear" else _srgb_encode(np.maximum(img, 0.0))
        self._decode = interpolation_space == "srgb"
        self.strength = float(strength)
        self.grid = grid
        H, W = img.shape[:2]
        self.rotation, self.turn = _map_rotation(rotation_deg)
        # v of the rows bounding the bilinear pieces, and the texel row found there
        if grid == "mitsuba":
            self.v_knots = np.arange(H) / (H - 1)
            knot_rows = self.texels
        else:
            self.v_knots = np.concatenate(([0.0], (np.arange(H) + 0.5) / H, [1.0]))
            knot_rows = np.concatenate((self.texels[:1], self.texels, self.texels[-1:]))
        lum = self.strength * luminance(knot_rows)                     # (K, W)
        right = np.roll(lum, -1, axis=1)
        cell_lum = 0.25 * (lum[:-1] + lum[1:] + right[:-1] + right[1:])   # exact mean of the bilinear piece
        self.cos_knots = np.cos(math.pi * self.v_knots)
        omega = (2.0 * math.pi / W) * (self.cos_knots[:-1] - self.cos_knots[1:])[:, None] * np.ones((1, W))
        mass = np.maximum(cell_lum, 0.0) * omega if importance else omega
        if not mass.sum() > 0:
            mass = omega                                               # a black map: sample by solid angle
        prob = mass / mass.sum()
        self.cell_pdf = np.where(omega > 0, prob / np.where(omega > 0, omega, 1.0), 0.0)   # per sr
        self.cdf = np.cumsum(prob.ravel())
        self.cdf[-1] = 1.0
        # mean radiance over the sphere (light selection): ∫ L dω / 4π
        rows = knot_rows.astype(np.float64)
        rows_right = np.roll(rows, -1, axis=1)
        piece_mean = 0.25 * (rows[:-1] + rows[1:] + rows_right[:-1] + rows_right[1:])
        self._rgb = self.strength * np.einsum("kwc,kw->c", piece_mean, omega) / (4.0 * math.pi)

    def _to_map(self, d):
        """Directions (3, N) turned by −rotation about +Z (world → map frame)."""
        if self.turn is not None:
            return self.turn.T @ d
        if self.rotation == 0.0:
            return d
        c, s = math.cos(self.rotation), math.sin(self.rotation)
        return np.stack((c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]))

    def _uv(self, d):
        dm = self._to_map(d)
        norm = np.sqrt(dot(dm, dm))
        u = np.mod(0.5 - np.arctan2(dm[1], dm[0]) / (2.0 * math.pi), 1.0)
        v = np.arccos(np.clip(dm[2] / np.where(norm > 0, norm, 1.0), -1.0, 1.0)) / math.pi
        return u, v

    def lookup_rgb(self, d):
        """Linear sRGB radiance (N, 3) × strength in the world directions d (3, N)."""
        u, v = self._uv(d)
        H, W = self.texels.shape[:2]
        x = np.mod(u * W - 0.5, W)
        i0 = np.minimum(np.floor(x), W - 1).astype(np.int64)
        fx = (x - i0)[:, None]
        if self.grid == "mitsuba":
            y = v * (H - 1)
            j0 = np.minimum(np.floor(y), H - 2).astype(np.int64)
            fy = (y - j0)[:, None]
        else:
            y = v * H - 0.5
            j0 = np.clip(np.floor(y), 0, H - 2).astype(np.int64)
            fy = np.clip(y - j0, 0.0, 1.0)[:, None]
        i1 = (i0 + 1) % W
        img = self._interpolated
        top = img[j0, i0] * (1 - fx) + img[j0, i1] * fx
        bot = img[j0 + 1, i0] * (1 - fx) + img[j0 + 1, i1] * fx
        rgb = top * (1 - fy) + bot * fy
        return (np.maximum(srgb_to_linear(rgb), 0.0) if self._decode else rgb) * self.strength

    def emitted(self, d, lookup, rgb_mode: bool, mono: bool):
        """Radiance towards −d for rays travelling along d (3, n): RGB (3, n), mono luminance (1, n)
        or the illuminant spectrum D65n · Σ rgb_c B_c at ``lookup``'s wavelengths (L, n)."""
        rgb = self.lookup_rgb(d).T
        if rgb_mode:
            return rgb
        if mono:
            return np.broadcast_to(luminance(rgb.T)[None, :], lookup.lam.shape).copy()
        basis = lookup.basis
        return lookup.d65 * (rgb[0] * basis[0] + rgb[1] * basis[1] + rgb[2] * basis[2])

    def _cell(self, u, v):
        H, W = self.texels.shape[:2]
        i = np.mod(np.floor(u * W - 0.5).astype(np.int64), W)
        if self.grid == "mitsuba":
            j = np.minimum(np.floor(v * (H - 1)), H - 2).astype(np.int64)
        else:
            j = np.clip(np.floor(v * H + 0.5), 0, H).astype(np.int64)
        return j, i

    def sample(self, p, u):
        W = self.texels.shape[1]
        k = np.minimum(np.searchsorted(self.cdf, u[0], side="right"), self.cdf.size - 1)
        j, i = np.divmod(k, W)
        cos_t = self.cos_knots[j] + u[1] * (self.cos_knots[j + 1] - self.cos_knots[j])
        sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
        phi = math.pi * (1.0 - 2.0 * ((i + 0.5 + u[2]) / W))
        dm = np.stack((sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t))
        if self.turn is not None:
            wi = self.turn @ dm
        else:
            c, s = math.cos(self.rotation), math.sin(self.rotation)
            wi = np.stack((c * dm[0] - s * dm[1], s * dm[0] + c * dm[1], dm[2])) if self.rotation else dm
        pdf = self.cell_pdf[j, i]
        valid = pdf > 0
        n = p.shape[1]
        return wi, np.full(n, np.inf), np.where(valid, 1.0 / np.where(valid, pdf, 1.0), 0.0), pdf, valid

    def pdf(self, d):
        """Solid-angle pdf (N,) of ``sample`` producing the world directions d (3, N)."""
        return self.cell_pdf[self._cell(*self._uv(d))]

    def rgb(self):
        """Mean linear sRGB radiance over the sphere (for light selection)."""
        return self._rgb

    def power(self, scene_radius=1.0):
        return float(luminance(self._rgb)) * 4.0 * math.pi ** 2 * scene_radius ** 2

    def importance(self, p, n=None):
        return np.full(p.shape[1], math.pi * float(luminance(self._rgb)))

    def selection_record(self):
        return SELECT_CONSTANT, [math.pi * float(luminance(self._rgb))]


def _srgb_encode(linear):
    """sRGB transfer function (IEC 61966-2-1), the power law continued above 1; float64."""
    linear = np.asarray(linear, np.float64)
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * np.maximum(linear, 0.0031308) ** (1 / 2.4) - 0.055)


def spread_profile(spread_rad: float):
    """Cycles' area-light spread f(cosθ) (kernel/light/area.h: area_light_spread_attenuation),
    normalised so that ∫ f cosθ dω = π; None for spread ≥ 180° (f = 1, Lambertian)."""
    half = 0.5 * spread_rad
    if half >= 0.5 * math.pi - 1e-9:
        return None
    tan_half = math.tan(half)
    norm = 1.0 / (tan_half - half) if half > 0.05 else 3.0 / half ** 3

    def f(cos_t):
        c = np.clip(cos_t, 1e-12, 1.0)
        tan_t = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
        return np.where(cos_t > 0, np.maximum(0.0, (tan_half - tan_t) * norm), 0.0)
    return f


class SphericalRectangle:
    """A planar rectangle (corner, unit edge axes x ⟂ y, edge lengths) sampled uniformly in the
    solid angle it subtends (Ureña, Conty & Kettunen 2013, "An Area-Preserving Parametrization
    for Spherical Rectangles"; Cycles' kernel/light/area.h samples rectangle lamps this way).
    Distances in scene units, solid angles in sr; the arithmetic is engine.kernels.light_sampling's."""

    def __init__(self, corner, ex, ey):
        self.corner = np.asarray(corner, np.float64)
        self.len_x = float(np.linalg.norm(ex))
        self.len_y = float(np.linalg.norm(ey))
        self.x = np.asarray(ex, np.float64) / self.len_x
        self.y = np.asarray(ey, np.float64) / self.len_y
        self.z = np.cross(self.x, self.y)

    @classmethod
    def from_triangles(cls, corners, tol=1e-9):
        """The rectangle covered exactly by two triangles (2, 3, 3) (world coordinates), or None
        when they do not form one (e.g. a sheared parallelogram or a disk fan)."""
        pts = corners.reshape(-1, 3)
        unique = []
        for q in pts:
            if not any(np.allclose(q, v, rtol=0.0, atol=tol * (1.0 + np.abs(q).max())) for v in unique):
                unique.append(q)
        if len(corners) != 2 or len(unique) != 4:
            return None
        a = unique[0]
        # the corner opposite a is the farthest one; the other two span the edges from a
        rest = sorted(unique[1:], key=lambda q: float(np.dot(q - a, q - a)))
        ex, ey, diag = rest[0] - a, rest[1] - a, rest[2] - a
        lx, ly = np.linalg.norm(ex), np.linalg.norm(ey)
        if lx <= 0 or ly <= 0:
            return None
        scale = max(lx, ly)
        tri_area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
        if (abs(np.dot(ex, ey)) > tol * lx * ly or np.abs(diag - ex - ey).max() > tol * scale
                or abs(tri_area.sum() - lx * ly) > 1e-7 * lx * ly):
            return None
        return cls(a, ex, ey)

    def _local(self, p):
        """Rectangle coordinates relative to points p (3, N) (engine.kernels.light_sampling.rect_local)."""
        return rect_local(p, self.corner, self.x, self.y, self.z, self.len_x, self.len_y)

    def solid_angle(self, p):
        """Solid angle (N,) that the rectangle subtends at points p (3, N); 0 in its plane."""
        x0, x1, y0, y1, z0, _ = self._local(p)
        with np.errstate(invalid="ignore", divide="ignore"):
            S = rect_angles(x0, x1, y0, y1, z0)[3]
        return np.where(z0 < 0, np.nan_to_num(S), 0.0)

    def sample(self, p, u1, u2):
        """Points (3, N) on the rectangle, uniform in solid angle seen from p, and that solid angle (N,)."""
        return rect_sample(p, u1, u2, self.corner, self.x, self.y, self.z, self.len_x, self.len_y)


class AreaEmitter(_Light):
    """A Lambertian emitter made of mesh triangles: one-sided (emits along their front normal)
    or two-sided (both faces, same radiance), optionally with Cycles' spread profile.

    Points are sampled uniformly by area, solid-angle pdf dist² / (|cosθ_light| · A_total); an
    emitter that is one rectangle (two triangles: Blender's square/rectangle lamps) is sampled
    uniformly in the solid angle Ω it subtends, pdf 1/Ω (``SphericalRectangle``), except where
    Ω ≤ ``MIN_RECT_SOLID_ANGLE`` (then by area). ``pdf_hit`` evaluates the same choice from the
    ray's origin, so next-event estimation and MIS agree.
    """

    def __init__(self, spectrum, tris: np.ndarray, compiled, two_sided=False, spread_deg=180.0):
        super().__init__(spectrum)
        self.tris = tris
        areas = compiled.tri_area[tris]
        self.total_area = float(areas.sum())
        self.cdf = np.cumsum(areas) / self.total_area
        self.compiled = compiled
        self.two_sided = bool(two_sided)
        self.profile = spread_profile(math.radians(spread_deg))
        # Opaque emitters can stop their own grazing shadow rays (see CompiledScene.unblock_own_hits).
        # The correction is applied to two-sided (Blender) emitters only: for the scene format's
        # one-sided emitters it would change peer renders (cornell_lambert: 2 of 25,600 pixels at 2 spp).
        self.blocks_own_shadow_rays = self.two_sided and bool(compiled.tri_occluder[tris].all())
        # Solid-angle sampling needs a rectangle; the integrator's own-shadow correction recovers
        # cosθ from the area pdf, so emitters that block their own shadow rays keep area sampling.
        self.rect = None
        if len(tris) == 2 and not self.blocks_own_shadow_rays:
            self.rect = SphericalRectangle.from_triangles(compiled.vertices[compiled.faces[tris]])
            if self.rect is not None:
                self.normal = compiled.tri_normal[tris[0]].astype(np.float64)

    def sample(self, p, u):
        # u has 3 rows: triangle choice, then the point within it.
        if self.rect is None:
            return self._sample_area(p, u)
        r = self.rect
        wi, dist, scale, pdf, valid, use, cos_l = rect_light_sample(p, u[1], u[2], r.corner, r.x, r.y, r.z, r.len_x,
                                                                    r.len_y, self.normal, self.two_sided)
        if self.profile is not None:
            scale = scale * self.profile(cos_l)
            valid &= scale > 0
        return self._area_where_tiny(p, u, use, wi, dist, scale, pdf, valid)

    def _area_where_tiny(self, p, u, use, wi, dist, scale, pdf, valid):
        """The solid-angle sample (wi, dist, scale, pdf, valid), with area samples where ``use`` is
        False: the rectangle's solid angle is too small for its parametrisation (MIN_RECT_SOLID_ANGLE)."""
        if not use.all():
            far = (~use).nonzero()[0]
            a_wi, a_dist, a_scale, a_pdf, a_valid = self._sample_area(p[:, far], u[:, far])
            wi[:, far], dist[far], scale[far], pdf[far], valid[far] = a_wi, a_dist, a_scale, a_pdf, a_valid
        return wi, dist, scale, pdf, valid

    def _sample_area(self, p, u):
        """Uniform sampling by area (module docstring's ``sample`` contract)."""
        c = self.compiled
        if not self.two_sided and self.profile is None:
            return area_light_sample(p, u, self.cdf, self.tris, c.faces, c.vertices, c.tri_normal, self.total_area)
        # the same sampling, with both faces / the spread profile (NumPy: only Blender lamps use it)
        idx = np.minimum(np.searchsorted(self.cdf, u[0], side="right"), len(self.tris) - 1)
        tri = self.tris[idx]
        f = c.faces[tri]
        su = np.sqrt(u[1])
        b1 = 1.0 - su
        b2 = u[2] * su
        V = c.vertices
        x = (V[f[:, 0]] * (1.0 - b1 - b2)[:, None] + V[f[:, 1]] * b1[:, None] + V[f[:, 2]] * b2[:, None]).T
        to = x - p
        dist2 = dot(to, to)
        dist = np.sqrt(dist2)
        wi = to / np.where(dist > 0, dist, 1.0)
        cos_l = -dot(wi, c.tri_normal[tri].T)
        if self.two_sided:
            cos_l = np.abs(cos_l)
        valid = (cos_l > 0) & (dist > 0)
        pdf = np.where(valid, dist2 / np.where(valid, cos_l, 1.0) / self.total_area, 0.0)
        scale = np.where(valid, 1.0 / np.where(valid, pdf, 1.0), 0.0)
        if self.profile is not None:
            scale = scale * self.profile(cos_l)
            valid &= scale > 0
        return wi, dist, scale, pdf, valid

    def facing(self, cos_l):
        """cosθ at the emitter of rays arriving with −dot(d, n) = cos_l, as seen by the emitting side
        (≤ 0: the ray sees a side that does not emit)."""
        return np.abs(cos_l) if self.two_sided else cos_l

    def emission_factor(self, cos_l):
        """Directional factor of the radiance (the spread profile), or None (Lambertian)."""
        return None if self.profile is None else self.profile(cos_l)

    @property
    def hit_pdf_needs_origin(self) -> bool:
        """Whether ``pdf_hit`` needs the segment's origin: a rectangle is sampled by solid angle, so a
        BSDF-sampled ray that reaches it is MIS-weighted with 1/Ω from where the ray started (the area
        pdf there would not be the pdf next-event estimation used, and the weights would not sum to 1)."""
        return self.rect is not None

    def pdf_hit(self, dist, cos_l, origin=None):
        """Solid-angle pdf with which ``sample`` from the points ``origin`` (3, N) picks the point at
        distance dist whose emitting side faces the ray at cos_l (from ``facing``).  Without
        ``origin`` (camera rays, never MIS-weighted) the area-sampling pdf."""
        ok = cos_l > 0
        area = np.where(ok, dist * dist / np.where(ok, cos_l, 1.0) / self.total_area, 0.0)
        if self.rect is None or origin is None:
            return area
        omega = self.rect.solid_angle(origin)
        use = omega > MIN_RECT_SOLID_ANGLE
        return np.where(use, np.where(ok, 1.0 / np.where(use, omega, 1.0), 0.0), area)

    def power(self):
        """Emitted power (luminance units; Lambertian: π·L·A per emitting side)."""
        return math.pi * float(luminance(self.rgb())) * self.total_area * (2 if self.two_sided else 1)

    def _bound(self):
        """Centroid (3,) and squared radius about it of the emitter's triangles (light selection)."""
        if not hasattr(self, "_centre"):
            c = self.compiled
            corners = c.vertices[c.faces[self.tris]].reshape(-1, 3)
            w = np.repeat(c.tri_area[self.tris], 3)
            self._centre = (corners * w[:, None]).sum(0) / w.sum()
            self._r2 = float(((corners - self._centre) ** 2).sum(1).max())
        return self._centre, self._r2

    def _plane_normal(self):
        """The unit normal (3,) shared by all the emitter's triangles if they lie in one plane, else None."""
        c = self.compiled
        normals = c.tri_normal[self.tris].astype(np.float64)
        normal = normals[0] / np.linalg.norm(normals[0])
        corners = c.vertices[c.faces[self.tris]].reshape(-1, 3)
        extent = max(float(np.ptp(corners, axis=0).max()), 1e-300)
        offsets = (corners - corners[0]) @ normal
        if np.abs(normals @ normal - 1.0).max() > 1e-9 or np.abs(offsets).max() > 1e-9 * extent:
            return None
        return normal

    def selection_record(self):
        centre, r2 = self._bound()
        power = float(luminance(self.rgb())) * self.total_area * (2 if self.two_sided else 1)
        row = [*centre, power, max(r2, 1e-12), math.sqrt(r2)]
        normal = None if self.two_sided else self._plane_normal()
        if normal is not None:      # a one-sided planar emitter (Blender's area lamps): dark behind its plane
            row += [1.0, *normal]
        return SELECT_AREA, row

    def importance(self, p, n=None):
        """Bound-like estimate of the irradiance at p (3, N) with side normals n: L·A/max(d², r²)
        about the centroid, times the orientation terms (receiver; emitter if one-sided and planar)."""
        _, row = self.selection_record()
        row = row + [0.0] * (10 - len(row))
        return area_importance(p, n, np.array(row[:3]), row[3], row[4], row[5], row[6], np.array(row[7:10]))


class EllipseEmitter(AreaEmitter):
    """A one-sided disk or ellipse lamp: the fan of ``sides`` triangles around its centre whose outer
    vertices lie at the parametric angles phase + 2πk/sides of the ellipse centre + cos·axis_a +
    sin·axis_b (Blender's disk and ellipse lamps, polar_addon.export.lights).  Sampled close to the
    solid angle it subtends (engine.kernels.lamp_sampling: the concentric map of a bilinear warp
    fitted to cosθ_l/d²) instead of by area; ``pdf_hit`` gives the same pdf from the ray's origin.
    Everything else (emission, spread profile, light selection) is ``AreaEmitter``'s."""

    MIN_SIDES = 8
    hit_pdf_needs_direction = True     # pdf_hit depends on where on the lamp the ray arrives

    def __init__(self, spectrum, tris, compiled, ellipse, spread_deg=180.0):
        super().__init__(spectrum, tris, compiled, False, spread_deg)
        self.centre, self.axis_a, self.axis_b, self.sides, self.phase = ellipse
        self.normal = compiled.tri_normal[tris[0]].astype(np.float64)

    @classmethod
    def fan_ellipse(cls, corners, normals, tol=1e-7):
        """(centre, axis_a, axis_b, sides, phase) of triangles (K, 3, 3) that are the fan of a regular
        polygon inscribed in an ellipse (up to an affine map), all with the unit normal normals (K, 3);
        None otherwise."""
        K = len(corners)
        if K < cls.MIN_SIDES or np.abs(normals - normals[0]).max() > 1e-6:
            return None
        pts = corners.reshape(-1, 3)
        scale = float(np.abs(pts - pts.mean(0)).max())
        if not scale > 0:
            return None
        # the centre is the vertex all triangles share
        centre = None
        for q in corners[0]:
            if all(np.abs(tri - q).max(axis=1).min() <= tol * scale for tri in corners):
                centre = q
                break
        if centre is None:
            return None
        ring = pts[np.abs(pts - centre).max(axis=1) > tol * scale]
        unique = []
        for q in ring:
            if not any(np.abs(q - r).max() <= tol * scale for r in unique):
                unique.append(q)
        ring = np.array(unique)
        if len(ring) != K:
            return None
        n = normals[0] / np.linalg.norm(normals[0])
        e1 = ring[0] - centre
        e1 = e1 / np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        q = np.stack(((ring - centre) @ e1, (ring - centre) @ e2), axis=1)
        if np.abs((ring - centre) @ n).max() > tol * scale:
            return None
        # conic through the ring: qᵀ M q = 1, M symmetric positive definite
        A = np.stack((q[:, 0] ** 2, 2 * q[:, 0] * q[:, 1], q[:, 1] ** 2), axis=1)
        m, *_ = np.linalg.lstsq(A, np.ones(K), rcond=None)
        if np.abs(A @ m - 1.0).max() > 1e-6:
            return None
        M = np.array([[m[0], m[1]], [m[1], m[2]]])
        w, V = np.linalg.eigh(M)
        if not (w > 0).all():
            return None
        axis_a = (V[0, 0] * e1 + V[1, 0] * e2) / math.sqrt(w[0])
        axis_b = (V[0, 1] * e1 + V[1, 1] * e2) / math.sqrt(w[1])
        if np.dot(np.cross(axis_a, axis_b), n) < 0:
            axis_b = -axis_b
        # parametric angles of the ring: regular?
        aa, bb = axis_a @ axis_a, axis_b @ axis_b
        ang = np.sort(np.mod(np.arctan2((ring - centre) @ axis_b / bb, (ring - centre) @ axis_a / aa), 2 * math.pi))
        steps = np.diff(np.concatenate((ang, [ang[0] + 2 * math.pi])))
        if np.abs(steps - 2 * math.pi / K).max() > 1e-6:
            return None
        # the fan covers the polygon exactly once
        tri_area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
        polygon = 0.5 * K * math.sin(2 * math.pi / K) * float(np.linalg.norm(np.cross(axis_a, axis_b)))
        if abs(tri_area.sum() - polygon) > 1e-6 * polygon:
            return None
        return centre, axis_a, axis_b, K, float(ang[0])

    def sample(self, p, u):
        # u has 3 rows: the first (triangle choice) is unused, then the warped point
        wi, dist, scale, pdf, cos_l, valid = ellipse_lamp_sample(p, u[1], u[2], self.centre, self.axis_a, self.axis_b,
                                                                 self.normal, self.sides, self.phase)
        if self.profile is not None:
            scale = scale * self.profile(cos_l)
            valid &= scale > 0
        return wi, dist, scale, pdf, valid

    def pdf_hit(self, dist, cos_l, origin=None, d=None):
        """Solid-angle pdf with which ``sample`` from ``origin`` (3, N) reaches the lamp along the
        directions d (3, N) at distance dist; without them (camera rays) the area-sampling pdf."""
        if origin is None or d is None:
            return super().pdf_hit(dist, cos_l)
        return ellipse_lamp_pdf(origin, origin + d * dist, self.centre, self.axis_a, self.axis_b, self.normal)


class SpreadRectangleEmitter(AreaEmitter):
    """A one-sided rectangle lamp with a spread profile (Cycles' soft-box grid): the spherical
    rectangle's (u, v) (``SphericalRectangle``) are drawn from a bilinear warp fitted to the profile
    seen at its four corners (engine.kernels.lamp_sampling), so samples go where the grid lets light
    through (on the Cycles parity floor, unshadowed: 17× less variance per sample than uniform in
    solid angle at a 90° spread).  ``pdf_hit`` inverts the parametrisation at the arrival point."""

    hit_pdf_needs_direction = True     # pdf_hit depends on where on the lamp the ray arrives
    CORNER_FLOOR = 1e-2                # corner values ≥ this × the largest: the warp covers the lamp

    def _corner_profile(self, p):
        """Warp corner values (4, N) (order of WARP_CORNERS: u along the rectangle's x, v along y)."""
        r = self.rect
        ex, ey = r.x * r.len_x, r.y * r.len_y
        g = np.empty((4, p.shape[1]))
        for k, (a, b) in enumerate(((0, 0), (1, 0), (0, 1), (1, 1))):
            to = (r.corner + a * ex + b * ey)[:, None] - p
            cos_l = -dot(to, self.normal[:, None]) / np.sqrt(np.maximum(dot(to, to), 1e-300))
            g[k] = self.profile(cos_l)
        top = g.max(axis=0)
        return np.where(top > 0, np.maximum(g, self.CORNER_FLOOR * top), 1.0)

    def sample(self, p, u):
        if self.rect is None:
            return super().sample(p, u)
        r = self.rect
        uu, vv, pdf_uv = bilinear_warp_sample(self._corner_profile(p), u[1], u[2])
        wi, dist, scale, pdf, valid, use, cos_l = rect_light_sample(p, uu, vv, r.corner, r.x, r.y, r.z, r.len_x,
                                                                    r.len_y, self.normal, False)
        scale = scale / pdf_uv * self.profile(cos_l)
        pdf = pdf * pdf_uv
        valid &= scale > 0
        return self._area_where_tiny(p, u, use, wi, dist, scale, pdf, valid)

    def warp_coordinates(self, origin, x):
        """(u, v) ∈ [0, 1]² of the spherical-rectangle parametrisation seen from origin (3, N) at which
        ``rect_sample`` gives the rectangle points x (3, N), and the solid angle Ω (N,)."""
        r = self.rect
        x0, x1, y0, y1, z0, _ = r._local(origin)
        rel = x - origin
        xh = np.clip(dot(rel, r.x[:, None]), x0, x1)
        yh = np.clip(dot(rel, r.y[:, None]), y0, y1)
        with np.errstate(invalid="ignore", divide="ignore"):
            omega = np.nan_to_num(rect_angles(x0, x1, y0, y1, z0)[3])
            part = np.nan_to_num(rect_angles(x0, xh, y0, y1, z0)[3])
            d2 = xh * xh + z0 * z0
            h0 = y0 / np.sqrt(d2 + y0 * y0)
            h1 = y1 / np.sqrt(d2 + y1 * y1)
            hh = yh / np.sqrt(d2 + yh * yh)
            u = np.clip(part / np.where(omega > 0, omega, 1.0), 0.0, 1.0)
            v = np.clip(np.nan_to_num((hh - h0) / (h1 - h0)), 0.0, 1.0)
        return u, v, np.where(z0 < 0, omega, 0.0)

    def pdf_hit(self, dist, cos_l, origin=None, d=None):
        """Solid-angle pdf with which ``sample`` from ``origin`` (3, N) reaches the lamp along d (3, N)
        at distance dist; without them (camera rays) the area-sampling pdf."""
        if self.rect is None or origin is None or d is None:
            return super().pdf_hit(dist, cos_l, origin)
        ok = cos_l > 0
        area = np.where(ok, dist * dist / np.where(ok, cos_l, 1.0) / self.total_area, 0.0)
        u, v, omega = self.warp_coordinates(origin, origin + d * dist)
        use = omega > MIN_RECT_SOLID_ANGLE
        warp = bilinear_warp_pdf(self._corner_profile(origin), u, v)
        return np.where(use, np.where(ok, warp / np.where(use, omega, 1.0), 0.0), area)


def mesh_emitter(spectrum, tris, compiled, two_sided=False, spread_deg=180.0):
    """The emitter of an emissive mesh's triangles: an ``EllipseEmitter`` for a one-sided disk or
    ellipse fan, a ``SpreadRectangleEmitter`` for a one-sided rectangle with a spread, else an
    ``AreaEmitter``."""
    if not two_sided and len(tris) >= EllipseEmitter.MIN_SIDES:
        corners = compiled.vertices[compiled.faces[tris]].astype(np.float64)
        ellipse = EllipseEmitter.fan_ellipse(corners, compiled.tri_normal[tris].astype(np.float64))
        if ellipse is not None:
            return EllipseEmitter(spectrum, tris, compiled, ellipse, spread_deg)
    if not two_sided and len(tris) == 2 and spread_profile(math.radians(spread_deg)) is not None:
        return SpreadRectangleEmitter(spectrum, tris, compiled, False, spread_deg)
    return AreaEmitter(spectrum, tris, compiled, two_sided, spread_deg)


def point_light_sample_numpy(p, u, position, radius, soft_falloff, spot):
    """Next-event samples of a point or spot light (``PointEmitter``, ``SpotEmitter``) at p (3, N)
    for u (3, N) (rows 1–2 used): the module docstring's ``sample`` contract.  ``spot`` = [edge kind
    (0: no spot, 1: hard edge, 2: smoothstep), axis (3), cos_outer, cos_inner].  Radius 0: a delta
    light; else a disk facing p (``soft_falloff``) or a sphere."""
    to = position[:, None] - p
    dist2 = dot(to, to)
    dist = np.sqrt(dist2)
    valid = dist > 0
    wi = to / np.where(valid, dist, 1.0)
    # by the direction to the centre, as Cycles' spot_light_attenuation
    falloff = 1.0 if spot[0] == 0 else spot_falloff(wi, spot[1:4], spot[4], spot[5])
    if radius <= 0:
        scale = np.where(valid, falloff / np.where(valid, dist2, 1.0), 0.0)
        return wi, dist, scale, np.zeros(p.shape[1]), valid
    r = radius
    if soft_falloff:
        # disk ⟂ (p − centre), radius r, uniform by area: pdf = t²/(cos·πr²), radiance I/(πr²)
        rho = r * np.sqrt(u[1])
        phi = 2.0 * math.pi * u[2]
        offset = local_to_world(np.stack((rho * np.cos(phi), rho * np.sin(phi), np.zeros_like(rho))), -wi)
        to_s = to + offset
        t2 = dot(to_s, to_s)
        t = np.sqrt(t2)
        w = to_s / np.where(t > 0, t, 1.0)
        cos_l = dot(w, wi)                # the disk's normal is −wi (it faces p)
        valid &= (cos_l > 0) & (t > 0)
        pdf = np.where(valid, t2 / np.where(valid, cos_l * math.pi * r * r, 1.0), 0.0)
        scale = np.where(valid, falloff * cos_l / np.where(valid, t2, 1.0), 0.0)
        return w, t, scale, pdf, valid
    # sphere: uniform cone of half-angle asin(r/d), hit distance by the law of cosines
    valid &= dist > r
    sin2 = np.minimum(r * r / np.where(valid, dist2, 1.0), 1.0)
    one_minus_cos_max = sin2 / (1.0 + np.sqrt(1.0 - sin2))
    w, cos_t = uniform_cone(u[1], u[2], one_minus_cos_max, wi)
    t = dist * cos_t - np.sqrt(np.maximum(r * r - dist2 * (1.0 - cos_t * cos_t), 0.0))
    pdf = np.where(valid, 1.0 / (2.0 * math.pi * np.where(valid, one_minus_cos_max, 1.0)), 0.0)
    scale = np.where(valid, falloff * 2.0 * one_minus_cos_max / (r * r), 0.0)
    return w, np.maximum(t, 0.0), scale, pdf, valid


#: One compiled pass per light where Numba is available (engine.kernels.light_sampling).
point_light_sample = twin(point_light_sample_numba, point_light_sample_numpy)


class PointEmitter(_Light):
    """Isotropic light of radiant intensity I: irradiance I/d² at normal incidence.

    With a radius r > 0 (Cycles, kernel/light/point.h) it is a uniform emitter of radiance
    I/(πr²): a disk of radius r facing the receiver (``soft_falloff``; sampled uniformly by area,
    on-axis irradiance I/(d² + r²)) or a sphere (sampled uniformly in its cone, exactly I/d²
    outside; receivers inside it get no direct light from it).
    """

    def __init__(self, spectrum, position, radius=0.0, soft_falloff=True):
        super().__init__(spectrum)
        self.position = np.asarray(position, np.float64)
        self.radius = float(radius)
        self.soft_falloff = bool(soft_falloff)
        self.is_delta = self.radius <= 0
        self.hittable = not self.is_delta

    def _falloff(self, wi):
        return 1.0

    def intersect(self, o, d, seg, hit, p_ref):
        """Rays o + t·d, 0 < t < seg, that reach the sphere or disk: (rows, radiance factor relative
        to the intensity spectrum (n,), solid-angle pdf of next-event estimation from p_ref (n,)).

        The disk faces the ray origin (Cycles' point_light_intersect); the spot attenuation is
        that of the origin's direction, so from outside the cone the light is black."""
        r = self.radius
        c = self.position[:, None]
        ok, t, cos_l = lamp_hits(o, d, seg, self.position, r, self.soft_falloff)
        rows = ok.nonzero()[0]
        if rows.size == 0:
            return rows, np.zeros(0), np.zeros(0)
        to_c = c - o[:, rows]
        wi = to_c / np.sqrt(dot(to_c, to_c))
        factor = self._falloff(wi) / (math.pi * r * r) * np.ones(rows.size)
        q = p_ref[:, rows] if p_ref is not None else o[:, rows]
        if self.soft_falloff:
            pdf = t[rows] ** 2 / (cos_l[rows] * math.pi * r * r)
        else:
            to = c - q
            sin2 = np.minimum(r * r / np.maximum(dot(to, to), r * r), 1.0)
            pdf = 1.0 / (2.0 * math.pi * (sin2 / (1.0 + np.sqrt(1.0 - sin2))))
        return rows, factor, pdf

    def sample(self, p, u):
        # u has 3 rows: the first (light choice) is unused, then the point on the disk or in the cone
        spot = getattr(self, "spot_record", None)
        return point_light_sample(p, u, self.position, self.radius, self.soft_falloff,
                                  np.zeros(6) if spot is None else np.array(spot))

    def power(self):
        return 4.0 * math.pi * float(luminance(self.rgb()))

    def selection_record(self):
        spot = getattr(self, "spot_record", [0.0] * 6)
        return SELECT_POINT, [*self.position, float(luminance(self.rgb())), max(self.radius ** 2, 1e-12), self.radius,
                              *spot]

    def importance(self, p, n=None):
        """Irradiance at p (3, N) facing the light, I·falloff/max(d², r²), times the orientation term."""
        _, row = self.selection_record()
        spot = None if row[6] == 0 else (np.array(row[7:10]), row[10], row[11])
        return point_importance(p, n, self.position, row[3], row[4], row[5], spot)


class SpotEmitter(PointEmitter):
    """Point light restricted to a cone; ``blend`` smooths the edge (smoothstep in cos angle).

    Profile "angle": the edge runs from cos(half) to cos(half·(1 − blend)); profile "cycles"
    (kernel/light/spot.h: spot_light_attenuation): from cos(half) to cos(half) + blend·(1 − cos(half)).
    """

    def __init__(self, spectrum, position, direction, cone_angle_deg, blend, blend_profile="angle",
                 radius=0.0, soft_falloff=True):
        super().__init__(spectrum, position, radius, soft_falloff)
        self.axis = normalize(np.asarray(direction, np.float64))
        half = math.radians(cone_angle_deg) / 2
        self.cos_outer = math.cos(half)
        if blend_profile == "cycles":
            self.cos_inner = min(1.0, self.cos_outer + blend * (1.0 - self.cos_outer))
        else:
            self.cos_inner = math.cos(half * (1.0 - blend))

    def power(self):
        return 2.0 * math.pi * (1.0 - self.cos_outer) * float(luminance(self.rgb()))

    def _falloff(self, wi):
        return spot_falloff(wi, self.axis, self.cos_outer, self.cos_inner)

    @property
    def spot_record(self):
        """[edge kind (1 hard, 2 smooth), axis, cos_outer, cos_inner] (SELECT_POINT's spot columns)."""
        return [1.0 if self.cos_inner <= self.cos_outer else 2.0, *self.axis, self.cos_outer, self.cos_inner]


class DirectionalEmitter(_Light):
    """Parallel light (sun) travelling along ``direction`` with irradiance E ⟂ to it.

    With an angular diameter > 0 (Cycles' sun angle, kernel/light/distant.h) it is a disc of
    uniform radiance E/(π sin²θh), θh = angle/2, sampled uniformly in its cone (soft shadows,
    the same irradiance E on a surface facing it).
    """

    at_infinity = True

    def __init__(self, spectrum, direction, angle_deg=0.0):
        super().__init__(spectrum)
        self.direction = normalize(np.asarray(direction, np.float64))
        half = 0.5 * math.radians(angle_deg)
        self.is_delta = half <= 0
        self.hittable = not self.is_delta
        self.one_minus_cos = 2.0 * math.sin(0.5 * half) ** 2
        # radiance / E divided by the cone pdf: 2π(1 − cosθh) / (π sin²θh)
        self.factor = 2.0 * self.one_minus_cos / math.sin(half) ** 2 if half > 0 else 1.0
        self.radiance_factor = 1.0 / (math.pi * math.sin(half) ** 2) if half > 0 else 0.0

    def intersect(self, o, d, seg, hit, p_ref):
        """Rays that escape (not ``hit``) within the sun's disc: (rows, radiance/E, cone pdf);
        Cycles' integrate_distant_lights."""
        rows = (~hit & (1.0 - dot(d, -self.direction[:, None]) <= self.one_minus_cos)).nonzero()[0]
        return (rows, np.full(rows.size, self.radiance_factor),
                np.full(rows.size, 1.0 / (2.0 * math.pi * self.one_minus_cos)))

    def sample(self, p, u):
        n = p.shape[1]
        if self.is_delta:
            wi = np.broadcast_to(-self.direction[:, None], (3, n)).copy()
            return wi, np.full(n, np.inf), np.ones(n), np.zeros(n), np.ones(n, bool)
        wi, _ = uniform_cone(u[1], u[2], self.one_minus_cos, -self.direction)
        return (wi, np.full(n, np.inf), np.full(n, self.factor),
                np.full(n, 1.0 / (2.0 * math.pi * self.one_minus_cos)), np.ones(n, bool))

    def power(self, scene_radius=1.0):
        return float(luminance(self.rgb())) * math.pi * scene_radius ** 2

    def selection_record(self):
        sin_half = math.sqrt(self.one_minus_cos * (2.0 - self.one_minus_cos))
        return SELECT_DISTANT, [*(-self.direction), float(luminance(self.rgb())), sin_half]

    def importance(self, p, n=None):
        _, row = self.selection_record()
        return distant_importance(p, n, -self.direction, row[3], row[4])


class LightSet:
    """All lights of a compiled scene.  NEE picks one light per vertex: uniformly (probability
    1/count, ``Scene.light_selection`` "uniform"; ``prob[i]``) or, with "power", by importance:
    for up to ``SPATIAL_MAX`` lights, per shading point ∝ each light's estimated irradiance
    there (power/dist² × ``facing_factor``, as the importance of Cycles' light tree without the
    tree), mixed with
    ``GLOBAL_SHARE`` of the power distribution (so no light that can contribute gets
    probability 0); for more lights ∝ power alone.  Every MIS pdf includes the probability
    with which the light would have been chosen at the vertex the ray left (``prob_at``).
    """

    SPATIAL_MAX = 64
    GLOBAL_SHARE = GLOBAL_SHARE

    def __init__(self, scene, compiled):
        self.lights = []
        self.environment = None
        self.environment_index = -1
        self.camera_hidden = set()     # lights (indices) that camera rays do not see
        for mesh_index, mesh in enumerate(scene.meshes):
            if mesh.emission is None:
                continue
            tris = np.nonzero((compiled.tri_mesh == mesh_index) & (compiled.tri_area > 0))[0]
            if len(tris) == 0:
                continue
            compiled.tri_emitter[tris] = len(self.lights)
            if not getattr(mesh, "visible_camera", True) and not getattr(mesh, "occluder", True):
                self.camera_hidden.add(len(self.lights))
            self.lights.append(mesh_emitter(mesh.emission, tris, compiled, getattr(mesh, "two_sided", False),
                                            getattr(mesh, "spread_deg", 180.0)))
        for index, light in enumerate(scene.lights):
            if not getattr(light, "visible_camera", True):
                self.camera_hidden.add(len(self.lights))
            if isinstance(light, EnvironmentLight):
                image = getattr(light, "image", None)
                self.environment = (EnvironmentEmitter(light.radiance) if image is None else
                                    EnvironmentMapEmitter(image, light.strength, light.rotation_deg, light.grid,
                                                          interpolation_space=getattr(light, "interpolation_space",
                                                                                      "linear")))
                self.environment_index = len(self.lights)
                self.lights.append(self.environment)
            elif isinstance(light, SpotLight):
                self.lights.append(SpotEmitter(light.intensity, light.position, light.direction,
                                               light.cone_angle_deg, light.blend,
                                               getattr(light, "blend_profile", "angle"),
                                               getattr(light, "radius", 0.0), getattr(light, "soft_falloff", True)))
            elif isinstance(light, PointLight):
                self.lights.append(PointEmitter(light.intensity, light.position, getattr(light, "radius", 0.0),
                                                getattr(light, "soft_falloff", True)))
            elif isinstance(light, DirectionalLight):
                self.lights.append(DirectionalEmitter(light.irradiance, light.direction,
                                                      getattr(light, "angle_deg", 0.0)))
            else:       # e.g. a light of another copy of this package: never leave a light out silently
                raise SceneError(f"lights[{index}]", f"is a {type(light).__module__}.{type(light).__name__}, not "
                                                     "one of engine.scene.description's light types")
        count = len(self.lights)
        self.select_prob = 1.0 / count if count else 0.0
        self.selection = getattr(scene, "light_selection", "uniform")
        if self.selection not in ("uniform", "power"):
            raise SceneError("light_selection", f"must be 'uniform' or 'power', got {self.selection!r}")
        self.prob = np.full(count, self.select_prob)
        self.mix_prob = self.prob
        self.cdf = None
        if self.selection == "power" and count > 1:
            radius = max(float(np.linalg.norm(compiled.vertices - compiled.vertices.mean(0), axis=1).max()), 1e-9)
            power = np.array([lt.power(radius) if lt.at_infinity else lt.power() for lt in self.lights])
            power = np.where(np.isfinite(power) & (power > 0), power, 0.0)
            if power.sum() > 0:
                self.prob = power / power.sum()
                self.cdf = np.cumsum(self.prob)
                self.cdf[-1] = 1.0
                # the global share mixed into the per-point probabilities leaves a constant sky out
                # beside other lights (EnvironmentEmitter.SELECTION_SHARE)
                local = np.where([type(lt) is EnvironmentEmitter for lt in self.lights], 0.0, power)
                self.mix_prob = local / local.sum() if local.sum() > 0 else self.prob
        self.spatial = self.cdf is not None and count <= self.SPATIAL_MAX
        if self.spatial:
            # every light's importance formula as (kind, parameters): one compiled pass for all lights
            records = [light.selection_record() for light in self.lights]
            self._kinds = np.array([k for k, _ in records], np.int64)
            self._params = np.zeros((count, SELECTION_PARAMS))
            for i, (_, row) in enumerate(records):
                self._params[i, :len(row)] = row
        self.hittable = [i for i, light in enumerate(self.lights) if light.hittable]

    def probabilities(self, p, n=None):
        """Selection probabilities (count, N) at shading points p (3, N) with side normals n (the
        geometric normal on the side the path arrived from) or None."""
        if not self.spatial:
            return np.repeat(self.prob[:, None], p.shape[1], axis=1)
        return selection_probabilities(p, n, self._kinds, self._params, self.mix_prob)

    def prob_at(self, li, p, n=None):
        """Probability (N,) or scalar that NEE at points p (3, N) with side normals n picks light ``li``."""
        if not self.spatial or p is None:
            return self.prob[li]
        return self.probabilities(p, n)[li]

    def choose(self, u, p=None, n=None):
        """(light index (N,), the remainder of u rescaled to [0, 1), the chosen lights'
        probabilities (N,) or None where they are ``prob[index]``) for uniform numbers u (N,)
        at shading points p (3, N) with side normals n."""
        count = len(self.lights)
        if self.cdf is None:
            choice = np.minimum((u * count).astype(np.int64), count - 1)
            return choice, u * count - choice, None
        if self.spatial and p is not None:
            return choose_light(u, self.probabilities(p, n))
        choice = np.minimum(np.searchsorted(self.cdf, u, side="right"), count - 1)
        lo = np.where(choice > 0, self.cdf[np.maximum(choice - 1, 0)], 0.0)
        rest = (u - lo) / np.where(self.prob[choice] > 0, self.prob[choice], 1.0)
        return choice, np.clip(rest, 0.0, np.nextafter(1.0, 0.0)), None

    def __len__(self):
        return len(self.lights)
