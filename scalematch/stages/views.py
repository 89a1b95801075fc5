"""Step 1 (before the scale-space): simulated tilted views of the high image (Morel & Yu 2009, "ASIFT").

A camera that looks at a plane obliquely sees it compressed along one direction: locally, a
change of viewpoint is an affine map, and every affine map with a positive determinant is a
similarity after a compression by a *tilt* t >= 1 along some direction (its *longitude* phi):
``A = lambda R(psi) [R(phi)^T diag(1/t, 1) R(phi)]``. The scale search of the paper absorbs
the similarity; these views absorb the compression. Each view is the high image turned by phi,
blurred along x by ``c sqrt(t^2 - 1)`` (Morel & Yu's anti-aliasing, c = 0.8) and shrunk along x
by t; ``to_view`` (2x3) maps a high-image pixel to its pixel in the view.

Views are tried progressively (Mishkin, Matas & Perdoch 2015, "MODS"): the pipeline first runs
without any, and adds a pass of views only when the previous pass found nothing, so ordinary
pairs cost no more than before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar, List, Mapping, Optional, Sequence, Tuple

import cv2
import numpy as np

from ..checks import AT_LEAST_ONE, Bounds, COUNT, FACTOR, NON_NEGATIVE, POSITIVE, check_bounds, in_range, one_of
from ..geometry import apply, compose, invert, resize_map
from .nodata import away_from, distance_inside


#: The passes of views (docs/design/VIEWS.md, "The passes"): t = 2, then 4, then 6 and 8
#: together (longitude steps 72/t: 5, 10, then 15 + 20 views), as far as MODS's steepest view
#: synthesis (t = 8). Each pass runs only when every earlier one found nothing, so only a "no"
#: pays for all of them
#: (docs/design/VIEWS.md, "The third pass": 2.3x the time of a "no" with t = 2 and 4 only)
PASSES: Tuple[Tuple[float, ...], ...] = ((2.0,), (4.0,), (6.0, 8.0))
#: The passes without the third one (the ``tilt-4`` preset): tilts up to about 6 solved
TILT4_PASSES: Tuple[Tuple[float, ...], ...] = PASSES[:2]
#: ``ViewParams.coarser_directions``: the coarser image's views in one direction of the search
#: (the one whose coarser image is the smaller), or in both
COARSER_DIRECTIONS = ("one", "both")
#: Most views the passes may hold together: each view is a search of its own at every scale, so
#: the time of a "no" grows with their number. Four times the default's 50 (a longitude step
#: of 18 degrees, a quarter of Morel & Yu's 72, stays within it).
MAX_VIEWS = 200


@dataclass(frozen=True)
class ViewParams:
    """Which tilted views to simulate when the plain search finds nothing."""

    enabled: bool = True  #: False: never simulate views (today's 0.1 behaviour)
    #: passes of tilts, each run only when every earlier pass found nothing. Morel & Yu sample
    #: t = sqrt(2)^k; the gradient descriptor tolerates a tilt of about 2 on its own (measured
    #: on tilted zoom pairs, docs/BENCHMARKS.md), so views at t = 2 then 4 (a sampling ratio of
    #: 2) cover tilts up to about 6 with 15 views instead of 27; t = 6 and 8 reach 8 and more
    #: (docs/design/VIEWS.md, "The third pass": 92 % of the pairs at t = 6 and at t = 8,
    #: ratio 2, both orders)
    passes: Tuple[Tuple[float, ...], ...] = PASSES
    #: longitude step at tilt t is ``longitude_step_deg / t`` over [0, 180) (Morel & Yu: 72)
    longitude_step_deg: float = 72.0
    #: anti-aliasing blur along the compressed axis: c * sqrt(t^2 - 1) px (Morel & Yu: c = 0.8)
    antialias_c: float = 0.8
    #: each pass also views the coarser image (after the finer one's views, both directions):
    #: where the finer image is the oblique one (a telephoto seen obliquely against a frontal
    #: wide shot) its directional ratios are r and r / t, and below 1 no scale searched reaches
    #: them; a view of the coarser image compressed by t along that axis does
    #: (docs/design/VIEWS.md, "Views of the coarser image")
    coarser: bool = True
    #: ... in "both" directions of the automatic order, or in "one": the one whose coarser
    #: image is the smaller (shorter longer side; the given one on a tie), cheaper to detect.
    #: Both reach the same pairs in principle (a pair whose finer image maps with singular
    #: values s1 > 1 > s2: the given direction's views of tilt s1 / s2 at scale s1, the other's
    #: at 1 / s2; docs/design/VIEWS.md, "Views of the coarser image"), but not always in
    #: practice: "one" made a "no" 0.84x as long (122 null runs) and solved 74 of the oblique
    #: set's 104 runs, "both" 80
    coarser_directions: str = "both"
    #: views of a pass matched in full: the ones whose probe scores best (the others are only
    #: detected and probed, which costs about half a search)
    full_searches: int = 3
    #: ... and only when that score reaches this: measured on 16 unrelated pairs, no view's
    #: probe score went above 4 in either order, while the views that solved tilted zoom pairs
    #: scored 5 to 80 (a chance similarity fit of the probe's 100 points finds 2-4 inliers)
    min_probe_score: float = 5.0
    #: a match of the plain search with fewer distinct inliers than this is compared with the
    #: first pass of views, and the stronger (lower log10 NFA) answer is taken: a tilted view
    #: of a repeated facade gave a plain similarity of 6 wrong inliers at log10 NFA -12.6 on a
    #: tilted zoom pair (t = 2.83) where the views find the truth (docs/BENCHMARKS.md)
    confirm_below_inliers: int = 12
    #: the probe of a view first detects and scores every N-th scale only (N = 1: each one);
    #: the ``full_searches`` views that score best are then probed at every scale, so the views
    #: matched in full are chosen as with N = 1 wherever those few include the right one.
    #: Detection is most of a view's cost and most views are only probed. N = 2: a "no" 0.86x
    #: as long, the tilted zoom pairs and Oxford solved as before (docs/design/VIEWS.md,
    #: "The passes"); without the completion 3 tilted pairs of 104 were lost (the right view's
    #: probe score fell from 7-12 to 4, under ``min_probe_score``, its best scale not probed)
    probe_every: int = 2
    #: keypoints closer than this to the view's empty corners are dropped, px at s = 1 (x s):
    #: the descriptor window is 16 level px wide, so 8 px keeps it inside the image
    edge_margin_px: float = 8.0
    #: the first look (ASIFT's two resolutions, Morel & Yu 2009, section 4): every view of a
    #: pass is probed on copies of both images shrunk by a factor K, and only the views it
    #: ranks best are probed and matched at full resolution. K makes the coarser image's
    #: shorter side this many px (0: no first look), at most ``first_look_max_factor``; below
    #: ``first_look_min_factor`` the images are searched at full resolution only. The shrunk
    #: probe ranks the views where the coarser image keeps 500 px (on steep pairs the winning
    #: view ranks 1st at K = 1.5 with 512 px, 3rd to 5th at K = 2.56 with 300 px), and it pays
    #: only where K is 2 or more: camera-size photos, whose "no" it makes 1.85x sooner (two
    #: unrelated 12-16 MP photos: 8.6 s against 16.0 s in process) with 84 tilted and oblique
    #: pairs of such photos solved as before; a 1 MP image is searched as without it
    #: (docs/design/SPEED.md, "The first look")
    first_look_short_px: float = 500.0
    first_look_max_factor: float = 3.0
    first_look_min_factor: float = 2.0
    #: views of a step that the first look hands on to the full-resolution probe, at most ...
    first_look_follow: int = 3
    #: ... and only those whose first-look score reaches this (0: the best ones, whatever they
    #: scored)
    first_look_min_score: float = 0.0

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "longitude_step_deg": POSITIVE,
        "antialias_c": NON_NEGATIVE,
        "min_probe_score": NON_NEGATIVE,
        "edge_margin_px": NON_NEGATIVE,
        "full_searches": AT_LEAST_ONE,
        "first_look_short_px": NON_NEGATIVE,
        "first_look_min_score": NON_NEGATIVE,
        "first_look_max_factor": FACTOR,
        "first_look_min_factor": FACTOR,
        "first_look_follow": AT_LEAST_ONE,
        "probe_every": AT_LEAST_ONE,
        "confirm_below_inliers": COUNT,
    }

    def __post_init__(self) -> None:
        check_bounds("views", self, self.BOUNDS)
        for tilts in self.passes:
            for t in tilts:
                in_range("views", "passes", t, FACTOR)
        one_of("views", "coarser_directions", self.coarser_directions, COARSER_DIRECTIONS)
        n = views_in(self.passes, self.longitude_step_deg)
        if n > MAX_VIEWS:
            raise ValueError(f"views: the passes hold {n} views at a longitude step of "
                             f"{self.longitude_step_deg:g} degrees, more than the {MAX_VIEWS} "
                             f"searched at most; take fewer tilts or a larger "
                             f"views.longitude_step_deg")


@dataclass(frozen=True)
class View:
    """A simulated view of the high image."""

    tilt: float  #: t >= 1 (1: the image itself)
    longitude_deg: float  #: phi, degrees, the direction compressed by t
    image: np.ndarray = field(repr=False)  #: (h', w') float32 view
    to_view: np.ndarray = field(repr=False)  #: 2x3, high px -> view px
    #: (h', w') float32 distance (view px) to the nearest pixel outside the high image or on its
    #: no-data region (:mod:`scalematch.stages.nodata`), or None when every pixel of the view
    #: shows the scene
    inside_distance: object = field(default=None, repr=False)
    #: (h, w) of the image viewed (None: unknown), where a map found through the view must hold
    source_shape: Optional[Tuple[int, int]] = None

    @property
    def is_identity(self) -> bool:
        return self.tilt == 1.0


def n_longitudes(tilt: float, step_deg: float) -> int:
    """How many longitudes :func:`longitudes` gives ``tilt``.

    >>> n_longitudes(1.0, 72.0), n_longitudes(2.0, 72.0), n_longitudes(8.0, 72.0)
    (1, 5, 20)
    """
    return 1 if tilt <= 1.0 else int(math.ceil(180.0 / (step_deg / tilt) - 1e-9))


def longitudes(tilt: float, step_deg: float) -> List[float]:
    """Longitudes phi in [0, 180) for ``tilt``: n equal steps of at most ``step_deg / tilt``."""
    n = n_longitudes(tilt, step_deg)
    return [k * 180.0 / n for k in range(n)] if tilt > 1.0 else [0.0]


def views_in(passes: Sequence[Sequence[float]], step_deg: float) -> int:
    """The views that ``passes`` of tilts hold at a longitude step of ``step_deg``, counted
    without making them (the bound ``MAX_VIEWS`` is checked before a long list is built).

    >>> views_in(PASSES, 72.0)
    50
    """
    return sum(n_longitudes(t, step_deg) for tilts in passes for t in tilts if t > 1.0)


def view_plan(params: ViewParams) -> List[List[Tuple[float, float]]]:
    """The passes of (tilt, longitude) pairs, after the plain pass (which is not listed)."""
    if not params.enabled:
        return []
    return [[(t, phi) for t in tilts for phi in longitudes(t, params.longitude_step_deg)]
            for tilts in params.passes]


def identity_view(high: np.ndarray, valid: Optional[np.ndarray] = None) -> View:
    """The image itself as a view; ``valid`` (bool, its shape): where it shows the scene
    (:func:`scalematch.stages.nodata.valid_mask`; None: everywhere)."""
    return View(1.0, 0.0, high, np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
                distance_inside(valid), tuple(high.shape[:2]))


def tilt_view(high: np.ndarray, tilt: float, longitude_deg: float,
              params: ViewParams = ViewParams(), valid: Optional[np.ndarray] = None) -> View:
    """The view of ``high`` (H, W) float32 compressed by ``tilt`` along ``longitude_deg``.

    The image is turned by phi onto a canvas that holds all of it, blurred along x by
    ``antialias_c * sqrt(t^2 - 1)`` px and resized along x by 1/t (``cv2.resize``'s
    centre-aligned convention: x -> (x + 0.5) / t - 0.5). ``valid``: where the image shows the
    scene (None: everywhere); the view's ``inside_distance`` measures to the rest.
    """
    if tilt <= 1.0:
        return identity_view(high, valid)
    h, w = high.shape
    a = math.radians(longitude_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float64) @ rot.T
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    turn = np.hstack([rot, (-lo)[:, None]])
    cw, ch = (int(v) for v in np.ceil(hi - lo) + 1)
    img = cv2.warpAffine(np.asarray(high, np.float32), turn, (cw, ch), flags=cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    shown = np.ones((h, w), np.uint8) if valid is None else valid.astype(np.uint8)
    inside = cv2.warpAffine(shown, turn, (cw, ch), flags=cv2.INTER_NEAREST,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    img = cv2.GaussianBlur(img, (0, 0), sigmaX=params.antialias_c * math.sqrt(tilt * tilt - 1),
                           sigmaY=0.01)
    nw = max(int(round(cw / tilt)), 1)
    img = cv2.resize(img, (nw, ch), interpolation=cv2.INTER_LINEAR)
    inside = cv2.resize(inside, (nw, ch), interpolation=cv2.INTER_NEAREST)
    to_view = compose(resize_map(nw / cw, 1.0), turn)
    dist = cv2.distanceTransform(inside, cv2.DIST_L2, 3)
    return View(float(tilt), float(longitude_deg), img, to_view, dist, (h, w))


def keep_inside(view: View, xy: np.ndarray, margin_px: float) -> np.ndarray:
    """Boolean mask of the points (N, 2) (view px) at least ``margin_px`` from the view's edge."""
    if view.inside_distance is None or len(xy) == 0:
        return np.ones(len(xy), bool)
    return away_from(view.inside_distance, xy, margin_px)


def valid_in(view: View) -> Optional[np.ndarray]:
    """(h', w') bool: where the view shows the scene (None: everywhere)."""
    return None if view.inside_distance is None else view.inside_distance > 0


def to_high(view: View, xy: np.ndarray) -> np.ndarray:
    """View px (N, 2) -> high-image px (N, 2)."""
    return apply(invert(view.to_view), xy)
