"""Cycles' light passes with their Stokes components: Diffuse / Glossy / Transmission × Direct / Indirect /
Color, Volume Direct / Indirect, Emission and Environment (docs/guide/polariser-and-passes.md, "Light passes";
the rules are Cycles' kernel/film/light_passes.h, data_passes.h and read.h).

A path's light is put into a pass by its first non-transparent scattering vertex (crossings of alpha and
NULL-lobe surfaces before it keep it "seen directly"):

- light a path picks up before that vertex is **Emission** (an emitter) or **Environment** (the world);
- at that vertex, the light sample (next-event estimation) and the emission the sampled segment reaches are
  **Direct**; all later light is **Indirect**;
- the lobe: Cycles splits the vertex's BSDF value by closure type (``bsdf_eval_accum``: diffuse, glossy, and
  transmission as the rest) and carries the ratios on.  Here the vertex's value is split into its diffuse part
  (``BSDF.diffuse_share``: a depolariser, M00·diag(1, 0, 0, 0)) and the rest, which is Glossy where the light
  arrives from the viewer's side and Transmission where it crosses the surface.  The light sample is split
  exactly (Mueller matrices: the diffuse part of its Stokes vector is T[:, 0]·d·weight, the rest carries all
  the polarisation the glossy lobe made).  What follows the sampled direction is split as Cycles splits it:
  the diffuse share of its S0 is the diffuse part's fraction of the sampled value's M00 at that direction
  (per wavelength), with the Stokes direction of depolarised light behind the throughput before the vertex
  (T[:, 0]/T00: unpolarised when nothing polarising lies in front); Glossy or Transmission get the rest.
  Every contribution is divided without remainder, so the passes sum to Combined sample by sample;
- **Color** is the vertex's albedo of the lobe: the one-sample estimate T00·(BSDF·cos/pdf) of the sampled
  direction, split by the same fraction, unpolarised (S0 only), as a colour under white light (Σ_λ a·D65·w_rgb
  at the sampled wavelengths: unbiased for the RGB of a·D65, the round trip of an RGB albedo; in RGB transport
  the albedo itself, engine.render.integrator.albedo_rgb); Direct and Indirect are their light's sum divided
  by Color's (Cycles' ``safe_divide_even_color``), so (Direct + Indirect)·Color + … recombine to Combined;
- a path whose first vertex is a **medium vertex** (a participating medium's scattering: engine.render.participating)
  puts all its later light into **Volume Direct** (the light sample there and the emission its sampled segment
  reaches) and **Volume Indirect**, undivided (Cycles' PATH_RAY_VOLUME_PASS, set by path_state_next for a
  LABEL_VOLUME_SCATTER bounce before any pass flag; Cycles has no Volume Color).

The passes are traced as a second pass over the render's own samples (the same random numbers, hence the same
paths: engine.render.light_paths.trace_light_paths with a recorder), so a render that does not ask for them
runs exactly as before.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..kernels.transport import spectral_stokes_rgb_samples, stokes_rgb_samples
from ..materials.base import LobeColors
from ..materials.flags import BSDFFlags
from ..spectral.cie import d65_normalised
from ..vec3 import dot
from ..materials.material_set import MaterialSet
from .integrator import albedo_rgb
from .light_paths import TRANSPARENT, LightPathRules, classify, trace_light_paths

#: CLI / engine key → the pass's name in Blender (Cycles' passes in Blender 4.5–5.x), in Cycles' order
LIGHT_PASSES = {"diffuse_direct": "Diffuse Direct", "diffuse_indirect": "Diffuse Indirect",
                "diffuse_color": "Diffuse Color", "glossy_direct": "Glossy Direct",
                "glossy_indirect": "Glossy Indirect", "glossy_color": "Glossy Color",
                "transmission_direct": "Transmission Direct", "transmission_indirect": "Transmission Indirect",
                "transmission_color": "Transmission Color", "volume_direct": "Volume Direct",
                "volume_indirect": "Volume Indirect", "emission": "Emission", "environment": "Environment"}
ALL_LIGHT_PASSES = tuple(LIGHT_PASSES)
#: the light sums a batch keeps, in this order: per lobe Direct, Indirect; then Emission, Environment, Volume
#: Direct, Indirect (the last four are not divided by a Color)
LIGHT_SUMS = ("Diffuse Direct", "Diffuse Indirect", "Glossy Direct", "Glossy Indirect", "Transmission Direct",
              "Transmission Indirect", "Emission", "Environment", "Volume Direct", "Volume Indirect")
COLORS = ("Diffuse Color", "Glossy Color", "Transmission Color")
DIFFUSE, GLOSSY, TRANS = range(3)
EMIT, ENV, VOLUME = 6, 7, 8
#: the Stokes components' passes: "<pass> S1" … "<pass> S3" beside "<pass>" (= S0, Cycles' own)
STOKES_SUFFIXES = (" S1", " S2", " S3")


def stokes_pass_names(name: str) -> tuple[str, ...]:
    """The passes of one light pass: its S0 under Cycles' name, then S1–S3 (Color passes: S0 only)."""
    return (name,) if name in COLORS else (name,) + tuple(name + s for s in STOKES_SUFFIXES)


