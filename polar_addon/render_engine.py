"""The Polar render engine as Blender sees it (bl_idname "POLAR").

F12, ``bpy.ops.render.render()`` and ``blender -b … -E POLAR`` all land in ``render()``: export
the evaluated depsgraph, trace it with the standalone engine, and return the Stokes passes.
Errors become Blender errors (``report({'ERROR'})``), so a failed render never saves a silently
black image; cancelling (Esc, ``test_break``) stops between batches and keeps the finished samples.
"""

import dataclasses
import time
import traceback

import bpy
import numpy as np

from ..engine.polarisation.stokes import (angle_of_linear_polarisation, degree_of_circular_polarisation,
                                          degree_of_linear_polarisation, degree_of_polarisation)
from ..engine.render.renderer import Renderer, RenderRequest, msamples_per_second
from ..engine.scene.description import RenderSettings
from ..engine.errors import SceneError
from .export.camera import border_window
from .export.scene import export_scene
from .export.texture_bake import BAKE_CACHE
from ..engine.output.colormaps import diverging, hue_saturation, sequential
from ..engine.postprocess.filters import apply_filter, filter_row
from ..engine.postprocess.mosaic import mosaic as polarisation_mosaic
from ..engine.spectral.cie import LUMINANCE_WEIGHTS
from . import passes
from .compositor import DenoiseUnavailable, denoise_stokes, polariser_inputs
from .properties import (DEFAULT_PASSES, DENOISE_PASSES, HALVES_TO_ENGINE, NOISE_QUANTITY_TO_ENGINE,
                         PARALLEL_TO_ENGINE, PASS_NAMES, POLARISATION_TO_ENGINE, SAMPLER_TO_ENGINE)
from .ui_names import ui_message
from .viewport import ViewportSession, stop_all_sessions
from ..engine import kernels
from .kernel_cache import first_compile_pending, wait_for_precompile

#: Seconds between progressive updates of the image shown while rendering (at least).
DISPLAY_INTERVAL = 1.0
#: Live display updates may take at most this share of the render's wall time: each update runs on
#: the thread that feeds the render workers, so while it runs one worker waits (the next interval is
#: stretched to cost ÷ share when an update is slow, e.g. at 1080p).
LIVE_DISPLAY_SHARE = 0.02
#: Passes refreshed by live display updates (cheap copies); the derived and false-colour passes
#: (DoP, AoLP, Polariser, Vis…) are computed once, from the finished image.
LIVE_PASSES = ("S0", "S1", "S2", "S3")


class RenderControl:
    """What scripts, tests and farms ask of final renders besides Blender's UI: ``cancel`` stops them as
    Esc does (test_break() is always False headless); ``scheduler``: a Dask scheduler address to trace
    them on (examples/batch_render.py --scheduler; None: this machine)."""

    def __init__(self):
        self.cancel = False
        self.scheduler = None


#: The final renders' control (PolarRenderEngine.control).
CONTROL = RenderControl()


#: Render properties ▸ Spectral → the engine's RenderSettings.spectral
SPECTRAL_TO_ENGINE = {"SPECTRAL": "spectral", "MONO": "mono", "RGB": "rgb"}


def engine_settings(scene, preview=False) -> RenderSettings:
    """Engine RenderSettings from the scene's Polar settings (frame-dependent seed if asked), its Cycles
    Light Paths (cycles_light_paths) and Cycles' Light Tree switch."""
    p = scene.polar
    seed = p.seed + (scene.frame_current if p.use_animated_seed else 0)
    total, light_paths = cycles_light_paths(scene)
    c = getattr(scene, "cycles", None)
    # Cycles' Light Tree (Render Properties ▸ Sampling ▸ Lights), on by default: on → the engine's "on" (Cycles
    # chooses with its tree whatever the count of lights; with the tree's choice as Cycles' the real-asset suite's σ²
    # is lower than or equal to the per-point power selection's on every cell: docs/benchmarks/light-tree.md,
    # session 6), off → "off"
    light_tree = "on" if c is None or getattr(c, "use_light_tree", True) else "off"
    return RenderSettings(spp=p.preview_samples if preview else p.samples,
                          max_depth=min(p.max_bounces, total) + 2,
                          rr_depth=5, seed=seed, spectral=SPECTRAL_TO_ENGINE[p.spectral],
                          wavelength_nm=p.wavelength_nm, polarisation=POLARISATION_TO_ENGINE[p.polarisation],
                          batch_rays=p.batch_rays, threads=p.threads, parallel=PARALLEL_TO_ENGINE[p.parallel],
                          simplify="auto" if p.skip_clear_layers else "off",
                          sampler=SAMPLER_TO_ENGINE[p.sampler], halves=HALVES_TO_ENGINE[p.halves],
                          light_tree=light_tree, **light_paths)


