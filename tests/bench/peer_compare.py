"""Peer agreement: our Stokes images against Mitsuba 3 renders, 8×8-block z-scores.

    python tests/bench/peer_compare.py --mitsuba DIR [--scenes a,b] [--spp 32] [--renders 2] [--out DIR]

DIR holds Mitsuba renders made by ``shared/peers/render_peer.py --renders 2``
(files ``<scene>__<variant>__<W>x<H>__<spp>spp__seed<S>.npy``).  For each
scene this renders ours ``--renders`` times (seeds 0, 1, …) at ``--spp``,
saves them in the same layout and compares them with ``shared/peers/compare.py``'s method on the
luminance (Y) and on each of R, G, B (with the variance floor for unequal
sample counts).  Ours is rendered at the Mitsuba renders' resolution (from
their file names).  Scenes whose S0 legitimately differs (RGB upsampling of
coloured walls: ``cornell_lambert``) are judged on S1..S3 only.  Scenes whose
Mitsuba reference is an unpolarised variant (``rough_glass_sphere``: Mitsuba's
``roughdielectric`` is a depolariser in its polarised variants) are rendered
here with polarisation off and compared on S0 alone (``compare.py`` does that
when one side has one component).  ``envmap_spheres`` is compared with
Mitsuba's ``llvm_ad_mono_polarized`` render in luminance only.  Prints a table; exit status 1 if a judged
component fails the 99 % criterion.

Zero-variance guard: the z-scores are computed here with ``compare.py``'s own functions (same blocks,
same variance floor), except for blocks where both sides' block standard errors are ~0 (≤ ZERO_SE_REL
× the block's |mean|, or exactly 0): a z-score there divides a float32 rounding difference by ~0 (the
directly seen constant sky of ``envmap_spheres``: Mitsuba's float32 values differ from ours by
≤ 6.7e-6 relative with variance 0 on both sides).  Such a block passes when the two block means agree
to ZERO_VAR_REL_TOL relative; the table's "noiseless" column counts the blocks judged that way.
Not part of the test command (it needs Mitsuba renders and minutes of time).
"""

from __future__ import annotations

import argparse
import dataclasses
import glob
import importlib.util
import os
import re
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)

from engine.render.renderer import Renderer  # noqa: E402
from engine.scene.loader import load_scene  # noqa: E402

SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
PEERS = os.path.join(SHARED, "peers")
DEFAULT_SCENES = ["conv_s3_check", "plane_brewster", "fresnel_sphere", "fresnel_sphere_au", "glass_sphere",
                  "cornell_lambert", "rough_glass_sphere", "envmap_spheres"]
S0_DIFFERS = {"cornell_lambert"}   # coloured diffuse walls: RGB→spectrum upsampling methods differ
# Mitsuba's roughdielectric depolarises in its polarised variants, so the reference is its unpolarised
# spectral render (S0 only) and ours is the scalar (polarisation off) render of the same scene.
UNPOLARISED_PEER = {"rough_glass_sphere": "llvm_ad_spectral"}
# The environment map enters Mitsuba's mono variant as each texel's luminance, exactly the luminance of
# our RGB render; its spectral variants upsample coloured texels their own way (peers README, Lights).
# So the reference is the mono polarised render, compared in luminance (Y) only.
MONO_PEER = {"envmap_spheres": "llvm_ad_mono_polarized"}
# Mitsuba's mono luminance weights (peers README): Rec.709's rounded ones differ by up to 5e-5 on the
# map's coloured patches, which z-scores of noiseless directly seen sky resolve.
MONO_Y = np.array([0.212671, 0.715160, 0.072169])
# Zero-variance guard (module docstring): a block's standard error counts as ~0 below this fraction of its
# |mean| (float32 noise of a deterministic pixel is ~1e-7 relative; Monte Carlo noise at these sample
# counts is ≥ 1e-4), and such blocks must agree to this relative difference instead of |z| < Z_LIMIT.
ZERO_SE_REL = 1e-6
ZERO_VAR_REL_TOL = 1e-4
Z_LIMIT = 4.0
BLOCK = 8


