"""Thin lens, equirectangular camera, ray visibility, holdout, film transparency and alpha
pass-through in the engine (analytic limits; Cycles parity is in test_cycles_parity_camera.py)."""

import dataclasses
import math

import numpy as np
import pytest

from engine.errors import SceneError
from engine.render.camera import CameraModel, aperture_sample
from engine.render.renderer import Renderer, RenderRequest
from engine.scene.loader import parse_camera, parse_scene


def _camera(**extra):
    d = {"origin": [0, 0, 0], "target": [0, 1, 0], "up": [0, 0, 1], "fov_deg": 40, "width": 32, "height": 24}
    d.update(extra)
    return CameraModel(parse_camera(d))


def _rays(cam, pixel, n, seed=1):
    rng = np.random.default_rng(seed)
    u = rng.random((4, n))
    u[:2] = 0.5                                   # one film point: the pixel centre
    return cam.generate(np.full(n, pixel), u)


def test_point_on_the_focus_plane_is_sharp_and_defocus_matches_the_thin_lens_formula():
    R, F = 0.05, 3.0
    cam = _camera(aperture_radius=R, focus_distance=F)
    o, d, x, t0, t1 = _rays(cam, 5 * 32 + 7, 4000)
    # origins on the lens disk (the plane ⟂ f through the camera), radius ≤ R
    assert np.allclose(o[1], 0.0) and np.sqrt(o[0] ** 2 + o[2] ** 2).max() <= R * (1 + 1e-12)
    # every ray meets the same point at depth F: the pinhole ray's point
    pin = _camera()
    _, d0, _, _, _ = _rays(pin, 5 * 32 + 7, 1)
    at_focus = o + d * (F - o[1]) / d[1]
    assert np.allclose(at_focus, (d0 * F / d0[1])[:, :1], atol=1e-12)
    # at depth z the rays spread over a disk of diameter 2R|1 − z/F| (the circle of confusion)
    for z in (1.0, 6.0):
        p = o + d * (z - o[1]) / d[1]
        centre = (d0 * z / d0[1])[:, 0]
        radius = np.sqrt((p[0] - centre[0]) ** 2 + (p[2] - centre[2]) ** 2)
        assert radius.max() == pytest.approx(R * abs(1 - z / F), rel=2e-2)
        assert radius.max() <= R * abs(1 - z / F) * (1 + 1e-9)
    # Stokes frames stay ⟂ the rays and point to image right
    assert np.allclose((x * d).sum(0), 0.0, atol=1e-12) and (x[0] > 0.9).all()


def test_pinhole_defaults_are_unchanged():
    cam = _camera()
    assert cam.lens_dimensions == 0
    explicit = _camera(aperture_radius=0, focus_distance=2, aperture_blades=0, film_transparent=False)
    u = np.random.default_rng(0).random((2, 50))
    pix = np.arange(50)
    for a, b in zip(cam.generate(pix, u), explicit.generate(pix, u)):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("blades,rotation", [(0, 0.0), (5, 0.3), (6, 0.0)])
def test_aperture_samples_are_uniform_on_the_disk_or_polygon(blades, rotation):
    u = np.random.default_rng(2).random((2, 200_000))
    bx, by = aperture_sample(u[0], u[1], blades, rotation)
    r = np.hypot(bx, by)
    assert r.max() <= 1 + 1e-12
    if blades == 0:
        assert np.mean(r < 0.5) == pytest.approx(0.25, abs=5e-3)          # uniform: area fraction
        return
    # an edge midpoint at `rotation`: the support along it is the apothem cos(π/N), along a vertex 1
    apothem = math.cos(math.pi / blades)
    along = bx * math.cos(rotation) + by * math.sin(rotation)
    assert along.max() == pytest.approx(apothem, abs=5e-3) and along.max() <= apothem + 1e-12
    vertex = rotation + math.pi / blades
    assert (bx * math.cos(vertex) + by * math.sin(vertex)).max() == pytest.approx(1.0, abs=5e-3)
    # uniform: the inner polygon scaled by 1/2 holds a quarter of the samples
    ang = np.arctan2(by, bx) - rotation
    wedge = np.cos((np.mod(ang + math.pi / blades, 2 * math.pi / blades)) - math.pi / blades)
    assert np.mean(r * wedge < apothem / 2) == pytest.approx(0.25, abs=5e-3)


