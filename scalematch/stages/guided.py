"""Guided growth of a hypothesis (paper section 4.2, "establish many other matches").

Given a transform found at one scale (finer px -> coarser px: here ``high`` is the finer image
and ``low`` the coarser), every high point of that scale is mapped into the low image; the low
point with the nearest *compatible* descriptor within a radius of the prediction becomes its
match; the model is refitted on the matches it explains
(:func:`scalematch.stages.estimator.refine`), and the round is repeated with the refitted
transform while the number of inliers grows (at most ``GuidedParams.max_rounds`` rounds).

Compatible (``GuidedParams``): descriptor distance at most ``max_distance``; in the default
mode (points with an orientation) the orientation in the low image minus that in the high
image within ``angle_tolerance_deg`` of the hypothesis' rotation. Jets (``angle`` nan) skip the
orientation test. Each low point is used once (the nearest in descriptor wins), and a keypoint
described twice (two dominant orientations) counts once.

A right hypothesis of a few inliers grows to many; a wrong one only gathers what chance puts
near its predictions: ``Growth.chance`` is the number of such chance matches to expect, from
the density of low points near the predictions and the fraction of descriptor- and
orientation-compatible pairs (an estimate, for comparison with ``Growth.n_inliers``).

Pixel convention: OpenCV's, (x, y), pixel centres at integers. Used by the decision's second
look (:func:`scalematch.stages.secondlook.look_again`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, ClassVar, List, Mapping, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from ..checks import ANGLE, AT_LEAST_ONE, Bounds, COUNT, POSITIVE, check_bounds
from ..geometry import apply, pairs_within, similarity_parts
from .descriptors import Described
from .estimator import RansacParams, map_model, refine
from .matcher import distinct_pairs


@dataclass(frozen=True)
class GuidedParams:
    """Guided growth; lengths in low-resolution px."""

    #: search radius around a predicted position, low px: the estimator's inlier threshold
    #: (RansacParams.threshold_px = 3) plus 1 px for the error of a hypothesis fitted on few
    #: points, which the first refit removes
    radius_px: float = 4.0
    #: largest descriptor distance of a guided match (Euclidean, descriptor units). Default mode
    #: (RootSIFT-like, unit norm), measured at s = 8 on ratio-8 pairs of 10 shared photos
    #: (seed 1): of high points within 1.5 px of a low point at their true position, 68 % are
    #: within 0.55 (median 0.30); of random pairs, 2.4 % (median 0.81). 0.7 kept 78 % of the
    #: former but 18 % of the latter: 0-2 more inliers grown, three times the chance matches.
    max_distance: float = 0.55
    #: largest difference between a match's orientation change and the hypothesis' rotation,
    #: degrees (OrientationParams.tolerance_deg = 20: true matches' error ~5-10)
    angle_tolerance_deg: float = 20.0
    #: False: descriptor distance only (the paper mode: its jets carry no orientation, and its
    #: preset sets this False)
    use_orientation: bool = True
    #: refit inlier threshold, low px; None: the robust fit's own (``RansacParams.threshold_px``)
    threshold_px: Optional[float] = None
    max_rounds: int = 5  #: guided rounds at most (each: match, refit, recount)
    #: an accepted answer is grown (``answer.grown_answer``) when it has fewer inliers than
    #: this: there its map is loose away from them. On the Oxford and perspective pairs (lab
    #: real-pairs, both orders) the answers under 30 inliers were 0.82 px off (median), 0.52
    #: once grown (graf 1->5 0.97 -> 0.28 px; a perspective facade 4.9 px off as a similarity,
    #: 0.49 as the homography its growth showed); no pair was lost (docs/results/BENCHMARKS.md)
    grow_below_inliers: int = 30
    #: high points sampled (evenly, no randomness) to estimate the fraction of compatible pairs
    #: behind ``Growth.chance`` (:func:`chance_matches`) ...
    chance_sample_high: int = 256
    #: ... and low points of the region: their pairs with the high sample estimate the fraction
    #: (a mean: the full 256 x 12,000 table, 1.5 GB at 128 dimensions, is not needed to know it)
    chance_sample_low: int = 2048

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "radius_px": POSITIVE,
        "max_distance": POSITIVE,
        "threshold_px": Bounds(lo=0, lo_open=True, optional=True),
        "grow_below_inliers": COUNT,
        "angle_tolerance_deg": ANGLE,
        "max_rounds": AT_LEAST_ONE,
        "chance_sample_high": AT_LEAST_ONE,
        "chance_sample_low": AT_LEAST_ONE,
    }

    def __post_init__(self) -> None:
        check_bounds("guided", self, self.BOUNDS)


@dataclass(frozen=True)
class Growth:
    """What guided growth made of a hypothesis."""

    model: str
    transform: np.ndarray = field(repr=False)  #: (2, 3) or (3, 3) finer px -> coarser px, final
    inliers: np.ndarray = field(repr=False)  #: (N, 4) float64: x, y in high px, x, y in low px
    rounds: int  #: guided rounds run (0 when the hypothesis found no match at all)
    counts: Tuple[int, ...]  #: distinct inliers after each round
    chance: float  #: inliers to expect by chance alone around these predictions (estimate)

    @property
    def n_inliers(self) -> int:
        return int(self.inliers.shape[0])


def _rotation(t: np.ndarray) -> float:
    """Rotation of a 2x3 / 3x3 transform, radians (a homography: its linear part's)."""
    return math.radians(similarity_parts(t)[1])


def _angle_ok(high: Described, low: Described, i: np.ndarray, j: np.ndarray, rot: float,
              params: GuidedParams) -> np.ndarray:
    """Orientation test for pairs (i, j): all True when orientations are not in use."""
    if not params.use_orientation:
        return np.ones(i.shape[0], bool)
    d = low.angle[j] - high.angle[i] - rot
    ok = np.abs(np.angle(np.exp(1j * d))) <= math.radians(params.angle_tolerance_deg)
    return ok | ~np.isfinite(d)  # jets: no orientation, no test


def guided_matches(t: np.ndarray, high: Described, low: Described,
                   params: GuidedParams = GuidedParams()) -> Tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """One guided round: for each high point, the nearest compatible low point near T(x).

    Parameters
    ----------
    t : (2, 3) or (3, 3) array
        Hypothesis, finer px -> coarser px (``high``'s to ``low``'s).
    high : Described
        Points of the high image at the hypothesis' scale (``xy`` in high px).
    low : Described
        Points of the low image (s = 1, ``xy`` in low px).
    params : GuidedParams

    Returns
    -------
    i, j : (K,) int arrays
        Rows of ``high`` and ``low`` matched, one to one.
    distance : (K,) float32 array
        Their descriptor distances.
    """
    empty = (np.zeros(0, int), np.zeros(0, int), np.zeros(0, np.float32))
    if len(high) == 0 or len(low) == 0:
        return empty
    pred = apply(t, high.xy)
    ok = np.all(np.isfinite(pred), axis=1)
    r = float(params.radius_px)
    lo = pred[ok].min(axis=0) - r if ok.any() else np.zeros(2)
    hi = pred[ok].max(axis=0) + r if ok.any() else np.zeros(2)
    near = np.nonzero(np.all((low.xy >= lo) & (low.xy <= hi), axis=1))[0]
    rows = np.nonzero(ok)[0]
    if near.size == 0 or rows.size == 0:
        return empty
    rot = _rotation(t)
    a, b = pairs_within(pred[rows], low.xy[near], r)  # by high row, then low row
    i, j = rows[a], near[b]
    keep = _angle_ok(high, low, i, j, rot, params)
    i, j = i[keep], j[keep]
    dist = np.linalg.norm(np.asarray(high.desc, np.float32)[i]
                          - np.asarray(low.desc, np.float32)[j], axis=1)
    keep = dist <= params.max_distance
    i, j, dist = i[keep], j[keep], dist[keep]
    i, j, dist = _nearest_each(i, dist, j)  # each high point's nearest low point
    # one to one: a low point goes to the high point nearest to it in descriptor
    j, i, dist = _nearest_each(j, dist, i)
    return i, j, dist.astype(np.float32)


def _nearest_each(key: np.ndarray, dist: np.ndarray, other: np.ndarray):
    """(key, other, dist) of the pair of smallest ``dist`` for each value of ``key`` (the first
    of ties in the order given), sorted by ``key``.

    >>> k, o, d = _nearest_each(np.array([2, 1, 2]), np.array([0.5, 0.3, 0.1]), np.array([7, 8, 9]))
    >>> k.tolist(), o.tolist(), d.tolist()
    ([1, 2], [8, 9], [0.3, 0.1])
    """
    order = np.lexsort((dist, key))
    key, other, dist = key[order], other[order], dist[order]
    first = np.ones(key.size, bool)
    first[1:] = key[1:] != key[:-1]
    return key[first], other[first], dist[first]


def chance_matches(t: np.ndarray, high: Described, low: Described,
                   params: GuidedParams = GuidedParams()) -> float:
    """Guided matches to expect by chance around the predictions of ``t`` (an estimate).

    For a high point predicted inside the region the predictions span, a compatible low point
    falls within ``radius_px`` with probability ``1 - exp(-rho f pi r^2)``: ``rho`` the density
    of low points in that region (points per low px^2), ``f`` the fraction of (high, low) pairs
    that pass the descriptor and orientation tests (measured on an even sample of
    ``chance_sample_high`` high points against the low points of the region). Low points cluster in
    textured parts, so the figure is a guide, not a bound.
    """
    if len(high) == 0 or len(low) == 0:
        return 0.0
    pred = apply(t, high.xy)
    ok = np.all(np.isfinite(pred), axis=1)
    if not ok.any():
        return 0.0
    lo, hi = pred[ok].min(axis=0), pred[ok].max(axis=0)
    near = np.nonzero(np.all((low.xy >= lo) & (low.xy <= hi), axis=1))[0]
    area = float(np.prod(np.maximum(hi - lo, 1.0)))
    inside = int(np.count_nonzero(np.all((pred >= low.xy.min(axis=0))
                                         & (pred <= low.xy.max(axis=0)), axis=1)))
    if near.size == 0 or inside == 0:
        return 0.0
    rows = np.nonzero(ok)[0]
    sample = rows[np.linspace(0, rows.size - 1, min(params.chance_sample_high, rows.size)).astype(int)]
    cols = near[np.linspace(0, near.size - 1, min(params.chance_sample_low, near.size)).astype(int)]
    a = high.desc[sample].astype(np.float32)
    b = low.desc[cols].astype(np.float32)
    d2 = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * (a @ b.T)
    close = d2 <= params.max_distance ** 2
    i = np.repeat(sample, cols.size)
    j = np.tile(cols, sample.size)
    good = _angle_ok(high, low, i, j, _rotation(t), params).reshape(close.shape)
    f = float(np.mean(good & close))
    rho = near.size / area
    return inside * (1.0 - math.exp(-rho * f * math.pi * params.radius_px ** 2))


def grow(t: np.ndarray, high: Described, low: Described, model: str = "similarity",
         params: GuidedParams = GuidedParams(),
         ransac: RansacParams = RansacParams()) -> Growth:
    """Grow hypothesis ``t`` by guided matching and refitting while its inliers increase.

    Parameters
    ----------
    t : (2, 3) or (3, 3) array
        Hypothesis, finer px -> coarser px (``high``'s to ``low``'s; for example RANSAC's winner
        on 5 inliers at scale s).
    high : Described
        The high image's points at the scale the hypothesis was found at (high px).
    low : Described
        The low image's points (s = 1, low px).
    model : str
        Model refitted each round (``estimator.MODELS``: similarity, affine, homography).
    params : GuidedParams
    ransac : RansacParams
        Refinement settings (``refine_iters``); the inlier threshold is ``params.threshold_px``
        (None: ``ransac.threshold_px``).

    Returns
    -------
    Growth
        The final transform and its distinct inliers; ``counts`` per round; ``transform`` is
        ``t`` itself and ``inliers`` empty when no guided match was found.

    Raises
    ------
    ValueError
        For the fundamental matrix (a point maps to a line: there is no position to predict).
    """
    map_model(model)  # guided growth predicts where each point goes
    t = np.asarray(t, np.float64)
    chance = chance_matches(t, high, low, params)
    best_t, best_in, counts = grow_rounds(t, model, Points([high], low), params, ransac)
    return Growth(model=model, transform=best_t, inliers=best_in, rounds=len(counts),
                  counts=tuple(counts), chance=float(chance))


def guided_pool(t: np.ndarray, highs: Sequence[Described], low: Described,
                params: GuidedParams = GuidedParams()) -> Tuple[np.ndarray, np.ndarray]:
    """The distinct guided matches of ``t`` (:func:`guided_matches`) at every scale of
    ``highs``: (finer px (K, 2), coarser px (K, 2)); a keypoint described twice counts once."""
    src: List[np.ndarray] = [np.zeros((0, 2))]
    dst: List[np.ndarray] = [np.zeros((0, 2))]
    for high in highs:
        i, j, _ = guided_matches(t, high, low, params)
        src.append(high.xy[i])
        dst.append(low.xy[j])
    return distinct_pairs(np.vstack(src), np.vstack(dst))


class Points(NamedTuple):
    """What guided matching draws from: the finer image's points described at each scale
    matched, and the coarser image's (s = 1, its px)."""

    highs: Sequence[Described]
    low: Described


def grow_rounds(t: np.ndarray, model: str, points: Points,
                params: GuidedParams = GuidedParams(), ransac: RansacParams = RansacParams(),
                inliers: Optional[np.ndarray] = None,
                allowed: Optional[Callable[[np.ndarray], bool]] = None
                ) -> Tuple[np.ndarray, np.ndarray, List[int]]:
    """``t`` refit on its guided matches at every scale of ``points`` (:func:`guided_pool`),
    round after round while they explain more pairs than ``inliers`` ((N, 4), none by
    default), at most ``params.max_rounds`` rounds: (transform, its inliers (N, 4) float64,
    the distinct inliers after each round). ``allowed(t)``, when given, must hold for a refit
    to be taken (the final answer's: not folded over)."""
    highs, low = points
    best_t = np.asarray(t, np.float64)
    best_in = np.zeros((0, 4)) if inliers is None else inliers
    counts: List[int] = []
    for _ in range(max(int(params.max_rounds), 1)):
        src, dst = guided_pool(best_t, highs, low, params)
        if len(src) == 0:
            break
        threshold = ransac.threshold_px if params.threshold_px is None else params.threshold_px
        est = refine(model, best_t, src, dst, ransac, threshold=threshold)
        counts.append(est.n_inliers)
        if est.n_inliers <= len(best_in) or (allowed is not None and not allowed(est.transform)):
            break
        best_t = est.transform
        best_in = np.hstack([src[est.inliers], dst[est.inliers]])
    return best_t, best_in, counts

