"""Shared fixtures: the photo the repo ships, and the shared data folder when it is present
($SCALEMATCH_SHARED, else ../shared beside the repository)."""

from __future__ import annotations

from pathlib import Path

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
