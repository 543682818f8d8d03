"""Command line: ``python -m engine render …`` and ``python -m engine mueller …``.

User mistakes (bad scene files, parameters out of range, an output path that
cannot be written — checked before rendering) end with a one-line message
naming the field and exit status 2, never a traceback.  Ctrl-C or SIGTERM
during a render stops after the batches in flight and writes the finished
samples (exit status 130 / 143, see :class:`StopSignals`); if the output then
cannot be written, they go to a rescue file (engine.output.rescue) and the
exit status is 1.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time

from .errors import SceneError
from .scene.description import HALVES_MODES, LIGHT_PATH_FIELDS, LIGHT_TREE_MODES, PARALLEL_MODES


class ProgressBar:
    """A one-line progress bar on stderr (only redrawn when it changes visibly)."""

    def __init__(self, label: str, stream=sys.stderr, width: int = 30):
        self.label, self.stream, self.width = label, stream, width
        self.t0 = time.perf_counter()
        self._last = None
        self._first = None          # (elapsed, fraction) at the first traced batch

    def __call__(self, fraction: float, stats: dict) -> None:
        if stats.get("message"):            # a note before the first batch (engine.render.processes)
            self.note(f"polar: {stats['message']}…")
            return
        filled = int(round(fraction * self.width))
        elapsed = time.perf_counter() - self.t0
        # The estimate starts at the first traced batch: what came before it (loading or compiling
        # kernels, the first batch's set-up) says nothing about the batches to come.
        if self._first is None:
            self._first = (elapsed, fraction)
        t1, f1 = self._first
        left = (f"{(elapsed - t1) * (1 - fraction) / (fraction - f1):6.1f}s left" if fraction > f1
                else "     ?s left")
        rate = stats.get("samples", 0) / max(elapsed, 1e-9) / 1e3
        line = (f"\r{self.label} [{'#' * filled}{'.' * (self.width - filled)}] {100 * fraction:5.1f}% "
                f"{elapsed:6.1f}s elapsed, {left}, {rate:7.1f} ksamples/s")
        if line != self._last:
            self.stream.write(line)
            self.stream.flush()
            self._last = line

    def note(self, text: str) -> None:
        """Print ``text`` on a line of its own (after the bar's line, if one is drawn)."""
        self.stream.write(("\n" if self._last is not None else "") + text + "\n")
        self.stream.flush()
        self._last = None

    def close(self):
        if self._last is not None:
            self.stream.write("\n")
            self.stream.flush()


#: What the command line says when a kernel starts compiling (once per process).
COMPILING_MESSAGE = "polar: compiling kernels (first run only)…"


def _say_compiling(bar: ProgressBar | None) -> None:
    """Say that kernels are being compiled (called by engine.kernels.COMPILES at the first compile)."""
    if bar is not None:
        bar.note(COMPILING_MESSAGE)
    else:
        print(COMPILING_MESSAGE, file=sys.stderr, flush=True)


#: Bounds of --exposure (stops): 2**±64 already maps any representable radiance to black or white.
EXPOSURE_LIMIT_STOPS = 64.0
#: Most samples per pixel of `estimate`'s pilot render.
MAX_PILOT_SPP = 4096
#: Most frames a polariser --sweep may produce (one per 0.05° over 180°).
MAX_SWEEP_FRAMES = 3600
#: When this process started (time.time()): temporary files older than this are not ours.
_STARTED = time.time()


def _finite(field: str, value: float, lo: float = -math.inf, hi: float = math.inf) -> float:
    """``value`` if it is a finite number in [lo, hi], else a SceneError naming ``field``."""
    if not (math.isfinite(value) and lo <= value <= hi):
        rng = "a finite number" if (lo, hi) == (-math.inf, math.inf) else f"a finite number in [{lo:g}, {hi:g}]"
        raise SceneError(field, f"must be {rng}, got {value!r}")
    return value


class StopSignals:
    """SIGINT (Ctrl-C) and SIGTERM (farms, ``timeout``) ask a render to stop and keep its samples.

    The first signal stops the render after the batches in flight (they abort between two
    bounces); the finished samples are then written and the exit status is 128 + the signal
    number (130 for SIGINT, 143 for SIGTERM).  Later signals never discard the render: while it
    stops and while its files are written they only print a note (SIGKILL still ends a process).
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.received = None
        self._previous = {}

    def _handle(self, signum, frame):
        if self.received is None:
            self.received = signum
        else:
            # os.write, not print: the progress bar may be inside a write to sys.stderr right now.
            os.write(2, b"\npolar: already stopping - the finished samples are being saved\n")

    @property
    def requested(self) -> bool:
        return self.received is not None

    def exit_status(self, default: int = 0) -> int:
        return 128 + int(self.received) if self.received is not None else default

    def __enter__(self):
        try:
            self._previous = {s: signal.signal(s, self._handle) for s in self.SIGNALS}
        except ValueError:          # not the main thread: the caller handles signals
            self._previous = {}
        return self

    def __exit__(self, *exc):
        for s, handler in self._previous.items():
            signal.signal(s, handler)
        return False


def _reason(e: BaseException) -> str:
    """A one-line reason for an exception (OS errors: 'path: strerror')."""
    if isinstance(e, OSError) and e.strerror:
        return f"{e.filename}: {e.strerror}" if e.filename else e.strerror
    return str(e) or type(e).__name__


def _load_scene(path):
    """engine.scene.loader.load_scene, refusing first a FIFO, device or socket (opening one could wait forever)."""
    from .scene.loader import load_scene
    return load_scene(path)


#: Options of `render` (and `estimate`, which has some of them) that override the scene's render block.
SETTING_OPTIONS = ("spp", "seed", "max_depth", "spectral", "polarisation", "wavelength_nm", "simplify",
                   "reduce_spectral", "sampler", "halves", "light_tree", "parallel",
                   *(f.name for f in LIGHT_PATH_FIELDS))


def _settings_from_options(scene, args):
    """The scene's RenderSettings with the options given applied (a new object), validated by the
    scene loader's own rules (engine.scene.loader.parse_settings: ``--spp`` in [1, 2²⁴], ``--seed`` in
    [0, 2⁶³ − 1], …) — the same for every command; an error names the option (``--spp``)."""
    from .scene.loader import parse_settings
    st = scene.settings
    overrides = {k: v for k in SETTING_OPTIONS if (v := getattr(args, k, None)) is not None}
    if not overrides:
        return st
    merged = {**{k: getattr(st, k) for k in ("spp", "max_depth", "rr_depth", "seed", "spectral",
                                              "wavelength_nm", "polarisation", "batch_rays", "threads",
                                              "reduce_spectral", "simplify", "sampler", "halves", "light_tree",
                                              "parallel", *(f.name for f in LIGHT_PATH_FIELDS))}, **overrides}
    try:
        st = parse_settings(merged, "option")
    except SceneError as e:
        key = e.field.removeprefix("option.")
        if key not in overrides:
            raise
        raise SceneError("--" + key.replace("_", "-"), e.reason) from None
    return st


def _precompile(args) -> int:
    from .render.precompile import precompile
    return precompile(force=args.force, threads=args.threads, verbose=getattr(args, "verbose", False))


def _render(args) -> int:
    """``render``: says so when kernels start compiling (the first run: engine.kernels.COMPILES)."""
    from .kernels import COMPILES
    bars = []       # the progress bar, once it exists: the message goes around it
    with COMPILES.watch(lambda: _say_compiling(bars[0] if bars else None)):
        return _render_scene(args, bars)


def _render_scene(args, bars: list) -> int:
    import dataclasses

    from .output.destination import check_destination, remove_stale_temporaries
    from .render.renderer import Renderer, RenderRequest
    from .render.resume import resume_state, scene_fingerprint

    _finite("--exposure", args.exposure, -EXPOSURE_LIMIT_STOPS, EXPOSURE_LIMIT_STOPS)
    if args.resume and args.scheduler:
        raise SceneError("--scheduler", "cannot be combined with --resume yet")
    if getattr(args, "denoise_data", False):
        for option, used in (("--resume", args.resume), ("--scheduler", args.scheduler)):
            if used:
                raise SceneError("--denoise-data", f"cannot be combined with {option} yet")
    data_request = _data_pass_request(args)
    light_keys = _light_pass_keys(args)
    scene = _load_scene(args.scene)
    st = _settings_from_options(scene, args)
    if getattr(args, "denoise_data", False):
        st = dataclasses.replace(st, denoise_data=True)
    adaptive = _adaptive_settings(args, st.spp)
    st = _resolve_halves(st, args.resume)
    out = args.output
    if not out.lower().endswith(".exr"):
        raise SceneError("-o", f"the output must be an .exr file, got {out!r}")
    # Before any rendering: a render must never be finished only to find it cannot be saved.
    try:
        check_destination(out)
    except OSError as e:
        raise SceneError("-o", e.strerror or str(e)) from None
    for path in remove_stale_temporaries(os.path.dirname(os.path.abspath(out)), _STARTED):
        print(f"polar: removed a temporary file left by an interrupted write: {path}", file=sys.stderr)
    scene_hash = scene_fingerprint(scene)      # before compiling: nothing has filled a cache yet

    renderer = Renderer(scene)
    resumed = None
    if args.resume:
        resumed = resume_state(args.resume, renderer, st, scene_hash, spp=args.spp, seed=args.seed,
                               sampler=args.sampler, adaptive=adaptive is not None)
        st = resumed.settings
        if adaptive is not None:
            adaptive = _adaptive_settings(args, st.spp)      # --spp may come from the file
    cam = scene.camera
    print(f"polar: {os.path.basename(args.scene)}: {cam.width}×{cam.height}, {st.spp} spp, "
          f"{len(renderer.compiled.faces)} triangles, {len(renderer.lights)} lights, "
          f"polarisation {st.polarisation}, {st.spectral}"
          f"{'' if st.spectral == 'spectral' else f' at {st.wavelength_nm:g} nm'}", file=sys.stderr)
    if args.scheduler is None:
        # Load (or, the first time, compile) the render's kernels before the clock starts: the
        # stats' sampling time and the progress estimate are then the render's own (Ctrl-C here
        # stops with nothing to write).
        renderer.warm_up(st)
    with StopSignals() as signals:
        bar = None if args.quiet else ProgressBar("rendering")
        bars.append(bar)
        prediction = _Prediction(st, adaptive)
        request = RenderRequest(st, adaptive=adaptive, resume=resumed.film if resumed else None,
                                resume_halves=resumed.halves if resumed and adaptive else None,
                                scheduler=args.scheduler, progress=bar, should_stop=lambda: signals.requested,
                                on_first_pass=prediction if adaptive else None,
                                unit_times=prediction.unit_times if adaptive else None)
        try:
            result = _render_request(renderer, request)
        finally:
            if bar is not None:
                bar.close()
        result.stats.update(prediction.first)
        ran = dataclasses.replace(st, halves=result.settings.halves)     # the passes trace the render's own rays
        if data_request is not None and not (result.cancelled and not result.film.count.any()):
            from .render.data_passes import render_data_passes
            result.data_passes = render_data_passes(renderer, data_request, ran)
        if light_keys and not (result.cancelled and not result.film.count.any()):
            _add_light_passes(renderer, ran, light_keys, result)
        # Still inside: a signal while the files are written must not lose them.
        status = _write_render(args, out, result, st, scene_hash, adaptive)
    return status if status else signals.exit_status(130 if result.cancelled else 0)


def _resolve_halves(st, resume):
    """``st`` with ``halves`` resolved for this render (engine.scene.description.resolve_halves): "auto" is one
    sequence, adaptive or not (the error estimate splits it into two classes, engine.render.halves); a resumed
    render's "auto" is left for engine.render.resume.resume_state (the file's)."""
    from .scene.description import resolve_halves
    if st.halves == "auto" and resume:
        return st
    return resolve_halves(st)


def _data_pass_request(args):
    """The DataPassRequest of ``--data-passes`` (None without it); a bad value is a SceneError naming the option."""
    spec = getattr(args, "data_passes", None)
    if not spec:
        return None
    from .render.data_passes import ALL_PASSES, DataPassRequest, Mist
    names = ALL_PASSES if spec.strip() == "all" else tuple(n.strip() for n in spec.split(",") if n.strip())
    unknown = [n for n in names if n not in ALL_PASSES]
    if unknown or not names:
        raise SceneError("--data-passes", f"must be 'all' or a comma-separated list of {', '.join(ALL_PASSES)}; "
                                          f"got {spec!r}")
    mist = Mist()
    if args.mist:
        parts = [p.strip() for p in args.mist.split(",")]
        try:
            if len(parts) not in (2, 3):
                raise ValueError("START,DEPTH[,FALLOFF] expected")
            mist = Mist(float(parts[0]), float(parts[1]), *(parts[2:]))
        except ValueError as e:
            raise SceneError("--mist", f"START,DEPTH[,FALLOFF] with START, DEPTH ≥ 0 and FALLOFF quadratic, linear "
                                       f"or inverse_quadratic; got {args.mist!r} ({e})") from None
    for option, value, lo, hi in (("--cryptomatte-levels", args.cryptomatte_levels, 2, 16),
                                  ("--data-samples", args.data_samples, 1, 1 << 24)):
        if value is not None and not lo <= value <= hi:
            raise SceneError(option, f"must be an integer in [{lo}, {hi}], got {value}")
    return DataPassRequest(frozenset(names), cryptomatte_levels=args.cryptomatte_levels, mist=mist,
                           samples=args.data_samples)


def _light_pass_keys(args) -> tuple:
    """The light passes ``--light-passes`` asks for (engine keys; () without it); a bad value is a SceneError."""
    spec = getattr(args, "light_passes", None)
    if not spec:
        return ()
    from .render.light_passes import ALL_LIGHT_PASSES
    names = ALL_LIGHT_PASSES if spec.strip() == "all" else tuple(n.strip() for n in spec.split(",") if n.strip())
    if not names or any(n not in ALL_LIGHT_PASSES for n in names):
        raise SceneError("--light-passes", f"must be 'all' or a comma-separated list of {', '.join(ALL_LIGHT_PASSES)}; "
                                           f"got {spec!r}")
    return names


def _add_light_passes(renderer, settings, keys: tuple, result) -> None:
    """Trace the light passes (engine.render.light_passes) into ``result`` (the passes ``keys`` to write)."""
    from .render.light_passes import render_light_passes
    result.light_passes = render_light_passes(renderer, settings)
    result.light_pass_keys = keys
    for w in result.light_passes.warnings:
        print(f"warning: {w}", file=sys.stderr)


def _light_pass_channels(result, meta: dict, channels: dict | None) -> dict | None:
    """``channels`` with the light passes' EXR channels of ``--light-passes`` (and their header entry)."""
    light = getattr(result, "light_passes", None)
    if light is None:
        return channels
    meta["polar.light_samples"] = int(light.samples)
    return {**(channels or {}), **light.channels(result.light_pass_keys)}


