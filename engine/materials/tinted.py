"""A material whose reflected and transmitted light are tinted: Cycles' Glass BSDF Color and the
Principled BSDF's transmission tint.

Cycles tints a glass closure's light by a colour at every scattering event — the Glass BSDF's Color
multiplies reflection and refraction alike, the Principled BSDF's Transmission multiplies each
refraction by √(Base Color) (reflections untinted): a tint at each crossing of the surface, not an
absorption along the path (that is a volume: engine.scene interiors).  :class:`Tinted` wraps any
model and multiplies its Mueller value by the reflection tint ρ_r(λ) where ω_i and ω_o lie on the
same side of the geometric surface and by the transmission tint ρ_t(λ) where they lie on opposite
sides.  A scalar per wavelength scales the whole Mueller matrix, so the polarisation the model
predicts is unchanged and realisability is kept (ρ ≥ 0).  Sampling is the wrapped model's; the
sample weight and ``eval`` carry the tint, ``pdf`` does not.  The tints are spectra (reflectances in
[0, 1], constant or varying over the surface: engine.textures); None is 1.
"""

from __future__ import annotations

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, LobeColors, MuellerValue, ShadingPoint
from ..kernels import twin
from ..kernels.f82 import f82_ratio_loop
from ..spectral import Spectrum
from ..textures import TexturedNumber, TexturedSpectrum
from ..vec3 import dot

__all__ = ["CoatTinted", "F82Reflectance", "FresnelTinted", "Tinted"]


def _grey(spec) -> bool:
    return spec is None or (not isinstance(spec, TexturedSpectrum) and spec.is_grey)


