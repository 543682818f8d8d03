"""Emitters whose radiance varies over the surface: strength × a texture's RGB (Blender: an Image
Texture into Emission Color), against values computed without the textured emitter — a constant
emitter of the texel's colour, a numerical integral over the emitter — and its own two samplings
(by area / by emitted luminance), which must agree in the mean and differ in the variance."""

import dataclasses
import math

import numpy as np
import pytest

from engine.materials.lambert import Lambert
from engine.render.accel import CompiledScene
from engine.render.lights import LightSet, TexturedAreaEmitter
from engine.render.renderer import Renderer
from engine.scene.description import Camera, Mesh, RenderSettings, Scene
from engine.scene.shapes import quad
from engine.spectral import GRID_NM, ConstantSpectrum, RGBIlluminantSpectrum, luminance, spectrum_to_linear_srgb
from engine.textures import ImageTexture, TextureInput, VertexAttributes, textured_emission

RHO = 0.5


def constant_rgb(rgb, strength=1.0):
    """The linear sRGB a constant emitter of this colour develops to (what RGB mode renders)."""
    return spectrum_to_linear_srgb(RGBIlluminantSpectrum(list(rgb), strength).eval(GRID_NM))


def grid_mesh(name, corner, ex, ey, nx, ny, emission, **options):
    """An nx × ny grid of quads corner + (i/nx)·ex + (j/ny)·ey, front side along ex × ey, UV (i/nx, j/ny)."""
    i, j = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), indexing="xy")
    s, t = (i / nx).ravel(), (j / ny).ravel()
    ex, ey = np.asarray(ex, float), np.asarray(ey, float)
    vertices = np.asarray(corner, float)[None, :] + s[:, None] * ex + t[:, None] * ey
    faces = []
    for b in range(ny):
        for a in range(nx):
            v00, v01 = b * (nx + 1) + a, (b + 1) * (nx + 1) + a
            v10, v11 = v00 + 1, v01 + 1
            faces += [[v00, v10, v11], [v00, v11, v01]]
    faces = np.array(faces, np.int64)
    mesh = Mesh(name, vertices, faces, ["black"], np.zeros(len(faces), np.int32), emission=emission,
                uv=np.stack((s, t), axis=1))
    for key, value in options.items():
        setattr(mesh, key, value)
    return mesh


def image(pixels, interpolation="Closest"):
    return ImageTexture(np.asarray(pixels, np.float32), interpolation, "EXTEND")


def floor_scene(meshes, res=8, spp=16, width=2.0, max_depth=2, spectral="spectral", sampler="stratified", seed=0):
    """A Lambertian floor (albedo RHO) at z = 0 seen straight from above by an orthographic camera
    (x, y ∈ [−width/2, width/2])."""
    f = quad(*[np.array(p, float) for p in ([-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0])])
    cam = Camera(origin=np.array([0.0, 0.0, 5.0]), target=np.zeros(3), up=np.array([0.0, 1.0, 0.0]),
                 width=res, height=res, projection="orthographic", ortho_width=width)
    return Scene(camera=cam, meshes=[Mesh("floor", f.vertices, f.faces, ["grey"], np.zeros(2, np.int32)), *meshes],
                 materials={"grey": Lambert(ConstantSpectrum(RHO)), "black": Lambert(ConstantSpectrum(0.0))},
                 lights=[], settings=RenderSettings(spp=spp, spectral=spectral, max_depth=max_depth, sampler=sampler,
                                                    seed=seed))


def render(scene, **settings):
    return Renderer(scene).render(dataclasses.replace(scene.settings, **settings))


def light_of(scene, name):
    lights = LightSet(scene, CompiledScene(scene))
    index = [m.name for m in scene.meshes if m.emission is not None].index(name)
    return lights, lights.lights[index]


# ------------------------------------------------------------------------ (1) seen by the camera

