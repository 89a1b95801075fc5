"""OpenCV charts: shape and dtype, the file is written and decodes, NaN/empty data, colours."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from scalematch.plot import (HIGHLIGHT_COLOUR, PALETTE, bar_chart, finite_runs, format_tick,
                             line_chart, nice_ticks)

X = [1, 1.5, 2, 2.5, 3, 4, 5, 6]


def _has_colour(img: np.ndarray, bgr, tol: int = 12, min_pixels: int = 20) -> bool:
    d = np.abs(img.astype(int) - np.array(bgr)[None, None, :]).max(axis=2)
    return int((d <= tol).sum()) >= min_pixels


def test_line_chart_shape_dtype_and_file(tmp_path):
    path = tmp_path / "sub" / "line.png"
    img = line_chart({"a": (X, np.linspace(1, 0.1, 8)), "b": (X, np.linspace(0.9, 0.7, 8))},
                     path, "title", "factor", "repeatability", ylim=(0, 1), xticks=X)
    assert img.shape == (600, 900, 3) and img.dtype == np.uint8
    back = cv2.imread(str(path))
    assert back is not None and np.array_equal(back, img)
    assert (img == 255).all(axis=2).mean() > 0.5  # a white background


def test_line_chart_series_get_distinct_colours():
    img = line_chart({"a": (X, np.linspace(1, 0.1, 8)), "b": (X, np.linspace(0.1, 0.9, 8)),
                      "c": (X, np.full(8, 0.5))}, None)
    for colour in PALETTE[:3]:
        assert _has_colour(img, colour), f"series colour {colour} not drawn"
    assert len(set(PALETTE)) == len(PALETTE)


def test_path_none_writes_nothing(tmp_path):
    line_chart({"a": ([0, 1], [0, 1])}, None)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("series", [
    {},
    {"empty": ([], [])},
    {"all nan": ([np.nan, np.nan], [np.nan, np.nan])},
    {"some nan": (X, [0.9, np.nan, 0.4, np.inf, 0.2, np.nan, 0.1, 0.05])},
    {"one point": ([3.0], [0.5])},
    {"flat": (X, np.full(8, 0.3))},
])
def test_line_chart_missing_data_does_not_crash(tmp_path, series):
    img = line_chart(series, tmp_path / "x.png", "t", "x", "y")
    assert img.shape == (600, 900, 3)
    assert cv2.imread(str(tmp_path / "x.png")) is not None


def test_line_chart_bad_input_says_what():
    with pytest.raises(ValueError, match="xs has 2 values"):
        line_chart({"a": ([1, 2], [1, 2, 3])}, None)
    with pytest.raises(ValueError, match="ylim"):
        line_chart({"a": ([1, 2], [1, 2])}, None, ylim=(1, 0))


def test_bar_chart_highlight_and_file(tmp_path):
    path = tmp_path / "bar.png"
    labels = [1.0, 1.19, 1.41, 1.68, 2.0, 2.38]
    img = bar_chart(labels, [3, 8, 40, 120, 35, np.nan], path, "inliers per scale", "scale s",
                    "inliers", highlight=3)
    assert img.shape == (600, 900, 3) and img.dtype == np.uint8
    assert cv2.imread(str(path)) is not None
    assert _has_colour(img, HIGHLIGHT_COLOUR, tol=2, min_pixels=1000)
    plain = bar_chart(labels, [3, 8, 40, 120, 35, 1], None)
    assert not _has_colour(plain, HIGHLIGHT_COLOUR, tol=2, min_pixels=1000)


@pytest.mark.parametrize("values", [[], [np.nan, np.nan], [0, 0, 0], [-3, 2, 5]])
def test_bar_chart_degenerate_data_does_not_crash(values):
    img = bar_chart([str(i) for i in range(len(values))], values, None, "t", "x", "y",
                    highlight=0 if values else None)
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


def test_format_tick_and_runs():
    assert format_tick(0.25, 0.25) == "0.25"
    assert format_tick(2.0, 0.5) == "2.0"
    assert format_tick(100.0, 25.0) == "100"
    runs = finite_runs(np.arange(6.0), np.array([1, np.nan, 2, 3, np.inf, 4.0]))
    assert [r.tolist() for r in runs] == [[0], [2, 3], [5]]
