"""The match / no-match decision (decision.py): the winner through its tests, the second look."""

from __future__ import annotations

import math

import numpy as np

from scalematch.geometry import similarity_matrix
from scalematch.result import figure
from scalematch.stages.decision import mean_transfer_gap


def test_mean_transfer_gap_of_a_shift_is_the_shift():
    t = similarity_matrix(0.25, 10.0, 100.0, 50.0)
    u = t.copy()
    u[0, 2] += 1.0
    assert mean_transfer_gap(t, u, (480, 640)) == __import__("pytest").approx(1.0)
    assert mean_transfer_gap(t, t, (480, 640)) == 0.0


def test_a_mirror_transform_is_folded_and_a_turn_is_not():
    from scalematch.stages.decision import folded as _folded

    assert _folded(np.array([[-0.5, 0.0, 10.0], [0.0, 0.5, 3.0]]))  # x mirrored
    assert not _folded(np.array([[0.0, -0.5, 10.0], [0.5, 0.0, 3.0]]))  # turned by 90 deg
    assert _folded(np.array([[0.5, 0.0, 1.0], [0.0, -0.5, 2.0], [0.0, 0.0, 1.0]]))


# ------------------------------------------ the second look (docs/design/DECISION.md, test 3)

def _outcomes(k: int, n: int, s: float = 8.0):
    """One scale whose similarity (ratio s) has k inliers among n candidates, and its
    neighbour with nothing: what a footprint 80 low px wide leaves at ratio 8."""
    from scalematch.result import ScaleRow
    from scalematch.search.plan import ScaleOutcome
    from scalematch.stages.estimator import Estimate

    t = similarity_matrix(1.0 / s, 30.0, 400.0, 300.0)
    rng = np.random.default_rng(0)
    src = rng.uniform(0, 640, (n, 2))
    dst = src @ t[:, :2].T + t[:, 2]
    dst[k:] += rng.uniform(20, 200, (n - k, 2))  # the others are far off
    inl = np.arange(n) < k
    est = Estimate("similarity", t, inl, np.where(inl, 0.5, 50.0))
    row = ScaleRow(s=s, ratio=s, points=40, initial=n, kept=n, inliers=k, outlier_pct=0.0)
    empty = ScaleRow(s=s * 1.26, ratio=math.nan, points=20, initial=0, kept=0, inliers=0,
                     outlier_pct=100.0)
    return t, (ScaleOutcome(row, est, src, dst, n),
               ScaleOutcome(empty, None, np.zeros((0, 2)), np.zeros((0, 2)), 0))


def _look(grown: int, margin: float, windows=None, asked=None):
    """A second look that grows to ``grown`` inliers at pixel margin ``margin``, with the
    near windows ``windows`` (a NearWindows) when the decision asks for them below that
    margin; ``asked``, a list, records the margin below which it was asked."""
    from scalematch.stages.secondlook import Look

    def look(t, outcome, windows_below=float("nan")):
        if asked is not None:
            asked.append(windows_below)
        pairs = np.hstack([outcome.src[:1].repeat(grown, 0), outcome.dst[:1].repeat(grown, 0)])
        if windows is not None and margin < windows_below:
            return Look(t, pairs, 0.5, 0.99, margin, 5.0, windows)
        return Look(t, pairs, 0.5, 0.99, margin, 5.0)
    return _Sight(look)


class _Sight:
    """A stand-in for ``secondlook.Sight``: its second look is ``look``; its best placement
    nearby is ``near`` (a ``nearby.Nearby``; None: cannot tell), and ``asked`` records the
    maps it was asked about."""

    def __init__(self, look, near=None):
        from scalematch.stages.nearby import Nearby
        from scalematch.stages.pixelcheck import PixelParams

        self.look = look
        self.pixel = PixelParams()
        self.near = near if near is not None else Nearby(math.nan, math.nan, math.nan, None)
        self.asked = []

    def nearby(self, t):
        self.asked.append(t)
        return self.near


def _params(config):
    """decide's parameters after the shapes, from a Config."""
    from scalematch.stages.decision import SearchContext
    from scalematch.stages.estimator import FitSpec

    fit = FitSpec(config.model, config.ransac, config.seed)
    return dict(params=config.decision, context=SearchContext(fit, config.orientation))


def test_five_inliers_are_refused_without_a_second_look_and_accepted_with_a_good_one():
    from scalematch.config import Config
    from scalematch.stages.decision import decide

    t, outcomes = _outcomes(k=5, n=8)
    config = Config()
    plain = decide(outcomes, (768, 1024), (480, 640), **_params(config))
    assert not plain.matched and "too few inliers: 5" in plain.reason
    good = decide(outcomes, (768, 1024), (480, 640), **_params(config),
                   sight=_look(grown=25, margin=0.3))
    assert good.matched and figure(good.figures, "grown_inliers") == 25
    assert figure(good.figures, "pixel_margin") == 0.3 and good.inliers.shape == (25, 4)


