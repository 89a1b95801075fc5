"""The bar chart of a match's scales, drawn with OpenCV only (docs/ALGORITHM.md step 8: the per-scale table).

A white canvas with axes, ticks with numeric labels, grid lines, axis titles and a title, as a
BGR image; no plotting library is needed. Lines and text are anti-aliased (``cv2.LINE_AA``). A bar
with a missing value (NaN/inf) is not drawn, and a chart with no finite value says "no data".
The lab's line charts (:mod:`scalematch.lab.plot`) use matplotlib, an optional extra.

Pixel convention: OpenCV's, x to the right, y down; data y grows upwards on the canvas.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence, Tuple, Union

import cv2
import numpy as np

#: Default canvas (width, height), px: readable on a screen and in a Markdown page.
DEFAULT_SIZE = (900, 600)
#: Bar colours, BGR: ordinary bars, the highlighted (winning) bar, and muted bars (counted,
#: but not candidates: e.g. a fit whose ratio contradicts its scale)
BAR_COLOUR = (200, 170, 130)
HIGHLIGHT_COLOUR = (40, 39, 214)
MUTED_COLOUR = (218, 218, 218)
BLACK = (0, 0, 0)
GRID = (225, 225, 225)
TEXT = (40, 40, 40)
FONT = cv2.FONT_HERSHEY_SIMPLEX
#: Target number of ticks per axis for ``nice_ticks``.
N_TICKS = 6
PathLike = Union[str, Path]


# --------------------------------------------------------------------------------------------
# Pure helpers: tick placement, number formatting, the data -> pixel mapping
# --------------------------------------------------------------------------------------------

def nice_ticks(lo: float, hi: float, n: int = N_TICKS) -> np.ndarray:
    """About ``n`` round tick values (steps 1, 2, 2.5 or 5 x 10^k) covering [lo, hi].

    Parameters
    ----------
    lo, hi : float
        The data range; ``lo == hi`` is widened by one unit; non-finite gives [0, 1].
    n : int
        Target number of intervals.

    Returns
    -------
    (K,) float64 array
        Increasing ticks with ``ticks[0] <= lo`` and ``ticks[-1] >= hi``.
    """
    if not (math.isfinite(lo) and math.isfinite(hi)):
        lo, hi = 0.0, 1.0
    if hi < lo:
        lo, hi = hi, lo
    if hi - lo < 1e-12 * max(abs(lo), abs(hi), 1.0):
        lo, hi = lo - 0.5, hi + 0.5
    raw = (hi - lo) / max(n, 1)
    mag = 10.0 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * mag >= raw * (1 - 1e-9))
    first = math.floor(lo / step + 1e-9) * step
    last = math.ceil(hi / step - 1e-9) * step
    k = int(round((last - first) / step))
    return first + step * np.arange(k + 1)


def format_tick(value: float, step: float) -> str:
    """``value`` with just enough decimals for ticks ``step`` apart ("0.25", "2", "1e+04")."""
    if not math.isfinite(value):
        return ""
    if abs(value) < 1e-9 * max(abs(step), 1e-300):
        value = 0.0
    if abs(value) >= 1e5 or (value != 0 and abs(value) < 1e-3):
        return f"{value:.3g}"
    decimals = 0
    if step > 0:
        while decimals < 6 and abs(round(step, decimals) - step) > 1e-9 * abs(step):
            decimals += 1
    return f"{value:.{decimals}f}"


@dataclass(frozen=True)
class Frame:
    """The plot area on the canvas and the data ranges it shows (data -> pixel mapping)."""

    left: int  #: plot area, canvas px
    top: int
    right: int
    bottom: int
    xlim: Tuple[float, float]  #: data x at left and right
    ylim: Tuple[float, float]  #: data y at bottom and top

    def px(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Data (N,) x and y -> (N, 2) canvas px (float)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        l, r, t, b = self.left, self.right, self.top, self.bottom
        u = l + (x - self.xlim[0]) / (self.xlim[1] - self.xlim[0]) * (r - l)
        v = b - (y - self.ylim[0]) / (self.ylim[1] - self.ylim[0]) * (b - t)
        return np.stack([u, v], axis=-1)

@dataclass(frozen=True)
class Ticks:
    """The ticks of one axis: their data values and their labels."""

    at: Tuple[float, ...]  #: data values, increasing
    labels: Tuple[str, ...]  #: one label per tick


@dataclass(frozen=True)
class Layout:
    """What a chart writes around its plot area, and at what size: ``_frame`` leaves room for
    it, ``_axes`` draws it."""

    size: Tuple[int, int]  #: canvas (width, height), px
    f: float  #: font size factor, 1 at the default canvas (``_font_scale``)
    yticks: Ticks  #: the y ticks: the width of their labels sets the left margin
    title: str = ""
    xlabel: str = ""
    ylabel: str = ""


def _finite(values: np.ndarray) -> np.ndarray:
    values = np.asarray(values, dtype=np.float64).ravel()
    return values[np.isfinite(values)]


# --------------------------------------------------------------------------------------------
# Drawing primitives (they draw on the canvas they are given)
# --------------------------------------------------------------------------------------------

def _font_scale(size: Tuple[int, int]) -> float:
    """Font size factor: 1 at the default 900x600 canvas."""
    return max(0.5, min(size[0] / DEFAULT_SIZE[0], size[1] / DEFAULT_SIZE[1]))


def _text(img: np.ndarray, text: str, org: Tuple[float, float], scale: float,
          colour=TEXT, thickness: int = 1, anchor: str = "left") -> None:
    """Put ``text`` with its baseline at org[1]; anchor 'left', 'centre' or 'right' in x."""
    (tw, _), _ = cv2.getTextSize(text, FONT, scale, thickness)
    x = org[0] - (tw / 2 if anchor == "centre" else tw if anchor == "right" else 0)
    cv2.putText(img, text, (int(round(x)), int(round(org[1]))), FONT, scale, colour, thickness,
                cv2.LINE_AA)


def _text_size(text: str, scale: float, thickness: int = 1) -> Tuple[int, int]:
    (tw, th), base = cv2.getTextSize(text, FONT, scale, thickness)
    return tw, th + base


def _vertical_text(img: np.ndarray, text: str, centre: Tuple[float, float], scale: float) -> None:
    """Text turned 90 degrees counter-clockwise (reading upwards), centred on ``centre``."""
    if not text:
        return
    (tw, th), base = cv2.getTextSize(text, FONT, scale, 1)
    patch = np.full((th + base + 4, tw + 4, 3), 255, np.uint8)
    _text(patch, text, (2, 2 + th), scale)
    patch = cv2.rotate(patch, cv2.ROTATE_90_COUNTERCLOCKWISE)
    ph, pw = patch.shape[:2]
    x0 = int(round(centre[0] - pw / 2))
    y0 = int(round(centre[1] - ph / 2))
    h, w = img.shape[:2]
    xa, ya = max(x0, 0), max(y0, 0)
    xb, yb = min(x0 + pw, w), min(y0 + ph, h)
    if xb > xa and yb > ya:
        region = img[ya:yb, xa:xb]
        sub = patch[ya - y0:yb - y0, xa - x0:xb - x0]
        np.minimum(region, sub, out=region)  # dark text over a white background

def _frame(layout: Layout, xlim: Tuple[float, float], ylim: Tuple[float, float]) -> Frame:
    """The plot area of ``layout``'s canvas, with room for its title, axis titles and y tick
    labels, showing ``xlim`` and ``ylim``."""
    w, h = layout.size
    f = layout.f
    ytick_width = max((_text_size(s, 0.5 * f)[0] for s in layout.yticks.labels), default=0)
    left = int(ytick_width + 18 * f + (30 * f if layout.ylabel else 0))
    top = int((55 if layout.title else 25) * f)
    bottom = int(h - (70 if layout.xlabel else 45) * f)
    right = int(w - 30 * f)
    if right - left < 20 or bottom - top < 20:
        raise ValueError(f"canvas {w}x{h} is too small for a chart; use at least 300x200")
    return Frame(left, top, right, bottom, tuple(map(float, xlim)), tuple(map(float, ylim)))


def _axes(img: np.ndarray, fr: Frame, layout: Layout, xticks: Ticks,
          vertical_grid: bool = True) -> None:
    """Grid, frame, ticks with labels, axis titles and the chart title."""
    f = layout.f
    fs = 0.5 * f
    tick = max(int(5 * f), 3)
    for y in layout.yticks.at:
        v = int(round(fr.px(fr.xlim[0], y)[1]))
        cv2.line(img, (fr.left, v), (fr.right, v), GRID, 1, cv2.LINE_AA)
    if vertical_grid:
        for x in xticks.at:
            u = int(round(fr.px(x, fr.ylim[0])[0]))
            cv2.line(img, (u, fr.top), (u, fr.bottom), GRID, 1, cv2.LINE_AA)
    cv2.rectangle(img, (fr.left, fr.top), (fr.right, fr.bottom), BLACK, 1, cv2.LINE_AA)
    _, th = _text_size("0", fs)
    for y, lab in zip(layout.yticks.at, layout.yticks.labels):
        v = int(round(fr.px(fr.xlim[0], y)[1]))
        cv2.line(img, (fr.left - tick, v), (fr.left, v), BLACK, 1, cv2.LINE_AA)
        _text(img, lab, (fr.left - tick - 4, v + th / 2 - 2), fs, anchor="right")
    for x, lab in zip(xticks.at, xticks.labels):
        u = int(round(fr.px(x, fr.ylim[0])[0]))
        cv2.line(img, (u, fr.bottom), (u, fr.bottom + tick), BLACK, 1, cv2.LINE_AA)
        _text(img, lab, (u, fr.bottom + tick + th + 3), fs, anchor="centre")
    w = img.shape[1]
    if layout.title:
        ts = 0.7 * f
        while ts > 0.35 and _text_size(layout.title, ts, 2)[0] > w - 20:
            ts *= 0.9
        _text(img, layout.title, (w / 2, 35 * f), ts, BLACK, 2 if f >= 0.8 else 1,
              anchor="centre")
    if layout.xlabel:
        _text(img, layout.xlabel, ((fr.left + fr.right) / 2, fr.bottom + tick + 2 * th + 22 * f),
              0.55 * f, anchor="centre")
    if layout.ylabel:
        _vertical_text(img, layout.ylabel, (16 * f, (fr.top + fr.bottom) / 2), 0.55 * f)


def _no_data(img: np.ndarray, fr: Frame, f: float) -> None:
    _text(img, "no data", ((fr.left + fr.right) / 2, (fr.top + fr.bottom) / 2), 0.8 * f,
          (150, 150, 150), 1, anchor="centre")


def save(image: np.ndarray, path: Optional[PathLike]) -> None:
    """Write ``image`` to ``path`` (format from the extension); nothing when path is None."""
    if path is None:
        return
    p = Path(path)
    if p.parent and not p.parent.exists():
        p.parent.mkdir(parents=True, exist_ok=True)
    ok, buf = cv2.imencode(p.suffix or ".png", image)
    if not ok:
        raise ValueError(f"{p}: OpenCV cannot write this format; use .png or .jpg")
    buf.tofile(str(p))

@dataclass(frozen=True)
class Titles:
    """The words of a chart: its title and its axes' titles."""

    title: str = ""
    xlabel: str = ""
    ylabel: str = ""


