"""Data passes and Cryptomatte as Cycles writes them, from the renderer's own camera rays.

``render_data_passes(renderer, DataPassRequest(...))`` traces the first hits of the camera rays of samples
0 … n − 1 of every pixel — the rays of the render's own first samples: the same camera model, pixel
jitter (box filter) and lens numbers as the integrator (engine.render.sampler), so the result is a
function of (scene, seed, n) only, whatever the threads — through the compiled scene (engine.render.accel),
and fills the passes Cycles' film_write_data_passes fills, by Cycles' rules (kernel/film/data_passes.h,
read.h):

- **first sample only, no filter** (overwritten, not averaged): Depth (z along the camera axis; distance for
  panoramas; 1e10 where sample 0 saw the background), Position (world; 0), Object Index, Material Index
  (pass indices; 0) — at the first surface whose alpha ≥ ``alpha_threshold`` (Cycles' Alpha Threshold).
- **averaged over the samples**: Normal (world shading normal turned towards the camera, not renormalised;
  background samples add 0), UV ((u, v, 1) of the UV map, (0, 0, 0) without one) at that same surface;
  Mist 1 − mean of Σ T·α·(1 − m(d)) over the surfaces a sample crosses (m: the World's mist ramp over the
  camera distance d, falloff 2 / 1 / ½), so the background is 1; Vector (motion in pixels towards the
  previous frame (x, y) and from the next (z, w), raster y up) averaged over the samples that hit.
- **Cryptomatte**: each surface adds its coverage T·α (T: what earlier pass-through surfaces let through)
  to its object's, material's and asset's id; per pixel the ids ranked by coverage ÷ samples, the first
  ``cryptomatte_levels`` kept (engine.output.cryptomatte).

Camera-hidden surfaces are skipped, holdout surfaces end the ray (nothing written), pass-through (alpha)
surfaces are crossed deterministically with the weight 1 − α (the expectation of Cycles' random transparent
bounces).  Nothing here runs unless a pass is requested; the render's image is unchanged.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..output import cryptomatte as cm
from ..scene.description import Camera, Scene
from .accel import RAY_EPSILON, CompiledScene
from .camera import CameraModel
from .sampler import camera_numbers
from ..scene.description import resolve_halves
from .visibility import MAX_PASS_THROUGH, ray_visibility

#: Requestable data passes → (Blender/Cycles pass name, channel names)
DATA_PASSES = {
    "depth": ("Depth", "Z"), "mist": ("Mist", "Z"), "normal": ("Normal", "XYZ"), "position": ("Position", "XYZ"),
    "uv": ("UV", "UVA"), "vector": ("Vector", "XYZW"), "object_index": ("Object Index", "X"),
    "material_index": ("Material Index", "X"),
}
#: Requestable Cryptomatte layers → the kind they hash (engine.output.cryptomatte.KINDS)
CRYPTOMATTE_PASSES = {"crypto_object": "object", "crypto_material": "material", "crypto_asset": "asset"}
ALL_PASSES = tuple(DATA_PASSES) + tuple(CRYPTOMATTE_PASSES)
#: Blender's World ▸ Mist Pass ▸ Falloff → Cycles' exponent
MIST_FALLOFF = {"quadratic": 2.0, "linear": 1.0, "inverse_quadratic": 0.5}
#: Depth where sample 0 saw the background (Cycles' film_get_pass_pixel_depth)
BACKGROUND_DEPTH = 1e10
#: Samples per pixel of the data passes when the request does not say: min(spp, this)
DEFAULT_SAMPLES = 64
#: Camera rays per traced chunk
BATCH_RAYS = 1 << 16


@dataclass(frozen=True)
class Mist:
    """The World's mist settings: ``start`` ≥ 0 and ``depth`` ≥ 0 (scene units) of the ramp, ``falloff``
    one of MIST_FALLOFF (Blender's defaults 5, 25, quadratic)."""

    start: float = 5.0
    depth: float = 25.0
    falloff: str = "quadratic"

    def __post_init__(self):
        for name in ("start", "depth"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
                raise ValueError(f"mist.{name} must be a finite number ≥ 0, got {v!r}")
        if self.falloff not in MIST_FALLOFF:
            raise ValueError(f"mist.falloff must be one of {', '.join(MIST_FALLOFF)}, got {self.falloff!r}")

    def ramp(self, distance: np.ndarray) -> np.ndarray:
        """m(d) in [0, 1] (Cycles: saturate((d − start)/depth)^falloff; depth 0 gives 0)."""
        inv = 1.0 / self.depth if self.depth > 0 else 0.0
        m = np.clip((distance - self.start) * inv, 0.0, 1.0)
        return m ** MIST_FALLOFF[self.falloff]


@dataclass(frozen=True)
class Motion:
    """What the Vector pass needs: the cameras of the previous and the next frame (None: this frame's) and,
    per mesh of the scene (in order), its world-space vertex positions at those frames (None, or a None
    entry: the mesh does not move)."""

    camera_pre: Camera | None = None
    camera_post: Camera | None = None
    positions_pre: tuple | None = None
    positions_post: tuple | None = None


@dataclass(frozen=True)
class DataPassRequest:
    """Which passes (names of ALL_PASSES), Cryptomatte ``cryptomatte_levels`` (2 … 16, Cycles' default 6),
    the World's ``mist``, Cycles' ``alpha_threshold`` in [0, 1], ``samples`` per pixel (None:
    min(spp, DEFAULT_SAMPLES)) and the Vector pass's ``motion`` (None: nothing moves)."""

    passes: frozenset = field(default_factory=frozenset)
    cryptomatte_levels: int = 6
    mist: Mist = field(default_factory=Mist)
    alpha_threshold: float = 0.5
    samples: int | None = None
    motion: Motion | None = None

    def __post_init__(self):
        passes = frozenset(self.passes)
        unknown = sorted(passes - set(ALL_PASSES))
        if unknown:
            raise ValueError(f"data passes: unknown {', '.join(unknown)}; allowed: {', '.join(ALL_PASSES)}")
        object.__setattr__(self, "passes", passes)
        cm.check_levels(self.cryptomatte_levels)
        a = self.alpha_threshold
        if not isinstance(a, (int, float)) or not 0.0 <= a <= 1.0:
            raise ValueError(f"alpha_threshold must be a number in [0, 1], got {a!r}")
        if self.samples is not None and (isinstance(self.samples, bool) or not isinstance(self.samples, int)
                                         or not 1 <= self.samples <= 1 << 24):
            raise ValueError(f"data pass samples must be an integer in [1, 2^24], got {self.samples!r}")

    def samples_for(self, spp: int) -> int:
        """Samples per pixel the passes use with a render of ``spp``."""
        return self.samples if self.samples is not None else max(1, min(int(spp), DEFAULT_SAMPLES))


@dataclass
class DataPasses:
    """The result: ``images`` {Blender pass name: (H, W, C) float32} (C = len of its channels),
    ``cryptomatte`` {layer ("CryptoObject" …): [RGBA passes (H, W, 4) float32]}, ``names`` {layer: names
    in the manifest}, ``samples`` per pixel used; H, W the window's (the whole image without one)."""

    images: dict
    cryptomatte: dict
    names: dict
    samples: int

    def channels(self) -> dict:
        """EXR channels {"<Pass>.<Channel>": (H, W) float32}: "Depth.Z", "Normal.X" …, "Object Index.X",
        "CryptoObject00.r" … (Blender's pass and channel names)."""
        out = {}
        for name, img in self.images.items():
            for i, c in enumerate(_CHANNELS[name]):
                out[f"{name}.{c}"] = np.ascontiguousarray(img[..., i], np.float32)
        for layer, passes in self.cryptomatte.items():
            for k, p in enumerate(passes):
                for i, c in enumerate("rgba"):
                    out[f"{layer}{k:02d}.{c}"] = np.ascontiguousarray(p[..., i], np.float32)
        return out

    def metadata(self, prefix: str = "") -> dict:
        """The Cryptomatte header strings of every layer, its name ``prefix`` + layer (Blender:
        "<ViewLayer>." — a standalone EXR: "")."""
        out = {}
        for layer in self.cryptomatte:
            out.update(cm.layer_metadata(prefix + layer, self.names[layer]))
        return out


_CHANNELS = {name: channels for name, channels in DATA_PASSES.values()}


class _Identity:
    """Per-mesh and per-material identity tables of a scene (names, pass indices, Cryptomatte id indices)."""

    def __init__(self, scene: Scene, compiled: CompiledScene):
        meshes = scene.meshes
        self.object_names = [m.object_name or m.name for m in meshes]
        self.asset_names = [m.asset_name or o for m, o in zip(meshes, self.object_names)]
        self.pass_index = np.array([int(m.pass_index) for m in meshes], np.float64)
        names, indices = {}, {}
        for m in meshes:
            mnames = m.material_names or list(m.materials)
            mpass = m.material_pass_indices or [0] * len(m.materials)
            for key, name, index in zip(m.materials, mnames, mpass):
                names.setdefault(key, name)
                indices.setdefault(key, int(index))
        keys = compiled.material_names
        self.material_names = [names.get(k, k) for k in keys]
        self.material_pass = np.array([indices.get(k, 0) for k in keys], np.float64)
        used_meshes = np.unique(compiled.tri_mesh)
        # the names each layer's ids index (those of the meshes and materials some triangle has)
        self.layer_names = {}
        self.mesh_id, self.material_id = {}, None
        for kind, per_mesh in (("object", self.object_names), ("asset", self.asset_names)):
            table = list(dict.fromkeys(per_mesh[i] for i in used_meshes))
            lookup = {n: i for i, n in enumerate(table)}
            self.layer_names[kind] = table
            self.mesh_id[kind] = np.array([lookup.get(n, -1) for n in per_mesh], np.int64)
        table = list(dict.fromkeys(self.material_names[i] for i in compiled.used_materials))
        lookup = {n: i for i, n in enumerate(table)}
        self.layer_names["material"] = table
        self.material_id = np.array([lookup.get(n, -1) for n in self.material_names], np.int64)

    def ids(self, kind: str, mesh: np.ndarray, material: np.ndarray) -> np.ndarray:
        return self.material_id[material] if kind == "material" else self.mesh_id[kind][mesh]


def _merged_uv(scene: Scene, compiled: CompiledScene) -> tuple[np.ndarray | None, np.ndarray]:
    """(per-vertex UV (V, 2) in the compiled numbering or None, per-mesh has-a-UV-map (M,) bool)."""
    has = np.array([(m.pass_uv if m.pass_uv is not None else m.uv) is not None for m in scene.meshes], bool)
    if not has.any():
        return None, has
    out = np.zeros((len(compiled.vertices), 2))
    offset = 0
    for m in scene.meshes:
        uv = m.pass_uv if m.pass_uv is not None else m.uv
        n = len(m.vertices)
        if uv is not None:
            out[offset:offset + n] = np.asarray(uv, np.float64)[:, :2]
        offset += n
    return out, has


def _merged_positions(scene: Scene, compiled: CompiledScene, positions) -> np.ndarray:
    """World positions (V, 3) at another frame in the compiled numbering (this frame's where not given)."""
    out = compiled.vertices.copy()
    if positions is None:
        return out
    if len(positions) != len(scene.meshes):
        raise ValueError(f"motion positions: one entry per mesh ({len(scene.meshes)}), got {len(positions)}")
    offset = 0
    for m, p in zip(scene.meshes, positions):
        n = len(m.vertices)
        if p is not None:
            p = np.asarray(p, np.float64)
            if p.shape != (n, 3):
                raise ValueError(f"motion positions of mesh {m.name!r}: shape ({n}, 3) expected, got {p.shape}")
            out[offset:offset + n] = p
        offset += n
    return out


def _add(out: np.ndarray, index: np.ndarray, values: np.ndarray) -> None:
    """out[index] += values, summing repeated indices (np.add.at's result, by np.bincount: far faster);
    ``values`` (n,) or (n, C) for ``out`` (P,) or (P, C)."""
    n = out.shape[0]
    if values.ndim == 1:
        out += np.bincount(index, weights=values, minlength=n)
    else:
        for c in range(values.shape[1]):
            out[:, c] += np.bincount(index, weights=values[:, c], minlength=n)


def _reduce(pixel: np.ndarray, ident: np.ndarray, weight: np.ndarray, n_pix: int, n_ids: int) -> tuple:
    """(pixel, id, summed weight) of every (pixel, id) pair with weight (the matte samples of a chunk)."""
    key = pixel.astype(np.int64) * n_ids + ident
    if n_pix * n_ids <= max(1 << 20, 4 * key.size):
        total = np.bincount(key, weights=weight, minlength=n_pix * n_ids)
        unique = np.flatnonzero(total)
        return unique // n_ids, unique % n_ids, total[unique]
    unique, inverse = np.unique(key, return_inverse=True)
    return unique // n_ids, unique % n_ids, np.bincount(inverse, weights=weight)


def raster(model: CameraModel, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Raster coordinates (x right, y up from the image's bottom, in pixels) of world points p (3, N) seen by
    ``model`` (Cycles' worldtoraster; equirectangular: longitude/latitude over the image)."""
    cam = model.cam
    W, H = cam.width, cam.height
    q = p - model.origin[:, None]
    qf = model.forward @ q
    qr = model.right @ q
    qu = model.up @ q
    if cam.projection == "equirectangular":
        length = np.sqrt(qf ** 2 + qr ** 2 + qu ** 2)
        psi = np.arctan2(qr, qf)
        lam = np.arcsin(np.clip(qu / np.where(length > 0, length, 1.0), -1.0, 1.0))
        lon0, lon1 = (math.radians(a) for a in cam.longitude_deg)
        lat0, lat1 = (math.radians(a) for a in cam.latitude_deg)
        return (psi - lon0) / (lon1 - lon0) * W, (lam - lat0) / (lat1 - lat0) * H
    if cam.projection == "perspective":
        z = np.where(qf != 0, qf, 1e-30)
        qr, qu = qr / z, qu / z
    return (W / 2 * (qr / model.tx + 1 - 2 * model.shift_x),
            H / 2 * (qu / model.ty + 1 - 2 * model.shift_y))


class _Tracer:
    """The first-hit tracing of one request over a scene (shared by the worker threads: read-only)."""

    def __init__(self, scene: Scene, compiled: CompiledScene, camera: CameraModel, request: DataPassRequest,
                 seed: int, sampler: str, pixels: np.ndarray, halves: str = "independent"):
        self.scene, self.compiled, self.camera, self.request = scene, compiled, camera, request
        self.pixels = pixels            # flat indices of the window's pixels (row-major)
        self.seed, self.sampler, self.halves = seed, sampler, halves
        self.passes = request.passes
        self.vis = ray_visibility(compiled)
        self.identity = _Identity(scene, compiled)
        self.kinds = [CRYPTOMATTE_PASSES[p] for p in ALL_PASSES if p in self.passes and p in CRYPTOMATTE_PASSES]
        self.uv, self.has_uv = _merged_uv(scene, compiled) if "uv" in self.passes else (None, None)
        if self.uv is not None:
            self.uv = self.uv[compiled.faces]            # per triangle corner (F, 3, 2)
        self.motion = None        # Vector's (positions before, after, cameras before, after); None: static
        motion = request.motion
        if "vector" in self.passes and motion is not None and any(
                x is not None for x in (motion.camera_pre, motion.camera_post, motion.positions_pre,
                                        motion.positions_post)):
            self.motion = (_merged_positions(scene, compiled, motion.positions_pre)[compiled.faces],
                           _merged_positions(scene, compiled, motion.positions_post)[compiled.faces],
                           CameraModel(motion.camera_pre) if motion.camera_pre is not None else camera,
                           CameraModel(motion.camera_post) if motion.camera_post is not None else camera)

    def rays(self, pixel: np.ndarray, sample: np.ndarray):
        """The integrator's camera rays of (pixel, sample) (engine.render.integrator._camera_paths)."""
        _, u = camera_numbers(self.seed, self.sampler, pixel, sample, self.camera.lens_dimensions, 0, self.halves)
        o, d, _, t_min, t_max = self.camera.generate(pixel, u)
        t_min = np.asarray(t_min, np.float64)
        t_max = np.asarray(t_max, np.float64)
        if np.any(t_min > 0):
            o = o + d * t_min[None, :]
            t_max = t_max - t_min
        return o, d, t_max

    def _interpolate(self, corners: np.ndarray, prim: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Per-vertex values at the hits, from their per-triangle ``corners`` (F, 3, C) (one gather per hit)."""
        c = corners[prim]
        return c[:, 0] * (1 - u - v)[:, None] + c[:, 1] * u[:, None] + c[:, 2] * v[:, None]

    def __call__(self, chunk: np.ndarray, n_samples: int) -> dict:
        """Sums of the pixels ``chunk`` (local indices into the window's pixel list ``self.pixels``) over
        ``n_samples`` samples each."""
        passes, compiled, vis, request = self.passes, self.compiled, self.vis, self.request
        n_pix = chunk.size
        local = np.repeat(np.arange(n_pix), n_samples)
        sample = np.tile(np.arange(n_samples, dtype=np.int64), n_pix)
        pixel = self.pixels[chunk][local]
        o, d, t_max = self.rays(pixel, sample)
        n = pixel.size
        out = {"normal": np.zeros((n_pix, 3)), "uv": np.zeros((n_pix, 3)), "vector": np.zeros((n_pix, 4)),
               "vector_weight": np.zeros(n_pix), "mist": np.zeros(n_pix), "depth": np.full(n_pix, BACKGROUND_DEPTH),
               "position": np.zeros((n_pix, 3)), "object_index": np.zeros(n_pix), "material_index": np.zeros(n_pix),
               "crypto": {kind: [] for kind in self.kinds}}
        T = np.ones(n)
        done = np.zeros(n, bool)
        active = np.arange(n)
        threshold = request.alpha_threshold
        for _ in range(MAX_PASS_THROUGH + 1):
            if active.size == 0:
                break
            hits = compiled.intersect(o[:, active], d[:, active], t_max[active])
            got = hits.prim >= 0
            active, prim, hu, hv, t = active[got], hits.prim[got], hits.u[got], hits.v[got], hits.t[got]
            if active.size == 0:
                break
            mesh = compiled.tri_mesh[prim]
            material = compiled.tri_material[prim]
            hidden = vis.camera_hidden[mesh] if vis is not None else np.zeros(active.size, bool)
            holdout = vis.holdout[mesh] if vis is not None else np.zeros(active.size, bool)
            alpha = vis.alpha_at(mesh, prim, hu, hv) if vis is not None and vis.any_alpha else np.ones(active.size)
            alpha = np.where(hidden, 0.0, alpha)
            surface = ~hidden & ~holdout
            p, n_g, n_s = compiled.surface(prim, hu, hv)
            dd = d[:, active]
            w = T[active] * alpha
            lp = local[active]
            if surface.any():
                s = np.nonzero(surface & (w > 0))[0]
                for kind in self.kinds:
                    ident = self.identity.ids(kind, mesh[s], material[s])
                    out["crypto"][kind].append((lp[s], ident, w[s]))
                if "mist" in passes:
                    cam = self.camera
                    q = p[:, s] - cam.origin[:, None]
                    dist = (np.abs(cam.forward @ q) if cam.cam.projection == "orthographic"
                            else np.sqrt((q * q).sum(axis=0)))
                    _add(out["mist"], lp[s], w[s] * (1.0 - request.mist.ramp(dist)))
            first = surface & ~done[active] & ((alpha >= threshold) | (threshold == 0.0))
            if first.any():
                self._first_surface(out, np.nonzero(first)[0], active, lp, sample, p, n_g, n_s, dd, prim, hu, hv,
                                    mesh, material)
                done[active[first]] = True
            # holdout ends the ray with nothing written (Cycles' holdout surfaces); the rest crosses on
            T[active] *= 1.0 - alpha
            keep = ~holdout & (T[active] > 0)
            step = t + RAY_EPSILON * (1.0 + np.abs(p).max(axis=0))
            active, step, p = active[keep], step[keep], p[:, keep]
            o[:, active] = p + dd[:, keep] * (RAY_EPSILON * (1.0 + np.abs(p).max(axis=0)))[None, :]
            t_max[active] = t_max[active] - step
            active = active[t_max[active] > 0]
        for kind in self.kinds:
            parts = out["crypto"][kind]
            if parts:
                lp, ident, w = (np.concatenate(x) for x in zip(*parts))
                out["crypto"][kind] = _reduce(lp, ident, w, n_pix, len(self.identity.layer_names[kind]))
            else:
                out["crypto"][kind] = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
        return out

    def _first_surface(self, out, f, active, lp, sample, p, n_g, n_s, dd, prim, hu, hv, mesh, material):
        """Record the passes of the first (opaque enough) surface of the rays ``active[f]``."""
        passes = self.passes
        pix = lp[f]
        if "normal" in passes:
            flip = (n_g[:, f] * dd[:, f]).sum(axis=0) > 0         # Cycles turns N to the incoming ray's side
            n = np.where(flip[None, :], -n_s[:, f], n_s[:, f])
            _add(out["normal"], pix, n.T)
        if "uv" in passes and self.uv is not None:
            has = self.has_uv[mesh[f]]
            uv = self._interpolate(self.uv, prim[f], hu[f], hv[f])
            val = np.column_stack((uv, np.ones(f.size))) * has[:, None]
            _add(out["uv"], pix, val)
        if "vector" in passes:
            if self.motion is not None:          # (a static scene: 0)
                pre_pos, post_pos, cam_pre, cam_post = self.motion
                xc, yc = raster(self.camera, p[:, f])
                xa, ya = raster(cam_pre, self._interpolate(pre_pos, prim[f], hu[f], hv[f]).T)
                xb, yb = raster(cam_post, self._interpolate(post_pos, prim[f], hu[f], hv[f]).T)
                _add(out["vector"], pix, np.column_stack((xa - xc, ya - yc, xc - xb, yc - yb)))
            out["vector_weight"] += np.bincount(pix, minlength=out["vector_weight"].size)
        zero = sample[active[f]] == 0
        if zero.any():
            z = f[zero]
            pz = lp[z]
            cam = self.camera
            q = p[:, z] - cam.origin[:, None]
            if cam.cam.projection == "equirectangular":
                out["depth"][pz] = np.sqrt((q * q).sum(axis=0))
            else:
                out["depth"][pz] = cam.forward @ q
            out["position"][pz] = p[:, z].T
            out["object_index"][pz] = self.identity.pass_index[mesh[z]]
            out["material_index"][pz] = self.identity.material_pass[material[z]]


def render_data_passes(renderer, request: DataPassRequest, settings=None, window=None,
                       threads: int | None = None) -> DataPasses:
    """The data passes and Cryptomatte layers ``request`` asks for, of ``renderer`` (an
    engine.render.renderer.Renderer, or a Scene) with ``settings`` (None: the scene's: its seed, sampler, halves
    and spp; ``halves`` "auto" as a uniform render resolves it: pass an adaptive render's resolved settings for
    its rays), over ``window`` (x0, y0, x1, y1) or the whole image.  Deterministic for a seed; independent of
    ``threads`` (None: settings.threads, 0: one per core)."""
    if isinstance(renderer, Scene):
        scene, compiled, camera = renderer, CompiledScene(renderer), CameraModel(renderer.camera)
    else:
        scene, compiled, camera = renderer.scene, renderer.compiled, renderer.camera
    settings = resolve_halves(settings or scene.settings)
    W, H = scene.camera.width, scene.camera.height
    x0, y0, x1, y1 = window or (0, 0, W, H)
    if not (0 <= x0 < x1 <= W and 0 <= y0 < y1 <= H):
        raise ValueError(f"window {window} must lie inside the {W}×{H} image and be non-empty")
    w, h = x1 - x0, y1 - y0
    n_samples = request.samples_for(settings.spp)
    rows, cols = np.mgrid[y0:y1, x0:x1]
    tracer = _Tracer(scene, compiled, camera, request, int(settings.seed), settings.sampler,
                     (rows * W + cols).ravel().astype(np.int64), settings.halves)
    n_pix = tracer.pixels.size
    per_chunk = max(1, BATCH_RAYS // n_samples)
    chunks = [np.arange(a, min(a + per_chunk, n_pix)) for a in range(0, n_pix, per_chunk)]
    workers = threads if threads is not None else settings.threads
    workers = max(1, workers if workers > 0 else (os.cpu_count() or 1))
    if workers == 1 or len(chunks) == 1:
        results = [tracer(c, n_samples) for c in chunks]
    else:
        with ThreadPoolExecutor(workers) as pool:
            results = list(pool.map(lambda c: tracer(c, n_samples), chunks))
    return _assemble(tracer, request, chunks, results, n_pix, n_samples, (h, w))


def _assemble(tracer, request, chunks, results, n_pix, n_samples, shape) -> DataPasses:
    """Per-pixel sums of the chunks → the passes (Cycles' film conversion: ÷ samples, 1 − mist, …)."""
    h, w = shape
    full = {}
    for key, dims in (("normal", 3), ("uv", 3), ("vector", 4), ("vector_weight", 0), ("mist", 0), ("depth", 0),
                      ("position", 3), ("object_index", 0), ("material_index", 0)):
        arr = np.zeros((n_pix, dims) if dims else n_pix)
        for c, r in zip(chunks, results):
            arr[c] = r[key]
        full[key] = arr
    passes = request.passes
    images = {}
    inv = 1.0 / n_samples
    if "depth" in passes:
        images["Depth"] = full["depth"][:, None]
    if "mist" in passes:
        images["Mist"] = np.clip(1.0 - full["mist"] * inv, 0.0, 1.0)[:, None]
    if "normal" in passes:
        images["Normal"] = full["normal"] * inv
    if "position" in passes:
        images["Position"] = full["position"]
    if "uv" in passes:
        images["UV"] = full["uv"] * inv
    if "vector" in passes:
        weight = full["vector_weight"]
        images["Vector"] = full["vector"] / np.where(weight > 0, weight, 1.0)[:, None]
    if "object_index" in passes:
        images["Object Index"] = full["object_index"][:, None]
    if "material_index" in passes:
        images["Material Index"] = full["material_index"][:, None]
    order = [DATA_PASSES[p][0] for p in DATA_PASSES if DATA_PASSES[p][0] in images]
    images = {name: images[name].reshape(h, w, -1).astype(np.float32) for name in order}
    crypto, names = {}, {}
    levels = request.cryptomatte_levels
    slots = 2 * cm.pass_count(levels)
    for kind in tracer.kinds:
        layer = cm.KINDS[kind]
        pix, ident, weight = (np.concatenate(x) if x else np.zeros(0) for x in
                              zip(*[(c[r["crypto"][kind][0]], r["crypto"][kind][1], r["crypto"][kind][2])
                                    for c, r in zip(chunks, results)]))
        ids, cover = cm.ranked(pix.astype(np.int64), ident.astype(np.int64), weight * inv, n_pix, slots)
        table = tracer.identity.layer_names[kind]
        id_values = np.array([cm.name_id(n) for n in table], np.float32)
        crypto[layer] = cm.layer_passes(ids.reshape(h, w, slots), cover.reshape(h, w, slots), id_values, levels)
        names[layer] = table
    return DataPasses(images=images, cryptomatte=crypto, names=names, samples=n_samples)
