"""An ordinary Blender scene rendered by Cycles and by Polar: Cycles | Polar S0 | Polar DoLP.

    python examples/cycles_side_by_side.py [--out examples/images/cycles_side_by_side.png]
                                           [--width 320] [--height 200] [--samples 128]

Built with plain Blender objects and Principled BSDFs, as an artist would (no Polarising BSDF
node): a grey floor, a red plastic ball (Principled, roughness 0.2), a gold ball (Principled
metallic), a white box, an area light, a sun with a 5° angle, a point light with a radius and a
dim sky.  The same .blend is rendered with Cycles (bpy ships it) and with Polar through the
extension's exporter, as F12 does.  Cycles' pixel filter is a box of one pixel, like Polar's.
The S0 columns should look alike (Polar's S0 is Cycles' image where nothing polarises; the
plastic and gold are modelled by Polar's polarising models, so their highlights may differ);
DoLP shows what Cycles cannot: the degree of linear polarisation of the plastic's and the
floor's reflections.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)


def _compat():
    """The add-on's Blender-version helpers (polar_addon.compat)."""
    from tests.blender_support import load_addon
    return load_addon().polar_addon.compat


def principled(bpy, name, colour, roughness=0.5, metallic=0.0):
    mat = bpy.data.materials.new(name)
    node = _compat().ensure_node_tree(mat).nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (*colour, 1.0)
    node.inputs["Roughness"].default_value = roughness
    node.inputs["Metallic"].default_value = metallic
    return mat


def build(bpy, width, height):
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    bpy.ops.mesh.primitive_plane_add(size=20)
    bpy.context.object.data.materials.append(principled(bpy, "Floor", (0.5, 0.5, 0.5), roughness=0.35))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.6, location=(-0.9, 0.3, 0.6), segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(principled(bpy, "Red plastic", (0.6, 0.05, 0.04), roughness=0.2))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(0.5, -0.4, 0.5), segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(principled(bpy, "Gold", (1.0, 0.77, 0.34), roughness=0.25,
                                                        metallic=1.0))
    bpy.ops.mesh.primitive_cube_add(size=0.8, location=(1.4, 1.0, 0.4), rotation=(0, 0, math.radians(25)))
    bpy.context.object.data.materials.append(principled(bpy, "White", (0.8, 0.8, 0.8), roughness=0.8))
    bpy.ops.object.light_add(type="AREA", location=(-2.0, -1.5, 3.0), rotation=(math.radians(35), math.radians(-30), 0))
    bpy.context.object.data.energy, bpy.context.object.data.size = 300.0, 1.5
    bpy.ops.object.light_add(type="SUN", rotation=(math.radians(50), 0.0, math.radians(40)))
    bpy.context.object.data.energy, bpy.context.object.data.angle = 2.0, math.radians(5)
    bpy.ops.object.light_add(type="POINT", location=(1.5, -2.0, 1.5))
    bpy.context.object.data.energy, bpy.context.object.data.shadow_soft_size = 80.0, 0.3
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = 35
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (0.0, -6.0, 2.4), (math.radians(72), 0.0, 0.0)
    scene.camera = cam
    world = bpy.data.worlds.new("World")
    scene.world = world
    bg = _compat().ensure_node_tree(world).nodes["Background"]
    bg.inputs["Color"].default_value = (0.55, 0.7, 1.0, 1.0)
    bg.inputs["Strength"].default_value = 0.3
    return scene


def render_cycles(bpy, scene, samples, tmp):
    from tests.blender_support import read_multilayer
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device, c.samples, c.use_denoising, c.use_adaptive_sampling = "CPU", samples, False, False
    c.pixel_filter_type, c.filter_width = "BOX", 1.0
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = 6
    _compat().set_multilayer_exr(scene.render.image_settings)
    scene.render.filepath = os.path.join(tmp, "cycles")
    bpy.ops.render.render(write_still=True)
    return read_multilayer(scene.render.filepath + ".exr")["Combined"][..., :3]


def render_polar(bpy, scene, samples, width, height):
    from polar_render.engine.render.renderer import Renderer
    from polar_render.engine.scene.description import RenderSettings
    from polar_render.polar_addon.export.scene import export_scene
    depsgraph = bpy.context.evaluated_depsgraph_get()
    settings = RenderSettings(spp=samples, max_depth=8, seed=1)         # Cycles bounces + 2 segments
    engine_scene, warnings = export_scene(depsgraph, scene.camera, width, height, settings)
    for w in warnings:
        print("polar warning:", w)
    return Renderer(engine_scene).render(settings).stokes()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(REPO, "examples", "images", "cycles_side_by_side.png"))
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=200)
    ap.add_argument("--samples", type=int, default=128)
    a = ap.parse_args(argv)
    import bpy

    from engine.output.colormaps import sequential, tonemap
    from engine.output.png import write_png
    from engine.postprocess.sheets import contact_sheet
    from engine.polarisation.stokes import degree_of_linear_polarisation as dolp
    from tests.blender_support import load_addon
    load_addon()
    scene = build(bpy, a.width, a.height)
    with tempfile.TemporaryDirectory() as tmp:
        cycles = render_cycles(bpy, scene, a.samples, tmp)
    stokes = render_polar(bpy, scene, a.samples, a.width, a.height)
    y = stokes @ np.array([0.2126, 0.7152, 0.0722])
    d = dolp(y)
    ratio = float(np.mean(stokes[0] @ np.array([0.2126, 0.7152, 0.0722])) / np.mean(cycles @ np.array(
        [0.2126, 0.7152, 0.0722])))
    print(f"mean luminance Polar S0 / Cycles = {ratio:.4f}")
    sheet = contact_sheet([tonemap(cycles), tonemap(stokes[0]), sequential(np.nan_to_num(d))],
                          columns=3)   # left to right: Cycles, Polar S0, Polar DoLP (0 purple … 1 yellow)
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    write_png(a.out, sheet)
    print(a.out)


if __name__ == "__main__":
    main()
