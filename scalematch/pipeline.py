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
from typing import Callable, List, Optional, Tuple

import numpy as np

from .config import Config
from .geometry import compose, similarity_parts
from .result import MatchResult, ScaleRow
from .stages.constraints import orientation_groups, semi_local_filter
from .stages.decision import Decision, decide
from .stages.descriptors import Described, describe_gradients, describe_jets
from .stages.detector import Keypoints, detect_on_level
from .stages.estimator import MIN_SAMPLE, Estimate, estimate
from .stages.mahalanobis import load_covariance, whiten
from .stages.matcher import match_descriptors
from .stages.scalespace import Level, as_float_image, scale_space
from .stages.views import View, keep_inside, to_high, view_plan, views_of
from .working import in_original_low, shrink, working_factor, working_scales

#: Smallest image side the matcher accepts, px: below it the 16 px descriptor window and the
#: Harris filters (4 sigma~ = 8 px) see mostly border.
MIN_SIDE_PX = 24
#: Largest high image, px, whose scale-space levels are kept from detection to the full pass
#: (about 2.7 image copies of float32 over third-octave scales: 43 MB at 4 MP); a larger
#: image's levels are computed again, so peak memory stays bounded for camera-size images.
#: The result is the same either way.
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
    if n_in and config.model != "fundamental":
        ratio, angle, _ = similarity_parts(best.transform)
    initial = len(distinct_pairs(high.xy[cand.i], low.xy[cand.j])[0])
    row = ScaleRow(s=s, ratio=ratio, points=len(kp), initial=initial, kept=kept,
                   inliers=n_in, outlier_pct=100.0 * (1 - n_in / initial) if initial else 100.0,
                   rotation_deg=angle)
    return ScaleOutcome(row, best, best_src, best_dst, initial)


def _part(kp: Keypoints, rows: slice) -> Keypoints:
    """Some of the keypoints: ``slice(n)`` the ``n`` strongest (they are sorted strongest first)."""
    return Keypoints(s=kp.s, xy=kp.xy[rows], response=kp.response[rows])


def probe_score(high: Described, low: Described, config: Config) -> float:
    """How promising a scale looks from the initial matches of its strongest points alone.

    The paper (section 5) notes that the initial matches already point at the best scale.
    ``high`` holds the ``ProbeParams.points`` strongest points of the scale. In the paper mode
    the score is their number of candidate matches. In the default mode it is the number of
    inliers of a quick similarity fit to the candidates in the dominant rotation peak, counted
    only when the fit's ratio agrees with the scale: rotation alone cannot rank scales where
    the scene's edges share a few directions (facades), geometry can.
    """
    cand = match_descriptors(high.desc, low.desc, config.matcher)
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



def _check_images(low: np.ndarray, high: np.ndarray) -> None:
    for name, img in (("low", low), ("high", high)):
        if min(img.shape) < MIN_SIDE_PX:
            raise ValueError(f"the {name}-resolution image is {img.shape[1]}x{img.shape[0]} px; "
                             f"at least {MIN_SIDE_PX} px on each side is needed")


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


def _joined(head: Described, rest: Described, offset: int) -> Described:
    """The descriptors of keypoints [0, offset) and [offset, N) as one ``Described``."""
    return Described(s=head.s, xy=np.vstack([head.xy, rest.xy]),
                     index=np.concatenate([head.index, rest.index + offset]),
                     angle=np.concatenate([head.angle, rest.angle]),
                     desc=np.vstack([head.desc, rest.desc]))


