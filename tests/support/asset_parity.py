"""Real-asset parity with Cycles: third-party glTF 2.0 assets, imported by Blender's own glTF importer,
rendered by Cycles and by Polar (through the extension's exporter, as F12 does), compared per block.

Shared by tests/blender/test_real_assets.py (which asserts the rule) and tests/bench/asset_speed.py
(which measures noise × time).  Needs the ``bpy`` module.  The assets, their sources and licences are
in tests/data/assets/SOURCES.md.

One case is an asset under one lighting:

* ``lamps``: a sun (5° disc), an area light and a grey world, sized and placed from the asset's
  bounding box so that every asset gets the same irradiance whatever its scale;
* ``hdri``: the procedural sky tests/data/assets/environment/sky_sun.exr as the world (an Environment
  Texture, mapped directly by the exporter).

The camera frames the asset's bounding sphere from a fixed direction per asset (deterministic).
Cycles runs as the parity tests set it: CPU, no adaptive sampling, no denoising, clamps 0, Filter
Glossy 0, box pixel filter 1 px, light tree off, the same bounce limit for every kind of bounce as
Polar's Max Bounces.  Both renderers get the same samples per pixel and several seeds each.

**The rule** (``compare``): per 16 × 16-pixel block that the asset covers (at least a quarter of its
pixels hit the asset, from Blender's own ray cast), the luminance means m_P (Polar S0) and m_C
(Cycles) over the seeds must agree within 4 σ + 2 %: |m_P − m_C| ≤ 4 √(σ_P² + σ_C²) + 0.02 m_C, the
σ being each mean's standard error from the spread between seeds.  A case passes when at least 95 %
of its blocks do.  The report also gives the luminance ratio Polar ÷ Cycles over those blocks, the
per-channel ratios and Polar's export warnings.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

from tests.conftest import REPO

ASSETS = os.path.join(REPO, "tests", "data", "assets")
HDRI = os.path.join(ASSETS, "environment", "sky_sun.exr")
REC709 = np.array([0.2126, 0.7152, 0.0722])
LIGHTINGS = ("lamps", "hdri")

BLOCK = 16                 # pixels per block side
COVERAGE = 0.25            # a block is the asset's when at least this share of its pixels hit it
SIGMAS = 4.0               # tolerance: SIGMAS standard errors …
RELATIVE = 0.02            # … + this fraction of Cycles' block mean
TOP_SHARE = 0.01           # noise_tail: the brightest pixels' share of σ² is read over this fraction of pixels
PASS_FRACTION = 0.95       # a case passes when at least this share of its blocks does


@dataclass(frozen=True)
class Asset:
    """A glTF file under tests/data/assets and how it is framed."""
    name: str
    path: str                          # relative to tests/data/assets
    covers: str                        # the material features it exercises
    azimuth: float = 30.0              # camera direction from the asset's centre, degrees (0: Blender's −Y, front)
    elevation: float = 20.0
    zoom: float = 1.0                  # > 1 frames tighter than the bounding sphere
    size: tuple = (96, 96)             # render resolution (width, height), multiples of BLOCK

    @property
    def file(self):
        return os.path.join(ASSETS, self.path)


#: The suite.  Sizes, sources, authors and licences: tests/data/assets/SOURCES.md.
CATALOGUE = {a.name: a for a in (
    Asset("BoomBox", "BoomBox/BoomBox.glb",
          "textured metal/roughness: base colour, metallic-roughness (separated channels), tangent-space "
          "normal map, emissive map, occlusion", azimuth=0.0, elevation=15.0, zoom=1.2),
    Asset("AttenuationTest", "AttenuationTest/16_volume.gltf",
          "transmission with volume attenuation (KHR_materials_volume: Volume Absorption on the material's "
          "Volume output, thickness texture), thin double-sided transmissive quads, textured backdrop",
          azimuth=0.0, elevation=5.0, zoom=1.8),
    Asset("UnlitTest", "UnlitTest/01_unlit.gltf",
          "mixed shaders: KHR_materials_unlit → Mix Shader (Light Path ▸ Is Camera Ray) of Transparent and "
          "Emission, and a second Mix Shader with Transparent for alpha blending", azimuth=0.0, elevation=10.0),
    Asset("TextureTransform", "TextureTransform/09_texture_transform.gltf",
          "KHR_texture_transform → Mapping nodes (offset, rotation, scale) on base colour, metallic-roughness "
          "and normal textures (Closest and Linear filtering, repeat)", azimuth=0.0, elevation=60.0, zoom=1.3),
    Asset("SpecGlossEmission", "SpecGlossEmission/14_emission_strength.gltf",
          "KHR_materials_pbrSpecularGlossiness (Principled IOR 1000, Specular Tint = specular colour) beside "
          "metal/roughness, emissive factors, textures and KHR_materials_emissive_strength (Mix nodes); "
          "a row of 18 spheres, hence the wide frame", azimuth=0.0, elevation=0.0, zoom=1.05, size=(256, 48)),
    Asset("SingleVsDoubleSided", "SingleVsDoubleSided/01_single_vs_double_sided.gltf",
          "open shells seen from inside: back faces of a double-sided and of a single-sided smooth "
          "dielectric (Blender renders both sides either way)", azimuth=0.0, elevation=35.0),
    Asset("Sunglasses", "Sunglasses/SunglassesKhronos.glb",
          "product model: thin transmissive lenses (IOR 1, iridescence), transmission + volume "
          "(nose pads), glossy frames, a base colour texture", azimuth=-25.0, elevation=12.0, zoom=1.15),
)}


@dataclass
class CaseReport:
    """What one asset × lighting case measured."""
    asset: str
    lighting: str
    spp: int
    seeds: int
    width: int
    height: int
    blocks: int = 0                     # blocks of the asset compared
    passed: int = 0
    luminance_ratio: float = float("nan")          # Σ Polar ÷ Σ Cycles over the asset's blocks
    channel_ratios: tuple = (float("nan"),) * 3    # R, G, B, same blocks
    warnings: list = field(default_factory=list)
    failing: list = field(default_factory=list)    # (row, column, Polar ÷ Cycles, tolerance) per failing block
    seconds: dict = field(default_factory=dict)    # cycles, polar (render time, all seeds), export; *_each per seed
    noise: dict = field(default_factory=dict)      # per renderer: mean per-pixel S0 variance over asset pixels
    tails: dict = field(default_factory=dict)      # per renderer: noise_tail of those variances
    error: str = ""                                # the export or render error, if Polar refused the scene

    @property
    def fraction(self) -> float:
        return self.passed / self.blocks if self.blocks else float("nan")

    @property
    def ok(self) -> bool:
        return self.blocks > 0 and self.fraction >= PASS_FRACTION

    def line(self) -> str:
        if self.error:
            return f"{self.asset:20s} {self.lighting:5s} Polar refused the scene: {self.error}"
        r, g, b = self.channel_ratios
        return (f"{self.asset:20s} {self.lighting:5s} pass {self.passed:2d}/{self.blocks:2d} "
                f"({100 * self.fraction:5.1f} %) Y {self.luminance_ratio:6.3f} RGB {r:.3f} {g:.3f} {b:.3f} "
                f"| cycles {self.seconds.get('cycles', 0):5.1f} s polar {self.seconds.get('polar', 0):5.1f} s "
                f"| {len(self.warnings)} warning(s)")


# --------------------------------------------------------------------------- scene

def reset(width, height):
    import bpy
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    return scene


def import_asset(asset: Asset):
    """Import with Blender's glTF importer; the mesh objects."""
    import bpy
    bpy.ops.import_scene.gltf(filepath=asset.file)
    return [o for o in bpy.context.scene.objects if o.type == "MESH"]


