"""Issue 32, the command line: adaptive sampling, `estimate`, resuming adaptive renders and `polariser`
fail cleanly too.

Every run ends with status 0 and finite output, or status 2 and exactly one ``error:`` line naming the
option — never a traceback, a hang, dropped samples or a silent misreading.  Per class of failure a
table of cases, then hypothesis fuzzers over the adaptive/estimate options, over damaged resume files
and over polariser inputs and options.

Renders are 8×8 pixels of examples/demo.json with coarse spheres and a few samples (≈ 20 ms each):
runs call ``engine.cli.main`` in this process (as tests/cli/test_robustness_cli.py does) under an alarm
that fails a run taking longer than :data:`DEADLINE` seconds; the cases that could block in a system
call (a FIFO) run the CLI as a subprocess with a timeout.
"""

import contextlib
import io
import json
import math
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import OpenEXR
import pytest
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis.control import currently_in_test_context
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from engine import cli
from engine.output.exr import _check_metadata, read_stokes_exr, write_stokes_exr
from engine.output.png import read_png
from engine.render.adaptive import QUANTITIES, STATE_PREFIX, _float64_to_words, _words_to_float64
from tests.conftest import REPO

DEMO = os.path.join(REPO, "examples", "demo.json")
#: Seconds a single in-process run may take before it counts as a hang.
DEADLINE = 60
#: Adaptive options of the renders that are resumed (the base file: 4 spp, continued to 6).
ADAPTIVE = ["--noise-threshold=0.1", "--min-spp=2"]
FUZZ = settings(max_examples=100, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


class Hang(BaseException):
    """A run exceeded :data:`DEADLINE` (BaseException: no ``except Exception`` in the CLI swallows it)."""


@contextlib.contextmanager
def deadline(seconds=DEADLINE):
    def on_alarm(signum, frame):
        raise Hang(f"the command did not finish within {seconds} s")
    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def run(*args):
    """(exit status, stdout, stderr) of ``python -m engine ARGS`` run in this process."""
    out, err = io.StringIO(), io.StringIO()
    with deadline(), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = cli.main([str(a) for a in args])
        except SystemExit as e:           # argparse's own refusals (a word where an integer belongs)
            status = e.code
    return status, out.getvalue(), err.getvalue()


def run_process(*args, timeout=120):
    """(exit status, stderr) of the CLI in a subprocess; a timeout fails the test (a hang)."""
    p = subprocess.run([sys.executable, "-m", "engine", *map(str, args)], cwd=REPO, capture_output=True,
                       text=True, timeout=timeout)
    return p.returncode, p.stderr


def error_lines(err):
    return [line for line in err.splitlines() if "error:" in line]


def assert_refused(status, err, field, *words):
    """Status 2, no traceback, exactly one line ``error: FIELD: …`` holding ``words``."""
    assert status == 2, err
    assert "Traceback" not in err
    lines = error_lines(err)
    assert len(lines) == 1 and lines[0].startswith(f"error: {field}: "), err
    for w in words:
        assert w in lines[0], (w, err)


def assert_finite_exr(path):
    stokes, channels, _ = read_stokes_exr(path)
    assert np.isfinite(stokes).all()
    for name, values in channels.items():
        assert np.isfinite(values).all(), name


def assert_clean(status, err, exr=None, png=None):
    """Status 0 with finite output, or status 2 with exactly one error line (ours, or argparse's usage
    error for a word where a number belongs); never a traceback."""
    assert "Traceback" not in err, err
    lines = error_lines(err)
    if currently_in_test_context():        # the fuzzers' statistics (--hypothesis-show-statistics)
        event(f"status {status}" + (f" {lines[0].split(':')[1].strip()}" if len(lines) == 1 else ""))
    if status == 0:
        assert not lines, err
        if exr is not None:
            assert_finite_exr(exr)
        if png is not None:
            assert read_png(str(png)).size > 0
        return
    assert status == 2, (status, err)
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ") or re.match(r"python -m engine \w+: error: argument ", lines[0]), err


# --- scenes and files ------------------------------------------------------------------------------

def tiny_scene(directory, spp=4):
    with open(DEMO) as fh:
        scene = json.load(fh)
    scene["camera"]["width"], scene["camera"]["height"] = 8, 8
    scene["render"]["spp"] = spp
    for obj in scene["objects"]:
        if obj["shape"] == "sphere":
            obj["subdivisions"] = 2
    path = os.path.join(str(directory), "tiny.json")
    with open(path, "w") as fh:
        json.dump(scene, fh)
    return path


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("adaptive")


@pytest.fixture(scope="module")
def scene(work):
    return tiny_scene(work)


@pytest.fixture(scope="module")
def adaptive_exr(work, scene):
    """A finished adaptive render (4 spp, --min-spp 2) with its state: the file the resume cases damage."""
    path = work / "base.exr"
    status, _, err = run("render", scene, "-o", path, "--noise-threshold=1e-9", "--min-spp=2", "-q", "--no-previews")
    assert status == 0, err
    _, channels, _ = read_stokes_exr(path)
    assert f"{STATE_PREFIX}.first.count.hi" in channels and f"{STATE_PREFIX}.cost.hi" in channels
    return path


def write_raw_exr(path, channels, header):
    """Write channels as they are (NaN included) with the header's polar.* entries: a damaged file."""
    hdr = _check_metadata({k: v for k, v in header.items() if k.startswith("polar.")})
    hdr.update(compression=OpenEXR.ZIP_COMPRESSION, type=OpenEXR.scanlineimage)
    OpenEXR.File(hdr, {n: np.ascontiguousarray(a) for n, a in channels.items()}).write(str(path))


def resume(scene, damaged, out, adaptive=True):
    if os.path.exists(out):
        os.remove(out)
    return run("render", scene, "-o", out, "--resume", damaged, "--spp=6", "-q", "--no-previews",
               *(ADAPTIVE if adaptive else []))


def set_value(channels, name, value, pixel=None):
    """Store the float64 ``value`` in the state array ``name`` (its .hi/.lo words), at one pixel or all."""
    hi, lo = (channels[f"{STATE_PREFIX}.{name}.{w}"].copy() for w in ("hi", "lo"))
    h, low = _float64_to_words(np.array([value], np.float64))
    sel = (slice(None), slice(None)) if pixel is None else divmod(pixel, hi.shape[1])
    hi[sel], lo[sel] = h[0], low[0]
    channels[f"{STATE_PREFIX}.{name}.hi"], channels[f"{STATE_PREFIX}.{name}.lo"] = hi, lo


def state_value(channels, name):
    return _words_to_float64(channels[f"{STATE_PREFIX}.{name}.hi"], channels[f"{STATE_PREFIX}.{name}.lo"])


# --- class 1: extreme adaptive thresholds ----------------------------------------------------------

EXTREME_THRESHOLDS = [      # (options, where the counts end: "min" everywhere, or "max" somewhere)
    (["--noise-threshold=1e300"], "min"),
    (["--noise-threshold=1.7976931348623157e308"], "min"),
    (["--noise-threshold=1e300", "--noise-quantity=dolp"], "min"),
    (["--noise-threshold=1e200", "--noise-quantity=stokes"], "min"),
    (["--noise-threshold=1e160", "--noise-quantity=docp"], "min"),
    (["--noise-threshold=90", "--noise-quantity=aolp"], "min"),
    (["--noise-threshold=1e-320"], "max"),
    (["--noise-threshold=5e-324"], "max"),
    (["--noise-threshold=1e-300", "--noise-quantity=dolp"], "max"),
    (["--noise-threshold=1e-320", "--noise-quantity=stokes", "--time-limit=1e300"], "max"),
]


@pytest.mark.parametrize("options, ends", EXTREME_THRESHOLDS)
def test_extreme_thresholds_render_to_the_minimum_or_the_maximum(options, ends, scene, work):
    out = work / "extreme.exr"
    status, _, err = run("render", scene, "-o", out, "--spp=6", "--min-spp=2", "-q", "--no-previews", *options)
    assert_clean(status, err, exr=out)
    assert status == 0, err
    _, channels, header = read_stokes_exr(out)
    spp = channels["spp"]
    if ends == "min":           # a huge threshold: every tile stops after the minimum samples
        assert (spp == 2).all() and header["polar.stop_reason"] == "threshold"
    else:                       # a tiny one: the noisy tiles sample to the maximum
        assert spp.max() == 6 and spp.min() >= 2 and header["polar.stop_reason"] == "max_spp"
    assert header["polar.noise_threshold"] == float(options[0].split("=")[1])


@pytest.mark.parametrize("value", ["inf", "-inf", "nan", "0", "-0", "-1e-300", "1e309"])
def test_thresholds_that_are_not_finite_positive_numbers_are_refused(value, scene, work):
    status, _, err = run("render", scene, "-o", work / "x.exr", f"--noise-threshold={value}", "-q")
    assert_refused(status, err, "--noise-threshold", "finite number > 0")
    status, _, err = run("estimate", scene, f"--target=s0:{value}", "--pilot-spp=2")
    assert_refused(status, err, "--target")


def target_lines(out):
    lines = [line for line in out.splitlines() if line.startswith("target ")]
    assert lines and not re.search(r"\b(nan|inf)\b", "\n".join(lines)), out
    return lines


@pytest.mark.parametrize("target, ends", [("s0:1e300", "min"), ("dolp:1.7976931348623157e308", "min"),
                                          ("aolp:90", "min"), ("docp:1e200", "min"), ("s0:5e-324", "max"),
                                          ("stokes:1e-320", "max"), ("dolp:1e-300", "max")])
def test_estimate_with_extreme_targets_predicts_the_minimum_or_the_maximum(target, ends, scene):
    status, out, err = run("estimate", scene, f"--target={target}", "--spp=64", "--min-spp=4", "--pilot-spp=4")
    assert_clean(status, err)
    assert status == 0, err
    (line,) = target_lines(out)
    median, uniform = (int(v) for v in re.search(r"adaptive median (\d+) spp.*uniform (\d+) spp", line).groups())
    if ends == "min":
        assert median == 4 and uniform == 4, line
    else:
        assert uniform == 64 and "would stop at the maximum spp" in line, line


# --- class 2: a time limit before the first pass ends ----------------------------------------------

@pytest.mark.parametrize("options", [["--time-limit=1e-9"], ["--time-limit=5e-324"],
                                     ["--time-limit=1e-300", "--noise-threshold=0.1"],
                                     ["--time-limit=1e-9", "--noise-threshold=0.5", "--noise-quantity=dolp"]])
@pytest.mark.parametrize("existing", [False, True])
def test_a_time_limit_before_any_sample_writes_nothing(options, existing, scene, work):
    out = work / "limited.exr"
    if existing:
        out.write_bytes(b"an earlier render")
    elif out.exists():
        out.unlink()
    status, stdout, err = run("render", scene, "-o", out, "-q", *options)
    assert_refused(status, err, "--time-limit", "before any sample", "nothing written")
    assert stdout == ""
    assert out.read_bytes() == b"an earlier render" if existing else not out.exists()
    assert not [f for f in os.listdir(work) if f.startswith(".polar-tmp")]


@pytest.mark.parametrize("value", ["-1", "nan", "inf", "1e309", "-1e-300"])
def test_bad_time_limits_are_refused(value, scene, work):
    status, _, err = run("render", scene, "-o", work / "x.exr", f"--time-limit={value}", "-q")
    assert_refused(status, err, "--time-limit", "≥ 0")


@pytest.mark.parametrize("value", ["1e300", "1.7976931348623157e308", "0"])
def test_a_huge_time_limit_is_no_limit(value, scene, work):
    out = work / "long.exr"
    status, _, err = run("render", scene, "-o", out, f"--time-limit={value}", "--spp=4", "--min-spp=2", "-q",
                         "--no-previews", *(["--noise-threshold=0.5"] if value == "0" else []))
    assert_clean(status, err, exr=out)
    assert status == 0
    assert read_stokes_exr(out)[2]["polar.stop_reason"] in ("threshold", "max_spp")


# --- class 3: estimate's bounds are render's, and its work is bounded ------------------------------

SHARED_OPTION_MISTAKES = [      # the same options of render and estimate: the same refusal
    ["--spp=0"], ["--spp=1"], ["--spp=16777217"], ["--spp=1000000000000"], ["--spp=-5"],
    ["--spp=" + "9" * 40], ["--seed=-1"], ["--seed=9223372036854775808"], ["--seed=18446744073709551616"],
    ["--min-spp=1"], ["--min-spp=0"], ["--min-spp=-3"], ["--spp=64", "--min-spp=65"],
    ["--min-spp=" + "9" * 30], ["--spp=1e12"], ["--seed=1.5"], ["--min-spp=nan"],
]


@pytest.mark.parametrize("options", SHARED_OPTION_MISTAKES)
def test_estimate_refuses_exactly_what_render_refuses(options, scene, work):
    r_status, _, r_err = run("render", scene, "-o", work / "x.exr", "--noise-threshold=0.1", "-q", *options)
    e_status, _, e_err = run("estimate", scene, "--target=s0:0.1", "--pilot-spp=2", *options)
    assert r_status == e_status == 2, (r_err, e_err)
    (r_line,), (e_line,) = error_lines(r_err), error_lines(e_err)
    assert "Traceback" not in r_err + e_err
    if r_line.startswith("error: "):
        assert e_line == r_line and re.match(r"error: --(spp|seed|min-spp): ", r_line), (r_line, e_line)
    else:                              # argparse: not an integer at all
        assert r_line.split("error: ")[1] == e_line.split("error: ")[1]


@pytest.mark.parametrize("options", [["--seed=4611686018427387904"], ["--seed=0"], ["--spp=2", "--min-spp=2"],
                                     ["--spp=3", "--min-spp=3"]])
def test_estimate_accepts_what_render_accepts(options, scene, work):
    out = work / "edge.exr"
    status, _, err = run("render", scene, "-o", out, "--noise-threshold=0.1", "-q", "--no-previews", *options)
    assert_clean(status, err, exr=out)
    assert status == 0, err
    status, out_text, err = run("estimate", scene, "--target=s0:0.1", "--pilot-spp=2", *options)
    assert status == 0, err
    target_lines(out_text)


@pytest.mark.parametrize("options, field", [
    (["--pilot-spp=1"], "--pilot-spp"), (["--pilot-spp=4097"], "--pilot-spp"), (["--pilot-spp=-2"], "--pilot-spp"),
    (["--target=aolp:90.001"], "--target"), (["--target=s0"], "--target"), (["--target=x:1"], "--target"),
    (["--target=s0:"], "--target"), (["--target=:0.1"], "--target"), (["--target=s0:0.1:2"], "--target"),
])
def test_estimate_only_mistakes(options, field, scene):
    status, out, err = run("estimate", scene, *([] if any(o.startswith("--target") for o in options)
                                                else ["--target=s0:0.1"]), *options)
    assert_refused(status, err, field)
    assert out == ""


@pytest.mark.parametrize("options", [["--spp=16777216"], ["--spp=16777216", "--min-spp=16777216"],
                                     ["--spp=16777216", "--min-spp=2", "--target=dolp:1e-300"]])
def test_estimate_at_the_render_maximum_finishes_in_seconds(options, scene):
    started = time.perf_counter()
    status, out, err = run("estimate", scene, "--target=s0:0.05", "--pilot-spp=4", *options)
    seconds = time.perf_counter() - started
    assert status == 0, err
    for line in target_lines(out):
        counts = [int(v) for v in re.findall(r"(\d+) spp", line)]
        assert counts and all(2 <= c <= 16777216 for c in counts), line
    assert seconds < 30, seconds            # 200+ s before the round probe was bounded


# --- class 4: damaged adaptive state in a resume file ----------------------------------------------

def _drop(name):
    return lambda ch, hd: ch.pop(name)


def _state(name, value, pixel=None):
    return lambda ch, hd: set_value(ch, name, value, pixel)


def _float(name, value, pixel=0):
    def change(ch, hd):
        a = ch[name].copy()
        a.reshape(-1)[pixel] = value
        ch[name] = a
    return change


def _header(key, value):
    return lambda ch, hd: hd.__setitem__(key, value)


def _as_float(name):
    return lambda ch, hd: ch.__setitem__(name, ch[name].astype(np.float32))


def _first_count_above_spp(ch, hd):
    set_value(ch, "first.count", float(ch["spp"].reshape(-1)[3]) + 2, pixel=3)


DAMAGE = {     # name: (change of channels/header, words the one error line holds)
    "missing B.S0.Y.hi": (_drop(f"{STATE_PREFIX}.B.S0.Y.hi"), [f"{STATE_PREFIX}.B.S0.Y.hi", "lacks"]),
    "missing A.S0.Y.hi": (_drop(f"{STATE_PREFIX}.A.S0.Y.hi"), [f"{STATE_PREFIX}.A.S0.Y.hi"]),
    "missing sum.S2.G.lo": (_drop(f"{STATE_PREFIX}.sum.S2.G.lo"), [f"{STATE_PREFIX}.sum.S2.G.lo"]),
    "missing first.A.S3.Y.lo": (_drop(f"{STATE_PREFIX}.first.A.S3.Y.lo"), [f"{STATE_PREFIX}.first.A.S3.Y.lo"]),
    "missing first.count.hi": (_drop(f"{STATE_PREFIX}.first.count.hi"), [f"{STATE_PREFIX}.first.count.hi"]),
    "missing cost.lo": (_drop(f"{STATE_PREFIX}.cost.lo"), [f"{STATE_PREFIX}.cost.lo"]),
    "missing spp": (_drop("spp"), ["sample counts"]),
    "NaN in B.S0.Y": (_state("B.S0.Y", math.nan, 5), [f"{STATE_PREFIX}.B.S0.Y", "not finite", "1 pixel"]),
    "+inf in sum.S1.G": (_state("sum.S1.G", math.inf), [f"{STATE_PREFIX}.sum.S1.G", "not finite", "64 pixels"]),
    "-inf in sumsq.S0.Y": (_state("sumsq.S0.Y", -math.inf, 0), [f"{STATE_PREFIX}.sumsq.S0.Y", "not finite"]),
    "NaN in first.A.S1.Y": (_state("first.A.S1.Y", math.nan, 7), [f"{STATE_PREFIX}.first.A.S1.Y", "not finite"]),
    "inf in cost": (_state("cost", math.inf, 1), [f"{STATE_PREFIX}.cost", "not finite"]),
    "a finite wrong sum": (_state("sum.S0.R", 1e30, 9), [f"{STATE_PREFIX}.sum.S0.R", "stored means", "1 pixels"]),
    "a sum off by a little": (lambda ch, hd: set_value(ch, "sum.S3.B", float(state_value(ch, "sum.S3.B")[2, 2])
                                                       * 1.001 + 1e-3, 18), [f"{STATE_PREFIX}.sum.S3.B"]),
    "negative sum of squares": (_state("sumsq.S2.Y", -1.0, 4), [f"{STATE_PREFIX}.sumsq.S2.Y", "negative"]),
    "fractional cost": (_state("cost", 0.5, 2), [f"{STATE_PREFIX}.cost", "whole numbers"]),
    "negative cost": (_state("cost", -4.0, 2), [f"{STATE_PREFIX}.cost", "whole numbers"]),
    "first count above spp": (_first_count_above_spp, [f"{STATE_PREFIX}.first.count", "whole numbers"]),
    "words stored as float": (_as_float(f"{STATE_PREFIX}.A.S2.Y.lo"), [f"{STATE_PREFIX}.A.S2.Y.lo", "uint32"]),
    "NaN in S0.R": (_float("S0.R", np.nan, 3), ["S0…S3", "1 non-finite value"]),
    "inf in the noise channel": (_float("noise", np.inf, 3), ["channel noise", "non-finite"]),
    "NaN counts": (lambda ch, hd: (_as_float("spp")(ch, hd), _float("spp", np.nan)(ch, hd)), ["spp channel"]),
    "counts beyond 2^24": (_float("spp", 2 ** 31, 5), ["spp channel", "16777216"]),
    "seed is a word": (_header("polar.seed", "abc"), ["polar.seed", "'abc'"]),
    "seed is negative": (_header("polar.seed", -1), ["polar.seed"]),
    "seed is a float": (_header("polar.seed", 0.5), ["polar.seed"]),
    "spp is 0": (_header("polar.spp", 0), ["polar.spp"]),
    "spp is NaN": (_header("polar.spp", math.nan), ["polar.spp"]),
    "spp beyond 2^24": (_header("polar.spp", "16777217"), ["polar.spp"]),
}


@pytest.mark.parametrize("damage", sorted(DAMAGE))
@pytest.mark.parametrize("adaptive", [True, False])
def test_a_damaged_resume_file_is_refused_naming_the_file_and_channel(damage, adaptive, adaptive_exr, scene, work):
    stokes, channels, header = read_stokes_exr(adaptive_exr)
    channels, header = dict(channels), dict(header)
    change, words = DAMAGE[damage]
    change(channels, header)
    damaged = work / "damaged.exr"
    write_raw_exr(damaged, channels, header)
    status, _, err = resume(scene, damaged, work / "resumed.exr", adaptive)
    assert_refused(status, err, "--resume", repr(str(damaged)), *words)
    assert not (work / "resumed.exr").exists()


def test_the_undamaged_file_resumes_exactly(adaptive_exr, scene, work):
    _, channels, header = read_stokes_exr(adaptive_exr)
    copy = work / "copy.exr"
    write_raw_exr(copy, channels, header)                 # the test's writer changes nothing that matters
    for source in (adaptive_exr, copy):
        out = work / f"resumed-{os.path.basename(source)}"
        status, _, err = run("render", scene, "-o", out, "--resume", source, "--spp=6", "-q", "--no-previews",
                             "--noise-threshold=1e-9", "--min-spp=2")
        assert_clean(status, err, exr=out)
        assert status == 0 and read_stokes_exr(out)[1]["spp"].max() == 6
    direct = work / "direct.exr"
    assert run("render", scene, "-o", direct, "--spp=6", "--noise-threshold=1e-9", "--min-spp=2", "-q",
               "--no-previews")[0] == 0
    np.testing.assert_array_equal(read_stokes_exr(direct)[0], read_stokes_exr(work / "resumed-copy.exr")[0])


# --- classes 5 and 6: polariser inputs -------------------------------------------------------------

@pytest.fixture(scope="module")
def small_exr(work):
    path = work / "s.exr"
    s = np.zeros((4, 6, 5, 3))
    s[0], s[1] = 1.0, 0.5
    write_stokes_exr(path, s)
    return path


def stokes_file(path, stokes):
    channels = {f"S{k}.{c}": np.ascontiguousarray(stokes[k, :, :, i], np.float32)
                for k in range(4) for i, c in enumerate("RGB")}
    write_raw_exr(path, channels, {})
    return path


NONFINITE = {"one NaN": ([(0, 1, 2, 0)], np.nan, "in 1 of its 30 pixels"),
             "three infs": ([(3, 0, 0, 2), (3, 1, 1, 2), (1, 5, 4, 1)], np.inf, "in 3 of its 30 pixels"),
             "-inf twice in one pixel": ([(2, 2, 2, 0), (0, 2, 2, 1)], -np.inf, "in 1 of its 30 pixels")}
POLARISER_MODES = {"png": ["-o", "p.png"], "exr": ["-o", "p.exr"], "mosaic": ["--mosaic", "-o", "m.exr"],
                   "sweep": ["--sweep", "0:90:45", "-o", "sheet.png"], "circular": ["--type", "circular-left",
                                                                                   "-o", "c.png"]}


@pytest.mark.parametrize("where", sorted(NONFINITE))
@pytest.mark.parametrize("mode", sorted(POLARISER_MODES))
def test_polariser_refuses_non_finite_stokes_and_counts_the_pixels(where, mode, work):
    s = np.ones((4, 6, 5, 3))
    s[1:] = 0.25
    pixels, value, count = NONFINITE[where]
    for idx in pixels:
        s[idx] = value
    src = stokes_file(work / "nonfinite.exr", s)
    args = [a if not a.endswith((".png", ".exr")) else work / ("out-" + a) for a in POLARISER_MODES[mode]]
    status, out, err = run("polariser", src, *args)
    assert_refused(status, err, "EXR", count, "non-finite")
    assert out == "" and not [f for f in os.listdir(work) if f.startswith("out-")]


def test_polariser_values_beyond_float32_are_refused_for_an_exr_and_clip_in_a_png(work):
    s = np.zeros((4, 2, 2, 3), np.float32)
    s[0] = s[1] = s[2] = 3.0e38                    # finite, but ½(S0 + S1 cos + S2 sin) overflows float32
    src = stokes_file(work / "huge.exr", s)
    status, _, err = run("polariser", src, "--angle=22.5", "-o", work / "huge-out.exr")
    assert_refused(status, err, "-o", "float32")
    assert not (work / "huge-out.exr").exists()
    status, _, err = run("polariser", src, "--angle=22.5", "-o", work / "huge-out.png")
    assert_clean(status, err, png=work / "huge-out.png")
    assert status == 0 and (read_png(str(work / "huge-out.png")) == 255).all()


def test_polariser_refuses_a_device_and_follows_a_symlink(small_exr, work):
    status, _, err = run("polariser", "/dev/null", "-o", work / "d.png")
    assert_refused(status, err, "EXR", "not a regular file")
    link = work / "link.exr"
    if not link.exists():
        os.symlink(small_exr, link)
    status, _, err = run("polariser", link, "-o", work / "l.png")
    assert_clean(status, err, png=work / "l.png")
    assert status == 0


@pytest.mark.parametrize("command", ["polariser", "mosaic", "resume", "render scene", "estimate scene"])
def test_a_fifo_without_a_writer_is_refused_not_waited_on(command, scene, work):
    fifo = work / f"{command.replace(' ', '-')}.fifo"
    if not fifo.exists():
        os.mkfifo(fifo)
    args = {"polariser": ["polariser", fifo, "-o", work / "f.png"],
            "mosaic": ["polariser", fifo, "--mosaic", "-o", work / "f.png"],
            "resume": ["render", scene, "-o", work / "f.exr", "--resume", fifo, "-q"],
            "render scene": ["render", fifo, "-o", work / "f.exr", "-q"],
            "estimate scene": ["estimate", fifo, "--target=s0:0.1"]}[command]
    status, err = run_process(*args, timeout=120)
    if command.endswith("scene"):       # the scene loader's messages name no field: "error: scene file …"
        assert status == 2 and "Traceback" not in err and len(error_lines(err)) == 1, err
        assert error_lines(err)[0] == f"error: scene file {str(fifo)!r} is not a regular file (a FIFO, device or " \
                                      "socket)"
    else:
        assert_refused(status, err, "--resume" if command == "resume" else "EXR", "not a regular file")


# --- class 7: options that would be silently ignored -----------------------------------------------

IGNORED = [       # (options, the field named)
    (["--mosaic", "--sweep", "0:90:45"], "--sweep"), (["--mosaic", "--type", "linear"], "--type"),
    (["--mosaic", "--type", "retarder"], "--type"), (["--mosaic", "--angle", "10"], "--angle"),
    (["--mosaic", "--retardance", "90"], "--retardance"), (["--mosaic", "--retarder-angle", "0"], "--retarder-angle"),
    (["--mosaic-layout="], "--mosaic-layout"), (["--mosaic-layout", "0,45,90,135"], "--mosaic-layout"),
    (["--mosaic", "--mosaic-layout="], "--mosaic-layout"), (["--mosaic", "--mosaic-layout", ",,,"], "--mosaic-layout"),
    (["--mosaic", "--mosaic-layout", "0,45,90"], "--mosaic-layout"),
    (["--retardance", "90"], "--retardance"), (["--type", "linear", "--retarder-angle", "10"], "--retarder-angle"),
    (["--type", "circular-left", "--angle", "30"], "--angle"),
    (["--type", "circular-right", "--extinction", "0.1"], "--extinction"),
    (["--type", "circular-right", "--sweep", "0:90:45"], "--sweep"),
    (["--sweep", "0:90:45", "--angle", "3"], "--angle"),
]


@pytest.mark.parametrize("options, field", IGNORED)
def test_polariser_options_that_do_nothing_in_the_mode_are_refused(options, field, small_exr, work):
    status, out, err = run("polariser", small_exr, "-o", work / "ignored.png", *options)
    assert_refused(status, err, field)
    assert out == "" and not (work / "ignored.png").exists()


@pytest.mark.parametrize("name, options", [
    ("out.jpg", []), ("out.jpeg", []), ("out", []), ("out.tif", ["--mosaic"]), ("out.exr.bak", []),
    ("sheet.exr", ["--sweep", "0:90:45"]), ("x.png.", []),
])
def test_polariser_outputs_the_writer_does_not_produce_are_refused(name, options, small_exr, work):
    status, _, err = run("polariser", small_exr, "-o", work / name, *options)
    assert_refused(status, err, "-o", ".png")
    assert not (work / name).exists()


@pytest.mark.parametrize("options", [["--exposure", "1"], ["--mosaic", "--exposure", "-2"]])
def test_polariser_exposure_of_an_exr_is_refused(options, small_exr, work):
    status, _, err = run("polariser", small_exr, "-o", work / "lin.exr", *options)
    assert_refused(status, err, "--exposure", "PNG")


@pytest.mark.parametrize("name, options", [
    ("a.PNG", []), ("b.EXR", ["--angle", "30"]), ("c.png", ["--type", "retarder", "--retarder-angle", "30",
                                                            "--retardance", "45", "--angle", "0", "--extinction",
                                                            "0.01", "--exposure", "1"]),
    ("d.png", ["--mosaic", "--extinction", "0.1", "--exposure", "1", "--mosaic-layout", "0,45,135,90"]),
    ("e.exr", ["--mosaic"]), ("f.png", ["--sweep", "0:180:90", "--extinction", "0.5", "--exposure", "2"]),
    ("g.png", ["--type", "circular-right", "--exposure", "1"]), ("h.png", ["--type", "linear", "--angle", "0"]),
])
def test_polariser_options_that_apply_still_work(name, options, small_exr, work):
    out = work / name
    status, stdout, err = run("polariser", small_exr, "-o", out, *options)
    assert_clean(status, err, exr=out if name.lower().endswith(".exr") else None,
                 png=out if name.lower().endswith(".png") else None)
    assert status == 0 and stdout.strip() == str(out)


# --- fuzzers -------------------------------------------------------------------------------------

SPECIAL_NUMBERS = ["0", "-0", "1", "2", "3", "16", "nan", "inf", "-inf", "1e-320", "5e-324", "1e-9", "1e300",
                   "-1e300", "1.7976931348623157e308", "1e309", "16777216", "16777217", "9223372036854775807",
                   "9223372036854775808", "18446744073709551616", "-1", "1e12", "0x10", "", " 3", "1_0", "½"]
#: Anything a user might type where a number belongs.
NUMBERS = st.one_of(st.sampled_from(SPECIAL_NUMBERS), st.floats().map(repr), st.integers(-2 ** 70, 2 ** 70).map(str))
JUNK = st.one_of(NUMBERS, st.text(max_size=8))
#: Legal values, extremes included (a tiny threshold samples to --spp: a render's --spp stays small).
LEGAL = {
    "--noise-threshold": st.one_of(st.floats(min_value=0, exclude_min=True, max_value=90).map(repr),
                                   st.sampled_from(["5e-324", "1e-320", "1e-9", "0.01", "0.5", "90"])),
    "--noise-threshold-not-aolp": st.one_of(st.floats(min_value=0, exclude_min=True, allow_infinity=False).map(repr),
                                            st.sampled_from(["1e300", "1.7976931348623157e308"])),
    "--noise-quantity": st.sampled_from(QUANTITIES),
    # finite limits stay well inside DEADLINE: a render that never converges (threshold 5e-324) runs until its
    # limit; the huge ones are safe only with the legal spp (≤ 8), see adaptive_options
    "--time-limit": st.one_of(st.sampled_from(["0", "1e300", "1e-9", "5e-324", "20", "1.7976931348623157e308"]),
                              st.floats(min_value=0, max_value=20).map(repr)),
    "--seed": st.one_of(st.integers(0, 2 ** 53).map(str), st.sampled_from(["0", str(2 ** 62)])),
    "--render-spp": st.integers(2, 8).map(str),
    "--estimate-spp": st.one_of(st.integers(2, 1 << 24).map(str), st.sampled_from(["2", "64", "16777216"])),
    "--pilot-spp": st.integers(2, 6).map(str),
}


@st.composite
def threshold_and_quantity(draw):
    quantity = draw(LEGAL["--noise-quantity"])
    if quantity != "aolp" and draw(st.booleans()):
        return quantity, draw(LEGAL["--noise-threshold-not-aolp"])
    return quantity, draw(LEGAL["--noise-threshold"])


@st.composite
def adaptive_options(draw, command):
    """Legal options (extreme values included), and in about a third of the cases one mistake: an option's
    value replaced by anything a user might type, or an option that does not apply."""
    spp = draw(LEGAL[f"--{command}-spp"])
    min_spp = str(draw(st.integers(2, int(spp))))
    quantity, threshold = draw(threshold_and_quantity())
    if command == "render":
        opts = {"--spp": spp, "--min-spp": min_spp, "--noise-threshold": threshold, "--noise-quantity": quantity,
                "--time-limit": draw(LEGAL["--time-limit"]), "--seed": draw(LEGAL["--seed"])}
        keep = [k for k in opts if k == "--noise-threshold" or draw(st.booleans())]
    else:
        opts = {"--spp": spp, "--min-spp": min_spp, "--seed": draw(LEGAL["--seed"]),
                "--pilot-spp": draw(LEGAL["--pilot-spp"])}
        keep = ["--pilot-spp"] + [k for k in opts if k != "--pilot-spp" and draw(st.booleans())]
    if draw(st.integers(0, 2)) == 0:                         # one mistake
        key = draw(st.sampled_from(sorted(opts)))
        opts[key] = draw(JUNK if key == "--noise-quantity" else NUMBERS)
        keep = sorted(set(keep) | {key})
        if command == "render" and key == "--spp":
            # a mistaken spp may be a legal huge count (16777216): with a threshold that never converges the
            # render would run until its limit, so give it one that ends well inside DEADLINE
            opts["--time-limit"] = "5"
            keep = sorted(set(keep) | {"--time-limit"})
    args = [f"{k}={opts[k]}" for k in keep]
    if command == "estimate":
        targets = [":".join(draw(threshold_and_quantity())[::-1][::-1]) for _ in range(draw(st.integers(1, 3)))]
        if draw(st.integers(0, 3)) == 0:
            targets[0] = draw(st.one_of(st.tuples(JUNK, NUMBERS).map(":".join), st.text(max_size=10)))
        args += [f"--target={t}" for t in targets]
    return args


@pytest.mark.fuzz
@FUZZ
@given(adaptive_options("render"))
def test_fuzz_adaptive_render_options(work, scene, args):
    out = work / "fuzz.exr"
    if out.exists():
        out.unlink()
    status, _, err = run("render", scene, "-o", out, "-q", "--no-previews", *args)
    assert_clean(status, err, exr=out if status == 0 else None)
    if status == 2 and "--time-limit" not in err:
        assert not out.exists()                        # refused before rendering


@pytest.mark.fuzz
@FUZZ
@given(adaptive_options("estimate"))
def test_fuzz_estimate_options(scene, args):
    status, out, err = run("estimate", scene, *args)
    assert_clean(status, err)
    if status == 0:
        assert len(target_lines(out)) == sum(a.startswith("--target=") for a in args)


STATE_NAMES = ([f"sum.S{k}.{c}" for k in range(4) for c in "RGB"]
               + [f"{q}.S{k}.Y" for q in ("sumsq", "A", "B", "first.A", "first.B") for k in range(4)]
               + ["cost", "first.count", "first.cost"])
POISON = st.one_of(st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, -1.0, 0.5, 1e-310, 0.0, 2.0 ** 60]),
                   st.floats())
