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
low image's resolution (:mod:`scalematch.stages.placing`). ``near_windows`` makes the same
comparison window by window.

Where the pixels are compared: only where both images show the scene (NaN marks the rest: a
no-data canvas, :mod:`scalematch.stages.nodata`). The uniqueness test, which compares the claim
with every placement elsewhere, is :mod:`scalematch.stages.uniqueness`.

Pixel convention: OpenCV's, (x, y), pixel centres at integers. Used by the decision's second
look and by the pixel tests of every match's final map (:mod:`scalematch.stages.decision`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar, Mapping, NamedTuple, Optional, Tuple

import numpy as np

from ..checks import ANGLE, AT_LEAST_ONE, Bounds, CORRELATION, COUNT, FACTOR, NON_NEGATIVE, POSITIVE, check_bounds
from ..geometry import apply, as_matrix3, footprint, local_affine, ratio_at, similarity_matrix
from .placing import blurred_for_ratio, place, quad_area, small_to_high, vouched_mask, warp_into


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
    #: side of the windows of the agreement test (``uniqueness.window_agreement``), px of the
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
    #: blurred by this times sqrt(ratio^2 - 1) before it is compared (``placing.blurred_for_ratio``;
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

    >>> import cv2
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
    scoring = _scoring(low, high, t, params, nearby=True)
    if isinstance(scoring, str):
        return _nan_check(scoring)
    score, t3, area, others = scoring
    ncc, n = score(t3)
    fraction = n / area
    if n < params.min_overlap_px:
        return _nan_check(f"{n} low px overlap (< {params.min_overlap_px})", n, fraction)
    if not math.isfinite(ncc):
        return _nan_check("flat: no grey-level variation over the overlap", n, fraction)
    pert = np.array([score(m)[0] for m in others])
    return _against_perturbed(ncc, pert, n, fraction)


def overlap_ncc(low: np.ndarray, high: np.ndarray, t: np.ndarray,
                params: PixelParams = PixelParams()) -> float:
    """ZNCC of the hypothesis ``t`` alone over its overlap: :func:`pixel_check`'s ``ncc``
    without the nearby placements (nan where that check would be nan: too small an overlap,
    flat, no footprint). The measure by which richer models of one match are compared
    (:func:`scalematch.stages.refit.chosen_model`).

    >>> import cv2
    >>> rng = np.random.default_rng(0)
    >>> low = cv2.GaussianBlur(rng.uniform(0, 255, (120, 160)).astype(np.float32), (0, 0), 1.5)
    >>> high = cv2.resize(low[20:80, 30:110], (320, 240), interpolation=cv2.INTER_CUBIC)
    >>> t = np.array([[0.25, 0, 30 - 0.375], [0, 0.25, 20 - 0.375]])  # 4x, centre-aligned
    >>> ncc = overlap_ncc(low, high, t)
    >>> ncc > 0.9, abs(ncc - pixel_check(low, high, t).ncc) < 1e-6
    (True, True)
    """
    scoring = _scoring(np.asarray(low, np.float32), np.asarray(high, np.float32), t, params,
                       nearby=False)
    if isinstance(scoring, str):
        return float("nan")
    score, t3, _, _ = scoring
    return score(t3)[0]


def _scoring(low: np.ndarray, high: np.ndarray, t: np.ndarray, params: PixelParams,
             nearby: bool):
    """(score, t3, area, others): the hypothesis ``t`` placed on ``low`` (:func:`place`), its
    nearby placements ``others`` (:func:`perturbations`; none without ``nearby``), and the
    :func:`_scorer` of one box holding all their footprints; or why it cannot be placed."""
    placed = place(low, high.shape, t, params.min_overlap_px, params.max_side_px)
    if isinstance(placed, str):
        return placed
    low, t3, ratio, corners, area = placed
    others = perturbations(t3, high.shape, params) if nearby else []
    box = _common_box(low.shape, [corners] + [footprint(m, high.shape) for m in others])
    if box is None:
        return "the footprint lies outside the low image"
    return _scorer(low, high, ratio, box, params), t3, area, others


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
            params: PixelParams, region: Optional[np.ndarray] = None):
    """``score(m3) -> (zncc, overlap px)``: the high image, blurred for ``ratio``, warped by the
    3x3 map ``m3`` (high px -> low px) onto ``box`` of ``low`` and compared where both show
    the scene (zncc nan under ``min_overlap_px``), and within ``region`` (bool, the box's
    shape; None: everywhere)."""
    x0, y0, x1, y1 = box
    crop = low[y0:y1 + 1, x0:x1 + 1]
    size = (x1 - x0 + 1, y1 - y0 + 1)
    small, k = blurred_for_ratio(high, ratio, params.camera_blur_px)
    shift = np.array([[1.0, 0, -x0], [0, 1.0, -y0], [0, 0, 1.0]])
    from_small = small_to_high(k)
    crop_shown = np.isfinite(crop)
    if region is not None:
        crop_shown &= region

    def score(m3: np.ndarray, windows: int = 0) -> Tuple[float, int]:
        img, mask = warp_into(small, shift @ m3 @ from_small, size, params.edge_px)
        mask &= crop_shown & np.isfinite(img)
        if windows:  # (share of the windows that agree, windows compared)
            return _windows_agreeing(img, crop, mask, windows, params.window_ncc)
        n = int(mask.sum())
        if n < params.min_overlap_px:
            return float("nan"), n
        return zncc(img[mask], crop[mask], params.min_std), n

    return score