@dataclass(frozen=True)
class Marks:
    """Which bars of a bar chart stand out: one highlighted (the winning scale), some muted."""

    #: index (into the labels) of the bar drawn in the highlight colour; None or out of range
    #: highlights nothing
    highlight: Optional[int] = None
    #: indices of the bars drawn in a light grey (shown, but not in the running)
    muted: Sequence[int] = ()


def bar_chart(labels: Sequence[object], values: Sequence[float],
              path: Optional[PathLike] = None, titles: Titles = Titles(),
              marks: Marks = Marks(), size: Tuple[int, int] = DEFAULT_SIZE,
              annotate: bool = True) -> np.ndarray:
    """A bar chart over categories (e.g. inliers against scale), one bar optionally highlighted.

    Parameters
    ----------
    labels : sequence
        One label per bar (numbers are shown with ``str``, floats with ``:g``).
    values : sequence of float
        Bar heights; NaN/inf draws no bar ("-" above the slot).
    path : str or Path, optional
        Where to write the image; None writes nothing.
    titles : Titles
        The chart's title and its axes' titles.
    marks : Marks
        The bar highlighted (e.g. the winning scale) and the bars muted.
    size : (int, int)
        Canvas (width, height), px.
    annotate : bool
        Write each bar's value above it.

    Returns
    -------
    (H, W, 3) uint8 array
        The chart, BGR.
    """
    highlight, muted = marks.highlight, marks.muted
    vals = np.asarray(values, dtype=np.float64).ravel()
    labs = [f"{v:g}" if isinstance(v, (float, np.floating)) else str(v) for v in labels]
    if len(labs) != vals.size:
        raise ValueError(f"bar_chart: {len(labs)} labels but {vals.size} values")
    w, h = int(size[0]), int(size[1])
    f = _font_scale((w, h))
    img = np.full((h, w, 3), 255, np.uint8)
    fin = _finite(vals)
    layout = Layout((w, h), f, _bar_yticks(fin, annotate), titles.title, titles.xlabel,
                    titles.ylabel)
    n = len(labs)
    fr = _frame(layout, (-0.5, n - 0.5) if n else (-0.5, 0.5),
                (layout.yticks.at[0], layout.yticks.at[-1]))
    slot = (fr.right - fr.left) / max(n, 1)  # canvas px per bar
    _axes(img, fr, layout, _bar_xticks(labs, slot, f, highlight), vertical_grid=False)
    if not fin.size:
        _no_data(img, fr, f)
    _draw_bars(img, fr, vals, highlight, frozenset(muted))
    # values are drawn after all bars so a tall neighbour never covers them
    if annotate and (_text_size("0000", 0.45 * f)[0] <= slot or n <= 20):
        _draw_values(img, fr, vals, highlight, f)
    cv2.rectangle(img, (fr.left, fr.top), (fr.right, fr.bottom), BLACK, 1, cv2.LINE_AA)
    save(img, path)
    return img


