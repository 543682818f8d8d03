"""The command line never loses a finished render and answers user mistakes with one line.

Most cases run ``engine.cli.main`` in this process (fast); the signal cases run the CLI as a
subprocess and signal it after its first progress output.  Renders use examples/demo.json at
16×8 pixels and a few samples.
"""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import engine.output.exr as exr_mod
from engine import cli
from engine.output.exr import read_stokes_exr, write_stokes_exr
from tests.conftest import REPO

DEMO = os.path.join(REPO, "examples", "demo.json")


def small_demo(directory, name="scene.json", spp=2, **changes):
    """A copy of examples/demo.json at 16×8 pixels and ``spp`` samples; ``changes`` are applied
    as dotted paths, e.g. ``{"materials.glass.n": 1.6}``."""
    with open(DEMO) as fh:
        scene = json.load(fh)
    scene["camera"]["width"], scene["camera"]["height"] = 16, 8
    scene["render"]["spp"] = spp
    for path, value in changes.items():
        node = scene
        *parents, last = path.split(".")
        for key in parents:
            node = node[int(key)] if isinstance(node, list) else node[key]
        node[int(last) if isinstance(node, list) else last] = value
    path = os.path.join(str(directory), name)
    with open(path, "w") as fh:
        json.dump(scene, fh)
    return path


def run_cli(capsys, *args):
    """(exit status, stdout, stderr) of ``python -m engine ARGS`` run in this process."""
    status = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return status, out, err


def error_lines(err):
    return [line for line in err.splitlines() if line.startswith("error:")]


def assert_one_line_error(status, err, field):
    assert status == 2, err
    assert "Traceback" not in err
    lines = error_lines(err)
    assert len(lines) == 1 and lines[0].startswith(f"error: {field}: "), err


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("scenes")
    small_demo(d)
    return d


@pytest.fixture
def unwritable_dir(tmp_path):
    """A folder in which no file can be created (chmod as a user; /sys as root, where chmod does not bind)."""
    d = tmp_path / "ro"
    d.mkdir()
    os.chmod(d, 0o500)
    try:
        open(d / "probe", "w").close()
    except OSError:
        yield str(d)
        os.chmod(d, 0o700)
        return
    os.remove(d / "probe")
    os.chmod(d, 0o700)
    try:
        open("/sys/polar-probe.exr", "w").close()
    except OSError:
        yield "/sys"
        return
    pytest.skip("no folder here refuses new files")


# --- checked before rendering --------------------------------------------------------------------

def _bad_render_args(tmp_path, unwritable):
    folder = tmp_path / "existing.exr"
    folder.mkdir()
    text = tmp_path / "notes.exr"
    text.write_text("not an EXR\n")
    ok = str(tmp_path / "ok.exr")
    return {
        "output is a folder": (["-o", str(folder)], "-o"),
        "output folder refuses files": (["-o", os.path.join(unwritable, "out.exr")], "-o"),
        "output name too long": (["-o", str(tmp_path / ("n" * 252 + ".exr"))], "-o"),
        "output is not .exr": (["-o", str(tmp_path / "x.png")], "-o"),
        "exposure overflows": (["-o", ok, "--exposure", "1e308"], "--exposure"),
        "exposure nan": (["-o", ok, "--exposure", "nan"], "--exposure"),
        "exposure inf": (["-o", ok, "--exposure", "inf"], "--exposure"),
        "scheduler not a url": (["-o", ok, "--scheduler", "not a url"], "--scheduler"),
        "resume a text file": (["-o", ok, "--resume", str(text)], "--resume"),
        "resume a folder": (["-o", ok, "--resume", str(tmp_path)], "--resume"),
        "resume a missing file": (["-o", ok, "--resume", str(tmp_path / "missing.exr")], "--resume"),
    }


BAD_RENDER_CASES = ["output is a folder", "output folder refuses files", "output name too long", "output is not .exr",
                    "exposure overflows", "exposure nan", "exposure inf", "scheduler not a url",
                    "resume a text file", "resume a folder", "resume a missing file"]


@pytest.mark.parametrize("case", BAD_RENDER_CASES)
def test_render_mistakes_are_one_line_errors_before_rendering(case, tmp_path, scene_dir, unwritable_dir, capsys):
    args, field = _bad_render_args(tmp_path, unwritable_dir)[case]
    status, out, err = run_cli(capsys, "render", scene_dir / "scene.json", "-q", *args)
    assert_one_line_error(status, err, field)
    assert "samples in" not in err and out == ""                      # nothing was rendered


