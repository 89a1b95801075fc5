"""The fundamental matrix refined (stages/epipolar.py): Levenberg-Marquardt on the Sampson
error of its inliers."""

from __future__ import annotations

import doctest

import numpy as np

from scalematch.geometry import epipolar_distances
from scalematch.lab.synthetic import make_two_plane_pair
from scalematch.stages import epipolar
from scalematch.stages.epipolar import refine_fundamental, sampson_residuals


def test_a_matrix_off_the_truth_is_brought_onto_the_points_of_a_two_plane_scene(raccoon):
    """300 points of a two-plane scene, located to 0.5 px in both images, and a matrix 3 px off
    them: refined, it is of rank 2, its Sampson error is the points' noise, and noiseless
    points lie within 0.3 px of its lines."""
    pair = make_two_plane_pair(raccoon[100:580, 200:840])
    rng = np.random.default_rng(0)
    finer = rng.uniform((20, 20), (620, 460), (300, 2))
    coarser = pair.low_point(finer)
    noisy_f, noisy_c = finer + rng.normal(0, 0.5, finer.shape), coarser + rng.normal(0, 0.5, finer.shape)
    start = pair.fundamental + 3e-3 * rng.normal(size=(3, 3)) * np.abs(pair.fundamental).max()
    assert np.median(epipolar_distances(start, finer, coarser)) > 1.0
    refined = refine_fundamental(start, noisy_f, noisy_c)
    assert np.linalg.matrix_rank(refined, tol=1e-9) == 2
    rms = float(np.sqrt(np.mean(sampson_residuals(refined, noisy_f, noisy_c) ** 2)))
    assert rms < 0.6  # the noise of two 0.5 px locations, seen along one direction
    assert np.median(epipolar_distances(refined, finer, coarser)) < 0.3


def test_docstring_examples():
    result = doctest.testmod(epipolar)
    assert result.failed == 0 and result.attempted >= 4
