"""ShadingPoint.memo across take: per-point values (PER_POINT_MEMOS) are read from the batch a subset was taken from."""

import numpy as np

from engine.materials.base import PER_POINT_MEMOS, ShadingPoint
from engine.materials.torrance_sparrow import TorranceSparrow
from engine.spectral import ConstantSpectrum


def points(n=12, seed=0):
    rng = np.random.default_rng(seed)
    n_s = np.tile([[0.0], [0.0], [1.0]], n)
    wo = rng.normal(size=(3, n))
    wo[2] = np.abs(wo[2]) + 0.1
    wo /= np.linalg.norm(wo, axis=0)
    return ShadingPoint(np.zeros((3, n)), n_s, n_s.copy(), wo, np.full((4, n), 550.0))


def test_a_subset_reads_the_per_point_memo_of_its_parent_batch():
    sp, owner, calls = points(), object(), []
    key = next(iter(PER_POINT_MEMOS))
    value = np.arange(24.0).reshape(2, 12)
    sp.memo(owner, key, lambda: calls.append(1) or value)
    sel = np.array([1, 5, 6, 11])
    sub = sp.take(sel).take(np.array([0, 2]))                    # a subset of a subset
    got = sub.memo(owner, key, lambda: calls.append(2) or None)
    assert calls == [1] and np.array_equal(got, value[:, [1, 6]])
    masked = sp.take(np.arange(12) % 3 == 0)
    assert np.array_equal(masked.memo(owner, key, lambda: None), value[:, ::3])
    # other keys, other owners and flipped batches compute their own
    assert sub.memo(owner, "other", lambda: "own") == "own"
    assert sub.memo(object(), key, lambda: "own") == "own"
    assert sp.take(sel).flipped(np.ones(4, bool)).memo(owner, key, lambda: "own") == "own"


def test_torrance_sparrow_values_at_a_subset_are_the_parents_bit_for_bit():
    """The multiscatter term and complex index of a subset (its parent's, gathered) equal those computed there, and
    through a mix's and a material set's points too."""
    def ts(m):
        return TorranceSparrow(ConstantSpectrum(0.4), ConstantSpectrum(2.5), m, distribution="ggx",
                               multiscatter=True)
    a, b = ts(0.4), ts(0.7)
    sp = points(40, seed=3)
    sel = np.array([0, 3, 4, 17, 39])
    for m in (a, b):
        full = (m.relative_eta(sp), m.multiscatter_extra(sp))
        fresh = points(40, seed=3).take(sel)
        want = (m.relative_eta(fresh), m.multiscatter_extra(fresh))
        sub = sp.take(sel)
        assert "_memo" not in sub.__dict__
        for f, w, g in zip(full, want, (m.relative_eta(sub), m.multiscatter_extra(sub))):
            assert np.array_equal(g, w) and np.array_equal(g, np.take(f, sel, axis=-1))


def test_the_shading_points_of_mixes_sets_and_normal_maps_read_their_parents_memo():
    from engine.materials.material_set import SetShadingPoint
    from engine.materials.mix import MixShadingPoint
    from engine.materials.normal_map import MappedShadingPoint
    sp, owner, key = points(), object(), next(iter(PER_POINT_MEMOS))
    base = (sp.p, sp.n_s, sp.n_g, sp.wo, sp.lam)
    value = np.arange(12.0)[None, :]
    sel = np.array([2, 3, 9])
    for q in (MixShadingPoint(*base, owner=None, parts=(None, None)),
              SetShadingPoint(*base, material=np.zeros(12, np.int64), owner=None, parts=(None,), pos=np.arange(12)),
              MappedShadingPoint(*base, n_smooth=sp.n_s)):
        q.memo(owner, key, lambda: value)
        sub = q.take(sel)
        assert type(sub) is type(q) and np.array_equal(sub.memo(owner, key, lambda: None), value[:, sel])
