"""Throughputs read through a column map.

The path tracer does not copy the throughput T when it drops finished paths: PathState keeps T in
``T_store`` and the column ``T_col`` of each live path, and every kernel that reads T takes the
columns (``T_cols``) apart from the paths it writes (``rows``).  Reading through the map must give
exactly what reading a gathered copy gives, on both backends.
"""

import dataclasses
import numpy as np
import pytest

from engine import kernels
from engine.kernels import transport
from engine.render.path_state import ARRAY_FIELDS, PathState
from engine.render.sampler import PathSampler
from engine.spectral import WavelengthLookup
from tests.conftest import shared_path

needs_numba = pytest.mark.skipif(kernels._numba is None, reason="numba is not installed (NumPy kernels only)")


def unit(rng, n):
    v = rng.normal(size=(3, n))
    return v / np.linalg.norm(v, axis=0)


def perpendicular(rng, wo):
    x = unit(rng, wo.shape[1])
    x -= wo * (x * wo).sum(0)
    return x / np.linalg.norm(x, axis=0)


# ----------------------------------------------------------------------------- kernels: T_cols

def frames(rng, n):
    wo = unit(rng, n)
    return wo, perpendicular(rng, wo), perpendicular(rng, wo)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("P,L", [(4, 4), (3, 1), (1, 4)])
def test_updates_through_columns_equal_updates_of_the_gathered_throughput(backend, P, L):
    """update_abcs / update_depolarising / update_general and add_light read T at ``T_cols`` (repeated
    columns too, as the camera paths' shared identity) exactly as at ``rows`` of a gathered copy."""
    if backend == "numba" and kernels._numba is None:
        pytest.skip("numba is not installed")
    suffix = "_" + backend
    rng = np.random.default_rng(31 + P + L)
    n, stored = 300, 500
    T_store = rng.normal(size=(P, P, L, stored))
    cols = np.sort(rng.integers(0, stored, n))               # increasing, with repeats
    cols[:40] = 7
    rows = np.sort(rng.permutation(n)[:200])
    T_dense = T_store[..., cols]                             # what a compress would have copied
    wo, x_T, x_out = frames(rng, rows.size)
    A, B, C, S, D = (rng.normal(size=(L, rows.size)) for _ in range(5))
    M = rng.normal(size=(4, 4, L, rows.size))
    cases = [("update_abcs", (x_out, x_T, wo, A, B, C, S, D)), ("update_depolarising", (A,)),
             ("update_general", (x_out, x_T, wo, M))]
    for name, args in cases:
        f = getattr(transport, name + suffix)
        want, got = np.full((P, P, L, n), 5.0), np.full((P, P, L, n), 5.0)
        f(want, T_dense, rows, *args)
        f(got, T_store, rows, *args, T_cols=cols[rows])
        assert got.tobytes() == want.tobytes(), name
    path = rng.permutation(2 * n)[:n]
    Le, w = rng.random((L, rows.size)), rng.random(rows.size)
    want, got = rng.normal(size=(P, L, 2 * n)), None
    got = want.copy()
    getattr(transport, "add_light" + suffix)(want, path, T_dense, rows, Le, w)
    getattr(transport, "add_light" + suffix)(got, path, T_store, rows, Le, w, T_cols=cols[rows])
    assert got.tobytes() == want.tobytes()


@pytest.mark.parametrize("compact", [True, False])
def test_next_segments_can_leave_the_throughput_in_place(compact):
    """With compact_T False the survivors' throughputs are T's columns idx (divided by the roulette
    in place); every other output is the same as with compact_T True, on both backends."""
    rng = np.random.default_rng(41)
    n, P, L = 400, 4, 4
    T0 = rng.random((P, P, L, n))
    args = lambda: (T0.copy(), rng_args[0], rng_args[1], rng_args[2], rng_args[3].copy(), True, *rng_args[4:])  # noqa
    rng_args = (rng.random(n) + 0.5, np.ones(n), rng.random(n), rng.random(n) < 0.8, unit(rng, n), unit(rng, n),
                np.arange(n), rng.integers(0, 2**63, n).astype(np.uint64), rng.random(n) < 0.5, rng.random(n),
                rng.normal(size=(3, n)), unit(rng, n), 1e-4)
    impls = [transport.next_segments_numpy] + ([transport.next_segments_numba] if kernels.COMPILED else [])
    for f in impls:
        ref = f(*args())
        out = f(*args(), compact_T=compact)
        idx = out[0]
        assert 0 < idx.size < n
        for i, (a, b) in enumerate(zip(ref, out)):
            if i == 2 and not compact:
                assert b.shape[-1] == n and b[..., idx].tobytes() == a.tobytes()
            elif isinstance(a, np.ndarray):
                assert a.tobytes() == b.tobytes(), i
            else:
                assert a == b


# ----------------------------------------------------------------------------- PathState's column map

