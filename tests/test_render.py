"""render: pictures of a hand-built MatchResult with a known transform."""

from __future__ import annotations

import csv
import dataclasses
import json
import math

import cv2
import numpy as np
import pytest

from scalematch.config import Config
from scalematch.geometry import apply, compose, footprint, similarity_parts
from scalematch.lab.synthetic import zoom_warp
from scalematch.chart import MUTED_COLOUR
from scalematch.render import (OUTLINE, disagreeing_rows, matches_image, overlay,
                               overlay_zoom, scale_plot, verdict, write_outputs)
from scalematch.result import MatchResult, ScaleRow

RATIO, ANGLE = 3.0, 25.0
CROP = (300, 200, 480, 360)  # x0, y0, w, h of the high-resolution crop of the photo


@pytest.fixture(scope="module")
def pair(raccoon):
    """(low, high, T): high a full-resolution crop, low the whole photo turned and shrunk by 3."""
    x0, y0, w, h = CROP
    high = raccoon[y0:y0 + h, x0:x0 + w].copy()
    low, a = zoom_warp(raccoon, RATIO, ANGLE)
    t = compose(a, np.array([[1.0, 0, x0], [0, 1.0, y0]]))  # high px -> photo px -> low px
    return low, high, t


def make_result(t, model="similarity", matched=True, high_shape=(360, 480)) -> MatchResult:
    rng = np.random.default_rng(1)
    xy_high = rng.uniform([0, 0], [high_shape[1] - 1, high_shape[0] - 1], size=(40, 2))
    if t is not None and model != "fundamental":
        xy_low = apply(t, xy_high)
    else:
        xy_low = xy_high / RATIO
    ratio, angle, tr = similarity_parts(t) if t is not None else (np.nan, np.nan, (np.nan,) * 2)
    rows = tuple(ScaleRow(s=s, ratio=ratio if s == 3 else np.nan, points=100 * s, initial=50,
                          kept=30, inliers=40 if s == 3 else 3, outlier_pct=20.0)
                 for s in (1.0, 2.0, 3.0, 4.0))
    return MatchResult(
        matched=matched, reason="" if matched else "too few inliers", model=model,
        transform=t if matched else None, resolution_ratio=ratio if matched else np.nan,
        rotation_deg=angle if matched else np.nan, translation=tr, best_scale=3.0,
        inliers=np.hstack([xy_high, xy_low]) if matched else np.zeros((0, 4)), scales=rows,
        timings={"total": 1.0}, config=Config())


