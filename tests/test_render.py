"""render: pictures of a hand-built MatchResult with a known transform: the matches picture,
the files of a folder (the overlay: test_overlay.py, the per-scale chart: test_scalechart.py)."""

from __future__ import annotations

import csv

import cv2
import numpy as np

from conftest import RATIO
from scalematch.config import Config
from scalematch.geometry import apply, footprint, similarity_parts
from scalematch.overlay import OUTLINE, overlay_zoom
from scalematch.render import matches_image, write_outputs
from scalematch.result import MatchResult, ScaleRow


def make_result(t, model="similarity", matched=True, high_shape=(360, 480)) -> MatchResult:
    rng = np.random.default_rng(1)
    xy_high = rng.uniform([0, 0], [high_shape[1] - 1, high_shape[0] - 1], size=(40, 2))
    if t is not None and model != "fundamental":
        xy_low = apply(t, xy_high)
    else:
        xy_low = xy_high / RATIO
    ratio, angle, tr = similarity_parts(t) if t is not None else (np.nan, np.nan, (np.nan,) * 2)
    rows = tuple(ScaleRow(s=s, ratio=ratio if s == 3 else np.nan, points=100 * s, initial=50,
                          kept=30, inliers=40 if s == 3 else 3, outlier_pct=20.0)
                 for s in (1.0, 2.0, 3.0, 4.0))
    return MatchResult(
        matched=matched, reason="" if matched else "too few inliers", model=model,
        transform=t if matched else None, resolution_ratio=ratio if matched else np.nan,
        rotation_deg=angle if matched else np.nan, translation=tr, best_scale=3.0,
        inliers=np.hstack([xy_high, xy_low]) if matched else np.zeros((0, 4)), scales=rows,
        timings={"total": 1.0}, config=Config())


def green_red_gap(out: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """|green - red| of the overlay over the footprint ``corners``, eroded by 3 px: the warped
    high image against the low one, pixel by pixel."""
    inside = np.zeros(out.shape[:2], np.uint8)
    cv2.fillConvexPoly(inside, np.round(corners).astype(np.int32), 1)
    inside = cv2.erode(inside, np.ones((7, 7), np.uint8)).astype(bool)
    return np.abs(out[..., 1].astype(float) - out[..., 2].astype(float))[inside]


def outline_mask(img: np.ndarray) -> np.ndarray:
    return np.all(np.abs(img.astype(int) - np.array(OUTLINE)) <= 40, axis=2)


def picture_of(out: np.ndarray, low: np.ndarray) -> int:
    """The row of ``out`` (an overlay) where the picture of ``low`` (grey, the size the overlay
    draws it) begins, between the caption bands: where the overlay's blue channel is ``low``
    (magenta: the coarser image in red and blue), the outline and the footprint aside."""
    h = low.shape[0]
    gaps = [np.median(np.abs(out[k:k + h, :, 0].astype(float) - low))
            for k in range(out.shape[0] - h + 1)]
    return int(np.argmin(gaps))


def test_matches_image(pair):
    low, high, t = pair
    res = make_result(t)
    img = matches_image(low, high, res)
    assert img.ndim == 3 and 360 <= img.shape[0] <= 720 + 100
    assert img.shape[1] >= low.shape[1] + high.shape[1] - 1  # both at height 377


def test_write_outputs(tmp_path, pair):
    low, high, t = pair
    paths = write_outputs(tmp_path / "out", "low.png", "high.png", low, high, make_result(t))
    for name in ("overlay.png", "matches.png", "scales.png", "matches.csv"):
        assert paths[name].is_file() and paths[name].stat().st_size > 0
    with open(paths["matches.csv"]) as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["x_high", "y_high", "x_low", "y_low"] and len(rows) == 41
    # a low image under 600 px is drawn enlarged, the high one warped onto that grid: grey
    # where they agree, as at its own size
    zoom = overlay_zoom(low.shape)
    drawn = cv2.imread(str(paths["overlay.png"]))
    assert zoom == 2 and drawn.shape[1:] == (2 * low.shape[1], 3)
    big = cv2.resize(np.clip(low, 0, 255).astype(np.uint8), None, fx=zoom, fy=zoom,
                     interpolation=cv2.INTER_LINEAR)
    top = picture_of(drawn, big)
    assert top > 20 and drawn.shape[0] - top - big.shape[0] > 10  # a band above, one below
    drawn = drawn[top:top + big.shape[0]]
    corners = footprint(t, high.shape) * zoom + (zoom - 1) / 2  # cv2.resize's grid
    assert green_red_gap(drawn, corners).mean() < 3.0  # measured 1.7 (2.7 at its own size)
    # not matched: everything is still written, the CSV has only its header
    paths = write_outputs(tmp_path / "none", "low.png", "high.png", low, high,
                          make_result(None, matched=False))
    assert paths["matches.csv"].read_text().strip() == "x_high,y_high,x_low,y_low"


def test_told_apart_names_two_files_of_the_same_name_by_their_folders():
    from scalematch.render import told_apart

    assert told_apart("data/boat/img1.png", "data/graf/img1.png") == ("boat/img1.png",
                                                                      "graf/img1.png")
    assert told_apart("a/low.png", "a/high.png") == ("low.png", "high.png")