@pytest.mark.parametrize("occluder", [True, False])
def test_a_textured_emitter_seen_directly_has_the_texels_colour_times_the_strength(occluder):
    """A quad filling the view, 2×1 texture: left texel red, right black, strength 2; an opaque
    emitter (the hit's barycentrics) or a lamp that rays cross (the crossing point's).  RGB mode (the
    materials are grey): each pixel is exactly what a constant emitter of its texel's colour renders
    (= 2·(1, 0, 0) within the D65/sRGB white point's 3·10⁻⁴); mono: 2·luminance(red); spectral
    (reduction off): the same mean within its noise; the black half exactly 0."""
    strength, red = 2.0, (1.0, 0.0, 0.0)
    emission = textured_emission(TextureInput(image([[red, (0.0, 0.0, 0.0)]])), strength)
    lamp = grid_mesh("lamp", (-1, -1, 1), (2, 0, 0), (0, 2, 0), 1, 1, emission,       # faces +z, the camera
                     occluder=occluder)
    scene = floor_scene([lamp], res=8, spp=4, max_depth=1)
    expected = constant_rgb(red, strength)
    assert np.abs(expected - (2.0, 0.0, 0.0)).max() < 1e-3
    S = render(scene).stokes()[0]                                           # (H, W, 3); columns 0–3: x < 0
    np.testing.assert_allclose(S[:, :4], np.broadcast_to(expected, (8, 4, 3)), rtol=1e-12, atol=1e-15)
    assert np.all(S[:, 4:] == 0)
    # the same image from a constant red emitter over the left half (an independent construction)
    left = grid_mesh("left", (-1, -1, 1), (1, 0, 0), (0, 2, 0), 1, 1, RGBIlluminantSpectrum(list(red), strength))
    np.testing.assert_allclose(render(floor_scene([left], res=8, spp=4, max_depth=1)).stokes()[0][:, :4], S[:, :4],
                               rtol=1e-12)
    mono = render(scene, spectral="mono").stokes()[0]
    np.testing.assert_allclose(mono[:, :4], strength * 0.2126, rtol=1e-12)
    assert np.all(mono[:, 4:] == 0)
    spectral = render(scene, reduce_spectral="off", spp=16)
    mean = spectral.stokes()[0][:, :4].mean(axis=(0, 1))
    assert np.all(spectral.stokes()[0][:, 4:] == 0)
    np.testing.assert_allclose(mean, expected, atol=0.02 * strength)


# ------------------------------------------------------------------------ (2) a lit floor, integrated

#: a 4×4 texture: coloured texels, two black ones (rows from v = 0)
TEXELS = np.array([[(1.0, 0.2, 0.1), (0.0, 0.0, 0.0), (0.3, 0.9, 0.2), (0.5, 0.5, 0.5)],
                   [(0.1, 0.1, 0.8), (2.0, 1.0, 0.0), (0.0, 0.0, 0.0), (0.2, 0.6, 0.9)],
                   [(0.9, 0.9, 0.1), (0.4, 0.0, 0.4), (1.5, 0.3, 0.3), (0.1, 0.8, 0.8)],
                   [(0.6, 0.3, 0.0), (0.0, 0.4, 0.1), (0.2, 0.2, 1.2), (1.0, 1.0, 1.0)]])
H_LAMP, SIDE = 0.5, 1.0


def gauss(n, a, b):
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (b - a) * x + 0.5 * (a + b), 0.5 * (b - a) * w


