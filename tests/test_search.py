"""search: the plan as data, the skip and stop rules, on fabricated attempts (no pixels)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from scalematch.config import Config
from scalematch.result import Direction, Evidence
from scalematch.search import (Attempt, Step, search_plan, skips, stop_reason, strongest)
from scalematch.stages.decision import Decision
from scalematch.stages.views import ViewParams, identity_view

GIVEN, SWAPPED = Direction.GIVEN, Direction.SWAPPED
BOTH = {GIVEN: (1.0, 2.0, 4.0), SWAPPED: (1.0, 2.0)}


def attempt(step: Step, matched: bool, inliers: int = 50, lnfa: float = -30.0) -> Attempt:
    verdict = Decision(matched, "" if matched else "too few inliers", 2.0, None,
                       np.zeros((0, 4)), Evidence(inliers=inliers, log10_nfa=lnfa))
    return Attempt(step, identity_view(np.zeros((30, 30), np.float32)), 10.0, (), verdict)


def test_the_plan_runs_each_pass_in_both_directions_given_first():
    plan = search_plan(Config(), BOTH)
    assert [(s.direction, s.view_pass, s.side, len(s.views)) for s in plan] == [
        (GIVEN, 0, "finer", 1), (SWAPPED, 0, "finer", 1),
        (GIVEN, 1, "finer", 5), (SWAPPED, 1, "finer", 5),
        (GIVEN, 1, "coarser", 5), (SWAPPED, 1, "coarser", 5),
        (GIVEN, 2, "finer", 10), (SWAPPED, 2, "finer", 10),
        (GIVEN, 2, "coarser", 10), (SWAPPED, 2, "coarser", 10),
        (GIVEN, 3, "finer", 35), (SWAPPED, 3, "finer", 35),
        (GIVEN, 3, "coarser", 35), (SWAPPED, 3, "coarser", 35)]
    assert plan[1].scales == (1.0, 2.0) and plan[0].scales == (1.0, 2.0, 4.0)
    # progress units: 1 view detected + 1 matched at 3 scales; 5 views + 3 full searches at 3
    assert plan[0].cost == 6 and plan[2].cost == (5 + 3) * 3
    # a view of the coarser image is detected once (s = 1), then 3 full searches at 3 scales
    assert plan[4].cost == 5 + 3 * 3
    # the same views for both images in a pass
    assert plan[4].views == plan[2].views and plan[8].views == plan[6].views


def test_the_coarser_image_is_viewed_only_when_asked():
    no_coarser = Config(views=ViewParams(coarser=False))
    assert {s.side for s in search_plan(no_coarser, BOTH)} == {"finer"}
    assert len(search_plan(no_coarser, BOTH)) == 8


def test_one_direction_views_the_smaller_coarser_image():
    """``coarser_directions="one"``: both directions' views of the coarser image reach the same
    pairs (docs/design/VIEWS.md, "Views of the coarser image"), so only the smaller coarser
    image, cheaper, is viewed."""
    def viewed(views, finer_sides, order="auto"):
        config = Config(order=order, views=views)
        return [(s.direction, s.view_pass) for s in search_plan(config, BOTH, finer_sides)
                if s.side == "coarser"]
    one = ViewParams(coarser_directions="one")
    # the given direction's finer image is the small one (400 px): the swapped direction's
    # coarser image is then that small image, viewed in the swapped direction
    small_high = {GIVEN: 400, SWAPPED: 1024}
    passes = (1, 2, 3)
    assert viewed(one, small_high) == [(SWAPPED, k) for k in passes]
    assert viewed(one, {GIVEN: 1024, SWAPPED: 400}) == [(GIVEN, k) for k in passes]
    assert viewed(one, {GIVEN: 800, SWAPPED: 800}) == [(GIVEN, k) for k in passes]  # a tie
    # the default views both; with one direction searched, its coarser image is viewed
    assert viewed(ViewParams(), small_high) == [(d, k) for k in passes for d in (GIVEN, SWAPPED)]
    assert viewed(one, small_high, order="given") == [(GIVEN, k) for k in passes]
    with pytest.raises(ValueError, match="coarser_directions"):
        ViewParams(coarser_directions="either")


def test_the_plan_follows_the_order_the_views_and_the_model():
    assert [s.direction for s in search_plan(Config(order="given"), BOTH)] == [GIVEN] * 7
    no_views = Config(views=ViewParams(enabled=False))
    assert [s.view_pass for s in search_plan(no_views, BOTH)] == [0, 0]
    # a fundamental matrix has no ratio, so no view to refit: the images themselves only
    assert len(search_plan(Config(model="fundamental"), BOTH)) == 2
    # a direction with no scale at working size is not searched
    assert [s.direction for s in search_plan(no_views, {GIVEN: (), SWAPPED: (1.0,)})] == [SWAPPED]


def test_a_strong_plain_match_stops_the_search_at_once():
    plan = search_plan(Config(), BOTH)
    found = [attempt(plan[0], True, inliers=40)]
    assert stop_reason(plan[0], found, plan, Config()) == "matched"


def test_nothing_found_goes_on_to_the_end_of_the_plan():
    config = Config()
    plan = search_plan(config, BOTH)
    attempts = []
    for step in plan[:-1]:
        attempts.append(attempt(step, False))
        assert stop_reason(step, attempts, plan, config) is None
    assert stop_reason(plan[-1], attempts + [attempt(plan[-1], False)], plan, config) == \
        "plan done"


def test_a_weak_plain_match_is_confirmed_by_the_first_pass_of_views():
    """Fewer than confirm_below_inliers: the other direction of pass 0 is skipped, the first
    pass of views runs, and the stronger answer wins."""
    config = Config()
    plan = search_plan(config, BOTH)
    weak = attempt(plan[0], True, inliers=config.views.confirm_below_inliers - 1, lnfa=-12.6)
    assert stop_reason(plan[0], [weak], plan, config) is None
    assert skips(plan[1], [weak]) and not skips(plan[2], [weak])
    # the views find nothing in the given direction: the swapped views still run
    none = attempt(plan[2], False)
    assert stop_reason(plan[2], [weak, none], plan, config) is None
    # ... and the views of the coarser image, both directions; when the pass is over the weak
    # match stands
    seen = [weak, none] + [attempt(s, False) for s in plan[3:5]]
    assert [stop_reason(s, seen[:k + 3], plan, config) for k, s in enumerate(plan[3:5])] == \
        [None, None]
    assert plan[5].side == "coarser" and plan[5].view_pass == 1
    assert stop_reason(plan[5], seen + [attempt(plan[5], False)], plan, config) == "matched"
    # a view with stronger evidence wins
    strong = attempt(plan[2], True, inliers=60, lnfa=-80.0)
    assert stop_reason(plan[2], [weak, strong], plan, config) == "matched"
    assert strongest([weak, strong]) is strong


def test_strongest_is_none_without_a_match_and_prefers_the_lowest_nfa():
    plan = search_plan(Config(), BOTH)
    assert strongest([attempt(plan[0], False)]) is None
    a, b = attempt(plan[0], True, lnfa=-5.0), attempt(plan[1], True, lnfa=-50.0)
    assert strongest([a, b]) is b and math.isfinite(b.verdict.evidence.log10_nfa)


@pytest.mark.parametrize("config", [Config(), Config(order="given"), Config.paper()])
def test_every_plan_has_the_given_image_itself_first(config):
    plan = search_plan(config, BOTH)
    assert plan[0].direction is GIVEN and plan[0].view_pass == 0 and plan[0].views == ((1.0, 0.0),)
