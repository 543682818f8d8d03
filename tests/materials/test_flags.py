"""Lobe and capability flags of every material model (engine.materials.flags.BSDFFlags).

Two kinds of checks:
- the flags each model reports for representative parameters (which lobes: Dirac / glossy /
  diffuse, reflection / transmission / null; polarising, retarding, λ-dependent), and how a
  Weidlich–Wilkie stack composes them from its coats and base;
- the flags against what the model actually computes (the oracle is the Mueller algebra, not the
  flags code): no capability may be missing — a model without RETARDING has M_i3 = M_3i = 0 for
  every lobe and direction, one without POLARISING returns only M00, one without
  WAVELENGTH_DEPENDENT the same matrix at every λ, a Dirac-only one a zero ``eval``, a NULL lobe
  wi = −wo; a SEPARABLE_DIFFUSE model returns its diffuse part as a depolarising value or share.
The readers (choose_transport, simplify) keep their answers: tests/render/test_effects.py and
tests/materials/test_simplify.py run unchanged.
"""

import numpy as np
import pytest

from engine.materials.base import BSDF, BSDFFlags as F, ShadingPoint
from engine.materials.batching import shading_groups
from engine.materials.black_glass import BlackGlass
from engine.materials.conductor import SmoothConductor
from engine.materials.dielectric import SmoothDielectric
from engine.materials.filter_sheet import FilterSheet
from engine.materials.htsg import HTSG
from engine.materials.lambert import Lambert, LambertSet
from engine.materials.simplify import simplify_material
from engine.materials.smooth_limit import MirrorWithDiffuse
from engine.materials.torrance_sparrow import TorranceSparrow
from engine.materials.weidlich_wilkie import Coat, WeidlichWilkie
from engine.render.effects import choose_transport, effective_materials
from engine.spectral import ConstantSpectrum, named_ior
from engine.spectral.spectrum import RGBReflectanceSpectrum, RGBUnboundedSpectrum

C = ConstantSpectrum
GOLD = named_ior("Au")
RGB = RGBReflectanceSpectrum([0.2, 0.5, 0.7])
LAMS = np.array([420.0, 510.0, 600.0, 690.0])


def lobes(m):
    return m.flags & F.LOBES


def caps(m):
    return m.flags & ~F.LOBES


# ------------------------------------------------------------------------------------------------
# the flags type
# ------------------------------------------------------------------------------------------------

def test_compound_flags_follow_mitsuba():
    assert F.DELTA == F.DELTA_REFLECTION | F.DELTA_TRANSMISSION | F.NULL
    assert F.TRANSMISSION & F.NULL and not F.REFLECTION & F.NULL      # null counts as transmission
    assert F.SMOOTH == F.DIFFUSE | F.GLOSSY
    assert (F.DELTA_REFLECTION | F.POLARISING).is_delta_only
    assert not (F.DELTA_REFLECTION | F.DIFFUSE_REFLECTION).is_delta_only
    assert not F.POLARISING.is_delta_only                              # no lobe at all is not "Dirac only"
    assert F.NULL.is_delta_only and F.NULL.transmits
    assert (F.GLOSSY_REFLECTION | F.RETARDING).has(F.RETARDING | F.POLARISING)


def test_boolean_views_are_read_only():
    m = Lambert(C(0.5))
    for name in ("delta_only", "transmits", "polarising", "creates_circular"):
        with pytest.raises(AttributeError):
            setattr(m, name, True)


def test_a_model_without_flags_is_assumed_to_do_everything():
    class Unknown(BSDF):
        pass
    f = Unknown().flags
    assert f.has(F.POLARISING) and f.has(F.RETARDING) and f.has(F.WAVELENGTH_DEPENDENT)
    assert not f.is_delta_only and not f.transmits


# ------------------------------------------------------------------------------------------------
# each model, representative parameters
# ------------------------------------------------------------------------------------------------

