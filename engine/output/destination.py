"""Where an output file goes: checks made before a long render, and our temporary files.

Outputs are written to a hidden temporary file in the target's folder and renamed into place
(:func:`engine.output.atomic_output_path`).  Its name is short and independent of the target's
name — ``.polar-tmp-<pid>-<8 random characters><ext>`` — so a target name that the file system
accepts (up to NAME_MAX bytes, usually 255) never fails because of the temporary name, and a
temporary file left by a killed process can be recognised (and removed) later.
"""

from __future__ import annotations

import errno
import os
import re
import tempfile

#: Start of every temporary output file's name (followed by "<pid>-").
TEMP_PREFIX = ".polar-tmp-"
_TEMP_RE = re.compile(r"^\.polar-tmp-(\d+)-[A-Za-z0-9_]{8}\.(exr|png|npz)$")
# Temporary names of older versions: ".<target name>.<8 random characters>.tmp<ext>".
_LEGACY_TEMP_RE = re.compile(r"^\..+\.[A-Za-z0-9_]{8}\.tmp\.(exr|png)$")


def make_temporary(directory: str, ext: str) -> str:
    """Create (empty, mode 0600) and return a new temporary output path in ``directory``."""
    fd, tmp = tempfile.mkstemp(prefix=f"{TEMP_PREFIX}{os.getpid()}-", suffix=ext, dir=directory)
    os.close(fd)
    return tmp


def name_max(directory: str) -> int:
    """Longest file name (bytes) the file system of ``directory`` accepts (255 if unknown)."""
    try:
        return int(os.pathconf(directory, "PC_NAME_MAX"))
    except (OSError, ValueError, AttributeError):
        return 255


def check_destination(path: str | os.PathLike) -> str:
    """Make sure a file can be written at ``path``, before the work that produces it.

    Creates the folder if needed, then proves that our temporary file and the target name itself
    can be created there (both are removed again; an existing target is left untouched).
    Returns the absolute path; raises OSError whose message says what is wrong.
    """
    path = os.path.abspath(os.fspath(path))
    directory, name = os.path.split(path)
    if os.path.isdir(path):
        raise IsADirectoryError(errno.EISDIR, f"{path!r} is a folder; give a file name inside it")
    try:
        os.makedirs(directory, exist_ok=True)
    except OSError as e:
        raise type(e)(e.errno, f"cannot create the folder {directory!r}: {e.strerror}") from None
    if not os.path.isdir(directory):
        raise NotADirectoryError(errno.ENOTDIR, f"{directory!r} is not a folder")
    limit = name_max(directory)
    if len(os.fsencode(name)) > limit:
        raise OSError(errno.ENAMETOOLONG, f"the file name is {len(os.fsencode(name))} bytes; "
                                          f"this file system allows at most {limit}")
    try:
        os.remove(make_temporary(directory, os.path.splitext(name)[1]))
        if not os.path.lexists(path):
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            os.close(fd)
            os.remove(path)
    except OSError as e:
        raise type(e)(e.errno, f"cannot create files in {directory!r}: {e.strerror}") from None
    return path


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True


def remove_stale_temporaries(directory: str, older_than: float) -> list[str]:
    """Remove our temporary output files in ``directory`` left by processes that died mid-write.

    A file counts as stale when it matches our naming pattern, was last modified before
    ``older_than`` (a time.time() value, e.g. when this process started) and — if its name
    carries a process id — that process no longer runs (or is this one, after pid reuse).
    Returns the paths removed; files that cannot be removed are left alone.
    """
    removed = []
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    for name in names:
        m = _TEMP_RE.match(name)
        if m is None and not _LEGACY_TEMP_RE.match(name):
            continue
        path = os.path.join(directory, name)
        try:
            if not os.path.isfile(path) or os.path.getmtime(path) >= older_than:
                continue
            if m is not None:
                pid = int(m.group(1))
                if pid != os.getpid() and _process_alive(pid):
                    continue
            os.remove(path)
            removed.append(path)
        except OSError:
            continue
    return removed
