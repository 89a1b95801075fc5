"""The one-to-many matcher: every scale of the finer image against the coarser one (paper 4.2, 5).

``match(low, high, config)`` checks its inputs once, brings very large images to their working
size, builds one :class:`Search` (the images, the configuration, the mode's strategy from
:mod:`scalematch.modes`, what the steps share, the progress meter) and runs the search plan
(:mod:`scalematch.search`) with it, a step at a time: each step detects the views of the
finer image at every scale (scale-adapted Harris), describes their strongest points, scores the
scales with the probe, and matches the promising ones in full against the coarser image's
points (found once, at s = 1): candidates, geometric constraints, robust estimation. The scale
with the most inliers wins (docs/ALGORITHM.md step 7) and :mod:`scalematch.stages.decision` says
whether the evidence is enough; :mod:`scalematch.answer` makes the one :class:`MatchResult` of
the attempts (the winner refit in the finer image's pixels, its pixel tests, grown, pinned).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import replace
from typing import Callable, Dict, Iterator, List, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from .config import Config
from .geometry import usable_ratio
from .greylevels import grey_levels
from .result import (Direction, MatchResult, NoDataSeen, ScaleRow,
                     StepRecord)
from .features import (Describing, ImageViews, Roles, first_level, first_level_points,
                       image_views)
from .answer import answered_by_a_matrix, build_result, plane_instead, without_parallax
from .sharing import Detected, LowFeatures, Measured, Memo, Meter, Probed, Search
from .search import (Attempt, ScaleOutcome, SearchRun, Step, coarser_viewed, fit_spec,
                     out_of_time, overwhelming, search_plan, skips, stop_reason)
from .stages.decision import SearchContext, decide
from .stages.descriptors import Described
from .stages.detector import Contrast, Gradients, Keypoints, detect_on_level
from .stages.estimator import Estimate, FitSpec, estimate, model_of
from .stages.matcher import distinct_pairs, match_descriptors
from .stages.nodata import NoData, distance_inside
from .stages.probe import probe_scores, select_scales
from .stages.scalespace import Level, scale_space
from .stages.secondlook import Sight
from .stages.threads import thread_map
from .stages.views import View, identity_view, tilt_view, valid_in, view_scales
from .stages.vote import (Candidates as VoteCandidates, Cells, Ranked, best_pairs, index_scale,
                          log10_nfa as cells_nfa, scale_index, vote as vote_cells)
from .modes import mode_of
from .working import WorkImages, at_working_size, in_original, shown_scale

__all__ = ["match", "distinct_pairs"]

#: Largest view of the finer image, px, whose scale-space levels are kept from detection to the
#: full pass (about 2.7 image copies of float32 over third-octave scales: 43 MB at 4 MP); a
#: larger image's levels are computed again, so peak memory stays bounded for camera-size
#: images. The result is the same either way.
KEEP_LEVELS_MAX_PX = 4_000_000

def match(low: np.ndarray, high: np.ndarray, config: Config = Config(),
          progress: Optional[Callable[[int, int], None]] = None,
          decoded_factors: Tuple[float, float] = (1.0, 1.0)) -> MatchResult:
    """Match a low-resolution image against a high-resolution one of the same scene.

    ``low``, ``high``: (H, W) grey images (8-bit levels, 16-bit integers or floats in [0, 1];
    ``ValueError`` for what cannot match). ``config``: every parameter, recorded in the result.
    ``progress(done, total)`` follows the search plan. ``decoded_factors``: each image is its
    file's shrunk by this factor (a JPEG decoded reduced); the answer is in the files' pixels.

    Returns a :class:`MatchResult`: ``matched`` False with a ``reason`` when the evidence is too
    weak (a wrong transform reported as a match is the worst outcome); ``transform`` maps the
    finer image's pixels to the coarser one's, ``order`` says which image is the finer.
    """
    check_config(config)
    t0 = time.perf_counter()
    # 1. The images at their working size, checked at the door; their no-data found
    #    (working.py, stages/nodata.py)
    work = at_working_size(grey_levels(low, "low"), grey_levels(high, "high"), config,
                           decoded_factors)
    # 2-6. The search and its answer, in the images' own pixels
    result = searched_answer(work, config, progress, t0)
    # 7. A fundamental matrix whose inliers show no parallax does not fix its epipole, and
    #    none found says nothing of a flat scene: the plane map of the same images answers
    #    instead (answer.without_parallax, answer.plane_instead)
    if answered_by_a_matrix(config) and not (result.matched and result.evidence.parallax):
        plane = searched_answer(work, replace(config, model=config.decision.plane_model),
                                None, time.perf_counter())
        result = without_parallax(result, plane, config) if result.matched else \
            plane_instead(result, plane)
    return result


def searched_answer(work: WorkImages, config: Config,
                    progress: Optional[Callable[[int, int], None]], t0: float) -> MatchResult:
    """The search of images at their working size ``work`` with ``config``, and its answer in
    the images' own pixels (``match``'s steps 2 to 6; ``t0``: when the search's time began,
    ``time.perf_counter``)."""
    # 2. The plan (search.py, MODS): the given order, the other, then passes of tilted views
    plan = search_plan(config, work.scales, finer_sides(work))
    # 3. What every step shares: the mode's strategy (modes.py), the caches, the progress meter
    search = Search(work, config, mode_of(config), Memo(),
                    Meter(progress, sum(step.cost for step in plan)))
    # 4. Each step until one decides: the scale-space of the finer image and Harris points at
    #    every scale, descriptors, the probe, then matching, constraints and RANSAC at the
    #    scales it chose, and the decision (run_step, stages/decision.py)
    run = run_plan(search, plan, t0)
    # 5. The answer: the winner refit, judged by its pixels and grown; or a "no" and why
    #    (answer.py)
    result = build_result(search, run)
    # 6. In the images' own pixels, with what each showed of no-data
    return replace(in_original(result, work, config),
                   nodata=(nodata_seen(work.low_nodata), nodata_seen(work.high_nodata)))


def check_config(config: Config) -> None:
    """``TypeError`` unless ``config`` is a :class:`Config`; the process's BLAS warmed up."""
    if not isinstance(config, Config):
        raise TypeError(f"config must be a scalematch.Config, not {type(config).__name__}: "
                        f"Config(model=\"affine\") or Config.preset(\"no-views\"), say")
    warm_up_blas()


