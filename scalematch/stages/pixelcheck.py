"""A check with the pixels (paper eq. 3 and 5: grey-level correlation after the map).

The high image, blurred for its resolution ratio ``r`` (the camera model of EVALUATION.md: a
Gaussian of std ``0.5 sqrt(r^2 - 1)`` high px before shrinking by ``r``), is warped by the
hypothesis onto its footprint in the low image, and the two are compared by zero-mean normalised
cross-correlation (ZNCC) over the pixels they share. The same is measured for nearby wrong
placements -- the hypothesis shifted by a fraction of the footprint's size along each axis,
turned by a few degrees about the footprint's centre, and scaled by the neighbouring scale
steps ``2^(+-1/3)`` -- so the figure reads "how much better than nearby wrong answers" and does
not depend on how many corners the scene has.

Why plain ZNCC: the low image differs from the warped high one by a grey-level gain and offset
(EVALUATION.md step 2) and noise; ZNCC is exactly invariant to the former and averages the
latter over the whole footprint. Its weakness, a high score for any placement over a smooth
shading or one strong edge that both images share, is what the comparison with the perturbed
placements removes: those share the shading too, so the *margin* is small unless the fine
structure lines up.

Cheap by construction: the high image is first shrunk by an integer factor ``k ~ r / 2`` with
``cv2.INTER_AREA`` (a box filter) and blurred by the rest of the camera blur on the small copy;
all placements are warped only onto the bounding box of the footprints in the low image, at the
low image's resolution.

Where the pixels are compared: only where both images show the scene (NaN marks the rest: a
no-data canvas, :mod:`scalematch.stages.nodata`), and for the uniqueness test only near the
inliers (``vouch_radius``): an occluder, a foreground object or a 3-D scene's other planes hold
no inlier, and one ZNCC over the whole footprint would count them against a true map.

Pixel convention: OpenCV's, (x, y), pixel centres at integers. Used by the decision's second
look and by the pixel tests of every match's final map (:mod:`scalematch.stages.decision`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import ClassVar, Mapping, NamedTuple, Optional, Tuple, Union

import cv2
import numpy as np

from ..checks import ANGLE, AT_LEAST_ONE, Bounds, CORRELATION, COUNT, FACTOR, NON_NEGATIVE, POSITIVE, check_bounds
from ..geometry import apply, as_matrix3, footprint, ratio_at, similarity_matrix


@dataclass(frozen=True)
class PixelParams:
    """The pixel check; lengths in low-resolution px unless said otherwise."""

    #: shift of the perturbed placements, fraction of the footprint's size (sqrt of its area):
    #: a quarter moves every pixel well past the correlation length of the fine structure
    #: while keeping 3/4 of the footprint over the same region (the same shading)
    shift_fraction: float = 0.25
    #: turn of the perturbed placements about the footprint's centre, degrees: at a 60 px
    #: footprint (ratio 10-16) 10 degrees moves its edge by 5 px, beyond the 3 px inlier threshold
    rotation_deg: float = 10.0
    #: scale factor of the perturbed placements: the neighbouring scales of the search
    #: (Config.scales are third octaves, 2^(1/3))
    scale_step: float = 2.0 ** (1.0 / 3.0)
    #: fewest low pixels shared by the warped high image and the low image; fewer: "cannot
    #: tell" (nan). 256 = a 16x16 patch, the descriptor's window (GradientParams: 16 px)
    min_overlap_px: int = 256
    #: smallest grey-level std of either image over the overlap, grey levels: below, the region
    #: is flat and correlation means nothing (nan). Small enough for a 12-bit image read as
    #: 0-15 grey levels (textured regions: std ~1)
    min_std: float = 1e-3
    #: pixels of the warped image this close to its edge are left out (bilinear interpolation
    #: there mixes in the zero border)
    edge_px: int = 1
    #: a footprint larger than this (sqrt of its area, low px) is checked on the low image shrunk
    #: to it (cv2.INTER_AREA): 128 px leave 16k pixels to correlate, ample, and bound the cost
    #: at small ratios (a 320x240 footprint at ratio 2 otherwise warps 9 x 77k pixels)
    max_side_px: float = 128.0
    #: the same for the uniqueness test, which slides the footprint over the whole low image
    #: (its cost grows with the low image's area over this side squared). 64 px keep a 4k-pixel
    #: template, ample to tell a copy from the original (docs/design/DECISION.md, "What the
    #: pixel tests cost": the misfit ratios of true claims and of null claims, at 64 and 32 px)
    unique_side_px: float = 64.0
    #: the uniqueness test compares the pixels within this fraction of the footprint's size
    #: (sqrt of its area) of the inliers, where the points vouch for the map: an occluder, a
    #: foreground object or a 3-D scene's other planes hold no inlier and stay out. A quarter
    #: (16 px of a 64 px footprint) is twice the descriptor window's radius (8 of its 16 px
    #: at the point's scale), so most of what is compared was not what the descriptors matched
    vouch_radius: float = 0.25
    #: side of the windows of the agreement test (:func:`window_agreement`), px of the
    #: uniqueness test's template (``unique_side_px``): 8 tiles a 64 px template with 64
    #: windows, each half the descriptor window (16 px at the point's scale)
    window_px: int = 8
    #: a window agrees at a placement when its ZNCC there is at least this: measured on the
    #: occluded pairs and the null facades that reach the test, 0.8 separates the copy of a
    #: facade (a third to a half of its windows agree) from the scene itself (two thirds to
    #: nine tenths; docs/design/DECISION.md, "Windows that agree")
    window_ncc: float = 0.8
    #: distance from the claimed placement, a fraction of the template's shorter side, within
    #: which a correlation peak counts as the same placement (half a footprint: a copy of the
    #: structure elsewhere is at least that far away, or it would overlap the claim)
    unique_exclusion: float = 0.5
    #: camera blur the coarser image is taken to carry, in its own px: the finer image is
    #: blurred by this times sqrt(ratio^2 - 1) before it is compared (:func:`blurred_for_ratio`;
    #: the camera model of EVALUATION.md, as ``HarrisParams.camera_blur_px``)
    camera_blur_px: float = 0.5

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "shift_fraction": POSITIVE,
        "max_side_px": POSITIVE,
        "unique_side_px": POSITIVE,
        "vouch_radius": POSITIVE,
        "rotation_deg": ANGLE,
        "scale_step": FACTOR,
        "camera_blur_px": NON_NEGATIVE,
        "min_overlap_px": AT_LEAST_ONE,
        "min_std": NON_NEGATIVE,
        "edge_px": COUNT,
        "window_px": Bounds(lo=2, integer=True),
        "window_ncc": CORRELATION,
        "unique_exclusion": NON_NEGATIVE,
    }

    def __post_init__(self) -> None:
        check_bounds("pixel", self, self.BOUNDS)


@dataclass(frozen=True)
class PixelCheck:
    """ZNCC of a hypothesis and of its perturbed placements; nan values mean "cannot tell"."""

    ncc: float  #: ZNCC of the hypothesis over the overlap, in [-1, 1]
    best_perturbed: float  #: the highest ZNCC of the perturbed placements
    margin: float  #: ncc - best_perturbed (> 0: better than every nearby wrong placement)
    z: float  #: (ncc - mean of perturbed) / std of perturbed (std floored at 0.01)
    perturbed: Tuple[float, ...] = field(repr=False)  #: ZNCC of each perturbed placement
    overlap_px: int = 0  #: low px shared by the hypothesis' warp and the low image
    overlap_fraction: float = 0.0  #: overlap_px over the footprint's area
    reason: str = ""  #: why ncc is nan ("" when it is not)

    @property
    def decided(self) -> bool:
        """True when the check could measure the hypothesis and its neighbours."""
        return math.isfinite(self.margin)


def blurred_for_ratio(high: np.ndarray, ratio: float,
                      camera_blur_px: float = 0.5) -> Tuple[np.ndarray, int]:
    """The high image (h, w) with the camera blur of ``ratio``, on a copy shrunk by ``k``.

    Returns (small, k): ``small[y_s, x_s]`` is the high image blurred by
    ``camera_blur_px * sqrt(ratio^2 - 1)`` high px sampled at ``x = k x_s + (k - 1) / 2``
    (``cv2.INTER_AREA``'s centre-aligned box, variance ``(k^2 - 1) / 12`` high px^2, counted in
    the blur). ``k = max(1, floor(ratio / 2))`` keeps two small pixels per low pixel.
    """
    img = np.asarray(high, np.float32)
    r = max(float(ratio), 1.0)
    k = max(1, int(r // 2))
    h, w = img.shape
    k = min(k, max(1, min(h, w) // 8))
    if k > 1:
        img = cv2.resize(img[: (h // k) * k, : (w // k) * k], (w // k, h // k),
                         interpolation=cv2.INTER_AREA)
    total = camera_blur_px * math.sqrt(max(r * r - 1.0, 0.0))
    rest = math.sqrt(max(total * total - (k * k - 1) / 12.0, 0.0)) / k
    if rest > 0.05:
        img = cv2.GaussianBlur(img, (0, 0), rest, borderType=cv2.BORDER_REFLECT_101)
    return img, k


def quad_area(q: np.ndarray) -> float:
    """Area of a quadrilateral (4, 2) given in order (half the cross product of its diagonals)."""
    d1, d2 = q[2] - q[0], q[3] - q[1]
    return 0.5 * abs(float(d1[0] * d2[1] - d1[1] * d2[0]))


def small_to_high(k: int) -> np.ndarray:
    """3x3 map from the shrunk copy's px to high px: x = k x_s + (k - 1) / 2."""
    c = (k - 1) / 2.0
    return np.array([[k, 0.0, c], [0.0, k, c], [0.0, 0.0, 1.0]])


