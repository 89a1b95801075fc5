"""pinning: the error a map's inliers leave it free to make, on synthetic points with known
answers (no shared data)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scalematch.geometry import apply, grid
from scalematch.stages.pinning import (PinParams, expected_error, jacobian, point_covariances,
                                       residual_sigma)

SHAPE = (480, 640)  #: the finer image, (H, W)
#: a ratio-16 map of a 640x480 finer image into a coarser one (its footprint: 40x30 px)
SIMILARITY = np.array([[0.0625, 0.0, 300.0], [0.0, 0.0625, 200.0]])
HOMOGRAPHY = np.vstack([SIMILARITY, [0.0, 0.0, 1.0]])
#: a perspective map: its local ratio grows across the finer image
PERSPECTIVE = np.array([[0.30, 0.02, 400.0], [-0.01, 0.28, 300.0], [6e-4, 1e-5, 1.0]])
NOISE_PX = 0.5  #: std of the noise added to the coarser points, px per coordinate


def _pairs(t: np.ndarray, lo, hi, n: int, noise: float = NOISE_PX, seed: int = 0) -> np.ndarray:
    """(n, 4) pairs of ``t`` from finer points uniform in the box ``lo``..``hi``, the coarser
    points with Gaussian noise of std ``noise``."""
    rng = np.random.default_rng(seed)
    src = rng.uniform(lo, hi, (n, 2))
    return np.hstack([src, apply(t, src) + rng.normal(0.0, noise, (n, 2))])


def test_a_similarity_of_exact_pairs_has_the_closed_form_error_of_its_floor():
    """A similarity fitted to N exact pairs: each point's variance per coordinate is
    sigma^2 (1/N + d^2/S), d its distance from the pairs' centroid, S the sum of the pairs'
    squared distances from it; sigma is the floor, the fit leaving no residual."""
    xy = grid(SHAPE, 5)
    pairs = np.hstack([xy, apply(SIMILARITY, xy)])
    params = PinParams(min_sigma_px=0.3)
    c = xy.mean(axis=0)
    s = float(np.sum((xy - c) ** 2))
    g = grid(SHAPE)
    d2 = np.sum((g - c) ** 2, axis=1)
    want = float(np.mean(np.sqrt(2.0 * 0.3 ** 2 * (1.0 / len(xy) + d2 / s))))
    assert expected_error("similarity", SIMILARITY, pairs, SHAPE, params) == pytest.approx(want,
                                                                                       rel=1e-9)


def test_an_exact_fit_without_a_floor_is_pinned_exactly():
    for model, t in (("similarity", SIMILARITY), ("affine", SIMILARITY),
                     ("homography", PERSPECTIVE)):
        pairs = _pairs(t, (0, 0), (639, 479), 30, noise=0.0)
        err = expected_error(model, t, pairs, SHAPE, PinParams(min_sigma_px=0.0))
        assert err < 1e-6, model


def test_a_homography_is_pinned_by_points_over_the_whole_image_not_by_points_in_a_corner():
    """The same 40 pairs with the same noise, spread over the finer image or crowded in a
    quarter of it (a 160x120 corner): the crowded ones leave the homography free to err
    several times more, beyond the tolerance; a similarity fitted to them stays within it."""
    spread = _pairs(HOMOGRAPHY, (0, 0), (639, 479), 40)
    crowded = _pairs(HOMOGRAPHY, (0, 0), (159, 119), 40)
    params = PinParams()
    over_all = expected_error("homography", HOMOGRAPHY, spread, SHAPE, params)
    in_corner = expected_error("homography", HOMOGRAPHY, crowded, SHAPE, params)
    assert over_all < 0.5 * params.tolerance_px
    assert in_corner > 3.0 * over_all and in_corner > 2.0 * params.tolerance_px
    assert expected_error("similarity", SIMILARITY, crowded, SHAPE, params) < params.tolerance_px


def test_the_error_follows_the_noise():
    """The residual std scales the error: noise four times larger, the error four times
    larger (the floor well below both)."""
    params = PinParams(min_sigma_px=0.01)
    small = _pairs(HOMOGRAPHY, (0, 0), (639, 479), 60, noise=0.25, seed=3)
    large = _pairs(HOMOGRAPHY, (0, 0), (639, 479), 60, noise=1.0, seed=3)
    a = expected_error("homography", HOMOGRAPHY, small, SHAPE, params)
    b = expected_error("homography", HOMOGRAPHY, large, SHAPE, params)
    assert b / a == pytest.approx(4.0, rel=0.02)


def test_the_error_does_not_depend_on_where_the_images_lie():
    """Both images shifted by thousands of px (the map composed with the shifts): the same
    error, within 1e-6 (the computation is in normalised coordinates)."""
    pairs = _pairs(PERSPECTIVE, (0, 0), (319, 239), 25)
    params = PinParams()
    here = expected_error("homography", PERSPECTIVE, pairs, SHAPE, params)
    shift_f = np.array([[1.0, 0.0, -5000.0], [0.0, 1.0, 3000.0], [0.0, 0.0, 1.0]])
    shift_c = np.array([[1.0, 0.0, 7000.0], [0.0, 1.0, -2000.0], [0.0, 0.0, 1.0]])
    t = shift_c @ PERSPECTIVE @ np.linalg.inv(shift_f)
    moved = np.hstack([apply(shift_f, pairs[:, :2]), apply(shift_c, pairs[:, 2:])])
    g = apply(shift_f, grid(SHAPE))
    sigma = residual_sigma("homography", t, moved, params.min_sigma_px)
    cov = point_covariances("homography", t, moved, g, sigma)
    there = float(np.mean(np.sqrt(np.trace(cov, axis1=1, axis2=2))))
    assert there == pytest.approx(here, rel=1e-6)


def test_only_the_grid_points_inside_the_coarser_image_count_when_its_shape_is_given():
    """A footprint half outside the coarser image: the points outside, far from the inliers,
    do not count, so the error is smaller."""
    t = np.array([[1.0, 0.0, -320.0], [0.0, 1.0, 0.0]])  # the left half falls outside
    pairs = _pairs(t, (320, 0), (639, 479), 30)
    params = PinParams()
    whole = expected_error("affine", t, pairs, SHAPE, params)
    inside = expected_error("affine", t, pairs, SHAPE, params, coarser_shape=(480, 640))
    assert inside < 0.8 * whole


@pytest.mark.parametrize("model,n", [("similarity", 1), ("affine", 2), ("homography", 3)])
def test_fewer_pairs_than_parameters_leave_the_map_free(model, n):
    t = HOMOGRAPHY if model == "homography" else SIMILARITY
    pairs = _pairs(t, (0, 0), (639, 479), n)
    assert expected_error(model, t, pairs, SHAPE) == math.inf


@pytest.mark.parametrize("model", ["affine", "homography"])
def test_collinear_or_coincident_points_leave_the_map_free(model):
    t = HOMOGRAPHY if model == "homography" else SIMILARITY
    x = np.linspace(0, 639, 12)
    line = np.column_stack([x, 0.5 * x + 10])
    collinear = np.hstack([line, apply(t, line)])
    same = np.tile(collinear[:1], (12, 1))
    assert expected_error(model, t, collinear, SHAPE) == math.inf
    assert expected_error(model, t, same, SHAPE) == math.inf


def test_as_many_pairs_as_parameters_rest_on_the_floor():
    """Two pairs fix a similarity exactly: no residual is left to measure, the floor is the
    residual std."""
    pairs = np.array([[0.0, 0.0, 300.0, 200.0], [639.0, 479.0, 340.0, 230.0]])
    assert residual_sigma("similarity", SIMILARITY, pairs, 0.3) == 0.3
    assert math.isfinite(expected_error("similarity", SIMILARITY, pairs, SHAPE))


def test_the_residual_std_counts_the_degrees_of_freedom():
    """Residuals of (1, 0) px on 6 pairs under an affine map: 6 squared px over 12 - 6 degrees
    of freedom."""
    src = grid(SHAPE, 3)[:6]
    pairs = np.hstack([src, apply(SIMILARITY, src) + [1.0, 0.0]])
    assert residual_sigma("affine", SIMILARITY, pairs, 0.0) == pytest.approx(1.0)


def test_the_jacobian_of_a_homography_matches_finite_differences():
    xy = np.array([[10.0, 20.0], [600.0, 400.0]])
    h = PERSPECTIVE / PERSPECTIVE[2, 2]
    j = jacobian("homography", h, xy)
    eps = 1e-7
    for k, (r, c) in enumerate([(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2), (2, 0), (2, 1)]):
        step = eps * max(1.0, abs(h[r, c]))
        d = h.copy()
        d[r, c] += step
        numeric = ((apply(d, xy) - apply(h, xy)) / step).ravel()
        assert numeric == pytest.approx(j[:, k], rel=1e-4, abs=1e-6)


def test_a_model_without_points_is_refused():
    with pytest.raises(ValueError, match="fundamental"):
        jacobian("fundamental", np.eye(3), np.zeros((1, 2)))


def test_the_parameters_are_checked():
    with pytest.raises(ValueError, match="tolerance_px"):
        PinParams(tolerance_px=0.0)
    with pytest.raises(ValueError, match="min_sigma_px"):
        PinParams(min_sigma_px=-1.0)
