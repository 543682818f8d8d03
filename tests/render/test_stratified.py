"""RenderSettings.sampler "stratified" (and "sobol", the default, in the determinism tests): same expectation
as the independent sampler, an honest standard error, and the determinism of every other render (threads,
batches, resumption, adaptive rounds)."""

import copy
import dataclasses
import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.materials.lambert import Lambert
from engine.output.exr import read_stokes_exr
from engine.render.film import Film
from engine.render.renderer import Renderer, RenderRequest
from engine.scene.description import Camera, Mesh, RenderSettings, Scene
from engine.scene.loader import parse_settings
from engine.scene.shapes import quad
from engine.spectral import ConstantSpectrum, RGBIlluminantSpectrum

RHO = 0.6
H = 2.0
WIDTH = 4.0                 # the orthographic camera sees x, y ∈ [−2, 2]
SEEDS = 4


def white(scale):
    return RGBIlluminantSpectrum([1.0, 1.0, 1.0], scale)


def plane_scene(meshes, res, spp, max_depth=2):
    """A Lambertian floor (albedo RHO) at z = 0 seen straight from above by an orthographic camera."""
    floor = quad(*[np.array(p, float) for p in ([-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0])])
    cam = Camera(origin=np.array([0.0, 0.0, 5.0]), target=np.zeros(3), up=np.array([0.0, 1.0, 0.0]),
                 width=res, height=res, projection="orthographic", ortho_width=WIDTH)
    return Scene(camera=cam, meshes=[Mesh("floor", floor.vertices, floor.faces, ["grey"], np.zeros(2, np.int32)),
                                     *meshes],
                 materials={"grey": Lambert(ConstantSpectrum(RHO)), "black": Lambert(ConstantSpectrum(0.0))},
                 lights=[], settings=RenderSettings(spp=spp, spectral="mono", max_depth=max_depth))


#: a tilted square (corners counter-clockwise seen from +z) at z = 1 facing the camera: its edges
#: cross pixels at every angle and offset
DIAMOND = [(0.13, -1.23), (1.21, 0.05), (-0.03, 1.19), (-1.17, -0.11)]


def emitter_scene(L, res, spp):
    up = quad(*[np.array([x, y, 1.0]) for x, y in DIAMOND])
    return plane_scene([Mesh("lamp", up.vertices, up.faces, ["black"], np.zeros(2, np.int32), emission=white(L))],
                       res, spp, max_depth=1)


def lamp_scene(L, a, res, spp):
    """A square lamp of side a at height H facing down onto the floor."""
    q = quad(*[np.array(p, float) for p in ([-a / 2, a / 2, H], [a / 2, a / 2, H], [a / 2, -a / 2, H],
                                             [-a / 2, -a / 2, H])])
    return plane_scene([Mesh("lamp", q.vertices, q.faces, ["black"], np.zeros(2, np.int32), emission=white(L))],
                       res, spp)


def coverage(res, polygon, n=200):
    """Fraction of each pixel (res, res) (row 0 at the top) inside the convex polygon, by an n × n
    grid of points per pixel (error ≲ 1/n per edge crossing)."""
    c = (np.arange(res * n) + 0.5) / (res * n) * WIDTH - WIDTH / 2
    x, y = c[None, :], -c[:, None]
    inside = np.ones((res * n, res * n), bool)
    P = np.array(polygon)
    for (x0, y0), (x1, y1) in zip(P, np.roll(P, -1, axis=0)):
        inside &= (x1 - x0) * (y - y0) - (y1 - y0) * (x - x0) >= 0
    return inside.reshape(res, n, res, n).mean(axis=(1, 3))


def seed_renders(scene, sampler, seeds=SEEDS, spp=None):
    """(S0 images (seeds, H, W), their standard errors) of renders with seeds 0…seeds−1."""
    renderer, out, errors = Renderer(scene), [], []
    for seed in range(seeds):
        st = dataclasses.replace(scene.settings, seed=seed, sampler=sampler,
                                 spp=scene.settings.spp if spp is None else spp)
        r = renderer.render(st)
        out.append(r.stokes_luminance()[0])
        errors.append(r.film.stderr_luminance()[0])
    return np.array(out), np.array(errors)


