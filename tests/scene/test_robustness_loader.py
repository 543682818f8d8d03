"""Hostile scene files (issue 13): every user mistake is one SceneError naming the field and the
allowed range (the CLI prints it as one `error: ...` line and exits 2), never another exception."""

import copy
import json
import os

import numpy as np
import pytest

from engine.cli import main
from engine.errors import SceneError
from engine.materials.htsg import HTSG
from engine.materials.lambert import Lambert
from engine.materials.weidlich_wilkie import Coat, WeidlichWilkie
from engine.scene import loader
from engine.scene.loader import load_scene, parse_material, parse_scene

I4 = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]

#: A scene with every kind of number field: materials of each type, shapes, transforms, lights.
RICH = {
    "format": "polar-scene/1",
    "camera": {"origin": [0, -5, 1.5], "target": [0, 0, 1], "up": [0, 0, 1], "fov_deg": 40, "width": 6, "height": 4,
               "ortho_width": 2, "clip_start": 0, "clip_end": 100, "shift": [0, 0]},
    "render": {"spp": 1, "max_depth": 6, "rr_depth": 3, "seed": 1, "wavelength_nm": 550, "batch_rays": 2048,
               "threads": 1},
    "materials": {
        "lam": {"type": "lambert", "albedo": 0.5},
        "rgb": {"type": "lambert", "albedo": [0.5, 0.5, 0.5]},
        "tab": {"type": "lambert", "albedo": {"spectrum": [[360, 0.5], [830, 0.5]]}},
        "cond": {"type": "conductor", "n": 0.2, "k": 3, "exterior_n": 1},
        "pol": {"type": "polariser", "axis": [1, 0, 0], "extinction": 0, "transmittance": 1},
        "ret": {"type": "retarder", "axis": [1, 0, 0], "retardance_deg": 90},
        "ts": {"type": "torrance_sparrow", "n": 1.5, "k": 0, "m": 0.1, "diffuse_albedo": 0.2, "diffuse_weight": 1,
               "specular_weight": 1, "exterior_n": 1},
        "ww": {"type": "weidlich_wilkie", "base": "ts",
               "coats": [{"n": 1.5, "thickness": 1, "absorption": 0.1, "distribution": "blinn", "exponent": 50},
                         {"n": 1.4, "distribution": "beckmann", "m": 0.2}]},
        "ht": {"type": "htsg", "n": 1.5, "k": 0.1, "sigma0_um": 0.1, "tau_um": 2, "albedo": 0.1, "exterior_n": 1},
        "bg": {"type": "black_glass", "n": 1.5, "k": 0, "exterior_n": 1},
        "die": {"type": "dielectric", "n": 1.5, "exterior_n": 1},
    },
    "objects": [
        {"name": "s", "shape": "sphere", "center": [-1, 0, 1], "radius": 0.8, "subdivisions": 1, "material": "ww"},
        {"name": "q", "shape": "quad", "vertices": [[-9, -9, 0], [9, -9, 0], [9, 9, 0], [-9, 9, 0]],
         "material": "bg", "emission": {"radiance": 0.5, "color": [1, 1, 1]}},
        {"name": "t", "shape": "triangles", "vertices": [[0, 0, 3], [1, 0, 3], [0, 1, 3]], "faces": [[0, 1, 2]],
         "normals": [[0, 0, 1], [0, 0, 1], [0, 0, 1]], "materials": ["lam", "ht"], "material_ids": [1],
         "transform": {"matrix": I4}},
        {"name": "u", "shape": "sphere", "material": "cond", "subdivisions": 0,
         "transform": {"translate": [0, 0, 0], "scale": 1, "rotate_deg": [0, 0, 0]}},
        {"name": "v", "shape": "sphere", "material": "ts", "subdivisions": 0, "transform": {"scale": [1, 1, 1]}},
    ],
    "lights": [{"type": "environment", "radiance": 1.0, "color": [1, 1, 1]},
               {"type": "point", "position": [0, -2, 3], "intensity": 5},
               {"type": "spot", "position": [0, 0, 4], "target": [0, 0, 0], "cone_angle_deg": 30, "blend": 0.1,
                "intensity": 2},
               {"type": "directional", "direction": [0.2, 0.1, -1], "irradiance": 2}],
}


def field_of(path):
    out = ""
    for k in path:
        out = f"{out}[{k}]" if isinstance(k, int) else (f"{out}.{k}" if out else k)
    return out


