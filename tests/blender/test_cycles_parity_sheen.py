"""Cycles parity of the sheen model (engine.materials.sheen) against Cycles' own renders.

A smooth UV sphere whose only lobe is a sheen — a Principled BSDF with a black base, Specular IOR Level 0
and a tinted Sheen layer, or a Sheen BSDF node (Microfiber) — seen by an orthographic camera, lit by a sun
(angle 0) or by a uniform white world, rendered by Cycles (CPU, direct light only, every sample on its
pixel's centre: the Normal pass is the shading normal there).  Polar's side is the model itself, per pixel
at that normal: under the sun strength × f(wo, L)·cosθ_L, under the world ∫ f cosθ dω over the directions
above the pixel's facet, from the model's own sampler (weights E·tint; Cycles rejects its samples below the
facet, and the sphere shadows its light samples there — at the rim a low-roughness sheen puts a few
percent of its lobe between the facet's plane and the shading normal's).

The asset rule of tests/support/asset_parity.py (``compare``), per 16 × 16 block that the sphere covers:
|m_P − m_C| ≤ 4σ + 2 % m_C on the Rec.709 luminance (σ: the standard errors of both means over the seeds),
here for every block, not 95 %; and each RGB channel's total within 2 %.  About 3 s for the four cases.
"""

import tempfile

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import load_addon, read_multilayer  # noqa: E402
from tests.support import asset_parity as ap  # noqa: E402

SIZE = 64
SUN = 3.0                                                   # W/m²
SUN_DIRECTION = np.array([0.75, -0.3, 0.59])               # towards the sun; the camera looks along +y
VIEW = np.array([0.0, -1.0, 0.0])                          # towards the camera
ORTHO_SCALE = 2.2

#: name → (node, its inputs, sheen roughness, sheen colour = weight × tint)
MATERIALS = {
    "principled": ("ShaderNodeBsdfPrincipled",
                   {"Base Color": (0.0, 0.0, 0.0, 1.0), "Specular IOR Level": 0.0, "Sheen Weight": 0.8,
                    "Sheen Roughness": 0.35, "Sheen Tint": (0.9, 0.55, 0.25, 1.0)},
                   0.35, 0.8 * np.array([0.9, 0.55, 0.25])),
    "sheen_node": ("ShaderNodeBsdfSheen",
                   {"Color": (0.3, 0.6, 1.0, 1.0), "Roughness": 0.1},
                   0.1, np.array([0.3, 0.6, 1.0])),
}
#: lighting → (samples per pixel, seeds)
LIGHTINGS = {"sun": (1, 2), "world": (16, 4)}


def build(material, lighting):
    from mathutils import Vector
    scene = ap.reset(SIZE, SIZE)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, segments=96, ring_count=48)
    obj = bpy.context.object
    obj.data.shade_smooth()
    mat = bpy.data.materials.new("Sheen")
    compat = load_addon().polar_addon.compat
    compat.ensure_node_tree(mat)
    tree = mat.node_tree
    for node in list(tree.nodes):
        if node.type != "OUTPUT_MATERIAL":
            tree.nodes.remove(node)
    kind, inputs, _, _ = MATERIALS[material]
    bsdf = tree.nodes.new(kind)
    if kind == "ShaderNodeBsdfSheen":
        bsdf.distribution = "MICROFIBER"
    for k, v in inputs.items():
        bsdf.inputs[k].default_value = v
    tree.links.new(bsdf.outputs[0], tree.nodes[0].inputs["Surface"])
    obj.data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.type, cam.data.ortho_scale = "ORTHO", ORTHO_SCALE
    cam.location = Vector(tuple(5.0 * VIEW))
    cam.rotation_euler = Vector(tuple(-VIEW)).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(cam)
    scene.camera = cam
    world = bpy.data.worlds.new("World")
    scene.world = world
    compat.ensure_node_tree(world)
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bg.inputs["Strength"].default_value = 1.0 if lighting == "world" else 0.0
    if lighting == "sun":
        sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
        sun.data.energy, sun.data.angle = SUN, 0.0
        sun.rotation_euler = Vector(tuple(SUN_DIRECTION)).to_track_quat("Z", "Y").to_euler()
        scene.collection.objects.link(sun)
    ap.cycles_settings(scene, 1, 1)         # the parity settings, Max Bounces 1: direct light only
    # every sample on its pixel's centre (Cycles' box filter is 1 px whatever its width; a 0.01 px
    # Gaussian is a point), so the Normal pass is the shading normal there
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = "GAUSSIAN", 0.01
    scene.render.film_transparent = True
    scene.view_layers[0].use_pass_normal = True
    return scene


