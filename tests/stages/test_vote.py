"""The pooled vote: candidates that agree on one similarity gather in one cell far beyond
chance; candidates at random do not; a point matched many times is one vote."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scalematch.stages.vote import (Candidates, Cells, VoteParams, best_pairs, group_cells,
                                    index_scale, log10_nfa, scale_index, vote)

#: finer views' longer sides and coarser views' shapes of the fabricated votes
FINER_SIDES = np.array([640.0, 400.0])
COARSER_SHAPES = np.array([[768.0, 1024.0], [768.0, 1024.0], [500.0, 700.0]])


def candidates(rng: np.random.Generator, n_true: int, n_random: int, s: float = 4.0,
               angle_deg: float = 30.0, shift=(300.0, 200.0)) -> Candidates:
    """``n_true`` candidates of finer view 1 and coarser view 2 at scale ``s`` that agree on
    the similarity q = R p / s + shift (each point once, a little noise), and ``n_random``
    candidates of any view pair, scale, rotation and position."""
    a = math.radians(angle_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    p = rng.uniform(0, 400, (n_true, 2))
    q = p @ rot.T / s + shift + rng.normal(0, 0.5, (n_true, 2))
    theta = np.full(n_true, a) + rng.normal(0, math.radians(5), n_true)
    rp = rng.uniform(0, 600, (n_random, 2))
    rq = rng.uniform(0, 700, (n_random, 2))
    return Candidates(
        finer_view=np.concatenate([np.full(n_true, 1), rng.integers(0, 2, n_random)]),
        coarser_view=np.concatenate([np.full(n_true, 2), rng.integers(0, 3, n_random)]),
        s=np.concatenate([np.full(n_true, s), index_scale(rng.integers(0, 13, n_random))]),
        finer_xy=np.vstack([p, rp]), coarser_xy=np.vstack([q, rq]),
        rotation=np.concatenate([theta, rng.uniform(-math.pi, math.pi, n_random)]),
        finer_point=np.arange(n_true + n_random),
        coarser_point=np.arange(n_true + n_random) + 10_000)


def test_candidates_of_one_similarity_make_the_strongest_cell_far_beyond_chance():
    rng = np.random.default_rng(0)
    cells = vote(candidates(rng, 15, 2000), FINER_SIDES, COARSER_SHAPES)
    nfa = log10_nfa(cells, cells.tried)
    best = int(np.argmin(nfa))
    assert (cells.finer_view[best], cells.coarser_view[best]) == (1, 2)
    assert index_scale(cells.scale_index[best]) == pytest.approx(4.0, rel=0.01)
    # two nearest bins a dimension: a true candidate may fall on either side of a boundary,
    # but most of them meet in the best cell
    assert cells.votes[best] >= 10 and nfa[best] < -10
    ranked = best_pairs([cells], [nfa], 3, VoteParams())
    assert (ranked[0].finer_view, ranked[0].coarser_view) == (1, 2)


def test_candidates_at_random_leave_no_cell_beyond_the_bound():
    for seed in range(5):
        cells = vote(candidates(np.random.default_rng(seed), 0, 2000), FINER_SIDES,
                     COARSER_SHAPES)
        nfa = log10_nfa(cells, cells.tried)
        assert nfa.min(initial=np.inf) > VoteParams().max_log_nfa, seed
        assert best_pairs([cells], [nfa], 3, VoteParams()) == []


def test_a_point_matched_many_times_is_one_vote():
    """Twelve finer points all matched to one coarser point agree on nothing: their cell
    counts one vote (the fewer side's distinct points), under ``min_votes``."""
    rng = np.random.default_rng(1)
    c = candidates(rng, 12, 0)
    one = Candidates(c.finer_view, c.coarser_view, c.s, c.finer_xy,
                     np.tile(c.coarser_xy[:1], (12, 1)), np.full(12, c.rotation[0]),
                     c.finer_point, np.zeros(12, np.int64))
    assert len(vote(one, FINER_SIDES, COARSER_SHAPES)) == 0
    assert len(vote(c, FINER_SIDES, COARSER_SHAPES)) > 0


def test_the_count_multiplies_every_cell_tried():
    """The same cell counts 10 times the false alarms when the vote tried 10 times the
    cells: log10 NFA + 1."""
    cells = Cells(np.array([1]), np.array([2]), np.array([6]), np.array([8]), np.array([100]),
                  np.array([1e-3]), 1000)
    assert log10_nfa(cells, 10_000)[0] - log10_nfa(cells, 1000)[0] == pytest.approx(1.0)


def test_no_candidates_make_no_cells():
    empty = Candidates(*(np.zeros(0),) * 3, np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0),
                       np.zeros(0, np.int64), np.zeros(0, np.int64))
    cells = vote(empty, FINER_SIDES, COARSER_SHAPES)
    assert len(cells) == 0 and cells.tried == 0


def test_the_cells_of_a_group_cover_the_coarser_view_and_a_footprint_around_it():
    # a 640 px finer view at scale 4 spans 160 px: bins of 40 px over 1024 + 160 by 768 + 160
    # (30 x 24), times 12 rotations
    cells, p = group_cells(np.array([640.0]), np.array([[768.0, 1024.0]]), np.array([4.0]),
                           VoteParams())
    assert cells[0] == 12 * 30 * 24 and p[0] == pytest.approx(8 / cells[0])
    assert scale_index(np.array([4.0]))[0] == 6


def test_candidates_joined_keep_every_part_in_order_and_none_is_empty():
    one = Candidates(np.array([1]), np.array([0]), np.array([2.0]), np.zeros((1, 2)),
                     np.ones((1, 2)), np.array([0.5]), np.array([7]), np.array([8]))
    two = Candidates.joined([one, one])
    assert len(two) == 2 and two.finer_point.tolist() == [7, 7]
    assert len(Candidates.joined([])) == 0 and len(vote(Candidates.joined([]), np.ones(1),
                                                        np.ones((1, 2)))) == 0
