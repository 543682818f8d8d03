"""Image output: Stokes EXR files, PNG previews and the colour maps they use.

Image convention shared by all writers here: a *Stokes image* is a float
array of shape (4, H, W, 3) holding S0..S3 on the first axis; row 0 is the
image top, column 0 the left edge, and the last axis is linear sRGB
(Rec. 709 primaries, D65) R, G, B radiance.  Scalar polarisation images
(DoP, DoLP, AoLP, DoCP) are derived from the *luminance* Stokes vector
Y = 0.2126 R + 0.7152 G + 0.0722 B of each component (see
:func:`luminance_stokes`).

Submodules are not imported here so that writing PNGs does not need OpenEXR.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

import numpy as np

from ..spectral.cie import LUMINANCE_WEIGHTS  # noqa: F401  (re-exported: Y of the written images)


def check_stokes_image(stokes_rgb) -> np.ndarray:
    """Return ``stokes_rgb`` as a float64 array after checking it is a finite (4, H, W, 3) image.

    Raises ValueError with a message naming the problem (shape, dtype or the
    count of non-finite values).
    """
    a = np.asarray(stokes_rgb)
    if a.ndim != 4 or a.shape[0] != 4 or a.shape[3] != 3 or a.shape[1] < 1 or a.shape[2] < 1:
        raise ValueError(f"Stokes image must have shape (4, H, W, 3) with H, W >= 1; got {a.shape}")
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f"Stokes image must be real numeric; got dtype {a.dtype}")
    a = a.astype(np.float64, copy=False)
    bad = ~np.isfinite(a)
    if bad.any():
        raise ValueError(f"Stokes image has {int(bad.sum())} non-finite value(s) (NaN/inf)")
    return a


def luminance_stokes(stokes_rgb) -> np.ndarray:
    """Luminance Stokes image, shape (4, H, W): Σ_c w_c S_k[..., c] with Rec. 709 weights."""
    return np.asarray(stokes_rgb, dtype=np.float64) @ LUMINANCE_WEIGHTS


@contextlib.contextmanager
def atomic_output_path(path: str | os.PathLike) -> Iterator[str]:
    """Yield a temporary path next to ``path``; on success os.replace() it onto ``path``.

    The temporary file lives in the same directory (so the rename is atomic),
    is hidden, keeps the target's extension and has a short name of its own
    (:mod:`engine.output.destination`), so any target name the file system
    accepts works.  If the body raises, the temporary file is removed and the
    target is left untouched.  The result keeps an existing target's
    permission bits, else gets 0644.
    """
    from .destination import make_temporary

    path = os.fspath(path)
    directory, name = os.path.split(os.path.abspath(path))
    tmp = make_temporary(directory, os.path.splitext(name)[1])
    try:
        # mkstemp creates 0600; give the result the target's mode (or rw-r--r--).
        try:
            mode = os.stat(path).st_mode & 0o7777
        except FileNotFoundError:
            mode = 0o644
        os.chmod(tmp, mode)
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)
        raise
