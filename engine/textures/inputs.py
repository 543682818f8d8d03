"""Material parameters that vary over a surface: a texture plus how its values become the parameter.

Scene files give a texturable parameter either a constant (as before) or an object::

    {"texture": "wood.png", "color_space": "sRGB", "interpolation": "Linear", "extension": "REPEAT",
     "channel": "R", "scale": 1.0, "offset": 0.0}
    {"vertex_color": "Col", "scale": 1.0}

(paths relative to the scene file).  The parameter's value at a point is offset + scale·t, where t
is the texture's value: for a spectrum its RGB (a 1-channel texture is grey), upsampled per point
exactly as a constant [r, g, b] (engine.spectral, Mallett & Yuksel); for a number one channel
(``channel``; default: the only channel of a grey image, else the Rec. 709 luminance, which is
Blender's colour-to-number conversion).

:class:`TexturedSpectrum` is a Spectrum that can only be evaluated at surface points
(``ShadingPoint.spectrum`` does that); :class:`TexturedNumber` stands for a number
(``ShadingPoint.number``).  Both keep the bounds of every value they can take, which the scene
loader checks against the parameter's declared range.  Texels are float32: a texel meant as a range
limit (roughness 1e-4) may be stored one rounding below it (9.99999975e-05), so values that equal a
closed limit in float32 are accepted and clipped to the limit (:meth:`TexturedNumber.clamped_to`).
"""

from __future__ import annotations

import math
import os

import numpy as np

from .image import COLOR_SPACES, default_color_space, read_texture
from .texture import EXTENSIONS, INTERPOLATIONS, ImageTexture, Texture, VertexColour
from ..errors import SceneError
from ..spectral import GRID_NM, Spectrum, d65_normalised, spectrum_to_linear_srgb
from ..spectral.cie import LUMINANCE_WEIGHTS, luminance
from ..spectral.spectrum import basis_rgb

CHANNELS = ("R", "G", "B", "A", "luminance")
_KEYS_IMAGE = {"texture", "color_space", "interpolation", "extension", "channel", "scale", "offset", "note"}
_KEYS_VERTEX = {"vertex_color", "channel", "scale", "offset", "note"}


