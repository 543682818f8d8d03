"""Cycles parity of a Principled floor seen at grazing angles: the weight of the diffuse base under the specular layer.

A large Principled plane (dielectric, Base Color 0.8, default IOR and Specular IOR Level) under a uniform white world,
seen by an orthographic camera at θ from the normal (every pixel at the same angle), exported as F12 exports it and
rendered by Cycles and by Polar at equal samples; the mean luminance ratio Polar/Cycles must lie within 0.4 % + 3σ of
1 (σ from the spread of the seeds). A plane under a uniform sky shows each pixel's albedo: the specular layer's plus
the base's, which Cycles weights by one minus its *estimate* of the layer's albedo (``closure_layering_weight`` of
``bsdf_albedo``: the ggx_gen_schlick_ior_s table read on its 16 nodes, times the multiscatter closure weight;
engine.materials.ggx_energy.cycles_layering_albedo, docs/physics.md).

Measured (8², 3 × 256 spp, Polar/Cycles before → after the estimate was Cycles'): roughness 0 at 80° 1.0045 → 1.0004,
at 89° 1.0105 → 1.0002; roughness 0.5 at 83° 1.0104 → 1.0019 (± 0.0007).
"""

import math
import tempfile

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import add_plane, load_addon, white_world  # noqa: E402

N = 8
SPP = 256
SEEDS = 3
BOUNCES = 4
REC709 = np.array([0.2126, 0.7152, 0.0722])

#: (roughness, viewing angle from the normal in degrees)
CASES = [(0.0, 80.0), (0.0, 89.0), (0.5, 83.0)]


def scene_of(roughness):
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = N
    scene.render.resolution_percentage = 100
    mat = bpy.data.materials.new("Floor")
    mat.use_nodes = True
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Roughness"].default_value = roughness
    p.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    add_plane(200.0, mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.type = "ORTHO"
    cam.data.ortho_scale = 0.3               # a footprint of 0.3 × 17 at 89°, well inside the plane
    scene.collection.objects.link(cam)
    scene.camera = cam
    white_world(scene, 1.0)
    return scene, cam


@pytest.mark.parametrize("roughness, angle", CASES)
def test_principled_floor_at_grazing_angles_matches_cycles(roughness, angle):
    load_addon()
    from tests.support import asset_parity as ap
    scene, cam = scene_of(roughness)
    t = math.radians(angle)
    cam.location = (0.0, -20.0 * math.sin(t), 20.0 * math.cos(t))
    cam.rotation_euler = (t, 0.0, 0.0)
    with tempfile.TemporaryDirectory() as tmp:
        cycles = (ap.render_cycles(scene, SPP, SEEDS, BOUNCES, tmp) @ REC709).mean(axis=(1, 2))
    renderer, settings, _ = ap.export_polar(scene, SPP, BOUNCES)
    polar = (ap.render_polar(renderer, settings, SEEDS)[:, 0] @ REC709).mean(axis=(1, 2))
    ratio = polar.mean() / cycles.mean()
    sigma = ratio * math.hypot(cycles.std(ddof=1) / cycles.mean(), polar.std(ddof=1) / polar.mean()) / math.sqrt(SEEDS)
    assert abs(ratio - 1.0) < 0.004 + 3.0 * sigma, (roughness, angle, ratio, sigma)
