"""The mix material (engine.materials.mix): f = Σ w_k·f_k of other models, checked against the
components evaluated on their own (never against the mix itself): values, densities, sampling
weights and their expectations, frames, textured and unnormalised weights, shading normals, the
scene format and renders."""

import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.materials.base import BSDF, BSDFFlags, BSDFSample, MuellerValue, ShadingPoint
from engine.materials.dielectric import SmoothDielectric
from engine.materials.evaluate import mueller_at
from engine.materials.normal_map import ShadingNormal
from engine.materials.lambert import Lambert
from engine.materials.mix import Layered, Mix, MixShadingPoint, rotate_mueller_batch
from engine.materials.sampling import cosine_hemisphere, local_to_world
from engine.polarisation.frames import rotate_mueller_frames, scattering_plane_axis, sp_basis_axis
from engine.polarisation.mueller import is_realisable, mueller_from_jones
from engine.render.renderer import Renderer
from engine.scene.loader import parse_material, parse_scene
from engine.spectral import ConstantSpectrum
from engine.spectral.spectrum import WavelengthLookup
from engine.textures import SurfacePoints, VertexAttributes
from engine.vec3 import cross, dot

F = BSDFFlags
LAM = np.array([[450.0], [520.0], [600.0], [680.0]])


def unit(v):
    return v / np.linalg.norm(v, axis=0)


def points(n, rng, surface=None, n_s=None):
    """Shading points with normal +z (or ``n_s``), viewers in the upper hemisphere, four wavelengths."""
    n_s = np.tile([[0.0], [0.0], [1.0]], (1, n)) if n_s is None else n_s
    wo = rng.normal(size=(3, n))
    wo[2] = np.abs(wo[2]) + 0.05
    lam = np.tile(LAM, (1, n))
    return ShadingPoint(np.zeros((3, n)), n_s, n_s.copy(), unit(wo), lam, False, WavelengthLookup(lam), None, surface)


def upper(n, rng):
    w = rng.normal(size=(3, n))
    w[2] = np.abs(w[2]) + 0.05
    return unit(w)


def lambert(a):
    return Lambert(ConstantSpectrum(a))


def in_basis(value: MuellerValue, wi, wo) -> np.ndarray:
    """A value's matrix (4, 4, L, N) in the oracles' s-p basis of each beam (frame-independent)."""
    M = value.matrix()
    if value.kind == "depolarising":
        return M
    k_in, k_out = -wi, wo
    return rotate_mueller_frames(M, value.x_in[:, None, :], sp_basis_axis(k_in)[:, None, :], k_in[:, None, :],
                                 value.x_out[:, None, :], sp_basis_axis(k_out)[:, None, :], k_out[:, None, :])


class Fixed(BSDF):
    """A test model: a fixed realisable Mueller matrix per wavelength (times cosθ_i-independent 1/π), given
    in frames turned by ``turn_in``/``turn_out`` (rad) from the scattering plane, sampled cosine-weighted."""

    flags = F.GLOSSY_REFLECTION | F.POLARISING | F.RETARDING | F.WAVELENGTH_DEPENDENT

    def __init__(self, M, turn_in, turn_out):
        self.M, self.turn_in, self.turn_out = M, turn_in, turn_out       # M: (4, 4, L)

    def _frames(self, wi, wo):
        k_in, k_out = -wi, wo
        s = scattering_plane_axis(k_in, k_out)
        turn = lambda k, a: math.cos(a) * s + math.sin(a) * cross(k, s)  # noqa: E731
        return turn(k_in, self.turn_in), turn(k_out, self.turn_out)

    def eval(self, sp, wi):
        front = (dot(sp.n_s, wi) > 0) & (sp.cos_o > 0)
        x_in, x_out = self._frames(wi, sp.wo)
        M = self.M[..., None] * (front / np.pi)[None, None, None, :]
        return MuellerValue("general", x_in, x_out, M=M)

    def pdf(self, sp, wi):
        c = dot(sp.n_s, wi)
        return np.where((c > 0) & (sp.cos_o > 0), c / np.pi, 0.0)

    def sample(self, sp, u_lobe, u_dir):
        wi = local_to_world(cosine_hemisphere(u_dir), sp.n_s)
        pdf = self.pdf(sp, wi)
        ok = pdf > 0
        v = self.eval(sp, wi)
        weight = v.scaled(np.where(ok, dot(sp.n_s, wi) / np.where(ok, pdf, 1.0), 0.0)[None, :])
        return BSDFSample(wi=wi, weight=weight, pdf=pdf, is_delta=np.zeros(sp.n, bool), valid=ok,
                          eta_sq=np.ones(sp.n))


def jones_mueller(rng, L=4, scale=0.4):
    """Realisable non-depolarising Mueller matrices (4, 4, L) with M00 ≤ scale."""
    out = []
    for _ in range(L):
        J = rng.normal(size=(2, 2)) + 1j * rng.normal(size=(2, 2))
        M = mueller_from_jones(J)
        out.append(M * scale / M[0, 0])
    return np.stack(out, axis=-1)


# --------------------------------------------------------------------------- values and densities

def test_two_lamberts_are_the_lambert_of_the_mixed_albedo():
    rng = np.random.default_rng(1)
    sp, wi = points(400, rng), upper(400, rng)
    mix = Mix([lambert(0.2), lambert(0.6)], [0.25, 0.5])
    single = lambert(0.25 * 0.2 + 0.5 * 0.6)
    v = mix.eval(sp, wi)
    assert v.kind == "depolarising" and not mix.flags.polarising
    np.testing.assert_allclose(v.A, single.eval(sp, wi).A, rtol=1e-14, atol=0)
    np.testing.assert_allclose(mix.pdf(sp, wi), single.pdf(sp, wi), rtol=1e-14, atol=0)
    u_lobe, u_dir = rng.random(400), rng.random((2, 400))
    got, want = mix.sample(sp, u_lobe, u_dir), single.sample(sp, u_lobe, u_dir)
    np.testing.assert_array_equal(got.valid, want.valid)
    np.testing.assert_allclose(got.wi, want.wi, rtol=0, atol=1e-15)     # each Lambert samples with u_dir alone
    np.testing.assert_allclose(got.weight.A, want.weight.A, rtol=1e-14)
    np.testing.assert_allclose(got.pdf, want.pdf, rtol=1e-14)


def test_spectral_albedos_mix_per_wavelength():
    rng = np.random.default_rng(2)
    sp, wi = points(50, rng), upper(50, rng)
    a, b = parse_material({"type": "lambert", "albedo": [0.9, 0.2, 0.1]}, "a"), \
        parse_material({"type": "lambert", "albedo": [0.1, 0.3, 0.8]}, "b")
    got = Mix([a, b], [0.7, 0.3]).eval(sp, wi).A
    ok = (dot(wi, sp.n_s) > 0)[None, :]
    want = (0.7 * a.albedo.eval(sp.lam) + 0.3 * b.albedo.eval(sp.lam)) / np.pi * ok
    np.testing.assert_allclose(got, want, rtol=1e-14, atol=1e-17)


