"""The one walk over an evaluated depsgraph → engine Scene, for F12 and for the rendered viewport.

:class:`SceneWalk` walks ``depsgraph.object_instances`` once per sync, keeps what it exported (local
triangle arrays per object data, placed meshes per instance, converted materials, lights, the world) and
redoes only what :class:`Changes` invalidates.  F12 (:func:`export_scene`) is one full sync of a fresh walk
that bakes linked material inputs (``bake_resolution``) and has the render camera; the viewport keeps one
walk alive, syncs it with each batch of depsgraph updates and bakes nothing (``materials.VIEWPORT_NO_BAKE``
says why).  Both end in :func:`finish_scene`, where the rules for the whole scene live (two-sided emitters,
emission under layers, camera-only materials, light selection), so the viewport shows what F12 renders.
Warnings for what is approximated or skipped are collected and reported once each; real mistakes raise
SceneError naming the object.  Geometry is read by ``export.geometry``.
"""

import dataclasses

import numpy as np

from ...engine.errors import SceneError
from ...engine.materials.lambert import Lambert
from ...engine.polarisation.sources import parse_polarisation
from ...engine.scene.description import Camera, EnvironmentLight, Mesh, RenderSettings, Scene
from ...engine.spectral import ConstantSpectrum
from .. import compat
from . import geometry
from .camera import export_camera
from .geometry import CONVERTED_TYPES, GEOMETRY_TYPES, UNSUPPORTED_TYPES
from .lights import export_light as export_light_
from .materials import VIEWPORT_NO_BAKE, export_material
from .node_reader import BakeTarget
from .texture_bake import RESOLUTION_MAX, RESOLUTION_MIN
from .volumes import MIE_MODEL, volume_object, world_medium
from .world import export_world as export_world_

BLACK = "__polar_black__"


# ---------------------------------------------------------------------------------- what changed

@dataclasses.dataclass
class Changes:
    """What a batch of depsgraph updates invalidates (names are original ``name_full``)."""
    objects_geometry: set = dataclasses.field(default_factory=set)   # evaluated mesh changed
    #: objects flagged as changed geometry in a batch that edits materials: Blender 5.3 flags the
    #: objects using an edited material so; the sync re-reads them only if their geometry differs
    objects_geometry_unconfirmed: set = dataclasses.field(default_factory=set)
    objects_transform: set = dataclasses.field(default_factory=set)
    objects_shading: set = dataclasses.field(default_factory=set)    # e.g. material slots reassigned
    data_geometry: set = dataclasses.field(default_factory=set)      # mesh / curve data edited
    lights_data: set = dataclasses.field(default_factory=set)
    materials: set = dataclasses.field(default_factory=set)
    all_materials: bool = False      # a shared node group, texture or image changed
    world: bool = False
    scene: bool = False              # settings, visibility, objects added or removed (SceneWalk
    #                                  compares these itself: this flag alone restarts nothing)

    def any(self) -> bool:
        return bool(self.objects_geometry or self.objects_geometry_unconfirmed or self.objects_transform
                    or self.objects_shading
                    or self.data_geometry or self.lights_data or self.materials or self.all_materials
                    or self.world or self.scene)


# ---------------------------------------------------------------------------------- the walk

@dataclasses.dataclass
class SyncResult:
    """An assembled engine Scene and what the session must do with it."""
    scene: object
    rebuild: bool      # geometry, transforms or emitters changed: rebuild the BVH and light set
    restart: bool      # anything visible changed: restart accumulation
    warnings: list


def _instance_key(inst):
    obj = inst.object
    if not getattr(inst, "is_instance", False):
        return (obj.original.name_full,)
    parent = getattr(inst, "parent", None)
    return (parent.original.name_full if parent is not None else "", obj.original.name_full,
            tuple(getattr(inst, "persistent_id", ())))


