"""Cycles' data passes and Cryptomatte in Polar's render result (engine side: engine.render.data_passes).

The render engine asks this module three things:

- ``register_data_passes(engine, scene, view_layer)`` (from ``update_render_passes``): the passes the view
  layer enables (View Layer ▸ Passes ▸ Data: Z, Mist, Position, Normal, Vector, UV, Object Index, Material
  Index; Cryptomatte Object / Material / Asset with its Levels), registered with Cycles' names and channel
  layouts ("Depth" Z, "Normal" XYZ, "Vector" XYZW, "UV" UVA, "CryptoObject00" rgba, …), so the compositor's
  Render Layers and Cryptomatte nodes see what they see from a Cycles render;
- ``data_pass_request(view_layer, scene)`` before the export (None when nothing is enabled: no cost), and
  ``exporting(request)`` around ``export_scene`` (meshes then carry their UV map when the UV pass is on);
  ``add_motion(engine, depsgraph, camera_object, width, height, engine_scene, request)`` after it, which
  exports the previous and next frames' geometry and camera for the Vector pass (as Cycles does with motion
  blur off), only when Vector is enabled;
- ``write_data_passes(engine, result, renderer, request, settings, window)`` after the render: traces the
  passes (the render's own camera rays) and writes them, with the Cryptomatte manifests as the render
  result's metadata ("cryptomatte/<id>/name|hash|conversion|manifest", layer "<ViewLayer>.CryptoObject").
"""

import contextlib
import dataclasses

import numpy as np

from ..engine.output.cryptomatte import pass_count
from ..engine.render.data_passes import (CRYPTOMATTE_PASSES, DATA_PASSES, DataPassRequest, Mist, Motion,
                                         render_data_passes)
from ..engine.render.light_passes import LIGHT_PASSES, render_light_passes, stokes_pass_names
from .export import geometry

#: View layer property → engine pass name (engine.render.data_passes.ALL_PASSES)
VIEW_LAYER_PASSES = (("use_pass_z", "depth"), ("use_pass_mist", "mist"), ("use_pass_position", "position"),
                     ("use_pass_normal", "normal"), ("use_pass_vector", "vector"), ("use_pass_uv", "uv"),
                     ("use_pass_object_index", "object_index"), ("use_pass_material_index", "material_index"),
                     ("use_pass_cryptomatte_object", "crypto_object"),
                     ("use_pass_cryptomatte_material", "crypto_material"),
                     ("use_pass_cryptomatte_asset", "crypto_asset"))
#: View layer property (Cycles' Light passes; "cycles.": on view_layer.cycles) → engine light pass
#: (engine.render.light_passes.LIGHT_PASSES)
VIEW_LAYER_LIGHT_PASSES = tuple((f"use_pass_{key}", key) for key in (
    "diffuse_direct", "diffuse_indirect", "diffuse_color", "glossy_direct", "glossy_indirect", "glossy_color",
    "transmission_direct", "transmission_indirect", "transmission_color")) + (
    ("cycles.use_pass_volume_direct", "volume_direct"), ("cycles.use_pass_volume_indirect", "volume_indirect"),
    ("use_pass_emit", "emission"), ("use_pass_environment", "environment"))
#: Cycles' pass types (list_render_passes in Cycles' engine.py)
PASS_TYPES = {"Depth": "VALUE", "Mist": "VALUE", "Position": "VECTOR", "Normal": "VECTOR", "Vector": "VECTOR",
              "UV": "VECTOR", "Object Index": "VALUE", "Material Index": "VALUE"}
#: World ▸ Mist Pass ▸ Falloff → engine.render.data_passes.MIST_FALLOFF
MIST_FALLOFF = {"QUADRATIC": "quadratic", "LINEAR": "linear", "INVERSE_QUADRATIC": "inverse_quadratic"}


