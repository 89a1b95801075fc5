"""Features once per image: the tilted views of each image, described into one table that both
orders of a search read.

An image is the finer one in one order of the search and the coarser one in the other, and
each of its views serves both: as the finer image, the view's levels are probed (from
``ViewParams.finer_from_scale`` on, every ``ViewParams.vote_every``-th; the
``ProbeParams.points`` strongest points of each described); as the coarser image, the view's
first level is described (its ``VIEWS_COARSER_POINTS`` strongest). The pooled vote
(:mod:`scalematch.stages.vote`) reads the tables; the view pairs it chooses are made again at
full resolution and matched in full with every point of the levels they need (a level costs
less to make again than to keep).

The views of an image whose shorter side is over ``ViewParams.max_short_side_px`` are
simulated on the image shrunk to it (:func:`stages.views.decimation_of`; a view pixel is then
that many image pixels, ``View.scale``), ASIFT's low resolution for the vote. The image itself
(the identity view) keeps its full resolution: its levels are those of the plain search,
whose detection this module takes as it is (:class:`Roles`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, List, Mapping, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from ..stages.descriptors import Described
from ..stages.detector import Contrast, Gradients, HarrisParams, Keypoints, detect_on_level
from ..stages.scalespace import Level, scale_space
from ..stages.threads import thread_map
from ..stages.views import View, ViewParams, decimation_of, source_of, view_of, view_scales

#: Points of a view's first level described for the vote when the image is the coarser one,
#: strongest first: the vote needs only enough of them to find the view pair (the pair matched
#: in full is described whole). 500 found every tilted, steep and oblique pair of the gate
#: that 12,000 found, at a third of the coarser side's descriptions (docs/design/VIEWS.md,
#: "The pooled vote")
VIEWS_COARSER_POINTS = 500
#: Points of the image's own first level described for the vote as the coarser image (its
#: strongest; the plain search describes up to ``harris_low.max_points``)
IDENTITY_COARSER_POINTS = 1500


@dataclass(frozen=True)
class Table:
    """Described points pooled over views and levels (N rows each); ``xy`` in each view's px."""

    view: np.ndarray = field(repr=False)  #: (N,) int, index of the view (0: the image itself)
    s: np.ndarray = field(repr=False)  #: (N,) the level's scale in the view's pixels
    xy: np.ndarray = field(repr=False)  #: (N, 2) view px
    angle: np.ndarray = field(repr=False)  #: (N,) radians
    desc: np.ndarray = field(repr=False)  #: (N, D) float32
    point: np.ndarray = field(repr=False)  #: (N,) id of the point (view, level, position)

    def __len__(self) -> int:
        return int(self.s.shape[0])

    def rows(self, keep: np.ndarray) -> "Table":
        """The rows selected by ``keep`` (a boolean mask or indices)."""
        return Table(self.view[keep], self.s[keep], self.xy[keep], self.angle[keep],
                     self.desc[keep], self.point[keep])

    @staticmethod
    def of(parts: Sequence[Tuple[int, Described]], dim: int) -> "Table":
        """The table of ``parts``: (view index, a level's descriptors) each."""
        parts = [(v, d) for v, d in parts if len(d)]
        if not parts:
            return Table(np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 2)), np.zeros(0),
                         np.zeros((0, dim), np.float32), np.zeros(0, np.int64))
        view = np.concatenate([np.full(len(d), v, np.int64) for v, d in parts])
        s = np.concatenate([np.full(len(d), d.s) for _, d in parts])
        # a point described at two orientations is one point: its level's keypoint row
        point = np.concatenate([d.index for _, d in parts]).astype(np.int64)
        level = np.concatenate([np.full(len(d), k, np.int64) for k, (_, d) in enumerate(parts)])
        return Table(view, s, np.vstack([d.xy for _, d in parts]),
                     np.concatenate([d.angle for _, d in parts]),
                     np.vstack([d.desc for _, d in parts]).astype(np.float32),
                     level * (int(point.max()) + 1) + point)


class ViewInfo(NamedTuple):
    """What the vote and the full match need of a view once its table is made: which view it
    is, how many image pixels a view pixel is (``View.scale``) and its size."""

    tilt: float
    longitude_deg: float
    scale: float
    shape: Tuple[int, int]

    @staticmethod
    def of(view: View) -> "ViewInfo":
        return ViewInfo(view.tilt, view.longitude_deg, view.scale, tuple(view.image.shape[:2]))


@dataclass(frozen=True)
class ImageViews:
    """One image's views and their tables; index 0 is the image itself. The views' images are
    not kept: a view chosen for a full match is made again (:func:`stages.views.tilt_view`)."""

    views: Tuple[ViewInfo, ...]
    #: every level probed of every view, the probe's points (the image as the finer one)
    finer: Table = field(repr=False)
    #: the first level of every view, its strongest points (the image as the coarser one)
    coarser: Table = field(repr=False)

    @property
    def sides(self) -> np.ndarray:
        """(V,) each view's longer side, its own px."""
        return np.array([max(v.shape) for v in self.views], np.float64)

    @property
    def shapes(self) -> np.ndarray:
        """(V, 2) each view's (H, W)."""
        return np.array([v.shape for v in self.views], np.float64)


