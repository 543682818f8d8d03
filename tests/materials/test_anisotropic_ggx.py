"""Anisotropic GGX polarising reflection (engine.materials.anisotropic_ggx: Blender's Anisotropic and
Anisotropic Rotation inputs as Cycles applies them).

Oracles: the isotropic limit is Torrance–Sparrow's GGX lobe (height-correlated Smith) to rounding; the
anisotropic lobe against a scalar transcription of Cycles' formulas (bsdf_aniso_D, bsdf_aniso_lambda, the
eval/pdf of bsdf_microfacet_eval) in a frame built here; D's normalisation and the visible-normal identity
∫ G1 (ω·h)⁺ D dω_h = cosθ by quadrature; chi-square of the sampler; the lobe's axes (wider along T, a
quarter turn swaps them); white furnaces by an independent quadrature of eval (single scattering ≤ 1,
the "lobe" compensation 1 within 1 %, Cycles' compensation with its isotropic α = √(α_x α_y) as Cycles
has it); realisable matrices; finite values at the hard cases (grazing, α = 1e-4, α ratio 10, tangent ∥
normal)."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from engine.materials import ggx_energy
from engine.materials.anisotropic_ggx import (AnisotropicGGX, LobeAlbedoTable, anisotropic_albedo, cycles_alphas,
                                              ggx_aniso_D, ggx_aniso_lambda)
from engine.materials.base import ShadingPoint
from engine.materials.flags import BSDFFlags
from engine.materials.roughness import ALPHA_MIN as M_MIN
from engine.materials.torrance_sparrow import SpecularAlbedoTable, TorranceSparrow
from engine.polarisation.fresnel import fresnel_reflectance, fresnel_reflection_abcs
from engine.polarisation.mueller import is_realisable
from engine.polarisation.thin_film import film_reflection_abcs
from engine.spectral.film_channels import film_band_reflectance
from engine.spectral import RGBUnboundedSpectrum, named_ior
from engine.spectral.gulbrandsen import GulbrandsenIndex
from engine.textures.conductor_index import TexturedGulbrandsenIndex
from engine.textures.inputs import TexturedSpectrum, TextureInput
from engine.textures.surface import SurfacePoints, VertexAttributes
from engine.textures.texture import VertexColour
from tests.materials.test_rough_dielectric import sphere_quadrature
from tests.support import chi2

# --- helpers ---------------------------------------------------------------------------------------------

Z = np.array([0.0, 0.0, 1.0])


def sph(theta_deg, phi_deg=0.0):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def tile(v, n):
    return np.tile(np.asarray(v, dtype=np.float64).reshape(3, 1), (1, n))


def point(wo, normal=None, lam=550.0, surface=None):
    """ShadingPoint for views wo (3, N), normal +z (or (3, N)), one wavelength unless lam is (L, N)."""
    wo = np.asarray(wo, dtype=np.float64).reshape(3, -1)
    n = wo.shape[1]
    nrm = tile(Z, n) if normal is None else np.asarray(normal, dtype=np.float64)
    lam = np.full((1, n), float(lam)) if np.isscalar(lam) else np.asarray(lam, dtype=np.float64)
    return ShadingPoint(np.zeros((3, n)), nrm, nrm, wo, lam, surface=surface)


def fixed_tangent(t):
    """A tangent callable returning the constant vector t at every point."""
    t = np.asarray(t, dtype=np.float64)
    return lambda sp: tile(t, sp.n)


def random_units(rng, n):
    v = rng.normal(size=(3, n))
    return v / np.linalg.norm(v, axis=0)


def random_geometry(rng, n):
    """(normal, wo, wi) (3, n) each, wo and wi on the normal's side."""
    nrm = random_units(rng, n)
    wo, wi = random_units(rng, n), random_units(rng, n)
    wo = np.where(np.sum(wo * nrm, axis=0) < 0, -wo, wo)
    wi = np.where(np.sum(wi * nrm, axis=0) < 0, -wi, wi)
    return nrm, wo, wi


def uv_surface(beta, n, rng, colours=None):
    """SurfacePoints of n hits on one triangle in the xy plane whose +u direction is (cos β, sin β, 0)
    (``colours``: a (3, 3) colour attribute "Col" at its vertices)."""
    c, s = math.cos(beta), math.sin(beta)
    verts = np.array([[0.0, 0.0, 0.0], [c, s, 0.0], [-s, c, 0.0]])
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    layers = {} if colours is None else {"Col": np.asarray(colours, dtype=np.float64)}
    attrs = VertexAttributes(np.array([[0, 1, 2]]), uv, layers, vertices=verts)
    b1 = rng.random(n) * 0.5
    b2 = rng.random(n) * 0.5
    return SurfacePoints(attrs, np.zeros(n, dtype=np.int64), b1, b2)


def m00(value):
    return value.A[0] + (0.0 if value.depol is None else value.depol[0])


def white(ax, ay, **kw):
    """F ≡ 1 up to 1e-16 (κ = 1e8), tangent +x."""
    return AnisotropicGGX(1.0, 1e8, ax, ay, tangent=fixed_tangent([1.0, 0.0, 0.0]), **kw)