MODELS = {
    # name: (constructor, lobes, capabilities)
    "lambert_grey": (lambda: Lambert(C(0.5)), F.DIFFUSE_REFLECTION, F.SEPARABLE_DIFFUSE),
    "lambert_rgb": (lambda: Lambert(RGB), F.DIFFUSE_REFLECTION, F.SEPARABLE_DIFFUSE | F.WAVELENGTH_DEPENDENT),
    "gold": (lambda: SmoothConductor(*GOLD), F.DELTA_REFLECTION,
             F.POLARISING | F.RETARDING | F.WAVELENGTH_DEPENDENT),
    "conductor_complex": (lambda: SmoothConductor(C(0.2), C(3.0)), F.DELTA_REFLECTION, F.POLARISING | F.RETARDING),
    "conductor_real": (lambda: SmoothConductor(C(1.5), C(0.0)), F.DELTA_REFLECTION, F.POLARISING),
    "black_glass": (lambda: BlackGlass(C(1.5)), F.DELTA_REFLECTION, F.POLARISING),
    "dielectric": (lambda: SmoothDielectric(1.5), F.DELTA_REFLECTION | F.DELTA_TRANSMISSION,
                   F.POLARISING | F.RETARDING),
    "polariser": (lambda: FilterSheet([1.0, 0.0, 0.0], extinction=0.01), F.NULL, F.POLARISING),
    "retarder": (lambda: FilterSheet([1.0, 0.0, 0.0], "retarder"), F.NULL, F.POLARISING | F.RETARDING),
    "ts_conductor": (lambda: TorranceSparrow(0.2, 3.0, 0.3), F.GLOSSY_REFLECTION, F.POLARISING | F.RETARDING),
    "ts_dielectric": (lambda: TorranceSparrow(1.5, 0.0, 0.3), F.GLOSSY_REFLECTION, F.POLARISING),
    "ts_internal": (lambda: TorranceSparrow(1.5, 0.0, 0.3, exterior_n=2.0), F.GLOSSY_REFLECTION,
                    F.POLARISING | F.RETARDING),                     # η < 1: total internal reflection
    "ts_plastic": (lambda: TorranceSparrow(1.5, 0.0, 0.3, diffuse_albedo=0.5, diffuse_weight=0.5),
                   F.GLOSSY_REFLECTION | F.DIFFUSE_REFLECTION, F.POLARISING | F.SEPARABLE_DIFFUSE),
    "ts_diffuse_only": (lambda: TorranceSparrow(0.2, 3.0, 0.3, diffuse_albedo=RGB, diffuse_weight=1.0,
                                                specular_weight=0.0),
                        F.DIFFUSE_REFLECTION, F.SEPARABLE_DIFFUSE | F.WAVELENGTH_DEPENDENT),
    "ts_gold": (lambda: TorranceSparrow(*GOLD, 0.3), F.GLOSSY_REFLECTION,
                F.POLARISING | F.RETARDING | F.WAVELENGTH_DEPENDENT),
    "mirror_diffuse": (lambda: MirrorWithDiffuse(1.5, 0.0, diffuse_albedo=0.5, diffuse_weight=0.5),
                       F.DELTA_REFLECTION | F.DIFFUSE_REFLECTION, F.POLARISING | F.SEPARABLE_DIFFUSE),
    "mirror_gold": (lambda: MirrorWithDiffuse(*GOLD), F.DELTA_REFLECTION,
                    F.POLARISING | F.RETARDING | F.WAVELENGTH_DEPENDENT),
    "htsg": (lambda: HTSG(0.2, 3.0, 0.02, 2.0), F.GLOSSY_REFLECTION | F.DELTA_REFLECTION,
             F.POLARISING | F.RETARDING | F.WAVELENGTH_DEPENDENT),
    "htsg_albedo": (lambda: HTSG(0.2, 3.0, 0.02, 2.0, albedo=0.1),
                    F.GLOSSY_REFLECTION | F.DELTA_REFLECTION | F.DIFFUSE_REFLECTION,
                    F.POLARISING | F.RETARDING | F.WAVELENGTH_DEPENDENT),    # diffuse folded in: not separable
}


