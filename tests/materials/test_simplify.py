"""engine.materials.simplify: skipping index-matched, clear Weidlich–Wilkie coats is an exact reduction.

The reduced material must have the same Mueller BRDF (eval), the same Dirac lobes
(delta_reflection) and an unbiased sampler for the same integral (directional albedo);
its ``pdf`` is its own proposal density, not the stack's (see test_pdf_is_the_reduced_materials_own).
"""

import copy
import math

import numpy as np
import pytest

from engine.materials.catalogue import make_model
from engine.materials.conductor import SmoothConductor
from engine.materials.htsg import HTSG
from engine.materials.lambert import Lambert
from engine.materials.simplify import (
    index_matched_and_clear,
    same_spectrum,
    simplify_material,
)
from engine.materials.torrance_sparrow import TorranceSparrow
from engine.materials.weidlich_wilkie import Coat, WeidlichWilkie
from engine.polarisation.frames import plane_of_incidence_axis, scattering_plane_axis
from engine.spectral import ConstantSpectrum
from engine.spectral.spectrum import RGBUnboundedSpectrum, TabulatedSpectrum
from engine.vec3 import reflect
from tests.materials.test_torrance_sparrow import matrix_in_frames
from tests.materials.test_weidlich_wilkie import _col, _direction, _point, _random_pairs

Z = np.array([0.0, 0.0, 1.0])
LAMS = np.array([450.0, 520.0, 600.0, 680.0])   # 4 wavelengths per path: spectral bases (gold) are exercised

BASES = {
    "lambert": lambda: Lambert(ConstantSpectrum(0.8)),
    "gold": lambda: make_model("fresnel", {"metal": "Au"}),
    "ts_conductor": lambda: TorranceSparrow(0.2, 3.0, 0.3),
    "ts_diffuse": lambda: TorranceSparrow(1.6, 0.0, 0.25, diffuse_albedo=0.5, diffuse_weight=0.5),
    "coated_rough": lambda: WeidlichWilkie(Coat(n=1.5, thickness=1.0, absorption=0.1, distribution="beckmann",
                                                m=0.2), Lambert(ConstantSpectrum(0.7))),
    "coated_smooth": lambda: WeidlichWilkie(Coat(n=1.5), TorranceSparrow(0.2, 3.0, 0.3), form="published"),
    "htsg": lambda: HTSG(0.2, 3.0, 0.02, 2.0, albedo=0.1),
}
#: Bases with a Dirac lobe: a rough coat hides it, so a rough matched coat over them is kept (see below).
DIRAC_BASES = {"gold", "coated_smooth", "htsg"}
COATS = {"smooth": {}, "blinn": {"exponent": 30.0}, "beckmann": {"m": 0.3}}
FORMS = ("energy", "published", "first_order")


def _clear_coat(dist, n=1.0, **kw):
    return Coat(n=n, distribution=dist, **COATS[dist], **kw)


def _unit(v):
    return v / np.linalg.norm(v, axis=0)


def _directions(n=600, seed=7):
    """(wi, wo) (3, M): random pairs over the whole sphere (both hemispheres) and special geometries:
    normal incidence/exitance, near-grazing (cosθ down to 1e-3), mirror and retro-reflection pairs."""
    rng = np.random.default_rng(seed)
    wi_all, wo_all = [_unit(rng.normal(size=(3, n)))], [_unit(rng.normal(size=(3, n)))]  # both hemispheres
    up_i, up_o = _random_pairs(n, seed + 1)
    wi_all.append(up_i)
    wo_all.append(up_o)
    m = 40
    up_i, up_o = _random_pairs(m, seed + 2)
    z = np.tile(_col(Z), (1, m))
    wi_all += [z, up_i, z, up_i, reflect(up_o, z)]          # normal incidence, normal exitance, both, retro, mirror
    wo_all += [up_o, z, z, up_i, up_o]
    for c in (1e-3, 1e-2, 0.05):                               # near grazing, either side, various azimuths
        phi = rng.uniform(0.0, 2.0 * math.pi, m)
        g = np.stack((math.sqrt(1.0 - c * c) * np.cos(phi), math.sqrt(1.0 - c * c) * np.sin(phi), np.full(m, c)))
        other = _random_pairs(m, seed + int(1e4 * c))[0]
        wi_all += [g, other, g]
        wo_all += [other, g, reflect(g, z)]
    g0 = np.stack((np.cos(np.arange(m)), np.sin(np.arange(m)), np.zeros(m)))       # exactly grazing
    wi_all += [g0, up_i]
    wo_all += [up_o, g0]
    return np.concatenate(wi_all, axis=1), np.concatenate(wo_all, axis=1)


