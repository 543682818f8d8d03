"""Memoised texture values shared by subsets of a batch of surface points (SurfacePoints.take), and a
textured metal's (n, κ) computed once per batch (TexturedGulbrandsenIndex)."""

import numpy as np
import pytest

from engine.spectral import ConstantSpectrum
from engine.textures import ImageTexture, SurfacePoints, TexturedNumber, TexturedSpectrum, TextureInput, \
    VertexAttributes
from engine.textures import conductor_index
from engine.textures.conductor_index import TexturedGulbrandsenIndex

N = 40


def _batch(seed=0) -> SurfacePoints:
    """N hits on random triangles of a random mesh with UVs, vertex positions and a colour layer."""
    rng = np.random.default_rng(seed)
    nv = 30
    faces = rng.integers(0, nv, size=(20, 3))
    attrs = VertexAttributes(faces, rng.uniform(-1, 2, (nv, 2)), {"Col": rng.uniform(0, 1, (nv, 3))},
                             rng.normal(size=(nv, 3)))
    b1 = rng.uniform(0, 0.5, N)
    return SurfacePoints(attrs, rng.integers(0, 20, N), b1, rng.uniform(0, 0.5, N))


class CountingTexture(ImageTexture):
    calls = 0

    def eval(self, points):
        CountingTexture.calls += 1
        return super().eval(points)


def _texture(seed=1):
    rng = np.random.default_rng(seed)
    return CountingTexture(rng.uniform(0, 1, (5, 7, 3)).astype(np.float32), "Cubic")


def _lam(n, seed=2):
    return np.random.default_rng(seed).uniform(380, 780, (4, n))


def _values(points, colour, number, lam):
    """Every kind of memoised value at ``points``: (L, N), (3, N), (N,), (2, N), a tuple, a layer."""
    return [colour.at(points, lam, False), colour.at(points, lam[:1], True), colour.rgb_at(points),
            colour.linear_srgb_at(points), number.at(points), points.uv(), *points.position_derivatives(),
            points.attribute("Col", 3)]


@pytest.mark.parametrize("sel", [np.array([0, 3, 4, 17, 39]), np.arange(N) % 3 == 1, slice(5, 30, 2)],
                         ids=["indices", "mask", "slice"])
def test_a_subset_reuses_its_parents_values_bit_for_bit_without_a_lookup(sel):
    tex = _texture()
    colour = TexturedSpectrum(TextureInput(tex), "illuminant")
    number = TexturedNumber(TextureInput(tex, "G", 2.0, 0.5))
    lam = _lam(N)
    parent = _batch()
    whole = _values(parent, colour, number, lam)
    CountingTexture.calls = 0
    child = parent.take(sel)
    grandchild = child.take(np.array([0, 2]))
    got = _values(child, colour, number, lam[:, sel])
    got2 = _values(grandchild, colour, number, lam[:, sel][:, [0, 2]])
    assert CountingTexture.calls == 0                       # every value came from the parent
    # exactly the parent's values at those points, and exactly what a fresh lookup there gives
    fresh = _values(SurfacePoints(parent.attributes, parent.prim[sel], parent.b1[sel], parent.b2[sel]), colour,
                    number, lam[:, sel])
    assert CountingTexture.calls > 0
    for w, g, f, g2 in zip(whole, got, fresh, got2):
        assert g.dtype == f.dtype and np.array_equal(g, w[..., sel]) and np.array_equal(g, f)
        assert np.array_equal(g2, g[..., [0, 2]])
    # a value taken from the parent is the child's own (a copy: writing to it leaves the parent's alone)
    assert not np.shares_memory(got[0], whole[0])


def test_a_subset_looks_up_what_its_parent_has_not_and_keeps_it():
    tex = _texture()
    colour = TexturedSpectrum(TextureInput(tex))
    parent = _batch()
    sel = np.array([1, 2, 5])
    child = parent.take(sel)
    CountingTexture.calls = 0
    a = colour.rgb_at(child)
    b = colour.rgb_at(child)
    assert CountingTexture.calls == 1 and a is b
    assert not parent._memo                                 # nothing is written to the parent


