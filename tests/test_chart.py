"""The OpenCV bar chart (chart.py): shape, the file is written, highlight, NaN/empty data, ticks."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from scalematch.chart import HIGHLIGHT_COLOUR, Marks, Titles, bar_chart, format_tick, nice_ticks


def _has_colour(img: np.ndarray, bgr, tol: int = 12, min_pixels: int = 20) -> bool:
    d = np.abs(img.astype(int) - np.array(bgr)[None, None, :]).max(axis=2)
    return int((d <= tol).sum()) >= min_pixels


def test_bar_chart_highlight_and_file(tmp_path):
    path = tmp_path / "bar.png"
    labels = [1.0, 1.19, 1.41, 1.68, 2.0, 2.38]
    img = bar_chart(labels, [3, 8, 40, 120, 35, np.nan], path,
                    Titles("inliers per scale", "scale s", "inliers"), Marks(highlight=3))
    assert img.shape == (600, 900, 3) and img.dtype == np.uint8
    assert cv2.imread(str(path)) is not None
    assert _has_colour(img, HIGHLIGHT_COLOUR, tol=2, min_pixels=1000)
    plain = bar_chart(labels, [3, 8, 40, 120, 35, 1], None)
    assert not _has_colour(plain, HIGHLIGHT_COLOUR, tol=2, min_pixels=1000)


@pytest.mark.parametrize("values", [[], [np.nan, np.nan], [0, 0, 0], [-3, 2, 5]])
def test_bar_chart_degenerate_data_does_not_crash(values):
    img = bar_chart([str(i) for i in range(len(values))], values, None, Titles("t", "x", "y"),
                    Marks(highlight=0 if values else None))
    assert img.shape == (600, 900, 3)


def test_custom_size():
    img = bar_chart(["a", "b"], [1, 2], None, size=(400, 300))
    assert img.shape == (300, 400, 3)


def test_nice_ticks_cover_range_with_round_steps():
    t = nice_ticks(0.03, 0.97)
    assert t[0] <= 0.03 and t[-1] >= 0.97
    assert np.allclose(np.diff(t), 0.2)
    assert np.allclose(nice_ticks(0, 150), [0, 25, 50, 75, 100, 125, 150])
    assert nice_ticks(5, 5).size >= 2
    assert np.allclose(nice_ticks(np.nan, 1), [0, 0.2, 0.4, 0.6, 0.8, 1.0])


def test_format_tick():
    assert format_tick(0.25, 0.25) == "0.25"
    assert format_tick(2.0, 0.5) == "2.0"
    assert format_tick(100.0, 25.0) == "100"


def test_bar_ticks_leave_room_for_the_values_and_thin_crowded_labels():
    from scalematch.chart import Ticks, _bar_xticks, _bar_yticks

    # 120 * 1.08 = 129.6: steps of 25 up to 150, room above the tallest bar for its value
    assert _bar_yticks(np.array([3.0, 120.0]), annotate=True) == Ticks(
        (0.0, 25.0, 50.0, 75.0, 100.0, 125.0, 150.0), ("0", "25", "50", "75", "100", "125", "150"))
    empty = _bar_yticks(np.array([]), annotate=False)  # no data: 0 to 1
    assert empty.labels == ("0.0", "0.2", "0.4", "0.6", "0.8", "1.0") and empty.at[-1] == 1.0
    labels = [f"{i}" for i in range(10)]
    assert _bar_xticks(labels, slot=100.0, f=1.0, highlight=None).labels == tuple(labels)
    # 2 px per bar: one label in k, and the highlighted bar's too
    thin = _bar_xticks(labels, slot=2.0, f=1.0, highlight=7)
    assert thin.at[0] == 0.0 and 7.0 in thin.at and len(thin.at) < 4
