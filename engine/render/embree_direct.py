"""Embree queried from compiled loops: the Embree library inside the embreex wheel, through its C API.

embreex's ``EmbreeScene.run`` wants float32 (N, 3) copies of the rays and allocates six result arrays per
call (the geometric normal included).  :class:`DirectScene` builds the same scene through Embree's C API
(ctypes) — robust traversal, Embree's default build quality, vertices and triangles copied into Embree's
own buffers with embreex's strides — and queries it from the compiled loops of engine.kernels.rays,
which read the renderer's (3, N) float64 rays directly and call ``rtcIntersect16`` / ``rtcOccluded16`` on
packets of 16 rays (or ``rtcIntersect1`` / ``rtcOccluded1`` per ray), each ray set up as embreex sets it
up.  The hits are embreex's bit for bit either way (triangle, distance and barycentrics of every hit ray,
the shadow answers; tests/render/test_accel.py); a miss's barycentrics mean nothing in either.  Packets
cost 6–21 % less a ray by its kind (docs/benchmarks.md, tests/bench/embree_calls.py).

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

from ..kernels.rays import closest_hits_loop, occluded_loop, packet_queries

_COMPACT, _ROBUST = 1 << 1, 1 << 2   # RTC_SCENE_FLAG_*
_COHERENT = 1                        # RTC_RAY_QUERY_FLAG_COHERENT (0: incoherent)
_ALL_FEATURES = 0xFFFFFFFF           # RTC_FEATURE_FLAG_ALL
_TRIANGLE = 0                        # RTC_GEOMETRY_TYPE_TRIANGLE
_INDEX, _VERTEX = 0, 1               # RTC_BUFFER_TYPE_*
_UINT3, _FLOAT3 = 0x5003, 0x9003     # RTC_FORMAT_*
#: float32 words a lane of an RTCRayHit(W) buffer (20 in Embree 4; room for optional instance fields)
_RAYHIT_WORDS = 32
#: rays per query: packets of 16 (rtcIntersect16 / rtcOccluded16; 4 and 8 measured slower, 1: one-ray queries)
PACKET = 16


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
                                    ("rtcCommitScene", None, [vp]),
                                    ("rtcSetSceneBuildQuality", None, [vp, c_int])]:
                f = getattr(lib, name)
                f.restype, f.argtypes = res, args
            address = {(query, w): ctypes.cast(getattr(lib, f"rtc{query}{w}"), vp).value
                       for query in ("Intersect", "Occluded") for w in (1, 4, 8, 16)}
        except (OSError, AttributeError):
            continue
        # (scene, ray, arguments) as integers: the compiled loops pass the buffer's address
        one = ctypes.CFUNCTYPE(None, sz, sz, sz)
        lib.intersect1, lib.occluded1 = one(address["Intersect", 1]), one(address["Occluded", 1])
        # (valid, scene, ray packet, arguments): rtcIntersectW / rtcOccludedW by width W
        packet = ctypes.CFUNCTYPE(None, sz, sz, sz, sz)
        lib.intersect = {w: packet(address["Intersect", w]) for w in (4, 8, 16)}
        lib.occluded = {w: packet(address["Occluded", w]) for w in (4, 8, 16)}
        return lib
    return None


def _release(lib, scene, device):
    lib.rtcReleaseScene(scene)
    lib.rtcReleaseDevice(device)


def _aligned(n: int, dtype) -> np.ndarray:
    """A zeroed (n,) array whose data is 64-byte aligned (Embree's RTCRayHit16 alignment)."""
    buf = np.zeros(n + 64, dtype)
    start = (-buf.ctypes.data % 64) // buf.itemsize
    return buf[start:start + n]


def _arguments(flags: int, features: int) -> np.ndarray:
    """An RTCIntersectArguments / RTCOccludedArguments buffer: query flags, feature mask, no context,
    filter or user-geometry callback (room for optional fields)."""
    args = np.zeros(8, np.uint64)
    words = args.view(np.uint32)
    words[0], words[1] = flags, features
    return args


class DirectScene:
    """One triangle mesh (vertices (V, 3), triangles (F, 3)) as an Embree scene queried from compiled loops;
    the queries of embreex's ``EmbreeScene.run``: the same numbers bit for bit in one-ray queries (``width`` 1) and
    in packets of ``width`` 4, 8 or 16 rays.  ``scene_flags``, ``quality`` (an RTCBuildQuality,
    None: Embree's default), ``features`` (the queries' RTCFeatureFlags) and ``config`` (rtcNewDevice's
    configuration string) are Embree's settings (the defaults: measured best, tests/bench/embree_calls.py)."""

    def __init__(self, lib, vertices: np.ndarray, faces: np.ndarray, width: int = PACKET,
                 scene_flags: int = _ROBUST, quality: int | None = None, features: int = _ALL_FEATURES,
                 config: str | None = None):
        self._lib = lib
        self.width = width
        self._features = features
        device = lib.rtcNewDevice(config.encode() if config else None)
        scene = lib.rtcNewScene(device)
        self._finalizer = weakref.finalize(self, _release, lib, scene, device)
        lib.rtcSetSceneFlags(scene, scene_flags)
        if quality is not None:
            lib.rtcSetSceneBuildQuality(scene, quality)
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

    def _buffers(self):
        """(valid (W,) int32, RTCRayHitW float32) for one call (calls run in parallel threads)."""
        w = self.width
        return _aligned(w, np.int32), _aligned(_RAYHIT_WORDS * w, np.float32)

    def closest(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray | None, prims: np.ndarray | None,
                coherent: bool = False):
        """(prim (N,) int64, −1 = miss, mapped through ``prims`` unless None; u, v, t (N,) float64).
        ``coherent``: rays of neighbouring pixels in a row (Embree's coherent query flag)."""
        n = o.shape[1]
        prim, u, v, t = np.empty(n, np.int64), np.empty(n), np.empty(n), np.empty(n)
        has_t = t_max is not None
        o, d = np.asarray(o, np.float64), np.asarray(d, np.float64)
        t_max = np.asarray(t_max, np.float64) if has_t else np.empty(0)
        mapped = prims is not None
        prims = prims if mapped else np.empty(0, np.int64)
        valid, rh = self._buffers()
        if self.width == 1:
            closest_hits_loop(self._lib.intersect1, self.handle, rh, o, d, t_max, has_t, prims, mapped, prim, u, v, t)
        else:
            args = _arguments(_COHERENT if coherent else 0, self._features)
            packet_queries(self._lib.intersect[self.width], self.handle, valid, rh, args, o, d, t_max, has_t, False,
                           prims, mapped, prim, u, v, t, np.empty(0, np.bool_))
        return prim, u, v, t

    def occluded(self, o: np.ndarray, d: np.ndarray, t_max: np.ndarray) -> np.ndarray:
        """True where the segment o → o + t_max·d is blocked."""
        blocked = np.empty(o.shape[1], np.bool_)
        o, d, t_max = np.asarray(o, np.float64), np.asarray(d, np.float64), np.asarray(t_max, np.float64)
        valid, rh = self._buffers()
        if self.width == 1:
            occluded_loop(self._lib.occluded1, self.handle, rh, o, d, t_max, blocked)
        else:
            empty = np.empty(0)
            packet_queries(self._lib.occluded[self.width], self.handle, valid, rh, _arguments(0, self._features),
                           o, d, t_max, True, True, np.empty(0, np.int64), False, np.empty(0, np.int64), empty, empty,
                           empty, blocked)
        return blocked
