"""Materials shaded together (LambertSet) give exactly the image of materials shaded one by one."""

import dataclasses

import numpy as np
import pytest

from engine.materials import batching
from engine.materials.lambert import Lambert, LambertSet
from engine.render import integrator
from engine.render.renderer import Renderer
from engine.scene.loader import load_scene
from engine.spectral import ConstantSpectrum
from engine.spectral.spectrum import RGBReflectanceSpectrum
from tests.conftest import shared_path


def one_by_one(materials):
    return list(materials), np.arange(len(materials)), np.zeros(len(materials), np.int64)


def cornell(spectral, res=24, spp=3):
    scene = load_scene(shared_path("peers", "scenes", "cornell_lambert.json"))
    scene.camera.width = scene.camera.height = res
    scene.settings = dataclasses.replace(scene.settings, spp=spp, spectral=spectral)
    return scene


@pytest.mark.parametrize("spectral", ["spectral", "mono"])
@pytest.mark.parametrize("grey", [False, True])
def test_lambert_set_render_is_bitwise_the_one_by_one_render(monkeypatch, spectral, grey):
    """Coloured (spectral), grey (RGB mode: λ-independent) and mono; several bounces, so a stale
    per-bounce value would show (the first version memoised albedos per wavelength lookup only)."""
    scene = cornell(spectral)
    if grey:
        for name, m in scene.materials.items():
            if isinstance(m, Lambert):
                scene.materials[name] = Lambert(ConstantSpectrum(float(np.mean(m.albedo.linear_srgb()))))
    renderer = Renderer(scene)
    settings = dataclasses.replace(scene.settings, polarisation="off")
    tracer = integrator.PathTracer(renderer.compiled, renderer.lights, renderer.camera, settings)
    assert any(isinstance(s, LambertSet) for s in tracer.shaders)
    batched = renderer.render().stokes()
    monkeypatch.setattr(integrator, "shading_groups", one_by_one)
    separate = renderer.render().stokes()
    assert np.abs(batched).max() > 0
    np.testing.assert_array_equal(batched, separate)


def test_mixed_constant_and_rgb_albedos_give_each_members_value():
    members = [Lambert(ConstantSpectrum(0.3)), Lambert(RGBReflectanceSpectrum([0.8, 0.1, 0.1])),
               Lambert(RGBReflectanceSpectrum([0.5, 0.5, 0.5]))]
    group = LambertSet(members)
    from engine.materials.base import ShadingPoint
    from engine.spectral import WavelengthLookup
    n = 600
    rng = np.random.default_rng(0)
    lam = rng.uniform(360, 830, (4, n))
    slot = rng.integers(0, 3, n)
    up = np.tile([[0.0], [0.0], [1.0]], n)
    wo = np.tile([[0.3], [0.0], [0.9539392014169456]], n)
    wi = np.tile([[-0.5], [0.0], [0.8660254037844386]], n)
    sp = ShadingPoint(np.zeros((3, n)), up, up, wo, lam, lookup=WavelengthLookup(lam), material=slot)
    got = group.eval(sp, wi).A
    for k, m in enumerate(members):
        mine = slot == k
        ref = m.eval(ShadingPoint(np.zeros((3, mine.sum())), up[:, mine], up[:, mine], wo[:, mine], lam[:, mine]),
                     wi[:, mine]).A
        np.testing.assert_array_equal(got[:, mine], ref)


def test_only_batchable_lambert_materials_are_grouped():
    from engine.materials.conductor import SmoothConductor
    from engine.spectral.spectrum import TabulatedSpectrum
    mats = [Lambert(ConstantSpectrum(0.5)), SmoothConductor(ConstantSpectrum(0.2), ConstantSpectrum(3.0)),
            Lambert(TabulatedSpectrum([400, 700], [0.2, 0.8], kind="reflectance")),
            Lambert(RGBReflectanceSpectrum([0.2, 0.4, 0.6]))]
    shaders, group_of, slot_of = batching.shading_groups(mats)
    assert isinstance(shaders[0], LambertSet) and shaders[0].members == [mats[0], mats[3]]
    assert group_of.tolist() == [0, 1, 2, 0] and slot_of[[0, 3]].tolist() == [0, 1]
    assert shaders[1] is mats[1] and shaders[2] is mats[2]
    single = batching.shading_groups(mats[:2])[0]
    assert single == mats[:2]                       # one Lambert: nothing to batch
    with pytest.raises(ValueError):
        LambertSet([mats[1]])
