"""OpenCV baselines: a real zoom pair is recovered, a flat pair gives no match, no crash."""

from __future__ import annotations

import numpy as np
import pytest

from scalematch.lab.baselines import BASELINES, BaselineResult, match_baseline
from scalematch.lab.evaluation import SUCCESS_PX, reprojection_error
from scalematch.lab.synthetic import make_zoom_pair


@pytest.fixture(scope="module")
def pair(raccoon):
    return make_zoom_pair(raccoon, 2.0, np.random.default_rng(3))


def test_sift_recovers_ratio_2(pair):
    res = match_baseline(pair.low, pair.high, "sift", seed=0)
    assert isinstance(res, BaselineResult)
    assert res.transform is not None and res.transform.shape == (2, 3)
    assert res.inliers >= 10 and res.matches >= res.inliers
    assert reprojection_error(res.transform, pair.truth, pair.high.shape,
                              pair.low.shape) < SUCCESS_PX


def test_homography_model(pair):
    res = match_baseline(pair.low, pair.high, "sift", model="homography", seed=0)
    assert res.transform.shape == (3, 3)
    assert reprojection_error(res.transform, pair.truth, pair.high.shape,
                              pair.low.shape) < SUCCESS_PX


def test_same_seed_same_answer(pair):
    a = match_baseline(pair.low, pair.high, "orb", seed=4)
    b = match_baseline(pair.low, pair.high, "orb", seed=4)
    assert a.inliers == b.inliers and np.array_equal(a.transform, b.transform)


@pytest.mark.parametrize("method", BASELINES)
def test_flat_pair_is_no_match(method):
    low = np.full((300, 400), 128, np.float32)
    high = np.full((240, 320), 90, np.float32)
    res = match_baseline(low, high, method)
    assert res.transform is None
    assert res.inliers == 0 and res.matches == 0
    assert res.method == method


def test_unknown_method_and_model():
    img = np.zeros((50, 50), np.float32)
    with pytest.raises(ValueError, match="unknown baseline"):
        match_baseline(img, img, "surf")
    with pytest.raises(ValueError, match="model"):
        match_baseline(img, img, "sift", model="fundamental")
