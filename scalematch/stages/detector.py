"""Stage 2: scale-adapted Harris interest points (docs/ALGORITHM.md step 2, paper section 3).

At scale ``s`` (paper eq. "Harris-scale")::

    M_s = s^2 * G(s*sigma~) * [[Ix^2, IxIy], [IxIy, Iy^2]](s*sigma)      (derivatives at s*sigma)
    C_s = det(M_s) - alpha * trace(M_s)^2

The ``s^2`` factor on ``M`` is the normalisation of the paper's proposition: zooming an image out
by ``s`` divides gradients by ``s`` and hence ``M`` by ``s^2`` and ``C`` by ``s^4`` (eq.
cornerness-rel), so ``C_s = s^4 (det M - alpha tr(M)^2)`` is comparable across scales and one
threshold serves every scale. (The paper writes the s^4 both inside ``M_s`` and in front of
``C_s``; applied twice it would no longer be scale-invariant, so it is applied once, here.)

Derivatives are taken in full-resolution units even when a level is decimated: a level gradient
is divided by ``d``, so ``M`` on a level is multiplied by ``(s / d)^2``.

**Adaptive detection (docs/design/DECISION.md, "Adaptive detection").**
``C`` scales as ``gain^4`` under ``I -> gain * I``, so the absolute threshold lets contrast
decide what the detector sees (a 12-bit image read as 0-15 grey levels finds almost nothing).
Two options, both measured on the s = 1 image once (:func:`image_contrast`) and applied at
every scale:

* ``contrast_relative`` (on by default, as ``Config`` uses it, so :func:`detect` is the
  detector of :func:`scalematch.match`; off, the paper's absolute threshold): the threshold is
  multiplied by ``min(contrast_cap, (c / c_ref)^4)``, ``c`` the 90th percentile of the
  gradient magnitude and ``c_ref`` = ``HarrisParams.reference_contrast`` (that of the benchmark photos),
  never below the noise floor (:func:`noise_floor`: ten times the largest response pure noise
  of the image's estimated noise std gives);
* ``min_points`` (40 by default): when fewer points pass the threshold at a scale, the
  strongest local maxima above the noise floor make up a floor of ``min_points`` (a per-scale
  point budget): the coarse scales of a small finer image hold few points, and an occluder or
  a footprint cut off by the coarser image's edge leaves fewer still.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar, List, Mapping, NamedTuple, Optional, Sequence

import cv2
import numpy as np

from ..checks import AT_LEAST_ONE, Bounds, COUNT, NON_NEGATIVE, POSITIVE, check_bounds
from .filters import gaussian_derivative
from .nodata import away_from
from .scalespace import Level, as_float_image, gaussian_blur, scale_space


#: Smallest image side the matcher accepts, px (the one minimum: reading an image and matching
#: arrays both check it): below it the 16 px descriptor window and the Harris filters
#: (4 sigma~ = 8 px) see mostly border.
MIN_SIDE_PX = 24


@dataclass(frozen=True)
class HarrisParams:
    """Parameters of the scale-adapted Harris detector; lengths in pixels at s = 1."""

    sigma: float = 1.0  #: derivation std, px (paper section 3.2, sigma = 1)
    sigma_tilde: float = 2.0  #: integration std, px (paper section 3.2, sigma~ = 2)
    alpha: float = 0.04  #: cornerness det - alpha tr^2 (Harris & Stephens 1988: 0.04-0.06)
    #: cornerness threshold in (grey level / px)^4 with s^4 normalisation (paper proposition 2);
    #: grey levels of an 8-bit image. Set so that 3-grey-level noise on a flat image gives none.
    threshold: float = 100.0
    nms_radius: float = 2.0  #: non-maximum suppression radius, px at s = 1, grows as s
    max_points: int = 6000  #: cap per scale, strongest first (0 = no cap)
    border: float = 2.0  #: points closer than this to the border are dropped, px at s = 1 (x s)
    subpixel: bool = True  #: refine positions by a quadratic fit of the 3x3 response
    decimate: bool = True  #: compute coarse scales on decimated levels (same response)
    min_level_sigma: float = 1.0  #: decimate while the derivation std stays >= this, level px
    #: blur a decimated level carries, in its own px (stages/scalespace.py): the camera model
    #: of EVALUATION.md, whose coarser images are blurred by 0.5 sqrt(r^2 - 1) before shrinking
    #: by r "so that after shrinking the camera blur is about 0.5 px"
    camera_blur_px: float = 0.5
    #: a level whose shorter side is under this many px is not searched (no point found): the
    #: Harris window at s = 1 (integration std 2, border 2) leaves nothing inside 12 px
    min_level_side_px: int = 12
    #: adaptive detection (False: the paper's absolute threshold above): multiply
    #: ``threshold`` by ``min(contrast_cap, (c / reference_contrast)^4)``, ``c`` the image's
    #: contrast (:func:`image_contrast`), floored at the image's noise floor (:func:`noise_floor`).
    #: On, as ``Config`` uses it: a 12-bit image stored as 0-4095 in 16 bits, or 32 grey levels,
    #: found no point at the absolute threshold (docs/design/DECISION.md, "Adaptive detection")
    contrast_relative: bool = True
    #: largest factor the contrast may put on ``threshold`` (1: it only ever lowers it, so images
    #: at least as contrasted as the reference photos keep today's points; inf: fully relative)
    contrast_cap: float = 1.0
    #: per-scale point budget (0 = off): when fewer points pass the threshold, the strongest local
    #: maxima above the noise floor are kept up to this many. A 640x480 finer image holds 16 to
    #: 66 points at scales 6 to 8 (median 34; occluded pairs at ratios 6 and 8, seed 1), and the
    #: footprint at ratio 8-10 had 5-14 at the winning scale; a budget of 40 solved 6 more of
    #: 152 occluded and partial runs at ratios 6 and 8 (seed 1), 80 the same 6
    min_points: int = 40
    #: percentile of the gradient magnitude (Gaussian derivatives of std ``sigma``, s = 1) taken
    #: as an image's contrast (:func:`image_contrast`). The median measures the flat parts: on
    #: the low images cut from the shared photos it ranged 0.05 to 5.7 grey levels/px (sky,
    #: walls) while the 90th percentile ranged 6.4 to 17.9 (19 pairs at ratio 8, seed 0;
    #: docs/design/DECISION.md, "Adaptive detection")
    contrast_percentile: float = 90.0
    #: ... taken over every n-th pixel along each axis: a quarter of the pixels (77k at
    #: 640x480) gives the full image's 90th percentile within 1.2 % (median 0.16 %, 120 images
    #: of 60 zoom pairs, seed 0), and the full sort was half the measure's cost (8.0 ms -> 3.2
    #: ms a 640x480 image; docs/design/DECISION.md, "What the pixel tests cost")
    contrast_sample_step: int = 2
    #: the contrast ``threshold`` = 100 was tuned at, grey levels/px: the median contrast of
    #: the 76 images (high crop and low image) cut from the 38 photos of ../shared/data/photos
    #: at ratio 4, seed 0 (high 14.6, low 10.2, both 12.0)
    reference_contrast: float = 12.0
    #: largest Harris response C (s = 1) of pure Gaussian noise of std 1 grey level over a
    #: 640x480 image: measured 1.08 for std 3 (C scales as std^4: 1.08 / 81), seed 0
    noise_response_per_std4: float = 1.08 / 81.0
    #: the largest pure-noise response falls with the scale as s^-4.4 to s^-4.7 (measured, same
    #: image: 4.5e-2 at s = 2, 1.7e-3 at s = 4, 1.1e-4 at s = 8, 1.8e-5 at s = 12.7); the floor
    #: falls as s^-this, a little slower, so it stays above the noise at every scale
    noise_scale_exponent: float = 4.0
    #: the noise floor is this many times the largest pure-noise response (a factor 10 in C is a
    #: factor 1.8 in gradient: noise maxima do not reach it)
    noise_margin: float = 10.0

    @property
    def adaptive(self) -> bool:
        """True when detection needs the image's :class:`Contrast`."""
        return self.contrast_relative or self.min_points > 0

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "sigma": POSITIVE,
        "sigma_tilde": POSITIVE,
        "min_level_sigma": POSITIVE,
        # alpha >= 0.25 makes every cornerness negative (det <= tr^2 / 4)
        "alpha": Bounds(lo=0, hi=0.25, hi_open=True),
        "threshold": NON_NEGATIVE,
        "nms_radius": NON_NEGATIVE,
        "border": NON_NEGATIVE,
        "max_points": COUNT,
        "contrast_cap": Bounds(lo=0, lo_open=True, allow_inf=True),
        "min_points": COUNT,
        "contrast_percentile": Bounds(lo=0, hi=100),
        "contrast_sample_step": AT_LEAST_ONE,
        "reference_contrast": POSITIVE,
        "noise_response_per_std4": POSITIVE,
        "noise_scale_exponent": NON_NEGATIVE,
        "noise_margin": NON_NEGATIVE,
        "camera_blur_px": NON_NEGATIVE,
        "min_level_side_px": AT_LEAST_ONE,
    }

    def __post_init__(self) -> None:
        check_bounds("harris", self, self.BOUNDS)