def test_longest_legal_file_name_renders(tmp_path, scene_dir, capsys):
    out = tmp_path / ("n" * 245 + ".exr")                            # 249 bytes: temp names must not add to it
    status, _, err = run_cli(capsys, "render", scene_dir / "scene.json", "-o", out, "-q")
    assert status == 0, err
    assert read_stokes_exr(str(out))[2]["polar.complete"] == 1
    assert not [n for n in os.listdir(tmp_path) if n.startswith(".")]


def test_stale_temporaries_of_killed_writes_are_removed(tmp_path, scene_dir, capsys):
    old = time.time() - 3600
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = [tmp_path / f".polar-tmp-{dead.pid}-abcdefgh.exr", tmp_path / ".out.exr.k2j4x9q1.tmp.exr"]
    kept = [tmp_path / f".polar-tmp-{os.getppid()}-abcdefgh.exr",    # its writer still runs
            tmp_path / ".polar-tmp-1-abcdefgh.png.bak",             # not our pattern
            tmp_path / ".hidden-notes.exr"]
    for p in stale + kept:
        p.write_bytes(b"partial")
        os.utime(p, (old, old))
    fresh = tmp_path / f".polar-tmp-{dead.pid}-zyxwvuts.exr"          # written after this process started
    fresh.write_bytes(b"partial")
    status, _, err = run_cli(capsys, "render", scene_dir / "scene.json", "-o", tmp_path / "out.exr", "-q",
                             "--no-previews")
    assert status == 0, err
    for p in stale:
        assert not p.exists()
        assert str(p) in err
    for p in kept + [fresh]:
        assert p.exists()


# --- a failing write keeps the samples -----------------------------------------------------------

def test_write_failure_saves_finished_samples_to_a_rescue_file(tmp_path, scene_dir, capsys, monkeypatch):
    reference = tmp_path / "ref.exr"
    assert run_cli(capsys, "render", scene_dir / "scene.json", "-o", reference, "-q", "--no-previews")[0] == 0
    target = tmp_path / "out.exr"
    real = exr_mod.write_stokes_exr

    def failing(path, *a, **kw):
        if os.path.abspath(path) == str(target):
            raise PermissionError(13, "Permission denied", str(target))
        return real(path, *a, **kw)

    monkeypatch.setattr(exr_mod, "write_stokes_exr", failing)
    status, out, err = run_cli(capsys, "render", scene_dir / "scene.json", "-o", target, "-q", "--stderr")
    assert status == 1 and "Traceback" not in err
    (line,) = error_lines(err)
    assert line.startswith("error: -o: cannot write") and "Permission denied" in line
    rescue = line.split("finished samples saved to ")[1]
    assert os.path.basename(rescue).startswith("polar-rescue-") and rescue.endswith(".exr")
    stokes, channels, header = read_stokes_exr(rescue)
    np.testing.assert_array_equal(stokes, read_stokes_exr(str(reference))[0])
    assert header["polar.rescued_from"] == str(target) and "S0.Y.stderr" in channels
    assert not target.exists() and out == ""
    # the rescue file is an ordinary Polar EXR: the render continues from it
    status, _, err = run_cli(capsys, "render", scene_dir / "scene.json", "-o", tmp_path / "more.exr", "-q",
                             "--no-previews", "--resume", rescue, "--spp", "3")
    assert status == 0, err
    assert np.all(read_stokes_exr(str(tmp_path / "more.exr"))[1]["spp"] == 3)


def test_values_an_exr_cannot_hold_are_rescued_losslessly(tmp_path, scene_dir, capsys, monkeypatch):
    from engine.render.renderer import RenderResult
    monkeypatch.setattr(RenderResult, "stokes", lambda self: self.film.mean() * 1e39)   # beyond float32
    target = tmp_path / "hot.exr"
    status, _, err = run_cli(capsys, "render", scene_dir / "scene.json", "-o", target, "-q", "--stderr")
    assert status == 1 and "Traceback" not in err
    (line,) = error_lines(err)
    assert "not finite as float32" in line
    rescue = line.split("finished samples saved to ")[1]
    assert rescue.endswith(".npz") and not target.exists()
    data = np.load(rescue)
    assert data["stokes"].dtype == np.float64 and np.all(np.isfinite(data["stokes"]))
    assert data["stokes"][0].max() > 1e38 and np.all(data["spp"] == 2)
    assert json.loads(str(data["metadata"]))["polar.complete"] == 1