def test_repeated_or_reordered_points_start_with_an_empty_memo():
    # e.g. Weidlich-Wilkie's wavelength lanes: point j once per wavelength, whose lookups see
    # another wavelength array (L·N lanes of one wavelength each) under the same memo key
    tex = _texture()
    colour = TexturedSpectrum(TextureInput(tex))
    parent = _batch()
    lam = _lam(N)
    colour.at(parent, lam[:1], False)
    lanes = np.tile(np.arange(N), 4)
    lam_lanes = lam.reshape(1, 4 * N)
    CountingTexture.calls = 0
    lane_values = colour.at(parent.take(lanes), lam_lanes, False)
    assert CountingTexture.calls == 1
    fresh = colour.at(SurfacePoints(parent.attributes, parent.prim[lanes], parent.b1[lanes], parent.b2[lanes]),
                      lam_lanes, False)
    assert np.array_equal(lane_values, fresh)
    colour.rgb_at(parent.take(np.array([3, 1])))            # reordered: looked up again
    assert CountingTexture.calls == 3


def test_a_value_that_is_not_per_point_is_looked_up_again():
    parent = _batch()
    parent.memo("scalar", lambda: np.float64(3.0))
    parent.memo("pair", lambda: (np.zeros((2, N)), np.zeros(7)))
    child = parent.take(np.array([0, 1]))
    assert child.memo("scalar", lambda: np.float64(4.0)) == 4.0
    assert child.memo("pair", lambda: "computed") == "computed"


@pytest.mark.parametrize("mono", [False, True])
def test_a_textured_metals_n_and_kappa_share_one_gulbrandsen_map(monkeypatch, mono):
    calls = []
    real = conductor_index.metal_index

    def counting(r, g, mode):
        calls.append(mode)
        return real(r, g, mode)

    monkeypatch.setattr(conductor_index, "metal_index", counting)
    base = TexturedSpectrum(TextureInput(_texture()))
    tint = ConstantSpectrum(0.7)
    n_part, k_part = (TexturedGulbrandsenIndex(base, tint, part, "schlick_tint") for part in ("n", "k"))
    points = _batch()
    lam = _lam(N)[:1] if mono else _lam(N)
    n = n_part.at(points, lam, mono)
    k = k_part.at(points, lam, mono)
    assert calls == ["schlick_tint"]
    r = base.at(points, lam, mono)
    n_ref, k_ref = conductor_index.index_of(r, tint.eval(lam, mono=mono), "schlick_tint")   # (the NumPy map)
    assert np.array_equal(n, n_ref) and np.array_equal(k, k_ref) and n.shape == lam.shape
    # another mode or edge tint is another map
    TexturedGulbrandsenIndex(base, tint, "k", "tint").at(points, lam, mono)
    TexturedGulbrandsenIndex(base, ConstantSpectrum(0.7), "n", "schlick_tint").at(points, lam, mono)
    assert len(calls) == 3
    # a subset of the points takes its (n, κ) from the batch's
    sel = np.array([2, 3, 11])
    assert np.array_equal(k_part.at(points.take(sel), lam[:, sel], mono), k[:, sel]) and len(calls) == 3


def test_rgb_channel_subsets_share_the_tables_without_a_gather():
    """A channels lookup's subsets read the root's identity basis and white D65 as stride-0 views: the values
    np.take would gather (every column is the same), for subsets of subsets too."""
    from engine.spectral import RGB_WAVELENGTHS_NM, WavelengthLookup, rgb_channel_tables
    n = 50
    lam = np.repeat(np.array(RGB_WAVELENGTHS_NM)[:, None], n, axis=1)
    root = WavelengthLookup(lam, *rgb_channel_tables(n), channels=True)
    idx = np.array([1, 4, 4, 49])
    for sub, rows in ((root.take(idx), idx), (root.take(idx).compress(np.array([True, False, True, True])),
                                             idx[[0, 2, 3]])):
        assert sub.basis.shape == (3, 3, rows.size) and sub.basis.strides[-1] == 0
        assert np.array_equal(sub.basis, np.take(root.basis, rows, axis=-1))
        assert np.array_equal(sub.d65, np.take(root.d65, rows, axis=-1)) and sub.d65.strides[-1] == 0
        assert np.array_equal(sub.lam, np.take(lam, rows, axis=-1))
    plain = WavelengthLookup(np.full((4, n), 550.0))
    assert plain.take(idx).basis.strides[-1] != 0       # spectral lookups still gather their own tables
