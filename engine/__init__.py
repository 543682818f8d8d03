"""Polar's standalone rendering engine: a spectral path tracer with Mueller-matrix transport.

Usable without Blender::

    from engine import load_scene, render
    scene = load_scene("examples/demo.json")
    result = render(scene)          # RenderResult: result.stokes() is (4, H, W, 3)

Conventions (Stokes frames, signs, Fresnel) are those of the project's
physics reference; see docs/physics.md, "Conventions".
"""

__version__ = "0.1.0"


def load_scene(path):
    """Read and validate a scene file (see engine.scene.loader)."""
    from .scene.loader import load_scene as _load
    return _load(path)


def render(scene, settings=None, progress=None, should_stop=None):
    """Render a Scene (see engine.render.renderer.render)."""
    from .render.renderer import render as _render
    return _render(scene, settings, progress, should_stop)
