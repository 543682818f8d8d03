"""Textures: values that vary over a surface, evaluated in batches at surface points.

A texture maps the points of a :class:`~engine.textures.surface.SurfacePoints` batch to C values
each, ``eval(points) -> (C, N)`` float64:

- :class:`ImageTexture`: an image looked up at the points' UV coordinates, as Blender's Image
  Texture node: pixel (i, j) covers u ∈ [i/W, (i+1)/W), v ∈ [j/H, (j+1)/H) (row 0 at the bottom),
  its centre at ((i+½)/W, (j+½)/H).
  Interpolation: ``"Closest"`` (the pixel containing (u, v)), ``"Linear"`` (bilinear between the
  four nearest pixel centres), ``"Cubic"`` (uniform cubic B-spline over 4×4 pixel centres, as
  Cycles' bicubic; its weights are ≥ 0 and sum to 1, so values stay within the pixels' range).
  Extension (pixels outside the image): ``"REPEAT"`` (tile), ``"EXTEND"`` (the edge pixel),
  ``"CLIP"`` (0: transparent black), ``"MIRROR"`` (tile, every other tile mirrored).  Coordinates
  beyond 2⁵² (where every float is whole) are first reduced to what the extension makes of them, so
  any finite UV gives a finite value; a UV that overflowed to inf or NaN reads (0, 0).
  Interpolation space: ``"linear"`` (the texels are linear values, filtered as they are) or
  ``"srgb"`` (the texels are sRGB-encoded values; the colour channels are filtered encoded and the
  result decoded, value = dec(Σ wᵢ·encᵢ), as Cycles does for every image it keeps in the sRGB colour
  space: 8-bit ones and float files tagged sRGB, scene/image.cpp ``compress_as_srgb``, decoded in
  svm_image_texture after the lookup; dec is IEC 61966-2-1's, its power law continued above 1 and
  negative values → 0, as Cycles' color_srgb_to_linear).  Texel centres and Closest give the
  decoded texels; between a dark and a bright texel the value follows ~t^2.4 rather than t.
- :class:`VertexColour`: a per-vertex colour attribute interpolated over each triangle
  (Blender's Color Attribute node), in linear values.
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from ..kernels import twin
from ..kernels.texture_lookup import bilinear_loop
from .image import srgb_to_linear

INTERPOLATIONS = ("Closest", "Linear", "Cubic")
EXTENSIONS = ("REPEAT", "EXTEND", "CLIP", "MIRROR")
INTERPOLATION_SPACES = ("linear", "srgb")


def colour_channels(channels: int) -> int:
    """How many leading channels of a 1–4-channel image are colour (the rest, if any, is alpha)."""
    return 1 if channels <= 2 else 3


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """Cycles' sRGB decoding (util/color.h color_srgb_to_linear): IEC 61966-2-1, the power law
    continued above 1, negative values → 0; float64 in, float64 out."""
    return np.maximum(srgb_to_linear(encoded), 0.0)


#: |u| from which every float64 is a whole number: there the image repeats (mirrors) with period 1 (2), and
#: EXTEND/CLIP give what they give at u = 2 or -1, so coordinates are reduced first (no overflow below).
_WHOLE = 2.0 ** 52


def _reduce_coordinates(uv: np.ndarray, extension: str) -> np.ndarray:
    """``uv`` (2, N) with huge coordinates (|u| ≥ 2⁵²) replaced by equivalent small ones for the
    extension, and non-finite ones (an overflow of extreme vertex UVs) by 0; others unchanged."""
    big = ~(np.abs(uv) < _WHOLE)
    if not big.any():
        return uv
    period = {"REPEAT": 1.0, "MIRROR": 2.0}.get(extension)
    with np.errstate(invalid="ignore"):
        reduced = np.mod(uv, period) if period is not None else np.clip(uv, -1.0, 2.0)
    reduced = np.where(np.isfinite(uv), reduced, 0.0)
    return np.where(big, reduced, uv)


def _wrap(i: np.ndarray, n: int, extension: str) -> tuple[np.ndarray, np.ndarray | None]:
    """Pixel indices i (any integers) mapped into [0, n) and, for CLIP, which were inside."""
    if extension == "REPEAT":
        return np.mod(i, n), None
    if extension == "EXTEND":
        return np.clip(i, 0, n - 1), None
    if extension == "MIRROR":
        m = np.mod(i, 2 * n)
        return np.where(m < n, m, 2 * n - 1 - m), None
    inside = (i >= 0) & (i < n)
    return np.clip(i, 0, n - 1), inside


def cubic_bspline_weights(t: np.ndarray) -> tuple[np.ndarray, ...]:
    """Uniform cubic B-spline weights of the pixels at offsets −1, 0, 1, 2 for a fraction t ∈ [0, 1)."""
    s = 1.0 - t
    t2 = t * t
    t3 = t2 * t
    return (s * s * s / 6.0, (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0, (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
            t3 / 6.0)


class Texture:
    """Base class: ``eval(points) -> (channels, N)`` and the range of values it can return."""

    channels: int = 3
    name: str = "texture"

    def eval(self, points) -> np.ndarray:
        raise NotImplementedError

    def value_range(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-channel (lo, hi) bounds of every value ``eval`` can return (C,) each."""
        raise NotImplementedError

    def texels_per_triangle(self, attributes, prim: np.ndarray) -> np.ndarray:
        """How many texels (T,) each triangle ``prim`` covers (the resolution at which its mean is to
        be estimated; 0 where the texture is smooth over it)."""
        return np.zeros(len(prim))

    def may_be_positive(self, attributes, prim: np.ndarray, channels: tuple) -> np.ndarray:
        """(T,) bool, conservative: False only where every value ``eval`` can return on triangle
        ``prim`` (vertex attributes ``attributes``) is ≤ 0 in each of the ``channels``."""
        return np.ones(len(prim), bool)


