"""Precomputed material tables kept on disk, so a new process does not build them again.

A rough Weidlich–Wilkie coat needs its top interface's albedo E_top(θ, η) (a 2-D quadrature per
θ node and η node): 1.3 s for one index, 3.8 s over a dispersive coat's η range, 6.6–7 s for a
coat whose roughness is textured, on every CLI render, Blender session or batch frame process.
The table is a pure function of its parameters and of the engine's source, so it is stored as
``<kernel cache base>/tables/<digest of every engine module>/<name>-<hash of the key>.npy``
(engine.kernels.cache_base: ``POLAR_KERNEL_CACHE``, inside Blender the extension's user folder)
and read back bit for bit.  Any edit of the engine (or an upgrade) starts a fresh folder.

A file that cannot be read as the expected array is built again and replaced; a folder that cannot
be written only costs the build (the render goes on).  Files are written to a temporary name and
renamed into place, so a reader never sees half a table and two processes may race harmlessly.  Within a
process one thread reads or builds at a time (``_LOCK``): ``np.load`` parses the file's header with
``ast.literal_eval``, which CPython 3.11 does not allow on two threads at once (a two-thread render's first
use of a table raised "SystemError: AST constructor recursion depth mismatch").
``POLAR_TABLE_CACHE=0`` turns the cache off.
"""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile
import threading
from collections.abc import Callable

import numpy as np

from ..kernels import cache_base, compiled_sources_digest

#: one reader or builder of a table at a time in this process (the module docstring); re-entrant, as a build
#: may read another table
_LOCK = threading.RLock()


@functools.lru_cache(maxsize=1)
def _sources_digest() -> str:
    return compiled_sources_digest(every_module=True)


def enabled() -> bool:
    return os.environ.get("POLAR_TABLE_CACHE", "1").lower() not in ("0", "off", "false", "no")


def table_dir() -> str:
    """The folder of this engine source's cached tables."""
    return os.path.join(cache_base(), "tables", _sources_digest())


def _key_text(key: tuple) -> str:
    """The key canonically: floats exactly (hex), everything else by repr."""
    return repr(tuple(float(v).hex() if isinstance(v, float) else v for v in key))


def table_path(name: str, key: tuple) -> str:
    digest = hashlib.sha256(_key_text(key).encode()).hexdigest()[:24]
    return os.path.join(table_dir(), f"{name}-{digest}.npy")


def cached_table(name: str, key: tuple, shape: tuple[int, ...], build: Callable[[], np.ndarray]) -> np.ndarray:
    """The float64 array ``build()`` of the given shape, read from the disk cache when a process
    has built it before for the same ``name``, ``key`` (numbers and strings) and engine source."""
    with _LOCK:
        return _cached_table(name, key, shape, build)


def _cached_table(name, key, shape, build) -> np.ndarray:
    if not enabled():
        return build()
    path = table_path(name, key)
    try:
        table = np.load(path, allow_pickle=False)
        if table.dtype == np.float64 and table.shape == tuple(shape):
            return table
    except (OSError, ValueError, EOFError):
        pass            # missing, unreadable or truncated: built again below
    table = np.ascontiguousarray(build(), dtype=np.float64)
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=os.path.dirname(path), suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as fh:
                np.save(fh, table, allow_pickle=False)
            os.replace(tmp, path)
        except BaseException:
            os.unlink(tmp)
            raise
    except OSError:
        pass            # a read-only or full disk: the table was built, the render goes on
    return table
