"""Material parameter declarations: one table per model drives the scene loader, the `mueller`
catalogue and the Blender node's sockets (engine.materials.parameters)."""

import importlib
import importlib.util
import math
import os
import sys

import pytest

from engine.errors import SceneError
from engine.materials.catalogue import CATALOGUE, MODEL_PARAMETERS, MODELS, make_model, parameter_help
from engine.materials.parameters import REQUIRED
from engine.scene.loader import parse_material
from engine.spectral.ior import NAMED_METALS
from tests.conftest import REPO

#: Smallest valid material per catalogue model: (scene-file object, flat catalogue parameters).
MINIMAL = {
    "lambert": ({"type": "lambert"}, {}),
    "conductor": ({"type": "conductor", "n": 1.5}, {"n": "1.5"}),
    "torrance_sparrow": ({"type": "torrance_sparrow", "n": 1.5, "m": 0.1}, {"n": "1.5", "m": "0.1"}),
    "htsg": ({"type": "htsg", "n": 1.5, "sigma0_um": 0.1, "tau_um": 3.0},
             {"n": "1.5", "sigma0_um": "0.1", "tau_um": "3"}),
    "weidlich_wilkie": ({"type": "weidlich_wilkie", "coats": [{}]}, {}),
}
#: What a coat parameter needs beside it (its distribution).
COAT_CONTEXT = {"exponent": {"distribution": "blinn"}, "m": {"distribution": "beckmann"}}


def probes(p):
    """Values on, inside and just outside the declared range of a number-valued parameter."""
    step = lambda x: max(1e-3, abs(x) * 1e-2)   # noqa: E731
    out = [math.nan, math.inf, -math.inf]
    if math.isfinite(p.lo):
        out += [p.lo, p.lo - step(p.lo), p.lo + step(p.lo)]
    if math.isfinite(p.hi):
        out += [p.hi, p.hi + step(p.hi), p.hi - step(p.hi)]
    return out


def range_cases():
    """(scene type, flat name, loader key path, Parameter) of every number or spectrum parameter."""
    for decl in MODELS.values():
        if decl.name not in MINIMAL:
            continue
        for p in decl.parameters:
            if p.kind in ("number", "spectrum"):
                yield decl.name, p.name, (p.name,), p
            elif p.kind == "coats":
                for q in p.members.parameters:
                    if q.kind in ("number", "spectrum"):
                        yield decl.name, "coat_" + q.name, ("coats", q.name), q
            elif p.kind == "material":   # the catalogue's base is a Lambert
                yield decl.name, "base_albedo", ("base", "albedo"), MODELS["lambert"]["albedo"]


def _accepts(build):
    try:
        build()
    except SceneError as e:
        return e.field
    return None


CASES = list(range_cases())


@pytest.mark.parametrize("model,flat,path,param", CASES, ids=[f"{c[0]}.{c[1]}" for c in CASES])
def test_loader_and_catalogue_enforce_the_declared_range_identically(model, flat, path, param):
    scene, cat = MINIMAL[model]
    catalogue_name = MODELS[model].catalogue
    for v in probes(param):
        d = {k: (list(x) if isinstance(x, list) else x) for k, x in scene.items()}
        if path[0] == "coats":
            d["coats"] = [{**COAT_CONTEXT.get(path[1], {}), path[1]: v}]
        elif path[0] == "base":
            d["base"] = {"type": "lambert", "albedo": v}
        else:
            d[path[0]] = v
        flat_params = dict(cat, **{flat: repr(v) if math.isfinite(v) else str(v)})
        if path[0] == "coats" and path[1] in COAT_CONTEXT:
            flat_params["coat_distribution"] = COAT_CONTEXT[path[1]]["distribution"]
        if flat in ("m", "coat_m", "alpha") and 0 < v < 1e-4:
            continue   # between 0 and the smallest slope: the smooth-limit rule, tested below
        expected = param.contains(v)
        loader_field = _accepts(lambda d=d: parse_material(d, "m"))
        catalogue_field = _accepts(lambda fp=flat_params: make_model(catalogue_name, fp))
        assert (loader_field is None) == expected, (v, loader_field)
        assert (catalogue_field is None) == expected, (v, catalogue_field)
        if not expected:
            assert loader_field.split(".")[-1].startswith(path[-1]), loader_field
            assert catalogue_field == f"param.{flat}", catalogue_field


def test_every_declared_default_lies_in_its_range_and_kinds_are_consistent():
    for decl in list(MODELS.values()) + [MODELS["weidlich_wilkie"]["coats"].members]:
        for p in decl.parameters:
            if p.kind == "number" and p.default not in (REQUIRED, None):
                assert p.contains(p.default), (decl.name, p.name)
            if p.kind == "choice" and p.default not in (REQUIRED, None):
                assert p.default in p.choices, (decl.name, p.name)
            if p.only_with is not None:
                assert p.only_with[0] in decl, (decl.name, p.name)


