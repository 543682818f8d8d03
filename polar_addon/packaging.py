"""Build the installable extension zip: ``python -m polar_addon.packaging [--output-dir dist]``.

1. Downloads the wheels listed in ``blender_manifest.toml`` (embreex, OpenEXR; numpy comes with
   Blender) into ``wheels/`` with pip, for Linux x86-64 and CPython 3.11 (Blender 5.0's Python).
2. Validates and builds the zip with Blender's own extension tool (``blender_ext.py`` from the
   bpy module — the same code as ``blender --command extension build``).

Other platforms: add their wheels (win_amd64, macosx_11_0_arm64, …) to the manifest's ``wheels``
and ``platforms`` lists and run the build with ``--split-platforms`` (see README).
This module needs no Blender session (it only locates bpy's copy of ``blender_ext.py``).
"""

import argparse
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MANIFEST = os.path.join(ROOT, "blender_manifest.toml")
WHEEL_NAME = re.compile(r"\./wheels/([A-Za-z0-9_]+)-([^-]+)-(cp\d+)-[^-]+-(.+)\.whl")


def manifest_wheels():
    with open(MANIFEST, encoding="utf-8") as fh:
        return re.findall(r'"(\./wheels/[^"]+\.whl)"', fh.read())


def download_wheels(dest=os.path.join(ROOT, "wheels")):
    """Make sure every wheel of the manifest is in ``dest`` (pip download, binary only)."""
    os.makedirs(dest, exist_ok=True)
    for rel in manifest_wheels():
        target = os.path.join(ROOT, rel)
        if os.path.exists(target):
            continue
        m = WHEEL_NAME.match(rel)
        if not m:
            raise SystemExit(f"cannot parse wheel name {rel}")
        name, version, pytag, platform = m.groups()
        cmd = [sys.executable, "-m", "pip", "download", f"{name}=={version}", "--no-deps", "--only-binary=:all:",
               "--python-version", pytag[2:], "--implementation", "cp", "--dest", dest, "--quiet"]
        for plat in platform.split("."):
            cmd += ["--platform", plat]
        subprocess.run(cmd, check=True)
        if not os.path.exists(target):
            raise SystemExit(f"pip did not produce {rel}; check the name in blender_manifest.toml")


def blender_ext_tool():
    import importlib.util
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise SystemExit("the bpy module is needed to build the extension (pip install bpy==5.0.1)")
    base = os.path.dirname(spec.origin)
    for version in sorted(os.listdir(base), reverse=True):
        tool = os.path.join(base, version, "scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py")
        if os.path.exists(tool):
            return tool
    raise SystemExit(f"blender_ext.py not found under {base}")


def build(output_dir=os.path.join(ROOT, "dist")):
    """Download wheels, validate the manifest and build the zip; returns the zip's path."""
    download_wheels()
    tool = blender_ext_tool()
    os.makedirs(output_dir, exist_ok=True)
    subprocess.run([sys.executable, tool, "validate", ROOT], check=True)
    subprocess.run([sys.executable, tool, "build", "--source-dir", ROOT, "--output-dir", output_dir], check=True)
    with open(MANIFEST, encoding="utf-8") as fh:
        text = fh.read()
    ext_id = re.search(r'^id\s*=\s*"([^"]+)"', text, re.M).group(1)
    version = re.search(r'^version\s*=\s*"([^"]+)"', text, re.M).group(1)
    path = os.path.join(output_dir, f"{ext_id}-{version}.zip")
    if not os.path.exists(path):
        raise SystemExit(f"the build did not produce {path}")
    return path


def main():
    ap = argparse.ArgumentParser(description="Build the Polar Blender extension zip")
    ap.add_argument("--output-dir", default=os.path.join(ROOT, "dist"))
    print(build(ap.parse_args().output_dir))


if __name__ == "__main__":
    main()
