"""Two engine trees raced on the real-asset suite: CPU seconds per warm render, alternated in one run.

    python tests/bench/asset_ab.py --base /path/to/other/checkout [--assets BoomBox,Sunglasses]
                                   [--lighting hdri] [--spp 16] [--rounds 5] [--threads 1] [--identical]

Each tree runs in a worker process of its own (the same glTF cases as tests/blender/test_real_assets.py,
built by tests/support/asset_parity and exported through that tree's extension), which renders each case
twice to warm up (kernels compiled or loaded, tables built).  The driver then asks the two workers in turn
— base, this tree, base, … — for one render of a case at a time, so both sides see the same load, and
prints per case the median over ``--rounds`` of each side's process CPU seconds per render (all its
threads; wall seconds beside), the ratio this ÷ base of the medians and its range over the rounds' pairs,
and the load average before and after.  ``--identical`` also checks that both trees give the same Stokes
image (seed 0) bit for bit (each side then builds its albedo tables itself: POLAR_TABLE_CACHE=0).  Not part of
the test command (it times).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))


def worker(tree: str, spp: int, threads: int) -> None:
    """Serve ``render NAME LIGHTING SEED`` lines on stdin: one JSON line {cpu, wall, digest} each."""
    import dataclasses
    import hashlib
    import time
    sys.path.insert(0, tree)
    from tests.support import asset_parity as ap
    cases = {}
    out = sys.stdout
    sys.stdout = sys.stderr         # Blender's and the importer's chatter away from the protocol
    for line in sys.stdin:
        _, name, lighting, seed = line.split()
        if (name, lighting) not in cases:
            asset = ap.CATALOGUE[name]
            scene = ap.build(asset, lighting, *asset.size)
            renderer, settings, _ = ap.export_polar(scene, spp, 8, "AUTO", "RGB")
            settings = dataclasses.replace(settings, threads=threads) if threads else settings
            for s in range(2):
                renderer.render(dataclasses.replace(settings, seed=s))
            cases[name, lighting] = renderer, settings
        renderer, settings = cases[name, lighting]
        c, t = time.process_time(), time.perf_counter()
        img = renderer.render(dataclasses.replace(settings, seed=int(seed))).stokes()
        cpu, wall = time.process_time() - c, time.perf_counter() - t
        out.write(json.dumps({"cpu": cpu, "wall": wall, "digest": hashlib.sha1(img.tobytes()).hexdigest()}) + "\n")
        out.flush()


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base", required=True, help="the other checkout (its tests/ and engine/ are used)")
    p.add_argument("--assets", default="BoomBox,SpecGlossEmission,TextureTransform,Sunglasses")
    p.add_argument("--lighting", default="hdri,lamps")
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--identical", action="store_true")
    p.add_argument("--worker", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        return worker(a.worker, a.spp, a.threads)
    trees = {"base": os.path.abspath(a.base), "this": REPO}
    # the table cache is keyed by the sources, not by NumPy's SIMD loops: a table another process built on its
    # AVX-512 loops differs in last bits from one built here, so the bit check has both sides build their own
    env = dict(os.environ, **({"POLAR_TABLE_CACHE": "0"} if a.identical else {}))
    procs = {k: subprocess.Popen([sys.executable, os.path.abspath(__file__), "--base", a.base, "--worker", tree,
                                  "--spp", str(a.spp), "--threads", str(a.threads)], cwd=tree, text=True, env=env,
                                 stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
             for k, tree in trees.items()}

    def ask(side, name, lighting, seed):
        procs[side].stdin.write(f"render {name} {lighting} {seed}\n")
        procs[side].stdin.flush()
        return json.loads(procs[side].stdout.readline())

    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())}; threads {a.threads}, "
          f"{a.spp} spp, {a.rounds} rounds alternated; base = {trees['base']}")
    print(f"{'case':28s} {'base CPU s':>10s} {'this CPU s':>10s} {'this/base':>9s} {'pairs min–max':>14s} "
          f"{'base wall':>9s} {'this wall':>9s}")
    for name in a.assets.split(","):
        for lighting in a.lighting.split(","):
            runs = {"base": [], "this": []}
            for r in range(a.rounds):
                for side in (("base", "this") if r % 2 == 0 else ("this", "base")):
                    runs[side].append(ask(side, name, lighting, 0))
            med = {k: statistics.median(x["cpu"] for x in v) for k, v in runs.items()}
            wall = {k: statistics.median(x["wall"] for x in v) for k, v in runs.items()}
            pairs = [t["cpu"] / b["cpu"] for b, t in zip(runs["base"], runs["this"])]
            ratio = med["this"] / med["base"]
            line = (f"{name + ' ' + lighting:28s} {med['base']:10.3f} {med['this']:10.3f} {ratio:9.3f} "
                    f"{min(pairs):6.3f}–{max(pairs):6.3f} {wall['base']:9.3f} {wall['this']:9.3f}")
            if a.identical:
                line += "  identical" if runs["base"][0]["digest"] == runs["this"][0]["digest"] else "  DIFFERENT"
            print(line, flush=True)
    for proc in procs.values():
        proc.stdin.close()
        proc.wait()
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
