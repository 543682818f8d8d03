"""Rendered viewport shading: a background render session, as Cycles and BlendLuxCore do it.

Three parts, only the last touches Blender's drawing API:

* :func:`classify` turns ``depsgraph.updates`` into :class:`Changes` (which objects, meshes,
  materials, lights, world changed), and :class:`IncrementalExport` keeps per-object exports and
  redoes only what a change invalidates: a moved object is re-placed from its cached local arrays
  (no ``to_mesh``), an edited mesh is re-read with ``foreach_get`` for that object only, an edited
  material is re-converted and swapped into the compiled scene without touching the BVH.
  The accelerator (``engine.render.accel.CompiledScene``, one Embree BVH over all triangles) has no
  per-mesh update, so a geometry or transform change rebuilds the BVH — from the cached world-space
  arrays, not by re-exporting the scene — and that rebuild runs on the render thread.
* :class:`ViewportSession` owns a render thread that accumulates 1-sample passes at a reduced
  resolution (:func:`viewport_resolution`) for the current view.  A view change (orbit, zoom,
  resize) only replaces the camera and restarts accumulation; a scene change restarts it with the
  new scene.  The thread polls a stop flag between samples and hands the renderer a ``should_stop``
  that the tracer polls between bounces, so Esc / leaving rendered mode stops within a batch.
* ``view_draw`` only uploads the latest accumulated image (:meth:`ViewportSession.draw`): it never
  traces.  Drawing needs a display (the gpu module refuses to run headless), so it stays a few lines.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import math
import threading
import weakref

import numpy as np

from ..engine.render.allocator import render_heap
from .ui_names import ui_message

#: Samples traced per viewport pass: the image is rendered at a reduced resolution so that one
#: refinement pass stays interactive, and drawn scaled up to the region.
VIEWPORT_PIXELS_PER_PASS = 65536
#: Seconds ``stop()`` waits for the render thread (the tracer stops between two bounces).
STOP_TIMEOUT = 5.0

#: ID types whose data an object's evaluated geometry is made of.
GEOMETRY_DATA_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META", "CURVES", "POINTCLOUD", "VOLUME"}
#: ID types that can feed any material or the world (shared node groups, textures, images).
SHARED_SHADING_TYPES = {"NODETREE", "TEXTURE", "IMAGE"}

RESTART_TYPES_GEOMETRY = {"OBJECT", "MESH", "CURVE", "SURFACE", "FONT", "META", "LIGHT", "CAMERA",
                          "COLLECTION", "SCENE"}
RESTART_TYPES_SHADING = {"MATERIAL", "NODETREE", "WORLD", "TEXTURE", "IMAGE"}

_live_sessions = weakref.WeakSet()


def viewport_resolution(width: int, height: int, budget: int = VIEWPORT_PIXELS_PER_PASS):
    """(w, h) of the progressive image for a region of width × height pixels (same aspect)."""
    factor = max(1, math.ceil(math.sqrt(width * height / budget)))
    return max(1, width // factor), max(1, height // factor)


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
    scene: bool = False              # settings, visibility, objects added or removed (IncrementalExport
    #                                  compares these itself: this flag alone restarts nothing)

    def any(self) -> bool:
        return bool(self.objects_geometry or self.objects_geometry_unconfirmed or self.objects_transform
                    or self.objects_shading
                    or self.data_geometry or self.lights_data or self.materials or self.all_materials
                    or self.world or self.scene)


def depsgraph_updates(depsgraph):
    """``depsgraph.updates`` as (id_type, name, geometry, transform, shading) tuples.

    Embedded data (a material's or world's own node tree) is left out: its owner is reported too
    (verified in bpy 5.0.1: editing a node gives MATERIAL 'Floor' and NODETREE 'Shader Nodetree')."""
    out = []
    for u in depsgraph.updates:
        id_ = u.id
        if getattr(id_, "is_embedded_data", False):
            continue
        original = getattr(id_, "original", None) or id_
        out.append((getattr(id_, "id_type", "OBJECT"), getattr(original, "name_full", getattr(id_, "name", "")),
                    bool(u.is_updated_geometry), bool(u.is_updated_transform), bool(u.is_updated_shading)))
    return out


def classify(updates) -> Changes:
    """Changes from (id_type, name, is_updated_geometry, is_updated_transform, is_updated_shading).

    An OBJECT update without flags is a selection change and invalidates nothing.  A material's own
    update re-converts that material only; a NODETREE/TEXTURE/IMAGE update (it may be a group used by
    several materials) re-converts every material and the world.  In a batch that edits a material
    (or a shared node tree) and no geometry data, OBJECT geometry flags are unconfirmed: Blender 5.3
    flags every object using the edited material so (4.5-5.2 do not), while a mesh edit flags the
    mesh data too, and a modifier edit comes without a material update.
    """
    c = Changes()
    for id_type, name, geometry, transform, shading in updates:
        if id_type == "OBJECT":
            if geometry:
                c.objects_geometry.add(name)
            if transform:
                c.objects_transform.add(name)
            if shading:
                c.objects_shading.add(name)
        elif id_type in GEOMETRY_DATA_TYPES:
            if geometry:          # a material edit also flags the mesh data, with shading only
                c.data_geometry.add(name)
        elif id_type == "LIGHT":
            c.lights_data.add(name)
        elif id_type == "MATERIAL":
            c.materials.add(name)
        elif id_type == "WORLD":
            c.world = True
        elif id_type in SHARED_SHADING_TYPES:
            c.all_materials = True
            c.world = True
        elif id_type in ("SCENE", "COLLECTION"):
            c.scene = True
    if (c.materials or c.all_materials) and not c.data_geometry:
        c.objects_geometry_unconfirmed = c.objects_geometry
        c.objects_geometry = set()
    return c


class ViewportSync:
    """View bookkeeping: restarts accumulation when the view changes; counts samples.

    ``on_updates`` is the coarse rule kept for callers that only need to know whether to restart;
    the session uses :func:`classify` and :class:`IncrementalExport` to decide what to redo.
    """

    def __init__(self, target_samples: int = 16):
        self.target_samples = target_samples
        self.needs_export = True
        self.view_key = None
        self.samples = 0

    def on_updates(self, updates) -> bool:
        """Depsgraph updates: (id_type, is_updated_geometry, is_updated_transform, is_updated_shading) tuples.

        Returns True if accumulation must restart: geometry, transforms, lights, cameras and any
        shading change do; a pure selection change (no flags set) does not.
        """
        restart = False
        for id_type, geometry, transform, shading in updates:
            if id_type in RESTART_TYPES_SHADING or (id_type in RESTART_TYPES_GEOMETRY and
                                                    (geometry or transform or shading)):
                restart = True
        if restart:
            self.needs_export = True
            self.samples = 0
        return restart

    def on_view(self, view_matrix, projection_matrix, size) -> bool:
        """A new view (orbit, zoom, resize) restarts accumulation but keeps the exported scene."""
        key = view_key(view_matrix, projection_matrix, size)
        if key != self.view_key:
            self.view_key = key
            self.samples = 0
            return True
        return False

    def done(self) -> bool:
        return self.samples >= self.target_samples

    def add_samples(self, n: int):
        self.samples += n


def view_key(view_matrix, projection_matrix, size):
    """Hashable identity of a viewport view (matrices rounded to 1e-9, region size)."""
    return (tuple(np.round(np.asarray(view_matrix, float).ravel(), 9)),
            tuple(np.round(np.asarray(projection_matrix, float).ravel(), 9)), tuple(size))


def camera_from_view(view_matrix, projection_matrix, width, height, is_perspective):
    """Engine Camera of a 3D viewport region (view and window matrices as 4×4 arrays)."""
    from ..engine.scene.description import Camera
    V = np.asarray(view_matrix, float)
    P = np.asarray(projection_matrix, float)
    inv = np.linalg.inv(V)
    origin = inv[:3, 3]
    forward = -inv[:3, 2] / np.linalg.norm(inv[:3, 2])
    up = inv[:3, 1] / np.linalg.norm(inv[:3, 1])
    cam = Camera(origin=origin, target=origin + forward, up=up, width=int(width), height=int(height))
    if is_perspective:
        cam.fov_deg = float(np.degrees(2 * np.arctan(1.0 / P[0, 0])))
    else:
        cam.projection = "orthographic"
        cam.ortho_width = float(2.0 / P[0, 0])
    return cam


# ---------------------------------------------------------------------------------- incremental export

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
    """The working state of one :meth:`IncrementalExport.sync`: what it (re)did and the scene parts it collected."""

    def __init__(self, export: IncrementalExport, full: bool, changes: Changes):
        self.export = export
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

    def material_key(self, material):
        """The key of ``material`` (None: the default), converted once; records its emission and alpha."""
        materials = self.export.materials
        name = material.name_full if material is not None else None
        if name not in materials:
            key = f"mat:{name}" if name is not None else "mat:<default>"
            bsdf, emission, alpha = self.export._material_entry(material, self.warnings)
            materials[name] = (key, bsdf, emission, alpha)
            self.counts["materials"] += 1
        key, _, emission, alpha = materials[name]
        self.emissions[key], self.alphas[key] = emission, alpha
        return key

    def material_of(self, key):
        """(emission, alpha) of the converted material ``key``; (None, 1.0) if there is none."""
        for k, _, e, a in self.export.materials.values():
            if k == key:
                return e, a
        return None, 1.0


class IncrementalExport:
    """Per-object exports of a depsgraph, redone only where :class:`Changes` says so.

    It walks ``depsgraph.object_instances`` with the same rules as ``export.scene.export_scene``
    (object types, converted curves/text, unsupported types) and places each instance with the same
    ``export.scene.object_meshes``, so the viewport shows what F12 renders.
    Caches: local triangle arrays per (object, data) (``geometry_arrays``: the to_mesh + foreach_get
    step), placed world-space engine Meshes per instance (keyed by its matrix and material slots),
    lights per instance, converted materials per name, and the world.  ``counts`` records what the
    last :meth:`sync` (re)did: "arrays" (meshes read from Blender), "placed" (instances
    transformed), "materials", "lights", "world".  The export functions are injectable so that
    the logic is testable without Blender.
    """

    def __init__(self, geometry_arrays=None, object_meshes=None, material_entry=None, export_light=None,
                 export_world=None, object_rays=None, geometry_unchanged=None):
        from .export import scene as scene_export
        from .export.lights import export_light as _light
        from .export.materials import VIEWPORT_NO_BAKE
        from .export.world import export_world as _world
        self._geometry_arrays = geometry_arrays or scene_export.geometry_arrays
        self._object_meshes = object_meshes or scene_export.object_meshes
        # (BSDF, emission, alpha) as F12 takes them (export.scene.material_entry), except that the viewport
        # does not bake linked inputs (materials.VIEWPORT_NO_BAKE says why; F12 does)
        self._material_entry = material_entry or (
            lambda m, w: scene_export.material_entry(m, w, bake=VIEWPORT_NO_BAKE))
        self._finish_scene = scene_export.finish_scene
        self._export_light = export_light or _light
        self._export_world = export_world or _world
        self._object_rays = object_rays or scene_export.object_rays
        self._attributes_outdated = scene_export.attributes_outdated
        self._geometry_unchanged = geometry_unchanged or scene_export.geometry_unchanged
        self.arrays = {}      # (object, data) name → local arrays or None
        self.placed = {}      # instance key → ((matrix bytes, slot names), [Mesh])
        self.lights = {}      # instance key → (matrix bytes, light or None)
        self.materials = {}   # material name (None = default) → (key, bsdf, emission, alpha)
        self.world = None
        self.world_name = None
        self.settings = None
        self.initialised = False
        self.counts = {}

    def sync(self, depsgraph, changes: Changes | None, settings) -> SyncResult:
        """Bring the caches up to date with ``depsgraph`` (``changes`` None: export everything)."""
        full = changes is None or not self.initialised
        run = _SyncPass(self, full, changes or Changes())
        self._reconvert_materials(run)
        self._walk_instances(depsgraph, run)
        self._drop_gone(run)
        self._sync_world(depsgraph, run)
        self._compare_settings(settings, run)
        return self._assemble(depsgraph, settings, run)

    def _reconvert_materials(self, run):
        """Drop the edited materials (all of them on a full sync); their keys go to ``run.reconverted``."""
        # An emission that changes re-places its meshes (_reuse_placed).
        for name in list(self.materials):
            if run.full or run.changes.all_materials or name in run.changes.materials:
                del self.materials[name]
                run.reconverted.add(f"mat:{name}" if name is not None else "mat:<default>")
                run.restart = True

    def _walk_instances(self, depsgraph, run):
        """Export or re-use each instance of ``depsgraph.object_instances``, as export_scene walks them."""
        from .export.scene import CONVERTED_TYPES, GEOMETRY_TYPES, UNSUPPORTED_TYPES

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
            elif obj.type in UNSUPPORTED_TYPES:
                run.warnings.append(f"object {obj.name!r}: {UNSUPPORTED_TYPES[obj.type]} are not supported; skipped")
            elif obj.type in GEOMETRY_TYPES and not (obj.type in CONVERTED_TYPES and name in meshed):
                self._sync_geometry(run, obj, M, ikey, name, view_layer)

    def _sync_light(self, run, obj, M, ikey, name):
        """Re-export a light instance that moved or changed, and collect it (an area light is a Mesh)."""
        from ..engine.scene.description import Mesh

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
        """Re-read the object's local arrays if needed, place the instance and collect its meshes."""
        data_name = obj.data.name_full if obj.data is not None else ""
        dkey = (name, obj.type, data_name)
        reread = self._needs_reread(run, obj, name, data_name, dkey)
        if reread:
            self.arrays[dkey] = self._geometry_arrays(obj)
            run.counts["arrays"] += 1
        run.seen_arrays.add(dkey)
        arrays = self.arrays[dkey]
        if arrays is None:
            return
        entry = self._place(run, obj, M, ikey, arrays, reread, view_layer)
        run.seen_placed.add(ikey)
        run.used.update(dict.fromkeys(mesh.materials[0] for mesh in entry[1]))
        run.meshes.extend(entry[1])

    def _needs_reread(self, run, obj, name, data_name, dkey):
        """Whether the (object, data) arrays ``dkey`` must be read again from Blender (once per sync)."""
        changes = run.changes
        reread = run.full or dkey not in self.arrays or (dkey not in run.seen_arrays and (
            name in changes.objects_geometry or data_name in changes.data_geometry
            or (name in changes.objects_geometry_unconfirmed
                and not self._geometry_unchanged(obj, self.arrays[dkey]))))
        if not reread and dkey not in run.seen_arrays and (changes.materials or changes.all_materials):
            reread = self._attributes_outdated(obj, self.arrays[dkey])   # a texture added or removed
        return reread

    def _place(self, run, obj, M, ikey, arrays, reread, view_layer):
        """The instance's (signature, [Mesh]) entry: placed again if its arrays or signature changed."""
        slots = [s.material for s in obj.material_slots] or [None]
        rays = self._object_rays(obj, view_layer, run.warnings)     # cheap; its flags may change unflagged
        signature = (M.tobytes(), tuple(m.name_full if m is not None else None for m in slots),
                     tuple(sorted(rays.items())))
        entry = self.placed.get(ikey)
        if reread or entry is None or entry[0] != signature:
            entry = (signature, self._object_meshes(obj.name, arrays, M, slots, run.material_key, run.emissions,
                                                    run.alphas, lambda rays=rays: rays, run.warnings))
            self.placed[ikey] = entry
            run.counts["placed"] += 1
            run.rebuild = run.restart = True
            return entry
        return self._reuse_placed(run, ikey, signature, slots, entry)

    def _reuse_placed(self, run, ikey, signature, slots, entry):
        """Keep placed meshes, refreshing emission and alpha of re-converted materials (a rebuild if they matter)."""
        for m in slots:
            run.material_key(m)
        if not any(mesh.materials[0] in run.reconverted for mesh in entry[1]):
            return entry
        fresh = [dataclasses.replace(mesh, emission=run.material_of(mesh.materials[0])[0],
                                     alpha=run.material_of(mesh.materials[0])[1]) for mesh in entry[1]]
        if any((a.emission is not None) or (b.emission is not None) or a.alpha != b.alpha
               for a, b in zip(entry[1], fresh)):
            run.rebuild = True
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

    def _assemble(self, depsgraph, settings, run) -> SyncResult:
        """The engine Scene of the collected meshes, lights and used materials, and what to redo."""
        from ..engine.errors import SceneError
        from ..engine.materials.lambert import Lambert
        from ..engine.scene.description import Camera
        from ..engine.spectral import ConstantSpectrum
        from .export.scene import BLACK

        # A SCENE/COLLECTION update by itself changes nothing the walk above has not compared
        # (objects added, removed or hidden; world; settings), e.g. editing the viewport sample count.
        restart = run.restart or run.full
        rebuild = run.rebuild or run.full
        if not run.meshes:
            raise SceneError("scene", "nothing to render: the scene has no visible geometry")
        bsdfs = {key: bsdf for key, bsdf, _, _ in self.materials.values()}
        materials = {BLACK: Lambert(ConstantSpectrum(0.0))}
        materials.update((key, bsdfs[key]) for key in run.used if key != BLACK)
        # The viewport camera replaces this placeholder (ViewportSession.set_view).
        placeholder = Camera(origin=np.zeros(3), target=np.array([0.0, 0.0, -1.0]), up=np.array([0.0, 1.0, 0.0]),
                             width=1, height=1)
        self.initialised = True
        self.counts = run.counts
        scene = self._finish_scene(placeholder, run.meshes, materials, run.lights, settings,
                                   f"blender-viewport:{depsgraph.scene.name}", run.warnings)
        return SyncResult(scene, rebuild=rebuild, restart=restart, warnings=list(dict.fromkeys(run.warnings)))


