"""Resuming an interrupted render gives the image of an uninterrupted one."""

import dataclasses
import signal
import subprocess
import sys
import time

import numpy as np

from engine.output.exr import read_stokes_exr
from engine.render.film import film_from_stokes
from engine.render.renderer import Renderer, RenderRequest
from engine.scene.loader import load_scene
from tests.conftest import REPO, shared_path


def test_resume_from_stored_means_equals_the_uninterrupted_render():
    scene = load_scene(shared_path("peers", "scenes", "fresnel_sphere.json"))
    scene.camera.width = scene.camera.height = 24
    # one pass per unit; the stored standard error is the i.i.d. one
    scene.settings = dataclasses.replace(scene.settings, spp=6, batch_rays=24 * 24, sampler="independent")
    renderer = Renderer(scene)
    full = renderer.render()
    calls = {"n": 0}
    partial = renderer.render(RenderRequest(should_stop=lambda: calls.__setitem__("n", calls["n"] + 1)
                                            or calls["n"] > 2))
    assert partial.cancelled and partial.film.spp_image().max() < 6
    stored = film_from_stokes(partial.stokes().astype(np.float32), partial.film.spp_image(),
                              partial.film.stderr_luminance().astype(np.float32))
    resumed = renderer.render(RenderRequest(resume=stored))
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
    assert channels["spp"].min() < 24      # partial (a band may have finished before the signal)
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


# --- refusing to mix two renders -----------------------------------------------------------------

import json  # noqa: E402
import os  # noqa: E402

import pytest  # noqa: E402

from engine import cli  # noqa: E402
from engine.render.resume import scene_fingerprint  # noqa: E402
from tests.cli.test_robustness_cli import small_demo  # noqa: E402

pytestmark = pytest.mark.subprocess


@pytest.fixture(scope="module")
def partial(tmp_path_factory):
    """A finished 2-spp render of the small demo (seed 4) and the folder of its scene."""
    d = tmp_path_factory.mktemp("resume")
    scene = small_demo(d)
    out = str(d / "part.exr")
    assert cli.main(["render", scene, "-o", out, "--seed", "4", "--no-previews", "-q"]) == 0
    return d, scene, out


REFUSED = {
    "max depth": ({}, ["--max-depth", "3"], "max_depth"),
    "polarisation": ({}, ["--polarisation", "linear"], "polarisation"),
    "spectral": ({}, ["--spectral", "mono"], "spectral"),
    "reduce spectral": ({}, ["--reduce-spectral", "exact"], "reduce_spectral"),
    "simplify": ({}, ["--simplify", "off"], "simplify"),
    "rr depth": ({"render.rr_depth": 3}, [], "rr_depth"),
    "material parameter": ({"materials.glass.n": 1.6}, [], "scene"),
    "light": ({"lights.0.radiance": 2.0}, [], "scene"),
    "geometry": ({"objects.0.radius": 0.9}, [], "scene"),
    "camera": ({"camera.fov_deg": 35}, [], "scene"),
}


@pytest.mark.parametrize("case", list(REFUSED))
def test_resume_refuses_another_render_naming_the_difference(case, partial, tmp_path, capsys):
    _, _, part = partial
    changes, args, named = REFUSED[case]
    scene = small_demo(tmp_path, **changes)
    status = cli.main(["render", scene, "-o", str(tmp_path / "x.exr"), "--resume", part, "--spp", "4", "-q",
                       "--no-previews", *args])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("error: --resume: 'part.exr' is another render: ") and named in lines[0]
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize("changes, args", [
    ({}, []),                                                            # the same render, more samples
    ({"render.batch_rays": 2048, "render.threads": 1}, ["--exposure", "2"]),   # what does not change the estimator
    ({"render.spp": 64}, []),                                            # the scene's own count is not checked
])
def test_resume_accepts_what_does_not_change_the_estimator(changes, args, partial, tmp_path, capsys):
    _, _, part = partial
    scene = small_demo(tmp_path, **changes)
    out = tmp_path / "more.exr"
    status = cli.main(["render", scene, "-o", str(out), "--resume", part, "--spp", "5", "-q", "--no-previews", *args])
    assert status == 0, capsys.readouterr().err
    from engine.output.exr import read_stokes_exr
    _, channels, header = read_stokes_exr(str(out))
    assert np.all(channels["spp"] == 5) and header["polar.seed"] == 4 and header["polar.complete"] == 1