def _scattering_matrices(model, wi, wo):
    """eval() as (4, 4, L, N) in the scattering-plane frames s = unit(k_i × k_o) on both beams."""
    sp = _point(wo, lam=LAMS, L=LAMS.size)
    x = scattering_plane_axis(-wi, wo)
    return matrix_in_frames(model.eval(sp, wi), x, -wi, x, wo)


def _assert_same_eval(a, b, wi, wo, rel=1e-12):
    """eval agrees to ``rel`` relative to M00 (floored at 1e-3 sr⁻¹, i.e. 1e-15 sr⁻¹ absolute where a glossy
    lobe is ~0: an index-matched coat's own lobe is F(η = 1) ≈ 1e-33…1e-23 from rounding, not 0).

    Near grazing the bound is _near_grazing_bound.  Below the horizon and at exactly grazing incidence both are 0.
    """
    Ma, Mb = _scattering_matrices(a, wi, wo), _scattering_matrices(b, wi, wo)
    assert np.all(np.isfinite(Ma)) and np.all(np.isfinite(Mb))
    c = np.minimum(wi[2], wo[2])
    bound = _near_grazing_bound(c, rel)[None, :]                                   # (1, N)
    scale = np.maximum(np.maximum(np.abs(Ma[0, 0]), np.abs(Mb[0, 0])), 1e-3)       # (L, N)
    err = np.abs(Ma - Mb).max(axis=(0, 1))
    worst = np.unravel_index(np.argmax(err / (bound * scale)), err.shape)
    assert np.all(err <= bound * scale), (float(err[worst]), float(scale[worst]), wi[:, worst[1]], wo[:, worst[1]])
    assert np.all(Ma[..., c <= 0] == 0) and np.all(Mb[..., c <= 0] == 0)
    return Ma


def _near_grazing_bound(c, rel):
    """max(rel, 1e-16/cos²θ): the stack refracts through η = 1 with cosθ' = √(1 − (1 − cos²θ)), whose rounding
    (~1e-16/cos²θ relative) the base then sees — 1e-12 down to cosθ = 0.01 (89.4°), 1e-10 at cosθ = 1e-3."""
    with np.errstate(divide="ignore"):
        return np.maximum(rel, 1e-16 / np.square(c))


def _assert_same_delta(a, b, rel=1e-12):
    """delta_reflection over viewer directions incl. normal and near-grazing incidence; None counts as a zero
    lobe (an index-matched smooth coat's own mirror is F(η = 1) ≈ 1e-23, not None).

    Exactly grazing (cosθ = 0) is left out: there the stack's refracted ray has cosθ' = 0 and its layered
    Dirac lobe is 0, whereas a bare mirror's grazing limit is M_F → identity (a set of measure zero)."""
    wo = np.concatenate((_random_pairs(300, 3)[1], _col(Z), _col([math.sqrt(1 - 1e-6), 0.0, 1e-3]),
                         _col([math.sqrt(1 - 1e-4), 0.0, 1e-2])), axis=1)
    sp = _point(wo, lam=LAMS, L=LAMS.size)
    zs = np.tile(_col(Z), (1, wo.shape[1]))
    wi = reflect(wo, zs)
    s = plane_of_incidence_axis(zs, wo)
    W = [model.delta_reflection(sp) for model in (a, b)]
    M = [np.zeros((4, 4) + sp.lam.shape) if d is None else matrix_in_frames(d, s, -wi, s, wo) for d in W]
    assert np.all(np.isfinite(M[0])) and np.all(np.isfinite(M[1]))
    scale = np.maximum(np.abs(M[0][0, 0]), np.abs(M[1][0, 0]))
    if W[0] is None or W[1] is None:
        scale = np.maximum(scale, 1.0)                     # a lobe against none: absolute (weights ≤ 1)
    bound = _near_grazing_bound(wo[2], rel)[None, :]
    assert np.all(np.abs(M[0] - M[1]).max(axis=(0, 1)) <= bound * scale)


