"""A metal's complex index from its colour: Gulbrandsen's map, applied per wavelength.

Gulbrandsen (2014, "Artist Friendly Metallic Fresnel", JCGT 3(4)) gives the complex index n + iκ
whose normal-incidence reflectance is r and whose "edge tint" is g (both in [0, 1]):

    n = g·(1 − r)/(1 + r) + (1 − g)·(1 + √r)/(1 − √r),
    κ = √( (r·(n + 1)² − (n − 1)²) / (1 − r) ).

Blender's metals are colours (Principled Base Color, Glossy Color).  Mapping each RGB channel to n, κ
and then upsampling n and κ as spectra does **not** give the colour back: Fresnel reflectance is not
linear in n, κ (a saturated red mirror developed 7 % too bright, gold's red channel 28 % too dark).
So the map is applied *per wavelength*, to the reflectance spectra r(λ) and g(λ) upsampled from the
colours: F(0°, λ) = r(λ) exactly, which develops back to the colour as every reflectance does.
Cycles' metals follow the F82 curve (Schlick's, bent at θ₈₂ = acos(1/7) by a tint): with g solved
for (:func:`edge_tint_for_f82`) the polarising conductor also reflects Cycles' value at θ₈₂, so the two
curves agree at 0° and θ₈₂ and differ little between (a 0.8-grey metal under a sky: S0 within 0.3 %).
:class:`GulbrandsenIndex` is the n or κ spectrum of such a pair; the textured twin is
engine.textures.inputs.TexturedGulbrandsenIndex.  ``linear_srgb`` gives the per-channel map (what an
RGB renderer uses: exact per channel).
"""

from __future__ import annotations

import weakref

import numpy as np

from .spectrum import Spectrum

__all__ = ["COS_82", "R_MAX", "GulbrandsenIndex", "edge_tint_for_f82", "gulbrandsen_nk", "schlick_f82"]

#: Largest reflectivity mapped (r → 1 sends n to infinity); Cycles clamps the same way (0.999 in its
#: thin-film conductor, 0.99 in the earlier exporter): 0.999 keeps F(0°) within 1e-3 of white metal.
R_MAX = 0.999


def gulbrandsen_nk(r, g):
    """(n, κ) arrays of reflectivity r and edge tint g (broadcast; clipped to [0, R_MAX] and [0, 1])."""
    r = np.clip(np.asarray(r, np.float64), 0.0, R_MAX)
    g = np.clip(np.asarray(g, np.float64), 0.0, 1.0)
    sr = np.sqrt(r)
    n = g * (1.0 - r) / (1.0 + r) + (1.0 - g) * (1.0 + sr) / (1.0 - sr)
    k = np.sqrt(np.maximum((r * (n + 1.0) ** 2 - (n - 1.0) ** 2) / (1.0 - r), 0.0))
    return n, k


#: cos θ of the F82 model's second angle (θ ≈ 81.8°, where cos θ (1 − cos θ)⁶ peaks)
COS_82 = 1.0 / 7.0
_TABLE_R = 513
_TABLE_T = 257


def _reflectance_82(r, g):
    from ..polarisation.fresnel import fresnel_reflectance
    n, k = gulbrandsen_nk(r, g)
    return fresnel_reflectance(COS_82, n + 1j * k)


def schlick_f82(r):
    """Schlick's reflectance at θ₈₂ for normal-incidence reflectance r (Cycles' F82-tint curve with a
    white tint: the Principled BSDF's metal at Specular Tint white)."""
    r = np.asarray(r, np.float64)
    return r + (1.0 - r) * (1.0 - COS_82) ** 5


def _edge_table() -> np.ndarray:
    """g(r, t) on a grid (nodes in √r and t): the edge tint whose reflectance at θ₈₂ lies the fraction t of the way from
    g = 0's to g = 1's (monotone in g: bisection, 48 steps)."""
    r = R_MAX * np.linspace(0.0, 1.0, _TABLE_R)[:, None] ** 2      # nodes in √r: g changes fastest near r = 0
    t = np.linspace(0.0, 1.0, _TABLE_T)[None, :]
    lo_f, hi_f = _reflectance_82(r, 0.0), _reflectance_82(r, 1.0)
    target = lo_f + t * (hi_f - lo_f)
    lo, hi = np.zeros(np.broadcast_shapes(r.shape, t.shape)), np.ones(np.broadcast_shapes(r.shape, t.shape))
    for _ in range(48):
        mid = 0.5 * (lo + hi)
        below = _reflectance_82(r, mid) < target
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return 0.5 * (lo + hi)


_EDGE = None


def edge_tint_for_f82(r, f82):
    """The edge tint g ∈ [0, 1] (arrays, broadcast) with which Gulbrandsen's metal of normal-incidence
    reflectance r reflects f82 at θ₈₂ (the F82 models' second point: Cycles' Principled metal); where no
    g reaches f82 the nearest end.  A table g(r, t) built once (0.1 s), bilinear: F(θ₈₂) within 2e-4."""
    global _EDGE
    if _EDGE is None:
        _EDGE = _edge_table()
    r = np.clip(np.asarray(r, np.float64), 0.0, R_MAX)
    lo_f, hi_f = _reflectance_82(r, 0.0), _reflectance_82(r, 1.0)
    t = np.clip((np.asarray(f82, np.float64) - lo_f) / np.maximum(hi_f - lo_f, 1e-300), 0.0, 1.0)
    x = np.sqrt(r / R_MAX) * (_TABLE_R - 1)
    y = t * (_TABLE_T - 1)
    i = np.minimum(x.astype(np.int64), _TABLE_R - 2)
    j = np.minimum(y.astype(np.int64), _TABLE_T - 2)
    fx, fy = x - i, y - j
    E = _EDGE
    return ((E[i, j] * (1.0 - fx) + E[i + 1, j] * fx) * (1.0 - fy)
            + (E[i, j + 1] * (1.0 - fx) + E[i + 1, j + 1] * fx) * fy)


