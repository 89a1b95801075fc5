"""Repeatability of the standard and the scale-adapted Harris detector against the zoom factor.

The paper's figure "repeatability" (section 3.3): the standard Harris detector (s = 1 on both
images) against the scale-adapted one (s = factor on the high-resolution image, s = 1 on the
low-resolution one), for scale factors 1 to 6. The paper reports the standard detector below 40 %
past a factor of 2 and the adapted one well above. This module measures it on real photos with
exact ground truth.

Protocol, for each photo and each factor r (all numbers are ``StudyParams`` fields):

* ``high`` = an 800x600 crop of the photo at full resolution: of 6 random positions (seeded)
  the most textured one, i.e. the largest mean gradient magnitude of the crop shrunk by 3
  (the middle of the factors measured). The same crop serves every factor of that photo.
* ``low`` = ``synthetic.zoom_warp(context, r, theta)``: the camera model (blur
  0.5*sqrt(r^2 - 1), then rotate by theta and shrink by r in one warp) applied to the crop
  enlarged by a context band of 16 low-resolution px (16 r high px) on each side, so that the
  low-resolution detector sees real image, not the canvas edge, all around the crop. theta is
  drawn uniformly in [-180, 180) per photo and factor (seeded), or fixed by ``angle_deg``.
* ``truth`` = the 2x3 similarity mapping a ``high`` pixel to a ``low`` pixel (crop offset composed
  with the warp), OpenCV pixel centres at integer coordinates.
* Points: ``detector.detect_one`` with the *same* ``HarrisParams`` for all three detections (the
  library defaults with the absolute threshold, ``contrast_relative`` off: threshold 100 on the
  s^4-normalised cornerness, NMS radius 2 s px, cap 6000 points per scale): standard = s = 1 on
  ``high`` and on ``low``; adapted = s = r on ``high`` and s = 1 on ``low`` (the low-resolution
  points are the same for both).
* Common region (Schmid, Mohr & Bauckhage 2000): a point of one image counts only when its true
  position in the other image lies inside that image, at least ``margin_low_px`` = 6 low px
  (3 sigma~, the integration Gaussian's support at s = 1 in ``low`` and at s = r in ``high``)
  from its border. The same region serves both detectors.
* Repeatability (Schmid et al. 2000): the number of point pairs, one to one, whose distance in
  ``low`` after mapping the ``high`` point by the truth is at most eps = 1.5 low px, over
  min(n_high_common, n_low_common).

The measure rewards density: with ``n`` random points per low px^2 a point finds a partner within
eps by chance with probability about ``1 - exp(-n pi eps^2)``. The standard detector at s = 1
keeps about r^2 times more ``high`` points per low px^2 than the adapted one, so the raw measure
credits it with chance coincidences. The study therefore reports two figures per detector:

* ``raw``: the measure above, on every detected point in the common region (Schmid et al. 2000
  as written);
* ``equal``: the same measure after keeping, in each image, only the ``n`` strongest points of the
  common region, ``n = min(n_high_common, n_low_common)``: both images then have the same number
  of points in the same region, and chance coincidences are as likely in either direction.

Run it: ``python -m scalematch.lab.repeatability --out-dir OUT`` (or ``scalematch repeatability``).
"""

from __future__ import annotations

import csv
import io
import json
import math
import time
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, List, Optional, Sequence, Tuple, Union

import click
import cv2
import numpy as np

from ..geometry import apply, compose
from ..stages.detector import HarrisParams, detect, detect_one
from .datasets import load_photo, study_photos
from .synthetic import most_textured_crop, zoom_warp

PathLike = Union[str, Path]

#: Scale factors of the study: the paper's figure spans 1 to 6.
DEFAULT_FACTORS = (1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0)
#: Repeatability tolerance, low-resolution px (Schmid, Mohr & Bauckhage 2000: eps = 1.5).
EPS_PX = 1.5


