"""One BLAS thread while a render's workers run.

A few small products in the hot path go through NumPy's BLAS (the 3×3 colour matrix times each
path's colour-matching values in ``engine.spectral.cie``, RGB spectra in ``engine.spectral.spectrum``).
OpenBLAS splits even those over its own thread pool, one thread per core: a 1-thread render of
fresnel_sphere_au used 4.55 s of CPU in 3.66 s of wall time, 3.42 s in 3.41 s with one BLAS
thread, and with two render workers the BLAS threads compete with them for the same two cores.
The render's parallelism is over work units, so BLAS gets one thread per caller while the
workers run.  The numbers do not change: the contractions are 3 terms long, and BLAS divides
the output, not the sums, between its threads.

threadpoolctl (scikit-learn's; it finds OpenBLAS, MKL or BLIS in the process and calls their
own ``set_num_threads``) does it; where it is not installed nothing changes.  The limit is
process-wide and restored when the render ends.  The libraries are looked up once per process (a
``ThreadpoolController``; NumPy's BLAS is loaded with the engine): the lookup reads the process's memory
map, 2.4 ms per render inside Blender (5 % of a small asset's render).
"""

from __future__ import annotations

import contextlib
import threading

try:
    from threadpoolctl import ThreadpoolController
except ImportError:             # optional: only the speed depends on it
    ThreadpoolController = None

_lock = threading.Lock()
_depth = 0                      # renders (or warm-ups) running now, in any thread
_limiter = None                 # the active limit, restored by the last one to finish
_controller = None              # the process's thread pools, found on first use


@contextlib.contextmanager
def one_blas_thread():
    """Within the block, BLAS calls use one thread each (nested and concurrent uses share one limit)."""
    global _depth, _limiter, _controller
    if ThreadpoolController is None:
        yield
        return
    with _lock:
        if _depth == 0:
            if _controller is None:
                _controller = ThreadpoolController()
            _limiter = _controller.limit(limits=1, user_api="blas")
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                _limiter.restore_original_limits()
                _limiter = None
