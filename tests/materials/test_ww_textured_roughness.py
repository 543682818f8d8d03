"""A Weidlich–Wilkie coat whose Beckmann roughness m varies over the surface (a texture).

Oracles: the constant-m model (texels whose value is a node of the coat's E_top(θ, η, m) table give
it to ~1e-12; between nodes the table errs by ≤ 2e-3 against the exact constant-m quadrature
``top_albedo``), the Mueller realisability checks, the energy bound, and Pearson's χ² of the
sampler against pdf().
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.materials.base import ShadingPoint
from engine.materials.microfacet import Beckmann
from engine.materials.weidlich_wilkie import COAT, Coat, WeidlichWilkie, _RoughnessAlbedoTable, top_albedo
from engine.polarisation.mueller import realisability_report
from engine.scene.loader import parse_material
from engine.spectral import WavelengthLookup
from engine.spectral.spectrum import TabulatedSpectrum
from tests.support import chi2
from tests.scene.test_textures import _points_at, _shading_points, _texture_file

M_TEXELS = np.array([[0.1, 0.4], [0.17, 0.25]])     # bottom row 0.17, 0.25 (between nodes); top row the ends
#: texel (column i, row j from the bottom) of each block of points in _uv()
TEXELS = ((0, 0), (1, 0), (0, 1), (1, 1))
LAMBERT = {"type": "lambert", "albedo": [0.7, 0.4, 0.2]}
TS_BASE = {"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": 0.3, "diffuse_albedo": [0.2, 0.3, 0.1],
           "diffuse_weight": 0.5}


#: a dispersive coat index (per-wavelength lanes)
DISPERSIVE = TabulatedSpectrum([360.0, 830.0], [1.6, 1.4])


def _material(tmp_path, m, base=LAMBERT, n=1.5, form="energy"):
    """The layered model with coat roughness ``m``: a number or a texture object (read through the
    coat's declaration: range-checked, a TexturedNumber)."""
    if isinstance(m, dict):
        m = COAT["m"].read(m, "materials.w.coats[0].m", base_dir=str(tmp_path))
    return WeidlichWilkie(Coat(n=n, thickness=0.5, absorption=0.3, distribution="beckmann", m=m),
                          parse_material(base, "materials.w.base"), form=form)


def _scene_material(tmp_path, m):
    return parse_material({"type": "weidlich_wilkie", "coats": [{"n": 1.5, "distribution": "beckmann", "m": m}]},
                          "materials.w", base_dir=str(tmp_path))


def _textured(tmp_path, **kw):
    _texture_file(tmp_path, M_TEXELS, "m.exr")
    return _material(tmp_path, {"texture": "m.exr", "interpolation": "Closest"}, **kw)


def _uv(reps):
    return np.repeat(np.array([[0.25, 0.75, 0.25, 0.75], [0.25, 0.25, 0.75, 0.75]]), reps, axis=1)


def _texel_value(i, j):
    return float(np.float32(M_TEXELS[M_TEXELS.shape[0] - 1 - j, i]))


def _batch(reps, seed, lam=None):
    rng = np.random.default_rng(seed)
    n = 4 * reps
    sp = _shading_points(n, rng, _points_at(_uv(reps)), lam)
    wi = rng.normal(size=(3, n))
    wi[2] = np.abs(wi[2])
    wi /= np.linalg.norm(wi, axis=0)
    return sp, wi, rng


@pytest.mark.parametrize("base,n,form", [(LAMBERT, 1.5, "energy"), (TS_BASE, 1.5, "energy"),
                                         (LAMBERT, DISPERSIVE, "energy"), (TS_BASE, 1.5, "published")])
def test_textured_m_is_the_constant_model_at_node_texels_and_close_between(tmp_path, base, n, form):
    """The texture's least and greatest values are table nodes: there eval, pdf and sample equal the
    constant model's to ~1e-12 (dispersive coat: per-wavelength lanes). Between nodes only the
    albedo table differs (≤ 2e-3 in E_top): values within a few 1e-3 of the constant model's."""
    mat = _textured(tmp_path, base=base, n=n, form=form)
    assert mat.varies_over_surface
    table = mat.albedo_table()
    assert table.m[0] == np.float32(0.1) and table.m[-1] == np.float32(0.4)
    reps = 12
    sp, wi, rng = _batch(reps, 5)
    u_lobe, u_dir = rng.uniform(size=4 * reps), rng.uniform(size=(2, 4 * reps))
    f = mat.eval(sp, wi).matrix()
    pdf = mat.pdf(sp, wi)
    smp = mat.sample(sp, u_lobe, u_dir)
    for t, (i, j) in enumerate(TEXELS):
        sel = np.arange(t * reps, (t + 1) * reps)
        m = _texel_value(i, j)
        const = _material(tmp_path, m, base=base, n=n, form=form)
        sub = sp.take(sel)
        sub.surface = None
        fc = const.eval(sub, wi[:, sel]).matrix()
        pc = const.pdf(sub, wi[:, sel])
        at_node = m in (table.m[0], table.m[-1])
        if at_node or form == "published":      # the published form uses no albedo table
            np.testing.assert_allclose(f[..., sel], fc, rtol=1e-12, atol=1e-12 * np.abs(fc).max())
            if at_node:
                np.testing.assert_allclose(pdf[sel], pc, rtol=1e-12, atol=0)
                cs = const.sample(sub, u_lobe[sel], u_dir[:, sel])
                np.testing.assert_allclose(smp.wi[:, sel], cs.wi, rtol=0, atol=1e-13)
                w, wc = smp.weight.matrix()[..., sel], cs.weight.matrix()
                np.testing.assert_allclose(w, wc, rtol=1e-12, atol=1e-12 * np.abs(wc).max())
        else:
            assert not np.any(np.isin(m, table.m))
            # E_top enters t_in, t_out (·f_layer) and c_ms: a relative change of a few ΔE
            assert np.max(np.abs(f[..., sel] - fc)) <= 1e-2 * np.abs(fc).max()
            # the coat lobe itself (D, G per point) is exact: compare where the layer term is absent
            np.testing.assert_allclose(pdf[sel], pc, rtol=1e-2)


def test_the_roughness_table_is_exact_at_nodes_and_within_2e_3_between():
    """Against top_albedo (the exact constant-m quadrature) at every node and at the midpoints (in ln m)
    between nodes: θ on the table's 1° grid, η a node of the η grid (a dispersive coat) and between."""
    table = _RoughnessAlbedoTable("ts", 1.3, 1.7, 0.05, 0.5)
    assert np.all(np.diff(np.log(table.m)) <= 0.2 + 1e-12) and table.m[0] == 0.05 and table.m[-1] == 0.5
    mu = np.cos(np.radians(np.arange(0.0, 90.5, 1.0)))
    etas = table.tables[0].eta
    # nodes: the η grid's ends and middle × every third m and the last (each exact check costs what
    # building that node cost: all 78 took 10 s and tested the same code path)
    for eta in (etas[0], etas[len(etas) // 2], etas[-1]):
        for m in (*table.m[::3], table.m[-1]):
            exact = np.clip(top_albedo(mu, eta, Beckmann(m), "ts"), 0.0, 1.0)
            np.testing.assert_allclose(table(mu, eta, m), exact, rtol=0, atol=1e-12)
    worst = 0.0
    for eta in (1.3, 1.5):
        for a, b in zip(table.m[:-1], table.m[1:]):
            m = math.sqrt(a * b)
            exact = np.clip(top_albedo(mu, eta, Beckmann(m), "ts"), 0.0, 1.0)
            worst = max(worst, float(np.max(np.abs(table(mu, eta, m) - exact))))
    assert worst <= 2e-3, worst


def test_textured_m_is_realisable_and_conserves_energy(tmp_path):
    """White non-absorbing Lambert base: the exact model reflects exactly 1; with the interpolated
    E_top the albedo stays ≤ 1 + the table's error (2e-3) + the Monte-Carlo error."""
    _texture_file(tmp_path, M_TEXELS, "m.exr")
    m = COAT["m"].read({"texture": "m.exr", "interpolation": "Closest"}, "m", base_dir=str(tmp_path))
    mat = WeidlichWilkie(Coat(n=1.5, distribution="beckmann", m=m), parse_material({"type": "lambert", "albedo": 1.0},
                                                                                    "base"))
    sp, wi, _ = _batch(50, 8)
    rep = realisability_report(mat.eval(sp, wi).matrix(), tol=1e-9)
    for key, ok in rep.items():
        assert np.all(ok), key
    n = 100_000
    rng = np.random.default_rng(2)
    for theta in (0.0, 60.0, 85.0):
        for i, j in TEXELS:
            uv = np.tile([[0.25 + 0.5 * i], [0.25 + 0.5 * j]], (1, n))
            wo = np.tile([[math.sin(math.radians(theta))], [0.0], [math.cos(math.radians(theta))]], (1, n))
            lam = np.full((1, n), 550.0)
            nrm = np.tile([[0.0], [0.0], [1.0]], (1, n))
            sp = ShadingPoint(np.zeros((3, n)), nrm, nrm, wo, lam, True, WavelengthLookup(lam), None,
                              _points_at(uv))
            s = mat.sample(sp, rng.random(n), rng.random((2, n)))
            w = s.weight.matrix()[0, 0, 0]
            albedo, err = w.mean(), w.std() / math.sqrt(n)
            assert albedo <= 1.0 + 2e-3 + 4.0 * err, (theta, i, j, albedo, err)


@pytest.mark.parametrize("theta_o,base", [(35.0, LAMBERT), (70.0, TS_BASE)])
def test_sampling_with_a_textured_m_matches_pdf_chi_square(tmp_path, theta_o, base):
    """Samples at a texel between nodes (m = 0.17) against pdf() at the same surface point."""
    mat = _textured(tmp_path, base=base)
    uv_pt = np.array([[0.25], [0.25]])          # bottom-left texel, m = 0.17
    wo = np.array([[math.sin(math.radians(theta_o)) * math.cos(0.6)],
                   [math.sin(math.radians(theta_o)) * math.sin(0.6)], [math.cos(math.radians(theta_o))]])

    def point(k):
        nrm = np.tile([[0.0], [0.0], [1.0]], (1, k))
        lam = np.tile([[450.0], [550.0], [650.0]], (1, k))
        return ShadingPoint(np.zeros((3, k)), nrm, nrm, np.tile(wo, (1, k)), lam, False, WavelengthLookup(lam), None,
                            _points_at(np.tile(uv_pt, (1, k))))
    n = 200_000
    rng = np.random.default_rng(11)
    bs = mat.sample(point(n), rng.random(n), rng.random((2, n)))
    nd = bs.valid & ~bs.is_delta
    k = 2000
    wi = bs.wi[:, nd][:, :k]
    np.testing.assert_allclose(bs.pdf[nd][:k], mat.pdf(point(wi.shape[1]), wi), rtol=1e-12)
    result = chi2.direction_sampler_test(bs.wi, nd, lambda d: mat.pdf(point(d.shape[1]), d), n_cos=20, n_phi=40,
                                         order=6)
    chi2.assert_accepted(result, test_count=2, what="textured-m Weidlich–Wilkie samples")


def test_the_loader_checks_a_textured_coat_roughness(tmp_path):
    _texture_file(tmp_path, np.array([[0.0, 0.3]]), "low.exr")
    with pytest.raises(SceneError, match=r"materials\.w\.coats\[0\]\.m: .*\[0\.0001"):
        _scene_material(tmp_path, {"texture": "low.exr"})
    mat = _scene_material(tmp_path, {"texture": "low.exr", "offset": 0.05})     # m in [0.05, 0.35]
    assert mat.coat.textured_m and mat.describe()["coat"]["m"].startswith("TexturedNumber")
    with pytest.raises(SceneError, match=r"materials\.w\.coats\[0\]\.exponent: a texture on this parameter"):
        parse_material({"type": "weidlich_wilkie", "coats": [{"distribution": "blinn",
                                                              "exponent": {"texture": "low.exr", "offset": 10.0}}]},
                       "materials.w", base_dir=str(tmp_path))


@pytest.mark.blender
def test_blender_coat_roughness_socket_takes_a_texture(tmp_path):
    """A Polarising BSDF (Weidlich–Wilkie) node with an image on Coat Roughness exports a textured
    Beckmann m; at the texels that are table nodes (the image's least and greatest values) the
    material equals the exporter's own conversion of that constant Coat Roughness to ~1e-12."""
    bpy = pytest.importorskip("bpy")
    from tests.blender_support import polar_material
    from tests.blender.test_texture_export import _export, _image_node, _texel_points, base_scene
    values = np.array([[0.1, 0.4], [0.2, 0.3]])           # file rows top first: row 0 (bottom) = 0.2, 0.3
    _texture_file(tmp_path, values, "m.exr")
    bpy.ops.wm.read_homefile(use_empty=True)
    mat = polar_material("Coated", "WEIDLICH_WILKIE")
    node = next(nd for nd in mat.node_tree.nodes if getattr(nd, "model", None) == "WEIDLICH_WILKIE")
    tex = _image_node(mat, str(tmp_path / "m.exr"), "Non-Color")
    mat.node_tree.links.new(tex.outputs["Color"], node.inputs["Coat Roughness"])
    scene = base_scene(mat)
    exported, warnings = _export(scene)
    assert warnings == []
    plane = next(m for m in exported.meshes if m.name.startswith("Plane"))
    bsdf = exported.materials[plane.materials[0]]
    assert bsdf.varies_over_surface and bsdf.coat.textured_m
    sp, row, col, wi = _texel_points(2, 2)
    f = bsdf.eval(sp, wi).matrix()
    mat.node_tree.links.remove(node.inputs["Coat Roughness"].links[0])
    for j, i in ((1, 0), (1, 1)):                           # the top row: 0.1 and 0.4, the table's ends
        sel = np.nonzero((row == j) & (col == i))[0]
        node.inputs["Coat Roughness"].default_value = float(np.float32(values[1 - j, i]))
        const = _export(scene)[0].materials[plane.materials[0]]
        assert not const.varies_over_surface
        sub = sp.take(sel)
        sub.surface = None
        fc = const.eval(sub, wi[:, sel]).matrix()
        np.testing.assert_allclose(f[..., sel], fc, rtol=1e-12, atol=1e-12 * np.abs(fc).max())