#: Cycles' Light Paths properties (scene.cycles, the same names in Blender 4.5–5.3) → RenderSettings fields
CYCLES_LIGHT_PATHS = {"diffuse_bounces": "max_diffuse_bounces", "glossy_bounces": "max_glossy_bounces",
                      "transmission_bounces": "max_transmission_bounces",
                      "transparent_max_bounces": "max_transparent_bounces", "volume_bounces": "max_volume_bounces",
                      "sample_clamp_direct": "clamp_direct", "sample_clamp_indirect": "clamp_indirect",
                      "caustics_reflective": "caustics_reflective", "caustics_refractive": "caustics_refractive"}


def cycles_light_paths(scene) -> tuple[int, dict]:
    """(Cycles' Max Bounces ▸ Total, the RenderSettings light-path fields) from the scene's Cycles settings
    (Render Properties ▸ Light Paths, shown for Polar too), so a file renders with the trade-offs it was tuned
    for in Cycles; the total caps Polar's own Max Bounces.  Without the Cycles add-on: no limits."""
    c = getattr(scene, "cycles", None)
    if c is None:
        return 1 << 20, {}
    out = {field: getattr(c, name) for name, field in CYCLES_LIGHT_PATHS.items()}
    for field in ("max_diffuse_bounces", "max_glossy_bounces", "max_transmission_bounces", "max_transparent_bounces",
                  "max_volume_bounces"):
        out[field] = min(int(out[field]), 1024)
    for field in ("clamp_direct", "clamp_indirect"):
        out[field] = float(out[field])
    return int(c.max_bounces), out


def light_path_warnings(scene) -> list[str]:
    """What Polar does not apply of the scene's Cycles Light Paths (said once per render, never dropped silently)."""
    c = getattr(scene, "cycles", None)
    blur = float(getattr(c, "blur_glossy", 0.0)) if c is not None else 0.0
    if blur > 0:
        return [f"Filter Glossy {blur:g} (Light Paths ▸ Caustics) is not applied: glossy surfaces keep their "
                "roughness after diffuse bounces (set it to 0 to match Cycles)"]
    return []


def adaptive_settings(scene, preview=False):
    """engine AdaptiveSettings from the scene's Polar settings, or None (off, or a preview render)."""
    p = scene.polar
    if preview or p.samples < 2 or not (p.use_adaptive_sampling or p.time_limit > 0):
        return None                          # (the error needs an even and an odd sample)
    from ..engine.render.adaptive import AdaptiveSettings
    threshold = p.adaptive_threshold if p.use_adaptive_sampling else 0.0     # a time limit alone
    return AdaptiveSettings(threshold=threshold, quantity=NOISE_QUANTITY_TO_ENGINE[p.noise_quantity],
                            min_spp=max(2, min(p.adaptive_min_samples, p.samples)), time_limit=p.time_limit)


def adaptive_summary(out, adaptive) -> str:
    """' | adaptive: …' for the stats line: why sampling stopped, the achieved error, the samples."""
    from ..engine.render.adaptive import UNITS, film_noise
    film = out.film
    err, _, tile_err = film_noise(film, out.halves, adaptive.quantity)
    sampled = film.count > 0
    counts, finite = film.count[sampled], tile_err[sampled & np.isfinite(err)]
    achieved = (f"{adaptive.quantity} error p95 {np.percentile(finite, 95):.3g} {UNITS[adaptive.quantity]}"
                + (f" (threshold {adaptive.threshold:g})" if adaptive.threshold > 0
                   else f" (budget {adaptive.time_limit:g} s)")) if finite.size else ""
    return (f" | adaptive: {out.stats['stop_reason']}, {achieved}, spp {counts.min()}–{counts.max()} "
            f"(median {np.median(counts):.0f})") if counts.size else ""


def _display_colour(uint8_rgb):
    """Colour-map output (sRGB-encoded uint8) as linear values, so Blender's Standard view shows it as is."""
    v = uint8_rgb.astype(np.float64) / 255.0
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _blender_rows(img):
    """An (H, W[, C]) image as the flat float32 array a render pass's ``rect.foreach_set`` takes
    (Blender's rows start at the bottom of the image)."""
    return np.ascontiguousarray(img[::-1], dtype=np.float32).ravel()