def expected_floor_rgb(strength, res, width):
    """ρ/π ∫ L(x) cosθ_p cosθ_x / r² dA over the lamp (SIDE², height H_LAMP, facing down, texel (i, j)
    on x ∈ [−½ + i/4, …], y ∈ [½ − (j+1)/4, ½ − j/4]: ey = −y), per cell by Gauss–Legendre, averaged
    over each pixel by Gauss–Legendre; the cells' colours as constant emitters develop."""
    out = np.zeros((res, res, 3))
    px = (np.arange(res) + 0.5) / res * width - width / 2
    half = width / res / 2
    for row in range(res):
        for col in range(res):
            fx, wx = gauss(4, px[col] - half, px[col] + half)
            fy, wy = gauss(4, -px[row] - half, -px[row] + half)          # row 0 at the top (+y)
            P = np.stack(np.meshgrid(fx, fy, indexing="ij"), -1).reshape(-1, 2)
            W = np.outer(wx, wy).ravel() / (2 * half) ** 2
            total = np.zeros(3)
            for j in range(4):
                for i in range(4):
                    if not TEXELS[j, i].any():
                        continue
                    gx, gwx = gauss(12, -SIDE / 2 + i * SIDE / 4, -SIDE / 2 + (i + 1) * SIDE / 4)
                    gy, gwy = gauss(12, SIDE / 2 - (j + 1) * SIDE / 4, SIDE / 2 - j * SIDE / 4)
                    dx = gx[None, :, None] - P[:, 0, None, None]
                    dy = gy[None, None, :] - P[:, 1, None, None]
                    r2 = dx * dx + dy * dy + H_LAMP ** 2
                    g = (H_LAMP ** 2 / r2 ** 2 * gwx[None, :, None] * gwy[None, None, :]).sum(axis=(1, 2))
                    total += (W * g).sum() * constant_rgb(TEXELS[j, i], strength)
            out[row, col] = RHO / math.pi * total
    return out


@pytest.mark.parametrize("cells", [1, 2])
def test_a_floor_under_a_textured_lamp_has_the_integrated_irradiance(cells):
    """A 4×4-texel lamp (coloured texels, two black) over the floor — one rectangle (sampled by the
    mixture of solid angle and luminance) or 2×2 cells (by luminance), each triangle over several
    texels — a non-occluding lamp hidden from the camera (BSDF-sampled rays cross it: its texture is
    read where they cross).  RGB per channel, mean of 8 seeds: within 5 standard errors of the seeds
    per pixel for ≥ 95 % of the pixels and over the image."""
    strength, res, width, seeds = 3.0, 6, 2.0, 8
    lamp = grid_mesh("lamp", (-SIDE / 2, SIDE / 2, H_LAMP), (SIDE, 0, 0), (0, -SIDE, 0), cells, cells,
                     textured_emission(TextureInput(image(TEXELS)), strength), occluder=False, visible_camera=False)
    scene = floor_scene([lamp], res=res, spp=64, width=width)
    images = np.array([render(scene, seed=s).stokes()[0] for s in range(seeds)])
    expected = expected_floor_rgb(strength, res, width)
    mean, se = images.mean(0), images.std(0, ddof=1) / math.sqrt(seeds)
    assert np.mean(np.abs(mean - expected) <= 5 * se + 1e-9) >= 0.95
    totals = images.sum(axis=(1, 2))                                         # (seeds, 3)
    t_se = totals.std(0, ddof=1) / math.sqrt(seeds)
    assert np.all(np.abs(totals.mean(0) - expected.sum(axis=(0, 1))) < 5 * t_se)
    assert np.all(t_se < 0.015 * expected.sum(axis=(0, 1)))                 # a test that can fail
    # the same lamp split into 14 constant-coloured cells (independent emitters): same image within noise
    cells = [grid_mesh(f"cell{j}{i}", (-SIDE / 2 + i * SIDE / 4, SIDE / 2 - j * SIDE / 4, H_LAMP), (SIDE / 4, 0, 0),
                       (0, -SIDE / 4, 0), 1, 1, RGBIlluminantSpectrum(list(TEXELS[j, i]), strength),
                       occluder=False, visible_camera=False)
             for j in range(4) for i in range(4) if TEXELS[j, i].any()]
    split = render(floor_scene(cells, res=res, spp=128, width=width)).stokes()[0]
    assert np.all(np.abs(split.sum(axis=(0, 1)) - totals.mean(0)) < 5 * t_se + 0.01 * expected.sum(axis=(0, 1)))


