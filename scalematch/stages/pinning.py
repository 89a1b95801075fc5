"""How firmly a map's inliers pin it down: the error they leave it free to make.

A map fitted by least squares to N point pairs whose residuals have the standard deviation
sigma has the parameter covariance ``sigma^2 (J^T J)^-1``, J the (2N, p) Jacobian of the mapped
points with respect to the map's p parameters at the inliers (Hartley & Zisserman, "Multiple
View Geometry", 2nd ed., 2004, 5.2: the covariance of an estimated transformation, and its
forward propagation). Propagated through the map to a point of the finer image it is that
point's 2x2 positional covariance in the coarser image, ``J_c C J_c^T``, whose trace is the
point's expected squared error. Averaged over EVALUATION.md's 21x21 grid of the finer image it
predicts the error a claim is judged by (the mean distance between the map and the truth over
that grid): :func:`expected_error`, coarser px.

Inliers spread over the whole footprint pin a homography's eight parameters everywhere; inliers
crowded in part of it (a small footprint at a high ratio, texture on one side) leave its far
corners loose, and its extra freedom then fits their noise: a ratio-8 homography of 11 inliers
was 10.8 px off (expected error 4.5 px) while the similarity fitted to the same inliers was
within 1 px (expected error 0.95 px). ``stages.refit.pinned_model`` answers the next simpler
model where the expected error exceeds the claim's tolerance (``PinParams``).

The figure is the mean over the grid, not the loosest corner: a homography of a perspective
pair solved to 0.13 px had a corner 2-sigma radius of 3.4 px (its far corner, beyond its
inliers) against 3.7 px for the similarity fitted to the same inliers, 10 px off; its expected
grid error, 0.32 px against 1.6, tells them apart as the evaluation does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Mapping, Optional, Tuple

import numpy as np

from ..checks import Bounds, NON_NEGATIVE, POSITIVE, check_bounds
from ..geometry import apply, as_matrix3, grid
from .epipolar import normalising_transform

#: Free parameters of each model whose error is measured (a homography's 3x3 matrix is defined
#: up to scale: eight)
PARAMETERS = {"similarity": 4, "affine": 6, "homography": 8}
#: Largest condition number of the normalised normal matrix J^T J: past it the inliers do not
#: determine the map (coincident or collinear points) and the expected error is infinite.
#: Float64 keeps about 16 digits; 1e12 leaves 4 of them to the inverse
MAX_CONDITION = 1e12


@dataclass(frozen=True)
class PinParams:
    """A map is claimed as its model only where its inliers pin it down: its expected grid
    error (:func:`expected_error`) within ``tolerance_px``; otherwise the next simpler model
    fitted to the same inliers answers (``stages.refit.pinned_model``)."""

    enabled: bool = True  #: False: every map is answered as fitted
    #: largest expected grid error, coarser px, of a map claimed as its model: a third of the
    #: success tolerance of 3 px (EVALUATION.md). The expected error counts the points' noise
    #: only: of 1,118 homographies claimed on synthetic zoom pairs at ratios 8 to 20, the 1,092
    #: within it were off by at most 3.9 times it (2.8 px), one wrong match (12.4 px) aside
    tolerance_px: float = 1.0
    #: smallest residual standard deviation, coarser px, that the error assumes: a keypoint's
    #: localisation error; a handful of inliers can fit closer than their points are located
    #: (a fit through exactly as many pairs as parameters has no residual at all). The
    #: residuals of those 1,118 homographies were 0.17 to 1.17 px per coordinate, median 0.6;
    #: 0.3 is their 1st percentile
    min_sigma_px: float = 0.3

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "tolerance_px": POSITIVE,
        "min_sigma_px": NON_NEGATIVE,
    }

    def __post_init__(self) -> None:
        check_bounds("pin", self, self.BOUNDS)


def jacobian(model: str, t: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(2M, p) derivatives of the mapped points ``t(xy)`` (M, 2) with respect to the map's
    parameters: rows x'_0, y'_0, x'_1, ...

    The parameters: a similarity (a, b, tx, ty) of ``x' = a x - b y + tx, y' = b x + a y +
    ty``; an affine map its six entries; a homography its entries h11 .. h32 (h33 = 1).

    >>> jacobian("similarity", np.eye(3)[:2], np.array([[2.0, 3.0]])).tolist()
    [[2.0, -3.0, 1.0, 0.0], [3.0, 2.0, 0.0, 1.0]]
    """
    x, y = xy[:, 0], xy[:, 1]
    one, zero = np.ones_like(x), np.zeros_like(x)
    if model == "similarity":
        rx = [x, -y, one, zero]
        ry = [y, x, zero, one]
    elif model == "affine":
        rx = [x, y, one, zero, zero, zero]
        ry = [zero, zero, zero, x, y, one]
    elif model == "homography":
        h = as_matrix3(t)
        h = h / h[2, 2]
        w = h[2, 0] * x + h[2, 1] * y + 1.0
        u, v = apply(h, xy).T
        rx = [x / w, y / w, one / w, zero, zero, zero, -u * x / w, -u * y / w]
        ry = [zero, zero, zero, x / w, y / w, one / w, -v * x / w, -v * y / w]
    else:
        raise ValueError(f"no corner uncertainty for the {model!r} model; one of "
                         f"{', '.join(PARAMETERS)}")
    out = np.empty((2 * len(xy), len(rx)))
    out[0::2] = np.stack(rx, axis=1)
    out[1::2] = np.stack(ry, axis=1)
    return out