class _SyncPass:
    """The working state of one :meth:`SceneWalk.sync`: what it (re)did and the scene parts it collected."""

    def __init__(self, walk: "SceneWalk", full: bool, changes: Changes):
        self.walk = walk
        self.full = full              # export everything
        self.changes = changes
        self.counts = {"arrays": 0, "placed": 0, "materials": 0, "lights": 0, "world": 0}
        self.warnings = []
        self.rebuild = self.restart = False
        self.reconverted = set()      # keys of the materials dropped to be converted again
        self.emissions, self.alphas = {}, {}
        self.meshes, self.lights = [], []
        self.seen_placed, self.seen_lights, self.seen_arrays = set(), set(), set()
        self.used = {}   # material keys in order of first use: stable under material edits, so that the
        #                  compiled scene's material indices stay valid and a material swap needs no rebuild

    def material_key(self, material, obj=None, M=None, uv_map=None):
        """The key of ``material`` (None: the default) on object ``obj`` (placed by ``M``, its exported UVs
        ``uv_map``), converted once; records its emission and alpha.  A material that bakes a linked input
        (F12 only) is converted once per object (the bake is on that object's UV map; instances share the
        first instance's); any other once for all objects."""
        materials = self.walk.materials
        name = material.name_full if material is not None else None
        per_object = (name, obj.name_full if obj is not None else None)
        cache_key = name if name in materials else per_object
        if cache_key not in materials:
            target = self.walk.bake_target(material, obj, M, uv_map)
            bsdf, emission, alpha = self.walk._material_entry(material, self.warnings, target)
            key = f"mat:{name}" if name is not None else "mat:<default>"
            if getattr(target, "baked", False):
                key = f"mat:{name}@{obj.name_full}"
            cache_key = per_object if getattr(target, "requested", False) else name
            materials[cache_key] = (key, bsdf, emission, alpha)
            self.walk.polarisations[key] = emission_polarisation(material) if emission is not None else None
            self.counts["materials"] += 1
        key, _, emission, alpha = materials[cache_key]
        self.emissions[key], self.alphas[key] = emission, alpha
        return key

    def material_of(self, key):
        """(emission, alpha) of the converted material ``key``; (None, 1.0) if there is none."""
        for k, _, e, a in self.walk.materials.values():
            if k == key:
                return e, a
        return None, 1.0


