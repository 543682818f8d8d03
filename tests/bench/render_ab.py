"""Two checkouts of the engine raced render by render: CPU seconds per render, and the images compared bit for bit.

    python tests/bench/render_ab.py --base /path/to/other/checkout [--cases BoomBox:hdri,peer:rough_sphere_a030]
                                    [--rounds 3] [--renders 3] [--threads 1] [--spp 16]

A case is ``Asset:lighting`` (tests/support/asset_parity.CATALOGUE, exported through the extension as the parity
suite does, ``--spp`` samples, 8 bounces, RGB) or ``peer:scene`` (../shared/peers/scenes/<scene>.json at its own
settings, ``--spp`` samples).  Each round runs every case once in a fresh process per checkout, this one (A) and
``--base`` (B), alternating A B A B so that the machine's drift falls on both alike; a process renders one warm-up
render (Numba's cache read, first-touch costs), then ``--renders`` renders with seeds 1, 2, …, timed by the
process's CPU clock (``time.process_time``: every thread's CPU).  Printed per case: the median over the rounds of
A's and B's CPU seconds per render, and the median of the per-round ratios A ÷ B; whether A's and B's images (every
Stokes component of every seed, float64) are bit-identical, else their largest absolute difference relative to the
image's largest |S0|.  The load average is printed before and after.  Not a test: the machine may be shared.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))

DEFAULT_CASES = "BoomBox:hdri,BoomBox:lamps,SpecGlossEmission:hdri,SpecGlossEmission:lamps,TextureTransform:hdri," \
                "TextureTransform:lamps,peer:rough_sphere_a030"


def child(root: str, case: str, renders: int, threads: int, spp: int, out: str) -> None:
    """Render ``case`` with the engine of ``root``; write {'cpu': [...]} to ``out`` + '.json', the images to .npy."""
    import dataclasses
    import numpy as np
    sys.path.insert(0, root)
    kind, name = case.split(":")
    if kind == "peer":
        from engine.render.renderer import Renderer
        from engine.scene.loader import load_scene
        scene = load_scene(os.path.join(os.path.dirname(root), "shared", "peers", "scenes", f"{name}.json"))
        renderer, settings = Renderer(scene), scene.settings
    else:
        from tests.support import asset_parity as ap
        asset = ap.CATALOGUE[kind]
        renderer, settings, _ = ap.export_polar(ap.build(asset, name, *asset.size), spp, 8, "AUTO", "RGB")
    settings = dataclasses.replace(settings, spp=spp, threads=threads)
    renderer.render(dataclasses.replace(settings, seed=0))
    cpu, images = [], []
    for seed in range(1, renders + 1):
        c0 = time.process_time()
        image = renderer.render(dataclasses.replace(settings, seed=seed)).stokes()
        cpu.append(time.process_time() - c0)
        images.append(image)
    np.save(out + ".npy", np.array(images))
    with open(out + ".json", "w") as f:
        json.dump({"cpu": cpu}, f)


def run(root: str, case: str, args, out: str) -> list[float]:
    cmd = [sys.executable, os.path.abspath(__file__), "--child", root, "--case", case, "--renders", str(args.renders),
           "--threads", str(args.threads), "--spp", str(args.spp), "--out", out]
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    with open(out + ".json") as f:
        return json.load(f)["cpu"]


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base", help="the other checkout (B)")
    p.add_argument("--cases", default=DEFAULT_CASES)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--renders", type=int, default=3)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--child")
    p.add_argument("--case")
    p.add_argument("--out")
    args = p.parse_args(argv)
    if args.child:
        child(args.child, args.case, args.renders, args.threads, args.spp, args.out)
        return
    import numpy as np
    print(f"load average before: {os.getloadavg()}")
    print(f"A = {REPO}, B = {args.base}; {args.rounds} rounds × {args.renders} renders, {args.threads} thread(s), "
          f"{args.spp} spp")
    cases = args.cases.split(",")
    cpu = {c: {"A": [], "B": []} for c in cases}
    with tempfile.TemporaryDirectory() as tmp:
        same = {}
        for r in range(args.rounds):
            for c in cases:
                for side, root in (("A", REPO), ("B", args.base)):
                    cpu[c][side].append(float(np.mean(run(root, c, args, os.path.join(tmp, f"{c}_{side}")))))
                if r == 0:
                    a, b = (np.load(os.path.join(tmp, f"{c}_{s}.npy")) for s in "AB")
                    same[c] = ("bit-identical" if np.array_equal(a, b) else
                               f"differ: max |A − B| = {np.max(np.abs(a - b)) / np.max(np.abs(b[:, 0])):.2e} × max S0")
        print(f"{'case':34s} {'A cpu s':>9s} {'B cpu s':>9s} {'A ÷ B':>7s}  images")
        for c in cases:
            ratios = [x / y for x, y in zip(cpu[c]["A"], cpu[c]["B"])]
            print(f"{c:34s} {np.median(cpu[c]['A']):9.3f} {np.median(cpu[c]['B']):9.3f} {np.median(ratios):7.3f}  "
                  f"{same[c]}  (ratios {', '.join(f'{x:.3f}' for x in ratios)})")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