def search_scales(view: View, low: LowFeatures, config: Config, whitening,
                  step: Callable[[], None] = lambda: None) -> List[ScaleOutcome]:
    """Steps 1-6 at every scale of one view of the high image (the paper's one-to-many search).

    With the probe on, every scale is detected and scored from its strongest points, and only
    the best scales and their neighbours are matched in full. ``step()`` is called once per
    scale detected and once per scale matched (or skipped).

    The levels of a high image of at most ``KEEP_LEVELS_MAX_PX`` pixels are kept for the full
    pass (with the probe's descriptors: only the other points are described then); a larger
    image's levels are computed again, by the same cascade, so the two paths give the same
    result and memory holds two levels at a time.
    """
    high = view.image
    scales = sorted(config.scales)
    space = dict(sigma=config.harris.sigma, min_level_sigma=config.harris.min_level_sigma,
                 decimate=config.harris.decimate)
    probing = config.probe.enabled and len(scales) > config.probe.keep
    keep = high.size <= KEEP_LEVELS_MAX_PX
    detected = []  # (keypoints, descriptors of the probe points or all, level if kept) per scale
    for level in scale_space(high, scales, **space):
        if min(level.image.shape) < MIN_SIDE_PX // 2:
            detected.append((Keypoints.empty(level.s), None, None))
        else:
            kp = _inside(view, detect_on_level(level, config.harris), config.views.edge_margin_px)
            part = _part(kp, slice(config.probe.points)) if probing else kp
            detected.append((kp, _describe(level, part, config, whitening),
                             level if keep else None))
        step()
    usable = [i for i, (kp, d, _) in enumerate(detected) if d is not None and len(d)]
    if probing:
        scores = [probe_score(detected[i][1], low.described, config) for i in usable]
        run = sorted(usable[j] for j in select_scales(scores, config.probe.keep))
    else:
        run = usable
    if keep or not run:
        levels = ((i, detected[i][2]) for i in run)
    else:  # the detection's cascade again, up to the largest scale run
        levels = ((i, level) for i, level in enumerate(scale_space(
            high, scales[:run[-1] + 1], **space)) if i in run)
    full = {}
    for i, level in levels:
        kp, desc, _ = detected[i]
        if probing and len(kp) > config.probe.points:  # the probe described the strongest
            rest = _describe(level, _part(kp, slice(config.probe.points, None)), config,
                             whitening)
            desc = _joined(desc, rest, config.probe.points)
        full[i] = _full_scale(level, kp, desc, low.described, low.image, config)
    outcomes: List[ScaleOutcome] = []
    for n, s in enumerate(scales):
        if n in full:
            outcomes.append(full[n])
        else:
            # skipped: the probe judged it hopeless (not: too small, or no points at all)
            row = ScaleRow(s=s, ratio=float("nan"), points=len(detected[n][0]), initial=0, kept=0,
                           inliers=0, outlier_pct=100.0, skipped=n in usable)
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
    best = next(o for o in attempt.outcomes if o.row.s == v.best_scale)
    est = estimate(model, to_high(attempt.view, best.src), best.dst, config.ransac,
                   seed=config.seed)
    if est.transform is not None and est.n_inliers >= len(src):
        return est.transform, np.hstack([to_high(attempt.view, best.src)[est.inliers],
                                         best.dst[est.inliers]]), model
    est = estimate(model, src, dst, config.ransac, seed=config.seed)
    if est.transform is None or est.n_inliers < MIN_SAMPLE[model] + 1:
        composed = compose(v.transform, attempt.view.to_view) if v.transform.shape == (2, 3) \
            else v.transform @ np.vstack([attempt.view.to_view, [0.0, 0.0, 1.0]])
        return composed, np.hstack([src, dst]), "affine" if composed.shape == (2, 3) else model
    inl = est.inliers
    return est.transform, np.hstack([src[inl], dst[inl]]), model


def _as_finer_to_coarser(t: np.ndarray, inliers: np.ndarray, swapped: bool, model: str):
    """Flip a match whose transform implies a ratio below 1 (the 'high' image is the coarser)."""
    ratio = similarity_parts(t)[0]
    if model == "fundamental" or not (math.isfinite(ratio) and ratio < 1.0):
        return t, inliers, swapped
    t3 = np.vstack([t, [0.0, 0.0, 1.0]]) if t.shape == (2, 3) else t
    inv = np.linalg.inv(t3)
    inv = inv[:2] if t.shape == (2, 3) else inv / inv[2, 2]
    return inv, inliers[:, [2, 3, 0, 1]], not swapped


