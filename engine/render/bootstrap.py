"""The command of a child Python process that imports this engine as its parent does: the worker processes of
engine.render.processes and the Blender extension's background compile (polar_addon.kernel_cache).

Inside Blender the engine is a subpackage of the extension (``bl_ext.<repo>.polar_render.engine``) whose top
``__init__`` imports bpy, which a plain Python child does not have: the child makes the package's modules empty
namespace packages (``__path__`` set, no ``__init__`` run) and imports ``<package>.engine`` below them, with the
parent's ``sys.path`` (the extension's wheels) first.  Module names stay the parent's (Numba's cache entries and
pickled objects name them).  Nothing here imports the engine's heavy modules (the extension imports this before
it sets Numba's cache folder).
"""

from __future__ import annotations

import json
import os
import sys

#: Reads (package, folder, sys.path) from argv; ``{before}`` runs before the engine is importable.
_HEAD = r"""
import importlib, json, os, sys, types
package, folder, paths = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
sys.path[:0] = [p for p in paths if p not in sys.path]
"""

#: Makes ``engine`` the importable name of the engine package (``<package>.engine`` or ``engine``).
_PACKAGE = r"""
parts = package.split(".") if package else []
for i in range(len(parts)):
    name = ".".join(parts[:i + 1])
    if name not in sys.modules:
        module = types.ModuleType(name)
        module.__path__ = [folder] if i == len(parts) - 1 else []
        sys.modules[name] = module
        if i:
            setattr(sys.modules[".".join(parts[:i])], parts[i], module)
if not package:
    sys.path.insert(0, folder)
engine = (package + ".engine") if package else "engine"
"""

#: This engine's folder's parent (the extension's or the checkout's root).
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def engine_package() -> str:
    """The package that contains this engine ("" where the engine is the top-level ``engine``)."""
    engine = __name__.rsplit(".render.bootstrap", 1)[0]
    return engine.rsplit(".", 1)[0] if "." in engine else ""


def child_command(body: str, before: str = "", package: str | None = None, folder: str = ROOT) -> list:
    """[sys.executable, "-c", code, package, folder, paths]: code runs ``before``, makes the engine importable as
    the module name in ``engine`` (``package`` None: this engine's own), then runs ``body``."""
    paths = [p for p in sys.path if p and os.path.isdir(p)]
    package = engine_package() if package is None else package
    return [sys.executable, "-c", _HEAD + before + _PACKAGE + body, package, folder, json.dumps(paths)]
