"""Real data from ../shared (skipped when absent): the boat zoom sequence and real photos.

Known answers: boat img1 -> imgN with the published homographies (1->6 is left out: every
method, SIFT included, is 5-6 px from that reference, see docs/results/BOAT.md); synthetic pairs
cut from real photos by the EVALUATION.md protocol; unrelated pairs must not be claimed.
"""

from __future__ import annotations

import numpy as np
import pytest

from scalematch import Config, match
from scalematch.lab.datasets import boat_pairs, list_photos, load_photo, scene_of
from scalematch.lab.evaluation import reprojection_error
from scalematch.lab.synthetic import (make_tilted_pair, make_unrelated_pair, pair_rng,
                                      pairs_from_photos)

#: photos of different scenes (architecture, aerial, texture) used below
PHOTOS = ("opensfm-berlin_01.jpg", "snowpeak_IMG_2280.JPG", "monstree_IMG_1042.JPG")


def test_boat_sequence_with_the_homography_model(shared_dir):
    pairs = [p for p in boat_pairs(shared_dir) if not p[3].endswith("6")]
    assert len(pairs) == 4
    for low, high, truth, name in pairs:
        r = match(low, high, Config(model="homography"))
        assert r.matched, f"{name}: {r.reason}"
        err = reprojection_error(r.transform, truth, high.shape, low.shape)
        assert err < 1.5, f"{name}: {err:.2f} px"  # measured 0.10 to 0.78 px


@pytest.mark.parametrize("ratio", [4.0, 8.0])
def test_synthetic_pairs_from_real_photos(shared_dir, ratio):
    paths = [p for p in list_photos(shared_dir) if p.name in PHOTOS]
    assert len(paths) == len(PHOTOS)
    for pair in pairs_from_photos(paths, [ratio], seed=0):
        r = match(pair.low, pair.high)
        err = reprojection_error(r.transform if r.matched else None, pair.truth, pair.high.shape,
                                 pair.low.shape)
        assert err < 3.0, f"{pair.source} x{ratio}: {r.reason or f'{err:.2f} px'}"


def test_unrelated_real_photos_are_not_claimed(shared_dir):
    paths = list_photos(shared_dir)
    rng = np.random.default_rng(0)
    for k in range(4):
        a, b = rng.choice(len(paths), 2, replace=False)
        if scene_of(paths[a].name) == scene_of(paths[b].name):
            continue
        pair = make_unrelated_pair(load_photo(paths[a]), load_photo(paths[b]), 4.0, rng)
        r = match(pair.low, pair.high)
        assert not r.matched, f"{paths[a].name} vs {paths[b].name}: claimed {r.resolution_ratio}"


def test_a_repeated_facade_seen_obliquely_is_not_a_wrong_similarity(shared_dir):
    # measured in the real-pair benchmark: the plain search matched a repeated pattern with a
    # similarity of 6 inliers, all 47-69 px off (log10 NFA -12.6); a weak plain match must
    # face the first pass of tilted views, which finds the truth
    name = "openmvg-360school_R0010939.jpg"
    pair = make_tilted_pair(load_photo(shared_dir / "data" / "photos" / name), 2.0, 2.83,
                            pair_rng(0, f"{name} tilt 2.83", 2.0), source=name)
    r = match(pair.low, pair.high)
    assert r.matched, r.reason
    assert reprojection_error(r.transform, pair.truth, pair.high.shape, pair.low.shape) < 3.0
    # without views the plain search alone finds the right affine map too (measured 0.39 px,
    # uniqueness ratio 76): its probe, counting distinct point pairs, no longer sends it to
    # the facade's scale, and the facade's similarity is not what it answers
    plain = match(pair.low, pair.high, Config.preset("no-views"))
    assert plain.matched, plain.reason
    assert reprojection_error(plain.transform, pair.truth, pair.high.shape, pair.low.shape) < 3.0


def test_a_smooth_crop_s_tilted_view_does_not_outvote_the_right_plain_match(shared_dir):
    """The hard set (least textured crop) at ratio 3: a t = 2 view's affine map of 11 inliers
    out of 12 candidates (log10 NFA -43) was 48.5 px off and outvoted the plain similarity,
    right, of 11 inliers. Among several matches the final map that fits the pixels best wins
    (ZNCC 0.995 against 0.963): answered at 0.24 px."""
    name = "popos_jad-limcaco-183877.jpg"
    pair = next(pairs_from_photos([shared_dir / "data" / "photos" / name], [3.0], 0, pick="least"))
    r = match(pair.low, pair.high)
    assert r.matched, r.reason
    assert reprojection_error(r.transform, pair.truth, pair.high.shape, pair.low.shape) < 1.0


