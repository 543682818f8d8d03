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

In a process whose malloc is not glibc's (macOS, Windows, musl, a jemalloc build) nothing changes,
and nothing changes inside Blender either (``bpy`` loaded): the settings are process-wide and would
also hold Blender's own memory (images, undo steps) on its heap; there a render pays its page faults.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
import threading

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


def _glibc():
    """The process's C library if it is glibc (has mallopt and malloc_trim) and the process is not
    Blender's (a host application's allocator is not ours to tune), else None."""
    if not sys.platform.startswith("linux") or "bpy" in sys.modules:
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


def keep_freed_memory() -> bool:
    """Apply the settings above (once per process); True where they apply (glibc)."""
    global _libc
    with _lock:
        if _libc is None:
            libc = _glibc()
            _libc = libc or False
            if libc:
                libc.mallopt(_M_ARENA_MAX, 1)
                libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)
                libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
                libc.mallopt(_M_TOP_PAD, TOP_PAD)
        return bool(_libc)


def return_freed_memory() -> None:
    """Hand the freed memory of a finished render back to the system (glibc ``malloc_trim``)."""
    if _libc:
        _libc.malloc_trim(0)