@dataclass(frozen=True)
class Keypoints:
    """Interest points detected at one scale; coordinates in full-resolution pixels."""

    s: float  #: the scale they were detected at
    xy: np.ndarray = field(repr=False)  #: (N, 2) float64, (x, y) full-resolution px
    response: np.ndarray = field(repr=False)  #: (N,) float32, normalised cornerness C_s

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    @staticmethod
    def empty(s: float) -> "Keypoints":
        return Keypoints(s=s, xy=np.zeros((0, 2)), response=np.zeros(0, np.float32))

    def part(self, rows: slice) -> "Keypoints":
        """Some of the keypoints: ``slice(n)`` the ``n`` strongest (detection sorts them
        strongest first)."""
        return Keypoints(s=self.s, xy=self.xy[rows], response=self.response[rows])


@dataclass(frozen=True)
class Contrast:
    """How strong an image's structure and noise are, measured once on the s = 1 image."""

    #: the ``contrast_percentile`` of the gradient magnitude at sigma, grey levels/px
    gradient: float
    noise_std: float  #: estimated noise std, grey levels (Immerkaer 1996; texture inflates it)


def noise_std(image: np.ndarray) -> float:
    """Noise std (grey levels) of ``image`` (H, W) by Immerkaer's method (CVIU 64(2), 1996).

    The mean absolute response to the 3x3 difference-of-Laplacians mask, times sqrt(pi/2)/6:
    exact for white Gaussian noise on a locally linear image; texture makes it larger (so the
    noise floor it sets is conservative). Linear in the image: gain g gives g times the value.
    """
    img = np.asarray(image, np.float32)
    if min(img.shape[:2]) < 3:
        return 0.0
    mask = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    r = cv2.filter2D(img, cv2.CV_32F, mask, borderType=cv2.BORDER_REFLECT_101)[1:-1, 1:-1]
    # the mean |r| as OpenCV's L1 norm: np.abs on the strided view was 1 ms of 1.3 (640x480)
    return float(np.sqrt(np.pi / 2.0) / 6.0 * cv2.norm(r, cv2.NORM_L1) / r.size)