def test_the_pixel_check_or_a_growth_that_fails_refuses_a_few_inlier_hypothesis():
    from scalematch.config import Config
    from scalematch.stages.decision import decide

    _, outcomes = _outcomes(k=5, n=8)
    config = Config()
    for look in (_look(grown=25, margin=0.01), _look(grown=25, margin=float("nan"))):
        verdict = decide(outcomes, (768, 1024), (480, 640), **_params(config), sight=look)
        assert not verdict.matched and "pass the pixel check" in verdict.reason
    # three inliers are never enough, whatever the look says (the evidence is recorded)
    _, three = _outcomes(k=3, n=8)
    verdict = decide(three, (768, 1024), (480, 640), **_params(config),
                   sight=_look(grown=40, margin=0.6))
    assert not verdict.matched and figure(verdict.figures, "grown_inliers") == 40


def test_a_few_inlier_map_the_pixels_place_better_nearby_is_ambiguous():
    """Few inliers cannot tell two placements apart: where a placement an eighth of the
    footprint or more away fits the pixels better than the 5-inlier map, the answer is "no";
    a better placement within that (the same map, a pixel off) or none better changes
    nothing. Maps of ``min_inliers`` or more are not searched around."""
    from scalematch.config import Config
    from scalematch.stages.acontrario import figures
    from scalematch.stages.decision import decide
    from scalematch.stages.nearby import Nearby

    config = Config()
    cases = {  # (moved, best, claimed) -> refused
        (0.30, 0.96, 0.85): True,
        (0.13, 0.90, 0.89): True,
        (0.30, 0.80, 0.85): False,
        (0.05, 0.99, 0.90): False,
        (0.30, float("nan"), float("nan")): False,  # cannot tell
    }
    _, outcomes = _outcomes(k=5, n=8)
    for (moved, best, claimed), refused in cases.items():
        sight = _Sight(_look(grown=25, margin=0.3).look, Nearby(claimed, best, moved, np.eye(3)))
        verdict = decide(outcomes, (768, 1024), (480, 640), **_params(config), sight=sight)
        assert len(sight.asked) == 1 and verdict.matched is not refused, (moved, best, claimed)
        if refused:
            assert verdict.reason.startswith(f"ambiguous: a placement {moved:.0%} of the "
                                             f"footprint away fits the pixels better")
            assert verdict.test == "nearby placement"
            shown = figures(verdict.test, verdict.figures, config.decision)
            assert shown["inliers"] == 5 and shown["pixel_margin"] == 0.3  # the record's
    _, many = _outcomes(k=12, n=20)
    sight = _Sight(_look(grown=25, margin=0.3).look, Nearby(0.5, 0.99, 0.3, np.eye(3)))
    verdict = decide(many, (768, 1024), (480, 640), **_params(config), sight=sight)
    assert verdict.matched and sight.asked == []


def test_an_occluded_few_inlier_map_is_confirmed_by_its_windows_beyond_chance_only():
    """A margin short of ``few_min_margin`` (an occluder sinks the one ZNCC) is made up by the
    windows of the nearby placements (``min_near_windows``, as the final map's), but only in
    the first tier (log10 NFA at most ``few_max_log_nfa``); nearby placements that agree as
    often, or windows too few for their agreement to be beyond chance (2 of 2: 10^-1.2),
    confirm nothing; 7 of 12 with none nearby is beyond it (10^-5.3). The figures are those measured on a true
    occluded map at ratio 8 (37 windows, 0.35 at the map, 0.03 nearby; margin 0.09)."""
    from scalematch.config import Config
    from scalematch.stages.decision import decide
    from scalematch.stages.pixelcheck import NearWindows

    params = Config().decision
    _, strong = _outcomes(k=5, n=8)  # log10 NFA -12.4
    asked = []
    occluded = _look(grown=5, margin=0.09, windows=NearWindows(37, 0.35, 0.03), asked=asked)
    good = decide(strong, (768, 1024), (480, 640), **_params(Config()), sight=occluded)
    assert asked == [params.few_min_margin]
    assert good.matched, good.reason
    assert figure(good.figures, "pixel_windows") == 37
    assert figure(good.figures, "pixel_windows_agreeing") == 0.35
    few = decide(strong, (768, 1024), (480, 640), **_params(Config()),
                 sight=_look(grown=5, margin=0.09, windows=NearWindows(12, 7 / 12, 0.0)))
    assert few.matched, few.reason
    for windows in (NearWindows(37, 0.35, 0.2), NearWindows(2, 1.0, 0.0),
                    NearWindows(37, 0.2, 0.0)):
        verdict = decide(strong, (768, 1024), (480, 640), **_params(Config()),
                         sight=_look(grown=5, margin=0.09, windows=windows))
        assert not verdict.matched and verdict.test == "too few inliers", windows
    _, weak = _outcomes(k=5, n=100)  # log10 NFA -5.0: the windows are not asked for
    asked.clear()
    verdict = decide(weak, (768, 1024), (480, 640), **_params(Config()),
                     sight=_look(grown=5, margin=0.09, windows=NearWindows(37, 0.35, 0.03),
                                asked=asked))
    assert params.few_max_log_nfa < verdict.log10_nfa <= params.max_log_nfa
    assert not verdict.matched and math.isnan(asked[0]) and figure(verdict.figures, "pixel_windows") == 0