class TextureInput:
    """A texture and the map from its values to a parameter: offset + scale·t^power, t the channel
    or RGB.  ``power`` (default 1) is for parameters that are a power of what artists paint, e.g.
    the Blender exporter's Beckmann m = roughness² (the square of the interpolated value, as
    Cycles' α = r²); with power ≠ 1 every value the texture can give must be ≥ 0."""

    def __init__(self, texture: Texture, channel: str | None = None, scale: float = 1.0, offset: float = 0.0,
                 power: float = 1.0):
        self.texture, self.channel, self.scale, self.offset = texture, channel, float(scale), float(offset)
        self.power = float(power)
        if not (np.isfinite(self.power) and self.power > 0):
            raise ValueError(f"texture power must be a finite number > 0, got {power!r}")

    def __repr__(self):
        extra = "" if self.channel is None else f", channel={self.channel!r}"
        if self.power != 1.0:
            extra += f", power={self.power:g}"
        return f"TextureInput({self.texture!r}{extra}, scale={self.scale:g}, offset={self.offset:g})"

    def _map(self, t):
        if self.power != 1.0:
            t = np.maximum(t, 0.0) ** self.power
        if self.scale == 1.0 and self.offset == 0.0:
            return t
        return self.offset + self.scale * t

    def _grey(self) -> bool:
        return self.texture.channels <= 2

    def _scalar_of(self, values: np.ndarray) -> np.ndarray:
        """One channel (…) of texture values (C, …) per ``channel``."""
        ch = self.channel
        if ch is None:
            ch = "R" if self._grey() else "luminance"
        if ch == "luminance":
            if self._grey():
                return values[0]
            w = LUMINANCE_WEIGHTS
            return w[0] * values[0] + w[1] * values[1] + w[2] * values[2]
        index = "RGBA".index(ch)
        if self._grey():      # grey (+ alpha) images: R = G = B = grey
            index = 0 if index < 3 else 1
        return values[index]

    def channels_read(self) -> tuple:
        """The texture channels the parameter's values depend on."""
        grey = self._grey()
        ch = self.channel
        if ch is None or ch == "luminance":
            return (0,) if grey else (0, 1, 2)
        index = "RGBA".index(ch)
        return ((0 if index < 3 else 1),) if grey else (index,)

    def may_be_positive(self, attributes, prim: np.ndarray) -> np.ndarray:
        """(T,) bool, conservative: False only where the parameter is ≤ 0 in every channel all over
        triangle ``prim`` (so an emitter's radiance, clipped at 0, is 0 there)."""
        if self.offset > 0 or self.scale < 0:
            return np.ones(len(prim), bool)
        if self.scale == 0:
            return np.zeros(len(prim), bool)
        # offset ≤ 0 < scale: values of texels ≤ 0 (weights ≥ 0: every filter's) map to ≤ 0
        return self.texture.may_be_positive(attributes, prim, self.channels_read())

    def number(self, points) -> np.ndarray:
        """The parameter (N,) at the points."""
        return points.memo((self, "number"), lambda: self._map(self._scalar_of(self.texture.eval(points))))

    def number_at_uv(self, uv: np.ndarray) -> np.ndarray:
        """The parameter (N,) at texture coordinates uv (2, N) (image textures: e.g. a bump map's
        heights at shifted coordinates)."""
        return self._map(self._scalar_of(self.texture.lookup(uv)))

    def rgb(self, points) -> np.ndarray:
        """The parameter as linear RGB (3, N) at the points (grey textures and ``channel``: r = g = b)."""
        def compute():
            t = self.texture.eval(points)
            if self.channel is not None or self._grey():
                s = self._scalar_of(t)
                return self._map(np.stack((s, s, s)))
            return self._map(t[:3])
        return points.memo((self, "rgb"), compute)

    def bounds(self, rgb: bool) -> tuple[float, float]:
        """(lo, hi) over every value the parameter can take (from the texture's per-channel bounds;
        a channel choice and the luminance are monotone in them, the weights being ≥ 0)."""
        lo, hi = (np.asarray(v, np.float64) for v in self.texture.value_range())
        if rgb and self.channel is None and not self._grey():
            lo, hi = float(np.min(lo[:3])), float(np.max(hi[:3]))
        else:
            lo, hi = float(self._scalar_of(lo[:, None])[0]), float(self._scalar_of(hi[:, None])[0])
        if self.power != 1.0:
            if lo < 0:
                raise ValueError(f"a texture raised to the power {self.power:g} must have values >= 0, "
                                 f"{self.texture!r} reaches {lo:g}")
            lo, hi = lo ** self.power, hi ** self.power
        a, b = self.offset + self.scale * lo, self.offset + self.scale * hi
        return min(a, b), max(a, b)


def _clipped_bounds(lo: float, hi: float, clip) -> tuple[float, float]:
    """The bounds [lo, hi] of a textured value after clipping to ``clip`` (None: unchanged)."""
    if clip is None:
        return lo, hi
    return min(max(lo, clip[0]), clip[1]), max(min(hi, clip[1]), clip[0])


def _float32_clip(lo: float, hi: float, limit_lo: float, limit_hi: float, clip):
    """The clip interval of a textured value with bounds [lo, hi] against closed limits: a limit it
    crosses by no more than float32 rounding (equal to it in float32) is added to ``clip`` (None: no
    clip yet); a bound further out is left for the caller's range check to refuse."""
    new_lo, new_hi = clip if clip is not None else (-math.inf, math.inf)
    if lo < limit_lo and np.float32(lo) >= np.float32(limit_lo):
        new_lo = max(new_lo, limit_lo)
    if hi > limit_hi and np.float32(hi) <= np.float32(limit_hi):
        new_hi = min(new_hi, limit_hi)
    return clip if (new_lo, new_hi) == (-math.inf, math.inf) else (new_lo, new_hi)


