"""Pairs with what real photographs bring (EVALUATION.md, "Pairs with what real photographs
bring"): a synthetic zoom pair with one realistic change, its truth composed exactly.

Clean crops flatter a matcher: a rectified or georeferenced image sits on a canvas with no-data
corners, a foreground object covers part of a scene, a telephoto frame overhangs the wide one,
and the light changes between two shots. Each function below takes a :class:`ZoomPair` (truth a
2x3 similarity, high px -> low px) and returns a new one with one of these changes; the null
pairs get the same changes (:func:`padded_null`), since a canvas border is itself a strong corner.

Every draw comes from the ``rng`` given, so a pair depends on its seed only.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Tuple

import cv2
import numpy as np

from ..geometry import apply, as_matrix3, compose, invert, similarity_matrix
from .synthetic import ZoomPair

#: Turn of a padded image on its canvas, degrees, drawn in [lo, hi) with a random sign: from a
#: rectified image's few degrees to a georeferenced tile's half-right-angle corners
PAD_ANGLE_RANGE = (10.0, 50.0)
#: Share of the high image an occluder covers (EVALUATION.md: "10 to 40 %")
OCCLUDER_SHARE_RANGE = (0.10, 0.40)
#: Aspect ratio (width / height) of an occluder, drawn log-uniformly in [1/x, x]
OCCLUDER_ASPECT = 2.0
#: Share of the high image's footprint left inside the low image (EVALUATION.md: "30 to 70 %")
INSIDE_RANGE = (0.30, 0.70)
#: Gammas of the relit pairs (EVALUATION.md: "gamma 0.5 or 2")
GAMMAS = (0.5, 2.0)
#: Darkest end of the shading falloff, as a gain: a ramp from 1 to this across the image
FALLOFF_GAIN_RANGE = (0.4, 0.7)
#: JPEG quality of the relit pairs (EVALUATION.md: "30 to 50")
JPEG_QUALITY_RANGE = (30, 50)
#: Kinds of change, in the order of the benchmark's tables
KINDS = ("padded", "occluded", "partial", "relit")


def on_canvas(image: np.ndarray, angle_deg: float, fill: float = 0.0) -> Tuple[np.ndarray, np.ndarray]:
    """``image`` (h, w) turned by ``angle_deg`` about its centre on a canvas that holds it whole,
    the corners filled with ``fill``; returns (canvas, R) with R (2x3) mapping an image px to its
    canvas px.

    >>> canvas, r = on_canvas(np.ones((40, 60), np.float32), 90.0)
    >>> canvas.shape, np.round(apply(r, [[0.0, 0.0]]), 6).tolist()
    ((60, 40), [[39.0, 0.0]])
    """
    img = np.asarray(image, np.float32)
    h, w = img.shape
    lin = similarity_matrix(1.0, angle_deg)
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float64)
    mapped = apply(lin, corners)
    lo = mapped.min(axis=0)
    size = np.ceil(mapped.max(axis=0) - lo).astype(int) + 1
    r = lin.copy()
    r[:, 2] = -lo
    out = cv2.warpAffine(img, r, (int(size[0]), int(size[1])), flags=cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=float(fill))
    return out, r


def _signed_angle(rng: np.random.Generator) -> float:
    return float(rng.uniform(*PAD_ANGLE_RANGE) * rng.choice([-1.0, 1.0]))


def padded(pair: ZoomPair, rng: np.random.Generator) -> ZoomPair:
    """The high image turned on a black-cornered canvas (a rectified or georeferenced image
    with no-data borders); the truth follows: ``truth o R^-1``."""
    high, r = on_canvas(pair.high, _signed_angle(rng))
    truth = None if pair.truth is None else compose(pair.truth, invert(r))
    return replace(pair, high=high, truth=truth)


def padded_null(pair: ZoomPair, rng: np.random.Generator) -> ZoomPair:
    """A null pair (``truth`` None) with both images on black-cornered canvases: two canvases
    must not match each other's corners."""
    if pair.truth is not None:
        raise ValueError("padded_null takes a null pair (truth None)")
    low, _ = on_canvas(pair.low, _signed_angle(rng))
    high, _ = on_canvas(pair.high, _signed_angle(rng))
    return replace(pair, low=low, high=high)


def occluder_box(shape: Tuple[int, int], share: float, rng: np.random.Generator) -> Tuple[int, int, int, int]:
    """(x, y, w, h) of a box covering ``share`` of an image of ``shape`` (h, w), inside it."""
    h, w = shape
    aspect = math.exp(rng.uniform(-math.log(OCCLUDER_ASPECT), math.log(OCCLUDER_ASPECT)))
    bw = int(round(min(w, math.sqrt(share * w * h * aspect))))
    bh = int(round(min(h, share * w * h / max(bw, 1))))
    x = int(rng.integers(0, w - bw + 1))
    y = int(rng.integers(0, h - bh + 1))
    return x, y, bw, bh