HEADER_KEYS = ["polar.seed", "polar.spp", "polar.scene_hash", "polar.max_depth", "polar.window", "polar.spectral",
               "polar.noise_threshold", "polar.min_spp", "polar.complete", "polar.polarisation"]
HEADER_VALUES = st.one_of(st.text(max_size=12), st.integers(-2 ** 40, 2 ** 40), st.floats())


@st.composite
def damage(draw, channel_names):
    kind = draw(st.sampled_from(["drop", "state", "bits", "float", "header"]))
    pixel = draw(st.one_of(st.none(), st.integers(0, 63)))
    if kind == "drop":
        return kind, draw(st.sampled_from(channel_names)), None, None
    if kind == "state":
        return kind, draw(st.sampled_from(STATE_NAMES)), pixel, draw(POISON)
    if kind == "bits":
        name = draw(st.sampled_from([n for n in channel_names if n.startswith(STATE_PREFIX + ".")] + ["spp"]))
        return kind, name, pixel, draw(st.integers(0, 2 ** 32 - 1))
    if kind == "float":
        name = draw(st.sampled_from([n for n in channel_names if not n.startswith(STATE_PREFIX + ".")
                                     and n != "spp"]))
        return kind, name, pixel, draw(st.floats(width=32))
    return kind, draw(st.sampled_from(HEADER_KEYS)), None, draw(HEADER_VALUES)


