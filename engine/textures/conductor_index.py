"""A metal's complex index from a textured colour, per point and per wavelength.

The textured twin of engine.spectral.gulbrandsen.GulbrandsenIndex: the reflectivity (and edge tint)
are textured reflectance spectra (or constant spectra), upsampled per point as every textured colour
is, and Gulbrandsen's map is applied to their values at each point and wavelength, so that the
metal's normal-incidence reflectance is the texel's colour (engine.spectral.gulbrandsen explains
why the map is not applied per RGB channel)."""

from __future__ import annotations

import numpy as np

from .inputs import TexturedSpectrum
from ..kernels import twin
from ..kernels.gulbrandsen import F82, SCHLICK, SCHLICK_TINT, index_loop
from ..spectral import Spectrum
from ..spectral import gulbrandsen
from ..spectral.gulbrandsen import COS_82, EDGE_MODES, R_MAX, gulbrandsen_nk, index_of

__all__ = ["TexturedGulbrandsenIndex"]


def metal_index_numpy(r, edge, mode: str):
    """(n, κ) of reflectivities r and ``edge`` values (arrays, broadcast) by ``mode``
    (engine.spectral.gulbrandsen.index_of); NaN where r or the edge is NaN."""
    r, edge = np.broadcast_arrays(np.asarray(r, np.float64), np.asarray(edge, np.float64))
    bad = np.isnan(r) | np.isnan(edge)
    if bad.any():                       # (a NaN would index the edge-tint table at INT_MIN)
        n, k = index_of(np.where(bad, 0.5, r), np.where(bad, 0.5, edge), mode)
        return np.where(bad, np.nan, n), np.where(bad, np.nan, k)
    return index_of(r, edge, mode)


_MODE_CODES = {"f82": F82, "schlick": SCHLICK, "schlick_tint": SCHLICK_TINT}
#: Schlick's (1 − cos θ₈₂)⁵, the same Python float as gulbrandsen.schlick_f82's
_SCHLICK_82 = (1.0 - COS_82) ** 5


def metal_index_numba(r, edge, mode: str):
    """metal_index_numpy in one compiled loop (engine.kernels.gulbrandsen) for the modes that solve for the edge
    tint, the same bits (NaN in, NaN out); the others ("tint", "cycles_film": no Fresnel) go to the NumPy twin."""
    if mode not in _MODE_CODES:
        return metal_index_numpy(r, edge, mode)
    r, edge = np.broadcast_arrays(np.asarray(r, np.float64), np.asarray(edge, np.float64))
    shape = r.shape
    if gulbrandsen._EDGE is None:       # (the edge-tint table, built once on first use)
        gulbrandsen.edge_tint_for_f82(0.0, 0.0)
    n, k = np.empty(r.size), np.empty(r.size)
    # (copies: a broadcast view handed to Numba draws NumPy's writeable-broadcast FutureWarning)
    index_loop(r.reshape(-1).copy(), edge.reshape(-1).copy(), _MODE_CODES[mode],
               _SCHLICK_82, COS_82, R_MAX, gulbrandsen._EDGE, n, k)
    return n.reshape(shape), k.reshape(shape)


#: A metal's (n, κ) from its reflectivity and edge (metal_index_numpy), compiled where available.
metal_index = twin(index_loop and metal_index_numba, metal_index_numpy)


def _values(spec, points, lam, mono, basis):
    if isinstance(spec, TexturedSpectrum):
        return spec.at(points, lam, mono, basis)
    return spec.eval(lam, mono=mono)


def _on_lanes(r, g, keep: np.ndarray, mode: str):
    """metal_index(r, g, mode) at the points ``keep`` (N,) bool, n = 1 and κ = 0 at the others; None where r and g
    do not broadcast to points along their last axis."""
    r, g = np.broadcast_arrays(np.asarray(r, np.float64), np.asarray(g, np.float64))
    if r.ndim == 0 or r.shape[-1] != keep.size:
        return None
    sel = np.flatnonzero(keep)
    n, k = np.ones(r.shape), np.zeros(r.shape)
    if sel.size:
        n[..., sel], k[..., sel] = metal_index(np.take(r, sel, axis=-1), np.take(g, sel, axis=-1), mode)
    return n, k


class TexturedGulbrandsenIndex(TexturedSpectrum):
    """n (``part`` "n") or κ ("k") at surface points of a reflectivity and an edge tint, either or both
    textured (the others constant spectra); both reflectances in [0, 1].  ``live``: a weight ≥ 0 per point (a
    TexturedNumber, the metal's weight in a mixture: engine.materials.principled), or None: where it is 0 nothing
    reads the index unweighted, so it is n = 1, κ = 0 there (no reflection) instead of Gulbrandsen's map."""

    def __init__(self, reflectivity: Spectrum, edge_tint: Spectrum, part: str, mode: str = "tint", live=None):
        self.live = live
        if part not in ("n", "k"):
            raise ValueError(f"part must be 'n' or 'k', got {part!r}")
        if mode not in EDGE_MODES:
            raise ValueError(f"mode must be one of {EDGE_MODES}, got {mode!r}")
        self.mode = mode
        textured = [s for s in (reflectivity, edge_tint) if isinstance(s, TexturedSpectrum)]
        if not textured:
            raise ValueError("a textured index needs a textured reflectivity or edge tint "
                             "(engine.spectral.gulbrandsen.GulbrandsenIndex otherwise)")
        self.reflectivity, self.edge_tint, self.part = reflectivity, edge_tint, part
        self.source, self.kind, self.clip = textured[0].source, "unbounded", None
        r_hi = float(reflectivity.hi) if isinstance(reflectivity, TexturedSpectrum) else \
            float(np.max(reflectivity.eval(np.linspace(360.0, 830.0, 95))))
        r_hi = min(max(r_hi, 0.0), R_MAX)
        if part == "n":     # n lies between (1 − r)/(1 + r) (g = 1) and (1 + √r)/(1 − √r) (g = 0)
            self.lo = (1.0 - R_MAX) / (1.0 + R_MAX)
            self.hi = float((1.0 + np.sqrt(r_hi)) / (1.0 - np.sqrt(r_hi)))
        else:
            self.lo = 0.0
            self.hi = float(np.max(gulbrandsen_nk(r_hi, np.linspace(0.0, 1.0, 101))[1]))

    def clamped_to(self, lo: float = -np.inf, hi: float = np.inf) -> TexturedGulbrandsenIndex:
        return self            # every value lies within [lo, hi] by construction

    def __repr__(self):
        return f"TexturedGulbrandsenIndex({self.reflectivity!r}, {self.edge_tint!r}, {self.part!r})"

    def at(self, points, lam: np.ndarray, mono: bool, basis: np.ndarray | None = None,
           d65: np.ndarray | None = None) -> np.ndarray:
        def compute():
            r = _values(self.reflectivity, points, lam, mono, basis)
            g = _values(self.edge_tint, points, lam, mono, basis)
            if self.live is not None:
                keep = np.asarray(self.live.at(points)) > 0
                if keep.ndim == 1 and not keep.all():
                    nk = _on_lanes(r, g, keep, self.mode)
                    if nk is not None:
                        return nk
            return metal_index(r, g, self.mode)
        # (n, κ) once per batch: the n and the κ of the same metal share one Gulbrandsen map
        key = ("gulbrandsen_nk", self.reflectivity, self.edge_tint, self.mode, mono, lam.shape[0], self.live)
        return points.memo(key, compute)[0 if self.part == "n" else 1]
