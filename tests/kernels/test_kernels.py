"""Compiled kernels (Numba) against their NumPy twins, and whole renders with either backend.

The NumPy version of every kernel is the reference; the compiled one must give the same numbers
(bit-for-bit where the arithmetic order is the same, else to 1e-12 relative), including at the
edges the renderer meets: degenerate normals, zero rotations, one-wavelength rows broadcast over
several, empty batches.  Skipped pieces say why when Numba is not installed.
"""

import dataclasses
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from engine import kernels
from engine.kernels import geometry, hashing, material_groups, shadow_rays, transport
from engine.render.renderer import Renderer
from engine.scene.loader import load_scene
from tests.conftest import REPO as _REPO, shared_path

needs_numba = pytest.mark.skipif(kernels._numba is None, reason="numba is not installed (NumPy kernels only)")
REPO = _REPO


def unit(rng, n):
    v = rng.normal(size=(3, n))
    return v / np.linalg.norm(v, axis=0)


@needs_numba
@pytest.mark.parametrize("n", [0, 1, 1000])
@pytest.mark.parametrize("with_normals", [False, True])
def test_surface_attributes_bitwise(n, with_normals):
    rng = np.random.default_rng(n)
    V = rng.normal(size=(50, 3)) * 10
    F = rng.integers(0, 50, size=(40, 3))
    N = rng.normal(size=(50, 3))
    N[:5] = 0.0                                   # zero vertex normals → fall back to n_g
    N[5:8] = [[1, 0, 0], [-1, 0, 0], [0, 0, 0]]   # cancelling normals
    has = rng.random(40) < 0.7
    tn = rng.normal(size=(40, 3))
    prim = rng.integers(0, 40, n)
    u = rng.random(n) * 0.5
    v = rng.random(n) * 0.5
    args = (F, V, N, has, tn, with_normals, prim, u, v)
    for a, b in zip(geometry.surface_attributes_numpy(*args), geometry.surface_attributes_numba(*args)):
        assert a.shape == b.shape
        np.testing.assert_array_equal(a, b)


@needs_numba
def test_offset_origin_bitwise():
    rng = np.random.default_rng(1)
    n = 2000
    p = rng.normal(size=(3, n)) * 10.0 ** rng.integers(-3, 6, n)
    n_g, w = unit(rng, n), unit(rng, n)
    w[:, :10] = np.cross(n_g[:, :10].T, rng.normal(size=(10, 3))).T   # grazing: n_g·w ≈ 0
    np.testing.assert_array_equal(geometry.offset_origin_numpy(p, n_g, w, 8.9e-5),
                                  geometry.offset_origin_numba(p, n_g, w, 8.9e-5))
    # an F-ordered input (a gather of a transposed array) gives a C-ordered result: the precompiled signature
    f = np.asfortranarray(p)
    out = geometry.offset_origin_numba(f, n_g, w, 8.9e-5)
    assert out.flags.c_contiguous and np.array_equal(out, geometry.offset_origin_numpy(p, n_g, w, 8.9e-5))


@needs_numba
def test_uniforms_bitwise_and_in_unit_interval():
    keys = np.random.default_rng(2).integers(0, 2**63, 5000, dtype=np.uint64) * np.uint64(2) + np.uint64(1)
    keys[:3] = [0, 2**64 - 1, 2**63]
    offsets = np.array([(d * 0x9E3779B97F4A7C15) & (2**64 - 1) for d in range(1, 8)], dtype=np.uint64)
    a, b = hashing.uniforms_numpy(keys, offsets), hashing.uniforms_numba(keys, offsets)
    np.testing.assert_array_equal(a, b)
    assert a.min() >= 0.0 and a.max() < 1.0


@needs_numba
@pytest.mark.parametrize("n,k", [(0, 3), (1, 0), (3000, 2), (3000, 5)])
def test_path_keys_and_uniforms_bitwise_and_as_keys_then_uniforms(n, k):
    rng = np.random.default_rng(n + k)
    pixel = rng.integers(0, 4096 * 4096, n)
    sample = rng.integers(0, 1 << 20, n)
    seed_key = hashing.mix64(np.array([0x632BE59BD9B4E019 + 12345], np.uint64))
    offsets = np.array([(d * 0x9E3779B97F4A7C15) & (2**64 - 1) for d in range(1, k + 1)], dtype=np.uint64)
    keys_a, u_a = hashing.path_keys_and_uniforms_numpy(seed_key, pixel, sample, offsets)
    keys_b, u_b = hashing.path_keys_and_uniforms_numba(seed_key, pixel, sample, offsets)
    np.testing.assert_array_equal(keys_a, keys_b)
    np.testing.assert_array_equal(u_a, u_b)
    assert u_a.shape == (k, n) and keys_a.dtype == np.uint64
    np.testing.assert_array_equal(u_b, hashing.uniforms_numpy(keys_a, offsets))   # the same as two passes


@needs_numba
@pytest.mark.parametrize("P", [1, 3, 4])
@pytest.mark.parametrize("L_T,L_M", [(4, 4), (1, 1), (4, 1)])
@pytest.mark.parametrize("depol", [False, True])
def test_update_abcs_bitwise(P, L_T, L_M, depol):
    rng = np.random.default_rng(P * 10 + L_T)
    n = 500
    T = rng.normal(size=(P, P, L_T, n))
    wo = unit(rng, n)
    x_T = unit(rng, n)
    x_T -= wo * (x_T * wo).sum(0)
    x_T /= np.linalg.norm(x_T, axis=0)
    x_out = unit(rng, n)
    x_out -= wo * (x_out * wo).sum(0)
    x_out /= np.linalg.norm(x_out, axis=0)
    x_out[:, :5] = x_T[:, :5]          # no rotation
    x_out[:, 5:8] = -x_T[:, 5:8]       # half turn: R = identity too
    x_out[:, 8:10] = 0.0               # degenerate frame: r² = 0 handled
    A, B, C, S = (rng.normal(size=(L_M, n)) for _ in range(4))
    D = rng.random((L_M, n)) if depol else None
    # a vertex group: every other path of a bigger batch, in shuffled order
    Tfull = rng.normal(size=(P, P, L_T, 2 * n))
    rows = rng.permutation(np.arange(0, 2 * n, 2))
    Tfull[..., rows] = T
    a = np.full_like(Tfull, 7.0)
    b = a.copy()
    before = Tfull.copy()
    transport.update_abcs_numpy(a, Tfull, rows, x_out, x_T, wo, A, B, C, S, D)
    transport.update_abcs_numba(b, Tfull, rows, x_out, x_T, wo, A, B, C, S, D)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(Tfull, before)
    assert np.all(a[..., 1::2] == 7.0)


def test_update_abcs_is_the_matrix_product():
    """The NumPy reference itself against an explicit T·R(φ)·M with 4×4 matrices."""
    from engine.polarisation.frames import rotator
    from engine.polarisation.mueller import abcs_matrix
    rng = np.random.default_rng(7)
    n = 50
    T = rng.normal(size=(4, 4, 1, n))
    phi = rng.uniform(0, np.pi, n)
    A, B, C, S = (rng.normal(size=(1, n)) for _ in range(4))
    D = rng.random((1, n))
    M = abcs_matrix(A, B, C, S)
    M[0, 0] += D
    R = rotator(np.cos(2 * phi), np.sin(2 * phi))
    want = np.einsum("ijln,jkn,klmn->ilmn", T, R, M[:, :, None] if M.ndim == 3 else M)
    # frames with x_out at angle φ from x_T about wo = z, measured towards y_T = wo × x_T
    wo = np.tile([[0.0], [0.0], [1.0]], n)
    x_T = np.tile([[1.0], [0.0], [0.0]], n)
    x_out = np.stack((np.cos(phi), -np.sin(phi), np.zeros(n)))
    got = np.empty_like(T)
    transport.update_abcs(got, T, np.arange(n), x_out, x_T, wo, A, B, C, S, D)
    np.testing.assert_allclose(got, want.reshape(got.shape), rtol=1e-12, atol=1e-12)


@needs_numba
@pytest.mark.parametrize("L_T,L_e", [(4, 4), (1, 3), (1, 4)])
def test_add_light_bitwise(L_T, L_e):
    rng = np.random.default_rng(L_T + L_e)
    P, n_paths, n = 4, 300, 120
    T = rng.normal(size=(P, P, L_T, n))
    path = rng.permutation(n_paths)[:n]
    sel = np.sort(rng.choice(n, 60, replace=False))
    Le, w = rng.random((L_e, sel.size)), rng.random(sel.size)
    a = rng.normal(size=(P, L_e, n_paths))
    b = a.copy()
    transport.add_light_numpy(a, path, T, sel, Le, w)
    transport.add_light_numba(b, path, T, sel, Le, w)
    np.testing.assert_array_equal(a, b)


@needs_numba
@pytest.mark.parametrize("P,L_T,L_w", [(4, 4, 4), (4, 1, 3), (3, 1, 4), (1, 4, 4)])
def test_throughput_times_stokes(P, L_T, L_w):
    rng = np.random.default_rng(P + L_T)
    n = 400
    T = rng.normal(size=(P, P, L_T, 3 * n))
    rows = rng.choice(3 * n, n, replace=False)
    S = rng.normal(size=(P, L_T, n))
    w = rng.random((L_w, n))
    a = transport.throughput_times_stokes_numpy(T, rows, S, w)
    b = transport.throughput_times_stokes_numba(T, rows, S, w)
    assert a.shape == b.shape
    np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-14)
    # the compiled sums bit for bit: Σ_m T[i, m]·S[m] added in m order from 0, then × the weight
    acc = np.zeros((P, L_T, n))
    for m in range(P):
        acc = acc + T[:, m][..., rows] * S[m][None]
    assert b.tobytes() == (acc * w[None]).tobytes()


# ----------------------------------------------------------------------------- whole renders

RENDER_SNIPPET = r"""
import dataclasses, json, sys
import numpy as np
sys.path.insert(0, {repo!r})
from engine import kernels
from engine.render.renderer import Renderer
from engine.scene.loader import load_scene
scene = load_scene({scene!r})
scene.camera.width = scene.camera.height = 20
scene.settings = dataclasses.replace(scene.settings, spp=3, threads=1)
np.save({out!r}, Renderer(scene).render().stokes())
print(json.dumps(kernels.BACKEND))
"""


@pytest.mark.subprocess
@needs_numba
@pytest.mark.parametrize("name", ["fresnel_sphere", "glass_sphere", "cornell_lambert", "rough_sphere_a030"])
def test_render_with_numpy_kernels_equals_compiled(tmp_path, name):
    """The same render with POLAR_KERNELS=numpy and with Numba, in fresh processes."""
    images = {}
    for backend in ("numpy", "numba"):
        out = tmp_path / f"{backend}.npy"
        code = RENDER_SNIPPET.format(repo=REPO, scene=shared_path("peers", "scenes", f"{name}.json"), out=str(out))
        env = dict(os.environ, POLAR_KERNELS=backend)
        proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert json.loads(proc.stdout.strip().splitlines()[-1]).startswith(backend)
        images[backend] = np.load(out)
    assert np.abs(images["numpy"]).max() > 0
    np.testing.assert_allclose(images["numba"], images["numpy"], rtol=1e-10, atol=1e-13)


def test_backend_is_reported():
    scene = load_scene(shared_path("peers", "scenes", "plane_brewster.json"))
    scene.camera.width = scene.camera.height = 4
    scene.settings = dataclasses.replace(scene.settings, spp=1)
    stats = Renderer(scene).render().stats
    assert stats["kernels"] == kernels.BACKEND


# ----------------------------------------------------------------------------- Fresnel, frames, camera, tables, lights

