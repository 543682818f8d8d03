"""Render a Scene: the one entry point, ``Renderer.render(RenderRequest)``.

A ``Renderer`` compiles a scene once (BVH, lights, camera); ``render`` then resolves a ``RenderPlan``
(engine.render.plan: transport, simplified materials, spectral reduction, work units), picks the
schedule (uniform passes, or adaptive rounds) and the executor (local threads, or a Dask cluster) and
runs the one driver (engine.render.driver), which adds every traced unit to the film with ``Film.add``.
Units are added in a fixed order and the stateless sampler makes every sample independent of the
split, so the image is deterministic for a seed whatever the threads or the cluster.  Between units
the driver reports progress and asks whether to stop; a cancelled render returns the finished
samples (the film records the true per-pixel sample count).  ``RenderResult.stats_line`` is the one
summary of a render's statistics (CLI and Blender).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
import os
import threading
import time
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .accel import CompiledScene
from .adaptive import AdaptiveRounds
from .allocator import keep_freed_memory, render_heap, return_freed_memory
from .blas_threads import one_blas_thread
from ..kernels import BACKEND as KERNEL_BACKEND
from ..kernels import COMPILES as KERNEL_COMPILES
from .camera import CameraModel
from .driver import LocalThreads, UniformPasses, drive, local_workers, python_shaded
from .film import Film, HalfBuffers, SampleSums
from .integrator import PathTracer
from .media import tracked_media
from .participating import ParticipatingPathTracer
from .lights import LightSet
from .plan import RenderPlan, RenderRequest
from ..scene.description import RenderSettings, Scene
from ..spectral.cie import LUMINANCE_WEIGHTS
from ..errors import SceneError

__all__ = ["RenderRequest", "RenderResult", "Renderer", "render", "stats_line"]


def msamples_per_second(stats: dict) -> float:
    """Camera samples per second of a render's ``stats`` so far, in millions."""
    return stats.get("samples", 0) / max(stats.get("seconds", 0.0), 1e-9) / 1e6


def kernel_compiles() -> tuple[int, float]:
    """(kernels compiled, seconds) in this process so far (engine.kernels.CompileLog)."""
    return KERNEL_COMPILES.snapshot()


def stats_line(stats: dict, sep: str = "; ") -> str:
    """The summary of a render's ``stats`` in one line (parts joined by ``sep``): samples, seconds,
    Msamples/s and rays; transport and why; how the spectrum is carried; the kernels; each exact
    simplification; non-finite samples dropped.  The CLI and Blender both show this line.

    ``seconds`` is the sampling time; kernels compiled for this render (``kernels_compiled``, in
    ``kernel_compile_seconds``: Numba compiles, not loads from its cache) are named with the kernels,
    and said to be outside the render time when they all compiled in ``Renderer.warm_up``."""
    kernels = f"kernels: {stats.get('kernels', '?')}"
    if stats.get("kernels_compiled"):
        kernels += (f", {stats['kernels_compiled']} compiled in {stats.get('kernel_compile_seconds', 0.0):.1f} s "
                    f"(first run only{'' if stats.get('compiled_in_render') else '; not in the render time'})")
    parts = [f"{stats['samples']} samples in {stats.get('seconds', 0.0):.2f} s ({msamples_per_second(stats):.3f} "
             f"Msamples/s), {stats['rays']} rays + {stats['shadow_rays']} shadow rays",
             f"transport: {stats['transport_reason']}", f"spectral: {stats['spectral']}", kernels]
    if stats.get("parallel") == "processes":
        started = (f"; started in {stats['pool_start_seconds']:.1f} s, first render only"
                   if stats.get("pool_start_seconds") else "")
        parts.append(f"parallel: {stats['threads']} processes ({stats['parallel_reason']}{started})")
    elif stats.get("threads_reason"):
        parts.append(f"threads: {stats['threads']} ({stats['threads_reason']})")
    if stats.get("parallel_warning"):
        parts.append(f"parallel: {stats['parallel_warning']}")
    parts += [f"simplified: {why}" for why in stats.get("simplified", [])]
    if stats.get("light_paths"):
        parts.append(f"light paths: {stats['light_paths']}")
    if stats.get("nonfinite"):
        parts.append(f"dropped non-finite samples: {stats['nonfinite']}")
    return sep.join(parts)


