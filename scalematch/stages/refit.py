"""After the decision: the winning search's transform refit in the finer image's own pixels.

Six refinements, in this order, each keeping the answer unless the evidence says otherwise:

1. :func:`refit_in_high`: a match found on a simulated tilted view (of the finer image, or of
   the coarser one) is refit in the images' own pixels (the view's similarity composed with the
   view's compression is an affine map).
2. :func:`richer_model`: a similarity that explains clearly fewer candidates than an affine map
   or a homography gives way to it (``ModelCheckParams``).
3. :func:`pooled_refit`: the transform refined on the candidates of every scale matched in full.
4. :func:`union_homography`: a homography fitted afresh to those pooled candidates replaces an
   answer that explains clearly fewer of them (perspective: each scale matches the part of the
   footprint at its own local ratio, so only the union sees the whole of it;
   docs/design/VIEWS.md, "Perspective pairs").
5. :func:`guided_refit`, once the answer is accepted (``answer.grown_answer``): the paper's
   step (iv), "establish many other matches once this matrix is known": every described point
   of every scale matched in full is predicted by the answer and matched among the coarser
   points near its prediction (guided matching, :mod:`scalematch.stages.guided`); the answer
   is refit on those matches while they grow. Matches spread over the whole footprint pin
   down the parts the winning scale's inliers leave loose (a homography's far corners).
6. :func:`pinned_model`, last: a map whose inliers leave it free to err by more than the
   claim's tolerance (:func:`scalematch.stages.pinning.expected_error`) gives way to the next
   simpler model fitted to the same inliers that they pin down.

Each takes the winning scale's outcome (``best``: its candidates ``src`` -> ``dst``) or all the
outcomes of the winning search, and returns ``(transform, inliers (N, 4), model)``. A search
matched against a view of the coarser image (``coarser``, a :class:`View`; None: the image
itself) has its ``dst`` in that view's pixels: each function maps them back first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Dict, Mapping, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from ..checks import Bounds, COUNT, FACTOR, check_bounds, one_of
from ..geometry import compose, invert
from .acontrario import Decision
from .decision import folded
from .descriptors import Described
from .estimator import (MIN_SAMPLE, MODELS, FitSpec, RansacParams, estimate, model_of, refine,
                        residuals)
from .guided import GuidedParams, Points, grow_rounds, guided_pool
from .matcher import distinct_pairs
from .pinning import PinParams, expected_error
from .views import View, to_high


@dataclass(frozen=True)
class ModelCheckParams:
    """A similarity answer is checked against richer models on the same candidates.

    A viewpoint change (tilt, perspective) makes a similarity hold on part of the image only:
    measured on graf, wall and tilted zoom pairs (docs/BENCHMARKS.md), the best similarity was
    tens of px off away from its inliers. When an affine map or a homography fitted to the
    winning scale's candidates explains clearly more of them, that model is reported instead
    (``MatchResult.model`` says which); on plain zoom pairs the similarity is exact and stays.
    """

    enabled: bool = True  #: False: the similarity is always the answer when asked for
    models: Tuple[str, ...] = ("affine", "homography")  #: tried in this order (simplest first)
    #: a richer model is taken when its inliers reach ``min_gain`` x the similarity's and at
    #: least ``min_extra`` more (a model with more freedom always fits a few more by chance)
    min_gain: float = 1.25
    min_extra: int = 10
    #: pool the candidates of every scale matched in full and fit a homography to them afresh
    #: (:func:`union_homography`, same ``min_gain`` and ``min_extra``): on perspective zoom pairs
    #: whose local ratio spans 4x across the footprint the winning scale sees one band of it,
    #: and its similarity was 4.6-6.8 px off at the far ends (docs/design/VIEWS.md,
    #: "Perspective pairs")
    union: bool = True

    def clearly_more(self, n: int, k: int) -> bool:
        """Whether ``n`` inliers of a richer model clearly beat ``k`` of the simpler one
        (``min_gain`` times as many and ``min_extra`` more).

        >>> ModelCheckParams().clearly_more(28, 20), ModelCheckParams().clearly_more(60, 40)
        (False, True)
        """
        return n >= self.min_gain * k and n - k >= self.min_extra

    #: each number's range, checked when the parameters are made (``checks.check_bounds``)
    BOUNDS: ClassVar[Mapping[str, Bounds]] = {
        "min_gain": FACTOR,
        "min_extra": COUNT,
    }

    def __post_init__(self) -> None:
        check_bounds("model_check", self, self.BOUNDS)
        for name in self.models:
            one_of("model_check", "models", name, MODELS)


class Fit(NamedTuple):
    """A map and what supports it, at one stage of the answer (found, refit, grown, pinned)."""

    transform: np.ndarray  #: finer px -> coarser px: (2, 3), or (3, 3) for a homography or F
    inliers: np.ndarray  #: (N, 4) x, y finer; x, y coarser
    model: str  #: the model of ``transform`` (``Config.model``'s names)


def _back(view: Optional[View], xy: np.ndarray) -> np.ndarray:
    """Points of a view (N, 2) in its image's pixels (None: the image itself)."""
    return xy if view is None else to_high(view, xy)