def zncc(a: np.ndarray, b: np.ndarray, min_std: float = PixelParams.min_std) -> float:
    """Zero-mean normalised cross-correlation of two equal-length samples (nan when flat).

    >>> x = np.arange(10.0)
    >>> zncc(x, 3 * x + 7), zncc(x, -x), zncc(x, np.ones(10))
    (1.0, -1.0, nan)
    """
    a = np.asarray(a, np.float64).ravel()
    b = np.asarray(b, np.float64).ravel()
    if a.size < 2:
        return float("nan")
    a = a - a.mean()
    b = b - b.mean()
    dot = lambda u, v: float(np.einsum("i,i->", u, v))  # noqa: E731 (no BLAS threads: small)
    sa, sb = math.sqrt(dot(a, a) / a.size), math.sqrt(dot(b, b) / b.size)
    if not (sa > min_std and sb > min_std):
        return float("nan")
    return float(round(dot(a, b) / (a.size * sa * sb), 12))


def perturbations(t: np.ndarray, high_shape: Tuple[int, int],
                  params: PixelParams = PixelParams()) -> Tuple[np.ndarray, ...]:
    """The nearby wrong placements of ``t`` (each a 3x3 finer px -> coarser px map).

    Four shifts (+-x, +-y) by ``shift_fraction`` of the footprint's size, two turns by
    ``+-rotation_deg`` and two scalings by ``scale_step^+-1`` about the footprint's centre.
    """
    t3 = as_matrix3(t)
    h, w = high_shape[:2]
    centre = apply(t3, [[(w - 1) / 2.0, (h - 1) / 2.0]])[0]
    corners = footprint(t3, (h, w))
    area = quad_area(corners) if corners is not None else 0.0
    step = params.shift_fraction * math.sqrt(max(area, 0.0))
    to_c = np.array([[1.0, 0, -centre[0]], [0, 1.0, -centre[1]], [0, 0, 1.0]])
    back = np.array([[1.0, 0, centre[0]], [0, 1.0, centre[1]], [0, 0, 1.0]])
    moves = [similarity_matrix(1.0, 0.0, dx, dy) for dx, dy in
             ((step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step))]
    about = [similarity_matrix(1.0, a) for a in (params.rotation_deg, -params.rotation_deg)]
    about += [similarity_matrix(f, 0.0) for f in (params.scale_step, 1.0 / params.scale_step)]
    out = [as_matrix3(m) @ t3 for m in moves]
    out += [back @ as_matrix3(m) @ to_c @ t3 for m in about]
    return tuple(out)


