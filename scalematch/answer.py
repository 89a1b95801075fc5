"""The answer: everything after the search, from its attempts to one :class:`MatchResult`.

The search (:mod:`scalematch.pipeline`, the plan of :mod:`scalematch.search`) hands over every
attempt it made, each decided (:func:`scalematch.stages.decision.decide`). Here the answer is
made of them, in this order (:func:`build_result`):

1. for an epipolar geometry, the strongest matched attempt refit in the images' own pixels,
   with the parallax its inliers show (:func:`matrix_answer`), and nothing more; for a map,
   the best fit: the matched attempt whose map, refit in the finer image's own pixels
   (:func:`final_fit`: :mod:`scalematch.stages.refit`) as the model the pixels choose
   (:func:`model_by_pixels`), lines the pixels up best
   (:func:`best_fitting`); with none, the "no" of the strongest refused attempt
   (:func:`refused`), or of an empty plan (:func:`unreachable`);
2. the pixel tests of that final map (:func:`judged_by_pixels`:
   :func:`scalematch.stages.finalchecks.final_checks`), which may still refuse it;
3. the map grown by guided matching (:func:`grown_answer`) and claimed as the model its
   inliers pin down (:func:`pinned_answer`: :mod:`scalematch.stages.pinning`);
4. the match itself, turned to map the finer image to the coarser one (:func:`answered`),
   with its evidence assembled once (:func:`evidence_of`).

Every result here is at working size; :func:`scalematch.working.in_original` brings it to the
images' own pixels.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, replace
from typing import Optional, Sequence, Tuple

import numpy as np

from .config import Config
from .geometry import finer_to_coarser
from .result import Direction, Evidence, MatchResult, Rejected, ScaleRow, build_evidence, figure
from .search.plan import Attempt, SearchRun, climbing, fit_spec, probe_best, searched, strongest
from .search.shared import Search
from .stages.acontrario import FinalFigures, figures
from .stages.estimator import model_of, residuals
from .stages.finalchecks import (Claim, final_checks, near_windows_agree, plane_parallax,
                                 searched_unique, windows_agree)
from .stages.matcher import distinct_pairs
from .stages.pixelcheck import NearWindows, matches_beat_plane, near_windows, overlap_ncc, pixel_check
from .stages.refit import (Fit, Pinned, allowed_maps, by_counts, by_pixels, candidates_in_images,
                           chosen_model, guided_refit, pinned_model, pooled_refit, refit_in_high,
                           richer_fits)
from .stages.rivals import EpipolarFit, off_plane
from .stages.uniqueness import window_agreement
from .working import WorkImages, at_working_size_of, shown_scale

__all__ = ["answered_by_a_matrix", "build_result", "plane_instead", "without_parallax"]


def in_images(attempt: Attempt, search: Search) -> Fit:
    """A matched attempt's transform refit in the images' own pixels, on its winning scale's
    inliers."""
    return refit_in_high(attempt.view, attempt.verdict, attempt.winning_outcome(),
                         fit_spec(search.config), attempt.coarser_view)


def final_fit(attempt: Attempt, search: Search) -> Tuple[Fit, Fit]:
    """(as searched, final): a matched attempt's map refit in the images' own pixels
    (:func:`in_images`) and refined on every scale matched in full, in the model searched; and
    the same as the model the pixels choose (:func:`model_by_pixels`)."""
    fit = pooled_refit(in_images(attempt, search), attempt.view, attempt.outcomes,
                       fit_spec(search.config).ransac, attempt.coarser_view)
    return fit, model_by_pixels(fit, attempt, search)


def model_by_pixels(fit: Fit, attempt: Attempt, search: Search) -> Fit:
    """``fit``, or a richer model of the same match (:func:`stages.refit.richer_fits`) chosen
    by the pixels (:func:`stages.refit.chosen_model`): for a similarity searched for (the
    default, or ``--model affine`` or ``homography``, the ceiling of the climb:
    :func:`plan.climbs`), with the model check on.

    A richer map may answer where it lines the pixels up clearly better than ``fit``
    (:func:`stages.refit.by_pixels`) and the pixels vouch for it window by window over the
    whole overlap (its freedom was fitted to the pixels that chose it: the windows must agree
    where they were not compared), or where it explains clearly more candidates and the pixels
    do not refuse it (:func:`stages.refit.by_counts`: a scene with depth, where no map lines
    all the pixels up, answers the plane most matches lie on). Among those, the pixels choose:
    a wrong affine map of a plane in perspective can fit more candidates than its homography.
    """
    config = search.config
    check, spec = climbing(config), fit_spec(config)
    if not check.enabled or spec.model != "similarity":
        return fit
    richer = richer_fits(fit, attempt.view, attempt.winning_outcome(), attempt.outcomes, check,
                         spec, attempt.coarser_view)
    if not richer:
        return fit
    coarse, fine = search.work.shown(attempt.direction)
    options = [fit] + [r.fit for r in richer]
    nccs = [overlap_ncc(coarse, fine, o.transform, config.pixel) for o in options]
    gain = check.min_ncc_gain

    def vouched(t) -> bool:
        whole = window_agreement(coarse, fine, t, config.pixel)
        if not math.isfinite(whole.elsewhere):  # no room elsewhere: the share at it decides
            whole = whole._replace(elsewhere=0.0)
        return windows_agree(whole, config.decision)

    counted = [True] + [
        by_counts(r.counted and check.clearly_more(len(r.fit.inliers), r.simpler_inliers),
                  n, nccs[0], gain) for r, n in zip(richer, nccs[1:])]
    pixels = [False] + [by_pixels(n, nccs[0], gain) for n in nccs[1:]]
    allowed = allowed_maps(nccs, counted, pixels, lambda k: vouched(options[k].transform), gain)
    return options[chosen_model(nccs, [o.model for o in options], allowed, gain)]


def grown_answer(attempt: Attempt, fit: Fit, search: Search) -> Fit:
    """An accepted answer ``fit`` (:func:`final_fit`) grown by guided
    matching over every scale matched in full (:func:`stages.refit.guided_refit`): the paper's
    step (iv), "establish many other matches once this matrix is known", for an answer of
    fewer than ``GuidedParams.grow_below_inliers`` inliers. It follows the decision and the pixel
    tests, which judge the map the search found: growth spreads a repeated structure's copy as
    readily as the truth. In the default mode only (the paper's jets have no guided distance
    of their own)."""
    config = search.config
    if search.mode.orientation is None or len(fit.inliers) >= search.mode.guided.grow_below_inliers:
        return fit
    if not attempt.view.is_identity or attempt.coarser_view is not None:
        return fit  # a view's points and orientations are in the view's frame
    spec = fit_spec(config)
    asked = climbing(config) if spec.model == "similarity" else None  # as model_by_pixels
    return guided_refit(fit, attempt.view.source_shape, attempt.outcomes,
                        search.memo.coarser[attempt.direction].described,
                        search.mode.guided, spec, asked)


def pinned_answer(attempt: Attempt, fit: Fit, search: Search) -> Tuple[Fit, Pinned]:
    """(the fit, how firmly its inliers pin it): an accepted answer ``fit``, or the
    simpler model its inliers pin down (:func:`stages.refit.pinned_model`), at working size."""
    coarser, finer = search.work.coarser_finer(attempt.direction)
    return pinned_model(fit, finer.shape, coarser.shape, search.config.pin,
                        fit_spec(search.config))


def best_fitting(search: Search, attempts: Sequence[Attempt]):
    """(winner, its final fit, its pixel check, its fit as searched): the matched attempt to
    report, or (None, None, None, None); the pixel check is None unless several were compared
    (:func:`final_fit` gives the two fits).

    One matched attempt is the answer. When several matched (a weak plain match and a view
    of the pass that confirms it), each is refit and the one whose final transform lines the
    pixels up best (ZNCC, :func:`stages.pixelcheck.pixel_check`) wins; the lowest log10 NFA
    (:func:`plan.strongest`) decides where the pixels cannot (no overlap, no ratio). The NFA
    alone favours few candidates that all agree: on a smooth least-textured crop (popos_jad
    x3; docs/design/DECISION.md, "The final map: fitting best, and better than its
    neighbours") a t = 2 view's affine map, 11 inliers of 12 candidates
    at log10 NFA -43, 48 px off, beat the plain similarity of 11 inliers that was right; its
    pixels: ZNCC 0.963 against 0.996.
    """
    config, work = search.config, search.work
    matched = [a for a in attempts if a.matched]
    if len(matched) <= 1:
        winner = strongest(attempts)
        if winner is None:
            return None, None, None, None
        searched_fit, fit = final_fit(winner, search)
        return winner, fit, None, searched_fit
    both = [final_fit(a, search) for a in matched]
    fits = [fit for _, fit in both]
    checks = [pixel_check(*work.shown(a.direction), fit.transform, config.pixel)
              for a, fit in zip(matched, fits)]

    def fitness(k: int) -> Tuple[float, float]:
        ncc = checks[k].ncc
        return (ncc if math.isfinite(ncc) else -math.inf,
                -matched[k].verdict.log10_nfa)

    k = max(range(len(matched)), key=fitness)
    return matched[k], fits[k], checks[k], both[k][0]


def best_refused(attempts: Sequence[Attempt]) -> Optional[Attempt]:
    """The refused search whose best transform is strongest (lowest log10 NFA), among those
    made on the images themselves (a view's transform is in the view's pixels): a "no" shows
    it (``MatchResult.rejected``); None when no search found a transform to refuse."""
    refused = [a for a in attempts if not a.matched and a.verdict.candidate is not None
               and a.view.is_identity and a.coarser_view is None]
    return min(refused, key=lambda a: a.verdict.log10_nfa, default=None)


def rejected_candidate(t: np.ndarray, inliers: np.ndarray, model: str, direction: Direction,
                       test: str, log10_nfa: float, figures_: dict) -> Rejected:
    """A refused transform (finer working px -> coarser working px, found in ``direction``) as
    the ``rejected`` block of a "no", turned round as a match would be (``finer_to_coarser``);
    ``figures_``: the refusing test's figures, as the test saw them (at working size)."""
    t, inliers, swapped = finer_to_coarser(np.asarray(t, np.float64), inliers,
                                           direction is Direction.SWAPPED)
    return Rejected(t, model, inliers, log10_nfa, test, figures_,
                    Direction.SWAPPED if swapped else Direction.GIVEN)


def evidence_of(shown: Attempt, run: SearchRun, final: Optional[FinalFigures],
                work: WorkImages, seen: Optional[dict] = None) -> Evidence:
    """The one :class:`Evidence` of a search's answer, assembled here from its parts: the
    decision's figures for the search ``shown`` (:func:`stages.decision.decide`), the pixel
    tests of the final transform when it faced them (``final``,
    :func:`stages.finalchecks.final_checks`), the search's own figures (searches, the view shown,
    the probe, the steps), and the working size's: its factors, and the implied ratio and the
    footprint's area in the images' own pixels (as the per-scale table, ``working.in_original``),
    and the answer's own figures (``seen``): its parallax (:func:`answer_parallax`) and how
    firmly its inliers pin it (:func:`pinned_answer`).
    """
    records, plan, stopped = run.records, run.plan, run.stopped
    decided = shown.verdict.figures
    direction = shown.direction
    g = shown_scale(work, direction) * shown.view.scale
    f_coarser = work.f_low if direction is Direction.GIVEN else work.f_high
    searched_ = dict(searches=sum(r.views for r in records), search_order=direction,
                     view_tilt=shown.shown_view.tilt,
                     view_longitude_deg=shown.shown_view.longitude_deg,
                     view_of="coarser" if shown.coarser_view is not None else "finer",
                     probe_score=shown.chosen_by,
                     probe_best=probe_best([r.probe_best for r in records]),
                     steps_run=len(records), steps_planned=len(plan), stopped=stopped)
    sized = dict(low_working_factor=work.f_low, high_working_factor=work.f_high,
                 implied_ratio=figure(decided, "implied_ratio") * g,
                 footprint_area_px=figure(decided, "footprint_area_px") * f_coarser ** 2)
    return build_evidence(decided, asdict(final) if final is not None else {},
                          searched_, sized, seen or {})


def out_of_reach(config: Config, work: WorkImages) -> str:
    """Why an empty plan searched nothing: at every scale of ``config.scales`` the finer image
    of either order would span fewer than ``config.min_footprint_px`` coarser pixels
    (:func:`scalematch.search.plan.within_reach`)."""
    sizes = " and ".join(f"{w}x{h}" for h, w in (work.low.shape, work.high.shape))
    floor = f"under {config.min_footprint_px:g} px of the coarser one"
    if max(max(work.low.shape), max(work.high.shape)) < config.min_footprint_px:
        return f"the images are too small ({sizes} px): the finer one would span {floor}"
    scales = ", ".join(f"{s:g}" for s in config.scales)
    return (f"no scale searched fits these images ({sizes} px at working size): at every scale "
            f"searched ({scales}) the finer image would span {floor}; try smaller scales "
            f"(--scales)")


def build_result(search: Search, run: SearchRun) -> MatchResult:
    """The one :class:`MatchResult` of a search, at working size (``working.in_original`` next),
    its evidence assembled once (:func:`evidence_of`).

    A match shows the strongest matched attempt, refit in the finer image's pixels; no match
    shows the first search made (the finer image itself, in the given order), with its reason.
    The refit transform faces the pixel tests (:func:`stages.finalchecks.final_checks`): a
    repeated structure is refused there. The accepted map, grown, is claimed as its model only
    where its inliers pin it down (:func:`pinned_answer`); a simpler model they pin answers
    otherwise.
    """
    if not run.attempts:  # an empty plan: no scale asked for is within reach of these images
        return unreachable(search, run)
    if answered_by_a_matrix(search.config):
        return matrix_answer(search, run)
    winner, fit, near, searched_fit = best_fitting(search, run.attempts)
    if winner is None:
        return refused(search, run, best_refused(run.attempts) or run.attempts[0])
    final, refusal = judged_by_pixels(search, run, winner, fit, near, searched_fit)
    if refusal is not None:
        return refusal
    fit = grown_answer(winner, fit, search)
    fit, pinned = pinned_answer(winner, fit, search)
    seen = answer_parallax(winner, fit.transform, fit.model, search.config)
    return answered(search, run, winner, fit, seen, final, pinned)


def answered_by_a_matrix(config: Config) -> bool:
    """Whether ``config.model`` answers with a matrix (the fundamental matrix: a point maps to a
    line; :func:`matrix_answer`) rather than a map; where the matrix shows no parallax, or none
    is found, the plane map of a second search answers instead (:func:`without_parallax`,
    :func:`plane_instead`)."""
    return not model_of(config.model).has_ratio


def matrix_answer(search: Search, run: SearchRun) -> MatchResult:
    """The answer of a search for an epipolar geometry: its strongest matched attempt
    (:func:`plan.strongest`), refit in the images' own pixels, with the parallax its inliers
    show by themselves (:func:`stages.finalchecks.plane_parallax`). No pixels judge it and it
    is not grown: a point maps to a line, so there is no place to check or predict."""
    winner = strongest(run.attempts)
    if winner is None:
        return refused(search, run, best_refused(run.attempts) or run.attempts[0])
    fit, config = in_images(winner, search), search.config
    coarser, finer = search.work.shown(winner.direction)
    seen = plane_parallax(fit.inliers, winner.verdict.figures, fit_spec(config), config.decision,
                          functools.partial(matches_beat_plane, coarser, finer,
                                            params=config.pixel))
    return answered(search, run, winner, fit, seen)


def _common(search: Search, run: SearchRun, shown: Attempt) -> dict:
    """What every result of a search holds: a "no" has no best scale (NaN, null in the JSON),
    as it has no ratio; its refused candidate is told in ``rejected``."""
    return dict(model=search.config.model, best_scale=math.nan,
                scales=rows_of(shown), timings=run.timings,
                config=search.config, search=run.records,
                covariance_used=search.mode.covariance_used)


def rows_of(attempt: Attempt) -> Tuple[ScaleRow, ...]:
    """The per-scale rows of an attempt in the finer image's scales: a view simulated on the
    image shrunk (``View.scale``) has its rows' scales and ratios in its own pixels."""
    k = attempt.view.scale
    return tuple(o.row if k == 1.0 else replace(o.row, s=o.row.s * k, ratio=o.row.ratio * k)
                 for o in attempt.outcomes)


def unreachable(search: Search, run: SearchRun) -> MatchResult:
    """The "no" of an empty plan: no scale asked for is within reach of these images."""
    config, work = search.config, search.work
    return MatchResult(
        matched=False, model=config.model, reason=out_of_reach(config, work),
        timings=run.timings, config=config, search=run.records,
        covariance_used=search.mode.covariance_used,
        evidence=build_evidence(dict(steps_planned=len(run.plan), stopped=run.stopped,
                                     low_working_factor=work.f_low,
                                     high_working_factor=work.f_high)))


def refused(search: Search, run: SearchRun, shown: Attempt) -> MatchResult:
    """The "no" of a search whose every attempt was refused: the reason of the one ``shown``
    and, when it had a transform on the images themselves, that transform as ``rejected``."""
    config, records, verdict = search.config, run.records, shown.verdict
    searches = sum(r.views for r in records)
    more = f" ({searches} searches: {searched(records)})" if searches > 1 else ""
    if run.stopped == "time budget":
        more += (f"; the time budget of {config.time_budget_s:g} s ran out after "
                 f"{len(records)} of {len(run.plan)} steps")
    has_candidate = shown.verdict.candidate is not None and shown.view.is_identity and \
        shown.coarser_view is None and not shown.matched
    rejected = None if not has_candidate else rejected_candidate(
        verdict.candidate, verdict.candidate_inliers, fit_spec(config).model, shown.direction,
        verdict.test, verdict.log10_nfa,
        figures(verdict.test, verdict.figures, config.decision))
    return MatchResult(matched=False, reason=verdict.reason + more, rejected=rejected,
                       evidence=evidence_of(shown, run, None, search.work),
                       **_common(search, run, shown))


def judged_by_pixels(search: Search, run: SearchRun, winner: Attempt, fit: Fit,
                     near, searched_fit: Fit
                     ) -> Tuple[Optional[FinalFigures], Optional[MatchResult]]:
    """(the pixel tests' figures, None) for a winner's refit ``fit`` that passes them
    (:func:`stages.finalchecks.final_checks`), or (figures, the "no" that refuses it).

    A map climbed to a richer model (``searched_fit``: the same map in the model searched,
    :func:`final_fit`) that only its windows find unique (its uniqueness ratio refused it) is
    unique only if the map found is unique as well
    (:func:`stages.finalchecks.searched_unique`): the richer model's freedom was fitted to the
    pixels the windows compare, and on a repeated facade it bends the map onto a copy's
    windows. A climbed map unique by its ratio stands on its own."""
    config, verdict = search.config, winner.verdict
    t, inliers, model = fit
    coarse, fine = search.work.shown(winner.direction)
    claim = Claim(t, verdict.log10_nfa, vouched=inliers[:, :2])
    final, reason, test = final_checks(coarse, fine, claim, config.decision, near,
                                       pixel=config.pixel)
    if not reason and final.unique_windows and searched_fit.model != model:
        t, inliers, model = searched_fit
        as_found, reason = searched_unique(
            coarse, fine, Claim(t, verdict.log10_nfa, vouched=inliers[:, :2]), config.decision,
            config.pixel)
        if reason:
            final, test = as_found, "uniqueness"
    if not reason:
        return final, None
    return final, MatchResult(
        matched=False, reason=reason, rejected=rejected_candidate(
            t, inliers, model, winner.direction, test, verdict.log10_nfa,
            figures(test, verdict.figures, config.decision, final)),
        evidence=evidence_of(winner, run, final, search.work), **_common(search, run, winner))


def answered(search: Search, run: SearchRun, winner: Attempt, fit: Fit, seen: dict,
             final: Optional[FinalFigures] = None, pinned: Optional[Pinned] = None
             ) -> MatchResult:
    """The match: the winner's final ``fit`` turned to map the finer image to the coarser one,
    its ratio, angle and translation, and its evidence with the answer's parallax figures
    (``seen``), its pixel tests' (``final``) and how firmly its inliers pin it (``pinned``,
    :func:`pinned_answer`)."""
    t, inliers, model = fit
    kind = model_of(model)
    if pinned is not None:
        work = search.work
        seen = dict(seen, **pinned.figures(
            work.f_low if winner.direction is Direction.GIVEN else work.f_high))
    t = kind.refined(t, inliers)  # a matrix: LM on the Sampson error
    t, inliers, swapped = finer_to_coarser(t, inliers, winner.direction is Direction.SWAPPED,
                                           kind.parts)
    ratio, angle, tr = kind.parts(t, inliers[:, :2])
    return MatchResult(**dict(_common(search, run, winner), model=model,
                              best_scale=winner.verdict.best_scale * winner.view.scale),
                       matched=True, transform=t, resolution_ratio=ratio, rotation_deg=angle,
                       translation=tr, inliers=inliers,
                       evidence=evidence_of(winner, run, final, search.work, seen),
                       order=Direction.SWAPPED if swapped else Direction.GIVEN)


def answer_parallax(attempt: Attempt, t: np.ndarray, model: str, config: Config) -> dict:
    """The parallax figures (``Evidence.parallax_points``, ``parallax``) of the answer's own
    map ``t`` (the images' pixels at working size, the finer image's to the coarser one's),
    over every candidate of its winning scale. Counted against the map answered, not the
    scale's similarity: a plane seen in perspective (Oxford graf 1 -> 2, wall 1 -> 3) leaves
    true matches off a similarity that an epipolar geometry explains (551 and 1598 such
    points), which its homography, the answer, holds (8 and 3)."""
    params = config.decision
    src, dst = candidates_in_images(attempt.view, attempt.winning_outcome(),
                                    attempt.coarser_view)
    if len(src) == 0:
        return {}
    held = residuals(model, t, src, dst) <= config.ransac.threshold_px
    fit = EpipolarFit(params.parallax_threshold_px, params.parallax_min_candidates,
                      params.parallax_confidence)
    n = off_plane(src, dst, held, fit, config.seed, t, params.parallax_max_offset)
    k = len(distinct_pairs(src[held], dst[held])[0])
    return {"parallax_points": n,
            "parallax": n >= max(params.parallax_min_points, params.parallax_share * k)}


def plane_instead(result: MatchResult, plane: MatchResult) -> MatchResult:
    """The answer for a fundamental matrix asked for and not found (``result``, a "no"): the
    plane map of the same pair, ``plane``, where it passed the decision and the candidates off
    its map show no parallax (``Evidence.parallax``): a flat scene, where an epipolar geometry
    has nothing to fix its epipole on, and where at high ratios its 8-point sample finds too few
    inliers to stand out from chance; otherwise ``result``. Both are in the images' own
    pixels; the time is both searches'."""
    timings = _both_timings(result, plane)
    if plane.matched and not plane.evidence.parallax:
        return replace(plane, timings=timings, config=result.config)
    return replace(result, timings=timings)


def _both_timings(result: MatchResult, plane: MatchResult) -> dict:
    """The timings of an answer made of a fundamental matrix's search (``result``) and the
    plane map's search after it (``plane``): the plane's steps, the matrix's as "epipolar",
    and both in "total"."""
    return dict(plane.timings, epipolar=result.seconds, total=result.seconds + plane.seconds)


def plane_near_its_inliers(plane: MatchResult, work: WorkImages,
                           config: Config) -> Optional[NearWindows]:
    """The windows of a plane map that only the pixels refused (``plane``: a "no" whose
    ``rejected`` map failed the test "pixels", the last of the decision), compared near its own
    inliers (:func:`scalematch.stages.pixelcheck.near_windows` with ``vouched``) at the images'
    working sizes ``work``; None for any other plane result.

    Over the whole footprint, a scene with depth puts its other planes among the windows
    compared, which the plane's map does not fit; near the plane's inliers it fits, where the
    plane is. The uniqueness test compares there already (``PixelParams.vouch_radius``)."""
    rej = plane.rejected
    if plane.matched or rej is None or rej.test != "pixels":
        return None
    t, inliers = at_working_size_of(rej, work)
    coarser, finer = work.shown(rej.order)
    return near_windows(coarser, finer, t, config.pixel, inliers[:, :2])


def _no_plane_reason(result: MatchResult, plane: MatchResult, config: Config,
                     near: Optional[NearWindows], held_near: bool) -> str:
    """Why a matched matrix without parallax is refused (:func:`without_parallax`): its count
    off the plane, the plane map's refusal, and what its windows near its own inliers showed."""
    e = result.evidence
    count = (f"log10 NFA {e.parallax_log10_nfa:.1f} > {config.decision.max_log_nfa:g}"
             if math.isfinite(e.parallax_log10_nfa) else "too few to count")
    where = ""
    if near is not None and near.windows:
        where = (f"; near its own inliers {near.claimed:.0%} of its {near.windows} windows "
                 f"agree, {near.nearby:.0%} nearby")
        if held_near:
            where += (f", which establishes the plane, but the {e.parallax_vouched_points} "
                      f"inliers off it that fit better there fix the epipole at log10 NFA "
                      f"{e.epipole_log10_nfa:.1f}")
    return (f"an epipolar geometry fits {result.n_inliers} inliers but shows no parallax "
            f"beyond chance ({e.parallax_points} off its dominant plane, {count}), so they "
            f"do not fix its epipole, and no plane map of the scene passes the decision "
            f"({plane.reason}{where})")


def without_parallax(result: MatchResult, plane: MatchResult, config: Config,
                     near: Optional[NearWindows] = None) -> MatchResult:
    """The answer for a matched fundamental matrix ``result`` whose inliers show no parallax
    of their own (``stages.finalchecks.plane_parallax``): the plane map of the same pair,
    ``plane``, where it passed the decision, with the matrix's figures in its evidence;
    otherwise "no", with the matrix shown as ``rejected`` (test "plane"). Both are in the
    images' own pixels.

    Without parallax the inliers do not fix the epipole: a scene with little depth fits every
    epipolar geometry through its plane's map, and a repeated structure matched to its shifted
    copy fits one too. The plane map faces the tests an epipolar geometry cannot (a plausible
    scale and footprint, no repeated structure, the pixels), and it is what the inliers do
    determine. It is searched as the default would search it (``config`` with
    ``decision.plane_model``, which the model check may turn into an affine map or a
    homography: ``pipeline.match``); ``model`` then says which it is.

    Where that plane map passes, the plane is established by more than the matrix's inliers,
    and the inliers off it need only fix the epipole: where those whose own match fits the
    pixels better than the plane's prediction do so beyond chance
    (``Evidence.epipole_log10_nfa`` at most ``max_log_nfa``), the matrix answers, its parallax
    seen through the plane. A plane map that passed every test but the last, the pixels over its
    whole footprint, establishes the plane as well where its windows near its own inliers
    agree (``near``: :func:`plane_near_its_inliers`, judged as the whole footprint's are,
    ``stages.finalchecks.near_windows_agree``): a scene with depth puts its other planes in
    the footprint. It establishes the plane for the matrix only; it does not answer itself.
    """
    e = result.evidence
    held_near = (not plane.matched and near is not None
                 and near_windows_agree(near, config.decision))
    planar = plane.n_inliers if plane.matched else \
        plane.rejected.n_inliers if held_near else 0
    figs = dict(plane_inliers=planar,
                parallax_log10_nfa=e.parallax_log10_nfa,
                parallax_vouched_points=e.parallax_vouched_points,
                epipole_log10_nfa=e.epipole_log10_nfa)
    if near is not None:
        figs.update(plane_windows=near.windows, plane_windows_agreeing=near.claimed,
                    plane_windows_nearby=near.nearby)
    timings = _both_timings(result, plane)
    if (plane.matched or held_near) and e.epipole_log10_nfa <= config.decision.max_log_nfa:
        return replace(result, evidence=build_evidence(asdict(e), figs, {"parallax": True}),
                       timings=timings)
    if plane.matched:
        return replace(plane, evidence=build_evidence(asdict(plane.evidence), figs),
                       timings=timings, config=result.config)
    reached = dict(asdict(e), **figs)
    evidence = build_evidence(reached)
    reason = _no_plane_reason(result, plane, config, near, held_near)
    rejected = Rejected(result.transform, result.model, result.inliers, e.log10_nfa, "plane",
                        figures("plane", reached, config.decision), result.order)
    return replace(result, matched=False, reason=reason, transform=None,
                   inliers=np.zeros((0, 4)), evidence=evidence, timings=timings,
                   order=Direction.GIVEN, rejected=rejected)
