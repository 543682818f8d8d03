"""Adaptive sampling: error formulas, stopping rule, determinism, time limit, options, estimate.

Error formulas are checked against half-buffers computed by hand; determinism compares sums bit
for bit.  No test times anything: the time limit runs on an injected clock.
"""

import dataclasses
import math
import os

import numpy as np
import pytest

from engine import cli
from engine.output.exr import read_stokes_exr, write_stokes_exr
from engine.render.adaptive import (AdaptiveSettings, HalfBuffers, TILE, checkpoints, film_noise, next_targets,
                                    pixel_noise, state_channels, state_from_channels, tile_ids, tile_noise)
from engine.render.estimate import best_mse_time_gain, mse_time_gain, parse_target, predict
from engine.render.film import Film
from engine.render.renderer import Renderer, RenderRequest
from engine.scene.loader import load_scene
from engine.errors import SceneError
from tests.conftest import shared_path
from tests.support.adaptive import adaptive_render


def col(*v):
    return np.asarray(v, np.float64)[:, None]


# ------------------------------------------------------------------------------------ error formulas

def test_s0_error_is_the_relative_half_buffer_difference():
    err, defined = pixel_noise("s0", col(3.0, 0, 0, 0), col(1.0, 0, 0, 0))
    assert err[0] == pytest.approx(0.5)                  # |3 − 1| / (3 + 1)
    err, _ = pixel_noise("s0", col(0.0, 0, 0, 0), col(0.0, 0, 0, 0))
    assert err[0] == 0.0 and defined[0]                  # black in both halves: converged


def test_dolp_and_docp_errors_are_half_the_absolute_differences():
    a, b = col(2.0, 1.2, 0.0, 1.0), col(1.0, 0.0, 0.4, -0.25)     # DoLP 0.6 / 0.4, DoCP 0.5 / −0.25
    assert pixel_noise("dolp", a, b)[0][0] == pytest.approx(0.1)
    assert pixel_noise("docp", a, b)[0][0] == pytest.approx(0.375)


def test_aolp_error_wraps_at_90_degrees_and_ignores_unpolarised_pixels():
    t = np.radians(178.0)
    a = col(1.0, math.cos(t), math.sin(t), 0.0)          # AoLP +89°
    b = col(1.0, math.cos(t), -math.sin(t), 0.0)         # AoLP −89°: 2° apart, not 178°
    err, defined = pixel_noise("aolp", a, b)
    assert defined[0] and err[0] == pytest.approx(1.0)
    weak_a, weak_b = col(1.0, 0.01, 0.0, 0.0), col(1.0, 0.0, 0.02, 0.0)    # DoLP ≈ 0.01 < 0.05
    err, defined = pixel_noise("aolp", weak_a, weak_b)
    assert not defined[0] and err[0] == 0.0


def test_stokes_error_is_the_largest_normalised_component_error():
    a, b = col(2.0, 1.0, 0.0, 0.0), col(2.0, 0.6, 0.0, 0.2)     # S1/S0 0.5 / 0.3, S3/S0 0 / 0.1
    assert pixel_noise("stokes", a, b)[0][0] == pytest.approx(0.1)
    a, b = col(3.0, 0.0, 0.0, 0.0), col(1.0, 0.0, 0.0, 0.0)
    assert pixel_noise("stokes", a, b)[0][0] == pytest.approx(0.5)   # the S0 error dominates


def test_half_buffer_means_split_even_and_odd_samples():
    film, halves = Film(1, 1), HalfBuffers(1)
    from engine.render.adaptive import add_in_sample_order
    values = np.zeros((4, 3, 5))
    values[0] = np.array([1.0, 2.0, 3.0, 4.0, 5.0])[None, :]        # grey: Y = value
    add_in_sample_order(film, halves, np.zeros(5, np.int64), np.arange(5), values)
    a, b = halves.means(film.count)
    assert a[0, 0] == pytest.approx((1 + 3 + 5) / 3) and b[0, 0] == pytest.approx((2 + 4) / 2)
    err, _, _ = film_noise(film, halves, "s0")
    assert err[0] == pytest.approx(abs(3 - 3) / 6)