def _render_request(renderer, request):
    """``renderer.render(request)``; a Dask scheduler that cannot be reached or used is a SceneError
    naming --scheduler."""
    if request.scheduler is None:
        return renderer.render(request)
    try:
        return renderer.render(request)
    except OSError as e:
        raise SceneError("--scheduler", f"cannot reach the Dask scheduler at {request.scheduler}: {e}") from None
    except RuntimeError as e:
        raise SceneError("--scheduler", str(e)) from None


class _Prediction:
    """An adaptive render's ``on_first_pass``: records in ``first`` the prediction made after the first
    pass (from the pass's ``unit_times``)."""

    def __init__(self, settings, adaptive):
        self.settings, self.adaptive, self.first, self.unit_times = settings, adaptive, {}, []

    def __call__(self, film, halves, seconds, samples):
        from .render.estimate import cost_map, predict, tile_cost_per_sample
        ad = self.adaptive
        if samples > 0 and ad.threshold > 0 and self.unit_times:
            costs = cost_map(self.unit_times, film.count.size, seconds, tile_cost_per_sample(film, halves))
            self.first["prediction"] = predict(film, halves, ad.quantity, ad.threshold, ad.min_spp,
                                               self.settings.spp, costs, sampler=self.settings.sampler)


def _adaptive_report(result, adaptive) -> tuple[dict, dict]:
    """(extra channels, header entries) of an adaptive render, and its summary printed on stderr."""
    import numpy as np
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):    # ∞: no estimate (handled)
        return _adaptive_summary(result, adaptive)


