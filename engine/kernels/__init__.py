"""Compiled hot loops with pure-NumPy twins that give the same numbers.

The renderer's inner work — surface reconstruction, the per-vertex Mueller update
T ← T·R(φ)·M, scatter-adding light into the per-path accumulators, counter-based
random numbers, Fresnel coefficients — is a chain of small elementwise steps.  In
NumPy each step allocates and walks a full batch array, so shading costs several
times the ray casting.  Each kernel here is written twice:

- ``*_numpy``: the reference, vectorised NumPy (always available);
- ``*_numba``: the same arithmetic in the same order as a Numba loop over paths
  (``nogil`` so worker threads run in parallel, ``cache`` so a process compiles
  each kernel once per machine).

Every pair is declared once with :func:`twin`, which records it in :data:`TWINS` (so tests can
enumerate them) and returns the function to use: the Numba version when the optional ``numba``
package imports and ``POLAR_KERNELS`` is not ``numpy``, otherwise the NumPy one.  Tests run both
on the same inputs and require equality (bit-for-bit where the operation order is the same, 1e-12
relative where a reduction order differs).  Numba is optional at run time (a dependency of the
package, but the Blender extension does not bundle it): without it a render gives the same image,
only slower.

Kernels are the lowest compute layer: they import only ``engine.vec3`` and each other.  A NumPy
reference that is physics of a higher layer (the Fresnel amplitudes of engine.polarisation.fresnel)
stays there and is paired with its compiled loop by :func:`twin` where it is defined.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import time
import warnings
from typing import NamedTuple
from collections.abc import Callable

#: Modules whose warnings (e.g. Numba's FutureWarning about broadcast arrays while typing a kernel's
#: arguments) are implementation noise for a user: hidden unless POLAR_LIBRARY_WARNINGS=1, the CLI's
#: -v, or Blender started with --debug (library_warnings(True)).
LIBRARY_WARNING_MODULES = r"(numba|llvmlite)(\.|$)"


def library_warnings(show: bool) -> None:
    """Show (True) or hide (False) warnings raised inside the kernel libraries (process-wide)."""
    ours = [f for f in warnings.filters
            if f[0] == "ignore" and getattr(f[3], "pattern", None) == LIBRARY_WARNING_MODULES]
    for f in ours:
        warnings.filters.remove(f)
    getattr(warnings, "_filters_mutated", lambda: None)()   # the same bookkeeping as filterwarnings does
    if not show:
        warnings.filterwarnings("ignore", module=LIBRARY_WARNING_MODULES)


library_warnings(os.environ.get("POLAR_LIBRARY_WARNINGS", "") not in ("", "0"))

try:  # optional dependency
    import numba as _numba
except ImportError:  # pragma: no cover - exercised on machines without numba
    _numba = None

#: True when the compiled kernels are in use.
COMPILED = _numba is not None and os.environ.get("POLAR_KERNELS", "numba").lower() != "numpy"
#: Human-readable backend name for logs and render stats.
BACKEND = f"numba {_numba.__version__}" if COMPILED else "numpy"


#: The package these kernels belong to: "engine", or e.g. "bl_ext.user_default.polar_render.engine"
#: inside Blender.
_PACKAGE = __name__.rsplit(".kernels", 1)[0]


#: The engine package's folder (the sources whose compiled code is cached).
_ENGINE_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def compiled_sources_digest(root: str = _ENGINE_DIR, every_module: bool = False) -> str:
    """16 hex digits identifying the source of every module under ``root`` that holds compiled code.

    Numba checks a cached kernel against its own file's time stamp only, but a kernel has the
    helpers it calls from other files compiled into it (``abcs_at`` inside every Fresnel step): after
    an edit to engine/kernels/fresnel.py the cached Torrance–Sparrow step would go on running the old
    Fresnel arithmetic.  Keying the cache folder by all compiled sources makes any such edit (or an
    upgrade) start a fresh folder.  Reading them costs a few milliseconds per import.
    ``every_module``: the digest of every module's source (what a cached precomputed table depends on).
    """
    digest = hashlib.sha1()
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith((".", "__")))
        for name in sorted(f for f in files if f.endswith(".py")):
            path = os.path.join(folder, name)
            with open(path, "rb") as fh:
                data = fh.read()
            if every_module or b"jit" in data:
                digest.update(os.path.relpath(path, root).encode() + b"\0" + data + b"\0")
    return digest.hexdigest()[:16]


def cache_dir() -> str:
    """Where compiled kernels are cached: one folder per package name and compiled sources.

    Numba keys its cache by source file, but a cached kernel refers to its module by name; the same
    files imported under two names (a checkout used both as ``engine`` and as the Blender extension
    ``polar_render.engine``) would load each other's entries and fail.  Below the package name, one
    folder per :func:`compiled_sources_digest`, so a changed helper is never run from a stale kernel.
    ``POLAR_KERNEL_CACHE`` overrides the base folder (default: $XDG_CACHE_HOME or ~/.cache, then
    polar/numba).
    """
    return os.path.join(cache_base(), _PACKAGE, _SOURCES_DIGEST)


def cache_base() -> str:
    """The base folder of the kernel cache (and of engine.materials.table_cache's tables):
    ``POLAR_KERNEL_CACHE``, else $XDG_CACHE_HOME or ~/.cache, then polar/numba."""
    return os.environ.get("POLAR_KERNEL_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "polar", "numba")


_SOURCES_DIGEST = compiled_sources_digest()

#: Every compiled kernel :func:`jit` made in this process (engine.kernels.precompile counts them).
DISPATCHERS: list = []


class CompileLog:
    """This process's compilations of the package's kernels (loads from Numba's cache are not compiles).

    ``compiled``: kernels compiled (a kernel's helpers compiled with it count too); ``seconds``: the wall
    time of the outermost compilations.  Numba compiles one kernel at a time under its compiler lock,
    and announces each (the "numba:compile" event) only when the on-disk cache had no entry for it:
    ``watch`` calls a function at the start of the first compilation while it is active, which is
    how the command line says "compiling kernels (first run only)" exactly when it happens.
    """

    def __init__(self):
        self.compiled = 0
        self.seconds = 0.0
        self._depth = 0
        self._t0 = 0.0
        self._watchers: list = []

    def snapshot(self) -> tuple[int, float]:
        """(compiled, seconds) so far; subtract two snapshots for what happened in between."""
        return self.compiled, self.seconds

    @contextlib.contextmanager
    def watch(self, on_first_compile: Callable[[], None]):
        """While active, call ``on_first_compile()`` (once, in the compiling thread) when a kernel starts
        compiling."""
        entry = [on_first_compile]
        self._watchers.append(entry)
        try:
            yield self
        finally:
            self._watchers.remove(entry)

    # called by a numba.core.event.Listener registered for "numba:compile" (when numba is in use)
    def on_start(self, event) -> None:
        if not _ours(event):
            return
        self.compiled += 1
        self._depth += 1
        if self._depth == 1:
            self._t0 = time.perf_counter()
            for entry in list(self._watchers):
                if entry[0] is not None:
                    callback, entry[0] = entry[0], None
                    callback()

    def on_end(self, event) -> None:
        if not _ours(event):
            return
        self._depth -= 1
        if self._depth == 0:
            self.seconds += time.perf_counter() - self._t0



def _ours(event) -> bool:
    dispatcher = (event.data or {}).get("dispatcher")
    module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
    return module == _PACKAGE or module.startswith(_PACKAGE + ".")


def uses_cache() -> bool:
    """True when the compiled kernels are in use, and so Numba's on-disk cache (engine.render.precompile)."""
    return COMPILED


#: The process's compile log (engine.render.renderer puts it in a render's stats, the CLI says when it starts).
COMPILES = CompileLog()
if COMPILED:
    from numba.core import event as _numba_event

    class _CompileListener(_numba_event.Listener):
        def on_start(self, event):
            COMPILES.on_start(event)

        def on_end(self, event):
            COMPILES.on_end(event)

    _numba_event.register("numba:compile", _CompileListener())


def jit(fn, *, refcounts=True):
    """Compile ``fn`` with Numba (no fast-math: IEEE results like NumPy), or return None.

    The cache folder is chosen when the function is decorated (Numba picks its cache locator then),
    so it is set for this decoration only and other Numba users in the process are unaffected.
    """
    if _numba is None:
        return None
    from numba.core import config
    previous = config.CACHE_DIR
    config.CACHE_DIR = cache_dir()
    try:
        dispatcher = _numba.njit(cache=True, nogil=True, fastmath=False, error_model="numpy", _nrt=refcounts)(fn)
    finally:
        config.CACHE_DIR = previous
    DISPATCHERS.append(dispatcher)
    return dispatcher


def jit_inner(fn):
    """``jit`` for a helper that compiled loops call per element: compiled without Numba's reference
    counting (same numbers).

    A compiled function takes a reference to each array argument on entry and drops it on exit,
    two atomic operations on the array's shared header per call.  Inlined into a loop, LLVM removes
    them only where no branch follows the array reads: a measured-metal table lookup (a NaN test
    after the interpolation) cost 59 ns instead of 5, and threads reading one table contend for its
    header.  A helper so compiled must not allocate, return or keep an array, nor call a function
    that allocates (Numba refuses the first two without reference counting).
    """
    return jit(fn, refcounts=False)


class Twin(NamedTuple):
    """A kernel's two implementations: ``compiled`` (None without Numba) and the NumPy ``reference``."""
    compiled: Callable | None
    reference: Callable


#: Every declared kernel pair, by the dotted name of its public function (without the package
#: prefix), e.g. "kernels.transport.update_abcs" or "polarisation.fresnel.fresnel_reflection_abcs".
TWINS: dict[str, Twin] = {}


def twin(compiled, reference):
    """Declare a kernel pair and return the function to use: ``compiled`` when enabled, else ``reference``.

    ``reference`` is the NumPy function ``<name>_numpy``; ``compiled`` the Numba-backed function with
    its signature, or None (no Numba: written as ``_loop and wrapper``, ``jit`` returning None then).
    """
    public = reference.__name__.removesuffix("_numpy")
    module = reference.__module__
    if module.startswith(_PACKAGE + "."):
        module = module[len(_PACKAGE) + 1:]
    key = f"{module}.{public}"
    TWINS[key] = Twin(compiled, reference)
    return compiled if (COMPILED and compiled is not None) else reference
