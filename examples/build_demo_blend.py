"""Build the thesis demo scene as a .blend and render it in batch.

    python examples/build_demo_blend.py [--blend out/polar_demo.blend] [--render] [--samples 16]

Four spheres, one per polarising model — Fresnel gold, Torrance–Sparrow gold, HTSG aluminium and a
Weidlich–Wilkie glass coat over red Lambert — on a perfectly smooth black-glass floor under a
uniform white sky (the thesis's Chapter 6 set-up).  HTSG uses physical roughness values
(σ₀ = 0.18 µm, τ = 3 µm), not the thesis's implausible σ₀ = 20 µm, τ = 0.2 µm.
With --render the file is rendered through examples/batch_render.py.
"""

import argparse
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

from batch_render import enable_polar  # noqa: E402


def build(path, samples, addon):
    """Build and save the demo scene; ``addon`` is the extension's polar_addon package."""
    import bpy
    bsdf, compat = addon.nodes.bsdf, addon.compat
    material = bsdf.polarising_material
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "POLAR"
    scene.render.resolution_x, scene.render.resolution_y = 640, 240
    scene.polar.samples = samples
    floor_mat, _ = material("Black glass", "BLACK_GLASS", IOR=1.5)
    bpy.ops.mesh.primitive_plane_add(size=200)
    bpy.context.object.name = "Floor"
    bpy.context.object.data.materials.append(floor_mat)
    red, _ = material("Red Lambert", "LAMBERT", Albedo=(0.7, 0.05, 0.04, 1.0))
    coat, coat_node = material("WW glass coat over red", "WEIDLICH_WILKIE", **{"Coat IOR": 1.5,
                                                                             "Coat Roughness": 0.1})
    base = bsdf.new_polarising_bsdf(coat.node_tree, "LAMBERT", Albedo=(0.7, 0.05, 0.04, 1.0))
    coat.node_tree.links.new(base.outputs[0], coat_node.inputs["Base"])
    spheres = [("Fresnel gold", material("Fresnel gold", "CONDUCTOR", metal="Au")[0]),
               ("TS gold", material("TS gold", "TORRANCE_SPARROW", metal="Au", Roughness=0.15)[0]),
               ("HTSG aluminium", material("HTSG aluminium", "HTSG", metal="Al", Sigma0=0.18, Tau=3.0)[0]),
               ("WW coat", coat)]
    for i, (name, mat) in enumerate(spheres):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(-3.3 + 2.2 * i, 0.0, 1.0), segments=96,
                                             ring_count=48)
        bpy.ops.object.shade_smooth()
        bpy.context.object.name = name
        bpy.context.object.data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location = (0.0, -12.0, 4.0)
    cam.rotation_euler = (math.radians(75.0), 0.0, 0.0)
    cam.data.lens = 40
    scene.camera = cam
    world = bpy.data.worlds.new("Sky")
    compat.ensure_node_tree(world).nodes["Background"].inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    scene.world = world
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(path))
    return path


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--blend", default="out/polar_demo.blend")
    ap.add_argument("--render", action="store_true")
    ap.add_argument("--samples", type=int, default=16)
    ap.add_argument("--output", default="out/batch")
    args = ap.parse_args()
    polar = enable_polar(installed=False)
    path = build(args.blend, args.samples, polar.polar_addon)
    print(path)
    if args.render:
        import batch_render
        return batch_render.main([path, "--output", args.output])
    return 0


if __name__ == "__main__":
    sys.exit(main())
