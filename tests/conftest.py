"""Shared fixtures: the photo the repo ships, and the shared data folder when it is present
($SCALEMATCH_SHARED, else ../shared beside the repository)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from scalematch.imageio import read_grey
from scalematch.lab.datasets import find_shared

ROOT = Path(__file__).resolve().parents[1]
#: where the commands look too (``find_shared``): $SCALEMATCH_SHARED, else ../shared
SHARED = find_shared() or ROOT.parent / "shared"


@pytest.fixture(scope="session")
def raccoon() -> np.ndarray:
    """data/raccoon.jpg (public domain, 1024x768) as float32 grey levels."""
    return read_grey(ROOT / "data" / "raccoon.jpg")


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
