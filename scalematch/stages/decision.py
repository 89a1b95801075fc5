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
   inside confirm a few-inlier map (:func:`scalematch.stages.secondlook.look_confirms`); with weaker
   evidence at least ``min_inside`` of it must lie inside.
4. *Consistent neighbouring scales*: at least ``min_agreeing_scales`` other scales found
   (nearly) the same transform, as the paper's Table 1 shows for a true match, unless the
   winner alone is overwhelming (``max_log_nfa_alone``).
5. *No repeated structure*: no second transform of the same scale and angle stands elsewhere
   among the candidates the winner leaves over (:func:`repeats`).
"""


from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, Optional, Sequence, Tuple

import numpy as np

from ..geometry import apply, footprint, grid
from .acontrario import Decision, DecisionParams, Winner, chance_probability, log10_nfa
from .constraints import OrientationParams
from .estimator import FitSpec, model_of
from .rivals import mean_transfer_gap, same_scale_and_angle, second_transform, Second
from .secondlook import (Look, Sight, few_confirmed, look_confirms, look_windows_below,
                         placed_better_nearby)


#: Points along each side of the grid that measures a footprint's share inside the coarser
#: image: numerics, not a threshold (an area's quadrature: 121 points put the share within
#: 1/11 of the exact one, and ``DecisionParams.min_inside`` is compared with it)
INSIDE_GRID_POINTS = 11


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


def _closeness(o) -> float:
    """How far an outcome's implied ratio is from its scale, |log(ratio / s)| (inf: no ratio)."""
    return ratio_distance(o.row.ratio, o.row.s)


def ratio_distance(ratio: float, s: float) -> float:
    """|log(ratio / s)|: how far a fit's ratio is from the scale it was found at (inf: none).

    >>> round(ratio_distance(4.0, 2.0), 3), ratio_distance(float("nan"), 2.0)
    (0.693, inf)
    """
    return abs(math.log(ratio / s)) if ratio > 0 and math.isfinite(ratio) else math.inf


def disagrees(row, model: str, params: "DecisionParams") -> bool:
    """True when a per-scale row's fit of ``model`` has a ratio that contradicts its scale
    (beyond ``params.scale_agreement``): not that scale's answer, whatever its inliers (a fit
    that collapses many finer points onto a few coarser ones counts many; a NaN ratio is as far
    from its scale as any). False without a fit, and for a model without a ratio (an epipolar
    geometry absorbs the zoom: no scale to contradict)."""
    return maps_points(model) and row.inliers > 0 and \
        ratio_distance(row.ratio, row.s) > math.log(params.scale_agreement)


def maps_points(model: str) -> bool:
    """Whether the decision tests ``model``'s answer as a map: a point maps to a point, so it
    implies a ratio to check against its scale, a footprint and the pixels under it. An
    epipolar geometry maps a point to a line and faces the count alone, its inliers counted one
    to one (``Model.counted``)."""
    return model_of(model).has_ratio


def nothing_matched(outcomes: Sequence) -> str:
    """Why no scale of ``outcomes`` produced a transform: the probe judged every scale with
    points hopeless (``ScaleRow.skipped``: no quick similarity held a point beyond its
    sample), so none was matched in full; or the scales matched had too few candidates.

    >>> from scalematch.result import ScaleRow
    >>> from scalematch.search.plan import ScaleOutcome
    >>> none = np.zeros((0, 2))
    >>> row = ScaleRow(s=2.0, ratio=math.nan, points=30, initial=0, kept=0, inliers=0,
    ...                outlier_pct=100.0, skipped=True)
    >>> nothing_matched([ScaleOutcome(row, None, none, none, 0)])
    'the probe found no scale worth matching in full'
    >>> from dataclasses import replace
    >>> nothing_matched([ScaleOutcome(replace(row, skipped=False), None, none, none, 0)])
    'too few candidate matches'
    """
    with_points = [o for o in outcomes if o.row.points > 0]
    if with_points and all(o.row.skipped for o in with_points):
        return "the probe found no scale worth matching in full"
    return "too few candidate matches"