@dataclass(frozen=True)
class StudyParams:
    """Every number the study depends on; recorded with its results."""

    crop_w: int = 800  #: high-resolution crop width, px (the brief: 800x600 at full resolution)
    crop_h: int = 600  #: high-resolution crop height, px
    n_positions: int = 6  #: random crop positions tried, most textured kept (EVALUATION.md: 6)
    texture_shrink: float = 3.0  #: crop shrunk by this before measuring texture (mid factor)
    eps: float = EPS_PX  #: repeatability tolerance, low px (Schmid et al. 2000)
    #: common-region margin, low px: 3 sigma~ = 6, the support of the integration Gaussian of the
    #: low detector at s = 1 (and of the adapted high detector at s = r, in low px)
    margin_low_px: float = 6.0
    #: context band around the crop that goes into ``low``, low px (>= margin + 3 sigma~ + blur)
    context_low_px: float = 16.0
    angle_deg: Optional[float] = None  #: rotation of ``low``; None = uniform in [-180, 180)
    #: same for every detection: the paper's absolute threshold (``HarrisParams()`` follows the
    #: image's contrast)
    harris: HarrisParams = field(default_factory=lambda: HarrisParams(contrast_relative=False,
                                                                          min_points=0))

    def __post_init__(self) -> None:
        if self.crop_w < 64 or self.crop_h < 64:
            raise ValueError(f"crop must be at least 64x64 px, got {self.crop_w}x{self.crop_h}")
        if self.eps <= 0:
            raise ValueError(f"eps must be > 0 px, got {self.eps}")


@dataclass(frozen=True)
class PairMeasure:
    """Repeatability of both detectors on one photo at one factor."""

    photo: str  #: file name
    factor: float  #: zoom ratio r (high px per low px)
    angle_deg: float  #: rotation of ``low``
    n_low: int  #: low-resolution points in the common region (s = 1)
    n_high_standard: int  #: high-resolution points in the common region at s = 1
    n_high_adapted: int  #: high-resolution points in the common region at s = r
    standard_raw: float  #: repeatability, every point (nan when a side has none)
    adapted_raw: float
    standard_equal: float  #: repeatability, equal number of points on both sides
    adapted_equal: float
    #: what random points would score (``chance_repeatability``), for each of the four figures
    chance_standard_raw: float = float("nan")
    chance_adapted_raw: float = float("nan")
    chance_standard_equal: float = float("nan")
    chance_adapted_equal: float = float("nan")


@dataclass(frozen=True)
class FactorRow:
    """Means over photos at one factor (nan-valued photos left out of the mean)."""

    factor: float
    standard_raw: float
    adapted_raw: float
    standard_equal: float
    adapted_equal: float
    n_photos: int  #: photos with a value at this factor
    chance_standard_raw: float = float("nan")  #: chance level of ``standard_raw``
    chance_standard_equal: float = float("nan")  #: chance level of ``standard_equal``
    chance_adapted_equal: float = float("nan")  #: chance level of ``adapted_equal``
    standard_equal_max: float = float("nan")  #: ``standard_equal`` of the best photo
    adapted_equal_min: float = float("nan")  #: ``adapted_equal`` of the worst photo


@dataclass(frozen=True)
class StudyTable:
    """The study's result: per-factor means, per-pair measures, and what produced them."""

    rows: Tuple[FactorRow, ...]
    pairs: Tuple[PairMeasure, ...] = field(repr=False)
    photos: Tuple[str, ...]  #: photos measured (file names)
    skipped: Tuple[Tuple[str, str], ...]  #: (photo, reason) for photos that could not be used
    seed: int
    params: StudyParams = field(repr=False)
    seconds: float = 0.0


# --------------------------------------------------------------------------------------------
# The measure
# --------------------------------------------------------------------------------------------

def _scale_of(truth: np.ndarray) -> float:
    """Length scale of a 2x3 similarity/affine (low px per high px): sqrt|det|."""
    return math.sqrt(abs(float(np.linalg.det(np.asarray(truth, float)[:2, :2]))))


