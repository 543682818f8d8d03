"""The Denoise switch (Render ▸ Sampling ▸ Denoise): OpenImageDenoise run on the final render inside Polar's
``render()``, as the "Polar Denoise" compositor group runs it on the passes.

Oracle: the group itself, with Blender's own Denoise node, fed by the same render's passes (the same seed:
the Stokes and guide passes are the same numbers).  Its four outputs are rendered one at a time into the
composite (tests/blender/test_denoise.py's ``render_group_outputs``) and compared with the switch's S0…S3 passes.
"""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender.test_denoise import demo_like_scene, read_all, render_group_outputs  # noqa: E402
from tests.blender_support import drawn_properties, load_addon, read_multilayer, render_to_exr  # noqa: E402
from tests.conftest import REPO  # noqa: E402
from tests.support import blender_envs  # noqa: E402


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def _stokes(passes):
    return np.stack([passes[f"S{k}"] for k in range(4)])


@pytest.mark.parametrize("clamp", [True, False])
def test_denoise_switch_equals_the_compositor_group(addon, tmp_path, clamp, capsys):
    from polar_render.polar_addon.compositor import add_denoise_to_compositor
    scene = demo_like_scene(48, 32, 4)
    node = add_denoise_to_compositor(scene)
    node.inputs["Clamp DoP"].default_value = 1.0 if clamp else 0.0
    noisy, group, _ = render_group_outputs(scene, node, tmp_path, "group")
    # the switch: no compositor at all, the guide passes off (the switch renders its guides itself)
    scene.compositing_node_group = None
    layer = bpy.context.view_layer.polar
    layer.use_pass_denoising_albedo = layer.use_pass_denoising_normal = False
    scene.polar.use_denoising = True
    scene.polar.denoising_clamp_dop = clamp
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "switch")))
    switch = _stokes(passes)
    assert np.abs(switch[0] - noisy[0]).max() > 1e-3, "nothing was denoised"
    difference = np.abs(switch - group).max()
    scale = np.abs(group).max()
    with capsys.disabled():
        print(f"\nDenoise switch vs Polar Denoise group (clamp {clamp}): max |difference| {difference:.3g} "
              f"(max |S| {scale:.3g}, max |denoised − noisy| {np.abs(switch - noisy).max():.3g})")
    np.testing.assert_allclose(switch, group, rtol=1e-6, atol=1e-7 * scale)
    # the passes that follow the Stokes image: Combined is the denoised S0, the derived ones from it
    np.testing.assert_array_equal(passes["Combined"][..., :3], passes["S0"])
    y = np.einsum("shwc,c->shw", switch.astype(np.float64), [0.2126, 0.7152, 0.0722])
    lit = y[0] > 1e-3
    dolp = np.hypot(y[1], y[2])[lit] / y[0][lit]
    np.testing.assert_allclose(passes["DoLP"][..., 0][lit], dolp, rtol=1e-4, atol=1e-5)
    assert "Denoising Albedo" not in passes                      # guides used, passes still off


def test_switch_off_writes_the_noisy_render(addon, tmp_path):
    scene = demo_like_scene(24, 16, 2)
    assert scene.polar.use_denoising is False and scene.polar.denoising_clamp_dop is True
    plain = _stokes(read_multilayer(render_to_exr(scene, str(tmp_path / "off"))))
    scene.polar.use_denoising = True
    denoised = _stokes(read_multilayer(render_to_exr(scene, str(tmp_path / "on"))))
    assert not np.array_equal(plain, denoised)
    scene.polar.use_denoising = False
    np.testing.assert_array_equal(_stokes(read_multilayer(render_to_exr(scene, str(tmp_path / "off2")))), plain)


def test_without_openimagedenoise_the_render_warns_and_is_not_denoised(addon, tmp_path, monkeypatch, capfd):
    from polar_render.polar_addon import compositor
    scene = demo_like_scene(24, 16, 2)
    plain = _stokes(read_multilayer(render_to_exr(scene, str(tmp_path / "plain"))))
    monkeypatch.setattr(compositor.compat, "oidn_library", lambda: None)
    scene.polar.use_denoising = True
    capfd.readouterr()
    path = render_to_exr(scene, str(tmp_path / "missing"))
    out = capfd.readouterr()
    assert "Denoise: Blender's OpenImageDenoise library was not found: the render is not denoised" in out.out + out.err
    np.testing.assert_array_equal(_stokes(read_multilayer(path)), plain)
    assert read_all(path)                                          # the image was still written


def test_blenders_openimagedenoise_is_found(addon):
    from polar_render.polar_addon import compat
    lib = compat.oidn_library()
    assert lib is not None and hasattr(lib, "oidnExecuteFilter")


def test_sampling_panel_draws_the_switch(addon):
    from polar_render.polar_addon.ui import POLAR_PT_sampling
    scene = demo_like_scene(8, 6, 1)
    drawn = [name for _, name in drawn_properties(POLAR_PT_sampling, scene)]
    assert "use_denoising" in drawn and "denoising_clamp_dop" in drawn


