"""The one render driver: a schedule's rounds of work units, traced by an executor, added to the film.

A **schedule** says which work units to trace, round after round: ``UniformPasses`` (every pixel to
``spp``: one round of bands of rows × ranges of sample passes) or adaptive sampling's rounds
(engine.render.adaptive.AdaptiveRounds).  Its ``job`` turns a unit into a film part on a worker
(``job(tracer, unit, abort)`` → (part, stats, …); a picklable object, so that Dask workers run the same
code).  An **executor** traces a round's units concurrently and hands the results back in unit order:
``LocalThreads`` (``trace_in_order``) or a Dask cluster (engine.render.distributed.DaskCluster).  The
driver adds every part with ``Film.add`` — the film's sums are written by the film alone — counts the
stats, reports progress and asks the caller whether to stop.  Units are added strictly in order and
the sampler is stateless, so the image does not depend on the executor or the number of workers.
"""

from __future__ import annotations

import contextlib
import threading
from collections import deque
from concurrent.futures import CancelledError, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FuturesTimeout

import numpy as np

from .blas_threads import one_blas_thread
from .film import SampleSums
from .halves import part_classes
from .plan import RenderPlan, RenderRequest, unit_pixels

#: How often (seconds) the caller's stop request is polled while units are in flight.
STOP_POLL_SECONDS = 0.05
#: Units submitted per worker thread (one traced, the next queued so that the worker never waits
#: for the thread that adds finished units to the film).
UNITS_AHEAD = 2
#: Counters of the tracer's stats that a render sums over its units.
RAY_COUNTERS = ("rays", "shadow_rays", "nonfinite")
#: With this many materials or more shaded by Python calls (every material but a LambertSet's and the smooth ones:
#: AttenuationTest's 18 glasses, 2 rough materials, render in 0.74× the wall time on two threads), one worker thread
#: traces as fast as two or faster: each bounce runs each material's NumPy calls on its share of the paths, and two
#: threads hand the GIL to each other at every call (docs/benchmarks.md "Real assets against Cycles").
CONVOY_MATERIALS = 3


def local_workers(cores: int, materials) -> int:
    """Worker threads for a render whose threads are not set (``cores``: one per CPU core): one where the scene's
    used ``materials`` (BSDFs) are shaded by ``CONVOY_MATERIALS`` or more separate Python calls per bounce (two
    threads then convoy on the GIL), else ``cores``.  Lambert materials (one LambertSet) and smooth (delta-only)
    materials do not count: a smooth vertex is a few calls around compiled steps, no light sampling.  The image does
    not depend on it (engine.render.plan)."""
    return 1 if convoys(materials) else cores


def python_shaded(materials) -> int:
    """How many of the scene's used ``materials`` are shaded by separate Python (NumPy) calls per bounce: all but a
    LambertSet's and the smooth (delta-only) ones, whose vertices are a few calls around compiled steps."""
    from ..materials.lambert import LambertSet
    return sum(not (LambertSet.batchable(m) or m.flags.is_delta_only) for m in materials)


def convoys(materials) -> bool:
    """True where ``CONVOY_MATERIALS`` or more of the scene's used ``materials`` are shaded by Python calls
    (``python_shaded``, ``local_workers``): two threads then convoy on the GIL, worker processes do not
    (engine.render.processes)."""
    return python_shaded(materials) >= CONVOY_MATERIALS


class StopCheck:
    """``stop()`` is True when the caller asks to stop (``reason`` "cancelled") or the time limit has
    passed (``reason`` "time_limit"; ``time_limit`` 0: none); polled from the caller's thread only."""

    def __init__(self, should_stop, time_limit: float, clock, t0: float):
        self.should_stop, self.time_limit, self.clock, self.t0 = should_stop, time_limit, clock, t0
        self.reason = None

    def __call__(self) -> bool:
        if self.should_stop is not None and self.should_stop():
            self.reason = "cancelled"
            return True
        if self.time_limit > 0 and self.clock() - self.t0 >= self.time_limit:
            self.reason = "time_limit"
            return True
        return False


class Tally:
    """Samples added so far and seconds since the render started (by the request's clock)."""

    def __init__(self, clock, t0: float):
        self.clock, self.t0, self.samples = clock, t0, 0

    def seconds(self) -> float:
        return self.clock() - self.t0


