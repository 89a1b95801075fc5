"""Stage 6: robust estimation of the high -> low transform (ALGORITHM.md step 6, paper 4.2).

RANSAC through OpenCV for the four models of the paper: similarity (default,
``cv2.estimateAffinePartial2D``), affine (``cv2.estimateAffine2D``), plane homography
(``cv2.findHomography``) and fundamental matrix (``cv2.findFundamentalMat``). The winner is
refined on all its inliers (OpenCV's Levenberg-Marquardt for the affine kinds; least squares on
the inliers for the homography), then the inliers are recounted with the refined model.
OpenCV objects never leave this module: arrays in, arrays out.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import cv2
import numpy as np

#: minimal sample size of each model (points that determine it)
MIN_SAMPLE = {"similarity": 2, "affine": 3, "homography": 4, "fundamental": 8}


@dataclass(frozen=True)
class RansacParams:
    #: inlier threshold in low-resolution px at the matching scale. The paper lets it depend on s
    #: (section 4.2); here positions are compared on the level where the high image is zoomed
    #: out by s, where localisation error is about 1 px in both images, so the threshold in low
    #: px is constant and its value in high-resolution px is ``threshold_px * s``.
    threshold_px: float = 3.0
    confidence: float = 0.999  #: RANSAC confidence (OpenCV default 0.99; higher for few inliers)
    max_iters: int = 5000  #: RANSAC iterations cap
    refine_iters: int = 10  #: Levenberg-Marquardt refinement iterations (OpenCV default)


@dataclass(frozen=True)
class Estimate:
    """A fitted model: ``transform`` maps high px -> low px; ``inliers`` is a boolean mask."""

    model: str
    transform: Optional[np.ndarray] = field(repr=False)  #: 2x3 or 3x3, None when failed
    inliers: np.ndarray = field(repr=False)  #: (K,) bool over the input correspondences
    residuals: np.ndarray = field(repr=False)  #: (K,) low px (Sampson distance for "fundamental")

    @property
    def n_inliers(self) -> int:
        return int(self.inliers.sum())


def residuals(model: str, t: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Transfer error |T(src) - dst| in low px (Sampson distance for the fundamental matrix)."""
    src = np.asarray(src, np.float64)
    dst = np.asarray(dst, np.float64)
    if model == "fundamental":
        x1 = np.hstack([src, np.ones((len(src), 1))])
        x2 = np.hstack([dst, np.ones((len(dst), 1))])
        fx1 = x1 @ t.T
        ftx2 = x2 @ t
        num = np.einsum("ij,ij->i", x2, fx1) ** 2
        den = fx1[:, 0] ** 2 + fx1[:, 1] ** 2 + ftx2[:, 0] ** 2 + ftx2[:, 1] ** 2
        return np.sqrt(num / np.maximum(den, 1e-18))
    if t.shape == (2, 3):
        mapped = src @ t[:, :2].T + t[:, 2]
    else:
        p = np.hstack([src, np.ones((len(src), 1))]) @ t.T
        mapped = p[:, :2] / np.where(np.abs(p[:, 2:3]) < 1e-12, 1e-12, p[:, 2:3])
    return np.linalg.norm(mapped - dst, axis=1)


def _fit(model: str, src, dst, thr: float, params: RansacParams, ransac: bool):
    method = cv2.RANSAC if ransac else 0
    if model == "similarity":
        if ransac:
            t, _ = cv2.estimateAffinePartial2D(src, dst, method=cv2.RANSAC,
                                               ransacReprojThreshold=thr, maxIters=params.max_iters,
                                               confidence=params.confidence,
                                               refineIters=params.refine_iters)
        else:
            t, _ = cv2.estimateAffinePartial2D(src, dst, method=cv2.LMEDS,
                                               refineIters=params.refine_iters)
        return t
    if model == "affine":
        if ransac:
            t, _ = cv2.estimateAffine2D(src, dst, method=cv2.RANSAC, ransacReprojThreshold=thr,
                                        maxIters=params.max_iters, confidence=params.confidence,
                                        refineIters=params.refine_iters)
        else:
            t, _ = cv2.estimateAffine2D(src, dst, method=cv2.LMEDS, refineIters=params.refine_iters)
        return t
    if model == "homography":
        t, _ = cv2.findHomography(src, dst, method, thr, maxIters=params.max_iters,
                                  confidence=params.confidence)
        return t
    if model == "fundamental":
        if len(src) < 8:
            return None
        t, _ = cv2.findFundamentalMat(src, dst, cv2.FM_RANSAC if ransac else cv2.FM_8POINT,
                                      thr, params.confidence, params.max_iters)
        return None if t is None or t.shape != (3, 3) else t
    raise ValueError(f"unknown model {model!r}")


def estimate(model: str, src: np.ndarray, dst: np.ndarray, params: RansacParams = RansacParams(),
             seed: int = 0, threshold: Optional[float] = None) -> Estimate:
    """RANSAC fit of ``model`` mapping ``src`` (high px, (K, 2)) to ``dst`` (low px, (K, 2)).

    ``threshold`` (low px) overrides ``params.threshold_px``. Fewer correspondences than the
    model's minimal sample give an empty estimate (transform None, no inliers), not an error.
    """
    k = len(src)
    thr = float(params.threshold_px if threshold is None else threshold)
    none = Estimate(model, None, np.zeros(k, bool), np.full(k, np.inf))
    if k < MIN_SAMPLE[model] + 1:
        return none
    src32 = np.ascontiguousarray(src, np.float32).reshape(-1, 1, 2)
    dst32 = np.ascontiguousarray(dst, np.float32).reshape(-1, 1, 2)
    cv2.setRNGSeed(int(seed))
    t = _fit(model, src32, dst32, thr, params, ransac=True)
    if t is None or not np.all(np.isfinite(t)):
        return none
    res = residuals(model, t, src, dst)
    inl = res <= thr
    # refine on all inliers, then recount (twice: the inlier set can grow once refined)
    for _ in range(2):
        if inl.sum() <= MIN_SAMPLE[model]:
            break
        t2 = _fit(model, src32[inl], dst32[inl], thr, params, ransac=False)
        if t2 is None or not np.all(np.isfinite(t2)):
            break
        res2 = residuals(model, t2, src, dst)
        inl2 = res2 <= thr
        if inl2.sum() < inl.sum():
            break
        t, res, inl = t2, res2, inl2
    return Estimate(model, np.asarray(t, np.float64), inl, res)