def _combined(s0_rgb, alpha, dtype=np.float64):
    """The Combined pass (H, W, 4): S0 as RGB, alpha = coverage of the camera rays (1 if None)."""
    combined = np.ones(s0_rgb.shape[:2] + (4,), dtype)
    combined[..., :3] = s0_rgb
    if alpha is not None:
        combined[..., 3] = alpha
    return combined


def mosaic_inputs(settings):
    """(2×2 layout in degrees, extinction) of the scene's Polarisation Mosaic pass."""
    a = tuple(settings.mosaic_angles)
    return ((a[0], a[1]), (a[2], a[3])), settings.mosaic_extinction


def pass_images(stokes_rgb, polariser=None, wanted=None, alpha=None, mosaic=None):
    """{pass name: (H, W, C)} for the Polar passes from a Stokes image (4, H, W, 3).

    ``polariser`` = (angle, extinction, retarder angle, retardance) for the Polariser pass;
    ``wanted`` limits the (costlier) false-colour passes; ``alpha`` (H, W) is the Combined pass's
    alpha (coverage of the camera rays; 1 if None); ``mosaic`` = (layout, extinction, (row, column)
    of the image's top-left pixel in the frame) for the Polarisation Mosaic pass.
    """
    wanted = set(PASS_NAMES) if wanted is None else set(wanted)
    y = np.einsum("shwc,c->shw", stokes_rgb, LUMINANCE_WEIGHTS)
    out = {f"S{i}": stokes_rgb[i] for i in range(4)}
    out["DoP"] = degree_of_polarisation(y)[..., None]
    out["DoLP"] = degree_of_linear_polarisation(y)[..., None]
    out["AoLP"] = angle_of_linear_polarisation(y)[..., None]
    out["DoCP"] = degree_of_circular_polarisation(y)[..., None]
    out["Combined"] = _combined(stokes_rgb[0], alpha)
    if "Polariser" in wanted and polariser is not None:
        angle, extinction, r_angle, retardance = polariser
        out["Polariser"] = apply_filter(stokes_rgb, filter_row("retarder", angle, extinction, r_angle, retardance))
    if "Polarisation Mosaic" in wanted and mosaic is not None:
        layout, extinction, origin = mosaic
        out["Polarisation Mosaic"] = polarisation_mosaic(stokes_rgb, layout, extinction, origin)
    lit = y[0] > 0
    ratio = lambda k: np.where(lit, y[k] / np.where(lit, y[0], 1.0), np.nan)  # noqa: E731
    if "VisDoP" in wanted:
        out["VisDoP"] = _display_colour(sequential(np.where(lit, out["DoP"][..., 0], np.nan)))
    for k in (1, 2, 3):
        if f"VisS{k}" in wanted:
            out[f"VisS{k}"] = _display_colour(diverging(ratio(k)))
    if "VisAoLP" in wanted:
        out["VisAoLP"] = _display_colour(hue_saturation(np.where(lit, out["AoLP"][..., 0], np.nan),
                                                        np.where(lit, out["DoLP"][..., 0], np.nan)))
    return out


def _live_alpha(renderer):
    """Alpha of the render in progress (None while every sample is opaque)."""
    film = renderer.live_film
    return film.alpha() if film is not None and film.has_alpha else None


