"""Polar's Blender side: render engine, settings, the Polarising BSDF node, panels, operators.

Imports the standalone engine (``..engine``); the engine never imports anything from here.
"""

from . import engine, nodes, operators, properties, ui

_modules = (properties, nodes, engine, operators, ui)


def register():
    for module in _modules:
        module.register()


def unregister():
    for module in reversed(_modules):
        module.unregister()
