"""Install the extension zip into one Blender and run the smoke set there, then judge what it wrote:
shared by tests/blender/test_extension.py (which asserts) and tests/bench/blender_versions.py (which
tabulates every supported Blender).  Needs numpy and OpenEXR in this process, not bpy.
"""

import json
import os
import subprocess
import textwrap
import time

import numpy as np

from tests.support import blender_envs

SMOKE_SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "extension_smoke.py")
#: The Virtual Polariser angle the smoke set renders with (degrees).
POLARISER_ANGLE = 30.0
PASSES = ("Combined", "S0", "S1", "S2", "S3", "DoP", "DoLP", "AoLP", "DoCP", "Polariser")

INSTALL = textwrap.dedent("""
    import sys
    import bpy
    from bl_pkg import cli_extension
    sys.exit(cli_extension(["install-file", "-r", "user_default", "-e", sys.argv[1]]) or 0)
""")


def clean_env(home, user):
    """This process's environment without Polar's overrides, with Blender's user folder at ``user``."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "POLAR_KERNEL_CACHE", "POLAR_KERNELS")}
    env.update(BLENDER_USER_RESOURCES=str(user), HOME=str(home))
    return env


def printed(proc, key):
    """Values a script printed as ``KEY=value`` lines, in order."""
    return [line.split("=", 1)[1] for line in proc.stdout.splitlines() if line.startswith(key + "=")]


def install(python, zip_path, env):
    """Install the zip with Blender's extension command: (installed folder or None, log).  None also
    where the command exits 0 without installing (Blender 4.5 refusing a newer minimum version so)."""
    proc = subprocess.run([python, "-c", INSTALL, zip_path], env=env, capture_output=True, text=True,
                          cwd=env["HOME"], timeout=600)
    log = proc.stdout + proc.stderr
    folder = os.path.join(env["BLENDER_USER_RESOURCES"], "extensions", "user_default", "polar_render")
    refused = [line for line in log.splitlines() if line.startswith("ERROR") or "incompatible" in line]
    ok = proc.returncode == 0 and not refused and os.path.exists(os.path.join(folder, "blender_manifest.toml"))
    return (folder if ok else None), log


def run_smoke(series, zip_path, home):
    """Install into a clean user folder below ``home`` and run the smoke set: a dict with "install"
    ("ok" or the refusal), the smoke script's report, "out" (its EXR folder) and "seconds"."""
    start = time.monotonic()
    python = blender_envs.interpreter(series)
    env = clean_env(home, os.path.join(home, "user"))
    # the smoke set compiles only what it renders, in-process (test_extension's own install test covers
    # the background compile the extension starts when enabled)
    env["POLAR_PRECOMPILE"] = "0"
    folder, log = install(python, zip_path, env)
    result = {"series": series, "install": "ok" if folder else log.strip().splitlines()[-5:], "log": log}
    if folder:
        out = os.path.join(home, "out")
        proc = subprocess.run([python, SMOKE_SCRIPT, out, str(POLARISER_ANGLE)], env=env, capture_output=True,
                              text=True, cwd=home, timeout=900)
        reports = printed(proc, "POLAR_SMOKE")
        result["log"] += proc.stdout[-4000:] + proc.stderr[-4000:]
        if reports:
            result.update(json.loads(reports[-1]), out=out)
        else:
            result["enable"] = f"the smoke script ended with status {proc.returncode} and no report"
    result["seconds"] = time.monotonic() - start
    return result


def read_layer(path, layer="ViewLayer"):
    """{pass: (H, W, C)} of one layer of a multilayer EXR (tests.blender_support.read_multilayer)."""
    from tests.blender_support import read_multilayer
    return read_multilayer(path, layer=layer)


