"""The placements near a map (nearby.py): the pixels find the true one from a map a few
percent and a few pixels off, and leave a true map where it is."""

from __future__ import annotations

import numpy as np
import pytest

from scalematch.geometry import apply, as_matrix3, footprint
from scalematch.lab.synthetic import make_zoom_pair
from scalematch.stages.nearby import _about, best_nearby


@pytest.fixture(scope="module", params=[4.0, 8.0])
def zoom(request, raccoon):
    """Zoom pairs of data/raccoon.jpg at ratios 4 and 8 (grey-level change and noise)."""
    return make_zoom_pair(raccoon, request.param, np.random.default_rng(3))


def _corner_gap(a: np.ndarray, b: np.ndarray, shape) -> float:
    """Mean distance of two maps' footprint corners, coarser px."""
    return float(np.linalg.norm(footprint(a, shape) - footprint(b, shape), axis=1).mean())


def test_the_true_map_is_its_own_best_placement(zoom):
    truth = as_matrix3(zoom.truth)
    near = best_nearby(zoom.low, zoom.high, truth)
    # raccoon at ratio 4 / 8: ZNCC 0.99 at the truth; the best placement within a grid step
    assert near.claimed > 0.95 and near.best == pytest.approx(near.claimed, abs=0.02)
    assert near.moved < 0.05 and _corner_gap(near.transform, truth, zoom.high.shape) < 2.0


def test_a_map_off_the_truth_is_placed_back_on_it(zoom):
    """A map 9 % too small, turned by 5 degrees and shifted by a sixth of its footprint:
    what a few inliers on a repeated texture can give. The best placement nearby is the true
    one, within the grid's step (its edge within 1.5 of the 64 px the search works at: 2.3 %
    of the footprint), and fits far better than the map (measured: corners 0.72 and 0.37 px
    off of 111 and 55 px footprints; ZNCC 0.97 and 0.99 against 0.05 and 0.04)."""
    truth = as_matrix3(zoom.truth)
    h, w = zoom.high.shape
    centre = apply(truth, [[(w - 1) / 2, (h - 1) / 2]])[0]
    size = np.sqrt(w * h) / np.sqrt(abs(np.linalg.det(np.linalg.inv(truth)[:2, :2])))
    shift = np.array([[1.0, 0.0, size / 6.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    off = shift @ _about(centre, 0.91, 5.0) @ truth
    near = best_nearby(zoom.low, zoom.high, off)
    assert near.moved > 0.15 and near.best > near.claimed + 0.2
    assert _corner_gap(near.transform, truth, zoom.high.shape) < 0.023 * size


def test_no_scene_no_figures(zoom):
    blank = np.full(zoom.low.shape, np.nan, np.float32)
    near = best_nearby(blank, zoom.high, as_matrix3(zoom.truth))
    assert np.isnan(near.best) and np.isnan(near.claimed) and near.transform is None
