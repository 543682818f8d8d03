"""Throughput and memory: our engine (polarised and unpolarised) next to Mitsuba 3, in one run.

    python tests/bench/bench_engine.py [--scenes a,b] [--spp 8] [--mitsuba-python PY]
                                       [--mitsuba-spp 64] [--scalar-spp 4] [--out bench.md]

For every scene: wall time, samples per second and peak resident memory of
  - ours, full Mueller transport (spectral, 4 wavelengths per path),
  - ours, polarisation off (scalar transport, same paths),
  - Mitsuba 3 ``llvm_ad_spectral_polarized`` and ``scalar_spectral_polarized``
    (through shared/peers/render_peer.py with the given Python; skipped if it
    cannot import mitsuba),
each in its own process (peak RSS from wait4), all on this machine in this
run, so the ratios are comparable; every measurement is repeated (--repeats,
interleaved) and the fastest run kept, because this VM's speed varies.  Mitsuba's time is measured around its
render call by render_peer.py (scene loading and JIT compilation included
for LLVM; the first LLVM render of a session also fills Dr.Jit's kernel
cache, so a warm-up render is made first).  Prints a Markdown table.
Not part of the test command: benchmarks never run as tests.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
PEERS = os.path.join(SHARED, "peers")
DEFAULT_SCENES = ["plane_brewster", "fresnel_sphere", "glass_sphere", "rough_sphere_a030", "cornell_lambert"]


def run_measured(cmd):
    """Run cmd; return (stdout, wall seconds, peak RSS in MB of that very process, from wait4)."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, text=True)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{stderr[-2000:]}")
    return stdout, wall, usage.ru_maxrss / 1024


def ours_once(scene_name, spp, polarisation, threads=0):
    """Child mode: render one scene and print a JSON line with timing and peak RSS."""
    sys.path.insert(0, REPO)
    from engine.render.renderer import Renderer
    from engine.scene.loader import load_scene
    scene = load_scene(os.path.join(PEERS, "scenes", f"{scene_name}.json"))
    scene.settings.spp = spp
    scene.settings.polarisation = polarisation
    scene.settings.threads = threads
    renderer = Renderer(scene)
    # Time spent in Embree (closest-hit and shadow queries incl. their float32 conversions),
    # summed over threads: its share of the wall time is meaningful for the 1-thread run.
    inside = [0.0]
    compiled = renderer.compiled
    for name in ("intersect", "occluded"):
        method = getattr(compiled, name)

        def timed(*a, _method=method, **k):
            t = time.perf_counter()
            try:
                return _method(*a, **k)
            finally:
                inside[0] += time.perf_counter() - t
        setattr(compiled, name, timed)
    t0 = time.perf_counter()
    result = renderer.render()
    seconds = time.perf_counter() - t0
    print(json.dumps({"seconds": seconds, "samples": result.stats["samples"], "rays": result.stats["rays"],
                      "shadow_rays": result.stats["shadow_rays"], "compile_seconds": renderer.compile_seconds,
                      "embree_seconds": inside[0], "kernels": result.stats.get("kernels", "")}))


