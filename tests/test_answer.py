"""The answer module (answer.py): what is made of the search's attempts."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from scalematch import Config, match
from scalematch.answer import plane_instead, without_parallax
from scalematch.result import Evidence, MatchResult
from scalematch.stages.views import ViewParams


def _claimed_f(f):
    """A matched fundamental matrix ``f`` with no parallax, as the search would report it."""
    return MatchResult(matched=True, model="fundamental", transform=f, inliers=np.zeros((0, 4)),
                       timings={"total": 0.1},
                       evidence=Evidence(inliers=30, log10_nfa=-20.0, parallax_points=4,
                                         parallax_log10_nfa=math.inf))


def test_a_fundamental_matrix_without_parallax_or_plane_map_is_refused(raccoon):
    """Two halves of one photo: nothing in common, so no plane map passes; an F whose inliers
    show no parallax is refused, and the reason says both."""
    left, right = raccoon[:, :480], raccoon[:, 544:]
    f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # a rectified pair: y' = y
    config = Config(model="fundamental", views=ViewParams(enabled=False))
    plane = match(left[:240, :320], right[:240, :320], replace(config, model="similarity"))
    r = without_parallax(_claimed_f(f), plane, config)
    assert not r.matched and r.transform is None
    assert r.rejected.test == "plane" and r.rejected.transform is not None
    assert r.evidence.plane_inliers == 0
    assert "no parallax" in r.reason and "no plane map" in r.reason


def test_a_plane_map_in_place_of_a_matrix_is_searched_without_match_calling_itself(
        monkeypatch, raccoon):
    """A flat zoom pair asked for a fundamental matrix: its plane map answers, searched on the
    same working images within the one call of ``match`` (which never calls itself)."""
    from scalematch import pipeline
    from scalematch.lab.synthetic import make_zoom_pair

    calls = []
    real = pipeline.match

    def counted(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(pipeline, "match", counted)
    pair = make_zoom_pair(raccoon, 2.0, np.random.default_rng(0), high_size=(320, 240))
    r = pipeline.match(pair.low, pair.high, Config(model="fundamental"))
    assert calls == [1]
    assert r.matched and r.model != "fundamental" and r.evidence.plane_inliers == r.n_inliers


def test_a_matrix_not_found_gives_way_to_a_plane_map_without_parallax_only():
    """``--model fundamental`` that found no matrix: a plane map that passed the decision and
    shows no parallax answers (a flat scene), in the time of both searches; a plane map whose
    candidates show parallax (a scene with depth) does not, and the "no" stays."""
    no = MatchResult(matched=False, model="fundamental", reason="could arise by chance",
                     timings={"total": 0.5})
    flat = MatchResult(matched=True, model="similarity", transform=np.eye(3)[:2],
                       inliers=np.zeros((0, 4)), timings={"total": 1.5},
                       evidence=Evidence(inliers=30, parallax=False))
    r = plane_instead(no, flat)
    assert r.matched and r.model == "similarity" and r.seconds == 2.0
    deep = replace(flat, evidence=Evidence(inliers=30, parallax=True))
    r = plane_instead(no, deep)
    assert not r.matched and r.reason == "could arise by chance" and r.seconds == 2.0
    unmatched = MatchResult(matched=False, model="similarity", reason="too few inliers",
                            timings={"total": 1.5})
    assert not plane_instead(no, unmatched).matched


def test_a_matrix_whose_plane_map_passes_answers_where_the_points_off_it_fix_the_epipole():
    """A matrix without parallax of its own, and a plane map of the pair that passed: the
    matrix answers where its inliers off the plane, vouched by the pixels, fix the epipole
    beyond chance (``epipole_log10_nfa`` at most ``max_log_nfa``); otherwise the plane map."""
    f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    config = Config(model="fundamental")
    plane = MatchResult(matched=True, model="homography", transform=np.eye(3),
                        inliers=np.zeros((40, 4)), timings={"total": 0.2},
                        evidence=Evidence(inliers=40, log10_nfa=-40.0))
    bound = config.decision.max_log_nfa
    seen = replace(_claimed_f(f), evidence=replace(_claimed_f(f).evidence,
                                                   parallax_vouched_points=15,
                                                   epipole_log10_nfa=bound - 0.5))
    r = without_parallax(seen, plane, config)
    assert r.matched and r.model == "fundamental" and np.array_equal(r.transform, f)
    assert r.evidence.parallax and r.evidence.plane_inliers == 40
    assert r.timings["total"] == 0.1 + 0.2
    weak = replace(seen, evidence=replace(seen.evidence, epipole_log10_nfa=bound + 0.5))
    r = without_parallax(weak, plane, config)
    assert r.matched and r.model == "homography" and r.evidence.epipole_log10_nfa == bound + 0.5


def test_a_plane_map_refused_by_its_whole_footprint_establishes_the_plane_near_its_inliers():
    """A plane map that only the pixels over its whole footprint refused (test "pixels": a 3-D
    scene's other planes are in it): where its windows near its own inliers agree, the plane is
    established for the matrix, which answers where its points off the plane fix the epipole;
    the plane map never answers itself, and windows that do not agree leave the "no"."""
    from scalematch.answer import plane_near_its_inliers
    from scalematch.result import Rejected
    from scalematch.stages.pixelcheck import NearWindows

    f = np.array([[0, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    config = Config(model="fundamental")
    bound = config.decision.max_log_nfa
    refused = MatchResult(matched=False, model="homography", reason="the pixels do not confirm it",
                          timings={"total": 0.2},
                          rejected=Rejected(np.eye(3), "homography", np.zeros((30, 4)), -12.0,
                                            "pixels"))
    seen = replace(_claimed_f(f), evidence=replace(_claimed_f(f).evidence,
                                                   parallax_vouched_points=12,
                                                   epipole_log10_nfa=bound - 2.0))
    agree, few = NearWindows(37, 0.4, 0.0), NearWindows(22, 0.2, 0.0)
    r = without_parallax(seen, refused, config, agree)
    assert r.matched and r.model == "fundamental" and np.array_equal(r.transform, f)
    assert r.evidence.plane_inliers == 30 and r.evidence.plane_windows == 37
    assert r.evidence.plane_windows_agreeing == 0.4
    r = without_parallax(seen, refused, config, few)
    assert not r.matched and r.rejected.test == "plane" and r.evidence.plane_inliers == 0
    assert r.evidence.plane_windows == 22 and r.rejected.figures["plane_windows"] == 22
    assert "near its own inliers 20% of its 22 windows agree, 0% nearby)" in r.reason
    weak = replace(seen, evidence=replace(seen.evidence, epipole_log10_nfa=bound + 0.5))
    r = without_parallax(weak, refused, config, agree)
    assert not r.matched and r.rejected.test == "plane"
    assert "which establishes the plane, but the 12 inliers off it that fit better there " \
        f"fix the epipole at log10 NFA {bound + 0.5:.1f})" in r.reason
    assert not without_parallax(seen, refused, config).matched  # no windows measured
    # only a map refused by the pixels alone is looked at again
    by_chance = replace(refused, rejected=replace(refused.rejected, test="chance"))
    passed = replace(refused, matched=True, rejected=None)
    assert plane_near_its_inliers(by_chance, None, config) is None
    assert plane_near_its_inliers(passed, None, config) is None
