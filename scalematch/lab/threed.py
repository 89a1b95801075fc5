"""The fundamental-matrix benchmark on real 3-D pairs from the multi-view scenes of
``shared/data/photos``, against a reference F from a stronger run.

Protocol (../shared/EVALUATION.md, "Real pairs"): the eight ef pairs are too few to tune a
decision on; the photos of one scene seen from several places give more. A pair is two photos
of one scene (:func:`candidate_pairs`) that truly overlap: the first look of its reference
has at least ``MIN_FIRST_LOOK_INLIERS`` inliers, the reference ``MIN_REFERENCE_INLIERS``, and
it passed a check by eye (``BY_EYE_DROPPED``). Each pair is given as a zoom pair, one photo
shrunk by 4 (``KINDS``).

The reference of a pair (:func:`reference_of`), made once by ``scalematch lab 3d-reference``
and stored in ``threed_reference.json`` beside this module: SIFT on the full-resolution photos
with no cap on the keypoints, matched under the guidance of a first look at the photos shrunk
to 1024 px (:func:`guided_matches`), MAGSAC++ (``cv2.USAC_MAGSAC``) at ``REFERENCE_PX``, then
Levenberg-Marquardt on the Sampson error of its inliers (:func:`refine_fundamental`). The JSON
keeps the F, its inlier count and a fixed sample of its inliers spread over the photo
(:func:`spread_sample`), and for a scene of three or more views the points seen in all three
(:func:`tracks_of`).

An answer F is scored in the pixels of the images as given (:func:`points_given`) by

* ``error_px``: the mean symmetric epipolar distance of the reference's sample
  (``efpairs.symmetric_epipolar_error``, as the ef pairs' clicked points);
* ``orders_px``: its distance to the other order's answer (:func:`f_distance`);
* ``transfer_px``: the epipolar transfer from a third view (:func:`transfer_errors`): each
  point of a three-view track predicted in one image from the answer's line and the line of
  the third view's reference, against where it was seen.

Every F here is in one convention: ``x_B^T F x_A = 0`` (A -> B), A and B the pair's photos in
name order. The data is read at run time from the shared folder and never copied into the
repository. A benchmark, not a test: nothing here asserts a time.
``scalematch lab 3d-pairs --help``, ``scalematch lab 3d-reference --help``.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import click
import cv2
import numpy as np

from ..overlay import line_ends
from ..stages.epipolar import (homogeneous, refine_fundamental,
                               sampson_residuals)
from .datasets import POINT_WITH_OPTION, list_photos, require_shared, scene_of, shared_option
from .efpairs import (MAGSAC_CONFIDENCE, MAGSAC_ITERATIONS, SOLVED_PX, WRONG_PX, EfPair, Run,
                      run_orders, symmetric_epipolar_error)

PathLike = Union[str, Path]

#: The photos' folder inside the shared folder (photos/SOURCES.md)
PHOTOS_SUBDIR = Path("data") / "photos"
#: Scene prefixes whose photos are several views of one scene (photos/SOURCES.md: the drone
#: flights, the castle, the tree, the cathedral, the Strecha sets). Left out: the prefixes that
#: gather unrelated photos of one source (deepin, popos, jpegtest) and openmvg-360school, whose
#: equirectangular panoramas have no pinhole camera and so no fundamental matrix.
MULTIVIEW_SCENES = ("brighton", "monstree", "openmvg-palmdesert", "opensfm-berlin", "sceaux",
                    "snowpeak", "strecha")
#: The reference JSON, beside this module (made by ``scalematch lab 3d-reference``)
REFERENCE_JSON = Path(__file__).with_name("threed_reference.json")

#: The reference's MAGSAC++ inlier threshold, px of the full-resolution photos (EVALUATION.md,
#: "Real pairs": "MAGSAC++ at 0.5 px"); also the Sampson distance under which a point is an
#: inlier of the refined F
REFERENCE_PX = 0.5
#: The reference's MAGSAC++ iterations: ten times the peer's (efpairs.MAGSAC_ITERATIONS), for a
#: stronger run on tens of thousands of matches
REFERENCE_ITERATIONS = 10 * MAGSAC_ITERATIONS
#: The reference's first look, which guides its matching: SIFT on the photos shrunk so that
#: the longer side is ``COARSE_SIDE`` px, Lowe's ratio test ``COARSE_RATIO`` (Lowe, IJCV 2004,
#: 7.1: 0.8 removes 90 % of the false matches and 5 % of the true ones) and MAGSAC++ at
#: ``COARSE_PX`` of the shrunk photos (the peer's settings, efpairs). At full resolution the
#: ratio test alone fails on bark, rock and foliage: a photo's 100 000 to 250 000 keypoints
#: hold a near twin of almost every descriptor, and on monstree IMG_1029~IMG_1042 MAGSAC++
#: kept 13 of 1155 such matches, against 78 of 172 at 1024 px
COARSE_SIDE = 1024
COARSE_RATIO = 0.8
COARSE_PX = 1.0
#: Guided matching at full resolution (Hartley & Zisserman, 11.9): each keypoint's
#: ``GUIDED_K`` nearest descriptors in the other photo, of which the nearest within the band
#: of the first look's epipolar line (half width: ``COARSE_PX`` times the shrink factor, what
#: the first look is good to), if its distance is under ``GUIDED_RATIO`` times that of the
#: next one in the band (Lowe's test among the candidates the geometry allows); a pair is kept
#: when each is the other's choice. Without the ratio test, the band and the mutual choice let
#: through hundreds of chance pairs of look-alike grass and leaf blobs: 803 guided matches and
#: 265 inliers on brighton DJI_0020~DJI_0030, which do not overlap (14 inliers with it)
GUIDED_K = 16
GUIDED_RATIO = 0.8
#: The nearest descriptors: FLANN's randomised kd-trees (Muja & Lowe, "Fast approximate
#: nearest neighbors with automatic algorithm configuration", VISAPP 2009): the index kind, the
#: trees and the leaves checked per query. On monstree IMG_1029~IMG_1042 (band and mutual
#: choice, no ratio test), 64 checks gave 549 matches in 19 s, 256 gave 1075 in 132 s while
#: other work shared the cores; an exact search of 100 000 by 150 000 descriptors takes about
#: 6 min a pair here
FLANN_KDTREE = 1
FLANN_TREES = 4
FLANN_CHECKS = 128
#: Rounds of refit and re-selection of the inliers at ``REFERENCE_PX`` after MAGSAC++: the
#: inlier set stops changing within two on the scenes here
REFERENCE_ROUNDS = 3
#: Two photos overlap when the first look has at least ``MIN_FIRST_LOOK_INLIERS`` inliers
#: (the 24 candidate pairs of no overlap have 9 to 12, the 16 others 46 to 702:
#: docs/results/THREED.md, "The references") and the reference at least ``MIN_REFERENCE_INLIERS``,
#: three times the guided matching's chance inliers on a pair of no overlap (14)
MIN_FIRST_LOOK_INLIERS = 30
MIN_REFERENCE_INLIERS = 40
#: The semi-local check of the reference's inliers, after the semi-local constraints of
#: Schmid & Mohr ("Local greyvalue invariants for image retrieval", PAMI 1997, 3.3): the affine
#: map fitted to an inlier's ``NEIGHBOURS`` nearest inliers in A must bring it within
#: ``LOCAL_TOLERANCE`` times their median distance from it in B. An epipolar line holds every
#: window of a row of windows and every blob of a lawn: such a pair fits F and not its
#: neighbours (157 of 486 inliers of strecha castle-P30_0029~entry-P10_0000, window to
#: window along the row, whose epipolar lines run along the rows; 7 of 177 of brighton
#: DJI_0020~DJI_0033, each far from the overlap). A true pair across a depth edge fails it
#: too, which costs a few points and no wrong one
NEIGHBOURS = 8
LOCAL_TOLERANCE = 0.3
#: The reference's sample of its inliers: one per cell of a grid over photo A (columns, rows),
#: the inlier of least Sampson distance in each, so the score weighs the whole overlap and
#: not its most textured corner
SAMPLE_GRID = (8, 6)
#: The three-view tracks kept per pair and third view: one per cell of this grid over photo A
TRACK_GRID = (6, 4)
#: Fewest tracks through a third view for its transfer to be reported
MIN_TRACKS = 5
#: Least angle between the two epipolar lines a transferred point is the crossing of, degrees:
#: near-parallel lines (three cameras nearly in a line, as along a drone's flight) put the
#: crossing anywhere along them (Hartley & Zisserman, 15.3: transfer degenerates there)
MIN_TRANSFER_DEG = 10.0
#: Passes of the first-order (Sampson) correction that move a point pair onto an F
CORRECTION_PASSES = 3
#: How the two photos are given: one of them shrunk by 4 (the longer side 750 to 1150 px) and
#: the other as it is, which scalematch's working size brings to 2048 px: a zoom pair of
#: ratio about 2 as this tool's users have it, with the low-resolution image either photo
#: ("A/4": A shrunk). "photos" (both as they are) is offered too; SIFT's exact matching of two
#: photos of 100 000 to 250 000 keypoints takes minutes a run, so it is not in the default
KINDS = ("B/4", "A/4")
#: The orders a pair is given in: A first (the ``low`` argument), then B first (efpairs.ORDERS)
ORDERS = ("A,B", "B,A")
#: The methods, in the order they are reported (efpairs' runners)
METHODS = ("scalematch", "sift-magsac")
#: The check by eye of the references (``scalematch lab 3d-reference --draw``, one picture a
#: pair: every sample point as a pair of crops, docs/results/THREED.md): the references dropped
#: (pair label -> why), and the sample points dropped from references kept (pair label -> (x_A, y_A)
#: of each, px, and why). A point is matched to the sample within ``BY_EYE_POINT_PX``
BY_EYE_DROPPED: Dict[str, str] = {
    "sceaux 100_7100~100_7110": "repeated windows: 5 of its 11 sample points pair a window, a "
                                "pier or the door with the next one along the row, on the same "
                                "epipolar line (points 2, 3, 4, 6, 8)",
}
BY_EYE_DROPPED_POINTS: Dict[str, Tuple[Tuple[Tuple[float, float], ...], str]] = {
    "monstree IMG_1029~IMG_1042": (((2902.24, 3775.17),),
                                   "moss on the ground beside the trunk against the wood of "
                                   "the jaw (point 12)"),
    "monstree IMG_1029~IMG_1046": (((1652.79, 1646.28),),
                                   "pale wood beside an eye against the bark of a ridge "
                                   "(point 1)"),
}
BY_EYE_POINT_PX = 1.0


# --------------------------------------------------------------------------------------------
# The pairs
# --------------------------------------------------------------------------------------------

def candidate_pairs(names: Sequence[str]) -> List[Tuple[str, str]]:
    """Every two photos of one multi-view scene (``MULTIVIEW_SCENES``), as (A, B) file names
    with A < B, sorted: the pairs a reference is fitted to.

    >>> candidate_pairs(["sceaux_2.JPG", "deepin_a.jpg", "sceaux_1.JPG", "deepin_b.jpg",
    ...                  "brighton_9.JPG"])
    [('sceaux_1.JPG', 'sceaux_2.JPG')]
    """
    by_scene: Dict[str, List[str]] = {}
    for n in sorted(set(names)):
        if scene_of(n) in MULTIVIEW_SCENES:
            by_scene.setdefault(scene_of(n), []).append(n)
    return sorted(p for ns in by_scene.values() for p in itertools.combinations(ns, 2))


def pair_label(a: str, b: str) -> str:
    """A pair's short name: the scene, then each photo's name after it, without the extension.

    >>> pair_label("sceaux_100_7100.JPG", "sceaux_100_7102.JPG")
    'sceaux 100_7100~100_7102'
    """
    return f"{scene_of(a)} {_view(a)}~{_view(b)}"


def _view(name: str) -> str:
    return Path(name).stem.split("_", 1)[1]


def third_views(pair: Tuple[str, str], pairs: Sequence[Tuple[str, str]]) -> List[str]:
    """The photos C such that (A, C) and (B, C) are both among ``pairs`` (in either order),
    sorted: the third views of ``pair`` = (A, B).

    >>> third_views(("a", "b"), [("a", "b"), ("a", "c"), ("b", "c"), ("a", "d")])
    ['c']
    """
    have = {frozenset(p) for p in pairs}
    a, b = pair
    others = {x for p in pairs for x in p} - {a, b}
    return sorted(c for c in others if frozenset((a, c)) in have and frozenset((b, c)) in have)


# --------------------------------------------------------------------------------------------
# Epipolar geometry over numpy arrays (x_B^T F x_A = 0)
# --------------------------------------------------------------------------------------------

def correct_onto(f: np.ndarray, points: np.ndarray, passes: int = CORRECTION_PASSES) -> np.ndarray:
    """(N, 4) points (x_A, y_A, x_B, y_B) moved onto ``x_B^T F x_A = 0`` by the first-order
    (Sampson) correction, repeated ``passes`` times (Hartley & Zisserman, 12.4): the nearest
    point pairs that F explains.

    >>> f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # y_B = y_A
    >>> correct_onto(f, np.array([[0.0, 0, 5, 2]])).round(9).tolist()
    [[0.0, 1.0, 5.0, 1.0]]
    """
    f = np.asarray(f, np.float64)
    p = np.asarray(points, np.float64).reshape(-1, 4).copy()
    for _ in range(passes):
        xa, xb = homogeneous(p[:, :2]), homogeneous(p[:, 2:])
        fxa, ftxb = xa @ f.T, xb @ f
        num = np.einsum("ij,ij->i", xb, fxa)
        grad = np.stack([ftxb[:, 0], ftxb[:, 1], fxa[:, 0], fxa[:, 1]], axis=1)
        den = np.sum(grad ** 2, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            p -= np.where(den > 0, num / den, 0.0)[:, None] * grad
    return p


def f_distance(f_1: Optional[np.ndarray], f_2: Optional[np.ndarray], points: np.ndarray) -> float:
    """How far two Fs are over a scene's points, px: the points moved onto each F
    (:func:`correct_onto`), their mean symmetric epipolar distance under the other, the two
    averaged. 0 for one F; NaN when either is None.

    >>> f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    >>> pts = np.array([[0.0, 0, 5, 0], [10, 10, 20, 10]])
    >>> f_distance(f, 7 * f, pts), f_distance(f, None, pts)
    (0.0, nan)
    """
    if f_1 is None or f_2 is None:
        return math.nan
    one = symmetric_epipolar_error(f_2, correct_onto(f_1, points))
    two = symmetric_epipolar_error(f_1, correct_onto(f_2, points))
    return 0.5 * (one + two)


def _cross_points(l_1: np.ndarray, l_2: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(N, 2) crossings of two (N, 3) families of lines and the (N,) sines of their angles."""
    x = np.cross(l_1, l_2)
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = x[:, :2] / x[:, 2:]
        sine = np.abs(l_1[:, 0] * l_2[:, 1] - l_1[:, 1] * l_2[:, 0]) / (
            np.hypot(l_1[:, 0], l_1[:, 1]) * np.hypot(l_2[:, 0], l_2[:, 1]))
    return xy, np.nan_to_num(sine)


