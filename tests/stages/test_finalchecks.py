"""The final transform's tests (finalchecks.py): uniqueness and the nearby placements by the
pixels, and the parallax of an epipolar geometry counted one to one."""

from __future__ import annotations

import math

import numpy as np

from scalematch.geometry import similarity_matrix
from scalematch.stages.acontrario import chance_probability, log10_nfa, windows_chance
from scalematch.stages.epipolar import one_to_one


def test_a_structure_that_fits_elsewhere_as_well_is_ambiguous(raccoon):
    """The uniqueness check (docs/results/NULLS.md, the hardest nulls): the finer image warped by
    the transform must fit its place at least min_unique_ratio times better (misfit 1 - ZNCC) than
    any other place in the coarser image."""
    import cv2

    from scalematch.config import Config
    from scalematch.stages.finalchecks import Claim, final_checks

    params = Config().decision
    base = raccoon[200:260, 300:380]  # 80 x 60 px
    high = cv2.resize(base, (320, 240), interpolation=cv2.INTER_CUBIC)  # 4x finer
    t = similarity_matrix(0.25, 0.0, 40 - 0.375, 30 - 0.375)
    unique = raccoon[170:350, 260:500]  # the place, and other (unrelated) texture around it
    final, reason, _ = final_checks(unique, high, Claim(t, math.inf), params)
    assert reason == "" and final.unique_ratio > 3 * params.min_unique_ratio
    tiled = np.tile(base, (3, 3))  # the same structure nine times over
    t_tiled = similarity_matrix(0.25, 0.0, 80 - 0.375, 60 - 0.375)  # the centre copy
    final, reason, _ = final_checks(tiled, high, Claim(t_tiled, math.inf), params)
    assert reason.startswith("ambiguous") and final.unique_ratio < params.min_unique_ratio


def test_a_map_found_on_a_copy_is_ambiguous_as_searched(raccoon):
    """searched_unique judges the map the search found (the model searched) by the uniqueness
    test of final_checks: the centre copy of a structure tiled nine times is ambiguous, its
    own place is not, and a map its geometry proves (log10 NFA at most max_log_nfa_geometry)
    is not measured at all."""
    import cv2

    from scalematch.config import Config
    from scalematch.stages.finalchecks import Claim, searched_unique

    params = Config().decision
    base = raccoon[200:260, 300:380]
    high = cv2.resize(base, (320, 240), interpolation=cv2.INTER_CUBIC)
    t = similarity_matrix(0.25, 0.0, 40 - 0.375, 30 - 0.375)
    final, reason = searched_unique(raccoon[170:350, 260:500], high, Claim(t, -20.0), params)
    assert reason == "" and final.unique_ratio > 3 * params.min_unique_ratio
    tiled = np.tile(base, (3, 3))
    t_tiled = similarity_matrix(0.25, 0.0, 80 - 0.375, 60 - 0.375)
    final, reason = searched_unique(tiled, high, Claim(t_tiled, -20.0), params)
    assert reason.startswith("ambiguous") and "(as searched)" in reason
    assert final.unique_ratio < params.min_unique_ratio
    proved = Claim(t_tiled, params.max_log_nfa_geometry - 1.0)
    assert searched_unique(tiled, high, proved, params) == (None, "")


def test_a_final_map_its_neighbours_fit_better_is_refused(raccoon):
    """The final pixel test (min_final_margin): the right map passes with a wide margin; the
    same map turned by 10 degrees about its footprint's centre (one of the pixel check's
    nearby placements is then the truth) fits worse than that neighbour: refused, "the pixels
    do not confirm it" (the uniqueness test, which would refuse it first, left out here)."""
    from dataclasses import replace

    import cv2

    from scalematch.config import Config
    from scalematch.geometry import compose
    from scalematch.stages.finalchecks import Claim, final_checks

    params = Config().decision
    base = raccoon[200:260, 300:380]
    high = cv2.resize(base, (320, 240), interpolation=cv2.INTER_CUBIC)
    low = raccoon[170:350, 260:500]
    t = similarity_matrix(0.25, 0.0, 40 - 0.375, 30 - 0.375)
    final, reason, _ = final_checks(low, high, Claim(t, math.inf), params)
    assert reason == "" and final.final_margin > 0.3  # measured 0.6-0.7
    turn = cv2.getRotationMatrix2D((80.0, 60.0), 10.0, 1.0)  # about the footprint's centre
    alone = replace(params, min_unique_ratio=0.0)
    final, reason, _ = final_checks(low, high, Claim(compose(turn, t), math.inf), alone)
    assert final.final_margin < params.min_final_margin
    assert reason.startswith("the pixels do not confirm it"), reason


