"""Polar Render — Blender extension entry point.

Only forwards registration to polar_addon; importing this file must not import bpy,
so that the engine package beside it stays usable without Blender.
"""


def register():
    from .polar_addon import register as _register
    _register()


def unregister():
    from .polar_addon import unregister as _unregister
    _unregister()
