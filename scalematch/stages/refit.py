"""After the decision: the winning search's transform refit in the finer image's own pixels.

Five refinements, in this order, each keeping the answer unless the evidence says otherwise:

1. :func:`refit_in_high`: a match found on a simulated tilted view (of the finer image, or of
   the coarser one) is refit in the images' own pixels (the view's similarity composed with the
   view's compression is an affine map).
2. :func:`pooled_refit`: the transform refined on the candidates of every scale matched in full.
3. :func:`richer_fits` and :func:`chosen_model` (``answer.model_by_pixels``): an affine
   map and a homography fitted to the winning scale's candidates and to the pooled ones; the
   one that lines the pixels up clearly better than the map found, and that the pixels vouch
   for window by window over the whole overlap, answers (``ModelCheckParams``). In
   perspective each scale matches the part of the footprint at its own local ratio, so only
   the pooled candidates see the whole of it (docs/design/VIEWS.md, "Perspective pairs").
4. :func:`guided_refit`, once the answer is accepted (``answer.grown_answer``): the paper's
   step (iv), "establish many other matches once this matrix is known": every described point
   of every scale matched in full is predicted by the answer and matched among the coarser
   points near its prediction (guided matching, :mod:`scalematch.stages.guided`); the answer
   is refit on those matches while they grow. Matches spread over the whole footprint pin
   down the parts the winning scale's inliers leave loose (a homography's far corners).
5. :func:`pinned_model`, last: a map whose inliers leave it free to err by more than the
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
from typing import Any, Callable, ClassVar, Dict, List, Mapping, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from ..checks import Bounds, CORRELATION, COUNT, FACTOR, check_bounds, one_of
from ..geometry import compose, invert
from .acontrario import Decision
from .decision import folded
from .descriptors import Described
from .estimator import (MIN_SAMPLE, MODELS, FitSpec, RansacParams, estimate, refine,
                        residuals)
from .guided import GuidedParams, Points, grow_rounds, guided_pool
from .matcher import distinct_pairs
from .pinning import PinParams, expected_error
from .views import View, to_high


@dataclass(frozen=True)
class ModelCheckParams:
    """A similarity answer is checked against richer models of the same match.

    A viewpoint change (tilt, perspective) makes a similarity hold on part of the image only:
    measured on graf, wall and tilted zoom pairs (docs/results/BENCHMARKS.md), the best similarity
    was tens of px off away from its inliers. An affine map and a homography are fitted to the
    match's candidates (:func:`richer_fits`) and the pixels choose (:func:`chosen_model`):
    inlier counts cannot, since a model with more freedom always fits a few more by chance and
    a wrong affine map of a plane in perspective can fit more candidates than its homography.
    ``MatchResult.model`` says which model answers; on plain zoom pairs the similarity lines
    the pixels up as well as any, and stays.
    """

    enabled: bool = True  #: False: the similarity is always the answer when asked for
    models: Tuple[str, ...] = ("affine", "homography")  #: the richer models fitted
    #: guided growth (:func:`guided_refit`) takes a richer model when its guided matches reach
    #: ``min_gain`` x the similarity's and at least ``min_extra`` more (a model with more
    #: freedom always fits a few more by chance)
    min_gain: float = 1.25
    min_extra: int = 10
    #: fit the richer models to the pooled candidates of every scale matched in full as well as
    #: the winning scale's: on perspective zoom pairs whose local ratio spans 4x across the
    #: footprint the winning scale sees one band of it, and its similarity was 4.6-6.8 px off
    #: at the far ends (docs/design/VIEWS.md, "Perspective pairs")
    union: bool = True
    #: a richer model answers where it lines the pixels up better than the map found, by at
    #: least this much ZNCC over the overlap (:func:`by_pixels`), or explains clearly more
    #: candidates and lines them up no worse by more than this (:func:`by_counts`); among the
    #: maps allowed, the simplest model within this much of the best (:func:`chosen_model`).
    #: Where a richer model is needed the gap is wide (a plane in perspective: similarity 0.40,
    #: homography 0.92; Oxford graf 1 -> 6 zoomed by 4: affine 0.42, homography 0.75), and on
    #: the gate's 176 zoom pairs no richer map gains this much: the similarity stays
    #: (docs/design/DECISION.md, "The model chosen by the pixels")
    min_ncc_gain: float = 0.05

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
        "min_ncc_gain": CORRELATION,
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
    """``fit``, a map, refined on the candidates of every scale matched in full.

    The neighbouring scales of a true match find the same transform (the paper's Table 1) from
    other points; pooled, they spread the inliers wider over the image, which pins a homography
    or an affine map down where the winning scale alone had few points. Kept only when it
    explains at least as many pooled pairs; the inliers reported stay those of the winning
    scale (the pairs the decision counted) that the refined transform still explains.
    """
    t, inliers, model = fit
    pool = _pooled(view, outcomes, coarser)
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


class Richer(NamedTuple):
    """A richer model of a match (:func:`richer_fits`), and how many of the candidates it was
    fitted to the map found explains (the count it is compared with)."""

    fit: Fit
    simpler_inliers: int
    #: whether inlier counts may choose it (:func:`by_counts`): not an affine map of the
    #: pooled candidates, whose wider spread lets a wrong affine map of a repeated texture
    #: gather clearly more of them (two same-photo nulls, 43 against 31 and 35 against 24)
    counted: bool = True


def richer_fits(fit: Fit, view: View, best, outcomes: Sequence, check: ModelCheckParams,
                spec: FitSpec, coarser: Optional[View] = None) -> List[Richer]:
    """Each model of ``check.models`` richer than ``fit``'s, fitted (RANSAC, ``spec``) to the
    winning scale's candidates ``best`` and to the pooled candidates of every scale matched in
    full (``check.union``), in the images' own pixels: the maps compared with ``fit``
    (:func:`chosen_model`). Maps that fold the finer image over are left out.

    A viewpoint change makes a similarity hold on part of the image only; in perspective each
    scale matches the band of the footprint whose local ratio is near it, so the pooled
    candidates of neighbouring scales cover what the winning scale's leave out.
    """
    richer = [m for m in check.models if MIN_SAMPLE[m] > MIN_SAMPLE[fit.model]]
    if not richer:
        return []
    sets = [candidates_in_images(view, best, coarser)]
    pool = _pooled(view, outcomes, coarser) if check.union else None
    if pool is not None:
        sets.append(pool)
    out = []
    for n, (src, dst) in enumerate(sets):
        before = int((residuals(fit.model, fit.transform, src, dst) <=
                      spec.ransac.threshold_px).sum())
        for m in richer:
            est = estimate(m, src, dst, spec.ransac, seed=spec.seed)
            if est.transform is None or est.n_inliers <= MIN_SAMPLE[m] or \
                    folded(est.transform, view.source_shape):
                continue
            inl = est.inliers
            out.append(Richer(Fit(est.transform, np.hstack([src[inl], dst[inl]]), m), before,
                              counted=not (n > 0 and m == "affine")))
    return out


def by_pixels(ncc: float, found: float, gain: float) -> bool:
    """Whether a richer map of ZNCC ``ncc`` lines the pixels up clearly better than the map
    found (``found``): by ``gain`` at least (nan: the pixels cannot tell, no)."""
    return math.isfinite(ncc) and math.isfinite(found) and ncc >= found + gain


def by_counts(counted: bool, ncc: float, found: float, gain: float) -> bool:
    """Whether a richer map that explains clearly more candidates (``counted``) may answer:
    unless the pixels refuse it, lining them up worse than the map found by more than
    ``gain``, or not at all where the map found's can be measured (nan: its footprint leaves
    the overlap). Where the map found's pixels cannot be measured either, the counts decide."""
    if not math.isfinite(found):
        return counted
    return counted and math.isfinite(ncc) and ncc >= found - gain


