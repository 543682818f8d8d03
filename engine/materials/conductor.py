"""Smooth conductor: a perfect Fresnel mirror with complex index η = n + iκ.

The relative index is η/n_exterior.  The Dirac lobe reflects wo about the
shading normal with the Fresnel Mueller matrix M_F(cosθ) of docs/physics.md §0 in
the plane-of-incidence frames x = s = unit(n × k) (shared by both beams).
One-sided: zero when wo lies behind the shading normal.

A thin film on the mirror (``film_n``, ``film_thickness`` in nm; none at ≤ 0.1 nm, Cycles' cutoff — Blender's
Metallic BSDF and Principled Thin Film): Airy's sum over the film on the complex index n + iκ replaces M_F
(engine.polarisation.thin_film.film_reflection_abcs, per wavelength): interference colours and an s–p phase
difference of the film's own (RETARDING, WAVELENGTH_DEPENDENT).
"""

from __future__ import annotations

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, DeltaVertices, MuellerValue, ShadingPoint, depolarising_value
from ..kernels import twin
from ..kernels.delta_bounce import constant_mirror_loop, tabulated_mirror_loop
from ..kernels.geometry import unit_cross_numpy
from ..kernels.tables import complex_index_table
from ..kernels.transport import update_abcs_numpy
from ..polarisation.frames import plane_of_incidence_axis
from ..polarisation.fresnel import fresnel_reflection_abcs, fresnel_reflection_abcs_numpy, tabulated_mirror_abcs, \
    tabulated_mirror_abcs_numpy
from ..polarisation.thin_film import facet_film, film_at, film_label, film_reflection_abcs
from ..spectral import LAMBDA_MAX, LAMBDA_MIN, ConstantSpectrum
from .parameters import REQUIRED, ModelDeclaration, Parameter, Socket, exterior_n_parameter
from ..errors import SceneError
from ..spectral.ior import NAMED_METALS
from ..spectral.spectrum import TabulatedSpectrum
from ..textures import textured
from ..vec3 import reflect


def mirror_reflection(sp: ShadingPoint, eta: np.ndarray, film: tuple[float, float] | None = None,
                      exterior_n: float = 1.0):
    """(wi, MuellerValue, valid) of a smooth-interface mirror reflection of wo.

    ``eta`` is the relative complex index (L, N) seen from the wo side.  ``film`` = (index, thickness nm)
    (engine.polarisation.thin_film.facet_film) or None: a thin film on the interface, between the medium
    ``exterior_n`` and the substrate eta·exterior_n (Airy's sum at the path's wavelengths replaces M_F).
    """
    cos_o = sp.cos_o
    valid = cos_o >= 0  # cosθ = 0 is the grazing limit M_F → identity, not "behind"
    wi = reflect(sp.wo, sp.n_s)
    s = plane_of_incidence_axis(sp.n_s, -wi)
    c = np.maximum(cos_o, 0.0)[None, :]
    if film is None:
        A, B, C, S = fresnel_reflection_abcs(c, eta)
    else:
        A, B, C, S = film_reflection_abcs(c, exterior_n, film[0], film[1], eta * exterior_n, sp.lam)
    m = valid.astype(np.float64)[None, :]
    return wi, MuellerValue("abcs", s, s, A * m, B * m, C * m, S * m), valid


# ----------------------------------------------------------------------------- one step per delta vertex

def _mirror_numpy(rows, n_s, wo):
    """(wo, cosθ_o, mirror direction, plane-of-incidence axis s) of the paths ``rows`` (NumPy)."""
    n_s, wo = n_s[:, rows], wo[:, rows]
    cos_o = n_s[0] * wo[0] + n_s[1] * wo[1] + n_s[2] * wo[2]
    wi = reflect(wo, n_s)
    return wo, cos_o, wi, unit_cross_numpy(n_s, -wi, 1e-12)


def _store_mirror(rows, x_T, T, wo, wi, s, abcs, cos_o, T_out, d, x_out, valid, eta_sq, T_cols):
    update_abcs_numpy(T_out, T, rows, s, x_T[:, rows], wo, *abcs, None, T_cols)
    d[:, rows] = wi
    x_out[:, rows] = s
    valid[rows] = cos_o >= 0
    eta_sq[rows] = 1.0


def constant_mirror_scatter_numpy(rows, n_s, wo, x_T, T, eta, T_out, d, x_out, valid, eta_sq, T_cols=None):
    """The Fresnel mirror of one complex relative index ``eta`` at the paths ``rows`` (engine.kernels.
    delta_bounce: T_out, d, x_out, valid, eta_sq written there; their throughputs in the columns
    ``T_cols`` of T, None: ``rows``): mirror_reflection + update_abcs."""
    wo, cos_o, wi, s = _mirror_numpy(rows, n_s, wo)
    m = (cos_o >= 0).astype(np.float64)[None, :]
    abcs = fresnel_reflection_abcs_numpy(np.maximum(cos_o, 0.0)[None, :], np.full((1, 1), eta, np.complex128))
    _store_mirror(rows, x_T, T, wo, wi, s, [v * m for v in abcs], cos_o, T_out, d, x_out, valid, eta_sq, T_cols)