def test_tile_error_is_the_rms_over_the_tiles_defined_pixels():
    W = H = 2 * TILE
    tiles = tile_ids(W, H)
    err = np.zeros(W * H)
    defined = np.ones(W * H, bool)
    first = np.flatnonzero(tiles == 0)
    err[first[:2]] = [0.3, 0.4]
    defined[first[2:]] = False                            # only two pixels of tile 0 count
    t = tile_noise(err, defined, tiles, np.arange(W * H))
    assert t[first[0]] == pytest.approx(math.sqrt((0.09 + 0.16) / 2))
    assert np.all(t[tiles != 0] == 0.0)


# ------------------------------------------------------------------------------------ stopping rule

def test_checkpoints_grow_by_a_quarter_in_even_steps_up_to_the_maximum():
    assert checkpoints(16, 64).tolist() == [16, 20, 26, 34, 44, 56, 64]
    assert checkpoints(2, 2).tolist() == [2]
    long, short = checkpoints(16, 1000), checkpoints(16, 64)
    assert long[:6].tolist() == short[:6].tolist()        # a larger maximum extends the schedule


def test_stopping_rule():
    marks = checkpoints(16, 64)
    counts = np.array([0, 5, 16, 16, 22, 56, 64, 64])
    noise = np.array([9, 9, 0.02, 0.005, 0.001, 0.02, 0.02, 0.0])
    target = next_targets(counts, noise, marks, 0.01)
    # nothing yet → min; mid-way → next checkpoint whatever the noise; on a checkpoint: on if above,
    # done if below; at the maximum: done
    assert target.tolist() == [16, 16, 20, 16, 26, 64, 64, 64]


# ------------------------------------------------------------------------------------ renders

def small_scene(name="fresnel_sphere", res=24, spp=48, sampler="independent"):
    scene = load_scene(shared_path("peers", "scenes", f"{name}.json"))
    scene.camera.width = scene.camera.height = res
    # the counts asserted below are the independent sampler's (and sobol's, one sequence: its octave classes)
    scene.settings = dataclasses.replace(scene.settings, spp=spp, sampler=sampler)
    return scene


@pytest.fixture(scope="module", params=["independent", "sobol"])
def sphere(request):
    scene = small_scene(sampler=request.param)
    return scene, Renderer(scene)


AD = AdaptiveSettings(threshold=0.05, quantity="s0", min_spp=8)


@pytest.fixture(scope="module")
def reference(sphere):
    scene, renderer = sphere
    return renderer.render(RenderRequest(adaptive=AD))


def test_adaptive_render_spends_samples_unevenly_and_says_why_it_stopped(reference):
    if reference.settings.sampler != "independent":
        pytest.skip("the counts asserted are the independent sampler's (sobol stops at the threshold here)")
    counts = reference.film.count
    assert counts.min() == 8 and counts.max() == 48 and len(np.unique(counts)) > 2
    assert reference.stats["stop_reason"] == "max_spp"
    for t in np.unique(tile_ids(24, 24)):                 # a tile's pixels always share their count
        assert len(np.unique(counts[tile_ids(24, 24) == t])) == 1


@pytest.mark.parametrize("threads,batch_rays", [(1, 1 << 17), (2, 700), (1, 100)])
def test_counts_and_image_do_not_depend_on_threads_or_batch_size(sphere, reference, threads, batch_rays):
    scene, renderer = sphere
    st = dataclasses.replace(scene.settings, threads=threads, batch_rays=batch_rays)
    other = renderer.render(RenderRequest(st, adaptive=AD))
    np.testing.assert_array_equal(other.film.count, reference.film.count)
    np.testing.assert_array_equal(other.film.sums, reference.film.sums)
    np.testing.assert_array_equal(other.halves.sums, reference.halves.sums)
    np.testing.assert_array_equal(other.halves.cost, reference.halves.cost)          # the allocation's cost


def test_resume_after_a_cancel_through_the_exr_gives_the_same_counts_and_image(sphere, reference, tmp_path):
    scene, renderer = sphere
    st = dataclasses.replace(scene.settings, batch_rays=200)   # many units: stop after a few
    calls = {"n": 0}
    partial = renderer.render(RenderRequest(st, adaptive=AD, should_stop=lambda: calls.__setitem__("n", calls["n"] + 1)
                                            or calls["n"] > 12))
    assert partial.cancelled and partial.stats["stop_reason"] == "cancelled"
    assert partial.film.count.sum() < reference.film.count.sum()
    path = str(tmp_path / "part.exr")
    write_stokes_exr(path, partial.stokes(), extra={"spp": partial.film.spp_image().astype("uint32"),
                                                     **state_channels(partial.film, partial.halves)})
    _, channels, _ = read_stokes_exr(path)
    film, halves = state_from_channels(channels, channels["spp"], halves=partial.settings.halves)
    assert halves.halves == ("one_sequence" if scene.settings.sampler == "sobol" else "independent")
    np.testing.assert_array_equal(film.sums, partial.film.sums)
    np.testing.assert_array_equal(halves.sums, partial.halves.sums)
    resumed = renderer.render(RenderRequest(adaptive=AD, resume=film, resume_halves=halves))
    np.testing.assert_array_equal(resumed.film.count, reference.film.count)
    np.testing.assert_array_equal(resumed.film.sums, reference.film.sums)
    np.testing.assert_array_equal(resumed.halves.sums, reference.halves.sums)
    np.testing.assert_array_equal(resumed.halves.cost, reference.halves.cost)


