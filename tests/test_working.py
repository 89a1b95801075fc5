"""The working size of a large low image: the same answer, in the original low pixels."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from scalematch import Config, match
from scalematch.lab.evaluation import reprojection_error
from scalematch.lab.synthetic import make_zoom_pair
from scalematch.result import Direction
from scalematch.stages.decision import mean_transfer_gap
from scalematch.working import (at_working_size, decode_sides, direction_scales, in_decoded, shrink,
                                working_factor)

#: a match at the working size against the truth, original low px (a working pixel is f of them)
ERROR_TOL_PX = 2.0
#: full size against working size, original low px, mean over a grid spanning the high image
GAP_TOL_PX = 1.0


def _pair(photo, ratio, seed):
    return make_zoom_pair(photo, ratio, np.random.default_rng(seed), high_size=(320, 240))


def test_shrink_follows_the_pixel_centre_convention():
    """Working pixel x_w holds the original pixels around f * x_w + (f - 1) / 2 (x and y),
    within 0.06 original px (INTER_AREA's rounded area weights; measured 0.05 at f = 2.34)."""
    h, w, f = 400, 600, 600 / 256
    ramp_x = np.tile(np.arange(w, dtype=np.float32), (h, 1))
    ramp_y = np.tile(np.arange(h, dtype=np.float32)[:, None], (1, w))
    small_x, small_y = shrink(ramp_x, f), shrink(ramp_y, f)
    assert small_x.shape == (round(h / f), 256)
    xs = np.arange(2, small_x.shape[1] - 2)
    ys = np.arange(2, small_y.shape[0] - 2)
    assert np.abs(small_x[3, xs] - (f * xs + (f - 1) / 2)).max() < 0.06
    assert np.abs(small_y[ys, 3] - (f * ys + (f - 1) / 2)).max() < 0.06


def test_factor_and_scales():
    assert working_factor((768, 1024), 2048) == 1.0
    assert working_factor((4000, 6000), 2048) == pytest.approx(6000 / 2048)
    assert working_factor((4000, 6000), None) == 1.0
    # the low image shrunk 3x: each configured ratio s is searched at 3 s in the given
    # direction; the other direction's ratios s (low image the finer) at s / 3 when that is
    # at least 1, else at 3 / s in the given direction
    scales = direction_scales((1.0, 2.0, 4.0), 3.0, 1.0)
    assert scales[Direction.GIVEN] == pytest.approx((1.5, 3.0, 6.0, 12.0))
    assert scales[Direction.SWAPPED] == pytest.approx((4 / 3,))
    # the paper's unit steps keep their spacing at working size (the high image shrunk 2.93x:
    # ratio 8 is searched at 8 / 2.93 = 2.73, as the bench's ratio-10 pair needs)
    paper = direction_scales(tuple(float(s) for s in range(1, 9)), 1.0, 2.93)
    assert paper[Direction.GIVEN] == pytest.approx(tuple(s / 2.93 for s in range(3, 9)))
    assert paper[Direction.SWAPPED][:2] == pytest.approx((2.93 / 2, 2.93))


@pytest.mark.parametrize("ratio,seed", [(2.0, 0), (3.0, 1)])
def test_working_size_gives_the_full_size_answer(raccoon, ratio, seed):
    pair = _pair(raccoon, ratio, seed)
    side = max(pair.low.shape) // 2  # f = 2: the low image matched at half its size
    full = match(pair.low, pair.high, Config(low_max_side=None))
    small = match(pair.low, pair.high, Config(low_max_side=side))
    assert full.matched and small.matched, small.reason
    assert small.evidence.low_working_factor == pytest.approx(max(pair.low.shape) / side)
    assert small.config.low_max_side == side
    err = reprojection_error(small.transform, pair.truth, pair.high.shape, pair.low.shape)
    assert err < ERROR_TOL_PX
    assert mean_transfer_gap(small.transform, full.transform, pair.high.shape) < GAP_TOL_PX
    assert small.resolution_ratio == pytest.approx(full.resolution_ratio, rel=0.02)
    # inliers in original low px: each fits the transform within the RANSAC threshold (in
    # working px, so f times it here)
    f = small.evidence.low_working_factor
    fit = cv2.transform(small.inliers[None, :, :2], small.transform)[0]
    assert np.linalg.norm(fit - small.inliers[:, 2:], axis=1).max() <= f * 3.0 + 1e-6
    assert abs(small.best_scale / ratio - 1) < 0.3  # reported in the original pixels
    # the evidence's figures in pixels too: the implied ratio and the footprint's area (low px^2)
    assert small.evidence.implied_ratio == pytest.approx(full.evidence.implied_ratio, rel=0.02)
    assert small.evidence.footprint_area_px == pytest.approx(full.evidence.footprint_area_px,
                                                             rel=0.04)


def test_working_size_in_the_swapped_order(raccoon):
    """The first image given is the finer one: it is the one shrunk, the answer still maps
    the finer image's original pixels to the coarser one's."""
    pair = _pair(raccoon, 3.0, 2)
    result = match(pair.high, pair.low, Config(low_max_side=200))  # 320 px -> f = 1.6
    assert result.matched and result.order == "swapped", result.reason
    err = reprojection_error(result.transform, pair.truth, pair.high.shape, pair.low.shape)
    assert err < ERROR_TOL_PX


def test_low_max_side_is_checked():
    with pytest.raises(ValueError, match="low_max_side"):
        Config(low_max_side=10)


def _pair_large(photo, ratio, seed):
    return make_zoom_pair(photo, ratio, np.random.default_rng(seed), high_size=(480, 360),
                          low_max=(480, 360))


def _check(result, pair, full=None):
    assert result.matched, result.reason
    err = reprojection_error(result.transform, pair.truth, pair.high.shape, pair.low.shape)
    assert err < ERROR_TOL_PX
    if full is not None:
        assert mean_transfer_gap(result.transform, full.transform, pair.high.shape) < GAP_TOL_PX
    # inliers in original px: (finer x, y, coarser x, y) fit the transform within the RANSAC
    # threshold in the coarser image's working px (at most f of its original px)
    f = max(result.evidence.low_working_factor, result.evidence.high_working_factor)
    fit = cv2.transform(result.inliers[None, :, :2], result.transform)[0]
    assert np.linalg.norm(fit - result.inliers[:, 2:], axis=1).max() <= f * 3.0 + 1e-6


def test_a_shrunk_high_image_gives_the_full_size_answer(raccoon):
    """High 480 px matched at 240 (f = 2): ratio 3 becomes 1.5, still the given order."""
    pair = _pair_large(raccoon, 3.0, 3)
    full = match(pair.low, pair.high, Config(high_max_side=None))
    small = match(pair.low, pair.high, Config(high_max_side=240))
    assert small.evidence.high_working_factor == pytest.approx(2.0)
    assert small.order == "given" and small.config.high_max_side == 240
    _check(small, pair, full)
    assert small.resolution_ratio == pytest.approx(full.resolution_ratio, rel=0.02)
    assert abs(small.best_scale / 3.0 - 1) < 0.3  # reported in the original pixels


def test_a_high_image_shrunk_past_the_low_one_is_found_in_the_other_order(raccoon):
    """Ratio 2, high 480 px matched at 120 (f = 4): the working high image is the coarser one
    (working ratio 1/2); the search finds it in the other order, and the answer is given in the
    order of the original pixels. The scale table stays in its search's direction, in original
    pixels: low px per high px, 1/2 at the best scale."""
    pair = _pair_large(raccoon, 2.0, 4)
    small = match(pair.low, pair.high, Config(high_max_side=120))
    assert small.evidence.search_order == "swapped"
    assert small.order == "given" and small.resolution_ratio == pytest.approx(2.0, rel=0.03)
    assert small.best_scale == pytest.approx(0.5, rel=0.3)
    _check(small, pair)


def test_both_images_shrunk_keep_the_ratio(raccoon):
    pair = _pair_large(raccoon, 2.0, 5)
    result = match(pair.low, pair.high, Config(low_max_side=160, high_max_side=320))
    assert result.evidence.low_working_factor > 1 and result.evidence.high_working_factor > 1
    assert result.order == "given"
    _check(result, pair)


def test_the_given_order_keeps_the_high_image_at_full_size(raccoon):
    """With order='given' a shrunk high image could not be found coarser: it is not shrunk."""
    pair = _pair_large(raccoon, 3.0, 3)
    result = match(pair.low, pair.high, Config(order="given", high_max_side=160))
    assert result.evidence.high_working_factor == 1.0
    _check_given = reprojection_error(result.transform, pair.truth, pair.high.shape,
                                      pair.low.shape)
    assert result.matched and _check_given < ERROR_TOL_PX


def test_high_max_side_is_checked():
    with pytest.raises(ValueError, match="high_max_side"):
        Config(high_max_side=10)


def test_the_reason_names_a_scale_of_the_table_at_working_size(raccoon):
    """The reason names the scale the table shows, in the images' own scales and to its 3
    digits, not the working pixels' scale (such as "at scale 2.37176")."""
    import re

    low = raccoon[:600, :800]
    noise = np.random.default_rng(3).uniform(0, 255, (600, 800)).astype(np.float32)
    high = cv2.GaussianBlur(noise, (0, 0), 3.0) * 4.0  # a texture the raccoon does not hold
    # every scale matched in full (no probe): the best of them is refused, named by its scale
    result = match(low, high, Config(low_max_side=300, high_max_side=500,
                                     views=replace(Config().views, enabled=False),
                                     probe=replace(Config().probe, enabled=False)))
    assert not result.matched
    found = re.findall(r"scale (\d+(?:\.\d+)?)", result.reason)
    assert found, result.reason
    shown = {f"{row.s:.3g}" for row in result.scales}
    assert all(s in shown for s in found), (found, shown)


@pytest.mark.parametrize("which", ["low", "high"])
def test_an_image_decoded_reduced_gives_the_answer_in_the_files_pixels(raccoon, which):
    """An image given already halved (as a JPEG decoded at half size: the same centre-aligned
    map) with ``decoded_factors`` gives the answer of the full-size image, in its pixels: with a
    working size of half its side the search sees the same array either way."""
    pair = _pair_large(raccoon, 3.0, 4) if which == "high" else _pair(raccoon, 2.0, 5)
    h, w = pair.low.shape  # even sides: halving is then exactly the map of a factor 2
    pair = replace(pair, low=pair.low[:h // 2 * 2, :w // 2 * 2])
    if which == "low":
        config = Config(low_max_side=max(pair.low.shape) // 2)
        factors, args = (2.0, 1.0), (shrink(pair.low, 2.0), pair.high)
    else:
        config = Config(high_max_side=max(pair.high.shape) // 2)
        factors, args = (1.0, 2.0), (pair.low, shrink(pair.high, 2.0))
    full = match(pair.low, pair.high, config)
    result = match(*args, config, decoded_factors=factors)
    _check(result, pair, full)
    np.testing.assert_allclose(result.transform, full.transform, atol=1e-9)
    assert (result.evidence.low_working_factor, result.evidence.high_working_factor) == \
        (full.evidence.low_working_factor, full.evidence.high_working_factor) == factors
    # drawn on the images as decoded: in_decoded maps the answer onto them
    drawn = in_decoded(result, *factors)
    up = {1.0: lambda p: p, 2.0: lambda p: 2 * p + 0.5}  # decoded px -> file px
    corner = np.array([[[3.0, 5.0]]])
    np.testing.assert_allclose(up[factors[0]](cv2.transform(corner, drawn.transform)),
                               cv2.transform(up[factors[1]](corner), result.transform), atol=1e-9)


def test_the_high_image_is_decoded_reduced_only_in_the_automatic_order():
    assert decode_sides(Config()) == (2048, 2048)
    assert decode_sides(Config(order="given")) == (2048, None)
    with pytest.raises(ValueError, match="only with order 'auto'"):
        at_working_size(np.zeros((64, 64), np.float32), np.zeros((64, 64), np.float32),
                        Config(order="given"), decoded_factors=(1, 2))
