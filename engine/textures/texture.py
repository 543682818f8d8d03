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
  ``"CLIP"`` (0: transparent black), ``"MIRROR"`` (tile, every other tile mirrored).
- :class:`VertexColour`: a per-vertex colour attribute interpolated over each triangle
  (Blender's Color Attribute node), in linear values.
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError

INTERPOLATIONS = ("Closest", "Linear", "Cubic")
EXTENSIONS = ("REPEAT", "EXTEND", "CLIP", "MIRROR")


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


class ImageTexture(Texture):
    """An image (float32 (H, W, C), linear values, row 0 at v = 0) looked up by UV; see the module docstring."""

    def __init__(self, pixels: np.ndarray, interpolation: str = "Linear", extension: str = "REPEAT",
                 name: str = "image", field: str = "", uv_transform: tuple | None = None):
        if interpolation not in INTERPOLATIONS:
            raise SceneError(f"{field}.interpolation" if field else "interpolation",
                             f"must be one of {', '.join(INTERPOLATIONS)}, got {interpolation!r}")
        if extension not in EXTENSIONS:
            raise SceneError(f"{field}.extension" if field else "extension",
                             f"must be one of {', '.join(EXTENSIONS)}, got {extension!r}")
        pixels = np.asarray(pixels)
        if pixels.ndim == 2:
            pixels = pixels[:, :, None]
        if pixels.ndim != 3 or pixels.shape[0] < 1 or pixels.shape[1] < 1 or not 1 <= pixels.shape[2] <= 4:
            raise SceneError(field, f"an image must be (height, width, 1–4 channels), got shape {pixels.shape}")
        if not np.all(np.isfinite(pixels)):
            raise SceneError(field, f"image {name!r} has non-finite pixel values")
        self.pixels = pixels
        self.height, self.width, self.channels = pixels.shape
        self.interpolation, self.extension, self.name = interpolation, extension, name
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
        return (f"ImageTexture({self.name!r}, {self.width}×{self.height}×{self.channels}, "
                f"{self.interpolation}, {self.extension}{extra})")

    def value_range(self):
        flat = self.pixels.reshape(-1, self.channels)
        lo, hi = flat.min(axis=0).astype(np.float64), flat.max(axis=0).astype(np.float64)
        if self.extension == "CLIP":        # outside the image: 0
            lo, hi = np.minimum(lo, 0.0), np.maximum(hi, 0.0)
        return lo, hi

    def _texels(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Pixel values (N, C) float64 at integer pixel coordinates (wrapped per the extension)."""
        ii, in_x = _wrap(i, self.width, self.extension)
        jj, in_y = _wrap(j, self.height, self.extension)
        out = self.pixels[jj, ii].astype(np.float64)
        if in_x is not None:
            out *= (in_x & in_y)[:, None]
        return out

    def lookup(self, uv: np.ndarray) -> np.ndarray:
        """Values (C, N) at texture coordinates uv (2, N)."""
        if self.uv_transform is not None:
            uv = self.uv_transform[0] @ uv + self.uv_transform[1][:, None]
        x = uv[0] * self.width
        y = uv[1] * self.height
        if self.interpolation == "Closest":
            return self._texels(np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)).T
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
        return out.T

    def eval(self, points) -> np.ndarray:
        return self.lookup(points.uv())


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