class _ScaledLobes(BSDF):
    """A wrapper whose Mueller values are ``base``'s times a scalar per wavelength, ``_factor(sp, wi)`` (L, N) or
    a number: sampling, pdf, shading point and refraction are the base's; only the value is scaled."""

    base: BSDF

    def shading_point(self, sp: ShadingPoint) -> ShadingPoint:
        return self.base.shading_point(sp)

    def _factor(self, sp: ShadingPoint, wi: np.ndarray):
        raise NotImplementedError

    def eval(self, sp: ShadingPoint, wi: np.ndarray) -> MuellerValue:
        return self.base.eval(sp, wi).times(self._factor(sp, wi))

    def refraction_eta_sq(self, sp: ShadingPoint) -> np.ndarray | None:
        return self.base.refraction_eta_sq(sp)

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        return self.base.pdf(sp, wi)

    def eval_and_pdf(self, sp: ShadingPoint, wi: np.ndarray) -> tuple[MuellerValue, np.ndarray]:
        """(``eval``, ``pdf``) through the base's eval_and_pdf (one pass where it has one)."""
        cls = type(self)
        if cls.eval is not _ScaledLobes.eval or cls.pdf is not _ScaledLobes.pdf:
            return super().eval_and_pdf(sp, wi)
        f, pdf = self.base.eval_and_pdf(sp, wi)
        return f.times(self._factor(sp, wi)), pdf

    def sample(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        bs = self.base.sample(sp, u_lobe, u_dir)
        return BSDFSample(bs.wi, bs.weight.scaled(self._factor(sp, bs.wi)), bs.pdf, bs.is_delta, bs.valid, bs.eta_sq)

    def sample_direction(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        bs = self.base.sample_direction(sp, u_lobe, u_dir)
        if bs.weight is None or not (bs.is_delta & bs.valid).any():
            return BSDFSample(bs.wi, None, bs.pdf, bs.is_delta, bs.valid, bs.eta_sq)
        return BSDFSample(bs.wi, bs.weight.scaled(self._factor(sp, bs.wi)), bs.pdf, bs.is_delta, bs.valid, bs.eta_sq)


class Tinted(_ScaledLobes):
    """``base`` with its reflected light × ``reflection`` and its transmitted light × ``transmission``."""

    def __init__(self, base: BSDF, reflection: Spectrum | None = None, transmission: Spectrum | None = None):
        self.base, self.reflection, self.transmission = base, reflection, transmission
        self.name = base.name
        flags = base.flags
        if not (_grey(reflection) and _grey(transmission)):
            flags = flags | BSDFFlags.WAVELENGTH_DEPENDENT
        self.flags = flags
        self.varies_over_surface = base.varies_over_surface or any(
            isinstance(s, TexturedSpectrum) for s in (reflection, transmission))

    @property
    def exterior_n(self):
        return getattr(self.base, "exterior_n", None)

    def _tint(self, sp: ShadingPoint, spec) -> np.ndarray | float:
        return 1.0 if spec is None else sp.spectrum(spec)

    def _factor(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray | float:
        """(L, N) tint of the pairs (ω_i, ω_o): transmission where they lie on opposite sides of n_g."""
        if self.reflection is None and self.transmission is None:
            return 1.0
        through = dot(wi, sp.n_g) * dot(sp.wo, sp.n_g) < 0
        r, t = self._tint(sp, self.reflection), self._tint(sp, self.transmission)
        return np.where(through[None, :], t, r) * np.ones(sp.lam.shape)

    def delta_reflection(self, sp: ShadingPoint) -> MuellerValue | None:
        value = self.base.delta_reflection(sp)
        if value is None or self.reflection is None:
            return value
        return value.scaled(self._tint(sp, self.reflection))

    def lobe_colors(self, sp: ShadingPoint) -> LobeColors | None:
        """The base's, reflected lobes × the reflection tint, the transmission × the transmission tint."""
        colors = self.base.lobe_colors(sp)
        return None if colors is None else colors.tinted(self._tint(sp, self.reflection),
                                                          self._tint(sp, self.transmission))

    def describe(self) -> dict[str, object]:
        out = dict(self.base.describe())
        if self.reflection is not None:
            out["reflection_tint"] = repr(self.reflection)
        if self.transmission is not None:
            out["transmission_tint"] = repr(self.transmission)
        return out


class FresnelTinted(_ScaledLobes):
    """A dielectric reflection layer with Cycles' Specular Tint: Cycles' generalized Schlick Fresnel with
    F0 × tint, F(θ) = F_real(θ) + F0(tint − 1)(1 − F_real(θ))/(1 − F0) (F_real the dielectric's own
    reflectance at the facet angle, F0 = F_real(0°)), rendered as the polarising layer ``base`` (a
    dielectric Torrance–Sparrow or mirror of real index ``n``) times F/F_real per wavelength — the tint
    changes how much is reflected, not the polarisation of what is (a scalar per wavelength: realisable
    wherever F ≥ 0).  The facet angle is that of the half vector of (ω_i, ω_o).  On a glass (a base that
    transmits: Principled's transmission) the refraction carries Cycles' transmittance 1 − F too,
    × (1 − F_t)/(1 − F_real) (``_glass_factor``)."""

    def __init__(self, base: BSDF, n, tint: Spectrum):
        # the index: a number, or per point (a NumberSpectrum: a per-point IOR or Specular IOR Level of the
        # Principled dielectric, a per-point IOR of its glass)
        self.per_point = isinstance(n, TexturedSpectrum)
        self.base, self.n, self.tint = base, n if self.per_point else float(n), tint
        self.name = base.name
        self.f0 = None if self.per_point else ((self.n - 1.0) / (self.n + 1.0)) ** 2
        self.flags = base.flags | (BSDFFlags.NONE if _grey(tint) else BSDFFlags.WAVELENGTH_DEPENDENT)
        self.varies_over_surface = base.varies_over_surface or isinstance(tint, TexturedSpectrum) or self.per_point

    @property
    def multiscatter(self):
        return getattr(self.base, "multiscatter", False)

    def _fresnel_factor(self, sp: ShadingPoint, cos_facet: np.ndarray) -> np.ndarray:
        from ..polarisation.fresnel import fresnel_reflectance
        if self.per_point:                  # the same per point: n (N,) real, F0 < 1
            n = self.n.numbers(sp.surface_points())
            F = fresnel_reflectance(np.clip(cos_facet, 0.0, 1.0), n.astype(np.complex128))
            f0 = ((n - 1.0) / (n + 1.0)) ** 2
            t = sp.spectrum(self.tint)
            tinted = F[None, :] + f0[None, :] * (t - 1.0) * (1.0 - F[None, :]) / (1.0 - f0[None, :])
            return np.where(F[None, :] > 0, np.maximum(tinted, 0.0) / np.where(F > 0, F, 1.0)[None, :], 1.0)
        F = fresnel_reflectance(np.clip(cos_facet, 0.0, 1.0), complex(self.n))
        t = sp.spectrum(self.tint)
        if self.f0 >= 1.0:
            return np.ones(sp.lam.shape)
        tinted = F[None, :] + self.f0 * (t - 1.0) * (1.0 - F[None, :]) / (1.0 - self.f0)
        return np.where(F[None, :] > 0, np.maximum(tinted, 0.0) / np.where(F > 0, F, 1.0)[None, :], 1.0)

    def _factor(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        if not self.flags.transmits:
            h = wi + sp.wo      # the facet angle: cosθ_h = |ω_i + ω_o| / 2
            return self._fresnel_factor(sp, 0.5 * np.sqrt(dot(h, h)))
        return self._glass_factor(sp, wi)

    def _glass_factor(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        """A glass (base transmits): reflection × F_t/F and refraction × (1 − F_t)/(1 − F), Cycles' generalized
        Schlick for its Principled transmission (transmittance 1 − F_t), F the glass's own reflectance seen from
        the viewer's side at the facet angle — of the half vector (reflection) or of Walter's refraction half
        vector −(n_i ω_i + n_o ω_o) (refraction); F = 1 (total internal reflection) changes nothing."""
        from ..polarisation.fresnel import fresnel_reflectance
        if self.per_point:
            return self._glass_factor_per_point(sp, wi)
        outside = sp.cos_o >= 0
        n_o = np.where(outside, 1.0, self.n)            # the viewer's medium, the other one
        n_i = np.where(outside, self.n, 1.0)
        through = dot(wi, sp.n_g) * dot(sp.wo, sp.n_g) < 0
        h = np.where(through[None, :], -(n_i[None, :] * wi + n_o[None, :] * sp.wo), wi + sp.wo)
        length = np.sqrt(dot(h, h))
        cos_f = np.abs(dot(sp.wo, h)) / np.where(length > 0, length, 1.0)
        F = np.stack([fresnel_reflectance(np.clip(cos_f, 0.0, 1.0)[None, :], complex(e))[0]
                      for e in (self.n, 1.0 / self.n)])[np.where(outside, 0, 1), np.arange(sp.n)]
        t = sp.spectrum(self.tint) * np.ones(sp.lam.shape)
        if self.f0 >= 1.0:
            return np.ones(sp.lam.shape)
        F_t = np.clip(F[None, :] + self.f0 * (t - 1.0) * (1.0 - F[None, :]) / (1.0 - self.f0), 0.0, 1.0)
        refl = np.where(F[None, :] > 0, F_t / np.where(F > 0, F, 1.0)[None, :], 1.0)
        trans = np.where(F[None, :] < 1, (1.0 - F_t) / np.where(F < 1, 1.0 - F, 1.0)[None, :], 1.0)
        return np.where(through[None, :], trans, refl)

    def _glass_factor_per_point(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        """``_glass_factor`` with the glass's index n (N,) per point: the same arithmetic at each point's own n."""
        from ..polarisation.fresnel import fresnel_reflectance
        n = self.n.numbers(sp.surface_points())
        outside = sp.cos_o >= 0
        n_o = np.where(outside, 1.0, n)
        n_i = np.where(outside, n, 1.0)
        through = dot(wi, sp.n_g) * dot(sp.wo, sp.n_g) < 0
        h = np.where(through[None, :], -(n_i[None, :] * wi + n_o[None, :] * sp.wo), wi + sp.wo)
        length = np.sqrt(dot(h, h))
        cos_f = np.abs(dot(sp.wo, h)) / np.where(length > 0, length, 1.0)
        F = fresnel_reflectance(np.clip(cos_f, 0.0, 1.0), np.where(outside, n, 1.0 / n).astype(np.complex128))
        f0 = (((n - 1.0) / (n + 1.0)) ** 2)[None, :]
        t = sp.spectrum(self.tint) * np.ones(sp.lam.shape)
        F_t = np.clip(F[None, :] + f0 * (t - 1.0) * (1.0 - F[None, :]) / (1.0 - f0), 0.0, 1.0)
        refl = np.where(F[None, :] > 0, F_t / np.where(F > 0, F, 1.0)[None, :], 1.0)
        trans = np.where(F[None, :] < 1, (1.0 - F_t) / np.where(F < 1, 1.0 - F, 1.0)[None, :], 1.0)
        return np.where(through[None, :], trans, refl)

    def delta_reflection(self, sp: ShadingPoint) -> MuellerValue | None:
        value = self.base.delta_reflection(sp)
        if value is None:
            return None
        if self.flags.transmits:
            return value.scaled(self._glass_factor(sp, 2.0 * sp.cos_o[None, :] * sp.n_s - sp.wo))
        return value.scaled(self._fresnel_factor(sp, np.abs(sp.cos_o)))

    def describe(self) -> dict[str, object]:
        return {**self.base.describe(), "specular_tint": repr(self.tint)}


class CoatTinted(_ScaledLobes):
    """Everything below a Principled coat seen through the coat's tint, as Cycles approximates it (kernel/svm/
    closure.h, Coat Tint): the tint t is the coat's transmittance at normal incidence for a coat of thickness
    1, so along the view direction refracted into the coat (index n, cosθ_t = √(1 − (1 − cos²θ_o)/n²)) the light
    is × t^(1/cosθ_t), blended by the coat weight w: factor = 1 + w·(t^(1/cosθ_t) − 1) per wavelength, (L, N).
    Cycles' approximation: the path length of the view direction only, once (not the light's way in), on every
    lobe below (reflection and transmission alike).  A scalar per wavelength ≥ 0: polarisation unchanged,
    realisability kept.  θ_o is taken from the lobe's own shading normal (the coat's where no map differs)."""

    def __init__(self, base: BSDF, tint: Spectrum, n, weight: float):
        # the coat's index: a number, or per point (a NumberSpectrum: engine.textures.inputs)
        self.base, self.tint, self.n = base, tint, n if isinstance(n, TexturedSpectrum) else float(n)
        self.weight = weight if isinstance(weight, TexturedNumber) else float(weight)     # per point or constant
        self.name = base.name
        self.flags = base.flags | (BSDFFlags.NONE if _grey(tint) else BSDFFlags.WAVELENGTH_DEPENDENT)
        self.varies_over_surface = base.varies_over_surface or isinstance(tint, TexturedSpectrum) or \
            isinstance(weight, TexturedNumber) or isinstance(n, TexturedSpectrum)
        self.two_sided = base.two_sided

    def with_base(self, base: BSDF) -> CoatTinted:
        """The same tint over another base (engine.materials.mix.map_normals maps the base lobe by lobe)."""
        return CoatTinted(base, self.tint, self.n, self.weight)

    @property
    def exterior_n(self):
        return getattr(self.base, "exterior_n", None)

    def factor(self, sp: ShadingPoint) -> np.ndarray:
        """(L, N) the tint factor at the points' view directions."""
        cos_o = np.clip(np.abs(sp.cos_o), 0.0, 1.0)
        n = self.n.numbers(sp.surface_points()) if isinstance(self.n, TexturedSpectrum) else self.n
        cos_t = np.sqrt(1.0 - (1.0 - cos_o * cos_o) / (n * n))
        t = np.maximum(sp.spectrum(self.tint), 0.0) * np.ones(sp.lam.shape)
        return 1.0 + sp.number(self.weight) * (np.power(t, (1.0 / cos_t)[None, :]) - 1.0)

    def _factor(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        return self.factor(sp)

    def lobe_colors(self, sp: ShadingPoint) -> LobeColors | None:
        """The base's, every lobe × the tint factor (Cycles' tint scales the closures' weights below the coat)."""
        colors = self.base.lobe_colors(sp)
        return None if colors is None else colors.scaled(self.factor(sp))

    def delta_reflection(self, sp: ShadingPoint) -> MuellerValue | None:
        value = self.base.delta_reflection(sp)
        return None if value is None else value.scaled(self.factor(sp))

    def describe(self) -> dict[str, object]:
        n = repr(self.n) if isinstance(self.n, TexturedSpectrum) else f"{self.n:g}"
        return {**self.base.describe(), "coat_tint": f"{self.tint!r} (coat n {n}, weight {self.weight!r})"}


#: the reflectance curves F82Reflectance follows
CURVES = ("f82_tint", "constant")
#: cosθ of the F82 model's second point (θ₈₂ = acos(1/7)) and Schlick's weight (1 − cosθ)⁵ there
_F82_SIX = 6.0 / 7.0


def f82_curve(cos_theta: np.ndarray, f0: np.ndarray, tint: np.ndarray | None) -> np.ndarray:
    """Cycles' F82-Tint reflectance (Kutz et al., "Novel aspects of the Adobe Standard Material"; Cycles'
    fresnel_f82 with fresnel_f82tint_B): F = F_Schlick(θ) − b·cosθ·(1 − cosθ)⁶, clipped to [0, 1], with b chosen
    so that F(θ₈₂) = F_Schlick(θ₈₂)·tint (b = 0 for no tint).  Arrays broadcast ((L, N) per wavelength and point)."""
    c = np.clip(cos_theta, 0.0, 1.0)
    s = 1.0 - c
    s5 = s ** 5
    schlick = f0 + (1.0 - f0) * s5
    if tint is None:
        return np.clip(schlick, 0.0, 1.0)
    f5 = _F82_SIX ** 5
    b = (f0 + (1.0 - f0) * f5) * (7.0 / (f5 * _F82_SIX)) * (1.0 - tint)
    return np.clip(schlick - b * c * s5 * s, 0.0, 1.0)


def f82_ratio_numpy(cos_facet: np.ndarray, eta: np.ndarray, f0: np.ndarray, tint: np.ndarray | None, curve: str,
                    shape: tuple) -> np.ndarray:
    """F82Reflectance's ratio F_curve(θ)/F(θ) (``shape`` (L, N)) at facet cosines (N,), for the metal's index η, its
    F0 and tint (L, N) (clipped to [0, 1] here; tint None: none) and ``curve``; 1 where F = 0."""
    from ..polarisation.fresnel import fresnel_reflectance
    cos_f = np.clip(cos_facet, 0.0, 1.0)[None, :]
    F = fresnel_reflectance(cos_f, eta) * np.ones(shape)
    f0 = np.clip(f0, 0.0, 1.0)
    tint = None if tint is None else np.clip(tint, 0.0, 1.0)
    target = (f82_curve(cos_f, f0, tint) if curve == "f82_tint" else f0) * np.ones(shape)
    return np.where(F > 0, target / np.where(F > 0, F, 1.0), 1.0)


def f82_ratio_numba(cos_facet, eta, f0, tint, curve: str, shape: tuple) -> np.ndarray:
    """f82_ratio_numpy in one compiled loop (engine.kernels.f82), the bits of the NumPy code with compiled Fresnel;
    inputs of other shapes go to the NumPy twin."""
    L, n = shape
    cos_facet = np.asarray(cos_facet, np.float64)
    eta = np.asarray(eta)
    if cos_facet.shape != (n,) or np.ndim(eta) != 2 or eta.shape[0] not in (1, L) or eta.shape[1] not in (1, n):
        return f82_ratio_numpy(cos_facet, eta, f0, tint, curve, shape)

    def spread(a, dtype):     # (L, N) read-only C arrays (one type for the loop; a read-only input is not copied)
        out = np.ascontiguousarray(np.broadcast_to(np.asarray(a, dtype), shape)).view()
        out.flags.writeable = False
        return out
    c = np.clip(cos_facet, 0.0, 1.0)
    s = 1.0 - c
    s5 = s ** 5         # (NumPy's power, as f82_curve's)
    out = np.empty(shape)
    f5 = _F82_SIX ** 5
    f82_ratio_loop(c, s, s5, spread(eta, np.complex128), spread(f0, np.float64),
                   spread(0.0 if tint is None else tint, np.float64), tint is not None, curve == "f82_tint", f5,
                   7.0 / (f5 * _F82_SIX), out)
    return out


#: F82Reflectance's ratio (f82_ratio_numpy), compiled where available.
f82_ratio = twin(f82_ratio_loop and f82_ratio_numba, f82_ratio_numpy)


class F82Reflectance(_ScaledLobes):
    """A metal lobe (a conductor Torrance–Sparrow, anisotropic GGX or mirror of complex index n + iκ) whose
    unpolarised reflectance follows Cycles' F82-Tint curve (:func:`f82_curve`; the Principled BSDF's metal): the
    Mueller value × F_F82(θ)/F(θ) per wavelength and point, F the index's own unpolarised reflectance, θ the facet
    angle (half vector of ω_i, ω_o).  The index (Gulbrandsen's, engine.spectral.gulbrandsen, through F0 and F82)
    keeps the polarisation physical — the s–p split and the retardance of a metal — while S0 is Cycles'
    (no metal reflects exactly the F82 curve, most visibly at a strong tint or a dark colour).  A scalar ≥ 0 per
    wavelength: realisable.  The energy compensation stays the lobe's own (its F_ss is the F82 model's already:
    engine.materials.ggx_energy.f82_average_fresnel).  ``curve`` "constant": F = F0 at every angle instead
    (Cycles' Glossy BSDF, whose colour is its reflectance at every angle)."""

    def __init__(self, base: BSDF, f0: Spectrum, tint: Spectrum | None, curve: str = "f82_tint",
                 index: BSDF | None = None, unless_film=None):
        if curve not in CURVES:
            raise ValueError(f"curve must be one of {CURVES}, got {curve!r}")
        self.base, self.f0, self.tint, self.curve = base, f0, tint, curve
        #: a per-point film thickness (TexturedNumber): where thicker than Cycles' cutoff the metal is filmed and
        #: reflects what its film gives (Cycles' iridescence), so the curve applies only where it is thinner
        self.unless_film = unless_film
        self.index = base if index is None else index       # the metal whose relative_eta(sp) gives n + iκ
        self.name = base.name
        self.flags = base.flags
        self.varies_over_surface = base.varies_over_surface or isinstance(f0, TexturedSpectrum) or \
            isinstance(tint, TexturedSpectrum) or unless_film is not None
        self.two_sided = base.two_sided

    def with_base(self, base: BSDF) -> F82Reflectance:
        """The same curve on another base (engine.materials.mix.map_normals)."""
        return F82Reflectance(base, self.f0, self.tint, self.curve, self.index, self.unless_film)

    @property
    def exterior_n(self):
        return getattr(self.base, "exterior_n", None)

    @property
    def multiscatter(self):
        return getattr(self.base, "multiscatter", False)

    def _ratio(self, sp: ShadingPoint, cos_facet: np.ndarray) -> np.ndarray:
        """F_F82(θ)/F(θ) (L, N) at the facet cosines (N,) (1 where F = 0; f82_ratio)."""
        f0 = sp.spectrum(self.f0)
        tint = None if self.tint is None else sp.spectrum(self.tint)
        ratio = f82_ratio(cos_facet, self.index.relative_eta(sp), f0, tint, self.curve, sp.lam.shape)
        if self.unless_film is not None:
            from ..polarisation.thin_film import FILM_CUTOFF_NM
            ratio = np.where((sp.number(self.unless_film) > FILM_CUTOFF_NM)[None, :], 1.0, ratio)
        return ratio

    def _factor(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        h = wi + sp.wo      # the facet angle: cosθ_h = |ω_i + ω_o| / 2
        return self._ratio(sp, 0.5 * np.sqrt(dot(h, h)))

    def lobe_colors(self, sp: ShadingPoint) -> LobeColors | None:
        """Glossy: the curve's albedo at the view direction — a mirror's curve at cosθ_o; a GGX lobe's (isotropic
        Torrance–Sparrow, or anisotropic at α = √(α_x α_y) as Cycles reads its tables) F0·E + (1 − F0)·E_S −
        b·E_B (engine.materials.ggx_energy.schlick_moments; the constant curve F0·E), × (1 + k) with the lobe's
        multiscatter (the compensated lobe's albedo: Cycles' estimate mix(F0, 1, s) × its darkening; Cycles
        leaves the tint's b term out of it).  None under a film, or over another base."""
        from .anisotropic_ggx import AnisotropicGGX
        from .normal_map import ShadingNormal
        if self.unless_film is not None:
            return None
        base = self.base.base if isinstance(self.base, ShadingNormal) else self.base
        mu = np.clip(sp.cos_o, 0.0, 1.0)
        f0 = np.clip(sp.spectrum(self.f0), 0.0, 1.0) * np.ones(sp.lam.shape)
        tint = None if self.tint is None else np.clip(sp.spectrum(self.tint), 0.0, 1.0)
        if base.flags.lobes == BSDFFlags.DELTA_REFLECTION and getattr(base, "film", None) is None:
            glossy = f82_curve(mu[None, :], f0, tint) if self.curve == "f82_tint" else f0
            return LobeColors.of(sp, glossy=glossy)
        if isinstance(base, AnisotropicGGX):
            alpha = np.sqrt(sp.number(base.alpha_x) * sp.number(base.alpha_y))
        elif getattr(base, "distribution", None) == "ggx" and getattr(base, "film", None) is None:
            alpha = sp.number(base.m)
        else:
            return None
        from .ggx_energy import conductor_albedo, schlick_moments
        E = conductor_albedo(mu, alpha, correlated=True)
        if self.curve == "f82_tint":
            E_S, E_B = schlick_moments(mu, alpha)
            glossy = f0 * E + (1.0 - f0) * E_S
            if tint is not None:
                f5 = _F82_SIX ** 5
                glossy = glossy - (f0 + (1.0 - f0) * f5) * (7.0 / (f5 * _F82_SIX)) * (1.0 - tint) * E_B
        else:
            glossy = f0 * E
        if getattr(base, "multiscatter", False):
            glossy = glossy * (1.0 + base.multiscatter_extra(sp))
        return LobeColors.of(sp, glossy=np.maximum(glossy, 0.0) * sp.number(getattr(base, "s", 1.0)))

    def delta_reflection(self, sp: ShadingPoint) -> MuellerValue | None:
        value = self.base.delta_reflection(sp)
        return None if value is None else value.scaled(self._ratio(sp, np.abs(sp.cos_o)))

    def describe(self) -> dict[str, object]:
        return {**self.base.describe(),
                "reflectance": f"Cycles' {self.curve} curve (F0 {self.f0!r}, tint {self.tint!r})"}