class TexturedNumber:
    """A number parameter that varies over the surface (see ``ShadingPoint.number``); ``clip``:
    (lo, hi) its values are clipped to (see :meth:`clamped_to`), None for none."""

    def __init__(self, source: TextureInput, clip: tuple[float, float] | None = None):
        self.source, self.clip = source, clip
        self.lo, self.hi = _clipped_bounds(*source.bounds(rgb=False), clip)

    def clamped_to(self, lo: float = -math.inf, hi: float = math.inf) -> TexturedNumber:
        """This parameter clipped to the closed limits [lo, hi] it reaches beyond only by float32
        rounding (a texel stored as float32 9.99999975e-05 for the limit 1e-4); itself otherwise, so
        a value really out of range stays for the range check to refuse."""
        clip = _float32_clip(self.lo, self.hi, lo, hi, self.clip)
        return self if clip == self.clip else TexturedNumber(self.source, clip)

    def at(self, points) -> np.ndarray:
        values = self.source.number(points)
        return values if self.clip is None else np.clip(values, *self.clip)

    def __float__(self):
        raise TypeError("a textured parameter has no single value: evaluate it at surface points")

    def as_spectrum(self, kind: str = "unbounded") -> TexturedSpectrum:
        """The same values as a grey (λ-independent) textured spectrum (e.g. a coat's real index)."""
        src = self.source
        channel = src.channel or ("R" if src._grey() else "luminance")
        return TexturedSpectrum(TextureInput(src.texture, channel, src.scale, src.offset, src.power), kind,
                                self.clip)

    def __repr__(self):
        return f"TexturedNumber({self.source!r})"


def _illuminant_rgb_matrix() -> tuple[np.ndarray, np.ndarray]:
    """(M (3, 3), white (3,)): the linear sRGB that D65n(λ)·B_i(λ) develops to (column i; the exact
    integral on the 1 nm grid, as a constant light's ``rgb()``), and that D65n itself develops to."""
    global _ILLUMINANT_RGB
    if _ILLUMINANT_RGB is None:
        d65 = d65_normalised(GRID_NM)
        basis = basis_rgb(GRID_NM)
        M = np.stack([spectrum_to_linear_srgb(d65 * basis[i]) for i in range(3)], axis=1)
        white = spectrum_to_linear_srgb(d65)
        M.setflags(write=False)
        white.setflags(write=False)
        _ILLUMINANT_RGB = (M, white)
    return _ILLUMINANT_RGB


_ILLUMINANT_RGB = None


class SquaredNumber(TexturedNumber):
    """The square of a textured number x (any affine map of its texels): x² per point, clipped to ``clip``;
    e.g. α = r² of a roughness texture whose values are offset + scale·t."""

    def __init__(self, of: TexturedNumber, clip: tuple[float, float] | None = None):
        self.of, self.source, self.clip = of, of.source, clip
        lo, hi = of.lo, of.hi
        sq_lo = 0.0 if lo <= 0.0 <= hi else min(lo * lo, hi * hi)
        self.lo, self.hi = _clipped_bounds(sq_lo, max(lo * lo, hi * hi), clip)

    def clamped_to(self, lo: float = -math.inf, hi: float = math.inf) -> SquaredNumber:
        clip = _float32_clip(self.lo, self.hi, lo, hi, self.clip)
        return self if clip == self.clip else SquaredNumber(self.of, clip)

    def at(self, points) -> np.ndarray:
        x = self.of.at(points)
        values = x * x
        return values if self.clip is None else np.clip(values, *self.clip)

    def __repr__(self):
        return f"SquaredNumber({self.of!r})"


