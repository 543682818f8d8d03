"""Render a Scene: split the image into work units, trace them, merge the film.

A work unit is a band of image rows × a range of sample passes, sized so that
one unit traces at most ``settings.batch_rays`` camera paths (bounded
memory).  Units are processed in a fixed order and the stateless sampler
makes every sample independent of the split, so the image is deterministic
for a seed.  Between units the renderer reports progress and asks whether to
stop; a cancelled render returns the finished samples (the film records the
true per-pixel sample count).
"""

from __future__ import annotations

import copy
import math
import os
import time
from collections import deque
from collections.abc import Callable, Iterator
import threading
import weakref
from concurrent.futures import CancelledError, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FuturesTimeout
from dataclasses import dataclass, field

import numpy as np

from .accel import CompiledScene
from .allocator import keep_freed_memory, render_heap, return_freed_memory
from .blas_threads import one_blas_thread
from ..kernels import BACKEND as KERNEL_BACKEND
from .camera import CameraModel
from .effects import effective_materials, resolve_transport
from .film import Film, SampleSums
from .integrator import PathTracer
from .lights import LightSet
from ..scene.description import RenderSettings, Scene
from ..spectral.cie import LUMINANCE_WEIGHTS
from ..errors import SceneError


@dataclass
class RenderResult:
    film: Film
    settings: RenderSettings
    stats: dict = field(default_factory=dict)
    cancelled: bool = False
    halves: object = None        # engine.render.adaptive.HalfBuffers of an adaptive render

    def stokes(self) -> np.ndarray:
        """Stokes image (4, H, W, 3) in the per-pixel camera frame (linear sRGB)."""
        return self.film.mean()

    def stokes_luminance(self) -> np.ndarray:
        """Luminance Stokes image (4, H, W)."""
        return np.einsum("shwc,c->shw", self.stokes(), LUMINANCE_WEIGHTS)


#: How often (seconds) the caller's stop request is polled while units are in flight.
STOP_POLL_SECONDS = 0.05
#: Units submitted per worker thread (one traced, the next queued so that the worker never waits
#: for the thread that adds finished units to the film).
UNITS_AHEAD = 2
#: Fewer work units per worker than this (few passes on a small image): work_units cuts the rows into bands.
UNITS_PER_WORKER = 4
#: Paths traced by Renderer.warm_up (a grid over the image: enough to reach every visible material).
WARM_UP_PATHS = 4096
#: Bytes per pixel of the film (Stokes × RGB sums, luminance sums of squares, sample count).
FILM_BYTES_PER_PIXEL = (4 * 3 + 4 + 1) * 8
#: Bytes per path of a batch in flight (throughput, frames, rays, random keys, accumulators; measured
#: peak ≈ 3 kB per path of full spectral transport, with headroom).
BATCH_BYTES_PER_PATH = 4096


def memory_estimate(width: int, height: int, batch_rays: int, workers: int) -> int:
    """Bytes a render needs besides the scene: the film and the batches in flight."""
    return width * height * FILM_BYTES_PER_PIXEL + workers * batch_rays * BATCH_BYTES_PER_PATH


def available_memory() -> int:
    """Physical memory of this machine in bytes (0 if unknown)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 0


def work_units(width: int, height: int, spp: int, batch_rays: int, first_pass: int = 0,
               window: tuple[int, int, int, int] | None = None,
               workers: int = 1) -> Iterator[tuple[int, int, int, int]]:
    """Yield (row0, row1, pass0, pass1) covering the window's rows × passes [first_pass, spp).

    ``window`` = (x0, y0, x1, y1) in pixels (row 0 at the top, x1/y1 exclusive)
    restricts the rows here and the columns in ``unit_pixels``.

    The passes are grouped by ``batch_rays`` alone: a pixel's sums are added group by group, so the
    grouping fixes the image's bits.  When that gives fewer than ``UNITS_PER_WORKER`` units per
    worker and fewer bands of rows than ``workers`` (a small image, whose passes fit one batch), the
    rows are cut into ``workers`` bands, so that every worker gets a unit of each group (the asset
    suite's 96 × 96 × 16 spp: passes 0–13 and 14–15, each in two bands, not one unit of 14 passes
    traced alone).  Bands change no pixel's additions: the image is the same for any ``workers``
    (and a Dask render, engine.render.distributed, is the local one bit for bit).
    """
    x0, y0, x1, y1 = window or (0, 0, width, height)
    cols = max(x1 - x0, 1)
    rows = y1 - y0
    rows_per_unit = max(1, min(rows, batch_rays // cols))
    passes_per_unit = max(1, batch_rays // (rows_per_unit * cols))
    bands, groups = -(-rows // rows_per_unit), -(-max(spp - first_pass, 0) // passes_per_unit)
    if bands < workers and groups * bands < UNITS_PER_WORKER * workers:
        bands = min(workers, rows)      # (nearly) equal bands, one per worker
        cuts = [y0 + i * rows // bands for i in range(bands + 1)]
    else:
        cuts = list(range(y0, y1, rows_per_unit)) + [y1]
    for p0 in range(first_pass, spp, passes_per_unit):
        p1 = min(spp, p0 + passes_per_unit)
        for r0, r1 in zip(cuts[:-1], cuts[1:]):
            yield r0, r1, p0, p1


def unit_pixels(width: int, r0: int, r1: int, window: tuple[int, int, int, int] | None = None) -> np.ndarray:
    """Flat pixel indices of rows [r0, r1) within the window's columns."""
    x0, _, x1, _ = window or (0, 0, width, 0)
    rows = np.arange(r0, r1, dtype=np.int64)
    return (rows[:, None] * width + np.arange(x0, x1, dtype=np.int64)[None, :]).ravel()