# ------------------------------------------------------------------------------------------ settings

def test_the_sampler_setting_is_validated_naming_the_field_and_the_choices():
    # one default everywhere: the scene format, the command line, the Python API and Blender
    assert RenderSettings().sampler == "sobol" and parse_settings({}).sampler == "sobol"
    assert parse_settings({"sampler": "independent"}).sampler == "independent"
    assert parse_settings({"sampler": "stratified"}).sampler == "stratified"
    assert RenderSettings(sampler="sobol").stratified and RenderSettings(sampler="stratified").stratified
    assert not RenderSettings(sampler="independent").stratified        # no even/odd half sums
    with pytest.raises(SceneError) as e:
        parse_settings({"sampler": "halton"})
    assert "render.sampler" in str(e.value) and "'independent', 'stratified', 'sobol', 'padded'" in str(e.value)


# ---------------------------------------------------------------------------------------- unbiasedness

def test_a_camera_visible_emitter_keeps_its_exact_pixel_coverage():
    """Emitters only (max_depth 1): a pixel's value is L × the share of it the tilted square covers.
    Mean over 8 seeds of stratified renders = that over the edge pixels within 4 standard errors (+ the
    coverage grid's error), and per pixel for ≥ 90 % of them (a corner's sliver is a rare event that
    16 samples × 8 seeds do not see fairly); the stratified jitter leaves ≥ 3× less variance there."""
    L, res, seeds = 2.0, 16, 8
    scene = emitter_scene(L, res, 16)
    expected = L * coverage(res, DIAMOND)
    strat, se = seed_renders(scene, "stratified", seeds)
    indep, _ = seed_renders(scene, "independent", seeds)
    mean, se_mean = strat.mean(0), np.sqrt((se ** 2).sum(0)) / seeds
    edge = (expected > 0.02 * L) & (expected < 0.98 * L)
    assert edge.sum() > 20
    assert np.mean(np.abs(mean - expected)[edge] <= 4 * se_mean[edge] + 0.01 * L) >= 0.9
    assert abs((mean - expected)[edge].sum()) < 4 * np.sqrt((se_mean[edge] ** 2).sum()) + 0.005 * L * edge.sum()
    # interior pixels are exact; the edges' variance falls
    assert np.all(strat[:, expected == L] == L) and np.all(strat[:, expected == 0] == 0)
    assert indep.var(0, ddof=1)[edge].mean() > 3 * strat.var(0, ddof=1)[edge].mean()


def test_an_area_lamp_on_a_floor_keeps_the_closed_form_and_the_independent_mean():
    """A small square lamp over a Lambertian floor: stratified mean over seeds = the closed form
    (ρ/π · L·a² · cos²/r², finite-size error ~ (a/H)²) per pixel within 4σ + 0.5 % and over the image,
    and = the independent sampler's mean within noise."""
    L, a, res = 500.0, 0.1, 12
    scene = lamp_scene(L, a, res, 16)
    c = (np.arange(res) + 0.5) / res * WIDTH - WIDTH / 2
    r2 = c[None, :] ** 2 + c[:, None] ** 2 + H * H
    expected = RHO / math.pi * L * a * a * (H * H / r2) / r2
    strat, se = seed_renders(scene, "stratified")
    indep, se_i = seed_renders(scene, "independent")
    mean, se_mean = strat.mean(0), np.sqrt((se ** 2).sum(0)) / SEEDS
    assert np.mean(np.abs(mean - expected) < 4 * se_mean + 0.005 * expected) > 0.99
    total_se = np.sqrt((se_mean ** 2).sum())
    assert abs((mean - expected).sum()) < 4 * total_se + 0.005 * expected.sum()
    diff_se = np.sqrt(total_se ** 2 + ((se_i ** 2).sum(0) / SEEDS ** 2).sum())
    assert abs((mean - indep.mean(0)).sum()) < 4 * diff_se


