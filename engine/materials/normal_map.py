"""Shading normals from textures: tangent-space normal maps and bump (height) maps.

:class:`ShadingNormal` wraps any material.  The integrator evaluates every material at
``bsdf.shading_point(sp)``; for this wrapper that is ``sp`` with the shading normal n_s replaced by
the mapped one, so the model's frames, its cosines and the integrator's |n_s·ω_i| all use the same
normal (polarisation frames follow it consistently).  The geometric normal n_g is left alone: it
offsets ray origins and decides on which side of the actual surface a direction lies.

- Normal map (Blender's Normal Map node, tangent space): a Non-Color RGB texel c gives
  n_t = (2c − 1) in the OpenGL convention (green +Y = +v), n_t = (2c_r − 1, 1 − 2c_g, 2c_b − 1) in
  DirectX's (green pointing down, Blender 5.1's Normal Map ▸ Convention);
  n_m = normalise(n_t.x·T + n_t.y·B + n_t.z·n_s) with the tangent frame of
  engine.textures.surface.SurfacePoints.tangent_frame; ``strength`` s ≥ 0 scales the tangent-space
  vector before it is mapped, as Cycles' Normal Map node does in tangent space (Blender 4.x/5.x,
  kernel/svm/tex_coord.h): n_t.x, n_t.y ×= s, n_t.z ← 1 + min(s, 1)·(n_t.z − 1) (s = 1: the map's
  normal; s = 0: n_s).  Where the mapped vector is the zero vector (a (0.5, 0.5, 0.5) texel) or not
  finite, n_s is kept, as Cycles does.
- Bump map (height h in scene units × ``distance``): h_u, h_v by central differences one texel
  apart; ∂p/∂u' = ∂p/∂u + d·h_u·n_s, ∂p/∂v' = ∂p/∂v + d·h_v·n_s (pbrt's bump mapping without the
  ∂n terms), n_b = normalise(∂p/∂u' × ∂p/∂v') on the side of n_s, blended by ``strength`` as above.

Light leaks, as Cycles (kernel/closure/bsdf.h, bump_shadowing_term; Blender's Material ▸ Settings ▸
Bump Map Correction, on by default, ``bump_correction``).  N is the lobe's normal after mapping, N_s the
interpolated normal before it (a MappedShadingPoint's ``n_smooth``), ω_i the direction towards the
light:
- a direction with (n_g·ω_i)(n_g·N)(N·ω_i) < 0 lies on one side of the mapped normal and on the other
  of the surface: f = 0, and such a sample is invalid (Cycles rejects it when evaluating, and when
  sampling a diffuse lobe; Polar rejects it for every lobe, so sampling and evaluation agree).  Cycles
  writes the interpolated normal N_s where Polar takes the geometric one n_g: with N_s, a glossy metal
  with a tilted normal map on a smooth UV sphere rendered face-by-face stripes and 8 of 12 blocks against
  Cycles (the directions between a face's plane and the smooth normal's horizon are lit in Cycles); with
  n_g, 12 of 12 (tests/blender/test_cycles_parity_principled.py, "Normal" on a metal);
- a diffuse lobe is softened towards its terminator by a GGX masking term G1(α², |N_s·ω_i|) with
  α² = min(1, tan²θ_d / 8), cosθ_d = |N_s·N| (Conty Estevez et al. 2019, "A microfacet-based shadowing
  function to solve the bump terminator problem");
- a specular lobe (glossy or Dirac, no diffuse one) gets Cycles' valid normal (valid_specular_normal)
  so that the mirror direction of the view stays above the surface;
- a diffuse lobe shades by N·ω_i even where the viewer is behind N (Cycles' diffuse closures never look
  at the view direction): such a lobe is evaluated with the view mirrored in N's tangent plane, which
  changes nothing for a depolarising lobe's Mueller matrix (Lambert) and little for Oren–Nayar.
Without Bump Map Correction only the first rule applies.  A composite material is mapped lobe by lobe
(engine.materials.mix.map_normals), as Cycles maps each closure of a shader.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import BSDF, BSDFFlags, BSDFSample, MuellerValue, ShadingPoint, take_lanes
from ..kernels import twin
from ..kernels.normal_map import normal_factor_numba
from ..textures import ImageTexture, TextureInput
from ..vec3 import dot, reflect


#: lobes whose mapped normal is corrected so that the mirror direction of the view stays above the surface
_SPECULAR = BSDFFlags.GLOSSY_REFLECTION | BSDFFlags.DELTA_REFLECTION | BSDFFlags.GLOSSY_TRANSMISSION | \
    BSDFFlags.DELTA_TRANSMISSION


def valid_specular_normal(n: np.ndarray, n_g: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Cycles' correction of a mapped shading normal (kernel/closure/bsdf_util.h,
    ensure_valid_specular_reflection): where the mirror direction R = 2(n·ω_o)n − ω_o of the view would
    lie below t = min(0.9·(ω_o·n_g), 0.01) above the geometric surface, n is turned towards n_g in the
    plane of n_g and n just far enough that R·n_g = t (the root of 4a z⁴ − 2b z² + c = 0 for z = n'·n_g,
    a = I_x² + I_z², b = 2(a + I_z t), c = (I_z + t)²).  Without it a steep normal map darkens glossy
    surfaces (their reflections go into the surface and are lost).  Applied where the viewer is on the
    front (ω_o·n_g > 0), to a lobe with glossy or mirror parts and no diffuse one (a composite material is
    mapped lobe by lobe: engine.materials.mix.map_normals); n, n_g, ω_o are (3, N) unit vectors."""
    iz = dot(wo, n_g)
    refl = 2.0 * dot(n, wo)[None, :] * n - wo
    t = np.minimum(0.9 * iz, 0.01)
    fix = (iz > 0) & (dot(n_g, refl) < t)
    if not fix.any():
        return n
    x = _normalise(n - dot(n, n_g)[None, :] * n_g, n)
    ix = dot(wo, x)
    a = ix * ix + iz * iz
    b = 2.0 * (a + iz * t)
    c = (t + iz) ** 2
    root = np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))
    safe_a = np.where(a > 0, a, 1.0)
    nz2 = np.where(ix < 0, 0.25 * (b + root) / safe_a, 0.25 * (b - root) / safe_a)
    nz2 = np.clip(nz2, 0.0, 1.0)
    fixed = np.sqrt(1.0 - nz2)[None, :] * x + np.sqrt(nz2)[None, :] * n_g
    return np.where(fix[None, :], _normalise(fixed, n_g), n)


