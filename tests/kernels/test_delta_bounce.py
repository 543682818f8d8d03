"""One-step scatter of the delta-only materials (BSDF.scatter_delta, engine.kernels.delta_bounce).

Each family's step must give exactly what the path tracer's generic chain gives — ``sample`` then
the throughput update T·R(x_out → x_T)·M — on the same backend (bit for bit: the images must not
change), and the compiled loop must agree with its NumPy twin (bit for bit where no complex Fresnel
arithmetic is involved, else to rounding).  Inputs include the edges the renderer meets: directions
behind the shading normal, normal incidence (degenerate plane of incidence), total internal
reflection, a filter axis along the beam, one wavelength row broadcast or four.
"""

import numpy as np
import pytest

from engine import kernels
from engine.materials.base import DeltaVertices, ShadingPoint
from engine.materials.black_glass import BlackGlass
from engine.materials.conductor import SmoothConductor, constant_mirror_scatter_numpy, tabulated_mirror_scatter_numpy
from engine.materials.dielectric import SmoothDielectric, dielectric_scatter_numpy
from engine.materials.filter_sheet import FilterSheet, filter_sheet_scatter_numpy
from engine.render.integrator import scatter_throughput
from engine.spectral import ConstantSpectrum, TabulatedSpectrum
from engine.spectral.ior import named_ior

needs_numba = pytest.mark.skipif(kernels._numba is None, reason="numba is not installed (NumPy kernels only)")


def unit(rng, n):
    v = rng.normal(size=(3, n))
    return v / np.linalg.norm(v, axis=0)


def batch(rng, n, P, L):
    """Shading normals, directions (some at normal incidence, some behind), frames ⟂ wo, T, λ, u."""
    n_s, wo = unit(rng, n), unit(rng, n)
    wo[:, :6] = n_s[:, :6]                                   # normal incidence: s from any_perpendicular
    wo[:, 6:9] = -n_s[:, 6:9]
    n_s[:, 9:12] = [[0.0], [0.0], [-1.0]]                     # the fallback's own branch cut
    wo[:, 9:12] = [[0.0], [0.0], [-1.0]]
    wo[:, 12] = [1.0, 0.0, 0.0]                               # filter axis along the beam
    x_T = np.cross(wo.T, unit(rng, n).T).T
    x_T /= np.linalg.norm(x_T, axis=0)
    T = rng.normal(size=(P, P, L, n))
    lam = rng.uniform(380.0, 780.0, (L, n))
    lam[0, 20:40] = np.repeat([380.0, 500.0, 501.0, 640.0, 780.0], 4)   # on knots of the tables
    gold_knots = named_ior("Au")[0].wavelengths
    lam[-1, 40:60] = gold_knots[(gold_knots >= 380.0) & (gold_knots <= 780.0)][:20]
    u = rng.random(n)
    u[:20] = [0.0, 1.0 - 1e-16] * 10
    return n_s, wo, x_T, T, lam, u


def fresh_outputs(T):
    """Output arrays filled with NaN: columns a step does not own must stay untouched."""
    n = T.shape[-1]
    return [np.full_like(T, np.nan), np.full((3, n), np.nan), np.full((3, n), np.nan), np.zeros(n, bool),
            np.full(n, np.nan)]


def generic(bsdf, rows, n_s, wo, x_T, T, lam, u):
    """The path tracer's generic chain at the paths ``rows``: sample, then scatter_throughput."""
    sp = ShadingPoint(np.zeros((3, rows.size)), n_s[:, rows], n_s[:, rows], wo[:, rows], lam[:, rows])
    bs = bsdf.sample(sp, u[rows], None)
    T_out, d, x_out, valid, eta_sq = fresh_outputs(T)
    scatter_throughput(T_out, T, rows, bs.weight, x_T[:, rows], wo[:, rows])
    d[:, rows], x_out[:, rows], valid[rows] = bs.wi, bs.weight.x_in, bs.valid
    eta_sq[rows] = bs.eta_sq
    return T_out, d, x_out, valid, eta_sq


MATERIALS = {
    "conductor": lambda: SmoothConductor(ConstantSpectrum(0.47), ConstantSpectrum(2.4)),
    "conductor_in_water": lambda: SmoothConductor(ConstantSpectrum(0.2), ConstantSpectrum(3.5), 1.33),
    "black_glass": lambda: BlackGlass(ConstantSpectrum(1.5)),
    "black_glass_tir": lambda: BlackGlass(ConstantSpectrum(1.2), 1.5),
    "gold": lambda: SmoothConductor(*named_ior("Au")),
    "gold_in_oil": lambda: SmoothConductor(*named_ior("Au"), 1.5),
    "metal_on_two_grids": lambda: SmoothConductor(      # n and κ tabulated at different wavelengths, knots hit
        TabulatedSpectrum([350.0, 380.0, 500.0, 501.0, 640.0, 800.0], [0.2, 0.3, 1.1, 1.1, 0.9, 0.4]),
        TabulatedSpectrum(np.linspace(300.0, 850.0, 12), np.linspace(1.0, 6.0, 12) ** 1.5)),
    "glass": lambda: SmoothDielectric(1.5),
    "glass_in_water": lambda: SmoothDielectric(1.2, 1.33),
    "polariser": lambda: FilterSheet([0.3, -0.2, 1.0], "polariser", extinction=0.01, transmittance=0.9),
    "retarder": lambda: FilterSheet([1.0, 0.0, 0.0], "retarder", retardance_deg=37.0),
}


