"""How a match is judged (EVALUATION.md, "Success and error").

An estimated transform E and the truth T (each 2x3 or 3x3, high px -> low px) map a 21x21 grid
of points spanning the high-resolution image; the points T maps inside the low-resolution image
are kept, and the error is the mean distance between the two mappings in low-resolution pixels.
A method that gives no transform ("no reliable match") has an infinite error: it fails the pair
but claims nothing false.
"""

from __future__ import annotations

import math
from typing import Optional, Tuple

import numpy as np

from ..geometry import apply, grid

#: Success threshold on the reprojection error, low-resolution px (EVALUATION.md).
SUCCESS_PX = 3.0


def _check(t: np.ndarray, name: str) -> np.ndarray:
    t = np.asarray(t, dtype=np.float64)
    if t.shape not in ((2, 3), (3, 3)):
        raise ValueError(f"{name} must be a 2x3 affine or a 3x3 homography, got shape {t.shape}")
    return t


def reprojection_error(estimate: Optional[np.ndarray], truth: np.ndarray,
                       high_shape: Tuple[int, ...], low_shape: Tuple[int, ...]) -> float:
    """Mean distance, low px, between ``estimate`` and ``truth`` over a grid spanning ``high``.

    Parameters
    ----------
    estimate : 2x3 or 3x3 array, or None
        The estimated transform, high px -> low px; None (no match) gives ``inf``.
    truth : 2x3 or 3x3 array
        The true transform, high px -> low px.
    high_shape, low_shape : tuple
        Shapes (H, W, ...) of the high and low images.

    Returns
    -------
    float
        The mean error over the grid points ``truth`` maps inside ``low``; ``inf`` when the
        estimate is None, not finite, or no grid point lands inside ``low``.
    """
    t = _check(truth, "truth")
    if estimate is None:
        return math.inf
    e = _check(estimate, "estimate")
    if not np.all(np.isfinite(e)):
        return math.inf
    pts = grid(high_shape[:2])
    true_low = apply(t, pts)
    lh, lw = int(low_shape[0]), int(low_shape[1])
    inside = ((true_low[:, 0] >= -0.5) & (true_low[:, 0] <= lw - 0.5)
              & (true_low[:, 1] >= -0.5) & (true_low[:, 1] <= lh - 0.5))
    if not inside.any():
        return math.inf
    with np.errstate(all="ignore"):
        est_low = apply(e, pts[inside])
    d = np.linalg.norm(est_low - true_low[inside], axis=1)
    err = float(np.mean(d))
    return err if math.isfinite(err) else math.inf


def is_success(err: float, threshold: float = SUCCESS_PX) -> bool:
    """True when ``err`` (low px) is below ``threshold`` (EVALUATION.md: 3 px)."""
    return bool(err < threshold)


def fit_similarity(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares 2x3 similarity mapping (N, 2) ``src`` onto (N, 2) ``dst`` (N >= 2)."""
    src = np.asarray(src, dtype=np.float64).reshape(-1, 2)
    dst = np.asarray(dst, dtype=np.float64).reshape(-1, 2)
    if len(src) < 2:
        raise ValueError("fit_similarity needs at least 2 point pairs")
    x, y = src[:, 0], src[:, 1]
    one, zero = np.ones_like(x), np.zeros_like(x)
    # unknowns (a, b, tx, ty) of [[a, -b, tx], [b, a, ty]]
    m = np.concatenate([np.stack([x, -y, one, zero], 1), np.stack([y, x, zero, one], 1)])
    rhs = np.concatenate([dst[:, 0], dst[:, 1]])
    a, b, tx, ty = np.linalg.lstsq(m, rhs, rcond=None)[0]
    return np.array([[a, -b, tx], [b, a, ty]])


def similarity_floor(truth: np.ndarray, high_shape: Tuple[int, ...],
                     low_shape: Tuple[int, ...]) -> float:
    """The error of the best similarity (least squares on the grid) against ``truth``.

    Zero for a similarity truth; for a homography (the boat pairs) it is the part of the error
    no similarity can remove: a method fitting a similarity cannot do better (within the
    least-squares-versus-mean-distance gap).
    """
    t = _check(truth, "truth")
    pts = grid(high_shape[:2])
    true_low = apply(t, pts)
    lh, lw = int(low_shape[0]), int(low_shape[1])
    inside = ((true_low[:, 0] >= -0.5) & (true_low[:, 0] <= lw - 0.5)
              & (true_low[:, 1] >= -0.5) & (true_low[:, 1] <= lh - 0.5))
    if inside.sum() < 2:
        return math.inf
    return reprojection_error(fit_similarity(pts[inside], true_low[inside]), t, high_shape,
                              low_shape)
