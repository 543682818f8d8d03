"""Build the installable extension zips: ``python -m polar_addon.packaging [--output-dir dist]``.

1. Downloads the wheels listed in ``blender_manifest.toml`` into ``wheels/`` with pip (binary only):
   embreex, OpenEXR, numba and llvmlite for every platform in the manifest's ``platforms`` and every
   Python of :data:`BLENDER_PYTHONS` (3.11 for Blender 4.5-5.0, 3.13 for 5.1 on); numpy comes with
   Blender.  Network is needed here, at build time only.
2. Checks that every platform gets one wheel of each bundled package for each of those Pythons.
3. Validates and builds one zip per platform with Blender's own extension tool (``blender_ext.py``
   from the bpy module — the same code as ``blender --command extension build --split-platforms``):
   ``polar_render-<version>-<platform>.zip``, each holding only its platform's wheels, for both
   Pythons: Blender installs the ones of its own Python when the extension is installed or Blender
   starts, so one zip serves every supported Blender (docs/guide/blender.md, "Build and install").

The download is injectable (``fetch``) so that tests can build with fake wheel files and no network.
This module needs no Blender session (it only locates bpy's copy of ``blender_ext.py``).
"""

import argparse
import os
import platform as _platform
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WHEEL_NAME = re.compile(r"\./wheels/([A-Za-z0-9_]+)-([^-]+)-(cp\d+|py3)-[^-]+-(.+)\.whl")
#: Packages every platform's zip must carry (project names as they appear in wheel file names).
#: threadpoolctl (pure Python, one ``any`` wheel for all) keeps NumPy's BLAS to one thread while the
#: render's workers run (engine.render.blas_threads).
BUNDLED = ("embreex", "openexr", "numba", "llvmlite", "threadpoolctl")
#: Every platform Blender builds extensions for (what a pure-Python ``any`` wheel runs on).
BLENDER_PLATFORMS = frozenset({"linux-x64", "linux-arm64", "windows-x64", "windows-arm64", "macos-x64",
                               "macos-arm64"})
#: The Blender series the extension supports and the CPython each embeds (the wheel tag it needs).
#: ``blender_version_min`` in the manifest is the first of these.
BLENDER_PYTHONS = {"4.5": "cp311", "5.0": "cp311", "5.1": "cp313", "5.2": "cp313", "5.3": "cp313"}


def manifest_text(source_dir=ROOT):
    with open(os.path.join(source_dir, "blender_manifest.toml"), encoding="utf-8") as fh:
        return fh.read()


def manifest_wheels(source_dir=ROOT):
    """The manifest's ``wheels`` entries, as written (``./wheels/<file>.whl``)."""
    return re.findall(r'"(\./wheels/[^"]+\.whl)"', manifest_text(source_dir))


def manifest_platforms(source_dir=ROOT):
    m = re.search(r"^platforms\s*=\s*\[([^\]]*)\]", manifest_text(source_dir), re.M)
    return re.findall(r'"([^"]+)"', m.group(1)) if m else []


def wheel_platforms(filename):
    """Blender platforms (``linux-x64``, ``windows-x64``, ``macos-arm64``, …) a wheel file runs on.

    The same mapping as Blender's ``--split-platforms`` for the tags used here; ``any`` wheels fit all
    (:data:`BLENDER_PLATFORMS`).
    """
    tags = os.path.basename(filename)[:-len(".whl")].split("-")[-1].split(".")
    found = set()
    for tag in tags:
        if tag == "any":
            return set(BLENDER_PLATFORMS)
        system = ("linux" if "linux" in tag else "windows" if tag.startswith("win") else
                  "macos" if tag.startswith("macosx") else None)
        if system is None:
            continue
        if tag.endswith(("x86_64", "amd64")):
            found.add(f"{system}-x64")
        elif tag.endswith(("aarch64", "arm64")):
            found.add(f"{system}-arm64")
        elif tag.endswith("universal2"):
            found.update({"macos-x64", "macos-arm64"})
    return found


def check_manifest(source_dir=ROOT):
    """Every declared platform has exactly one wheel of each package in :data:`BUNDLED` for each Python
    of :data:`BLENDER_PYTHONS` (a pure-Python ``py3`` wheel serves them all), and the manifest's
    ``blender_version_min`` is the oldest supported Blender."""
    platforms = manifest_platforms(source_dir)
    if not platforms:
        raise SystemExit("blender_manifest.toml: 'platforms' is empty; list the platforms wheels are bundled for")
    oldest = min(BLENDER_PYTHONS, key=lambda v: tuple(map(int, v.split("."))))
    m = re.search(r'^blender_version_min\s*=\s*"([^"]+)"', manifest_text(source_dir), re.M)
    if not m or m.group(1) != f"{oldest}.0":
        raise SystemExit(f"blender_manifest.toml: blender_version_min must be \"{oldest}.0\", the oldest supported "
                         f"Blender (polar_addon.packaging.BLENDER_PYTHONS), found {m.group(1) if m else 'none'}")
    wheels = [WHEEL_NAME.match(w) for w in manifest_wheels(source_dir)]
    for plat in platforms:
        for python in sorted(set(BLENDER_PYTHONS.values())):
            names = [w.group(1).lower() for w in wheels
                     if w.group(3) in (python, "py3") and plat in wheel_platforms(w.group(0))]
            for package in BUNDLED:
                if names.count(package) != 1:
                    raise SystemExit(f"blender_manifest.toml: platform {plat} needs exactly one {package} wheel for "
                                     f"{python} in 'wheels', found {names.count(package)}")


