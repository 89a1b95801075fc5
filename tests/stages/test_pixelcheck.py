"""The pixel check: the truth lines the pixels up clearly better than nearby wrong placements."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from scalematch.geometry import apply, as_matrix3, similarity_matrix, similarity_parts
from scalematch.lab.synthetic import make_zoom_pair
from scalematch.stages.pixelcheck import PixelParams, perturbations, pixel_check, zncc


@pytest.fixture(scope="module", params=[4.0, 8.0])
def zoom(request, raccoon):
    """Zoom pairs of data/raccoon.jpg at ratios 4 and 8 (grey-level change and noise)."""
    return make_zoom_pair(raccoon, request.param, np.random.default_rng(3))


def _elsewhere(pair, turn, at):
    ratio, angle, _ = similarity_parts(pair.truth)
    h, w = pair.high.shape
    t = similarity_matrix(1 / ratio, angle + turn)
    t[:, 2] = np.array(at) * pair.low.shape[::-1] - apply(t, [[(w - 1) / 2, (h - 1) / 2]])[0]
    return t


def test_truth_beats_its_perturbed_placements(zoom):
    check = pixel_check(zoom.low, zoom.high, zoom.truth)
    # measured on 21 pairs cut from ../shared photos (docs/design/DECISION.md, "Guided growth
    # and the pixel check, alone"): ncc >= 0.995 and margin >= 0.076; here (raccoon, ratio
    # 4 / 8) ncc 1.00, margin 0.54 / 0.46
    assert check.decided and check.reason == ""
    assert check.ncc > 0.95
    assert check.margin > 0.1
    assert len(check.perturbed) == 8 and max(check.perturbed) == pytest.approx(
        check.best_perturbed)
    assert check.overlap_fraction > 0.9


def test_wrong_placements_are_no_better_than_their_neighbours(zoom):
    for turn, at in ((90.0, (0.3, 0.3)), (180.0, (0.7, 0.6)), (35.0, (0.25, 0.75))):
        check = pixel_check(zoom.low, zoom.high, _elsewhere(zoom, turn, at))
        # measured over 84 wrong and unrelated placements: margin at most 0.005
        assert not check.margin > 0.05, (turn, at, check)


def test_perturbations_move_the_footprint():
    t = similarity_matrix(0.125, 30.0, 100.0, 80.0)
    moved = perturbations(t, (480, 640))
    assert len(moved) == 8
    centre = apply(t, [[319.5, 239.5]])[0]
    step = 0.25 * math.sqrt(80 * 60)  # a quarter of the footprint's size, low px
    shifts = [np.linalg.norm(apply(m, [[319.5, 239.5]])[0] - centre) for m in moved]
    assert shifts[:4] == pytest.approx([step] * 4)
    assert shifts[4:] == pytest.approx([0.0] * 4, abs=1e-9)  # turns, scalings about the centre
    ratios = [similarity_parts(m)[0] for m in moved[6:]]
    assert ratios == pytest.approx([8 / 2 ** (1 / 3), 8 * 2 ** (1 / 3)])


def test_partly_outside_footprint_is_measured_on_the_overlap(zoom):
    t = as_matrix3(zoom.truth).copy()
    fp_w = zoom.high.shape[1] / zoom.ratio
    # move low so that the footprint hangs 40 % over its left edge
    x_min = apply(t, [[0, 0], [zoom.high.shape[1] - 1, 0], [0, zoom.high.shape[0] - 1],
                      [zoom.high.shape[1] - 1, zoom.high.shape[0] - 1]])[:, 0].min()
    cut = int(math.ceil(x_min + 0.4 * fp_w))
    t[0, 2] -= cut
    check = pixel_check(zoom.low[:, cut:], zoom.high, t)
    assert 0.3 < check.overlap_fraction < 0.8
    assert check.ncc > 0.9 and check.margin > 0.05


def test_tiny_footprint_cannot_tell(raccoon):
    t = similarity_matrix(1 / 40.0, 0.0, 50.0, 50.0)  # 512x384 -> 13x10 low px
    check = pixel_check(raccoon, raccoon[:384, :512], t)
    assert not check.decided and math.isnan(check.ncc) and "footprint" in check.reason


def test_outside_the_low_image_cannot_tell(zoom):
    t = as_matrix3(zoom.truth).copy()
    t[0, 2] += 5000
    check = pixel_check(zoom.low, zoom.high, t)
    assert not check.decided and check.reason


def test_flat_images_cannot_tell_without_warnings():
    low = np.full((200, 300), 90.0, np.float32)
    high = np.full((240, 320), 120.0, np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check = pixel_check(low, high, similarity_matrix(0.25, 0.0, 60.0, 50.0))
    assert not check.decided and "flat" in check.reason


def test_homography_hypothesis(zoom):
    check = pixel_check(zoom.low, zoom.high, as_matrix3(zoom.truth) * 3.0)  # same map, w = 3
    assert check.ncc > 0.95 and check.margin > 0.1


def test_zncc_is_invariant_to_gain_and_offset():
    rng = np.random.default_rng(0)
    a = rng.normal(size=500)
    b = a + rng.normal(scale=0.5, size=500)
    assert zncc(a, b) == pytest.approx(zncc(a, 0.2 * b - 40.0), abs=1e-9)
    assert math.isnan(zncc(a, np.zeros(500)))
    assert PixelParams().scale_step == pytest.approx(2 ** (1 / 3))


def test_windows_tell_an_occluded_truth_from_its_neighbours(zoom, raccoon):
    """An occluder (a third of the finer image replaced by other texture) lowers one ZNCC over
    the footprint at the truth as at its nearby placements; window by window it loses only the
    windows it covers: most of the rest agree at the truth, almost none nearby."""
    from scalematch.stages.pixelcheck import near_windows

    high = zoom.high.copy()
    h, w = high.shape
    other = np.asarray(raccoon, np.float32)[:h, -w // 3:]  # another part of the photo
    high[:, : w // 3] = other[:, : w // 3] * 1.5  # stronger contrast than the scene
    whole = near_windows(zoom.low, zoom.high, zoom.truth)
    occluded = near_windows(zoom.low, high, zoom.truth)
    # measured (ratio 4 / 8): 1.0 of 44 windows at the truth, 0.15 at most nearby (a scale
    # step keeps the centre's windows in place); occluded 0.6-0.7, nearby 0.1-0.15
    assert whole.windows >= 16 and whole.claimed > 0.9 and whole.nearby < 0.3
    # the occluder's third lost, the scene's windows still agree; nearby placements do not
    assert occluded.windows >= 16
    assert 0.3 < occluded.claimed < whole.claimed and occluded.nearby < occluded.claimed / 2


def test_windows_near_the_inliers_leave_out_the_rest_of_the_footprint(zoom, raccoon):
    """Two thirds of the finer image replaced by other texture (another plane of a 3-D scene,
    which the map does not fit): over the whole footprint few windows agree; compared near
    inliers on the third the map fits (``vouched``), most do, and nearby placements still do
    not."""
    from scalematch.stages.pixelcheck import near_windows

    high = zoom.high.copy()
    h, w = high.shape
    other = np.asarray(raccoon, np.float32)[-h:, :w]
    high[:, w // 3:] = other[:, w // 3:] * 1.5
    # inliers on the third the map fits, a disc's radius (a quarter of the footprint's size)
    # from the rest
    inliers = np.array([[x, y] for x in np.linspace(0.03, 0.1, 2) * w
                        for y in np.linspace(0.05, 0.95, 6) * h])
    whole = near_windows(zoom.low, high, zoom.truth)
    near = near_windows(zoom.low, high, zoom.truth, vouched=inliers)
    # measured (ratio 4 / 8): whole 0.22 / 0.23 of 45 / 44 windows; near the inliers 1.0 of 10,
    # nearby 0.0 / 0.1
    assert whole.claimed < 0.3 and near.windows >= 8
    assert near.claimed > 0.8 and near.nearby < near.claimed / 2
    assert near.windows < whole.windows


def test_windows_of_a_wrong_placement_do_not_agree(zoom):
    from scalematch.stages.pixelcheck import near_windows

    for turn, at in ((90.0, (0.3, 0.3)), (180.0, (0.7, 0.6)), (35.0, (0.25, 0.75))):
        w = near_windows(zoom.low, zoom.high, _elsewhere(zoom, turn, at))
        assert not w.claimed > 0.1, (turn, at, w)


def test_a_match_off_the_plane_beats_it_only_where_the_scene_moved(raccoon):
    """The plane map of a zoom by 2 (finer px -> coarser px, x / 2 - 0.25); in the coarser
    image one block of the scene stands 6 px further right, as a nearer object would.
    ``matches_beat_plane``: a point in that block matched to where it moved fits the pixels
    better than the plane's prediction; a point of the plane matched 6 px off (a look-alike
    along a row), or at its own place, does not."""
    import cv2

    from scalematch.stages.pixelcheck import matches_beat_plane

    finer = raccoon[100:500, 200:700].astype(np.float32)
    coarser = cv2.resize(finer, (250, 200), interpolation=cv2.INTER_AREA)
    moved = coarser.copy()
    moved[60:140, 106:186] = coarser[60:140, 100:180]  # the block 6 px to the right
    h = np.array([[0.5, 0, -0.25], [0, 0.5, -0.25], [0, 0, 1.0]])
    inside = np.array([[2 * x + 0.5, 2 * y + 0.5] for x in (125, 140, 155) for y in (80, 100, 120)])
    outside = np.array([[2 * x + 0.5, 2 * y + 0.5] for x in (40, 60, 200) for y in (30, 170)])
    to = lambda pts, dx: np.hstack([pts, apply(h, pts) + (dx, 0.0)])  # noqa: E731
    assert matches_beat_plane(moved, finer, h, to(inside, 6.0)).all()
    assert not matches_beat_plane(moved, finer, h, to(outside, 6.0)).any()
    assert not matches_beat_plane(moved, finer, h, to(outside, 0.0)).any()  # a tie is no win