@pytest.mark.parametrize("sampler", ["stratified", "cycles"])
def test_stratified_wavelengths_keep_the_mean_and_cut_the_spectral_noise(sampler):
    """A coloured emitter filling the view, seen directly and traced spectrally without the RGB
    reduction: a pixel's only noise is its sampled wavelengths.  Stratified over the pixel's samples,
    the image mean = the independent sampler's within 4σ, and the pixel variance falls > 100×
    (measured 620× at 16 spp: the estimate is smooth in the wavelengths' number; 1.1× if the
    stratified number ignored that the wavelengths repeat with period 1/count in it; "cycles" 463×, 17× with its
    wavelengths' set Owen-scrambled instead of digitally shifted)."""
    res = 8
    wall = quad(*[np.array([x, y, 1.0]) for x, y in ((-9, -9), (9, -9), (9, 9), (-9, 9))])
    scene = plane_scene([Mesh("wall", wall.vertices, wall.faces, ["black"], np.zeros(2, np.int32),
                              emission=RGBIlluminantSpectrum([1.0, 0.25, 0.05], 2.0))], res, 16, max_depth=1)
    scene.settings = dataclasses.replace(scene.settings, spectral="spectral", reduce_spectral="off")
    strat, se = seed_renders(scene, sampler)
    indep, se_i = seed_renders(scene, "independent")
    diff_se = np.sqrt(((se ** 2).sum() + (se_i ** 2).sum()) / SEEDS ** 2) / res
    assert abs(strat.mean() - indep.mean()) < 4 * diff_se
    ratio = indep.var(0, ddof=1).mean() / strat.var(0, ddof=1).mean()
    print(f"variance independent ÷ stratified {ratio:.1f}")
    assert ratio > 100, ratio


@pytest.mark.parametrize("sampler", ["stratified", "cycles"])
def test_a_stratified_lens_keeps_the_mean_and_cuts_the_defocus_noise(sampler):
    """The tilted emitter square seen through a thin lens focused far in front of it (blur ≈ ±2.4 pixels,
    so the pixel jitter's share of the noise is small): stratified and independent means agree within
    4σ over the blurred edge, whose pixel variance falls > 1.8× at 64 spp (measured 2.6–2.7×; 0.9–1.1×
    with only the jitter stratified: an edge across the lens disk gains ~√n, less than a smooth integrand; "cycles"
    3.8×)."""
    res, seeds = 16, 8
    scene = emitter_scene(2.0, res, 64)
    scene.camera.aperture_radius, scene.camera.focus_distance = 0.2, 1.0
    strat, se = seed_renders(scene, sampler, seeds)
    indep, se_i = seed_renders(scene, "independent", seeds)
    mean = strat.mean(0)
    edge = (mean > 0.1) & (mean < 1.9)
    assert edge.sum() > 60
    diff_se = np.sqrt(((se ** 2).sum(0) + (se_i ** 2).sum(0))[edge].sum()) / seeds
    assert abs((mean - indep.mean(0))[edge].sum()) < 4 * diff_se
    ratio = indep.var(0, ddof=1)[edge].mean() / strat.var(0, ddof=1)[edge].mean()
    print(f"variance independent ÷ stratified {ratio:.1f}")
    assert ratio > 1.8, ratio


# ----------------------------------------------------------------------------------- standard error