def load_compare():
    """shared/peers/compare.py as a module (its block statistics and variance floor)."""
    spec = importlib.util.spec_from_file_location("peer_compare_shared", os.path.join(PEERS, "compare.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def judge_blocks(a_mean, a_var, b_mean, b_var, a_spp, b_spp, compare, block=BLOCK):
    """Per component: (mean a, mean b, rms z, max |z|, pass fraction, noiseless blocks).

    compare.py's z-test (variance floor with the total sample counts, 8×8 blocks) except that blocks
    whose standard errors are ~0 on both sides (before the floor) pass iff |Δmean| ≤ ZERO_VAR_REL_TOL ×
    max(|mean a|, |mean b|); rms and max |z| are over the other blocks."""
    ma, va_raw = compare.block_stats(a_mean, a_var, block)
    mb, vb_raw = compare.block_stats(b_mean, b_var, block)
    fa, fb = compare.variance_floor(a_var, a_spp, b_var, b_spp)
    z = compare.block_z(a_mean, fa, b_mean, fb, block)
    scale = np.maximum(np.abs(ma), np.abs(mb))
    noiseless = (np.sqrt(va_raw) <= ZERO_SE_REL * np.abs(ma)) & (np.sqrt(vb_raw) <= ZERO_SE_REL * np.abs(mb))
    agree = np.abs(ma - mb) <= ZERO_VAR_REL_TOL * scale
    passed = np.where(noiseless, agree, np.abs(z) < Z_LIMIT)
    out = {}
    for c in range(z.shape[0]):
        zc = z[c][~noiseless[c]]
        finite = zc[np.isfinite(zc)]
        out[f"S{c}"] = (float(a_mean[c].mean()), float(b_mean[c].mean()),
                        float(np.sqrt(np.mean(finite ** 2))) if finite.size else 0.0,
                        float(np.abs(zc).max()) if zc.size else 0.0,
                        float(passed[c].mean()), int(noiseless[c].sum()))
    return out


def compare_sides(ours, mitsuba, ch, a_spp, b_spp, compare):
    """judge_blocks on the two sets of renders in channel ``ch`` (compare.py's loading and reduction;
    one side S0 only → S0 only)."""
    am, av = compare.side(ours, None, ch)
    bm, bv = compare.side(mitsuba, None, ch)
    if am.shape[1:] == bm.shape[1:] and 1 in (am.shape[0], bm.shape[0]) and am.shape[0] != bm.shape[0]:
        am, av, bm, bv = am[:1], av[:1], bm[:1], bv[:1]
    if am.shape != bm.shape:
        raise SystemExit(f"shape mismatch {am.shape} vs {bm.shape}")
    return judge_blocks(am, av, bm, bv, a_spp, b_spp, compare)


def mitsuba_files(directory, scene):
    """(files, spp, (width, height)) of the Mitsuba renders of ``scene`` in ``directory``."""
    variant = UNPOLARISED_PEER.get(scene) or MONO_PEER.get(scene, "*_polarized")
    files = sorted(glob.glob(os.path.join(directory, f"{scene}__{variant}__*spp__seed*.npy")))
    files = [f for f in files if not f.endswith("_lum.npy")]
    if not files:
        return [], 0, None
    m = re.search(r"__(\d+)x(\d+)__(\d+)spp__", files[0])
    return files, int(m.group(3)), (int(m.group(1)), int(m.group(2)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mitsuba", required=True, help="folder with Mitsuba renders (render_peer.py output)")
    ap.add_argument("--scenes", default=",".join(DEFAULT_SCENES))
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--renders", type=int, default=2)
    ap.add_argument("--out", default=os.path.join(REPO, "out", "peer_compare"))
    ap.add_argument("--channels", default="Y,R,G,B")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    compare = load_compare()
    failed = False
    rows = []
    for scene_name in args.scenes.split(","):
        mfiles, m_spp, m_size = mitsuba_files(args.mitsuba, scene_name)
        if len(mfiles) < 2:
            print(f"{scene_name}: fewer than 2 Mitsuba renders in {args.mitsuba}; skipped")
            continue
        scene = load_scene(os.path.join(PEERS, "scenes", f"{scene_name}.json"))
        spp = args.spp * (16 if scene_name == "conv_s3_check" else 1)
        scene.settings = dataclasses.replace(scene.settings, spp=spp)
        scene.camera.width, scene.camera.height = m_size
        if scene_name in UNPOLARISED_PEER:
            scene.settings = dataclasses.replace(scene.settings, polarisation="off")
        renderer = Renderer(scene)
        ours = []
        t0 = time.perf_counter()
        for seed in range(args.renders):
            scene.settings = dataclasses.replace(scene.settings, seed=seed)
            result = renderer.render(scene.settings)
            path = os.path.join(args.out, f"{scene_name}__polar__{scene.camera.width}x{scene.camera.height}__"
                                          f"{spp}spp__seed{seed}.npy")
            stokes = result.stokes()
            if scene_name in MONO_PEER:
                stokes = np.einsum("shwc,c->shw", stokes, MONO_Y)     # one channel: compare.py takes it as is
            np.save(path, stokes.astype(np.float32))
            ours.append(path)
        seconds = time.perf_counter() - t0
        for ch in (["Y"] if scene_name in MONO_PEER else args.channels.split(",")):
            res = compare_sides(ours, mfiles, ch, spp * args.renders, m_spp * len(mfiles), compare)
            judged = (["S1", "S2", "S3"] if scene_name in S0_DIFFERS else
                      ["S0"] if scene_name in UNPOLARISED_PEER else ["S0", "S1", "S2", "S3"])
            for comp in ["S0", "S1", "S2", "S3"]:
                if comp not in res:
                    continue
                mean_a, mean_b, rms, zmax, frac, noiseless = res[comp]
                ok = frac >= 0.99 or comp not in judged
                failed |= not ok
                rows.append((scene_name, ch, comp, mean_a, mean_b, rms, zmax, frac, noiseless, "ok" if ok else
                             ("FAIL" if comp in judged else "not judged")))
        print(f"{scene_name}: ours {args.renders}×{spp} spp in {seconds:.1f} s; Mitsuba {len(mfiles)}×{m_spp} spp"
              f" ({os.path.basename(mfiles[0]).split('__')[1]}, {m_size[0]}×{m_size[1]})")
    print("\n| scene | channel | component | mean (ours) | mean (Mitsuba) | rms(z) | max abs(z) | blocks passed |"
          " noiseless blocks (by rel. diff) | verdict |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:+.5f} | {r[4]:+.5f} | {r[5]:.2f} | {r[6]:.2f} | "
              f"{100 * r[7]:.2f} % | {r[8]} | {r[9]} |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
