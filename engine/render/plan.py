"""What a render does, resolved once: ``RenderPlan`` (from a scene and settings) and ``RenderRequest``.

The plan is the one place where the exact simplifications of the materials and the transport are
resolved (engine.render.effects), where the spectral reduction is decided and described, and where the
image (or window) is cut into work units; the driver (engine.render.driver), the tracer, resume and the
Dask workers ask the plan.  ``RenderRequest`` is what a caller asks of ``Renderer.render``: the settings,
the window, adaptive sampling, a resumed film, the executor (a Dask scheduler) and the callbacks.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from ..materials.base import BSDF, BSDFFlags
from ..scene.description import RenderSettings
from .effects import effective_materials, media_needs, resolve_transport, source_needs
from .media import media_flags, spectral_media
from ..scene.description import resolve_halves
from .light_paths import describe as describe_light_paths

#: (x0, y0, x1, y1): a pixel rectangle, row 0 at the top, x1 and y1 exclusive.
Window = tuple[int, int, int, int]

#: Fewer work units per worker than this (few passes on a small image): work_units cuts the rows into bands.
UNITS_PER_WORKER = 4


@dataclass(frozen=True)
class RenderRequest:
    """One render as a caller asks for it (``Renderer.render``).

    ``settings``: None renders the scene's; ``window``: only that pixel rectangle (other pixels keep 0
    samples); ``adaptive`` (engine.render.adaptive.AdaptiveSettings): sample adaptively up to
    ``settings.spp``; ``resume``: a Film of finished samples (sample passes a pixel has are not traced
    again), ``resume_halves``: its adaptive HalfBuffers; ``scheduler``: a Dask scheduler address
    ("tcp://host:8786") or a ``distributed.Client`` to trace on (None: local threads).
    ``progress(done_fraction, stats)`` is called after every work unit; ``should_stop()`` is polled
    between units and ends the render early; ``clock()`` gives seconds for the time limit;
    ``on_first_pass(film, halves, seconds, samples)``: called once every pixel of an adaptive render has
    ``min_spp`` samples; ``unit_times``: a list receiving (pixels, paths, seconds, cost) of every unit
    of an adaptive render's first pass (engine.render.estimate).
    """

    settings: RenderSettings | None = None
    window: Window | None = None
    adaptive: object = None
    resume: object = None
    resume_halves: object = None
    scheduler: object = None
    progress: Callable[[float, dict], None] | None = None
    should_stop: Callable[[], bool] | None = None
    clock: Callable[[], float] = time.perf_counter
    on_first_pass: Callable | None = None
    unit_times: list | None = None

    @classmethod
    def of(cls, request: RenderRequest | RenderSettings | None) -> RenderRequest:
        """``request`` as a RenderRequest (settings alone, or None: the scene's settings)."""
        return request if isinstance(request, RenderRequest) else cls(settings=request)


def spectral_reduction(settings: RenderSettings, materials: Sequence[BSDF], used: Sequence[int],
                       extra: BSDFFlags = BSDFFlags.NONE) -> tuple[bool, bool]:
    """(uniform, rgb_mode) for ``settings`` and the ``used`` materials (indices into ``materials``) and
    ``extra`` flags (the participating media's phase functions: engine.render.media.media_flags).

    uniform: every wavelength of a path has the same Mueller product (no used material depends on λ),
    so one is carried; rgb_mode: paths carry RGB (the "rgb" transport, or, with ``reduce_spectral``
    "auto", each light's spectrum integrated exactly against the observer: the same expectation)."""
    channels = settings.spectral == "rgb"
    independent = not (any(m.flags.has(BSDFFlags.WAVELENGTH_DEPENDENT) for m in {materials[i] for i in used})
                       or extra.has(BSDFFlags.WAVELENGTH_DEPENDENT))
    reduce = settings.reduce_spectral
    uniform = reduce in ("auto", "exact", True) and independent and not channels
    rgb_mode = channels or (reduce in ("auto", True) and independent and settings.spectral != "mono")
    return uniform, rgb_mode


def spectral_description(settings: RenderSettings, materials: Sequence[BSDF], used: Sequence[int],
                         extra: BSDFFlags = BSDFFlags.NONE, needs: Sequence[str] = ()) -> str:
    """How the paths carry the spectrum, as the render's stats report it; ``needs``: the names of what depends
    on λ (materials, media), reported when they keep the paths spectral."""
    uniform, rgb_mode = spectral_reduction(settings, materials, used, extra)
    if settings.spectral == "rgb":
        return "RGB channels (Cycles' colour arithmetic)"
    if rgb_mode:
        return "RGB with exactly integrated light spectra (nothing depends on λ)"
    if uniform:
        return "spectral, one Mueller product per path (nothing depends on λ)"
    if settings.spectral == "spectral" and settings.reduce_spectral in ("auto", "exact", True) and needs:
        return f"spectral ({', '.join(repr(n) for n in needs)} depend{'s' if len(needs) == 1 else ''} on λ)"
    return settings.spectral


def wavelength_needs(compiled, materials: Sequence[BSDF], world) -> list[str]:
    """The names of the used materials (by the compiled scene's index) and media (engine.render.media.spectral_media)
    whose values depend on λ: what keeps a render's paths spectral."""
    names = [compiled.material_names[i] for i in sorted(set(compiled.used_materials))
             if materials[i].flags.has(BSDFFlags.WAVELENGTH_DEPENDENT)]
    return names + [n for n in spectral_media(compiled, world) if n not in names]


def rendered_materials(compiled, simplify: str = "auto", materials=None) -> tuple[list[BSDF], list[str]]:
    """(the materials as rendered, by the compiled scene's material index; the simplifications' reasons).

    ``materials``: {name: BSDF} (default: the compiled scene's own; the viewport swaps in new ones)."""
    if materials is None:
        materials = dict(zip(compiled.material_names, compiled.materials))
    out, simplified = effective_materials(materials, compiled.used_material_names, simplify)
    return [out[name] for name in compiled.material_names], simplified


def check_window(window, width: int, height: int) -> Window | None:
    """``window`` as four ints inside the image (ValueError if it is not, or is empty), or None."""
    if window is None:
        return None
    x0, y0, x1, y1 = (int(v) for v in window)
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise ValueError(f"window {window} must lie inside the {width}×{height} image and be non-empty")
    return x0, y0, x1, y1


@dataclass(frozen=True)
class RenderPlan:
    """A render resolved from a scene and settings.

    ``settings``: as rendered (``polarisation`` and ``halves`` resolved; a copy, never changed); ``transport_reason``:
    why that transport; ``materials``: the compiled scene's materials by index with the exact
    simplifications applied, ``simplified``: their reasons; ``spectral``: how paths carry the spectrum
    (reported); ``width`` × ``height`` pixels, ``window`` (or None: all); ``workers``: threads (or Dask
    workers) the work units are cut for."""

    settings: RenderSettings
    transport_reason: str
    materials: tuple
    simplified: tuple
    spectral: str
    width: int
    height: int
    window: Window | None = None
    workers: int = 1
    #: why that many local threads, where chosen automatically (reported; '' otherwise)
    threads_reason: str = ""

    @classmethod
    def resolve(cls, scene, compiled, settings: RenderSettings | None = None, window=None,
                workers: int | None = None) -> RenderPlan:
        """The plan of rendering ``scene`` (compiled as ``compiled``) with ``settings`` (None: the
        scene's); ``workers`` None: ``settings.threads``, or one per CPU core; ``halves`` resolved
        (engine.scene.description.resolve_halves)."""
        requested = resolve_halves(settings or scene.settings)
        materials, simplified = rendered_materials(compiled, requested.simplify, scene.materials)
        polarisation, reason = resolve_transport(requested.polarisation, dict(zip(compiled.material_names, materials)),
                                                 compiled.used_material_names, sources=source_needs(scene),
                                                 media=media_needs(scene, compiled.used_material_names),
                                                 world=getattr(scene, "medium", None))
        st = dataclasses.replace(requested, polarisation=polarisation)
        world = getattr(scene, "medium", None)
        extra = media_flags(compiled, world)
        if spectral_reduction(st, materials, compiled.used_materials, extra) \
                != spectral_reduction(st, materials, compiled.used_materials):
            # a medium's coefficients need λ (the tracers see only the materials and phase functions): no reduction
            st = dataclasses.replace(st, reduce_spectral="off")
        W, H = scene.camera.width, scene.camera.height
        if workers is None:
            workers = st.threads if st.threads > 0 else (os.cpu_count() or 1)
        return cls(st, reason, tuple(materials), tuple(simplified),
                   spectral_description(dataclasses.replace(st, reduce_spectral=requested.reduce_spectral),
                                        materials, compiled.used_materials, extra,
                                        wavelength_needs(compiled, materials, world)), W, H,
                   check_window(window, W, H), int(workers))

    @property
    def stratified(self) -> bool:
        """A low-discrepancy sampler (its numbers depend on the pixel and sample)."""
        return self.settings.stratified

    @property
    def split_halves(self) -> bool:
        """A low-discrepancy sampler with independently scrambled even and odd samples: the film then keeps
        even/odd half sums (RenderSettings.split_halves)."""
        return self.settings.split_halves

    def units(self, first_pass: int = 0) -> list[tuple[int, int, int, int]]:
        """The uniform render's work units (row0, row1, pass0, pass1) from sample pass ``first_pass`` on."""
        st = self.settings
        return list(work_units(self.width, self.height, st.spp, st.batch_rays, first_pass, self.window, self.workers))

    def pixels(self) -> np.ndarray:
        """Flat indices of the window's pixels (row by row)."""
        x0, y0, x1, y1 = self.window or (0, 0, self.width, self.height)
        ys, xs = np.mgrid[y0:y1, x0:x1]
        return (ys * self.width + xs).ravel().astype(np.int64)

    def stats(self) -> dict:
        """The render's statistics before any sample: counters at 0 and what the plan decided."""
        return {"rays": 0, "shadow_rays": 0, "nonfinite": 0, "samples": 0, "transport": self.settings.polarisation,
                "transport_reason": self.transport_reason, "spectral": self.spectral,
                "simplified": list(self.simplified), "light_paths": describe_light_paths(self.settings),
                **({"threads": self.workers, "threads_reason": self.threads_reason} if self.threads_reason else {})}


def work_units(width: int, height: int, spp: int, batch_rays: int, first_pass: int = 0,
               window: Window | None = None, workers: int = 1) -> Iterator[tuple[int, int, int, int]]:
    """Yield (row0, row1, pass0, pass1) covering the window's rows × passes [first_pass, spp).

    ``window`` restricts the rows here and the columns in ``unit_pixels``.  The passes are grouped by the image's
    size and ``batch_rays`` alone, never by ``workers``: a pixel's sums are added group by group, so the grouping
    fixes the image's bits.  Groups are of equal size (16 passes that need two batches: 8 + 8, not 14 + 2, whose
    small batch would pay a whole batch's per-bounce calls for a few paths), and an image whose rows fit one batch
    but whose passes do not is grouped for bands of half its rows (96 × 96 at 16 spp: two bands of all 16 passes,
    one batch for each of two workers, instead of two batches each).  When that gives fewer than
    ``UNITS_PER_WORKER`` units per worker and fewer bands of rows than ``workers``, the rows are cut into
    ``workers`` bands, so that every worker gets a unit of each group; bands are (nearly) equal.  Bands change no
    pixel's additions: the image is the same for any ``workers`` (and on a Dask cluster).
    """
    x0, y0, x1, y1 = window or (0, 0, width, height)
    cols = max(x1 - x0, 1)
    rows = y1 - y0
    todo = max(spp - first_pass, 0)
    rows_per_unit = max(1, min(rows, batch_rays // cols))
    if rows_per_unit == rows > 1 and rows * cols * todo > batch_rays:
        rows_per_unit = -(-rows // 2)           # the passes do not fit one batch: group them for half-height bands
    most = max(1, batch_rays // (rows_per_unit * cols))
    groups = -(-todo // most)
    bands = -(-rows // rows_per_unit)
    if bands < workers and groups * bands < UNITS_PER_WORKER * workers:
        bands = min(workers, rows)      # one band per worker
    cuts = [y0 + i * rows // bands for i in range(bands + 1)]       # (nearly) equal bands
    for g in range(groups):                         # (nearly) equal groups, each within ``most``
        p0, p1 = first_pass + g * todo // groups, first_pass + (g + 1) * todo // groups
        for r0, r1 in zip(cuts[:-1], cuts[1:]):
            yield r0, r1, p0, p1


def unit_pixels(width: int, r0: int, r1: int, window: Window | None = None) -> np.ndarray:
    """Flat pixel indices of rows [r0, r1) within the window's columns."""
    x0, _, x1, _ = window or (0, 0, width, 0)
    rows = np.arange(r0, r1, dtype=np.int64)
    return (rows[:, None] * width + np.arange(x0, x1, dtype=np.int64)[None, :]).ravel()
