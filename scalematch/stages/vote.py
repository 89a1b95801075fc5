"""The pooled vote: which view pairs and scales of a search are worth matching in full.

Every image is described once, in every view and at every scale (:mod:`scalematch.search.features`),
and the candidate matches of all view pairs are found in one pass of nearest neighbours per
side. Each candidate pairs two oriented points at known scales, so it predicts a whole
similarity between the two views: the ratio is the finer point's scale, the rotation the
difference of their orientations, the shift what puts the finer point on the coarser one. Every
candidate votes once in a table over (finer view, coarser view, scale, rotation, shift), in the
two nearest bins of each of the last three (Lowe 2004, "Distinctive image features from
scale-invariant keypoints", section 7.3: bins of 30 degrees, and of a quarter of the matched
image's size for the shift).

A cell is worth a full match when its votes are beyond chance. The count is a-contrario
(Desolneux, Moisan & Morel 2008): under the null hypothesis a candidate's shift and rotation are
uniform, so it falls in a given cell with probability ``p`` (the cell's 8 bins among the
group's), and a cell of ``k`` distinct votes among the ``n`` candidates of its (view pair,
scale) group has ``NFA = cells * C(n, k) p^k`` (the union bound on the binomial tail, as the
decision's count), ``cells`` the number of cells of the whole vote: every cell tried is counted.

Nothing here decides a match: the vote ranks the cells, and the matches it leads to face the
decision (:mod:`scalematch.stages.decision`) like any other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import ClassVar, List, Mapping, Sequence, Tuple

import numpy as np

from ..checks import AT_LEAST_ONE, Bounds, POSITIVE, check_bounds

#: Scales are indexed by third octaves: index round(3 log2 s) (1, 1.26, 1.59, 2, ... -> 0, 1, 2,
#: 3, ...), as the default's scales; two scales within the same index are one
SCALE_STEPS_PER_OCTAVE = 3
#: Widths of the fields of a packed cell key (:func:`_packed`): views, scale index, rotation bin
#: and shift bins (offset by half their range, so negative bins pack too)
_VIEW_BITS, _SCALE_BITS, _ROT_BITS, _SHIFT_BITS = 8, 6, 6, 14


@dataclass(frozen=True)
class VoteParams:
    """The bins of the vote and how far beyond chance a cell must be to be matched in full."""

    #: rotation bins over 360 degrees: 30 degrees each (Lowe 2004, section 7.3)
    rotation_bins: int = 12
    #: shift bins across the finer view's footprint (its longer side at the cell's scale): a
    #: quarter of it each (Lowe 2004: "0.25 times the maximum projected training image dimension")
    shift_bins: float = 4.0
    #: a cell is matched in full only when its log10 NFA is at most this: one false alarm
    #: expected over the whole vote at 0. Measured on the gate's tilted, steep and oblique
    #: pairs (the right view pairs' best cells at -6.6 to -170) and its unrelated and
    #: same-photo pairs (the best cell of each at -8.1 to 0.0, median -3.0): the bound sends
    #: about half the null pairs to no full match at all, and the decision judges the rest
    #: (``scripts/vote_ranking.py``; docs/design/VIEWS.md, "The pooled vote")
    max_log_nfa: float = -3.0
    #: fewest distinct votes a cell needs to be counted (two points fix a similarity)
    min_votes: int = 3

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "rotation_bins": Bounds(lo=1, hi=(1 << _ROT_BITS) - 1, integer=True),
        "shift_bins": POSITIVE,
        "max_log_nfa": Bounds(),
        "min_votes": AT_LEAST_ONE,
    }

    def __post_init__(self) -> None:
        check_bounds("vote", self, self.BOUNDS)


@dataclass(frozen=True)
class Candidates:
    """Candidate matches of one side of a vote, from a point of a finer view at a scale to a
    point of a coarser view (K rows each); positions in each view's pixels."""

    finer_view: np.ndarray = field(repr=False)  #: (K,) int, index of the finer view
    coarser_view: np.ndarray = field(repr=False)  #: (K,) int, index of the coarser view
    s: np.ndarray = field(repr=False)  #: (K,) the finer point's scale in its view's pixels
    finer_xy: np.ndarray = field(repr=False)  #: (K, 2) finer view px
    coarser_xy: np.ndarray = field(repr=False)  #: (K, 2) coarser view px
    rotation: np.ndarray = field(repr=False)  #: (K,) coarser angle - finer angle, radians
    #: (K,) ids of the points (a point described at two orientations, or matched twice, is one)
    finer_point: np.ndarray = field(repr=False)
    coarser_point: np.ndarray = field(repr=False)

    def __len__(self) -> int:
        return int(self.s.shape[0])

    @staticmethod
    def joined(parts: Sequence["Candidates"]) -> "Candidates":
        """``parts`` as one set of candidates, in their order (none: an empty set)."""
        if not parts:
            ints, xy = np.zeros(0, np.int64), np.zeros((0, 2))
            return Candidates(ints, ints, np.zeros(0), xy, xy, np.zeros(0), ints, ints)
        return Candidates(*(np.concatenate([getattr(part, f.name) for part in parts])
                            for f in fields(Candidates)))


