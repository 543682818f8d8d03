"""The built extension zip installs through Blender's own extension machinery and renders.

Runs in fresh bpy processes with an isolated BLENDER_USER_RESOURCES, so nothing from this
checkout is importable there except what the zip installs.
"""

import os
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("bpy")

from tests.blender_support import read_multilayer  # noqa: E402

INSTALL = textwrap.dedent("""
    import sys
    import bpy
    from bl_pkg import cli_extension
    sys.exit(cli_extension(["install-file", "-r", "user_default", "-e", sys.argv[1]]) or 0)
""")

RENDER = textwrap.dedent("""
    import json, math, sys
    import bpy
    import addon_utils
    addon_utils.enable("bl_ext.user_default.polar_render", default_set=True)
    import bl_ext.user_default.polar_render as ext
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "POLAR"
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    scene.polar.samples = 2
    bpy.ops.mesh.primitive_plane_add(size=200)
    mat = bpy.data.materials.new("Floor")
    tree = mat.node_tree
    node = tree.nodes.new("PolarShaderNodeBSDF")
    node.model = "BLACK_GLASS"
    tree.links.new(node.outputs[0], tree.get_output_node("ALL").inputs["Surface"])
    bpy.context.object.data.materials.append(mat)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    th = math.atan(1.5)
    cam.location, cam.rotation_euler = (0, -10 * math.sin(th), 10 * math.cos(th)), (th, 0, 0)
    cam.data.lens = 200
    scene.camera = cam
    world = bpy.data.worlds.new("World")
    scene.world = world
    ims = scene.render.image_settings
    ims.media_type = "MULTI_LAYER_IMAGE"
    ims.color_depth = "32"
    scene.render.filepath = sys.argv[1]
    bpy.ops.render.render(write_still=True)
    engine_file = sys.modules[ext.__name__ + ".engine"].__file__
    print("POLAR_ENGINE_FILE=" + engine_file)
""")


def run_bpy(script, *args, env):
    return subprocess.run([sys.executable, "-c", script, *args], env=env, capture_output=True, text=True,
                          cwd=env["HOME"], timeout=600)


def test_zip_installs_enables_and_renders(tmp_path):
    from polar_addon.packaging import build
    zip_path = build(str(tmp_path / "dist"))
    user = tmp_path / "user"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    env.update(BLENDER_USER_RESOURCES=str(user), HOME=str(tmp_path))
    proc = run_bpy(INSTALL, zip_path, env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    installed = user / "extensions" / "user_default" / "polar_render"
    assert (installed / "blender_manifest.toml").exists() and (installed / "engine").is_dir()
    out = str(tmp_path / "render")
    proc = run_bpy(RENDER, out, env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    engine_file = next(line.split("=", 1)[1] for line in proc.stdout.splitlines()
                       if line.startswith("POLAR_ENGINE_FILE="))
    assert engine_file.startswith(str(installed))                # the installed copy rendered, not this checkout
    passes = read_multilayer(out + ".exr")
    for name in ("S0", "S1", "S2", "S3", "DoP", "DoLP", "AoLP", "DoCP"):
        assert name in passes
    h, w = passes["DoLP"].shape[:2]
    assert passes["DoLP"][h // 2 - 2:h // 2 + 2, w // 2 - 2:w // 2 + 2].min() > 0.9