@pytest.mark.parametrize("halves", ["independent", "one_sequence"])
def test_the_stratified_standard_error_is_honest_against_a_reference(halves):
    """A lamp-lit floor with a camera-visible emitter in front: z = (pixel − reference) / √(se² + se_ref²)
    over the pixels of 4 stratified 16-spp renders has rms ≈ 1 (the error it reports is the error it
    has), where the i.i.d. formula on the same samples overestimates it (rms(z) < 0.85).  With one sequence the
    half sums are its octave classes (engine.render.halves), correlated, and the calibrated error (factor 1/1.2,
    from the peer scenes, where the raw one overstates the image's error 0.75–2.1×) understates this floor's:
    measured rms(z) 1.74 (the raw estimate 0.69× the error here), where the i.i.d. formula gives 0.44."""
    res = 16
    lamp = lamp_scene(40.0, 1.0, res, 16).meshes[1]
    up = quad(*[np.array([x * 0.6, y * 0.6, 1.0]) for x, y in DIAMOND])
    glow = Mesh("glow", up.vertices, up.faces, ["black"], np.zeros(2, np.int32), emission=white(1.5))
    scene = plane_scene([lamp, glow], res, 16)
    ref_st = dataclasses.replace(scene.settings, spp=1024, seed=99, halves="independent")     # its honest error
    ref = Renderer(scene).render(ref_st)
    y_ref, se_ref = ref.stokes_luminance()[0], ref.film.stderr_luminance()[0]
    renderer, z, z_iid = Renderer(scene), [], []
    for seed in range(SEEDS):
        st = dataclasses.replace(scene.settings, seed=seed, sampler="stratified", halves=halves)
        r = renderer.render(st)
        y, se = r.stokes_luminance()[0], r.film.stderr_luminance()[0]
        assert r.film.half_y is not None and r.film.one_sequence == (halves == "one_sequence")
        assert ("one sequence" in r.film.stderr_method) == (halves == "one_sequence")
        iid = copy.copy(r.film)
        iid.half_y = None
        se_iid = iid.stderr_luminance()[0]
        ok = se_iid > 0
        z.append((y - y_ref)[ok] / np.sqrt(se ** 2 + se_ref ** 2)[ok])
        z_iid.append((y - y_ref)[ok] / np.sqrt(se_iid ** 2 + se_ref ** 2)[ok])
    rms, rms_iid = np.sqrt(np.mean(np.concatenate(z) ** 2)), np.sqrt(np.mean(np.concatenate(z_iid) ** 2))
    print(f"rms(z) {rms:.3f}, i.i.d. formula {rms_iid:.3f}")
    if halves == "one_sequence":
        assert 1.2 < rms < 2.4 and rms_iid < 0.6, (rms, rms_iid)      # measured 1.74: see the docstring
        return
    assert 0.85 < rms < 1.2, rms
    assert rms_iid < 0.85, rms_iid