class LightPassBatch:
    """The light passes' bookkeeping of one batch (indexed by the batch's path index, never compacted): each
    path's level (0: before its first vertex, 1: its Direct segment, 2: Indirect), its first vertex's diffuse
    fraction (Lm, N), the Stokes direction of depolarised light behind the throughput there (P, Lm, N), its
    side (transmission) and whether it was a medium vertex (``volume``), and the sums: ``per_pass`` (10, P, L, N)
    of light and colours (3, Lm, N)."""

    def __init__(self, tracer, state, acc):
        n, P = acc.radiance.shape[2], acc.radiance.shape[0]
        L, Lm = acc.radiance.shape[1], state.T_store.shape[2]
        self.tracer, self.acc = tracer, acc
        self.level = np.zeros(n, np.int8)
        self.frac = np.zeros((Lm, n))
        self.col0 = np.zeros((P, Lm, n))
        self.col0[0] = 1.0
        self.transmit = np.zeros(n, bool)
        self.volume = np.zeros(n, bool)
        self.per_pass = np.zeros((len(LIGHT_SUMS), P, L, n))
        self.color = np.zeros((len(COLORS), Lm, n))
        # this vertex's: the light sample's diffuse part and side, the sampled direction's diffuse fraction
        self.nee_diffuse = np.zeros((P, L, n))
        self.nee_transmit = np.zeros(n, bool)
        self.nee_pure = np.zeros(n, bool)
        self.frac_now = np.zeros((Lm, n))
        self.rules = LightPathRules(tracer.settings, tracer.materials)
        self.transmits = np.array([m.flags.transmits for m in tracer.materials], bool)
        self.medium = self.rules.volume                 # per material: a medium vertex's pseudo-material
        self.unseparated: set[str] = set()
        self.estimated: set[str] = set()           # materials without lobe_colors (one-sample colours)
        # albedos become colours under white light: the colour-matching weights times D65 at the sampled λ
        self.white = None if acc.w_rgb is None or tracer.mono else acc.w_rgb * d65_normalised(state.lk.lam)[None]
        acc.lobes = self

    # ------------------------------------------------------------------ hooks of the integrator

    def _diffuse(self, bsdf, sp, wi) -> tuple[np.ndarray, np.ndarray]:
        """(diffuse part d, M00 of the value) (Lm, m) of ``bsdf`` (diffuse and glossy lobes) at directions ``wi``."""
        f = bsdf.eval(sp, wi)
        d = bsdf.diffuse_share(sp, wi, f)
        if d is None:
            d = np.zeros_like(f.m00())
            for m, idx, q, wi_m, f_m in _members(bsdf, sp, wi, f):     # a set: its members one by one
                dm = None if idx is None else m.diffuse_share(q, wi_m, f_m)
                if dm is None:
                    self.unseparated.add(m.name)
                else:
                    d[:, idx] = dm
        return d, f.m00()

    def light(self, bsdf, sp, path, wi, weight, T, cols) -> None:
        """Next-event estimation at vertices of the paths ``path``: the diffuse part T[:, 0]·d·weight (P, L, m)
        of each light sample (direction ``wi``, weight (L, m) after shadowing) at first vertices; a material
        whose smooth lobes are all diffuse gives all of it (marked, so that no rounding is left over)."""
        first = self.level[path] == 0
        if not first.any() or not bsdf.flags.has(BSDFFlags.DIFFUSE):
            return
        ids = path[first]
        if not bsdf.flags.has(BSDFFlags.GLOSSY):
            self.nee_pure[ids] = True
            return
        d, _ = self._diffuse(bsdf, sp, wi)
        col = T[:, 0][..., cols]                    # (P, Lm, m): the throughput's response to depolarised light
        part = col * (d * weight)[None]
        self.nee_diffuse[:, :, ids] = part[:, :, first]
        # transmitted: the light's side of the shading normal is not the viewer's (Cycles' glass closures)
        self.nee_transmit[ids] = ((dot(wi, sp.n_s) * dot(sp.wo, sp.n_s) < 0) & bsdf.flags.transmits)[first]

    def sampled(self, bsdf, sp, path, bs) -> None:
        """The BSDF sample of the paths ``path`` (a non-delta material's): the diffuse fraction of its value at
        the sampled direction (0 for Dirac lobes), for first vertices."""
        first = self.level[path] == 0
        if not first.any() or not bsdf.flags.has(BSDFFlags.DIFFUSE):
            return
        if bsdf.flags.has(BSDFFlags.GLOSSY):
            d, f00 = self._diffuse(bsdf, sp, bs.wi)
            frac = np.where(f00 > 0, d / np.where(f00 > 0, f00, 1.0), 0.0)
        else:
            frac = np.ones((self.frac.shape[0], path.size))
        frac = np.where(bs.is_delta[None, :], 0.0, np.clip(frac, 0.0, 1.0))
        self.frac_now[:, path[first]] = frac[:, first]

    # ------------------------------------------------------------------ stages

    def mark(self, state) -> tuple:
        """The live paths and their radiance before a stage (and this vertex's records cleared)."""
        ids = state.path.copy()
        self.nee_diffuse[:, :, ids] = 0.0
        self.nee_pure[ids] = False
        self.frac_now[:, ids] = 0.0
        return ids, self.acc.radiance[:, :, ids].copy()

    def _added(self, seen) -> tuple[np.ndarray, np.ndarray]:
        ids, before = seen
        return ids, self.acc.radiance[:, :, ids] - before

    def _split(self, ids: np.ndarray, added: np.ndarray, indirect: int) -> None:
        """Light ``added`` (P, L, m) of paths past their first vertex into Direct (``indirect`` 0) or Indirect (1)."""
        if ids.size == 0:
            return
        vol = self.volume[ids]
        if vol.any():
            self.per_pass[VOLUME + indirect][:, :, ids[vol]] += added[:, :, vol]
            ids, added = ids[~vol], added[:, :, ~vol]
        s0 = self.frac[:, ids] * added[0]                  # (L, m): the diffuse share of S0
        diffuse = self.col0[:, :, ids] * s0[None]
        rest = added - diffuse
        trans = self.transmit[ids]
        self.per_pass[2 * DIFFUSE + indirect][:, :, ids] += diffuse
        self.per_pass[2 * GLOSSY + indirect][:, :, ids] += np.where(trans, 0.0, rest)
        self.per_pass[2 * TRANS + indirect][:, :, ids] += np.where(trans, rest, 0.0)

    def emitted(self, seen, hit: np.ndarray, background: np.ndarray) -> None:
        """The emission stage's light: Emission / Environment before the first vertex, else Direct / Indirect."""
        ids, added = self._added(seen)
        level = self.level[ids]
        zero = level == 0
        for k, where in ((EMIT, zero & hit), (ENV, zero & ~hit)):
            if where.any():
                self.per_pass[k][:, :, ids[where]] += added[:, :, where]
        for lv in (1, 2):
            where = level == lv
            if where.any():
                self._split(ids[where], added[:, :, where], lv - 1)

    def scattered(self, seen, factor: np.ndarray | None, state, surf, mat: np.ndarray, nxt) -> None:
        """The scatter stage's light (light samples: Direct at first vertices, else Indirect) and the first
        vertices' records: fraction, side, colour (from the new throughput T00 = T00_before·M00 of the sample)."""
        ids, added = self._added(seen)
        level = self.level[ids]
        first = level == 0
        medium = self.medium[mat]
        vol_first = first & medium
        if vol_first.any():                     # a medium vertex's light sample: Volume Direct, undivided
            self.per_pass[VOLUME][:, :, ids[vol_first]] += added[:, :, vol_first]
        surf_first = first & ~medium
        if surf_first.any():
            f_ids = ids[surf_first]
            diffuse = self.nee_diffuse[:, :, f_ids] * (1.0 if factor is None else factor[surf_first])
            diffuse = np.where(self.nee_pure[f_ids], added[:, :, surf_first], diffuse)
            rest = added[:, :, surf_first] - diffuse
            trans = self.nee_transmit[f_ids]
            self.per_pass[2 * DIFFUSE][:, :, f_ids] += diffuse
            self.per_pass[2 * GLOSSY][:, :, f_ids] += np.where(trans, 0.0, rest)
            self.per_pass[2 * TRANS][:, :, f_ids] += np.where(trans, rest, 0.0)
        self._split(ids[~first], added[:, :, ~first], 1)
        kind, _ = classify(self.rules, mat, surf.n_g, surf.wo, nxt.d, nxt.is_delta)
        new = first & (kind != TRANSPARENT)
        self.volume[ids[new]] = medium[new]
        new = new & ~medium                     # surface first vertices: their lobe records and colours
        if new.any():
            n_ids = ids[new]
            frac = self.frac_now[:, n_ids]
            self.frac[:, n_ids] = frac
            rows = new.nonzero()[0]
            cols = state.T_columns(rows)
            T_pre = state.T_store[:, 0][..., rows if cols is None else cols]     # (P, Lm, m)
            t00 = T_pre[0]
            self.col0[:, :, n_ids] = np.where(t00 != 0, T_pre / np.where(t00 != 0, t00, 1.0), self.col0[:, :, n_ids])
            # Cycles' glass closure counts light as transmitted by the side of its shading normal (light_passes.h)
            n_s = surf.n_s[:, rows]
            crossed = dot(nxt.d[:, rows], n_s) * dot(surf.wo[:, rows], n_s) < 0
            self.transmit[n_ids] = crossed & self.transmits[mat[new]]
            a = np.where(nxt.valid[new], nxt.T[0, 0][:, new], 0.0)         # (Lm, m)
            trans = self.transmit[n_ids]
            colors, known = self._colors(state, surf, mat, rows, t00)
            self.color[DIFFUSE][:, n_ids] = np.where(known, colors.diffuse, frac * a)
            self.color[GLOSSY][:, n_ids] = np.where(known, colors.glossy, np.where(trans, 0.0, (1.0 - frac) * a))
            self.color[TRANS][:, n_ids] = np.where(known, colors.transmission, np.where(trans, (1.0 - frac) * a, 0.0))
        self.level[ids] = np.where(first & (kind != TRANSPARENT), 1, np.where(level >= 1, 2, level))

    def _colors(self, state, surf, mat: np.ndarray, rows: np.ndarray, t00: np.ndarray) -> tuple:
        """The Color passes' albedos of the first vertices ``rows`` (batch rows; throughput T00 (Lm, m) before
        them): (LobeColors T00 × BSDF.lobe_colors at each vertex's shading point, known (m,): where its material
        has them; elsewhere the caller's one-sample estimate, the material named in a warning)."""
        tracer = self.tracer
        out = LobeColors(*(np.zeros(t00.shape) for _ in range(3)))
        known = np.zeros(rows.size, bool)
        flip = tracer._back_faces(mat, surf.n_g, surf.wo)
        groups = tracer.group_of[mat[rows]]
        for g in np.unique(groups):
            at = np.flatnonzero(groups == g)
            bsdf = tracer.shaders[g]
            sp = tracer._shading_point(bsdf, state, surf, mat, flip, rows[at])
            colors = bsdf.lobe_colors(sp)
            parts = [(bsdf, None, colors)]
            if colors is None:                          # a set: its members one by one
                parts = [(m, idx, None if idx is None else m.lobe_colors(q)) for m, idx, q, _, _ in _members(bsdf, sp)]
            for m, idx, c in parts:
                if c is None:
                    self.estimated.add(m.name)
                    continue
                sub = at if idx is None else at[idx]
                known[sub] = True
                out.diffuse[:, sub], out.glossy[:, sub] = t00[:, sub] * c.diffuse, t00[:, sub] * c.glossy
                out.transmission[:, sub] = t00[:, sub] * c.transmission
        return out, known

    def finish(self) -> dict:
        """The batch's passes per path: "light" (10, 4, 3, N) Stokes × RGB (as the film converts the radiance),
        "color" (3, 3, N) linear sRGB albedos, "unseparated" (the materials whose lobes were not told apart)."""
        tracer, acc = self.tracer, self.acc
        n = self.level.size
        light = np.zeros((len(LIGHT_SUMS), 4, 3, n))
        for k in range(len(LIGHT_SUMS)):
            if tracer.rgb_mode:
                light[k], _ = stokes_rgb_samples(self.per_pass[k])
            else:
                light[k], _ = spectral_stokes_rgb_samples(self.per_pass[k], acc.w_rgb)
        path = np.arange(n)
        if self.white is None:
            color = np.stack([albedo_rgb(self.color[k], acc.w_rgb, path, tracer.channels) for k in range(len(COLORS))])
        else:       # Σ_λ a·D65·w: unbiased for the colour of a·D65 (white D65 gives 1 per channel in expectation)
            color = np.einsum("kln,cln->kcn", self.color, self.white)
        # a sample with a non-finite value anywhere counts 0 everywhere (as the film drops it)
        bad = ~(np.isfinite(light).all(axis=(0, 1, 2)) & np.isfinite(color).all(axis=(0, 1)))
        light[..., bad] = 0.0
        color[..., bad] = 0.0
        return {"light": light, "color": color, "unseparated": sorted(self.unseparated),
                "estimated": sorted(self.estimated), "dropped": bad}


