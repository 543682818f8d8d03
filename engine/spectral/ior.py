"""Measured complex indices of refraction n + i k of named metals.

Tables (``data/ior/<name>.csv``, copied verbatim from the project's shared data) are Palik's
*Handbook of Optical Constants of Solids* as tabulated by luxpop.com, the data Mitsuba 3 and
pbrt ship. They cover about 298-886 nm (vacuum wavelength), i.e. the rendered 360-830 nm, and
are interpolated linearly in wavelength; evaluating outside a table raises SceneError.
"""

from __future__ import annotations

import functools
import os

from ..errors import SceneError

from .cie import DATA_DIR, read_csv_table
from .spectrum import TabulatedSpectrum

NAMED_METALS = ("Au", "Ag", "Al", "Cu", "Cr")


@functools.cache
def _load(name: str) -> tuple[TabulatedSpectrum, TabulatedSpectrum]:
    cols, rows = read_csv_table(os.path.join(DATA_DIR, "ior", f"{name}.csv"))
    if cols != ["wavelength_nm", "n", "k"]:
        raise RuntimeError(f"ior/{name}.csv: unexpected columns {cols}")
    wl = rows[:, 0]
    return (
        TabulatedSpectrum(wl, rows[:, 1], name=f"{name}.n", kind="unbounded"),
        TabulatedSpectrum(wl, rows[:, 2], name=f"{name}.k", kind="unbounded"),
    )


def named_ior(name, field: str = "") -> tuple[TabulatedSpectrum, TabulatedSpectrum]:
    """(n, k) spectra of a named metal (one of NAMED_METALS, case-sensitive); cached.

    Unknown names raise SceneError(field, ...) listing the allowed names.
    """
    if not isinstance(name, str) or name not in NAMED_METALS:
        raise SceneError(
            field, f"unknown named metal {name!r}; allowed: {', '.join(NAMED_METALS)}"
        )
    return _load(name)
