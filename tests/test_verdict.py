"""verdict: the words of a match, in the verdict line and the evidence line."""

from __future__ import annotations

import numpy as np

from scalematch.result import MatchResult
from scalematch.verdict import verdict


def test_the_verdict_calls_no_image_finer_near_a_ratio_of_1():
    """Two crops of one photo match at ratio 1.000, either way round by chance: "the first
    image is the finer one" would be false there; what the transform maps is said instead."""
    def swapped(ratio):
        return MatchResult(matched=True, model="similarity", resolution_ratio=ratio,
                           rotation_deg=0.0, order="swapped", best_scale=1.0,
                           transform=np.array([[1 / ratio, 0, 0], [0, 1 / ratio, 0.0]]),
                           inliers=np.zeros((0, 4)))
    assert verdict(swapped(1.0)).endswith(
        "order swapped (the transform maps the first image into the second)")
    assert verdict(swapped(3.0)).endswith("order swapped (the first image is the finer one)")


def test_the_verdict_says_which_image_the_tilted_view_was_of():
    """A match found on a view of the coarser image says so; one on a view of the finer image
    says only the tilt."""
    from scalematch.result import Evidence

    def found(view_of):
        return MatchResult(matched=True, model="affine", resolution_ratio=1.0, rotation_deg=0.0,
                           best_scale=2.0, transform=np.array([[1.0, 0, 0], [0, 1.0, 0]]),
                           inliers=np.zeros((0, 4)),
                           evidence=Evidence(view_tilt=4.0, view_longitude_deg=36.0,
                                             view_of=view_of))
    assert verdict(found("coarser")).endswith(
        "seen tilted by 4 at 36 deg (the coarser image)")
    assert verdict(found("finer")).endswith("seen tilted by 4 at 36 deg")


def test_the_evidence_line_says_when_windows_decided():
    """A match the final margin refused and its windows accepted says so, with their shares;
    one whose margin passed says nothing of windows."""
    from dataclasses import replace

    from scalematch.verdict import evidence_line
    from scalematch.result import build_evidence

    plain = dict(log10_nfa=-59.6, final_ncc=0.15, final_margin=-0.09, unique_ratio=0.69,
                 judged_by="pixels")
    by_windows = MatchResult(matched=True, model="similarity", evidence=build_evidence(
        plain, dict(near_windows=38, near_windows_agreeing=0.5, near_windows_nearby=0.026,
                    unique_windows=20, windows_agreeing=0.8, windows_elsewhere=0.2)))
    line = evidence_line(by_windows)
    assert "-0.09 against nearby placements" in line
    assert "50% of 38 windows agree there, 3% nearby" in line
    assert "80% of 20 windows agree at its place, 20% elsewhere" in line
    margin_only = replace(by_windows, evidence=build_evidence(dict(plain, final_margin=0.3)))
    assert "windows" not in evidence_line(margin_only)
    # a refused few-inlier map: the second look's margin, and its windows where measured
    look = dict(log10_nfa=-10.0, pixel_ncc=0.2, pixel_margin=0.05, pixel_windows=37,
                pixel_windows_agreeing=0.2, pixel_windows_nearby=0.03)
    refused = MatchResult(matched=False, model="similarity", evidence=build_evidence(look))
    assert "+0.05 against nearby placements; 20% of 37 windows agree there, 3% nearby" in \
        evidence_line(refused)


def test_the_verdict_says_when_a_plane_map_answers_for_a_matrix_not_found():
    """``--model fundamental`` answered by a plane map because no matrix was found says so; the
    same map asked for by the default says nothing of epipolar geometry."""
    from scalematch.config import Config

    def plane(config):
        return MatchResult(matched=True, model="similarity", resolution_ratio=9.9,
                           rotation_deg=0.0, best_scale=10.1, config=config,
                           transform=np.array([[0.1, 0, 0], [0, 0.1, 0.0]]),
                           inliers=np.zeros((0, 4)))
    assert verdict(plane(Config(model="fundamental"))).endswith(
        "no epipolar geometry found: the plane map of a flat scene answers")
    assert "epipolar" not in verdict(plane(Config()))


def test_the_evidence_line_says_how_the_plane_of_a_matrix_was_established():
    """A matrix answered with its parallax seen through the plane says how many points fixed the
    epipole; where the plane map was established near its own inliers, that too."""
    from scalematch.result import build_evidence
    from scalematch.verdict import evidence_line

    through = dict(log10_nfa=-20.0, parallax=True, parallax_vouched_points=12, plane_inliers=29,
                   epipole_log10_nfa=-4.8)
    line = evidence_line(MatchResult(matched=True, model="fundamental",
                                     evidence=build_evidence(through)))
    assert "parallax: 12 inliers off the plane map (29 inliers) that fit better off it, " \
           "log10 NFA -4.8 for the epipole" in line
    near = dict(through, plane_windows=37, plane_windows_agreeing=0.4, plane_windows_nearby=0.0)
    line = evidence_line(MatchResult(matched=True, model="fundamental",
                                     evidence=build_evidence(near)))
    assert "(29 inliers, its pixels agreeing near them: 40% of 37 windows, 0% nearby)" \
        in line
