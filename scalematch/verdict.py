"""The words of a match: its one-line verdict (stderr's and the pictures' captions), its model
as said, and its evidence beyond the points (the overlay's caption).

* ``verdict``: matched or not, the model, ratio, rotation, inliers and best scale, or the reason;
* ``model_said``: the model, and the richer one its inliers did not pin down;
* ``evidence_line``: the a-contrario test, the pixel tests and the uniqueness, in one line.
"""

from __future__ import annotations

import numpy as np

from .result import MatchResult
from .stages.estimator import model_of

#: Below this ratio the verdict does not call either image the finer one (5 %: a ratio found at
#: 1.000 either way round, EXIF-turned crops of one photo, was reported swapped by chance)
NEAR_ONE_RATIO = 1.05


def said_as_matrix(model: str) -> bool:
    """Whether an answer of ``model`` is told as a matrix (its inliers and parallax) rather
    than as a map (its ratio, rotation and footprint): a point maps to a line."""
    return not model_of(model).has_ratio


def verdict(result: MatchResult) -> str:
    """The one-line verdict of a match, for the command line and the captions alike.

    Matched: the model, ratio, rotation, inliers and best scale (to the per-scale table's three
    significant digits), a tilted view and a swapped order when so, and the richer model
    fitted first when its inliers did not pin it down (``evidence.unpinned_model``); the
    fundamental matrix has no ratio. The best scale is the finer image's: a step whose images
    were shrunk to their working sizes (or a JPEG decoded reduced) can have searched the image
    that is the coarser one in the files as the finer, and its scale in the files' pixels is
    then below 1
    (``best_scale``, the table's ``s``): the verdict gives 1 / s, the scale at which the finer
    image was found. Not matched: the reason, and the best scale when there is one and the
    reason does not name the scale it is about already.

    >>> from scalematch.result import MatchResult
    >>> no = MatchResult(matched=False, model="similarity", best_scale=2.0,
    ...                  reason="too few inliers: 3 at scale 2")
    >>> verdict(no)
    'no reliable match: too few inliers: 3 at scale 2'
    >>> verdict(MatchResult(matched=False, model="similarity", best_scale=2.0, reason="ambiguous"))
    'no reliable match: ambiguous, best scale 2'
    >>> verdict(MatchResult(matched=True, model="similarity", best_scale=0.63,
    ...                     inliers=np.zeros((760, 4)), resolution_ratio=2.0, rotation_deg=0.0,
    ...                     order="swapped"))  # a 16 MP JPEG decoded at half size, found finer
    'matched (similarity): ratio 2.000, rotation 0.0 deg, 760 inliers, best scale 1.59, order swapped (the first image is the finer one)'
    >>> from scalematch.result import build_evidence
    >>> loose = build_evidence(dict(unpinned_model="homography", unpinned_px=4.5, pin_px=0.9))
    >>> verdict(MatchResult(matched=True, model="similarity", best_scale=8.0, evidence=loose,
    ...                     inliers=np.zeros((11, 4)), resolution_ratio=8.0, rotation_deg=0.0))
    'matched (similarity; the homography was not pinned down by its inliers, 4.50 px expected error): ratio 8.000, rotation 0.0 deg, 11 inliers, best scale 8'
    """
    s = result.best_scale
    if result.matched and 0 < s < 1:  # found at 1/s, the finer image's scale
        s = 1.0 / s
    best = f"best scale {s:.3g}" if np.isfinite(s) else ""
    if not result.matched:
        reason = result.reason or "the evidence is too weak"
        named = "scale" in reason  # "... at scale 2", "(the best, at scale 1, ...)"
        return f"no reliable match: {reason}" + (f", {best}" if best and not named else "")
    if said_as_matrix(result.model):
        return f"matched ({result.model} matrix): {result.n_inliers} inliers, {best}"
    tilt = float(result.evidence.view_tilt)
    whose = " (the coarser image)" if result.evidence.view_of == "coarser" else ""
    view = (f", seen tilted by {tilt:g} at {result.evidence.view_longitude_deg:g} deg{whose}"
            if tilt > 1.0 else "")
    order = ""
    if result.order == "swapped":  # near a ratio of 1 neither image is finer: say what maps
        order = (", order swapped (the first image is the finer one)"
                 if result.resolution_ratio >= NEAR_ONE_RATIO else
                 ", order swapped (the transform maps the first image into the second)")
    plane = (", parallax: the map of the scene's dominant plane" if result.evidence.parallax
             else "")
    if not np.isnan(result.evidence.parallax_log10_nfa):  # a fundamental matrix was asked for
        plane = (", no parallax: the plane map answers (an epipolar geometry's epipole is not "
                 "fixed by its inliers)")
    elif result.config is not None and said_as_matrix(result.config.model):  # none found
        plane = ", no epipolar geometry found: the plane map of a flat scene answers"
    return (f"matched ({model_said(result)}): ratio {result.resolution_ratio:.3f}, rotation "
            f"{result.rotation_deg:.1f} deg, {result.n_inliers} inliers, {best}{view}{order}"
            f"{plane}")


