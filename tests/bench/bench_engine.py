"""Speed benchmark of issue 16: every target measured side by side in one run, with PASS/MISS.

    python tests/bench/bench_engine.py [--scenes a,b] [--res 128] [--spp 32] [--mitsuba-spp 128]
                                       [--ref-spp 2048] [--mitsuba-python PY] [--skip blender,cycles,memory]
                                       [--out bench.md] [--sampler sobol,cycles] [--full]

Prints one Markdown table per target (the issue's target next to each measured ratio):

1. **Time to equal error** (peer scenes, ``shared/peers``): ours (polarisation auto, 2 threads) and
   Mitsuba 3 ``llvm_ad_spectral_polarized`` each render every scene twice (seeds 0 and 1) at the same
   resolution; the error is the RMSE of the luminance S0 (and S1) against a high-spp reference, with
   the reference's own noise subtracted (error² − var_ref, var_ref from its two halves).  Monte Carlo
   error² ∝ 1/time, so time to equal error ours ÷ Mitsuba = (t_M·e_M²)/(t_ours·e_ours²), > 1: we are
   faster.  Next to it, that ratio ÷ the Embree share of table 3: what our sampling would reach if
   only the ray queries took time (a target above it needs cheaper queries, not cheaper shading
   alone; a 2-thread ratio ÷ a 1-thread share, so an estimate).  References: Mitsuba,
   2 × ``--ref-spp`` (``render_peer.py``), cached in ``out/bench_refs/`` (git-ignored); without
   Mitsuba, our own 2 × ``--ref-spp`` render.  Where our
   S0 legitimately differs from Mitsuba's (``cornell_lambert``: RGB → spectrum upsampling of the
   coloured walls) our S0 error is our noise alone (from the two seeds), marked ‡.
2. **Throughput**: Msamples/s and Mrays/s (camera + bounce + shadow rays) of ours next to Mitsuba
   LLVM (and ``scalar_spectral_polarized`` at ``--mitsuba-scalar-spp``), peak RSS of each process.
3. **Embree share**: CPU time inside the Embree closest-hit and shadow queries ÷ CPU time of a
   1-thread render (the ``intersect``/``occluded`` calls incl. their float32 conversions; CPU time
   is not inflated by other processes' load as wall time is; the wall-time share in brackets).
4. **Thread scaling**: throughput with 2 threads ÷ 1 thread, the fastest of ``--scaling-repeats``
   alternated 1- and 2-thread renders each, with the CPU seconds of both (extra CPU with 2 threads
   is time lost to contention) and the hypervisor's steal during each (/proc/stat: CPU time given to
   other guests, as a share of both cores' wall time; a 2-thread render waits for the slower core),
   and the same ratio for the Embree queries alone (``embree_alone_scaling``: the rays of a short
   render re-queried in two halves, one thread after the other or two at once; no code of ours, no
   GIL between them): a reference for what the machine gives a GIL-free workload of that scene.
5. **Full Stokes ÷ scalar**: render time with ``--polarisation full`` ÷ ``--polarisation off``.
6. **Blender ÷ CLI**: ``tests/bench/blender_overhead.py`` (F12 render in bpy vs the engine render of
   the same exported scene, and where Blender's extra time goes).
7. **Peak memory** of the 1080p demo (``examples/demo.json`` at 1920×1080, 1 spp); quick runs render
   a proxy at ``--memory-res`` and add the engine's own film + batch estimate
   (``engine.render.renderer.memory_estimate``: 136 bytes per pixel) for the missing pixels.
8. **Cycles**: ``tests/bench/cycles_noise.py`` (the Cycles parity scenes: time and noise of S0 at
   equal samples, variance × time Polar ÷ Cycles).

Our renders run in one child process per scene (kernels loaded by ``Renderer.warm_up`` first, for
each transport the jobs use; the times are those of ``Renderer.render``, as Mitsuba's are of its
render call), Mitsuba's through ``render_peer.py`` (its first render of a scene includes its JIT
compilation; the fastest of three is kept).  ``--full`` uses 256², more samples and every scene,
renders the demo at 1080p, and rewrites the tables in docs/benchmarks/performance.md between the
``bench:begin`` / ``bench:end`` markers.

``--sampler`` takes a comma list (``--full``: the default ``sobol`` and ``cycles``): every sampler's renders
are measured in the same run against the same references and Mitsuba renders (and, for Cycles, the
same Cycles renders).  The first sampler gets tables 1–8; each further one the tables that depend on
our sampler (1–5 and 8), numbered with its initial (1s, 2s, 3s–5s, 8s).
Benchmarks never run as tests.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
SHARED = os.environ.get("POLAR_SHARED") or next(
    (d for d in (os.path.join(os.path.dirname(REPO), "shared"), "/work/shared") if os.path.isdir(d)), "shared")
PEERS = os.path.join(SHARED, "peers")
REF_DIR = os.path.join(REPO, "out", "bench_refs")
DEFAULT_MITSUBA = "/work/peerenv/bin/python"
DEFAULT_SCENES = ["fresnel_sphere", "fresnel_sphere_au", "glass_sphere", "rough_sphere_a030", "cornell_lambert",
                  "plane_brewster"]
#: Issue 16 targets.  Time to equal error (S0), ours ÷ Mitsuba LLVM, at least:
EQUAL_ERROR_TARGET = {"fresnel_sphere": 1.0, "fresnel_sphere_au": 0.5, "glass_sphere": 0.5,
                      "rough_sphere_a030": 0.5, "cornell_lambert": 0.5}
SPHERE_SCENES = {"fresnel_sphere", "fresnel_sphere_au", "glass_sphere", "rough_sphere_a030"}
EMBREE_SHARE_TARGET = 0.5          # of a 1-thread render, sphere scenes
THREADS_TARGET = 1.9               # 2 threads ÷ 1
CAPTURED_RAYS = 1 << 19            # rays of a render re-queried alone for the Embree-alone thread scaling
FULL_OVER_SCALAR_TARGET = 1.3      # full Stokes time ÷ scalar time, at most
BLENDER_TARGET = 1.10              # Blender time ÷ CLI time, at most
MEMORY_TARGET_GB = 2.0             # 1080p demo, peak RSS below
CYCLES_TARGET = 3.0                # variance × time of S0, Polar ÷ Cycles, at most (diffuse scenes)
#: Cycles scenes of a quick run (tests/bench/cycles_noise.py; --full: all of them)
CYCLES_QUICK = ["area_square", "point_radius", "all_lights", "eight_points_world"]
#: Scenes whose S0 differs from Mitsuba's by design (peer_compare.S0_DIFFERS): our error = our noise.
S0_DIFFERS = {"cornell_lambert"}


# ---------------------------------------------------------------------------------------- helpers

def run_measured(cmd, env=None):
    """Run cmd; return (stdout, wall seconds, peak RSS in MB of that very process, from wait4)."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, text=True, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{stderr[-2000:]}")
    return stdout, wall, usage.ru_maxrss / 1024