class ImageTexture(Texture):
    """An image (float32 (H, W, C), row 0 at v = 0) looked up by UV; see the module docstring.

    ``pixels``: linear values (``interpolation_space="linear"``) or, for ``"srgb"``, the sRGB-encoded
    values of the colour channels (alpha linear), as floats or as the unsigned integer codes of an
    8/16-bit image (value = code / full scale; 4–8 times less memory, as Cycles' byte images).
    ``linear_pixels``: the decoded texels (float32) either way."""

    def __init__(self, pixels: np.ndarray, interpolation: str = "Linear", extension: str = "REPEAT",
                 name: str = "image", field: str = "", uv_transform: tuple | None = None,
                 interpolation_space: str = "linear"):
        if interpolation not in INTERPOLATIONS:
            raise SceneError(f"{field}.interpolation" if field else "interpolation",
                             f"must be one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
        if extension not in EXTENSIONS:
            raise SceneError(f"{field}.extension" if field else "extension",
                             f"must be one of {', '.join(EXTENSIONS)}, got {extension!r}")
        if interpolation_space not in INTERPOLATION_SPACES:
            raise SceneError(f"{field}.interpolation_space" if field else "interpolation_space",
                             f"must be one of {', '.join(INTERPOLATION_SPACES)}, got {interpolation_space!r}")
        pixels = np.asarray(pixels)
        if pixels.ndim == 2:
            pixels = pixels[:, :, None]
        if pixels.ndim != 3 or pixels.shape[0] < 1 or pixels.shape[1] < 1 or not 1 <= pixels.shape[2] <= 4:
            raise SceneError(field, f"an image must be (height, width, 1–4 channels), got shape {pixels.shape}")
        #: full scale of integer codes (None: float texels)
        self._code_scale = None
        if pixels.dtype.kind == "u":
            if interpolation_space != "srgb":
                raise SceneError(field or "pixels", "integer texels are only taken as sRGB-encoded codes "
                                                    "(interpolation_space 'srgb')")
            self._code_scale = float(np.iinfo(pixels.dtype).max)
        elif pixels.dtype.kind != "f":
            raise SceneError(field or "pixels", f"texels must be floats or unsigned integer codes, got {pixels.dtype}")
        if not np.all(np.isfinite(pixels)):
            raise SceneError(field, f"image {name!r} has non-finite pixel values")
        # one layout and read-only (a view: the caller's array keeps its flags), whether the texels come from a
        # file (read-only) or from Blender: the compiled lookups' one precompiled signature
        pixels = np.ascontiguousarray(pixels).view()
        pixels.flags.writeable = False
        self.pixels = pixels
        self.height, self.width, self.channels = pixels.shape
        self.interpolation, self.extension, self.name = interpolation, extension, name
        self.interpolation_space = interpolation_space
        self.linear_pixels = pixels
        self._colour = colour_channels(self.channels)
        if interpolation_space == "srgb":
            # decoded texels rounded to float32, exactly what decoding at load time stored: Closest
            # lookups and texel centres keep those values, and value_range is theirs
            encoded = self._values(pixels)
            decoded = encoded.copy()
            decoded[..., :self._colour] = srgb_decode(encoded[..., :self._colour])
            decoded = decoded.astype(np.float32)
            decoded.setflags(write=False)
            self.linear_pixels = decoded
            flat = encoded.reshape(-1, self.channels)[:, :self._colour]
            # filtered encoded values are kept within the texels' range (convex weights; this only
            # removes float64 rounding), so every lookup stays within value_range
            lo, hi = flat.min(axis=0), flat.max(axis=0)
            self._encoded_range = (np.minimum(lo, 0.0), hi) if extension == "CLIP" else (lo, hi)
        #: (A (2, 2), b (2,)) or None: the image is looked up at A·uv + b (Blender's Mapping node);
        #: ``lookup`` takes the mesh's UVs, so differences along them (bump maps) stay correct
        self.uv_transform = None
        if uv_transform is not None:
            A, b = np.asarray(uv_transform[0], np.float64), np.asarray(uv_transform[1], np.float64)
            if A.shape != (2, 2) or b.shape != (2,) or not (np.all(np.isfinite(A)) and np.all(np.isfinite(b))):
                raise SceneError(field or "uv_transform", "must be a finite 2×2 matrix and a 2-vector")
            self.uv_transform = (A, b)

    def __repr__(self):
        extra = "" if self.uv_transform is None else \
            f", UV {np.round(self.uv_transform[0], 4).tolist()} + {np.round(self.uv_transform[1], 4).tolist()}"
        if self.interpolation_space != "linear":
            extra += f", {self.interpolation_space}"
        return (f"ImageTexture({self.name!r}, {self.width}×{self.height}×{self.channels}, "
                f"{self.interpolation}, {self.extension}{extra})")

    def value_range(self):
        # "srgb": the decoding is monotone, so the bounds are those of the decoded texels
        flat = self.linear_pixels.reshape(-1, self.channels)
        lo, hi = flat.min(axis=0).astype(np.float64), flat.max(axis=0).astype(np.float64)
        if self.extension == "CLIP":        # outside the image: 0
            lo, hi = np.minimum(lo, 0.0), np.maximum(hi, 0.0)
        return lo, hi

    def _values(self, texels: np.ndarray) -> np.ndarray:
        """Stored texels as float64 values (integer codes divided by their full scale; alpha then
        rounded to float32, the values linear_pixels holds, as an image decoded at load time)."""
        out = texels.astype(np.float64)
        if self._code_scale is None:
            return out
        out /= self._code_scale
        out[..., self._colour:] = out[..., self._colour:].astype(np.float32)
        return out

    def _texels(self, i: np.ndarray, j: np.ndarray, pixels: np.ndarray | None = None) -> np.ndarray:
        """Pixel values (N, C) float64 of ``pixels`` (default: the stored texels) at integer pixel
        coordinates (wrapped per the extension)."""
        ii, in_x = _wrap(i, self.width, self.extension)
        jj, in_y = _wrap(j, self.height, self.extension)
        out = self._values(self.pixels[jj, ii]) if pixels is None else pixels[jj, ii].astype(np.float64)
        if in_x is not None:
            out *= (in_x & in_y)[:, None]
        return out

    def lookup(self, uv: np.ndarray) -> np.ndarray:
        """Values (C, N) at texture coordinates uv (2, N)."""
        if self.uv_transform is not None:
            uv = self.uv_transform[0] @ uv + self.uv_transform[1][:, None]
        uv = _reduce_coordinates(uv, self.extension)
        if self.interpolation == "Linear":
            return bilinear_lookup(self, uv)
        return self._filtered(uv)

    def _filtered(self, uv: np.ndarray) -> np.ndarray:
        """Values (C, N) at reduced texture coordinates uv (2, N) (after the transform): the NumPy filter."""
        x = uv[0] * self.width
        y = uv[1] * self.height
        if self.interpolation == "Closest":
            return self._texels(np.floor(x).astype(np.int64), np.floor(y).astype(np.int64), self.linear_pixels).T
        x = x - 0.5
        y = y - 0.5
        x0 = np.floor(x)
        y0 = np.floor(y)
        fx, fy = x - x0, y - y0
        i0, j0 = x0.astype(np.int64), y0.astype(np.int64)
        if self.interpolation == "Linear":
            wx = (1.0 - fx, fx)
            wy = (1.0 - fy, fy)
            offsets = (0, 1)
        else:
            wx = cubic_bspline_weights(fx)
            wy = cubic_bspline_weights(fy)
            offsets = (-1, 0, 1, 2)
        out = np.zeros((uv.shape[1], self.channels))
        for b, dj in enumerate(offsets):
            row = np.zeros_like(out)
            for a, di in enumerate(offsets):
                row += self._texels(i0 + di, j0 + dj) * wx[a][:, None]
            out += row * wy[b][:, None]
        if self.interpolation_space == "srgb":
            c = self._colour
            encoded = np.clip(out[:, :c], *self._encoded_range)
            # decoded in float64, rounded to float32 as the decoded texels are (texel centres exact)
            out[:, :c] = srgb_decode(encoded).astype(np.float32)
        return out.T

    def eval(self, points) -> np.ndarray:
        return self.lookup(points.uv())

    #: the texel footprint test pools the image to at most this many blocks a side
    FOOTPRINT_BLOCKS = 1024

    def _triangle_uv(self, attributes, prim: np.ndarray) -> np.ndarray:
        """The corners' lookup coordinates (T, 3, 2) of triangles ``prim`` (after the UV transform)."""
        if attributes.uv is None:
            uv = np.zeros((len(prim), 3, 2))
        else:
            uv = attributes.uv[attributes.faces[prim]].astype(np.float64)
        if self.uv_transform is not None:
            A, b = self.uv_transform
            uv = uv @ A.T + b
        return uv

    def texels_per_triangle(self, attributes, prim):
        uv = self._triangle_uv(attributes, prim)
        e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) * (self.width * self.height)
        return np.where(np.isfinite(area), area, 0.0)

    def may_be_positive(self, attributes, prim, channels):
        """The texels that lookups inside a triangle read with a weight > 0 lie in a range about its UV
        bounding box (Closest: the texels it overlaps; Linear: ± 1½ texels; Cubic: ± 2½), wrapped per
        the extension; a triangle may be positive if any of them is (checked in the image pooled to
        blocks of texels, so a superset).  Lookups exactly on the triangle's edges (a set of zero
        area) may read a texel beyond."""
        uv = self._triangle_uv(attributes, prim)
        lo, hi = uv.min(axis=1), uv.max(axis=1)
        known = np.all(np.isfinite(lo) & np.isfinite(hi) & (np.abs(lo) < 2.0 ** 30) & (np.abs(hi) < 2.0 ** 30), axis=1)
        lo, hi = np.where(known[:, None], lo, 0.0), np.where(known[:, None], hi, 0.0)
        # texel k is read with weight > 0 at x = u·size ∈ (k − r, k + 1 + r): it meets (a, b) if
        # a − 1 − r < k < b + r (a point a: closed, widened to whole texels)
        r = {"Closest": 0.0, "Linear": 0.5, "Cubic": 1.5}[self.interpolation]

        def texel_range(a, b):
            flat = b <= a
            return (np.where(flat, np.floor(a - 1.0 - r), np.floor(a - 1.0 - r) + 1).astype(np.int64),
                    np.where(flat, np.ceil(b + r), np.ceil(b + r) - 1).astype(np.int64))

        ax = _axis_interval(*texel_range(lo[:, 0] * self.width, hi[:, 0] * self.width), self.width, self.extension)
        ay = _axis_interval(*texel_range(lo[:, 1] * self.height, hi[:, 1] * self.height), self.height,
                            self.extension)
        positive = np.zeros(self.pixels.shape[:2], bool)
        for c in channels:
            positive |= self.pixels[:, :, c] > 0
        block = max(1, -(-max(self.width, self.height) // self.FOOTPRINT_BLOCKS))
        hb, wb = -(-self.height // block), -(-self.width // block)
        padded = np.zeros((hb * block, wb * block), bool)
        padded[:self.height, :self.width] = positive
        pooled = padded.reshape(hb, block, wb, block).any(axis=(1, 3))
        table = np.zeros((hb + 1, wb + 1), np.int64)
        table[1:, 1:] = pooled.cumsum(0).cumsum(1)
        x0, x1, y0, y1 = ax[0] // block, ax[1] // block + 1, ay[0] // block, ay[1] // block + 1
        count = table[y1, x1] - table[y0, x1] - table[y1, x0] + table[y0, x0]
        return ~known | (~(ax[2] | ay[2]) & (count > 0))


def bilinear_lookup_numpy(texture: ImageTexture, uv: np.ndarray) -> np.ndarray:
    """Values (C, N) of a Linear ``texture`` at reduced texture coordinates uv (2, N): its NumPy filter."""
    return texture._filtered(uv)


def bilinear_lookup_numba(texture: ImageTexture, uv: np.ndarray) -> np.ndarray:
    """bilinear_lookup_numpy in one compiled loop (engine.kernels.texture_lookup), the same values."""
    out = np.empty((texture.channels, uv.shape[1]))
    srgb = texture.interpolation_space == "srgb"
    lo, hi = texture._encoded_range if srgb else (_NO_RANGE, _NO_RANGE)
    bilinear_loop(np.ascontiguousarray(uv, np.float64), texture.pixels, texture.width, texture.height,
                  EXTENSIONS.index(texture.extension), texture._code_scale or 0.0, texture._colour, srgb,
                  np.ascontiguousarray(lo, np.float64), np.ascontiguousarray(hi, np.float64), out)
    return out


_NO_RANGE = np.zeros(1)
#: A Linear image texture's lookup at reduced coordinates, compiled where available.
bilinear_lookup = twin(bilinear_loop and bilinear_lookup_numba, bilinear_lookup_numpy)


def _axis_interval(lo: np.ndarray, hi: np.ndarray, n: int, extension: str):
    """(a, b, empty): one interval [a, b] ⊂ [0, n) holding every pixel index the integer range
    [lo, hi] wraps to under the extension (a superset where it wraps into two pieces), and where
    it holds none (CLIP beyond the image)."""
    empty = np.zeros(lo.shape, bool)
    if extension == "EXTEND":
        return np.clip(lo, 0, n - 1), np.clip(hi, 0, n - 1), empty
    if extension == "CLIP":
        a, b = np.maximum(lo, 0), np.minimum(hi, n - 1)
        return np.minimum(a, n - 1), np.maximum(b, 0), a > b
    full = hi - lo + 1 >= n
    if extension == "REPEAT":
        a, b = np.mod(lo, n), np.mod(hi, n)
        full |= a > b
    else:       # MIRROR: period 2n, pixel m < n → m, else 2n − 1 − m; a range shorter than n crosses ≤ 1 fold
        m_lo = np.mod(lo, 2 * n)
        m_hi = m_lo + (hi - lo)
        f_lo = np.where(m_lo < n, m_lo, 2 * n - 1 - m_lo)
        m_hi_w = np.mod(m_hi, 2 * n)
        f_hi = np.where(m_hi_w < n, m_hi_w, 2 * n - 1 - m_hi_w)
        same = m_lo // n == m_hi // n
        top = m_lo < n          # crossing from the rising piece into the falling one: the fold at n − 1
        a = np.where(same | top, np.minimum(f_lo, f_hi), 0)
        b = np.where(same, np.maximum(f_lo, f_hi), np.where(top, n - 1, np.maximum(f_lo, f_hi)))
    return np.where(full, 0, a), np.where(full, n - 1, b), empty


class VertexColour(Texture):
    """A colour attribute (per-vertex values, linear) of the meshes, by name; 0 where a mesh lacks it."""

    def __init__(self, layer: str, channels: int = 3):
        self.layer, self.channels, self.name = layer, channels, layer

    def __repr__(self):
        return f"VertexColour({self.layer!r})"

    def value_range(self):
        # vertex colours are checked by the scene loader where meshes are read; interpolation
        # stays within their range (convex weights)
        return np.zeros(self.channels), np.ones(self.channels)

    def eval(self, points) -> np.ndarray:
        return points.attribute(self.layer, self.channels)

    def may_be_positive(self, attributes, prim, channels):
        """Interpolation within a triangle is convex: positive somewhere only if at a corner."""
        layer = attributes.layers.get(self.layer)
        if layer is None:
            return np.zeros(len(prim), bool)
        corners = layer[attributes.faces[prim]]           # (T, 3, C)
        cols = [c for c in channels if c < layer.shape[1]]
        return np.any(corners[:, :, cols] > 0, axis=(1, 2)) if cols else np.zeros(len(prim), bool)
