"""scalematch.geometry: the neighbour search the guided growth uses (the rest of the module is
tested through its users and its doctests)."""

from __future__ import annotations

import numpy as np
import pytest

from scalematch.geometry import pairs_within


def _table(a: np.ndarray, b: np.ndarray, radius: float):
    """The full N x M table: what pairs_within must give, in the same order."""
    d2 = ((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=2)
    return np.nonzero(d2 <= radius * radius)


@pytest.mark.parametrize("radius", [0.0, 1.0, 4.0, 25.0])
def test_pairs_within_gives_the_full_tables_pairs_in_its_order(radius):
    rng = np.random.default_rng(0)
    for spread in (5.0, 60.0, 600.0):
        b = rng.uniform(0, spread, (300, 2))
        a = rng.uniform(-30, spread + 30, (250, 2))  # some outside b's extent
        a[:40] = b[:40]  # at distance 0
        a[40:80] = b[40:80] + [radius, 0.0]  # at exactly the radius
        a[80:120] = b[80:120] + [0.0, -radius]
        a[120] = np.nan  # no pair
        got = pairs_within(a, b, radius)
        want = _table(a, b, radius)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
        assert len(got[0]) >= 40  # the coincident points at least


def test_pairs_within_empty_and_far():
    assert [len(x) for x in pairs_within(np.zeros((0, 2)), np.zeros((3, 2)), 4.0)] == [0, 0]
    assert [len(x) for x in pairs_within(np.zeros((3, 2)), np.zeros((0, 2)), 4.0)] == [0, 0]
    i, k = pairs_within([[1e12, -1e12]], [[0.0, 0.0]], 4.0)  # far off the grid: no overflow
    assert len(i) == 0
