"""Stage 3: descriptors of interest points (docs/ALGORITHM.md step 3, paper section 4).

Two descriptors, both computed on a scale-space :class:`~scalematch.stages.scalespace.Level` for all the
points of one scale in one vectorised pass.

**Local-jet invariants (the paper, ``mode="paper"``).** With ``L`` the image smoothed by a
Gaussian of std ``sigma_j`` (the point's scale times ``JetParams.scale_factor``) and ``L_i``,
``L_ij``, ``L_ijk`` its derivatives (Einstein summation over x, y; ``eps`` the antisymmetric
tensor, eps_xy = 1, eps_yx = -1), the differential invariants of Koenderink & van Doorn (1987)
as used by Schmid & Mohr (PAMI 1997) are::

    v1 = L_i L_i                                  (squared gradient magnitude)
    v2 = L_i L_ij L_j
    v3 = L_ii                                     (Laplacian)
    v4 = L_ij L_ji
    v5 = eps_ij (L_jkl L_i L_k L_l - L_jkk L_i L_l L_l)
    v6 = L_iij L_j L_k L_k - L_ijk L_i L_j L_k
    v7 = -eps_ij L_jkl L_i L_k L_l
    v8 = L_ijk L_i L_j L_k

(``v0 = L`` is dropped.) Each is invariant to image rotation by construction. Under a grey-level
change ``I -> a I + b`` the derivatives scale by ``a``, so dividing by the matching power of the
gradient magnitude ``g = sqrt(v1)`` removes ``a``; multiplying by the matching power of
``sigma_j`` makes them dimensionless (the same at scale s of the high image and at scale 1 of the
low one). The descriptor is the 7-vector::

    ( sigma v2 / g^3,  sigma v3 / g,  sigma^2 v4 / g^2,
      sigma^2 v5 / g^4,  sigma^2 v6 / g^4,  sigma^2 v7 / g^4,  sigma^2 v8 / g^4 )

**Oriented gradient histograms (``mode="default"``).** The improvement that closes the gap to
the targets: at the same scale-adapted Harris points, a dominant gradient orientation (a 36-bin
histogram, Lowe 2004 section 5) and, in a window turned to that orientation, 4x4 cells of 8-bin
gradient-orientation histograms (Lowe 2004 section 6), L2-normalised, clipped at 0.2, then
square-rooted (RootSIFT, Arandjelovic & Zisserman 2012) so that Euclidean distance compares
them well. All lengths are in level pixels: at scale s a level is the image zoomed out by about
s, the same pixel size as the low image at s = 1, so one window size serves both images.
"""

from __future__ import annotations

from typing import ClassVar, Mapping

import functools
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..checks import AT_LEAST_ONE, Bounds, NON_NEGATIVE, POSITIVE, SHARE, check_bounds
from .filters import gaussian_derivative
from .scalespace import Level, gaussian_blur

# --------------------------------------------------------------------------- local jet (paper)


@dataclass(frozen=True)
class JetParams:
    """Local-jet invariants (paper section 4)."""

    #: jet std = scale_factor * s * sigma~ ... in full-resolution px; the detection's integration
    #: scale (sigma~ = 2 at s = 1) is the natural size of the point's neighbourhood.
    scale_factor: float = 1.0
    #: floor on the gradient magnitude (grey levels / px) before dividing by it: keeps a
    #: point with a vanishing gradient from blowing its invariants up.
    min_gradient: float = 0.5

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "scale_factor": POSITIVE,
        "min_gradient": POSITIVE,
    }

    def __post_init__(self) -> None:
        check_bounds("jets", self, self.BOUNDS)


#: Number of local-jet invariants in the descriptor (v2..v8).
JET_DIM = 7

_EPS = np.array([[0.0, 1.0], [-1.0, 0.0]])


