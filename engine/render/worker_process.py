"""A local worker process's loop (engine.render.processes): started by the pool's bootstrap, it answers the
parent's messages until its stdin ends.  Kept apart from the pool so that the pool (which the renderer imports)
does not import the renderer.
"""

from __future__ import annotations

import os
import pickle
import traceback

from .processes import SharedFlag, receive, send


def serve(inp, out) -> None:
    """A worker's loop: ``("scene", key, blob)``, ``("job", id, blob)``, ``("unit", index, unit)`` (answered by
    ``("done", index, result or None if stopped)`` or ``("failed", index, text)``), ``("exit",)``; ends at EOF."""
    try:
        from .blas_threads import one_blas_thread
        from .renderer import _WORKER_SCENES
    except BaseException as e:               # noqa: BLE001 — said to the parent, which falls back to threads
        send(out, ("broken", f"{type(e).__name__}: {e}"))
        raise
    send(out, ("ready", os.getpid()))
    flag, key, scene, job = None, None, None, None
    while True:
        try:
            message = receive(inp)
        except EOFError:
            return
        kind = message[0]
        if kind == "exit":
            return
        if kind == "flag":
            flag = SharedFlag(message[1])
        elif kind == "scene":
            key, scene = message[1], pickle.loads(message[2])
        elif kind == "job":
            job = pickle.loads(message[2])
        elif kind == "unit":
            try:
                tracer = _WORKER_SCENES.tracer(key, scene, job.settings, job.count_cost)
                with one_blas_thread():     # the processes are the parallelism (engine.render.blas_threads)
                    result = job(tracer, message[2], flag)
                send(out, ("done", message[1], result))
            except Exception as e:          # noqa: BLE001 — the parent raises it
                send(out, ("failed", message[1], f"{type(e).__name__}: {e}\n{traceback.format_exc()}"))
