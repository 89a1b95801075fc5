"""The chosen scales matched in full and decided (the paper's steps 4 to 7).

A view pair chosen by the probe or the vote (:class:`Candidate`) has its chosen scales matched
in full (:func:`finish_view`: candidates, the mode's constraints and the robust fit at each
scale, :func:`_full_scale`), and its outcomes are decided
(:func:`match_chosen`: :func:`scalematch.stages.decision.decide`, with the second look's
:class:`~scalematch.stages.secondlook.Sight`).
"""

from __future__ import annotations

from typing import Callable, Iterator, List, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from ..config import Config
from ..geometry import usable_ratio
from ..result import Direction, ScaleRow
from ..stages.decision import SearchContext, decide
from ..stages.descriptors import Described
from ..stages.detector import Keypoints
from ..stages.estimator import Estimate, estimate, model_of
from ..stages.matcher import distinct_pairs, match_descriptors
from ..stages.scalespace import Level, scale_space
from ..stages.secondlook import Sight
from ..stages.threads import thread_map
from ..stages.views import View, valid_in
from ..working import shown_scale
from .detect import space_of
from .plan import Attempt, ScaleOutcome, Step, fit_spec, overwhelming
from .shared import Detected, LowFeatures, Probed, Search


def _full_scale(level: Level, kp: Keypoints, high: Described, coarser: "LowFeatures",
                search: "Search") -> ScaleOutcome:
    """Candidate matching, constraints and robust estimation at one scale."""
    config, low, low_image = search.config, coarser.described, coarser.image
    model = fit_spec(config).model
    s = level.s
    cand = match_descriptors(high.desc, low.desc, config.matcher)
    best: Optional[Estimate] = None
    best_src = best_dst = np.zeros((0, 2))
    kept = 0
    if len(cand):
        for mask in search.mode.constrain(high, low, cand, level, low_image):
            src, dst = distinct_pairs(high.xy[cand.i[mask]], low.xy[cand.j[mask]])
            est = estimate(model, src, dst, config.ransac, seed=config.seed)
            if best is None or est.n_inliers > best.n_inliers:
                best, best_src, best_dst, kept = est, src, dst, len(src)
    n_in = best.n_inliers if best is not None and best.transform is not None else 0
    ratio = angle = float("nan")
    if n_in:
        # where the inliers are: a homography's ratio varies across the image (perspective)
        ratio, angle, _ = model_of(model).parts(best.transform, best_src[best.inliers])
        ratio = usable_ratio(ratio)
    initial = len(distinct_pairs(high.xy[cand.i], low.xy[cand.j])[0])
    row = ScaleRow(s=s, ratio=ratio, points=len(kp), initial=initial, kept=kept,
                   inliers=n_in, outlier_pct=100.0 * (1 - n_in / initial) if initial else 100.0,
                   rotation_deg=angle)
    return ScaleOutcome(row, best, best_src, best_dst, initial, high)


def _joined(head: Described, rest: Described, offset: int) -> Described:
    """The descriptors of keypoints [0, offset) and [offset, N) as one ``Described``."""
    return Described(s=head.s, xy=np.vstack([head.xy, rest.xy]),
                     index=np.concatenate([head.index, rest.index + offset]),
                     angle=np.concatenate([head.angle, rest.angle]),
                     desc=np.vstack([head.desc, rest.desc]))


def _levels(view: View, detected: Sequence[Detected], wanted: Sequence[int],
            scales: Sequence[float], config: Config) -> Tuple[Iterator[Tuple[int, Level]], bool]:
    """(the levels ``wanted`` of a view as (index, level), in order; True when they were kept
    by the detection) -- else the detection's cascade again, up to the largest one wanted, a
    level at a time (bounded memory)."""
    if all(detected[i].level is not None for i in wanted):
        return ((i, detected[i].level) for i in wanted), True
    scales = sorted(scales)
    return ((i, level) for i, level in enumerate(scale_space(
        view.image, scales[:wanted[-1] + 1], **space_of(config))) if i in wanted), False


