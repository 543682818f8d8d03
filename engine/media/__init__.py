"""Participating media: phase functions as Mueller matrices and free-flight building blocks.

One phase function per file, each with one declaration of its parameters (``DECLARATION``, as the
material models: engine.materials.parameters) and the interface of engine.media.phase.PhaseFunction.
``engine.media.catalogue`` lists them; the transport (media on meshes and the world, delta tracking, medium
vertices) is engine.render.participating.
Conventions and formulas: docs/physics.md, "Phase functions".
"""
