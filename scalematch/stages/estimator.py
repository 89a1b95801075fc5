"""Stage 6: robust estimation of the finer -> coarser transform (docs/ALGORITHM.md step 6, paper 4.2).

RANSAC through OpenCV for the four models of the paper: similarity (default,
``cv2.estimateAffinePartial2D``), affine (``cv2.estimateAffine2D``), plane homography
(``cv2.findHomography``) and fundamental matrix (``cv2.findFundamentalMat`` with MAGSAC++,
OpenCV's USAC). The winner is refined on all its inliers (OpenCV's Levenberg-Marquardt for the
affine kinds; least squares on the inliers for the homography; MAGSAC++'s own weighted fit is
kept for the fundamental matrix, and the answer's is refined by Levenberg-Marquardt on the
Sampson error of its inliers, ``stages/epipolar.py``), then the inliers are recounted with the
refined model.
OpenCV objects never leave this module: arrays in, arrays out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, ClassVar, Dict, Mapping, Optional, Tuple

import cv2
import numpy as np

from ..checks import Bounds, COUNT, POSITIVE, PROBABILITY, check_bounds
from ..geometry import (answer_parts, as_matrix3, compose, epipolar_distances, epipoles,
                        invert, transfer_error)
from ..geometry import footprint as _map_footprint
from .epipolar import one_to_one, refine_fundamental

#: Most RANSAC iterations a fit may run: 20 times the default cap. Every scale of every search
#: runs its own RANSAC, so the cap multiplies the time of a "no"; beyond it the confidence
#: asked for is reached anyway (99.9 % for 2-point samples at 10 % inliers takes 688)
MAX_RANSAC_ITERS = 100_000

@dataclass(frozen=True)
class RansacParams:
    """The robust fit of every scale (``Config.ransac``)."""

    #: inlier threshold in low-resolution px at the matching scale. The paper lets it depend on s
    #: (section 4.2); here positions are compared on the level where the high image is zoomed
    #: out by s, where localisation error is about 1 px in both images, so the threshold in low
    #: px is constant and its value in high-resolution px is ``threshold_px * s``.
    threshold_px: float = 3.0
    confidence: float = 0.999  #: RANSAC confidence (OpenCV default 0.99; higher for few inliers)
    max_iters: int = 5000  #: RANSAC iterations cap
    refine_iters: int = 10  #: Levenberg-Marquardt refinement iterations (OpenCV default)
    #: MAGSAC++'s threshold for the fundamental matrix, px: the largest noise scale it
    #: marginalises over (Barath et al. 2020, "MAGSAC++"). 1 px is the reference's setting
    #: (ef/SOURCES.md); on the 8 ef pairs, both orders, 1 and 2 px gave the same median error
    #: (0.61 px) and 3 px (the plane models' inlier threshold) 0.62, with a worst pair at 0.95,
    #: 0.93 and 1.30 px. The inliers are still counted at ``threshold_px``
    magsac_threshold_px: float = 1.0

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "threshold_px": POSITIVE,
        "magsac_threshold_px": POSITIVE,
        "confidence": PROBABILITY,
        "max_iters": Bounds(lo=1, hi=MAX_RANSAC_ITERS, integer=True),
        "refine_iters": COUNT,
    }

    def __post_init__(self) -> None:
        check_bounds("ransac", self, self.BOUNDS)


@dataclass(frozen=True)
class FitSpec:
    """How a stage fits a transform: the model, the robust fit's parameters and the one seed
    of its random samples (``Config.model``, ``Config.ransac``, ``Config.seed``)."""

    model: str
    ransac: RansacParams = field(default_factory=RansacParams)
    seed: int = 0


@dataclass(frozen=True)
class Estimate:
    """A fitted model: ``transform`` maps ``src`` to ``dst`` (finer px -> coarser px);
    ``inliers`` is a boolean mask."""

    model: str
    transform: Optional[np.ndarray] = field(repr=False)  #: 2x3 or 3x3, None when failed
    inliers: np.ndarray = field(repr=False)  #: (K,) bool over the input correspondences
    #: (K,) low px (for "fundamental": the distance to the epipolar lines, ``_epipolar_distance``)
    residuals: np.ndarray = field(repr=False)

    @property
    def n_inliers(self) -> int:
        return int(self.inliers.sum())


def _epipolar_distance(f: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Each pair's distance, px, to the epipolar geometry ``x_low^T F x_high = 0``: the larger
    of its two one-sided distances (the coarser point to the epipolar line of the finer one,
    and the finer point to the line of the coarser one).

    The a-contrario test counts a chance inlier as a coarser point falling in a band of
    ``2 threshold_px`` along its line (``_band_area``); a pair within the threshold on both
    sides is within that band, so the count stays within the chance the test assumes. The
    Sampson distance is not: where the epipole lies among the points (|F x| small) it lets a
    pair lie far from its line, and unrelated photos found F of 53 such "inliers" at log10
    NFA -37 (docs/results/NULLS.md, "Mode fundamental"; ORSA counts the one-sided distance, Moisan &
    Stival 2004).
    """
    return epipolar_distances(f, src, dst).max(axis=1)


