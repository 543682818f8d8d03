"""Shader nodes: the "Polarising BSDF" node lives in the normal shader editor."""

from . import bsdf


def register():
    bsdf.register()


def unregister():
    bsdf.unregister()
