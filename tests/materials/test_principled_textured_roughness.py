"""A Principled Roughness texture reaching every lobe (issue 33): the transmission and the anisotropy.

Transmission: the rough dielectric's α = r² per point.  At each texel the textured lobe is the constant-roughness
lobe of that texel's value (eval, pdf, sample, to 1e-12), with Cycles' Multiscatter GGX compensation too where the
texel lies on the compensation table's roughness nodes (between them it interpolates those per-α tables bilinearly
in √α); the compiled passes read α per path and give the NumPy references' bits.  Anisotropy: α_x, α_y per point
from r² and the Anisotropic.
"""

from __future__ import annotations

import numpy as np
import pytest

from engine import kernels

GLASS = {"type": "principled", "transmission": 1.0, "ior": 1.45, "base_color": [0.9, 0.7, 0.5]}


def _both_hemispheres(wi, rng):
    """wi (3, N) with about half its directions mirrored below the surface (refraction)."""
    flip = rng.uniform(size=wi.shape[1]) < 0.5
    out = wi.copy()
    out[2] = np.where(flip, -out[2], out[2])
    return out


def _matrix(value):
    return value.matrix()


@pytest.mark.parametrize("distribution, texels", [
    ("ggx", [0.05, 0.3, 0.62, 1.0]),
    ("multi_ggx", [0.25, 0.5, 0.75]),           # on the compensation table's nodes r = j/32: exact there too
])
def test_textured_roughness_reaches_the_transmission(tmp_path, distribution, texels):
    from engine.materials.rough_dielectric import RoughDielectric
    from tests.support.texel_rows import textured_and_constant
    base = {**GLASS, "distribution": distribution}
    sp, wi, u_lobe, u_dir, textured, rows = textured_and_constant(tmp_path, base, "roughness", texels, reps=40,
                                                                  seed=5)
    wi = _both_hemispheres(wi, np.random.default_rng(9))
    assert textured.varies_over_surface
    glass = textured.base if hasattr(textured, "base") else textured
    assert isinstance(glass, RoughDielectric) and glass.per_point
    f, pdf, s = _matrix(textured.eval(sp, wi)), textured.pdf(sp, wi), textured.sample(sp, u_lobe, u_dir)
    assert (wi[2] < 0).any() and (s.wi[2] < 0).any()
    for sel, _, const, sub in rows:
        np.testing.assert_allclose(f[..., sel], _matrix(const.eval(sub, wi[:, sel])), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(pdf[sel], const.pdf(sub, wi[:, sel]), rtol=1e-12, atol=1e-14)
        cs = const.sample(sub, u_lobe[sel], u_dir[:, sel])
        np.testing.assert_allclose(s.wi[:, sel], cs.wi, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(s.pdf[sel], cs.pdf, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(_matrix(s.weight)[..., sel], _matrix(cs.weight), rtol=1e-12, atol=1e-14)


def test_compensation_between_nodes_is_close_to_the_constant_lobe(tmp_path):
    """Between the roughness nodes the compensation is the bilinear interpolation of the per-α tables: within
    a few 1e-3 of the constant lobe's own table (Cycles interpolates a 16³ table)."""
    from tests.support.texel_rows import textured_and_constant
    sp, wi, _, _, textured, rows = textured_and_constant(tmp_path, {**GLASS, "distribution": "multi_ggx"},
                                                         "roughness", [0.13, 0.41, 0.87], reps=40, seed=6)
    wi = _both_hemispheres(wi, np.random.default_rng(10))
    f = _matrix(textured.eval(sp, wi))
    for sel, _, const, sub in rows:
        want = _matrix(const.eval(sub, wi[:, sel]))
        scale = np.max(np.abs(want[0, 0]))
        assert np.max(np.abs(f[0, 0][..., sel] - want[0, 0])) <= 5e-3 * scale


@pytest.mark.skipif(kernels._numba is None, reason="numba is not installed (NumPy kernels only)")
def test_per_path_alpha_twins_bitwise():
    """The compiled eval, pdf and sample with α per path give the NumPy references' bits, and each path the
    values of the constant-α pass at its own α (viewers on both sides)."""
    from engine.materials import rough_dielectric as rd
    rng = np.random.default_rng(4)
    n = 600
    n_s = rng.normal(size=(3, n))
    n_s /= np.linalg.norm(n_s, axis=0)
    wo, wi = rng.normal(size=(3, n)), rng.normal(size=(3, n))
    wo /= np.linalg.norm(wo, axis=0)
    wi /= np.linalg.norm(wi, axis=0)
    alpha = rng.uniform(1e-3, 1.0, n)
    u_lobe, u_dir = rng.uniform(size=n), rng.uniform(size=(2, n))
    for distribution in ("ggx", "beckmann"):
        args = (1.5, 1.0, distribution)
        pairs = [(rd.rough_dielectric_eval_numba(n_s, wo, wi, 2, *args, False, alpha),
                  rd.rough_dielectric_eval_numpy(n_s, wo, wi, 2, *args, False, alpha)),
                 ([rd.rough_dielectric_pdf_numba(n_s, wo, wi, *args, alpha)],
                  [rd.rough_dielectric_pdf_numpy(n_s, wo, wi, *args, alpha)]),
                 (rd.rough_dielectric_sample_numba(n_s, wo, u_lobe, u_dir, 1, *args, False, alpha),
                  rd.rough_dielectric_sample_numpy(n_s, wo, u_lobe, u_dir, 1, *args, False, alpha))]
        for got, want in pairs:
            for g, w in zip(got, want):
                np.testing.assert_array_equal(g, w)
        for i in (0, 17, 300):
            one = rd.rough_dielectric_eval_numba(n_s[:, i:i + 1], wo[:, i:i + 1], wi[:, i:i + 1], 2, *args, False,
                                                 float(alpha[i]))
            for g, w in zip(one, pairs[0][0]):
                np.testing.assert_array_equal(g[..., 0], w[..., i])


@pytest.mark.parametrize("base", [
    {"type": "principled", "metallic": 1.0, "anisotropic": 0.7, "base_color": [0.9, 0.7, 0.5]},
    {"type": "principled", "anisotropic": 1.0, "base_color": [0.6, 0.2, 0.1], "distribution": "ggx"},
])
def test_textured_roughness_keeps_the_anisotropy(tmp_path, base):
    """A Roughness texture under a constant Anisotropic: at each texel the anisotropic lobe of that roughness
    (Cycles' α_x = r²/aspect, α_y = r²·aspect per point), not an isotropic one."""
    from engine.materials.anisotropic_ggx import AnisotropicGGX
    from tests.support.texel_rows import textured_and_constant
    sp, wi, u_lobe, u_dir, textured, rows = textured_and_constant(tmp_path, base, "roughness", [0.2, 0.5, 0.9],
                                                                  reps=30, seed=7)

    def lobes(model):
        found, stack = [], [model]
        while stack:
            m = stack.pop()
            found += [m] if isinstance(m, AnisotropicGGX) else []
            stack += list(getattr(m, "components", [])) + [getattr(m, "base", None)] * hasattr(m, "base")
            stack = [c for c in stack if c is not None]
        return found
    assert any(lobe.per_point for lobe in lobes(textured))
    f, pdf, s = _matrix(textured.eval(sp, wi)), textured.pdf(sp, wi), textured.sample(sp, u_lobe, u_dir)
    for sel, _, const, sub in rows:
        assert lobes(const) and not any(lobe.isotropic for lobe in lobes(const))
        np.testing.assert_allclose(f[..., sel], _matrix(const.eval(sub, wi[:, sel])), rtol=1e-9, atol=1e-13)
        np.testing.assert_allclose(pdf[sel], const.pdf(sub, wi[:, sel]), rtol=1e-9, atol=1e-13)
        cs = const.sample(sub, u_lobe[sel], u_dir[:, sel])
        np.testing.assert_allclose(s.wi[:, sel], cs.wi, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(_matrix(s.weight)[..., sel], _matrix(cs.weight), rtol=1e-9, atol=1e-13)


TINT = [1.0, 0.5, 0.2]


@pytest.mark.parametrize("base, key, texels", [
    ({"specular_tint": TINT, "roughness": 0.3}, "specular_ior_level", [0.1, 0.5, 0.9]),
    ({"specular_tint": TINT, "roughness": 0.3}, "ior", [1.2, 1.6, 2.2]),
    ({"anisotropic": 0.7, "roughness": 0.35}, "ior", [1.2, 1.6, 2.2]),
    ({"anisotropic": 0.7, "roughness": 0.35, "specular_tint": TINT}, "specular_ior_level", [0.1, 0.5, 0.9]),
])
@pytest.mark.parametrize("colour", [0.0, [0.6, 0.3, 0.2]])
def test_per_point_index_with_a_tint_or_an_anisotropy(tmp_path, base, key, texels, colour):
    """A per-point IOR or Specular IOR Level beside a Specular Tint or an anisotropy: at each texel the specular
    layer of that constant value (a black base: to 1e-9); over a coloured base the layering albedo comes from the
    index tables (IndexAlbedoTables, within 2e-3 of the constant index's table)."""
    from tests.support.texel_rows import textured_and_constant
    material = {"type": "principled", "base_color": colour, **base}
    sp, wi, u_lobe, u_dir, textured, rows = textured_and_constant(tmp_path, material, key, texels, reps=30, seed=8)
    assert textured.varies_over_surface
    f, pdf = _matrix(textured.eval(sp, wi)), textured.pdf(sp, wi)
    black = colour == 0.0
    for sel, _, const, sub in rows:
        want = _matrix(const.eval(sub, wi[:, sel]))
        # the pdf's lobe choice reads the layering albedo too, the specular layer's as its sample weight (Cycles'):
        # the index tables' E within 2e-3 (1.15e-3 at most here: a black base, anisotropic, IOR 2.2)
        np.testing.assert_allclose(pdf[sel], const.pdf(sub, wi[:, sel]), rtol=2e-3)
        if black:
            np.testing.assert_allclose(f[..., sel], want, rtol=1e-9, atol=1e-13)
        else:
            assert np.max(np.abs(f[0, 0][..., sel] - want[0, 0])) <= 5e-3 * np.max(np.abs(want[0, 0]))