def allowed_maps(nccs: Sequence[float], counted: Sequence[bool], pixels: Sequence[bool],
                 vouch: Callable[[int], bool], gain: float) -> List[bool]:
    """Which maps of one match may answer (:func:`chosen_model`'s ``allowed``): the first (the
    map found), each one ``counted`` (:func:`by_counts`), and each one the ``pixels`` ask for
    (:func:`by_pixels`) that ``vouch(k)`` confirms. ``vouch`` is costly (a window map over the
    whole coarser image), so it is asked only of maps that can still count: in descending ZNCC,
    until one falls more than ``gain`` below the best map allowed so far, below which no map
    can set the best or be chosen. The same answer as vouching every one.

    >>> calls = []
    >>> def vouch(k):
    ...     calls.append(k)
    ...     return k != 2
    >>> allowed_maps([0.4, 0.6, 0.9, 0.88, 0.7], [False, True, False, False, False],
    ...              [False, False, True, True, True], vouch, 0.05), calls
    ([True, True, False, True, False], [2, 3])
    """
    allowed = [True] + [bool(c) for c in counted[1:]]
    top = max((nccs[k] for k in range(1, len(nccs)) if allowed[k] and math.isfinite(nccs[k])),
              default=-math.inf)
    for k in sorted((k for k in range(1, len(nccs)) if pixels[k] and not allowed[k]),
                    key=lambda k: -nccs[k]):
        if nccs[k] < top - gain:
            break
        if vouch(k):
            allowed[k] = True
            top = max(top, nccs[k])
    return allowed


