"""Reprojection error and success, with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scalematch.geometry import grid, similarity_matrix
from scalematch.lab.evaluation import SUCCESS_PX, is_success, reprojection_error, similarity_floor

HIGH = (480, 640)
LOW = (768, 1024)


def test_identical_is_zero():
    t = similarity_matrix(0.5, 30.0, 400.0, 100.0)
    assert reprojection_error(t, t, HIGH, LOW) == pytest.approx(0.0, abs=1e-12)


def test_one_pixel_shift_is_one():
    t = similarity_matrix(0.25, -70.0, 500.0, 300.0)
    e = t.copy()
    e[0, 2] += 1.0
    assert reprojection_error(e, t, HIGH, LOW) == pytest.approx(1.0, abs=1e-12)
    e = t.copy()
    e[:, 2] += [0.6, 0.8]
    assert reprojection_error(e, t, HIGH, LOW) == pytest.approx(1.0, abs=1e-12)


def test_none_is_inf_and_failure():
    t = similarity_matrix(0.5, 0.0, 10.0, 10.0)
    err = reprojection_error(None, t, HIGH, LOW)
    assert math.isinf(err)
    assert not is_success(err)


def test_homography_equals_equivalent_affine():
    t = similarity_matrix(0.3, 45.0, 300.0, 200.0)
    h = np.vstack([t, [0, 0, 1]]) * 2.5  # same map, other scale of the homogeneous matrix
    e = t.copy()
    e[1, 2] += 2.0
    assert reprojection_error(h, t, HIGH, LOW) == pytest.approx(0.0, abs=1e-9)
    assert reprojection_error(e, h, HIGH, LOW) == pytest.approx(2.0, abs=1e-9)


def test_only_points_inside_low_count():
    # the truth maps the left half of high outside low; the estimate is wrong only there
    t = np.array([[1.0, 0, -320.0], [0, 1.0, 0]])
    e = t.copy()
    e[0, 2] += 0.5
    err = reprojection_error(e, t, HIGH, LOW)
    assert err == pytest.approx(0.5)
    assert math.isinf(reprojection_error(e, np.array([[1.0, 0, 5000], [0, 1, 0]]), HIGH, LOW))


def test_grid_spans_image_and_threshold():
    g = grid(HIGH)
    assert g.shape == (441, 2)
    assert g.min(axis=0).tolist() == [0, 0] and g.max(axis=0).tolist() == [639, 479]
    assert SUCCESS_PX == 3.0
    assert is_success(2.99) and not is_success(3.0)


def test_bad_shape_raises():
    with pytest.raises(ValueError, match="2x3"):
        reprojection_error(np.eye(2), np.eye(3), HIGH, LOW)


def test_similarity_floor():
    t = similarity_matrix(0.3, 45.0, 300.0, 200.0)
    assert similarity_floor(t, HIGH, LOW) == pytest.approx(0.0, abs=1e-6)
    h = np.vstack([t, [1e-4, 0, 1]])  # a little perspective
    floor = similarity_floor(h, HIGH, LOW)
    assert 0.1 < floor < reprojection_error(t, h, HIGH, LOW)
