"""RenderSettings.halves: a pixel's even and odd samples drawn as two independently scrambled sequences or as one
sequence (engine.scene.description.resolve_halves, engine.render.sampler.sequence_index): the nets it makes, how
"auto" resolves, that the film then keeps no half sums and says what its error is, and that every split of a render
(threads, batches, windows, resumption, a Dask cluster: tests/render/test_distributed.py) gives the one-shot image."""

import dataclasses

import numpy as np
import pytest

from engine.errors import SceneError
from engine.render.adaptive import AdaptiveSettings
from engine.render.film import HalfBuffers, OrderedSamples
from engine.render.halves import class_counts, part_classes
from engine.render.renderer import Renderer, RenderRequest
from engine.render.sampler import (PADDED_JITTER, PAIR_JITTER, SOBOL_DIRECTION, camera_numbers, cycles_pairs,
                                   padded_pairs, sequence_index, sobol_pairs, stratified_pair, vertex_pair)
from engine.scene.description import RenderSettings, resolve_halves
from engine.scene.loader import load_scene, parse_settings
from engine.spectral.cie import LUMINANCE_WEIGHTS
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


def test_the_setting_is_validated_and_auto_resolves_to_one_sequence():
    """"auto" is one sequence whether or not the render reads the half sums (adaptive sampling splits it into
    classes, engine.render.halves); the film keeps the class sums either way."""
    assert RenderSettings().halves == "auto" and parse_settings({}).halves == "auto"
    assert parse_settings({"halves": "one_sequence"}).halves == "one_sequence"
    with pytest.raises(SceneError) as e:
        parse_settings({"halves": "whole"})
    assert "render.halves" in str(e.value) and "'auto', 'independent', 'one_sequence'" in str(e.value)
    st = RenderSettings(sampler="sobol")
    assert resolve_halves(st).halves == "one_sequence"
    assert resolve_halves(RenderSettings(sampler="independent", halves="one_sequence")).halves == "independent"
    once = resolve_halves(st)
    assert resolve_halves(once) is once                                         # idempotent
    assert once.split_halves and not st.split_halves and not RenderSettings(sampler="independent").split_halves
    assert resolve_halves(dataclasses.replace(st, halves="one_sequence")).halves == "one_sequence"
    assert resolve_halves(dataclasses.replace(st, halves="independent")).halves == "independent"
    with pytest.raises(SceneError, match="render.halves: must be one of 'auto', 'independent', 'one_sequence'"):
        resolve_halves(dataclasses.replace(st, halves="one-sequence"))       # (settings built in Python)


def test_each_octave_class_of_one_sequence_is_a_net_and_even_odd_is_not():
    """The classes of one sequence (engine.render.halves: A = samples 0 … q − 1, B = q … c − 1, q the largest power
    of two below c): at c = 2^(m+1) each class of a pixel covers the elementary intervals of the pixel jitter's two
    dimensions (van der Corput and Sobol' dimension 2) evenly — it is a (0, m, 2)-net — and so does every deeper
    pair of each pattern; the even samples of the same sequence put every point in one half of the van der Corput
    dimension."""
    sample = np.arange(2 ** 10)
    for p in range(4):
        pixel = np.full(sample.size, 77 + p)
        for kind in ("stratified", "sobol", "padded", "cycles"):
            x, y = _draw(kind, pixel, sequence_index(sample, "one_sequence"))
            for m in range(1, 10):
                c = 2 ** (m + 1)
                n_a, n_b = class_counts(np.array([c]), "one_sequence")
                assert n_a[0] == n_b[0] == 2 ** m
                assert _is_net(x[:n_a[0]], y[:n_a[0]], m) and _is_net(x[n_a[0]:c], y[n_a[0]:c], m), (kind, p, m)
                if kind == "stratified":        # the jitter pair: the even samples miss half of van der Corput's
                    even = x[:c][0::2]
                    assert np.all(even < 0.5) or np.all(even >= 0.5)