def state(rng, n):
    lk = WavelengthLookup(rng.uniform(380, 780, (4, n)))
    return PathState(path=np.arange(n), T=rng.normal(size=(4, 4, 4, n)), x_T=unit(rng, n), o=None, d=unit(rng, n),
                     t_max=None, eta_sq=rng.random(n), prev_delta=rng.random(n) < 0.5, prev_pdf=rng.random(n),
                     p_prev=None, n_prev=None, sampler=PathSampler(rng.integers(0, 2**63, n).astype(np.uint64)),
                     lk=lk, lk_m=lk)


def test_path_state_drops_paths_without_copying_the_throughput():
    rng = np.random.default_rng(43)
    s = state(rng, 300)
    store = s.T_store
    dense = store.copy()
    m1 = rng.random(300) < 0.7
    s.compress(m1)
    assert s.T_store is store and np.array_equal(s.T_col, np.flatnonzero(m1))
    idx = np.flatnonzero(rng.random(s.n) < 0.5)
    s.keep(idx, s.sampler.keys[idx])
    want = dense[..., np.flatnonzero(m1)][..., idx]
    assert s.T_store is store
    rows = np.array([0, 3, 5])
    assert np.array_equal(s.T_store[..., s.T_columns(rows)], want[..., rows])
    assert np.array_equal(s.T_store[..., s.T_columns()], want)
    assert np.array_equal(s.T, want) and s.T_col is None and s.T_columns(rows) is None    # gathered once
    # a step that gives T itself, with or without a column map
    new = rng.normal(size=(4, 4, 4, s.n + 5))
    keep_all = np.arange(s.n)
    s.keep(keep_all, s.sampler.keys, T=new, T_col=keep_all + 5)
    assert s.T_store is new and np.array_equal(s.T, new[..., 5:])
    for name in ARRAY_FIELDS:
        assert getattr(s, name) is None or getattr(s, name).shape[-1] == s.n


def test_camera_paths_share_one_identity_column():
    """The camera paths' T is one identity column that every path reads (no (P, P, L, n) identity)."""
    from engine.render.integrator import PathTracer
    from engine.render.renderer import Renderer
    from engine.scene.loader import load_scene
    scene = load_scene(shared_path("peers", "scenes", "fresnel_sphere_au.json"))
    scene.camera.width = scene.camera.height = 8
    r = Renderer(scene)
    st = dataclasses.replace(scene.settings, polarisation="full")
    tracer = PathTracer(r.compiled, r.lights, r.camera, st)
    st, _ = tracer._camera_paths(np.arange(64, dtype=np.int64), np.zeros(64, np.int64))
    L = st.T_store.shape[2]
    assert L == 4 and st.T_store.shape[-1] == 1 and np.array_equal(st.T_col, np.zeros(64))
    assert np.array_equal(st.T[..., 17], np.eye(4)[:, :, None].repeat(L, 2))


@pytest.mark.parametrize("backend", ["reference", "compiled"])
def test_delta_steps_through_columns_equal_steps_on_the_gathered_throughput(backend):
    """The four delta-material steps (both twins) read T at ``T_cols`` exactly as at ``rows`` of a
    gathered copy, and write only the rows."""
    from engine.kernels import TWINS
    from engine.spectral.ior import named_ior
    if backend == "compiled" and not kernels.COMPILED:
        pytest.skip("numba is not installed")
    rng = np.random.default_rng(53)
    n, stored, P, L = 600, 900, 4, 4
    n_s, wo = unit(rng, n), unit(rng, n)
    x_T = perpendicular(rng, wo)
    lam = rng.uniform(380.0, 780.0, (L, n))
    u = rng.random(n)
    T_store = rng.normal(size=(P, P, L, stored))
    cols = np.sort(rng.integers(0, stored, n))
    cols[:50] = 3                                            # shared columns, as the camera's identity
    rows = np.sort(rng.permutation(n)[:400])
    T_dense = T_store[..., cols]
    n_au, k_au = named_ior("Au")
    steps = {
        "materials.conductor.constant_mirror_scatter": lambda T: (rows, n_s, wo, x_T, T, 0.3 + 2.9j),
        "materials.conductor.tabulated_mirror_scatter": lambda T: (rows, n_s, wo, x_T, T, lam, n_au.wavelengths,
                                                                   n_au.values, k_au.wavelengths, k_au.values, 1.0),
        "materials.dielectric.dielectric_scatter": lambda T: (rows, n_s, wo, x_T, T, u, 1.5, 1 / 1.5),
        "materials.filter_sheet.filter_sheet_scatter": lambda T: (rows, wo, x_T, T, np.array([0.6, 0.0, 0.8]),
                                                                  0.45, 0.44, 0.1, 0.0),
    }
    for key, args in steps.items():
        f = getattr(TWINS[key], backend)
        outs = []
        for T, extra in ((T_dense, {}), (T_store, {"T_cols": cols[rows]})):
            out = [np.full((P, P, L, n), np.nan), np.full((3, n), np.nan), np.full((3, n), np.nan),
                   np.zeros(n, bool), np.full(n, np.nan)]
            f(*args(T), *out, **extra)
            outs.append(out)
        for a, b in zip(*outs):
            assert a.tobytes() == b.tobytes(), key
        assert np.isnan(outs[1][0][..., np.setdiff1d(np.arange(n), rows)]).all()
