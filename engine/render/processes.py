"""Local worker processes: ``LocalProcesses``, the driver's executor that traces units in a pool of Python processes
on this machine, so that a render whose bounces are shaded by many NumPy calls uses every core where two threads
would convoy on the GIL (engine.render.driver.CONVOY_MATERIALS).

The pool (``pool()``) is module-level: started lazily by the first render that asks for it, reused by later
renders and scenes, closed at exit (and by the Blender add-on on unregister: ``close_pool``).  A worker is a plain
``sys.executable -c`` child — never multiprocessing's spawn, which re-imports the caller's ``__main__``
— that imports this engine under the caller's package name without running the enclosing package's ``__init__``
(the Blender extension's imports bpy), with the caller's ``sys.path`` (the extension's wheels).  Messages are
length-prefixed pickles over the child's stdin/stdout (its own prints go to stderr).  Each worker keeps the
compiled scene of the last scene key it was sent (renderer._WORKER_SCENES, as a Dask worker): a render pickles its scene
once and sends it to a worker only when the worker's key differs; the job once per round, then unit indices.

Results are added in unit order by the one driver, and the sampler is stateless, so the image is bit-for-bit the
threaded render's.  A stop request sets a one-byte flag in a file mapping that every worker's tracer polls between
bounces (``SharedFlag``); the finished prefix is kept, as with threads.  A worker that dies has its units traced
again (by another worker, or by this process's threads) and is replaced at the next render; a pool that cannot
start makes the render fall back to threads with one warning (``StartFailed``).
"""

from __future__ import annotations

import atexit
import functools
import hashlib
import mmap
import os
import pickle
import queue
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque

from . import bootstrap
from .driver import STOP_POLL_SECONDS, UNITS_AHEAD, trace_in_order

#: Seconds a worker may take to start (import the engine) before the pool gives up (POLAR_WORKER_START_TIMEOUT).
START_TIMEOUT = 120.0
#: Seconds the workers may take to end their units once a stop is requested, before they are killed.
ABORT_TIMEOUT = 30.0
#: Paths (pixels × samples) from which a render amortises starting the pool: its start and the workers' first
#: units cost ≈ 1.7 s more than a first render on threads (this 2-core VM, warm kernel cache), about 3 s of
#: convoying threads here (docs/benchmarks/performance.md "Worker processes"); a running pool is always used.
AMORTISED_PATHS = 1 << 21
#: Memory of a worker (check_memory): ``WORKER_BYTES`` (the interpreter with the engine imported, 115 MB, and its
#: loaded kernels) + ``SCENE_COPY_FACTOR`` × the pickled scene (BVH, lights, tracers), besides its batches; measured
#: on the real assets (a worker's RSS grew by 70 MB + 2.8 × the pickle after its first render: AttenuationTest 2.7 MB
#: → 77 MB, BoomBox 6.6 → 84, SpecGlossEmission 16.1 → 115, of which ≈ 35 MB its batch).
WORKER_BYTES = 160 << 20
SCENE_COPY_FACTOR = 3

_HEADER = struct.Struct("<Q")

# The child's own part (engine.render.bootstrap makes ``engine`` importable first).
_BEFORE = r"""
import signal
signal.signal(signal.SIGINT, signal.SIG_IGN)          # Ctrl-C is the parent's: it stops the render
inp, out = os.fdopen(os.dup(0), "rb"), os.fdopen(os.dup(1), "wb")
os.dup2(2, 1)                                         # prints go to stderr, never into the messages
"""
_BODY = """
importlib.import_module(engine + ".render.worker_process").serve(inp, out)
"""


def send(stream, message) -> None:
    """Write ``message`` (any picklable object) as one length-prefixed pickle."""
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)))
    stream.write(data)
    stream.flush()


def receive(stream):
    """The next message of ``stream``; EOFError at its end."""
    head = stream.read(_HEADER.size)
    if len(head) < _HEADER.size:
        raise EOFError
    size = _HEADER.unpack(head)[0]
    data = stream.read(size)
    if len(data) < size:
        raise EOFError
    return pickle.loads(data)


def _function(module: str, code: bytes, name: str, defaults, kwdefaults, cells):
    """A function rebuilt from ``dumps_scene``'s parts, its globals those of ``module`` (imported here)."""
    import importlib
    import marshal
    import types
    closure = None if cells is None else tuple(types.CellType() if c is _EMPTY else types.CellType(c) for c in cells)
    f = types.FunctionType(marshal.loads(code), importlib.import_module(module).__dict__, name, defaults, closure)
    f.__kwdefaults__ = kwdefaults
    return f