def finer_sides(work: WorkImages) -> Dict[Direction, int]:
    """Each direction's finer image's longer side at working size, px (its reach)."""
    return {d: max(d.coarser_finer(work.low, work.high)[1].shape) for d in Direction}


def nodata_seen(nodata: NoData) -> NoDataSeen:
    """The record of what an image showed of no-data (the JSON's ``low.nodata``)."""
    return NoDataSeen(nodata.value, nodata.share)


def run_plan(search: Search, plan: Sequence[Step], t0: float) -> SearchRun:
    """Run the steps of ``plan`` in order, each unless an earlier attempt makes it needless
    (:func:`scalematch.search.skips`), until one stops the search or the time budget (counted
    from ``t0``, ``time.perf_counter``) is spent."""
    config = search.config
    attempts: List[Attempt] = []
    records: List[StepRecord] = []
    timings: Dict[str, float] = {}
    stopped = "plan done"
    for step in plan:
        if skips(step, attempts, config):
            search.meter.tick(step.cost)
            continue
        if out_of_time(time.perf_counter() - t0, len(records), config):
            stopped = "time budget"
            break
        found, record, seconds = run_step(search, step, searches=sum(r.views for r in records))
        attempts += found
        records.append(record)
        timings[record.name] = seconds
        stopped = stop_reason(step, attempts, plan, config)
        if stopped:
            break
    search.meter.finish()
    timings["total"] = time.perf_counter() - t0
    return SearchRun(tuple(attempts), tuple(records), tuple(plan), stopped, timings)


@functools.cache
def warm_up_blas() -> None:
    """Run one small matrix product, once per process.

    OpenBLAS allocates its work buffers at its first matrix product, and when that allocation
    fails (a process near its memory limit) it ends the process with exit code 1 from native
    code, which reads as "no reliable match". One small product before the images are worked on
    (at the start of ``match``, and when a batch worker starts) takes them while memory is
    there; later products reuse them.
    """
    np.ones((128, 128), np.float32) @ np.ones((128, 128), np.float32)


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