def transfer_errors(f_ab: np.ndarray, f_ac: np.ndarray, f_bc: np.ndarray, tracks: np.ndarray,
                    min_deg: float = MIN_TRANSFER_DEG) -> np.ndarray:
    """Epipolar transfer from a third view C (Hartley & Zisserman, 15.3): the distances, px,
    between each track's point in B and the crossing of its lines ``F_AB x_A`` and
    ``F_CB x_C``, and between its point in A and the crossing of ``F_AB^T x_B`` and
    ``F_CA x_C``; the crossings of lines less than ``min_deg`` apart are left out.

    Parameters
    ----------
    f_ab, f_ac, f_bc : (3, 3) arrays
        ``x_B^T F_AB x_A = 0``, ``x_C^T F_AC x_A = 0``, ``x_C^T F_BC x_B = 0``; ``f_ab`` is the
        F scored, the other two the third view's references.
    tracks : (N, 6) array
        x_A, y_A, x_B, y_B, x_C, y_C of points seen in all three.

    Returns
    -------
    (M,) array
        The distances of the crossings kept (in B, then in A).
    """
    t = np.asarray(tracks, np.float64).reshape(-1, 6)
    xa, xb, xc = homogeneous(t[:, :2]), homogeneous(t[:, 2:4]), homogeneous(t[:, 4:])
    f_ab, f_ac, f_bc = (np.asarray(m, np.float64) for m in (f_ab, f_ac, f_bc))
    in_b, sin_b = _cross_points(xa @ f_ab.T, xc @ f_bc)  # F_AB x_A and F_CB x_C = F_BC^T x_C
    in_a, sin_a = _cross_points(xb @ f_ab, xc @ f_ac)  # F_AB^T x_B and F_CA x_C = F_AC^T x_C
    least = math.sin(math.radians(min_deg))
    d_b = np.linalg.norm(in_b - t[:, 2:4], axis=1)[sin_b >= least]
    d_a = np.linalg.norm(in_a - t[:, :2], axis=1)[sin_a >= least]
    return np.concatenate([d_b, d_a])


def spread_sample(xy: np.ndarray, residual: np.ndarray, size: Tuple[int, int],
                  grid: Tuple[int, int] = SAMPLE_GRID) -> np.ndarray:
    """Indices of at most one point per cell of a ``grid`` (columns, rows) over an image of
    ``size`` (W, H): the point of least ``|residual|`` in each cell, in cell order.

    >>> xy = np.array([[1.0, 1], [2, 2], [9, 9], [9, 1]])
    >>> spread_sample(xy, np.array([0.3, 0.1, 0.2, 0.5]), (10, 10), (2, 2)).tolist()
    [1, 3, 2]
    """
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    if len(xy) == 0:
        return np.zeros(0, np.int64)
    w, h = size
    cols, rows = grid
    cx = np.clip((xy[:, 0] * cols / w).astype(np.int64), 0, cols - 1)
    cy = np.clip((xy[:, 1] * rows / h).astype(np.int64), 0, rows - 1)
    cell = cy * cols + cx
    order = np.lexsort((np.abs(np.asarray(residual, np.float64)), cell))
    first = np.ones(len(order), bool)
    first[1:] = cell[order][1:] != cell[order][:-1]
    return order[first]


# --------------------------------------------------------------------------------------------
# The images as given: one photo shrunk by a zoom factor
# --------------------------------------------------------------------------------------------

def shrunk_size(size: Tuple[int, int], zoom: float) -> Tuple[int, int]:
    """(W, H) of an image of ``size`` (W, H) shrunk by ``zoom``, rounded, at least 1 px.

    >>> shrunk_size((4000, 2250), 4)
    (1000, 562)
    """
    return max(1, int(round(size[0] / zoom))), max(1, int(round(size[1] / zoom)))


def shrink_map(size: Tuple[int, int], zoom: float) -> np.ndarray:
    """3x3 map of a pixel of an image of ``size`` (W, H) to its pixel in the copy shrunk by
    ``zoom`` to :func:`shrunk_size` (``cv2.resize``'s centre-aligned convention,
    :func:`scalematch.geometry.resize_map`, with the scale of each axis as rounded)."""
    from ..geometry import as_matrix3, resize_map

    w, h = shrunk_size(size, zoom)
    return as_matrix3(resize_map(w / size[0], h / size[1]))


def parse_kind(kind: str) -> Tuple[float, float]:
    """(zoom of A, zoom of B) of a kind: "photos", "A/<zoom>" or "B/<zoom>"; ``ValueError``
    otherwise.

    >>> parse_kind("B/4"), parse_kind("A/2.5"), parse_kind("photos")
    ((1.0, 4.0), (2.5, 1.0), (1.0, 1.0))
    """
    text = kind.strip()
    if text == "photos":
        return 1.0, 1.0
    side, _, value = text.partition("/")
    try:
        zoom = float(value)
    except ValueError:
        zoom = math.nan
    if side not in ("A", "B") or not zoom >= 1:
        raise ValueError(f"a kind is 'photos', 'A/<zoom>' or 'B/<zoom>' with zoom >= 1, "
                         f"got {kind!r}")
    return (zoom, 1.0) if side == "A" else (1.0, zoom)


