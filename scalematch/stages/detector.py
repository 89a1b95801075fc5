"""Stage 2: scale-adapted Harris interest points (ALGORITHM.md step 2, paper section 3).

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
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import List, Optional, Sequence

import cv2
import numpy as np

from ..checks import in_range
from .filters import gaussian_derivative
from .scalespace import Level, gaussian_blur, scale_space


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

    def __post_init__(self) -> None:
        for name in ("sigma", "sigma_tilde", "min_level_sigma"):
            in_range("harris", name, getattr(self, name), lo=0, lo_open=True)
        # alpha >= 0.25 makes every cornerness negative (det <= tr^2 / 4)
        in_range("harris", "alpha", self.alpha, lo=0, hi=0.25, hi_open=True)
        for name in ("threshold", "nms_radius", "border"):
            in_range("harris", name, getattr(self, name), lo=0)
        in_range("harris", "max_points", self.max_points, lo=0, integer=True)


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


def harris_response(level: Level, params: HarrisParams) -> np.ndarray:
    """Normalised cornerness C_s on ``level`` (level pixel grid), float32."""
    s = level.s
    sd = level.sigma_on_level(s * params.sigma)
    si = s * params.sigma_tilde / level.d
    img = level.image
    ix = gaussian_derivative(img, sd, 1, 0)
    iy = gaussian_derivative(img, sd, 0, 1)
    norm = np.float32((s / level.d) ** 2)  # s^2 of the paper, with level -> full-res units
    a = gaussian_blur(ix * ix, si) * norm
    b = gaussian_blur(iy * iy, si) * norm
    c = gaussian_blur(ix * iy, si) * norm
    del ix, iy
    tr = a + b
    out = a * b
    out -= c * c
    out -= np.float32(params.alpha) * tr * tr
    return out


def _local_maxima(resp: np.ndarray, radius: float, threshold: float, border: float) -> np.ndarray:
    """(row, col) of strict-enough local maxima above ``threshold``, away from the border."""
    r = max(int(round(radius)), 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    dil = cv2.dilate(resp, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=-np.inf)
    mask = (resp >= dil) & (resp > threshold)
    b = int(np.ceil(border))
    if b > 0:
        mask[:b, :] = False
        mask[-b:, :] = False
        mask[:, :b] = False
        mask[:, -b:] = False
    return np.argwhere(mask)


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


def detect_on_level(level: Level, params: HarrisParams = HarrisParams()) -> Keypoints:
    """Scale-adapted Harris points of one scale-space level, in full-resolution pixels."""
    h, w = level.image.shape
    radius = params.nms_radius * level.s / level.d
    border = params.border * level.s / level.d
    if min(h, w) <= 2 * int(np.ceil(border)) + 2:
        return Keypoints.empty(level.s)
    resp = harris_response(level, params)
    rc = _local_maxima(resp, radius, params.threshold, border)
    if rc.shape[0] == 0:
        return Keypoints.empty(level.s)
    score = resp[rc[:, 0], rc[:, 1]]
    order = np.argsort(-score, kind="stable")
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
           params: HarrisParams = HarrisParams()) -> List[Keypoints]:
    """Scale-adapted Harris points of ``image`` at every scale in ``scales``.

    Parameters
    ----------
    image : (H, W) array
        Grey image in grey levels (8-bit range).
    scales : sequence of float
        Scales s (>= 1); 1 gives the standard Harris detector with sigma, sigma~.
    params : HarrisParams

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
    levels = scale_space(image, scales, sigma=params.sigma,
                         min_level_sigma=params.min_level_sigma, decimate=params.decimate)
    return [detect_on_level(level, params) for level in levels]


def detect_one(image: np.ndarray, s: float = 1.0,
               params: HarrisParams = HarrisParams()) -> Keypoints:
    """Harris points of ``image`` at the single scale ``s``."""
    return detect(image, (s,), params)[0]


def response_at(image: np.ndarray, s: float, params: Optional[HarrisParams] = None) -> np.ndarray:
    """The normalised response C_s at full resolution (no decimation): for checks and figures."""
    params = params or HarrisParams()
    level = next(scale_space(image, (s,), sigma=params.sigma, decimate=False))
    return harris_response(level, params)