def number_paths(node, prefix=()):
    if isinstance(node, dict):
        for k, v in node.items():
            yield from number_paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from number_paths(v, prefix + (i,))
    elif isinstance(node, (int, float)) and not isinstance(node, bool):
        yield prefix


NUMBER_PATHS = list(number_paths(RICH))


def changed(path, value, doc=RICH):
    doc = copy.deepcopy(doc)
    node = doc
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return doc


def write(tmp_path, data: bytes, name="scene.json"):
    path = tmp_path / name
    path.write_bytes(data)
    return str(path)


def test_rich_scene_loads():
    scene = parse_scene(RICH)
    assert len(scene.meshes) == 5 and len(scene.materials) == 11 and len(NUMBER_PATHS) > 100


# --------------------------------------------------------------------------- huge integers

@pytest.mark.parametrize("path", NUMBER_PATHS, ids=field_of)
def test_integer_beyond_double_range_in_any_number_field_names_it(path):
    for value in (10 ** 400, -10 ** 400, 10 ** 5000):
        with pytest.raises(SceneError) as err:
            parse_scene(changed(path, value))
        assert err.value.field == field_of(path)
        assert "±1.8e308" in str(err.value) and "digits" in str(err.value)


@pytest.mark.parametrize("digits", [310, 400, 4301, 100_000])
def test_long_integer_literal_in_a_file_even_in_a_note_names_the_field(tmp_path, digits):
    text = json.dumps(dict(RICH, note="X")).replace('"X"', "-" + "7" * digits)
    with pytest.raises(SceneError) as err:
        load_scene(write(tmp_path, text.encode()))
    assert err.value.field == "note" and f"{digits} digits" in str(err.value)


def test_number_and_integer_readers_state_the_range_for_huge_integers():
    with pytest.raises(SceneError, match=r"camera.width: must be a whole number in \[1, 65536\], got an integer "
                                         r"with 401 digits"):
        loader.integer(10 ** 400, "camera.width", 1, 65536)
    with pytest.raises(SceneError, match=r"x: must be a finite number in \[0, inf\], got an integer with 400 digits"):
        loader.number(-(10 ** 400 - 1), "x", 0)


def test_largest_double_range_integers_are_ordinary_numbers():
    big = int(1.7e308)
    with pytest.raises(SceneError, match=r"camera.clip_end.*\(0, inf\]|must be greater"):
        parse_scene(changed(("camera", "clip_start"), big))
    scene = parse_scene(changed(("camera", "clip_end"), big))
    assert scene.camera.clip_end == float(big)


# --------------------------------------------------------------------------- nesting

def nested(levels):
    note = []
    for _ in range(levels - 1):
        note = [note]
    return note


def test_deep_nesting_in_a_file_is_reported_with_its_line(tmp_path):
    text = json.dumps(RICH, indent=1).replace('"render"', '"note": ' + "[" * 100_000 + "]" * 100_000 + ',\n"render"')
    with pytest.raises(SceneError, match=r"nest more than 64 levels deep \(at line \d+\)"):
        load_scene(write(tmp_path, text.encode()))


@pytest.mark.parametrize("levels,ok", [(63, True), (64, False), (200, False), (100_000, False)])
def test_nesting_bound_names_the_field(levels, ok):
    doc = dict(RICH, note=nested(levels))          # the scene object is level 1, so note reaches 1 + levels
    if ok:
        parse_scene(doc)
        return
    with pytest.raises(SceneError, match="nest more than 64 levels deep") as err:
        parse_scene(doc)
    assert err.value.field.startswith("note[0]")


def test_nesting_in_a_file_between_the_bound_and_pythons_recursion_limit_names_the_field(tmp_path):
    text = json.dumps(dict(RICH, note=nested(300)))
    with pytest.raises(SceneError, match="nest more than 64") as err:
        load_scene(write(tmp_path, text.encode()))
    assert err.value.field.startswith("note[0]")


def test_shared_and_cyclic_python_structures_terminate():
    shared = [[1.0, 2.0]] * 3
    chain = shared
    for _ in range(60):
        chain = [chain, chain]                     # 2**60 paths, 60 distinct lists
    parse_scene(dict(RICH, note=chain))
    loop = []
    loop.append(loop)
    parse_scene(dict(RICH, note=loop))             # visited once; a note is never read


# --------------------------------------------------------------------------- encodings

TEXT = json.dumps(dict(RICH, note="café"), ensure_ascii=False)


