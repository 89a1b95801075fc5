"""Shared fixtures: the photo the repo ships, and ../shared when it is present."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from scalematch.imageio import read_grey

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"


@pytest.fixture(scope="session")
def raccoon() -> np.ndarray:
    """data/raccoon.jpg (public domain, 1024x768) as float32 grey levels."""
    return read_grey(ROOT / "data" / "raccoon.jpg")


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    """../shared, or skip the test when it is absent."""
    if not (SHARED / "data" / "photos").is_dir():
        pytest.skip("../shared is absent")
    return SHARED