def pip_download(name, version, python_version, platform_tags, dest):
    """Fetch one binary wheel from the package index with pip (the default ``fetch``)."""
    cmd = [sys.executable, "-m", "pip", "download", f"{name}=={version}", "--no-deps", "--only-binary=:all:",
           "--python-version", python_version, "--implementation", "cp", "--dest", dest, "--quiet"]
    for tag in platform_tags:
        cmd += ["--platform", tag]
    subprocess.run(cmd, check=True)


def download_wheels(source_dir=ROOT, fetch=pip_download):
    """Make sure every wheel of the manifest is in ``<source_dir>/wheels``.

    ``fetch(name, version, python_version, platform_tags, dest)`` must leave the wheel named in the
    manifest in ``dest``; wheels already there are not fetched again.
    """
    dest = os.path.join(source_dir, "wheels")
    os.makedirs(dest, exist_ok=True)
    for rel in manifest_wheels(source_dir):
        target = os.path.join(source_dir, rel)
        if os.path.exists(target):
            continue
        m = WHEEL_NAME.match(rel)
        if not m:
            raise SystemExit(f"blender_manifest.toml: cannot parse wheel name {rel} "
                             "(expected ./wheels/<name>-<version>-cp3NN-<abi>-<platform>.whl "
                             "or ./wheels/<name>-<version>-py3-none-any.whl)")
        name, version, pytag, platform_tags = m.groups()
        # a pure-Python wheel (py3-none-any) is fetched for Blender's Python as well
        fetch(name, version, pytag[2:] if pytag.startswith("cp") else "311", platform_tags.split("."), dest)
        if not os.path.exists(target):
            raise SystemExit(f"the download did not produce {rel}; check the name in blender_manifest.toml")


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


def host_platform():
    """This machine as a Blender platform name, e.g. ``linux-x64``."""
    system = {"linux": "linux", "win32": "windows", "darwin": "macos"}.get(sys.platform, sys.platform)
    machine = _platform.machine().lower()
    arch = "x64" if machine in ("x86_64", "amd64") else "arm64" if machine in ("arm64", "aarch64") else machine
    return f"{system}-{arch}"


def build_all(output_dir=os.path.join(ROOT, "dist"), source_dir=ROOT, fetch=pip_download):
    """Download wheels, validate and build one zip per platform; returns {platform: zip path}."""
    check_manifest(source_dir)
    download_wheels(source_dir, fetch)
    tool = blender_ext_tool()
    os.makedirs(output_dir, exist_ok=True)
    subprocess.run([sys.executable, tool, "validate", source_dir], check=True)
    subprocess.run([sys.executable, tool, "build", "--source-dir", source_dir, "--output-dir", output_dir,
                    "--split-platforms"], check=True)
    text = manifest_text(source_dir)
    ext_id = re.search(r'^id\s*=\s*"([^"]+)"', text, re.M).group(1)
    version = re.search(r'^version\s*=\s*"([^"]+)"', text, re.M).group(1)
    zips = {}
    for plat in manifest_platforms(source_dir):
        path = os.path.join(output_dir, f"{ext_id}-{version}-{plat.replace('-', '_')}.zip")
        if not os.path.exists(path):
            raise SystemExit(f"the build did not produce {path}")
        zips[plat] = path
    return zips


def build(output_dir=os.path.join(ROOT, "dist"), source_dir=ROOT, fetch=pip_download):
    """Build every platform's zip (:func:`build_all`); returns the path of this machine's zip."""
    zips = build_all(output_dir, source_dir, fetch)
    host = host_platform()
    if host not in zips:
        raise SystemExit(f"no zip for this machine ({host}); the manifest's platforms are {sorted(zips)}")
    return zips[host]


def main():
    ap = argparse.ArgumentParser(description="Build the Polar Blender extension zips (one per platform)")
    ap.add_argument("--output-dir", default=os.path.join(ROOT, "dist"))
    for plat, path in build_all(ap.parse_args().output_dir).items():
        print(f"{plat}: {path} ({os.path.getsize(path) / 1e6:.1f} MB)")


if __name__ == "__main__":
    main()
