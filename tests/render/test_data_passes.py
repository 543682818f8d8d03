"""Data passes and Cryptomatte (engine.render.data_passes, engine.output.cryptomatte): analytic checks.

Depth, Position, Normal, UV, indices and Mist of planes at known places; Cryptomatte coverage of a known
edge and of pass-through surfaces; the Vector pass of a known motion; MurmurHash3 against its published
reference vectors and the float conversion bit by bit; determinism; the CLI's EXR channels and manifests.
"""

import json
import struct

import numpy as np
import pytest

from engine.cli import main
from engine.output import cryptomatte as cm
from engine.output.exr import read_stokes_exr
from engine.render.data_passes import (ALL_PASSES, BACKGROUND_DEPTH, DataPassRequest, Mist, Motion,
                                       render_data_passes)
from engine.scene.loader import parse_scene


def _quad(z, x0=-5.0, x1=5.0, y0=-5.0, y1=5.0):
    return [[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]


def _scene(objects, camera=None, spp=16, seed=3):
    cam = {"origin": [0.0, 0.0, 3.0], "target": [0.0, 0.0, 0.0], "up": [0, 1, 0], "fov_deg": 30,
           "width": 8, "height": 6}
    cam.update(camera or {})
    return parse_scene({
        "format": "polar-scene/1", "camera": cam, "render": {"spp": spp, "seed": seed},
        "materials": {"grey": {"type": "lambert", "albedo": 0.5}, "white": {"type": "lambert", "albedo": 0.9}},
        "objects": objects, "lights": [{"type": "environment", "radiance": 1.0}]})


def _passes(scene, *names, **options):
    return render_data_passes(scene, DataPassRequest(frozenset(names or ALL_PASSES), **options))


ORTHO = {"projection": "orthographic", "ortho_width": 8.0, "width": 8, "height": 6}


# ---------------------------------------------------------------------------------- hashing


# MurmurHash3_x86_32 reference vectors (the values every port checks against: smhasher's MurmurHash3.cpp)
MURMUR_VECTORS = [
    (b"", 0, 0x00000000), (b"", 1, 0x514E28B7), (b"", 0xFFFFFFFF, 0x81F16F39),
    (b"\0\0\0\0", 0, 0x2362F9DE), (b"aaaa", 0x9747B28C, 0x5A97808A), (b"aaa", 0x9747B28C, 0x283E0130),
    (b"aa", 0x9747B28C, 0x5D211726), (b"a", 0x9747B28C, 0x7FA09EA6), (b"abcd", 0x9747B28C, 0xF0478627),
    (b"abc", 0x9747B28C, 0xC84A62DD), (b"ab", 0x9747B28C, 0x74875592), (b"Hello, world!", 0x9747B28C, 0x24884CBA),
    (b"The quick brown fox jumps over the lazy dog", 0x9747B28C, 0x2FA826CD),
    (b"\xff\xff\xff\xff", 0, 0x76293B50), (b"\x21\x43\x65\x87", 0, 0xF55B516B),
]


@pytest.mark.parametrize("data, seed, expected", MURMUR_VECTORS)
def test_murmurhash3_reference_vectors(data, seed, expected):
    assert cm.murmurhash3_32(data, seed) == expected


def test_names_hash_as_blender_writes_them():
    # the manifest Cycles wrote for these names (bpy 5.0.1): "Floor":"6a2fb16e", "Ball":"74d3ebe9", …
    for name, hexid in (("Floor", "6a2fb16e"), ("Ball", "74d3ebe9"), ("Box", "803b1009"), ("Red", "6e1a9181"),
                        ("default_surface", "78d05529"), ("Rig", "b76dec1e")):
        assert f"{cm.murmurhash3_32(name):08x}" == hexid
    assert cm.murmurhash3_32("Élan") == cm.murmurhash3_32("Élan".encode())


def _float_of(bits):
    return struct.unpack("<f", struct.pack("<I", bits))[0]


def test_hash_to_float_clamps_the_exponent_only():
    # an ordinary hash: the float with the same bits
    assert cm.hash_to_float(0x6A2FB16E) == np.float32(_float_of(0x6A2FB16E))
    # exponent 0 (a denormal or zero) → 1; exponent 255 (inf/NaN) → 254; sign and mantissa kept
    assert struct.pack("<f", cm.hash_to_float(0x803B1009)) == struct.pack("<I", 0x80BB1009)
    assert struct.pack("<f", cm.hash_to_float(0x00000000)) == struct.pack("<I", 0x00800000)
    assert struct.pack("<f", cm.hash_to_float(0xFFFFFFFF)) == struct.pack("<I", 0xFF7FFFFF)
    assert np.isfinite(cm.hash_to_float(0x7F800000)) and cm.hash_to_float(0x7F800000) != 0


def test_layer_metadata_as_cycles_names_it():
    meta = cm.layer_metadata("ViewLayer.CryptoObject", ["Floor", "Ball", "Floor"])
    # the key is the first 7 hex digits of the hash of the layer name (Cycles' add_cryptomatte_layer)
    assert meta == {"cryptomatte/542cafa/name": "ViewLayer.CryptoObject",
                    "cryptomatte/542cafa/hash": "MurmurHash3_32",
                    "cryptomatte/542cafa/conversion": "uint32_to_float32",
                    "cryptomatte/542cafa/manifest": '{"Floor":"6a2fb16e","Ball":"74d3ebe9"}'}
    assert json.loads(meta["cryptomatte/542cafa/manifest"]) == {"Floor": "6a2fb16e", "Ball": "74d3ebe9"}


# ---------------------------------------------------------------------------------- geometry passes


def test_plane_at_known_depth():
    scene = _scene([{"name": "floor", "shape": "quad", "vertices": _quad(0.0), "material": "grey"}])
    out = _passes(scene, "depth", "position", "normal", "uv", "mist", mist=Mist(1.0, 4.0, "linear"))
    np.testing.assert_allclose(out.images["Depth"], 3.0, rtol=0, atol=1e-12)          # z along the axis: exact
    np.testing.assert_allclose(out.images["Position"][..., 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(out.images["Normal"], np.broadcast_to([0, 0, 1], (6, 8, 3)), atol=1e-12)
    # the quad's UV map is the unit square over [-5, 5]²: UV = (x, y)/10 + ½ averaged over the pixel
    pos = out.images["Position"]
    assert np.all(out.images["UV"][..., 2] == 1)
    # pixel means of a linear map: the pixel centre's value within the jitter's stratification (1/16 px)
    t = np.tan(np.radians(15))
    cols = (np.arange(8) + 0.5) / 8 * 2 - 1
    rows = 1 - (np.arange(6) + 0.5) / 6 * 2
    centre_u = (3 * t * cols) / 10 + 0.5
    centre_v = (3 * t * 6 / 8 * rows) / 10 + 0.5
    px = 2 * 3 * t / 8 / 10                                   # one pixel in UV units
    np.testing.assert_allclose(out.images["UV"][..., 0], np.broadcast_to(centre_u, (6, 8)), atol=px / 16)
    np.testing.assert_allclose(out.images["UV"][..., 1], np.broadcast_to(centre_v[:, None], (6, 8)), atol=px / 16)
    # Position is sample 0's hit, inside its pixel
    assert np.all(np.abs(pos[..., 0] / 10 + 0.5 - centre_u) <= px / 2 + 1e-12)
    # Mist: mean over the samples of the linear ramp (d − 1)/4, d = 3/cos θ ≈ 3 near the axis
    d_centre = 3.0 / np.cos(np.arctan(np.hypot(3 * t * cols[3] / 3, 3 * t * 0.75 * rows[2] / 3)))
    assert abs(out.images["Mist"][2, 3, 0] - (d_centre - 1) / 4) < 2e-3


def test_background_values_are_cycles():
    scene = _scene([{"name": "tile", "shape": "quad", "vertices": _quad(0.0, -0.1, 0.1, -0.1, 0.1),
                     "material": "grey", "pass_index": 4}], camera=ORTHO)
    out = _passes(scene)
    corner = (0, 0)
    assert out.images["Depth"][corner][0] == np.float32(BACKGROUND_DEPTH)
    assert out.images["Mist"][corner][0] == 1.0
    for name in ("Normal", "Position", "UV", "Vector", "Object Index", "Material Index"):
        assert not out.images[name][corner].any(), name
    for passes in out.cryptomatte.values():
        assert not passes[0][corner].any()


def test_indices_and_cryptomatte_of_two_objects():
    scene = _scene([{"name": "left", "shape": "quad", "vertices": _quad(0.0, -4, 0, -3, 3), "material": "grey",
                     "pass_index": 3, "asset": "rig"},
                    {"name": "right", "shape": "quad", "vertices": _quad(0.0, 0, 4, -3, 3), "material": "white",
                     "pass_index": 7}], camera=ORTHO)
    scene.meshes[1].material_names = ["Paint"]
    scene.meshes[1].material_pass_indices = [9]
    out = _passes(scene)
    np.testing.assert_array_equal(out.images["Object Index"][:, :4, 0], 3)
    np.testing.assert_array_equal(out.images["Object Index"][:, 4:, 0], 7)
    np.testing.assert_array_equal(out.images["Material Index"][:, :4, 0], 0)
    np.testing.assert_array_equal(out.images["Material Index"][:, 4:, 0], 9)
    ob = out.cryptomatte["CryptoObject"][0]
    left, right = cm.hash_to_float(cm.murmurhash3_32(b"left")), cm.hash_to_float(cm.murmurhash3_32(b"right"))
    assert np.all(ob[:, :4, 0] == left) and np.all(ob[:, 4:, 0] == right)
    np.testing.assert_array_equal(ob[..., 1], 1.0)                  # full coverage, a single id per pixel
    assert not ob[..., 2:].any()
    assert np.all(out.cryptomatte["CryptoAsset"][0][:, :4, 0] == cm.name_id("rig"))
    assert np.all(out.cryptomatte["CryptoAsset"][0][:, 4:, 0] == cm.name_id("right"))
    assert np.all(out.cryptomatte["CryptoMaterial"][0][:, :4, 0] == cm.name_id("grey"))
    assert np.all(out.cryptomatte["CryptoMaterial"][0][:, 4:, 0] == cm.name_id("Paint"))
    assert out.names == {"CryptoObject": ["left", "right"], "CryptoMaterial": ["grey", "Paint"],
                         "CryptoAsset": ["rig", "right"]}
    assert len(out.cryptomatte["CryptoObject"]) == 3                # 6 levels: 3 RGBA passes (Cycles' default)


def test_edge_coverage_and_ranks():
    # the boundary at x = 0.25 px inside column 4 (ortho: 1 px = 1 unit): column 4 is ¼ left, ¾ right
    scene = _scene([{"name": "left", "shape": "quad", "vertices": _quad(0.0, -4, 0.25, -3, 3), "material": "grey"},
                    {"name": "right", "shape": "quad", "vertices": _quad(0.0, 0.25, 4, -3, 3), "material": "grey"}],
                   camera=ORTHO, spp=64)
    out = _passes(scene, "crypto_object", cryptomatte_levels=2)
    (p,) = out.cryptomatte["CryptoObject"]
    col = p[:, 4]
    assert np.all(col[:, 0] == cm.name_id("right")) and np.all(col[:, 2] == cm.name_id("left"))
    np.testing.assert_allclose(col[:, 1], 0.75, atol=1 / 32)       # rank 0 the larger coverage
    np.testing.assert_allclose(col[:, 3], 0.25, atol=1 / 32)
    np.testing.assert_allclose(col[:, 1] + col[:, 3], 1.0, rtol=0, atol=1e-6)
    # odd levels keep one rank more, as Cycles (two ranks per RGBA pass): 3 levels → 2 passes, 4 ranks
    assert len(_passes(scene, "crypto_object", cryptomatte_levels=3).cryptomatte["CryptoObject"]) == 2


def test_pass_through_surfaces_and_hidden_objects():
    objects = [{"name": "glass", "shape": "quad", "vertices": _quad(1.0), "material": "grey", "alpha": 0.3},
               {"name": "ghost", "shape": "quad", "vertices": _quad(0.5), "material": "grey", "visible_camera": False},
               {"name": "floor", "shape": "quad", "vertices": _quad(0.0), "material": "grey", "pass_index": 2}]
    out = _passes(_scene(objects, camera=ORTHO))
    # alpha 0.3 < the threshold 0.5: the data passes see the floor; Cryptomatte weights 0.3 and 0.7 exactly
    np.testing.assert_allclose(out.images["Depth"], 3.0, atol=1e-9)
    np.testing.assert_array_equal(out.images["Object Index"], 2)
    ob = out.cryptomatte["CryptoObject"][0]
    assert np.all(ob[..., 0] == cm.name_id("floor")) and np.all(ob[..., 2] == cm.name_id("glass"))
    np.testing.assert_allclose(ob[..., 1], 0.7, rtol=1e-6)
    np.testing.assert_allclose(ob[..., 3], 0.3, rtol=1e-6)
    assert "ghost" not in out.names["CryptoObject"] or not np.any(ob[..., [0, 2]] == cm.name_id("ghost"))
    # alpha 0.6 ≥ 0.5: the glass is the first surface; with the threshold at 0.7 the floor again
    objects[0]["alpha"] = 0.6
    np.testing.assert_allclose(_passes(_scene(objects, camera=ORTHO), "depth").images["Depth"], 2.0, atol=1e-9)
    deeper = _passes(_scene(objects, camera=ORTHO), "depth", alpha_threshold=0.7).images["Depth"]
    np.testing.assert_allclose(deeper, 3.0, atol=1e-9)


def test_normal_faces_the_camera():
    # the quad wound clockwise seen from the camera: its geometric normal points away; the pass shows +z
    scene = _scene([{"name": "back", "shape": "quad", "vertices": _quad(0.0)[::-1], "material": "grey"}])
    np.testing.assert_allclose(_passes(scene, "normal").images["Normal"], np.broadcast_to([0, 0, 1], (6, 8, 3)),
                               atol=1e-12)


def test_vector_of_a_known_motion():
    scene = _scene([{"name": "floor", "shape": "quad", "vertices": _quad(0.0), "material": "grey"}], camera=ORTHO)
    v = scene.meshes[0].vertices
    # one frame earlier the plane was 0.5 units to the left, one frame later 0.25 units up (1 unit = 1 px)
    motion = Motion(positions_pre=(v - [0.5, 0, 0],), positions_post=(v + [0, 0.25, 0],))
    out = render_data_passes(scene, DataPassRequest(frozenset({"vector"}), motion=motion))
    np.testing.assert_allclose(out.images["Vector"], np.broadcast_to([-0.5, 0.0, 0.0, -0.25], (6, 8, 4)), atol=1e-9)
    # a static scene: 0
    assert not _passes(scene, "vector").images["Vector"].any()


def test_deterministic_and_thread_independent():
    scene = _scene([{"name": "ball", "shape": "sphere", "center": [0, 0, 0], "radius": 0.8, "material": "grey"},
                    {"name": "floor", "shape": "quad", "vertices": _quad(-1.0), "material": "white"}], spp=8)
    a = render_data_passes(scene, DataPassRequest(frozenset(ALL_PASSES)), threads=1)
    b = render_data_passes(scene, DataPassRequest(frozenset(ALL_PASSES)), threads=2)
    for name in a.images:
        np.testing.assert_array_equal(a.images[name], b.images[name], err_msg=name)
    for layer in a.cryptomatte:
        for x, y in zip(a.cryptomatte[layer], b.cryptomatte[layer]):
            np.testing.assert_array_equal(x, y)
    assert a.samples == 8 and DataPassRequest().samples_for(1000) == 64
    # a window (border render) is the same pixels of the whole image
    w = render_data_passes(scene, DataPassRequest(frozenset(ALL_PASSES)), window=(2, 1, 7, 5))
    for name in a.images:
        np.testing.assert_array_equal(w.images[name], a.images[name][1:5, 2:7], err_msg=name)
    np.testing.assert_array_equal(w.cryptomatte["CryptoObject"][0], a.cryptomatte["CryptoObject"][0][1:5, 2:7])


@pytest.mark.parametrize("options, field", [({"passes": {"depht"}}, "unknown depht"),
                                            ({"cryptomatte_levels": 17}, "cryptomatte_levels"),
                                            ({"alpha_threshold": 1.5}, "alpha_threshold"),
                                            ({"samples": 0}, "samples")])
def test_bad_requests_name_the_field(options, field):
    with pytest.raises(ValueError, match=field):
        DataPassRequest(**options)
    with pytest.raises(ValueError, match="mist.falloff"):
        Mist(falloff="cubic")


def test_cli_writes_the_channels_and_manifests(tmp_path):
    scene = {"format": "polar-scene/1",
             "camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov_deg": 30, "width": 8,
                        "height": 6},
             "render": {"spp": 4, "seed": 1}, "materials": {"grey": {"type": "lambert", "albedo": 0.5}},
             "objects": [{"name": "floor", "shape": "quad", "vertices": _quad(0.0), "material": "grey",
                          "pass_index": 5}],
             "lights": [{"type": "environment", "radiance": 1.0}]}
    path = tmp_path / "s.json"
    path.write_text(json.dumps(scene))
    out = tmp_path / "s.exr"
    assert main(["render", str(path), "-o", str(out), "--data-passes", "depth,object_index,crypto_object",
                 "--cryptomatte-levels", "2", "-q", "--no-previews"]) == 0
    _, channels, header = read_stokes_exr(out)
    assert channels["Depth.Z"].dtype == np.float32
    np.testing.assert_allclose(channels["Depth.Z"], 3.0, rtol=1e-6)
    np.testing.assert_array_equal(channels["Object Index.X"], 5.0)
    assert np.all(channels["CryptoObject00.r"] == cm.name_id("floor"))
    assert "CryptoObject01.r" not in channels and "Normal.X" not in channels
    assert header["cryptomatte/3ae39a5/name"] == "CryptoObject"
    assert json.loads(header["cryptomatte/3ae39a5/manifest"]) == {"floor": f"{cm.murmurhash3_32('floor'):08x}"}
    assert main(["render", str(path), "-o", str(out), "--data-passes", "depth,fog", "-q"]) != 0


def test_a_scene_without_geometry_is_background_everywhere():
    from engine.errors import SceneError
    from engine.scene.description import Camera, Scene
    scene = Scene(camera=Camera(origin=np.zeros(3), target=np.array([0.0, 0.0, -1.0]), up=np.array([0.0, 1.0, 0.0]),
                                width=4, height=3))
    try:
        out = _passes(scene)
    except SceneError:
        pytest.skip("this engine refuses scenes without geometry")
    assert np.all(out.images["Depth"] == np.float32(BACKGROUND_DEPTH)) and np.all(out.images["Mist"] == 1)
    assert not any(p.any() for passes in out.cryptomatte.values() for p in passes)
    assert out.names == {"CryptoObject": [], "CryptoMaterial": [], "CryptoAsset": []}
