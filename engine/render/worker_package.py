"""Make the package that contains this engine importable on Dask workers under the same name.

Inside Blender the engine is a subpackage of the extension (e.g. ``bl_ext.user_default.polar_render
.engine``), so the scene objects and task functions sent to workers refer to that package.  This
module imports nothing from the engine: it is sent to the workers by value (cloudpickle) as a worker
plugin, which loads the package from the same path on every worker, including workers that join or
restart later.  The workers therefore need the extension at the same path (a shared file system,
or the same installation on every machine).
"""

import importlib.util
import sys
import types

from distributed.diagnostics.plugin import SchedulerPlugin, WorkerPlugin


def load_package(name: str, path: str):
    """Import package ``name`` from folder ``path`` (creating namespace parents), if not yet imported."""
    if name in sys.modules:
        return
    parts = name.split(".")
    for i in range(1, len(parts)):            # namespace parents such as bl_ext.user_default
        parent = ".".join(parts[:i])
        if parent not in sys.modules:
            module = types.ModuleType(parent)
            module.__path__ = []
            sys.modules[parent] = module
    spec = importlib.util.spec_from_file_location(name, f"{path}/__init__.py", submodule_search_locations=[path])
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)


class PackageLoader(WorkerPlugin):
    """Dask worker plugin: import ``name`` from ``path`` (the package folder) on each worker."""

    idempotent = True

    def __init__(self, name: str, path: str):
        self.name, self.path = name, path

    def setup(self, worker=None):
        load_package(self.name, self.path)


class SchedulerPackageLoader(SchedulerPlugin):
    """The same on the scheduler, which unpickles task graphs too."""

    idempotent = True

    def __init__(self, name: str, path: str):
        self.name, self.path = name, path

    async def start(self, scheduler=None):
        load_package(self.name, self.path)
