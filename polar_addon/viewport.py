"""Rendered viewport shading: a background render session, as Cycles and BlendLuxCore do it.

Three parts, only the last touches Blender's drawing API:

* :func:`classify` turns ``depsgraph.updates`` into :class:`Changes` (which objects, meshes,
  materials, lights, world changed), and the scene walk (``export.scene.SceneWalk``) keeps per-object exports and
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
import dataclasses
import math
import threading
import weakref

import numpy as np

from ..engine.render.allocator import render_heap
from .export.scene import Changes, SceneWalk, SyncResult  # noqa: F401  (SyncResult: the sessions' input)
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
    the session uses :func:`classify` and :class:`SceneWalk` to decide what to redo.
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

    def __init__(self, settings_for=None, exporter: SceneWalk | None = None,
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
        """A new scene from :class:`SceneWalk` (a restart only if something visible changed)."""
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
                    renderer.set_camera(camera)
                    view = camera
                from ..engine.render.renderer import RenderRequest
                # threads: a 1-sample pass per redraw, and every camera move would send and compile the scene
                # in each worker process again (engine.render.processes)
                out = renderer.render(RenderRequest(dataclasses.replace(settings, spp=1, seed=settings.seed + n,
                                                                        parallel="threads"),
                                                    should_stop=lambda g=generation: self._stop
                                                    or self._generation != g))
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
            self.exporter = SceneWalk(source="blender-viewport")
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
