"""RenderSettings.halves: a pixel's even and odd samples drawn as two independently scrambled sequences or as one
sequence (engine.scene.description.resolve_halves, engine.render.sampler.sequence_index): the nets it makes, how
"auto" resolves, that the film then keeps no half sums and says what its error is, and that every split of a render
(threads, batches, windows, resumption, a Dask cluster: tests/render/test_distributed.py) gives the one-shot image."""

import dataclasses

import numpy as np
import pytest

from engine.errors import SceneError
from engine.render.adaptive import AdaptiveSettings
from engine.render.renderer import Renderer, RenderRequest
from engine.render.sampler import (PADDED_JITTER, PAIR_JITTER, SOBOL_DIRECTION, camera_numbers, cycles_pairs,
                                   padded_pairs, sequence_index, sobol_pairs, stratified_pair, vertex_pair)
from engine.scene.description import RenderSettings, resolve_halves
from engine.scene.loader import load_scene, parse_settings
from tests.conftest import shared_path


def _draw(kind, pixel, index):
    """(x, y) of one pair of ``kind`` for patterns' index ``index`` (engine.render.sampler.sequence_index)."""
    n = pixel.size
    if kind == "stratified":
        return stratified_pair(3, pixel, index, np.zeros(n), np.zeros(n), pair=PAIR_JITTER)
    if kind == "sobol":
        return sobol_pairs(3, pixel, index, [vertex_pair("sobol", 1, SOBOL_DIRECTION)])
    if kind == "padded":
        return padded_pairs(3, pixel, index, [PADDED_JITTER])
    return cycles_pairs(3, pixel, index, [vertex_pair("cycles", 1, SOBOL_DIRECTION)])


def _is_net(x, y, m):
    """Every elementary interval of area 2^-m (2^a × 2^(m−a) boxes) holds exactly one of the 2^m points."""
    for a in range(m + 1):
        cell = np.floor(x * 2 ** a).astype(np.int64) * 2 ** (m - a) + np.floor(y * 2 ** (m - a)).astype(np.int64)
        if np.bincount(cell, minlength=2 ** m).max() != 1:
            return False
    return True


@pytest.mark.parametrize("kind", ["stratified", "sobol", "padded", "cycles"])
def test_one_sequence_makes_the_first_2m_samples_of_a_pixel_one_net(kind):
    """With "one_sequence" a pixel's samples 0 … 2^m − 1 are a (0, m, 2)-net of every pair; with independent
    halves they are two nets of 2^(m−1) points (a net of 2^m points only by chance: not for most pixels)."""
    m = 6
    sample = np.arange(2 ** m)
    nets = {"one_sequence": 0, "independent": 0}
    for p in range(8):
        pixel = np.full(sample.size, 1000 + p)
        for halves in nets:
            x, y = _draw(kind, pixel, sequence_index(sample, halves))
            nets[halves] += _is_net(x, y, m)
        x, y = _draw(kind, pixel, sequence_index(sample, "independent"))
        assert _is_net(x[0::2], y[0::2], m - 1) and _is_net(x[1::2], y[1::2], m - 1)
    assert nets["one_sequence"] == 8 and nets["independent"] <= 2


def test_sequence_index_needs_a_resolved_mode():
    assert np.array_equal(sequence_index(np.arange(4), "one_sequence"), [0, 2, 4, 6])
    assert np.array_equal(sequence_index(np.arange(4), "independent"), np.arange(4))
    with pytest.raises(ValueError, match="resolved"):
        sequence_index(np.arange(4), "auto")


def test_camera_numbers_are_stateless_in_one_sequence():
    """A sample's numbers depend on (seed, pixel, sample) only: any order or subset of a batch draws them."""
    pixel = np.repeat(np.arange(5), 16)
    sample = np.tile(np.arange(16), 5)
    _, u = camera_numbers(2, "sobol", pixel, sample, 2, 1, "one_sequence")
    order = np.random.default_rng(1).permutation(pixel.size)
    _, v = camera_numbers(2, "sobol", pixel[order], sample[order], 2, 1, "one_sequence")
    np.testing.assert_array_equal(v, u[:, order])
    _, w = camera_numbers(2, "sobol", pixel, sample, 2, 1, "independent")
    assert np.array_equal(u[:, ::16], w[:, ::16]) and not np.array_equal(u, w)     # sample 0 is the same point
    assert np.array_equal(u[4], w[4])                    # the hashed dimension is keyed by the sample itself


