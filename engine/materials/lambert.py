"""Lambertian depolariser: f = (ρ/π)·diag(1, 0, 0, 0), one-sided.

ρ is the albedo spectrum (engine.spectral).  Zero when wi or wo lies behind
the shading normal (as Mitsuba 3's ``diffuse``).  Sampling: cosine-weighted
hemisphere about the shading normal, pdf = cosθ_i/π, weight = ρ.
"""

from __future__ import annotations

import numpy as np

from ..kernels import twin
from ..kernels.diffuse import cosine_sample_numba, direct_light_numba, rgb_albedo_numba, set_albedo_numba
from .base import BSDF, BSDFFlags, BSDFSample, LobeColors, ShadingPoint, depolarising_value
from .parameters import ModelDeclaration, Parameter, Socket
from .sampling import cosine_hemisphere, local_to_world
from ..spectral import ConstantSpectrum
from ..spectral.spectrum import basis_rgb
from ..textures import textured
from ..vec3 import dot


def cosine_sample_numpy(u: np.ndarray, n_s: np.ndarray, wo: np.ndarray):
    """(wi, valid, pdf) of cosine-weighted sampling about n_s (3, n) from u (2, n): wi (3, n) world
    space, valid where wo (3, n) and wi lie in front of n_s, pdf = cosθ_i/π (1/sr, 0 where not valid)."""
    local = cosine_hemisphere(u)
    wi = local_to_world(local, n_s)
    cos_o = n_s[0] * wo[0] + n_s[1] * wo[1] + n_s[2] * wo[2]
    valid = (cos_o > 0) & (local[2] > 0)
    return wi, valid, np.where(valid, local[2] / np.pi, 0.0)


#: One compiled pass over the paths where Numba is available (engine.kernels.diffuse).
cosine_sample = twin(cosine_sample_numba, cosine_sample_numpy)