def json_lines(stdout):
    return [json.loads(line) for line in stdout.splitlines() if line.startswith("{")]


def verdict(value, target, at_least=True):
    if value is None or not np.isfinite(value):
        return "—"
    return "PASS" if (value >= target if at_least else value <= target) else "MISS"


def fmt(value, spec=".2f", suffix=""):
    return "—" if value is None or not np.isfinite(value) else f"{value:{spec}}{suffix}"


# ------------------------------------------------------------------------------ child: our renders

def steal_seconds():
    """Seconds of CPU time stolen from this virtual machine so far (all cores; /proc/stat), or None."""
    try:
        with open("/proc/stat") as fh:
            fields = fh.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def ours_child(cfg):
    """Child mode: our renders of one scene, one JSON line each; images (luminance Stokes) to .npy."""
    sys.path.insert(0, REPO)
    from engine.render.renderer import Renderer
    from engine.scene.loader import load_scene
    from engine.spectral.cie import LUMINANCE_WEIGHTS
    path = cfg["scene"] if cfg["scene"].endswith(".json") else os.path.join(PEERS, "scenes", f"{cfg['scene']}.json")
    scene = load_scene(path)
    if cfg.get("width"):
        scene.camera.width, scene.camera.height = cfg["width"], cfg["height"]
    renderer = Renderer(scene)
    # seconds inside Embree (wall, summed over threads), number of queries, CPU seconds of the calling threads
    inside = [0.0, 0, 0.0]
    compiled = renderer.compiled
    queries = {}            # the untimed methods, for embree_alone_scaling
    captured = []           # (method, first half's (args, kwargs), second half's), copies
    counted = {"intersect": 0, "occluded": 0}
    capturing = [False]     # only in a job that asks for it: the copies would add to a timed render
    for name in ("intersect", "occluded"):
        method = queries[name] = getattr(compiled, name)

        def timed(*a, _method=method, _name=name, **k):
            if capturing[0] and counted[_name] < CAPTURED_RAYS:
                n = a[0].shape[-1]
                counted[_name] += n
                halves = (slice(0, n // 2), slice(n // 2, n))
                captured.append((queries[_name], *(split_call(a, k, sl) for sl in halves)))
            t, c = time.perf_counter(), time.thread_time()
            try:
                return _method(*a, **k)
            finally:
                inside[0] += time.perf_counter() - t
                inside[1] += 1
                inside[2] += time.thread_time() - c
        setattr(compiled, name, timed)
    base = scene.settings

    def settings(job):
        return dataclasses.replace(base, spp=job["spp"], seed=job.get("seed", 0),
                                   polarisation=job.get("polarisation", "auto"), threads=job.get("threads", 0),
                                   sampler=job.get("sampler", base.sampler))

    # every kernel of every job's transport compiled or loaded before the timed renders
    for polarisation in dict.fromkeys(job.get("polarisation", "auto") for job in cfg["jobs"]):
        renderer.warm_up(settings({"spp": 1, "polarisation": polarisation}))
    for job in cfg["jobs"]:
        st = settings(job)
        capturing[0] = bool(job.get("capture"))
        inside[:] = [0.0, 0, 0.0]
        steal0 = steal_seconds()
        t0, c0 = time.perf_counter(), time.process_time()
        result = renderer.render(st)
        seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
        steal1 = steal_seconds()
        if job.get("save"):
            np.save(job["save"], np.einsum("shwc,c->shw", result.stokes(), LUMINANCE_WEIGHTS))
        s = result.stats
        print(json.dumps({"job": job["name"], "seconds": seconds, "cpu_seconds": cpu, "samples": s["samples"],
                          "rays": s["rays"], "shadow_rays": s["shadow_rays"],
                          # None if the tracer no longer goes through these two methods (not measured)
                          "embree_seconds": inside[0] if inside[1] else None,
                          "embree_cpu_seconds": inside[2] if inside[1] else None,
                          "transport": s.get("transport", ""), "kernels": s.get("kernels", ""),
                          "compile_seconds": renderer.compile_seconds,
                          # CPU time the hypervisor gave other guests while this render ran, as a share of
                          # the machine's (all cores) wall time: a 2-thread render waits for the slower core
                          "steal": None if steal0 is None else (steal1 - steal0) / (seconds * (os.cpu_count() or 1))}),
              flush=True)
    if cfg.get("embree_alone") and captured:
        print(json.dumps({"job": "embree_alone", **embree_alone_scaling(captured, cfg["embree_alone"])}),
              flush=True)


def split_call(args, kwargs, sl):
    """Copies of a ray query's arguments restricted to the rays ``sl`` (arrays sliced on their last,
    per-ray axis; anything else as it is)."""
    def part(x):
        return np.ascontiguousarray(x[..., sl]) if isinstance(x, np.ndarray) and x.ndim else x
    return tuple(part(x) for x in args), {key: part(x) for key, x in kwargs.items()}


def embree_alone_scaling(captured, repeats):
    """The thread scaling of the Embree queries alone: the render's own rays (its first calls of each
    kind, up to CAPTURED_RAYS rays of each), each call split into two halves that one thread queries one
    after the other or two threads at once (compiled loops or embreex: no GIL held; the threads are
    started before the clock, behind a barrier), alternated, fastest of ``repeats`` each.  Nothing of ours
    runs in between: a reference for what this machine gives a GIL-free compiled workload of the scene
    (shared caches, memory, the hypervisor), to read the render's own scaling against."""
    import threading

    def query(k):
        for method, *halves in captured:
            args, kwargs = halves[k]
            method(*args, **kwargs)

    def timed(threads):
        if threads == 1:
            t = time.perf_counter()
            query(0)
            query(1)
            return time.perf_counter() - t
        start = threading.Barrier(3)

        def work(k):
            start.wait()
            query(k)
        workers = [threading.Thread(target=work, args=(k,)) for k in range(2)]
        for w in workers:
            w.start()
        start.wait()
        t = time.perf_counter()
        for w in workers:
            w.join()
        return time.perf_counter() - t

    timed(1)
    best = {1: float("inf"), 2: float("inf")}
    for _ in range(repeats):
        for threads in (1, 2):
            best[threads] = min(best[threads], timed(threads))
    rays = sum(first[0][0].shape[-1] + second[0][0].shape[-1] for _, first, second in captured)
    return {"rays": rays, "one_thread_seconds": best[1], "two_thread_seconds": best[2], "scaling": best[1] / best[2]}


def memory_child(cfg):
    """Child mode: one render of the demo scene at the given size (peak RSS measured by the parent)."""
    sys.path.insert(0, REPO)
    from engine.render.renderer import Renderer
    from engine.scene.loader import load_scene
    scene = load_scene(os.path.join(REPO, "examples", "demo.json"))
    scene.camera.width, scene.camera.height = cfg["width"], cfg["height"]
    scene.settings = dataclasses.replace(scene.settings, spp=cfg["spp"])
    t0 = time.perf_counter()
    Renderer(scene).render()
    print(json.dumps({"seconds": time.perf_counter() - t0}))


def run_ours(scene, res, jobs, embree_alone=0):
    cfg = {"scene": scene, "width": res, "height": res, "jobs": jobs, "embree_alone": embree_alone}
    out, _, peak = run_measured([sys.executable, __file__, "--child", json.dumps(cfg)])
    return {r["job"]: r for r in json_lines(out)}, peak


# ---------------------------------------------------------------------------------------- Mitsuba

def mitsuba_renders(python, scene, variant, spp, res, seed, renders, outdir):
    """Render with render_peer.py; (list of luminance Stokes images, list of render seconds, peak RSS MB)."""
    cmd = [python, os.path.join(PEERS, "render_peer.py"), scene, "--variant", variant, "--spp", str(spp),
           "--res", str(res), "--seed", str(seed), "--renders", str(renders), "--out", outdir]
    _, _, peak = run_measured(cmd)
    images, seconds = [], []
    for k in range(renders):
        stem = os.path.join(outdir, f"{scene}__{variant}__{res}x{res}__{spp}spp__seed{seed + k}")
        images.append(np.load(stem + "_lum.npy").astype(np.float64))
        with open(stem + ".json") as fh:
            seconds.append(float(json.load(fh)["render_seconds"]))
    return images, seconds, peak


def reference(scene, res, ref_spp, mitsuba):
    """(mean luminance Stokes image (4, H, W), variance of that mean per component (4,), source)."""
    os.makedirs(REF_DIR, exist_ok=True)
    source = "mitsuba" if mitsuba else "ours"
    path = os.path.join(REF_DIR, f"{scene}__{source}__{res}__{ref_spp}x2.npz")
    if not os.path.exists(path):
        if mitsuba:
            imgs, _, _ = mitsuba_renders(mitsuba, scene, "llvm_ad_spectral_polarized", ref_spp, res, 1000, 2, REF_DIR)
        else:
            saves = [os.path.join(REF_DIR, f"{scene}__ours__{res}__{ref_spp}__seed{s}.npy") for s in (1000, 1001)]
            run_ours(scene, res, [{"name": f"ref{s}", "spp": ref_spp, "seed": s, "save": p}
                                  for s, p in zip((1000, 1001), saves)])
            imgs = [np.load(p) for p in saves]
        np.savez(path, a=imgs[0], b=imgs[1])
    z = np.load(path)
    a, b = z["a"], z["b"]
    return (a + b) / 2, np.mean((a - b) ** 2, axis=(1, 2)) / 4, source


def error2(images, ref, ref_var, noise_only=False):
    """Mean squared error per Stokes component (4,) of the renders, reference noise removed.

    ``noise_only``: the renders' own variance from their seed-to-seed spread (no reference)."""
    if noise_only:
        a, b = images[:2]
        return np.mean((a - b) ** 2, axis=(1, 2)) / 2
    return np.mean([np.mean((img - ref) ** 2, axis=(1, 2)) for img in images], axis=0) - ref_var


# ------------------------------------------------------------------------------------------- main

def measure_scene(scene, args, tmp, mitsuba, sampler, peer):
    """Our renders of ``scene`` with ``sampler`` beside the reference and Mitsuba's renders, which
    ``peer`` (a dict kept per scene) holds after the first sampler: every sampler of a run is compared
    with the same Mitsuba renders."""
    saves = [os.path.join(tmp, f"{scene}_{sampler}_ours_seed{s}.npy") for s in (0, 1)]
    # 1- and 2-thread renders alternate (a change in the machine's load hits both alike); the fastest
    # of each is kept.  The 2-thread renders of seeds 0 and 1 are also the error measurement's.
    jobs = []
    for k in range(max(args.scaling_repeats, 2)):
        jobs.append({"name": f"auto_1thread{k}", "spp": args.spp, "seed": k, "threads": 1})
        jobs.append({"name": f"auto{k}", "spp": args.spp, "seed": k, "threads": 2,
                     **({"save": saves[k]} if k < 2 else {})})
    jobs += [{"name": "full", "spp": args.spp, "polarisation": "full"},
             {"name": "off", "spp": args.spp, "polarisation": "off"}]
    for job in jobs:            # (the references keep the scene's sampler: any unbiased one will do)
        job["sampler"] = sampler
    ours, peak = run_ours(scene, args.res, jobs)
    # the Embree-alone scaling in a child of its own (its copies of the rays stay out of the peak RSS
    # above): the rays of a short render, in no table
    alone, _ = run_ours(scene, args.res, [{"name": "capture", "spp": max(8, args.spp // 8), "seed": 7,
                                           "capture": True, "sampler": sampler}],
                        embree_alone=max(args.scaling_repeats, 2) + 2)
    runs = range(max(args.scaling_repeats, 2))
    best = min((ours["auto0"], ours["auto1"]), key=lambda r: r["seconds"])
    row = {"scene": scene, "sampler": sampler, "ours": ours, "ours_best": best, "ours_peak": peak,
           "two_threads": min((ours[f"auto{k}"] for k in runs), key=lambda r: r["seconds"]),
           "one_thread": min((ours[f"auto_1thread{k}"] for k in runs), key=lambda r: r["seconds"]),
           "embree_alone": alone.get("embree_alone")}
    if "ref" not in peer:
        peer["ref"] = reference(scene, args.res, args.ref_spp, mitsuba)
    ref, ref_var, source = peer["ref"]
    row["ref_source"] = source
    row["ours_e2"] = error2([np.load(p) for p in saves], ref, ref_var)
    row["ours_noise_only"] = scene in S0_DIFFERS and source == "mitsuba"
    if row["ours_noise_only"]:
        row["ours_e2"][0] = error2([np.load(p) for p in saves], None, None, noise_only=True)[0]
    row["ref_var"] = ref_var
    if mitsuba and "llvm" not in peer:
        imgs, secs, mpeak = mitsuba_renders(mitsuba, scene, "llvm_ad_spectral_polarized", args.mitsuba_spp, args.res,
                                            0, 3, tmp)
        peer["llvm"] = {"seconds": min(secs), "samples": args.res ** 2 * args.mitsuba_spp, "peak": mpeak,
                        "e2": error2(imgs[:2], ref, ref_var)}
        if args.mitsuba_scalar_spp:
            _, secs, speak = mitsuba_renders(mitsuba, scene, "scalar_spectral_polarized", args.mitsuba_scalar_spp,
                                             args.res, 0, 1, tmp)
            peer["scalar"] = {"seconds": min(secs), "samples": args.res ** 2 * args.mitsuba_scalar_spp,
                              "peak": speak}
    row.update({k: peer[k] for k in ("llvm", "scalar") if k in peer})
    return row


def equal_error_ratio(row, k):
    """Time to equal error in Stokes component k, ours ÷ Mitsuba (> 1: ours faster); None if undefined."""
    llvm = row.get("llvm")
    if not llvm:
        return None
    e_o, e_m = row["ours_e2"][k], llvm["e2"][k]
    if e_o <= 0 or e_m <= 0:        # at the reference's noise (or S1 ≡ 0 in both)
        return None
    return (llvm["seconds"] * e_m) / (row["ours_best"]["seconds"] * e_o)


def rate(r):
    return r["samples"] / r["seconds"] / 1e6


def embree_share(row):
    """(CPU-time share, wall-time share) of the Embree queries in the fastest 1-thread render, or Nones."""
    one = row["one_thread"]
    embree, embree_cpu = one["embree_seconds"], one.get("embree_cpu_seconds")
    share_wall = None if embree is None else embree / one["seconds"]
    return (share_wall if embree_cpu is None else embree_cpu / one["cpu_seconds"]), share_wall


def tables(rows, blender, memory, cycles, args, header, sampler, suffix=""):
    """The Markdown tables of one sampler's rows: numbered 1–8, or with ``suffix`` appended to each number
    (a second sampler of the same run: the tables that depend on our sampler; Mitsuba's columns are the
    same renders as the first sampler's, Blender ÷ CLI and memory are not repeated)."""
    out = [header, ""] if header else []
    label = f" — {sampler} sampler"
    out += [f"**1{suffix}. Time to equal error, ours ÷ Mitsuba LLVM{label}** (> 1: ours faster; RMSE of luminance "
            f"S0 and S1 against a {rows[0]['ref_source'] if rows else '?'} reference of 2 × {args.ref_spp} spp, its "
            "noise removed; Mitsuba's independent sampler)", "",
            "| scene | ours: s @ spp | RMSE S0 / S1 | Mitsuba: s @ spp | RMSE S0 / S1 | S0 ratio | target | | "
            "S1 ratio | S0 ratio if only Embree took time ⁂ |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        llvm = r.get("llvm", {})
        s0, s1 = equal_error_ratio(r, 0), equal_error_ratio(r, 1)
        target = EQUAL_ERROR_TARGET.get(r["scene"])
        e_o = np.sqrt(np.maximum(r["ours_e2"], 0))
        e_m = np.sqrt(np.maximum(llvm["e2"], 0)) if llvm else None
        mark = " ‡" if r["ours_noise_only"] else ""
        share = embree_share(r)[0]
        out.append(f"| {r['scene']} | {r['ours_best']['seconds']:.2f} @ {args.spp} | {e_o[0]:.2e}{mark} / "
                   f"{e_o[1]:.2e} | " + (f"{llvm['seconds']:.2f} @ {args.mitsuba_spp} | {e_m[0]:.2e} / {e_m[1]:.2e}"
                                         if llvm else "— | —")
                   + f" | {fmt(s0, '.2f', '×')} | " + (f"≥ {target}×" if target else "(none)")
                   + f" | {verdict(s0, target) if target else ''} | {fmt(s1, '.2f', '×')} | "
                   f"{fmt(s0 / share if s0 and share else None, '.2f', '×')} |")
    if any(r["ours_noise_only"] for r in rows):
        out.append("\n‡ our S0 error is our noise alone (S0 differs from Mitsuba's by design: RGB upsampling).")
    out.append("\n⁂ the S0 ratio ÷ the Embree share of table 3: the ratio our sampling would reach if everything but "
               "the ray queries (shading, sampling, transport, Python) took no time (a 2-thread ratio ÷ a "
               "1-thread share: an estimate); a target above it needs cheaper ray queries, not cheaper shading "
               "alone.")
    out += ["", f"**2{suffix}. Throughput{label}** (2 threads; ours polarisation auto)", "",
            "| scene | transport | ours Msamples/s | ours Mrays/s | Mitsuba LLVM Msamples/s | ours ÷ LLVM | "
            "Mitsuba scalar Msamples/s | ours ÷ scalar | peak RSS ours / LLVM (MB) |",
            "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b = r["ours_best"]
        llvm, scal = r.get("llvm"), r.get("scalar")
        mrays = (b["rays"] + b["shadow_rays"]) / b["seconds"] / 1e6
        out.append(f"| {r['scene']} | {b['transport']} | {rate(b):.3f} | {mrays:.2f} | "
                   f"{fmt(rate(llvm) if llvm else None, '.3f')} | "
                   f"{fmt(rate(b) / rate(llvm) if llvm else None, '.3f')} | "
                   f"{fmt(rate(scal) if scal else None, '.3f')} | "
                   f"{fmt(rate(b) / rate(scal) if scal else None, '.3f')} | "
                   f"{r['ours_peak']:.0f} / {fmt(llvm['peak'] if llvm else None, '.0f')} |")
    out += ["", f"**3{suffix}–5{suffix}. Embree share, thread scaling, full Stokes ÷ scalar{label}** (ours; 1- and "
            "2-thread renders "
            f"alternated, fastest of {max(args.scaling_repeats, 2)} each; the Embree share is of the CPU time of "
            "the fastest 1-thread render, wall-time share in brackets)", "",
            "| scene | Embree share, 1 thread | target | | 2 threads ÷ 1 | target | | Embree alone 2 ÷ 1 | "
            "CPU s 1 → 2 threads | steal 1 → 2 threads | full ÷ scalar time | target | |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        o, one, two = r["ours"], r["one_thread"], r["two_threads"]
        share, share_wall = embree_share(r)
        sphere = r["scene"] in SPHERE_SCENES
        scale = rate(two) / rate(one)
        fo = o["full"]["seconds"] / o["off"]["seconds"]
        out.append(f"| {r['scene']} | {fmt(share, '.0%')} ({fmt(share_wall, '.0%')}) | "
                   f"{'≥ 50 %' if sphere else '(none)'} | "
                   f"{verdict(share, EMBREE_SHARE_TARGET) if sphere else ''} | {scale:.2f}× | ≥ {THREADS_TARGET}× | "
                   f"{verdict(scale, THREADS_TARGET)} | "
                   f"{fmt(r['embree_alone']['scaling'] if r.get('embree_alone') else None, '.2f', '×')} | "
                   f"{one['cpu_seconds']:.2f} → {two['cpu_seconds']:.2f} | "
                   f"{fmt(one.get('steal'), '.0%')} → {fmt(two.get('steal'), '.0%')} | "
                   f"{fo:.2f}× | ≤ {FULL_OVER_SCALAR_TARGET}× | "
                   f"{verdict(fo, FULL_OVER_SCALAR_TARGET, at_least=False)} |")
    if blender:
        sp = blender["split"]
        out += ["", f"**6. Blender ÷ CLI** ({blender['width']}×{blender['height']}, {blender['spp']} spp, the "
                "scene of tests/bench/blender_overhead.py)", "",
                "| Blender (s) | CLI: render of the export (s) | ratio | target | | CPU time ratio | "
                "Blender's extra, profiled |", "|---|---|---|---|---|---|---|",
                f"| {blender['blender_seconds']:.2f} | {blender['cli_seconds']:.2f} | {blender['ratio']:.3f} | "
                f"≤ {BLENDER_TARGET} | {verdict(blender['ratio'], BLENDER_TARGET, at_least=False)} | "
                f"{blender['cpu_ratio']:.3f} | export "
                f"{sp['export']:.2f} s, live display {sp['  of which live display']:.2f} s, final passes "
                f"{sp['pass writing (all calls)']:.2f} s of {sp['Blender operator total']:.2f} s |"]
    if memory:
        how = "" if memory["exact"] else f" (extrapolated: {memory['bytes_per_pixel']:.0f} B/pixel)"
        out += ["", "**7. Peak memory, 1080p demo** (examples/demo.json)", "",
                "| rendered at | peak RSS (GB) | 1920×1080 (GB) | target | |", "|---|---|---|---|---|",
                f"| {memory['width']}×{memory['height']}, {memory['spp']} spp | {memory['peak_gb']:.2f} | "
                f"{memory['full_gb']:.2f}{how} | < {MEMORY_TARGET_GB} | "
                f"{verdict(memory['full_gb'], MEMORY_TARGET_GB, at_least=False)} |"]
    if cycles:
        out += ["", f"**8{suffix}. Cycles parity scenes{label}** ({cycles[0]['width']}×{cycles[0]['height']}, "
                f"{cycles[0]['spp']} spp each, σ = per-pixel standard deviation of luminance S0 over lit pixels, "
                "from 2 seeds; Cycles' default Sobol'–Burley pattern)", "",
                "| scene | Cycles s | Polar s | σ Polar ÷ Cycles | variance × time Polar ÷ Cycles | target | |",
                "|---|---|---|---|---|---|---|"]
        for c in cycles:
            p, cy = c["POLAR"], c["CYCLES"]
            vt = p["variance"] * p["seconds"] / (cy["variance"] * cy["seconds"]) if cy["variance"] > 0 else None
            out.append(f"| {c['scene']} | {cy['seconds']:.2f} | {p['seconds']:.2f} | "
                       f"{fmt((p['variance'] / cy['variance']) ** 0.5 if cy['variance'] > 0 else None)} | "
                       f"{fmt(vt, '.2f', '×')} | ≤ {CYCLES_TARGET}× | {verdict(vt, CYCLES_TARGET, at_least=False)} |")
    return "\n".join(out)


def measure_memory(args):
    """Peak RSS of the demo at 1920×1080, or extrapolated linearly in the pixel count from two proxies.

    The proxies (``--memory-res`` and half its width and height) get enough samples per pixel to fill
    every worker's batches, whose memory does not shrink with the image; what grows with the image
    (the film's sums, the finished image) is then linear in the pixel count."""
    sys.path.insert(0, REPO)
    from engine.scene.loader import load_scene
    batch = load_scene(os.path.join(REPO, "examples", "demo.json")).settings.batch_rays
    sizes = [(1920, 1080)] if args.full else [(w // 2, h // 2) for w, h in [tuple(
        int(v) for v in args.memory_res.split("x"))]] + [tuple(int(v) for v in args.memory_res.split("x"))]
    peaks = []
    for w, h in sizes:
        spp = max(1, -(-(os.cpu_count() or 1) * batch // (w * h)))
        _, _, peak = run_measured([sys.executable, __file__, "--memory-child",
                                   json.dumps({"width": w, "height": h, "spp": spp})])
        peaks.append(peak / 1024)
    (w, h) = sizes[-1]
    full = peaks[-1]
    per_pixel = None
    if len(sizes) == 2:
        (w1, h1), (w2, h2) = sizes
        per_pixel = (peaks[1] - peaks[0]) / (w2 * h2 - w1 * h1)
        full = peaks[1] + per_pixel * (1920 * 1080 - w2 * h2)
    return {"width": w, "height": h, "spp": spp, "peak_gb": peaks[-1], "exact": len(sizes) == 1, "full_gb": full,
            "bytes_per_pixel": None if per_pixel is None else per_pixel * 2 ** 30}


def update_readme(text):
    """Rewrite the performance tables of docs/benchmarks/performance.md (between its bench markers)."""
    path = os.path.join(REPO, "docs", "benchmarks", "performance.md")
    with open(path) as fh:
        readme = fh.read()
    begin, end = "<!-- bench:begin -->", "<!-- bench:end -->"
    if begin not in readme or end not in readme:
        raise SystemExit("docs/benchmarks/performance.md has no bench:begin / bench:end markers")
    head, rest = readme.split(begin, 1)
    _, tail = rest.split(end, 1)
    with open(path, "w") as fh:
        fh.write(head + begin + "\n" + text + "\n" + end + tail)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default=",".join(DEFAULT_SCENES))
    ap.add_argument("--res", type=int, default=None, help="image size (square); default 128, --full 256")
    ap.add_argument("--spp", type=int, default=None, help="our samples per pixel per render (default 32; --full 128)")
    ap.add_argument("--mitsuba-spp", type=int, default=None,
                    help="Mitsuba LLVM spp per render (default 128; --full 512)")
    ap.add_argument("--mitsuba-scalar-spp", type=int, default=4, help="Mitsuba scalar spp (0: skip)")
    ap.add_argument("--ref-spp", type=int, default=None, help="spp of each of the 2 reference renders "
                                                              "(default 2048; --full 8192)")
    ap.add_argument("--mitsuba-python", default=os.environ.get("MITSUBA_PYTHON", DEFAULT_MITSUBA))
    ap.add_argument("--skip", default="", help="comma list of: blender, cycles, memory, mitsuba")
    ap.add_argument("--blender-res", default=None, help="Blender ÷ CLI image size (default 480x270; --full 960x540)")
    ap.add_argument("--cycles-res", default=None, help="Cycles scenes size (default 160x120; --full 320x240)")
    ap.add_argument("--cycles-spp", type=int, default=None, help="default 16; --full 64")
    ap.add_argument("--cycles-scenes", default=None, help=f"default {','.join(CYCLES_QUICK)}; --full all")
    ap.add_argument("--memory-res", default="960x540", help="proxy size for the 1080p memory figure (quick runs)")
    ap.add_argument("--scaling-repeats", type=int, default=3,
                    help="1- and 2-thread renders per scene for the thread scaling, alternated (at least 2)")
    ap.add_argument("--sampler", default=None,
                    help="our renders' RenderSettings.sampler (peer scenes and the Cycles scenes' Pattern): "
                         "independent, stratified, sobol, or a comma list measured in the same run (default: "
                         "the engine's default, sobol; --full: sobol,cycles)")
    ap.add_argument("--full", action="store_true",
                    help="the published settings; rewrites docs/benchmarks/performance.md's tables")
    ap.add_argument("--out", default="")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--memory-child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        ours_child(json.loads(args.child))
        return 0
    if args.memory_child:
        memory_child(json.loads(args.memory_child))
        return 0
    full = args.full
    args.res = args.res or (256 if full else 128)
    args.spp = args.spp or (128 if full else 32)
    args.mitsuba_spp = args.mitsuba_spp or (512 if full else 128)
    args.ref_spp = args.ref_spp or (8192 if full else 2048)
    skip = set(filter(None, args.skip.split(",")))
    # ours at the engine's default pattern (RenderSettings.sampler); --full also races the selectable `cycles`
    sys.path.insert(0, REPO)
    from engine.scene.description import SAMPLERS, RenderSettings
    default = RenderSettings().sampler
    samplers = (args.sampler or (f"{default},cycles" if full else default)).split(",")
    for sampler in samplers:
        if sampler not in SAMPLERS:
            ap.error(f"--sampler: {sampler!r} is not one of {', '.join(SAMPLERS)}")

    mitsuba = "" if "mitsuba" in skip else args.mitsuba_python
    if mitsuba and subprocess.run([mitsuba, "-c", "import mitsuba"], capture_output=True).returncode != 0:
        print(f"Mitsuba not importable with {mitsuba}: references are our own renders, no Mitsuba columns "
              "(Debian/Ubuntu: apt-get install -y libllvm19)", file=sys.stderr)
        mitsuba = ""
    t_start = time.perf_counter()
    tmp = tempfile.mkdtemp(prefix="polar_bench_")
    rows = {s: [] for s in samplers}
    for scene in args.scenes.split(","):
        peer = {}
        for sampler in samplers:
            rows[sampler].append(measure_scene(scene, args, tmp, mitsuba, sampler, peer))
            print(f"{scene} ({sampler}): done ({time.perf_counter() - t_start:.0f} s)", file=sys.stderr)
    blender = memory = None
    cycles = []
    py = sys.executable
    if "blender" not in skip:
        w, h = (args.blender_res or ("960x540" if full else "480x270")).split("x")
        out, _, _ = run_measured([py, os.path.join(HERE, "blender_overhead.py"), "--width", w, "--height", h,
                                  "--spp", "8", "--repeats", "3" if full else "2", "--json"])
        blender = json_lines(out)[-1]
        print(f"blender: done ({time.perf_counter() - t_start:.0f} s)", file=sys.stderr)
    if "memory" not in skip:
        memory = measure_memory(args)
        print(f"memory: done ({time.perf_counter() - t_start:.0f} s)", file=sys.stderr)
    if "cycles" not in skip:
        out, _, _ = run_measured([py, os.path.join(HERE, "cycles_noise.py"), "--json",
                                  "--res", args.cycles_res or ("320x240" if full else "160x120"),
                                  "--spp", str(args.cycles_spp or (64 if full else 16)),
                                  "--sampler", ",".join(samplers),
                                  "--scenes", args.cycles_scenes or ("all" if full else
                                                                    ",".join(CYCLES_QUICK))])
        cycles = json_lines(out)
        print(f"cycles: done ({time.perf_counter() - t_start:.0f} s)", file=sys.stderr)
    header = (f"Run {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC on {platform.node() or '?'} "
              f"({os.cpu_count()} cores, {platform.processor() or platform.machine()}): "
              f"`bench_engine.py {' '.join(sys.argv[1:])}`, {args.res}² peer scenes, ours {args.spp} spp "
              f"({' and '.join(samplers)} sampler{'s' if len(samplers) > 1 else ''}), "
              f"Mitsuba {args.mitsuba_spp} spp, {time.perf_counter() - t_start:.0f} s in all.")
    parts = []
    for k, sampler in enumerate(samplers):
        parts.append(tables(rows[sampler], blender if k == 0 else None, memory if k == 0 else None,
                            [c for c in cycles if c.get("sampler", sampler) == sampler], args,
                            header if k == 0 else "", sampler, "" if k == 0 else sampler[0]))
    kernels = next((r[0]["ours_best"].get("kernels", "?") for r in rows.values() if r), "?")
    text = "\n\n".join(parts) + f"\n\n(our kernels: {kernels})"
    print(text)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text + "\n")
    if full:
        update_readme(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
