"""Plane geometry shared by the stages, the pictures and the lab: one definition of each map.

Conventions (docs/GUIDE.md, "Conventions"): points are (x, y) in OpenCV pixels, pixel centres at
integers, so a W x H image's edge runs through (-0.5, -0.5) .. (W - 0.5, H - 0.5). A transform
is a 2x3 affine (similarity) or a 3x3 homography mapping a pixel of the finer (high-resolution)
image to one of the coarser (low-resolution) image, whichever order the images were given in.
Angles are degrees, counter-clockwise in (x, y) with y down (so clockwise on screen).
"""

from __future__ import annotations

import math
from typing import Optional, Tuple

import numpy as np

#: Points per side of the grid spanning the high image (EVALUATION.md: 21x21).
GRID_POINTS = 21
#: Smallest |w| a homography's point is divided by: a point on the horizon (w = 0) is sent
#: 1e12 px away instead of to a division by zero (the estimator's residuals of a degenerate fit)
W_MIN = 1e-12

#: an epipole farther than this many px from an image's origin is reported at infinity, as a
#: direction: at 10^8 px the epipolar lines across a 10^4 px image turn by under 10^-4 rad
EPIPOLE_FAR = 1e8

#: The ratios a fitted map can mean: beyond 1000 (or under 1/1000) an image of a few thousand
#: px would span a few px of the other or less. Such a ratio is a degenerate fit (all points
#: sent to one), not a zoom, and is reported as none (NaN, null in the JSON).
USABLE_RATIOS = (1e-3, 1e3)


def usable_ratio(ratio: float) -> float:
    """``ratio`` when it is within ``USABLE_RATIOS``, else NaN.

    >>> usable_ratio(3.0), usable_ratio(7.49e19), usable_ratio(float("inf"))
    (3.0, nan, nan)
    """
    lo, hi = USABLE_RATIOS
    return ratio if lo < ratio < hi else math.nan


def similarity_matrix(scale: float, angle_deg: float, tx: float = 0.0, ty: float = 0.0) -> np.ndarray:
    """2x3 matrix of x' = scale * R(angle) x + t (angle counter-clockwise on screen is negative).

    Returns
    -------
    (2, 3) float64 array

    >>> similarity_matrix(0.5, 90.0, 10.0, 0.0).round(6).tolist()
    [[0.0, -0.5, 10.0], [0.5, 0.0, 0.0]]
    """
    a = math.radians(angle_deg)
    c, s = scale * math.cos(a), scale * math.sin(a)
    return np.array([[c, -s, tx], [s, c, ty]], dtype=np.float64)


def similarity_parts(t: np.ndarray) -> Tuple[float, float, Tuple[float, float]]:
    """(resolution ratio 1/h, rotation in degrees, translation) of a 2x3 or 3x3 transform.

    For affine and homography matrices the linear part's sqrt(|det|) stands for h, the angle is
    atan2(T[1,0], T[0,0]) as for a similarity.

    Parameters
    ----------
    t : (2, 3) or (3, 3) array
        Finer px -> coarser px.

    Returns
    -------
    ratio : float
        High-resolution pixels per low-resolution pixel (inf for a singular map).
    angle : float
        Degrees.
    translation : (float, float)
        Low px (divided by ``t[2, 2]`` for a homography).

    >>> ratio, angle, (tx, ty) = similarity_parts(similarity_matrix(0.25, 30.0, 5.0, -2.0))
    >>> round(ratio, 6), round(angle, 6), tx, ty
    (4.0, 30.0, 5.0, -2.0)
    """
    t = np.asarray(t, dtype=np.float64)
    a = t[:2, :2]
    if t.shape == (3, 3):
        a = a / t[2, 2]
        tr = (t[0, 2] / t[2, 2], t[1, 2] / t[2, 2])
    else:
        tr = (t[0, 2], t[1, 2])
    h = math.sqrt(abs(float(np.linalg.det(a))))
    ratio = 1.0 / h if h > 0 else float("inf")
    angle = math.degrees(math.atan2(a[1, 0], a[0, 0]))
    return ratio, angle, (float(tr[0]), float(tr[1]))