@pytest.mark.cluster
@pytest.mark.subprocess
def test_a_dask_cluster_gives_the_local_counts_and_image(sphere, reference):
    distributed = pytest.importorskip("distributed")
    scene, renderer = sphere
    st = dataclasses.replace(scene.settings, batch_rays=2000)   # several tasks per round
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                       silence_logs=40)
    client = distributed.Client(cluster)
    try:
        remote = renderer.render(RenderRequest(st, adaptive=AD, scheduler=client))
    finally:
        client.close()
        cluster.close()
    assert remote.stats["stop_reason"] == reference.stats["stop_reason"]
    np.testing.assert_array_equal(remote.film.count, reference.film.count)
    np.testing.assert_array_equal(remote.film.sums, reference.film.sums)
    np.testing.assert_array_equal(remote.halves.sums, reference.halves.sums)
    np.testing.assert_array_equal(remote.halves.cost, reference.halves.cost)


def test_the_time_limit_stops_sampling_on_an_injected_clock(sphere, reference):
    if sphere[0].settings.sampler != "independent":
        pytest.skip("the independent sampler's counts reach the limit (sobol stops at the threshold here)")
    scene, renderer = sphere
    st = dataclasses.replace(scene.settings, batch_rays=300)
    ticks = {"t": 0.0}

    def clock():                                           # one "second" per look at the clock
        ticks["t"] += 1.0
        return ticks["t"]

    limited = renderer.render(RenderRequest(st, adaptive=AdaptiveSettings(0.05, "s0", 8, time_limit=40.0), clock=clock))
    assert limited.stats["stop_reason"] == "time_limit" and not limited.cancelled
    assert limited.film.count.sum() < reference.film.count.sum()
    assert limited.film.count.min() >= 0
    # what was done is the beginning of the unlimited render: continuing it gives the same result
    resumed = renderer.render(RenderRequest(adaptive=AD, resume=limited.film, resume_halves=limited.halves))
    np.testing.assert_array_equal(resumed.film.count, reference.film.count)
    np.testing.assert_array_equal(resumed.film.sums, reference.film.sums)


def test_a_scene_that_converges_at_min_spp_stops_there():
    scene = small_scene("plane_brewster", res=16, spp=64)
    result = Renderer(scene).render(RenderRequest(adaptive=AdaptiveSettings(0.02, "s0", 4)))
    assert result.stats["stop_reason"] == "threshold"
    assert np.all(result.film.count == 4)


def test_a_threshold_of_zero_samples_every_pixel_to_the_maximum():
    scene = small_scene("plane_brewster", res=8, spp=12)
    result = Renderer(scene).render(RenderRequest(adaptive=AdaptiveSettings(0.0, "s0", 4)))
    assert result.stats["stop_reason"] == "max_spp" and np.all(result.film.count == 12)
    uniform = Renderer(scene).render()
    np.testing.assert_allclose(result.stokes(), uniform.stokes(), rtol=1e-12, atol=1e-15)


# ------------------------------------------------------------------------------------ command line

def run_cli(capsys, *argv):
    status = cli.main(list(argv))
    return status, capsys.readouterr()


@pytest.fixture()
def small_json(tmp_path):
    import json
    with open(shared_path("peers", "scenes", "fresnel_sphere.json")) as fh:
        scene = json.load(fh)
    scene["camera"]["width"] = scene["camera"]["height"] = 16
    peers = os.path.dirname(shared_path("peers", "scenes", "fresnel_sphere.json"))
    for obj in scene["objects"]:
        if "file" in obj:
            obj["file"] = os.path.normpath(os.path.join(peers, obj["file"]))
    path = str(tmp_path / "scene.json")
    with open(path, "w") as fh:
        json.dump(scene, fh)
    return path


