"""Data passes and Cryptomatte of a Polar render against Cycles' (bpy ships it).

A floor, a sphere and a cube (parented to an empty: its asset is the empty) with pass indices, materials
with Material Indices, the World's mist and a sphere that moves between frames; every data pass and the
three Cryptomatte layers enabled.  Cycles renders it (box filter 1 px, as Polar's); Polar renders it
through a small render engine (``Shim``) that calls ``polar_addon.passes`` the way the Polar render engine
does (the lines it adds to render_engine.py), both written as multilayer EXRs.  On interior pixels (a 3 × 3
neighbourhood of one object in both renders, no crease): Depth within 1 % relative, Mist within 0.02, Normal cosine
> 0.99, Object and Material Index equal, Cryptomatte rank-0 ids equal; the manifests name the same ids, and
the compositor's Cryptomatte node picks the same matte (the ball and the box) from both renders.
"""

import json
import traceback

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from tests.blender_support import add_camera, add_plane, add_sphere, empty_scene, load_addon  # noqa: E402

W, H, SPP = 160, 120, 16
ERRORS = []


@pytest.fixture(scope="module")
def addon():
    return load_addon()


def _shim_class():
    from polar_render.engine.render.renderer import Renderer
    from polar_render.polar_addon import passes
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings

    class Shim(bpy.types.RenderEngine):
        """The Polar render engine's data-pass path, alone (the lines render_engine.py adds)."""
        bl_idname = "POLAR_DATA_PASS_SHIM"
        bl_label = "Polar data-pass shim"

        def update_render_passes(self, scene=None, renderlayer=None):
            self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
            passes.register_data_passes(self, scene, renderlayer)

        def render(self, depsgraph):
            try:
                scene = depsgraph.scene
                settings = engine_settings(scene)
                camera_object = scene.camera
                request = passes.data_pass_request(depsgraph.view_layer, scene)
                with passes.exporting(request):
                    engine_scene, _ = export_scene(depsgraph, camera_object, W, H, settings)
                request = passes.add_motion(self, depsgraph, camera_object, W, H, engine_scene, request)
                renderer = Renderer(engine_scene)
                result = self.begin_result(0, 0, W, H, layer=depsgraph.view_layer.name)
                passes.write_data_passes(self, result, renderer, request, settings, None)
                self.end_result(result)
            except Exception:  # noqa: BLE001 — reported by the test
                ERRORS.append(traceback.format_exc())

    return Shim


def _material(name, colour, index):
    mat = bpy.data.materials.new(name)
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*colour, 1.0)
    mat.pass_index = index
    return mat


def _scene():
    scene = empty_scene(W, H, SPP)
    scene.frame_start, scene.frame_end = 1, 3
    world = bpy.data.worlds.new("World")
    scene.world = world
    world.mist_settings.start, world.mist_settings.depth, world.mist_settings.falloff = 3.0, 8.0, "LINEAR"
    add_camera(scene, (0.0, -5.5, 5.0), (np.radians(50.0), 0.0, 0.0), lens=40.0)
    floor = add_plane(12.0, _material("Grey", (0.5, 0.5, 0.5), 2))
    floor.name = "Floor"
    ball = add_sphere(0.9, (-1.1, 0.0, 0.9), _material("Red", (0.8, 0.1, 0.1), 5))
    ball.name, ball.pass_index = "Ball", 3
    # the ball moves 0.3 along +x and 0.2 up per frame (keys at frames 1, 2, 3: the Vector pass at frame 2
    # reads the keyed positions only): Cycles' Vector with motion blur off
    for frame, x, z in ((1, -1.4, 0.7), (2, -1.1, 0.9), (3, -0.8, 1.1)):
        scene.frame_set(frame)
        ball.location = (x, 0.0, z)
        ball.keyframe_insert("location", frame=frame)
    scene.frame_set(2)
    bpy.ops.mesh.primitive_cube_add(size=1.2, location=(1.3, 0.6, 0.6))
    box = bpy.context.object
    box.name, box.pass_index = "Box", 7
    box.rotation_euler = (0.0, 0.0, 0.5)
    box.data.materials.append(_material("Blue", (0.1, 0.2, 0.8), 9))
    rig = bpy.data.objects.new("Rig", None)
    scene.collection.objects.link(rig)
    box.parent = rig
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    scene.collection.objects.link(sun)
    sun.rotation_euler = (0.5, 0.2, 0.0)
    layer = scene.view_layers[0]
    for p in ("z", "mist", "normal", "position", "vector", "uv", "object_index", "material_index",
              "cryptomatte_object", "cryptomatte_material", "cryptomatte_asset"):
        setattr(layer, f"use_pass_{p}", True)
    layer.pass_cryptomatte_depth = 4
    scene.render.use_motion_blur = False
    scene.render.image_settings.color_depth = "32"
    # the compositor's Cryptomatte node picks the ball and the box from the render's CryptoObject layer
    compat = load_addon().polar_addon.compat
    tree = compat.compositor_tree(scene, create=True)
    node = tree.nodes.new("CompositorNodeCryptomatteV2")
    node.source, node.scene, node.matte_id = "RENDER", scene, "Ball, Box"
    tree.links.new(node.outputs["Matte"], compat.compositor_output(tree).inputs[0])
    return scene