def test_class_counts_and_the_streamed_octave_split():
    """n_A = the largest power of two below c; sample-by-sample addition (adaptive's half-buffers) and part sums
    folded into a film (uniform units) both give A = the sum of the first n_A samples, B = the rest."""
    n_a, n_b = class_counts(np.arange(10), "one_sequence")
    np.testing.assert_array_equal(n_a, [0, 0, 1, 2, 2, 4, 4, 4, 4, 8])
    np.testing.assert_array_equal(n_a + n_b, np.arange(10))
    np.testing.assert_array_equal(class_counts(np.arange(10), "independent")[0], (np.arange(10) + 1) // 2)
    sample = np.arange(8)
    assert part_classes(np.zeros(8, np.int64), sample, "independent") is sample        # the old split, unchanged
    pix = np.repeat(np.arange(3), 5)
    smp = np.tile(np.arange(4, 9), 3)                                 # every pixel's samples 4 … 8 (end 9: q = 8)
    np.testing.assert_array_equal(part_classes(pix, smp, "one_sequence"), smp >= 8)
    np.testing.assert_array_equal(part_classes(pix, smp, "one_sequence", 9), smp >= 8)
    rng = np.random.default_rng(3)
    n, spp = 6, 37
    y = rng.random((4, n, spp))
    q = class_counts(np.array([spp]), "one_sequence")[0][0]
    streamed = HalfBuffers(n, "one_sequence")
    for s0, s1 in ((0, 5), (5, 6), (6, 20), (20, 37)):            # parts of passes, in ascending order
        pix, smp = np.repeat(np.arange(n), s1 - s0), np.tile(np.arange(s0, s1), n)
        streamed.add(OrderedSamples(pix, smp, np.stack([y[:, pix, smp]] * 3, axis=1) / LUMINANCE_WEIGHTS.sum()))
    np.testing.assert_allclose(streamed.sums[0], y[:, :, :q].sum(axis=-1), rtol=1e-12)
    np.testing.assert_allclose(streamed.sums[1], y[:, :, q:].sum(axis=-1), rtol=1e-12)


def test_a_one_sequence_films_class_a_is_its_first_octave(one_shot):
    """A uniform 8-spp render's class A is its samples 0 … 3: the 4-spp render's luminance sums."""
    scene, renderer, ref = one_shot
    four = renderer.render(dataclasses.replace(scene.settings, spp=4)).film
    y4 = np.einsum("c,scn->sn", LUMINANCE_WEIGHTS, four.sums)
    np.testing.assert_allclose(ref.film.half_y[0], y4, rtol=1e-12, atol=1e-15)


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
    assert ref.settings.halves == "one_sequence" and ref.film.half_y is not None and ref.film.one_sequence
    assert ref.film.stderr_method.startswith("stratified one sequence") and "calibrated" in ref.film.stderr_method
    # the class sums add up to the luminance sums
    y = np.einsum("c,scn->sn", LUMINANCE_WEIGHTS, ref.film.sums)
    np.testing.assert_allclose(ref.film.half_y.sum(axis=0), y, rtol=1e-12, atol=1e-12)
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


def test_a_resumed_film_continues_in_its_own_halves_and_a_mismatch_is_refused(one_shot):
    """The Python API as the CLI's --resume: "auto" takes the film's split; an explicit other split is refused, never
    mixed into the film's class sums."""
    scene, renderer, _ = one_shot
    first = renderer.render(dataclasses.replace(scene.settings, spp=3, halves="independent")).film
    assert first.half_y is not None and first.halves == "independent"
    whole = renderer.render(dataclasses.replace(scene.settings, spp=6, halves="independent"))
    resumed = renderer.render(RenderRequest(dataclasses.replace(scene.settings, spp=6), resume=first))
    assert resumed.settings.halves == "independent" and not resumed.film.one_sequence
    np.testing.assert_allclose(resumed.film.half_y, whole.film.half_y, rtol=1e-12, atol=1e-12)
    with pytest.raises(ValueError, match="halves: cannot resume a film whose class sums split 'independent'"):
        renderer.render(RenderRequest(dataclasses.replace(scene.settings, spp=6, halves="one_sequence"),
                                      resume=first))


def test_a_resumed_one_sequence_render_equals_the_one_shot_render(one_shot):
    scene, renderer, ref = one_shot
    first = renderer.render(dataclasses.replace(scene.settings, spp=3)).film
    r = renderer.render(RenderRequest(resume=first))
    np.testing.assert_allclose(r.film.sums, ref.film.sums, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(r.film.half_y, ref.film.half_y, rtol=1e-12, atol=1e-12)
    assert r.film.one_sequence


def test_adaptive_sampling_keeps_one_sequence_and_independent_halves_stay_selectable():
    """"auto" and "one_sequence" with adaptive sampling: one sequence, the half-buffers its classes A/B (their sums
    are the film's class sums); "independent" draws the images of the versions before (two sequences, even/odd)."""
    scene = _scene(spp=8)
    renderer = Renderer(scene)
    ad = AdaptiveSettings(threshold=0.05, quantity="s0", min_spp=4, time_limit=0.0)
    r = renderer.render(RenderRequest(adaptive=ad))
    assert r.settings.halves == "one_sequence" and r.halves.halves == "one_sequence" and r.film.one_sequence
    one = renderer.render(RenderRequest(dataclasses.replace(scene.settings, halves="one_sequence"), adaptive=ad))
    np.testing.assert_array_equal(one.film.sums, r.film.sums)
    np.testing.assert_array_equal(r.film.half_y, r.halves.sums)
    split = renderer.render(RenderRequest(dataclasses.replace(scene.settings, halves="independent"), adaptive=ad))
    assert split.settings.halves == "independent" and split.halves.halves == "independent"
    assert not split.film.one_sequence and not np.array_equal(split.film.sums[:, :, :16], r.film.sums[:, :, :16])


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
    """A uniform render writes polar.halves one_sequence, with --stderr too (the calibrated class estimate, marked
    so: the option does not change the image); --halves independent writes none (two independent sequences, as
    every file before) and --stderr's even/odd estimate; a resume with "auto" continues the file's mode, naming
    another is refused, and continuing a uniform file adaptively is refused (no half-buffers)."""
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
    assert "S0.Y.stderr" in channels and "S0.Y.even" in channels
    assert header["polar.stderr"].startswith("stratified one sequence")
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
    for args, named in ((["--resume", one, "--halves", "independent"], "halves is 'one_sequence' in the file but "
                                                                         "'independent' now"),
                        (["--resume", split, "--halves", "one_sequence"], "halves is 'independent' in the file"),
                        (["--resume", one, "--noise-threshold", "0.1"], "half-buffers")):
        status = cli.main(["render", scene, "-o", str(tmp_path / "x.exr"), "--spp", "6", *args, *base])
        lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
        assert status == 2 and len(lines) == 1 and named in lines[0], lines
    assert not (tmp_path / "x.exr").exists()
    # the one-sequence render resumed equals the one-shot 6-spp render (float32 means stored)
    whole = str(tmp_path / "whole.exr")
    assert cli.main(["render", scene, "-o", whole, "--spp", "6", *base]) == 0
    assert cli.main(["render", scene, "-o", more, "--resume", one, "--spp", "6", *base]) == 0
    np.testing.assert_allclose(read_stokes_exr(more)[0], read_stokes_exr(whole)[0], rtol=1e-5, atol=1e-7)


def test_cli_adaptive_renders_resume_in_their_own_halves(tmp_path, capsys):
    """An adaptive render draws one sequence (polar.halves one_sequence) and resumes to the direct render bit for
    bit; a file of an adaptive render with independent halves (no polar.halves: every file before one sequence)
    resumes with "auto" as independent halves, equal to the direct independent render."""
    from engine import cli
    from engine.output.exr import read_stokes_exr
    from tests.cli.test_robustness_cli import small_demo
    scene = small_demo(tmp_path, spp=4)
    base = ["--no-previews", "--quiet", "--noise-threshold", "0.02", "--min-spp", "4"]
    for halves in ("auto", "independent"):
        part, whole, more = (str(tmp_path / f"{halves}_{n}.exr") for n in ("part", "whole", "more"))
        assert cli.main(["render", scene, "-o", part, "--spp", "8", "--halves", halves, *base]) == 0
        assert cli.main(["render", scene, "-o", whole, "--spp", "16", "--halves", halves, *base]) == 0
        header = read_stokes_exr(part)[2]
        assert header.get("polar.halves") == ("one_sequence" if halves == "auto" else None)
        assert cli.main(["render", scene, "-o", more, "--resume", part, "--spp", "16", *base]) == 0
        a, b = read_stokes_exr(more), read_stokes_exr(whole)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1]["spp"], b[1]["spp"])
        assert a[2].get("polar.halves") == header.get("polar.halves")
    capsys.readouterr()


def test_the_estimates_pilot_draws_one_sequence():
    """``estimate``'s pilot (an adaptive first pass) resolves "auto" to one sequence, its half-buffers the octave
    classes, and predicts from them."""
    from engine.render.estimate import pilot_render, predict
    scene = _scene(spp=8)
    pilot, seconds = pilot_render(Renderer(scene), scene.settings, 8)
    assert pilot.settings.halves == "one_sequence" and pilot.halves.halves == "one_sequence"
    np.testing.assert_array_equal(pilot.halves.sums[0].sum(axis=0) != 0, pilot.film.sums[0].sum(axis=0) != 0)
    p = predict(pilot.film, pilot.halves, "s0", 0.05, 8, 64, seconds, sampler="sobol")
    assert p.counts.min() >= 8 and p.counts.max() <= 64 and np.isfinite(p.variance).all()
