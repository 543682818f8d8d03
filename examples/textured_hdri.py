"""A textured, HDRI-lit Blender scene rendered by Cycles and by Polar: Cycles | Polar S0 | Polar DoLP.

    python examples/textured_hdri.py [--out examples/images/textured_hdri.png]
                                     [--width 320] [--height 200] [--samples 128]

Everything is made the way an artist would make it, with plain Blender nodes:
- the world is an Environment Texture (an equirectangular EXR written by this script: a blue sky
  gradient, a small bright sun 30° above the horizon and a brown ground) behind a Mapping node that
  turns it 60° about Z;
- the floor's Base Color is an Image Texture (a checker PNG, sRGB) and its Roughness another
  (a stripe PNG, Non-Color);
- a ball has a Normal Map node fed by a tangent-space normal PNG (bumps), another a Bump node fed
  by a height PNG;
- a glossy dielectric ball shows the sky's polarised reflection.
The same .blend is rendered by Cycles (bpy ships it) and by Polar through the extension's exporter.
Where nothing polarises, S0 should be Cycles' picture; DoLP is what Cycles cannot show.
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
sys.path.insert(0, os.path.join(REPO, "examples"))

from cycles_side_by_side import principled, render_cycles, render_polar  # noqa: E402


def sky_exr(path, width=256, height=128):
    """Equirectangular sky: rows from the top (v = 1, zenith) down, as Blender reads EXRs."""
    v = 1.0 - (np.arange(height) + 0.5) / height                    # 1 at the top row
    u = (np.arange(width) + 0.5) / width
    elevation = (v - 0.5) * math.pi
    azimuth = (u - 0.5) * 2 * math.pi
    el, az = np.meshgrid(elevation, azimuth, indexing="ij")
    sky = np.stack([0.25 + 0.25 * np.sin(el), 0.45 + 0.25 * np.sin(el), 0.9 + 0.1 * np.sin(el)], -1)
    ground = np.broadcast_to(np.array([0.18, 0.12, 0.07]), sky.shape)
    img = np.where(el[..., None] > 0, sky, ground)
    sun_dir = np.array([math.cos(math.radians(30)), 0.0, math.sin(math.radians(30))])
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1)
    img = img + 400.0 * (d @ sun_dir > math.cos(math.radians(2.5)))[..., None]
    rgba = np.concatenate([img, np.ones(img.shape[:2] + (1,))], -1).astype(np.float32)
    _save(path, rgba[::-1], "OPEN_EXR", float_buffer=True)


def _save(path, rgba_bottom_up, file_format, float_buffer=False):
    import bpy
    h, w = rgba_bottom_up.shape[:2]
    image = bpy.data.images.new(os.path.basename(path), w, h, alpha=True, float_buffer=float_buffer)
    image.pixels.foreach_set(np.ascontiguousarray(rgba_bottom_up, np.float32).ravel())
    image.filepath_raw, image.file_format = path, file_format
    image.save()
    bpy.data.images.remove(image)


def pattern_pngs(folder, n=256):
    """checker.png (sRGB colours), stripes.png (roughness 0.1/0.6), bumps_normal.png, bumps_height.png."""
    y, x = np.mgrid[0:n, 0:n] / n
    checker = ((np.floor(x * 8) + np.floor(y * 8)) % 2)[..., None]
    colours = checker * np.array([0.9, 0.85, 0.75]) + (1 - checker) * np.array([0.15, 0.25, 0.45])
    grey = lambda g: np.concatenate([np.repeat(g[..., None], 3, -1), np.ones((n, n, 1))], -1)  # noqa: E731
    _save(os.path.join(folder, "checker.png"), np.concatenate([colours, np.ones((n, n, 1))], -1), "PNG")
    _save(os.path.join(folder, "stripes.png"), grey(np.where((x * 6) % 1 < 0.5, 0.1, 0.6)), "PNG")
    h = 0.5 + 0.5 * np.sin(2 * math.pi * 6 * x) * np.sin(2 * math.pi * 3 * y)
    _save(os.path.join(folder, "bumps_height.png"), grey(h), "PNG")
    gx, gy = np.gradient(h, 1.0 / n)
    nrm = np.stack([-gx * 0.02, -gy * 0.02, np.ones_like(h)], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    _save(os.path.join(folder, "bumps_normal.png"),
          np.concatenate([0.5 + 0.5 * nrm, np.ones((n, n, 1))], -1), "PNG")


def image_node(bpy, mat, path, non_color=False):
    node = mat.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = bpy.data.images.load(path)
    if non_color:
        node.image.colorspace_settings.name = "Non-Color"
    return node


def build(bpy, width, height, folder):
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    sky_exr(os.path.join(folder, "sky.exr"))
    pattern_pngs(folder)

    floor = principled(bpy, "Checker floor", (0.5, 0.5, 0.5))
    p, links = floor.node_tree.nodes["Principled BSDF"], floor.node_tree.links
    links.new(image_node(bpy, floor, os.path.join(folder, "checker.png")).outputs["Color"], p.inputs["Base Color"])
    links.new(image_node(bpy, floor, os.path.join(folder, "stripes.png"), True).outputs["Color"],
              p.inputs["Roughness"])
    bpy.ops.mesh.primitive_plane_add(size=8)
    bpy.context.object.data.materials.append(floor)

    bumpy = principled(bpy, "Normal-mapped", (0.7, 0.3, 0.1), roughness=0.5)
    p, links = bumpy.node_tree.nodes["Principled BSDF"], bumpy.node_tree.links
    nmap = bumpy.node_tree.nodes.new("ShaderNodeNormalMap")
    links.new(image_node(bpy, bumpy, os.path.join(folder, "bumps_normal.png"), True).outputs["Color"],
              nmap.inputs["Color"])
    links.new(nmap.outputs["Normal"], p.inputs["Normal"])
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.6, location=(-1.2, 0.4, 0.6), segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(bumpy)

    bumped = principled(bpy, "Bump-mapped", (0.2, 0.5, 0.25), roughness=0.6)
    p, links = bumped.node_tree.nodes["Principled BSDF"], bumped.node_tree.links
    bump = bumped.node_tree.nodes.new("ShaderNodeBump")
    bump.inputs["Distance"].default_value = 0.05
    links.new(image_node(bpy, bumped, os.path.join(folder, "bumps_height.png"), True).outputs["Color"],
              bump.inputs["Height"])
    links.new(bump.outputs["Normal"], p.inputs["Normal"])
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, location=(1.3, 0.8, 0.5), segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(bumped)

    glossy = principled(bpy, "Black glossy", (0.02, 0.02, 0.02), roughness=0.05)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.55, location=(0.1, -0.6, 0.55), segments=64, ring_count=32)
    bpy.ops.object.shade_smooth()
    bpy.context.object.data.materials.append(glossy)

    world = bpy.data.worlds.new("HDRI")
    scene.world = world
    nodes, links = world.node_tree.nodes, world.node_tree.links
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(os.path.join(folder, "sky.exr"))
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(60))
    coords = nodes.new("ShaderNodeTexCoord")
    links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    links.new(env.outputs["Color"], nodes["Background"].inputs["Color"])

    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = 35
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (0.0, -5.5, 2.0), (math.radians(74), 0.0, 0.0)
    scene.camera = cam
    return scene


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(REPO, "examples", "images", "textured_hdri.png"))
    ap.add_argument("--width", type=int, default=320)
    ap.add_argument("--height", type=int, default=200)
    ap.add_argument("--samples", type=int, default=128)
    a = ap.parse_args(argv)
    import bpy

    from engine.output.colormaps import sequential, tonemap
    from engine.output.png import write_png
    from engine.polarisation.stokes import degree_of_linear_polarisation as dolp
    from engine.postprocess.sheets import contact_sheet
    from tests.blender_support import load_addon
    load_addon()
    lum = np.array([0.2126, 0.7152, 0.0722])
    with tempfile.TemporaryDirectory() as tmp:
        scene = build(bpy, a.width, a.height, tmp)
        cycles = render_cycles(bpy, scene, a.samples, tmp)
        stokes = render_polar(bpy, scene, a.samples, a.width, a.height)
    ratio = float(np.mean(stokes[0] @ lum) / np.mean(cycles @ lum))
    print(f"mean luminance Polar S0 / Cycles = {ratio:.4f}")
    sheet = contact_sheet([tonemap(cycles), tonemap(stokes[0]), sequential(np.nan_to_num(dolp(stokes @ lum)))],
                          columns=3)   # left to right: Cycles, Polar S0, Polar DoLP (0 purple … 1 yellow)
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    write_png(a.out, sheet)
    print(a.out)


if __name__ == "__main__":
    main()