def chosen_model(nccs: Sequence[float], models: Sequence[str], allowed: Sequence[bool],
                 gain: float) -> int:
    """The index of the map to answer among maps of one match: ``nccs`` their ZNCC over the
    overlap (:func:`scalematch.stages.pixelcheck.overlap_ncc`), ``models`` their models,
    ``allowed`` which may answer (:func:`by_pixels`, :func:`by_counts`); the first is the map
    found, which answers when no other may. Among those allowed the pixels choose: the
    simplest model within ``gain`` of the best ZNCC, its best map (where the pixels cannot
    tell, the first allowed).

    >>> chosen_model([0.40, 0.54, 0.92, 0.75], ["similarity", "affine", "homography",
    ...                                         "homography"], [True, True, True, True], 0.05)
    2
    >>> chosen_model([0.40, 0.80, 0.83], ["similarity", "affine", "homography"],
    ...              [True, True, True], 0.05)
    1
    >>> chosen_model([0.95, 0.97], ["similarity", "affine"], [True, False], 0.05)
    0
    >>> chosen_model([float("nan"), float("nan")], ["similarity", "affine"], [True, True], 0.05)
    1
    """
    ok = [k for k in range(1, len(nccs)) if allowed[k]]
    if not ok:
        return 0
    v = {k: (nccs[k] if math.isfinite(nccs[k]) else -math.inf) for k in ok}
    best = max(v.values())
    if best == -math.inf:
        return ok[0]
    near = [k for k in ok if v[k] >= best - gain]
    simplest = min(MIN_SAMPLE[models[k]] for k in near)
    return max((k for k in near if MIN_SAMPLE[models[k]] == simplest), key=lambda k: v[k])


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
    answers of under 30 inliers, docs/results/BENCHMARKS.md). ``source_shape``: the finer image's
    (H, W), which no answer may fold over; ``low``: the coarser image's points (s = 1, its
    px); ``spec``: the RANSAC parameters and seed of the refits. Only for a search made on the
    images themselves: a view's points and orientations are in the view's frame.
    """
    t, inliers, model = fit
    highs = [o.described for o in outcomes
             if o.estimate is not None and o.described is not None and len(o.described)]
    if not highs:
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
