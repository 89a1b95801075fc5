"""The probe: how promising each scale of a search looks from its strongest points (paper 5).

The paper notes (section 5) that the initial matches already point at the best scale. The
probe describes only the ``ProbeParams.points`` strongest points of each scale, matches them
against the coarser image, and scores each scale; only the best-scoring scales (and their
neighbours) are then matched in full. The same scores rank the simulated views of a pass, and
tell a search with nothing in it from one worth finishing (:mod:`scalematch.search`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import ClassVar, List, Mapping, Optional, Sequence

import numpy as np

from ..checks import AT_LEAST_ONE, NON_NEGATIVE, Bounds, check_bounds
from ..geometry import similarity_parts
from .constraints import OrientationParams, orientation_groups
from .descriptors import Described
from .estimator import FitSpec, estimate
from .matcher import Candidates, MatcherParams, distinct_pairs, match_descriptors


@dataclass(frozen=True)
class ProbeParams:
    """Skipping hopeless scales from the initial matches of their strongest points (paper 5)."""

    enabled: bool = True  #: False runs the full matching at every scale
    #: strongest points per scale used to score it (100 and 150 measured the same success on
    #: the 38 photos at ratios 8 and 10; 100 is 16 % faster)
    points: int = 100
    keep: int = 3  #: best-scoring scales kept, each with its two neighbours
    #: a scale is among the best only with at least this score: its quick fit holds a distinct
    #: point pair beyond its minimal sample (a similarity is fixed by 2 points, so 2 inliers
    #: are no evidence). A null pair's scales score 0 to 2 at nearly every scale, and were
    #: matched in full for nothing; on the gate's pairs, no run was lost and 4 moved by under
    #: 0.2 px (docs/design/SPEED.md, "The probe's floor"). 0 keeps the best scales whatever
    #: they score
    min_score: float = 3.0
    #: RANSAC iterations of the probe's quick fit: 500 draws find a 2-point sample of inliers
    #: with 99.9 % confidence down to an inlier fraction of 12 %
    ransac_iters: int = 500

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "points": AT_LEAST_ONE,
        "keep": AT_LEAST_ONE,
        "min_score": NON_NEGATIVE,
        "ransac_iters": AT_LEAST_ONE,
    }

    def __post_init__(self) -> None:
        check_bounds("probe", self, self.BOUNDS)


def probe_scores(highs: Sequence[Described], low: Described, params: ProbeParams, *,
                 matcher: MatcherParams, orientation: Optional[OrientationParams],
                 fit: FitSpec, scale_agreement: float) -> List[float]:
    """How promising each scale looks from the initial matches of its strongest points alone.

    Each of ``highs`` holds the ``ProbeParams.points`` strongest points of one scale. In the
    paper mode (``orientation`` None: descriptors without an orientation) a scale's score is
    their number of candidate matches. In the default mode it is the number of distinct inliers
    (point pairs: a point described at two orientations counts once) of a quick similarity fit
    to the candidates in the dominant rotation peak, counted only when the fit's ratio agrees
    with the scale: rotation alone cannot rank scales where the scene's edges
    share a few directions (facades), geometry can. One nearest-neighbour search serves every
    scale (each candidate depends on its own row only; one large product is faster than many
    small ones).

    ``matcher``: the candidates' parameters; ``fit``: the quick fit's model (a similarity),
    RANSAC parameters (run with ``params.ransac_iters`` iterations) and the one seed;
    ``scale_agreement``: how far a fit's ratio may be from its scale
    (``DecisionParams.scale_agreement``).
    """
    if not highs:
        return []
    cand = match_descriptors(np.vstack([h.desc for h in highs]), low.desc, matcher)
    bounds = np.cumsum([0] + [len(h) for h in highs])
    quick = replace(fit, ransac=replace(fit.ransac, max_iters=params.ransac_iters))
    out = []
    for h, lo, hi in zip(highs, bounds[:-1], bounds[1:]):
        rows = (cand.i >= lo) & (cand.i < hi)
        part = Candidates(cand.i[rows] - lo, cand.j[rows], cand.distance[rows], cand.second[rows])
        out.append(_score(h, low, part, orientation, quick, scale_agreement))
    return out


def _score(high: Described, low: Described, cand: Candidates,
           orientation: Optional[OrientationParams], quick: FitSpec,
           scale_agreement: float) -> float:
    if len(cand) == 0:
        return 0.0
    if orientation is None:  # nothing to group the candidates by: their number
        return float(len(cand))
    groups = orientation_groups(low.angle[cand.j] - high.angle[cand.i], orientation)
    best = 0.0
    for mask in groups:
        # distinct pairs, as the full match fits them (search.full): a point described at two
        # orientations is matched twice, and a chance similarity through two points and such a
        # copy would score 3, the floor
        src, dst = distinct_pairs(high.xy[cand.i[mask]], low.xy[cand.j[mask]])
        est = estimate(quick.model, src, dst, quick.ransac, seed=quick.seed)
        if est.transform is None:
            continue
        ratio = similarity_parts(est.transform)[0]
        if math.isfinite(ratio) and abs(math.log(ratio / high.s)) <= math.log(scale_agreement):
            best = max(best, float(est.n_inliers))
    return best


def select_scales(scores: List[float], keep: int, min_score: float = 0.0) -> List[int]:
    """Indices of the ``keep`` best-scoring scales and their immediate neighbours.

    >>> select_scales([0.0, 5.0, 1.0, 0.0, 9.0], keep=1)
    [3, 4]
    """
    order = [i for i in sorted(range(len(scores)), key=lambda i: (-scores[i], i))[:keep]
             if scores[i] >= min_score]
    chosen = set()
    for i in order:
        chosen.update(j for j in (i - 1, i, i + 1) if 0 <= j < len(scores))
    return sorted(chosen)
