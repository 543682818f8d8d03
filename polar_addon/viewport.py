"""Rendered viewport shading: progressive refinement of the standalone engine's image.

The logic (what an edit invalidates, when to restart accumulation, how many samples are done) is
in ``ViewportSync``, which has no Blender dependency and is unit-tested.  ``ViewportSession``
adds the few Blender calls: export, one small batch per redraw, and drawing the texture.  Drawing
cannot run headless (the gpu module needs a display), so it is kept to a few lines.
"""

import numpy as np

RESTART_TYPES_GEOMETRY = {"OBJECT", "MESH", "CURVE", "SURFACE", "FONT", "META", "LIGHT", "CAMERA",
                          "COLLECTION", "SCENE"}
RESTART_TYPES_SHADING = {"MATERIAL", "NODETREE", "WORLD", "TEXTURE", "IMAGE"}


#: Samples traced per viewport redraw: the image is rendered at a reduced resolution so that one
#: refinement pass stays interactive, and drawn scaled up to the region.
VIEWPORT_PIXELS_PER_PASS = 65536


def viewport_resolution(width: int, height: int, budget: int = VIEWPORT_PIXELS_PER_PASS):
    """(w, h) of the progressive image for a region of width × height pixels (same aspect)."""
    import math
    factor = max(1, math.ceil(math.sqrt(width * height / budget)))
    return max(1, width // factor), max(1, height // factor)


class ViewportSync:
    """What to redo after edits and view changes; counts accumulated samples."""

    def __init__(self, target_samples: int = 16):
        self.target_samples = target_samples
        self.needs_export = True
        self.view_key = None
        self.samples = 0

    def on_updates(self, updates) -> bool:
        """Depsgraph updates: (id_type, is_updated_geometry, is_updated_transform, is_updated_shading) tuples.

        Returns True if accumulation must restart.  Geometry, transforms, lights, cameras and any
        shading change require a new export; a pure selection change (no flags set) does not.
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
        key = (tuple(np.round(np.asarray(view_matrix, float).ravel(), 9)),
               tuple(np.round(np.asarray(projection_matrix, float).ravel(), 9)), tuple(size))
        if key != self.view_key:
            self.view_key = key
            self.samples = 0
            return True
        return False

    def done(self) -> bool:
        return self.samples >= self.target_samples

    def add_samples(self, n: int):
        self.samples += n


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


class ViewportSession:
    """Blender side of the viewport: export on demand, one small batch per redraw, draw."""

    def __init__(self, settings_for):
        #: settings_for(scene, preview=True) → engine RenderSettings (render_engine.engine_settings,
        #: passed in so that this module does not import the render engine that owns the session)
        self.settings_for = settings_for
        self.sync_state = ViewportSync()
        self.renderer = None
        self.depsgraph_scene = None
        self.accum = None
        self.error = None

    def sync(self, depsgraph, context):
        updates = [(u.id.id_type if hasattr(u.id, "id_type") else "OBJECT", u.is_updated_geometry,
                    u.is_updated_transform, u.is_updated_shading) for u in depsgraph.updates]
        self.sync_state.on_updates(updates)
        self.sync_state.target_samples = depsgraph.scene.polar.preview_samples
        if self.sync_state.needs_export:
            from .export.scene import export_scene
            from ..engine.render.renderer import Renderer
            region = context.region
            try:
                scene, _ = export_scene(depsgraph, depsgraph.scene.camera, region.width, region.height,
                                        self.settings_for(depsgraph.scene, preview=True))
                self.renderer = Renderer(scene)
                self.error = None
            except Exception as e:  # noqa: BLE001 — shown in the viewport header instead
                self.renderer, self.error = None, str(e)
            self.sync_state.needs_export = False

    def step(self, context) -> bool:
        """Render one more sample pass for the current view; True when the target is reached."""
        if self.renderer is None:
            return True
        rv3d, region = context.region_data, context.region
        if self.sync_state.on_view(rv3d.view_matrix, rv3d.window_matrix, (region.width, region.height)):
            self.accum = None
        if self.sync_state.done():
            return True
        import copy
        scene = self.renderer.scene
        w, h = viewport_resolution(region.width, region.height)
        scene.camera = camera_from_view(rv3d.view_matrix, rv3d.window_matrix, w, h, rv3d.is_perspective)
        from ..engine.render.camera import CameraModel
        self.renderer.camera = CameraModel(scene.camera)
        settings = copy.copy(scene.settings)
        settings.spp = 1
        settings.seed = scene.settings.seed + self.sync_state.samples
        image = self.renderer.render(settings).stokes()[0]
        n = self.sync_state.samples
        self.accum = image if self.accum is None else (self.accum * n + image) / (n + 1)
        self.sync_state.add_samples(1)
        return self.sync_state.done()

    def draw(self, engine, context):
        if self.accum is None:
            return
        import gpu
        from gpu_extras.presets import draw_texture_2d
        h, w = self.accum.shape[:2]
        rgba = np.ones((h, w, 4), np.float32)
        rgba[..., :3] = self.accum[::-1]
        buffer = gpu.types.Buffer("FLOAT", w * h * 4, rgba.ravel())
        texture = gpu.types.GPUTexture((w, h), format="RGBA16F", data=buffer)
        engine.bind_display_space_shader(context.scene)
        draw_texture_2d(texture, (0, 0), context.region.width, context.region.height)
        engine.unbind_display_space_shader()
