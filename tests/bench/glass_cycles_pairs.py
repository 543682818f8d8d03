"""A rough Principled glass sphere under the asset suite's lighting, Cycles against Polar, with the diagnostics of
docs/benchmarks.md ("Rough glass under the HDRI against Cycles"):

    python tests/bench/glass_cycles_pairs.py [--roughness 0.4 0.4] [--lighting hdri] [--spp 256] [--seeds 8]
        [--bounces 8] [--polarisation AUTO] [--spectral RGB] [--world-bsdf-only] [--cycles-pairs]

prints Polar ÷ Cycles of the sphere's mean luminance (± one standard error over seeds) and per 16 × 16 block.
``--world-bsdf-only``: Cycles without light samples of the world (World ▸ Settings ▸ Sampling: None), its
BSDF-sampled estimate.  ``--cycles-pairs``: Polar's rough dielectric also given Cycles' value and pdf on the
refraction pairs no facet refracts (bsdf_microfacet_eval's unchecked half vector; a patch of this process only,
NumPy arithmetic, polarisation-free on those pairs), which reproduces Cycles' default.  Not part of the test command.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, REPO)


def _ggx_lambda(alpha2, cos_n):
    return 0.5 * (np.sqrt(1.0 + alpha2 * np.maximum(1.0 / (cos_n * cos_n) - 1.0, 0.0)) - 1.0)


def install_cycles_pairs(module) -> None:
    """Add to ``module``'s rough_dielectric_eval and _pdf Cycles' GGX glass value (f, no cosine) and pdf on the
    refraction pairs its _half_vector rejects (the half vector with the viewer behind or the light in front)."""
    fresnel_reflection_abcs = module.fresnel_reflection_abcs
    base_eval, base_pdf = module.rough_dielectric_eval, module.rough_dielectric_pdf

    def unchecked(n_s, wo, wi, n_int, n_ext, alpha):
        _, eta, wo_l, wi_l = module._local(n_s, wo, n_int, n_ext, wi)
        _, refl, ok, _, _ = module._half_vector(wi_l, wo_l, eta)
        hv = -(eta * wi_l + wo_l)
        length = np.sqrt(np.sum(hv * hv, axis=0))
        pair = ~ok & ~refl & (length > 1e-12) & (wo_l[2] > 0) & (wi_l[2] < 0)
        h = hv / np.where(pair, length, 1.0)
        c2 = np.minimum(h[2] ** 2, 1.0)
        a2 = np.broadcast_to(np.asarray(alpha, float) ** 2, c2.shape)
        D = a2 / (math.pi * (1.0 - c2 + a2 * c2) ** 2)                        # bsdf_D reads cos²θ_H only
        d_i, d_o = np.abs(np.sum(h * wi_l, axis=0)), np.abs(np.sum(h * wo_l, axis=0))
        c_o, c_i = wo_l[2], np.where(pair, np.abs(wi_l[2]), 1.0)
        T = 1.0 - fresnel_reflection_abcs(np.clip(d_o, 0.0, 1.0), eta)[0]
        common = D * d_i * d_o / (np.where(pair, c_o, 1.0) * length * length)
        lam_o, lam_i = _ggx_lambda(a2, c_o), _ggx_lambda(a2, c_i)
        value = np.where(pair, T * common / c_i / (1.0 + lam_o + lam_i), 0.0)
        pdf = np.where(pair, T * common * eta * eta / (1.0 + lam_o), 0.0)
        return value, pdf

    def eval_(n_s, wo, wi, L, n_int, n_ext, distribution, rational, alpha, no_fresnel=False):
        x, A, B, C, S = base_eval(n_s, wo, wi, L, n_int, n_ext, distribution, rational, alpha, no_fresnel)
        v = unchecked(n_s, wo, wi, n_int, n_ext, alpha)[0][None, :]
        return x, A + v, B, C + v, S

    def pdf_(n_s, wo, wi, n_int, n_ext, distribution, alpha, no_fresnel=False):
        return (base_pdf(n_s, wo, wi, n_int, n_ext, distribution, alpha, no_fresnel)
                + unchecked(n_s, wo, wi, n_int, n_ext, alpha)[1])

    module.rough_dielectric_eval, module.rough_dielectric_pdf = eval_, pdf_


def main() -> None:
    ap_ = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap_.add_argument("--roughness", type=float, nargs=2, default=(0.4, 0.4), help="the checker's two values")
    ap_.add_argument("--lighting", default="hdri", choices=("hdri", "lamps"))
    ap_.add_argument("--spp", type=int, default=256)
    ap_.add_argument("--seeds", type=int, default=8)
    ap_.add_argument("--bounces", type=int, default=8)
    ap_.add_argument("--polarisation", default="AUTO")
    ap_.add_argument("--spectral", default="RGB")
    ap_.add_argument("--world-bsdf-only", action="store_true")
    ap_.add_argument("--cycles-pairs", action="store_true")
    a = ap_.parse_args()
    import tests.blender.test_cycles_parity_principled as parity
    from tests.blender_support import load_addon
    from tests.support import asset_parity as ap
    load_addon()
    if a.cycles_pairs:
        install_cycles_pairs(sys.modules["polar_render.engine.materials.rough_dielectric"])
    scene = parity.sphere_scene("Roughness", tuple(a.roughness), {"Transmission Weight": 1.0,
                                                                  "Base Color": (0.9, 0.9, 0.9)}, a.lighting)
    if a.world_bsdf_only:
        scene.world.cycles.sampling_method = "NONE"
    size = parity.SIZE
    hit = ap.coverage(scene, size, size)
    with tempfile.TemporaryDirectory() as tmp:
        cycles = ap.render_cycles(scene, a.spp, a.seeds, a.bounces, tmp) @ ap.REC709
    renderer, settings, warnings = ap.export_polar(scene, a.spp, a.bounces, a.polarisation, a.spectral)
    polar = ap.render_polar(renderer, settings, a.seeds)[:, 0] @ ap.REC709
    mc, mp = cycles[:, hit].mean(axis=1), polar[:, hit].mean(axis=1)
    ratio = mp.mean() / mc.mean()
    se = ratio * math.hypot(mc.std(ddof=1) / mc.mean(), mp.std(ddof=1) / mp.mean()) / math.sqrt(a.seeds)
    print(f"{vars(a)}\nsphere mean luminance: Cycles {mc.mean():.4f}, Polar {mp.mean():.4f}; Polar ÷ Cycles "
          f"{ratio:.4f} ± {se:.4f}; warnings {warnings}; load {os.getloadavg()[0]:.1f}")
    shape = (size // ap.BLOCK, size // ap.BLOCK)
    blocks = ap.block_means(polar, shape).mean(0) / np.maximum(ap.block_means(cycles, shape).mean(0), 1e-12)
    print("per block, Polar ÷ Cycles:\n", np.array2string(blocks, precision=3))


if __name__ == "__main__":
    main()
