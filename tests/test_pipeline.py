"""The one-to-many matcher end to end: known-answer pairs cut from the shipped photo."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from scalematch import Config, match, pipeline
from scalematch.config import ProbeParams
from scalematch.geometry import apply, similarity_parts
from scalematch.lab.evaluation import reprojection_error
from scalematch.lab.synthetic import make_zoom_pair
from scalematch.stages.decision import mean_transfer_gap

#: tolerances of issue 4: ratio within 3 %, angle within 1 degree, error under 2 px
RATIO_TOL = 0.03
ANGLE_TOL_DEG = 1.0
ERROR_TOL_PX = 2.0


def _pair(photo, ratio, seed, size=(320, 240)):
    return make_zoom_pair(photo, ratio, np.random.default_rng(seed), high_size=size)


def _angle_gap(a, b):
    return abs((a - b + 180.0) % 360.0 - 180.0)


def _check_known_answer(result, pair):
    true_ratio, true_angle, _ = similarity_parts(pair.truth)
    assert result.matched, result.reason
    assert abs(result.resolution_ratio / true_ratio - 1) < RATIO_TOL
    assert _angle_gap(result.rotation_deg, true_angle) < ANGLE_TOL_DEG
    err = reprojection_error(result.transform, pair.truth, pair.high.shape, pair.low.shape)
    assert err < ERROR_TOL_PX


@pytest.mark.parametrize("ratio,seed", [(2.0, 0), (2.0, 1), (5.0, 0), (5.0, 1)])
def test_known_ratio_angle_and_error(raccoon, ratio, seed):
    pair = _pair(raccoon, ratio, seed)
    _check_known_answer(match(pair.low, pair.high), pair)


def test_scale_table_peaks_at_the_true_ratio(raccoon):
    pair = _pair(raccoon, 4.0, 2)
    result = match(pair.low, pair.high, Config(probe=ProbeParams(enabled=False)))
    rows = result.scales
    best = max(rows, key=lambda r: r.inliers)
    assert abs(math.log(best.s / 4.0)) <= math.log(1.2), f"best scale {best.s} for ratio 4"
    # its neighbours agree on the estimate (the paper's Table 1: scales 4, 5, 6 all give 5)
    i = rows.index(best)
    agree = [r for r in rows[max(i - 1, 0):i + 2] if r is not best and r.inliers >= 4
             and abs(r.ratio / 4.0 - 1) < 0.05]
    assert agree, "no neighbouring scale agrees with the best one"
    # far from the true ratio, scales find (almost) nothing
    far = [r for r in rows if abs(math.log(r.s / 4.0)) > math.log(2.5)]
    assert all(r.inliers < best.inliers / 3 for r in far)


def test_probe_gives_the_same_answer_as_running_every_scale(raccoon):
    pair = _pair(raccoon, 3.0, 4)
    fast = match(pair.low, pair.high)
    full = match(pair.low, pair.high, Config(probe=ProbeParams(enabled=False)))
    assert any(r.skipped for r in fast.scales) and not any(r.skipped for r in full.scales)
    assert fast.matched and full.matched
    # the same scale wins, described on the same level: the same answer
    assert fast.best_scale == full.best_scale
    assert mean_transfer_gap(fast.transform, full.transform, pair.high.shape) < 1e-6


def test_kept_and_recomputed_levels_give_the_same_result(raccoon, monkeypatch):
    """A high image over ``KEEP_LEVELS_MAX_PX`` has its levels computed again for the full
    pass (the memory bound); the answer must not depend on which path ran."""
    pair = _pair(raccoon, 3.0, 4)
    kept = match(pair.low, pair.high)
    monkeypatch.setattr(pipeline, "KEEP_LEVELS_MAX_PX", 0)
    again = match(pair.low, pair.high)
    assert kept.matched and again.matched
    assert np.array_equal(kept.transform, again.transform)
    assert np.array_equal(kept.inliers, again.inliers)
    assert repr(kept.scales) == repr(again.scales)  # (nan != nan: compared as text)


def test_result_contract(raccoon):
    pair = _pair(raccoon, 3.0, 5)
    r = match(pair.low, pair.high)
    assert r.matched and r.reason == "" and r.model == "similarity"
    t = r.transform
    assert t.shape == (2, 3)
    assert r.rotation_deg == pytest.approx(math.degrees(math.atan2(t[1, 0], t[0, 0])))
    assert r.translation == pytest.approx((t[0, 2], t[1, 2]))
    assert r.resolution_ratio == pytest.approx(1 / math.sqrt(abs(np.linalg.det(t[:, :2]))))
    assert r.inliers.shape == (r.n_inliers, 4) and r.n_inliers >= 8
    # every inlier pair fits the transform within the RANSAC threshold
    gap = np.linalg.norm(apply(t, r.inliers[:, :2]) - r.inliers[:, 2:], axis=1)
    assert gap.max() <= r.config.ransac.threshold_px
    assert len(r.scales) == len(r.config.scales)
    assert r.timings["total"] > 0


def test_same_input_same_output(raccoon):
    pair = _pair(raccoon, 4.0, 6)
    a, b = match(pair.low, pair.high), match(pair.low, pair.high)
    assert a.matched == b.matched
    assert np.array_equal(a.inliers, b.inliers)


@pytest.mark.parametrize("model", ["affine", "homography"])
def test_other_models_recover_the_transform(raccoon, model):
    pair = _pair(raccoon, 3.0, 0)
    r = match(pair.low, pair.high, Config(model=model))
    assert r.matched, r.reason
    assert r.transform.shape == ((2, 3) if model == "affine" else (3, 3))
    err = reprojection_error(r.transform, pair.truth, pair.high.shape, pair.low.shape)
    assert err < ERROR_TOL_PX


def test_fundamental_matrix_is_consistent_with_the_inliers(raccoon):
    pair = _pair(raccoon, 2.0, 0)
    r = match(pair.low, pair.high, Config(model="fundamental"))
    assert r.matched, r.reason
    f = r.transform
    x1 = np.hstack([r.inliers[:, :2], np.ones((r.n_inliers, 1))])
    x2 = np.hstack([r.inliers[:, 2:], np.ones((r.n_inliers, 1))])
    lines = x1 @ f.T  # epipolar lines in the low image
    dist = np.abs(np.einsum("ij,ij->i", x2, lines)) / np.hypot(lines[:, 0], lines[:, 1])
    assert np.median(dist) < 2.0


def test_paper_mode_matches_a_ratio_3_pair(raccoon):
    pair = _pair(raccoon, 3.0, 0, size=(480, 360))
    r = match(pair.low, pair.high, Config.paper())
    _check_known_answer(r, pair)
    assert r.config.mode == "paper" and r.config.scales == (1, 2, 3, 4, 5, 6, 7, 8)


def test_unrelated_pair_is_no_reliable_match(raccoon):
    """Low from the left half of the photo, high from its right half: nothing in common."""
    left, right = raccoon[:, :480], raccoon[:, 544:]
    low = make_zoom_pair(left, 3.0, np.random.default_rng(0), high_size=(160, 120)).low
    high = right[200:560, 0:480]
    for config in (Config(), Config.paper()):
        r = match(low, high, config)
        assert not r.matched and r.reason
        assert r.transform is None and r.inliers.shape == (0, 4)


def test_flat_pair_is_no_reliable_match():
    rng = np.random.default_rng(0)
    low = (128 + rng.normal(0, 3, (300, 400))).astype(np.float32)
    high = (90 + rng.normal(0, 3, (240, 320))).astype(np.float32)
    r = match(low, high)
    assert not r.matched
    assert "no scale" in r.reason or "inliers" in r.reason


def test_too_small_image_is_a_clear_error():
    with pytest.raises(ValueError, match="at least"):
        match(np.zeros((10, 10), np.float32), np.zeros((100, 100), np.float32))