class TexturedSpectrum(Spectrum):
    """A spectrum parameter given by an RGB texture: per point the RGB upsampling of a constant
    [r, g, b] with the texel's values (r = g = b gives exactly that constant).

    Kind ``"illuminant"`` (an emitter's radiance, :func:`textured_emission`): per point exactly what
    a constant ``RGBIlluminantSpectrum`` of the texel's colour is, D65n(λ)·(r B_r + g B_g + b B_b)(λ)
    (r = g = b: r·D65n); in RGB :meth:`linear_srgb_at` (that spectrum integrated against the CIE
    observer, as a constant light's ``rgb()``); mono the luminance."""

    is_constant = False

    def __init__(self, source: TextureInput, kind: str = "reflectance", clip: tuple[float, float] | None = None):
        self.source, self.kind, self.clip = source, kind, clip
        self.lo, self.hi = _clipped_bounds(*source.bounds(rgb=True), clip)

    def clamped_to(self, lo: float = -math.inf, hi: float = math.inf) -> TexturedSpectrum:
        """As :meth:`TexturedNumber.clamped_to`, on the texels' RGB values."""
        clip = _float32_clip(self.lo, self.hi, lo, hi, self.clip)
        return self if clip == self.clip else TexturedSpectrum(self.source, self.kind, clip)

    def __repr__(self):
        return f"TexturedSpectrum({self.source!r})"

    def _eval(self, lam):
        raise TypeError("a textured spectrum varies over the surface: evaluate it with ShadingPoint.spectrum")

    @property
    def mono_value(self) -> float:
        raise TypeError("a textured spectrum varies over the surface: it has no single mono value")

    def linear_srgb(self) -> np.ndarray:
        raise TypeError("a textured spectrum varies over the surface: it has no single colour")

    def rgb_at(self, points) -> np.ndarray:
        """The texels' RGB (3, N) at the points, mapped (scale, offset) and clipped."""
        rgb = self.source.rgb(points)
        return rgb if self.clip is None else np.clip(rgb, *self.clip)

    def at(self, points, lam: np.ndarray, mono: bool, basis: np.ndarray | None = None,
           d65: np.ndarray | None = None) -> np.ndarray:
        """Values (L, N) at the points and their wavelengths ``lam`` (L, N) (mono: the luminance);
        ``basis``, ``d65``: the RGB basis and (illuminants) D65n at ``lam``, if already looked up."""
        def compute():
            rgb = self.rgb_at(points)
            if mono:
                return np.broadcast_to(luminance(rgb.T)[None, :], lam.shape).copy()
            b = basis if basis is not None else basis_rgb(lam)
            value = rgb[0][None, :] * b[0] + rgb[1][None, :] * b[1] + rgb[2][None, :] * b[2]
            grey = (rgb[0] == rgb[1]) & (rgb[1] == rgb[2])
            value = np.where(grey[None, :], rgb[0][None, :], value)
            if self.kind == "illuminant":
                value = value * (d65 if d65 is not None else d65_normalised(lam))
            return value
        return points.memo((self, mono, lam.shape[0]), compute)

    def linear_srgb_at(self, points) -> np.ndarray:
        """Linear sRGB (3, N) the values at the points develop to: for an illuminant the exact
        integral of its spectrum against the CIE observer (the expectation of the spectral estimator,
        as a constant light's ``rgb()``), else the texels' RGB."""
        def compute():
            rgb = self.rgb_at(points)
            if self.kind != "illuminant":
                return rgb
            M, white = _illuminant_rgb_matrix()
            grey = (rgb[0] == rgb[1]) & (rgb[1] == rgb[2])
            return np.where(grey[None, :], white[:, None] * rgb[0][None, :], M @ rgb)
        return points.memo((self, "linear_srgb"), compute)

    def luminance_at(self, points) -> np.ndarray:
        """Luminance (N,) of :meth:`linear_srgb_at` (an emitter's importance)."""
        return luminance(self.linear_srgb_at(points).T)


def textured_emission(source: TextureInput, strength: float = 1.0, field: str = "emission") -> TexturedSpectrum:
    """An emitter's radiance that varies over its surface: strength × the texture's RGB at each point,
    as a spectrum exactly as a constant ``RGBIlluminantSpectrum(rgb, strength)`` (Blender: an Image
    Texture into Emission Color, × Emission Strength).  Give it as a Mesh's ``emission``.  Negative
    values (HDR tools write some) emit nothing."""
    strength = float(strength)
    if not (math.isfinite(strength) and strength >= 0):
        raise SceneError(f"{field}.radiance", f"must be a finite number ≥ 0, got {strength!r}")
    scaled = TextureInput(source.texture, source.channel, source.scale * strength, source.offset * strength,
                          source.power)
    lo, _ = scaled.bounds(rgb=True)
    return TexturedSpectrum(scaled, "illuminant", (0.0, math.inf) if lo < 0 else None)