def match(low: np.ndarray, high: np.ndarray, config: Config = Config(),
          progress: Optional[Callable[[int, int], None]] = None) -> MatchResult:
    """Match a low-resolution image against a high-resolution one of the same scene.

    The search runs progressively and stops at the first reliable match (MODS, Mishkin et al.
    2015): the given order (``low`` coarser than ``high``) on the image itself; then, with
    ``config.order == "auto"``, the other order; then each pass of simulated tilted views of
    the finer image (``config.views``), in both orders. The a-contrario test counts every search
    made, so trying more cannot make a chance transform look reliable.

    Parameters
    ----------
    low, high : (H, W) arrays
        Grey images in 8-bit grey levels (see :func:`scalematch.read_grey`).
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
    f = working_factor(np.shape(low), config.low_max_side)
    if f > 1.0:  # a very large low image: matched at its working size, answered in its pixels
        small = replace(config, low_max_side=None, scales=working_scales(config.scales, f))
        return in_original_low(match(shrink(as_float_image(low), f), high, small, progress),
                               f, config)
    t0 = time.perf_counter()
    low = as_float_image(low)
    high = as_float_image(high)
    _check_images(low, high)
    whitening = load_covariance(config.covariance_path).whitening() if config.mode == "paper" else None
    images = {False: (low, high), True: (high, low)}
    directions = (False, True) if config.order == "auto" else (False,)
    plain = [[(1.0, 0.0)]]
    passes = plain + (view_plan(config.views) if config.model != "fundamental" else [])
    per_search = 2 * len(config.scales)
    feats = {}
    count = {"done": 0, "total": per_search}

    def step() -> None:
        count["done"] += 1
        if progress is not None:
            progress(count["done"], count["total"])

    attempts: List[Attempt] = []
    winner: Optional[Attempt] = None
    for views in passes:
        found: List[Attempt] = []
        for swapped in directions:
            lo_img, hi_img = images[swapped]
            if swapped not in feats:
                feats[swapped] = describe_low(lo_img, config, whitening)
            for view in views_of(hi_img, views, config.views):
                if attempts:
                    count["total"] += per_search
                outcomes = tuple(search_scales(view, feats[swapped], config, whitening, step))
                verdict = decide(outcomes, lo_img.shape, view.image.shape, config,
                                 searches=len(attempts) + 1)
                attempt = Attempt(swapped, view, outcomes, verdict)
                attempts.append(attempt)
                if verdict.matched:
                    found.append(attempt)
                    if verdict.evidence["log10_nfa"] <= config.decision.max_log_nfa_alone:
                        break  # overwhelming: no other view of this pass can do better
            if found:
                break
        if found:
            winner = max(found, key=lambda a: a.verdict.evidence["inliers"])
            break
    timings = {"total": time.perf_counter() - t0}
    if winner is None:
        first = attempts[0]
        tried = len(attempts)
        more = f" ({tried} searches: both orders, tilted views)" if tried > 1 else ""
        return MatchResult(matched=False, reason=first.verdict.reason + more, model=config.model,
                           transform=None, resolution_ratio=float("nan"),
                           rotation_deg=float("nan"), translation=(float("nan"), float("nan")),
                           best_scale=first.verdict.best_scale, inliers=np.zeros((0, 4)),
                           scales=tuple(o.row for o in first.outcomes), timings=timings,
                           config=config, evidence=dict(first.verdict.evidence, searches=tried),
                           order="given")
    t, inliers, model = _refit_in_high(winner, config)
    t, inliers, swapped = _as_finer_to_coarser(t, inliers, winner.swapped, model)
    evidence = dict(winner.verdict.evidence, searches=len(attempts),
                    view_tilt=winner.view.tilt, view_longitude_deg=winner.view.longitude_deg)
    if model == "fundamental":
        ratio, angle, tr = float("nan"), float("nan"), (float("nan"), float("nan"))
    else:
        ratio, angle, tr = similarity_parts(t)
    return MatchResult(matched=True, reason="", model=model, transform=t,
                       resolution_ratio=ratio, rotation_deg=angle, translation=tr,
                       best_scale=winner.verdict.best_scale, inliers=inliers,
                       scales=tuple(o.row for o in winner.outcomes), timings=timings,
                       config=config, evidence=evidence,
                       order="swapped" if swapped else "given")
