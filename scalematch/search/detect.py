"""The finer image detected and described, and the coarser image described at s = 1.

Every view and level of the search is detected here (scale-adapted Harris at each scale of a
view's scale-space, :mod:`scalematch.stages.detector`) and its strongest points described by
the mode's descriptor (:mod:`scalematch.search.modes`): the plain steps' finer image at every
scale (:func:`detect_view`), the coarser image at s = 1 (:func:`describe_low`), a view of the
coarser image (:func:`describe_coarser_view`) and a view pair chosen by the vote at the scales
of its cells (:func:`detect_chosen`). What a step found is kept in the search's ``Memo`` for
the steps after it (:func:`plain_probed`, :func:`coarser_described`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from ..config import Config
from ..result import Direction
from ..stages.detector import Contrast, Gradients, Keypoints, detect_on_level
from ..stages.nodata import distance_inside
from ..stages.scalespace import Level, scale_space
from ..stages.views import View, identity_view
from .features import first_level, first_level_points, level_points
from .shared import Detected, LowFeatures, Measured, Probed, Search

#: Largest view of the finer image, px, whose scale-space levels are kept from detection to the
#: full pass (about 2.7 image copies of float32 over third-octave scales: 43 MB at 4 MP); a
#: larger image's levels are computed again, so peak memory stays bounded for camera-size
#: images. The result is the same either way.
KEEP_LEVELS_MAX_PX = 4_000_000


def describe_low(low: np.ndarray, search: Search,
                 contrast: Optional[Contrast] = None,
                 grads: Optional[Gradients] = None,
                 inside: Optional[np.ndarray] = None) -> LowFeatures:
    """The coarser image's points at s = 1 (``contrast``: its own, for adaptive detection;
    measured here when not given; ``grads``: its gradients, when measured with it; ``inside``:
    the distance to its no-data region, :func:`stages.nodata.distance_inside`)."""
    config = search.config
    level = Level(s=1.0, d=1.0, blur=0.0, image=low)
    kp = detect_on_level(level, config.harris_low, contrast, grads, inside,
                         config.views.edge_margin_px)
    return LowFeatures(low, search.mode.describe(level, kp), kp)


def shares_first_level(config: Config) -> bool:
    """True when an image's s = 1 points as the coarser one give its s = 1 points as the finer:
    the same detector but for a cap at least as large."""
    high, low = config.harris, config.harris_low
    return replace(low, max_points=high.max_points) == high and high.max_points > 0 and (
        low.max_points == 0 or low.max_points >= high.max_points)


def space_of(config: Config) -> dict:
    return dict(sigma=config.harris.sigma, min_level_sigma=config.harris.min_level_sigma,
                decimate=config.harris.decimate, camera_blur_px=config.harris.camera_blur_px)


class Reuse(NamedTuple):
    """What the detection of the finer image takes from the rest of the search: none of it
    changes the points found (:func:`detect_view`).

    ``known``: the same image described as the coarser one (the other direction), whose points
    give its s = 1 points (:func:`shares_first_level`). ``measured``: the finer image's
    contrast (:func:`scalematch.stages.detector.image_contrast`), when the detector adapts to
    it, and its gradients at s = 1 (:meth:`Memo.measured`).
    """

    known: Optional[LowFeatures] = None
    measured: Measured = Measured(None)


def detect_view(view: View, search: Search, scales: Sequence[float],
                tick: Callable[[], None] = lambda: None,
                reuse: Reuse = Reuse()) -> Tuple[Tuple[Detected, ...], bool]:
    """Detect every scale of the finer image and describe the probe's points: (detected,
    probing).

    ``scales``: the scales to detect (the step's). ``tick()`` is called once per scale
    detected. The levels of an image of at most ``KEEP_LEVELS_MAX_PX`` pixels are kept for the
    full pass. ``reuse``: what other steps found on the same images (:class:`Reuse`).
    """
    config = search.config
    known, (contrast, grads) = reuse
    scales = sorted(scales)
    probing = config.probe.enabled and len(scales) > config.probe.keep
    keep = view.image.size <= KEEP_LEVELS_MAX_PX
    n_probe = config.probe.points if probing else config.harris.max_points
    reuse = known is not None and view.is_identity and shares_first_level(config)
    detected = []
    for level in scale_space(view.image, scales, **space_of(config)):
        if min(level.image.shape) < config.harris.min_level_side_px:
            detected.append(Detected(Keypoints.empty(level.s), None, None))
        elif reuse and level.s == 1.0:  # found already: the coarser image of the other direction
            kp, part, full = known.strongest(config.harris.max_points, n_probe)
            detected.append(Detected(kp, part, level if keep else None, full))
        else:
            first = grads if view.is_identity and level.s == 1.0 else None
            kp = level_points(view, level, config.harris, contrast, config.views.edge_margin_px,
                              first)
            part = kp.part(slice(config.probe.points)) if probing else kp
            detected.append(Detected(kp, search.mode.describe(level, part),
                                     level if keep else None))
        tick()
    return tuple(detected), probing


def describe_coarser_view(view: View, search: Search, contrast: Optional[Contrast]
                          ) -> LowFeatures:
    """A view of the coarser image described as the coarser image is (at s = 1,
    ``harris_low``), its points away from the view's empty corners; ``contrast``: the coarser
    image's own (the detector adapts to it as for the image itself)."""
    config = search.config
    kp = first_level_points(view, config.harris_low, contrast, config.views.edge_margin_px)
    return LowFeatures(view.image, search.mode.describe(first_level(view), kp), kp)


def plain_probed(search: Search, direction: Direction, scales: Sequence[float]) -> Probed:
    """The finer image of ``direction`` detected at every scale of ``scales``, as its plain
    step did (kept in ``memo.plain``; detected here when that step did not run, its score
    unset)."""
    memo = search.memo
    if direction not in memo.plain:
        hi_img = search.work.coarser_finer(direction)[1]
        view = identity_view(hi_img, search.work.valid(direction)[1])
        detected, probing = detect_view(view, search, scales, reuse=Reuse(
            memo.coarser.get(direction.other), Measured(memo.contrast(hi_img,
                                                                     search.config.harris))))
        memo.plain[direction] = Probed(view, detected, (), (), math.nan, probing)
    return memo.plain[direction]


def coarser_described(search: Search, direction: Direction) -> LowFeatures:
    """The coarser image of ``direction`` described at s = 1, as its plain step did (kept in
    ``memo.coarser``; described here when that step did not run)."""
    memo, cfg = search.memo, search.config
    if direction not in memo.coarser:
        lo_img = search.work.coarser_finer(direction)[0]
        memo.coarser[direction] = describe_low(
            lo_img, search, memo.contrast(lo_img, cfg.harris_low),
            None, distance_inside(search.work.valid(direction)[0]))
    return memo.coarser[direction]


def detect_chosen(view: View, scales: Sequence[float], wanted: Sequence[int], search: Search,
                  contrast: Optional[Contrast]) -> Probed:
    """A tilted view detected at the scales ``wanted`` (positions in its ``scales``, its own
    pixels) for a full match: every point, the probe's strongest described (the others are
    described by :func:`finish_view`); the other scales are left empty."""
    config = search.config
    detected = []
    for n, level in enumerate(scale_space(view.image, scales[:max(wanted) + 1] if wanted else [],
                                          **space_of(config))):
        if n not in wanted or min(level.image.shape) < config.harris.min_level_side_px:
            detected.append(Detected(Keypoints.empty(level.s), None, None))
            continue
        kp = level_points(view, level, config.harris, contrast, config.views.edge_margin_px)
        detected.append(Detected(kp, search.mode.describe(level, kp.part(
            slice(config.probe.points))), level))
    detected += [Detected(Keypoints.empty(s_), None, None) for s_ in scales[len(detected):]]
    usable = tuple(n for n in wanted if detected[n].probe is not None)
    return Probed(view, tuple(detected), usable, usable, math.inf, True)
