"""Embree closest-hit queries by three call paths, ns per ray: embreex, rtcIntersect1 and 16-ray packets.

    python tests/bench/embree_calls.py [--scene glass_sphere] [--res 128] [--spp 16] [--repeats 5]

Side by side in one run, on one scene's Embree scene built the way engine.render.accel builds it
(robust traversal, Embree's default build quality):

- ``embreex``: ``EmbreeScene.run(o, d, output=1)`` (a Cython loop of ``rtcIntersect1`` that allocates
  six result arrays per call, Ng included): what the engine calls without Numba
  (engine.render.accel.EmbreexScene);
- ``rtcIntersect1``: the same Embree library (the one inside the embreex wheel) called per ray from a
  Numba loop through a ctypes function pointer, writing only prim, u, v and t (what the engine does
  with Numba, engine.render.embree_direct, which also reads the float64 rays directly);
- ``rtcIntersect16``: the same from Numba, rays in packets of 16 (Embree's SoA ``RTCRayHit16``).

Rays: the scene's camera rays (pixel-major: each pixel's ``--spp`` samples in a row, as the engine's
batches hold them; and sample-major), and random rays aimed at the scene's first mesh.  Prints ns per
ray, and whether prim and u of the packets equal the ``rtcIntersect1`` ones bit for bit.  Needs
Numba and a Linux embreex wheel (``embreex.libs/libembree4-*.so.4``).  Benchmarks never run as tests.
"""

from __future__ import annotations

import argparse
import ctypes
import glob
import os
import sys
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, REPO)

RTC_SCENE_FLAG_ROBUST = 1 << 2
RTC_BUILD_QUALITY_MEDIUM = 1
RTC_GEOMETRY_TYPE_TRIANGLE = 0
RTC_BUFFER_TYPE_INDEX, RTC_BUFFER_TYPE_VERTEX = 0, 1
RTC_FORMAT_UINT3, RTC_FORMAT_FLOAT3 = 0x5003, 0x9003
INVALID = 0xFFFFFFFF


def embree_library():
    import embreex
    here = os.path.dirname(os.path.dirname(embreex.__file__))
    found = glob.glob(os.path.join(here, "embreex.libs", "libembree4*.so*"))
    if not found:
        raise SystemExit("no libembree4 in the embreex wheel's embreex.libs/ (this bench needs a Linux wheel)")
    vp, sz, c_int = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int
    lib = ctypes.CDLL(found[0])
    for name, res, args in [("rtcNewDevice", vp, [ctypes.c_char_p]), ("rtcNewScene", vp, [vp]),
                            ("rtcSetSceneFlags", None, [vp, c_int]), ("rtcSetSceneBuildQuality", None, [vp, c_int]),
                            ("rtcNewGeometry", vp, [vp, c_int]),
                            ("rtcSetSharedGeometryBuffer", None, [vp, c_int, ctypes.c_uint, c_int, vp, sz, sz, sz]),
                            ("rtcCommitGeometry", None, [vp]), ("rtcAttachGeometry", ctypes.c_uint, [vp, vp]),
                            ("rtcCommitScene", None, [vp])]:
        f = getattr(lib, name)
        f.restype, f.argtypes = res, args
    return lib


def direct_scene(lib, vertices, faces):
    """(RTCScene handle, the arrays Embree shares): robust, default build quality, as accel builds it."""
    dev = lib.rtcNewDevice(None)
    scene = lib.rtcNewScene(dev)
    lib.rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST)
    lib.rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_MEDIUM)
    V = np.zeros((len(vertices), 4), np.float32)         # 16-byte stride, as embreex's TriangleMesh
    V[:, :3] = vertices
    F = np.ascontiguousarray(faces, dtype=np.uint32)
    geom = lib.rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE)
    lib.rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, V.ctypes.data, 0, 16, len(V))
    lib.rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, F.ctypes.data, 0, 12, len(F))
    lib.rtcCommitGeometry(geom)
    lib.rtcAttachGeometry(scene, geom)
    lib.rtcCommitScene(scene)
    return scene, (V, F)


def aligned(n, dtype, alignment):
    buf = np.zeros(n + alignment, dtype)
    off = (-buf.ctypes.data % alignment) // buf.itemsize
    return buf[off:off + n]


