"""Synthetic zoom pairs: the truth is exact, the footprint fits, the seed decides everything."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from scalematch.geometry import apply, similarity_parts
from scalematch.lab.datasets import scene_of
from scalematch.lab.synthetic import (ZoomPair, make_unrelated_pair, make_zoom_pair,
                                      pairs_from_photos, unrelated_from_pairs)

RACCOON = Path(__file__).resolve().parents[2] / "data" / "raccoon.jpg"


def _corners(shape):
    h, w = shape[:2]
    return np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=np.float64)


def _ncc(a: np.ndarray, b: np.ndarray) -> float:
    a = a - a.mean()
    b = b - b.mean()
    return float((a * b).sum() / math.sqrt((a * a).sum() * (b * b).sum()))


@pytest.mark.parametrize("ratio", [2.0, 3.0])
def test_truth_is_exact(raccoon, ratio):
    """high warped by the truth (after the camera blur) equals low over the footprint."""
    pair = make_zoom_pair(raccoon, ratio, np.random.default_rng(1))
    lh, lw = pair.low.shape
    blurred = cv2.GaussianBlur(pair.high, (0, 0), 0.5 * math.sqrt(ratio ** 2 - 1))
    warped = cv2.warpAffine(blurred, pair.truth, (lw, lh), flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(np.ones_like(pair.high), pair.truth, (lw, lh), flags=cv2.INTER_NEAREST)
    mask = cv2.erode(mask, np.ones((7, 7), np.uint8)) > 0  # away from the crop's edge
    assert mask.sum() > 1000
    assert _ncc(warped[mask], pair.low[mask]) > 0.97
    # a truth off by 2 low px correlates visibly worse
    off = pair.truth.copy()
    off[0, 2] += 2.0
    shifted = cv2.warpAffine(blurred, off, (lw, lh), flags=cv2.INTER_LINEAR)
    assert _ncc(shifted[mask], pair.low[mask]) < _ncc(warped[mask], pair.low[mask]) - 0.05


def test_ratio_and_angle_recoverable(raccoon):
    pair = make_zoom_pair(raccoon, 2.5, np.random.default_rng(2))
    ratio, angle, _ = similarity_parts(pair.truth)
    assert ratio == pytest.approx(2.5, rel=1e-9)
    assert angle == pytest.approx(pair.angle_deg, abs=1e-9)
    assert -180.0 <= pair.angle_deg < 180.0
    assert pair.truth.shape == (2, 3)


def test_footprint_inside_low_and_grey_levels(raccoon):
    for seed in range(4):
        pair = make_zoom_pair(raccoon, 2.0, np.random.default_rng(seed), high_size=(200, 150),
                              low_max=(300, 250))
        lh, lw = pair.low.shape
        assert lh <= 250 and lw <= 300
        assert pair.high.shape == (150, 200)
        fp = apply(pair.truth, _corners(pair.high.shape))
        assert fp.min() >= -0.5 and fp[:, 0].max() <= lw - 0.5 and fp[:, 1].max() <= lh - 0.5
        assert pair.low.dtype == np.float32 and pair.high.dtype == np.float32
        assert np.array_equal(pair.low, np.rint(pair.low))  # an 8-bit image
        assert pair.low.min() >= 0 and pair.low.max() <= 255
        assert 0.75 <= pair.gain <= 1.2 and -15 <= pair.offset <= 15 and 0 <= pair.noise_std <= 3
        x, y = pair.crop_xy
        assert np.array_equal(pair.high, raccoon[y:y + 150, x:x + 200])


def test_crop_at_most_half_of_photo(raccoon):
    pair = make_zoom_pair(raccoon, 2.0, np.random.default_rng(0))
    assert pair.high.shape == (384, 512)  # 640x480 capped at half of 1024x768


def test_same_seed_same_pair_other_seed_other_pair(raccoon):
    a = make_zoom_pair(raccoon, 3.0, np.random.default_rng(7))
    b = make_zoom_pair(raccoon, 3.0, np.random.default_rng(7))
    c = make_zoom_pair(raccoon, 3.0, np.random.default_rng(8))
    assert np.array_equal(a.low, b.low) and np.array_equal(a.high, b.high)
    assert np.array_equal(a.truth, b.truth)
    assert not np.array_equal(a.truth, c.truth)


def test_pairs_from_photos_order_and_determinism():
    ratios = [2, 3]
    first = list(pairs_from_photos([RACCOON], ratios, seed=5))
    again = list(pairs_from_photos([RACCOON], ratios, seed=5))
    other = list(pairs_from_photos([RACCOON], ratios, seed=6))
    assert [p.ratio for p in first] == [2.0, 3.0]
    assert all(p.source == "raccoon.jpg" for p in first)
    assert all(np.array_equal(p.low, q.low) and np.array_equal(p.truth, q.truth)
               for p, q in zip(first, again))
    assert not np.array_equal(first[0].truth, other[0].truth)
    # a pair depends on (seed, photo, ratio) only, not on the other ratios asked for
    alone = next(pairs_from_photos([RACCOON], [3], seed=5))
    assert np.array_equal(alone.truth, first[1].truth)


def test_unrelated_pair(raccoon):
    other = np.ascontiguousarray(raccoon[::-1, ::-1])
    pair = make_unrelated_pair(raccoon, other, 2.0, np.random.default_rng(0),
                               source_low="a_1.jpg", source_high="b_1.jpg")
    assert pair.truth is None
    assert pair.high_source == "b_1.jpg"
    x, y = pair.crop_xy
    h, w = pair.high.shape
    assert np.array_equal(pair.high, other[y:y + h, x:x + w])


def test_unrelated_from_pairs_never_pairs_one_scene():
    rng = np.random.default_rng(0)
    z = np.zeros((4, 4), np.float32)
    t = np.eye(3)[:2]
    pairs = [ZoomPair(low=z + i, high=z + 10 + i, truth=t, ratio=r, angle_deg=0.0, source=s)
             for i, (s, r) in enumerate([("a_1", 2.0), ("a_2", 2.0), ("b_1", 2.0),
                                         ("c_1", 3.0), ("d_1", 3.0)])]
    out = unrelated_from_pairs(pairs, 50, rng, scene_of)
    assert len(out) == 2 * 2 + 2  # a_1/a_2 x b_1 both ways, c_1 x d_1 both ways
    for u in out:
        assert u.truth is None
        assert scene_of(u.source) != scene_of(u.high_source)
    again = unrelated_from_pairs(pairs, 3, np.random.default_rng(0), scene_of)
    assert [(u.source, u.high_source) for u in again] == \
        [(u.source, u.high_source) for u in out[:3]]


def test_the_least_textured_crop_is_drawn_from_the_same_candidates(raccoon):
    from scalematch.lab.synthetic import choose_crop, texture_score

    most = choose_crop(raccoon, 3.0, np.random.default_rng(1), (200, 150))
    least = choose_crop(raccoon, 3.0, np.random.default_rng(1), (200, 150), pick="least")
    score = lambda c: texture_score(raccoon[c[1]:c[1] + c[3], c[0]:c[0] + c[2]], 3.0)  # noqa: E731
    assert score(least) < score(most)
    with pytest.raises(ValueError, match="pick must be one of"):
        choose_crop(raccoon, 3.0, np.random.default_rng(1), (200, 150), pick="some")


@pytest.mark.parametrize("spread", [4.0, 8.0])
def test_a_perspective_pair_spans_its_local_ratios_and_its_truth_lines_the_pixels_up(raccoon,
                                                                                      spread):
    """make_perspective_pair: over the high image the truth's local ratio (high px
    per low px, 1 / sqrt(det J)) runs from the ratio asked to ratio x spread (within 1 %, the
    extremes sit at corners), and the high image warped by it matches the low image (ZNCC > 0.8
    over the footprint: noise and blur aside, the same pixels)."""
    from scalematch.lab.synthetic import make_perspective_pair

    pair = make_perspective_pair(raccoon, 2.0, spread, np.random.default_rng(1))
    h = pair.truth
    hh, ww = pair.high.shape
    xy = np.stack(np.meshgrid(np.linspace(0, ww - 1, 33), np.linspace(0, hh - 1, 25)),
                  -1).reshape(-1, 2)
    w = h[2, 0] * xy[:, 0] + h[2, 1] * xy[:, 1] + h[2, 2]
    local = 1.0 / np.sqrt(np.linalg.det(h) / w ** 3)  # det of the Jacobian: det(H) / w^3
    assert local.min() == pytest.approx(2.0, rel=0.01)
    assert local.max() == pytest.approx(2.0 * spread, rel=0.01)
    size = (pair.low.shape[1], pair.low.shape[0])
    warped = cv2.warpPerspective(pair.high, h, size)
    inside = cv2.warpPerspective(np.ones_like(pair.high), h, size, flags=cv2.INTER_NEAREST) > 0
    assert np.corrcoef(warped[inside], pair.low[inside])[0, 1] > 0.8


@pytest.mark.parametrize("ratio,tilt", [(2.0, 2.83), (2.0, 4.0)])
def test_an_oblique_pair_has_the_finer_image_foreshortened_and_its_truth_lines_the_pixels_up(
        raccoon, ratio, tilt):
    """make_oblique_pair: the truth's directional ratios (high px per low px) are
    ratio and ratio / tilt exactly (the finer image is coarser along one axis), and the high
    image warped by it matches the low image (ZNCC > 0.9 over the footprint)."""
    from scalematch.lab.synthetic import make_oblique_pair

    pair = make_oblique_pair(raccoon, ratio, tilt, np.random.default_rng(2), high_size=(160, 120))
    sv = 1.0 / np.linalg.svd(pair.truth[:, :2])[1]
    assert sorted(sv) == pytest.approx([ratio / tilt, ratio], rel=1e-9)
    size = (pair.low.shape[1], pair.low.shape[0])
    warped = cv2.warpAffine(pair.high, pair.truth, size)
    inside = cv2.erode(cv2.warpAffine(np.ones_like(pair.high), pair.truth, size,
                                      flags=cv2.INTER_NEAREST), np.ones((3, 3))) > 0
    assert inside.sum() > 1000
    assert np.corrcoef(warped[inside], pair.low[inside])[0, 1] > 0.9


def test_an_oblique_pair_says_when_the_photo_holds_no_crop(raccoon):
    from scalematch.lab.synthetic import make_oblique_pair

    with pytest.raises(ValueError, match="holds no"):
        make_oblique_pair(raccoon[:100, :100], 2.0, 8.0, np.random.default_rng(0),
                          high_size=(180, 180))


@pytest.mark.parametrize("kind", ["clipped", "night", "backdrop", "sky"])
def test_a_flat_pair_has_its_flat_region_and_an_exact_truth(raccoon, kind):
    """The finer image is 30-50 % flat (clipped at 255, crushed dark, one backdrop level, a
    smooth sky) behind a wavy outline, the coarser image sees the same region, and the truth
    lines the pixels up as a plain zoom pair's does."""
    from scalematch.lab.synthetic import FLAT_SHARE_RANGE, make_flat_pair

    photo = cv2.resize(raccoon, (2048, 1536), interpolation=cv2.INTER_CUBIC)
    pair = make_flat_pair(photo, 2.0, kind, np.random.default_rng(5), high_size=(320, 240))
    hi = pair.high
    gx = cv2.Sobel(hi, cv2.CV_32F, 1, 0) / 8
    gy = cv2.Sobel(hi, cv2.CV_32F, 0, 1) / 8
    flat = np.hypot(gx, gy) < {"clipped": 0.5, "night": 0.5, "backdrop": 0.5, "sky": 3.0}[kind]
    lo, hi_share = FLAT_SHARE_RANGE
    assert lo - 0.1 < flat.mean() < hi_share + 0.1
    if kind == "clipped":
        assert (pair.high == 255).mean() > lo - 0.1
    lh, lw = pair.low.shape
    blurred = cv2.GaussianBlur(pair.high, (0, 0), 0.5 * math.sqrt(3.0))
    warped = cv2.warpAffine(blurred, pair.truth, (lw, lh), flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(np.ones_like(pair.high), pair.truth, (lw, lh), flags=cv2.INTER_NEAREST)
    mask = cv2.erode(mask, np.ones((7, 7), np.uint8)) > 0
    assert _ncc(warped[mask], pair.low[mask]) > 0.95