def mitsuba_once(python, scene_name, variant, spp, outdir):
    """One Mitsuba render through render_peer.py; its own render time (render_s) and our wait4 peak RSS."""
    cmd = [python, os.path.join(PEERS, "render_peer.py"), scene_name, "--variant", variant, "--spp", str(spp),
           "--out", outdir]
    _, wall, peak = run_measured(cmd)
    metas = sorted((os.path.join(outdir, f) for f in os.listdir(outdir)
                    if f.startswith(f"{scene_name}__{variant}__") and f.endswith(".json")), key=os.path.getmtime)
    with open(metas[-1]) as fh:
        meta = json.load(fh)
    return {"seconds": float(meta["render_seconds"]), "samples": meta["width"] * meta["height"] * spp,
            "peak_rss_mb": peak, "wall": wall}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(DEFAULT_SCENES))
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--mitsuba-python", default=os.environ.get("MITSUBA_PYTHON", ""))
    ap.add_argument("--mitsuba-spp", type=int, default=64)
    ap.add_argument("--scalar-spp", type=int, default=4)
    ap.add_argument("--out", default="")
    ap.add_argument("--repeats", type=int, default=3,
                    help="runs per measurement; the fastest is kept (this VM's speed varies run to run)")
    ap.add_argument("--child", nargs=4, metavar=("SCENE", "SPP", "POLARISATION", "THREADS"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        ours_once(args.child[0], int(args.child[1]), args.child[2], int(args.child[3]))
        return 0

    have_mitsuba = bool(args.mitsuba_python) and subprocess.run(
        [args.mitsuba_python, "-c", "import mitsuba"], capture_output=True).returncode == 0
    tmp = tempfile.mkdtemp(prefix="polar_bench_")
    rows = []
    if have_mitsuba:   # warm Dr.Jit's kernel cache once
        mitsuba_once(args.mitsuba_python, "conv_s3_check", "llvm_ad_spectral_polarized", 16, tmp)
    for scene in args.scenes.split(","):
        res = {}
        for _ in range(args.repeats):     # interleaved, so slow phases of the machine hit every renderer
            for mode, threads in (("full", 0), ("off", 0), ("full1", 1)):
                out, _, peak = run_measured([sys.executable, __file__, "--child", scene, str(args.spp),
                                             mode.rstrip("1"), str(threads)])
                r = json.loads(out.strip().splitlines()[-1])
                r["peak_rss_mb"] = peak
                if mode not in res or r["seconds"] < res[mode]["seconds"]:
                    res[mode] = r
            if have_mitsuba:
                for variant, spp in (("llvm_ad_spectral_polarized", args.mitsuba_spp),
                                     ("scalar_spectral_polarized", args.scalar_spp)):
                    try:
                        r = mitsuba_once(args.mitsuba_python, scene, variant, spp, tmp)
                    except RuntimeError as e:
                        print(f"{scene} {variant}: {e}", file=sys.stderr)
                        continue
                    if variant not in res or r["seconds"] < res[variant]["seconds"]:
                        res[variant] = r
        rows.append((scene, res))
        print(f"{scene}: done", file=sys.stderr)

    def rate(r):
        return r["samples"] / r["seconds"] / 1e6 if r.get("samples") else float("nan")

    lines = ["| scene | ours full (Msamples/s) | ours off | full/off time | Mitsuba LLVM | Mitsuba scalar |"
             " ours ÷ LLVM | ours ÷ scalar | peak RSS ours / LLVM / scalar (MB) | ours: Mrays/s |"
             " 2 threads ÷ 1 | Embree share (1 thread) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for scene, res in rows:
        full, off = res["full"], res["off"]
        llvm = res.get("llvm_ad_spectral_polarized", {})
        scal = res.get("scalar_spectral_polarized", {})
        rays = (full["rays"] + full["shadow_rays"]) / full["seconds"] / 1e6
        lines.append(
            f"| {scene} | {rate(full):.3f} | {rate(off):.3f} | {full['seconds'] / off['seconds']:.2f}× | "
            f"{rate(llvm) if llvm else float('nan'):.3f} | {rate(scal) if scal else float('nan'):.3f} | "
            f"{rate(full) / rate(llvm) if llvm else float('nan'):.3f} | "
            f"{rate(full) / rate(scal) if scal else float('nan'):.3f} | "
            f"{full['peak_rss_mb']:.0f} / {llvm.get('peak_rss_mb', float('nan')):.0f} / "
            f"{scal.get('peak_rss_mb', float('nan')):.0f} | {rays:.2f} | "
            f"{rate(full) / rate(res['full1']):.2f}× | "
            f"{res['full1']['embree_seconds'] / res['full1']['seconds']:.0%} |")
    kernels = rows[0][1]["full"].get("kernels", "?") if rows else "?"
    text = "\n".join(lines) + f"\n\n(our kernels: {kernels})"
    print(text)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
