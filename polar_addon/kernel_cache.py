"""Where the engine's compiled (Numba) kernels are cached inside Blender, and whether they are.

The extension bundles numba and llvmlite wheels.  Numba compiles each kernel on its first call and
caches the machine code on disk; the engine chooses that folder from ``POLAR_KERNEL_CACHE`` when its
kernels are decorated, i.e. when ``engine.kernels`` is first imported.  :func:`configure` therefore
runs in ``register()`` before any engine module is imported, and points the cache at Blender's
per-extension user folder (``<user>/extensions/.user/<repo>/polar_render/numba/<version>``), so it
survives Blender restarts, is removed with the extension, and starts empty for a new version.

Filling that cache takes a minute or two, once.  So that no render is the one that waits for it,
:func:`start_precompile` (from ``register()``) runs engine.render.precompile in a background
*process* (a thread would hold the GIL while Numba compiles, and freeze Blender's UI), writing into
the same folder under the same module names as the extension's engine (Numba's cache entries name
their module).  A render that starts before it has finished waits for it (:func:`wait_for_precompile`:
status "compiling kernels", Esc cancels); if it fails, the failure is logged and renders compile what
they need themselves, as without it.  It starts only for an installed extension whose cache is not
complete yet (``POLAR_PRECOMPILE=0`` never starts it, ``=1`` also from a checkout), never twice, and is
stopped when the extension is disabled or Blender quits.
"""

import atexit
import logging
import os
import shutil
import subprocess
import time
import tomllib

ENV = "POLAR_KERNEL_CACHE"
_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
log = logging.getLogger(__name__)


def _extension_version():
    with open(os.path.join(_ROOT, "blender_manifest.toml"), "rb") as fh:
        return tomllib.load(fh)["version"]


def configure(extension_package):
    """Set ``POLAR_KERNEL_CACHE`` to the extension's user folder; returns the folder in use, or None.

    ``extension_package`` is the extension's top package (``bl_ext.<repo>.polar_render``).  A value set
    outside Blender (e.g. a render farm's shared cache) is kept.  Loaded from a checkout rather than
    installed as an extension, Blender has no user folder for it: the engine's default stays.
    """
    import bpy
    try:
        base = bpy.utils.extension_path_user(extension_package, path="numba", create=True)
    except ValueError:          # "does not name an extension": a checkout loaded as a package
        _PRECOMPILE["installed"] = False
        return os.environ.get(ENV)
    _PRECOMPILE["installed"] = True
    current = os.environ.get(ENV)
    if current and not os.path.abspath(current).startswith(os.path.abspath(base) + os.sep):
        return current
    version = _extension_version()
    for old in os.listdir(base):        # caches of earlier versions of the extension are never read again
        if old != version:
            shutil.rmtree(os.path.join(base, old), ignore_errors=True)
    folder = os.path.join(base, version)
    os.makedirs(folder, exist_ok=True)
    os.environ[ENV] = folder
    return folder


def warn_if_numpy_fallback(kernels):
    """One warning at register time when the bundled numba wheels did not load (NumPy kernels, ~1.7x slower)."""
    if not kernels.COMPILED and os.environ.get("POLAR_KERNELS", "numba").lower() != "numpy":
        log.warning("Polar: numba could not be imported (bundled wheels missing or not for this platform); "
                    "rendering with the NumPy kernels (about 1.7x slower on the benchmark scenes). "
                    "Install the extension zip made for this platform.")


def first_compile_pending(kernels):
    """True when the compiled kernels are in use and their cache folder holds no compiled kernel yet.

    Numba writes one ``.nbi`` index per cached source file; none means the next render compiles
    every kernel it calls (tens of seconds, once).
    """
    if not kernels.COMPILED:
        return False
    for _, _, files in os.walk(kernels.cache_dir()):
        if any(name.endswith(".nbi") for name in files):
            return False
    return True


#: The status a render shows while it waits for the background compile (the first, then with seconds).
WAITING = "Polar | compiling kernels (first render only)"
#: Seconds between a waiting render's checks (for the process, and for Esc).
WAIT_POLL = 0.2
#: The background compile's process (subprocess.Popen), its log file, and whether its end was reported.
_PRECOMPILE = {"process": None, "log": None, "reported": False, "installed": False}

