"""Multi-channel OpenEXR files holding a Stokes image and its derived maps.

Channel layout written by :func:`write_stokes_exr` (one scanline part, ZIP
compression, float32 unless ``half=True``):

``S0.R S0.G S0.B … S3.R S3.G S3.B``
    the Stokes image, linear sRGB radiance (same units as the renderer's S0);
``R G B``
    a copy of S0, so ordinary viewers show the unpolarised image;
``A``
    only when ``alpha`` is given (film transparency, holdouts): the coverage of the camera
    rays per pixel in [0, 1], as Cycles' alpha; colours are not premultiplied further (the
    transparent samples carry no colour, so R G B are already premultiplied);
``DoP DoLP DoCP``
    dimensionless, from the luminance Stokes vector (0 where S0 = 0); DoCP signed;
``AoLP``
    radians in (−π/2, π/2], from image-right towards image-up;
extra channels
    anything passed in ``extra`` (e.g. ``spp``, ``S0.Y.stderr``); integer
    arrays are stored as EXR UINT, floating ones like the Stokes channels;
data passes
    ``data`` (engine.render.data_passes.DataPasses.channels), always float32 (also with
    ``half=True``: depths of 1e10 and Cryptomatte ids need it), named as Blender names the passes:
    ``Depth.Z`` (z along the camera axis, 1e10 on the background), ``Mist.Z``, ``Normal.X/Y/Z``,
    ``Position.X/Y/Z``, ``UV.U/V/A``, ``Vector.X/Y/Z/W`` (pixels; x, y towards the previous frame,
    z, w from the next), ``Object Index.X``, ``Material Index.X`` and the Cryptomatte layers
    ``CryptoObject00.r/g/b/a`` … ``CryptoMaterial…``, ``CryptoAsset…`` (r, b: ids; g, a: coverage),
    whose manifests are the header strings ``cryptomatte/<7 hex>/name|hash|conversion|manifest``
    (the Cryptomatte specification; pass them in ``metadata``: DataPasses.metadata()).

The frame convention is stored as the string attribute ``polar.conventions``
(:data:`STOKES_EXR_CONVENTIONS`).
"""

from __future__ import annotations

import os

import numpy as np
import OpenEXR

from . import atomic_output_path, check_stokes_image, luminance_stokes
from ..polarisation import stokes as st

STOKES_EXR_CONVENTIONS = (
    "Polar Stokes EXR. Channels Sk.R/G/B (k=0..3): Stokes vector per linear sRGB "
    "(Rec.709, D65) channel; R,G,B = S0. Frame: x = image right, y = image up, light "
    "travelling towards the camera. S1>0: linear along x; S2>0: linear along (x+y)/sqrt2; "
    "S3 = 2 Im(Ex Ey*) > 0: right-circular (optics convention). AoLP = 0.5 atan2(S2,S1) "
    "in radians, from image right towards image up, in (-pi/2, pi/2]. DoP, DoLP, AoLP, "
    "DoCP (signed, S3/S0) are computed from the luminance Stokes vector "
    "Y = 0.2126 R + 0.7152 G + 0.0722 B; ratios are 0 where S0 = 0."
)

STOKES_CHANNELS = tuple(f"S{k}.{c}" for k in range(4) for c in "RGB")
DERIVED_CHANNELS = ("DoP", "DoLP", "AoLP", "DoCP")
_BUILTIN_CHANNELS = frozenset(STOKES_CHANNELS + ("R", "G", "B") + DERIVED_CHANNELS)

# Standard / structural EXR attributes the caller's metadata must not override.
_RESERVED_ATTRIBUTES = frozenset({
    "channels", "compression", "dataWindow", "displayWindow", "lineOrder",
    "pixelAspectRatio", "screenWindowCenter", "screenWindowWidth", "type",
    "tiles", "name", "version", "chunkCount", "chromaticities",
})
# Rec. 709 / sRGB primaries and D65 white (CIE xy): red, green, blue, white.
_REC709_CHROMATICITIES = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
_HALF_MAX = float(np.finfo(np.float16).max)
_INT32 = (-(2**31), 2**31 - 1)


def _header_value(key: str, value):
    """Map a Python metadata value to what the OpenEXR bindings store with a proper type.

    str → string; bool/int in int32 range → int; other ints → decimal string;
    float → double (a 1-element float64 array is how the bindings write an
    EXR ``double``; a bare Python float would be truncated to float32).
    """
    if isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (int, np.integer)):
        value = int(value)
        return value if _INT32[0] <= value <= _INT32[1] else str(value)
    if isinstance(value, (float, np.floating)):
        return np.array([float(value)], dtype=np.float64)
    raise ValueError(
        f"metadata {key!r}: unsupported type {type(value).__name__} (use str, int or float)"
    )


