"""Step 1 (before the scale-space): simulated tilted views of the images (Morel & Yu 2009, "ASIFT").

A camera that looks at a plane obliquely sees it compressed along one direction: locally, a
change of viewpoint is an affine map, and every affine map with a positive determinant is a
similarity after a compression by a *tilt* t >= 1 along some direction (its *longitude* phi):
``A = lambda R(psi) [R(phi)^T diag(1/t, 1) R(phi)]``. The scale search of the paper absorbs
the similarity; these views absorb the compression. Each view is the image shrunk by
:func:`decimation_of` (camera-size images), turned by phi, blurred along x by
``c sqrt(t^2 - 1)`` (Morel & Yu's anti-aliasing, c = 0.8) and shrunk along x by t;
``to_view`` (2x3) maps an image pixel to its pixel in the view.

The search first runs without any view, and adds the views only when the images themselves
found nothing (Mishkin, Matas & Perdoch 2015, "MODS"), so ordinary pairs cost no more than
before; the views of both images are then searched together, in one pooled vote
(:mod:`scalematch.search.features`, :mod:`scalematch.stages.vote`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar, List, Mapping, NamedTuple, Optional, Sequence, Tuple

import cv2
import numpy as np

from ..checks import AT_LEAST_ONE, Bounds, COUNT, FACTOR, NON_NEGATIVE, POSITIVE, check_bounds, in_range, one_of
from ..geometry import apply, compose, invert, resize_map
from .nodata import distance_inside
from .scalespace import antialias_sigma, gaussian_blur


#: The passes of views (docs/design/VIEWS.md, "The passes"): t = 2, then 4, then 6 and 8
#: together (longitude steps 72/t: 5, 10, then 15 + 20 views), as far as MODS's steepest view
#: synthesis (t = 8). Each pass runs only when every earlier one found nothing, so only a "no"
#: pays for all of them; each pass is one pooled vote over its views of both images
PASSES: Tuple[Tuple[float, ...], ...] = ((2.0,), (4.0,), (6.0, 8.0))
#: The passes without the third one (the ``tilt-4`` preset): tilts up to about 6 solved
TILT4_PASSES: Tuple[Tuple[float, ...], ...] = PASSES[:2]
#: ``ViewParams.coarser_directions``: the coarser image's views in one direction of the search
#: (the one whose coarser image is the smaller), or in both
COARSER_DIRECTIONS = ("one", "both")
#: Most views the passes may hold together: each view is searched at every scale, so the time
#: of a "no" grows with their number. Four times the default's 50 (a longitude step of 18
#: degrees, a quarter of Morel & Yu's 72, stays within it).
MAX_VIEWS = 200


@dataclass(frozen=True)
class ViewParams:
    """Which tilted views to simulate when the plain search finds nothing."""

    enabled: bool = True  #: False: never simulate views (the plain search in both orders only)
    #: passes of tilts, each run only when every earlier pass found nothing. Morel & Yu sample
    #: t = sqrt(2)^k; the gradient descriptor tolerates a tilt of about 2 on its own (measured
    #: on tilted zoom pairs, docs/results/BENCHMARKS.md), so views at t = 2 then 4 (a sampling ratio
    #: of 2) cover tilts up to about 6 with 15 views instead of 27; t = 6 and 8 reach 8 and more
    #: (docs/design/VIEWS.md, "The third pass")
    passes: Tuple[Tuple[float, ...], ...] = PASSES
    #: longitude step at tilt t is ``longitude_step_deg / t`` over [0, 180) (Morel & Yu: 72)
    longitude_step_deg: float = 72.0
    #: anti-aliasing blur along the compressed axis: c * sqrt(t^2 - 1) px (Morel & Yu: c = 0.8)
    antialias_c: float = 0.8
    #: the views are simulated on their image shrunk so that its shorter side is at most this
    #: many px (0: always at full resolution; :func:`decimation_of`), ASIFT's low resolution
    #: (Morel & Yu 2009, section 4), and the view pairs the vote chooses are made again at full
    #: resolution for their full match. 512 px shrinks a 1 MP image (1024x768) by 1.5, a
    #: camera-size image at the working size of 2048 px by 3, and leaves a 640x480 image as it
    #: is: on the gate's tilted, steep and oblique pairs, the same pairs solved as with every
    #: view at full resolution, 0.90x the time; at half resolution the oblique pairs'
    #: footprints in the coarser image's views held too few points (6 of the gate's 24 oblique
    #: runs lost; docs/design/VIEWS.md, "The pooled vote")
    max_short_side_px: float = 512.0
    #: the views of the finer image are searched from this scale on (of the image's pixels):
    #: their levels are then made from the view decimated by 2 (``stages.scalespace``), and
    #: the finer levels, most of a view's cost, are never made. Every tilted and steep pair of
    #: the gate was solved by a view at scale 2 or more (docs/design/VIEWS.md, "The pooled
    #: vote"); the views of the coarser image keep its full resolution, which the oblique
    #: pairs need (at decimation 2, 14 of the gate's 24 oblique runs were solved, and 2 wrong)
    finer_from_scale: float = 2.0
    #: the views of the coarser image are searched too (both images' views are in the vote):
    #: where the finer image is the oblique one (a telephoto seen obliquely against a frontal
    #: wide shot) its directional ratios are r and r / t, and below 1 no scale searched reaches
    #: them; a view of the coarser image compressed by t along that axis does
    #: (docs/design/VIEWS.md, "Views of the coarser image")
    coarser: bool = True
    #: ... in "both" directions of the automatic order, or in "one": the one whose coarser
    #: image is the smaller (shorter longer side; the given one on a tie). Both reach the same
    #: pairs in principle (a pair whose finer image maps with singular values s1 > 1 > s2: the
    #: given direction's views of tilt s1 / s2 at scale s1, the other's at 1 / s2;
    #: docs/design/VIEWS.md, "Views of the coarser image"), but not always in practice
    coarser_directions: str = "both"
    #: view pairs matched in full: the ones whose best cell of the pooled vote is strongest
    #: (``stages.vote.best_pairs``)
    full_searches: int = 3
    #: a match of the plain search with fewer distinct inliers than this is compared with the
    #: views, and the stronger answer is taken: a tilted view of a repeated facade gave a plain
    #: similarity of 6 wrong inliers at log10 NFA -12.6 on a tilted zoom pair (t = 2.83) where
    #: the views find the truth (docs/results/BENCHMARKS.md)
    confirm_below_inliers: int = 12
    #: the vote probes every N-th level of a tilted view (N = 1: each one); the view pairs
    #: matched in full are matched at every level near their best cells. Detection is most of
    #: a view's cost; a third-octave scale off still matches (the descriptor's tolerance)
    vote_every: int = 2
    #: keypoints closer than this to the view's empty corners are dropped, px at s = 1 (x s):
    #: the descriptor window is 16 level px wide, so 8 px keeps it inside the image
    edge_margin_px: float = 8.0

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "longitude_step_deg": POSITIVE,
        "antialias_c": NON_NEGATIVE,
        "max_short_side_px": NON_NEGATIVE,
        "finer_from_scale": FACTOR,
        "edge_margin_px": NON_NEGATIVE,
        "full_searches": AT_LEAST_ONE,
        "confirm_below_inliers": COUNT,
        "vote_every": AT_LEAST_ONE,
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
    """A simulated view of an image."""

    tilt: float  #: t >= 1 (1: the image itself)
    longitude_deg: float  #: phi, degrees, the direction compressed by t
    image: np.ndarray = field(repr=False)  #: (h', w') float32 view
    to_view: np.ndarray = field(repr=False)  #: 2x3, image px -> view px
    #: (h', w') float32 distance (view px) to the nearest pixel outside the image or on its
    #: no-data region (:mod:`scalematch.stages.nodata`), or None when every pixel of the view
    #: shows the scene
    inside_distance: object = field(default=None, repr=False)
    #: (h, w) of the image viewed (None: unknown), where a map found through the view must hold
    source_shape: Optional[Tuple[int, int]] = None
    #: image px per view px along the uncompressed direction (:func:`decimation_of`; 1 for the
    #: image itself): a scale s of the view's pixels is the scale s * scale of the image's
    scale: float = 1.0

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
    """The passes of (tilt, longitude) pairs, after the plain search (the image itself is not
    listed).

    >>> [len(p) for p in view_plan(ViewParams())], view_plan(ViewParams())[0][:2]
    ([5, 10, 35], [(2.0, 0.0), (2.0, 36.0)])
    """
    if not params.enabled:
        return []
    return [[(t, phi) for t in tilts if t > 1.0
             for phi in longitudes(t, params.longitude_step_deg)] for tilts in params.passes]


def view_scales(view: View, scales: Sequence[float]) -> List[float]:
    """The scales of the image's pixels (sorted) that ``view`` serves, in the view's pixels:
    ``s / view.scale`` where that is at least 1 (a view does not enlarge its pixels).

    >>> v = View(2.0, 0.0, np.zeros((4, 4), np.float32), np.eye(2, 3), scale=2.0)
    >>> view_scales(v, (1.0, 1.587, 2.0, 2.52, 4.0))
    [1.0, 1.26, 2.0]
    """
    return [round(s / view.scale, 6) for s in sorted(scales) if s / view.scale >= 1.0 - 1e-9]


def shrunk(image: np.ndarray, factor: float, camera_blur_px: float = 0.5
           ) -> Tuple[np.ndarray, np.ndarray]:
    """(``image`` shrunk by ``factor``, the 2x3 map from its pixels to the shrunk ones): blurred
    as the scale-space blurs a level decimated by ``factor``
    (:func:`stages.scalespace.antialias_sigma`), then resampled by area."""
    if factor <= 1.0:
        return image, np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    h, w = image.shape[:2]
    nw, nh = max(int(round(w / factor)), 1), max(int(round(h / factor)), 1)
    blurred = gaussian_blur(np.asarray(image, np.float32), antialias_sigma(factor, camera_blur_px))
    return cv2.resize(blurred, (nw, nh), interpolation=cv2.INTER_AREA), resize_map(nw / w, nh / h)


def identity_view(high: np.ndarray, valid: Optional[np.ndarray] = None) -> View:
    """The image itself as a view; ``valid`` (bool, its shape): where it shows the scene
    (:func:`scalematch.stages.nodata.valid_mask`; None: everywhere)."""
    return View(1.0, 0.0, high, np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
                distance_inside(valid), tuple(high.shape[:2]))


class Source(NamedTuple):
    """An image as its views are made from it: shrunk by ``scale`` (:func:`decimation_of`),
    where it shows the scene (None: everywhere) and the map from the image's pixels."""

    image: np.ndarray
    valid: Optional[np.ndarray]
    to_source: np.ndarray  #: 2x3, image px -> source px
    shape: Tuple[int, int]  #: (h, w) of the image itself
    scale: float  #: image px per source px


