"""Candidate selection (matcher.py) on small hand-made descriptor sets with known answers.

The set used by most tests, in 2-D so that every distance can be checked by hand::

    low  (j):  0 = (0, 0)    1 = (10, 0)    2 = (0, 10)
    high (i):  0 = (1, 0)    1 = (4.5, 0)   2 = (0, 9)

    i  nearest j (d1)   second j (d2)                 d1 / d2
    0  0  (1)           1  (9)                        0.111
    1  0  (4.5)         1  (5.5)                      0.818
    2  2  (1)           0  (9)                        0.111

Nearest high point of each low point: j0 -> i0 (1), j1 -> i1 (5.5), j2 -> i2 (1); so the pair
(i1, j0) is not mutual.
"""

from __future__ import annotations

import numpy as np
import pytest

from scalematch.stages.matcher import Candidates, MatcherParams, distinct_rows, match_descriptors

LOW = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]], np.float32)
HIGH = np.array([[1.0, 0.0], [4.5, 0.0], [0.0, 9.0]], np.float32)

#: distances are computed in float32 from |a|^2 + |b|^2 - 2ab: exact to ~1e-5 at these sizes
TOL = 1e-4


def _pairs(c: Candidates):
    return list(zip(c.i.tolist(), c.j.tolist()))


def test_nn_gives_every_high_point_its_nearest():
    c = match_descriptors(HIGH, LOW, MatcherParams(selection="nn"))
    assert _pairs(c) == [(0, 0), (1, 0), (2, 2)]
    np.testing.assert_allclose(c.distance, [1.0, 4.5, 1.0], atol=TOL)
    np.testing.assert_allclose(c.second, [9.0, 5.5, 9.0], atol=TOL)
    assert c.i.dtype.kind == "i" and c.j.dtype.kind == "i"
    assert c.distance.dtype == np.float32 and c.second.dtype == np.float32


@pytest.mark.parametrize("ratio, expected", [
    (0.8, [(0, 0), (2, 2)]),  # 4.5 / 5.5 = 0.818 > 0.8: the ambiguous point 1 is dropped
    (0.85, [(0, 0), (1, 0), (2, 2)]),  # 0.818 <= 0.85: kept
    (0.1, []),  # 1 / 9 = 0.111 > 0.1: nothing survives
])
def test_ratio_keeps_points_clearly_nearer_than_the_second(ratio, expected):
    c = match_descriptors(HIGH, LOW, MatcherParams(selection="ratio", ratio=ratio))
    assert _pairs(c) == expected
    assert np.all(c.distance <= ratio * c.second + TOL)


def test_knn_lists_k_neighbours_in_distance_order():
    c = match_descriptors(HIGH, LOW, MatcherParams(selection="knn", k=2))
    assert _pairs(c) == [(0, 0), (0, 1), (1, 0), (1, 1), (2, 2), (2, 0)]
    np.testing.assert_allclose(c.distance, [1.0, 9.0, 4.5, 5.5, 1.0, 9.0], atol=TOL)
    # the "second" column is each high point's second-nearest distance, on all of its rows
    np.testing.assert_allclose(c.second, [9.0, 9.0, 5.5, 5.5, 9.0, 9.0], atol=TOL)


def test_knn_with_k_larger_than_the_low_set_lists_all_of_it():
    c = match_descriptors(HIGH, LOW, MatcherParams(selection="knn", k=5))
    assert len(c) == 9
    # high 0 = (1, 0): j0 at 1, j1 at 9, j2 at sqrt(101)
    np.testing.assert_allclose(c.distance[:3], [1.0, 9.0, np.sqrt(101.0)], atol=TOL)
    assert c.j[:3].tolist() == [0, 1, 2]


@pytest.mark.parametrize("max_distance, expected", [
    (5.0, [(0, 0), (1, 0), (2, 2)]),
    (6.0, [(0, 0), (1, 0), (1, 1), (2, 2)]),  # 5.5 <= 6
    (0.5, []),
])
def test_threshold_keeps_every_neighbour_under_the_bound(max_distance, expected):
    c = match_descriptors(HIGH, LOW, MatcherParams(selection="threshold", k=3,
                                                   max_distance=max_distance))
    assert _pairs(c) == expected
    assert np.all(c.distance <= max_distance)


def test_max_distance_also_bounds_nn():
    c = match_descriptors(HIGH, LOW, MatcherParams(selection="nn", max_distance=2.0))
    assert _pairs(c) == [(0, 0), (2, 2)]


def test_mutual_drops_a_pair_that_is_not_nearest_both_ways():
    c = match_descriptors(HIGH, LOW, MatcherParams(selection="nn", mutual=True))
    assert _pairs(c) == [(0, 0), (2, 2)]
    # (1, 1) is in the knn list, but j1's nearest high point is i1 (5.5 < 9): mutual, kept
    c = match_descriptors(HIGH, LOW, MatcherParams(selection="knn", k=2, mutual=True))
    assert _pairs(c) == [(0, 0), (1, 1), (2, 2)]