def energy(model, wo):
    """∫ M00 cosθ_i dω_i over the hemisphere by a polar quadrature about the mirror direction (independent
    of the sampler)."""
    mirror = wo * np.array([-1.0, -1.0, 1.0])
    v, W = sphere_quadrature(mirror, n_phi=192, panels=40)
    val = model.eval(point(tile(wo, v.shape[1])), v)
    return float(np.sum(m00(val) * np.maximum(v[2], 0.0) * W))


# --- Cycles' parameters ----------------------------------------------------------------------------------


def test_cycles_alphas():
    assert cycles_alphas(0.5, 0.0) == (0.25, 0.25)
    aspect = math.sqrt(1.0 - 0.9 * 0.6)
    ax, ay = cycles_alphas(0.5, 0.6)
    assert ax == pytest.approx(0.25 / aspect, rel=1e-15) and ay == pytest.approx(0.25 * aspect, rel=1e-15)
    assert ax * ay == pytest.approx(0.25 ** 2, rel=1e-14)          # Cycles' table α √(α_x α_y) is r²
    ax, ay = cycles_alphas(1.0, 1.0)                               # α_x saturated at 1 (bsdf_microfacet_ggx_setup)
    assert ax == 1.0 and ay == pytest.approx(math.sqrt(0.1), rel=1e-15)
    assert cycles_alphas(0.3, 1.0)[0] / cycles_alphas(0.3, 1.0)[1] == pytest.approx(10.0, rel=1e-12)
    assert cycles_alphas(2.0, -1.0) == (1.0, 1.0)                  # inputs clipped to [0, 1]


# --- the isotropic limit is Torrance–Sparrow's GGX lobe --------------------------------------------------


def _gulbrandsen():
    base = RGBUnboundedSpectrum([0.9, 0.6, 0.3])
    return GulbrandsenIndex(base, base, "n", "schlick"), GulbrandsenIndex(base, base, "k", "schlick")


INDICES = {"gold-ish": (0.2, 3.0), "glass": (1.5, 0.0), "inside": (0.7, 0.0), "Au": named_ior("Au"),
           "gulbrandsen": _gulbrandsen()}