@pytest.mark.parametrize("name", sorted(MODELS))
def test_model_flags(name):
    make, want_lobes, want_caps = MODELS[name]
    m = make()
    assert lobes(m) == want_lobes, (name, lobes(m))
    assert caps(m) == want_caps, (name, caps(m))


def test_boolean_views_of_the_flags():
    assert SmoothConductor(*GOLD).delta_only and not SmoothConductor(*GOLD).transmits
    assert SmoothDielectric(1.5).delta_only and SmoothDielectric(1.5).transmits
    assert FilterSheet([0, 0, 1.0]).delta_only and FilterSheet([0, 0, 1.0]).transmits
    assert not MirrorWithDiffuse(1.5, 0.0, diffuse_albedo=0.5, diffuse_weight=0.5).delta_only
    assert MirrorWithDiffuse(1.5, 0.0).delta_only
    lam = Lambert(C(0.5))
    assert not lam.polarising and not lam.creates_circular and not lam.delta_only
    assert BlackGlass(C(1.5)).polarising and not BlackGlass(C(1.5)).creates_circular


def test_a_black_torrance_sparrow_keeps_its_glossy_lobe():
    """s = d = 0: no light at all, but it is not mistaken for a Dirac-only material (as before)."""
    m = TorranceSparrow(1.5, 0.0, 0.3, specular_weight=0.0)
    assert lobes(m) == F.GLOSSY_REFLECTION and not m.delta_only and not m.polarising
    ww = WeidlichWilkie(Coat(n=1.5), m)
    assert not ww.delta_only


def test_lambert_set_flags():
    grey = [Lambert(C(0.2)), Lambert(C(0.7))]
    s = LambertSet(grey)
    assert s.flags == F.DIFFUSE_REFLECTION | F.SEPARABLE_DIFFUSE | F.BATCHED
    s = LambertSet(grey + [Lambert(RGB)])
    assert s.flags == F.DIFFUSE_REFLECTION | F.SEPARABLE_DIFFUSE | F.BATCHED | F.WAVELENGTH_DEPENDENT
    shaders, _, _ = shading_groups(grey + [SmoothConductor(*GOLD)])
    assert [x.flags.has(F.BATCHED) for x in shaders] == [True, False]


# ------------------------------------------------------------------------------------------------
# Weidlich–Wilkie: composed from the coats and the base
# ------------------------------------------------------------------------------------------------

def test_clear_smooth_coat_over_lambert():
    ww = WeidlichWilkie(Coat(n=1.5), Lambert(C(0.8)))
    assert lobes(ww) == F.DELTA_REFLECTION | F.DIFFUSE_REFLECTION
    assert caps(ww) == F.POLARISING                   # η = 1.5 ≥ 1 and a depolarising base: no retardance
    assert not ww.delta_only and not ww.transmits


def test_absorbing_coats():
    grey = WeidlichWilkie(Coat(n=1.5, thickness=1.0, absorption=0.3), Lambert(C(0.8)))
    assert lobes(grey) == F.DELTA_REFLECTION | F.DIFFUSE_REFLECTION and caps(grey) == F.POLARISING
    tinted = WeidlichWilkie(Coat(n=1.5, thickness=1.0, absorption=RGBUnboundedSpectrum([0.1, 0.5, 2.0])),
                            Lambert(C(0.8)))
    assert caps(tinted) == F.POLARISING | F.WAVELENGTH_DEPENDENT
    coloured_base = WeidlichWilkie(Coat(n=1.5), Lambert(RGB))
    assert caps(coloured_base) == F.POLARISING | F.WAVELENGTH_DEPENDENT