def model_said(result: MatchResult) -> str:
    """The model of a match, and the richer one fitted first when its inliers did not pin it
    down (``evidence.unpinned_model``, ``stages.refit.pinned_model``)."""
    e = result.evidence
    if not e.unpinned_model:
        return result.model
    return (f"{result.model}; the {e.unpinned_model} was not pinned down by its inliers, "
            f"{e.unpinned_px:.2f} px expected error")


def evidence_line(result: MatchResult) -> str:
    """The evidence beyond the points, one line: the pixel check, the uniqueness."""
    e = result.evidence
    parts = [f"log10 NFA {e.log10_nfa:.1f}"] if np.isfinite(e.log10_nfa) else []
    # the final map's check where there is one (a match), else the search's (few inliers)
    final = np.isfinite(e.final_ncc)
    ncc, margin = (e.final_ncc, e.final_margin) if final else (e.pixel_ncc, e.pixel_margin)
    windows, agreeing, nearby = (
        (e.near_windows, e.near_windows_agreeing, e.near_windows_nearby) if final else
        (e.pixel_windows, e.pixel_windows_agreeing, e.pixel_windows_nearby))
    if np.isfinite(ncc):
        parts.append(f"pixels: ZNCC {ncc:.2f}, {margin:+.2f} against nearby placements")
    if windows:  # the margin fell short: the windows decided
        parts.append(f"{agreeing:.0%} of {windows} windows agree there, {nearby:.0%} nearby")
    if np.isfinite(e.unique_ratio):
        parts.append(f"fits its place {e.unique_ratio:.3g}x better than anywhere else")
    if e.unique_windows:  # the ratio refused: the windows decided
        parts.append(f"{e.windows_agreeing:.0%} of {e.unique_windows} windows agree at its "
                     f"place, {e.windows_elsewhere:.0%} elsewhere")
    if result.matched and e.judged_by == "geometry":
        parts.append("unique by its geometry")
    if result.matched and e.parallax and said_as_matrix(result.model) and e.plane_inliers:
        near = (f", its pixels agreeing near them: {e.plane_windows_agreeing:.0%} of "
                f"{e.plane_windows} windows, {e.plane_windows_nearby:.0%} nearby"
                if e.plane_windows else "")
        parts.append(f"parallax: {e.parallax_vouched_points} inliers off the plane map "
                     f"({e.plane_inliers} inliers{near}) that fit better off it, log10 NFA "
                     f"{e.epipole_log10_nfa:.1f} for the epipole")
    elif result.matched and e.parallax and said_as_matrix(result.model):
        parts.append(f"parallax: {e.parallax_points} inliers off the dominant plane, log10 "
                     f"NFA {e.parallax_log10_nfa:.1f}")
    elif result.matched and e.parallax:
        parts.append(f"{e.parallax_points} matches off its plane fit an epipolar geometry "
                     f"(--model fundamental gives it)")
    return "; ".join(parts)