def describe_low(low: np.ndarray, search: Search,
                 contrast: Optional[Contrast] = None,
                 grads: Optional[Gradients] = None,
                 inside: Optional[np.ndarray] = None) -> LowFeatures:
    """The coarser image's points at s = 1 (``contrast``: its own, for adaptive detection;
    measured here when not given; ``grads``: its gradients, when measured with it; ``inside``:
    the distance to its no-data region, :func:`stages.nodata.distance_inside`)."""
    config = search.config
    level = Level(s=1.0, d=1.0, blur=0.0, image=low)
    kp = detect_on_level(level, config.harris_low, contrast, grads, inside,
                         config.views.edge_margin_px)
    return LowFeatures(low, search.mode.describe(level, kp), kp)


def shares_first_level(config: Config) -> bool:
    """True when an image's s = 1 points as the coarser one give its s = 1 points as the finer:
    the same detector but for a cap at least as large."""
    high, low = config.harris, config.harris_low
    return replace(low, max_points=high.max_points) == high and high.max_points > 0 and (
        low.max_points == 0 or low.max_points >= high.max_points)


def _detect(view: View, level: Level, config: Config, contrast: Optional[Contrast],
            grads: Optional[Gradients] = None) -> Keypoints:
    """The points of one level of a view, away from its empty corners and no-data regions."""
    return detect_on_level(level, config.harris, contrast, grads, view.inside_distance,
                           config.views.edge_margin_px)


def _space(config: Config) -> dict:
    return dict(sigma=config.harris.sigma, min_level_sigma=config.harris.min_level_sigma,
                decimate=config.harris.decimate, camera_blur_px=config.harris.camera_blur_px)


def _joined(head: Described, rest: Described, offset: int) -> Described:
    """The descriptors of keypoints [0, offset) and [offset, N) as one ``Described``."""
    return Described(s=head.s, xy=np.vstack([head.xy, rest.xy]),
                     index=np.concatenate([head.index, rest.index + offset]),
                     angle=np.concatenate([head.angle, rest.angle]),
                     desc=np.vstack([head.desc, rest.desc]))


class Reuse(NamedTuple):
    """What the detection of the finer image takes from the rest of the search: none of it
    changes the points found (:func:`detect_view`).

    ``known``: the same image described as the coarser one (the other direction), whose points
    give its s = 1 points (:func:`shares_first_level`). ``measured``: the finer image's
    contrast (:func:`scalematch.stages.detector.image_contrast`), when the detector adapts to
    it, and its gradients at s = 1 (:meth:`Memo.measured`).
    """

    known: Optional[LowFeatures] = None
    measured: Measured = Measured(None)


def detect_view(view: View, search: Search, scales: Sequence[float],
                tick: Callable[[], None] = lambda: None,
                reuse: Reuse = Reuse()) -> Tuple[Tuple[Detected, ...], bool]:
    """Detect every scale of the finer image and describe the probe's points: (detected,
    probing).

    ``scales``: the scales to detect (the step's). ``tick()`` is called once per scale
    detected. The levels of an image of at most ``KEEP_LEVELS_MAX_PX`` pixels are kept for the
    full pass. ``reuse``: what other steps found on the same images (:class:`Reuse`).
    """
    config = search.config
    known, (contrast, grads) = reuse
    scales = sorted(scales)
    probing = config.probe.enabled and len(scales) > config.probe.keep
    keep = view.image.size <= KEEP_LEVELS_MAX_PX
    n_probe = config.probe.points if probing else config.harris.max_points
    reuse = known is not None and view.is_identity and shares_first_level(config)
    detected = []
    for level in scale_space(view.image, scales, **_space(config)):
        if min(level.image.shape) < config.harris.min_level_side_px:
            detected.append(Detected(Keypoints.empty(level.s), None, None))
        elif reuse and level.s == 1.0:  # found already: the coarser image of the other direction
            kp, part, full = known.strongest(config.harris.max_points, n_probe)
            detected.append(Detected(kp, part, level if keep else None, full))
        else:
            first = grads if view.is_identity and level.s == 1.0 else None
            kp = _detect(view, level, config, contrast, first)
            part = kp.part(slice(config.probe.points)) if probing else kp
            detected.append(Detected(kp, search.mode.describe(level, part),
                                     level if keep else None))
        tick()
    return tuple(detected), probing


