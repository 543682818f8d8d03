"""Thin polarising filters placed in the scene: linear polariser and linear retarder sheets.

An ideal thin sheet (index-matched, no reflection) transmits light straight through (ω_i = −ω_o,
a Dirac lobe) and multiplies its Stokes vector by the filter's Mueller matrix.  The filter axis is
a world-space vector (the transmission axis of a polariser, the fast axis of a retarder) that
should lie in the sheet's plane; for each beam it is projected onto the plane ⟂ the propagation
direction k and used as the Stokes frame x = s, where both matrices have the ABCS form:

- polariser with principal transmittances t_max (along the axis) and t_min = extinction·t_max:
  A = (t_max + t_min)/2, B = (t_max − t_min)/2, C = √(t_max t_min), S = 0;
- retarder with retardance δ (Jones diag(1, e^{iδ}) in the fast-axis frame, e^{−iωt}):
  A = t, B = 0, C = t·cos δ, S = t·sin δ.

Two-sided; works the same from both sides (for a beam along the sheet's normal the projected
axis is the axis itself).  A polariser in front of the camera gives exactly the post-process
filter of engine.postprocess.filters (tested).
"""

from __future__ import annotations

import math

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, DeltaVertices, MuellerValue, ShadingPoint, depolarising_value
from .parameters import ModelDeclaration, Parameter
from ..kernels import twin
from ..kernels.delta_bounce import filter_sheet_loop
from ..kernels.transport import update_abcs_numpy
from ..vec3 import any_perpendicular, dot


def filter_axis_frame(axis, k):
    """The filter axis (3,) projected ⟂ the beams k (3, N), normalised; any_perpendicular(k) where ∥ k."""
    a = axis[:, None]
    x = a - dot(np.broadcast_to(a, k.shape), k) * k
    length = np.sqrt(dot(x, x))
    ok = length > 1e-9
    return np.where(ok, x / np.where(ok, length, 1.0), any_perpendicular(k))


def filter_sheet_scatter_numpy(rows, wo, x_T, T, axis, A, B, C, S, T_out, d, x_out, valid, eta_sq, T_cols=None):
    """FilterSheet.sample and the throughput update at the paths ``rows`` (engine.kernels.delta_bounce:
    T_out, d, x_out, valid, eta_sq written there; throughputs in the columns ``T_cols`` of T, None:
    ``rows``) for the sheet's constant (A, B, C, S)."""
    wo = wo[:, rows]
    x = filter_axis_frame(axis, wo)
    one = np.ones((1, rows.shape[0]))
    update_abcs_numpy(T_out, T, rows, x, x_T[:, rows], wo, A * one, B * one, C * one, S * one, None, T_cols)
    d[:, rows] = -wo
    x_out[:, rows] = x
    valid[rows] = True
    eta_sq[rows] = 1.0


def filter_sheet_scatter_numba(rows, wo, x_T, T, axis, A, B, C, S, T_out, d, x_out, valid, eta_sq, T_cols=None):
    filter_sheet_loop(rows, wo, x_T, T, axis, A, B, C, S, T_out, d, x_out, valid, eta_sq,
                      rows if T_cols is None else T_cols)


filter_sheet_scatter = twin(filter_sheet_loop and filter_sheet_scatter_numba, filter_sheet_scatter_numpy)


class FilterSheet(BSDF):
    name = "filter_sheet"

    def __init__(self, axis, kind: str = "polariser", extinction: float = 0.0, retardance_deg: float = 90.0,
                 transmittance: float = 1.0):
        if kind not in ("polariser", "retarder"):
            raise ValueError(f"kind must be 'polariser' or 'retarder', got {kind!r}")
        axis = np.asarray(axis, dtype=np.float64)
        norm = np.linalg.norm(axis)
        if not norm > 0:
            raise ValueError("axis must be a non-zero vector")
        self.axis = axis / norm
        self.kind = kind
        self.extinction = float(extinction)
        self.retardance_deg = float(retardance_deg)
        self.transmittance = float(transmittance)
        # light passes straight through (a null lobe); only a retarder creates circular polarisation
        self.flags = (BSDFFlags.NULL | BSDFFlags.POLARISING
                      | BSDFFlags.when(kind == "retarder", BSDFFlags.RETARDING))

    def _abcs(self):
        t = self.transmittance
        if self.kind == "polariser":
            t_min = t * self.extinction
            return 0.5 * (t + t_min), 0.5 * (t - t_min), math.sqrt(t * t_min), 0.0
        d = math.radians(self.retardance_deg)
        return t, 0.0, t * math.cos(d), t * math.sin(d)

    def eval(self, sp, wi):
        return depolarising_value(np.zeros_like(sp.lam), sp.n)

    def pdf(self, sp, wi):
        return np.zeros(sp.n)

    def sample(self, sp: ShadingPoint, u_lobe, u_dir) -> BSDFSample:
        x = filter_axis_frame(self.axis, sp.wo)    # light passes straight through towards the viewer
        A, B, C, S = self._abcs()
        shape = sp.lam.shape
        value = MuellerValue("abcs", x, x, np.full(shape, A), np.full(shape, B), np.full(shape, C),
                             np.full(shape, S))
        n = sp.n
        return BSDFSample(wi=-sp.wo, weight=value, pdf=np.zeros(n), is_delta=np.ones(n, bool),
                          valid=np.ones(n, bool), eta_sq=np.ones(n))

    def scatter_delta(self, v: DeltaVertices) -> bool:
        """``sample`` + the throughput update in one step (see BSDF)."""
        filter_sheet_scatter(v.rows, v.wo, v.x_T, v.T, self.axis, *(float(c) for c in self._abcs()), v.T_out, v.d,
                             v.x_out, v.valid, v.eta_sq, T_cols=v.T_cols)
        return True

    def describe(self):
        return {"type": self.name, "kind": self.kind, "axis": self.axis.tolist(), "extinction": self.extinction,
                "retardance_deg": self.retardance_deg, "transmittance": self.transmittance}


# --------------------------------------------------------------------------- declarations

_AXIS = Parameter("axis", "filter axis in world space (transmission axis / fast axis), in the sheet's plane",
                  kind="direction")
_TRANSMITTANCE = Parameter("transmittance", "transmittance t along the axis", lo=0.0, hi=1.0, default=1.0)

POLARISER = ModelDeclaration(
    "polariser", "Polariser sheet", "Thin linear polariser: t_max along the axis, t_min = extinction·t_max",
    [_AXIS, Parameter("extinction", "extinction ratio t_min/t_max (0 = ideal)", lo=0.0, hi=1.0, default=0.0),
     _TRANSMITTANCE])
RETARDER = ModelDeclaration(
    "retarder", "Retarder sheet", "Thin linear retarder (wave plate) with its fast axis along the axis",
    [_AXIS, Parameter("retardance_deg", "retardance δ", unit="deg", lo=-360.0, hi=360.0, default=90.0),
     _TRANSMITTANCE])


@POLARISER.builder
def _polariser(p):
    return FilterSheet(p["axis"], "polariser", extinction=p["extinction"], transmittance=p["transmittance"])


@RETARDER.builder
def _retarder(p):
    return FilterSheet(p["axis"], "retarder", retardance_deg=p["retardance_deg"], transmittance=p["transmittance"])
