"""The per-scale chart of a match (scales.png): inliers against scale, the paper's Table 1 as a
bar chart (drawn by :func:`scalematch.chart.bar_chart`), the winner highlighted, the scales the
probe skipped marked and the fits whose ratio contradicts their scale greyed.
"""

from __future__ import annotations

from typing import Sequence, Tuple

import numpy as np

from .chart import Marks, Titles, bar_chart
from .result import MatchResult, ScaleRow
from .stages.decision import disagrees


def scale_labels(rows: Sequence[ScaleRow]) -> list:
    """The chart's label of each scale: three significant digits, as the table (a working size
    makes scales such as 0.629961 and 10.0794), an asterisk when the probe skipped it.

    >>> from scalematch.result import ScaleRow
    >>> scale_labels([ScaleRow(s=0.629961, ratio=0.63, points=9, initial=4, kept=2, inliers=0,
    ...                        outlier_pct=100.0),
    ...               ScaleRow(s=10.0794, ratio=float("nan"), points=9, initial=0, kept=0,
    ...                        inliers=0, outlier_pct=100.0, skipped=True)])
    ['0.63', '10.1*']
    """
    return [f"{r.s:.3g}" + ("*" if r.skipped else "") for r in rows]


def scale_plot(result: MatchResult, size: Tuple[int, int] = (900, 500)) -> np.ndarray:
    """Bar chart of inliers against scale s, the winning scale highlighted.

    Scales the probe skipped as hopeless have no bar and an asterisk on their label; a scale
    whose fit's ratio contradicts it (:func:`disagreeing_rows`) has a light grey bar, as the
    decision does not count it, however many inliers it has. Each bar is its scale's own fit;
    the answer is that fit refined on the matches of every scale (and grown), so where its
    inliers differ from the winning bar's the title gives both.
    """
    rows = list(result.scales)
    labels = scale_labels(rows)
    values = [float("nan") if r.skipped else float(r.inliers) for r in rows]
    best = None
    if np.isfinite(result.best_scale) and rows:
        best = int(np.argmin([abs(r.s - result.best_scale) for r in rows]))
    if result.matched:
        title = (f"inliers per scale: best s = {result.best_scale:.3g}, "
                 f"ratio {result.resolution_ratio:.2f}")
        if best is not None and rows[best].inliers != result.n_inliers:
            title += f"; the answer, refined over every scale: {result.n_inliers} inliers"
    else:
        title = "inliers per scale: no reliable match"
    xlabel = "scale s of the high-resolution image"
    notes = []
    if any(r.skipped for r in rows):
        notes.append("* skipped: hopeless from its initial matches")
    muted = [i for i in disagreeing_rows(result) if i != best]
    if muted:
        notes.append("grey: fit's ratio far from s, not counted")
    if notes:
        xlabel += "   (" + "; ".join(notes) + ")"
    return bar_chart(labels, values, titles=Titles(title, xlabel, "inliers"),
                     marks=Marks(highlight=best, muted=muted), size=size)


def disagreeing_rows(result: MatchResult) -> list:
    """Indices of the per-scale rows whose fit's ratio contradicts their scale (beyond the
    decision's ``scale_agreement``): the decision does not count them (a fit that collapses
    many finer points onto a few coarser ones can have many inliers). None for a model
    without a ratio, or without the configuration."""
    if result.config is None:
        return []
    return [i for i, r in enumerate(result.scales)
            if not r.skipped and disagrees(r, result.model, result.config.decision)]
