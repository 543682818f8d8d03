"""Rendering on a Dask cluster: ``DaskCluster``, the driver's executor that traces units on Dask workers.

``Renderer.render(RenderRequest(..., scheduler="tcp://host:8786"))`` (or a ``distributed.Client``)
sends the scene to every worker once, submits one task per work unit of each round (uniform passes,
or adaptive rounds: engine.render.driver) and hands the results back in unit order.  Because random
numbers are a stateless function of (seed, pixel, sample, dimension) and the parts are added in the
same order, the image is bit-for-bit the single-machine render of the same settings — however many
workers there are, and also when a worker dies: Dask re-runs its unfinished tasks elsewhere, and a
re-run unit returns exactly the same numbers.  Workers keep the compiled scene (BVH) between tasks.

Needs ``pip install "dask[distributed]"`` on the client and the workers, and the engine importable
on the workers (same version).
"""

from __future__ import annotations

import hashlib
import os
import pickle
import time
from concurrent.futures import CancelledError

from .driver import STOP_POLL_SECONDS

# How often a unit whose task was lost (its worker died, the scene was lost) is submitted again before the render
# gives up with the units finished so far (POLAR_DASK_RETRIES overrides it).
UNIT_RETRIES = 3


def unit_retries() -> int:
    """``POLAR_DASK_RETRIES`` (a whole number ≥ 0), else ``UNIT_RETRIES``; RuntimeError naming it if malformed."""
    text = os.environ.get("POLAR_DASK_RETRIES", "").strip()
    if not text:
        return UNIT_RETRIES
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise RuntimeError(f"POLAR_DASK_RETRIES must be a whole number ≥ 0 (units submitted again after a lost "
                           f"worker or scene), got {text!r}")
    return value


def retryable(failure: BaseException) -> bool:
    """True for a task that was lost rather than failed: Dask cancels the tasks whose data (the scattered scene)
    or worker it lost, and a re-run unit returns the same numbers.  Not for an exception raised by the unit itself
    (it would raise again) nor for KilledWorker (the unit killed Dask's allowed number of workers already: retrying
    it would take down more of a farm)."""
    return isinstance(failure, CancelledError)


def _ordered_on_cluster(client, submit, units, add_result, stop_requested,
                        retries: int | None = None) -> tuple[bool, str | None]:
    """Submit ``units`` (``submit(unit, again)`` → future; ``again``: the unit failed before), pass results to
    ``add_result`` in unit order.  A lost unit (``retryable``) is submitted again up to ``retries`` times (default
    ``unit_retries()``): a re-run unit returns the same numbers, so the image does not change.

    While nothing finishes, the stop request is polled (a cluster may stall for long; Ctrl-C /
    SIGTERM must still end the render with its finished units).  Returns (stopped, error): stopped by
    a stop request, or by a failed cluster (then ``error`` says why).
    """
    from distributed import as_completed
    if retries is None:
        retries = unit_retries()
    futures = [submit(unit, False) for unit in units]
    index = {f.key: i for i, f in enumerate(futures)}
    tries = [0] * len(units)
    results, next_to_add, stopped, error = {}, 0, False, None
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
            i = index[future.key]
            try:
                results[i] = future.result()
            except Exception as failure:        # noqa: BLE001 — lost workers, lost scene data, a failed unit
                again = _resubmit(submit, units, futures, i) \
                    if retryable(failure) and tries[i] < retries and not stop_requested() else failure
                if not isinstance(again, BaseException):
                    tries[i] += 1
                    index[again.key] = i
                    pending.add(again)
                    continue
                stopped = True
                error = (f"the Dask cluster failed after {next_to_add} of {len(units)} work units "
                         f"({type(again).__name__}: {str(again).splitlines()[0] if str(again) else ''})")
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
    return stopped, error


def _resubmit(submit, units, futures, i):
    """Submit unit ``i`` again (its future replaces the failed one): the new future, or the exception
    that submitting raised (the scheduler itself is gone)."""
    try:
        futures[i] = submit(units[i], True)
    except Exception as e:      # noqa: BLE001
        return e
    return futures[i]


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


class DaskCluster:
    """The executor of a render on a Dask cluster (a context manager: closes the client it opened).

    ``scheduler``: an address ("tcp://host:8786") or a ``distributed.Client``; ``scene`` is scattered to
    every worker once; ``task(key, scene, job, unit)`` runs a unit on a worker (engine.render.renderer.
    trace_on_worker).  ``error`` says why the cluster failed mid-render (None: it did not)."""

    local = False

    def __init__(self, scheduler, scene, task):
        try:
            from distributed import Client
        except ImportError:
            raise RuntimeError("distributed rendering needs Dask: pip install \"dask[distributed]\"") from None
        # How long to try to reach the scheduler, and for a worker to receive the scene (seconds).
        text = os.environ.get("POLAR_DASK_TIMEOUT", "").strip() or "20"
        try:
            timeout = float(text)
        except ValueError:
            timeout = float("nan")
        if not timeout > 0 or timeout == float("inf"):
            raise RuntimeError(f"POLAR_DASK_TIMEOUT must be a number of seconds > 0, got {text!r}")
        self.retries = unit_retries()         # checked before the cluster is reached
        self.own_client = isinstance(scheduler, str)
        if self.own_client:
            try:
                scheduler = Client(scheduler, timeout=timeout)
            except (ValueError, TypeError) as e:
                raise RuntimeError(f"{scheduler!r} is not a Dask scheduler address like tcp://host:8786 ({e})") \
                    from None
        self.client, self.task, self.error = scheduler, task, None
        try:
            _share_enclosing_package(self.client)
            self.key = scene_key(scene)
            self._scene_data, self._timeout = scene, timeout
            try:
                self.scene = self.client.scatter(scene, broadcast=True, timeout=timeout)
            except TimeoutError:
                raise RuntimeError(f"no Dask worker joined the scheduler within {timeout:g} s") from None
            self.workers = max(1, len(self.client.scheduler_info()["workers"]))
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        if self.own_client:
            self.client.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def stats(self) -> dict:
        return {"workers": len(self.client.scheduler_info()["workers"])}

    def run(self, units, job, tracer, add_result, stop_requested, abort) -> bool:
        """Trace ``units`` on the workers (``tracer`` is not used: each worker builds its own), add the
        results in unit order; True if stopped (a stop request, or a failed cluster: ``error``)."""
        stopped, error = _ordered_on_cluster(self.client, lambda unit, again: self._submit(job, unit, again),
                                             units, add_result, stop_requested, self.retries)
        self.error = self.error or error
        return stopped

    def _submit(self, job, unit, again: bool):
        """The task of ``unit``; on a retry, the scene is scattered again first if the cluster lost it."""
        if again and self.scene.status != "finished":
            self.scene = self.client.scatter(self._scene_data, broadcast=True, hash=False, timeout=self._timeout)
        return self.client.submit(self.task, self.key, self.scene, job, unit, pure=False)