# ----------------------------------------------------------------------------- the passes of a render


def _members(bsdf, sp, wi=None, f=None) -> list:
    """A MaterialSet's ``member_parts``; any other BSDF as one part without indices (idx None: nothing to split)."""
    if isinstance(bsdf, MaterialSet):
        return bsdf.member_parts(sp, wi, f)
    return [(bsdf, None, sp, wi, f)]


@dataclass
class LightPasses:
    """The light passes of a render (H, W, 3) each, linear sRGB: ``stokes[name]`` (4, H, W, 3) for Direct,
    Indirect, Emission and Environment (S0 … S3), ``color[name]`` (H, W, 3) for the Color passes; ``combined``
    (4, H, W, 3): the traced samples' mean (what the passes recombine to); ``warnings``: one line per thing not
    separated."""
    stokes: dict
    color: dict
    combined: np.ndarray
    samples: int
    warnings: list = field(default_factory=list)

    def images(self, keys=ALL_LIGHT_PASSES) -> dict:
        """{pass name: (H, W, 3)} of the passes ``keys`` (engine keys): S0 under Cycles' name, S1–S3 as
        "<name> S1" … (Color passes: one image)."""
        out = {}
        for key in keys:
            name = LIGHT_PASSES[key]
            if name in self.color:
                out[name] = self.color[name]
            else:
                for k, pass_name in enumerate(stokes_pass_names(name)):
                    out[pass_name] = self.stokes[name][k]
        return out

    def recombined(self) -> np.ndarray:
        """Combined (4, H, W, 3) from the passes as Cycles' compositing adds them: (Direct + Indirect)·Color per
        lobe, plus Volume Direct + Indirect, Emission and Environment (equal to ``combined`` wherever no lobe has
        light with a Color of 0: a division that cannot be undone, Cycles' too)."""
        out = sum(self.stokes[name] for name in LIGHT_SUMS[EMIT:])
        for k, c in enumerate(COLORS):
            out = out + (self.stokes[LIGHT_SUMS[2 * k]] + self.stokes[LIGHT_SUMS[2 * k + 1]]) * self.color[c][None]
        return out

    def channels(self, keys=ALL_LIGHT_PASSES) -> dict:
        """EXR channels {"Diffuse Direct.R": (H, W), …, "Diffuse Direct S1.R": …} of the passes ``keys``."""
        return {f"{name}.{c}": img[..., i] for name, img in self.images(keys).items() for i, c in enumerate("RGB")}