@dataclass(frozen=True)
class Cells:
    """The cells of a vote with at least ``min_votes`` votes (C rows each), and the number of
    cells the whole vote tried (``tried``, the a-contrario count's multiplier)."""

    finer_view: np.ndarray = field(repr=False)  #: (C,) int
    coarser_view: np.ndarray = field(repr=False)  #: (C,) int
    scale_index: np.ndarray = field(repr=False)  #: (C,) int, :func:`scale_index`
    votes: np.ndarray = field(repr=False)  #: (C,) int, distinct points voting (the fewer side's)
    candidates: np.ndarray = field(repr=False)  #: (C,) int, candidates of the cell's group
    chance: np.ndarray = field(repr=False)  #: (C,) probability of a candidate in the cell
    tried: int

    def __len__(self) -> int:
        return int(self.votes.shape[0])


def scale_index(s: np.ndarray) -> np.ndarray:
    """The third-octave index of each scale (``SCALE_STEPS_PER_OCTAVE``).

    >>> scale_index(np.array([1.0, 1.26, 1.587, 2.0, 16.0])).tolist()
    [0, 1, 2, 3, 12]
    """
    return np.round(np.log2(np.asarray(s, np.float64)) * SCALE_STEPS_PER_OCTAVE).astype(np.int64)


def index_scale(index: np.ndarray) -> np.ndarray:
    """The scale of a third-octave index (the inverse of :func:`scale_index`)."""
    return 2.0 ** (np.asarray(index, np.float64) / SCALE_STEPS_PER_OCTAVE)


def _packed(fields: Sequence[np.ndarray]) -> np.ndarray:
    """(finer view, coarser view, scale index, rotation bin, shift x, shift y) as one int64."""
    widths = (_VIEW_BITS, _VIEW_BITS, _SCALE_BITS, _ROT_BITS, _SHIFT_BITS, _SHIFT_BITS)
    offsets = (0, 0, 0, 0, 1 << (_SHIFT_BITS - 1), 1 << (_SHIFT_BITS - 1))
    code = np.zeros(len(fields[0]), np.int64)
    for values, width, offset in zip(fields, widths, offsets):
        code = (code << width) | np.clip(values + offset, 0, (1 << width) - 1)
    return code


