"""Cold start: a render on an empty kernel cache says it compiles; after ``python -m engine precompile`` a
render in a new process compiles nothing; the command line says when it compiles kernels, keeps that out of the render's
time (stats) and starts its time estimate after the first traced batch.

Whether a process compiled is read from Numba's own compile events (engine.kernels.COMPILES, which
the stats line reports) and from the cache files, never from timing."""

import io
import json
import os
import shutil
import subprocess
import sys
import types

import pytest

from engine import kernels
from engine.cli import COMPILING_MESSAGE, ProgressBar
from engine.render.renderer import stats_line
from tests.conftest import REPO, shared_path


def run(args, cache, **kw):
    env = {**os.environ, "POLAR_KERNEL_CACHE": str(cache)}
    env.pop("POLAR_KERNELS", None)
    return subprocess.run([sys.executable, "-m", "engine", *args], cwd=REPO, capture_output=True, text=True,
                          env=env, timeout=900, **kw)


def cache_files(cache) -> set:
    return {os.path.join(d, f) for d, _, files in os.walk(cache) for f in files if f.endswith((".nbi", ".nbc"))}


def tiny_scene(tmp_path, name="fresnel_sphere_au"):
    """A peer scene at 16×12 (what a user renders first is not one of the precompile's own scenes)."""
    source = shared_path("peers", "scenes", f"{name}.json")
    data = json.load(open(source))
    data["camera"]["width"], data["camera"]["height"] = 16, 12
    for obj in data.get("objects", []):
        if "file" in obj:
            obj["file"] = os.path.join(os.path.dirname(source), obj["file"])
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(data))
    return str(path)


@pytest.mark.skipif(not kernels.COMPILED, reason="Numba kernels disabled")
def test_a_render_on_an_empty_cache_says_it_compiles_and_keeps_that_apart(tmp_path):
    cold = run(["render", tiny_scene(tmp_path), "-o", str(tmp_path / "cold.exr"), "--spp", "2", "--no-previews"],
               tmp_path / "cache")
    assert cold.returncode == 0, cold.stderr
    assert COMPILING_MESSAGE in cold.stderr
    assert "compiled in" in cold.stderr and "first run only" in cold.stderr
    assert cache_files(tmp_path / "cache")


@pytest.mark.skipif(not kernels.COMPILED, reason="Numba kernels disabled")
def test_after_precompile_renders_compile_nothing(tmp_path):
    """``precompile`` on the user's own cache folder, which the Makefile's install step fills (``make test`` runs
    it first, so the suite does not compile every kernel a second time), fills what is missing or finds its
    marker; new processes rendering other scenes and transports then compile nothing and write no file."""
    filled = run(["precompile"], kernels.cache_base())
    assert filled.returncode == 0, filled.stderr
    assert ("kernels ready" in filled.stderr and "compiling every kernel into" in filled.stderr
            or "kernels already compiled" in filled.stderr), filled.stderr
    # the renders read a copy of the filled folder, which the suite's other processes do not write into
    cache = tmp_path / "cache"
    folder = kernels.cache_dir()
    shutil.copytree(folder, os.path.join(cache, os.path.relpath(folder, kernels.cache_base())))
    files = cache_files(cache)
    assert files
    for name, options in (("fresnel_sphere_au", ["--spp", "2"]),
                          ("cornell_lambert", ["--spp", "3", "--sampler", "independent", "--polarisation", "off"]),
                          ("glass_sphere", ["--spp", "2", "--spectral", "rgb"])):
        warm = run(["render", tiny_scene(tmp_path, name), "-o", str(tmp_path / f"{name}.exr"), "--no-previews",
                    *options], cache)
        assert warm.returncode == 0, warm.stderr
        assert COMPILING_MESSAGE not in warm.stderr, (name, warm.stderr)
        assert "compiled in" not in warm.stderr, (name, warm.stderr)
    assert cache_files(cache) == files
    # idempotent: a second precompile finds the marker and returns at once
    again = run(["precompile"], cache)
    assert again.returncode == 0 and "kernels already compiled" in again.stderr, again.stderr


def test_the_progress_estimate_starts_after_the_first_traced_batch():
    out = io.StringIO()
    bar = ProgressBar("rendering", stream=out)
    bar(0.05, {"samples": 10})                 # the first batch: nothing to extrapolate from yet
    assert "?s left" in out.getvalue()
    bar(0.5, {"samples": 100})
    last = out.getvalue().rsplit("\r", 1)[-1]
    assert "?s left" not in last and "s left" in last
    bar.note(COMPILING_MESSAGE)                # a note goes on a line of its own below the bar
    assert out.getvalue().endswith("\n" + COMPILING_MESSAGE + "\n")


def test_the_stats_line_names_kernel_compilation_apart_from_the_render_time():
    stats = {"samples": 100, "seconds": 1.0, "rays": 1, "shadow_rays": 0, "transport_reason": "full",
             "spectral": "spectral", "kernels": "numba 0.0"}
    assert "compiled" not in stats_line(stats)
    assert "compiled" not in stats_line({**stats, "kernels_compiled": 0})
    line = stats_line({**stats, "kernels_compiled": 12, "kernel_compile_seconds": 20.5})
    assert "kernels: numba 0.0, 12 compiled in 20.5 s (first run only; not in the render time)" in line
    line = stats_line({**stats, "kernels_compiled": 3, "kernel_compile_seconds": 2.0, "compiled_in_render": True})
    assert "3 compiled in 2.0 s (first run only)" in line


def test_the_compile_log_counts_the_packages_compilations_and_calls_a_watcher_once():
    log = kernels.CompileLog()

    def event(module):
        return types.SimpleNamespace(data={"dispatcher": types.SimpleNamespace(
            py_func=types.SimpleNamespace(__module__=module))})
    said = []
    with log.watch(lambda: said.append("compiling")):
        outer, inner = event("engine.kernels.transport"), event("engine.kernels.fresnel")
        log.on_start(outer)
        log.on_start(inner)                    # a helper compiled inside its caller
        log.on_end(inner)
        log.on_end(outer)
        log.on_start(event("someone_else"))    # other Numba users of the process are not counted
        log.on_end(event("someone_else"))
        log.on_start(outer)
        log.on_end(outer)
    assert said == ["compiling"] and log.compiled == 3 and log.seconds >= 0
    log.on_start(outer)
    log.on_end(outer)
    assert said == ["compiling"] and log.compiled == 4     # the watch ended


def test_precompile_is_quick_without_numba(tmp_path):
    env = {**os.environ, "POLAR_KERNELS": "numpy", "POLAR_KERNEL_CACHE": str(tmp_path)}
    proc = subprocess.run([sys.executable, "-m", "engine", "precompile"], cwd=REPO, capture_output=True, text=True,
                          env=env, timeout=300)
    assert proc.returncode == 0 and "nothing to compile" in proc.stderr, proc.stderr
    assert not cache_files(tmp_path)