class SceneWalk:
    """The exports of a depsgraph's instances, kept and redone only where :class:`Changes` says so.

    ``bake_resolution``: texels of the bakes of linked material inputs (F12), or None to bake nothing (the
    viewport: linked inputs keep their own value, one warning each).  Caches: local triangle arrays per
    (object, data) (``geometry_arrays``: the to_mesh + foreach_get step), placed world-space engine Meshes per
    instance (keyed by its matrix, material slots and ray visibility), lights per instance, converted
    materials per name (per (name, object) where baked), and the world.  ``counts`` records what the last
    :meth:`sync` (re)did: "arrays" (meshes read from Blender), "placed" (instances transformed), "materials",
    "lights", "world".  The export functions are injectable so that the logic is testable without Blender
    (``material_entry(material, warnings, bake)`` → (BSDF, emission, alpha)).
    """

    def __init__(self, bake_resolution: int | None = None, geometry_arrays=None, object_meshes=None,
                 material_entry=None, export_light=None, export_world=None, object_rays=None,
                 geometry_unchanged=None, source: str = "blender"):
        self.bake_resolution = bake_resolution
        self.source = source
        self._geometry_arrays = geometry_arrays or geometry.geometry_arrays
        self._object_meshes = object_meshes or geometry.object_meshes
        self._material_entry = material_entry or _material_entry
        self._export_light = export_light or export_light_
        self._export_world = export_world or export_world_
        self._object_rays = object_rays or geometry.object_rays
        self._attributes_outdated = geometry.attributes_outdated
        self._geometry_unchanged = geometry_unchanged or geometry.geometry_unchanged
        self.arrays = {}      # (object, data) name → local arrays or None
        self.placed = {}      # instance key → ((matrix bytes, slot names, rays), [Mesh])
        self.lights = {}      # instance key → (matrix bytes, light or None)
        self.materials = {}   # material name (None: the default) or, baked, (name, object) → (key, bsdf, emission,
        #                       alpha)
        self.polarisations = {}   # material key → its emission's SourcePolarisation (None: unpolarised)
        self.world = None
        self.world_name = None
        self.world_medium = None      # the World Output ▸ Volume medium (engine Interior) or None
        self.settings = None
        self.initialised = False
        self.counts = {}

    def bake_target(self, material, obj, M, uv_map):
        """What ``export_material`` bakes linked inputs on: nothing in the viewport (VIEWPORT_NO_BAKE), the
        object's UV map at ``bake_resolution`` texels for F12 (None for the default material)."""
        if self.bake_resolution is None:
            return VIEWPORT_NO_BAKE
        if obj is None or material is None:
            return None
        return BakeTarget(obj, M, material, self.bake_resolution, uv_map)

    def sync(self, depsgraph, changes: Changes | None, settings, camera=None) -> SyncResult:
        """Bring the caches up to date with ``depsgraph`` (``changes`` None: export everything) and assemble
        the Scene (``camera`` None: a placeholder the viewport replaces with its view)."""
        full = changes is None or not self.initialised
        run = _SyncPass(self, full, changes or Changes())
        # Render Properties ▸ Volumes ▸ Mie: Cycles' fit or exact Lorenz–Mie (export.volumes)
        mie = getattr(getattr(depsgraph.scene, "polar", None), "volume_mie", "CYCLES")
        token = MIE_MODEL.set("lorenz_mie" if mie == "LORENZ_MIE" else "cycles_mie")
        try:
            return self._sync(depsgraph, run, settings, camera)
        finally:
            MIE_MODEL.reset(token)

    def _sync(self, depsgraph, run, settings, camera) -> SyncResult:
        self._reconvert_materials(run)
        self._walk_instances(depsgraph, run)
        self._drop_gone(run)
        self._sync_world(depsgraph, run)
        self._compare_settings(settings, run)
        return self._assemble(depsgraph, settings, run, camera)

    def _reconvert_materials(self, run):
        """Drop the edited materials (all of them on a full sync); their keys go to ``run.reconverted``."""
        # An emission that changes re-places its meshes (_reuse_placed).
        for cache_key, entry in list(self.materials.items()):
            name = cache_key[0] if isinstance(cache_key, tuple) else cache_key
            if run.full or run.changes.all_materials or name in run.changes.materials:
                del self.materials[cache_key]
                run.reconverted.add(entry[0])
                run.restart = True

    def _walk_instances(self, depsgraph, run):
        """Export or re-use each instance of ``depsgraph.object_instances``.

        Text, metaballs, surfaces and bevelled curves come twice (also inside collection instances): as
        themselves and as a mesh instance of their evaluated mesh (what Cycles renders); the latter is taken."""
        view_layer = getattr(depsgraph, "view_layer", None)
        meshed = {inst.object.original.name_full for inst in depsgraph.object_instances
                  if inst.object.type == "MESH" and inst.object.original.type in CONVERTED_TYPES}
        for inst in depsgraph.object_instances:
            obj = inst.object
            M = np.array(inst.matrix_world, dtype=np.float64)
            ikey = _instance_key(inst)
            name = obj.original.name_full
            if obj.type == "LIGHT":
                self._sync_light(run, obj, M, ikey, name)
            elif obj.type == "VOLUME":
                self._sync_volume(run, obj, M, ikey, name)
            elif obj.type in UNSUPPORTED_TYPES:
                run.warnings.append(f"object {obj.name!r}: {UNSUPPORTED_TYPES[obj.type]} are not supported; skipped")
            elif obj.type in GEOMETRY_TYPES and not (obj.type in CONVERTED_TYPES and name in meshed):
                if self._sync_geometry(run, obj, M, ikey, name, view_layer) is None and obj.type == "CURVE" \
                        and getattr(inst, "is_instance", False):
                    owner = inst.parent.name if getattr(inst, "parent", None) is not None else obj.name
                    run.warnings.append(f"object {owner!r}: geometry-nodes curves without a mesh are not rendered "
                                        "(nor by Cycles): convert them with Curve to Mesh")

    def _sync_light(self, run, obj, M, ikey, name):
        """Re-export a light instance that moved or changed, and collect it (an area light is a Mesh)."""
        changes = run.changes
        data_name = obj.data.name_full if obj.data is not None else ""
        entry = self.lights.get(ikey)
        if (run.full or entry is None or entry[0] != M.tobytes() or data_name in changes.lights_data
                or name in changes.objects_shading or name in changes.objects_geometry):
            entry = (M.tobytes(), self._export_light(obj, M, run.warnings))
            self.lights[ikey] = entry
            run.counts["lights"] += 1
            run.rebuild = run.restart = True
        run.seen_lights.add(ikey)
        light = entry[1]
        if isinstance(light, Mesh):
            run.meshes.append(light)
        elif light is not None:
            run.lights.append(light)

    def _sync_geometry(self, run, obj, M, ikey, name, view_layer):
        """Re-read the object's local arrays if needed, place the instance and collect its meshes; returns
        the arrays (None: the object has no renderable geometry)."""
        data_name = obj.data.name_full if obj.data is not None else ""
        dkey = (name, obj.type, data_name)
        reread = self._needs_reread(run, obj, name, data_name, dkey)
        if reread:
            self.arrays[dkey] = self._geometry_arrays(obj)
            run.counts["arrays"] += 1
        run.seen_arrays.add(dkey)
        arrays = self.arrays[dkey]
        if arrays is None:
            return None
        entry = self._place(run, obj, M, ikey, arrays, reread, view_layer)
        run.seen_placed.add(ikey)
        run.used.update(dict.fromkeys(mesh.materials[0] for mesh in entry[1]))
        run.meshes.extend(entry[1])
        return arrays

    def _sync_volume(self, run, obj, M, ikey, name):
        """A Volume object: a transparent box around its OpenVDB grid whose interior is its material's medium with
        that grid's density (export.volumes.volume_object); read again when the object, its material, its file
        or the frame's file changed."""
        material = next((s.material for s in obj.material_slots if s.material is not None), None)
        changes = run.changes
        signature = (M.tobytes(), material.name_full if material is not None else None, compat.volume_file(obj))
        entry = self.placed.get(ikey)
        if (run.full or entry is None or entry[0] != signature or name in changes.objects_geometry
                or changes.all_materials or (material is not None and material.name_full in changes.materials)):
            made = volume_object(obj, M, material, run.warnings) if material is not None else None
            if made is None and material is None:
                run.warnings.append(f"Volume object {obj.name!r} has no material (Cycles renders it with a "
                                    "Principled Volume); skipped")
            meshes = []
            if made is not None:
                mesh, interior = made
                key = f"{material.name} ({obj.name} volume)"
                bsdf = Lambert(ConstantSpectrum(0.0))
                bsdf.interior = interior
                self.materials[("__volume__", ikey)] = (key, bsdf, None, 0.0)
                mesh.materials, mesh.alpha = [key], 0.0
                meshes = [mesh]
            entry = (signature, meshes)
            self.placed[ikey] = entry
            run.counts["placed"] += 1
            run.rebuild = run.restart = True
        run.seen_placed.add(ikey)
        run.used.update(dict.fromkeys(mesh.materials[0] for mesh in entry[1]))
        run.meshes.extend(entry[1])

    def _needs_reread(self, run, obj, name, data_name, dkey):
        """Whether the (object, data) arrays ``dkey`` must be read again from Blender (at most once per sync:
        instances of one object share its arrays)."""
        if dkey in run.seen_arrays:
            return False
        changes = run.changes
        reread = run.full or dkey not in self.arrays or (
            name in changes.objects_geometry or data_name in changes.data_geometry
            or (name in changes.objects_geometry_unconfirmed
                and not self._geometry_unchanged(obj, self.arrays[dkey])))
        if not reread and (changes.materials or changes.all_materials):
            reread = self._attributes_outdated(obj, self.arrays[dkey])   # a texture added or removed
        return reread

    def _place(self, run, obj, M, ikey, arrays, reread, view_layer):
        """The instance's (signature, [Mesh]) entry: placed again if its arrays or signature changed."""
        slots = [s.material for s in obj.material_slots] or [None]
        rays = self._object_rays(obj, view_layer, run.warnings)     # cheap; its flags may change unflagged
        signature = (M.tobytes(), tuple(m.name_full if m is not None else None for m in slots),
                     tuple(sorted(rays.items())))
        uv_map = arrays[4]["uv_map"] if len(arrays) > 4 else None       # baked inputs: on the exported UVs

        def material_key(m):
            return run.material_key(m, obj, M, uv_map)

        entry = self.placed.get(ikey)
        if reread or entry is None or entry[0] != signature:
            entry = (signature, self._object_meshes(obj.name, arrays, M, slots, material_key, run.emissions,
                                                    run.alphas, lambda rays=rays: rays, run.warnings))
            self._polarise_emitters(entry[1], M)
            self.placed[ikey] = entry
            run.counts["placed"] += 1
            run.rebuild = run.restart = True
            return entry
        return self._reuse_placed(run, ikey, signature, slots, entry, material_key, M)

    def _polarise_emitters(self, meshes, M):
        """Give the emissive meshes of an instance (placed by ``M``) their material's emission polarisation
        (Material ▸ Emission Polarisation); reference axis: the UV map's U direction where the mesh has UVs
        (engine.polarisation.sources.uv_tangent), else the object's local X."""
        for mesh in meshes:
            pol = self.polarisations.get(mesh.materials[0]) if mesh.emission is not None else None
            if pol is not None:
                mesh.emission_polarisation = pol
                mesh.emission_axis = None if mesh.uv is not None else M[:3, 0] / np.linalg.norm(M[:3, 0])

    def _reuse_placed(self, run, ikey, signature, slots, entry, material_key, M):
        """Keep placed meshes, refreshing emission and alpha of re-converted materials (a rebuild if they matter)."""
        for m in slots:
            material_key(m)
        if not any(mesh.materials[0] in run.reconverted for mesh in entry[1]):
            return entry
        fresh = [dataclasses.replace(mesh, emission=run.material_of(mesh.materials[0])[0],
                                     alpha=run.material_of(mesh.materials[0])[1]) for mesh in entry[1]]
        if any((a.emission is not None) or (b.emission is not None) or a.alpha != b.alpha
               for a, b in zip(entry[1], fresh)):
            run.rebuild = True
        self._polarise_emitters(fresh, M)
        entry = (signature, fresh)
        self.placed[ikey] = entry
        return entry

    def _drop_gone(self, run):
        """Forget objects that disappeared (deleted, hidden, moved out of the view layer)."""
        for cache, seen in ((self.placed, run.seen_placed), (self.lights, run.seen_lights),
                            (self.arrays, run.seen_arrays)):
            gone = set(cache) - seen
            if gone and cache is not self.arrays:
                run.rebuild = run.restart = True
            for k in gone:
                del cache[k]

    def _sync_world(self, depsgraph, run):
        """Re-export the world if it changed or was swapped, and collect it with the lights."""
        scene_world = depsgraph.scene.world
        world_name = scene_world.name_full if scene_world is not None else None
        if run.full or run.changes.world or world_name != self.world_name:
            self.world = self._export_world(scene_world, run.warnings)
            self.world_medium = world_medium(scene_world, run.warnings)
            self.world_name = world_name
            run.counts["world"] += 1
            run.restart = True
        if self.world is not None:
            run.lights.append(self.world)

    def _compare_settings(self, settings, run):
        """Restart if the settings changed; the viewport sample count only sets how far accumulation goes."""
        comparable = dataclasses.replace(settings, spp=0) if dataclasses.is_dataclass(settings) else settings
        if comparable != self.settings:
            self.settings = comparable
            run.restart = True

    def _assemble(self, depsgraph, settings, run, camera) -> SyncResult:
        """The engine Scene of the collected meshes, lights and used materials, and what to redo."""
        # A SCENE/COLLECTION update by itself changes nothing the walk above has not compared
        # (objects added, removed or hidden; world; settings), e.g. editing the viewport sample count.
        restart = run.restart or run.full
        rebuild = run.rebuild or run.full
        bsdfs = {key: bsdf for key, bsdf, _, _ in self.materials.values()}
        materials = {BLACK: Lambert(ConstantSpectrum(0.0))}
        materials.update((key, bsdfs[key]) for key in run.used if key != BLACK)
        if camera is None:      # the viewport camera replaces this placeholder (ViewportSession.set_view)
            camera = Camera(origin=np.zeros(3), target=np.array([0.0, 0.0, -1.0]), up=np.array([0.0, 1.0, 0.0]),
                            width=1, height=1)
        self.initialised = True
        self.counts = run.counts
        scene = finish_scene(camera, run.meshes, materials, run.lights, settings,
                             f"{self.source}:{depsgraph.scene.name}", run.warnings, medium=self.world_medium)
        return SyncResult(scene, rebuild=rebuild, restart=restart, warnings=list(dict.fromkeys(run.warnings)))


