"""Weidlich–Wilkie stacks give the same value however an index-matched clear (null) coat is inserted
(engine.materials.weidlich_wilkie, the energy form's internal-reflection factor c_ms)."""

import numpy as np
import pytest

from engine.materials.base import ShadingPoint
from engine.materials.lambert import Lambert
from engine.materials.torrance_sparrow import TorranceSparrow
from engine.materials.weidlich_wilkie import Coat, WeidlichWilkie
from engine.spectral import ConstantSpectrum


def pairs(n, seed):
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(2, 3, n))
    w[:, 2] = np.abs(w[:, 2]) + 0.05
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    return w[0], w[1]


def value(model, wi, wo):
    n = wo.shape[1]
    nrm = np.tile([[0.0], [0.0], [1.0]], (1, n))
    sp = ShadingPoint(np.zeros((3, n)), nrm, nrm, wo, np.full((1, n), 550.0))
    return model.eval(sp, wi).matrix()[:, :, 0, :]


ROUGH = dict(n=1.5, distribution="beckmann", m=0.3)
BASES = {"lambert": lambda: Lambert(ConstantSpectrum(0.8)),
         "ts_with_diffuse": lambda: TorranceSparrow(1.6, 0.0, 0.2, diffuse_albedo=0.6, diffuse_weight=1.0)}
NULL_COATS = {"smooth": lambda: Coat(n=1.5), "rough": lambda: Coat(n=1.5, distribution="beckmann", m=0.2),
              "thick_clear": lambda: Coat(n=1.5, thickness=3.0, absorption=0.0),
              "absorbing_but_thin": lambda: Coat(n=1.5, thickness=0.0, absorption=4.0)}


@pytest.mark.parametrize("base", sorted(BASES))
@pytest.mark.parametrize("null", sorted(NULL_COATS))
@pytest.mark.parametrize("form", ["energy", "published"])
def test_inserted_null_coat_changes_nothing(base, null, form):
    wi, wo = pairs(300, 11)
    ref = value(WeidlichWilkie(Coat(**ROUGH), BASES[base](), form=form), wi, wo)
    for model in (WeidlichWilkie([Coat(**ROUGH), NULL_COATS[null]()], BASES[base](), form=form),
                  WeidlichWilkie([Coat(**ROUGH), NULL_COATS[null](), NULL_COATS[null]()], BASES[base](), form=form),
                  WeidlichWilkie(Coat(**ROUGH), WeidlichWilkie(NULL_COATS[null](), BASES[base](), form=form),
                                 form=form)):
        np.testing.assert_allclose(value(model, wi, wo), ref, rtol=1e-9, atol=1e-12 * ref[0, 0].max())


def test_the_issue_case():
    """WW([rough n=1.5, clear smooth n=1.5], Lambert) was 0.109 where WW(rough n=1.5, Lambert) gave 0.199."""
    lam = Lambert(ConstantSpectrum(1.0))
    wi, wo = pairs(50, 3)
    one = value(WeidlichWilkie(Coat(**ROUGH), lam), wi, wo)[0, 0]
    two = value(WeidlichWilkie([Coat(**ROUGH), Coat(n=1.5)], lam), wi, wo)[0, 0]
    np.testing.assert_allclose(two, one, rtol=1e-9)
    # the factor matters: without it the value would be much lower (c_ms = 1/(1 − ρR̄) ≈ 1.8 here)
    bare = WeidlichWilkie(Coat(**ROUGH), lam)
    assert bare.internal_reflectance(np.array(1.5), np.array(0.0)) > 0.4


def test_absorbing_or_mismatched_coats_are_not_null():
    wi, wo = pairs(200, 5)
    lam = Lambert(ConstantSpectrum(0.8))
    ref = value(WeidlichWilkie(Coat(**ROUGH), lam), wi, wo)[0, 0]
    for coat in (Coat(n=1.5, thickness=1.0, absorption=0.1), Coat(n=1.5 + 1e-3)):
        other = value(WeidlichWilkie([Coat(**ROUGH), coat], lam), wi, wo)[0, 0]
        assert np.all(other < ref)