class _Empty:
    def __reduce__(self):
        return "_EMPTY"


_EMPTY = _Empty()      # an empty closure cell


class _ScenePickler(pickle.Pickler):
    """Pickles functions that plain pickle cannot (lambdas and local functions the materials hold: Principled's
    layer albedos) by their code, defaults and closure; their globals are their module's, imported by the worker
    under the same name (the same engine, the same interpreter: marshal's code format)."""

    def reducer_override(self, obj):
        import marshal
        import types
        if isinstance(obj, types.FunctionType) and "<" in obj.__qualname__:
            cells = None
            if obj.__closure__ is not None:
                cells = []
                for c in obj.__closure__:
                    try:
                        cells.append(c.cell_contents)
                    except ValueError:
                        cells.append(_EMPTY)
                cells = tuple(cells)
            return _function, (obj.__module__, marshal.dumps(obj.__code__), obj.__name__, obj.__defaults__,
                               obj.__kwdefaults__, cells)
        return NotImplemented


def dumps_scene(scene) -> bytes:
    """``scene`` pickled for the workers (``_ScenePickler``); StartFailed if it cannot be (a local class, …)."""
    import io
    buffer = io.BytesIO()
    try:
        _ScenePickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(scene)
    except (pickle.PicklingError, TypeError, AttributeError, RecursionError) as e:
        raise StartFailed(f"the scene cannot be sent to them: {type(e).__name__}: {e}") from None
    return buffer.getvalue()


class SharedFlag:
    """A one-byte flag in a file mapping shared by the parent and its workers; ``is_set`` as threading.Event's
    (the tracers poll it between bounces).  ``path`` None: a new file (``close`` removes it)."""

    def __init__(self, path: str | None = None):
        self.owner = path is None
        if path is None:
            fd, path = tempfile.mkstemp(prefix="polar-stop-")
            os.write(fd, b"\0")
            os.close(fd)
        self.path = path
        with open(path, "r+b") as f:
            self._map = mmap.mmap(f.fileno(), 1)

    def set(self) -> None:
        self._map[0] = 1

    def clear(self) -> None:
        self._map[0] = 0

    def is_set(self) -> bool:
        return self._map[0] != 0

    def close(self) -> None:
        self._map.close()
        if self.owner:
            try:
                os.unlink(self.path)
            except OSError:
                pass


class StartFailed(RuntimeError):
    """The worker processes could not start (the message says why); the render falls back to threads."""


class _Worker:
    """One child process, the reader thread that queues its messages, and what the parent sent it."""

    def __init__(self, command: list, replies: queue.Queue):
        self.log = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.log,
                                     env=dict(os.environ))
        self.key, self.job, self.outstanding, self.alive = None, None, deque(), True
        self.reader = threading.Thread(target=self._read, args=(replies,), daemon=True, name="polar-worker-reader")
        self.reader.start()

    def _read(self, replies: queue.Queue) -> None:
        try:
            while True:
                replies.put((self, receive(self.proc.stdout)))
        except (EOFError, OSError, pickle.UnpicklingError, ValueError):
            replies.put((self, ("eof",)))

    def send(self, message) -> bool:
        """False if the worker is gone (its reader reports it)."""
        try:
            send(self.proc.stdin, message)
            return True
        except (BrokenPipeError, OSError, ValueError):
            return False

    def last_error(self) -> str:
        """The last line the child wrote to stderr (why it died), or its exit code."""
        try:
            self.log.seek(0)
            lines = [ln for ln in self.log.read().decode("utf-8", "replace").splitlines() if ln.strip()]
        except (OSError, ValueError):
            lines = []
        code = self.proc.poll()
        return lines[-1].strip() if lines else f"exit code {code}"

    def reap(self, wait: float = 5.0) -> None:
        """Wait for a worker whose messages ended (killed if it does not exit)."""
        try:
            self.proc.wait(wait)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()

    def stop(self, wait: float = 2.0) -> None:
        self.alive = False
        if self.proc.poll() is None:
            self.send(("exit",))
            try:
                self.proc.stdin.close()
            except OSError:
                pass
            try:
                self.proc.wait(wait)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.log.close()