def _bar_yticks(fin: np.ndarray, annotate: bool) -> Ticks:
    """The y ticks of bars of the finite heights ``fin``: from 0 or below to the highest bar,
    with room above it for its value when ``annotate``; 0 to 1 without data."""
    lo = min(0.0, float(fin.min())) if fin.size else 0.0
    hi = max(0.0, float(fin.max())) if fin.size else 1.0
    if hi <= lo:
        hi = lo + 1.0
    yt = nice_ticks(lo, hi * (1.08 if annotate and hi > 0 else 1.0))
    ystep = float(yt[1] - yt[0]) if yt.size > 1 else 1.0
    return Ticks(tuple(float(v) for v in yt), tuple(format_tick(v, ystep) for v in yt))


def _bar_xticks(labs: Sequence[str], slot: float, f: float, highlight: Optional[int]) -> Ticks:
    """The x ticks of bars ``slot`` px apart: every bar's label, thinned to one in k when they
    would overlap; the highlighted bar's always shown."""
    widest = max((_text_size(s, 0.5 * f)[0] for s in labs), default=0)
    every = max(1, int(math.ceil((widest + 6) / max(slot, 1))))
    shown = [i for i in range(len(labs)) if i % every == 0 or i == highlight]
    return Ticks(tuple(float(i) for i in shown), tuple(labs[i] for i in shown))


