"""The "sobol" sampler (the default): the camera's numbers exactly as "stratified" draws them, the first vertex's
as "cycles" does (engine.render.sampler.vertex_pattern), every deeper vertex's numbers from
shuffled, Owen-scrambled Sobol' (0, 2)-sequence pairs (engine.kernels.sobol, engine.render.sampler.sobol_pairs)
where "stratified" hashes them.

The pairs' numbers are functions of (seed, pixel, sample, pair) alone, every pair of a pixel's first 2^m
even (or odd) samples is a (0, m, 2)-net, the pairs and pixels are decorrelated, the even and odd samples
are independent sequences; renders keep the independent sampler's expectation, equal "stratified"'s bit
for bit for camera rays alone, and have less noise where deeper vertices matter.
The determinism of whole renders (threads, batch size, resumption, adaptive rounds) is tested with
the other samplers' tests in tests/render/test_stratified.py, parametrised by the sampler.
"""

import dataclasses

import numpy as np
import pytest

from engine.render.renderer import Renderer, RenderRequest
from engine.render.sampler import SOBOL_PER_BOUNCE, padded_pairs, sobol_pair_index, sobol_pairs, vertex_pattern

#: pairs tested: the second vertex's, the third's, a deep vertex's, a very deep one
PAIRS = [0, 1, 2, 3, SOBOL_PER_BOUNCE, sobol_pair_index(7, 1), sobol_pair_index(300, 2)]


def net_cells(x, y, m, kx):
    """Elementary-interval index of each point for intervals 2^-kx × 2^-(m − kx)."""
    return (np.floor(x * 2 ** kx) * 2 ** (m - kx) + np.floor(y * 2 ** (m - kx))).astype(np.int64)


def is_net(x, y, m):
    """True if the 2^m points (x, y) have one point in each elementary interval of area 2^-m, every shape."""
    return all(np.array_equal(np.sort(net_cells(x, y, m, kx)), np.arange(2 ** m)) for kx in range(m + 1))


def test_pair_layout():
    """The pairs start at the second vertex (bounce 1); the first one draws "cycles"' sets."""
    assert sobol_pair_index(1, 0) == 0
    assert sobol_pair_index(3, 1) == 2 * SOBOL_PER_BOUNCE + 1
    with pytest.raises(ValueError):
        sobol_pair_index(0, 0)


# ------------------------------------------------------------------------------ determinism

#: the samplers drawing pairs: "sobol" (every pair Owen-scrambled) and "padded" (the jitter Owen, the others XOR)
PAIRS_OF = [sobol_pairs, padded_pairs]


@pytest.mark.parametrize("sobol_pairs", PAIRS_OF)
def test_numbers_depend_only_on_seed_pixel_sample_and_pair(sobol_pairs):
    """Any batch split, path order and pair list gives each (seed, pixel, sample, pair) the same number."""
    rng = np.random.default_rng(1)
    n = 3000
    pixel = rng.integers(0, 1 << 21, n)
    sample = np.where(rng.random(n) < 0.7, rng.integers(0, 256, n), rng.integers(0, 1 << 34, n))
    pairs = [0, 5, 41, 4000]
    full = sobol_pairs(9, pixel, sample, pairs)
    assert full.shape == (8, n) and np.all((full >= 0) & (full < 1))
    order = rng.permutation(n)
    shuffled = sobol_pairs(9, pixel[order], sample[order], pairs)
    np.testing.assert_array_equal(shuffled, full[:, order])
    for part in np.array_split(np.arange(n), 7):                     # batches
        np.testing.assert_array_equal(sobol_pairs(9, pixel[part], sample[part], pairs), full[:, part])
    swapped = sobol_pairs(9, pixel, sample, [4000, 41])
    np.testing.assert_array_equal(swapped, np.concatenate((full[6:8], full[4:6])))
    assert not np.array_equal(sobol_pairs(10, pixel, sample, pairs), full)       # the seed matters


