"""scalechart: the per-scale chart, the winner highlighted, the fits that do not count greyed."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np

from scalematch.chart import MUTED_COLOUR
from scalematch.config import Config
from scalematch.result import MatchResult, ScaleRow
from scalematch.scalechart import disagreeing_rows, scale_plot
from test_render import make_result


def test_scale_plot(pair):
    low, high, t = pair
    res = make_result(t)
    plot = scale_plot(res)
    assert plot.ndim == 3 and plot.shape[2] == 3
    # the winner (s = 3, index 2) is drawn in the highlight colour: some red pixels exist
    assert np.any(np.all(plot == (40, 39, 214), axis=2))
    assert scale_plot(make_result(None, matched=False)).ndim == 3


def collapsed_fit_result(model="similarity") -> MatchResult:
    """A match at s = 2.52 (ratio 4.01) beside a fit at s = 1.59 that collapses many finer
    points onto a few coarser ones (ratio 406, 79 inliers: measured on a 185 px low image)."""
    rows = (ScaleRow(1.587, 406.6, 6000, 1559, 356, 79, 94.9, 104.6),
            ScaleRow(2.52, 4.01, 3198, 862, 181, 19, 97.8, -29.9),
            ScaleRow(4.0, 4.6, 1412, 90, 20, 4, 95.6, -30.0),
            ScaleRow(8.0, 2.9e20, 346, 102, 24, 5, 95.1, 150.5))
    return MatchResult(matched=True, model=model, best_scale=2.52, resolution_ratio=4.01,
                       scales=rows, config=Config())


def test_a_fit_whose_ratio_contradicts_its_scale_is_shown_as_not_counted():
    res = collapsed_fit_result()
    assert disagreeing_rows(res) == [0, 3]  # 4.6 at s = 4 is within the 1.6x agreement
    plot = scale_plot(res)
    grey = np.all(plot == MUTED_COLOUR, axis=2)
    assert grey.any() and not np.all(plot == (40, 39, 214), axis=2)[grey].any()
    # the tall grey bar is the first slot's (left quarter), the red one the second's
    cols = np.nonzero(grey.any(axis=0))[0]
    assert cols.min() < plot.shape[1] // 4
    assert disagreeing_rows(collapsed_fit_result("fundamental")) == []  # no ratio to compare


def test_the_scale_chart_gives_the_answers_inliers_where_they_differ_from_the_winning_bar(
        pair, monkeypatch):
    """The verdict counts the answer's inliers (its fit refined over every scale), the bars
    each scale's own fit: a title that gave only the bars read as a contradiction (6 against
    a winning bar of 5)."""
    import scalematch.scalechart as scalechart

    seen = []
    monkeypatch.setattr(scalechart, "bar_chart", lambda *a, titles, **k: seen.append(titles))
    res = make_result(pair[2])  # the winning bar (s = 3) has 40 inliers, the answer 40
    scalechart.scale_plot(res)
    more = dataclasses.replace(res, inliers=np.vstack([res.inliers, res.inliers[:6]]))
    scalechart.scale_plot(more)
    assert "refined" not in seen[0].title
    assert seen[1].title.endswith("the answer, refined over every scale: 46 inliers")


def test_a_degenerate_fits_ratio_is_none_in_the_table_and_the_json():
    """A fit sending every point to one gives a ratio like 7.49e+19: not a zoom. The table's
    row holds NaN (null in the JSON), and the decision ignores the row as before (a NaN ratio
    is as far from its scale as any)."""
    from scalematch.geometry import usable_ratio
    from scalematch.stages.acontrario import DecisionParams
    from scalematch.stages.decision import disagrees

    row = ScaleRow(8.0, usable_ratio(7.49e19), 346, 102, 24, 5, 95.1, 150.5)
    assert math.isnan(row.ratio) and disagrees(row, "similarity", DecisionParams())
    res = dataclasses.replace(collapsed_fit_result(), scales=(row,))
    assert json.loads(res.to_json("a.png", "b.png"))["scales"][0]["ratio"] is None
