"""Smooth dielectric interface with reflection, refraction and total internal reflection.

Two-sided: the interior (index ``n``) lies behind the shading normal, the
exterior (``exterior_n``) in front of it.  From the viewer's side (wo) the
relative index is η = n_far / n_near.

- Reflection: the Fresnel Mueller matrix M_F(cosθ_o, η) in the plane-of-
  incidence frames; beyond the critical angle (TIR) r_s, r_p are complex
  with |r| = 1, so M_F becomes a pure retarder (S ≠ 0: circular polarisation).
- Refraction: the diattenuator with T_s = 1 − F_s, T_p = 1 − F_p (no
  retardance for real η below the critical angle), in the shared s-p frames
  x = s = unit(n × k).
- Lobe choice: reflection with probability P_r = mean over the path's
  wavelengths of the unpolarised reflectance (F_s + F_p)/2; the weights are
  divided by the chosen probability, so the estimator is exact per wavelength.

**Radiance scaling.**  Radiance is not conserved across a refracting interface:
L/n² is.  Paths are traced from the camera, so a refracted camera ray that
moves from a medium of index n_o (the wo side) into n_i (the wi side) carries
radiance L_o = (n_o/n_i)² T L_i.  The factor (n_o/n_i)² = 1/η² is part of the
sample weight, *not* of the Mueller matrix; it cancels for a path that enters
and leaves a closed object (as in Mitsuba 3's ``dielectric``).

The index must be the same at every wavelength (no dispersion): a refracted
direction is shared by all wavelengths of a path.  It may vary over the surface (``n`` a TexturedNumber or a
NumberSpectrum, e.g. a Principled IOR texture): every formula above is elementwise in η, so each point gets
exactly the constant-index interface of its own value; such an instance has ``varies_over_surface`` set and no
fused ``scatter_delta`` step (the integrator then samples it through ``sample``).
"""

from __future__ import annotations

import math

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, DeltaVertices, MuellerValue, ShadingPoint, depolarising_value
from .parameters import ModelDeclaration, Parameter, Socket, exterior_n_parameter
from ..errors import SceneError
from ..kernels import twin
from ..kernels.delta_bounce import dielectric_loop
from ..kernels.geometry import unit_cross_numpy
from ..kernels.transport import update_abcs_numpy
from ..textures import TexturedNumber, TexturedSpectrum
from ..polarisation.frames import plane_of_incidence_axis
from ..polarisation.fresnel import fresnel_reflection_abcs, fresnel_reflection_abcs_numpy, \
    fresnel_transmission_abcs, refracted_cosine
from ..vec3 import reflect


def dielectric_scatter_numpy(rows, n_s, wo, x_T, T, u_lobe, eta_front, eta_back, T_out, d, x_out, valid, eta_sq,
                             T_cols=None):
    """SmoothDielectric.sample and the throughput update at the paths ``rows`` (engine.kernels.delta_bounce:
    T_out, d, x_out, valid, eta_sq written there); relative index ``eta_front`` seen from the front
    (wo·n_s ≥ 0), ``eta_back`` from behind; the throughputs in the columns ``T_cols`` of T (None:
    ``rows``).  The same NumPy steps as ``sample``."""
    n_s, wo, u = n_s[:, rows], wo[:, rows], u_lobe[rows]
    cos_o = n_s[0] * wo[0] + n_s[1] * wo[1] + n_s[2] * wo[2]
    front = cos_o >= 0
    c, eta, nn = np.abs(cos_o), np.where(front, eta_front, eta_back), np.where(front[None, :], n_s, -n_s)
    A, B, C, S = fresnel_reflection_abcs_numpy(c, eta)
    reflect_lobe = u < A
    cos_t, tir = refracted_cosine(c, eta)
    inv_eta = 1.0 / eta
    wi = np.where(reflect_lobe[None, :], reflect(wo, nn), -wo * inv_eta + (c * inv_eta - cos_t) * nn)
    s = unit_cross_numpy(nn, -wi, 1e-12)
    # fresnel_transmission_abcs from the same reflection coefficients
    T_s = np.where(tir, 0.0, np.clip(1.0 - (A + B), 0.0, 1.0))
    T_p = np.where(tir, 0.0, np.clip(1.0 - (A - B), 0.0, 1.0))
    trans = 0.5 * (T_s + T_p), 0.5 * (T_s - T_p), np.sqrt(T_s * T_p), np.zeros_like(T_s)
    p_r = np.where(A > 0, A, 1.0)
    scale_t = inv_eta * inv_eta / np.where(A < 1, 1.0 - A, 1.0)
    value = [np.where(reflect_lobe, r / p_r, t * scale_t)[None, :] for r, t in zip((A, B, C, S), trans)]
    update_abcs_numpy(T_out, T, rows, s, x_T[:, rows], wo, *value, None, T_cols)
    d[:, rows] = wi
    x_out[:, rows] = s
    valid[rows] = reflect_lobe | ~tir
    eta_sq[rows] = np.where(reflect_lobe, 1.0, eta * eta)


