"""Issue 36's race: time to equal error against Mitsuba 3 LLVM at its best sampler, ours at our defaults.

    python tests/bench/peer_race.py [--scenes a,b] [--res 128] [--spp 64] [--seeds 8] [--threads 2]
                                    [--mitsuba-python /work/peerenv/bin/python] [--samplers independent,…]

For each peer scene (``shared/peers/scenes``) Mitsuba 3 (``llvm_ad_spectral_polarized``, through the shared
harness ``render_peer.py``, ``--renders K`` in one process) renders it ``--seeds`` times with each of its
samplers, and we render it ``--seeds`` times at our defaults (the scene's settings: the default sampler,
``--threads`` worker threads).  Every render is at ``--res``² and the same sample count, except where a
Mitsuba sampler rounds it: ``ldsampler`` to a power-of-two square (4, 16, 64, 256 …), ``orthogonal`` to a
prime square (``--spp`` 64 → 49 is asked for, 7²), ``stratified``/``multijitter`` to a square; the real
count is printed.

* **Error** = mean over the pixels of the per-pixel variance over the seeds (ddof 1) of the luminance of
  S0 (and of S1).  Both renderers are unbiased (tests/bench/peer_compare.py: the same images within noise)
  and their seeds independent, so this is each render's mean squared error, without a reference (checked
  on ldsampler, rough_sphere_a030, 64²: 1.63e-5 across seeds against 1.70e-5 against a 3072-spp
  reference with its own variance removed).
* **Time** = wall seconds of a render: Mitsuba's ``render_seconds`` (the median over its seeds after the
  first, which includes its JIT compilation), ours the median of ``Renderer.render`` after a warm-up render.
* **Ratio** = (t_M·MSE_M) ÷ (t_ours·MSE_ours): Monte Carlo error² ∝ 1/time, so > 1 means we reach equal
  error first.  The row's verdict races Mitsuba's best sampler (the smallest t·MSE).  Targets (issue 36):
  S0 ≥ 0.5 on every scene, ≥ 1 on fresnel_sphere and cornell_lambert; S1 is reported where measurable
  (not cornell_lambert, where S1 = 0).  Throughput: samples per second, ours ÷ Mitsuba's independent
  sampler's, target ≥ 0.5 on fresnel_sphere, glass_sphere and rough_sphere_a030.

Both sides run one after the other on the same machine in one run (the load average is printed); not
part of the test command.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import glob
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)

from engine.render.renderer import Renderer  # noqa: E402
from engine.scene.loader import load_scene  # noqa: E402

SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
PEERS = os.path.join(SHARED, "peers")
SCENES = ["fresnel_sphere", "fresnel_sphere_au", "glass_sphere", "rough_sphere_a030", "cornell_lambert"]
MITSUBA_SAMPLERS = ["independent", "stratified", "multijitter", "ldsampler", "orthogonal"]
#: scenes whose S1 is 0 (nothing polarises)
NO_S1 = {"cornell_lambert"}
#: the issue's S0 targets (others: 0.5) and the scenes whose throughput is judged
S0_TARGET = {"fresnel_sphere": 1.0, "cornell_lambert": 1.0}
THROUGHPUT_SCENES = {"fresnel_sphere", "glass_sphere", "rough_sphere_a030"}
#: Rec. 709 luminance (Mitsuba's weights, applied to both sides' linear sRGB)
Y = np.array([0.212671, 0.715160, 0.072169])


def mitsuba_count(sampler: str, spp: int) -> int:
    """The sample count Mitsuba renders when asked for ``spp`` (its samplers' rounding rules)."""
    if sampler == "ldsampler":
        r = 2
        while r * r < spp:
            r *= 2
        return r * r
    if sampler in ("stratified", "multijitter"):
        r = int(np.ceil(np.sqrt(spp) - 1e-9))
        return r * r
    if sampler == "orthogonal":
        r = 2
        while r * r < spp or any(r % q == 0 for q in range(2, r)):
            r += 1
        return r * r
    return spp


def asked_count(sampler: str, spp: int) -> int:
    """The count to ask ``sampler`` for: ``spp``, or for orthogonal the largest prime square ≤ ``spp``."""
    if sampler != "orthogonal":
        return spp
    best = 4
    for r in range(2, int(np.sqrt(spp)) + 1):
        if all(r % q for q in range(2, r)):
            best = r * r
    return best


def mse(images: np.ndarray) -> float:
    """Mean over pixels of the per-pixel variance over seeds (axis 0)."""
    return float(images.var(axis=0, ddof=1).mean())


def mitsuba_side(python, scene, sampler, spp, res, seeds, out):
    """(S0 luminance (k, H, W), S1 luminance, seconds per render, real spp) of Mitsuba's renders."""
    asked = asked_count(sampler, spp)
    d = os.path.join(out, f"{scene}_{sampler}")
    os.makedirs(d, exist_ok=True)
    cmd = [python, os.path.join(PEERS, "render_peer.py"), scene, "--res", str(res), "--spp", str(asked),
           "--renders", str(seeds), "--sampler", sampler, "--out", d]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    files = sorted(f for f in glob.glob(os.path.join(d, "*seed*.npy")) if not f.endswith("_lum.npy"))
    imgs = np.array([np.load(f)[:2] @ Y for f in files])
    secs = [json.load(open(f[:-4] + ".json"))["render_seconds"] for f in files]
    return imgs[:, 0], imgs[:, 1], float(np.median(secs[1:] or secs)), mitsuba_count(sampler, asked)


def our_side(scene_name, spp, res, seeds, threads, sampler=None):
    """(S0 luminance (k, H, W), S1 luminance, seconds per render, sampler) of our renders at our defaults
    (``sampler``: that sampler instead of the default)."""
    scene = load_scene(os.path.join(PEERS, "scenes", f"{scene_name}.json"))
    scene.camera.width = scene.camera.height = res
    renderer = Renderer(scene)
    base = dataclasses.replace(scene.settings, spp=spp, threads=threads)
    if sampler:                 # "sobol" or "sobol/one_sequence": a sampler and its RenderSettings.halves
        name, _, halves = sampler.partition("/")
        base = dataclasses.replace(base, sampler=name, **({"halves": halves} if halves else {}))
    renderer.render(dataclasses.replace(base, seed=seeds))             # warm-up: kernels, memory
    imgs, secs = [], []
    for seed in range(seeds):
        t = time.perf_counter()
        stokes = renderer.render(dataclasses.replace(base, seed=seed)).stokes()
        secs.append(time.perf_counter() - t)
        imgs.append(stokes[:2] @ Y)
    imgs = np.array(imgs)
    return imgs[:, 0], imgs[:, 1], float(np.median(secs)), f"{base.sampler}/{base.halves}"


def row(scene, e_o, t_o, ours_sampler, sides, spp, first=True) -> int:
    """Print the table row of one of our samplers against Mitsuba's ``sides``; the targets it misses (counted for
    the first of ``--ours`` only)."""
    ratio = {s: v[0] * v[2] / (t_o * e_o[0]) for s, v in sides.items()}
    best = min(sides, key=lambda s: sides[s][0] * sides[s][2])
    t_b, n_b, e_b0, e_b1 = sides[best]
    r1 = "—" if scene in NO_S1 or e_o[1] == 0 else f"{t_b * e_b1 / (t_o * e_o[1]):.2f}"
    target = S0_TARGET.get(scene, 0.5)
    ok = ratio[best] >= target
    thr, misses = "", int(not ok)
    if "independent" in sides:
        t_i, n_i = sides["independent"][:2]
        tr = (spp / t_o) / (n_i / t_i)
        thr = f"{tr:.2f}" + ((" PASS" if tr >= 0.5 else " MISS") if scene in THROUGHPUT_SCENES else "")
        misses += scene in THROUGHPUT_SCENES and tr < 0.5
    # noise per sample (MSE × spp: Monte Carlo MSE ∝ 1/spp), ours ÷ Mitsuba's, each sampler
    per_sample = {s: spp * e_o[0] / (v[1] * v[2]) for s, v in sides.items()}
    every = ", ".join(f"{s} {r:.2f} ({per_sample[s]:.2f})" for s, r in ratio.items())
    print(f"| {scene} | {t_o:.2f} ({ours_sampler}), {e_o[0]:.2e} / {e_o[1]:.2e} | {best} ({n_b}) {t_b:.2f}, "
          f"{e_b0:.2e} / {e_b1:.2e} | {ratio[best]:.2f} (≥ {target:g}) {'PASS' if ok else 'MISS'} | {r1} "
          f"| {every} | {thr} |", flush=True)
    return misses if first else 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--samplers", default=",".join(MITSUBA_SAMPLERS), help="Mitsuba's samplers raced")
    ap.add_argument("--ours", default="", help="our samplers, a comma list, each raced against the same Mitsuba "
                    "renders (default: the scene's, i.e. the default sampler); 'sobol/independent': with those "
                    "RenderSettings.halves")
    ap.add_argument("--mitsuba-python", default=os.environ.get("MITSUBA_PYTHON", "/work/peerenv/bin/python"))
    a = ap.parse_args(argv)
    if a.seeds < 3:
        ap.error("--seeds: at least 3 (the error is a variance over seeds; the first Mitsuba render is not timed)")
    if not os.path.exists(a.mitsuba_python):
        ap.error(f"--mitsuba-python: {a.mitsuba_python} not found (Mitsuba 3 with libLLVM is needed)")
    load = os.getloadavg()
    print(f"# peer race, {datetime.datetime.now():%Y-%m-%d %H:%M}: {a.res}², {a.spp} spp asked, {a.seeds} seeds, "
          f"ours {a.threads} thread(s); load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print("| scene | ours (sampler) s, MSE S0 / S1 | Mitsuba best (spp) s, MSE S0 / S1 | S0 ratio (target) | S1 ratio "
          "| every Mitsuba sampler: S0 ratio (S0 MSE per sample ours ÷ Mitsuba's) | throughput ours ÷ Mitsuba |")
    print("|---|---|---|---|---|---|---|")
    misses = 0
    with tempfile.TemporaryDirectory() as out:
        for scene in a.scenes.split(","):
            sides = {}
            for s in a.samplers.split(","):
                m0, m1, t_m, real = mitsuba_side(a.mitsuba_python, scene, s, a.spp, a.res, a.seeds, out)
                sides[s] = (t_m, real, mse(m0), mse(m1))
            for k, ours in enumerate(a.ours.split(",")):
                o0, o1, t_o, ours_sampler = our_side(scene, a.spp, a.res, a.seeds, a.threads, ours)
                misses += row(scene, (mse(o0), mse(o1)), t_o, ours_sampler, sides, a.spp, first=k == 0)
    print(f"# {misses} target(s) missed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