def textured(*values) -> bool:
    """True if any of the values is a texture-driven parameter."""
    return any(isinstance(v, (TexturedNumber, TexturedSpectrum)) for v in values)


def parse_texture_input(raw: dict, field: str, base_dir: str | None) -> TextureInput:
    """A TextureInput from a scene-file object (see the module docstring); errors name ``field.key``."""
    is_image = "texture" in raw
    if is_image == ("vertex_color" in raw):
        raise SceneError(field, "a texture object needs exactly one of 'texture' (an image file) or "
                                "'vertex_color' (a colour attribute name)")
    allowed = _KEYS_IMAGE if is_image else _KEYS_VERTEX
    extra = sorted(set(raw) - allowed)
    if extra:
        raise SceneError(f"{field}.{extra[0]}", f"unknown key (allowed: {', '.join(sorted(allowed))})")

    def num(key, default):
        v = raw.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
            raise SceneError(f"{field}.{key}", f"must be a finite number, got {v!r}")
        return float(v)

    channel = raw.get("channel")
    if channel is not None and channel not in CHANNELS:
        raise SceneError(f"{field}.channel", f"must be one of {', '.join(CHANNELS)}, got {channel!r}")
    if is_image:
        path = raw["texture"]
        if not isinstance(path, str) or not path:
            raise SceneError(f"{field}.texture", "must be an image file path (relative to the scene file)")
        full = path if os.path.isabs(path) else os.path.join(base_dir or ".", path)
        space = raw.get("color_space", default_color_space(path))
        if space not in COLOR_SPACES:
            raise SceneError(f"{field}.color_space", f"must be one of {', '.join(COLOR_SPACES)}, got {space!r}")
        interp = raw.get("interpolation", "Linear")
        if interp not in INTERPOLATIONS:
            raise SceneError(f"{field}.interpolation", f"must be one of {', '.join(INTERPOLATIONS)}, got {interp!r}")
        ext = raw.get("extension", "REPEAT")
        if ext not in EXTENSIONS:
            raise SceneError(f"{field}.extension", f"must be one of {', '.join(EXTENSIONS)}, got {ext!r}")
        pixels, interpolation_space = read_texture(full, space, f"{field}.texture")
        texture = ImageTexture(pixels, interp, ext, name=path, field=field, interpolation_space=interpolation_space)
        if channel == "A" and texture.channels not in (2, 4):
            raise SceneError(f"{field}.channel", f"image {path!r} has no alpha channel")
    else:
        layer = raw["vertex_color"]
        if not isinstance(layer, str) or not layer:
            raise SceneError(f"{field}.vertex_color", "must be the name of a colour attribute of the mesh")
        texture = VertexColour(layer, 4 if channel == "A" else 3)
    return TextureInput(texture, channel, num("scale", 1.0), num("offset", 0.0))


class RootSpectrum(TexturedSpectrum):
    """√ of a textured spectrum per point and wavelength (negative values: 0), e.g. the Principled
    transmission tint √(base colour) of a colour texture mapped by scale and offset."""

    def __init__(self, of: TexturedSpectrum):
        self.of, self.source, self.kind, self.clip = of, of.source, "unbounded", None
        self.lo, self.hi = math.sqrt(max(of.lo, 0.0)), math.sqrt(max(of.hi, 0.0))

    def clamped_to(self, lo: float = -math.inf, hi: float = math.inf) -> RootSpectrum:
        return self

    def __repr__(self):
        return f"RootSpectrum({self.of!r})"

    def at(self, points, lam: np.ndarray, mono: bool, basis: np.ndarray | None = None,
           d65: np.ndarray | None = None) -> np.ndarray:
        return points.memo((self, mono, lam.shape[0]),
                           lambda: np.sqrt(np.maximum(self.of.at(points, lam, mono, basis), 0.0)))