def _draw_bars(img: np.ndarray, fr: Frame, vals: np.ndarray, highlight: Optional[int],
               muted: frozenset = frozenset()) -> None:
    """Bar i of height ``vals[i]`` centred on data x = i (none where the value is not finite),
    bar ``highlight`` in the highlight colour, the bars ``muted`` in light grey."""
    half = 0.38  # half a bar's width, data units (a slot is 1)
    base_v = fr.px(0.0, 0.0)[1]
    for i, v in enumerate(vals):
        if not math.isfinite(v):
            continue
        (ua, vv), (ub, _) = fr.px(np.array([i - half, i + half]), np.array([v, v]))
        colour = HIGHLIGHT_COLOUR if i == highlight else MUTED_COLOUR if i in muted \
            else BAR_COLOUR
        y_a, y_b = sorted((int(round(vv)), int(round(base_v))))
        cv2.rectangle(img, (int(round(ua)), y_a), (int(round(ub)), max(y_b, y_a + 1)), colour, -1,
                      cv2.LINE_AA)


def _draw_values(img: np.ndarray, fr: Frame, vals: np.ndarray, highlight: Optional[int],
                 f: float) -> None:
    """Each bar's value above it ("-" for a missing one), the highlighted bar's in bold."""
    base_v = fr.px(0.0, 0.0)[1]
    fs = 0.45 * f
    for i, v in enumerate(vals):
        u = fr.px(float(i), 0.0)[0]
        if math.isfinite(v):
            vv = min(fr.px(float(i), float(v))[1], base_v)
            text = format_tick(v, 1.0 if float(v).is_integer() else 0.01)
        else:
            vv, text = base_v, "-"
        _text(img, text, (u, vv - 5 * f), fs, BLACK if i == highlight else TEXT,
              2 if i == highlight else 1, anchor="centre")