def test_points_matched_many_times_count_once_for_an_epipolar_geometry():
    """Twelve finer points matched to one coarser point (all on any line through it) and two
    coarser points matched to one finer point count as one inlier each; distinct pairs count."""
    rng = np.random.default_rng(0)
    distinct = np.hstack([rng.uniform(0, 400, (10, 2)), rng.uniform(0, 400, (10, 2))])
    to_one = np.hstack([rng.uniform(0, 400, (12, 2)), np.tile([[200.0, 150.0]], (12, 1))])
    to_one[:, 2:] += rng.uniform(-0.3, 0.3, (12, 2))  # the same point, localised again
    from_one = np.array([[50.0, 60, 10, 10], [50.2, 60, 300, 250]])
    pairs = np.vstack([distinct, to_one, from_one])
    assert len(one_to_one(pairs, 1.0)) == 10 + 1 + 1
    assert len(one_to_one(distinct, 1.0)) == 10


def _two_views(depths: np.ndarray, rng) -> np.ndarray:
    """(N, 4) finer, coarser px of scene points seen by two pinhole cameras: the finer camera
    at the origin (focal 800 px, 640x480), the coarser one moved sideways and forward, turned
    by 5 degrees and with half the focal length (a zoom ratio of 2); points spread over the
    finer image at the given depths."""
    xy = rng.uniform((40, 40), (600, 440), (len(depths), 2))
    rays = np.hstack([(xy - (320, 240)) / 800.0, np.ones((len(xy), 1))])
    world = rays * depths[:, None]
    a = math.radians(5.0)
    turn = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    cam = (world - (1.5, 0.2, -1.0)) @ turn.T
    coarser = 400.0 * cam[:, :2] / cam[:, 2:] + (320, 240)
    return np.hstack([xy, coarser])


def _counted_f(pairs: np.ndarray, candidates: int):
    """The figures the decision reaches for an epipolar geometry with ``pairs`` as its
    inliers among ``candidates``, counted as it counts them (one test per subset size)."""
    p = chance_probability(3.0, (480, 640), "fundamental", False, 0.0)
    k = len(pairs)
    return dict(inliers=k, candidates=candidates, chance_p=p,
                log10_nfa=log10_nfa(candidates, k, 8, p, candidates - 8))


def test_a_3d_scene_shows_parallax_off_its_plane_and_a_flat_one_does_not():
    """A wall at 10 m with 60 points and 40 points at 4-30 m, among 150 candidates: the 40
    are off the wall's homography and fit the epipolar geometry far beyond chance. The same wall with 4 points off
    it, or with a shifted copy of 12 of its points (a repeated structure matched to its copy),
    shows no parallax: the plane map then answers."""
    from scalematch.stages.acontrario import DecisionParams
    from scalematch.stages.finalchecks import plane_parallax
    from scalematch.stages.estimator import FitSpec

    rng = np.random.default_rng(1)
    fit, params = FitSpec("fundamental"), DecisionParams()
    wall = _two_views(np.full(60, 10.0), rng)
    deep = _two_views(rng.uniform(4.0, 30.0, 40), rng)
    scene = np.vstack([wall, deep])
    seen = plane_parallax(scene, _counted_f(scene, 150), fit, params)
    assert seen["parallax"] and seen["parallax_points"] >= 35
    assert seen["parallax_log10_nfa"] < -15

    flat = np.vstack([wall, deep[:4]])
    seen = plane_parallax(flat, _counted_f(flat, 150), fit, params)
    assert not seen["parallax"] and seen["parallax_points"] <= 4

    copy = _two_views(np.full(12, 10.0), rng)  # more of the wall's points ...
    copy[:, 2:] += (37.0, 0.0)  # ... matched to their copies one period away
    repeated = np.vstack([wall, copy])
    seen = plane_parallax(repeated, _counted_f(repeated, 150), fit, params)
    assert not seen["parallax"] and seen["parallax_points"] == 12