def group_cells(finer_side: np.ndarray, coarser_shape: np.ndarray, s: np.ndarray,
                params: VoteParams) -> Tuple[np.ndarray, np.ndarray]:
    """(cells of a (view pair, scale) group, chance of a candidate in one cell): the shift
    ranges over the coarser view and a footprint around it (``finer_side / s`` px, the finer
    view's longer side at the scale), in bins of ``footprint / shift_bins``, times the rotation
    bins; a candidate votes in 8 cells (two bins a dimension).

    >>> cells, p = group_cells(np.array([640.0]), np.array([[480.0, 640.0]]), np.array([4.0]),
    ...                        VoteParams())
    >>> int(cells[0]), round(float(p[0]), 6)
    (3840, 0.002083)
    """
    footprint = np.asarray(finer_side, np.float64) / np.asarray(s, np.float64)
    width = footprint / params.shift_bins
    shape = np.asarray(coarser_shape, np.float64).reshape(-1, 2)
    cells = params.rotation_bins * np.ceil((shape[:, 1] + footprint) / width) * np.ceil(
        (shape[:, 0] + footprint) / width)
    return cells, np.minimum(1.0, 8.0 / cells)


def vote(c: Candidates, finer_sides: np.ndarray, coarser_shapes: np.ndarray,
         params: VoteParams = VoteParams()) -> Cells:
    """The cells of one side's candidates ``c``; ``finer_sides``: (V_f,) the longer side of
    each finer view, px; ``coarser_shapes``: (V_c, 2) each coarser view's (H, W).

    A candidate (finer point p at scale s, coarser point q, rotation theta) predicts the
    similarity ``q = R(theta) p / s + tau`` between the two views; it votes for its (view pair,
    scale index) group's two nearest rotation bins and two nearest shift bins along x and y.
    A cell's votes are the distinct points voting in it, counted on the side with fewer (many
    finer points matched to one coarser point are one vote).
    """
    if len(c) == 0:
        return _no_cells()
    fv, cv = c.finer_view.astype(np.int64), c.coarser_view.astype(np.int64)
    si = scale_index(c.s)
    s = np.asarray(c.s, np.float64)
    cos, sin = np.cos(c.rotation), np.sin(c.rotation)
    p, q = np.asarray(c.finer_xy, np.float64), np.asarray(c.coarser_xy, np.float64)
    tau = q - np.stack([cos * p[:, 0] - sin * p[:, 1], sin * p[:, 0] + cos * p[:, 1]], 1) / s[:, None]
    width = np.asarray(finer_sides, np.float64)[fv] / s / params.shift_bins
    rot = (np.asarray(c.rotation, np.float64) / (2 * math.pi) * params.rotation_bins) % \
        params.rotation_bins
    codes, which = [], []
    for dr in (0, 1):
        rb = (np.floor(rot - 0.5).astype(np.int64) + dr) % params.rotation_bins
        for dx in (0, 1):
            xb = np.floor(tau[:, 0] / width - 0.5).astype(np.int64) + dx
            for dy in (0, 1):
                yb = np.floor(tau[:, 1] / width - 0.5).astype(np.int64) + dy
                codes.append(_packed((fv, cv, si, rb, xb, yb)))
                which.append(np.arange(len(c)))
    code, k = np.concatenate(codes), np.concatenate(which)
    cells, first, inv = np.unique(code, return_index=True, return_inverse=True)
    inv = inv.ravel()
    votes = np.minimum(_distinct(inv, c.finer_point[k], len(cells)),
                       _distinct(inv, c.coarser_point[k], len(cells)))
    group = (fv << (_VIEW_BITS + _SCALE_BITS)) | (cv << _SCALE_BITS) | si
    groups, g_inv, g_count = np.unique(group, return_inverse=True, return_counts=True)
    g_fv, g_cv = groups >> (_VIEW_BITS + _SCALE_BITS), (groups >> _SCALE_BITS) & ((1 << _VIEW_BITS) - 1)
    g_si = groups & ((1 << _SCALE_BITS) - 1)
    g_cells, g_p = group_cells(np.asarray(finer_sides, np.float64)[g_fv],
                               np.asarray(coarser_shapes, np.float64)[g_cv], index_scale(g_si),
                               params)
    keep = votes >= params.min_votes
    g_of = g_inv.ravel()[k[first]]
    return Cells(fv[k[first]][keep], cv[k[first]][keep], si[k[first]][keep], votes[keep],
                 g_count[g_of][keep], g_p[g_of][keep], int(g_cells.sum()))


