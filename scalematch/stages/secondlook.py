"""The second look at a few-inlier hypothesis (docs/design/DECISION.md, test 3).

A best transform of more inliers than its minimal sample and fewer than ``min_inliers``, or
one whose footprint lies mostly outside the coarser image, is looked at again: grown by guided
matching and checked with the pixels (:func:`look_again`, :class:`Look`, from what a search
sees: :class:`Sight`, :class:`Seen`); :func:`look_confirms` and :func:`few_confirmed` say
whether its pixels confirm it, :func:`placed_better_nearby` whether a placement nearby fits
them better.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .acontrario import DecisionParams, Winner
from .descriptors import Described
from .estimator import FitSpec
from .finalchecks import near_windows_agree
from .guided import GuidedParams, grow
from .nearby import Nearby, best_nearby
from .nodata import with_nan
from .pixelcheck import NearWindows, PixelParams, near_windows, pixel_check


@dataclass(frozen=True)
class Look:
    """A second look at a hypothesis: guided growth, then the pixel check of the grown map."""

    transform: np.ndarray = field(repr=False)  #: the grown transform (finer px -> coarser px)
    inliers: np.ndarray = field(repr=False)  #: (N, 4) its distinct inliers
    chance: float  #: guided matches to expect by chance around the predictions
    ncc: float  #: ZNCC of the pixels under the grown map (nan: cannot tell)
    margin: float  #: ncc minus the best of the nearby wrong placements (nan: cannot tell)
    z: float  #: ncc against the nearby placements' mean, in their standard deviations
    #: the same window by window (:func:`scalematch.stages.pixelcheck.near_windows`), measured
    #: only when asked and the margin falls short (0 windows: not measured)
    windows: NearWindows = NearWindows(0, math.nan, math.nan)


@dataclass(frozen=True)
class Seen:
    """One image of a hypothesis as the second look sees it."""

    #: its described points (the finer image's at the hypothesis' scale)
    described: Described = field(repr=False)
    #: its pixels at the search's working size, NaN where it shows no scene
    image: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class Sight:
    """What a second look at a hypothesis of one search sees (:meth:`look`): the images it
    compared, at the search's working size, where each shows the scene, and the coarser
    image's described points; handed to :func:`scalematch.stages.decision.decide` as data, so the
    decision calls nothing of the search that made it."""

    finer: np.ndarray = field(repr=False)  #: the finer image (or view) searched
    finer_valid: Optional[np.ndarray] = field(repr=False)  #: where it shows the scene (None: all)
    coarser: Described = field(repr=False)  #: the coarser image's (or view's) described points
    coarser_image: np.ndarray = field(repr=False)
    coarser_valid: Optional[np.ndarray] = field(repr=False)
    fit: FitSpec
    guided: GuidedParams
    pixel: PixelParams

    def look(self, t: np.ndarray, outcome, windows_below: float = math.nan) -> Look:
        """:func:`look_again` at hypothesis ``t`` of a scale's ``outcome`` (its described finer
        points), the images with NaN where they show no scene."""
        return look_again(t, Seen(outcome.described, with_nan(self.finer, self.finer_valid)),
                          Seen(self.coarser, with_nan(self.coarser_image, self.coarser_valid)),
                          fit=self.fit, guided=self.guided, pixel=self.pixel,
                          windows_below=windows_below)

    def nearby(self, t: np.ndarray) -> Nearby:
        """The placement near ``t`` that fits the pixels best
        (:func:`scalematch.stages.nearby.best_nearby`)."""
        return best_nearby(with_nan(self.coarser_image, self.coarser_valid),
                           with_nan(self.finer, self.finer_valid), t, self.pixel)


def look_again(t: np.ndarray, finer: Seen, coarser: Seen, *, fit: FitSpec, guided: GuidedParams,
               pixel: PixelParams, windows_below: float = math.nan) -> Look:
    """Grow hypothesis ``t`` by guided matching (:func:`scalematch.stages.guided.grow`) and check
    the grown map with the pixels (:func:`scalematch.stages.pixelcheck.pixel_check`); where its
    margin is below ``windows_below`` (nan: never), window by window too
    (:func:`scalematch.stages.pixelcheck.near_windows`).

    ``finer``: every described point of the finer image at the hypothesis' scale, and its
    pixels; ``coarser``: the coarser image's points and pixels. ``fit``: the model searched for
    and the refit's RANSAC parameters (growth draws no sample: the seed is not used);
    ``guided``: the growth's parameters (``use_orientation`` off for descriptors without one:
    the paper's jets); ``pixel``: the pixel check's.
    """
    growth = grow(t, finer.described, coarser.described, fit.model, guided, fit.ransac)
    grown = growth.transform if growth.n_inliers else np.asarray(t, np.float64)
    check = pixel_check(coarser.image, finer.image, grown, pixel)
    windows = near_windows(coarser.image, finer.image, grown, pixel) \
        if check.margin < windows_below else NearWindows(0, math.nan, math.nan)
    return Look(grown, growth.inliers, growth.chance, check.ncc, check.margin, check.z, windows)


def pixels_confirm(log10_nfa: float, margin: float, params: DecisionParams) -> bool:
    """Whether a few-inlier transform's NFA and pixel margin reach one of the two tiers: a
    modest margin with a low NFA, or a margin no wrong placement reaches with the plain
    a-contrario bound (``few_*`` and ``max_log_nfa`` of
    :class:`scalematch.stages.acontrario.DecisionParams`). A nan margin (cannot tell) confirms
    nothing.

    >>> p = DecisionParams()
    >>> pixels_confirm(-7.0, 0.15, p), pixels_confirm(-4.5, 0.15, p), pixels_confirm(-4.5, 0.4, p)
    (True, False, True)
    >>> pixels_confirm(-2.5, 0.27, p), pixels_confirm(-2.9, 0.2, p), pixels_confirm(-1.5, 0.87, p)
    (True, False, False)
    """
    tiers = ((params.few_max_log_nfa, params.few_min_margin),
             (params.max_log_nfa, params.few_clear_margin))
    return any(log10_nfa <= nfa and margin >= least for nfa, least in tiers)


def look_windows_below(log10_nfa: float, params: DecisionParams) -> float:
    """The pixel margin below which the second look of a transform at ``log10_nfa`` also
    compares its nearby placements window by window (:func:`look_confirms`): the first tier's
    ``few_min_margin`` for a transform beyond chance by ``few_max_log_nfa``; nan (never) above.
    """
    return params.few_min_margin if log10_nfa <= params.few_max_log_nfa else math.nan


def look_confirms(log10_nfa: float, second: Optional[Look], params: DecisionParams) -> bool:
    """Whether the second look's pixels confirm a transform at ``log10_nfa``: its margin
    (:func:`pixels_confirm`), or, in the first tier (``few_max_log_nfa``), where an occluder in
    the finer image sinks the one ZNCC at the hypothesis as at its neighbours, its windows
    (:func:`scalematch.stages.finalchecks.near_windows_agree`, as the final map's:
    ``DecisionParams.min_near_windows``).
    """
    if second is None:
        return False
    return pixels_confirm(log10_nfa, second.margin, params) or (
        log10_nfa <= params.few_max_log_nfa and near_windows_agree(second.windows, params))


def few_confirmed(w: Winner, second: Optional[Look], params: DecisionParams) -> bool:
    """Whether the second look accepts a winner of fewer than ``min_inliers``: enough inliers,
    far enough beyond chance for its pixels (:func:`look_confirms`). Its growth is recorded,
    not asked for: at the coarse scales where few points remain there is nothing to grow into
    (the true 5-inlier answers at ratios 10-16 grew 5 -> 5; docs/design/DECISION.md, "The
    ground for each threshold")."""
    return second is not None and w.k >= params.few_min_inliers and \
        look_confirms(w.log10_nfa, second, params)


def placed_better_nearby(t: np.ndarray, k: int, sight: Sight) -> Optional[str]:
    """Why a map ``t`` of ``k`` inliers (fewer than ``min_inliers``) is ambiguous, or None: a
    placement at least :func:`_apart` from it, within a scale step, ``rotation_deg`` and half
    a footprint (:func:`scalematch.stages.nearby.best_nearby`), fits the pixels better. A few
    points can agree on a copy of a repeated texture a few windows off the truth, whose pixels
    fit well but not best (docs/design/DECISION.md, "Placed better nearby")."""
    near = sight.nearby(t)
    if near.moved >= _apart(sight.pixel) and near.best > near.claimed:
        return (f"ambiguous: a placement {near.moved:.0%} of the footprint away fits the pixels "
                f"better than the map of {k} inliers (ZNCC {near.best:.2f} against "
                f"{near.claimed:.2f})")
    return None


def _apart(pixel: PixelParams) -> float:
    """How far from a map (a fraction of the footprint's size) a placement is another one: half
    the pixel check's perturbation (``PixelParams.shift_fraction``), whose placements count as
    wrong ones; a map a few pixels off its best placement (a similarity on a slightly oblique
    plane) stays within it."""
    return 0.5 * pixel.shift_fraction
