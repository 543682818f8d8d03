"""Rendering on a Dask cluster: the same work units as a local render, traced on Dask workers.

``render_distributed(scene, address)`` sends the scene to every worker once, submits one task per
work unit (a band of rows × a range of sample passes, engine.render.renderer.work_units) and adds
the returned per-unit sums to the film in unit order.  Because random numbers are a stateless
function of (seed, pixel, sample, dimension) and the sums are added in the same order, the image
is bit-for-bit the single-machine render of the same settings — however many workers there are,
and also when a worker dies: Dask re-runs its unfinished tasks elsewhere, and a re-run unit
returns exactly the same numbers.  Workers keep the compiled scene (BVH) between tasks.

Needs ``pip install "dask[distributed]"`` on the client and the workers, and the engine importable
on the workers (same version).
"""

from __future__ import annotations

import copy
import hashlib
import os
import pickle
import time

import numpy as np

from .blas_threads import one_blas_thread
from .film import Film, SampleSums
from .renderer import STOP_POLL_SECONDS, RenderResult, Renderer, unit_pixels, work_units
from .effects import effective_materials, resolve_transport

#: Per-worker cache of compiled scenes (key → Renderer); a worker process renders one scene at a time.
_COMPILED: dict = {}


def _renderer_for(key, scene):
    renderer = _COMPILED.get(key)
    if renderer is None:
        _COMPILED.clear()
        renderer = _COMPILED[key] = Renderer(scene)
    return renderer


def _render_unit(key, scene, settings, unit, window, width):
    """Trace one work unit on a worker; returns (first pixel, sums (4, 3, n), sumsq (4, n), counts (n,), stats)."""
    from .integrator import PathTracer
    renderer = _renderer_for(key, scene)
    r0, r1, p0, p1 = unit
    pix = unit_pixels(width, r0, r1, window)
    pixel = np.tile(pix, p1 - p0)
    sample = np.repeat(np.arange(p0, p1, dtype=np.int64), pix.size)
    # per-path costs are adaptive sampling's only (_trace_paths)
    tracer = PathTracer(renderer.compiled, renderer.lights, renderer.camera, settings, count_cost=False)
    with one_blas_thread():             # the worker's threads are its parallelism (engine.render.blas_threads)
        values, stats = tracer.trace(pixel, sample)
    lo, hi = int(pix.min()), int(pix.max()) + 1
    part = Film(hi - lo, 1)
    stratified = settings.stratified
    part.add(SampleSums.of(pixel - lo, values, stats.pop("alpha", None), sample=sample if stratified else None))
    if part.half_y is not None:
        stats["half_y"] = part.half_y                   # even/odd luminance sums (the standard error)
    if part.has_alpha:
        stats["alpha_sums"] = part.alpha_sums           # coverage (film transparency, holdouts)
    return lo, part.sums, part.sumsq_y, part.count, stats


def _trace_paths(key, scene, settings, unit):
    """Trace one adaptive work unit on a worker; returns (pixel, sample, values (4, 3, N), stats)."""
    from .adaptive import unit_paths
    from .integrator import PathTracer
    renderer = _renderer_for(key, scene)
    pixel, sample = unit_paths(unit)
    tracer = PathTracer(renderer.compiled, renderer.lights, renderer.camera, settings, count_cost=True)
    with one_blas_thread():
        values, stats = tracer.trace(pixel, sample)
    return pixel, sample, values, stats


def _ordered_on_cluster(client, submit, units, add_result, stop_requested, stats) -> bool:
    """Submit ``units`` (``submit(unit)`` → future), pass results to ``add_result`` in unit order.

    While nothing finishes, the stop request is polled (a cluster may stall for long; Ctrl-C /
    SIGTERM must still end the render with its finished units).  Returns True if stopped (a stop
    request, or a failed cluster: then ``stats["error"]`` says why).
    """
    from distributed import as_completed
    futures = [submit(unit) for unit in units]
    index = {f.key: i for i, f in enumerate(futures)}
    results, next_to_add, stopped = {}, 0, False
    pending = as_completed(futures)
    while not pending.is_empty() and not stopped:
        batch = pending.next_batch(block=False)
        if not batch:
            if stop_requested():
                stopped = True
                break
            time.sleep(STOP_POLL_SECONDS)
            continue
        for future in batch:
            try:
                results[index[future.key]] = future.result()
            except Exception as e:      # noqa: BLE001 — lost workers, lost scene data, a failed unit
                stopped = True
                stats["error"] = (f"the Dask cluster failed after {next_to_add} of {len(units)} work units "
                                  f"({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''})")
                break
            future.release()          # the worker may free the unit's result now
        # Add in unit order so that the sums (and so the image) do not depend on timing.
        while next_to_add in results:
            add_result(results.pop(next_to_add))
            next_to_add += 1
        if not stopped and stop_requested():
            stopped = True
    if stopped:
        for f in futures:
            f.cancel()
    return stopped


def _share_enclosing_package(client):
    """If the engine is a subpackage (Blender extension), make that package importable on the workers."""
    engine_pkg = __name__.rsplit(".render.distributed", 1)[0]          # "engine" or "<pkg>.engine"
    if "." not in engine_pkg:
        return
    import cloudpickle
    from . import worker_package
    top = engine_pkg.rsplit(".", 1)[0]
    path = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    cloudpickle.register_pickle_by_value(worker_package)
    client.register_plugin(worker_package.SchedulerPackageLoader(top, path), name=f"polar-package-scheduler-{top}")
    client.register_plugin(worker_package.PackageLoader(top, path), name=f"polar-package-{top}")


