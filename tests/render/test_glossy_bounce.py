"""Next-event estimation and the BSDF sample at rough conductors in compiled steps (engine.kernels.glossy_bounce)
against their twin, the integrator's NumPy chain (PathTracer._next_event then add_to_paths; _sample_bsdf,
scatter_throughput and _store_sample).

The compiled route must leave every image bit for bit as the chain makes it, in every transport (full, linear
and scalar Stokes; spectral, RGB, mono; a wavelength-dependent metal; several lights with delta lamps and the
light tree; a textured roughness), while casting only the shadow rays whose answer can change
the radiance.  Edge inputs (a direction in the shading plane, below the horizon, an infinite or NaN weight, a
light none of whose samples counts) are paired directly.
"""

import dataclasses
import os

import numpy as np
import pytest

from engine import kernels
from engine.render import integrator
from engine.render import precompile
from engine.render.renderer import Renderer
from engine.scene.loader import load_scene, parse_scene

needs_numba = pytest.mark.skipif(not integrator.GLOSSY_BOUNCE, reason="compiled kernels not in use")

PEERS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "..", "shared",
                     "peers", "scenes")


#: One rough conductor per scene (several would be shaded together as a MaterialSet, which takes the chain).
METALS = {"cu": {"type": "torrance_sparrow", "metal": "Cu", "m": 0.3},
          "nk_smith": {"type": "torrance_sparrow", "n": 0.47, "k": 2.4, "m": 0.2, "shadowing": "smith"},
          "ggx": {"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": 0.4, "distribution": "ggx"},
          "textured": {"type": "torrance_sparrow", "metal": "Au",
                       "m": {"texture": "grey.png", "color_space": "Non-Color", "scale": 0.4, "offset": 0.05}}}


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """Per METALS entry: tiles and a floor of it under a sky, lamps and an emitting quad (engine.render.precompile's
    scenes write the texture)."""
    folder = tmp_path_factory.mktemp("glossy_bounce")
    precompile.scenes(str(folder))
    out = {}
    for name, metal in METALS.items():
        objects = precompile._row(["metal", "lambert", "metal"], 0.5) + [
            precompile._floor("metal"),
            {"name": "lamp", "shape": "quad", "material": "lambert",
             "vertices": [[-1, 3, 3], [1, 3, 3], [1, 5, 3], [-1, 5, 3]], "emission": {"radiance": 4}}]
        objects[2]["name"] = "metal2"
        scene = precompile._scene({"metal": metal, "lambert": {"type": "lambert", "albedo": 0.5}}, objects,
                                  [{"type": "environment", "radiance": 0.5}] + precompile.LAMPS, spp=4)
        out[name] = parse_scene(scene, base_dir=str(folder), source=name)
    # the metal alone (one material group: its sample's arrays become the next segments, _new_scattered)
    alone = precompile._scene({"metal": METALS["cu"]}, precompile._row(["metal"], 0.5) + [precompile._floor("metal")],
                              [{"type": "environment", "radiance": 0.5}, precompile.LAMPS[0]], spp=4)
    out["alone"] = parse_scene(alone, base_dir=str(folder), source="alone")
    return out


def render_both(monkeypatch, scene, **overrides):
    """(compiled route's Stokes image, the chain's, the compiled route's calls, shadow rays of each)."""
    calls = []
    for name in ("light_terms_loop", "sample_update_loop"):
        kernel = getattr(integrator, name)

        def counted(*args, kernel=kernel, name=name):
            calls.append(name)
            return kernel(*args)
        monkeypatch.setattr(integrator, name, counted)
    settings = dataclasses.replace(scene.settings, threads=1, **overrides)
    images, rays = [], []
    for on in (True, False):
        monkeypatch.setattr(integrator, "GLOSSY_BOUNCE", on)
        result = Renderer(scene).render(settings)
        images.append(result.stokes())
        rays.append(result.stats["shadow_rays"])
    return images[0], images[1], calls, rays


CASES = [("cu", {}), ("cu", {"polarisation": "linear", "spectral": "rgb", "sampler": "independent"}),
         ("cu", {"polarisation": "off", "spectral": "mono", "sampler": "stratified"}),
         ("cu", {"light_tree": "on"}), ("nk_smith", {}), ("nk_smith", {"reduce_spectral": "off"}),
         ("ggx", {"polarisation": "linear"}),
         ("textured", {}), ("textured", {"spectral": "rgb", "polarisation": "off"}), ("alone", {}),
         ("alone", {"polarisation": "linear", "spectral": "rgb"})]


@needs_numba
@pytest.mark.parametrize("name, overrides", CASES)
def test_the_compiled_route_gives_the_chains_image_bit_for_bit(monkeypatch, scenes, name, overrides):
    fused, chain, calls, rays = render_both(monkeypatch, scenes[name], **overrides)
    assert set(calls) == {"light_terms_loop", "sample_update_loop"}, "the compiled steps were not taken"
    assert np.array_equal(fused, chain, equal_nan=True)
    assert rays[0] <= rays[1]


