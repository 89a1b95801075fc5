"""Pairs with what real photographs bring, end to end (``lab.realistic``): a no-data canvas,
an occluder, a repeated structure, two canvases that must not match, a "no" that shows its
best candidate. Known answers cut from the shipped photo."""

from __future__ import annotations

import numpy as np
import pytest

from scalematch import match
from scalematch.geometry import apply, compose, invert
from scalematch.lab import realistic
from scalematch.lab.evaluation import reprojection_error
from scalematch.lab.synthetic import make_unrelated_pair, make_zoom_pair

#: success as EVALUATION.md counts it: grid error under 3 px in the low image
SUCCESS_PX = 3.0


def _zoom(photo, ratio, seed, size=(320, 240)):
    return make_zoom_pair(photo, ratio, np.random.default_rng(seed), high_size=size)


def _error(result, pair) -> float:
    assert result.matched, result.reason
    assert result.order == "given"
    return reprojection_error(result.transform, pair.truth, pair.high.shape, pair.low.shape)


@pytest.mark.parametrize("ratio,seed", [(3.0, 0), (6.0, 1)])
def test_a_high_image_on_a_black_cornered_canvas_is_matched(raccoon, ratio, seed):
    """A rectified image on a canvas with no-data corners: the canvas edge is no part of the
    scene, and the pixels are compared only where both images show it."""
    pair = realistic.padded(_zoom(raccoon, ratio, seed), np.random.default_rng(seed))
    assert (pair.high == 0).mean() > 0.1  # the corners are there
    assert _error(match(pair.low, pair.high), pair) < SUCCESS_PX


def test_an_occluder_over_a_third_of_the_high_image_is_not_ambiguity(raccoon):
    """A patch of another picture over 35 % of the high image: the points prove the map, and
    the pixels are compared where the inliers are."""
    pair = _zoom(raccoon, 3.0, 2)
    other = np.ascontiguousarray(np.rot90(raccoon)[::-1])  # not this scene's pixels anywhere
    h, w = pair.high.shape
    high = pair.high.copy()
    high[: int(0.6 * h), : int(0.6 * w)] = other[: int(0.6 * h), : int(0.6 * w)]
    result = match(pair.low, high)
    assert _error(result, pair) < SUCCESS_PX
    assert result.evidence.judged_by in ("geometry", "pixels")


def test_two_padded_canvases_of_unrelated_scenes_do_not_match(raccoon):
    """Each image on its own black-cornered canvas, different scenes: the canvases' corners
    and edges must not match each other."""
    rng = np.random.default_rng(3)
    other = realistic_other(raccoon)
    null = make_unrelated_pair(raccoon, other, 3.0, rng, high_size=(320, 240))
    null = realistic.padded_null(null, rng)
    for low, high in ((null.low, null.high), (null.high, null.low)):
        result = match(low, high)
        assert not result.matched, "two canvases matched each other"


def realistic_other(photo: np.ndarray) -> np.ndarray:
    """A picture of no scene of ``photo``: smooth random blobs and stripes, as textured."""
    from scalematch.lab.synthetic import smooth_scene

    return smooth_scene(photo.shape, seed=5) * 0.5 + np.random.default_rng(5).uniform(
        0, 128, photo.shape).astype(np.float32)


def test_a_no_shows_its_best_candidate_with_the_test_that_refused_it(raccoon):
    """A true pair refused on purpose (a log10 NFA limit beyond reach): the ``rejected`` block
    holds the right transform, its inliers, and the test's figures."""
    from dataclasses import replace

    from scalematch.config import Config

    pair = _zoom(raccoon, 3.0, 5)
    config = Config()
    config = replace(config, decision=replace(config.decision, max_log_nfa=-1e6))
    result = match(pair.low, pair.high, config)
    assert not result.matched
    rej = result.rejected
    assert rej is not None and rej.test == "chance"
    assert rej.figures["max_log_nfa"] == -1e6 and rej.figures["log10_nfa"] == rej.log10_nfa
    assert reprojection_error(rej.transform, pair.truth, pair.high.shape,
                              pair.low.shape) < SUCCESS_PX
    assert rej.n_inliers >= 10
    d = result.to_dict("low.png", "high.png", pair.low.shape, pair.high.shape)
    assert d["rejected"]["test"] == "chance" and d["rejected"]["n_inliers"] == rej.n_inliers