@pytest.mark.parametrize("args,option", [
    (["--noise-threshold", "-1"], "--noise-threshold"),
    (["--noise-threshold", "nan"], "--noise-threshold"),
    (["--noise-threshold", "0.1", "--noise-quantity", "dop"], "--noise-quantity"),
    (["--noise-threshold", "0.1", "--min-spp", "1"], "--min-spp"),
    (["--noise-threshold", "0.1", "--min-spp", "99"], "--min-spp"),
    (["--noise-threshold", "0.1", "--time-limit", "-3"], "--time-limit"),
    (["--noise-threshold", "120", "--noise-quantity", "aolp"], "--noise-threshold"),
    (["--min-spp", "4"], "--min-spp"),
    (["--noise-threshold", "0.1", "--spp", "1"], "--spp"),
    (["--noise-quantity", "dolp"], "--noise-quantity"),
])
def test_bad_adaptive_options_are_one_line_errors(capsys, small_json, tmp_path, args, option):
    status, out = run_cli(capsys, "render", small_json, "-o", str(tmp_path / "x.exr"), "--spp", "16", *args)
    assert status == 2
    lines = out.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {option}:"), out.err
    assert not os.path.exists(tmp_path / "x.exr")


def test_cli_writes_counts_noise_stop_reason_and_resumes_to_a_tighter_threshold(capsys, small_json, tmp_path):
    loose, tight, direct = (str(tmp_path / n) for n in ("loose.exr", "tight.exr", "direct.exr"))
    common = ["--spp", "32", "--min-spp", "4", "--noise-quantity", "dolp", "--no-previews", "-q",
              "--sampler", "independent"]
    assert run_cli(capsys, "render", small_json, "-o", loose, "--noise-threshold", "0.05", *common)[0] == 0
    status, out = run_cli(capsys, "render", small_json, "-o", direct, "--noise-threshold", "0.01", *common)
    assert status == 0 and "predicted after the first pass" in out.err and "actual" in out.err
    _, ch, header = read_stokes_exr(direct)
    assert header["polar.stop_reason"] in ("threshold", "max_spp") and header["polar.noise_quantity"] == "dolp"
    assert "noise" in ch and ch["noise"].shape == (16, 16) and ch["spp"].min() == 4
    # A tile's path to the loose threshold is the start of its path to the tight one.
    assert run_cli(capsys, "render", small_json, "-o", tight, "--resume", loose, "--noise-threshold", "0.01",
                   *common)[0] == 0
    a, ca, _ = read_stokes_exr(direct)
    b, cb, _ = read_stokes_exr(tight)
    np.testing.assert_array_equal(cb["spp"], ca["spp"])
    np.testing.assert_array_equal(b, a)
    np.testing.assert_array_equal(cb["noise"], ca["noise"])


def test_a_time_limit_alone_that_does_not_run_out_samples_every_noisy_pixel_up_to_the_maximum(capsys, small_json,
                                                                                              tmp_path):
    # budget mode (engine.render.adaptive.budget_targets): every pixel of this scene is noisy
    path = str(tmp_path / "t.exr")
    status, out = run_cli(capsys, "render", small_json, "-o", path, "--spp", "6", "--min-spp", "2",
                          "--time-limit", "3600", "--no-previews", "-q")
    assert status == 0, out.err
    _, ch, header = read_stokes_exr(path)
    assert header["polar.stop_reason"] == "max_spp" and np.all(ch["spp"] == 6)


def test_resuming_a_uniform_render_adaptively_is_refused(capsys, small_json, tmp_path):
    uniform = str(tmp_path / "u.exr")
    assert run_cli(capsys, "render", small_json, "-o", uniform, "--spp", "4", "--no-previews", "-q")[0] == 0
    status, out = run_cli(capsys, "render", small_json, "-o", str(tmp_path / "r.exr"), "--resume", uniform,
                          "--spp", "8", "--noise-threshold", "0.1", "--min-spp", "2", "-q")
    assert status == 2 and out.err.startswith("error: --noise-threshold:") and "half-buffers" in out.err


def test_uniform_renders_have_no_adaptive_channels(capsys, small_json, tmp_path):
    path = str(tmp_path / "u.exr")
    assert run_cli(capsys, "render", small_json, "-o", path, "--spp", "2", "--no-previews", "-q")[0] == 0
    _, ch, header = read_stokes_exr(path)
    assert "noise" not in ch and "polar.stop_reason" not in header
    assert not any(name.startswith("adaptive.") for name in ch)