def inside(xy: np.ndarray, shape: Tuple[int, ...], margin: float = 0.0) -> np.ndarray:
    """(N,) bool: points (x, y) at least ``margin`` px inside an image of ``shape`` (H, W)."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    h, w = int(shape[0]), int(shape[1])
    return ((xy[:, 0] >= margin) & (xy[:, 0] <= w - 1 - margin)
            & (xy[:, 1] >= margin) & (xy[:, 1] <= h - 1 - margin))


def common_masks(high_xy: np.ndarray, low_xy: np.ndarray, truth: np.ndarray,
                 high_shape: Tuple[int, ...], low_shape: Tuple[int, ...],
                 margin: float = 0.0) -> Tuple[np.ndarray, np.ndarray]:
    """Which points lie in the region both images see.

    Parameters
    ----------
    high_xy : (N, 2) array
        Points of the high-resolution image, (x, y) px.
    low_xy : (M, 2) array
        Points of the low-resolution image, (x, y) px.
    truth : (2, 3) array
        High px -> low px.
    high_shape, low_shape : tuple
        (H, W, ...) of each image.
    margin : float
        Distance from the other image's border, in low px (``margin / scale`` in high px).

    Returns
    -------
    (N,) bool array, (M,) bool array
        A high point counts when its mapped position is inside ``low``, a low point when its
        back-mapped position is inside ``high``, both at least ``margin`` from the border.
    """
    truth = np.asarray(truth, dtype=np.float64)
    back = cv2.invertAffineTransform(truth)
    k = _scale_of(truth)
    mh = inside(apply(truth, high_xy), low_shape, margin)
    ml = inside(apply(back, low_xy), high_shape, margin / k if k > 0 else 0.0)
    return mh, ml


def pairs_within(a: np.ndarray, b: np.ndarray, eps: float, chunk: int = 1024) -> int:
    """Closest-first greedy one-to-one pairing of ``a`` and ``b`` points within ``eps`` px.

    Parameters
    ----------
    a : (N, 2) array
    b : (M, 2) array
    eps : float
        Pairing distance, px.

    Returns
    -------
    int
        The number of pairs (each point in at most one), formed closest first; <= min(N, M).
        Greedy, as in the usual implementations of the measure: a maximum matching could find a
        few more pairs where points crowd within ``eps`` of each other.
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
    if a.shape[0] == 0 or b.shape[0] == 0:
        return 0
    order = np.argsort(b[:, 0], kind="stable")
    bs = b[order]
    ia_all, ib_all, d_all = [], [], []
    for start in range(0, a.shape[0], chunk):
        pa = a[start:start + chunk]
        lo = np.searchsorted(bs[:, 0], pa[:, 0].min() - eps, "left")
        hi = np.searchsorted(bs[:, 0], pa[:, 0].max() + eps, "right")
        if hi <= lo:
            continue
        d = np.linalg.norm(pa[:, None, :] - bs[None, lo:hi, :], axis=2)
        ia, ib = np.nonzero(d <= eps)
        ia_all.append(ia + start)
        ib_all.append(ib + lo)
        d_all.append(d[ia, ib])
    if not ia_all:
        return 0
    ia = np.concatenate(ia_all)
    ib = np.concatenate(ib_all)
    dist = np.concatenate(d_all)
    used_a = np.zeros(a.shape[0], bool)
    used_b = np.zeros(b.shape[0], bool)
    count = 0
    for k in np.argsort(dist, kind="stable"):
        if not used_a[ia[k]] and not used_b[ib[k]]:
            used_a[ia[k]] = used_b[ib[k]] = True
            count += 1
    return count