def score_view(view: View, detected: Tuple, probing: bool, low: LowFeatures,
               search: Search) -> Probed:
    """Score each scale of a detected view from its strongest points (paper 5)."""
    config = search.config
    usable = [i for i, d in enumerate(detected) if d.probe is not None and len(d.probe)]
    if probing:
        # the probe's quick fit is a similarity whatever the model searched for: its ratio
        # and angle are what rank the scales
        quick = FitSpec("similarity", config.ransac, config.seed)
        scores = probe_scores([detected[i].probe for i in usable], low.described, config.probe,
                              matcher=config.matcher, orientation=search.mode.orientation,
                              fit=quick, scale_agreement=config.decision.scale_agreement)
        run = sorted(usable[j] for j in select_scales(scores, config.probe.keep,
                                                               config.probe.min_score))
        best = max(scores, default=0.0)
    else:
        run, best = usable, math.inf
    return Probed(view, detected, tuple(usable), tuple(run), best, probing)


def _levels(view: View, detected: Sequence[Detected], wanted: Sequence[int],
            scales: Sequence[float], config: Config) -> Tuple[Iterator[Tuple[int, Level]], bool]:
    """(the levels ``wanted`` of a view as (index, level), in order; True when they were kept
    by the detection) -- else the detection's cascade again, up to the largest one wanted, a
    level at a time (bounded memory)."""
    if all(detected[i].level is not None for i in wanted):
        return ((i, detected[i].level) for i in wanted), True
    scales = sorted(scales)
    return ((i, level) for i, level in enumerate(scale_space(
        view.image, scales[:wanted[-1] + 1], **_space(config))) if i in wanted), False


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


def run_step(search: Search, step: Step,
             searches: int) -> Tuple[List[Attempt], StepRecord, float]:
    """Run one step of the plan: the finer image itself (probe its scales, match the promising
    ones in full, decide), or the pooled views (:func:`run_views`); (attempts, record,
    seconds).

    ``search.memo`` holds what earlier steps computed on the same images; ``searches`` counts
    the view pairs searched by earlier steps (the a-contrario test counts them all).
    """
    t0 = time.perf_counter()
    meter = search.meter
    start = meter.done
    if step.view_pass > 0:
        attempts, record = run_views(search, step, searches)
    else:
        candidate = probe_plain(search, step)
        attempts = match_chosen(search, step, [candidate], searches + 1)
        record = StepRecord(step.direction, 0, 1, len(attempts), candidate.score,
                            any(a.matched for a in attempts), step.side)
    meter.tick(start + step.cost - meter.done)  # what the step left out
    return attempts, record, time.perf_counter() - t0


class Candidate(NamedTuple):
    """A view pair to match in full: a view of the finer image probed (its chosen scales in
    ``probed.run``), the coarser features it is matched against and the view of the coarser
    image they come from (None: the image itself)."""

    probed: "Probed"
    coarser: LowFeatures
    coarser_view: Optional[View]
    direction: Direction
    scales: Tuple[float, ...]  #: the finer view's scales, in its own pixels (sorted)
    score: float  #: what chose it: the probe's best score, or the pair's votes


def probe_plain(search: Search, step: Step) -> Candidate:
    """Detect and probe the finer image itself at every scale against the coarser image, which
    is described once per direction (``memo.coarser``), on a thread while the finer image is
    detected; the finer image probed is kept (``memo.plain``) for the views."""
    cfg, memo, direction = search.config, search.memo, step.direction
    lo_img, hi_img = search.work.coarser_finer(direction)
    lo_valid, hi_valid = search.work.valid(direction)
    view = identity_view(hi_img, hi_valid)

    def detect():  # the gradients measured with the contrast serve the image's s = 1 level
        reuse = Reuse(memo.coarser.get(direction.other), memo.measured(hi_img, cfg.harris))
        return detect_view(view, search, step.scales, search.meter.tick, reuse)

    if direction not in memo.coarser:  # described while the finer image is detected
        memo.coarser[direction], detected = thread_map(lambda job: job(), [
            lambda: describe_low(lo_img, search, *memo.measured(lo_img, cfg.harris_low),
                                 distance_inside(lo_valid)),
            detect])
    else:
        detected = detect()
    probed = score_view(view, *detected, memo.coarser[direction], search)
    memo.plain[direction] = probed
    return Candidate(probed, memo.coarser[direction], None, direction, tuple(sorted(step.scales)),
                     probed.score)


