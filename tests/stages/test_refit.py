"""refit: the richer maps offered to the pixels (perspective pairs), guided growth and the pin
test on fabricated outcomes and points with a known map."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from scalematch.config import Config
from scalematch.geometry import apply
from scalematch.result import ScaleRow
from scalematch.search.plan import ScaleOutcome
from scalematch.stages.descriptors import Described
from scalematch.stages.estimator import Estimate, FitSpec, estimate
from scalematch.stages.guided import GuidedParams
from scalematch.stages.refit import Fit, guided_refit, richer_fits
from scalematch.stages.views import identity_view

#: a perspective map of a 640x480 high image: the local ratio grows about 4x across it
PERSPECTIVE = np.array([[0.30, 0.02, 400.0], [-0.01, 0.28, 300.0], [6e-4, 1e-5, 1.0]])


def _outcomes(truth: np.ndarray, bands, n: int = 40, outliers: int = 10, seed: int = 0):
    """One outcome per x band of the high image: ``n`` exact pairs of ``truth`` in the band
    and ``outliers`` random pairs (as a scale of a perspective pair sees its own band)."""
    rng = np.random.default_rng(seed)
    out = []
    for x0, x1 in bands:
        src = np.column_stack([rng.uniform(x0, x1, n), rng.uniform(0, 479, n)])
        dst = apply(truth, src)
        src = np.vstack([src, rng.uniform(0, 479, (outliers, 2))])
        dst = np.vstack([dst, rng.uniform(0, 600, (outliers, 2))])
        row = ScaleRow(s=2.0, ratio=3.0, points=n, initial=n, kept=n, inliers=n, outlier_pct=0.0)
        est = Estimate("similarity", np.eye(3)[:2], np.ones(len(src), bool), np.zeros(len(src)))
        out.append(ScaleOutcome(row, est, src, dst, len(src)))
    return out


def _similarity_on(outcome, config):
    """The similarity the winning scale alone would give: fitted to its own band."""
    est = estimate("similarity", outcome.src, outcome.dst, config.ransac, seed=0)
    inl = est.inliers
    return Fit(est.transform, np.hstack([outcome.src[inl], outcome.dst[inl]]), "similarity")


def _grid_error(t: np.ndarray, truth: np.ndarray) -> float:
    xy = np.stack(np.meshgrid(np.linspace(0, 639, 9), np.linspace(0, 479, 7)), -1).reshape(-1, 2)
    return float(np.max(np.linalg.norm(apply(t, xy) - apply(truth, xy), axis=1)))


def _richer(fit, outcomes, config):
    """:func:`richer_fits` of ``fit`` on a 640x480 finer image, the middle scale winning."""
    return richer_fits(fit, identity_view(np.zeros((480, 640))), outcomes[1], outcomes,
                       config.model_check, FitSpec(config.model, config.ransac, config.seed))


def test_the_richer_maps_include_the_homography_of_every_scale():
    """Three scales each match a third of the footprint; the middle one's similarity is tens
    of px off at the ends. Among the richer maps offered to the pixels, the homography fitted
    to all three scales' candidates is exact (within 0.1 px)."""
    config = Config()
    outcomes = _outcomes(PERSPECTIVE, [(0, 213), (213, 426), (426, 639)])
    fit = _similarity_on(outcomes[1], config)
    assert _grid_error(fit[0], PERSPECTIVE) > 10
    options = [r.fit for r in _richer(fit, outcomes, config)]
    assert sorted({o.model for o in options}) == ["affine", "homography"]
    errors = [_grid_error(o.transform, PERSPECTIVE) for o in options if o.model == "homography"]
    assert min(errors) < 0.1
    assert max(len(o.inliers) for o in options) >= 110


@pytest.mark.parametrize("check,models", [
    (replace(Config().model_check, union=False), {"affine", "homography"}),
    (replace(Config().model_check, models=("affine",)), {"affine"}),
    (replace(Config().model_check, models=()), set()),
], ids=["union off", "affine only", "no richer model"])
def test_the_richer_maps_are_the_model_checks_own(check, models):
    """Only the models of the model check are offered; with ``union`` off, fitted to the
    winning scale's candidates alone (which hold a third of the perspective: none exact)."""
    outcomes = _outcomes(PERSPECTIVE, [(0, 213), (213, 426), (426, 639)])
    fit = _similarity_on(outcomes[1], Config())
    options = [r.fit for r in _richer(fit, outcomes, replace(Config(), model_check=check))]
    assert {o.model for o in options} == models
    assert len(options) == len(models) * (1 if not check.union else 2)