def repeatability(high_xy: np.ndarray, low_xy: np.ndarray, truth: np.ndarray,
                  high_shape: Tuple[int, ...], low_shape: Tuple[int, ...],
                  eps: float = EPS_PX, margin: float = 0.0) -> float:
    """Repeatability rate of Schmid, Mohr & Bauckhage (2000) between a high and a low image.

    Parameters
    ----------
    high_xy : (N, 2) array
        Points detected in the high-resolution image, (x, y) px.
    low_xy : (M, 2) array
        Points detected in the low-resolution image, (x, y) px.
    truth : (2, 3) array
        The true transform, high px -> low px.
    high_shape, low_shape : tuple
        (H, W, ...) of each image.
    eps : float
        A pair repeats when the mapped high point is within ``eps`` low px of the low point.
    margin : float
        Common-region margin in low px (see ``common_masks``).

    Returns
    -------
    float
        repeated / min(n_high_common, n_low_common) in [0, 1], pairs counted one to one;
        nan when either image has no point in the common region.
    """
    high_xy = np.asarray(high_xy, dtype=np.float64).reshape(-1, 2)
    low_xy = np.asarray(low_xy, dtype=np.float64).reshape(-1, 2)
    truth = np.asarray(truth, dtype=np.float64)
    if truth.shape != (2, 3):
        raise ValueError(f"truth must be a 2x3 affine (high px -> low px), got {truth.shape}")
    mh, ml = common_masks(high_xy, low_xy, truth, high_shape, low_shape, margin)
    n = min(int(mh.sum()), int(ml.sum()))
    if n == 0:
        return float("nan")
    return pairs_within(apply(truth, high_xy[mh]), low_xy[ml], eps) / n


def strongest(xy: np.ndarray, response: np.ndarray, n: int) -> np.ndarray:
    """The ``n`` points of largest response, (n, 2) (all of them when fewer)."""
    order = np.argsort(-np.asarray(response), kind="stable")[:max(int(n), 0)]
    return np.asarray(xy).reshape(-1, 2)[order]


def chance_repeatability(n_high: int, n_low: int, area: float, eps: float = EPS_PX) -> float:
    """Repeatability that points scattered at random would reach by coincidence.

    With ``max(n_high, n_low)`` points spread uniformly over ``area`` low px^2, a point of the
    smaller set has a partner within ``eps`` with probability ``1 - exp(-max * pi eps^2 / area)``
    (Poisson); that is the expected value of the measure, whose denominator is the smaller set.
    nan when a set is empty or the area is not positive.
    """
    if min(n_high, n_low) <= 0 or area <= 0:
        return float("nan")
    return 1.0 - math.exp(-max(n_high, n_low) * math.pi * eps * eps / area)


def equal_budget_repeatability(high_xy: np.ndarray, high_resp: np.ndarray, low_xy: np.ndarray,
                               low_resp: np.ndarray, truth: np.ndarray,
                               high_shape: Tuple[int, ...], low_shape: Tuple[int, ...],
                               eps: float = EPS_PX, margin: float = 0.0) -> float:
    """``repeatability`` after keeping the same number of strongest points in both images.

    Each image keeps its ``n = min(n_high_common, n_low_common)`` strongest points of the common
    region, so chance coincidences within ``eps`` are equally likely either way. Same arguments
    as ``repeatability`` plus the (N,) and (M,) responses; nan when a side has no point.
    """
    high_xy = np.asarray(high_xy, dtype=np.float64).reshape(-1, 2)
    low_xy = np.asarray(low_xy, dtype=np.float64).reshape(-1, 2)
    mh, ml = common_masks(high_xy, low_xy, truth, high_shape, low_shape, margin)
    n = min(int(mh.sum()), int(ml.sum()))
    if n == 0:
        return float("nan")
    h = strongest(high_xy[mh], np.asarray(high_resp)[mh], n)
    lo = strongest(low_xy[ml], np.asarray(low_resp)[ml], n)
    return pairs_within(apply(truth, h), lo, eps) / n


# --------------------------------------------------------------------------------------------
# Pairs with exact ground truth
# --------------------------------------------------------------------------------------------