def _adaptive_summary(result, adaptive) -> tuple[dict, dict]:
    import numpy as np

    from .render.adaptive import UNITS, film_noise, image_error, state_channels
    film, stats = result.film, result.stats
    err, _, tile_err = film_noise(film, result.halves, adaptive.quantity)
    noise = np.where(np.isfinite(err), err, -1.0).reshape(film.height, film.width)
    extra = {"noise": noise.astype("float32"), **state_channels(film, result.halves)}
    meta = {"polar.stop_reason": stats["stop_reason"], "polar.noise_quantity": adaptive.quantity,
            "polar.noise_threshold": float(adaptive.threshold), "polar.min_spp": int(adaptive.min_spp),
            "polar.time_limit": float(adaptive.time_limit), "polar.noise_tile": 4}
    lit = film.count > 0
    counts = film.count[lit]
    finite = tile_err[lit & np.isfinite(err) & np.isfinite(tile_err)]
    achieved = (f"achieved {adaptive.quantity} error (tile RMS): median {np.median(finite):.3g}, "
                f"95th percentile {np.percentile(finite, 95):.3g}, max {finite.max():.3g} {UNITS[adaptive.quantity]}"
                if finite.size else "no error estimate (fewer than 2 samples)")
    rms = image_error(film, result.halves, adaptive.quantity)
    achieved += (f"; image RMS {rms:.3g}" + (" (÷ the image's mean luminance)" if adaptive.quantity == "s0" else "")
                 if np.isfinite(rms) else "")
    print(f"polar: adaptive: stopped by {stats['stop_reason']}; {achieved}; samples per pixel median "
          f"{np.median(counts):.0f}, 95th percentile {np.percentile(counts, 95):.0f}, max {counts.max()}",
          file=sys.stderr)
    p = stats.get("prediction")
    if p is not None:
        total = float(stats["seconds"])
        print(f"polar: predicted after the first pass: median {p.median:.0f} spp, 95th percentile {p.p95:.0f} spp, "
              f"{p.adaptive_seconds:.1f} s; actual: median {np.median(counts):.0f} spp, "
              f"95th percentile {np.percentile(counts, 95):.0f} spp, {total:.1f} s", file=sys.stderr)
    return extra, meta


