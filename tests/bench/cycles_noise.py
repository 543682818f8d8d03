"""Polar against Cycles on the Cycles parity scenes: time and noise at equal samples.

    python tests/bench/cycles_noise.py [--scenes all_lights,point_radius] [--res 160x120] [--spp 16]
                                       [--sampler PATTERN[,PATTERN…]] [--json]

Builds each scene of tests/blender/test_cycles_parity_lights.py in bpy (diffuse floor and box, one kind of light
each; ``all_lights`` has 8 point/spot/area/sun lights of 1–1000 W and an emitter; plus
``eight_points_world``: eight point lights of 1–1000 W and a grey world, issue 16's case, and
``defocused_lamp``: ``area_square`` through a thin lens at f/1.4 focused at 1.5 m), renders it
twice (seeds 0 and 1) with Cycles (CPU, 2 threads, the test's unbiased settings) and twice with
Polar (F12 path: ``bpy.ops.render.render``, polarisation auto, which picks scalar transport here),
both at ``--spp`` samples and written to EXR, and reports per renderer the best wall time and the
noise of the luminance S0: σ² = mean over lit pixels of (A − B)² / 2, the per-render pixel
variance from the two seeds (lit: Cycles' mean above 2 % of its brightest pixel).  Variance × time
of Polar ÷ Cycles is the issue-16 target (≤ 3); noise ratio = σ_Polar / σ_Cycles at equal spp.
``--sampler independent,stratified`` renders Polar with both patterns beside one set of Cycles renders
(one result line per pattern).  Runs in the bpy module; not part of the test command.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)

from engine.scene.description import SAMPLERS  # noqa: E402  (our sampling patterns: the engine's one list)

REC709 = np.array([0.2126, 0.7152, 0.0722])
QUICK_SCENES = ["area_square", "point_radius", "all_lights", "eight_points_world"]


def eight_points_world():
    """Issue 16's many-light case (not a parity test): eight point lights of 1–1000 W and a grey world."""
    import bpy
    import tests.blender.test_cycles_parity_lights as parity
    for i, energy in enumerate(np.geomspace(1.0, 1000.0, 8)):
        angle = 2 * np.pi * i / 8
        parity.add_light("POINT", (2.0 * np.cos(angle), 2.0 * np.sin(angle), 0.8 + 0.2 * i), energy=float(energy),
                         shadow_soft_size=0.1)
    background = bpy.context.scene.world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    background.inputs["Strength"].default_value = 0.1


def defocused_lamp():
    """Depth of field (not a parity test): ``area_square`` seen at f/1.4 focused 1.5 m in front of the
    camera, so the cube, the lit floor and the shadow edges are blurred over many pixels."""
    import bpy
    import tests.blender.test_cycles_parity_lights as parity
    parity.area_square()
    cam = bpy.context.scene.camera.data
    cam.dof.use_dof = True
    cam.dof.aperture_fstop = 1.4
    cam.dof.focus_distance = 1.5


BENCH_SCENES = {"eight_points_world": eight_points_world, "defocused_lamp": defocused_lamp}


def render_luminance(scene, path):
    """(seconds of bpy.ops.render.render incl. the EXR write, luminance S0 image)."""
    import bpy
    from tests.blender_support import read_multilayer
    scene.render.filepath = path
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - t0
    return seconds, read_multilayer(path + ".exr")["Combined"][..., :3] @ REC709