@pytest.mark.parametrize("change", ["padded", "partial", "relit"])
def test_each_change_keeps_an_exact_truth(raccoon, change):
    """The changed pair's truth maps each high pixel where the scene is in the low image: the
    padded canvas by R^-1 composed, the partial low image by its cut, relighting by nothing."""
    pair = _zoom(raccoon, 2.0, 0)
    moved = getattr(realistic, change)(pair, np.random.default_rng(1))
    if change == "padded":
        # the canvas pixel at integer c shows the high image at R^-1 c (bilinear), and the
        # new truth maps c where the old truth maps R^-1 c
        import cv2

        r = compose(invert(moved.truth), pair.truth)  # high px -> canvas px
        c = np.array([[150.0, 120.0]])
        p = apply(invert(r), c)
        assert np.allclose(apply(moved.truth, c), apply(pair.truth, p), atol=1e-6)
        sample = cv2.remap(pair.high, p[:, :1].astype(np.float32), p[:, 1:].astype(np.float32),
                           cv2.INTER_LINEAR)[0, 0]
        assert moved.high[120, 150] == pytest.approx(float(sample), abs=0.5)
    elif change == "partial":
        g = np.array([[x, y] for x in np.linspace(0, 319, 9) for y in np.linspace(0, 239, 9)])
        q = apply(moved.truth, g)
        h, w = moved.low.shape
        share = np.mean((q[:, 0] >= 0) & (q[:, 0] <= w - 1) & (q[:, 1] >= 0) & (q[:, 1] <= h - 1))
        assert 0.2 <= share <= 0.8
        # the pixel the truth names is the same scene pixel as before the cut
        k = np.argmax((q[:, 0] > 5) & (q[:, 0] < w - 5) & (q[:, 1] > 5) & (q[:, 1] < h - 5))
        before = apply(pair.truth, g[k:k + 1])[0]
        after = q[k]
        assert pair.low[int(round(before[1])), int(round(before[0]))] == \
            moved.low[int(round(after[1])), int(round(after[0]))]
    else:
        assert np.array_equal(moved.truth, pair.truth) and moved.low.shape == pair.low.shape
        assert np.abs(moved.low - pair.low).mean() > 5  # relit


def _epipolar_distance(f: np.ndarray, finer: np.ndarray, coarser: np.ndarray) -> float:
    """Mean symmetric epipolar distance (px) of point pairs under F (x_coarser^T F x_finer = 0),
    as ../shared/data/ef/SOURCES.md scores a fundamental matrix."""
    hf = np.column_stack([finer, np.ones(len(finer))])
    hc = np.column_stack([coarser, np.ones(len(coarser))])
    to_coarser, to_finer = hf @ f.T, hc @ f
    num = np.abs(np.sum(hc * to_coarser, axis=1))
    return float(np.mean(0.5 * (num / np.hypot(*to_coarser[:, :2].T)
                                + num / np.hypot(*to_finer[:, :2].T))))


@pytest.mark.shared
def test_a_3d_desk_scene_is_answered_with_its_dominant_plane_and_says_parallax(shared_dir):
    """../shared/data/ef/zoom: a desk scene at a zoom of about 2.6, 13 clicked points and no
    plane through them all. By default: the map of its dominant plane, holding at least 4 of
    the clicked points within 3 px, with the parallax said; ``--model fundamental``: the
    epipolar geometry, under 3 px from the clicked points (measured: 4 points, 0.8 px), with
    85 inliers off the dominant plane at log10 NFA -161."""
    from scalematch.config import Config
    from scalematch.imageio import read_grey

    folder = shared_dir / "data" / "ef"
    a, b = read_grey(folder / "zoom_A.png"), read_grey(folder / "zoom_B.png")
    clicked = np.loadtxt(folder / "zoom_points.txt")
    plane = match(a, b)
    assert plane.matched, plane.reason
    assert plane.evidence.parallax and plane.evidence.parallax_points >= 50
    finer, coarser = (clicked[:, 2:], clicked[:, :2]) if plane.order == "given" else \
        (clicked[:, :2], clicked[:, 2:])
    near = np.linalg.norm(apply(plane.transform, finer) - coarser, axis=1) < SUCCESS_PX
    assert near.sum() >= 4
    epipolar = match(a, b, Config(model="fundamental"))
    assert epipolar.matched, epipolar.reason
    # its parallax is beyond chance by itself, so no plane map is searched to vouch for it
    assert epipolar.evidence.parallax and epipolar.evidence.parallax_log10_nfa < -50
    assert "plane" not in epipolar.timings
    finer, coarser = (clicked[:, 2:], clicked[:, :2]) if epipolar.order == "given" else \
        (clicked[:, :2], clicked[:, 2:])
    assert _epipolar_distance(np.asarray(epipolar.transform), finer, coarser) < SUCCESS_PX
