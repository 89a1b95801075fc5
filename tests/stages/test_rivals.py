"""What the candidates show beside the winner (rivals.py): a repeated structure's second
transform, a 3-D scene's parallax."""

from __future__ import annotations

import cv2
import numpy as np

from scalematch.geometry import apply, similarity_matrix
from scalematch.stages.estimator import RansacParams
from scalematch.stages.rivals import (EpipolarFit, off_plane, same_scale_and_angle,
                                     second_transform)


#: the decision's parallax fit: 1.5 px from the epipolar line (DecisionParams' default)
FIT = EpipolarFit(1.5)

def _copies(shift, n=80, seed=0):
    """Candidates of a facade matched half on its place, half on a copy ``shift`` px away."""
    rng = np.random.default_rng(seed)
    src = rng.uniform(0, 640, (n, 2))
    t = similarity_matrix(0.25, 20.0, 300.0, 200.0)
    dst = apply(t, src)
    dst[n // 2:] += shift
    return src, dst, t, np.arange(n) < n // 2


def test_a_copy_elsewhere_is_a_second_transform_of_the_same_scale_and_angle():
    src, dst, t, inl = _copies((150.0, 40.0))
    second = second_transform(src, dst, inl, t, (480, 640), RansacParams())
    assert second.inliers == 40
    assert abs(second.gap_px - np.hypot(150, 40)) < 0.5
    assert same_scale_and_angle(t, second.transform, 1.15, 10.0)


def test_unrelated_leftovers_give_no_strong_second_transform():
    rng = np.random.default_rng(1)
    src, dst, t, inl = _copies((0.0, 0.0))
    dst[40:] = rng.uniform(0, 700, (40, 2))  # the rest: chance candidates
    second = second_transform(src, dst, inl, t, (480, 640), RansacParams())
    assert second.inliers <= 4


def _two_views(n_plane, n_off, seed=0):
    """Points on a plane and off it, seen by two cameras a baseline apart (px, (N, 2) each)."""
    rng = np.random.default_rng(seed)
    k = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    plane = np.column_stack([rng.uniform(-2, 2, (n_plane, 2)), np.full(n_plane, 10.0)])
    off = np.column_stack([rng.uniform(-2, 2, (n_off, 2)), rng.uniform(5.0, 20.0, n_off)])
    xyz = np.vstack([plane, off])
    a = np.radians(4.0)
    r = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])

    def project(points):
        p = points @ k.T
        return p[:, :2] / p[:, 2:]

    return project(xyz), project(xyz @ r.T + [0.8, 0.0, 0.0]), np.arange(len(xyz)) < n_plane


def test_matches_off_the_plane_that_an_epipolar_geometry_explains_show_parallax():
    src, dst, on_plane = _two_views(40, 60)
    assert off_plane(src, dst, on_plane, FIT) >= 50
    # a flat scene leaves nothing off its plane: the rest are chance candidates
    rng = np.random.default_rng(2)
    flat_dst = dst.copy()
    flat_dst[40:] = rng.uniform(0, 640, (60, 2))
    assert off_plane(src, flat_dst, on_plane, FIT) <= 10
    assert off_plane(src[:10], dst[:10], on_plane[:10], FIT) == 0  # too few to tell


def test_false_matches_sliding_one_way_on_a_flat_scene_are_not_parallax():
    """Matches that slide along a flat scene's edges share one direction, so a translation's
    epipolar geometry lines them all up; offset by more than a quarter of the candidates'
    extent, they are not counted as parallax. A 3-D scene's points off the plane still are."""
    rng = np.random.default_rng(3)
    src = rng.uniform(0, 640, (120, 2))
    t = similarity_matrix(0.25, 20.0, 10.0, 10.0)  # finer -> a 220 px square of the coarser
    dst = apply(t, src)
    on_plane = np.arange(120) < 80
    dst[80:] += np.column_stack([rng.uniform(130.0, 200.0, 40), np.zeros(40)])  # slid along x
    assert off_plane(src, dst, on_plane, FIT) >= 30  # an epipolar geometry explains them
    assert off_plane(src, dst, on_plane, FIT, plane=t, max_offset=0.25) <= 2
    src3, dst3, on3 = _two_views(40, 60)
    plane3, _ = cv2.findHomography(src3[on3], dst3[on3])
    assert off_plane(src3, dst3, on3, FIT, plane=plane3, max_offset=0.25) >= 50