def bounds(objects):
    """(centre, radius) of the world-space bounding box of the objects' evaluated meshes."""
    import bpy
    from mathutils import Vector
    depsgraph = bpy.context.evaluated_depsgraph_get()
    corners = []
    for obj in objects:
        ev = obj.evaluated_get(depsgraph)
        corners += [ev.matrix_world @ Vector(c) for c in ev.bound_box]
    P = np.array([tuple(c) for c in corners])
    lo, hi = P.min(0), P.max(0)
    centre = (lo + hi) / 2
    return centre, float(np.linalg.norm(hi - lo) / 2)


def direction(azimuth, elevation):
    """Unit vector from azimuth (degrees, 0 = −Y, 90 = +X) and elevation (degrees above the XY plane)."""
    a, e = math.radians(azimuth), math.radians(elevation)
    return np.array([math.cos(e) * math.sin(a), -math.cos(e) * math.cos(a), math.sin(e)])


def _aim(obj, target):
    from mathutils import Vector
    d = Vector(tuple(target)) - obj.location
    obj.rotation_euler = d.to_track_quat("-Z", "Y").to_euler()


def frame(scene, asset: Asset, centre, radius, lens=50.0):
    """A perspective camera looking at the bounding sphere from the asset's direction, filling the frame."""
    import bpy
    from mathutils import Vector
    data = bpy.data.cameras.new("AssetCamera")
    data.lens, data.sensor_width, data.sensor_fit = lens, 36.0, "AUTO"
    half = math.atan(data.sensor_width / 2 / lens)
    distance = radius / math.sin(half) / asset.zoom
    data.clip_start, data.clip_end = max(1e-4, (distance - radius) * 0.05), (distance + radius) * 20
    cam = bpy.data.objects.new("AssetCamera", data)
    scene.collection.objects.link(cam)
    cam.location = Vector(tuple(centre + distance * direction(asset.azimuth, asset.elevation)))
    _aim(cam, centre)
    scene.camera = cam
    return cam