def test_an_occluded_map_the_margin_refuses_is_confirmed_by_its_windows(raccoon):
    """Where one ZNCC over the footprint refuses the final map (forced here: a margin no map
    reaches), the windows decide (``min_near_windows``): the right map of a finer image a
    third occluded passes, the same map turned by 10 degrees, whose neighbour is the truth,
    is refused, and so is a map onto another part of the photo."""
    from dataclasses import replace

    import cv2

    from scalematch.config import Config
    from scalematch.geometry import compose
    from scalematch.stages.finalchecks import Claim, final_checks

    base = raccoon[200:260, 300:380]
    high = cv2.resize(base, (320, 240), interpolation=cv2.INTER_CUBIC)
    high[:, :100] = 255.0 - cv2.resize(raccoon[20:80, 20:45], (100, 240))  # an occluder
    low = raccoon[170:350, 260:500]
    t = similarity_matrix(0.25, 0.0, 40 - 0.375, 30 - 0.375)
    params = replace(Config().decision, min_final_margin=0.99, min_unique_ratio=0.0)
    final, reason, _ = final_checks(low, high, Claim(t, math.inf), params)
    assert reason == "", reason
    assert windows_chance(final.near_windows, final.near_windows_agreeing,
                          final.near_windows_nearby) <= params.max_log_nfa
    assert final.near_windows_agreeing >= params.min_near_windows
    turn = cv2.getRotationMatrix2D((80.0, 60.0), 10.0, 1.0)
    final, reason, test = final_checks(low, high, Claim(compose(turn, t), math.inf), params)
    assert test == "pixels" and "of its windows agree" in reason, reason
    away = similarity_matrix(0.25, 0.0, 150 - 0.375, 110 - 0.375)
    final, reason, test = final_checks(low, high, Claim(away, math.inf), params)
    assert test == "pixels", reason


def test_the_plane_given_the_points_off_it_need_only_fix_the_epipole():
    """With the plane's map given, the points off it fix only the epipole (2 points, not 8):
    the 20 points of a second depth (5 m; the wall at 10 m) among 150 candidates, too few
    for the matrix by themselves, are beyond chance for the epipole where their matches beat
    the plane (``beat_plane`` all True); where the plane fits them better (all False), nothing
    counts."""
    from scalematch.stages.acontrario import DecisionParams
    from scalematch.stages.estimator import FitSpec
    from scalematch.stages.finalchecks import plane_parallax

    rng = np.random.default_rng(2)
    fit, params = FitSpec("fundamental"), DecisionParams()
    scene = np.vstack([_two_views(np.full(60, 10.0), rng), _two_views(np.full(20, 5.0), rng)])
    counted = _counted_f(scene, 150)
    alone = plane_parallax(scene, counted, fit, params)
    off = alone["parallax_points"]
    assert 17 <= off <= 20 and not alone["parallax"]  # a point near the wall's map stays on it
    assert "epipole_log10_nfa" not in alone  # measured only where the pixels can vouch
    vouched = plane_parallax(scene, counted, fit, params, lambda h, off: np.ones(len(off), bool))
    assert vouched["parallax_vouched_points"] == off
    assert vouched["epipole_log10_nfa"] <= params.max_log_nfa < alone["parallax_log10_nfa"]
    none = plane_parallax(scene, counted, fit, params, lambda h, off: np.zeros(len(off), bool))
    assert none["parallax_vouched_points"] == 0 and math.isinf(none["epipole_log10_nfa"])
