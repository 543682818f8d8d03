"""A weighted mixture of phase functions: M = Σ_k w_k·M_k with Σ w_k = 1 (Blender's Mix / Add Shader of volume
shaders, and Cycles' Mie blend, keep several scattering closures in one medium).

Each component is a normalised phase function (engine.media.phase.PhaseFunction), so the mixture is one too;
the weights are the components' shares of the medium's scattering coefficient (one number each: the same at
every wavelength).  Elements: the weighted sums of the components' six elements (kind "depolarising" when every
component is, else "general").  Sampling picks component k with probability w_k (u[0] rescaled onto [0, 1))
and samples it exactly: the pdf is Σ w_k·p_k, the mixture's a1 — Cycles' volume closure selection by weight,
with one-sample MIS over the components.  A straight-on Dirac part of a component (Fournier–Forand's
``forward_dirac``) keeps weight 1: it is sampled with the same probability w_k·mass as its share of the mixture.
"""

from __future__ import annotations

import numpy as np

from .phase import PhaseFunction, PhaseMatrix
from ..materials.flags import BSDFFlags

#: PhaseMatrix element names, in its constructor's order after ``kind``
_ELEMENTS = ("a1", "b1", "a2", "a3", "b2", "a4")


class PhaseMixture(PhaseFunction):
    """Components ``phases`` (list of PhaseFunction) with weights ``weights`` (≥ 0, not all 0; normalised)."""

    name = "mixture"

    def __init__(self, phases, weights):
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        if len(phases) == 0 or w.size != len(phases) or not np.all(np.isfinite(w)) or np.any(w < 0) \
                or not w.sum() > 0:
            raise ValueError("a phase mixture needs one weight ≥ 0 per component, not all 0")
        self.phases, self.weights = list(phases), w / w.sum()
        self.cdf = np.cumsum(self.weights)
        self.cdf[-1] = 1.0
        flags = BSDFFlags.NONE
        for p in self.phases:
            flags |= p.flags
        self.flags = flags
        self.forward_dirac = any(p.forward_dirac for p in self.phases)

    def elements(self, mu, lam) -> PhaseMatrix:
        parts = [p.elements(mu, lam) for p in self.phases]
        if all(part.kind == "depolarising" for part in parts):
            return PhaseMatrix.depolarising(sum(w * np.asarray(part.a1) for w, part in zip(self.weights, parts)))
        return PhaseMatrix("general", *(sum(w * np.asarray(getattr(part, e), dtype=np.float64)
                                            for w, part in zip(self.weights, parts)) for e in _ELEMENTS))

    def pdf_mu(self, mu, lam) -> np.ndarray:
        return sum(w * p.pdf_mu(mu, lam) for w, p in zip(self.weights, self.phases))

    def sample_mu(self, u, lam):
        u = np.asarray(u, dtype=np.float64)
        lam = np.broadcast_to(np.asarray(lam, dtype=np.float64), u.shape)
        k = np.minimum(np.searchsorted(self.cdf, u, side="right"), len(self.phases) - 1)
        start = np.concatenate(([0.0], self.cdf[:-1]))
        out = np.empty_like(u)
        for j in np.unique(k):
            at = k == j
            v = np.clip((u[at] - start[j]) / self.weights[j], 0.0, np.nextafter(1.0, 0.0))
            out[at] = self.phases[j].sample_mu(v, lam[at])
        return out

    def describe(self) -> dict:
        return {"type": self.name, "components": [p.describe() for p in self.phases],
                "weights": self.weights.tolist()}