@needs_numba
def test_fresnel_abcs_matches_reference_at_hard_cases():
    from engine.kernels.fresnel import fresnel_reflection_abcs_numba
    from engine.polarisation.fresnel import fresnel_reflection_abcs_numpy
    rng = np.random.default_rng(3)
    n = 20000
    cos = rng.random((1, n))
    brewster = np.cos(np.arctan(1.5))
    cos[0, :12] = [0.0, 1.0, 1e-300, -0.2, 1.3, brewster, np.cos(np.arcsin(1 / 1.5)), 1e-16, 1 - 1e-16, 0.5,
                   np.nextafter(0.0, 1.0), 1e-200]
    etas = [np.full((4, n), 1.5 + 0j), np.full((1, n), 1 / 1.5 + 0j),           # outside and inside (TIR)
            np.ones((1, n)) + 0j,                                                 # index-matched
            rng.uniform(0.05, 4, (4, n)) + 1j * rng.uniform(0, 8, (4, n)),        # metals
            np.full((1, n), 0.2 + 3.5j), np.full((1, n), 1e-3 + 1e3j)]           # extreme κ
    for eta in etas:
        want = fresnel_reflection_abcs_numpy(cos, eta)
        got = fresnel_reflection_abcs_numba(cos, eta)
        for w, g in zip(want, got):
            assert g.shape == w.shape and np.all(np.isfinite(g))
            np.testing.assert_allclose(g, w, rtol=0, atol=4e-15)


@needs_numba
def test_plane_axes_bitwise_including_degenerate_frames():
    from engine.kernels.geometry import unit_cross_numba, unit_cross_numpy
    rng = np.random.default_rng(4)
    n, k = unit(rng, 3000), unit(rng, 3000)
    k[:, :100] = n[:, :100]                         # normal incidence: fallback axis
    k[:, 100:200] = -n[:, 100:200]
    n[:, 200:210] = [[0.0], [0.0], [-1.0]]          # the fallback's own branch cut
    k[:, 200:210] = [[0.0], [0.0], [1.0]]
    got = unit_cross_numba(n, k, 1e-12)
    np.testing.assert_array_equal(got, unit_cross_numpy(n, k, 1e-12))


@needs_numba
@pytest.mark.parametrize("name", ["fresnel_sphere", "cornell_lambert", "conv_s3_check"])
def test_pinhole_camera_rays_bitwise(name, monkeypatch):
    from engine.render import camera
    scene = load_scene(shared_path("peers", "scenes", f"{name}.json"))
    scene.camera.shift = (0.1, -0.25)
    model = camera.CameraModel(scene.camera)
    n = scene.camera.width * scene.camera.height
    pixel, u = np.arange(n), np.random.default_rng(5).random((2, n))
    compiled = model.generate(pixel, u)
    monkeypatch.setattr(camera, "pinhole_rays", geometry.pinhole_rays_numpy)
    reference = model.generate(pixel, u)
    for a, b in zip(reference, compiled):
        np.testing.assert_array_equal(a, b)


@needs_numba
def test_spectral_table_interpolation_bitwise():
    from engine.kernels.tables import interp_grid_numpy
    from engine.spectral import cie
    from engine.spectral.spectrum import _BASIS
    lam = np.random.default_rng(6).uniform(300, 900, (4, 5000))
    lam[0, :6] = [np.nan, 360.0, 830.0, np.nextafter(360.0, 0), np.nextafter(830.0, 1e4), 595.5]
    for table in (cie._CMF, _BASIS, cie._D65N[None]):
        for outside in ("zero", "clamp"):
            np.testing.assert_array_equal(cie.interp_grid(table, lam, outside),
                                          interp_grid_numpy(table, lam, 360.0, 830.0, outside == "zero"))


@needs_numba
@pytest.mark.parametrize("two_sided", [False, True])
def test_area_light_sampling_bitwise(two_sided):
    scene = load_scene(shared_path("peers", "scenes", "cornell_lambert.json"))
    r = Renderer(scene)
    light = next(lt for lt in r.lights.lights if hasattr(lt, "cdf"))
    c = r.compiled
    rng = np.random.default_rng(7)
    p = rng.uniform(-1, 1, (3, 5000))
    p[:, :3] = c.vertices[c.faces[light.tris[0]]].T       # on the light itself: dist 0 → invalid
    normal = c.tri_normal[light.tris[0]].astype(np.float64)
    centre = c.vertices[c.faces[light.tris]].reshape(-1, 3).mean(axis=0)
    u = rng.random((3, 5000))
    p[:, 2500:] = (centre - normal)[:, None] + 0.1 * rng.uniform(-1, 1, (3, 2500))     # behind the light
    args = (p, u, light.cdf, light.tris, c.faces, c.vertices, c.tri_normal, light.total_area, two_sided)
    want, got = geometry.area_light_sample_numpy(*args), geometry.area_light_sample_numba(*args)
    for w, g in zip(want, got):
        np.testing.assert_array_equal(w, g)
    assert not got[4][:3].any() and got[4].any()
    # two-sided: the back faces' samples count as well (one-sided: only the front faces')
    back = (normal @ got[0] > 0) & (got[1] > 0)
    assert back.sum() > 100 and (got[4][back].all() if two_sided else not got[4][back].any())


@needs_numba
@pytest.mark.parametrize("P,L_T,L_M", [(4, 4, 4), (4, 1, 1), (3, 4, 1), (1, 4, 4)])
def test_update_depolarising_and_general(P, L_T, L_M):
    rng = np.random.default_rng(P + 10 * L_T)
    n = 300
    T = rng.normal(size=(P, P, L_T, 2 * n))
    rows = rng.permutation(2 * n)[:n]
    A = rng.random((L_M, n))
    a = np.full_like(T, 3.0)
    b = a.copy()
    transport.update_depolarising_numpy(a, T, rows, A)
    transport.update_depolarising_numba(b, T, rows, A)
    np.testing.assert_array_equal(a, b)
    wo = unit(rng, n)
    x_T, x_out = (np.cross(wo.T, rng.normal(size=(n, 3))).T for _ in range(2))
    x_T /= np.linalg.norm(x_T, axis=0)
    x_out /= np.linalg.norm(x_out, axis=0)
    M = rng.normal(size=(4, 4, L_M, n))
    transport.update_general_numpy(a, T, rows, x_out, x_T, wo, M)
    transport.update_general_numba(b, T, rows, x_out, x_T, wo, M)
    np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12)
    assert np.all(b[..., np.setdiff1d(np.arange(2 * n), rows)] == 3.0)


@needs_numba
def test_throughput_times_stokes_with_fewer_stokes_components():
    rng = np.random.default_rng(11)
    T = rng.normal(size=(4, 4, 4, 100))
    rows = rng.permutation(100)[:40]
    S1 = rng.normal(size=(1, 4, 40))
    w = rng.random((4, 40))
    S4 = np.concatenate((S1, np.zeros((3, 4, 40))))
    full = transport.throughput_times_stokes_numpy(T, rows, S4, w)
    np.testing.assert_allclose(transport.throughput_times_stokes_numpy(T, rows, S1, w), full, rtol=1e-13)
    np.testing.assert_allclose(transport.throughput_times_stokes_numba(T, rows, S1, w), full, rtol=1e-13)


@pytest.mark.subprocess
@needs_numba
def test_same_files_under_two_package_names_do_not_share_compiled_kernels(tmp_path):
    """A checkout is imported as ``engine`` and, by the Blender tests and by developers, as the
    extension package; Numba's cache is keyed by file, its entries by module name, so a shared cache
    made the second name fail with ModuleNotFoundError (found by CI).  Each name gets its own cache."""
    pkg = tmp_path / "pkgs"
    pkg.mkdir()
    (pkg / "polar_render").symlink_to(REPO, target_is_directory=True)
    env = dict(os.environ, POLAR_KERNEL_CACHE=str(tmp_path / "cache"), POLAR_KERNELS="numba")
    # one kernel whose compiled code calls into another module (the measured-metal mirror reads
    # engine.kernels.tables): compiling the whole renderer three times took a minute and tests no more
    code = ("import sys; sys.path.insert(0, {pkg!r}); import numpy as np; "
            "from {mod}.kernels import BACKEND; from {mod}.kernels.fresnel import tabulated_mirror_abcs_numba as f; "
            "wl = np.array([400.0, 700.0]); (A, B, C, S), _ = f(np.array([0.5]), np.array([[550.0]]), wl, "
            "np.array([0.2, 0.3]), wl, np.array([3.0, 4.0]), 1.0); print(BACKEND, A[0, 0])")
    printed = set()
    for mod in ("polar_render.engine", "engine", "polar_render.engine"):
        proc = subprocess.run([sys.executable, "-c", code.format(pkg=str(pkg), mod=mod)], cwd=REPO,
                              env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-1500:]
        assert proc.stdout.strip().startswith("numba")
        printed.add(proc.stdout.strip())
    assert len(printed) == 1                              # the same reflectance under both names
    assert sorted(os.listdir(tmp_path / "cache")) == ["engine", "polar_render.engine"]
    for name in ("engine", "polar_render.engine"):        # each name compiled (and cached) its own kernel
        assert any(f.startswith("fresnel._tabulated_mirror_loop") and f.endswith(".nbi")
                   for _, _, files in os.walk(tmp_path / "cache" / name) for f in files)


def test_a_changed_helper_gets_a_fresh_kernel_cache(tmp_path):
    """Numba checks a cached kernel against its own file only, so after an edit of abcs_at (in
    kernels/fresnel.py) the cached Torrance–Sparrow step kept the old Fresnel arithmetic inlined (found
    when the twin test failed bit-wise on a warm cache).  The cache folder is keyed by every compiled
    source: an edit of one moves it, an edit of a module without compiled code does not."""
    import shutil
    root = tmp_path / "engine"
    shutil.copytree(os.path.join(REPO, "engine"), root, ignore=shutil.ignore_patterns("__pycache__"))
    first = kernels.compiled_sources_digest(str(root))
    assert first == kernels.compiled_sources_digest(os.path.join(REPO, "engine"))
    fresnel = root / "kernels" / "fresnel.py"
    fresnel.write_text(fresnel.read_text().replace("zr = e2r - (1.0 - c * c)", "zr = e2r - 1.0 + c * c"))
    edited = kernels.compiled_sources_digest(str(root))
    assert edited != first
    errors = root / "errors.py"
    errors.write_text(errors.read_text() + "\n# a comment\n")
    assert kernels.compiled_sources_digest(str(root)) == edited
    assert kernels.cache_dir().endswith(os.sep + first)