def test_a_homography_is_offered_nothing_richer():
    outcomes = _outcomes(PERSPECTIVE, [(0, 213), (213, 426), (426, 639)])
    fit = Fit(PERSPECTIVE, np.zeros((0, 4)), "homography")
    assert _richer(fit, outcomes, Config()) == []


def test_a_match_on_a_view_of_the_coarser_image_is_refit_in_its_own_pixels():
    """Candidates found against a view of the coarser image (compressed by 4 at
    longitude 30) are mapped back through the view and refit: the answer is the true affine map
    from finer px to coarser px to 1e-3 px (the estimator works in float32), though the view's
    own similarity could not hold it."""
    from scalematch.geometry import compose
    from scalematch.stages.acontrario import Decision
    from scalematch.stages.refit import refit_in_high
    from scalematch.stages.views import tilt_view

    coarse = np.zeros((300, 400), np.float32)
    view = tilt_view(coarse, 4.0, 30.0)
    rng = np.random.default_rng(5)
    truth = np.array([[0.9, -0.8, 120.0], [0.5, 1.2, 40.0]])  # finer px -> coarser px
    src = rng.uniform(0, 200, (40, 2))
    dst = apply(compose(view.to_view, truth), src)  # in the view's px
    row = ScaleRow(s=1.0, ratio=1.0, points=40, initial=40, kept=40, inliers=40, outlier_pct=0.0)
    est = Estimate("similarity", np.eye(3)[:2], np.ones(len(src), bool), np.zeros(len(src)))
    best = ScaleOutcome(row, est, src, dst, len(src))
    t_view = estimate("affine", src, dst, Config().ransac).transform
    verdict = Decision(True, "", 1.0, t_view, np.hstack([src, dst]))
    t, inliers, model = refit_in_high(identity_view(np.zeros((200, 200), np.float32)), verdict,
                                      best, FitSpec("similarity", Config().ransac, 0),
                                      coarser=view)
    assert model == "affine" and len(inliers) == 40
    assert np.abs(apply(t, src) - apply(truth, src)).max() < 1e-3
    assert np.abs(inliers[:, 2:4] - apply(truth, src)).max() < 1e-3


def _described(xy: np.ndarray, desc: np.ndarray, s: float = 1.0) -> Described:
    return Described(s=s, xy=np.asarray(xy, np.float64), index=np.arange(len(xy)),
                     angle=np.zeros(len(xy)), desc=desc.astype(np.float32))


def _scene(truth: np.ndarray, n: int = 300, seed: int = 0):
    """Finer points over a 640x480 image and their coarser partners under ``truth``, with the
    same unit descriptors, among as many unrelated coarser points."""
    rng = np.random.default_rng(seed)
    xy = np.column_stack([rng.uniform(0, 639, n), rng.uniform(0, 479, n)])
    desc = rng.normal(size=(n, 32))
    desc /= np.linalg.norm(desc, axis=1, keepdims=True)
    other = rng.normal(size=(n, 32))
    other /= np.linalg.norm(other, axis=1, keepdims=True)
    low_xy = np.vstack([apply(truth, xy), rng.uniform(0, 800, (n, 2))])
    return _described(xy, desc), _described(low_xy, np.vstack([desc, other]))


def _scale(described: Described):
    row = ScaleRow(s=1.0, ratio=1.0, points=len(described), initial=0, kept=0, inliers=0,
                   outlier_pct=0.0)
    est = Estimate("homography", np.eye(3), np.zeros(0, bool), np.zeros(0))
    return ScaleOutcome(row, est, np.zeros((0, 2)), np.zeros((0, 2)), 0, described)