@pytest.mark.parametrize("data,words", [
    (TEXT.encode("utf-16"), "UTF-16 little-endian"),
    (b"\xfe\xff" + TEXT.encode("utf-16-be"), "UTF-16 big-endian"),
    (TEXT.encode("utf-32"), "UTF-32 little-endian"),
    (TEXT.encode("utf-16-le"), "looks like UTF-16 or UTF-32"),
    (TEXT.encode("utf-32-be"), "looks like UTF-16 or UTF-32"),
    (TEXT.encode("latin-1"), "is not valid UTF-8"),
    (TEXT.encode("cp1252"), "is not valid UTF-8"),
    (TEXT.encode()[:-40] + b"\xff\xfe" + TEXT.encode()[-38:], "byte 0xFF"),
], ids=["utf16-bom", "utf16be-bom", "utf32-bom", "utf16-no-bom", "utf32-no-bom", "latin1", "cp1252", "bad-bytes"])
def test_files_that_are_not_utf8_are_rejected_saying_so(tmp_path, data, words):
    with pytest.raises(SceneError) as err:
        load_scene(write(tmp_path, data))
    assert words in str(err.value) and "must be UTF-8" in str(err.value) and err.value.field == ""


def test_invalid_utf8_reports_line_and_column(tmp_path):
    data = b'{"format": "polar-scene/1",\n  "note": "caf\xe9"}'
    with pytest.raises(SceneError, match=r"byte 0xE9 at line 2, column 15 is not valid UTF-8"):
        load_scene(write(tmp_path, data))


def test_utf8_with_and_without_byte_order_mark_loads(tmp_path):
    for data in (TEXT.encode(), b"\xef\xbb\xbf" + TEXT.encode()):
        assert len(load_scene(write(tmp_path, data)).meshes) == 5


# --------------------------------------------------------------------------- layered materials

COAT = {"n": 1.5}


def with_materials(**mats):
    doc = copy.deepcopy(RICH)
    doc["materials"].update(mats)
    return doc


def inline_stack(levels, coats=1):
    m = {"type": "lambert"}
    for _ in range(levels):
        m = {"type": "weidlich_wilkie", "coats": [COAT] * coats, "base": m}
    return m


def named_chain(length):
    mats = {f"m{i}": {"type": "weidlich_wilkie", "coats": [COAT], "base": f"m{i + 1}"} for i in range(length)}
    mats[f"m{length}"] = {"type": "lambert"}
    return mats


@pytest.mark.parametrize("mats,field,words", [
    ({"x": {"type": "weidlich_wilkie", "coats": [COAT] * 600}}, "materials.x.coats", "at most 64 coats"),
    ({"x": {"type": "weidlich_wilkie", "coats": [COAT] * 65}}, "materials.x.coats", "got 65"),
    ({"x": inline_stack(9, coats=8)}, "materials.x" + ".base" * 8 + ".coats", "at most 64 coats in all"),
    ({"x": inline_stack(18)}, "materials.x" + ".base" * 18, "more than 16 levels deep below materials.x"),
    (named_chain(400), "materials.m17.base", "more than 16 levels deep below materials.m0"),
    (named_chain(18), "materials.m17.base", "counting bases given inline and by name"),
    (dict(named_chain(9), a={"type": "weidlich_wilkie", "coats": [COAT], "base": inline_stack(9)}, **{
        "m9": {"type": "weidlich_wilkie", "coats": [COAT], "base": "a"}}), "materials.a" + ".base" * 8, "16 levels"),
], ids=["600-coats", "65-coats", "coats-in-all", "inline-18", "named-400", "named-18", "named-then-inline"])
def test_layered_stacks_are_bounded(mats, field, words):
    with pytest.raises(SceneError) as err:
        parse_scene(with_materials(**mats))
    assert err.value.field == field and words in str(err.value), str(err.value)


@pytest.mark.parametrize("mats", [{"x": inline_stack(17)}, named_chain(17), {"x": inline_stack(8, coats=8)},
                                  {"x": {"type": "weidlich_wilkie", "coats": [COAT] * 64}}])
def test_stacks_at_the_bounds_load(mats):
    parse_scene(with_materials(**mats))


def test_circular_named_bases_are_still_reported_as_such():
    mats = {"a": {"type": "weidlich_wilkie", "coats": [COAT], "base": "b"},
            "b": {"type": "weidlich_wilkie", "coats": [COAT], "base": "a"}}
    with pytest.raises(SceneError, match="refers to itself"):
        parse_scene(with_materials(**mats))


def test_parse_material_bounds_coats_when_called_directly():
    with pytest.raises(SceneError, match="at most 64 coats"):
        parse_material({"type": "weidlich_wilkie", "coats": [COAT] * 600}, "m")