def _distinct(cell: np.ndarray, point: np.ndarray, n_cells: int) -> np.ndarray:
    """How many distinct ``point`` ids vote in each of ``n_cells`` cells."""
    span = int(np.max(point)) + 1 if len(point) else 1
    pairs = np.unique(cell.astype(np.int64) * span + np.asarray(point, np.int64))
    return np.bincount(pairs // span, minlength=n_cells)


def _no_cells() -> Cells:
    empty = np.zeros(0, np.int64)
    return Cells(empty, empty, empty, empty, empty, np.zeros(0), 0)


def log10_nfa(cells: Cells, tried: int) -> np.ndarray:
    """Each cell's log10 number of false alarms among ``tried`` cells (every side's, every
    direction's): ``log10(tried) + log10 C(n, k) + k log10 p`` (``acontrario.log10_binom``'s
    binomial, over arrays through one table of log-factorials).

    >>> c = Cells(*(np.array([0]),) * 3, np.array([3]), np.array([10]), np.array([0.01]), 100)
    >>> round(float(log10_nfa(c, 100)[0]), 4) == round(2 + math.log10(120) - 6, 4)
    True
    """
    n = np.asarray(cells.candidates, np.int64)
    k = np.asarray(cells.votes, np.int64)
    log_fact = np.concatenate([[0.0], np.cumsum(np.log10(np.arange(1, int(n.max(initial=0)) + 1)))])
    binom = log_fact[n] - log_fact[k] - log_fact[n - k]
    return binom + k * np.log10(np.maximum(cells.chance, 1e-300)) + math.log10(max(tried, 1))


@dataclass(frozen=True)
class Ranked:
    """A view pair worth matching in full: its side (an index into the sides voted), its best
    cell and the scales of its cells beyond chance, best first."""

    side: int
    finer_view: int
    coarser_view: int
    log10_nfa: float  #: the best cell's
    votes: int  #: the best cell's
    scale_indices: Tuple[int, ...]  #: of the pair's cells beyond chance, best first


def best_pairs(cells: Sequence[Cells], nfa: Sequence[np.ndarray], limit: int,
               params: VoteParams) -> List[Ranked]:
    """The ``limit`` view pairs, over every side's ``cells`` (with their log10 NFA ``nfa``),
    whose best cell has the lowest log10 NFA, among the cells at or below
    ``params.max_log_nfa``; each with the scales of its cells beyond chance, best first.

    >>> c = Cells(np.array([1, 1, 2]), np.array([0, 0, 0]), np.array([3, 4, 6]),
    ...           np.array([9, 5, 7]), np.array([40, 40, 30]), np.array([1e-3] * 3), 1000)
    >>> [(r.side, r.finer_view, r.scale_indices)
    ...  for r in best_pairs([c], [np.array([-9.0, -4.0, -1.0])], 3, VoteParams())]
    [(0, 1, (3, 4))]
    """
    side = np.concatenate([np.full(len(c), k, np.int64) for k, c in enumerate(cells)] or
                          [np.zeros(0, np.int64)])
    row = np.concatenate([np.arange(len(c)) for c in cells] or [np.zeros(0, np.int64)])
    lnfa = np.concatenate(list(nfa) or [np.zeros(0)])
    pairs: dict = {}
    for i in np.argsort(lnfa, kind="stable"):
        if lnfa[i] > params.max_log_nfa:
            break
        c, r = cells[side[i]], row[i]
        key = (int(side[i]), int(c.finer_view[r]), int(c.coarser_view[r]))
        if key not in pairs:
            if len(pairs) == limit:
                continue
            pairs[key] = Ranked(*key, float(lnfa[i]), int(c.votes[r]), ())
        si, got = int(c.scale_index[r]), pairs[key]
        if si not in got.scale_indices:
            pairs[key] = Ranked(got.side, got.finer_view, got.coarser_view, got.log10_nfa,
                                got.votes, got.scale_indices + (si,))
    return list(pairs.values())