def test_texturable_parameters_are_the_surface_varying_ones():
    texturable = {(d.name, p.name) for d in list(MODELS.values()) + [MODELS["weidlich_wilkie"]["coats"].members]
                  for p in d.parameters if p.texturable}
    assert texturable == {
        ("lambert", "albedo"), ("conductor", "n"), ("conductor", "k"),
        ("torrance_sparrow", "n"), ("torrance_sparrow", "k"), ("torrance_sparrow", "m"),
        ("torrance_sparrow", "diffuse_albedo"), ("torrance_sparrow", "diffuse_weight"),
        ("torrance_sparrow", "specular_weight"),
        ("htsg", "n"), ("htsg", "k"), ("htsg", "sigma0_um"), ("htsg", "tau_um"), ("htsg", "albedo"),
        ("coat", "n"), ("coat", "thickness"), ("coat", "absorption"), ("coat", "exponent"), ("coat", "m"),
        ("principled", "base_color"), ("principled", "metallic"), ("principled", "roughness"),
        ("principled", "transmission"), ("principled", "coat_tint"), ("principled", "coat_weight"),
        ("principled", "sheen_weight"), ("principled", "sheen_tint"), ("principled", "coat_roughness"),
        ("principled", "sheen_roughness"), ("principled", "specular_tint"), ("principled", "thin_film_thickness"),
        ("principled", "specular_ior_level"), ("principled", "diffuse_roughness"), ("oren_nayar", "roughness"),
        ("principled", "coat_ior"), ("principled", "thin_film_ior"), ("conductor", "thin_film_ior"),
        ("torrance_sparrow", "thin_film_ior"), ("principled", "anisotropic"), ("principled", "anisotropic_rotation"),
        ("principled", "ior"),
        ("conductor", "thin_film_thickness"), ("torrance_sparrow", "thin_film_thickness"), ("oren_nayar", "albedo"),
        ("sheen", "tint"), ("sheen", "roughness"), ("thin_film", "film_n"), ("thin_film", "thickness"),
        ("thin_film", "n"), ("rough_dielectric", "n"), ("rough_dielectric", "alpha"), ("refraction", "n"),
        ("rough_dielectric", "thin_film_thickness"), ("rough_dielectric", "thin_film_ior"),
        ("refraction", "alpha")}


@pytest.mark.parametrize("coat,field", [
    ({"distribution": "smooth", "m": 0.1}, "m"), ({"m": 0.1}, "m"), ({"exponent": 20}, "exponent"),
    ({"distribution": "blinn", "exponent": 20, "m": 0.1}, "m"),
    ({"distribution": "beckmann", "m": 0.1, "exponent": 20}, "exponent")])
def test_a_coat_parameter_its_distribution_ignores_is_rejected(coat, field):
    with pytest.raises(SceneError) as err:
        parse_material({"type": "weidlich_wilkie", "coats": [coat]}, "materials.x")
    assert err.value.field == f"materials.x.coats[0].{field}"
    assert "only meaningful with distribution" in str(err.value)
    flat = {"coat_" + k: str(v) for k, v in coat.items()}
    with pytest.raises(SceneError) as err:
        make_model("weidlich_wilkie", flat)
    assert err.value.field == f"param.coat_{field}" and "coat_distribution" in str(err.value)


def test_t_term_is_rejected_where_the_energy_form_ignores_it():
    with pytest.raises(SceneError) as err:
        parse_material({"type": "weidlich_wilkie", "coats": [{}], "t_term": "t21"}, "x")
    assert err.value.field == "x.t_term" and "'published'" in str(err.value)
    parse_material({"type": "weidlich_wilkie", "coats": [{}], "t_term": "t21", "form": "published"}, "x")


def test_filter_sheets_take_only_their_own_parameters():
    parse_material({"type": "retarder", "axis": [1, 0, 0], "retardance_deg": 45}, "x")
    with pytest.raises(SceneError) as err:
        parse_material({"type": "polariser", "axis": [1, 0, 0], "retardance_deg": 45}, "x")
    assert err.value.field == "x.retardance_deg"


def test_torrance_sparrow_weights_have_a_finite_upper_bound():
    for key in ("diffuse_weight", "specular_weight"):
        with pytest.raises(SceneError) as err:
            parse_material({"type": "torrance_sparrow", "n": 1.5, "m": 0.1, key: 1e300}, "x")
        assert err.value.field == f"x.{key}" and "[0, 1e+06]" in str(err.value)
        with pytest.raises(SceneError) as err:
            make_model("torrance_sparrow", {"n": "1.5", "m": "0.1", key: "1e300"})
        assert err.value.field == f"param.{key}" and "[0, 1e+06]" in str(err.value)