# ------------------------------------------------------------------------------------ estimate

def test_prediction_follows_one_over_root_spp():
    film, halves = Film(TILE, TILE), HalfBuffers(TILE * TILE)
    film.count[:] = 16
    film.sums[0, :] = 16.0                                   # grey Y = 1 in every pixel
    halves.sums[0, 0] = 8 * 1.2                              # Y_A = 1.2, Y_B = 0.8: s0 error 0.2
    halves.sums[1, 0] = 8 * 0.8
    p = predict(film, halves, "s0", 0.05, 16, 4096, seconds_per_sample=1e-6)
    # 16 · (0.2 / 0.05)² = 256 samples: the first checkpoint ≥ 256
    marks = checkpoints(16, 4096)
    expected = int(marks[np.searchsorted(marks, 256)])
    assert p.median == expected and p.uniform_spp == 256
    assert p.adaptive_seconds == pytest.approx(TILE * TILE * expected * 1e-6)


def test_rendering_every_tile_to_the_threshold_gains_nothing_over_uniform_at_equal_cost():
    # Counts ∝ variance (every tile exactly at the threshold) with equal costs: MSE × time is the
    # uniform one; counts ∝ σ are optimal then, gaining mean(σ²)/mean(σ)² (Cauchy–Schwarz).
    sigma = np.array([0.01, 0.1, 1.0, 2.0])
    v = sigma ** 2
    assert mse_time_gain(v, 1e-6, 1000 * v) == pytest.approx(1.0)
    assert mse_time_gain(v, 1e-6, 7 * sigma) == pytest.approx(np.mean(v) / np.mean(sigma) ** 2)
    assert best_mse_time_gain(v, 1e-6) == pytest.approx(np.mean(v) / np.mean(sigma) ** 2)
    assert mse_time_gain(v, 1e-6, np.full(4, 64)) == pytest.approx(1.0)
    # Costs: the optimum is n ∝ √(v/c); a pixel 4× as expensive gets half the samples.
    c = np.array([1.0, 4.0, 1.0, 4.0])
    assert mse_time_gain(v, c, np.sqrt(v / c)) == pytest.approx(best_mse_time_gain(v, c))
    assert best_mse_time_gain(v, c) == pytest.approx(np.sum(v) * np.sum(c) / np.sum(np.sqrt(v * c)) ** 2)
    rng = np.random.default_rng(1)
    for _ in range(20):                                      # no allocation beats the bound
        assert mse_time_gain(v, c, rng.uniform(1, 100, 4)) <= best_mse_time_gain(v, c) + 1e-12


def test_prediction_reports_the_gain_of_holding_quiet_tiles_at_min_spp():
    # Two tiles: a noisy one (s0 error 0.2 at 16 spp) and a quiet one (0.01): the quiet one stays at
    # min_spp, the noisy one goes to its checkpoint; the gain is the ratio of MSE × time (equal costs).
    film, halves = Film(2 * TILE, TILE), HalfBuffers(2 * TILE * TILE)
    film.count[:] = 16
    film.sums[0, :] = 16.0
    noisy = (np.arange(2 * TILE * TILE) % (2 * TILE)) < TILE
    e = np.where(noisy, 0.2, 0.01)
    halves.sums[0, 0] = 8 * (1 + e)
    halves.sums[1, 0] = 8 * (1 - e)
    p = predict(film, halves, "s0", 0.05, 16, 4096, seconds_per_sample=1e-6)
    n = np.where(noisy, p.counts.max(), 16)
    assert set(np.unique(p.counts)) == {16, int(p.counts.max())}
    v = e ** 2 * 16
    assert p.gain == pytest.approx(np.mean(v) * v.size / (np.mean(v / n) * np.sum(n)))
    assert p.gain > 1 and p.best_gain >= p.gain
    assert "better than uniform" in p.describe()


@pytest.mark.parametrize("text", ["dolp", "dolp:", "dolp:-1", "foo:0.1", "s0:inf"])
def test_bad_targets_name_the_option(text):
    with pytest.raises(SceneError, match="--target"):
        parse_target(text)