#: Child process: the engine imported under the extension's own package name (its modules' names are in Numba's
#: cache entries) without running the extension's __init__ (which needs bpy: engine.render.bootstrap), then precompile.
_NICE = """
try:
    os.nice(10)                  # behind Blender's own work
except (AttributeError, OSError):
    pass
"""
_PRECOMPILE_BODY = """
sys.exit(importlib.import_module(engine + ".render.precompile").main(["--threads", "1"]))
"""


def precompile_command(extension_package: str) -> list:
    """The command of the background compile (tests replace it with a slow or failing one)."""
    from ..engine.render.bootstrap import child_command
    return child_command(_PRECOMPILE_BODY, _NICE, extension_package, _ROOT)


def _wanted(installed: bool) -> bool:
    choice = os.environ.get("POLAR_PRECOMPILE", "")
    if choice in ("0", "1"):
        return choice == "1"
    return installed


def start_precompile(extension_package: str, installed: bool | None = None):
    """Start the background compile unless it is running, not wanted, or nothing is to do; returns its
    process or None.  ``installed``: the extension runs from Blender's extension folder (default: as
    :func:`configure` found; checkouts and test sessions leave it to ``make`` unless POLAR_PRECOMPILE=1)."""
    if installed is None:
        installed = _PRECOMPILE["installed"]
    from ..engine import kernels
    from ..engine.render.precompile import precompiled
    running = _PRECOMPILE["process"]
    if running is not None and running.poll() is None:
        return running
    if not kernels.COMPILED or not _wanted(installed) or precompiled():
        return None
    log_path = os.path.join(kernels.cache_base(), "precompile.log")
    try:
        os.makedirs(os.path.dirname(log_path), exist_ok=True)
        log_file = open(log_path, "w", encoding="utf-8")
    except OSError:
        import tempfile
        log_file = tempfile.NamedTemporaryFile("w", prefix="polar-precompile-", suffix=".log", delete=False)
        log_path = log_file.name
    try:
        process = subprocess.Popen(precompile_command(extension_package), stdin=subprocess.DEVNULL, stdout=log_file,
                                   stderr=subprocess.STDOUT, env=dict(os.environ), cwd=os.path.dirname(log_path))
    except OSError as e:
        log.warning("Polar: could not start compiling the kernels in the background (%s): the first render "
                    "compiles them", e)
        return None
    finally:
        log_file.close()
    _PRECOMPILE.update(process=process, log=log_path, reported=False)
    log.info("Polar: compiling kernels in the background (pid %d, log %s)", process.pid, log_path)
    return process


def stop_precompile() -> None:
    """Stop a background compile still running (the extension is disabled, or Blender quits); what it
    compiled so far stays cached."""
    process = _PRECOMPILE["process"]
    if process is not None and process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout=2)
        except subprocess.TimeoutExpired:
            process.kill()
    _PRECOMPILE["process"] = None


atexit.register(stop_precompile)


def precompile_running() -> bool:
    process = _PRECOMPILE["process"]
    return process is not None and process.poll() is None


def _log_tail(lines: int = 1) -> list:
    try:
        with open(_PRECOMPILE["log"], encoding="utf-8", errors="replace") as fh:
            return fh.read().splitlines()[-lines:]
    except (OSError, TypeError):
        return []


def _progress() -> str:
    """The background compile's last step, e.g. "[3/15]" (from its log), or ""."""
    tail = _log_tail()
    if tail and "[" in tail[0] and "/" in tail[0]:
        step = tail[0][tail[0].index("["):].split("]", 1)[0] + "]"
        return f" | step {step}"
    return ""


def wait_for_precompile(status, cancelled) -> str:
    """Wait for the background compile: "none" (none was running), "done", "failed" (logged: the render
    then compiles what it needs) or "cancelled" (``cancelled()`` said so while waiting).  ``status(text)``
    shows the wait (first ``WAITING``, then with the seconds waited)."""
    process = _PRECOMPILE["process"]
    if process is None:
        return "none"
    if process.poll() is None:
        status(WAITING)
        t0 = time.monotonic()
        while process.poll() is None:
            if cancelled():
                return "cancelled"
            time.sleep(WAIT_POLL)
            if process.poll() is None:
                status(f"{WAITING} | waiting {time.monotonic() - t0:.0f} s{_progress()}")
    if process.returncode != 0:
        if not _PRECOMPILE["reported"]:
            _PRECOMPILE["reported"] = True
            log.warning("Polar: compiling the kernels in the background failed (exit status %s, log %s): "
                        "renders compile what they need themselves.%s", process.returncode, _PRECOMPILE["log"],
                        "".join("\n  " + line for line in _log_tail(8)))
        return "failed"
    return "done"