def dielectric_scatter_numba(rows, n_s, wo, x_T, T, u_lobe, eta_front, eta_back, T_out, d, x_out, valid, eta_sq,
                             T_cols=None):
    dielectric_loop(rows, n_s, wo, x_T, T, u_lobe, eta_front, eta_back, T_out, d, x_out, valid, eta_sq,
                    rows if T_cols is None else T_cols)


dielectric_scatter = twin(dielectric_loop and dielectric_scatter_numba, dielectric_scatter_numpy)


def per_point_index(n) -> bool:
    """An index that varies over the surface: a TexturedNumber, or a λ-independent TexturedSpectrum
    (engine.textures.inputs.NumberSpectrum, e.g. the Principled IOR's index per point)."""
    return isinstance(n, (TexturedNumber, TexturedSpectrum))


def index_at(n, sp):
    """An index at the shading points: the number itself, or its values (N,) where it varies over the surface."""
    if isinstance(n, TexturedNumber):
        return sp.number(n)
    if isinstance(n, TexturedSpectrum):
        return n.numbers(sp.surface_points())
    return n


def one_side_of(values, name: str, exterior_n: float):
    """The declared index ``name`` of engine.materials.parameters.Values, refused (SceneError naming the field) where
    it varies per point across ``exterior_n``: the interface would turn inside out between points (the Principled
    IOR, the Glass and Refraction BSDFs' IOR)."""
    n = values[name]
    if per_point_index(n) and n.lo < exterior_n < n.hi:
        raise SceneError(values.field(name), f"a per-point index must lie on one side of {exterior_n:g}, got values in "
                                             f"[{n.lo:g}, {n.hi:g}]")
    return n


def checked_index(n, name: str = "n"):
    """A real index as the dielectric models keep it: a finite number > 0, or a per-point index whose bounds are."""
    if per_point_index(n):
        if not (math.isfinite(n.lo) and math.isfinite(n.hi) and n.lo > 0):
            raise ValueError(f"{name} must be finite and > 0 everywhere, got values in [{n.lo:g}, {n.hi:g}]")
        return n
    return float(n)


