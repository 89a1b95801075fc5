"""The 3-D pairs benchmark (``scalematch.lab.threed``): the scores on cameras of known geometry,
the Levenberg-Marquardt refinement, the reference fit, the images as given, the pair list, the
stored references, and the shared photos (skipped when absent)."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from scalematch.lab import threed
from test_efpairs import _camera, _project  # tests/lab is on sys.path (pytest)
from test_efpairs import _fundamental as _f
from scalematch.lab.efpairs import Run, symmetric_epipolar_error
from scalematch.lab.threed import (REFERENCE_PX, ThirdView, ThreedPair, accepted,
                                   benchmark_pairs, candidate_pairs, correct_onto, f_distance,
                                   f_given, fit_reference, markdown, parse_kind, points_given,
                                   read_references, refine_fundamental, row_of,
                                   sampson_residuals, shrink, shrink_map, spread_sample,
                                   summarise, third_views, tracks_of, transfer_errors,
                                   transfer_px)


def _fundamental(p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """F with x2^T F x1 = 0 of two cameras, unit norm."""
    f = _f(p1, p2)
    return f / np.linalg.norm(f)


#: Three cameras around a scene of depths 6 to 10: A at the origin, B to the right and turned
#: with a longer focal, C above and to the left (not on the line AB: transfer works)
P_A = _camera(1000.0, 0.0, [0, 0, 0])
P_B = _camera(1300.0, -10.0, [1.0, 0.1, 0.2])
P_C = _camera(900.0, 12.0, [-0.8, -0.9, 0.3])
SCENE = np.random.default_rng(0).uniform([-2, -1.5, 6], [2, 1.5, 10], (200, 3))
X_A, X_B, X_C = (_project(p, SCENE) for p in (P_A, P_B, P_C))
POINTS = np.hstack([X_A, X_B])
TRACKS = np.hstack([X_A, X_B, X_C])
F_AB, F_AC, F_BC = _fundamental(P_A, P_B), _fundamental(P_A, P_C), _fundamental(P_B, P_C)


def _sampson_error(f, points) -> float:
    r = sampson_residuals(f, points[:, :2], points[:, 2:])
    return float(r @ r)


def test_an_exact_f_scores_zero_everywhere():
    assert np.abs(sampson_residuals(F_AB, X_A, X_B)).max() < 1e-9
    assert symmetric_epipolar_error(F_AB, POINTS) < 1e-9
    assert f_distance(F_AB, -4.0 * F_AB, POINTS) < 1e-9  # scale and sign do not matter
    assert transfer_errors(F_AB, F_AC, F_BC, TRACKS).max() < 1e-6
    assert len(transfer_errors(F_AB, F_AC, F_BC, TRACKS)) > 300  # most crossings kept
    # the wrong convention is far off by every score
    assert symmetric_epipolar_error(F_AB.T, POINTS) > 10
    assert f_distance(F_AB, F_AB.T, POINTS) > 10
    assert np.median(transfer_errors(F_AB.T, F_AC, F_BC, TRACKS)) > 10


def test_a_wrong_f_is_as_far_from_the_right_one_as_from_the_points():
    # F of camera B moved 20 cm up: its distance to the right F over the scene is its error there
    f_off = _fundamental(P_A, _camera(1300.0, -10.0, [1.0, 0.3, 0.2]))
    err = symmetric_epipolar_error(f_off, POINTS)
    assert err > 10
    assert f_distance(F_AB, f_off, POINTS) == pytest.approx(err, rel=0.2)
    assert math.isnan(f_distance(F_AB, None, POINTS))


def test_correct_onto_moves_points_onto_the_f():
    noisy = POINTS + np.random.default_rng(1).normal(0, 2.0, POINTS.shape)
    moved = correct_onto(F_AB, noisy)
    assert symmetric_epipolar_error(F_AB, moved) < 1e-6
    assert np.linalg.norm(moved - noisy, axis=1).mean() < 4.0  # moved little


def test_transfer_through_a_third_view_in_line_with_the_two_is_left_out():
    # C on the line through A and B: every epipolar line in B through A's and C's points meets
    # at B's epipole, the crossings say nothing
    p_c = _camera(900.0, 0.0, [2.0, 0.2, 0.4])
    tracks = np.hstack([X_A, X_B, _project(p_c, SCENE)])
    d = transfer_errors(F_AB, _fundamental(P_A, p_c), _fundamental(P_B, p_c), tracks)
    assert len(d) < 0.2 * 2 * len(SCENE)
    third = ThirdView("c", _fundamental(P_A, p_c), _fundamental(P_B, p_c), tracks[:2])
    assert math.isnan(transfer_px(F_AB, [third]))  # too few tracks
    assert math.isnan(transfer_px(None, [third]))


def test_levenberg_marquardt_lowers_the_sampson_error_of_a_noisy_pair():
    rng = np.random.default_rng(2)
    noisy = POINTS + rng.normal(0, 1.0, POINTS.shape)
    start = F_AB + 2e-3 * rng.normal(size=(3, 3))  # off, and of rank 3
    refined = refine_fundamental(start, noisy[:, :2], noisy[:, 2:])
    assert np.linalg.matrix_rank(refined, tol=1e-9) == 2
    assert np.linalg.norm(refined) == pytest.approx(1.0)
    assert _sampson_error(refined, noisy) < 0.01 * _sampson_error(start, noisy)
    # at the minimum: no lower than the truth's by much more than the fit's 7 parameters
    assert _sampson_error(refined, noisy) <= _sampson_error(F_AB, noisy)
    assert _sampson_error(refined, noisy) > 0.8 * _sampson_error(F_AB, noisy)
    assert f_distance(refined, F_AB, POINTS) < 0.5
    # from the 8-point algorithm's F (already near): lower still
    f8, _ = cv2.findFundamentalMat(noisy[:, :2], noisy[:, 2:], cv2.FM_8POINT)
    assert _sampson_error(refine_fundamental(f8, noisy[:, :2], noisy[:, 2:]),
                          noisy) <= _sampson_error(f8, noisy)
    with pytest.raises(ValueError, match="at least 8"):
        refine_fundamental(F_AB, X_A[:7], X_B[:7])


def test_the_reference_fit_finds_the_f_among_outliers():
    rng = np.random.default_rng(3)
    pts = POINTS + rng.normal(0, 0.15, POINTS.shape)
    bad = rng.uniform(0, 1280, (80, 4))
    a, b = np.vstack([pts[:, :2], bad[:, :2]]), np.vstack([pts[:, 2:], bad[:, 2:]])
    f, inl, magsac, rms0 = fit_reference(a, b, seed=0)
    assert f is not None and magsac >= 150 and math.isfinite(rms0)
    assert inl[:200].mean() > 0.95 and inl[200:].sum() <= 2
    assert symmetric_epipolar_error(f, POINTS) < 0.3
    again = fit_reference(a, b, seed=0)
    assert np.array_equal(again[0], f)  # one seed, one answer
    assert fit_reference(a[:5], b[:5])[0] is None


def test_guided_matching_pairs_the_twins_in_the_band_and_nothing_else():
    rng = np.random.default_rng(4)
    desc = rng.uniform(0, 255, (len(SCENE), 128)).astype(np.float32)
    # A's descriptors, B's the same with noise; then points of A with no twin in B, and near
    # twins of A's descriptors in B far from their lines
    far = X_B + [0.0, 300.0]  # across the lines, which run about along x here
    a = threed.Features(np.vstack([X_A, rng.uniform(0, 1280, (100, 2))]).astype(np.float32),
                        np.vstack([desc, rng.uniform(0, 255, (100, 128))]).astype(np.float32))
    b = threed.Features(np.vstack([X_B, far]).astype(np.float32),
                        np.vstack([desc + rng.normal(0, 2, desc.shape),
                                   desc + rng.normal(0, 1, desc.shape)]).astype(np.float32))
    m = threed.guided_matches(a, b, F_AB, band_px=2.0)
    twins = m[m[:, 0] < len(SCENE)]
    assert len(twins) >= 0.95 * len(SCENE)
    assert np.array_equal(twins[:, 0], twins[:, 1])  # each twin with its twin, not a decoy
    # a point of A with no twin meets a decoy in its band by chance only: 16 nearest of 300
    # descriptors here, of 100 000 in a photo
    assert len(m) - len(twins) <= 0.05 * len(SCENE)
    # without the band the decoys (nearer descriptors) would win
    assert len(threed.guided_matches(a, b, F_AB.T, band_px=2.0)) < 0.1 * len(SCENE)


@pytest.mark.parametrize("kind", ["B/4", "A/3", "photos"])
def test_a_photo_shrunk_keeps_the_geometry_in_its_own_pixels(kind):
    size = (1281, 961)  # odd: each axis shrinks by its own rounded factor
    z_a, z_b = parse_kind(kind)
    s_a, s_b = shrink_map(size, z_a), shrink_map(size, z_b)
    pts = points_given(TRACKS, s_a, s_b)
    assert np.allclose(pts[:, 4:], X_C)  # C unchanged
    w, h = threed.shrunk_size(size, z_b)
    assert np.allclose(pts[:, 2:4], (X_B + 0.5) * [w / 1281, h / 961] - 0.5)
    one = np.eye(3)
    assert symmetric_epipolar_error(f_given(F_AB, s_a, s_b), pts[:, :4]) < 1e-9
    assert transfer_errors(f_given(F_AB, s_a, s_b), f_given(F_AC, s_a, one),
                           f_given(F_BC, s_b, one), pts).max() < 1e-6
    assert shrink(np.zeros((961, 1281), np.float32), z_b).shape == (h, w)


def test_kinds_are_checked():
    for bad in ("C/4", "B/0.5", "B/x", "both"):
        with pytest.raises(ValueError, match="a kind is"):
            parse_kind(bad)


def test_spread_sample_and_tracks():
    xy = np.array([[10.0, 10], [20, 20], [90, 90], [60, 10], [95, 95]])
    keep = spread_sample(xy, np.array([0.4, 0.1, 0.3, 0.2, 0.05]), (100, 100), (2, 2))
    assert keep.tolist() == [1, 3, 4]  # the least residual in each occupied cell, cell order
    assert spread_sample(np.zeros((0, 2)), np.zeros(0), (10, 10)).shape == (0,)
    t = tracks_of(np.array([[0, 0], [1, 1], [2, 2]]), np.array([[0, 7], [2, 8]]),
                  np.array([[0, 7], [2, 9]]))
    assert t.tolist() == [[0, 0, 7]]  # 2: seen as two C points, no track


def test_candidate_pairs_are_the_multiview_scenes_in_a_fixed_order():
    names = ["snowpeak_2.JPG", "deepin_a.jpg", "deepin_b.jpg", "snowpeak_1.JPG",
             "openmvg-360school_1.jpg", "openmvg-360school_2.jpg", "strecha_x-P1_0.jpg",
             "strecha_y-P2_0.jpg", "sceaux_1.JPG"]
    pairs = candidate_pairs(names)
    assert pairs == [("snowpeak_1.JPG", "snowpeak_2.JPG"),
                     ("strecha_x-P1_0.jpg", "strecha_y-P2_0.jpg")]
    assert candidate_pairs(list(reversed(names))) == pairs
    assert third_views(("a", "b"), [("a", "b"), ("c", "a"), ("b", "c")]) == ["c"]


def _doc(drop_bc: bool = False):
    """A reference document of three synthetic views a, b, c (one scene)."""
    def entry(x, y, f, pts, tracks=None):
        return {"label": threed.pair_label(x, y), "a": x, "b": y, "size_a": [1280, 960],
                "size_b": [1280, 960], "matches": 300, "magsac_inliers": 200, "inliers": 200,
                "rms_magsac_px": 0.2, "rms_px": 0.1, "overlap": True,
                "f": f.tolist(), "sample": pts.tolist(), "tracks": tracks or {}}
    ac = np.hstack([X_A, X_C])
    bc = np.hstack([X_B, X_C])
    e_bc = entry("sceaux_b.JPG", "sceaux_c.JPG", F_BC, bc)
    if drop_bc:
        e_bc["overlap"] = False
    return {"pairs": [entry("sceaux_a.JPG", "sceaux_b.JPG", F_AB, POINTS,
                            {"sceaux_c.JPG": TRACKS.tolist()}),
                      entry("sceaux_a.JPG", "sceaux_c.JPG", F_AC, ac), e_bc]}


def test_benchmark_pairs_of_a_document():
    pairs = benchmark_pairs(_doc(), ("photos", "B/4"))
    assert [(p.label, p.kind) for p in pairs] == [
        ("sceaux a~b", "photos"), ("sceaux a~b", "B/4"), ("sceaux a~c", "photos"),
        ("sceaux a~c", "B/4"), ("sceaux b~c", "photos"), ("sceaux b~c", "B/4")]
    ab4 = pairs[1]
    assert ab4.name == "sceaux a~b B/4" and ab4.scene == "sceaux"
    assert symmetric_epipolar_error(ab4.f, ab4.points) < 1e-9
    assert [t.name for t in ab4.thirds] == ["sceaux_c.JPG"]
    assert transfer_px(ab4.f, ab4.thirds) < 1e-6
    again = benchmark_pairs(_doc(), ("photos", "B/4"))  # the same list, point for point
    assert [p.name for p in again] == [p.name for p in pairs]
    assert all(np.array_equal(p.points, q.points) for p, q in zip(pairs, again))
    # a third view counts only when both its references are accepted
    pairs = benchmark_pairs(_doc(drop_bc=True), ("A/4",))
    assert [p.label for p in pairs] == ["sceaux a~b", "sceaux a~c"] and not pairs[0].thirds


def test_rows_summary_and_table_of_a_synthetic_run():
    pair = ThreedPair("sceaux a~b", "sceaux_a.JPG", "sceaux_b.JPG", "photos", F_AB, POINTS,
                      (ThirdView("sceaux_c.JPG", F_AC, F_BC, TRACKS),))
    f_off = _fundamental(P_A, _camera(1300.0, -10.0, [1.0, 0.3, 0.2]))
    rows = [row_of(pair, "A,B", Run("scalematch", F_AB, True, 50, 1.0)),
            row_of(pair, "A,B", Run("sift-magsac", F_AB, True, 60, 2.0)),
            row_of(pair, "B,A", Run("scalematch", None, False, 0, 1.5, reason="no")),
            row_of(pair, "B,A", Run("sift-magsac", f_off, True, 30, 2.0))]
    threed.fill_orders(rows, pair)
    assert rows[0]["solved"] and rows[0]["transfer_px"] < 1e-6
    assert not rows[2]["solved"] and not rows[2]["wrong"] and math.isnan(rows[2]["orders_px"])
    assert rows[3]["wrong"] and rows[3]["orders_px"] > 10 and rows[0]["set"] == "tuning"
    s = {r["method"]: r for r in summarise(rows)}
    assert (s["scalematch"]["solved"], s["scalematch"]["lost_to_sift"]) == (1, 0)
    assert (s["sift-magsac"]["solved"], s["sift-magsac"]["wrong"]) == (1, 1)
    rows[1]["solved"] = rows[2]["solved"] = False
    rows[3]["solved"] = True  # SIFT solves B,A, scalematch does not: lost
    assert {r["method"]: r for r in summarise(rows)}["scalematch"]["lost_to_sift"] == 1
    text = markdown(rows, {"command": "test"})
    assert "| sceaux a~b | tuning | photos | A,B | 0.00 | 50 | 0.00 |" in text
    assert "| sceaux a~b | tuning | photos | B,A | no F | 0 | - | - | 1.5 |" in text


def test_the_stored_references():
    doc = read_references()
    meta = doc["meta"]
    assert meta["command"].startswith("scalematch lab 3d-reference") and meta["commit"]
    assert meta["settings"]["magsac_px"] == REFERENCE_PX
    good = [e for e in doc["pairs"] if accepted(e)]
    assert len(good) == 15  # 16 overlap, one dropped by eye (docs/results/THREED.md)
    for e in good:
        f, pts = np.array(e["f"]), threed.sample_of(e)
        assert e["inliers"] >= threed.MIN_REFERENCE_INLIERS and len(pts) >= 5
        assert np.abs(sampson_residuals(f, pts[:, :2], pts[:, 2:])).max() < REFERENCE_PX
        assert threed.by_eye(e).startswith("accepted")
    labels = {e["label"] for e in doc["pairs"] if e["overlap"]}
    for label in (*threed.BY_EYE_DROPPED, *threed.BY_EYE_DROPPED_POINTS):
        assert label in labels  # every verdict is about a reference there is
    for label, (points, why) in threed.BY_EYE_DROPPED_POINTS.items():
        e = next(e for e in doc["pairs"] if e["label"] == label)
        assert len(threed.sample_of(e)) == len(e["sample"]) - len(points) and why
    labels = [p.name for p in benchmark_pairs(doc)]
    assert labels == [p.name for p in benchmark_pairs(read_references())]  # deterministic
    assert len(labels) == len(set(labels)) == len(good) * len(threed.KINDS)


def test_the_stored_pairs_are_the_candidates_of_the_shared_photos(shared_dir):
    from scalematch.lab.datasets import list_photos

    doc = read_references()
    names = [p.name for p in list_photos(shared_dir)]
    assert [(e["a"], e["b"]) for e in doc["pairs"]] == candidate_pairs(names)


@pytest.mark.shared
def test_a_pair_as_given_has_its_points_inside(shared_dir):
    doc = read_references()
    entry = next(e for e in doc["pairs"] if accepted(e) and e["label"].startswith("sceaux"))
    pair = benchmark_pairs(doc, ("B/4",), [entry["label"]])[0]
    images = threed.load_images(shared_dir / "data" / "photos", pair)
    assert images.a.shape == tuple(entry["size_a"][::-1])
    assert images.b.shape[1] == round(entry["size_b"][0] / 4)
    for img, xy in ((images.a, pair.points[:, :2]), (images.b, pair.points[:, 2:])):
        assert np.all(xy >= -0.5) and np.all(xy < np.array(img.shape[::-1]) - 0.5)


def test_the_commands_check_their_options(tmp_path):
    from scalematch.cli import cli

    runner = CliRunner()
    result = runner.invoke(cli, ["lab", "3d-pairs", "--help"])
    assert result.exit_code == 0 and "--kinds" in result.output
    result = runner.invoke(cli, ["lab", "3d-pairs", "--shared", str(tmp_path)])
    assert result.exit_code == 2 and "data/photos, which is not there" in result.output
    (tmp_path / "data" / "photos").mkdir(parents=True)
    result = runner.invoke(cli, ["lab", "3d-pairs", "--shared", str(tmp_path), "--reference",
                                 str(tmp_path / "none.json")])
    assert result.exit_code == 1 and "3d-reference" in result.output
    stored = tmp_path / "reference.json"
    stored.write_text(json.dumps(_doc()))
    given = ["lab", "3d-pairs", "--shared", str(tmp_path), "--reference", str(stored), "--no-ef"]
    result = runner.invoke(cli, [*given, "--pairs", "nowhere a~b"])
    assert result.exit_code == 2 and "unknown pair" in result.output
    result = runner.invoke(cli, [*given, "--kinds", "B/0.5"])
    assert result.exit_code == 2 and "a kind is" in result.output
    result = runner.invoke(cli, [*given, "--methods", "orb"])
    assert result.exit_code == 2 and "unknown method" in result.output


def test_docstring_examples():
    import doctest

    result = doctest.testmod(threed)
    assert result.failed == 0 and result.attempted >= 10
