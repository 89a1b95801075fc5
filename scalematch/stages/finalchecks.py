"""The tests of a match's final transform, after the refit (docs/design/DECISION.md).

:func:`final_checks` judges a :class:`Claim` by its pixels: unique in the coarser image (one
ZNCC, or window by window: :func:`windows_agree`, :func:`unique_threshold`) and better than its
nearby placements (the margin, or window by window: :func:`near_windows_agree`);
:func:`searched_unique` asks the same uniqueness of the map as the search found it, for a map
climbed to a richer model that only its windows find unique.
:func:`plane_parallax` says whether an epipolar geometry's inliers show parallax off their
dominant plane, counted one to one (:func:`one_to_one`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Dict, Mapping, Optional

import numpy as np

from ..result import figure
from .acontrario import DecisionParams, FinalFigures, log10_nfa, windows_chance
from .epipolar import one_to_one
from .estimator import FitSpec, estimate, model_of
from .pixelcheck import NearWindows, PixelParams, near_windows, pixel_check
from .threads import thread_map
from .uniqueness import Agreement, agreement_of, unique_template, uniqueness_of


@dataclass(frozen=True)
class Claim:
    """A match's final transform as the pixel tests judge it (:func:`final_checks`)."""

    transform: np.ndarray = field(repr=False)  #: refit, finer px -> coarser px
    log10_nfa: float  #: the decision's a-contrario figure for it
    #: the finer px (N, 2) of the inliers that vouch for it; None: the whole footprint
    vouched: Optional[np.ndarray] = field(default=None, repr=False)


#: the points that fix an epipolar geometry once its plane's map is given: F = [e']x H leaves
#: the epipole e', 2 degrees of freedom, and each point off the plane puts e' on one line
#: (Hartley & Zisserman, "Multiple View Geometry", 2nd ed., 13.3; DEGENSAC's plane and
#: parallax)
EPIPOLE_SAMPLE = 2


def plane_parallax(pairs: np.ndarray, counted: Mapping[str, Any], fit: FitSpec,
                   params: DecisionParams,
                   beat_plane: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None
                   ) -> Dict[str, Any]:
    """Whether an epipolar geometry's inliers ``pairs`` ((N, 4) x, y finer; x, y coarser, the
    search's working px) show parallax by themselves: the figures ``parallax_points``,
    ``parallax_log10_nfa`` and ``parallax`` of the evidence, and, given ``beat_plane`` and no
    parallax seen so, the count of the points off the plane with the plane given
    (``parallax_vouched_points``, ``epipole_log10_nfa``: only a matrix without parallax of its
    own needs it, and it compares the pixels at every point off the plane).

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

    Where the plane's map is established otherwise (the plane map of the pair passes the
    decision: ``answer.without_parallax``), the points off it need only fix the epipole,
    m = :data:`EPIPOLE_SAMPLE`. They count there only where their own match fits the pixels
    better than the plane's prediction (``beat_plane(h, off_pairs)``, a boolean per pair:
    :func:`scalematch.stages.pixelcheck.matches_beat_plane`): a flat scene's look-alikes (a
    repeated window matched to its neighbour, points along an edge) line up with an epipole as
    a scene with depth does, but the plane fits them better where they stand.
    """
    m = model_of(fit.model).min_sample
    n, k = int(figure(counted, "candidates")), int(figure(counted, "inliers"))
    p = float(figure(counted, "chance_p"))
    log10_tests = figure(counted, "log10_nfa") - log10_nfa(n, k, m, p, 1.0)
    pairs = np.asarray(pairs, np.float64).reshape(-1, 4)
    pairs = pairs[one_to_one(pairs, params.same_point_px)]
    plane = estimate("homography", pairs[:, :2], pairs[:, 2:], fit.ransac, seed=fit.seed)
    on_plane = int(plane.n_inliers)
    k_off = len(pairs) - on_plane

    def off_plane_nfa(k_counted: int, sample: int) -> float:
        lnfa = log10_nfa(max(n - on_plane, k_counted), k_counted, sample, p, 1.0)
        if math.isfinite(lnfa) and math.isfinite(log10_tests):
            lnfa += max(log10_tests, 0.0)
        return lnfa

    lnfa = off_plane_nfa(k_off, m)
    seen = {"parallax_points": k_off, "parallax_log10_nfa": lnfa,
            "parallax": bool(lnfa <= params.max_log_nfa)}
    if beat_plane is not None and not seen["parallax"] and plane.transform is not None and k_off:
        held = int(np.count_nonzero(beat_plane(plane.transform, pairs[~plane.inliers])))
        seen.update(parallax_vouched_points=held,
                    epipole_log10_nfa=off_plane_nfa(held, EPIPOLE_SAMPLE))
    return seen


def windows_agree(a: Agreement, params: DecisionParams) -> bool:
    """Whether the windows of a claim (:func:`scalematch.stages.uniqueness.window_agreement`)
    show it unique: agreeing at the claim beyond chance at the rate elsewhere
    (:func:`scalematch.stages.acontrario.windows_chance` at most ``max_log_nfa``), most of
    them, far fewer anywhere else.

    >>> p = DecisionParams()
    >>> windows_agree(Agreement(40, 0.8, 0.2), p), windows_agree(Agreement(40, 0.5, 0.1), p)
    (True, False)
    >>> windows_agree(Agreement(40, 0.8, 0.5), p), windows_agree(Agreement(2, 1.0, 0.0), p)
    (False, False)
    >>> windows_agree(Agreement(11, 8 / 11, 2 / 11), p)  # an occluded map: 8 of 11 windows
    True
    """
    return _beyond_the_rest(a.windows, a.claimed, a.elsewhere, params.min_window_agreement,
                            params)


