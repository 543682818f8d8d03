"""The built extension zip installs through Blender's own extension machinery and renders, on every
Blender series CI keeps: the pinned bpy 5.0.1 of the project's .venv, and the oldest and newest
supported (4.5 LTS on Python 3.11, 5.3 on Python 3.13) in environments of their own
(tests/support/blender_envs.py; `make test` creates them).

Runs in fresh bpy processes with an isolated BLENDER_USER_RESOURCES, so nothing from this
checkout is importable there except what the zip installs.
"""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

pytest.importorskip("bpy")

from tests.blender_support import read_multilayer  # noqa: E402
from tests.support import blender_envs  # noqa: E402
from tests.support import extension_smoke  # noqa: E402  (constants only: it runs inside each Blender)

SMOKE_SCRIPT = extension_smoke.__file__
#: The series the smoke set runs on here: the pinned one, the oldest and the newest supported.
SERIES = ("5.0",) + blender_envs.CI_SERIES
PASSES = ("Combined", "S0", "S1", "S2", "S3", "DoP", "DoLP", "AoLP", "DoCP", "Polariser")

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


def run_bpy(script, *args, env, python=sys.executable):
    return subprocess.run([python, "-c", script, *args], env=env, capture_output=True, text=True,
                          cwd=env["HOME"], timeout=600)


def clean_env(home, user):
    """This process's environment without Polar's overrides, with Blender's user folder at ``user``."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "POLAR_KERNEL_CACHE", "POLAR_KERNELS")}
    env.update(BLENDER_USER_RESOURCES=str(user), HOME=str(home))
    return env


def install(python, zip_path, env):
    """Install the zip with Blender's extension command; fails the test if it did not install, even
    where the command exits 0 (Blender 4.5 refuses a too-new minimum version so)."""
    proc = run_bpy(INSTALL, zip_path, env=env, python=python)
    log = proc.stdout + proc.stderr
    installed = os.path.join(env["BLENDER_USER_RESOURCES"], "extensions", "user_default", "polar_render")
    assert proc.returncode == 0, log
    assert os.path.exists(os.path.join(installed, "blender_manifest.toml")), log
    assert not [line for line in log.splitlines() if line.startswith("ERROR") or "incompatible" in line], log
    return installed


@pytest.fixture(scope="module")
def zip_path(tmp_path_factory):
    """This machine's extension zip, built once for the module (the wheels are downloaded once per checkout)."""
    from polar_addon.packaging import build
    return build(str(tmp_path_factory.mktemp("dist")))


@pytest.fixture(scope="module")
def smoke(zip_path, tmp_path_factory):
    """series → (report, output folder): the zip installed into a clean user folder of that Blender and
    tests/support/extension_smoke.py run there (once per series for the module)."""
    done = {}

    def run(series):
        if series not in done:
            python = blender_envs.interpreter(series)
            home = tmp_path_factory.mktemp(f"blender{series}")
            env = clean_env(home, home / "user")
            install(python, zip_path, env)
            out = home / "out"
            proc = subprocess.run([python, SMOKE_SCRIPT, str(out)], env=env, capture_output=True, text=True,
                                  cwd=str(home), timeout=600)
            reports = printed(proc, "POLAR_SMOKE")
            assert proc.returncode == 0 and reports, proc.stdout[-3000:] + proc.stderr[-3000:]
            done[series] = (json.loads(reports[-1]), out)
        return done[series]
    return run


def printed(proc, key):
    """Values the scripts above print as ``KEY=value`` lines, in order."""
    return [line.split("=", 1)[1] for line in proc.stdout.splitlines() if line.startswith(key + "=")]


def test_zip_installs_enables_renders_and_caches_kernels_in_the_user_folder(tmp_path, zip_path):
    """Installed from its zip, the installed copy (not this checkout) renders every Stokes pass, and
    caches compiled kernels in Blender's user folder for the extension; the first render (empty
    cache) says it is compiling, the second does not.  One install for both: the cold render
    compiles every kernel (≈ 1 min)."""
    user = tmp_path / "user"
    env = clean_env(tmp_path, user)
    installed = user / "extensions" / "user_default" / "polar_render"
    assert install(sys.executable, zip_path, env) == str(installed)
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
    """On each Blender: the zip installs and enables, a Principled + Polarising BSDF scene renders every
    pass, the Virtual Polariser's composite is Malus' law on the passes, the Polar Denoise group
    denoises, and a material edit re-exports the material alone in the viewport (Blender 5.3 also
    flags the geometry of the objects using it)."""
    report, out = smoke(series)
    assert report["blender"].startswith(blender_envs.RELEASES[series][0]), report
    assert report["python"] == blender_envs.RELEASES[series][1]
    for stage in ("enable", "render", "polariser", "denoise", "viewport"):
        assert report.get(stage) == "ok", (stage, report)
    assert report["backend"].startswith("numba")          # the bundled wheels of this Python loaded
    passes = read_multilayer(str(out / "render.exr"))
    assert set(PASSES) <= set(passes)
    assert passes["DoLP"][-2:, :].min() > 0.5               # the floor near Brewster's angle
    assert all(np.isfinite(p).all() for p in passes.values())

    composite = read_multilayer(str(out / "polariser.exr"), layer="Composite")["Combined"][..., :3]
    S = read_multilayer(str(out / "polariser.exr"))
    theta = np.radians(extension_smoke.POLARISER_ANGLE)
    malus = 0.5 * (S["S0"] + np.cos(2 * theta) * S["S1"] + np.sin(2 * theta) * S["S2"])
    np.testing.assert_allclose(composite, malus, rtol=0, atol=1e-6 * S["S0"].max())

    denoised = read_multilayer(str(out / "denoise.exr"), layer="Composite")["Combined"][..., :3]
    noisy = read_multilayer(str(out / "denoise.exr"))["S0"]
    assert np.isfinite(denoised).all() and np.abs(denoised - noisy).max() > 1e-3 * noisy.max()

    counts = report["viewport_counts"]
    assert counts["material"] == {"arrays": 0, "materials": 1}, counts
    assert counts["mesh"]["arrays"] == 1 and counts["modifier"]["arrays"] == 1, counts


@pytest.mark.parametrize("series", blender_envs.CI_SERIES)
def test_every_pass_equals_the_pinned_blenders(smoke, series):
    """The same scene and seed on 4.5 and 5.3 as on 5.0.1: every pass within 1e-6 of max S0
    (measured: identical, as the engine and its compiled kernels are the same code)."""
    reference = read_multilayer(str(smoke("5.0")[1] / "render.exr"))
    other = read_multilayer(str(smoke(series)[1] / "render.exr"))
    scale = reference["S0"].max()
    for name in PASSES:
        assert np.abs(other[name] - reference[name]).max() <= 1e-6 * scale, name