def export_scene(depsgraph, camera_object, width, height, settings: RenderSettings):
    """(engine Scene, list of warnings) of an evaluated depsgraph, as F12 renders it: one full sync of a fresh
    :class:`SceneWalk` that bakes linked material inputs at the scene's Texture Bake Resolution."""
    scene = depsgraph.scene
    resolution = int(getattr(getattr(scene, "polar", None), "texture_bake_resolution", 512))
    if not RESOLUTION_MIN <= resolution <= RESOLUTION_MAX:
        raise SceneError("render settings", f"Texture Bake Resolution must be in [{RESOLUTION_MIN}, {RESOLUTION_MAX}], "
                                            f"got {resolution}")
    warnings = []
    camera = export_camera(scene, camera_object, width, height, warnings)
    result = SceneWalk(bake_resolution=resolution).sync(depsgraph, None, settings, camera=camera)
    view_layer_warnings(getattr(depsgraph, "view_layer", None), warnings)
    return result.scene, list(dict.fromkeys(warnings + result.warnings))


def view_layer_warnings(view_layer, warnings) -> None:
    """One warning each for the View Layer passes Polar does not write: its Shader AOVs and its Light Groups (the
    lights of a group still light the Combined and Stokes passes; no per-group pass is written)."""
    if view_layer is None:
        return
    layer = getattr(view_layer, "name", "")
    aovs = [a.name for a in getattr(view_layer, "aovs", ()) if a.name]
    if aovs:
        warnings.append(f"view layer {layer!r}: Shader AOV {', '.join(repr(a) for a in aovs)} not written (Polar "
                        "renders no shader AOVs)")
    groups = [g.name for g in getattr(view_layer, "lightgroups", ()) if g.name]
    if groups:
        warnings.append(f"view layer {layer!r}: Light Group {', '.join(repr(g) for g in groups)} not written (no "
                        "per-group passes; their lights light the Combined and Stokes passes as usual)")