@pytest.mark.parametrize("name", sorted(MATERIALS))
@pytest.mark.parametrize("P,L", [(4, 1), (4, 4), (3, 4), (1, 1)])
def test_one_step_equals_sample_then_update(name, P, L):
    """scatter_delta writes exactly the generic chain's T, direction, frame, validity and η² at its
    rows (same backend, bit for bit) and leaves every other column alone."""
    rng = np.random.default_rng(11)
    n = 3000
    n_s, wo, x_T, T, lam, u = batch(rng, n, P, L)
    bsdf = MATERIALS[name]()
    for rows in (np.arange(n), np.sort(rng.permutation(n)[:1700])):
        outs = fresh_outputs(T)
        v = DeltaVertices(rows, n_s, wo, lam, False, u, T, x_T, *outs)
        assert bsdf.scatter_delta(v)
        want = generic(bsdf, rows, n_s, wo, x_T, T, lam, u)
        for got, ref in zip(outs, want):
            assert np.array_equal(got, ref, equal_nan=True)
        assert outs[3][rows].any() and np.all(np.isfinite(outs[0][..., rows]))
    if name.startswith("glass"):
        assert (outs[4][rows] == 1).any() and (outs[4][rows] != 1).any()      # both lobes sampled


def test_measured_metal_outside_its_tables_and_in_mono_falls_back():
    rng = np.random.default_rng(12)
    n_s, wo, x_T, T, lam, u = batch(rng, 200, 4, 4)
    gold = SmoothConductor(*named_ior("Au"))
    lam[2, 150] = 2000.0                                   # beyond the measured range
    outs = fresh_outputs(T)
    rows = np.arange(100, 200)
    assert not gold.scatter_delta(DeltaVertices(rows, n_s, wo, lam, False, u, T, x_T, *outs))
    assert np.all(np.isnan(outs[0])) and np.all(np.isnan(outs[1]))        # nothing written
    assert gold.scatter_delta(DeltaVertices(np.arange(100), n_s, wo, lam, False, u, T, x_T, *outs))
    assert not gold.scatter_delta(DeltaVertices(rows, n_s, wo, lam[:1], True, u, T[:, :, :1], x_T, *outs))


@needs_numba
@pytest.mark.parametrize("P,L", [(4, 4), (3, 1), (1, 4)])
def test_compiled_steps_match_their_numpy_twins(P, L):
    """The loops of engine.kernels.delta_bounce against the NumPy references: the filter sheet bit
    for bit, the Fresnel families to rounding (complex square root and division differ)."""
    from engine.kernels import TWINS
    rng = np.random.default_rng(13)
    n = 3000
    n_s, wo, x_T, T, lam, u = batch(rng, n, P, L)
    rows = np.sort(rng.permutation(n)[:2000])
    n_au, k_au = named_ior("Au")
    tables = (n_au.wavelengths, n_au.values, k_au.wavelengths, k_au.values, 1.33)
    cases = {
        "materials.conductor.constant_mirror_scatter": (constant_mirror_scatter_numpy,
                                                        (rows, n_s, wo, x_T, T, 0.3 + 2.9j)),
        "materials.conductor.tabulated_mirror_scatter": (tabulated_mirror_scatter_numpy,
                                                         (rows, n_s, wo, x_T, T, lam, *tables)),
        "materials.dielectric.dielectric_scatter": (dielectric_scatter_numpy,
                                                    (rows, n_s, wo, x_T, T, u, 1.5, 1 / 1.5)),
        "materials.filter_sheet.filter_sheet_scatter": (filter_sheet_scatter_numpy,
                                                        (rows, wo, x_T, T, np.array([0.6, 0.0, 0.8]),
                                                         0.45, 0.44, 0.1, 0.0)),
    }
    for key, (reference, args) in cases.items():
        assert TWINS[key].reference is reference
        got, want = fresh_outputs(T), fresh_outputs(T)
        r1 = TWINS[key].compiled(*args, *got)
        r2 = reference(*args, *want)
        assert r1 in (None, True) and r2 in (None, True)
        for g, w in zip(got, want):
            if key.endswith("filter_sheet_scatter") or g.dtype == bool:
                assert np.array_equal(g, w, equal_nan=True), key
            else:
                np.testing.assert_allclose(g, w, rtol=1e-12, atol=1e-13, err_msg=key)
        # the geometry (directions, frames) involves no complex arithmetic
        assert np.array_equal(got[2], want[2], equal_nan=True), key