def test_estimate_command_prints_a_prediction_per_target(capsys, small_json):
    status, out = run_cli(capsys, "estimate", small_json, "--target", "dolp:0.02", "--target", "s0:0.05",
                          "--pilot-spp", "4", "--spp", "64", "--min-spp", "4")
    assert status == 0, out.err
    lines = [line for line in out.out.splitlines() if line.startswith("target ")]
    assert len(lines) == 2 and "dolp ≤ 0.02" in lines[0] and "uniform" in lines[1] and "95th percentile" in lines[0]


# ------------------------------------------------------------------------------------ Blender

@pytest.mark.blender
def test_blender_adaptive_render_has_a_noise_pass_and_reports_the_achieved_error(tmp_path, capfd):
    bpy = pytest.importorskip("bpy")
    from tests.blender_support import (add_plane, brewster_camera, empty_scene, load_addon, polar_material,
                                       read_multilayer, render_to_exr, white_world)
    load_addon()
    scene = empty_scene(width=24, height=16, samples=32)
    add_plane(200, polar_material("Floor", "BLACK_GLASS"))
    brewster_camera(scene, lens=200.0)
    white_world(scene)
    p = scene.polar
    p.use_adaptive_sampling, p.adaptive_threshold, p.noise_quantity, p.adaptive_min_samples = True, 0.5, "DOLP", 4
    assert bpy.ops.polar.estimate_cost() == {"FINISHED"}
    assert p.estimate_report.startswith("Adaptive: median 4,") and "Uniform:" in p.estimate_report
    capfd.readouterr()
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "adaptive")))
    out = capfd.readouterr().out
    assert "adaptive: threshold, dolp error p95" in out and "spp 4–4" in out
    assert "Noise" in passes and passes["Noise"].shape[:2] == (16, 24)
    assert 0 <= passes["Noise"].min() and passes["Noise"].max() <= 0.5 * 2       # a tile RMS ≤ 0.5
    p.use_adaptive_sampling = False
    passes = read_multilayer(render_to_exr(scene, str(tmp_path / "uniform")))
    assert "Noise" not in passes


def test_cost_map_spreads_the_pilot_time_over_pixels_by_their_units_cost():
    from engine.render.estimate import cost_map
    units = [(np.array([0, 1]), 4, 2.0), (np.array([2, 3]), 4, 6.0)]     # 0.5 and 1.5 s per path
    sps = cost_map(units, 5, seconds=1.0)                                 # two threads: wall 1 s
    np.testing.assert_allclose(sps[:4], [0.0625, 0.0625, 0.1875, 0.1875])
    assert sps[4] == pytest.approx(0.125)                                 # not in the pilot: the mean
    assert float(np.sum(sps[:4] * 2)) == pytest.approx(1.0)              # the pilot's samples: its wall time


@pytest.mark.blender
def test_blender_sampling_panel_shows_the_adaptive_settings_and_the_estimate_button():
    bpy = pytest.importorskip("bpy")
    from tests.blender_support import empty_scene, load_addon
    addon = load_addon()
    scene = empty_scene()
    scene.polar.estimate_report = "Adaptive: median 16\nUniform: 64"
    drawn = {"props": [], "operators": [], "labels": []}

    class Layout:                                   # records what the panel draws
        use_property_split = False

        def column(self, **kw):
            return self

        row = column

        def prop(self, data, name, **kw):
            assert name in data.bl_rna.properties, name
            drawn["props"].append(name)

        def operator(self, idname, **kw):
            drawn["operators"].append(idname)

        def label(self, text="", **kw):
            drawn["labels"].append(text)

    class Context:
        pass

    panel, context = Context(), Context()
    panel.layout, context.scene = Layout(), scene
    addon.polar_addon.ui.POLAR_PT_sampling.draw(panel, context)
    for name in ("use_adaptive_sampling", "adaptive_threshold", "noise_quantity", "samples", "adaptive_min_samples",
                 "time_limit"):
        assert name in drawn["props"], name
    assert drawn["operators"] == ["polar.estimate_cost"] and drawn["labels"] == ["Adaptive: median 16", "Uniform: 64"]
    assert hasattr(bpy.ops.polar, "estimate_cost")


# ------------------------------------------------------------------------------------ allocation rule

def test_the_allocation_level_gives_the_threshold_as_the_images_rms_error():
    from engine.render.adaptive import allocation_level
    sigma = np.array([0.01, 0.1, 0.1, 1.0, 3.0])
    mu = allocation_level(sigma, 0.02)
    assert mu == pytest.approx(0.02 ** 2 / np.mean(sigma))
    n = sigma / mu                                             # the optimal counts n ∝ σ
    assert math.sqrt(np.mean(sigma ** 2 / n)) == pytest.approx(0.02)
    assert allocation_level(np.zeros(4), 0.02) == math.inf    # nothing noisy: every tile stops at once


