"""The lights' compiled loops against their NumPy twins: bit for bit, on directions that reach the hard cases
(the poles, the seam at u = 0, the first and last rows, black texels, sRGB interpolation)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from engine import kernels
from engine.render.lights.environment import EnvironmentMapEmitter

numba_only = pytest.mark.skipif(not kernels.COMPILED, reason="needs the compiled kernels")


def _directions(rng, n):
    d = rng.normal(size=(3, n))
    d /= np.linalg.norm(d, axis=0)
    special = np.array([[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [-1, -1e-17, 0], [-1, 1e-17, 0.3],
                        [0, 1, 0], [1e-300, 0, 1], [3.0, 4.0, -5.0]], float).T       # poles, the seam, unnormalised
    return np.ascontiguousarray(np.concatenate((d, special), axis=1))


def _map(rng, dtype, grid, space, rotation=0.0, shape=(9, 16)):
    img = rng.uniform(0.0, 4.0, size=shape + (3,)).astype(dtype)
    img[2, 3:7] = 0.0                                        # black texels: pieces of pdf 0 for importance
    img[0, 0] = 300.0                                        # a sun at the seam, on the first row
    return EnvironmentMapEmitter(img, strength=1.7, rotation_deg=rotation, grid=grid, interpolation_space=space)


@numba_only
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("grid", ["cycles", "mitsuba"])
@pytest.mark.parametrize("space", ["linear", "srgb"])
@pytest.mark.parametrize("shape", [(9, 16), (64, 128)])
def test_environment_map_lookup_pdf_and_sample_bitwise(dtype, grid, space, shape):
    from engine.render.lights import environment as env_module
    rng = np.random.default_rng(7)
    env = _map(rng, dtype, grid, space, rotation=[10.0, -20.0, 30.0], shape=shape)
    mitsuba = grid == "mitsuba"
    u, v = env_module._uv_numpy(env._to_map(_directions(rng, 3000)))
    u[:2], v[:2] = [0.0, np.nextafter(1.0, 0.0)], [0.0, 1.0]                     # the seam, the poles
    for name, args in (("lookup", (u, v, env._interpolated, mitsuba, env.strength)),
                       ("pdf", (u, v, env.cell_pdf, env.texels.shape[0], mitsuba))):
        pair = kernels.TWINS[f"render.lights.environment.{name}"]
        a, b = pair.compiled(*args), pair.reference(*args)
        assert a.shape == b.shape and np.array_equal(a, b), name
    u = rng.uniform(size=(3, 3000))
    u[1, :3] = [0.0, np.nextafter(1.0, 0.0), env.row_cdf[5]]     # the ends of the rows' cdf and a value on a step
    u[2, :3] = [np.nextafter(1.0, 0.0), 0.0, 0.5]
    u[1, 103:203] = env.row_cdf[rng.integers(0, env.row_cdf.size - 1, 100)]     # on the rows' steps
    u[2, 203:303] = 0.0                                                          # a row's first piece
    u[2, 303:403] = np.nextafter(1.0, 0.0)                                       # … and its last
    pair = kernels.TWINS["render.lights.environment.sample"]
    args = (env.cdf, env.row_cdf, env.row_prob, env.row_start, env.cos_knots, env.cell_pdf, u)
    for a, b in zip(pair.compiled(*args), pair.reference(*args)):
        assert a.shape == b.shape and np.array_equal(a, b)


def test_environment_map_sample_agrees_with_its_pdf_and_radiance_with_the_texels():
    """Independent of the twins: the sampled directions' pdf is the pdf of their cells (sample against pdf), and a
    direction through a texel centre sees that texel × strength (the lookup against the image)."""
    rng = np.random.default_rng(3)
    env = _map(rng, np.float64, "cycles", "linear", rotation=[10.0, -20.0, 30.0])
    u = rng.uniform(size=(3, 4000))
    wi, dist, scale, pdf_s, ok = env.sample(np.zeros((3, 4000)), u)
    assert np.all(np.isinf(dist)) and np.allclose(np.linalg.norm(wi, axis=0), 1.0)
    assert np.allclose(env.pdf(wi)[ok], pdf_s[ok], rtol=1e-12) and np.allclose(scale[ok] * pdf_s[ok], 1.0)
    H, W = env.texels.shape[:2]
    rows, cols = rng.integers(0, H, 50), rng.integers(0, W, 50)
    theta, phi = math.pi * (rows + 0.5) / H, math.pi * (1.0 - 2.0 * (cols + 0.5) / W)
    dm = np.stack((np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)))
    rgb = env.lookup_rgb(env._to_world(dm))
    assert np.allclose(rgb, 1.7 * env.texels[rows, cols], rtol=1e-9, atol=1e-9)


@numba_only
def test_constant_sky_sample_bitwise():
    rng = np.random.default_rng(5)
    u = rng.uniform(size=(3, 2000))
    u[:, :4] = [[0.0, np.nextafter(1.0, 0.0), 0.5, 0.25], [0.0, np.nextafter(1.0, 0.0), 0.5, 0.75], [0.0] * 4]
    pair = kernels.TWINS["render.lights.environment.uniform_sample"]
    for a, b in zip(pair.compiled(u), pair.reference(u)):
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)


@numba_only
@pytest.mark.parametrize("two_sided", [False, True])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_triangle_sample_bitwise(two_sided, dtype):
    """The light tree's per-triangle sample (AreaEmitter.sample_triangles): points in front, behind, on the
    triangle's plane and at a vertex (distance 0), a degenerate triangle (area 0)."""
    rng = np.random.default_rng(11)
    V = rng.normal(size=(30, 3)).astype(dtype)
    faces = rng.integers(0, 30, size=(20, 3)).astype(np.int32)
    faces[0] = [4, 4, 5]                                                    # zero area
    e1, e2 = V[faces[:, 1]] - V[faces[:, 0]], V[faces[:, 2]] - V[faces[:, 0]]
    cross = np.cross(e1, e2)
    length = np.linalg.norm(cross, axis=1)
    area, normal = 0.5 * length, cross / np.where(length > 0, length, 1.0)[:, None]
    n = 4000
    p = rng.normal(size=(3, n)) * 2.0
    tri = rng.integers(0, 20, n)
    u1, u2 = rng.uniform(size=n), rng.uniform(size=n)
    u1[:3], u2[:3] = 1.0, 0.0                                               # b1 = 0, b2 = 0: vertex 0 …
    p[:, :3] = V[faces[tri[:3], 0]].T                                       # … where p is (distance 0)
    pair = kernels.TWINS["kernels.geometry.triangle_sample"]
    args = (p, tri, u1, u2, faces, V, normal, area, two_sided)
    for a, b in zip(pair.compiled(*args), pair.reference(*args)):
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)
    wi, dist, scale, pdf, valid, cos_l, b1, b2 = pair.reference(*args)
    assert valid.any() and not valid.all() and np.all(pdf[~valid] == 0) and np.all(scale[valid] * pdf[valid] > 0)