@pytest.mark.parametrize("mode", [{}, {"reduce_spectral": "off"}, {"spectral": "mono"}, {"spectral": "rgb"}])
def test_a_uniform_texture_renders_as_the_constant_emitter_of_its_colour(mode):
    """A rectangle lamp whose texture is one colour everywhere: sampled as the constant emitter is (by
    solid angle), so the lit floor and the lamp seen directly equal the constant emitter's render with
    the same random numbers, to rounding (RGB, spectral and mono; the "rgb" transport too, where both are the
    colour's own channels — before, the textured one was its integrated illuminant, 2e-4 off)."""
    colour, strength = (0.8, 0.4, 0.2), 3.0
    textured = grid_mesh("lamp", (-0.5, 0.5, 0.6), (1, 0, 0), (0, -1, 0), 1, 1,
                         textured_emission(TextureInput(image(np.full((3, 5, 3), colour))), strength))
    constant = grid_mesh("lamp", (-0.5, 0.5, 0.6), (1, 0, 0), (0, -1, 0), 1, 1,
                         RGBIlluminantSpectrum(list(np.float32(colour).astype(float)), strength))
    scenes = [floor_scene([m], res=8, spp=8, max_depth=3) for m in (textured, constant)]
    assert light_of(scenes[0], "lamp")[1].density is None
    a, b = (render(s, **mode).stokes()[0] for s in scenes)
    assert b.max() > 0
    np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-14)


# ------------------------------------------------------------------------ (3) MIS: both samplings agree

#: a 4×4 texture with a bright corner, a black band and dim texels (the triangles' weights all differ)
PANEL = np.array([[(8.0, 6.0, 2.0), (0.5, 0.5, 0.5), (0.0, 0.0, 0.0), (0.1, 0.1, 0.1)],
                  [(0.4, 0.2, 0.1), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.2, 0.2, 0.2)],
                  [(0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 2.0, 3.0), (0.0, 0.0, 0.0)],
                  [(0.3, 0.3, 0.3), (0.0, 0.0, 0.0), (0.2, 0.1, 0.0), (0.05, 0.05, 0.05)]])


@pytest.mark.parametrize("panel", ["one-sided rectangle", "two-sided occluding grid"])
def test_luminance_and_area_sampling_render_the_same_mean(panel):
    """A vertical panel close to the floor (so BSDF-sampled rays hit it often, and MIS weighs both
    estimates), paths up to 3 segments, mono: the image rendered with the emitter sampled by emitted
    luminance (a rectangle: the mixture of solid angle and luminance) equals the one sampled as a
    constant emitter (a rectangle: by solid angle; a two-sided grid, Blender's emissive mesh that can
    shadow itself: by area) within 4.5 σ over the image and per pixel (≥ 98 %).  A pdf_hit not
    matching the sampling would bias the luminance image."""
    emission = textured_emission(TextureInput(image(PANEL, "Linear")), 2.0)
    if panel == "one-sided rectangle":      # faces −x: the front of corner → corner+ex → corner+ex+ey
        make = dict(nx=1, ny=1)
        options = {}
    else:
        make = dict(nx=6, ny=6)
        options = {"two_sided": True}
    lum = grid_mesh("panel", (0.4, -0.8, 0.3), (0, 0, 0.8), (0, 1.6, 0), emission=emission, **make, **options)
    area = grid_mesh("panel", (0.4, -0.8, 0.3), (0, 0, 0.8), (0, 1.6, 0), emission=emission, **make,
                     **options, emission_sampling="area")
    settings = dict(res=10, spp=128, width=2.0, max_depth=3, spectral="mono", sampler="independent")
    scenes = [floor_scene([lum], **settings), floor_scene([area], **settings)]
    emitters = [light_of(s, "panel")[1] for s in scenes]
    assert emitters[0].density is not None and emitters[1].density is None          # the two samplings
    if panel == "one-sided rectangle":
        assert emitters[1].rect is not None
    else:
        assert emitters[0].blocks_own_shadow_rays and emitters[1].blocks_own_shadow_rays
    results = [render(s) for s in scenes]
    (a, b), (sa, sb) = [r.stokes_luminance()[0] for r in results], [r.film.stderr_luminance()[0] for r in results]
    se = np.sqrt(sa ** 2 + sb ** 2)
    assert abs(a.sum() - b.sum()) < 4.5 * np.sqrt((se ** 2).sum())
    assert np.sqrt((se ** 2).sum()) < 0.04 * a.sum()
    assert np.mean(np.abs(a - b) <= 4.5 * se + 1e-12) >= 0.98
    assert all(r.stats["nonfinite"] == 0 for r in results)


