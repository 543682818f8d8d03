"""Checks on input files before they are opened (the bottom layer: every reader may use them)."""

from __future__ import annotations

import os
import stat

from .errors import SceneError


def refuse_special_file(path, field: str, prefix: str = "") -> None:
    """A SceneError naming ``field`` (message: ``prefix`` + the path) if ``path`` exists and is neither a
    regular file nor a folder (a FIFO, a device, a socket): reading one could wait forever for a writer.
    Checked before opening; a missing or unreadable path is left for the reader to report."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError, TypeError):
        return
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        raise SceneError(field, f"{prefix}{os.fspath(path)!r} is not a regular file (a FIFO, device or socket)")