def residual_sigma(model: str, t: np.ndarray, inliers: np.ndarray, min_sigma_px: float) -> float:
    """The residual standard deviation per coordinate, coarser px, of ``t`` on ``inliers``
    (N, 4): the squared residuals over the degrees of freedom (2N - p), at least
    ``min_sigma_px`` (``min_sigma_px`` alone when no degree of freedom is left).

    >>> pairs = np.array([[0, 0, 1, 0], [1, 0, 2, 0], [0, 1, 1, 1], [1, 1, 2, 1]], float)
    >>> residual_sigma("similarity", np.eye(3)[:2], pairs, 0.25)  # residuals 1 px in x
    1.0
    """
    r = apply(t, inliers[:, :2]) - inliers[:, 2:4]
    dof = 2 * len(inliers) - PARAMETERS[model]
    sigma = float(np.sqrt(np.sum(r * r) / dof)) if dof > 0 else 0.0
    return max(sigma, float(min_sigma_px))


def point_covariances(model: str, t: np.ndarray, inliers: np.ndarray, points: np.ndarray,
                      sigma: float) -> Optional[np.ndarray]:
    """(M, 2, 2) covariances, coarser px^2, of ``t(points)`` for a map fitted by least squares
    to ``inliers`` (N, 4: x_f, y_f, x_c, y_c) with residual std ``sigma`` per coordinate; None
    when the inliers do not determine the map (fewer coordinates than parameters, or
    coincident or collinear points).

    Computed in Hartley-normalised coordinates of both images (the covariance of a mapped point
    does not depend on how the map is parameterised, and the normal matrix is then well
    conditioned); an isotropic scale of the coarser image's coordinates scales it back.
    """
    src, dst = inliers[:, :2], inliers[:, 2:4]
    p = PARAMETERS[model]
    if 2 * len(src) < p:
        return None
    to_n, from_d = normalising_transform(src), normalising_transform(dst)
    kd = from_d[0, 0]  # the coarser coordinates' isotropic scale
    tn = from_d @ as_matrix3(t) @ np.linalg.inv(to_n)
    tn = tn / tn[2, 2] if model == "homography" else tn[:2]
    j = jacobian(model, tn, apply(to_n, src))
    normal = j.T @ j
    if not np.all(np.isfinite(normal)) or np.linalg.cond(normal) > MAX_CONDITION:
        return None
    params = (sigma * kd) ** 2 * np.linalg.inv(normal)
    jc = jacobian(model, tn, apply(to_n, points)).reshape(len(points), 2, p)
    return jc @ params @ jc.transpose(0, 2, 1) / kd ** 2


def expected_error(model: str, t: np.ndarray, inliers: np.ndarray, finer_shape: Tuple[int, int],
                   params: PinParams = PinParams(),
                   coarser_shape: Optional[Tuple[int, int]] = None) -> float:
    """The error, coarser px, that ``inliers`` (N, 4: x_f, y_f, x_c, y_c) leave the map ``t``
    (finer px -> coarser px) free to make: the mean over the finer image's 21x21 grid
    (``finer_shape``, (H, W)) of each point's RMS position error (the square root of the trace
    of :func:`point_covariances`, the residual std from :func:`residual_sigma` with the floor
    ``params.min_sigma_px``); inf when the inliers do not determine the map.

    With ``coarser_shape``, only the grid points ``t`` maps inside the coarser image count, as
    the evaluation counts them (a footprint partly outside is judged where it lies inside);
    the whole grid when none does.

    >>> xy = grid((480, 640), 5)  # 25 exact pairs over the whole image, a similarity at ratio 8
    >>> pairs = np.hstack([xy, xy / 8.0])
    >>> t = np.array([[0.125, 0, 0], [0, 0.125, 0]])
    >>> round(expected_error("similarity", t, pairs, (480, 640)), 3)  # sigma: the floor, 0.3
    0.111
    """
    inliers = np.asarray(inliers, np.float64).reshape(-1, 4)
    points = grid(finer_shape[:2])
    if coarser_shape is not None:
        m = apply(t, points)
        inside = ((m[:, 0] >= -0.5) & (m[:, 0] <= coarser_shape[1] - 0.5)
                  & (m[:, 1] >= -0.5) & (m[:, 1] <= coarser_shape[0] - 0.5))
        points = points[inside] if inside.any() else points
    sigma = residual_sigma(model, t, inliers, params.min_sigma_px)
    cov = point_covariances(model, t, inliers, points, sigma)
    if cov is None:
        return float("inf")
    spread = np.trace(cov, axis1=1, axis2=2)
    return float(np.mean(np.sqrt(np.maximum(spread, 0.0))))
