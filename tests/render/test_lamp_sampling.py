"""Disk and ellipse lamps sampled through a bilinear warp of the concentric map
(engine.kernels.lamp_sampling, engine.render.lights.EllipseEmitter)."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from engine.kernels.lamp_sampling import (bilinear_warp_pdf, bilinear_warp_sample, concentric_disk,
                                          concentric_disk_inverse, ellipse_lamp_pdf)
from engine.render.lights import AreaEmitter, EllipseEmitter, mesh_emitter
from engine.spectral import RGBIlluminantSpectrum
from tests.support.chi2 import assert_accepted, pearson


def test_concentric_map_round_trip():
    u, v = np.random.default_rng(0).random((2, 20000))
    uu, vv = concentric_disk_inverse(*concentric_disk(u, v))
    assert np.abs(uu - u).max() < 1e-12 and np.abs(vv - v).max() < 1e-12


def test_bilinear_warp_follows_its_pdf():
    """χ² of warped samples against the exact cell masses (a bilinear density's mean over a cell is
    its value at the cell centre), and the returned pdf is ``bilinear_warp_pdf``."""
    n = 200000
    rng = np.random.default_rng(1)
    c = np.array([0.02, 1.0, 0.5, 3.0])[:, None] * np.ones((4, n))
    u, v, pdf = bilinear_warp_sample(c, *rng.random((2, n)))
    assert np.array_equal(pdf, bilinear_warp_pdf(c, u, v))
    k = 16
    counts, _, _ = np.histogram2d(u, v, bins=k, range=[[0, 1], [0, 1]])
    mid = (np.arange(k) + 0.5) / k
    uc, vc = np.meshgrid(mid, mid, indexing="ij")
    expected = bilinear_warp_pdf(c[:, :k * k], uc.ravel(), vc.ravel()).reshape(k, k) / (k * k) * n
    assert_accepted(pearson(counts, expected), what="warped (u, v)")


def disk_lamp(sides=64, sx=1.2, sy=1.2, rotation=0.4):
    """Triangles (as polar_addon.export.lights builds them) of a disk/ellipse lamp facing down-ish."""
    t = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    local = np.vstack(([0.0, 0.0, 0.0], np.stack((0.5 * sx * np.cos(t), 0.5 * sy * np.sin(t), 0 * t), axis=1)))
    faces = np.array([[0, 1 + (i + 1) % sides, 1 + i] for i in range(sides)])
    c, s = math.cos(rotation), math.sin(rotation)
    R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    V = local @ R.T + np.array([-0.5, -0.5, 2.0])
    return V, faces


def compiled_of(V, faces):
    tri = V[faces]
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(cr, axis=1)
    return SimpleNamespace(vertices=V, faces=faces, tri_area=area, tri_normal=cr / (2 * area[:, None]),
                           tri_occluder=np.zeros(len(faces), bool))


@pytest.mark.parametrize("sx,sy", [(1.2, 1.2), (0.6, 0.3)])
def test_ellipse_lamp_matches_area_sampling(sx, sy):
    """The warp-sampled lamp: detected from its fan, its NEE pdf is the one ``pdf_hit`` gives for the
    same point, and its irradiance estimate equals sampling by area (same expectation), with less
    variance."""
    V, faces = disk_lamp(sx=sx, sy=sy)
    compiled = compiled_of(V, faces)
    tris = np.arange(len(faces))
    spectrum = RGBIlluminantSpectrum([1, 1, 1], 1.0)
    lamp = mesh_emitter(spectrum, tris, compiled)
    assert isinstance(lamp, EllipseEmitter)
    area = AreaEmitter(spectrum, tris, compiled)
    rng = np.random.default_rng(2)
    n = 200000
    for q in ([0.3, -1.2, 0.0], [-2.5, 1.0, 0.0], [-0.4, -0.6, 1.5]):
        p = np.repeat(np.array(q, float)[:, None], n, axis=1)
        u = rng.random((3, n))
        wi, dist, scale, pdf, ok = lamp.sample(p, u)
        assert ok.mean() > 0.99
        back = ellipse_lamp_pdf(p[:, ok], p[:, ok] + wi[:, ok] * dist[ok], lamp.centre, lamp.axis_a, lamp.axis_b,
                                lamp.normal)
        assert np.allclose(back, pdf[ok], rtol=1e-9)
        assert np.allclose(lamp.pdf_hit(dist[ok], -wi[:, ok].T @ lamp.normal, p[:, ok], wi[:, ok]), pdf[ok], rtol=1e-9)
        est = scale * np.maximum(wi[2], 0) * ok                 # irradiance on an upward receiver
        wa, _, sa, _, oka = area.sample(p, rng.random((3, n)))
        ref = sa * np.maximum(wa[2], 0) * oka
        err = math.sqrt(est.var() / n + ref.var() / n)
        assert abs(est.mean() - ref.mean()) < 4.5 * err + 1e-12
        assert est.var() < ref.var()


def test_mesh_emitter_keeps_other_meshes():
    quad = compiled_of(np.array([[0, 0, 1.0], [1, 0, 1], [1, 1, 1], [0, 1, 1]]), np.array([[0, 2, 1], [0, 3, 2]]))
    spectrum = RGBIlluminantSpectrum([1, 1, 1], 1.0)
    assert type(mesh_emitter(spectrum, np.arange(2), quad)) is AreaEmitter
    V, faces = disk_lamp()
    assert type(mesh_emitter(spectrum, np.arange(64), compiled_of(V, faces), two_sided=True)) is AreaEmitter
    V[5] += 0.01                                        # not on the ellipse any more
    assert type(mesh_emitter(spectrum, np.arange(64), compiled_of(V, faces))) is AreaEmitter


def test_ellipse_lamp_sample_twins_agree():
    """The compiled ellipse-lamp sampler gives the NumPy twin's bits (registered in kernels.TWINS)."""
    from engine import kernels
    from engine.kernels import lamp_sampling as ls
    pair = kernels.TWINS["kernels.lamp_sampling.ellipse_lamp_sample"]
    if pair.compiled is None:
        pytest.skip("Numba is not available")
    V, faces = disk_lamp(sx=0.6, sy=0.3)
    lamp = mesh_emitter(RGBIlluminantSpectrum([1, 1, 1], 1.0), np.arange(64), compiled_of(V, faces))
    rng = np.random.default_rng(3)
    n = 5000
    p = rng.random((3, n)) * 6 - 3
    p[:, :10] = lamp.centre[:, None]               # on the lamp: invalid, no NaN
    u1, u2 = rng.random((2, n))
    u1[:4], u2[:4] = [0.0, 1.0, 0.5, 0.0], [0.0, 1.0, 0.5, 1.0]
    args = (p, u1, u2, lamp.centre, lamp.axis_a, lamp.axis_b, lamp.normal, lamp.sides, lamp.phase)
    for a, b in zip(pair.compiled(*args), ls.ellipse_lamp_sample_numpy(*args)):
        assert np.array_equal(a, b, equal_nan=True)