def _assert_same_flags(a, b):
    assert a.delta_only == b.delta_only
    assert a.transmits == b.transmits


# ---------------------------------------------------------------------------------------------
# (a) an index-matched, clear top coat over each base: the material is its (configured) base
# ---------------------------------------------------------------------------------------------

CASES_A = [(b, d, f) for b in sorted(BASES) for d in COATS for f in FORMS if not (d != "smooth" and b in DIRAC_BASES)]


@pytest.mark.parametrize("base_name,dist,form", CASES_A)
def test_matched_clear_top_coat_is_skipped(base_name, dist, form):
    base = BASES[base_name]()
    model = WeidlichWilkie(_clear_coat(dist), base, form=form)
    simple, reasons = simplify_material(model, name="varnish")
    assert type(simple) is type(base) and simple is not base and simple is not model.base
    assert len(reasons) == 2 and reasons[0].startswith("coat 1 of 'varnish' is index-matched (n = 1.0 = medium above)")
    assert "skipped" in reasons[0]
    wi, wo = _directions()
    M = _assert_same_eval(model, simple, wi, wo)
    below = (wi[2] <= 0) | (wo[2] <= 0)
    assert np.all(M[..., below] == 0)                      # one-sided: both hemispheres covered
    _assert_same_delta(model, simple)
    _assert_same_flags(model, simple)
    # the reduced material is the base as configured inside the stack (same exterior medium)
    assert getattr(simple, "exterior_n", None) == getattr(model.base, "exterior_n", None)


@pytest.mark.parametrize("base_name", ["ts_conductor", "htsg", "coated_rough", "gold"])
def test_base_keeps_the_exterior_medium_it_saw(base_name):
    """Under water (exterior 1.33) a matched coat n = 1.33: the base must still see 1.33, not its own 1.0."""
    base = BASES[base_name]()
    dist = "smooth" if base_name in DIRAC_BASES else "beckmann"
    model = WeidlichWilkie(_clear_coat(dist, n=1.33), base, exterior_n=1.33)
    simple, reasons = simplify_material(model)
    assert len(reasons) == 2 and type(simple) is type(base)
    ext = simple.exterior_n
    assert (ext.value if isinstance(ext, ConstantSpectrum) else ext) == 1.33
    ext0 = base.exterior_n
    assert (ext0.value if isinstance(ext0, ConstantSpectrum) else ext0) == 1.0      # the caller's base untouched
    wi, wo = _directions(300, 11)
    _assert_same_eval(model, simple, wi, wo)
    _assert_same_delta(model, simple)
    # and it is not the unconfigured base: that one differs (relative index η/1 instead of η/1.33)
    if base_name == "gold":   # delta-only
        sp = _point(wo[:, :50], lam=LAMS, L=LAMS.size)
        assert not np.allclose(base.delta_reflection(sp).matrix(), simple.delta_reflection(sp).matrix())
    else:
        assert not np.allclose(_scattering_matrices(base, wi, wo), _scattering_matrices(simple, wi, wo))


def test_match_base_exterior_false_returns_the_base_as_evaluated():
    base = TorranceSparrow(0.2, 3.0, 0.3)
    model = WeidlichWilkie(_clear_coat("beckmann", n=1.5), base, exterior_n=1.5, match_base_exterior=False)
    simple, _ = simplify_material(model)
    assert isinstance(simple, TorranceSparrow) and simple.exterior_n == 1.0
    wi, wo = _directions(300, 12)
    _assert_same_eval(model, simple, wi, wo)


