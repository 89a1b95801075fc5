"""Stage 4: candidate matches between descriptors (docs/ALGORITHM.md step 4, paper eq. mahalanobis).

Descriptors are compared by Euclidean distance; the Mahalanobis distance of the paper becomes a
Euclidean one once the jets are whitened by Lambda^-1/2 (see :mod:`scalematch.stages.mahalanobis`).
How candidates are selected is the named parameter ``MatcherParams.selection``:

* ``"nn"``: the nearest neighbour of each high-resolution point;
* ``"knn"``: its ``k`` nearest neighbours (one-to-many candidates for the later constraints);
* ``"threshold"``: every neighbour (up to ``k``) closer than ``max_distance``;
* ``"ratio"``: the nearest neighbour when it is clearly nearer than the second (Lowe 2004).

``max_distance`` (when finite) applies to every selection.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Mapping, Tuple

import numpy as np

from ..checks import AT_LEAST_ONE, Bounds, check_bounds, one_of
from .threads import thread_map

SELECTIONS = ("nn", "knn", "threshold", "ratio")

#: rows of the distance matrix computed at once: the passes over a chunk after the product
#: (argmin twice) stay in the 32 MB cache of the machine measured; 2048 was 4-5 % slower on one
#: thread and 10 % on two (6000 x 12000 RootSIFT descriptors, medians of 5)
_CHUNK = 512
#: descriptor pairs from which a match is spread over threads (2 cores, medians of 15: 1.8 M
#: pairs 8.0 -> 7.8 ms, 3 M 12.0 -> 9.2 ms, 12 M 51.5 -> 32.1 ms)
_THREADED_MIN = 2_000_000


@dataclass(frozen=True)
class MatcherParams:
    """Which descriptor matches become candidates (``Config.matcher``)."""

    selection: str = "ratio"  #: one of SELECTIONS
    k: int = 2  #: neighbours for "knn" / "threshold"
    ratio: float = 0.9  #: nearest / second-nearest distance for "ratio" (Lowe 2004: 0.8)
    max_distance: float = float("inf")  #: absolute distance limit (descriptor units)
    mutual: bool = False  #: keep only matches that are also nearest the other way round

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "k": AT_LEAST_ONE,
        "ratio": Bounds(lo=0, hi=1, lo_open=True),
        "max_distance": Bounds(lo=0, lo_open=True, allow_inf=True),
    }

    def __post_init__(self) -> None:
        check_bounds("matcher", self, self.BOUNDS)
        one_of("matcher", "selection", self.selection, SELECTIONS)


@dataclass(frozen=True)
class Candidates:
    """Candidate matches: row ``i`` of the high descriptors with row ``j`` of the low ones."""

    i: np.ndarray = field(repr=False)  #: (K,) int, index into the high-resolution descriptors
    j: np.ndarray = field(repr=False)  #: (K,) int, index into the low-resolution descriptors
    distance: np.ndarray = field(repr=False)  #: (K,) float32, descriptor distance
    second: np.ndarray = field(repr=False)  #: (K,) float32, distance to the 2nd nearest (ratio)

    def __len__(self) -> int:
        return int(self.i.shape[0])

    @staticmethod
    def empty() -> "Candidates":
        z = np.zeros(0, int)
        return Candidates(z, z, np.zeros(0, np.float32), np.zeros(0, np.float32))


def _knn(a: np.ndarray, b: np.ndarray, k: int):
    """k nearest rows of b for each row of a: (indices (N, k), distances (N, k)), sorted.

    Squared distances are ``|a|^2 + |b|^2 - 2 a.b``; the order along a row does not depend on
    ``|a|^2``, so the matrix holds ``|b|^2 - 2 a.b`` (one pass over it after the product) and
    ``|a|^2`` is added to the k values kept. Products of more than ``_THREADED_MIN`` pairs are
    cut into chunks matched on threads (:mod:`scalematch.stages.threads`).
    """
    k = min(k, b.shape[0])
    bb = np.einsum("ij,ij->i", b, b)
    bt = -2.0 * b.T  # (D, M)
    threaded = a.shape[0] * b.shape[0] >= _THREADED_MIN

    def chunk(lo: int):
        aa = a[lo:lo + _CHUNK]
        d2 = aa @ bt
        d2 += bb[None, :]
        rows = np.arange(aa.shape[0])
        if k <= 3:  # repeated argmin is several times faster than argpartition for small k
            cols = np.empty((aa.shape[0], k), int)
            vals = np.empty((aa.shape[0], k), d2.dtype)
            for r in range(k):
                c = np.argmin(d2, axis=1)
                cols[:, r], vals[:, r] = c, d2[rows, c]
                d2[rows, c] = np.inf
        else:
            part = np.argpartition(d2, k - 1, axis=1)[:, :k]
            pd = np.take_along_axis(d2, part, axis=1)
            order = np.argsort(pd, axis=1)
            cols, vals = np.take_along_axis(part, order, axis=1), np.take_along_axis(pd, order, 1)
        vals += np.einsum("ij,ij->i", aa, aa)[:, None]
        return cols, np.sqrt(np.maximum(vals, 0))

    starts = list(range(0, a.shape[0], _CHUNK))
    parts = thread_map(chunk, starts) if threaded else [chunk(lo) for lo in starts]
    if not parts:
        return np.empty((0, k), int), np.empty((0, k), np.float32)
    return (np.concatenate([c for c, _ in parts]),
            np.concatenate([v for _, v in parts]).astype(np.float32))


def match_descriptors(high: np.ndarray, low: np.ndarray,
                      params: MatcherParams = MatcherParams()) -> Candidates:
    """Candidate matches from high-resolution descriptors (N, D) to low ones (M, D)."""
    if params.selection not in SELECTIONS:
        raise ValueError(f"selection must be one of {SELECTIONS}, got {params.selection!r}")
    if high.shape[0] == 0 or low.shape[0] == 0:
        return Candidates.empty()
    a = np.asarray(high, np.float32)
    b = np.asarray(low, np.float32)
    k = max(params.k, 2) if params.selection in ("knn", "threshold", "ratio") else 2
    idx, dist = _knn(a, b, k)
    n = a.shape[0]
    second = dist[:, 1] if dist.shape[1] > 1 else np.full(n, np.inf, np.float32)
    if params.selection == "ratio":
        keep = dist[:, 0] <= params.ratio * second
        i = np.nonzero(keep)[0]
        j, d, sec = idx[i, 0], dist[i, 0], second[i]
    elif params.selection == "nn":
        i, j, d, sec = np.arange(n), idx[:, 0], dist[:, 0], second
    else:  # knn / threshold: every listed neighbour, one-to-many
        kk = idx.shape[1]
        i = np.repeat(np.arange(n), kk)
        j, d = idx.ravel(), dist.ravel()
        sec = np.repeat(second, kk)
    keep = d <= params.max_distance
    i, j, d, sec = i[keep], j[keep], d[keep], sec[keep]
    if params.mutual and i.size:
        back, _ = _knn(b[j], a, 1)
        ok = back[:, 0] == i
        i, j, d, sec = i[ok], j[ok], d[ok], sec[ok]
    return Candidates(i=i.astype(int), j=j.astype(int), distance=d.astype(np.float32),
                      second=sec.astype(np.float32))


def distinct_pairs(src: np.ndarray, dst: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """The distinct rows of the point pairs (src, dst), (K, 2) each, in their first order.

    A keypoint with several dominant orientations is described once per orientation, so the
    same pair of positions can be matched more than once; counting it once keeps the inlier
    count and the a-contrario test honest.

    >>> src, dst = distinct_pairs(np.array([[1.0, 2], [1, 2], [3, 4]]), np.zeros((3, 2)))
    >>> src.tolist()
    [[1.0, 2.0], [3.0, 4.0]]
    """
    keep = distinct_rows(src, dst)
    return src[keep], dst[keep]


def distinct_rows(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Row indices of the distinct (src, dst) position pairs (to 1e-3 px), in first order.

    Rows sorted by a stable lexicographic sort, each group's first row kept: what
    ``np.unique(axis=0, return_index=True)`` gives, without its structured-array view, whose
    comparison turns an exception raised inside it (Ctrl-C's KeyboardInterrupt) into a
    TypeError ("Cannot compare structured arrays unless they have a common dtype"): a batch
    then recorded an internal error and went on instead of stopping.
    """
    if len(src) == 0:
        return np.zeros(0, int)
    keys = np.round(np.hstack([src, dst]), 3)
    order = np.lexsort(keys.T[::-1])  # stable: equal rows stay in their first order
    ranked = keys[order]
    starts = np.ones(len(keys), bool)
    starts[1:] = np.any(ranked[1:] != ranked[:-1], axis=1)
    return np.sort(order[starts])