def test_guided_refit_pins_a_loose_homography_over_the_whole_footprint():
    """A homography fitted to 8 noisy pairs in one corner is px off at the far corners; the
    guided matches it predicts over the whole image make it exact."""
    high, low = _scene(PERSPECTIVE)
    rng = np.random.default_rng(1)
    corner = np.nonzero((high.xy[:, 0] < 200) & (high.xy[:, 1] < 150))[0][:8]
    src = high.xy[corner]
    dst = apply(PERSPECTIVE, src) + rng.normal(0, 0.5, (len(corner), 2))
    loose = estimate("homography", src, dst, Config().ransac, seed=0).transform
    assert _grid_error(loose, PERSPECTIVE) > 2
    fit = (loose, np.hstack([src, dst]), "homography")
    t, inliers, model = guided_refit(fit, (480, 640), [_scale(high)], low, GuidedParams(),
                                     FitSpec("homography", Config().ransac))
    assert model == "homography" and len(inliers) >= 290
    assert _grid_error(t, PERSPECTIVE) < 0.05


#: a milder perspective: the local ratio changes by about a third across the image
MILD = np.array([[0.5, 0.01, 100.0], [-0.005, 0.48, 80.0], [2e-4, 2e-5, 1.0]])


def test_guided_refit_turns_a_similarity_into_the_homography_its_matches_show():
    """A similarity fitted in the middle band of a perspective map holds near that band; a
    homography fitted to its guided matches grows over the whole image (the model check)."""
    high, low = _scene(MILD)
    band = np.nonzero((high.xy[:, 0] > 260) & (high.xy[:, 0] < 380))[0]
    src, dst = high.xy[band], apply(MILD, high.xy[band])
    est = estimate("similarity", src, dst, Config().ransac, seed=0)
    fit = (est.transform, np.hstack([src[est.inliers], dst[est.inliers]]), "similarity")
    config = Config()
    t, inliers, model = guided_refit(fit, (480, 640), [_scale(high)], low, GuidedParams(),
                                     FitSpec("similarity", config.ransac),
                                     check=config.model_check)
    assert model == "homography"
    assert _grid_error(t, MILD) < 0.05


def test_guided_refit_keeps_a_fit_that_nothing_grows():
    """Coarser points unrelated to the finer ones: no guided match, the fit is returned as is."""
    high, _ = _scene(PERSPECTIVE)
    _, low = _scene(PERSPECTIVE, seed=5)  # other descriptors everywhere
    fit = (PERSPECTIVE, np.zeros((0, 4)), "homography")
    t, inliers, model = guided_refit(fit, (480, 640), [_scale(high)], low, GuidedParams(),
                                     FitSpec("homography", Config().ransac))
    assert t is PERSPECTIVE and model == "homography" and len(inliers) == 0


# ------------------------------------------------------------------------- pinned_model
#: a ratio-16 similarity of a 640x480 finer image (footprint 40x30 coarser px), as a homography
ZOOM16 = np.array([[0.0625, 0.0, 300.0], [0.0, 0.0625, 200.0], [0.0, 0.0, 1.0]])
SHAPES = ((480, 640), (768, 1024))  #: the finer and the coarser image, (H, W)


def _noisy_pairs(truth: np.ndarray, lo, hi, n: int, noise: float, seed: int) -> np.ndarray:
    """(n, 4) pairs of ``truth`` from finer points uniform in the box ``lo``..``hi``, the
    coarser points with Gaussian noise of std ``noise`` px."""
    rng = np.random.default_rng(seed)
    src = rng.uniform(lo, hi, (n, 2))
    return np.hstack([src, apply(truth, src) + rng.normal(0.0, noise, (n, 2))])


def _homography_of(pairs: np.ndarray):
    est = estimate("homography", pairs[:, :2], pairs[:, 2:], Config().ransac, seed=0)
    return est.transform, pairs[est.inliers], "homography"


def _pinned(fit, config: Config = Config()):
    from scalematch.stages.refit import pinned_model

    return pinned_model(fit, *SHAPES, config.pin, FitSpec("homography", config.ransac, 0))


