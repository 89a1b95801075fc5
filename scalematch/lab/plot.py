"""Lab charts with matplotlib (the optional extra ``scalematch[lab]``), returned as BGR images.

The benchmark and the studies draw line charts: one colour and marker per series, a legend
placed where it hides the least, and a line broken at a missing value (NaN or inf). A chart
with no finite value at all says "no data". Figures are drawn on matplotlib's Agg canvas (no
window, no global pyplot state) and handed back as OpenCV-style BGR arrays, so callers and
tests treat them like any other image. The product's own small chart of a match's scales
(:mod:`scalematch.chart`) needs OpenCV only.
"""

from __future__ import annotations

from typing import Dict, Optional, Sequence, Tuple

import numpy as np

from ..chart import DEFAULT_SIZE, PathLike, save

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
MARKERS = ("o", "s", "^", "D", "P", "X", "*")
#: Canvas resolution: ``size`` px at this many dots per inch.
DPI = 100

Series = Dict[str, Tuple[Sequence[float], Sequence[float]]]


def _as_xy(pair: Tuple[Sequence[float], Sequence[float]],
           name: str) -> Tuple[np.ndarray, np.ndarray]:
    """(xs, ys) as float arrays with every non-finite value NaN (matplotlib breaks lines there)."""
    if len(pair) != 2:
        raise ValueError(f"series {name!r} must be a pair (xs, ys), got {len(pair)} items")
    x = np.asarray(pair[0], dtype=np.float64).ravel()
    y = np.asarray(pair[1], dtype=np.float64).ravel()
    if x.shape != y.shape:
        raise ValueError(f"series {name!r}: xs has {x.size} values but ys has {y.size}")
    bad = ~(np.isfinite(x) & np.isfinite(y))
    return np.where(bad, np.nan, x), np.where(bad, np.nan, y)


def _figure(size: Tuple[int, int]):
    """A matplotlib Figure of ``size`` (width, height) px on an Agg canvas."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise ImportError("the lab's charts need matplotlib: pip install 'scalematch[lab]'"
                          ) from exc
    fig = Figure(figsize=(size[0] / DPI, size[1] / DPI), dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


def _to_bgr(fig) -> np.ndarray:
    """The drawn figure as an (H, W, 3) uint8 BGR array."""
    fig.canvas.draw()
    rgba = np.asarray(fig.canvas.buffer_rgba())
    return np.ascontiguousarray(rgba[:, :, 2::-1])


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
        The y range shown; default the data range.
    xticks : sequence of float, optional
        Positions of the x ticks (e.g. the factors measured); default matplotlib's.
    size : (int, int)
        Canvas (width, height), px.

    Returns
    -------
    (H, W, 3) uint8 array
        The chart, BGR.

    >>> img = line_chart({"a": ([1, 2, 3], [0.5, float("nan"), 0.9])}, ylim=(0, 1), size=(300, 200))
    >>> img.shape, img.dtype
    ((200, 300, 3), dtype('uint8'))
    """
    data = [(str(name), *_as_xy(pair, str(name))) for name, pair in series.items()]
    if ylim is not None:
        lo, hi = float(ylim[0]), float(ylim[1])
        if not (np.isfinite(lo) and np.isfinite(hi)) or hi <= lo:
            raise ValueError(f"ylim must be two finite values, low < high; got {ylim}")
    fig = _figure((int(size[0]), int(size[1])))
    ax = fig.add_subplot()
    for i, (name, x, y) in enumerate(data):
        colour = tuple(c / 255.0 for c in PALETTE[i % len(PALETTE)][::-1])
        ax.plot(x, y, label=name, color=colour, marker=MARKERS[i % len(MARKERS)],
                linewidth=2, markersize=6, clip_on=False)  # markers on the limits drawn whole
    if ylim is not None:
        ax.set_ylim(lo, hi)
    if xticks is not None:
        ax.set_xticks([float(v) for v in xticks if np.isfinite(v)])
    if not any(np.isfinite(y).any() for _, _, y in data):
        ax.text(0.5, 0.5, "no data", transform=ax.transAxes, ha="center", va="center",
                color="grey", fontsize=14)
    elif data:
        ax.legend(loc="best", fontsize="small", framealpha=0.85)
    ax.set_title(title)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, color="0.9")
    ax.set_axisbelow(True)
    fig.tight_layout()
    img = _to_bgr(fig)
    save(img, path)
    return img