# ------------------------------------------------------------------------ (4) importance by luminance

def test_luminance_sampling_cuts_the_variance_of_a_small_bright_region():
    """A 16×16-cell lamp whose texture is dim (0.02) but for one bright texel (50): by area, 1 NEE
    sample in 256 finds the bright cell; by luminance nearly all.  Same mean (4 σ), and the lit floor's
    pixel variance (i.i.d. standard errors, independent sampler) ≥ 3× lower by luminance."""
    pixels = np.full((16, 16, 3), 0.02, np.float32)
    pixels[9, 4] = 50.0
    emission = textured_emission(TextureInput(image(pixels)), 1.0)
    make = dict(corner=(-0.8, 0.8, 0.6), ex=(1.6, 0, 0), ey=(0, -1.6, 0), nx=16, ny=16, emission=emission,
                occluder=False, visible_camera=False)
    settings = dict(res=8, spp=32, width=2.0, spectral="mono", sampler="independent")
    by_lum = render(floor_scene([grid_mesh("lamp", **make)], **settings))
    by_area = render(floor_scene([grid_mesh("lamp", **make, emission_sampling="area")], **settings))
    a, b = by_lum.stokes_luminance()[0], by_area.stokes_luminance()[0]
    va, vb = by_lum.film.stderr_luminance()[0] ** 2, by_area.film.stderr_luminance()[0] ** 2
    assert abs(a.sum() - b.sum()) < 4 * np.sqrt(va.sum() + vb.sum())
    ratio = vb.mean() / va.mean()
    assert ratio >= 3.0, ratio


# ------------------------------------------------------------------------ (5) black emitters

@pytest.mark.parametrize("sampling", ["luminance", "area"])
def test_an_all_black_textured_emitter_gives_no_light_and_no_nan(sampling):
    """An emitter whose texture is black everywhere (seen by the camera and lighting the floor), under
    uniform and power light selection, in RGB, mono and spectral: every pixel 0, no non-finite sample."""
    emission = textured_emission(TextureInput(image(np.zeros((4, 4, 3)))), 5.0)
    lamp = grid_mesh("lamp", (-0.5, -0.5, 0.5), (1, 0, 0), (0, 1, 0), 2, 2, emission, two_sided=True,
                     emission_sampling=sampling)
    scene = floor_scene([lamp], res=6, spp=4, max_depth=3)
    _, light = light_of(scene, "lamp")
    assert light.black and light.power() == 0
    for selection in ("uniform", "power"):
        scene.light_selection = selection
        for mode in ({}, {"spectral": "mono"}, {"reduce_spectral": "off"}):
            r = render(scene, **mode)
            assert np.all(r.stokes() == 0) and r.stats["nonfinite"] == 0, (selection, mode)


def test_next_event_samples_never_land_on_black_triangles():
    """Partly black (4×4 PANEL on 8×8 cells, Closest): every luminance-sampled point has emitted
    luminance > 0, every triangle whose texels are black gets probability 0, and the pdf of each
    sample is what pdf_hit gives at that point (MIS sees the same pdf)."""
    emission = textured_emission(TextureInput(image(PANEL)), 1.0)
    lamp = grid_mesh("lamp", (-0.5, 0.5, 1.0), (1, 0, 0), (0, -1, 0), 8, 8, emission)
    scene = floor_scene([lamp])
    _, light = light_of(scene, "lamp")
    # cell (a, b) of the 8×8 grid lies in texel (a // 2, b // 2): black texels → weight 0
    cell_black = np.repeat(np.repeat(~PANEL.any(axis=2), 2, axis=0), 2, axis=1)          # [row b, column a]
    tri_black = np.repeat(cell_black.ravel(), 2)
    assert np.all(light.density[tri_black] == 0) and np.all(light.density[~tri_black] > 0)
    rng = np.random.default_rng(7)
    p = np.stack((rng.uniform(-1, 1, 20000), rng.uniform(-1, 1, 20000), np.zeros(20000)))
    wi, dist, scale, pdf, valid, where = light.sample_points(p, rng.random((3, 20000)))
    assert valid.all() and np.isfinite(scale).all()
    points = where
    from engine.render.accel import surface_points
    lum = emission.luminance_at(surface_points(light.compiled, *points))
    assert lum.min() > 0
    np.testing.assert_allclose(light.pdf_hit(dist, light.cos_at(where, wi), p, prim=where[0]), pdf, rtol=1e-12)


