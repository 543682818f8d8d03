"""Absorbing interiors: Beer–Lambert attenuation inside closed meshes (Blender's Volume Absorption,
engine.render.media).  Oracles are independent of the tracer: exp(−σ·d) per channel (RGB mode), the
spectral integral of exp(−σ(λ)·d) against the CIE observer (spectral mode), and for a glass sphere
under a uniform sky the closed-form series of the in-plane s and p transports, integrated over each
pixel by quadrature (no Monte Carlo)."""

import copy

import numpy as np
import pytest

from engine.errors import SceneError
from engine.render.renderer import Renderer
from engine.scene.description import Interior
from engine.scene.loader import parse_scene
from engine.spectral import GRID_NM, RGBIlluminantSpectrum, basis_rgb, spectrum_to_linear_srgb

SIGMA = np.array([1.0, 2.0, 3.0])       # σ_a per unit length (r, g, b)
THICK = 0.5                             # slab thickness
MATCHED = {"type": "dielectric", "n": 1.0}      # an index-matched surface: no Fresnel, no refraction


def box(lo, hi):
    """A closed box (12 triangles, normals outwards) as a "triangles" object."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)], float)
    faces = []
    for q in ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)):
        faces += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    centre = v.mean(axis=0)
    for f in faces:
        a, b, c = v[f]
        if np.dot(np.cross(b - a, c - a), (a + b + c) / 3 - centre) < 0:
            f[1], f[2] = f[2], f[1]
    return {"shape": "triangles", "vertices": v.tolist(), "faces": faces}


def emitter(z=-1.0, h=4.0):
    """A white emitter of radiance 1 at height z facing up (+z)."""
    return {"shape": "quad", "vertices": [[-h, -h, z], [h, -h, z], [h, h, z], [-h, h, z]], "material": "black",
            "emission": {"radiance": 1.0}}


def scene(objects, materials, camera=None, lights=(), spp=4, size=8, **render):
    cam = camera or {"projection": "orthographic", "ortho_width": 0.5, "origin": [0, 0, 5], "target": [0, 0, 0],
                     "up": [0, 1, 0]}
    return {"format": "polar-scene/1", "camera": {"width": size, "height": size, **cam},
            "render": {"spp": spp, "max_depth": 8, "sampler": "independent", **render},
            "materials": {"black": {"type": "lambert", "albedo": 0.0}, **materials},
            "objects": list(objects), "lights": list(lights)}


def render(data):
    return Renderer(parse_scene(copy.deepcopy(data))).render()


def with_interior(material, interior):
    return {**material, "interior": interior}


def slab(surface):
    """The slab 0 ≤ z ≤ THICK (wide: every camera ray crosses its top and bottom) and its material."""
    obj = box([-3, -3, 0], [3, 3, THICK])
    if surface == "pass-through":
        obj["alpha"] = 0.0                  # a volume without a surface (Blender: only a Volume output)
        return obj, {"type": "lambert", "albedo": 0.5}
    return obj, dict(MATCHED)


def pixel_mean(result):
    return result.stokes()[0].mean(axis=(0, 1))


# ----------------------------------------------------------------------------- (1) a slab

@pytest.mark.parametrize("surface", ["index-matched", "pass-through"])
def test_slab_transmits_exp_minus_sigma_d_per_channel_in_rgb_mode(surface):
    obj, material = slab(surface)
    clear = scene([{**obj, "material": "slab"}, emitter()], {"slab": material})
    dark = scene([{**obj, "material": "slab"}, emitter()],
                 {"slab": with_interior(material, {"absorption": SIGMA.tolist()})})
    a, b = render(clear), render(dark)
    assert a.stats["spectral"].startswith("RGB")
    np.testing.assert_allclose(pixel_mean(b) / pixel_mean(a), np.exp(-SIGMA * THICK), rtol=2e-6)
    assert "absorbing interiors: 'slab'" in b.stats["transport_reason"]
    assert "absorbing" not in a.stats["transport_reason"]


def test_slab_in_spectral_mode_matches_the_spectral_integral():
    """Spectral mode attenuates each wavelength by exp(−σ(λ)·d), σ(λ) the upsampled RGB: the pixel is
    the CIE integral of D65n·exp(−σ(λ)·d) (not exp(−σ_c·d) per channel: a coloured absorber's
    spectrum is not its RGB)."""
    obj, material = slab("index-matched")
    data = scene([{**obj, "material": "slab"}, emitter()],
                 {"slab": with_interior(material, {"absorption": SIGMA.tolist()})}, spp=128, size=16,
                 reduce_spectral="off")
    result = render(data)
    assert result.stats["spectral"] == "spectral"
    pixels = result.stokes()[0].reshape(-1, 3)
    white = RGBIlluminantSpectrum([1.0, 1.0, 1.0]).eval(GRID_NM)
    sigma = SIGMA @ basis_rgb(GRID_NM)
    want = spectrum_to_linear_srgb(white * np.exp(-sigma * THICK))
    got, err = pixels.mean(axis=0), pixels.std(axis=0) / np.sqrt(len(pixels))
    assert np.all(np.abs(got - want) < 4 * err + 1e-4), (got, want, err)
    # which is not the RGB mode's answer (for this coloured absorber the two differ by more than the
    # test's resolution in red)
    assert abs(want[0] - np.exp(-SIGMA[0] * THICK)) > max(5e-3, 5 * err[0])


# ----------------------------------------------------------------------------- (2) a glass sphere

def _fresnel_sp(cos_i, n):
    """(R_s, R_p) of a smooth interface from index 1 into n (independent of the engine)."""
    sin_t = np.sqrt(1 - cos_i ** 2) / n
    cos_t = np.sqrt(1 - sin_t ** 2)
    rs = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    rp = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    return rs ** 2, rp ** 2, cos_t


def sphere_radiance(b, sigma, n=1.5, radius=1.0):
    """S0 (…, 3) leaving a smooth absorbing sphere along a ray at impact parameter b under a uniform,
    unpolarised sky of radiance 1.  All vertices of such a path lie in one plane through the centre, so
    s and p never mix: S0 = ½(S0_s + S0_p), each the series R + T²a·Σ(Ra)^k = R + T²a/(1 − Ra) with the
    same R at every (internal) bounce and a = exp(−σ·2r·cosθ_t) per chord."""
    cos_i = np.sqrt(np.clip(1 - (b / radius) ** 2, 0, 1))
    Rs, Rp, cos_t = _fresnel_sp(cos_i, n)
    a = np.exp(-np.multiply.outer(2 * radius * cos_t, sigma))
    out = 0
    for R in (Rs, Rp):
        R = R[..., None]
        out = out + 0.5 * (R + (1 - R) ** 2 * a / (1 - R * a))
    return out


def test_glass_sphere_under_a_uniform_sky_matches_the_in_plane_series():
    sigma = np.array([0.3, 0.8, 2.0])
    size, width = 16, 1.2
    cam = {"projection": "orthographic", "ortho_width": width, "origin": [0, -5, 0], "target": [0, 0, 0],
           "up": [0, 0, 1]}
    glass = {"type": "dielectric", "n": 1.5}
    objects = [{"shape": "sphere", "center": [0, 0, 0], "radius": 1.0, "material": "glass"}]
    sky = [{"type": "environment", "radiance": 1.0}]
    common = dict(camera=cam, lights=sky, spp=64, size=size, max_depth=64, rr_depth=64)
    clear = render(scene(objects, {"glass": glass}, **common))
    dark = render(scene(objects, {"glass": with_interior(glass, {"absorption": sigma.tolist()})}, **common))
    # the oracle, integrated over each pixel's square on a 12 × 12 grid (it is smooth there: b < 0.85)
    sub = (np.arange(12) + 0.5) / 12
    edges = (np.arange(size) / size - 0.5) * width
    x = (edges[:, None] + sub[None, :] * width / size).ravel()
    bx, bz = np.meshgrid(x, x)
    f = sphere_radiance(np.hypot(bx, bz), sigma)
    want = f.reshape(size, 12, size, 12, 3).mean(axis=(1, 3))
    got = dark.stokes()[0]
    resid = (got - want).reshape(-1, 3)
    err = resid.std(axis=0) / np.sqrt(resid.shape[0])
    assert np.all(np.abs(resid.mean(axis=0)) < 4 * err + 2e-4), (resid.mean(axis=0), err)
    assert np.abs(resid).max() < 0.1
    # without absorption the sphere is invisible against the sky (energy conservation), within noise
    c = clear.stokes()[0].reshape(-1, 3)
    assert np.all(np.abs(c.mean(axis=0) - 1) < 4 * c.std(axis=0) / np.sqrt(len(c)) + 2e-4)
    # the ratio, per channel, as the series says (the unabsorbed mean is 1 within 4e-3)
    ratio = got.reshape(-1, 3).mean(axis=0) / c.mean(axis=0)
    assert np.all(np.abs(ratio - want.reshape(-1, 3).mean(axis=0)) < 4 * err + 4e-3), (ratio, want.mean(axis=(0, 1)))


# ----------------------------------------------------------------------------- (3) nested media

OUTER, INNER = np.array([0.2, 0.4, 0.6]), np.array([1.5, 0.5, 1.0])


def nested(camera, lights=()):
    materials = {"water": with_interior(MATCHED, {"absorption": OUTER.tolist()}),
                 "ice": with_interior(MATCHED, {"absorption": INNER.tolist()})}
    objects = [{**box([-2, -2, 0], [2, 2, 2]), "material": "water"},
               {**box([-0.5, -0.5, 0.5], [0.5, 0.5, 1.0]), "material": "ice"}, emitter()]
    return scene(objects, materials, camera=camera, lights=lights), {**materials, "water": MATCHED, "ice": MATCHED}


@pytest.mark.parametrize("camera,outer_length", [
    ({"projection": "orthographic", "ortho_width": 0.5, "origin": [0, 0, 5], "target": [0, 0, 0],
      "up": [0, 1, 0]}, 2.0),
    # inside the water: each camera ray's stack starts with the water (Cycles' +Z test), per ray ...
    ({"projection": "orthographic", "ortho_width": 0.5, "origin": [0, 0, 1.5], "target": [0, 0, 0],
      "up": [0, 1, 0]}, 1.5),
    # ... and for a pinhole (one origin, one test ray); a 1° field: lengths within 4e-5
    ({"fov_deg": 1.0, "origin": [0, 0, 1.5], "target": [0, 0, 0], "up": [0, 1, 0]}, 1.5)])
def test_nested_media_attenuate_by_the_product_over_segments(camera, outer_length):
    """A cube of ice inside a box of water: the segments in the water only are attenuated by σ_water,
    those in the ice by σ_water + σ_ice (Cycles adds the coefficients of every volume on the stack)."""
    data, clear_materials = nested(camera)
    clear = copy.deepcopy(data)
    clear["materials"].update(clear_materials)
    ratio = pixel_mean(render(data)) / pixel_mean(render(clear))
    want = np.exp(-OUTER * outer_length - INNER * 0.5)
    np.testing.assert_allclose(ratio, want, rtol=1e-4 if "fov_deg" in camera else 2e-6)


def test_shadow_rays_inside_a_medium_are_attenuated():
    """A Lambert floor and a point light both inside an absorbing box, seen by a camera also inside:
    the light is attenuated along the shadow ray (height 1) and the camera ray (height 1.5)."""
    cam = {"projection": "orthographic", "ortho_width": 0.01, "origin": [0, 0, 1.5], "target": [0, 0, 0],
           "up": [0, 1, 0]}
    floor = {"shape": "quad", "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], "material": "floor"}
    lamp = [{"type": "point", "position": [0, 0, 1.0], "intensity": 3.0}]
    objects = [{**box([-2, -2, -0.5], [2, 2, 2]), "material": "water"}, floor]
    mats = {"floor": {"type": "lambert", "albedo": 0.5}}
    clear = render(scene(objects, {**mats, "water": MATCHED}, camera=cam, lights=lamp, max_depth=3))
    dark = render(scene(objects, {**mats, "water": with_interior(MATCHED, {"absorption": OUTER.tolist()})},
                        camera=cam, lights=lamp, max_depth=3))
    np.testing.assert_allclose(pixel_mean(clear), 0.5 / np.pi * 3.0, rtol=1e-3)
    np.testing.assert_allclose(pixel_mean(dark) / pixel_mean(clear), np.exp(-OUTER * 2.5), rtol=1e-4)


def test_shadow_and_camera_rays_crossing_a_pass_through_volume():
    """A surface-less absorbing box (alpha 0: crossed without a bounce) around a floor, the lamp and the
    camera outside: the camera ray runs 2 inside (top at z = 2), the shadow ray from the floor too."""
    cam = {"projection": "orthographic", "ortho_width": 0.01, "origin": [0, 0, 4], "target": [0, 0, 0],
           "up": [0, 1, 0]}
    floor = {"shape": "quad", "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], "material": "floor"}
    lamp = [{"type": "point", "position": [0, 0, 3.0], "intensity": 3.0}]
    fog = {**box([-2, -2, -0.5], [2, 2, 2]), "material": "fog", "alpha": 0.0}
    mats = {"floor": {"type": "lambert", "albedo": 0.5}}
    fog_material = {"type": "lambert", "albedo": 0.5}
    clear = render(scene([fog, floor], {**mats, "fog": fog_material}, camera=cam, lights=lamp, max_depth=3))
    dark = render(scene([fog, floor], {**mats, "fog": with_interior(fog_material, {"absorption": OUTER.tolist()})},
                        camera=cam, lights=lamp, max_depth=3))
    np.testing.assert_allclose(pixel_mean(dark) / pixel_mean(clear), np.exp(-OUTER * 4.0), rtol=1e-4)


# ----------------------------------------------------------------------------- (4) polarisation

@pytest.mark.parametrize("reduce", ["auto", "off"])
def test_absorption_scales_every_stokes_component_alike(reduce):
    """A polariser (30°) and a quarter-wave-ish retarder make the emitter's light elliptically polarised;
    the absorbing slab behind them scales S0…S3 by the same exp(−σ·d) (per channel in RGB mode); in
    spectral mode the normalised Stokes vector S_k/S0 of each channel is unchanged."""
    sheets = [{"shape": "quad", "vertices": [[-3, -3, z], [3, -3, z], [3, 3, z], [-3, 3, z]], "material": m}
              for z, m in ((-0.6, "polariser"), (-0.3, "retarder"))]
    obj, material = slab("index-matched")
    materials = {"polariser": {"type": "polariser", "axis": [1.0, 0.577, 0.0]},
                 "retarder": {"type": "retarder", "axis": [1.0, 0.0, 0.0], "retardance_deg": 60.0}}
    common = dict(polarisation="full", rr_depth=100, reduce_spectral=reduce, spp=8)
    clear = render(scene([{**obj, "material": "slab"}, *sheets, emitter()], {**materials, "slab": material},
                         **common)).stokes()
    dark = render(scene([{**obj, "material": "slab"}, *sheets, emitter()],
                        {**materials, "slab": with_interior(material, {"absorption": SIGMA.tolist()})},
                        **common)).stokes()
    S = clear.mean(axis=(1, 2))                          # (4, 3)
    assert np.all(np.abs(S[1:] / S[0]) > 0.05)           # S1, S2 and S3 all present
    if reduce == "auto":
        np.testing.assert_allclose(dark, clear * np.exp(-SIGMA * THICK), rtol=1e-6, atol=1e-12)
    else:
        D = dark.mean(axis=(1, 2))
        np.testing.assert_allclose(D[1:] / D[0], S[1:] / S[0], rtol=1e-9)
        assert np.all(D[0] < 0.7 * S[0])


# ----------------------------------------------------------------------------- (5) zero density

def test_zero_density_is_no_interior_bit_for_bit():
    obj, material = slab("index-matched")
    base = scene([{**obj, "material": "slab"}, emitter()], {"slab": material}, spp=2)
    none = render(base)
    zero = copy.deepcopy(base)
    zero["materials"]["slab"]["interior"] = {"color": [0.2, 0.5, 0.9], "density": 0.0}
    parsed = parse_scene(zero)
    assert not hasattr(parsed.materials["slab"], "interior")
    assert render(zero).stokes().tobytes() == none.stokes().tobytes()
    # through the Python API: an interior that absorbs nothing is ignored when the scene is compiled
    api = parse_scene(copy.deepcopy(base))
    api.materials["slab"].interior = Interior([0.0, 0.0, 0.0])
    result = Renderer(api).render()
    assert result.stokes().tobytes() == none.stokes().tobytes()
    assert "absorbing" not in result.stats["transport_reason"]


def test_blender_volume_absorption_is_density_times_one_minus_colour():
    interior = Interior.from_color_density([0.25, 0.5, 1.0], 4.0)
    np.testing.assert_array_equal(interior.absorption.linear_srgb(), [3.0, 2.0, 0.0])
    obj, material = slab("index-matched")
    data = scene([{**obj, "material": "slab"}, emitter()],
                 {"slab": with_interior(material, {"color": [0.25, 0.5, 1.0], "density": 4.0})})
    np.testing.assert_array_equal(parse_scene(data).materials["slab"].interior.absorption.linear_srgb(), [3, 2, 0])


# ----------------------------------------------------------------------------- (6) bad input

@pytest.mark.parametrize("interior,field", [
    ({"absorption": [1.0, -2.0, 3.0]}, "materials.slab.interior.absorption[1]"),
    ({"absorption": float("nan")}, "materials.slab.interior.absorption"),
    ({"absorption": -1.0}, "materials.slab.interior.absorption"),
    ({"color": [0.5, float("nan"), 0.5], "density": 1.0}, "materials.slab.interior.color[1]"),
    ({"color": [0.5, 0.5, 0.5], "density": -1.0}, "materials.slab.interior.density"),
    ({"color": [0.5, 0.5, 0.5], "density": float("nan")}, "materials.slab.interior.density"),
    ({"color": [0.5, 0.5, 0.5]}, "materials.slab.interior.density"),
    ({"absorption": 1.0, "density": 1.0}, "materials.slab.interior.absorption"),
    ({"absorbtion": 1.0}, "materials.slab.interior.absorbtion"),
    ([1, 2, 3], "materials.slab.interior")])
def test_bad_interiors_are_refused_in_one_line_naming_the_field(interior, field):
    obj, material = slab("index-matched")
    data = scene([{**obj, "material": "slab"}, emitter()], {"slab": {**material, "interior": interior}})
    with pytest.raises(SceneError) as e:
        parse_scene(data)
    assert e.value.field == field and "\n" not in str(e.value) and str(e.value).startswith(field)


def test_bad_interiors_from_python_name_the_field():
    for make, field in ((lambda: Interior([1.0, -1.0, 0.0]), "interior.absorption[1]"),
                        (lambda: Interior(float("nan")), "interior.absorption"),
                        (lambda: Interior.from_color_density([0.5, 0.5, 2.0], 1.0), "interior.color"),
                        (lambda: Interior.from_color_density([0.5, 0.5, 0.5], -1.0), "interior.density")):
        with pytest.raises(SceneError) as e:
            make()
        assert e.value.field == field and "\n" not in str(e.value)


def test_an_interior_belongs_to_a_scene_material_not_a_mixed_one():
    mix = {"type": "mix", "materials": [{"type": "lambert", "albedo": 0.5, "interior": {"absorption": 1.0}},
                                        {"type": "lambert", "albedo": 0.2}], "weights": [0.5, 0.5]}
    obj, _ = slab("index-matched")
    with pytest.raises(SceneError) as e:
        parse_scene(scene([{**obj, "material": "m"}, emitter()], {"m": mix}))
    assert e.value.field == "materials.m.materials[0].interior"


# ----------------------------------------------------------------------------- the stacks

def test_medium_stack_operations_follow_cycles_list_rule():
    """enter/leave on (K, n) stacks = Cycles' volume stack on lists: enter appends unless present or full,
    leave removes the entry wherever it is (the entries above move down)."""
    from engine.render.media import enter, leave
    rng = np.random.default_rng(1)
    K, n = 4, 40
    for _ in range(50):
        lists = [[] for _ in range(n)]
        stack = np.full((K, n), -1, np.int32)
        for _ in range(12):
            cols = np.sort(rng.choice(n, size=int(rng.integers(1, n)), replace=False))
            vol = rng.integers(0, 5, cols.size).astype(np.int32)
            if rng.random() < 0.5:
                enter(stack, cols, vol)
                for c, v in zip(cols, vol):
                    if v not in lists[c] and len(lists[c]) < K:
                        lists[c].append(int(v))
            else:
                leave(stack, cols, vol)
                for c, v in zip(cols, vol):
                    if v in lists[c]:
                        lists[c].remove(int(v))
            want = np.full((K, n), -1)
            for c, entries in enumerate(lists):
                want[:len(entries), c] = entries
            assert np.array_equal(stack, want)