def test_the_variance_ratio_is_one_for_independent_halves_and_local():
    """stratified_variance_ratio of i.i.d. samples is ≈ 1 (the half-split and the i.i.d. estimates
    agree in expectation), and it follows a pixel region whose halves agree exactly (ratio 0)."""
    rng = np.random.default_rng(3)
    W, Hh, n = 20, 10, 16
    film = Film(W, Hh)
    pixel = np.tile(np.arange(W * Hh), n)
    sample = np.repeat(np.arange(n), W * Hh)
    values = np.zeros((4, 3, pixel.size))
    values[0] = rng.exponential(1.0, pixel.size)[None, :]
    from engine.render.film import SampleSums
    film.add(SampleSums.of(pixel, values, sample=sample))
    iid = copy.copy(film)
    iid.half_y = None
    ratio = (film.stderr_luminance()[0] / iid.stderr_luminance()[0]) ** 2
    assert abs(ratio.mean() - 1) < 0.1
    # the right half's pixels repeat each even sample in the next odd one: A = B there
    right = (np.arange(W * Hh) % W) >= W // 2
    v = values.copy()
    twin = right[pixel] & (sample % 2 == 1)
    v[:, :, twin] = values[:, :, np.flatnonzero(twin) - W * Hh]
    film = Film(W, Hh)
    film.add(SampleSums.of(pixel, v, sample=sample))
    se = film.stderr_luminance()[0]
    assert np.all(se[:, W // 2 + 2:] == 0) and np.all(se[:, :W // 2 - 2] > 0)


# -------------------------------------------------------------------------------------- determinism

@pytest.fixture(scope="module", params=[(s, h) for s in ("stratified", "sobol", "padded", "cycles")
                                        for h in ("independent", "one_sequence")])
def lamp_reference(request):
    scene = lamp_scene(40.0, 1.0, 16, 8)
    sampler, halves = request.param
    scene.settings = dataclasses.replace(scene.settings, sampler=sampler, halves=halves)
    ref = Renderer(scene).render()
    assert ref.film.half_y is not None and ref.film.one_sequence == (halves == "one_sequence")
    return scene, ref


def _same_halves(a, b):
    """Both films' class sums (even/odd, or one sequence's octave classes: engine.render.halves) equal within float
    rounding."""
    assert a.half_y is not None and b.half_y is not None
    np.testing.assert_allclose(a.half_y, b.half_y, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("threads", [1, 2])
def test_stratified_images_do_not_depend_on_threads(lamp_reference, threads):
    scene, ref = lamp_reference
    st = dataclasses.replace(scene.settings, threads=threads)
    r = Renderer(scene).render(st)
    assert np.array_equal(r.film.sums, ref.film.sums) and np.array_equal(r.film.half_y, ref.film.half_y)
    assert np.array_equal(r.film.stderr_luminance(), ref.film.stderr_luminance())


def test_stratified_images_do_not_depend_on_the_batch_size(lamp_reference):
    """Smaller batches split the sample passes into more work units: the same numbers per sample,
    sums added in another grouping (equal within float rounding)."""
    scene, ref = lamp_reference
    st = dataclasses.replace(scene.settings, batch_rays=1024)
    r = Renderer(scene).render(st)
    np.testing.assert_allclose(r.film.sums, ref.film.sums, rtol=1e-12, atol=1e-12)
    _same_halves(r.film, ref.film)


def test_a_resumed_stratified_render_equals_the_uninterrupted_one(lamp_reference):
    """4 samples, then resumed to 8 from the film: the same sums (up to the addition order of a
    batch split, which is none here: passes 0–3 then 4–7) and half sums as one 8-sample render."""
    scene, ref = lamp_reference
    renderer = Renderer(scene)
    first = renderer.render(dataclasses.replace(scene.settings, spp=4)).film
    r = renderer.render(RenderRequest(dataclasses.replace(scene.settings, spp=8), resume=first))
    np.testing.assert_allclose(r.film.sums, ref.film.sums, rtol=1e-12, atol=1e-12)
    _same_halves(r.film, ref.film)


def test_cli_writes_the_sampler_and_resume_refuses_another(tmp_path, capsys):
    """The default render is sobol (header polar.sampler); an independent one writes no sampler
    header, as every file before stratified became the default did, and resumes without naming it
    (the sampler is read from the file, as the seed is); naming another one is refused; a stratified
    file (the default before sobol) resumes as stratified."""
    from engine import cli
    from tests.cli.test_robustness_cli import small_demo
    scene = small_demo(tmp_path, spp=4)
    out = tmp_path / "a.exr"
    assert cli.main(["render", scene, "-o", str(out), "--stderr", "--no-previews", "--quiet"]) == 0
    stokes, channels, header = read_stokes_exr(str(out))
    assert header["polar.sampler"] == "sobol" and "S0.Y.stderr" in channels
    plain = tmp_path / "b.exr"
    assert cli.main(["render", scene, "-o", str(plain), "--sampler", "independent", "--no-previews",
                     "--quiet"]) == 0
    assert "polar.sampler" not in read_stokes_exr(str(plain))[2]
    capsys.readouterr()
    status = cli.main(["render", scene, "-o", str(tmp_path / "c.exr"), "--resume", str(out), "--spp", "6",
                       "--sampler", "independent", "--no-previews", "--quiet"])
    assert status == 2 and "sampler" in capsys.readouterr().err
    assert cli.main(["render", scene, "-o", str(tmp_path / "d.exr"), "--resume", str(out), "--spp", "6",
                     "--no-previews", "--quiet"]) == 0
    assert read_stokes_exr(str(tmp_path / "d.exr"))[2]["polar.sampler"] == "sobol"
    assert cli.main(["render", scene, "-o", str(tmp_path / "e.exr"), "--resume", str(plain), "--spp", "6",
                     "--no-previews", "--quiet"]) == 0                  # an older (independent) file
    assert "polar.sampler" not in read_stokes_exr(str(tmp_path / "e.exr"))[2]
    strat, whole = tmp_path / "f.exr", tmp_path / "g.exr"
    assert cli.main(["render", scene, "-o", str(strat), "--sampler", "stratified", "--no-previews", "--quiet"]) == 0
    assert cli.main(["render", scene, "-o", str(whole), "--sampler", "stratified", "--spp", "6", "--no-previews",
                     "--quiet"]) == 0
    resumed = tmp_path / "h.exr"
    assert cli.main(["render", scene, "-o", str(resumed), "--resume", str(strat), "--spp", "6", "--no-previews",
                     "--quiet"]) == 0                                  # an older (stratified) file
    resumed_stokes, _, resumed_header = read_stokes_exr(str(resumed))
    assert resumed_header["polar.sampler"] == "stratified"
    np.testing.assert_allclose(resumed_stokes, read_stokes_exr(str(whole))[0], rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("sampler", ["stratified", "sobol", "padded", "cycles"])
def test_a_resumed_stratified_exr_keeps_the_stratified_standard_error(tmp_path, capsys, sampler):
    """--stderr of a stratified render writes the even samples' means (S*.Y.even) and names the
    estimate (polar.stderr); resuming from that file gives the uninterrupted render's error."""
    from engine import cli
    from tests.cli.test_robustness_cli import small_demo
    scene = small_demo(tmp_path, spp=4)
    opts = ["--sampler", sampler, "--halves", "independent", "--stderr", "--no-previews", "--quiet"]
    part, whole, resumed = (str(tmp_path / f"{n}.exr") for n in ("part", "whole", "resumed"))
    assert cli.main(["render", scene, "-o", part, *opts]) == 0
    assert cli.main(["render", scene, "-o", whole, "--spp", "8", *opts]) == 0
    assert cli.main(["render", scene, "-o", resumed, "--spp", "8", "--resume", part, *opts]) == 0
    _, a, header = read_stokes_exr(whole)
    _, b, _ = read_stokes_exr(resumed)
    assert header["polar.stderr"].startswith("stratified") and "S3.Y.even" in a
    for i in range(4):
        np.testing.assert_allclose(b[f"S{i}.Y.stderr"], a[f"S{i}.Y.stderr"], rtol=1e-3, atol=1e-7)


@pytest.mark.parametrize("sampler", ["stratified", "sobol", "padded", "cycles"])
def test_stratified_adaptive_sampling_is_deterministic_and_reports_the_stratified_error(sampler):
    """Adaptive sampling with stratified numbers: its even/odd half-buffers are the film's half sums
    (so the reported standard error is the stratified one), and the counts and image do not depend
    on threads or batch size."""
    from engine.render.adaptive import AdaptiveSettings
    from engine.scene.loader import load_scene
    from tests.conftest import shared_path
    scene = load_scene(shared_path("peers", "scenes", "fresnel_sphere.json"))
    scene.camera.width = scene.camera.height = 24
    scene.settings = dataclasses.replace(scene.settings, spp=32, sampler=sampler)
    ad = AdaptiveSettings(threshold=0.015, quantity="s0", min_spp=8)
    renderer = Renderer(scene)
    runs = []
    for threads, batch in ((1, 1 << 17), (2, 700)):
        st = dataclasses.replace(scene.settings, threads=threads, batch_rays=batch)
        runs.append(renderer.render(RenderRequest(st, adaptive=ad)))
    a, b = runs
    assert np.array_equal(a.film.count, b.film.count) and len(np.unique(a.film.count)) > 1
    assert np.array_equal(a.film.sums, b.film.sums)
    assert a.film.half_y is a.halves.sums
    iid = copy.copy(a.film)
    iid.half_y = None
    assert np.mean(a.film.stderr_luminance()[0]) < np.mean(iid.stderr_luminance()[0])
