"""Polar's Blender side: render engine, settings, the Polarising BSDF node, panels, operators.

Imports the standalone engine (``..engine``); the engine never imports anything from here.
Submodules are imported in ``register()`` so that ``polar_addon.packaging`` works without Blender.
"""


def _modules():
    from . import engine, nodes, operators, properties, ui
    return (properties, nodes, engine, operators, ui)


def register():
    for module in _modules():
        module.register()


def unregister():
    for module in reversed(_modules()):
        module.unregister()
