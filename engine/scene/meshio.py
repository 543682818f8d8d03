"""Mesh files: ``read_mesh(path, field="")`` picks the reader from the extension.

The readers are ``ply.read_ply`` (PLY, via plyfile) and ``obj.read_obj``
(Wavefront OBJ); ``MeshData`` and the geometry helpers live in ``trimesh``
and are re-exported here for the modules that import them from this one.
Both readers fill ``MeshData.uv`` when the file has texture coordinates
(PLY ``u, v`` and its aliases, OBJ ``vt``, split per corner) and PLY fills
``MeshData.colors["Col"]`` from ``red, green, blue(, alpha)``.
"""
from __future__ import annotations

import os

from ..files import refuse_special_file
from .obj import read_obj
from .ply import read_ply
from .trimesh import (MeshData, compute_vertex_normals, face_normals, mesh_file_error,
                      triangle_areas)

__all__ = [
    "MeshData",
    "read_mesh",
    "read_ply",
    "read_obj",
    "face_normals",
    "triangle_areas",
    "compute_vertex_normals",
]

_READERS = {".ply": read_ply, ".obj": read_obj}


def read_mesh(path, field: str = "") -> MeshData:
    """Read a mesh file, choosing the reader from the extension (.ply, .obj)."""
    refuse_special_file(path, field, "mesh file ")
    ext = os.path.splitext(os.fspath(path))[1].lower()
    reader = _READERS.get(ext)
    if reader is None:
        raise mesh_file_error(field, path, f"unsupported mesh format '{ext or '(no extension)'}' "
                                           f"(supported: {', '.join(sorted(_READERS))})")
    return reader(path, field)