def _warp_into(small: np.ndarray, m3: np.ndarray, size: Tuple[int, int],
               edge_px: int) -> Tuple[np.ndarray, np.ndarray]:
    """Warp ``small`` by the 3x3 map ``m3`` (small px -> box px) onto a box of ``size`` (w, h);
    returns (image, valid mask)."""
    ones = np.ones(small.shape, np.uint8)
    if abs(m3[2, 0]) < 1e-15 and abs(m3[2, 1]) < 1e-15:
        m = (m3 / m3[2, 2])[:2]
        img = cv2.warpAffine(small, m, size, flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        mask = cv2.warpAffine(ones, m, size, flags=cv2.INTER_NEAREST,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    else:
        img = cv2.warpPerspective(small, m3, size, flags=cv2.INTER_LINEAR,
                                  borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        mask = cv2.warpPerspective(ones, m3, size, flags=cv2.INTER_NEAREST,
                                   borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    if edge_px > 0:
        mask = cv2.erode(mask, np.ones((2 * edge_px + 1,) * 2, np.uint8),
                         borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return img, mask.astype(bool)


def shrunk(image: np.ndarray, factor: float) -> Tuple[np.ndarray, np.ndarray]:
    """``image`` shrunk by about ``factor`` (INTER_AREA) and the 3x3 map from its px to the
    shrunk px (centre-aligned: x_s = (x + 0.5) / f - 0.5 with f the factor actually used)."""
    h, w = image.shape
    ow, oh = max(int(round(w / factor)), 1), max(int(round(h / factor)), 1)
    fx, fy = w / ow, h / oh
    out = cv2.resize(image, (ow, oh), interpolation=cv2.INTER_AREA)
    m = np.array([[1.0 / fx, 0.0, 0.5 / fx - 0.5], [0.0, 1.0 / fy, 0.5 / fy - 0.5],
                  [0.0, 0.0, 1.0]])
    return out, m


class Placed(NamedTuple):
    """A hypothesis ready to be warped: at most ``max_side_px`` of footprint (``low`` shrunk
    and the map with it, centre-aligned, when it was larger)."""

    low: np.ndarray  #: the low image, maybe shrunk
    t3: np.ndarray  #: 3x3 high px -> (shrunk) low px
    ratio: float  #: the map's ratio, high px per (shrunk) low px
    corners: np.ndarray  #: (4, 2) the footprint in (shrunk) low px
    area: float  #: its area, (shrunk) low px^2


def local_ratio(t3: np.ndarray, high_shape: Tuple[int, int]) -> float:
    """High px per low px of the 3x3 map ``t3`` at the high image's centre
    (:func:`scalematch.geometry.ratio_at` there). For an affine map (w = 1 everywhere) it is the ratio of
    :func:`scalematch.geometry.similarity_parts`; for a homography it is the ratio where the
    footprint is, not at the high image's origin (in perspective, a factor 4 and more apart
    across the footprint: the high image is blurred for its middle).

    >>> h = np.array([[0.5, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 1.0]])
    >>> local_ratio(h, (101, 201)), local_ratio(h * 3.0, (101, 201))
    (2.0, 2.0)
    >>> round(local_ratio(np.array([[0.5, 0, 0], [0, 0.5, 0], [0.01, 0, 1.0]]), (101, 201)), 3)
    5.657
    """
    h, w = high_shape[:2]
    return ratio_at(np.asarray(t3, np.float64), ((w - 1) / 2.0, (h - 1) / 2.0))


def _placed(low: np.ndarray, high_shape: Tuple[int, int], t: np.ndarray,
            params: PixelParams) -> Union[Placed, str]:
    """The hypothesis ``t`` placed on ``low`` (:class:`Placed`), or why it cannot be: no
    footprint, a footprint under ``min_overlap_px``, a singular map."""
    t3 = as_matrix3(np.asarray(t, np.float64))
    corners = footprint(t3, high_shape)
    if corners is None or not np.all(np.isfinite(t3)):
        return "the transform has no footprint"
    area = quad_area(corners)
    if area < params.min_overlap_px:
        return f"footprint of {area:.0f} low px^2 (< {params.min_overlap_px})"
    ratio = local_ratio(t3, high_shape)
    if not (math.isfinite(ratio) and ratio > 0):
        return "the transform is singular"
    q = min(1.0, params.max_side_px / math.sqrt(area))
    if q < 1.0:  # work on the low image shrunk by 1/q: the maps gain a centre-aligned scaling
        low, shrink = shrunk(low, 1.0 / q)
        t3 = shrink @ t3
        ratio, corners, area = (ratio / shrink[0, 0], footprint(t3, high_shape),
                                area * shrink[0, 0] ** 2)
    return Placed(low, t3, ratio, corners, area)


def _nan_check(reason: str, overlap: int = 0, fraction: float = 0.0) -> PixelCheck:
    nan = float("nan")
    return PixelCheck(nan, nan, nan, nan, (), overlap, fraction, reason)


def pixel_check(low: np.ndarray, high: np.ndarray, t: np.ndarray,
                params: PixelParams = PixelParams()) -> PixelCheck:
    """How much better the hypothesis ``t`` lines the pixels up than nearby wrong placements.

    Parameters
    ----------
    low : (H, W) array
        The low-resolution image, grey levels; NaN where it shows no scene (left out).
    high : (h, w) array
        The high-resolution image, grey levels; NaN where it shows no scene (left out).
    t : (2, 3) or (3, 3) array
        Hypothesis, finer px -> coarser px (``high``'s to ``low``'s; similarity, affine or
        homography).
    params : PixelParams

    Returns
    -------
    PixelCheck
        ``ncc`` of the hypothesis, ``best_perturbed`` and ``margin = ncc - best_perturbed``, a
        z-score against the perturbed placements; nan with a ``reason`` when the overlap is
        smaller than ``min_overlap_px``, flat, or the map has no footprint.

    >>> rng = np.random.default_rng(0)
    >>> low = cv2.GaussianBlur(rng.uniform(0, 255, (120, 160)).astype(np.float32), (0, 0), 1.5)
    >>> high = cv2.resize(low[20:80, 30:110], (320, 240), interpolation=cv2.INTER_CUBIC)
    >>> t = np.array([[0.25, 0, 30 - 0.375], [0, 0.25, 20 - 0.375]])  # 4x, centre-aligned
    >>> check = pixel_check(low, high, t)
    >>> check.ncc > 0.9, check.margin > 0.5
    (True, True)
    """
    low = np.asarray(low, np.float32)
    high = np.asarray(high, np.float32)
    if low.ndim != 2 or high.ndim != 2:
        raise ValueError(f"expected 2-D grey images, got shapes {low.shape} and {high.shape}")
    placed = _placed(low, high.shape, t, params)
    if isinstance(placed, str):
        return _nan_check(placed)
    low, t3, ratio, corners, area = placed
    others = perturbations(t3, high.shape, params)
    box = _common_box(low.shape, [corners] + [footprint(m, high.shape) for m in others])
    if box is None:
        return _nan_check("the footprint lies outside the low image")
    score = _scorer(low, high, ratio, box, params)
    ncc, n = score(t3)
    fraction = n / area
    if n < params.min_overlap_px:
        return _nan_check(f"{n} low px overlap (< {params.min_overlap_px})", n, fraction)
    if not math.isfinite(ncc):
        return _nan_check("flat: no grey-level variation over the overlap", n, fraction)
    pert = np.array([score(m)[0] for m in others])
    return _against_perturbed(ncc, pert, n, fraction)


def _common_box(low_shape: Tuple[int, int],
                footprints) -> Optional[Tuple[int, int, int, int]]:
    """(x0, y0, x1, y1), inclusive low px: one box holding every placement's footprint (each
    (4, 2), or None: left out), clipped to the low image; None when nothing of it is inside."""
    hh, ww = low_shape
    pts = np.vstack([p for p in footprints if p is not None])
    x0, y0 = np.maximum(np.floor(pts.min(axis=0)).astype(int), 0)
    x1 = min(int(np.ceil(pts[:, 0].max())), ww - 1)
    y1 = min(int(np.ceil(pts[:, 1].max())), hh - 1)
    if x1 <= x0 or y1 <= y0:
        return None
    return x0, y0, x1, y1


def _scorer(low: np.ndarray, high: np.ndarray, ratio: float, box: Tuple[int, int, int, int],
            params: PixelParams):
    """``score(m3) -> (zncc, overlap px)``: the high image, blurred for ``ratio``, warped by the
    3x3 map ``m3`` (high px -> low px) onto ``box`` of ``low`` and compared where both show
    the scene (zncc nan under ``min_overlap_px``)."""
    x0, y0, x1, y1 = box
    crop = low[y0:y1 + 1, x0:x1 + 1]
    size = (x1 - x0 + 1, y1 - y0 + 1)
    small, k = blurred_for_ratio(high, ratio, params.camera_blur_px)
    shift = np.array([[1.0, 0, -x0], [0, 1.0, -y0], [0, 0, 1.0]])
    from_small = small_to_high(k)
    crop_shown = np.isfinite(crop)

    def score(m3: np.ndarray, windows: int = 0) -> Tuple[float, int]:
        img, mask = _warp_into(small, shift @ m3 @ from_small, size, params.edge_px)
        mask &= crop_shown & np.isfinite(img)
        if windows:  # (share of the windows that agree, windows compared)
            return _windows_agreeing(img, crop, mask, windows, params.window_ncc)
        n = int(mask.sum())
        if n < params.min_overlap_px:
            return float("nan"), n
        return zncc(img[mask], crop[mask], params.min_std), n

    return score


#: A window whose grey levels vary less than this (std, grey levels) in either image is flat:
#: its correlation means nothing, and it is not counted (as ``agreement_map``'s default)
WINDOW_MIN_STD = 1.0


def _windows_agreeing(img: np.ndarray, crop: np.ndarray, mask: np.ndarray, side: int,
                      least: float) -> Tuple[float, int]:
    """(share, n): of the ``n`` windows of ``side`` px tiling ``mask`` (wholly inside it, in
    neither image flat), the share whose ZNCC between ``img`` and ``crop`` is at least
    ``least`` (nan for none)."""
    agree = n = 0
    h, w = mask.shape
    for y in range(0, h - side + 1, side):
        for x in range(0, w - side + 1, side):
            if not mask[y:y + side, x:x + side].all():
                continue
            a, b = img[y:y + side, x:x + side], crop[y:y + side, x:x + side]
            if float(a.std()) <= WINDOW_MIN_STD or float(b.std()) <= WINDOW_MIN_STD:
                continue
            n += 1
            agree += zncc(a.ravel(), b.ravel()) >= least
    return (agree / n if n else float("nan")), n


def _against_perturbed(ncc: float, pert: np.ndarray, n: int, fraction: float) -> PixelCheck:
    """The check of a hypothesis of ZNCC ``ncc`` (over ``n`` low px, ``fraction`` of its
    footprint) against its perturbed placements' ZNCC ``pert`` (nan: not measured)."""
    good = pert[np.isfinite(pert)]
    if good.size == 0:
        return PixelCheck(ncc, float("nan"), float("nan"), float("nan"), tuple(pert.tolist()),
                          n, fraction, "no perturbed placement could be measured")
    best = float(good.max())
    z = (ncc - float(good.mean())) / max(float(good.std()), 0.01)
    return PixelCheck(ncc=ncc, best_perturbed=best, margin=ncc - best, z=float(z),
                      perturbed=tuple(float(v) for v in pert), overlap_px=n,
                      overlap_fraction=float(fraction))


class NearWindows(NamedTuple):
    """The nearby-placement check by windows (:func:`near_windows`)."""

    windows: int  #: windows compared at the claimed placement
    claimed: float  #: share of them that agree there (ZNCC at least ``window_ncc``)
    nearby: float  #: the highest share at a nearby wrong placement


def near_windows(low: np.ndarray, high: np.ndarray, t: np.ndarray,
                 params: PixelParams = PixelParams()) -> NearWindows:
    """:func:`pixel_check` window by window: the high image placed by ``t`` and by its nearby
    wrong placements (:func:`perturbations`), cut into windows of the same share of the
    footprint as the uniqueness test's (``window_px`` of ``unique_side_px``), each compared
    with the low image on its own (ZNCC at least ``window_ncc``).

    One ZNCC over the footprint counts an occluder (another object in front of the scene in
    the finer image) against the map over all of its area, at the claim as at its neighbours;
    a share of windows loses only the windows it covers. nan shares (0 windows): cannot tell.

    >>> rng = np.random.default_rng(0)
    >>> low = cv2.GaussianBlur(rng.uniform(0, 255, (120, 160)).astype(np.float32), (0, 0), 1.5)
    >>> high = cv2.resize(low[20:80, 30:110], (320, 240), interpolation=cv2.INTER_CUBIC)
    >>> high[:120, :160] = 128 + 60 * np.sign(np.sin(np.arange(160) / 5.0))  # an occluder
    >>> w = near_windows(low, high, np.array([[0.25, 0, 30 - 0.375], [0, 0.25, 20 - 0.375]]))
    >>> w.windows >= 16, w.claimed > 0.5, w.nearby < 0.2
    (True, True, True)
    """
    nan = float("nan")
    low = np.asarray(low, np.float32)
    high = np.asarray(high, np.float32)
    placed = _placed(low, high.shape, t, params)
    if isinstance(placed, str):
        return NearWindows(0, nan, nan)
    low, t3, ratio, corners, area = placed
    others = perturbations(t3, high.shape, params)
    box = _common_box(low.shape, [corners] + [footprint(m, high.shape) for m in others])
    if box is None:
        return NearWindows(0, nan, nan)
    side = max(int(round(math.sqrt(area) * params.window_px / params.unique_side_px)), 2)
    score = _scorer(low, high, ratio, box, params)
    claimed, n = score(t3, side)
    if n == 0:
        return NearWindows(0, nan, nan)
    nearby = [score(m, side)[0] for m in others]
    good = [v for v in nearby if math.isfinite(v)]
    return NearWindows(n, claimed, max(good) if good else nan)


# --------------------------------------------------------------------------- uniqueness

#: Smallest misfit 1 - ZNCC used as a divisor (a perfect fit would divide by zero): a numerical
#: guard, far below any misfit measured (no answer depends on it)
MISFIT_FLOOR = 1e-6


@dataclass(frozen=True)
class Uniqueness:
    """How much better the claimed placement fits than the best placement elsewhere."""

    claimed: float  #: ZNCC of the placed high image at the claimed position
    elsewhere: float  #: the best ZNCC of the same warped image at any position half a footprint away
    #: misfit elsewhere over misfit at the claim, ``(1 - elsewhere) / (1 - claimed)``: how many
    #: times better the claimed placement fits (nan: cannot tell, e.g. no room elsewhere). A
    #: ratio, not a difference: on a smooth scene every placement correlates 0.99, yet the
    #: true one has ten times less misfit
    ratio: float


def masked_zncc_map(image: np.ndarray, tpl: np.ndarray, mask: np.ndarray,
                    min_std: float = PixelParams.min_std) -> np.ndarray:
    """ZNCC of ``tpl`` over its ``mask`` (bool, same shape) at every placement inside ``image``
    (float32, (H - h + 1, W - w + 1); -1 where the image is flat under the mask).

    What ``cv2.matchTemplate(image, tpl, TM_CCOEFF_NORMED, mask=mask)`` computes, from three
    unmasked correlations (each one DFT-based in OpenCV): the template zero-meaned over the mask,
    and the mask against the image and its square (the window's sum and sum of squares), 2-4
    times faster than OpenCV's masked path, equal to it within 1e-4.

    >>> rng = np.random.default_rng(0)
    >>> img = rng.uniform(0, 255, (40, 50)).astype(np.float32)
    >>> m = np.ones((10, 12), bool); m[:3, :4] = False
    >>> r = masked_zncc_map(img, img[5:15, 7:19], m)
    >>> [int(v) for v in np.unravel_index(np.argmax(r), r.shape)], round(float(r.max()), 4)
    ([5, 7], 1.0)
    """
    img = np.asarray(image, np.float32)
    m = mask.astype(np.float32)
    n = float(m.sum())
    tz = (np.asarray(tpl, np.float32) - float((tpl * m).sum()) / n) * m
    num = cv2.matchTemplate(img, tz, cv2.TM_CCORR)
    s1 = cv2.matchTemplate(img, m, cv2.TM_CCORR)
    s2 = cv2.matchTemplate(img * img, m, cv2.TM_CCORR)
    var = s2 - s1 * s1 / n  # n times the window's variance under the mask
    flat = var <= n * min_std * min_std
    out = num / np.sqrt(np.where(flat, 1.0, var) * float((tz * tz).sum()))
    out[flat] = -1.0
    return np.clip(out, -1.0, 1.0)


def vouched_mask(shape: Tuple[int, int], xy: np.ndarray, radius: float) -> np.ndarray:
    """(H, W) bool: the discs of ``radius`` px around the points ``xy`` (N, 2), (x, y) px.

    >>> m = vouched_mask((20, 30), np.array([[5.0, 5.0], [25.0, 15.0]]), 3)
    >>> bool(m[5, 5]), bool(m[15, 25]), bool(m[10, 15]), int(m.sum())
    (True, True, False, 58)
    """
    out = np.zeros(shape, np.uint8)
    r = max(int(round(radius)), 1)
    for x, y in np.rint(np.asarray(xy, np.float64)).astype(int):
        cv2.circle(out, (int(x), int(y)), r, 1, thickness=-1)
    return out.astype(bool)


def uniqueness(low: np.ndarray, high: np.ndarray, t: np.ndarray,
               params: PixelParams = PixelParams(),
               vouched: Optional[np.ndarray] = None) -> Uniqueness:
    """Slide the high image, warped by ``t`` (rotation, scale, tilt kept), over the whole low
    image and compare the claimed placement with the best one elsewhere (``cv2.matchTemplate``,
    ZNCC over the footprint's mask).

    A repeated structure (the windows of a facade, the panels of a bus) matches wherever a copy
    of it stands: the claimed placement is then no better than another one, and the claim is
    ambiguous even when many points agree with it. A true match fits its own place better than
    any copy (the pixels are the same ones, not alike ones).

    ``vouched`` (finer px, (N, 2)): the inliers; only the pixels within ``vouch_radius`` of the
    footprint's size of them are compared (None: all). Pixels that are NaN in either image (no
    scene there, :func:`scalematch.stages.nodata.with_nan`) are left out.

    >>> rng = np.random.default_rng(0)
    >>> low = cv2.GaussianBlur(rng.uniform(0, 255, (120, 160)).astype(np.float32), (0, 0), 1.5)
    >>> high = cv2.resize(low[20:80, 30:110], (320, 240), interpolation=cv2.INTER_CUBIC)
    >>> u = uniqueness(low, high, np.array([[0.25, 0, 30 - 0.375], [0, 0.25, 20 - 0.375]]))
    >>> u.claimed > 0.9, u.ratio > 3
    (True, True)
    >>> tiled = np.tile(low[20:80, 30:110], (2, 2))            # the structure twice over
    >>> u = uniqueness(tiled, high, np.array([[0.25, 0, -0.375], [0, 0.25, -0.375]]))
    >>> 0.8 < u.ratio < 1.25
    True
    """
    return uniqueness_of(unique_template(low, high, t, params, vouched), params)


def uniqueness_of(placed: Optional["Template"], params: PixelParams) -> Uniqueness:
    """:func:`uniqueness` of a template made already (None: cannot tell, all nan)."""
    nan = float("nan")
    if placed is None:
        return Uniqueness(nan, nan, nan)
    r = masked_zncc_map(placed.low, placed.tpl, placed.mask, params.min_std)
    claimed = _at_claim(r, placed)
    far = _far(r.shape, placed, params.unique_exclusion)
    if not far.any():
        return Uniqueness(claimed, nan, nan)
    elsewhere = float(r[far].max())
    return Uniqueness(claimed, elsewhere, (1.0 - elsewhere) / max(1.0 - claimed, MISFIT_FLOOR))


class Template(NamedTuple):
    """The finer image warped by a claim, cut to where it is compared, for the tests that slide
    it over the coarser image (:func:`uniqueness`, :func:`window_agreement`)."""

    low: np.ndarray  #: (H, W) float32 coarser image at the tests' size, 0 where it has no scene
    tpl: np.ndarray  #: (h, w) float32 warped finer image, 0 outside ``mask``
    mask: np.ndarray  #: (h, w) bool: the pixels compared
    y0: int  #: the claimed placement: the template's top-left corner in ``low``
    x0: int


def unique_template(low: np.ndarray, high: np.ndarray, t: np.ndarray, params: PixelParams,
                    vouched: Optional[np.ndarray] = None) -> Optional[Template]:
    """The :class:`Template` of claim ``t`` (finer px -> coarser px) at the uniqueness test's
    size (``unique_side_px``), compared where both images show the scene and, with ``vouched``
    (the inliers, finer px), within ``vouch_radius`` of them; None when it cannot tell: too
    small an overlap, flat, or no room elsewhere."""
    placed = _placed(np.asarray(low, np.float32), high.shape, t,
                     replace(params, max_side_px=params.unique_side_px))
    if isinstance(placed, str):
        return None
    low, t3, ratio, _, _ = placed
    small, k = blurred_for_ratio(high, ratio, params.camera_blur_px)
    hh, ww = low.shape
    img, mask = _warp_into(small, t3 @ small_to_high(k), (ww, hh), params.edge_px)
    shown = np.isfinite(low)
    mask &= np.isfinite(img) & shown  # both show the scene at the claimed placement
    if vouched is not None and len(vouched):  # where the inliers vouch for the map
        radius = params.vouch_radius * math.sqrt(max(float(mask.sum()), 1.0))
        mask &= vouched_mask(mask.shape, apply(t3, vouched), radius)
    low = np.where(shown, low, np.float32(0.0))
    rows, cols = np.nonzero(mask)
    if rows.size < params.min_overlap_px:
        return None
    y0, y1, x0, x1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    tmask = mask[y0:y1, x0:x1]
    tpl = np.ascontiguousarray(np.where(tmask, img[y0:y1, x0:x1], np.float32(0.0)))
    if tpl.shape[0] >= hh or tpl.shape[1] >= ww or float(tpl[tmask].std()) <= params.min_std:
        return None  # no room to place it anywhere else, or flat
    return Template(low, tpl, tmask, int(y0), int(x0))


def _at_claim(score: np.ndarray, placed: Template) -> float:
    """The best of ``score`` (a map over placements) within 1 px of the claimed placement."""
    y0, x0 = placed.y0, placed.x0
    return float(score[max(y0 - 1, 0):y0 + 2, max(x0 - 1, 0):x0 + 2].max())


def _far(shape: Tuple[int, int], placed: Template, exclusion: float) -> np.ndarray:
    """(shape) bool: the placements ``exclusion`` of the template's size away from the
    claimed one (``PixelParams.unique_exclusion``)."""
    yy, xx = np.ogrid[0:shape[0], 0:shape[1]]
    radius = exclusion * min(placed.tpl.shape)
    return (yy - placed.y0) ** 2 + (xx - placed.x0) ** 2 > radius * radius


class Agreement(NamedTuple):
    """How many windows of the placed finer image agree with the coarser one (ZNCC of at least
    ``PixelParams.window_ncc``), at the claimed placement and at the best placement elsewhere."""

    windows: int  #: windows compared (wholly inside the compared pixels, not flat)
    claimed: float  #: share of them that agree at the claimed placement
    elsewhere: float  #: the highest share anywhere half a footprint away


def agreement_map(low: np.ndarray, tpl: np.ndarray, mask: np.ndarray, side: int,
                  least: float, min_std: float = 1.0) -> Tuple[np.ndarray, int]:
    """(share, n): for every placement of ``tpl`` in ``low`` (as ``cv2.matchTemplate`` counts
    them), the share of its ``n`` windows of ``side`` px (a grid over ``tpl``, those wholly in
    ``mask`` with a grey-level std above ``min_std``) whose own ZNCC there is at least ``least``.

    >>> rng = np.random.default_rng(0)
    >>> img = cv2.GaussianBlur(rng.uniform(0, 255, (60, 80)).astype(np.float32), (0, 0), 1.0)
    >>> tpl = img[10:42, 20:52].copy(); tpl[:16, :16] = 0        # an occluded quarter
    >>> m = np.ones(tpl.shape, bool)
    >>> share, n = agreement_map(img, tpl, m, 8, 0.8)
    >>> n, float(share[10, 20]), float(np.delete(share.ravel(), 10 * share.shape[1] + 20).max()) < 0.5
    (12, 1.0, True)
    """
    hh, ww = low.shape
    h, w = tpl.shape
    ph, pw = hh - h + 1, ww - w + 1
    count = np.zeros((ph, pw), np.float32)
    n = 0
    for oy in range(0, h - side + 1, side):
        for ox in range(0, w - side + 1, side):
            patch = np.ascontiguousarray(tpl[oy:oy + side, ox:ox + side])
            if not mask[oy:oy + side, ox:ox + side].all() or float(patch.std()) <= min_std:
                continue
            r = cv2.matchTemplate(low, patch, cv2.TM_CCOEFF_NORMED)
            count += r[oy:oy + ph, ox:ox + pw] >= least
            n += 1
    return count / max(n, 1), n


def window_agreement(low: np.ndarray, high: np.ndarray, t: np.ndarray,
                     params: PixelParams = PixelParams(),
                     vouched: Optional[np.ndarray] = None) -> Agreement:
    """The uniqueness test by windows: the placed finer image (:func:`unique_template`) cut
    into windows of ``window_px``, each compared on its own (ZNCC at least ``window_ncc``), at
    the claimed placement and at every placement elsewhere.

    One ZNCC over the footprint counts an occluder, a shadow or a relit patch against the map
    over its whole area; a share of windows loses only the windows it covers. A copy of a
    repeated structure is alike, not the same: fewer of its windows agree at the claim, and as
    many agree at the other copies. nan shares (0 windows): cannot tell.
    """
    return agreement_of(unique_template(low, high, t, params, vouched), params)


def agreement_of(placed: Optional[Template], params: PixelParams) -> Agreement:
    """:func:`window_agreement` of a template made already (None: cannot tell)."""
    nan = float("nan")
    if placed is None:
        return Agreement(0, nan, nan)
    share, n = agreement_map(placed.low, placed.tpl, placed.mask, params.window_px,
                             params.window_ncc)
    if n == 0:
        return Agreement(0, nan, nan)
    far = _far(share.shape, placed, params.unique_exclusion)
    return Agreement(n, _at_claim(share, placed), float(share[far].max()) if far.any() else nan)
