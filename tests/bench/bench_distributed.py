"""Throughput of distributed rendering with 1 and 2 Dask workers on this machine, side by side.

    python tests/bench/bench_distributed.py [--scene fresnel_sphere] [--spp 8] [--res 256]

Starts a local Dask cluster (worker processes, one thread each), renders the peer scene with 1 and
then 2 workers, checks that both images equal the local render, and prints samples per second and
the speed-up.  Not part of the test command.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)

from engine.render.renderer import Renderer, RenderRequest  # noqa: E402
from engine.scene.loader import load_scene  # noqa: E402

SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))


def main():
    import distributed
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="fresnel_sphere")
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--res", type=int, default=256)
    args = ap.parse_args()
    scene = load_scene(os.path.join(SHARED, "peers", "scenes", f"{args.scene}.json"))
    scene.camera.width = scene.camera.height = args.res
    scene.settings = dataclasses.replace(scene.settings, spp=args.spp, batch_rays=1 << 15, threads=1)
    t0 = time.perf_counter()
    local = Renderer(scene).render()
    rows = [("local, 1 thread", time.perf_counter() - t0, True)]
    for n in (1, 2):
        with distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                                      silence_logs=40) as cluster, distributed.Client(cluster) as client:
            renderer = Renderer(scene)
            renderer.render(RenderRequest(scheduler=client))          # warm-up: workers compile the scene
            t0 = time.perf_counter()
            result = renderer.render(RenderRequest(scheduler=client))
            rows.append((f"Dask, {n} worker{'s' if n > 1 else ''}", time.perf_counter() - t0,
                         bool(np.array_equal(result.stokes(), local.stokes()))))
    samples = args.res * args.res * args.spp
    print(f"{args.scene}, {args.res}×{args.res}, {args.spp} spp ({samples} samples)\n")
    print("| configuration | seconds | Msamples/s | speed-up vs 1 worker | image equals local |")
    print("|---|---|---|---|---|")
    one = rows[1][1]
    for name, sec, same in rows:
        print(f"| {name} | {sec:.2f} | {samples / sec / 1e6:.3f} | {one / sec:.2f}× | {same} |")


if __name__ == "__main__":
    main()
