"""Shared fixtures: the photo the repo ships (grey, and a colour crop of it), the pictures' pair
cut from it, and the shared data folder when it is present ($SCALEMATCH_SHARED, else ../shared
beside the repository)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from scalematch.geometry import compose
from scalematch.imageio import read_grey
from scalematch.lab.datasets import find_shared
from scalematch.lab.synthetic import zoom_warp

ROOT = Path(__file__).resolve().parents[1]
#: where the commands look too (``find_shared``): $SCALEMATCH_SHARED, else ../shared
SHARED = find_shared() or ROOT.parent / "shared"


@pytest.fixture(scope="session")
def raccoon() -> np.ndarray:
    """data/raccoon.jpg (public domain, 1024x768) as float32 grey levels."""
    return read_grey(ROOT / "data" / "raccoon.jpg")


@pytest.fixture(scope="module")
def bgr() -> np.ndarray:
    """A 120x160 colour crop of the raccoon photo (non-square, so rotations show)."""
    img = cv2.imread(str(ROOT / "data" / "raccoon.jpg"), cv2.IMREAD_COLOR)
    return np.ascontiguousarray(img[300:420, 400:560])


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """The shared data folder, or skip the test when it is absent."""
    if not (SHARED / "data" / "photos").is_dir():
        pytest.skip(f"the shared data is absent ({SHARED}; set SCALEMATCH_SHARED)")
    return SHARED


@pytest.fixture
def flat_pair(tmp_path):
    """Two flat grey images with 3-grey-level noise: nothing to match (exit 1). (A constant image
    is refused as bad input: test_constant_image_is_bad_input.)"""
    low, high = tmp_path / "flat_low.png", tmp_path / "flat_high.png"
    rng = np.random.default_rng(0)
    cv2.imwrite(str(low), np.clip(128 + rng.normal(0, 3, (120, 160)), 0, 255).astype(np.uint8))
    cv2.imwrite(str(high), np.clip(90 + rng.normal(0, 3, (200, 240)), 0, 255).astype(np.uint8))
    return low, high


#: The pictures' pair (``pair``: test_render.py, test_overlay.py, test_scalechart.py): the photo
#: turned by ANGLE and shrunk by RATIO, and a crop of it at full resolution
RATIO, ANGLE = 3.0, 25.0
CROP = (300, 200, 480, 360)  # x0, y0, w, h of the high-resolution crop of the photo


@pytest.fixture(scope="module")
def pair(raccoon):
    """(low, high, T): high a full-resolution crop, low the whole photo turned and shrunk by 3."""
    x0, y0, w, h = CROP
    high = raccoon[y0:y0 + h, x0:x0 + w].copy()
    low, a = zoom_warp(raccoon, RATIO, ANGLE)
    t = compose(a, np.array([[1.0, 0, x0], [0, 1.0, y0]]))  # high px -> photo px -> low px
    return low, high, t
