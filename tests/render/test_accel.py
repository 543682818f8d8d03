"""Ray casting through Embree (engine.render.accel): no ray slips between the triangles of a closed mesh.

The BVH is built in Embree's robust mode (embreex's default).  Mitsuba 3 builds its own without it,
and that is ≈ 20 % faster in closest-hit and shadow queries (measured on glass_sphere: 12 % of a
render), but rays aimed exactly at the shared edges of a closed mesh then slip through it: ≈ 7 % of
them from outside, 5 % from inside (a ray leaving a glass sphere that is never refracted).  Robust
mode lets none through at edges (0 of 60,000 each way).  At exact vertices (5–6 triangles meeting)
it still lets 0.2–0.6 % through; a rendered ray hits a vertex with probability zero, so that case is
measured here, not asserted.  Embree's packet queries (rtcIntersect4/8/16, what the renderer calls) are held to
the same: no leak, and the one-ray query's hits bit for bit.
"""

import numpy as np
import pytest

from engine.materials.lambert import Lambert
from engine.render.accel import CompiledScene
from engine.scene.description import Camera, Mesh, Scene
from engine.scene.shapes import icosphere
from engine.spectral import ConstantSpectrum


def closed_sphere(level=5):
    m = icosphere(level)
    cam = Camera(origin=np.array([0.0, -4.0, 0.0]), target=np.zeros(3), up=np.array([0.0, 0.0, 1.0]), width=8,
                 height=8, fov_deg=40.0)
    mesh = Mesh("ball", m.vertices, m.faces, ["grey"], np.zeros(len(m.faces), np.int32))
    return CompiledScene(Scene(camera=cam, meshes=[mesh], materials={"grey": Lambert(ConstantSpectrum(0.5))})), m


def unit(a):
    return a / np.linalg.norm(a, axis=0)


def direct_scenes():
    """Embree's library for DirectScene (one-ray and packet queries), or skip without it or Numba."""
    from engine import kernels
    from engine.render.embree_direct import library
    if library() is None or not kernels.COMPILED:
        pytest.skip("no compiled kernels, or Embree's library not found next to embreex")
    return library()


class _Rays:
    """A CompiledScene's ``intersect`` on another query object (one DirectScene width)."""

    def __init__(self, rays):
        self.rays = rays

    def intersect(self, o, d):
        from engine.render.accel import Hits
        return Hits(*self.rays.closest(o, d, None, None))


def test_rays_aimed_at_shared_edges_never_slip_through_a_closed_mesh():
    compiled, m = closed_sphere()
    assert_no_leak_at_shared_edges(compiled, m)


@pytest.mark.parametrize("width", [1, 4, 8, 16])
def test_no_query_width_slips_through_shared_edges(width):
    from engine.render.embree_direct import DirectScene
    lib = direct_scenes()
    compiled, m = closed_sphere()
    assert_no_leak_at_shared_edges(_Rays(DirectScene(lib, compiled.vertices, compiled.faces, width=width)), m)


def assert_no_leak_at_shared_edges(compiled, m):
    rng = np.random.default_rng(7)
    V = np.asarray(m.vertices, np.float64).T                # (3, nv) on the unit sphere
    F = np.asarray(m.faces)
    n = 60000
    e = F[rng.integers(0, len(F), n)]
    p = V[:, e[:, 0]] + rng.random(n) * (V[:, e[:, 1]] - V[:, e[:, 0]])     # on an edge two triangles share
    # from outside, within ≈ 30° of the inward normal: the first hit is the edge itself, 3 away
    normal = unit(p)
    w = unit(rng.normal(size=(3, n)))
    w = unit(normal + 0.55 * (w - (w * normal).sum(0) * normal))
    hits = compiled.intersect(p + 3.0 * w, -w)
    through = np.abs(hits.t - 3.0) > 1e-3
    assert not through.any(), f"{through.sum()} of {n} rays from outside slipped through an edge"
    # from inside (a refracted ray in a glass sphere), towards the edge point
    o = 0.3 * unit(rng.normal(size=(3, n))) * rng.random(n)
    hits = compiled.intersect(o, unit(p - o))
    through = np.abs(hits.t - np.linalg.norm(p - o, axis=0)) > 1e-3
    assert not through.any(), f"{through.sum()} of {n} rays from inside slipped through an edge"


