"""glibc malloc settings for a render: freed batch arrays are kept for the next batch.

A batch allocates and frees the same few hundred MB of NumPy arrays at every bounce.  With glibc's
default settings most of them come from fresh ``mmap``s (above its 128 KiB – 32 MiB adaptive
threshold, or larger than a worker thread's 64 MiB heap) or from heap space that ``free`` has just
handed back (heap top trimming, whole per-thread heaps deleted when empty), so every bounce
page-faults its arrays in again: measured 70–140 thousand faults and 0.2–0.45 s of kernel time per
1-thread render of 128² × 64 spp (15–25 % of its CPU time), more with two threads, whose faults
and ``munmap``s serialise on the process's memory map.  Within a render the memory is wanted
again at once, and by the next render of the same renderer (viewport, benchmarks); the renderer
hands it back (``malloc_trim``) when it is dropped.

The settings (glibc ``mallopt``; process-wide, they stay set, no-ops without glibc):

- one malloc arena (``M_ARENA_MAX``): worker threads share the main heap, which has no 64 MiB
  limit per chunk (it takes effect for threads that have no arena yet, as in a fresh process);
- arrays up to 1 GiB from the heap (``M_MMAP_THRESHOLD``), no automatic trimming of the heap top
  (``M_TRIM_THRESHOLD``), and a 64 MiB pad that per-thread heaps keep (``M_TOP_PAD``: with
  arenas that already exist, e.g. in Blender, their heaps are then not deleted when they empty).

In a process whose malloc is not glibc's (macOS, Windows, musl, a jemalloc build) nothing changes.
Inside Blender (``bpy`` loaded) the settings are not kept: they are process-wide and would also hold
Blender's own memory (images, undo steps) on its heap.  There :func:`render_heap` applies them for the
duration of each render only, then sets glibc's limits back to values its own dynamic rule reaches
in a long-running process (mmap threshold 32 MiB, trim threshold 64 MiB, top pad 128 KiB, 8 arenas
per core) and hands the freed memory back (``malloc_trim``).  Measured on a 960×540, 8-spp F12 render
of tests/bench/blender_overhead.py's scene: 434 → 78 thousand page faults, 4.84 → 3.84 s.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import os
import sys
import threading
from contextlib import contextmanager

# glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3
_M_ARENA_MAX = -8
#: Largest array served from the heap instead of its own mmap (bytes).
MMAP_THRESHOLD = 1 << 30
#: Free memory at the heap top kept rather than trimmed (bytes; mallopt's largest value, 2 GiB).
TRIM_THRESHOLD = 2**31 - 1
#: Extra memory every heap extension asks for and keeps (bytes).
TOP_PAD = 64 << 20

_lock = threading.Lock()
_libc = None          # the C library once configured, False where it is not glibc


def _in_host() -> bool:
    """True inside Blender (``bpy`` loaded): a host application whose allocator is ours only during a render."""
    return "bpy" in sys.modules


def _glibc():
    """The process's C library if it is glibc (has mallopt and malloc_trim) and the process is not
    Blender's (a host application's allocator is not ours to keep tuned), else None."""
    return None if _in_host() else _glibc_library()


@functools.lru_cache(maxsize=1)
def _glibc_library():
    """The process's C library if it is glibc, else None (looked up once: ``find_library`` runs ``ldconfig -p``,
    3.7 ms, which inside Blender every render paid)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        if not hasattr(libc, "gnu_get_libc_version"):     # glibc only (musl has no mallopt)
            return None
        libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
        libc.malloc_trim.argtypes = [ctypes.c_size_t]
        return libc
    except (OSError, AttributeError):
        return None


def _apply(libc) -> None:
    libc.mallopt(_M_ARENA_MAX, 1)
    libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
    libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    libc.mallopt(_M_TOP_PAD, TOP_PAD)


def keep_freed_memory() -> bool:
    """Apply the settings above (once per process); True where they apply (glibc, not inside Blender)."""
    global _libc
    with _lock:
        if _libc is None:
            libc = _glibc()
            _libc = libc or False
            if libc:
                _apply(libc)
        return bool(_libc)


#: glibc limits set back after a render inside Blender: the largest its dynamic mmap threshold reaches
#: on 64-bit (DEFAULT_MMAP_THRESHOLD_MAX) and the trim threshold it pairs with it (2×), the default
#: top pad, and the default arena limit (8 per core).  (Setting the threshold once ends glibc's
#: dynamic adjustment, so the values it settles at in a long-running process are the ones restored.)
HOST_MMAP_THRESHOLD = 32 << 20
HOST_TRIM_THRESHOLD = 64 << 20
HOST_TOP_PAD = 128 << 10

_host_renders = 0     # renders inside Blender holding the settings (the viewport and F12 can overlap)


@contextmanager
def render_heap():
    """The settings above for the duration of a render inside Blender (nothing elsewhere: outside
    Blender :func:`keep_freed_memory` keeps them for the process)."""
    global _host_renders
    libc = _glibc_library() if _in_host() else None
    if libc is None:
        yield
        return
    with _lock:
        _host_renders += 1
        if _host_renders == 1:
            _apply(libc)
    try:
        yield
    finally:
        with _lock:
            _host_renders -= 1
            if _host_renders == 0:
                libc.mallopt(_M_ARENA_MAX, 8 * (os.cpu_count() or 1))
                libc.mallopt(_M_MMAP_THRESHOLD, HOST_MMAP_THRESHOLD)
                libc.mallopt(_M_TRIM_THRESHOLD, HOST_TRIM_THRESHOLD)
                libc.mallopt(_M_TOP_PAD, HOST_TOP_PAD)
                libc.malloc_trim(0)


def return_freed_memory() -> None:
    """Hand the freed memory of a finished render back to the system (glibc ``malloc_trim``)."""
    if _libc:
        _libc.malloc_trim(0)