def occluded(pair: ZoomPair, other: np.ndarray, rng: np.random.Generator) -> ZoomPair:
    """10-40 % of the high image covered by a patch of ``other`` (another photo, grey): a
    foreground object that the low image does not show. The truth is unchanged."""
    share = float(rng.uniform(*OCCLUDER_SHARE_RANGE))
    x, y, bw, bh = occluder_box(pair.high.shape, share, rng)
    oh, ow = other.shape
    if oh < bh or ow < bw:
        other = cv2.resize(np.asarray(other, np.float32), (max(ow, bw), max(oh, bh)))
        oh, ow = other.shape
    ox = int(rng.integers(0, ow - bw + 1))
    oy = int(rng.integers(0, oh - bh + 1))
    high = np.array(pair.high, np.float32, copy=True)
    high[y:y + bh, x:x + bw] = np.asarray(other, np.float32)[oy:oy + bh, ox:ox + bw]
    return replace(pair, high=high)


def partial(pair: ZoomPair, rng: np.random.Generator) -> ZoomPair:
    """The low image cut across the high image's footprint so that 30-70 % of it (of a grid
    over the high image) lies inside: a telephoto frame overhanging the wide one. The cut runs
    along x or y, keeping the left/top or the right/bottom part; the truth gains the shift."""
    if pair.truth is None:
        raise ValueError("partial takes a pair with a truth")
    want = float(rng.uniform(*INSIDE_RANGE))
    axis = int(rng.integers(0, 2))
    keep_low_side = bool(rng.integers(0, 2))
    h, w = pair.high.shape
    gx, gy = np.meshgrid(np.linspace(0, w - 1, 41), np.linspace(0, h - 1, 41))
    pts = apply(pair.truth, np.column_stack([gx.ravel(), gy.ravel()]))
    values = np.sort(pts[:, axis])
    k = int(round(want * (values.size - 1)))
    cut = float(values[k] if keep_low_side else values[values.size - 1 - k])
    lh, lw = pair.low.shape
    if keep_low_side:
        end = int(min(max(math.floor(cut) + 1, 32), (lw, lh)[axis]))
        low = pair.low[:, :end] if axis == 0 else pair.low[:end, :]
        truth = pair.truth
    else:
        start = int(max(min(math.ceil(cut), (lw, lh)[axis] - 32), 0))
        low = pair.low[:, start:] if axis == 0 else pair.low[start:, :]
        shift = np.array([[1.0, 0.0, -start if axis == 0 else 0.0],
                          [0.0, 1.0, -start if axis == 1 else 0.0]])
        truth = compose(shift, pair.truth)
    return replace(pair, low=np.ascontiguousarray(low), truth=truth)


def relit(pair: ZoomPair, rng: np.random.Generator) -> ZoomPair:
    """The low image relit: a gamma of 0.5 or 2, a shading falloff (a linear ramp of gain from
    1 to 0.4-0.7 across the image in a random direction), then JPEG at quality 30-50."""
    gamma = float(rng.choice(GAMMAS))
    darkest = float(rng.uniform(*FALLOFF_GAIN_RANGE))
    direction = float(rng.uniform(0.0, 2.0 * math.pi))
    quality = int(rng.integers(JPEG_QUALITY_RANGE[0], JPEG_QUALITY_RANGE[1] + 1))
    low = np.clip(np.asarray(pair.low, np.float32), 0, 255) / 255.0
    low = 255.0 * np.power(low, gamma)
    h, w = low.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    along = xx * math.cos(direction) + yy * math.sin(direction)
    along = (along - along.min()) / max(float(along.max() - along.min()), 1.0)
    low = low * (1.0 - (1.0 - darkest) * along)
    ok, buf = cv2.imencode(".jpg", np.clip(np.rint(low), 0, 255).astype(np.uint8),
                           [cv2.IMWRITE_JPEG_QUALITY, quality])
    low = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE).astype(np.float32)
    return replace(pair, low=low)


def oxford_zoom(img1: np.ndarray, imgn: np.ndarray, h1n: np.ndarray,
                shrink: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(low, high, truth 3x3 high px -> low px): ``high`` = img1, ``low`` = imgN shrunk by
    ``shrink`` (``cv2.INTER_AREA``, centre-aligned), truth the shrink composed with H1toN."""
    h, w = imgn.shape
    ow, oh = max(int(round(w / shrink)), 1), max(int(round(h / shrink)), 1)
    low = cv2.resize(np.asarray(imgn, np.float32), (ow, oh), interpolation=cv2.INTER_AREA)
    fx, fy = w / ow, h / oh
    s = np.array([[1.0 / fx, 0.0, 0.5 / fx - 0.5], [0.0, 1.0 / fy, 0.5 / fy - 0.5],
                  [0.0, 0.0, 1.0]])
    truth = s @ as_matrix3(h1n)
    return low, np.asarray(img1, np.float32), truth / truth[2, 2]