def source_of(image: np.ndarray, valid: Optional[np.ndarray], decimation: float) -> Source:
    """``image`` prepared to make its views from (shrunk once for all of them)."""
    small, to_small = shrunk(image, decimation)
    if valid is not None and decimation > 1.0:
        valid = cv2.resize(valid.astype(np.uint8), (small.shape[1], small.shape[0]),
                           interpolation=cv2.INTER_NEAREST).astype(bool)
    return Source(np.asarray(small, np.float32), valid, to_small, tuple(image.shape[:2]),
                  max(float(decimation), 1.0))


def tilt_view(high: np.ndarray, tilt: float, longitude_deg: float,
              params: ViewParams = ViewParams(), valid: Optional[np.ndarray] = None) -> View:
    """The view of ``high`` (H, W) float32 compressed by ``tilt`` along ``longitude_deg``.

    The image is shrunk by :func:`decimation_of` (:func:`shrunk`), turned by phi onto a canvas
    that holds all of it, blurred along x by ``antialias_c * sqrt(t^2 - 1)`` px and resized
    along x by 1/t (``cv2.resize``'s centre-aligned convention: x -> (x + 0.5) / t - 0.5;
    :func:`compressed_x`). ``valid``: where the image shows the scene (None: everywhere); the
    view's ``inside_distance`` measures to the rest. Many views of one image:
    :func:`view_of` on one :func:`source_of`.
    """
    if tilt <= 1.0:
        return identity_view(high, valid)
    return view_of(source_of(high, valid, decimation_of(high.shape, params)), tilt,
                   longitude_deg, params)


