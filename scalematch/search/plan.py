"""The search as data: a plan of steps, what each step found, and the rule that stops the search.

A match is searched for progressively (Mishkin, Matas & Perdoch 2015, "MODS"): first the
finer image itself, in the given order, then in the other (with the automatic order), and only
when neither finds a match, passes of simulated tilted views of both images, each pass only
when the earlier ones found nothing, and each in both orders at once: one pooled vote over
every view pair of the pass (:mod:`scalematch.features`, :mod:`scalematch.stages.vote`). The
views of the finer image reach a finer image seen more obliquely than the coarser one; the
views of the coarser image reach a finer image that is the oblique one (docs/design/VIEWS.md,
"Views of the coarser image").
:func:`search_plan` writes that down as a tuple of :class:`Step`;
:func:`scalematch.pipeline.match` runs it with a short loop, asking :func:`skips` before a
step and :func:`stop_reason` after it. Nothing here touches pixels: the plan and the rule are
pure functions of the configuration and of what the steps found (:class:`Attempt`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Dict, Mapping, Optional, Sequence, Tuple

import numpy as np

from ..result import Direction, ScaleRow, StepRecord
from ..stages.acontrario import Decision
from ..stages.descriptors import Described
from ..config import Config
from ..stages.estimator import Estimate, FitSpec, model_of
from ..stages.refit import ModelCheckParams
from ..stages.views import View, view_plan
from ..working import WorkImages
from .modes import votes_over_views

#: (tilt, longitude in degrees) of a view; (1, 0) is the image itself.
ViewKey = Tuple[float, float]
PLAIN: Tuple[ViewKey, ...] = ((1.0, 0.0),)

#: Why a search stopped (``Evidence.stopped``).
STOP_REASONS = {
    "matched": "a reliable match was found",
    "plan done": "every step of the plan was run",
    "time budget": "the time budget ran out before every step was run",
}


@dataclass(frozen=True)
class Step:
    """One step of the plan: the finer image itself in one direction, or a pass of views of
    both images in every direction searched (``view_pass`` 1 and on)."""

    #: which image is taken as the coarser one; None for a pass of views, which searches
    #: every direction of ``directions``
    direction: Optional[Direction]
    view_pass: int  #: 0: the finer image itself; k >= 1: the k-th pass of views, pooled
    views: Tuple[ViewKey, ...]  #: the views (of each image, for the step of views)
    #: the finer image's scales searched (a pass of views: those of its ``directions``)
    scales: Tuple[float, ...]
    full_searches: int  #: at most this many views (view pairs) are matched in full
    #: whose views the step searches: "finer", the finer image itself (the plain steps);
    #: "both", the views of both images (the step of views)
    side: str = "finer"
    #: the directions the step of views searches, each with its scales
    directions: Tuple[Tuple[Direction, Tuple[float, ...]], ...] = ()

    @property
    def cost(self) -> int:
        """Progress units: each scale of the finer image detected, and each scale of each view
        of each image (the step of views), and each full search at each scale."""
        if self.view_pass == 0:
            return 2 * len(self.scales)
        return sum(len(self.views) * (len(scales) + 1) for _, scales in self.directions) + \
            self.full_searches * max((len(sc) for _, sc in self.directions), default=0)


def within_reach(scales: Sequence[float], finer_side: Optional[float],
                 min_footprint_px: float) -> Tuple[float, ...]:
    """The scales at which the finer image (longer side ``finer_side`` px) still spans at least
    ``min_footprint_px`` coarser px (all of them when ``finer_side`` is None).

    >>> within_reach((1.0, 8.0, 16.0, 32.0), 640, 32.0)
    (1.0, 8.0, 16.0)
    """
    if finer_side is None:
        return tuple(scales)
    return tuple(s for s in scales if finer_side / s >= min_footprint_px * (1 - 1e-9))


def search_plan(config, scales: Mapping[Direction, Tuple[float, ...]],
                finer_sides: Optional[Mapping[Direction, float]] = None) -> Tuple[Step, ...]:
    """The steps of the search, in the order they run.

    ``scales[d]``: the scales of direction ``d`` (at working size a direction may have none,
    :func:`scalematch.working.direction_scales`); ``finer_sides[d]``: the longer side of that
    direction's finer image, px, which bounds its scales (:func:`within_reach`, with
    ``config.min_footprint_px``). The plain steps (the finer image itself) run the given
    direction first, then the other with ``config.order == "auto"``; the step of views
    (``config.views``) follows, for models with a ratio in the default mode (a fundamental
    matrix has no view to refit; the paper's jets carry no orientation to vote with).

    >>> from scalematch.config import Config
    >>> plan = search_plan(Config(), {Direction.GIVEN: (1.0, 2.0), Direction.SWAPPED: (1.0,)})
    >>> [(s.direction and str(s.direction)[0], s.view_pass, s.side, len(s.views)) for s in plan]
    ... # doctest: +NORMALIZE_WHITESPACE
    [('g', 0, 'finer', 1), ('s', 0, 'finer', 1), (None, 1, 'both', 5), (None, 2, 'both', 10),
     (None, 3, 'both', 35)]
    >>> [(str(d)[0], sc) for d, sc in plan[-1].directions]
    [('g', (1.0, 2.0)), ('s', (1.0,))]
    """
    order = (Direction.GIVEN, Direction.SWAPPED) if config.order == "auto" else (Direction.GIVEN,)
    known = finer_sides or {}
    scales = {d: within_reach(scales.get(d, ()), known.get(d), config.min_footprint_px)
              for d in order}
    directions = [d for d in order if scales[d]]
    plan = [Step(d, 0, PLAIN, tuple(scales[d]), 1) for d in directions]
    if directions and searched_as_a_map(config) and votes_over_views(config):
        both = tuple((d, tuple(scales[d])) for d in directions)
        plan += [Step(None, k, tuple(keys), (), config.views.full_searches, "both", both)
                 for k, keys in enumerate(view_plan(config.views), 1) if keys]
    return tuple(plan)


def coarser_viewed(directions: Sequence[Direction], finer_sides: Mapping[Direction, float],
                   how: str) -> Tuple[Direction, ...]:
    """The directions whose coarser image is viewed (``ViewParams.coarser_directions``): all of
    ``directions`` for "both"; for "one", the direction whose coarser image (the other
    direction's finer one, longer side ``finer_sides``) is the smaller, the first on a tie or
    when the sides are unknown.

    >>> coarser_viewed([Direction.GIVEN, Direction.SWAPPED],
    ...                {Direction.GIVEN: 400, Direction.SWAPPED: 1024}, "one")
    (<Direction.SWAPPED: 'swapped'>,)
    """
    if how == "both" or len(directions) < 2:
        return tuple(directions)
    return (min(directions, key=lambda d: finer_sides.get(d.other, 0)),)


@dataclass(frozen=True)
class ScaleOutcome:
    """What one scale of one search produced (summarised for users as a :class:`ScaleRow`)."""

    row: ScaleRow
    estimate: Optional[Estimate]
    src: np.ndarray = field(repr=False)  #: (K, 2) finer px of the candidates given to the estimator
    dst: np.ndarray = field(repr=False)  #: (K, 2) coarser px
    candidates: int  #: initial candidate matches
    #: every described point of the finer image at this scale (for the second look), or None
    described: Optional[Described] = field(default=None, repr=False)


@dataclass(frozen=True)
class Attempt:
    """One search matched in full: a view of the finer image, in one direction, and its verdict."""

    step: Step = field(repr=False)
    direction: Direction  #: which image was taken as the coarser one
    view: View = field(repr=False)
    #: what chose this view pair for the full match: the probe's best score (the finer image
    #: itself; inf when the probe is off), or the votes of its best cell (a pass of views)
    chosen_by: float
    outcomes: Tuple[ScaleOutcome, ...] = field(repr=False)
    verdict: Decision = field(repr=False)
    #: the view of the coarser image matched against (None: the coarser image itself); the
    #: outcomes' and the verdict's coarser px are then this view's
    coarser_view: Optional[View] = field(default=None, repr=False)

    @property
    def matched(self) -> bool:
        return self.verdict.matched

    @property
    def shown_view(self) -> View:
        """The tilted view that found it: of the coarser image when there is one."""
        return self.coarser_view if self.coarser_view is not None else self.view

    def winning_outcome(self) -> ScaleOutcome:
        """The outcome of the scale the decision chose."""
        return next(o for o in self.outcomes if o.row.s == self.verdict.best_scale)


def strongest(attempts: Sequence[Attempt]) -> Optional[Attempt]:
    """The matched attempt with the strongest evidence (lowest log10 NFA; the first of ties)."""
    found = [a for a in attempts if a.matched]
    return min(found, key=lambda a: a.verdict.log10_nfa) if found else None


def skips(step: Step, attempts: Sequence[Attempt], config) -> bool:
    """A step is skipped when its pass already found a match (in the other direction) that
    ends the pass: a map's (:func:`searched_as_a_map`)."""
    return searched_as_a_map(config) and any(
        a.matched and a.step.view_pass == step.view_pass for a in attempts)


def searched_as_a_map(config) -> bool:
    """Whether ``config.model`` is searched as a map (a point maps to a point): through the
    views after the plain steps, each view's map refit in the images themselves, and a match
    found in one order ends its pass, the other order skipped. A fundamental matrix is searched
    by the plain steps alone (a view's matrix has no refit in the images that keeps it one), and
    it fits the wrong order too: with the coarser image taken
    for the finer, its scales cannot reach the true ratio, yet at s = 1 an epipolar geometry
    absorbs the zoom and fits a few of the candidates (on the Adelaide scenes with one image
    shrunk by 2, 20 to 26 inliers at log10 NFA -4 to -16, 3 to 19 px off, where the right order
    finds 84 to 244 at -120 to -457; ``scripts/adelaide_pairs.py``). So its pass runs both
    orders and the strongest answers (:func:`strongest`)."""
    return model_of(config.model).has_ratio


def overwhelming(attempt: Attempt, config) -> bool:
    """A match so far beyond chance that no other view of its step can do better."""
    return attempt.matched and \
        attempt.verdict.log10_nfa <= config.decision.max_log_nfa_alone


def stop_reason(step: Step, attempts: Sequence[Attempt], plan: Sequence[Step],
                config) -> Optional[str]:
    """Why the search stops after ``step`` (a key of ``STOP_REASONS``), or None to go on.

    The search stops once its pass is over (or skipped from here on: it found a match) with a
    match found, unless that match must be confirmed: a plain match (pass 0) on fewer than
    ``views.confirm_below_inliers`` distinct inliers can be a repeated structure seen through
    a viewpoint change, so the first pass of views gets to show a stronger answer.
    """
    best = strongest(attempts)
    rest = plan[plan.index(step) + 1:]
    if best is None:
        return None if rest else "plan done"
    pass_over = not any(s.view_pass == step.view_pass for s in rest) or skips(
        step, attempts, config)
    if not pass_over:
        return None
    weak = best.verdict.counted < config.views.confirm_below_inliers
    confirm = weak and step.view_pass == 0 and any(s.view_pass > 0 for s in rest)
    if confirm:
        return None
    return "matched"


def out_of_time(elapsed_s: float, steps_run: int, config) -> bool:
    """True when no further step may start: ``config.time_budget_s`` is spent and at least
    one step has run (the first step, the given order's plain search, always runs).

    >>> from scalematch.config import Config
    >>> two = Config(time_budget_s=2.0)
    >>> out_of_time(2.5, 1, two), out_of_time(2.5, 0, two), out_of_time(1.5, 1, two)
    (True, False, False)
    >>> out_of_time(99.0, 3, Config())  # no budget
    False
    """
    budget = config.time_budget_s
    return budget is not None and steps_run > 0 and elapsed_s >= budget


def probe_best(probes: Sequence[float]) -> float:
    """The best of some probe scores (NaN when there are none)."""
    return max(probes) if len(probes) else math.nan


def searched(records: Sequence[StepRecord]) -> str:
    """What the steps run searched, for a "no" (``24 searches: both orders, tilted views``).

    >>> from dataclasses import replace
    >>> g = StepRecord(Direction.GIVEN, 0, 1, 1, 3.0, False)
    >>> searched([g, replace(g, direction=Direction.SWAPPED)])
    'both orders'
    >>> searched([g, replace(g, view_pass=1, views=100, side="both")])
    'the order given, tilted views of both images'
    """
    orders = {r.direction for r in records if r.view_pass == 0}
    what = ["both orders" if len(orders) > 1 else
            "the order given" if Direction.GIVEN in orders else "the other order"]
    if any(r.view_pass > 0 for r in records):
        what.append("tilted views of both images")
    return ", ".join(what)


@dataclass(frozen=True)
class SearchRun:
    """What running a search plan gave (``run.run_plan``): every attempt, the steps' records,
    the plan, why it stopped, and seconds per step by name (and "total")."""

    attempts: Tuple[Attempt, ...]
    records: Tuple[StepRecord, ...]
    plan: Tuple[Step, ...]
    stopped: str
    timings: Dict[str, float]


#: The models that name a ceiling rather than the search (``Config.model``): the search finds a
#: similarity at every scale, and the answer may climb to a richer map of the same match no
#: further than the model asked for (:func:`climbs`). A homography searched for at every scale
#: needs 4 inliers of one scale and its scales to agree where a similarity needs 2: on the
#: gate's zoom pairs at ratios 10 and 16 the homography search lost 8 runs of 176 that the
#: similarity's solved with 6 to 8 inliers (docs/design/DECISION.md, "The model asked for
#: is a ceiling")
CEILINGS = ("affine", "homography")


def searched_model(config: Config) -> str:
    """The model the search fits at every scale: the similarity for a ceiling of
    :data:`CEILINGS` while the model check is on (it climbs to that ceiling), the model asked
    for otherwise (``--set model_check.enabled=false`` searches an affine map or a homography
    at every scale, as the paper's method does)."""
    if config.model in CEILINGS and config.model_check.enabled:
        return "similarity"
    return config.model


def climbs(config: Config) -> Tuple[str, ...]:
    """The richer models the answer may climb to from the similarity found
    (``ModelCheckParams.models``): those of the model check up to the model asked for when it
    is a ceiling (:data:`CEILINGS`); all of them for the default, the similarity."""
    models = config.model_check.models
    if config.model not in CEILINGS:
        return models
    top = model_of(config.model).min_sample
    return tuple(m for m in models if model_of(m).min_sample <= top)


def climbing(config: Config) -> ModelCheckParams:
    """The model check of ``config`` with its richer models cut at the ceiling
    (:func:`climbs`): what the answer's climb and guided growth may take."""
    return replace(config.model_check, models=climbs(config))


def fit_spec(config: Config) -> FitSpec:
    """How the search fits its transforms: the model searched (:func:`searched_model`), RANSAC
    and the seed."""
    return FitSpec(searched_model(config), config.ransac, config.seed)


def finer_sides(work: WorkImages) -> Dict[Direction, int]:
    """Each direction's finer image's longer side at working size, px (its reach)."""
    return {d: max(d.coarser_finer(work.low, work.high)[1].shape) for d in Direction}