def test_the_setting_is_validated_and_auto_resolves_by_what_reads_the_halves():
    assert RenderSettings().halves == "auto" and parse_settings({}).halves == "auto"
    assert parse_settings({"halves": "one_sequence"}).halves == "one_sequence"
    with pytest.raises(SceneError) as e:
        parse_settings({"halves": "whole"})
    assert "render.halves" in str(e.value) and "'auto', 'independent', 'one_sequence'" in str(e.value)
    st = RenderSettings(sampler="sobol")
    assert resolve_halves(st, False).halves == "one_sequence" and resolve_halves(st, True).halves == "independent"
    assert resolve_halves(RenderSettings(sampler="independent", halves="one_sequence"), True).halves == "independent"
    once = resolve_halves(st, False)
    assert resolve_halves(once, False) is once                                         # idempotent
    assert not once.split_halves and resolve_halves(st, True).split_halves
    with pytest.raises(SceneError) as e:
        resolve_halves(dataclasses.replace(st, halves="one_sequence"), True, "--halves")
    assert e.value.field == "--halves" and "adaptive" in str(e.value)


def _scene(res=16, spp=8, **settings):
    scene = load_scene(shared_path("peers", "scenes", "rough_sphere_a030.json"))
    scene.camera.width = scene.camera.height = res
    scene.settings = dataclasses.replace(scene.settings, spp=spp, **settings)
    return scene


@pytest.fixture(scope="module", params=["sobol", "cycles"])
def one_shot(request):
    scene = _scene(sampler=request.param)
    renderer = Renderer(scene)
    return scene, renderer, renderer.render()


def test_a_uniform_render_draws_one_sequence_and_says_what_its_error_is(one_shot):
    scene, renderer, ref = one_shot
    assert ref.settings.halves == "one_sequence" and ref.film.half_y is None and ref.film.one_sequence
    assert "not an estimate" in ref.film.stderr_method
    split = renderer.render(dataclasses.replace(scene.settings, halves="independent"))
    assert split.film.half_y is not None and not split.film.one_sequence
    assert not np.array_equal(split.film.sums, ref.film.sums)        # other numbers, the same expectation


@pytest.mark.parametrize("threads, batch", [(1, 1 << 17), (2, 1 << 17), (2, 512)])
def test_one_sequence_does_not_depend_on_threads_or_batches(one_shot, threads, batch):
    scene, renderer, ref = one_shot
    r = renderer.render(dataclasses.replace(scene.settings, threads=threads, batch_rays=batch))
    if batch == 1 << 17:
        np.testing.assert_array_equal(r.film.sums, ref.film.sums)
    else:       # the sums added in another grouping
        np.testing.assert_allclose(r.film.sums, ref.film.sums, rtol=1e-12, atol=1e-12)


def test_one_sequence_windows_give_the_one_shot_pixels(one_shot):
    """Tiles (windows) of the image: each pixel's samples, so its sums, are the one-shot render's."""
    scene, renderer, ref = one_shot
    W = scene.camera.width
    for window in ((0, 0, 8, 16), (8, 0, 16, 5), (8, 5, 16, 16)):
        r = renderer.render(RenderRequest(window=window))
        x0, y0, x1, y1 = window
        pix = (np.arange(y0, y1)[:, None] * W + np.arange(x0, x1)[None, :]).ravel()
        np.testing.assert_array_equal(r.film.sums[:, :, pix], ref.film.sums[:, :, pix])


def test_a_resumed_one_sequence_render_equals_the_one_shot_render(one_shot):
    scene, renderer, ref = one_shot
    first = renderer.render(dataclasses.replace(scene.settings, spp=3)).film
    r = renderer.render(RenderRequest(resume=first))
    np.testing.assert_allclose(r.film.sums, ref.film.sums, rtol=1e-12, atol=1e-12)
    assert r.film.half_y is None and r.film.one_sequence


def test_adaptive_sampling_switches_auto_to_independent_halves_and_refuses_one_sequence():
    scene = _scene(spp=8)
    renderer = Renderer(scene)
    ad = AdaptiveSettings(threshold=0.05, quantity="s0", min_spp=4, time_limit=0.0)
    r = renderer.render(RenderRequest(adaptive=ad))
    assert r.settings.halves == "independent" and r.film.half_y is not None
    with pytest.raises(SceneError) as e:
        renderer.render(RenderRequest(dataclasses.replace(scene.settings, halves="one_sequence"), adaptive=ad))
    assert e.value.field == "render.halves"


