"""The match / no-match decision (decision.py): the a-contrario test and its parts."""

from __future__ import annotations

import math

import numpy as np

from scalematch.geometry import similarity_matrix
from scalematch.stages.decision import chance_probability, log10_binom, log10_nfa, mean_transfer_gap


def test_log10_binom_known_values():
    assert log10_binom(10, 3) == __import__("pytest").approx(math.log10(120))
    assert log10_binom(5, 0) == 0.0 and log10_binom(3, 5) == -math.inf


def test_nfa_falls_with_inliers_and_rises_with_candidates():
    p = chance_probability(3.0, (768, 1024), "similarity", True, 20.0)
    # 8 inliers among 20 candidates: far beyond chance; 3 among 300: not
    assert log10_nfa(20, 8, 2, p, tests=40) < -20
    assert log10_nfa(300, 3, 2, p, tests=3000) > 0
    assert log10_nfa(50, 9, 2, p, 100) < log10_nfa(50, 8, 2, p, 100) < log10_nfa(500, 8, 2, p, 100)
    assert log10_nfa(10, 2, 2, p, 1) == math.inf  # the minimal sample proves nothing


def test_chance_probability():
    p = chance_probability(3.0, (100, 100), "similarity", False, 20.0)
    assert p == __import__("pytest").approx(math.pi * 9 / 1e4)
    assert chance_probability(3.0, (100, 100), "similarity", True, 20.0) == \
        __import__("pytest").approx(p * 40 / 360)


def test_mean_transfer_gap_of_a_shift_is_the_shift():
    t = similarity_matrix(0.25, 10.0, 100.0, 50.0)
    u = t.copy()
    u[0, 2] += 1.0
    assert mean_transfer_gap(t, u, (480, 640)) == __import__("pytest").approx(1.0)
    assert mean_transfer_gap(t, t, (480, 640)) == 0.0


def test_a_mirror_transform_is_folded_and_a_turn_is_not():
    from scalematch.stages.decision import folded as _folded

    assert _folded(np.array([[-0.5, 0.0, 10.0], [0.0, 0.5, 3.0]]))  # x mirrored
    assert not _folded(np.array([[0.0, -0.5, 10.0], [0.5, 0.0, 3.0]]))  # turned by 90 deg
    assert _folded(np.array([[0.5, 0.0, 1.0], [0.0, -0.5, 2.0], [0.0, 0.0, 1.0]]))