ROUGH = {"n": 1.5, "distribution": "beckmann", "m": 0.2}
MIRROR_HTSG = {"type": "htsg", "metal": "Al", "sigma0_um": 0, "tau_um": 3}


@pytest.mark.parametrize("base,words", [
    ({"type": "conductor", "metal": "Al"}, "delta-only base (conductor)"),
    (MIRROR_HTSG, "HTSG base with sigma0_um = 0 and no albedo"),
    (dict(MIRROR_HTSG, albedo=[0, 0, 0]), "HTSG base with sigma0_um = 0"),
    ({"type": "weidlich_wilkie", "coats": [{"n": 1.4}], "base": MIRROR_HTSG}, "smooth coat over an HTSG base"),
])
def test_rough_coat_over_an_all_dirac_base_is_rejected_alike(base, words):
    doc = with_materials(x={"type": "weidlich_wilkie", "coats": [ROUGH], "base": base})
    with pytest.raises(SceneError) as err:
        parse_scene(doc)
    assert err.value.field == "materials.x" and words in str(err.value) and "sigma0_um > 0" in str(err.value)


@pytest.mark.parametrize("base", [dict(MIRROR_HTSG, sigma0_um=0.05), dict(MIRROR_HTSG, albedo=0.3)])
def test_rough_coat_over_htsg_with_a_function_valued_part_is_accepted(base):
    parse_scene(with_materials(x={"type": "weidlich_wilkie", "coats": [ROUGH], "base": base}))


def test_weidlich_wilkie_rejects_a_rough_coat_over_a_mirror_htsg_also_from_python():
    rough = Coat(n=1.5, distribution="beckmann", m=0.2)
    with pytest.raises(ValueError, match="sigma0_um = 0"):
        WeidlichWilkie([rough], HTSG(1.2, 7.0, 0.0, 3.0))
    with pytest.raises(ValueError, match="sigma0_um = 0"):
        WeidlichWilkie([rough, Coat(n=1.3)], HTSG(1.2, 7.0, 0.0, 3.0))
    WeidlichWilkie([Coat(n=1.3)], HTSG(1.2, 7.0, 0.0, 3.0))          # a smooth coat layers the mirror
    WeidlichWilkie([rough], Lambert(0.5))


# --------------------------------------------------------------------------- inline arrays

