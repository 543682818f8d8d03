"""Continuing an interrupted render from its EXR, and refusing to mix two different renders.

Adding new samples to stored ones is only right when both come from the same estimator.  Every
EXR written by the CLI carries the estimator's identity in its header (:func:`estimator_identity`):

``polar.scene_hash``
    SHA-256 of the loaded scene description — camera, meshes (vertices, faces, normals, material
    slots, emission), materials with every parameter, lights — walked canonically
    (:func:`scene_fingerprint`).  The render settings and the file's path are not part of it: a
    moved or reformatted scene file still matches, a changed number anywhere in the scene does not;
``polar.window``
    the rendered pixel rectangle "x0 y0 x1 y1" (the resolution is the image's own size);
``polar.max_depth``, ``polar.rr_depth``, ``polar.seed``, ``polar.spectral``, ``polar.wavelength_nm``
(mono only), ``polar.polarisation_requested`` and ``polar.polarisation`` (as resolved),
``polar.reduce_spectral``, ``polar.simplify``, ``polar.sampler`` (written only for the
"stratified" sampler: a file without it was rendered with the "independent" one), ``polar.halves`` (the
resolved RenderSettings.halves, written only when "one_sequence": a file of a low-discrepancy sampler without it
drew its even and odd samples from two independent sequences), and ``polar.light_tree`` (written only when not
"auto").  A continuation with ``halves`` "auto" takes the file's, so a resume never mixes the two.

What may differ on resume: the total sample count (raised, never below the samples done), threads,
batch size, Dask scheduler, previews, exposure, and the adaptive sampling settings (threshold,
quantity, minimum samples, time limit).  An adaptive render stores its float64 sums and half-buffers
bit for bit (engine.render.adaptive.state_channels): resuming it continues the exact sums, and
continuing adaptively needs them (a file rendered without adaptive sampling has no half-buffers).
The seed and the sample count are taken from the file unless given.  Anything else that differs is
refused with one line naming each difference.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import re
import stat
from typing import NamedTuple

import numpy as np

from ..errors import SceneError
from ..materials.batching import object_fields
from .film import film_from_stokes
from ..scene.description import resolve_halves
from ..scene.description import LIGHT_PATH_FIELDS

#: Header keys that must match between a stored render and its continuation, with the option
#: that sets each (for the error message).
MATCHED = {
    "polar.scene_hash": "the scene file",
    "polar.window": "the image window",
    "polar.max_depth": "--max-depth",
    "polar.rr_depth": "render.rr_depth",
    "polar.seed": "--seed",
    "polar.spectral": "--spectral",
    "polar.wavelength_nm": "--wavelength-nm",
    "polar.polarisation_requested": "--polarisation",
    "polar.polarisation": "--polarisation (as resolved)",
    "polar.reduce_spectral": "--reduce-spectral",
    "polar.simplify": "--simplify",
    "polar.sampler": "--sampler",
    "polar.halves": "--halves or render.halves",
    "polar.light_tree": "--light-tree",
    **{f"polar.{f.name}": "--" + f.name.replace("_", "-") for f in LIGHT_PATH_FIELDS},
}


def _feed(h, obj, seen: set) -> None:
    """Hash ``obj`` canonically: type names, sorted fields, array dtype/shape/bytes, exact floats."""
    if obj is None or isinstance(obj, (bool, str)):
        h.update(repr(obj).encode())
    elif isinstance(obj, (int, np.integer)):
        h.update(b"i" + str(int(obj)).encode())
    elif isinstance(obj, (float, np.floating)):
        h.update(b"f" + float(obj).hex().encode())
    elif isinstance(obj, complex):
        h.update(b"c" + obj.real.hex().encode() + obj.imag.hex().encode())
    elif isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        h.update(f"a{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes() if a.dtype != object else repr(a.tolist()).encode())
    elif isinstance(obj, (list, tuple)):
        h.update(f"l{len(obj)}".encode())
        for v in obj:
            _feed(h, v, seen)
    elif isinstance(obj, (set, frozenset)):
        h.update(f"s{len(obj)}".encode())
        for v in sorted(obj, key=repr):
            _feed(h, v, seen)
    elif isinstance(obj, dict):
        h.update(f"d{len(obj)}".encode())
        for k in sorted(obj, key=str):
            _feed(h, str(k), seen)
            _feed(h, obj[k], seen)
    elif callable(obj) and hasattr(obj, "__qualname__"):       # functions, classes, kernels
        h.update(f"F{getattr(obj, '__module__', '')}.{obj.__qualname__}".encode())
    else:
        if id(obj) in seen:                                     # a shared or cyclic reference
            h.update(b"<seen>")
            return
        seen.add(id(obj))
        t = type(obj)
        h.update(f"o{t.__module__}.{t.__qualname__}".encode())
        # caches a class fills on first use (from its other fields) are hashed as not filled yet (None): a render,
        # or a lookup anywhere in the process, must not change the fingerprint of the scene that holds the object,
        # and fingerprints of files written before stay valid
        _feed(h, object_fields(obj), seen)


def scene_fingerprint(scene) -> str:
    """SHA-256 (hex) of what a scene renders: camera, meshes, materials, lights (not settings/source)."""
    h = hashlib.sha256(b"polar-scene/1")
    seen: set = set()
    parts = (scene.camera, scene.meshes, scene.materials, scene.lights)
    if getattr(scene, "medium", None) is not None:     # only then: other scenes' fingerprints are unchanged
        parts += (scene.medium,)
    for part in parts:
        _feed(h, dataclasses.asdict(part) if dataclasses.is_dataclass(part) else part, seen)
    return h.hexdigest()


def estimator_identity(scene_hash: str, settings, resolved: str, window=None, size=None) -> dict:
    """Header entries that identify the estimator of a render (see the module docstring)."""
    x0, y0, x1, y1 = window or (0, 0, *size)
    ident = {"polar.scene_hash": scene_hash, "polar.window": f"{x0} {y0} {x1} {y1}",
             "polar.max_depth": int(settings.max_depth), "polar.rr_depth": int(settings.rr_depth),
             "polar.seed": int(settings.seed), "polar.spectral": settings.spectral,
             "polar.polarisation_requested": settings.polarisation, "polar.polarisation": resolved,
             "polar.reduce_spectral": settings.reduce_spectral, "polar.simplify": settings.simplify}
    if settings.stratified:
        # only then: the headers of independent renders stay as they were (and older files match)
        ident["polar.sampler"] = settings.sampler
        if settings.halves != "independent":
            # (resolved: "one_sequence"; "auto" here is a caller's bug, recorded as such so that it never matches)
            ident["polar.halves"] = settings.halves
    if getattr(settings, "light_tree", "auto") != "auto":      # (only where set, as the light paths below)
        ident["polar.light_tree"] = settings.light_tree
    for f in LIGHT_PATH_FIELDS:         # only where set: the headers of other renders stay as they were
        value = getattr(settings, f.name, f.default)
        if value != f.default:
            # floats as their exact decimal text (a float32 header attribute would round them)
            text = {"bool": "on" if value else "off", "float": repr(float(value))}
            ident[f"polar.{f.name}"] = text.get(f.kind, value)
    if settings.spectral == "mono":
        ident["polar.wavelength_nm"] = float(settings.wavelength_nm)
    return ident


def _same(a, b) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        try:
            return math.isclose(float(a), float(b), rel_tol=1e-12, abs_tol=0.0)
        except (TypeError, ValueError):
            return False
    return str(a) == str(b)          # ints beyond int32 are stored as decimal strings


#: What a key's absence means (written only where it differs from this)
ABSENT_MEANS = {"polar.halves": "independent"}


def differences(header: dict, identity: dict) -> list[str]:
    """What differs between a stored render's header and this render's identity (empty: resumable)."""
    out = []
    for key, option in MATCHED.items():
        stored, now = header.get(key, ABSENT_MEANS.get(key)), identity.get(key, ABSENT_MEANS.get(key))
        if stored is None and now is None:
            continue
        if not _same(stored, now):
            what = key.removeprefix("polar.")
            if key == "polar.scene_hash":
                out.append(f"the scene differs ({option} or its meshes/materials/lights changed)")
            else:
                out.append(f"{what} is {stored!r} in the file but {now!r} now ({option})")
    return out


#: Most samples per pixel a render takes (engine.scene.loader.parse_settings: ``spp`` ≤ 2²⁴).
MAX_SPP = 1 << 24
#: Bounds of a seed (engine.scene.loader.parse_settings).
MAX_SEED = 2 ** 63 - 1


def read_polar_exr(path: str, field: str, layer: str | None = None):
    """(stokes, channels, header) of a Stokes EXR, or a SceneError naming ``field``: a path that does
    not exist, a folder, anything but a regular file (a FIFO or device is refused before it is opened:
    reading it could wait forever), or a file that is not a Stokes EXR.  The one reader of the CLI's
    input EXRs (``--resume``, ``polariser``).  ``layer``: the view layer of a Blender multilayer EXR;
    a ValueError about it is re-raised as a SceneError naming --layer."""
    from ..output.exr import read_stokes_exr
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise SceneError(field, f"{path!r} does not exist") from None
    except (OSError, ValueError) as e:           # ValueError: a NUL in the path
        raise SceneError(field, f"cannot read {path!r}: {getattr(e, 'strerror', None) or e}") from None
    if stat.S_ISDIR(mode):
        raise SceneError(field, f"{path!r} is a folder, not a Stokes EXR")
    if not stat.S_ISREG(mode):                   # as engine.files.refuse_special_file, from the mode at hand
        raise SceneError(field, f"{path!r} is not a regular file (a FIFO, device or socket)")
    try:
        return read_stokes_exr(path, layer)
    except MemoryError:
        raise SceneError(field, f"{path!r} claims an image too large to read into memory") from None
    except (ValueError, OSError, RuntimeError) as e:
        if layer is not None and "view layer" in str(e):
            raise SceneError("--layer", str(e)) from None
        raise SceneError(field, f"{path!r} is not a Polar Stokes EXR: {e}") from None


def nonfinite_pixels(stokes: np.ndarray) -> int:
    """How many pixels of a Stokes image (4, H, W[, C]) hold a NaN or ±inf in any component."""
    bad = ~np.isfinite(np.asarray(stokes))
    return int(np.count_nonzero(bad.reshape(bad.shape[0], bad.shape[1], bad.shape[2], -1).any(axis=(0, 3))))


def _header_integer(header: dict, key: str, lo: int, hi: int, path: str) -> int:
    """A whole-number header entry within [lo, hi] (ints beyond int32 are stored as strings), or a SceneError."""
    value = header.get(key)
    number = None
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        number = int(value)
    elif isinstance(value, str) and re.fullmatch(r"\s*[+-]?[0-9]{1,40}\s*", value):
        number = int(value)
    if number is None or not lo <= number <= hi:
        raise SceneError("--resume", f"{path!r} is damaged: its header {key} must be a whole number in "
                                     f"[{lo}, {hi}], got {value!r}")
    return number


def read_resumable(path: str):
    """(stokes, channels, header) of a Polar EXR to resume, or a SceneError naming --resume: besides
    :func:`read_polar_exr`'s refusals, a file without per-pixel counts, seed or scene fingerprint, one
    whose header ``polar.seed``/``polar.spp`` or ``spp`` channel is not whole numbers in range, and one
    with a float channel (Stokes means, errors, alpha…) that is not finite (which channel, how many pixels)."""
    stokes, channels, header = read_polar_exr(path, "--resume")
    if "spp" not in channels or "polar.seed" not in header:
        raise SceneError("--resume", f"{path!r} has no per-pixel sample counts (not written by Polar)")
    if "polar.scene_hash" not in header:
        raise SceneError("--resume", f"{path!r} was written without the scene fingerprint (an older Polar), "
                                     "so it cannot be checked to belong to this render")
    _header_integer(header, "polar.seed", 0, MAX_SEED, path)
    _header_integer(header, "polar.spp", 1, MAX_SPP, path)
    counts = np.asarray(channels["spp"])
    if counts.dtype.kind == "f":
        whole = np.isfinite(counts) & (counts == np.floor(np.where(np.isfinite(counts), counts, 0)))
    else:
        whole = np.ones(counts.shape, bool)
    if counts.dtype.kind not in "uif" or not (whole & (counts >= 0) & (counts <= MAX_SPP)).all():
        raise SceneError("--resume", f"{path!r} is damaged: its spp channel must hold whole numbers in "
                                     f"[0, {MAX_SPP}] (samples per pixel)")
    for name in ("stokes", *sorted(channels)):
        values = stokes if name == "stokes" else np.asarray(channels[name])
        if values.dtype.kind != "f":
            continue
        bad = int(np.count_nonzero(~np.isfinite(values)))
        if bad:
            what = "the Stokes channels S0…S3" if name == "stokes" else f"channel {name}"
            raise SceneError("--resume", f"{path!r} is damaged: {what} hold{'' if name == 'stokes' else 's'} "
                                         f"{bad} non-finite value{'s' if bad > 1 else ''} (NaN or ±inf)")
    return stokes, channels, header


class Resumed(NamedTuple):
    """A stored render to continue: its ``film`` of finished samples, the ``settings`` to continue with
    and, for a file of an adaptive render, its ``halves`` (engine.render.film.HalfBuffers; else None)."""
    film: object
    settings: object
    halves: object = None


def resume_state(path: str, renderer, settings, scene_hash: str, spp=None, seed=None, sampler=None,
                 adaptive: bool = False) -> Resumed:
    """The render stored at ``path``, to continue with ``renderer`` (its scene; the transport that
    ``settings`` resolve to is its plan's).

    ``spp``/``seed``/``sampler`` are the values given on the command line (None: take the stored ones;
    a file without ``polar.sampler`` was rendered with the "independent" sampler, the default until
    the stratified one became it); ``adaptive``: to continue adaptively (a SceneError if the file has no
    half-buffers).  Raises SceneError naming every setting that differs from the stored render's.
    """
    scene = renderer.scene
    stokes, channels, header = read_resumable(path)
    H, W = stokes.shape[1:3]
    if (W, H) != (scene.camera.width, scene.camera.height):
        raise SceneError("--resume", f"{path!r} is {W}×{H} but the scene renders "
                                     f"{scene.camera.width}×{scene.camera.height}")
    if seed is not None and str(seed) != str(header["polar.seed"]):
        raise SceneError("--seed", f"must be the resumed render's seed ({header['polar.seed']}) to continue it")
    stored_sampler = header.get("polar.sampler", "independent")
    st = dataclasses.replace(settings, seed=int(header["polar.seed"]),
                             sampler=stored_sampler if sampler is None else settings.sampler,
                             spp=int(header["polar.spp"]) if spp is None else settings.spp)
    stored_halves = header.get("polar.halves", "independent")
    if st.halves == "auto":             # continue as the file was drawn
        st = dataclasses.replace(st, halves=stored_halves)
    st = resolve_halves(st)
    ident = estimator_identity(scene_hash, st, renderer.plan(st).settings.polarisation, size=(W, H))
    diff = differences(header, ident)
    if diff:
        raise SceneError("--resume", f"{os.path.basename(path)!r} is another render: " + "; ".join(diff))
    counts = channels["spp"].astype(np.int64)
    if counts.max() > st.spp:
        raise SceneError("--spp", f"must be at least the samples already done ({int(counts.max())})")
    from .adaptive import has_state, state_from_channels
    if has_state(channels):
        film, halves = state_from_channels(channels, counts, repr(path), means=stokes, halves=st.halves)
        if st.split_halves:
            film.keep_half_sums(halves.sums.copy())     # class A/B luminance sums: the stratified standard error
    else:
        if adaptive:
            raise SceneError("--noise-threshold", f"{os.path.basename(path)!r} was rendered without adaptive "
                                                  "sampling, so it has no half-buffers to continue adaptively "
                                                  "(resume it without --noise-threshold)")
        stderr = np.stack([channels[f"S{i}.Y.stderr"] for i in range(4)]) if "S0.Y.stderr" in channels else None
        even = None
        if st.split_halves and "S0.Y.even" in channels:
            # the i.i.d. error restores the sums of squares; the even means the half sums
            even = np.stack([channels[f"S{i}.Y.even"] for i in range(4)])
            stderr = np.stack([channels[f"S{i}.Y.stderr_iid"] for i in range(4)])
        film, halves = film_from_stokes(stokes, counts, stderr, channels.get("A"), even, st.halves), None
    return Resumed(film, st, halves)