#: A window whose grey levels vary less than this (std, grey levels) in either image is flat:
#: its correlation means nothing, and it is not counted (as ``uniqueness.agreement_map``'s default)
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
                 params: PixelParams = PixelParams(),
                 vouched: Optional[np.ndarray] = None) -> NearWindows:
    """:func:`pixel_check` window by window: the high image placed by ``t`` and by its nearby
    wrong placements (:func:`perturbations`), cut into windows of the same share of the
    footprint as the uniqueness test's (``window_px`` of ``unique_side_px``), each compared
    with the low image on its own (ZNCC at least ``window_ncc``). With ``vouched`` (high px,
    (N, 2): the map's inliers), only the low image's pixels within ``vouch_radius`` of the
    footprint's size of them are compared, at the claim and at its neighbours alike, as the
    uniqueness test compares them: a 3-D scene's other planes hold no inlier of a plane's map.

    One ZNCC over the footprint counts an occluder (another object in front of the scene in
    the finer image) against the map over all of its area, at the claim as at its neighbours;
    a share of windows loses only the windows it covers. nan shares (0 windows): cannot tell.

    >>> import cv2
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
    placed = place(low, high.shape, t, params.min_overlap_px, params.max_side_px)
    if isinstance(placed, str):
        return NearWindows(0, nan, nan)
    low, t3, ratio, corners, area = placed
    others = perturbations(t3, high.shape, params)
    box = _common_box(low.shape, [corners] + [footprint(m, high.shape) for m in others])
    if box is None:
        return NearWindows(0, nan, nan)
    side = max(int(round(math.sqrt(area) * params.window_px / params.unique_side_px)), 2)
    region = None
    if vouched is not None and len(vouched):
        x0, y0, x1, y1 = box
        region = vouched_mask((y1 - y0 + 1, x1 - x0 + 1),
                              apply(t3, np.asarray(vouched, np.float64)) - [x0, y0],
                              params.vouch_radius * math.sqrt(area))
    score = _scorer(low, high, ratio, box, params, region)
    claimed, n = score(t3, side)
    if n == 0:
        return NearWindows(0, nan, nan)
    nearby = [score(m, side)[0] for m in others]
    good = [v for v in nearby if math.isfinite(v)]
    return NearWindows(n, claimed, max(good) if good else nan)


def matches_beat_plane(coarser: np.ndarray, finer: np.ndarray, h: np.ndarray,
                       pairs: np.ndarray, params: PixelParams = PixelParams()) -> np.ndarray:
    """For each pair of ``pairs`` ((N, 4) x, y finer; x, y coarser) off the plane whose map is
    ``h`` (3x3, finer px -> coarser px): whether its own match fits the pixels better than the
    plane's prediction. The finer image around the finer point, blurred for the plane's ratio
    and placed by the plane's local affine map (:func:`scalematch.geometry.local_affine`), is compared by ZNCC with
    the coarser image at the match and at ``h``'s prediction, over a window of twice
    ``params.window_px`` (the descriptor's 16 px window). Where the scene is flat, the plane's
    prediction is the scene's own place, and a match off it is a look-alike (a repeated
    window, an edge) that fits no better; where the scene has depth, the plane's prediction
    lands on another part of the scene. False where either place cannot be compared (the
    window leaves an image, or is flat)."""
    h = as_matrix3(np.asarray(h, np.float64))
    pairs = np.asarray(pairs, np.float64).reshape(-1, 4)
    out = np.zeros(len(pairs), bool)
    if not len(pairs):
        return out
    small, k = blurred_for_ratio(finer, ratio_at(h, pairs[0, :2]), params.camera_blur_px)
    to_small = small_to_high(k)
    coarser = np.asarray(coarser, np.float32)
    for i, (x, y, xc, yc) in enumerate(pairs):
        a, at = local_affine(h, np.array([x, y])), np.array([x, y])
        match, plane = (_local_zncc(coarser, small, _placed(a, at, target) @ to_small, target,
                                    params)
                        for target in (np.array([xc, yc]), apply(h, at[None])[0]))
        out[i] = bool(match > plane)  # nan on either side: False
    return out


def _placed(a: np.ndarray, x: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The 3x3 affine map with linear part ``a`` that sends the point ``x`` to ``target``."""
    m = np.eye(3)
    m[:2, :2] = a
    m[:2, 2] = target - a @ x
    return m


def _local_zncc(coarser: np.ndarray, small: np.ndarray, m3: np.ndarray, target: np.ndarray,
                params: PixelParams) -> float:
    """ZNCC of the coarser image's window of side ``2 params.window_px + 1`` around ``target``
    with the image ``small`` placed by ``m3`` (small px -> coarser px); nan where the window
    leaves the coarser image or too little of it is covered."""
    half = params.window_px
    side = 2 * half + 1
    x0, y0 = int(round(target[0])) - half, int(round(target[1])) - half
    if x0 < 0 or y0 < 0 or x0 + side > coarser.shape[1] or y0 + side > coarser.shape[0]:
        return float("nan")
    shift = np.array([[1.0, 0, -x0], [0, 1.0, -y0], [0, 0, 1.0]])
    img, mask = warp_into(small, shift @ m3, (side, side), params.edge_px)
    crop = coarser[y0:y0 + side, x0:x0 + side]
    mask &= np.isfinite(crop) & np.isfinite(img)
    if mask.sum() < side * side // 2:
        return float("nan")
    return zncc(img[mask], crop[mask], params.min_std)
