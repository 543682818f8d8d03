"""Embree queries by call path, ns per ray: embreex, the engine's compiled one-ray loop, packets of 4, 8, 16.

    python tests/bench/embree_calls.py [--scene glass_sphere] [--res 128] [--spp 16] [--repeats 5] [--builds]
    python tests/bench/embree_calls.py --render fresnel_sphere,glass_sphere [--res 256] [--spp 8] [--widths 1,16]

Side by side in one run, on one scene's geometry (robust traversal), each from the renderer's (3, N)
float64 rays to its (prim, u, v, t) float64 hits (closest) or blocked flags (shadow):

- ``embreex``: engine.render.accel.EmbreexScene, what the engine calls without Numba (float32 (N, 3)
  copies of the rays, embreex's ``run`` — a Cython loop of ``rtcIntersect1`` that allocates six result
  arrays per call, Ng included — and the conversion of its results);
- ``1``: engine.render.embree_direct.DirectScene with width 1 (``rtcIntersect1`` / ``rtcOccluded1`` per ray
  from a compiled loop, embreex's numbers bit for bit);
- ``4``, ``8``, ``16``: the same scene queried in packets (``rtcIntersectW`` / ``rtcOccludedW``), the query
  flag incoherent; ``16c``: packets of 16 with the coherent flag.

Rays: the scene's camera rays (pixel-major: each pixel's ``--spp`` samples in a row, as the engine's
batches hold them; and sample-major), camera rays reflected at their hits (a mirror's first bounce, in
the same order), and random rays aimed at the scene's first mesh.  Shadow rays: from the camera rays'
hits towards random points around the mesh (bounded).  Each table row also counts the packets' hits that
differ from the one-ray query's: another triangle (and where not a tie, t within 1e-6 relative), t beyond
1e-6 relative, u or v beyond 1e-5, and the bits of u that differ.  ``--builds`` adds rows for build
settings (quality HIGH, RTC_SCENE_FLAG_COMPACT, a triangle-only feature mask, Embree's AVX2 kernels instead of
AVX-512, huge pages).  Needs Numba and the
Embree library next to embreex (engine.render.embree_direct.library).

``--render``: the rays of real renders instead (1 thread, the scenes' settings, ``--spp``, after a warm-up
render): every Embree query of the render is made once per width of ``--widths``, in random order, each timed
by the thread's CPU clock (the render goes on with the first width's answer), and the CPU ns per ray are
printed by kind (camera rays, later segments, shadow rays).  Benchmarks never run as tests.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, REPO)


def differences(a, b):
    """(other triangle not a tie, t beyond 1e-6 relative, u/v beyond 1e-5, u not bit-identical) of hits b
    against the one-ray hits a, counted over the rays a hits."""
    hit = (a[0] >= 0) | (b[0] >= 0)
    rel = np.abs(b[3] - a[3]) / np.maximum(np.abs(a[3]), 1e-30)
    other = hit & (a[0] != b[0])
    same = hit & (a[0] == b[0])
    return (int((other & (rel > 1e-6)).sum()), int((hit & (rel > 1e-6)).sum()),
            int((same & ((np.abs(b[1] - a[1]) > 1e-5) | (np.abs(b[2] - a[2]) > 1e-5))).sum()),
            int((same & (b[1] != a[1])).sum()), int(other.sum()), int(hit.sum()))


def in_render(scenes, res, spp, widths):
    """Each scene rendered with every Embree query made at every width (paired); prints ns per ray by kind."""
    import threading
    from engine.render import integrator
    from engine.render.renderer import Renderer
    from engine.scene.loader import load_scene
    shared = os.environ.get("POLAR_SHARED") or os.path.join(os.path.dirname(REPO), "shared")
    bounce = threading.local()
    intersect = integrator.PathTracer._intersect

    def tagged(self, state, acc, b):
        bounce.b = b
        try:
            return intersect(self, state, acc, b)
        finally:
            bounce.b = None

    integrator.PathTracer._intersect = tagged
    for name in scenes:
        scene = load_scene(os.path.join(shared, "peers", "scenes", f"{name}.json"))
        scene.camera.width = scene.camera.height = res
        totals = paired_render(Renderer(scene), scene, spp, widths, bounce)
        print(f"{name} ({res}², {spp} spp, load average {os.getloadavg()[0]:.2f}), CPU ns per ray by width: " +
              "; ".join(f"{kind} ({v[widths[0]][1]} rays) " + ", ".join(f"{w}: {v[w][0] / v[w][1]:.0f}" for w in widths)
                        for kind, v in totals.items()))


def paired_render(renderer, scene, spp, widths, bounce):
    """{kind: {width: [CPU ns, rays]}} of one render whose every Embree query is made at each width."""
    import dataclasses
    from engine.render.embree_direct import DirectScene
    rays = renderer.compiled.rays
    if not isinstance(rays, DirectScene):
        raise SystemExit("the render's scene is not a DirectScene (no Numba, or no Embree library)")
    rng = np.random.default_rng(0)
    totals = {}

    def paired(kind, n, query):
        out = None
        for w in rng.permutation(widths):
            rays.width = int(w)
            t0 = time.thread_time_ns()
            res_w = query()
            ns = totals.setdefault(kind, {}).setdefault(int(w), [0, 0])
            ns[0] += time.thread_time_ns() - t0
            ns[1] += n
            out = res_w if out is None or w == widths[0] else out
        return out

    def closest(o, d, t_max, prims, **kw):
        b = getattr(bounce, "b", None)
        kind = "camera" if b == 0 else "later segments" if b is not None else "other closest"
        return paired(kind, o.shape[1], lambda: DirectScene.closest(rays, o, d, t_max, prims))

    def occluded(o, d, t_max):
        return paired("shadow", o.shape[1], lambda: DirectScene.occluded(rays, o, d, t_max))

    settings = dataclasses.replace(scene.settings, spp=spp, threads=1, seed=0)
    renderer.render(dataclasses.replace(settings, seed=9))
    rays.closest, rays.occluded = closest, occluded
    renderer.render(settings)
    return totals


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="glass_sphere")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--builds", action="store_true", help="also time build settings (quality, compact, features)")
    ap.add_argument("--render", help="scenes whose renders' own queries are timed at every width (comma-separated)")
    ap.add_argument("--widths", default="1,16")
    args = ap.parse_args()
    if args.render:
        in_render(args.render.split(","), args.res if args.res != 128 else 256, args.spp if args.spp != 16 else 8,
                  [int(w) for w in args.widths.split(",")])
        return 0
    from engine.render.accel import EmbreexScene
    from engine.render.embree_direct import _COMPACT, _ROBUST, DirectScene, library
    from engine.render.renderer import Renderer
    from engine.scene.loader import load_scene
    shared = os.environ.get("POLAR_SHARED") or os.path.join(os.path.dirname(REPO), "shared")
    scene = load_scene(os.path.join(shared, "peers", "scenes", f"{args.scene}.json"))
    scene.camera.width = scene.camera.height = args.res
    renderer = Renderer(scene)
    compiled, camera = renderer.compiled, renderer.camera
    lib = library()
    if lib is None:
        raise SystemExit("Embree's library was not found next to embreex")
    V, F = compiled.vertices, compiled.faces
    paths = {"embreex": EmbreexScene(V, F)}
    for w in (1, 4, 8, 16):
        paths[str(w)] = DirectScene(lib, V, F, width=w)
    if args.builds:
        paths["16, quality HIGH"] = DirectScene(lib, V, F, width=16, quality=2)
        paths["16, COMPACT"] = DirectScene(lib, V, F, width=16, scene_flags=_ROBUST | _COMPACT)
        paths["16, triangles only"] = DirectScene(lib, V, F, width=16, features=1 << 1)
        paths["16, isa=avx2"] = DirectScene(lib, V, F, width=16, config="isa=avx2")
        paths["16, hugepages=1"] = DirectScene(lib, V, F, width=16, config="hugepages=1")
    rng = np.random.default_rng(0)
    n_pix = args.res * args.res
    mesh = scene.meshes[0]
    centre, radius = mesh.vertices.mean(axis=0)[:, None], np.ptp(mesh.vertices, axis=0).max() / 2
    sets = {}
    for name, pixels in [("camera, pixel-major", np.repeat(np.arange(n_pix), args.spp)),
                         ("camera, sample-major", np.tile(np.arange(n_pix), args.spp))]:
        oc, dc, *_ = camera.generate(pixels, rng.random((2, pixels.size)))
        sets[name] = (oc, dc, None)
    oc, dc, _ = sets["camera, pixel-major"]
    h = paths["1"].closest(oc, dc, None, None)
    hit = h[0] >= 0
    p, n_g = compiled.surface(np.maximum(h[0], 0), h[1], h[2])[:2]
    n_g = np.where((n_g * dc).sum(0) > 0, -n_g, n_g)
    p = p + 1e-4 * (1 + np.abs(p).max(0)) * n_g
    sets["reflected at the camera rays' hits"] = (p[:, hit], (dc - 2 * (dc * n_g).sum(0) * n_g)[:, hit], None)
    o = rng.normal(size=(3, n_pix * args.spp))
    o = centre + 3 * radius * o / np.linalg.norm(o, axis=0)
    d = centre + 0.5 * radius * rng.normal(size=o.shape) - o
    sets["random, at the first mesh"] = (o, d / np.linalg.norm(d, axis=0), None)
    target = centre + 2 * radius * rng.normal(size=(3, int(hit.sum())))
    ws = target - p[:, hit]
    dist = np.linalg.norm(ws, axis=0)
    shadow = (p[:, hit], ws / dist, dist)

    def best(n, f, *call_args, **kw):
        times = []
        for _ in range(args.repeats):
            t0 = time.thread_time()
            f(*call_args, **kw)
            times.append(time.thread_time() - t0)
        return min(times) / n * 1e9

    names = list(paths)
    print(f"{args.scene}, {len(F)} triangles, {args.res}² × {args.spp} camera rays; CPU ns per ray (fastest of "
          f"{args.repeats}); load average {os.getloadavg()[0]:.2f}\n")
    print("| rays | " + " | ".join(names) + " | 16c | 16 ÷ 1 | differing from one ray's (of hits): other triangle"
          " (not a tie), t > 1e-6 rel, u/v > 1e-5, u's bits; ties |")
    print("|---|" + "---|" * (len(names) + 3))
    for name, (o, d, t_max) in sets.items():
        n = o.shape[1]
        one = paths["1"].closest(o, d, t_max, None)
        times = [best(n, paths[k].closest, o, d, t_max, None) for k in names]
        t_c = best(n, paths["16"].closest, o, d, t_max, None, coherent=True)
        diffs = [differences(one, paths[k].closest(o, d, t_max, None)) for k in ("4", "8", "16")]
        diffs.append(differences(one, paths["16"].closest(o, d, t_max, None, coherent=True)))
        worst = max(diffs, key=lambda x: x[:4])
        print(f"| {name} | " + " | ".join(f"{x:.0f}" for x in times) + f" | {t_c:.0f} | "
              f"{times[names.index('16')] / times[names.index('1')]:.2f} | {worst[0]}, {worst[1]}, {worst[2]}, "
              f"{worst[3]} of {worst[5]}; {worst[4] - worst[0]} |")
    o, d, t_max = shadow
    times = [best(o.shape[1], paths[k].occluded, o, d, t_max) for k in names]
    one = paths["1"].occluded(o, d, t_max)
    other = sum(int((paths[k].occluded(o, d, t_max) != one).sum()) for k in names[1:])
    print("| shadow, camera hits to random points | " + " | ".join(f"{x:.0f}" for x in times) +
          f" | | {times[names.index('16')] / times[names.index('1')]:.2f} | {other} answers differ of "
          f"{o.shape[1]} ({one.mean():.2f} blocked) |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
