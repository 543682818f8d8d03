"""Environment lights: a constant sky and equirectangular maps (importance-sampled by luminance).

Part of engine.render.lights (its package docstring states the light interface)."""

from __future__ import annotations

import math

import numpy as np

from ...errors import SceneError
from ...kernels import environment_map, twin
from ...kernels.light_sampling import SELECT_CONSTANT
from ...materials.sampling import uniform_sphere
from ...spectral import luminance
from ...textures.image import srgb_to_linear
from ...scene.description import ENVMAP_GRIDS, ENVMAP_INTERPOLATION_SPACES
from ...vec3 import dot
from .base import _Light


class EnvironmentEmitter(_Light):
    """Constant radiance from every direction; sampled uniformly on the sphere."""

    at_infinity = True

    @property
    def constant_sky(self) -> bool:
        # a sky derived from this one that varies must say varies_with_direction (else it renders as constant)
        return not self.varies_with_direction

    def sample(self, p, u):
        return _uniform_sample(u)

    def pdf(self, d, uv=None):
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
        # rows (the marginal) and the flat cdf's value before each row: sample() picks the row, then the piece in it
        self.row_prob = prob.sum(axis=1)
        self.row_cdf = np.cumsum(self.row_prob)
        self.row_cdf[-1] = 1.0
        self.row_start = np.concatenate(([0.0], self.cdf[W - 1:-1:W]))
        # mean radiance over the sphere (light selection): ∫ L dω / 4π
        rows = knot_rows.astype(np.float64)
        rows_right = np.roll(rows, -1, axis=1)
        piece_mean = 0.25 * (rows[:-1] + rows[1:] + rows_right[:-1] + rows_right[1:])
        self._rgb = self.strength * np.einsum("kwc,kw->c", piece_mean, omega) / (4.0 * math.pi)

    def set_stokes(self, stokes, polarisation) -> None:
        """Polarise the map: ``stokes`` (H, W, 3) the normalised S1, S2, S3 of each texel (degree ≤ 1) in the
        map's frame (x = unit(Z × ω) in map coordinates: the tangent of increasing longitude, y = k × x, k = −ω,
        as an equirectangular Polar render's frame), ``polarisation`` a DirectionalPolarisation."""
        s = np.asarray(stokes, np.float64)
        if s.shape != self.texels.shape:
            raise SceneError("image", f"the Stokes channels have shape {s.shape}, the map {self.texels.shape}")
        self._stokes = s
        self.polarisation = polarisation

    def set_sky(self, sky, polarisation) -> None:
        """Polarise the map as the clear sky ``sky`` (engine.spectral.daylight.ClearSky, world frame:
        its sun direction is not turned with the map) polarises daylight; ``polarisation`` a
        DirectionalPolarisation."""
        self._sky = sky
        self.polarisation = polarisation

    def emitted_polarisation(self, k):
        """(normalised Stokes (4, n), frame x (3, n)) of the sky light travelling along k (3, n), ω = −k: a
        clear sky's (``set_sky``), or the map's Stokes channels (bilinear) in its frame x = unit(Z_map × ω) (at
        the poles the tangent of longitude 0) turned with the map into the world; None: unpolarised."""
        if self.polarisation is None:
            return None
        w = -k
        if getattr(self, "_sky", None) is not None:
            # linear, along the sky's electric field e (⟂ ω): S = (1, P, 0, 0) in the frame x = e
            dolp, e = self._sky.polarisation(w.T)
            s = np.zeros((4, w.shape[1]))
            s[0], s[1] = 1.0, dolp
            return s, np.ascontiguousarray(e.T)
        wm = self._to_map(w)
        u, v = _uv_numpy(wm)
        s = np.empty((4, w.shape[1]))
        s[0] = 1.0
        s[1:] = bilinear_numpy(self._stokes, u, v, self.grid == "mitsuba").T
        x = np.stack((-wm[1], wm[0], np.zeros_like(wm[0])))
        norm = np.sqrt(x[0] ** 2 + x[1] ** 2)
        x = np.where(norm > 1e-12, x / np.where(norm > 1e-12, norm, 1.0), np.array([[0.0], [1.0], [0.0]]))
        return s, self._to_world(x)

    def _to_world(self, v):
        """Vectors (3, N) of the map frame turned into the world (the map's rotation; ``_to_map``'s inverse)."""
        if self.turn is not None:
            return self.turn @ v
        if self.rotation == 0.0:
            return v
        c, s = math.cos(self.rotation), math.sin(self.rotation)
        return np.stack((c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]))

    def _to_map(self, d):
        """Directions (3, N) turned by −rotation about +Z (world → map frame)."""
        if self.turn is not None:
            return self.turn.T @ d
        if self.rotation == 0.0:
            return d
        c, s = math.cos(self.rotation), math.sin(self.rotation)
        return np.stack((c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]))

    def map_coordinates(self, d):
        """(u, v) (N,) each: the map's coordinates of the world directions d (3, N) (the class docstring's)."""
        return _uv_numpy(self._to_map(d))

    def lookup_rgb(self, d, uv=None):
        """Linear sRGB radiance (N, 3) × strength in the world directions d (3, N) (a view of a (3, N) array);
        ``uv``: their ``map_coordinates`` if the caller has them."""
        rgb = _map_lookup(*(self.map_coordinates(d) if uv is None else uv), self._interpolated,
                          self.grid == "mitsuba", 1.0 if self._decode else self.strength)
        return (np.maximum(srgb_to_linear(rgb), 0.0) * self.strength if self._decode else rgb).T

    def emitted(self, d, lookup, rgb_mode: bool, mono: bool, uv=None):
        """Radiance towards −d for rays travelling along d (3, n): RGB (3, n), mono luminance (1, n)
        or the illuminant spectrum D65n · Σ rgb_c B_c at ``lookup``'s wavelengths (L, n).  ``uv``: the directions'
        ``map_coordinates`` if the caller has them (the same numbers)."""
        rgb = self.lookup_rgb(d, uv).T
        if rgb_mode:
            return rgb
        if mono:
            return np.broadcast_to(luminance(rgb.T)[None, :], lookup.lam.shape).copy()
        basis = lookup.basis
        return lookup.d65 * (rgb[0] * basis[0] + rgb[1] * basis[1] + rgb[2] * basis[2])

    def sample(self, p, u):
        dm, scale, pdf = _map_sample(self.cdf, self.row_cdf, self.row_prob, self.row_start, self.cos_knots,
                                     self.cell_pdf, u)
        return self._to_world(dm), np.full(p.shape[1], np.inf), scale, pdf, pdf > 0

    def pdf(self, d, uv=None):
        """Solid-angle pdf (N,) of ``sample`` producing the world directions d (3, N) (``uv``: their
        ``map_coordinates`` if the caller has them)."""
        return _map_pdf(*(self.map_coordinates(d) if uv is None else uv), self.cell_pdf, self.texels.shape[0],
                        self.grid == "mitsuba")

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


