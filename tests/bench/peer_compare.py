"""Peer agreement: our Stokes images against Mitsuba 3 renders, 8×8-block z-scores.

    python tests/bench/peer_compare.py --mitsuba DIR [--scenes a,b] [--spp 32] [--renders 2] [--out DIR]

DIR holds Mitsuba renders made by ``shared/peers/render_peer.py --renders 2``
(files ``<scene>__<variant>__<W>x<H>__<spp>spp__seed<S>.npy``).  For each
scene this renders ours ``--renders`` times (seeds 0, 1, …) at ``--spp``,
saves them in the same layout and runs ``shared/peers/compare.py`` on the
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
Not part of the test command (it needs Mitsuba renders and minutes of time).
"""

from __future__ import annotations

import argparse
import glob
import os
import re
import subprocess
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


def mitsuba_files(directory, scene):
    """(files, spp, (width, height)) of the Mitsuba renders of ``scene`` in ``directory``."""
    variant = UNPOLARISED_PEER.get(scene) or MONO_PEER.get(scene, "*_polarized")
    files = sorted(glob.glob(os.path.join(directory, f"{scene}__{variant}__*spp__seed*.npy")))
    files = [f for f in files if not f.endswith("_lum.npy")]
    if not files:
        return [], 0, None
    m = re.search(r"__(\d+)x(\d+)__(\d+)spp__", files[0])
    return files, int(m.group(3)), (int(m.group(1)), int(m.group(2)))


def parse_compare(text):
    """{component: (mean_a, mean_b, rms_z, max_z, pass_fraction)} from compare.py's table."""
    out = {}
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 6 and re.fullmatch(r"S[0-3]", parts[0]):
            out[parts[0]] = tuple(float(x) for x in parts[1:])
    return out


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
    failed = False
    rows = []
    for scene_name in args.scenes.split(","):
        mfiles, m_spp, m_size = mitsuba_files(args.mitsuba, scene_name)
        if len(mfiles) < 2:
            print(f"{scene_name}: fewer than 2 Mitsuba renders in {args.mitsuba}; skipped")
            continue
        scene = load_scene(os.path.join(PEERS, "scenes", f"{scene_name}.json"))
        spp = args.spp * (16 if scene_name == "conv_s3_check" else 1)
        scene.settings.spp = spp
        scene.camera.width, scene.camera.height = m_size
        if scene_name in UNPOLARISED_PEER:
            scene.settings.polarisation = "off"
        renderer = Renderer(scene)
        ours = []
        t0 = time.perf_counter()
        for seed in range(args.renders):
            scene.settings.seed = seed
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
            cmd = [sys.executable, os.path.join(PEERS, "compare.py"), "--a", *ours, "--b", *mfiles,
                   "--channel", ch, "--a-spp", str(spp * args.renders), "--b-spp", str(m_spp * len(mfiles))]
            proc = subprocess.run(cmd, capture_output=True, text=True)
            res = parse_compare(proc.stdout)
            judged = (["S1", "S2", "S3"] if scene_name in S0_DIFFERS else
                      ["S0"] if scene_name in UNPOLARISED_PEER else ["S0", "S1", "S2", "S3"])
            for comp in ["S0", "S1", "S2", "S3"]:
                if comp not in res:
                    continue
                mean_a, mean_b, rms, zmax, frac = res[comp]
                ok = frac >= 0.99 or comp not in judged
                failed |= not ok
                rows.append((scene_name, ch, comp, mean_a, mean_b, rms, zmax, frac, "ok" if ok else
                             ("FAIL" if comp in judged else "not judged")))
            if not res:
                print(proc.stdout, proc.stderr)
        print(f"{scene_name}: ours {args.renders}×{spp} spp in {seconds:.1f} s; Mitsuba {len(mfiles)}×{m_spp} spp"
              f" ({os.path.basename(mfiles[0]).split('__')[1]}, {m_size[0]}×{m_size[1]})")
    print("\n| scene | channel | component | mean (ours) | mean (Mitsuba) | rms(z) | max abs(z) | blocks within 4σ |"
          " verdict |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:+.5f} | {r[4]:+.5f} | {r[5]:.2f} | {r[6]:.2f} | "
              f"{100 * r[7]:.2f} % | {r[8]} |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
