"""Polarised sources in the transport: the Stokes vector of emitted light, carried into the path's frames.

A source hands the integrator, for light leaving along k (3, n), its normalised Stokes vectors s (4, n)
in its own frame x_e (``_Light.emitted_polarisation``; engine.polarisation.sources).  The light a path
picks up is then T · R(x_e → x_T) · s · L_e (an emitter hit: x_T is the path's frame ⟂ its segment) or,
by next-event estimation, T · R(x_out → x_T) · M · R(x_e → x_in) · s · L_e, M the BSDF's Mueller matrix in
its frames (x_in, x_out).  Unpolarised sources never come here: their s = (1, 0, 0, 0) is what the
integrator's scalar path (T[:, 0] · L_e, M[:, 0]) already computes, bit for bit.
"""

from __future__ import annotations

import numpy as np

from ..kernels.stokes_rotation import frame_rotation, rotate_stokes
from ..materials.base import MuellerValue


def in_frame(s: np.ndarray, x_from: np.ndarray, x_to: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Stokes vectors s (4, n) of beams along k (3, n), re-expressed from frame x_from to x_to (3, n)."""
    return rotate_stokes(s, *frame_rotation(x_from, x_to, k))


def mueller_times_stokes(m: MuellerValue, s: np.ndarray, P: int) -> np.ndarray:
    """M · s: the Stokes vectors (P, L, n) leaving in frame ``m.x_out`` for incident normalised Stokes s
    (4, n) in frame ``m.x_in`` (components beyond P dropped: the transport has P)."""
    if m.kind == "general":
        return np.einsum("ijln,jn->iln", m.M[:P, :4], s)
    L, n = m.A.shape
    out = np.zeros((P, L, n))
    a0 = m.A if m.depol is None else m.A + m.depol
    if m.kind == "depolarising":
        out[0] = m.A * s[0]
        return out
    out[0] = a0 * s[0] + m.B * s[1]
    if P > 1:
        out[1] = m.B * s[0] + m.A * s[1]
        out[2] = m.C * s[2] + m.S * s[3]
    if P > 3:
        out[3] = -m.S * s[2] + m.C * s[3]
    return out


def light_samples_polarisation(light_set, owners: list, wi: np.ndarray):
    """(s (4, n), x_e (3, n)) of next-event light samples arriving along wi (3, n) — the light travels along
    −wi — from the lights of ``owners`` ((light index, its samples) pairs); unpolarised lights' samples get
    s = (1, 0, 0, 0).  None when none of the chosen lights is polarised."""
    if not any(light_set.lights[li].polarisation is not None for li, _ in owners):
        return None
    n = wi.shape[1]
    s = np.zeros((4, n))
    s[0] = 1.0
    x = np.zeros((3, n))
    x[0] = 1.0
    for li, sel in owners:
        light = light_set.lights[li]
        if light.polarisation is None:
            continue
        k = -(wi if isinstance(sel, slice) else wi[:, sel])
        got = light.emitted_polarisation(k)
        s[:, sel], x[:, sel] = got
    return s, x
