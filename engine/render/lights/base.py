"""Light base class and a cone sampler shared by the emitters.

Part of engine.render.lights (its package docstring states the light interface)."""

from __future__ import annotations

import math

import numpy as np

from ...materials.sampling import local_to_world
from ...polarisation.sources import emitter_frame, reference_axes
from ...spectral import GRID_NM, spectrum_to_linear_srgb


def uniform_cone(u1, u2, one_minus_cos_max, axis):
    """Directions uniform in the cone of 1 − cosθ ≤ ``one_minus_cos_max`` around the unit
    ``axis`` (3,) or (3, N); pdf = 1/(2π·one_minus_cos_max)."""
    one_minus_cos = u1 * one_minus_cos_max
    cos_t = 1.0 - one_minus_cos
    sin_t = np.sqrt(np.maximum(one_minus_cos * (2.0 - one_minus_cos), 0.0))
    phi = 2.0 * math.pi * u2
    local = np.stack((sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t))
    axis = np.broadcast_to(axis.reshape(3, -1), local.shape)
    return local_to_world(local, axis), cos_t


class _Light:
    is_delta = False
    at_infinity = False
    hittable = False      # an analytic emitter that rays find through ``intersect`` (not in the BVH)
    blocks_own_shadow_rays = False    # an opaque emitter whose geometry can stop its own shadow rays
    hit_pdf_needs_origin = False      # ``pdf_hit`` needs the segment's origin (solid-angle sampled lamps)
    hit_pdf_needs_direction = False   # ... and where on the lamp the ray arrives (warp-sampled lamps)
    #: an emitter hidden from indirect rays lights nothing by next-event estimation either (Cycles excludes
    #: a mesh light from the ray types its object is invisible to); camera rays still see it
    shades_nothing = False
    varies_over_surface = False       # radiance per point (TexturedAreaEmitter: sample_points, emitted_at)
    #: the radiance depends on the direction the light leaves along (the integrator reads it per direction only
    #: then: a world map); False: one radiance in every direction it emits
    varies_with_direction = False

    @property
    def constant_sky(self) -> bool:
        """A world of one radiance from every direction: Cycles turns its MIS off, and LightSet's "cycles" selection
        leaves it to BSDF sampling beside other lights.  False but for a whole-sphere sky that does not vary."""
        return False

    #: the emitted light's polarisation (engine.polarisation.sources.SourcePolarisation; None: unpolarised)
    #: and its reference axes (axis, other), set by LightSet.set_polarisation
    polarisation = None
    polarisation_axes = None

    def __init__(self, spectrum):
        self.spectrum = spectrum

    def set_polarisation(self, polarisation, axis=None) -> None:
        """Polarise this light (``polarisation``: a SourcePolarisation; ``axis``: its reference axis (3,) in
        world space, None: world +X); an unpolarised ``polarisation`` leaves it unpolarised."""
        if polarisation is not None and polarisation.polarised:
            self.polarisation, self.polarisation_axes = polarisation, reference_axes(axis)

    def emitted_polarisation(self, k: np.ndarray):
        """(normalised Stokes (4, n), frame x (3, n)) of the light leaving along the unit directions k (3, n)
        (its frame: x ⟂ k, y = k × x), or None for an unpolarised light."""
        if self.polarisation is None:
            return None
        x = emitter_frame(*self.polarisation_axes, k)
        return np.repeat(self.polarisation.stokes()[:, None], k.shape[1], axis=1), x

    def radiance(self, lam, mono) -> np.ndarray:
        return self.spectrum.eval(lam, mono=mono)

    def map_coordinates(self, d: np.ndarray):
        """The coordinates a world map reads at the world directions d (3, N) — (u, v) (N,) each, computed once
        for its ``emitted`` and ``pdf`` (their ``uv``) — or None: a light that reads no map."""
        return None

    def channel_rgb(self) -> np.ndarray:
        """Linear sRGB (3,) as an RGB renderer uses this light ("rgb" transport): an RGB-defined
        spectrum's own colour (Cycles' light colour × strength), else :meth:`rgb`."""
        if not hasattr(self, "_channel_rgb"):
            try:
                self._channel_rgb = np.asarray(self.spectrum.linear_srgb(), np.float64).reshape(3)
            except (NotImplementedError, TypeError, AttributeError, ValueError):
                self._channel_rgb = self.rgb()
        return self._channel_rgb

    def rgb(self) -> np.ndarray:
        """Linear sRGB (3,) of the emitted spectrum: the exact expectation of the spectral estimator."""
        if not hasattr(self, "_rgb"):
            self._rgb = spectrum_to_linear_srgb(self.spectrum.eval(GRID_NM))
        return self._rgb