@needs_numba
def test_beckmann_visible_slopes_match_the_numpy_reference():
    from engine.kernels.microfacet import visible_slope_x_numba, visible_slope_x_numpy
    rng = np.random.default_rng(12)
    n = 40000
    tan = np.concatenate([rng.random(n // 4) * 0.1, rng.random(n // 4) * 3, 10 ** rng.uniform(0, 300, n // 4),
                          np.zeros(n // 4)])
    u1 = rng.random(n)
    u1[:8] = [0.0, 1 - 1e-17, 1e-300, 0.5, 1e-16, 0.999999, 1e-10, 0.3]
    with np.errstate(all="ignore"):
        want = visible_slope_x_numpy(tan, u1)
    got = visible_slope_x_numba(tan, u1)
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@needs_numba
@pytest.mark.parametrize("P", [1, 3, 4])
@pytest.mark.parametrize("L", [1, 4])
@pytest.mark.parametrize("apply_rr", [False, True])
def test_roulette_bitwise_including_nonfinite_and_black_paths(P, L, apply_rr):
    """Russian roulette + validity: same survivors, same divided throughputs, same non-finite count,
    with NaN/inf entries (in T00 and elsewhere), black paths, huge η² (q clamped) and q = 0."""
    rng = np.random.default_rng(P * 10 + L)
    n = 600
    T = rng.uniform(-0.2, 1.0, size=(P, P, L, n))
    T[..., 0:20] = np.nan if P == 1 else T[..., 0:20]
    T[0, 0, :, 20:40] = 0.0                                    # black
    T[-1, -1, -1, 40:60] = np.inf                              # non-finite off T00 (T00 itself for P = 1)
    T[0, 0, 0, 60:80] = np.nan                                 # NaN q
    eta_sq = rng.uniform(0.5, 3.0, n)
    eta_sq[80:100] = 1e6
    u = rng.uniform(size=n)
    valid = rng.uniform(size=n) < 0.9
    a_T, a_valid = T.copy(), valid.copy()
    b_T, b_valid = T.copy(), valid.copy()
    a_T, a_bad = transport.roulette_numpy(a_T, eta_sq, u, a_valid, apply_rr)
    b_T, b_bad = transport.roulette_numba(b_T, eta_sq, u, b_valid, apply_rr)
    assert np.array_equal(a_valid, b_valid) and a_bad == b_bad
    assert np.array_equal(a_T, b_T, equal_nan=True)
    assert 0 < a_valid.sum() < n and a_bad > 0


@needs_numba
def test_cosine_sampling_one_pass_matches_the_reference():
    """Lambert's compiled cosine sampling against cosine_sample_numpy: same directions, validity and
    pdfs (to rounding, sin/cos being the platform's), incl. u on the disk map's axes and diagonals,
    normals along ±z (the local frame's branch) and viewers behind the surface."""
    from engine.materials import lambert
    rng = np.random.default_rng(7)
    n = 2000
    u = rng.uniform(size=(2, n))
    u[:, :4] = [[0.5, 0.5, 0.0, 0.25], [0.5, 0.9, 0.0, 0.25]]   # centre, an axis, a corner, a diagonal
    n_s = unit(rng, n)
    n_s[:, 4:8] = [[0, 0, 0, 0], [0, 0, 0, 0], [1, -1, 1, -1]]
    wo = unit(rng, n)
    got = lambert.cosine_sample_numba(u, n_s, wo)
    ref = lambert.cosine_sample_numpy(u, n_s, wo)
    np.testing.assert_allclose(got[0], ref[0], rtol=1e-14, atol=1e-15)
    assert np.array_equal(got[1], ref[1])
    np.testing.assert_allclose(got[2], ref[2], rtol=1e-14, atol=0)
    assert 0 < ref[1].sum() < n


@needs_numba
def test_complex_index_from_measured_tables_bitwise():
    """Tabulated (n, κ) → relative complex index in one pass: NumPy's np.interp arithmetic (knots,
    ends, between knots) and complex division by the exterior index, bit for bit; ``inside`` False
    when a wavelength leaves either table."""
    from engine.kernels import tables
    from engine.spectral.ior import named_ior
    n_spec, k_spec = named_ior("Au")
    rng = np.random.default_rng(3)
    lam = rng.uniform(360.0, 830.0, (4, 3000))
    lam[0, :50] = n_spec.wavelengths[:50]                      # exactly on knots
    lam[1, :2] = [360.0, 830.0]
    for ext in (1.0, 1.33, 0.7):
        args = (lam, n_spec.wavelengths, n_spec.values, k_spec.wavelengths, k_spec.values, ext)
        (a, ia), (b, ib) = tables.complex_index_table_numpy(*args), tables.complex_index_table_numba(*args)
        assert ia == ib
        assert np.array_equal(a.real, b.real) and np.array_equal(a.imag, b.imag)
    outside = lam.copy()
    outside[2, 7] = 5000.0
    args = (outside, n_spec.wavelengths, n_spec.values, k_spec.wavelengths, k_spec.values, 1.0)
    assert tables.complex_index_table_numpy(*args)[1] is False
    assert tables.complex_index_table_numba(*args)[1] is False


@needs_numba
@pytest.mark.parametrize("L", [1, 3, 4])
def test_add_to_paths_bitwise(L):
    """The scatter-add of per-path values (next-event estimation) into the batch radiance, bit for bit."""
    rng = np.random.default_rng(L)
    n = 800
    acc_a = rng.normal(size=(4, L, 2 * n))
    acc_b = acc_a.copy()
    path = rng.permutation(2 * n)[:n]
    values = rng.normal(size=(4, L, n))
    transport.add_to_paths_numpy(acc_a, path, values)
    transport.add_to_paths_numba(acc_b, path, values)
    assert np.array_equal(acc_a, acc_b)


@needs_numba
def test_rgb_albedo_of_a_lambert_set_bitwise():
    from engine.materials import lambert
    rng = np.random.default_rng(11)
    rgb = rng.uniform(size=(3, 5))
    slot = rng.integers(0, 5, 700)
    basis = rng.uniform(size=(3, 4, 700))
    assert np.array_equal(lambert.rgb_albedo_numpy(rgb, slot, basis), lambert.rgb_albedo_numba(rgb, slot, basis))
    # constant members mixed in: their value, the others' colours on the basis
    constant, value = np.array([True, False, True, False, False]), rng.uniform(size=5)
    want = lambert.set_albedo_numpy(rgb, value, constant, slot, basis)
    assert np.array_equal(want, lambert.set_albedo_numba(rgb, value, constant, slot, basis))
    fixed = constant[slot]
    assert np.array_equal(want[:, fixed], np.broadcast_to(value[slot][fixed], (4, fixed.sum())))


@needs_numba
def test_segments_near_box_twins_agree():
    # the conservative box test before Embree (CompiledScene.passthrough_hits): segments into, past, along and
    # away from the box, axis-parallel ones, unbounded, negative and NaN lengths, non-finite origins and directions
    from engine.kernels import rays
    rng = np.random.default_rng(11)
    n = 4000
    lo, hi = np.array([-1.0, -0.5, 2.0]), np.array([1.0, 0.5, 2.0])           # a flat box (one quad)
    o = rng.uniform(-3, 3, (3, n)) * 10.0 ** rng.integers(-3, 3, (1, n))
    d = rng.uniform(lo, hi, (n, 3)).T - o
    d[:, ::3] = rng.normal(size=(3, (n + 2) // 3))
    d[rng.integers(0, 3, n // 5), rng.integers(0, n, n // 5)] = 0.0
    d /= np.linalg.norm(d, axis=0)
    t = np.where(rng.random(n) < 0.4, np.inf, rng.uniform(-1, 10, n))
    t[:2], o[1, 2], d[0, 3], o[2, 4] = np.nan, np.nan, np.inf, -np.inf
    want = rays.segments_near_box_numpy(o, d, t, lo, hi)
    assert 0 < want.sum() < n and want[:5].all()
    assert np.array_equal(rays.segments_near_box_numba(o, d, t, lo, hi), want)
    view = o[:, ::2], d[:, ::2], t[::2]                         # non-contiguous inputs
    assert np.array_equal(rays.segments_near_box_numba(*view, lo, hi), want[::2])
    assert len(rays._near_box_loop.signatures) == 1          # the precompiled one, whatever the callers' layouts

@needs_numba
def test_embree_ray_and_hit_conversions_bitwise():
    # the casts Embree's float32 layout needs: rounding, overflow to inf, NaN, capped lengths,
    # misses (−1) with and without a map from the BVH's triangles to the scene's
    from engine.kernels import rays
    rng = np.random.default_rng(7)
    n = 3000
    o = rng.normal(size=(3, n)) * 10.0 ** rng.integers(-40, 40, (3, n))
    d = unit(rng, n)
    t = np.abs(rng.normal(size=n)) * 10.0 ** rng.integers(-3, 45, n)
    t[:3] = (np.inf, np.nan, 1e37)
    o[0, 0] = np.nan
    with np.errstate(over="ignore"):                             # |o| > float32's range: inf
        for t_max in (t, None):
            for a, b in zip(rays.embree_rays_numpy(o, d, t_max), rays.embree_rays_numba(o, d, t_max)):
                assert (a is None and b is None) or (a.dtype == b.dtype and a.tobytes() == b.tobytes())
        view = o[:, ::2], d[:, ::2], t[::2]                      # non-contiguous inputs
        for a, b in zip(rays.embree_rays_numpy(*view), rays.embree_rays_numba(*view)):
            assert a.tobytes() == b.tobytes()
    prim_id = rng.integers(-1, 50, n).astype(np.int32)
    u, v, tfar = (rng.random(n).astype(np.float32) for _ in range(3))
    tfar[:5] = np.inf
    for prims in (None, rng.permutation(200)[:50].astype(np.int64)):
        for a, b in zip(rays.embree_hits_numpy(prim_id, u, v, tfar, prims),
                        rays.embree_hits_numba(prim_id, u, v, tfar, prims)):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()


def test_measured_metal_mirror_in_one_pass():
    """Tables → complex index → Fresnel (A, B, C, S), zero behind the normal, in one compiled loop:
    bit for bit the compiled two-step chain the conductor used before, to rounding the NumPy
    reference; ``inside`` False when a wavelength leaves the tables."""
    from engine.kernels import fresnel, tables
    from engine.polarisation.fresnel import tabulated_mirror_abcs_numpy
    from engine.spectral.ior import named_ior
    rng = np.random.default_rng(5)
    n = 4000
    lam = rng.uniform(360.0, 830.0, (4, n))
    cos = rng.uniform(-0.3, 1.0, n)
    cos[:8] = [0.0, -0.0, 1.0, 1e-300, -1e-300, np.nan, 1.2, np.nextafter(0.0, 1.0)]
    for metal, ext in (("Au", 1.0), ("Cr", 1.33), ("Cu", 0.7)):
        n_spec, k_spec = named_ior(metal)
        lam[0, :20] = n_spec.wavelengths[5:25]                 # on knots
        args = (lam, n_spec.wavelengths, n_spec.values, k_spec.wavelengths, k_spec.values, ext)
        got, inside = fresnel.tabulated_mirror_abcs_numba(cos, *args)
        with np.errstate(invalid="ignore"):                     # the NaN cosine
            want, inside_ref = tabulated_mirror_abcs_numpy(cos, *args)
        eta, _ = tables.complex_index_table_numba(*args)
        chain = fresnel.fresnel_reflection_abcs_numba(np.maximum(cos, 0.0)[None, :], eta)
        m = (cos >= 0).astype(np.float64)[None, :]
        assert inside and inside_ref
        for g, w, c in zip(got, want, chain):
            assert g.shape == (4, n)
            assert np.array_equal(g, c * m, equal_nan=True)
            np.testing.assert_allclose(g[:, 8:], w[:, 8:], rtol=0, atol=4e-15)
            assert np.array_equal(np.isnan(g), np.isnan(w))
        assert np.all(got[0][:, cos < 0] == 0)
    outside = lam.copy()
    outside[3, 11] = 900.0
    args = (outside, n_spec.wavelengths, n_spec.values, k_spec.wavelengths, k_spec.values, 1.0)
    assert fresnel.tabulated_mirror_abcs_numba(cos, *args)[1] is False
    with np.errstate(invalid="ignore"):
        assert tabulated_mirror_abcs_numpy(cos, *args)[1] is False


@needs_numba
@pytest.mark.parametrize("count", [1, 3, 4])
def test_wavelength_sampling_and_rgb_weights_bitwise(count):
    """Hero wavelengths (λ, pdf) and their sRGB weights: the compiled passes around NumPy's own atanh,
    cosh and 3×3 product give the reference's numbers bit for bit, at u = 0, strata edges, u → 1, for
    paths in any array shape, and weight 0 where pdf = 0."""
    from engine.kernels import wavelengths
    from engine.spectral import cie
    rng = np.random.default_rng(8)
    u = rng.random(5000)
    u[:6] = [0.0, 0.25, 0.5, 0.75, np.nextafter(1.0, 0.0), 1e-300]
    for shape in [(5000,), (50, 100), (0,)]:
        uu = u[:int(np.prod(shape))].reshape(shape)
        want = cie.sample_wavelengths_numpy(uu, count)
        got = cie._sample_wavelengths_compiled(uu, count)
        for w, g in zip(want, got):
            assert g.shape == w.shape == (count,) + shape and np.array_equal(g, w)
        lam, pdf = want
        pdf = pdf.copy()
        pdf.reshape(-1)[:3] = 0.0
        assert np.array_equal(cie._rgb_weights_compiled(lam, pdf), cie.rgb_weights_numpy(lam, pdf))
    assert np.all((got[0] >= cie.LAMBDA_MIN) & (got[0] <= cie.LAMBDA_MAX))
    assert wavelengths.sample_tanh is not None


@needs_numba
@pytest.mark.parametrize("two_sided", [False, True])
def test_rectangle_lamp_sampling_bitwise(two_sided):
    """Solid-angle sampling of a rectangle lamp in one pass (engine.kernels.light_sampling) against
    its NumPy reference, bit for bit: points above and below the lamp, in its plane (Ω = 0), far
    away (Ω below MIN_RECT_SOLID_ANGLE: ``use`` False), on its corner and edges, u at 0 and near 1."""
    from engine.kernels import light_sampling as ls
    rng = np.random.default_rng(5)
    n = 4000
    corner, ex, ey = np.array([-0.3, 0.2, 1.1]), np.array([0.7, 0.1, 0.0]), np.array([-0.1, 0.7, 0.05])
    len_x, len_y = np.linalg.norm(ex), np.linalg.norm(ey)
    ax, ay = ex / len_x, ey / len_y - (ey / len_y @ (ex / len_x)) * ex / len_x
    ay /= np.linalg.norm(ay)
    az = np.cross(ax, ay)
    normal = -az
    p = rng.uniform(-2, 2, (3, n))
    p[:, 0] = corner                                    # on the corner
    p[:, 1] = corner + 0.5 * len_x * ax                 # on an edge
    p[:, 2:6] = (corner + 0.3 * ax + 0.2 * ay)[:, None] + np.array([0.0, 1.0, 1e5, -1e-9])[None, :] * az[:, None]
    p[:, 6] = corner + 0.2 * ax + 0.1 * ay - 0.3 * ax   # in the plane, outside the rectangle
    u1, u2 = rng.random(n), rng.random(n)
    u1[:4], u2[:4] = [0.0, 0.0, np.nextafter(1.0, 0.0), 0.5], [0.0, np.nextafter(1.0, 0.0), 0.0, 1.0]
    args = (p, u1, u2, corner, ax, ay, az, len_x, len_y, normal, two_sided)
    with np.errstate(all="ignore"):
        want = ls.rect_light_sample_numpy(*args)
    got = ls.rect_light_sample_numba(*args)
    for w, g in zip(want, got):
        assert np.array_equal(w, g, equal_nan=True)
    valid, use = want[4], want[5]
    assert 0 < valid.sum() < n and not use[4] and not use[0] and use.any()


@needs_numba
@pytest.mark.parametrize("L_A,L", [(1, 4), (4, 4), (1, 3), (1, 1)])
@pytest.mark.parametrize("delta", [False, True])
def test_lambert_direct_light_bitwise(L_A, L, delta):
    """Lambert's one-pass next-event value, MIS and light weight (engine.kernels.diffuse) against
    direct_light_numpy, bit for bit: lights behind the surface, viewers behind it, grazing (cosθ_i = 0)
    and invalid light samples, zero pdfs, a scalar or per-path selection probability."""
    from engine.materials import lambert
    rng = np.random.default_rng(L_A + 10 * L)
    n = 3000
    n_s, wo, wi = unit(rng, n), unit(rng, n), unit(rng, n)
    wi[:, :3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    n_s[:, :3] = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]     # wi ⟂ n_s: cosθ_i = 0
    albedo = rng.uniform(size=(L_A, n))
    emitted = rng.uniform(size=(L, n))
    scale = rng.uniform(0, 3, n)
    ok = rng.random(n) < 0.9
    pdf_light = rng.uniform(0, 5, n)
    pdf_light[10:20] = 0.0
    for select in (0.25, rng.uniform(0.1, 1.0, n)):
        args = (n_s, wo, wi, albedo, emitted, scale, ok, pdf_light, select, delta)
        if isinstance(select, np.ndarray):      # per-path lights: some delta, some not
            args = args[:-1] + (rng.random(n) < 0.3 if delta else np.zeros(n, bool),)
        want, got = lambert.direct_light_numpy(*args), lambert.direct_light_numba(*args)
        for w, g in zip(want, got):
            assert w.shape == g.shape and np.array_equal(w, g)
        assert 0 < want[2].sum() < n and (want[0] > 0).any() and (want[1] > 0).any()


def selection_table(rng):
    """(kinds, params) of one light of each selection formula: a constant, a point, a hard-edged and a
    smooth spot with radii, an area emitter, a sun and a one-sided planar area emitter
    (engine.kernels.light_sampling SELECT_*)."""
    from engine.kernels import light_sampling as ls
    axis = unit(rng, 2).T
    rows = [(ls.SELECT_CONSTANT, [2.5]),
            (ls.SELECT_POINT, [0.3, -0.2, 1.5, 40.0, 1e-12, 0.0]),
            (ls.SELECT_POINT, [1.0, 1.0, 2.0, 10.0, 0.09, 0.3, 1.0, *axis[0], 0.8, 0.8]),
            (ls.SELECT_POINT, [-1.0, 0.5, 1.0, 25.0, 0.04, 0.2, 2.0, *axis[1], 0.5, 0.9]),
            (ls.SELECT_AREA, [0.0, 0.0, 1.9, 3.0, 0.18, 0.18 ** 0.5]),
            (ls.SELECT_DISTANT, [0.2, 0.3, 0.9327379053088815, 2.0, 0.05]),
            (ls.SELECT_AREA, [0.5, -0.5, 1.2, 5.0, 0.1, 0.1 ** 0.5, 1.0, *axis[0]])]     # one-sided, planar
    params = np.zeros((len(rows), ls.SELECTION_PARAMS))
    for i, (_, row) in enumerate(rows):
        params[i, :len(row)] = row
    return np.array([k for k, _ in rows]), params


def test_one_sided_area_importance_is_zero_only_behind_its_plane():
    """A planar one-sided emitter (normal +z, centre at z = 1, radius 0.5) sends nothing behind its
    plane: importance 0 there (z < 1 − ε beyond the bounding sphere's silhouette), unchanged on its
    axis in front, and > 0 everywhere in front (also grazing, beside the emitter)."""
    from engine.kernels import light_sampling as ls
    centre, normal = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])
    p = np.array([[0.0, 0.0, 3.0], [0.0, 0.0, -1.0], [3.0, 0.0, 1.01], [3.0, 0.0, 0.0], [0.3, 0.0, 0.99]]).T
    two = ls.area_importance(p, None, centre, 2.0, 0.25, 0.5)
    one = ls.area_importance(p, None, centre, 2.0, 0.25, 0.5, 1.0, normal)
    assert one[0] == two[0] and one[1] == 0.0 and one[2] > 0
    assert one[3] == 0.0                   # behind the plane by more than the silhouette's angle
    assert one[4] > 0                      # just behind, inside the bounding sphere: kept (conservative)


@needs_numba
@pytest.mark.parametrize("with_normals", [False, True])
def test_light_selection_probabilities_bitwise(with_normals):
    """Per-point light selection (importance of every light kind, normalised and mixed with the
    power distribution) in one compiled pass against the NumPy reference, bit for bit, incl. points
    on a point light (d = 0), behind lights, inside a spot's cone edge, and a batch where every
    importance is 0 but the constant's; then the choice of a light from those probabilities."""
    from engine.kernels import light_sampling as ls
    rng = np.random.default_rng(17)
    kinds, params = selection_table(rng)
    n_pts = 3000
    p = rng.uniform(-2, 2, (3, n_pts))
    p[:, 0] = params[1, :3]
    n = unit(rng, n_pts) if with_normals else None
    prob = np.array([0.05, 0.3, 0.1, 0.15, 0.25, 0.1, 0.05])
    want = ls.selection_probabilities_numpy(p, n, kinds, params, prob)
    got = ls.selection_probabilities_numba(p, n, kinds, params, prob)
    assert np.array_equal(want, got)
    np.testing.assert_allclose(want.sum(0), 1.0, rtol=1e-12)
    u = rng.random(n_pts)
    u[:3] = [0.0, np.nextafter(1.0, 0.0), 0.5]
    for w, g in zip(ls.choose_light_numpy(u, want), ls.choose_light_numba(u, want)):
        assert np.array_equal(w, g)
    dark = params.copy()
    dark[1:, 3] = 0.0                                   # only the constant light shines
    assert np.array_equal(ls.selection_probabilities_numpy(p, n, kinds, dark, prob),
                          ls.selection_probabilities_numba(p, n, kinds, dark, prob))
    # one point at a time: NumPy then sums the lights' importances pairwise (from 8 lights on)
    many = np.tile(np.arange(len(kinds)), 4)[:21]
    for count in (7, 8, 9, 16, 21):
        k, rows, pr = kinds[many[:count]], params[many[:count]], np.full(count, 1.0 / count)
        for j in range(40):
            q, m = p[:, j:j + 1], None if n is None else n[:, j:j + 1]
            assert np.array_equal(ls.selection_probabilities_numpy(q, m, k, rows, pr),
                                  ls.selection_probabilities_numba(q, m, k, rows, pr))


@needs_numba
@pytest.mark.parametrize("radius,soft", [(0.0, True), (0.3, True), (0.3, False)])
@pytest.mark.parametrize("spot_kind", [0, 1, 2])
def test_point_and_spot_light_sampling_bitwise(radius, soft, spot_kind):
    """Point and spot lights' next-event samples (delta, disk facing the receiver, sphere) in one
    compiled pass against engine.render.lights.lamps.point_light_sample_numpy, bit for bit, incl. a
    receiver on the light's centre and receivers inside the sphere; one point at a time too."""
    from engine.kernels.light_sampling import point_light_sample_numba
    from engine.render.lights import point_light_sample_numpy
    rng = np.random.default_rng(3 + spot_kind)
    n = 2000
    position = np.array([0.2, -0.4, 1.5])
    p = rng.uniform(-2, 2, (3, n))
    p[:, 0] = position
    p[:, 1] = position + 0.1                            # inside the sphere
    u = rng.random((3, n))
    axis = unit(rng, 1)[:, 0]
    spot = [np.array([0.0] * 6), np.array([1.0, *axis, 0.6, 0.6]), np.array([2.0, *axis, 0.4, 0.9])][spot_kind]
    for q, v in ((p[:, 5:6], u[:, 5:6]), (p, u)):
        args = (q, v, position, radius, soft, spot)
        want, got = point_light_sample_numpy(*args), point_light_sample_numba(*args)
        for w, g in zip(want, got):
            assert np.array_equal(w, g)
    assert 0 < want[4].sum() < n and (want[2] > 0).any()


@needs_numba
@pytest.mark.parametrize("soft", [True, False])
def test_lamp_disk_and_sphere_hits_bitwise(soft):
    """Rays against a point light's disk or sphere (emission seen by BSDF-sampled rays) in one
    compiled pass against lamp_hits_numpy: hit mask, distance and cosθ, bit for bit, incl. rays
    starting at the centre and inside the sphere, per-ray segment lengths."""
    from engine.kernels import light_sampling as ls
    rng = np.random.default_rng(23)
    n = 5000
    position = np.array([0.1, 0.2, 1.0])
    o = rng.uniform(-1.5, 1.5, (3, n))
    o[:, 0] = position
    o[:, 1] = position + 0.05
    to = position[:, None] + rng.normal(scale=0.3, size=(3, n)) - o
    d = to / np.linalg.norm(to, axis=0)
    seg = rng.uniform(0.5, 5.0, n)
    for s in (seg, np.inf):
        want, got = ls.lamp_hits_numpy(o, d, s, position, 0.35, soft), ls.lamp_hits_numba(o, d, s, position, 0.35, soft)
        for w, g in zip(want, got):
            assert np.array_equal(w, g)
    assert 0 < want[0].sum() < n

# ----------------------------------------------------------------------------- Torrance–Sparrow passes

def _ts_batch(seed, L, eta_kind):
    """Shading points with the frames' edge cases: normals along ±z (the local frame's branch), viewers
    behind the surface, wi = −wo (no half vector), wi = wo (backscatter: the scattering plane's
    fallback axis), grazing wi; per-point m and s; an index constant over λ and the batch (given once,
    (1, 1)), or per point and λ (partly constant over λ)."""
    rng = np.random.default_rng(seed)
    n = 3000
    n_s = unit(rng, n)
    n_s[:, :4] = [[0, 0, 0, 0], [0, 0, 0, 0], [1, -1, 1, -1]]
    wo = unit(rng, n)
    wo *= np.where((n_s * wo).sum(0) < 0, -1.0, 1.0)[None, :]
    wo[:, 4:40] = unit(rng, 36)                                   # some behind the surface
    wi = unit(rng, n)
    wi[:, 40:60] = -wo[:, 40:60]
    wi[:, 60:80] = wo[:, 60:80]
    t = np.cross(n_s[:, 80:100].T, rng.normal(size=(20, 3))).T
    wi[:, 80:100] = t / np.linalg.norm(t, axis=0)                 # grazing
    if eta_kind == "constant":
        eta = np.array([[0.47 + 2.4j]])
    else:
        eta = rng.uniform(0.2, 2.5, (L, n)) + 1j * rng.uniform(0, 4, (L, n))
        eta[:, :1000] = eta[:1, :1000]                             # partly constant over λ
        eta[:, 100:200] = 1.5                                      # real, above 1
    m = rng.uniform(1e-4, 1.5, n)
    m[200:300] = 0.3
    s = rng.uniform(0, 2, n)
    w_d = rng.uniform(0, 1, n)
    w_d[300:320] = 0.0
    if eta_kind == "constant":
        m, s = 0.3, 0.8                                            # numbers, as for untextured parameters
    return rng, n_s, wo, wi, eta, m, s, w_d


def _numpy_math_is_libm():
    """NumPy's float64 exp, log, sin and cos give the C library's bits here (no SIMD variants of its
    own, as on CPUs without AVX-512): then the compiled passes must reproduce the NumPy steps exactly."""
    import math
    x = np.random.default_rng(0).uniform(-30.0, 30.0, 4000)
    return all(np.array_equal(f(x if name != "log" else np.abs(x)),
                              [getattr(math, name)(v if name != "log" else abs(v)) for v in x])
               for name, f in (("exp", np.exp), ("log", np.log), ("sin", np.sin), ("cos", np.cos)))


#: The NumPy references of the material passes call the engine's compiled Fresnel and visible-slope
#: kernels when those are selected (POLAR_KERNELS is not "numpy"): with the C library's exp, log, sin
#: and cos in NumPy too, every step is then the same arithmetic and the passes must match bit for bit.
EXACT_TWINS = _numpy_math_is_libm() and kernels.COMPILED


def _bitwise(got, want):
    """The same bits where EXACT_TWINS, else the same to rounding (complex square roots and divisions
    are not bit-identical between NumPy and Numba) and the same flags."""
    assert len(got) == len(want)
    for g, w in zip(got, want):
        g, w = np.asarray(g), np.asarray(w)
        if EXACT_TWINS or g.dtype == bool:
            assert np.array_equal(g, w, equal_nan=True)
        else:
            np.testing.assert_allclose(g, w, rtol=1e-10, atol=1e-12)


@needs_numba
@pytest.mark.parametrize("distribution,shadowing", [("beckmann", "ts"), ("beckmann", "smith"),
                                                    ("beckmann", "smith_rational"), ("beckmann", "none"),
                                                    ("beckmann", "smith_correlated"), ("ggx", "smith_correlated"),
                                                    ("ggx", "smith"), ("ggx", "ts"), ("ggx", "none")])
@pytest.mark.parametrize("L,eta_kind", [(4, "constant"), (4, "varying"), (1, "varying"), (1, "constant")])
def test_torrance_sparrow_eval_bitwise(distribution, shadowing, L, eta_kind):
    from engine.materials import torrance_sparrow as ts
    _, n_s, wo, wi, eta, m, s, _ = _ts_batch(1, L, eta_kind)
    got = ts.torrance_sparrow_eval_numba(n_s, wo, wi, eta, L, s, m, shadowing, distribution)
    want = ts.torrance_sparrow_eval_numpy(n_s, wo, wi, eta, L, s, m, shadowing, distribution)
    _bitwise(got, want)
    assert 0 < want[5].sum() < n_s.shape[1] and np.count_nonzero(want[1]) > 1000


@needs_numba
@pytest.mark.parametrize("p_kind", ["fresnel", "given", "specular_only"])
@pytest.mark.parametrize("has_diffuse", [False, True])
@pytest.mark.parametrize("eta_kind", ["constant", "varying"])
@pytest.mark.parametrize("distribution", ["beckmann", "ggx"])
def test_torrance_sparrow_pdf_and_sample_bitwise(p_kind, has_diffuse, eta_kind, distribution):
    """The mixture pdf and the sampled direction, pdf, validity, weight and frame: the same bits as
    the material's NumPy steps (lobe choice by the Fresnel estimate or a given P_spec), the weight
    times the factor or not (``scale``: a multiscatter lobe adds its term first)."""
    from engine.materials import torrance_sparrow as ts
    rng, n_s, wo, wi, eta, m, s, w_d = _ts_batch(2, 4, eta_kind)
    n = n_s.shape[1]
    p_given = {"fresnel": None, "given": np.clip(rng.uniform(size=n), 0.1, 0.9), "specular_only": np.ones(n)}[p_kind]
    got = ts.torrance_sparrow_pdf_numba(n_s, wo, wi, m, p_given, eta, 4, s, w_d, True, has_diffuse, distribution)
    want = ts.torrance_sparrow_pdf_numpy(n_s, wo, wi, m, p_given, eta, 4, s, w_d, True, has_diffuse, distribution)
    _bitwise([got], [want])
    u_lobe = rng.uniform(size=n)
    u_dir = rng.uniform(size=(2, n))
    u_dir[:, :4] = [[0.5, 0.0, 1 - 1e-16, 0.25], [0.5, 0.0, 1e-300, 0.25]]
    forms = ("ts", "smith_rational") if distribution == "beckmann" else ("smith_correlated", "smith")
    for shadowing, scale in zip(forms, (True, False)):
        got = ts.torrance_sparrow_sample_numba(n_s, wo, u_lobe, u_dir, eta, 4, s, m, shadowing, p_given, w_d,
                                               has_diffuse, distribution, scale)
        want = ts.torrance_sparrow_sample_numpy(n_s, wo, u_lobe, u_dir, eta, 4, s, m, shadowing, p_given, w_d,
                                                has_diffuse, distribution, scale)
        _bitwise(got, want)
        assert 0.3 * n < want[2].sum() < n
        # the direction alone (TorranceSparrow.sample_direction): the same direction, pdf and validity, no value
        alone = ts.torrance_sparrow_sample_numba(n_s, wo, u_lobe, u_dir, eta, 4, s, m, shadowing, p_given, w_d,
                                                 has_diffuse, distribution, scale, False)
        assert all(v is None for v in alone[4:9])
        _bitwise(alone[:4] + alone[9:], got[:4] + got[9:])


def test_torrance_sparrow_material_uses_the_declared_twins():
    """Beckmann facets go through the twins (the compiled pass where Numba is on); Blinn facets and a
    pure-Lambert TS keep the NumPy steps, with the same interface."""
    from engine.materials.base import ShadingPoint
    from engine.materials.torrance_sparrow import TorranceSparrow
    for key in ("eval", "pdf", "sample"):
        assert f"materials.torrance_sparrow.torrance_sparrow_{key}" in kernels.TWINS
    rng = np.random.default_rng(5)
    n = 500
    n_s, wo = unit(rng, n), unit(rng, n)
    wo *= np.where((n_s * wo).sum(0) < 0, -1.0, 1.0)[None, :]
    sp = ShadingPoint(np.zeros((3, n)), n_s, n_s, wo, rng.uniform(400, 700, (4, n)))
    u = rng.uniform(size=(3, n))
    for mat in (TorranceSparrow(0.47, 2.4, 0.3, shadowing="smith_rational"),
                TorranceSparrow(1.5, 0.0, 0.3, distribution="blinn", diffuse_albedo=0.5, diffuse_weight=1.0),
                TorranceSparrow(1.5, 0.0, 0.3, specular_weight=0.0, diffuse_albedo=0.5, diffuse_weight=1.0)):
        eta = mat.relative_eta(sp)
        assert np.array_equal(np.broadcast_to(mat._eta(sp), eta.shape), eta)     # the index given once: same bits
        bs = mat.sample(sp, u[0], u[1:])
        ok = bs.valid
        assert ok.sum() > n // 3
        np.testing.assert_allclose(bs.pdf[ok], mat.pdf(sp, bs.wi)[ok], rtol=1e-15)
        f = mat.eval(sp, bs.wi)
        cos_i = (n_s * bs.wi).sum(0)
        np.testing.assert_allclose(bs.weight.A[:, ok], (f.A * cos_i / np.where(ok, bs.pdf, 1.0))[:, ok], rtol=1e-13)


@needs_numba
@pytest.mark.parametrize("kw", [
    dict(multiscatter=True),                                                   # Principled's metal lobe
    dict(diffuse_albedo="rgb", diffuse_weight=1.0, diffuse_layering="albedo_scaling",
         multiscatter=True),                                                   # its dielectric over the base
    dict(shadowing="smith", diffuse_albedo=0.5, diffuse_weight=0.7),           # Fresnel lobe choice, "add"
], ids=["metal", "layered", "separable"])
def test_ggx_torrance_sparrow_material_compiled_equals_numpy_steps(kw, monkeypatch):
    """A GGX Torrance–Sparrow (the Principled BSDF's metal and specular lobes) through the compiled passes
    gives the bits of its NumPy steps (``_facet_eval``, ``_mixture_pdf``, ``_mixture_sample``, which it ran
    before): eval, pdf and the sample's direction, pdf, validity and weight, multiscatter term included."""
    from engine.materials import torrance_sparrow as ts
    from engine.materials.base import ShadingPoint
    from engine.spectral.spectrum import RGBReflectanceSpectrum
    if kw.get("diffuse_albedo") == "rgb":
        kw = dict(kw, diffuse_albedo=RGBReflectanceSpectrum((0.6, 0.3, 0.2)))
    rng = np.random.default_rng(11)
    n = 3000
    n_s, wo = unit(rng, n), unit(rng, n)
    wo *= np.where((n_s * wo).sum(0) < 0, -1.0, 1.0)[None, :]
    sp = ShadingPoint(np.zeros((3, n)), n_s, n_s, wo, np.tile([[450.0], [520.0], [600.0], [680.0]], (1, n)))
    mat = ts.TorranceSparrow(1.5 if "diffuse_albedo" in kw else 0.2, 0.0 if "diffuse_albedo" in kw else 3.1, 0.25,
                             distribution="ggx", **kw)
    assert mat._compiled_lobe
    u = rng.uniform(size=(3, n))
    wi = unit(rng, n)

    def run():
        bs = mat.sample(sp, u[0], u[1:])
        f = mat.eval(sp, wi)
        return [mat.pdf(sp, wi), f.x_in, f.A, f.B, f.C, f.S, f.depol, bs.wi, bs.pdf, bs.valid, bs.weight.x_in,
                bs.weight.A, bs.weight.B, bs.weight.C, bs.weight.S, bs.weight.depol]
    got = run()
    monkeypatch.setattr(ts.TorranceSparrow, "_compiled_lobe", property(lambda self: False))
    want = run()
    _bitwise([g for g in got if g is not None], [w for w in want if w is not None])
    assert [g is None for g in got] == [w is None for w in want]
    assert 0.5 * n < want[9].sum() and np.count_nonzero(want[2]) > n // 3


@needs_numba
def test_ggx_d_at_takes_the_flat_limit_as_ggx_d():
    """Facets within 1e-75 of the horizon: (1 + tan²θ_h)² overflows, both D's give the limit α²/π (the compiled
    one gave NaN), and elsewhere the same bits."""
    from engine.kernels.microfacet import ggx_d_at
    from engine.materials.ggx import GGX
    h = np.array([[1.0, 0.6, 0.0, 0.3], [0.0, 0.0, 0.0, 0.1], [1e-80, 0.8, 1.0, 1e-70]])
    h /= np.linalg.norm(h, axis=0)
    for alpha in (1e-4, 0.3, 1.0):
        got = np.array([ggx_d_at(*h[:, i], alpha) for i in range(h.shape[1])])
        want = GGX(alpha).D(h)
        assert np.array_equal(got, want) and got[0] == alpha * alpha / np.pi and np.all(np.isfinite(got))


# ----------------------------------------------------------------------------- rough dielectric passes

@needs_numba
@pytest.mark.parametrize("distribution,rational", [("beckmann", False), ("beckmann", True), ("ggx", False)])
@pytest.mark.parametrize("n_int,n_ext,alpha", [(1.5, 1.0, 0.2), (1.33, 1.7, 0.9), (1.5, 1.0, 1e-4)])
def test_rough_dielectric_eval_pdf_sample_bitwise(distribution, rational, n_int, n_ext, alpha):
    """Viewers on both sides (η and its inverse), total internal reflection, ±z normals, wi = ±wo, with and
    without Fresnel: the compiled passes give the material's NumPy steps' bits."""
    from engine.materials import rough_dielectric as rd
    rng = np.random.default_rng(int(alpha * 1e4) + int(n_int * 100))
    n = 3000
    n_s = unit(rng, n)
    n_s[:, :4] = [[0, 0, 0, 0], [0, 0, 0, 0], [1, -1, 1, -1]]
    wo, wi = unit(rng, n), unit(rng, n)
    wi[:, 20:30] = -wo[:, 20:30]
    wi[:, 30:40] = wo[:, 30:40]
    args = (n_int, n_ext, distribution)
    u_lobe, u_dir = rng.uniform(size=n), rng.uniform(size=(2, n))
    for no_fresnel in (False, True):        # the rough dielectric; Cycles' Refraction (engine.materials.refraction)
        _bitwise(rd.rough_dielectric_eval_numba(n_s, wo, wi, 4, *args, rational, alpha, no_fresnel),
                 rd.rough_dielectric_eval_numpy(n_s, wo, wi, 4, *args, rational, alpha, no_fresnel))
        _bitwise([rd.rough_dielectric_pdf_numba(n_s, wo, wi, *args, alpha, no_fresnel)],
                 [rd.rough_dielectric_pdf_numpy(n_s, wo, wi, *args, alpha, no_fresnel)])
        got = rd.rough_dielectric_sample_numba(n_s, wo, u_lobe, u_dir, 1, *args, rational, alpha, no_fresnel)
        want = rd.rough_dielectric_sample_numpy(n_s, wo, u_lobe, u_dir, 1, *args, rational, alpha, no_fresnel)
        _bitwise(got, want)
        refracted = want[3] != 1.0
        valid = want[2]
        assert (refracted & valid).any() and (refracted[valid].all() if no_fresnel else (~refracted & valid).any())
        assert 0.3 * n < valid.sum() <= n


@needs_numba
@pytest.mark.parametrize("P", [1, 3, 4])
@pytest.mark.parametrize("L", [1, 4])
@pytest.mark.parametrize("n", [0, 1, 700])
def test_identity_throughput_bitwise(P, L, n):
    """The camera paths' T = identity (P, P, L, n), written in one compiled pass over reused memory."""
    a = transport.identity_throughput_numpy(P, L, n)
    b = transport.identity_throughput_numba(P, L, n)
    assert a.shape == b.shape == (P, P, L, n) and np.array_equal(a, b)
    assert np.array_equal(b.reshape(P * P, L * n).sum(axis=1).reshape(P, P), np.eye(P) * L * n)


@needs_numba
def test_roulette_before_rr_depth_does_not_read_its_numbers():
    """Before rr_depth the integrator skips the roulette dimension and passes no numbers: both twins
    give what they give with numbers."""
    rng = np.random.default_rng(3)
    T = rng.uniform(-0.2, 1.0, size=(4, 4, 4, 300))
    T[0, 0, :, :10] = 0.0
    T[1, 2, 3, 10:20] = np.nan
    valid = rng.uniform(size=300) < 0.9
    results = []
    for f in (transport.roulette_numpy, transport.roulette_numba):
        for u in (rng.uniform(size=300), np.empty(0)):
            v = valid.copy()
            out, bad = f(T.copy(), np.ones(300), u, v, False)
            results.append((out, bad, v))
    for out, bad, v in results[1:]:
        assert np.array_equal(out, results[0][0], equal_nan=True) and bad == results[0][1]
        assert np.array_equal(v, results[0][2])


@needs_numba
@pytest.mark.parametrize("P", [1, 4])
@pytest.mark.parametrize("L", [1, 4])
@pytest.mark.parametrize("apply_rr", [False, True])
@pytest.mark.parametrize("everyone", [False, True])
def test_next_segments_bitwise(P, L, apply_rr, everyone):
    """The end of a bounce in one step (η², roulette, survivors' columns, next origins) against its
    NumPy twin, and against the separate steps it replaces (roulette, np.take, offset_origin)."""
    rng = np.random.default_rng(P + 2 * L + 4 * apply_rr + 8 * everyone)
    n = 500
    T = rng.uniform(0.01, 1.0, size=(P, P, L, n))
    valid = np.ones(n, bool)
    if not everyone:
        T[0, 0, :, :20] = 0.0
        T[-1, -1, -1, 20:30] = np.nan
        valid = rng.uniform(size=n) < 0.8
    eta_sq, eta_step = rng.uniform(0.5, 2.0, n), rng.uniform(0.5, 2.0, n)
    u = rng.uniform(size=n) * (0.0 if everyone else 1.0)
    x_T, d, p, n_g = unit(rng, n), unit(rng, n), rng.normal(size=(3, n)) * 10, unit(rng, n)
    path = rng.permutation(n).astype(np.int64)
    keys = rng.integers(0, 2**63, n, dtype=np.uint64)
    is_delta, pdf = rng.uniform(size=n) < 0.5, rng.uniform(size=n)
    args = (eta_sq, eta_step, u, None, apply_rr, x_T, d, path, keys, is_delta, pdf, p, n_g, 1e-4)
    out = []
    for f in (transport.next_segments_numpy, transport.next_segments_numba):
        v = valid.copy()
        a = list(args)
        a[3] = v
        out.append(f(T.copy(), *a))
    for x, y in zip(*out):
        assert np.array_equal(x, y, equal_nan=True)
    # the separate steps
    v = valid.copy()
    e = eta_sq * eta_step
    T_r, bad = transport.roulette_numpy(T.copy(), e, u, v, apply_rr)
    idx = np.flatnonzero(v)
    assert np.array_equal(out[0][0], idx) and out[0][1] == bad and (idx.size == n) == everyone
    assert np.array_equal(out[1][2], T_r[..., idx])
    assert np.array_equal(out[1][5], e[idx]) and np.array_equal(out[1][7], keys[idx])
    assert np.array_equal(out[1][11], geometry.offset_origin_numpy(p[:, idx], n_g[:, idx], d[:, idx], 1e-4))


@needs_numba
@pytest.mark.parametrize("P", [1, 3, 4])
def test_stokes_rgb_samples_bitwise(P):
    """The batch's film samples: components beyond P zero, samples with a NaN or ±inf anywhere zeroed
    and counted, −0.0 kept."""
    rng = np.random.default_rng(P)
    rgb = rng.normal(size=(P, 3, 300))
    rgb[-1, 2, :10] = np.nan
    rgb[0, 0, 10:15] = -np.inf
    rgb[:, :, 15:20] = -0.0
    a, bad_a = transport.stokes_rgb_samples_numpy(rgb)
    b, bad_b = transport.stokes_rgb_samples_numba(rgb)
    assert a.tobytes() == b.tobytes() and bad_a == bad_b == 15
    assert not a[P:].any() and not a[:, :, :15].any() and np.array_equal(a[:P, :, 15:], rgb[:, :, 15:])
    # in place (the integrator's accumulators): the same bits; with P = 4 the input itself is the output
    for kernel in (transport.stokes_rgb_samples_numpy, transport.stokes_rgb_samples_numba):
        mine = rgb.copy()
        c, bad_c = kernel(mine, in_place=True)
        assert c.tobytes() == a.tobytes() and bad_c == 15 and (c is mine) == (P == 4)


@needs_numba
@pytest.mark.parametrize("P,L", [(1, 4), (3, 4), (4, 4), (4, 1)])
def test_spectral_stokes_rgb_samples_bitwise(P, L):
    """Spectral radiance to the film's Stokes × RGB samples: einsum's sums (each λ added in order from
    0) bit for bit, non-finite samples (an inf times a zero weight included) zeroed and counted."""
    rng = np.random.default_rng(10 * P + L)
    n = 3000
    radiance = rng.lognormal(size=(P, L, n)) * rng.choice([-1.0, 1.0], size=(P, L, n))
    w_rgb = rng.normal(size=(3, L, n))
    radiance[-1, -1, :10] = np.nan
    radiance[0, 0, 10:15] = np.inf
    w_rgb[:, 0, 10:15] = 0.0                                   # inf · 0: NaN
    radiance[:, :, 15:20] = -0.0
    a, bad_a = transport.spectral_stokes_rgb_samples_numpy(radiance, w_rgb)
    b, bad_b = transport.spectral_stokes_rgb_samples_numba(radiance, w_rgb)
    assert a.tobytes() == b.tobytes() and bad_a == bad_b == 15
    assert not a[P:].any() and not a[:, :, :15].any()
    want = sum(radiance[:, q, None, 20:] * w_rgb[None, :, q, 20:] for q in range(L))
    np.testing.assert_allclose(a[:P, :, 20:], want, rtol=1e-12, atol=1e-12)


@needs_numba
@pytest.mark.parametrize("n,span", [(0, 0), (1, 1), (5000, 37), (3000, 4096)])
@pytest.mark.parametrize("halves", [False, True])
def test_pixel_sums_bitwise(n, span, halves):
    """A batch's per-pixel Stokes sums, luminance squares, counts and even/odd luminance sums in one pass: the
    bincounts' bits (each pixel's samples added in order from +0.0; −0.0 samples, unsorted and repeated
    pixels, pixels without samples), y made as einsum makes it, and the sums themselves."""
    rng = np.random.default_rng(n + span)
    local = rng.integers(0, max(span, 1), n) if span else np.zeros(0, np.int64)
    x = rng.lognormal(size=(4, 3, n)) * rng.choice([-1.0, 1.0], size=(4, 3, n))
    x[:, :, :7] = -0.0
    w = np.array([0.2126, 0.7152, 0.0722])
    sample = rng.integers(0, 64, n) if halves else None
    a = transport.pixel_sums_numpy(local, span, x, w, sample)
    b = transport.pixel_sums_numba(local, span, x, w, sample)
    assert (a[3] is None) == (b[3] is None) == (not halves)
    for u, v in zip(a, b):
        if u is not None:
            assert u.dtype == v.dtype and u.shape == v.shape and u.tobytes() == v.tobytes()
    if n:
        y = np.einsum("c,scn->sn", w, x)
        p = local[0]
        mine = local == p
        np.testing.assert_allclose(a[0][:, :, p], x[:, :, mine].sum(-1), rtol=1e-12)
        np.testing.assert_allclose(a[1][:, p], (y[:, mine] ** 2).sum(-1), rtol=1e-12)
        assert a[2][p] == mine.sum() and a[2].sum() == n
        if halves:
            odd = mine & (sample % 2 == 1)
            np.testing.assert_allclose(a[3][1, :, p], y[:, odd].sum(-1), rtol=1e-12, atol=1e-300)
            np.testing.assert_allclose(a[3].sum(axis=0), np.stack([np.bincount(local, y[s], span) for s in range(4)]),
                                       rtol=1e-12, atol=1e-12)


@needs_numba
@pytest.mark.parametrize("n", [0, 1, 2000])
def test_material_groups_bitwise_and_as_nonzero_per_group(n):
    """Each hit path's material, the paths per group and the paths sorted by group: as the gathers,
    bincount and np.nonzero(grp == g) they replace (groups absent from the batch included)."""
    rng = np.random.default_rng(n)
    tri_material = rng.integers(0, 6, 500).astype(np.int32)
    group_of = np.array([0, 3, 0, 1, 3, 0], np.int64)          # group 2 has no material
    prim = rng.integers(0, 500, n)
    a = material_groups.material_groups_numpy(prim, tri_material, group_of, 4)
    b = material_groups.material_groups_numba(prim, tri_material, group_of, 4)
    for x, y in zip(a, b):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    mat, counts, order = b
    grp = group_of[tri_material[prim]]
    assert np.array_equal(mat, tri_material[prim]) and counts[2] == 0
    ends = np.cumsum(counts)
    for g in range(4):
        assert np.array_equal(order[ends[g] - counts[g]:ends[g]], np.nonzero(grp == g)[0])


@needs_numba
@pytest.mark.parametrize("n", [0, 1, 900])
def test_shadow_rays_bitwise_and_as_offset_origin_and_the_length_rule(n):
    """Shadow-ray origins and lengths in one pass: as offset_origin and the length rule they replace,
    with lights at infinity (inf, nan distances) and far-away points."""
    rng = np.random.default_rng(n + 5)
    p = rng.normal(size=(3, n)) * rng.choice([1.0, 1e3], n)
    n_g, wi = unit(rng, n), unit(rng, n)
    dist = rng.uniform(0.0, 20.0, n)
    dist[: n // 10] = np.inf
    dist[n // 10: n // 5] = np.nan
    a = shadow_rays.shadow_rays_numpy(p, n_g, wi, dist, 8.9e-5)
    b = shadow_rays.shadow_rays_numba(p, n_g, wi, dist, 8.9e-5)
    assert all(x.tobytes() == y.tobytes() for x, y in zip(a, b))
    assert a[0].tobytes() == geometry.offset_origin_numba(p, n_g, wi, 8.9e-5).tobytes()
    want = np.where(np.isfinite(dist), dist * (1.0 - 1e-4) - 1e-4 * (1.0 + np.abs(p).max(0)), np.inf)
    assert a[1].tobytes() == want.tobytes()


def test_helpers_called_from_compiled_loops_are_compiled_without_reference_counting():
    """A @jit helper that another compiled function calls, and that allocates nothing (nor calls
    anything that does), must be @jit_inner: with reference counting each call takes and drops a
    reference to every array argument (atomic operations LLVM cannot always remove; 59 ns instead of
    5 ns per measured-metal table lookup).  An allocating helper must stay @jit (it needs them)."""
    import ast
    import pathlib
    from tests.conftest import REPO
    fns = {}
    for path in pathlib.Path(REPO, "engine", "kernels").glob("*.py"):
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.FunctionDef):
                kind = {getattr(d, "id", None) for d in node.decorator_list} & {"jit", "jit_inner"}
                if kind:
                    fns[node.name] = (kind.pop(), node)

    def calls(node):
        return {c.func.id for c in ast.walk(node)
                if isinstance(c, ast.Call) and isinstance(c.func, ast.Name) and c.func.id in fns}

    allocating = {name for name, (_, node) in fns.items() if any(
        isinstance(a, ast.Attribute) and a.attr in ("empty", "zeros", "ones", "empty_like", "zeros_like", "full",
                                                    "array", "copy") for a in ast.walk(node))}
    grown = True
    while grown:
        before = len(allocating)
        allocating |= {name for name, (_, node) in fns.items() if calls(node) & allocating}
        grown = len(allocating) > before
    called = set().union(*(calls(node) for _, node in fns.values()))
    wrong = sorted(name for name in called if (fns[name][0] == "jit_inner") == (name in allocating))
    assert not wrong, f"helpers with the wrong decorator (jit_inner iff called and not allocating): {wrong}"
    assert sum(kind == "jit_inner" for kind, _ in fns.values()) >= 50


@needs_numba
def test_vcavity_shadowing_bitwise():
    """The V-cavity G (the coat albedo tables' and the NumPy Torrance–Sparrow's) on random directions,
    back sides, grazing zeros, ±0, infinities and NaN, in the (3, B, K) shapes the tables use."""
    from engine.kernels.microfacet import g_vcavity_numba, g_vcavity_numpy
    rng = np.random.default_rng(5)
    n = 30000
    wi, wo, h = (rng.normal(size=(3, n)) for _ in range(3))
    specials = np.array([0.0, -0.0, 1e-300, -1e-300, 1.0, np.inf, -np.inf, np.nan, 1e300])
    for a in (wi, wo, h):
        a[:, :3000] = rng.choice(specials, size=(3, 3000))
    for args in ((wi, wo, h), (wi.reshape(3, 30, 1000), wo.reshape(3, 30, 1000), h.reshape(3, 30, 1000)),
                 (wi[:, :1], wo, h)):                                   # broadcast ω_i
        with np.errstate(all="ignore"):
            want = g_vcavity_numpy(*args)
        got = g_vcavity_numba(*args)
        assert got.shape == want.shape and got.tobytes() == want.tobytes()


@needs_numba
@pytest.mark.parametrize("P,L", [(3, 1), (4, 1), (4, 3)])
def test_unpolarised_response_in_frame_bitwise(P, L):
    """A BSDF's response to unpolarised light, (M00, M10, 0, 0) rotated into the paths' frames: the compiled
    pass gives the NumPy chain's bits (zeros, rows, frame_rotation, rotate_stokes), keeps S0 and the polarised
    intensity |M10| (a rotation), is the identity where the frames coincide and finite where x_T is degenerate."""
    from engine.kernels import stokes_rotation as sr
    rng = np.random.default_rng(P + 10 * L)
    n = 500
    wo = rng.normal(size=(3, n))
    wo /= np.linalg.norm(wo, axis=0)
    x_out = np.cross(wo.T, rng.normal(size=(n, 3))).T
    x_out /= np.linalg.norm(x_out, axis=0)
    x_T = np.cross(wo.T, rng.normal(size=(n, 3))).T
    x_T /= np.linalg.norm(x_T, axis=0)
    x_T[:, :20] = x_out[:, :20]                 # the same frame: no rotation
    x_T[:, 20:25] = 0.0                         # degenerate: the identity
    m00, b = rng.random((L, n)), rng.normal(size=(L, n))
    b[:, 25:30] = -0.0
    a = sr.unpolarised_response_in_frame_numpy(m00, b, x_out, x_T, wo, P)
    c = sr.unpolarised_response_in_frame_numba(m00, b, x_out, x_T, wo, P)
    assert a.shape == c.shape == (P, L, n) and a.tobytes() == c.tobytes()
    assert np.array_equal(c[0], m00) and not c[3:].any()
    ok = np.ones(n, bool)
    ok[20:25] = False
    np.testing.assert_allclose(np.hypot(c[1], c[2])[:, ok], np.abs(b)[:, ok], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(c[1, :, :20], b[:, :20], rtol=1e-12, atol=1e-15)
    assert np.isfinite(c).all()


def test_frame_rotation_is_the_identity_where_a_frame_is_degenerate():
    """A zero frame (or one along the beam) keeps S1 and S2 (the docstring's identity), in both twins; a NaN
    frame stays NaN (the NaN rules see it) rather than becoming a silent identity."""
    from engine.kernels.stokes_rotation import frame_rotation, frame_rotation_at
    k = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    x_from = np.array([[1.0, 0.0, np.nan], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    x_to = np.array([[0.0, 1.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    x_to[:, 0] = (0.0, 0.0, 1.0)                            # along the beam: degenerate
    c2, s2 = frame_rotation(x_from, x_to, k)
    assert (c2[:2] == 1.0).all() and (s2[:2] == 0.0).all()
    assert np.isnan(c2[2])
    for j in range(3):
        cj, sj = frame_rotation_at(x_from, x_to, k, j)
        assert (cj == c2[j] or (np.isnan(cj) and np.isnan(c2[j]))) and (sj == s2[j] or np.isnan(sj))


@needs_numba
@pytest.mark.parametrize("correlated", [False, True])
@pytest.mark.parametrize("alpha_kind,eta_cols", [("number", "per_point"), ("per_point", "per_point"),
                                                 ("per_point", "one")])
def test_conductor_compensation_twins(correlated, alpha_kind, eta_cols):
    """The GGX conductor's multiscatter share k (engine.materials.ggx_energy.conductor_extra): the compiled loop
    against the NumPy twin on cosines 0 … 1 (the ends included), roughness 0 … 1 and metal-like indices."""
    from engine.materials import ggx_energy as g
    assert "materials.ggx_energy.conductor_extra" in kernels.TWINS
    rng = np.random.default_rng(11)
    n = 4000
    mu = rng.uniform(0.0, 1.0, n)
    mu[:4] = 0.0, 1.0, 1e-12, 0.5
    alpha = 0.3 if alpha_kind == "number" else rng.uniform(0.0, 1.0, n)
    cols = n if eta_cols == "per_point" else 1
    eta = rng.uniform(0.05, 3.0, (3, cols)) + 1j * rng.uniform(0.0, 6.0, (3, cols))
    if cols > 1:            # runs of one metal's index (evaluated once per run), and a NaN
        eta[:, 100:300] = eta[:, 100:101]
        eta[1, 50] = np.nan
    got = g.conductor_extra_numba(mu, alpha, eta, correlated)
    want = g.conductor_extra_numpy(mu, alpha, eta, correlated)
    assert got.shape == want.shape == (3, n) and np.nanmax(want) > 0.1 and np.nanmin(want) >= 0.0
    _bitwise([got], [want])
    assert g.conductor_extra_numba(mu[:0], alpha if np.ndim(alpha) == 0 else alpha[:0], eta[:, :0], correlated
                                   ).shape == (3, 0)


@needs_numba
@pytest.mark.parametrize("mode", ["f82", "schlick", "schlick_tint", "tint"])
def test_metal_index_twins(mode):
    """A textured metal's complex index from its colour (engine.textures.conductor_index.metal_index: Gulbrandsen's
    map with the edge tint solved for the F82 value): the compiled loop against the NumPy twin bit for bit, on
    reflectivities and edges beyond [0, 1] (the clips), 0, 1 and R_MAX, in (L, N) batches and broadcast."""
    from engine.textures import conductor_index as ci
    assert "textures.conductor_index.metal_index" in kernels.TWINS
    rng = np.random.default_rng(13)
    r = rng.uniform(-0.05, 1.05, (4, 900))
    r[0, :4] = 0.0, 1.0, 0.999, 1e-9
    r[1, :2] = np.nan                   # NaN in, NaN out on both sides (not a table read at INT_MIN)
    edge = rng.uniform(-0.1, 1.1, (4, 900))
    edge[0, 7] = np.nan
    for e in (edge, edge[:1], 0.7):
        got, want = ci.metal_index_numba(r, e, mode), ci.metal_index_numpy(r, e, mode)
        for g, w in zip(got, want):
            assert g.shape == w.shape == r.shape and np.nanmax(w) - np.nanmin(w) > 0.5
            assert np.isnan(w[1, :2]).all() and (np.ndim(e) == 0 or np.isnan(w[0, 7]))
            _bitwise([g], [w])


@needs_numba
@pytest.mark.parametrize("darken", [False, True])
@pytest.mark.parametrize("alpha_kind,eta_kind", [("number", "number"), ("per_point", "number"),
                                                 ("number", "per_point"), ("per_point", "per_point")])
def test_cycles_layer_weight_twins(darken, alpha_kind, eta_kind):
    """Cycles' layering weight of a dielectric GGX layer (engine.materials.ggx_energy.cycles_layer_weight: its albedo
    estimate, × the compensation's darkening): the compiled loop against the NumPy twin on cosines beyond 0 … 1 (the
    ends and the table's nodes included), roughness 0 … 1 and indices below and above 1 (IOR 1000 included)."""
    from engine.materials import ggx_energy as g
    assert "materials.ggx_energy.cycles_layer_weight" in kernels.TWINS
    rng = np.random.default_rng(12)
    n = 4000
    mu = rng.uniform(-0.1, 1.1, n)
    mu[:8] = 0.0, 1.0, 1e-12, 0.5, 1.0 / 15.0, 7.0 / 15.0, 0.25, 1.0 - 1e-15
    alpha = 0.09 if alpha_kind == "number" else np.concatenate(([0.0, 1.0, 1.0 / 225.0], rng.uniform(0, 1, n - 3)))
    eta = 1.45 if eta_kind == "number" else np.concatenate(([1.0, 1000.0, 0.5, 1.0 / 1.45],
                                                            rng.uniform(0.3, 4.0, n - 4)))
    mu[8] = np.nan                      # NaN in, NaN out on both sides (not a table read at INT_MIN)
    if alpha_kind == "per_point":
        alpha[9] = np.nan
    if eta_kind == "per_point":
        eta[10] = np.nan
    got = g.cycles_layer_weight_numba(mu, alpha, eta, darken)
    want = g.cycles_layer_weight_numpy(mu, alpha, eta, darken)
    bad = np.isnan(mu) | np.isnan(np.broadcast_to(alpha, n)) | np.isnan(np.broadcast_to(eta, n))
    assert np.isnan(want[bad]).all() and not np.isnan(want[~bad]).any()
    assert got.shape == want.shape == (n,) and np.ptp(want[~bad]) > 0.3 and np.all(want[~bad] >= 0.0)
    _bitwise([got], [want])
    assert g.cycles_layer_weight_numba(mu[:0], 0.3, 1.5, darken).shape == (0,)


@needs_numba
def test_area_lights_sampled_together_as_each_alone():
    """Several emitters sampled by area in one pass (kernels.geometry.area_lights_sample, next-event estimation's
    AreaGroup): per point the bits of its own emitter's area_light_sample, compiled and NumPy, one- and two-sided."""
    scene = load_scene(shared_path("peers", "scenes", "cornell_lambert.json"))
    c = Renderer(scene).compiled
    rng = np.random.default_rng(11)
    groups = [np.sort(rng.choice(len(c.faces), k, replace=False)) for k in (2, 1, 7, 30)]
    two_sided = np.array([False, True, True, False])
    areas = [c.tri_area[t] for t in groups]
    cdfs = [np.cumsum(a) / a.sum() for a in areas]
    total = np.array([a.sum() for a in areas])
    start = np.concatenate(([0], np.cumsum([len(t) for t in groups]))).astype(np.int64)
    cdf, tris = np.concatenate(cdfs), np.concatenate(groups).astype(np.int64)
    n = 4000
    p, u = rng.uniform(-1, 1, (3, n)), rng.random((3, n))
    member = rng.integers(0, len(groups), n)
    args = (p, u, member, cdf, start, tris, c.faces, c.vertices, c.tri_normal, total, two_sided)
    got, want = geometry.area_lights_sample_numba(*args), geometry.area_lights_sample_numpy(*args)
    for k in range(len(groups)):
        rows = np.flatnonzero(member == k)
        alone = geometry.area_light_sample_numba(p[:, rows], u[:, rows], cdfs[k], groups[k], c.faces, c.vertices,
                                                 c.tri_normal, total[k], two_sided[k])
        for g, w, a in zip(got, want, alone):
            assert np.array_equal(g[..., rows], a) and np.array_equal(w[..., rows], a)
    assert got[4].any() and not got[4].all()


@needs_numba
@pytest.mark.parametrize("faces_dtype", [np.int32, np.int64])
def test_interpolate_vertex_attribute_twins(faces_dtype):
    """Per-vertex attributes (UVs, colours, tangents) at hits (engine.textures.SurfacePoints): the compiled pass
    against the NumPy gathers, bit for bit, for 1–4 channels, barycentrics inside and beyond the triangle, no hits."""
    from engine.kernels.geometry import interpolate_vertex_attribute_numba, interpolate_vertex_attribute_numpy
    assert "kernels.geometry.interpolate_vertex_attribute" in kernels.TWINS
    rng = np.random.default_rng(9)
    faces = rng.integers(0, 50, (40, 3)).astype(faces_dtype)
    for C in (1, 2, 3, 4):
        values = rng.normal(0.0, 10.0, (50, C))
        for n in (0, 1, 2000):
            prim = rng.integers(0, 40, n)
            u, v = rng.uniform(-0.2, 1.0, n), rng.uniform(-0.2, 1.0, n)
            got = interpolate_vertex_attribute_numba(faces, values, prim, u, v)
            want = interpolate_vertex_attribute_numpy(faces, values, prim, u, v)
            assert got.shape == want.shape == (C, n) and got.flags.c_contiguous
            assert np.array_equal(got, want)        # (products and sums only: the same bits everywhere)


@needs_numba
@pytest.mark.parametrize("extension", ["REPEAT", "EXTEND", "CLIP", "MIRROR"])
def test_bilinear_texture_lookup_twins(extension):
    """Linear image lookups (engine.textures.texture.bilinear_lookup): the compiled loop against the NumPy filter
    for float texels (linear and sRGB-encoded) and 8/16-bit codes with 1, 3 and 4 channels, at coordinates inside,
    on and beyond the image's edges."""
    from engine.textures import texture as T
    assert "textures.texture.bilinear_lookup" in kernels.TWINS
    rng = np.random.default_rng(4)
    uv = rng.uniform(-2.5, 3.5, (2, 3000))
    uv[:, :4] = [[0.0, 1.0, 0.5, -1e-12], [0.0, 1.0, 1.0 - 1e-12, 2.0]]
    for dtype, spaces in ((np.float32, ("linear", "srgb")), (np.uint8, ("srgb",)), (np.uint16, ("srgb",))):
        for C in (1, 3, 4):
            pix = rng.uniform(0.0, 1.0, (7, 9, C))
            pix = pix.astype(np.float32) * 1.7 if dtype == np.float32 else (pix * np.iinfo(dtype).max).astype(dtype)
            for space in spaces:
                tex = T.ImageTexture(pix, "Linear", extension, interpolation_space=space)
                got, want = T.bilinear_lookup_numba(tex, uv), T.bilinear_lookup_numpy(tex, uv)
                assert got.shape == want.shape == (C, uv.shape[1]) and np.ptp(want) > 0.5
                _bitwise([got], [want])


@pytest.mark.skipif(not kernels.COMPILED, reason="Numba kernels disabled")
def test_tangent_frame_twins_agree_bit_for_bit():
    """A normal map's tangent frame (engine.textures.SurfacePoints.tangent_frame) compiled and in NumPy: given
    tangents or ∂p/∂u, Gram–Schmidt, the least-aligned-axis fallback (ties: the first axis, as np.argmin) where
    neither exists or T ∥ n."""
    from engine.kernels.geometry import tangent_frame_numba, tangent_frame_numpy
    rng = np.random.default_rng(5)
    for _ in range(24):
        n = int(rng.integers(1, 2000))
        n_s = rng.normal(size=(3, n))
        n_s /= np.linalg.norm(n_s, axis=0)
        n_s[:, ::7] = [[0.0], [0.0], [1.0]]
        n_s[:, 1::11] = [[0.0], [1.0], [0.0]]
        n_s[:, 2::13] = np.sqrt(1 / 3)
        t, dpdv = rng.normal(size=(3, n)), rng.normal(size=(3, n))
        t[:, ::5] = 0.0
        t[:, 1::9] = 2.0 * n_s[:, 1::9]
        ok = rng.random(n) < 0.8
        t4 = rng.normal(size=(4, n))
        t4[:3, ::3] = 0.0
        for has_t4 in (False, True):
            with np.errstate(all="ignore"):
                want = tangent_frame_numpy(n_s, t, dpdv, ok, t4, has_t4)
            got = tangent_frame_numba(n_s, t, dpdv, ok, t4, has_t4)
            assert all(g.tobytes() == w.tobytes() for g, w in zip(got, want))


@pytest.mark.skipif(not kernels.COMPILED, reason="Numba kernels disabled")
def test_lambert_direct_light_compiles_one_signature_for_any_input_flags():
    """A memoised (read-only) or fresh albedo, a scalar or per-path light choice probability, a broadcast or array
    delta flag: one compiled signature, so the precompile covers it whichever paths its scenes take (a Lambert
    scene rendered after the precompile compiled one again)."""
    from engine.kernels import diffuse
    rng = np.random.default_rng(2)
    n = 50
    n_s = np.tile([[0.0], [0.0], [1.0]], n)
    wo = wi = n_s.copy()
    albedo, emitted = rng.random((3, n)), rng.random((3, n))
    frozen = albedo.copy()
    frozen.flags.writeable = False
    scale, ok, pdf = rng.random(n), np.ones(n, bool), rng.random(n) + 0.1
    results = []
    for a in (albedo, frozen):
        for sel in (0.5, np.full(n, 0.5)):
            for delta in (False, np.zeros(n, bool)):
                results.append(diffuse.direct_light_numba(n_s, wo, wi, a, emitted, scale, ok, pdf, sel, delta))
    assert len(diffuse._direct_light_loop.signatures) == 1
    assert all(np.array_equal(r[1], results[0][1]) and np.array_equal(r[0], results[0][0]) for r in results)