# ----------------------------------------------------------------------------- the map's per-direction arithmetic
# (NumPy references of engine.kernels.environment_map's compiled loops, paired below)

def _uv_numpy(dm):
    """(u, v) (N,) each of map-frame directions dm (3, N) (EnvironmentMapEmitter's convention)."""
    norm = np.sqrt(dot(dm, dm))
    u = np.mod(0.5 - np.arctan2(dm[1], dm[0]) / (2.0 * math.pi), 1.0)
    v = np.arccos(np.clip(dm[2] / np.where(norm > 0, norm, 1.0), -1.0, 1.0)) / math.pi
    return u, v


def bilinear_numpy(img, u, v, mitsuba):
    """Bilinear lookup of ``img`` (H, W, C) on the map's texel grid (``mitsuba``: knots at the rows, else Cycles'
    texel centres) at (u, v) (N,) each, periodic in u → (N, C)."""
    H, W = img.shape[:2]
    x = np.mod(u * W - 0.5, W)
    i0 = np.minimum(np.floor(x), W - 1).astype(np.int64)
    fx = (x - i0)[:, None]
    if mitsuba:
        y = v * (H - 1)
        j0 = np.minimum(np.floor(y), H - 2).astype(np.int64)
        fy = (y - j0)[:, None]
    else:
        y = v * H - 0.5
        j0 = np.clip(np.floor(y), 0, H - 2).astype(np.int64)
        fy = np.clip(y - j0, 0.0, 1.0)[:, None]
    i1 = (i0 + 1) % W
    top = img[j0, i0] * (1 - fx) + img[j0, i1] * fx
    bot = img[j0 + 1, i0] * (1 - fx) + img[j0 + 1, i1] * fx
    return top * (1 - fy) + bot * fy