def choose_crop(photo: np.ndarray, size: Tuple[int, int], pad: int, n_positions: int,
                shrink: float, rng: np.random.Generator) -> Tuple[int, int, int, int]:
    """(x0, y0, w, h): the most textured of ``n_positions`` random crops, ``pad`` px inside.

    The crop is shrunk to fit when the photo is too small for ``size`` plus the padding; a
    ``ValueError`` says so when it would be under 64 px.
    """
    ph, pw = photo.shape[:2]
    w = min(int(size[0]), pw - 2 * pad)
    h = min(int(size[1]), ph - 2 * pad)
    if w < 64 or h < 64:
        raise ValueError(f"photo {pw}x{ph} too small for a crop with a {pad} px context band")
    return most_textured_crop(photo, (w, h), (pad, pad), n_positions, shrink, rng)


def make_pair(photo: np.ndarray, crop: Tuple[int, int, int, int], factor: float,
              angle_deg: float, context_low_px: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(high, low, truth) for one photo, crop and factor.

    ``high`` is ``photo[y0:y0+h, x0:x0+w]``; ``low`` is ``zoom_warp`` of the crop enlarged by
    ``context_low_px * factor`` px on each side (clipped to the photo); ``truth`` (2x3) maps a
    ``high`` pixel to a ``low`` pixel.
    """
    x0, y0, w, h = crop
    ph, pw = photo.shape[:2]
    pad = int(math.ceil(context_low_px * factor))
    cx0, cy0 = max(x0 - pad, 0), max(y0 - pad, 0)
    cx1, cy1 = min(x0 + w + pad, pw), min(y0 + h + pad, ph)
    high = np.ascontiguousarray(photo[y0:y0 + h, x0:x0 + w])
    context = np.ascontiguousarray(photo[cy0:cy1, cx0:cx1])
    low, a = zoom_warp(context, factor, angle_deg)
    shift = np.array([[1.0, 0.0, x0 - cx0], [0.0, 1.0, y0 - cy0]])
    return high, low, compose(a, shift)


def _photo_rng(seed: int, name: str, *extra: int) -> np.random.Generator:
    """A generator that depends on the seed and the photo's name only (not on the list)."""
    return np.random.default_rng([int(seed), zlib.crc32(name.encode("utf-8")), *extra])


def measure_photo(photo: np.ndarray, name: str, factors: Sequence[float], seed: int,
                  params: StudyParams = StudyParams()) -> List[PairMeasure]:
    """Both detectors' repeatability on one photo at every factor (see the module docstring)."""
    pad = int(math.ceil(params.context_low_px * max(factors)))
    crop = choose_crop(photo, (params.crop_w, params.crop_h), pad, params.n_positions,
                       params.texture_shrink, _photo_rng(seed, name))
    x0, y0, w, h = crop
    high = np.ascontiguousarray(photo[y0:y0 + h, x0:x0 + w])
    hp = params.harris
    scales = sorted(set([1.0] + [float(f) for f in factors]))
    at_scale = {kp.s: kp for kp in detect(high, scales, hp)}
    out = []
    for r in factors:
        r = float(r)
        if params.angle_deg is None:
            angle = float(_photo_rng(seed, name, 1, int(round(r * 1000))).uniform(-180.0, 180.0))
        else:
            angle = float(params.angle_deg)
        _, low, truth = make_pair(photo, crop, r, angle, params.context_low_px)
        kl = detect_one(low, 1.0, hp)
        ks, ka = at_scale[1.0], at_scale[r]
        args = (truth, high.shape, low.shape)
        kw = dict(eps=params.eps, margin=params.margin_low_px)
        ms, ml = common_masks(ks.xy, kl.xy, *args, margin=params.margin_low_px)
        ma, _ = common_masks(ka.xy, kl.xy, *args, margin=params.margin_low_px)
        k = _scale_of(truth)
        area = (w * k - 2 * params.margin_low_px) * (h * k - 2 * params.margin_low_px)
        n_l, n_s, n_a = int(ml.sum()), int(ms.sum()), int(ma.sum())
        eq_s, eq_a = min(n_s, n_l), min(n_a, n_l)
        out.append(PairMeasure(
            photo=name, factor=r, angle_deg=angle, n_low=n_l,
            n_high_standard=n_s, n_high_adapted=n_a,
            standard_raw=repeatability(ks.xy, kl.xy, *args, **kw),
            adapted_raw=repeatability(ka.xy, kl.xy, *args, **kw),
            standard_equal=equal_budget_repeatability(ks.xy, ks.response, kl.xy, kl.response,
                                                      *args, **kw),
            adapted_equal=equal_budget_repeatability(ka.xy, ka.response, kl.xy, kl.response,
                                                     *args, **kw),
            chance_standard_raw=chance_repeatability(n_s, n_l, area, params.eps),
            chance_adapted_raw=chance_repeatability(n_a, n_l, area, params.eps),
            chance_standard_equal=chance_repeatability(eq_s, eq_s, area, params.eps),
            chance_adapted_equal=chance_repeatability(eq_a, eq_a, area, params.eps)))
    return out


# --------------------------------------------------------------------------------------------
# The study over photos
# --------------------------------------------------------------------------------------------

def _mean(values: Sequence[float]) -> float:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else float("nan")


def _extreme(values: Sequence[float], fn) -> float:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(fn(v)) if v.size else float("nan")


def summarise(pairs: Sequence[PairMeasure], factors: Sequence[float]) -> Tuple[FactorRow, ...]:
    """Per-factor means over photos (photos where a value is nan are left out of that mean)."""
    rows = []
    for r in factors:
        at = [p for p in pairs if abs(p.factor - float(r)) < 1e-9]
        ok = [p for p in at if math.isfinite(p.standard_raw) and math.isfinite(p.adapted_raw)]
        rows.append(FactorRow(
            factor=float(r),
            standard_raw=_mean([p.standard_raw for p in at]),
            adapted_raw=_mean([p.adapted_raw for p in at]),
            standard_equal=_mean([p.standard_equal for p in at]),
            adapted_equal=_mean([p.adapted_equal for p in at]),
            n_photos=len(ok),
            chance_standard_raw=_mean([p.chance_standard_raw for p in at]),
            chance_standard_equal=_mean([p.chance_standard_equal for p in at]),
            chance_adapted_equal=_mean([p.chance_adapted_equal for p in at]),
            standard_equal_max=_extreme([p.standard_equal for p in at], np.max),
            adapted_equal_min=_extreme([p.adapted_equal for p in at], np.min)))
    return tuple(rows)


def run_study(photo_paths: Sequence[PathLike], factors: Sequence[float] = DEFAULT_FACTORS,
              seed: int = 0, params: StudyParams = StudyParams(),
              progress: Optional[Callable[[str], None]] = None) -> StudyTable:
    """Repeatability of the standard and the adapted Harris detector on every photo and factor.

    Parameters
    ----------
    photo_paths : sequence of path
        Photos to cut pairs from (any format ``read_grey`` reads).
    factors : sequence of float
        Zoom factors r >= 1.
    seed : int
        The one seed: crop positions and rotations depend on it and on each photo's file name.
    params : StudyParams
    progress : callable, optional
        Called with the name of each photo as it starts (for a progress display).

    Returns
    -------
    StudyTable
        Per-factor means and per-pair measures; unreadable or too small photos are listed in
        ``skipped`` with the reason, not raised.
    """
    factors = tuple(float(f) for f in factors)
    if not factors or min(factors) < 1.0:
        raise ValueError(f"factors must be a non-empty list of values >= 1, got {factors}")
    t0 = time.perf_counter()
    pairs: List[PairMeasure] = []
    used, skipped = [], []
    for path in photo_paths:
        name = Path(path).name
        if progress is not None:
            progress(name)
        try:
            photo = load_photo(path)
            pairs.extend(measure_photo(photo, name, factors, seed, params))
            used.append(name)
        except ValueError as err:  # ImageError is a ValueError; so is a photo too small
            skipped.append((name, str(err)))
    return StudyTable(rows=summarise(pairs, factors), pairs=tuple(pairs), photos=tuple(used),
                      skipped=tuple(skipped), seed=int(seed), params=params,
                      seconds=time.perf_counter() - t0)


# --------------------------------------------------------------------------------------------
# Output: text table, CSV, plot
# --------------------------------------------------------------------------------------------

def _pct(v: float) -> str:
    return "   -" if not math.isfinite(v) else f"{100 * v:4.0f}"


def format_table(table: StudyTable) -> str:
    """The per-factor table as aligned text, repeatability in percent."""
    lines = ["        |  all points (raw)  |  equal budget      |  chance level      | equal, photo  |",
             " factor | standard  adapted  | standard  adapted  | std raw  equal std | std    adapt  |"
             " photos",
             " (r)    |   mean      mean   |   mean      mean   |   mean     mean    | best   worst  |",
             "--------+--------------------+--------------------+--------------------+---------------+"
             "-------"]
    for r in table.rows:
        lines.append(f" {r.factor:6.2f} |   {_pct(r.standard_raw)}     {_pct(r.adapted_raw)}    |"
                     f"   {_pct(r.standard_equal)}     {_pct(r.adapted_equal)}    |"
                     f"   {_pct(r.chance_standard_raw)}     {_pct(r.chance_standard_equal)}     |"
                     f" {_pct(r.standard_equal_max)}   {_pct(r.adapted_equal_min)}   |"
                     f" {r.n_photos:5d}")
    lines.append("(repeatability in %; chance = what random points would score; best/worst = the "
                 "photo most favourable to standard / least favourable to adapted)")
    return "\n".join(lines)


def table_csv(table: StudyTable) -> str:
    """Per-factor rows as CSV (fractions in [0, 1])."""
    buf = io.StringIO()
    wr = csv.writer(buf, lineterminator="\n")
    names = list(FactorRow.__dataclass_fields__)
    wr.writerow(names)
    for r in table.rows:
        wr.writerow([f"{v:.4f}" if isinstance(v, float) else v for v in
                     (getattr(r, n) for n in names)])
    return buf.getvalue()


def pairs_csv(table: StudyTable) -> str:
    """Per photo and factor measures as CSV."""
    buf = io.StringIO()
    names = list(PairMeasure.__dataclass_fields__)
    wr = csv.writer(buf, lineterminator="\n")
    wr.writerow(names)
    for p in table.pairs:
        wr.writerow([f"{v:.4f}" if isinstance(v, float) else v for v in
                     (getattr(p, n) for n in names)])
    return buf.getvalue()


def plot_table(table: StudyTable, path: Optional[PathLike] = None) -> np.ndarray:
    """The paper's figure: repeatability (%) against the factor, both detectors, both budgets."""
    from .plot import line_chart

    x = [r.factor for r in table.rows]
    pct = lambda attr: [100 * getattr(r, attr) for r in table.rows]  # noqa: E731
    series = {
        "adapted, equal budget (s = factor)": (x, pct("adapted_equal")),
        "standard, equal budget (s = 1)": (x, pct("standard_equal")),
        "adapted, raw (s = factor)": (x, pct("adapted_raw")),
        "standard, raw (s = 1)": (x, pct("standard_raw")),
        "chance level of standard, raw": (x, pct("chance_standard_raw")),
        "paper: standard < 40% past 2": ([min(x), max(x)] if x else [], [40.0, 40.0] if x else []),
    }
    n = len(table.photos)
    return line_chart(series, path,
                      f"Harris repeatability against scale factor ({n} photo{'s' * (n != 1)}, "
                      f"eps {table.params.eps:g} px, seed {table.seed})",
                      "scale factor r (high-res px per low-res px)", "repeatability (%)",
                      ylim=(0, 100), xticks=x)


def write_outputs(table: StudyTable, out_dir: PathLike) -> List[Path]:
    """Write repeatability.csv, repeatability_pairs.csv, repeatability.json and .png."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = [out / "repeatability.csv", out / "repeatability_pairs.csv",
             out / "repeatability.json", out / "repeatability.png"]
    files[0].write_text(table_csv(table))
    files[1].write_text(pairs_csv(table))
    meta = {"seed": table.seed, "params": asdict(table.params), "photos": list(table.photos),
            "skipped": [list(s) for s in table.skipped], "seconds": round(table.seconds, 1),
            "rows": [asdict(r) for r in table.rows]}
    files[2].write_text(json.dumps(meta, indent=2, default=float,
                                   allow_nan=True).replace("NaN", "null") + "\n")
    plot_table(table, files[3])
    return files


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------

def _parse_factors(text: str) -> Tuple[float, ...]:
    try:
        vals = tuple(float(t) for t in text.replace(" ", "").split(",") if t)
    except ValueError:
        raise click.BadParameter(f"expected numbers separated by commas, got {text!r}")
    if not vals or min(vals) < 1.0:
        raise click.BadParameter(f"factors must be >= 1, got {text!r}")
    return vals


@click.command("repeatability")
@click.argument("images", nargs=-1, type=click.Path(exists=True, dir_okay=False))
@click.option("--photos", "n_photos", type=click.IntRange(min=1), default=None,
              help="Use only the first N photos (sorted by name).")
@click.option("--factors", default=",".join(f"{f:g}" for f in DEFAULT_FACTORS),
              show_default=True, help="Zoom factors, comma-separated, each >= 1.")
@click.option("--seed", type=int, default=0, show_default=True,
              help="The one seed (crop positions, rotations).")
@click.option("--angle", type=float, default=None,
              help="Rotate every low image by this many degrees [default: random per pair].")
@click.option("--crop", default="800x600", show_default=True,
              help="High-resolution crop size WxH, px.")
@click.option("--out-dir", type=click.Path(file_okay=False), default="repeatability_out",
              show_default=True, help="Where to write the CSVs, JSON and PNG.")
@click.option("--silent", is_flag=True, help="No progress messages.")
def repeatability_command(images, n_photos, factors, seed, angle, crop, out_dir, silent):
    """Repeatability of standard vs scale-adapted Harris against the zoom factor.

    IMAGES are photos to cut synthetic zoom pairs from (default: the photos of the shared
    folder, $SCALEMATCH_SHARED or <repo>/../shared). Prints the table and writes
    repeatability.csv, repeatability_pairs.csv, repeatability.json and repeatability.png
    to --out-dir.

    Example: scalematch lab repeatability --photos 10 --out-dir out
    """
    fac = _parse_factors(factors)
    try:
        cw, ch = (int(v) for v in crop.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"expected WxH such as 800x600, got {crop!r}",
                                 param_hint="--crop")
    try:
        params = StudyParams(crop_w=cw, crop_h=ch, angle_deg=angle)
    except ValueError as err:
        raise click.BadParameter(str(err), param_hint="--crop")
    paths, progress = study_photos(images, n_photos, silent)
    table = run_study(paths, fac, seed, params, progress)
    for name, reason in table.skipped:
        click.echo(f"skipped {name}: {reason}", err=True)
    if not table.photos:
        raise click.ClickException("no photo could be used (see the messages above)")
    click.echo(format_table(table))
    files = write_outputs(table, out_dir)
    click.echo(f"{len(table.photos)} photos, seed {seed}, {table.seconds:.0f} s; wrote "
               + ", ".join(str(f) for f in files))


if __name__ == "__main__":
    repeatability_command()