def _write_render(args, out, result, st, scene_hash, adaptive=None) -> int:
    """Write the EXR (or a rescue file) and the previews; 0, or 1 if the EXR could not be written."""
    from .output.exr import write_stokes_exr
    from .output.previews import write_previews
    from .output.rescue import save_rescue
    import dataclasses

    from .render.resume import estimator_identity

    stats = result.stats
    error = stats.get("error")
    if result.cancelled:
        print(f"polar: {'stopped' if error else 'interrupted'} — writing the {stats['samples']} finished samples",
              file=sys.stderr)
    print(f"polar: {result.stats_line()}", file=sys.stderr)
    film = result.film
    if result.cancelled and not film.count.any():
        if error:
            print(f"error: --scheduler: {error}; no sample had finished, nothing written", file=sys.stderr)
            return 1
        print("polar: no sample had finished — nothing written", file=sys.stderr)
        return 0
    if not film.count.any():                       # the time limit passed before the first sample finished
        limit = f" of {adaptive.time_limit:g} s" if adaptive is not None else ""
        print(f"error: --time-limit: the time limit{limit} passed before any sample had finished; nothing written"
              f"{' (the existing file is unchanged)' if os.path.exists(out) else ''}: allow more time",
              file=sys.stderr)
        return 2
    spp_image = film.spp_image()
    meta = {"polar.spp": int(st.spp), "polar.complete": int(not result.cancelled),
            "polar.spp_min": int(spp_image.min()), "polar.spp_max": int(spp_image.max()),
            "polar.seed": int(st.seed), "polar.max_depth": int(st.max_depth), "polar.spectral": st.spectral,
            "polar.polarisation": stats["transport"], "polar.transport_reason": stats["transport_reason"],
            "polar.scene": os.path.basename(args.scene),
            "polar.render_seconds": float(stats["seconds"]), "polar.nonfinite_samples": int(stats["nonfinite"]),
            "polar.kernels": stats.get("kernels", ""), "polar.simplified": "; ".join(stats.get("simplified", []))}
    if st.spectral == "mono":
        meta["polar.wavelength_nm"] = float(st.wavelength_nm)
    # the halves as the render resolved them (the resume fingerprint: a resume never mixes them)
    meta.update(estimator_identity(scene_hash, dataclasses.replace(st, halves=result.settings.halves),
                                   stats["transport"], size=(film.width, film.height)))
    extra = {"spp": spp_image.astype("uint32")}
    if adaptive is not None and result.halves is not None:
        more_extra, more_meta = _adaptive_report(result, adaptive)
        extra.update(more_extra)
        meta.update(more_meta)
        meta["polar.complete"] = int(not result.cancelled)
    if args.stderr:
        se = film.stderr_luminance()
        for i in range(4):
            extra[f"S{i}.Y.stderr"] = se[i].astype("float32")
        meta["polar.stderr"] = film.stderr_method
        if film.half_y is not None:
            # the even samples' means and the i.i.d. error (the sums of squares): a resumed render keeps
            # the stratified estimate
            iid = film.stderr_luminance(iid=True)
            for i, even in enumerate(film.even_means_luminance()):
                extra[f"S{i}.Y.even"] = even.astype("float32")
                extra[f"S{i}.Y.stderr_iid"] = iid[i].astype("float32")
    if getattr(film, "has_denoise_data", False):
        # Cycles' denoising guides: albedo (linear sRGB reflectance) and world-space shading normal.
        albedo, normal = film.denoise_data()
        for i, c in enumerate("RGB"):
            extra[f"denoise.albedo.{c}"] = albedo[..., i].astype("float32")
        for i, c in enumerate("XYZ"):
            extra[f"denoise.normal.{c}"] = normal[..., i].astype("float32")
    stokes = result.stokes()
    alpha = film.alpha() if film.has_alpha else None   # coverage of camera rays (transparent film, holdout)
    data = getattr(result, "data_passes", None)        # --data-passes (engine.render.data_passes)
    data_channels = None
    if data is not None:
        meta.update(data.metadata())
        meta["polar.data_samples"] = int(data.samples)
        data_channels = data.channels()
    data_channels = _light_pass_channels(result, meta, data_channels)
    try:
        write_stokes_exr(out, stokes, metadata=meta, extra=extra, alpha=alpha, data=data_channels)
    except Exception as e:              # noqa: BLE001 — whatever failed, the samples must survive
        reason = _reason(e)
        try:
            saved = save_rescue(out, stokes, meta, {**extra, **(data_channels or {}),
                                                    **({} if alpha is None else {"A": alpha})})
        except OSError as lost:
            print(f"error: -o: cannot write {out!r}: {reason}; {lost}: the finished samples are lost",
                  file=sys.stderr)
            return 1
        print(f"error: -o: cannot write {out!r}: {reason}; finished samples saved to {saved}", file=sys.stderr)
        return 1
    written = [out]
    if not args.no_previews:
        try:
            written += write_previews(os.path.splitext(out)[0], stokes, exposure=args.exposure)
        except Exception as e:          # noqa: BLE001 — the EXR is written; previews are a convenience
            print(f"warning: previews not written: {_reason(e)}", file=sys.stderr)
    for path in written:
        print(path)
    if error:
        print(f"error: --scheduler: {error}; the finished samples were written to {out} (incomplete: "
              "continue with --resume, without --scheduler)", file=sys.stderr)
        return 1
    return 0


def _read_polar_exr(path, field, layer=None):
    """(stokes, channels, header) of a Stokes EXR whose Stokes values are all finite, or a SceneError
    naming ``field`` (engine.render.resume.read_polar_exr: missing, a folder, not a regular file, not a
    Stokes EXR; here also: how many pixels hold NaN or ±inf — a Polar render never writes them).

    ``layer``: the view layer to read in a Blender multilayer EXR (``<Layer>.S0.R`` …), None: the
    only one holding the Stokes passes."""
    from .render.resume import nonfinite_pixels, read_polar_exr
    stokes, channels, header = read_polar_exr(path, field, layer)
    bad = nonfinite_pixels(stokes)
    if bad:
        raise SceneError(field, f"{path!r} has non-finite Stokes values (NaN or ±inf) in {bad} of its "
                                f"{stokes.shape[1] * stokes.shape[2]} pixels; the polariser needs finite values")
    return stokes, channels, header


def _parse_params(pairs):
    params = {}
    for item in pairs or []:
        if "=" not in item:
            raise SceneError("--param", f"must look like NAME=VALUE, got {item!r}")
        key, value = item.split("=", 1)
        params[key.strip()] = value.strip()
    return params


def _mueller(args) -> int:
    from .materials.catalogue import CATALOGUE, make_model
    from .materials.evaluate import mueller_at
    from .media.catalogue import PHASE_MODELS

    if not (360 <= args.wavelength_nm <= 830):
        raise SceneError("--wavelength-nm", f"must be in [360, 830], got {args.wavelength_nm:g}")
    if args.model in PHASE_MODELS:
        return _mueller_phase(args)
    if args.model not in CATALOGUE:
        raise SceneError("model", f"unknown model {args.model!r} (BSDF models: {', '.join(CATALOGUE)}; phase "
                                  f"functions: {', '.join(PHASE_MODELS)})")
    model = make_model(args.model, _parse_params(args.param))
    if args.scattering_angle is not None:
        raise SceneError("--scattering-angle", f"is only for phase functions ({', '.join(PHASE_MODELS)}); for "
                                               f"the BSDF {args.model!r} give --theta-i and --theta-o")
    for name, v in (("--theta-i", args.theta_i), ("--theta-o", args.theta_o)):
        if v is None:
            raise SceneError(name, "is required for a BSDF model (an angle in [0, 90] degrees)")
        if not (0 <= v <= 90):
            raise SceneError(name, f"must be in [0, 90], got {v:g}")
    phi_o = 0.0 if args.phi_o is None else args.phi_o
    _finite("--phi-o", phi_o)
    basis = args.basis or "sp"
    result = mueller_at(model, args.theta_i, args.theta_o, phi_o, args.wavelength_nm, basis)
    result.update(model=args.model, params=_parse_params(args.param),
                  geometry={"theta_i_deg": args.theta_i, "theta_o_deg": args.theta_o, "phi_o_deg": phi_o,
                            "wavelength_nm": args.wavelength_nm})
    print(json.dumps(result))
    return 0


