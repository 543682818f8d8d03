"""The command line: a full render to EXR + previews, bad input, and Ctrl-C keeping finished work."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np

from engine.output.exr import read_stokes_exr
from tests.conftest import REPO, shared_path


def run(args, **kw):
    return subprocess.run([sys.executable, "-m", "engine", *args], cwd=REPO, capture_output=True, text=True, **kw)


def test_render_writes_exr_with_all_channels_header_and_previews(tmp_path):
    out = tmp_path / "sub" / "brewster.exr"
    proc = run(["render", shared_path("peers", "scenes", "conv_s3_check.json"), "-o", str(out), "--spp", "16",
                "--seed", "3", "--stderr"])
    assert proc.returncode == 0, proc.stderr
    stokes, channels, header = read_stokes_exr(str(out))
    for name in ("S0.R", "S1.G", "S2.B", "S3.R", "R", "G", "B", "DoLP", "AoLP", "DoCP", "DoP", "spp", "S3.Y.stderr"):
        assert name in channels
    assert stokes.shape == (4, 8, 8, 3)
    assert header["polar.spp"] == 16 and header["polar.seed"] == 3 and header["polar.complete"] == 1
    assert "S3 = 2" in header["polar.conventions"]
    assert np.all(channels["spp"] == 16)
    y = np.einsum("shwc,c->shw", stokes, [0.2126, 0.7152, 0.0722])
    assert np.all(y[3] > 0)                                  # right-circular light everywhere in this scene
    np.testing.assert_allclose(channels["DoCP"], y[3] / y[0], rtol=1e-5)
    for suffix in ("S0", "S1", "S2", "S3", "DoLP", "AoLP"):
        assert (tmp_path / "sub" / f"brewster_{suffix}.png").stat().st_size > 0
    assert "Msamples/s" in proc.stderr


def test_bad_scene_gives_one_line_error_and_status_2(tmp_path):
    scene = json.load(open(shared_path("peers", "scenes", "conv_s3_check.json")))
    scene["materials"]["gold_like"]["k"] = -2.4
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(scene))
    proc = run(["render", str(path), "-o", str(tmp_path / "x.exr")])
    assert proc.returncode == 2
    assert "materials.gold_like.k" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "x.exr").exists()
    proc = run(["render", str(path), "-o", str(tmp_path / "x.exr"), "--spp", "0"])
    assert proc.returncode == 2 and "Traceback" not in proc.stderr


def test_ctrl_c_writes_the_finished_samples(tmp_path):
    out = tmp_path / "partial.exr"
    proc = subprocess.Popen([sys.executable, "-m", "engine", "render",
                             shared_path("peers", "scenes", "plane_brewster.json"), "-o", str(out), "--spp", "400",
                             "--no-previews"], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # Wait for the first progress update (at least one finished batch), then interrupt.
    buf = ""
    deadline = time.time() + 120
    while "%" not in buf and time.time() < deadline:
        buf += proc.stderr.read(1)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    stokes, channels, header = read_stokes_exr(str(out))
    assert header["polar.complete"] == 0
    spp = channels["spp"]
    assert 0 < spp.max() and spp.min() < 400 and header["polar.spp_max"] == spp.max()
    done = spp > 0
    assert np.all(stokes[0][done] > 0) and np.all(np.isfinite(stokes))
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".")]     # no temporary file left


def test_polariser_command_png_exr_sweep_and_errors(tmp_path):
    from engine.output.png import read_png
    from engine.postprocess.filters import malus
    src = str(tmp_path / "s.exr")
    assert run(["render", shared_path("peers", "scenes", "plane_brewster.json"), "-o", src, "--spp", "1",
                "--no-previews", "-q"]).returncode == 0
    stokes, _, _ = read_stokes_exr(src)
    out = tmp_path / "p90.exr"
    assert run(["polariser", src, "--angle", "90", "-o", str(out)]).returncode == 0
    filtered, _, header = read_stokes_exr(str(out))
    np.testing.assert_allclose(filtered[0], malus(stokes.astype(np.float64), 90.0), rtol=1e-5, atol=1e-7)
    assert header["polar.filter"] == "linear"
    png = tmp_path / "rc.png"
    assert run(["polariser", src, "--type", "circular-right", "-o", str(png)]).returncode == 0
    assert read_png(str(png)).shape[:2] == (256, 256)
    sheet = tmp_path / "sweep.png"
    assert run(["polariser", src, "--sweep", "0:180:45", "-o", str(sheet)]).returncode == 0
    assert read_png(str(sheet)).shape[1] > 256 * 2
    bad = run(["polariser", str(tmp_path / "missing.exr"), "-o", str(png)])
    assert bad.returncode == 2 and "does not exist" in bad.stderr
    bad = run(["polariser", src, "--sweep", "10:0:5", "-o", str(sheet)])
    assert bad.returncode == 2 and "--sweep" in bad.stderr


def test_simplified_layers_and_kernels_are_reported_and_overridable(tmp_path):
    with open(os.path.join(REPO, "examples", "thesis_ww_coat_red.json")) as fh:
        scene = json.load(fh)
    scene["materials"]["ball"]["coats"] = [{"n": 1.0}]          # index-matched and clear
    scene["camera"]["width"] = scene["camera"]["height"] = 16
    path = tmp_path / "matched.json"
    path.write_text(json.dumps(scene))
    out = tmp_path / "matched.exr"
    proc = run(["render", str(path), "-o", str(out), "--spp", "1", "--no-previews", "-q"])
    assert proc.returncode == 0, proc.stderr
    assert "simplified: coat 1 of 'ball' is index-matched" in proc.stderr
    assert "kernels: " in proc.stderr
    header = read_stokes_exr(str(out))[2]
    assert "index-matched" in header["polar.simplified"] and header["polar.kernels"]
    proc = run(["render", str(path), "-o", str(out), "--spp", "1", "--no-previews", "-q", "--simplify", "off",
                "--reduce-spectral", "exact"])
    assert proc.returncode == 0, proc.stderr
    assert "simplified:" not in proc.stderr and read_stokes_exr(str(out))[2]["polar.simplified"] == ""
