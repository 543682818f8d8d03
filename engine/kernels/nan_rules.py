"""NumPy's NaN rules for two floats inside compiled loops: np.minimum and np.maximum propagate a NaN
in either argument (Python's min/max and a bare comparison would not), so a loop that replaces a
NumPy expression keeps its numbers bit for bit."""

from __future__ import annotations

from . import jit_inner


@jit_inner
def minimum_at(a, b):
    """np.minimum(a, b) of two floats."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a <= b else b


@jit_inner
def maximum_at(a, b):
    """np.maximum(a, b) of two floats."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a >= b else b