def enabled_passes(view_layer) -> frozenset:
    """The engine names of the data and Cryptomatte passes ``view_layer`` enables."""
    return frozenset(name for prop, name in VIEW_LAYER_PASSES if getattr(view_layer, prop, False))


def levels(view_layer) -> int:
    """The view layer's Cryptomatte Levels, as Cycles clamps them (2 … 16)."""
    return min(16, max(2, int(getattr(view_layer, "pass_cryptomatte_depth", 6))))


def pass_layout(view_layer) -> list:
    """[(pass name, channel ids, pass type)] of the enabled passes, in Cycles' order."""
    enabled = enabled_passes(view_layer)
    out = [(name, channels, PASS_TYPES[name]) for key, (name, channels) in DATA_PASSES.items() if key in enabled]
    for key, kind in CRYPTOMATTE_PASSES.items():
        if key in enabled:
            layer = {"object": "CryptoObject", "material": "CryptoMaterial", "asset": "CryptoAsset"}[kind]
            out += [(f"{layer}{i:02d}", "rgba", "COLOR") for i in range(pass_count(levels(view_layer)))]
    return out


def light_pass_keys(view_layer) -> tuple:
    """The engine keys of the light passes ``view_layer`` enables (View Layer ▸ Passes ▸ Light), Cycles' order."""
    def enabled(prop):
        owner, _, name = prop.rpartition(".")
        return getattr(getattr(view_layer, owner, None) if owner else view_layer, name, False)
    return tuple(key for prop, key in VIEW_LAYER_LIGHT_PASSES if enabled(prop))


def register_data_passes(engine, scene, view_layer) -> None:
    """Register the enabled data, Cryptomatte and light passes (``RenderEngine.update_render_passes``); a light
    pass as Cycles' RGB pass (S0) and, but for the Color passes, its Stokes components "<pass>_S1" … "_S3"."""
    for name, channels, kind in pass_layout(view_layer):
        engine.register_pass(scene, view_layer, name, len(channels), channels, kind)
    for key in light_pass_keys(view_layer):
        for name in stokes_pass_names(LIGHT_PASSES[key]):
            engine.register_pass(scene, view_layer, name, 3, "RGB", "COLOR")


def write_light_passes(engine, result, renderer, keys: tuple, settings, window=None):
    """Trace the light passes (engine.render.light_passes) of ``renderer`` with ``settings`` over ``window`` and
    write the passes ``keys`` into ``result``'s first layer; returns the engine's LightPasses (None without keys)."""
    if not keys:
        return None
    light = render_light_passes(renderer, settings, window)
    passes = result.layers[0].passes
    for name, img in light.images(keys).items():
        target = passes.get(name)
        if target is not None:
            target.rect.foreach_set(_blender_rows(img))
    return light


def data_pass_request(view_layer, scene) -> DataPassRequest | None:
    """The engine request of the passes ``view_layer`` enables, with the World's mist, the layer's
    Cryptomatte Levels and Alpha Threshold; None when none is enabled."""
    passes = enabled_passes(view_layer)
    if not passes:
        return None
    mist = Mist()
    world = getattr(scene, "world", None)
    settings = getattr(world, "mist_settings", None) if world is not None else None
    if settings is not None:
        mist = Mist(max(0.0, float(settings.start)), max(0.0, float(settings.depth)),
                    MIST_FALLOFF.get(settings.falloff, "quadratic"))
    threshold = min(1.0, max(0.0, float(getattr(view_layer, "pass_alpha_threshold", 0.5))))
    return DataPassRequest(passes, cryptomatte_levels=levels(view_layer), mist=mist, alpha_threshold=threshold)


@contextlib.contextmanager
def exporting(request):
    """Around ``export_scene``: meshes carry their active render UV map when ``request`` has the UV pass."""
    token = geometry.PASS_UV.set(request is not None and "uv" in request.passes)
    try:
        yield
    finally:
        geometry.PASS_UV.reset(token)