def child_command() -> list:
    """The command of a worker: this interpreter importing this engine as this process does (engine.render.
    bootstrap), then engine.render.worker_process.serve."""
    return bootstrap.child_command(_BODY, _BEFORE)


class WorkerPool:
    """The persistent worker processes of this process (``pool()``); one render uses them at a time (``lock``)."""

    def __init__(self):
        self.workers: list[_Worker] = []
        self.replies: queue.Queue = queue.Queue()
        self.flag = SharedFlag()
        self.lock = threading.Lock()
        self.rounds = 0              # rounds run (LocalProcesses.run), the id of a round's job
        self.command = None          # (tests: a child that cannot start)
        self.starting = False        # start_in_background's thread is starting workers
        self.unavailable = None      # why a background start failed (auto does not try again)

    @property
    def running(self) -> int:
        return sum(w.alive for w in self.workers)

    def ensure(self, n: int, timeout: float | None = None) -> float:
        """Start workers until ``n`` are alive; returns the seconds it took (0: none started).  StartFailed (with
        the child's last error line) if one does not start within ``timeout`` (default START_TIMEOUT)."""
        for w in self.workers:
            if not w.alive:
                w.stop(0.1)         # (reaped; its log closed)
        self.workers = [w for w in self.workers if w.alive]
        missing = n - len(self.workers)
        if missing <= 0:
            return 0.0
        if not sys.executable:
            raise StartFailed("no Python executable (sys.executable is empty)")
        if timeout is None:
            timeout = float(os.environ.get("POLAR_WORKER_START_TIMEOUT", START_TIMEOUT))
        t0 = time.perf_counter()
        command = self.command or child_command()
        new = []
        try:
            for _ in range(missing):
                new.append(_Worker(command, self.replies))
        except OSError as e:
            for w in new:
                w.stop(0.1)
            raise StartFailed(f"cannot start {command[0]!r}: {e}") from None
        waiting = set(new)
        failure = None
        while waiting and failure is None:
            try:
                worker, message = self.replies.get(timeout=max(0.0, t0 + timeout - time.perf_counter()))
            except queue.Empty:
                failure = f"no worker answered within {timeout:g} s"
                break
            if worker not in waiting:
                continue
            if message[0] == "ready":
                waiting.discard(worker)
                worker.send(("flag", self.flag.path))
            else:
                worker.reap()
                failure = message[1] if message[0] == "broken" else worker.last_error()
        if failure is not None:
            for w in new:
                w.stop(0.1)
            raise StartFailed(failure)
        self.workers += new
        return time.perf_counter() - t0

    def close(self) -> None:
        for w in self.workers:
            w.stop()
        self.workers = []


_POOL: WorkerPool | None = None
_POOL_LOCK = threading.Lock()
#: Whether "auto" may start the pool in the background after a render too small to wait for it: only a host that
#: renders again in this process (Blender: F12 after F12, an animation's frames) says so (``keep_pool_warm``); a
#: command-line render is one render, whose process would start two workers only to end them.
_WARM = False


def keep_pool_warm(on: bool = True) -> None:
    """Let "auto" start the pool in the background after small renders (``choose_parallel``): for hosts that render
    again in this process (the Blender add-on on register; tests/bench/asset_speed.py's warm renders)."""
    global _WARM
    _WARM = bool(on)