#: Pairs that determine a fundamental matrix: its 7 degrees of freedom, by the linear 8-point
#: solver (Hartley & Zisserman, "Multiple View Geometry", 2nd ed., 11.1)
FUNDAMENTAL_SAMPLE = 8


def _no_parts(t: np.ndarray, finer_xy=None) -> Tuple[float, float, Tuple[float, float]]:
    """A fundamental matrix maps a point to a line: no ratio, rotation or translation."""
    return math.nan, math.nan, (math.nan, math.nan)


def _map_carried(t: np.ndarray, s_fine: np.ndarray, s_coarse: np.ndarray) -> np.ndarray:
    """A point map ``t`` (finer px -> coarser px) in other pixels of both images, given each
    image's map to them (``s_fine``, ``s_coarse``, 2x3): ``S_coarse o T o S_fine^-1``."""
    return compose(s_coarse, compose(t, invert(s_fine)))


def _matrix_carried(f: np.ndarray, s_fine: np.ndarray, s_coarse: np.ndarray) -> np.ndarray:
    """A fundamental matrix (``x_coarse^T F x_fine = 0``) in other pixels of both images:
    ``S_coarse^-T F S_fine^-1``."""
    return as_matrix3(invert(s_coarse)).T @ f @ as_matrix3(invert(s_fine))


def _no_footprint(f: np.ndarray, high_shape: Tuple[int, ...]) -> None:
    """A fundamental matrix maps a point to a line: the finer image has no footprint."""
    return None


def _all_counted(pairs: np.ndarray, same_point_px: float) -> int:
    """A point map's inliers each count: a point matched twice fits it at most once."""
    return len(pairs)


def _counted_one_to_one(pairs: np.ndarray, same_point_px: float) -> int:
    """An epipolar geometry's inliers counted one to one (:func:`.epipolar.one_to_one`): a
    point matched many times lies on every line through it, so it fits any geometry whose
    epipole is on such a line."""
    return len(one_to_one(pairs, same_point_px))


def _no_epipoles(t: np.ndarray):
    """A point map has no epipoles."""
    return None