def test_a_roughness_below_the_smooth_limit_builds_the_smooth_model_from_a_file_and_the_catalogue():
    """engine.materials.roughness: one rule for every microfacet model and every front end: a constant slope below
    SMOOTH_LIMIT (0 included) is the smooth model; from SMOOTH_LIMIT = ALPHA_MIN on, the rough lobe."""
    from engine.materials.roughness import ALPHA_MIN, SMOOTH_LIMIT
    assert SMOOTH_LIMIT == ALPHA_MIN == 1e-4
    for m in ("0", "5e-5", repr(math.nextafter(SMOOTH_LIMIT, 0.0))):
        for built in (parse_material({"type": "torrance_sparrow", "n": 1.5, "m": float(m)}, "x"),
                      make_model("torrance_sparrow", {"n": "1.5", "m": m}, "x")):
            assert type(built).__name__ == "MirrorWithDiffuse" and built.m == 0.0
        for built in (parse_material({"type": "rough_dielectric", "n": 1.5, "alpha": float(m)}, "x"),
                      make_model("rough_dielectric", {"n": "1.5", "alpha": m}, "x")):
            assert built.name == "dielectric"
        coat = make_model("weidlich_wilkie", {"coat_n": "1.5", "coat_distribution": "beckmann", "coat_m": m})
        assert coat.coat.smooth
    assert make_model("torrance_sparrow", {"n": "1.5", "m": repr(SMOOTH_LIMIT)}).m == SMOOTH_LIMIT
    assert make_model("rough_dielectric", {"n": "1.5", "alpha": repr(SMOOTH_LIMIT)}).alpha == SMOOTH_LIMIT
    assert not make_model("weidlich_wilkie", {"coat_n": "1.5", "coat_distribution": "beckmann",
                                              "coat_m": "0.01"}).coat.smooth


@pytest.mark.parametrize("model", list(MINIMAL))
def test_loader_and_catalogue_build_the_same_model(model):
    extra = {"torrance_sparrow": ({"diffuse_albedo": 0.3, "exterior_n": 1.2},
                                  {"diffuse_albedo": "0.3", "exterior_n": "1.2"}),
             "htsg": ({"metal": "Al", "albedo": 0.1}, {"metal": "Al", "albedo": "0.1"}),
             "conductor": ({"k": 2.0}, {"k": "2"}),
             "lambert": ({"albedo": 0.4}, {"albedo": "0.4"}),
             "weidlich_wilkie": ({"coats": [{"n": 1.4, "distribution": "beckmann", "m": 0.2}],
                                  "base": {"type": "lambert", "albedo": 0.5}},
                                 {"coat_n": "1.4", "coat_distribution": "beckmann", "coat_m": "0.2",
                                  "base_albedo": "0.5"})}[model]
    scene, cat = MINIMAL[model]
    d, flat = {**scene, **extra[0]}, {**cat, **extra[1]}
    if "metal" in flat:
        d.pop("n")
        flat.pop("n")
    assert parse_material(d, "x").describe() == make_model(MODELS[model].catalogue, flat).describe()


def test_mueller_help_lists_every_catalogue_model_and_parameter():
    text = parameter_help()
    for name, params in MODEL_PARAMETERS.items():
        assert f"  {name}: " in text
        for key in params:
            assert f"    {key}: " in text
    assert set(CATALOGUE) == {"lambert", "fresnel", "torrance_sparrow", "htsg", "weidlich_wilkie", "rough_dielectric",
                              "thin_dielectric", "refraction"}


# ------------------------------------------------------------------------------------------ Blender node

#: The repository imported as a package, as Blender imports the extension, but under its own name:
#: tests.blender_support registers the add-on when it first imports ``polar_render``.
_PACKAGE = "polar_render_data"


def node_models():
    """polar_addon.nodes.models without bpy."""
    if _PACKAGE not in sys.modules:
        spec = importlib.util.spec_from_file_location(_PACKAGE, os.path.join(REPO, "__init__.py"),
                                                      submodule_search_locations=[REPO])
        module = importlib.util.module_from_spec(spec)
        sys.modules[_PACKAGE] = module
        spec.loader.exec_module(module)
    return importlib.import_module(f"{_PACKAGE}.polar_addon.nodes.models")


