"""Shared test fixtures: where the project's shared/ folder (oracles, peer scenes) lives."""

import os

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.environ.get("POLAR_SHARED", os.path.join(os.path.dirname(REPO), "shared"))
ORACLES = os.path.join(SHARED, "oracles")
PEERS = os.path.join(SHARED, "peers")


def shared_path(*parts):
    path = os.path.join(SHARED, *parts)
    if not os.path.exists(path):
        pytest.fail(f"shared data missing: {path} (set POLAR_SHARED to the shared/ folder)")
    return path


# CI runs property tests derandomized, so that main stays green for a given commit; developers'
# runs explore new random examples every time (and the failures they find become regression tests).
if os.environ.get("CI"):
    from hypothesis import settings as _hsettings
    _hsettings.register_profile("ci", derandomize=True, deadline=None)
    _hsettings.load_profile("ci")
