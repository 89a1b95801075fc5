"""search: the plan as data, the skip and stop rules, on fabricated attempts (no pixels)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from scalematch.config import MODELS, Config
from scalematch.result import Direction
from scalematch.search.plan import (Attempt, Step, fit_spec, search_plan, skips, stop_reason,
                               strongest)
from scalematch.stages.acontrario import Decision
from scalematch.stages.views import ViewParams, identity_view

GIVEN, SWAPPED = Direction.GIVEN, Direction.SWAPPED
BOTH = {GIVEN: (1.0, 2.0, 4.0), SWAPPED: (1.0, 2.0)}


def attempt(step: Step, matched: bool, inliers: int = 50, lnfa: float = -30.0) -> Attempt:
    verdict = Decision(matched, "" if matched else "too few inliers", 2.0, None,
                       np.zeros((0, 4)), dict(inliers=inliers, log10_nfa=lnfa))
    return Attempt(step, step.direction or GIVEN, identity_view(np.zeros((30, 30), np.float32)),
                   10.0, (), verdict)


def test_the_plan_runs_the_images_themselves_given_first_then_passes_of_pooled_views():
    plan = search_plan(Config(), BOTH)
    assert [(s.direction, s.view_pass, s.side, len(s.views)) for s in plan] == [
        (GIVEN, 0, "finer", 1), (SWAPPED, 0, "finer", 1), (None, 1, "both", 5),
        (None, 2, "both", 10), (None, 3, "both", 35)]
    assert plan[1].scales == (1.0, 2.0) and plan[0].scales == (1.0, 2.0, 4.0)
    # a pass of views searches both directions, each at its own scales
    assert plan[2].directions == ((GIVEN, (1.0, 2.0, 4.0)), (SWAPPED, (1.0, 2.0)))
    # progress units: each scale detected and matched; each view at each scale (and its first
    # level) of each direction, and 3 full searches at the most scales
    assert plan[0].cost == 6
    assert plan[2].cost == 5 * (3 + 1) + 5 * (2 + 1) + 3 * 3


def test_the_plan_follows_the_order_the_views_the_model_and_the_mode():
    given = search_plan(Config(order="given"), BOTH)
    assert [(s.direction, s.view_pass) for s in given] == [(GIVEN, 0)] + [(None, k) for k in range(1, 4)]
    assert given[1].directions == ((GIVEN, (1.0, 2.0, 4.0)),)
    no_views = Config(views=ViewParams(enabled=False))
    assert [s.view_pass for s in search_plan(no_views, BOTH)] == [0, 0]
    # a fundamental matrix has no ratio, so no view to refit: the images themselves only
    assert len(search_plan(Config(model="fundamental"), BOTH)) == 2
    # the paper's jets carry no orientation to vote with: no views, even when asked for
    assert len(search_plan(Config.paper(views=ViewParams()), BOTH)) == 2
    # a direction with no scale at working size is not searched
    assert [s.direction for s in search_plan(no_views, {GIVEN: (), SWAPPED: (1.0,)})] == [SWAPPED]
    # the passes asked for are the steps of views
    assert [len(s.views) for s in search_plan(Config.preset("tilt-4"), BOTH)[2:]] == [5, 10]


def test_one_direction_views_the_smaller_coarser_image():
    """``coarser_directions="one"``: both directions' views of the coarser image reach the same
    pairs (docs/design/VIEWS.md, "Views of the coarser image"), so only the smaller coarser
    image, cheaper, is viewed."""
    from scalematch.search.plan import coarser_viewed

    both = [GIVEN, SWAPPED]
    # the given direction's finer image is the small one (400 px): the swapped direction's
    # coarser image is then that small image, viewed in the swapped direction
    assert coarser_viewed(both, {GIVEN: 400, SWAPPED: 1024}, "one") == (SWAPPED,)
    assert coarser_viewed(both, {GIVEN: 1024, SWAPPED: 400}, "one") == (GIVEN,)
    assert coarser_viewed(both, {GIVEN: 800, SWAPPED: 800}, "one") == (GIVEN,)  # a tie
    assert coarser_viewed(both, {GIVEN: 400, SWAPPED: 1024}, "both") == (GIVEN, SWAPPED)
    assert coarser_viewed([GIVEN], {GIVEN: 400, SWAPPED: 1024}, "one") == (GIVEN,)
    with pytest.raises(ValueError, match="coarser_directions"):
        ViewParams(coarser_directions="either")


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
    """Fewer than confirm_below_inliers: the other direction of the plain search is skipped,
    the first pass of views runs, and the stronger answer wins."""
    config = Config()
    plan = search_plan(config, BOTH)
    weak = attempt(plan[0], True, inliers=config.views.confirm_below_inliers - 1, lnfa=-12.6)
    assert stop_reason(plan[0], [weak], plan, config) is None
    assert skips(plan[1], [weak], config) and not skips(plan[2], [weak], config)
    # the views find nothing: the weak match stands
    assert stop_reason(plan[2], [weak, attempt(plan[2], False)], plan, config) == "matched"
    # a view with stronger evidence wins
    strong = attempt(plan[2], True, inliers=60, lnfa=-80.0)
    assert stop_reason(plan[2], [weak, strong], plan, config) == "matched"
    assert strongest([weak, strong]) is strong


def test_a_fundamental_matrix_searches_both_orders_and_the_strongest_answers():
    """A map with a ratio found in the given order ends its pass; a fundamental matrix also
    fits the wrong order (weakly, at s = 1), so the other order still runs."""
    config = Config(model="fundamental")
    plan = search_plan(config, BOTH)
    assert [(s.direction, s.view_pass) for s in plan] == [(GIVEN, 0), (SWAPPED, 0)]
    weak = attempt(plan[0], True, inliers=23, lnfa=-5.9)
    assert not skips(plan[1], [weak], config)
    assert stop_reason(plan[0], [weak], plan, config) is None
    strong = attempt(plan[1], True, inliers=243, lnfa=-456.0)
    assert stop_reason(plan[1], [weak, strong], plan, config) == "matched"
    assert strongest([weak, strong]) is strong
    # the same match under a model with a ratio skips the other order
    default = search_plan(Config(), BOTH)
    assert skips(default[1], [attempt(default[0], True, inliers=23)], Config())


def test_strongest_is_none_without_a_match_and_prefers_the_lowest_nfa():
    plan = search_plan(Config(), BOTH)
    assert strongest([attempt(plan[0], False)]) is None
    a, b = attempt(plan[0], True, lnfa=-5.0), attempt(plan[1], True, lnfa=-50.0)
    assert strongest([a, b]) is b and math.isfinite(b.verdict.log10_nfa)


@pytest.mark.parametrize("config", [Config(), Config(order="given"), Config.paper()])
def test_every_plan_has_the_given_image_itself_first(config):
    plan = search_plan(config, BOTH)
    assert plan[0].direction is GIVEN and plan[0].view_pass == 0 and plan[0].views == ((1.0, 0.0),)


def test_an_affine_map_or_a_homography_asked_for_is_the_ceiling_of_a_similarity_searched():
    """``--model affine`` and ``homography`` search the similarity and let the answer climb no
    further than the model named; the default climbs as far as the model check goes; with the
    check off, the model asked for is searched at every scale."""
    from scalematch.search.plan import climbs, searched_model

    assert [searched_model(Config(model=m)) for m in MODELS] == \
        ["similarity", "similarity", "similarity", "fundamental"]
    assert climbs(Config(model="affine")) == ("affine",)
    assert climbs(Config(model="homography")) == climbs(Config()) == ("affine", "homography")
    off = replace(Config().model_check, enabled=False)
    assert searched_model(Config(model="homography", model_check=off)) == "homography"
    assert fit_spec(Config(model="affine")).model == "similarity"
