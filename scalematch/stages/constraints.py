"""Stage 5: geometric constraints on candidate matches (docs/ALGORITHM.md step 5, paper 4.1).

**Semi-local constraints (the paper).** A candidate (m, m') is supported by the other candidates
(m_j, m'_j) with m_j in the neighbourhood N(m) of m in the high image (radius grows with s) and
m'_j in N(m') in the low image: two matches define a similarity; the paper explores the pairs
depth first, keeping the similarity that the most neighbours agree with. A candidate is kept
when enough neighbours agree (``SemiLocalParams.min_support``), and a final check with the
paper's correlation measure (eq. 5) compares the two patches once the high-resolution patch is
warped by the local similarity.

**Orientation consistency (the default).** With oriented descriptors each candidate carries an
angle difference; true matches share the rotation of the transform, random ones spread over the
circle. Candidates whose angle difference is near the peak of that distribution are kept (a
one-dimensional Hough transform, Lowe 2004 section 7.3).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, List, Mapping

import cv2
import numpy as np

from ..checks import AT_LEAST_ONE, Bounds, CORRELATION, COUNT, FACTOR, POSITIVE, SHARE, check_bounds
from .scalespace import Level

# --------------------------------------------------------------- orientation consistency (default)


@dataclass(frozen=True)
class OrientationParams:
    """The rotation-consistency groups (``Config.orientation``): the histogram of the rotations
    the candidates imply, and the peaks whose candidates are fitted."""

    bins: int = 36  #: histogram bins over 360 degrees (10 degrees each, as Lowe's pose bins: 30)
    tolerance_deg: float = 20.0  #: kept around a peak (orientation error of true matches ~5-10)
    second_peak: float = 0.5  #: a second peak at least this fraction of the first is also tried
    max_peaks: int = 2  #: peaks tried at most

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "bins": AT_LEAST_ONE,
        "tolerance_deg": Bounds(lo=0, hi=180, lo_open=True),
        "second_peak": SHARE,
        "max_peaks": AT_LEAST_ONE,
    }

    def __post_init__(self) -> None:
        check_bounds("orientation", self, self.BOUNDS)


def orientation_groups(dtheta: np.ndarray, params: OrientationParams = OrientationParams()
                       ) -> List[np.ndarray]:
    """Boolean masks of candidates consistent with each of the strongest rotation peaks.

    ``dtheta`` (K,) radians: angle in the low image minus angle in the high image.
    """
    k = dtheta.shape[0]
    if k == 0:
        return []
    nb = params.bins
    a = np.mod(dtheta, 2 * np.pi)
    hist = np.bincount((a * nb / (2 * np.pi)).astype(int) % nb, minlength=nb).astype(float)
    smooth = np.roll(hist, 1) + hist + np.roll(hist, -1)
    order = np.argsort(-smooth, kind="stable")
    tol = np.radians(params.tolerance_deg)
    groups: List[np.ndarray] = []
    used = np.zeros(nb, bool)
    for b in order:
        if len(groups) >= params.max_peaks or smooth[b] < params.second_peak * smooth[order[0]]:
            break
        if used[b] or smooth[b] <= 0:
            continue
        # the peak angle: circular mean of the candidates in the 3 bins around b
        centre = (b + 0.5) * 2 * np.pi / nb
        near = np.abs(np.angle(np.exp(1j * (a - centre)))) <= 1.5 * 2 * np.pi / nb
        peak = np.angle(np.mean(np.exp(1j * a[near]))) if near.any() else centre
        mask = np.abs(np.angle(np.exp(1j * (a - peak)))) <= tol
        groups.append(mask)
        span = int(np.ceil(params.tolerance_deg / (360.0 / nb)))
        for o in range(-span, span + 1):
            used[(b + o) % nb] = True
    return groups


# ------------------------------------------------------------------ semi-local constraints (paper)


@dataclass(frozen=True)
class SemiLocalParams:
    """The paper's semi-local constraints (``Config.semi_local``): a candidate is kept when
    enough of its neighbours agree with a local similarity through it and its patches
    correlate (eq. 5)."""

    #: neighbourhood radius in the low image, px; in the high image it is ``radius_px * s``
    #: (the high image at scale s is the low one zoomed in by about s). The paper leaves it open;
    #: 30 px holds some tens of Harris points at the default threshold.
    radius_px: float = 30.0
    max_neighbours: int = 20  #: nearest neighbours explored per candidate (depth-first bound)
    tolerance_px: float = 3.0  #: a neighbour agrees with a local similarity within this, low px
    #: the local similarity's scale must be within this factor of 1/s (the scale being matched)
    scale_tolerance: float = 1.5
    min_support: int = 2  #: agreeing neighbours besides the pair defining the similarity
    #: final check (paper eq. 5): zero-mean normalised SSD of the two patches, as a correlation
    correlation_min: float = 0.5
    patch_radius_px: float = 6.0  #: half-size of the correlation patches, low px

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "radius_px": POSITIVE,
        "tolerance_px": POSITIVE,
        "patch_radius_px": POSITIVE,
        "max_neighbours": AT_LEAST_ONE,
        "scale_tolerance": FACTOR,
        "min_support": COUNT,
        "correlation_min": CORRELATION,
    }

    def __post_init__(self) -> None:
        check_bounds("semi_local", self, self.BOUNDS)


def semi_local_support(p: np.ndarray, q: np.ndarray, s: float,
                       params: SemiLocalParams = SemiLocalParams()):
    """Support of each candidate (K,) and its best local similarity (a, b) (complex, (K,)).

    ``p`` (K, 2) high px, ``q`` (K, 2) low px of the candidates at scale ``s``.
    """
    k = p.shape[0]
    support = np.zeros(k, int)
    best_a = np.full(k, np.nan + 0j)
    best_b = np.full(k, np.nan + 0j)
    if k < 3:
        return support, best_a, best_b
    rh = params.radius_px * s
    rl = params.radius_px
    zp = p[:, 0] + 1j * p[:, 1]
    zq = q[:, 0] + 1j * q[:, 1]
    for c in range(k):
        dh = np.abs(zp - zp[c])
        dl = np.abs(zq - zq[c])
        nb = np.nonzero((dh <= rh) & (dl <= rl) & (dh > 1e-6) & (dl > 1e-6))[0]
        if nb.size < 2:
            continue
        if nb.size > params.max_neighbours:
            nb = nb[np.argsort(dh[nb])[: params.max_neighbours]]
        # depth 1: similarity from (c, n) for every neighbour n; depth 2: count agreeing others
        dp = zp[nb] - zp[c]
        a = (zq[nb] - zq[c]) / dp
        scale_ok = np.abs(np.log(np.abs(a) * s)) <= np.log(params.scale_tolerance)
        if not scale_ok.any():
            continue
        a = a[scale_ok]
        b = zq[c] - a * zp[c]
        pred = a[:, None] * zp[nb][None, :] + b[:, None]
        agree = np.abs(pred - zq[nb][None, :]) <= params.tolerance_px
        votes = agree.sum(axis=1) - 1  # the neighbour defining the similarity agrees trivially
        w = int(np.argmax(votes))
        support[c] = votes[w]
        best_a[c], best_b[c] = a[w], b[w]
    return support, best_a, best_b


def _zncc(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    x = x - x.mean(axis=1, keepdims=True)
    y = y - y.mean(axis=1, keepdims=True)
    den = np.sqrt((x * x).sum(1) * (y * y).sum(1))
    return np.where(den > 1e-9, (x * y).sum(1) / np.maximum(den, 1e-9), 0.0)


def correlation_check(high_level: Level, low_image: np.ndarray, q: np.ndarray, a: np.ndarray,
                      b: np.ndarray, params: SemiLocalParams = SemiLocalParams()) -> np.ndarray:
    """Correlation (K,) of the low patch at ``q`` with the high patch warped by (a, b).

    Paper eq. 5 is a sum of squared differences; computed on zero-mean, unit-norm patches it is
    ``2 - 2 * ZNCC``, which also absorbs the grey-level change I -> aI + b, so the ZNCC is returned.
    """
    k = q.shape[0]
    if k == 0:
        return np.zeros(0)
    r = int(np.ceil(params.patch_radius_px))
    oy, ox = np.mgrid[-r:r + 1, -r:r + 1]
    zo = (ox + 1j * oy).ravel()
    zq = q[:, 0] + 1j * q[:, 1]
    pts_low = zq[:, None] + zo[None, :]  # (K, P) low px
    pts_high = (pts_low - b[:, None]) / a[:, None]  # back into high px
    lv = high_level.to_level(np.stack([pts_high.real.ravel(), pts_high.imag.ravel()], 1))
    hp = cv2.remap(high_level.image, lv[:, 0].astype(np.float32).reshape(k, -1),
                   lv[:, 1].astype(np.float32).reshape(k, -1), cv2.INTER_LINEAR,
                   borderMode=cv2.BORDER_REFLECT_101)
    lp = cv2.remap(low_image, pts_low.real.astype(np.float32), pts_low.imag.astype(np.float32),
                   cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
    return _zncc(hp.astype(np.float64), lp.astype(np.float64))


def semi_local_filter(p: np.ndarray, q: np.ndarray, high_level: Level, low_image: np.ndarray,
                      params: SemiLocalParams = SemiLocalParams()) -> np.ndarray:
    """Boolean mask (K,) of candidates kept by the semi-local constraints and eq. 5."""
    support, a, b = semi_local_support(p, q, high_level.s, params)
    keep = support >= params.min_support
    if keep.any():
        idx = np.nonzero(keep)[0]
        corr = correlation_check(high_level, low_image, q[idx], a[idx], b[idx], params)
        keep[idx[corr < params.correlation_min]] = False
    return keep
