"""Wavefront polarised path tracer.

Each path carries, per wavelength, the Mueller product T of everything seen
so far *from the camera side* (T = M_1 · R · M_2 · R · …), as an array
(P, P, L, N): P = 4 (full Stokes), 3 (linear Stokes) or 1 (scalar), L wavelengths, N
paths.  T maps a Stokes vector expressed in the path's current frame
``x_T`` (⟂ the current segment) to the camera's per-pixel output frame
(docs/physics.md §0: x = unit(d × u_cam), k = −d).  At a vertex whose Mueller
value M is given in frames (x_in, x_out):

    T ← T · R(x_out → x_T) · M,   x_T ← x_in.

An unpolarised light of radiance L_e adds T[:, 0]·L_e; a polarised one (engine.render.polarised_light)
T·R(x_e → x_T)·s·L_e with its normalised Stokes vector s in its own frame x_e.  Paths
are traced in bounded batches; all paths of a batch are at the same depth,
random numbers come from the stateless sampler (engine.render.sampler), so
results do not depend on batching.

Next-event estimation at non-delta vertices is combined with BSDF sampling
by the power heuristic (as Mitsuba 3's ``path``).  ``max_depth`` counts
path segments; Russian roulette from ``rr_depth`` on uses
q = min(max_λ T00 · η², 0.95), η² undoing the refraction radiance scale.

Absorbing interiors (engine.render.media): paths carry a stack of the volumes they are inside and
their Beer–Lambert transmittance τ (L, n) per wavelength apart from T (a scalar per wavelength: the
polarisation is unchanged); light picked up is multiplied by τ up to where it is found, shadow rays
by the absorption along them, and the roulette sees T00·η²·max_λ τ.  Scenes without any interior
never allocate or read either, so their images are unchanged.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..materials.base import BSDF, BSDFFlags, BSDFSample, DeltaVertices, MuellerValue, ShadingPoint
from ..materials.batching import shading_groups
from ..polarisation.frames import frame_rotation, rotate_stokes
from .accel import RAY_EPSILON, Hits, offset_origin, surface_points
from ..kernels import uses_cache
from ..kernels.error_function import ERFCX_COEF, ERFCX_K
from ..kernels.glossy_bounce import add_light_terms_loop, light_terms_loop, sample_update_loop
from ..kernels.light_sampling import lamp_hits
from ..kernels.material_groups import material_groups
from ..kernels.shadow_rays import shadow_rays
from ..kernels.stokes_rotation import unpolarised_response_in_frame
from ..kernels.transport import (add_light, add_to_paths, identity_throughput, keep_columns, next_segments, put_columns,
                                 scale_columns, spectral_stokes_rgb_samples, stokes_rgb_samples,
                                 throughput_times_stokes, update_abcs, update_depolarising, update_general)
from .effects import TRANSPORT_SIZES
from .light_paths import LightPathRules, trace_light_paths
from .lights.area import AreaGroup
from .lights.lamps import PointEmitter
from .media import Media, cross
from .path_state import PathState
from .polarised_light import in_frame, light_samples_polarisation, mueller_times_stokes
from .plan import rendered_materials, spectral_reduction
from .sampler import (PADDED_LAYOUT, PADDED_WAVELENGTH, PAIR_BSDF_DIRECTION, PAIR_CHOICES, PAIR_LIGHT_POINT,
                      PAIR_WAVELENGTH, SOBOL_CHOICES, SOBOL_DIRECTION, SOBOL_LIGHT_POINT, SOBOL_ROULETTE, PathSampler,
                      camera_numbers, pattern_pairs, sequence_index, stratified_pair, vertex_pair,
                      vertex_pattern)
from .visibility import ray_visibility
from ..scene.description import resolve_halves
from ..spectral import RGB_WAVELENGTHS_NM, WavelengthLookup, rgb_channel_tables, rgb_weights, sample_wavelengths
from ..vec3 import dot

if TYPE_CHECKING:
    import threading

    from .accel import CompiledScene
    from .camera import CameraModel
    from .lights import LightSet, _Light
    from ..scene.description import RenderSettings


#: Next-event estimation and the BSDF sample at rough conductors in compiled steps (engine.kernels.glossy_bounce;
#: False: the NumPy chain, their twin, as without Numba)
GLOSSY_BOUNCE = uses_cache() and light_terms_loop is not None
ERFCX_COEF_F64 = np.ascontiguousarray(ERFCX_COEF, dtype=np.float64)
ERFCX_K_F64 = float(ERFCX_K)
_NO_LAMBDA = np.empty(0)


# ----------------------------------------------------------------------------- Mueller kernels

def scatter_throughput(out: np.ndarray, T: np.ndarray, rows: np.ndarray, m: MuellerValue, x_T: np.ndarray,
                       wo: np.ndarray, T_cols: np.ndarray | None = None) -> None:
    """out[..., rows] = T[..., T_cols] · R(x_out → x_T) · M at vertices with Mueller value ``m``.

    ``m`` (frames x_in, x_out), ``x_T`` (the paths' current frames, ⟂ the arriving segment, i.e.
    ⟂ wo) and ``wo`` are given for the paths ``rows`` only; ``T_cols``: the columns of T holding
    their throughputs (None: ``rows``).  T is left unchanged.
    """
    if m.kind == "abcs":
        update_abcs(out, T, rows, m.x_out, x_T, wo, m.A, m.B, m.C, m.S, m.depol, T_cols)
    elif m.kind == "depolarising":
        update_depolarising(out, T, rows, m.A, T_cols)
    else:
        update_general(out, T, rows, m.x_out, x_T, wo, m.M, T_cols)


def unpolarised_response(m: MuellerValue, P: int) -> np.ndarray:
    """M · (1, 0, 0, 0): the Stokes vector (P, L, N) scattered from unpolarised light, in frame x_out."""
    L, N = m.A.shape if m.A is not None else m.M.shape[2:]
    out = np.zeros((P, L, N))
    if m.kind == "general":
        out[:] = m.M[:P, 0]
        return out
    out[0] = m.m00()
    if m.kind == "abcs" and P > 1:
        out[1] = m.B
    return out


def gather(a: np.ndarray, sel: slice | np.ndarray) -> np.ndarray:
    """a[..., sel] for ascending int64 indices ``sel`` (a material group's paths; kernels.transport.keep_columns for
    a C-contiguous ``a``, 1.6× np.take's speed, else np.take: ~2× faster than fancy indexing); ``a`` itself for
    slice(None) (the same object, so per-object memos such as a LambertSet's albedo still match)."""
    if isinstance(sel, slice):
        return a if sel == slice(None) else a[..., sel]
    if a.ndim and a.flags.c_contiguous and sel.dtype == np.int64 and sel.shape[0]:
        return keep_columns(a, sel)             # (an index out of range raises IndexError, as np.take)
    return np.take(a, sel, axis=-1)


def power_heuristic(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a2 = a * a
    b2 = b * b
    den = a2 + b2
    return np.where(den > 0, a2 / np.where(den > 0, den, 1.0), 0.0)


# ----------------------------------------------------------------------------- per-bounce records

#: A path's cost (adaptive sampling's allocation weighs by it): PATH_COST, plus VERTEX_COST per
#: surface hit (a shaded vertex) and per light sample.  1-thread CPU time of 16×16-pixel windows
#: (256 spp, glass_sphere, fresnel_sphere_au 64², demo 128×64) fitted per scene: ≈ 0.3 µs per path,
#: 1.3–1.5 µs per surface hit, 1.1–1.2 µs per light sample (+ 2.3 ms per bounce of a batch, shared by
#: its paths): a vertex costs ≈ 4 paths.  The earlier count (segments + light samples) made a glass
#: path 2× a floor path's; its shaded vertices make it ≈ 2.5× (CPU time: 3–4×).
PATH_COST = 1
VERTEX_COST = 4


def same_side(n_g: np.ndarray, n_s: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(n,) True where the directions w (3, n) lie on the same side of the geometric normal n_g as of the shading
    normal n_s (BSDF.geometric_sides): above both (reflection) or below both (refraction)."""
    return (dot(n_g, w) > 0.0) == (dot(n_s, w) > 0.0)


@dataclass(eq=False)
class _Accumulators:
    """What a batch accumulates per path of the batch (indexed by ``PathState.path``): the
    radiance (P, L, N) (RGB: L = 3), the transparency (N,) (None: not tracked), the denoising
    guides (None: not asked) and the ray counts; ``w_rgb`` (3, L, N) colour weights of the
    wavelength samples (None in RGB mode).  ``path_cost`` (N,): each path's cost in units of
    :data:`PATH_COST`, the deterministic cost of a sample that adaptive sampling weighs its
    allocation by (engine.render.adaptive); None where the tracer does not count costs."""
    radiance: np.ndarray
    w_rgb: np.ndarray | None
    transparency: np.ndarray | None
    guides: DenoiseGuides | None
    stats: dict[str, int]
    #: (N,) the batch's pixels and the patterns' sample indices (engine.render.sampler.sequence_index) with the
    #: low-discrepancy samplers (their numbers depend on them), else None
    pixel: np.ndarray | None = None
    sample: np.ndarray | None = None
    count_cost: bool = True
    path_cost: np.ndarray | None = field(init=False)
    #: the light passes' first-vertex recorder (engine.render.light_passes.LightPassBatch; None: not asked)
    lobes: object | None = None

    def __post_init__(self):
        self.path_cost = np.full(self.radiance.shape[-1], PATH_COST, np.int64) if self.count_cost else None


@dataclass(eq=False)
class _SurfaceHits:
    """The live paths' hit points: triangle ``prim`` (n,), position ``p``, geometric and shading
    normals ``n_g``, ``n_s``, direction to the previous vertex ``wo`` (3, n), textured attributes
    ``at`` (engine.render.accel.surface_points, None when no material is textured)."""
    prim: np.ndarray
    p: np.ndarray
    n_g: np.ndarray
    n_s: np.ndarray
    wo: np.ndarray
    at: object


@dataclass(eq=False)
class _Scattered:
    """The sampled continuation of every live path: new throughput ``T`` (P, P, Lm, n) in frame
    ``x_T`` ⟂ direction ``d`` (3, n), ``valid``, ``is_delta``, solid-angle ``pdf``, refraction
    scale ``eta_step`` (n,), the roulette number ``u_rr`` (n,) and the vertex's side normal
    ``n_side`` (3, n) (None where no light selection needs it)."""
    u_rr: np.ndarray
    n_side: np.ndarray | None
    T: np.ndarray
    d: np.ndarray
    x_T: np.ndarray
    valid: np.ndarray
    is_delta: np.ndarray
    pdf: np.ndarray
    eta_step: np.ndarray


def one_lobe(materials) -> np.ndarray:
    """(materials,) bool: the materials with one lobe and so no lobe choice (Lambert, a rough conductor)."""
    return np.array([bin(int(m.flags.lobes)).count("1") == 1 for m in materials], bool)


@dataclass(eq=False)
class _VertexNumbers:
    """A bounce's random numbers (dimensions 1–8): the light sample ``u_light`` (4, n) (None where
    ``nee`` is False: skipped), the BSDF sample ``u_bsdf`` (3, n), or (1, n) (the lobe) while
    ``direction_dims`` still holds the direction's two (every group a one-step delta material), the
    roulette number ``u_rr`` (n,) (empty without roulette); ``pixel``, ``sample`` (n,): the paths'
    pixels and sample indices at a stratified first vertex or with the "sobol" sampler, else None;
    ``sobol_direction``: with "sobol" and the direction numbers still to draw, their pair of dimensions."""
    nee: bool
    u_light: np.ndarray | None
    u_bsdf: np.ndarray
    direction_dims: PathSampler | None
    pixel: np.ndarray | None
    sample: np.ndarray | None
    u_rr: np.ndarray | None = None
    sobol_direction: int | None = None
    pattern: str = ""                   # the pattern of ``sobol_direction`` (sampler.vertex_pattern)


@dataclass(eq=False)
class _LightSamples:
    """Next-event light samples of n vertices: direction ``wi`` (3, n), distance ``dist``, radiance
    scale ``scale``, the light's solid-angle ``pdf_l``, ``ok`` (n,), ``delta`` (bool, or (n,) for
    several lights), ``emitted`` (L, n), the selection probability ``select_prob`` (scalar or (n,)),
    ``owners``: (light index, its vertices: slice(None) or indices) per chosen light, and ``points``:
    the sampled points (triangle, b1, b2) of chosen lights whose radiance varies over the surface."""
    wi: np.ndarray
    dist: np.ndarray
    scale: np.ndarray
    pdf_l: np.ndarray
    ok: np.ndarray
    delta: bool | np.ndarray
    emitted: np.ndarray
    select_prob: float | np.ndarray
    owners: list
    points: dict
    #: polarised lights among the chosen: (normalised Stokes (4, n), its frame x_e (3, n)) of each sample's
    #: light (engine.render.polarised_light); None: every chosen light is unpolarised
    polarised: tuple | None = None


# ----------------------------------------------------------------------------- denoising guides

def albedo_rgb(a: np.ndarray, w_rgb: np.ndarray | None, path: np.ndarray, channels: bool = False) -> np.ndarray:
    """Linear sRGB (3, n) of per-wavelength albedos ``a`` (Lm, n) (reflectances, not radiances) of the batch
    paths ``path``: each channel's colour-matching weights ``w_rgb`` (3, L, N) normalised to sum 1 (None: RGB
    mode: the mean, or with ``channels`` (the "rgb" transport, Lm = 3) the channels themselves), kept within the
    sampled values; non-finite albedos count 0."""
    a = np.where(np.isfinite(a), a, 0.0)       # as the dropped non-finite samples
    if w_rgb is None:
        if channels and a.shape[0] == 3:
            return a.copy()
        return np.repeat(a.mean(axis=0)[None], 3, axis=0)
    w = w_rgb[:, :, path]                              # (3, L, n); Lm is L or 1
    den = w.sum(axis=1)
    rgb = np.where(den != 0, np.einsum("cln,ln->cn", w, np.broadcast_to(a, w.shape[1:]))
                   / np.where(den != 0, den, 1.0), 0.0)
    # sRGB colour-matching weights can be negative: keep each channel within the sampled
    # albedos (a weighted mean of them when the weights are positive)
    return np.clip(rgb, a.min(axis=0), a.max(axis=0))


class DenoiseGuides:
    """Per-path albedo and normal at the first non-delta vertex (Cycles' denoising data).

    Paths continue through delta-only vertices (mirrors, smooth glass) as in Cycles, and the
    albedo found behind them is scaled by the path's throughput T00 so far (a tinted mirror tints
    it).  The albedo is the one-sample estimate of the directional albedo M00 of the sampled
    BSDF weight (BSDF·cos/pdf from unpolarised light), whose pixel mean converges to the Mueller
    M00 directional albedo; for a cosine-sampled Lambert it is exactly ρ.  Wavelength samples are
    turned into linear sRGB by their colour-matching weights, normalised per channel (a reflectance,
    not a radiance) and kept within the sampled values.  The normal is the world-space shading
    normal, facing the arriving ray.
    Paths that leave the scene (or end) before a non-delta vertex keep albedo 0 and normal 0.
    """

    def __init__(self, n: int):
        self.albedo = np.zeros((3, n))
        self.normal = np.zeros((3, n))
        self.done = np.zeros(n, bool)

    def record(self, path: np.ndarray, T00: np.ndarray, weight: MuellerValue, valid: np.ndarray, n_s: np.ndarray,
               wo: np.ndarray, w_rgb: np.ndarray | None) -> None:
        """Record the vertices of paths ``path`` (original indices) not recorded yet.

        ``T00`` (Lm, n): throughput before the vertex; ``weight``: the sampled BSDF weight (counted
        where ``valid``); ``n_s``, ``wo`` (3, n): shading normal and direction to the previous vertex; ``w_rgb``
        (3, L, N) colour weights of the wavelength samples (None: RGB mode, grey materials).
        """
        new = ~self.done[path]
        if not new.any():
            return
        a = np.where(valid, unpolarised_response(weight, 1)[0], 0.0) * T00     # (Lm, n)
        rgb = albedo_rgb(a, w_rgb, path)
        facing = np.where(dot(n_s, wo) < 0, -1.0, 1.0)
        idx = path[new]
        self.albedo[:, idx] = rgb[:, new]
        self.normal[:, idx] = (n_s * facing)[:, new]
        self.done[idx] = True


# ----------------------------------------------------------------------------- tracer

class PathTracer:
    """Traces batches of camera paths for one compiled scene."""

    def __init__(self, compiled: CompiledScene, lights: LightSet, camera: CameraModel, settings: RenderSettings,
                 materials: list[BSDF] | None = None, count_cost: bool = True):
        """``materials``: the compiled scene's materials as rendered (by material index:
        ``RenderPlan.materials``); None: the plan's rule (engine.render.plan.rendered_materials).
        ``settings``: as rendered (``polarisation`` and ``halves`` resolved; ``halves`` "auto" traces as a uniform
        render resolves it, engine.scene.description.resolve_halves).  ``count_cost``: report each path's
        cost (``stats["path_cost"]``), which only adaptive sampling reads; without it the per-vertex
        counting is skipped (a masked scatter-add per bounce and per next-event vertex)."""
        self.scene = compiled
        self.count_cost = count_cost
        self.lights = lights
        self.camera = camera
        self.settings = resolve_halves(settings)
        if materials is None:
            materials, _ = rendered_materials(compiled, getattr(settings, "simplify", "auto"))
        self.materials: list[BSDF] = list(materials)
        self.has_area_lights = compiled.has_area_lights     # once, not per bounce (scans every triangle)
        # emitters whose radiance varies over the surface read it at the hits' barycentrics
        self.textured_lights = any(light.varies_over_surface for light in lights.lights)
        #: the light tree (engine.render.lights.tree) where RenderSettings.light_tree asks for it, else None: the
        #: LightSet chooses (uniformly or by power, as before the tree)
        self.tree = lights.light_tree() if lights.uses_tree(getattr(settings, "light_tree", "auto")) else None
        #: the emitters sampled uniformly by area, sampled together when several lights are chosen at a bounce
        self.area_group = AreaGroup(lights.lights)
        #: the light choice needs each vertex's position and side normal
        self.spatial = lights.spatial or self.tree is not None
        # where segments start is kept for light selection, analytic lamps and warp-sampled lamps' pdfs
        self.keep_origins = (self.spatial or bool(lights.hittable)
                             or any(light.hit_pdf_needs_origin or light.hit_pdf_needs_direction
                                    for light in lights.lights))
        # by material index: opaque two-sided materials, whose back faces shade with flipped normals
        # (BSDF.two_sided; read from the scene's materials, which simplification may have replaced)
        self.two_sided = np.array([bool(m.two_sided) and not m.flags.transmits for m in compiled.materials], bool)
        self.any_two_sided = bool(self.two_sided.any())
        # textured parameters need the hits' per-vertex attributes (UV, colours)
        self.textured = any(m.varies_over_surface for m in self.materials)
        self.P = TRANSPORT_SIZES[settings.polarisation]
        self.mono = settings.spectral == "mono"
        #: "rgb" transport: the path's wavelength axis carries the R, G, B channels (Cycles' arithmetic)
        self.channels = settings.spectral == "rgb"
        self.n_lambda = 1 if self.mono else 3 if self.channels else 4
        self._material_tables(compiled.used_materials)
        # absorbing interiors (None: the scene has none, and nothing below reads a medium)
        self.media = Media(compiled, self.rgb_mode, self.mono) if compiled.has_volumes else None
        # Object ray visibility / holdout / alpha (None: none used) and film transparency (Cycles).
        self.visibility = ray_visibility(compiled)
        self.film_transparent = bool(getattr(camera.cam, "film_transparent", False))
        self.track_alpha = self.film_transparent or (self.visibility is not None and self.visibility.any_holdout)
        # Denoising guides (Cycles' Denoising Albedo / Normal), only when asked: renders without
        # them run exactly the same arithmetic as before.
        self.denoise_data = bool(getattr(settings, "denoise_data", False))
        # Cycles' light-path limits (engine.render.light_paths; None: none set, trace runs as before them)
        self.light_paths = (LightPathRules(settings, self.materials)
                            if getattr(settings, "light_paths_active", False) else None)

    def _material_tables(self, used: np.ndarray) -> None:
        """The tables read by material index while tracing, from ``self.materials`` (``used``: the indices the
        scene's triangles use); a subclass that adds materials (participating media's phase vertices) calls it again."""
        # materials shaded together (e.g. all RGB Lambert materials in one call)
        self.shaders, self.group_of, self.slot_of = shading_groups(self.materials)
        # one lobe and no lobe choice (a rough conductor, Lambert): "sobol"'s first vertex draws its direction
        # jointly with the pixel jitter (_sobol_vertex_numbers); per material, not per shading group, so that the
        # image does not depend on how materials are batched
        self.one_lobe = one_lobe(self.materials)
        # Where no material depends on λ, every wavelength of a path has the same Mueller product:
        # carry T for one wavelength and apply the spectral emission and colour matching at the
        # lights (exactly the same estimate, a quarter of the Mueller arithmetic).
        # "auto": with λ-independent materials the spectral estimator's expectation is T times each
        # light's spectrum integrated against the CIE observer, so trace in RGB with those exact
        # light colours: no wavelength sampling and no chromatic noise (same expectation).
        self.uniform, self.rgb_mode = spectral_reduction(self.settings, self.materials, used)
        # a textured emitter's colour in RGB: its spectrum integrated against the observer (the expectation of
        # the spectral estimator), except in the "rgb" transport, whose texels are the channels themselves (as a
        # constant light's channel_rgb: Cycles' arithmetic)
        self._integrated_rgb = self.rgb_mode and not self.channels

    def reseeded(self, settings: RenderSettings) -> PathTracer:
        """This tracer for ``settings`` (as rendered) that differ from its own in the seed alone: a shallow copy with
        those settings, everything else shared (nothing the constructor builds reads the seed, and tracing changes no
        attribute); a worker's next render of the scene skips building the shading groups and light tables again
        (renderer._WorkerScenes).  ValueError where anything else differs."""
        settings = resolve_halves(settings)
        if dataclasses.replace(settings, seed=self.settings.seed) != self.settings:
            raise ValueError("reseeded: the settings differ in more than the seed")
        tracer = copy.copy(self)
        tracer.settings = settings
        return tracer

    def _emitted(self, light: _Light, lookup: WavelengthLookup, d: np.ndarray | None = None,
                 rows: np.ndarray | None = None, uv=None) -> np.ndarray:
        """Emitted radiance (L, n) of ``light`` for paths with these wavelengths (RGB (3, n) in RGB mode)
        arriving along the directions d (3, n) (used by lights whose radiance varies with direction).
        ``rows``: a mask of ``lookup``'s paths (the n taken; None: all), taken only where the wavelengths
        are read (not in RGB mode); ``uv``: the light's ``map_coordinates(d)`` if the caller has them."""
        if d is not None and getattr(light, "varies_with_direction", False):
            return light.emitted(d, lookup if rows is None else lookup.take(rows), self.rgb_mode, self.mono, uv=uv)
        if self.rgb_mode:
            rgb = light.channel_rgb() if self.channels else light.rgb()
            n = lookup.n if rows is None else int(np.count_nonzero(rows))
            return np.repeat(rgb[:, None], n, axis=1)
        if rows is not None:
            lookup = lookup.take(rows)
        if self.mono:
            return light.radiance(lookup.lam, True)
        return light.spectrum.eval_cached(lookup)

    @property
    def samples_wavelengths(self) -> bool:
        """True when paths sample their wavelengths (one random dimension after the camera's)."""
        return not (self.rgb_mode or self.mono)

    def _wavelengths(self, u: np.ndarray | None, n: int) -> tuple[np.ndarray, np.ndarray | None]:
        """(λ (L, n) nm, sRGB weights (3, L, n) or None in RGB mode) of the paths; ``u`` (n,) their
        wavelength dimension (None where ``samples_wavelengths`` is False)."""
        if self.channels:
            return np.repeat(np.array(RGB_WAVELENGTHS_NM)[:, None], n, axis=1), None
        if self.rgb_mode:
            return np.full((1, n), 550.0), None
        if self.mono:
            lam = np.full((1, n), self.settings.wavelength_nm)
            return lam, np.ones((3, 1, n))
        lam, pdf = sample_wavelengths(u, self.n_lambda)
        return lam, rgb_weights(lam, pdf)

    def trace(self, pixel: np.ndarray, sample: np.ndarray,
              abort: threading.Event | None = None) -> tuple[np.ndarray, dict[str, int]] | None:
        """Trace one path per (pixel, sample) pair; returns (stokes_rgb (4, 3, N), stats dict).

        ``abort`` (a threading.Event) is checked between bounces; if it is set the batch is
        abandoned and None is returned.

        Each bounce runs named stages over one PathState: ``_intersect`` (closest hits, ray
        visibility), ``_emission`` (light the segment reached), ``_surface`` (drop the paths that
        left the scene, reconstruct the hit points), ``_scatter`` (per material group: next-event
        estimation and BSDF sampling into the next segment) and ``_next_segments`` (Russian roulette,
        non-finite and black paths, the survivors kept and their next origins, in one compiled step).
        """
        if self.light_paths is not None:
            return trace_light_paths(self, pixel, sample, abort)
        st = self.settings
        n_total = pixel.shape[0]
        state, acc = self._camera_paths(pixel, sample)
        for bounce in range(st.max_depth):
            if abort is not None and abort.is_set():
                return None
            if state.n == 0:
                break
            hits, hit, background = self._intersect(state, acc, bounce)
            self._emission(state, acc, hits, hit, background, bounce)
            if bounce + 1 >= st.max_depth:
                break
            surf = self._surface(state, hits, hit)
            if surf is None:
                break
            nxt = self._scatter(state, acc, surf, bounce)
            self._next_segments(state, acc, surf, nxt, bounce)
        return self._finish(acc, n_total)

    # ------------------------------------------------------------------ stages

    def _camera_paths(self, pixel: np.ndarray, sample: np.ndarray) -> tuple[PathState, _Accumulators]:
        """Camera rays of the batch as a PathState (T = identity) and zeroed accumulators."""
        P, n_total = self.P, pixel.shape[0]
        # the paths' keys and every random number of this stage in one pass: the camera's dimensions
        # (pixel jitter, lens), then the wavelengths'
        k_camera = 2 + self.camera.lens_dimensions
        k = k_camera + (1 if self.samples_wavelengths else 0)
        stratified = self.settings.stratified           # "stratified" and "sobol": the same numbers here
        # pixel jitter stratified over each pixel's samples: edges of bright camera-visible emitters
        # (a lamp, a sun disc) are otherwise most of the image's noise (see stratified_pair); the
        # lens point (a defocused edge's noise) and the wavelengths (a coloured metal's or a light's
        # spectrum: the spectral noise) likewise
        sampler, u = camera_numbers(self.settings.seed, self.settings.sampler, pixel, sample,
                                    self.camera.lens_dimensions, k - k_camera, self.settings.halves)
        if stratified:
            # from here on the patterns' index: the sample itself, or 2·sample where even and odd samples are one
            # sequence (engine.render.sampler.sequence_index)
            sample = sequence_index(sample, self.settings.halves)
            seed = self.settings.seed
            if self.samples_wavelengths:
                # a path's wavelengths are frac(u + j/count), j < count: periodic in u with period 1/count, so
                # the stratified x sets u within a period (the pixel's samples stratify that period, not
                # [0, 1) count times over) and y which period (the hero's quarter, also stratified)
                count = self.n_lambda
                if self.settings.sampler in PADDED_LAYOUT:
                    x, y = pattern_pairs(self.settings.sampler, seed, pixel, sample, [PADDED_WAVELENGTH])
                else:
                    x, y = stratified_pair(seed, pixel, sample, u[k_camera], u[k_camera], pair=PAIR_WAVELENGTH)
                u[k_camera] = (x + np.floor(y * count)) / count
        o, d, x_T, t_min, t_max = self.camera.generate(pixel, u[:k_camera])
        lam, w_rgb = self._wavelengths(u[k_camera] if self.samples_wavelengths else None, n_total)
        L = 3 if self.rgb_mode else lam.shape[0]
        # table values at the path's wavelengths, once; "rgb" transport: the identity basis and a white
        # D65, so every RGB colour evaluates to its own channel values
        lk = WavelengthLookup(lam, *rgb_channel_tables(n_total), channels=True) if self.channels \
            else WavelengthLookup(lam)
        # wavelengths the materials are evaluated at (one where nothing depends on λ)
        lk_m = WavelengthLookup(lam[:1]) if self.uniform else lk
        Lm = lk_m.lam.shape[0]
        if np.any(t_min > 0):
            o = o + d * t_min[None, :]
            t_max = t_max - t_min
        # T = identity for every camera path: one column that all of them read (PathState.T_col), so
        # the batch's (P, P, Lm, n) identity is never written (512 bytes a path at 4 wavelengths:
        # writing it was ~4 % of a fresnel_sphere_au render); the first scatter writes a dense T.
        state = PathState(path=np.arange(n_total), T=identity_throughput(P, Lm, 1), x_T=x_T, o=o, d=d, t_max=t_max,
                          eta_sq=np.ones(n_total), prev_delta=np.ones(n_total, bool), prev_pdf=np.zeros(n_total),
                          p_prev=None, n_prev=None, sampler=sampler, lk=lk, lk_m=lk_m,
                          T_col=np.zeros(n_total, np.int64))
        if self.media is not None:
            state.media = self.media.camera_stacks(o)        # camera rays starting inside volumes
        # Transparency T per sample (alpha = 1 − T): camera rays reaching the background of a
        # transparent film or a holdout (Cycles' film_write_transparent / holdout).
        acc = _Accumulators(radiance=np.zeros((P, L, n_total)), w_rgb=w_rgb,
                            transparency=np.zeros(n_total) if self.track_alpha else None,
                            guides=DenoiseGuides(n_total) if self.denoise_data else None,
                            stats={"rays": 0, "shadow_rays": 0, "nonfinite": 0},
                            pixel=pixel if stratified else None, sample=sample if stratified else None,
                            count_cost=self.count_cost)
        return state, acc

    def _intersect(self, state: PathState, acc: _Accumulators,
                   bounce: int) -> tuple[Hits, np.ndarray, np.ndarray]:
        """Closest hits of the paths' segments (hidden and pass-through surfaces skipped); returns
        (hits, hit mask, background mask: misses that see the environment).  Camera rays reaching a
        transparent background or a holdout add to the transparency and count as misses without light."""
        compiled, vis = self.scene, self.visibility
        o, d, t_max = state.o, state.d, state.t_max
        hits = compiled.intersect(o, d, t_max)
        acc.stats["rays"] += state.n
        through = None          # camera rays: the weight left after surfaces crossed without a random choice
        if vis is not None:
            record = [] if self.media is not None else None
            null = [] if bounce == 0 and vis.tri_null is not None and self.media is None else None
            hits, extra = vis.pass_through(compiled, o, d, t_max, hits, bounce == 0, state.sampler.keys, bounce,
                                           record=record, null_crossings=null)
            acc.stats["rays"] += extra
            state.crossings = record
            if null:
                through = self._null_crossings(state, acc, null)
        hit = hits.prim >= 0
        background = ~hit
        if bounce == 0 and acc.transparency is not None:
            # Camera rays have T = identity here (× ``through``): each adds that to the transparency it reaches.
            if self.film_transparent:
                acc.transparency[state.path[background]] += 1.0 if through is None else through[background]
                background = np.zeros_like(hit)
            if vis is not None and vis.any_holdout:
                held = hit & vis.holdout[vis.tri_mesh[np.where(hit, hits.prim, 0)]]
                acc.transparency[state.path[held]] += 1.0 if through is None else through[held]
                hit = hit & ~held
        if acc.path_cost is not None:
            acc.path_cost[state.path[hit]] += VERTEX_COST   # shaded vertices (paths of a batch are distinct)
        return hits, hit, background

    def _null_crossings(self, state: PathState, acc: _Accumulators, layers: list) -> np.ndarray:
        """Camera rays that crossed see-through surfaces which scatter nothing (RayVisibility.pass_through's
        ``null_crossings``, in the order crossed): each crossing adds alpha × the surface's emission (weighted by
        what the earlier crossings left; camera rays: T = identity, MIS weight 1) and leaves 1 − alpha of the ray;
        T of the paths is scaled by what is left, which is returned (n,)."""
        through = np.ones(state.n)
        if self.has_area_lights:
            at_prev = lambda sel: (None, None)       # noqa: E731  (camera rays: no previous vertex)
            for rays, prims, u, v, dists, alpha in layers:
                lit = self.scene.tri_emitter[prims] >= 0
                if lit.any():
                    sel = lit.nonzero()[0]
                    self._emitter_hits(acc.radiance, state.path, state.T_store, state.T_columns, rays[sel], prims[sel],
                                       dists[sel], state.d, state.lk, state.prev_delta, state.prev_pdf, at_prev, True,
                                       bary=(u[sel], v[sel]) if self.textured_lights else None,
                                       scale=alpha[sel] * through[rays[sel]])
                through[rays] *= 1.0 - alpha
        else:
            for rays, _, _, _, _, alpha in layers:
                through[rays] *= 1.0 - alpha
        rows = np.flatnonzero(through < 1.0)
        T = state.T                                  # dense (the camera's shared identity column gathered)
        T[..., rows] *= through[rows]
        state.T = T
        return through

    def _emission(self, state: PathState, acc: _Accumulators, hits: Hits, hit: np.ndarray, background: np.ndarray,
                  bounce: int) -> None:
        """Light reached by the segments, MIS-weighted against next-event estimation from the
        vertices they left: the environment (misses), emitting triangles, analytic lamps and
        non-occluding lamps crossed before the hit."""
        light_set, env, compiled = self.lights, self.lights.environment, self.scene
        radiance, path, T, o, d, t_max = acc.radiance, state.path, state.T_store, state.o, state.d, state.t_max
        cols = state.T_columns
        prev_delta, prev_pdf, lk = state.prev_delta, state.prev_pdf, state.lk
        p_prev, n_prev = state.p_prev, state.n_prev

        def at_prev(sel):
            """(position, side normal) of the vertices that the paths ``sel`` left (light selection)."""
            return (None, None) if p_prev is None else (p_prev[:, sel], None if n_prev is None else n_prev[:, sel])

        # absorbing interiors: the transmittance (L, m) of the paths ``rows`` up to distance s along their
        # segments (att(rows, s)), None where nothing absorbs
        segment = att = None
        if self.media is not None:
            segment = self.media.march(state.media, d, state.crossings or [], lk, state.gap)   # → segment ends
            state.crossings = None
            if segment.absorbs or state.tau is not None:
                att = self._attenuation(state, segment)

        if env is not None and background.any():
            miss = background
            nd = ~prev_delta[miss]
            # the missed directions, where something reads them (contiguous (3, m), unlike d[:, miss]): a
            # sky that varies with direction, MIS against its sampling, a polarised sky's frames
            reads_d = (getattr(env, "varies_with_direction", False) or nd.any()
                       or (env.polarisation is not None and self.P > 1))
            d_miss = np.compress(miss, d, axis=1) if reads_d else None
            uv = None if d_miss is None else env.map_coordinates(d_miss)     # (a map's: once for both)
            Le = self._emitted(env, lk, d_miss, rows=miss, uv=uv)
            w = np.ones(nd.shape[0])
            if nd.any():
                p_light = env.pdf(d_miss, uv=uv) * self._pick_probability(light_set.environment_index, at_prev(miss))
                w = np.where(nd, power_heuristic(prev_pdf[miss], p_light), 1.0)
            rows = miss.nonzero()[0]
            if att is not None:
                Le = Le * att(rows, np.full(rows.size, np.inf))
            self._add_light(radiance, path, T, rows, Le, w, cols(rows), env, d_miss, state.x_T)
        if self.has_area_lights:
            lit = (compiled.tri_emitter[hits.prim] >= 0) & hit
            if lit.any():
                idx = lit.nonzero()[0]
                self._emitter_hits(radiance, path, T, cols, idx, hits.prim[idx], hits.t[idx], d, lk,
                                   prev_delta, prev_pdf, at_prev, bounce == 0,
                                   bary=(hits.u[idx], hits.v[idx]) if self.textured_lights else None, att=att,
                                   x_T=state.x_T)
        if light_set.hittable:
            # analytic lamps (sphere/disk lights, sun discs): seen, never occluding
            seg = np.where(hit, hits.t, np.inf if t_max is None else t_max)
            for li in light_set.hittable:
                light = light_set.lights[li]
                if bounce == 0 and li in light_set.camera_hidden:
                    continue
                rows, factor, pdf_l = light.intersect(o, d, seg, hit, p_prev)
                if rows.size:
                    Le = self._emitted(light, lk.take(rows)) * factor[None, :]
                    if att is not None:
                        Le = Le * att(rows, self._lamp_distances(light, o, d, seg, rows))
                    p_light = pdf_l * self._pick_probability(li, at_prev(rows))
                    w = np.where(prev_delta[rows], 1.0, power_heuristic(prev_pdf[rows], p_light))
                    self._add_light(radiance, path, T, rows, Le, w, cols(rows), light, d[:, rows], state.x_T)
        if compiled.has_passthrough:
            # lamps (non-occluding emitters) crossed before the hit: they add light, the ray goes on
            seg = np.where(hit, hits.t, np.inf if t_max is None else t_max)
            for rows, prims, dists in compiled.passthrough_hits(o, d, seg):
                self._emitter_hits(radiance, path, T, cols, rows, prims, dists, d, lk, prev_delta, prev_pdf,
                                   at_prev, bounce == 0, o=o, att=att, x_T=state.x_T)
        if segment is not None and segment.absorbs:
            # the paths' transmittance up to their hits (the paths that missed end here)
            every = np.arange(state.n)
            seg_tau = segment.transmittance(every, np.where(hit, hits.t, 0.0))
            state.tau = seg_tau if state.tau is None else state.tau * seg_tau

    def _stokes_of_light(self, polarised: bool, x_T: np.ndarray | None) -> bool:
        """Whether light enters the paths as a Stokes vector (a polarised light, ``polarised``, in a polarising
        transport whose paths carry frames ``x_T``); else as S0 alone (add_light)."""
        return polarised and self.P > 1 and x_T is not None

    def _add_light(self, radiance: np.ndarray, path: np.ndarray, T: np.ndarray, rows: np.ndarray, Le: np.ndarray,
                   w: np.ndarray, T_cols: np.ndarray, light, d: np.ndarray, x_T: np.ndarray | None) -> None:
        """Light of radiance ``Le`` (L, m) from ``light`` reaching the paths ``rows`` along their segments ``d``
        (3, m), MIS weight ``w`` (m,): T[:, 0] · Le · w (add_light), or for a polarised light in a polarising
        transport T · R(x_e → x_T) · s · Le · w with the light's Stokes vector s (engine.render.polarised_light)."""
        if not self._stokes_of_light(light.polarisation is not None, x_T):
            add_light(radiance, path, T, rows, Le, w, T_cols)
            return
        k = -d
        s, x_e = light.emitted_polarisation(k)
        s = in_frame(s, x_e, x_T[:, rows], k)[:self.P]
        cols = rows if T_cols is None else T_cols
        radiance[:, :, path[rows]] += throughput_times_stokes(T, cols, s[:, None, :], Le * w[None, :])

    @staticmethod
    def _attenuation(state: PathState, segment):
        """att(rows, s): the transmittance (L, m) of the paths ``rows`` from the camera to distance s
        (m,) along their current segments: τ so far × exp(−∫σ_a) over [0, s] (None: 1)."""
        tau = state.tau

        def att(rows: np.ndarray, s: np.ndarray) -> np.ndarray | None:
            f = segment.transmittance(rows, s) if segment.absorbs else None
            if tau is not None:
                f = tau[:, rows] if f is None else f * tau[:, rows]
            return f
        return att

    @staticmethod
    def _lamp_distances(light, o: np.ndarray, d: np.ndarray, seg: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Distances (m,) at which the rays ``rows`` reach a hittable lamp (``light.intersect``'s rows):
        a sphere or disk lamp's hit, infinity for a sun's disc."""
        if not isinstance(light, PointEmitter):
            return np.full(rows.size, np.inf)
        _, t, _ = lamp_hits(o[:, rows], d[:, rows], seg[rows], light.position, light.radius, light.soft_falloff)
        return t

    def _surface(self, state: PathState, hits: Hits, hit: np.ndarray) -> _SurfaceHits | None:
        """Keep the paths that hit a surface and reconstruct their hit points (None: none left).

        The previous vertex's fields (segment origin and length, sampling record) are consumed
        by the emission stage and dropped first, so the compression does not carry them.
        """
        state.o = state.t_max = state.prev_delta = state.prev_pdf = state.p_prev = state.n_prev = None
        prim, u, v = state.compress(hit, hits.prim, hits.u, hits.v)
        if state.n == 0:
            return None
        compiled = self.scene
        p, n_g, n_s = compiled.surface(prim, u, v)
        at = surface_points(compiled, prim, u, v) if self.textured else None
        return _SurfaceHits(prim=prim, p=p, n_g=n_g, n_s=n_s, wo=-state.d, at=at)

    def _scatter(self, state: PathState, acc: _Accumulators, surf: _SurfaceHits, bounce: int) -> _Scattered:
        """Per material group: next-event estimation (into the radiance) and BSDF sampling of the
        next segment with the Mueller update T ← T·R(x_out → x_T)·M (into a new T)."""
        # T is read through its column map (PathState.T_col); the scatter writes a new, dense one
        n, T = state.n, state.T_store
        n_g, n_s, wo = surf.n_g, surf.n_s, surf.wo
        n_side = n_g * np.sign(dot(n_g, wo))[None, :] if self.spatial else None
        # Stokes frame of the arriving segment: x_T is already ⟂ d.
        # each path's material, and the paths sorted by material group (ascending within a group)
        mat, counts, order = material_groups(surf.prim, self.scene.tri_material, self.group_of, len(self.shaders))
        ends = np.cumsum(counts)
        # back faces of two-sided materials: flipped after any normal map (as Cycles maps, then flips)
        flip = self._back_faces(mat, n_g, wo)
        n_s_delta = n_s if flip is None else np.where(flip[None, :], -n_s, n_s)
        # the groups present, ascending
        groups = np.flatnonzero(counts)
        # One material covers every path: its sample's arrays become the next segments as they are
        # (no gathered copies in, no scattered copies out).  Otherwise each group writes its columns.
        # Delta-only materials with a one-step scatter_delta write their columns in place in any case.
        whole = len(groups) == 1
        fused = [self.shaders[g].flags.is_delta_only and type(self.shaders[g]).scatter_delta is not BSDF.scatter_delta
                 for g in groups]
        columns = not whole or fused[0]
        nums = self._vertex_numbers(state, acc, groups, fused, bounce, mat)
        nxt = self._new_scattered(nums.u_rr, n_side, T.shape[:3] + (n,), columns)
        # (every path belongs to one material group, which writes its columns of nxt.T, d, x_T and valid:
        # scatter_delta at its rows, else from its sample; is_delta, pdf and eta_step keep their presets
        # where a one-step delta material leaves them)
        for g, one_step in zip(groups, fused):
            sel = slice(None) if whole else order[ends[g] - counts[g]:ends[g]]
            bsdf = self.shaders[g]
            rows = np.arange(n) if isinstance(sel, slice) else sel
            t_cols = state.T_columns(sel)           # T's columns of these paths (None: rows)
            if one_step and self._scatter_delta(bsdf, state, surf, nxt, rows, n_s_delta, nums.u_bsdf[0], t_cols):
                if bsdf.geometric_sides:
                    nxt.valid[rows] &= same_side(gather(n_g, sel), gather(n_s, sel), nxt.d[:, rows])
                continue            # pdf 0 and is_delta True: as preset
            if nums.direction_dims is not None or nums.sobol_direction is not None:
                self._late_direction_numbers(nums)
            sp = self._shading_point(bsdf, state, surf, mat, flip, sel)
            xTm = gather(state.x_T, sel)
            if self.tree is not None and bsdf.flags.transmits:
                nxt.n_side[:, sel] = 0.0        # the tree's light choice: light from either side counts
            lobe = self._lobe_kernel_inputs(bsdf, sp, state, acc)      # (a rough conductor: compiled steps)
            # its sample first: next-event estimation reads the sampler's Smith Λ(ω_o) (neither reads what the
            # other writes: the order changes no number)
            lam_o = None
            if lobe is not None and acc.guides is None:
                lam_o = self._sample_update(bsdf, sp, lobe, nums.u_bsdf, sel, rows, T, xTm, t_cols, nxt)
            if nums.nee and not bsdf.flags.is_delta_only:
                self._group_next_event(state, acc, surf, bsdf, sp, sel, rows, xTm, t_cols, nums.u_light, lobe, lam_o)
            if lam_o is not None:
                if bsdf.geometric_sides:
                    nxt.valid[rows] &= same_side(sp.n_g, sp.n_s, nxt.d[:, rows])
                continue
            bs = self._sample_bsdf(bsdf, sp, nums.u_bsdf, sel)
            if bsdf.geometric_sides:            # (BSDF.geometric_sides) a direction into the other side: no sample
                bs = dataclasses.replace(bs, valid=bs.valid & same_side(sp.n_g, sp.n_s, bs.wi))
            if acc.lobes is not None:
                acc.lobes.sampled(bsdf, sp, gather(state.path, sel), bs)
            if acc.guides is not None and not bsdf.flags.is_delta_only:
                acc.guides.record(gather(state.path, sel), T[0, 0][:, rows if t_cols is None else t_cols], bs.weight,
                                  bs.valid, sp.n_s, sp.wo, acc.w_rgb)
            scatter_throughput(nxt.T, T, rows, bs.weight, xTm, sp.wo, t_cols)
            self._store_sample(nxt, bs, sel, columns)
        return nxt

    def _vertex_numbers(self, state: PathState, acc: _Accumulators, groups: np.ndarray, fused: list[bool],
                        bounce: int, mat: np.ndarray | None = None) -> _VertexNumbers:
        """The bounce's random numbers for the material ``groups`` present (``fused``: one-step delta
        materials; ``mat`` (n,): each path's material), drawn from the paths' sampler in dimension order
        (1–4 light, 5–7 BSDF, 8 roulette)."""
        st, sampler = self.settings, state.sampler
        # Dimensions 1–4 light sampling, 5–7 the BSDF (lobe, direction), 8 roulette; only those this
        # bounce reads are hashed (at delta vertices, before rr_depth, most are not): the numbers are
        # stateless in the dimension, so skipping leaves every other one as it was.
        nee = (self.lights.sampled and bounce + 2 <= st.max_depth
               and not all(self.shaders[g].flags.is_delta_only for g in groups))
        if st.sampler in PADDED_LAYOUT or st.sampler == "sobol":
            # the padded layout's pairs (with "sobol" the first vertex's from Cycles' sets: sampler.vertex_pattern)
            return self._sobol_vertex_numbers(state, acc, nee, all(fused), bounce + 1 >= st.rr_depth, bounce, mat)
        u_light = sampler.next(4) if nee else sampler.skip(4)
        direction_dims = None
        if all(fused):
            u_bsdf = sampler.next(1)                # the lobe choice (smooth dielectric) only
            direction_dims = PathSampler(sampler.keys)
            direction_dims.dimension = sampler.dimension
            sampler.skip(2)
        else:
            u_bsdf = sampler.next(3)
        nums = _VertexNumbers(nee=nee, u_light=u_light, u_bsdf=u_bsdf, direction_dims=direction_dims,
                              pixel=None, sample=None)
        if bounce == 0 and st.stratified:
            nums.pixel, nums.sample = acc.pixel[state.path], acc.sample[state.path]
            self._stratify_vertex(nums)
        if bounce + 1 >= st.rr_depth:
            nums.u_rr = sampler.next(1)[0]
        else:
            sampler.skip(1)
            nums.u_rr = np.empty(0)                 # not read without roulette
        return nums

    def _sobol_vertex_numbers(self, state: PathState, acc: _Accumulators, nee: bool, delta_only: bool,
                              roulette: bool, bounce: int, mat: np.ndarray | None = None) -> _VertexNumbers:
        """The numbers of vertex ``bounce`` with the pair-drawing patterns (engine.render.sampler.vertex_pattern:
        "sobol"'s first vertex from Cycles' sets), by role (engine.render.sampler.SOBOL_*): (light choice, lobe),
        the light point, (roulette, light number 3),
        the direction (deferred where every group is a one-step delta material: ``delta_only``); only the
        pairs this bounce reads are computed (each number depends on its own pair alone)."""
        pixel, sample = acc.pixel[state.path], acc.sample[state.path]
        roles = [SOBOL_CHOICES] + ([SOBOL_LIGHT_POINT] if nee else []) + ([SOBOL_ROULETTE] if nee or roulette else [])
        roles += [] if delta_only else [SOBOL_DIRECTION]
        sampler = vertex_pattern(self.settings.sampler, bounce)
        pairs = [vertex_pair(sampler, bounce, r) for r in roles]
        out = pattern_pairs(sampler, self.settings.seed, pixel, sample, pairs)
        row = {r: 2 * m for m, r in enumerate(roles)}
        u_light = None
        if nee:
            lp, rr = row[SOBOL_LIGHT_POINT], row[SOBOL_ROULETTE]
            u_light = out[[0, lp, lp + 1, rr + 1]]
        if delta_only:
            u_bsdf = out[1:2].copy()                # the lobe choice only; the direction if a group asks
        else:
            d = row[SOBOL_DIRECTION]
            u_bsdf = out[[1, d, d + 1]]
            if sampler != self.settings.sampler and mat is not None:
                # "sobol"'s first vertex: without a lobe choice the direction is "stratified"'s, one Sobol' net with
                # the jitter (rough_sphere_a030: MSE 0.81× Cycles' set); with one, the lobe and direction are Cycles'
                # 3-D set (docs/benchmarks/real-assets.md, helper F)
                # (the Cycles numbers of those rows are still drawn: stratified_pair takes them as its bits below 2^-32)
                one = np.flatnonzero(self.one_lobe[mat])
                if one.size:
                    u_bsdf[1, one], u_bsdf[2, one] = stratified_pair(self.settings.seed, pixel[one], sample[one],
                                                                     u_bsdf[1, one], u_bsdf[2, one],
                                                                     pair=PAIR_BSDF_DIRECTION)
        nums = _VertexNumbers(nee=nee, u_light=u_light, u_bsdf=u_bsdf, direction_dims=None, pixel=pixel,
                              sample=sample, u_rr=out[row[SOBOL_ROULETTE]] if roulette else np.empty(0),
                              sobol_direction=vertex_pair(sampler, bounce, SOBOL_DIRECTION) if delta_only else None,
                              pattern=sampler)
        return nums

    def _stratify_vertex(self, nums: _VertexNumbers) -> None:
        """Stratify the first vertex's numbers in place (``nums.pixel``, ``nums.sample`` set)."""
        # The first vertex's light sample (choice, point) and BSDF sample (lobe, direction) are
        # stratified over the pixel's samples like the jitter (Sobol' dimensions 3–8, each pair with
        # its own per-pixel scramble: still uniform and independent per sample, so unbiased): a
        # lamp's direct light is most of a lit floor's noise.  Only the numbers read are computed
        # (each stratified number depends on its own hashed one and the pair's scramble alone).
        seed, pixel, sample = self.settings.seed, nums.pixel, nums.sample
        nee, u_light, u_bsdf = nums.nee, nums.u_light, nums.u_bsdf
        if nee:
            u_light[1], u_light[2] = stratified_pair(seed, pixel, sample, u_light[1], u_light[2],
                                                     pair=PAIR_LIGHT_POINT)
        if nums.direction_dims is None:
            u_bsdf[1], u_bsdf[2] = stratified_pair(seed, pixel, sample, u_bsdf[1], u_bsdf[2],
                                                   pair=PAIR_BSDF_DIRECTION)
        choice, u_bsdf[0] = stratified_pair(seed, pixel, sample, u_light[0] if nee else u_bsdf[0], u_bsdf[0],
                                            pair=PAIR_CHOICES)
        if nee:
            u_light[0] = choice

    def _late_direction_numbers(self, nums: _VertexNumbers) -> None:
        """A one-step material fell back to ``sample``: its direction numbers (2, n) after all, appended
        to ``nums.u_bsdf`` (stratified at a stratified first vertex, from their pair with "sobol");
        ``nums.direction_dims`` (``nums.sobol_direction``) is spent."""
        if nums.sobol_direction is not None:
            extra = pattern_pairs(nums.pattern, self.settings.seed, nums.pixel, nums.sample, [nums.sobol_direction])
            nums.u_bsdf = np.concatenate((nums.u_bsdf, extra))
            nums.sobol_direction = None
            return
        extra = nums.direction_dims.next(2)
        if nums.pixel is not None:
            extra[0], extra[1] = stratified_pair(self.settings.seed, nums.pixel, nums.sample, extra[0], extra[1],
                                                 pair=PAIR_BSDF_DIRECTION)
        nums.u_bsdf = np.concatenate((nums.u_bsdf, extra))
        nums.direction_dims = None

    @staticmethod
    def _new_scattered(u_rr: np.ndarray, n_side: np.ndarray | None, T_shape: tuple, columns: bool) -> _Scattered:
        """The bounce's continuation record: T (``T_shape`` (P, P, Lm, n)) to be written and eta_step
        preset 1; with ``columns`` (groups write their columns) also d, x_T, valid, is_delta (preset
        True) and pdf (preset 0), else those come from the single group's sample."""
        n = T_shape[3]
        return _Scattered(u_rr=u_rr, n_side=n_side, T=np.empty(T_shape),
                          d=np.empty((3, n)) if columns else None, x_T=np.empty((3, n)) if columns else None,
                          valid=np.empty(n, bool) if columns else None,
                          is_delta=np.ones(n, bool) if columns else None, pdf=np.zeros(n) if columns else None,
                          eta_step=np.ones(n))

    def _scatter_delta(self, bsdf: BSDF, state: PathState, surf: _SurfaceHits, nxt: _Scattered, rows: np.ndarray,
                       n_s: np.ndarray, u_lobe: np.ndarray, t_cols: np.ndarray | None) -> bool:
        """The delta fast path: a one-step delta material writes the columns ``rows`` of ``nxt`` in
        place (BSDF.scatter_delta; ``n_s`` (3, n): all paths' shading normals, back faces flipped,
        ``u_lobe`` (n,)).  False where it falls back to ``sample`` (nothing written)."""
        if not bsdf.scatter_delta(DeltaVertices(rows, n_s, surf.wo, state.lk_m.lam, self.mono, u_lobe, state.T_store,
                                                state.x_T, nxt.T, nxt.d, nxt.x_T, nxt.valid, nxt.eta_step, t_cols)):
            return False
        if not bsdf.radiance_scaling:       # Cycles' convention: the refraction's 1/η² taken back
            scale_columns(nxt.T, rows, nxt.eta_step[rows])      # nxt.T[..., rows] *= eta_step[rows], in place
            nxt.eta_step[rows] = 1.0
        return True

    def _shading_point(self, bsdf: BSDF, state: PathState, surf: _SurfaceHits, mat: np.ndarray,
                       flip: np.ndarray | None, sel: slice | np.ndarray) -> ShadingPoint:
        """The shading point of the paths ``sel`` for ``bsdf``: mapped normal, back faces flipped."""
        lk_m = state.lk_m
        sp = ShadingPoint(gather(surf.p, sel), gather(surf.n_s, sel), gather(surf.n_g, sel), gather(surf.wo, sel),
                          gather(lk_m.lam, sel), self.mono, lk_m.take(sel),
                          self.slot_of[gather(mat, sel)] if bsdf.flags.has(BSDFFlags.BATCHED) else None,
                          None if surf.at is None else surf.at.take(sel))
        sp = bsdf.shading_point(sp)        # a normal/bump-mapped shading normal, else sp itself
        if flip is not None:
            sp = sp.flipped(gather(flip, sel))
        return sp

    def _group_next_event(self, state: PathState, acc: _Accumulators, surf: _SurfaceHits, bsdf: BSDF,
                          sp: ShadingPoint, sel: slice | np.ndarray, rows: np.ndarray, x_T: np.ndarray,
                          t_cols: np.ndarray | None, u_light: np.ndarray, lobe: tuple | None = None,
                          lam_o: np.ndarray | None = None) -> None:
        """Next-event estimation at the paths ``sel`` (batch rows ``rows``, frames ``x_T`` (3, m)) of one
        non-delta group, added to their radiance (and their cost); ``u_light`` (4, n) of all paths; ``lobe``: the
        BSDF's compiled-step inputs (``_lobe_kernel_inputs``; None: the NumPy chain), ``lam_o`` (m,) its sample's Smith
        Λ(ω_o) (``_sample_update``; None: not sampled yet)."""
        medium = None
        if self.media is not None:      # the vertices' volumes and transmittance (shadow rays)
            medium = (gather(state.media, sel), None if state.tau is None else gather(state.tau, sel),
                      gather(surf.prim, sel), gather(surf.n_g, sel), gather(surf.wo, sel), gather(surf.p, sel),
                      gather(state.sampler.keys, sel), state.bounce)
        if lobe is not None and medium is None and self._compiled_light_terms(state, sp):
            # a rough conductor: its NEE in two compiled steps around the shadow rays (the same numbers)
            self._glossy_next_event(sp, state.lk.take(sel), bsdf, lobe, state.T_store, rows, x_T,
                                    gather(u_light, sel), acc, gather(state.path, sel), t_cols, lam_o)
        else:
            contrib = self._next_event(sp, state.lk.take(sel), bsdf, state.T_store, rows, x_T, gather(u_light, sel),
                                       acc.stats, t_cols, medium,
                                       lobes=None if acc.lobes is None else (acc.lobes, gather(state.path, sel)))
            add_to_paths(acc.radiance, gather(state.path, sel), contrib)
        if acc.path_cost is not None:
            acc.path_cost[gather(state.path, sel)] += VERTEX_COST     # a light sample (cost)

    def _lobe_kernel_inputs(self, bsdf: BSDF, sp: ShadingPoint, state: PathState, acc: _Accumulators) -> tuple | None:
        """The BSDF's inputs of engine.kernels.glossy_bounce (BSDF.lobe_kernel_inputs), or None where its next-event
        estimation and sample take the NumPy chain: NumPy kernels, the light passes' recorder, a transport or
        wavelength layout the kernels do not take."""
        get = getattr(bsdf, "lobe_kernel_inputs", None)
        if get is None or not GLOSSY_BOUNCE or acc.lobes is not None or self.P == 2:
            return None
        if sp.lam.shape[0] not in (1, state.T_store.shape[2]):
            return None
        return get(sp)

    def _compiled_light_terms(self, state: PathState, sp: ShadingPoint) -> bool:
        """Whether next-event estimation at a ``_lobe_kernel_inputs`` group runs the compiled steps: not with
        polarised lights or shadow rays through see-through surfaces, and where each wavelength row count (the
        radiance's L, T's, the lobe's) is 1 or L."""
        if (self.lights.polarised and self.P > 1) or (self.visibility is not None and self.visibility.affects_shadows):
            return False
        L = 3 if self.rgb_mode else state.lk.lam.shape[0]
        return state.T_store.shape[2] in (1, L) and sp.lam.shape[0] in (1, L)

    def _sample_update(self, bsdf: BSDF, sp: ShadingPoint, lobe: tuple, u_bsdf: np.ndarray, sel: slice | np.ndarray,
                       rows: np.ndarray, T: np.ndarray, x_T: np.ndarray, T_cols: np.ndarray | None,
                       nxt: _Scattered) -> np.ndarray:
        """``_sample_bsdf``, ``scatter_throughput`` and ``_store_sample`` of a group whose BSDF gave ``lobe``
        (``_lobe_kernel_inputs``) in one compiled pass (glossy_bounce.sample_update_loop; the same numbers): the
        sampled segments and new throughputs of the paths ``sel`` (batch rows ``rows``, frames ``x_T``) into ``nxt``;
        returns the sampler's Smith Λ(ω_o) (m,) (NaN where not computed) for next-event estimation."""
        n, N = sp.n, nxt.T.shape[3]
        if nxt.d is None:           # a single group's record (_new_scattered): its columns, written in full here
            nxt.d, nxt.x_T, nxt.valid = np.empty((3, N)), np.empty((3, N)), np.empty(N, bool)
            nxt.is_delta, nxt.pdf = np.empty(N, bool), np.empty(N)
        c = np.ascontiguousarray
        eta, s, m, dist, kind, p, use_given, _, _, w_d, _ = lobe
        lam_o = np.empty(n)
        u_lobe = gather(u_bsdf[0], sel)
        sample_update_loop(c(rows, dtype=np.int64), c(rows if T_cols is None else T_cols, dtype=np.int64),
                           c(sp.n_s, dtype=np.float64), c(sp.wo, dtype=np.float64), c(x_T, dtype=np.float64),
                           c(np.broadcast_to(u_lobe, (n,)), dtype=np.float64),
                           c(gather(u_bsdf[1:], sel), dtype=np.float64), eta, s, m, dist, kind, p, use_given, w_d,
                           ERFCX_COEF_F64, ERFCX_K_F64, T, sp.lam.shape[0], lam_o, nxt.T, nxt.d, nxt.x_T, nxt.valid,
                           nxt.pdf, nxt.is_delta, nxt.eta_step)
        return lam_o

    def _glossy_next_event(self, sp: ShadingPoint, lookup: WavelengthLookup, bsdf: BSDF, terms: tuple,
                           T: np.ndarray, rows: np.ndarray, x_T: np.ndarray, u: np.ndarray, acc: _Accumulators,
                           path: np.ndarray, T_cols: np.ndarray | None, lam_o: np.ndarray | None = None) -> None:
        """``_next_event`` and ``add_to_paths`` of a group whose BSDF gave ``terms`` (``_lobe_kernel_inputs``): the
        light weight, MIS, response and T·S in one compiled step (light_terms_loop), the shadow rays whose answer
        can change the radiance, then T·S·weight·visibility into ``acc.radiance`` at ``path`` (the chain's bits);
        ``lam_o``: the sample's Smith Λ(ω_o) (m,) (NaN: not computed; None: none)."""
        n, P = sp.n, self.P
        L = 3 if self.rgb_mode else lookup.lam.shape[0]
        ls = self._sample_lights(sp, lookup, u, L, bsdf.flags.transmits, bsdf.geometric_sides)
        c = np.ascontiguousarray
        ok = np.array(ls.ok, dtype=bool)
        A, B, C, S = (np.empty((sp.lam.shape[0], 1)) for _ in range(4))
        o, o_t, wi_t = (np.empty((3, n)) for _ in range(3))
        terms_acc, weight = np.empty((n, P, L)), np.empty((n, L))
        skip, t_t, test = np.empty(n, bool), np.empty(n), np.empty(n, np.int64)
        cols = c(rows if T_cols is None else T_cols, dtype=np.int64)
        f64 = np.float64
        k = light_terms_loop(c(sp.n_s, dtype=f64), c(sp.wo, dtype=f64), c(x_T, dtype=f64), c(sp.p, dtype=f64),
                             c(sp.n_g, dtype=f64), c(ls.wi, dtype=f64), c(ls.dist, dtype=f64), c(ls.scale, dtype=f64),
                             c(ls.pdf_l, dtype=f64), ok, c(np.atleast_1d(ls.delta), dtype=bool),
                             c(ls.emitted, dtype=f64), c(np.atleast_1d(ls.select_prob), dtype=f64), *terms,
                             ERFCX_COEF_F64, ERFCX_K_F64, _NO_LAMBDA if lam_o is None else lam_o, T, cols,
                             RAY_EPSILON, A, B, C, S, o, terms_acc, weight, skip, o_t, wi_t, t_t, test)
        if not ok.any():            # no sample counts: nothing added (as _light_weight)
            return
        blocked = np.zeros(n, bool)
        if k:
            blocked[test[:k]] = self.scene.occluded(c(o_t[:, :k]), c(wi_t[:, :k]), t_t[:k])
            acc.stats["shadow_rays"] += k
            if blocked.any():
                self._unblock_own_hits(sp, ls, blocked)
        if len(ls.owners) > 1:
            for _, sel in ls.owners:
                if not ok[sel].any():
                    skip[sel] = True        # a light none of whose samples counts adds nothing
        add_light_terms_loop(acc.radiance, c(path, dtype=np.int64), terms_acc, weight, skip, blocked)

    @staticmethod
    def _sample_bsdf(bsdf: BSDF, sp: ShadingPoint, u_bsdf: np.ndarray, sel: slice | np.ndarray) -> BSDFSample:
        """BSDF sample of the paths ``sel`` (``u_bsdf`` (3, n) of all paths), its weight in Cycles'
        convention where the material asks for it (BSDF.radiance_scaling)."""
        bs = bsdf.sample(sp, gather(u_bsdf[0], sel), gather(u_bsdf[1:], sel))
        if not bsdf.radiance_scaling and bs.eta_sq is not None:     # Cycles' convention (BSDF.radiance_scaling)
            bs = BSDFSample(bs.wi, bs.weight.scaled(bs.eta_sq[None, :]), bs.pdf, bs.is_delta, bs.valid, None)
        return bs

    @staticmethod
    def _store_sample(nxt: _Scattered, bs: BSDFSample, sel: slice | np.ndarray, columns: bool) -> None:
        """The sampled segments of the paths ``sel`` into ``nxt``: their columns, or (not ``columns``:
        a single group) the sample's arrays themselves."""
        if not columns:
            nxt.d, nxt.x_T, nxt.is_delta, nxt.pdf = bs.wi, bs.weight.x_in, bs.is_delta, bs.pdf
            nxt.valid = np.array(bs.valid, dtype=bool)      # own copy: the roulette updates it in place
            if bs.eta_sq is not None:
                nxt.eta_step[:] = bs.eta_sq
            return
        if isinstance(sel, slice):
            sel = np.arange(nxt.pdf.shape[0])[sel]
        put_columns(nxt.d, sel, bs.wi)
        put_columns(nxt.x_T, sel, bs.weight.x_in)
        put_columns(nxt.valid, sel, bs.valid)
        put_columns(nxt.is_delta, sel, bs.is_delta)
        put_columns(nxt.pdf, sel, bs.pdf)
        if bs.eta_sq is not None:
            put_columns(nxt.eta_step, sel, bs.eta_sq)

    def _back_faces(self, mat: np.ndarray, n_g: np.ndarray, wo: np.ndarray) -> np.ndarray | None:
        """(n,) True where a path sees the back of a two-sided material (n_g·wo < 0), or None for none."""
        if not self.any_two_sided:
            return None
        flip = self.two_sided[mat] & (dot(n_g, wo) < 0)
        return flip if flip.any() else None

    def _next_segments(self, state: PathState, acc: _Accumulators, surf: _SurfaceHits, nxt: _Scattered,
                       bounce: int) -> None:
        """Russian roulette (from ``rr_depth``) on the new throughputs, then the paths that go on
        (sampled validly, survived, finite and not black) keep their sampled segments, starting from
        the offset hit points: one compiled step (kernels.transport.next_segments) for the roulette,
        the survivors' columns and their origins.  Paths with a non-finite throughput end here
        (counted; their light so far is kept).  With absorbing interiors the paths that cross a
        volume's face enter or leave it (engine.render.media) and the roulette weighs T00·η² by the
        largest transmittance max_λ τ (paths absorbed entirely end here)."""
        eta_in, tau_max = state.eta_sq, None
        if state.media is not None:
            vol, entering = self.media.crossing_sides(surf.prim, surf.wo, nxt.d, surf.n_g)
            if (vol >= 0).any():
                cross(state.media, np.arange(state.n), vol, entering)
            if state.tau is not None:
                tau_max = state.tau.max(axis=0)
                nxt.valid &= tau_max > 0
                tau_max = np.where(tau_max > 0, tau_max, 1.0)
                eta_in = state.eta_sq * tau_max
        (idx, nonfinite, T, x_T, d, eta_sq, path, keys, is_delta, pdf, p, o) = next_segments(
            nxt.T, eta_in, nxt.eta_step, nxt.u_rr, nxt.valid, bounce + 1 >= self.settings.rr_depth,
            nxt.x_T, nxt.d, state.path, state.sampler.keys, nxt.is_delta, nxt.pdf, surf.p, surf.n_g, RAY_EPSILON,
            compact_T=False)
        if tau_max is not None:
            eta_sq = eta_sq / tau_max[idx]          # η² alone again (τ stays apart from it)
        # with volumes: the new origins lie off the surface, and distances in volumes count from the vertex
        gap = ((o - p) * d).sum(axis=0) if state.media is not None else None
        acc.stats["nonfinite"] += nonfinite
        state.n_prev = nxt.n_side
        # where the next segment starts (light selection, analytic lamps' pdfs); the survivors'
        # throughputs stay where the scatter wrote them (columns idx of T, PathState.T_col)
        state.keep(idx, path=path, T=T, T_col=idx if idx.shape[0] < T.shape[3] else None, x_T=x_T, d=d,
                   eta_sq=eta_sq, prev_delta=is_delta, prev_pdf=pdf, p_prev=p if self.keep_origins else None, o=o,
                   keys=keys, gap=gap)
        state.t_max = None

    def _finish(self, acc: _Accumulators, n_total: int) -> tuple[np.ndarray, dict[str, int]]:
        """The batch's Stokes × RGB values (4, 3, n_total) (non-finite samples zeroed and counted)."""
        stats = acc.stats
        radiance = acc.radiance
        if self.rgb_mode:
            out, nonfinite = stokes_rgb_samples(radiance, in_place=True)     # the accumulators end here
        else:
            out, nonfinite = spectral_stokes_rgb_samples(radiance, acc.w_rgb)
        stats["nonfinite"] += nonfinite
        if acc.transparency is not None:
            stats["alpha"] = 1.0 - acc.transparency
        if acc.guides is not None:
            stats["denoise"] = (acc.guides.albedo, acc.guides.normal)
        if acc.path_cost is not None:
            stats["path_cost"] = acc.path_cost
        return out, stats

    def _shadow_transmittance(self, p: np.ndarray, n_g: np.ndarray, wi: np.ndarray, t_max: np.ndarray,
                              ok: np.ndarray, stats: dict[str, int], record: list | None = None) -> np.ndarray:
        """Fraction (m,) of the light that reaches p along wi through shadow-invisible and pass-through
        surfaces (0 where blocked, and where ``ok`` is False: no shadow ray is cast there).  ``record``:
        a list to which the pass-through surfaces crossed are appended (engine.render.visibility)."""
        trans = np.zeros(p.shape[1])
        idx = ok.nonzero()[0]
        if idx.size:
            w = gather(wi, idx)
            layers = [] if record is not None else None
            p_idx = gather(p, idx)
            o = offset_origin(p_idx, gather(n_g, idx), w)
            tr, rays = self.visibility.transmittance(self.scene, o, w, t_max[idx], record=layers)
            trans[idx] = tr
            stats["shadow_rays"] += rays
            if layers:          # distances from the vertex (the shadow rays start off the surface)
                gap = ((o - p_idx) * w).sum(axis=0)
                record.extend((idx[r], prims, t + gap[r]) for r, prims, t in layers)
        return trans

    def _shadow_media(self, medium: tuple, wi: np.ndarray, dist: np.ndarray, lookup: WavelengthLookup,
                      crossings: list) -> np.ndarray | None:
        """Absorption (L, n) of the light arriving along the shadow rays wi over their lengths ``dist``
        (inf: from outside the scene) times the paths' transmittance so far, or None for none.
        ``medium`` = (stacks (K, n), τ (L, n) or None, triangles, geometric normals, wo, positions (3, n),
        the paths' sampler keys, their bounce) of the vertices; ``crossings``: the pass-through surfaces the
        shadow rays cross."""
        tau = medium[1]
        n = medium[0].shape[1]
        segment = self.media.march(self._shadow_stack(medium, wi), wi, crossings, lookup)
        f = segment.transmittance(np.arange(n), dist) if segment.absorbs else None
        if tau is not None:
            f = tau if f is None else f * tau
        return f

    def _shadow_stack(self, medium: tuple, wi: np.ndarray) -> np.ndarray:
        """The volume stacks (K, n) (a copy) the shadow rays along wi start with (``medium`` as for
        ``_shadow_media``): one that leaves through the vertex's own face into (out of) its volume starts
        inside (outside) it."""
        stack, _, prim, n_g, wo = medium[:5]
        stack = stack.copy()
        vol, entering = self.media.crossing_sides(prim, wo, wi, n_g)
        if (vol >= 0).any():
            cross(stack, np.arange(stack.shape[1]), vol, entering)
        return stack

    def _next_event(self, sp: ShadingPoint, lookup: WavelengthLookup, bsdf: BSDF, T: np.ndarray, rows: np.ndarray,
                    x_T: np.ndarray, u: np.ndarray, stats: dict[str, int],
                    T_cols: np.ndarray | None = None, medium: tuple | None = None,
                    lobes: tuple | None = None) -> np.ndarray:
        """Direct light at non-delta vertices, MIS-weighted against BSDF sampling; (P, L, n).

        ``lookup`` holds the path's wavelengths (lights are evaluated at all of them); the
        material sees ``sp.lam`` (one wavelength where nothing depends on λ).  Each chosen light
        samples its own paths; the samples are then put together, so that the BSDF, the shadow
        rays and the throughput run once over all paths (per path the same arithmetic as one
        light at a time).  ``rows``: the vertices' paths in the batch's state, ``T_cols``: the
        columns of T holding their throughputs (None: ``rows``; PathState.T_col).  ``medium``: the
        vertices' absorbing volumes and transmittance (see ``_shadow_media``; None: no interiors).  ``lobes``:
        (the light passes' recorder, the vertices' batch path indices), told each sample's direction and weight.
        """
        n = sp.n
        P = self.P
        L = 3 if self.rgb_mode else lookup.lam.shape[0]
        ls = self._sample_lights(sp, lookup, u, L, bsdf.flags.transmits, bsdf.geometric_sides)
        weighted = self._light_weight(sp, bsdf, x_T, ls)
        if weighted is None:
            return np.zeros((P, L, n))
        S, weight = weighted
        crossings = [] if medium is not None else None
        weight = weight * self._shadow_visibility(sp, ls, stats, crossings)[None, :]
        if medium is not None:
            absorbed = self._shadow_media(medium, ls.wi, ls.dist, lookup, crossings)
            if absorbed is not None:
                weight = weight * absorbed
        if lobes is not None:
            lobes[0].light(bsdf, sp, lobes[1], ls.wi, weight, T, rows if T_cols is None else T_cols)
        light_out = throughput_times_stokes(T, rows if T_cols is None else T_cols, S, weight)
        for _, sel in ls.owners:
            if len(ls.owners) > 1 and not ls.ok[sel].any():
                light_out[:, :, sel] = 0.0          # a light none of whose samples counts adds nothing
        if light_out.shape == (P, L, n):
            return light_out
        out = np.zeros((P, L, n))
        out[:] = light_out
        return out

    def _sample_lights(self, sp: ShadingPoint, lookup: WavelengthLookup, u: np.ndarray, L: int,
                       transmits: bool = False, geometric_sides: bool = False) -> _LightSamples:
        """One light sample per vertex: the light chosen by u[0] (its fraction within the light's slot
        reused), the point on it by u[1], u[2] ((4, n)); ``L``: the radiance's wavelength count.  With the
        light tree the choice may be a triangle of a mesh light (sampled by area within it) or no light at all
        (nothing can reach the vertex: no sample); ``transmits``: the material transmits (light from both sides)."""
        light_set = self.lights
        n_side = sp.n_g * np.sign(dot(sp.n_g, sp.wo))[None, :] if self.spatial else None
        tri = None
        if self.tree is not None:
            if transmits:
                n_side = np.zeros_like(n_side)
            choice, u_rest, chosen_prob, tri = self.tree.choose(u[0], sp.p, n_side)
        else:
            choice, u_rest, chosen_prob = light_set.choose(u[0], sp.p, n_side)
        lights_chosen = np.unique(choice)
        if len(lights_chosen) == 1 and lights_chosen[0] >= 0:
            ls = self._sample_one_light(int(lights_chosen[0]), sp, lookup, u, u_rest, chosen_prob, tri)
        else:
            ls = self._sample_several_lights(lights_chosen, choice, sp, lookup, u, u_rest, chosen_prob, L, tri)
        if light_set.polarised and self.P > 1:
            ls.polarised = light_samples_polarisation(light_set, ls.owners, ls.wi)
        if geometric_sides:         # (BSDF.geometric_sides) a light on the other side of the surface than of n_s: none
            ls.ok = ls.ok & same_side(sp.n_g, sp.n_s, ls.wi)
        return ls

    def _light_points(self, light, li: int, p: np.ndarray, u: np.ndarray, tri: np.ndarray | None, lookup, points):
        """(wi, dist, scale, pdf, valid, emitted) of light ``li`` sampled from p (3, m) with u (3, m): on the
        triangles ``tri`` (m,) the light tree chose (a split light), else by the light's own sampling; the
        sampled points of lights that vary over the surface or were sampled by triangle go into ``points``."""
        if tri is not None and self.tree.split[li]:
            wi, dist, scale, pdf_l, ok, points[li] = light.sample_triangles(p, tri, u[1], u[2])
            emitted = (light.emitted_at(points[li], lookup, self._integrated_rgb, self.mono)
                       if light.varies_over_surface else self._emitted(light, lookup, wi))
        elif light.varies_over_surface:
            wi, dist, scale, pdf_l, ok, points[li] = light.sample_points(p, u)
            emitted = light.emitted_at(points[li], lookup, self._integrated_rgb, self.mono)
        else:
            wi, dist, scale, pdf_l, ok = light.sample(p, u)
            emitted = self._emitted(light, lookup, wi)
        return wi, dist, scale, pdf_l, ok, emitted

    def _sample_one_light(self, li: int, sp: ShadingPoint, lookup: WavelengthLookup, u: np.ndarray,
                          u_rest: np.ndarray, chosen_prob: np.ndarray | None,
                          tri: np.ndarray | None = None) -> _LightSamples:
        """Light ``li`` sampled for every vertex: its arrays as they are, no gathered copies."""
        light_set = self.lights
        points = {}
        light = light_set.lights[li]
        # Reuse u[0]'s fraction within the chosen light's slot for triangle choice.
        wi, dist, scale, pdf_l, ok, emitted = self._light_points(light, li, sp.p, np.stack((u_rest, u[1], u[2])), tri,
                                                                 lookup, points)
        delta = light.is_delta
        if light.shades_nothing:         # hidden from indirect rays: lights nothing (Cycles)
            ok = np.zeros_like(ok)
        select_prob = light_set.prob[li] if chosen_prob is None else chosen_prob
        return _LightSamples(wi=wi, dist=dist, scale=scale, pdf_l=pdf_l, ok=ok, delta=delta, emitted=emitted,
                             select_prob=select_prob, owners=[(li, slice(None))], points=points)

    def _sample_several_lights(self, lights_chosen: np.ndarray, choice: np.ndarray, sp: ShadingPoint,
                               lookup: WavelengthLookup, u: np.ndarray, u_rest: np.ndarray,
                               chosen_prob: np.ndarray | None, L: int, tri: np.ndarray | None = None) -> _LightSamples:
        """Each light of ``lights_chosen`` sampled for its vertices (``choice`` (n,)), put together; vertices
        whose choice is no light (the light tree's NO_LIGHT, < 0) get no valid sample."""
        light_set = self.lights
        n = sp.n
        points = {}
        wi, dist, scale, pdf_l = np.empty((3, n)), np.empty(n), np.empty(n), np.empty(n)
        ok, delta, emitted = np.empty(n, bool), np.empty(n, bool), np.empty((L, n))
        select_prob = light_set.prob[choice] if chosen_prob is None else chosen_prob
        # each light's vertices: ascending rows of one stable sort (np.nonzero(choice == li) without a pass each)
        order = np.argsort(choice, kind="stable")
        bounds = np.searchsorted(choice[order], lights_chosen, side="right")
        first = 0
        if lights_chosen[0] < 0:            # no light: an invalid sample of weight 0 (probability 1: no 0/0)
            none = np.flatnonzero(choice < 0)
            wi[:, none], dist[none], scale[none], pdf_l[none], ok[none], delta[none] = 0.0, 1.0, 0.0, 0.0, False, False
            emitted[:, none] = 0.0
            select_prob = np.where(choice < 0, 1.0, select_prob)
            first = 1
        u_all = np.stack((u_rest, u[1], u[2]))      # (3, n): one gather per light
        owners, by_area, group = [], [], self.area_group
        for k in range(first, len(lights_chosen)):
            li = int(lights_chosen[k])
            sel = order[(bounds[k - 1] if k else 0):bounds[k]]
            light = light_set.lights[li]
            owners.append((li, sel))
            delta[sel] = light.is_delta
            if group.index[li] >= 0 and (tri is None or not self.tree.split[li]):
                by_area.append((li, sel))            # sampled below, with the group's other emitters
                emitted[:, sel] = self._emitted(light, lookup.take(sel))
                continue
            w, d, sc, pdf, valid, emitted[:, sel] = self._light_points(
                light, li, gather(sp.p, sel), gather(u_all, sel), None if tri is None else tri[sel], lookup.take(sel),
                points)
            wi[:, sel], dist[sel], scale[sel], pdf_l[sel], ok[sel] = w, d, sc, pdf, valid
            if light.shades_nothing:
                ok[sel] = False
        if by_area:
            # the emitters sampled by area, in one compiled pass (per point the same arithmetic as their ``sample``)
            rows = by_area[0][1] if len(by_area) == 1 else np.concatenate([sel for _, sel in by_area])
            member = np.repeat(group.index[[li for li, _ in by_area]], [sel.size for _, sel in by_area])
            wi[:, rows], dist[rows], scale[rows], pdf_l[rows], ok[rows] = group.sample(
                gather(sp.p, rows), gather(u_all, rows), member)
            for li, sel in by_area:
                if light_set.lights[li].shades_nothing:
                    ok[sel] = False
        return _LightSamples(wi=wi, dist=dist, scale=scale, pdf_l=pdf_l, ok=ok, delta=delta, emitted=emitted,
                             select_prob=select_prob, owners=owners, points=points)

    def _light_weight(self, sp: ShadingPoint, bsdf: BSDF, x_T: np.ndarray,
                      ls: _LightSamples) -> tuple[np.ndarray, np.ndarray] | None:
        """(S, weight) of the light samples before shadowing: the BSDF's Stokes response S ((P or 1, L, n)
        in frame ``x_T``) to the unpolarised light and its weight (L, n): radiance × |cosθ| × MIS / selection
        probability; ``ls.ok`` narrowed to the samples that count.  None where none does."""
        direct = getattr(bsdf, "direct_light", None)
        if direct is not None:
            # Lambert: the BSDF's value, pdf, MIS and the light's weight in one pass (the same numbers)
            S, weight, ls.ok = direct(sp, ls.wi, ls.emitted, ls.scale, ls.ok, ls.pdf_l, ls.select_prob, ls.delta)
            return (S, weight) if ls.ok.any() else None
        value = ls.emitted * ls.scale[None, :]
        cos_i = np.abs(dot(sp.n_s, ls.wi))
        ls.ok &= cos_i > 0
        if not ls.ok.any():
            return None
        f = pdf = None
        if isinstance(ls.delta, np.ndarray) or not ls.delta:      # the MIS reads the BSDF's pdf: asked with eval
            f, pdf = bsdf.eval_and_pdf(sp, ls.wi)
        S = self._bsdf_response(sp, bsdf, x_T, ls.wi, ls.polarised, f)
        mis = self._light_mis(sp, bsdf, ls, pdf)
        return S, value * (cos_i * mis / ls.select_prob * ls.ok)[None, :]

    def _bsdf_response(self, sp: ShadingPoint, bsdf: BSDF, x_T: np.ndarray, wi: np.ndarray,
                       polarised: tuple | None = None, f: MuellerValue | None = None) -> np.ndarray:
        """The Stokes vector (P, L, n) (depolarisers: (1, L, n)) the BSDF scatters towards wo from light of unit
        radiance arriving along wi (3, n), in the paths' frames ``x_T``: unpolarised light, or with ``polarised``
        = (normalised Stokes (4, n), its frame x_e (3, n)) polarised light (engine.render.polarised_light).
        ``f``: ``bsdf.eval(sp, wi)`` if the caller has it."""
        P = self.P
        f = bsdf.eval(sp, wi) if f is None else f
        if not bsdf.radiance_scaling:          # Cycles' convention (BSDF.radiance_scaling)
            k = bsdf.refraction_eta_sq(sp)
            if k is not None:
                through = dot(wi, sp.n_g) * dot(sp.wo, sp.n_g) < 0
                f = f.scaled(np.where(through, k, 1.0)[None, :])
        if polarised is None and f.kind == "abcs" and P > 2:
            # (M00, M10, 0, 0) in the paths' frames, in one compiled pass (the same arithmetic)
            return unpolarised_response_in_frame(f.m00(), f.B, f.x_out, x_T, sp.wo, P)
        if polarised is not None and f.kind != "depolarising":
            s_in = in_frame(polarised[0], polarised[1], f.x_in, -wi)
            S = mueller_times_stokes(f, s_in, P)
        else:
            # light leaving a depolariser has only S0
            S = unpolarised_response(f, 1 if f.kind == "depolarising" else P)
        if P > 1 and f.kind != "depolarising":
            c2, s2 = frame_rotation(f.x_out, x_T, sp.wo)
            S = rotate_stokes(S, c2, s2)
        return S

    @staticmethod
    def _light_mis(sp: ShadingPoint, bsdf: BSDF, ls: _LightSamples, pdf: np.ndarray | None = None) -> np.ndarray:
        """Power-heuristic MIS weights (n,) of the light samples against BSDF sampling (delta lights: 1); ``pdf``:
        ``bsdf.pdf(sp, ls.wi)`` if the caller has it."""
        if not isinstance(ls.delta, np.ndarray) and ls.delta:
            return np.ones(sp.n)
        pdf = bsdf.pdf(sp, ls.wi) if pdf is None else pdf
        if isinstance(ls.delta, np.ndarray):       # several lights: delta ones have no MIS
            return np.where(ls.delta, 1.0, power_heuristic(ls.pdf_l * ls.select_prob, pdf))
        return power_heuristic(ls.pdf_l * ls.select_prob, pdf)

    def _shadow_visibility(self, sp: ShadingPoint, ls: _LightSamples, stats: dict[str, int],
                           crossings: list | None) -> np.ndarray:
        """The fraction (n,) of each light sample's light that reaches its vertex (0 where ``ls.ok`` is
        False: no shadow ray is cast there): the transmittance through shadow-invisible and pass-through
        surfaces (float; ``crossings`` collects the pass-through surfaces), else unoccluded (bool)."""
        p = sp.p
        # every path's shadow ray (origin off the surface, length short of the light) in one pass
        o, t_max = shadow_rays(p, sp.n_g, ls.wi, ls.dist, RAY_EPSILON)
        if self.visibility is not None and self.visibility.affects_shadows:
            # shadow-invisible and pass-through (alpha) surfaces let (part of) the light through
            return self._shadow_transmittance(p, sp.n_g, ls.wi, t_max, ls.ok, stats, crossings)
        blocked = self._occluded(o, ls.wi, t_max, ls.ok, stats)
        if blocked.any():
            self._unblock_own_hits(sp, ls, blocked)
        return ~blocked

    def _occluded(self, o: np.ndarray, wi: np.ndarray, t_max: np.ndarray, ok: np.ndarray,
                  stats: dict[str, int]) -> np.ndarray:
        """(n,) True where the shadow ray from o (3, n) along wi is blocked short of t_max (only where
        ``ok``: elsewhere False, no ray cast)."""
        n = wi.shape[1]
        if ok.all():
            blocked = self.scene.occluded(o, wi, t_max)
            stats["shadow_rays"] += n
            return blocked
        test = ok.nonzero()[0]
        blocked = np.zeros(n, bool)
        # np.take: contiguous (3, m) columns (o[:, test] would be a transposed copy)
        blocked[test] = self.scene.occluded(gather(o, test), gather(wi, test), t_max[test])
        stats["shadow_rays"] += test.size
        return blocked

    def _unblock_own_hits(self, sp: ShadingPoint, ls: _LightSamples, blocked: np.ndarray) -> None:
        """In place: ``blocked`` (n,) cleared where the shadow ray towards a light that blocks its own
        shadow rays was stopped by that light itself (CompiledScene.unblock_own_hits; the lights' rays in one
        query: each ray's answer is its own, whichever rays share the call)."""
        rows, lights, dists, cosines = [], [], [], []
        for li, sel in ls.owners:
            light = self.lights.lights[li]
            if not light.blocks_own_shadow_rays:
                continue
            # only the light's blocked rays are looked at again (the others stay as they are)
            mine = blocked[sel]          # (sel may be slice(None): every vertex)
            if not mine.any():
                continue
            every = mine.all()
            if not every:
                sel = np.flatnonzero(mine) if isinstance(sel, slice) else sel[mine]
            d, pdf = ls.dist[sel], ls.pdf_l[sel]
            if li in ls.points:        # at the sampled points (their pdf need not be by area)
                tri = ls.points[li][0]
                cos_l = light.cos_at((tri if every else tri[mine],), gather(ls.wi, sel))
            else:                   # cosθ at the light from the area pdf dist²/(cosθ·A)
                cos_l = np.minimum(d * d / np.maximum(pdf * light.total_area, 1e-300), 1.0)
            rows.append(sel)
            lights.append(np.full(d.shape[0], li, np.int64))
            dists.append(d)
            cosines.append(cos_l)
        if not rows:
            return
        # (one light: its rows as they are, slice(None) included, so gather copies nothing)
        sel = rows[0] if len(rows) == 1 else np.concatenate(rows)      # (several lights: index arrays)
        light = lights[0][0] if len(rows) == 1 else np.concatenate(lights)
        d, cos_l = (dists[0], cosines[0]) if len(rows) == 1 else (np.concatenate(dists), np.concatenate(cosines))
        blocked[sel] = self.scene.unblock_own_hits(light, gather(sp.p, sel), gather(sp.n_g, sel), gather(ls.wi, sel),
                                                   d, cos_l, blocked[sel])

    def _pick_probability(self, li: int, prev: tuple):
        """The probability (m,) or scalar with which next-event estimation at the vertices ``prev`` = (positions,
        side normals) (3, m) or (None, None) picks light ``li`` (a whole light: the tree's, or the LightSet's)."""
        if self.tree is None:
            return self.lights.prob_at(li, *prev)
        if prev[0] is None:         # camera rays: never MIS-weighted
            return 1.0
        return self.tree.probability_of_light(li, *prev)

    def _hit_pdf(self, light, li: int, dist: np.ndarray, cos_l: np.ndarray, prim: np.ndarray, prev: tuple,
                 d: np.ndarray, sel: np.ndarray) -> np.ndarray:
        """The probability density (m,) (solid angle) with which next-event estimation from the vertices ``prev`` =
        (positions, side normals) (3, m) would have produced the hits of ``light`` (index ``li``) at distances
        ``dist`` on triangles ``prim`` facing the rays ``sel`` (directions d[:, sel]) at ``cos_l``: the light's
        (or, for a light the tree splits, the hit triangle's) pick probability × the light's pdf of the point."""
        if self.tree is not None and self.tree.split[li]:
            # the tree picks this light's triangles one by one: the hit triangle's pick probability × its pdf
            p_light = light.triangle_pdf(dist, cos_l, prim)
            return p_light * (1.0 if prev[0] is None else self.tree.probability_of_triangles(prim, *prev))
        if light.varies_over_surface:
            p_light = light.pdf_hit(dist, cos_l, prev[0], prim=prim)
        else:
            # lamps sampled by a warp need the arrival point, hence the direction (EllipseEmitter)
            p_light = light.pdf_hit(dist, cos_l, prev[0], *((d[:, sel],) if light.hit_pdf_needs_direction else ()))
        return p_light * self._pick_probability(li, prev)

    def _emitter_hits(self, radiance: np.ndarray, path: np.ndarray, T: np.ndarray, cols, idx: np.ndarray,
                      prims: np.ndarray, dists: np.ndarray, d: np.ndarray, lk: WavelengthLookup, prev_delta: np.ndarray,
                      prev_pdf: np.ndarray, at_prev, camera: bool, bary=None, o: np.ndarray | None = None,
                      att=None, scale: np.ndarray | None = None, x_T: np.ndarray | None = None) -> None:
        """Emission picked up where the rays ``idx`` (each at most once) hit or cross emitting
        triangles ``prims`` at distances ``dists``, MIS-weighted against next-event estimation
        from the vertices the rays left (``at_prev(rows)``: their positions and side normals).
        ``camera``: these are camera rays (lights hidden from the camera add nothing); ``cols(rows)``:
        the columns of T holding the throughputs of the paths ``rows`` (PathState.T_columns).
        Lights whose radiance varies over the surface read it at the hits: their barycentrics
        ``bary`` = (u, v) (n,) each, or where None, at the points o + dists·d of the rays' origins
        ``o`` (3, N) (crossings of non-occluding emitters).  ``att(rows, s)``: the paths' absorption up
        to distance s (PathTracer._attenuation; None: none).  ``scale`` (n,): a weight per ray ``idx`` (None: 1).
        ``x_T`` (3, N): the paths' frames (polarised emitters' light is put into them)."""
        light_set = self.lights
        emitter = self.scene.tri_emitter[prims]
        cos_hit = -dot(d[:, idx], self.scene.tri_normal[prims].T)
        # each light's hits: ascending rows of one stable sort (np.flatnonzero(emitter == li) without a pass each),
        # every per-hit array put in that order once, so that a light's hits are slices of it
        order = np.argsort(emitter, kind="stable")
        lights, starts = np.unique(emitter[order], return_index=True)
        ends = np.append(starts[1:], order.size)
        cos_s = cos_hit[order]
        front = np.zeros(order.size, bool)
        emitting = []
        for li, start, end in zip(lights, starts, ends):
            if li < 0 or (camera and li in light_set.camera_hidden):
                continue
            light = light_set.lights[li]
            part = slice(start, end)
            cos_s[part] = light.facing(cos_s[part])
            front[part] = cos_s[part] > 0       # one-sided emitters shine only from their front faces
            emitting.append((int(li), light, start, end))
        kept = np.flatnonzero(front)
        if kept.size == 0:
            return
        rows_all = order[kept]
        sel_all, prim_all, dist_all, cos_all = idx[rows_all], prims[rows_all], dists[rows_all], cos_s[kept]
        bary_all = None if bary is None else (bary[0][rows_all], bary[1][rows_all])
        scale_all = None if scale is None else scale[rows_all]
        bounds = np.searchsorted(kept, [[s for _, _, s, _ in emitting], [e for _, _, _, e in emitting]])
        # MIS against next-event estimation, only where the path's last bounce was not a delta one (weight 1
        # there: camera rays, smooth surfaces), so its light-pick probability is not traversed for nothing
        nd_all = ~prev_delta[sel_all]
        p_light_all = np.zeros(kept.size)
        per_light, Le_all, polarised = [], None, False
        for (li, light, _, _), a, b in zip(emitting, bounds[0], bounds[1]):
            if a == b:
                continue
            part = slice(a, b)
            sel, hit_prim, dist_l, cos_l = sel_all[part], prim_all[part], dist_all[part], cos_all[part]
            if light.varies_over_surface:
                if bary_all is not None:
                    b1, b2 = bary_all[0][part], bary_all[1][part]
                else:
                    b1, b2 = light.barycentrics(hit_prim, o[:, sel] + d[:, sel] * dist_l[None, :])
                Le = light.emitted_at((hit_prim, b1, b2), lk.take(sel), self._integrated_rgb, self.mono)
            else:
                Le = self._emitted(light, lk.take(sel))
            factor = light.emission_factor(cos_l)
            if factor is not None:
                Le = Le * factor[None, :]
            if scale_all is not None:
                Le = Le * scale_all[part][None, :]
            if att is not None:
                f = att(sel, dist_l)
                if f is not None:
                    Le = Le * f
            if Le_all is None:
                Le_all = np.empty((Le.shape[0], kept.size))
            Le_all[:, part] = Le
            nd = nd_all[part]
            if nd.any():
                which = slice(None) if nd.all() else np.flatnonzero(nd)
                s_nd = sel[which]
                p_light_all[part][which] = self._hit_pdf(light, li, dist_l[which], cos_l[which], hit_prim[which],
                                                         at_prev(s_nd), d, s_nd)
            polarised = polarised or light.polarisation is not None
            per_light.append((light, part))
        # the MIS weights, and the light into the paths: in one pass for all the lights (each ray hits once)
        w_all = np.ones(kept.size)
        nd_rows = np.flatnonzero(nd_all)
        if nd_rows.size:
            w_all[nd_rows] = power_heuristic(prev_pdf[sel_all[nd_rows]], p_light_all[nd_rows])
        if not self._stokes_of_light(polarised, x_T):
            add_light(radiance, path, T, sel_all, Le_all, w_all, cols(sel_all))
            return
        for light, part in per_light:
            sel = sel_all[part]
            self._add_light(radiance, path, T, sel, Le_all[:, part], w_all[part], cols(sel), light, d[:, sel], x_T)
