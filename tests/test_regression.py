"""CI regression on synthetic zoom pairs: no ../shared needed.

Pairs are cut from the shipped photo (data/raccoon.jpg, 1024x768) by the project's own generator
(EVALUATION.md protocol: random rotation, gain, offset, noise). Every pair must be matched with
the known ratio (3 %), angle (1 degree) and reprojection error (2 low px). A failure here means the
pipeline has regressed: look at `scalematch LOW HIGH -v` on the pair before changing tolerances.
"""

from __future__ import annotations

import numpy as np
import pytest

from scalematch import match
from scalematch.geometry import similarity_parts
from scalematch.lab.evaluation import reprojection_error
from scalematch.lab.synthetic import make_zoom_pair

CASES = [(r, seed) for r in (2.0, 3.0, 4.0, 5.0, 6.0) for seed in (10, 11)]


@pytest.mark.parametrize("ratio,seed", CASES)
def test_synthetic_zoom_pair_is_recovered(raccoon, ratio, seed):
    pair = make_zoom_pair(raccoon, ratio, np.random.default_rng(seed), high_size=(400, 300))
    r = match(pair.low, pair.high)
    true_ratio, true_angle, _ = similarity_parts(pair.truth)
    assert r.matched, r.reason
    assert abs(r.resolution_ratio / true_ratio - 1) < 0.03
    assert abs((r.rotation_deg - true_angle + 180) % 360 - 180) < 1.0
    err = reprojection_error(r.transform, pair.truth, pair.high.shape, pair.low.shape)
    assert err < 2.0
