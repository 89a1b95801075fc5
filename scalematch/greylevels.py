"""Grey levels: any decoded image array, or one given to ``match``, as float32 8-bit grey levels,
checked for what would leave nothing to match; a grey image drawn as 8-bit BGR.

Colour is turned to grey with ITU-R BT.601 luma (0.299 R + 0.587 G + 0.114 B, cv2.COLOR_BGR2GRAY);
16-bit images are scaled to the 8-bit range (so thresholds in grey levels mean the same thing);
floats at most ``UNIT_FLOAT_MAX`` are taken as [0, 1]; the alpha channel of RGBA images is
ignored. Errors are ``ImageError`` (:mod:`scalematch.imagefile`).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import cv2
import numpy as np

from .headers import MAX_TIFF_PAGES
from .imagefile import ImageError, pages_of
from .stages.detector import MIN_SIDE_PX

#: A float image whose largest value is at most this is taken as scaled to [0, 1] (scikit-image's
#: convention) and multiplied by 255: a [0, 1] image brightened, or resampled with a cubic
#: kernel, overshoots 1 a little (a copy brightened 8 % reached 1.03 and, read as 0-255 grey
#: levels, matched nothing), while grey levels 0-255 whose brightest pixel is under 2 hold
#: less than two levels of contrast, nothing to match either way
UNIT_FLOAT_MAX = 2.0


def _level_scale(img: np.ndarray) -> float:
    """The factor that brings ``img``'s values to 8-bit grey levels: 255/65535 for 16-bit, 255
    for floats at most ``UNIT_FLOAT_MAX`` (an image in [0, 1]), else 1."""
    if img.dtype == np.uint16:
        return 255.0 / 65535.0
    if img.dtype.kind == "f" and img.size and float(np.nanmax(img)) <= UNIT_FLOAT_MAX:
        return 255.0
    return 1.0


def to_grey(image: np.ndarray) -> np.ndarray:
    """Any decoded image array (H, W), (H, W, 3) BGR or (H, W, 4) BGRA -> (H, W) float32 grey levels.

    >>> bgr = np.array([[[0, 0, 255], [255, 255, 255]]], np.uint8)  # a red, a white pixel
    >>> to_grey(bgr).astype(float).round(2).tolist()
    [[76.24, 255.0]]
    """
    img = np.asarray(image)
    scale = _level_scale(img)
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[:, :, :3]
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img.astype(np.float32), cv2.COLOR_BGR2GRAY)
    elif img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim != 2:
        raise ImageError(f"unsupported image layout {img.shape}")
    out = np.array(img, dtype=np.float32, order="C")  # always a copy: the caller's stays intact
    if scale != 1.0:  # in place: one pass and one image less (a 24 MP one: 40 ms)
        out *= np.float32(scale)
    return out


def to_bgr8(image: np.ndarray) -> np.ndarray:
    """Any image array (grey float in grey levels or in [0, 1], as :func:`to_grey` reads it;
    8/16-bit, BGR, BGRA) -> uint8 (H, W, 3) BGR."""
    img = np.asarray(image)
    scale = _level_scale(img)
    if scale != 1.0:
        img = img.astype(np.float32) * np.float32(scale)
    img = np.clip(np.nan_to_num(img.astype(np.float32)), 0, 255).astype(np.uint8) \
        if img.dtype != np.uint8 else img
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.shape[2] == 1:
        return cv2.cvtColor(img[:, :, 0], cv2.COLOR_GRAY2BGR)
    if img.shape[2] == 4:
        return np.ascontiguousarray(img[:, :, :3])
    return np.ascontiguousarray(img)


def grey_levels(image: np.ndarray, name: str = "image") -> np.ndarray:
    """The check at the edge of ``match``: a 2-D grey array (or one channel, (H, W, 1)) ->
    float32 8-bit grey levels.

    Scaled as ``to_grey`` scales: floats at most ``UNIT_FLOAT_MAX`` (images in [0, 1],
    scikit-image's convention, a little past 1 when brightened or resampled) by 255, 16-bit by
    255/65535; other values are taken as grey levels. Raises ``ImageError`` (a ``ValueError``)
    for what would otherwise give "no match" without saying why: a bool array, a NaN or infinite
    value, a constant image; a side under ``MIN_SIDE_PX``.
    """
    img = np.asarray(image)
    if img.dtype == np.bool_:
        raise ImageError(f"the {name} image is a bool array (a mask?); give grey levels, "
                         f"e.g. image.astype(np.uint8) * 255")
    if isinstance(image, (str, os.PathLike)) or img.dtype.kind in "USO" and img.ndim == 0:
        raise ImageError(f"the {name} image is a path ({str(image)!r}), not an array; read it "
                         f"first: scalematch.read_grey({str(image)!r})")
    if img.dtype.kind not in "uif":
        raise ImageError(f"the {name} image has dtype {img.dtype}; give grey levels as an "
                         f"integer or float array (scalematch.read_grey reads an image file)")
    if img.ndim == 3 and img.shape[2] == 1:  # one channel, as some readers give grey images
        img = img[:, :, 0]
    if img.ndim != 2:
        raise ImageError(f"the {name} image has shape {img.shape}; give a 2-D grey image "
                         f"(scalematch.read_grey reads and converts any image file)")
    if min(img.shape) < MIN_SIDE_PX:
        raise ImageError(f"the {name} image is {img.shape[1]}x{img.shape[0]} px; at least "
                         f"{MIN_SIDE_PX} px on each side is needed")
    problem = _levels_problem(img)
    if problem:
        raise ImageError(f"the {name} image {problem}")
    return to_grey(img)


def _levels_problem(img: np.ndarray) -> str:
    """What leaves nothing to match in the grey levels of ``img``, or "": NaN or infinite
    values, or a constant image."""
    lo, hi = float(img.min()), float(img.max())  # nan when any value is nan
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "holds NaN or infinite values; replace them (e.g. np.nan_to_num) or crop them out"
    if lo == hi:
        return f"is constant (every pixel {lo:g}): there is nothing to match in it"
    return ""


def grey_of_file(image: np.ndarray, path: str | Path) -> np.ndarray:
    """The grey levels (:func:`to_grey`) of ``image``, decoded from the file ``path``;
    ``ImageError`` naming the file when they leave nothing to match (a constant image, NaN
    or infinite values), as :func:`grey_levels` would without its name. Of a TIFF of several
    pages only the first is decoded, and a blank first page is common (a cover, a mask): the
    message then says so.

    >>> grey_of_file(np.full((30, 40), 7, np.uint8), "flat.png")
    Traceback (most recent call last):
    ...
    scalematch.imagefile.ImageError: flat.png: image is constant (every pixel 7): there is nothing to match in it
    """
    grey = to_grey(image)
    problem = _levels_problem(grey)
    if problem:
        pages = pages_of(Path(path))
        if pages > 1:  # the page read may not be the one the user looks at
            more = " or more" if pages >= MAX_TIFF_PAGES else ""
            raise ImageError(f"{path}: image {problem}; the file is a TIFF of {pages}{more} "
                             f"pages and only the first is read: save the page wanted as an "
                             f"image file of its own")
        raise ImageError(f"{path}: image {problem}")
    return grey