class NumberSpectrum(TexturedSpectrum):
    """A λ-independent spectrum whose value at each point is ``fn`` of a textured number there (e.g. the
    Principled dielectric's index from a per-point Specular IOR Level); ``lo``, ``hi`` bound every value fn
    gives on the number's range (the caller states them: fn monotone on it, or wider)."""

    def __init__(self, of: TexturedNumber, fn, lo: float, hi: float):
        self.of, self.fn, self.source, self.kind, self.clip = of, fn, of.source, "unbounded", None
        self.lo, self.hi = float(lo), float(hi)

    def clamped_to(self, lo: float = -math.inf, hi: float = math.inf) -> NumberSpectrum:
        return self

    def __repr__(self):
        return f"NumberSpectrum({self.of!r}, {getattr(self.fn, '__name__', 'fn')})"

    def numbers(self, points) -> np.ndarray:
        """The values (N,) at the points."""
        return points.memo((self, "numbers"), lambda: np.asarray(self.fn(self.of.at(points)), np.float64))

    def at(self, points, lam: np.ndarray, mono: bool, basis: np.ndarray | None = None,
           d65: np.ndarray | None = None) -> np.ndarray:
        return np.broadcast_to(self.numbers(points)[None, :], lam.shape).copy()

    def rgb_at(self, points) -> np.ndarray:
        v = self.numbers(points)
        return np.stack((v, v, v))


class MappedNumber(TexturedNumber):
    """A number that is ``fn`` of a textured number at each point (e.g. the anisotropic GGX α_x of a per-point
    Anisotropic); ``lo``, ``hi`` bound every value fn gives on the number's range (the caller states them)."""

    def __init__(self, of: TexturedNumber, fn, lo: float, hi: float):
        self.of, self.fn, self.source, self.clip = of, fn, of.source, None
        self.lo, self.hi = float(lo), float(hi)

    def clamped_to(self, lo: float = -math.inf, hi: float = math.inf) -> MappedNumber:
        return self

    def at(self, points) -> np.ndarray:
        return points.memo((self, "mapped"), lambda: np.asarray(self.fn(self.of.at(points)), np.float64))

    def __repr__(self):
        return f"MappedNumber({self.of!r}, {getattr(self.fn, '__name__', 'fn')})"


class MappedNumbers(TexturedNumber):
    """A number that is ``fn`` of several numbers at each point, each textured (a TexturedNumber) or constant (e.g.
    the anisotropic GGX α_x of a per-point roughness and a per-point Anisotropic); ``lo``, ``hi`` bound every value
    fn gives on the numbers' ranges (the caller states them)."""

    def __init__(self, of: tuple, fn, lo: float, hi: float):
        self.of, self.fn, self.clip = tuple(of), fn, None
        self.source = next(v.source for v in self.of if isinstance(v, TexturedNumber))
        self.lo, self.hi = float(lo), float(hi)

    def clamped_to(self, lo: float = -math.inf, hi: float = math.inf) -> MappedNumbers:
        return self

    def at(self, points) -> np.ndarray:
        def compute():
            args = (v.at(points) if isinstance(v, TexturedNumber) else v for v in self.of)
            return np.asarray(self.fn(*args), np.float64)
        return points.memo((self, "mapped"), compute)

    def __repr__(self):
        return f"MappedNumbers({', '.join(repr(v) for v in self.of)}, {getattr(self.fn, '__name__', 'fn')})"