def decide(outcomes: Sequence, coarser_shape, finer_shape, params: DecisionParams, *,
           context: SearchContext,
           sight: Optional[Sight] = None) -> Decision:
    """Pick the winning scale and decide whether its transform is a reliable match.

    ``coarser_shape``, ``finer_shape``: the (H, W) of the images searched (or their views);
    ``params``: the decision's thresholds; ``context``: the search's model, robust fit (its
    threshold sets the a-contrario test's tolerance), seed
    (:func:`scalematch.stages.rivals.second_transform`), rotation groups and
    searches made, which the a-contrario count multiplies, and the scale its reasons are shown
    at (:class:`SearchContext`). With ``sight`` (:class:`scalematch.stages.secondlook.Sight`), its
    ``look(t, outcome, windows_below)`` takes the second look
    (:func:`scalematch.stages.secondlook.look_again`, with
    :func:`scalematch.stages.secondlook.look_windows_below`) at a best transform of
    more inliers than its minimal sample and fewer than ``min_inliers`` (a sample alone is no
    evidence: its NFA is infinite): its figures go in the evidence, and it may
    accept a transform of ``few_min_inliers`` or more
    (:func:`scalematch.stages.secondlook.look_confirms`). The accepted transform faces more tests
    once refit (:func:`scalematch.stages.finalchecks.final_checks`).
    """
    with_t = [o for o in outcomes if o.estimate is not None and o.estimate.transform is not None
              and o.row.inliers > 0]
    if not with_t:
        return Decision(False, f"no scale produced a transform ({nothing_matched(outcomes)})",
                        math.nan, None, np.zeros((0, 4)), {})
    # a transform whose ratio contradicts the scale it was found at is not that scale's answer
    plausible = [o for o in with_t if not disagrees(o.row, context.fit.model, params)]
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
                    best.row.s, None, np.zeros((0, 4)), {})


def _counted(best, outcomes: Sequence, coarser_shape, context: SearchContext,
             same_point_px: float) -> Winner:
    """The winning outcome ``best`` with its a-contrario count over all of ``outcomes``; an
    epipolar geometry's inliers counted one to one
    (:func:`scalematch.stages.epipolar.one_to_one`, ``same_point_px``)."""
    orientation = context.orientation
    model = context.fit.model
    k = model_of(model).counted(np.hstack([best.src[best.estimate.inliers],
                                           best.dst[best.estimate.inliers]]), same_point_px)
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
    shown = best.row.s * context.shown_scale
    t = best.estimate.transform
    pairs = np.hstack([best.src[best.estimate.inliers], best.dst[best.estimate.inliers]])
    figs = dict(inliers=int(k), candidates=int(w.n), log10_nfa=lnfa, chance_p=w.p)

    def no(reason: str, test: str) -> Decision:  # with the figures, t and pairs reached
        return Decision(False, reason, best.row.s, None, np.zeros((0, 4)),
                        dict(figs), test, t, pairs)

    # the second look decides only below min_inliers, or for a footprint mostly outside the
    # coarser image (the final map's pixel tests follow every match, final_checks): elsewhere
    # it would cost a tenth of a plain pair's time for nothing
    placed = maps_points(context.fit.model)  # a footprint and pixels to test
    second = sight.look(t, best, look_windows_below(lnfa, params)) \
        if sight is not None and placed and (
            w.m < k < params.min_inliers
            or _outside_unproven(t, shapes, lnfa, params)) else None
    figs = _with_look(figs, second)
    if k < params.min_inliers:
        if not few_confirmed(w, second, params):
            return no(f"too few inliers: {k} at scale {shown:.3g} (at least "
                      f"{params.min_inliers} needed, or {params.few_min_inliers} beyond chance "
                      f"that pass the pixel check)", "too few inliers")
        if len(second.inliers) >= k:  # grown (or kept): the refit map and its inliers
            t, pairs = second.transform, second.inliers
        elsewhere = placed_better_nearby(t, k, sight)
        if elsewhere is not None:
            return no(elsewhere, "nearby placement")
    if lnfa > params.max_log_nfa:
        return no(f"the best transform ({_inliers_said(k, len(pairs))} of {w.n} candidates at "
                  f"scale {shown:.3g}) could arise by chance ({_count_said(lnfa, w.m, params)})",
                  "chance")
    if not placed:
        return Decision(True, "", best.row.s, t, pairs, dict(figs))
    figs, refusal = _footprint_tests(t, shapes, w, figs, params, second)
    if refusal is None:
        figs, refusal = _agreement_test(t, w, with_t, shapes[1], figs, params,
                                        context.shown_scale)
    if refusal is None:
        figs, refusal = _rival_test(w, shapes[1], figs, params, context.fit)
    if refusal is not None:
        return no(*refusal)
    return Decision(True, "", best.row.s, t, pairs, dict(figs))


def _inliers_said(k: int, matches: int) -> str:
    """The inliers counted, as a reason says them: with the matches they stand for when an
    epipolar geometry counted them one to one (:func:`scalematch.stages.epipolar.one_to_one`), so
    that the reason and the ``rejected`` block (its ``n_inliers`` are the matches) give the same
    figures.

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