def trace_in_order(units, trace_unit, add_result, workers: int, stop_requested, abort: threading.Event) -> bool:
    """Trace ``units`` on ``workers`` threads and pass each result to ``add_result`` in unit order.

    Units are traced concurrently (Embree and the compiled kernels release the GIL) but added
    strictly in unit order, so the image does not depend on the number of threads.  Up to
    ``UNITS_AHEAD`` units per worker are submitted at once, and the next ones before a finished
    unit is added: a worker that finishes starts its next unit at once instead of waiting for
    this thread (finished results are small: the unit's film sums).  The stop request is polled
    from this (the caller's) thread only — Blender's test_break must not be called from workers —
    and sets ``abort``, which ends units in flight between two bounces (``trace_unit`` then
    returns None and the unit is discarded whole); units not started yet are not traced.  Only a
    prefix of ``units`` is ever added: a later unit that finished while an earlier one was ended is
    discarded too, since a film (and so a resume) counts each pixel's samples as passes 0 … k−1.
    Returns True if stopped.
    """
    cancelled = False
    workers = max(1, min(workers, len(units)))
    ahead = UNITS_AHEAD * workers
    # BLAS's own threads would compete with the workers for the same cores (engine.render.blas_threads)
    with one_blas_thread(), ThreadPoolExecutor(max_workers=workers) as pool:
        pending = deque()
        next_unit = 0
        gap = False

        def stop():
            nonlocal cancelled
            cancelled = True
            abort.set()
            for future in pending:
                future.cancel()             # not started yet: never traced

        def submit():
            nonlocal next_unit
            while not cancelled and next_unit < len(units) and len(pending) < ahead:
                if stop_requested():
                    stop()
                    break
                pending.append(pool.submit(trace_unit, units[next_unit]))
                next_unit += 1

        try:
            submit()
            while pending:
                future = pending[0]
                while not future.done():
                    try:
                        future.result(timeout=STOP_POLL_SECONDS)
                    except FuturesTimeout:
                        if not cancelled and stop_requested():
                            stop()
                    except CancelledError:
                        break
                pending.popleft()
                result = None if future.cancelled() else future.result()
                submit()
                if result is None:
                    gap = True              # ended or never traced: nothing after it may be added
                elif not gap:
                    add_result(result)
        except BaseException:
            stop()                          # a failed unit (or Ctrl-C): trace nothing more
            raise
    return cancelled


