"""Library warnings (Numba's FutureWarning on the first render) stay out of the user's terminal unless
asked for: POLAR_LIBRARY_WARNINGS=1, `python -m engine -v`, or Blender started with --debug."""

import subprocess
import sys
import warnings

import numpy as np
import pytest

from engine import kernels
from engine.cli import build_parser, main


def _first(a):
    return a[0]


def _second(a):
    return a[1]


def _third(a):
    return a[2]


def _library_futurewarnings(records):
    return [w for w in records if issubclass(w.category, FutureWarning) and "numba" in w.filename]


@pytest.mark.skipif(kernels._numba is None, reason="needs numba")
def test_numba_futurewarning_is_hidden_unless_asked():
    # Numba types the arguments in Python (and warns) when a kernel is first called, so each phase
    # uses a kernel of its own.
    with warnings.catch_warnings(record=True) as rec:
        kernels.library_warnings(False)                  # the default at import
        kernels.jit(_first)(np.broadcast_arrays(np.ones(3), np.ones(1))[1])    # a broadcast_arrays view: Numba warns
        assert _library_futurewarnings(rec) == []
        kernels.library_warnings(True)
        kernels.jit(_second)(np.broadcast_arrays(np.ones(4), np.ones(1))[1])
        assert _library_futurewarnings(rec), "the warning this filter exists for is no longer raised"
        kernels.library_warnings(False)
        n = len(rec)
        kernels.jit(_third)(np.broadcast_arrays(np.ones(5), np.ones(1))[1])
        assert len(rec) == n
    # our own warnings are never filtered
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        kernels.library_warnings(False)
        warnings.warn("engine warning", UserWarning, stacklevel=1)
        assert len(rec) == 1


def test_filter_is_installed_at_import_and_env_var_shows_them():
    code = ("import warnings, engine.kernels as k; "
            "print(any(getattr(f[3], 'pattern', None) == k.LIBRARY_WARNING_MODULES for f in warnings.filters))")
    quiet = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert quiet.stdout.strip() == "True"
    import os
    env = dict(os.environ, POLAR_LIBRARY_WARNINGS="1")
    shown = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    assert shown.stdout.strip() == "False"


def test_cli_verbose_flag_shows_library_warnings(tmp_path):
    assert build_parser().parse_args(["-v", "polariser", "x.exr", "-o", "y.png"]).verbose
    assert build_parser().parse_args(["polariser", "x.exr", "-o", "y.png", "-v"]).verbose
    assert not build_parser().parse_args(["polariser", "x.exr", "-o", "y.png"]).verbose
    ours = lambda: any(getattr(f[3], "pattern", None) == kernels.LIBRARY_WARNING_MODULES  # noqa: E731
                       for f in warnings.filters)
    with warnings.catch_warnings():
        kernels.library_warnings(False)
        assert main(["polariser", str(tmp_path / "missing.exr"), "-o", str(tmp_path / "o.png")]) == 2
        assert ours()
        assert main(["-v", "polariser", str(tmp_path / "missing.exr"), "-o", str(tmp_path / "o.png")]) == 2
        assert not ours()
