"""The light tree's race (issue 36 item 3): many small emitters and lamps, Polar against Cycles, in one run.

    python tests/bench/light_tree_race.py [--res 160x120] [--spp 16] [--triangles 1000] [--json]

Builds in bpy the Cycles parity lights' base scene (white diffuse floor and box, black world, camera looking down
at 45°) with ``--triangles`` small emissive triangles (≈ 8–15 cm, facing the floor, 0.4–2.6 m above it, hidden from
the camera: the noise measured is the floor's lighting) in four meshes of emission strength 2, 10, 50 and 250, and
8 lamps (4 point, 2 spot, 2 area, 5–500 W), and renders it at
``--spp`` with Cycles (CPU, 2 threads, light tree on: Cycles' default), with Polar with the tree (Cycles' Light
Tree switch read by the exporter) and with Polar without it (``scene.cycles.use_light_tree = False``: the light
set's per-point selection by power over whole lights), each with seeds 0 and 1 after a warm-up render.  Per
renderer: the best wall time of the two (F12 path incl. export and EXR write), the noise of the luminance S0
(σ² = mean over lit pixels of (A − B)²/2) and the mean; printed side by side with the ratios variance × time
Polar ÷ Cycles (issue 36: ≤ 1.5 with the tree) and Polar tree ÷ no tree, and the machine's load.  Runs in the bpy
module; not part of the test command.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)
sys.path.insert(0, HERE)

#: emission strengths of the four triangle meshes (mixed power)
STRENGTHS = (2.0, 10.0, 50.0, 250.0)


def many_lights(triangles: int, seed: int = 1) -> None:
    """The emissive triangles and the 8 lamps, added to the parity base scene."""
    import bpy
    import tests.blender.test_cycles_parity_lights as parity
    rng = np.random.default_rng(seed)
    centre = np.column_stack((rng.uniform(-3.0, 3.0, triangles), rng.uniform(-2.0, 3.0, triangles),
                              rng.uniform(0.4, 2.6, triangles)))
    size = rng.uniform(0.08, 0.15, triangles)
    angle = rng.uniform(0.0, 2 * np.pi, triangles)[:, None] + np.array([0.0, 2.0 * np.pi / 3, 4.0 * np.pi / 3])
    # corners clockwise seen from above: the front faces the floor
    corners = np.stack((centre[:, None, 0] + size[:, None] * np.cos(-angle),
                        centre[:, None, 1] + size[:, None] * np.sin(-angle),
                        np.repeat(centre[:, None, 2], 3, axis=1)), axis=2)
    for k, strength in enumerate(STRENGTHS):
        part = corners[k::len(STRENGTHS)].reshape(-1, 3)
        mesh = bpy.data.meshes.new(f"Emitters{k}")
        mesh.from_pydata([tuple(v) for v in part], [], [(3 * i, 3 * i + 1, 3 * i + 2) for i in range(len(part) // 3)])
        mesh.update()
        obj = bpy.data.objects.new(f"Emitters{k}", mesh)
        obj.data.materials.append(parity.emission(f"Glow{k}", strength))
        obj.visible_camera = False          # the noise measured is the floor's lighting, not the emitters' edges
        bpy.context.scene.collection.objects.link(obj)
    energies = np.geomspace(5.0, 500.0, 8)
    spots = {1, 5}
    areas = {3, 6}
    for i, energy in enumerate(energies):
        a = 2 * np.pi * i / 8
        where = (2.2 * np.cos(a), 0.5 + 2.2 * np.sin(a), 1.0 + 0.15 * i)
        if i in spots:
            parity.add_light("SPOT", where, rotation=(0.3, 0.2 * (i - 3), 0.0), energy=float(energy),
                             spot_size=1.2, spot_blend=0.3, shadow_soft_size=0.05)
        elif i in areas:
            parity.add_light("AREA", where, energy=float(energy), size=0.4, shape="SQUARE" if i == 3 else "DISK")
        else:
            parity.add_light("POINT", where, energy=float(energy), shadow_soft_size=0.05)


def measure(width, height, spp, triangles, tmp):
    import bpy
    import tests.blender.test_cycles_parity_lights as parity
    from cycles_noise import race_settings, render_luminance
    scene = parity.base_scene()
    many_lights(triangles)
    race_settings(scene, width, height, spp)
    c = scene.cycles
    c.blur_glossy = 0.0                 # (Polar warns that it does not apply it; nothing here is glossy)
    runs = {"Cycles": ("CYCLES", True), "Polar tree": ("POLAR", True), "Polar no tree": ("POLAR", False)}
    out = {}
    for name, (engine, tree) in runs.items():
        scene.render.engine = engine
        c.use_light_tree = tree
        scene.polar.samples, scene.polar.max_bounces, scene.polar.threads = spp, parity.BOUNCES, 0
        render_luminance(scene, os.path.join(tmp, f"{engine}_{tree}_warm"))     # kernels, caches
        times, images = [], []
        for seed in (0, 1):
            c.seed = scene.polar.seed = seed
            t, img = render_luminance(scene, os.path.join(tmp, f"{engine}_{tree}_{seed}"))
            times.append(t)
            images.append(img)
        out[name] = (min(times), images)
        bpy.context.view_layer.update()
    cyc = out["Cycles"][1]
    lit = (cyc[0] + cyc[1]) / 2
    lit = lit > 0.02 * lit.max()
    result = {"width": width, "height": height, "spp": spp, "triangles": triangles, "load": os.getloadavg()}
    for name, (t, (a, b)) in out.items():
        result[name] = {"seconds": t, "variance": float(np.mean(((a - b)[lit]) ** 2) / 2),
                        "mean": float(np.mean(((a + b) / 2)[lit]))}
    return result


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--res", default="160x120")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--triangles", type=int, default=1000)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    from tests.blender_support import load_addon
    load_addon()
    width, height = (int(v) for v in args.res.split("x"))
    with tempfile.TemporaryDirectory() as tmp:
        r = measure(width, height, args.spp, args.triangles, tmp)
    if args.json:
        print(json.dumps(r))
        return 0
    print(f"{args.triangles} emissive triangles + 8 lamps, {width}×{height}, {args.spp} spp, load average before "
          f"{r['load'][0]:.2f} / {r['load'][1]:.2f} / {r['load'][2]:.2f}")
    c = r["Cycles"]
    for name in ("Cycles", "Polar tree", "Polar no tree"):
        p = r[name]
        print(f"  {name:14s} {p['seconds']:7.2f} s  σ {p['variance'] ** 0.5:.4g}  mean {p['mean']:.4g}  "
              f"var×time ÷ Cycles {p['variance'] * p['seconds'] / (c['variance'] * c['seconds']):.2f}")
    a, b = r["Polar tree"], r["Polar no tree"]
    print(f"  Polar tree ÷ no tree: var×time {a['variance'] * a['seconds'] / (b['variance'] * b['seconds']):.2f}, "
          f"variance {a['variance'] / b['variance']:.2f}, time {a['seconds'] / b['seconds']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