def apply_damage(channels, header, change):
    kind, name, pixel, value = change
    sel = slice(None) if pixel is None else pixel
    if kind == "drop":
        channels.pop(name, None)
    elif kind == "state":
        if f"{STATE_PREFIX}.{name}.hi" in channels and f"{STATE_PREFIX}.{name}.lo" in channels:
            set_value(channels, name, value, pixel)
    elif kind in ("bits", "float") and name in channels:
        a = channels[name].copy()
        a.reshape(-1)[sel] = value
        channels[name] = a
    elif kind == "header":
        header[name] = value


@pytest.fixture(scope="module")
def base_state(adaptive_exr):
    _, channels, header = read_stokes_exr(adaptive_exr)
    return channels, header


@pytest.mark.fuzz
@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_fuzz_damaged_resume_files(base_state, scene, work, data):
    channels, header = dict(base_state[0]), dict(base_state[1])
    for change in data.draw(st.lists(damage(sorted(channels)), min_size=1, max_size=3)):
        apply_damage(channels, header, change)
    damaged = work / "fuzz-damaged.exr"
    try:
        write_raw_exr(damaged, channels, header)
    except (ValueError, TypeError):        # a header value the EXR library cannot store at all
        assume(False)
    adaptive = data.draw(st.booleans())
    out = work / "fuzz-resumed.exr"
    status, _, err = resume(scene, damaged, out, adaptive)
    assert_clean(status, err, exr=out if status == 0 else None)
    if status == 2:
        assert not out.exists()


