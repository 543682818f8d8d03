"""The renderer-neutral peer scene format (shared/peers/README.md) → engine format.

Peer scenes describe one light (``light``), quads and PLY meshes placed by
``translate`` + uniform ``scale``, Mitsuba-style materials and the path
integrator's ``max_depth``/``rr_depth`` (max_depth counts path segments, as
ours does).  The conversion is purely structural; the engine loader then
validates the result like any scene file, so errors still name fields.
"""

from __future__ import annotations

from ..errors import SceneError


def is_peer_scene(data: dict) -> bool:
    return isinstance(data, dict) and "light" in data and "objects" in data and "format" not in data


def _material(m: dict, field: str) -> dict:
    if not isinstance(m, dict) or "type" not in m:
        raise SceneError(field, "must be an object with a 'type'")
    t = m["type"]
    if t == "diffuse":
        return {"type": "lambert", "albedo": m.get("albedo_linear_srgb", [0.5, 0.5, 0.5])}
    if t == "conductor":
        if m.get("named"):
            return {"type": "conductor", "metal": m["named"]}
        return {"type": "conductor", "n": m.get("n"), "k": m.get("k", 0.0)}
    if t == "black_glass":
        return {"type": "black_glass", "n": m.get("n", 1.5)}
    if t == "dielectric":
        return {"type": "dielectric", "n": m.get("n", 1.5), "exterior_n": m.get("exterior_n", 1.0)}
    if t == "rough_conductor":
        if m.get("distribution", "beckmann") != "beckmann":
            raise SceneError(f"{field}.distribution", "only 'beckmann' is supported")
        # Mitsuba's roughconductor: Beckmann with α = m and Smith G with Walter's rational G1.
        return {"type": "torrance_sparrow", "n": m.get("n"), "k": m.get("k", 0.0), "m": m.get("alpha"),
                "shadowing": "smith_rational"}
    if t == "rough_dielectric":
        # Mitsuba's roughdielectric (Walter 2007): separable Smith G; Beckmann with Walter's rational G1.
        dist = m.get("distribution", "beckmann")
        if dist not in ("beckmann", "ggx"):
            raise SceneError(f"{field}.distribution", f"must be 'beckmann' or 'ggx', got {dist!r}")
        return {"type": "rough_dielectric", "n": m.get("n", 1.5), "exterior_n": m.get("exterior_n", 1.0),
                "alpha": m.get("alpha", 0.1), "distribution": dist,
                "shadowing": "smith_rational" if dist == "beckmann" else "smith"}
    raise SceneError(f"{field}.type", f"unknown peer material type {t!r} (allowed: diffuse, conductor, "
                                      "black_glass, dielectric, rough_conductor, rough_dielectric)")


def peer_to_engine(data: dict) -> dict:
    """Convert a parsed peer scene into an engine-format scene dict."""
    for key, kind in (("camera", dict), ("materials", dict), ("integrator", dict), ("objects", list)):
        if not isinstance(data.get(key, kind()), kind):
            raise SceneError(key, f"must be {'an object' if kind is dict else 'a list'}")
    cam = dict(data.get("camera", {}))
    for key in ("model", "pixel_filter"):
        allowed = {"model": "pinhole", "pixel_filter": "box"}[key]
        if cam.pop(key, allowed) != allowed:
            raise SceneError(f"camera.{key}", f"only {allowed!r} is supported")
    out = {"format": "polar-scene/1", "camera": cam,
           "materials": {name: _material(m, f"materials.{name}") for name, m in data.get("materials", {}).items()},
           "objects": [], "lights": []}

    integ = data.get("integrator", {})
    out["render"] = {"max_depth": integ.get("max_depth", 16), "rr_depth": integ.get("rr_depth", 5)}

    light = data["light"]
    if not isinstance(light, dict):
        raise SceneError("light", "must be an object")
    if light.get("type") == "constant_environment":
        out["lights"].append({"type": "environment", "radiance": light.get("radiance", 1.0)})
    elif light.get("type") == "envmap":
        # the peer format's texel grid is Mitsuba's (rows on the poles), its file relative to the scene
        if not isinstance(light.get("file"), str):
            raise SceneError("light.file", "must be the path of the environment map (EXR)")
        out["lights"].append({"type": "environment", "image": light["file"], "strength": light.get("scale", 1.0),
                              "grid": "mitsuba"})
    elif light.get("type") != "area_light":
        raise SceneError("light.type", "must be 'constant_environment', 'envmap' or 'area_light'")

    for i, obj in enumerate(data["objects"]):
        field = f"objects[{i}]"
        if not isinstance(obj, dict):
            raise SceneError(field, "must be an object")
        o = {"name": obj.get("name", field), "material": obj.get("material")}
        shape = obj.get("shape")
        if shape == "quad":
            o.update(shape="quad", vertices=obj.get("vertices"))
        elif shape == "mesh":
            o.update(shape="mesh", file=obj.get("file"))
            tr = obj.get("transform")
            if tr is not None:
                if not isinstance(tr, dict) or set(tr) - {"translate", "scale"}:
                    raise SceneError(f"{field}.transform", "peer scenes allow only 'translate' and 'scale'")
                o["transform"] = tr
        else:
            raise SceneError(f"{field}.shape", f"must be 'quad' or 'mesh', got {shape!r}")
        if obj.get("emitter") is not None:
            em = obj["emitter"]
            o["emission"] = {"radiance": em.get("radiance", 1.0) if isinstance(em, dict) else em}
        out["objects"].append(o)
    return out