class SmoothDielectric(BSDF):
    name = "dielectric"
    # total internal reflection retards; the index is one number (no dispersion): λ-independent
    flags = BSDFFlags.DELTA_REFLECTION | BSDFFlags.DELTA_TRANSMISSION | BSDFFlags.POLARISING | BSDFFlags.RETARDING

    def __init__(self, n, exterior_n: float = 1.0):
        # the index: a number, or per point (a TexturedNumber / NumberSpectrum: a Principled IOR texture)
        self.n_int = checked_index(n)
        self.n_ext = float(exterior_n)
        self.per_point = per_point_index(self.n_int)
        if self.per_point:
            # (an instance attribute: a constant index keeps the class default, so compiled per-path loops that
            # take ``type(bsdf) is SmoothDielectric`` for a constant-index delta material can refuse this one)
            self.varies_over_surface = True

    def _n(self, sp: ShadingPoint):
        """The interior index at the points: a number, or (N,) where it varies over the surface."""
        return index_at(self.n_int, sp)

    def _sides(self, sp: ShadingPoint):
        cos_o = sp.cos_o
        outside = cos_o >= 0
        n = self._n(sp)
        eta = np.where(outside, n / self.n_ext, self.n_ext / n)
        nn = np.where(outside[None, :], sp.n_s, -sp.n_s)
        return np.abs(cos_o), eta, nn

    def eval(self, sp, wi):
        return depolarising_value(np.zeros_like(sp.lam), sp.n)

    def pdf(self, sp, wi):
        return np.zeros(sp.n)

    def delta_reflection(self, sp):
        c, eta, nn = self._sides(sp)
        wi = reflect(sp.wo, nn)
        s = plane_of_incidence_axis(nn, -wi)
        A, B, C, S = fresnel_reflection_abcs(c, eta)
        L = sp.lam.shape[0]
        tile = lambda v: np.broadcast_to(v, (L, sp.n)).copy()  # noqa: E731
        return MuellerValue("abcs", s, s, tile(A), tile(B), tile(C), tile(S))

    @staticmethod
    def _directions(sp, c, eta, nn, reflect_lobe):
        """(ω_i (3, N), its s axis, TIR (N,), 1/η (N,)) of the chosen lobes: the mirror direction, or the
        refraction of the camera ray d = −ω_o, t = d/η + (c/η − cosθ_t) n."""
        wi_r = reflect(sp.wo, nn)
        cos_t, tir = refracted_cosine(c, eta)
        inv_eta = 1.0 / eta
        wi_t = -sp.wo * inv_eta + (c * inv_eta - cos_t) * nn
        wi = np.where(reflect_lobe[None, :], wi_r, wi_t)
        return wi, plane_of_incidence_axis(nn, -wi), tir, inv_eta

    def sample(self, sp, u_lobe, u_dir) -> BSDFSample:
        c, eta, nn = self._sides(sp)
        L = sp.lam.shape[0]
        A, B, C, S = fresnel_reflection_abcs(c, eta)
        p_reflect = A  # the index is wavelength-independent, so A is the same for every λ
        reflect_lobe = u_lobe < p_reflect
        wi, s, tir, inv_eta = self._directions(sp, c, eta, nn, reflect_lobe)

        At, Bt, Ct, St = fresnel_transmission_abcs(c, eta)
        p_r = np.where(p_reflect > 0, p_reflect, 1.0)
        p_t = np.where(p_reflect < 1, 1.0 - p_reflect, 1.0)
        radiance_scale = inv_eta * inv_eta
        scale_t = radiance_scale / p_t
        pick = lambda r, t: np.where(reflect_lobe, r / p_r, t * scale_t)  # noqa: E731
        tile = lambda v: np.broadcast_to(v, (L, sp.n)).copy()  # noqa: E731
        value = MuellerValue("abcs", s, s, tile(pick(A, At)), tile(pick(B, Bt)), tile(pick(C, Ct)),
                             tile(pick(S, St)))
        valid = reflect_lobe | ~tir
        eta_sq = np.where(reflect_lobe, 1.0, eta * eta)
        return BSDFSample(wi=wi, weight=value, pdf=np.zeros(sp.n), is_delta=np.ones(sp.n, bool),
                          valid=valid, eta_sq=eta_sq)

    def scatter_delta(self, v: DeltaVertices) -> bool:
        """``sample`` + the throughput update in one step (see BSDF); not for an index per point (the vertices
        carry no surface points: ``sample`` then)."""
        if self.per_point:
            return False
        dielectric_scatter(v.rows, v.n_s, v.wo, v.x_T, v.T, v.u_lobe, self.n_int / self.n_ext, self.n_ext / self.n_int,
                           v.T_out, v.d, v.x_out, v.valid, v.eta_sq, T_cols=v.T_cols)
        return True

    def describe(self):
        return {"type": self.name, "n": repr(self.n_int) if self.per_point else self.n_int, "exterior_n": self.n_ext}

    def lobe_colors(self, sp: ShadingPoint):
        """Glossy: the mirror's M00 (R, its reflectance at the view angle, from either side; a film's where
        ``delta_reflection`` has one); transmission: 1 − R (the energy; Cycles' glass colour at roughness 0)."""
        from .glass_colors import smooth_glass_colors
        return smooth_glass_colors(sp, self.delta_reflection(sp).m00())


# --------------------------------------------------------------------------- declaration

#: The Polarising BSDF node's index input of the smooth dielectric models (glass and black glass).
IOR_SOCKET = Socket("IOR", "FLOAT", 1.5, 1.0001, 5.0, "Index of refraction of the material (outside: 1)")

DECLARATION = ModelDeclaration(
    "dielectric", "Fresnel Dielectric",
    "Smooth glass-like interface: reflection, refraction, total internal reflection",
    [Parameter("n", "real index of the material", lo=0.0, lo_open=True, socket=IOR_SOCKET),
     exterior_n_parameter()], node="DIELECTRIC")


@DECLARATION.builder
def _dielectric(p):
    return SmoothDielectric(p["n"], p["exterior_n"])