def pool() -> WorkerPool:
    """This process's worker pool (created, not started, on first use)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            _POOL = WorkerPool()
        return _POOL


def pool_running() -> int:
    """Worker processes alive now (0: the pool was not started)."""
    return 0 if _POOL is None else _POOL.running


def close_pool() -> None:
    """End the worker processes (at exit; the Blender add-on on unregister); a later render starts new ones."""
    global _POOL
    with _POOL_LOCK:
        p, _POOL = _POOL, None
    if p is not None:
        p.close()
        p.flag.close()


atexit.register(close_pool)


def kernels_ready() -> bool:
    """True when the workers will load every compiled kernel from the cache (engine.render.precompile ran for these
    sources, or Numba is not in use: kernel_marker.precompiled): with a cold cache each worker would compile the
    same kernels at once (fresnel_sphere's first render: 27.6 s on 2 processes against 13.7 s on threads)."""
    from .kernel_marker import precompiled
    return precompiled()


def choose_parallel(mode: str, workers: int, shaded: bool, paths: int) -> tuple[str, str, bool]:
    """("threads" | "processes", why, start the pool in the background) for a local render: ``mode``
    RenderSettings.parallel; ``workers`` the worker count (one per core, or ``threads``); ``shaded``: the scene has
    materials shaded by Python calls per bounce (driver.python_shaded), on which two threads hand the GIL to each
    other (the real assets: 2 processes took 0.74–0.92× the wall time of threads on 12 of 14 cases; the peer scenes,
    delta and Lambert only, 1.11× on fresnel_sphere: threads); ``paths``: pixels × samples to trace.  "auto" takes
    processes there when the pool runs already, or the render traces ``AMORTISED_PATHS`` or more and the kernel
    cache is filled (``kernels_ready``); a smaller render runs on threads and, where the host renders again in this
    process (``keep_pool_warm``), starts the pool in the background (the third value), so that the renders after
    it (an animation's frames, re-renders) find it running."""
    if mode != "auto":
        return mode, "set by render.parallel", False
    if workers < 2 or not shaded:
        return "threads", "", False
    why = "automatic: the scene's materials are shaded by Python calls that threads would contend for"
    if pool_running() >= workers:
        return "processes", why, False
    if not kernels_ready():
        return "threads", "", False
    if paths >= AMORTISED_PATHS:
        return "processes", why + "; starting the workers pays at this size", False
    return "threads", "", _WARM


def start_in_background(workers: int) -> bool:
    """Start the pool's ``workers`` processes on a daemon thread, holding the pool (a render that asks for it
    meanwhile waits: LocalProcesses); False if they run or are starting already.  A pool that cannot start is not
    tried again in this process (``pool().unavailable`` says why)."""
    p = pool()
    with _POOL_LOCK:
        if p.starting or p.unavailable or p.running >= workers:
            return False
        p.starting = True

    def start():
        try:
            with p.lock:
                p.ensure(workers)
                with _POOL_LOCK:
                    orphaned = _POOL is not p        # close_pool ran meanwhile (the extension was disabled)
                if orphaned:
                    p.close()
        except StartFailed as e:
            p.unavailable = str(e)
        finally:
            p.starting = False
    threading.Thread(target=start, daemon=True, name="polar-pool-start").start()
    return True


class LocalProcesses:
    """The executor of a local render on ``workers`` worker processes of the pool (holds the pool for this render
    until ``close``).  ``blob``: the scene, pickled once by the caller; ``stats()`` says how many and why,
    and the pool's start-up seconds when this render started it; ``warning``: a worker died (its units were
    traced again)."""

    local = True
    error = None
    #: the render's own tracer is only needed where every worker died: the renderer passes a functools.partial
    #: that builds it (≈ 1 ms of SpecGlossEmission's render before its units went out)
    traces_elsewhere = True

    def __init__(self, blob: bytes, workers: int, reason: str, progress=None, key: str | None = None):
        self.workers, self.reason, self.warning = max(1, int(workers)), reason, None
        self.blob = blob
        # as distributed.scene_key, from the one pickle (``key``: the caller's, of the same blob)
        self.key = key or hashlib.sha1(self.blob).hexdigest()
        self.pool = pool()
        waits = self.pool.starting          # the background start holds the pool until its workers answer
        if not self.pool.lock.acquire(timeout=START_TIMEOUT if waits else 0):
            raise StartFailed("the worker processes are busy with another render")
        try:
            if self.pool.running < self.workers and progress is not None:
                progress(0.0, {"samples": 0, "seconds": 0.0, "transport": "", "message":
                               "starting worker processes (first render only)"})
            self.start_seconds = self.pool.ensure(self.workers)
        except BaseException:
            self.pool.lock.release()
            raise
        self._run = None

    def close(self) -> None:
        """Hand the pool back (the workers keep running for the next render)."""
        if self.pool is not None:
            self.pool.lock.release()
            self.pool = None

    def stats(self) -> dict:
        s = {"parallel": "processes", "parallel_reason": self.reason, "threads": self.workers}
        if self.start_seconds:
            s["pool_start_seconds"] = self.start_seconds
        return s

    def run(self, units, job, tracer, add_result, stop_requested, abort) -> bool:
        """Trace ``units`` with ``job`` on the workers, add results in unit order; True if stopped.  ``tracer``
        (this process's) traces the units left when every worker died."""
        p = self.pool
        p.flag.clear()
        p.rounds += 1           # (a pool-wide count: a worker holds the job of the last round it was sent)
        self._run = p.rounds
        job_message = ("job", self._run, pickle.dumps(job, protocol=pickle.HIGHEST_PROTOCOL))
        workers = [w for w in p.workers if w.alive][:self.workers]
        todo, results, next_add = deque(range(len(units))), {}, 0
        cancelled, gap = False, False

        def feed(w: _Worker, ahead: int = UNITS_AHEAD) -> None:
            while w.alive and todo and not cancelled and len(w.outstanding) < ahead:
                if w.key != self.key:
                    w.key = self.key if w.send(("scene", self.key, self.blob)) else None
                if w.job != self._run:
                    w.job = self._run if w.send(job_message) else None
                i = todo.popleft()
                w.outstanding.append(i)
                if not w.send(("unit", i, units[i])):
                    break               # gone: its reader reports it, and its units go back to ``todo``

        def stop():
            nonlocal cancelled
            cancelled = True
            abort.set()
            p.flag.set()

        def lost(w: _Worker) -> None:
            w.alive = False
            todo.extendleft(sorted(w.outstanding, reverse=True))
            w.outstanding.clear()
            self.warning = (f"a worker process died ({w.last_error()}); its units were traced again, "
                            "the image is unchanged")
            workers.remove(w)

        try:
            for ahead in range(1, UNITS_AHEAD + 1):     # round robin: a round's first units go one to each worker
                for w in workers:
                    feed(w, ahead)
            while next_add < len(units) and not (cancelled and not any(w.outstanding for w in workers)):
                if not workers and not cancelled:
                    cancelled = self._trace_here(units, todo, results, job, tracer, stop_requested, abort)
                    todo.clear()
                else:
                    try:
                        w, message = p.replies.get(timeout=STOP_POLL_SECONDS if not cancelled else ABORT_TIMEOUT)
                    except queue.Empty:
                        if cancelled:           # a worker that does not end its units: killed
                            for w in list(workers):
                                if w.outstanding:
                                    w.proc.kill()
                                    w.stop(1.0)
                                    w.outstanding.clear()
                                    workers.remove(w)
                        elif stop_requested():
                            stop()
                        continue
                    if w not in workers:
                        continue
                    if message[0] == "eof":
                        w.reap()
                        lost(w)
                    elif message[0] == "failed":
                        w.outstanding.remove(message[1])
                        stop()
                        raise RuntimeError(f"a worker process failed a unit: {message[2]}")
                    elif message[0] == "done":
                        w.outstanding.remove(message[1])
                        results[message[1]] = message[2]
                    for x in workers:
                        feed(x)
                while next_add in results:
                    result = results.pop(next_add)
                    if result is None:
                        gap = True          # ended by the stop: nothing after it may be added
                    if not gap:
                        add_result(result)
                    next_add += 1
                if gap and not cancelled:
                    stop()
                if not cancelled and stop_requested():
                    stop()
        except BaseException:
            stop()
            self._drain(workers)
            raise
        return cancelled

    def _trace_here(self, units, todo, results, job, tracer, stop_requested, abort) -> bool:
        """Every worker died: trace the units of ``todo`` on this process's threads into ``results`` (``tracer``: a
        PathTracer, or a functools.partial that builds it)."""
        if isinstance(tracer, functools.partial):
            tracer = tracer()
        order = sorted(todo)
        out = {}
        done = trace_in_order(order, lambda i: (lambda r: None if r is None else (i, r))(job(tracer, units[i], abort)),
                              lambda ir: out.__setitem__(*ir), os.cpu_count() or 1, stop_requested, abort)
        results.update(out)
        for i in order:
            if i not in out:
                results[i] = None       # not traced (stopped): ends the prefix
                break
        return done

    def _drain(self, workers) -> None:
        """After a failure: wait (ABORT_TIMEOUT) for the units in flight to end, killing workers that do not."""
        deadline = time.perf_counter() + ABORT_TIMEOUT
        while any(w.outstanding for w in workers) and time.perf_counter() < deadline:
            try:
                w, message = self.pool.replies.get(timeout=0.1)
            except queue.Empty:
                continue
            if w in workers and message[0] in ("done", "failed"):
                w.outstanding.remove(message[1])
            elif w in workers and message[0] == "eof":
                w.alive = False
                w.outstanding.clear()
        for w in workers:
            if w.outstanding:
                w.proc.kill()
                w.stop(1.0)
                w.outstanding.clear()
