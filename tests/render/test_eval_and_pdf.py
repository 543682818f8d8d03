"""The real assets' Principled vertices in fewer steps.  A BSDF's value and density at the same directions in one
call (BSDF.eval_and_pdf): next-event estimation against a non-delta light and a mixture's sample ask each component
once for both, and a Torrance–Sparrow facet lobe computes both in one compiled pass
(engine.kernels.torrance_sparrow._eval_pdf_loop).  A normal map's factor on its lobe (the leak rule and the
terminator softening) in one compiled pass (engine.kernels.normal_map).

The route is paired with the chain it replaces (``eval`` then ``pdf``, each through the mixture, normal-map and tint
wrappers): the same image bit for bit for the real assets' material shapes (Principled with a normal map and
textured metallic and roughness, a plain Principled, a Torrance–Sparrow with a diffuse lobe, several of them shaded
together as a MaterialSet) under a sky, lamps and an emitting quad, in several transports; and the compiled pass
against its NumPy twin on crafted directions; the normal map's factor likewise (its NumPy twin as the chain).
"""

import dataclasses

import numpy as np
import pytest

from engine import kernels
from engine.kernels import normal_map as normal_map_kernels
from engine.materials import material_set, mix, normal_map, tinted
from engine.materials import torrance_sparrow as ts
from engine.materials.base import BSDF
from engine.render import precompile
from engine.render.renderer import Renderer
from engine.scene.loader import parse_scene

needs_numba = pytest.mark.skipif(not kernels.COMPILED, reason="compiled kernels not in use")


def _chain_sum_and_pdf(self, sp, points, weights, p, wi, cosine):
    return self._sum(sp, points, weights, wi, cosine), self._pdf(points, p, wi)


def use_chain(monkeypatch):
    """Every eval_and_pdf back to its two calls (BSDF's default), the mixture's too."""
    for cls in (ts.TorranceSparrow, normal_map.ShadingNormal, tinted._ScaledLobes, mix.Mix, material_set.MaterialSet):
        monkeypatch.setattr(cls, "eval_and_pdf", BSDF.eval_and_pdf)
    monkeypatch.setattr(mix.Mix, "_sum_and_pdf", _chain_sum_and_pdf)


def counted(monkeypatch, module, name) -> list:
    """``module.name`` replaced by a wrapper that records each call's arguments in the returned list."""
    calls, fn = [], getattr(module, name)

    def wrapper(*args):
        calls.append(args)
        return fn(*args)
    monkeypatch.setattr(module, name, wrapper)
    return calls


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """Tiles and a floor of each material set (engine.render.precompile's textures) under a sky, lamps and an
    emitting quad."""
    folder = tmp_path_factory.mktemp("eval_and_pdf")
    textured = precompile._textured_materials(precompile._textures(str(folder)))
    plain = precompile.PLAIN_MATERIALS
    sets = {"t_principled": {"t_principled": textured["t_principled"]},
            "principled": {"principled": plain["principled"]},
            "ts_ggx": {"ts_ggx": plain["ts_ggx"]},
            "several": {"t_principled": textured["t_principled"], "ts_ggx": plain["ts_ggx"],
                        "principled": plain["principled"]}}
    out = {}
    for name, materials in sets.items():
        names = list(materials)
        objects = precompile._row(names + ["lambert"], 0.5) + [
            dict(precompile._floor(names[0]), name="floor"),
            {"name": "lamp", "shape": "quad", "material": "lambert",
             "vertices": [[-1, 3, 3], [1, 3, 3], [1, 5, 3], [-1, 5, 3]], "emission": {"radiance": 4}}]
        scene = precompile._scene(dict(materials, lambert={"type": "lambert", "albedo": 0.5}), objects,
                                  [{"type": "environment", "radiance": 0.5}] + precompile.LAMPS, spp=4)
        out[name] = parse_scene(scene, base_dir=str(folder), source=name)
    return out


