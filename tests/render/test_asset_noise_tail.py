"""tests/support/asset_parity.noise_tail: the share of σ² in the brightest 1 % of pixels and σ² of the rest, which
tell fireflies' luck from an estimator's noise in the real-asset race (tests/bench/asset_speed.py)."""

import numpy as np
import pytest

from tests.support.asset_parity import noise_tail


def test_share_and_rest_of_known_variances():
    var = np.full(1000, 1e-4)
    var[:10] = 1.0                                  # the top 1 %: ten pixels
    share, rest = noise_tail(np.random.default_rng(1).permutation(var))
    assert share == pytest.approx(10.0 / (10.0 + 990e-4), rel=1e-12)
    assert rest == pytest.approx(1e-4, rel=1e-12)
    assert noise_tail(np.zeros(5)) == (0.0, 0.0)


def test_four_seeds_of_fireflies_are_luck_the_rest_is_not():
    """Two renderers with the same estimator (a pixel's sample is a firefly of 2000 with probability 3e-5, about
    one a render, else N(0.1, 0.05)): over 16 groups of 4 seeds their mean-σ² ratio swings by more than 10× (the
    Sunglasses case read 13.5× with seeds 0–3 and 0.38× with seeds 4–7), while the ratio of σ² without the top
    1 % stays within 1.2× and the share puts most of σ² in that top 1 %."""
    rng = np.random.default_rng(7)
    seeds, spp, pixels = 64, 16, 2000

    def render():
        x = rng.normal(0.1, 0.05, (seeds, pixels, spp))
        x[rng.random(x.shape) < 3e-5] = 2000.0
        return x.mean(-1)

    a, b = render(), render()
    ratios, rests, shares = [], [], []
    for g in range(0, seeds, 4):
        va, vb = a[g:g + 4].var(0, ddof=1), b[g:g + 4].var(0, ddof=1)
        ratios.append(va.mean() / vb.mean())
        (share, rest_a), rest_b = noise_tail(va), noise_tail(vb)[1]
        rests.append(rest_a / rest_b)
        shares.append(share)
    assert max(ratios) / min(ratios) > 10.0
    assert max(rests) < 1.2 and min(rests) > 1 / 1.2
    assert np.median(shares) > 0.9