def constant_mirror_scatter_numba(rows, n_s, wo, x_T, T, eta, T_out, d, x_out, valid, eta_sq, T_cols=None):
    constant_mirror_loop(rows, n_s, wo, x_T, T, eta, T_out, d, x_out, valid, eta_sq, rows if T_cols is None else T_cols)


constant_mirror_scatter = twin(constant_mirror_loop and constant_mirror_scatter_numba, constant_mirror_scatter_numpy)


def tabulated_mirror_scatter_numpy(rows, n_s, wo, x_T, T, lam, wl_n, n, wl_k, k, exterior_n, T_out, d, x_out, valid,
                                   eta_sq, T_cols=None):
    """The Fresnel mirror of a measured metal at the paths ``rows`` (index from the tables at ``lam``);
    False, writing nothing, where some wavelength lies outside a table."""
    wo_r, cos_o, wi, s = _mirror_numpy(rows, n_s, wo)
    abcs, inside = tabulated_mirror_abcs_numpy(cos_o, lam[:, rows], wl_n, n, wl_k, k, exterior_n)
    if not inside:
        return False
    _store_mirror(rows, x_T, T, wo_r, wi, s, abcs, cos_o, T_out, d, x_out, valid, eta_sq, T_cols)
    return True


def tabulated_mirror_scatter_numba(rows, n_s, wo, x_T, T, lam, wl_n, n, wl_k, k, exterior_n, T_out, d, x_out, valid,
                                   eta_sq, T_cols=None):
    # times 1/e: NumPy's complex division by e + 0i (engine.kernels.tables.relative_index_at)
    return bool(tabulated_mirror_loop(rows, n_s, wo, x_T, T, lam, wl_n, n, wl_k, k, 1.0 / float(exterior_n), T_out,
                                      d, x_out, valid, eta_sq, rows if T_cols is None else T_cols))


tabulated_mirror_scatter = twin(tabulated_mirror_loop and tabulated_mirror_scatter_numba,
                                tabulated_mirror_scatter_numpy)


class SmoothConductor(BSDF):
    name = "conductor"

    def __init__(self, n, k, exterior_n=1.0, film_n: float | None = None, film_thickness: float = 0.0):
        self.n = n
        self.k = k
        self.exterior_n = float(exterior_n)
        # a thin film on the mirror (module docstring): (index, thickness nm) or None (none, or ≤ 0.1 nm)
        self.film = facet_film(film_n, film_thickness)
        self.varies_over_surface = textured(n, k, *(self.film if self.film is not None else ()))
        self._tables = type(n) is TabulatedSpectrum and type(k) is TabulatedSpectrum
        if self._tables:
            self._table_arrays = tuple(np.ascontiguousarray(a, dtype=np.float64)
                                       for a in (n.wavelengths, n.values, k.wavelengths, k.values))
        # one index at every wavelength and point: computed once, as relative_eta does per point
        self._eta = None
        if type(n) is ConstantSpectrum and type(k) is ConstantSpectrum:
            one = np.ones((1, 1))
            self._eta = complex(((n.value * one + 1j * (k.value * one)) / self.exterior_n)[0, 0])
        constant = bool(getattr(n, "is_constant", False) and getattr(k, "is_constant", False))
        # A real index (κ = 0 at every wavelength) reflects without retardance, unless it is below the
        # exterior index somewhere: then total internal reflection retards (S ≠ 0).  A textured n may
        # (its spectral upsampling is not bounded by the texels' range), so it counts as retarding.
        real = getattr(k, "is_constant", False) and float(k.eval([550.0])[0]) == 0.0
        no_tir = real and not textured(n) and \
            float(np.min(n.eval(np.linspace(LAMBDA_MIN, LAMBDA_MAX, 95)))) >= self.exterior_n
        filmed = self.film is not None           # the film's s–p phase difference and interference colours
        self.flags = (BSDFFlags.DELTA_REFLECTION | BSDFFlags.POLARISING
                      | BSDFFlags.when(filmed or not no_tir, BSDFFlags.RETARDING)
                      | BSDFFlags.when(filmed or not constant, BSDFFlags.WAVELENGTH_DEPENDENT))

    def relative_eta(self, sp: ShadingPoint) -> np.ndarray:
        if self._tables and not sp.mono:
            # measured tables: both interpolations and the complex index in one pass (same numbers)
            eta, inside = complex_index_table(sp.lam, self.n.wavelengths, self.n.values, self.k.wavelengths,
                                              self.k.values, self.exterior_n)
            if inside:
                return eta
        return (sp.spectrum(self.n) + 1j * sp.spectrum(self.k)) / self.exterior_n

    def mirror(self, sp: ShadingPoint):
        """(wi, MuellerValue, valid) of the mirror reflection of wo (mirror_reflection's result)."""
        if self.film is not None:
            return mirror_reflection(sp, self.relative_eta(sp), film_at(self.film, sp), self.exterior_n)
        if self._tables and not sp.mono:
            # measured tables: interpolation, complex index and Fresnel in one pass (same numbers)
            abcs, inside = tabulated_mirror_abcs(sp.cos_o, sp.lam, self.n.wavelengths, self.n.values,
                                                 self.k.wavelengths, self.k.values, self.exterior_n)
            if inside:
                wi = reflect(sp.wo, sp.n_s)
                s = plane_of_incidence_axis(sp.n_s, -wi)
                return wi, MuellerValue("abcs", s, s, *abcs), sp.cos_o >= 0
        return mirror_reflection(sp, self.relative_eta(sp))

    def eval(self, sp, wi):
        return depolarising_value(np.zeros_like(sp.lam), sp.n)

    def pdf(self, sp, wi):
        return np.zeros(sp.n)

    def delta_reflection(self, sp):
        return self.mirror(sp)[1]

    def sample(self, sp, u_lobe, u_dir) -> BSDFSample:
        wi, value, valid = self.mirror(sp)
        return BSDFSample(wi=wi, weight=value, pdf=np.zeros(sp.n), is_delta=np.ones(sp.n, bool),
                          valid=valid, eta_sq=np.ones(sp.n))

    def scatter_delta(self, v: DeltaVertices) -> bool:
        """``sample`` + the throughput update in one step (constant or measured index; see BSDF)."""
        if self.film is not None:
            return False        # no fused step: the film's reflectance depends on the wavelength
        out = (v.T_out, v.d, v.x_out, v.valid, v.eta_sq)
        if self._eta is not None:
            constant_mirror_scatter(v.rows, v.n_s, v.wo, v.x_T, v.T, self._eta, *out, T_cols=v.T_cols)
            return True
        if self._tables and not v.mono:
            return tabulated_mirror_scatter(v.rows, v.n_s, v.wo, v.x_T, v.T, v.lam, *self._table_arrays,
                                            self.exterior_n, *out, T_cols=v.T_cols)
        return False

    def describe(self):
        out = {"type": self.name, "n": repr(self.n), "k": repr(self.k), "exterior_n": self.exterior_n}
        if self.film is not None:
            out["thin_film"] = film_label(self.film)
        return out