def _read(path, layer="ViewLayer"):
    """({pass: (H, W, C)} with channels in Blender's order, header) of a multilayer EXR (row 0 = top)."""
    import OpenEXR
    order = "RGBAXYZWUVrgba"
    with OpenEXR.File(path, separate_channels=True) as f:
        chans = {n: np.array(c.pixels) for p in f.parts for n, c in p.channels.items()}
        header = dict(f.parts[0].header)
    passes = {}
    for name, pixels in chans.items():
        parts = name.split(".")
        if len(parts) == 3 and parts[0] == layer:
            passes.setdefault(parts[1], {})[parts[2]] = pixels
    return {p: np.stack([c[k] for k in sorted(c, key=lambda k: (k == "A" and "U" in c, order.index(k)))], -1)
            for p, c in passes.items()}, header


def _render(scene, engine, path):
    """(passes, header, the compositor's matte (H, W)) of a render of ``scene`` by ``engine``."""
    scene.render.engine = engine
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    passes, header = _read(path + ".exr")
    return passes, header, _read(path + ".exr", "Composite")[0]["Combined"][..., 0]


def _manifests(header):
    out = {}
    for key, value in header.items():
        if key.startswith("cryptomatte/") and key.endswith("/name"):
            name = value if isinstance(value, str) else value.decode()
            raw = header[key[:-len("name")] + "manifest"]
            out[name.split(".")[-1]] = json.loads(raw if isinstance(raw, str) else raw.decode())
    return out


def _bits(f):
    return np.frombuffer(np.asarray(f, np.float32).tobytes(), np.uint32).reshape(np.shape(f))


def _id_bits(hex_hash):
    """The float32 bits of a manifest's hash (the Cryptomatte conversion: the exponent clamped to [1, 254])."""
    h = int(hex_hash, 16)
    return (h & 0x807FFFFF) | (min(max((h >> 23) & 0xFF, 1), 254) << 23)


