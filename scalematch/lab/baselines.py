"""The peers a user would reach for: OpenCV SIFT, ORB, AKAZE and BRISK with the textbook recipe.

Each baseline: detect and describe both images (8-bit), brute-force 2-nearest-neighbour
matching (L2 for SIFT, Hamming for the binary descriptors), Lowe's ratio test at 0.8, then the
same RANSAC for everyone: ``cv2.estimateAffinePartial2D`` (a similarity) or
``cv2.findHomography`` at 3 px, seeded through ``cv2.setRNGSeed``. Fewer than ``MIN_INLIERS``
inliers is "no match". OpenCV objects (KeyPoint, DMatch) are turned into arrays here and never
leave this module. The transform maps a high-resolution pixel to a low-resolution pixel.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Optional, Tuple

import cv2
import numpy as np

#: The baselines, in the order they are reported.
BASELINES = ("sift", "orb", "akaze", "brisk")
#: Lowe's ratio test threshold (Lowe, IJCV 2004, section 7.1, rejects 90% of false matches at 0.8).
RATIO_TEST = 0.8
#: RANSAC inlier threshold, px of the low image (EVALUATION.md: the same RANSAC at 3 px for all).
RANSAC_PX = 3.0
#: Fewest inliers accepted as a match; below it the baseline says "no match". 4 is the smallest
#: sample that over-determines a homography (and a similarity twice over).
MIN_INLIERS = 4
#: ORB keypoints per image. OpenCV's default of 500 is tuned for video frames; spread over the
#: 8 pyramid levels of a 640x480 high image it leaves too few points at the one scale that
#: overlaps a 2-10x smaller low image, so ORB would lose for a setting, not its design. 5000 is
#: about what SIFT finds on these images.
ORB_FEATURES = 5000
#: Models the baselines can fit.
BASELINE_MODELS = ("similarity", "homography")


@dataclass(frozen=True)
class BaselineResult:
    """What a baseline produced on one pair."""

    method: str  #: sift | orb | akaze | brisk
    transform: Optional[np.ndarray] = field(repr=False)  #: high px -> low px; None = no match
    inliers: int  #: RANSAC inliers (0 when no model)
    matches: int  #: matches surviving the ratio test
    seconds: float  #: wall time of detect + describe + match + estimate
    keypoints: Tuple[int, int] = (0, 0)  #: keypoints found in (low, high)
    model: str = "similarity"  #: similarity | homography


def make_detector(method: str):
    """The OpenCV feature object and its descriptor norm for ``method`` (see BASELINES)."""
    if method == "sift":
        return cv2.SIFT_create(), cv2.NORM_L2
    if method == "orb":
        return cv2.ORB_create(nfeatures=ORB_FEATURES), cv2.NORM_HAMMING
    if method in ("akaze", "brisk"):
        name = "AKAZE_create" if method == "akaze" else "BRISK_create"
        # OpenCV 4 has them in cv2, OpenCV 5 moved them to cv2.xfeatures2d (contrib)
        factory = getattr(cv2, name, None) or getattr(getattr(cv2, "xfeatures2d", None), name, None)
        if factory is None:
            raise ValueError(f"this OpenCV build has no {name}; install opencv-contrib-python")
        return factory(), cv2.NORM_HAMMING
    raise ValueError(f"unknown baseline {method!r}; choose one of {BASELINES}")


def to_uint8(image: np.ndarray) -> np.ndarray:
    """(H, W) grey levels in the 8-bit range -> (H, W) uint8 (rounded, clipped)."""
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"expected a grey (H, W) image, got shape {img.shape}")
    if img.dtype == np.uint8:
        return img
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def detect_and_describe(detector, image: np.ndarray) -> Tuple[np.ndarray, Optional[np.ndarray]]:
    """(N, 2) float32 keypoint positions (x, y) and their (N, D) descriptors (None when N = 0)."""
    kps, desc = detector.detectAndCompute(image, None)
    xy = np.array([k.pt for k in kps], dtype=np.float32).reshape(-1, 2)
    if desc is None or len(kps) == 0:
        return xy[:0], None
    return xy, desc


def ratio_matches(desc_high: Optional[np.ndarray], desc_low: Optional[np.ndarray], norm: int,
                  ratio: float = RATIO_TEST) -> np.ndarray:
    """(M, 2) int indices (high, low) of the matches passing Lowe's ratio test."""
    if desc_high is None or desc_low is None or len(desc_high) == 0 or len(desc_low) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    knn = cv2.BFMatcher(norm).knnMatch(desc_high, desc_low, k=2)
    kept = [(m[0].queryIdx, m[0].trainIdx) for m in knn
            if len(m) == 2 and m[0].distance < ratio * m[1].distance]
    return np.array(kept, dtype=np.int64).reshape(-1, 2)


def estimate(high_pts: np.ndarray, low_pts: np.ndarray, model: str = "similarity",
             seed: int = 0) -> Tuple[Optional[np.ndarray], int]:
    """RANSAC at ``RANSAC_PX``: (transform high -> low or None, number of inliers)."""
    if model not in BASELINE_MODELS:
        raise ValueError(f"model must be one of {BASELINE_MODELS}, got {model!r}")
    need = 2 if model == "similarity" else 4
    if len(high_pts) < max(need, MIN_INLIERS):
        return None, 0
    cv2.setRNGSeed(int(seed))
    if model == "similarity":
        t, mask = cv2.estimateAffinePartial2D(high_pts, low_pts, method=cv2.RANSAC,
                                              ransacReprojThreshold=RANSAC_PX)
    else:
        t, mask = cv2.findHomography(high_pts, low_pts, cv2.RANSAC, RANSAC_PX)
    n = int(mask.sum()) if mask is not None else 0
    if t is None or n < MIN_INLIERS or not np.all(np.isfinite(t)):
        return None, n
    return np.asarray(t, dtype=np.float64), n


def match_baseline(low: np.ndarray, high: np.ndarray, method: str = "sift",
                   model: str = "similarity", seed: int = 0) -> BaselineResult:
    """Match ``high`` into ``low`` with an OpenCV baseline.

    Parameters
    ----------
    low, high : (H, W) arrays
        Grey levels in the 8-bit range (float or uint8).
    method : str
        One of BASELINES.
    model : str
        "similarity" (``cv2.estimateAffinePartial2D``) or "homography" (``cv2.findHomography``).
    seed : int
        Seeds OpenCV's RANSAC (``cv2.setRNGSeed``), for repeatable results.

    Returns
    -------
    BaselineResult
        ``transform`` (2x3 or 3x3, high px -> low px) is None when fewer than ``MIN_INLIERS``
        inliers support a model; a flat image gives no match, not an exception.
    """
    detector, norm = make_detector(method)
    t0 = time.perf_counter()
    lo8, hi8 = to_uint8(low), to_uint8(high)
    xy_low, d_low = detect_and_describe(detector, lo8)
    xy_high, d_high = detect_and_describe(detector, hi8)
    m = ratio_matches(d_high, d_low, norm)
    t, n = estimate(xy_high[m[:, 0]], xy_low[m[:, 1]], model, seed)
    return BaselineResult(method=method, transform=t, inliers=n, matches=int(len(m)),
                          seconds=time.perf_counter() - t0,
                          keypoints=(int(len(xy_low)), int(len(xy_high))), model=model)