class GaussianTracer:
    """Grey pixels of luminance 1 whose samples are 1 + σ·z, z standard normal from a hash of
    (pixel, sample): a synthetic noise map with a known per-sample σ per pixel (no geometry)."""

    def __init__(self, sigma):
        self.sigma = np.asarray(sigma, np.float64)

    def trace(self, pixel, sample, abort=None):
        with np.errstate(over="ignore"):                       # the hash wraps modulo 2⁶⁴ on purpose
            return self._trace(pixel, sample)

    def _trace(self, pixel, sample):
        x = ((pixel.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15))
             ^ (sample.astype(np.uint64) * np.uint64(0xBF58476D1CE4E5B9)))
        u = []
        for k in (1, 2):                                       # splitmix64 finaliser, two streams
            z = x + np.uint64(k) * np.uint64(0x94D049BB133111EB)
            z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
            z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
            z = z ^ (z >> np.uint64(31))
            u.append(((z >> np.uint64(11)).astype(np.float64) + 0.5) / 2.0 ** 53)
        gauss = np.sqrt(-2 * np.log(u[0])) * np.cos(2 * np.pi * u[1])
        values = np.zeros((4, 3, pixel.size))
        values[0] = (1.0 + self.sigma[pixel] * gauss)[None, :]
        return values, {"rays": pixel.size, "shadow_rays": 0, "nonfinite": 0}


def synthetic_render(sigma_tiles, threshold, min_spp=16, spp=4096, side=8):
    """Adaptive render (s0) of a side×side-tile image whose tiles have per-sample σ ``sigma_tiles``."""
    W = H = side * TILE
    sigma = np.asarray(sigma_tiles, np.float64)[tile_ids(W, H)]
    film, halves = Film(W, H), HalfBuffers(W * H)

    reason, stats = adaptive_render(GaussianTracer(sigma), film, halves, spp, 1 << 16,
                                    AdaptiveSettings(threshold, "s0", min_spp))
    return film, halves, reason, stats


def test_samples_land_in_proportion_to_sigma_where_a_tile_is_noisier_than_the_mean():
    # 64 tiles, σ log-spaced over two decades: those above the mean σ end at σ/μ (their share of
    # the error, μ = T²/mean σ), the quieter ones at σ²/T² (the threshold), none below min_spp.
    sigma = np.geomspace(0.02, 2.0, 64)
    T = 0.02
    film, halves, reason, stats = synthetic_render(sigma, T)
    assert reason == "threshold"
    n = film.count[np.searchsorted(tile_ids(32, 32), np.arange(64))].astype(np.float64)  # a pixel per tile
    mu = T ** 2 / np.mean(sigma)
    expected = np.maximum(16, np.minimum(sigma / mu, sigma ** 2 / T ** 2))
    ratio = n / expected
    # a tile's error estimate (16 pixels, one degree of freedom each) scatters by ~18 %, so its count
    # (∝ σ or σ²) by up to ~40 %, and a checkpoint step is +25 %
    assert 0.8 < np.median(ratio) < 1.25 and np.mean((ratio > 0.5) & (ratio < 2)) >= 0.9, ratio
    noisy = sigma > np.mean(sigma)
    slope = np.polyfit(np.log(sigma[noisy]), np.log(n[noisy]), 1)[0]
    assert 0.8 < slope < 1.2                                  # ∝ σ, not σ² (the old rule's 2)
    # MSE × samples against uniform sampling (exact σ): the rule's ideal counts gain 2.08×, every
    # tile to the threshold 1.53× (only by the min_spp floor), the bound of any allocation 2.38×
    gain = mse_time_gain(sigma ** 2, 1.0, n)
    every_tile_to_t = mse_time_gain(sigma ** 2, 1.0, np.clip(sigma ** 2 / T ** 2, 16, 4096))
    assert gain > 1.2 * every_tile_to_t and gain > 0.75 * best_mse_time_gain(sigma ** 2, 1.0)