def candidates_in_images(view: View, best, coarser: Optional[View] = None
                         ) -> Tuple[np.ndarray, np.ndarray]:
    """(src, dst): every candidate of a winning scale ``best`` in the images' own pixels (the
    finer image's, through ``view``; the coarser image's, through ``coarser`` or as they are)."""
    return to_high(view, best.src), _back(coarser, best.dst)


def refit_in_high(view: View, verdict: Decision, best, spec: FitSpec,
                  coarser: Optional[View] = None) -> Fit:
    """The winning view's match in the images' own pixels.

    The view's similarity composed with the views' compressions is an affine map; it is refit
    on the inliers mapped back to the images (an affine map, or a homography when that is
    the model asked for, ``spec.model``), so the answer is exact rather than limited to the
    sampled tilts. ``spec``: also the robust fit's parameters and the one seed.
    """
    asked, ransac, seed = spec.model, spec.ransac, spec.seed
    if view.is_identity and coarser is None:
        return Fit(verdict.transform, verdict.inliers, asked)
    src = to_high(view, verdict.inliers[:, :2])
    dst = _back(coarser, verdict.inliers[:, 2:4])
    model = "homography" if asked == "homography" else "affine"
    # every candidate of the winning scale, not only the view's similarity inliers: the sampled
    # tilt differs from the true one, so the similarity holds on part of the image only
    cand_src, cand_dst = candidates_in_images(view, best, coarser)
    est = estimate(model, cand_src, cand_dst, ransac, seed=seed)
    if est.transform is not None and est.n_inliers >= len(src):
        return Fit(est.transform, np.hstack([cand_src[est.inliers], cand_dst[est.inliers]]), model)
    est = estimate(model, src, dst, ransac, seed=seed)
    if est.transform is None or est.n_inliers < MIN_SAMPLE[model] + 1:
        composed = compose(verdict.transform, view.to_view)
        if coarser is not None:
            composed = compose(invert(coarser.to_view), composed)
        return Fit(composed, np.hstack([src, dst]),
                   "affine" if composed.shape == (2, 3) else model)
    inl = est.inliers
    return Fit(est.transform, np.hstack([src[inl], dst[inl]]), model)


def richer_model(fit: Fit, view: View, best, check: ModelCheckParams, ransac: RansacParams,
                 seed: int) -> Fit:
    """A richer model when the similarity explains too little of the winning scale.

    The candidates of the winning scale are refit with each of ``check.models``;
    the first whose inliers pass ``min_gain`` and ``min_extra`` over the similarity's, and
    whose transform does not fold the image over, is taken (see ``ModelCheckParams``).
    """
    t, inliers, model = fit
    if not check.enabled or model != "similarity" or not view.is_identity:
        return fit
    k = len(inliers)
    for richer in check.models:
        est = estimate(richer, best.src, best.dst, ransac, seed=seed)
        if est.transform is None or folded(est.transform, view.source_shape):
            continue
        if check.clearly_more(est.n_inliers, k):
            inl = est.inliers
            return Fit(est.transform, np.hstack([best.src[inl], best.dst[inl]]), richer)
    return fit


def _pooled(view: View, outcomes: Sequence,
            coarser: Optional[View] = None) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """The distinct candidates (finer px, coarser px) of every scale matched in full, or None
    when fewer than two scales were."""
    done = [o for o in outcomes if o.estimate is not None and len(o.src)]
    if len(done) < 2:
        return None
    return distinct_pairs(to_high(view, np.vstack([o.src for o in done])),
                          _back(coarser, np.vstack([o.dst for o in done])))


