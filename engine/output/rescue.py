"""Saving finished samples when the requested output cannot be written.

A long render must not be lost because its output path failed at the end (folder removed or made
read-only, disk full, a folder created at the target's name) or because the values do not fit the
file (beyond the float32 range of an EXR).  :func:`save_rescue` then writes the same data to
``polar-rescue-<YYYYmmdd-HHMMSS>-<pid>.exr`` beside the target, else in the system temporary folder
(``$TMPDIR``), the working folder or the home folder — the first that works.  Values an EXR cannot
hold are kept losslessly in ``polar-rescue-….npz`` instead (NumPy archive: ``stokes`` (4, H, W, 3)
float64 means, the extra channels by name, and ``metadata``, the header as a JSON string).
"""

from __future__ import annotations

import json
import os
import tempfile
import time

import numpy as np

from . import atomic_output_path

RESCUE_PREFIX = "polar-rescue-"


def rescue_directories(target: str | os.PathLike) -> list[str]:
    """Folders tried for a rescue file, in order (duplicates removed)."""
    candidates = [os.path.dirname(os.path.abspath(os.fspath(target))), tempfile.gettempdir(), os.getcwd(),
                  os.path.expanduser("~")]
    out = []
    for d in candidates:
        if d and d not in out:
            out.append(d)
    return out


def save_rescue(target, stokes_rgb, metadata: dict | None = None, extra: dict | None = None) -> str:
    """Write the data meant for ``target`` to a rescue file; return its path.

    Raises OSError (listing every folder tried and why it failed) only if no rescue file could be
    written anywhere.
    """
    from .exr import write_stokes_exr

    stem = f"{RESCUE_PREFIX}{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
    metadata = dict(metadata or {})
    metadata["polar.rescued_from"] = os.path.abspath(os.fspath(target))
    extra = dict(extra or {})
    fits_exr = True
    failures = []
    for directory in rescue_directories(target):
        if fits_exr:
            path = os.path.join(directory, stem + ".exr")
            try:
                write_stokes_exr(path, stokes_rgb, metadata=metadata, extra=extra)
                return path
            except ValueError:
                fits_exr = False          # the data, not the place: keep them losslessly below
            except Exception as e:        # noqa: BLE001 — any failure of this place: try the next one
                failures.append(f"{directory}: {e}")
                continue
        path = os.path.join(directory, stem + ".npz")
        try:
            with atomic_output_path(path) as tmp:
                with open(tmp, "wb") as fh:
                    np.savez(fh, stokes=np.asarray(stokes_rgb, np.float64),
                             metadata=np.array(json.dumps(metadata, default=str)),
                             **{name: np.asarray(v) for name, v in extra.items()})
            return path
        except Exception as e:            # noqa: BLE001
            failures.append(f"{directory}: {e}")
    raise OSError(f"no rescue file could be written ({'; '.join(failures)})")
