"""Issue 36's cold start: after a fresh install and the background compile, is the first F12 as fast as a warm one?

    python tests/bench/cold_start.py [--samples 16] [--warm 3] [--keep DIR]

One run, on this machine, with the bpy module of the project's venv (Blender 5.0.1):

1. builds the extension zip (polar_addon.packaging.build) and installs it into a new, empty Blender user
   folder (tests.support.extension_run.install: Blender's own extension command);
2. **session A** (a fresh process): enables the installed extension — which starts the background compile
   (polar_addon.kernel_cache.start_precompile) — and waits until it reports done, timing it; then builds the demo
   .blend (examples/build_demo_blend.py's scene, ``--samples`` spp) and renders it with F12
   (``bpy.ops.render.render``) ``1 + --warm`` times: the first F12 after the compile, then warm ones;
3. **session B** (another fresh process, the same user folder): opens the saved .blend and renders it the same
   way — the first F12 of a new Blender session on a machine whose kernel cache is already filled.

Prints the seconds of every F12, the first ÷ the median warm one per session (issue 36's target: ≤ 1.3 in
session A), the background compile's seconds and the load average.  Not part of the test command.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)

from tests.support.extension_run import clean_env, install, printed  # noqa: E402

#: The session script: enable the installed extension, wait for its background compile, (build and) F12.
SESSION = textwrap.dedent("""
    import json, os, statistics, sys, time
    import bpy
    import addon_utils
    blend, samples, warm, build, examples = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4] == "1", \\
        sys.argv[5]
    t0 = time.perf_counter()
    addon_utils.enable("bl_ext.user_default.polar_render", default_set=True)
    polar = sys.modules["bl_ext.user_default.polar_render"]
    enabled = time.perf_counter() - t0
    cache = polar.polar_addon.kernel_cache
    started = cache.precompile_running()
    while cache.precompile_running():
        time.sleep(0.2)
    compiled = time.perf_counter() - t0
    if not build:
        bpy.ops.wm.open_mainfile(filepath=blend)
    else:
        sys.path.insert(0, examples)
        from build_demo_blend import build as build_demo
        build_demo(blend, samples, polar.polar_addon)
    times = []
    for _ in range(1 + warm):
        t = time.perf_counter()
        bpy.ops.render.render()
        times.append(time.perf_counter() - t)
    addon_utils.disable("bl_ext.user_default.polar_render", default_set=False)
    print("POLAR_COLD=" + json.dumps(dict(enable=enabled, precompile_started=started, compile=compiled,
                                          f12=times)))
""")


def session(env, blend, samples, warm, build):
    """One fresh Blender-module process: the session script's report (dict), or raises with its output."""
    proc = subprocess.run([sys.executable, "-c", SESSION, blend, str(samples), str(warm), "1" if build else "0",
                           os.path.join(REPO, "examples")], env=env, capture_output=True, text=True,
                          cwd=env["HOME"], timeout=1800)
    found = printed(proc, "POLAR_COLD")
    if proc.returncode != 0 or not found:
        raise SystemExit(f"session failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return json.loads(found[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=16, help="the demo's samples per pixel (its default: 16)")
    ap.add_argument("--warm", type=int, default=3, help="warm F12s after the first, per session")
    ap.add_argument("--keep", default="", help="a folder to work in and keep (default: a temporary one)")
    a = ap.parse_args(argv)
    if a.warm < 1:
        ap.error("--warm: must be at least 1 (the warm F12s the first is compared with)")
    from polar_addon.packaging import build
    with tempfile.TemporaryDirectory() as tmp:
        root = a.keep or tmp
        os.makedirs(root, exist_ok=True)
        load_before = os.getloadavg()
        t = time.perf_counter()
        zip_path = build(os.path.join(root, "dist"))
        print(f"zip built in {time.perf_counter() - t:.1f} s: {os.path.basename(zip_path)}", flush=True)
        env = clean_env(root, os.path.join(root, "user"))
        env.pop("POLAR_PRECOMPILE", None)          # the extension's own default: compile when enabled
        folder, log = install(sys.executable, zip_path, env)
        if not folder:
            raise SystemExit("install failed:\n" + log[-3000:])
        blend = os.path.join(root, "polar_demo.blend")
        rows = []
        for name, build_blend in (("A: install, enable, wait for the compile, build the demo, F12", True),
                                  ("B: a new session opens the demo, F12", False)):
            r = session(env, blend, a.samples, a.warm, build_blend)
            first, rest = r["f12"][0], r["f12"][1:]
            warm = statistics.median(rest)
            rows.append((name, r, first, warm))
            print(f"{name}: background compile {'started' if r['precompile_started'] else 'not started'}, "
                  f"done {r['compile']:.1f} s after enabling; F12 s {', '.join(f'{x:.2f}' for x in r['f12'])}; "
                  f"first ÷ warm {first / warm:.2f}", flush=True)
        load_after = os.getloadavg()
    print()
    print(f"# cold start, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}: demo .blend, {a.samples} spp, "
          f"bpy {_bpy_version()}; load average {' '.join(f'{x:.2f}' for x in load_before)} before, "
          f"{' '.join(f'{x:.2f}' for x in load_after)} after")
    print("| session | background compile s | first F12 s | warm F12 s (median) | first ÷ warm (target ≤ 1.3) |")
    print("|---|---|---|---|---|")
    for name, r, first, warm in rows:
        verdict = "PASS" if first / warm <= 1.3 else "MISS"
        compile_s = f"{r['compile']:.1f}" if r["precompile_started"] else "— (already complete)"
        print(f"| {name} | {compile_s} | {first:.2f} | {warm:.2f} | {first / warm:.2f} {verdict} |")
    return 0


def _bpy_version() -> str:
    try:
        from importlib.metadata import version
        return version("bpy")
    except Exception:               # noqa: BLE001 — only a label
        return "?"


if __name__ == "__main__":
    sys.exit(main())
