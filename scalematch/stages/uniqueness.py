"""The uniqueness test: does the finer image, warped by a claim, fit its own place in the coarser
image better than any placement elsewhere (half a footprint away and more)?

A repeated structure (the windows of a facade, the panels of a bus) matches wherever a copy of
it stands; a true match fits its own place better than any copy (the pixels are the same ones,
not alike ones). Both tests slide one :class:`Template` of the claim (``unique_template``) over
the whole coarser image:

* ``uniqueness``: one ZNCC over the template, the misfit elsewhere against the misfit at the
  claim (``Uniqueness.ratio``);
* ``window_agreement``: the template cut into windows, the share that agree at the claim
  against the highest share elsewhere (``Agreement``).

Where the pixels are compared: only where both images show the scene (NaN marks the rest:
:mod:`scalematch.stages.nodata`), and only near the inliers (``PixelParams.vouch_radius``): an
occluder, a foreground object or a 3-D scene's other planes hold no inlier, and one ZNCC over
the whole footprint would count them against a true map. The placing, blur and warp are
:mod:`scalematch.stages.placing`'s; the parameters are ``PixelParams``
(:mod:`scalematch.stages.pixelcheck`).

Pixel convention: OpenCV's, (x, y), pixel centres at integers. Used by the decision's pixel
tests (:mod:`scalematch.stages.decision`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Optional, Tuple

import cv2
import numpy as np

from ..geometry import apply
from .pixelcheck import PixelParams
from .placing import blurred_for_ratio, place, small_to_high, vouched_mask, warp_into

#: shifts where the footprint overlaps less than this share of its valid pixels with the
#: coarser image's scene are not compared: a partial overlap leaves 30 to 70 % inside
#: (EVALUATION.md, "partial"), and below a quarter the template is a strip
MIN_SHARED = 0.25


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


def masked_zncc(image: np.ndarray, image_valid: np.ndarray, tpl: np.ndarray,
                tpl_valid: np.ndarray, min_shared: float = MIN_SHARED,
                min_std: float = PixelParams.min_std) -> np.ndarray:
    """ZNCC of ``tpl`` at every placement inside ``image`` ((H - h + 1, W - w + 1) float32),
    over the pixels valid in both (:func:`masked_zncc_map` when only the template has a mask) (``image_valid``, ``tpl_valid``: bool masks of their shapes);
    -1 where they share less than ``min_shared`` of the template's valid pixels or either is
    flat there. Six unmasked correlations (each DFT-based in OpenCV): the shared count, the
    sums and sums of squares of either side over the shared pixels, and the cross term
    (Padfield, "Masked object registration in the Fourier domain", IEEE TIP 2012).

    >>> rng = np.random.default_rng(0)
    >>> img = rng.uniform(0, 255, (40, 50)).astype(np.float32)
    >>> ok = np.ones(img.shape, bool); ok[:, :10] = False    # no scene on the left
    >>> m = np.ones((10, 12), bool)
    >>> r = masked_zncc(np.where(ok, img, 0), ok, img[5:15, 7:19], m)
    >>> [int(v) for v in np.unravel_index(np.argmax(r), r.shape)], round(float(r.max()), 4)
    ([5, 7], 1.0)
    """
    def corr(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return cv2.matchTemplate(a, b, cv2.TM_CCORR)

    mi, mt = image_valid.astype(np.float32), tpl_valid.astype(np.float32)
    im = np.where(image_valid, image, 0).astype(np.float32)
    tp = np.where(tpl_valid, tpl, 0).astype(np.float32)
    n = corr(mi, mt)
    s_t, s_tt = corr(mi, tp), corr(mi, tp * tp)
    s_i, s_ii = corr(im, mt), corr(im * im, mt)
    s_ti = corr(im, tp)
    nn = np.maximum(n, 1.0)
    var_t = s_tt - s_t * s_t / nn  # n times each side's variance over the shared pixels
    var_i = s_ii - s_i * s_i / nn
    ok = (n >= min_shared * float(mt.sum())) & (var_t > nn * min_std ** 2) & \
        (var_i > nn * min_std ** 2)
    out = (s_ti - s_t * s_i / nn) / np.sqrt(np.where(ok, var_t * var_i, 1.0))
    return np.where(ok, np.clip(out, -1.0, 1.0), -1.0).astype(np.float32)


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
    placed = place(np.asarray(low, np.float32), high.shape, t, params.min_overlap_px,
                   params.unique_side_px)
    if isinstance(placed, str):
        return None
    low, t3, ratio, _, _ = placed
    small, k = blurred_for_ratio(high, ratio, params.camera_blur_px)
    hh, ww = low.shape
    img, mask = warp_into(small, t3 @ small_to_high(k), (ww, hh), params.edge_px)
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
