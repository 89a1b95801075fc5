"""No-data regions (``stages.nodata``): a canvas left by a rotation or a warp is found, a clipped
or flat region of the scene is not, a declared value is taken wherever it covers a region."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from scalematch import Config, match
from scalematch.lab.evaluation import reprojection_error
from scalematch.lab.realistic import on_canvas
from scalematch.lab.synthetic import FLAT_KINDS, flat_field, flatten, zoom_pair_from_crop
from scalematch.stages.nodata import NoDataParams, canvas_of, find_nodata, parse_rule


def _textured(raccoon: np.ndarray, size=(640, 480)) -> np.ndarray:
    w, h = size
    return np.ascontiguousarray(raccoon[100:100 + h, 200:200 + w])


def _photo_with_band(raccoon: np.ndarray, seed: int = 0):
    """A 4096x3072 photo (the raccoon enlarged 4x, 2 grey levels of noise) and a 640x480 crop
    of it whose top 40 % is clipped to 255, in the photo too (the low image sees it)."""
    rng = np.random.default_rng(seed)
    photo = cv2.resize(raccoon, (4096, 3072), interpolation=cv2.INTER_CUBIC)
    photo = np.clip(photo + rng.normal(0, 2.0, photo.shape), 0, 254).astype(np.float32)
    x, y, w, h = 1500, 1200, 640, 480
    photo[y:y + int(0.4 * h), x:x + w] = 255.0
    return photo, (x, y, w, h)


def test_a_finer_image_clipped_at_its_top_loses_no_point_and_matches_at_ratio_10(raccoon):
    """The finer image's top 40 % at 255, noise elsewhere: a clipped highlight touching the
    border is scene. Matched at ratio 10 with the automatic rule, it keeps every point it has
    with no no-data at all (the per-scale table's points), and the answer is right."""
    photo, crop = _photo_with_band(raccoon)
    pair = zoom_pair_from_crop(photo, crop, 10.0, np.random.default_rng(3))
    assert (pair.high == 255).mean() == pytest.approx(0.4, abs=0.01)
    assert find_nodata(pair.high).share == 0.0
    auto = match(pair.low, pair.high)
    off = match(pair.low, pair.high, Config(nodata=NoDataParams(rule="none")))
    assert [r.points for r in auto.scales] == [r.points for r in off.scales]
    assert auto.matched, auto.reason
    err = reprojection_error(auto.transform, pair.truth, pair.high.shape, pair.low.shape)
    assert err < 3.0


def test_a_canvas_from_a_10_degree_turn_is_found(raccoon):
    img = _textured(raccoon)
    canvas, r = on_canvas(img, 10.0)
    picture = cv2.warpAffine(np.ones(img.shape, np.uint8), r, canvas.shape[::-1]) > 0
    nd = find_nodata(canvas)
    assert nd.value == 0.0
    # within the rim of pixels the warp mixed with the fill (about 1 % of this canvas)
    assert nd.share == pytest.approx(1.0 - picture.mean(), abs=0.015)
    assert nd.valid[picture].mean() > 0.99  # the picture is scene
    assert (~nd.valid)[~picture].mean() > 0.95  # the corners are not


def test_a_canvas_from_a_homography_warp_is_found(raccoon):
    img = _textured(raccoon)
    h, w = img.shape
    src = np.float32([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]])
    dst = np.float32([[120, 40], [700, 10], [760, 520], [60, 430]])  # a facade from below
    hom = cv2.getPerspectiveTransform(src, dst)
    canvas = cv2.warpPerspective(img, hom, (820, 560), flags=cv2.INTER_LINEAR)
    picture = cv2.warpPerspective(np.ones((h, w), np.uint8), hom, (820, 560)) > 0
    nd = find_nodata(canvas)
    assert nd.share == pytest.approx(1.0 - picture.mean(), abs=0.015)
    assert nd.valid[picture].mean() > 0.99


@pytest.mark.parametrize("kind", FLAT_KINDS)
def test_flat_and_clipped_regions_of_the_scene_are_not_no_data(raccoon, kind):
    """A clipped sky, a night sky, a backdrop and a plain sky over 30-50 % of the picture,
    behind the scene's own outline (``synthetic.flatten``): scene, not canvas."""
    img = _textured(raccoon)
    rng = np.random.default_rng(7)
    d = flat_field(img.shape, (0, 0, img.shape[1], img.shape[0]), 0.45, rng)
    flat = flatten(img, d, kind, rng)
    assert find_nodata(flat).share == 0.0


def test_a_straight_band_along_a_side_is_scene_and_a_slanted_corner_is_canvas():
    band = np.zeros((200, 300), bool)
    band[:80] = True
    assert not canvas_of(band).any()
    corner = np.fromfunction(lambda y, x: x + 2 * y < 180, (200, 300))
    assert canvas_of(corner).sum() == corner.sum()


def test_a_declared_value_is_no_data_in_any_shape_and_none_turns_it_off(raccoon):
    """A round mask (no straight edge, so the automatic rule leaves it) is taken when its
    value is declared, as GDAL rasters declare theirs."""
    img = _textured(raccoon).copy()
    yy, xx = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    outside = (xx - 320) ** 2 + (yy - 240) ** 2 > 230 ** 2
    img[outside] = 7.0
    declared = find_nodata(img, NoDataParams(rule=7.0))
    assert declared.value == 7.0
    assert declared.share == pytest.approx(outside.mean(), abs=0.01)
    assert find_nodata(img, NoDataParams(rule="none")).valid is None


def test_a_noisy_canvas_is_found_through_its_median():
    """A canvas with 3 grey levels of sensor noise over an offset (the synthetic low images):
    its level is read through a 5x5 median."""
    rng = np.random.default_rng(1)
    img = np.clip(rng.normal(128, 40, (300, 400)), 0, 255).astype(np.float32)
    img = cv2.GaussianBlur(img, (0, 0), 1.5)
    canvas, _ = on_canvas(img, 25.0)
    noisy = np.clip(canvas + 4.0 + rng.normal(0, 3.0, canvas.shape), 0, 255).astype(np.float32)
    assert find_nodata(noisy).share == pytest.approx((canvas == 0).mean(), abs=0.03)


def test_the_json_says_what_was_taken_as_no_data(raccoon):
    img = _textured(raccoon, (320, 240))
    low = cv2.resize(raccoon, (512, 384), interpolation=cv2.INTER_AREA)
    high, _ = on_canvas(cv2.resize(img, (640, 480)), 20.0)
    r = match(low, high)
    d = r.to_dict()
    finer = d["high"] if r.order == "given" else d["low"]
    assert finer["nodata"]["value"] == 0.0 and 0.1 < finer["nodata"]["share"] < 0.5
    coarser = d["low"] if r.order == "given" else d["high"]
    assert coarser["nodata"] == {"value": None, "share": 0.0}
    assert d["config"]["nodata"]["rule"] == "auto"


def test_the_rule_typed_by_a_user():
    assert parse_rule("auto") == "auto" and parse_rule("NONE") == "none"
    assert parse_rule("0") == 0.0 and math.isclose(parse_rule("254.5"), 254.5)
    for beyond in ("nan", "-9.5", "256"):  # the images are matched as 8-bit grey: 0 to 255
        with pytest.raises(ValueError, match="--nodata"):
            parse_rule(beyond)
    with pytest.raises(ValueError, match="nodata.rule"):
        NoDataParams(rule=300.0)
    assert NoDataParams(rule="3").rule == 3.0  # as --set nodata.rule=3 gives it
    with pytest.raises(ValueError, match="nodata.rule"):
        NoDataParams(rule="black")