def safe_divide_even_color(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a / b per RGB channel (last axis) as Cycles' ``safe_divide_even_color``: a channel whose divisor is 0
    takes the other channels' mean ratio (0 where every divisor is 0)."""
    ok = b != 0
    q = np.where(ok, a / np.where(ok, b, 1.0), 0.0)
    x, y, z = (q[..., i] for i in range(3))
    bx, by, bz = (ok[..., i] for i in range(3))
    out = q.copy()
    out[..., 0] = np.where(bx, x, np.where(~by, z, np.where(~bz, y, 0.5 * (y + z))))
    out[..., 1] = np.where(by, y, np.where(~bx, z, np.where(~bz, x, 0.5 * (x + z))))
    out[..., 2] = np.where(bz, z, np.where(~bx, y, np.where(~by, x, 0.5 * (x + y))))
    return out


def render_light_passes(renderer, settings=None, window=None, threads: int | None = None) -> LightPasses:
    """The light passes of ``renderer`` (engine.render.renderer.Renderer) with ``settings`` (None: the scene's)
    over ``window`` (x0, y0, x1, y1; None: the whole image): samples 0 … spp − 1 of every pixel traced again
    with the render's tracer (the same paths as the render's), their light split as the module docstring
    says.  Deterministic for a seed, whatever ``threads`` (None: settings.threads, 0: one per core)."""
    scene = renderer.scene
    settings = settings or scene.settings
    W, H = scene.camera.width, scene.camera.height
    x0, y0, x1, y1 = window or (0, 0, W, H)
    plan = renderer.plan(settings, (x0, y0, x1, y1))
    tracer = renderer.tracer(plan)
    rows, cols = np.mgrid[y0:y1, x0:x1]
    pixels = (rows * W + cols).ravel().astype(np.int64)
    spp = int(plan.settings.spp)
    per_chunk = max(1, int(plan.settings.batch_rays) // spp)
    chunks = [np.arange(a, min(a + per_chunk, pixels.size)) for a in range(0, pixels.size, per_chunk)]

    def run(c):
        pixel = np.repeat(pixels[c], spp)
        sample = np.tile(np.arange(spp, dtype=np.int64), c.size)
        out, stats = trace_light_paths(tracer, pixel, sample,
                                       passes=lambda state, acc: LightPassBatch(tracer, state, acc))
        lp = stats["light_passes"]
        out[..., lp["dropped"]] = 0.0           # the samples the passes drop are dropped from their combined too
        m = c.size
        return (out.reshape(4, 3, m, spp).sum(-1), lp["light"].reshape(len(LIGHT_SUMS), 4, 3, m, spp).sum(-1),
                lp["color"].reshape(3, 3, m, spp).sum(-1), lp["unseparated"], lp["estimated"])

    workers = threads if threads is not None else settings.threads
    workers = max(1, workers if workers > 0 else (os.cpu_count() or 1))
    if workers == 1 or len(chunks) == 1:
        results = [run(c) for c in chunks]
    else:
        with ThreadPoolExecutor(workers) as pool:
            results = list(pool.map(run, chunks))
    n = pixels.size
    combined, light, color = np.zeros((4, 3, n)), np.zeros((len(LIGHT_SUMS), 4, 3, n)), np.zeros((3, 3, n))
    unseparated, estimated = set(), set()
    for c, (o, li, co, un, est) in zip(chunks, results):
        combined[..., c], light[..., c], color[..., c] = o, li, co
        unseparated.update(un)
        estimated.update(est)
    h, w = y1 - y0, x1 - x0

    def image(a):                                # (..., 3, n) sums → (..., h, w, 3)
        return np.moveaxis(a, -2, -1).reshape(a.shape[:-2] + (h, w, 3))
    inv = 1.0 / spp
    color_img = {name: image(color[k]) * inv for k, name in enumerate(COLORS)}
    stokes = {}
    for k, name in enumerate(LIGHT_SUMS):
        if k >= EMIT:
            stokes[name] = image(light[k]) * inv
        else:
            stokes[name] = safe_divide_even_color(image(light[k]), image(color[k // 2])[None])
    warnings = [f"light passes: the diffuse and glossy lobes of {', '.join(repr(u) for u in sorted(unseparated))} "
                "are not separated; their light counts as Glossy (or Transmission)"] if unseparated else []
    if estimated:
        warnings.append(f"light passes: no per-lobe albedo for {', '.join(repr(u) for u in sorted(estimated))}; "
                        "their Color passes are one-sample estimates, so their Direct and Indirect passes (light / "
                        "Color) run high at low sample counts")
    return LightPasses(stokes=stokes, color=color_img, combined=image(combined) * inv, samples=spp, warnings=warnings)
