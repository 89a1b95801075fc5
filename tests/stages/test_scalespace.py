"""Scale-space levels (scalespace.py) and Gaussian derivative filters (filters.py)."""

from __future__ import annotations

import numpy as np
import pytest

from scalematch.stages.filters import gaussian_derivative
from scalematch.stages.scalespace import antialias_sigma, resample, scale_space


def test_derivative_filters_are_exact_on_polynomials():
    y, x = np.mgrid[0:64, 0:64].astype(np.float32)
    cases = [(x, 1, 0), (y, 0, 1), (x * x / 2, 2, 0), (x * y, 1, 1), (x ** 3 / 6, 3, 0),
             (x * x * y / 2, 2, 1)]
    for img, ox, oy in cases:
        assert gaussian_derivative(img, 1.5, ox, oy)[32, 32] == pytest.approx(1.0, abs=1e-3)
    assert abs(gaussian_derivative(np.full((32, 32), 7, np.float32), 2.0, 1, 0)).max() < 1e-5


def test_levels_keep_full_resolution_coordinates():
    """A bright dot at a known full-resolution position stays there on every level."""
    img = np.zeros((400, 600), np.float32)
    img[201, 333] = 1000.0
    for level in scale_space(img, (1.0, 2.0, 3.0, 5.0, 8.0)):
        r, c = np.unravel_index(np.argmax(level.image), level.image.shape)
        # sub-pixel peak of the (blurred) dot, mapped back
        win = level.image[r - 1:r + 2, c - 1:c + 2].astype(np.float64)
        dy = (win[2, 1] - win[0, 1]) / (2 * (2 * win[1, 1] - win[0, 1] - win[2, 1]))
        dx = (win[1, 2] - win[1, 0]) / (2 * (2 * win[1, 1] - win[1, 0] - win[1, 2]))
        x, y = level.to_full(np.array([[c + dx, r + dy]]))[0]
        assert abs(x - 333) < 0.25 * level.d + 0.1 and abs(y - 201) < 0.25 * level.d + 0.1
        assert level.d == pytest.approx(max(1.0, level.s))
        assert level.blur == pytest.approx(antialias_sigma(level.d))


def test_level_sigma_accounts_for_the_blur_already_there():
    level = next(scale_space(np.zeros((100, 100), np.float32), (4.0,)))
    total = 4.0
    on_level = level.sigma_on_level(total)
    assert (on_level * level.d) ** 2 + level.blur ** 2 == pytest.approx(total ** 2)


def test_resample_sizes_and_identity():
    img = np.random.default_rng(0).random((100, 150)).astype(np.float32)
    assert resample(img, 1.0) is img
    assert resample(img, 2.0).shape == (50, 75)
