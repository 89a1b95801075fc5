"""Lab charts drawn with OpenCV only: the line chart of the benchmark and the studies, BGR images.

Built on the product's chart primitives (:mod:`scalematch.chart`: axes, ticks, text, ``save`` and
the bar chart of a match's scales), with one colour and marker per series and a legend. Lines and
text are anti-aliased (``cv2.LINE_AA``). Empty series and NaN/inf values are not errors: a line is
broken at a missing value, and a chart with no finite value at all says "no data".

Pixel convention: OpenCV's, x to the right, y down; data y grows upwards on the canvas.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Dict, List, Optional, Sequence, Tuple

import cv2
import numpy as np

from ..chart import (DEFAULT_SIZE, Frame, PathLike, _axes, _finite, _font_scale, _frame,
                     _no_data, _text, _text_size, format_tick, nice_ticks, save)

#: Series colours, BGR: the Tableau-10 palette (matplotlib's default cycle), distinct in hue.
PALETTE = (
    (180, 119, 31),   # blue
    (14, 127, 255),   # orange
    (44, 160, 44),    # green
    (40, 39, 214),    # red
    (189, 103, 148),  # purple
    (75, 86, 140),    # brown
    (194, 119, 227),  # pink
    (127, 127, 127),  # grey
    (34, 189, 188),   # olive
    (207, 190, 23),   # cyan
)
#: Marker shapes cycled with the colours (a second cue for readers who do not see colour).
MARKERS = ("circle", "square", "triangle", "diamond", "cross", "x", "star")

Series = Dict[str, Tuple[Sequence[float], Sequence[float]]]


def finite_runs(x: np.ndarray, y: np.ndarray) -> List[np.ndarray]:
    """Indices of the maximal runs of consecutive points where both x and y are finite."""
    ok = np.isfinite(x) & np.isfinite(y)
    runs: List[np.ndarray] = []
    start = None
    for i, good in enumerate(ok):
        if good and start is None:
            start = i
        elif not good and start is not None:
            runs.append(np.arange(start, i))
            start = None
    if start is not None:
        runs.append(np.arange(start, len(ok)))
    return runs


def _as_xy(pair: Tuple[Sequence[float], Sequence[float]],
           name: str) -> Tuple[np.ndarray, np.ndarray]:
    if len(pair) != 2:
        raise ValueError(f"series {name!r} must be a pair (xs, ys), got {len(pair)} items")
    x = np.asarray(pair[0], dtype=np.float64).ravel()
    y = np.asarray(pair[1], dtype=np.float64).ravel()
    if x.shape != y.shape:
        raise ValueError(f"series {name!r}: xs has {x.size} values but ys has {y.size}")
    return x, y


def _marker(img: np.ndarray, centre: Tuple[float, float], kind: str, colour, size: int) -> None:
    """One marker of ``kind`` (see MARKERS), about ``size`` px across."""
    c = (int(round(centre[0])), int(round(centre[1])))
    r = max(size // 2, 2)
    if kind == "circle":
        cv2.circle(img, c, r, colour, -1, cv2.LINE_AA)
    elif kind == "square":
        cv2.rectangle(img, (c[0] - r + 1, c[1] - r + 1), (c[0] + r - 1, c[1] + r - 1), colour, -1,
                      cv2.LINE_AA)
    elif kind == "triangle":
        pts = np.array([[c[0], c[1] - r - 1], [c[0] - r, c[1] + r - 1], [c[0] + r, c[1] + r - 1]],
                       np.int32)
        cv2.fillPoly(img, [pts], colour, cv2.LINE_AA)
    elif kind == "diamond":
        pts = np.array([[c[0], c[1] - r - 1], [c[0] + r + 1, c[1]], [c[0], c[1] + r + 1],
                        [c[0] - r - 1, c[1]]], np.int32)
        cv2.fillPoly(img, [pts], colour, cv2.LINE_AA)
    elif kind == "cross":
        cv2.drawMarker(img, c, colour, cv2.MARKER_CROSS, 2 * r + 2, 2, cv2.LINE_AA)
    elif kind == "x":
        cv2.drawMarker(img, c, colour, cv2.MARKER_TILTED_CROSS, 2 * r + 2, 2, cv2.LINE_AA)
    else:
        cv2.drawMarker(img, c, colour, cv2.MARKER_STAR, 2 * r + 4, 1, cv2.LINE_AA)


def _densify(p: np.ndarray, step: float = 4.0) -> np.ndarray:
    """(N, 2) polyline vertices -> points every ``step`` px along it (vertices included)."""
    if p.shape[0] < 2:
        return p
    out = [p[:1]]
    for a, b in zip(p[:-1], p[1:]):
        k = max(int(np.hypot(*(b - a)) / step), 1)
        t = np.arange(1, k + 1)[:, None] / k
        out.append(a + t * (b - a))
    return np.concatenate(out)


def _legend_size(entries: List[Tuple[str, tuple, str]], f: float) -> Tuple[int, int]:
    """(width, height) px of the legend box for ``entries``."""
    fs = 0.5 * f
    width = max(_text_size(name, fs)[0] for name, _, _ in entries) + int(28 * f) + int(24 * f)
    return width, int(22 * f) * len(entries) + int(10 * f)


def _legend_spot(fr: Frame, size: Tuple[int, int], points: np.ndarray,
                 f: float) -> Tuple[Tuple[int, int], int]:
    """Top-left corner of the legend inside the plot where it hides the fewest ``points``.

    Returns the corner and how many of ``points`` (canvas px sampled along the lines) it hides;
    the top-right corner wins ties.
    """
    width, height = size
    pad = int(10 * f)
    mid_x = (fr.left + fr.right - width) // 2
    mid_y = (fr.top + fr.bottom - height) // 2
    spots = [(fr.right - pad - width, fr.top + pad), (fr.left + pad, fr.top + pad),
             (fr.right - pad - width, fr.bottom - pad - height),
             (fr.left + pad, fr.bottom - pad - height),
             (fr.right - pad - width, mid_y), (fr.left + pad, mid_y),
             (mid_x, fr.top + pad), (mid_x, fr.bottom - pad - height)]

    def hidden(spot):
        x0, y0 = spot
        if points.size == 0:
            return 0
        inside = ((points[:, 0] >= x0 - 8) & (points[:, 0] <= x0 + width + 8)
                  & (points[:, 1] >= y0 - 8) & (points[:, 1] <= y0 + height + 8))
        return int(inside.sum())

    best = min(spots, key=hidden)
    return best, hidden(best)


def _draw_legend(img: np.ndarray, spot: Tuple[int, int], entries: List[Tuple[str, tuple, str]],
                 f: float) -> None:
    """A boxed legend with its top-left corner at ``spot``."""
    fs = 0.5 * f
    line_h = int(22 * f)
    swatch = int(28 * f)
    width, height = _legend_size(entries, f)
    x0, y0 = spot
    sub = img[y0:y0 + height, x0:x0 + width]
    sub[:] = (0.15 * sub + 0.85 * 255).astype(np.uint8)  # light box, grid faintly visible
    cv2.rectangle(img, (x0, y0), (x0 + width, y0 + height), (160, 160, 160), 1, cv2.LINE_AA)
    _, th = _text_size("Ag", fs)
    for i, (name, colour, marker) in enumerate(entries):
        yc = y0 + int(5 * f) + line_h * i + line_h // 2
        xa, xb = x0 + int(8 * f), x0 + int(8 * f) + swatch
        cv2.line(img, (xa, yc), (xb, yc), colour, max(int(2 * f), 2), cv2.LINE_AA)
        _marker(img, ((xa + xb) / 2, yc), marker, colour, max(int(8 * f), 5))
        _text(img, name, (xb + 8 * f, yc + th / 2 - 3), fs)


# --------------------------------------------------------------------------------------------
# Charts
# --------------------------------------------------------------------------------------------

def line_chart(series: Series, path: Optional[PathLike] = None, title: str = "",
               xlabel: str = "", ylabel: str = "",
               ylim: Optional[Tuple[float, float]] = None,
               xticks: Optional[Sequence[float]] = None,
               size: Tuple[int, int] = DEFAULT_SIZE) -> np.ndarray:
    """A line chart of several series, one colour and marker each, with a legend.

    Parameters
    ----------
    series : dict name -> (xs, ys)
        Each a pair of equal-length sequences of float; NaN/inf values break the line there.
        Series are drawn (and listed in the legend) in dict order.
    path : str or Path, optional
        Where to write the image (PNG or JPEG by extension); None writes nothing.
    title, xlabel, ylabel : str
    ylim : (float, float), optional
        The y range shown; default the data range with round ticks.
    xticks : sequence of float, optional
        Positions of the x ticks (e.g. the factors measured); default round ticks.
    size : (int, int)
        Canvas (width, height), px.

    Returns
    -------
    (H, W, 3) uint8 array
        The chart, BGR.
    """
    data = [(str(name), *_as_xy(pair, str(name))) for name, pair in series.items()]
    w, h = int(size[0]), int(size[1])
    f = _font_scale((w, h))
    xs = np.concatenate([_finite(x[np.isfinite(y)]) for _, x, y in data]) if data else np.zeros(0)
    ys = np.concatenate([_finite(y[np.isfinite(x)]) for _, x, y in data]) if data else np.zeros(0)

    if xticks is not None and len(_finite(np.asarray(xticks, float))):
        xt = np.unique(_finite(np.asarray(xticks, float)))
        lo, hi = float(xt.min()), float(xt.max())
        if xs.size:
            lo, hi = min(lo, float(xs.min())), max(hi, float(xs.max()))
        xlim = (lo, hi) if hi > lo else (lo - 0.5, hi + 0.5)
        xstep = float(np.min(np.diff(xt))) if xt.size > 1 else 1.0
    else:
        xt = nice_ticks(float(xs.min()), float(xs.max())) if xs.size else nice_ticks(0.0, 1.0)
        xlim = (float(xt[0]), float(xt[-1]))
        xstep = float(xt[1] - xt[0]) if xt.size > 1 else 1.0

    if ylim is not None:
        ylo, yhi = float(ylim[0]), float(ylim[1])
        if not (math.isfinite(ylo) and math.isfinite(yhi)) or yhi <= ylo:
            raise ValueError(f"ylim must be two finite values, low < high; got {ylim}")
        yt = nice_ticks(ylo, yhi)
        yt = yt[(yt >= ylo - 1e-9 * (yhi - ylo)) & (yt <= yhi + 1e-9 * (yhi - ylo))]
        y_range = (ylo, yhi)
    else:
        yt = nice_ticks(float(ys.min()), float(ys.max())) if ys.size else nice_ticks(0.0, 1.0)
        y_range = (float(yt[0]), float(yt[-1]))
    ystep = float(yt[1] - yt[0]) if yt.size > 1 else 1.0
    ylabels = [format_tick(v, ystep) for v in yt]
    xlabels = [format_tick(v, xstep) for v in xt]

    ytw = max((_text_size(s, 0.5 * f)[0] for s in ylabels), default=0)
    fr = replace(_frame((w, h), f, bool(title), bool(xlabel), bool(ylabel), ytw, xlim, y_range),
                 inset=int(8 * f))
    entries = [(name, PALETTE[i % len(PALETTE)], MARKERS[i % len(MARKERS)])
               for i, (name, _, _) in enumerate(data)]

    def draw(fr: Frame) -> Tuple[np.ndarray, np.ndarray]:
        img = np.full((h, w, 3), 255, np.uint8)
        _axes(img, fr, xt, xlabels, yt, ylabels, f, title, xlabel, ylabel)
        canvas = img.copy()
        along = []
        thick = max(int(round(2 * f)), 2)
        for (_, x, y), (_, colour, marker) in zip(data, entries):
            for run in finite_runs(x, y):
                p = fr.px(x[run], y[run])
                along.append(_densify(p))
                pts = np.round(p * 16).astype(np.int32).reshape(-1, 1, 2)  # 4 fractional bits
                if len(run) > 1:
                    cv2.polylines(canvas, [pts], False, colour, thick, cv2.LINE_AA, shift=4)
                for q in p:
                    _marker(canvas, (q[0], q[1]), marker, colour, max(int(9 * f), 5))
        # data outside ylim is clipped to the plot area
        img[fr.top + 1:fr.bottom, fr.left + 1:fr.right] = \
            canvas[fr.top + 1:fr.bottom, fr.left + 1:fr.right]
        if not ys.size:
            _no_data(img, fr, f)
        return img, (np.concatenate(along) if along else np.zeros((0, 2)))

    img, along = draw(fr)
    if entries:
        box = _legend_size(entries, f)
        spot, hidden = _legend_spot(fr, box, along, f)
        narrowed = fr.right - box[0] - int(20 * f)
        if hidden > 0 and narrowed - fr.left >= 0.5 * (fr.right - fr.left):
            # no free spot inside: the legend goes to the right of a narrower plot
            fr = replace(fr, right=narrowed)
            img, along = draw(fr)
            spot = (fr.right + int(10 * f), fr.top)
        _draw_legend(img, spot, entries, f)
    save(img, path)
    return img

