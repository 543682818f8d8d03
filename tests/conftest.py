"""Shared test fixtures: where the project's shared/ folder (oracles, peer scenes) lives."""

import os
import sys

import pytest

# On AVX-512 CPUs NumPy runs its float64 arccos, sin, cos, … loops through SVML and OpenBLAS its
# SkylakeX matrix kernels; both round differently in the last bit from the C library's functions
# and loops that the compiled kernels use, and the twin tests compare bit for bit.  On such a CPU
# the tests keep NumPy on its AVX2 loops and OpenBLAS on its Haswell kernels (both need only
# AVX2 + FMA, which every AVX-512 CPU has); set before NumPy is first imported.


def _cpu_has_avx512() -> bool:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            return any(line.startswith("flags") and " avx512f" in line for line in f)
    except OSError:
        return False


if "numpy" not in sys.modules and _cpu_has_avx512():
    os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", "AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX "
                                                      "AVX512_CLX AVX512_CNL AVX512_ICL")
    os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
ORACLES = os.path.join(SHARED, "oracles")
PEERS = os.path.join(SHARED, "peers")


def shared_path(*parts):
    path = os.path.join(SHARED, *parts)
    if not os.path.exists(path):
        pytest.fail(f"shared data missing: {path} (set POLAR_SHARED to the shared/ folder)")
    return path


# CI runs property tests derandomized, so that main stays green for a given commit; developers'
# runs explore new random examples every time (and the failures they find become regression tests).
if os.environ.get("CI"):
    from hypothesis import settings as _hsettings
    _hsettings.register_profile("ci", derandomize=True, deadline=None)
    _hsettings.load_profile("ci")


# Markers (declared in pyproject.toml): by folder here, by module or test in the files themselves.
# `make test-fast` leaves out blender, subprocess, cluster and fuzz.
_FOLDER_MARKS = {"blender": ("blender",), "cli": ("subprocess",)}


def pytest_collection_modifyitems(config, items):
    tests = os.path.dirname(os.path.abspath(__file__))
    for item in items:
        folder = os.path.relpath(str(item.path), tests).split(os.sep)[0]
        for name in _FOLDER_MARKS.get(folder, ()):
            item.add_marker(name)
