"""Polar's Blender side: render engine, settings, the Polarising BSDF node, panels, operators.

Imports the standalone engine (``..engine``); the engine never imports anything from here.
Submodules are imported in ``register()`` so that ``polar_addon.packaging`` works without Blender.
"""


def _modules():
    from . import nodes, operators, properties, render_engine, ui
    return (properties, nodes, render_engine, operators, ui)


def register():
    from . import kernel_cache
    # Before any engine module is imported: the engine picks its Numba cache folder on import.
    kernel_cache.configure(__package__.rpartition(".")[0])
    for module in _modules():
        module.register()
    from ..engine import kernels
    kernel_cache.warn_if_numpy_fallback(kernels)
    # Compile every kernel in a background process now, not in the first render (that waits for it).
    kernel_cache.start_precompile(__package__.rpartition(".")[0])
    # A Blender session renders again and again: "auto" may start the worker processes after a small render
    from ..engine.render.processes import keep_pool_warm
    keep_pool_warm()


def unregister():
    from . import kernel_cache
    kernel_cache.stop_precompile()
    from ..engine.render.processes import close_pool, keep_pool_warm
    keep_pool_warm(False)
    close_pool()                # the render's worker processes (engine.render.processes)
    for module in reversed(_modules()):
        module.unregister()