def pooled_refit(fit: Fit, view: View, outcomes: Sequence, ransac: RansacParams,
                 coarser: Optional[View] = None) -> Fit:
    """``fit`` refined on the candidates of every scale matched in full.

    The neighbouring scales of a true match find the same transform (the paper's Table 1) from
    other points; pooled, they spread the inliers wider over the image, which pins a homography
    or an affine map down where the winning scale alone had few points. Kept only when it
    explains at least as many pooled pairs; the inliers reported stay those of the winning
    scale (the pairs the decision counted) that the refined transform still explains.
    """
    t, inliers, model = fit
    pool = _pooled(view, outcomes, coarser) if model_of(model).has_ratio else None
    if pool is None:
        return fit
    src, dst = pool
    before = int((residuals(model, t, src, dst) <= ransac.threshold_px).sum())
    est = refine(model, t, src, dst, ransac)
    if est.n_inliers < before or folded(est.transform, view.source_shape):
        return fit
    keep = residuals(model, est.transform, inliers[:, :2], inliers[:, 2:4]) <= \
        ransac.threshold_px
    return Fit(est.transform, inliers[keep], model)


def union_homography(fit: Fit, view: View, outcomes: Sequence, check: ModelCheckParams,
                     spec: FitSpec, coarser: Optional[View] = None) -> Fit:
    """A homography fitted to the candidates of every scale matched in full, when it explains
    clearly more of them than ``fit`` does (``min_gain`` times and ``min_extra`` more; the
    same pooled pairs count for both, so a plain zoom pair, where the similarity explains them
    all, keeps it).

    In perspective the local ratio changes across the footprint, so each scale matches the
    band of it whose local ratio is near that scale, and a similarity or an affine map fitted
    there holds on that band only: the pooled candidates of neighbouring scales cover the
    others, and a homography fitted to all of them holds on the whole. Only for a similarity
    asked for (``spec.model``: the model searched for) with the model check on
    (``ModelCheckParams.union``) and a homography among its models, as :func:`richer_model`;
    ``spec``: also the robust fit's parameters and the one seed.
    """
    asked, ransac, seed = spec.model, spec.ransac, spec.seed
    t, inliers, model = fit
    if (not check.enabled or not check.union or asked != "similarity"
            or model == "homography" or "homography" not in check.models):
        return fit
    pool = _pooled(view, outcomes, coarser)
    if pool is None:
        return fit
    src, dst = pool
    before = int((residuals(model, t, src, dst) <= ransac.threshold_px).sum())
    if not check.clearly_more(len(src), before):
        return fit  # no homography could explain enough more: the fit is not tried (same answer)
    est = estimate("homography", src, dst, ransac, seed=seed)
    if est.transform is None or folded(est.transform, view.source_shape):
        return fit
    if check.clearly_more(est.n_inliers, before):
        inl = est.inliers
        return Fit(est.transform, np.hstack([src[inl], dst[inl]]), "homography")
    return fit


def guided_refit(fit: Fit, source_shape: Tuple[int, int], outcomes: Sequence,
                 low: Described, guided: GuidedParams, spec: FitSpec,
                 check: Optional[ModelCheckParams] = None) -> Fit:
    """``fit`` grown by guided matching at every scale matched in full
    (:func:`scalematch.stages.guided.grow_rounds`, as the decision's second look grows one): kept
    unless its guided matches explain more pairs than its own inliers, and the inliers
    reported are then those matches.

    With ``check`` (the model check, for a similarity asked for), each richer model of
    ``check.models`` is fitted to the grown fit's guided matches and grown the same way; it is
    taken when it explains clearly more of the footprint (``check.clearly_more``): a model's
    guided matches spread as far as its predictions hold, so the model that bends as the
    scene does reaches the far corners. A similarity that stays one is returned as it was:
    four parameters are pinned by its own inliers, and the guided matches, looser, moved the
    zoom pairs' answers by hundredths of a px either way (median 0.157 -> 0.19 px on 220
    answers of under 30 inliers, docs/BENCHMARKS.md). ``source_shape``: the finer image's
    (H, W), which no answer may fold over; ``low``: the coarser image's points (s = 1, its
    px); ``spec``: the RANSAC parameters and seed of the refits. Only for a search made on the
    images themselves: a view's points and orientations are in the view's frame.
    """
    t, inliers, model = fit
    highs = [o.described for o in outcomes
             if o.estimate is not None and o.described is not None and len(o.described)]
    if not model_of(model).has_ratio or not highs:
        return fit
    points, ransac = Points(highs, low), spec.ransac

    def unfolded(m: np.ndarray) -> bool:
        return not folded(m, source_shape)

    best_t, best_in, _ = grow_rounds(t, model, points, guided, ransac, inliers, unfolded)
    richer = [m for m in check.models if MIN_SAMPLE[m] > MIN_SAMPLE[model]] \
        if check is not None and check.enabled else []
    for m in richer:
        src, dst = guided_pool(best_t, highs, low, guided)
        alt = estimate(m, src, dst, ransac, seed=spec.seed)
        if alt.transform is None or not unfolded(alt.transform):
            continue
        alt_t, alt_in, _ = grow_rounds(alt.transform, m, points, guided, ransac,
                                       allowed=unfolded)
        if check.clearly_more(len(alt_in), len(best_in)):
            model, best_t, best_in = m, alt_t, alt_in
    if model == "similarity":  # its own inliers pin it: growth adds only looser matches
        return fit
    return Fit(best_t, best_in, model)