def describe_coarser_view(view: View, search: Search, contrast: Optional[Contrast]
                          ) -> LowFeatures:
    """A view of the coarser image described as the coarser image is (at s = 1,
    ``harris_low``), its points away from the view's empty corners; ``contrast``: the coarser
    image's own (the detector adapts to it as for the image itself)."""
    config = search.config
    kp = first_level_points(view, config.harris_low, contrast, config.views.edge_margin_px)
    return LowFeatures(view.image, search.mode.describe(first_level(view), kp), kp)


def plain_probed(search: Search, direction: Direction, scales: Sequence[float]) -> Probed:
    """The finer image of ``direction`` detected at every scale of ``scales``, as its plain
    step did (kept in ``memo.plain``; detected here when that step did not run, its score
    unset)."""
    memo = search.memo
    if direction not in memo.plain:
        hi_img = search.work.coarser_finer(direction)[1]
        view = identity_view(hi_img, search.work.valid(direction)[1])
        detected, probing = detect_view(view, search, scales, reuse=Reuse(
            memo.coarser.get(direction.other), Measured(memo.contrast(hi_img,
                                                                     search.config.harris))))
        memo.plain[direction] = Probed(view, detected, (), (), math.nan, probing)
    return memo.plain[direction]


def coarser_described(search: Search, direction: Direction) -> LowFeatures:
    """The coarser image of ``direction`` described at s = 1, as its plain step did (kept in
    ``memo.coarser``; described here when that step did not run)."""
    memo, cfg = search.memo, search.config
    if direction not in memo.coarser:
        lo_img = search.work.coarser_finer(direction)[0]
        memo.coarser[direction] = describe_low(
            lo_img, search, memo.contrast(lo_img, cfg.harris_low),
            None, distance_inside(search.work.valid(direction)[0]))
    return memo.coarser[direction]


def match_chosen(search: Search, step: Step, candidates: Sequence[Candidate],
                 searches: int) -> List[Attempt]:
    """Match in full each of ``candidates`` (a view of the finer image probed, with the chosen
    scales: ``Probed.run``), and decide each; ``searches``: the view pairs searched so far,
    these included (the a-contrario test counts them all)."""
    work, cfg, mode = search.work, search.config, search.mode
    attempts: List[Attempt] = []
    for p, low_feats, coarser_view, direction, scales, score in candidates:
        outcomes = tuple(finish_view(p, low_feats, search, scales, search.meter.tick))

        coarser_shown = (valid_in(coarser_view) if coarser_view is not None
                         else work.valid(direction)[0])
        sight = Sight(p.view.image, valid_in(p.view), low_feats.described, low_feats.image,
                      coarser_shown, fit_spec(cfg), mode.guided, cfg.pixel)
        context = SearchContext(fit_spec(cfg), mode.orientation, searches,
                                shown_scale(work, direction) * p.view.scale)
        verdict = decide(outcomes, low_feats.image.shape, p.view.image.shape, cfg.decision,
                         context=context, sight=sight)
        attempts.append(Attempt(replace(step, direction=direction), p.view, score,
                                outcomes, verdict, coarser_view))
        if overwhelming(attempts[-1], cfg):
            break  # no other view of this step can do better
    return attempts