@pytest.mark.parametrize("n", [0, 1, 2000])
def test_the_compiled_numbers_are_the_numpy_twins_bit_for_bit(n):
    from engine import kernels
    from engine.kernels import sobol
    from engine.render.sampler import _seed_key
    if not kernels.COMPILED:
        pytest.skip("Numba kernels disabled")
    rng = np.random.default_rng(n + 3)
    pixel = rng.integers(0, 1 << 22, n)
    sample = np.where(rng.random(n) < 0.5, rng.integers(0, 64, n), rng.integers(0, 1 << 40, n))
    pairs = np.array([0, 1, 2, 3, 17, 1 << 20], np.int64)
    for seed in (0, 5, 2 ** 63 - 1):
        for owen in (None, np.array([True, False, False, True, False, False])):     # "sobol"'s, "padded"'s
            a = sobol.owen_sobol_pairs_numpy(_seed_key(seed), pixel, sample, pairs, owen)
            b = sobol.owen_sobol_pairs_numba(_seed_key(seed), pixel, sample, pairs, owen)
            assert np.array_equal(a, b)
        # "cycles"' sets (rows: a set's coordinates 0–3, sets in any order)
        sets, row_set = np.array([0, 2, 3, 4, 5, 1 << 20], np.int64), np.array([0, 0, 2, 2, 2, 2, 3, 5, 1, 4], np.int64)
        row_coord = np.array([0, 1, 0, 1, 2, 3, 2, 0, 1, 0], np.int64)
        shift = np.array([False, True, False, False, False, True])                       # the wavelengths' set
        a = sobol.owen_sobol_sets_numpy(_seed_key(seed), pixel, sample, sets, row_set, row_coord, shift)
        b = sobol.owen_sobol_sets_numba(_seed_key(seed), pixel, sample, sets, row_set, row_coord, shift)
        assert np.array_equal(a, b)


# ---------------------------------------------------------------------------- stratification

@pytest.mark.parametrize("sobol_pairs", PAIRS_OF)
@pytest.mark.parametrize("pair", PAIRS)
def test_each_pixels_first_samples_of_every_pair_are_nets(pair, sobol_pairs):
    """For a pixel, the first 2^k even samples of a pair (and the first 2^k odd ones) are a (0, k, 2)-net
    for every k ≤ 7: each of the 2^k elementary intervals of every shape holds exactly one point (so each
    coordinate alone is stratified in 2^k strata); also a later aligned block (samples 2^k·c … of the half)."""
    m = 7
    for pixel in (0, 1, 12345, 1 << 20):
        for parity in (0, 1):
            sample = parity + 2 * np.arange(2 ** m + 2 ** 5)
            x, y = sobol_pairs(3, np.full(sample.size, pixel), sample, [pair])
            for k in range(1, m + 1):
                assert is_net(x[:2 ** k], y[:2 ** k], k), (pixel, parity, k)
            assert is_net(x[2 ** m:], y[2 ** m:], 5)                 # the block of indices 128 … 159