def finish_view(probed: Probed, low: LowFeatures, search: Search, scales: Sequence[float],
                tick: Callable[[], None] = lambda: None) -> List[ScaleOutcome]:
    """Match the probe's chosen scales of a view in full (steps 4-6); one outcome per scale.

    The probe's descriptors are kept: only the other points are described. ``scales``: the
    view's (the step's, in the view's pixels). ``tick()`` is called once per scale matched or
    skipped.
    """
    config = search.config
    scales = sorted(scales)
    detected, run = probed.detected, probed.run
    levels, kept = _levels(probed.view, detected, run, scales, config)

    def one(item) -> ScaleOutcome:
        i, level = item
        kp, desc, _, full = detected[i]
        if full is not None:
            desc = full
        elif probed.probing and len(kp) > config.probe.points:  # the probe described the strongest
            rest = search.mode.describe(level, kp.part(slice(config.probe.points, None)))
            desc = _joined(desc, rest, config.probe.points)
        return _full_scale(level, kp, desc, low, search)

    if kept:  # every level in memory: the scales are matched side by side on threads
        full = dict(zip(run, thread_map(one, list(levels))))
    else:  # levels made one after the other by the cascade (bounded memory): in turn
        full = {i: one((i, level)) for i, level in levels}
    outcomes: List[ScaleOutcome] = []
    for n, s_ in enumerate(scales):
        if n in full:
            outcomes.append(full[n])
        else:
            # skipped: the probe judged it hopeless (not: too small, or no points at all)
            row = ScaleRow(s=s_, ratio=float("nan"), points=len(detected[n].keypoints), initial=0,
                           kept=0, inliers=0, outlier_pct=100.0, skipped=n in probed.usable)
            outcomes.append(ScaleOutcome(row, None, np.zeros((0, 2)), np.zeros((0, 2)), 0))
        tick()
    return outcomes


class Candidate(NamedTuple):
    """A view pair to match in full: a view of the finer image probed (its chosen scales in
    ``probed.run``), the coarser features it is matched against and the view of the coarser
    image they come from (None: the image itself)."""

    probed: "Probed"
    coarser: LowFeatures
    coarser_view: Optional[View]
    direction: Direction
    scales: Tuple[float, ...]  #: the finer view's scales, in its own pixels (sorted)
    chosen_by: float  #: what chose it: the probe's best score, or the pair's votes


def match_chosen(search: Search, step: Step, candidates: Sequence[Candidate],
                 searches: int) -> List[Attempt]:
    """Match in full each of ``candidates`` (a view of the finer image probed, with the chosen
    scales: ``Probed.run``), and decide each; ``searches``: the view pairs searched so far,
    these included (the a-contrario test counts them all)."""
    work, cfg, mode = search.work, search.config, search.mode
    attempts: List[Attempt] = []
    for p, low_feats, coarser_view, direction, scales, chosen_by in candidates:
        outcomes = tuple(finish_view(p, low_feats, search, scales, search.meter.tick))

        coarser_shown = (valid_in(coarser_view) if coarser_view is not None
                         else work.valid(direction)[0])
        sight = Sight(p.view.image, valid_in(p.view), low_feats.described, low_feats.image,
                      coarser_shown, fit_spec(cfg), mode.guided, cfg.pixel)
        context = SearchContext(fit_spec(cfg), mode.orientation, searches,
                                shown_scale(work, direction) * p.view.scale)
        verdict = decide(outcomes, low_feats.image.shape, p.view.image.shape, cfg.decision,
                         context=context, sight=sight)
        attempts.append(Attempt(step, direction, p.view, chosen_by, outcomes, verdict,
                                coarser_view))
        if overwhelming(attempts[-1], cfg):
            break  # no other view of this step can do better
    return attempts
