"""Where an image shows no scene: a canvas left by a rotation, a warp or a stitch, or a grey level
the user declares.

A rectified or georeferenced image sits on a canvas whose corners hold no data (black, most
often); a rotated scan has the same. Such a region is no part of the scene, yet its edge with
the picture is the strongest corner an image can have, and in a pixel comparison it correlates
with nothing. So the detector keeps its points away from it (their descriptor window would
straddle the edge), and the pixel tests leave it out (:mod:`scalematch.stages.pixelcheck`, as
NaN).

A photograph holds regions of one grey level that are scene: a clipped highlight (an overexposed
sky at 254-255), a night sky crushed to black, a studio backdrop, a shadow. Their edges are the
scene's own (rooftops, a subject's outline), often the only texture a telephoto frame has, so
they keep their points. What tells a canvas from them is its outline: a rotation or a warp
leaves the picture a convex polygon on its canvas, bounded by straight edges at whatever angle
the warp left. So the automatic rule (``NoDataParams.rule`` "auto", :func:`canvas_of`) takes as
no-data the part of the border's grey level outside the convex hull of the solid scene, when
the hull's edges that bound it are the picture's own edges: the scene begins right within them
along most of their length, and one of them is slanted. A band of one level along an image side
with an axis-parallel edge is as likely a clipped sky cut by the frame as a letterbox, and is
left to the scene.

A canvas of another shape (a round mask), or a picture pasted square on its canvas, is declared
with a grey level instead (``rule`` a number, ``--nodata VALUE``, the way GDAL rasters declare
theirs): every solid region of that level is then no-data, wherever it is. ``rule`` "none"
turns no-data off. The level is on the scale the matcher reads (8-bit grey levels; a 16-bit
image's values times 255/65535, a [0, 1] float image's times 255).

Pixel convention: OpenCV's, (x, y), pixel centres at integers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Real
from typing import ClassVar, Mapping, Optional, Tuple, Union

import cv2
import numpy as np

from ..checks import AT_LEAST_ONE, Bounds, NON_NEGATIVE, POSITIVE, SHARE, check_bounds

#: The rules a ``NoDataParams.rule`` may name besides a declared grey level
RULES = ("auto", "none")

#: The highest grey level a declared no-data value may be: the images are matched as 8-bit
#: grey (:mod:`scalematch.greylevels` scales 16-bit images down), so levels run from 0 to 255
MAX_GREY_LEVEL = 255.0


@dataclass(frozen=True)
class NoDataParams:
    """How no-data regions are found (the module docstring says why)."""

    #: "auto": a canvas found by its outline; "none": no no-data; a number: that grey level is
    #: no-data wherever it forms a solid region (``--nodata``)
    rule: Union[str, float] = "auto"
    #: grey levels a no-data pixel may differ from the region's value: an exact canvas fill,
    #: and the rounding of a resize at working size (an 8-bit no-data region stays within one
    #: level)
    tolerance: float = 2.0
    #: smallest share of the image the no-data regions cover together: a canvas corner of a
    #: 10-degree turn holds about 8 % of the canvas, so 0.5 % keeps any real canvas and leaves
    #: out a dark pixel run along a photo's edge
    min_share: float = 0.005
    #: a no-data region is solid: it holds this square (px) wherever it is thinner, it is part
    #: of the picture (a one-pixel line or a stripe of one grey level)
    core_px: int = 5
    #: the canvas's outline: how near (px) a hull edge the canvas and the scene must come (past
    #: the few pixels over which a warp's blur spreads the picture's edge)
    edge_probe_px: float = 6.0
    #: ... the share of the bounding edges' length along which the scene must begin right
    #: within them (the rest: the scene's own dark or clipped parts that touch the canvas)
    support_share: float = 0.6
    #: ... and the shortest edge (px) that can show the canvas's obliqueness
    min_edge_px: float = 20.0
    #: an edge is slanted when it is at least this far (degrees) from both image axes: a
    #: rotation of a degree leaves canvas slivers whose edges drift 13 px over a 768 px side
    oblique_deg: float = 0.5

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "tolerance": NON_NEGATIVE,
        "min_share": SHARE,
        "core_px": AT_LEAST_ONE,
        "edge_probe_px": POSITIVE,
        "support_share": SHARE,
        "min_edge_px": NON_NEGATIVE,
        "oblique_deg": Bounds(lo=0, hi=45),
    }

    def __post_init__(self) -> None:
        check_bounds("nodata", self, self.BOUNDS)
        rule = self.rule
        if isinstance(rule, str):  # "auto", "none", or a grey level written out ("--set")
            try:
                object.__setattr__(self, "rule", parse_rule(rule))
            except ValueError:
                raise ValueError(f"nodata.rule must be 'auto', 'none' or a grey level from 0 "
                                 f"to {MAX_GREY_LEVEL:g}, got {rule!r}") from None
        elif not (isinstance(rule, Real) and not isinstance(rule, bool)
                  and 0.0 <= float(rule) <= MAX_GREY_LEVEL):
            raise ValueError(f"nodata.rule must be 'auto', 'none' or a grey level from 0 to "
                             f"{MAX_GREY_LEVEL:g}, got {rule!r}")

    @property
    def declared(self) -> Optional[float]:
        """The declared grey level, None under the "auto" and "none" rules."""
        return None if isinstance(self.rule, str) else float(self.rule)


def parse_rule(text: str) -> Union[str, float]:
    """The rule a user typed (``--nodata``): "auto", "none", or a grey level.

    >>> parse_rule("none"), parse_rule(" 0 "), parse_rule("255.0")
    ('none', 0.0, 255.0)
    >>> parse_rule("black")
    Traceback (most recent call last):
    ...
    ValueError: --nodata must be auto, none or a grey level (a number), got 'black'
    >>> parse_rule("300")
    Traceback (most recent call last):
    ...
    ValueError: --nodata must be a grey level from 0 to 255 (the images' 8-bit levels), got 300
    """
    t = str(text).strip().lower()
    if t in RULES:
        return t
    try:
        v = float(t)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise ValueError(f"--nodata must be auto, none or a grey level (a number), got {text!r}")
    if not 0.0 <= v <= MAX_GREY_LEVEL:
        raise ValueError(f"--nodata must be a grey level from 0 to {MAX_GREY_LEVEL:g} (the "
                         f"images' 8-bit levels), got {v:g}")
    return v


@dataclass(frozen=True)
class NoData:
    """What one image showed of no-data: where (``valid``), at which level, how much."""

    valid: Optional[np.ndarray]  #: (H, W) bool, True where the image shows the scene; None: all
    value: float  #: the no-data grey level (NaN when there is none)
    share: float  #: share of the image taken as no-data, 0..1

    @staticmethod
    def none() -> "NoData":
        return NoData(None, math.nan, 0.0)


def border_value(image: np.ndarray) -> float:
    """The most common grey level (rounded) of the image's outermost pixel ring."""
    img = np.asarray(image, np.float32)
    ring = np.concatenate([img[0], img[-1], img[1:-1, 0], img[1:-1, -1]])
    values, counts = np.unique(np.rint(ring), return_counts=True)
    return float(values[np.argmax(counts)])


def _solid(near: np.ndarray, core_px: int) -> np.ndarray:
    """The parts of ``near`` (uint8 0/1) that hold a ``core_px`` square: eroded (the image's
    outside counts as ``near``), to be dilated back once the regions are chosen."""
    core = np.ones((core_px, core_px), np.uint8)
    return cv2.erode(near, core, borderType=cv2.BORDER_CONSTANT, borderValue=1)


def _grown(core: np.ndarray, near: np.ndarray, core_px: int) -> np.ndarray:
    """The chosen cores (uint8 0/1) dilated back by the square, within ``near``: bool."""
    square = np.ones((core_px, core_px), np.uint8)
    grown = cv2.dilate(core, square, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return grown.astype(bool) & near.astype(bool)


def canvas_of(region: np.ndarray, params: NoDataParams = NoDataParams()) -> np.ndarray:
    """The part of ``region`` (H, W bool: the border-touching regions of the border's grey
    level) that is a canvas: (H, W) bool, empty when none is.

    A rotation or a warp leaves the picture a convex polygon on its canvas. So the picture is
    taken as the convex hull of the solid scene (the pixels outside ``region``, eroded by
    ``core_px`` so that a canvas's noise does not count), and the canvas as the part of
    ``region`` outside that hull. It is one when the hull's edges that bound it are edges of
    the picture: along ``support_share`` of their length the scene begins right inside them
    (a clipped sky's hull edge spans the rooftops it rests on, with sky between), and one of
    them is oblique (``oblique_deg``: a band along an image side with an axis-parallel edge is
    as likely a clipped sky cut by the frame as a letterbox, and is left to the scene).

    >>> corner = np.fromfunction(lambda y, x: x + 2 * y < 180, (200, 300))  # a turn's corner
    >>> int(canvas_of(corner).sum()) == int(corner.sum())
    True
    >>> band = np.zeros((200, 300), bool); band[:80] = True               # a straight band
    >>> int(canvas_of(band).sum())
    0
    """
    region = np.asarray(region, bool)
    h, w = region.shape
    empty = np.zeros((h, w), bool)
    core = np.ones((params.core_px, params.core_px), np.uint8)
    # the image's outside is no scene: a few noise pixels along the frame are no picture
    scene = cv2.erode((~region).astype(np.uint8), core, borderType=cv2.BORDER_CONSTANT,
                      borderValue=0)
    hull = _hull(scene)
    if hull is None:
        return empty
    inside = np.zeros((h, w), np.uint8)
    cv2.fillConvexPoly(inside, hull.astype(np.int32), 1)
    inside = cv2.dilate(inside, core).astype(bool)  # the erosion's rim given back
    outside = region & ~inside
    if not outside.any():
        return empty
    near_out = cv2.distanceTransform((~outside).astype(np.uint8), cv2.DIST_L2, 3)
    near_scene = cv2.distanceTransform(region.astype(np.uint8), cv2.DIST_L2, 3)
    bounding = supported = 0.0
    oblique = False
    for p, q in zip(hull, np.roll(hull, -1, axis=0)):
        bound, support = _edge_support(p, q, near_out, near_scene, params.edge_probe_px)
        bounding += bound
        supported += support
        if bound >= max(params.min_edge_px, 1.0) and support >= params.support_share * bound:
            angle = math.degrees(math.atan2(abs(q[1] - p[1]), abs(q[0] - p[0])))
            oblique |= min(angle, 90.0 - angle) >= params.oblique_deg
    if bounding <= 0 or not oblique or supported < params.support_share * bounding:
        return empty
    return outside


def _hull(mask: np.ndarray) -> Optional[np.ndarray]:
    """(K, 2) float64 convex hull (x, y) of the pixels of ``mask`` (uint8), None when empty:
    from each row's first and last pixel, which hold every extreme point (a hull of a
    million pixels takes a second; of their rows' ends, a millisecond)."""
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    on = mask[rows].astype(bool)
    first = on.argmax(axis=1)
    last = on.shape[1] - 1 - on[:, ::-1].argmax(axis=1)
    ends = np.concatenate([np.column_stack([first, rows]), np.column_stack([last, rows])])
    return cv2.convexHull(ends.astype(np.int32)).reshape(-1, 2).astype(np.float64)


def _edge_support(p: np.ndarray, q: np.ndarray, near_out: np.ndarray, near_scene: np.ndarray,
                  probe_px: float) -> Tuple[float, float]:
    """(px of the hull edge p->q within ``probe_px`` of the canvas candidate, px of those also
    within ``probe_px`` of the scene), every pixel along it; ``near_out`` and ``near_scene``
    are each pixel's distance to them. A distance, not a probe at a fixed offset: a warp's
    blur spreads the picture's edge over a few pixels."""
    h, w = near_out.shape
    length = float(np.hypot(*(q - p)))
    if length < 1.0:
        return 0.0, 0.0
    t = np.linspace(0.0, 1.0, int(length) + 1)[:, None]
    along = p + t * (q - p)
    x = np.clip(np.rint(along[:, 0]).astype(int), 0, w - 1)
    y = np.clip(np.rint(along[:, 1]).astype(int), 0, h - 1)
    bound = near_out[y, x] <= probe_px
    return float(bound.sum()), float((bound & (near_scene[y, x] <= probe_px)).sum())


def find_nodata(image: np.ndarray, params: NoDataParams = NoDataParams()) -> NoData:
    """The no-data of ``image`` (H, W) under ``params.rule``: where it shows the scene, the
    no-data level and share (:class:`NoData`; ``NoData.none()`` when it shows it everywhere).

    >>> img = np.full((60, 80), 120.0, np.float32); img[::2] += 40   # a striped picture ...
    >>> canvas, _ = _turned(img, 20.0)                                 # ... turned on black
    >>> nd = find_nodata(canvas)
    >>> nd.value, round(nd.share, 2), bool(nd.valid[canvas.shape[0] // 2, canvas.shape[1] // 2])
    (0.0, 0.34, True)
    >>> find_nodata(img).valid is None                                 # no canvas
    True
    """
    img = np.asarray(image, np.float32)
    h, w = img.shape
    if params.rule == "none" or h < 3 or w < 3:
        return NoData.none()
    # a canvas's sensor noise or JPEG ringing spreads its level over a few grey levels: the
    # level is read through a median (5x5), which keeps the canvas's edge where it is
    level = _median5(img)
    value = params.declared if params.declared is not None else border_value(level)
    near = (np.abs(level - np.float32(value)) <= params.tolerance).astype(np.uint8)
    solid = _solid(near, params.core_px)
    n, labels = cv2.connectedComponents(solid, connectivity=4)
    if n <= 1:
        return NoData.none()
    if params.declared is not None:
        nodata = _grown((labels > 0).astype(np.uint8), near, params.core_px)
    else:
        ring = np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]])
        lut = np.zeros(n, np.uint8)
        lut[ring[ring > 0]] = 1
        touching = lut[labels]
        region = _grown(touching, near, params.core_px)
        if region.mean() < params.min_share:  # too little of the border's level to be one
            return NoData.none()
        nodata = canvas_of(region, params)
    share = float(nodata.mean())
    if share == 0.0 or share < params.min_share:
        return NoData.none()
    return NoData(~nodata, float(value), share)