def compiled_loops(lib):
    import numba
    sz = ctypes.c_size_t
    one = ctypes.CFUNCTYPE(None, sz, sz, sz)(ctypes.cast(lib.rtcIntersect1, ctypes.c_void_p).value)
    sixteen = ctypes.CFUNCTYPE(None, sz, sz, sz, sz)(ctypes.cast(lib.rtcIntersect16, ctypes.c_void_p).value)

    @numba.njit(nogil=True)
    def trace1(scene, o, d, rh, prim, u, v, t):
        # RTCRayHit: org, tnear, dir, time, tfar, mask, id, flags | Ng, u, v, primID, geomID, instID
        addr = rh.ctypes.data
        ri = rh.view(np.uint32)
        for i in range(o.shape[1]):
            rh[0], rh[1], rh[2], rh[3] = o[0, i], o[1, i], o[2, i], 0.0
            rh[4], rh[5], rh[6], rh[7] = d[0, i], d[1, i], d[2, i], 0.0
            rh[8] = np.float32(1e37)
            ri[9], ri[10], ri[11] = INVALID, 0, 0
            ri[17], ri[18], ri[19] = INVALID, INVALID, INVALID
            one(scene, addr, 0)
            prim[i] = -1 if ri[18] == INVALID else np.int64(ri[17])
            u[i], v[i], t[i] = rh[15], rh[16], rh[8]

    @numba.njit(nogil=True)
    def trace16(scene, o, d, pk, valid, prim, u, v, t):
        # RTCRayHit16: the same fields, each as 16 lanes
        addr, vaddr = pk.ctypes.data, valid.ctypes.data
        pi = pk.view(np.uint32)
        n = o.shape[1]
        for i0 in range(0, n, 16):
            m = min(16, n - i0)
            for k in range(16):
                j = i0 + (k if k < m else 0)
                valid[k] = -1 if k < m else 0
                pk[k], pk[16 + k], pk[32 + k], pk[48 + k] = o[0, j], o[1, j], o[2, j], 0.0
                pk[64 + k], pk[80 + k], pk[96 + k], pk[112 + k] = d[0, j], d[1, j], d[2, j], 0.0
                pk[128 + k] = np.float32(1e37)
                pi[144 + k], pi[160 + k], pi[176 + k] = INVALID, 0, 0
                pi[272 + k], pi[288 + k], pi[304 + k] = INVALID, INVALID, INVALID
            sixteen(vaddr, scene, addr, 0)
            for k in range(m):
                prim[i0 + k] = -1 if pi[288 + k] == INVALID else np.int64(pi[272 + k])
                u[i0 + k], v[i0 + k], t[i0 + k] = pk[240 + k], pk[256 + k], pk[128 + k]

    return trace1, trace16


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="glass_sphere")
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    from engine.render.accel import EmbreexScene
    from engine.render.renderer import Renderer
    from engine.scene.loader import load_scene
    shared = os.environ.get("POLAR_SHARED") or os.path.join(os.path.dirname(REPO), "shared")
    scene = load_scene(os.path.join(shared, "peers", "scenes", f"{args.scene}.json"))
    scene.camera.width = scene.camera.height = args.res
    renderer = Renderer(scene)
    compiled, camera = renderer.compiled, renderer.camera
    lib = embree_library()
    handle, _keep = direct_scene(lib, compiled.vertices, compiled.faces)
    reference = EmbreexScene(compiled.vertices, compiled.faces).embree
    trace1, trace16 = compiled_loops(lib)
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
    rh = aligned(20, np.float32, 16)
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
    print("| rays | embreex run | rtcIntersect1 from Numba | rtcIntersect16 from Numba | 16 ÷ embreex | "
          "prim, u as rtcIntersect1 |")
    print("|---|---|---|---|---|---|")
    for name, (o, d) in ray_sets.items():
        n = o.shape[1]
        o32, d32 = o.astype(np.float32), d.astype(np.float32)
        oT, dT = np.ascontiguousarray(o32.T), np.ascontiguousarray(d32.T)
        out1 = [np.empty(n, np.int64), np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32)]
        out16 = [np.empty_like(a) for a in out1]
        trace1(handle, o32, d32, rh, *out1)
        trace16(handle, o32, d32, pk, valid, *out16)
        t_x = best(n, reference.run, oT, dT, output=1)
        t_1 = best(n, trace1, handle, o32, d32, rh, *out1)
        t_16 = best(n, trace16, handle, o32, d32, pk, valid, *out16)
        same = np.array_equal(out1[0], out16[0]) and np.array_equal(out1[1], out16[1])
        print(f"| {name} | {t_x:.0f} | {t_1:.0f} | {t_16:.0f} | {t_16 / t_x:.2f} | {'yes' if same else 'no'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