#: The group (Image nodes → Polar Denoise → the composite, one output at a time, a compositor-only render) and
#: ``denoise_stokes`` on the same synthetic noisy Stokes image and guides, in a fresh process of one Blender
#: series; needs bpy and numpy only (the add-on's modules are imported without its engine).
CROSS_VERSION = textwrap.dedent(r"""
import importlib, os, sys, types
import numpy as np
import bpy

repo, out_dir = sys.argv[1], sys.argv[2]
package = types.ModuleType("polar_addon_only")             # the add-on's modules without its engine
package.__path__ = [os.path.join(repo, "polar_addon")]
sys.modules[package.__name__] = package
compat = importlib.import_module(package.__name__ + ".compat")
compositor = importlib.import_module(package.__name__ + ".compositor")

rng = np.random.default_rng(7)
H, W = 24, 32
yy, xx = np.mgrid[0:H, 0:W] / 10.0
base = (0.3 + 0.2 * np.sin(xx)[..., None] * np.cos(yy)[..., None] * np.array([1.0, 0.8, 0.6]))
S = np.zeros((4, H, W, 3))
S[0] = base * rng.gamma(4.0, 0.25, (H, W, 3))               # noisy intensity
S[1] = 0.5 * S[0] * np.cos(3 * yy)[..., None] + 0.05 * rng.normal(size=(H, W, 3))
S[2] = 0.3 * S[0] * np.sin(2 * xx)[..., None] + 0.05 * rng.normal(size=(H, W, 3))
S[3] = 0.02 * rng.normal(size=(H, W, 3))
albedo = np.clip(0.6 + 0.1 * rng.normal(size=(H, W, 3)), 0, 1)
normal = np.stack([np.sin(xx), np.cos(yy), np.ones_like(xx)], -1)
normal /= np.linalg.norm(normal, axis=-1, keepdims=True)

bpy.ops.wm.read_homefile(use_empty=True)
scene = bpy.context.scene
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = W, H, 100
scene.render.engine = "CYCLES"
compat.set_multilayer_exr(scene.render.image_settings)
scene.render.image_settings.color_depth = "32"
if hasattr(scene.render.image_settings, "media_type"):
    scene.render.image_settings.media_type = "IMAGE"
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"


def image(name, rows):
    img = bpy.data.images.new(name, W, H, float_buffer=True, alpha=True)
    px = np.ones((H, W, 4), np.float32)
    px[..., :3] = rows
    img.pixels.foreach_set(px.ravel())
    return img


tree = compat.compositor_tree(scene, create=True)
for node in list(tree.nodes):
    tree.nodes.remove(node)
group = tree.nodes.new("CompositorNodeGroup")
group.node_tree = compositor.ensure_denoise_group()
for name, rows in [(f"S{k}", S[k]) for k in range(4)] + [("Albedo", albedo), ("Normal", normal)]:
    node = tree.nodes.new("CompositorNodeImage")
    node.image = image(name, rows)                         # rows bottom first, as Blender holds pixels
    tree.links.new(node.outputs["Image"], group.inputs[name])
out = compat.compositor_output(tree)
result = {}
for k in range(4):
    for link in list(out.inputs[0].links):
        tree.links.remove(link)
    tree.links.new(group.outputs[f"S{k}"], out.inputs[0])
    scene.render.filepath = os.path.join(out_dir, f"group{k}.exr")
    bpy.ops.render.render(write_still=True)
    loaded = bpy.data.images.load(scene.render.filepath)
    px = np.empty(W * H * 4, np.float32)
    loaded.pixels.foreach_get(px)                           # Blender's rows, bottom first
    result[k] = px.reshape(H, W, 4)[..., :3]
group_out = np.stack([result[k] for k in range(4)])
switch = compositor.denoise_stokes(S, albedo, normal, quality=scene.render.compositor_denoise_final_quality)
print("BLENDER", bpy.app.version_string, "OIDN", compat.oidn_library()._name)
print("MAXDIFF", float(np.abs(switch - group_out).max()), "SCALE", float(np.abs(group_out).max()),
      "CHANGED", float(np.abs(group_out - S.astype(np.float32)).max()))
""")


@pytest.mark.parametrize("series", ("5.0",) + blender_envs.CI_SERIES)
def test_denoise_switch_equals_the_group_on_every_ci_blender(tmp_path, series, capsys):
    release, _ = blender_envs.RELEASES[series]
    if blender_envs.project_bpy_release() == release:
        python = sys.executable
    else:
        python = os.path.join(blender_envs.env_dir(series), "bin", "python")
        if not os.path.exists(os.path.join(blender_envs.env_dir(series), ".installed")):
            pytest.skip(f"no Blender {series} environment (python tests/support/blender_envs.py {series})")
    script = tmp_path / "cross_version.py"
    script.write_text(CROSS_VERSION)
    proc = subprocess.run([python, str(script), REPO, str(tmp_path)], capture_output=True, text=True, timeout=600)
    lines = [line for line in proc.stdout.splitlines() if line.startswith(("BLENDER", "MAXDIFF"))]
    assert proc.returncode == 0 and len(lines) == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    with capsys.disabled():
        print("\n" + " | ".join(lines))
    values = lines[1].split()
    difference, changed = float(values[1]), float(values[5])
    assert changed > 0.1, "the group denoised nothing"
    assert difference == 0.0                # the same library, the same calls, the same float32 arithmetic
