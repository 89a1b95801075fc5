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


def test_a_point_described_twice_counts_once_in_a_scales_score():
    """Two distinct point pairs only fix a similarity: they score under the floor of 3, also
    when one of the points is described at a second orientation and matched again (the copy
    of a pair is no evidence); a third distinct pair on the same map scores 3."""
    from scalematch.config import Config
    from scalematch.stages.descriptors import Described
    from scalematch.stages.estimator import FitSpec
    from scalematch.stages.matcher import Candidates
    from scalematch.stages.probe import _score

    config = Config()
    s = 4.0
    high_xy = np.array([[100.0, 80.0], [300.0, 200.0], [100.0, 80.0], [220.0, 40.0]])
    low_xy = high_xy / s + np.array([50.0, 30.0])  # ratio 4, no turn
    angle = np.array([0.3, 1.1, 2.0, 0.7])  # row 2 is row 0 at a second orientation

    def score(rows):
        high = Described(s=s, xy=high_xy[rows], index=np.arange(len(rows)), angle=angle[rows],
                         desc=np.zeros((len(rows), 4), np.float32))
        low = Described(s=1.0, xy=low_xy[rows], index=np.arange(len(rows)), angle=angle[rows],
                        desc=np.zeros((len(rows), 4), np.float32))
        n = len(rows)
        cand = Candidates(np.arange(n), np.arange(n), np.zeros(n, np.float32),
                          np.ones(n, np.float32))
        quick = FitSpec("similarity", config.ransac, config.seed)
        return _score(high, low, cand, config.orientation, quick,
                      config.decision.scale_agreement)

    floor = config.probe.min_score
    assert score([0, 1]) < floor
    assert score([0, 1, 2]) < floor  # the same pair of positions twice
    assert score([0, 1, 3]) == 3.0 == floor