def scene_key(scene) -> str:
    return hashlib.sha1(pickle.dumps(scene, protocol=pickle.HIGHEST_PROTOCOL)).hexdigest()


def render_distributed(scene, address, settings=None, progress=None, should_stop=None, window=None,
                       client=None, adaptive=None) -> RenderResult:
    """Render ``scene`` on the Dask scheduler at ``address`` (e.g. "tcp://host:8786").

    Same arguments and result as ``Renderer.render``; ``client`` may be an existing
    ``distributed.Client`` (then ``address`` is ignored).  If the cluster fails mid-render (every
    worker lost, the scene's data lost with them, a unit failing), the units finished so far are
    returned as a cancelled result with ``stats["error"]`` saying what happened.  A bad address
    or a cluster without workers raises RuntimeError, an unreachable scheduler OSError.
    ``adaptive`` (engine.render.adaptive.AdaptiveSettings): sample adaptively; the rounds are decided
    here and their units traced on the workers, added in the same order as a local render, so the
    counts and the image equal the local adaptive render's.
    """
    try:
        from distributed import Client
    except ImportError:
        raise RuntimeError("distributed rendering needs Dask: pip install \"dask[distributed]\"") from None
    own_client = client is None
    # How long to try to reach the scheduler, and for a worker to receive the scene (seconds).
    timeout = float(os.environ.get("POLAR_DASK_TIMEOUT", "20"))
    if client is None:
        try:
            client = Client(address, timeout=timeout)
        except (ValueError, TypeError) as e:
            raise RuntimeError(f"{address!r} is not a Dask scheduler address like tcp://host:8786 ({e})") from None
    try:
        _share_enclosing_package(client)
        local = Renderer(scene)          # validates and resolves the settings exactly as a local render
        st = copy.copy(settings or scene.settings)
        used = local.compiled.used_material_names
        materials, simplified = effective_materials(scene.materials, used, st.simplify)
        st.polarisation, reason = resolve_transport(st.polarisation, materials, used)
        W, H = scene.camera.width, scene.camera.height
        units = list(work_units(W, H, st.spp, st.batch_rays, window=window))
        key = scene_key(scene)
        try:
            scene_future = client.scatter(scene, broadcast=True, timeout=timeout)
        except TimeoutError:
            raise RuntimeError(f"no Dask worker joined the scheduler within {timeout:g} s") from None
        if adaptive is not None:
            return _render_adaptive_on(client, key, scene_future, st, reason, simplified, W, H, window, adaptive,
                                       progress, should_stop)
        film = Film(W, H)
        stats = {"rays": 0, "shadow_rays": 0, "nonfinite": 0, "samples": 0, "transport": st.polarisation,
                 "transport_reason": reason, "spectral": st.spectral, "simplified": simplified,
                 "workers": len(client.scheduler_info()["workers"])}
        t0 = time.perf_counter()
        added = [0]

        def add_unit(result):
            lo, sums, sumsq, count, s = result
            n = count.shape[0]
            if "alpha_sums" in s or film.has_alpha:
                if not film.has_alpha:
                    film.alpha_sums = film.count.astype(np.float64)
                film.alpha_sums[lo:lo + n] += s["alpha_sums"] if "alpha_sums" in s else count
            film.sums[:, :, lo:lo + n] += sums
            film.sumsq_y[:, lo:lo + n] += sumsq
            film.count[lo:lo + n] += count
            if "half_y" in s:
                if film.half_y is None:
                    film.half_y = np.zeros((2, 4, film.count.shape[0]))
                film.half_y[:, :, lo:lo + n] += s["half_y"]
            for k in ("rays", "shadow_rays", "nonfinite"):
                stats[k] += s[k]
            stats["samples"] += int(count.sum())
            stats["seconds"] = time.perf_counter() - t0
            added[0] += 1
            if progress is not None:
                progress(added[0] / len(units), stats)

        cancelled = _ordered_on_cluster(
            client, lambda iu: client.submit(_render_unit, key, scene_future, st, iu[1], window, W, pure=True,
                                             key=f"polar-{key[:12]}-{st.seed}-{iu[0]}-{iu[1]}"),
            list(enumerate(units)), add_unit, should_stop or (lambda: False), stats)
        stats["seconds"] = time.perf_counter() - t0
        return RenderResult(film=film, settings=st, stats=stats, cancelled=cancelled)
    finally:
        if own_client:
            client.close()


def _render_adaptive_on(client, key, scene_future, st, reason, simplified, W, H, window, adaptive, progress,
                        should_stop) -> RenderResult:
    from .adaptive import HalfBuffers, render_adaptive
    film, halves = Film(W, H), HalfBuffers(W * H)
    stats = {"rays": 0, "shadow_rays": 0, "nonfinite": 0, "samples": 0, "transport": st.polarisation,
             "transport_reason": reason, "spectral": st.spectral, "simplified": simplified,
             "workers": len(client.scheduler_info()["workers"])}

    def run_units(units, trace_unit, add_result, stop_requested, abort):
        return _ordered_on_cluster(client, lambda unit: client.submit(_trace_paths, key, scene_future, st, unit,
                                                                      pure=False),
                                   units, add_result, stop_requested, stats)

    stats["stop_reason"] = render_adaptive(None, film, halves, st.spp, st.batch_rays, adaptive, window, run_units,
                                           stats, progress=progress, should_stop=should_stop,
                                           workers=max(1, stats["workers"]))
    if st.stratified:
        film.half_y = halves.sums           # the half-buffers are the even/odd luminance sums
    stats.setdefault("seconds", 0.0)
    return RenderResult(film=film, settings=st, stats=stats, cancelled=stats["stop_reason"] == "cancelled",
                        halves=halves)