class Gradients(NamedTuple):
    """The first Gaussian derivatives of an image at std ``sigma`` px: what its contrast and
    its s = 1 Harris response share (measured once, not twice: 2-3 ms a 1024x768 image)."""

    sigma: float
    ix: np.ndarray  #: (H, W) float32, d/dx
    iy: np.ndarray  #: (H, W) float32, d/dy


def gradients(image: np.ndarray, sigma: float = 1.0) -> Gradients:
    """The :class:`Gradients` of a grey image (H, W) at std ``sigma`` px."""
    img = np.asarray(image, np.float32)
    return Gradients(float(sigma), gaussian_derivative(img, sigma, 1, 0),
                     gaussian_derivative(img, sigma, 0, 1))


def image_contrast(image: np.ndarray, params: "HarrisParams" = HarrisParams(),
                   grads: Optional[Gradients] = None) -> Contrast:
    """The :class:`Contrast` of a grey image (H, W), to be computed once on the s = 1 image.

    ``gradient`` is the ``params.contrast_percentile`` (90th) percentile of the gradient
    magnitude (Gaussian derivatives of std ``params.sigma`` px; ``grads``: those of ``image``,
    when measured already): robust to large flat areas, and exactly proportional to a
    grey-level gain (offset-free). A flat image gives 0.

    >>> rng = np.random.default_rng(0)
    >>> img = rng.uniform(0, 255, (64, 64)).astype(np.float32)
    >>> a, b = image_contrast(img), image_contrast(img / 16 + 3)
    >>> round(a.gradient / b.gradient, 3), round(a.noise_std / b.noise_std, 3)
    (16.0, 16.0)
    >>> image_contrast(img, HarrisParams(), gradients(img, 1.0)) == a
    True
    """
    img = np.asarray(image, np.float32)
    sigma = params.sigma
    if grads is None or round(grads.sigma, 6) != round(float(sigma), 6) or \
            grads.ix.shape != img.shape:
        grads = gradients(img, sigma)
    step = params.contrast_sample_step
    gx = np.ascontiguousarray(grads.ix[::step, ::step])
    gy = np.ascontiguousarray(grads.iy[::step, ::step])
    return Contrast(gradient=percentile(cv2.magnitude(gx, gy), params.contrast_percentile),
                    noise_std=noise_std(img))


