"""The working size of very large images (docs/design/SPEED.md, "Working size").

An image whose longer side exceeds its ``Config`` limit (``low_max_side``, ``high_max_side``)
is matched as a copy shrunk by ``f = side / limit`` (``cv2.INTER_AREA``, the same ``f`` on both
axes), and the answer is given back in the original pixels. With OpenCV's pixel-centre
convention the working pixel ``x_w`` covers original pixels ``[x_w f, (x_w + 1) f)`` (edges), so

    x_original = f * x_working + (f - 1) / 2        (same for y)

which is the similarity ``S`` below. A transform ``T`` (finer image's working px -> coarser
image's working px) becomes ``S_coarser o T o S_finer^-1``.

Shrinking the low image by ``f_low`` and the high one by ``f_high`` multiplies the resolution
ratio by ``f_low / f_high``. Each search direction runs on its own scales
(:func:`direction_scales`), so that every ratio the configuration covers in the original pixels
(either way round) is still searched, and no more. A ratio that the shrinking brings below 1 is
found in the other order: that is why the high image is shrunk only when the order is searched
automatically. The per-scale table and ``best_scale`` are
reported in the original pixels, in the direction of the search they come from
(``Evidence.search_order``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Dict, Optional, Sequence, Tuple

import cv2
import numpy as np

from .geometry import apply, finer_to_coarser, invert, resize_map
from .imagefile import DEFAULT_MAX_PIXELS
from .imageio import Decoded, read_reduced
from .result import Direction, MatchResult
from .stages.estimator import model_of
from .stages.nodata import NoData, find_nodata, with_nan


def working_factor(shape: Tuple[int, ...], max_side: Optional[int]) -> float:
    """Shrink factor f >= 1 bringing the longer side of ``shape`` to ``max_side`` (1: none)."""
    if max_side is None or max(shape[:2]) <= max_side:
        return 1.0
    return max(shape[:2]) / float(max_side)


def shrink(image: np.ndarray, f: float) -> np.ndarray:
    """``image`` (H, W) shrunk by ``f`` with pixel-area averaging (anti-aliased), float32."""
    return cv2.resize(image, (0, 0), fx=1.0 / f, fy=1.0 / f, interpolation=cv2.INTER_AREA)


@dataclass(frozen=True)
class WorkImages:
    """The two images as the search sees them: each at its working size, with its factor."""

    low: np.ndarray = field(repr=False)  #: (H, W) float32, the first image given, working size
    high: np.ndarray = field(repr=False)  #: (H, W) float32, the second image given
    #: ``low`` is the first image shrunk by this (1: full size); from the file's image when it
    #: was decoded reduced (``decoded_factors``)
    f_low: float
    f_high: float  #: ``high`` is the second image shrunk by this (the same)
    scales: Dict[Direction, Tuple[float, ...]] = field(repr=False)  #: each direction's scales
    #: what each image shows of no-data at working size (:func:`scalematch.stages.nodata.
    #: find_nodata`): where it shows the scene, the no-data level and share
    low_nodata: NoData = field(default_factory=NoData.none, repr=False)
    high_nodata: NoData = field(default_factory=NoData.none, repr=False)

    @property
    def low_valid(self) -> Optional[np.ndarray]:
        """Where the first image shows the scene (None: everywhere)."""
        return self.low_nodata.valid

    @property
    def high_valid(self) -> Optional[np.ndarray]:
        """Where the second image shows the scene (None: everywhere)."""
        return self.high_nodata.valid

    def coarser_finer(self, direction: Direction) -> Tuple[np.ndarray, np.ndarray]:
        """(coarser, finer) images of ``direction``."""
        return direction.coarser_finer(self.low, self.high)

    def valid(self, direction: Direction) -> Tuple[Optional[np.ndarray], Optional[np.ndarray]]:
        """(coarser, finer) valid masks of ``direction`` (None: the image shows the scene
        everywhere)."""
        return direction.coarser_finer(self.low_valid, self.high_valid)

    def shown(self, direction: Direction) -> Tuple[np.ndarray, np.ndarray]:
        """(coarser, finer) images of ``direction`` with NaN where they show no scene, for the
        pixel tests (:func:`scalematch.stages.nodata.with_nan`)."""
        (lo, hi), (lv, hv) = self.coarser_finer(direction), self.valid(direction)
        return with_nan(lo, lv), with_nan(hi, hv)


def shown_scale(work: "WorkImages", direction: Direction) -> float:
    """Factor from a direction's working scales to the scales of the images given: a row's scale
    is finer px per coarser px, so original = working * f_finer / f_coarser."""
    return work.f_high / work.f_low if direction is Direction.GIVEN else work.f_low / work.f_high


def decode_sides(config) -> Tuple[Optional[int], Optional[int]]:
    """The longer side (px) the low and the high image may be decoded down to, at least
    (``scalematch.imageio.read_reduced``): their working sizes; None (full size) for the high
    image unless the order is automatic, as :func:`at_working_size` shrinks it."""
    return config.low_max_side, config.high_max_side if config.order == "auto" else None


def at_working_size(low: np.ndarray, high: np.ndarray, config,
                    decoded_factors: Tuple[float, float] = (1.0, 1.0)) -> WorkImages:
    """``low`` and ``high`` (checked float32 grey levels) at their working sizes.

    The high image is shrunk only with ``config.order == "auto"``: shrinking can make it the
    coarser one, which only the automatic order then finds. ``decoded_factors``: each image given is
    already its original shrunk by this factor (a JPEG decoded at a reduced size, the same
    centre-aligned map); the factors recorded are then from the originals.
    """
    d_low, d_high = (float(f) for f in decoded_factors)
    if d_high != 1.0 and config.order != "auto":
        raise ValueError("the high image may be given reduced only with order 'auto' "
                         "(decode_sides)")
    f_low = working_factor(low.shape, config.low_max_side)
    f_high = working_factor(high.shape, config.high_max_side) if config.order == "auto" else 1.0
    t_low, t_high = f_low * d_low, f_high * d_high
    low = shrink(low, f_low) if f_low > 1.0 else low
    high = shrink(high, f_high) if f_high > 1.0 else high
    return WorkImages(low, high, t_low, t_high, direction_scales(config.scales, t_low, t_high),
                      find_nodata(low, config.nodata), find_nodata(high, config.nodata))


def direction_scales(scales: Sequence[float], f_low: float,
                     f_high: float) -> Dict[Direction, Tuple[float, ...]]:
    """The working scales of each search direction.

    A search direction's working ratio is its ratio in the original pixels times ``h``:
    ``h = f_low / f_high`` in the given direction, ``1 / h`` in the other. Each configured
    scale ``s`` (an original ratio) is searched at ``s * h`` in its direction when that is at
    least 1, and otherwise, the working finer image being then the coarser one, at
    ``1 / (s * h)`` in the other direction. So the configured ratios are searched, either way
    round, at the same spacing and with the same tolerance around each as at full size.

    >>> given, swapped = direction_scales((1.0, 2.0, 4.0, 8.0), 1.0, 4.0).values()
    >>> given, swapped
    ((1.0, 2.0), (2.0, 4.0, 8.0, 16.0, 32.0))
    >>> [round(s, 3) for s in direction_scales((1.0, 1.5, 3.0), 1.0, 1.2)[Direction.GIVEN]]
    [1.25, 2.5]
    """
    h = {Direction.GIVEN: f_low / f_high, Direction.SWAPPED: f_high / f_low}
    out: Dict[Direction, Dict[float, float]] = {d: {} for d in Direction}  # rounded -> exact
    for d in Direction:
        for s in scales:
            w = s * h[d]
            if w >= 1.0 - 1e-9:  # exact values: reported back, they give the configured scales
                out[d].setdefault(round(w, 6), max(w, 1.0))
            else:
                out[d.other].setdefault(round(1.0 / w, 6), 1.0 / w)
    return {d: tuple(sorted(v.values())) for d, v in out.items()}


def _to_original(f: float) -> np.ndarray:
    """S (2x3): working px -> original px of an image shrunk by ``f``."""
    return resize_map(f)


def _mapped(result, s_low: np.ndarray, s_high: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """(transform, inliers) of a matched ``result`` (or a ``Rejected`` candidate) with each
    image's pixels mapped by its map (2x3: ``s_low`` for the first image given, ``s_high`` for
    the second), the finer and coarser one as ``result.order`` says."""
    swapped = result.order == Direction.SWAPPED
    s_fine, s_coarse = (s_low, s_high) if swapped else (s_high, s_low)
    # in the original pixels of both images (working px -> original px: each image's S)
    t = model_of(result.model).carried(result.transform, s_fine, s_coarse)
    pts = np.asarray(result.inliers, np.float64).reshape(-1, 4)
    return t, np.hstack([apply(s_fine, pts[:, :2]), apply(s_coarse, pts[:, 2:4])])


def at_working_size_of(candidate, work: WorkImages) -> Tuple[np.ndarray, np.ndarray]:
    """(transform, inliers) of a candidate in the images' own pixels (a matched result or a
    ``Rejected``) at the working sizes of ``work``: :func:`in_original` undone."""
    return _mapped(candidate, resize_map(1.0 / work.f_low), resize_map(1.0 / work.f_high))


def _rejected_mapped(result: MatchResult, s_low: np.ndarray, s_high: np.ndarray,
                     turn: bool) -> MatchResult:
    """``result`` with its ``rejected`` candidate mapped as :func:`_mapped` maps a match (and,
    with ``turn``, turned round as ``finer_to_coarser`` turns one)."""
    rej = result.rejected
    if rej is None:
        return result
    t, inliers = _mapped(rej, s_low, s_high)
    swapped = rej.order == Direction.SWAPPED
    if turn:
        t, inliers, swapped = finer_to_coarser(t, inliers, swapped)
    return replace(result, rejected=replace(
        rej, transform=t, inliers=inliers,
        order=Direction.SWAPPED if swapped else Direction.GIVEN))


def in_original(result: MatchResult, work: WorkImages, config) -> MatchResult:
    """``result`` of a match on the images at their working sizes (``work``), in their
    original pixels.

    ``config`` is the configuration the caller asked for (recorded in the result). A match
    whose ratio in the original pixels is below 1 is turned round, as the pipeline does.
    """
    f_low, f_high = work.f_low, work.f_high
    if f_low == 1.0 and f_high == 1.0:
        return result
    g = shown_scale(work, result.evidence.search_order)
    rows = tuple(replace(r, s=r.s * g, ratio=r.ratio * g) for r in result.scales)
    # the evidence is in these pixels already (answer.evidence_of)
    out = replace(result, scales=rows, best_scale=result.best_scale * g, config=config)
    if not result.matched:
        return _rejected_mapped(out, _to_original(f_low), _to_original(f_high), turn=True)
    swapped = result.order == Direction.SWAPPED
    t, inliers = _mapped(result, _to_original(f_low), _to_original(f_high))
    # the shrinking can make the finer working image the coarser original one
    parts = model_of(result.model).parts
    t, inliers, swapped = finer_to_coarser(t, inliers, swapped, parts)
    ratio, angle, tr = parts(t, inliers[:, :2])
    return replace(out, transform=t, inliers=inliers, resolution_ratio=ratio,
                   rotation_deg=angle, translation=tr,
                   order=Direction.SWAPPED if swapped else Direction.GIVEN)


def in_decoded(result: MatchResult, f_low: float, f_high: float) -> MatchResult:
    """``result`` (in the files' pixels) with its transform and inliers in the pixels of the
    images as decoded, ``f_low`` and ``f_high`` times smaller than the files' (a JPEG decoded
    at a reduced size, :func:`scalematch.imageio.read_reduced`): what the pictures draw on
    them. The ratio, angle, translation and table stay the files'.

    >>> from scalematch.result import MatchResult
    >>> r = MatchResult(matched=True, model="similarity",
    ...                 transform=np.array([[0.25, 0, 100.0], [0, 0.25, 50.0]]),
    ...                 inliers=np.array([[0.0, 0.0, 100.0, 50.0]]))
    >>> d = in_decoded(r, 2.0, 1.0)   # the low image decoded at half size
    >>> d.transform.round(3).tolist(), d.inliers.round(3).tolist()
    ([[0.125, 0.0, 49.75], [0.0, 0.125, 24.75]], [[0.0, 0.0, 49.75, 24.75]])
    """
    if f_low == 1.0 and f_high == 1.0:
        return result
    if not result.matched or result.transform is None:
        return _rejected_mapped(result, invert(_to_original(f_low)),
                                invert(_to_original(f_high)), turn=False)
    t, inliers = _mapped(result, invert(_to_original(f_low)), invert(_to_original(f_high)))
    return replace(result, transform=t, inliers=inliers)


def read_pair(low_path, high_path, config, max_pixels: int = DEFAULT_MAX_PIXELS
              ) -> Tuple[Decoded, Decoded]:
    """The two image files of a match as the command line reads them: a JPEG far above its
    working size decoded at 1/2, 1/4 or 1/8 (:func:`decode_sides`,
    :func:`scalematch.imageio.read_reduced`). ``match(to_grey(low.image), to_grey(high.image),
    config, decoded_factors=(low.factor, high.factor))`` then answers in the files' pixels.
    ``ImageError`` for a file that cannot be used."""
    low_side, high_side = decode_sides(config)
    return (read_reduced(low_path, low_side, max_pixels=max_pixels),
            read_reduced(high_path, high_side, max_pixels=max_pixels))
