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


def test_windows_chance_is_the_binomial_tail_at_the_rate_elsewhere():
    """windows_chance: log10 P[Bin(n, q) >= j], q = (c + 1) / (n + 2) (Laplace's rule of
    succession), checked against the sum written out by hand."""
    from math import comb, log10

    from scalematch.stages.acontrario import windows_chance

    n, j, c = 11, 8, 2
    q = (c + 1) / (n + 2)
    by_hand = log10(sum(comb(n, i) * q ** i * (1 - q) ** (n - i) for i in range(j, n + 1)))
    assert abs(windows_chance(n, j / n, c / n) - by_hand) < 1e-9
    # more windows agreeing at the same shares is stronger evidence; none compared is none
    assert windows_chance(44, 32 / 44, 8 / 44) < windows_chance(11, 8 / 11, 2 / 11)
    assert windows_chance(0, float("nan"), float("nan")) == float("inf")
    # as many agreeing elsewhere as at the claim: no evidence (the tail is over a half)
    assert windows_chance(20, 0.5, 0.5) > -0.31