@dataclass
class RenderResult:
    film: Film
    settings: RenderSettings         # as rendered (RenderPlan.settings: the transport resolved)
    stats: dict = field(default_factory=dict)
    cancelled: bool = False
    halves: object = None        # engine.render.film.HalfBuffers of an adaptive render

    def stokes(self) -> np.ndarray:
        """Stokes image (4, H, W, 3) in the per-pixel camera frame (linear sRGB)."""
        return self.film.mean()

    def stokes_luminance(self) -> np.ndarray:
        """Luminance Stokes image (4, H, W)."""
        return np.einsum("shwc,c->shw", self.stokes(), LUMINANCE_WEIGHTS)

    def stats_line(self, sep: str = "; ") -> str:
        """:func:`stats_line` of this render."""
        return stats_line(self.stats, sep)


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


def check_memory(plan: RenderPlan, scene_copies: int = 0) -> None:
    """A SceneError if a local render of ``plan`` needs more than 80 % of this machine's memory; ``scene_copies``:
    bytes of the worker processes' compiled scenes (engine.render.processes)."""
    W, H, st = plan.width, plan.height, plan.settings
    need, have = memory_estimate(W, H, st.batch_rays, plan.workers) + scene_copies, available_memory()
    if have and need > 0.8 * have:
        max_pixels = max(int((0.8 * have - plan.workers * st.batch_rays * BATCH_BYTES_PER_PATH - scene_copies)
                             / FILM_BYTES_PER_PIXEL), 0)
        raise SceneError("camera.width", f"a {W}×{H} render needs about {need / 2**30:.1f} GiB but this machine "
                                         f"has {have / 2**30:.1f} GiB: use at most ~{max_pixels:,} pixels "
                                         "(or a smaller render.batch_rays)")


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
        #: seconds spent building the scene (BVH, lights, camera): not kernel compilation
        self.compile_seconds = time.perf_counter() - t0
        self._live_film = None
        #: kernels compiled (count, seconds) in warm_up since the last render reported them
        self._warm_compiles = (0, 0.0)
        #: (scene, its pickle for worker processes, the pickle's SHA-1): _scene_blob
        self._blob = None

    def plan(self, settings: RenderSettings | None = None, window=None, workers: int | None = None) -> RenderPlan:
        """The RenderPlan of rendering this scene with ``settings`` (default: the scene's); threads not set
        (``workers`` None and ``settings.threads`` 0): as many as ``driver.local_workers`` decides."""
        plan = RenderPlan.resolve(self.scene, self.compiled, settings, window, workers)
        if workers is None and plan.settings.threads <= 0:
            n = local_workers(plan.workers, self._used_materials(plan))
            why = ("automatic: one per CPU core" if n == plan.workers else
                   "automatic: one, as the scene's materials are shaded by Python calls that two threads would "
                   "contend for (threads > 0 overrides)")
            plan = dataclasses.replace(plan, workers=n, threads_reason=why)
        return plan

    def tracer(self, plan: RenderPlan, count_cost: bool = False) -> PathTracer:
        """A PathTracer of ``plan`` (its settings and materials); ``count_cost``: per-path costs
        (adaptive sampling's)."""
        world = getattr(self.scene, "medium", None)
        if tracked_media(self.compiled, world):       # participating media: the tracer with medium vertices
            return ParticipatingPathTracer(self.compiled, self.lights, self.camera, plan.settings,
                                           materials=list(plan.materials), count_cost=count_cost, world=world)
        return PathTracer(self.compiled, self.lights, self.camera, plan.settings, materials=list(plan.materials),
                          count_cost=count_cost)

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
        before = kernel_compiles()
        plan = self.plan(settings)
        tracer = self.tracer(plan)
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
                          np.zeros_like(pixel) if plan.split_halves else None)
        count, seconds = (a - b for a, b in zip(kernel_compiles(), before))
        self._warm_compiles = (self._warm_compiles[0] + count, self._warm_compiles[1] + seconds)
        return time.perf_counter() - t0

    def set_camera(self, camera) -> None:
        """Render from ``camera`` (an engine Camera, e.g. the viewport's) from now on; the geometry stays compiled."""
        self.scene = dataclasses.replace(self.scene, camera=camera)
        self.camera = CameraModel(camera)

    @property
    def live_film(self) -> Film | None:
        """The film of the render in progress (for progressive display), or None."""
        return self._live_film

    def last_film_mean(self) -> np.ndarray | None:
        """The Stokes image of the render in progress (for progressive display), or None."""
        film = self._live_film
        return None if film is None else film.mean()

    def render(self, request: RenderRequest | RenderSettings | None = None) -> RenderResult:
        """Render as ``request`` asks (engine.render.plan.RenderRequest; RenderSettings or None: a
        uniform render of those settings, or the scene's).

        A resumed render equals an uninterrupted one of ``settings.spp`` samples (the sampler is
        stateless) up to float rounding; an adaptive render's ``stats["stop_reason"]`` says why it ended
        and the result's ``halves`` holds its half-buffers; a Dask cluster that fails mid-render gives a
        cancelled result with ``stats["error"]``.  A bad scheduler address or a cluster without workers
        raises RuntimeError, an unreachable scheduler OSError.
        """
        request = continue_as_drawn(RenderRequest.of(request), self.scene.settings)
        with render_heap():      # inside Blender: the allocator settings for this render only
            # "auto" halves resolve to one sequence, adaptive or not (engine.render.halves: classes A/B)
            plan = self.plan(request.settings, request.window)
            with self._executor(request, plan) as executor:
                if executor.workers != plan.workers:
                    plan = dataclasses.replace(plan, workers=executor.workers,
                                               threads_reason="" if executor.local else plan.threads_reason)
                return self._render(plan, request, executor)

    @contextlib.contextmanager
    def _executor(self, request: RenderRequest, plan: RenderPlan):
        if request.scheduler is None:
            with self._local_executor(request, plan) as executor:
                yield executor
            return
        from .distributed import DaskCluster
        with DaskCluster(request.scheduler, self.scene, trace_on_worker) as cluster:
            yield cluster

    def _local_executor(self, request: RenderRequest, plan: RenderPlan):
        """Worker processes or threads for a local render of ``plan`` (RenderSettings.parallel, decided by
        engine.render.processes.choose_parallel); processes that cannot start (or whose scene copies would not fit in
        memory: check_memory): threads, whose ``warning`` says why."""
        from .processes import SCENE_COPY_FACTOR, WORKER_BYTES, LocalProcesses, StartFailed, choose_parallel, \
            dumps_scene, start_in_background
        st = plan.settings
        workers = st.threads if st.threads > 0 else (os.cpu_count() or 1)
        x0, y0, x1, y1 = plan.window or (0, 0, plan.width, plan.height)
        mode, why, prestart = choose_parallel(st.parallel, workers, python_shaded(self._used_materials(plan)) > 0,
                                              (x1 - x0) * (y1 - y0) * st.spp)
        warning = None
        if prestart:
            start_in_background(workers)
        if mode == "processes":
            try:
                blob, key = self._scene_blob(dumps_scene)
                try:        # each worker holds its own compiled scene
                    check_memory(dataclasses.replace(plan, workers=workers),
                                 workers * (WORKER_BYTES + SCENE_COPY_FACTOR * len(blob)))
                except SceneError as e:
                    raise StartFailed(f"{workers} copies of the scene do not fit: {e.reason}") from None
                return contextlib.closing(LocalProcesses(blob, workers, why, request.progress, key))
            except StartFailed as e:
                warning = f"worker processes could not start ({e}); rendered on threads"
        check_memory(plan)
        threads = LocalThreads(plan.workers)
        threads.warning = warning
        return contextlib.nullcontext(threads)

    def _used_materials(self, plan: RenderPlan) -> list:
        """The BSDFs of ``plan`` (its simplified materials) that the scene's objects use."""
        return [plan.materials[i] for i in self.compiled.used_materials]

    def _scene_blob(self, dumps) -> tuple[bytes, str]:
        """(the scene pickled for worker processes, its SHA-1) (``dumps``: processes.dumps_scene), once per scene
        object: the compiled state follows ``self.scene`` (set_camera replaces it); pickling and hashing
        SpecGlossEmission's 16 MB took 20 ms a render."""
        import hashlib
        cached = self._blob
        if cached is None or cached[0] is not self.scene:
            blob = dumps(self.scene)
            cached = self._blob = (self.scene, blob, hashlib.sha1(blob).hexdigest())
        return cached[1], cached[2]

    def _render(self, plan: RenderPlan, request: RenderRequest, executor) -> RenderResult:
        W, H = plan.width, plan.height
        film = Film(W, H)
        # samples one sequence: the half sums are its classes A/B (engine.render.halves), and the film says so
        film.one_sequence = plan.stratified and plan.settings.halves == "one_sequence"
        resume = request.resume
        if resume is not None:
            if (resume.width, resume.height) != (W, H):
                raise ValueError(f"cannot resume a {resume.width}×{resume.height} render at {W}×{H}")
            if resume.half_y is not None and resume.halves != film.halves:
                raise ValueError(f"halves: cannot resume a film whose class sums split {resume.halves!r} samples "
                                 f"with {plan.settings.halves!r} ones (leave render.halves 'auto' to continue as "
                                 "it was drawn)")
            film.merge(resume)
        stats = {**plan.stats(), "compile_seconds": self.compile_seconds, "kernels": KERNEL_BACKEND,
                 **executor.stats()}
        if request.adaptive is None:
            schedule = UniformPasses(plan, resume)
        else:
            halves = request.resume_halves if request.resume_halves is not None \
                else HalfBuffers(W * H, plan.settings.halves)
            # the render's split of its samples into classes (a resumed state is the same render's, so its sums
            # were split this way: engine.render.halves)
            halves.halves = plan.settings.halves
            schedule = AdaptiveRounds(plan, film, halves, request.adaptive, executor.workers, stats,
                                      request.on_first_pass, request.unit_times)
        before = kernel_compiles()
        if not executor.local:
            tracer = None
        elif getattr(executor, "traces_elsewhere", False):
            # worker processes trace; this process only if they all die (LocalProcesses builds it then)
            tracer = functools.partial(self.tracer, plan, count_cost=schedule.job.count_cost)
        else:
            tracer = self.tracer(plan, count_cost=schedule.job.count_cost)
        self._live_film = film
        try:
            cancelled = drive(schedule, film, tracer, executor, stats, request)
        finally:
            self._live_film = None
        # kernels compiled by this render's warm-up and inside it (Numba compiles, not cache loads)
        count, seconds = (a - b for a, b in zip(kernel_compiles(), before))
        warm_count, warm_seconds = self._warm_compiles
        self._warm_compiles = (0, 0.0)
        stats.update(kernels_compiled=warm_count + count, kernel_compile_seconds=warm_seconds + seconds,
                     compiled_in_render=count > 0)
        if executor.error:
            stats["error"] = executor.error
        if getattr(executor, "warning", None):
            stats["parallel_warning"] = executor.warning
        return RenderResult(film=film, settings=plan.settings, stats=stats, cancelled=cancelled,
                            halves=schedule.halves)


