"""The decision's parameters, its verdict, the tests that refuse and the a-contrario count.

:class:`DecisionParams` (the thresholds of every test, ``Config.decision``); :class:`Decision`,
the verdict :func:`scalematch.stages.decision.decide` gives; :data:`TESTS`, the tests that refuse
a best transform and the figures each reports (:func:`figures`, with the final map's
:class:`FinalFigures`); and the a-contrario count of a winner (Moisan & Stival 2004 "ORSA";
docs/ALGORITHM.md step 8): :func:`log10_binom`, :func:`log10_nfa`, :func:`chance_probability`
and :class:`Winner`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar, Mapping, Optional

import numpy as np

from ..checks import Bounds, COUNT, FACTOR, FINITE, MARGIN, NON_NEGATIVE, POSITIVE, PROBABILITY, SHARE, check_bounds, one_of
from ..result import EVIDENCE_DEFAULTS, figure
from .estimator import model_of


@dataclass(frozen=True)
class DecisionParams:
    """The thresholds of every test of the decision (``Config.decision``)."""

    #: fewest inliers ever accepted; the a-contrario test below is the real criterion (true
    #: matches at ratio 10 measured with 7 inliers at log10 NFA -17, unrelated pairs never above
    #: 4 inliers)
    min_inliers: int = 6
    #: log10 of the expected number of chance transforms as good as the winner; -2 means one
    #: in a hundred pairs of unrelated images could show such a transform by chance
    max_log_nfa: float = -2.0
    scale_agreement: float = 1.6  #: implied ratio within this factor of the winning scale
    #: fraction of the finer image's footprint inside the coarser one, required only when the
    #: evidence is not overwhelming (log10 NFA above ``max_log_nfa_alone``) and the second
    #: look's pixels do not confirm the part inside
    #: (:func:`scalematch.stages.secondlook.look_confirms`; taken for this at any count of
    #: inliers): partial overlap is normal for real pairs, where it is proven by the points or the
    #: pixels; what is left is a chance transform hung mostly off the coarser image, whose pixels
    #: cannot be checked (docs/DESIGN.md, "What real pairs need")
    min_inside: float = 0.5
    #: another scale agrees when its transform maps the finer image within this many coarser
    #: px of the winner's (mean over a grid, as EVALUATION.md measures error)
    agreement_px: float = 4.0
    min_agreeing_scales: int = 1  #: other scales that must agree with the winner ...
    #: ... unless the winner alone is this far beyond chance (log10 NFA): the best transforms of
    #: 39 unrelated pairs measured during development never went below -1.05, true ones at
    #: ratio 10 with 7 or 8 inliers reach -17 to -25 (false claims: docs/results/BENCHMARKS.md)
    max_log_nfa_alone: float = -10.0
    min_area_px: float = 64.0  #: smallest footprint area in the coarser image, px^2 (8x8)
    #: the second look may accept a transform with fewer than ``min_inliers`` (the right answer
    #: at ratio 8-10 had 4-5 inliers at log10 NFA -7 to -13; docs/design/DECISION.md, "The
    #: ground for each threshold"), down to this many ...
    few_min_inliers: int = 4
    #: ... when its log10 NFA is at most this (null runs' best transforms: median +4, none
    #: below -6 but the repeated structures, docs/results/NULLS.md) ...
    few_max_log_nfa: float = -6.0
    #: ... and its pixel check beats every nearby wrong placement by this much ZNCC (true
    #: few-inlier answers measured 0.05 to 0.43; random wrong placements at most 0.04,
    #: docs/design/DECISION.md, "The ground for each threshold" and "Guided growth and the
    #: pixel check, alone"); the uniqueness check (``min_unique_ratio``) follows, as for all.
    #: Short of it, the nearby placements compared window by window may confirm instead
    #: (:func:`scalematch.stages.secondlook.look_confirms`: an occluder sinks the one ZNCC;
    #: docs/design/DECISION.md, "The second look, window by window")
    few_min_margin: float = 0.1
    #: ... or, with a pixel margin of at least this, the plain a-contrario bound
    #: (``max_log_nfa``): the pixels then decide. The NFA counts every search made (202 for a
    #: "no" that reaches every view), and few points remain where the footprint is small or
    #: overhangs the coarser image: true 4-5 inlier answers there reach only -2.5 to -4.5, with
    #: pixel margins of 0.27 to 0.87 (zoom pairs at ratio 16, partial pairs at ratios 6-8, the
    #: Oxford pairs zoomed by 8). No null run's best transform of 3 or more
    #: inliers reached half of it: 0.127 at the most in 1216 runs, 0.043 in the 600 runs of
    #: the rule with windows (docs/design/DECISION.md, "The ground for each threshold")
    few_clear_margin: float = 0.25
    #: a transform about to be accepted must place the finer image better than anywhere else in
    #: the coarser one: the misfit (1 - ZNCC) of the best other placement at least this many
    #: times the claimed one's (``stages.uniqueness.uniqueness``). A repeated structure (the
    #: windows of a facade) is matched by many points wherever a copy of it stands. Measured
    #: (docs/results/NULLS.md): the 12 claims of the hardest nulls (two halves of one photo; 6 to 13
    #: inliers, log10 NFA down to -38) 0.48 to 1.1; 152 true zoom pairs 3.75 to 898 (median
    #: 148); Oxford pairs 4.8 to 12.6; tilted pairs 10.7 and more. 2 sits between 1.1 and 3.75.
    #: Compared near the inliers (``PixelParams.vouch_radius``) the facades score 0.70 to 1.83
    #: (600 null runs, docs/design/DECISION.md, "Why the geometry can outweigh the pixels")
    #: nan (the finer image covers the coarser one: no room elsewhere) passes.
    min_unique_ratio: float = 2.0
    #: ... or, compared window by window (``stages.uniqueness.window_agreement``), windows
    #: agreeing at the claim beyond chance (:func:`windows_chance` at most ``max_log_nfa``), of
    #: which this share ...
    min_window_agreement: float = 0.6
    #: ... and this many times the share that agrees anywhere else. An occluder loses only
    #: the windows it covers. Measured (docs/design/DECISION.md, "Windows that agree"): the
    #: null facades that reach the test agree at 0.33 to 0.50 of their windows; the occluded
    #: true pairs one ZNCC refuses at 0.70 to 0.88, 2.7 to 15 times their best elsewhere
    min_window_ratio: float = 2.0
    #: the final (refit) transform must line the pixels up better than its nearby wrong
    #: placements by more than this ZNCC (``Evidence.final_margin``). The search's own check
    #: (``pixel_margin``) cannot serve: it measures the similarity found in a view, which a
    #: tilted scene's true map is not (true tilted claims measured down to -0.56 there).
    #: Measured (scripts/margin_study.py; docs/design/DECISION.md, "The final map: fitting
    #: best, and better than its neighbours") on the 686 right claims
    #: of true pairs (zoom, hard set, Oxford, tilted to t = 8): 0.035 at the least (p5 0.07 to
    #: 0.22 per set); a wrong claim the NFA passes (a tilted view fitted to the wrong tilt) sits
    #: at or below 0 (-0.015 measured). 0 means "a peak of the fit".
    min_final_margin: float = 0.0
    #: ... or, where that one ZNCC refuses, compared window by window over the whole
    #: footprint (``stages.pixelcheck.near_windows``): windows agreeing at the claim beyond
    #: chance (:func:`windows_chance` at the best nearby placement's share, at most
    #: ``max_log_nfa``), at least this share of them, and ``min_window_ratio`` times the
    #: share at the best nearby placement. An occluder loses only the windows it covers.
    #: Measured (docs/design/DECISION.md, "Nearby placements, window by window"): the
    #: occluded true claims this margin refused agree at 0.36 to 0.54 of their windows, their
    #: nearby placements at 0.03 at most; the null claims that reach the final tests (the
    #: halves of one facade, 6 to 13 inliers) at 0.04 to 0.10 where their margin refuses
    min_near_windows: float = 0.3
    #: a transform this far beyond chance (log10 NFA) is judged unique by the geometry alone:
    #: the pixel tests above are measured and recorded, not decisive, unless a second transform
    #: (``second_share``) shows a repeated structure. The pixels of a real pair are broken by
    #: what the points never see: an occluder, a relit or parallax-ridden scene, a no-data
    #: border. Measured (docs/results/NULLS.md, docs/design/DECISION.md): the lowest log10 NFA of
    #: any null run's best transform is -38 (a facade cut in two, refused as ambiguous by its
    #: pixels); true answers refused by the pixels alone had -135 to -2080 (occluded,
    #: padded and 3-D pairs, docs/results/BENCHMARKS.md). -60 leaves 22 orders of magnitude below
    #: the worst null
    max_log_nfa_geometry: float = -60.0
    #: a repeated structure shows as a second transform of the same scale and angle, shifted,
    #: among the candidates the winner leaves over: with at least this share of the winner's
    #: inliers (and ``min_inliers``, beyond chance) the match is refused as ambiguous. Matching
    #: a repeated structure splits each point's nearest neighbour among the copies, so the
    #: copies' support is comparable. Measured on the 500 solved pairs of the realistic sets
    #: (docs/results/BENCHMARKS.md, "Pairs with what real photographs bring"): 0 to 0.286 (median 0,
    #: 99th percentile 0.25); the strongest null facade's second transform: 11 / 13 = 0.85
    second_share: float = 0.5
    #: the second transform's scale within this factor, and its angle within
    #: ``second_angle_deg``, of the winner's: the same structure, elsewhere
    second_scale_factor: float = 1.15
    second_angle_deg: float = 10.0
    #: ... and shifted by at least this fraction of the footprint's size (sqrt of its area): a
    #: copy stands elsewhere, as the pixels' uniqueness test counts it
    #: (``PixelParams.unique_exclusion``); a nearer second similarity is the same scene fitted
    #: piecewise (a tilted plane fits two similarities a few px apart)
    second_min_shift: float = 0.5
    #: the scene shows parallax (``Evidence.parallax``: a 3-D scene, the answer the map of its
    #: dominant plane) when an epipolar geometry explains at least this many of the answer's
    #: outliers among its scale's candidates (``stages.rivals.off_plane``, counted for the
    #: answer by ``answer.answer_parallax``; recorded, never decisive) ...
    parallax_min_points: int = 10
    #: ... and this share of its inliers: a flat scene leaves a few off-plane points that chance
    #: lines up (0 to 2 measured on 15 zoom pairs of real photos), a 3-D scene a share of its
    #: inliers or more (nearly 3 times them on the desk scene of ../shared/data/ef/zoom)
    parallax_share: float = 0.25
    #: distance to the epipolar line within which a candidate fits it, px
    parallax_threshold_px: float = 1.5
    #: fewest candidates the epipolar geometry is fitted to: 8 for its linear solver, and as
    #: many again to tell a fit from a chance one
    parallax_min_candidates: int = 16
    #: its RANSAC's confidence (OpenCV's default, 0.99, stops early on the few hundred
    #: candidates of one scale)
    parallax_confidence: float = 0.999
    #: ... among the candidates the winner's map sends at most this share of the candidates'
    #: extent (its diagonal, coarser px) from their match: the eight 3-D pairs of
    #: ../shared/data/ef moved 90 % of their off-plane points under 0.17 of it, while false
    #: matches sliding along a flat scene's edges lined up at offsets of 0.2 to 1.1
    #: (``stages.rivals.off_plane``)
    parallax_max_offset: float = 0.25
    #: an epipolar geometry's inliers that share a point count once
    #: (:func:`scalematch.stages.finalchecks.one_to_one`): two inliers share one when their finer
    #: points, or their coarser points, lie within this many px of each other. Many finer points
    #: matched to one coarser point lie on every epipolar line through it, so with the epipole there
    #: they all fit: on the null set, the 7 pairs whose matrix reached the plane test had 19 to 46
    #: inliers, 3 to 25 of them such copies; counted once, the strongest fell from log10 NFA -56
    #: to -2.3 (docs/design/DECISION.md). 1 px: a point's position as the detector gives it
    same_point_px: float = 1.0
    #: a fundamental matrix whose inliers show no parallax
    #: (:func:`scalematch.stages.finalchecks.plane_parallax`) gives way to the plane map of the same
    #: pair (``answer.without_parallax``), searched with this model: the default's, which the model
    #: check turns into an affine map or a homography where the scene asks for one
    plane_model: str = "similarity"

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "min_inliers": COUNT,
        "min_agreeing_scales": COUNT,
        "max_log_nfa": FINITE,
        "same_point_px": NON_NEGATIVE,
        "max_log_nfa_alone": FINITE,
        "scale_agreement": FACTOR,
        "min_inside": SHARE,
        "agreement_px": POSITIVE,
        "min_area_px": NON_NEGATIVE,
        "few_min_inliers": COUNT,
        "few_max_log_nfa": FINITE,
        "few_min_margin": MARGIN,
        "few_clear_margin": MARGIN,
        "min_unique_ratio": NON_NEGATIVE,
        "min_window_agreement": SHARE,
        "min_window_ratio": NON_NEGATIVE,
        "min_final_margin": MARGIN,
        "min_near_windows": SHARE,
        "max_log_nfa_geometry": FINITE,
        "second_share": NON_NEGATIVE,
        "second_scale_factor": FACTOR,
        "second_angle_deg": NON_NEGATIVE,
        "second_min_shift": NON_NEGATIVE,
        "parallax_min_points": COUNT,
        "parallax_share": NON_NEGATIVE,
        "parallax_max_offset": Bounds(lo=0, allow_inf=True),
        "parallax_threshold_px": POSITIVE,
        "parallax_min_candidates": Bounds(lo=8, integer=True),
        "parallax_confidence": PROBABILITY,
    }

    def __post_init__(self) -> None:
        check_bounds("decision", self, self.BOUNDS)
        one_of("decision", "plane_model", self.plane_model, ("similarity", "affine", "homography"))


@dataclass(frozen=True)
class Decision:
    """The verdict of :func:`scalematch.stages.decision.decide`: a match, or a "no" and why."""

    matched: bool
    reason: str
    best_scale: float
    transform: Optional[np.ndarray] = field(repr=False)
    inliers: np.ndarray = field(repr=False)  #: (N, 4) x, y finer; x, y coarser
    #: the figures its tests reached, by :class:`~scalematch.result.Evidence`'s names (the
    #: answer makes its one Evidence of them: ``answer.evidence_of``)
    figures: Mapping[str, Any] = field(default_factory=dict)
    #: a "no": the test that refused (a key of ``TESTS``; "" when matched or nothing to refuse)
    test: str = ""
    #: a "no": the best transform and its inliers, as ``transform`` and ``inliers`` would be
    candidate: Optional[np.ndarray] = field(default=None, repr=False)
    candidate_inliers: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)), repr=False)

    @property
    def log10_nfa(self) -> float:
        """The a-contrario figure of its best transform (inf where none was counted)."""
        return float(figure(self.figures, "log10_nfa"))

    @property
    def counted(self) -> int:
        """The inliers the a-contrario test counted (one to one for an epipolar geometry)."""
        return int(figure(self.figures, "inliers"))


#: The tests that refuse a best transform, and the figures each reports (from the evidence,
#: then from :class:`DecisionParams`): the ``rejected`` block of a "no" (``result.Rejected``)
TESTS = {
    "too few inliers": ("inliers", "min_inliers", "log10_nfa", "pixel_margin"),
    "chance": ("inliers", "candidates", "log10_nfa", "max_log_nfa"),
    "folded": (),
    "footprint area": ("footprint_area_px", "min_area_px"),
    "footprint inside": ("footprint_inside", "min_inside", "log10_nfa", "max_log_nfa_alone",
                         "pixel_margin"),
    "agreeing scales": ("agreeing_scales", "min_agreeing_scales", "log10_nfa",
                        "max_log_nfa_alone"),
    "repeated structure": ("inliers", "second_inliers", "second_gap_px", "second_share"),
    "nearby placement": ("inliers", "log10_nfa", "pixel_ncc", "pixel_margin"),
    "uniqueness": ("unique_ratio", "min_unique_ratio", "unique_claimed", "unique_elsewhere",
                   "unique_windows", "windows_agreeing", "windows_elsewhere",
                   "min_window_agreement", "log10_nfa", "max_log_nfa_geometry"),
    "pixels": ("final_margin", "min_final_margin", "near_windows", "near_windows_agreeing",
               "near_windows_nearby", "min_near_windows", "log10_nfa", "max_log_nfa_geometry"),
    "plane": ("inliers", "log10_nfa", "parallax_points", "parallax_log10_nfa", "max_log_nfa",
              "plane_inliers", "parallax_vouched_points", "epipole_log10_nfa", "plane_windows",
              "plane_windows_agreeing", "plane_windows_nearby"),
}


@dataclass(frozen=True)
class FinalFigures:
    """The pixel tests of a match's final transform
    (:func:`scalematch.stages.finalchecks.final_checks`): the figures of the same names in
    :class:`Evidence`."""

    unique_claimed: float  #: ZNCC of the finer image at the claimed placement
    unique_elsewhere: float  #: the best ZNCC anywhere half a footprint away
    unique_ratio: float  #: misfit elsewhere over misfit at the claim
    final_ncc: float  #: ZNCC under the final transform
    final_margin: float  #: how much better than the nearby wrong placements
    judged_by: str  #: "geometry" or "pixels": what judged the match unique
    #: the uniqueness test by windows, measured when one ZNCC refuses (0 and nan: not measured)
    unique_windows: int = 0  #: windows compared
    windows_agreeing: float = math.nan  #: share of them that agree at the claim
    windows_elsewhere: float = math.nan  #: the highest share anywhere else
    #: the nearby placements by windows, measured when the final margin refuses (0 and nan:
    #: not measured)
    near_windows: int = 0  #: windows compared
    near_windows_agreeing: float = math.nan  #: share of them that agree at the claim
    near_windows_nearby: float = math.nan  #: the highest share at a nearby placement


def figures(test: str, reached: Mapping[str, Any], params: DecisionParams,
            final: Optional[FinalFigures] = None) -> dict:
    """The figures of ``test`` (:data:`TESTS`): name -> value, from the final transform's
    pixel tests (``final``, when it faced them), the figures ``reached`` (by
    :class:`~scalematch.result.Evidence`'s names; its default where not reached) or the params.

    >>> figures("chance", dict(inliers=5, candidates=40, log10_nfa=-1.0), DecisionParams())
    {'inliers': 5, 'candidates': 40, 'log10_nfa': -1.0, 'max_log_nfa': -2.0}
    """
    def one(name: str):
        if final is not None and hasattr(final, name):
            return getattr(final, name)
        return figure(reached, name) if name in EVIDENCE_DEFAULTS else getattr(params, name)

    return {name: one(name) for name in TESTS.get(test, ())}



def log10_binom(n: int, k: int) -> float:
    if k < 0 or k > n:
        return -math.inf
    return (math.lgamma(n + 1) - math.lgamma(k + 1) - math.lgamma(n - k + 1)) / math.log(10)


def log10_binomial_tail(n: int, k: int, p: float) -> float:
    """log10 P[Bin(n, p) >= k], summed exactly (n is a few hundred at most here).

    >>> round(log10_binomial_tail(4, 4, 0.5), 4) == round(math.log10(1 / 16), 4)
    True
    >>> log10_binomial_tail(10, 0, 0.3)
    0.0
    """
    if k <= 0:
        return 0.0
    if k > n or p <= 0.0:
        return -math.inf
    if p >= 1.0:
        return 0.0
    terms = [log10_binom(n, i) + i * math.log10(p) + (n - i) * math.log10(1.0 - p)
             for i in range(k, n + 1)]
    top = max(terms)
    return top + math.log10(sum(10.0 ** (t - top) for t in terms))


def succession(count: int, n: int) -> float:
    """Laplace's rule of succession: the chance of one more success after ``count`` of ``n``,
    (c + 1) / (n + 2), which no count of 0 makes 0."""
    return (count + 1.0) / (n + 2.0)


def windows_chance(windows: int, claimed: float, other: float) -> float:
    """log10 of the chance that ``claimed`` (a share) of ``windows`` windows agree at a
    placement where each agrees as often as at the best other placement (``other``, a share):
    the binomial tail at that rate, the rate read by the rule of succession
    (:func:`succession` of the count agreeing there). A handful of
    windows cannot carry a claim however many agree (1 of 1 against 0 of 1: 10^-0.5); 8 of 11
    against 2 of 11 can (10^-3.2). A share that is nan (nothing compared) gives +inf.

    >>> round(windows_chance(11, 8 / 11, 2 / 11), 2), round(windows_chance(1, 1.0, 0.0), 2)
    (-3.18, -0.48)
    """
    if windows <= 0 or not math.isfinite(claimed):
        return math.inf
    other = other if math.isfinite(other) else 0.0
    agree, elsewhere = round(claimed * windows), round(other * windows)
    return log10_binomial_tail(windows, agree, succession(elsewhere, windows))


def log10_nfa(n: int, k: int, m: int, p: float, tests: float) -> float:
    """log10 of the number of false alarms of a k-inlier consensus among n candidates."""
    if k <= m or n <= m:
        return math.inf
    return (math.log10(max(tests, 1.0)) + log10_binom(n, k) + log10_binom(k, m)
            + (k - m) * math.log10(max(min(p, 1.0), 1e-300)))


def chance_probability(threshold_px: float, coarser_shape, model: str, oriented: bool,
                       orientation_tol_deg: float) -> float:
    """p: chance that a candidate with a uniform random position in the coarser image fits
    within threshold."""
    h, w = coarser_shape
    p = model_of(model).chance_area(threshold_px, (h, w)) / (h * w)
    if oriented:
        p *= 2.0 * orientation_tol_deg / 360.0
    return min(p, 1.0)


@dataclass(frozen=True)
class Winner:
    """The winning scale's outcome and its a-contrario count (:func:`log10_nfa`)."""

    outcome: object = field(repr=False)  #: a ``plan.ScaleOutcome``
    k: int  #: its inliers
    n: int  #: its candidates (at least ``k``)
    m: int  #: the model's minimal sample
    p: float  #: the chance that one random candidate fits (:func:`chance_probability`)
    tests: int  #: scales with candidates x subsets x searches x rotation groups
    log10_nfa: float

    def nfa_of(self, inliers: int) -> float:
        """log10 NFA of another consensus of ``inliers`` among the same candidates."""
        return log10_nfa(self.n, inliers, self.m, self.p, self.tests)