def test_an_overhanging_footprint_needs_overwhelming_evidence_or_pixels_that_confirm_it():
    from scalematch.config import Config
    from scalematch.stages.decision import _inside_fraction, decide

    t, outcomes = _outcomes(k=5, n=8)
    coarser = (340, 1024)  # the footprint's lower 62 % hangs below the coarser image
    assert _inside_fraction(t, (480, 640), coarser) < Config().decision.min_inside
    config = Config()
    # a margin no wrong placement reaches (few_clear_margin) confirms the part inside
    clear = decide(outcomes, coarser, (480, 640), **_params(config),
                   sight=_look(grown=5, margin=0.6))
    assert clear.matched and figure(clear.figures, "footprint_inside") < 0.5
    # many inliers but no second look: the footprint test refuses below max_log_nfa_alone
    t, outcomes = _outcomes(k=6, n=100)
    plain = decide(outcomes, coarser, (480, 640), **_params(config))
    assert plain.log10_nfa > config.decision.max_log_nfa_alone
    assert not plain.matched and plain.test == "footprint inside"


def test_a_few_inlier_hypothesis_that_does_not_grow_keeps_its_own_inliers():
    """At coarse scales there may be nothing to grow into: the pixel check alone confirms, and
    the hypothesis keeps its own transform and inliers."""
    from scalematch.config import Config
    from scalematch.stages.decision import decide

    t, outcomes = _outcomes(k=5, n=8)
    verdict = decide(outcomes, (768, 1024), (480, 640), **_params(Config()),
                     sight=_look(grown=0, margin=0.3))
    assert verdict.matched and verdict.inliers.shape == (5, 4)
    assert np.allclose(verdict.transform, t)


def test_a_perspective_map_is_folded_only_where_it_turns_the_image_over(raccoon):
    """Whether a homography folds the high image cannot depend on where the coarser image's
    origin is. The exact truth of a perspective pair (local ratio 2 to 16) shifted by (-3000,
    2000) coarser px is the same map up to a translation: not folded, though its top-left 2x2
    block (its Jacobian only where the map is affine) has a negative determinant there.
    Mirrored, or with the horizon (w = 0) moved into the image, it is folded."""
    from scalematch.lab.synthetic import make_perspective_pair
    from scalematch.stages.decision import folded

    pair = make_perspective_pair(raccoon, 2.0, 8.0, np.random.default_rng(1))
    shifted = np.array([[1.0, 0.0, -3000.0], [0.0, 1.0, 2000.0], [0.0, 0.0, 1.0]]) @ pair.truth
    shifted /= shifted[2, 2]
    assert np.linalg.det(shifted[:2, :2]) < 0  # what the old test read as a mirror
    for h in (pair.truth, shifted, -shifted):
        assert not folded(h, pair.high.shape)
    assert folded(shifted @ np.diag([-1.0, 1.0, 1.0]), pair.high.shape)
    hh, ww = pair.high.shape
    horizon = pair.truth.copy()
    horizon[2] = [2.0 / ww, 0.0, -1.0]  # w = 2x / W - 1: zero across the middle of the image
    assert folded(horizon, pair.high.shape)


# --------------------------------------------------------------- what the candidates show