def test_rough_coat_over_a_rough_conductor():
    ww = WeidlichWilkie(Coat(n=1.5, distribution="beckmann", m=0.2), TorranceSparrow(0.2, 3.0, 0.3))
    assert lobes(ww) == F.GLOSSY_REFLECTION
    assert caps(ww) == F.POLARISING | F.RETARDING
    assert not ww.delta_only


def test_rough_coat_hides_the_dirac_lobe_below():
    ww = WeidlichWilkie(Coat(n=1.5, distribution="blinn", exponent=30.0), HTSG(0.2, 3.0, 0.02, 2.0))
    assert lobes(ww) == F.GLOSSY_REFLECTION
    with pytest.raises(ValueError, match="delta-only"):
        WeidlichWilkie(Coat(n=1.5, distribution="beckmann", m=0.2), SmoothConductor(*GOLD))


def test_smooth_coat_over_a_mirror_is_dirac_only():
    ww = WeidlichWilkie(Coat(n=1.5), SmoothConductor(*GOLD))
    assert lobes(ww) == F.DELTA_REFLECTION and ww.delta_only
    assert caps(ww) == F.POLARISING | F.RETARDING | F.WAVELENGTH_DEPENDENT


def test_coat_that_may_totally_reflect_retards():
    ww = WeidlichWilkie(Coat(n=1.2), Lambert(C(0.8)), exterior_n=1.33)      # η = 1.2/1.33 < 1
    assert ww.flags.has(F.RETARDING)


def test_stack_of_coats():
    ww = WeidlichWilkie([Coat(n=1.5, distribution="beckmann", m=0.3), Coat(n=1.3)], Lambert(C(0.5)))
    assert lobes(ww) == F.GLOSSY_REFLECTION | F.DIFFUSE_REFLECTION
    assert lobes(ww.base) == F.DELTA_REFLECTION | F.DIFFUSE_REFLECTION
    assert ww.base.flags.has(F.RETARDING)            # inner coat: η = 1.3/1.5 < 1
    assert ww.flags.has(F.RETARDING)                 # inherited from the base


def test_base_with_a_transmitting_lobe_is_rejected():
    with pytest.raises(ValueError, match="transmits"):
        WeidlichWilkie(Coat(n=1.5), SmoothDielectric(1.5))
    with pytest.raises(ValueError, match="transmits"):
        WeidlichWilkie(Coat(n=1.5), FilterSheet([1.0, 0, 0]))


# ------------------------------------------------------------------------------------------------
# the flags against what the models compute
# ------------------------------------------------------------------------------------------------

def _unit(v):
    return v / np.linalg.norm(v, axis=0)


def _point(wo, lam=LAMS):
    n = wo.shape[1]
    z = np.tile(np.array([[0.0], [0.0], [1.0]]), (1, n))
    return ShadingPoint(np.zeros((3, n)), z, z, wo, np.broadcast_to(lam[:, None], (lam.size, n)).copy())


def _directions(n, seed, two_sided):
    rng = np.random.default_rng(seed)
    wi, wo = _unit(rng.normal(size=(3, n))), _unit(rng.normal(size=(3, n)))
    if not two_sided:
        wi[2], wo[2] = np.abs(wi[2]), np.abs(wo[2])
    c = np.linspace(1e-3, 0.2, n)                  # include near-grazing viewers (total internal reflection)
    wo[:, ::4] = _unit(np.stack((np.sqrt(1 - c * c), np.zeros(n), np.sign(wo[2] + 1e-300) * c)))[:, ::4]
    return wi, wo


def _values(m, n=600, seed=3, lam=LAMS):
    """Every Mueller value the model produces for random geometries: (name, value) pairs."""
    wi, wo = _directions(n, seed, m.flags.transmits)
    sp = _point(wo, lam)
    rng = np.random.default_rng(seed + 1)
    out = [("eval", m.eval(sp, wi))]
    d = m.delta_reflection(sp)
    if d is not None:
        out.append(("delta_reflection", d))
    s = m.sample(sp, rng.uniform(size=n), rng.uniform(size=(2, n)))
    out.append(("sample", s.weight))
    return out, sp, wi, s


