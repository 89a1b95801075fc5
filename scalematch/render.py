"""The pictures of a match written into a folder (``write_outputs``, the command line's
``--out-dir``), and the side-by-side matches picture drawn here.

* ``overlay.png``: the finer image warped onto the coarser one (:mod:`scalematch.overlay`);
* ``matches.png`` (``matches_image``): the two images side by side at one height, a line per
  inlier;
* ``scales.png``: inliers against scale (:mod:`scalematch.scalechart`);
* ``matches.csv`` (``write_matches_csv``): the inliers.

Conventions as in ``result``: OpenCV pixels (centres at integers), ``transform`` maps a
high-resolution pixel to a low-resolution pixel (2x3 or 3x3).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Dict, Tuple, Union

import cv2
import numpy as np

from .captions import band
from .geometry import apply, resize_map
from .greylevels import to_bgr8
from .overlay import INLIER_DOT, enlarged, overlay, overlay_footer, overlay_zoom
from .result import MatchResult
from .scalechart import scale_plot
from .verdict import verdict
from .working import in_decoded

PathLike = Union[str, Path]

#: The matches picture's inlier lines (BGR; their dots: ``overlay.INLIER_DOT``), and a "no"'s
#: refused candidate's, greyed
INLIER_LINE = (60, 200, 60)  # green
REJECTED_LINE = (150, 150, 150)
REJECTED_DOT = (190, 190, 190)
#: Height range of the side-by-side matches picture, px.
MATCHES_HEIGHT = (360, 720)
#: Inlier lines drawn at most (a seeded random subset beyond this, said in the caption).
MAX_LINES = 300
#: The files ``write_outputs`` writes into its folder.
OUTPUT_FILES = ("overlay.png", "matches.png", "scales.png", "matches.csv")


def _fit_height(img: np.ndarray, height: int) -> Tuple[np.ndarray, float]:
    h = img.shape[0]
    f = height / h
    if abs(f - 1.0) < 1e-9:
        return img, 1.0
    w = max(int(round(img.shape[1] * f)), 1)
    interp = cv2.INTER_AREA if f < 1 else cv2.INTER_LINEAR
    out = cv2.resize(img, (w, height), interpolation=interp)
    return out, w / img.shape[1]


def size_label(width: int, height: int, factor: float) -> str:
    """An image's size as drawn, and how much smaller than its file that is.

    >>> size_label(2304, 1728, 2.0), size_label(640, 480, 1.0)
    ('2304x1728 (the file at 1/2)', '640x480')
    """
    return f"{width}x{height}" + (f" (the file at 1/{factor:g})" if factor != 1.0 else "")


def matches_image(low: np.ndarray, high: np.ndarray, result: MatchResult,
                  seed: int = 0, factors: Tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """low (left) and high (right) side by side at one height, a line per inlier match.

    The height is the taller image's, kept within ``MATCHES_HEIGHT``; at most ``MAX_LINES``
    lines (a seeded random subset beyond that, said in the caption). ``factors``: the images
    are their files' shrunk by these (the caption says so; ``result`` is in their pixels).
    """
    low_bgr, high_bgr = to_bgr8(low), to_bgr8(high)
    height = int(np.clip(max(low_bgr.shape[0], high_bgr.shape[0]), *MATCHES_HEIGHT))
    a, fa = _fit_height(low_bgr, height)
    b, fb = _fit_height(high_bgr, height)
    gap = 10
    canvas = np.full((height, a.shape[1] + gap + b.shape[1], 3), 255, np.uint8)
    canvas[:, :a.shape[1]] = a
    x0 = a.shape[1] + gap
    canvas[:, x0:] = b
    refused = not result.matched and result.rejected is not None
    pts = np.asarray(result.rejected.inliers if refused else result.inliers,
                     dtype=np.float64).reshape(-1, 4)
    line_colour, dot_colour = (REJECTED_LINE, REJECTED_DOT) if refused else (INLIER_LINE, INLIER_DOT)
    note = ""
    if pts.shape[0] > MAX_LINES:
        keep = np.random.default_rng(seed).choice(pts.shape[0], MAX_LINES, replace=False)
        pts = pts[np.sort(keep)]
        note = f" ({MAX_LINES} of them drawn)"
    for xh, yh, xl, yl in pts:
        pa = apply(resize_map(fa), [[xl, yl]])[0]
        pb = apply(resize_map(fb), [[xh, yh]])[0] + (x0, 0.0)
        ia = (int(round(pa[0] * 16)), int(round(pa[1] * 16)))
        ib = (int(round(pb[0] * 16)), int(round(pb[1] * 16)))
        cv2.line(canvas, ia, ib, line_colour, 1, cv2.LINE_AA, shift=4)
        cv2.circle(canvas, ia, 2 * 16, dot_colour, -1, cv2.LINE_AA, shift=4)
        cv2.circle(canvas, ib, 2 * 16, dot_colour, -1, cv2.LINE_AA, shift=4)
    lh, lw = low_bgr.shape[:2]
    hh, hw = high_bgr.shape[:2]
    what = (f"{len(pts)} inliers of the refused candidate (grey){note}" if refused
            else f"{result.n_inliers} inlier matches{note}")
    head = (f"left: low {size_label(lw, lh, factors[0])}   right: high "
            f"{size_label(hw, hh, factors[1])}   {what}")
    return np.vstack([band([head, verdict(result)], canvas.shape[1]), canvas])


def _write_png(path: Path, image: np.ndarray) -> None:
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"{path}: OpenCV could not encode the picture")
    buf.tofile(str(path))


def write_matches_csv(path: PathLike, result: MatchResult) -> None:
    """Inlier matches as CSV: header x_high,y_high,x_low,y_low, one row per match (px)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["x_high", "y_high", "x_low", "y_low"])
        for row in np.asarray(result.inliers, dtype=np.float64).reshape(-1, 4):
            w.writerow([f"{v:.3f}" for v in row])


