"""The built extension zip installs through Blender's own extension machinery and renders, on every
Blender series CI keeps: the pinned bpy 5.0.1 of the project's .venv, and the oldest and newest
supported (4.5 LTS on Python 3.11, 5.3 on Python 3.13) in environments of their own
(tests/support/blender_envs.py; `make test` creates them).

Runs in fresh bpy processes with an isolated BLENDER_USER_RESOURCES, so nothing from this
checkout is importable there except what the zip installs.
"""

import os
import shutil
import sys
import textwrap

import pytest

pytest.importorskip("bpy")

from tests.blender_support import read_multilayer  # noqa: E402
from tests.support import blender_envs  # noqa: E402
from tests.support.extension_run import (clean_env, install, judge, pass_difference, printed,  # noqa: E402
                                         run_smoke)

#: The series the smoke set runs on here: the pinned one, the oldest and the newest supported.
SERIES = ("5.0",) + blender_envs.CI_SERIES

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
    import subprocess
    return subprocess.run([sys.executable, "-c", script, *args], env=env, capture_output=True, text=True,
                          cwd=env["HOME"], timeout=600)


@pytest.fixture(scope="module")
def zip_path(tmp_path_factory):
    """This machine's extension zip, built once for the module (the wheels are downloaded once per checkout)."""
    from polar_addon.packaging import build
    return build(str(tmp_path_factory.mktemp("dist")))


@pytest.fixture(scope="module")
def smoke(zip_path, tmp_path_factory):
    """series → tests.support.extension_run.run_smoke's result (once per series for the module).

    Series of one Python (5.0 and 4.5: 3.11) run in turn in the same folder, so that the later one finds the
    kernels the earlier one compiled (Numba keys its cache by the source files' path): the same bundled Numba
    compiles the same code on the same Python, once instead of twice (≈ 30 s of the suite).  Each series still
    installs into a clean user folder; only the kernel cache is carried over."""
    done, homes, base = {}, {}, tmp_path_factory.mktemp("blender")

    def run(series):
        if series not in done:
            home = base / f"python{blender_envs.RELEASES[series][1]}"
            earlier = homes.get(home)
            if earlier is not None:             # keep the earlier series' files, carry its kernel cache over
                kept = base / f"blender{earlier}"
                home.rename(kept)
                done[earlier]["out"] = str(kept / os.path.relpath(done[earlier]["out"], home))
                cache = os.path.join("user", "extensions", ".user")
                if (kept / cache).is_dir():
                    shutil.copytree(kept / cache, home / cache)
            home.mkdir(exist_ok=True)
            homes[home] = series
            done[series] = run_smoke(series, zip_path, str(home))
        return done[series]
    return run


def test_zip_installs_enables_renders_and_caches_kernels_in_the_user_folder(tmp_path, zip_path):
    """Installed from its zip, the installed copy (not this checkout) renders every Stokes pass, and
    caches compiled kernels in Blender's user folder for the extension; the first render (empty
    cache) says it is compiling, the second does not.  One install for both.  The background compile
    of every kernel that enabling starts is switched off here (POLAR_PRECOMPILE=0: the cold render
    compiles what it uses, ≈ 25 s instead of every kernel's ≈ 90 s, the suite's budget); its
    behaviour is tested in test_kernel_cache_precompile.py and its effect measured by
    tests/bench/cold_start.py."""
    user = tmp_path / "user"
    env = clean_env(tmp_path, user)
    env["POLAR_PRECOMPILE"] = "0"
    installed = user / "extensions" / "user_default" / "polar_render"
    folder, log = install(sys.executable, zip_path, env)
    assert folder == str(installed), log
    assert (installed / "engine").is_dir()
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


@pytest.mark.parametrize("series", SERIES)
def test_smoke_set_installs_enables_renders_and_runs_the_operators(smoke, series):
    """On each Blender: the zip installs (a refusal fails even where Blender's command exits 0) and
    enables, a Principled + Polarising BSDF scene renders every pass, the Virtual Polariser's
    composite is Malus' law on the passes, the Polar Denoise group denoises, and a material edit
    re-exports the material alone in the viewport (Blender 5.3 also flags the geometry of the
    objects using it), the render on worker processes equals the threaded one pass for pass (and the processes
    end when the extension is disabled), a Normal Map set to the DirectX convention (5.1 on) is exported as such,
    and the LCD preset and the Sky Polarisation of every sky type of that Blender export polarised sources."""
    result = smoke(series)
    assert result["install"] == "ok", result["log"]
    release, python = blender_envs.RELEASES[series]
    assert result["blender"].startswith(release) and result["python"] == python, result
    for stage in ("enable", "render", "processes", "polariser", "denoise", "viewport", "normal_map", "sources"):
        assert result.get(stage) == "ok", (stage, result.get(stage), result["log"])
    assert result["backend"].startswith("numba")          # the bundled wheels of this Python loaded
    assert judge(result) == {"passes": "ok", "processes": "ok", "polariser": "ok", "denoise": "ok", "viewport": "ok",
                             "normal_map": "ok", "sources": "ok"}


@pytest.mark.parametrize("series", blender_envs.CI_SERIES)
def test_every_pass_equals_the_pinned_blenders(smoke, series):
    """The same scene and seed on 4.5 and 5.3 as on 5.0.1: every pass within 1e-6 of max S0
    (measured: identical, as the engine and its compiled kernels are the same code)."""
    difference = pass_difference(smoke(series), smoke("5.0"))
    assert difference and max(difference.values()) <= 1e-6, difference
