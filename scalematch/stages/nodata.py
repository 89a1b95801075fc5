"""Where an image shows no scene: the constant no-data regions that touch its border.

A rectified or georeferenced image sits on a canvas whose corners hold no data (black, most
often); a rotated scan or a stitched panorama has the same. Such a region is no part of the
scene, yet its edge with the picture is the strongest corner an image can have, and in a pixel
comparison it correlates with nothing. So the detector keeps its points away from it (their
descriptor window would straddle the edge), and the pixel tests leave it out
(:mod:`scalematch.stages.pixelcheck`, as NaN).

A no-data region here is a connected region of one grey level (within ``NODATA_TOLERANCE``)
that touches the image's border and covers at least ``NODATA_MIN_SHARE`` of it. A photograph's
clipped sky can meet that definition; its points near the clip edge are then left out too,
which costs a few points and makes no false claim.

Pixel convention: OpenCV's, (x, y), pixel centres at integers.
"""

from __future__ import annotations

from typing import Optional

import cv2
import numpy as np

#: Grey levels a no-data pixel may differ from the region's value: an exact canvas fill, and
#: the rounding of a resize at working size (an 8-bit no-data region stays within one level)
NODATA_TOLERANCE = 2.0
#: Smallest share of the image a no-data region covers: a canvas corner of a 10-degree turn
#: holds about 8 % of the canvas, so 0.5 % keeps any real canvas and leaves out a dark pixel
#: run along a photo's edge
NODATA_MIN_SHARE = 0.005
#: A no-data region is solid: it holds this square (px) wherever it is thinner, it is part of
#: the picture (a one-pixel line or a stripe of one grey level)
NODATA_CORE_PX = 5
_CORE = np.ones((NODATA_CORE_PX, NODATA_CORE_PX), np.uint8)


def border_value(image: np.ndarray) -> float:
    """The most common grey level (rounded) of the image's outermost pixel ring."""
    img = np.asarray(image, np.float32)
    ring = np.concatenate([img[0], img[-1], img[1:-1, 0], img[1:-1, -1]])
    values, counts = np.unique(np.rint(ring), return_counts=True)
    return float(values[np.argmax(counts)])


def valid_mask(image: np.ndarray, tolerance: float = NODATA_TOLERANCE,
               min_share: float = NODATA_MIN_SHARE) -> Optional[np.ndarray]:
    """(H, W) bool, True where ``image`` shows the scene; None when it shows it everywhere.

    The no-data region is every connected region (4-neighbours) of pixels within
    ``tolerance`` of the border's most common grey level (:func:`border_value`) that touches
    the border, kept when together they cover at least ``min_share`` of the image.

    >>> img = np.full((60, 80), 120.0, np.float32); img[::2] += 40   # a striped picture ...
    >>> canvas = np.zeros((100, 120), np.float32); canvas[20:80, 20:100] = img  # ... on black
    >>> valid = valid_mask(canvas)
    >>> int(valid.sum()), bool(valid[50, 60]), bool(valid[5, 5])
    (4800, True, False)
    >>> valid_mask(img) is None                                      # no canvas
    True
    """
    img = np.asarray(image, np.float32)
    h, w = img.shape
    if h < 3 or w < 3:
        return None
    near = (np.abs(img - border_value(img)) <= tolerance).astype(np.uint8)
    # a canvas is a solid region: thin runs of one level (a line, a stripe) are not
    solid = cv2.erode(near, _CORE, borderType=cv2.BORDER_CONSTANT, borderValue=1)
    n, labels = cv2.connectedComponents(solid, connectivity=4)
    if n <= 1:
        return None
    ring = np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]])
    touching = np.unique(ring[ring > 0])
    if touching.size == 0:
        return None
    core = np.isin(labels, touching).astype(np.uint8)
    nodata = cv2.dilate(core, _CORE, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
    nodata &= near.astype(bool)
    if nodata.sum() < min_share * h * w:
        return None
    return ~nodata


def distance_inside(valid: Optional[np.ndarray]) -> Optional[np.ndarray]:
    """(H, W) float32 distance (px) from each pixel to the nearest no-data pixel; None when
    ``valid`` is None (no no-data)."""
    if valid is None:
        return None
    return cv2.distanceTransform(valid.astype(np.uint8), cv2.DIST_L2, 3)


def away_from(inside: np.ndarray, xy: np.ndarray, margin_px) -> np.ndarray:
    """Boolean mask of the points (N, 2) (x, y px) at least ``margin_px`` (a number, or one per
    point) from the nearest pixel outside, given ``inside`` (H, W): each pixel's distance to it.

    >>> away_from(distance_inside(np.pad(np.ones((5, 5), bool), 1)), np.array([[1, 1], [3, 3]]), 2)
    array([False,  True])
    """
    h, w = inside.shape
    x = np.clip(np.rint(xy[:, 0]).astype(int), 0, w - 1)
    y = np.clip(np.rint(xy[:, 1]).astype(int), 0, h - 1)
    return inside[y, x] >= margin_px


def with_nan(image: np.ndarray, valid: Optional[np.ndarray]) -> np.ndarray:
    """``image`` as float32 with NaN where it shows no scene and on the pixel ring next to it,
    which interpolation mixed with the fill (itself when ``valid`` is None)."""
    if valid is None:
        return image
    out = np.array(image, np.float32, copy=True)
    out[cv2.erode(valid.astype(np.uint8), np.ones((3, 3), np.uint8),
                  borderType=cv2.BORDER_CONSTANT, borderValue=1) == 0] = np.nan
    return out
