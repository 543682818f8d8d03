"""The live paths of one batch as a structure of arrays (paths on the last axis).

The wavefront integrator (engine.render.integrator) keeps everything a path carries from one
bounce to the next in one ``PathState`` and drops finished paths with one ``compress(mask)``
(as pbrt-v4's wavefront queues or Mitsuba 3's ``path.cpp`` loop state), instead of passing
positional tuples between the stages; ``keep(idx, ...)`` does the same for a compiled step that
already restricted some fields itself (the end of a bounce: engine.kernels.transport.next_segments).
Frames and units as in the integrator's docstring:

- ``path`` (n,) int64: index of each path in the batch (where its radiance is accumulated);
- ``T`` (P, P, Lm, n): Mueller product seen from the camera, in frame ``x_T`` (3, n) ⟂ ``d`` (kept
  as ``T_store`` and a column map ``T_col``: dropping paths does not copy it);
- ``o``, ``d`` (3, n): the segment to trace next (origin, unit direction), ``t_max`` (n,) its
  length or None (unbounded);
- ``eta_sq`` (n,): product of the refraction radiance scales η² (undone in Russian roulette);
- ``prev_delta`` (n,) bool, ``prev_pdf`` (n,) 1/sr: how the segment was sampled (MIS of emission);
- ``p_prev``, ``n_prev`` (3, n) or None: where the segment starts and that vertex's side normal
  (light selection and analytic lamps' pdfs; None where no light needs them);
- ``sampler``: the paths' random-number keys (engine.render.sampler.PathSampler);
- ``lk``, ``lk_m``: wavelength lookups of the paths (lights) and of the materials (one wavelength
  where nothing depends on λ; the same object as ``lk`` otherwise);
- ``media`` (MAX_MEDIA, n) int32 or None: the absorbing volumes each path is inside (engine.render.media;
  None in scenes without any), ``tau`` (L, n) or None (all 1): the Beer–Lambert transmittance of the
  path so far per wavelength (RGB channel in RGB mode), a scalar kept apart from T; ``gap`` (n,) or
  None (0): how far along ``d`` the segment's origin ``o`` lies from the vertex it leaves (the offset
  off the surface), so that distances inside volumes are measured from the vertex; ``crossings``:
  the pass-through surfaces the current segments cross (recorded by the intersection, consumed by
  the emission stage; not a per-path array).

Fields a stage has consumed are set to None, so that ``compress`` does not carry them.
"""

from __future__ import annotations

import numpy as np

from ..kernels.transport import keep_columns
from ..spectral import WavelengthLookup
from .sampler import PathSampler

#: Per-path array fields, compressed together (None fields are skipped).
ARRAY_FIELDS = ("path", "T", "x_T", "o", "d", "t_max", "eta_sq", "prev_delta", "prev_pdf", "p_prev", "n_prev",
                "tau", "media", "gap")


class PathState:
    """Everything a batch's live paths carry between bounces; see the module docstring.

    The throughputs are not copied when paths are dropped: they stay in ``T_store`` (P, P, Lm, m) and
    ``T_col`` (n,) int64 says which column holds each live path's (None: column j for path j).  A
    spectral full-Stokes T is 512 bytes a path, and copying the survivors' columns at every bounce
    (twice: after the hits, after the roulette) was two of the five passes over it per vertex; the
    stages read T through the column map instead (``T_columns``), and the next scatter writes a new,
    dense T.  The camera paths share one identity column.  ``T`` gives the live paths' throughputs as one dense
    array (gathered on first use, if needed).
    """

    def __init__(self, path: np.ndarray, T: np.ndarray, x_T: np.ndarray, o: np.ndarray | None, d: np.ndarray,
                 t_max: np.ndarray | None, eta_sq: np.ndarray, prev_delta: np.ndarray | None,
                 prev_pdf: np.ndarray | None, p_prev: np.ndarray | None, n_prev: np.ndarray | None,
                 sampler: PathSampler, lk: WavelengthLookup, lk_m: WavelengthLookup, T_col: np.ndarray | None = None,
                 tau: np.ndarray | None = None, media: np.ndarray | None = None, gap: np.ndarray | None = None):
        self.path, self.x_T, self.o, self.d, self.t_max, self.eta_sq = path, x_T, o, d, t_max, eta_sq
        self.prev_delta, self.prev_pdf, self.p_prev, self.n_prev = prev_delta, prev_pdf, p_prev, n_prev
        self.sampler, self.lk, self.lk_m = sampler, lk, lk_m
        self.T_store, self.T_col = T, T_col
        self.tau, self.media, self.gap = tau, media, gap
        self.crossings: list | None = None
        #: the bounce the paths are at (set by the participating-media tracer, which keys its numbers by it)
        self.bounce = 0

    @property
    def T(self) -> np.ndarray:
        """The live paths' throughputs (P, P, Lm, n), dense (gathered from ``T_store`` once if needed)."""
        if self.T_col is not None:
            self.T_store, self.T_col = keep_columns(self.T_store, self.T_col), None
        return self.T_store

    @T.setter
    def T(self, value: np.ndarray) -> None:
        self.T_store, self.T_col = value, None

    def T_columns(self, rows: np.ndarray | slice | None = None) -> np.ndarray | None:
        """The columns of ``T_store`` holding the throughputs of the paths ``rows`` (int64 indices,
        None: all live paths); None where they are the columns ``rows`` themselves."""
        if self.T_col is None:
            return None
        if rows is None or (isinstance(rows, slice) and rows == slice(None)):
            return self.T_col
        return self.T_col[rows]

    @property
    def n(self) -> int:
        """Number of live paths."""
        return self.path.shape[0]

    def compress(self, mask: np.ndarray, *extra: np.ndarray | None) -> tuple[np.ndarray | None, ...]:
        """Keep the paths where ``mask`` (n,) is True, in every field; returns ``extra`` per-path
        arrays (paths on the last axis, e.g. the hits of this bounce) restricted the same way.

        The kept indices are found once and every array is copied by one compiled gather
        (engine.kernels.transport.keep_columns: np.compress on the last axis walks a (4, 4, L, n)
        throughput element by element), except T, whose column map is restricted instead; a full
        mask keeps the arrays themselves (no copy).
        """
        if mask.all():
            return extra
        idx = np.flatnonzero(mask)
        self.keep(idx, keep_columns(self.sampler.keys, idx))
        return tuple(None if a is None else keep_columns(a, idx) for a in extra)

    def keep(self, idx: np.ndarray, keys: np.ndarray, **kept: np.ndarray | None) -> None:
        """Keep the paths ``idx`` (sorted int64 indices), given the fields ``kept`` (by name) and the
        sampler's ``keys`` already restricted to them (a compiled step that made them in one pass, e.g.
        engine.kernels.transport.next_segments); every other field is gathered here as by ``compress``
        (T by its column map).  ``T`` may come with ``T_col`` (its columns of the kept paths; None:
        dense).  Where idx keeps every path, the given arrays are set and nothing is gathered."""
        every = idx.shape[0] == self.n
        for name in ARRAY_FIELDS:
            if name == "T":
                if "T" in kept:
                    self.T_store, self.T_col = kept["T"], kept.get("T_col")
                elif not every:
                    self.T_col = idx if self.T_col is None else keep_columns(self.T_col, idx)
            elif name in kept:
                setattr(self, name, kept[name])
            elif not every and getattr(self, name) is not None:
                setattr(self, name, keep_columns(getattr(self, name), idx))
        self.sampler.keys = keys
        if not every:
            new = self.lk.take(idx)
            self.lk_m = new if self.lk_m is self.lk else self.lk_m.take(idx)
            self.lk = new