@dataclass(frozen=True)
class Describing:
    """How a search detects and describes a view (the same for every view of an image)."""

    describe: Callable[[Level, Keypoints], Described]  #: the mode's (``Mode.describe``)
    harris: HarrisParams  #: the finer image's detector (every level)
    harris_low: HarrisParams  #: the coarser image's detector (the first level)
    contrast: Optional[Contrast]  #: the image's own (:func:`stages.detector.image_contrast`)
    space: Mapping[str, float]  #: :func:`stages.scalespace.scale_space`'s keyword parameters
    probe_points: int  #: the strongest points of a level described for the vote
    edge_margin_px: float  #: :attr:`ViewParams.edge_margin_px`
    every: int  #: a view's levels probed: every ``every``-th (``ViewParams.vote_every``)
    min_side: int  #: a level with a shorter side is not searched (``min_level_side_px``)
    from_scale: float = 1.0  #: a view's levels are probed from this scale of the image on


class Roles(NamedTuple):
    """What a search needs of an image's views: the image itself (``identity``) as the plain
    steps detected it (``finer``: the probe's descriptors of each of its levels, empty when it
    is never the finer image; ``coarser``: its first level as the coarser image, strongest
    first, None when it never is), the scales of its views as the finer image (none: it never
    is), and whether its views' first levels serve as the coarser image (``coarser_views``)."""

    identity: View
    finer: Sequence[Described]
    coarser: Optional[Described]
    scales: Sequence[float]
    coarser_views: bool


def view_levels(view: View, scales: Sequence[float], how: Describing) -> List[Level]:
    """The levels of ``view`` at ``scales`` (the scales in the image's pixels that the view
    serves: :func:`stages.views.view_scales`), in the view's own pixels."""
    return list(scale_space(view.image, view_scales(view, scales), **how.space))


def first_level(view: View) -> Level:
    """A view's first level: the view itself at s = 1."""
    return Level(s=1.0, d=1.0, blur=0.0, image=view.image)


def level_points(view: View, level: Level, harris: HarrisParams, contrast: Optional[Contrast],
                 edge_margin_px: float, grads: Optional[Gradients] = None) -> Keypoints:
    """The points of one level of a view, found by ``harris`` away from the view's empty
    corners and no-data regions (``edge_margin_px`` from them); ``contrast``: the image's own;
    ``grads``: the level's gradients when measured already. Every view and level of the search
    is detected here: the finer image's levels (:mod:`scalematch.search.detect`), the vote's
    levels of each view (:func:`view_rows`) and a view's first level as the coarser image's
    (:func:`first_level_points`)."""
    return detect_on_level(level, harris, contrast, grads, view.inside_distance, edge_margin_px)


def first_level_points(view: View, harris_low: HarrisParams, contrast: Optional[Contrast],
                       edge_margin_px: float) -> Keypoints:
    """The points of a view's first level as the coarser image's detector (``harris_low``)
    finds them, away from the view's empty corners; ``contrast``: the image's own."""
    return level_points(view, first_level(view), harris_low, contrast, edge_margin_px)


def view_rows(view: View, scales: Sequence[float], how: Describing) -> List[Described]:
    """The probe's descriptors of each level of one tilted view probed for the vote (from
    ``how.from_scale`` on, every ``how.every``-th: the cascade makes only those)."""
    scales = sorted(s for s in scales if s >= how.from_scale - 1e-9)[::how.every]
    probed = []
    for level in view_levels(view, scales, how) if scales else []:
        if min(level.image.shape) < how.min_side:
            continue
        kp = level_points(view, level, how.harris, how.contrast, how.edge_margin_px)
        if len(kp):
            probed.append(how.describe(level, kp.part(slice(how.probe_points))))
    return probed


def first_level_rows(view: View, how: Describing) -> Described:
    """A tilted view's first level as the coarser image's, its ``VIEWS_COARSER_POINTS``
    strongest points described."""
    kp = first_level_points(view, how.harris_low, how.contrast, how.edge_margin_px)
    return how.describe(first_level(view), kp.part(slice(VIEWS_COARSER_POINTS)))


def image_views(image: np.ndarray, valid: Optional[np.ndarray], roles: Roles,
                keys: Sequence[Tuple[float, float]], params: ViewParams, how: Describing,
                tick: Callable[[], None] = lambda: None) -> ImageViews:
    """Every view of ``image`` (``valid``: where it shows the scene; None: everywhere) and its
    tables, as far as the search needs them (``roles``): the image itself from the plain
    steps' detection, and its tilted views ``keys`` (tilt, longitude), simulated and
    described here side by side on threads (on the image shrunk by
    :func:`stages.views.decimation_of` when it is camera-size). ``tick()`` is called once per
    view made."""
    keys = list(keys) if roles.scales or roles.coarser_views else []
    source = source_of(image, valid, decimation_of(image.shape, params)) if keys else None

    def one(key) -> Tuple[ViewInfo, List[Described], Optional[Described]]:
        view = view_of(source, *key, params)
        probed = view_rows(view, roles.scales, how) if roles.scales else []
        first = first_level_rows(view, how) if roles.coarser_views else None
        tick()
        return ViewInfo.of(view), probed, first

    made = thread_map(one, keys)
    finer = [(0, d) for d in roles.finer] + [
        (k + 1, d) for k, (_, probed, _) in enumerate(made) for d in probed]
    first = ([(0, roles.coarser.of_strongest(IDENTITY_COARSER_POINTS))]
             if roles.coarser is not None else []) + [
        (k + 1, d) for k, (_, _, d) in enumerate(made) if d is not None]
    dim = next((d.desc.shape[1] for _, d in finer + first if d.desc.ndim == 2), 0)
    return ImageViews((ViewInfo.of(roles.identity),) + tuple(info for info, _, _ in made),
                      Table.of(finer, dim), Table.of(first, dim))