@pytest.mark.parametrize("case", ["grid by luminance", "grid by area", "rectangle by solid angle",
                                  "rectangle mixture", "far rectangle mixture", "two-sided grid"])
def test_every_sampling_estimates_the_emitted_solid_angle_integral(case):
    """E[L_e(x)·scale] over next-event samples from a point = ∫ L_e dω over the emitter (the luminance,
    by dense quadrature over each triangle: 64² equal-area points): every sampling (by luminance, by
    area, a rectangle by solid angle, the rectangle's mixture — also where its solid angle is so small
    that the rectangle falls back to area sampling) is unbiased, within 5 σ of 40,000 samples."""
    from engine.render.accel import surface_points
    from engine.render.lights.textured import triangle_grid
    # PANEL upside down: its bright corner lies in one of a rectangle's triangles (not on the diagonal)
    emission = textured_emission(TextureInput(image(PANEL[::-1], "Linear")), 1.0)
    n = 1 if "rectangle" in case else 4
    options = {"emission_sampling": "area"} if case in ("grid by area", "rectangle by solid angle") else {}
    if case == "two-sided grid":
        options["two_sided"] = True
    lamp = grid_mesh("lamp", (-0.5, 0.5, 1.0), (1, 0, 0), (0, -1, 0), n, n, emission, **options)
    scene = floor_scene([lamp])
    _, light = light_of(scene, "lamp")
    assert (light.rect is not None) == ("rectangle" in case)
    assert (light.density is None) == (case in ("grid by area", "rectangle by solid angle"))
    origin = np.array([800.0, -600.0, -400.0]) if case == "far rectangle mixture" else np.array([0.3, -0.2, 0.1])
    if case == "far rectangle mixture":
        from engine.render.lights import MIN_RECT_SOLID_ANGLE
        assert light.rect.solid_angle(origin[:, None])[0] < MIN_RECT_SOLID_ANGLE
    if case == "two-sided grid":
        origin = np.array([0.3, -0.2, 1.6])              # above: sees the back faces
    m = 40000
    rng = np.random.default_rng(11)
    p = np.repeat(origin[:, None], m, axis=1)
    wi, dist, scale, pdf, valid, where = light.sample_points(p, rng.random((3, m)))
    lum = emission.luminance_at(surface_points(light.compiled, *where))
    est = np.where(valid, lum * scale, 0.0)
    # the reference: Σ over triangles ∫ L cosθ / d² dA
    b1, b2 = triangle_grid(64)
    c = light.compiled
    total = 0.0
    for t in light.tris:
        f = c.faces[t]
        x = (c.vertices[f[0]][:, None] * (1 - b1 - b2) + c.vertices[f[1]][:, None] * b1
             + c.vertices[f[2]][:, None] * b2)
        to = x - origin[:, None]
        d2 = (to * to).sum(0)
        cos = -(to * c.tri_normal[t][:, None]).sum(0) / np.sqrt(d2)
        cos = np.abs(cos) if light.two_sided else np.maximum(cos, 0.0)
        L = emission.luminance_at(surface_points(c, np.full(b1.size, t), b1, b2))
        total += c.tri_area[t] * np.mean(L * cos / d2)
    assert total > 0
    assert abs(est.mean() - total) < 5 * est.std() / math.sqrt(m), (est.mean(), total)
    ok = valid & (pdf > 0)
    np.testing.assert_allclose(light.pdf_hit(dist[ok], light.cos_at(where, wi)[ok], p[:, ok], prim=where[0][ok]),
                               pdf[ok], rtol=1e-9)


# ------------------------------------------------------------------------ power and selection