CASES = [("t_principled", {}), ("t_principled", {"polarisation": "linear", "spectral": "rgb"}),
         ("t_principled", {"polarisation": "off", "spectral": "mono", "light_tree": "on"}),
         ("principled", {}), ("principled", {"spectral": "rgb", "sampler": "sobol"}), ("ts_ggx", {}),
         ("several", {}), ("several", {"spectral": "rgb", "light_tree": "on"})]


@needs_numba
@pytest.mark.parametrize("name, overrides", CASES)
def test_eval_and_pdf_gives_the_chains_image_bit_for_bit(monkeypatch, scenes, name, overrides):
    scene = scenes[name]
    settings = dataclasses.replace(scene.settings, threads=1, **overrides)
    calls = counted(monkeypatch, ts, "torrance_sparrow_eval_pdf")
    route = Renderer(scene).render(settings).stokes()
    assert calls, "the one-pass value and density were not taken"
    use_chain(monkeypatch)
    n = len(calls)
    chain = Renderer(scene).render(settings).stokes()
    assert len(calls) == n
    assert np.array_equal(route, chain, equal_nan=True)


@needs_numba
@pytest.mark.parametrize("overrides", [{}, {"spectral": "rgb"}])
def test_a_material_set_asks_each_member_once_for_value_and_density(monkeypatch, scenes, overrides):
    """A MaterialSet's eval_and_pdf (SpecGlossEmission's 18 rough materials are one): each member's eval_and_pdf, the
    image of its eval then pdf bit for bit."""
    scene = scenes["several"]
    settings = dataclasses.replace(scene.settings, threads=1, **overrides)
    calls = counted(monkeypatch, material_set.MaterialSet, "eval_and_pdf")
    pdfs = counted(monkeypatch, material_set.MaterialSet, "pdf")
    route = Renderer(scene).render(settings).stokes()
    assert calls and not pdfs, "the material set's value and density were not taken in one call"
    monkeypatch.setattr(material_set.MaterialSet, "eval_and_pdf", BSDF.eval_and_pdf)
    chain = Renderer(scene).render(settings).stokes()
    assert pdfs            # (the chain: eval, then pdf)
    assert np.array_equal(route, chain, equal_nan=True)


def _batch(n=4000, seed=3):
    rng = np.random.default_rng(seed)

    def unit(shape):
        v = rng.normal(size=shape)
        return v / np.linalg.norm(v, axis=0)
    n_s, wo, wi = unit((3, n)), unit((3, n)), unit((3, n))
    wo *= np.where((wo * n_s).sum(0) < 0, -1.0, 1.0)[None, :]
    wi[:, 0] = -n_s[:, 0]                                   # below the horizon
    wi[:, 1] = wo[:, 1]                                     # backscatter
    wi[:, 2] = -wo[:, 2]                                    # ω_i + ω_o = 0: no half vector
    wi[:, 3] = np.cross(n_s[:, 3], wo[:, 3]) / np.linalg.norm(np.cross(n_s[:, 3], wo[:, 3]))   # grazing
    return rng, n_s, wo, wi


@needs_numba        # (without Numba the fused pass is its two NumPy parts: nothing to compare)
@pytest.mark.parametrize("distribution, shadowing", [("beckmann", "ts"), ("beckmann", "smith"),
                                                     ("ggx", "smith_correlated")])