def judge(result):
    """{check: "ok" or what is wrong} for the EXR files of one smoke run (stages that did not run: "-")."""
    checks = {}
    out = result.get("out")

    def check(name, stage, fn):
        if result.get(stage) != "ok" or out is None:
            checks[name] = "-" if stage not in result else str(result[stage])
            return
        try:
            problem = fn()
        except Exception as e:          # noqa: BLE001 — a broken file is a finding, not a crash
            problem = f"{type(e).__name__}: {e}"
        checks[name] = problem or "ok"

    def passes():
        found = read_layer(os.path.join(out, "render.exr"))
        missing = [p for p in PASSES if p not in found]
        if missing:
            return f"missing {', '.join(missing)}"
        if not all(np.isfinite(found[p]).all() for p in PASSES):
            return "non-finite values"
        if found["DoLP"][-2:, :].min() <= 0.5:
            return "the Brewster floor is not polarised"
        return None

    def processes():
        threads, procs = read_layer(os.path.join(out, "render.exr")), read_layer(os.path.join(out, "processes.exr"))
        differ = [p for p in PASSES if not np.array_equal(threads[p], procs[p])]
        if differ:
            return f"worker processes changed {', '.join(differ)}"
        if result.get("processes_after_disable"):
            return f"{result['processes_after_disable']} worker process(es) outlived the extension"
        return None

    def polariser():
        path = os.path.join(out, "polariser.exr")
        S = read_layer(path)
        composite = read_layer(path, "Composite")["Combined"][..., :3]
        theta = np.radians(POLARISER_ANGLE)
        malus = 0.5 * (S["S0"] + np.cos(2 * theta) * S["S1"] + np.sin(2 * theta) * S["S2"])
        error = np.abs(composite - malus).max() / S["S0"].max()
        return None if error <= 1e-6 else f"composite differs from Malus' law by {error:.2g} of max S0"

    def denoise():
        path = os.path.join(out, "denoise.exr")
        denoised = read_layer(path, "Composite")["Combined"][..., :3]
        noisy = read_layer(path)["S0"]
        if not np.isfinite(denoised).all():
            return "non-finite denoised image"
        return None if np.abs(denoised - noisy).max() > 1e-3 * noisy.max() else "the image was not denoised"

    def viewport():
        counts = result["viewport_counts"]
        if counts["material"] != {"arrays": 0, "materials": 1}:
            return f"a material edit re-exported {counts['material']}"
        if counts["mesh"]["arrays"] != 1 or counts["modifier"]["arrays"] != 1:
            return f"mesh/modifier edits re-read {counts['mesh']['arrays']}/{counts['modifier']['arrays']} meshes"
        return None

    def normal_map():
        release = tuple(map(int, blender_envs.RELEASES[result["series"]][0].split(".")))
        expected = "directx" if release >= (5, 1) else "absent"      # the Convention setting came with 5.1
        found = result["normal_map_convention"]
        return None if found == expected else f"a DirectX Normal Map is read as {found} (expected {expected})"

    def sources():
        found = result["polarised_sources"]
        if found["light"] != ["linear", 45.0]:
            return f"the LCD preset exported {found['light']}"
        skies = found["skies"]
        expected = {"NISHITA", "PREETHAM", "HOSEK_WILKIE"} if result["series"] == "4.5" else \
            {"SINGLE_SCATTERING", "MULTIPLE_SCATTERING", "PREETHAM", "HOSEK_WILKIE"}
        if set(skies) != expected or any(model != "berry" or sun[2] <= 0 for model, sun in skies.values()):
            return f"sky polarisation per type: {skies}"
        return None

    check("passes", "render", passes)
    check("processes", "processes", processes)
    check("polariser", "polariser", polariser)
    check("denoise", "denoise", denoise)
    check("viewport", "viewport", viewport)
    check("normal_map", "normal_map", normal_map)
    check("sources", "sources", sources)
    return checks


def pass_difference(result, reference):
    """max |Δ| / max S0 of ``reference`` over every pass: {pass: value} (None if either has no render)."""
    if "out" not in result or "out" not in reference:
        return None
    a = read_layer(os.path.join(result["out"], "render.exr"))
    b = read_layer(os.path.join(reference["out"], "render.exr"))
    scale = b["S0"].max()
    return {p: float(np.abs(a[p] - b[p]).max() / scale) for p in PASSES if p in a and p in b}