def _mueller_phase(args) -> int:
    """`mueller` for a phase function: its matrices at the scattering angles, in the scattering-plane frames."""
    from .media.catalogue import make_phase, phase_matrices_at

    for name, given in (("--theta-i", args.theta_i), ("--theta-o", args.theta_o), ("--phi-o", args.phi_o)):
        if given is not None:
            raise SceneError(name, f"is only for BSDF models; the phase function {args.model!r} takes "
                                   "--scattering-angle DEG (in [0, 180], repeatable)")
    if args.basis not in (None, "scattering"):
        raise SceneError("--basis", f"a phase function's matrices are given in the scattering-plane frames only "
                                    f"(--basis scattering), got {args.basis!r}")
    if not args.scattering_angle:
        raise SceneError("--scattering-angle", "is required for a phase function (an angle in [0, 180] degrees, "
                                               "repeatable)")
    for v in args.scattering_angle:
        if not (0 <= v <= 180):
            raise SceneError("--scattering-angle", f"must be in [0, 180], got {v:g}")
    params = _parse_params(args.param)
    phase = make_phase(args.model, params)
    result = {"model": args.model, "params": params, "basis": "scattering", "wavelength_nm": args.wavelength_nm,
              "scattering_angles_deg": args.scattering_angle}
    result.update(phase_matrices_at(phase, args.scattering_angle, args.wavelength_nm))
    print(json.dumps(result))
    return 0


#: Output extensions of `polariser`: tonemapped PNG or linear EXR (a --sweep contact sheet: PNG only).
POLARISER_OUTPUTS = (".png", ".exr")
#: Defaults of the polariser options (None in the parser, so that an option given where it does nothing is seen).
POLARISER_DEFAULTS = {"type": "linear", "angle": 0.0, "extinction": 0.0, "retarder_angle": 45.0,
                      "retardance": 90.0, "exposure": 0.0}


def _polariser_options(args) -> str:
    """Refuse options that would do nothing in this mode, and outputs the writer does not produce; then
    set the defaults of the options not given.  Returns the output's extension (".png" or ".exr")."""
    given = {k for k in POLARISER_DEFAULTS if getattr(args, k) is not None} | \
        {k for k in ("sweep", "mosaic_layout") if getattr(args, k) is not None}

    def flag(k):
        return "--" + k.replace("_", "-")

    def refuse(keys, why):
        for k in keys:
            if k in given:
                raise SceneError(flag(k), why)
    ext = os.path.splitext(args.output)[1].lower()
    allowed = (".png",) if args.sweep is not None and not args.mosaic else POLARISER_OUTPUTS
    if ext not in allowed:
        what = ("--sweep writes a PNG contact sheet: the output must end in .png" if len(allowed) == 1 else
                "the output must end in .png (tonemapped) or .exr (linear)")
        raise SceneError("-o", f"{what}, got {args.output!r}")
    if args.mosaic:
        refuse(("sweep", "type", "angle", "retarder_angle", "retardance"),
               "does not combine with --mosaic (the micro-polarisers' angles are --mosaic-layout)")
    else:
        refuse(("mosaic_layout",), "only applies with --mosaic")
        kind = args.type or POLARISER_DEFAULTS["type"]
        if kind != "retarder":
            refuse(("retarder_angle", "retardance"), f"only applies with --type retarder (not {kind})")
        if kind.startswith("circular"):
            refuse(("angle", "extinction", "sweep"), f"does not apply to --type {kind} (a circular analyser has "
                                                      "no transmission axis)")
        if args.sweep is not None:
            refuse(("angle",), "does not combine with --sweep (the sweep gives the angles)")
    if ext == ".exr":
        refuse(("exposure",), "only applies to a PNG output (an EXR is written linear, without exposure)")
    for k, v in POLARISER_DEFAULTS.items():
        if getattr(args, k) is None:
            setattr(args, k, v)
    return ext


def _write_filtered_exr(out, image, stokes_shape, metadata):
    """Write a filtered (unpolarised) image as a Stokes EXR; values beyond float32 are a SceneError (-o)."""
    import numpy as np

    from .output.exr import write_stokes_exr
    over = int(np.count_nonzero(np.abs(image) > np.finfo(np.float32).max))
    if over:
        raise SceneError("-o", f"{over} filtered values exceed the float32 range of an EXR (±3.4e38); write a .png")
    unpolarised = np.zeros(stokes_shape, np.float32)        # as the Stokes EXR stores it
    unpolarised[0] = image
    write_stokes_exr(out, unpolarised, metadata=metadata)


def _sweep_angles(start: float, stop: float, step: float, frames: int) -> list:
    """The angles of ``np.arange(start, stop + 1e-9, step)`` (what --sweep always gave: STOP included
    despite rounding), computed as numpy does, without building that range where the 1e-9 would make it
    vast (a STEP of 1e-20) or empty (START of 1e300): then the ``frames`` = ⌊(STOP − START)/STEP⌋ + 1."""
    import numpy as np
    n = math.ceil(((stop + 1e-9) - start) / step)
    n = n if frames <= n <= frames + 1 else frames
    angles = start + np.arange(n, dtype=np.float64) * ((start + step) - start)
    if n > 1:
        angles[1] = start + step
    return list(angles)