def green_red_gap(out: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """|green - red| of the overlay over the footprint ``corners``, eroded by 3 px: the warped
    high image against the low one, pixel by pixel."""
    inside = np.zeros(out.shape[:2], np.uint8)
    cv2.fillConvexPoly(inside, np.round(corners).astype(np.int32), 1)
    inside = cv2.erode(inside, np.ones((7, 7), np.uint8)).astype(bool)
    return np.abs(out[..., 1].astype(float) - out[..., 2].astype(float))[inside]


def outline_mask(img: np.ndarray) -> np.ndarray:
    return np.all(np.abs(img.astype(int) - np.array(OUTLINE)) <= 40, axis=2)


def picture_of(out: np.ndarray, low: np.ndarray) -> int:
    """The row of ``out`` (an overlay) where the picture of ``low`` (grey, the size the overlay
    draws it) begins, between the caption bands: where the overlay's blue channel is ``low``
    (magenta: the coarser image in red and blue), the outline and the footprint aside."""
    h = low.shape[0]
    gaps = [np.median(np.abs(out[k:k + h, :, 0].astype(float) - low))
            for k in range(out.shape[0] - h + 1)]
    return int(np.argmin(gaps))


@pytest.mark.parametrize("as_homography", [False, True])
def test_overlay_fits_and_outlines_where_the_transform_says(pair, as_homography):
    low, high, t = pair
    tt = np.vstack([t, [0, 0, 1]]) * 2.0 if as_homography else t  # same map, scaled 3x3
    out = overlay(low, high, make_result(tt, "homography" if as_homography else "similarity"))
    assert out.shape[1:] == (low.shape[1], 3) and out.dtype == np.uint8
    assert out.shape[0] > low.shape[0] + 50  # the caption band above the picture
    out = out[-low.shape[0]:]  # the picture: no footer, no band below it
    corners = footprint(tt, high.shape)
    np.testing.assert_allclose(corners, apply(t, [[-0.5, -0.5], [479.5, -0.5], [479.5, 359.5],
                                                  [-0.5, 359.5]]), atol=1e-9)
    mask = outline_mask(out)
    # every corner and edge midpoint of the footprint has outline pixels within 2 px
    probes = np.vstack([corners, (corners + np.roll(corners, -1, axis=0)) / 2])
    ys, xs = np.nonzero(mask)
    for px, py in probes:
        assert np.min(np.hypot(xs - px, ys - py)) <= 2.0, (px, py)
    # and the outline is nowhere else: all outline pixels lie near the footprint's edges
    d = np.full(len(xs), np.inf)
    for p, q in zip(corners, np.roll(corners, -1, axis=0)):
        v = q - p
        tpar = np.clip(((xs - p[0]) * v[0] + (ys - p[1]) * v[1]) / (v @ v), 0, 1)
        d = np.minimum(d, np.hypot(xs - p[0] - tpar * v[0], ys - p[1] - tpar * v[1]))
    # the dot on the high image's top-left corner: filled, and the rest near the edges
    from scalematch.render import CORNER_DOT_PER_THICKNESS, _outline_thickness

    radius = CORNER_DOT_PER_THICKNESS * _outline_thickness(*low.shape[:2])
    at_dot = np.hypot(xs - corners[0][0], ys - corners[0][1]) <= radius + 1
    assert at_dot.sum() >= 0.6 * np.pi * radius ** 2
    assert np.percentile(d[~at_dot], 99) <= 2.5
    # inside the footprint the warped high (green) agrees with low (red): a correct fit
    diff = green_red_gap(out, corners)
    assert diff.mean() < 6.0


def test_a_small_footprint_gets_its_region_enlarged_in_a_free_corner(raccoon, monkeypatch):
    """A 64 x 48 px crop found in the photo shrunk by 2 (a 32 x 24 px footprint in 512 x 384):
    its region is drawn enlarged (INSET_SHARE of the shorter side) in the corner farthest
    from it, away from the footprint; a footprint as large as the demo's gets none."""
    import scalematch.render as render

    x0, y0 = 700, 500  # lower right of the photo: the inset goes to the upper left
    high = raccoon[y0:y0 + 48, x0:x0 + 64].copy()
    low = cv2.resize(raccoon, (512, 384), interpolation=cv2.INTER_AREA)
    t = np.array([[0.5, 0, x0 / 2 - 0.25], [0, 0.5, y0 / 2 - 0.25]])
    res = make_result(t, high_shape=high.shape)
    with_inset = overlay(low, high, res)[-384:]  # the pictures, below their captions (the
    monkeypatch.setattr(render, "INSET_MAX_SHARE", 0.0)  # inset's says one line more)
    without = overlay(low, high, res)[-384:]
    changed = np.any(with_inset != without, axis=2)
    ys, xs = np.nonzero(changed)
    near = (np.abs(xs - (x0 / 2 + 16)) < 40) & (np.abs(ys - (y0 / 2 + 12)) < 40)
    assert near.any()  # the region it enlarges is framed where it is
    xs, ys = xs[~near], ys[~near]
    side = int(render.INSET_SHARE * 384)
    assert side - 2 <= xs.max() - xs.min() <= side + 12
    assert xs.max() < x0 / 2 and ys.max() < y0 / 2  # upper left, clear of the footprint
    assert render.inset_plan(render._footprint_outline(*((make_result(t).transform,
                                                           (360, 480), (377, 419))))[0],
                             (377, 419)) is None  # the demo's size of footprint


def test_overlay_is_grey_where_they_agree_whatever_the_exposure(pair):
    """The low image darker and flatter than the high one (gain 0.6, offset 20, as the
    benchmark's pairs are): the warped high image is brought to the low one's grey levels, so
    a correct fit still reads grey (green = red within 6 levels on average)."""
    low, high, t = pair
    dim = np.clip(low * 0.6 + 20.0, 0, 255)
    out = overlay(dim, high, make_result(t))
    corners = footprint(t, high.shape)
    diff = green_red_gap(out, corners)
    assert diff.mean() < 6.0


def test_overlay_is_grey_where_they_agree_beside_a_no_data_canvas(pair):
    """Half of the footprint on the low image's black canvas (no data, touching its border):
    the grey levels are matched where both images show the scene, so the other half still
    reads grey (green = red within 6 levels on average), not tinted by the black."""
    low, high, t = pair
    corners = footprint(t, high.shape)
    cut = int(round(corners[:, 0].mean()))
    canvas = low.copy()
    canvas[:, :cut] = 0.0
    out = overlay(canvas, high, make_result(t))
    inside = np.zeros(out.shape[:2], np.uint8)
    cv2.fillConvexPoly(inside, np.round(corners).astype(np.int32), 1)
    inside = cv2.erode(inside, np.ones((7, 7), np.uint8)).astype(bool)
    inside[:, :cut + 4] = False  # the half that shows the scene in both
    gap = np.abs(out[..., 1].astype(float) - out[..., 2].astype(float))[inside]
    assert inside.sum() > 1000 and gap.mean() < 6.0


def test_overlay_of_a_wrong_transform_disagrees(pair):
    low, high, t = pair
    wrong = t.copy()
    wrong[:, 2] += 12.0  # 12 low-res pixels off
    out = overlay(low, high, make_result(wrong))
    corners = footprint(wrong, high.shape)
    diff = green_red_gap(out, corners)
    assert diff.mean() > 10.0


def test_overlay_when_not_matched_or_fundamental(pair):
    low, high, t = pair
    out = overlay(low, high, make_result(None, matched=False))
    h = low.shape[0]
    assert out.shape[0] > h + 20 and out.shape[1:] == (low.shape[1], 3)
    assert not outline_mask(out).any()
    plain = np.clip(low, 0, 255).astype(np.uint8)
    assert out[:-h].max() > 200  # the caption is written in a band above
    assert np.array_equal(out[-h:, :, 0], plain)  # and the picture is low itself, uncovered
    f = overlay(low, high, make_result(np.eye(3), model="fundamental"))
    assert f.shape[0] > h and f.shape[1:] == (low.shape[1], 3)


def test_matches_image_and_scale_plot(pair):
    low, high, t = pair
    res = make_result(t)
    img = matches_image(low, high, res)
    assert img.ndim == 3 and 360 <= img.shape[0] <= 720 + 100
    assert img.shape[1] >= low.shape[1] + high.shape[1] - 1  # both at height 377
    plot = scale_plot(res)
    assert plot.ndim == 3 and plot.shape[2] == 3
    # the winner (s = 3, index 2) is drawn in the highlight colour: some red pixels exist
    assert np.any(np.all(plot == (40, 39, 214), axis=2))
    assert scale_plot(make_result(None, matched=False)).ndim == 3


def collapsed_fit_result(model="similarity") -> MatchResult:
    """A match at s = 2.52 (ratio 4.01) beside a fit at s = 1.59 that collapses many finer
    points onto a few coarser ones (ratio 406, 79 inliers: measured on a 185 px low image)."""
    rows = (ScaleRow(1.587, 406.6, 6000, 1559, 356, 79, 94.9, 104.6),
            ScaleRow(2.52, 4.01, 3198, 862, 181, 19, 97.8, -29.9),
            ScaleRow(4.0, 4.6, 1412, 90, 20, 4, 95.6, -30.0),
            ScaleRow(8.0, 2.9e20, 346, 102, 24, 5, 95.1, 150.5))
    return MatchResult(matched=True, model=model, best_scale=2.52, resolution_ratio=4.01,
                       scales=rows, config=Config())


def test_a_fit_whose_ratio_contradicts_its_scale_is_shown_as_not_counted():
    res = collapsed_fit_result()
    assert disagreeing_rows(res) == [0, 3]  # 4.6 at s = 4 is within the 1.6x agreement
    plot = scale_plot(res)
    grey = np.all(plot == MUTED_COLOUR, axis=2)
    assert grey.any() and not np.all(plot == (40, 39, 214), axis=2)[grey].any()
    # the tall grey bar is the first slot's (left quarter), the red one the second's
    cols = np.nonzero(grey.any(axis=0))[0]
    assert cols.min() < plot.shape[1] // 4
    assert disagreeing_rows(collapsed_fit_result("fundamental")) == []  # no ratio to compare


def test_write_outputs(tmp_path, pair):
    low, high, t = pair
    paths = write_outputs(tmp_path / "out", "low.png", "high.png", low, high, make_result(t))
    for name in ("overlay.png", "matches.png", "scales.png", "matches.csv"):
        assert paths[name].is_file() and paths[name].stat().st_size > 0
    with open(paths["matches.csv"]) as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["x_high", "y_high", "x_low", "y_low"] and len(rows) == 41
    # a low image under 600 px is drawn enlarged, the high one warped onto that grid: grey
    # where they agree, as at its own size
    zoom = overlay_zoom(low.shape)
    drawn = cv2.imread(str(paths["overlay.png"]))
    assert zoom == 2 and drawn.shape[1:] == (2 * low.shape[1], 3)
    big = cv2.resize(np.clip(low, 0, 255).astype(np.uint8), None, fx=zoom, fy=zoom,
                     interpolation=cv2.INTER_LINEAR)
    top = picture_of(drawn, big)
    assert top > 20 and drawn.shape[0] - top - big.shape[0] > 10  # a band above, one below
    drawn = drawn[top:top + big.shape[0]]
    corners = footprint(t, high.shape) * zoom + (zoom - 1) / 2  # cv2.resize's grid
    assert green_red_gap(drawn, corners).mean() < 3.0  # measured 1.7 (2.7 at its own size)
    # not matched: everything is still written, the CSV has only its header
    paths = write_outputs(tmp_path / "none", "low.png", "high.png", low, high,
                          make_result(None, matched=False))
    assert paths["matches.csv"].read_text().strip() == "x_high,y_high,x_low,y_low"


def border_pair(raccoon, x0, y0, w, h, f):
    """(low, t): low a w x h crop of the photo at (x0, y0) shrunk by f; t maps the whole photo
    (the high image) onto it, so its footprint runs beyond every side of low."""
    low = cv2.resize(raccoon[y0:y0 + h, x0:x0 + w], (round(w / f), round(h / f)),
                     interpolation=cv2.INTER_AREA)
    # high px -> low px, centre convention: x_low = (x_high + 0.5 - x0) / f - 0.5
    t = np.array([[1 / f, 0, (0.5 - x0) / f - 0.5], [0, 1 / f, (0.5 - y0) / f - 0.5]])
    corners = footprint(t, raccoon.shape)
    assert corners[:, 0].min() < 0 and corners[:, 0].max() > low.shape[1]  # beyond every side
    assert corners[:, 1].min() < 0 and corners[:, 1].max() > low.shape[0]
    return low, t


def assert_outlined_all_round(mask: np.ndarray, edge: int = 3) -> None:
    """The outline (2 px thick, inside the picture) runs along all four sides of ``mask``
    (within ``edge`` px of the border) and nowhere inside."""
    sides = {"left": mask[:, :edge].any(axis=1), "right": mask[:, -edge:].any(axis=1),
             "top": mask[:edge].any(axis=0), "bottom": mask[-edge:].any(axis=0)}
    for side, hit in sides.items():
        assert hit.mean() > 0.97, (side, hit.mean())  # all along (round corners aside)
    assert not mask[2 * edge:-2 * edge, 2 * edge:-2 * edge].any()


@pytest.mark.parametrize("crop", [(300, 200, 400, 300, 2.0), (100, 100, 800, 600, 2.0),
                                  (40, 30, 950, 700, 1.25)])
def test_the_captions_go_above_and_below_the_picture_at_any_size(raccoon, crop):
    """high (the whole photo) covers more than the whole low image (a crop of it, shrunk by 2:
    200x150, 400x300 and 512x384 px): the footprint runs beyond the picture on every side, so
    its outline follows the picture's edges, all the way round. The captions are bands above
    and below the picture, at any size (drawn over it, they covered 30-40 % of a 3:2 picture
    and hid a footprint's corner and its dot): the whole picture shows, undimmed."""
    low, t = border_pair(raccoon, *crop)
    out = overlay(low, raccoon, make_result(t, high_shape=raccoon.shape),
                  footer=["low: low.png   high: high.png"])  # as write_outputs draws it
    h = low.shape[0]
    assert out.shape[1] == low.shape[1] and out.shape[0] > h
    top = picture_of(out, low)
    gap = np.mean(np.abs(out[top + 8:top + h - 8, 8:-8, 0].astype(float) - low[8:-8, 8:-8]))
    assert gap < 1.0  # the picture undimmed: no strip over it
    assert top > 20 and out.shape[0] - h - top > 10  # a band above (3 lines), one below
    assert_outlined_all_round(outline_mask(out[top:top + h]))
    assert not outline_mask(out[:top]).any()  # the bands hold text only
    assert not outline_mask(out[top + h:]).any()


def test_told_apart_names_two_files_of_the_same_name_by_their_folders():
    from scalematch.render import told_apart

    assert told_apart("data/boat/img1.png", "data/graf/img1.png") == ("boat/img1.png",
                                                                      "graf/img1.png")
    assert told_apart("a/low.png", "a/high.png") == ("low.png", "high.png")


def test_the_verdict_calls_no_image_finer_near_a_ratio_of_1():
    """Two crops of one photo match at ratio 1.000, either way round by chance: "the first
    image is the finer one" would be false there; what the transform maps is said instead."""
    def swapped(ratio):
        return MatchResult(matched=True, model="similarity", resolution_ratio=ratio,
                           rotation_deg=0.0, order="swapped", best_scale=1.0,
                           transform=np.array([[1 / ratio, 0, 0], [0, 1 / ratio, 0.0]]),
                           inliers=np.zeros((0, 4)))
    assert verdict(swapped(1.0)).endswith(
        "order swapped (the transform maps the first image into the second)")
    assert verdict(swapped(3.0)).endswith("order swapped (the first image is the finer one)")


def test_the_verdict_says_which_image_the_tilted_view_was_of():
    """A match found on a view of the coarser image says so; one on a view of the finer image
    says only the tilt."""
    from scalematch.result import Evidence

    def found(view_of):
        return MatchResult(matched=True, model="affine", resolution_ratio=1.0, rotation_deg=0.0,
                           best_scale=2.0, transform=np.array([[1.0, 0, 0], [0, 1.0, 0]]),
                           inliers=np.zeros((0, 4)),
                           evidence=Evidence(view_tilt=4.0, view_longitude_deg=36.0,
                                             view_of=view_of))
    assert verdict(found("coarser")).endswith(
        "seen tilted by 4 at 36 deg (the coarser image)")
    assert verdict(found("finer")).endswith("seen tilted by 4 at 36 deg")


def test_a_no_draws_its_refused_candidate_dashed_and_its_inliers_grey(pair):
    """A "no" with a ``rejected`` candidate: the overlay draws its footprint dashed in red where
    the transform puts it (dashes and gaps along each side), nothing where a match's outline
    would be amber; matches.png draws its inliers in grey."""
    from dataclasses import replace

    from scalematch.render import REJECTED, REJECTED_DOT
    from scalematch.result import Rejected

    low, high, t = pair
    found = make_result(t)
    no = replace(make_result(None, matched=False), reason="ambiguous: ...",
                 rejected=Rejected(t, "similarity", found.inliers, -30.0, "uniqueness",
                                   {"unique_ratio": 1.2, "min_unique_ratio": 2.0}))
    out = overlay(low, high, no)[-low.shape[0]:]  # the picture, below its caption
    assert not outline_mask(out).any()
    red = np.all(np.abs(out.astype(int) - np.array(REJECTED)) <= 40, axis=2)
    corners = footprint(t, high.shape)
    # along the top side of the footprint: red dashes with gaps between them
    a, b = corners[0], corners[1]
    on_side = [bool(red[int(round(y)), int(round(x))].any())
               for x, y in (a + (b - a) * f for f in np.linspace(0.05, 0.95, 60))]
    assert 0.3 < np.mean(on_side) < 0.8
    far = np.ones(red.shape, bool)
    cv2.fillConvexPoly(far.view(np.uint8), np.round(corners).astype(np.int32), 0)
    far = cv2.erode(far.astype(np.uint8), np.ones((15, 15), np.uint8)).astype(bool)
    assert not red[far].any()  # nothing away from its footprint
    m = matches_image(low, high, no)
    grey = np.all(np.abs(m.astype(int) - np.array(REJECTED_DOT)) <= 8, axis=2)
    assert grey.sum() > 40  # the refused inliers' dots


def test_a_fundamental_matrix_is_drawn_with_the_epipolar_lines_of_some_inliers(pair):
    """A rectified pair's matrix (y' = y): its inliers' epipolar lines are rows of the low
    image, drawn in their colour across its width, one per inlier drawn."""
    from scalematch.render import EPIPOLAR_LINE, EPIPOLAR_LINES_DRAWN

    low, high, _ = pair
    f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    res = make_result(f, model="fundamental")
    out = overlay(low, high, res)
    picture = out[-low.shape[0]:]
    # anti-aliased: a line's pixels are near its colour over the rows it crosses
    lined = np.abs(picture.astype(int) - EPIPOLAR_LINE).sum(axis=2) < 120
    rows = np.nonzero(lined.sum(axis=1) > 0.9 * low.shape[1])[0]
    drawn = np.linspace(0, len(res.inliers) - 1, EPIPOLAR_LINES_DRAWN).round().astype(int)
    expected = np.round(res.inliers[drawn, 1]).astype(int)
    assert len(rows) >= EPIPOLAR_LINES_DRAWN - 1  # two lines may share a row
    assert all(np.min(np.abs(rows - y)) <= 1 for y in expected)


def test_the_evidence_line_says_when_windows_decided():
    """A match the final margin refused and its windows accepted says so, with their shares;
    one whose margin passed says nothing of windows."""
    from dataclasses import replace

    from scalematch.render import evidence_line
    from scalematch.result import build_evidence

    plain = dict(log10_nfa=-59.6, final_ncc=0.15, final_margin=-0.09, unique_ratio=0.69,
                 judged_by="pixels")
    by_windows = MatchResult(matched=True, model="similarity", evidence=build_evidence(
        plain, dict(near_windows=38, near_windows_agreeing=0.5, near_windows_nearby=0.026,
                    unique_windows=20, windows_agreeing=0.8, windows_elsewhere=0.2)))
    line = evidence_line(by_windows)
    assert "-0.09 against nearby placements" in line
    assert "50% of 38 windows agree there, 3% nearby" in line
    assert "80% of 20 windows agree at its place, 20% elsewhere" in line
    margin_only = replace(by_windows, evidence=build_evidence(dict(plain, final_margin=0.3)))
    assert "windows" not in evidence_line(margin_only)
    # a refused few-inlier map: the second look's margin, and its windows where measured
    look = dict(log10_nfa=-10.0, pixel_ncc=0.2, pixel_margin=0.05, pixel_windows=37,
                pixel_windows_agreeing=0.2, pixel_windows_nearby=0.03)
    refused = MatchResult(matched=False, model="similarity", evidence=build_evidence(look))
    assert "+0.05 against nearby placements; 20% of 37 windows agree there, 3% nearby" in \
        evidence_line(refused)


def test_the_scale_chart_gives_the_answers_inliers_where_they_differ_from_the_winning_bar(
        pair, monkeypatch):
    """The verdict counts the answer's inliers (its fit refined over every scale), the bars
    each scale's own fit: a title that gave only the bars read as a contradiction (6 against
    a winning bar of 5)."""
    import scalematch.render as render

    seen = []
    monkeypatch.setattr(render, "bar_chart", lambda *a, titles, **k: seen.append(titles))
    res = make_result(pair[2])  # the winning bar (s = 3) has 40 inliers, the answer 40
    render.scale_plot(res)
    more = dataclasses.replace(res, inliers=np.vstack([res.inliers, res.inliers[:6]]))
    render.scale_plot(more)
    assert "refined" not in seen[0].title
    assert seen[1].title.endswith("the answer, refined over every scale: 46 inliers")


def test_a_degenerate_fits_ratio_is_none_in_the_table_and_the_json():
    """A fit sending every point to one gives a ratio like 7.49e+19: not a zoom. The table's
    row holds NaN (null in the JSON), and the decision ignores the row as before (a NaN ratio
    is as far from its scale as any)."""
    from scalematch.geometry import usable_ratio
    from scalematch.stages.decision import DecisionParams, disagrees

    row = ScaleRow(8.0, usable_ratio(7.49e19), 346, 102, 24, 5, 95.1, 150.5)
    assert math.isnan(row.ratio) and disagrees(row, DecisionParams())
    res = dataclasses.replace(collapsed_fit_result(), scales=(row,))
    assert json.loads(res.to_json("a.png", "b.png"))["scales"][0]["ratio"] is None


def test_a_fundamental_matrix_marks_its_inliers_in_proportion_to_the_picture():
    """On a 2,500 px picture an inlier's circle is seen when the picture is seen whole: its
    extent grows with the picture (a 3 px circle was a speck there), and stays small on a
    small one."""
    from scalematch.render import INLIER_DOT

    f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    for shape in ((1900, 2500), (360, 480)):
        low = np.full(shape, 90, np.uint8)
        res = dataclasses.replace(make_result(f, model="fundamental"),
                                  inliers=np.array([[10.0, 20.0, shape[1] / 2, shape[0] / 2]]))
        picture = overlay(low, low, res)[-shape[0]:]
        dot = np.abs(picture.astype(int) - INLIER_DOT).sum(axis=2) < 60
        ys, xs = np.nonzero(dot)
        extent = xs.max() - xs.min() + 1
        assert min(shape) / 80 <= extent <= min(shape) / 10, (shape, extent)