def points_given(points: np.ndarray, map_a: np.ndarray, map_b: np.ndarray) -> np.ndarray:
    """(N, 2k) points (x_A, y_A, x_B, y_B[, x_C, y_C]) of the full-resolution photos with A's
    and B's mapped by the 3x3 ``map_a`` and ``map_b`` (:func:`shrink_map`) into the pixels of
    the images as given; C's are kept.

    >>> s = shrink_map((8, 8), 4)
    >>> points_given(np.array([[1.5, 1.5, 1.0, 1.0]]), s, np.eye(3)).tolist()
    [[0.0, 0.0, 1.0, 1.0]]
    """
    p = np.asarray(points, np.float64).copy()
    for cols, m in ((slice(0, 2), map_a), (slice(2, 4), map_b)):
        p[:, cols] = homogeneous(p[:, cols]) @ np.asarray(m, np.float64)[:2].T
    return p


def f_given(f: np.ndarray, map_src: np.ndarray, map_dst: np.ndarray) -> np.ndarray:
    """An F (``x_dst^T F x_src = 0``) of the full-resolution photos in the pixels of the images
    as given, ``map_src`` and ``map_dst`` taking the photos' pixels there:
    ``S_dst^-T F S_src^-1``."""
    s_src, s_dst = (np.linalg.inv(np.asarray(m, np.float64)) for m in (map_src, map_dst))
    return s_dst.T @ np.asarray(f, np.float64) @ s_src


def shrink(image: np.ndarray, zoom: float) -> np.ndarray:
    """``image`` shrunk by ``zoom`` to :func:`shrunk_size` with area averaging (the same view
    from a camera with ``zoom`` times fewer pixels)."""
    if zoom == 1:
        return image
    h, w = image.shape[:2]
    return cv2.resize(image, shrunk_size((w, h), zoom), interpolation=cv2.INTER_AREA)


# --------------------------------------------------------------------------------------------
# The reference: full resolution, every SIFT point, MAGSAC++ at 0.5 px, then LM
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Features:
    """SIFT keypoints of one photo, at full resolution or shrunk."""

    xy: np.ndarray = field(repr=False)  #: (N, 2) float32 positions (x, y), px of the image
    desc: np.ndarray = field(repr=False)  #: (N, 128) float32 descriptors
    size: Tuple[int, int] = (0, 0)  #: (W, H) of the photo at full resolution
    zoom: float = 1.0  #: the shrink factor of the image the keypoints are in


def coarse_zoom(size: Tuple[int, int], side: int = COARSE_SIDE) -> float:
    """The shrink factor that brings the longer side of ``size`` (W, H) to ``side`` (1 when it
    is already no longer).

    >>> coarse_zoom((4000, 2250)), coarse_zoom((800, 600))
    (3.90625, 1.0)
    """
    return max(1.0, max(size) / side)


def detect(path: PathLike, cache: Optional[PathLike] = None) -> Tuple[Features, Features]:
    """OpenCV SIFT with its default settings on the photo (grey, EXIF orientation applied) at
    full resolution, with no cap on the keypoints, and shrunk by :func:`coarse_zoom`; kept in
    ``cache/<name>.npz`` when given."""
    from ..imageio import read_grey
    from .baselines import detect_and_describe, to_uint8

    path = Path(path)
    stored = Path(cache) / f"{path.name}.npz" if cache is not None else None
    if stored is not None and stored.is_file():
        with np.load(stored) as z:
            size = (int(z["size"][0]), int(z["size"][1]))
            return (Features(z["xy"], z["desc"].astype(np.float32), size),
                    Features(z["coarse_xy"], z["coarse_desc"].astype(np.float32), size,
                             float(z["coarse_zoom"])))
    grey = read_grey(path)
    size = (grey.shape[1], grey.shape[0])
    zoom = coarse_zoom(size)
    out = []
    for image, z in ((grey, 1.0), (shrink(grey, zoom), zoom)):
        xy, desc = detect_and_describe(cv2.SIFT_create(), to_uint8(image))
        out.append(Features(xy, np.zeros((0, 128), np.float32) if desc is None else desc, size, z))
    if stored is not None:
        stored.parent.mkdir(parents=True, exist_ok=True)
        # SIFT's descriptor values are whole numbers 0..255 (OpenCV rounds and clips them)
        np.savez(stored, xy=out[0].xy, desc=out[0].desc.astype(np.uint8), size=np.array(size),
                 coarse_xy=out[1].xy, coarse_desc=out[1].desc.astype(np.uint8),
                 coarse_zoom=np.array(zoom))
    return out[0], out[1]


def first_look(coarse_a: Features, coarse_b: Features, seed: int = 0
               ) -> Tuple[Optional[np.ndarray], int]:
    """The F of the shrunk photos (ratio test ``COARSE_RATIO``, MAGSAC++ at ``COARSE_PX``
    of the shrunk photos), in full-resolution px, and its inlier count; (None, n) with fewer
    than 8."""
    from .baselines import ratio_matches

    m = one_to_one(ratio_matches(coarse_b.desc, coarse_a.desc, cv2.NORM_L2, COARSE_RATIO)[:, ::-1])
    if len(m) < 8:
        return None, 0
    cv2.setRNGSeed(int(seed))
    f, mask = cv2.findFundamentalMat(coarse_a.xy[m[:, 0]], coarse_b.xy[m[:, 1]], cv2.USAC_MAGSAC,
                                     COARSE_PX, MAGSAC_CONFIDENCE, MAGSAC_ITERATIONS)
    n = int(mask.sum()) if mask is not None else 0
    if f is None or f.shape[0] < 3 or n < 8:
        return None, n
    s_a, s_b = (shrink_map(c.size, c.zoom) for c in (coarse_a, coarse_b))
    f = s_b.T @ np.asarray(f[:3], np.float64) @ s_a  # x_B'^T F' x_A' with x' = S x
    return f / np.linalg.norm(f), n


def one_to_one(matches: np.ndarray) -> np.ndarray:
    """The (M, 2) index pairs whose first index and whose second index each occur once: many
    points matched to one point fit every F whose epipole lies on it, and MAGSAC++ finds that F
    (SIFT on two unrelated Strecha photos: 94 of 169 matches, 75 of them to one keypoint).

    >>> one_to_one(np.array([[0, 1], [2, 3], [0, 4], [5, 6]])).tolist()
    [[2, 3], [5, 6]]
    """
    m = np.asarray(matches, np.int64).reshape(-1, 2)
    once = np.ones(len(m), bool)
    for col in (0, 1):
        _, inverse, counts = np.unique(m[:, col], return_inverse=True, return_counts=True)
        once &= counts[inverse] == 1
    return m[once]


def nearest_descriptors(train: np.ndarray, query: np.ndarray, k: int = GUIDED_K, seed: int = 0
                        ) -> Tuple[np.ndarray, np.ndarray]:
    """(N, k) indices into ``train`` of each query descriptor's ``k`` nearest, nearest first,
    and their (N, k) L2 distances (FLANN, ``FLANN_TREES`` trees, ``FLANN_CHECKS`` checks;
    OpenCV's RNG seeded, so the trees are the same each run); -1 where fewer were found."""
    k = min(k, len(train))
    if k == 0 or len(query) == 0:
        return np.full((len(query), max(k, 0)), -1, np.int64), np.zeros((len(query), max(k, 0)))
    cv2.setRNGSeed(int(seed))
    index = cv2.flann_Index(np.ascontiguousarray(train, np.float32),
                            {"algorithm": FLANN_KDTREE, "trees": FLANN_TREES})
    idx, dist2 = index.knnSearch(np.ascontiguousarray(query, np.float32), k,
                                 params={"checks": FLANN_CHECKS})
    idx = np.asarray(idx, np.int64).reshape(len(query), k)
    return idx, np.sqrt(np.maximum(np.asarray(dist2, np.float64).reshape(len(query), k), 0))


def best_in_band(f: np.ndarray, xy_query: np.ndarray, xy_train: np.ndarray,
                 candidates: np.ndarray, distances: np.ndarray, band_px: float,
                 query_is_a: bool, ratio: float = GUIDED_RATIO) -> np.ndarray:
    """(N,) per query point the first of its ``candidates`` (indices into ``xy_train``, nearest
    descriptor first, at ``distances``) whose pair lies within ``band_px`` of F's epipolar lines
    in both photos, when its descriptor distance is under ``ratio`` times the next one in the
    band (the last candidate's when no other is in it); -1 otherwise. F: ``x_B^T F x_A = 0``;
    ``query_is_a``: the queries are A's points.

    >>> f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # y_B = y_A
    >>> xy = np.array([[0.0, 0], [3, 5.5], [1, 5]])
    >>> cands = np.array([[0, 2, 1]])
    >>> best_in_band(f, np.array([[0.0, 5]]), xy, cands, np.array([[1.0, 2, 3]]), 1.0,
    ...              True).tolist()   # 2 and 1 are in the band: 2 < 0.8 x 3
    [2]
    >>> best_in_band(f, np.array([[0.0, 5]]), xy, cands, np.array([[1.0, 2, 2.2]]), 1.0,
    ...              True).tolist()   # too near its rival in the band
    [-1]
    """
    from ..geometry import epipolar_distances

    n, k = candidates.shape
    if n == 0 or k == 0:
        return np.full(n, -1, np.int64)
    query = np.repeat(np.asarray(xy_query, np.float64), k, axis=0)
    train = np.asarray(xy_train, np.float64)[np.maximum(candidates, 0).ravel()]
    pa, pb = (query, train) if query_is_a else (train, query)
    ok = (epipolar_distances(f, pa, pb).max(axis=1) < band_px).reshape(n, k) & (candidates >= 0)
    rows = np.arange(n)
    first = np.argmax(ok, axis=1)
    rest = ok.copy()
    rest[rows, first] = False
    second = np.where(rest.any(axis=1), np.argmax(rest, axis=1), k - 1)
    keep = ok.any(axis=1) & (distances[rows, first] < ratio * distances[rows, second])
    return np.where(keep, candidates[rows, first], -1)


