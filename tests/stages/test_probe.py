"""The probe: which scales are matched in full (stages/probe.py)."""

from __future__ import annotations

import math

import numpy as np

from scalematch import Config, match
from scalematch.lab.synthetic import make_zoom_pair
from scalematch.stages.probe import select_scales


def test_the_best_scales_are_kept_with_their_neighbours():
    assert select_scales([0.0, 5.0, 1.0, 0.0, 9.0], keep=1) == [3, 4]
    assert select_scales([0.0, 5.0, 1.0, 0.0, 9.0], keep=2) == [0, 1, 2, 3, 4]


def test_a_scale_whose_fit_is_its_minimal_sample_is_not_among_the_best():
    # scores of 2 are a similarity's own 2-point sample: only the 9 and its neighbours are kept
    assert select_scales([0.0, 2.0, 0.0, 9.0, 1.0, 2.0], keep=3, min_score=3) == [2, 3, 4]
    # nothing beyond a minimal sample anywhere: no scale is matched in full
    assert select_scales([2.0, 2.0, 1.0, 0.0], keep=3, min_score=3) == []
    # without a floor the three best are kept however low they score
    assert select_scales([2.0, 2.0, 1.0, 0.0], keep=3) == [0, 1, 2, 3]


def test_the_true_scale_clears_the_floor_and_is_matched_in_full(raccoon):
    """A zoom pair at ratio 4: the true scale scores well above the floor, so the answer is
    found there, within 2 % of the ratio."""
    pair = make_zoom_pair(raccoon, 4.0, np.random.default_rng(1), high_size=(320, 240))
    result = match(pair.low, pair.high, Config.preset("no-views"))
    assert result.matched, result.reason
    assert abs(result.resolution_ratio / 4.0 - 1) < 0.02
    near = [r for r in result.scales if abs(math.log(r.s / 4.0)) < math.log(1.3)]
    assert near and not all(r.skipped for r in near)
