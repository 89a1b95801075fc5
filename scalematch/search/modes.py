"""The two modes as strategies, chosen once per search: how a level's points are described and
which candidate matches are handed to the estimator.

``"default"``: oriented gradient histograms, the candidates grouped by the rotation they imply
(:class:`GradientMode`). ``"paper"``: the local jets whitened by the covariance Lambda, the
semi-local constraints (:class:`JetMode`). :func:`mode_of` builds the one a ``Config`` names;
the stages then take what it gives them (``orientation``: None for descriptors without an
orientation, ``guided``: the second look's growth) instead of comparing the mode's name.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, Dict, List, Optional, Union

import numpy as np

from ..config import Config
from ..stages.constraints import OrientationParams, SemiLocalParams, orientation_groups, \
    semi_local_filter
from ..stages.descriptors import Described, GradientParams, JetParams, describe_gradients, \
    describe_jets
from ..stages.detector import Keypoints
from ..stages.guided import GuidedParams
from ..stages.matcher import Candidates
from ..stages.scalespace import Level


@dataclass(frozen=True)
class GradientMode:
    """The default mode: oriented gradient histograms, candidates grouped by their rotation."""

    gradients: GradientParams
    #: the rotation-consistency groups; the a-contrario count and the probe use it too
    orientation: Optional[OrientationParams]
    guided: GuidedParams  #: the second look's guided growth, orientation used
    covariance_used: str = ""  #: no covariance: the histograms are compared as they are
    #: its points carry an orientation, so the pooled vote over views can count rotations
    votes_over_views: ClassVar[bool] = True

    @staticmethod
    def of(config: Config) -> "GradientMode":
        return GradientMode(config.gradients, config.orientation, config.guided)

    def describe(self, level: Level, kp: Keypoints) -> Described:
        return describe_gradients(level, kp.xy, self.gradients)

    def constrain(self, high: Described, low: Described, cand: Candidates, level: Level,
                  low_image: np.ndarray) -> List[np.ndarray]:
        """Candidate subsets for the estimator (boolean masks over ``cand``): one per peak of
        the rotations the candidates imply."""
        return orientation_groups(low.angle[cand.j] - high.angle[cand.i], self.orientation)


@dataclass(frozen=True)
class JetMode:
    """The paper's mode: local jets whitened by Lambda (Mahalanobis), semi-local constraints."""

    sigma_tilde: float  #: the jets' integration scale (``HarrisParams.sigma_tilde``)
    jets: JetParams
    semi_local: SemiLocalParams
    whitening: np.ndarray = field(repr=False)  #: Lambda^-1/2 (``stages.mahalanobis``)
    covariance_used: str  #: where Lambda was read from (``MatchResult.covariance_used``)
    #: the second look's guided growth (without orientation: ``Config`` sets it so)
    guided: GuidedParams
    #: the jets carry no orientation: no rotation groups, none in the a-contrario count
    orientation: Optional[OrientationParams] = None
    #: no orientation to vote with: the paper's search is the plain one
    votes_over_views: ClassVar[bool] = False

    @staticmethod
    def of(config: Config) -> "JetMode":
        from ..stages.mahalanobis import load_covariance  # the paper mode only

        cov = load_covariance(config.covariance_path)
        return JetMode(config.harris.sigma_tilde, config.jets, config.semi_local,
                       cov.whitening(), cov.source, config.guided)

    def describe(self, level: Level, kp: Keypoints) -> Described:
        from ..stages.mahalanobis import whiten

        desc = describe_jets(level, kp.xy, self.sigma_tilde, self.jets)
        ok = np.all(np.isfinite(desc), axis=1)
        rows = np.nonzero(ok)[0]
        return Described(s=level.s, xy=kp.xy[rows], index=rows,
                         angle=np.full(rows.size, np.nan), desc=whiten(desc[rows], self.whitening))

    def constrain(self, high: Described, low: Described, cand: Candidates, level: Level,
                  low_image: np.ndarray) -> List[np.ndarray]:
        """One candidate subset for the estimator: those the semi-local constraints keep."""
        return [semi_local_filter(high.xy[cand.i], low.xy[cand.j], level, low_image,
                                  self.semi_local)]


Mode = Union[GradientMode, JetMode]

#: Each name of ``config.MODES`` and its strategy (built from a ``Config`` by its ``of``)
KINDS: Dict[str, type] = {"default": GradientMode, "paper": JetMode}


def votes_over_views(config: Config) -> bool:
    """Whether ``config.mode``'s points can be voted over views (:mod:`scalematch.search.viewpass`),
    which needs their orientations."""
    return KINDS[config.mode].votes_over_views


def mode_of(config: Config) -> Mode:
    """The strategy of ``config.mode``, built once for a search (the paper's reads Lambda)."""
    return KINDS[config.mode].of(config)
