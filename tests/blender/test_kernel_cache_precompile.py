"""The extension compiles its kernels in a background process when it is enabled: registering starts at
most one, a render that starts before it has finished waits for it (and Esc stops the wait), and a failed
one is logged and leaves the render to compile in-process.  The background command is replaced by a
fake one (sleeping, or failing); the real one is run with the NumPy kernels, which it finishes at once,
to check that it imports the engine under the extension's package name.

(tests/blender/test_extension.py renders from an installed zip, where the real compile runs.)"""

import importlib
import logging
import os
import subprocess
import sys
import textwrap
import types

import pytest

pytest.importorskip("bpy")

from tests.blender_support import load_addon  # noqa: E402
from tests.conftest import REPO  # noqa: E402


@pytest.fixture
def addon(monkeypatch):
    ext = load_addon()
    cache = sys.modules[ext.__name__ + ".polar_addon.kernel_cache"]
    precompile = importlib.import_module(ext.__name__ + ".engine.render.precompile")
    monkeypatch.setattr(precompile, "precompiled", lambda: False)       # as on a fresh install
    monkeypatch.setenv("POLAR_PRECOMPILE", "1")                         # (a checkout: not started by default)
    cache.stop_precompile()
    yield types.SimpleNamespace(ext=ext, cache=cache)
    cache.stop_precompile()
    cache._PRECOMPILE.update(log=None, reported=False)


def fake(monkeypatch, cache, code):
    monkeypatch.setattr(cache, "precompile_command", lambda package: [sys.executable, "-c", code])


class FakeEngine:
    """What PolarRenderEngine._render uses of itself before it exports the scene."""

    def __init__(self, cancel=False):
        from polar_render.polar_addon.render_engine import RenderControl
        self.control = RenderControl()
        self.control.cancel = cancel
        self.statuses, self.reports = [], []

    def update_stats(self, stats, info):
        self.statuses.append(info)

    def test_break(self):
        return False

    def report(self, kind, message):
        self.reports.append(message)


class Exported(Exception):
    """Raised where the render goes on to export the scene (after any wait)."""


class Depsgraph:
    @property
    def scene(self):
        raise Exported


def render(engine):
    from polar_render.polar_addon.render_engine import PolarRenderEngine
    PolarRenderEngine._render(engine, Depsgraph())


#: Enabling, re-enabling and disabling the extension, in a fresh bpy process: unregistering and registering
#: again in the shared test process once failed there (order-dependent: "expected ShaderNodeCustomGroup
#: subclass of class PolarShaderNodeBSDF") and left every later Blender test of that worker without the engine.
REGISTER_CYCLE = textwrap.dedent("""
    import os, sys
    sys.path.insert(0, os.getcwd())
    from tests.blender_support import load_addon
    ext = load_addon()
    cache = sys.modules[ext.__name__ + ".polar_addon.kernel_cache"]
    precompile = sys.modules[ext.__name__ + ".engine.render.precompile"]
    precompile.precompiled = lambda: False                          # as on a fresh install
    os.environ["POLAR_PRECOMPILE"] = "1"                           # (a checkout: not started by default)
    cache.stop_precompile()
    cache.precompile_command = lambda package: [sys.executable, "-c", "import time; time.sleep(60)"]
    ext.unregister()
    ext.register()                                                 # as Blender enables the extension
    first = cache._PRECOMPILE["process"]
    assert first is not None and first.poll() is None
    assert cache.start_precompile(ext.__name__) is first           # enabled again: the same process
    ext.unregister()                                               # disabling stops it (and quitting Blender)
    assert first.poll() is not None and cache._PRECOMPILE["process"] is None
    os.environ["POLAR_PRECOMPILE"] = "0"
    ext.register()                                                 # switched off: none
    assert cache._PRECOMPILE["process"] is None
    print("REGISTER_CYCLE_OK")
""")


