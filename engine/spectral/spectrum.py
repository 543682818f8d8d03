"""Spectral parameters of materials and lights (reflectances, radiances, indices of refraction).

Every ``Spectrum`` evaluates to float64 values at wavelengths in nm:
``eval(lam_nm) -> ndarray`` of lam's shape. With ``mono=True`` it returns its single
monochrome value instead (the renderer's one-wavelength verification mode), which follows
Mitsuba 3's monochrome variants: constants as given, RGB triples -> Rec. 709 luminance,
tables -> luminance of their pre-integrated linear sRGB.

Units: reflectance is dimensionless in [0, 1]; emission is spectral radiance in the renderer's
units, where ``d65_normalised`` (∫ D65n ȳ dλ = 1) has luminance Y = 1 and develops to linear
sRGB (1, 1, 1); n and k are dimensionless.

RGB upsampling uses the Mallett & Yuksel (2019) basis (``data/mallett_yuksel_2019_srgb.csv``):
s(λ) = r B_r(λ) + g B_g(λ) + b B_b(λ), with B_r + B_g + B_b = 1 at every λ. The basis is
linear, so values > 1 (emission, unbounded parameters) need no normalisation by max(rgb):
max · basis(rgb / max) = basis(rgb). Outside 360-830 nm the basis holds its end values.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from ..errors import SceneError

from . import cie

_BASIS = cie.load_grid_table("mallett_yuksel_2019_srgb.csv", 3)  # (3, 471)
_BASIS = _BASIS / _BASIS.sum(axis=0, keepdims=True)  # undo 10-digit CSV rounding: sums = 1
_BASIS.setflags(write=False)

KINDS = ("reflectance", "illuminant", "unbounded")


def basis_rgb(lam_nm) -> np.ndarray:
    """Mallett-Yuksel 2019 basis B_r, B_g, B_b at lam_nm [nm] -> (3, *lam.shape)."""
    return cie.interp_grid(_BASIS, lam_nm, outside="clamp")


def _rgb_combination(rgb: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """r·B_r + g·B_g + b·B_b for a basis (3, ...) (cheaper than tensordot for three terms)."""
    return rgb[0] * basis[0] + rgb[1] * basis[1] + rgb[2] * basis[2]


class Spectrum:
    """Base class: a real function of wavelength [nm]."""

    is_constant: bool = False  # same value at every wavelength
    is_grey: bool = False  # colour-neutral in its role (develops to r = g = b)

    def eval(self, lam_nm, mono: bool = False) -> np.ndarray:
        """Values at lam_nm [nm] (float64, lam's shape); mono: the monochrome value broadcast."""
        lam = np.asarray(lam_nm, dtype=np.float64)
        if mono:
            return np.full(lam.shape, self.mono_value, dtype=np.float64)
        return self._eval(lam)

    def eval_cached(self, lookup: WavelengthLookup) -> np.ndarray:
        """Values at ``lookup.lam`` using its precomputed table values (same result as ``eval``)."""
        return self._eval(lookup.lam)

    @property
    def mono_value(self) -> float:
        """Value used in the monochrome (one-wavelength) mode."""
        return float(cie.luminance(self.linear_srgb()))

    def linear_srgb(self) -> np.ndarray:
        """Nominal linear sRGB triple of this parameter (what an RGB renderer would use)."""
        raise NotImplementedError

    def _eval(self, lam: np.ndarray) -> np.ndarray:
        raise NotImplementedError


#: Where models that need a wavelength evaluate the R, G and B channels of "rgb" transport (nm): the
#: dominant wavelengths of the linear-sRGB primaries (≈ 611, 549, 464 nm, rounded).
RGB_WAVELENGTHS_NM = (610.0, 550.0, 465.0)


def rgb_channel_tables(n: int):
    """(basis (3, 3, n), d65 (3, n)) of a WavelengthLookup whose three "wavelengths" are the R, G, B
    channels ("rgb" transport): the identity basis and a D65 of 1, so that every RGB-defined spectrum
    (reflectance, unbounded, illuminant, textured) evaluates to its own channel values."""
    return np.broadcast_to(np.eye(3)[:, :, None], (3, 3, n)), np.ones((3, n))


def _same_columns(table: np.ndarray, n: int) -> np.ndarray:
    """``table`` (..., N) whose columns are all equal (the "rgb" transport's tables, ``rgb_channel_tables``) for n
    paths: a read-only view of its first column, what ``np.take`` of any n columns holds, without the gather (which
    first copied the whole broadcast table: 7 % of a textured emitter's render)."""
    return np.broadcast_to(table[..., :1], table.shape[:-1] + (n,))


class WavelengthLookup:
    """The table values every RGB spectrum needs at a batch of path wavelengths, computed once.

    ``lam`` (L, N) nm; ``basis`` (3, L, N) the RGB upsampling basis; ``d65`` (L, N) the normalised
    D65.  ``take(idx)`` / ``compress(mask)`` follow the paths as the integrator drops them.  Tables
    are evaluated on first use for the whole batch and gathered on first use by a subset (the
    integrator takes many subsets — material groups, lights — of which most never read a table; np.take, 2–3× the
    speed of fancy indexing).
    """

    __slots__ = ("_root", "_idx", "_lam", "_basis", "_d65", "_memo", "_channels")

    def __init__(self, lam, basis=None, d65=None, channels: bool = False):
        self._root, self._idx = None, None
        self._lam, self._basis, self._d65 = lam, basis, d65
        self._memo = None
        self._channels = channels

    @property
    def channels(self) -> bool:
        """True when the three "wavelengths" are the R, G, B channels of "rgb" transport (``rgb_channel_tables``):
        a model that needs a wavelength evaluates each channel at engine.spectral.RGB_WAVELENGTHS_NM."""
        return self._channels if self._root is None else self._root._channels

    def memo(self, key, compute):
        """``compute()`` once per lookup and ``key`` (read-only array: callers must not modify it).

        ``key`` is an object, or a tuple of objects, that together with the wavelengths determine
        the value (a spectrum; a material set and its per-path slot array); entries match by
        identity.  A material's parameter is typically needed by both its ``eval`` (next-event
        estimation) and its ``sample`` at the same vertices.
        """
        keys = key if isinstance(key, tuple) else (key,)
        ident = tuple(id(k) for k in keys)
        if self._memo is None:
            self._memo = {}
        hit = self._memo.get(ident)
        if hit is not None and all(a is b for a, b in zip(hit[0], keys)):
            return hit[1]
        value = compute()
        value.setflags(write=False)
        self._memo[ident] = (keys, value)
        return value

    @classmethod
    def _subset(cls, root: WavelengthLookup, idx: np.ndarray) -> WavelengthLookup:
        sub = cls.__new__(cls)
        sub._root, sub._idx = root, idx
        sub._lam = sub._basis = sub._d65 = sub._memo = None
        sub._channels = None
        return sub

    @property
    def n(self) -> int:
        """The number of paths (``lam.shape[1]``, without gathering a subset's wavelengths)."""
        return self._lam.shape[1] if self._root is None else self._idx.shape[0]

    @property
    def lam(self) -> np.ndarray:
        if self._lam is None:
            self._lam = np.take(self._root.lam, self._idx, axis=-1)
        return self._lam

    @property
    def basis(self) -> np.ndarray:
        if self._basis is None:
            root = self._root
            if root is None:
                self._basis = basis_rgb(self.lam)
            elif root._channels:
                self._basis = _same_columns(root.basis, self._idx.shape[0])
            else:
                self._basis = np.take(root.basis, self._idx, axis=-1)
        return self._basis

    @property
    def d65(self) -> np.ndarray:
        if self._d65 is None:
            root = self._root
            if root is None:
                self._d65 = cie.d65_normalised(self.lam)
            elif root._channels:
                self._d65 = _same_columns(root.d65, self._idx.shape[0])
            else:
                self._d65 = np.take(root.d65, self._idx, axis=-1)
        return self._d65

    def take(self, idx) -> WavelengthLookup:
        """The lookup of the paths ``idx`` (integer indices, a slice or a boolean mask)."""
        if isinstance(idx, slice) and idx == slice(None):
            return self
        idx = np.arange(self.lam.shape[1])[idx] if not isinstance(idx, np.ndarray) or idx.dtype == bool \
            else idx
        if self._root is None:
            return WavelengthLookup._subset(self, idx)
        return WavelengthLookup._subset(self._root, self._idx[idx])

    def compress(self, mask) -> WavelengthLookup:
        return self.take(np.flatnonzero(mask))


class ConstantSpectrum(Spectrum):
    """The same value at every wavelength."""

    is_constant = True
    is_grey = True

    def __init__(self, value: float):
        self.value = float(value)

    @property
    def mono_value(self) -> float:
        return self.value

    def linear_srgb(self) -> np.ndarray:
        return np.full(3, self.value)

    def _eval(self, lam):
        return np.full(lam.shape, self.value, dtype=np.float64)

    def __repr__(self):
        return f"ConstantSpectrum({self.value!r})"


def _check_rgb(rgb, field: str, upper: float | None) -> np.ndarray:
    rng = "in [0, 1]" if upper is not None else "≥ 0"
    try:
        arr = np.asarray(rgb, dtype=np.float64)
    except (TypeError, ValueError):
        raise SceneError(field, f"must be an [r, g, b] list with components {rng}, got {_show(rgb)}") from None
    if arr.shape != (3,):
        raise SceneError(field, f"must be an [r, g, b] list with components {rng}, got {_show(rgb)}")
    for i, c in enumerate(arr):
        if not math.isfinite(c) or c < 0 or (upper is not None and c > upper):
            raise SceneError(
                f"{field}[{i}]" if field else f"[{i}]",
                f"[r, g, b] components must be {rng}, got {_show(list(rgb))}",
            )
    return arr


class _RGBBasisSpectrum(Spectrum):
    _upper: float | None = None

    def __init__(self, rgb, field: str = ""):
        self.rgb = _check_rgb(rgb, field, self._upper)
        self.rgb.setflags(write=False)
        self.is_constant = self.is_grey = bool(self.rgb[0] == self.rgb[1] == self.rgb[2])

    @property
    def mono_value(self) -> float:
        return float(cie.luminance(self.rgb))

    def linear_srgb(self) -> np.ndarray:
        return self.rgb.copy()

    def _eval(self, lam):
        if self.is_constant:
            return np.full(lam.shape, self.rgb[0], dtype=np.float64)
        return _rgb_combination(self.rgb, basis_rgb(lam))

    def eval_cached(self, lookup):
        if self.is_constant:
            return np.full(lookup.lam.shape, self.rgb[0], dtype=np.float64)
        return lookup.memo(self, lambda: _rgb_combination(self.rgb, lookup.basis))

    def __repr__(self):
        return f"{type(self).__name__}({self.rgb.tolist()!r})"


class RGBReflectanceSpectrum(_RGBBasisSpectrum):
    """Reflectance upsampled from linear sRGB in [0, 1]³ (Mallett & Yuksel 2019).

    Under the unit D65 white it develops back to rgb (within 2.5e-4, the D65-table/sRGB white
    point mismatch); r = g = b gives exactly that constant. mono: luminance.
    """

    _upper = 1.0


class RGBUnboundedSpectrum(_RGBBasisSpectrum):
    """Non-negative parameter of any magnitude (e.g. n, k) upsampled from an RGB triple."""

    _upper = None


class RGBIlluminantSpectrum(Spectrum):
    """Emission scale · D65n(λ) · (r B_r + g B_g + b B_b)(λ): develops to linear sRGB scale·rgb.

    rgb ≥ 0 of any magnitude; (1, 1, 1) with scale 1 is the unit white (Y = 1).
    ``is_white`` when r = g = b (then exactly ∝ D65). mono: scale · luminance(rgb).
    """

    def __init__(self, rgb, scale: float = 1.0, field: str = ""):
        self.rgb = _check_rgb(rgb, field, None)
        self.rgb.setflags(write=False)
        scale = float(scale)
        if not math.isfinite(scale) or scale < 0:
            raise SceneError(field, f"scale must be a number ≥ 0, got {_show(scale)}")
        self.scale = scale
        self.is_white = bool(self.rgb[0] == self.rgb[1] == self.rgb[2])
        self.is_grey = self.is_white
        self.is_constant = bool(scale == 0.0 or not np.any(self.rgb))

    @property
    def mono_value(self) -> float:
        return self.scale * float(cie.luminance(self.rgb))

    def linear_srgb(self) -> np.ndarray:
        return self.scale * self.rgb

    def _eval(self, lam):
        d65 = cie.d65_normalised(lam)
        if self.is_white:
            return (self.scale * self.rgb[0]) * d65
        return self.scale * d65 * np.tensordot(self.rgb, basis_rgb(lam), axes=1)

    def eval_cached(self, lookup):
        if self.is_white:
            return (self.scale * self.rgb[0]) * lookup.d65
        return self.scale * lookup.d65 * np.tensordot(self.rgb, lookup.basis, axes=1)

    def __repr__(self):
        return f"RGBIlluminantSpectrum({self.rgb.tolist()!r}, scale={self.scale!r})"


class TabulatedSpectrum(Spectrum):
    """Piecewise-linear table of (wavelength [nm], value); evaluating outside it is an error.

    ``kind`` only matters for ``linear_srgb``/mono, which follow Mitsuba 3's
    ``spectrum_list_to_srgb`` (1 nm over 360-830 nm, wavelengths outside the table skipped):
    "reflectance" integrates s·D65n·cmf and clamps RGB to [0, 1]; "illuminant" integrates s·cmf
    (values already in the renderer's radiance units); "unbounded" integrates s·cmf / ∫ȳ so a
    flat table of v gives v; the last two clamp RGB at 0.
    """

    #: Filled on first use (linear_srgb); not part of the spectrum (engine.render.resume.scene_fingerprint).
    _cached_fields = ("_rgb",)

    def __init__(self, wavelengths_nm, values, name: str = "", kind: str = "unbounded"):
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
        wl = np.array(wavelengths_nm, dtype=np.float64)
        v = np.array(values, dtype=np.float64)
        if wl.ndim != 1 or wl.shape != v.shape or wl.size < 2:
            raise SceneError(name, "a spectrum table needs at least 2 (wavelength, value) pairs")
        if not (np.all(np.isfinite(wl)) and np.all(np.isfinite(v))):
            raise SceneError(name, "spectrum table entries must be finite numbers")
        if np.any(np.diff(wl) <= 0):
            raise SceneError(name, "spectrum table wavelengths must be strictly increasing")
        wl.setflags(write=False)
        v.setflags(write=False)
        self.wavelengths, self.values, self.name, self.kind = wl, v, name, kind
        self.is_constant = bool(np.all(v == v[0]))
        self.is_grey = self.is_constant and (kind != "illuminant" or v[0] == 0.0)
        self._rgb = None

    @property
    def range_nm(self) -> tuple[float, float]:
        return float(self.wavelengths[0]), float(self.wavelengths[-1])

    def linear_srgb(self) -> np.ndarray:
        if self._rgb is None:
            lo, hi = self.range_nm
            g = cie.GRID_NM
            inside = (g >= lo) & (g <= hi)
            s = np.where(inside, np.interp(g, self.wavelengths, self.values), 0.0)
            rgb = cie.spectrum_to_linear_srgb(s, illuminant=self.kind == "reflectance")
            if self.kind == "unbounded":
                rgb = rgb / cie.CIE_Y_INTEGRAL
            rgb = np.clip(rgb, 0.0, 1.0 if self.kind == "reflectance" else None)
            rgb.setflags(write=False)
            self._rgb = rgb
        return self._rgb.copy()

    def _eval(self, lam):
        lo, hi = self.range_nm
        bad = (lam < lo) | (lam > hi) | np.isnan(lam)
        if np.any(bad):
            x = float(lam[bad].flat[0])
            label = f"table {self.name!r}" if self.name else "spectrum table"
            raise SceneError(
                self.name,
                f"{label} covers {lo:g}-{hi:g} nm only; cannot evaluate it at {x:g} nm",
            )
        return np.interp(lam, self.wavelengths, self.values)

    def __repr__(self):
        lo, hi = self.range_nm
        return f"TabulatedSpectrum({self.name!r}, {self.wavelengths.size} points, {lo:g}-{hi:g} nm)"


# --- user input ------------------------------------------------------------------------------


def _show(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _is_number(x) -> bool:
    """A real number that converts to a float (an integer beyond ±1.8e308 does not: it is refused
    with the field's range instead of an OverflowError)."""
    if not isinstance(x, numbers.Real) or isinstance(x, (bool, np.bool_)):
        return False
    if isinstance(x, int):
        try:
            float(x)
        except OverflowError:
            return False
    return True


def _allowed(kind: str) -> str:
    if kind == "reflectance":
        return (
            'must be a number in [0, 1], an [r, g, b] list with components in [0, 1], '
            'or {"spectrum": [[wavelength_nm, value], ...]} with values in [0, 1]'
        )
    return (
        'must be a number ≥ 0, an [r, g, b] list with components ≥ 0, '
        'or {"spectrum": [[wavelength_nm, value], ...]} with values ≥ 0'
    )


def _in_range(x: float, kind: str) -> bool:
    return math.isfinite(x) and x >= 0.0 and (kind != "reflectance" or x <= 1.0)


def parse_spectrum(value, field: str, kind: str = "reflectance") -> Spectrum:
    """Build a Spectrum from a JSON value; bad input raises SceneError(field, message).

    * number -> ``ConstantSpectrum`` ("reflectance", "unbounded"), or for "illuminant"
      ``RGBIlluminantSpectrum((v, v, v))``: a D65 white of luminance v, so radiance 1 develops
      to linear sRGB (1, 1, 1), as Mitsuba 3 treats a float emitter radiance.
    * [r, g, b] -> ``RGBReflectanceSpectrum`` / ``RGBIlluminantSpectrum`` /
      ``RGBUnboundedSpectrum``.
    * {"spectrum": [[λ_nm, v], ...]} -> ``TabulatedSpectrum``; it must cover 360-830 nm. For
      "illuminant" the values are radiance with ȳ normalised to unit area (Mitsuba 3's
      convention: a flat table of v has luminance v), i.e. they are divided by ∫ȳ dλ.

    Ranges: reflectance in [0, 1]; illuminant and unbounded ≥ 0; NaN and ±inf are rejected.
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    allowed = _allowed(kind)
    if _is_number(value):
        v = float(value)
        if not _in_range(v, kind):
            raise SceneError(field, f"{allowed}, got {_show(value)}")
        if kind == "illuminant":
            return RGBIlluminantSpectrum((v, v, v), field=field)
        return ConstantSpectrum(v)
    if isinstance(value, (list, tuple)):
        if len(value) != 3 or not all(_is_number(c) for c in value):
            raise SceneError(field, f"{allowed}, got {_show(value)}")
        cls = {
            "reflectance": RGBReflectanceSpectrum,
            "illuminant": RGBIlluminantSpectrum,
            "unbounded": RGBUnboundedSpectrum,
        }[kind]
        return cls(value, field=field)
    if isinstance(value, dict) and set(value) == {"spectrum"}:
        return _parse_table(value["spectrum"], f"{field}.spectrum" if field else "spectrum", kind)
    raise SceneError(field, f"{allowed}, got {_show(value)}")


def _parse_table(table, field: str, kind: str) -> TabulatedSpectrum:
    rng = "in [0, 1]" if kind == "reflectance" else "≥ 0"
    if not isinstance(table, (list, tuple)) or len(table) < 2:
        raise SceneError(
            field, f"must be a list of at least 2 [wavelength_nm, value] pairs, got {_show(table)}"
        )
    wl, vals = [], []
    for i, pair in enumerate(table):
        ok = isinstance(pair, (list, tuple)) and len(pair) == 2 and all(map(_is_number, pair))
        if not ok or not math.isfinite(float(pair[0])) or float(pair[0]) <= 0:
            raise SceneError(
                f"{field}[{i}]",
                f"must be a [wavelength_nm, value] pair with wavelength_nm > 0, got {_show(pair)}",
            )
        if not _in_range(float(pair[1]), kind):
            raise SceneError(f"{field}[{i}]", f"value must be {rng}, got {_show(pair[1])}")
        if wl and float(pair[0]) <= wl[-1]:
            raise SceneError(
                f"{field}[{i}]",
                f"wavelengths must be strictly increasing, got {pair[0]!r} after {wl[-1]!r}",
            )
        wl.append(float(pair[0]))
        vals.append(float(pair[1]))
    if wl[0] > cie.LAMBDA_MIN or wl[-1] < cie.LAMBDA_MAX:
        raise SceneError(
            field,
            f"must cover the rendered range {cie.LAMBDA_MIN:g}-{cie.LAMBDA_MAX:g} nm, "
            f"got {wl[0]:g}-{wl[-1]:g} nm",
        )
    v = np.array(vals)
    if kind == "illuminant":
        v = v / cie.CIE_Y_INTEGRAL
    return TabulatedSpectrum(wl, v, name=field, kind=kind)


def as_spectrum(value, name: str = "value") -> Spectrum:
    """A Spectrum as is, or a finite number as a ConstantSpectrum (ValueError otherwise).

    For model constructors used from Python; scene files go through ``parse_spectrum``.
    """
    if isinstance(value, Spectrum):
        return value
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a Spectrum or a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return ConstantSpectrum(v)
