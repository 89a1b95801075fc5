"""The lab's line charts (matplotlib): shape and dtype, the file is written and decodes, NaN/empty
data. Skipped when matplotlib (the extra ``scalematch[lab]``) is not installed."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

pytest.importorskip("matplotlib")
from scalematch.lab.plot import PALETTE, line_chart  # noqa: E402

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


def test_a_missing_value_breaks_the_line():
    """Two runs either side of a NaN: no line is drawn across the gap."""
    img = line_chart({"a": ([0, 1, 2, 3, 4], [0.5, 0.5, np.nan, 0.5, 0.5])}, None, ylim=(0, 1),
                     size=(500, 300))
    blue = np.abs(img.astype(int) - np.array(PALETTE[0])).max(axis=2) <= 12
    row = blue[np.argmax(blue.sum(axis=1))]  # the row the line runs along
    xs = np.nonzero(row)[0]
    assert np.diff(xs).max() > 40  # the gap at x = 2