@pytest.mark.parametrize("multiscatter", [False, True])
@pytest.mark.parametrize("alpha", [M_MIN, 0.02, 0.3, 1.0])
@pytest.mark.parametrize("index", list(INDICES))
def test_isotropic_limit_is_torrance_sparrow(index, alpha, multiscatter):
    n, k = INDICES[index]
    rng = np.random.default_rng(7)
    N = 3000
    nrm, wo, wi = random_geometry(rng, N)
    # a third of the pairs near the specular peak (the lobe is narrow at small α)
    near = slice(0, N // 3)
    refl = 2.0 * np.sum(wo * nrm, axis=0) * nrm - wo
    wi[:, near] = refl[:, near] + 3.0 * alpha * random_units(rng, N // 3)
    wi /= np.linalg.norm(wi, axis=0)
    lam = np.tile(np.array([[450.0], [550.0], [650.0]]), (1, N))
    sp = point(wo, nrm, lam)
    ours = AnisotropicGGX(n, k, alpha, alpha, rotation=0.3, multiscatter=multiscatter)
    ts = TorranceSparrow(n, k, alpha, distribution="ggx", shadowing="smith_correlated", multiscatter=multiscatter)
    a, b = ours.eval(sp, wi), ts.eval(sp, wi)
    Ma, Mb = a.matrix(), b.matrix()
    assert np.all(np.isfinite(Ma))
    scale = np.abs(Mb).max()
    assert scale > 0
    np.testing.assert_allclose(Ma, Mb, rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_allclose(a.x_in, b.x_in, atol=1e-12)
    np.testing.assert_allclose(a.x_out, b.x_out, atol=1e-12)
    if multiscatter:
        np.testing.assert_allclose(a.depol, b.depol, rtol=1e-12, atol=1e-12 * scale)
        np.testing.assert_allclose(ours.multiscatter_extra(sp), ts.multiscatter_extra(sp), rtol=1e-12)
    pa, pb = ours.pdf(sp, wi), ts.pdf(sp, wi)
    np.testing.assert_allclose(pa, pb, rtol=1e-12, atol=1e-12 * pb.max())
    # the same sampler (the same local frame for an isotropic lobe): the same samples
    u_lobe, u_dir = rng.random(N), rng.random((2, N))
    sa, sb = ours.sample(sp, u_lobe, u_dir), ts.sample(sp, u_lobe, u_dir)
    assert np.array_equal(sa.valid, sb.valid)
    np.testing.assert_allclose(sa.wi, sb.wi, atol=1e-12)
    np.testing.assert_allclose(sa.pdf, sb.pdf, rtol=1e-12, atol=1e-12 * sb.pdf.max())
    Wa, Wb = sa.weight.matrix(), sb.weight.matrix()
    np.testing.assert_allclose(Wa, Wb, rtol=1e-10, atol=1e-12 * max(np.abs(Wb).max(), 1.0))


def test_per_point_gulbrandsen_index():
    """The textured (per-point) Gulbrandsen index of engine.textures.conductor_index, read through sp.spectrum
    at the points' colours: the isotropic limit is Torrance–Sparrow's with the same index; anisotropic values are
    finite, wavelength dependent and depend on the surface."""
    colour = TexturedSpectrum(TextureInput(VertexColour("Col")))
    n, k = (TexturedGulbrandsenIndex(colour, colour, part, "schlick") for part in ("n", "k"))
    rng = np.random.default_rng(12)
    N = 500
    _, wo, wi = random_geometry(rng, N)
    wo[2], wi[2] = np.abs(wo[2]), np.abs(wi[2])
    surface = uv_surface(0.3, N, rng, colours=[[0.9, 0.6, 0.2], [0.95, 0.95, 0.9], [0.5, 0.8, 0.3]])
    lam = np.tile(np.array([[450.0], [550.0], [650.0]]), (1, N))
    sp = point(wo, lam=lam, surface=surface)
    for multiscatter in (False, True):
        ours = AnisotropicGGX(n, k, 0.2, 0.2, multiscatter=multiscatter)
        ts = TorranceSparrow(n, k, 0.2, distribution="ggx", multiscatter=multiscatter)
        Mb = ts.eval(sp, wi).matrix()
        np.testing.assert_allclose(ours.eval(sp, wi).matrix(), Mb, rtol=1e-12, atol=1e-12 * np.abs(Mb).max())
        assert ours.varies_over_surface and ours.flags.wavelength_dependent
    aniso = AnisotropicGGX(n, k, 0.4, 0.05, rotation=0.1, multiscatter=True)
    M = aniso.eval(sp, wi).matrix()
    assert np.all(np.isfinite(M)) and np.all(M[0, 0] >= 0) and np.abs(M[0, 0, 0] - M[0, 0, 2]).max() > 0


def test_nearly_isotropic_lobe_in_any_frame_is_torrance_sparrow():
    """The anisotropic code path (tangent frame from a surface, rotated) with α_y = α_x(1 + 1e-9): TS's lobe
    to 1e-7 — the frame matters only through the anisotropy."""
    rng = np.random.default_rng(3)
    N = 2000
    _, wo, wi = random_geometry(rng, N)
    wo[2], wi[2] = np.abs(wo[2]), np.abs(wi[2])
    sp = point(wo, surface=uv_surface(0.7, N, rng))
    alpha = 0.2
    ours = AnisotropicGGX(0.3, 2.0, alpha, alpha * (1.0 + 1e-9), rotation=0.37)
    assert ours.varies_over_surface
    ts = TorranceSparrow(0.3, 2.0, alpha, distribution="ggx")
    Ma, Mb = ours.eval(sp, wi).matrix(), ts.eval(sp, wi).matrix()
    np.testing.assert_allclose(Ma, Mb, rtol=1e-7, atol=1e-9 * np.abs(Mb).max())
    pb = ts.pdf(sp, wi)
    np.testing.assert_allclose(ours.pdf(sp, wi), pb, rtol=1e-7, atol=1e-9 * pb.max())


# --- the anisotropic lobe against Cycles' formulas -------------------------------------------------------


def _cycles_reference(n_s, T, wo, wi, ax, ay, eta):
    """Scalar transcription of Cycles' bsdf_microfacet_eval (GGX, anisotropic reflection): f·cosθ_light and pdf,
    Cycles' I = the view (our ω_o), O = the light (our ω_i); f = F·D/(4 cos_I cos_O (1 + Λ_I + Λ_O))."""
    def nrm(v):
        return v / math.sqrt(v @ v)

    Yc = nrm(np.cross(n_s, T))                 # make_orthonormals_tangent
    Xc = np.cross(Yc, n_s)
    H = nrm(wo + wi)
    cos_NI, cos_NO = n_s @ wo, n_s @ wi

    def lam(V):
        a = ((ax * (Xc @ V)) ** 2 + (ay * (Yc @ V)) ** 2) / (n_s @ V) ** 2
        return 0.5 * (math.sqrt(1.0 + a) - 1.0)

    Hl = np.array([Xc @ H, Yc @ H, n_s @ H]) / np.array([ax, ay, 1.0])
    D = 1.0 / (math.pi * ax * ay * (Hl @ Hl) ** 2)
    F = float(fresnel_reflectance(np.array([H @ wo]), eta)[0])
    common = D / cos_NI * 0.25
    return F * common / (1.0 + lam(wo) + lam(wi)) / cos_NO, common / (1.0 + lam(wo)), H @ wo


@pytest.mark.parametrize("ax, ay, rotation", [(0.4, 0.04, 0.0), (0.05, 0.5, 0.13), (1.0, 0.1, -0.4), (0.3, 0.2, 2.25)])
def test_anisotropic_lobe_is_cycles(ax, ay, rotation):
    rng = np.random.default_rng(11)
    N = 300
    nrm, wo, wi = random_geometry(rng, N)
    T = random_units(rng, N)
    eta = complex(0.4, 2.5)
    model = AnisotropicGGX(0.4, 2.5, ax, ay, rotation=rotation, tangent=lambda sp: T)
    sp = point(wo, nrm)
    v = model.eval(sp, wi)
    pdf = model.pdf(sp, wi)
    for j in range(N):
        ang = 2.0 * math.pi * rotation            # Cycles' rotate_around_axis (Rodrigues, right-handed)
        t = T[:, j]
        nj = nrm[:, j]
        t = math.cos(ang) * t + math.sin(ang) * np.cross(nj, t) + (1.0 - math.cos(ang)) * (nj @ t) * nj
        f, p, cos_f = _cycles_reference(nj, t, wo[:, j], wi[:, j], ax, ay, eta)
        assert v.A[0, j] == pytest.approx(f, rel=1e-9, abs=1e-300)
        assert pdf[j] == pytest.approx(p, rel=1e-9, abs=1e-300)
        # the polarisation: the Fresnel ABCS at the facet angle, scaled by the same lobe value
        Af, Bf, Cf, Sf = (x[0, 0] for x in fresnel_reflection_abcs(np.array([[cos_f]]), np.array([[eta]])))
        scale = f / Af
        for got, want in zip((v.B[0, j], v.C[0, j], v.S[0, j]), (Bf, Cf, Sf)):
            assert got == pytest.approx(want * scale, rel=1e-9, abs=1e-12 * f)


@pytest.mark.parametrize("ax, ay", [(0.5, 0.05), (0.05, 0.5), (1.0, 0.1), (0.01, 0.3)])
def test_distribution_normalised_and_lambda_consistent(ax, ay):
    """∫ D cosθ_h dω_h = 1 and the visible-normal identity ∫ G1(ω) (ω·h)⁺ D(h) dω_h = cosθ (which ties Λ to
    D) for views at several azimuths, by polar quadrature about +z."""
    v, W = sphere_quadrature(Z, n_phi=384, panels=60)
    up = v[2] > 0
    h, W = v[:, up], W[up]
    D = ggx_aniso_D(h, ax, ay)
    assert float(np.sum(D * h[2] * W)) == pytest.approx(1.0, abs=2e-4)
    for theta, phi in ((0.0, 0.0), (40.0, 0.0), (70.0, 30.0), (85.0, 90.0), (60.0, 135.0)):
        w = sph(theta, phi)
        g1 = 1.0 / (1.0 + ggx_aniso_lambda(w[:, None], ax, ay)[0])
        proj = float(np.sum(g1 * np.maximum(w @ h, 0.0) * D * W))
        assert proj == pytest.approx(w[2], abs=3e-4), (theta, phi)


# --- sampling --------------------------------------------------------------------------------------------

SAMPLING_CASES = [
    # (θ_o, φ_o, α_x, α_y, rotation)
    (30.0, 20.0, 0.4, 0.06, 0.1),
    (70.0, 0.0, 0.08, 0.5, 0.0),
    (0.0, 0.0, 0.6, 0.2, 0.3),
    (60.0, 100.0, 1.0, 0.1, 0.0),
    (85.0, 45.0, 0.3, 0.1, 0.6),
]


@pytest.mark.parametrize("case", SAMPLING_CASES, ids=lambda c: f"th{c[0]}-ph{c[1]}-{c[2]}x{c[3]}-rot{c[4]}")
def test_sampling_chi2(case):
    """sample() directions follow pdf(): chi-square over (cosθ, φ) cells (+ one cell for invalid samples)."""
    theta, phi, ax, ay, rot = case
    model = AnisotropicGGX(0.2, 3.0, ax, ay, rotation=rot, tangent=fixed_tangent([1.0, 0.0, 0.0]))
    N = 100_000
    rng = np.random.default_rng(2024)
    wo = sph(theta, phi)
    s = model.sample(point(tile(wo, N)), rng.random(N), rng.random((2, N)))
    assert np.all(s.wi[2, s.valid] > 0)
    result = chi2.direction_sampler_test(s.wi, s.valid, lambda wi: model.pdf(point(tile(wo, wi.shape[1])), wi),
                                         n_cos=24, n_phi=48, order=8)
    chi2.assert_accepted(result, test_count=len(SAMPLING_CASES), what="anisotropic GGX samples")


@pytest.mark.parametrize("multiscatter", [False, True])
def test_sample_weight_is_eval_cos_over_pdf(multiscatter):
    rng = np.random.default_rng(5)
    N = 3000
    nrm, wo, _ = random_geometry(rng, N)
    lam = np.tile(np.array([[450.0], [550.0], [650.0]]), (1, N))
    Au = named_ior("Au")
    model = AnisotropicGGX(*Au, 0.6, 0.08, rotation=0.2, tangent=lambda sp: random_units(np.random.default_rng(1), N),
                           multiscatter=multiscatter)
    sp = point(wo, nrm, lam)
    s = model.sample(sp, rng.random(N), rng.random((2, N)))
    v = s.valid
    assert v.mean() > 0.5
    f = model.eval(sp, s.wi)
    pdf = model.pdf(sp, s.wi)
    np.testing.assert_allclose(s.pdf[v], pdf[v], rtol=1e-12)
    assert np.all(pdf[v] > 0) and np.all(s.pdf[~v] == 0)
    cos_i = np.sum(nrm * s.wi, axis=0)
    np.testing.assert_allclose(s.weight.matrix()[..., v], f.matrix()[..., v] * (cos_i[v] / pdf[v]), rtol=1e-12,
                               atol=1e-14)
    np.testing.assert_allclose(s.weight.x_in, f.x_in)
    assert np.all(s.weight.matrix()[..., ~v] == 0.0)


# --- where the anisotropy goes ---------------------------------------------------------------------------


@pytest.mark.parametrize("source", ["callable", "surface"])
def test_lobe_is_wider_along_the_tangent_and_a_quarter_turn_swaps_it(source):
    beta = 0.6                                        # the tangent's direction in the xy plane
    T = np.array([math.cos(beta), math.sin(beta), 0.0])
    B = np.cross(Z, T)
    angles = np.array([2.0, 5.0, 10.0, 20.0, 40.0, 70.0])
    N = angles.size
    rng = np.random.default_rng(0)
    surface = uv_surface(beta, N, rng) if source == "surface" else None
    kw = {} if source == "surface" else {"tangent": fixed_tangent(T)}
    ax, ay = 0.3, 0.03
    model = AnisotropicGGX(0.2, 3.0, ax, ay, **kw)
    turned = AnisotropicGGX(0.2, 3.0, ax, ay, rotation=0.25, **kw)
    half = AnisotropicGGX(0.2, 3.0, ax, ay, rotation=0.5, **kw)
    sp = point(tile(Z, N), surface=surface)           # normal view: the lobe is D about the normal
    X, Y = model.tangent_frame(sp)
    np.testing.assert_allclose(X, tile(T, N), atol=1e-12)
    np.testing.assert_allclose(Y, tile(B, N), atol=1e-12)
    th = np.radians(angles)
    along_T = np.cos(th) * Z[:, None] + np.sin(th) * T[:, None]
    along_B = np.cos(th) * Z[:, None] + np.sin(th) * B[:, None]
    pT, pB = model.pdf(sp, along_T), model.pdf(sp, along_B)
    assert np.all(pT > pB)
    assert np.all(m00(model.eval(sp, along_T)) > m00(model.eval(sp, along_B)))
    # a quarter turn (right-handed about n: T → n × T = B) swaps the axes; half a turn changes nothing
    np.testing.assert_allclose(turned.pdf(sp, along_B), pT, rtol=1e-10)
    np.testing.assert_allclose(turned.pdf(sp, along_T), pB, rtol=1e-10)
    np.testing.assert_allclose(half.pdf(sp, along_T), pT, rtol=1e-10)
    # the half-vector of a tilt θ in the plane (T, n) is tilted θ/2: D(θ/2 along T) / D(θ/2 along B)
    ratio = pT / pB
    t2 = np.tan(th / 2.0) ** 2
    np.testing.assert_allclose(ratio, ((1.0 + t2 / ay ** 2) / (1.0 + t2 / ax ** 2)) ** 2, rtol=1e-10)
    # the sampled directions spread along T: their spread in ω·T is several times that in ω·B
    M = 20000
    s = model.sample(point(tile(sph(10.0, 30.0), M), surface=uv_surface(beta, M, rng) if surface else None),
                     rng.random(M), rng.random((2, M)))
    w = s.wi[:, s.valid]
    assert np.std(T @ w) > 3.0 * np.std(B @ w)


def test_tangent_fallbacks():
    """No surface attributes: engine.vec3.local_frame's tangent; a tangent ∥ n (or zero, or NaN): the same."""
    rng = np.random.default_rng(4)
    N = 6
    nrm, wo, wi = random_geometry(rng, N)
    sp = point(wo, nrm)
    default = AnisotropicGGX(0.2, 3.0, 0.5, 0.05)
    X0, Y0 = default.tangent_frame(sp)
    np.testing.assert_allclose(np.sum(X0 * nrm, axis=0), 0.0, atol=1e-15)
    np.testing.assert_allclose(np.cross(nrm.T, X0.T).T, Y0, atol=1e-15)
    for bad in (lambda sp: sp.n_s, lambda sp: -3.0 * sp.n_s, lambda sp: np.zeros((3, sp.n)),
                lambda sp: np.full((3, sp.n), np.nan)):
        model = AnisotropicGGX(0.2, 3.0, 0.5, 0.05, tangent=bad, rotation=0.3)
        X, Y = model.tangent_frame(sp)
        assert np.all(np.isfinite(X)) and np.all(np.isfinite(Y))
        v = model.eval(sp, wi)
        assert np.all(np.isfinite(v.matrix()))
        assert np.all(np.isfinite(model.pdf(sp, wi)))


# --- energy ----------------------------------------------------------------------------------------------

FURNACE_ALPHAS = [cycles_alphas(0.5, 0.5), cycles_alphas(0.3, 1.0), (0.5, 0.05), (0.05, 0.5), (1.0, 0.1)]
FURNACE_VIEWS = [(0.0, 0.0), (30.0, 20.0), (60.0, 90.0), (75.0, 0.0), (85.0, 45.0)]


@pytest.mark.parametrize("alphas", FURNACE_ALPHAS, ids=lambda a: f"{a[0]:.3g}x{a[1]:.3g}")
def test_white_furnace(alphas):
    """F = 1: single scattering ≤ 1 (and loses energy), the "lobe" compensation returns 1 within 1 % at every
    view; Cycles' compensation is exactly Cycles' formula at α = √(α_x α_y) (conductor_extra)."""
    ax, ay = alphas
    single = white(ax, ay)
    lobe = white(ax, ay, multiscatter=True, multiscatter_albedo="lobe")
    cycles = white(ax, ay, multiscatter=True)
    for theta, phi in FURNACE_VIEWS:
        wo = sph(theta, phi)
        e_ss, e_ms = energy(single, wo), energy(lobe, wo)
        assert e_ss <= 1.0 + 1e-6 and e_ss < e_ms - 1e-3, (theta, phi, e_ss, e_ms)
        assert e_ms == pytest.approx(1.0, abs=1e-2), (theta, phi, e_ms)
        sp = point(wo[:, None])
        k = cycles.multiscatter_extra(sp)
        want = ggx_energy.conductor_extra(np.array([wo[2]]), math.sqrt(ax * ay), np.array([[1e8j + 1.0]]),
                                          correlated=True)
        np.testing.assert_allclose(k, want, rtol=1e-12)


def test_cycles_compensation_is_not_energy_conserving_for_strong_anisotropy():
    """Cycles reads its isotropic tables at √(α_x α_y) = r²: for r = 0.4, Anisotropic = 1 (α = 0.506, 0.051)
    the compensated white furnace at normal view is the anisotropic albedo over the isotropic one,
    0.818/0.968 ≈ 0.85 — Blender's render, not 1; mild anisotropy (r = 0.5, a = 0.2) stays within 1 %."""
    ax, ay = cycles_alphas(0.4, 1.0)
    e = energy(white(ax, ay, multiscatter=True), Z)
    E_lobe = anisotropic_albedo(Z[:, None], ax, ay)[0]
    E_iso = ggx_energy.conductor_albedo(np.array([1.0]), 0.16, correlated=True)[0]
    assert E_lobe == pytest.approx(0.818, abs=2e-3)
    assert e == pytest.approx(E_lobe / E_iso, abs=3e-3)
    assert e == pytest.approx(0.845, abs=5e-3)
    mild = white(*cycles_alphas(0.5, 0.2), multiscatter=True)
    for theta, phi in FURNACE_VIEWS[:3]:
        assert energy(mild, sph(theta, phi)) == pytest.approx(1.0, abs=1e-2)


def test_albedo_table_against_direct_quadrature():
    """The "lobe" table (bilinear in √μ and the azimuth coordinate) against the direct quadrature between nodes;
    the isotropic quadrature is engine.materials.ggx_energy's."""
    mu = np.array([0.05, 0.3, 0.7, 1.0])
    s = np.sqrt(1.0 - mu * mu)
    iso = anisotropic_albedo(np.stack((s, 0.0 * s, mu)), 0.4, 0.4)
    np.testing.assert_allclose(iso, ggx_energy.ggx_albedo(mu, 0.4, correlated=True), atol=1e-3)   # both rules ≲ 1e-3
    rng = np.random.default_rng(9)
    views = random_units(rng, 400)
    views[2] = np.abs(views[2])
    views = views[:, views[2] > 0.01]
    for ax, ay in ((0.5, 0.05), (0.05, 0.5), (1.0, M_MIN)):
        table = LobeAlbedoTable(ax, ay)
        np.testing.assert_allclose(table(views), anisotropic_albedo(views, ax, ay), atol=5e-3)


@pytest.mark.parametrize("mode", ["cycles", "lobe"])
def test_reflection_albedo(mode):
    """The layering albedo with the lobe's own Fresnel: Cycles' estimate (the isotropic GGX reflection table at
    √(α_x α_y), as Torrance–Sparrow's "albedo_scaling" table) or this lobe's, against a quadrature of eval."""
    ax, ay = 0.4, 0.04
    model = AnisotropicGGX(1.5, 0.0, ax, ay, tangent=fixed_tangent([1.0, 0.0, 0.0]), multiscatter=True,
                           multiscatter_albedo=mode)
    views = [(0.0, 0.0), (45.0, 30.0), (75.0, 90.0)]
    wo = np.stack([sph(t, p) for t, p in views], axis=1)
    E = model.reflection_albedo(point(wo))
    if mode == "cycles":
        a = math.sqrt(ax * ay)
        E_F = SpecularAlbedoTable(1.5 + 0j, a, a, "smith_correlated", "ggx")(wo[2], a)
        k = ggx_energy.conductor_extra(wo[2], a, np.array([[1.5 + 0j]]), correlated=True)[0]
        np.testing.assert_allclose(E, E_F * (1.0 + k), rtol=1e-12)
    else:
        for j in range(wo.shape[1]):
            assert E[j] == pytest.approx(energy(model, wo[:, j]), abs=5e-3)
    with pytest.raises(ValueError, match="constant n and k"):
        AnisotropicGGX(*named_ior("Au"), ax, ay).reflection_albedo(point(wo))


# --- thin film -------------------------------------------------------------------------------------------


def test_thin_film_replaces_the_facet_fresnel():
    """A film on every facet: the lobe's scalar part times Airy's coated-interface ABCS at the facet angle
    (engine.polarisation.thin_film); the isotropic limit is Torrance–Sparrow's filmed lobe where it has one."""
    rng = np.random.default_rng(21)
    N = 400
    nrm, wo, wi = random_geometry(rng, N)
    lam = np.tile(np.array([[450.0], [550.0], [650.0]]), (1, N))
    sp = point(wo, nrm, lam)
    T = random_units(rng, N)
    kw = dict(rotation=0.1, tangent=lambda sp: T, exterior_n=1.2)
    bare = AnisotropicGGX(1.5, 0.0, 0.5, 0.06, **kw)
    filmed = AnisotropicGGX(1.5, 0.0, 0.5, 0.06, film_n=1.33, film_thickness=400.0, multiscatter=True, **kw)
    assert filmed.creates_circular and filmed.flags.wavelength_dependent
    assert not bare.creates_circular and not bare.flags.wavelength_dependent
    assert AnisotropicGGX(1.5, 0.0, 0.5, 0.06, film_n=1.33, film_thickness=0.05).film is None
    vb, vf = bare.eval(sp, wi), filmed.eval(sp, wi)
    cos_f = np.minimum(0.5 * np.linalg.norm(wo + wi, axis=0), 1.0)[None, :]
    bare_abcs = fresnel_reflection_abcs(cos_f, np.array([[1.5 / 1.2]]))
    film_abcs = film_reflection_abcs(cos_f, 1.2, 1.33, 400.0, np.array([[1.5 + 0j]]), lam)
    lobe = np.where(bare_abcs[0] > 0, vb.A / bare_abcs[0], 0.0)
    for got, want in zip((vf.A, vf.B, vf.C, vf.S), film_abcs):
        np.testing.assert_allclose(got, want * lobe, rtol=1e-12, atol=1e-14 * np.abs(vf.A).max())
    assert np.abs(vf.S).max() > 0
    # the compensation keeps the substrate's F_ss (as Torrance–Sparrow's)
    np.testing.assert_allclose(vf.depol, filmed.multiscatter_extra(sp) * vf.A, rtol=1e-12)
    np.testing.assert_allclose(filmed.multiscatter_extra(sp),
                               AnisotropicGGX(1.5, 0.0, 0.5, 0.06, multiscatter=True, **kw).multiscatter_extra(sp))
    # layering albedo: the film's reflectance at the view angle, the largest of its colour channels' band averages
    # (tests/materials/test_thin_film_layering.py checks those against a quadrature)
    E = filmed.reflection_albedo(sp)
    cos_o = np.clip(np.sum(nrm * wo, axis=0), 0.0, 1.0)
    want = film_band_reflectance(cos_o, 1.2, 1.33, 400.0, 1.5 + 0j)
    np.testing.assert_allclose(E, want.max(axis=0), rtol=1e-12)
    assert "thin_film" in filmed.describe()
    if "film_n" in inspect.signature(TorranceSparrow).parameters:
        iso = AnisotropicGGX(0.3, 2.0, 0.3, 0.3, film_n=1.4, film_thickness=300.0, multiscatter=True)
        ts = TorranceSparrow(0.3, 2.0, 0.3, distribution="ggx", film_n=1.4, film_thickness=300.0, multiscatter=True)
        Mb = ts.eval(sp, wi).matrix()
        np.testing.assert_allclose(iso.eval(sp, wi).matrix(), Mb, rtol=1e-12, atol=1e-12 * np.abs(Mb).max())


# --- polarisation ----------------------------------------------------------------------------------------

DIRECTION = st.tuples(*(st.floats(-1.0, 1.0) for _ in range(3))).filter(lambda v: 1e-3 < np.linalg.norm(v))


@settings(deadline=None, max_examples=60, suppress_health_check=[HealthCheck.too_slow])
@given(wo=DIRECTION, wi=DIRECTION, ax=st.floats(1e-4, 1.0), ay=st.floats(1e-4, 1.0), n=st.floats(0.05, 20.0),
       k=st.floats(0.0, 20.0), rotation=st.floats(-1.0, 1.0))
def test_matrices_are_realisable(wo, wi, ax, ay, n, k, rotation):
    wo, wi = np.asarray(wo) / np.linalg.norm(wo), np.asarray(wi) / np.linalg.norm(wi)
    wo[2], wi[2] = abs(wo[2]), abs(wi[2])
    model = AnisotropicGGX(n, k, ax, ay, rotation=rotation, multiscatter=True)
    v = model.eval(point(wo[:, None]), wi[:, None])
    M = v.matrix()[:, :, 0, 0]
    assert np.all(np.isfinite(M)) and np.all(v.depol >= 0)
    if M[0, 0] > 0:
        assert is_realisable((M / M[0, 0])[:, :, None])[0]
        ss = AnisotropicGGX(n, k, ax, ay, rotation=rotation).eval(point(wo[:, None]), wi[:, None]).matrix()[:, :, 0, 0]
        assert is_realisable((ss / ss[0, 0])[:, :, None])[0]
        assert abs(M[1, 0]) / M[0, 0] <= abs(ss[1, 0]) / ss[0, 0] + 1e-12   # the added energy is depolarised


# --- hard cases ------------------------------------------------------------------------------------------

HARD_ALPHAS = [(M_MIN, M_MIN), (M_MIN, 1.0), (1.0, M_MIN), (0.1, 1.0), (1.0, 0.1), (0.01, 0.1)]


@pytest.mark.parametrize("alphas", HARD_ALPHAS, ids=lambda a: f"{a[0]:g}x{a[1]:g}")
@pytest.mark.parametrize("multiscatter", ["off", "cycles", "lobe"])
def test_hard_cases_are_finite(alphas, multiscatter):
    ax, ay = alphas
    if multiscatter == "lobe" and ax == ay == M_MIN:
        pytest.skip("same table as the isotropic minimum")
    kw = {} if multiscatter == "off" else {"multiscatter": True, "multiscatter_albedo": multiscatter}
    grazing = [sph(90.0, 0.0), sph(90.0, 90.0), np.array([1.0, 0.0, 1e-12]), np.array([0.6, 0.8, 1e-300])]
    normal = [Z, sph(1e-9, 30.0)]
    generic = [sph(45.0, 10.0), sph(80.0, 100.0), sph(89.9, 45.0)]
    dirs = grazing + normal + generic
    wo = np.stack([d / np.linalg.norm(d) for d in dirs for _ in dirs], axis=1)
    wi = np.stack([d / np.linalg.norm(d) for _ in dirs for d in dirs], axis=1)
    # exact specular and exact backscatter pairs
    wi_spec = wo * np.array([[-1.0], [-1.0], [1.0]])
    wo, wi = np.concatenate((wo, wo, wo), axis=1), np.concatenate((wi, wi_spec, wo), axis=1)
    N = wo.shape[1]
    lam = np.tile(np.array([[450.0], [650.0]]), (1, N))
    for tangent in (None, lambda sp: sp.n_s, fixed_tangent([0.3, -0.2, 0.9])):
        model = AnisotropicGGX(0.2, 3.0, ax, ay, rotation=0.1, tangent=tangent, **kw)
        sp = point(wo, lam=lam)
        v = model.eval(sp, wi)
        M = v.matrix()
        assert np.all(np.isfinite(M)) and np.all(M[0, 0] >= 0)
        assert np.all(np.isfinite(v.x_in)) and np.allclose(np.sum(v.x_in ** 2, axis=0), 1.0)
        p = model.pdf(sp, wi)
        assert np.all(np.isfinite(p)) and np.all(p >= 0)
        rng = np.random.default_rng(1)
        s = model.sample(sp, rng.random(N), rng.random((2, N)))
        assert np.all(np.isfinite(s.weight.matrix())) and np.all(np.isfinite(s.pdf)) and np.all(s.pdf >= 0)
        assert np.all(np.isfinite(s.wi[:, s.valid]))
        # eval vanishes below and on the horizon (one-sided)
        flat = (wo[2] <= 1e-200) | (wi[2] <= 1e-200)
        assert np.all(M[..., flat] == 0.0)


# --- construction, flags, description --------------------------------------------------------------------


def test_flags_and_surface_dependence():
    glass = AnisotropicGGX(1.5, 0.0, 0.3, 0.1)
    assert glass.flags & BSDFFlags.GLOSSY_REFLECTION and glass.polarising
    assert not glass.creates_circular and not glass.flags.wavelength_dependent and not glass.transmits
    metal = AnisotropicGGX(*named_ior("Au"), 0.3, 0.1)
    assert metal.creates_circular and metal.flags.wavelength_dependent
    assert AnisotropicGGX(0.7, 0.0, 0.3, 0.1).creates_circular            # total internal reflection
    assert AnisotropicGGX(0.2, 3.0, 0.3, 0.1).varies_over_surface
    assert not AnisotropicGGX(0.2, 3.0, 0.3, 0.3).varies_over_surface
    assert not metal.delta_only and metal.delta_reflection(point(tile(Z, 1))) is None
    d = AnisotropicGGX(0.2, 3.0, 0.3, 0.1, rotation=0.25, multiscatter=True).describe()
    assert d["type"] == "anisotropic_ggx" and d["alpha_x"] == 0.3 and d["alpha_y"] == 0.1
    assert d["rotation"] == 0.25 and d["multiscatter"] is True and d["multiscatter_albedo"] == "cycles"


@pytest.mark.parametrize("kw, match", [
    ({"alpha_x": 0.5 * M_MIN}, "alpha_x"), ({"alpha_y": float("nan")}, "alpha_y"),
    ({"alpha_x": 1.5, "multiscatter": True}, "multiscatter"), ({"multiscatter_albedo": "exact"}, "multiscatter_albedo"),
    ({"rotation": float("inf")}, "rotation"), ({"exterior_n": 0.0}, "exterior_n"), ({"tangent": 3}, "tangent")])
def test_invalid_parameters(kw, match):
    args = {"alpha_x": 0.3, "alpha_y": 0.1, **kw}
    with pytest.raises(ValueError, match=match):
        AnisotropicGGX(0.2, 3.0, **args)


@pytest.mark.parametrize("key, texels, base", [
    ("anisotropic", [0.0, 0.45, 1.0], {"type": "principled", "metallic": 1.0, "roughness": 0.4}),
    ("anisotropic", [0.2, 0.9], {"type": "principled", "roughness": 0.35, "base_color": [0.6, 0.2, 0.1]}),
    ("anisotropic_rotation", [0.0, 0.125, 0.3], {"type": "principled", "metallic": 1.0, "roughness": 0.4,
                                                 "anisotropic": 0.8})])
def test_per_point_anisotropy_is_the_constant_lobe_per_texel(tmp_path, key, texels, base):
    """Anisotropic (α_x, α_y per point) or its Rotation from a texture: at each texel the lobe with that constant
    value (eval, pdf, sample)."""
    from tests.support.texel_rows import textured_and_constant
    sp, wi, u_lobe, u_dir, textured, rows = textured_and_constant(tmp_path, base, key, texels, reps=30, seed=3)
    assert textured.varies_over_surface
    f, pdf, s = textured.eval(sp, wi).matrix(), textured.pdf(sp, wi), textured.sample(sp, u_lobe, u_dir)
    for sel, _, const, sub in rows:
        np.testing.assert_allclose(f[..., sel], const.eval(sub, wi[:, sel]).matrix(), rtol=1e-9, atol=1e-13)
        np.testing.assert_allclose(pdf[sel], const.pdf(sub, wi[:, sel]), rtol=1e-9, atol=1e-13)
        cs = const.sample(sub, u_lobe[sel], u_dir[:, sel])
        np.testing.assert_allclose(s.wi[:, sel], cs.wi, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(s.weight.matrix()[..., sel], cs.weight.matrix(), rtol=1e-9, atol=1e-13)