@pytest.mark.parametrize("width", [1, 4, 8, 16])
def test_the_compiled_queries_give_embreex_hits_bit_for_bit(width):
    """engine.render.embree_direct (Embree's C API called from compiled loops, the renderer's scene when
    the kernels are compiled), one ray or packets of ``width`` rays a query, against embreex's ``run``: the
    same triangle, distance and barycentrics for every hit ray, the same misses, the same shadow-ray
    answers; bounded and unbounded rays, a triangle-id map, and rays from inside the mesh."""
    from engine.render.accel import EmbreexScene
    from engine.render.embree_direct import DirectScene
    lib = direct_scenes()
    _, m = closed_sphere(4)
    rng = np.random.default_rng(11)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    reference, direct = EmbreexScene(V, F), DirectScene(lib, V, F, width=width)
    n = 20003                                                          # a last packet part-filled
    o = 2.5 * unit(rng.normal(size=(3, n))) * rng.random(n)           # outside and inside the sphere
    d = unit(rng.normal(size=(3, n)))
    t_max = rng.uniform(0.5, 6.0, n)
    t_max[::7] = np.inf
    prims = rng.permutation(len(F)).astype(np.int64)
    for bound in (None, t_max):
        for mapping in (None, prims):
            a = reference.closest(o, d, bound, mapping)
            b = direct.closest(o, d, bound, mapping)
            hit = a[0] >= 0
            assert 0.2 < hit.mean() < 0.95
            np.testing.assert_array_equal(b[0], a[0])
            for x, y in zip(a[1:], b[1:]):
                assert x[hit].tobytes() == y[hit].tobytes()
            np.testing.assert_array_equal(b[3][~hit], a[3][~hit])      # a miss keeps its length
    blocked = reference.occluded(o, d, t_max)
    assert 0.1 < blocked.mean() < 0.9
    np.testing.assert_array_equal(direct.occluded(o, d, t_max), blocked)


@pytest.mark.parametrize("width", [4, 8, 16])
def test_packets_of_camera_rays_give_the_one_ray_hits_bit_for_bit(width):
    """Coherent camera rays (each pixel's samples in a row, the renderer's batches), with and without
    Embree's coherent flag: packets hit what one-ray queries hit, with the
    same t, u and v bits; and the rays refracted into the sphere there (towards its far side)."""
    from engine.render.embree_direct import DirectScene
    lib = direct_scenes()
    compiled, m = closed_sphere(5)
    cam = np.array([0.0, -4.0, 0.0])
    rng = np.random.default_rng(3)
    n_pix, spp = 64 * 64, 4
    pixel = np.repeat(np.arange(n_pix), spp)
    x = (pixel % 64 + rng.random(pixel.size)) / 64 - 0.5
    y = (pixel // 64 + rng.random(pixel.size)) / 64 - 0.5
    d = unit(np.stack([0.8 * x, np.ones_like(x), 0.8 * y]))
    o = np.repeat(cam[:, None], pixel.size, axis=1)
    one = DirectScene(lib, compiled.vertices, compiled.faces, width=1)
    packets = DirectScene(lib, compiled.vertices, compiled.faces, width=width)
    a = one.closest(o, d, None, None)
    hit = a[0] >= 0
    assert 0.3 < hit.mean() < 0.95
    for coherent in (False, True):
        b = packets.closest(o, d, None, None, coherent=coherent)
        np.testing.assert_array_equal(b[0], a[0])
        for x_, y_ in zip(a[1:], b[1:]):
            assert x_[hit].tobytes() == y_[hit].tobytes()
    p = cam[:, None] + a[3][hit] * d[:, hit]
    n = unit(p)
    w = unit(d[:, hit] - 0.5 * n)
    o2 = p - 1e-4 * n
    a2, b2 = one.closest(o2, w, None, None), packets.closest(o2, w, None, None)
    assert (a2[0] >= 0).all()
    for x_, y_ in zip(a2, b2):
        assert x_.tobytes() == y_.tobytes()


def test_a_render_queries_the_compiled_scene_when_the_kernels_are_compiled():
    from engine import kernels
    from engine.render.embree_direct import library
    compiled, _ = closed_sphere(2)
    expected = "DirectScene" if kernels.COMPILED and library() is not None else "EmbreexScene"
    assert type(compiled.rays).__name__ == expected
