"""The extension on every supported Blender: the README's table of tested versions.

    python tests/bench/blender_versions.py [--series 4.5 5.0 5.1 5.2 5.3] [--zip dist/polar_render-…zip]

Builds this machine's extension zip (``make extension``'s code) unless ``--zip`` names one, makes a
``bpy`` environment per Blender series from PyPI where missing (tests/support/blender_envs.py:
``.venv-blender/bpy-<release>``, ~400 MB each; 5.0 runs in the project's .venv), installs the zip into
a clean user folder of each with Blender's extension command and runs the smoke set there
(tests/support/extension_smoke.py: enable, render every pass, the Virtual Polariser and Polar Denoise
operators, viewport edits).  Prints a Markdown table: each stage "ok" or what failed, the largest
difference of any pass from 5.0.1's (max |Δ| / max S0) and the wall time of install + smoke set
(cold: each fresh user folder compiles the kernels it renders with).  Not part of the test command.
"""

import argparse
import os
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, REPO)

from tests.support import blender_envs  # noqa: E402
from tests.support.extension_run import judge, pass_difference, run_smoke  # noqa: E402


def quietly(fn, *args):
    """Run ``fn`` with this process's standard output sent to standard error (Blender's build tool
    prints there), so that standard output holds the table alone."""
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        return fn(*args)
    finally:
        os.dup2(saved, 1)
        os.close(saved)


def cell(value):
    if value == "ok":
        return "ok"
    text = value if isinstance(value, str) else " ".join(value)
    return "**fails**: " + text.replace("|", "/").replace("\n", " ")[:120]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--series", nargs="+", default=list(blender_envs.RELEASES), choices=list(blender_envs.RELEASES))
    ap.add_argument("--zip", help="an extension zip for this machine (default: build one)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="polar-blender-versions-") as tmp:
        if args.zip:
            zip_path = os.path.abspath(args.zip)
        else:
            from polar_addon.packaging import build
            zip_path = quietly(build, os.path.join(tmp, "dist"))
        results = {}
        for series in dict.fromkeys(["5.0"] + args.series):        # 5.0.1 first: the reference
            home = os.path.join(tmp, series)
            os.makedirs(home)
            print(f"Blender {series} …", file=sys.stderr, flush=True)
            results[series] = run_smoke(series, zip_path, home)
        rows = ["| Blender (bpy) | Python | install | enable | render + passes | Virtual Polariser | Polar Denoise "
                "| viewport edits | DirectX normal map | max pass Δ vs 5.0.1 | seconds |",
                "|---|---|---|---|---|---|---|---|---|---|---|"]
        for series in args.series:
            r = results[series]
            checks = judge(r)
            diff = pass_difference(r, results["5.0"])
            release, python = blender_envs.RELEASES[series]
            lts = " LTS" if "LTS" in r.get("blender", "") else ""
            absent = r.get("normal_map_convention") == "absent"
            normal_map = cell(checks["normal_map"]) + (" (no such setting)" if absent else "")
            worst = None if not diff else max(diff.values())
            rows.append(" | ".join([
                f"| {series}{lts} ({release})", python, cell(r["install"]), cell(r.get("enable", "-")),
                cell(checks["passes"]), cell(checks["polariser"]), cell(checks["denoise"]), cell(checks["viewport"]),
                normal_map, "-" if worst is None else "0" if worst == 0 else f"{worst:.1e}", f"{r['seconds']:.0f} |"]))
        print("\n".join(rows))
        failed = [s for s in args.series if results[s]["install"] != "ok" or set(judge(results[s]).values()) != {"ok"}]
        return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