NON_RETARDING = [k for k in MODELS if not MODELS[k][2] & F.RETARDING]
NON_POLARISING = [k for k in MODELS if not MODELS[k][2] & F.POLARISING]
CONSTANT_IN_LAMBDA = [k for k in MODELS if not MODELS[k][2] & F.WAVELENGTH_DEPENDENT]
WW_CASES = {
    "smooth_over_lambert": lambda: WeidlichWilkie(Coat(n=1.5), Lambert(C(0.8))),
    "rough_over_ts_dielectric": lambda: WeidlichWilkie(Coat(n=1.5, distribution="beckmann", m=0.3),
                                                       TorranceSparrow(1.8, 0.0, 0.3)),
    "tir_coat": lambda: WeidlichWilkie(Coat(n=1.2), SmoothConductor(C(1.5), C(0.0)), exterior_n=1.33),
    "smooth_over_gold": lambda: WeidlichWilkie(Coat(n=1.5), SmoothConductor(*GOLD)),
}


@pytest.mark.parametrize("name", NON_RETARDING + ["ww_smooth_over_lambert", "ww_rough_over_ts_dielectric"])
def test_without_retarding_no_circular_polarisation_is_created(name):
    m = WW_CASES[name[3:]]() if name.startswith("ww_") else MODELS[name][0]()
    assert not m.flags.has(F.RETARDING)
    for what, v in _values(m)[0]:
        M = v.matrix()
        scale = max(float(np.abs(M[0, 0]).max()), 1e-300)
        assert np.abs(M[3, :3]).max() <= 1e-12 * scale and np.abs(M[:3, 3]).max() <= 1e-12 * scale, (name, what)


@pytest.mark.parametrize("name", ["gold", "conductor_complex", "dielectric", "retarder", "ts_conductor",
                                  "ts_internal", "mirror_gold", "htsg", "ww_tir_coat", "ww_smooth_over_gold"])
def test_retarding_models_do_create_circular_polarisation(name):
    """Not an exactness requirement (RETARDING may be conservative), but these really retard."""
    m = WW_CASES[name[3:]]() if name.startswith("ww_") else MODELS[name][0]()
    assert m.flags.has(F.RETARDING)
    worst = 0.0
    for _, v in _values(m, n=2000)[0]:
        M = v.matrix()
        worst = max(worst, float(np.abs(M[3, :3]).max()), float(np.abs(M[:3, 3]).max()))
    assert worst > 1e-3


@pytest.mark.parametrize("make", [lambda: SmoothConductor(C(1.0), C(0.0), 1.33), lambda: BlackGlass(C(1.0), 1.33)])
def test_real_index_below_the_exterior_retards(make):
    m = make()
    M = m.delta_reflection(_point(_directions(400, 5, False)[1])).matrix()
    assert (np.abs(M[2, 3]).max() > 1e-3) == m.flags.has(F.RETARDING)


@pytest.mark.parametrize("name", NON_POLARISING)
def test_without_polarising_only_m00_is_nonzero(name):
    m = MODELS[name][0]()
    for what, v in _values(m)[0]:
        M = v.matrix().copy()
        assert np.abs(M[0, 0]).max() > 0, (name, what)
        M[0, 0] = 0.0
        assert np.all(M == 0), (name, what)


@pytest.mark.parametrize("name", CONSTANT_IN_LAMBDA + ["ww_smooth_over_lambert", "ww_tir_coat"])
def test_wavelength_independent_models_give_the_same_matrix_at_every_wavelength(name):
    m = WW_CASES[name[3:]]() if name.startswith("ww_") else MODELS[name][0]()
    assert not m.flags.has(F.WAVELENGTH_DEPENDENT)
    for what, v in _values(m)[0]:
        M = v.matrix()
        np.testing.assert_array_equal(M, np.broadcast_to(M[:, :, :1], M.shape), err_msg=f"{name} {what}")


