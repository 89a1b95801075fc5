"""The one-to-many matcher: every scale of the high image against the low image (paper 4.2, 5).

``match(low, high, config)`` runs, for each scale s of the high-resolution image: detection
(scale-adapted Harris), description, candidate matching against the low image's points (found
once, at s = 1), geometric constraints, and robust estimation; the scale with the most inliers
wins (ALGORITHM.md step 7) and :mod:`scalematch.stages.decision` says whether the evidence is enough.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from .config import Config
from .geometry import compose, finer_to_coarser, similarity_parts
from .imageio import grey_levels
from .result import MatchResult, ScaleRow
from .stages.constraints import orientation_groups, semi_local_filter
from .stages.decision import Decision, decide, folded
from .stages.descriptors import Described, describe_gradients, describe_jets
from .stages.detector import MIN_SIDE_PX, Keypoints, detect_on_level
from .stages.estimator import MIN_SAMPLE, Estimate, estimate, model_of, refine, residuals
from .stages.mahalanobis import load_covariance, whiten
from .stages.matcher import Candidates, match_descriptors
from .stages.scalespace import Level, as_float_image, scale_space
from .stages.threads import thread_map
from .stages.views import View, keep_inside, to_high, view_plan, views_of
from .working import direction_scales, in_original, shrink, working_factor

#: Largest view of the high image, px, whose scale-space levels are kept from detection to the
#: full pass (about 2.7 image copies of float32 over third-octave scales: 43 MB at 4 MP); a
#: larger image's levels are computed again, so peak memory stays bounded for camera-size
#: images. The result is the same either way.
KEEP_LEVELS_MAX_PX = 4_000_000

@dataclass(frozen=True)
class ScaleOutcome:
    """What one scale produced (internal to the pipeline; summarised as a ScaleRow)."""

    row: ScaleRow
    estimate: Optional[Estimate]
    src: np.ndarray  #: (K, 2) high px of the candidates given to the estimator
    dst: np.ndarray  #: (K, 2) low px
    candidates: int  #: initial candidate matches


def _describe(level: Level, kp: Keypoints, config: Config, whitening) -> Described:
    if config.mode == "paper":
        desc = describe_jets(level, kp.xy, config.harris.sigma_tilde, config.jets)
        ok = np.all(np.isfinite(desc), axis=1)
        rows = np.nonzero(ok)[0]
        return Described(s=level.s, xy=kp.xy[rows], index=rows,
                         angle=np.full(rows.size, np.nan), desc=whiten(desc[rows], whitening))
    return describe_gradients(level, kp.xy, config.gradients)


def _constrain(config: Config, high: Described, low: Described, cand, level: Level,
               low_image: np.ndarray) -> List[np.ndarray]:
    """Candidate subsets to hand to the estimator (each a boolean mask over the candidates)."""
    p = high.xy[cand.i]
    q = low.xy[cand.j]
    if config.mode == "paper":
        return [semi_local_filter(p, q, level, low_image, config.semi_local)]
    dtheta = low.angle[cand.j] - high.angle[cand.i]
    return orientation_groups(dtheta, config.orientation)


def distinct_pairs(src: np.ndarray, dst: np.ndarray):
    """The distinct rows of the point pairs (src, dst), (K, 2) each, in their first order.

    A keypoint with several dominant orientations is described once per orientation, so the
    same pair of positions can be matched more than once; counting it once keeps the inlier
    count and the a-contrario test honest.
    """
    if len(src) == 0:
        return src, dst
    rows = np.round(np.hstack([src, dst]), 3)
    _, first = np.unique(rows, axis=0, return_index=True)
    keep = np.sort(first)
    return src[keep], dst[keep]


def _full_scale(level: Level, kp: Keypoints, high: Described, low: Described,
                low_image: np.ndarray, config: Config) -> ScaleOutcome:
    """Candidate matching, constraints and robust estimation at one scale."""
    s = level.s
    cand = match_descriptors(high.desc, low.desc, config.matcher)
    best: Optional[Estimate] = None
    best_src = best_dst = np.zeros((0, 2))
    kept = 0
    if len(cand):
        for mask in _constrain(config, high, low, cand, level, low_image):
            src, dst = distinct_pairs(high.xy[cand.i[mask]], low.xy[cand.j[mask]])
            est = estimate(config.model, src, dst, config.ransac, seed=config.seed)
            if best is None or est.n_inliers > best.n_inliers:
                best, best_src, best_dst, kept = est, src, dst, int(mask.sum())
    n_in = best.n_inliers if best is not None and best.transform is not None else 0
    ratio = angle = float("nan")
    if n_in and model_of(config.model).has_ratio:
        ratio, angle, _ = similarity_parts(best.transform)
    initial = len(distinct_pairs(high.xy[cand.i], low.xy[cand.j])[0])
    row = ScaleRow(s=s, ratio=ratio, points=len(kp), initial=initial, kept=kept,
                   inliers=n_in, outlier_pct=100.0 * (1 - n_in / initial) if initial else 100.0,
                   rotation_deg=angle)
    return ScaleOutcome(row, best, best_src, best_dst, initial)


def _part(kp: Keypoints, rows: slice) -> Keypoints:
    """Some of the keypoints: ``slice(n)`` the ``n`` strongest (they are sorted strongest first)."""
    return Keypoints(s=kp.s, xy=kp.xy[rows], response=kp.response[rows])


def probe_scores(highs: Sequence[Described], low: Described, config: Config) -> List[float]:
    """How promising each scale looks from the initial matches of its strongest points alone.

    The paper (section 5) notes that the initial matches already point at the best scale.
    Each of ``highs`` holds the ``ProbeParams.points`` strongest points of one scale. In the
    paper mode a scale's score is their number of candidate matches. In the default mode it is
    the number of inliers of a quick similarity fit to the candidates in the dominant rotation
    peak, counted only when the fit's ratio agrees with the scale: rotation alone cannot rank
    scales where the scene's edges share a few directions (facades), geometry can. One
    nearest-neighbour search serves every scale (each candidate depends on its own row only;
    one large product is faster than many small ones).
    """
    if not highs:
        return []
    cand = match_descriptors(np.vstack([h.desc for h in highs]), low.desc, config.matcher)
    bounds = np.cumsum([0] + [len(h) for h in highs])
    out = []
    for h, lo, hi in zip(highs, bounds[:-1], bounds[1:]):
        rows = (cand.i >= lo) & (cand.i < hi)
        part = Candidates(cand.i[rows] - lo, cand.j[rows], cand.distance[rows], cand.second[rows])
        out.append(_score(h, low, part, config))
    return out


def _score(high: Described, low: Described, cand: Candidates, config: Config) -> float:
    if len(cand) == 0:
        return 0.0
    if config.mode == "paper":
        return float(len(cand))
    groups = orientation_groups(low.angle[cand.j] - high.angle[cand.i], config.orientation)
    best = 0.0
    for mask in groups:
        est = estimate("similarity", high.xy[cand.i[mask]], low.xy[cand.j[mask]],
                       replace(config.ransac, max_iters=config.probe.ransac_iters),
                       seed=config.seed)
        if est.transform is None:
            continue
        ratio = similarity_parts(est.transform)[0]
        if math.isfinite(ratio) and abs(math.log(ratio / high.s)) <= math.log(
                config.decision.scale_agreement):
            best = max(best, float(est.n_inliers))
    return best


def select_scales(scores: List[float], keep: int) -> List[int]:
    """Indices of the ``keep`` best-scoring scales and their immediate neighbours."""
    order = sorted(range(len(scores)), key=lambda i: (-scores[i], i))[:keep]
    chosen = set()
    for i in order:
        chosen.update(j for j in (i - 1, i, i + 1) if 0 <= j < len(scores))
    return sorted(chosen)



@dataclass(frozen=True)
class LowFeatures:
    """The low-resolution image described once, at s = 1 (ALGORITHM.md step 1: I' at s = 1)."""

    image: np.ndarray = field(repr=False)  #: (H, W) float32
    described: Described = field(repr=False)


def describe_low(low: np.ndarray, config: Config, whitening) -> LowFeatures:
    level = Level(s=1.0, d=1.0, blur=0.0, image=low)
    return LowFeatures(low, _describe(level, detect_on_level(level, config.harris_low), config,
                                      whitening))


def _inside(view: View, kp: Keypoints, margin_px: float) -> Keypoints:
    """The keypoints of a simulated view that lie away from its empty corners."""
    if view.inside_distance is None or len(kp) == 0:
        return kp
    ok = keep_inside(view, kp.xy, margin_px * kp.s)
    return Keypoints(s=kp.s, xy=kp.xy[ok], response=kp.response[ok])


@dataclass(frozen=True)
class Probed:
    """A view of the high image detected at every scale and scored by the probe."""

    view: View = field(repr=False)
    #: per scale: (keypoints, descriptors of the probe points -- of all points without the
    #: probe --, the level when kept for the full pass or None)
    detected: Tuple = field(repr=False)
    usable: Tuple[int, ...]  #: scales with described points
    run: Tuple[int, ...]  #: scales to match in full
    score: float  #: the best probe score over the scales (inf when the probe is off)
    probing: bool


def _space(config: Config) -> dict:
    return dict(sigma=config.harris.sigma, min_level_sigma=config.harris.min_level_sigma,
                decimate=config.harris.decimate)


def _joined(head: Described, rest: Described, offset: int) -> Described:
    """The descriptors of keypoints [0, offset) and [offset, N) as one ``Described``."""
    return Described(s=head.s, xy=np.vstack([head.xy, rest.xy]),
                     index=np.concatenate([head.index, rest.index + offset]),
                     angle=np.concatenate([head.angle, rest.angle]),
                     desc=np.vstack([head.desc, rest.desc]))


def detect_view(view: View, config: Config, whitening,
                step: Callable[[], None] = lambda: None) -> Tuple[Tuple, bool]:
    """Detect every scale of one view and describe the probe's points: (detected, probing).

    ``step()`` is called once per scale detected. The levels of a view of at most
    ``KEEP_LEVELS_MAX_PX`` pixels are kept for the full pass.
    """
    scales = sorted(config.scales)
    probing = config.probe.enabled and len(scales) > config.probe.keep
    keep = view.image.size <= KEEP_LEVELS_MAX_PX
    detected = []
    for level in scale_space(view.image, scales, **_space(config)):
        if min(level.image.shape) < MIN_SIDE_PX // 2:
            detected.append((Keypoints.empty(level.s), None, None))
        else:
            kp = _inside(view, detect_on_level(level, config.harris), config.views.edge_margin_px)
            part = _part(kp, slice(config.probe.points)) if probing else kp
            detected.append((kp, _describe(level, part, config, whitening),
                             level if keep else None))
        step()
    return tuple(detected), probing


def score_view(view: View, detected: Tuple, probing: bool, low: LowFeatures,
               config: Config) -> Probed:
    """Score each scale of a detected view from its strongest points (paper 5)."""
    usable = [i for i, (kp, d, _) in enumerate(detected) if d is not None and len(d)]
    if probing:
        scores = probe_scores([detected[i][1] for i in usable], low.described, config)
        run = sorted(usable[j] for j in select_scales(scores, config.probe.keep))
        best = max(scores, default=0.0)
    else:
        run, best = usable, math.inf
    return Probed(view, detected, tuple(usable), tuple(run), best, probing)


def finish_view(probed: Probed, low: LowFeatures, config: Config, whitening,
                step: Callable[[], None] = lambda: None) -> List[ScaleOutcome]:
    """Match the probe's chosen scales of a view in full (steps 4-6); one outcome per scale.

    The probe's descriptors are kept: only the other points are described. ``step()`` is
    called once per scale matched or skipped.
    """
    scales = sorted(config.scales)
    detected, run = probed.detected, probed.run
    kept = all(detected[i][2] is not None for i in run)
    if kept:
        levels = ((i, detected[i][2]) for i in run)
    else:  # the detection's cascade again, up to the largest scale run (bounded memory)
        levels = ((i, level) for i, level in enumerate(scale_space(
            probed.view.image, scales[:run[-1] + 1], **_space(config))) if i in run)

    def one(item) -> ScaleOutcome:
        i, level = item
        kp, desc, _ = detected[i]
        if probed.probing and len(kp) > config.probe.points:  # the probe described the strongest
            rest = _describe(level, _part(kp, slice(config.probe.points, None)), config,
                             whitening)
            desc = _joined(desc, rest, config.probe.points)
        return _full_scale(level, kp, desc, low.described, low.image, config)

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
            row = ScaleRow(s=s_, ratio=float("nan"), points=len(detected[n][0]), initial=0,
                           kept=0, inliers=0, outlier_pct=100.0, skipped=n in probed.usable)
            outcomes.append(ScaleOutcome(row, None, np.zeros((0, 2)), np.zeros((0, 2)), 0))
        step()
    return outcomes


@dataclass(frozen=True)
class Attempt:
    """One search: a direction (which image is taken as the finer one) and a view of it."""

    swapped: bool  #: True: the second image given was found to be the coarser one
    view: View = field(repr=False)
    outcomes: Tuple[ScaleOutcome, ...] = field(repr=False)
    verdict: Decision = field(repr=False)


def _winning_outcome(attempt: Attempt) -> ScaleOutcome:
    """The outcome of the scale the decision chose."""
    return next(o for o in attempt.outcomes if o.row.s == attempt.verdict.best_scale)


def _refit_in_high(attempt: Attempt, config: Config) -> Tuple[np.ndarray, np.ndarray, str]:
    """(transform, inliers (N, 4), model) of a tilted view's match, in high-image pixels.

    The view's similarity composed with the view's compression is an affine map; it is refit
    on the inliers mapped back to the high image (an affine map, or a homography when that is
    the model asked for), so the answer is exact rather than limited to the sampled tilts.
    """
    v = attempt.verdict
    if attempt.view.is_identity:
        return v.transform, v.inliers, config.model
    src = to_high(attempt.view, v.inliers[:, :2])
    dst = v.inliers[:, 2:4]
    model = "homography" if config.model == "homography" else "affine"
    # every candidate of the winning scale, not only the view's similarity inliers: the sampled
    # tilt differs from the true one, so the similarity holds on part of the image only
    best = _winning_outcome(attempt)
    cand_src = to_high(attempt.view, best.src)
    est = estimate(model, cand_src, best.dst, config.ransac, seed=config.seed)
    if est.transform is not None and est.n_inliers >= len(src):
        return est.transform, np.hstack([cand_src[est.inliers], best.dst[est.inliers]]), model
    est = estimate(model, src, dst, config.ransac, seed=config.seed)
    if est.transform is None or est.n_inliers < MIN_SAMPLE[model] + 1:
        composed = compose(v.transform, attempt.view.to_view)
        return composed, np.hstack([src, dst]), "affine" if composed.shape == (2, 3) else model
    inl = est.inliers
    return est.transform, np.hstack([src[inl], dst[inl]]), model


def _richer_model(t: np.ndarray, inliers: np.ndarray, model: str, attempt: Attempt,
                  config: Config):
    """(transform, inliers, model): a richer model when the similarity explains too little.

    The candidates of the winning scale are refit with each of ``config.model_check.models``;
    the first whose inliers pass ``min_gain`` and ``min_extra`` over the similarity's, and
    whose transform does not fold the image over, is taken (see ``ModelCheckParams``).
    """
    check = config.model_check
    if not check.enabled or model != "similarity" or not attempt.view.is_identity:
        return t, inliers, model
    best = _winning_outcome(attempt)
    k = len(inliers)
    for richer in check.models:
        est = estimate(richer, best.src, best.dst, config.ransac, seed=config.seed)
        if est.transform is None or folded(est.transform):
            continue
        if est.n_inliers >= check.min_gain * k and est.n_inliers - k >= check.min_extra:
            inl = est.inliers
            return est.transform, np.hstack([best.src[inl], best.dst[inl]]), richer
    return t, inliers, model


def _pooled_refit(t: np.ndarray, inliers: np.ndarray, model: str, attempt: Attempt,
                  config: Config):
    """(transform, inliers): ``t`` refined on the candidates of every scale matched in full.

    The neighbouring scales of a true match find the same transform (the paper's Table 1) from
    other points; pooled, they spread the inliers wider over the image, which pins a homography
    or an affine map down where the winning scale alone had few points. Kept only when it
    explains at least as many pooled pairs as ``t``; the inliers reported stay those of the
    winning scale (the pairs the decision counted) that the refined transform still explains.
    """
    if not model_of(model).has_ratio:
        return t, inliers
    done = [o for o in attempt.outcomes if o.estimate is not None and len(o.src)]
    if len(done) < 2:
        return t, inliers
    src = to_high(attempt.view, np.vstack([o.src for o in done]))
    src, dst = distinct_pairs(src, np.vstack([o.dst for o in done]))
    before = int((residuals(model, t, src, dst) <= config.ransac.threshold_px).sum())
    est = refine(model, t, src, dst, config.ransac)
    if est.n_inliers < before or folded(est.transform):
        return t, inliers
    keep = residuals(model, est.transform, inliers[:, :2], inliers[:, 2:4]) <= \
        config.ransac.threshold_px
    return est.transform, inliers[keep]


def match(low: np.ndarray, high: np.ndarray, config: Config = Config(),
          progress: Optional[Callable[[int, int], None]] = None) -> MatchResult:
    """Match a low-resolution image against a high-resolution one of the same scene.

    The search runs progressively and stops at the first reliable match (MODS, Mishkin et al.
    2015): the given order (``low`` coarser than ``high``) on the image itself; then, with
    ``config.order == "auto"``, the other order; then each pass of simulated tilted views of
    the finer image (``config.views``), in both orders. The a-contrario test counts every search
    made, so trying more cannot make a chance transform look reliable.

    An image longer than its working size (``config.low_max_side``, ``config.high_max_side``)
    is matched shrunk and the answer given in its own pixels (:mod:`scalematch.working`).
    Independent pieces of work run on as many threads as OpenCV uses
    (:mod:`scalematch.stages.threads`); the answer does not depend on them.

    Parameters
    ----------
    low, high : (H, W) arrays
        Grey images in 8-bit grey levels (see :func:`scalematch.read_grey`), or floats in
        [0, 1] (scaled by 255); ``ValueError`` for bool, NaN or constant arrays.
    config : Config
        Every parameter; recorded in the result.
    progress : callable, optional
        ``progress(done, total)`` after each scale detected or matched; ``total`` grows when
        the search goes on to the other order or to tilted views.

    Returns
    -------
    MatchResult
        ``matched`` False with a ``reason`` when the evidence is too weak: a wrong transform
        reported as a match is the worst outcome, so the decision errs on the side of no.
        ``order`` says whether the images were found in the order given; ``transform`` always
        maps the finer image's pixels to the coarser image's.
    """
    f_low = working_factor(np.shape(low), config.low_max_side)
    # a shrunk high image can become the coarser one: only the automatic order finds it then
    f_high = working_factor(np.shape(high), config.high_max_side) \
        if config.order == "auto" else 1.0
    if f_low > 1.0 or f_high > 1.0:  # very large images: matched at their working size
        low_w = shrink(as_float_image(low), f_low) if f_low > 1.0 else low
        high_w = shrink(as_float_image(high), f_high) if f_high > 1.0 else high
        inner = replace(config, low_max_side=None, high_max_side=None)
        found = _search(low_w, high_w, inner, direction_scales(config.scales, f_low, f_high),
                        progress)
        return in_original(found, f_low, f_high, config)
    return _search(low, high, config, {False: config.scales, True: config.scales}, progress)


def _search(low: np.ndarray, high: np.ndarray, config: Config,
            scales: Dict[bool, Tuple[float, ...]],
            progress: Optional[Callable[[int, int], None]]) -> MatchResult:
    """:func:`match` on images of their working size; ``scales[swapped]``: each direction's."""
    t0 = time.perf_counter()
    # ValueError: bool, NaN, constant, or a side under MIN_SIDE_PX
    low = as_float_image(grey_levels(low, "low"))
    high = as_float_image(grey_levels(high, "high"))
    cov = load_covariance(config.covariance_path) if config.mode == "paper" else None
    config = replace(config, covariance_used=cov.source) if cov is not None else config
    whitening = cov.whitening() if cov is not None else None
    images = {False: (low, high), True: (high, low)}
    # a direction may have no scale of its own at working size (direction_scales)
    directions = tuple(d for d in ((False, True) if config.order == "auto" else (False,))
                       if scales[d])
    plain = [[(1.0, 0.0)]]
    passes = plain + (view_plan(config.views) if model_of(config.model).has_ratio else [])
    configs = {d: replace(config, scales=tuple(scales[d])) for d in directions}
    feats = {}
    count = {"done": 0, "total": 0}

    def step() -> None:
        count["done"] += 1
        if progress is not None:
            progress(count["done"], count["total"])

    attempts: List[Attempt] = []
    searches = 0  # every view probed counts: the best ones are chosen among them all
    winner: Optional[Attempt] = None
    matches: List[Attempt] = []  # every reliable match found so far

    def strength(a: Attempt) -> float:
        return a.verdict.evidence["log10_nfa"]

    for k, views in enumerate(passes):
        found: List[Attempt] = []
        for swapped in directions:
            lo_img, hi_img = images[swapped]
            cfg = configs[swapped]
            per_search = 2 * len(cfg.scales)  # progress steps: detect + match each scale
            count["total"] += len(views) * per_search // 2
            probed = []
            for v in views_of(hi_img, views, config.views):
                if swapped in feats:
                    found_view = detect_view(v, cfg, whitening, step)
                else:  # the coarser image is described while the first view is detected
                    feats[swapped], found_view = thread_map(lambda job: job(), [
                        lambda: describe_low(lo_img, config, whitening),
                        lambda: detect_view(v, cfg, whitening, step)])
                probed.append(score_view(v, *found_view, feats[swapped], cfg))
            searches += len(probed)
            chosen = sorted(probed, key=lambda p: -p.score)
            if k > 0:  # a pass of simulated views (pass 0 is the image itself)
                chosen = [p for p in chosen[:config.views.full_searches]
                          if p.score >= config.views.min_probe_score]
            count["total"] += len(chosen) * per_search // 2
            for p in chosen:
                outcomes = tuple(finish_view(p, feats[swapped], cfg, whitening, step))
                verdict = decide(outcomes, lo_img.shape, p.view.image.shape, cfg,
                                 searches=searches)
                attempt = Attempt(swapped, p.view, outcomes, verdict)
                attempts.append(attempt)
                if verdict.matched:
                    found.append(attempt)
                    if verdict.evidence["log10_nfa"] <= config.decision.max_log_nfa_alone:
                        break  # overwhelming: no other view of this pass can do better
            if found:
                break
        matches += found
        if matches:
            best = min(matches, key=strength)
            # a plain match on a handful of inliers can be a repeated structure seen through a
            # viewpoint change: the first pass of views gets to show a stronger answer
            weak = best.verdict.evidence["inliers"] < config.views.confirm_below_inliers
            if not (weak and k == 0 and len(passes) > 1):
                winner = best
                break
    if winner is None and matches:
        winner = min(matches, key=strength)
    timings = {"total": time.perf_counter() - t0}
    if winner is None:
        first = attempts[0]
        tried = searches
        more = f" ({tried} searches: both orders, tilted views)" if tried > 1 else ""
        return MatchResult(matched=False, reason=first.verdict.reason + more, model=config.model,
                           transform=None, resolution_ratio=float("nan"),
                           rotation_deg=float("nan"), translation=(float("nan"), float("nan")),
                           best_scale=first.verdict.best_scale, inliers=np.zeros((0, 4)),
                           scales=tuple(o.row for o in first.outcomes), timings=timings,
                           config=config, evidence=dict(
                               first.verdict.evidence, searches=tried,
                               search_order="swapped" if first.swapped else "given"),
                           order="given")
    t, inliers, model = _refit_in_high(winner, config)
    t, inliers, model = _richer_model(t, inliers, model, winner, config)
    t, inliers = _pooled_refit(t, inliers, model, winner, config)
    t, inliers, swapped = finer_to_coarser(t, inliers, winner.swapped,
                                           model_of(model).has_ratio)
    evidence = dict(winner.verdict.evidence, searches=searches,
                    search_order="swapped" if winner.swapped else "given",
                    view_tilt=winner.view.tilt, view_longitude_deg=winner.view.longitude_deg)
    if not model_of(model).has_ratio:
        ratio, angle, tr = float("nan"), float("nan"), (float("nan"), float("nan"))
    else:
        ratio, angle, tr = similarity_parts(t)
    return MatchResult(matched=True, reason="", model=model, transform=t,
                       resolution_ratio=ratio, rotation_deg=angle, translation=tr,
                       best_scale=winner.verdict.best_scale, inliers=inliers,
                       scales=tuple(o.row for o in winner.outcomes), timings=timings,
                       config=config, evidence=evidence,
                       order="swapped" if swapped else "given")
