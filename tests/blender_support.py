"""Helpers for tests that drive Blender through the bpy module (pip package ``bpy``).

The add-on is loaded the way Blender loads the extension: the repository root as a package
(``polar_render``) whose ``register()`` forwards to ``polar_addon``.
"""

import atexit
import importlib.util
import math
import os
import sys

from tests.conftest import REPO

PACKAGE = "polar_render"


def load_addon():
    """Import the repository as the extension package and register it (once per process; it is
    unregistered at exit, without which a Blender 4.5 process hangs there)."""
    import bpy  # noqa: F401
    if PACKAGE in sys.modules:
        return sys.modules[PACKAGE]
    spec = importlib.util.spec_from_file_location(PACKAGE, os.path.join(REPO, "__init__.py"),
                                                  submodule_search_locations=[REPO])
    module = importlib.util.module_from_spec(spec)
    sys.modules[PACKAGE] = module
    spec.loader.exec_module(module)
    module.register()
    atexit.register(module.unregister)
    return module


def empty_scene(width=48, height=36, samples=4):
    import bpy
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "POLAR"
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.polar.samples = samples
    scene.polar.max_bounces = 7
    light_paths_off(scene)
    load_addon().polar_addon.compat.set_multilayer_exr(scene.render.image_settings)
    return scene


def light_paths_off(scene, bounces=1024):
    """Cycles' Light Paths as the tests keep them, read by both renderers (Polar reads them too:
    polar_addon.render_engine.cycles_light_paths): ``bounces`` as the total and every kind's limit (1024: none),
    no clamping, no Filter Glossy, both caustics on."""
    c = scene.cycles
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = bounces
    c.transparent_max_bounces = bounces
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.caustics_reflective = c.caustics_refractive = True


def add_camera(scene, location, rotation, lens=50.0):
    import bpy
    data = bpy.data.cameras.new("Camera")
    data.lens = lens
    cam = bpy.data.objects.new("Camera", data)
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = location, rotation
    scene.camera = cam
    return cam


def brewster_camera(scene, distance=10.0, lens=50.0):
    th = math.atan(1.5)
    return add_camera(scene, (0.0, -distance * math.sin(th), distance * math.cos(th)), (th, 0.0, 0.0), lens)


def white_world(scene, strength=1.0):
    import bpy
    world = bpy.data.worlds.new("World")
    scene.world = world
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bg.inputs["Strength"].default_value = strength
    return world


def polar_material(name, model, **inputs):
    """A material whose Surface is a Polarising BSDF of ``model`` with the given input values."""
    return load_addon().polar_addon.nodes.bsdf.polarising_material(name, model, **inputs)[0]


def add_plane(size, material=None, location=(0, 0, 0)):
    import bpy
    bpy.ops.mesh.primitive_plane_add(size=size, location=location)
    obj = bpy.context.object
    if material is not None:
        obj.data.materials.append(material)
    return obj


def add_sphere(radius, location, material=None, smooth=True):
    import bpy
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=location, segments=48, ring_count=24)
    obj = bpy.context.object
    if smooth:
        bpy.ops.object.shade_smooth()
    if material is not None:
        obj.data.materials.append(material)
    return obj


def read_multilayer(path, layer="ViewLayer"):
    """{pass: (H, W, C) array} from a Blender multilayer EXR (row 0 = top of the image)."""
    import numpy as np
    import OpenEXR
    with OpenEXR.File(path, separate_channels=True) as f:
        chans = {n: np.array(c.pixels) for p in f.parts for n, c in p.channels.items()}
    passes = {}
    for name, pixels in chans.items():
        parts = name.split(".")
        if len(parts) != 3 or parts[0] != layer:
            continue
        passes.setdefault(parts[1], {})[parts[2]] = pixels
    order = {"R": 0, "G": 1, "B": 2, "A": 3, "X": 0}
    return {p: np.stack([c[k] for k in sorted(c, key=lambda k: order.get(k, 9))], axis=-1)
            for p, c in passes.items()}


def render_to_exr(scene, path):
    import bpy
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    return path + ".exr" if not path.endswith(".exr") else path


def cycles_seed_renders(scene, tmp, spp, seeds, bounces, light_threshold=None):
    """(seeds, H, W, 3) linear RGB of Cycles' Combined pass, one render per seed 0, 1, …, with the parity
    settings the Cycles comparisons share: CPU, no adaptive sampling, no denoising, box filter 1 px, no
    clamping, no Filter Glossy, ``bounces`` as Max and every kind's bounces (Transparent kept), 2 threads, a
    32-bit multilayer EXR per seed in ``tmp``; ``light_threshold``: Cycles' Light Threshold, if given (0: every
    light sampled)."""
    import bpy
    import numpy as np
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device, c.samples, c.use_adaptive_sampling, c.use_denoising = "CPU", spp, False, False
    c.pixel_filter_type, c.filter_width = "BOX", 1.0
    if light_threshold is not None:
        c.light_sampling_threshold = light_threshold
    transparent = c.transparent_max_bounces
    light_paths_off(scene, bounces)            # no clamping, no Filter Glossy, caustics on; Max/Diffuse = bounces
    c.transparent_max_bounces = transparent
    scene.render.threads_mode, scene.render.threads = "FIXED", 2
    load_addon().polar_addon.compat.set_multilayer_exr(scene.render.image_settings)
    scene.render.image_settings.color_depth = "32"
    out = []
    for seed in range(seeds):
        c.seed = seed
        scene.render.filepath = os.path.join(tmp, f"cycles_{seed}")
        bpy.ops.render.render(write_still=True)
        out.append(read_multilayer(scene.render.filepath + ".exr")["Combined"][..., :3])
    return np.array(out)



def drawn_properties(panel_class, scene) -> list:
    """(data, property name) of every property ``panel_class.draw`` puts in its layout for ``scene`` (headless
    Blender has no window: a recording layout stands in)."""
    class Layout:
        def __init__(self, drawn):
            self.drawn, self.use_property_split, self.active, self.enabled = drawn, False, True, True

        def column(self, **_):
            return Layout(self.drawn)

        row = column

        def prop(self, data, name, **_):
            self.drawn.append((data, name))

        def operator(self, *_, **__):
            pass

        def label(self, **_):
            pass

        def separator(self, **_):
            pass

    drawn = []
    panel_class.draw(type("P", (), {"layout": Layout(drawn)})(), type("C", (), {"scene": scene})())
    return drawn