def decimation_of(shape: Sequence[int], params: ViewParams) -> float:
    """How much an image of ``shape`` (H, W) is shrunk to make its views: its shorter side
    brought to ``params.max_short_side_px`` when longer (1: full resolution).

    >>> decimation_of((768, 1024), ViewParams()), decimation_of((1536, 2048), ViewParams())
    (1.5, 3.0)
    >>> decimation_of((480, 640), ViewParams())
    1.0
    >>> decimation_of((1536, 2048), ViewParams(max_short_side_px=0))
    1.0
    """
    short = float(min(shape[:2]))
    limit = params.max_short_side_px
    return short / limit if limit > 0 and short > limit else 1.0


def view_of(source: Source, tilt: float, longitude_deg: float, params: ViewParams) -> View:
    """The view of ``source`` (:func:`source_of`) compressed by ``tilt`` along
    ``longitude_deg`` (:func:`tilt_view`)."""
    high, valid = source.image, source.valid
    h, w = high.shape
    a = math.radians(longitude_deg)
    rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    corners = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float64) @ rot.T
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    turn = np.hstack([rot, (-lo)[:, None]])
    cw, ch = (int(v) for v in np.ceil(hi - lo) + 1)
    img = cv2.warpAffine(high, turn, (cw, ch), flags=cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    img = compressed_x(img, tilt, params.antialias_c)
    nw = img.shape[1]
    squeeze = resize_map(nw / cw, 1.0)
    if valid is None:  # the image's own outline, turned and squeezed: a parallelogram
        inside = np.zeros((ch, nw), np.uint8)
        outline = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
        cv2.fillConvexPoly(inside, np.round(apply(compose(squeeze, turn), outline)).astype(
            np.int32), 1)
    else:
        inside = cv2.resize(cv2.warpAffine(valid.astype(np.uint8), turn, (cw, ch),
                                           flags=cv2.INTER_NEAREST,
                                           borderMode=cv2.BORDER_CONSTANT, borderValue=0),
                            (nw, ch), interpolation=cv2.INTER_NEAREST)
    to_view = compose(compose(squeeze, turn), source.to_source)
    dist = cv2.distanceTransform(inside, cv2.DIST_L2, 3)
    return View(float(tilt), float(longitude_deg), img, to_view, dist, source.shape, source.scale)


def compressed_x(image: np.ndarray, tilt: float, c: float) -> np.ndarray:
    """``image`` (float32) compressed along x by ``tilt`` after Morel & Yu's anti-aliasing blur
    of ``c sqrt(t^2 - 1)`` px, done as halvings (each a blur of ``c sqrt(3)`` px and a resize by
    1/2) and a last step of the factor left: the blurs compose to the same total (``c^2 (4^k -
    1)`` of the halvings, in the image's px, plus ``c^2 (r^2 - 1) 4^k`` of the last step, is
    ``c^2 (t^2 - 1)`` for ``t = r 2^k``), but each runs on a narrower image with a short kernel:
    one blur of 6.3 px (t = 8) on the whole canvas was most of a view's cost. The resizes are
    centre-aligned, so they compose to one resize by the final width over the first.

    >>> img = np.tile(np.arange(64, dtype=np.float32), (4, 1))
    >>> compressed_x(img, 8.0, 0.8).shape, compressed_x(img, 1.0, 0.8).shape
    ((4, 8), (4, 64))
    """
    out = np.asarray(image, np.float32)
    left = float(tilt)
    while left >= 2.0 - 1e-9 and out.shape[1] > 1:
        out = _blurred_resized(out, c * math.sqrt(3.0), 2.0)
        left /= 2.0
    if left > 1.0 + 1e-9:
        out = _blurred_resized(out, c * math.sqrt(left * left - 1.0), left)
    return out


def _blurred_resized(image: np.ndarray, sigma: float, factor: float) -> np.ndarray:
    """``image`` blurred along x by ``sigma`` px, then resized along x by 1 / ``factor``."""
    blurred = cv2.GaussianBlur(image, (0, 0), sigmaX=sigma, sigmaY=0.01)
    nw = max(int(round(image.shape[1] / factor)), 1)
    return cv2.resize(blurred, (nw, image.shape[0]), interpolation=cv2.INTER_LINEAR)


def valid_in(view: View) -> Optional[np.ndarray]:
    """(h', w') bool: where the view shows the scene (None: everywhere)."""
    return None if view.inside_distance is None else view.inside_distance > 0


def to_high(view: View, xy: np.ndarray) -> np.ndarray:
    """View px (N, 2) -> high-image px (N, 2)."""
    return apply(invert(view.to_view), xy)