def test_dispersive_matched_index_is_skipped():
    """Equal sample values (distinct objects) at every wavelength: skipped; exact per wavelength."""
    def table():
        return TabulatedSpectrum([360.0, 500.0, 830.0], [1.52, 1.50, 1.48], name="glass")

    base = WeidlichWilkie(Coat(n=2.0, distribution="beckmann", m=0.3), Lambert(ConstantSpectrum(0.6)))
    model = WeidlichWilkie([_clear_coat("smooth", n=table()), Coat(n=1.7, distribution="blinn", exponent=40.0)],
                           base, exterior_n=table(), form="published")
    simple, reasons = simplify_material(model)
    assert isinstance(simple, WeidlichWilkie) and len(simple.coats) == 1 and simple.coats[0].n == 1.7
    assert len(reasons) == 1 and "coat 1 of 'weidlich_wilkie'" in reasons[0]
    wi, wo = _directions(300, 13)
    _assert_same_eval(model, simple, wi, wo)
    # RGB and constant spectra: equal only if bit-identical at every wavelength and in mono mode
    assert same_spectrum(RGBUnboundedSpectrum([1.5, 1.5, 1.5]), RGBUnboundedSpectrum([1.5, 1.5, 1.5]))
    assert same_spectrum(ConstantSpectrum(1.5), ConstantSpectrum(1.5))
    assert not same_spectrum(table(), TabulatedSpectrum([360.0, 830.0], [1.52, 1.48]))
    assert not same_spectrum(ConstantSpectrum(1.5), TabulatedSpectrum([400.0, 700.0], [1.5, 1.5]))  # raises outside


# ---------------------------------------------------------------------------------------------
# (b) stacks where only some coats are index matched
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("base_name", ["ts_conductor", "htsg", "coated_rough"])
def test_lower_coat_matching_the_upper_coat_is_skipped(form, base_name):
    base = BASES[base_name]()
    upper = Coat(n=1.5, thickness=1.0, absorption=0.2, distribution="beckmann", m=0.25)
    model = WeidlichWilkie([upper, _clear_coat("smooth", n=1.5, thickness=3.0)], base, form=form)
    simple, reasons = simplify_material(model, name="m")
    assert isinstance(simple, WeidlichWilkie) and simple.coats == [upper] and simple.coats[0] is upper
    assert reasons == [("coat 2 of 'm' is index-matched (n = 1.5 = coat 1 above) and clear "
                        "(absorption·thickness = 0): skipped")]
    assert (simple.form, simple.t_term, simple.transmission_normal, simple.shadowing) == \
        (model.form, model.t_term, model.transmission_normal, model.shadowing)
    wi, wo = _directions(400, 21)
    _assert_same_eval(model, simple, wi, wo)
    _assert_same_delta(model, simple)
    # it is exactly the one-coat stack built directly (options, base configuration, sampler)
    ref = WeidlichWilkie(upper, base, form=form)
    sp = _point(wo, lam=LAMS, L=LAMS.size)
    np.testing.assert_array_equal(simple.eval(sp, wi).matrix(), ref.eval(sp, wi).matrix())
    np.testing.assert_array_equal(simple.pdf(sp, wi), ref.pdf(sp, wi))


@pytest.mark.parametrize("form", FORMS)
def test_matched_top_coat_of_a_stack_and_a_middle_coat(form):
    lam = Lambert(ConstantSpectrum(0.9))
    c_mid = Coat(n=1.8, distribution="blinn", exponent=60.0, thickness=1.0, absorption=0.05)
    c_low = Coat(n=1.4, thickness=0.5, absorption=0.3)
    # top matched to the exterior; the third coat matched to the second (clear: zero thickness, α > 0)
    model = WeidlichWilkie([_clear_coat("beckmann", n=1.0), c_mid, Coat(n=1.8, absorption=5.0), c_low],
                           lam, form=form, t_term="t21" if form == "published" else "ww", shadowing="smith",
                           layer_cosine_fraction=0.5)
    simple, reasons = simplify_material(model)
    assert simple.coats == [c_mid, c_low] and simple.t_term == model.t_term and simple.shadowing == "smith"
    assert simple.w_c == simple.base.w_c == 0.5                    # an explicit option is kept on every level
    assert [r.split(" is ")[0] for r in reasons] == ["coat 1 of 'weidlich_wilkie'", "coat 3 of 'weidlich_wilkie'"]
    wi, wo = _directions(400, 22)
    _assert_same_eval(model, simple, wi, wo)
    _assert_same_delta(model, simple)


