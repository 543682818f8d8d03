"""tests/support/asset_parity.timing: the warm seconds of alternated Cycles / Polar renders (asset_speed.py) as
medians with the quartiles of the per-step ratio, so a load that slows both renders of a step cancels."""

import numpy as np
import pytest

from tests.support.asset_parity import timing


def test_first_step_left_out_and_medians():
    c = [0.9, 0.10, 0.12, 0.11, 0.13, 0.10]          # Cycles' first render syncs the scene
    p = [2.0, 0.30, 0.36, 0.33, 0.39, 0.30]
    t = timing(c, p)
    assert t["n"] == 5
    assert t["cycles"] == pytest.approx(0.11)
    assert t["polar"] == pytest.approx(0.33)
    assert t["ratio"] == pytest.approx(3.0)
    assert t["q1"] == pytest.approx(3.0) and t["q3"] == pytest.approx(3.0)
    assert t["lo"] == pytest.approx(3.0) and t["hi"] == pytest.approx(3.0)


def test_load_shared_by_a_step_cancels_in_the_ratio():
    """Each step's load slows both renders alike (×1 … ×3): the medians of the seconds move with the load, the
    per-step ratio does not; a ratio of medians taken from runs at different loads would be off by the load's."""
    rng = np.random.default_rng(3)
    load = rng.uniform(1.0, 3.0, 16)
    c, p = 0.05 * load, 0.2 * load * rng.uniform(0.97, 1.03, 16)
    t = timing(list(c), list(p))
    assert t["q1"] <= t["ratio"] <= t["q3"]
    assert 0.97 * 4 <= t["lo"] and t["hi"] <= 1.03 * 4
    # the sequential timing's risk: Cycles' seconds from the quieter half of the run, Polar's from the busier one
    quiet, busy = np.argsort(load[1:])[:7] + 1, np.argsort(load[1:])[8:] + 1
    assert np.median(p[busy]) / np.median(c[quiet]) > 1.3 * t["hi"]