def rgb_albedo_numpy(rgb: np.ndarray, slot: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Albedo spectra (L, n) of RGB-upsampled members: r·B_r + g·B_g + b·B_b with each point's
    member colour rgb[:, slot] ((3, M) table, slot (n,)) and the RGB basis (3, L, n) at its λ."""
    rgb = rgb[:, slot]
    return rgb[0][None, :] * basis[0] + rgb[1][None, :] * basis[1] + rgb[2][None, :] * basis[2]


rgb_albedo = twin(rgb_albedo_numba, rgb_albedo_numpy)


def set_albedo_numpy(rgb, value, constant, slot, basis):
    """Albedo spectra (L, n) of a LambertSet with constant and RGB members: member ``slot`` (n,)'s
    ``value`` where it is ``constant`` (M,), else its colour rgb (3, M) on the RGB basis (3, L, n)."""
    const = np.broadcast_to(value[slot][None, :], basis.shape[1:])
    return np.where(constant[slot][None, :], const, rgb_albedo_numpy(rgb, slot, basis))


set_albedo = twin(set_albedo_numba, set_albedo_numpy)


def direct_light_numpy(n_s, wo, wi, albedo, emitted, scale, ok, pdf_light, select_prob, delta):
    """Next-event estimation through Lambert surfaces (shading normals n_s, viewers wo, light
    directions wi, all (3, n)) in one pass: (S (1, Lm, n) = (ρ/π)·[wi and wo in front] for the
    albedo ρ (Lm, n): the unpolarised Stokes vector leaving towards wo per unit incident light,
    weight (L, n) = emitted·scale·|cosθ_i|·MIS / select_prob where ``ok`` (the light's validity) and
    cosθ_i ≠ 0, else 0, that validity (n,)).  MIS is the power heuristic of the light's pdf
    pdf_light·select_prob against Lambert's cosθ_i/π (1 for a ``delta`` light: bool or (n,)); ``emitted``
    (L, n) is the light's spectrum, ``scale`` (n,) its radiance/pdf factor from ``sample``, and
    ``select_prob`` (scalar or (n,)) the probability with which the light was chosen."""
    c = dot(n_s, wi)
    cos_i = np.abs(c)
    ok = ok & (cos_i > 0)
    front = (c > 0) & (dot(n_s, wo) > 0)
    A = albedo * (front / np.pi)[None, :]
    if np.all(delta):
        mis = np.ones(n_s.shape[1])
    else:
        a = pdf_light * select_prob
        a2 = a * a
        b = np.where(front, c / np.pi, 0.0)
        den = a2 + b * b
        mis = np.where(delta, 1.0, np.where(den > 0, a2 / np.where(den > 0, den, 1.0), 0.0))
    weight = emitted * scale[None, :] * (cos_i * mis / select_prob * ok)[None, :]
    return A[None], weight, ok


direct_light = twin(direct_light_numba, direct_light_numpy)


class Lambert(BSDF):
    name = "lambert"

    def __init__(self, albedo):
        self.albedo = albedo
        self.varies_over_surface = textured(albedo)
        # a pure depolariser: neither polarising nor retarding; λ-independent for a grey albedo
        self.flags = (BSDFFlags.DIFFUSE_REFLECTION | BSDFFlags.SEPARABLE_DIFFUSE
                      | BSDFFlags.when(not getattr(albedo, "is_constant", False), BSDFFlags.WAVELENGTH_DEPENDENT))

    def _albedo(self, sp: ShadingPoint) -> np.ndarray:
        return sp.spectrum(self.albedo)

    def lobe_colors(self, sp: ShadingPoint) -> LobeColors:
        """Diffuse: ρ (Cycles' diffuse closure: its weight)."""
        return LobeColors.of(sp, diffuse=self._albedo(sp))

    @property
    def scatters_nothing(self) -> bool:
        return isinstance(self.albedo, ConstantSpectrum) and self.albedo.value == 0.0

    def eval(self, sp: ShadingPoint, wi: np.ndarray):
        ok = (dot(sp.n_s, wi) > 0) & (sp.cos_o > 0)
        a = self._albedo(sp) * (ok / np.pi)[None, :]
        return depolarising_value(a, sp.n)

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        c = dot(sp.n_s, wi)
        return np.where((c > 0) & (sp.cos_o > 0), c / np.pi, 0.0)

    def direct_light(self, sp: ShadingPoint, wi, emitted, scale, ok, pdf_light, select_prob, delta):
        """(S, weight, ok) of next-event estimation towards wi in one pass (``direct_light_numpy``):
        the same numbers as ``eval``, ``pdf`` and the integrator's power heuristic."""
        return direct_light(sp.n_s, sp.wo, wi, self._albedo(sp), emitted, scale, ok, pdf_light, select_prob, delta)

    def sample(self, sp: ShadingPoint, u_lobe, u_dir) -> BSDFSample:
        wi, valid, pdf = cosine_sample(u_dir, sp.n_s, sp.wo)
        a = self._albedo(sp) * valid[None, :]
        return BSDFSample(wi=wi, weight=depolarising_value(a, sp.n), pdf=pdf,
                          is_delta=np.zeros(sp.n, bool), valid=valid, eta_sq=np.ones(sp.n))

    def describe(self) -> dict:
        return {"type": self.name, "albedo": repr(self.albedo)}


class LambertSet(Lambert):
    """Several Lambert materials shaded as one batch; point i uses member ``sp.material[i]``.

    Scenes have many diffuse materials that differ only in colour; shading them in one call
    instead of one call each removes most of the per-call overhead.  Members' albedos must be
    constant or RGB-upsampled spectra (``batchable``); each point gets exactly the value its own
    material would give (same arithmetic).
    """

    name = "lambert_set"

    def __init__(self, members: list):
        if not all(self.batchable(m) for m in members):
            raise ValueError("LambertSet members must be Lambert materials with constant or RGB albedos")
        self.members = list(members)
        self.albedo = None
        # the members' flags (all Lambert: they differ at most in λ-dependence), shaded as a batch
        self.flags = BSDFFlags.BATCHED
        for m in members:
            self.flags |= m.flags
        self._constant = np.array([m.albedo.is_constant for m in members])
        self._value = np.array([m.albedo.linear_srgb()[0] if m.albedo.is_constant else 0.0 for m in members])
        self._rgb = np.array([m.albedo.linear_srgb() for m in members]).T.copy()      # (3, members)
        self._mono = np.array([m.albedo.mono_value for m in members])

    @staticmethod
    def batchable(m) -> bool:
        from ..spectral.spectrum import ConstantSpectrum, _RGBBasisSpectrum
        return type(m) is Lambert and isinstance(m.albedo, (ConstantSpectrum, _RGBBasisSpectrum))

    def _albedo(self, sp: ShadingPoint) -> np.ndarray:
        slot = sp.material
        L, n = sp.lam.shape
        if sp.mono:
            return np.broadcast_to(self._mono[slot][None, :], (L, n)).copy()
        if self._constant.all():
            return np.broadcast_to(self._value[slot][None, :], (L, n)).copy()
        mixed = self._constant.any()

        def combine():
            basis = sp.lookup.basis if sp.lookup is not None else basis_rgb(sp.lam)
            if mixed:
                return set_albedo(self._rgb, self._value, self._constant, slot, basis)
            return rgb_albedo(self._rgb, slot, basis)
        # the value depends on the slots too: memo per (set, slot array) — the slot array is the
        # same object for a vertex's eval and sample, and new at every bounce
        return sp.lookup.memo((self, slot), combine) if sp.lookup is not None else combine()

    def describe(self) -> dict:
        return {"type": self.name, "members": [m.describe() for m in self.members]}


# --------------------------------------------------------------------------- declaration

DECLARATION = ModelDeclaration(
    "lambert", "Lambert", "Ideal depolariser: diffuse, unpolarised reflection (albedo/π)",
    [Parameter("albedo", "albedo ρ (BRDF ρ/π)", kind="spectrum", spectrum="reflectance", lo=0.0, hi=1.0,
               default=0.8, texturable=True,
               socket=Socket("Albedo", "COLOR", (0.8, 0.8, 0.8), 0.0, 1.0, "Diffuse reflectance (linear sRGB)"))],
    catalogue="lambert", node="LAMBERT")


DECLARATION.per_point = frozenset({"albedo"})


@DECLARATION.builder
def _lambert(p):
    return Lambert(p["albedo"])
