"""The a-contrario count (acontrario.py): binomials, the NFA and the chance a candidate fits."""

from __future__ import annotations

import math

from scalematch.stages.acontrario import chance_probability, log10_binom, log10_nfa


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