def test_the_power_and_light_selection_use_the_textured_luminance():
    """Per-triangle mean luminance = the texel's (grid-aligned Closest texels: exact), the emitter's
    power π·Σ A·L, and power light selection picks it against a constant emitter in that ratio
    (not by the white value of the texture socket)."""
    emission = textured_emission(TextureInput(image(TEXELS)), 2.0)
    lamp = grid_mesh("lamp", (-0.5, 0.5, 1.0), (1, 0, 0), (0, -1, 0), 4, 4, emission)
    white = RGBIlluminantSpectrum([1.0, 1.0, 1.0], 1.0)
    other = grid_mesh("other", (2.0, 0.5, 1.0), (1, 0, 0), (0, -1, 0), 1, 1, white)
    scene = floor_scene([lamp, other])
    scene.light_selection = "power"
    lights, light = light_of(scene, "lamp")
    texel_lum = np.array([float(luminance(constant_rgb(c, 2.0))) for c in TEXELS.astype(np.float32).reshape(-1, 3)])
    np.testing.assert_allclose(light.tri_luminance, np.repeat(texel_lum, 2), rtol=1e-12, atol=1e-15)
    power = math.pi * texel_lum.sum() / 16
    assert light.power() == pytest.approx(power, rel=1e-12)
    constant_power = math.pi * float(luminance(constant_rgb((1, 1, 1))))
    total = power + constant_power
    np.testing.assert_allclose(lights.prob, [power / total, constant_power / total], rtol=1e-12)


def test_a_vertex_colour_emission_has_the_corners_mean_luminance_and_zero_where_they_are_black():
    """Emission from a colour attribute (linear over each triangle): each triangle's estimated mean
    luminance is the mean of its corners' (exact for a linear function), triangles with three black
    corners get probability 0 and the power is π·Σ A·L̄."""
    from engine.textures import VertexColour
    lamp = grid_mesh("lamp", (-0.5, 0.5, 1.0), (1, 0, 0), (0, -1, 0), 3, 3, None)
    rng = np.random.default_rng(5)
    colours = rng.random((16, 3)) * 2.0
    colours[[0, 1, 4, 5]] = 0.0                          # the corner cell (a, b) = (0, 0) is black
    lamp.colors = {"Col": colours}
    lamp.emission = textured_emission(TextureInput(VertexColour("Col")), 1.5)
    _, light = light_of(floor_scene([lamp]), "lamp")
    corner_lum = np.array([float(luminance(constant_rgb(c, 1.5))) for c in colours])
    expected = corner_lum[lamp.faces].mean(axis=1)
    np.testing.assert_allclose(light.tri_luminance, expected, rtol=1e-12, atol=1e-15)
    assert np.all(light.density[:2] == 0) and np.all(light.density[2:] > 0)
    assert light.power() == pytest.approx(math.pi * (expected / 18).sum(), rel=1e-12)


def test_the_texture_footprint_is_conservative():
    """Random triangles over sparse textures (every interpolation and extension): where
    ``may_be_positive`` says a triangle cannot be positive, dense lookups inside it are all 0."""
    rng = np.random.default_rng(3)
    for interpolation in ("Closest", "Linear", "Cubic"):
        for extension in ("REPEAT", "EXTEND", "CLIP", "MIRROR"):
            pixels = np.where(rng.random((7, 9, 3)) < 0.04, rng.random((7, 9, 3)), 0.0)
            tex = ImageTexture(pixels.astype(np.float32), interpolation, extension)
            T = 400
            centre = rng.uniform(-1.5, 2.5, (T, 1, 2))
            uv = centre + rng.normal(0, 0.08, (T, 3, 2))
            attributes = VertexAttributes(np.arange(3 * T).reshape(T, 3), uv.reshape(-1, 2), {})
            may = tex.may_be_positive(attributes, np.arange(T), (0, 1, 2))
            assert 0 < may.sum() < T
            w = rng.dirichlet(np.ones(3), 200)                        # points inside each triangle
            pts = np.einsum("pk,tkc->tpc", w, uv)[~may].reshape(-1, 2).T
            assert np.all(tex.lookup(pts)[:3] <= 0), (interpolation, extension)