# ----------------------------------------------------------------------------- dropping finished paths

@needs_numba
def test_keep_columns_bitwise_for_every_field_shape_and_dtype():
    """The compiled gather of PathState.compress copies exactly np.compress's values (NaN payloads,
    signed zeros, bools, 64-bit keys) for (n,), (3, n) and (P, P, L, n) fields, also a non-contiguous
    one, keeping none, some or all paths."""
    from engine.kernels import transport
    rng = np.random.default_rng(14)
    n = 1000
    fields = [rng.normal(size=(4, 4, 4, n)), rng.normal(size=(3, n)), rng.normal(size=n),
              rng.integers(0, 2**63, n, dtype=np.int64), rng.integers(0, 2**64 - 1, n, dtype=np.uint64),
              rng.random(n) < 0.5, rng.normal(size=(n, 3)).T, np.array([np.nan, -0.0, np.inf] * (n // 3) + [1.0])]
    for mask in (np.zeros(n, bool), rng.random(n) < 0.7, np.ones(n, bool)):
        idx = np.flatnonzero(mask)
        for a in fields:
            got = transport.keep_columns_numba(a, idx)
            want = np.compress(mask, a, axis=-1)
            assert got.dtype == want.dtype and got.shape == want.shape and got.tobytes() == want.tobytes()
            assert transport.keep_columns_numpy(a, idx).tobytes() == want.tobytes()


@needs_numba
def test_put_columns_bitwise_for_every_field_shape_and_dtype():
    """The compiled scatter of a material group's sample into the bounce's columns writes exactly NumPy's
    out[..., idx] = a (NaN payloads, signed zeros, bools; a broadcast or non-contiguous source; no, some or every
    column, in any order) and leaves the other columns alone."""
    from engine.kernels import transport
    rng = np.random.default_rng(16)
    n = 1000
    outs = [rng.normal(size=(3, n)), rng.normal(size=n), rng.random(n) < 0.5, rng.normal(size=(2, 4, n))]
    for idx in (np.empty(0, np.int64), rng.permutation(n)[:600], np.arange(n)):
        m = idx.shape[0]
        for out in outs:
            sources = [rng.normal(size=out.shape[:-1] + (m,)), np.array([np.nan, -0.0, np.inf] * m)[:m],
                       rng.random(m) < 0.5, np.asfortranarray(rng.normal(size=out.shape[:-1] + (m,)))]
            for a in sources + [np.float64(2.5)]:
                if np.ndim(a) == 1 and out.ndim > 1:
                    a = np.broadcast_to(a, out.shape[:-1] + (m,))
                want, got = out.copy(), out.copy()
                want[..., idx] = a
                transport.put_columns_numba(got, idx, a)
                assert got.dtype == want.dtype and got.tobytes() == want.tobytes()
                numpy_twin = out.copy()
                transport.put_columns_numpy(numpy_twin, idx, a)
                assert numpy_twin.tobytes() == want.tobytes()
    # a non-contiguous destination (a view): written in place, not into a reshaped copy
    base = rng.normal(size=(4, 2, n))
    view, want = base.transpose(1, 0, 2), base.copy().transpose(1, 0, 2)
    idx = rng.permutation(n)[:300]
    want[..., idx] = 16.0
    transport.put_columns_numba(view, idx, 16.0)
    assert np.array_equal(view, want)
    with pytest.raises(IndexError):     # an index out of range raises, as NumPy's assignment does
        transport.put_columns_numba(rng.normal(size=(3, n)), np.array([5, n], np.int64), 1.0)
    with pytest.raises(IndexError):
        transport.keep_columns(rng.normal(size=(3, n)), np.array([5, n + 3], np.int64))


def test_path_state_compress_keeps_the_masked_paths_in_every_field():
    from engine.render.path_state import ARRAY_FIELDS, PathState
    from engine.render.sampler import PathSampler
    from engine.spectral import WavelengthLookup
    rng = np.random.default_rng(15)
    n = 500
    lk = WavelengthLookup(rng.uniform(380, 780, (4, n)))
    state = PathState(path=np.arange(n), T=rng.normal(size=(4, 4, 4, n)), x_T=unit(rng, n), o=rng.normal(size=(3, n)),
                      d=unit(rng, n), t_max=None, eta_sq=rng.random(n), prev_delta=rng.random(n) < 0.5,
                      prev_pdf=rng.random(n), p_prev=None, n_prev=rng.normal(size=(3, n)),
                      sampler=PathSampler(rng.integers(0, 2**63, n).astype(np.uint64)), lk=lk, lk_m=lk)
    before = {name: getattr(state, name) for name in ARRAY_FIELDS}
    keys, lam = state.sampler.keys, lk.lam
    mask = rng.random(n) < 0.6
    extra = rng.normal(size=(3, n))
    kept, none = state.compress(mask, extra, None)
    for name, a in before.items():
        assert (a is None and getattr(state, name) is None) or np.array_equal(getattr(state, name), a[..., mask])
    assert np.array_equal(kept, extra[:, mask]) and none is None
    assert np.array_equal(state.sampler.keys, keys[mask]) and np.array_equal(state.lk.lam, lam[:, mask])
    assert state.lk_m is state.lk and state.n == mask.sum()
    assert state.compress(np.ones(state.n, bool), kept) == (kept,)       # a full mask copies nothing


def test_path_state_keep_gathers_only_the_fields_not_given():
    """PathState.keep: the fields a compiled step already restricted are set as given, the others
    (and the sampler keys, the wavelength lookups) are those of compress with the same paths."""
    from engine.render.path_state import ARRAY_FIELDS, PathState
    from engine.render.sampler import PathSampler
    from engine.spectral import WavelengthLookup
    rng = np.random.default_rng(16)
    n = 400

    def state():
        r = np.random.default_rng(17)
        lk = WavelengthLookup(r.uniform(380, 780, (4, n)))
        return PathState(path=np.arange(n), T=r.normal(size=(4, 4, 4, n)), x_T=r.normal(size=(3, n)),
                         o=None, d=r.normal(size=(3, n)), t_max=None, eta_sq=r.random(n), prev_delta=r.random(n) < 0.5,
                         prev_pdf=r.random(n), p_prev=None, n_prev=r.normal(size=(3, n)),
                         sampler=PathSampler(r.integers(0, 2**63, n).astype(np.uint64)), lk=lk, lk_m=lk)
    for mask in (rng.random(n) < 0.6, np.ones(n, bool)):
        a, b = state(), state()
        a.compress(mask)
        idx = np.flatnonzero(mask)
        given = {"T": b.T[..., idx] * 1.0, "d": b.d[:, idx] * 1.0, "o": np.full((3, idx.size), 7.0)}
        b.keep(idx, b.sampler.keys[idx], **given)
        for name in ARRAY_FIELDS:
            if name in given:
                assert getattr(b, name) is given[name]
            else:
                x, y = getattr(a, name), getattr(b, name)
                assert (x is None and y is None) or np.array_equal(x, y)
        assert np.array_equal(a.sampler.keys, b.sampler.keys) and np.array_equal(a.lk.lam, b.lk.lam)
        assert b.lk_m is b.lk and b.n == mask.sum()


@needs_numba
def test_scale_columns_bitwise_as_numpys_in_place_product():
    """The compiled in-place scale of a group's columns (a Blender glass's 1/η² taken back) is NumPy's
    out[..., idx] *= s bit for bit — float32 throughputs rounded from the float64 product as NumPy rounds them —
    and leaves the other columns alone; a non-contiguous destination is written in place."""
    from engine.kernels import transport
    rng = np.random.default_rng(23)
    n = 900
    s_all = np.concatenate((rng.uniform(0.3, 3.0, n - 3), [np.nan, np.inf, -0.0]))
    for shape, dtype in (((4, 4, 3, n), np.float64), ((3, 3, 1, n), np.float64), ((4, 4, 3, n), np.float32),
                         ((n,), np.float64)):
        out = rng.normal(size=shape).astype(dtype)
        for idx in (np.empty(0, np.int64), np.sort(rng.permutation(n)[:500]), rng.permutation(n)[:300],
                    np.arange(n)):
            s = s_all[idx]
            want, got, twin_out = out.copy(), out.copy(), out.copy()
            want[..., idx] *= s
            transport.scale_columns_numba(got, idx, s)
            transport.scale_columns_numpy(twin_out, idx, s)
            assert got.dtype == want.dtype and got.tobytes() == want.tobytes()
            assert twin_out.tobytes() == want.tobytes()
    base = rng.normal(size=(4, 2, n))
    view, want = base.transpose(1, 0, 2), base.copy().transpose(1, 0, 2)
    idx = rng.permutation(n)[:200]
    want[..., idx] *= s_all[idx]
    transport.scale_columns_numba(view, idx, s_all[idx])
    assert np.array_equal(view, want, equal_nan=True)
    with pytest.raises(IndexError):
        transport.scale_columns_numba(rng.normal(size=(3, n)), np.array([5, n], np.int64), np.ones(2))
