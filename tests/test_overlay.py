"""overlay: the finer image warped onto the coarser one, its footprint outlined, its captions."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from scalematch.geometry import apply, footprint
from scalematch.overlay import overlay
from scalematch.render import matches_image
from test_render import green_red_gap, make_result, outline_mask, picture_of


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
    from scalematch.overlay import CORNER_DOT_PER_THICKNESS, _outline_thickness

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
    import scalematch.overlay as overlay_module

    x0, y0 = 700, 500  # lower right of the photo: the inset goes to the upper left
    high = raccoon[y0:y0 + 48, x0:x0 + 64].copy()
    low = cv2.resize(raccoon, (512, 384), interpolation=cv2.INTER_AREA)
    t = np.array([[0.5, 0, x0 / 2 - 0.25], [0, 0.5, y0 / 2 - 0.25]])
    res = make_result(t, high_shape=high.shape)
    with_inset = overlay(low, high, res)[-384:]  # the pictures, below their captions (the
    monkeypatch.setattr(overlay_module, "INSET_MAX_SHARE", 0.0)  # inset's says one line more)
    without = overlay(low, high, res)[-384:]
    changed = np.any(with_inset != without, axis=2)
    ys, xs = np.nonzero(changed)
    near = (np.abs(xs - (x0 / 2 + 16)) < 40) & (np.abs(ys - (y0 / 2 + 12)) < 40)
    assert near.any()  # the region it enlarges is framed where it is
    xs, ys = xs[~near], ys[~near]
    side = int(overlay_module.INSET_SHARE * 384)
    assert side - 2 <= xs.max() - xs.min() <= side + 12
    assert xs.max() < x0 / 2 and ys.max() < y0 / 2  # upper left, clear of the footprint
    outline = overlay_module._footprint_outline(*((make_result(t).transform, (360, 480),
                                                   (377, 419))))[0]
    assert overlay_module.inset_plan(outline, (377, 419)) is None  # the demo's size of footprint


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


def test_a_no_draws_its_refused_candidate_dashed_and_its_inliers_grey(pair):
    """A "no" with a ``rejected`` candidate: the overlay draws its footprint dashed in red where
    the transform puts it (dashes and gaps along each side), nothing where a match's outline
    would be amber; matches.png draws its inliers in grey."""
    from dataclasses import replace

    from scalematch.overlay import REJECTED
    from scalematch.render import REJECTED_DOT
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
    from scalematch.overlay import EPIPOLAR_LINE, EPIPOLAR_LINES_DRAWN

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


def test_a_fundamental_matrix_marks_its_inliers_in_proportion_to_the_picture():
    """On a 2,500 px picture an inlier's circle is seen when the picture is seen whole: its
    extent grows with the picture (a 3 px circle was a speck there), and stays small on a
    small one."""
    from scalematch.overlay import INLIER_DOT

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