def test_nested_ww_base_is_simplified():
    ts = TorranceSparrow(0.2, 3.0, 0.3)
    inner = WeidlichWilkie([_clear_coat("smooth", n=1.5), _clear_coat("beckmann", n=1.5, thickness=2.0)], ts)
    model = WeidlichWilkie(Coat(n=1.5, distribution="beckmann", m=0.3), inner)
    simple, reasons = simplify_material(model, name="lacquer")
    # the base stack (exterior = the outer coat, 1.5) loses both coats; the outer coat stays, over the TS
    assert isinstance(simple, WeidlichWilkie) and len(simple.coats) == 1 and isinstance(simple.base, TorranceSparrow)
    assert simple.base.exterior_n == 1.5
    assert all("the base of 'lacquer'" in r for r in reasons) and len(reasons) == 3
    wi, wo = _directions(300, 23)
    _assert_same_eval(model, simple, wi, wo)


# ---------------------------------------------------------------------------------------------
# (c) counter-examples: nothing to skip, or skipping would change the BSDF
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("coat", [
    Coat(n=1.0 + 1e-6),                                            # index off by 1e-6
    Coat(n=float(np.nextafter(1.0, 0.0))),                         # off by one ulp
    Coat(n=1.0, thickness=1.0, absorption=1e-9),                   # absorbing (α·d > 0)
    Coat(n=1.0, thickness=2.0, absorption=0.3, distribution="beckmann", m=0.3),
    Coat(n=1.5, thickness=1.0, absorption=0.0),                    # clear but mismatched
    Coat(n=1.5, distribution="blinn", exponent=20.0),
], ids=["n+1e-6", "n-1ulp", "tiny-absorption", "absorbing-rough", "clear-mismatched", "clear-mismatched-rough"])
@pytest.mark.parametrize("base_name", ["lambert", "ts_conductor"])
def test_not_simplified(coat, base_name):
    model = WeidlichWilkie(coat, BASES[base_name]())
    assert not index_matched_and_clear(coat, model.exterior_n)
    simple, reasons = simplify_material(model)
    assert simple is model and reasons == []


def test_non_ww_materials_unchanged():
    for name in sorted(BASES):
        m = BASES[name]()
        if isinstance(m, WeidlichWilkie):
            continue
        assert simplify_material(m) == (m, [])
    sc = SmoothConductor(ConstantSpectrum(0.2), ConstantSpectrum(3.0))
    assert simplify_material(sc)[0] is sc


@pytest.mark.parametrize("base_name", ["htsg", "coated_smooth"])
def test_rough_matched_coat_over_a_dirac_lobe_is_kept(base_name):
    """A rough coat has no Dirac lobe and hides the base's (WeidlichWilkie: "ignored under a rough coat")."""
    base = BASES[base_name]()
    model = WeidlichWilkie(_clear_coat("beckmann"), base)
    assert simplify_material(model) == (model, [])
    assert model.delta_reflection(_point(_col(_direction(30.0, 0.0)))) is None
    assert base.delta_reflection(_point(_col(_direction(30.0, 0.0)))) is not None


def test_energy_form_lowest_matched_coat_over_diffuse_base_is_kept():
    """simplify keeps the lower coat of [1.5 rough, 1.5 smooth] over Lambert in the energy form (its rule for
    the internal-reflection factor c_ms); since issue 19 the stack evaluates the null coat's base directly,
    so keeping or skipping it gives the same value."""
    lam = Lambert(ConstantSpectrum(0.8))
    upper = Coat(n=1.5, distribution="beckmann", m=0.3)
    model = WeidlichWilkie([upper, _clear_coat("smooth", n=1.5)], lam)
    assert simplify_material(model) == (model, [])
    wi, wo = _random_pairs(50, 31)
    sp = _point(wo)
    ratio = WeidlichWilkie(upper, lam).eval(sp, wi).matrix()[0, 0] / model.eval(sp, wi).matrix()[0, 0]
    np.testing.assert_allclose(ratio, 1.0, rtol=1e-9)     # was > 1.5 before issue 19 (c_ms lost)
    # the published form has no such factor: there the coat goes
    pub = WeidlichWilkie([upper, _clear_coat("smooth", n=1.5)], lam, form="published")
    simple, reasons = simplify_material(pub)
    assert len(simple.coats) == 1 and len(reasons) == 1
    _assert_same_eval(pub, simple, *_directions(200, 32))
    # nor an energy-form stack over a WW base that keeps a coat over the Lambert
    nested = WeidlichWilkie(upper, WeidlichWilkie([_clear_coat("smooth", n=1.5), _clear_coat("smooth", n=1.5)], lam))
    simple, reasons = simplify_material(nested)
    assert isinstance(simple.base, WeidlichWilkie) and len(simple.base.coats) == 1 and len(reasons) == 1
    _assert_same_eval(nested, simple, *_directions(200, 33))


