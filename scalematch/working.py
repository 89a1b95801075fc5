"""The working size of a very large low-resolution image (issue 12).

A low image whose longer side exceeds ``Config.low_max_side`` is matched as a copy shrunk by
the factor ``f = side / low_max_side`` (``cv2.INTER_AREA``, the same ``f`` on both axes), and
the answer is given back in the original low image's pixels. With OpenCV's pixel-centre
convention the working pixel ``x_w`` covers original pixels ``[x_w f, (x_w + 1) f)`` (edges), so

    x_original = f * x_working + (f - 1) / 2        (same for y)

which is the similarity ``S`` below. A transform ``T`` (high px -> working low px) becomes
``S o T``; in the other order (the low image found to be the finer one) ``T o S^-1``.

Shrinking the low image by ``f`` multiplies the resolution ratio by ``f``, so the search runs on
the configured scales extended upward to ``f`` times the largest: the ratios the configuration
covers in the original pixels are all still searched. The per-scale table and ``best_scale``
are reported in the original pixels (the working scale divided by ``f``; times ``f`` when the
low image was found to be the finer one).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Optional, Sequence, Tuple

import cv2
import numpy as np

from .geometry import as_matrix3, compose, invert, similarity_parts
from .result import MatchResult
from .stages.estimator import model_of


def working_factor(shape: Tuple[int, ...], max_side: Optional[int]) -> float:
    """Shrink factor f >= 1 bringing the longer side of ``shape`` to ``max_side`` (1: none)."""
    if max_side is None or max(shape[:2]) <= max_side:
        return 1.0
    return max(shape[:2]) / float(max_side)


def shrink(image: np.ndarray, f: float) -> np.ndarray:
    """``image`` (H, W) shrunk by ``f`` with pixel-area averaging (anti-aliased), float32."""
    return cv2.resize(image, (0, 0), fx=1.0 / f, fy=1.0 / f, interpolation=cv2.INTER_AREA)


def working_scales(scales: Sequence[float], f: float) -> Tuple[float, ...]:
    """The scales to search on the shrunk low image: the configured ones, and each times ``f``
    where that exceeds the largest (the configured ratio range, in original pixels)."""
    top = max(scales)
    return tuple(sorted(set(scales) | {round(s * f, 3) for s in scales if s * f > top}))


def _to_original(f: float) -> np.ndarray:
    """S (2x3): working low px -> original low px."""
    c = (f - 1.0) / 2.0
    return np.array([[f, 0.0, c], [0.0, f, c]])


def _transform_in_original(t: np.ndarray, model: str, f: float, low_is_coarser: bool):
    s = _to_original(f)
    if not model_of(model).has_ratio:  # the fundamental matrix: x_coarse^T F x_fine = 0
        s_inv = as_matrix3(invert(s))
        return s_inv.T @ t if low_is_coarser else t @ s_inv
    return compose(s, t) if low_is_coarser else compose(t, invert(s))


def in_original_low(result: MatchResult, f: float, config) -> MatchResult:
    """``result`` of a match on the low image shrunk by ``f``, in the original low pixels.

    ``config`` is the configuration the caller asked for (recorded in the result).
    """
    low_is_coarser = result.order == "given"
    # a scale is high px per low px: the low image's pixels grow by f (or, swapped, the finer's)
    g = 1.0 / f if low_is_coarser else f
    rows = tuple(replace(r, s=r.s * g, ratio=r.ratio * g) for r in result.scales)
    evidence = dict(result.evidence, low_working_factor=f)
    out = replace(result, scales=rows, best_scale=result.best_scale * g, config=config,
                  evidence=evidence)
    if not result.matched:
        return out
    t = _transform_in_original(result.transform, result.model, f, low_is_coarser)
    inliers = np.array(result.inliers, dtype=np.float64)
    cols = slice(2, 4) if low_is_coarser else slice(0, 2)
    inliers[:, cols] = inliers[:, cols] * f + (f - 1.0) / 2.0
    if not model_of(result.model).has_ratio:
        return replace(out, transform=t, inliers=inliers)
    ratio, angle, tr = similarity_parts(t)
    return replace(out, transform=t, inliers=inliers, resolution_ratio=ratio,
                   rotation_deg=angle, translation=tr)