def test_add_shader_weights_sum_without_normalising():
    rng = np.random.default_rng(3)
    sp, wi = points(60, rng), upper(60, rng)
    gold = parse_material({"type": "conductor", "metal": "Au"}, "g")
    add = Mix([lambert(0.3), lambert(0.5), gold], [1.0, 1.0, 1.0])
    np.testing.assert_allclose(add.eval(sp, wi).A, 0.8 / np.pi * np.ones((4, 60)), rtol=1e-14)
    d, want = add.delta_reflection(sp), gold.delta_reflection(sp)
    np.testing.assert_allclose(in_basis(d, -sp.wo + 2 * sp.cos_o * sp.n_s, sp.wo),
                               in_basis(want, -sp.wo + 2 * sp.cos_o * sp.n_s, sp.wo), rtol=1e-13, atol=1e-15)
    # the sampling weights' mean over many samples: 0.8 (Lambert part) + the unpolarised Fresnel reflectance
    n = 40000
    sp1 = points(n, np.random.default_rng(4), n_s=None)
    sp1.wo[:] = np.array([[0.6], [0.0], [0.8]])
    bs = add.sample(sp1, (np.arange(n) + 0.5) / n, np.random.default_rng(5).random((2, n)))
    fresnel = float(gold.delta_reflection(sp1).A[0, 0])
    assert np.mean(bs.weight.matrix()[0, 0, 0]) == pytest.approx(0.8 + fresnel, rel=2e-3)


def test_nested_mixes_flatten_with_multiplied_weights_and_zero_weights_drop():
    a, b, c, d = lambert(0.1), lambert(0.2), lambert(0.4), lambert(0.9)
    m = Mix([Mix([a, b], [0.5, 0.25]), c, d], [0.5, 1.0, 0.0])
    assert m.components == [a, b, c] and m.weights == [0.25, 0.125, 1.0]
    rng = np.random.default_rng(6)
    sp, wi = points(20, rng), upper(20, rng)
    np.testing.assert_allclose(m.eval(sp, wi).A, lambert(0.25 * 0.1 + 0.125 * 0.2 + 0.4).eval(sp, wi).A, rtol=1e-14)
    black = Mix([d, SmoothDielectric(1.5)], [0.0, 0.0])          # nothing left: black, no lobes
    assert black.components == [] and black.flags == F.NONE and not black.delta_only
    assert not black.eval(sp, wi).A.any() and not black.pdf(sp, wi).any() and black.delta_reflection(sp) is None
    assert not black.sample(sp, np.full(20, 0.5), np.full((2, 20), 0.5)).valid.any()
    with pytest.raises(ValueError, match="one weight per material"):
        Mix([a, b], [1.0])
    with pytest.raises(ValueError, match="finite number ≥ 0"):
        Mix([a, b], [1.0, -1.0])


def _hemisphere_integral(f, sp_point, order=48):
    """∫ f(wi) dω over the sphere by Gauss–Legendre in cosθ (per hemisphere) × the trapezoid rule in φ
    (exact for a trigonometric polynomial of low degree in φ)."""
    x, w = np.polynomial.legendre.leggauss(order)
    total = 0.0
    phis = np.arange(2 * order) * (np.pi / order)
    for lo, hi in ((0.0, 1.0), (-1.0, 0.0)):
        c = 0.5 * (hi - lo) * x + 0.5 * (hi + lo)
        cw = 0.5 * (hi - lo) * w
        C, P = np.meshgrid(c, phis, indexing="ij")
        s = np.sqrt(1.0 - C * C)
        wi = np.stack([s * np.cos(P), s * np.sin(P), C]).reshape(3, -1)
        n = wi.shape[1]
        sp = ShadingPoint(np.zeros((3, n)), np.tile(sp_point.n_s[:, :1], (1, n)), np.tile(sp_point.n_g[:, :1], (1, n)),
                          np.tile(sp_point.wo[:, :1], (1, n)), np.tile(sp_point.lam[:, :1], (1, n)))
        vals = f(sp, wi).reshape(C.shape)
        total += np.sum(vals * cw[:, None]) * (np.pi / order)
    return total


def test_glass_plus_lambert_sampling_expectation_and_pdf_normalisation():
    glass, rho, w_glass, w_diffuse = SmoothDielectric(1.5), 0.6, 0.7, 0.5
    mix = Mix([glass, lambert(rho)], [w_glass, w_diffuse])
    assert mix.flags.has(F.DELTA_TRANSMISSION) and not mix.delta_only and mix.transmits
    cos_o = 0.6
    n = 100000
    rng = np.random.default_rng(7)
    sp = points(n, rng)
    sp.wo[:] = np.array([[0.8], [0.0], [cos_o]])
    bs = mix.sample(sp, (np.arange(n) + rng.random(n)) / n, rng.random((2, n)))
    m00 = bs.weight.matrix()[0, 0, 0]
    # independent: the unpolarised Fresnel reflectance of η = 1.5 at cosθ = 0.6, transmission × 1/η²
    eta = 1.5
    cos_t = math.sqrt(1.0 - (1.0 - cos_o ** 2) / eta ** 2)
    rs = (cos_o - eta * cos_t) / (cos_o + eta * cos_t)
    rp = (eta * cos_o - cos_t) / (eta * cos_o + cos_t)
    R = 0.5 * (rs * rs + rp * rp)
    want = w_glass * (R + (1.0 - R) / eta ** 2) + w_diffuse * rho
    assert np.mean(m00) == pytest.approx(want, rel=1e-3)
    # the non-delta density integrates to the probability of choosing the Lambert (albedo-weighted)
    p_diffuse = w_diffuse * rho / (w_diffuse * rho + w_glass * 1.0)
    integral = _hemisphere_integral(mix.pdf, sp.take(np.arange(1)))
    assert integral == pytest.approx(p_diffuse, rel=1e-9)
    assert np.mean(~bs.is_delta) == pytest.approx(p_diffuse, abs=2e-4)      # stratified lobe numbers
    # the delta samples carry pdf 0, the others the mixture's density
    assert np.all(bs.pdf[bs.is_delta] == 0) and np.all(bs.pdf[~bs.is_delta & bs.valid] > 0)