@pytest.mark.parametrize("p_kind", ["fresnel", "given"])
@pytest.mark.parametrize("has_diffuse", [False, True])
@pytest.mark.parametrize("per_point", [False, True])
def test_the_one_pass_kernel_matches_its_twin_and_the_two_passes(distribution, shadowing, p_kind, has_diffuse,
                                                                 per_point):
    """The fused pass (its twin where Numba is off) against the eval and pdf twins, bit for bit; with an index per
    wavelength and path (``per_point``: a textured metal's, whose Fresnel values the fused pass takes a block of
    paths at a time: _eval_pdf_rows_loop), real ones among them (abcs_at's other branch)."""
    rng, n_s, wo, wi = _batch()
    n = n_s.shape[1]
    shape = (4, n) if per_point else (4, 1)
    eta = (rng.uniform(0.2, 1.6, shape) + 1j * rng.uniform(0, 3, shape))
    if per_point:
        eta[:, 5:40] = eta[:, 5:40].real
        eta[2, 100] = complex(np.nan, 1.0)
    m = rng.uniform(0.05, 0.6, n)
    s, w_d = 0.9, rng.uniform(0, 1, n)
    p_given = None if p_kind == "fresnel" else np.clip(rng.uniform(size=n), 0.1, 0.9)
    got = ts.torrance_sparrow_eval_pdf(n_s, wo, wi, eta, 4, s, m, shadowing, p_given, eta, s, w_d, has_diffuse,
                                       distribution)
    want = ts.torrance_sparrow_eval(n_s, wo, wi, eta, 4, s, m, shadowing, distribution) + (
        ts.torrance_sparrow_pdf(n_s, wo, wi, m, p_given, eta, 4, s, w_d, True, has_diffuse, distribution),)
    for g, w in zip(got, want):
        assert g.shape == w.shape and np.array_equal(g, w, equal_nan=True)
    twin = ts.torrance_sparrow_eval_pdf_numpy(n_s, wo, wi, eta, 4, s, m, shadowing, p_given, eta, s, w_d,
                                              has_diffuse, distribution)
    for g, w in zip(got, twin):
        assert np.allclose(g, w, rtol=1e-12, atol=0, equal_nan=True)
    assert 0 < want[6].astype(bool).sum() < n


@needs_numba
@pytest.mark.parametrize("name, overrides", [("t_principled", {}), ("several", {"spectral": "rgb"})])
def test_the_compiled_normal_factor_gives_the_chains_image_bit_for_bit(monkeypatch, scenes, name, overrides):
    scene = scenes[name]
    settings = dataclasses.replace(scene.settings, threads=1, **overrides)
    calls = counted(monkeypatch, normal_map_kernels, "_normal_factor_loop")
    route = Renderer(scene).render(settings).stokes()
    assert {args[4] for args in calls} == {True, False}, "the compiled factor did not run for both lobe kinds"
    monkeypatch.setattr(normal_map, "normal_factor", normal_map.normal_factor_numpy)
    chain = Renderer(scene).render(settings).stokes()
    assert np.array_equal(route, chain, equal_nan=True)


@needs_numba        # (without Numba normal_factor is the twin itself)
@pytest.mark.parametrize("soften", [False, True])
def test_the_normal_factor_matches_its_twin(soften):
    """Crafted normals: N = N_s (cosθ_d = 1), ω_i ⟂ N_s, ω_i = N_s, opposite sides, a NaN, a tilted map."""
    rng, n, _, wi = _batch(2000, seed=11)
    n_g = n.copy()
    tilt = rng.normal(scale=0.4, size=n.shape)
    mapped = (n + tilt) / np.linalg.norm(n + tilt, axis=0)
    n_smooth = n.copy()
    mapped[:, 10] = n_smooth[:, 10]                         # cosθ_d = 1
    wi[:, 11] = np.cross(n_smooth[:, 11], mapped[:, 11])
    wi[:, 11] /= np.linalg.norm(wi[:, 11])                  # cosθ_i = 0
    wi[:, 12] = n_smooth[:, 12]                             # cosθ_i = 1
    wi[:, 13] = -n_g[:, 13]                                 # below the surface
    wi[:, 14] = np.nan
    got = normal_map.normal_factor(n_g, mapped, wi, n_smooth, soften)
    want = normal_map.normal_factor_numpy(n_g, mapped, wi, n_smooth, soften)
    assert np.array_equal(got, want, equal_nan=True)
    assert 0 < np.count_nonzero(want == 0) < len(want)
    if soften:          # (the side rule alone gives 0 at a NaN direction, the softening NaN)
        assert np.count_nonzero((want > 0) & (want < 1)) > 100 and np.isnan(want[14])
    else:
        assert want[14] == 0