def test_one_sequence_has_the_expectation_of_independent_halves():
    """rough_sphere_a030 (a glossy sphere under a sky: every bounce's numbers from the pattern), 12 seeds each:
    the image means agree within 4 standard errors, and one sequence has less variance (measured 0.4×)."""
    scene = _scene(res=12, spp=16)
    renderer = Renderer(scene)
    got = {}
    for halves in ("one_sequence", "independent"):
        got[halves] = np.array([renderer.render(dataclasses.replace(scene.settings, seed=s, halves=halves))
                                .stokes_luminance()[0] for s in range(12)])
    a, b = got["one_sequence"], got["independent"]
    ma, mb = a.mean(axis=(1, 2)), b.mean(axis=(1, 2))
    se = np.sqrt(ma.var(ddof=1) / ma.size + mb.var(ddof=1) / mb.size)
    assert abs(ma.mean() - mb.mean()) < 4 * se
    assert a.var(axis=0, ddof=1).mean() < b.var(axis=0, ddof=1).mean()


# ------------------------------------------------------------------------------- the CLI and its files

def test_cli_records_the_resolved_halves_and_resume_never_mixes_them(tmp_path, capsys):
    """A uniform render writes polar.halves one_sequence, with --stderr too (the i.i.d. error, marked: the option
    does not change the image); --halves independent writes none (two independent sequences, as every file before)
    and --stderr's half-split estimate; a resume with "auto" continues the file's mode, naming another is refused,
    and continuing a one-sequence file adaptively is refused."""
    from engine import cli
    from engine.output.exr import read_stokes_exr
    from tests.cli.test_robustness_cli import small_demo
    scene = small_demo(tmp_path, spp=4)
    one, split, err = (str(tmp_path / f"{n}.exr") for n in ("one", "split", "err"))
    base = ["--no-previews", "--quiet"]
    assert cli.main(["render", scene, "-o", one, *base]) == 0
    assert cli.main(["render", scene, "-o", split, "--halves", "independent", *base]) == 0
    assert cli.main(["render", scene, "-o", err, "--stderr", *base]) == 0
    split_err = str(tmp_path / "split_err.exr")
    assert cli.main(["render", scene, "-o", split_err, "--stderr", "--halves", "independent", *base]) == 0
    for path in (one, err):
        assert read_stokes_exr(path)[2]["polar.halves"] == "one_sequence"
    np.testing.assert_array_equal(read_stokes_exr(err)[0], read_stokes_exr(one)[0])
    _, channels, header = read_stokes_exr(err)
    assert "S0.Y.stderr" in channels and "S0.Y.even" not in channels and "not an estimate" in header["polar.stderr"]
    for path in (split, split_err):
        _, channels, header = read_stokes_exr(path)
        assert "polar.halves" not in header and header["polar.sampler"] == "sobol"
    _, channels, header = read_stokes_exr(split_err)
    assert "S0.Y.even" in channels and header["polar.stderr"].startswith("stratified")
    capsys.readouterr()
    more = str(tmp_path / "more.exr")
    assert cli.main(["render", scene, "-o", more, "--resume", one, "--spp", "6", *base]) == 0
    assert read_stokes_exr(more)[2]["polar.halves"] == "one_sequence"
    assert cli.main(["render", scene, "-o", more, "--resume", split, "--spp", "6", *base]) == 0
    assert "polar.halves" not in read_stokes_exr(more)[2]
    capsys.readouterr()
    for args, named in ((["--resume", one, "--halves", "independent"], "halves"),
                        (["--resume", split, "--halves", "one_sequence"], "halves"),
                        (["--resume", one, "--noise-threshold", "0.1"], "half-buffers"),
                        (["--halves", "one_sequence", "--noise-threshold", "0.1"], "--halves")):
        status = cli.main(["render", scene, "-o", str(tmp_path / "x.exr"), "--spp", "6", *args, *base])
        lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
        assert status == 2 and len(lines) == 1 and named in lines[0], lines
    assert not (tmp_path / "x.exr").exists()
    # the one-sequence render resumed equals the one-shot 6-spp render (float32 means stored)
    whole = str(tmp_path / "whole.exr")
    assert cli.main(["render", scene, "-o", whole, "--spp", "6", *base]) == 0
    assert cli.main(["render", scene, "-o", more, "--resume", one, "--spp", "6", *base]) == 0
    np.testing.assert_allclose(read_stokes_exr(more)[0], read_stokes_exr(whole)[0], rtol=1e-5, atol=1e-7)