def test_spread_rectangle_warp_matches_uniform_solid_angle():
    """A 0.8 m square lamp with a 90° spread (area_spread_ellipse's): the profile-warped spherical
    rectangle has the pdf ``pdf_hit`` gives for the same arrival, the expectation of the unwarped
    sampler and less variance."""
    from engine.render.lights import SpreadRectangleEmitter
    V = np.array([[-0.9, -0.4, 2.2], [-0.9, 0.4, 2.2], [-0.1, 0.4, 2.2], [-0.1, -0.4, 2.2]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])          # normal −Z (down)
    compiled = compiled_of(V, faces)
    assert compiled.tri_normal[0, 2] < 0
    spectrum = RGBIlluminantSpectrum([1, 1, 1], 1.0)
    lamp = mesh_emitter(spectrum, np.arange(2), compiled, spread_deg=90.0)
    assert type(lamp) is SpreadRectangleEmitter and lamp.rect is not None
    plain = AreaEmitter(spectrum, np.arange(2), compiled, spread_deg=90.0)
    rng = np.random.default_rng(4)
    n = 200000
    for q in ([0.3, -1.2, 0.0], [-2.5, 1.0, 0.0], [-0.4, 0.1, 1.5], [1.5, 0.0, 0.3]):
        p = np.repeat(np.array(q, float)[:, None], n, axis=1)
        wi, dist, scale, pdf, ok = lamp.sample(p, rng.random((3, n)))
        back = lamp.pdf_hit(dist[ok], -wi[:, ok].T @ lamp.normal, p[:, ok], wi[:, ok])
        assert np.allclose(back, pdf[ok], rtol=1e-7)
        est = scale * np.maximum(wi[2], 0) * ok
        wa, _, sa, _, oka = plain.sample(p, rng.random((3, n)))
        ref = sa * np.maximum(wa[2], 0) * oka
        err = math.sqrt(est.var() / n + ref.var() / n)
        assert abs(est.mean() - ref.mean()) < 4.5 * err + 1e-12
        assert est.var() <= ref.var() * 1.05