# ---------------------------------------------------------------------------------------------
# (d) the input is never modified
# ---------------------------------------------------------------------------------------------

def _snapshot(m):
    levels, out = [m], []
    while isinstance(levels[-1].base, WeidlichWilkie) or len(levels[-1].coats) > 1:
        levels.append(levels[-1].base)
    for lv in levels:
        out.append((id(lv), tuple(id(c) for c in lv.coats), [copy.copy(c.__dict__) for c in lv.coats],
                    id(lv.base), repr(lv.exterior_n), lv.form, lv.w_c, lv.describe()))
    out.append((id(levels[-1].base), copy.copy(levels[-1].base.__dict__)))
    return out


def test_input_is_not_modified():
    ts = TorranceSparrow(0.2, 3.0, 0.3)
    inner = WeidlichWilkie([_clear_coat("smooth", n=1.5), Coat(n=1.6, distribution="beckmann", m=0.2)], ts)
    model = WeidlichWilkie([_clear_coat("smooth"), Coat(n=1.5, distribution="beckmann", m=0.3),
                            _clear_coat("smooth", n=1.5)], inner, exterior_n=1.0)
    wi, wo = _random_pairs(100, 41)
    sp = _point(wo)
    before, M0 = _snapshot(model), model.eval(sp, wi).matrix()
    ts_before = copy.copy(ts.__dict__)
    simple, reasons = simplify_material(model)
    assert len(reasons) == 3 and simple is not model
    assert _snapshot(model) == before and ts.__dict__ == ts_before
    np.testing.assert_array_equal(model.eval(sp, wi).matrix(), M0)
    # the reduced material does not share mutable WeidlichWilkie levels with the input
    assert simple is not model.base and simple.base is not inner


# ---------------------------------------------------------------------------------------------
# (e) sampling: the reduced material's estimator has the same expectation
# ---------------------------------------------------------------------------------------------

def _mc_albedo(model, theta_o, n, seed):
    """Mean and standard error of the sampled weight M00 (incl. Dirac lobes) at viewer angle θ_o."""
    wo = np.tile(_col(_direction(theta_o, 25.0)), (1, n))
    rng = np.random.default_rng(seed)
    bs = model.sample(_point(wo, lam=LAMS, L=LAMS.size), rng.random(n), rng.random((2, n)))
    w = bs.weight.matrix()[0, 0].mean(axis=0)               # mean over the path's 4 wavelengths
    assert np.all(np.isfinite(w))
    return float(w.mean()), float(w.std() / math.sqrt(n))


@pytest.mark.parametrize("base_name,dist", [("lambert", "beckmann"), ("lambert", "smooth"), ("gold", "smooth"),
                                            ("ts_diffuse", "blinn"), ("coated_rough", "beckmann"),
                                            ("coated_smooth", "smooth"), ("htsg", "smooth")])
def test_sampled_albedo_agrees(base_name, dist):
    model = WeidlichWilkie(_clear_coat(dist), BASES[base_name]())
    simple, reasons = simplify_material(model)
    assert reasons
    n = 40_000
    for k, theta in enumerate((0.0, 45.0, 80.0)):
        a, sa = _mc_albedo(model, theta, n, 100 + k)
        b, sb = _mc_albedo(simple, theta, n, 200 + k)
        assert abs(a - b) <= 4.0 * math.hypot(sa, sb) + 1e-12, (theta, a, sa, b, sb)


def test_pdf_is_the_reduced_materials_own():
    """``pdf`` is not preserved: the stack's proposal (P_top ≥ 0.05 for the coat lobe, cosine mixture)
    differs from the base's.  The reduced material's pdf is exactly its sampler's (the base's)."""
    base = TorranceSparrow(0.2, 3.0, 0.3)
    model = WeidlichWilkie(_clear_coat("beckmann"), base)
    simple, _ = simplify_material(model)
    wi, wo = _random_pairs(500, 51)
    sp = _point(wo)
    np.testing.assert_array_equal(simple.pdf(sp, wi), base.pdf(sp, wi))
    assert not np.allclose(model.pdf(sp, wi), simple.pdf(sp, wi))