def _world(scene):
    import bpy
    world = bpy.data.worlds.new("AssetWorld")
    scene.world = world
    from tests.blender_support import load_addon
    load_addon().polar_addon.compat.ensure_node_tree(world)
    return world


def light_lamps(scene, centre, radius):
    """A sun (3 W/m², 5° disc), a square area light about 3 W/m² at the asset, a grey world (0.2)."""
    import bpy
    from mathutils import Vector
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.data.angle = 3.0, math.radians(5.0)
    sun.rotation_euler = Vector(tuple(direction(-40.0, 50.0))).to_track_quat("Z", "Y").to_euler()
    scene.collection.objects.link(sun)
    d = 3.0 * radius
    area = bpy.data.objects.new("Area", bpy.data.lights.new("Area", "AREA"))
    area.data.size = radius
    area.data.energy = 3.0 * math.pi * d * d           # on-axis irradiance S/(π d²) ≈ 3 W/m²
    area.location = Vector(tuple(centre + d * direction(60.0, 30.0)))
    _aim(area, centre)
    scene.collection.objects.link(area)
    world = _world(scene)
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.2, 0.2, 0.2, 1.0)
    bg.inputs["Strength"].default_value = 1.0


def light_hdri(scene):
    """The procedural sky (tests/data/assets/environment/sky_sun.exr) as an Environment Texture world."""
    import bpy
    world = _world(scene)
    tree = world.node_tree
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.load(HDRI, check_existing=True)
    env.image.colorspace_settings.name = "Linear Rec.709"
    bg = tree.nodes["Background"]
    tree.links.new(env.outputs["Color"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = 1.0


def build(asset: Asset, lighting: str, width: int, height: int):
    """Reset, import, frame and light: the scene."""
    if lighting not in LIGHTINGS:
        raise ValueError(f"lighting must be one of {LIGHTINGS}, got {lighting!r}")
    scene = reset(width, height)
    objects = import_asset(asset)
    centre, radius = bounds(objects)
    frame(scene, asset, centre, radius)
    if lighting == "lamps":
        light_lamps(scene, centre, radius)
    else:
        light_hdri(scene)
    return scene


def coverage(scene, width, height) -> np.ndarray:
    """(H, W) bool: the camera ray through each pixel centre hits the asset (Blender's ray cast)."""
    import bpy
    from mathutils import Vector
    cam = scene.camera
    depsgraph = bpy.context.evaluated_depsgraph_get()
    frame_pts = [Vector(v) for v in cam.data.view_frame(scene=scene)]
    xs = [v.x for v in frame_pts]
    ys = [v.y for v in frame_pts]
    z = frame_pts[0].z
    M = cam.matrix_world
    origin = M.translation
    hit = np.zeros((height, width), bool)
    for i in range(height):
        y = max(ys) - (i + 0.5) / height * (max(ys) - min(ys))
        for j in range(width):
            x = min(xs) + (j + 0.5) / width * (max(xs) - min(xs))
            d = (M.to_3x3() @ Vector((x, y, z))).normalized()
            hit[i, j] = scene.ray_cast(depsgraph, origin, d)[0]
    return hit


# --------------------------------------------------------------------------- renders

def cycles_settings(scene, spp, bounces, light_tree=False):
    """Cycles as the parity tests run it (its Light Paths are read by Polar too: export_polar sets them again);
    ``light_tree``: Cycles' Light Tree on (its default; Polar reads the switch as Blender's F12 does) instead of the
    parity settings' off (tests/bench/asset_speed.py --light-tree on: issue 36's race against Cycles)."""
    from tests.blender_support import light_paths_off, load_addon
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = spp
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.use_light_tree = bool(light_tree)
    c.light_sampling_threshold = 0.0
    light_paths_off(scene, bounces)     # every kind's bounces, no clamping, no Filter Glossy, caustics on (both read)
    c.volume_bounces = 0
    scene.render.threads_mode = "FIXED"
    scene.render.threads = 2
    scene.render.use_persistent_data = True          # the seeds' renders share one scene sync
    load_addon().polar_addon.compat.set_multilayer_exr(scene.render.image_settings)
    scene.render.image_settings.color_depth = "32"


def render_cycles(scene, spp, seeds, bounces, tmp, times=None, light_tree=False):
    """(seeds, H, W, 3) linear RGB of Cycles' Combined pass, one render per seed; ``times``: a list to which each
    render call's seconds are appended (the first one syncs the scene, the later ones reuse it)."""
    cycles_settings(scene, spp, bounces, light_tree)
    return np.array([cycles_once(scene, seed, tmp, times) for seed in range(seeds)])


def cycles_once(scene, seed, tmp, times=None):
    """(H, W, 3) one Cycles render of ``seed`` (settings as cycles_settings left them), its seconds appended to
    ``times``."""
    import bpy
    from tests.blender_support import read_multilayer
    scene.cycles.seed = seed
    scene.render.filepath = os.path.join(tmp, f"cycles_{seed}")
    t = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    if times is not None:
        times.append(time.perf_counter() - t)
    return read_multilayer(scene.render.filepath + ".exr")["Combined"][..., :3]


def export_polar(scene, spp, bounces, polarisation="AUTO", spectral="RGB"):
    """(Renderer, RenderSettings, warnings): the scene exported as F12 exports it; ``spectral`` the Render
    properties' Spectral mode (default RGB: Cycles' colour arithmetic, the mode parity is judged in)."""
    import bpy
    from tests.blender_support import load_addon
    load_addon()
    from polar_render.engine.render.renderer import Renderer
    from polar_render.polar_addon.export.scene import export_scene
    from polar_render.polar_addon.render_engine import engine_settings
    from tests.blender_support import light_paths_off
    light_paths_off(scene, bounces)     # Polar reads Cycles' Light Paths: the parity settings, as render_cycles
    p = scene.polar
    p.samples, p.max_bounces, p.polarisation, p.seed, p.spectral = spp, bounces, polarisation, 0, spectral
    p.use_adaptive_sampling = False
    settings = engine_settings(scene)
    W, H = scene.render.resolution_x, scene.render.resolution_y
    engine_scene, warnings = export_scene(bpy.context.evaluated_depsgraph_get(), scene.camera, W, H, settings)
    return Renderer(engine_scene), settings, list(warnings)


def render_polar(renderer, settings, seeds, times=None):
    """(seeds, 4, H, W, 3) Stokes images, one render per seed (seeds 0, 1, …); ``times``: a list to which each
    render's seconds are appended."""
    return np.array([polar_once(renderer, settings, seed, times) for seed in range(seeds)])


def polar_once(renderer, settings, seed, times=None):
    """(4, H, W, 3) one Polar render of ``seed``, its seconds appended to ``times``."""
    import dataclasses
    t = time.perf_counter()
    out = renderer.render(dataclasses.replace(settings, seed=seed)).stokes()
    if times is not None:
        times.append(time.perf_counter() - t)
    return out


def render_alternated(scene, renderer, settings, seeds, tmp, times_c, times_p, extra=0):
    """(cycles (seeds, H, W, 3), stokes (seeds, 4, H, W, 3)): both renderers seed by seed in turn — Cycles then
    Polar on even steps, Polar then Cycles on odd ones — so that the two renders of a step see the same load of a
    shared machine; ``extra`` more steps re-render seeds 0, 1, … for their seconds only (images not kept).  Cycles'
    settings must be set (cycles_settings) and the scene exported before; the seconds go to ``times_c``/``times_p``
    in step order (the first step's renders sync / warm up: see timing)."""
    cyc, stokes = [], []
    for step in range(seeds + extra):
        seed = step % seeds
        if step % 2 == 0:
            c = cycles_once(scene, seed, tmp, times_c)
            p = polar_once(renderer, settings, seed, times_p)
        else:
            p = polar_once(renderer, settings, seed, times_p)
            c = cycles_once(scene, seed, tmp, times_c)
        if step < seeds:
            cyc.append(c)
            stokes.append(p)
    return np.array(cyc), np.array(stokes)


# --------------------------------------------------------------------------- the rule

def block_means(images, mask_blocks_shape):
    """(seeds, rows, columns) block means of (seeds, H, W) images."""
    k, H, W = images.shape
    rows, cols = mask_blocks_shape
    return images[:, :rows * BLOCK, :cols * BLOCK].reshape(k, rows, BLOCK, cols, BLOCK).mean(axis=(2, 4))


def noise_tail(var: np.ndarray, top: float = TOP_SHARE) -> tuple[float, float]:
    """(share of Σ var in the ``top`` fraction of pixels with the largest variance, mean var of the other pixels)
    for per-pixel variances ``var`` (m,).  A share near 1 is a few fireflies (rare bright paths): the mean σ²
    of a few seeds then depends on whether they happened to catch one (docs/benchmarks.md, Sunglasses)."""
    v = np.sort(np.asarray(var, float).ravel())[::-1]
    if v.size == 0 or v.sum() <= 0:
        return 0.0, 0.0
    k = max(1, int(round(top * v.size)))
    return float(v[:k].sum() / v.sum()), float(v[k:].mean()) if v.size > k else 0.0


def compare(cycles_rgb, polar_s0_rgb, hit, report: CaseReport):
    """Apply the rule to (seeds, H, W, 3) images of both renderers and the (H, W) asset mask; fills the report."""
    H, W = hit.shape
    shape = (H // BLOCK, W // BLOCK)
    cov = block_means(hit[None].astype(float), shape)[0]
    mine = cov >= COVERAGE
    yc = block_means(cycles_rgb @ REC709, shape)
    yp = block_means(polar_s0_rgb @ REC709, shape)
    kc, kp = yc.shape[0], yp.shape[0]
    mc, mp = yc.mean(0), yp.mean(0)
    sc = yc.std(0, ddof=1) / math.sqrt(kc)
    sp = yp.std(0, ddof=1) / math.sqrt(kp)
    tol = SIGMAS * np.sqrt(sc ** 2 + sp ** 2) + RELATIVE * mc
    good = np.abs(mp - mc) <= tol
    report.blocks, report.passed = int(mine.sum()), int((good & mine).sum())
    if report.blocks:
        report.luminance_ratio = float(mp[mine].sum() / max(mc[mine].sum(), 1e-30))
        pix = np.kron(mine, np.ones((BLOCK, BLOCK), bool))
        pix = np.pad(pix, ((0, H - pix.shape[0]), (0, W - pix.shape[1])))
        c = cycles_rgb.mean(0)[pix].sum(0)
        p = polar_s0_rgb.mean(0)[pix].sum(0)
        report.channel_ratios = tuple(float(x) for x in p / np.maximum(c, 1e-30))
        var_c, var_p = (cycles_rgb @ REC709).var(0, ddof=1)[pix], (polar_s0_rgb @ REC709).var(0, ddof=1)[pix]
        report.noise = {"cycles": float(var_c.mean()), "polar": float(var_p.mean())}
        report.tails = {"cycles": noise_tail(var_c), "polar": noise_tail(var_p)}
    report.failing = [(int(i), int(j), float(mp[i, j] / mc[i, j]) if mc[i, j] > 0 else float("inf"),
                       float(tol[i, j] / mc[i, j]) if mc[i, j] > 0 else float("inf"))
                      for i, j in zip(*np.nonzero(mine & ~good))]
    return report


def run_case(asset: Asset | str, lighting: str, spp=16, seeds=4, width=None, height=None, bounces=8,
             polarisation="AUTO", out_dir=None, edit=None, spectral="RGB", alternate=False, extra=0,
             light_tree=False) -> CaseReport:
    """Build, render both ways, compare; with ``out_dir``, also write the images (see write_images).

    ``edit(scene)``, if given, changes the built scene before both renders (e.g. unlinks one material
    input): how a failing case is narrowed down to the material feature that causes it.  ``alternate``: the
    scene is exported first and the two renderers take turns seed by seed (render_alternated, ``extra`` timing-only
    steps): the same images, seconds measured side by side (tests/bench/asset_speed.py); else all Cycles renders,
    then the export and all Polar renders.  ``light_tree``: both renderers with Cycles' Light Tree on
    (cycles_settings)."""
    if isinstance(asset, str):
        asset = CATALOGUE[asset]
    width, height = width or asset.size[0], height or asset.size[1]
    report = CaseReport(asset.name, lighting, spp, seeds, width, height)
    scene = build(asset, lighting, width, height)
    if edit is not None:
        edit(scene)
    hit = coverage(scene, width, height)
    times_c, times_p = report.seconds.setdefault("cycles_each", []), report.seconds.setdefault("polar_each", [])
    with tempfile.TemporaryDirectory() as tmp:
        if not alternate:
            t = time.perf_counter()
            cyc = render_cycles(scene, spp, seeds, bounces, tmp, times_c, light_tree)
            report.seconds["cycles"] = time.perf_counter() - t
        else:
            cycles_settings(scene, spp, bounces, light_tree)
        try:
            t = time.perf_counter()
            renderer, settings, report.warnings = export_polar(scene, spp, bounces, polarisation, spectral)
            report.seconds["export"] = time.perf_counter() - t
            t = time.perf_counter()
            if alternate:
                cyc, stokes = render_alternated(scene, renderer, settings, seeds, tmp, times_c, times_p, extra)
                report.seconds["cycles"] = sum(times_c)
                report.seconds["alternated"] = True
            else:
                stokes = render_polar(renderer, settings, seeds, times_p)
        except Exception as e:      # a refused scene is a result of the case, reported, not a crash of the suite
            report.error = f"{type(e).__name__}: {e}"
            return report
    report.seconds["polar"] = sum(times_p) if alternate else time.perf_counter() - t
    compare(cyc, stokes[:, 0], hit, report)
    if out_dir is not None:
        write_images(out_dir, asset.name, lighting, cyc.mean(0), stokes.mean(0))
    return report


def timing(times_c, times_p, skip=1):
    """Warm seconds of alternated renders (render_alternated's per-step lists, the first ``skip`` steps left out:
    Cycles' scene sync, Polar's first render): {cycles, polar: median seconds; ratio: median over the steps of
    t_Polar ÷ t_Cycles of one step; q1, q3, lo, hi: quartiles and range of those per-step ratios; n: steps}.
    A step's two renders share the machine's load, so their ratio moves less than either side's seconds."""
    c, p = np.asarray(times_c[skip:] or times_c, float), np.asarray(times_p[skip:] or times_p, float)
    r = p / c
    q1, med, q3 = np.quantile(r, (0.25, 0.5, 0.75))
    return {"cycles": float(np.median(c)), "polar": float(np.median(p)), "ratio": float(med), "q1": float(q1),
            "q3": float(q3), "lo": float(r.min()), "hi": float(r.max()), "n": int(r.size)}


# --------------------------------------------------------------------------- images

def panel(cycles_rgb, stokes_rgb):
    """(H, 3W + 2·gap, 3) uint8: Cycles | Polar S0 | Polar DoLP (viridis, 0 purple … 1 yellow)."""
    from polar_render.engine.output.colormaps import sequential, tonemap
    from polar_render.engine.polarisation.stokes import degree_of_linear_polarisation
    y = stokes_rgb @ REC709
    dolp = np.nan_to_num(degree_of_linear_polarisation(y))
    gap = np.full((cycles_rgb.shape[0], 2, 3), 255, np.uint8)
    return np.concatenate([tonemap(cycles_rgb), gap, tonemap(stokes_rgb[0]), gap, sequential(dolp)], axis=1)


def write_images(out_dir, name, lighting, cycles_rgb, stokes_rgb):
    """<name>_<lighting>.png (Cycles | Polar S0 | Polar DoLP) and .npz (the linear images) in out_dir."""
    from polar_render.engine.output.png import write_png
    os.makedirs(out_dir, exist_ok=True)
    stem = os.path.join(out_dir, f"{name}_{lighting}")
    write_png(stem + ".png", panel(cycles_rgb, stokes_rgb))
    np.savez_compressed(stem + ".npz", cycles=cycles_rgb.astype(np.float32), stokes=stokes_rgb.astype(np.float32))
    return stem + ".png"


def figure(out_dir, path, names, lighting="hdri"):
    """Stack the panels of ``names`` (written by write_images) into one PNG at ``path``."""
    from polar_render.engine.output.png import read_png, write_png
    rows = [read_png(os.path.join(out_dir, f"{n}_{lighting}.png")) for n in names]
    width = max(r.shape[1] for r in rows)
    gap = np.full((4, width, 3), 255, np.uint8)
    stacked = []
    for r in rows:
        stacked += [np.pad(r[..., :3], ((0, 0), (0, width - r.shape[1]), (0, 0)), constant_values=255), gap]
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    write_png(path, np.concatenate(stacked[:-1], axis=0))
    return path
