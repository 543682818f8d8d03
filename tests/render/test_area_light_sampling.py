"""Solid-angle sampling of rectangular area lights (engine/render/lights/area.py: SphericalRectangle,
AreaEmitter) against analytic oracles: the solid angle of a rectangle seen from above a corner,
Lambert's polygon formula for the irradiance, a chi-square test of the sampled points against
the claimed pdf, and the pdf that MIS evaluates for rays that hit the light."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest

from engine.render.lights import MIN_RECT_SOLID_ANGLE, AreaEmitter, SphericalRectangle
from engine.spectral.spectrum import ConstantSpectrum
from tests.support.chi2 import assert_accepted, pearson

# a 1 × 0.6 rectangle in the plane z = 1, front normal +z
CORNER, EX, EY = np.array([-0.5, -0.3, 1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.6, 0.0])
POLYGON = np.array([CORNER, CORNER + EX, CORNER + EX + EY, CORNER + EY])


def emitter(two_sided=False, flip=False, polygon=POLYGON, faces=((0, 1, 2), (0, 2, 3))):
    """An AreaEmitter over two triangles of ``polygon``; ``flip``: front normal −z instead of +z."""
    F = np.array(faces)[:, ::-1] if flip else np.array(faces)
    V = np.asarray(polygon, np.float64)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    area = 0.5 * np.linalg.norm(n, axis=1)
    compiled = SimpleNamespace(vertices=V, faces=F, tri_normal=n / (2 * area[:, None]), tri_area=area,
                               tri_occluder=np.zeros(len(F), bool))
    return AreaEmitter(ConstantSpectrum(1.0), np.arange(len(F)), compiled, two_sided)


def lambert_irradiance(polygon, p, n):
    """Irradiance at p with normal n from a polygon of unit radiance wholly above p's horizon:
    Lambert's formula E = ½ |Σ_edges γ_i n·(v_i × v_{i+1})/|v_i × v_{i+1}||, γ_i the edge's angle."""
    v = polygon - p
    v = v / np.linalg.norm(v, axis=1)[:, None]
    total = 0.0
    for a, b in zip(v, np.roll(v, -1, axis=0)):
        g = np.cross(a, b)
        s = np.linalg.norm(g)
        total += math.atan2(s, a @ b) * (g @ n) / s
    return 0.5 * abs(total)


def irradiance_estimate(light, p0, n, count=200_000, seed=0):
    """(mean, standard error) of Σ L cos/pdf over ``count`` next-event samples at the point p0."""
    p = np.repeat(np.asarray(p0, np.float64)[:, None], count, axis=1)
    wi, dist, scale, pdf, valid = light.sample(p, np.random.default_rng(seed).random((3, count)))
    est = np.where(valid, scale * np.maximum(n @ wi, 0.0), 0.0)
    return est.mean(), est.std() / math.sqrt(count)


def test_rectangle_is_recognised_and_other_shapes_are_not():
    assert emitter().rect is not None
    assert emitter(faces=((0, 1, 3), (1, 2, 3))).rect is not None          # the other diagonal
    sheared = POLYGON + np.array([[0, 0, 0], [0, 0, 0], [0.2, 0, 0], [0.2, 0, 0]])
    assert emitter(polygon=sheared).rect is None                            # a parallelogram: area sampling


def test_a_rotated_rectangle_rounded_to_float32_is_still_a_rectangle():
    """Blender's area lamps come as float32 vertices through float32 matrices: a rotated one missed the exact test
    (every one of 2,000 random ones before), so it was sampled by area and split by the light tree."""
    rng = np.random.default_rng(7)
    sheared = 0
    for _ in range(300):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        size, centre = rng.uniform(0.01, 5.0, 2), rng.uniform(-100, 100, 3) * rng.uniform(0, 1)
        local = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]) * [size[0], size[1], 0] / 2
        pts = (local @ q.T + centre).astype(np.float32).astype(np.float64)
        rect = SphericalRectangle.from_triangles(np.array([[pts[0], pts[1], pts[2]], [pts[0], pts[2], pts[3]]]))
        assert rect is not None
        assert abs(rect.len_x * rect.len_y - size.prod()) <= 1e-5 * (1 + np.abs(pts).max()) * size.sum()
        shear = pts + np.outer([0, 0, 1, 1], 0.1 * size[0] * q[:, 0])          # 10 % of a side: not a rectangle
        sheared += SphericalRectangle.from_triangles(np.array([[shear[0], shear[1], shear[2]],
                                                               [shear[0], shear[2], shear[3]]])) is None
    assert sheared == 300


@pytest.mark.parametrize("a,b,h", [(1.0, 0.6, 1.0), (3.0, 0.2, 0.05), (0.01, 0.02, 10.0)])
def test_solid_angle_above_a_corner_matches_the_closed_form(a, b, h):
    # a rectangle a × b seen from the height h above one corner: Ω = atan(ab / (h √(a² + b² + h²)))
    rect = SphericalRectangle(np.zeros(3), np.array([a, 0.0, 0.0]), np.array([0.0, b, 0.0]))
    want = math.atan(a * b / (h * math.sqrt(a * a + b * b + h * h)))
    np.testing.assert_allclose(rect.solid_angle(np.array([[0.0], [0.0], [h]])), want, rtol=1e-10)
    np.testing.assert_allclose(rect.solid_angle(np.array([[0.0], [0.0], [-h]])), want, rtol=1e-10)


def test_pdf_integrates_to_one_over_the_subtended_solid_angle():
    # ∫ pdf dω = ∫_rectangle (1/Ω) cosθ_l / d² dA (Gauss–Legendre, 64 × 64 nodes)
    x, w = np.polynomial.legendre.leggauss(64)
    s, t = np.meshgrid(0.5 * (x + 1), 0.5 * (x + 1), indexing="ij")
    weights = np.outer(w, w) * 0.25 * np.linalg.norm(EX) * np.linalg.norm(EY)
    for p in ([0.2, 0.1, 1.3], [2.0, -1.0, 0.4], [0.0, 0.0, 2.5]):
        p = np.asarray(p)
        q = CORNER + s[..., None] * EX + t[..., None] * EY
        d = q - p
        d2 = (d * d).sum(-1)
        cos_l = np.abs(d[..., 2]) / np.sqrt(d2)
        omega = emitter().rect.solid_angle(p[:, None])[0]
        assert np.sum(weights * cos_l / d2) / omega == pytest.approx(1.0, rel=1e-6)


@pytest.mark.parametrize("p0", [[0.2, 0.1, 0.7], [0.45, 0.25, 0.99], [1.5, -2.0, 0.2], [-0.3, 0.0, 0.995]])
def test_sampled_points_follow_the_claimed_pdf_chi_square(p0):
    # Histogram of the sampled points over a 16 × 16 grid of the rectangle; a cell's expected share is
    # ∫_cell pdf·cosθ_l/d² dA (the pdf in solid angle carried to area), smooth inside the rectangle.
    light, p0 = emitter(flip=True), np.asarray(p0)     # emits towards −z, where p0 is
    count, cells = 200_000, 16
    p = np.repeat(p0[:, None], count, axis=1)
    wi, dist, scale, pdf, valid = light.sample(p, np.random.default_rng(3).random((3, count)))
    assert valid.all()
    q = p + wi * dist
    s = np.clip(((q[0] - CORNER[0]) / EX[0] * cells).astype(int), 0, cells - 1)
    t = np.clip(((q[1] - CORNER[1]) / EY[1] * cells).astype(int), 0, cells - 1)
    np.testing.assert_allclose(q[2], 1.0, atol=1e-9)                  # on the light's plane
    observed = np.bincount(s * cells + t, minlength=cells * cells).astype(float)
    omega = light.rect.solid_angle(p0[:, None])[0]
    np.testing.assert_allclose(pdf, 1.0 / omega, rtol=1e-12)
    # composite Gauss–Legendre: 8 panels of 8 nodes per cell and axis (the integrand peaks within
    # 0.01 of the light from the closest point)
    x, w = np.polynomial.legendre.leggauss(8)
    panels = cells * 8
    nodes = ((np.arange(panels)[:, None] + 0.5 * (x + 1)) / panels).ravel()
    weights = np.tile(w / (2 * panels), panels)
    ss, tt = np.meshgrid(nodes, nodes, indexing="ij")
    d = CORNER + ss[..., None] * EX + tt[..., None] * EY - p0
    f = np.abs(d[..., 2]) / ((d * d).sum(-1)) ** 1.5 * np.outer(weights, weights) * 0.6
    per = nodes.size // cells
    expected = f.reshape(cells, per, cells, per).sum(axis=(1, 3))
    expected *= count / omega
    assert expected.sum() == pytest.approx(count, rel=1e-6)
    assert_accepted(pearson(observed, expected.ravel()), test_count=4, what=f"rectangle samples from {p0}")


@pytest.mark.parametrize("p0,n", [([0.2, 0.1, 0.7], [0, 0, 1]),          # below, facing it
                                  ([0.45, 0.25, 0.999], [0, 0, 1]),      # very close, near a corner
                                  ([1.5, -2.0, 0.2], [0, 0, 1]),         # off to the side
                                  ([0.3, 0.0, 0.5], [0.3, 0, 0.9539392014169456]),  # tilted receiver
                                  ([0.0, 0.0, 1.0 - 1e-7], [0, 0, 1])])  # touching: E → π L
def test_irradiance_equals_lambert_polygon_formula(p0, n):
    light = emitter(flip=True)
    n = np.asarray(n, np.float64)
    mean, err = irradiance_estimate(light, np.asarray(p0), n)
    want = lambert_irradiance(POLYGON, np.asarray(p0), n)
    assert abs(mean - want) < 4.5 * err + 1e-12 * want, (mean, err, want)


def test_hard_cases_in_plane_behind_two_sided():
    light = emitter(flip=True)
    count = 1000
    u = np.random.default_rng(4).random((3, count))
    for p0 in ([2.0, 0.0, 1.0], [0.1, 0.1, 1.0], [0.1, 0.1, 1.5]):    # in the plane (outside, inside), behind
        p = np.repeat(np.asarray(p0, np.float64)[:, None], count, axis=1)
        wi, dist, scale, pdf, valid = light.sample(p, u)
        assert not valid.any() and np.all(scale == 0) and np.all(pdf == 0)
        assert np.all(np.isfinite(wi)) and np.all(np.isfinite(dist))
    # two-sided: the same irradiance from both sides
    both = emitter(two_sided=True)
    for p0, n in (([0.2, 0.1, 0.7], [0, 0, 1.0]), ([0.2, 0.1, 1.3], [0, 0, -1.0])):
        mean, err = irradiance_estimate(both, np.asarray(p0), np.asarray(n))
        want = lambert_irradiance(POLYGON, np.asarray(p0), np.asarray(n))
        assert abs(mean - want) < 4.5 * err


def test_far_away_falls_back_to_area_sampling_consistently():
    light = emitter(flip=True)
    p0 = np.array([0.0, 0.0, -2000.0])                 # Ω ≈ 0.6/2000² = 1.5e-7 sr < MIN_RECT_SOLID_ANGLE
    assert light.rect.solid_angle(p0[:, None])[0] < MIN_RECT_SOLID_ANGLE
    count = 20_000
    p = np.repeat(p0[:, None], count, axis=1)
    wi, dist, scale, pdf, valid = light.sample(p, np.random.default_rng(5).random((3, count)))
    assert valid.all()
    cos_l = wi[2]
    np.testing.assert_allclose(pdf, dist ** 2 / (cos_l * 0.6), rtol=1e-12)           # the area pdf
    np.testing.assert_allclose(light.pdf_hit(dist, cos_l, p), pdf, rtol=1e-12)
    # irradiance ≈ L·A·cos/d² (the rectangle is nearly a point): 0.6 / 2001²
    mean = np.mean(scale * wi[2])
    assert mean == pytest.approx(0.6 / 2001.0 ** 2, rel=1e-5)


@pytest.mark.parametrize("two_sided", [False, True])
def test_pdf_hit_is_the_pdf_of_next_event_estimation(two_sided):
    # MIS evaluates pdf_hit for BSDF rays that hit the light: it must equal the pdf that sample()
    # returned for the same point, from every kind of position (near, far → area fallback).
    light = emitter(two_sided=two_sided, flip=True)
    rng = np.random.default_rng(6)
    p = np.concatenate([rng.uniform(-2, 2, (3, 3000)) * [[1], [1], [0.5]],
                        np.array([[0.0], [0.0], [-3000.0]]) + rng.uniform(-1, 1, (3, 100))], axis=1)
    wi, dist, scale, pdf, valid = light.sample(p, rng.random((3, p.shape[1])))
    assert valid.any()
    cos_l = light.facing(wi[2])          # −d·n with the front normal n = −z
    np.testing.assert_allclose(light.pdf_hit(dist[valid], cos_l[valid], p[:, valid]), pdf[valid], rtol=1e-12)
    # and without an origin (camera rays) the area pdf
    np.testing.assert_allclose(light.pdf_hit(dist[valid], cos_l[valid]),
                               dist[valid] ** 2 / (cos_l[valid] * 0.6), rtol=1e-12)


def test_rays_that_reach_a_lone_rectangle_lamp_are_weighted_with_the_solid_angle_pdf(monkeypatch):
    """With one rectangle lamp (no light selection, no analytic lamps) the tracer still keeps where
    each segment started, so a BSDF-sampled ray that reaches the lamp is MIS-weighted with 1/Ω, the
    pdf next-event estimation used; without its origin pdf_hit falls back to the area pdf and the two
    weights no longer sum to 1."""
    from engine.render.renderer import Renderer
    from engine.scene.loader import load_scene
    from tests.conftest import shared_path
    scene = load_scene(shared_path("peers", "scenes", "cornell_lambert.json"))
    scene.camera.width = scene.camera.height = 16
    origins = []
    original = AreaEmitter.pdf_hit

    def pdf_hit(self, dist, cos_l, origin=None, *rest):
        origins.append(origin is not None)
        return original(self, dist, cos_l, origin, *rest)

    monkeypatch.setattr(AreaEmitter, "pdf_hit", pdf_hit)
    st = dataclasses.replace(scene.settings, spp=2, threads=1)
    Renderer(scene).render(st)
    assert len(origins) > 1 and all(origins[1:])        # the first call: camera rays (not MIS-weighted)
