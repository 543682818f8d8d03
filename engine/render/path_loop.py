"""The two transports of a batch: the wavefront (engine.render.integrator.PathTracer) and the compiled per-path
bounce loop (engine.kernels.path_loop) where it covers the scene.

The loop covers scenes whose used materials are all one-step delta materials (smooth conductor and black glass
of a constant index or of measured tables, smooth dielectric of a constant index), whose only light is a constant,
unpolarised environment (or none), without media, ray visibility, holdouts, transparent film, pass-through
emitters, textures or Cycles' light-path rules, drawn by the "independent", "stratified" or "sobol" sampler, with
the compiled kernels and Embree's C API in use.  :func:`coverage` says why a scene is not covered; the tracer then
runs the wavefront, which is the loop's twin: the same numbers bit for bit (tests/render/test_path_loop.py), and
what every other scene runs.  RenderSettings.tracer "wavefront" (default) runs the wavefront; "auto" takes the
loop where it covers the scene.  The render's stats say which ran (``stats["tracer"]``).
"""

from __future__ import annotations

import numpy as np

from .. import kernels
from ..kernels.path_loop import (CONSTANT_MIRROR, DIELECTRIC, INDEPENDENT, MEASURED_MIRROR, SOBOL, STRATIFIED,
                                 trace_delta_paths)
from ..kernels.delta_bounce import _knot_hints
from ..kernels.sobol import SOBOL2_REVERSED
from ..materials.conductor import SmoothConductor
from ..materials.dielectric import SmoothDielectric
from .accel import RAY_EPSILON
from .embree_direct import _RAYHIT_WORDS, _aligned, _arguments
from .lights.environment import EnvironmentEmitter
from .sampler import PAIR_CHOICES, _PAIR_KEYS, _SOBOL_V, _seed_key

#: RenderSettings.tracer's values
TRACERS = ("auto", "wavefront")
#: How the stats name the transports
WAVEFRONT = "wavefront"
#: coverage's reason where the settings ask for the wavefront (the stats then name it without a reason)
ASKED = "tracer 'wavefront'"
LOOP = "per-path loop (delta-only materials)"
_SAMPLERS = {"independent": INDEPENDENT, "stratified": STRATIFIED, "sobol": SOBOL}


def _material_kind(m, mono: bool) -> int:
    """The loop's kind of material ``m`` (engine.kernels.path_loop), 0 where it does not cover it: the materials
    whose one-step scatter (BSDF.scatter_delta) it repeats, exactly where that step takes them."""
    if isinstance(m, SmoothConductor) and type(m).scatter_delta is SmoothConductor.scatter_delta and m.film is None:
        if m._eta is not None:
            return CONSTANT_MIRROR
        if m._tables and not mono:
            return MEASURED_MIRROR
        return 0
    if type(m).scatter_delta is SmoothDielectric.scatter_delta and isinstance(m, SmoothDielectric) \
            and not m.per_point:
        return DIELECTRIC
    return 0


def coverage(tracer, plain: bool = True) -> str | None:
    """None where the loop covers the scene and settings of ``tracer`` (an engine.render.integrator.PathTracer),
    else why not (a few words); ``plain``: the
    tracer is a plain PathTracer (not one with medium vertices, engine.render.participating)."""
    st = tracer.settings
    if getattr(st, "tracer", "auto") == "wavefront":
        return ASKED
    if not kernels.uses_cache():
        return "no compiled kernels"
    if not plain:
        return "participating media"
    compiled = tracer.scene
    if getattr(compiled.rays, "_lib", None) is None or compiled.has_passthrough:
        return "no direct Embree scene" if not compiled.has_passthrough else "pass-through emitters"
    if tracer.light_paths is not None:
        return "light-path rules"
    if tracer.media is not None or tracer.visibility is not None or tracer.track_alpha:
        return "absorbing media" if tracer.media is not None else "ray visibility, holdout or transparent film"
    if st.sampler not in _SAMPLERS:
        return f"sampler '{st.sampler}'"
    lights = tracer.lights
    env = lights.environment
    if any(light is not env for light in lights.lights) or tracer.has_area_lights:
        return "lights other than a constant environment"
    if env is not None and (type(env) is not EnvironmentEmitter or getattr(env, "varies_with_direction", False)
                            or (env.polarisation is not None and tracer.P > 1)):
        return "an environment that varies or is polarised"
    if tracer.textured:
        return "textured materials"
    kinds = [_material_kind(tracer.materials[i], tracer.mono) for i in compiled.used_materials]
    if not all(kinds):
        return "materials other than smooth conductors and dielectrics"
    measured = {id(tracer.materials[i]._table_arrays[0]) for i, k in zip(compiled.used_materials, kinds)
                if k == MEASURED_MIRROR}
    if len(measured) > 1:
        return "more than one measured metal"
    return None