def _geometry_only(material, warnings, bake=None):
    from ..engine.materials.lambert import Lambert
    from ..engine.spectral import ConstantSpectrum
    return Lambert(ConstantSpectrum(0.5)), None, 1.0


def _frame_geometry(depsgraph, camera_object, width, height):
    """(camera, meshes) of the depsgraph's current frame: its geometry only (no materials, world)."""
    from ..engine.scene.description import RenderSettings
    from .export.camera import export_camera
    from .export.scene import SceneWalk
    camera = export_camera(depsgraph.scene, camera_object.evaluated_get(depsgraph), width, height, [])
    walk = SceneWalk(bake_resolution=None, material_entry=_geometry_only, export_world=lambda world, warnings: None)
    return camera, walk.sync(depsgraph, None, RenderSettings(), camera=camera).scene.meshes


def _match(meshes, others) -> tuple:
    """Per mesh of ``meshes``, the vertices of the same mesh in ``others`` (the k-th of its name; None where it is
    missing or its vertex count differs: no motion)."""
    by_name = {}
    for m in others:
        by_name.setdefault(m.name, []).append(m)
    seen = {}
    out = []
    for m in meshes:
        k = seen.get(m.name, 0)
        seen[m.name] = k + 1
        candidates = by_name.get(m.name, [])
        other = candidates[k] if k < len(candidates) else None
        ok = other is not None and np.shape(other.vertices) == np.shape(m.vertices)
        out.append(np.asarray(other.vertices, np.float64) if ok else None)
    return tuple(out)


def add_motion(engine, depsgraph, camera_object, width, height, engine_scene, request):
    """``request`` with the Vector pass's Motion: the previous and next frames' camera and mesh positions
    (``engine.frame_set``, as Cycles' motion sync; the frame is restored); ``request`` unchanged without Vector."""
    if request is None or "vector" not in request.passes:
        return request
    scene = depsgraph.scene
    frame, subframe = scene.frame_current, scene.frame_subframe
    views = {}
    try:
        for which, f in (("pre", frame - 1), ("post", frame + 1)):
            engine.frame_set(f, 0.0)
            views[which] = _frame_geometry(depsgraph, camera_object, width, height)
    finally:
        engine.frame_set(frame, subframe)
    motion = Motion(camera_pre=views["pre"][0], camera_post=views["post"][0],
                    positions_pre=_match(engine_scene.meshes, views["pre"][1]),
                    positions_post=_match(engine_scene.meshes, views["post"][1]))
    return dataclasses.replace(request, motion=motion)


def _blender_rows(img):
    """(H, W[, C]) with row 0 at the top → the flat float32 array ``rect.foreach_set`` takes (bottom row first)."""
    return np.ascontiguousarray(img[::-1], dtype=np.float32).ravel()


def write_data_passes(engine, result, renderer, request, settings, window=None):
    """Trace the passes of ``request`` (engine.render.data_passes) for ``renderer`` with ``settings`` over
    ``window`` and write them into ``result``'s first layer, with the Cryptomatte manifests as metadata.
    Returns the engine's DataPasses (None when ``request`` is None)."""
    if request is None:
        return None
    data = render_data_passes(renderer, request, settings, window)
    layer = result.layers[0]
    passes = layer.passes
    for name, img in data.images.items():
        target = passes.get(name)
        if target is not None:
            target.rect.foreach_set(_blender_rows(img))
    for name, plist in data.cryptomatte.items():
        for k, img in enumerate(plist):
            target = passes.get(f"{name}{k:02d}")
            if target is not None:
                target.rect.foreach_set(_blender_rows(img))
    # on the engine's whole render result, as Cycles (a partial result's stamp data is not kept)
    full = engine.get_result() if hasattr(engine, "get_result") else None
    for key, value in data.metadata(prefix=layer.name + ".").items():
        (full if full is not None else result).stamp_data_add_field(key, value)
    return data