class PolarRenderEngine(bpy.types.RenderEngine):
    bl_idname = "POLAR"
    bl_label = "Polar"
    bl_use_preview = True
    bl_use_postprocess = True
    bl_use_shading_nodes_custom = False
    bl_use_eevee_viewport = True
    #: requests from outside the UI (cancel, a Dask scheduler)
    control = CONTROL

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.viewport = None

    # ------------------------------------------------------------------ passes

    def update_render_passes(self, scene=None, renderlayer=None):
        self.register_pass(scene, renderlayer, "Combined", 4, "RGBA", "COLOR")
        settings = getattr(renderlayer, "polar", None)
        enabled = settings.enabled_passes() if settings is not None else list(DEFAULT_PASSES)
        p = getattr(scene, "polar", None) if scene is not None else None
        adaptive = p is not None and (p.use_adaptive_sampling or p.time_limit > 0)     # a time limit alone: budget
        for name in enabled:
            if name == "Noise" and not adaptive:
                continue
            if name == "Denoising Normal":
                self.register_pass(scene, renderlayer, name, 3, "XYZ", "VECTOR")
                continue
            if name.startswith("S") or name.startswith("Vis") or name in ("Polariser", "Polarisation Mosaic",
                                                                          "Denoising Albedo"):
                self.register_pass(scene, renderlayer, name, 3, "RGB", "COLOR")
            else:
                self.register_pass(scene, renderlayer, name, 1, "X", "VALUE")
        if renderlayer is not None:     # Cycles' data passes and Cryptomatte the view layer enables
            passes.register_data_passes(self, scene, renderlayer)

    # ------------------------------------------------------------------ final render

    def render(self, depsgraph):
        try:
            self._render(depsgraph)
        except SceneError as e:
            self.report({"ERROR"}, f"Polar: {ui_message(e)}")   # named as in Blender's UI
        except Exception as e:  # noqa: BLE001 — never a silently black image
            traceback.print_exc()
            self.report({"ERROR"}, f"Polar render failed: {type(e).__name__}: {e}")

    def _render(self, depsgraph):
        # The kernels compiling in the background since the extension was enabled: wait (Esc stops).
        waited = wait_for_precompile(lambda text: self.update_stats("", text),
                                     lambda: self.test_break() or self.control.cancel)
        if waited == "cancelled":
            self.report({"INFO"}, "Polar: render cancelled while the kernels were compiling")
            return
        scene = depsgraph.scene
        W, H = self.resolution_x, self.resolution_y
        settings = engine_settings(scene, preview=self.is_preview)
        camera_object = self.camera_override or scene.camera
        t0 = time.perf_counter()
        self.update_stats("", "Polar | exporting scene")
        bakes = BAKE_CACHE.mark()
        data_request = None if self.is_preview else passes.data_pass_request(depsgraph.view_layer, scene)
        with passes.exporting(data_request):
            engine_scene, warnings = export_scene(depsgraph, camera_object, W, H, settings)
        data_request = passes.add_motion(self, depsgraph, camera_object, W, H, engine_scene, data_request)
        bake_note = BAKE_CACHE.summary(since=bakes)
        for w in dict.fromkeys([*warnings, *light_path_warnings(scene)]):
            self.report({"WARNING"}, f"Polar: {w}")
        self.update_stats("", "Polar | building BVH")
        renderer = Renderer(engine_scene)
        window = None if self.is_preview else border_window(scene.render, W, H)
        layer_name = depsgraph.view_layer.name
        result = self.begin_result(0, 0, W, H, layer=layer_name)
        live = {"last": time.perf_counter(), "interval": DISPLAY_INTERVAL}
        enabled = set(depsgraph.view_layer.polar.enabled_passes()) if hasattr(depsgraph.view_layer, "polar") \
            else set(DEFAULT_PASSES)
        polariser = polariser_inputs(scene.polar)
        self._mosaic = mosaic_inputs(scene.polar)
        if first_compile_pending(kernels):
            self.update_stats("", "Polar | compiling kernels (first render only)")
        denoise = bool(getattr(scene.polar, "use_denoising", False)) and not self.is_preview
        if enabled & set(DENOISE_PASSES) or denoise:
            settings = dataclasses.replace(settings, denoise_data=True)

        def progress(fraction, stats):
            if stats.get("message"):            # before the first unit (engine.render.processes)
                self.update_stats("", f"Polar | {stats['message']}")
                return
            self.update_progress(fraction)
            self.update_stats("", f"Polar | {stats['transport']} | {100 * fraction:.0f}% | "
                                  f"{msamples_per_second(stats):.2f} Msamples/s")
            now = time.perf_counter()
            if now - live["last"] > live["interval"]:
                self._live_display(result, renderer, window, enabled)
                live["last"] = time.perf_counter()
                live["interval"] = max(DISPLAY_INTERVAL, (live["last"] - now) / LIVE_DISPLAY_SHARE)

        def should_stop():
            return self.test_break() or self.control.cancel

        adaptive = adaptive_settings(scene, self.is_preview)
        scheduler = None if self.is_preview else self.control.scheduler
        if scheduler and settings.denoise_data:     # not collected from Dask workers yet
            settings = dataclasses.replace(settings, denoise_data=False)
            self.report({"WARNING"}, "Polar: the Denoising Albedo / Normal passes are not rendered on a "
                                     "Dask cluster yet: they stay empty"
                                     + (" and Denoise runs without them" if denoise else ""))
        out = renderer.render(RenderRequest(settings, window, adaptive, scheduler=scheduler, progress=progress,
                                            should_stop=should_stop))
        stokes_rgb, denoise_note = out.stokes(), ""
        if denoise and stokes_rgb is not None:
            stokes_rgb, denoise_note = self._denoised(stokes_rgb, out.film, window, scene)
        self._write_passes(result, stokes_rgb, window, enabled, polariser,
                           out.film.alpha() if out.film.has_alpha else None)
        if out.halves is not None and "Noise" in enabled:
            self._write_noise(result, out, adaptive, window)
        if getattr(out.film, "has_denoise_data", False):
            self._write_denoise_data(result, out.film, window, enabled)
        # the passes trace the render's own camera rays: its halves as resolved
        settings = dataclasses.replace(settings, halves=out.settings.halves)
        if data_request is not None and not out.cancelled:
            self.update_stats("", "Polar | data passes")
            passes.write_data_passes(self, result, renderer, data_request, settings, window)
        light_keys = () if self.is_preview or out.cancelled else passes.light_pass_keys(depsgraph.view_layer)
        if light_keys:
            self.update_stats("", "Polar | light passes")
            light = passes.write_light_passes(self, result, renderer, light_keys, settings, window)
            for w in light.warnings:
                self.report({"WARNING"}, f"Polar: {w}")
        self.end_result(result)
        message = self._stats_message(out, adaptive, time.perf_counter() - t0, bake_note) + denoise_note
        self.update_stats("", message)
        self.report({"INFO"}, message)

    @staticmethod
    def _stats_message(out, adaptive, wall_seconds: float, bake_note: str) -> str:
        """The final render's stats line (engine.render.renderer.stats_line) with Blender's notes."""
        stats = out.stats
        message = f"Polar | {out.stats_line(' | ')} | export + BVH {wall_seconds - stats['seconds']:.1f} s"
        if bake_note:
            message += f" | {bake_note}"
        if stats.get("kernels") == "numpy":
            message += " | NumPy kernels (numba not loaded: slower)"
        if out.cancelled:
            message += " | cancelled: partial image"
        if stats.get("error"):          # a Dask cluster that failed mid-render: the finished part is shown
            message += f" | {stats['error']}"
        if out.halves is not None:
            message += adaptive_summary(out, adaptive)
        return message

    def _denoised(self, stokes_rgb, film, window, scene):
        """(the Stokes image with the rendered window denoised as the Polar Denoise group denoises the passes,
        the stats note) — the image unchanged and a warning where Blender's OpenImageDenoise cannot be used."""
        t0 = time.perf_counter()
        x0, y0, x1, y1 = window if window is not None else (0, 0, stokes_rgb.shape[2], stokes_rgb.shape[1])
        guides = film.denoise_data() if getattr(film, "has_denoise_data", False) else (None, None)
        # the passes as written (float32, Blender's rows: bottom first), as the compositor would read them
        crop = [None if g is None else np.asarray(g[y0:y1, x0:x1][::-1], np.float32) for g in guides]
        quality = getattr(scene.render, "compositor_denoise_final_quality", "HIGH")
        try:
            denoised = denoise_stokes(np.asarray(stokes_rgb[:, y0:y1, x0:x1][:, ::-1], np.float32), *crop,
                                      quality=quality, clamp_dop=scene.polar.denoising_clamp_dop)
        except DenoiseUnavailable as e:
            self.report({"WARNING"}, f"Polar: Denoise: {e}: the render is not denoised")
            return stokes_rgb, " | not denoised"
        out = np.array(stokes_rgb, np.float64)
        out[:, y0:y1, x0:x1] = denoised[:, ::-1]
        return out, f" | denoised (OpenImageDenoise, {quality.lower()}, {time.perf_counter() - t0:.1f} s)"

    def _write_noise(self, result, out, adaptive, window):
        """The Noise pass: per-pixel standard error of the adaptive quantity (−1: no estimate)."""
        from ..engine.render.adaptive import film_noise
        film = out.film
        err = film_noise(film, out.halves, adaptive.quantity)[0]
        noise = np.where(np.isfinite(err), err, -1.0).reshape(film.height, film.width)
        if window is not None:
            x0, y0, x1, y1 = window
            noise = noise[y0:y1, x0:x1]
        target = result.layers[0].passes.get("Noise")
        if target is not None:
            target.rect.foreach_set(_blender_rows(noise))

    def _write_denoise_data(self, result, film, window, enabled):
        """Denoising Albedo / Normal passes from the film's guides (Cycles' denoising data)."""
        albedo, normal = film.denoise_data()
        passes = result.layers[0].passes
        for name, img in (("Denoising Albedo", albedo), ("Denoising Normal", normal)):
            target = passes.get(name) if name in enabled else None
            if target is None:
                continue
            if window is not None:
                x0, y0, x1, y1 = window
                img = img[y0:y1, x0:x1]
            target.rect.foreach_set(_blender_rows(img))

    def _live_display(self, result, renderer, window, enabled):
        """Progressive display: the Combined and Stokes passes of the samples so far (no derived passes)."""
        stokes_rgb = renderer.last_film_mean()
        if stokes_rgb is None:
            return
        alpha = _live_alpha(renderer)
        if window is not None:
            x0, y0, x1, y1 = window
            stokes_rgb = stokes_rgb[:, y0:y1, x0:x1]
            alpha = None if alpha is None else alpha[y0:y1, x0:x1]
        passes = result.layers[0].passes
        for name in ("Combined",) + LIVE_PASSES:
            target = passes.get(name) if name == "Combined" or name in enabled else None
            if target is not None:
                target.rect.foreach_set(_blender_rows(stokes_rgb[int(name[1])] if name != "Combined"
                                                      else _combined(stokes_rgb[0], alpha, np.float32)))
        self.update_result(result)

    def _write_passes(self, result, stokes_rgb, window, enabled, polariser, alpha=None):
        if stokes_rgb is None:
            return
        origin = (0, 0)
        if window is not None:
            x0, y0, x1, y1 = window
            stokes_rgb = stokes_rgb[:, y0:y1, x0:x1]
            alpha = None if alpha is None else alpha[y0:y1, x0:x1]
            origin = (y0, x0)
        layout, extinction = getattr(self, "_mosaic", (None, 0.0))
        images = pass_images(stokes_rgb, polariser, enabled, alpha,
                             mosaic=(layout, extinction, origin) if layout is not None else None)
        passes = result.layers[0].passes
        for name, img in images.items():
            if name != "Combined" and name not in enabled:
                continue
            target = passes.get(name)
            if target is None:
                continue
            target.rect.foreach_set(_blender_rows(img))

    # ------------------------------------------------------------------ viewport

    def view_update(self, context, depsgraph):
        # Export only what the depsgraph's updates invalidate; tracing runs on the session's thread.
        if self.viewport is None:
            self.viewport = ViewportSession(engine_settings)
        self.viewport.sync(depsgraph, context)
        self.tag_redraw()

    def view_draw(self, context, depsgraph):
        # Draw the latest accumulated image; never traces (see polar_addon.viewport).
        if self.viewport is None:
            return
        if self.viewport.draw(self, context):
            self.tag_redraw()

    def __del__(self):
        # Leaving rendered shading (or Esc) frees the engine: stop the viewport's render thread.
        # (BlendLuxCore does the same; the Blender struct may already be gone, the Python attribute is not.)
        try:
            viewport = getattr(self, "viewport", None)
        except ReferenceError:
            return
        if viewport is not None:
            viewport.stop()