def index_of(r, edge, mode: str):
    """(n, κ) of reflectivity values r and ``edge`` values by ``mode``: "tint" (edge = Gulbrandsen's g),
    "f82" (edge = the reflectance at θ₈₂), "schlick" (the reflectance at θ₈₂ of Schlick's curve through
    r; ``edge`` unused), "schlick_tint" (Schlick's × min(edge, 1): Cycles' F82-Tint of the Principled metal,
    edge its Specular Tint) or "cycles_film" (Cycles' estimate under a thin film: that F82-Tint value taken as
    Gulbrandsen's edge tint g itself, r ≤ 0.999)."""
    if mode == "tint":
        return gulbrandsen_nk(r, edge)
    if mode == "cycles_film":       # Cycles' index under a thin film: r and its F82-Tint value taken as Gulbrandsen's
        f82 = schlick_f82(r) * np.minimum(np.maximum(edge, 0.0), 1.0)      # (r, g) (fresnel_iridescence's estimate)
        return gulbrandsen_nk(np.minimum(r, 0.999), f82)
    if mode == "schlick_tint":
        f82 = schlick_f82(r) * np.minimum(np.maximum(edge, 0.0), 1.0)
    else:
        f82 = schlick_f82(r) if mode == "schlick" else edge
    return gulbrandsen_nk(r, edge_tint_for_f82(r, f82))


EDGE_MODES = ("tint", "f82", "schlick", "schlick_tint", "cycles_film")
#: one object per mode: memo keys match by identity (WavelengthLookup.memo)
_MODE_KEYS = {mode: object() for mode in EDGE_MODES}


#: "rgb" transport's (n, κ) (2, 3, 1) per GulbrandsenIndex (GulbrandsenIndex._nk; not a field: the scene's
#: fingerprint, engine.render.resume, hashes the fields)
_CHANNEL_NK: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class GulbrandsenIndex(Spectrum):
    """n(λ) (``part`` "n") or κ(λ) (``part`` "k") of the reflectivity spectrum r and the ``edge``
    spectrum (constant engine.spectral Spectra; reflectances in [0, 1]) read by ``mode`` (:func:`index_of`:
    Gulbrandsen's edge tint g, the reflectance at θ₈₂, or Schlick's θ₈₂ reflectance of r)."""

    def __init__(self, reflectivity: Spectrum, edge: Spectrum, part: str, mode: str = "tint"):
        if part not in ("n", "k"):
            raise ValueError(f"part must be 'n' or 'k', got {part!r}")
        if mode not in EDGE_MODES:
            raise ValueError(f"mode must be one of {EDGE_MODES}, got {mode!r}")
        self.reflectivity, self.edge_tint, self.part, self.mode = reflectivity, edge, part, mode
        self.is_constant = bool(reflectivity.is_constant and edge.is_constant)
        self.is_grey = self.is_constant

    def _pick(self, n, k):
        return n if self.part == "n" else k

    def _eval(self, lam):
        return self._pick(*index_of(self.reflectivity.eval(lam), self.edge_tint.eval(lam), self.mode))

    def eval_cached(self, lookup):
        # (n, κ) once per lookup: the n and the κ of one metal (the same two spectra) share one Gulbrandsen map
        nk = lookup.memo((self.reflectivity, self.edge_tint, _MODE_KEYS[self.mode]), lambda: self._nk(lookup))
        return nk[0] if self.part == "n" else nk[1]

    def _nk(self, lookup) -> np.ndarray:
        """(2, L, N) n and κ at the lookup's paths.  "rgb" transport (``lookup.channels``): every path of every
        lookup holds the same three channel values (the spectra are not textured), so the map runs once per
        spectrum on one path's column and the result is a read-only view of it (elementwise: the same values;
        the map per lookup was 12 % of a many-metal render)."""
        if lookup.channels:
            nk = _CHANNEL_NK.get(self)
            if nk is None:
                r, edge = self.reflectivity.eval_cached(lookup), self.edge_tint.eval_cached(lookup)
                nk = np.stack(index_of(r[..., :1], edge[..., :1], self.mode))
                nk.setflags(write=False)
                _CHANNEL_NK[self] = nk
            return np.broadcast_to(nk, nk.shape[:-1] + lookup.lam.shape[-1:])
        return np.stack(index_of(self.reflectivity.eval_cached(lookup), self.edge_tint.eval_cached(lookup),
                                 self.mode))

    def linear_srgb(self) -> np.ndarray:
        return self._pick(*index_of(self.reflectivity.linear_srgb(), self.edge_tint.linear_srgb(), self.mode))

    @property
    def mono_value(self) -> float:
        """The map of the luminances (monochrome renders use the colours' luminance as reflectance)."""
        return float(self._pick(*index_of(self.reflectivity.mono_value, self.edge_tint.mono_value, self.mode)))

    def value_range(self) -> tuple[float, float]:
        """Bounds over the visible range (checked like any spectrum by the parameter declarations)."""
        lam = np.linspace(360.0, 830.0, 95)
        v = self._eval(lam)
        return float(v.min()), float(v.max())

    def __repr__(self):
        return f"GulbrandsenIndex({self.reflectivity!r}, {self.edge_tint!r}, {self.part!r}, {self.mode!r})"