#: Socket names saved .blend files refer to, per model, in order: never renamed, moved or removed
#: (new sockets may only be appended).
SAVED_SOCKETS = {
    "LAMBERT": [("Albedo", "COLOR")],
    "CONDUCTOR": [("n", "FLOAT"), ("k", "FLOAT")],
    "DIELECTRIC": [("IOR", "FLOAT")],
    "BLACK_GLASS": [("IOR", "FLOAT")],
    "TORRANCE_SPARROW": [("n", "FLOAT"), ("k", "FLOAT"), ("Roughness", "FLOAT"), ("Diffuse", "COLOR")],
    "HTSG": [("n", "FLOAT"), ("k", "FLOAT"), ("Sigma0", "FLOAT"), ("Tau", "FLOAT"), ("Diffuse", "COLOR")],
    "WEIDLICH_WILKIE": [("Coat IOR", "FLOAT"), ("Coat Thickness", "FLOAT"), ("Coat Absorption", "COLOR"),
                        ("Coat Roughness", "FLOAT"), ("Base", "SHADER")],
    "ROUGH_DIELECTRIC": [("IOR", "FLOAT"), ("Roughness", "FLOAT")],
    "THIN_DIELECTRIC": [("IOR", "FLOAT")],
}


def test_node_sockets_keep_the_saved_names_and_types():
    models = node_models()
    assert [i[0] for i in models.MODEL_ITEMS] == list(models.MODEL_SOCKETS) == list(SAVED_SOCKETS)
    for model, saved in SAVED_SOCKETS.items():
        sockets = models.MODEL_SOCKETS[model]
        assert [(s[0], s[1]) for s in sockets[:len(saved)]] == saved, model
        assert len({s[0] for s in sockets}) == len(sockets), model


def test_node_sockets_are_the_declared_parameters():
    models = node_models()
    for model, decl in models.NODE_MODELS.items():
        declared = []
        for p in decl.parameters:
            for q in (p.members.parameters if p.kind == "coats" else (p,)):
                if q.socket is not None:
                    declared.append((q, q.socket))
        assert [s.as_tuple() for _, s in declared] == [tuple(t) for t in models.MODEL_SOCKETS[model]]
        for p, s in declared:
            if s.type == "SHADER":
                assert p.kind == "material"
                continue
            assert s.type == "FLOAT" if p.kind == "number" else p.kind == "spectrum", (model, p.name)
            # The UI range lies inside the allowed one; roughness sockets start at 0, the smooth model.
            lo_ok = p.contains(s.soft_min) or (p.name == "m" and s.soft_min == 0.0)
            assert lo_ok and p.contains(s.soft_max), (model, s.name)
            default = s.default if s.type == "FLOAT" else s.default[0]
            assert p.contains(default) or (p.name == "m" and default == 0.0), (model, s.name)


def test_node_menus_map_to_declared_choices():
    models = node_models()
    assert {i[0].lower() for i in models.SHADOWING_ITEMS} <= set(MODELS["torrance_sparrow"]["shadowing"].choices)
    assert {i[0].lower() for i in models.WW_FORM_ITEMS} <= set(MODELS["weidlich_wilkie"]["form"].choices)
    assert [i[0] for i in models.METAL_ITEMS[1:]] == list(NAMED_METALS)
    for *_, value in models.DIELECTRIC_PRESETS[1:]:
        assert MODELS["dielectric"]["n"].contains(value)


# ------------------------------------------------------------------------------------------ with bpy

@pytest.mark.blender
def test_a_saved_node_without_a_newer_input_exports_its_default_and_gains_the_input():
    pytest.importorskip("bpy")
    from tests.blender_support import empty_scene, load_addon, polar_material
    addon = load_addon()
    from polar_render.polar_addon.export.materials import export_material
    from polar_render.polar_addon.nodes.bsdf import ensure_group
    empty_scene()
    sockets = addon.polar_addon.nodes.models.MODEL_SOCKETS["TORRANCE_SPARROW"]
    mat = polar_material("Old", "TORRANCE_SPARROW", Roughness=0.2)
    node = mat.node_tree.nodes["Polarising BSDF"]
    group = node.node_tree
    # As if the file had been saved before the last declared input existed.
    newest = sockets[-1][0]
    group.interface.remove(next(i for i in group.interface.items_tree if i.name == newest))
    assert newest not in node.inputs
    bsdf, _ = export_material(mat, [])
    assert bsdf.name == "torrance_sparrow" and bsdf.m == pytest.approx(0.2)
    ensure_group("TORRANCE_SPARROW")
    assert [s.name for s in node.inputs] == [s[0] for s in sockets]


@pytest.mark.blender
def test_torrance_sparrow_node_exports_its_exterior_index():
    pytest.importorskip("bpy")
    from tests.blender_support import empty_scene, load_addon, polar_material
    load_addon()
    from polar_render.polar_addon.export.materials import export_material
    empty_scene()
    for roughness in (0.2, 0.0):    # the rough model and its smooth limit
        mat = polar_material("Under water", "TORRANCE_SPARROW", metal="Au", Roughness=roughness,
                             **{"Exterior IOR": 1.33})
        bsdf, _ = export_material(mat, [])
        assert bsdf.exterior_n == pytest.approx(1.33) and bsdf.m == pytest.approx(roughness)