_F32_MAX = float(np.finfo(np.float32).max)
POLARISER_VALUES = st.one_of(st.floats(width=32), st.sampled_from([0.0, 1.0, -1.0, _F32_MAX, -_F32_MAX,
                                                                   float(np.float32(1e-45))]))
ANGLE = st.one_of(st.floats(-720, 720).map(repr), st.sampled_from(["0", "90", "1e300", "-45", "-0"]))
POLARISER_LEGAL = {"--angle": ANGLE, "--retarder-angle": ANGLE, "--retardance": ANGLE,
                   "--extinction": st.one_of(st.floats(0, 1).map(repr), st.sampled_from(["0", "1", "5e-324"])),
                   "--exposure": st.one_of(st.floats(-64, 64).map(repr), st.sampled_from(["-64", "64"])),
                   "--mosaic-layout": st.lists(ANGLE, min_size=4, max_size=4).map(",".join),
                   "--sweep": st.one_of(st.sampled_from(["0:180:45", "10:10:1", "0:0:1e-20", "1e300:1e300:1",
                                                         "0:3599:1", "-720:720:1"]),
                                        st.tuples(st.floats(-360, 0), st.floats(0, 360), st.floats(1, 90))
                                        .map(lambda t: ":".join(map(repr, t))))}
POLARISER_MISTAKES = st.one_of(
    st.tuples(st.sampled_from(sorted(POLARISER_LEGAL)), JUNK),
    st.tuples(st.sampled_from(sorted(POLARISER_LEGAL)), st.sampled_from(list(POLARISER_LEGAL.values())).flatmap(
        lambda v: v)),                                   # a legal value, maybe where it does not apply
    st.tuples(st.just("--sweep"), st.sampled_from(["-1e308:1e308:1", "0:1:5e-324", "0:3600:1", "9:1:1", "0:180"])),
    st.tuples(st.just("--type"), st.text(max_size=6)))