def local_affine(h: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The 2x2 Jacobian of the 3x3 map ``h`` at the point ``x`` (finer px -> coarser px): the
    affine map that ``h`` is near ``x``.

    >>> local_affine(np.diag([2.0, 3.0, 1.0]), np.array([5.0, 7.0]))
    array([[2., 0.],
           [0., 3.]])
    """
    u, v, w = h @ np.array([x[0], x[1], 1.0])
    return (h[:2, :2] * w - np.outer([u, v], h[2, :2])) / (w * w)


def ratio_at(t: np.ndarray, xy) -> float:
    """Resolution ratio (high px per low px) of ``t`` at the high-image point ``xy`` (x, y).

    For a 2x3 map it is :func:`similarity_parts`'s ratio everywhere. A homography's ratio varies
    across the image: its Jacobian at ``xy`` has determinant ``det(T) / w^3`` (``w`` the point's
    third coordinate), so the ratio there is ``|w|^1.5 / sqrt|det T|``. Taken at the origin, as
    ``similarity_parts`` does, a perspective map's ratio can be far from the one where its points
    are (Oxford graf 1->6 through a t = 4 view: 0.57 at the origin, 0.95 where the 142 inliers
    are, at scale 1).

    >>> h = np.array([[0.5, 0.0, 0.0], [0.0, 0.5, 0.0], [0.001, 0.0, 1.0]])
    >>> round(ratio_at(h, (0, 0)), 3), round(ratio_at(h, (1000, 0)), 3)
    (2.0, 5.657)
    >>> ratio_at(similarity_matrix(0.25, 30.0), (123.0, 45.0))
    4.0
    """
    t = np.asarray(t, dtype=np.float64)
    if t.shape != (3, 3):
        return similarity_parts(t)[0]
    det = abs(float(np.linalg.det(t)))
    w = float(t[2] @ [float(xy[0]), float(xy[1]), 1.0])
    if det == 0.0 or w == 0.0 or not math.isfinite(det * w):
        return math.inf
    return abs(w) ** 1.5 / math.sqrt(det)


def answer_parts(t: np.ndarray, finer_xy=None) -> Tuple[float, float, Tuple[float, float]]:
    """(ratio, rotation in degrees, translation) of an answer, as :func:`similarity_parts`
    gives them, but a homography's ratio and rotation read where its points are: at the
    centroid of ``finer_xy`` (N, 2), the inliers in the finer image (its origin without them).

    A perspective map's zoom and turn vary across the image; at the origin they can be far from
    where the scene was matched (Oxford graf 1->6: a ratio of 1.14 at img1's origin, about 1.8
    where its inliers are). The rotation is that of the map's Jacobian there
    (``atan2(J[1, 0], J[0, 0])``, as for a similarity); the translation stays the image of the
    origin. A 2x3 map's parts are the same everywhere.

    >>> h = np.array([[0.5, 0.0, 0.0], [0.0, 0.5, 0.0], [0.001, 0.0, 1.0]])
    >>> [round(v, 3) for v in answer_parts(h, [[1000.0, 0.0]])[:2]]
    [5.657, 0.0]
    >>> [round(v, 6) for v in answer_parts(similarity_matrix(0.25, 30.0, 5.0, -2.0), [[7.0, 9.0]])[:2]]
    [4.0, 30.0]
    """
    t = np.asarray(t, dtype=np.float64)
    ratio, angle, tr = similarity_parts(t)
    xy = np.asarray(finer_xy if finer_xy is not None else np.zeros((0, 2)), np.float64)
    if t.shape != (3, 3) or xy.size == 0:
        return ratio, angle, tr
    c = xy.reshape(-1, 2).mean(axis=0)
    p = t @ [c[0], c[1], 1.0]
    if p[2] == 0.0 or not np.all(np.isfinite(p)):
        return ratio, angle, tr
    jac = (t[:2, :2] * p[2] - np.outer(p[:2], t[2, :2])) / (p[2] * p[2])
    return ratio_at(t, c), math.degrees(math.atan2(jac[1, 0], jac[0, 0])), tr


def as_matrix3(t: np.ndarray) -> np.ndarray:
    """The 3x3 matrix of a 2x3 affine map (last row 0 0 1) or of a 3x3 homography (as given).

    >>> as_matrix3([[2.0, 0.0, 1.0], [0.0, 2.0, 0.0]]).tolist()
    [[2.0, 0.0, 1.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]
    """
    t = np.asarray(t, dtype=np.float64)
    return np.vstack([t, [0.0, 0.0, 1.0]]) if t.shape == (2, 3) else t


def _like(m3: np.ndarray, affine: bool) -> np.ndarray:
    """A 3x3 product back in the shape of its inputs: 2x3 for affine maps, else w = 1."""
    return m3[:2] if affine else m3 / m3[2, 2]


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a o b`` (apply b first, then a): 2x3 when both are 2x3, else a 3x3 with w = 1.

    Parameters
    ----------
    a, b : (2, 3) or (3, 3) arrays

    Returns
    -------
    (2, 3) or (3, 3) float64 array

    >>> shift = similarity_matrix(1.0, 0.0, 10.0, 0.0)
    >>> half = similarity_matrix(0.5, 0.0)
    >>> compose(half, shift).tolist()    # shift, then halve
    [[0.5, 0.0, 5.0], [0.0, 0.5, 0.0]]
    """
    affine = np.shape(a) == (2, 3) and np.shape(b) == (2, 3)
    return _like(as_matrix3(a) @ as_matrix3(b), affine)


def invert(t: np.ndarray) -> np.ndarray:
    """The inverse map, in the shape given (2x3 affine, or 3x3 with w = 1).

    >>> invert(similarity_matrix(0.5, 0.0, 1.0, 2.0)).tolist()
    [[2.0, 0.0, -2.0], [0.0, 2.0, -4.0]]
    """
    return _like(np.linalg.inv(as_matrix3(t)), np.shape(t) == (2, 3))


def finer_to_coarser(t: np.ndarray, pairs: np.ndarray, swapped: bool, parts=None):
    """(t, pairs, swapped) turned round when ``t`` implies a ratio below 1 (the image taken as
    the finer is the coarser one): ``t`` inverted, the columns of ``pairs`` (N, 4: x, y in
    each image) exchanged and ``swapped`` negated; otherwise unchanged. ``parts``: the model's
    (``estimator.Model.parts``; :func:`answer_parts` by default); a model without a ratio (a
    fundamental matrix) never turns.

    >>> t, pairs, swapped = finer_to_coarser(similarity_matrix(2.0, 0.0), np.zeros((1, 4)), False)
    >>> round(similarity_parts(t)[0], 6), swapped
    (2.0, True)
    """
    ratio = (parts or answer_parts)(t, pairs[:, :2])[0]
    if not (math.isfinite(ratio) and ratio < 1.0):
        return t, pairs, swapped
    return invert(t), pairs[:, [2, 3, 0, 1]], not swapped


def apply(t: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Map (N, 2) points by a 2x3 affine or a 3x3 homography.

    Parameters
    ----------
    t : (2, 3) or (3, 3) array
    xy : (N, 2) array_like
        Points (x, y); a single (2,) point is taken as (1, 2).

    Returns
    -------
    (N, 2) float64 array

    >>> apply(similarity_matrix(0.5, 0.0, 1.0, 2.0), [[10, 20], [0, 0]]).tolist()
    [[6.0, 12.0], [1.0, 2.0]]
    >>> apply([[2.0, 0, 0], [0, 2.0, 0], [0, 0, 2.0]], [3, 4]).tolist()  # a 3x3: divided by w
    [[3.0, 4.0]]
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    t = np.asarray(t, dtype=np.float64)
    if t.shape == (2, 3):
        return xy @ t[:, :2].T + t[:, 2]
    p = np.hstack([xy, np.ones((xy.shape[0], 1))]) @ t.T
    w = p[:, 2:3]  # a point on the horizon (w = 0) goes far away, not to a division by zero
    return p[:, :2] / np.where(np.abs(w) < W_MIN, W_MIN, w)


def transfer_error(t: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """(N,) distances |t(src) - dst|, px of ``dst``'s image, for (N, 2) point pairs.

    >>> transfer_error(similarity_matrix(1.0, 0.0, 3.0, 4.0), [[0, 0]], [[0, 0]]).tolist()
    [5.0]
    """
    return np.linalg.norm(apply(t, src) - np.asarray(dst, np.float64).reshape(-1, 2), axis=1)


def epipolar_distances(f: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """(N, 2) distances, px, of the pairs (src, dst) to an epipolar geometry
    ``x_dst^T F x_src = 0``: column 0, of each dst point to the line ``F x_src``; column 1, of
    each src point to the line ``F^T x_dst``. A line at infinity gives ``inf``.

    >>> f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # a rectified pair: y' = y
    >>> epipolar_distances(f, np.array([[10.0, 20], [5, 5]]), np.array([[30.0, 20], [50, 7]]))
    array([[0., 0.],
           [2., 2.]])
    """
    f = np.asarray(f, np.float64)
    xs = np.hstack([np.asarray(src, np.float64), np.ones((len(src), 1))])
    xd = np.hstack([np.asarray(dst, np.float64), np.ones((len(dst), 1))])
    line_dst, line_src = xs @ f.T, xd @ f  # F x_src (in dst's image), F^T x_dst (in src's)
    residual = np.abs(np.einsum("ij,ij->i", xd, line_dst))
    with np.errstate(divide="ignore", invalid="ignore"):
        d_dst = residual / np.hypot(line_dst[:, 0], line_dst[:, 1])
        d_src = residual / np.hypot(line_src[:, 0], line_src[:, 1])
    return np.nan_to_num(np.stack([d_dst, d_src], axis=1), nan=np.inf)


def epipoles(f: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The epipoles of an epipolar geometry ``x_coarser^T F x_finer = 0``: (finer, coarser),
    each homogeneous, ``[x, y, 1]`` in its image's px, or a unit ``[dx, dy, 0]`` when it lies
    at infinity (the epipolar lines are then parallel, along that direction). The finer
    image's is F's right null vector, the coarser image's its left one.

    >>> f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # a rectified pair: y' = y
    >>> [e.tolist() for e in epipoles(f)]
    [[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
    """
    u, _, vt = np.linalg.svd(np.asarray(f, np.float64))
    return _homogeneous_point(vt[-1]), _homogeneous_point(u[:, -1])


def _homogeneous_point(e: np.ndarray) -> np.ndarray:
    """``e`` as ``[x, y, 1]``, or as a unit direction ``[dx, dy, 0]`` beyond ``EPIPOLE_FAR``
    (signs fixed: the first non-zero of dx, dy positive)."""
    if abs(e[2]) * EPIPOLE_FAR > np.hypot(e[0], e[1]):
        return e / e[2]
    d = e[:2] / np.hypot(e[0], e[1])
    if d[0] < 0 or (d[0] == 0 and d[1] < 0):
        d = -d
    return np.array([d[0] + 0.0, d[1] + 0.0, 0.0])


def resize_map(fx: float, fy: Optional[float] = None) -> np.ndarray:
    """2x3 map from a pixel of an image to its pixel in a copy resized by (fx, fy).

    ``fx``, ``fy``: new size over old size (``fy`` defaults to ``fx``). The convention is
    ``cv2.resize``'s, centre-aligned: the edges of the images coincide, so
    ``x' = fx (x + 0.5) - 0.5``. Its inverse, ``resize_map(1 / fx)``, maps back; decimating
    by ``d`` (one pixel of the copy every ``d`` pixels) is ``resize_map(1 / d)``.

    >>> resize_map(0.5).tolist()      # halved: pixels 0 and 1 become pixel 0 (at 0.5 -> 0)
    [[0.5, 0.0, -0.25], [0.0, 0.5, -0.25]]
    >>> apply(resize_map(4.0), [[0.0, 0.0]]).tolist()   # pixel 0 shrunk by 4, back to full size
    [[1.5, 1.5]]
    """
    fy = fx if fy is None else fy
    return np.array([[fx, 0.0, (fx - 1.0) / 2.0], [0.0, fy, (fy - 1.0) / 2.0]])


def grid(shape: Tuple[int, int], n: int = GRID_POINTS) -> np.ndarray:
    """(n*n, 2) points (x, y) spanning an image of ``shape`` (H, W), corners included.

    >>> grid((3, 5), n=2).tolist()
    [[0.0, 0.0], [4.0, 0.0], [0.0, 2.0], [4.0, 2.0]]
    """
    h, w = int(shape[0]), int(shape[1])
    xs = np.linspace(0.0, w - 1.0, n)
    ys = np.linspace(0.0, h - 1.0, n)
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], axis=1)


def footprint(t: np.ndarray, high_shape: Tuple[int, ...], edges: bool = True
              ) -> Optional[np.ndarray]:
    """(4, 2) low-resolution px of the high image's four corners, clockwise from top-left.

    Parameters
    ----------
    t : (2, 3) or (3, 3) array
        Finer px -> coarser px.
    high_shape : tuple
        (H, W, ...) of the high image.
    edges : bool
        True (the convention): the image's outline, corners at (-0.5, -0.5) .. (W - 0.5,
        H - 0.5), as drawn in the overlay. False: the centres of the corner pixels, (0, 0) ..
        (W - 1, H - 1), which the decision's area test was measured with (it keeps that, so no
        decision changes).

    Returns
    -------
    (4, 2) array or None
        None when a homography sends a corner to infinity or behind the camera (or the result is
        not finite): such a transform has no footprint.

    >>> footprint(similarity_matrix(0.5, 0.0), (4, 6)).tolist()  # a 6x4 image halved
    [[-0.25, -0.25], [2.75, -0.25], [2.75, 1.75], [-0.25, 1.75]]
    """
    h, w = high_shape[:2]
    lo, hi_x, hi_y = (-0.5, w - 0.5, h - 0.5) if edges else (0.0, w - 1.0, h - 1.0)
    corners = np.array([[lo, lo], [hi_x, lo], [hi_x, hi_y], [lo, hi_y]], dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    if t.shape == (3, 3) and np.any(np.hstack([corners, np.ones((4, 1))]) @ t[2] <= 1e-12):
        return None
    out = apply(t, corners)
    return out if np.all(np.isfinite(out)) else None


def pairs_within(a: np.ndarray, b: np.ndarray, radius: float) -> Tuple[np.ndarray, np.ndarray]:
    """Every pair (i, k) of points ``a[i]``, ``b[k]`` ((N, 2) and (M, 2)) at most ``radius``
    apart, sorted by i then k (the row-major order of the full N x M table).

    ``b`` is put in a grid of cells a little wider than ``radius``; each point of ``a`` looks only
    in the 3 x 3 cells around its own, so the work follows the pairs that are near, not N x M
    (the full table of a 12 MP pair, about 20 000 x 20 000, took 3.5 s). Distances are
    ``dx**2 + dy**2`` in float64, compared with ``radius**2``: the pairs the full table gives.
    Points that are not finite have no pair.

    >>> i, k = pairs_within([[0, 0], [10, 0]], [[1, 0], [9, 1], [30, 30]], 2.0)
    >>> i.tolist(), k.tolist()
    ([0, 1], [0, 1])
    """
    a = np.asarray(a, np.float64).reshape(-1, 2)
    b = np.asarray(b, np.float64).reshape(-1, 2)
    none = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    b_ok = np.nonzero(np.all(np.isfinite(b), axis=1))[0]
    a_ok = np.all(np.isfinite(a), axis=1)
    if b_ok.size == 0 or not a_ok.any() or not radius >= 0:
        return none
    cell = max(float(radius), 1e-6) * (1 + 1e-6)  # any cell >= radius: the 3 x 3 cells hold all
    origin = b[b_ok].min(axis=0)
    cb = np.floor((b[b_ok] - origin) / cell).astype(np.int64)
    top = cb.max(axis=0)  # (largest x cell, largest y cell)
    key_b = cb[:, 1] * (top[0] + 1) + cb[:, 0]
    order = np.argsort(key_b, kind="stable")  # by cell, then by row of b
    sorted_keys = key_b[order]
    rows = np.nonzero(a_ok)[0]
    ca = np.floor((a[rows] - origin) / cell)
    # cells far outside b's grid have no neighbour (and would overflow the integer key)
    near = np.all((ca >= -1) & (ca <= top + 1), axis=1)
    rows, ca = rows[near], ca[near].astype(np.int64)
    found_a, found_b = [], []
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            cx, cy = ca[:, 0] + dx, ca[:, 1] + dy
            inside = (cx >= 0) & (cx <= top[0]) & (cy >= 0) & (cy <= top[1])
            key = cy[inside] * (top[0] + 1) + cx[inside]
            lo = np.searchsorted(sorted_keys, key, "left")
            count = np.searchsorted(sorted_keys, key, "right") - lo
            total = int(count.sum())
            if total == 0:
                continue
            ends = np.cumsum(count)
            within = np.arange(total) - np.repeat(ends - count, count)
            found_a.append(np.repeat(rows[inside], count))
            found_b.append(b_ok[order[np.repeat(lo, count) + within]])
    if not found_a:
        return none
    i, k = np.concatenate(found_a), np.concatenate(found_b)
    d = a[i] - b[k]
    close = d[:, 0] ** 2 + d[:, 1] ** 2 <= float(radius) * float(radius)
    i, k = i[close], k[close]
    order = np.lexsort((k, i))
    return i[order], k[order]