def percentile(values: np.ndarray, q: float) -> float:
    """``np.percentile(values, q)`` (linear interpolation), partitioning ``values`` in place.

    >>> v = np.random.default_rng(0).uniform(0, 9, 1001).astype(np.float32)
    >>> abs(percentile(v.copy(), 90.0) - float(np.percentile(v, 90.0))) < 1e-6
    True
    """
    flat = values.reshape(-1)
    n = flat.size
    if n == 0:
        return float("nan")
    pos = q / 100.0 * (n - 1)
    lo = int(math.floor(pos))
    hi = min(lo + 1, n - 1)
    flat.partition(lo)  # one selection; the next order statistic is the least of the rest
    a = float(flat[lo])
    b = float(flat[hi:].min()) if hi > lo else a  # (half the time of partition([lo, hi]))
    return a + (b - a) * (pos - lo)


def noise_floor(contrast: Contrast, s: float = 1.0,
                params: "HarrisParams" = HarrisParams()) -> float:
    """Response (C units) below which a local maximum at scale ``s`` may be noise:
    ``noise_margin`` times the largest response of pure noise of the image's noise std
    (``noise_response_per_std4`` at s = 1, falling as ``s^-noise_scale_exponent``)."""
    return (params.noise_margin * params.noise_response_per_std4 * contrast.noise_std ** 4
            / max(s, 1.0) ** params.noise_scale_exponent)


def effective_threshold(params: "HarrisParams", contrast: Optional[Contrast] = None,
                        s: float = 1.0) -> float:
    """The cornerness threshold used at scale ``s`` on an image of ``contrast``.

    ``params.threshold`` when ``contrast_relative`` is off; otherwise
    ``threshold * min(contrast_cap, (c / reference_contrast)^4)``, but not below
    :func:`noise_floor` at ``s`` (nor above ``threshold * contrast_cap``).

    >>> p = HarrisParams(contrast_relative=True)
    >>> effective_threshold(p, Contrast(gradient=6.0, noise_std=0.0))  # half the reference
    6.25
    >>> effective_threshold(p, Contrast(gradient=24.0, noise_std=0.0))  # capped at 1x
    100.0
    """
    if not params.contrast_relative:
        return float(params.threshold)
    if contrast is None:
        raise ValueError("contrast_relative needs the image's contrast: pass "
                         "contrast=image_contrast(image) computed on the s = 1 image")
    factor = min(params.contrast_cap, (contrast.gradient / params.reference_contrast) ** 4)
    top = params.threshold * params.contrast_cap
    return float(min(max(params.threshold * factor, noise_floor(contrast, s, params)), top))


def harris_response(level: Level, params: HarrisParams,
                    grads: Optional[Gradients] = None) -> np.ndarray:
    """Normalised cornerness C_s on ``level`` (level pixel grid), float32.

    ``grads``: the level image's :class:`Gradients` at the derivation std of this level,
    when measured already (the s = 1 image's, shared with :func:`image_contrast`); not changed.
    """
    s = level.s
    sd = level.sigma_on_level(s * params.sigma)
    si = s * params.sigma_tilde / level.d
    img = level.image
    own = grads is None or round(grads.sigma, 6) != round(sd, 6) or grads.ix.shape != img.shape
    if own:
        ix = gaussian_derivative(img, sd, 1, 0)
        iy = gaussian_derivative(img, sd, 0, 1)
    else:
        ix, iy = grads.ix, grads.iy
    norm = np.float32((s / level.d) ** 2)  # s^2 of the paper, with level -> full-res units
    # in place where the arrays are this function's own: the same float32 operations, in the
    # same order, as the expression C = a b - c^2 - (alpha tr) tr, with fewer temporaries
    a = gaussian_blur(ix * ix, si)
    a *= norm
    b = gaussian_blur(iy * iy, si)
    b *= norm
    c = gaussian_blur(np.multiply(ix, iy, out=ix if own else None), si)
    c *= norm
    tr = a + b
    a *= b
    c *= c
    a -= c
    tr2 = np.multiply(tr, np.float32(params.alpha), out=iy if own else None)
    tr2 *= tr
    a -= tr2
    return a