def test_a_single_low_descriptor_has_an_infinite_second_distance():
    c = match_descriptors(HIGH, LOW[:1], MatcherParams(selection="ratio", ratio=0.8))
    assert _pairs(c) == [(0, 0), (1, 0), (2, 0)]
    assert np.all(np.isinf(c.second))


def test_knn_agrees_with_brute_force_on_random_sets():
    rng = np.random.default_rng(0)
    high = rng.normal(size=(60, 16)).astype(np.float32)
    low = rng.normal(size=(45, 16)).astype(np.float32)
    d = np.linalg.norm(high[:, None].astype(np.float64) - low[None], axis=2)
    order = np.argsort(d, axis=1)
    for k in (2, 3, 5):  # k <= 3 and k > 3 take different code paths
        c = match_descriptors(high, low, MatcherParams(selection="knn", k=k))
        assert c.j.reshape(60, k).tolist() == order[:, :k].tolist()
        np.testing.assert_allclose(c.distance.reshape(60, k),
                                   np.take_along_axis(d, order[:, :k], 1), atol=1e-4)


@pytest.mark.parametrize("selection", ["nn", "knn", "threshold", "ratio"])
@pytest.mark.parametrize("n_high, n_low", [(0, 3), (3, 0), (0, 0)])
def test_empty_inputs_give_empty_candidates(selection, n_high, n_low):
    c = match_descriptors(np.zeros((n_high, 2), np.float32), np.zeros((n_low, 2), np.float32),
                          MatcherParams(selection=selection, mutual=True))
    assert len(c) == 0
    for a in (c.i, c.j, c.distance, c.second):
        assert a.shape == (0,)


def test_unknown_selection_is_a_value_error():
    with pytest.raises(ValueError, match="selection must be one of"):
        match_descriptors(HIGH, LOW, MatcherParams(selection="best"))


@pytest.mark.parametrize("threads", [1, 2])
def test_large_matches_in_chunks_and_threads_agree_with_brute_force(threads):
    """A product past _THREADED_MIN is cut into chunks of _CHUNK rows, on as many threads as
    OpenCV uses: the neighbours are the brute-force ones whatever the threads."""
    import cv2

    from scalematch.stages import matcher

    rng = np.random.default_rng(1)
    n_high = matcher._CHUNK * 2 + 37  # three chunks, the last one short
    n_low = matcher._THREADED_MIN // n_high + 1
    high = rng.normal(size=(n_high, 8)).astype(np.float32)
    low = rng.normal(size=(n_low, 8)).astype(np.float32)
    d = np.linalg.norm(high[:, None].astype(np.float64) - low[None], axis=2)
    order = np.argsort(d, axis=1)[:, :2]
    before = cv2.getNumThreads()
    cv2.setNumThreads(threads)
    try:
        c = match_descriptors(high, low, MatcherParams(selection="knn", k=2))
    finally:
        cv2.setNumThreads(before)
    gap = np.take_along_axis(d, np.argsort(d, axis=1)[:, 1:3], 1)
    clear = gap[:, 1] - gap[:, 0] > 1e-4  # rows without a near-tie for the second place
    assert (c.j.reshape(n_high, 2)[:, 0] == order[:, 0]).all()
    assert (c.j.reshape(n_high, 2)[clear, 1] == order[clear, 1]).all()
    np.testing.assert_allclose(c.distance.reshape(n_high, 2), np.take_along_axis(d, order, 1),
                               atol=1e-4)


def test_distinct_rows_keeps_the_first_of_each_repeated_position_pair():
    # rows 0, 2 and 4 are one pair (within 1e-3 px; -0.0 is 0.0), rows 1 and 3 another
    src = np.array([[1.0, 2.0], [5.0, 5.0], [1.0004, 2.0], [5.0, 5.0], [1.0, 2.0], [7.0, 1.0]])
    dst = np.array([[0.0, 3.0], [1.0, 1.0], [-0.0, 3.0], [1.0, 1.0], [0.0, 3.0], [0.0, 3.0]])
    assert distinct_rows(src, dst).tolist() == [0, 1, 5]


def test_distinct_rows_is_what_numpy_unique_over_rows_gives():
    rng = np.random.default_rng(0)
    for _ in range(200):
        n = int(rng.integers(1, 40))
        src = rng.integers(0, 3, (n, 2)) + rng.choice([0.0, 0.0004, 0.3], (n, 2))
        dst = rng.integers(-2, 2, (n, 2)).astype(float)
        _, first = np.unique(np.round(np.hstack([src, dst]), 3), axis=0, return_index=True)
        assert distinct_rows(src, dst).tolist() == sorted(first.tolist())