def _normalise(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """``v`` (3, N) normalised; ``fallback`` (unit, 3 × N) where ``v`` is zero or not finite (as Cycles'
    normal map node keeps the unperturbed normal there: a (0.5, 0.5, 0.5) texel, or a strength that
    blends a normal with its opposite)."""
    length = np.sqrt(dot(v, v))
    ok = np.isfinite(length) & (length > 0)
    unit = v / np.where(ok, length, 1.0)[None, :]
    ok &= np.isfinite(unit).all(axis=0)
    return np.where(ok[None, :], unit, fallback)


def normal_factor_numpy(n_g: np.ndarray, n: np.ndarray, wi: np.ndarray, n_smooth: np.ndarray,
                        soften: bool) -> np.ndarray:
    """(N,) ShadingNormal's factor on its lobe's value: the leak rule (n_g·ω_i)(n_g·N)(N·ω_i) ≥ 0 as 1 or 0 and,
    with ``soften`` (a diffuse lobe with bump map correction), times ``terminator_softening(n_smooth, n, wi)``."""
    keep = (dot(n_g, wi) * dot(n_g, n) * dot(n, wi) >= 0).astype(np.float64)
    if soften:
        keep = keep * terminator_softening(n_smooth, n, wi)
    return keep


#: normal_factor_numpy, compiled where available (engine.kernels.normal_map; the same bits).
normal_factor = twin(normal_factor_numba, normal_factor_numpy)


@dataclass
class MappedShadingPoint(ShadingPoint):
    """A shading point whose ``n_s`` is a mapped normal, with the interpolated normal it was mapped from
    (``n_smooth``, (3, N), Cycles' sd->N), flipped and taken along with it."""

    n_smooth: np.ndarray | None = None

    def _with(self, base: ShadingPoint, n_smooth) -> MappedShadingPoint:
        return MappedShadingPoint(base.p, base.n_s, base.n_g, base.wo, base.lam, base.mono, base.lookup,
                                  base.material, base.surface, n_smooth)

    def take(self, sel, shared: dict | None = None) -> MappedShadingPoint:
        return self._with(super().take(sel, shared), take_lanes(self.n_smooth, sel, shared))._taken_from(self, sel)

    def flipped(self, where: np.ndarray) -> MappedShadingPoint:
        return self._with(super().flipped(where), self.n_smooth * np.where(where, -1.0, 1.0)[None, :])


def _smooth_normal(sp: ShadingPoint) -> np.ndarray:
    return sp.n_smooth if isinstance(sp, MappedShadingPoint) else sp.n_g


def terminator_softening(n_smooth: np.ndarray, n: np.ndarray, wi: np.ndarray) -> np.ndarray:
    """Cycles' bump shadowing of a diffuse lobe (N,): the GGX masking G1 = 2 / (1 + √(1 + α² tan²θ_i)) at
    cosθ_i = |N_s·ω_i| with α² = min(1, tan²θ_d / 8), cosθ_d = |N_s·N|; 1 where N = N_s or cosθ_i = 1, 0 where
    cosθ_i < 1e-6.  All inputs (3, N) unit vectors."""
    cos_i = np.abs(dot(n_smooth, wi))
    cos_d = np.abs(dot(n_smooth, n))
    with np.errstate(divide="ignore", invalid="ignore"):
        tan2_d = 1.0 / np.square(cos_d) - 1.0
        alpha2 = np.clip(0.125 * tan2_d, 0.0, 1.0)
        tan2_i = (1.0 - np.square(cos_i)) / np.square(cos_i)
        g = 2.0 / (1.0 + np.sqrt(1.0 + alpha2 * tan2_i))
    g = np.where(cos_i < 1e-6, 0.0, g)
    return np.where((cos_d >= 1.0) | (cos_i >= 1.0), 1.0, g)


class ShadingNormal(BSDF):
    """``base`` with its shading normal from a normal map and/or a bump map (see the module docstring).
    ``base`` is one lobe's material (a composite is mapped lobe by lobe: mix.map_normals)."""

    varies_over_surface = True

    #: tangent-space conventions of a normal map's green channel: +v up (OpenGL) or down (DirectX)
    CONVENTIONS = ("opengl", "directx")

    def __init__(self, base: BSDF, normal_map: TextureInput | None = None, normal_strength: float = 1.0,
                 bump_map: TextureInput | None = None, bump_distance: float = 1.0, bump_strength: float = 1.0,
                 normal_convention: str = "opengl", bump_correction: bool = True):
        if normal_map is None and bump_map is None:
            raise ValueError("ShadingNormal needs a normal map or a bump map")
        if normal_convention not in self.CONVENTIONS:
            raise ValueError(f"normal_convention must be one of {', '.join(self.CONVENTIONS)}")
        if bump_map is not None and not isinstance(bump_map.texture, ImageTexture):
            raise ValueError("a bump map must be an image texture")
        self.base = base
        self.normal_map, self.normal_strength = normal_map, float(normal_strength)
        self.normal_green_down = normal_convention == "directx"
        self.bump_map, self.bump_distance, self.bump_strength = bump_map, float(bump_distance), float(bump_strength)
        self.bump_correction = bool(bump_correction)
        self.flags = base.flags
        self.name = base.name
        F = BSDFFlags
        self._specular = base.flags.has(_SPECULAR) and not base.flags.has(F.DIFFUSE)
        self._diffuse = base.flags.has(F.DIFFUSE) and not base.flags.has(_SPECULAR | F.POLARISING)

    # --- the shading normal ----------------------------------------------------------------------

    def shading_normal(self, sp: ShadingPoint) -> np.ndarray:
        """The mapped shading normal (3, N) at the points; a normal map alone is mapped once per batch and map
        (ShadingPoint.memo: mix.map_normals gives each lobe of a material the same map)."""
        if self.bump_map is None:
            key = ("normal_map", self.normal_strength, self.normal_green_down)
            return sp.memo(self.normal_map, key, lambda: self._mapped_normal(sp))
        return self._mapped_normal(sp)

    def _mapped_normal(self, sp: ShadingPoint) -> np.ndarray:
        points = sp.surface_points()
        n = sp.n_s
        if self.bump_map is not None:
            n = self._bumped(points, n)
        if self.normal_map is not None:
            c = self.normal_map.rgb(points)
            t, b = points.tangent_frame(n)
            x, y, z = 2.0 * c[0] - 1.0, 2.0 * c[1] - 1.0, 2.0 * c[2] - 1.0
            if self.normal_green_down:
                y = -y
            s = self.normal_strength
            if s != 1.0:                # Cycles' tangent-space strength
                x, y, z = s * x, s * y, 1.0 + min(s, 1.0) * (z - 1.0)
            n = _normalise(t * x[None, :] + b * y[None, :] + n * z[None, :], n)
        return n

    def _bumped(self, points, n: np.ndarray) -> np.ndarray:
        tex = self.bump_map.texture
        uv = points.uv()
        du, dv = 1.0 / tex.width, 1.0 / tex.height

        def height(shift_u, shift_v):
            shifted = uv + np.array([[shift_u], [shift_v]])
            return self.bump_map.number_at_uv(shifted)
        h_u = (height(du, 0.0) - height(-du, 0.0)) / (2.0 * du)
        h_v = (height(0.0, dv) - height(0.0, -dv)) / (2.0 * dv)
        dpdu, dpdv, ok = points.position_derivatives()
        d = self.bump_distance
        pu = dpdu + n * (d * h_u)[None, :]
        pv = dpdv + n * (d * h_v)[None, :]
        nb = np.cross(pu.T, pv.T).T
        length = np.sqrt(dot(nb, nb))
        ok = ok & (length > 0)
        nb = np.where(ok[None, :], nb / np.where(ok, length, 1.0)[None, :], n)
        nb = np.where((dot(nb, n) < 0)[None, :], -nb, nb)
        return _normalise(n + self.bump_strength * (nb - n), n)

    def shading_point(self, sp: ShadingPoint) -> ShadingPoint:
        n = self.shading_normal(sp)
        if self._specular and self.bump_correction:
            if self.bump_map is None:       # (the same map's corrected normal for every specular lobe)
                key = ("specular normal", self.normal_strength, self.normal_green_down)
                n = sp.memo(self.normal_map, key, lambda: valid_specular_normal(n, sp.n_g, sp.wo))
            else:
                n = valid_specular_normal(n, sp.n_g, sp.wo)
        return MappedShadingPoint(sp.p, n, sp.n_g, sp.wo, sp.lam, sp.mono, sp.lookup, sp.material, sp.surface,
                                  sp.n_s)

    # --- Cycles' rules for light leaks -------------------------------------------------------------

    @staticmethod
    def geometric_agreement(sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        """(N,) False where ω_i is on one side of the mapped normal N and on the other of the actual surface:
        (n_g·ω_i)(n_g·N)(N·ω_i) < 0 (the form of Cycles' bump_shadowing_term, with the geometric normal where
        Cycles takes the interpolated one: see the module docstring)."""
        return dot(sp.n_g, wi) * dot(sp.n_g, sp.n_s) * dot(sp.n_s, wi) >= 0

    def _factor(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        """(N,) the leak rule times, for a diffuse lobe with correction, the terminator softening (normal_factor:
        one compiled pass where available)."""
        return normal_factor(sp.n_g, sp.n_s, wi, _smooth_normal(sp), self._diffuse and self.bump_correction)

    def _base_point(self, sp: ShadingPoint) -> ShadingPoint:
        """The point the base lobe sees: a diffuse lobe's view mirrored into the front of its mapped
        normal where the viewer is behind it but in front of the smooth surface (see the module docstring);
        made once per batch (ShadingPoint.memo), so that the base's own memos hold across eval, pdf, sample."""
        if not self._diffuse:
            return sp
        return sp.memo(self, "base_point", lambda: self._mirrored_view(sp))

    def _mirrored_view(self, sp: ShadingPoint) -> ShadingPoint:
        c = dot(sp.n_s, sp.wo)
        behind = (c < 0) & (dot(_smooth_normal(sp), sp.wo) > 0)
        if not behind.any():
            return sp
        wo = np.where(behind[None, :], sp.wo - 2.0 * c[None, :] * sp.n_s, sp.wo)
        return ShadingPoint(sp.p, sp.n_s, sp.n_g, wo, sp.lam, sp.mono, sp.lookup, sp.material, sp.surface)

    # --- BSDF interface (at the mapped shading point) ---------------------------------------------

    def eval(self, sp: ShadingPoint, wi: np.ndarray) -> MuellerValue:
        return self.base.eval(self._base_point(sp), wi).times(self._factor(sp, wi)[None, :])

    def refraction_eta_sq(self, sp: ShadingPoint) -> np.ndarray | None:
        return self.base.refraction_eta_sq(sp)

    def lobe_colors(self, sp: ShadingPoint):
        """The base's at its point (the mapped normal; Cycles' closures take their albedo at their own N)."""
        return self.base.lobe_colors(self._base_point(sp))

    def diffuse_share(self, sp: ShadingPoint, wi: np.ndarray, f: MuellerValue) -> np.ndarray | None:
        """The base's diffuse part (its value scaled as ``eval`` scales it)."""
        q = self._base_point(sp)
        d = self.base.diffuse_share(q, wi, self.base.eval(q, wi))
        return None if d is None else d * self._factor(sp, wi)[None, :]

    def pdf(self, sp: ShadingPoint, wi: np.ndarray) -> np.ndarray:
        return self.base.pdf(self._base_point(sp), wi)

    def eval_and_pdf(self, sp: ShadingPoint, wi: np.ndarray) -> tuple[MuellerValue, np.ndarray]:
        """(``eval``, ``pdf``) through the base's eval_and_pdf at its point (one pass where it has one)."""
        cls = type(self)
        if cls.eval is not ShadingNormal.eval or cls.pdf is not ShadingNormal.pdf:
            return super().eval_and_pdf(sp, wi)
        f, pdf = self.base.eval_and_pdf(self._base_point(sp), wi)
        return f.times(self._factor(sp, wi)[None, :]), pdf

    def sample(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        bs = self.base.sample(self._base_point(sp), u_lobe, u_dir)
        factor = self._factor(sp, bs.wi)
        keep = factor > 0
        return BSDFSample(wi=bs.wi, weight=bs.weight.scaled(factor[None, :]), pdf=np.where(keep, bs.pdf, 0.0),
                          is_delta=bs.is_delta, valid=bs.valid & keep, eta_sq=bs.eta_sq)

    def sample_direction(self, sp: ShadingPoint, u_lobe: np.ndarray, u_dir: np.ndarray) -> BSDFSample:
        bs = self.base.sample_direction(self._base_point(sp), u_lobe, u_dir)
        factor = self._factor(sp, bs.wi)
        keep = factor > 0
        return BSDFSample(wi=bs.wi, weight=None if bs.weight is None else bs.weight.scaled(factor[None, :]),
                          pdf=np.where(keep, bs.pdf, 0.0), is_delta=bs.is_delta, valid=bs.valid & keep,
                          eta_sq=bs.eta_sq)

    def delta_reflection(self, sp: ShadingPoint):
        value = self.base.delta_reflection(sp)
        if value is None:
            return None
        return value.masked(self.geometric_agreement(sp, reflect(sp.wo, sp.n_s)))

    def describe(self) -> dict:
        out = dict(self.base.describe())
        if self.normal_map is not None:
            out["normal_map"] = (f"{self.normal_map!r}, strength {self.normal_strength:g}"
                                 + (", DirectX convention" if self.normal_green_down else ""))
        if self.bump_map is not None:
            out["bump_map"] = f"{self.bump_map!r}, distance {self.bump_distance:g}, strength {self.bump_strength:g}"
        return out


def set_bump_correction(bsdf: BSDF, on: bool) -> None:
    """Turn Cycles' bump map correction (the specular normal and the diffuse terminator softening; the side
    rule stays) on or off on every ShadingNormal of ``bsdf`` (through mixes and wrappers)."""
    if isinstance(bsdf, ShadingNormal):
        bsdf.bump_correction = bool(on)
    for part in getattr(bsdf, "components", ()):
        set_bump_correction(part, on)
    base = getattr(bsdf, "base", None)
    if isinstance(base, BSDF):
        set_bump_correction(base, on)


def has_mapped_normals(bsdf) -> bool:
    """Whether a normal or bump map shades any lobe of ``bsdf`` (a ShadingNormal anywhere in it: mixes, layers,
    wrappers).  Such lobes keep their own side rule (the module docstring) with their own normal, so a material's
    side rule about its one shading normal (BSDF.geometric_sides) must not be laid over them."""
    from .batching import bsdfs_within
    return any(isinstance(m, ShadingNormal) for m in bsdfs_within(bsdf))
