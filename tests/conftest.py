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
