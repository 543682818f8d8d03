"""Compile every kernel into the on-disk cache before the first render: ``python -m engine precompile``.

Numba compiles a kernel on its first call (for the argument types of that call) and caches the machine
code on disk (engine.kernels.cache_dir); a render that finds the cache empty spends tens of seconds
compiling, once.  This module renders a few tiny built-in scenes that between them touch every
material model (plain, textured, normal- and bump-mapped, mixed, layered, with an absorbing interior),
every kind of light (lamps, emissive and textured emissive meshes, non-occluding ones, a uniform environment, an image
environment, the polarised sky, polarised sources), cut-outs and holdouts, and every transport
(polarisation full / linear / off, spectral / RGB / mono, the spectral reductions, both samplers,
denoising data, adaptive sampling): each compiles what it calls, or loads it from the cache.  When
all of them rendered, it writes a marker into the cache folder (:func:`precompiled`), keyed by the
engine's sources (their time stamps and sizes, which is what Numba checks its cache against):
running it again then returns at once.

The Makefile's install step runs it, and the Blender extension runs it in a background process when
it is enabled (polar_addon.kernel_cache).  Each case is independent: one that fails is reported and
the others still run (the marker is then not written, so the next run tries again).
"""

from __future__ import annotations

import argparse
import json
import os
import struct
import sys
import tempfile
import time
import zlib

from .. import kernels

from .kernel_marker import ENGINE_DIR, MARKER, marker_path, precompiled, sources_stamp  # noqa: F401 (re-exported)

#: Size of the cases' images (pixels): every object of a case covers a few pixels.
WIDTH, HEIGHT = 48, 32


# ---------------------------------------------------------------- the cases' inputs