#: The models a map can give way to where its inliers do not pin it down, richest first
#: (:func:`pinned_model`)
SIMPLER = ("homography", "affine", "similarity")


@dataclass(frozen=True)
class Pinned:
    """What :func:`pinned_model` found (JSON ``evidence.pin_px``, ``unpinned_model``,
    ``unpinned_px``): the answer's expected grid error, and the model fitted first that was not
    claimed, with its own (none: ``""`` and NaN)."""

    error_px: float  #: the answer's expected grid error, coarser px (working size)
    refused: str = ""  #: the model its inliers did not pin down ("" when the answer is it)
    refused_px: float = math.nan  #: that model's expected grid error, coarser px

    def figures(self, factor: float = 1.0) -> Dict[str, Any]:
        """The evidence figures, in the coarser image's own px (``factor``: its px per working
        px); ``unpinned_px`` stays the one ``math.nan`` when no model was refused (an
        :class:`Evidence` compares equal to another only with the same NaN object)."""
        return {"pin_px": self.error_px * factor, "unpinned_model": self.refused,
                "unpinned_px": self.refused_px * factor if self.refused else math.nan}


def pinned_model(fit: Fit, finer_shape: Tuple[int, int], coarser_shape: Tuple[int, int],
                 params: PinParams, spec: FitSpec) -> Tuple[Fit, Pinned]:
    """``fit``, or the simpler model its inliers pin down: the answer's last refinement.

    A map whose expected grid error (:func:`scalematch.stages.pinning.expected_error`, over the
    finer image's grid points it maps inside the coarser image) exceeds
    ``params.tolerance_px`` is not claimed as its model: each simpler model of
    :data:`SIMPLER` is fitted to the same inliers (RANSAC, ``spec``) and the first whose own
    expected error is within the tolerance answers, with its own inliers. Each is measured on
    every inlier of ``fit``, so a simpler model that cannot follow them (a tilted view's
    affine map, a perspective) is loose by its misfit as well. Where no simpler model is
    within the tolerance, ``fit`` answers as it is.

    The covariance measures how far the points' noise moves a map, not how far a model too
    simple for the scene is from the truth: a simpler model replaces only a map its own
    inliers leave loose. On the gate's pairs that need the richer model (docs/REGRESS.md:
    tilted, steep and oblique pairs, an affine map; perspective and Oxford pairs, a
    homography), the maps answered had expected errors of 0.02 to 0.92 px, but for 8 runs of
    affine maps of 6 to 13 inliers (4 oblique pairs, 1.31 to 1.92 px; Oxford graf 1 -> 6
    zoomed by 4 and 8, 1.96 and 1.43 px): they keep their model, the similarity fitted to
    their inliers being 8 to 84 px loose.
    """
    t, inliers, model = fit
    first = expected_error(model, t, inliers, finer_shape, params, coarser_shape)
    if not params.enabled or first <= params.tolerance_px or model not in SIMPLER:
        return fit, Pinned(first)
    for simpler in SIMPLER[SIMPLER.index(model) + 1:]:
        est = estimate(simpler, inliers[:, :2], inliers[:, 2:4], spec.ransac, seed=spec.seed)
        if est.transform is None or folded(est.transform, finer_shape):
            continue
        px = expected_error(simpler, est.transform, inliers, finer_shape, params, coarser_shape)
        if px <= params.tolerance_px:
            return Fit(est.transform, inliers[est.inliers], simpler), Pinned(px, model, first)
    return fit, Pinned(first)