def test_non_delta_sample_weight_is_eval_cos_over_pdf():
    rng = np.random.default_rng(8)
    htsg = parse_material({"type": "htsg", "metal": "Al", "sigma0_um": 0.18, "tau_um": 3.0}, "h")
    gold = parse_material({"type": "conductor", "metal": "Au"}, "g")
    fixed = Fixed(jones_mueller(rng), 0.3, -1.1)
    mix = Mix([htsg, gold, lambert(0.5), fixed], [0.3, 0.4, 0.5, 0.6])
    sp = points(3000, rng)
    bs = mix.sample(sp, rng.random(3000), rng.random((2, 3000)))
    smooth = np.flatnonzero(bs.valid & ~bs.is_delta)
    assert 0 < smooth.size < 3000 and bs.is_delta.any()
    sub, wi = sp.take(smooth), bs.wi[:, smooth]
    weight = bs.weight.matrix()[..., smooth]
    f = mix.eval(sub, wi)
    want = f.matrix() * (np.abs(dot(sub.n_s, wi)) / mix.pdf(sub, wi))[None, None, None, :]
    # the same frames: compare the matrices in one basis
    got_b = in_basis(MuellerValue("general", bs.weight.x_in[:, smooth], bs.weight.x_out[:, smooth], M=weight), wi,
                     sub.wo)
    want_b = in_basis(MuellerValue("general", f.x_in, f.x_out, M=want), wi, sub.wo)
    np.testing.assert_allclose(got_b, want_b, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(bs.pdf[smooth], mix.pdf(sub, wi), rtol=1e-13)
    # the delta samples: (w/p)·M of the chosen mirror (gold, or HTSG's specular lobe)
    assert np.all(bs.pdf[bs.is_delta] == 0)


def test_polarising_values_in_different_frames_add_in_one_basis():
    rng = np.random.default_rng(9)
    a, b = Fixed(jones_mueller(rng), 0.4, 1.3), Fixed(jones_mueller(rng), -0.7, 2.9)
    diffuse = lambert(0.3)
    mix = Mix([a, b, diffuse], [0.6, 0.9, 0.5])
    sp, wi = points(200, rng), upper(200, rng)
    v = mix.eval(sp, wi)
    assert v.kind == "general"
    want = sum(w * in_basis(c.eval(sp, wi), wi, sp.wo) for c, w in ((a, 0.6), (b, 0.9), (diffuse, 0.5)))
    np.testing.assert_allclose(in_basis(v, wi, sp.wo), want, rtol=1e-12, atol=1e-14)
    assert np.all(is_realisable(v.matrix()))
    # the batched rotation is the frames module's
    M = rng.normal(size=(4, 4, 4, 200))
    x1, x2 = unit(cross(-wi, rng.normal(size=(3, 200)))), unit(cross(sp.wo, rng.normal(size=(3, 200))))
    y1, y2 = unit(cross(-wi, rng.normal(size=(3, 200)))), unit(cross(sp.wo, rng.normal(size=(3, 200))))
    from engine.polarisation.frames import frame_rotation
    np.testing.assert_allclose(
        rotate_mueller_batch(M, *frame_rotation(x1, y1, -wi), *frame_rotation(x2, y2, sp.wo)),
        rotate_mueller_frames(M, x1[:, None], y1[:, None], -wi[:, None], x2[:, None], y2[:, None], sp.wo[:, None]),
        rtol=1e-13, atol=1e-14)


@pytest.mark.parametrize("basis", ["sp", "scattering"])
@pytest.mark.parametrize("geometry", [(30.0, 30.0, 0.0), (60.0, 45.0, 120.0), (75.0, 20.0, -40.0), (0.0, 50.0, 90.0)])
def test_conductor_plus_lambert_mueller_matrix_is_the_weighted_sum(basis, geometry):
    gold = parse_material({"type": "conductor", "metal": "Au"}, "g")
    htsg = parse_material({"type": "htsg", "metal": "Al", "sigma0_um": 0.18, "tau_um": 3.0}, "h")
    white = lambert(0.7)
    for parts in (((gold, 0.4), (white, 0.5)), ((gold, 0.4), (white, 0.5), (htsg, 0.3))):
        mix = Mix([c for c, _ in parts], [w for _, w in parts])
        got = mueller_at(mix, *geometry, wavelength_nm=550.0, basis=basis)
        each = [(mueller_at(c, *geometry, wavelength_nm=550.0, basis=basis), w) for c, w in parts]
        brdf = sum(w * np.array(e["brdf"]) for e, w in each)
        delta = sum(w * np.array(e["delta"]) for e, w in each if e["delta"] is not None)
        np.testing.assert_allclose(np.array(got["brdf"]), brdf, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(np.array(got["delta"]), delta, rtol=1e-12, atol=1e-15)
        assert is_realisable(np.array(got["brdf"])) and is_realisable(np.array(got["delta"]))


def test_cheap_kinds_are_kept():
    rng = np.random.default_rng(10)
    sp, wi = points(30, rng), upper(30, rng)
    gold = parse_material({"type": "conductor", "metal": "Au"}, "g")
    silver = parse_material({"type": "conductor", "metal": "Ag"}, "s")
    d = Mix([gold, silver, lambert(0.5)], [0.5, 0.5, 1.0]).delta_reflection(sp)
    assert d.kind == "abcs"                                  # mirrors share the plane of incidence
    want = 0.5 * gold.delta_reflection(sp).matrix() + 0.5 * silver.delta_reflection(sp).matrix()
    np.testing.assert_allclose(d.matrix(), want, rtol=1e-14)
    assert Mix([lambert(0.5), lambert(0.1)], [1.0, 1.0]).delta_reflection(sp) is None
    fixed = Fixed(jones_mueller(rng), 0.2, 0.1)
    v = Mix([fixed, lambert(0.5)], [0.5, 0.5]).eval(sp, wi)      # one polarising value: its kind and frames
    f = fixed.eval(sp, wi)
    assert v.kind == "general"
    np.testing.assert_array_equal(v.x_in, f.x_in)
    np.testing.assert_array_equal(v.x_out, f.x_out)
    want = 0.5 * f.matrix()
    want[0, 0] += 0.25 / np.pi * (dot(wi, sp.n_s) > 0)
    np.testing.assert_allclose(v.matrix(), want, rtol=1e-14)


# --------------------------------------------------------------------------- flags, sides, textures, normals

def test_flags_are_the_union_and_the_fused_delta_step_is_not_used():
    glass = SmoothDielectric(1.5)
    m = Mix([glass, lambert(0.5)], [0.5, 0.5])
    assert m.flags.lobes == F.DELTA_REFLECTION | F.DELTA_TRANSMISSION | F.DIFFUSE_REFLECTION
    assert m.polarising and m.creates_circular and not m.flags.wavelength_dependent
    assert m.flags.has(F.SEPARABLE_DIFFUSE)          # the only non-Dirac lobe is a depolariser's
    two_glasses = Mix([glass, SmoothDielectric(1.33)], [0.5, 0.5])
    assert two_glasses.delta_only and type(two_glasses).scatter_delta is BSDF.scatter_delta
    rgb = parse_material({"type": "lambert", "albedo": [0.9, 0.2, 0.1]}, "a")
    assert Mix([rgb, lambert(0.1)], [1.0, 1.0]).flags.wavelength_dependent
    assert not Mix([lambert(0.5), lambert(0.1)], [1.0, 1.0]).varies_over_surface
    a, b = lambert(0.5), lambert(0.2)
    a.two_sided = b.two_sided = True
    assert Mix([a, b], [1.0, 1.0]).two_sided and not Mix([a, lambert(0.2)], [1.0, 1.0]).two_sided


def test_two_sided_mix_with_glass_flips_only_its_opaque_materials():
    """The integrator does not flip a material that transmits; a two-sided mix of glass and an opaque
    material shades the opaque one from the back as from the front and leaves the glass its sides."""
    glass, diffuse = SmoothDielectric(1.5), lambert(0.4)
    rng = np.random.default_rng(14)
    sp, wi = points(200, rng), upper(200, rng)
    back = ShadingPoint(sp.p, sp.n_s, sp.n_g, -sp.wo, sp.lam, sp.mono, sp.lookup)     # the viewer below
    one_sided = Mix([glass, diffuse], [0.5, 0.5])
    two_sided = Mix([glass, diffuse], [0.5, 0.5])
    two_sided.two_sided = True
    assert not one_sided.eval(back, -wi).A.any()
    np.testing.assert_allclose(two_sided.eval(back, -wi).A, 0.5 * diffuse.eval(sp, wi).A, rtol=1e-15)
    np.testing.assert_allclose(two_sided.pdf(back, -wi),
                               diffuse.pdf(sp, wi) * 0.5 * 0.4 / (0.5 * 0.4 + 0.5), rtol=1e-14)
    # the glass part still refracts from the back (its delta reflection seen from inside)
    at = two_sided.shading_point(back)
    want = glass.delta_reflection(back).matrix() * 0.5
    np.testing.assert_allclose(two_sided.delta_reflection(at).matrix(), want, rtol=1e-14)
    # a flipped mirror reflects into the same direction: gold seen from the back as from the front
    gold = parse_material({"type": "conductor", "metal": "Au"}, "g")
    both = Mix([glass, gold], [0.5, 0.5])
    both.two_sided = True
    front = ShadingPoint(sp.p, -sp.n_s, -sp.n_g, -sp.wo, sp.lam, sp.mono, sp.lookup)
    want = 0.5 * glass.delta_reflection(back).matrix() + 0.5 * gold.delta_reflection(front).matrix()
    np.testing.assert_allclose(both.delta_reflection(both.shading_point(back)).matrix(), want, rtol=1e-13,
                               atol=1e-16)


def _plane_points(uv):
    """Surface points on the quad [-1, 1]² (z = 0, default UVs) at texture coordinates uv (2, N)."""
    n = uv.shape[1]
    verts = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    quad_uv = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    return SurfacePoints(VertexAttributes(faces, quad_uv, {}, verts, None), np.zeros(n, np.int64), uv[0] - uv[1],
                         uv[1].copy())


def _exr(path, channels: dict):
    import OpenEXR
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                 {c: np.ascontiguousarray(v, np.float32) for c, v in channels.items()}).write(str(path))


def test_textured_weights_per_point(tmp_path):
    _exr(tmp_path / "w.exr", {"Y": np.array([[0.25, 1.0]])})
    tex = {"texture": "w.exr", "interpolation": "Closest"}
    mix = parse_material({"type": "mix", "materials": [{"type": "lambert", "albedo": 0.2},
                                                       {"type": "lambert", "albedo": 0.8}],
                          "weights": [tex, dict(tex, scale=-1.0, offset=1.0)]}, "m", base_dir=str(tmp_path))
    assert mix.varies_over_surface
    n = 2000
    uv = np.stack([np.where(np.arange(n) % 2 == 0, 0.25, 0.75), np.full(n, 0.1)])
    rng = np.random.default_rng(11)
    sp, wi = points(n, rng, surface=_plane_points(uv)), upper(n, rng)
    t = np.where(np.arange(n) % 2 == 0, 0.25, 1.0)
    albedo = t * 0.2 + (1.0 - t) * 0.8
    np.testing.assert_allclose(mix.eval(sp, wi).A, (albedo / np.pi)[None, :] * np.ones((4, 1)), rtol=1e-7)
    np.testing.assert_allclose(mix.pdf(sp, wi), dot(wi, sp.n_s) / np.pi, rtol=1e-12)
    bs = mix.sample(sp, rng.random(n), rng.random((2, n)))
    assert bs.valid.all()
    np.testing.assert_allclose(bs.weight.A[0], albedo, rtol=1e-7)
    with pytest.raises(SceneError, match=r"materials\.m\.weights\[1\]: texture values .* must be in \[0, inf\]"):
        parse_material({"type": "mix", "materials": [{"type": "lambert"}, {"type": "lambert"}],
                        "weights": [0.5, dict(tex, offset=-0.5)]}, "materials.m", base_dir=str(tmp_path))


def test_each_material_at_its_own_shading_normal_and_flipped_with_the_mix(tmp_path):
    a = math.radians(30.0)
    _exr(tmp_path / "n.exr", {"R": np.full((2, 2), 0.5 + 0.5 * math.sin(a)), "G": np.full((2, 2), 0.5),
                              "B": np.full((2, 2), 0.5 + 0.5 * math.cos(a))})
    mix = parse_material({"type": "mix", "materials": [
        {"type": "lambert", "albedo": 0.5, "normal_map": {"texture": "n.exr"}}, {"type": "lambert", "albedo": 0.3}],
        "weights": [0.6, 0.4]}, "m", base_dir=str(tmp_path))
    n = 500
    rng = np.random.default_rng(12)
    uv = np.stack([0.6 + 0.3 * rng.random(n), 0.5 * rng.random(n)])
    uv[1] = np.minimum(uv[1], uv[0])
    sp = points(n, rng, surface=_plane_points(uv))
    wi = unit(rng.normal(size=(3, n)))
    at = mix.shading_point(sp)
    assert isinstance(at, MixShadingPoint)
    n1 = mix.components[0].shading_normal(sp)          # the map's normal, from the component alone
    np.testing.assert_allclose(n1, np.tile([[math.sin(a)], [0.0], [math.cos(a)]], (1, n)), rtol=0, atol=1e-7)
    np.testing.assert_array_equal(at.parts[0].n_s, n1)
    # value × |n_s·ω_i| (what the integrator forms) = Σ w_k f_k |n_k·ω_i|, each at its own normal
    # Cycles' rules for the mapped diffuse lobe (engine.materials.normal_map): lit where N·ω_i > 0 and ω_i is
    # on the same side of the smooth normal N_s as of N, seen wherever the viewer is in front of N or of N_s,
    # softened by the GGX masking Λ-form G1 = 1 / (1 + Λ), Λ = (√(1 + α² tan²θ_i) − 1) / 2, α² = tan²θ_d / 8
    c1, c0 = dot(n1, wi), dot(sp.n_s, wi)
    seen = (dot(n1, sp.wo) > 0) | (sp.cos_o > 0)
    front1 = (c1 > 0) & seen & (c0 * dot(sp.n_s, n1) * c1 >= 0)
    cos_i = np.abs(c0)
    tan2_d = 1.0 / dot(sp.n_s, n1) ** 2 - 1.0           # tan² 30° up to the half-float texel
    lam = 0.5 * (np.sqrt(1.0 + tan2_d / 8.0 * (1.0 - cos_i ** 2) / cos_i ** 2) - 1.0)
    front1 = front1 / (1.0 + lam)
    front0 = (c0 > 0) & (sp.cos_o > 0)
    want = 0.6 * 0.5 / np.pi * front1 * np.abs(c1) + 0.4 * 0.3 / np.pi * front0 * np.abs(c0)
    np.testing.assert_allclose(mix.eval(at, wi).A[0] * np.abs(c0), want, rtol=1e-12, atol=1e-16)
    # two-sided back faces: the integrator flips the mix's point; the mapped normal is negated (mapped, then
    # flipped, as a normal-mapped material alone)
    where = rng.random(n) < 0.5
    flipped = at.flipped(where)
    alone = mix.components[0].shading_point(sp).flipped(where)
    np.testing.assert_array_equal(flipped.parts[0].n_s, alone.n_s)
    np.testing.assert_array_equal(flipped.take(np.arange(10)).parts[0].n_s, alone.n_s[:, :10])


# --------------------------------------------------------------------------- scene format

MIX = {"type": "mix", "materials": [{"type": "lambert", "albedo": 0.5}, "gold"], "weights": [0.5, 0.5]}


@pytest.mark.parametrize("change,field,words", [
    ({"weights": [-0.1, 0.5]}, "materials.m.weights[0]", "must be a finite number in [0, inf], got -0.1"),
    ({"weights": [0.5, float("nan")]}, "materials.m.weights[1]", "must be a finite number in [0, inf], got nan"),
    ({"weights": [0.5, float("inf")]}, "materials.m.weights[1]", "[0, inf]"),
    ({"weights": [0.5, "x"]}, "materials.m.weights[1]", "must be a number"),
    ({"weights": [0.5]}, "materials.m.weights", "one weight per material: 2 materials, got 1 weight"),
    ({"weights": [0.5, 0.5, 0.5]}, "materials.m.weights", "2 materials, got 3 weights"),
    ({"weights": 0.5}, "materials.m.weights", "must be a list, each a number in [0, inf]"),
    ({"materials": []}, "materials.m.materials", "must be a list of 1 to 64 materials"),
    ({"materials": [{"type": "lambert"}] * 65, "weights": [1.0] * 65}, "materials.m.materials", "1 to 64"),
    ({"materials": ["nope", "gold"]}, "materials.m.materials[0]", "unknown material 'nope'"),
    ({"materials": [{"type": "lambert", "albedo": 2}, "gold"]}, "materials.m.materials[0].albedo", "[0, 1]"),
    ({"weight": [1, 1]}, "materials.m.weight", "unknown field"),
], ids=["negative", "nan", "inf", "text", "too-few", "too-many", "not-a-list", "empty", "65", "unknown", "bad-part",
        "typo"])
def test_loader_errors_name_the_field_and_the_range(change, field, words):
    doc = _scene(dict(MIX, **change))
    with pytest.raises(SceneError) as err:
        parse_scene(doc)
    assert err.value.field == field and words in str(err.value), str(err.value)
    assert "\n" not in str(err.value)


def test_loader_bounds_nesting_and_refuses_maps_that_cannot_apply(tmp_path):
    chain = {f"m{i}": {"type": "mix", "materials": [f"m{i + 1}"], "weights": [1.0]} for i in range(300)}
    chain["m300"] = {"type": "lambert"}
    doc = _scene({"type": "lambert"})
    doc["materials"].update(chain)
    with pytest.raises(SceneError, match=r"nest more than 16 levels deep below materials\.m0") as err:
        parse_scene(doc)
    assert err.value.field == "materials.m17.materials"
    # fan-out by name does not multiply the work: 16 levels × 4 names each (4^16 paths) load at once
    fan = {f"f{i}": {"type": "mix", "materials": [f"f{i + 1}"] * 4, "weights": [0.25] * 4} for i in range(16)}
    fan["f16"] = {"type": "lambert"}
    doc = _scene({"type": "lambert"})
    doc["materials"].update(fan)
    top = parse_scene(doc).materials["f0"]
    assert [c.name for c in top.components] == ["lambert"] and top.weights == [1.0]    # one object, weights summed
    # distinct materials: at most 64 in all after flattening
    nine = {"type": "mix", "materials": [{"type": "lambert", "albedo": 0.1 * i} for i in range(9)], "weights": [1] * 9}
    with pytest.raises(SceneError, match="at most 64 materials in all .* got 72") as err:
        parse_material({"type": "mix", "materials": [nine] * 8, "weights": [1] * 8}, "materials.m")
    assert err.value.field == "materials.m.materials"
    _exr(tmp_path / "n.exr", {"R": np.full((2, 2), 0.5), "G": np.full((2, 2), 0.5), "B": np.full((2, 2), 1.0)})
    mapped = {"type": "lambert", "normal_map": {"texture": "n.exr"}}
    with pytest.raises(SceneError, match=r"materials\.m\.normal_map: a mix whose materials have their own normal"):
        parse_material({"type": "mix", "materials": [mapped], "weights": [1.0], "normal_map": {"texture": "n.exr"}},
                       "materials.m", base_dir=str(tmp_path))
    with pytest.raises(SceneError, match=r"materials\.w\.base: a material under a coat cannot have its own normal"):
        parse_material({"type": "weidlich_wilkie", "coats": [{"n": 1.5}],
                        "base": {"type": "mix", "materials": [mapped, {"type": "lambert"}], "weights": [0.5, 0.5]}},
                       "materials.w", base_dir=str(tmp_path))
    # a map on a mix of unmapped materials, and maps on the materials, are fine
    mapped_mix = parse_material({"type": "mix", "materials": [{"type": "lambert"}], "weights": [1.0],
                                 "normal_map": {"texture": "n.exr"}, "two_sided": True}, "m", base_dir=str(tmp_path))
    # (mapped material by material, as Cycles maps each closure: engine.materials.mix.map_normals)
    assert isinstance(mapped_mix, Mix) and mapped_mix.two_sided
    assert isinstance(mapped_mix.components[0], ShadingNormal)


def test_mix_under_a_coat_passes_the_coat_index_on():
    ww = parse_material({"type": "weidlich_wilkie", "coats": [{"n": 1.5}],
                         "base": {"type": "mix", "materials": [{"type": "conductor", "metal": "Au"},
                                                               {"type": "lambert", "albedo": 0.5}],
                                  "weights": [0.5, 0.5]}}, "w")
    inner = ww.base
    assert isinstance(inner, Mix) and inner.components[0].exterior_n == 1.5 and inner.exterior_n == 1.5
    assert not hasattr(Mix([lambert(0.5)], [1.0]), "exterior_n")
    rng = np.random.default_rng(13)
    sp, wi = points(50, rng), upper(50, rng)
    assert np.isfinite(ww.eval(sp, wi).matrix()).all() and np.all(is_realisable(ww.eval(sp, wi).matrix()))


def test_mix_is_not_a_polarising_bsdf_node_model():
    from engine.materials.catalogue import CATALOGUE, MODELS
    from tests.materials.test_parameters import node_models
    assert "mix" in MODELS and MODELS["mix"].node is None and "mix" not in CATALOGUE
    assert all(decl.name != "mix" for decl in node_models().NODE_MODELS.values())


# --------------------------------------------------------------------------- renders

def _scene(material, spp=16, size=16, max_depth=5, vertices=None, sampler="stratified", sphere=True,
           transparent=False):
    objects = [{"shape": "quad", "vertices": vertices or [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                "uv": [[0, 0], [1, 0], [1, 1], [0, 1]], "material": "m"}]
    if sphere:
        objects.append({"shape": "sphere", "center": [0.3, 0.2, 0.35], "radius": 0.35, "subdivisions": 2,
                        "material": "gold"})
    return {
        "format": "polar-scene/1",
        "camera": {"origin": [0, -3, 3], "target": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 40, "width": size,
                   "height": size, "film_transparent": transparent},
        "render": {"spp": spp, "seed": 3, "max_depth": max_depth, "sampler": sampler},
        "materials": {"m": material, "gold": {"type": "conductor", "metal": "Au"}},
        "objects": objects,
        "lights": [{"type": "environment", "radiance": 0.5, "color": [1.0, 0.9, 0.8]},
                   {"type": "point", "position": [-0.5, -1.0, 1.5], "intensity": 2.0}],
    }


def _render(doc):
    return Renderer(parse_scene(doc)).render()


def test_render_of_two_mixed_lamberts_is_the_single_lambert():
    mixed = _render(_scene({"type": "mix", "materials": [{"type": "lambert", "albedo": [0.8, 0.4, 0.2]},
                                                         {"type": "lambert", "albedo": 0.1}],
                            "weights": [0.5, 1.0]}))
    single = _render(_scene({"type": "lambert", "albedo": [0.5, 0.3, 0.2]}))
    a, b = mixed.stokes(), single.stokes()
    assert b[0].max() > 0
    # the same estimator, the same random numbers (each Lambert samples its direction from u_dir alone):
    # equal up to rounding (the RGB upsampling is linear in the colour)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
    assert mixed.stats["transport"] == single.stats["transport"]


def test_direct_light_render_is_linear_in_the_mixed_materials():
    """With one bounce (max_depth 2) the image is linear in the BSDF: render(mix) = Σ w_k render(k)
    within noise, every Stokes component (gold polarises and retards)."""
    gold = {"type": "conductor", "metal": "Au"}
    diffuse = {"type": "lambert", "albedo": 0.6}
    kw = dict(spp=32, size=16, max_depth=2, sampler="independent", sphere=False, transparent=True)
    mixed = _render(_scene({"type": "mix", "materials": [gold, diffuse], "weights": [0.7, 0.4]}, **kw)).stokes()
    ref = 0.7 * _render(_scene(gold, **kw)).stokes() + 0.4 * _render(_scene(diffuse, **kw)).stokes()
    d = (mixed - ref).reshape(4, -1)
    assert np.abs(ref[1:]).max() > 1e-3                          # polarised light in the image
    for s in range(4):
        se = d[s].std() / math.sqrt(d.shape[1])
        assert abs(d[s].mean()) <= 4.0 * se + 1e-12, (s, d[s].mean(), se)
    assert np.abs(d).mean() < 0.1 * np.abs(ref).mean()


def test_two_sided_mix_with_a_mapped_material_renders_its_back_as_its_front(tmp_path):
    _exr(tmp_path / "n.exr", {"R": np.full((2, 2), 0.5), "G": np.full((2, 2), 0.5), "B": np.full((2, 2), 1.0)})
    mat = {"type": "mix", "materials": [{"type": "lambert", "albedo": 0.5,
                                         "normal_map": {"texture": str(tmp_path / "n.exr")}},
                                        {"type": "conductor", "metal": "Au"}], "weights": [0.5, 0.5]}
    front = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]
    kw = dict(spp=4, size=10, max_depth=4, sphere=False)
    back = _render(_scene(dict(mat, two_sided=True), vertices=front[::-1], **kw)).stokes()
    front_image = _render(_scene(mat, vertices=front, **kw)).stokes()
    assert front_image[0].max() > 0
    np.testing.assert_allclose(back, front_image, rtol=1e-6, atol=1e-7)


def test_a_batch_computes_a_mixtures_weights_once_and_its_subsets_share_arrays(monkeypatch):
    """ShadingPoint.memo: next-event estimation's eval and pdf at one batch compute the mixture's weights and
    probabilities once (the values are those of a fresh batch); a taken or flipped batch computes its own.
    ShadingPoint.take(sel, shared): batches that share arrays get one gathered copy, the same values as apart."""
    rng = np.random.default_rng(3)
    sp = points(200, rng)
    mix = Mix([lambert(0.2), SmoothDielectric(1.5), lambert(0.7)], [0.3, 0.5, 0.2])
    calls = []
    original = Mix._weights
    monkeypatch.setattr(Mix, "_weights", lambda self, q: calls.append(q) or original(self, q))
    wi = upper(200, rng)
    f, pdf = mix.eval(sp, wi), mix.pdf(sp, wi)
    assert len(calls) == 1
    fresh = points(200, np.random.default_rng(3))
    assert np.array_equal(mix.pdf(fresh, wi), pdf) and np.array_equal(mix.eval(fresh, wi).A, f.A)
    sel = np.arange(0, 200, 3)
    mix.pdf(sp.take(sel), wi[:, sel])
    mix.pdf(sp.flipped(np.zeros(200, bool)), wi)
    assert len(calls) == 4          # (the fresh batch's, the subset's and the flipped batch's own)
    other = ShadingPoint(sp.p, -sp.n_s, sp.n_g, sp.wo, sp.lam, False, sp.lookup, None, None)
    shared = {}
    a, b = sp.take(sel, shared), other.take(sel, shared)
    assert a.wo is b.wo and a.lam is b.lam and a.lookup is b.lookup and a.n_s is not b.n_s
    c = other.take(sel)
    assert np.array_equal(b.n_s, c.n_s) and np.array_equal(b.wo, c.wo) and b.wo is not c.wo


@pytest.mark.parametrize("values", [
    {"metallic": 0.5, "roughness": 0.4},                            # F82 metal + layered dielectric over Lambert
    {"metallic": 0.3, "transmission": 0.5, "roughness": 0.0},       # Dirac glass and mirror lanes beside rough ones
    {"metallic": 0.2, "transmission": 0.6, "roughness": 0.3, "coat_weight": 0.5, "sheen_weight": 0.4},
])
def test_sampled_directions_alone_are_the_samples_and_nested_mixes_sum_once(values):
    """BSDF.sample_direction (what a mix asks of its components, nested mixes included): the same directions,
    densities, Dirac flags, validity and η² as ``sample``, the same weight on the Dirac lanes; and the mixture's
    weight on the other lanes is still Σ w_k·f_k·|cosθ_i| / Σ p_k·pdf_k."""
    model = parse_material({"type": "principled", **values}, "materials.p")
    # the specular layer over its diffuse base as two lobes (as normal maps split them): a mix inside the mix
    model = model.with_components([(getattr(c, "as_layers", lambda: None)() or c) for c in model.components])
    if not any(isinstance(c, Mix) for c in model.components):    # (the smooth one: under a layer, beside a Lambert)
        model = Mix([Layered(lambert(0.2), model, 0.3, lambda sp: np.full(sp.n, 0.5)), lambert(0.4)], [0.7, 0.3])
    n, rng = 3000, np.random.default_rng(11)
    u_lobe, u_dir = rng.random(n), rng.random((2, n))
    full = model.sample(points(n, np.random.default_rng(5)), u_lobe, u_dir)
    alone = model.sample_direction(points(n, np.random.default_rng(5)), u_lobe, u_dir)
    for field in ("wi", "pdf", "is_delta", "valid", "eta_sq"):
        assert np.array_equal(getattr(full, field), getattr(alone, field)), field
    delta = np.flatnonzero(full.is_delta & full.valid)
    if "transmission" in values and values["roughness"] == 0.0:
        assert delta.size
        assert np.array_equal(full.weight.matrix()[..., delta], alone.weight.matrix()[..., delta])
    else:
        assert alone.weight is None
    sp = points(n, np.random.default_rng(5))
    smooth = np.flatnonzero(full.valid & ~full.is_delta)
    sub, wi = sp.take(smooth), full.wi[:, smooth]
    f = model.eval(sub, wi)
    want = f.matrix() * (np.abs(dot(sub.n_s, wi)) / model.pdf(sub, wi))[None, None, None, :]
    got = MuellerValue("general", full.weight.x_in[:, smooth], full.weight.x_out[:, smooth],
                       M=full.weight.matrix()[..., smooth])
    np.testing.assert_allclose(in_basis(got, wi, sub.wo), in_basis(MuellerValue("general", f.x_in, f.x_out, M=want),
                                                                   wi, sub.wo), rtol=1e-10, atol=1e-13)


def _sum_inputs(seed: int, n: int, L: int = 4):
    """(rng, x (3, n) frames, abcs(depol): a random ABCS value in them with negative and positive zeros in a few
    entries (the sums' zero rules)) for the mixture sums' bit-for-bit tests."""
    rng = np.random.default_rng(seed)
    x = unit(rng.normal(size=(3, n)))

    def abcs(depol):
        A, B, C, S = (rng.normal(size=(L, n)) for _ in range(4))
        A[0, :5], B[1, :7] = -0.0, 0.0
        return MuellerValue("abcs", x, x, A, B, C, S, depol=rng.uniform(0, 1, (L, n)) if depol else None)
    return rng, x, abcs


def _assert_same_blocks(got, want):
    """The blocks A..S and depol of two values: both None or the same shape and bits."""
    for f in ("A", "B", "C", "S", "depol"):
        g, w = getattr(got, f), getattr(want, f)
        assert (g is None) == (w is None), f
        if w is not None:
            assert g.shape == w.shape and g.tobytes() == w.tobytes(), f


@pytest.mark.skipif(not __import__("engine.kernels", fromlist=["COMPILED"]).COMPILED, reason="needs Numba")
@pytest.mark.parametrize("shape", ["two", "three_with_depolarisers", "shared_depol", "six", "read_only",
                                   "read_only_scale"])
def test_compiled_abcs_sum_is_the_numpy_sum_bit_for_bit(shape):
    """The mixture's sum of ABCS values in shared frames (mix.abcs_sum): the compiled loop against the NumPy twin —
    scales per point and numbers, ABCS values with and without a depolarised share, depolarising terms between
    them — bit for bit, negative zeros included (0 + x, as Python's sum)."""
    from engine.kernels import TWINS
    from engine.materials import mix as M
    assert TWINS["materials.mix.abcs_sum"].compiled is M.abcs_sum_numba
    L, n = 4, 700
    rng, x, abcs = _sum_inputs(21, n)

    def depolarising():
        return MuellerValue("depolarising", x, x, A=rng.uniform(0, 1, (L, n)))
    terms = {"two": [(rng.uniform(0, 2, n), abcs(False)), (0.7, abcs(False))],
             "three_with_depolarisers": [(rng.uniform(0, 2, n), abcs(True)), (1.3, depolarising()),
                                         (rng.uniform(0, 1, n), abcs(False)), (0.25, abcs(True)),
                                         (rng.uniform(0, 1, n), depolarising())],
             "shared_depol": [(0.5, abcs(True)), (rng.uniform(0, 1, n), abcs(True))],
             # more values than the precompiled counts, and read-only blocks: the NumPy twin, no new compile
             "six": [(rng.uniform(0, 1, n), abcs(k % 2 == 0)) for k in range(6)],
             "read_only": [(0.5, abcs(False)), (0.25, abcs(False))],
             "read_only_scale": [(rng.uniform(0, 1, n), abcs(False)), (rng.uniform(0, 1, n), abcs(True))]}[shape]
    if shape == "read_only":
        terms[1][1].A.flags.writeable = False
    if shape == "read_only_scale":      # a read-only per-point weight (a texture's) beside a writeable one
        terms[1][0].flags.writeable = False
    signatures = len(M.chain_sum_loop.signatures)
    got, want = M.abcs_sum_numba(terms, x, x), M.abcs_sum_numpy(terms, x, x)
    if shape in ("six", "read_only"):
        assert len(M.chain_sum_loop.signatures) == signatures
    _assert_same_blocks(got, want)


@pytest.mark.skipif(not __import__("engine.kernels", fromlist=["COMPILED"]).COMPILED, reason="needs Numba")
@pytest.mark.parametrize("shape", ["sum_of_chains", "sum_with_depolariser", "one_with_depolarisers", "one_alone",
                                   "one_shared_depol", "long_chain"])
def test_compiled_sums_of_scaled_values_are_the_numpy_sums_bit_for_bit(shape):
    """ScaledValue terms (a normal map's factor, a tint per wavelength, deferred: MuellerValue.times) in the compiled
    sums (mix.abcs_sum and mix.one_abcs: the factors multiplied in the loop, in order) against the NumPy twins, which
    multiply them out first — bit for bit, negative zeros included; and a ScaledValue's blocks read directly are
    those of the eager ``scaled`` chain."""
    from engine.kernels import TWINS
    from engine.materials import mix as M
    from engine.materials.base import ScaledValue
    assert TWINS["materials.mix.one_abcs"].compiled is M.one_abcs_numba
    L, n = 4, 500
    rng, x, abcs = _sum_inputs(5, n)

    def leak():         # a normal map's factor: 1 or 0 per point, (1, N)
        return (rng.uniform(0, 1, n) > 0.2).astype(np.float64)[None, :]

    def chained(v, *factors):
        for f in factors:
            v = v.times(f)
        assert isinstance(v, ScaledValue)
        return v
    lam = MuellerValue("depolarising", x, x, A=rng.uniform(0, 1, (L, n)))
    terms = {"sum_of_chains": [(rng.uniform(0, 2, n), chained(abcs(True), leak(), rng.uniform(0, 2, (L, n)))),
                               (rng.uniform(0, 1, n), chained(abcs(True), leak()))],
             "sum_with_depolariser": [(rng.uniform(0, 2, n), abcs(False)), (0.3, chained(abcs(True), 0.7)),
                                      (rng.uniform(0, 1, n), chained(lam, leak()))],
             "one_with_depolarisers": [(rng.uniform(0, 2, n), chained(abcs(False), leak())),
                                       (rng.uniform(0, 1, n), chained(lam, rng.uniform(0, 1, n)[None, :])),
                                       (0.5, lam)],
             "one_alone": [(rng.uniform(0, 2, n), chained(abcs(False), leak()))],
             "one_shared_depol": [(rng.uniform(0, 2, n), chained(abcs(True), leak())),
                                  (rng.uniform(0, 1, n), lam)],
             "long_chain": [(0.5, chained(abcs(True), *(rng.uniform(0.5, 1.5, (L, n)) for _ in range(5))))]}[shape]
    one = sum(v.kind == "abcs" for _, v in terms) == 1
    if one:
        got, want = M.one_abcs_numba(terms), M.one_abcs_numpy(terms)
    else:
        got, want = M.abcs_sum_numba(terms, x, x), M.abcs_sum_numpy(terms, x, x)
    _assert_same_blocks(got, want)
    # the deferred product read directly: the eager chain's bits
    v, factors = abcs(True), (leak(), rng.uniform(0, 2, (L, n)), 0.3)
    eager = v
    for f in factors:
        eager = eager.scaled(f)
    lazy = chained(v, *factors)
    for f in ("A", "B", "C", "S", "depol"):
        assert getattr(lazy, f).tobytes() == getattr(eager, f).tobytes(), f


def test_layered_picks_its_layers_by_their_albedos_as_cycles_picks_closures():
    """Cycles picks a closure by its sample weight, weight × albedo estimate (bsdf_microfacet_estimate_albedo): a
    specular layer of albedo E over a diffuse base (what a normal map splits a Principled dielectric into,
    TorranceSparrow.as_layers) is sampled with p = E / (E + d·(1 − E)·ρ), not as if it reflected everything
    (p = 1 / (1 + d·(1 − E)·ρ): 4–6× too often beside a base that reflects most of the light; TextureTransform's σ²
    under lamps 1.14× Cycles' with it, docs/benchmarks/real-assets.md); and a mix over the layered material picks
    it by Σ w·a of its layers, as it would pick the layers flattened beside its other components."""
    from engine.materials.torrance_sparrow import TorranceSparrow
    model = parse_material({"type": "principled", "metallic": 0.0, "roughness": 0.6,
                            "base_color": [0.5, 0.5, 0.5]}, "materials.p")
    ts = model if isinstance(model, TorranceSparrow) else next(c for c in model.components
                                                               if isinstance(c, TorranceSparrow))
    layered = ts.as_layers()
    top, base = layered.components
    n, rng = 400, np.random.default_rng(3)
    sp, wi = points(n, rng), upper(n, rng)
    E = layered.albedo(sp)
    assert 0.02 < E.min() and E.max() < 0.5                  # a weak specular layer over a bright base
    a_base = layered.weights[1] * (1.0 - E) * 0.5
    p_top = E / (E + a_base)
    want = p_top * top.pdf(sp, wi) + (1.0 - p_top) * base.pdf(sp, wi)
    np.testing.assert_allclose(layered.pdf(points(n, np.random.default_rng(3)), wi), want, rtol=1e-12)
    mix = Mix([layered, lambert(0.3)], [0.4, 0.6])
    p_layered = 0.4 * (E + a_base) / (0.4 * (E + a_base) + 0.6 * 0.3)
    want_mix = p_layered * want + (1.0 - p_layered) * lambert(0.3).pdf(sp, wi)
    np.testing.assert_allclose(mix.pdf(points(n, np.random.default_rng(3)), wi), want_mix, rtol=1e-12)


def test_abcs_values_in_equal_frames_skip_the_rotations_only_where_those_are_the_identity():
    """add_values sums ABCS values whose frames are equal to the bit without computing the rotations
    (mix._shared_abcs_frames): only where _common_frames keeps the first value's frames and finds every rotation the
    identity — not for frames that differ by a rounding, a degenerate frame, or a beam that is not finite."""
    from engine.materials import mix as M
    rng = np.random.default_rng(3)
    n, L = 400, 4
    wi, wo = unit(rng.normal(size=(3, n))), unit(rng.normal(size=(3, n)))
    x = unit(cross(-wi, wo))

    def value(frame):
        A, B, C, S = (rng.normal(size=(L, n)) for _ in range(4))
        return MuellerValue("abcs", frame, frame, A, B, C, S)
    same = [value(x), value(x.copy())]
    assert M._shared_abcs_frames(same, -wi, wo)
    x_in, x_out, rotations = M._common_frames(same, -wi, wo, unit(wi + wo))
    assert x_in is x and x_out is x and all(M._is_identity_rotation(r) for r in rotations)
    terms = [(rng.uniform(0, 1, n), v) for v in same]
    fast, slow = M.add_values(terms, n, L, -wi, wo, unit(wi + wo)), M.abcs_sum(terms, x_in, x_out)
    assert all(getattr(fast, f).tobytes() == getattr(slow, f).tobytes() for f in "ABCS")
    nudged = x.copy()
    nudged[0, 7] = np.nextafter(nudged[0, 7], 2.0)
    assert not M._shared_abcs_frames([value(x), value(nudged)], -wi, wo)
    degenerate = x.copy()
    degenerate[:, 5] = 0.0
    assert not M._shared_abcs_frames([value(degenerate), value(degenerate.copy())], -wi, wo)
    bad = wi.copy()
    bad[1, 9] = np.nan
    assert not M._shared_abcs_frames(same, -bad, wo)
