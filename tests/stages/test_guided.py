"""Guided growth: a right hypothesis of 5 inliers grows to many, a wrong one does not."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from scalematch.geometry import apply, similarity_matrix, similarity_parts
from scalematch.lab.synthetic import make_zoom_pair
from scalematch.stages.descriptors import Described, describe_gradients
from scalematch.stages.detector import HarrisParams, detect_on_level
from scalematch.stages.estimator import estimate
from scalematch.stages.guided import GuidedParams, grow, guided_matches
from scalematch.stages.scalespace import Level, scale_space

RATIO = 6.0
#: the detector these tests were measured with: the absolute threshold (no contrast needed at s = 6)
ABSOLUTE = HarrisParams(contrast_relative=False, min_points=0)


@pytest.fixture(scope="module")
def zoom(raccoon):
    """A ratio-6 zoom pair of data/raccoon.jpg, described at s = 6 (high) and s = 1 (low)."""
    pair = make_zoom_pair(raccoon, RATIO, np.random.default_rng(0))
    level = next(scale_space(pair.high, (RATIO,)))
    high = describe_gradients(level, detect_on_level(level, ABSOLUTE).xy)
    low_level = Level(1.0, 1.0, 0.0, pair.low)
    low = describe_gradients(low_level,
                             detect_on_level(low_level, replace(ABSOLUTE, max_points=12000)).xy)
    return pair, high, low


def _true_pairs(pair, high, low, tol=1.5):
    """Rows (i, j) of high and low points within ``tol`` low px of each other under the truth."""
    d = np.linalg.norm(apply(pair.truth, high.xy)[:, None] - low.xy[None], axis=2)
    j = d.argmin(axis=1)
    i = np.nonzero(d[np.arange(len(j)), j] <= tol)[0]
    return i, j[i]


def _grid_error(t, truth, shape):
    h, w = shape
    g = np.stack(np.meshgrid(np.linspace(0, w - 1, 21), np.linspace(0, h - 1, 21)), -1)
    g = g.reshape(-1, 2)
    return float(np.linalg.norm(apply(t, g) - apply(truth, g), axis=1).mean())


def test_five_true_inliers_grow_to_many(zoom):
    pair, high, low = zoom
    i, j = _true_pairs(pair, high, low)
    assert i.size >= 30  # measured: 46 of the 49 high points at s = 6
    pick = np.linspace(0, i.size - 1, 5).astype(int)
    start = estimate("similarity", high.xy[i[pick]], low.xy[j[pick]])
    assert start.transform is not None
    out = grow(start.transform, high, low)
    # measured: 5 -> 33 inliers in one round (then no further growth), chance 0.4
    assert out.n_inliers >= 20, out.counts
    assert out.n_inliers > 10 * out.chance
    assert out.inliers.shape == (out.n_inliers, 4)
    assert 1 <= out.rounds <= GuidedParams().max_rounds
    # the grown transform is the truth: mean grid error under 1 low px (measured 0.2)
    assert _grid_error(out.transform, pair.truth, pair.high.shape) < 1.0
    ratio, angle, _ = similarity_parts(out.transform)
    assert abs(ratio / RATIO - 1) < 0.02


def test_wrong_hypothesis_does_not_grow(zoom):
    pair, high, low = zoom
    ratio, angle, _ = similarity_parts(pair.truth)
    h, w = pair.high.shape
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    for turn, at in ((90.0, (0.3, 0.3)), (180.0, (0.7, 0.6)), (0.0, (0.2, 0.8))):
        wrong = similarity_matrix(1 / ratio, angle + turn)
        wrong[:, 2] = np.array(at) * pair.low.shape[::-1] - apply(wrong, [centre])[0]
        out = grow(wrong, high, low)
        # measured: 0 guided matches for each; a wrong placement gathers chance matches only
        assert out.n_inliers <= 3, (turn, out.counts)


def test_shifted_truth_is_pulled_back(zoom):
    """A hypothesis 2 low px off (within the search radius) is refit onto the truth."""
    pair, high, low = zoom
    off = pair.truth.copy()
    off[:, 2] += (1.5, -1.2)
    out = grow(off, high, low)
    assert out.n_inliers >= 20
    assert _grid_error(out.transform, pair.truth, pair.high.shape) < 1.0


def test_orientation_test_rejects_turned_descriptors(zoom):
    """With orientations in use, matches must agree with the hypothesis' rotation."""
    pair, high, low = zoom
    turned = Described(s=high.s, xy=high.xy, index=high.index, angle=high.angle + np.pi,
                       desc=high.desc)
    i, _, _ = guided_matches(pair.truth, turned, low)
    i2, _, _ = guided_matches(pair.truth, turned, low, GuidedParams(use_orientation=False))
    assert i.size == 0 and i2.size >= 20


def test_no_points_is_an_empty_growth(zoom):
    pair, high, low = zoom
    none = Described(s=high.s, xy=np.zeros((0, 2)), index=np.zeros(0, int),
                     angle=np.zeros(0), desc=np.zeros((0, high.desc.shape[1]), np.float32))
    out = grow(pair.truth, none, low)
    assert out.n_inliers == 0 and out.inliers.shape == (0, 4) and out.rounds == 0
    assert np.array_equal(out.transform, pair.truth)


def test_fundamental_matrix_is_refused(zoom):
    pair, high, low = zoom
    with pytest.raises(ValueError, match="point-to-point"):
        grow(np.eye(3), high, low, model="fundamental")