class Renderer:
    """Compiles a scene once; ``render`` may then be called repeatedly."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        # Freed batch memory is kept for the next batch, and the next render of this renderer; handed
        # back when the renderer goes (engine.render.allocator).  Set before Embree's threads allocate.
        keep_freed_memory()
        weakref.finalize(self, return_freed_memory).atexit = False     # (not when the process ends anyway)
        t0 = time.perf_counter()
        self.compiled = CompiledScene(scene)
        self.lights = LightSet(scene, self.compiled)
        self.camera = CameraModel(scene.camera)
        self.compile_seconds = time.perf_counter() - t0
        self._live_film = None

    def _tracer(self, settings: RenderSettings | None, count_cost: bool = False):
        """(settings as rendered, PathTracer, simplified materials, transport reason) for ``settings``
        (default: the scene's): the materials' exact simplifications and the transport resolved;
        ``count_cost``: the tracer reports per-path costs (adaptive sampling's)."""
        st = copy.copy(settings or self.scene.settings)
        used = self.compiled.used_material_names
        materials, simplified = effective_materials(self.scene.materials, used, st.simplify)
        st.polarisation, transport_reason = resolve_transport(st.polarisation, materials, used)
        tracer = PathTracer(self.compiled, self.lights, self.camera, st,
                            materials=[materials[name] for name in self.compiled.material_names], count_cost=count_cost)
        return st, tracer, simplified, transport_reason

    def warm_up(self, settings: RenderSettings | None = None, paths: int = WARM_UP_PATHS) -> float:
        """Trace about ``paths`` throw-away paths (one per pixel of a grid spread over the image) as
        a render with ``settings`` would; returns the seconds taken.

        Every compiled kernel those paths call is compiled, or loaded from Numba's cache, now rather
        than inside the first render, where it would also hold the GIL and stall the other workers
        (a corner window of the image misses the objects and so most shading kernels); likewise the
        film's per-unit sums.  Nothing is added to any film; the sampler is stateless, so later renders
        are unchanged.
        """
        t0 = time.perf_counter()
        _, tracer, _, _ = self._tracer(settings)
        W, H = self.scene.camera.width, self.scene.camera.height
        nx = max(1, min(W, round(math.sqrt(paths * W / H))))
        ny = max(1, min(H, paths // nx))
        rows = np.linspace(0, H - 1, ny).round().astype(np.int64)
        cols = np.linspace(0, W - 1, nx).round().astype(np.int64)
        pixel = (rows[:, None] * W + cols[None, :]).ravel()
        with one_blas_thread():
            values, stats = tracer.trace(pixel, np.zeros_like(pixel))
            # and the film's per-unit sums (their kernel loaded in a render stalled the other worker)
            SampleSums.of(pixel, values, stats.get("alpha"), stats.get("denoise"),
                          np.zeros_like(pixel) if (settings or self.scene.settings).stratified else None)
        return time.perf_counter() - t0

    def last_film_mean(self) -> np.ndarray | None:
        """The Stokes image of the render in progress (for progressive display), or None."""
        film = self._live_film
        return None if film is None else film.mean()

    def render(self, settings: RenderSettings | None = None,
               progress: Callable[[float, dict], None] | None = None,
               should_stop: Callable[[], bool] | None = None,
               window: tuple[int, int, int, int] | None = None,
               resume: Film | None = None, adaptive=None, adaptive_resume=None,
               clock: Callable[[], float] | None = None, on_first_pass=None,
               unit_times: list | None = None) -> RenderResult:
        """Render with ``settings`` (default: the scene's).

        ``progress(done_fraction, stats)`` is called after every work unit;
        ``should_stop()`` is polled between units and ends the render early.
        ``window`` = (x0, y0, x1, y1) renders only that pixel rectangle (row 0 at
        the top, exclusive ends); other pixels keep 0 samples.
        ``resume`` = a Film with finished samples (e.g. from an interrupted render's EXR): sample
        passes a pixel already has are not traced again, so the result equals an uninterrupted
        render of ``settings.spp`` samples (the sampler is stateless) up to float rounding.
        ``adaptive`` = engine.render.adaptive.AdaptiveSettings samples adaptively up to
        ``settings.spp`` (``adaptive_resume``: the resumed render's HalfBuffers; ``clock``: seconds
        for the time limit; ``on_first_pass``, ``unit_times``: see render_adaptive); ``stats["stop_reason"]`` says why
        it ended and the result's ``halves`` holds the half-buffers.
        """
        with render_heap():      # inside Blender: the allocator settings for this render only
            return self._render(settings, progress, should_stop, window, resume, adaptive, adaptive_resume,
                                clock, on_first_pass, unit_times)

    def _render(self, settings, progress, should_stop, window, resume, adaptive, adaptive_resume, clock,
                on_first_pass, unit_times) -> RenderResult:
        st, tracer, simplified, transport_reason = self._tracer(settings, count_cost=adaptive is not None)
        cam = self.scene.camera
        W, H = cam.width, cam.height
        workers = st.threads if st.threads > 0 else (os.cpu_count() or 1)
        need, have = memory_estimate(W, H, st.batch_rays, workers), available_memory()
        if have and need > 0.8 * have:
            max_pixels = max(int((0.8 * have - workers * st.batch_rays * BATCH_BYTES_PER_PATH)
                                 / FILM_BYTES_PER_PIXEL), 0)
            raise SceneError("camera.width", f"a {W}×{H} render needs about {need / 2**30:.1f} GiB but this machine "
                                             f"has {have / 2**30:.1f} GiB: use at most ~{max_pixels:,} pixels "
                                             "(or a smaller render.batch_rays)")
        film = Film(W, H)
        done_before = None
        if resume is not None:
            if (resume.width, resume.height) != (W, H):
                raise ValueError(f"cannot resume a {resume.width}×{resume.height} render at {W}×{H}")
            film.merge(resume)
            done_before = resume.count.copy()
        if tracer.channels:
            stats_spectral = "RGB channels (Cycles' colour arithmetic)"
        elif tracer.rgb_mode:
            stats_spectral = "RGB with exactly integrated light spectra (no material depends on λ)"
        elif tracer.uniform:
            stats_spectral = "spectral, one Mueller product per path (no material depends on λ)"
        else:
            stats_spectral = st.spectral
        stats = {"rays": 0, "shadow_rays": 0, "nonfinite": 0, "samples": 0,
                 "compile_seconds": self.compile_seconds, "kernels": KERNEL_BACKEND, "transport": st.polarisation,
                 "transport_reason": transport_reason, "spectral": stats_spectral,
                 "simplified": simplified}
        if window is not None:
            x0, y0, x1, y1 = (int(v) for v in window)
            if not (0 <= x0 < x1 <= W and 0 <= y0 < y1 <= H):
                raise ValueError(f"window {window} must lie inside the {W}×{H} image and be non-empty")
            window = (x0, y0, x1, y1)
        first_pass = int(done_before.min()) if done_before is not None else 0
        units = list(work_units(W, H, st.spp, st.batch_rays, first_pass=first_pass, window=window, workers=workers))
        cols = (window[2] - window[0]) if window else W
        total = sum((r1 - r0) * cols * (p1 - p0) for r0, r1, p0, p1 in units)
        if done_before is not None:
            x0, y0, x1, y1 = window or (0, 0, W, H)
            done = done_before.reshape(H, W)[y0:y1, x0:x1]
            total = int(np.maximum(st.spp - done, 0).sum())
        total = max(total, 1)
        t0 = time.perf_counter()
        cancelled = False
        done = 0
        self._live_film = film

        abort = threading.Event()
        # stratified samples: the film keeps even/odd half sums for an honest standard error (not when
        # resuming a film without them: its error is then the i.i.d. one, an overestimate)
        stratified = st.stratified and (resume is None or resume.half_y is not None)

        def trace_unit(unit):
            r0, r1, p0, p1 = unit
            pix = unit_pixels(W, r0, r1, window)
            pixel = np.tile(pix, p1 - p0)
            sample = np.repeat(np.arange(p0, p1, dtype=np.int64), pix.size)
            if done_before is not None:
                todo = sample >= done_before[pixel]
                pixel, sample = pixel[todo], sample[todo]
            traced = tracer.trace(pixel, sample, abort=abort)
            if traced is None:
                return None
            values, s = traced
            # the unit's film sums, here on the worker: the adding thread only adds them in order
            return SampleSums.of(pixel, values, s.pop("alpha", None), s.pop("denoise", None),
                                 sample if stratified else None), s

        workers = st.threads if st.threads > 0 else (os.cpu_count() or 1)

        def stop_requested():
            return should_stop is not None and should_stop()

        def add_result(result):
            nonlocal done
            part, s = result
            film.add(part)
            for k in ("rays", "shadow_rays", "nonfinite"):
                stats[k] += s[k]
            done += part.n_samples
            stats["samples"] = done
            stats["seconds"] = time.perf_counter() - t0
            if progress is not None:
                progress(done / total, stats)

        if adaptive is not None:
            from .adaptive import HalfBuffers, render_adaptive
            halves = adaptive_resume if adaptive_resume is not None else HalfBuffers(W * H)
            stats["stop_reason"] = render_adaptive(
                tracer, film, halves, st.spp, st.batch_rays, adaptive, window,
                lambda units, trace, add, stop, ab: trace_in_order(units, trace, add, workers, stop, ab),
                stats, progress=progress, should_stop=should_stop, clock=clock or time.perf_counter,
                on_first_pass=on_first_pass, workers=workers, unit_times=unit_times)
            cancelled = stats["stop_reason"] == "cancelled"
            if st.stratified:
                film.half_y = halves.sums       # the half-buffers are the even/odd luminance sums
            stats.setdefault("seconds", 0.0)
            self._live_film = None
            return RenderResult(film=film, settings=st, stats=stats, cancelled=cancelled, halves=halves)
        cancelled = trace_in_order(units, trace_unit, add_result, workers, stop_requested, abort)
        self._live_film = None
        stats["seconds"] = time.perf_counter() - t0
        return RenderResult(film=film, settings=st, stats=stats, cancelled=cancelled)


def render(scene: Scene, settings: RenderSettings | None = None,
           progress: Callable[[float, dict], None] | None = None,
           should_stop: Callable[[], bool] | None = None) -> RenderResult:
    """Convenience: compile and render ``scene`` once."""
    return Renderer(scene).render(settings, progress, should_stop)