def test_a_steep_view_whose_refit_map_fits_no_better_than_its_neighbours_is_refused(shared_dir):
    """A tilted zoom pair at t = 5.66 (directional ratios 2 and 11): a t = 4 view gave an
    affine map of 9 inliers at log10 NFA -19, 47 px off; its final pixel check sits below its
    shifted and turned neighbours (margin -0.011, true claims 0.035 and above), so the answer
    is "no reliable match", not a wrong transform. The uniqueness test, which runs first, also
    refuses it (misfit ratio 1.83, below 2): ``rejected`` names a pixel test."""
    name = "openmvg-360school_R0010939.jpg"
    pair = make_tilted_pair(load_photo(shared_dir / "data" / "photos" / name), 2.0, 5.66,
                            pair_rng(0, f"{name} tilt 5.66", 2.0), source=name)
    r = match(pair.low, pair.high)
    if r.matched:
        assert reprojection_error(r.transform, pair.truth, pair.high.shape,
                                  pair.low.shape) < 3.0
    else:
        assert r.rejected is not None and r.rejected.test in ("uniqueness", "pixels"), r.reason
        assert r.evidence.final_margin < 0.0


def test_oxford_viewpoint_pairs_both_ways(shared_dir):
    from scalematch.lab.realpairs import canonical, oxford_pairs, pair_error

    pairs = [p for p in oxford_pairs(shared_dir) if p.name in ("graf 1->3", "graf 3->1",
                                                                "wall 1->4", "wall 4->1")]
    assert len(pairs) == 4
    for p in pairs:
        r = match(p.low, p.high, Config(model="homography"))
        assert r.matched, f"{p.name}: {r.reason}"
        err = pair_error(p, canonical(p, r.transform, r.order == "given"))
        assert err < 3.0, f"{p.name}: {err:.2f} px"  # measured 0.7 to 1.8 px


def test_graf_1_6_both_ways_with_the_homography_model(shared_dir):
    """About 60 degrees of viewpoint change, solved through a t = 4 view once a
    homography's ratio is taken where its inliers are (geometry.ratio_at: 0.95 there, 0.57 at
    the view's origin, which the scale test refused). Measured 0.93 px both ways."""
    from scalematch.geometry import ratio_at
    from scalematch.lab.realpairs import canonical, oxford_pairs, pair_error

    pairs = [p for p in oxford_pairs(shared_dir) if p.name in ("graf 1->6", "graf 6->1")]
    assert len(pairs) == 2
    for p in pairs:
        r = match(p.low, p.high, Config(model="homography"))
        assert r.matched, f"{p.name}: {r.reason}"
        assert r.evidence.view_tilt > 1  # a tilted view found it
        err = pair_error(p, canonical(p, r.transform, r.order == "given"))
        assert err < 3.0, f"{p.name}: {err:.2f} px"
        # the ratio reported is the map's where the inliers are (geometry.answer_parts), as the
        # published homography has it there: measured 1.895 against 1.890 (at img1's origin the
        # answer's ratio is 1.14)
        finer_is_img1 = (p.name == "graf 1->6") == (r.order == "given")
        truth = p.truth if finer_is_img1 else np.linalg.inv(p.truth)
        want = ratio_at(truth, r.inliers[:, :2].mean(axis=0))
        assert abs(r.resolution_ratio / want - 1) < 0.03, (r.resolution_ratio, want)


def test_a_plane_seen_in_perspective_is_not_said_to_show_parallax(shared_dir):
    """Oxford wall 1 -> 3 and graf 1 -> 2 (planar scenes, viewpoint changes): the scale's
    similarity leaves true matches off it that an epipolar geometry explains (1598 and 551);
    parallax is counted against the answer's own map, a homography that holds them."""
    from scalematch.imageio import read_grey

    for scene, other in (("wall", 3), ("graf", 2)):
        folder = shared_dir / "data" / "oxford" / scene
        r = match(read_grey(folder / "img1.png"), read_grey(folder / f"img{other}.png"))
        assert r.matched and r.model == "homography", r.reason
        assert not r.evidence.parallax and r.evidence.parallax_points < 10, scene
