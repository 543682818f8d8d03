"""The marker that ``python -m engine precompile`` (engine.render.precompile) writes into the kernel cache folder
once every kernel compiled, and ``precompiled()``, which reads it (the Blender extension's background compile, and
engine.render.processes' choice: workers that would compile the same kernels at once are not started
automatically).  Imports nothing of the renderer.
"""

from __future__ import annotations

import hashlib
import json
import os

from .. import kernels

#: The marker written into the kernel cache folder once every case rendered.
MARKER = "precompiled.json"
#: The engine package's folder.
ENGINE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def sources_stamp(root: str = ENGINE_DIR) -> str:
    """16 hex digits of the engine's source files' names, sizes and modification times.

    Numba trusts a cached kernel while its source file keeps its time stamp and size; the cache
    folder is keyed by the sources' contents (engine.kernels.compiled_sources_digest).  A reinstall
    or a checkout that rewrites the same contents keeps the folder but makes Numba recompile, so the
    marker is keyed by the stamps too."""
    digest = hashlib.sha1()
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith((".", "__")))
        for name in sorted(f for f in files if f.endswith(".py")):
            st = os.stat(os.path.join(folder, name))
            digest.update(f"{os.path.relpath(os.path.join(folder, name), root)}\0{st.st_mtime_ns}\0{st.st_size}\0"
                          .encode())
    return digest.hexdigest()[:16]


def marker_path() -> str:
    return os.path.join(kernels.cache_dir(), MARKER)


def precompiled() -> bool:
    """True when the kernels are not compiled (NumPy: nothing to do) or this cache folder holds every
    kernel, as the last precompile of these very source files left it."""
    if not kernels.uses_cache():
        return True
    try:
        with open(marker_path(), encoding="utf-8") as fh:
            marker = json.load(fh)
    except (OSError, ValueError):
        return False
    return marker.get("stamp") == sources_stamp() and marker.get("backend") == kernels.BACKEND
