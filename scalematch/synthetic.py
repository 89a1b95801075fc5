"""Synthetic zoom pairs with exact ground truth (EVALUATION.md, "Synthetic zoom pairs").

``zoom_warp`` is the camera model: blur by 0.5*sqrt(r^2 - 1), rotate by theta and shrink by r in
one affine warp onto a canvas that holds the whole rotated image. Everything else that cuts
pairs (crops, grey-level change, noise, window cut) builds on it.
"""

from __future__ import annotations

import math
from typing import Tuple

import cv2
import numpy as np

from .scalespace import CAMERA_BLUR_PX


def similarity_matrix(scale: float, angle_deg: float, tx: float = 0.0, ty: float = 0.0) -> np.ndarray:
    """2x3 matrix of x' = scale * R(angle) x + t (angle counter-clockwise on screen is negative)."""
    a = math.radians(angle_deg)
    c, s = scale * math.cos(a), scale * math.sin(a)
    return np.array([[c, -s, tx], [s, c, ty]], dtype=np.float64)


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """2x3 of ``a o b`` (apply b first, then a)."""
    a3 = np.vstack([a, [0, 0, 1]])
    b3 = np.vstack([b, [0, 0, 1]])
    return (a3 @ b3)[:2]


def apply(t: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Map (N, 2) points by a 2x3 affine or a 3x3 homography."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    t = np.asarray(t, dtype=np.float64)
    if t.shape == (2, 3):
        return xy @ t[:, :2].T + t[:, 2]
    p = np.hstack([xy, np.ones((xy.shape[0], 1))]) @ t.T
    return p[:, :2] / p[:, 2:3]


def zoom_warp(image: np.ndarray, ratio: float, angle_deg: float,
              interpolation: int = cv2.INTER_LINEAR) -> Tuple[np.ndarray, np.ndarray]:
    """Blur, rotate by ``angle_deg`` and shrink by ``ratio`` with one warp; return (image, A).

    The output canvas holds the whole rotated, shrunk image; ``A`` (2x3) maps a pixel of
    ``image`` to its pixel in the output (OpenCV convention, pixel centres at integers).
    """
    img = np.asarray(image)
    blur = CAMERA_BLUR_PX * math.sqrt(max(ratio * ratio - 1.0, 0.0))
    if blur > 0.05:
        img = cv2.GaussianBlur(img, (0, 0), blur, borderType=cv2.BORDER_REFLECT_101)
    h, w = img.shape[:2]
    lin = similarity_matrix(1.0 / ratio, angle_deg)
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=np.float64)
    mapped = apply(lin, corners)
    lo = mapped.min(axis=0)
    hi = mapped.max(axis=0)
    size = np.ceil(hi - lo).astype(int) + 1
    a = lin.copy()
    a[:, 2] = -lo
    out = cv2.warpAffine(img, a, (int(size[0]), int(size[1])), flags=interpolation,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out, a
