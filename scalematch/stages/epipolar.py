"""The fundamental matrix refined: Levenberg-Marquardt on the Sampson error of its inliers.

MAGSAC++ (``stages/estimator.py``) weighs each pair by its residual and returns its weighted
fit; the answer is then refined by Levenberg-Marquardt on the Sampson error (Hartley &
Zisserman, "Multiple View Geometry", 2nd ed., eq. 11.9 and A6.2) of the answer's inliers, with
F kept of rank 2 by its orthonormal representation (Bartoli & Sturm, "Nonlinear estimation of
the fundamental matrix with minimal parameters", PAMI 2004): seven parameters for its seven
degrees of freedom. The references of the 3-D benchmark (``lab/threed.py``) are refined the
same way.

Pairs (x_A, x_B) with ``x_B^T F x_A = 0``; for the matcher, A is the finer image and B the
coarser one.
"""

from __future__ import annotations

import math
from typing import Dict, Tuple

import numpy as np

#: Levenberg-Marquardt: iterations at most, the first damping relative to the mean diagonal of
#: J^T J, and the relative decrease of the cost under which it stops (Hartley & Zisserman,
#: "Multiple View Geometry", 2nd ed., A6.2)
LM_ITERATIONS = 100
LM_DAMPING = 1e-3
LM_TOLERANCE = 1e-10
#: Step of the forward differences of the Jacobian, in the units of the parameters (radians of
#: the rotations, the singular-value ratio): about sqrt of the float64 epsilon
LM_STEP = 1e-7

def one_to_one(pairs: np.ndarray, same_point_px: float) -> np.ndarray:
    """Row indices of ``pairs`` ((N, 4): x, y finer; x, y coarser) that share no point with an
    earlier row kept: a row is dropped when its finer point, or its coarser point, lies within
    ``same_point_px`` of a kept row's (0: the same position only). In first order.

    An epipolar geometry maps a point to a line, so many points matched to one point all fit
    any geometry whose epipole lies on it: counted once, they are one inlier.

    >>> one_to_one(np.array([[0, 0, 5, 5], [9, 9, 5.4, 5], [20, 0, 30, 0], [20.5, 0, 40, 0],
    ...                      [50, 50, 60, 60]], float), 1.0).tolist()
    [0, 2, 4]
    """
    pairs = np.asarray(pairs, np.float64).reshape(-1, 4)
    cell = max(float(same_point_px), 1e-3)
    seen: Tuple[Dict[Tuple[int, int], list], Dict[Tuple[int, int], list]] = ({}, {})
    keep = []
    for i, row in enumerate(pairs):
        points = (row[:2], row[2:])
        if any(_near(table, xy, cell) for table, xy in zip(seen, points)):
            continue
        keep.append(i)
        for table, xy in zip(seen, points):
            table.setdefault(_cell(xy, cell), []).append(xy)
    return np.asarray(keep, int)


def _cell(xy: np.ndarray, cell: float) -> Tuple[int, int]:
    return int(math.floor(xy[0] / cell)), int(math.floor(xy[1] / cell))


def _near(table: Dict[Tuple[int, int], list], xy: np.ndarray, cell: float) -> bool:
    """Whether a point of ``table`` (points by grid cell of side ``cell``) is within ``cell``."""
    cx, cy = _cell(xy, cell)
    return any(np.hypot(*(q - xy)) <= cell for dx in (-1, 0, 1) for dy in (-1, 0, 1)
               for q in table.get((cx + dx, cy + dy), ()))


def homogeneous(xy: np.ndarray) -> np.ndarray:
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    return np.hstack([xy, np.ones((len(xy), 1))])


def sampson_residuals(f: np.ndarray, pts_a: np.ndarray, pts_b: np.ndarray) -> np.ndarray:
    """(N,) signed Sampson distances, px, of the pairs (x_A, x_B) to ``x_B^T F x_A = 0``: the
    first-order distance of the 4-vector (x_A, y_A, x_B, y_B) to the variety F defines
    (Hartley & Zisserman, eq. 11.9). Their squares sum to the Sampson error.

    >>> f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # a rectified pair: y_B = y_A
    >>> sampson_residuals(f, np.array([[0.0, 0], [0, 0]]), np.array([[5.0, 0], [5, 2]])).round(6).tolist()
    [0.0, -1.414214]
    """
    f = np.asarray(f, np.float64)
    xa, xb = homogeneous(pts_a), homogeneous(pts_b)
    fxa, ftxb = xa @ f.T, xb @ f
    num = np.einsum("ij,ij->i", xb, fxa)
    den = np.sqrt(fxa[:, 0] ** 2 + fxa[:, 1] ** 2 + ftxb[:, 0] ** 2 + ftxb[:, 1] ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / den, np.inf)


def normalising_transform(xy: np.ndarray) -> np.ndarray:
    """3x3 similarity taking points to their centroid at 0 and mean distance sqrt(2) from it
    (Hartley, "In defense of the eight-point algorithm", PAMI 1997).

    >>> t = normalising_transform(np.array([[0.0, 0], [2, 0]]))
    >>> (homogeneous([[0.0, 0], [2, 0]]) @ t.T)[:, :2].round(6).tolist()
    [[-1.414214, 0.0], [1.414214, 0.0]]
    """
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    c = xy.mean(axis=0)
    d = float(np.mean(np.linalg.norm(xy - c, axis=1)))
    s = math.sqrt(2.0) / d if d > 0 else 1.0
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