def test_equirectangular_directions_and_frame():
    W, H = 64, 32
    cam = _camera(projection="equirectangular", width=W, height=H)
    f, r, up = cam.forward, cam.right, cam.up
    rows, cols = np.meshgrid(np.arange(H), np.arange(W), indexing="ij")
    pix = (rows * W + cols).ravel()
    u = np.full((2, pix.size), 0.5)
    o, d, x, t0, t1 = cam.generate(pix, u)
    d = d.reshape(3, H, W)
    x = x.reshape(3, H, W)
    assert np.allclose(np.linalg.norm(d, axis=0), 1) and np.allclose(np.linalg.norm(x, axis=0), 1)
    # image centre = forward, u = 0.25 left, u = 0.75 right, top row towards up (Cycles' layout)
    lon = np.arctan2(np.einsum("i,ihw->hw", r, d), np.einsum("i,ihw->hw", f, d))
    lat = np.arcsin(np.clip(np.einsum("i,ihw->hw", up, d), -1, 1))
    assert np.allclose(lon[H // 2], -np.pi + (np.arange(W) + 0.5) * 2 * np.pi / W)
    assert np.allclose(lat[:, W // 2], np.pi / 2 - (np.arange(H) + 0.5) * np.pi / H)
    # frame: ⟂ d, equal to unit(d × u_cam) away from the poles, continuous between neighbours
    assert np.allclose(np.einsum("ihw,ihw->hw", x, d), 0, atol=1e-12)
    dxu = np.cross(d, up[:, None, None], axis=0)
    assert np.allclose(x, dxu / np.linalg.norm(dxu, axis=0), atol=1e-12)
    assert np.einsum("ihw,ihw->hw", x[:, :, 1:], x[:, :, :-1]).min() > math.cos(2 * 2 * np.pi / W)
    assert np.einsum("ihw,ihw->hw", x[:, 1:], x[:, :-1]).min() > 0.999
    # at a pole the frame is still defined: it is the longitude tangent of the pixel
    _, dp, xp, _, _ = cam.generate(np.array([5]), np.array([[0.5], [0.0]]))   # top edge: latitude +90°
    assert abs(dp[:, 0] @ up - 1) < 1e-12 and np.isfinite(xp).all() and abs(np.linalg.norm(xp) - 1) < 1e-12


def test_camera_fields_are_validated():
    base = {"origin": [0, 0, 0], "target": [0, 1, 0], "width": 4, "height": 4}
    for extra, field in [({"aperture_radius": 0.1}, "camera.focus_distance"),
                         ({"aperture_radius": -1, "focus_distance": 1}, "camera.aperture_radius"),
                         ({"focus_distance": 0}, "camera.focus_distance"),
                         ({"aperture_blades": 2.5}, "camera.aperture_blades"),
                         ({"projection": "equirectangular", "latitude_deg": [10, -10]}, "camera.latitude_deg"),
                         ({"longitude_deg": [-200, 200]}, "camera.longitude_deg"),
                         ({"film_transparent": 1}, "camera.film_transparent")]:
        with pytest.raises(SceneError) as e:
            parse_camera({**base, **extra})
        assert e.value.field == field


# ----------------------------------------------------------------------------- rendering

def _scene(objects, camera_extra=None, lights=None, spp=16, max_depth=3):
    d = {"format": "polar-scene/1",
         "camera": {"origin": [0, -6, 1.5], "target": [0, 0, 0.5], "up": [0, 0, 1], "fov_deg": 40,
                    "width": 40, "height": 30, **(camera_extra or {})},
         "render": {"spp": spp, "max_depth": max_depth, "sampler": "independent"},
         "materials": {"white": {"type": "lambert", "albedo": 0.8}, "black": {"type": "lambert", "albedo": 0.0},
                       "glass": {"type": "black_glass", "n": 1.5}},
         "objects": objects,
         "lights": lights if lights is not None else [{"type": "environment", "radiance": 1.0}]}
    return parse_scene(d)


FLOOR = {"name": "floor", "shape": "quad", "vertices": [[-5, -5, 0], [5, -5, 0], [5, 5, 0], [-5, 5, 0]],
         "material": "white"}
BALL = {"name": "ball", "shape": "sphere", "center": [0, 0, 0.6], "radius": 0.6, "subdivisions": 3,
        "material": "white"}
POINT = [{"type": "point", "position": [1, -1, 4], "intensity": 20}]


def _render(scene):
    r = Renderer(scene).render()
    return r.stokes(), r.film


def test_camera_invisible_object_keeps_its_shadow_and_shadow_invisible_object_casts_none():
    base, _ = _render(_scene([FLOOR], lights=POINT, max_depth=2))
    with_ball, _ = _render(_scene([FLOOR, BALL], lights=POINT, max_depth=2))
    hidden, _ = _render(_scene([FLOOR, {**BALL, "visible_camera": False}], lights=POINT, max_depth=2))
    no_shadow, _ = _render(_scene([FLOOR, {**BALL, "visible_shadow": False}], lights=POINT, max_depth=2))
    y0, y1, yh = base[0, ..., 1], with_ball[0, ..., 1], hidden[0, ..., 1]
    ball_px = np.abs(y1 - y0) > 1e-9
    assert ((yh < y0 - 1e-3) & (np.abs(yh - y1) < 1e-6)).sum() > 10     # the ball's shadow stays
    assert (yh <= y0 * (1 + 1e-4) + 1e-9).all()        # (float32 hit points behind the ball differ slightly)
    sky_behind = (y0 == 0) & (y1 > 0)                                   # the ball against the black sky
    assert sky_behind.sum() > 5 and np.all(hidden[:, sky_behind] == 0)  # ... is gone
    # shadow-invisible: the floor is lit as without the ball (direct light only), the ball is still seen
    floor_only = ~ball_px | (np.abs(no_shadow[0, ..., 1] - base[0, ..., 1]) < 1e-12)
    assert np.array_equal(no_shadow[:, floor_only], base[:, floor_only])
    assert (np.abs(no_shadow[0, ..., 1] - base[0, ..., 1]) > 1e-6).sum() > 20


def test_film_transparent_and_holdout_alpha():
    img, film = _render(_scene([BALL], camera_extra={"film_transparent": True}, spp=32))
    a = film.alpha()
    opaque, _ = _render(_scene([BALL], spp=32))
    ball = opaque[0, ..., 1] < 0.999                          # the ball is darker than the sky (radiance 1)
    assert (a[~ball] <= 0.2).mean() > 0.95 and np.allclose(img[0][a == 0], 0)
    assert (a[ball] > 0).all() and (a[ball] == 1).sum() > 20
    # the sky still lights the ball: where fully covered, the colour is that of the opaque render
    full = a == 1
    assert np.array_equal(img[:, full], opaque[:, full])
    # holdout: covered pixels transparent and black even without a transparent film
    img_h, film_h = _render(_scene([FLOOR, {**BALL, "holdout": True}], spp=8))
    hole = film_h.alpha() == 0
    assert hole.sum() > 20 and np.allclose(img_h[:, hole], 0)
    assert (film_h.alpha() == 1).sum() > 0.5 * hole.size


def test_alpha_pass_through_leaves_the_stokes_vector_unchanged():
    """A Brewster black-glass floor seen through a veil: alpha 0 changes nothing, alpha 0.5 of a black
    veil halves S0..S2 and keeps the degree and angle of polarisation."""
    veil = {"name": "veil", "shape": "quad", "vertices": [[-3, -3, -1], [3, -3, -1], [3, -3, 4], [-3, -3, 4]],
            "material": "black"}
    glass = {**FLOOR, "material": "glass"}
    cam = {"origin": [0, -8, 8 / 1.5], "target": [0, 0, 0]}
    ref, _ = _render(_scene([glass], camera_extra=cam, spp=16))
    clear, _ = _render(_scene([glass, {**veil, "alpha": 0.0}], camera_extra=cam, spp=16))
    assert np.allclose(clear, ref, rtol=1e-6, atol=1e-9)
    half, _ = _render(_scene([glass, {**veil, "alpha": 0.5}], camera_extra=cam, spp=64))
    y_ref = ref[..., 1].sum(axis=(1, 2))
    y_half = half[..., 1].sum(axis=(1, 2))
    assert abs(y_ref[1]) > 0.05 * y_ref[0]                              # polarised
    assert y_half[0] / y_ref[0] == pytest.approx(0.5, abs=0.03)
    # each sample either stops at the black veil or is exactly the reference sample, so the degree of
    # polarisation is kept up to which (slightly different) samples survive
    assert y_half[1] / y_half[0] == pytest.approx(y_ref[1] / y_ref[0], rel=0.02)
    ratio = np.divide(half[1, ..., 1], half[0, ..., 1], out=np.zeros_like(half[0, ..., 1]), where=half[0, ..., 1] > 0)
    ratio_ref = np.divide(ref[1, ..., 1], ref[0, ..., 1], out=np.zeros_like(ref[0, ..., 1]), where=ref[0, ..., 1] > 0)
    lit = half[0, ..., 1] > 0.05 * half[0, ..., 1].max()
    assert np.abs(ratio - ratio_ref)[lit].max() < 0.02


def test_object_ray_fields_are_validated():
    for extra, field in [({"visible_camera": 1}, "objects[0].visible_camera"),
                         ({"holdout": "yes"}, "objects[0].holdout"),
                         ({"alpha": 1.5}, "objects[0].alpha"), ({"alpha": float("nan")}, "objects[0].alpha")]:
        with pytest.raises(SceneError) as e:
            _scene([{**BALL, **extra}])
        assert e.value.field == field


def test_exr_alpha_channel(tmp_path):
    from engine.output.exr import read_stokes_exr, write_stokes_exr
    _, film = _render(_scene([BALL], camera_extra={"film_transparent": True}, spp=4))
    path = tmp_path / "a.exr"
    write_stokes_exr(path, film.mean(), alpha=film.alpha())
    _, channels, _ = read_stokes_exr(path)
    assert np.array_equal(channels["A"], film.alpha().astype(np.float32))
    write_stokes_exr(path, film.mean())
    assert "A" not in read_stokes_exr(path)[1]


def test_resume_keeps_the_alpha_of_the_finished_samples():
    from engine.render.film import film_from_stokes
    scene = _scene([BALL], camera_extra={"film_transparent": True}, spp=8)
    renderer = Renderer(scene)
    full = renderer.render().film
    st = dataclasses.replace(scene.settings, spp=3)
    part = renderer.render(st).film
    resumed = renderer.render(RenderRequest(resume=film_from_stokes(part.mean(), part.spp_image(),
                                                                    alpha=part.alpha()))).film
    assert np.allclose(resumed.alpha(), full.alpha(), atol=1e-12)
    assert np.allclose(resumed.mean(), full.mean(), rtol=1e-6, atol=1e-9)


def test_panorama_lens_focuses_on_a_sphere():
    R, F = 0.04, 2.5
    cam = _camera(projection="equirectangular", width=16, height=8, aperture_radius=R, focus_distance=F)
    pin = _camera(projection="equirectangular", width=16, height=8)
    for pixel in (3, 2 * 16 + 5, 7 * 16 + 12):
        o, d, x, _, _ = _rays(cam, pixel, 500)
        _, d0, _, _, _ = _rays(pin, pixel, 1)
        assert np.linalg.norm(o, axis=0).max() <= R * (1 + 1e-12)
        assert np.allclose(np.einsum("in,i->n", o, d0[:, 0]), 0, atol=1e-12)       # lens disk ⟂ the pixel's ray
        t = np.einsum("in,in->n", F * d0 - o, d)                                    # distance to the focus point
        assert np.allclose(o + t * d, F * d0, atol=1e-12)
        assert np.allclose(np.einsum("in,in->n", x, d), 0, atol=1e-12)


def test_cli_writes_alpha_and_resume_continues_it(tmp_path):
    """`python -m engine render` of a transparent-film scene writes the A channel (coverage of camera
    rays), and `--resume` of a partial file gives the alpha of the uninterrupted render."""
    import json

    from engine.cli import main as cli_main
    from engine.output.exr import read_stokes_exr
    doc = {"format": "polar-scene/1",
           "camera": {"origin": [0, -6, 1.5], "target": [0, 0, 0.5], "up": [0, 0, 1], "fov_deg": 40,
                      "width": 12, "height": 9, "film_transparent": True},
           "render": {"spp": 4, "max_depth": 3},
           "materials": {"white": {"type": "lambert", "albedo": 0.8}},
           "objects": [BALL], "lights": [{"type": "environment", "radiance": 1.0}]}
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(doc))
    full, part = tmp_path / "full.exr", tmp_path / "part.exr"
    assert cli_main(["render", str(scene), "-o", str(full), "--no-previews", "-q"]) == 0
    a = read_stokes_exr(full)[1]["A"]
    assert a.min() == 0.0 and a.max() == 1.0            # sky transparent, ball opaque
    assert cli_main(["render", str(scene), "-o", str(part), "--spp", "2", "--no-previews", "-q"]) == 0
    assert cli_main(["render", str(scene), "-o", str(part), "--resume", str(part), "--spp", "4",
                     "--no-previews", "-q"]) == 0
    np.testing.assert_allclose(read_stokes_exr(part)[1]["A"], a, atol=1e-6)


def test_adaptive_render_keeps_alpha(tmp_path):
    """Adaptive sampling adds samples pass by pass; the coverage of camera rays still reaches the A channel."""
    import json

    from engine.cli import main as cli_main
    from engine.output.exr import read_stokes_exr
    doc = {"format": "polar-scene/1",
           "camera": {"origin": [0, -6, 1.5], "target": [0, 0, 0.5], "up": [0, 0, 1], "fov_deg": 40,
                      "width": 12, "height": 9, "film_transparent": True},
           "render": {"spp": 8, "max_depth": 3},
           "materials": {"white": {"type": "lambert", "albedo": 0.8}},
           "objects": [BALL], "lights": [{"type": "environment", "radiance": 1.0}]}
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps(doc))
    out = tmp_path / "a.exr"
    assert cli_main(["render", str(scene), "-o", str(out), "--noise-threshold", "0.5", "--min-spp", "4",
                     "--no-previews", "-q"]) == 0
    a = read_stokes_exr(out)[1]["A"]
    assert a.min() == 0.0 and a.max() == 1.0