def _check_metadata(metadata: dict) -> dict:
    out = {}
    for key, value in metadata.items():
        if not isinstance(key, str) or not key:
            raise ValueError(f"metadata keys must be non-empty strings; got {key!r}")
        if key in _RESERVED_ATTRIBUTES:
            raise ValueError(f"metadata key {key!r} is a reserved EXR attribute")
        out[key] = _header_value(key, value)
    return out


def _float_channel(name: str, values: np.ndarray, half: bool) -> np.ndarray:
    if half:
        big = np.abs(values) > _HALF_MAX
        if big.any():
            raise ValueError(
                f"channel {name!r}: {int(big.sum())} value(s) exceed the half-float maximum "
                f"{_HALF_MAX:g}; write with half=False"
            )
        stored = values.astype(np.float16)
    else:
        with np.errstate(over="ignore", invalid="ignore"):   # reported below, as a ValueError
            stored = values.astype(np.float32)
    # Checked on the stored values: a finite float64 beyond ±3.4e38 becomes inf in float32, and a
    # derived ratio of overflowing luminances is NaN; the file holds only finite numbers.
    bad = ~np.isfinite(stored)
    if bad.any():
        raise ValueError(
            f"channel {name!r}: {int(bad.sum())} value(s) are not finite as {stored.dtype} "
            f"(NaN, or beyond ±{float(np.finfo(stored.dtype).max):.3g})"
        )
    return stored


def _extra_channel(name, values, shape, half: bool) -> np.ndarray:
    if not isinstance(name, str) or not name:
        raise ValueError(f"extra channel names must be non-empty strings; got {name!r}")
    if name in _BUILTIN_CHANNELS:
        raise ValueError(f"extra channel {name!r} clashes with a built-in channel")
    a = np.asarray(values)
    if a.shape != shape:
        raise ValueError(f"extra channel {name!r} has shape {a.shape}; expected {shape} (H, W)")
    if np.issubdtype(a.dtype, np.integer) or a.dtype == np.bool_:
        if a.size and (a.min() < 0 or a.max() > 2**32 - 1):
            raise ValueError(f"extra channel {name!r}: integer values must lie in [0, 2**32 - 1]")
        return a.astype(np.uint32)
    if not np.issubdtype(a.dtype, np.floating):
        raise ValueError(f"extra channel {name!r}: dtype {a.dtype} is not integer or float")
    bad = ~np.isfinite(a)
    if bad.any():
        raise ValueError(f"extra channel {name!r} has {int(bad.sum())} non-finite value(s)")
    return _float_channel(name, a, half)


def write_stokes_exr(
    path: str | os.PathLike,
    stokes_rgb,
    metadata: dict | None = None,
    extra: dict[str, np.ndarray] | None = None,
    half: bool = False,
    alpha: np.ndarray | None = None,
    data: dict[str, np.ndarray] | None = None,
) -> None:
    """Write a Stokes image (4, H, W, 3) to a ZIP-compressed multi-channel EXR, atomically.

    Channels are described in the module docstring.  ``metadata`` maps header
    attribute names (e.g. ``polar.spp``, ``polar.seed``) to str / int / float;
    ints outside int32 are stored as strings, floats as EXR doubles.
    ``polar.conventions`` defaults to :data:`STOKES_EXR_CONVENTIONS`.
    ``half=True`` stores floating channels as 16-bit half (ValueError if a
    value exceeds 65504).  The file is written to a hidden temporary file in
    the target directory and renamed into place, so a failure never leaves a
    truncated file and never damages an existing one.  Raises ValueError for
    bad shapes, unsupported metadata or values that are not finite once
    stored (float32 overflows beyond ±3.4e38); then nothing is written.
    ``data``: data-pass channels (module docstring), float32 whatever ``half``.
    """
    s = check_stokes_image(stokes_rgb)
    _, height, width, _ = s.shape
    header = {"polar.conventions": STOKES_EXR_CONVENTIONS}
    header.update(_check_metadata(metadata or {}))
    header.update({
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        "chromaticities": _REC709_CHROMATICITIES,
    })

    channels: dict[str, np.ndarray] = {}
    for k in range(4):
        for c, cname in enumerate("RGB"):
            channels[f"S{k}.{cname}"] = _float_channel(f"S{k}.{cname}", s[k, :, :, c], half)
    for cname in "RGB":
        channels[cname] = channels[f"S0.{cname}"]
    if alpha is not None:
        channels["A"] = _extra_channel("A", np.asarray(alpha, np.float32), (height, width), half)
    y = luminance_stokes(s)
    derived = {
        "DoP": st.degree_of_polarisation(y),
        "DoLP": st.degree_of_linear_polarisation(y),
        "AoLP": st.angle_of_linear_polarisation(y),
        "DoCP": st.degree_of_circular_polarisation(y),
    }
    for name, values in derived.items():
        channels[name] = _float_channel(name, values, half)
    for name, values in (extra or {}).items():
        channels[name] = _extra_channel(name, values, (height, width), half)
    for name, values in (data or {}).items():
        if name in channels:
            raise ValueError(f"data channel {name!r} clashes with another channel")
        channels[name] = _extra_channel(name, np.asarray(values, np.float32), (height, width), False)

    # The bindings need C-contiguous arrays (slices of s are strided).
    channels = {n: np.ascontiguousarray(a) for n, a in channels.items()}
    exr = OpenEXR.File(header, channels)
    with atomic_output_path(path) as tmp:
        exr.write(tmp)


