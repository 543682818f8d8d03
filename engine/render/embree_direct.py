"""Embree queried from compiled loops: the Embree library inside the embreex wheel, through its C API.

embreex's ``EmbreeScene.run`` wants float32 (N, 3) copies of the rays and allocates six result arrays per
call (the geometric normal included).  :class:`DirectScene` builds the same scene through Embree's C API
(ctypes) — robust traversal, Embree's default build quality, vertices and triangles copied into Embree's
own buffers with embreex's strides — and queries it from the compiled loops of engine.kernels.rays,
which read the renderer's (3, N) float64 rays directly and call ``rtcIntersect1`` / ``rtcOccluded1`` per
ray with the ray set up as embreex sets it up.  The hits are embreex's bit for bit (triangle, distance
and barycentrics of every hit ray; tests/render/test_accel.py); a miss's barycentrics mean nothing in either.

The library is the one embreex itself loaded: ``embreex.libs/`` (Linux and Windows wheels) or
``embreex/.dylibs/`` (macOS).  :func:`library` returns None where it is not found; the scene is then
embreex's (engine.render.accel).
"""

from __future__ import annotations

import ctypes
import functools
import glob
import os
import weakref

import numpy as np

from ..kernels.rays import closest_hits_loop, occluded_loop

_ROBUST = 1 << 2                   # RTC_SCENE_FLAG_ROBUST
_TRIANGLE = 0                      # RTC_GEOMETRY_TYPE_TRIANGLE
_INDEX, _VERTEX = 0, 1             # RTC_BUFFER_TYPE_*
_UINT3, _FLOAT3 = 0x5003, 0x9003   # RTC_FORMAT_*
#: float32 words of an RTCRayHit buffer (80 bytes in Embree 4; room for optional instance fields)
_RAYHIT_WORDS = 32


def _candidates() -> list[str]:
    import embreex
    package = os.path.dirname(os.path.abspath(embreex.__file__))
    site = os.path.dirname(package)
    libs = os.path.join(site, "embreex.libs")
    patterns = [os.path.join(libs, "libembree4*.so*"), os.path.join(libs, "embree4*.dll"),
                os.path.join(package, ".dylibs", "libembree4*.dylib")]
    return sorted(path for pattern in patterns for path in glob.glob(pattern))


@functools.cache
def library():
    """The ctypes handle of embreex's Embree library with the functions used here typed, or None."""
    vp, sz, c_int = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int
    for path in _candidates():
        try:
            lib = ctypes.CDLL(path)
            for name, res, args in [("rtcNewDevice", vp, [ctypes.c_char_p]), ("rtcReleaseDevice", None, [vp]),
                                    ("rtcNewScene", vp, [vp]), ("rtcReleaseScene", None, [vp]),
                                    ("rtcSetSceneFlags", None, [vp, c_int]),
                                    ("rtcNewGeometry", vp, [vp, c_int]), ("rtcReleaseGeometry", None, [vp]),
                                    ("rtcSetNewGeometryBuffer", vp, [vp, c_int, ctypes.c_uint, c_int, sz, sz]),
                                    ("rtcCommitGeometry", None, [vp]), ("rtcAttachGeometry", ctypes.c_uint, [vp, vp]),
                                    ("rtcCommitScene", None, [vp])]:
                f = getattr(lib, name)
                f.restype, f.argtypes = res, args
            address = ctypes.cast(lib.rtcIntersect1, vp).value, ctypes.cast(lib.rtcOccluded1, vp).value
        except (OSError, AttributeError):
            continue
        # (scene, ray, arguments) as integers: the compiled loops pass the buffer's address
        query = ctypes.CFUNCTYPE(None, sz, sz, sz)
        lib.intersect1, lib.occluded1 = query(address[0]), query(address[1])
        return lib
    return None


def _release(lib, scene, device):
    lib.rtcReleaseScene(scene)
    lib.rtcReleaseDevice(device)


class DirectScene:
    """One triangle mesh (vertices (V, 3), triangles (F, 3)) as an Embree scene queried from compiled loops;
    the queries of embreex's ``EmbreeScene.run``, the same numbers."""

    def __init__(self, lib, vertices: np.ndarray, faces: np.ndarray):
        self._lib = lib
        device = lib.rtcNewDevice(None)
        scene = lib.rtcNewScene(device)
        self._finalizer = weakref.finalize(self, _release, lib, scene, device)
        lib.rtcSetSceneFlags(scene, _ROBUST)
        geom = lib.rtcNewGeometry(device, _TRIANGLE)
        n_v, n_f = len(vertices), len(faces)
        v = lib.rtcSetNewGeometryBuffer(geom, _VERTEX, 0, _FLOAT3, 16, n_v)
        f = lib.rtcSetNewGeometryBuffer(geom, _INDEX, 0, _UINT3, 12, n_f)
        if n_v:
            V = np.ctypeslib.as_array(ctypes.cast(v, ctypes.POINTER(ctypes.c_float)), shape=(n_v, 4))
            V[:, :3] = np.asarray(vertices, np.float32)
            V[:, 3] = 0.0
        if n_f:
            np.ctypeslib.as_array(ctypes.cast(f, ctypes.POINTER(ctypes.c_uint32)), shape=(n_f, 3))[:] = faces
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometry(scene, geom)
        lib.rtcReleaseGeometry(geom)
        lib.rtcCommitScene(scene)
        self.handle = scene

    @staticmethod
    def _rayhit() -> np.ndarray:
        """A 16-byte aligned float32 RTCRayHit buffer (one per call: calls run in parallel threads)."""
        buf = np.zeros(_RAYHIT_WORDS + 4, np.float32)
        start = (-buf.ctypes.data % 16) // 4
        return buf[start:start + _RAYHIT_WORDS]

    def closest(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray | None, prims: np.ndarray | None):
        """(prim (N,) int64, −1 = miss, mapped through ``prims`` unless None; u, v, t (N,) float64)."""
        n = o.shape[1]
        prim, u, v, t = np.empty(n, np.int64), np.empty(n), np.empty(n), np.empty(n)
        has_t = t_max is not None
        closest_hits_loop(self._lib.intersect1, self.handle, self._rayhit(), np.asarray(o, np.float64),
                          np.asarray(d, np.float64), np.asarray(t_max, np.float64) if has_t else np.empty(0), has_t,
                          prims if prims is not None else np.empty(0, np.int64), prims is not None, prim, u, v, t)
        return prim, u, v, t

    def occluded(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray) -> np.ndarray:
        """True where the segment o → o + t_max·d is blocked."""
        blocked = np.empty(o.shape[1], np.bool_)
        occluded_loop(self._lib.occluded1, self.handle, self._rayhit(), np.asarray(o, np.float64),
                      np.asarray(d, np.float64), np.asarray(t_max, np.float64), blocked)
        return blocked