# Panels of other engines that should also show for Polar (as Hydra Storm does).
COMPAT_PANELS = ("EEVEE_MATERIAL_PT_surface", "EEVEE_MATERIAL_PT_volume", "EEVEE_MATERIAL_PT_settings",
                 "EEVEE_MATERIAL_PT_context_material", "MATERIAL_PT_preview", "EEVEE_WORLD_PT_surface",
                 "EEVEE_WORLD_PT_mist")          # the Mist pass's ramp (polar_addon.passes)


def _compat_panels():
    for panel in bpy.types.Panel.__subclasses__():
        engines = getattr(panel, "COMPAT_ENGINES", None)
        if engines is not None and ("BLENDER_RENDER" in engines or panel.__name__ in COMPAT_PANELS):
            yield panel


def register():
    from . import ui_scene          # panels for the Cycles settings the exporter reads
    if bpy.app.debug:   # blender --debug: also show the kernel libraries' warnings (or POLAR_LIBRARY_WARNINGS=1)
        from ..engine.kernels import library_warnings
        library_warnings(True)
    bpy.utils.register_class(PolarRenderEngine)
    for panel in _compat_panels():
        panel.COMPAT_ENGINES.add("POLAR")
    ui_scene.register()


def unregister():
    stop_all_sessions()
    from . import ui_scene
    ui_scene.unregister()
    for panel in _compat_panels():
        panel.COMPAT_ENGINES.discard("POLAR")
    bpy.utils.unregister_class(PolarRenderEngine)