@pytest.mark.parametrize("name", ["lambert_rgb", "gold", "ts_gold", "htsg"])
def test_wavelength_dependent_models_differ_between_wavelengths(name):
    m = MODELS[name][0]()
    assert any(np.abs(np.diff(v.matrix(), axis=2)).max() > 1e-6 for _, v in _values(m)[0] if _ != "sample")


@pytest.mark.parametrize("name", sorted(MODELS))
def test_lobes_against_eval_and_sample(name):
    m = MODELS[name][0]()
    values, sp, wi, s = _values(m)
    f = values[0][1].matrix()
    if m.flags.is_delta_only:                      # no function value: eval and pdf are zero
        assert np.all(f == 0) and np.all(m.pdf(sp, wi) == 0)
        assert np.all(s.is_delta)
    else:
        assert np.abs(f[0, 0]).max() > 0
    if not m.flags.has(F.DELTA):
        assert not np.any(s.is_delta)
    if not m.flags.has(F.DELTA_REFLECTION):
        assert m.delta_reflection(sp) is None
    if m.flags.has(F.NULL):                          # straight through
        np.testing.assert_array_equal(s.wi, -sp.wo)
    ok = s.valid
    side = np.sign(s.wi[2, ok]) * np.sign(sp.wo[2, ok])
    assert np.any(side < 0) == m.flags.transmits
    # SEPARABLE_DIFFUSE: the diffuse lobes come back as a depolarising value or an ABCS share
    v = values[0][1]
    separate = v.kind == "depolarising" or (v.kind == "abcs" and v.depol is not None)
    if m.flags.has(F.SEPARABLE_DIFFUSE):
        assert separate and np.abs(v.A if v.kind == "depolarising" else v.depol).max() > 0
    elif m.flags.has(F.DIFFUSE):
        assert not separate


# ------------------------------------------------------------------------------------------------
# readers
# ------------------------------------------------------------------------------------------------

def test_choose_transport_reads_the_flags():
    mats = {"wall": Lambert(C(0.5)), "floor": BlackGlass(C(1.5)), "gold": SmoothConductor(*GOLD),
            "sheet": FilterSheet([1.0, 0, 0]), "wave_plate": FilterSheet([1.0, 0, 0], "retarder")}
    assert choose_transport(mats, {"wall"})[0] == "off"
    assert choose_transport(mats, {"wall", "floor"})[0] == "linear"
    assert choose_transport(mats, {"wall", "sheet"})[0] == "linear"
    assert choose_transport(mats, {"wall", "floor", "gold"})[0] == "full"
    assert choose_transport(mats, {"sheet", "wave_plate"})[0] == "full"


def test_skipped_matched_coat_makes_lambert_scalar():
    mats = {"ball": WeidlichWilkie(Coat(n=1.0), Lambert(C(0.5)))}
    assert choose_transport(mats)[0] == "linear"                 # the coat's interface "polarises"
    simple, why = effective_materials(mats)
    assert type(simple["ball"]) is Lambert and why
    assert choose_transport(simple)[0] == "off"


@pytest.mark.parametrize("base,reduced", [(lambda: Lambert(C(0.5)), False),
                                          (lambda: TorranceSparrow(1.6, 0.0, 0.25, diffuse_albedo=0.5,
                                                                   diffuse_weight=0.5), False),
                                          (lambda: TorranceSparrow(0.2, 3.0, 0.3), True)])
def test_simplify_keeps_the_energy_form_factor(base, reduced):
    """Energy form: a matched lowest coat between another coat and a base with a separable diffuse share
    stays (removing it would give the coat above the c_ms factor); over a glossy-only base it goes."""
    ww = WeidlichWilkie([Coat(n=1.5), Coat(n=1.5)], base())
    simple, why = simplify_material(ww)
    if reduced:
        assert simple is not ww and len(simple.coats) == 1 and len(why) == 1
    else:
        assert simple is ww and why == []
