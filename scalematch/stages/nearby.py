"""The placements near a map, searched by the pixels: does the map sit where the pixels fit best?

A map of few inliers is pinned by few points. On a repeated texture (a facade of equal windows)
a handful of points can agree on a copy of the scene off by the spacing of its windows, at a
scale a few percent off, and its pixels then fit well but not as well as the true placement a
fifth to a third of the footprint away (docs/design/DECISION.md, "Placed better nearby"). The pixel check's 8 perturbed placements
(:mod:`scalematch.stages.pixelcheck`) sit a quarter of the footprint away and tell a lucky
placement from its neighbours; the uniqueness test slides the footprint beyond half of it. This
searches between: every scale within one scale step of the map's (``PixelParams.scale_step``),
every angle within ``PixelParams.rotation_deg``, every shift within
``PixelParams.unique_exclusion`` of the footprint, and gives the best placement and its ZNCC.

How: the finer image, blurred for its ratio (:func:`scalematch.stages.placing.blurred_for_ratio`),
is warped for each scale and angle about the footprint's centre onto a template at most
``PixelParams.unique_side_px`` on its side; every shift is one correlation over the coarser
image (:func:`scalematch.stages.uniqueness.masked_zncc`), compared only where both images show
the scene (NaN elsewhere).
Each step of the grid moves the footprint's edge by at most half the inlier threshold (1.5 of
3 px at 64 px): 2.5 degrees and a scale factor of about 1.044.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Optional

import cv2
import numpy as np

from ..geometry import as_matrix3, footprint, similarity_matrix
from .pixelcheck import PixelParams
from .placing import blurred_for_ratio, local_ratio, quad_area, shrunk, small_to_high
from .uniqueness import masked_zncc

#: angle of one step of the grid, degrees: 2.5 moves the edge of a 64 px footprint by 1.4 px,
#: half the 3 px inlier threshold (``RansacParams.threshold_px``)
ANGLE_STEP_DEG = 2.5
#: scale factor of one step of the grid: 1.044 moves the edge of a 64 px footprint by 1.4 px
SCALE_STEP = 1.044


class Nearby(NamedTuple):
    """The best placement near a map (:func:`best_nearby`)."""

    claimed: float  #: ZNCC at the map itself (nan: cannot tell)
    best: float  #: the highest ZNCC of every placement searched, the map's included
    #: how far the best placement is from the map: the mean distance of their footprints'
    #: corners, as a fraction of the footprint's size (sqrt of its area)
    moved: float
    transform: Optional[np.ndarray]  #: the best placement, finer px -> coarser px (3x3)


def _about(centre: np.ndarray, scale: float, angle_deg: float) -> np.ndarray:
    """3x3: turn by ``angle_deg`` and scale by ``scale`` about ``centre`` (x, y), as
    :func:`scalematch.stages.pixelcheck.perturbations` turns and scales its placements."""
    m = as_matrix3(similarity_matrix(scale, angle_deg))
    m[:2, 2] = centre - m[:2, :2] @ centre
    return m


def _grid(step: float, reach: float) -> np.ndarray:
    """0, +-step, +-2 step ... up to +-reach (reach itself the last)."""
    n = max(int(math.ceil(reach / step - 1e-9)), 0)
    half = np.minimum(np.arange(1, n + 1) * step, reach)
    return np.concatenate([[0.0], half, -half])


class _Frame(NamedTuple):
    """The two images as the placements are scored: the coarser one shrunk so that the
    footprint is at most ``unique_side_px`` (``shrink`` maps its px there) and padded, the finer
    one blurred for the ratio on a copy shrunk by an integer factor (``to_finer`` maps its px
    back)."""

    low: np.ndarray  #: the coarser image, shrunk and padded by ``pad``, 0 where no scene
    low_valid: np.ndarray  #: where it shows the scene
    pad: int
    shrink: np.ndarray  #: 3x3, coarser px -> shrunk px
    small: np.ndarray  #: the finer image blurred and shrunk
    small_seen: np.ndarray  #: float32, 1 where it shows the scene, blurred with it
    to_finer: np.ndarray  #: 3x3, small px -> finer px


def _frame(coarser: np.ndarray, finer: np.ndarray, t3: np.ndarray, size: float,
           params: PixelParams) -> Optional[_Frame]:
    """The images of :func:`best_nearby` for a map ``t3`` whose footprint is ``size`` px
    (None: a singular map)."""
    q = min(1.0, params.unique_side_px / size)
    valid = np.isfinite(coarser)
    low = np.where(valid, coarser, 0).astype(np.float32)
    shrink = np.eye(3)
    if q < 1.0:
        low, shrink = shrunk(low, 1.0 / q)
        valid = cv2.resize(valid.astype(np.uint8), low.shape[::-1],
                           interpolation=cv2.INTER_NEAREST) > 0
    ratio = local_ratio(shrink @ t3, finer.shape)
    if not (math.isfinite(ratio) and ratio > 0):
        return None
    seen = np.isfinite(finer)
    small, k = blurred_for_ratio(np.where(seen, finer, 0).astype(np.float32), ratio,
                                 params.camera_blur_px)
    small_seen, _ = blurred_for_ratio(seen.astype(np.float32), ratio, params.camera_blur_px)
    pad = int(round(params.unique_exclusion * size * q)) + \
        2 * int(math.ceil(size * q * params.scale_step)) + 4
    return _Frame(cv2.copyMakeBorder(low, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=0),
                  np.pad(valid, pad), pad, shrink, small, small_seen, small_to_high(k))


def _scores(f: _Frame, placed: np.ndarray, finer_shape, reach: int) -> Optional[np.ndarray]:
    """ZNCC of the finer image placed by ``placed`` (finer px -> shrunk coarser px) at every
    shift within ``reach`` px ((2 reach + 1, 2 reach + 1); None: out of the padded image)."""
    corners = footprint(placed, finer_shape)
    x0, y0 = np.floor(corners.min(axis=0)).astype(int)
    x1, y1 = np.ceil(corners.max(axis=0)).astype(int)
    w, h = x1 - x0 + 1, y1 - y0 + 1
    ys, xs = y0 - reach + f.pad, x0 - reach + f.pad
    if ys < 0 or xs < 0 or ys + h + 2 * reach > f.low.shape[0] \
            or xs + w + 2 * reach > f.low.shape[1]:
        return None
    m = as_matrix3(similarity_matrix(1.0, 0.0, -x0, -y0)) @ placed @ f.to_finer
    tpl = cv2.warpPerspective(f.small, m, (w, h), flags=cv2.INTER_LINEAR)
    # bilinear: a pixel that mixes in the no-scene side, or the border, falls below 1
    tpl_ok = cv2.warpPerspective(f.small_seen, m, (w, h), flags=cv2.INTER_LINEAR) > 0.99
    if not tpl_ok.any():
        return None
    rows, cols = slice(ys, ys + h + 2 * reach), slice(xs, xs + w + 2 * reach)
    return masked_zncc(f.low[rows, cols], f.low_valid[rows, cols], tpl, tpl_ok)


def best_nearby(coarser: np.ndarray, finer: np.ndarray, t: np.ndarray,
                params: PixelParams = PixelParams()) -> Nearby:
    """The placement of ``finer`` in ``coarser`` that fits the pixels best near the map ``t``
    (finer px -> coarser px; similarity, affine or homography): every scale within
    ``params.scale_step`` and angle within ``params.rotation_deg`` about the footprint's centre,
    every shift within ``params.unique_exclusion`` of the footprint's size (the module's
    docstring). Both images are grey levels with NaN where they show no scene. A map without
    a footprint, or whose footprint shares no textured pixels with the coarser image, gives
    nan figures."""
    nothing = Nearby(math.nan, math.nan, math.nan, None)
    t3 = as_matrix3(np.asarray(t, np.float64))
    corners = footprint(t3, finer.shape) if np.all(np.isfinite(t3)) else None
    if corners is None:
        return nothing
    size = math.sqrt(quad_area(corners))
    f = _frame(coarser, finer, t3, size, params) if size > 0 else None
    if f is None:
        return nothing
    tq = f.shrink @ t3
    centre = footprint(tq, finer.shape).mean(axis=0)
    reach = int(round(params.unique_exclusion * size * f.shrink[0, 0]))
    claimed, best, best_t = math.nan, -1.0, None
    for scale in np.exp(_grid(math.log(SCALE_STEP), math.log(params.scale_step))):
        for angle in _grid(ANGLE_STEP_DEG, params.rotation_deg):
            placed = _about(centre, float(scale), float(angle)) @ tq
            score = _scores(f, placed, finer.shape, reach)
            if score is None:
                continue
            if scale == 1.0 and angle == 0.0 and score[reach, reach] > -1.0:
                claimed = float(score[reach, reach])
            j = np.unravel_index(int(np.argmax(score)), score.shape)
            if score[j] > best:
                shift = as_matrix3(similarity_matrix(1.0, 0.0, j[1] - reach, j[0] - reach))
                best, best_t = float(score[j]), np.linalg.inv(f.shrink) @ shift @ placed
    if best_t is None:
        return nothing
    moved = float(np.linalg.norm(footprint(best_t, finer.shape) - corners, axis=1).mean())
    return Nearby(claimed, best, moved / size, best_t)