def _material_entry(material, warnings, bake=None):
    return material_entry(material, warnings, bake)


def emission_polarisation(material):
    """The SourcePolarisation of a Blender material's emission (Material ▸ Emission Polarisation), None when
    unpolarised or without the setting."""
    settings = getattr(material, "polar", None) if material is not None else None
    described = settings.engine_dict() if settings is not None and hasattr(settings, "engine_dict") else None
    if described is None:
        return None
    return parse_polarisation(described, f"material {material.name!r} emission polarisation")[0]


def material_entry(material, warnings, bake=None):
    """(BSDF, emission, alpha) of a Blender material as every walk over the scene takes it (F12, the viewport):
    ``export_material``'s BSDF and emission, and the object alpha — Principled Alpha × a Mix Shader's
    transparency (``alpha_factor``)."""
    bsdf, emission = export_material(material, warnings, bake=bake)
    alpha = geometry.times_alpha(geometry.material_alpha(material, warnings), getattr(bsdf, "alpha_factor", 1.0),
                                 material, warnings)
    return bsdf, emission, alpha


def light_selection(settings: RenderSettings) -> str:
    """Scene.light_selection for a Blender scene: Cycles' Light Tree off (RenderSettings.light_tree "off",
    polar_addon.render_engine.engine_settings) → "cycles", the engine's choice as Cycles makes it without its tree;
    on → "power" (unused by F12, which then chooses with the tree, light_tree "on"; what the exported scene chooses
    with where it is rendered with light_tree "auto" and few lights)."""
    return "cycles" if settings.light_tree == "off" else "power"


