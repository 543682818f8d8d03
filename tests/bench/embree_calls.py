"""Embree closest-hit queries by three call paths, ns per ray: embreex, the engine's compiled loop, 16-ray packets.

    python tests/bench/embree_calls.py [--scene glass_sphere] [--res 128] [--spp 16] [--repeats 5]

Side by side in one run, on one scene's geometry (robust traversal, Embree's default build quality),
each from the renderer's (3, N) float64 rays to its (prim, u, v, t) float64 hits:

- ``embreex``: engine.render.accel.EmbreexScene.closest, what the engine calls without Numba (float32
  (N, 3) copies of the rays, embreex's ``run`` — a Cython loop of ``rtcIntersect1`` that allocates six
  result arrays per call, Ng included — and the conversion of its results);
- ``rtcIntersect1``: engine.render.embree_direct.DirectScene.closest, what the engine calls with Numba (the
  embreex wheel's own ``libembree4`` called per ray from a compiled loop through a ctypes function pointer);
- ``rtcIntersect16``: the same scene from a compiled loop here, rays in packets of 16 (Embree's SoA
  ``RTCRayHit16``); not used by the engine.

Rays: the scene's camera rays (pixel-major: each pixel's ``--spp`` samples in a row, as the engine's
batches hold them; and sample-major), and random rays aimed at the scene's first mesh.  Prints ns per
ray, and whether the packets' prim and u equal the one-ray query's bit for bit.  Needs Numba and the
Embree library next to embreex (engine.render.embree_direct.library).  Benchmarks never run as tests.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import sys
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, REPO)

INVALID = 0xFFFFFFFF


def aligned(n, dtype, alignment):
    buf = np.zeros(n + alignment, dtype)
    off = (-buf.ctypes.data % alignment) // buf.itemsize
    return buf[off:off + n]


def packet_loop(lib):
    """A compiled loop querying ``rtcIntersect16`` (the same ray set-up and casts as the engine's one-ray loop)."""
    import numba
    sz = ctypes.c_size_t
    sixteen = ctypes.CFUNCTYPE(None, sz, sz, sz, sz)(ctypes.cast(lib.rtcIntersect16, ctypes.c_void_p).value)

    @numba.njit(nogil=True)
    def trace16(scene, o, d, pk, valid, prim, u, v, t):
        # RTCRayHit16: org, tnear, dir, time, tfar, mask, id, flags | Ng, u, v, primID, geomID, instID; 16 lanes each
        addr, vaddr = pk.ctypes.data, valid.ctypes.data
        pi = pk.view(np.uint32)
        n = o.shape[1]
        for i0 in range(0, n, 16):
            m = min(16, n - i0)
            for k in range(16):
                j = i0 + (k if k < m else 0)
                valid[k] = -1 if k < m else 0
                pk[k], pk[16 + k], pk[32 + k] = np.float32(o[0, j]), np.float32(o[1, j]), np.float32(o[2, j])
                pk[64 + k], pk[80 + k], pk[96 + k] = np.float32(d[0, j]), np.float32(d[1, j]), np.float32(d[2, j])
                pk[48 + k], pk[112 + k], pk[128 + k] = 0.0, 0.0, np.float32(1e37)
                pi[144 + k], pi[160 + k], pi[176 + k] = INVALID, 0, 0
                pi[272 + k], pi[288 + k], pi[304 + k] = INVALID, INVALID, INVALID
            sixteen(vaddr, scene, addr, 0)
            for k in range(m):
                prim[i0 + k] = -1 if pi[288 + k] == INVALID else np.int64(pi[272 + k])
                u[i0 + k], v[i0 + k], t[i0 + k] = pk[240 + k], pk[256 + k], pk[128 + k]

    return sixteen, trace16


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="glass_sphere")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    from engine.render.accel import EmbreexScene
    from engine.render.embree_direct import DirectScene, library
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
    reference = EmbreexScene(compiled.vertices, compiled.faces)
    direct = DirectScene(lib, compiled.vertices, compiled.faces)
    _, trace16 = packet_loop(lib)
    rng = np.random.default_rng(0)
    n_pix = args.res * args.res
    mesh = scene.meshes[0]
    centre, radius = mesh.vertices.mean(axis=0)[:, None], np.ptp(mesh.vertices, axis=0).max() / 2
    o = rng.normal(size=(3, n_pix * args.spp))
    o = centre + 3 * radius * o / np.linalg.norm(o, axis=0)
    d = centre + 0.5 * radius * rng.normal(size=o.shape) - o
    ray_sets = {}
    for name, pixels in [("camera, pixel-major", np.repeat(np.arange(n_pix), args.spp)),
                         ("camera, sample-major", np.tile(np.arange(n_pix), args.spp))]:
        oc, dc, *_ = camera.generate(pixels, rng.random((2, pixels.size)))
        ray_sets[name] = (oc, dc)
    ray_sets["random, at the first mesh"] = (o, d / np.linalg.norm(d, axis=0))
    pk, valid = aligned(320, np.float32, 64), aligned(16, np.int32, 64)

    def best(n, f, *call_args, **kw):
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            f(*call_args, **kw)
            times.append(time.perf_counter() - t0)
        return min(times) / n * 1e9

    print(f"{args.scene}, {len(compiled.faces)} triangles, {args.res}² × {args.spp} rays per set; ns per ray "
          f"(fastest of {args.repeats}):\n")
    print("| rays | embreex | rtcIntersect1 (the engine) | rtcIntersect16 | 1 ÷ embreex | 16 ÷ embreex | "
          "packets' prim, u as one ray's |")
    print("|---|---|---|---|---|---|---|")
    for name, (o, d) in ray_sets.items():
        n = o.shape[1]
        out1 = direct.closest(o, d, None, None)
        out16 = [np.empty(n, np.int64), np.empty(n), np.empty(n), np.empty(n)]
        trace16(direct.handle, o, d, pk, valid, *out16)
        t_x = best(n, reference.closest, o, d, None, None)
        t_1 = best(n, direct.closest, o, d, None, None)
        t_16 = best(n, trace16, direct.handle, o, d, pk, valid, *out16)
        same = np.array_equal(out1[0], out16[0]) and np.array_equal(out1[1], out16[1])
        print(f"| {name} | {t_x:.0f} | {t_1:.0f} | {t_16:.0f} | {t_1 / t_x:.2f} | {t_16 / t_x:.2f} | "
              f"{'yes' if same else 'no'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