def test_resume_refuses_files_without_a_scene_fingerprint(partial, tmp_path, capsys):
    from engine.output.exr import write_stokes_exr
    _, scene, part = partial
    stokes, channels, header = read_stokes_exr(part)
    meta = {k: v for k, v in header.items() if k.startswith("polar.") and k not in ("polar.scene_hash",
                                                                                    "polar.conventions")}
    old = str(tmp_path / "old.exr")
    write_stokes_exr(old, stokes, metadata=meta, extra={"spp": channels["spp"]})
    status = cli.main(["render", scene, "-o", str(tmp_path / "x.exr"), "--resume", old, "-q"])
    err = capsys.readouterr().err
    assert status == 2 and "--resume" in err and "fingerprint" in err


def test_scene_fingerprint_is_the_scene_content_not_the_file(tmp_path):
    a = load_scene(small_demo(tmp_path, "a.json"))
    os.makedirs(tmp_path / "elsewhere")
    with open(small_demo(tmp_path, "b.json", spp=99, **{"render.max_depth": 3})) as fh:
        reformatted = json.dumps(json.load(fh), indent=4, sort_keys=True)
    (tmp_path / "elsewhere" / "c.json").write_text(reformatted)
    same = [load_scene(str(tmp_path / "b.json")), load_scene(str(tmp_path / "elsewhere" / "c.json"))]
    assert all(scene_fingerprint(s) == scene_fingerprint(a) for s in same)
    hashes = {scene_fingerprint(load_scene(small_demo(tmp_path, f"d{i}.json", **{k: v})))
              for i, (k, v) in enumerate([("materials.chalk.albedo", [0.8, 0.8, 0.7]), ("materials.floor.n", 1.5001),
                                           ("objects.1.center", [0.0, 0.0, 1.0001]), ("camera.width", 17)])}
    assert len(hashes) == 4 and scene_fingerprint(a) not in hashes


COATED_CHALK = {"materials.chalk": {"type": "weidlich_wilkie", "base": {"type": "lambert", "albedo": 0.6},
                                    "coats": [{"n": 1.5, "distribution": "beckmann", "m": 0.1}]}}


@pytest.mark.parametrize("spectral", ["spectral", "mono"])
def test_scene_fingerprint_does_not_change_when_the_scene_is_rendered(tmp_path, spectral):
    """Lazily filled caches (a measured metal's sRGB triple, a rough coat's albedo table) are not part
    of what a scene renders: found when the fingerprint of the demo differed in a pytest worker that
    had run an RGB-mode test first, so a resume there would have refused its own file."""
    from engine.render.renderer import Renderer
    from engine.spectral.ior import NAMED_METALS, named_ior
    scene = load_scene(small_demo(tmp_path, **COATED_CHALK))
    before = scene_fingerprint(scene)
    scene.settings = dataclasses.replace(scene.settings, spectral=spectral)
    Renderer(scene).render()
    for name in NAMED_METALS:                          # the shared, cached (n, κ) tables of every metal
        for spectrum in named_ior(name):
            spectrum.linear_srgb()
    for material in scene.materials.values():
        if hasattr(material, "albedo_table") and not material.coat.smooth:
            material.albedo_table()
    assert scene_fingerprint(scene) == before
    assert scene_fingerprint(load_scene(small_demo(tmp_path, **COATED_CHALK))) == before


def test_scene_fingerprint_is_the_same_in_another_process(tmp_path):
    path = small_demo(tmp_path)
    code = ("import sys; from engine.scene.loader import load_scene; from engine.render.resume import "
            "scene_fingerprint; print(scene_fingerprint(load_scene(sys.argv[1])))")
    other = subprocess.run([sys.executable, "-c", code, path], cwd=REPO, capture_output=True, text=True, check=True,
                           env={**os.environ, "PYTHONHASHSEED": "123"})
    assert other.stdout.strip() == scene_fingerprint(load_scene(path))