def _polariser(args) -> int:
    """`polariser`: one filter (PNG or EXR), a --sweep contact sheet (PNG) or a --mosaic.  Options that do
    nothing in the chosen mode, other output extensions, non-regular or non-finite inputs: one error line."""
    ext = _polariser_options(args)
    if getattr(args, "mosaic", False):
        return _polariser_mosaic(args, ext)
    from .output.colormaps import tonemap
    from .output.png import write_png
    from .postprocess.filters import apply_filter, filter_row
    from .postprocess.sheets import contact_sheet

    if not (0.0 <= args.extinction <= 1.0):
        raise SceneError("--extinction", f"must be in [0, 1], got {args.extinction:g}")
    for field, value in (("--angle", args.angle), ("--retarder-angle", args.retarder_angle),
                         ("--retardance", args.retardance)):
        _finite(field, value)
    _finite("--exposure", args.exposure, -EXPOSURE_LIMIT_STOPS, EXPOSURE_LIMIT_STOPS)
    out = args.output
    angles = None
    if args.sweep is not None:
        try:
            start, stop, step = (float(v) for v in args.sweep.split(":"))
        except ValueError:
            raise SceneError("--sweep", f"must look like START:STOP:STEP in degrees, got {args.sweep!r}") from None
        if not all(math.isfinite(v) for v in (start, stop, step)):
            raise SceneError("--sweep", f"START, STOP and STEP must be finite numbers, got {args.sweep!r}")
        if step <= 0 or stop < start:
            raise SceneError("--sweep", "needs STEP > 0 and STOP ≥ START")
        span = (stop - start) / step
        if not span < MAX_SWEEP_FRAMES:                    # also ∞ (STOP − START overflows, a subnormal STEP)
            frames = f"{math.floor(span) + 1}" if math.isfinite(span) else "more than"
            raise SceneError("--sweep", f"would make {frames} frames; at most {MAX_SWEEP_FRAMES} (use a larger STEP)")
        angles = _sweep_angles(start, stop, step, math.floor(span) + 1)
    stokes, _, _ = _read_polar_exr(args.exr, "EXR", args.layer)

    def filtered(angle):
        row = filter_row(args.type, angle, args.extinction, args.retarder_angle, args.retardance)
        return apply_filter(stokes, row)

    try:
        os.makedirs(os.path.dirname(os.path.abspath(out)) or ".", exist_ok=True)
        if angles is not None:
            tiles = [tonemap(filtered(a), args.exposure) for a in angles]
            write_png(out, contact_sheet(tiles, [f"{a:g}" for a in angles]))
        elif ext == ".exr":
            _write_filtered_exr(out, filtered(args.angle), stokes.shape, {"polar.filter": args.type,
                                                                         "polar.filter_angle_deg": args.angle})
        else:
            write_png(out, tonemap(filtered(args.angle), args.exposure))
    except OSError as e:
        raise SceneError("-o", f"cannot write {out!r}: {_reason(e)}") from None
    print(out)
    return 0


def _adaptive_options(r) -> None:
    g = r.add_argument_group("adaptive sampling (after --min-spp samples, only tiles whose estimated error "
                             "is above the threshold, and above their share of the image's error, get more, "
                             "up to --spp)")
    g.add_argument("--noise-threshold", type=float, metavar="T",
                   help="standard error to reach: relative for s0/stokes, absolute for dolp/docp, degrees for aolp; "
                        "tiles noisier than the image's mean stop at T·√(σ/σ̄), where more samples buy less")
    g.add_argument("--noise-quantity", default="s0", metavar="Q",
                   help="s0 (default) | dolp | aolp | docp | stokes: what the threshold applies to")
    g.add_argument("--min-spp", type=int, metavar="N", help="samples every pixel gets first (default min(16, --spp))")
    g.add_argument("--time-limit", type=float, metavar="S",
                   help="stop sampling after S seconds (0 = no limit); alone (no --noise-threshold): a time budget — "
                        "rounds give each tile samples ∝ σ/√cost (the threshold's share rule) for a cost growing "
                        "≈ 30 %% a round, until the time is up or every noisy tile has --spp")


def _adaptive_spp(spp: int) -> None:
    """A SceneError naming --spp if adaptive sampling cannot use ``spp`` (both half-buffers need a sample)."""
    if spp < 2:
        raise SceneError("--spp", f"must be at least 2 with adaptive sampling (even and odd samples), got {spp}")


def _adaptive_settings(args, spp: int):
    """AdaptiveSettings from the render options, or None for a uniform render (SceneError on bad values)."""
    from .render.adaptive import check_adaptive
    given = args.noise_threshold is not None or args.time_limit is not None
    if not given:
        for option, value in (("--min-spp", args.min_spp),):
            if value is not None:
                raise SceneError(option, "only applies to adaptive sampling: add --noise-threshold or --time-limit")
        if args.noise_quantity != "s0":
            raise SceneError("--noise-quantity", "only applies to adaptive sampling: add --noise-threshold")
        return None
    _adaptive_spp(spp)
    min_spp = args.min_spp if args.min_spp is not None else min(16, spp)
    threshold = args.noise_threshold
    ad = check_adaptive(threshold if threshold is not None else 1.0, args.noise_quantity, min_spp,
                        args.time_limit if args.time_limit is not None else 0.0, spp)
    if threshold is None:      # a time limit alone: budget mode (engine.render.adaptive.budget_targets)
        ad.threshold = 0.0
    return ad


def _estimate(args) -> int:
    """`estimate`: its options --spp, --seed, --min-spp and the thresholds follow render's rules (the same
    validators); its work is bounded whatever --spp: a pilot of --pilot-spp (≤ 4096) samples per pixel, one
    tile probed to at most 1024 spp (engine.render.estimate.round_overhead), the predictions arithmetic."""
    from .render.adaptive import check_adaptive, checkpoints
    from .render.estimate import ROUND_PROBE_MAX_SPP, parse_target, pilot_render, predict, round_overhead
    from .render.renderer import Renderer

    targets = [parse_target(t) for t in args.target]
    if not (2 <= args.pilot_spp <= MAX_PILOT_SPP):
        raise SceneError("--pilot-spp", f"must be an integer in [2, {MAX_PILOT_SPP}], got {args.pilot_spp}")
    scene = _load_scene(args.scene)
    st = _settings_from_options(scene, args)
    _adaptive_spp(st.spp)
    min_spp = args.min_spp if args.min_spp is not None else min(16, st.spp)
    for quantity, threshold in targets:
        check_adaptive(threshold, quantity, min_spp, 0.0, st.spp, threshold_field="--target", quantity_field="--target")
    renderer = Renderer(scene)
    cam = scene.camera
    print(f"polar: {os.path.basename(args.scene)}: {cam.width}×{cam.height}, pilot {args.pilot_spp} spp, "
          f"adaptive {min_spp}…{st.spp} spp ({len(checkpoints(min_spp, st.spp))} checkpoints)", file=sys.stderr)
    pilot, sps = pilot_render(renderer, st, args.pilot_spp)
    print(f"pilot: {pilot.stats['samples']} samples in {pilot.stats['seconds']:.2f} s "
          f"({pilot.stats['seconds'] / max(pilot.stats['samples'], 1) * 1e6:.2f} µs per sample on this machine, "
          f"{float(sps.min()) * 1e6:.2f}–{float(sps.max()) * 1e6:.2f} by region)")
    per_round = round_overhead(renderer, st, pilot, sps, min_spp)
    print(f"rounds: {per_round * 1e3:.0f} ms each besides their samples (one tile through the checkpoints up to "
          f"{min(st.spp, ROUND_PROBE_MAX_SPP)} spp)")
    for quantity, threshold in targets:
        p = predict(pilot.film, pilot.halves, quantity, threshold, min_spp, st.spp, sps, round_seconds=per_round,
                    sampler=st.sampler)
        print(f"target {p.describe()}")
    return 0