class DeltaScene:
    """The loop's view of a covered scene (``coverage`` None): the Embree query, geometry and per-material arrays
    of engine.kernels.path_loop.trace_delta_paths."""

    def __init__(self, tracer, vertex_cost: int):
        self.tracer = tracer
        self.vertex_cost = vertex_cost
        compiled, st = tracer.scene, tracer.settings
        rays = compiled.rays
        self.query, self.handle, self.features = rays._lib.intersect[16], rays.handle, rays._features
        M = len(tracer.materials)
        self.kind = np.zeros(M, np.int64)
        self.eta_c = np.zeros(M, np.complex128)
        self.eta_front, self.eta_back = np.ones(M), np.ones(M)
        self.scaling = np.ones(M, np.bool_)
        self.two_sided = np.ascontiguousarray(tracer.two_sided, np.bool_)
        tables = (np.array([0.0, 1.0]), np.zeros(2), np.array([0.0, 1.0]), np.zeros(2), 1.0)
        self.table_range = None
        for i in compiled.used_materials:
            m = tracer.materials[i]
            kd = self.kind[i] = _material_kind(m, tracer.mono)
            self.scaling[i] = bool(m.radiance_scaling)
            if kd == CONSTANT_MIRROR:
                self.eta_c[i] = m._eta
            elif kd == DIELECTRIC:
                self.eta_front[i], self.eta_back[i] = m.n_int / m.n_ext, m.n_ext / m.n_int
            else:       # the wavefront's tabulated_mirror_scatter_numba arguments (writable copies: one compiled
                wl_n, n, wl_k, k = (np.array(a, np.float64) for a in m._table_arrays)      # loop for every scene)
                tables = (wl_n, n, wl_k, k, 1.0 / float(m.exterior_n))
                self.table_range = (max(wl_n[0], wl_k[0]), min(wl_n[-1], wl_k[-1]))
        wl_n, _, wl_k, _, _ = tables
        first, hints = _knot_hints(wl_n)
        self.tables = tables + (bool(wl_n.shape[0] == wl_k.shape[0] and np.all(wl_n == wl_k)), float(first), hints)
        self.geometry = (compiled.faces, compiled.vertices, compiled.vertex_normals, compiled.tri_has_normals,
                         compiled.tri_normal, bool(compiled.any_vertex_normals),
                         np.ascontiguousarray(compiled.tri_material, np.int64))
        self.sampler = _SAMPLERS[st.sampler]
        self.seed_key = _seed_key(st.seed)
        self.choices = (_SOBOL_V[2 * PAIR_CHOICES], _SOBOL_V[2 * PAIR_CHOICES + 1], _PAIR_KEYS[PAIR_CHOICES][0])

    def covers_wavelengths(self, lam: np.ndarray) -> bool:
        """False where a measured metal's tables do not cover every wavelength of a batch (the wavefront's step
        then falls back to the material's ``sample``: the batch takes the wavefront)."""
        if self.table_range is None:
            return True
        lo, hi = self.table_range
        return bool(np.all((lam >= lo) & (lam <= hi)))

    def trace(self, pixel: np.ndarray, sample: np.ndarray):
        """PathTracer.trace's result for the batch, or None where this batch must take the wavefront."""
        tracer = self.tracer
        st = tracer.settings
        state, acc = tracer._camera_paths(pixel, sample)
        lam = np.ascontiguousarray(state.lk_m.lam, np.float64)
        if not self.covers_wavelengths(lam):
            return None
        env = tracer.lights.environment
        n = pixel.shape[0]
        Le = (np.ascontiguousarray(tracer._emitted(env, state.lk), np.float64) if env is not None
              else np.zeros((acc.radiance.shape[1], n)))
        has_t = state.t_max is not None
        t_max = np.ascontiguousarray(state.t_max, np.float64) if has_t else np.empty(0)
        valid16, rh = _aligned(16, np.int32), _aligned(_RAYHIT_WORDS * 16, np.float32)
        cost = acc.path_cost if acc.path_cost is not None else np.empty(0, np.int64)
        k_camera = 2 + tracer.camera.lens_dimensions + (1 if tracer.samples_wavelengths else 0)
        c = np.ascontiguousarray
        rays, nonfinite = trace_delta_paths(
            self.query, self.handle, valid16, rh, _arguments(0, self.features), c(state.o, np.float64),
            c(state.d, np.float64), t_max, has_t,
            c(state.x_T, np.float64), lam, c(state.sampler.keys, np.uint64), c(pixel, np.int64), c(sample, np.int64),
            *self.geometry, self.kind, self.eta_c, self.eta_front, self.eta_back, self.scaling, self.two_sided,
            *self.tables, env is not None, Le, tracer.P, st.max_depth, st.rr_depth, RAY_EPSILON,
            self.sampler, self.seed_key, k_camera, *self.choices, SOBOL2_REVERSED, acc.radiance, cost,
            self.vertex_cost)
        acc.stats["rays"] += int(rays)
        acc.stats["nonfinite"] += int(nonfinite)
        return tracer._finish(acc, n)