def _sample(image: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``image`` at level coordinates (N, 2); (N,) float64."""
    h, w = image.shape
    x = np.clip(xy[:, 0], 0, w - 1.001)
    y = np.clip(xy[:, 1], 0, h - 1.001)
    x0 = np.floor(x).astype(int)
    y0 = np.floor(y).astype(int)
    fx = x - x0
    fy = y - y0
    i = image
    return ((1 - fx) * (1 - fy) * i[y0, x0] + fx * (1 - fy) * i[y0, x0 + 1]
            + (1 - fx) * fy * i[y0 + 1, x0] + fx * fy * i[y0 + 1, x0 + 1]).astype(np.float64)


def local_jet(level: Level, xy_full: np.ndarray, sigma_full: float):
    """Derivatives up to order 3 at ``sigma_full`` (full-res px), in full-resolution units.

    Returns (L1 (N, 2), L2 (N, 2, 2), L3 (N, 2, 2, 2)) with index order (x, y).
    """
    sd = max(level.sigma_on_level(sigma_full), 0.5)
    xy = level.to_level(np.asarray(xy_full, dtype=np.float64))
    n = xy.shape[0]
    d = {}
    for ox, oy in ((1, 0), (0, 1), (2, 0), (1, 1), (0, 2), (3, 0), (2, 1), (1, 2), (0, 3)):
        d[ox, oy] = _sample(gaussian_derivative(level.image, sd, ox, oy), xy) / level.d ** (ox + oy)
    l1 = np.stack([d[1, 0], d[0, 1]], axis=1)
    l2 = np.empty((n, 2, 2))
    l2[:, 0, 0], l2[:, 0, 1], l2[:, 1, 0], l2[:, 1, 1] = d[2, 0], d[1, 1], d[1, 1], d[0, 2]
    l3 = np.empty((n, 2, 2, 2))
    for i in range(2):
        for j in range(2):
            for k in range(2):
                ny = i + j + k
                l3[:, i, j, k] = d[3 - ny, ny]
    return l1, l2, l3


def jet_invariants(l1: np.ndarray, l2: np.ndarray, l3: np.ndarray, sigma: float,
                   min_gradient: float = JetParams.min_gradient) -> np.ndarray:
    """The 7 rotation- and grey-level-invariant descriptors (module docstring), (N, 7)."""
    v1 = np.einsum("ni,ni->n", l1, l1)
    v2 = np.einsum("ni,nij,nj->n", l1, l2, l1)
    v3 = np.einsum("nii->n", l2)
    v4 = np.einsum("nij,nji->n", l2, l2)
    jkl_kl = np.einsum("njkl,nk,nl->nj", l3, l1, l1)  # L_jkl L_k L_l (free index j)
    jkk = np.einsum("njkk->nj", l3)
    v5 = (np.einsum("ij,ni,nj->n", _EPS, l1, jkl_kl)
          - np.einsum("ij,ni,nj->n", _EPS, l1, jkk) * v1)
    v6 = np.einsum("niij,nj->n", l3, l1) * v1 - np.einsum("nijk,ni,nj,nk->n", l3, l1, l1, l1)
    v7 = -np.einsum("ij,ni,nj->n", _EPS, l1, jkl_kl)
    v8 = np.einsum("nijk,ni,nj,nk->n", l3, l1, l1, l1)
    g = np.maximum(np.sqrt(v1), min_gradient)
    s = sigma
    return np.stack([s * v2 / g ** 3, s * v3 / g, s * s * v4 / g ** 2, s * s * v5 / g ** 4,
                     s * s * v6 / g ** 4, s * s * v7 / g ** 4, s * s * v8 / g ** 4], axis=1)


def describe_jets(level: Level, xy_full: np.ndarray, sigma_tilde: float,
                  params: JetParams = JetParams()) -> np.ndarray:
    """Jet invariants (N, 7) float32 of points ``xy_full`` (full-res px) detected at ``level.s``."""
    if len(xy_full) == 0:
        return np.zeros((0, JET_DIM), np.float32)
    sigma_full = params.scale_factor * level.s * sigma_tilde
    l1, l2, l3 = local_jet(level, xy_full, sigma_full)
    return jet_invariants(l1, l2, l3, sigma_full, params.min_gradient).astype(np.float32)


# ------------------------------------------------------- oriented gradient histograms (default)


@dataclass(frozen=True)
class GradientParams:
    """Oriented gradient-histogram descriptor; lengths in level px (= low-image px at s = r)."""

    cell_px: float = 4.0  #: width of one of the 4x4 cells (window 16 px: SIFT's 4 cells x 3 sigma)
    grid: int = 4  #: cells per side (Lowe 2004)
    bins: int = 8  #: orientation bins per cell (Lowe 2004)
    #: gradient samples per cell side (Lowe 2004: 4; 2 measured as accurate here, 4x cheaper)
    samples_per_cell: int = 2
    clip: float = 0.2  #: clip of the normalised histogram (Lowe 2004 section 6.1)
    orientation_bins: int = 36  #: orientation histogram bins (Lowe 2004 section 5)
    orientation_radius_px: float = 6.0  #: radius of the orientation window
    orientation_sigma_px: float = 3.0  #: Gaussian weight of the orientation window (1.5 sigma~)
    #: secondary orientation peaks within this fraction of the highest give extra points (Lowe: 0.8)
    secondary_peak: float = 0.8
    presmooth_px: float = 1.0  #: blur before sampling the window every cell_px/2 px (anti-alias)
    orientation_step_px: int = 2  #: the orientation window is sampled every this many px

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "cell_px": POSITIVE,
        "orientation_radius_px": POSITIVE,
        "orientation_sigma_px": POSITIVE,
        "clip": POSITIVE,
        "grid": AT_LEAST_ONE,
        "bins": AT_LEAST_ONE,
        "samples_per_cell": AT_LEAST_ONE,
        "orientation_bins": AT_LEAST_ONE,
        "orientation_step_px": AT_LEAST_ONE,
        "secondary_peak": SHARE,
        "presmooth_px": NON_NEGATIVE,
    }

    def __post_init__(self) -> None:
        check_bounds("gradients", self, self.BOUNDS)


@dataclass(frozen=True)
class Described:
    """Descriptors of the points of one scale; ``index`` maps a row back to its keypoint."""

    s: float
    xy: np.ndarray = field(repr=False)  #: (M, 2) full-resolution px (a point may appear twice)
    index: np.ndarray = field(repr=False)  #: (M,) row of the keypoint in its Keypoints
    angle: np.ndarray = field(repr=False)  #: (M,) orientation, radians (nan for jets)
    desc: np.ndarray = field(repr=False)  #: (M, D) float32

    def __len__(self) -> int:
        return int(self.xy.shape[0])

    def of_strongest(self, n: int) -> "Described":
        """The rows of the ``n`` strongest keypoints (keypoints sorted strongest first: ``index``
        below ``n``), every orientation of each: what describing only those gives, since a
        point's descriptors depend on that point alone."""
        keep = self.index < n
        return Described(s=self.s, xy=self.xy[keep], index=self.index[keep],
                         angle=self.angle[keep], desc=self.desc[keep])


_REMAP_ROWS = 16384


def _gradients_at(image: np.ndarray, px: np.ndarray, py: np.ndarray) -> tuple:
    """Central differences (gx, gy) of a float32 ``image`` at integer pixels (px, py) inside it,
    borders reflected (101): the values of ``cv2.Sobel(image, CV_32F, 1, 0, ksize=1, scale=0.5)`` (and
    0, 1) there, bit for bit, without filtering the whole level for a few hundred points."""
    h, w = image.shape
    img = np.asarray(image, np.float32)

    def after(i: np.ndarray, n: int) -> np.ndarray:  # i + 1, reflected at n (i in [0, n))
        out = i + 1
        out[out == n] = max(n - 2, 0)
        return out

    def before(i: np.ndarray, n: int) -> np.ndarray:  # i - 1, reflected at -1
        out = i - 1
        out[out < 0] = min(1, n - 1)
        return out

    half = np.float32(0.5)
    gx = (img[py, after(px, w)] - img[py, before(px, w)]) * half
    gy = (img[after(py, h), px] - img[before(py, h), px]) * half
    return gx, gy


def _turned(hist: np.ndarray, shift: int) -> np.ndarray:
    """``np.roll(hist, shift, axis=1)`` for a shift of +1 or -1 (a circular histogram's
    neighbour bins), without np.roll's general-case overhead (it was called 6 times per call)."""
    if shift == 1:
        return np.concatenate([hist[:, -1:], hist[:, :-1]], axis=1)
    return np.concatenate([hist[:, 1:], hist[:, :1]], axis=1)


@functools.lru_cache(maxsize=8)
def _orientation_window(params: GradientParams):
    """(ox, oy, weight) of the orientation window's samples, the same for every call with
    ``params`` (worked out once: most calls describe a few dozen points, where building the
    window was a tenth of the call)."""
    step = params.orientation_step_px
    r = int(np.ceil(params.orientation_radius_px))
    oy, ox = np.mgrid[-r:r + 1:step, -r:r + 1:step]
    disk = (ox ** 2 + oy ** 2) <= params.orientation_radius_px ** 2
    ox, oy = ox[disk], oy[disk]
    wgt = np.exp(-(ox ** 2 + oy ** 2) / (2 * params.orientation_sigma_px ** 2))
    for a in (ox, oy, wgt):
        a.setflags(write=False)
    return ox, oy, wgt


def dominant_orientations(image: np.ndarray, xy: np.ndarray, params: GradientParams):
    """Orientations (radians) at level points ``xy`` (N, 2): returns (rows (M,), angles (M,)).

    ``image`` is the level already smoothed by ``presmooth_px`` (enough for sampling gradients
    every ``orientation_step_px`` = 2 px).
    """
    n = xy.shape[0]
    if n == 0:
        return np.zeros(0, int), np.zeros(0)
    ox, oy, wgt = _orientation_window(params)
    h, w = image.shape
    cx = np.rint(xy[:, 0]).astype(int)
    cy = np.rint(xy[:, 1]).astype(int)
    px = np.clip(cx[:, None] + ox[None, :], 0, w - 1)
    py = np.clip(cy[:, None] + oy[None, :], 0, h - 1)
    vx, vy = _gradients_at(image, px, py)
    mag = np.sqrt(vx * vx + vy * vy) * wgt[None, :]
    nb = params.orientation_bins
    ang = np.arctan2(vy, vx)
    b = (ang + np.pi) * (nb / (2 * np.pi))
    b0 = np.floor(b).astype(int)
    f = b - b0
    rows = np.repeat(np.arange(n), ox.size)
    hist = np.bincount((rows * nb + b0.ravel() % nb), (mag * (1 - f)).ravel(), n * nb)
    hist += np.bincount((rows * nb + (b0.ravel() + 1) % nb), (mag * f).ravel(), n * nb)
    hist = hist.reshape(n, nb)
    for _ in range(2):  # smooth circularly, as Lowe's implementation does
        hist = (_turned(hist, 1) + hist + _turned(hist, -1)) / 3.0
    left, right = _turned(hist, 1), _turned(hist, -1)
    peak = (hist > left) & (hist > right) & (hist >= params.secondary_peak * hist.max(1, keepdims=True))
    peak &= hist > 0
    pr, pb = np.nonzero(peak)
    l, c, rr = left[pr, pb], hist[pr, pb], right[pr, pb]
    den = l - 2 * c + rr
    off = np.where(np.abs(den) > 1e-12, 0.5 * (l - rr) / np.where(den == 0, 1, den), 0.0)
    angles = (pb + 0.5 + off) * (2 * np.pi / nb) - np.pi
    return pr, angles


@functools.lru_cache(maxsize=8)
def _histogram_layout(params: GradientParams):
    """What every call of :func:`gradient_histograms` with ``params`` shares, worked out once:
    the sample grid in the keypoint frame (``uu`` x, ``vv`` y, one extra ring for the
    gradients), the samples' Gaussian weight (ns, ns), and the spatial pooling as one matrix
    (ns * ns, grid * grid): sample (y, x) gives cell (i, j) the weight ``pool[y, i] pool[x, j]``,
    bilinear between cell centres (Lowe's trilinear weights with the orientation's)."""
    g, spc = params.grid, params.samples_per_cell
    ns = spc * g  # samples per side
    step = params.cell_px / spc
    u = (np.arange(ns + 2) - (ns + 1) / 2.0) * step
    uu, vv = np.meshgrid(u, u)  # uu: x in keypoint frame, vv: y
    centre = (np.arange(ns) - (ns - 1) / 2.0) / (ns / 2.0)
    wgt = np.exp(-(centre[:, None] ** 2 + centre[None, :] ** 2) / (2 * 0.5 ** 2))
    pos = (np.arange(ns) + 0.5) / spc - 0.5  # sample position in cell units
    pool = np.clip(1.0 - np.abs(pos[:, None] - np.arange(g)[None, :]), 0.0, 1.0)
    cells = np.kron(pool, pool).astype(np.float32)
    for a in (uu, vv, wgt, cells):
        a.setflags(write=False)
    return uu, vv, wgt, cells


def gradient_histograms(image: np.ndarray, xy: np.ndarray, angles: np.ndarray,
                        params: GradientParams) -> np.ndarray:
    """4x4x8 oriented gradient histograms (M, 128) at level points ``xy`` turned by ``angles``.

    ``image`` is the level already smoothed by ``presmooth_px`` (anti-alias for the sampling).
    """
    m = xy.shape[0]
    g, nb = params.grid, params.bins
    dim = g * g * nb
    if m == 0:
        return np.zeros((0, dim), np.float32)
    ns = params.samples_per_cell * g  # samples per side
    uu, vv, wgt, cells = _histogram_layout(params)
    c, s = np.cos(angles)[:, None, None], np.sin(angles)[:, None, None]
    mapx = (xy[:, 0, None, None] + c * uu - s * vv).astype(np.float32)
    mapy = (xy[:, 1, None, None] + s * uu + c * vv).astype(np.float32)
    mapx = mapx.reshape(m, (ns + 2) ** 2)
    mapy = mapy.reshape(m, (ns + 2) ** 2)
    src = image  # already smoothed by presmooth_px (describe_gradients)
    patch = np.empty_like(mapx)
    for lo in range(0, m, _REMAP_ROWS):  # cv2.remap takes maps of fewer than 32767 rows
        patch[lo:lo + _REMAP_ROWS] = cv2.remap(src, mapx[lo:lo + _REMAP_ROWS],
                                               mapy[lo:lo + _REMAP_ROWS], cv2.INTER_LINEAR,
                                               borderMode=cv2.BORDER_REFLECT_101)
    patch = patch.reshape(m, ns + 2, ns + 2)
    dx = 0.5 * (patch[:, 1:-1, 2:] - patch[:, 1:-1, :-2])
    dy = 0.5 * (patch[:, 2:, 1:-1] - patch[:, :-2, 1:-1])
    mag = np.sqrt(dx * dx + dy * dy)
    mag *= wgt[None]
    b = (np.arctan2(dy, dx) + np.pi) * (nb / (2 * np.pi))
    b0 = np.floor(b).astype(int)
    f = (b - b0).astype(np.float32)
    b0 %= nb
    b1 = (b0 + 1) % nb
    # per-sample orientation histograms (M, nb, ns * ns), linear in angle: sample k of point p
    # puts its two shares into bins b0 and b1 (b0 != b1: no sum collides)
    area = ns * ns
    per = np.zeros((m, nb, area), np.float32)
    flat = per.reshape(-1)  # a view
    base = (np.arange(m)[:, None] * (nb * area) + np.arange(area)[None, :]).ravel()
    flat[base + b0.reshape(-1) * area] = (mag * (1 - f)).ravel()
    flat[base + b1.reshape(-1) * area] = (mag * f).ravel()
    # spatial pooling into g x g cells: one product, (M nb, ns ns) x (ns ns, g g)
    pooled = (per.reshape(m * nb, area) @ cells).reshape(m, nb, g * g)
    desc = np.ascontiguousarray(pooled.transpose(0, 2, 1)).reshape(m, dim)
    desc /= np.linalg.norm(desc, axis=1, keepdims=True) + 1e-12
    np.minimum(desc, params.clip, out=desc)
    desc /= desc.sum(axis=1, keepdims=True) + 1e-12
    return np.sqrt(desc).astype(np.float32)


def describe_gradients(level: Level, xy_full: np.ndarray,
                       params: GradientParams = GradientParams()) -> Described:
    """Oriented gradient-histogram descriptors of points (full-res px) of one level."""
    xy_full = np.asarray(xy_full, dtype=np.float64).reshape(-1, 2)
    xy = level.to_level(xy_full)
    smooth = gaussian_blur(level.image, params.presmooth_px)  # one blur serves both steps
    rows, angles = dominant_orientations(smooth, xy, params)
    desc = gradient_histograms(smooth, xy[rows], angles, params)
    return Described(s=level.s, xy=xy_full[rows], index=rows, angle=angles, desc=desc)