def test_a_textured_emission_needs_an_illuminant_and_a_known_sampling():
    from engine.errors import SceneError
    from engine.textures import TexturedSpectrum
    lamp = grid_mesh("lamp", (-0.5, 0.5, 1.0), (1, 0, 0), (0, -1, 0), 1, 1,
                     TexturedSpectrum(TextureInput(image(TEXELS)), "reflectance"))
    with pytest.raises(SceneError, match="illuminant"):
        light_of(floor_scene([lamp]), "lamp")
    lamp.emission = textured_emission(TextureInput(image(TEXELS)), 1.0)
    lamp.emission_sampling = "power"
    with pytest.raises(SceneError, match="emission_sampling"):
        light_of(floor_scene([lamp]), "lamp")
    with pytest.raises(SceneError, match="radiance"):
        textured_emission(TextureInput(image(TEXELS)), -1.0)
    plain = grid_mesh("lamp", (-0.5, 0.5, 1.0), (1, 0, 0), (0, -1, 0), 1, 1,
                      textured_emission(TextureInput(image(TEXELS))))
    assert isinstance(light_of(floor_scene([plain]), "lamp")[1], TexturedAreaEmitter)


@pytest.mark.parametrize("mode", [{"spectral": "rgb"}, {"spectral": "spectral"}, {"spectral": "mono"}])
def test_a_uniform_strength_texture_renders_as_the_constant_emitter(mode):
    """Emission Strength from a texture with a constant colour (engine.textures.inputs.ColouredEmission): a
    texture of one strength everywhere renders as the constant emitter colour × strength, lit floor and lamp
    seen directly, to rounding (RGB, spectral and mono)."""
    from engine.textures.inputs import ColouredEmission
    colour, strength = (0.8, 0.4, 0.2), 2.5
    textured = grid_mesh("lamp", (-0.5, 0.5, 0.6), (1, 0, 0), (0, -1, 0), 1, 1,
                         ColouredEmission(TextureInput(image(np.full((3, 5, 1), strength))), colour))
    constant = grid_mesh("lamp", (-0.5, 0.5, 0.6), (1, 0, 0), (0, -1, 0), 1, 1,
                         RGBIlluminantSpectrum(list(colour), float(np.float32(strength))))
    scenes = [floor_scene([m], res=8, spp=8, max_depth=3) for m in (textured, constant)]
    a, b = (render(s, **mode).stokes()[0] for s in scenes)
    assert b.max() > 0
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-13)


def test_rgb_transport_reads_a_textured_emitters_texels_without_the_channel_tables():
    """"rgb" transport (WavelengthLookup with the channels' identity basis and D65 = 1): a textured emitter's radiance
    is the texels' RGB × strength, the value of the spectral formula with those tables, without gathering them for
    the paths (a subset's ``n`` does not gather its wavelengths either)."""
    from engine.spectral import WavelengthLookup, rgb_channel_tables
    rng = np.random.default_rng(3)
    texels = rng.uniform(0.0, 1.0, (4, 4, 3)) ** 2
    texels[0, 0] = 0.25                                     # a grey texel (the formula's own branch)
    panel = grid_mesh("panel", [-0.5, -0.5, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 3, 2,
                      textured_emission(TextureInput(image(texels, "Linear")), 7.0))
    _, light = light_of(floor_scene([panel]), "panel")
    n = 500
    lam = np.repeat(np.array([610.0, 550.0, 465.0])[:, None], n, axis=1)
    lookup = WavelengthLookup(lam, *rgb_channel_tables(n), channels=True)
    sub = lookup.take(np.flatnonzero(rng.random(n) < 0.6))
    assert sub.n == sub._idx.shape[0] and sub._lam is None       # no wavelengths gathered for the count
    where = (rng.choice(light.tris, sub.n), rng.uniform(0, 0.5, sub.n), rng.uniform(0, 0.5, sub.n))
    got = light.emitted_at(where, sub, False, False)
    assert sub._basis is None and sub._d65 is None               # the tables were not read
    from engine.render.accel import surface_points
    want = light.spectrum.at(surface_points(light.compiled, *where), sub.lam, False, sub.basis, sub.d65)
    assert got.shape == (3, sub.n) and np.array_equal(got, want) and got.max() > 1.0
