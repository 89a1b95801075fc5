"""What the candidates show beside the winning transform (docs/ALGORITHM.md step 8, the decision).

The winner of the robust estimation explains some of the candidate matches at its scale. The
rest tell two things a user needs to know:

* **A repeated structure** (the windows of a facade, the panels of a bus) is matched wherever a
  copy of it stands, so its copies show as a *second* transform of the same scale and angle,
  shifted by the period, with comparable support (:func:`second_transform`). The decision
  refuses a match with such a rival as ambiguous (:func:`scalematch.stages.decision.repeats`).
* **Parallax.** A 3-D scene seen from two places has no single plane map: the winner is the
  map of its dominant plane, and the matches off that plane still obey an epipolar geometry
  (:func:`off_plane`). The answer stands, and says so.

Pixels in OpenCV's convention, (x, y), pixel centres at integers; ``src`` in the finer image,
``dst`` in the coarser one, as the estimator takes them.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Optional

import cv2
import numpy as np

from ..geometry import apply, grid, similarity_parts
from .estimator import estimate


class EpipolarFit(NamedTuple):
    """How :func:`off_plane` fits its fundamental matrix (``DecisionParams.parallax_*``)."""

    threshold_px: float  #: distance to the epipolar line within which a candidate fits it, px
    #: fewest candidates it is fitted to: 8 for its linear solver, and as many again to tell a
    #: fit from a chance one
    min_candidates: int = 16
    #: its RANSAC's confidence (OpenCV's default, 0.99, stops early on the few hundred
    #: candidates of one scale)
    confidence: float = 0.999


class Second(NamedTuple):
    """The strongest other transform among a winner's candidates."""

    inliers: int  #: its distinct inliers (0: none found)
    transform: Optional[np.ndarray]  #: 2x3 similarity, finer px -> coarser px (None: none)
    gap_px: float  #: mean distance between its map of the finer image and the winner's, px


NO_SECOND = Second(0, None, math.nan)


def mean_transfer_gap(t1: np.ndarray, t2: np.ndarray, high_shape) -> float:
    """Mean distance (coarser px) between two maps' images of a grid over the finer image."""
    g = grid(high_shape)
    try:
        return float(np.mean(np.linalg.norm(apply(t1, g) - apply(t2, g), axis=1)))
    except (FloatingPointError, ValueError):
        return math.inf


def second_transform(src: np.ndarray, dst: np.ndarray, inliers: np.ndarray, t: np.ndarray,
                     high_shape, ransac, seed: int = 0) -> Second:
    """The similarity that best fits the candidates (``src``, ``dst``: (K, 2)) the winner ``t``
    leaves over (``inliers``: its (K,) mask), by the same RANSAC (``ransac``: RansacParams).

    >>> rng = np.random.default_rng(0)
    >>> src = rng.uniform(0, 400, (60, 2))
    >>> t = np.array([[0.5, 0, 10], [0, 0.5, 20]])
    >>> dst = apply(t, src); dst[30:] += (100, 0)            # half of it: a copy 100 px away
    >>> from scalematch.stages.estimator import RansacParams
    >>> s = second_transform(src, dst, np.arange(60) < 30, t, (400, 400), RansacParams())
    >>> s.inliers, round(s.gap_px)
    (30, 100)
    """
    rest = ~np.asarray(inliers, bool)
    if rest.sum() <= 3:
        return NO_SECOND
    est = estimate("similarity", src[rest], dst[rest], ransac, seed=seed)
    if est.transform is None or est.n_inliers == 0:
        return NO_SECOND
    return Second(int(est.n_inliers), est.transform, mean_transfer_gap(est.transform, t, high_shape))


def same_scale_and_angle(t1: np.ndarray, t2: np.ndarray, scale_factor: float,
                         angle_deg: float) -> bool:
    """Whether two maps have scales within ``scale_factor`` and angles within ``angle_deg``.

    >>> from scalematch.geometry import similarity_matrix as sim
    >>> same_scale_and_angle(sim(0.5, 10), sim(0.52, 14, 90, 0), 1.15, 10)
    True
    >>> same_scale_and_angle(sim(0.5, 10), sim(0.5, 179), 1.15, 10)
    False
    """
    r1, a1, _ = similarity_parts(t1)
    r2, a2, _ = similarity_parts(t2)
    if not (math.isfinite(r1) and math.isfinite(r2) and r1 > 0 and r2 > 0):
        return False
    turn = abs((a2 - a1 + 180.0) % 360.0 - 180.0)
    return abs(math.log(r2 / r1)) <= math.log(scale_factor) and turn <= angle_deg


def off_plane(src: np.ndarray, dst: np.ndarray, inliers: np.ndarray, fit: EpipolarFit,
              seed: int = 0, plane: Optional[np.ndarray] = None,
              max_offset: float = math.inf) -> int:
    """How many candidates off the winner's plane (``inliers``: its (K,) mask) an epipolar
    geometry explains: a fundamental matrix fitted by RANSAC to all of them (``fit``: within
    ``fit.threshold_px`` of the epipolar line), counted among the winner's outliers. 0 when there are too few.

    With ``plane`` (the winner's map, 2x3 or 3x3, finer px -> coarser px), only the candidates
    it sends at most ``max_offset`` times the diagonal of the candidates' extent in the coarser
    image from their match count. False matches that slide along a scene's edges share one
    direction, so a translation's epipolar geometry lines them up whatever their offset: on a
    flat pair against a 148 x 138 px coarser image, 36 beside 88 inliers, most offset by more
    than the image's diagonal; the parallax of the eight 3-D pairs of ``../shared/data/ef``
    moved their points a median 1-4 % of that diagonal (90 % of them under 17 %).

    A planar scene leaves nothing for it: measured 0 to 2 on 15 zoom pairs of real photos
    (ratios 2-8), against 118 on the desk scene of ``../shared/data/ef/zoom`` (42 on its plane).
    """
    k = len(src)
    if k < fit.min_candidates:
        return 0
    cv2.setRNGSeed(int(seed))
    f, mask = cv2.findFundamentalMat(np.ascontiguousarray(src, np.float32),
                                     np.ascontiguousarray(dst, np.float32), cv2.FM_RANSAC,
                                     float(fit.threshold_px), float(fit.confidence))
    if f is None or mask is None:
        return 0
    fits = mask.ravel()[:k].astype(bool) & ~np.asarray(inliers, bool)
    if plane is not None and math.isfinite(max_offset) and fits.any():
        extent = np.ptp(np.asarray(dst, np.float64), axis=0)
        offset = np.linalg.norm(apply(plane, np.asarray(src, np.float64)[fits]) - dst[fits], axis=1)
        fits[np.nonzero(fits)[0][offset > max_offset * float(np.hypot(*extent))]] = False
    return int(np.count_nonzero(fits))