@pytest.mark.parametrize("key,value,field,words", [
    ("vertices", [[0, 0, "3"], [1, 0, 3], [0, 1, 3]], "objects[2].vertices[0][2]", "got '3'"),
    ("vertices", [[0, 0, True], [1, 0, 3], [0, 1, 3]], "objects[2].vertices[0][2]", "got True"),
    ("vertices", [[0, 0, 3], [1, 0], [0, 1, 3]], "objects[2].vertices[1]", "list of 3 numbers"),
    ("vertices", [[0, 0, 3], None, [0, 1, 3]], "objects[2].vertices[1]", "list of 3 numbers"),
    ("vertices", "abc", "objects[2].vertices", "got str"),
    ("faces", [["0", 1, 2]], "objects[2].faces[0][0]", "got '0'"),
    ("faces", [[0, False, 2]], "objects[2].faces[0][1]", "got False"),
    ("faces", [[0, 1, [2]]], "objects[2].faces[0][2]", "must be a number"),
    ("faces", [[0, 1, 1.5]], "objects[2].faces", "whole numbers"),
    ("normals", [[0, 0, "1"], [0, 0, 1], [0, 0, 1]], "objects[2].normals[0][2]", "got '1'"),
    ("normals", [[0, 0, 1], [0, 0, 1], [0, 0, False]], "objects[2].normals[2][2]", "got False"),
    ("material_ids", ["1"], "objects[2].material_ids[0]", "got '1'"),
    ("material_ids", [True], "objects[2].material_ids[0]", "got True"),
    ("material_ids", [[1]], "objects[2].material_ids[0]", "must be a number"),
    ("transform", {"matrix": I4[:3] + [[0, 0, 0]]}, "objects[2].transform.matrix[3]", "list of 4 numbers"),
    ("transform", {"matrix": I4[:3] + ["abcd"]}, "objects[2].transform.matrix[3]", "list of 4 numbers"),
    ("transform", {"matrix": I4[:3] + [[0, 0, 0, "1"]]}, "objects[2].transform.matrix[3][3]", "got '1'"),
    ("transform", {"matrix": I4[:3] + [[0, 0, 0, True]]}, "objects[2].transform.matrix[3][3]", "got True"),
    ("transform", {"matrix": I4[:3]}, "objects[2].transform.matrix", "4×4"),
    ("transform", {"matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}, "objects[2].transform.matrix[0]", "4 numbers"),
])
def test_inline_arrays_take_numbers_only(key, value, field, words):
    with pytest.raises(SceneError) as err:
        parse_scene(changed(("objects", 2, key), value))
    assert err.value.field == field and words in str(err.value), str(err.value)


def test_inline_arrays_still_accept_numpy_arrays_from_python():
    doc = copy.deepcopy(RICH)
    obj = doc["objects"][2]
    obj["vertices"] = np.array(obj["vertices"], dtype=np.float32)
    obj["faces"] = np.array(obj["faces"])
    obj["material_ids"] = np.array(obj["material_ids"])
    mesh = parse_scene(doc).meshes[2]
    assert mesh.vertices.shape == (3, 3) and mesh.material_ids.tolist() == [1]


# --------------------------------------------------------------------------- light bounds

@pytest.mark.parametrize("path", [("lights", 0, "radiance"), ("lights", 1, "intensity"), ("lights", 2, "intensity"),
                                  ("lights", 3, "irradiance"), ("objects", 1, "emission", "radiance"),
                                  ("lights", 0, "color", 1), ("objects", 1, "emission", "color", 0)])
@pytest.mark.parametrize("value", [1e39, 1e308, 2e30])
def test_light_values_are_at_most_1e30(path, value):
    with pytest.raises(SceneError) as err:
        parse_scene(changed(path, value))
    assert err.value.field == field_of(path) and "[0, 1e+30]" in str(err.value)


def test_light_value_times_colour_is_at_most_1e30():
    doc = changed(("lights", 1, "color"), [1e20, 1, 1], changed(("lights", 1, "intensity"), 1e20))
    with pytest.raises(SceneError, match=r"lights\[1\].color: times the intensity must be at most 1e\+30"):
        parse_scene(doc)


def test_brightest_allowed_lights_give_finite_images():
    from engine.render.renderer import Renderer
    doc = RICH
    for path in [("lights", 0, "radiance"), ("lights", 1, "intensity"), ("lights", 2, "intensity"),
                 ("lights", 3, "irradiance"), ("objects", 1, "emission", "radiance")]:
        doc = changed(path, 1e30, doc)
    stokes = Renderer(parse_scene(doc)).render().stokes().astype(np.float32)
    assert np.all(np.isfinite(stokes)) and stokes[0].max() > 1e29


# --------------------------------------------------------------------------- peer scenes

@pytest.mark.parametrize("key,value", [("camera", [1, 2]), ("camera", "abc"), ("materials", []),
                                       ("integrator", 3), ("objects", {"a": 1}), ("objects", "ab")])
def test_peer_scene_sections_of_the_wrong_type_name_the_section(key, value):
    peer = {"light": {"type": "constant_environment"}, "integrator": {}, "objects": [], "camera": {}}
    peer[key] = value
    with pytest.raises(SceneError) as err:
        parse_scene(peer)
    assert err.value.field == key


# --------------------------------------------------------------------------- the command line

@pytest.mark.parametrize("data,words", [
    (json.dumps(changed(("objects", 0, "radius"), 10 ** 400)).encode(), "objects[0].radius: must be a number"),
    (json.dumps(dict(RICH, note="X")).replace('"X"', "9" * 5000).encode(), "note: must be a number"),
    (json.dumps(dict(RICH, note="X")).replace('"X"', "[" * 100_000 + "]" * 100_000).encode(), "nest more than 64"),
    (TEXT.encode("utf-16"), "must be UTF-8"),
    (TEXT.encode("latin-1"), "not valid UTF-8"),
    (json.dumps(with_materials(x={"type": "weidlich_wilkie", "coats": [COAT] * 600})).encode(), "at most 64 coats"),
    (json.dumps(with_materials(**named_chain(400))).encode(), "16 levels"),
    (json.dumps(changed(("objects", 2, "transform"), {"matrix": [[1, 2], [3]]})).encode(), "matrix[0]"),
    (json.dumps(changed(("lights", 0, "radiance"), 1e39)).encode(), "1e+30"),
], ids=["int400", "note5000", "deep", "utf16", "latin1", "coats600", "chain400", "ragged-matrix", "radiance1e39"])
def test_cli_prints_one_error_line_and_exits_2(tmp_path, capsys, data, words):
    path = write(tmp_path, data)
    assert main(["render", path, "-o", str(tmp_path / "out.exr")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and words in err, err
    assert not (tmp_path / "out.exr").exists()


def test_obj_faces_before_the_first_usemtl_name_the_obj_line(tmp_path):
    """A scene mapping usemtl names to materials cannot place faces that come before every usemtl:
    the error names the OBJ line (not ``material_ids``, a field the user never wrote)."""
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nusemtl glass\nf 1 2 3\n")
    doc = {"format": "polar-scene/1",
           "camera": {"origin": [0, -5, 0], "target": [0, 0, 0], "up": [0, 0, 1], "width": 4, "height": 4},
           "materials": {"g": {"type": "lambert"}},
           "objects": [{"shape": "mesh", "file": "m.obj", "materials": {"glass": "g"}}],
           "lights": [{"type": "point", "position": [0, -2, 2], "intensity": 1}]}
    (tmp_path / "s.json").write_text(json.dumps(doc))
    with pytest.raises(SceneError) as e:
        load_scene(str(tmp_path / "s.json"))
    assert e.value.field == "objects[0].file" and "line 4" in str(e.value) and "usemtl" in str(e.value)
    doc["objects"][0] = {"shape": "mesh", "file": "m.obj", "material": "g"}   # one material: every face has it
    (tmp_path / "s.json").write_text(json.dumps(doc))
    assert len(load_scene(str(tmp_path / "s.json")).meshes) == 1


def test_an_emission_spectrum_table_is_refused_not_dropped():
    from engine.scene.loader import _parse_emission
    assert _parse_emission({"radiance": 2, "spectrum": "D65 white"}, "e") is not None   # peer-style description
    with pytest.raises(SceneError) as e:
        _parse_emission({"radiance": 2, "spectrum": [[360, 1], [830, 1]]}, "e")
    assert e.value.field == "e.spectrum" and "color" in str(e.value)


@pytest.mark.parametrize("value", [10**400, [10**400, 0, 0], {"spectrum": [[360, 10**400], [830, 1]]}])
def test_huge_integers_in_spectra_are_scene_errors_when_parse_material_is_called_directly(value):
    with pytest.raises(SceneError) as e:
        parse_material({"type": "lambert", "albedo": value}, "m")
    assert e.value.field.startswith("m.albedo")


def test_fifos_and_devices_are_refused_before_they_are_opened(tmp_path):
    """A scene, mesh or image path that names a FIFO (or a device) is one SceneError naming the field,
    raised before opening it: opening a FIFO with no writer would wait forever (an alarm turns a hang
    into a failure here)."""
    import signal
    from engine.scene.loader import load_scene, parse_scene
    from engine.scene.meshio import read_mesh
    from engine.textures.image import read_image
    fifo = tmp_path / "pipe.json"
    os.mkfifo(fifo)
    for ext in ("ply", "png", "exr", "hdr", "tif"):
        os.mkfifo(tmp_path / f"pipe.{ext}")
    previous = signal.signal(signal.SIGALRM, lambda *_: (_ for _ in ()).throw(TimeoutError("hung on a FIFO")))
    signal.alarm(20)
    try:
        with pytest.raises(SceneError, match=r"scene file '.*pipe\.json' is not a regular file"):
            load_scene(str(fifo))
        with pytest.raises(SceneError, match=r"^objects\[0\]\.file: mesh file '.*pipe\.ply' is not a regular"):
            read_mesh(str(tmp_path / "pipe.ply"), "objects[0].file")
        for ext in ("png", "exr", "hdr", "tif"):
            with pytest.raises(SceneError, match=r"^materials\.m\.albedo: image '.*' is not a regular file"):
                read_image(str(tmp_path / f"pipe.{ext}"), field="materials.m.albedo")
        with pytest.raises(SceneError, match=r"materials\.m\.albedo.*is not a regular file"):
            parse_scene({"format": "polar-scene/1",
                         "camera": {"origin": [0, -3, 1], "target": [0, 0, 0], "up": [0, 0, 1], "fov_deg": 30,
                                    "width": 4, "height": 4},
                         "materials": {"m": {"type": "lambert", "albedo": {"texture": "pipe.png"}}},
                         "objects": [{"shape": "quad", "vertices": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]],
                                      "material": "m"}],
                         "lights": [{"type": "environment", "radiance": 1.0}]}, base_dir=str(tmp_path))
        with pytest.raises(SceneError, match="is not a regular file"):
            load_scene("/dev/zero")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