def _polariser_mosaic(args, ext: str) -> int:
    """--mosaic: the raw image of a polarisation camera (2×2 micro-polarisers, engine.postprocess.mosaic)."""
    from .output.colormaps import tonemap
    from .output.png import write_png
    from .postprocess.mosaic import DEFAULT_LAYOUT, mosaic, parse_layout

    if not (0.0 <= args.extinction <= 1.0):
        raise SceneError("--extinction", f"must be in [0, 1], got {args.extinction:g}")
    _finite("--exposure", args.exposure, -EXPOSURE_LIMIT_STOPS, EXPOSURE_LIMIT_STOPS)
    layout = parse_layout(args.mosaic_layout.split(",") if args.mosaic_layout is not None else DEFAULT_LAYOUT,
                          "--mosaic-layout")
    stokes, _, _ = _read_polar_exr(args.exr, "EXR", args.layer)
    raw = mosaic(stokes, layout, args.extinction)
    out = args.output
    try:
        os.makedirs(os.path.dirname(os.path.abspath(out)) or ".", exist_ok=True)
        if ext == ".exr":
            _write_filtered_exr(out, raw, stokes.shape, {
                "polar.filter": "mosaic", "polar.mosaic_layout_deg": ",".join(f"{a:g}" for r in layout for a in r),
                "polar.filter_extinction": f"{args.extinction:g}"})
        else:
            write_png(out, tonemap(raw, args.exposure))
    except OSError as e:
        raise SceneError("-o", f"cannot write {out!r}: {_reason(e)}") from None
    print(out)
    return 0


VERBOSE_HELP = "also show warnings from the libraries the engine uses (Numba, …), hidden by default"


def _light_path_options(parser) -> None:
    """Cycles' light-path settings (engine.scene.description.LIGHT_PATH_FIELDS) as options: --max-diffuse-bounces N,
    --clamp-indirect X, --caustics-reflective on|off, …; the scene's values where not given."""
    group = parser.add_argument_group("Cycles' light paths (default: the scene's; docs/guide/scene-format.md)")
    for f in LIGHT_PATH_FIELDS:
        option = "--" + f.name.replace("_", "-")
        if f.kind == "bool":
            group.add_argument(option, type=_on_off, metavar="on|off",
                               help=f.help + f" (default: the scene's; {'on' if f.default else 'off'} if unset)")
        else:
            rng = f"[{f.lo:g}, {f.hi:g}]"
            group.add_argument(option, type=int if f.kind == "int" else float, metavar="N" if f.kind == "int" else "X",
                               help=f"{f.help}; {rng} (default: the scene's; {f.default:g} if unset: off)")


