"""Geometric constraints (constraints.py): rotation consistency and the semi-local search."""

from __future__ import annotations

import numpy as np

from scalematch.geometry import apply, similarity_matrix
from scalematch.stages.constraints import (OrientationParams, SemiLocalParams, correlation_check,
                                    orientation_groups, semi_local_support)
from scalematch.stages.scalespace import Level
from scalematch.lab.synthetic import zoom_warp


def test_orientation_groups_find_the_true_rotation():
    rng = np.random.default_rng(0)
    true = np.radians(123.0) + rng.normal(0, np.radians(5), 40)  # true matches, ~5 deg error
    noise = rng.uniform(-np.pi, np.pi, 160)  # random ones
    groups = orientation_groups(np.concatenate([true, noise]), OrientationParams())
    assert groups
    first = groups[0]
    assert first[:40].mean() >= 0.95  # the true ones are in the first group
    assert first[40:].mean() < 0.2  # 40 deg of 360 keeps about 11 % of random ones
    assert orientation_groups(np.zeros(0)) == []


def test_semi_local_support_separates_consistent_from_random_candidates():
    rng = np.random.default_rng(1)
    s = 4.0
    t = similarity_matrix(1 / s, 30.0, 200.0, 100.0)
    p = rng.uniform(0, 300, (60, 2))  # high px
    q = apply(t, p) + rng.normal(0, 0.3, (60, 2))
    q[40:] = rng.uniform(150, 300, (20, 2))  # 20 wrong candidates among them
    support, a, b = semi_local_support(p, q, s, SemiLocalParams())
    assert np.median(support[:40]) >= 5
    assert np.median(support[40:]) <= 1
    good = support[:40] >= 2
    # two-point similarities over neighbours a few low px apart with 0.3 px noise: the scale is
    # within 10 % (measured 0.236 to 0.266 for 1/s = 0.25)
    assert np.allclose(np.abs(a[:40][good]), 1 / s, rtol=0.1)


def test_correlation_check_is_high_for_the_true_warp(raccoon):
    high = raccoon[200:520, 300:700]
    low, t = zoom_warp(high, 2.0, 20.0)
    level = Level(1.0, 1.0, 0.0, high)
    p = np.array([[150.0, 120.0], [250.0, 200.0], [100.0, 250.0]])
    q = apply(t, p)
    a = np.full(3, complex(t[0, 0], t[1, 0]))
    b = np.full(3, complex(t[0, 2], t[1, 2]))
    good = correlation_check(level, low, q, a, b)
    bad = correlation_check(level, low, q, a * np.exp(1j * 2.0), b)  # rotated by 115 deg
    assert np.all(good > 0.8) and np.all(bad < good - 0.3)