def race_settings(scene, width, height, spp):
    """Both renderers' settings of a race: the size, Cycles on the CPU with 2 threads, ``spp`` samples without
    adaptive sampling, denoising, clamps or light threshold, a box pixel filter, the parity tests' bounces, and
    multilayer float EXR output."""
    import tests.blender.test_cycles_parity_lights as parity
    scene.render.resolution_x, scene.render.resolution_y = width, height
    c = scene.cycles
    scene.render.engine = "CYCLES"
    c.device, c.samples, c.use_adaptive_sampling, c.use_denoising = "CPU", spp, False, False
    c.pixel_filter_type, c.filter_width = "BOX", 1.0
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.light_sampling_threshold = 0.0
    c.max_bounces = c.diffuse_bounces = parity.BOUNCES
    c.caustics_reflective = c.caustics_refractive = True
    scene.render.threads_mode, scene.render.threads = "FIXED", 2
    ims = scene.render.image_settings
    ims.media_type, ims.color_depth = "MULTI_LAYER_IMAGE", "32"


def measure(name, width, height, spp, tmp, samplers=("independent",)):
    """One result per Polar sampling pattern in ``samplers``, each beside the same Cycles renders
    (Cycles renders once: its time and noise do not depend on Polar's pattern)."""
    import tests.blender.test_cycles_parity_lights as parity
    scene = parity.base_scene()
    {**parity.SCENES, **BENCH_SCENES}[name]()
    race_settings(scene, width, height, spp)
    c = scene.cycles
    out = {}
    for engine, sampler in [("CYCLES", None)] + [("POLAR", s) for s in samplers]:
        key = engine if sampler is None else (engine, sampler)
        scene.render.engine = engine
        scene.polar.samples, scene.polar.max_bounces, scene.polar.threads = spp, parity.BOUNCES, 0
        if sampler is not None:
            scene.polar.sampler = sampler.upper()
        render_luminance(scene, os.path.join(tmp, f"{name}_{engine}_warm"))   # kernels, caches
        times, images = [], []
        for seed in (0, 1):
            c.seed = seed
            scene.polar.seed = seed
            t, img = render_luminance(scene, os.path.join(tmp, f"{name}_{engine}_{seed}"))
            times.append(t)
            images.append(img)
        out[key] = (min(times), images)
    lit = (out["CYCLES"][1][0] + out["CYCLES"][1][1]) / 2
    lit = lit > 0.02 * lit.max()

    def stats(t, a, b):
        return {"seconds": t, "variance": float(np.mean(((a - b)[lit]) ** 2) / 2),
                "mean": float(np.mean(((a + b) / 2)[lit]))}

    cycles = stats(out["CYCLES"][0], *out["CYCLES"][1])
    return [{"scene": name, "spp": spp, "width": width, "height": height, "sampler": s, "CYCLES": cycles,
             "POLAR": stats(out[("POLAR", s)][0], *out[("POLAR", s)][1])} for s in samplers]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(QUICK_SCENES),
                    help="names from tests/blender/test_cycles_parity_lights.py, eight_points_world, or 'all'")
    ap.add_argument("--res", default="160x120")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--sampler", default="independent",
                    help="Polar's sampling pattern (Render Properties ▸ Sampling ▸ Pattern): independent, "
                         "stratified, or both as 'independent,stratified' (Cycles then renders once per scene)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    samplers = args.sampler.split(",")
    for s in samplers:
        if s not in SAMPLERS:
            ap.error(f"--sampler: {s!r} is not one of {', '.join(SAMPLERS)}")
    from tests.blender_support import load_addon
    import tests.blender.test_cycles_parity_lights as parity
    load_addon()
    width, height = (int(v) for v in args.res.split("x"))
    names = list(parity.SCENES) + list(BENCH_SCENES) if args.scenes == "all" else args.scenes.split(",")
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            for r in measure(name, width, height, args.spp, tmp, samplers):
                if args.json:
                    print(json.dumps(r), flush=True)
                    continue
                p, c = r["POLAR"], r["CYCLES"]
                print(f"{name} ({r['sampler']}): Cycles {c['seconds']:.2f} s σ {c['variance'] ** 0.5:.4g}, "
                      f"Polar {p['seconds']:.2f} s σ {p['variance'] ** 0.5:.4g}; var×time Polar ÷ Cycles "
                      f"{p['variance'] * p['seconds'] / (c['variance'] * c['seconds']):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
