"""Denoising in Blender: the Denoising Albedo / Normal passes and the "Polar Denoise" compositor group.

The group denoises the six non-negative analyser images (S0 ± S_k)/2 with Blender's Denoise node and
recombines them; with a pass-through in place of the Denoise node the recombination must give the
input back.  With the real Denoise node (OIDN, in the bpy build) the test measures how often the
recombined image has DoP > 1 before the group's clamp, and checks the clamp removes every case.
"""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import (add_plane, add_sphere, brewster_camera, empty_scene, load_addon,  # noqa: E402
                                   polar_material, white_world)


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def read_all(path):
    import OpenEXR
    with OpenEXR.File(path, separate_channels=True) as f:
        return {n: np.array(c.pixels, dtype=np.float64) for p in f.parts for n, c in p.channels.items()}


def demo_like_scene(width, height, samples):
    """The demo's ingredients: Brewster black-glass floor, gold and chalk spheres, white sky."""
    scene = empty_scene(width=width, height=height, samples=samples)
    add_plane(100, polar_material("Floor", "BLACK_GLASS"))
    add_sphere(1.0, (-1.2, 0.5, 1.0), polar_material("Gold", "CONDUCTOR", metal="Au"))
    add_sphere(1.0, (1.2, 0.5, 1.0), polar_material("Chalk", "LAMBERT"))
    brewster_camera(scene, distance=9, lens=35)
    white_world(scene)
    layer = bpy.context.view_layer.polar
    layer.use_pass_denoising_albedo = layer.use_pass_denoising_normal = True
    return scene


def render_group_outputs(scene, node, tmp_path, tag):
    """Render once per group output (S0…S3), returning (input Stokes, output Stokes, all channels)."""
    tree = scene.compositing_node_group
    out = next(n for n in tree.nodes if n.bl_idname == "NodeGroupOutput")
    result, chans = [], None
    for k in range(4):
        for link in list(out.inputs[0].links):
            tree.links.remove(link)
        tree.links.new(node.outputs[f"S{k}"], out.inputs[0])
        scene.render.filepath = str(tmp_path / f"{tag}{k}")
        bpy.ops.render.render(write_still=True)
        chans = read_all(str(tmp_path / f"{tag}{k}") + ".exr")
        result.append(np.stack([chans[f"Composite.Combined.{c}"] for c in "RGB"], -1))
    S = np.stack([np.stack([chans[f"ViewLayer.S{i}.{c}"] for c in "RGB"], -1) for i in range(4)])
    return S, np.stack(result), chans


def dop(S):
    return np.sqrt((S[1:] ** 2).sum(0)) / np.where(S[0] > 0, S[0], np.inf)


def test_guide_passes_and_exact_recombination_with_a_pass_through(addon, tmp_path):
    from polar_render.polar_addon.compositor import add_denoise_to_compositor, ensure_denoise_group
    scene = demo_like_scene(24, 16, 2)
    real = ensure_denoise_group()
    assert sum(n.bl_idname == "CompositorNodeDenoise" for n in real.nodes) == 6
    node = add_denoise_to_compositor(scene, denoiser="pass-through")
    links = {(link.from_socket.name, link.to_socket.name) for link in scene.compositing_node_group.links}
    assert ("Denoising Albedo", "Albedo") in links and ("Denoising Normal", "Normal") in links
    for clamp in (0.0, 1.0):
        node.inputs["Clamp DoP"].default_value = clamp
        S, out, chans = render_group_outputs(scene, node, tmp_path, f"c{clamp:g}_")
        assert np.abs(S[1]).max() > 0.1 * S[0].max()           # the floor is polarised
        expected = S.copy()
        if clamp:
            # |S| scaled down to S0 per pixel and colour channel (spectral estimates can exceed DoP 1
            # in one channel, or have S0 < 0 there: then S1…S3 become 0)
            length = np.sqrt((S[1:] ** 2).sum(0))
            factor = np.clip(np.where(length > 0, S[0] / np.where(length > 0, length, 1), 0), 0, 1)
            expected[1:] *= factor
        np.testing.assert_allclose(out, expected, rtol=2e-6, atol=1e-7)
    albedo = np.stack([chans[f"ViewLayer.Denoising Albedo.{c}"] for c in "RGB"], -1)
    normal = np.stack([chans[f"ViewLayer.Denoising Normal.{c}"] for c in "XYZ"], -1)
    assert albedo.min() >= 0 and albedo.max() > 0.3               # the chalk sphere
    assert np.linalg.norm(normal, axis=-1).max() <= 1 + 1e-5 and np.abs(normal).max() > 0.5


def test_operator_turns_the_passes_on_and_adds_the_group(addon):
    scene = empty_scene(8, 6, 1)
    assert not bpy.context.view_layer.polar.use_pass_denoising_albedo
    assert bpy.ops.polar.add_polar_denoise() == {"FINISHED"}
    layer = bpy.context.view_layer.polar
    assert layer.use_pass_denoising_albedo and layer.use_pass_denoising_normal and layer.use_pass_s3
    tree = scene.compositing_node_group
    node = next(n for n in tree.nodes if n.name == "Polar Denoise")
    assert node.node_tree.name == "Polar Denoise v1" and node.inputs["Albedo"].is_linked
    out = next(n for n in tree.nodes if n.bl_idname == "NodeGroupOutput")
    assert out.inputs[0].links[0].from_socket == node.outputs["S0"]


def test_denoise_node_dop_before_and_after_the_clamp(addon, tmp_path, capsys):
    from polar_render.polar_addon.compositor import add_denoise_to_compositor
    scene = demo_like_scene(64, 40, 4)
    node = add_denoise_to_compositor(scene)
    node.inputs["Clamp DoP"].default_value = 0.0
    S, raw, _ = render_group_outputs(scene, node, tmp_path, "raw")
    assert np.abs(raw[0] - S[0]).max() > 1e-3, "the Denoise node changed nothing: is OIDN in this bpy build?"
    lit = raw[0] > 1e-4
    over = (dop(raw) > 1 + 1e-5) & lit
    node.inputs["Clamp DoP"].default_value = 1.0
    _, clamped, _ = render_group_outputs(scene, node, tmp_path, "clamped")
    with capsys.disabled():
        print(f"\nPolar Denoise on the demo-like scene: DoP > 1 in {over.sum()} of {lit.sum()} lit pixel-channels "
              f"({100 * over.sum() / max(lit.sum(), 1):.2f} %) before the clamp; max DoP {dop(raw)[lit].max():.4f}; "
              f"input max DoP {dop(S)[S[0] > 1e-4].max():.4f}")
    assert dop(clamped)[clamped[0] > 1e-4].max() <= 1 + 1e-5
    np.testing.assert_allclose(clamped[0], raw[0], rtol=1e-6)      # the clamp leaves S0 alone
    keep = ~over & lit
    np.testing.assert_allclose(clamped[1:, keep], raw[1:, keep], rtol=1e-5, atol=1e-7)