def run_views(search: Search, step: Step, searches: int) -> Tuple[List[Attempt], StepRecord]:
    """The step of views: every view of both images described once (:mod:`scalematch.features`),
    one pooled vote over every view pair of every direction searched
    (:mod:`scalematch.stages.vote`), and the ``step.full_searches`` view pairs whose best cell
    is strongest, beyond chance, matched in full and decided; (attempts, record).

    A direction's view pairs are its finer image's views against its coarser image itself
    (``finer``), and its finer image itself against its coarser image's views (``coarser``,
    ``ViewParams.coarser``); the images themselves were searched by the plain steps.
    """
    cfg, work = search.config, search.work
    directions = [d for d, _ in step.directions]
    scales = dict(step.directions)
    viewed = coarser_viewed(directions, finer_sides(work), cfg.views.coarser_directions) \
        if cfg.views.coarser else ()
    images = views_of_images(search, step, viewed)
    sides: List[Tuple[Direction, str]] = []
    cells: List[Cells] = []
    for d in directions:
        coarser, finer = d.coarser_finer(images[Direction.GIVEN], images[Direction.SWAPPED])
        sides.append((d, "finer"))
        cells.append(side_cells(finer, coarser, "finer", cfg.matcher, cfg.vote))
        if d in viewed:
            sides.append((d, "coarser"))
            cells.append(side_cells(finer, coarser, "coarser", cfg.matcher, cfg.vote))
    # every cell voted so far counts, the earlier passes' too
    search.memo.cells_tried += sum(c.tried for c in cells)
    nfa = [cells_nfa(c, search.memo.cells_tried) for c in cells]
    ranked = best_pairs(cells, nfa, step.full_searches, cfg.vote)
    pairs = sum(len(step.views) for _, side in sides)
    chosen = [view_pair(search, sides[r.side][0], images, r, scales[sides[r.side][0]])
              for r in ranked]
    attempts = match_chosen(search, step, chosen, searches + pairs)
    record = StepRecord(step.direction, step.view_pass, pairs, len(attempts),
                        max((r.votes for r in ranked), default=0),
                        any(a.matched for a in attempts), "both")
    return attempts, record


def views_of_images(search: Search, step: Step, viewed: Sequence[Direction]
                    ) -> Dict[Direction, ImageViews]:
    """Each image's views and tables, keyed by the direction in which it is the coarser one
    (``GIVEN``: the first image given, ``SWAPPED``: the second), as far as the step needs them:
    as the finer image of a direction searched, every level of its views; as the coarser image
    of a direction in ``viewed``, the first level of its views. The images themselves come
    from the plain steps' detection (:func:`plain_probed`, :func:`coarser_described`)."""
    cfg, work, memo = search.config, search.work, search.memo
    scales = dict(step.directions)
    out = {}
    for d in (Direction.GIVEN, Direction.SWAPPED):
        image = d.coarser_finer(work.low, work.high)[0]
        valid = d.coarser_finer(work.low_valid, work.high_valid)[0]
        finer_scales = scales.get(d.other, ())  # this image is the other direction's finer one
        plain = plain_probed(search, d.other, finer_scales) if finer_scales else None
        coarser = coarser_described(search, d) if d in scales else None
        how = Describing(search.mode.describe, cfg.harris, cfg.harris_low,
                         memo.contrast(image, cfg.harris), _space(cfg), cfg.probe.points,
                         cfg.views.edge_margin_px, cfg.views.vote_every,
                         cfg.harris.min_level_side_px, cfg.views.finer_from_scale)
        roles = Roles(plain.view if plain is not None else identity_view(image, valid),
                      [x.probe for x in plain.detected if x.probe is not None]
                      if plain is not None else [],
                      coarser.described if coarser is not None else None, finer_scales,
                      d in viewed)
        out[d] = image_views(image, valid, roles, step.views, cfg.views, how, search.meter.tick)
    return out


def side_cells(finer: ImageViews, coarser: ImageViews, side: str, matcher, params) -> Cells:
    """The cells of one side of a direction's vote: the finer image's tilted views (all their
    levels probed) against the coarser image itself (``"finer"``), or the finer image itself
    (every scale probed) against each tilted view of the coarser image (``"coarser"``: the
    ratio test within each view, as a search of that view alone)."""
    f, c = finer.finer, coarser.coarser
    if side == "finer":
        f_rows, c_parts = f.rows(f.view > 0), [c.rows(c.view == 0)]
    else:
        f_rows = f.rows(f.view == 0)
        c_parts = [c.rows(c.view == v) for v in np.unique(c.view[c.view > 0])]
    found = []
    for part in c_parts:
        cand = match_descriptors(f_rows.desc, part.desc, matcher)
        if len(cand):
            i, j = cand.i, cand.j
            found.append(VoteCandidates(f_rows.view[i], part.view[j], f_rows.s[i] / part.s[j],
                                        f_rows.xy[i], part.xy[j], part.angle[j] - f_rows.angle[i],
                                        f_rows.point[i], part.point[j]))
    return vote_cells(VoteCandidates.joined(found), finer.sides, coarser.shapes, params)