@st.composite
def polariser_case(draw):
    """A small Stokes image (finite, or with NaN, ±inf, float32 extremes), a mode with legal options, and in
    about a third of the cases one mistake (junk, an option that does not apply, an output it cannot write)."""
    h, w = draw(st.integers(1, 5)), draw(st.integers(1, 5))
    values = draw(st.sampled_from([st.floats(-2.0, 2.0, width=32), st.floats(0.0, 1e3, width=32), POLARISER_VALUES]))
    stokes = draw(hnp.arrays(np.float32, (4, h, w, 3), elements=values))
    mode = draw(st.sampled_from(["filter", "sweep", "mosaic"]))
    kind = None if mode == "mosaic" else draw(st.sampled_from(
        [None, "linear", "retarder"] + (["circular-right", "circular-left"] if mode == "filter" else [])))
    ext = ".png" if mode == "sweep" else draw(st.sampled_from([".png", ".exr", ".PNG", ".EXR"]))
    applies = {"--extinction", "--exposure"} if not (kind or "").startswith("circular") else {"--exposure"}
    if ext.lower() == ".exr":
        applies.discard("--exposure")
    if mode == "mosaic":
        applies.add("--mosaic-layout")
    elif kind == "retarder":
        applies |= {"--retarder-angle", "--retardance"}
    if mode == "filter" and not (kind or "").startswith("circular"):
        applies.add("--angle")
    args = ["--mosaic"] if mode == "mosaic" else [f"--sweep={draw(POLARISER_LEGAL['--sweep'])}"] \
        if mode == "sweep" else []
    if kind is not None:
        args.append(f"--type={kind}")
    args += [f"{k}={draw(POLARISER_LEGAL[k])}" for k in sorted(applies) if draw(st.booleans())]
    if draw(st.integers(0, 2)) == 0:
        if draw(st.integers(0, 3)) == 0:
            ext = draw(st.sampled_from([".jpg", "", ".exr.bak", ".png.", ".tiff"]))
        else:
            option, value = draw(POLARISER_MISTAKES)
            args.append(f"{option}={value}")
    return stokes, args, ext


@pytest.mark.fuzz
@FUZZ
@given(polariser_case())
def test_fuzz_polariser_inputs_and_options(work, case):
    stokes, args, ext = case
    src = stokes_file(work / "fuzz-in.exr", stokes)
    out = work / f"fuzz-out{ext}"
    if out.exists():
        out.unlink()
    status, _, err = run("polariser", src, "-o", out, *args)
    is_exr = ext.lower().endswith(".exr")
    assert_clean(status, err, exr=out if status == 0 and is_exr else None,
                 png=out if status == 0 and not is_exr else None)
    if status == 0:
        assert np.isfinite(stokes).all()                       # non-finite inputs are always refused
        assert ext.lower() in (".png", ".exr", ".exr.png")
