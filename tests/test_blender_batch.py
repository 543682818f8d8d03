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