def test_a_homography_its_crowded_inliers_do_not_pin_gives_way_to_a_simpler_model():
    """30 pairs of a ratio-16 zoom, 0.4 px of noise, crowded in a 200x150 corner of the finer
    image: the homography fitted to them leaves its far corners free (expected grid error 1.7
    px, 4.4 px off); the affine map fitted to the same pairs is pinned (0.6 px) and answers,
    0.3 px off."""
    fit = _homography_of(_noisy_pairs(ZOOM16, (0, 0), (199, 149), 30, 0.4, seed=1))
    assert _grid_error(fit[0], ZOOM16) > 3.0
    (t, inliers, model), pinned = _pinned(fit)
    tolerance = Config().pin.tolerance_px
    assert model == "affine" and pinned.refused == "homography"
    assert pinned.refused_px > 1.5 * tolerance and pinned.error_px < 0.7 * tolerance
    assert len(inliers) == len(fit[1])
    assert _grid_error(t, ZOOM16) < 1.0


def test_a_homography_pinned_over_the_whole_image_is_kept():
    fit = _homography_of(_noisy_pairs(ZOOM16, (0, 0), (639, 479), 30, 0.4, seed=1))
    (t, _, model), pinned = _pinned(fit)
    assert model == "homography" and t is fit[0]
    assert pinned.refused == "" and pinned.error_px < 0.5 * Config().pin.tolerance_px


def test_a_perspective_no_simpler_model_follows_keeps_its_homography():
    """20 pairs of a strong perspective with 1 px of noise in the left third of the finer image:
    the homography is loose (expected error 1.9 px), but an affine map fitted to its inliers
    is loose by its misfit too (1.9 px, and 5.6 px off where the homography is 0.8): the
    homography stays, as fitted."""
    fit = _homography_of(_noisy_pairs(PERSPECTIVE, (0, 0), (213, 479), 20, 1.0, seed=0))
    (t, inliers, model), pinned = _pinned(fit)
    assert model == "homography" and t is fit[0] and inliers is fit[1]
    assert pinned.refused == "" and pinned.error_px > 1.5 * Config().pin.tolerance_px


def test_the_pin_test_off_or_a_similarity_answers_as_fitted():
    crowded = _noisy_pairs(ZOOM16, (0, 0), (199, 149), 30, 0.4, seed=1)
    fit = _homography_of(crowded)
    off = Config(pin=replace(Config().pin, enabled=False))
    assert _pinned(fit, off)[0] is fit
    similarity = estimate("similarity", crowded[:, :2], crowded[:, 2:], Config().ransac)
    fit = (similarity.transform, crowded, "similarity")
    assert _pinned(fit)[0] is fit


def test_the_pin_figures_are_given_in_the_coarser_images_own_px():
    from scalematch.stages.refit import Pinned

    figures = Pinned(0.5, "homography", 2.0).figures(factor=2.0)
    assert figures == {"pin_px": 1.0, "unpinned_model": "homography", "unpinned_px": 4.0}
    # none refused: the one NaN object, so that two evidences of one answer compare equal
    assert Pinned(0.5).figures(factor=2.0)["unpinned_px"] is math.nan


def test_vouching_only_the_maps_that_can_count_chooses_as_vouching_every_one():
    """``allowed_maps`` asks ``vouch`` of as few maps as it can; the map chosen is the one
    chosen when every map the pixels ask for is vouched for first (500 random draws of five
    maps: ZNCC, which the counts allow, which the pixels ask for, which the windows vouch)."""
    from scalematch.stages.refit import allowed_maps, chosen_model

    rng = np.random.default_rng(0)
    models = ["similarity", "affine", "homography", "affine", "homography"]
    asked = needed = 0
    for _ in range(500):
        nccs = list(np.round(rng.uniform(0, 1, 5), 2))
        counted = [True] + list(rng.random(4) < 0.3)
        pixels = [False] + [n >= nccs[0] + 0.05 for n in nccs[1:]]
        ok = rng.random(5) < 0.6
        eager = [True] + [c or (p and bool(v)) for c, p, v in
                          zip(counted[1:], pixels[1:], ok[1:])]
        calls = []
        lazy = allowed_maps(nccs, counted, pixels, lambda k: calls.append(k) or bool(ok[k]), 0.05)
        assert chosen_model(nccs, models, lazy, 0.05) == chosen_model(nccs, models, eager, 0.05)
        every = sum(1 for c, p in zip(counted[1:], pixels[1:]) if p and not c)
        assert len(calls) <= every
        asked, needed = asked + len(calls), needed + every
    assert asked < needed