def _median5(img: np.ndarray) -> np.ndarray:
    """``img`` (float32) through a 5x5 median; on whole levels in 0..255 when it lies there
    (OpenCV's 8-bit median is ten times its float one; the tolerance is two levels)."""
    if min(img.shape) < 5:
        return img
    if img.min() >= 0 and img.max() <= 255:
        return cv2.medianBlur(np.rint(img).astype(np.uint8), 5).astype(np.float32)
    return cv2.medianBlur(np.ascontiguousarray(img), 5)


def valid_mask(image: np.ndarray, params: NoDataParams = NoDataParams()) -> Optional[np.ndarray]:
    """(H, W) bool, True where ``image`` shows the scene; None when it shows it everywhere
    (:func:`find_nodata`)."""
    return find_nodata(image, params).valid


def _turned(image: np.ndarray, angle_deg: float):
    """``image`` turned by ``angle_deg`` on a black canvas that holds it (for the examples)."""
    h, w = image.shape
    m = cv2.getRotationMatrix2D((0.0, 0.0), angle_deg, 1.0)
    corners = np.array([[0, 0, 1], [w - 1, 0, 1], [w - 1, h - 1, 1], [0, h - 1, 1]], float)
    mapped = corners @ m.T
    m[:, 2] -= mapped.min(axis=0)
    size = np.ceil(mapped.max(axis=0) - mapped.min(axis=0)).astype(int) + 1
    return cv2.warpAffine(image, m, (int(size[0]), int(size[1])), flags=cv2.INTER_LINEAR), m