def continue_as_drawn(request: RenderRequest, scene_settings: RenderSettings) -> RenderRequest:
    """``request`` with ``halves`` "auto" set to the resumed film's split (as the command line's --resume takes the
    file's), so that a continuation never adds samples of the other split to the film's class sums."""
    film = request.resume
    settings = request.settings or scene_settings
    if film is None or film.half_y is None or settings.halves != "auto" or not settings.stratified:
        return request
    return dataclasses.replace(request, settings=dataclasses.replace(settings, halves=film.halves))


#: Tracers (settings) a worker keeps for its scene.
WORKER_TRACERS = 4


class _WorkerScenes:
    """On a Dask worker or a local worker process (engine.render.processes): the compiled scene of the render in
    progress and the tracers of its last ``WORKER_TRACERS`` settings (one scene at a time)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.key, self.renderer, self.tracers, self.seedless = None, None, {}, {}

    def tracer(self, key: str, scene: Scene, settings: RenderSettings, count_cost: bool) -> PathTracer:
        """The tracer of ``settings``: one kept, or one kept for other seeds reseeded (PathTracer.reseeded: a render
        per seed skips rebuilding the shading groups, ≈ 1 ms of SpecGlossEmission's), or a new one."""
        with self.lock:
            if key != self.key:
                self.key, self.renderer, self.tracers, self.seedless = None, None, {}, {}
                self.renderer, self.key = Renderer(scene), key
            which = (repr(settings), count_cost)
            if which not in self.tracers:
                if len(self.tracers) >= WORKER_TRACERS:     # a pool kept for many renders (seeds): the oldest goes
                    self.tracers.pop(next(iter(self.tracers)))
                plan = self.renderer.plan(settings)
                # (the materials' identities too: the sibling shares them)
                seedless = (repr(dataclasses.replace(plan.settings, seed=0)), count_cost,
                            tuple(map(id, plan.materials)))
                sibling = self.seedless.get(seedless)
                tracer = (sibling.reseeded(plan.settings) if sibling is not None
                          else self.renderer.tracer(plan, count_cost))
                if seedless not in self.seedless and len(self.seedless) >= WORKER_TRACERS:
                    self.seedless.pop(next(iter(self.seedless)))
                self.seedless[seedless] = self.tracers[which] = tracer
            return self.tracers[which]


_WORKER_SCENES = _WorkerScenes()


def trace_on_worker(key: str, scene: Scene, job, unit):
    """A Dask task: trace ``unit`` with ``job`` (engine.render.driver) on this worker's compiled ``scene``
    (compiled once per worker process and scene ``key``)."""
    tracer = _WORKER_SCENES.tracer(key, scene, job.settings, job.count_cost)
    with one_blas_thread():             # the worker's threads are its parallelism (engine.render.blas_threads)
        return job(tracer, unit)


def render(scene: Scene, settings: RenderSettings | None = None,
           progress: Callable[[float, dict], None] | None = None,
           should_stop: Callable[[], bool] | None = None) -> RenderResult:
    """Convenience: compile and render ``scene`` once."""
    return Renderer(scene).render(RenderRequest(settings, progress=progress, should_stop=should_stop))