def test_data_passes_match_cycles(addon, tmp_path):
    scene = _scene()
    c = scene.cycles
    c.device, c.samples, c.seed, c.use_adaptive_sampling, c.use_denoising = "CPU", SPP, 1, False, False
    c.pixel_filter_type, c.filter_width = "BOX", 1.0
    scene.render.threads_mode, scene.render.threads = "FIXED", 2
    theirs, their_header, their_matte = _render(scene, "CYCLES", str(tmp_path / "cycles"))
    shim = _shim_class()
    bpy.utils.register_class(shim)
    try:
        ours, our_header, our_matte = _render(scene, shim.bl_idname, str(tmp_path / "polar"))
    finally:
        bpy.utils.unregister_class(shim)
    assert not ERRORS, ERRORS[0]
    for name in ("Depth", "Mist", "Normal", "Position", "UV", "Vector", "Object Index", "Material Index",
                 "CryptoObject00", "CryptoObject01", "CryptoMaterial00", "CryptoAsset01"):
        assert ours[name].shape == theirs[name].shape, name

    # interior pixels: one object (Cycles' rank-0 object id) over the 3 × 3 neighbourhood in both renders
    ids_t, ids_o = _bits(theirs["CryptoObject00"][..., 0]), _bits(ours["CryptoObject00"][..., 0])
    same = (ids_t == ids_o) & (theirs["CryptoObject00"][..., 1] > 0.999) & (ours["CryptoObject00"][..., 1] > 0.999)
    interior = same.copy()
    unit = theirs["Normal"] / np.maximum(np.linalg.norm(theirs["Normal"], axis=-1, keepdims=True), 1e-12)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            interior[1:-1, 1:-1] &= (ids_t[1 + dy:H - 1 + dy, 1 + dx:W - 1 + dx] == ids_t[1:-1, 1:-1])
            # and no crease (the cube's edges: a pixel's mean normal there is its coverage of each face, which
            # 16 samples of two different samplers estimate differently)
            interior[1:-1, 1:-1] &= (unit[1 + dy:H - 1 + dy, 1 + dx:W - 1 + dx] * unit[1:-1, 1:-1]).sum(-1) > 0.95
    interior[0, :] = interior[-1, :] = interior[:, 0] = interior[:, -1] = False
    manifests_t, manifests_o = _manifests(their_header), _manifests(our_header)
    seen = {n for n, h in manifests_o["CryptoObject"].items() if _id_bits(h) in set(ids_t[interior].tolist())}
    assert seen == {"Floor", "Ball", "Box"}, seen
    assert interior.sum() > 0.5 * W * H

    depth_t, depth_o = theirs["Depth"][..., 0][interior], ours["Depth"][..., 0][interior]
    rel = np.abs(depth_o / depth_t - 1)
    mist = np.abs(ours["Mist"][..., 0] - theirs["Mist"][..., 0])[interior]
    nt, no = theirs["Normal"][interior], ours["Normal"][interior]
    cos = (nt * no).sum(-1) / (np.linalg.norm(nt, axis=-1) * np.linalg.norm(no, axis=-1))
    print(f"\ninterior pixels {interior.sum()}: depth rel max {rel.max():.4f} (median {np.median(rel):.2e}); "
          f"mist max {mist.max():.4f}; normal cos min {cos.min():.5f}")
    assert rel.max() < 0.01
    assert mist.max() < 0.02
    assert cos.min() > 0.99
    for name in ("Object Index", "Material Index"):
        np.testing.assert_array_equal(ours[name][..., 0][interior], theirs[name][..., 0][interior], err_msg=name)
    for layer in ("CryptoObject", "CryptoMaterial", "CryptoAsset"):
        np.testing.assert_array_equal(_bits(ours[f"{layer}00"][..., 0])[interior],
                                      _bits(theirs[f"{layer}00"][..., 0])[interior], err_msg=layer)
        for name, hexid in manifests_o[layer].items():      # every id we name, Cycles names alike
            assert manifests_t[layer].get(name) == hexid, (layer, name)
    assert set(manifests_o["CryptoAsset"]) == {"Floor", "Ball", "Rig"}

    # Blender's Cryptomatte node ("Ball, Box") picks the same matte from both renders: exactly on the interior
    # pixels, within the 16 samples' coverage noise on the edges
    np.testing.assert_array_equal(our_matte[interior], their_matte[interior])
    assert set(np.unique(their_matte[interior]).tolist()) == {0.0, 1.0}
    picked_t, picked_o = (their_matte > 0.5).sum(), (our_matte > 0.5).sum()
    print(f"Cryptomatte node matte: {picked_t} px (Cycles) vs {picked_o} (Polar) above ½; "
          f"|Δ| mean {np.abs(our_matte - their_matte).mean():.4f}, max {np.abs(our_matte - their_matte).max():.3f}")
    assert abs(int(picked_o) - int(picked_t)) <= 0.01 * picked_t
    assert np.abs(our_matte - their_matte).mean() < 0.005

    # UV (the floor's and the ball's, away from the sphere's seam) and Position (sample 0 of each: the
    # pixel's footprint apart), Vector of the moving ball
    uv = np.abs(ours["UV"] - theirs["UV"])[interior]
    pos = np.linalg.norm(ours["Position"] - theirs["Position"], axis=-1)[interior]
    ball = interior & (ids_t == _id_bits(manifests_t["CryptoObject"]["Ball"]))
    vec = np.abs(ours["Vector"] - theirs["Vector"])[ball]
    print(f"uv |Δ| p99 {np.percentile(uv, 99):.4f}; position |Δ| max {pos.max():.4f}; Vector (ball, {ball.sum()} px): "
          f"Cycles mean {theirs['Vector'][ball].mean(0).round(3)}, ours {ours['Vector'][ball].mean(0).round(3)}, "
          f"|Δ| max {vec.max():.4f}")
    assert np.percentile(uv, 99) < 0.02
    assert pos.max() < 0.15
    assert vec.max() < 0.1