# --------------------------------------------------------------------------- declaration

#: The complex index η = n + iκ of a conductor-like surface (shared with Torrance–Sparrow and HTSG,
#: which give their own node sockets); spectra, or a measured metal by name instead of both.
N = Parameter("n", "real part of the complex index (or give metal)", kind="spectrum", lo=0.0, lo_open=True,
              default=REQUIRED, texturable=True,
              socket=Socket("n", "FLOAT", 0.47, 0.01, 20.0, "Real part of the complex index of refraction"))
K = Parameter("k", "imaginary part κ of the complex index", kind="spectrum", lo=0.0, default=0.0, texturable=True,
              socket=Socket("k", "FLOAT", 2.4, 0.0, 50.0,
                            "Extinction coefficient κ ≥ 0 (imaginary part of the index)"))
METAL = Parameter("metal", f"measured metal ({' | '.join(NAMED_METALS)}) instead of n and k", kind="metal",
                  default=None)
#: A thin film on a conductor-like surface (shared with Torrance–Sparrow, which words its own doc): thickness in
#: nm (none at ≤ 0.1 nm, engine.polarisation.thin_film.FILM_CUTOFF_NM) and the film's real index.
THIN_FILM_THICKNESS = Parameter("thin_film_thickness", "a thin film on the mirror (0: none; Airy's sum over the "
                                                       "film on the metal replaces its Fresnel matrix)", unit="nm",
                                lo=0.0, hi=1e6, default=0.0, texturable=True)
THIN_FILM_IOR = Parameter("thin_film_ior", "the thin film's index", lo=0.0, lo_open=True, default=1.33,
                          texturable=True)


def complex_index(p):
    """(n, κ) spectra from ``metal`` or from ``n`` and ``k`` (not both)."""
    if p.given("metal"):
        if p.given("n") or p.given("k"):
            raise SceneError(p.field("metal"), "give either 'metal' or 'n' and 'k', not both")
        return p["metal"]
    return p["n"], p["k"]


DECLARATION = ModelDeclaration(
    "conductor", "Fresnel Conductor", "Smooth metal mirror with a complex index n + iκ",
    [N, K, METAL, THIN_FILM_THICKNESS, THIN_FILM_IOR, exterior_n_parameter()], catalogue="fresnel",
    node="CONDUCTOR")


DECLARATION.per_point = frozenset({"n", "k", "thin_film_thickness", "thin_film_ior"})


@DECLARATION.builder
def _conductor(p):
    film_n = p["thin_film_ior"]          # read (validated) whether or not a film is there
    return SmoothConductor(*complex_index(p), p["exterior_n"], film_n=film_n,
                           film_thickness=p["thin_film_thickness"])