def _as_fitted(t: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """A point map's answer is its fit: refined on its inliers where it was found."""
    return t


def _matrix_refined(f: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """A fundamental matrix refined by Levenberg-Marquardt on the Sampson error of its
    inliers ``pairs`` ((N, 4): finer px, coarser px; :mod:`scalematch.stages.epipolar`), when
    they are at least its minimal sample."""
    if len(pairs) < FUNDAMENTAL_SAMPLE:
        return f
    return refine_fundamental(f, pairs[:, :2], pairs[:, 2:])


def _disc_area(threshold_px: float, low_shape: Tuple[int, int]) -> float:
    """A point predicted by the model: a disc of radius ``threshold_px``."""
    return math.pi * threshold_px ** 2


def _band_area(threshold_px: float, low_shape: Tuple[int, int]) -> float:
    """A point on a predicted line: a band of width 2 thresholds along the image's diagonal."""
    return 2.0 * threshold_px * math.hypot(*low_shape)


def _fit_similarity(src, dst, thr: float, params: "RansacParams", ransac: bool):
    if ransac:
        return cv2.estimateAffinePartial2D(src, dst, method=cv2.RANSAC, ransacReprojThreshold=thr,
                                           maxIters=params.max_iters, confidence=params.confidence,
                                           refineIters=params.refine_iters)[0]
    return cv2.estimateAffinePartial2D(src, dst, method=cv2.LMEDS,
                                       refineIters=params.refine_iters)[0]


def _fit_affine(src, dst, thr: float, params: "RansacParams", ransac: bool):
    if ransac:
        return cv2.estimateAffine2D(src, dst, method=cv2.RANSAC, ransacReprojThreshold=thr,
                                    maxIters=params.max_iters, confidence=params.confidence,
                                    refineIters=params.refine_iters)[0]
    return cv2.estimateAffine2D(src, dst, method=cv2.LMEDS, refineIters=params.refine_iters)[0]


def _fit_homography(src, dst, thr: float, params: "RansacParams", ransac: bool):
    return cv2.findHomography(src, dst, cv2.RANSAC if ransac else 0, thr,
                              maxIters=params.max_iters, confidence=params.confidence)[0]


def _fit_fundamental(src, dst, thr: float, params: "RansacParams", ransac: bool):
    """MAGSAC++ (OpenCV's USAC, with its local optimisation and degeneracy test) when robust,
    OpenCV's RANSAC where USAC fails on a sample it cannot use (an assertion on an empty model
    was met on one null pair); the normalised 8-point algorithm on the pairs given otherwise."""
    if len(src) < 8:
        return None
    if not ransac:
        t, _ = cv2.findFundamentalMat(src, dst, cv2.FM_8POINT)
    else:
        try:
            t, _ = cv2.findFundamentalMat(src, dst, cv2.USAC_MAGSAC, params.magsac_threshold_px,
                                          params.confidence, params.max_iters)
        except cv2.error:
            t, _ = cv2.findFundamentalMat(src, dst, cv2.FM_RANSAC, thr, params.confidence,
                                          params.max_iters)
    return None if t is None or t.shape != (3, 3) else t


@dataclass(frozen=True)
class Model:
    """A transform the robust estimator can fit, and what the rest of the pipeline needs of it.

    ``fit(src, dst, thr, params, ransac)`` takes (K, 1, 2) float32 high and low px and returns
    the 2x3 or 3x3 transform (None when it fails): RANSAC with threshold ``thr`` low px, or a
    fit to all pairs given. ``residuals(t, src, dst)`` is each pair's error in low px.
    ``chance_area(threshold_px, low_shape)`` is the area, px^2, of the low image where a random
    point fits a prediction of the model (the a-contrario test's p is it over the image area).
    ``parts(t, finer_xy)`` is an answer's (ratio, rotation in degrees, translation), NaN where
    the model has none; ``carried(t, s_fine, s_coarse)`` is ``t`` in other pixels of both
    images (each image's 2x3 map to them); ``footprint(t, high_shape)`` the finer image's
    corners in the coarser image (None where it has none); ``refined(t, inliers)`` the answer
    refined on its inliers once it is accepted; ``counted(pairs, same_point_px)`` how many
    inliers ``pairs`` ((N, 4): finer px, coarser px) the a-contrario test counts;
    ``epipoles(t)`` a matrix's epipoles (:func:`scalematch.geometry.epipoles`; None for a map).
    """

    name: str
    min_sample: int  #: points that determine the model
    fit: Callable = field(repr=False)
    residuals: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] = field(repr=False)
    chance_area: Callable[[float, Tuple[int, int]], float] = field(repr=False)
    #: True: a point maps to a point, so the transform has a resolution ratio, a rotation, a
    #: footprint and an overlay; False (the fundamental matrix): a point maps to a line. What
    #: differs beyond the callables here is asked once a stage: how the model is searched
    #: (``plan.searched_as_a_map``), decided (``decision.maps_points``), answered
    #: (``answer.answered_by_a_matrix``), told (``verdict.said_as_matrix``) and grown
    #: (:func:`map_model`)
    has_ratio: bool = True
    #: True: :func:`refine` refits the model by least squares on the pairs it explains; False:
    #: the robust fit is its own local optimisation and is kept (MAGSAC++ weights each pair by
    #: its residual; an unweighted 8-point refit on the 3 px inliers moved the ef pairs' median
    #: error from 0.61 to 0.75 px, the worst from 0.95 to 1.02)
    refit_inliers: bool = True
    parts: Callable = field(default=answer_parts, repr=False)
    carried: Callable = field(default=_map_carried, repr=False)
    footprint: Callable = field(default=_map_footprint, repr=False)
    refined: Callable = field(default=_as_fitted, repr=False)
    counted: Callable[[np.ndarray, float], int] = field(default=_all_counted, repr=False)
    epipoles: Callable = field(default=_no_epipoles, repr=False)


#: The models of the paper (section 5 and "Further examples"), by name.
MODELS: Dict[str, Model] = {m.name: m for m in (
    Model("similarity", 2, _fit_similarity, transfer_error, _disc_area),
    Model("affine", 3, _fit_affine, transfer_error, _disc_area),
    Model("homography", 4, _fit_homography, transfer_error, _disc_area),
    Model("fundamental", FUNDAMENTAL_SAMPLE, _fit_fundamental, _epipolar_distance, _band_area, has_ratio=False,
          refit_inliers=False, parts=_no_parts, carried=_matrix_carried,
          footprint=_no_footprint, refined=_matrix_refined, counted=_counted_one_to_one,
          epipoles=epipoles),
)}
#: minimal sample of each model by name (kept for callers of the mapping; see MODELS)
MIN_SAMPLE = {name: m.min_sample for name, m in MODELS.items()}


def model_of(name: str) -> Model:
    """The :class:`Model` called ``name``; ``ValueError`` naming the known ones otherwise.

    >>> model_of("homography").min_sample, model_of("fundamental").min_sample
    (4, 8)
    """
    if name not in MODELS:
        raise ValueError(f"unknown model {name!r}; one of {', '.join(MODELS)}")
    return MODELS[name]


def map_model(name: str) -> Model:
    """The :class:`Model` called ``name`` where it maps a point to a point (a map has a place
    to predict each point at); ``ValueError`` for the fundamental matrix, which maps a point
    to a line, or an unknown name."""
    spec = model_of(name)
    if not spec.has_ratio:
        raise ValueError(f"a point-to-point model is needed, not {name!r}")
    return spec


def residuals(model: str, t: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Transfer error |T(src) - dst| in low px (for the fundamental matrix, the larger one-sided
    distance to the epipolar lines, px)."""
    return model_of(model).residuals(t, np.asarray(src, np.float64), np.asarray(dst, np.float64))


def estimate(model: str, src: np.ndarray, dst: np.ndarray, params: RansacParams = RansacParams(),
             seed: int = 0, threshold: Optional[float] = None) -> Estimate:
    """RANSAC fit of ``model`` mapping ``src`` (high px, (K, 2)) to ``dst`` (low px, (K, 2)).

    ``threshold`` (low px) overrides ``params.threshold_px``. Fewer correspondences than the
    model's minimal sample give an empty estimate (transform None, no inliers), not an error.
    """
    spec = model_of(model)
    k = len(src)
    thr = float(params.threshold_px if threshold is None else threshold)
    none = Estimate(model, None, np.zeros(k, bool), np.full(k, np.inf))
    if k < spec.min_sample + 1:
        return none
    src32 = np.ascontiguousarray(src, np.float32).reshape(-1, 1, 2)
    dst32 = np.ascontiguousarray(dst, np.float32).reshape(-1, 1, 2)
    cv2.setRNGSeed(int(seed))
    t = spec.fit(src32, dst32, thr, params, ransac=True)
    if t is None or not np.all(np.isfinite(t)):
        return none
    return refine(model, t, src, dst, params, threshold=thr)


def refine(model: str, t: np.ndarray, src: np.ndarray, dst: np.ndarray,
           params: RansacParams = RansacParams(), threshold: Optional[float] = None,
           rounds: int = 2) -> Estimate:
    """Refit ``t`` on the pairs it explains, then recount, ``rounds`` times (no sampling).

    The pairs within ``threshold`` low px of ``t`` are its inliers; the model is fitted to all of
    them and kept when it explains at least as many. RANSAC's winner is refined this way, and so
    is a transform given more pairs than it was found on (``pipeline``: every scale's candidates).
    """
    spec = model_of(model)
    thr = float(params.threshold_px if threshold is None else threshold)
    src32 = np.ascontiguousarray(src, np.float32).reshape(-1, 1, 2)
    dst32 = np.ascontiguousarray(dst, np.float32).reshape(-1, 1, 2)
    res = residuals(model, t, src, dst)
    inl = res <= thr
    for _ in range(rounds if spec.refit_inliers else 0):
        if inl.sum() <= spec.min_sample:
            break
        t2 = spec.fit(src32[inl], dst32[inl], thr, params, ransac=False)
        if t2 is None or not np.all(np.isfinite(t2)):
            break
        res2 = residuals(model, t2, src, dst)
        inl2 = res2 <= thr
        if inl2.sum() < inl.sum():
            break
        t, res, inl = t2, res2, inl2
    return Estimate(model, np.asarray(t, np.float64), inl, res)