def guided_matches(feats_a: Features, feats_b: Features, f: np.ndarray, band_px: float,
                   seed: int = 0) -> np.ndarray:
    """(M, 2) keypoint indices (A, B) of the mutual guided matches: B's point is A's choice in
    the band of F (:func:`best_in_band` among its ``GUIDED_K`` nearest descriptors) and A's
    point is B's."""
    for_b = best_in_band(f, feats_b.xy, feats_a.xy,
                         *nearest_descriptors(feats_a.desc, feats_b.desc, seed=seed), band_px,
                         query_is_a=False)
    for_a = best_in_band(f, feats_a.xy, feats_b.xy,
                         *nearest_descriptors(feats_b.desc, feats_a.desc, seed=seed), band_px,
                         query_is_a=True)
    bs = np.nonzero(for_b >= 0)[0]
    mutual = bs[for_a[for_b[bs]] == bs]
    return np.stack([for_b[mutual], mutual], axis=1).astype(np.int64)


@dataclass(frozen=True)
class Reference:
    """The reference F of one pair and the matches it explains."""

    f: Optional[np.ndarray] = field(repr=False)  #: x_B^T F x_A = 0, unit norm; None: no F
    pairs: np.ndarray = field(repr=False)  #: (K, 2) keypoint indices (A, B) of its inliers
    coarse_inliers: int = 0  #: inliers of the first look (shrunk photos)
    matches: int = 0  #: guided matches at full resolution
    magsac_inliers: int = 0  #: inliers of MAGSAC++ before the refinement
    rms_magsac_px: float = math.nan  #: Sampson RMS of the final inliers under MAGSAC++'s F
    rms_px: float = math.nan  #: the same under the refined F
    refined_inliers: int = 0  #: inliers of the refined F, before the semi-local check

    @property
    def inliers(self) -> int:
        return int(len(self.pairs))


def fit_reference(pts_a: np.ndarray, pts_b: np.ndarray, seed: int = 0
                  ) -> Tuple[Optional[np.ndarray], np.ndarray, int, float]:
    """The reference F of matched points: MAGSAC++ at ``REFERENCE_PX``, then
    :func:`refine_fundamental` on its inliers and the inliers chosen again at ``REFERENCE_PX``
    of Sampson distance, ``REFERENCE_ROUNDS`` times at most.

    Returns
    -------
    f : (3, 3) array or None
        Unit norm, ``x_B^T F x_A = 0``; None when MAGSAC++ finds fewer than 8 inliers.
    inliers : (N,) bool array
        The final inliers among the matches.
    magsac_inliers : int
        MAGSAC++'s own.
    rms_magsac_px : float
        The Sampson RMS of the final inliers under MAGSAC++'s F, px.
    """
    pts_a = np.asarray(pts_a, np.float64).reshape(-1, 2)
    pts_b = np.asarray(pts_b, np.float64).reshape(-1, 2)
    none = (None, np.zeros(len(pts_a), bool), 0, math.nan)
    if len(pts_a) < 8:
        return none
    cv2.setRNGSeed(int(seed))
    f0, mask = cv2.findFundamentalMat(pts_a.astype(np.float32), pts_b.astype(np.float32),
                                      cv2.USAC_MAGSAC, REFERENCE_PX, MAGSAC_CONFIDENCE,
                                      REFERENCE_ITERATIONS)
    if f0 is None or mask is None or f0.shape[0] < 3 or int(mask.sum()) < 8:
        return none
    f0 = np.asarray(f0[:3], np.float64)
    first = mask.ravel().astype(bool)
    inl, f = first, f0
    for _ in range(REFERENCE_ROUNDS):
        refined = refine_fundamental(f, pts_a[inl], pts_b[inl])
        new = np.abs(sampson_residuals(refined, pts_a, pts_b)) < REFERENCE_PX
        if int(new.sum()) < 8:
            break  # keep the last F whose own inliers these are
        f, same, inl = refined, bool(np.array_equal(new, inl)), new
        if same:
            break
    r0 = sampson_residuals(f0, pts_a[inl], pts_b[inl])
    return f, inl, int(first.sum()), float(np.sqrt(np.mean(r0 ** 2)))