def test_a_tile_below_the_threshold_at_min_spp_gets_no_more_samples_whatever_its_share():
    # one tile far noisier than the rest: the quiet tiles' error at 16 spp (σ/4 = 0.0025) is below
    # T = 0.01 so they stop at min_spp, although μ (set by the noisy tile) would give them more
    sigma = np.full(4, 0.01)
    sigma[0] = 1.0
    film, _, reason, _ = synthetic_render(sigma, 0.01, side=2)
    quiet = tile_ids(8, 8) != 0
    assert np.all(film.count[quiet] == 16) and film.count[~quiet].min() > 16 and reason == "threshold"


def test_a_noiseless_image_stops_at_min_spp():
    film, _, reason, stats = synthetic_render(np.zeros(4), 0.01, min_spp=6, side=2)
    assert reason == "threshold" and np.all(film.count == 6) and stats["allocation_level"] == math.inf


def test_the_first_pass_that_sets_the_allocation_travels_with_the_state(tmp_path):
    film, halves, _, _ = synthetic_render(np.geomspace(0.05, 1.0, 4), 0.05, side=2)
    assert halves.first is not None and np.all(halves.first[1] == 16)
    restored_film, restored = state_from_channels(state_channels(film, halves),
                                                  film.spp_image().astype(np.uint32))
    np.testing.assert_array_equal(restored.first[0], halves.first[0])
    np.testing.assert_array_equal(restored.first[1], halves.first[1])
    np.testing.assert_array_equal(restored.sums, halves.sums)


def test_the_images_error_of_s0_is_the_absolute_luminance_error_over_the_images_mean():
    from engine.render.adaptive import image_error
    film, halves = Film(2 * TILE, TILE), HalfBuffers(2 * TILE * TILE)
    film.count[:] = 16
    bright = (np.arange(2 * TILE * TILE) % (2 * TILE)) < TILE
    y = np.where(bright, 3.0, 1.0)                            # image mean luminance 2
    film.sums[0, :] = 16 * y
    halves.sums[0, 0] = 8 * y * 1.1                            # Y_A − Y_B = 0.2·Y: ½|A − B| = 0.1·Y
    halves.sums[1, 0] = 8 * y * 0.9
    assert image_error(film, halves, "s0") == pytest.approx(math.sqrt((0.3 ** 2 + 0.1 ** 2) / 2) / 2)
    assert film_noise(film, halves, "s0")[0] == pytest.approx(np.full(2 * TILE * TILE, 0.1))   # relative, per pixel


def test_the_predicted_time_counts_one_round_per_checkpoint_up_to_the_largest_count():
    film, halves = Film(TILE, TILE), HalfBuffers(TILE * TILE)
    film.count[:] = 16
    film.sums[0, :] = 16.0
    halves.sums[0, 0] = 8 * 1.2                              # s0 error 0.2 at 16 spp: 256 samples for 0.05
    halves.sums[1, 0] = 8 * 0.8
    p = predict(film, halves, "s0", 0.05, 16, 4096, seconds_per_sample=1e-6, round_seconds=0.5)
    marks = checkpoints(16, 4096)
    assert p.rounds == int(np.searchsorted(marks, p.counts.max())) + 1          # the steps, and the last look
    assert p.adaptive_seconds == pytest.approx(TILE * TILE * p.counts.max() * 1e-6 + 0.5 * p.rounds)


def test_a_round_larger_than_a_unit_is_cut_into_equal_units_a_multiple_of_the_workers():
    from engine.render.adaptive import MIN_UNIT_PATHS, adaptive_units, round_unit_paths, tile_ids
    W = H = 8 * TILE
    tiles = tile_ids(W, H)
    pixels = np.arange(W * H, dtype=np.int64)
    start, target = np.full(pixels.size, 16), np.full(pixels.size, 16 + 56)      # 56 passes
    batch = 2 * MIN_UNIT_PATHS // (W * H) * (W * H) + W * H                       # 2 units would need 2.x
    paths = int((target - start).sum())
    for workers in (1, 2, 3):
        per_unit = round_unit_paths(paths, pixels.size, 56, batch, workers)
        units = adaptive_units(pixels, start, target, tiles, per_unit)
        sizes = [u[0].size * (u[4] - u[3]) for u in units]
        assert len(units) % workers == 0 and max(sizes) <= batch
        assert max(sizes) - min(sizes) <= pixels.size * (len(units) - 1)         # whole, near-equal pass ranges
        assert sum(sizes) == paths
    assert round_unit_paths(1000, 100, 10, 1 << 17, 2) == MIN_UNIT_PATHS        # small rounds: one unit
