"""Scale selection and the decision "matched" or "no reliable match" (docs/ALGORITHM.md steps 7-8).

**Scale selection.** The scale with the most inliers wins (paper section 4.2); ties go to the
scale whose transform implies a ratio closest to the scale itself (the scale-space premise
s = 1/h), then to the smaller scale.

**Decision.** A wrong transform reported as a match is the worst outcome, so the winner must
show evidence that an unrelated pair cannot produce:

1. *Inliers beyond chance* (a contrario, Moisan & Stival 2004 "ORSA"): under the background
   model where the coarser-image end of each candidate is uniform over the coarser image (and,
   in the default mode, its orientation uniform over the circle), the expected number of transforms
   with k inliers among n candidates, over all scales and subsets tried, is
   ``NFA = tests * C(n, k) * C(k, m) * p^(k - m)``, with m the model's minimal sample and
   p the chance that one random candidate lands within the inlier threshold, and ``tests``
   counts the scales, the candidate subsets and the ``searches`` made (orders and simulated
   views: trying more must not make a chance transform look reliable). The match needs
   ``log10 NFA <= max_log_nfa``, and at least ``min_inliers``.
2. *A plausible scale*: the ratio the transform implies agrees with the scale it was found at
   (within ``scale_agreement``), as the scale-space premise demands of a true match.
3. *A plausible footprint*: the finer image maps onto a region of the coarser image that is
   not degenerate (folded over, or smaller than ``min_area_px``). A footprint that lies mostly
   outside the coarser image (a telephoto frame overhanging the wide one) is normal and accepted
   when the evidence is overwhelming (``max_log_nfa_alone``) or when the pixels of the part
   inside confirm a few-inlier map (:func:`look_confirms`); with weaker evidence at least
   ``min_inside`` of it must lie inside.
4. *Consistent neighbouring scales*: at least ``min_agreeing_scales`` other scales found
   (nearly) the same transform, as the paper's Table 1 shows for a true match.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, Dict, Mapping, Optional, Sequence, Tuple

import numpy as np

from ..checks import AT_LEAST_ONE, Bounds, COUNT, FACTOR, FINITE, MARGIN, NON_NEGATIVE, POSITIVE, PROBABILITY, SHARE, check_bounds, one_of
from ..geometry import apply, footprint, grid
from ..result import Evidence, build_evidence
from .constraints import OrientationParams
from .descriptors import Described
from .estimator import FitSpec, estimate, model_of
from .guided import GuidedParams, grow
from .nodata import with_nan
from .pixelcheck import NearWindows, PixelParams, near_windows, pixel_check
from .uniqueness import Agreement, agreement_of, unique_template, uniqueness_of
from .nearby import Nearby, best_nearby
from .rivals import mean_transfer_gap, same_scale_and_angle, second_transform, Second
from .threads import thread_map


#: Points along each side of the grid that measures a footprint's share inside the coarser
#: image: numerics, not a threshold (an area's quadrature: 121 points put the share within
#: 1/11 of the exact one, and ``DecisionParams.min_inside`` is compared with it)
INSIDE_GRID_POINTS = 11


@dataclass(frozen=True)
class DecisionParams:
    #: fewest inliers ever accepted; the a-contrario test below is the real criterion (true
    #: matches at ratio 10 measured with 7 inliers at log10 NFA -17, unrelated pairs never above
    #: 4 inliers)
    min_inliers: int = 6
    #: log10 of the expected number of chance transforms as good as the winner; -2 means one
    #: in a hundred pairs of unrelated images could show such a transform by chance
    max_log_nfa: float = -2.0
    scale_agreement: float = 1.6  #: implied ratio within this factor of the winning scale
    #: fraction of the finer image's footprint inside the coarser one, required only when the
    #: evidence is not overwhelming (log10 NFA above ``max_log_nfa_alone``): partial overlap is
    #: normal for real pairs (912 inliers at log10 NFA -4681 were refused at 50 %;
    #: docs/DESIGN.md, "What real pairs need"), or when the second look's pixels confirm it
    #: (:func:`look_confirms`; taken for this at any count of inliers)
    min_inside: float = 0.5
    #: another scale agrees when its transform maps the finer image within this many coarser
    #: px of the winner's (mean over a grid, as EVALUATION.md measures error)
    agreement_px: float = 4.0
    min_agreeing_scales: int = 1  #: other scales that must agree with the winner ...
    #: ... unless the winner alone is this far beyond chance (log10 NFA): the best transforms of
    #: 39 unrelated pairs measured during development never went below -1.05, true ones at
    #: ratio 10 with 7 or 8 inliers reach -17 to -25 (false claims: docs/BENCHMARKS.md)
    max_log_nfa_alone: float = -10.0
    min_area_px: float = 64.0  #: smallest footprint area in the coarser image, px^2 (8x8)
    #: a best transform with at least this many distinct inliers, and fewer than
    #: ``min_inliers``, gets a second look (guided growth and the pixel check,
    #: :func:`look_again`), recorded in the evidence
    look_min_inliers: int = 3
    #: the second look may accept a transform with fewer than ``min_inliers`` (the right answer
    #: at ratio 8-10 had 4-5 inliers at log10 NFA -7 to -13; docs/design/DECISION.md, "The
    #: ground for each threshold"), down to this many ...
    few_min_inliers: int = 4
    #: ... when its log10 NFA is at most this (null runs' best transforms: median +4, none
    #: below -6 but the repeated structures, docs/NULLS.md) ...
    few_max_log_nfa: float = -6.0
    #: ... its guided growth keeps at least this many inliers (0: growth is recorded, not
    #: required: at the coarse scales where few points remain there is nothing to grow into;
    #: measured 5 -> 5 on the true 5-inlier answers at ratio 10-16, docs/design/DECISION.md,
    #: "The ground for each threshold") ...
    few_min_grown: int = 0
    #: ... and its pixel check beats every nearby wrong placement by this much ZNCC (true
    #: few-inlier answers measured 0.05 to 0.43; random wrong placements at most 0.04,
    #: docs/design/DECISION.md, "The ground for each threshold" and "Guided growth and the
    #: pixel check, alone"); the uniqueness check (``min_unique_ratio``) follows, as for all.
    #: Short of it, the nearby placements compared window by window may confirm instead
    #: (:func:`look_confirms`: an occluder sinks the one ZNCC; docs/design/DECISION.md, "The
    #: second look, window by window")
    few_min_margin: float = 0.1
    #: ... or, with a pixel margin of at least this, the plain a-contrario bound
    #: (``max_log_nfa``): the pixels then decide. The NFA counts every search made (202 for a
    #: "no" that reaches every view), and few points remain where the footprint is small or
    #: overhangs the coarser image: true 4-5 inlier answers reach only -2.5 to -4.5 (hard set,
    #: cathedral x16: margin 0.47; realistic partial pairs at ratios 6-8: 0.53 to 0.87; Oxford
    #: boat 1->5 shrunk by 8, at scale 16: 0.27). No null run's best transform of 3 or more
    #: inliers reached half of it: 0.127 at the most in 1216 runs, 0.043 in the 600 runs of
    #: the rule with windows (docs/design/DECISION.md, "The ground for each threshold")
    few_clear_margin: float = 0.25
    #: a transform about to be accepted must place the finer image better than anywhere else in
    #: the coarser one: the misfit (1 - ZNCC) of the best other placement at least this many
    #: times the claimed one's (``stages.uniqueness.uniqueness``). A repeated structure (the
    #: windows of a facade) is matched by many points wherever a copy of it stands. Measured
    #: (docs/NULLS.md): the 12 claims of the hardest nulls (two halves of one photo; 6 to 13
    #: inliers, log10 NFA down to -38) 0.48 to 1.1; 152 true zoom pairs 3.75 to 898 (median
    #: 148); Oxford pairs 4.8 to 12.6; tilted pairs 10.7 and more. 2 sits between 1.1 and 3.75.
    #: Compared near the inliers (``PixelParams.vouch_radius``) the facades score 0.70 to 1.83
    #: (600 null runs, docs/design/DECISION.md, "Why the geometry can outweigh the pixels")
    #: nan (the finer image covers the coarser one: no room elsewhere) passes.
    min_unique_ratio: float = 2.0
    #: ... and at least this for a plain match of fewer than ``views.confirm_below_inliers``
    #: that no pass of views confirmed (``--no-views``, or a time budget spent first): the
    #: views' pass is what catches a repeated facade seen obliquely, which the plain search
    #: matches with a few inliers (a t = 2.83 tilted pair: 6 inliers at log10 NFA -12.5,
    #: 67 px off, ratio 2.10, claimed with ``--no-views``). The lowest true weak plain match
    #: measured with ``--no-views`` had 2.88 (an occluded pair at ratio 8, 5 inliers; the
    #: realistic and tilted sets, both orders); true zoom pairs 3.75 and more
    unconfirmed_min_unique_ratio: float = 2.5
    #: ... or, compared window by window (``stages.uniqueness.window_agreement``), at least
    #: ``min_windows`` windows of which this share agree at the claim ...
    min_window_agreement: float = 0.6
    #: ... and this many times the share that agrees anywhere else. An occluder loses only
    #: the windows it covers. Measured (docs/design/DECISION.md, "Windows that agree"): the
    #: null facades that reach the test agree at 0.33 to 0.50 of their windows; the occluded
    #: true pairs one ZNCC refuses at 0.70 to 0.88, 2.7 to 15 times their best elsewhere
    min_window_ratio: float = 2.0
    #: fewest windows for the agreement to count: 16 of 8 px cover a quarter of a 64 px
    #: template (``PixelParams.window_px``, ``unique_side_px``)
    min_windows: int = 16
    #: the final (refit) transform must line the pixels up better than its nearby wrong
    #: placements by more than this ZNCC (``Evidence.final_margin``). The search's own check
    #: (``pixel_margin``) cannot serve: it measures the similarity found in a view, which a
    #: tilted scene's true map is not (true tilted claims measured down to -0.56 there).
    #: Measured (scripts/margin_study.py; docs/design/DECISION.md, "The final map: fitting
    #: best, and better than its neighbours") on the 686 right claims
    #: of true pairs (zoom, hard set, Oxford, tilted to t = 8): 0.035 at the least (p5 0.07 to
    #: 0.22 per set); the one wrong claim there that the NFA passed (a t = 4 view of a t = 5.66
    #: pair, 9 inliers at log10 NFA -19, 47 px off): -0.015. 0 means "a peak of the fit".
    min_final_margin: float = 0.0
    #: ... or, where that one ZNCC refuses, compared window by window
    #: (``stages.pixelcheck.near_windows``: at least ``min_windows`` windows over the whole
    #: footprint) at least this share agree at the claim, and ``min_window_ratio`` times the
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
    #: border. Measured (docs/NULLS.md, docs/design/DECISION.md): the lowest log10 NFA of any
    #: null run's best transform is -38 (a facade cut in two, refused as ambiguous by its
    #: pixels); true answers refused by the pixels alone had -135 to -2080 (occluded,
    #: padded and 3-D pairs, docs/BENCHMARKS.md). -60 leaves 22 orders of magnitude below the
    #: worst null
    max_log_nfa_geometry: float = -60.0
    #: a repeated structure shows as a second transform of the same scale and angle, shifted,
    #: among the candidates the winner leaves over: with at least this share of the winner's
    #: inliers (and ``min_inliers``, beyond chance) the match is refused as ambiguous. Matching
    #: a repeated structure splits each point's nearest neighbour among the copies, so the
    #: copies' support is comparable. Measured on the 500 solved pairs of the realistic sets
    #: (docs/BENCHMARKS.md, "Pairs with what real photographs bring"): 0 to 0.286 (median 0,
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
    #: ... and this share of its inliers: measured 0 to 2 off-plane points on 15 zoom pairs of
    #: real photos, 118 beside 42 inliers on the desk scene of ../shared/data/ef/zoom
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
    #: an epipolar geometry's inliers that share a point count once (:func:`one_to_one`): two
    #: inliers share one when their finer points, or their coarser points, lie within this
    #: many px of each other. Many finer points matched to one coarser point lie on every
    #: epipolar line through it, so with the epipole there they all fit: on the null set, the
    #: 7 pairs whose matrix reached the plane test had 19 to 46 inliers, 3 to 25 of them such
    #: copies; counted once, a bus's panels fell from 29 to 7 inliers, a snowfield from 19 to
    #: 4, and a facade's log10 NFA from -56 to -2.3 (docs/design/DECISION.md)
    same_point_px: float = 1.0
    #: a fundamental matrix whose inliers show no parallax (:func:`plane_parallax`) gives way
    #: to the plane map of the same pair (``answer.without_parallax``), searched with this
    #: model: the default's, which the model check turns into an affine map or a homography
    #: where the scene asks for one
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
        "look_min_inliers": COUNT,
        "few_min_inliers": COUNT,
        "few_min_grown": COUNT,
        "few_max_log_nfa": FINITE,
        "few_min_margin": MARGIN,
        "few_clear_margin": MARGIN,
        "min_unique_ratio": NON_NEGATIVE,
        "min_window_agreement": SHARE,
        "min_window_ratio": NON_NEGATIVE,
        "min_windows": AT_LEAST_ONE,
        "min_final_margin": MARGIN,
        "min_near_windows": SHARE,
        "max_log_nfa_geometry": FINITE,
        "unconfirmed_min_unique_ratio": NON_NEGATIVE,
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
    matched: bool
    reason: str
    best_scale: float
    transform: Optional[np.ndarray] = field(repr=False)
    inliers: np.ndarray = field(repr=False)  #: (N, 4) x, y finer; x, y coarser
    evidence: Evidence = field(default_factory=build_evidence)
    #: a "no": the test that refused (a key of ``TESTS``; "" when matched or nothing to refuse)
    test: str = ""
    #: a "no": the best transform and its inliers, as ``transform`` and ``inliers`` would be
    candidate: Optional[np.ndarray] = field(default=None, repr=False)
    candidate_inliers: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)), repr=False)


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
              "plane_inliers"),
}


@dataclass(frozen=True)
class FinalFigures:
    """The pixel tests of a match's final transform (:func:`final_checks`): the figures of
    the same names in :class:`Evidence`."""

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


def figures(test: str, evidence: Evidence, params: DecisionParams,
            final: Optional[FinalFigures] = None) -> dict:
    """The figures of ``test`` (:data:`TESTS`): name -> value, from the final transform's
    pixel tests (``final``, when it faced them), the evidence or the params.

    >>> figures("chance", Evidence(inliers=5, candidates=40, log10_nfa=-1.0), DecisionParams())
    {'inliers': 5, 'candidates': 40, 'log10_nfa': -1.0, 'max_log_nfa': -2.0}
    """
    sources = ((final,) if final is not None else ()) + (evidence, params)
    return {name: getattr(next(s for s in sources if hasattr(s, name)), name)
            for name in TESTS.get(test, ())}


def log10_binom(n: int, k: int) -> float:
    if k < 0 or k > n:
        return -math.inf
    return (math.lgamma(n + 1) - math.lgamma(k + 1) - math.lgamma(n - k + 1)) / math.log(10)


def log10_nfa(n: int, k: int, m: int, p: float, tests: float) -> float:
    """log10 of the number of false alarms of a k-inlier consensus among n candidates."""
    if k <= m or n <= m:
        return math.inf
    return (math.log10(max(tests, 1.0)) + log10_binom(n, k) + log10_binom(k, m)
            + (k - m) * math.log10(max(min(p, 1.0), 1e-300)))


def _polygon_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _inside_fraction(t, finer_shape, coarser_shape) -> float:
    """The fraction of an ``INSIDE_GRID_POINTS``-square grid over the finer image that ``t``
    maps inside the coarser image."""
    p = apply(t, grid(finer_shape, INSIDE_GRID_POINTS))
    h, w = coarser_shape
    ok = (p[:, 0] >= -0.5) & (p[:, 1] >= -0.5) & (p[:, 0] <= w - 0.5) & (p[:, 1] <= h - 0.5)
    return float(ok.mean())


def folded(t: np.ndarray, finer_shape=None) -> bool:
    """True when the transform turns the finer image over (a mirror image) somewhere on it.

    A 2x3 map: its linear part's determinant is not positive. A homography H: its Jacobian at
    a pixel p has the determinant ``det(H) / w(p)^3`` (``w`` the third coordinate of H p), so it
    keeps the orientation over the image (``finer_shape``; None: at its origin only) when ``w``
    has one sign at every corner (the horizon w = 0 does not cross the image: ``w`` is affine)
    and ``det(H)`` has that sign too. (The top-left 2x2 block is that Jacobian only when H is
    affine: a steep perspective map 0.7 px from the truth was called folded; docs/design/VIEWS.md,
    "Perspective pairs".)

    >>> folded(np.array([[1.0, 0, 0], [0, -1.0, 0]]))  # a mirror
    True
    >>> h = np.array([[0.3, 0.0, 0.0], [0.0, 0.3, 0.0], [-1e-3, 0.0, 1.0]])  # w = 1 - x / 1000
    >>> folded(h, (480, 640)), folded(h, (480, 1280)), folded(-h, (480, 640))
    (False, True, False)
    """
    t = np.asarray(t, np.float64)
    if t.shape == (2, 3):
        return float(np.linalg.det(t[:, :2])) <= 0.0
    h, w = (1, 1) if finer_shape is None else finer_shape[:2]
    corners = np.array([[0, 0, 1], [w - 1, 0, 1], [w - 1, h - 1, 1], [0, h - 1, 1]], np.float64)
    depth = corners @ t[2]
    if not (np.all(depth > 0) or np.all(depth < 0)):
        return True  # the horizon crosses the image
    return float(np.linalg.det(t)) * float(np.sign(depth[0])) <= 0.0


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
class Look:
    """A second look at a hypothesis: guided growth, then the pixel check of the grown map."""

    transform: np.ndarray = field(repr=False)  #: the grown transform (finer px -> coarser px)
    inliers: np.ndarray = field(repr=False)  #: (N, 4) its distinct inliers
    chance: float  #: guided matches to expect by chance around the predictions
    ncc: float  #: ZNCC of the pixels under the grown map (nan: cannot tell)
    margin: float  #: ncc minus the best of the nearby wrong placements (nan: cannot tell)
    z: float  #: ncc against the nearby placements' mean, in their standard deviations
    #: the same window by window (:func:`scalematch.stages.pixelcheck.near_windows`), measured
    #: only when asked and the margin falls short (0 windows: not measured)
    windows: NearWindows = NearWindows(0, math.nan, math.nan)


@dataclass(frozen=True)
class Seen:
    """One image of a hypothesis as the second look sees it."""

    #: its described points (the finer image's at the hypothesis' scale)
    described: Described = field(repr=False)
    #: its pixels at the search's working size, NaN where it shows no scene
    image: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class Sight:
    """What a second look at a hypothesis of one search sees (:meth:`look`): the images it
    compared, at the search's working size, where each shows the scene, and the coarser
    image's described points; handed to :func:`decide` as data, so the decision calls nothing
    of the search that made it."""

    finer: np.ndarray = field(repr=False)  #: the finer image (or view) searched
    finer_valid: Optional[np.ndarray] = field(repr=False)  #: where it shows the scene (None: all)
    coarser: Described = field(repr=False)  #: the coarser image's (or view's) described points
    coarser_image: np.ndarray = field(repr=False)
    coarser_valid: Optional[np.ndarray] = field(repr=False)
    fit: FitSpec
    guided: GuidedParams
    pixel: PixelParams

    def look(self, t: np.ndarray, outcome, windows_below: float = math.nan) -> Look:
        """:func:`look_again` at hypothesis ``t`` of a scale's ``outcome`` (its described finer
        points), the images with NaN where they show no scene."""
        return look_again(t, Seen(outcome.described, with_nan(self.finer, self.finer_valid)),
                          Seen(self.coarser, with_nan(self.coarser_image, self.coarser_valid)),
                          fit=self.fit, guided=self.guided, pixel=self.pixel,
                          windows_below=windows_below)

    def nearby(self, t: np.ndarray) -> Nearby:
        """The placement near ``t`` that fits the pixels best
        (:func:`scalematch.stages.nearby.best_nearby`)."""
        return best_nearby(with_nan(self.coarser_image, self.coarser_valid),
                           with_nan(self.finer, self.finer_valid), t, self.pixel)


def look_again(t: np.ndarray, finer: Seen, coarser: Seen, *, fit: FitSpec, guided: GuidedParams,
               pixel: PixelParams, windows_below: float = math.nan) -> Look:
    """Grow hypothesis ``t`` by guided matching (:func:`scalematch.stages.guided.grow`) and check
    the grown map with the pixels (:func:`scalematch.stages.pixelcheck.pixel_check`); where its
    margin is below ``windows_below`` (nan: never), window by window too
    (:func:`scalematch.stages.pixelcheck.near_windows`).

    ``finer``: every described point of the finer image at the hypothesis' scale, and its
    pixels; ``coarser``: the coarser image's points and pixels. ``fit``: the model searched for
    and the refit's RANSAC parameters (growth draws no sample: the seed is not used);
    ``guided``: the growth's parameters (``use_orientation`` off for descriptors without one:
    the paper's jets); ``pixel``: the pixel check's.
    """
    growth = grow(t, finer.described, coarser.described, fit.model, guided, fit.ransac)
    grown = growth.transform if growth.n_inliers else np.asarray(t, np.float64)
    check = pixel_check(coarser.image, finer.image, grown, pixel)
    windows = near_windows(coarser.image, finer.image, grown, pixel) \
        if check.margin < windows_below else NearWindows(0, math.nan, math.nan)
    return Look(grown, growth.inliers, growth.chance, check.ncc, check.margin, check.z, windows)


def repeats(second: Second, second_nfa: float, k: int, area: float, winner: np.ndarray,
            params: DecisionParams) -> bool:
    """Whether ``second`` (:func:`scalematch.stages.rivals.second_transform`, at log10 NFA
    ``second_nfa``) shows a repeated structure beside a winner ``winner`` of ``k`` inliers whose
    footprint covers ``area`` coarser px^2: the same scale and angle, elsewhere (at least
    ``second_min_shift`` of the footprint's size away), beyond chance, with at least
    ``second_share`` of the winner's support.

    >>> from scalematch.geometry import similarity_matrix as sim
    >>> p, t = DecisionParams(), sim(0.5, 0.0)
    >>> repeats(Second(40, sim(0.5, 1.0, 120, 0), 120.0), -90.0, 60, 160 * 120, t, p)
    True
    >>> repeats(Second(5, sim(0.5, 1.0, 120, 0), 120.0), -9.0, 60, 160 * 120, t, p)  # too few
    False
    >>> repeats(Second(40, sim(0.5, 1.0, 12, 0), 12.0), -90.0, 60, 160 * 120, t, p)  # piecewise
    False
    """
    return (second.transform is not None
            and same_scale_and_angle(winner, second.transform, params.second_scale_factor,
                                     params.second_angle_deg)
            and second.gap_px >= params.second_min_shift * math.sqrt(max(area, 0.0))
            and second_nfa <= params.max_log_nfa
            and second.inliers >= max(params.min_inliers, params.second_share * k))


def pixels_confirm(log10_nfa: float, margin: float, params: DecisionParams) -> bool:
    """Whether a few-inlier transform's NFA and pixel margin reach one of the two tiers: a
    modest margin with a low NFA, or a margin no wrong placement reaches with the plain
    a-contrario bound (``few_*`` and ``max_log_nfa`` of :class:`DecisionParams`). A nan
    margin (cannot tell) confirms nothing.

    >>> p = DecisionParams()
    >>> pixels_confirm(-7.0, 0.15, p), pixels_confirm(-4.5, 0.15, p), pixels_confirm(-4.5, 0.4, p)
    (True, False, True)
    >>> pixels_confirm(-2.5, 0.27, p), pixels_confirm(-2.9, 0.2, p), pixels_confirm(-1.5, 0.87, p)
    (True, False, False)
    """
    tiers = ((params.few_max_log_nfa, params.few_min_margin),
             (params.max_log_nfa, params.few_clear_margin))
    return any(log10_nfa <= nfa and margin >= least for nfa, least in tiers)


def look_windows_below(log10_nfa: float, params: DecisionParams) -> float:
    """The pixel margin below which the second look of a transform at ``log10_nfa`` also
    compares its nearby placements window by window (:func:`look_confirms`): the first tier's
    ``few_min_margin`` for a transform beyond chance by ``few_max_log_nfa``; nan (never) above.
    """
    return params.few_min_margin if log10_nfa <= params.few_max_log_nfa else math.nan


def look_confirms(log10_nfa: float, second: Optional[Look], params: DecisionParams) -> bool:
    """Whether the second look's pixels confirm a transform at ``log10_nfa``: its margin
    (:func:`pixels_confirm`), or, in the first tier (``few_max_log_nfa``), where an occluder in
    the finer image sinks the one ZNCC at the hypothesis as at its neighbours, its windows
    (:func:`near_windows_agree`, as the final map's: ``DecisionParams.min_near_windows``).
    """
    if second is None:
        return False
    return pixels_confirm(log10_nfa, second.margin, params) or (
        log10_nfa <= params.few_max_log_nfa and near_windows_agree(second.windows, params))


@dataclass(frozen=True)
class SearchContext:
    """What the decision needs to know of the search it judges, beside its outcomes."""

    fit: FitSpec  #: the model searched for, the robust fit's parameters and the one seed
    #: the rotation groups of oriented descriptors (a chance candidate is less likely to fit,
    #: and each group is a test); None for descriptors without an orientation (the paper's jets)
    orientation: Optional[OrientationParams]
    #: whole searches made so far, this one included (each order and each simulated view is
    #: one): they multiply the number of tests of the a-contrario count
    searches: int = 1
    #: the search's scales and ratios times this are the ones the user's images have (the
    #: working size shrinks them, :mod:`scalematch.working`): the reasons name those
    shown_scale: float = 1.0


@dataclass(frozen=True)
class Winner:
    """The winning scale's outcome and its a-contrario count (:func:`log10_nfa`)."""

    outcome: object = field(repr=False)  #: a ``search.ScaleOutcome``
    k: int  #: its inliers
    n: int  #: its candidates (at least ``k``)
    m: int  #: the model's minimal sample
    p: float  #: the chance that one random candidate fits (:func:`chance_probability`)
    tests: int  #: scales with candidates x subsets x searches x rotation groups
    log10_nfa: float

    def nfa_of(self, inliers: int) -> float:
        """log10 NFA of another consensus of ``inliers`` among the same candidates."""
        return log10_nfa(self.n, inliers, self.m, self.p, self.tests)


def _closeness(o) -> float:
    """How far an outcome's implied ratio is from its scale, |log(ratio / s)| (inf: no ratio)."""
    return ratio_distance(o.row.ratio, o.row.s)


def ratio_distance(ratio: float, s: float) -> float:
    """|log(ratio / s)|: how far a fit's ratio is from the scale it was found at (inf: none).

    >>> round(ratio_distance(4.0, 2.0), 3), ratio_distance(float("nan"), 2.0)
    (0.693, inf)
    """
    return abs(math.log(ratio / s)) if ratio > 0 and math.isfinite(ratio) else math.inf


def disagrees(row, params: "DecisionParams") -> bool:
    """True when a per-scale row's fit has a ratio that contradicts its scale (beyond
    ``params.scale_agreement``): not that scale's answer, whatever its inliers (a fit that
    collapses many finer points onto a few coarser ones counts many). False without a fit."""
    return row.inliers > 0 and ratio_distance(row.ratio, row.s) > math.log(params.scale_agreement)


def decide(outcomes: Sequence, coarser_shape, finer_shape, params: DecisionParams, *,
           context: SearchContext,
           sight: Optional[Sight] = None) -> Decision:
    """Pick the winning scale and decide whether its transform is a reliable match.

    ``coarser_shape``, ``finer_shape``: the (H, W) of the images searched (or their views);
    ``params``: the decision's thresholds; ``context``: the search's model, robust fit (its
    threshold sets the a-contrario test's tolerance), seed
    (:func:`scalematch.stages.rivals.second_transform`), rotation groups and
    searches made, which the a-contrario count multiplies, and the scale its reasons are shown
    at (:class:`SearchContext`). With ``sight`` (:class:`Sight`), its ``look(t, outcome,
    windows_below)`` takes the second look (:func:`look_again`, with :func:`look_windows_below`) at a
    best transform of
    ``look_min_inliers`` to ``min_inliers - 1`` inliers: its figures go in the evidence, and it
    may accept a transform of ``few_min_inliers`` or more (:func:`look_confirms`).
    The accepted transform faces more tests once refit (:func:`final_checks`).
    """
    spec = model_of(context.fit.model)
    with_t = [o for o in outcomes if o.estimate is not None and o.estimate.transform is not None
              and o.row.inliers > 0]
    if not with_t:
        return Decision(False, "no scale produced a transform (too few candidate matches)",
                        math.nan, None, np.zeros((0, 4)), build_evidence())
    # a transform whose ratio contradicts the scale it was found at is not that scale's answer
    plausible = [o for o in with_t if not spec.has_ratio
                 or _closeness(o) <= math.log(params.scale_agreement)]
    if not plausible:
        return _implausible(with_t, context.shown_scale)
    best = min(plausible, key=lambda o: (-o.row.inliers, _closeness(o), o.row.s))
    winner = _counted(best, outcomes, coarser_shape, context, params.same_point_px)
    return _tested(winner, with_t, (coarser_shape, finer_shape), params, context, sight)


def _implausible(with_t: Sequence, shown_scale: float) -> Decision:
    """The "no" when no scale's transform agrees with its own scale."""
    best = max(with_t, key=lambda o: o.row.inliers)
    implied = best.row.ratio * shown_scale
    implies = (f"implies a ratio of {implied:.3g}" if math.isfinite(implied) else
               "implies no usable ratio")  # a degenerate fit: geometry.usable_ratio
    return Decision(False, f"no scale found a transform consistent with its own scale "
                    f"(the one with the most inliers, {best.row.inliers} at scale "
                    f"{best.row.s * shown_scale:.3g}, {implies})",
                    best.row.s, None, np.zeros((0, 4)), build_evidence())


def _counted(best, outcomes: Sequence, coarser_shape, context: SearchContext,
             same_point_px: float) -> Winner:
    """The winning outcome ``best`` with its a-contrario count over all of ``outcomes``; an
    epipolar geometry's inliers counted one to one (:func:`one_to_one`, ``same_point_px``)."""
    orientation = context.orientation
    model = context.fit.model
    k = best.row.inliers
    if not model_of(model).has_ratio:  # a point matched many times lies on every line through it
        k = len(one_to_one(np.hstack([best.src[best.estimate.inliers],
                                      best.dst[best.estimate.inliers]]), same_point_px))
    n = max(best.candidates, k)
    m = model_of(model).min_sample
    oriented = orientation is not None
    p = chance_probability(context.fit.ransac.threshold_px, coarser_shape, model, oriented,
                           orientation.tolerance_deg if oriented else 0.0)
    tests = max(int(context.searches), 1) * len([o for o in outcomes if o.candidates > 0]) * max(
        n - m, 1) * (orientation.max_peaks if oriented else 1)
    return Winner(best, k, n, m, p, tests, log10_nfa(n, k, m, p, tests))


def _tested(w: Winner, with_t: Sequence, shapes, params: DecisionParams,
            context: SearchContext, sight: Optional[Sight]) -> Decision:
    """The winner ``w`` through the tests, in order (the module's docstring): enough inliers
    (or few, confirmed by the second look), beyond chance, a plausible footprint, agreeing
    scales, no repeated structure. ``shapes``: (coarser, finer) (H, W)."""
    best, k, lnfa = w.outcome, w.k, w.log10_nfa
    spec = model_of(context.fit.model)
    shown = best.row.s * context.shown_scale
    t = best.estimate.transform
    pairs = np.hstack([best.src[best.estimate.inliers], best.dst[best.estimate.inliers]])
    figs = dict(inliers=int(k), candidates=int(w.n), log10_nfa=lnfa, chance_p=w.p)

    def no(reason: str, test: str) -> Decision:  # with the figures, t and pairs reached
        return Decision(False, reason, best.row.s, None, np.zeros((0, 4)),
                        build_evidence(figs), test, t, pairs)

    # the second look decides only below min_inliers, or for a footprint mostly outside the
    # coarser image (the final map's pixel tests follow every match, final_checks): elsewhere
    # it would cost a tenth of a plain pair's time for nothing
    second = sight.look(t, best, look_windows_below(lnfa, params)) \
        if sight is not None and spec.has_ratio and (
            params.look_min_inliers <= k < params.min_inliers
            or _outside_unproven(t, shapes, lnfa, params)) else None
    figs = _with_look(figs, second)
    if k < params.min_inliers:
        if not _few_confirmed(w, second, params):
            return no(f"too few inliers: {k} at scale {shown:.3g} (at least "
                      f"{params.min_inliers} needed, or {params.few_min_inliers} beyond chance "
                      f"that pass the pixel check)", "too few inliers")
        if len(second.inliers) >= k:  # grown (or kept): the refit map and its inliers
            t, pairs = second.transform, second.inliers
        elsewhere = _placed_better_nearby(t, k, sight)
        if elsewhere is not None:
            return no(elsewhere, "nearby placement")
    if lnfa > params.max_log_nfa:
        return no(f"the best transform ({_inliers_said(k, len(pairs))} of {w.n} candidates at "
                  f"scale {shown:.3g}) could arise by chance ({_count_said(lnfa, w.m, params)})",
                  "chance")
    if not spec.has_ratio:  # no footprint to check
        return Decision(True, "", best.row.s, t, pairs, build_evidence(figs))
    figs, refusal = _footprint_tests(t, shapes, w, figs, params, second)
    if refusal is None:
        figs, refusal = _agreement_test(t, w, with_t, shapes[1], figs, params,
                                        context.shown_scale)
    if refusal is None:
        figs, refusal = _rival_test(w, shapes[1], figs, params, context.fit)
    if refusal is not None:
        return no(*refusal)
    return Decision(True, "", best.row.s, t, pairs, build_evidence(figs))


def _inliers_said(k: int, matches: int) -> str:
    """The inliers counted, as a reason says them: with the matches they stand for when an
    epipolar geometry counted them one to one (:func:`one_to_one`), so that the reason and the
    ``rejected`` block (its ``n_inliers`` are the matches) give the same figures.

    >>> _inliers_said(6, 6), _inliers_said(6, 7)
    ('6 inliers', '6 inliers counted one to one (7 matches)')
    """
    return f"{k} inliers" if k == matches else \
        f"{k} inliers counted one to one ({matches} matches)"


def _count_said(lnfa: float, m: int, params: DecisionParams) -> str:
    """The a-contrario figure of a refusal: its log10 NFA against the bound, or, where no more
    inliers than the minimal sample ``m`` fit (the count is infinite; null in the JSON), that.

    >>> _count_said(-1.04, 2, DecisionParams()), _count_said(math.inf, 8, DecisionParams())
    ('log10 NFA -1.0 > -2', 'no more inliers than the 8 a fit is drawn from: none beyond chance')
    """
    if math.isfinite(lnfa):
        return f"log10 NFA {lnfa:.1f} > {params.max_log_nfa:g}"
    return f"no more inliers than the {m} a fit is drawn from: none beyond chance"


#: The figures the tests have reached (``Evidence``'s names; :func:`build_evidence` makes the
#: evidence of them)
Figures = Dict[str, Any]


def _with_look(figs: Figures, second: Optional[Look]) -> Figures:
    """``figs`` with the second look's figures (unchanged without one)."""
    if second is None:
        return figs
    return {**figs, "grown_inliers": len(second.inliers), "grown_chance": second.chance,
            "pixel_ncc": second.ncc, "pixel_margin": second.margin, "pixel_z": second.z,
            "pixel_windows": second.windows.windows,
            "pixel_windows_agreeing": second.windows.claimed,
            "pixel_windows_nearby": second.windows.nearby}


def _few_confirmed(w: Winner, second: Optional[Look], params: DecisionParams) -> bool:
    """Whether the second look accepts a winner of fewer than ``min_inliers``: enough inliers,
    far enough beyond chance for its pixels (:func:`look_confirms`), grown enough."""
    return second is not None and w.k >= params.few_min_inliers and \
        look_confirms(w.log10_nfa, second, params) and \
        len(second.inliers) >= params.few_min_grown


def _placed_better_nearby(t: np.ndarray, k: int, sight: Sight) -> Optional[str]:
    """Why a map ``t`` of ``k`` inliers (fewer than ``min_inliers``) is ambiguous, or None: a
    placement at least :func:`_apart` from it, within a scale step, ``rotation_deg`` and half
    a footprint (:func:`scalematch.stages.nearby.best_nearby`), fits the pixels better. A few
    points can agree on a copy of a repeated texture a few windows off the truth, whose pixels
    fit well but not best (docs/design/DECISION.md, "Placed better nearby")."""
    near = sight.nearby(t)
    if near.moved >= _apart(sight.pixel) and near.best > near.claimed:
        return (f"ambiguous: a placement {near.moved:.0%} of the footprint away fits the pixels "
                f"better than the map of {k} inliers (ZNCC {near.best:.2f} against "
                f"{near.claimed:.2f})")
    return None


def _apart(pixel: PixelParams) -> float:
    """How far from a map (a fraction of the footprint's size) a placement is another one: half
    the pixel check's perturbation (``PixelParams.shift_fraction``), whose placements count as
    wrong ones; a map a few pixels off its best placement (a similarity on a slightly oblique
    plane) stays within it."""
    return 0.5 * pixel.shift_fraction


def _outside_unproven(t: np.ndarray, shapes, lnfa: float, params: DecisionParams) -> bool:
    """Whether the footprint test needs the second look's pixels to accept ``t``: less than
    ``min_inside`` of its footprint inside the coarser image, its evidence beyond chance but
    not overwhelming alone (a transform of 3 to 5 inliers gets the look anyway)."""
    coarser_shape, finer_shape = shapes
    return params.max_log_nfa_alone < lnfa <= params.max_log_nfa and \
        _inside_fraction(t, finer_shape, coarser_shape) < params.min_inside


#: A test's refusal: (reason, test), or None when it passes
Refusal = Optional[Tuple[str, str]]


def _footprint_tests(t: np.ndarray, shapes, w: Winner, figs: Figures, params: DecisionParams,
                     second: Optional[Look]) -> Tuple[Figures, Refusal]:
    """Test 3, a plausible footprint of ``t`` (finer px -> coarser px; ``shapes``: (coarser,
    finer) (H, W)): not folded over, not too small, inside enough unless the evidence is
    overwhelming or the second look's pixels confirm it. (figures with the footprint's,
    refusal)."""
    coarser_shape, finer_shape = shapes
    poly = footprint(t, finer_shape, edges=False)  # corner pixel centres, as measured
    area = abs(_polygon_area(poly)) if poly is not None else 0.0  # None: a corner at infinity
    inside = _inside_fraction(t, finer_shape, coarser_shape)
    figs = {**figs, "implied_ratio": w.outcome.row.ratio, "footprint_area_px": area,
            "footprint_inside": inside}
    if folded(t, finer_shape):
        return figs, ("the transform folds the high image over (a mirror image): not a "
                      "view of it", "folded")
    if area < params.min_area_px:
        return figs, (f"the high image would cover only {area:.0f} px^2 of the low image",
                      "footprint area")
    if inside < params.min_inside and w.log10_nfa > params.max_log_nfa_alone and \
            not look_confirms(w.log10_nfa, second, params):
        return figs, (f"only {inside:.0%} of the high image's footprint lies inside the "
                      f"low image", "footprint inside")
    return figs, None


def _agreement_test(t: np.ndarray, w: Winner, with_t: Sequence, finer_shape,
                    figs: Figures, params: DecisionParams,
                    shown_scale: float) -> Tuple[Figures, Refusal]:
    """Test 4, consistent neighbouring scales: how many other scales found (nearly) ``t``;
    enough of them unless the winner is overwhelming alone or has fewer than ``min_inliers``
    (the second look confirmed it). ``shown_scale``: :attr:`SearchContext.shown_scale`."""
    best = w.outcome
    few = w.k < params.min_inliers
    agreeing = 0
    for o in with_t:
        if o is best or o.row.inliers < w.m + 1:
            continue
        if mean_transfer_gap(o.estimate.transform, t, finer_shape) <= params.agreement_px:
            agreeing += 1
    figs = {**figs, "agreeing_scales": agreeing}
    if agreeing < params.min_agreeing_scales and w.log10_nfa > params.max_log_nfa_alone \
            and not few:
        return figs, (f"no other scale agrees with the best one "
                      f"(scale {best.row.s * shown_scale:.3g}, "
                      f"{w.k} inliers)", "agreeing scales")
    return figs, None


def _rival_test(w: Winner, finer_shape, figs: Figures, params: DecisionParams,
                fit: FitSpec) -> Tuple[Figures, Refusal]:
    """What the candidates the winner leaves over show: a second transform of the same scale
    and angle (a repeated structure, refused: :func:`repeats`). (figures with its own,
    refusal). The points off the plane (parallax) are counted once, for the answer's own map
    (``answer.answer_parallax``), not for every winner decided."""
    best, k = w.outcome, w.k
    est = best.estimate
    inl = est.inliers
    rival = second_transform(best.src, best.dst, inl, est.transform, finer_shape,
                             fit.ransac, fit.seed)
    rival_nfa = w.nfa_of(rival.inliers)
    figs = {**figs, "second_inliers": rival.inliers, "second_log10_nfa": rival_nfa,
            "second_gap_px": rival.gap_px}
    if repeats(rival, rival_nfa, k, figs["footprint_area_px"], est.transform, params):
        return figs, (f"ambiguous: a second transform of the same scale and angle, "
                      f"{rival.gap_px:.0f} px away, has {rival.inliers} inliers against "
                      f"{k}: a repeated structure", "repeated structure")
    return figs, None


@dataclass(frozen=True)
class Claim:
    """A match's final transform as the pixel tests judge it (:func:`final_checks`)."""

    transform: np.ndarray = field(repr=False)  #: refit, finer px -> coarser px
    log10_nfa: float  #: the decision's a-contrario figure for it
    #: the finer px (N, 2) of the inliers that vouch for it; None: the whole footprint
    vouched: Optional[np.ndarray] = field(default=None, repr=False)
    #: a plain match of few inliers that no pass of views confirmed: its pixels must show it
    #: unique by ``DecisionParams.unconfirmed_min_unique_ratio``
    unconfirmed: bool = False


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


def plane_parallax(pairs: np.ndarray, counted: Evidence, fit: FitSpec,
                   params: DecisionParams) -> Dict[str, Any]:
    """Whether an epipolar geometry's inliers ``pairs`` ((N, 4) x, y finer; x, y coarser, the
    search's working px) show parallax by themselves: the figures ``parallax_points``,
    ``parallax_log10_nfa`` and ``parallax`` of the evidence.

    The inliers a homography explains (RANSAC at the inlier threshold of ``fit``) are the
    scene's dominant plane; the rest are off it. A scene with no depth, or a repeated structure
    matched to its shifted copy, leaves few off the plane, and those few fit an epipolar
    geometry as chance points would; a 3-D scene leaves many that fit it. So the inliers off the
    plane, counted one to one (:func:`one_to_one`), face the a-contrario test of the winner
    (``counted``: its candidates ``n``, one-to-one inliers ``k``, chance ``p`` and log10 NFA,
    from which the number of tests is recovered) among the candidates off the plane:

        log10 NFA_off = log10 tests + log10 C(n - k_plane, k_off) + log10 C(k_off, m)
                        + (k_off - m) log10 p

    and parallax is seen when it is at most ``params.max_log_nfa``, the bound of any claim.
    This is the test of DEGENSAC (Chum, Werner & Matas, "Two-view geometry estimation
    unaffected by a dominant plane", CVPR 2005) made a-contrario.
    """
    m = model_of(fit.model).min_sample
    n, k, p = int(counted.candidates), int(counted.inliers), float(counted.chance_p)
    log10_tests = counted.log10_nfa - log10_nfa(n, k, m, p, 1.0)
    pairs = np.asarray(pairs, np.float64).reshape(-1, 4)
    pairs = pairs[one_to_one(pairs, params.same_point_px)]
    plane = estimate("homography", pairs[:, :2], pairs[:, 2:], fit.ransac, seed=fit.seed)
    on_plane = int(plane.n_inliers)
    k_off = len(pairs) - on_plane
    lnfa = log10_nfa(max(n - on_plane, k_off), k_off, m, p, 1.0)
    if math.isfinite(lnfa) and math.isfinite(log10_tests):
        lnfa += max(log10_tests, 0.0)
    return {"parallax_points": k_off, "parallax_log10_nfa": lnfa,
            "parallax": bool(lnfa <= params.max_log_nfa)}


def windows_agree(a: Agreement, params: DecisionParams) -> bool:
    """Whether the windows of a claim (:func:`scalematch.stages.uniqueness.window_agreement`)
    show it unique: enough of them, most agreeing at the claim, far fewer anywhere else.

    >>> p = DecisionParams()
    >>> windows_agree(Agreement(40, 0.8, 0.2), p), windows_agree(Agreement(40, 0.5, 0.1), p)
    (True, False)
    >>> windows_agree(Agreement(40, 0.8, 0.5), p), windows_agree(Agreement(9, 1.0, 0.0), p)
    (False, False)
    """
    return (a.windows >= params.min_windows and a.claimed >= params.min_window_agreement
            and a.claimed >= params.min_window_ratio * a.elsewhere)


def unique_threshold(params: DecisionParams, unconfirmed: bool) -> float:
    """The uniqueness ratio a claim needs (:func:`final_checks`): ``min_unique_ratio``, or for
    a weak plain match no view confirmed, ``unconfirmed_min_unique_ratio`` if higher."""
    return max(params.min_unique_ratio, params.unconfirmed_min_unique_ratio) if unconfirmed \
        else params.min_unique_ratio


def final_checks(coarser: np.ndarray, finer: np.ndarray, claim: Claim, params: DecisionParams,
                 near=None, pixel: PixelParams = PixelParams()):
    """(figures, reason, test): the pixel tests of a match's final transform ``claim.transform``
    (``t`` below: finer px -> coarser px, refit, at log10 NFA ``claim.log10_nfa``) as
    :class:`FinalFigures`, why it is refused and by which test (:data:`TESTS`; "" when it is
    not).

    Uniqueness: a repeated structure is matched by many points wherever a copy of it stands;
    the pixels tell: the finer image, warped by ``t``, must fit its place ``min_unique_ratio``
    times better than any other place (:func:`scalematch.stages.uniqueness.uniqueness`),
    compared where the inliers vouched for the map (``claim.vouched``); or, where that one
    ZNCC refuses (an occluder sinks it), window by window (:func:`windows_agree`).
    Nearby placements: ``t`` must fit better than its shifted, turned and rescaled neighbours
    (:func:`scalematch.stages.pixelcheck.pixel_check`) by more than ``min_final_margin``.
    Both are measured on the final transform: a similarity found before the refit may hold on
    part of the image only (a tilted view, a mild tilt), which the pixels would count against it.
    The images carry NaN where they show no scene (:func:`scalematch.stages.nodata.with_nan`).

    Geometry first: a transform beyond chance by ``max_log_nfa_geometry`` (and with no second
    transform of comparable support, which :func:`decide` refuses) is unique by its geometry;
    its pixel figures are recorded, not decisive: an occluder, parallax or relighting lowers
    them where the points prove the map (``judged_by`` says which test decided).
    ``near``: the pixel check of ``t`` when it was measured already (``answer.best_fitting``).
    ``pixel``: the pixel tests' parameters (``Config.pixel``).
    """
    t, log10_nfa, vouched = claim.transform, claim.log10_nfa, claim.vouched
    placed = None  # the template of the uniqueness ratio, and of the windows where it refuses

    def unique():
        nonlocal placed
        placed = unique_template(coarser, finer, t, pixel, vouched)
        return uniqueness_of(placed, pixel)

    if near is None:  # side by side: neither needs the other
        u, near = thread_map(lambda job: job(), [unique,
                                                 lambda: pixel_check(coarser, finer, t, pixel)])
    else:
        u = unique()
    geometric = log10_nfa <= params.max_log_nfa_geometry
    final = FinalFigures(unique_claimed=u.claimed, unique_elsewhere=u.elsewhere,
                         unique_ratio=u.ratio, final_ncc=near.ncc, final_margin=near.margin,
                         judged_by="geometry" if geometric else "pixels")
    if geometric:
        return final, "", ""
    if u.ratio < unique_threshold(params, claim.unconfirmed):  # nan: no room elsewhere, passes
        a = agreement_of(placed, pixel)
        final = replace(final, unique_windows=a.windows, windows_agreeing=a.claimed,
                        windows_elsewhere=a.elsewhere)
        if not windows_agree(a, params):
            windows = (f"; {a.claimed:.0%} of its windows agree at the transform found, "
                       f"{a.elsewhere:.0%} elsewhere" if a.windows else "")
            return final, (f"ambiguous: the high image's pixels fit elsewhere in the low "
                           f"image nearly as well (ZNCC {u.elsewhere:.2f} there, "
                           f"{u.claimed:.2f} at the transform found{windows}; log10 NFA "
                           f"{log10_nfa:.1f})"), "uniqueness"
    if near.margin <= params.min_final_margin:  # nan: no check possible, passes
        return _nearby_windows(coarser, finer, t, final, params, pixel)
    return final, "", ""


def _nearby_windows(coarser: np.ndarray, finer: np.ndarray, t: np.ndarray, final: FinalFigures,
                    params: DecisionParams, pixel: PixelParams):
    """(figures, reason, test) of a final map whose margin refuses it: the nearby placements
    compared window by window (:func:`near_windows_agree`) decide."""
    w = near_windows(coarser, finer, t, pixel)
    final = replace(final, near_windows=w.windows, near_windows_agreeing=w.claimed,
                    near_windows_nearby=w.nearby)
    if near_windows_agree(w, params):
        return final, "", ""
    windows = (f"; {w.claimed:.0%} of its windows agree there, {w.nearby:.0%} at the best "
               f"nearby placement" if w.windows else "")
    return final, (f"the pixels do not confirm it: the transform found fits the low image no "
                   f"better than nearby wrong placements (ZNCC margin "
                   f"{final.final_margin:+.2f}{windows})"), "pixels"


def near_windows_agree(w: NearWindows, params: DecisionParams) -> bool:
    """Whether a claim's windows (:func:`scalematch.stages.pixelcheck.near_windows`) fit it
    better than its nearby wrong placements: enough of them, ``min_near_windows`` agreeing at
    the claim, ``min_window_ratio`` times the share at the best nearby placement.

    >>> p = DecisionParams()
    >>> [near_windows_agree(NearWindows(n, at, near), p)
    ...  for n, at, near in ((40, 0.45, 0.02), (40, 0.1, 0.0), (40, 0.45, 0.3), (9, 0.9, 0.0))]
    [True, False, False, False]
    """
    return (w.windows >= params.min_windows and w.claimed >= params.min_near_windows
            and w.claimed >= params.min_window_ratio * w.nearby)
