"""The finer image placed on the coarser one by a map, for the pixel tests
(:mod:`scalematch.stages.pixelcheck`, :mod:`scalematch.stages.uniqueness`,
:mod:`scalematch.stages.nearby`): blurred for its resolution ratio ``r`` (the camera model of
EVALUATION.md: a Gaussian of std ``0.5 sqrt(r^2 - 1)`` high px before shrinking by ``r``), and
warped (``warp_into``); a footprint too large for a test is compared on the coarser image
shrunk (``shrunk``, ``place``).

Cheap by construction: the high image is first shrunk by an integer factor ``k ~ r / 2`` with
``cv2.INTER_AREA`` (a box filter) and blurred by the rest of the camera blur on the small copy
(``blurred_for_ratio``); ``small_to_high`` maps the small copy's pixels back.

Pixel convention: OpenCV's, (x, y), pixel centres at integers.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Tuple, Union

import cv2
import numpy as np

from ..geometry import as_matrix3, footprint, ratio_at

def blurred_for_ratio(high: np.ndarray, ratio: float,
                      camera_blur_px: float = 0.5) -> Tuple[np.ndarray, int]:
    """The high image (h, w) with the camera blur of ``ratio``, on a copy shrunk by ``k``.

    Returns (small, k): ``small[y_s, x_s]`` is the high image blurred by
    ``camera_blur_px * sqrt(ratio^2 - 1)`` high px sampled at ``x = k x_s + (k - 1) / 2``
    (``cv2.INTER_AREA``'s centre-aligned box, variance ``(k^2 - 1) / 12`` high px^2, counted in
    the blur). ``k = max(1, floor(ratio / 2))`` keeps two small pixels per low pixel.
    """
    img = np.asarray(high, np.float32)
    r = max(float(ratio), 1.0)
    k = max(1, int(r // 2))
    h, w = img.shape
    k = min(k, max(1, min(h, w) // 8))
    if k > 1:
        img = cv2.resize(img[: (h // k) * k, : (w // k) * k], (w // k, h // k),
                         interpolation=cv2.INTER_AREA)
    total = camera_blur_px * math.sqrt(max(r * r - 1.0, 0.0))
    rest = math.sqrt(max(total * total - (k * k - 1) / 12.0, 0.0)) / k
    if rest > 0.05:
        img = cv2.GaussianBlur(img, (0, 0), rest, borderType=cv2.BORDER_REFLECT_101)
    return img, k


def quad_area(q: np.ndarray) -> float:
    """Area of a quadrilateral (4, 2) given in order (half the cross product of its diagonals)."""
    d1, d2 = q[2] - q[0], q[3] - q[1]
    return 0.5 * abs(float(d1[0] * d2[1] - d1[1] * d2[0]))


def small_to_high(k: int) -> np.ndarray:
    """3x3 map from the shrunk copy's px to high px: x = k x_s + (k - 1) / 2."""
    c = (k - 1) / 2.0
    return np.array([[k, 0.0, c], [0.0, k, c], [0.0, 0.0, 1.0]])