def test_pixels_and_pairs_are_decorrelated():
    """Pair j of pixel a against pair j of pixel b (the same sample indices), and pairs j, j' of one
    pixel: the correlation over a pixel's 64 samples has mean ≈ 0 and mean square of the order of
    independent uniforms' 1/63 over 2000 pixels (measured 1.5/63 between pairs: the nested index shuffle
    keeps every block of 2^k samples a block, so the top digits of two pairs are both (bit 0 of the index)
    XOR (a function of its other bits) and their correlation has the variance of 32 samples; a random
    permutation would need the sample count ahead), where unshuffled pairs (the same index order in each
    pair's sequence, only scrambled) are strongly dependent (mean square 36/63 between the x of two pairs,
    0.008/63 between the x of one and the y of the other)."""
    n_pix, spp = 2000, 64
    pixel = np.repeat(np.arange(n_pix), spp)
    sample = np.tile(np.arange(0, 2 * spp, 2), n_pix)
    u = sobol_pairs(4, pixel, sample, [3, 4, 9, 50]).reshape(8, n_pix, spp)
    other = sobol_pairs(4, pixel + n_pix, sample, [3]).reshape(2, n_pix, spp)

    def r(a, b):
        a = a - a.mean(1, keepdims=True)
        b = b - b.mean(1, keepdims=True)
        return (a * b).sum(1) / np.sqrt((a * a).sum(1) * (b * b).sum(1))

    combos = [(u[0], other[0]), (u[1], other[1])]                       # pixel a vs pixel b, same pair
    combos += [(u[i], u[j]) for i in range(8) for j in range(i + 1, 8) if i // 2 != j // 2]   # pairs of a pixel
    for a, b in combos:
        rho = r(a, b)
        assert abs(rho.mean()) < 4 / np.sqrt((spp - 1) * n_pix)
        assert 0.7 / (spp - 1) < (rho ** 2).mean() < 2.0 / (spp - 1)


def test_every_number_is_uniform_over_pixels():
    """Over pixels, each sample index's pair is uniform on [0, 1)² (mean 1/2, second moment 1/3, x and y
    uncorrelated): the scrambles make every point uniform, so the estimator is unbiased."""
    n = 200_000
    for s in (0, 1, 6, 63):
        x, y = sobol_pairs(2, np.arange(n), np.full(n, s), [sobol_pair_index(1, 1)])
        for v in (x, y):
            assert abs(v.mean() - 0.5) < 0.004 and abs((v * v).mean() - 1 / 3) < 0.004
            counts = np.bincount(np.floor(v * 16).astype(int), minlength=16)
            assert counts.min() > n / 16 * 0.95 and counts.max() < n / 16 * 1.05
        assert abs(np.corrcoef(x, y)[0, 1]) < 0.01


@pytest.mark.parametrize("sobol_pairs", PAIRS_OF)
def test_even_and_odd_samples_are_independent_sequences(sobol_pairs):
    """Sample 2i and sample 2i + 1 of a pixel come from independently scrambled sequences: over pixels
    their numbers are uncorrelated, and within a pixel the odd half is not the even half's points again
    (each half alone is a net: test_each_pixels_first_samples_of_every_pair_are_nets)."""
    n = 200_000
    for i in (0, 3, 10):
        even = sobol_pairs(5, np.arange(n), np.full(n, 2 * i), [0, 7])
        odd = sobol_pairs(5, np.arange(n), np.full(n, 2 * i + 1), [0, 7])
        assert all(abs(np.corrcoef(a, b)[0, 1]) < 0.01 for a in even for b in odd)
    # within pixels: the even and odd halves' 16 points are different point sets, whose cells agree no
    # more often than independent nets' would (a net's cell of a point: 1/16 chance for an independent one)
    n_pix = 4000
    pixel = np.repeat(np.arange(n_pix), 16)
    half = np.tile(np.arange(16), n_pix)
    e = sobol_pairs(5, pixel, 2 * half, [3])
    o = sobol_pairs(5, pixel, 2 * half + 1, [3])
    same = net_cells(e[0], e[1], 4, 2) == net_cells(o[0], o[1], 4, 2)
    assert abs(same.mean() - 1 / 16) < 4 * np.sqrt(1 / 16 * 15 / 16 / same.size)


# --------------------------------------------------------------------------------- renders

def seed_images(scene, sampler, seeds, spp):
    renderer, out, se = Renderer(scene), [], []
    for seed in range(seeds):
        st = dataclasses.replace(scene.settings, seed=seed, sampler=sampler, spp=spp)
        r = renderer.render(st)
        out.append(r.stokes_luminance()[0])
        se.append(r.film.stderr_luminance()[0])
    return np.array(out), np.array(se)


def peer_scene(name, res):
    """The shared peer scene ``name`` at res × res."""
    from engine.scene.loader import load_scene
    from tests.conftest import shared_path
    scene = load_scene(shared_path("peers", "scenes", f"{name}.json"))
    scene.camera.width = scene.camera.height = res
    return scene


def unbiased_variances(scene, samplers, seeds, spp):
    """Per-pixel variances over ``seeds`` renders of each of ``samplers`` (the first one tested, "independent"
    among them), after asserting that the first one's image mean is the independent sampler's within 4σ."""
    images = {s: seed_images(scene, s, seeds, spp)[0] for s in samplers}
    v = {s: a.var(0, ddof=1) for s, a in images.items()}
    first = samplers[0]
    se = np.sqrt(((v[first] + v["independent"]) / seeds).sum()) / v[first].size
    assert abs(images[first].mean() - images["independent"].mean()) < 4 * se
    return v


@pytest.fixture(scope="module")
def cornell():
    from engine.scene.loader import load_scene
    from tests.conftest import shared_path
    scene = load_scene(shared_path("peers", "scenes", "cornell_lambert.json"))
    scene.camera.width = scene.camera.height = 16
    return scene


def test_the_camera_numbers_are_the_stratified_samplers_and_the_first_vertex_cycles(cornell):
    """Camera rays alone (max_depth 1) see exactly "stratified"'s numbers: the renders are equal bit for bit; the
    first vertex (max_depth 2) draws "cycles"' sets (sampler.vertex_pattern), no longer "stratified"'s Sobol'
    dimensions 3–8 (tests/render/test_first_vertex_pattern.py: why); the deeper vertices "sobol"'s own pairs."""
    def render(sampler, depth):
        st = dataclasses.replace(cornell.settings, sampler=sampler, spp=8, max_depth=depth, seed=3)
        return Renderer(cornell).render(st).stokes_luminance()[0]
    np.testing.assert_array_equal(render("sobol", 1), render("stratified", 1))
    assert not np.array_equal(render("sobol", 2), render("stratified", 2))
    assert [vertex_pattern("sobol", b) for b in range(3)] == ["cycles", "sobol", "sobol"]
    assert [vertex_pattern(s, 0) for s in ("padded", "cycles")] == ["padded", "cycles"]


def test_a_diffuse_scene_keeps_the_independent_mean_and_the_stratified_variance(cornell):
    """cornell_lambert (diffuse interreflections, the first vertex's direct light most of the noise),
    16², 16 spp, 8 seeds: the image mean of sobol renders = the independent sampler's within 4σ, per
    pixel within 4σ for ≥ 97 % of the pixels; the pixel variance is > 2.5× lower than independent's
    (measured 2.9×) and no more than stratified's + 12 % (measured stratified ÷ sobol 1.00; the deeper
    vertices' pairs gain little here, and the variance ratio's own spread at 8 seeds is ~5 %)."""
    seeds, spp = 8, 16
    sob, _ = seed_images(cornell, "sobol", seeds, spp)
    ind, _ = seed_images(cornell, "independent", seeds, spp)
    strat, _ = seed_images(cornell, "stratified", seeds, spp)
    v_sob, v_ind, v_strat = (a.var(0, ddof=1) for a in (sob, ind, strat))
    diff_se = np.sqrt((v_sob + v_ind) / seeds)
    assert abs(sob.mean() - ind.mean()) < 4 * np.sqrt((diff_se ** 2).sum()) / diff_se.size
    lit = diff_se > 0
    assert np.mean(np.abs(sob.mean(0) - ind.mean(0))[lit] < 4 * diff_se[lit]) >= 0.97
    print(f"variance independent ÷ sobol {v_ind.mean() / v_sob.mean():.2f}, "
          f"stratified ÷ sobol {v_strat.mean() / v_sob.mean():.2f}")
    assert v_ind.mean() > 2.5 * v_sob.mean()
    assert v_strat.mean() > v_sob.mean() / 1.12


def test_a_glass_sphere_keeps_the_mean_with_less_variance():
    """glass_sphere (delta-only paths through the sphere, several vertices deep: the second and later
    vertices' lobe choices, hashed by "stratified", are stratified pairs here), 24², 32 spp, 6 seeds: the
    mean = the independent sampler's within 4σ; the pixel variance > 1.3× lower than the stratified
    sampler's (measured 1.50×; independent ÷ sobol 2.6×; the race at 128² gives 1.8×)."""
    v = unbiased_variances(peer_scene("glass_sphere", 24), ["sobol", "independent", "stratified"], 6, 32)
    v_sob, v_ind, v_strat = v["sobol"], v["independent"], v["stratified"]
    print(f"variance independent ÷ sobol {v_ind.mean() / v_sob.mean():.2f}, "
          f"stratified ÷ sobol {v_strat.mean() / v_sob.mean():.2f}")
    assert v_ind.mean() > 2 * v_sob.mean()
    assert v_strat.mean() > 1.3 * v_sob.mean()


def test_a_resumed_adaptive_sobol_render_equals_the_uninterrupted_one(tmp_path):
    """Adaptive sampling with the sobol sampler, cancelled after a few units and resumed through the EXR
    state: the same counts, image and half-buffers as the uninterrupted adaptive render, bit for bit."""
    from engine.output.exr import read_stokes_exr, write_stokes_exr
    from engine.render.adaptive import AdaptiveSettings, state_channels, state_from_channels
    from engine.scene.loader import load_scene
    from tests.conftest import shared_path
    scene = load_scene(shared_path("peers", "scenes", "fresnel_sphere.json"))
    scene.camera.width = scene.camera.height = 24
    scene.settings = dataclasses.replace(scene.settings, spp=48, sampler="sobol")
    ad = AdaptiveSettings(threshold=0.02, quantity="s0", min_spp=8)
    renderer = Renderer(scene)
    reference = renderer.render(RenderRequest(adaptive=ad))
    assert len(np.unique(reference.film.count)) > 1
    st = dataclasses.replace(scene.settings, batch_rays=200)
    calls = {"n": 0}
    partial = renderer.render(RenderRequest(st, adaptive=ad, should_stop=lambda: calls.__setitem__("n", calls["n"] + 1)
                                            or calls["n"] > 12))
    assert partial.cancelled and partial.film.count.sum() < reference.film.count.sum()
    path = str(tmp_path / "part.exr")
    write_stokes_exr(path, partial.stokes(), extra={"spp": partial.film.spp_image().astype("uint32"),
                                                     **state_channels(partial.film, partial.halves)})
    _, channels, _ = read_stokes_exr(path)
    film, halves = state_from_channels(channels, channels["spp"], halves=partial.settings.halves)
    assert halves.halves == partial.halves.halves == "one_sequence"
    resumed = renderer.render(RenderRequest(adaptive=ad, resume=film, resume_halves=halves))
    np.testing.assert_array_equal(resumed.film.count, reference.film.count)
    np.testing.assert_array_equal(resumed.film.sums, reference.film.sums)
    np.testing.assert_array_equal(resumed.halves.sums, reference.halves.sums)