@needs_numba
@pytest.mark.skipif(not os.path.exists(os.path.join(PEERS, "rough_sphere_a030.json")), reason="no peer scenes")
def test_rough_sphere_casts_only_the_shadow_rays_that_count(monkeypatch):
    scene = load_scene(os.path.join(PEERS, "rough_sphere_a030.json"))
    scene.camera.width = scene.camera.height = 24
    fused, chain, calls, rays = render_both(monkeypatch, scene, spp=4, seed=5)
    assert set(calls) == {"light_terms_loop", "sample_update_loop"} and np.array_equal(fused, chain)
    assert rays[0] < 0.75 * rays[1]           # a uniform sky's samples below the horizon cast none


@needs_numba
def test_edge_samples_pair_with_the_chain(monkeypatch, scenes):
    """Light samples crafted at the edges: each route adds the same bits to the radiance."""
    scene = scenes["cu"]
    renderer = Renderer(scene)
    settings = dataclasses.replace(scene.settings, threads=1)
    plan = renderer.plan(settings)
    tracer = renderer.tracer(plan)
    ts = next(m for m in tracer.materials if type(m).__name__ == "TorranceSparrow" and m.lobe_kernel_inputs)
    rng = np.random.default_rng(7)
    n, P = 64, tracer.P
    from engine.materials.base import ShadingPoint
    from engine.spectral import WavelengthLookup
    n_s = rng.normal(size=(3, n))
    n_s /= np.linalg.norm(n_s, axis=0)
    wo = rng.normal(size=(3, n))
    wo /= np.linalg.norm(wo, axis=0)
    wo *= np.sign((wo * n_s).sum(0))
    lam = rng.uniform(400, 700, (4, n))
    lk = WavelengthLookup(lam)
    sp = ShadingPoint(rng.normal(size=(3, n)), n_s, n_s.copy(), wo, lam, False, lk, None, None)
    wi = rng.normal(size=(3, n))
    wi /= np.linalg.norm(wi, axis=0)
    wi[:, 0] = np.cross(n_s[:, 0], wo[:, 0]) / np.linalg.norm(np.cross(n_s[:, 0], wo[:, 0]))   # in the shading plane
    wi[:, 1] = -n_s[:, 1]                                   # below the horizon
    wi[:, 2] = wo[:, 2]                                     # backscatter
    scale = np.full(n, 2.0)
    scale[3] = np.inf                                       # an infinite weight
    pdf_l = rng.uniform(0.1, 2.0, n)
    pdf_l[4] = np.nan
    ok = rng.random(n) > 0.2
    delta = rng.random(n) > 0.7
    owners = [(0, np.arange(0, 30)), (1, np.arange(30, 40)), (2, np.arange(40, n))]
    ok[30:40] = False                                       # a light none of whose samples counts
    scale[35] = np.inf

    def samples():
        return integrator._LightSamples(wi=wi.copy(), dist=np.full(n, np.inf), scale=scale.copy(),
                                        pdf_l=pdf_l.copy(), ok=ok.copy(), delta=delta.copy(),
                                        emitted=rng_emitted.copy(), select_prob=np.full(n, 0.5), owners=owners,
                                        points={})
    rng_emitted = rng.uniform(0.5, 2.0, (4, n))
    monkeypatch.setattr(tracer, "_sample_lights", lambda *a, **k: samples())
    monkeypatch.setattr(tracer.scene, "occluded", lambda o, d, t: d[0] > 0.3)      # a ray's own answer
    T = rng.normal(size=(P, P, 4, n))
    x_T = np.cross(wo.T, rng.normal(size=(n, 3))).T
    x_T /= np.linalg.norm(x_T, axis=0)
    rows = np.arange(n)
    path = rng.permutation(n)
    chain = np.zeros((P, 4, n))
    stats = {"shadow_rays": 0}
    contrib = tracer._next_event(sp, lk, ts, T, rows, x_T, np.zeros((4, n)), stats)
    integrator.add_to_paths(chain, path, contrib)
    acc = integrator._Accumulators(radiance=np.zeros((P, 4, n)), w_rgb=None, transparency=None, guides=None,
                                   stats={"shadow_rays": 0})
    terms = ts.lobe_kernel_inputs(sp)
    tracer._glossy_next_event(sp, lk, ts, terms, T, rows, x_T, np.zeros((4, n)), acc, path, None)
    assert np.array_equal(acc.radiance, chain, equal_nan=True)
    assert np.isnan(chain).any()                            # the infinite weight's NaN reached both alike


def test_the_route_is_off_without_compiled_kernels():
    assert integrator.GLOSSY_BOUNCE == (kernels.COMPILED and integrator.light_terms_loop is not None)