def trace_in_order(units, trace_unit, add_result, workers: int, stop_requested, abort: threading.Event) -> bool:
    """Trace ``units`` on ``workers`` threads and pass each result to ``add_result`` in unit order.

    Units are traced concurrently (Embree and the compiled kernels release the GIL) but added
    strictly in unit order, so the image does not depend on the number of threads.  Up to
    ``UNITS_AHEAD`` units per worker are submitted at once, and the next ones before a finished
    unit is added.  The stop request is polled from this (the caller's) thread only — Blender's
    test_break must not be called from workers — and sets ``abort``, which ends units in flight between
    two bounces (``trace_unit`` then returns None and the unit is discarded whole); units not started
    yet are not traced.  Only a prefix of ``units`` is ever added (a film, and so a resume, counts each
    pixel's samples as passes 0 … k−1).  Returns True if stopped.
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


class LocalThreads:
    """The executor of a local render: ``workers`` threads of this process (``trace_in_order``)."""

    local = True
    error = None
    warning = None          # why worker processes were asked for but not used (engine.render.processes)

    def __init__(self, workers: int):
        self.workers = max(1, int(workers))

    def stats(self) -> dict:
        return {}

    def run(self, units, job, tracer, add_result, stop_requested, abort) -> bool:
        """Trace ``units`` with ``job(tracer, unit, abort)``, add results in unit order; True if stopped."""
        return trace_in_order(units, lambda unit: job(tracer, unit, abort), add_result, self.workers,
                              stop_requested, abort)


class BandJob:
    """Traces a uniform render's unit (row0, row1, pass0, pass1) → (SampleSums, stats), or None if aborted.

    Passes a pixel already has (``done`` (n,): a resumed film's counts) are skipped; with ``stratified``
    (RenderSettings.split_halves) the part also holds the luminance sums of the sample classes A and B
    (engine.render.halves: even/odd with independent halves)."""

    count_cost = False

    def __init__(self, settings, width: int, window, stratified: bool, done: np.ndarray | None = None):
        self.settings, self.width, self.window, self.stratified, self.done = settings, width, window, stratified, done

    def __call__(self, tracer, unit, abort=None):
        r0, r1, p0, p1 = unit
        pix = unit_pixels(self.width, r0, r1, self.window)
        pixel = np.tile(pix, p1 - p0)
        sample = np.repeat(np.arange(p0, p1, dtype=np.int64), pix.size)
        if self.done is not None:
            todo = sample >= self.done[pixel]
            pixel, sample = pixel[todo], sample[todo]
        traced = tracer.trace(pixel, sample, abort=abort)
        if traced is None:
            return None
        values, s = traced
        # the unit's film sums, here on the worker: the adding thread only adds them in order
        return SampleSums.of(pixel, values, s.pop("alpha", None), s.pop("denoise", None),
                             part_classes(pixel, sample, self.settings.halves, p1) if self.stratified else None), s


class UniformPasses:
    """The schedule of a uniform render: every window pixel to ``settings.spp`` samples, in one round.

    ``resume``: a Film of finished samples; passes its pixels have are not traced again (its film
    without half sums keeps the i.i.d. error: no half sums are added then)."""

    time_limit = 0.0
    halves = None

    def __init__(self, plan: RenderPlan, resume=None):
        st = plan.settings
        done = None if resume is None else resume.count.copy()
        self.units = plan.units(int(done.min()) if done is not None else 0)
        if done is None:
            cols = (plan.window[2] - plan.window[0]) if plan.window else plan.width
            total = sum((r1 - r0) * cols * (p1 - p0) for r0, r1, p0, p1 in self.units)
        else:
            x0, y0, x1, y1 = plan.window or (0, 0, plan.width, plan.height)
            total = int(np.maximum(st.spp - done.reshape(plan.height, plan.width)[y0:y1, x0:x1], 0).sum())
        self.total = max(total, 1)
        stratified = st.split_halves and (resume is None or resume.half_y is not None)
        self.job = BandJob(st, plan.width, plan.window, stratified, done)
        self._given = False

    def errstate(self):
        return contextlib.nullcontext()

    def next_round(self, film, stop, tally):
        """The units of the next round, or None when the render is done."""
        if self._given:
            return None
        self._given = True
        return self.units

    def added(self, result) -> None:
        pass

    def fraction(self, samples: int, seconds: float) -> float:
        return samples / self.total

    def finish(self, film, stats, stopped: str | None) -> bool:
        """Complete the stats; True if the render was cancelled."""
        return stopped is not None


def drive(schedule, film, tracer, executor, stats: dict, request: RenderRequest) -> bool:
    """Render ``schedule`` into ``film`` with ``executor`` (``tracer``: the local executor's); only ever
    adds to the film through ``Film.add``.  ``stats`` receives the ray counters, ``samples`` and
    ``seconds``; returns True if the render was cancelled."""
    clock = request.clock
    t0 = clock()
    stop = StopCheck(request.should_stop, schedule.time_limit, clock, t0)
    tally = Tally(clock, t0)
    abort = threading.Event()

    def add_result(result):
        part, s = result[0], result[1]
        film.add(part)
        schedule.added(result)
        for k in RAY_COUNTERS:
            stats[k] += s[k]
        tally.samples += part.n_samples
        stats["samples"] = tally.samples
        stats["seconds"] = clock() - t0
        if request.progress is not None:
            request.progress(schedule.fraction(tally.samples, stats["seconds"]), stats)

    stopped = None
    with schedule.errstate():
        while True:
            units = schedule.next_round(film, stop, tally)
            if units is None:
                break
            halted = executor.run(units, schedule.job, tracer, add_result, stop, abort)
            stats["seconds"] = clock() - t0
            if halted:
                stopped = stop.reason or "cancelled"
                break
    return schedule.finish(film, stats, stopped)
