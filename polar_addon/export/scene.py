"""Evaluated depsgraph → engine Scene (geometry with modifiers and instances, materials, lights,
world, camera), using ``foreach_get`` fast paths.  Warnings for things that are approximated are
collected and reported once; real mistakes raise SceneError naming the object."""

import numpy as np

from ...engine.materials.lambert import Lambert
from ...engine.scene.description import Mesh, RenderSettings, Scene
from ...engine.errors import SceneError
from ...engine.spectral import ConstantSpectrum
from .camera import export_camera
from .lights import export_light
from .materials import export_material
from .world import export_world

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
BLACK = "__polar_black__"


def mesh_arrays(obj):
    """World-independent triangle data of an evaluated object: positions (T·3, 3) per corner,
    split (shading) normals per corner, and the material slot index per triangle; None if empty."""
    me = obj.to_mesh()
    try:
        me.calc_loop_triangles()
        nv, nt = len(me.vertices), len(me.loop_triangles)
        if nt == 0:
            return None
        P = np.empty(nv * 3, np.float32)
        me.attributes["position"].data.foreach_get("vector", P)
        F = np.empty(nt * 3, np.int32)
        me.loop_triangles.foreach_get("vertices", F)
        SN = np.empty(nt * 9, np.float32)
        me.loop_triangles.foreach_get("split_normals", SN)
        tri_poly = np.empty(nt, np.int32)
        me.loop_triangle_polygons.foreach_get("value", tri_poly)
        mi = me.attributes.get("material_index")
        if mi is not None and len(me.polygons):
            poly_mat = np.empty(len(me.polygons), np.int32)
            mi.data.foreach_get("value", poly_mat)
            tri_mat = poly_mat[tri_poly]
        else:
            tri_mat = np.zeros(nt, np.int32)
        return P.reshape(nv, 3).astype(np.float64), F.reshape(nt, 3), SN.reshape(nt * 3, 3).astype(np.float64), tri_mat
    finally:
        obj.to_mesh_clear()


def export_scene(depsgraph, camera_object, width, height, settings: RenderSettings):
    """(engine Scene, list of warnings) for an evaluated depsgraph."""
    scene = depsgraph.scene
    warnings = []
    camera = export_camera(scene, camera_object, width, height, warnings)
    materials = {BLACK: Lambert(ConstantSpectrum(0.0))}
    mat_keys = {}
    emissions = {}
    meshes, lights = [], []
    cache = {}

    def material_key(material):
        name = material.name_full if material is not None else None
        if name not in mat_keys:
            key = f"mat:{name}" if name is not None else "mat:<default>"
            bsdf, emission = export_material(material, warnings)
            materials[key] = bsdf
            emissions[key] = emission
            mat_keys[name] = key
        return mat_keys[name]

    for inst in depsgraph.object_instances:
        obj = inst.object
        M = np.array(inst.matrix_world, dtype=np.float64)
        if obj.type == "LIGHT":
            light = export_light(obj, M, warnings)
            if isinstance(light, Mesh):
                meshes.append(light)
            elif light is not None:
                lights.append(light)
            continue
        if obj.type not in GEOMETRY_TYPES:
            continue
        data_key = (obj.original.name_full, obj.data.name_full if obj.data is not None else "")
        if data_key not in cache or not inst.is_instance:
            cache[data_key] = mesh_arrays(obj)
        arrays = cache[data_key]
        if arrays is None:
            continue
        P, F, SN, tri_mat = arrays
        if not np.all(np.isfinite(P)):
            raise SceneError(f"object {obj.name!r}", "has non-finite vertex coordinates")
        Pw = P @ M[:3, :3].T + M[:3, 3]
        normal_matrix = np.linalg.inv(M[:3, :3]).T if abs(np.linalg.det(M[:3, :3])) > 1e-300 else None
        if normal_matrix is None:
            warnings.append(f"object {obj.name!r} has a singular transform (zero scale); skipped")
            continue
        tri = Pw[F]
        area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        degenerate = ~(area2 > 0)
        if degenerate.all():
            warnings.append(f"object {obj.name!r} has only zero-area faces; skipped")
            continue
        if degenerate.any():
            warnings.append(f"object {obj.name!r}: {int(degenerate.sum())} zero-area faces ignored")
        N = SN @ normal_matrix.T
        length = np.linalg.norm(N, axis=1, keepdims=True)
        N = np.where(length > 0, N / np.where(length > 0, length, 1.0), 0.0)
        mirrored = np.linalg.det(M[:3, :3]) < 0   # keep front faces in front under negative scale
        slots = [s.material for s in obj.material_slots] or [None]
        keys = [material_key(slots[i] if i < len(slots) else None) for i in range(len(slots))]
        tri_mat = np.clip(tri_mat, 0, len(keys) - 1)
        # One engine Mesh per (object, emissive material) so that emitters are separate lights.
        for slot in np.unique(tri_mat):
            sel = np.nonzero(tri_mat == slot)[0]
            key = keys[slot]
            corner = (sel[:, None] * 3 + np.arange(3)[None, :]).ravel()
            local_faces = np.arange(corner.size, dtype=np.int64).reshape(-1, 3)
            if mirrored:
                local_faces = local_faces[:, [0, 2, 1]]
            meshes.append(Mesh(name=f"{obj.name}:{slot}", vertices=Pw[F[sel]].reshape(-1, 3),
                               faces=local_faces, materials=[key], material_ids=np.zeros(len(sel), np.int32),
                               normals=N[corner], emission=emissions.get(key)))
    if not meshes:
        raise SceneError("scene", "nothing to render: the scene has no visible geometry")
    world = export_world(scene.world, warnings)
    if world is not None:
        lights.append(world)
    for mesh in meshes:
        if mesh.emission is not None and mesh.occluder:
            mesh.two_sided = True      # Cycles' Emission shader emits from both faces (lamps stay one-sided)
    if not lights and not any(m.emission is not None for m in meshes):
        warnings.append("the scene has no lights, no emissive materials and a black world: the image is black")
    # Cycles picks lights by importance (its light tree); selection by power is the closest
    # convergence for many lights of different strength.
    return Scene(camera=camera, meshes=meshes, materials=materials, lights=lights, settings=settings,
                 source=f"blender:{scene.name}", light_selection="power"), warnings