def render(scene, spp, seeds):
    """(seeds, H, W, 3) Combined, and the Normal pass (H, W, 3) and alpha (H, W) of the first seed."""
    c = scene.cycles
    c.samples = spp
    out, normal, alpha = [], None, None
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(seeds):
            c.seed = seed
            scene.render.filepath = f"{tmp}/cycles_{seed}"
            bpy.ops.render.render(write_still=True)
            passes = read_multilayer(scene.render.filepath + ".exr")
            out.append(passes["Combined"][..., :3])
            if normal is None:
                normal, alpha = passes["Normal"][..., :3], passes["Combined"][..., 3]
    return np.array(out, np.float64), normal.astype(np.float64), alpha


def facet_normals(scene, hit):
    """(H, W, 3) the geometric (facet) normal under each pixel centre (Blender's ray cast)."""
    from mathutils import Vector
    depsgraph = bpy.context.evaluated_depsgraph_get()
    M = scene.camera.matrix_world
    right, up = M.col[0].xyz.normalized(), M.col[1].xyz.normalized()
    origin, direction = M.translation, Vector(tuple(-VIEW))
    out = np.zeros(hit.shape + (3,))
    for i, j in zip(*np.nonzero(hit)):
        x = float((j + 0.5) / SIZE - 0.5) * ORTHO_SCALE
        y = float(0.5 - (i + 0.5) / SIZE) * ORTHO_SCALE
        found, _, normal, *_ = scene.ray_cast(depsgraph, origin + x * right + y * up, direction)
        out[i, j] = tuple(normal) if found else (np.nan,) * 3
    return out


def polar_image(material, lighting, normal, facet, hit, seed):
    """(H, W, 3) the model's prediction at every pixel centre on the sphere."""
    load_addon()
    from polar_render.engine.materials.base import ShadingPoint
    from polar_render.engine.materials.sheen import Sheen
    from polar_render.engine.spectral import ConstantSpectrum
    _, _, roughness, colour = MATERIALS[material]
    n = normal[hit].T
    n = n / np.linalg.norm(n, axis=0)
    m = n.shape[1]
    wo = np.tile(VIEW[:, None], (1, m))
    model = Sheen(ConstantSpectrum(1.0), roughness)
    if lighting == "sun":
        sp = ShadingPoint(np.zeros((3, m)), n, n, wo, np.full((1, m), 550.0))
        L = SUN_DIRECTION / np.linalg.norm(SUN_DIRECTION)
        value = SUN * model.eval(sp, np.tile(L[:, None], (1, m))).A[0] * np.maximum(L @ n, 0.0)
    else:
        # uniform radiance 1: the mean sample weight f·cosθ/pdf over the directions above the facet (Cycles
        # rejects BSDF samples below it, and the sphere shadows light samples there)
        sp = ShadingPoint(np.zeros((3, m)), n, facet[hit].T, wo, np.full((1, m), 550.0))
        rng = np.random.default_rng(seed)
        value = np.mean([model.sample(sp, rng.random(m), rng.random((2, m))).weight.A[0] for _ in range(64)],
                        axis=0)
    img = np.zeros(hit.shape + (3,))
    img[hit] = value[:, None] * colour[None, :]
    return img


@pytest.mark.parametrize("lighting", list(LIGHTINGS))
@pytest.mark.parametrize("material", list(MATERIALS))
def test_sheen_matches_cycles(material, lighting):
    spp, seeds = LIGHTINGS[lighting]
    scene = build(material, lighting)
    cycles, normal, alpha = render(scene, spp, seeds)
    hit = (alpha > 0.999) & (np.linalg.norm(normal, axis=-1) > 0.5)
    facet = facet_normals(scene, hit) if lighting == "world" else None
    polar = np.array([polar_image(material, lighting, normal, facet, hit, seed) for seed in range(seeds)])
    report = ap.CaseReport(f"sheen {material}", lighting, spp, seeds, SIZE, SIZE)
    ap.compare(cycles, polar, hit, report)
    print(report.line())
    assert report.blocks >= 8
    assert report.passed == report.blocks, (
        f"{report.line()}\nfailing blocks (row, column, Polar ÷ Cycles, tolerance): "
        f"{[(i, j, round(r, 4), round(t, 4)) for i, j, r, t in report.failing]}")
    for ratio in report.channel_ratios:        # each channel's total over the compared blocks (the tint)
        assert ratio == pytest.approx(1.0, abs=ap.RELATIVE), report.line()
