"""Batch rendering of .blend files through examples/batch_render.py (bpy module)."""

import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("bpy")

from tests.blender_support import read_multilayer  # noqa: E402
from tests.conftest import REPO  # noqa: E402

MAKE_BLEND = """
import math, sys
sys.path.insert(0, {repo!r})
from tests.blender_support import *
import bpy
load_addon()
scene = empty_scene(width=32, height=24, samples=2)
add_plane(200, polar_material("Floor", "BLACK_GLASS"))
brewster_camera(scene, lens=200.0)
white_world(scene)
scene.frame_start, scene.frame_end = 1, 2
bpy.ops.wm.save_as_mainfile(filepath=sys.argv[1])
"""


def test_batch_script_renders_frames_to_multilayer_exr(tmp_path):
    blend = str(tmp_path / "brewster.blend")
    subprocess.run([sys.executable, "-c", MAKE_BLEND.format(repo=REPO), blend], check=True, cwd=REPO,
                   capture_output=True)
    out = tmp_path / "frames"
    proc = subprocess.run([sys.executable, os.path.join(REPO, "examples", "batch_render.py"), blend,
                           "--frames", "1-2", "--output", str(out), "--samples", "2"],
                          cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    files = sorted(os.listdir(out))
    assert files == ["brewster_0001.exr", "brewster_0002.exr"]
    passes = read_multilayer(str(out / files[0]))
    assert passes["DoLP"][10:14, 14:18].min() > 0.9


def test_batch_script_reports_errors_with_status_1(tmp_path):
    blend = str(tmp_path / "nocam.blend")
    script = MAKE_BLEND.replace("brewster_camera(scene, lens=200.0)", "pass")
    subprocess.run([sys.executable, "-c", script.format(repo=REPO), blend], check=True, cwd=REPO,
                   capture_output=True)
    proc = subprocess.run([sys.executable, os.path.join(REPO, "examples", "batch_render.py"), blend,
                           "--output", str(tmp_path / "o")], cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 1 and "camera" in proc.stderr


def test_thesis_demo_blend_builds_and_renders(tmp_path):
    blend = str(tmp_path / "polar_demo.blend")
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, os.path.join(REPO, "examples", "build_demo_blend.py"), "--blend", blend,
                           "--render", "--samples", "1", "--output", str(out)], cwd=REPO, capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr
    passes = read_multilayer(str(out / "polar_demo_0001.exr"))
    S0 = passes["S0"] @ np.array([0.2126, 0.7152, 0.0722])
    h, w = S0.shape
    # four spheres along the middle row: each is lit, and the gold spheres make circular polarisation
    for x in (0.2, 0.4, 0.6, 0.8):
        assert S0[h // 2 - 3:h // 2 + 3, int(x * w) - 3:int(x * w) + 3].mean() > 0.02
    assert np.abs(passes["S3"]).max() > 1e-3
    import bpy
    from tests.blender_support import load_addon
    load_addon()
    bpy.ops.wm.open_mainfile(filepath=blend)
    models = {m.name: m.node_tree.nodes["Polarising BSDF"].model for m in bpy.data.materials
              if "Polarising BSDF" in m.node_tree.nodes}
    assert {"CONDUCTOR", "TORRANCE_SPARROW", "HTSG", "WEIDLICH_WILKIE", "BLACK_GLASS"} <= set(models.values())


@pytest.fixture(scope="module")
def dask_cluster():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                       silence_logs=40)
    yield cluster
    cluster.close()


@pytest.mark.parametrize("mode", ["samples", "frames"])
def test_batch_script_on_a_dask_cluster(tmp_path, dask_cluster, mode):
    blend = str(tmp_path / "brewster.blend")
    subprocess.run([sys.executable, "-c", MAKE_BLEND.format(repo=REPO), blend], check=True, cwd=REPO,
                   capture_output=True)
    local, remote = tmp_path / "local", tmp_path / "remote"
    base = [sys.executable, os.path.join(REPO, "examples", "batch_render.py"), blend, "--frames", "1-2",
            "--samples", "2"]
    subprocess.run(base + ["--output", str(local)], cwd=REPO, check=True, capture_output=True)
    extra = ["--scheduler", dask_cluster.scheduler_address] + (["--distribute-frames"] if mode == "frames" else [])
    proc = subprocess.run(base + ["--output", str(remote)] + extra, cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for name in ("brewster_0001.exr", "brewster_0002.exr"):
        a = read_multilayer(str(local / name))
        b = read_multilayer(str(remote / name))
        np.testing.assert_array_equal(a["S0"], b["S0"])
        np.testing.assert_array_equal(a["S1"], b["S1"])
