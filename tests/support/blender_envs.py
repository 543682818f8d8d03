"""Virtual environments holding one ``bpy`` release each, for the extension's smoke set on every
supported Blender (tests/blender/test_extension.py) and the version table (tests/bench/blender_versions.py).

    python tests/support/blender_envs.py 4.5 5.3        # create what is missing (make test does this)

Each environment is ``.venv-blender/bpy-<release>/`` in the checkout, made with the CPython that
Blender release embeds and ``pip install bpy==<release>`` from PyPI (about 400 MB each, once).
Blender 5.0 runs in the project's own ``.venv`` (``pyproject.toml`` pins bpy 5.0.1 there).
The interpreter is looked for on PATH (``python3.13``), then in pyenv's versions; each candidate is
run once to confirm its version, since a pyenv shim on PATH may name a version it cannot run.
"""

import glob
import importlib.metadata
import os
import shutil
import subprocess
import sys

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ROOT = os.path.join(REPO, ".venv-blender")
#: Blender series → (the bpy release tested, its CPython).  The series are
#: polar_addon.packaging.BLENDER_PYTHONS' (a test checks the two agree).
RELEASES = {"4.5": ("4.5.15", "3.11"), "5.0": ("5.0.1", "3.11"), "5.1": ("5.1.2", "3.13"),
            "5.2": ("5.2.4", "3.13"), "5.3": ("5.3.0", "3.13")}
#: The series whose smoke set `make test` runs beside the pinned 5.0.1: the oldest and the newest.
CI_SERIES = ("4.5", "5.3")


class SetupError(Exception):
    """A Blender environment cannot be made here (the message says what to install)."""


def _runs_as(candidate: str, version: str) -> bool:
    try:
        out = subprocess.run([candidate, "-c", "import sys; print('{}.{}'.format(*sys.version_info[:2]))"],
                             capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return out.returncode == 0 and out.stdout.strip() == version


def _patch_level(path: str) -> int:
    """3 for .../versions/3.13.3/bin/python3.13 (0 for a pre-release or an unusual name)."""
    patch = path.split(os.sep)[-3].split(".")[-1]
    return int(patch) if patch.isdigit() else 0


def find_python(version: str) -> str:
    """A CPython ``version`` ("3.13") interpreter: ``python3.13`` on PATH, else pyenv's newest 3.13.x."""
    candidates = [shutil.which(f"python{version}")]
    pyenv_root = os.environ.get("PYENV_ROOT") or os.path.join(os.path.expanduser("~"), ".pyenv")
    found = glob.glob(os.path.join(pyenv_root, "versions", f"{version}.*", "bin", f"python{version}"))
    candidates += sorted(found, key=_patch_level, reverse=True)
    for candidate in candidates:
        if candidate and _runs_as(candidate, version):
            return candidate
    raise SetupError(f"no Python {version} found (looked for python{version} on PATH and in "
                     f"{os.path.join(pyenv_root, 'versions')}); install it, e.g. `pyenv install {version}`")


def project_bpy_release():
    """The bpy release installed beside this interpreter (the project's .venv), or None."""
    try:
        return importlib.metadata.version("bpy")
    except importlib.metadata.PackageNotFoundError:
        return None


def env_dir(series: str) -> str:
    return os.path.join(ROOT, f"bpy-{RELEASES[series][0]}")


def interpreter(series: str) -> str:
    """The Python that runs Blender ``series``, creating its environment if needed (:func:`ensure`)."""
    release, python = RELEASES[series]
    if project_bpy_release() == release and "{}.{}".format(*sys.version_info[:2]) == python:
        return sys.executable
    return ensure(series)


def ensure(series: str, log=print) -> str:
    """Create ``.venv-blender/bpy-<release>`` if it is missing or incomplete; returns its python."""
    if series not in RELEASES:
        raise SetupError(f"Blender series {series!r} unknown: choose from {', '.join(RELEASES)}")
    release, python = RELEASES[series]
    folder = env_dir(series)
    exe = os.path.join(folder, "bin", "python")
    marker = os.path.join(folder, ".installed")
    if os.path.exists(marker):
        return exe
    base = find_python(python)
    log(f"creating {os.path.relpath(folder, REPO)} (Python {python}, bpy {release} from PyPI, ~400 MB, once)",
        flush=True)
    shutil.rmtree(folder, ignore_errors=True)
    for cmd in ([base, "-m", "venv", folder],
                [exe, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", f"bpy=={release}"]):
        proc = subprocess.run(cmd)
        if proc.returncode != 0:
            raise SetupError(f"creating the Blender {series} environment failed: {' '.join(cmd)} "
                             f"exited with {proc.returncode}")
    with open(marker, "w") as fh:
        fh.write(release + "\n")
    return exe


def main(argv=None):
    series = (argv if argv is not None else sys.argv[1:]) or list(CI_SERIES)
    try:
        for s in series:
            ensure(s)
    except SetupError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