def told_apart(a: PathLike, b: PathLike) -> Tuple[str, str]:
    """The shortest trailing parts of two paths that tell them apart (their file names, with
    as many parent folders as needed: two sequences' img1.png are boat/img1.png and
    graf/img1.png).

    >>> told_apart("data/boat/img1.png", "data/graf/img1.png")
    ('boat/img1.png', 'graf/img1.png')
    >>> told_apart("x/low.png", "y/high.png")
    ('low.png', 'high.png')
    """
    pa, pb = Path(a).resolve().parts, Path(b).resolve().parts
    for k in range(1, max(len(pa), len(pb)) + 1):
        na, nb = "/".join(pa[-k:]), "/".join(pb[-k:])
        if na != nb:
            return na, nb
    return Path(a).name, Path(b).name  # the same file twice


def write_outputs(out_dir: PathLike, low_path: PathLike, high_path: PathLike,
                  low: np.ndarray, high: np.ndarray, result: MatchResult,
                  factors: Tuple[float, float] = (1.0, 1.0)) -> Dict[str, Path]:
    """Write overlay.png, matches.png, scales.png and matches.csv into ``out_dir``.

    Everything is written whether or not a match was found (the overlay then shows ``low`` with
    the reason, the CSV only its header). ``low_path``/``high_path`` name the inputs in the
    pictures. ``factors``: ``low`` and ``high`` are their files' images shrunk by these (decoded
    at a reduced size, :func:`scalematch.imageio.read_reduced`); the pictures are drawn on them,
    the CSV stays in the files' pixels. Returns name -> path written. Raises ``OSError`` when
    ``out_dir`` is not writable.
    """
    drawn = in_decoded(result, *factors)
    f_low, f_high = factors
    # the pictures show the finer image on the coarser one: a "no", its refused candidate's
    order = result.rejected.order if not result.matched and result.rejected is not None \
        else result.order
    swapped = order == "swapped"
    if swapped:
        low_path, high_path, low, high = high_path, low_path, high, low
        f_low, f_high = f_high, f_low
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {name: out / name for name in OUTPUT_FILES}
    low_name, high_name = told_apart(low_path, high_path)
    zoom = overlay_zoom(low.shape)
    big = drawn if zoom == 1 else in_decoded(
        result, *((factors[0], factors[1] / zoom) if swapped else (factors[0] / zoom, factors[1])))
    ov = overlay(low if zoom == 1 else enlarged(low, zoom), high, big,
                 footer=[overlay_footer(low_name, high_name, swapped and not result.matched,
                                        f_low / zoom)],
                 enlarged_by=zoom)
    _write_png(paths["overlay.png"], ov)
    _write_png(paths["matches.png"], matches_image(low, high, drawn, factors=(f_low, f_high)))
    _write_png(paths["scales.png"], scale_plot(result))
    write_matches_csv(paths["matches.csv"], result)
    return paths