class ColouredEmission(TexturedSpectrum):
    """An emitter's radiance whose strength varies over the surface and whose colour is constant (Blender: a
    texture into Emission Strength, a constant Emission Color): per point exactly a constant
    ``RGBIlluminantSpectrum(colour, strength)`` of the texel's strength (``source``: a number, offset + scale·t;
    negative strengths emit nothing)."""

    def __init__(self, source: TextureInput, colour):
        self.source, self.kind = source, "illuminant"
        self.colour = np.maximum(np.asarray(colour, np.float64).reshape(3), 0.0)
        lo, hi = source.bounds(rgb=False)
        self.clip = (0.0, math.inf) if lo < 0 else None
        lo, hi = max(lo, 0.0), max(hi, 0.0)
        self.lo, self.hi = lo * float(self.colour.min()), hi * float(self.colour.max())

    def clamped_to(self, lo: float = -math.inf, hi: float = math.inf) -> ColouredEmission:
        return self

    def scaled(self, weight: float) -> ColouredEmission:
        """The same emission × weight (a shader mix's)."""
        src = self.source
        return ColouredEmission(TextureInput(src.texture, src.channel, src.scale * weight, src.offset * weight,
                                             src.power), self.colour)

    def __repr__(self):
        return f"ColouredEmission({self.source!r}, {self.colour.tolist()})"

    def rgb_at(self, points) -> np.ndarray:
        strength = np.maximum(self.source.number(points), 0.0)
        return self.colour[:, None] * strength[None, :]


class _ProductTexture:
    """What an emitter's estimates read of ``source.texture`` (engine.render.lights.textured) for a product of two
    textures: the finer resolution of the two over each triangle."""

    def __init__(self, *inputs: TextureInput):
        self.inputs = inputs
        self.channels = 3
        self.name = " × ".join(getattr(i.texture, "name", "texture") for i in inputs)

    def texels_per_triangle(self, attributes, prim: np.ndarray) -> np.ndarray:
        return np.maximum.reduce([i.texture.texels_per_triangle(attributes, prim) for i in self.inputs])

    def __repr__(self):
        return f"_ProductTexture({', '.join(repr(i.texture) for i in self.inputs)})"


class _ProductSource:
    """The ``source`` of a :class:`ProductEmission`: its texture (``_ProductTexture``) and where it may emit."""

    def __init__(self, colour: TextureInput, strength: TextureInput):
        self.colour, self.strength = colour, strength
        self.texture = _ProductTexture(colour, strength)

    def may_be_positive(self, attributes, prim: np.ndarray) -> np.ndarray:
        """(T,) bool, conservative: the product is ≤ 0 wherever either factor is."""
        return self.colour.may_be_positive(attributes, prim) & self.strength.may_be_positive(attributes, prim)

    def __repr__(self):
        return f"{self.colour!r} × {self.strength!r}"


class ProductEmission(TexturedSpectrum):
    """An emitter's radiance whose colour and strength both vary over the surface (Blender: a texture into Emission
    Color and another, or the same, into Emission Strength): per point exactly a constant
    ``RGBIlluminantSpectrum(colour, strength)`` of the colour texel and the strength texel there (negative colours
    and strengths emit nothing).  An emitter samples it for next-event estimation by the luminance of that product
    (``luminance_at``: engine.render.lights.textured)."""

    def __init__(self, colour: TextureInput, strength: TextureInput):
        self.colour, self.strength, self.kind, self.clip = colour, strength, "illuminant", None
        self.source = _ProductSource(colour, strength)
        c_lo, c_hi = (max(v, 0.0) for v in colour.bounds(rgb=True))
        s_lo, s_hi = (max(v, 0.0) for v in strength.bounds(rgb=False))
        self.lo, self.hi = c_lo * s_lo, c_hi * s_hi

    def clamped_to(self, lo: float = -math.inf, hi: float = math.inf) -> ProductEmission:
        return self

    def scaled(self, weight: float) -> ProductEmission:
        """The same emission × weight (a shader mix's)."""
        src = self.strength
        return ProductEmission(self.colour, TextureInput(src.texture, src.channel, src.scale * weight,
                                                         src.offset * weight, src.power))

    def __repr__(self):
        return f"ProductEmission({self.colour!r}, {self.strength!r})"

    def rgb_at(self, points) -> np.ndarray:
        strength = np.maximum(self.strength.number(points), 0.0)
        return np.maximum(self.colour.rgb(points), 0.0) * strength[None, :]