def view_pair(search: Search, direction: Direction, images: Dict[Direction, ImageViews],
              ranked: Ranked, scales: Sequence[float]) -> Candidate:
    """A view pair the vote ranks among the best, made ready to be matched in full at full
    resolution (ASIFT's second resolution, Morel & Yu 2009, section 4): the finer view (made
    again at full resolution when the vote's was shrunk: ``ViewParams.max_short_side_px``) detected
    at the scales of its cells beyond chance and their neighbours (every point, the probe's
    described), the coarser view (made again the same way) described whole, or the coarser
    image itself."""
    cfg, memo, work = search.config, search.memo, search.work
    coarser_img, finer_img = direction.coarser_finer(images[Direction.GIVEN],
                                                     images[Direction.SWAPPED])
    lo_img, hi_img = work.coarser_finer(direction)
    lo_valid, hi_valid = work.valid(direction)
    voted_f = finer_img.views[ranked.finer_view]
    voted_c = coarser_img.views[ranked.coarser_view]
    full = replace(cfg.views, max_short_side_px=0.0)
    f_view = plain_probed(search, direction, scales).view if ranked.finer_view == 0 else \
        tilt_view(hi_img, voted_f.tilt, voted_f.longitude_deg, full, hi_valid)
    c_view = None if ranked.coarser_view == 0 else \
        tilt_view(lo_img, voted_c.tilt, voted_c.longitude_deg, full, lo_valid)
    own = view_scales(f_view, scales)
    # the vote's scales are between its views' pixels: in the full views' pixels, times theirs
    shift = voted_f.scale / voted_c.scale
    indices = scale_index(index_scale(np.array(ranked.scale_indices[:cfg.probe.keep])) * shift)
    wanted = sorted({k for si in indices for k in _near_scale(own, int(si)) if 0 <= k < len(own)})
    if f_view.is_identity:
        probed = replace(plain_probed(search, direction, scales), run=tuple(wanted),
                         score=float(ranked.votes))
    else:
        probed = detect_chosen(f_view, own, wanted, search, memo.contrast(hi_img, cfg.harris))
    low = coarser_described(search, direction) if c_view is None else describe_coarser_view(
        c_view, search, memo.contrast(lo_img, cfg.harris_low))
    return Candidate(probed, low, c_view, direction, tuple(own), float(ranked.votes))


def _near_scale(own: Sequence[float], index: int) -> List[int]:
    """The positions in ``own`` (a view's scales) of the scale of third-octave ``index`` and
    of its two neighbours."""
    at = int(np.argmin([abs(k - index) for k in scale_index(np.asarray(own))]))
    return [at - 1, at, at + 1]


def detect_chosen(view: View, scales: Sequence[float], wanted: Sequence[int], search: Search,
                  contrast: Optional[Contrast]) -> Probed:
    """A tilted view detected at the scales ``wanted`` (positions in its ``scales``, its own
    pixels) for a full match: every point, the probe's strongest described (the others are
    described by :func:`finish_view`); the other scales are left empty."""
    config = search.config
    detected = []
    for n, level in enumerate(scale_space(view.image, scales[:max(wanted) + 1] if wanted else [],
                                          **_space(config))):
        if n not in wanted or min(level.image.shape) < config.harris.min_level_side_px:
            detected.append(Detected(Keypoints.empty(level.s), None, None))
            continue
        kp = _detect(view, level, config, contrast)
        detected.append(Detected(kp, search.mode.describe(level, kp.part(
            slice(config.probe.points))), level))
    detected += [Detected(Keypoints.empty(s_), None, None) for s_ in scales[len(detected):]]
    usable = tuple(n for n in wanted if detected[n].probe is not None)
    return Probed(view, tuple(detected), usable, usable, math.inf, True)


