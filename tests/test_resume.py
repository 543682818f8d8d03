"""Resuming an interrupted render gives the image of an uninterrupted one."""

import signal
import subprocess
import sys
import time

import numpy as np

from engine.output.exr import read_stokes_exr
from engine.render.film import film_from_stokes
from engine.render.renderer import Renderer
from engine.scene.loader import load_scene
from tests.conftest import REPO, shared_path


def test_resume_from_stored_means_equals_the_uninterrupted_render():
    scene = load_scene(shared_path("peers", "scenes", "fresnel_sphere.json"))
    scene.camera.width = scene.camera.height = 24
    scene.settings.spp = 6
    scene.settings.batch_rays = 24 * 24              # one pass per unit
    renderer = Renderer(scene)
    full = renderer.render()
    calls = {"n": 0}
    partial = renderer.render(should_stop=lambda: calls.__setitem__("n", calls["n"] + 1) or calls["n"] > 2)
    assert partial.cancelled and partial.film.spp_image().max() < 6
    stored = film_from_stokes(partial.stokes().astype(np.float32), partial.film.spp_image(),
                              partial.film.stderr_luminance().astype(np.float32))
    resumed = renderer.render(resume=stored)
    assert np.all(resumed.film.spp_image() == 6)
    np.testing.assert_allclose(resumed.stokes(), full.stokes(), rtol=2e-6, atol=1e-8)
    np.testing.assert_allclose(resumed.film.stderr_luminance(), full.film.stderr_luminance(), rtol=1e-3, atol=1e-7)


def test_cli_resume_after_ctrl_c(tmp_path):
    scene = shared_path("peers", "scenes", "plane_brewster.json")
    full, part, final = (str(tmp_path / n) for n in ("full.exr", "part.exr", "final.exr"))
    common = ["--spp", "24", "--seed", "5", "--no-previews", "--stderr"]
    subprocess.run([sys.executable, "-m", "engine", "render", scene, "-o", full, *common, "-q"], cwd=REPO, check=True,
                   capture_output=True)
    proc = subprocess.Popen([sys.executable, "-m", "engine", "render", scene, "-o", part, *common], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    buf, deadline = "", time.time() + 120
    while "%" not in buf and time.time() < deadline:
        buf += proc.stderr.read(1)
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=120)
    _, channels, _ = read_stokes_exr(part)
    assert channels["spp"].max() < 24
    done = subprocess.run([sys.executable, "-m", "engine", "render", scene, "-o", final, "--resume", part,
                           "--no-previews", "--stderr", "-q"], cwd=REPO, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    a, ca, ha = read_stokes_exr(full)
    b, cb, hb = read_stokes_exr(final)
    assert np.all(cb["spp"] == 24) and hb["polar.complete"] == 1 and hb["polar.seed"] == 5
    np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-7)


def test_resume_rejects_a_mismatching_file(tmp_path):
    out = str(tmp_path / "small.exr")
    subprocess.run([sys.executable, "-m", "engine", "render", shared_path("peers", "scenes", "conv_s3_check.json"),
                    "-o", out, "--spp", "2", "--no-previews", "-q"], cwd=REPO, check=True, capture_output=True)
    proc = subprocess.run([sys.executable, "-m", "engine", "render",
                           shared_path("peers", "scenes", "plane_brewster.json"),
                           "-o", str(tmp_path / "x.exr"), "--resume", out], cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 2 and "--resume" in proc.stderr and "8×8" in proc.stderr