def _png16(path: str, rgb) -> None:
    """A 16-bit RGB PNG (decoded by the engine's own reader, engine.textures.image)."""
    import numpy as np
    data = (np.clip(np.asarray(rgb, float), 0, 1) * 65535).round().astype(">u2")
    h, w = data.shape[:2]
    raw = b"".join(b"\0" + data[j].tobytes() for j in range(h))

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
    with open(path, "wb") as fh:
        fh.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0))
                 + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def _hdr(path: str, rgb) -> None:
    """A Radiance .hdr (new-style run-length scanlines) of linear ``rgb`` (H, W, 3), W in [8, 127]."""
    import numpy as np
    rgb = np.asarray(rgb, float)
    h, w = rgb.shape[:2]
    peak = np.maximum(rgb.max(axis=2), 1e-30)
    e = np.ceil(np.log2(peak)).astype(int)
    mant = np.clip((rgb / np.ldexp(1.0, e)[..., None] * 256).astype(int), 0, 255)
    rgbe = np.concatenate([mant, (e + 128)[..., None]], axis=2).astype(np.uint8)
    out = bytearray(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {h} +X {w}\n".encode())
    for j in range(h):
        out += bytes([2, 2, w >> 8, w & 255])
        for c in range(4):
            out += bytes([w]) + rgbe[j, :, c].tobytes()        # one literal run per channel
    with open(path, "wb") as fh:
        fh.write(bytes(out))


def _textures(folder: str) -> dict:
    """Small texture files in ``folder``: {name: file name}."""
    import numpy as np
    v, u = np.mgrid[0:8, 0:8] / 7.0
    _png16(os.path.join(folder, "colour.png"), np.stack([u, v, 1 - u * v], axis=2) * 0.8 + 0.1)
    _png16(os.path.join(folder, "grey.png"), np.repeat((0.2 + 0.6 * u * v)[..., None], 3, axis=2))
    _png16(os.path.join(folder, "normal.png"), np.stack([0.5 + 0.2 * (u - 0.5), 0.5 + 0.2 * (v - 0.5),
                                                         np.full_like(u, 0.95)], axis=2))
    _hdr(os.path.join(folder, "sky.hdr"), np.stack([0.5 + u, 0.6 + v, np.full_like(u, 1.2)], axis=2))
    return {"colour": "colour.png", "grey": "grey.png", "normal": "normal.png", "sky": "sky.hdr"}


#: Every model with untextured parameters (one tile or ball each).
PLAIN_MATERIALS = {
    "lambert": {"type": "lambert", "albedo": [0.8, 0.5, 0.3]},
    "lambert_grey": {"type": "lambert", "albedo": 0.5},
    "oren_nayar": {"type": "oren_nayar", "albedo": 0.6, "roughness": 0.5},
    "gold": {"type": "conductor", "metal": "Au"},
    "nk_metal": {"type": "conductor", "n": 0.2, "k": 3.0, "thin_film_thickness": 300.0},
    "gold_film": {"type": "conductor", "metal": "Au", "thin_film_thickness": 250.0},
    "glass": {"type": "dielectric", "n": 1.5},
    "cycles_glass": {"type": "dielectric", "n": 1.45, "radiance_scaling": False},     # Blender's: 1/η² taken back
    "green_glass": {"type": "dielectric", "n": 1.5, "interior": {"color": [0.2, 0.8, 0.3], "density": 2.0}},
    "black_glass": {"type": "black_glass", "n": 1.5},
    "ts_beckmann": {"type": "torrance_sparrow", "metal": "Cu", "m": 0.3},
    "ts_ggx": {"type": "torrance_sparrow", "n": 1.5, "m": 0.2, "distribution": "ggx", "diffuse_albedo": 0.5,
               "diffuse_weight": 0.5, "multiscatter": True},
    "htsg": {"type": "htsg", "metal": "Al", "sigma0_um": 0.2, "tau_um": 3.0},
    "coated": {"type": "weidlich_wilkie", "coats": [{"n": 1.5, "distribution": "beckmann", "m": 0.2}],
               "base": {"type": "lambert", "albedo": [0.7, 0.1, 0.1]}},
    "polariser": {"type": "polariser", "axis": [1, 0, 0]},
    "retarder": {"type": "retarder", "axis": [1, 0, 0], "retardance_deg": 90.0},
    "rough_glass": {"type": "rough_dielectric", "n": 1.5, "alpha": 0.2},
    "rough_glass_ggx": {"type": "rough_dielectric", "n": 1.33, "alpha": 0.3, "distribution": "ggx"},
    "thin_glass": {"type": "thin_dielectric", "n": 1.5},
    "thin_film": {"type": "thin_film", "n": 1.5, "film_n": 1.33, "thickness": 500.0},
    "mix": {"type": "mix", "materials": ["gold", {"type": "lambert", "albedo": 0.3}], "weights": [0.5, 0.5]},
    # (the mixtures' compiled sum, engine.kernels.mueller_sum, per count of terms: 1, 3 and 4 here, 2 above)
    "mix_one": {"type": "mix", "materials": [{"type": "torrance_sparrow", "metal": "Au", "m": 0.3}], "weights": [0.8]},
    "mix_three": {"type": "mix", "materials": [{"type": "torrance_sparrow", "metal": m, "m": 0.3}
                                               for m in ("Au", "Ag", "Cu")], "weights": [0.3, 0.3, 0.3]},
    "mix_four": {"type": "mix", "materials": [{"type": "torrance_sparrow", "metal": m, "m": 0.2} for m in ("Au", "Al")]
                 + [{"type": "torrance_sparrow", "n": 1.5, "m": 0.4}, {"type": "lambert", "albedo": 0.4}],
                 "weights": [0.25, 0.25, 0.25, 0.25]},
    "principled": {"type": "principled", "base_color": [0.8, 0.4, 0.2], "roughness": 0.4},
    "principled_metal": {"type": "principled", "metallic": 1.0, "roughness": 0.2, "anisotropic": 0.5},
    "principled_glass": {"type": "principled", "transmission": 1.0, "roughness": 0.1},
    "principled_layers": {"type": "principled", "coat_weight": 1.0, "sheen_weight": 1.0,
                          "thin_film_thickness": 300.0, "diffuse_roughness": 0.5},
    "sheen": {"type": "sheen", "roughness": 0.5},
}

#: Balls (closed volumes: refraction, interiors) among PLAIN_MATERIALS; the others are tiles.
BALLS = ("glass", "green_glass", "rough_glass", "principled_glass")


def _textured_materials(tex: dict) -> dict:
    def image(name, **extra):
        return {"texture": tex[name], **extra}
    return {
        "t_lambert": {"type": "lambert", "albedo": image("colour"), "normal_map": image("normal", strength=1.0)},
        "t_principled": {"type": "principled", "base_color": image("colour", interpolation="Cubic"),
                         "roughness": image("grey", color_space="Non-Color", channel="R"),
                         "metallic": image("grey", color_space="Non-Color", channel="G"),
                         "normal_map": image("normal", color_space="Non-Color")},
        "t_principled_glass": {"type": "principled", "transmission": 1.0,
                               "roughness": image("grey", color_space="Non-Color"),
                               "bump_map": image("grey", color_space="Non-Color", distance=0.02)},
        "t_ts": {"type": "torrance_sparrow", "metal": "Au",
                 "m": image("grey", color_space="Non-Color", scale=0.4, offset=0.05),
                 "bump_map": image("grey", color_space="Non-Color", distance=0.02)},
        "t_oren_nayar": {"type": "oren_nayar", "albedo": {"vertex_color": "Col"}, "two_sided": True},
        "t_mix": {"type": "mix", "materials": ["t_lambert", {"type": "conductor", "metal": "Ag"}],
                  "weights": [0.5, 0.5]},
    }


def _row(names, z, y=6.0, span=7.0, size=0.45, balls=()):
    """Objects of a row of tiles (quads tilted towards the camera) and balls, one per material."""
    objects = []
    n = len(names)
    for i, name in enumerate(names):
        x = -span / 2 + span * (i + 0.5) / n
        if name in balls:
            objects.append({"name": name, "shape": "sphere", "center": [x, y, z], "radius": size,
                            "subdivisions": 2, "material": name})
            continue
        s = size
        objects.append({"name": name, "shape": "quad", "material": name,
                        "vertices": [[x - s, y + 0.3 * s, z - s], [x + s, y - 0.3 * s, z - s],
                                     [x + s, y + 0.3 * s, z + s], [x - s, y - 0.3 * s, z + s]]})
    return objects


def _scene(materials, objects, lights, spp=2, max_depth=6):
    return {"format": "polar-scene/1",
            "camera": {"origin": [0, -4, 0.5], "target": [0, 6, 0.5], "up": [0, 0, 1], "fov_deg": 70,
                       "width": WIDTH, "height": HEIGHT},
            "render": {"spp": spp, "max_depth": max_depth, "rr_depth": 2, "seed": 1},
            "materials": materials, "objects": objects, "lights": lights}


def _disk(name, centre, radius, sides=16):
    """A one-sided emissive disk facing down (a fan of triangles: Blender's disk lamp as exported)."""
    import math
    turns = [2 * math.pi * i / sides for i in range(sides)]
    ring = [[centre[0] + radius * math.cos(t), centre[1] - radius * math.sin(t), centre[2]] for t in turns]
    return {"name": name, "shape": "triangles", "material": "lambert", "vertices": [list(centre)] + ring,
            "faces": [[0, 1 + i, 1 + (i + 1) % sides] for i in range(sides)], "emission": {"radiance": 5}}


def _floor(material="floor"):
    return {"name": "floor", "shape": "quad", "material": material,
            "vertices": [[-20, -20, -2], [20, -20, -2], [20, 20, -2], [-20, 20, -2]]}


LAMPS = [
    {"type": "point", "position": [2, 0, 4], "intensity": 20, "radius": 0.1},
    {"type": "spot", "position": [-2, 0, 4], "target": [0, 6, 0], "intensity": 30, "cone_angle_deg": 50,
     "blend": 0.2},
    {"type": "directional", "direction": [0.3, 0.6, -0.7], "irradiance": 2, "angle_deg": 2.0},
]


def scenes(folder: str) -> dict:
    """{name: scene JSON object} of the cases; texture files are written into ``folder``."""
    tex = _textures(folder)
    names = list(PLAIN_MATERIALS)
    half = (len(names) + 1) // 2
    plain_objects = (_row(names[:half], 1.4, balls=BALLS) + _row(names[half:], -0.4, balls=BALLS)
                     + [_floor("lambert"),
                        {"name": "lamp", "shape": "quad", "material": "lambert",
                         "vertices": [[-1, 3, 3], [1, 3, 3], [1, 5, 3], [-1, 5, 3]],
                         "emission": {"radiance": 4, "color": [1, 0.9, 0.8]}},
                        _disk("disk", [3, 3, 2.5], 0.5),
                        {"name": "panel", "shape": "quad", "material": "lambert",
                         "vertices": [[-3, 3, 2.5], [-2, 3, 2.5], [-2, 4, 2.5], [-3, 4, 2.5]],
                         "emission": {"radiance": 3, "spread_deg": 60}},
                        {"name": "bulb", "shape": "quad", "material": "lambert",      # a lamp rays pass through
                         "vertices": [[1.5, 3, 2.8], [2.5, 3, 2.8], [2.5, 4, 2.8], [1.5, 4, 2.8]],
                         "emission": {"radiance": 2, "occluder": False}},
                        {"name": "shard", "shape": "triangles", "material": "lambert",      # sampled by area
                         "vertices": [[2, 4, 3], [3, 4, 3], [2.5, 5, 3]], "faces": [[0, 1, 2]],
                         "emission": {"radiance": 2}},
                        {"name": "veil", "shape": "quad", "material": "lambert", "alpha": 0.4,
                         "vertices": [[2.5, 1, -1.5], [3.5, 1, -1.5], [3.5, 1, -0.5], [2.5, 1, -0.5]]},
                        {"name": "hole", "shape": "quad", "material": "lambert", "holdout": True,
                         "vertices": [[-3.5, 1, -1.5], [-2.5, 1, -1.5], [-2.5, 1, -0.5], [-3.5, 1, -0.5]]}])
    plain = _scene(PLAIN_MATERIALS, plain_objects, [{"type": "environment", "radiance": 0.5}] + LAMPS)

    textured_materials = {**_textured_materials(tex), "floor": {"type": "lambert", "albedo": 0.5}}
    tnames = [n for n in textured_materials if n != "floor"]
    tobjects = [o for o in _row(tnames, 0.5) if o["name"] != "t_oren_nayar"]
    tobjects.append({"name": "t_oren_nayar", "shape": "triangles", "material": "t_oren_nayar",
                     "vertices": [[-0.4, 2, -1.4], [0.4, 2, -1.4], [0, 2, -0.6]], "faces": [[0, 1, 2]],
                     "uv": [[0, 0], [1, 0], [0.5, 1]],
                     "colors": {"Col": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}})
    tobjects += [_floor(),
                 {"name": "screen", "shape": "quad", "material": "floor",
                  "vertices": [[-3, 4, -1.5], [-2, 4, -1.5], [-2, 4, -0.5], [-3, 4, -0.5]],
                  "emission": {"radiance": 2, "color": {"texture": tex["colour"]}, "sampling": "luminance"}},
                 {"name": "leaf", "shape": "quad", "material": "floor",
                  "alpha": {"texture": tex["grey"], "color_space": "Non-Color"},
                  "vertices": [[2, 2, -1.5], [3, 2, -1.5], [3, 2, -0.5], [2, 2, -0.5]]}]
    textured = _scene(textured_materials, tobjects,
                      [{"type": "environment", "image": tex["sky"], "strength": 1.0}] + LAMPS[:1])

    pol = {"type": "linear", "degree": 1, "angle": 45, "axis": [1, 0, 0]}
    sky_objects = _row(["gold", "glass", "lambert"], 0.5, balls=("glass",)) + [
        _floor("black_glass"),
        {"name": "screen", "shape": "quad", "material": "lambert",
         "vertices": [[-3, 4, -1.5], [-2, 4, -1.5], [-2, 4, -0.5], [-3, 4, -0.5]],
         "emission": {"radiance": 2, "polarisation": {"type": "circular", "degree": 0.8, "handedness": "left"}}}]
    sky = _scene({k: PLAIN_MATERIALS[k] for k in ("gold", "glass", "lambert", "black_glass")}, sky_objects,
                 [{"type": "sky", "sun_direction": [0.6, 0.3, 0.74], "turbidity": 2.5, "strength": 1},
                  {"type": "directional", "direction": [-0.6, -0.3, -0.74], "irradiance": 3, "angle_deg": 0.545,
                   "polarisation": pol},
                  {"type": "point", "position": [0, 2, 3], "intensity": 10, "polarisation": pol},
                  {"type": "spot", "position": [1, 2, 3], "target": [0, 6, 0], "intensity": 10,
                   "polarisation": pol}])

    # no material depends on the wavelength: the spectral reductions (RGB with exact light colours, exact)
    # (a rough conductor alone in its group, no cut-outs: its next-event estimation's compiled steps,
    # engine.kernels.glossy_light)
    grey = _scene({"chalk": {"type": "lambert", "albedo": [0.8, 0.7, 0.6]}, "glass": {"type": "dielectric", "n": 1.5},
                   "mirror": {"type": "conductor", "n": 0.2, "k": 3.0},
                   "blue": {"type": "lambert", "albedo": [0.2, 0.3, 0.7]},
                   "rough_metal": {"type": "torrance_sparrow", "n": 0.2, "k": 3.0, "m": 0.3}},
                  _row(["chalk", "glass", "mirror", "blue", "rough_metal"], 0.5, balls=("glass",)) + [_floor("chalk")],
                  [{"type": "environment", "radiance": 1.0}] + LAMPS)
    return {"plain": plain, "textured": textured, "sky": sky, "grey": grey}


#: (scene, what it covers, RenderSettings overrides, adaptive): every transport the engine has (the
#: scene's defaults: the default sampler, polarisation "auto", spectral).
CASES = (
    ("plain", "every material, lamps, emitters, cut-outs; full Stokes, spectral", {}, False),
    ("plain", "linear Stokes, RGB, independent sampler", {"polarisation": "linear", "spectral": "rgb",
                                                          "sampler": "independent"}, False),
    ("plain", "scalar transport, one wavelength, stratified sampler", {"polarisation": "off", "spectral": "mono",
                                                                        "sampler": "stratified"}, False),
    ("plain", "full Stokes, RGB, denoising data", {"polarisation": "full", "spectral": "rgb",
                                                   "denoise_data": True}, False),
    ("plain", "adaptive sampling", {"spp": 4}, True),
    ("plain", "lights chosen by power (Blender scenes with Light Tree on and few emitters)",
     {"light_selection": "power"}, False),
    ("textured", "lights chosen as Cycles without its tree (Blender scenes with Light Tree off)",
     {"light_selection": "cycles", "light_tree": "off"}, False),
    ("plain", "lights chosen by the light tree (Blender's Light Tree on, many emitters)", {"light_tree": "on"}, False),
    ("textured", "textures, normal and bump maps, vertex colours, image environment; spectral", {}, False),
    ("textured", "textures in RGB, linear Stokes", {"spectral": "rgb", "polarisation": "linear"}, False),
    ("textured", "textures, scalar transport, denoising data", {"polarisation": "off", "denoise_data": True}, False),
    ("sky", "the polarised sky, polarised lamps and emitters", {}, False),
    ("sky", "the sky in RGB", {"spectral": "rgb", "polarisation": "linear"}, False),
    ("grey", "spectral reduction: RGB with exact light colours", {}, False),
    ("grey", "spectral reduction: exact", {"reduce_spectral": "exact"}, False),
    ("grey", "no reduction, independent sampler", {"reduce_spectral": "off", "sampler": "independent"}, False),
    ("grey", "scalar, RGB", {"polarisation": "off", "spectral": "rgb"}, False),
)


def run_case(scene, overrides: dict, adaptive: bool, threads: int = 0):
    """Render ``scene`` (an engine Scene) with ``overrides`` of its settings: its kernels are compiled now."""
    import dataclasses

    from .adaptive import AdaptiveSettings
    from .renderer import Renderer, RenderRequest
    overrides = dict(overrides)
    if "light_selection" in overrides:          # (a Scene field: the Blender exporter sets it)
        scene = dataclasses.replace(scene, light_selection=overrides.pop("light_selection"))
    settings = dataclasses.replace(scene.settings, threads=threads, **overrides)
    renderer = Renderer(scene)
    request = RenderRequest(settings, adaptive=AdaptiveSettings(threshold=1.0, min_spp=2) if adaptive else None)
    return renderer.render(request)


def precompile(force: bool = False, out=sys.stderr, threads: int = 0, verbose: bool = False) -> int:
    """Render every case (see the module docstring), reporting on ``out``; 0 when all rendered (or
    nothing was to do), 1 when a case failed."""
    def say(text):
        print(f"polar: {text}", file=out, flush=True)

    if not kernels.uses_cache():
        say(f"kernels: {kernels.BACKEND} (numba not in use): nothing to compile")
        return 0
    folder = kernels.cache_dir()
    if not force and precompiled():
        say(f"kernels already compiled ({folder})")
        return 0
    from ..scene.loader import parse_scene
    say(f"compiling every kernel into {folder} (a minute or two the first time; cached ones load)…")
    t0 = time.perf_counter()
    failed = []
    with tempfile.TemporaryDirectory(prefix="polar-precompile-") as tmp:
        data = scenes(tmp)
        parsed = {}
        for i, (name, what, overrides, adaptive) in enumerate(CASES, 1):
            before = kernels.COMPILES.snapshot()
            t = time.perf_counter()
            # the line is finished when the case is (a log's last line then names the case running)
            print(f"polar:   [{i}/{len(CASES)}] {name}: {what}: ", end="", file=out, flush=True)
            try:
                if name not in parsed:
                    parsed[name] = parse_scene(data[name], base_dir=tmp, source=f"precompile:{name}")
                run_case(parsed[name], overrides, adaptive, threads)
            except Exception as e:      # noqa: BLE001 — the other cases still fill the cache
                failed.append(name)
                print(f"FAILED: {type(e).__name__}: {e}", file=out, flush=True)
                continue
            count = kernels.COMPILES.snapshot()[0] - before[0]
            print(f"{count} compiled, {time.perf_counter() - t:.1f} s", file=out, flush=True)
    total = time.perf_counter() - t0
    count = kernels.COMPILES.compiled
    if failed:
        say(f"kernels: {count} compiled in {total:.1f} s; {len(failed)} case(s) failed (see above): "
            "the first renders that need them compile them")
        return 1
    marker = {"stamp": sources_stamp(), "backend": kernels.BACKEND, "compiled": count, "seconds": round(total, 1),
              "when": time.strftime("%Y-%m-%d %H:%M:%S")}
    os.makedirs(folder, exist_ok=True)
    tmp_marker = marker_path() + f".{os.getpid()}.tmp"
    with open(tmp_marker, "w", encoding="utf-8") as fh:
        json.dump(marker, fh)
    os.replace(tmp_marker, marker_path())
    say(f"kernels ready: {count} compiled ({len(kernels.DISPATCHERS)} kernels, the rest loaded from the cache) "
        f"in {total:.1f} s")
    if verbose:     # (a helper compiled into its callers shows up only when the cache was empty)
        idle = sorted(f"{d.py_func.__module__}.{d.py_func.__name__}" for d in kernels.DISPATCHERS if not d.signatures)
        say(f"kernels no case called or compiled ({len(idle)}): {', '.join(idle) or 'none'}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m engine precompile", description=__doc__.split("\n\n")[0])
    ap.add_argument("--force", action="store_true", help="render every case even if the cache is marked complete")
    ap.add_argument("--threads", type=int, default=0, help="worker threads of the cases' renders (0: one per core)")
    ap.add_argument("-v", "--verbose", action="store_true", help="also list the kernels no case called")
    args = ap.parse_args(argv)
    return precompile(force=args.force, threads=args.threads, verbose=args.verbose)


if __name__ == "__main__":
    sys.exit(main())