def distance_inside(valid: Optional[np.ndarray]) -> Optional[np.ndarray]:
    """(H, W) float32 distance (px) from each pixel to the nearest no-data pixel; None when
    ``valid`` is None (no no-data)."""
    if valid is None:
        return None
    return cv2.distanceTransform(valid.astype(np.uint8), cv2.DIST_L2, 3)


def away_from(inside: np.ndarray, xy: np.ndarray, margin_px) -> np.ndarray:
    """Boolean mask of the points (N, 2) (x, y px) at least ``margin_px`` (a number, or one per
    point) from the nearest pixel outside, given ``inside`` (H, W): each pixel's distance to it.

    >>> away_from(distance_inside(np.pad(np.ones((5, 5), bool), 1)), np.array([[1, 1], [3, 3]]), 2)
    array([False,  True])
    """
    h, w = inside.shape
    x = np.clip(np.rint(xy[:, 0]).astype(int), 0, w - 1)
    y = np.clip(np.rint(xy[:, 1]).astype(int), 0, h - 1)
    return inside[y, x] >= margin_px


def with_nan(image: np.ndarray, valid: Optional[np.ndarray]) -> np.ndarray:
    """``image`` as float32 with NaN where it shows no scene and on the pixel ring next to it,
    which interpolation mixed with the fill (itself when ``valid`` is None)."""
    if valid is None:
        return image
    out = np.array(image, np.float32, copy=True)
    out[cv2.erode(valid.astype(np.uint8), np.ones((3, 3), np.uint8),
                  borderType=cv2.BORDER_CONSTANT, borderValue=1) == 0] = np.nan
    return out
