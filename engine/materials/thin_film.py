"""A smooth dielectric interface coated with a thin non-absorbing film: soap films, anti-reflection and
iridescent coatings (Blender's Principled Thin Film on a transmissive surface).

The film lies on the front side of the shading normal, between the exterior (``exterior_n``) and the
material (``n``); its index ``film_n`` and thickness ``thickness`` (nm) make the reflection
wavelength-dependent (interference colours) and give it an s–p phase difference, so that reflected light
becomes elliptically polarised (engine.polarisation.thin_film: Airy's sum; transmission T = 1 − R, its
retardance neglected).  Seen from inside, the same film is met from the substrate's side.  Directions,
radiance scaling and total internal reflection are those of the bare dielectric
(engine.materials.dielectric); the lobe is chosen with the wavelength-mean reflectance and each
wavelength's weight divided by that probability (exact per wavelength).  Thickness 0 is the bare
interface.
"""

from __future__ import annotations

import numpy as np

from .base import BSDFFlags, BSDFSample, DeltaVertices, MuellerValue
from .dielectric import IOR_SOCKET, SmoothDielectric, one_side_of
from .parameters import ModelDeclaration, Parameter, exterior_n_parameter
from ..polarisation.frames import plane_of_incidence_axis
from ..polarisation.thin_film import film_reflection_abcs, film_transmission_abcs
from ..textures import TexturedNumber
from ..vec3 import reflect


class ThinFilmDielectric(SmoothDielectric):
    """Smooth dielectric (index n, exterior exterior_n) under a film of index film_n, thickness d nm."""

    name = "thin_film"
    flags = SmoothDielectric.flags | BSDFFlags.WAVELENGTH_DEPENDENT

    def __init__(self, n: float, film_n: float, thickness, exterior_n: float = 1.0):
        super().__init__(n, exterior_n)
        # the film's index and thickness: numbers, or TexturedNumbers (per point: Blender's Thin Film inputs linked)
        self.film_n = film_n if isinstance(film_n, TexturedNumber) else float(film_n)
        self.thickness = thickness if isinstance(thickness, TexturedNumber) else float(thickness)
        for name, v, strict in (("film_n", self.film_n, True), ("thickness", self.thickness, False)):
            lo, hi = (v.lo, v.hi) if isinstance(v, TexturedNumber) else (v, v)
            if not (np.isfinite(lo) and np.isfinite(hi) and (lo > 0 if strict else lo >= 0)):
                raise ValueError(f"{name} must be a finite number {'> 0' if strict else '>= 0'}, got {v!r}")
        self.varies_over_surface = self.per_point or isinstance(self.film_n, TexturedNumber) or \
            isinstance(self.thickness, TexturedNumber)

    def _film(self, sp, c):
        """(A, B, C, S) (L, N) of the coated interface's reflection at incidence cosines c (N,)."""
        outside = sp.cos_o >= 0
        n = self._n(sp)             # (an index per point: (N,))
        n1 = np.where(outside, self.n_ext, n)[None, :]
        n3 = np.where(outside, n, self.n_ext)[None, :]
        return film_reflection_abcs(c[None, :], n1, sp.number(self.film_n), sp.number(self.thickness), n3, sp.lam)

    def delta_reflection(self, sp):
        c, _, nn = self._sides(sp)
        wi = reflect(sp.wo, nn)
        s = plane_of_incidence_axis(nn, -wi)
        A, B, C, S = self._film(sp, c)
        return MuellerValue("abcs", s, s, A, B, C, S)

    def sample(self, sp, u_lobe, u_dir) -> BSDFSample:
        c, eta, nn = self._sides(sp)
        A, B, C, S = self._film(sp, c)
        R_s, R_p = A + B, A - B
        p_reflect = A.mean(axis=0)
        reflect_lobe = u_lobe < p_reflect
        wi, s, tir, inv_eta = self._directions(sp, c, eta, nn, reflect_lobe)
        At, Bt, Ct, St = film_transmission_abcs(R_s, R_p)
        p_r = np.where(p_reflect > 0, p_reflect, 1.0)[None, :]
        p_t = np.where(p_reflect < 1, 1.0 - p_reflect, 1.0)[None, :]
        scale_t = (inv_eta * inv_eta)[None, :] / p_t
        pick = lambda r, t: np.where(reflect_lobe[None, :], r / p_r, t * scale_t)  # noqa: E731
        value = MuellerValue("abcs", s, s, pick(A, At), pick(B, Bt), pick(C, Ct), pick(S, St))
        valid = reflect_lobe | ~tir
        eta_sq = np.where(reflect_lobe, 1.0, eta * eta)
        return BSDFSample(wi=wi, weight=value, pdf=np.zeros(sp.n), is_delta=np.ones(sp.n, bool),
                          valid=valid, eta_sq=eta_sq)

    def scatter_delta(self, v: DeltaVertices) -> bool:
        return False            # no fused step: the film's reflectance depends on the wavelength

    def describe(self):
        thickness, film_n = (repr(v) if isinstance(v, TexturedNumber) else v for v in (self.thickness, self.film_n))
        return {"type": self.name, "n": repr(self.n_int) if self.per_point else self.n_int, "film_n": film_n,
                "thickness_nm": thickness,
                "exterior_n": self.n_ext}


DECLARATION = ModelDeclaration(
    "thin_film", "Thin-Film Dielectric",
    "Smooth dielectric under a thin non-absorbing film (soap films, coatings): interference colours and "
    "elliptical polarisation of the reflection",
    [Parameter("n", "real index of the material under the film", lo=0.0, lo_open=True, socket=IOR_SOCKET,
               texturable=True),
     Parameter("film_n", "real index of the film", lo=0.0, lo_open=True, default=1.33, texturable=True),
     Parameter("thickness", "film thickness", unit="nm", lo=0.0, hi=1e6, default=500.0, texturable=True),
     exterior_n_parameter()])

#: the film and the index under it may vary over the surface (Blender's Glass BSDF Thin Film and IOR inputs from a
#: texture, as the Principled's)
DECLARATION.per_point = frozenset({"film_n", "thickness", "n"})


@DECLARATION.builder
def _thin_film(p):
    n = one_side_of(p, "n", p["exterior_n"])
    if p["thickness"] == 0:
        return SmoothDielectric(n, p["exterior_n"])
    return ThinFilmDielectric(n, p["film_n"], p["thickness"], p["exterior_n"])