def _facade(shift, k=60, k2=40):
    """One scale where k candidates fit a similarity and k2 fit the same one shifted by
    ``shift`` (a repeated structure: the copy's candidates) at ratio 2, and a neighbour scale
    that agrees."""
    from scalematch.result import ScaleRow
    from scalematch.search.plan import ScaleOutcome
    from scalematch.stages.estimator import Estimate

    t = similarity_matrix(0.5, 15.0, 300.0, 200.0)
    rng = np.random.default_rng(0)
    src = rng.uniform(0, 640, (k + k2, 2))
    dst = src @ t[:, :2].T + t[:, 2]
    dst[k:] += shift
    inl = np.arange(k + k2) < k
    est = Estimate("similarity", t, inl, np.where(inl, 0.5, 50.0))
    row = ScaleRow(s=2.0, ratio=2.0, points=200, initial=k + k2, kept=k + k2, inliers=k,
                   outlier_pct=40.0)
    near = ScaleRow(s=2.52, ratio=2.0, points=150, initial=k, kept=k, inliers=k // 2,
                    outlier_pct=50.0)
    est2 = Estimate("similarity", t, inl, np.where(inl, 0.5, 50.0))
    return (ScaleOutcome(row, est, src, dst, k + k2), ScaleOutcome(near, est2, src, dst, k))


def test_a_repeated_facade_shows_a_second_transform_and_is_refused_as_ambiguous():
    from scalematch.config import Config
    from scalematch.stages.decision import decide

    verdict = decide(_facade((260.0, 0.0)), (768, 1024), (480, 640), **_params(Config()))
    assert not verdict.matched and verdict.test == "repeated structure"
    assert "second transform" in verdict.reason and "repeated structure" in verdict.reason
    assert figure(verdict.figures, "second_inliers") == 40 and verdict.candidate is not None
    # the same support for a copy only a few px away is one scene fitted piecewise
    near = decide(_facade((6.0, 0.0)), (768, 1024), (480, 640), **_params(Config()))
    assert near.matched and figure(near.figures, "second_inliers") == 40
    # a copy with a fifth of the support is not comparable: the winner stands
    weak = decide(_facade((260.0, 0.0), k2=12), (768, 1024), (480, 640),
                  **_params(Config()))
    assert weak.matched and figure(weak.figures, "second_inliers") == 12


def test_a_footprint_mostly_outside_is_confirmed_by_the_second_look_at_any_count():
    """A transform of 6 inliers (``min_inliers``) whose footprint lies 38 % inside the coarser
    image, beyond chance but not overwhelming (log10 NFA -8.3): refused without pixels, as one
    of 4 or 5 inliers would be; the second look is taken for it too, and its pixels (a margin
    of 0.3) confirm it, while a margin of 0 refuses it."""
    from dataclasses import replace

    from scalematch.config import Config
    from scalematch.stages.decision import decide

    t, (best, _) = _outcomes(k=6, n=80)
    neighbour = replace(best, row=replace(best.row, s=best.row.s * 1.26, inliers=4))
    outcomes = (best, neighbour)
    shapes = ((340, 1024), (480, 640))  # the footprint overhangs the coarser image's bottom
    plain = decide(outcomes, *shapes, **_params(Config()))
    assert not plain.matched and plain.test == "footprint inside", plain.reason
    assert -10 < plain.log10_nfa < -2 and figure(plain.figures, "footprint_inside") < 0.5
    good = decide(outcomes, *shapes, **_params(Config()), sight=_look(grown=6, margin=0.3))
    assert good.matched, good.reason
    assert figure(good.figures, "pixel_margin") == 0.3
    flat = decide(outcomes, *shapes, **_params(Config()), sight=_look(grown=6, margin=0.0))
    assert not flat.matched and flat.test == "footprint inside"


def test_a_refused_epipolar_geometry_says_the_figures_its_record_gives():
    """Matches sharing a point count once for an epipolar geometry: the reason gives that count
    and the matches it stands for (``rejected.n_inliers``), and a count too small to be beyond
    chance in words, not as "log10 NFA inf" (null in the JSON)."""
    from scalematch.config import Config
    from scalematch.result import ScaleRow
    from scalematch.search.plan import ScaleOutcome
    from scalematch.stages.decision import decide
    from scalematch.stages.estimator import Estimate

    rng = np.random.default_rng(3)
    src = rng.uniform(0, 400, (40, 2))
    dst = rng.uniform(0, 400, (40, 2))
    dst[1:3] = dst[0]  # three finer points matched to one coarser point
    inl = np.arange(40) < 9
    est = Estimate("fundamental", np.eye(3), inl, np.where(inl, 0.5, 50.0))
    row = ScaleRow(s=1.0, ratio=math.nan, points=40, initial=40, kept=40, inliers=9,
                   outlier_pct=77.5)
    config = Config(model="fundamental")
    d = decide([ScaleOutcome(row, est, src, dst, 40)], (480, 640), (480, 640),
               **_params(config))
    assert not d.matched and d.test == "chance"
    assert "7 inliers counted one to one (9 matches) of 40 candidates" in d.reason
    assert "inf" not in d.reason and "none beyond chance" in d.reason
    assert d.counted == 7 and len(d.candidate_inliers) == 9