def local_affine_maps(pts_a: np.ndarray, pts_b: np.ndarray, k: int = NEIGHBOURS) -> np.ndarray:
    """(N, 3, 2) per pair the affine map, A px -> B px (``[x, y, 1] @ map``), fitted by least
    squares to the pairs of x_A's ``k`` nearest other points in A, then again without the
    worst quarter of them, so that one wrong pair does not bend the maps of the points around
    it. Needs N >= 4.

    >>> a = np.array([[0.0, 0], [1, 0], [0, 1], [1, 1], [2, 2]])
    >>> (np.hstack([a, np.ones((5, 1))]) @ local_affine_maps(a, 3 * a + 1, k=4)[0]).round(6).tolist()
    [[1.0, 1.0], [4.0, 1.0], [1.0, 4.0], [4.0, 4.0], [7.0, 7.0]]
    """
    pa = np.asarray(pts_a, np.float64).reshape(-1, 2)
    pb = np.asarray(pts_b, np.float64).reshape(-1, 2)
    n = len(pa)
    k = min(k, n - 1)
    if k < 3:  # an affine map needs three pairs
        raise ValueError(f"local_affine_maps needs at least 4 pairs, got {n}")
    d = np.linalg.norm(pa[:, None, :] - pa[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    near = np.argsort(d, axis=1, kind="stable")[:, :k]
    x = np.concatenate([pa[near], np.ones((n, k, 1))], axis=2)  # (n, k, 3)
    y = pb[near]  # (n, k, 2)
    maps = np.linalg.pinv(x) @ y
    kept = max(3, k - k // 4)
    best = np.argsort(np.linalg.norm(x @ maps - y, axis=2), axis=1, kind="stable")[:, :kept]
    x, y = np.take_along_axis(x, best[:, :, None], 1), np.take_along_axis(y, best[:, :, None], 1)
    return np.linalg.pinv(x) @ y


def local_misfit(pts_a: np.ndarray, pts_b: np.ndarray, k: int = NEIGHBOURS) -> np.ndarray:
    """(N,) per pair (x_A, x_B): the distance from x_B of its neighbours' affine map
    (:func:`local_affine_maps`) applied to x_A, over the median distance of those neighbours'
    partners from x_B. Small when the pair moves as its neighbours do; ``inf`` for all when
    there are fewer than 4 pairs.

    A jittered 4x4 grid, so that no two neighbours are at the same distance and the wrong pair
    is clearly the worst of every fit it enters (on a regular grid the pair dropped is a
    floating-point tie that the BLAS breaks):

    >>> grid = np.array([[x, y] for y in range(4) for x in range(4)], float)
    >>> a = grid + np.random.default_rng(1).uniform(-0.3, 0.3, (16, 2))
    >>> b = 2 * a + 10   # a zoom of 2
    >>> b[5] = [40, 40]   # one partner elsewhere
    >>> m = local_misfit(a, b, k=8)
    >>> np.flatnonzero(m > 0.1).tolist(), round(float(m[5]), 1)
    ([5], 1.0)
    """
    pa = np.asarray(pts_a, np.float64).reshape(-1, 2)
    pb = np.asarray(pts_b, np.float64).reshape(-1, 2)
    n = len(pa)
    if n < 4:
        return np.full(n, np.inf)
    k = min(k, n - 1)
    maps = local_affine_maps(pa, pb, k)
    predicted = np.einsum("nj,njk->nk", np.hstack([pa, np.ones((n, 1))]), maps)
    d = np.linalg.norm(pa[:, None, :] - pa[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    near = np.argsort(d, axis=1, kind="stable")[:, :k]
    spread = np.median(np.linalg.norm(pb[near] - pb[:, None, :], axis=2), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.linalg.norm(predicted - pb, axis=1) / spread


def reference_of(full_a: Features, full_b: Features, coarse_a: Features, coarse_b: Features,
                 seed: int = 0) -> Reference:
    """The reference of two photos: the first look (:func:`first_look`), the guided matches
    at full resolution (:func:`guided_matches`), :func:`fit_reference`, then the inliers with
    a local misfit under ``LOCAL_TOLERANCE`` (:func:`local_misfit`) and F refined on them; no
    F when the first look has fewer than ``MIN_FIRST_LOOK_INLIERS`` inliers (no overlap)."""
    f_c, n_c = first_look(coarse_a, coarse_b, seed)
    empty = np.zeros((0, 2), np.int64)
    if f_c is None or n_c < MIN_FIRST_LOOK_INLIERS:
        return Reference(None, empty, n_c)
    band = COARSE_PX * max(coarse_a.zoom, coarse_b.zoom)
    m = guided_matches(full_a, full_b, f_c, band, seed)
    pts_a, pts_b = full_a.xy[m[:, 0]], full_b.xy[m[:, 1]]
    f, inl, n0, rms0 = fit_reference(pts_a, pts_b, seed)
    if f is None:
        return Reference(None, empty, n_c, len(m), n0)
    keep = np.nonzero(inl)[0]
    keep = keep[local_misfit(pts_a[keep], pts_b[keep]) < LOCAL_TOLERANCE]
    if len(keep) < 8:
        return Reference(None, empty, n_c, len(m), n0)
    f = refine_fundamental(f, pts_a[keep], pts_b[keep])
    rms = float(np.sqrt(np.mean(sampson_residuals(f, pts_a[keep], pts_b[keep]) ** 2)))
    return Reference(f, m[keep], n_c, len(m), n0, rms0, rms, int(inl.sum()))


def tracks_of(ab: np.ndarray, ac: np.ndarray, bc: np.ndarray) -> np.ndarray:
    """(N, 3) keypoint indices (A, B, C) of the points seen in three photos: the inlier pairs
    of A-B whose A point is paired in A-C and whose B point in B-C with the same C point.

    >>> tracks_of(np.array([[0, 0], [1, 1], [2, 2]]), np.array([[0, 5], [1, 6], [2, 7]]),
    ...           np.array([[0, 5], [1, 9]])).tolist()
    [[0, 0, 5]]
    """
    a_to_c = dict(map(tuple, np.asarray(ac, np.int64).reshape(-1, 2).tolist()))
    b_to_c = dict(map(tuple, np.asarray(bc, np.int64).reshape(-1, 2).tolist()))
    out = [(a, b, a_to_c[a]) for a, b in np.asarray(ab, np.int64).reshape(-1, 2).tolist()
           if a in a_to_c and b_to_c.get(b, -1) == a_to_c[a]]
    return np.array(out, np.int64).reshape(-1, 3)


def _oriented(refs: Dict[Tuple[str, str], Reference], x: str, y: str
              ) -> Tuple[np.ndarray, np.ndarray]:
    """(F with x_y^T F x_x = 0, (K, 2) inlier indices (x, y)) from the reference of {x, y}."""
    if (x, y) in refs:
        r = refs[(x, y)]
        return r.f, r.pairs
    r = refs[(y, x)]
    return r.f.T, r.pairs[:, ::-1]


def build_references(folder: PathLike, pairs: Sequence[Tuple[str, str]],
                     cache: Optional[PathLike] = None, seed: int = 0, log=lambda s: None
                     ) -> Dict[str, Any]:
    """The references of ``pairs`` (file names in ``folder``), as the JSON document stored in
    ``REFERENCE_JSON``: per pair its figures, F, inlier sample and three-view tracks; a pair
    with fewer than ``MIN_REFERENCE_INLIERS`` inliers is kept with its figures only."""
    folder = Path(folder)
    names = sorted({n for p in pairs for n in p})
    feats: Dict[str, Features] = {}
    coarse: Dict[str, Features] = {}
    for n in names:
        t0 = time.perf_counter()
        feats[n], coarse[n] = detect(folder / n, cache)
        log(f"{n}: {len(feats[n].xy)} SIFT keypoints, {len(coarse[n].xy)} shrunk by "
            f"{coarse[n].zoom:.2f}, {time.perf_counter() - t0:.1f} s")
    refs: Dict[Tuple[str, str], Reference] = {}
    for a, b in pairs:
        t0 = time.perf_counter()
        refs[(a, b)] = reference_of(feats[a], feats[b], coarse[a], coarse[b], seed)
        r = refs[(a, b)]
        log(f"{pair_label(a, b)}: first look {r.coarse_inliers} inliers, {r.matches} guided "
            f"matches, MAGSAC++ {r.magsac_inliers}, refined {r.refined_inliers}, "
            f"{r.inliers} moving with their neighbours, RMS {r.rms_magsac_px:.3f} -> {r.rms_px:.3f} px, "
            f"{time.perf_counter() - t0:.1f} s")
    overlapping = [p for p in pairs if refs[p].inliers >= MIN_REFERENCE_INLIERS]
    out = []
    for a, b in pairs:
        r = refs[(a, b)]
        fa, fb = feats[a], feats[b]
        entry: Dict[str, Any] = {
            "label": pair_label(a, b), "a": a, "b": b, "size_a": list(fa.size),
            "size_b": list(fb.size), "keypoints": [len(fa.xy), len(fb.xy)],
            "coarse_inliers": r.coarse_inliers, "matches": r.matches,
            "magsac_inliers": r.magsac_inliers, "refined_inliers": r.refined_inliers,
            "inliers": r.inliers,
            "rms_magsac_px": _round(r.rms_magsac_px, 4), "rms_px": _round(r.rms_px, 4),
            "overlap": (a, b) in overlapping}
        if entry["overlap"]:
            pa, pb = fa.xy[r.pairs[:, 0]].astype(np.float64), fb.xy[r.pairs[:, 1]].astype(np.float64)
            keep = spread_sample(pa, sampson_residuals(r.f, pa, pb), fa.size)
            entry["f"] = [[float(f"{v:.9e}") for v in row] for row in r.f]
            entry["sample"] = np.round(np.hstack([pa[keep], pb[keep]]), 2).tolist()
            entry["tracks"] = {}
            for c in third_views((a, b), overlapping):
                _, ac = _oriented(refs, a, c)
                _, bc = _oriented(refs, b, c)
                t = tracks_of(r.pairs, ac, bc)
                if len(t) == 0:
                    continue
                xy = np.hstack([fa.xy[t[:, 0]], fb.xy[t[:, 1]], feats[c].xy[t[:, 2]]])
                xy = xy.astype(np.float64)
                keep = spread_sample(xy[:, :2], sampson_residuals(r.f, xy[:, :2], xy[:, 2:4]),
                                     fa.size, TRACK_GRID)
                entry["tracks"][c] = np.round(xy[keep], 2).tolist()
        out.append(entry)
    return {"pairs": out}


def _round(v: float, digits: int) -> Optional[float]:
    return round(float(v), digits) if math.isfinite(v) else None


# --------------------------------------------------------------------------------------------
# The check by eye: the sample and a few epipolar lines, side by side
# --------------------------------------------------------------------------------------------

#: The picture of a reference: the height of each photo in the overview, px; how many sample
#: points get their epipolar lines drawn there; the half side of the full-resolution crops
#: around every sample point, px, their enlargement, and the crop pairs in a row
DRAW_HEIGHT = 560
DRAW_LINES = 8
DRAW_CROP = 80
DRAW_CROP_ZOOM = 1
DRAW_CROPS_PER_ROW = 6


def _colour(k: int) -> Tuple[int, int, int]:
    hsv = np.uint8([[[(k * 37) % 180, 255, 255]]])
    return tuple(int(v) for v in cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0])


def _crop(image: np.ndarray, to_image: np.ndarray, line: Optional[np.ndarray],
          colour: Tuple[int, int, int], label: str) -> np.ndarray:
    """A crop of side ``DRAW_CROP_ZOOM`` (2 ``DRAW_CROP`` + 1) px whose pixel p shows the
    photo's pixel ``to_image @ [p, 1]`` (a 2x3 map), its centre circled and ``line`` (a, b, c
    in the photo's pixels) drawn across it."""
    side = DRAW_CROP_ZOOM * (2 * DRAW_CROP + 1)
    patch = cv2.warpAffine(image, np.asarray(to_image, np.float64), (side, side),
                           flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                           borderMode=cv2.BORDER_CONSTANT)
    if line is not None:  # l^T (M p) = (M^T l)^T p
        m3 = np.vstack([np.asarray(to_image, np.float64), [0.0, 0.0, 1.0]])
        ends = line_ends(m3.T @ np.asarray(line, np.float64), (side, side))
        if ends is not None:
            cv2.line(patch, ends[0], ends[1], colour, 1, cv2.LINE_AA)
    centre = (side // 2, side // 2)
    cv2.circle(patch, centre, 2 * DRAW_CROP_ZOOM + 2, colour, 1, cv2.LINE_AA)
    cv2.putText(patch, label, (3, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1,
                cv2.LINE_AA)
    return patch


def local_similarities(pts_a: np.ndarray, pts_b: np.ndarray, k: int = NEIGHBOURS) -> np.ndarray:
    """(N,) complex: per pair, the scale and turn (``s exp(i theta)``) A -> B of the least-
    squares similarity between x_A's ``k`` nearest points in A (itself included) and their
    partners in B; 1 with fewer than 2 points.

    >>> a = np.array([[0.0, 0], [1, 0], [0, 1], [1, 1]])
    >>> b = np.stack([-2 * a[:, 1], 2 * a[:, 0]], axis=1)  # turned by 90 degrees, zoom of 2
    >>> sim = local_similarities(a, b, k=3)
    >>> np.abs(sim).round(6).tolist(), np.degrees(np.angle(sim)).round(6).tolist()
    ([2.0, 2.0, 2.0, 2.0], [90.0, 90.0, 90.0, 90.0])
    """
    za = np.asarray(pts_a, np.float64).reshape(-1, 2) @ [1.0, 1j]
    zb = np.asarray(pts_b, np.float64).reshape(-1, 2) @ [1.0, 1j]
    n = len(za)
    if n < 2:
        return np.ones(n, complex)
    near = np.argsort(np.abs(za[:, None] - za[None, :]), axis=1, kind="stable")[:, :min(k, n)]
    da = za[near] - za[near].mean(axis=1, keepdims=True)
    db = zb[near] - zb[near].mean(axis=1, keepdims=True)
    return np.sum(np.conj(da) * db, axis=1) / np.sum(np.abs(da) ** 2, axis=1)


def crop_maps(sample: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(N, 2, 3) and (N, 2, 3): per sample point (x_A, y_A, x_B, y_B) the maps from a crop's
    pixels to A's (the square of half side ``DRAW_CROP`` around x_A, enlarged
    ``DRAW_CROP_ZOOM`` times) and to B's (the same square scaled and turned by the
    similarity of the whole sample, :func:`local_similarities`, around x_B), so that both crops
    show the same detail at about the same size (a point's own neighbours in the sample can be
    few and in a line)."""
    pts = np.asarray(sample, np.float64).reshape(-1, 4)
    n = len(pts)
    z, c = DRAW_CROP_ZOOM, DRAW_CROP_ZOOM * (2 * DRAW_CROP + 1) / 2.0 - 0.5
    to_a = np.zeros((n, 2, 3))
    to_a[:, 0, 0] = to_a[:, 1, 1] = 1.0 / z
    to_a[:, :, 2] = pts[:, :2] - c / z  # the crop's centre pixel on x_A
    sim = local_similarities(pts[:, :2], pts[:, 2:], k=n)  # one similarity for the sample
    linear = np.stack([np.stack([sim.real, -sim.imag], 1), np.stack([sim.imag, sim.real], 1)], 1)
    to_b = np.zeros((n, 2, 3))
    to_b[:, :, :2] = linear @ to_a[:, :, :2]
    to_b[:, :, 2] = pts[:, 2:] - (to_b[:, :, :2] @ np.full(2, c))
    return to_a, to_b


def draw_reference(img_a: np.ndarray, img_b: np.ndarray, f: np.ndarray, sample: np.ndarray,
                   title: str = "") -> np.ndarray:
    """A BGR picture to check a reference by eye. Top: A and B side by side with every sample
    point, and for ``DRAW_LINES`` of them (one colour each) the epipolar line in the other
    photo, which must pass through the same detail. Below: every sample point as a pair of
    crops, A's then B's with the line of A's point across it, numbered in sample order ("k A",
    "k B"), B's brought to A's scale and turn by the neighbours' similarity
    (:func:`crop_maps`): the two crops of a pair must show the same detail.

    Parameters
    ----------
    img_a, img_b : (H, W, 3) uint8 arrays
        The photos at full resolution.
    f : (3, 3) array
        ``x_B^T F x_A = 0``.
    sample : (N, 4) array
        x_A, y_A, x_B, y_B, px.
    """
    f = np.asarray(f, np.float64)
    pts = np.asarray(sample, np.float64).reshape(-1, 4)
    scales = [DRAW_HEIGHT / im.shape[0] for im in (img_a, img_b)]
    small = [cv2.resize(im, (int(round(im.shape[1] * s)), DRAW_HEIGHT),
                        interpolation=cv2.INTER_AREA) for im, s in zip((img_a, img_b), scales)]
    lined = set(np.linspace(0, len(pts) - 1, min(DRAW_LINES, len(pts))).astype(int).tolist())
    for k, (x_a, y_a, x_b, y_b) in enumerate(pts):
        col = _colour(k)
        for im, s, pt, line in ((small[1], scales[1], (x_b, y_b), f @ [x_a, y_a, 1.0]),
                                (small[0], scales[0], (x_a, y_a), f.T @ [x_b, y_b, 1.0])):
            if k in lined:
                ends = line_ends(np.array([line[0], line[1], line[2] * s]),
                                 (im.shape[1], im.shape[0]))
                if ends is not None:
                    cv2.line(im, ends[0], ends[1], col, 1, cv2.LINE_AA)
            c = (int(round(pt[0] * s)), int(round(pt[1] * s)))
            cv2.circle(im, c, 5, col, 2, cv2.LINE_AA)
            cv2.putText(im, str(k), (c[0] + 6, c[1] - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.4, col, 1,
                        cv2.LINE_AA)
    top = np.hstack(small)
    crops = []
    to_a, to_b = crop_maps(pts)
    for k, (x_a, y_a, x_b, y_b) in enumerate(pts):
        crops.append(np.hstack([
            _crop(img_a, to_a[k], None, _colour(k), f"{k} A"),
            _crop(img_b, to_b[k], f @ [x_a, y_a, 1.0], _colour(k), f"{k} B"),
            np.zeros((DRAW_CROP_ZOOM * (2 * DRAW_CROP + 1), 6, 3), np.uint8)]))
    rows = [np.hstack(crops[i:i + DRAW_CROPS_PER_ROW]) for i in
            range(0, len(crops), DRAW_CROPS_PER_ROW)]
    width = max([top.shape[1]] + [r.shape[1] for r in rows])
    pad = lambda im: cv2.copyMakeBorder(im, 0, 2, 0, width - im.shape[1], cv2.BORDER_CONSTANT)
    head = np.zeros((30, width, 3), np.uint8)
    cv2.putText(head, title, (8, 21), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 1,
                cv2.LINE_AA)
    return np.vstack([head, pad(top)] + [pad(r) for r in rows])


# --------------------------------------------------------------------------------------------
# The reference command
# --------------------------------------------------------------------------------------------

def _meta(command: str, seed: int) -> Dict[str, Any]:
    import datetime as _dt

    from .bench import _git_commit, machine

    return {"command": command, "date": _dt.datetime.now().strftime("%Y-%m-%d %H:%M"),
            "commit": _git_commit(), "machine": machine(),
            "load": " ".join(f"{v:.1f}" for v in os.getloadavg()), "opencv": cv2.__version__,
            "numpy": np.__version__, "seed": seed}


def _command_line(name: str) -> str:
    import sys

    return (f"scalematch lab {name} " + " ".join(sys.argv[3:])).strip()


def compact_json(doc: Any) -> str:
    """``doc`` as indented JSON with each list of numbers on one line (a point, a row of F).

    >>> print(compact_json({"f": [[1, 2], [3, 4.5]], "name": "a"}), end="")
    {
     "f": [
      [1, 2],
      [3, 4.5]
     ],
     "name": "a"
    }
    """
    import re

    text = json.dumps(doc, indent=1)
    numbers = re.compile(r"\[\s*(-?[\d.eE+-]+(?:,\s*-?[\d.eE+-]+)*)\s*\]")
    return numbers.sub(lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]",
                       text) + "\n"


def read_references(path: PathLike = REFERENCE_JSON) -> Dict[str, Any]:
    """The reference JSON (``REFERENCE_JSON``); ``ValueError`` when it is absent."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no reference JSON; make it with `scalematch lab 3d-reference`")
    return json.loads(path.read_text())


def accepted(entry: Dict[str, Any]) -> bool:
    """Whether a reference entry is a benchmark pair: overlapping and not dropped by eye."""
    return bool(entry.get("overlap")) and entry["label"] not in BY_EYE_DROPPED


def sample_of(entry: Dict[str, Any]) -> np.ndarray:
    """(N, 4) the sample of a reference entry without the points dropped by eye
    (``BY_EYE_DROPPED_POINTS``)."""
    pts = np.array(entry.get("sample", []), np.float64).reshape(-1, 4)
    dropped = BY_EYE_DROPPED_POINTS.get(entry["label"], ((), ""))[0]
    keep = np.ones(len(pts), bool)
    for xy in dropped:
        keep &= np.linalg.norm(pts[:, :2] - np.asarray(xy, np.float64), axis=1) > BY_EYE_POINT_PX
    return pts[keep]


def by_eye(entry: Dict[str, Any]) -> str:
    """What the check by eye said of a reference entry: "accepted", "accepted, N points
    dropped: why", "dropped: why", or "-" for a pair that does not overlap."""
    if not entry.get("overlap"):
        return "-"
    if entry["label"] in BY_EYE_DROPPED:
        return f"dropped: {BY_EYE_DROPPED[entry['label']]}"
    points, why = BY_EYE_DROPPED_POINTS.get(entry["label"], ((), ""))
    if not points:
        return "accepted"
    return f"accepted, {len(points)} point{'s' if len(points) > 1 else ''} dropped: {why}"


def _read_colour(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)  # EXIF orientation applied, as read_grey
    if img is None:
        raise click.ClickException(f"{path}: not readable")
    return img


@click.command("3d-reference", context_settings={"help_option_names": ["-h", "--help"]})
@shared_option
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              default=REFERENCE_JSON, show_default="scalematch/lab/threed_reference.json",
              help="Where the references go.")
@click.option("--out-dir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("bench-out/threed-reference"), show_default=True,
              help="The keypoints' cache (features/) and the pictures (draw/).")
@click.option("--draw", is_flag=True, help="Also draw each overlapping pair's reference.")
@click.option("--draw-only", is_flag=True,
              help="Draw the references of --json without fitting them again.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seeds MAGSAC++ (OpenCV).")
@click.option("--silent", is_flag=True, help="No progress lines on stderr.")
def reference_command(shared, json_path, out_dir, draw, draw_only, seed, silent):
    """Fit the reference F of every two photos of one multi-view scene of
    ../shared/data/photos (full resolution, every SIFT point, MAGSAC++ at 0.5 px, then
    Levenberg-Marquardt on the Sampson error), and store them for `lab 3d-pairs`.

    \b
    Example:
      scalematch lab 3d-reference --draw
      scalematch lab 3d-reference --draw-only --out-dir /tmp/ref
    """
    folder = require_shared(shared, PHOTOS_SUBDIR) / PHOTOS_SUBDIR
    log = (lambda s: None) if silent else (lambda s: click.echo(s, err=True))
    if draw_only:
        doc = read_references(json_path)
    else:
        pairs = candidate_pairs([p.name for p in list_photos(folder.parent.parent)])
        doc = {"meta": {**_meta(_command_line("3d-reference"), seed),
                        "settings": reference_settings()},
               **build_references(folder, pairs, out_dir / "features", seed, log)}
        json_path.parent.mkdir(parents=True, exist_ok=True)
        json_path.write_text(compact_json(doc))
        log(f"wrote {json_path}")
    if draw or draw_only:
        (out_dir / "draw").mkdir(parents=True, exist_ok=True)
        for e in doc["pairs"]:
            if not e["overlap"]:
                continue
            pic = draw_reference(_read_colour(folder / e["a"]), _read_colour(folder / e["b"]),
                                 np.array(e["f"]), np.array(e["sample"]),
                                 f"{e['label']}: {e['inliers']} inliers, RMS {e['rms_px']} px")
            target = out_dir / "draw" / (e["label"].replace(" ", "_").replace("~", "--") + ".png")
            cv2.imwrite(str(target), pic)
            log(f"drew {target}")


def reference_settings() -> Dict[str, Any]:
    """The reference's settings, as recorded with it."""
    return {"detector": "OpenCV SIFT, default settings, no cap, full resolution",
            "first_look": f"SIFT at {COARSE_SIDE} px, ratio test {COARSE_RATIO}, MAGSAC++ at "
                          f"{COARSE_PX:g} px of the shrunk photos",
            "matcher": f"guided mutual matching in the first look's band ({COARSE_PX:g} px "
                       f"times the shrink factor), {GUIDED_K} nearest descriptors by FLANN "
                       f"({FLANN_TREES} kd-trees, {FLANN_CHECKS} checks)",
            "magsac_px": REFERENCE_PX,
            "magsac_confidence": MAGSAC_CONFIDENCE, "magsac_iterations": REFERENCE_ITERATIONS,
            "refinement": "Levenberg-Marquardt on the Sampson error, rank 2 (Bartoli-Sturm)",
            "rounds": REFERENCE_ROUNDS, "min_first_look_inliers": MIN_FIRST_LOOK_INLIERS,
            "min_inliers": MIN_REFERENCE_INLIERS,
            "sample_grid": list(SAMPLE_GRID), "track_grid": list(TRACK_GRID)}


# --------------------------------------------------------------------------------------------
# The benchmark pairs: the references in the pixels of the images as given
# --------------------------------------------------------------------------------------------

#: The scenes a decision may be tuned on; the others are held out, to be measured once a rule
#: is set (EVALUATION.md, "Real pairs": "say which pairs a rule was tuned on"). Each half holds
#: drone photos and photos from the ground
TUNING_SCENES = ("brighton", "monstree", "sceaux")


@dataclass(frozen=True)
class ThirdView:
    """A third photo C of a pair's scene, in the pixels of the images as given."""

    name: str  #: C's file name
    f_ac: np.ndarray = field(repr=False)  #: x_C^T F_AC x_A = 0 (reference)
    f_bc: np.ndarray = field(repr=False)  #: x_C^T F_BC x_B = 0 (reference)
    tracks: np.ndarray = field(repr=False)  #: (N, 6) x_A, y_A, x_B, y_B, x_C, y_C


@dataclass(frozen=True)
class ThreedPair:
    """One benchmark pair: photos A and B given as ``kind`` says, and its reference in the
    pixels of the images as given."""

    label: str  #: :func:`pair_label`
    a: str  #: A's file name
    b: str  #: B's file name
    kind: str  #: how the photos are given (``KINDS``, :func:`parse_kind`)
    f: np.ndarray = field(repr=False)  #: the reference, x_B^T F x_A = 0
    points: np.ndarray = field(repr=False)  #: (N, 4) the reference's sample
    thirds: Tuple[ThirdView, ...] = ()

    @property
    def scene(self) -> str:
        return scene_of(self.a)

    @property
    def name(self) -> str:
        return f"{self.label} {self.kind}"


def _entry_f(entries: Dict[frozenset, Dict[str, Any]], x: str, y: str) -> np.ndarray:
    """The reference F with ``x_y^T F x_x = 0`` from the entry of {x, y}."""
    e = entries[frozenset((x, y))]
    f = np.array(e["f"], np.float64)
    return f if e["a"] == x else f.T


def benchmark_pairs(doc: Dict[str, Any], kinds: Sequence[str] = KINDS,
                    labels: Optional[Sequence[str]] = None) -> List[ThreedPair]:
    """The benchmark pairs of a reference document: every accepted entry (:func:`accepted`)
    in every kind, in label order then kind order; only ``labels`` when given. A third view
    counts when both its references are accepted."""
    entries = {frozenset((e["a"], e["b"])): e for e in doc["pairs"] if accepted(e)}
    out = []
    for e in sorted(entries.values(), key=lambda e: e["label"]):
        if labels is not None and e["label"] not in labels:
            continue
        for kind in kinds:
            z_a, z_b = parse_kind(kind)
            s_a = shrink_map((int(e["size_a"][0]), int(e["size_a"][1])), z_a)
            s_b = shrink_map((int(e["size_b"][0]), int(e["size_b"][1])), z_b)
            thirds = tuple(
                ThirdView(c, f_given(_entry_f(entries, e["a"], c), s_a, np.eye(3)),
                          f_given(_entry_f(entries, e["b"], c), s_b, np.eye(3)),
                          points_given(np.array(t, np.float64), s_a, s_b))
                for c, t in sorted(e.get("tracks", {}).items())
                if frozenset((e["a"], c)) in entries and frozenset((e["b"], c)) in entries)
            out.append(ThreedPair(e["label"], e["a"], e["b"], kind,
                                  f_given(np.array(e["f"], np.float64), s_a, s_b),
                                  points_given(sample_of(e), s_a, s_b),
                                  thirds))
    return out


def transfer_px(f: Optional[np.ndarray], thirds: Sequence[ThirdView]) -> float:
    """The median distance, px, of the epipolar transfer of an answer F (x_B^T F x_A = 0)
    through every third view (:func:`transfer_errors`); NaN with no F or fewer than
    ``MIN_TRACKS`` crossings kept."""
    if f is None or not thirds:
        return math.nan
    d = np.concatenate([transfer_errors(f, t.f_ac, t.f_bc, t.tracks) for t in thirds])
    return float(np.median(d)) if len(d) >= MIN_TRACKS else math.nan


# --------------------------------------------------------------------------------------------
# Runs, rows, summary
# --------------------------------------------------------------------------------------------

def load_images(folder: PathLike, pair: ThreedPair) -> EfPair:
    """The pair's images as given, grey (each photo shrunk as ``pair.kind`` says), with the
    reference's sample as its points (efpairs' runners take an ``EfPair``)."""
    from ..imageio import read_grey

    z_a, z_b = parse_kind(pair.kind)
    a = shrink(read_grey(Path(folder) / pair.a), z_a)
    b = shrink(read_grey(Path(folder) / pair.b), z_b)
    return EfPair(pair.name, a, b, pair.points)


def row_of(pair: ThreedPair, order: str, run: Run) -> Dict[str, Any]:
    """One JSON row: the run's figures and its scores (``orders_px`` is filled in once both
    orders have run, :func:`fill_orders`)."""
    err = symmetric_epipolar_error(run.f, pair.points)
    row = {k: v for k, v in asdict(run).items() if k != "f"}
    return {"pair": pair.label, "scene": pair.scene, "kind": pair.kind, "order": order,
            "set": "tuning" if pair.scene in TUNING_SCENES else "held-out", **row,
            "error_px": err, "solved": bool(err < SOLVED_PX),
            "wrong": bool(run.claimed and err > WRONG_PX),
            "transfer_px": transfer_px(run.f, pair.thirds), "orders_px": math.nan,
            "f": None if run.f is None else (run.f / np.linalg.norm(run.f)).tolist()}


def fill_orders(rows: List[Dict[str, Any]], pair: ThreedPair) -> None:
    """Set ``orders_px`` of ``pair``'s rows: per method, the distance (:func:`f_distance`)
    between the answers of its two orders, over the reference's sample."""
    mine = [r for r in rows if r["pair"] == pair.label and r["kind"] == pair.kind]
    for m in {r["method"] for r in mine}:
        two = [r for r in mine if r["method"] == m]
        if len(two) != 2:
            continue
        fs = [None if r["f"] is None else np.array(r["f"]) for r in two]
        d = f_distance(fs[0], fs[1], pair.points)
        for r in two:
            r["orders_px"] = d


def _median(values: Sequence[float]) -> float:
    v = [x for x in values if x is not None and math.isfinite(x)]
    return float(np.median(v)) if v else math.nan


def summarise(rows: Sequence[Dict[str, Any]], group: str = "all") -> List[Dict[str, Any]]:
    """Per method, over the rows: runs, claimed, solved (< ``SOLVED_PX``), the median error
    of the solved, wrong Fs claimed (> ``WRONG_PX``), runs that SIFT + MAGSAC++ solves and
    the method does not (the same pair, kind and order), the medians of ``transfer_px`` and
    ``orders_px`` of the claims, the median time. ``group`` names the rows in the output."""
    solved_by = {(r["pair"], r["kind"], r["order"]): r["solved"] for r in rows
                 if r["method"] == "sift-magsac"}
    out = []
    for m in (*METHODS, *sorted({r["method"] for r in rows} - set(METHODS))):
        rs = [r for r in rows if r["method"] == m]
        if not rs:
            continue
        ok = [r["error_px"] for r in rs if r["solved"]]
        lost = sum(1 for r in rs if solved_by.get((r["pair"], r["kind"], r["order"]))
                   and not r["solved"])
        claims = [r for r in rs if r["claimed"]]
        out.append({"group": group, "method": m, "runs": len(rs), "claimed": len(claims),
                    "solved": len(ok), "median_error_px": _median(ok),
                    "wrong": sum(r["wrong"] for r in rs),
                    "lost_to_sift": lost if m != "sift-magsac" else 0,
                    "median_transfer_px": _median([r.get("transfer_px") for r in claims]),
                    "median_orders_px": _median([r.get("orders_px") for r in claims]),
                    "median_s": _median([r["seconds"] for r in rs])})
    return out


def ef_rows(folder: PathLike, methods: Sequence[str], seed: int = 0, log=lambda s: None
            ) -> List[Dict[str, Any]]:
    """The 8 ef pairs (``efpairs``), both orders, as rows of this benchmark: scored on their
    clicked points, ``orders_px`` on them too, no third view."""
    from . import efpairs

    rows = []
    for name in efpairs.pair_names(folder):
        pair = efpairs.load_pair(folder, name)

        def row(order: str, run: Run) -> Dict[str, Any]:
            return {**efpairs.row_of(pair, order, run), "pair": f"ef {name}", "scene": "ef",
                    "kind": "photos", "set": "ef", "transfer_px": math.nan,
                    "orders_px": math.nan}

        mine = efpairs.run_orders(pair, methods, row, seed, log)
        for m in methods:
            two = [r for r in mine if r["method"] == m]
            fs = [None if r["f"] is None else np.array(r["f"]) for r in two]
            for r in two:
                r["orders_px"] = f_distance(fs[0], fs[1], pair.points)
        rows += mine
    return rows


# --------------------------------------------------------------------------------------------
# Markdown
# --------------------------------------------------------------------------------------------

def _err(v: Optional[float]) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.2f}"


#: The groups of the summary: name -> which rows
GROUPS = (
    ("3-D pairs, B shrunk", lambda r: r["set"] != "ef" and r["kind"].startswith("B/")),
    ("3-D pairs, A shrunk", lambda r: r["set"] != "ef" and r["kind"].startswith("A/")),
    ("3-D pairs, both photos as they are", lambda r: r["set"] != "ef" and r["kind"] == "photos"),
    ("3-D pairs, all", lambda r: r["set"] != "ef"),
    ("3-D pairs, tuning scenes", lambda r: r["set"] == "tuning"),
    ("3-D pairs, held-out scenes", lambda r: r["set"] == "held-out"),
    ("ef pairs (clicked points)", lambda r: r["set"] == "ef"),
)


def markdown(rows: Sequence[Dict[str, Any]], meta: Dict[str, Any]) -> str:
    """The results section: the run, the summary by group and one line per pair, kind, order."""
    lines = [
        "## Fundamental matrix on real 3-D pairs of the multi-view photos", "",
        "Score: the mean symmetric epipolar distance of the reference's sample of inliers, px of "
        f"the images as given (solved: < {SOLVED_PX:g} px; a wrong F claimed: > "
        f"{WRONG_PX:g} px); the ef pairs are scored on their clicked points. *lost to SIFT*: "
        "runs SIFT + MAGSAC++ solves and the method does not. *transfer*: the median distance "
        "of the epipolar transfer through a third view of the scene; *orders*: the distance "
        "between the answers of the two orders; both px, medians over the claims. scalematch: "
        "`Config(model=\"fundamental\")`; SIFT: ratio test 0.8 + `cv2.findFundamentalMat("
        f"pts_A, pts_B, cv2.USAC_MAGSAC, 1, {MAGSAC_CONFIDENCE:g}, {MAGSAC_ITERATIONS})` "
        "(efpairs). Kind: which photo is shrunk and by how much (*B/4*: B shrunk by 4, A "
        "as it is). Order A,B: A "
        "given first.", "",
        f"- `{meta.get('command', '?')}`: {meta.get('date', '?')}, commit "
        f"{meta.get('commit', '?')}, {meta.get('machine', '?')}, load average at start "
        f"{meta.get('load', '?')}, seed {meta.get('seed', '?')}, OpenCV {meta.get('opencv', '?')}",
        f"- references: `{meta.get('reference_command', '?')}` ({meta.get('reference_date', '?')}, "
        f"commit {meta.get('reference_commit', '?')})", "",
        "| pairs | method | runs | claimed | solved | median error px of solved | wrong F claimed "
        "| lost to SIFT | median transfer px | median orders px | median s |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, keep in GROUPS:
        for s in summarise([r for r in rows if keep(r)], name):
            lost = "-" if s["method"] == "sift-magsac" else str(s["lost_to_sift"])
            lines.append(f"| {name} | {s['method']} | {s['runs']} | {s['claimed']} | "
                         f"{s['solved']} | {_err(s['median_error_px'])} | {s['wrong']} | {lost} | "
                         f"{_err(s['median_transfer_px'])} | {_err(s['median_orders_px'])} | "
                         f"{s['median_s']:.1f} |")
    lines += ["", "| pair | set | kind | order | scalematch F error px | inliers | transfer px | "
              "orders px | s | SIFT+MAGSAC error px | inliers | transfer px | orders px | s |",
              "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    by = {(r["pair"], r["kind"], r["order"], r["method"]): r for r in rows}
    keys = sorted({(r["set"] == "ef", r["pair"], r["kind"], r["order"]) for r in rows},
                  key=lambda k: (k[0], k[1].lower(), k[2], ORDERS.index(k[3])))
    for _, p, z, o in keys:
        cells = [p, by.get((p, z, o, next(iter(METHODS))), {}).get("set", "")
                 or next(r["set"] for r in rows if r["pair"] == p), z, o]
        for m in METHODS:
            r = by.get((p, z, o, m))
            if r is None:
                cells += [""] * 5
                continue
            cells += [_err(r["error_px"]) if r["claimed"] else "no F", str(r["inliers"]),
                      _err(r.get("transfer_px")), _err(r.get("orders_px")),
                      f"{r['seconds']:.1f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def markdown_references(doc: Dict[str, Any]) -> str:
    """The references section: how they were made and, per candidate pair, its figures, whether
    it overlaps, the check by eye, and the reference's own transfer through third views."""
    meta = doc.get("meta", {})
    st = meta.get("settings", {})
    lines = [
        "## The references", "",
        f"`{meta.get('command', '?')}`: {meta.get('date', '?')}, commit {meta.get('commit', '?')}, "
        f"{meta.get('machine', '?')}, OpenCV {meta.get('opencv', '?')}, seed {meta.get('seed', '?')}. "
        f"First look: {st.get('first_look', '?')}. Then {st.get('detector', '?')}; "
        f"{st.get('matcher', '?')}, one to one; MAGSAC++ at {st.get('magsac_px', '?')} px "
        f"({st.get('magsac_iterations', '?')} iterations); {st.get('refinement', '?')}, inliers "
        f"chosen again at {st.get('magsac_px', '?')} px of Sampson distance. A pair overlaps with "
        f"at least {st.get('min_first_look_inliers', '?')} inliers in the first look and "
        f"{st.get('min_inliers', '?')} in the reference. *RMS*: the Sampson RMS of the final "
        "inliers under MAGSAC++'s F, then under the refined one. *sample*: the inliers kept to "
        "score answers (one per cell of a grid over A); *tracks*: points seen in a third view. "
        "*transfer*: the reference's own median epipolar transfer through its third views.", "",
        "| pair | first look inliers | guided matches | MAGSAC++ inliers | inliers | RMS px | "
        "overlap | by eye | sample | tracks | transfer px |",
        "|---|---:|---:|---:|---:|---|---|---|---:|---:|---:|"]
    for e in sorted(doc["pairs"], key=lambda e: e["label"]):
        tracks, transfer = "-", "-"
        if accepted(e):
            pair = benchmark_pairs(doc, ("photos",), [e["label"]])[0]
            tracks = str(sum(len(t.tracks) for t in pair.thirds))
            transfer = _err(transfer_px(pair.f, pair.thirds))
        lines.append(
            f"| {e['label']} | {e.get('coarse_inliers', '-')} | {e['matches']} | "
            f"{e['magsac_inliers']} | {e['inliers']} | "
            f"{_err(e['rms_magsac_px'])} -> {_err(e['rms_px'])} | "
            f"{'yes' if e['overlap'] else 'no'} | {by_eye(e)} | "
            f"{len(sample_of(e)) or '-'} | {tracks} | {transfer} |")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------
# The benchmark command
# --------------------------------------------------------------------------------------------

def _listed(text: str, known: Sequence[str], what: str, hint: str) -> List[str]:
    """The comma-separated names of an option, each checked against ``known``
    (``click.BadParameter`` naming the option ``hint`` otherwise)."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    for n in names:
        if n not in known:
            raise click.BadParameter(f"unknown {what} {n!r}; one of {', '.join(known)}",
                                     param_hint=hint)
    return names


@click.command("3d-pairs", context_settings={"help_option_names": ["-h", "--help"]})
@shared_option
@click.option("--reference", "reference_path", type=click.Path(dir_okay=False, path_type=Path),
              default=REFERENCE_JSON, show_default="scalematch/lab/threed_reference.json",
              help="The references (made by `scalematch lab 3d-reference`).")
@click.option("--pairs", default="",
              help="Comma-separated pair labels, as the table shows them (default: every pair).")
@click.option("--scenes", default="", help="Comma-separated scenes (default: every scene).")
@click.option("--kinds", default=",".join(KINDS), show_default=True,
              help="How the photos are given: A/<zoom> (A shrunk), B/<zoom> or photos.")
@click.option("--methods", default=",".join(METHODS), show_default=True)
@click.option("--ef/--no-ef", default=True, show_default=True,
              help="Also run the 8 ef pairs (../shared/data/ef), scored on their clicked points.")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seeds scalematch (Config.seed) and OpenCV's RNG (MAGSAC++).")
@click.option("--out-dir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("bench-out/threed"), show_default=True)
@click.option("--write-doc", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write the tables and the references into this Markdown file (its 3d-pairs "
                   "and 3d-references sections).")
@click.option("--silent", is_flag=True, help="No progress lines on stderr.")
def threed_pairs_command(shared, reference_path, pairs, scenes, kinds, methods, ef, seed,
                         out_dir, write_doc, silent):
    """The fundamental matrix on the real 3-D pairs of the multi-view scenes of
    ../shared/data/photos, each photo shrunk by 4 in turn, both orders: scalematch (model
    fundamental) and SIFT + USAC_MAGSAC in the same run, scored against the reference F of
    each pair; with the 8 ef pairs. docs/results/THREED.md.

    \b
    Example:
      scalematch lab 3d-pairs --write-doc docs/results/THREED.md
      scalematch lab 3d-pairs --scenes sceaux --kinds photos --methods scalematch --no-ef
    """
    from .efpairs import EF_SUBDIR
    from .realpairs import write_section

    folder = require_shared(shared, PHOTOS_SUBDIR) / PHOTOS_SUBDIR
    try:
        doc = read_references(reference_path)
    except ValueError as e:
        raise click.ClickException(str(e))
    wanted = _listed(methods, METHODS, "method", "--methods") or list(METHODS)
    chosen_kinds = [k.strip() for k in kinds.split(",") if k.strip()]
    for k in chosen_kinds:
        try:
            parse_kind(k)
        except ValueError as e:
            raise click.BadParameter(str(e), param_hint="--kinds")
    every = benchmark_pairs(doc, chosen_kinds)
    labels = _listed(pairs, sorted({p.label for p in every}), "pair", "--pairs")
    chosen_scenes = _listed(scenes, sorted({p.scene for p in every}), "scene", "--scenes")
    todo = [p for p in every if (not labels or p.label in labels)
            and (not chosen_scenes or p.scene in chosen_scenes)]
    ef_dir = None
    if ef:
        no_ef = f"give --no-ef, or {POINT_WITH_OPTION}"
        ef_dir = require_shared(shared, EF_SUBDIR, no_ef) / EF_SUBDIR
    log = (lambda s: None) if silent else (lambda s: click.echo(s, err=True))
    ref_meta = doc.get("meta", {})
    meta = {**_meta(_command_line("3d-pairs"), seed),
            "reference_command": ref_meta.get("command"), "reference_date": ref_meta.get("date"),
            "reference_commit": ref_meta.get("commit")}
    out_dir.mkdir(parents=True, exist_ok=True)
    rows: List[Dict[str, Any]] = []
    for k, pair in enumerate(todo, start=1):
        log(f"[{k}/{len(todo)}] {pair.name}")
        rows += run_orders(load_images(folder, pair), wanted,
                           lambda order, run: row_of(pair, order, run), seed, log)
        fill_orders(rows, pair)
        (out_dir / "rows.json").write_text(json.dumps(rows, indent=1, default=str))
    if ef_dir is not None:
        rows += ef_rows(ef_dir, wanted, seed, log)
    (out_dir / "rows.json").write_text(json.dumps(rows, indent=1, default=str))
    (out_dir / "meta.json").write_text(json.dumps(meta))
    text = markdown(rows, meta)
    (out_dir / "3d-pairs.md").write_text(text)
    click.echo(text)
    if write_doc is not None:
        write_section(write_doc, markdown_references(doc), "3d-references",
                      "scalematch lab 3d-pairs")
        write_section(write_doc, text, "3d-pairs", "scalematch lab 3d-pairs")
        log(f"wrote {write_doc}")