def _local_maxima(resp: np.ndarray, radius: float, threshold: float, border: float) -> np.ndarray:
    """(row, col) of strict-enough local maxima above ``threshold``, away from the border,
    in row-major order (int64, (N, 2))."""
    r = max(int(round(radius)), 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    dil = cv2.dilate(resp, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=-np.inf)
    # OpenCV's comparisons and scan: a third of numpy's (resp >= dil) & (resp > t), argwhere
    mask = cv2.compare(resp, dil, cv2.CMP_GE)
    mask &= cv2.compare(resp, np.float32(threshold).item(), cv2.CMP_GT)
    b = int(np.ceil(border))
    if b > 0:
        mask[:b, :] = 0
        mask[-b:, :] = 0
        mask[:, :b] = 0
        mask[:, -b:] = 0
    found = cv2.findNonZero(mask)  # (x, y) in row-major order, or None
    if found is None:
        return np.zeros((0, 2), np.int64)
    return found.reshape(-1, 2)[:, ::-1].astype(np.int64)


def _subpixel(resp: np.ndarray, rc: np.ndarray) -> np.ndarray:
    """Quadratic-fit offsets (drow, dcol), each clipped to [-0.5, 0.5]."""
    h, w = resp.shape
    r = np.clip(rc[:, 0], 1, h - 2)
    c = np.clip(rc[:, 1], 1, w - 2)
    f0 = resp[r, c]
    dx = 0.5 * (resp[r, c + 1] - resp[r, c - 1])
    dy = 0.5 * (resp[r + 1, c] - resp[r - 1, c])
    dxx = resp[r, c + 1] - 2 * f0 + resp[r, c - 1]
    dyy = resp[r + 1, c] - 2 * f0 + resp[r - 1, c]
    dxy = 0.25 * (resp[r + 1, c + 1] - resp[r + 1, c - 1] - resp[r - 1, c + 1] + resp[r - 1, c - 1])
    det = dxx * dyy - dxy * dxy
    ok = det > 1e-12 * np.maximum(np.abs(f0), 1.0) ** 2
    safe = np.where(ok, det, 1.0)
    ox = np.where(ok, -(dyy * dx - dxy * dy) / safe, 0.0)
    oy = np.where(ok, -(dxx * dy - dxy * dx) / safe, 0.0)
    return np.stack([np.clip(oy, -0.5, 0.5), np.clip(ox, -0.5, 0.5)], axis=1)


def _level_contrast(level: Level, params: HarrisParams, contrast: Optional[Contrast],
                    grads: Optional[Gradients]):
    """(contrast, gradients) for detecting ``level``: the contrast measured here, from the
    gradients, when adaptive detection needs it on the s = 1 image itself (no blur, no
    decimation); gradients only for that image (None elsewhere)."""
    first = level.d == 1.0 and level.blur == 0.0 and level.s == 1.0
    grads = grads if first else None
    if contrast is not None or not params.adaptive:
        return contrast, grads
    if not first:
        raise ValueError(f"adaptive detection at s = {level.s:g} needs the image's contrast: "
                         f"pass contrast=image_contrast(image) computed on the s = 1 image")
    grads = gradients(level.image, params.sigma) if grads is None else grads
    return image_contrast(level.image, params, grads), grads


def detect_on_level(level: Level, params: HarrisParams = HarrisParams(),
                    contrast: Optional[Contrast] = None,
                    grads: Optional[Gradients] = None,
                    inside: Optional[np.ndarray] = None, margin_px: float = 0.0) -> Keypoints:
    """Scale-adapted Harris points of one scale-space level, in full-resolution pixels.

    ``contrast`` (:func:`image_contrast` of the s = 1 image) is needed when ``params.adaptive``;
    at s = 1 on an undecimated level it is measured here when not given. ``grads``: the s = 1
    image's :class:`Gradients` at ``params.sigma`` when measured already (the same points).
    ``inside``: (H, W) distance (full-resolution px) from each pixel to the nearest pixel that
    shows no scene (:func:`scalematch.stages.nodata.distance_inside`); maxima closer than
    ``margin_px * s`` are dropped before the strongest are kept, so the strong corners along a
    no-data edge take no place among them.
    """
    h, w = level.image.shape
    radius = params.nms_radius * level.s / level.d
    border = params.border * level.s / level.d
    if min(h, w) <= 2 * int(np.ceil(border)) + 2:
        return Keypoints.empty(level.s)
    contrast, grads = _level_contrast(level, params, contrast, grads)
    resp = harris_response(level, params, grads)
    threshold = effective_threshold(params, contrast, level.s)
    if params.min_points > 0:  # every maximum above the noise floor, the budget picks from them
        floor = max(noise_floor(contrast, level.s, params), 0.0)
        rc = _local_maxima(resp, radius, min(floor, threshold), border)
    else:
        rc = _local_maxima(resp, radius, threshold, border)
    if inside is not None and rc.shape[0]:
        rc = rc[away_from(inside, level.to_full(rc[:, ::-1].astype(np.float64)),
                          margin_px * level.s)]
    if rc.shape[0] == 0:
        return Keypoints.empty(level.s)
    score = resp[rc[:, 0], rc[:, 1]]
    order = np.argsort(-score, kind="stable")
    if params.min_points > 0:
        passed = int(np.count_nonzero(score > threshold))
        order = order[: max(passed, params.min_points)]
    if params.max_points > 0:
        order = order[: params.max_points]
    rc, score = rc[order], score[order]
    pos = rc.astype(np.float64)
    if params.subpixel:
        pos += _subpixel(resp, rc)
    xy_level = pos[:, ::-1]
    return Keypoints(s=level.s, xy=level.to_full(xy_level), response=score.astype(np.float32))


#: The paper's eight scales (section 5: sigma, 2 sigma, ..., 8 sigma).
PAPER_SCALES = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0)


