"""Where the engine's compiled (Numba) kernels are cached inside Blender, and whether they are.

The extension bundles numba and llvmlite wheels.  Numba compiles each kernel on its first call and
caches the machine code on disk; the engine chooses that folder from ``POLAR_KERNEL_CACHE`` when its
kernels are decorated, i.e. when ``engine.kernels`` is first imported.  :func:`configure` therefore
runs in ``register()`` before any engine module is imported, and points the cache at Blender's
per-extension user folder (``<user>/extensions/.user/<repo>/polar_render/numba/<version>``), so it
survives Blender restarts, is removed with the extension, and starts empty for a new version.
"""

import logging
import os
import shutil
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
        return os.environ.get(ENV)
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
