"""What accuracy costs: error against wall time for our engine and Mitsuba 3, in one run.

    python tests/bench/accuracy_time.py [--mitsuba-python PY] [--res 128] [--out out/accuracy]

For each scene (peer scenes at --res × --res, plus an HTSG sphere) it renders a reference
(Mitsuba llvm_ad_spectral_polarized at --ref-spp, or ours where Mitsuba cannot render the scene),
then renders with increasing samples per pixel in several configurations and reports the RMSE of
the luminance S0, S1, S2, S3 and DoLP images against the reference, next to the wall time:

- ours: polarisation full / auto / off; spectral (4 wavelengths per path) / mono (1); for the
  HTSG scene also a looser series tolerance (1e-4 instead of 1e-10);
- Mitsuba 3: llvm_ad_spectral_polarized and scalar_spectral_polarized (render call only).

"off" renders S1..S3 = 0, so its S1–S3/DoLP errors show what ignoring polarisation costs.
Writes ``table.md`` and ``accuracy_time.png`` (needs matplotlib: ``pip install matplotlib``; the
table is written without it) into --out.  Not part of the test command.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
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

from engine.materials.htsg import HTSG  # noqa: E402
from engine.render.renderer import Renderer  # noqa: E402
from engine.scene.loader import load_scene  # noqa: E402
from engine.spectral.cie import LUMINANCE_WEIGHTS  # noqa: E402

SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
PEERS = os.path.join(SHARED, "peers")
#: Every timed render runs this many times (same image); the fastest time is kept (machine noise).
REPEATS = 2
SCENES = ["plane_brewster", "fresnel_sphere", "glass_sphere", "rough_sphere_a030", "cornell_lambert", "htsg_sphere"]


def load(name, res):
    if name == "htsg_sphere":
        scene = load_scene(os.path.join(REPO, "examples", "thesis_htsg_aluminium.json"))
    else:
        scene = load_scene(os.path.join(PEERS, "scenes", f"{name}.json"))
    scene.camera.width = scene.camera.height = res
    return scene


def luminance_stokes(stokes_rgb):
    return np.einsum("shwc,c->shw", stokes_rgb, LUMINANCE_WEIGHTS)


def errors(img, ref):
    """RMSE of S0..S3 and DoLP (luminance) of img against ref, both (4, H, W)."""
    out = [float(np.sqrt(np.mean((img[i] - ref[i]) ** 2))) for i in range(4)]

    def dolp(y):
        return np.where(y[0] > 0, np.hypot(y[1], y[2]) / np.where(y[0] > 0, y[0], 1.0), 0.0)
    out.append(float(np.sqrt(np.mean((dolp(img) - dolp(ref)) ** 2))))
    return out


def render_ours(scene, spp, polarisation="auto", spectral="spectral", tolerance=None):
    scene = copy.copy(scene)
    scene.settings = dataclasses.replace(scene.settings, spp=spp, polarisation=polarisation, spectral=spectral,
                                         seed=1000 + spp)
    if tolerance is not None:
        scene.materials = {k: (HTSG(m.n, m.k, m.sigma0, m.tau, albedo=m.albedo if m.albedo is not None else 0.0,
                                    exterior_n=m.exterior_n, series_tolerance=tolerance) if isinstance(m, HTSG) else m)
                           for k, m in scene.materials.items()}
    renderer = Renderer(scene)
    best = None
    for _ in range(REPEATS):       # the same image each time (fixed seed); keep the fastest run
        t0 = time.perf_counter()
        result = renderer.render()
        seconds = time.perf_counter() - t0
        best = seconds if best is None else min(best, seconds)
    return luminance_stokes(result.stokes()), best


def render_mitsuba(python, name, variant, spp, res, outdir, seed=0):
    cmd = [python, os.path.join(PEERS, "render_peer.py"), name, "--variant", variant, "--spp", str(spp),
           "--res", str(res), "--seed", str(seed), "--out", outdir]
    stem = f"{name}__{variant}__{res}x{res}__{spp}spp__seed{seed}"
    seconds = None
    for _ in range(REPEATS):       # same seed, same image; keep the fastest render call
        subprocess.run(cmd, check=True, capture_output=True)
        with open(os.path.join(outdir, stem + ".json")) as fh:
            t = json.load(fh)["render_seconds"]
        seconds = t if seconds is None else min(seconds, t)
    return luminance_stokes(np.load(os.path.join(outdir, stem + ".npy")).astype(np.float64)), seconds


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mitsuba-python", default=os.environ.get("MITSUBA_PYTHON", ""))
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spps", default="1,2,4,8,16")
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--out", default=os.path.join(REPO, "out", "accuracy"))
    ap.add_argument("--replot", action="store_true", help="only redraw the plot from --out/rows.json")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    if args.replot:
        with open(os.path.join(args.out, "rows.json")) as fh:
            plot([tuple(r) for r in json.load(fh)], os.path.join(args.out, "accuracy_time.png"))
        return 0
    spps = [int(s) for s in args.spps.split(",")]
    have_mitsuba = bool(args.mitsuba_python) and subprocess.run(
        [args.mitsuba_python, "-c", "import mitsuba"], capture_output=True).returncode == 0
    tmp = tempfile.mkdtemp(prefix="polar_accuracy_")
    # One-off per process: load the compiled kernels (Numba cache) before any timing, as the
    # Mitsuba harness times only its render call.
    render_ours(load(args.scenes.split(",")[0], 16), 1)
    rows = []   # (scene, config, spp, seconds, [rmse S0..S3, DoLP])
    for name in args.scenes.split(","):
        scene = load(name, args.res)
        if have_mitsuba and name != "htsg_sphere":
            ref, _ = render_mitsuba(args.mitsuba_python, name, "llvm_ad_spectral_polarized", args.ref_spp,
                                    args.res, tmp, seed=99)
            ref_label = f"Mitsuba LLVM {args.ref_spp} spp"
        else:
            ref, _ = render_ours(scene, args.ref_spp // 4, "full")
            ref_label = f"ours {args.ref_spp // 4} spp"
        print(f"{name}: reference = {ref_label}", file=sys.stderr)
        configs = [("ours full", dict(polarisation="full")), ("ours auto", dict(polarisation="auto")),
                   ("ours off (unpolarised)", dict(polarisation="off")),
                   ("ours auto, mono 550 nm", dict(polarisation="auto", spectral="mono"))]
        if name == "htsg_sphere":
            configs.append(("ours auto, HTSG tol 1e-4", dict(polarisation="auto", tolerance=1e-4)))
        for label, kw in configs:
            for spp in spps:
                img, sec = render_ours(scene, spp, **kw)
                rows.append((name, label, spp, sec, errors(img, ref)))
        if have_mitsuba and name != "htsg_sphere":
            for variant, label, factor in (("llvm_ad_spectral_polarized", "Mitsuba LLVM", 4),
                                           ("scalar_spectral_polarized", "Mitsuba scalar", 1)):
                for spp in spps:
                    img, sec = render_mitsuba(args.mitsuba_python, name, variant, spp * factor, args.res, tmp)
                    rows.append((name, label, spp * factor, sec, errors(img, ref)))
    lines = [f"Resolution {args.res}×{args.res}; RMSE of the luminance Stokes images against the reference; "
             "time = wall time of the render call.", "",
             "| scene | configuration | spp | seconds | RMSE S0 | RMSE S1 | RMSE S2 | RMSE S3 | RMSE DoLP |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, label, spp, sec, e in rows:
        lines.append(f"| {name} | {label} | {spp} | {sec:.2f} | " + " | ".join(f"{v:.2e}" for v in e) + " |")
    summary = equal_error_summary(rows)
    lines += ["", "Speed to equal error (RMSE² = a/spp + c fitted per scene with c, the reference's own "
              "noise, shared; ratio of a·t/spp at each configuration's largest spp; > 1: ours reaches a "
              "given error faster):", ""] + summary
    with open(os.path.join(args.out, "table.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    with open(os.path.join(args.out, "rows.json"), "w") as fh:
        json.dump(rows, fh)
    print("\n".join(lines))
    plot(rows, os.path.join(args.out, "accuracy_time.png"))
    return 0


def equal_error_summary(rows, ours="ours auto", peers=("Mitsuba scalar", "Mitsuba LLVM")):
    """Markdown rows: per scene and quantity (S0, S1), how much faster ours reaches equal error.

    Each configuration's squared error is fitted as RMSE²(spp) = a/spp + c, with c shared by all
    configurations of a scene (the reference's own noise, which the renders cannot go below) and
    a the configuration's variance per sample.  The time to reach an error e ≫ √c is then
    a·(t/spp)/e², so the ratio of two renderers' times to equal error is the ratio of their
    a·(t/spp) (t at the configuration's largest spp).
    """
    out = ["| scene | quantity | ours auto ÷ Mitsuba scalar (speed to equal error) | ours auto ÷ Mitsuba LLVM |"
           " reference noise floor √c |",
           "|---|---|---|---|---|"]
    labels = (ours,) + tuple(peers)
    for scene in dict.fromkeys(r[0] for r in rows):
        for q, qname in ((0, "S0"), (1, "S1")):
            pts = [(labels.index(r[1]), r[2], r[3], r[4][q]) for r in rows if r[0] == scene and r[1] in labels]
            if not pts or min(p[3] for p in pts) <= 0 or len({p[0] for p in pts}) < 2:
                continue
            k = len(labels)
            A = np.zeros((len(pts), k + 1))
            y = np.empty(len(pts))
            for row, (i, spp, _, err) in enumerate(pts):
                w = 1.0 / (err * err)                     # relative residuals
                A[row, i] = w / spp
                A[row, k] = w
                y[row] = 1.0
            coef = np.linalg.lstsq(A, y, rcond=None)[0]
            cost = {}
            for i in range(k):
                mine = [p for p in pts if p[0] == i]
                if mine and coef[i] > 0:
                    spp, t = max((p[1], p[2]) for p in mine)
                    cost[i] = coef[i] * t / spp
            if 0 not in cost:
                continue
            cells = [f"{cost[i] / cost[0]:.2f}×" if i in cost else "–" for i in range(1, k)]
            out.append(f"| {scene} | {qname} | " + " | ".join(cells) + f" | {np.sqrt(max(coef[k], 0.0)):.1e} |")
    return out


def plot(rows, path):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: table only (pip install matplotlib for the plot)", file=sys.stderr)
        return
    from matplotlib.ticker import NullFormatter
    scenes = sorted({r[0] for r in rows}, key=SCENES.index)
    quantities = [(0, "S0"), (1, "S1"), (4, "DoLP")]
    labels_all = list(dict.fromkeys(r[1] for r in rows))
    colours = {label: plt.get_cmap("tab10")(i % 10) for i, label in enumerate(labels_all)}
    fig, axes = plt.subplots(len(quantities), len(scenes), figsize=(3.2 * len(scenes), 2.6 * len(quantities)),
                             squeeze=False)
    for j, name in enumerate(scenes):
        for i, (q, qname) in enumerate(quantities):
            ax = axes[i][j]
            for label in dict.fromkeys(r[1] for r in rows if r[0] == name):
                pts = sorted((r[3], r[4][q]) for r in rows if r[0] == name and r[1] == label)
                if pts and max(p[1] for p in pts) > 0:
                    ax.loglog(*zip(*pts), marker="o", ms=3, label=label, color=colours[label])
            if not ax.lines:
                ax.text(0.5, 0.5, "exactly 0 for every\nconfiguration", ha="center", va="center", fontsize=8,
                        transform=ax.transAxes)
                ax.set_xticks([])
                ax.set_yticks([])
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.yaxis.set_minor_formatter(NullFormatter())
            ax.set_title(f"{name}: {qname}", fontsize=8)
            ax.tick_params(labelsize=7)
            if i == len(quantities) - 1:
                ax.set_xlabel("wall time [s]", fontsize=7)
            if j == 0:
                ax.set_ylabel("RMSE", fontsize=7)
    handles, labels = axes[0][0].get_legend_handles_labels()
    for ax in axes.ravel():
        hs, ls = ax.get_legend_handles_labels()
        for hh, ll in zip(hs, ls):
            if ll not in labels:
                handles.append(hh)
                labels.append(ll)
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=7)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(path, dpi=110)
    print(f"wrote {path}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