def _layer_of(name: str) -> str | None:
    """The view layer of a Blender multilayer channel ``<Layer>.S<k>.<R|G|B>`` (None for other names).

    Blender names render passes ``<Layer>.<Pass>.<Channel>``; the layer name itself may hold dots,
    so the pass and channel are the last two fields.
    """
    parts = name.rsplit(".", 2)
    if len(parts) == 3 and parts[0] and f"{parts[1]}.{parts[2]}" in STOKES_CHANNELS:
        return parts[0]
    return None


def stokes_layers(channels) -> list[str]:
    """View layers (in name order) of a Blender multilayer EXR that hold all twelve Stokes channels."""
    names = set(channels)
    found = {layer for layer in map(_layer_of, names) if layer is not None}
    return sorted(layer for layer in found if all(f"{layer}.{c}" in names for c in STOKES_CHANNELS))


def read_stokes_exr(path: str | os.PathLike,
                    layer: str | None = None) -> tuple[np.ndarray, dict[str, np.ndarray], dict]:
    """Read a file written by :func:`write_stokes_exr`, or a Blender multilayer EXR of a Polar render.

    Returns ``(stokes_rgb, channels, header)``: the Stokes image as float32
    (4, H, W, 3), every stored channel by name (dtype as stored: float32,
    float16 or uint32) and the header dict, with EXR doubles turned back into
    Python floats.

    Blender writes its passes as ``<Layer>.<Pass>.<Channel>`` (e.g. ``ViewLayer.S0.R``), one
    part per pass: then ``layer`` names the view layer to read (needed only when several hold
    the Stokes passes), ``channels`` holds that layer's channels without the ``<Layer>.``
    prefix, and ``header`` is the first part's.  A file with top-level ``S0.R`` … is read as
    before (``layer`` must then be None).  Raises ValueError if a Stokes channel is missing,
    naming the view layers the file has.
    """
    f = OpenEXR.File(os.fspath(path), separate_channels=True)
    parts = f.parts if len(f.parts) > 1 else None
    if parts is None:
        channels = {name: ch.pixels for name, ch in f.channels().items()}
    else:
        channels = {name: ch.pixels for part in parts for name, ch in part.channels.items()}
    plain = all(n in channels for n in STOKES_CHANNELS)
    if layer is not None or not plain:
        layers = stokes_layers(channels)
        available = ", ".join(repr(x) for x in layers) or "none"
        if layer is None:
            if len(layers) > 1:
                raise ValueError(f"{os.fspath(path)}: several view layers hold the Stokes passes "
                                 f"({available}): choose one with --layer")
            if not layers:
                missing = [n for n in STOKES_CHANNELS if n not in channels]
                raise ValueError(f"{os.fspath(path)}: not a Stokes EXR, missing channels {missing} "
                                 "(and no view layer <Layer>.S0.R … of a Blender multilayer EXR)")
            layer = layers[0]
        elif layer not in layers:
            raise ValueError(f"{os.fspath(path)}: no view layer {layer!r} with the Stokes passes "
                             f"S0…S3; layers with them: {available}")
        prefix = layer + "."
        channels = {n[len(prefix):]: a for n, a in channels.items() if n.startswith(prefix)}
    height, width = channels["S0.R"].shape
    stokes_rgb = np.empty((4, height, width, 3), dtype=np.float32)
    for k in range(4):
        for c, cname in enumerate("RGB"):
            stokes_rgb[k, :, :, c] = channels[f"S{k}.{cname}"]
    header = {}
    for key, value in (f.header() if parts is None else parts[0].header).items():
        if isinstance(value, np.ndarray) and value.dtype == np.float64 and value.shape == (1,):
            value = float(value[0])
        header[key] = value
    return stokes_rgb, channels, header