def warp_into(small: np.ndarray, m3: np.ndarray, size: Tuple[int, int],
              edge_px: int) -> Tuple[np.ndarray, np.ndarray]:
    """Warp ``small`` by the 3x3 map ``m3`` (small px -> box px) onto a box of ``size`` (w, h);
    returns (image, valid mask)."""
    ones = np.ones(small.shape, np.uint8)
    if abs(m3[2, 0]) < 1e-15 and abs(m3[2, 1]) < 1e-15:
        m = (m3 / m3[2, 2])[:2]
        img = cv2.warpAffine(small, m, size, flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        mask = cv2.warpAffine(ones, m, size, flags=cv2.INTER_NEAREST,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    else:
        img = cv2.warpPerspective(small, m3, size, flags=cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        mask = cv2.warpPerspective(ones, m3, size, flags=cv2.INTER_NEAREST,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    if edge_px > 0:
        mask = cv2.erode(mask, np.ones((2 * edge_px + 1,) * 2, np.uint8),
                         borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return img, mask.astype(bool)


def shrunk(image: np.ndarray, factor: float) -> Tuple[np.ndarray, np.ndarray]:
    """``image`` shrunk by about ``factor`` (INTER_AREA) and the 3x3 map from its px to the
    shrunk px (centre-aligned: x_s = (x + 0.5) / f - 0.5 with f the factor actually used)."""
    h, w = image.shape
    ow, oh = max(int(round(w / factor)), 1), max(int(round(h / factor)), 1)
    fx, fy = w / ow, h / oh
    out = cv2.resize(image, (ow, oh), interpolation=cv2.INTER_AREA)
    m = np.array([[1.0 / fx, 0.0, 0.5 / fx - 0.5], [0.0, 1.0 / fy, 0.5 / fy - 0.5],
                  [0.0, 0.0, 1.0]])
    return out, m


class Placed(NamedTuple):
    """A hypothesis ready to be warped: at most ``max_side_px`` of footprint (``low`` shrunk
    and the map with it, centre-aligned, when it was larger)."""

    low: np.ndarray  #: the low image, maybe shrunk
    t3: np.ndarray  #: 3x3 high px -> (shrunk) low px
    ratio: float  #: the map's ratio, high px per (shrunk) low px
    corners: np.ndarray  #: (4, 2) the footprint in (shrunk) low px
    area: float  #: its area, (shrunk) low px^2


def local_ratio(t3: np.ndarray, high_shape: Tuple[int, int]) -> float:
    """High px per low px of the 3x3 map ``t3`` at the high image's centre
    (:func:`scalematch.geometry.ratio_at` there). For an affine map (w = 1 everywhere) it is the ratio of
    :func:`scalematch.geometry.similarity_parts`; for a homography it is the ratio where the
    footprint is, not at the high image's origin (in perspective, a factor 4 and more apart
    across the footprint: the high image is blurred for its middle).

    >>> h = np.array([[0.5, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 1.0]])
    >>> local_ratio(h, (101, 201)), local_ratio(h * 3.0, (101, 201))
    (2.0, 2.0)
    >>> round(local_ratio(np.array([[0.5, 0, 0], [0, 0.5, 0], [0.01, 0, 1.0]]), (101, 201)), 3)
    5.657
    """
    h, w = high_shape[:2]
    return ratio_at(np.asarray(t3, np.float64), ((w - 1) / 2.0, (h - 1) / 2.0))


def place(low: np.ndarray, high_shape: Tuple[int, int], t: np.ndarray,
          min_overlap_px: float, max_side_px: float) -> Union[Placed, str]:
    """The hypothesis ``t`` placed on ``low`` (:class:`Placed`), or why it cannot be: no
    footprint, a footprint under ``min_overlap_px`` low px^2, a singular map. A footprint
    larger than ``max_side_px`` (sqrt of its area) is placed on ``low`` shrunk to it
    (``PixelParams.min_overlap_px`` and ``max_side_px`` of :mod:`scalematch.stages.pixelcheck`)."""
    t3 = as_matrix3(np.asarray(t, np.float64))
    corners = footprint(t3, high_shape)
    if corners is None or not np.all(np.isfinite(t3)):
        return "the transform has no footprint"
    area = quad_area(corners)
    if area < min_overlap_px:
        return f"footprint of {area:.0f} low px^2 (< {min_overlap_px:g})"
    ratio = local_ratio(t3, high_shape)
    if not (math.isfinite(ratio) and ratio > 0):
        return "the transform is singular"
    q = min(1.0, max_side_px / math.sqrt(area))
    if q < 1.0:  # work on the low image shrunk by 1/q: the maps gain a centre-aligned scaling
        low, shrink = shrunk(low, 1.0 / q)
        t3 = shrink @ t3
        ratio, corners, area = (ratio / shrink[0, 0], footprint(t3, high_shape),
                                area * shrink[0, 0] ** 2)
    return Placed(low, t3, ratio, corners, area)


def vouched_mask(shape: Tuple[int, int], xy: np.ndarray, radius: float) -> np.ndarray:
    """(H, W) bool: the discs of ``radius`` px around the points ``xy`` (N, 2), (x, y) px.

    >>> m = vouched_mask((20, 30), np.array([[5.0, 5.0], [25.0, 15.0]]), 3)
    >>> bool(m[5, 5]), bool(m[15, 25]), bool(m[10, 15]), int(m.sum())
    (True, True, False, 58)
    """
    out = np.zeros(shape, np.uint8)
    r = max(int(round(radius)), 1)
    for x, y in np.rint(np.asarray(xy, np.float64)).astype(int):
        cv2.circle(out, (int(x), int(y)), r, 1, thickness=-1)
    return out.astype(bool)
