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
    import importlib, json, math, os, sys
    import bpy
    import addon_utils
    addon_utils.enable("bl_ext.user_default.polar_render", default_set=True)
    import bl_ext.user_default.polar_render as ext
    engine_class = sys.modules[ext.__name__ + ".polar_addon.render_engine"].PolarRenderEngine
    class RecordStats:          # headless Blender shows no status: print what the engine sets
        def __init__(self, engine):
            self.engine = engine
        def __getattr__(self, name):
            return getattr(self.engine, name)
        def update_stats(self, stats, info):
            print("POLAR_STATUS=" + info)
            self.engine.update_stats(stats, info)
    render_body = engine_class._render
    engine_class._render = lambda self, depsgraph: render_body(RecordStats(self), depsgraph)
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
    kernels = sys.modules[ext.__name__ + ".engine.kernels"]
    print("POLAR_KERNEL_CACHE=" + kernels.cache_dir())
    print("POLAR_TABLE_DIR=" + importlib.import_module(ext.__name__ + ".engine.materials.table_cache").table_dir())
    print("POLAR_BACKEND=" + kernels.BACKEND)
    lib = importlib.import_module(ext.__name__ + ".engine.render.embree_direct").library()
    print("POLAR_EMBREE_LIBRARY=" + ("" if lib is None else lib._name))
""")


def run_bpy(script, *args, env):
    return subprocess.run([sys.executable, "-c", script, *args], env=env, capture_output=True, text=True,
                          cwd=env["HOME"], timeout=600)


def printed(proc, key):
    """Values the scripts above print as ``KEY=value`` lines, in order."""
    return [line.split("=", 1)[1] for line in proc.stdout.splitlines() if line.startswith(key + "=")]


def test_zip_installs_enables_renders_and_caches_kernels_in_the_user_folder(tmp_path):
    """Installed from its zip, the installed copy (not this checkout) renders every Stokes pass, and
    caches compiled kernels in Blender's user folder for the extension; the first render (empty
    cache) says it is compiling, the second does not.  One install for both: the cold render
    compiles every kernel (≈ 1 min)."""
    from polar_addon.packaging import build
    zip_path = build(str(tmp_path / "dist"))
    user = tmp_path / "user"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "POLAR_KERNEL_CACHE", "POLAR_KERNELS")}
    env.update(BLENDER_USER_RESOURCES=str(user), HOME=str(tmp_path))
    proc = run_bpy(INSTALL, zip_path, env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    installed = user / "extensions" / "user_default" / "polar_render"
    assert (installed / "blender_manifest.toml").exists() and (installed / "engine").is_dir()
    user_folder = user / "extensions" / ".user" / "user_default" / "polar_render" / "numba"
    statuses = []
    for run in ("cold", "warm"):
        out = str(tmp_path / run)
        proc = run_bpy(RENDER, out, env=env)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert printed(proc, "POLAR_ENGINE_FILE")[0].startswith(str(installed))   # the installed copy
        assert printed(proc, "POLAR_BACKEND")[0].startswith("numba")
        # Embree is queried from compiled code (engine.render.embree_direct) with the bundled wheel's library
        assert printed(proc, "POLAR_EMBREE_LIBRARY")[0].startswith(str(user) + os.sep), proc.stdout
        cache = printed(proc, "POLAR_KERNEL_CACHE")[0]
        assert cache.startswith(str(user_folder / "0.1.0") + os.sep), cache
        assert any(name.endswith(".nbi") for _, _, files in os.walk(cache) for name in files)
        # precomputed material tables (engine.materials.table_cache) go to the same user folder
        assert printed(proc, "POLAR_TABLE_DIR")[0].startswith(str(user_folder / "0.1.0" / "tables") + os.sep)
        statuses.append(printed(proc, "POLAR_STATUS"))
        passes = read_multilayer(out + ".exr")
        for name in ("S0", "S1", "S2", "S3", "DoP", "DoLP", "AoLP", "DoCP"):
            assert name in passes
        h, w = passes["DoLP"].shape[:2]
        assert passes["DoLP"][h // 2 - 2:h // 2 + 2, w // 2 - 2:w // 2 + 2].min() > 0.9
    cold, warm = statuses
    assert "Polar | compiling kernels (first render only)" in cold
    assert warm and "samples in" in warm[-1]                     # the warm render's stats were recorded too
    assert not any("compiling kernels" in s for s in warm)
    assert "numba wheels missing" not in cold[-1]