def finish_scene(camera, meshes, materials, lights, settings, source, warnings, medium=None) -> Scene:
    """The engine Scene of a walk over a Blender scene (F12's ``export_scene`` and the viewport's
    ``SceneWalk.sync`` both end here, so that the viewport shows what F12 renders): the rules that
    hold for the whole scene — emissive meshes emit from both faces (Cycles' Emission shader; lamps stay
    one-sided), a Principled emission lies under its sheen and coat, a material seen by camera rays only
    (Light Path ▸ Is Camera Ray) is transparent to every other ray, lights are picked as Cycles' Light Tree switch
    says (``light_selection``) — and the warning for a black scene.
    A scene without geometry renders as Cycles renders it: the world (an HDRI or sky preview), lamps the camera
    sees, and black where neither is.  ``medium``: the world medium (World Output ▸ Volume), or None.
    Meshes are updated in place (the viewport's cached ones too: the rules are idempotent)."""
    for mesh in meshes:
        material = materials.get(mesh.materials[0])
        if mesh.emission is not None and mesh.occluder:
            mesh.two_sided = True
        if mesh.emission is not None and getattr(material, "emission_under_layers", False):
            mesh.emission_under_layers = True
        if getattr(material, "camera_only", False):
            mesh.visible_shadow = mesh.visible_indirect = False
    world = any(isinstance(light, EnvironmentLight) for light in lights)
    if not any(m.occluder or m.emission is None for m in meshes) and not world:
        warnings.append("the scene has no visible geometry and a black world: the image is black"
                        + (" but for the lamps the camera sees" if lights or meshes else ""))
    elif not lights and not any(m.emission is not None for m in meshes):
        warnings.append("the scene has no lights, no emissive materials and a black world: the image is black")
    return Scene(camera=camera, meshes=meshes, materials=materials, lights=lights, settings=settings, source=source,
                 light_selection=light_selection(settings), medium=medium)