def detect(image: np.ndarray, scales: Sequence[float] = PAPER_SCALES,
           params: HarrisParams = HarrisParams(),
           contrast: Optional[Contrast] = None) -> List[Keypoints]:
    """Scale-adapted Harris points of ``image`` at every scale in ``scales``.

    Parameters
    ----------
    image : (H, W) array
        Grey image in grey levels (8-bit range).
    scales : sequence of float
        Scales s (>= 1); 1 gives the standard Harris detector with sigma, sigma~.
    params : HarrisParams
    contrast : Contrast, optional
        The image's contrast for adaptive detection (``params.adaptive``); measured on
        ``image`` when not given.

    Returns
    -------
    list of Keypoints
        One per scale, in the order given; an image with no corners gives empty (0, 2) arrays.

    >>> square = np.zeros((64, 64), np.float32)
    >>> square[16:48, 16:48] = 255.0
    >>> at_1, at_2 = detect(square, scales=(1, 2))
    >>> len(at_1), sorted(at_1.xy.round().tolist())      # its four corners, (x, y) px
    (4, [[17.0, 17.0], [17.0, 46.0], [46.0, 17.0], [46.0, 46.0]])
    >>> len(detect(np.zeros((64, 64), np.float32))[0])   # flat: no point, not an error
    0
    """
    if params.adaptive and contrast is None:
        contrast = image_contrast(as_float_image(image), params)
    levels = scale_space(image, scales, sigma=params.sigma,
                         min_level_sigma=params.min_level_sigma, decimate=params.decimate,
                         camera_blur_px=params.camera_blur_px)
    return [detect_on_level(level, params, contrast) for level in levels]


def detect_one(image: np.ndarray, s: float = 1.0, params: HarrisParams = HarrisParams(),
               contrast: Optional[Contrast] = None) -> Keypoints:
    """Harris points of ``image`` at the single scale ``s``."""
    return detect(image, (s,), params, contrast)[0]