def final_checks(coarser: np.ndarray, finer: np.ndarray, claim: Claim, params: DecisionParams,
                 near=None, pixel: PixelParams = PixelParams()):
    """(figures, reason, test): the pixel tests of a match's final transform ``claim.transform``
    (``t`` below: finer px -> coarser px, refit, at log10 NFA ``claim.log10_nfa``) as
    :class:`scalematch.stages.acontrario.FinalFigures`, why it is refused and by which test
    (:data:`scalematch.stages.acontrario.TESTS`; "" when it is not).

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
    transform of comparable support, which :func:`scalematch.stages.decision.decide` refuses) is
    unique by its geometry; its pixel figures are recorded, not decisive: an occluder, parallax or
    relighting lowers them where the points prove the map (``judged_by`` says which test decided).
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
    final, reason = _unique(final, placed, log10_nfa, params, pixel)
    if reason:
        return final, reason, "uniqueness"
    if near.margin <= params.min_final_margin:  # nan: no check possible, passes
        return _nearby_windows(coarser, finer, t, final, params, pixel)
    return final, "", ""


def searched_unique(coarser: np.ndarray, finer: np.ndarray, claim: Claim, params: DecisionParams,
                    pixel: PixelParams = PixelParams()):
    """(figures, reason): the uniqueness test of :func:`final_checks` on the map as the search
    found it (``claim``: its model, refit), for an answer climbed to a richer model
    (``answer.model_by_pixels``); reason "" when it passes.

    The claim's log10 NFA is the searched map's, so its pixels must be unique as well: a
    richer model's freedom is fitted to the pixels it is then judged by, and on a repeated
    facade it bends the map onto a copy's windows (an affine or homography of half a facade
    agreeing at 65 % of its windows with the other half, where the similarity found agrees
    at 25 % to 45 %: docs/design/DECISION.md, "A 'no' on a knife's edge"). A map beyond chance
    by its geometry (``max_log_nfa_geometry``) is unique by it, as in :func:`final_checks`.
    """
    t, log10_nfa = claim.transform, claim.log10_nfa
    if log10_nfa <= params.max_log_nfa_geometry:
        return None, ""
    placed = unique_template(coarser, finer, t, pixel, claim.vouched)
    u = uniqueness_of(placed, pixel)
    final = FinalFigures(unique_claimed=u.claimed, unique_elsewhere=u.elsewhere,
                         unique_ratio=u.ratio, final_ncc=math.nan, final_margin=math.nan,
                         judged_by="pixels")
    return _unique(final, placed, log10_nfa, params, pixel, " (as searched)")


def _unique(final: FinalFigures, placed, log10_nfa: float, params: DecisionParams,
            pixel: PixelParams, which: str = ""):
    """(figures, reason): the uniqueness ratio of ``final``, or where it refuses, the windows
    of the template ``placed`` (:func:`windows_agree`); reason "" when the map is unique."""
    if not final.unique_ratio < params.min_unique_ratio:  # nan: no room elsewhere, passes
        return final, ""
    a = agreement_of(placed, pixel)
    final = replace(final, unique_windows=a.windows, windows_agreeing=a.claimed,
                    windows_elsewhere=a.elsewhere)
    if windows_agree(a, params):
        return final, ""
    windows = (f"; {a.claimed:.0%} of its windows agree at the transform found, "
               f"{a.elsewhere:.0%} elsewhere" if a.windows else "")
    return final, (f"ambiguous: the high image's pixels fit elsewhere in the low "
                   f"image nearly as well (ZNCC {final.unique_elsewhere:.2f} there, "
                   f"{final.unique_claimed:.2f} at the transform found{which}{windows}; "
                   f"log10 NFA {log10_nfa:.1f})")


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
    better than its nearby wrong placements: agreeing at the claim beyond chance at the best
    nearby placement's rate (:func:`scalematch.stages.acontrario.windows_chance` at most
    ``max_log_nfa``), ``min_near_windows`` of them, ``min_window_ratio`` times the share at the
    best nearby placement.

    >>> p = DecisionParams()
    >>> [near_windows_agree(NearWindows(n, at, near), p)
    ...  for n, at, near in ((40, 0.45, 0.02), (40, 0.1, 0.0), (40, 0.45, 0.3), (2, 1.0, 0.0))]
    [True, False, False, False]
    """
    return _beyond_the_rest(w.windows, w.claimed, w.nearby, params.min_near_windows, params)


def _beyond_the_rest(windows: int, claimed: float, other: float, least: float,
                     params: DecisionParams) -> bool:
    """The rule both window tests share: at least ``least`` of the ``windows`` agreeing at the
    claim, ``min_window_ratio`` times the share ``other`` at the best other placement, and so
    many beyond chance at that share (``windows_chance`` at most ``max_log_nfa``)."""
    return (claimed >= least and claimed >= params.min_window_ratio * other
            and windows_chance(windows, claimed, other) <= params.max_log_nfa)