def test_a_preview_blocked_by_a_folder_is_a_warning_and_keeps_the_exr(tmp_path, scene_dir, capsys):
    (tmp_path / "out_DoLP.png").mkdir()
    status, _, err = run_cli(capsys, "render", scene_dir / "scene.json", "-o", tmp_path / "out.exr", "-q")
    assert status == 0, err
    assert [line for line in err.splitlines() if line.startswith("warning: previews not written")]
    assert "Traceback" not in err and not error_lines(err)
    assert read_stokes_exr(str(tmp_path / "out.exr"))[2]["polar.complete"] == 1


@pytest.mark.parametrize("signum, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_while_writing_does_not_discard_the_render(signum, status, tmp_path, scene_dir, capsys, monkeypatch):
    real = exr_mod.write_stokes_exr

    def impatient(path, *a, **kw):
        os.kill(os.getpid(), signum)            # twice: an impatient user / a farm repeating itself
        os.kill(os.getpid(), signum)
        return real(path, *a, **kw)

    monkeypatch.setattr(exr_mod, "write_stokes_exr", impatient)
    got, _, err = run_cli(capsys, "render", scene_dir / "scene.json", "-o", tmp_path / "out.exr", "-q",
                          "--no-previews")
    assert got == status, err
    _, channels, header = read_stokes_exr(str(tmp_path / "out.exr"))
    assert header["polar.complete"] == 1 and np.all(channels["spp"] == 2)
    assert signal.getsignal(signum) is not None and "Traceback" not in err


def _render_until_progress(scene, out, *extra):
    """Start a CLI render and return the process once it has printed its first progress."""
    proc = subprocess.Popen([sys.executable, "-m", "engine", "render", scene, "-o", out, "--no-previews", *extra],
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    buf, deadline = "", time.time() + 120
    while "%" not in buf and time.time() < deadline:
        buf += proc.stderr.read(1)
    return proc


def test_sigterm_writes_the_finished_samples_and_exits_143(tmp_path, scene_dir, capsys):
    out = str(tmp_path / "part.exr")
    proc = _render_until_progress(str(scene_dir / "scene.json"), out, "--spp", "4000", "--seed", "9")
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    stokes, channels, header = read_stokes_exr(out)
    # partial: some pixels unfinished (a band on the other worker process may have finished all its samples)
    assert header["polar.complete"] == 0 and channels["spp"].max() > 0 and channels["spp"].min() < 4000
    assert np.all(np.isfinite(stokes)) and "Traceback" not in err
    assert not [n for n in os.listdir(tmp_path) if n.startswith(".")]
    # and it continues like an interrupted render
    status, _, err = run_cli(capsys, "render", scene_dir / "scene.json", "-o", tmp_path / "final.exr", "--resume",
                             out, "--spp", int(channels["spp"].max()) + 8, "--no-previews", "-q")
    assert status == 0, err


# --- mueller and polariser -----------------------------------------------------------------------

@pytest.mark.parametrize("theta_i, theta_o, phi_o", [(90, 90, 0), (90, 90, 180), (90, 89.9, 0), (90, 89.9, 180),
                                                     (60, 60, 180), (0, 0, 0), (30, 45, 0)])
@pytest.mark.parametrize("model, params", [("fresnel", {"n": 1.5}), ("fresnel", {"n": 0.2, "k": 3.0}),
                                           ("torrance_sparrow", {"n": 1.5, "m": 0.4})])
def test_scattering_basis_is_defined_and_equals_sp_in_the_plane_of_incidence(theta_i, theta_o, phi_o, model, params):
    """In the plane of incidence both bases have s = ±ŷ on both beams (a 180° turn leaves a Mueller
    matrix unchanged), so they must agree — also where k_i ∥ k_o ∥ x̂ leaves the plane undefined."""
    from engine.materials.catalogue import make_model
    from engine.materials.evaluate import mueller_at
    m = make_model(model, {k: str(v) for k, v in params.items()})
    a = mueller_at(m, theta_i, theta_o, phi_o, 550.0, "scattering")
    b = mueller_at(m, theta_i, theta_o, phi_o, 550.0, "sp")
    for key in ("brdf", "delta"):
        if a[key] is None:
            assert b[key] is None
            continue
        assert np.all(np.isfinite(a[key]))
        np.testing.assert_allclose(a[key], b[key], atol=1e-12)


def test_grazing_mirror_matrix_is_the_limit_of_near_grazing():
    from engine.materials.catalogue import make_model
    from engine.materials.evaluate import mueller_at
    m = make_model("fresnel", {"n": "0.2", "k": "3"})
    at = np.array(mueller_at(m, 90, 90, 0, 550.0, "scattering")["delta"])
    near = np.array(mueller_at(m, 90 - 1e-7, 90 - 1e-7, 0, 550.0, "scattering")["delta"])
    np.testing.assert_allclose(at, near, atol=1e-6)


@pytest.mark.parametrize("args, field", [
    (["--phi-o", "nan"], "--phi-o"), (["--phi-o", "inf"], "--phi-o"), (["--theta-i", "nan"], "--theta-i"),
    (["--wavelength-nm", "nan"], "--wavelength-nm"),
])
def test_mueller_rejects_non_finite_geometry(args, field, capsys):
    base = {"--theta-i": "30", "--theta-o": "30"}
    for flag, value in zip(args[::2], args[1::2]):
        base[flag] = value
    status, out, err = run_cli(capsys, "mueller", "--model", "fresnel", "--param", "n=1.5",
                               *[x for kv in base.items() for x in kv])
    assert_one_line_error(status, err, field)
    assert out == ""


@pytest.fixture(scope="module")
def small_exr(tmp_path_factory):
    d = tmp_path_factory.mktemp("polariser")
    path = str(d / "s.exr")
    s = np.zeros((4, 6, 5, 3))
    s[0], s[1] = 1.0, 0.5
    write_stokes_exr(path, s)
    return path


@pytest.mark.parametrize("args, field", [
    (["--angle", "inf"], "--angle"), (["--angle", "nan"], "--angle"),
    (["--retardance", "inf"], "--retardance"), (["--retarder-angle", "nan"], "--retarder-angle"),
    (["--sweep", "0:inf:1"], "--sweep"), (["--sweep", "nan:nan:1"], "--sweep"),
    (["--sweep", "0:1:1e-7"], "--sweep"), (["--sweep", "0:180"], "--sweep"),
    (["--exposure", "nan"], "--exposure"), (["--exposure", "1e308"], "--exposure"),
    (["--extinction", "nan"], "--extinction"),
])
def test_polariser_mistakes_are_one_line_errors(args, field, small_exr, tmp_path, capsys):
    status, out, err = run_cli(capsys, "polariser", small_exr, "-o", tmp_path / "p.png", *args)
    assert_one_line_error(status, err, field)
    assert not (tmp_path / "p.png").exists()


@pytest.mark.parametrize("what", ["text file", "folder"])
def test_polariser_input_that_is_not_an_exr(what, tmp_path, capsys):
    src = tmp_path / "in.exr"
    if what == "folder":
        src.mkdir()
    else:
        src.write_text("hello\n")
    status, _, err = run_cli(capsys, "polariser", src, "-o", tmp_path / "p.png")
    assert_one_line_error(status, err, "EXR")


def test_polariser_output_blocked_by_a_folder(small_exr, tmp_path, capsys):
    (tmp_path / "p.png").mkdir()
    status, _, err = run_cli(capsys, "polariser", small_exr, "-o", tmp_path / "p.png")
    assert_one_line_error(status, err, "-o")


def test_polariser_sweep_at_the_frame_limit_is_accepted(small_exr, tmp_path, capsys):
    status, _, err = run_cli(capsys, "polariser", small_exr, "-o", tmp_path / "sheet.png",
                               "--sweep", f"0:{cli.MAX_SWEEP_FRAMES - 1}:1")
    assert status == 0, err
    status, _, err = run_cli(capsys, "polariser", small_exr, "-o", tmp_path / "sheet.png",
                             "--sweep", f"0:{cli.MAX_SWEEP_FRAMES}:1")
    assert_one_line_error(status, err, "--sweep")


def test_a_signal_before_any_sample_keeps_an_existing_output(tmp_path, scene_dir, capsys, monkeypatch):
    from engine.render.renderer import Renderer
    out = tmp_path / "out.exr"
    out.write_bytes(b"an earlier, finished render")
    real = Renderer.render

    def stopped_at_once(self, *a, **kw):
        os.kill(os.getpid(), signal.SIGTERM)     # arrives before the first unit is submitted
        return real(self, *a, **kw)

    monkeypatch.setattr(Renderer, "render", stopped_at_once)
    status, stdout, err = run_cli(capsys, "render", scene_dir / "scene.json", "-o", out, "-q")
    assert status == 143 and "nothing written" in err and stdout == ""
    assert out.read_bytes() == b"an earlier, finished render"


def test_a_closed_stdout_pipe_ends_quietly(monkeypatch, capsys):
    """`python -m engine mueller ... | head -c 10`: the reader leaving is exit 141 without a traceback."""
    import io

    from engine.cli import main as cli_main

    class ClosedPipe(io.StringIO):
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr("sys.stdout", ClosedPipe())
    assert cli_main(["mueller", "--model", "fresnel", "--param", "n=1.5", "--theta-i", "30", "--theta-o", "30"]) == 141
    assert "Traceback" not in capsys.readouterr().err
