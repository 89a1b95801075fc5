"""The one-to-many matcher: every scale of the high image against the low image (paper 4.2, 5).

``match(low, high, config)`` runs, for each scale s of the high-resolution image: detection
(scale-adapted Harris), description, candidate matching against the low image's points (found
once, at s = 1), geometric constraints, and robust estimation; the scale with the most inliers
wins (ALGORITHM.md step 7) and :mod:`scalematch.stages.decision` says whether the evidence is enough.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Callable, List, Optional

import numpy as np

from .config import Config
from .geometry import similarity_parts
from .result import MatchResult, ScaleRow
from .stages.constraints import orientation_groups, semi_local_filter
from .stages.decision import Decision, decide
from .stages.descriptors import Described, describe_gradients, describe_jets
from .stages.detector import Keypoints, detect_on_level
from .stages.estimator import Estimate, estimate
from .stages.mahalanobis import load_covariance, whiten
from .stages.matcher import match_descriptors
from .stages.scalespace import Level, as_float_image, scale_space

#: Smallest image side the matcher accepts, px: below it the 16 px descriptor window and the
#: Harris filters (4 sigma~ = 8 px) see mostly border.
MIN_SIDE_PX = 24


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
            src = high.xy[cand.i[mask]]
            dst = low.xy[cand.j[mask]]
            est = estimate(config.model, src, dst, config.ransac, seed=config.seed)
            if best is None or est.n_inliers > best.n_inliers:
                best, best_src, best_dst, kept = est, src, dst, int(mask.sum())
    n_in = best.n_inliers if best is not None and best.transform is not None else 0
    ratio = angle = float("nan")
    if n_in and config.model != "fundamental":
        ratio, angle, _ = similarity_parts(best.transform)
    initial = len(cand)
    row = ScaleRow(s=s, ratio=ratio, points=len(kp), initial=initial, kept=kept,
                   inliers=n_in, outlier_pct=100.0 * (1 - n_in / initial) if initial else 100.0,
                   rotation_deg=angle)
    return ScaleOutcome(row, best, best_src, best_dst, initial)


def _head(kp: Keypoints, n: int) -> Keypoints:
    """The ``n`` strongest keypoints (they are sorted strongest first)."""
    return Keypoints(s=kp.s, xy=kp.xy[:n], response=kp.response[:n])


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


def log10_binomial_tail(n: int, k: int, p: float) -> float:
    """log10 P(X >= k) for X ~ Binomial(n, p)."""
    if k <= 0:
        return 0.0
    if k > n:
        return -math.inf
    logs = [math.lgamma(n + 1) - math.lgamma(i + 1) - math.lgamma(n - i + 1)
            + i * math.log(p) + (n - i) * math.log1p(-p) for i in range(k, n + 1)]
    top = max(logs)
    return (top + math.log(sum(math.exp(v - top) for v in logs))) / math.log(10)


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


def match(low: np.ndarray, high: np.ndarray, config: Config = Config(),
          progress: Optional[Callable[[int, int], None]] = None) -> MatchResult:
    """Match a low-resolution image against a high-resolution one of the same scene.

    Parameters
    ----------
    low, high : (H, W) arrays
        Grey images in 8-bit grey levels (see :func:`scalematch.read_grey`).
    config : Config
        Every parameter; recorded in the result.
    progress : callable, optional
        ``progress(done, total)`` after each scale.

    Returns
    -------
    MatchResult
        ``matched`` False with a ``reason`` when the evidence is too weak: a wrong transform
        reported as a match is the worst outcome, so the decision errs on the side of no.
    """
    t0 = time.perf_counter()
    timings = {}
    low = as_float_image(low)
    high = as_float_image(high)
    _check_images(low, high)
    whitening = load_covariance(config.covariance_path).whitening() if config.mode == "paper" else None

    low_level = Level(s=1.0, d=1.0, blur=0.0, image=low)
    low_kp = detect_on_level(low_level, config.harris_low)
    low_desc = _describe(low_level, low_kp, config, whitening)
    timings["low_image"] = time.perf_counter() - t0

    t1 = time.perf_counter()
    scales = sorted(config.scales)
    total = 2 * len(scales)  # progress: probing each scale, then matching it
    space = dict(sigma=config.harris.sigma, min_level_sigma=config.harris.min_level_sigma,
                 decimate=config.harris.decimate)
    probing = config.probe.enabled and len(scales) > config.probe.keep
    detected = []  # (keypoints, descriptors of the probe points or all) per scale
    for n, level in enumerate(scale_space(high, scales, **space)):
        if min(level.image.shape) < MIN_SIDE_PX // 2:
            detected.append((Keypoints.empty(level.s), None))
        else:
            kp = detect_on_level(level, config.harris)
            part = _head(kp, config.probe.points) if probing else kp
            detected.append((kp, _describe(level, part, config, whitening)))
        if progress is not None:
            progress(n + 1, total)
    timings["high_image"] = time.perf_counter() - t1

    t2 = time.perf_counter()
    usable = [i for i, (kp, d) in enumerate(detected) if d is not None and len(d)]
    if probing:
        scores = [probe_score(detected[i][1], low_desc, config) for i in usable]
        run = sorted(usable[j] for j in select_scales(scores, config.probe.keep))
    else:
        run = usable
    full = {}
    # the selected scales are described in full (their levels computed again: holding every
    # level of a large high image in memory would cost several full-resolution copies)
    for i, level in zip(run, scale_space(high, [scales[i] for i in run], **space)):
        kp = detected[i][0]
        desc = _describe(level, kp, config, whitening) if probing else detected[i][1]
        full[i] = _full_scale(level, kp, desc, low_desc, low, config)
    outcomes: List[ScaleOutcome] = []
    for n, s in enumerate(scales):
        if n in full:
            outcomes.append(full[n])
        else:
            # skipped: the probe judged it hopeless (not: too small, or no points at all)
            row = ScaleRow(s=s, ratio=float("nan"), points=len(detected[n][0]), initial=0, kept=0,
                           inliers=0, outlier_pct=100.0, skipped=n in usable)
            outcomes.append(ScaleOutcome(row, None, np.zeros((0, 2)), np.zeros((0, 2)), 0))
        if progress is not None:
            progress(len(scales) + n + 1, total)
    timings["matching"] = time.perf_counter() - t2

    t3 = time.perf_counter()
    verdict: Decision = decide(outcomes, low.shape, high.shape, config)
    timings["decision"] = time.perf_counter() - t3
    timings["total"] = time.perf_counter() - t0
    rows = tuple(o.row for o in outcomes)
    if not verdict.matched:
        return MatchResult(matched=False, reason=verdict.reason, model=config.model, transform=None,
                           resolution_ratio=float("nan"), rotation_deg=float("nan"),
                           translation=(float("nan"), float("nan")),
                           best_scale=verdict.best_scale, inliers=np.zeros((0, 4)), scales=rows,
                           timings=timings, config=config, evidence=verdict.evidence)
    t = verdict.transform
    if config.model == "fundamental":
        ratio, angle, tr = float("nan"), float("nan"), (float("nan"), float("nan"))
    else:
        ratio, angle, tr = similarity_parts(t)
    return MatchResult(matched=True, reason="", model=config.model, transform=t,
                       resolution_ratio=ratio, rotation_deg=angle, translation=tr,
                       best_scale=verdict.best_scale, inliers=verdict.inliers, scales=rows,
                       timings=timings, config=config, evidence=verdict.evidence)