def rotation(w: np.ndarray) -> np.ndarray:
    """3x3 rotation of the axis-angle vector ``w`` (Rodrigues' formula).

    >>> rotation(np.array([0.0, 0.0, math.pi / 2])).round(12).tolist()
    [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    """
    w = np.asarray(w, np.float64)
    theta = float(np.linalg.norm(w))
    if theta < 1e-300:
        return np.eye(3)
    k = w / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(theta) * kx + (1.0 - math.cos(theta)) * (kx @ kx)


def _orthonormal(f: np.ndarray) -> Tuple[np.ndarray, np.ndarray, float]:
    """(U, V, sigma) of the rank-2 F = U diag(1, sigma, 0) V^T, U and V rotations (Bartoli &
    Sturm, "Nonlinear estimation of the fundamental matrix with minimal parameters", PAMI
    2004): seven parameters for F's seven degrees of freedom."""
    u, s, vt = np.linalg.svd(np.asarray(f, np.float64))
    u = u * np.sign(np.linalg.det(u))
    v = vt.T * np.sign(np.linalg.det(vt))
    return u, v, float(s[1] / s[0]) if s[0] > 0 else 0.0


def _compose(u: np.ndarray, v: np.ndarray, sigma: float) -> np.ndarray:
    return u @ np.diag([1.0, sigma, 0.0]) @ v.T


def refine_fundamental(f: np.ndarray, pts_a: np.ndarray, pts_b: np.ndarray,
                       iterations: int = LM_ITERATIONS) -> np.ndarray:
    """F refined by Levenberg-Marquardt on the Sampson error of the pairs (x_A, x_B), rank 2
    kept by its orthonormal representation; unit Frobenius norm. The pairs are the inliers of
    F: the Sampson error has no robust loss here.

    Parameters
    ----------
    f : (3, 3) array
        The F to start from, ``x_B^T F x_A = 0``.
    pts_a, pts_b : (N, 2) arrays
        The pairs, px; N >= 8.
    iterations : int
        Iterations at most (``LM_ITERATIONS``).

    Returns
    -------
    (3, 3) float64 array
        Of rank 2; its Sampson error is at most that of ``f`` made rank 2.
    """
    pts_a = np.asarray(pts_a, np.float64).reshape(-1, 2)
    pts_b = np.asarray(pts_b, np.float64).reshape(-1, 2)
    if len(pts_a) < 8:
        raise ValueError(f"refine_fundamental needs at least 8 pairs, got {len(pts_a)}")
    # conditioning: the parameters act on F of normalised points, the error stays in px
    t_a, t_b = normalising_transform(pts_a), normalising_transform(pts_b)
    inv_a, inv_b = np.linalg.inv(t_a), np.linalg.inv(t_b)

    def to_px(fn: np.ndarray) -> np.ndarray:
        return t_b.T @ fn @ t_a

    def residuals(u, v, sigma, p):
        fn = _compose(u @ rotation(p[:3]), v @ rotation(p[3:6]), sigma + p[6])
        return sampson_residuals(to_px(fn), pts_a, pts_b)

    u, v, sigma = _orthonormal(inv_b.T @ np.asarray(f, np.float64) @ inv_a)
    r = residuals(u, v, sigma, np.zeros(7))
    cost = float(r @ r)
    lam = None
    for _ in range(iterations):
        step = _damped_step(lambda p: residuals(u, v, sigma, p), r, cost, lam)
        if step is None:
            break
        delta, r_new, cost_new, lam = step
        u, v, sigma = u @ rotation(delta[:3]), v @ rotation(delta[3:6]), sigma + delta[6]
        done = cost - cost_new <= LM_TOLERANCE * cost
        r, cost, lam = r_new, cost_new, lam / 10.0
        if done:
            break
    out = to_px(_compose(u, v, sigma))
    return out / np.linalg.norm(out)


def _damped_step(residuals, r: np.ndarray, cost: float, lam):
    """One Levenberg-Marquardt step from the parameters 0 of ``residuals`` (7 parameters ->
    (N,) residuals, ``r`` and ``cost`` at 0): the Jacobian by forward differences
    (``LM_STEP``), the damping ``lam`` (None: ``LM_DAMPING`` times the mean diagonal of J^T J)
    raised tenfold until a step lowers the cost. (delta, residuals, cost, damping) of that
    step, or None when none does in 20 tries."""
    zero = np.zeros(7)
    jac = np.empty((len(r), 7))
    for k in range(7):
        step = zero.copy()
        step[k] = LM_STEP
        jac[:, k] = (residuals(step) - r) / LM_STEP
    a, g = jac.T @ jac, jac.T @ r
    if lam is None:
        lam = LM_DAMPING * float(np.mean(np.diag(a)))
    for _ in range(20):
        delta = np.linalg.solve(a + lam * np.diag(np.diag(a) + 1e-300), -g)
        r_new = residuals(delta)
        cost_new = float(r_new @ r_new)
        if cost_new < cost:
            return delta, r_new, cost_new, lam
        lam *= 10.0
    return None