def _on_off(text: str) -> bool:
    if text not in ("on", "off"):
        raise argparse.ArgumentTypeError(f"must be on or off, got {text!r}")
    return text == "on"


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m engine", description="Polar: polarised spectral path tracer")
    sub = ap.add_subparsers(dest="command", required=True)

    r = sub.add_parser("render", help="render a scene file to a Stokes EXR (+ PNG previews)")
    r.add_argument("scene", help="scene JSON (engine format or a shared/peers scene)")
    r.add_argument("-o", "--output", required=True, help="output .exr path")
    r.add_argument("--spp", type=int, help="samples per pixel (default: the scene's)")
    r.add_argument("--seed", type=int, help="random seed (default: the scene's)")
    r.add_argument("--max-depth", type=int, help="maximum path segments (1 = emitters only)")
    r.add_argument("--spectral", choices=("spectral", "rgb", "mono"),
                   help="4 wavelengths per path, RGB channels (Cycles' colour arithmetic) or one wavelength")
    r.add_argument("--wavelength-nm", type=float, help="wavelength of --spectral mono (nm)")
    r.add_argument("--polarisation", choices=("auto", "full", "linear", "off"),
                   help="auto (default: the cheapest exact transport), full 4×4, linear 3×3 or scalar")
    r.add_argument("--reduce-spectral", choices=("auto", "exact", "off"),
                   help="where no material depends on λ: auto (RGB with exact light colours), exact "
                        "(sampled λ, one Mueller product per path) or off")
    r.add_argument("--simplify", choices=("auto", "off"),
                   help="auto (default): skip layered coats that are index-matched and clear; off: keep all")
    r.add_argument("--sampler", choices=("sobol", "padded", "cycles", "stratified", "independent"),
                   help="sobol (the default, as in Blender: stratified's numbers at the camera, Cycles' sets at the "
                        "first vertex, per-pixel shuffled, Owen-scrambled Sobol' pairs at every deeper vertex: less "
                        "noise, same expectation; --stderr comes from two classes of the samples), padded "
                        "(every number from its own shuffled Sobol' pair, the pixel jitter Owen-scrambled, the others "
                        "digitally shifted), "
                        "stratified (Sobol' pixel jitter, lens, wavelengths and first-vertex light/BSDF numbers, "
                        "deeper ones hashed) or independent (hashed numbers)")
    r.add_argument("--halves", choices=HALVES_MODES,
                   help="how a pixel's samples draw the low-discrepancy pattern: one_sequence (the sample index used "
                        "whole: the first 2^m samples one net; less noise; adaptive sampling and --stderr take the "
                        "error from two classes of its samples, calibrated), independent (the even and odd samples "
                        "two independently scrambled sequences, whose means give the error: the images of earlier "
                        "versions) or auto (default: one sequence)")
    r.add_argument("--light-tree", choices=LIGHT_TREE_MODES,
                   help="next-event estimation's light choice: on (the light tree over lamps and emissive triangles, "
                        "as Cycles' Light Tree), off (the scene's light_selection over whole lights) or auto (default: "
                        "the tree where the scene has more than 64 emitters)")
    r.add_argument("--parallel", choices=PARALLEL_MODES,
                   help="how the local workers run: threads, processes (a pool of worker processes: every core, also "
                        "where Python-shaded materials make threads convoy on the GIL) or auto (default: processes "
                        "where threads would convoy and the render is large enough to pay for starting them)")
    _light_path_options(r)
    r.add_argument("--exposure", type=float, default=0.0, help="preview exposure in stops")
    r.add_argument("--no-previews", action="store_true", help="write only the EXR")
    r.add_argument("--stderr", action="store_true", help="also write per-pixel standard errors")
    r.add_argument("--denoise-data", action="store_true",
                   help="also write denoising guides (channels denoise.albedo.R/G/B, denoise.normal.X/Y/Z: "
                        "albedo and shading normal at the first non-mirror hit, as Cycles' denoising data)")
    r.add_argument("--data-passes", metavar="LIST",
                   help="also write Cycles' data passes and Cryptomatte, comma-separated or 'all': depth, mist, "
                        "normal, position, uv, vector, object_index, material_index, crypto_object, "
                        "crypto_material, crypto_asset (channels Depth.Z, Normal.X/Y/Z, CryptoObject00.r/g/b/a …)")
    r.add_argument("--light-passes", metavar="LIST",
                   help="also write Cycles' light passes with their Stokes components, comma-separated or 'all': "
                        "diffuse_direct, diffuse_indirect, diffuse_color, glossy_direct, glossy_indirect, "
                        "glossy_color, transmission_direct, transmission_indirect, transmission_color, volume_direct, "
                        "volume_indirect, emission, environment "
                        "(channels 'Diffuse Direct.R/G/B' = S0, 'Diffuse Direct S1.R' … 'S3.B'; "
                        "Color passes S0 only); traced as a second pass over the render's samples")
    r.add_argument("--data-samples", type=int, metavar="N",
                   help="samples per pixel of the data passes (default min(spp, 64): the render's first camera rays)")
    r.add_argument("--cryptomatte-levels", type=int, default=6, metavar="N",
                   help="Cryptomatte ranks per pixel, 2..16 (default 6, as Cycles)")
    r.add_argument("--mist", metavar="START,DEPTH[,FALLOFF]",
                   help="the Mist pass's ramp (default 5,25,quadratic; falloff quadratic|linear|inverse_quadratic)")
    r.add_argument("--resume", metavar="EXR", help="continue the (interrupted) render stored in this EXR")
    r.add_argument("--scheduler", metavar="ADDRESS", help="render on a Dask cluster, e.g. tcp://host:8786 "
                                                          "(same image as a local render)")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    _adaptive_options(r)
    r.set_defaults(func=_render)

    e = sub.add_parser("estimate", help="predict the samples and time a target accuracy needs (short pilot render)")
    e.add_argument("scene", help="scene JSON (engine format or a shared/peers scene)")
    e.add_argument("--target", action="append", required=True, metavar="QUANTITY:THRESHOLD",
                   help="e.g. dolp:0.01 or s0:0.02 (repeatable); quantities s0|dolp|aolp|docp|stokes")
    e.add_argument("--pilot-spp", type=int, default=16, help="samples per pixel of the pilot render (default 16)")
    e.add_argument("--spp", type=int, help="maximum samples per pixel (default: the scene's)")
    e.add_argument("--min-spp", type=int, default=None, help="adaptive minimum samples per pixel (default 16)")
    e.add_argument("--seed", type=int, help="random seed (default: the scene's)")
    e.set_defaults(func=_estimate)

    k = sub.add_parser("precompile", help="compile every kernel into the on-disk cache (what the first render "
                                          "would otherwise do; instant when already done)")
    k.add_argument("--force", action="store_true", help="render every case even if the cache is marked complete")
    k.add_argument("--threads", type=int, default=0, help="worker threads (default: one per core)")
    k.set_defaults(func=_precompile)

    from .materials.catalogue import MODEL_PARAMETERS, parameter_help   # the declared models and parameters
    from .media.catalogue import PHASE_MODELS, phase_parameter_help
    m = sub.add_parser("mueller", help="print one model's Mueller BRDF at one geometry, or a phase function's "
                                       "Mueller matrices at scattering angles, as JSON",
                       epilog=parameter_help() + "\n\n" + phase_parameter_help(),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    m.add_argument("--model", required=True, help=" | ".join([*MODEL_PARAMETERS, *PHASE_MODELS]))
    m.add_argument("--param", action="append", metavar="NAME=VALUE", help="model parameter (repeatable)")
    m.add_argument("--theta-i", type=float, help="incidence angle (deg; BSDF models, required there)")
    m.add_argument("--theta-o", type=float, help="viewing angle (deg; BSDF models, required there)")
    m.add_argument("--phi-o", type=float, help="viewing azimuth (deg; BSDF models), 0 = forward side (the default)")
    m.add_argument("--scattering-angle", type=float, action="append", metavar="DEG",
                   help="scattering angle Θ in [0, 180] deg, 0 = straight on (phase functions, required there; "
                        "repeatable)")
    m.add_argument("--wavelength-nm", type=float, default=550.0, help="wavelength (nm)")
    m.add_argument("--basis", choices=("sp", "scattering"), help="Stokes basis of the result: sp (the default for "
                   "BSDF models) or scattering (x ⟂ the scattering plane on both beams; phase functions use only it)")
    m.set_defaults(func=_mueller)

    p = sub.add_parser("polariser", help="what a virtual polarising filter would show, from a rendered EXR")
    p.add_argument("exr", help="a Stokes EXR written by `render`, or a multilayer EXR of a Blender render "
                               "with Polar (its S0…S3 passes)")
    p.add_argument("--layer", metavar="NAME", help="view layer to read from a Blender multilayer EXR (needed "
                   "only when several view layers hold the Stokes passes)")
    p.add_argument("-o", "--output", required=True, help="output .png (tonemapped) or .exr (linear); "
                   "a --sweep writes a .png")
    p.add_argument("--type", choices=("linear", "circular-right", "circular-left", "retarder"),
                   help="the filter (default linear)")
    p.add_argument("--angle", type=float,
                   help="transmission axis in degrees, from image right towards image up (default 0)")
    p.add_argument("--extinction", type=float, help="t_min/t_max of the polariser (0 = ideal, the default)")
    p.add_argument("--retarder-angle", type=float, help="fast axis of the retarder (deg, default 45; "
                   "with --type retarder)")
    p.add_argument("--retardance", type=float, help="retardance of the retarder (deg, default 90; "
                   "with --type retarder)")
    p.add_argument("--sweep", metavar="START:STOP:STEP", help="contact sheet of polariser angles, e.g. 0:180:15")
    p.add_argument("--exposure", type=float, help="PNG exposure in stops (default 0)")
    p.add_argument("--mosaic", action="store_true", help="raw image of a polarisation camera: a 2×2 mosaic of "
                   "micro-polarisers (with --extinction), instead of one filter")
    p.add_argument("--mosaic-layout", metavar="A,B,C,D", help="micro-polariser angles in degrees: row 0 (top) "
                   "left, right, row 1 left, right (default 90,45,135,0)")
    p.set_defaults(func=_polariser)

    ap.add_argument("-v", "--verbose", action="store_true", help=VERBOSE_HELP)
    for command in sub.choices.values():   # also accepted after the command
        command.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help=VERBOSE_HELP)
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if args.verbose:
        from .kernels import library_warnings
        library_warnings(True)
    try:
        return args.func(args)
    except SceneError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader of our stdout went away (`... | head`): not an error of ours, and no traceback.
        # Point stdout at devnull so the interpreter's final flush does not raise again.
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):   # stdout is not a file descriptor (embedding, tests)
            pass
        return 141