# ---------------------------------------------------------------------------------- render thread

def _default_renderer(scene):
    from ..engine.render.renderer import Renderer
    return Renderer(scene)


class ViewportSession:
    """A background render session: one thread accumulating 1-sample passes for the current view.

    The Blender-facing methods (:meth:`sync`, :meth:`draw`) run on Blender's main thread and never
    trace; the tracer runs only on ``self.thread``.  ``renderer_factory(scene)`` builds the
    renderer (BVH); it is called on the render thread so that a rebuild does not block the UI.
    """

    def __init__(self, settings_for=None, exporter: IncrementalExport | None = None,
                 renderer_factory=_default_renderer):
        #: settings_for(scene, preview=True) → engine RenderSettings (render_engine.engine_settings,
        #: passed in so that this module does not import the render engine that owns the session)
        self.settings_for = settings_for
        self.exporter = exporter
        self.renderer_factory = renderer_factory
        self.view_sync = ViewportSync()
        self._cond = threading.Condition()
        self._stop = False
        self._generation = 0       # bumped whenever accumulation must restart
        self._pending = None       # (scene, rebuild) waiting for the render thread
        self._view = None          # engine Camera at the viewport resolution
        self._settings = None
        self.target_samples = 16
        self.samples = 0
        self.image = None          # (4, h, w, 3) accumulated Stokes image
        self.version = 0           # bumped with every new image
        self.error = None
        self._texture = None       # (version, GPUTexture) of the last upload
        self.thread = threading.Thread(target=self._run, name="polar-viewport", daemon=True)
        self.thread.start()
        _live_sessions.add(self)

    # ------------------------------------------------------------------ main thread: state changes

    def update_scene(self, result: SyncResult, target_samples: int | None = None):
        """A new scene from :class:`IncrementalExport` (a restart only if something visible changed)."""
        with self._cond:
            if target_samples is not None:
                self.target_samples = int(target_samples)
            if result.restart:
                rebuild = result.rebuild or (self._pending is not None and self._pending[1])
                self._pending = (result.scene, rebuild)
                self._settings = result.scene.settings
                self.error = None
                self._restart()
            self._cond.notify_all()

    def set_view(self, camera) -> None:
        """The viewport camera (an engine Camera at the progressive resolution): restart sampling."""
        with self._cond:
            self._view = camera
            self._restart()
            self._cond.notify_all()

    def set_error(self, message):
        with self._cond:
            self.error = message
            self._restart()
            self._cond.notify_all()

    def _restart(self):
        self._generation += 1
        self.samples = 0

    def latest(self):
        """(image, samples, version): the accumulated image to draw; never traces."""
        with self._cond:
            return self.image, self.samples, self.version

    def finished(self) -> bool:
        with self._cond:
            return self.error is not None or self.samples >= self.target_samples

    def stop(self, timeout: float = STOP_TIMEOUT) -> bool:
        """Ask the render thread to stop and wait for it; True if it has ended."""
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self.thread.is_alive() and threading.current_thread() is not self.thread:
            self.thread.join(timeout)
        return not self.thread.is_alive()

    # ------------------------------------------------------------------ render thread

    def _has_work(self, renderer):
        if self._view is None or self._settings is None or self.error is not None:
            return False
        if self._pending is not None:
            return True
        return renderer is not None and self.samples < self.target_samples

    def _run(self):
        # The allocator settings of a render (engine.render.allocator.render_heap) are held while
        # samples follow each other: per 1-spp render they would hand the memory back and fault it in
        # again every sample.  Released when the session idles (converged, waiting) or stops.
        heap = contextlib.ExitStack()
        try:
            self._loop(heap)
        finally:
            heap.close()

    def _loop(self, heap):
        renderer = None
        view = None
        held = False
        while True:
            if held:
                with self._cond:
                    idle = not self._stop and not self._has_work(renderer)
                if idle:
                    heap.close()
                    held = False
            with self._cond:
                while not self._stop and not self._has_work(renderer):
                    self._cond.wait()
                if self._stop:
                    return
                generation = self._generation
                pending, self._pending = self._pending, None
                camera, settings, n = self._view, self._settings, self.samples
            if not held:
                heap.enter_context(render_heap())
                held = True
            try:
                if pending is not None:
                    scene, rebuild = pending
                    if rebuild or renderer is None or list(scene.materials) != renderer.compiled.material_names:
                        renderer = self.renderer_factory(scene)     # BVH + light set, off the UI thread
                        view = None
                    else:
                        renderer.scene = scene                       # new materials, same geometry
                        view = None
                if camera is not view:
                    from ..engine.render.camera import CameraModel
                    renderer.scene = dataclasses.replace(renderer.scene, camera=camera)
                    renderer.camera = CameraModel(camera)
                    view = camera
                st = copy.copy(settings)
                st.spp = 1
                st.seed = settings.seed + n
                out = renderer.render(st, should_stop=lambda g=generation: self._stop or self._generation != g)
            except Exception as e:  # noqa: BLE001 — shown in the viewport header instead
                with self._cond:
                    if self._generation == generation:
                        self.error = ui_message(e) if hasattr(e, "field") else f"{type(e).__name__}: {e}"
                continue
            if out.cancelled:
                continue
            image = out.stokes()
            with self._cond:
                if self._generation != generation or self.samples != n:
                    continue
                self.image = image if n == 0 or self.image is None or self.image.shape != image.shape \
                    else (self.image * n + image) / (n + 1)
                self.samples = n + 1
                self.version += 1

    # ------------------------------------------------------------------ Blender side

    def sync(self, depsgraph, context):
        """view_update: classify the depsgraph's updates and re-export only what they invalidate."""
        if self.exporter is None:
            self.exporter = IncrementalExport()
        scene = depsgraph.scene
        changes = classify(depsgraph_updates(depsgraph)) if self.exporter.initialised else None
        try:
            result = self.exporter.sync(depsgraph, changes, self.settings_for(scene, preview=True))
        except Exception as e:  # noqa: BLE001 — shown in the viewport header instead
            self.exporter = None     # start from scratch after the user fixes the scene
            self.set_error(ui_message(e))
            return
        self.update_scene(result, target_samples=scene.polar.preview_samples)

    def draw(self, engine, context) -> bool:
        """view_draw: hand the current view to the render thread and draw the latest image.

        Returns True while more samples are coming (the caller then tags a redraw)."""
        rv3d, region = context.region_data, context.region
        if self.view_sync.on_view(rv3d.view_matrix, rv3d.window_matrix, (region.width, region.height)):
            w, h = viewport_resolution(region.width, region.height)
            self.set_view(camera_from_view(rv3d.view_matrix, rv3d.window_matrix, w, h, rv3d.is_perspective))
        image, samples, version = self.latest()
        if self.error is not None:
            engine.update_stats("", f"Polar | {self.error}")
        else:
            engine.update_stats("", f"Polar | sample {samples}/{self.target_samples}")
        if image is not None:
            self._draw_image(engine, context, image, version)
        return not self.finished()

    def _draw_image(self, engine, context, image, version):
        import gpu
        from gpu_extras.presets import draw_texture_2d
        if self._texture is None or self._texture[0] != version:
            s0 = image[0]
            h, w = s0.shape[:2]
            rgba = np.ones((h, w, 4), np.float32)
            rgba[..., :3] = s0[::-1]                       # Blender's rows start at the bottom
            buffer = gpu.types.Buffer("FLOAT", w * h * 4, rgba.ravel())
            self._texture = (version, gpu.types.GPUTexture((w, h), format="RGBA16F", data=buffer))
        engine.bind_display_space_shader(context.scene)
        draw_texture_2d(self._texture[1], (0, 0), context.region.width, context.region.height)
        engine.unbind_display_space_shader()


def stop_all_sessions():
    """Stop every live viewport session (add-on unregister, file load)."""
    for session in list(_live_sessions):
        session.stop()