def test_registering_starts_at_most_one_background_compile():
    proc = subprocess.run([sys.executable, "-c", REGISTER_CYCLE], capture_output=True, text=True, cwd=REPO,
                          timeout=300)
    assert proc.returncode == 0 and "REGISTER_CYCLE_OK" in proc.stdout, proc.stdout[-2000:] + proc.stderr[-4000:]


def test_nothing_starts_when_the_cache_is_complete_or_for_a_checkout(addon, monkeypatch):
    fake(monkeypatch, addon.cache, "import time; time.sleep(60)")
    monkeypatch.delenv("POLAR_PRECOMPILE")
    assert addon.cache.start_precompile(addon.ext.__name__, installed=False) is None
    precompile = sys.modules[addon.ext.__name__ + ".engine.render.precompile"]
    monkeypatch.setattr(precompile, "precompiled", lambda: True)
    assert addon.cache.start_precompile(addon.ext.__name__, installed=True) is None


def test_a_render_waits_for_the_background_compile(addon, monkeypatch):
    monkeypatch.setattr(addon.cache, "WAIT_POLL", 0.05)
    fake(monkeypatch, addon.cache, "import time; time.sleep(1.0)")
    process = addon.cache.start_precompile(addon.ext.__name__)
    engine = FakeEngine()
    with pytest.raises(Exported):
        render(engine)
    assert process.poll() == 0                 # it went on only once the compile had ended
    assert engine.statuses[0] == addon.cache.WAITING == "Polar | compiling kernels (first render only)"
    assert any("waiting" in s for s in engine.statuses[1:]), engine.statuses
    engine = FakeEngine()                      # the next render does not wait
    with pytest.raises(Exported):
        render(engine)
    assert engine.statuses == []


def test_esc_stops_the_wait(addon, monkeypatch):
    fake(monkeypatch, addon.cache, "import time; time.sleep(60)")
    process = addon.cache.start_precompile(addon.ext.__name__)
    engine = FakeEngine(cancel=True)
    render(engine)                             # returns without exporting
    assert process.poll() is None              # ... while the compile goes on
    assert engine.statuses == [addon.cache.WAITING]
    assert "cancelled" in engine.reports[0]


def test_a_failed_background_compile_is_logged_and_the_render_goes_on(addon, monkeypatch, caplog):
    fake(monkeypatch, addon.cache, "import sys; print('numba exploded'); sys.exit(3)")
    process = addon.cache.start_precompile(addon.ext.__name__)
    process.wait()
    engine = FakeEngine()
    with caplog.at_level(logging.WARNING), pytest.raises(Exported):
        render(engine)
    warnings = [r.getMessage() for r in caplog.records if "background failed" in r.getMessage()]
    assert len(warnings) == 1 and "exit status 3" in warnings[0] and "numba exploded" in warnings[0]
    with caplog.at_level(logging.WARNING), pytest.raises(Exported):
        render(FakeEngine())                   # logged once
    assert len([r for r in caplog.records if "background failed" in r.getMessage()]) == 1


def test_the_background_command_imports_the_engine_under_the_extensions_name(addon, tmp_path):
    """The real command, with the NumPy kernels (nothing to compile: it ends at once)."""
    command = addon.cache.precompile_command(addon.ext.__name__)
    last = 'sys.exit(importlib.import_module(engine + ".render.precompile").main(["--threads", "1"]))'
    assert last in command[2]
    probe = command[2].replace(last, 'module = importlib.import_module(engine + ".render.precompile")\n'
                                     'print("PRECOMPILE=" + module.__name__)\nsys.exit(module.main([]))')
    env = {**os.environ, "POLAR_KERNELS": "numpy", "POLAR_KERNEL_CACHE": str(tmp_path)}
    env.pop("PYTHONPATH", None)
    proc = subprocess.run([command[0], "-c", probe, *command[3:]], capture_output=True, text=True, env=env,
                          cwd=str(tmp_path), timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "PRECOMPILE=polar_render.engine.render.precompile" in proc.stdout
    assert "nothing to compile" in proc.stderr
    assert command[4] == REPO