def lookup_numpy(u, v, img, mitsuba, strength):
    """The bilinear value (C, N) of ``img`` (H, W, C) at the map coordinates u, v (N,) each (``_uv_numpy``),
    × ``strength``."""
    return (bilinear_numpy(img, u, v, mitsuba) * strength).T


def pdf_numpy(u, v, cell_pdf, H, mitsuba):
    """Solid-angle pdf (N,) at the map coordinates u, v (N,) each: cell_pdf (K, W) of the bilinear piece holding
    each (H: the map's rows)."""
    W = cell_pdf.shape[1]
    i = np.mod(np.floor(u * W - 0.5).astype(np.int64), W)
    if mitsuba:
        j = np.minimum(np.floor(v * (H - 1)), H - 2).astype(np.int64)
    else:
        j = np.clip(np.floor(v * H + 0.5), 0, H).astype(np.int64)
    return cell_pdf[j, i]


def sample_numpy(cdf, row_cdf, row_prob, row_start, cos_knots, cell_pdf, u):
    """(map-frame directions (3, n), 1/pdf (0 where the pdf is 0) (n,), solid-angle pdf (n,)) for the numbers
    u (3, n), u[0] unused, as Cycles' background map (light/background.h): u[1] picks the row by the rows'
    marginal ``row_cdf`` (``row_prob`` each), u[2] the piece within it by the row's part of the flat ``cdf`` (row by
    row; ``row_start`` its value before each row), and each number's remainder within its step places the direction
    uniformly in solid angle inside the piece.  One continuous map of the pair, so a stratified pair stays
    stratified on the sphere (the flat cdf on one number stratified the rows only: BoomBox's σ² under its HDRI,
    docs/benchmarks.md)."""
    W = cell_pdf.shape[1]
    j = np.minimum(np.searchsorted(row_cdf, u[1], side="right"), row_prob.size - 1)
    pj = row_prob[j]
    dv = np.clip((u[1] - (row_cdf[j] - pj)) / np.where(pj > 0, pj, 1.0), 0.0, 1.0)
    target = row_start[j] + u[2] * pj
    k = np.clip(np.searchsorted(cdf, target, side="right"), j * W, j * W + W - 1)
    i = k - j * W
    cell = cdf[k] - np.where(k > 0, cdf[k - 1], 0.0)
    du = np.clip((target - (cdf[k] - cell)) / np.where(cell > 0, cell, 1.0), 0.0, 1.0)
    cos_t = cos_knots[j] + dv * (cos_knots[j + 1] - cos_knots[j])
    sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
    phi = math.pi * (1.0 - 2.0 * ((i + 0.5 + du) / W))
    dm = np.stack((sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t))
    pdf = cell_pdf[j, i]
    valid = pdf > 0
    return dm, np.where(valid, 1.0 / np.where(valid, pdf, 1.0), 0.0), pdf


_map_lookup = twin(environment_map.lookup_numba, lookup_numpy)
_map_pdf = twin(environment_map.pdf_numba, pdf_numpy)


def uniform_sample_numpy(u):
    """(directions uniform on the sphere (3, n), distance ∞, 1/pdf = 4π, pdf = 1/4π, valid (n,) each) from u (≥ 2, n)
    (a constant sky's sample)."""
    n = u.shape[1]
    return (uniform_sphere(u), np.full(n, np.inf), np.full(n, 4.0 * math.pi), np.full(n, 1.0 / (4.0 * math.pi)),
            np.ones(n, bool))


_uniform_sample = twin(environment_map.uniform_sample_numba, uniform_sample_numpy)
_map_sample = twin(environment_map.sample_numba, sample_numpy)
